"""Soft-sphere subcommands: soft-jam, aqs, sd-shear, moduli."""

from __future__ import annotations

import argparse
import sys

import numpy as np
import xarray as xr

from ..analysis.contacts import summarize
from ..chains.compliance import compliance
from ..chains.hessian import constrained_hessian
from ..chains.jamming import DEFAULT_PROTOCOL, PROTOCOLS, jam_linked
from ..io import new_dataset_attrs, read_packing, write_dataset, write_packing
from ..minimize.onset import FORCE_TOL_VANDERWERF, ONSET_METHODS, JammingSettings
from ..models.spheres.hessian import (
    backbone_pairs,
    elastic_moduli,
    hessian,
    lowest_modes,
)
from ..models.spheres.potential import PowerLawPotential
from ..protocols.overdamped.run import dilute_start
from ..protocols.quasistatic import LERNER_DELTA_R, aqs_shear, lerner_sd_shear
from ..protocols.soft_jam import jam_to_pressure
from ..resources import check_memory, series_memory
from ..state.packing import LENGTH_UNITS, Packing, length_unit
from ..tolerances import MINIMIZE_FORCE_TOL
from .common import (
    add_command,
    add_preset,
    add_quiet,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .types import count, non_negative_int, path_with_suffix, positive, real, seed

#: Exponent w of the contact potential (eps / w) (1 - r / sigma)^w: the force is continuous at contact for w > 1.
EXPONENT = real(1.0, lo_open=True, need="an exponent w > 1 (2 harmonic, 2.5 Hertz)")


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "soft-jam", _soft_jam,
                    "soft-sphere jamming onset: compress/decompress bisection (or onset search) + enthalpy minimisation to P0 "
                    "(linked packings: fixed-box bisection with constraint projection)",
                    reads=("input",), writes=("out",), packings=("out",))
    p.add_argument("input", help="input netCDF packing (overlaps allowed)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF packing (lengths in units of the mean diameter)")
    p.add_argument("--pressure", type=positive, default=None,
                   help="target pressure P0 [epsilon / mean diameter^d], e.g. 1e-7 (required unless "
                        "--jam-protocol energy)")
    p.add_argument("--seed", type=seed, default=None,
                   help="start from uniformly random centres drawn with this seed (O'Hern's "
                        "infinite-temperature quench); default: start from the input centres")
    p.add_argument("--force-tol", type=positive, default=FORCE_TOL_VANDERWERF,
                   help=f"final max per-particle |F| [epsilon / mean diameter] (default {FORCE_TOL_VANDERWERF:.3g}: F^2 <= 1e-26)")
    p.add_argument("--pressure-rtol", type=positive, default=1e-6, help="final |P - P0| / P0 (default 1e-6)")
    p.add_argument("--delta-phi", type=positive, default=1e-3,
                   help="first step in packing fraction of the onset search or bisection (default 1e-3)")
    p.add_argument("--onset", choices=ONSET_METHODS, default="bisection",
                   help="how the compression to P0 chooses its packing fractions: 'bisection' (default) is O'Hern's "
                        "compress/decompress bisection in steps of --delta-phi; 'search' compresses the last "
                        "minimum below P0 with steps that double, in ~40-60 minimisations from a dilute start, "
                        "and jams 0.4-2 %% denser from one (docs/notes/chains.md)")
    p.add_argument("--exponent", type=EXPONENT, default=2.0, help="potential exponent w (2 harmonic, 2.5 Hertz)")
    p.add_argument("--box-dof", choices=["isotropic", "full"], default="isotropic",
                   help="final enthalpy minimisation over an isotropic box scale (default) or the whole box "
                        "(stress tensor -P0 1, the box may tilt); linked packings: full is --shear-stabilize, "
                        "whose bisection ends with that minimisation")
    p.add_argument("--max-steps", type=count, default=20_000_000, help="FIRE step budget of the whole protocol")
    p.add_argument("--shear-stabilize", action="store_true",
                   help="strain degrees of freedom at fixed volume in the bisection's minimisations (chains paper "
                        "Sec. II D), then, as for spheres, U + P0 V minimised with the whole box free: the final "
                        "stress is -P0 1; spheres and linked packings")
    p.add_argument("--jam-protocol", choices=PROTOCOLS, default=DEFAULT_PROTOCOL,
                   help=f"linked packings: bisection to --pressure, or the chains paper's decompression by the "
                        f"energy scaling of phi - phi_J down to --energy-tol (default {DEFAULT_PROTOCOL}; "
                        f"docs/notes/chains.md has the measurement)")
    p.add_argument("--energy-tol", type=positive, default=None,
                   help="energy per sphere [epsilon] at which --jam-protocol energy stops, e.g. 1e-12")
    p.add_argument("--newton-polish", action="store_true",
                   help="linked packings in a fixed box: let each minimisation of the final stage (to --force-tol) "
                        "end with the constrained trust-region Newton polish once FIRE's largest force is within 1e3 "
                        "of the tolerance (same tolerances; fewer FIRE steps from N ~ 1000, docs/notes/chains.md); "
                        "refused with --shear-stabilize, whose final stage is the enthalpy minimisation; shaped "
                        "bodies always polish their enthalpy stage")
    p.add_argument("--frozen-orientations", action="store_true",
                   help="shaped bodies: jam with every orientation fixed (VanderWerf et al. Fig. 3a, non-rotating "
                        "circulo-lines); counted with 2 degrees of freedom per body")
    add_quiet(p)
    add_preset(p)

    p = add_command(sub, "aqs", _aqs, "athermal quasistatic shear of a soft packing (stress-strain time series)",
                    reads=("input",), writes=("out", "final"), packings=("final",),
                    makes={"out": ("aqs",)})
    p.add_argument("input", help="input netCDF soft packing")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF time series (dim step, coordinate strain)")
    p.add_argument("--strain", type=positive, required=True, help="total strain (> 0)")
    p.add_argument("--step", type=positive, required=True, help="strain step delta gamma")
    p.add_argument("--fixed-pressure", action="store_true",
                   help="minimise the enthalpy at the input's pressure (or --pressure) after every step")
    p.add_argument("--pressure", type=positive, default=None, help="fixed pressure P0 (implies --fixed-pressure)")
    p.add_argument("--force-tol", type=positive, default=MINIMIZE_FORCE_TOL,
                   help=f"FIRE tolerance on max |F| per strain step (default {MINIMIZE_FORCE_TOL:g})")
    p.add_argument("--exponent", type=EXPONENT, default=2.0, help="potential exponent w")
    p.add_argument("--max-steps", type=count, default=10_000_000, help="FIRE steps allowed per strain step")
    p.add_argument("--final", type=path_with_suffix(".nc"), default=None,
                   help="also write the last state as a packing netCDF")
    add_quiet(p)
    add_preset(p)

    p = add_command(sub, "sd-shear", _sd_shear,
                    "Lerner et al. steepest-descent shear with tentative-network hard-sphere stress (flow schema)",
                    reads=("input",), writes=("out",), makes={"out": ("flow",)})
    p.add_argument("input", help="input netCDF packing")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF flow time series")
    p.add_argument("--strain", type=positive, required=True, help="total strain (> 0)")
    p.add_argument("--step", type=positive, default=1e-6, help="strain step (paper: 1e-6)")
    p.add_argument("--dt", type=positive, default=0.1, help="steepest-descent step (paper: 0.1)")
    p.add_argument("--grad-tol", type=positive, default=1e-9, help="max |grad U| stop (paper: 1e-9)")
    p.add_argument("--delta-r", type=positive, default=LERNER_DELTA_R, help="tentative network distance (paper: 1e-5)")
    p.add_argument("--max-steps", type=count, default=10_000_000, help="descent steps allowed per strain step")
    p.add_argument("--unit", choices=LENGTH_UNITS, default="small_diameter",
                   help="length unit lambda the input is rescaled to (default small_diameter, as jamflow shear)")
    add_quiet(p)

    p = add_command(sub, "moduli", _moduli,
                    "bulk and shear moduli (affine and relaxed) and lowest Hessian eigenvalues of a soft packing; "
                    "linked packings: compliance matrix, Voigt/Reuss/Hill moduli and constrained-Hessian modes",
                    reads=("input",), writes=("out",), makes={"out": ("moduli", "chain-moduli")})
    p.add_argument("input", help="input netCDF soft packing at force balance")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF dataset")
    p.add_argument("--modes", type=non_negative_int, default=10,
                   help="number of lowest non-translational eigenvalues (0: moduli only)")
    p.add_argument("--exponent", type=EXPONENT, default=2.0, help="potential exponent w")
    add_quiet(p)


def _series_rows(ds: xr.Dataset) -> list[tuple[str, str]]:
    """Last row of a shear time series: strain, stresses, contacts."""
    rows = [("strain steps", f"{ds.sizes['step']} (final strain {float(ds.strain[-1]):.6g})")]
    rows += [(f"final {name.replace('_', ' ')}", f"{float(ds[name][-1]):.6g}")
             for name in ("shear_stress", "pressure", "packing_fraction", "n_contacts") if name in ds]
    return rows


def _random_start(packing: Packing, seed: int) -> Packing:
    rng = np.random.default_rng(seed)
    s = rng.random((packing.n, packing.d))
    return packing.evolve(position=packing.box.to_cartesian(s), seed=seed)


def _soft_jam_linked(args: argparse.Namespace, packing: Packing) -> int:
    """soft-jam of a linked packing (or a shear-stabilised one): bisection with constraint projection (chains paper Sec. III)."""
    if args.seed is not None:
        raise ValueError("--seed draws random sphere centres, which would tear the links: start linked packings "
                         "from jamflow init-chains with its own --seed")
    bar = progress_bar(args.quiet, desc="soft-jam", unit=" bisection")

    def progress(info: dict) -> None:
        bar.update(1)
        bar.set_postfix(phi=f"{info['phi']:.8f}", P=f"{info['pressure']:.3e}")

    energy = args.jam_protocol == "energy"
    if energy and args.energy_tol is None:
        raise ValueError("--jam-protocol energy needs --energy-tol (energy per sphere at which it stops)")
    if energy and args.pressure is not None:
        raise ValueError("--pressure is the bisection's target; --jam-protocol energy stops at --energy-tol instead")
    settings = JammingSettings(args.force_tol, args.pressure_rtol, args.delta_phi, max_steps=args.max_steps,
                               box_dof=args.box_dof, onset=args.onset, newton_polish=args.newton_polish)
    result = jam_linked(packing, args.pressure, PowerLawPotential(exponent=args.exponent), settings, progress,
                        args.shear_stabilize, args.jam_protocol, args.energy_tol)
    bar.close()
    if not result.converged:
        goal = (f"0 < U/N <= energy_tol {args.energy_tol:g}" if energy else f"pressure_rtol {args.pressure_rtol:g}")
        raise RuntimeError(f"the linked {args.jam_protocol} protocol did not reach force_tol {args.force_tol:g} and "
                           f"{goal} within {args.max_steps} steps")
    out = result.packing
    write_packing(out, args.out, stage_parameters(args, "input", "out"))
    a = out.attrs
    stress = out.attrs["stress_deviation"]
    print_summary(args, args.out, [
        ("phi_J", f"{out.packing_fraction:.10f}"),
        ("pressure", f"{out.pressure:.6g} ("
                     + (f"energy per sphere {a['energy'] / out.n:.3g} <= {args.energy_tol:g}" if energy
                        else f"target {args.pressure:g}") + ") epsilon / mean diameter^d"),
        ("shear-stabilised", ("no" if not (args.shear_stabilize or args.box_dof == "full") else
                              "at fixed volume" if energy else "at fixed volume, then U + P0 V with the whole box free")
         + f" (max |sigma_ab - P delta_ab| / P = {stress:.3g})"),
        ("links", f"{len(out.links)} (max relative length error {a['max_link_error']:.3g})"),
        ("contacts N_c (backbone)", f"{a['n_contacts']} (cluster isostatic count {a['isostatic_count']}, "
                                    f"excess {a['n_contacts'] - a['isostatic_count']})"),
        ("rattlers", f"{a['n_rattlers']} ({a['n_rattling_clusters']} rattling clusters: {a['n_clusters_removed']} "
                     f"removed whole, {a['n_danglers']} danglers with {a['free_dofs']} free motions)"),
        ("max |P F|", f"{a['max_force_sq'] ** 0.5:.3g} epsilon / mean diameter"),
        ("FIRE steps", result.steps),
        ("onset", f"{'energy scaling' if energy else args.onset}, {len(result.history['phi'])} minimisations"),
    ])
    return 0


def _soft_jam(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, None)
    linked = bool((packing.links is not None and len(packing.links)) or args.shear_stabilize)
    if args.jam_protocol != "bisection" and not linked:
        raise ValueError("--jam-protocol energy is for linked or shear-stabilised packings (spheres: the bisection)")
    if args.pressure is None and not (linked and args.jam_protocol == "energy"):
        raise ValueError("--pressure is required (the target pressure P0)")
    if packing.shapes is not None:
        return _soft_jam_shapes(args, packing)
    if args.frozen_orientations:
        raise ValueError("--frozen-orientations is for shaped bodies (spheres have no orientation)")
    if linked:
        return _soft_jam_linked(args, packing)
    if args.newton_polish:
        raise ValueError("--newton-polish is for linked packings (spheres end with the enthalpy minimisation alone)")
    if args.seed is not None:
        packing = _random_start(packing, args.seed)
    bar = progress_bar(args.quiet, desc="soft-jam", unit=" bisection")

    def progress(info: dict) -> None:
        bar.update(1)
        bar.set_postfix(phi=f"{info['phi']:.8f}", P=f"{info['pressure']:.3e}")

    result = jam_to_pressure(
        packing, args.pressure, PowerLawPotential(exponent=args.exponent), args.force_tol,
        args.pressure_rtol, args.delta_phi, max_steps=args.max_steps, progress=progress,
        box_dof=args.box_dof, onset=args.onset,
    )
    bar.close()
    if not result.converged:
        raise RuntimeError(
            f"enthalpy minimisation did not reach force_tol {args.force_tol:g} / pressure_rtol "
            f"{args.pressure_rtol:g} within {args.max_steps} steps"
        )
    write_packing(result.packing, args.out, stage_parameters(args, "input", "out"))
    s = summarize(result.packing)
    print_summary(args, args.out, [
        ("phi_J", f"{s.phi:.10f}"),
        ("pressure", f"{result.packing.pressure:.6g} (target {args.pressure:g}) epsilon / mean diameter^d"),
        ("contacts N_c (backbone)", f"{s.n_contacts} (isostatic count {s.isostatic_count}, "
                                    f"excess {s.n_contacts - s.isostatic_count})"),
        ("rattlers", s.n_rattlers),
        ("max |F|", f"{result.packing.attrs['max_force_sq'] ** 0.5:.3g} epsilon / mean diameter"),
        ("FIRE steps", result.steps),
        ("onset", f"{args.onset}, {len(result.history['phi'])} minimisations to P0"),
    ])
    return 0


def _soft_jam_shapes(args: argparse.Namespace, packing: Packing) -> int:
    """soft-jam of shaped bodies: the linear spring of VanderWerf et al. Eq. 1, with rotations."""
    from ..shapes.jamming import jam_shapes

    if args.seed is not None:
        raise ValueError("--seed: a shape packing starts from its input; draw a new start with init-shapes --seed")
    if args.exponent != 2.0:
        raise ValueError(f"--exponent {args.exponent}: shaped bodies use the linear spring of Eq. 1 (exponent 2)")
    if args.box_dof != "isotropic":
        raise ValueError("--box-dof full is not available for shaped bodies (the box stays square)")
    bar = progress_bar(args.quiet, desc="soft-jam", unit=" bisection")

    def progress(info: dict) -> None:
        bar.update(1)
        bar.set_postfix(phi=f"{info['phi']:.8f}", P=f"{info['pressure']:.3e}")

    settings = JammingSettings(force_tol=args.force_tol, pressure_rtol=args.pressure_rtol,
                               delta_phi=args.delta_phi, max_steps=args.max_steps, onset=args.onset)
    result = jam_shapes(packing, args.pressure, settings, progress, rotations=not args.frozen_orientations)
    bar.close()
    if not result.converged:
        raise RuntimeError(f"FIRE did not reach force_tol {args.force_tol:g} within {args.max_steps} steps")
    out = result.packing
    write_packing(out, args.out, stage_parameters(args, "input", "out"))
    side = out.attrs["paper_length_unit"]
    print_summary(args, args.out, [
        ("phi_J", f"{out.packing_fraction:.10f}"),
        ("pressure", f"{out.pressure:.6g} k (target {args.pressure:g}); in the paper's units (box side L = 1) "
                     f"also {out.pressure:.6g} k: P / k does not depend on the length unit in 2D"),
        ("box side L (the paper's length unit)", f"{side:.8g} mean area-equivalent diameters"),
        ("orientations", "frozen (Fig. 3a)" if args.frozen_orientations else "free"),
        ("interacting pairs", len(out.contacts)),
        ("max |F|", f"{out.attrs['max_force_sq'] ** 0.5:.3g} k length"),
        ("max |torque|", f"{out.attrs['max_torque_sq'] ** 0.5:.3g} k length^2"),
        ("FIRE steps", result.steps),
        ("onset", f"{args.onset}, {len(result.history['phi'])} minimisations to P0"),
    ])
    return 0


def _strain_steps(args: argparse.Namespace) -> int:
    """Strain steps of ``--strain`` in ``--step``; refused when their time series would not fit in memory."""
    n = int(np.ceil(args.strain / args.step - 1e-9))
    check_memory(f"{args.command} of {n:.4g} strain steps", series_memory(n + 1),
                 "(give a larger --step or a smaller --strain)")
    return n


def _aqs(args: argparse.Namespace) -> int:
    n = _strain_steps(args)
    packing = read_packing(args.input, None)
    pressure = args.pressure
    if args.fixed_pressure and pressure is None:
        if packing.pressure is None or not packing.pressure > 0:
            raise ValueError("--fixed-pressure needs a positive pressure attribute in the input or --pressure")
        pressure = packing.pressure
    bar = progress_bar(args.quiet, total=n, desc="aqs")
    ds, final = aqs_shear(
        packing, args.strain, args.step, PowerLawPotential(exponent=args.exponent), args.force_tol,
        pressure, max_steps=args.max_steps, progress=lambda _: bar.update(1),
    )
    bar.close()
    write_dataset(ds, args.out)
    if args.final:
        write_packing(final, args.final, stage_parameters(args, "input", "out", "final"))
    print_summary(args, args.out, _series_rows(ds))
    return 0


def _sd_shear(args: argparse.Namespace) -> int:
    n = _strain_steps(args)
    packing = read_packing(args.input, None)
    warning = dilute_start(packing)
    if warning:
        print(f"jamflow sd-shear: warning: {warning}", file=sys.stderr)
    packing = packing.in_units(length_unit(packing.diameter, args.unit))
    bar = progress_bar(args.quiet, total=n + 1, desc="sd-shear")
    ds = lerner_sd_shear(packing, args.strain, args.step, args.dt, args.grad_tol, args.delta_r,
                         max_steps=args.max_steps, progress=lambda _: bar.update(1))
    bar.close()
    write_dataset(ds, args.out)
    print_summary(args, args.out, _series_rows(ds))
    return 0


def _moduli_linked(args: argparse.Namespace, packing: Packing) -> int:
    """Compliance (Sec. VI) and the constrained Hessian's lowest modes (Sec. IV) of a linked packing."""
    potential = PowerLawPotential(exponent=args.exponent)
    c = compliance(packing, potential)
    # strain modes only where the strain is a degree of freedom: a fixed-box packing is
    # not in equilibrium in the strain, and its box does not move
    stabilized = bool(packing.attrs.get("shear_stabilized", 0))
    ch = constrained_hessian(packing, potential, strain=stabilized)
    eigenvalues = ch.nonzero_eigenvalues[: args.modes]
    unit = "epsilon / length^d"
    names = [f"{'xyz'[a]}{'xyz'[b]}" for a, b in zip(*np.triu_indices(packing.d))]
    scalars = {name: ((), getattr(c, name), {"units": "1", "long_name": name.replace("_", " ") + " modulus",
                                              "comment": unit + " (inf: infinite, links forbid the strain)"})
               for name in ("bulk_voigt", "bulk_reuss", "bulk_hill", "shear_voigt", "shear_reuss", "shear_hill")}
    scalars["bulk_dilation"] = ((), c.bulk_dilation, {
        "units": "1", "long_name": "bulk modulus -V dP/dV under dilation (jamflow moduli's bulk)",
        "comment": unit + " (inf: infinite)"})
    scalars["shear_simple"] = ((), c.shear_simple, {
        "units": "1", "long_name": "simple-shear modulus (1/V) d2U/dgamma2, flow x, gradient y (jamflow moduli's shear)",
        "comment": unit + " (inf: infinite)"})
    ds = xr.Dataset(
        data_vars={
            **scalars,
            "compliance": (("strain_component", "stress_component"), c.S,
                           {"units": "1", "long_name": "compliance matrix S (Mandel basis eps_aa, sqrt2 eps_ab)",
                            "comment": "length^d / epsilon"}),
            "poisson_ratio": ((), c.poisson, {"units": "1", "long_name": "Poisson ratio (Hill moduli)"}),
            "anisotropy": ((), c.anisotropy, {"units": "1", "long_name": "universal anisotropy index"}),
            "eigenvalue": (("mode",), eigenvalues,
                           {"units": "1", "long_name": "lowest non-zero eigenvalues of the constrained Hessian "
                            + ("with strain at fixed volume" if stabilized else "at a fixed box"),
                            "comment": "epsilon / length^2 (unit mass)"}),
        },
        coords={"strain_component": names, "stress_component": names},
        attrs=new_dataset_attrs("jamflow linked-packing compliance and moduli", stage_parameters(args, "input", "out"),
                                d=packing.d, N=packing.n, n_links=len(packing.links), n_rigid=c.n_rigid,
                                n_unstable=c.n_unstable, pressure=c.pressure,
                                n_zero_modes=ch.n_zero, hessian_strain=int(stabilized), protocol=packing.protocol,
                                n_cemented=int(packing.attrs.get("n_cemented", 0)),
                                length_unit=packing.attrs.get("length_unit", "")),
    )
    write_dataset(ds, args.out)
    if c.n_unstable:
        print(f"jamflow moduli: warning: {args.input}: {c.n_unstable} strain direction(s) of negative stiffness: the "
              "packing is unstable to them at a fixed box (shear-stabilise it for positive moduli)", file=sys.stderr)
    print_summary(args, args.out, [
        ("bulk modulus K (Voigt, Reuss, Hill)", f"{c.bulk_voigt:.6g}, {c.bulk_reuss:.6g}, {c.bulk_hill:.6g} {unit}"),
        ("shear modulus G (Voigt, Reuss, Hill)", f"{c.shear_voigt:.6g}, {c.shear_reuss:.6g}, {c.shear_hill:.6g} {unit}"),
        ("bulk -V dP/dV, simple-shear G_xy", f"{c.bulk_dilation:.6g}, {c.shear_simple:.6g} {unit}"),
        ("Poisson ratio, anisotropy", f"{c.poisson:.4g}, {c.anisotropy:.4g}"),
        ("rigid stress directions (S = 0)", c.n_rigid),
        ("unstable strain directions (S < 0)", c.n_unstable),
        (f"zero modes (constrained Hessian, {'with strain' if stabilized else 'fixed box'})", ch.n_zero),
        ("lowest eigenvalue", f"{eigenvalues[0]:.4g} epsilon / length^2" if len(eigenvalues) else "none"),
    ])
    return 0


def _moduli(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, None)
    if packing.links is not None and (len(packing.links) or packing.attrs.get("shear_stabilized")):
        # a shear-stabilised packing gets the strain compliance of Sec. VI even with no links
        # (the zero-link point of paper Fig. 5)
        return _moduli_linked(args, packing)
    potential = PowerLawPotential(exponent=args.exponent)
    m = elastic_moduli(packing.position, packing.box, packing.diameter, potential)
    pairs, rattler = backbone_pairs(packing.position, packing.box, packing.diameter, potential)
    H = hessian(packing.position, packing.box, packing.diameter, potential, pairs)
    available = max(0, packing.d * int((~rattler).sum()) - packing.d)
    if args.modes > available:
        print(f"jamflow moduli: note: --modes {args.modes}: the {int((~rattler).sum())} non-rattlers have "
              f"{available} non-translational modes; computing those", file=sys.stderr)
    eigenvalues, _ = lowest_modes(H, packing.d, min(args.modes, available), keep=~rattler)
    unit = "epsilon / length^d"
    scalars = {name: ((), value, {"units": "1", "long_name": name.replace("_", " ") + " modulus", "comment": unit})
               for name, value in (("bulk", m.bulk), ("shear", m.shear),
                                   ("bulk_affine", m.bulk_affine), ("shear_affine", m.shear_affine))}
    ds = xr.Dataset(
        data_vars={
            **scalars,
            "pressure": ((), m.pressure, {"units": "1", "long_name": "virial pressure", "comment": unit}),
            "eigenvalue": (("mode",), eigenvalues,
                           {"units": "1", "long_name": "lowest non-translational Hessian eigenvalues (non-rattlers)",
                            "comment": "epsilon / length^2 (unit mass)"}),
        },
        attrs=new_dataset_attrs("jamflow soft-sphere elastic moduli", stage_parameters(args, "input", "out"),
                                d=packing.d, N=packing.n, n_rattlers=m.n_rattlers,
                                protocol=packing.protocol, length_unit=packing.attrs.get("length_unit", "")),
    )
    write_dataset(ds, args.out)
    print_summary(args, args.out, [
        ("bulk modulus B", f"{m.bulk:.6g} (affine {m.bulk_affine:.6g}) {unit}"),
        ("shear modulus G", f"{m.shear:.6g} (affine {m.shear_affine:.6g}) {unit}"),
        ("G / B", f"{m.shear / m.bulk:.4g}" if m.bulk else "undefined (B = 0)"),
        ("pressure", f"{m.pressure:.6g} {unit}"),
        ("rattlers", m.n_rattlers),
        ("lowest eigenvalue", f"{eigenvalues[0]:.4g} epsilon / length^2" if len(eigenvalues) else "none"),
    ])
    return 0
