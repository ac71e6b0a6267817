"""Subcommands on packings of 2D shaped bodies: init-shapes, modes (soft-jam handles jamming)."""

from __future__ import annotations

import argparse
import sys

import numpy as np
import xarray as xr

from ..io import new_dataset_attrs, read_packing, write_dataset, write_packing
from ..resources import check_fits
from ..shapes.generation import (
    SHAPE_CHOICES,
    bidisperse_shapes,
    random_polygon_shapes,
    random_shape_packing,
    unit_shape,
)
from .common import (
    add_command,
    add_quiet,
    packing_rows,
    print_summary,
    split_paths,
    stage_parameters,
)
from .types import (
    bins,
    count,
    integer,
    packing_fraction,
    path_with_suffix,
    positive,
    real,
    seed,
)

#: Most Monte Carlo samples per radius decrease of ``feasible-region``: the draw holds
#: (samples, 3) float64 coordinates and a few temporaries of that size, about 1 GB at 1e7.
MAX_SAMPLES: int = 10_000_000

#: Default packing fraction of the random start: random sequential addition of
#: elongated bodies (up to aspect ratio ~5) still finds free places quickly.
INIT_SHAPES_PHI: float = 0.3


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "init-shapes", _init_shapes,
                    "random bidisperse packing of 2D shaped bodies (VanderWerf et al.): areas 1.4^2 apart, "
                    "equal masses, mean area-equivalent diameter 1, no overlap",
                    writes=("out",), packings=("out",))
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF packing")
    p.add_argument("--shape", choices=SHAPE_CHOICES, required=True, help="shape family")
    p.add_argument("--aspect-ratio", type=positive, default=None,
                   help="length over width (ellipse a/b; circulo-line (l + 2R)/2R; dumbbell (2|v| + 2R)/2R)")
    p.add_argument("--asphericity", type=positive, default=None,
                   help="target asphericity A = p^2 / (4 pi a) > 1 (met exactly by bisection on the shape parameter)")
    p.add_argument("--shaft-length", type=positive, default=None,
                   help="dumbbell: the paper's shaft length X, the lobe-centre distance in lobe radii (Fig. 4: 2.4 "
                        "isostatic, 4 hypostatic; Table I's alpha - 1, X = 2 gives A - 1 = 0.514); the same as "
                        "--aspect-ratio 1 + X/2")
    p.add_argument("--sides", type=integer(3, 1000), default=None, help="circulo-polygon: number of sides n >= 3 (regular polygon)")
    p.add_argument("--random", action="store_true",
                   help="circulo-polygon: a random polygon per body at --asphericity (VanderWerf et al. App. B, "
                        "kept convex; the shapes draw from --seed)")
    p.add_argument("--n", type=count, required=True, help="number of bodies (even: half small, half large)")
    p.add_argument("--phi", type=packing_fraction, default=INIT_SHAPES_PHI,
                   help=f"packing fraction of the random start (default {INIT_SHAPES_PHI})")
    p.add_argument("--seed", type=seed, required=True, help="random seed")
    add_quiet(p)

    p = _pooled_command(sub, "contact-angles", _contact_angles,
                        "contact-angle distribution P(psi) of elongated bodies (VanderWerf et al. Fig. 14): psi "
                        "is the angle between a body's long axis and the vector from its centre to a contact "
                        "point, pooled over packings, contacts between non-rattlers", "jammed shape packings")
    p.add_argument("--bins", type=bins, default=18, help="bins on [0, pi/2] (default 18, 5 degrees each)")
    add_quiet(p)
    p = add_command(sub, "shape-survey", _shape_survey,
                    "phi_J and <z> against asphericity over jammed packings of shapes and disks (VanderWerf et al. "
                    "Figs. 5, 6, 8): one row per packing with contacts counted once, twice and (--spectral) as "
                    "N_c^0 - N_1, mean and standard error per shape family and asphericity",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("shape-survey",)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc",
                   help="jammed 2D packings (shapes from soft-jam, or bidisperse disks), then the output")
    p.add_argument("--spectral", action="store_true",
                   help="also count contacts as N_c = N_c^0 - N_1 from each packing's dynamical-matrix spectrum "
                        "(Fig. 8's definition for circulo shapes; one dense eigensolve of 3N x 3N per packing)")
    p.add_argument("--lambda-c", type=positive, default=None,
                   help="with --spectral: cutoff between regions 1 and 2 [k] (default: the widest admissible gap, "
                        "as jamflow modes)")
    add_quiet(p)

    p = add_command(sub, "constraint-curvature", _constraint_curvature,
                    "principal curvatures of the contact constraints of circulo-line packings per contact type "
                    "(VanderWerf et al. Sec. III C, Table II): mean and RMS deviation in units of the box side",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("constraint-curvature",)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help="jammed circulo-line packings, then the output")
    add_quiet(p)

    p = add_command(sub, "feasible-region", _feasible_region,
                    "volume and surface of the feasible region of one circulo-line caged by three fixed points "
                    "against the decrease of its radius (VanderWerf et al. Figs. 12-13)", writes=("out",),
                    makes={"out": ("feasible-region",)})
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF (dim shrink)")
    p.add_argument("--half-length", type=positive, default=0.2,
                   help="core half-length over the radius R (default 0.2: A - 1 = 0.013; three points hold lines "
                        "up to about 0.25 R at --beta 45)")
    p.add_argument("--beta", type=real(0.0, 90.0, lo_open=True, hi_open=True, need="an angle in (0, 90) degrees"), default=45.0, help="angle of the cap points below the axis [degree] (default 45)")
    p.add_argument("--shrinks", type=real(0.0, 0.5, lo_open=True, hi_open=True, need="a radius decrease dR / R in (0, 0.5)"), nargs="+", default=[1e-7, 1e-6, 1e-5, 1e-4, 1e-3],
                   help="radius decreases dR / R (default 1e-7 ... 1e-3)")
    p.add_argument("--samples", type=integer(1, MAX_SAMPLES, need=f"a number of samples in [1, {MAX_SAMPLES}]"), default=400_000, help="Monte Carlo samples per dR (default 400000)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the Monte Carlo samples (default 0)")
    add_quiet(p)

    p = add_command(sub, "modes", _modes,
                    "dynamical-matrix spectrum of a shape packing: regions 0-3, quartic modes N_1 and their "
                    "fourth derivatives, and the check N_c = N_c^0 - N_1 (VanderWerf et al. Sec. III B); of a "
                    "linked packing: constrained-Hessian eigenvalues and eigenvectors with the zero modes named "
                    "(chains paper Sec. IV A)",
                    reads=("input",), writes=("out",), makes={"out": ("modes", "linked-modes")})
    p.add_argument("input", help="input netCDF shape or linked packing at force balance (soft-jam)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF spectrum (dim mode)")
    p.add_argument("--lambda-c", type=positive, default=None,
                   help="cutoff between regions 1 and 2 [k]; default: the widest gap of log(lambda) in the "
                        "lower half of the nonzero spectrum that spans a decade and starts at most "
                        "1e3 P (region 1 empty without one)")
    p.add_argument("--strain", choices=["auto", "yes", "no"], default="auto",
                   help="linked packings: include the strain at fixed volume (default auto: when the packing is "
                        "shear-stabilised; a fixed-box packing is not in equilibrium in the strain)")
    add_quiet(p)


def _pooled_command(sub: argparse._SubParsersAction, name: str, handler, help: str,
                    inputs: str) -> argparse.ArgumentParser:
    """A command reading packings ``IN ... OUT`` with ``--parallel-contacts`` (Fig. 6)."""
    from ..shapes.counting import PARALLEL_MODES

    p = add_command(sub, name, handler, help, reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": (name,)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help=f"{inputs}, then the output")
    p.add_argument("--parallel-contacts", choices=PARALLEL_MODES, default="once",
                   help="a parallel circulo contact counts once or twice (Fig. 6; default once)")
    return p


def _contact_angles(args: argparse.Namespace) -> int:
    from ..shapes.analysis import contact_angle_dataset

    inputs, out = split_paths(args.paths, "shape packing")
    ds = contact_angle_dataset([read_packing(p, None) for p in inputs], args.parallel_contacts, args.bins)
    ds.attrs.update(new_dataset_attrs("jamflow contact-angle distribution", stage_parameters(args, "paths")))
    write_dataset(ds, out)
    a = ds.attrs
    print_summary(args, out, [
        ("packings, angles", f"{a['n_packings']}, {a['n_angles']} ({a['family']}, A - 1 = {a['asphericity'] - 1:.4g})"),
        ("mean psi", f"{a['psi_mean']:.4f} rad (uniform directions: {np.pi / 4:.4f})"),
        ("fraction psi < pi/4", f"{a['tip_fraction']:.4f}"),
        ("P(psi) first, last bin", f"{ds.P_psi.values[0]:.4f}, {ds.P_psi.values[-1]:.4f} 1/rad "
                                   f"(uniform 2/pi = {2 / np.pi:.4f})"),
    ])
    return 0


def _shape_survey(args: argparse.Namespace) -> int:
    from ..shapes.survey import CONVENTIONS, check_jammed, survey_dataset, survey_row

    inputs, out = split_paths(args.paths, "shape packing")
    if args.lambda_c is not None and not args.spectral:
        raise ValueError("--lambda-c sets the spectral count: give --spectral with it")
    packings = [read_packing(p, None) for p in inputs]
    for path, packing in zip(inputs, packings, strict=True):
        check_jammed(packing, path)
    rows = [survey_row(p, args.spectral, args.lambda_c, path) for path, p in zip(inputs, packings, strict=True)]
    for path, row in zip(inputs, rows, strict=True):
        if not row["jammed"]:
            print(f"jamflow shape-survey: warning: {path}: {row['status']}; left out of the means", file=sys.stderr)
    ds = survey_dataset(rows, inputs)
    ds.attrs.update(new_dataset_attrs("jamflow phi_J and <z> against asphericity",
                                      stage_parameters(args, "paths"), n_packings=len(rows),
                                      spectral=int(args.spectral)))
    write_dataset(ds, out)
    shown = [k for k, c in enumerate(CONVENTIONS) if args.spectral or c != "spectral"]
    rows_out = []
    for g in range(ds.sizes["group"]):
        z = ds.z_eq3_mean.values[g]
        zs = ds.z_eq3_sem.values[g]
        zc = ds.z_contacts_mean.values[g]
        head = f"{ds.group_family.values[g]} A-1={ds.group_asphericity.values[g] - 1:.3g}"
        rows_out.append((head, f"phi_J {ds.phi_J_mean.values[g]:.5f} ± {ds.phi_J_sem.values[g]:.5f} "
                               f"({ds.n_packings.values[g]} jammed, {ds.n_excluded.values[g]} left out, "
                               f"N = {ds.group_N.values[g]})"))
        rows_out.append(("  <z> Eq. 3 " + "/".join(CONVENTIONS[k] for k in shown),
                         " / ".join(f"{z[k]:.4f} ± {zs[k]:.4f}" for k in shown)))
        rows_out.append(("  z = 2 N_c / N' " + "/".join(CONVENTIONS[k] for k in shown),
                         " / ".join(f"{zc[k]:.4f}" for k in shown)))
    print_summary(args, out, rows_out)
    return 0


def _constraint_curvature(args: argparse.Namespace) -> int:
    from ..shapes.curvature import curvature_dataset

    inputs, out = split_paths(args.paths, "circulo-line packing")
    ds = curvature_dataset([read_packing(p, None) for p in inputs], inputs)
    ds.attrs.update(new_dataset_attrs("jamflow constraint curvatures", stage_parameters(args, "paths")))
    write_dataset(ds, out)
    print_summary(args, out, [
        (str(ds.contact_type.values[c]), f"kappa_1 {ds.kappa1_mean.values[c]:+.4g} ± {ds.kappa1_rms.values[c]:.2g}, "
                                         f"kappa_2 {ds.kappa2_mean.values[c]:+.4g} ± {ds.kappa2_rms.values[c]:.2g} "
                                         f"[1/L] ({int(ds.n_contacts.values[:, c].sum())} rows)")
        for c in range(ds.sizes["contact_type"])
    ] + [("packings, N, A", f"{ds.attrs['n_packings']}, {ds.attrs['N']}, {ds.attrs['asphericity']:.6g}")])
    return 0


def _feasible_region(args: argparse.Namespace) -> int:
    from ..shapes.feasible import cage_stability, feasible_scaling

    if args.samples < 1000:
        raise ValueError(f"--samples must be at least 1000, got {args.samples}")
    beta = np.radians(args.beta)
    stability = cage_stability(args.half_length, beta)
    if not stability < 0.0:
        raise ValueError(f"three points do not hold a line of half-length {args.half_length} R at beta = {args.beta} "
                         f"degrees (stress-weighted gap curvature along the free rotation {stability:+.3g} >= 0): "
                         "its feasible region is unbounded; shorten the line or change --beta")
    ds = feasible_scaling(np.array(args.shrinks), args.half_length, beta, args.samples, args.seed)
    ds.attrs.update(new_dataset_attrs("jamflow feasible region", stage_parameters(args, "out"),
                                      cage_stability=stability))
    write_dataset(ds, args.out)
    print_summary(args, args.out, [
        (f"dR / R = {d:.1e}", f"V {v:.4g} ± {ve:.1g}, S {s_:.4g} ± {se:.1g}")
        for d, v, ve, s_, se in zip(ds.shrink.values, ds.volume.values, ds.volume_err.values, ds.surface.values,
                                    ds.surface_err.values, strict=True)
    ] + [("exponents V, S", f"{ds.attrs['volume_exponent']:.4f}, {ds.attrs['surface_exponent']:.4f} "
                            "(expected 5/2, 3/2)"),
         ("stress-weighted curvature along the free rotation", f"{stability:+.4g} (< 0: held at quartic order)")])
    return 0


def _modes(args: argparse.Namespace) -> int:
    from ..shapes.spectrum import SPECTRUM_FORCE_RATIO, quartic_check, spectrum
    from ..shapes.survey import check_jammed, packing_asphericity, shape_label

    packing = read_packing(args.input, None)
    if packing.links is not None and len(packing.links) and packing.shapes is None:
        from .chains import linked_modes_command

        return linked_modes_command(args, packing)
    if packing.shapes is None:
        raise ValueError(f"{args.input}: not a shape packing (modes needs shapes and orientations)")
    if args.strain != "auto":
        raise ValueError("--strain is for linked packings; shape packings have no strain degrees of freedom here")
    check_jammed(packing, args.input)
    spec = spectrum(packing, args.lambda_c)
    if not spec.balanced:
        print(f"jamflow modes: warning: {args.input}: largest generalised force {spec.max_force:.3g} exceeds "
              f"{SPECTRUM_FORCE_RATIO:g} P = {SPECTRUM_FORCE_RATIO * spec.pressure:.3g}: residual forces shift the "
              "quartic eigenvalues (~P), so N_1 may be wrong; jam with a smaller --force-tol", file=sys.stderr)
    check = quartic_check(packing, spec)
    mode = ("mode",)
    ds = xr.Dataset(
        data_vars={
            "eigenvalue": (mode, spec.eigenvalue, {"units": "1", "long_name": "dynamical-matrix eigenvalue (ascending)",
                                                   "comment": "k (energy / length^2; orientations in rad)"}),
            "region": (mode, spec.region, {"units": "1", "long_name": "spectral region",
                                           "comment": "0 zero mode, 1 quartic, 2 rotational, 3 translational"}),
            "rotational_weight": (mode, spec.rotational_weight,
                                  {"units": "1", "long_name": "weight of the unit eigenvector on orientations"}),
            "fourth_derivative": (mode, spec.fourth_derivative,
                                  {"units": "1", "long_name": "d^4 U / ds^4 along region-1 modes (NaN elsewhere)",
                                   "comment": "k, s the amplitude along the unit eigenvector"}),
        },
        attrs=new_dataset_attrs("jamflow shape-packing spectrum", stage_parameters(args, "input", "out"),
                                N=packing.n, family=shape_label(packing), asphericity=packing_asphericity(packing),
                                n_quartic=spec.n_quartic, n_zero=spec.n_zero, lambda_c=spec.lambda_c,
                                lambda_0=spec.lambda_0, pressure=float(packing.pressure or np.nan),
                                max_generalized_force=spec.max_force, force_balanced_for_spectrum=int(spec.balanced),
                                n_nonpositive_fourth_derivative=int(np.sum(spec.fourth_derivative[spec.region == 1] <= 0.0)),
                                n_unresolved_fourth_derivative=int(np.sum(np.isnan(spec.fourth_derivative[spec.region == 1]))),
                                **check),
    )
    write_dataset(ds, args.out)
    d4 = spec.fourth_derivative[spec.region == 1]
    if np.any(d4 <= 0.0):
        print(f"jamflow modes: warning: {args.input}: {int(np.sum(d4 <= 0.0))} region-1 mode(s) with a non-positive "
              "fourth derivative: a stable quartic mode has d^4U/ds^4 > 0, so the mode is not quartic",
              file=sys.stderr)
    if np.any(np.isnan(d4)):
        print(f"jamflow modes: warning: {args.input}: {int(np.sum(np.isnan(d4)))} region-1 mode(s) without a fourth "
              "derivative (NaN): no second difference of v^T M v that keeps the contact network agrees between "
              "two steps", file=sys.stderr)
    print_summary(args, args.out, [
        ("N, modes", f"{packing.n}, {spec.eigenvalue.size}"),
        ("zero modes (region 0)", f"{spec.n_zero} (|lambda| <= {spec.lambda_0:.3g})"),
        ("quartic modes N_1 (region 1)", f"{spec.n_quartic} (lambda < lambda_c = {spec.lambda_c:.4g})"),
        ("regions 2, 3", f"{int(np.sum(spec.region == 2))}, {int(np.sum(spec.region == 3))}"),
        ("N_c once, twice", f"{check['n_contacts_once']}, {check['n_contacts_twice']}"),
        ("rattlers, sliders (twice)", f"{check['n_rattlers']}, {check['n_sliders']}"),
        ("N_c^0 - N_1", f"{check['isostatic_minus_quartic']} (N_c^0 = {check['isostatic_count']}; N_c twice "
                        + ("equals it)" if check["isostatic_minus_quartic"] == check["n_contacts_twice"] else
                           f"differs by {check['n_contacts_twice'] - check['isostatic_minus_quartic']:+d})")),
        ("d^4U/ds^4 on region 1", "none" if not d4.size else f"{d4.min():.4g} .. {d4.max():.4g}"),
    ])
    return 0


def _init_shapes(args: argparse.Namespace) -> int:
    check_fits("init-shapes", args.n, 2, "bodies")
    if args.random:
        if args.shape != "circulo-polygon" or args.aspect_ratio is not None or args.asphericity is None \
                or args.sides is None:
            raise ValueError("--random needs --shape circulo-polygon with --sides and --asphericity (no --aspect-ratio)")
        table = random_polygon_shapes(args.n, args.sides, args.asphericity, args.seed)
    else:
        table = bidisperse_shapes(unit_shape(args.shape, args.aspect_ratio, args.asphericity, args.sides,
                                             args.shaft_length))
    packing = random_shape_packing(table, args.n, args.phi, args.seed)
    params = stage_parameters(args, "out")
    packing = packing.evolve(parameters=params)
    write_packing(packing, args.out, params)
    print_summary(args, args.out, packing_rows(packing) + [
        ("shape", f"{args.shape} ({', '.join(sorted(set(table.kind)))})"),
        ("asphericity A", f"{table.asphericity[0]:.12g} (A - 1 = {table.asphericity[0] - 1.0:.6g}; "
                          f"max |A - A_0| over shapes {np.ptp(table.asphericity):.2g})"),
        ("areas small, large", f"{table.area[0]:.10g}, {table.area[-1]:.10g} (ratio {table.area[-1] / table.area[0]:.6g})"),
        ("bounding diameters", f"{2 * table.bounding_radius.min():.6g} .. {2 * table.bounding_radius.max():.6g}"),
        ("mean area-equivalent diameter", f"{np.mean(2.0 * np.sqrt(table.area[packing.shape_index] / np.pi)):.12g}"),
    ])
    return 0
