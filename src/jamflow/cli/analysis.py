"""Analysis subcommands: gaps, forces, overlap, overlap-series, jamming-table, rdf, flow-summary, flow-curve, plot."""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path

import numpy as np

from ..analysis.eos import jamming_table, table_markdown
from ..analysis.fitting import check_window
from ..analysis.flow import flow_curve, flow_summary
from ..analysis.forces import THETA_EXTENDED, THETA_LOCALISED, force_distribution
from ..analysis.gaps import MEAN_FIELD_GAP_EXPONENT, gap_distribution
from ..analysis.overlap import overlap_dataset, overlap_series
from ..analysis.structure import structure_dataset
from ..io import read_dataset, read_packing, write_dataset
from ..io.formats import read_dat
from ..state.packing import Packing
from .common import (
    add_command,
    add_quiet,
    print_summary,
    progress_bar,
    split_paths,
    stage_parameters,
)
from .packings import add_overlap_option, overlap_tol
from .types import (
    MAX_BINS,
    bins,
    integer,
    non_negative,
    non_negative_int,
    path_with_suffix,
    positive,
    resamples,
    seed,
)

#: ``jamflow plot`` kinds and what each takes as input (matplotlib is imported only when plotting).
PLOT_KINDS: dict[str, str] = {
    "packing": "one packing netCDF",
    "gaps": "one or more `jamflow gaps` outputs",
    "forces": "one `jamflow forces` output",
    "fit-windows": "one `jamflow gaps` or `jamflow forces` output (exponent against fit window)",
    "rdf": "one or more `jamflow rdf` outputs",
    "stress-strain": "one or more flow time series or `jamflow flow-summary` outputs",
    "phi-kappa": "one flow time series or `jamflow flow-summary` output",
    "flow-curve": "one `jamflow flow-curve` output (friction and phi against the viscous number)",
    "overlap": "one or more `jamflow overlap-series` outputs (one per sample)",
    "pareto": "one `jamflow tradeoff` output",
    "jamming-table": "one `jamflow jamming-table` output",
    "eos": "one or more LS equation-of-state datasets (`jamflow ls --eos`)",
    "chains-moduli": "one `jamflow chains-moduli` output (moduli against added links per sphere)",
    "phi-asphericity": "one `jamflow shape-survey` output (phi_J against A - 1, VanderWerf et al. Fig. 5)",
    "z-asphericity": "one `jamflow shape-survey` output (<z> against A - 1, VanderWerf et al. Fig. 8)",
    "contact-angles": "one or more `jamflow contact-angles` outputs (P(psi), VanderWerf et al. Fig. 14)",
    "spectra": "one or more `jamflow modes` outputs (sorted eigenvalues, VanderWerf et al. Fig. 7)",
    "quartic-pressure": "`jamflow modes` outputs at several P0 (region-1 eigenvalues and fourth derivatives, "
                        "VanderWerf et al. Figs. 10-11)",
    "mode": "a linked packing and its `jamflow modes` output: one mode as arrows (--mode)",
    "feasible-region": "one `jamflow feasible-region` output (the caged circulo-line, its feasible region and "
                       "their volume and surface against dR, VanderWerf et al. Figs. 12-13)",
}
#: the dataset kinds (jamflow.io.DATASET_KINDS) each figure kind reads
PLOT_INPUT_KINDS: dict[str, tuple[str, ...]] = {
    "packing": ("packing",),
    "gaps": ("gaps",),
    "forces": ("forces",),
    "fit-windows": ("gaps", "forces"),
    "rdf": ("rdf",),
    "stress-strain": ("flow", "flow-summary", "aqs"),
    "phi-kappa": ("flow", "flow-summary", "aqs"),
    "flow-curve": ("flow-curve",),
    "overlap": ("overlap-series",),
    "pareto": ("tradeoff",),
    "jamming-table": ("jamming-table",),
    "eos": ("eos",),
    "chains-moduli": ("chains-moduli-table",),
    "phi-asphericity": ("shape-survey",),
    "z-asphericity": ("shape-survey",),
    "contact-angles": ("contact-angles",),
    "spectra": ("modes",),
    "quartic-pressure": ("modes",),
    "mode": ("packing", "linked-modes"),
    "feasible-region": ("feasible-region",),
}


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "gaps", _gaps, "gap distribution p(h) over samples with a power-law fit",
                    "Gap distribution p(h), h = r/sigma_ij - 1, of non-contact near pairs between stable "
                    "particles (rattlers removed iteratively; --include-rattlers keeps them) on logarithmic bins, "
                    "averaged over samples (one file = one sample). gamma of p(h) ~ h^-gamma by maximum "
                    "likelihood on the pooled gaps in a window chosen inside [fit-min, fit-max] (raised to 1/p "
                    "for LS snapshots, lowered to a power-law break), with a bootstrap statistical error and a "
                    "systematic error from a scan of windows spanning >= 1.5 decades.",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("gaps",)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help="input packings (.nc or .dat), then the output")
    p.add_argument("--max-gap", type=positive, default=0.1, help="largest gap binned (default 0.1)")
    p.add_argument("--min-gap", type=positive, default=1e-13, help="smallest gap binned (default 1e-13)")
    p.add_argument("--bins-per-decade", type=bins, default=5, help="logarithmic bins per decade (default 5)")
    p.add_argument("--fit-min", type=positive, default=1e-5, help="lower end of the scaling range (default 1e-5)")
    p.add_argument("--fit-max", type=positive, default=1e-2, help="upper end of the scaling range (default 1e-2)")
    p.add_argument("--gap-tol", type=non_negative, default=None,
                   help="pairs with h <= GAP_TOL are contacts; default: the packing's own contacts, "
                        "else jamflow.tolerances.CONTACT_GAP_TOL")
    p.add_argument("--include-rattlers", action="store_true",
                   help="keep pairs with a rattler (needed for LS snapshots, which have no contact network)")
    _add_fit_options(p)
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "forces", _forces, "contact-force distribution P(f/<f>), tail exponent, bucklers",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("forces",)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help="packings with forces, then the output")
    p.add_argument("--f-max", type=positive, default=6.0, help="upper end of the bins, in mean forces (default 6)")
    p.add_argument("--linear-bins", type=bins, default=60, help="linear bins on [0, f_max] (default 60)")
    p.add_argument("--log-min", type=positive, default=1e-6, help="lower end of the log bins (default 1e-6)")
    p.add_argument("--bins-per-decade", type=bins, default=5, help="log bins per decade (default 5)")
    p.add_argument("--fit-min", type=positive, default=1e-3,
                   help="lower end of the small-force scaling range (default 1e-3)")
    p.add_argument("--fit-max", type=positive, default=1e-1,
                   help="upper end of the small-force scaling range (default 1e-1)")
    p.add_argument("--all-contacts", action="store_true",
                   help="use every contact, no rattler removal (flowing, hypostatic networks)")
    _add_fit_options(p)
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "overlap", _overlap, "contact-network overlap Q(A, B) = |C_A ∩ C_B| / N_c(B)",
                    reads=("a", "b"), writes=("out",), makes={"out": ("overlap",)})
    p.add_argument("a", help="packing A")
    p.add_argument("b", help="reference packing B")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    p.add_argument("--gap-tol", type=non_negative, default=None,
                   help="contacts from h <= GAP_TOL instead of the stored ones")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "overlap-series", _overlap_series,
                    "Q(p_tar) and |Delta phi_J| of one sample against its largest p_tar",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("overlap-series",)})
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help="jammed packings of one sample, then the output")
    p.add_argument("--p-target", type=positive, nargs="+", required=True,
                   help="target pressure of each input, same order")
    p.add_argument("--gap-tol", type=non_negative, default=None,
                   help="contacts from h <= GAP_TOL instead of the stored ones")
    p.add_argument("--growth-rate", type=positive, default=None,
                   help="LS growth rate kappa of the sample, stored as attribute 'kappa' to group samples in plots")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "jamming-table", _jamming_table,
                    "phi_J^(LS) from the LS equation of state against LS+CALiPPSO phi_J, per kappa (Table I)",
                    "Fits Eq. 15, phi = phi_J (1 - d/p), to each LS run's equation of state on a pressure window and "
                    "compares the extrapolated phi_J^(LS) with the phi_J of the packings CALiPPSO jams from its "
                    "snapshots; sample means and standard errors per growth rate. Prints the table as markdown.",
                    reads=("paths[:-1]", "eos"), writes=("paths[-1]",), makes={"paths[-1]": ("jamming-table",)})
    p.add_argument("paths", nargs="+", metavar="SERIES.nc ... OUT.nc",
                   help="overlap-series outputs (one per sample and kappa, with --growth-rate), then the output")
    p.add_argument("--eos", nargs="+", required=True, help="equation of state of each LS run, same order as the series")
    p.add_argument("--fit-min", type=positive, default=1e5, help="lowest reduced pressure of the fit (default 1e5)")
    p.add_argument("--fit-max", type=positive, default=1e11, help="highest reduced pressure of the fit (default 1e11)")
    add_quiet(p)

    p = add_command(sub, "rdf", _rdf, "radial distribution g(r) and crystallinity (2D psi6, 3D Q6)",
                    reads=("packing",), writes=("out",), makes={"out": ("rdf",)})
    p.add_argument("packing", help="input packing (.nc or .dat)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    p.add_argument("--r-max", type=positive, default=3.0,
                   help="largest r in mean diameters (default 3; clipped, with a note, to below half the smallest "
                        "box width)")
    p.add_argument("--bins", type=bins, default=150, help="number of r bins (default 150)")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "flow-summary", _flow_summary,
                    "stress-strain, friction, steady-state averages, contact lifetimes, event rates of a flow run",
                    reads=("run",), writes=("out",), makes={"out": ("flow-summary",)})
    p.add_argument("run", help="flow time series netCDF")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    p.add_argument("--strain-min", type=non_negative, default=None,
                   help="start of the steady-state window (default: mid run)")
    p.add_argument("--strain-max", type=non_negative, default=None, help="end of the steady-state window (default: end)")
    p.add_argument("--blocks", type=integer(2, MAX_BINS), default=10, help="blocks of the error estimate (default 10)")
    add_quiet(p)

    p = add_command(sub, "flow-curve", _flow_curve,
                    "friction mu and packing fraction phi against the viscous number I over shear runs",
                    "Collects `jamflow flow-summary` outputs of shear runs (one per pressure or density) into "
                    "mu(I), phi(I) with block errors; I = 1 / <p> in the runs' reduced stress unit "
                    "gamma_dot / (xi0 lambda^(d-2)).",
                    reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ("flow-curve",)})
    p.add_argument("paths", nargs="+", metavar="SUMMARY.nc ... OUT.nc", help="flow summaries, then the output")
    p.add_argument("--labels", nargs="+", default=None, help="one label per summary (default run0, run1, ...)")
    add_quiet(p)

    p = add_command(sub, "plot", _plot, "draw a figure (writes OUT.png and OUT.pdf)",
                    "Kinds: " + "; ".join(f"{k}: {v}" for k, v in PLOT_KINDS.items()), reads=("paths[:-1]",), writes=("paths[-1]",), makes={"paths[-1]": ()})
    p.add_argument("kind", choices=sorted(PLOT_KINDS), help="figure kind")
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.png", help="inputs, then the output figure")
    p.add_argument("--labels", nargs="+", default=None, help="legend label per input")
    p.add_argument("--slab-axis", type=non_negative_int, default=2, help="packing, d >= 3: axis normal to the drawn slab (default 2)")
    p.add_argument("--mode", type=non_negative_int, default=None,
                   help="mode: index of the mode (ascending eigenvalue; default the lowest vibration)")
    p.add_argument("--convention", choices=("paper", "once", "twice", "spectral"), default="paper",
                   help="z-asphericity: contacts of <z> (Eq. 3): each family's paper definition (default; Fig. 8: "
                        "N_c = N_c^0 - N_1 for circulo shapes, contacts for the rest), parallel circulo contacts "
                        "once or twice (Fig. 6), or N_c^0 - N_1 for all")
    add_overlap_option(p)
    add_quiet(p)


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bootstrap", type=resamples, default=200,
                   help="bootstrap resamples (packings, then samples within packings) of the statistical error "
                        "(default 200)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the bootstrap (default 0)")


def _exponent_rows(ds, name: str, symbol: str, reference: str) -> list[tuple[str, str]]:
    """Summary rows of a fitted exponent with its errors and window; a refusal or a
    missing error is also warned about on stderr."""
    a = ds.attrs
    value = a[name]
    rows = [(symbol, f"{value:.4f} ± {a[f'{name}_stat']:.4f} (stat) ± {a[f'{name}_sys']:.4f} "
                     f"(sys, {a[f'{name}_n_windows']} windows); {reference}" if np.isfinite(value) else "nan"),
            (f"{symbol} window", f"[{a['fit_min']:.3g}, {a['fit_max']:.3g}] ({a[f'{name}_n_in_window']} samples)")]
    if a[f"{name}_reason"]:
        print(f"jamflow: warning: {symbol}: {a[f'{name}_reason']}", file=sys.stderr)
    return rows


def _break_rows(ds) -> list[tuple[str, str]]:
    a = ds.attrs
    if not a["fit_break_detected"]:
        return []
    return [("power-law break", f"at {a['fit_break_at']:.3g} (z = {a['fit_break_z']:.1f}) inside "
                                f"[{a['fit_scaling_range_min']:.3g}, {a['fit_scaling_range_max']:.3g}]")]


def _load_packing(path: str, tol: float | None) -> Packing:
    if Path(path).suffix == ".dat":
        packing = read_dat(path)
        packing.validate(tol)
        return packing
    return read_packing(path, tol)


def _load_all(paths: list[str], tol: float | None, quiet: bool) -> list[Packing]:
    """The packings of a pooled analysis; two files holding one packing (a copy) are refused."""
    packings = [_load_packing(p, tol) for p in progress_bar(quiet or len(paths) < 2, paths, desc="reading")]
    seen: dict[str, str] = {}
    for path, packing in zip(paths, packings, strict=True):
        digest = hashlib.sha256()
        for array in (packing.position, packing.diameter, packing.box.matrix):
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
        key = digest.hexdigest()
        if key in seen:
            raise ValueError(f"{seen[key]} and {path} hold the same packing (same centres, diameters and box): "
                             "it would be counted twice")
        seen[key] = path
    return packings


def _gaps(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "packing")
    check_window(args.fit_min, args.fit_max, "--fit-min/--fit-max")
    ds = gap_distribution(_load_all(inputs, overlap_tol(args), args.quiet), args.max_gap, args.min_gap,
                          args.bins_per_decade, args.fit_min, args.fit_max, args.gap_tol,
                          stage_parameters(args, "paths") | {"inputs": inputs}, args.include_rattlers,
                          args.bootstrap, args.seed)
    write_dataset(ds, out)
    a = ds.attrs
    print_summary(args, out, [
        ("samples", f"{a['n_samples']} packing(s), {a['n_particles_counted']} particles counted, rattlers "
                    f"{'included' if a['rattlers_included'] else 'excluded'}, {int(ds['count'].sum())} gaps binned"),
        *_exponent_rows(ds, "fit_exponent", "gap exponent gamma", f"mean field {MEAN_FIELD_GAP_EXPONENT}"),
        *_break_rows(ds),
    ])
    return 0


def _forces(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "packing")
    check_window(args.fit_min, args.fit_max, "--fit-min/--fit-max")
    ds = force_distribution(_load_all(inputs, overlap_tol(args), args.quiet), args.f_max, args.linear_bins,
                            args.log_min, args.bins_per_decade, args.fit_min, args.fit_max,
                            not args.all_contacts, stage_parameters(args, "paths") | {"inputs": inputs},
                            args.bootstrap, args.seed)
    write_dataset(ds, out)
    a = ds.attrs
    print_summary(args, out, [
        ("samples, forces", f"{a['n_samples']}, {a['n_forces']} ({a['contacts_used']})"),
        ("buckler fraction", f"{a['buckler_fraction']:.4g}"),
        *_exponent_rows(ds, "fit_exponent", "theta (all)", f"mean field extended {THETA_EXTENDED}"),
        *_exponent_rows(ds, "fit_exponent_buckler", "theta (buckler contacts)", f"localised {THETA_LOCALISED}"),
        *_exponent_rows(ds, "fit_exponent_extended", "theta (extended contacts)", f"mean field {THETA_EXTENDED}"),
        *_break_rows(ds),
    ])
    return 0


def _overlap(args: argparse.Namespace) -> int:
    tol = overlap_tol(args)
    ds = overlap_dataset(_load_packing(args.a, tol), _load_packing(args.b, tol), args.gap_tol,
                         stage_parameters(args, "out"))
    write_dataset(ds, args.out)
    a = ds.attrs
    print_summary(args, args.out, [("Q", f"{a['Q']:.6g} ({a['n_common']} of {a['n_contacts_b']} contacts)"),
                                   ("|Delta phi|", f"{a['abs_delta_phi']:.3g}")])
    return 0


def _overlap_series(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "packing")
    packings = _load_all(inputs, overlap_tol(args), True)
    ds = overlap_series(packings, args.p_target, args.gap_tol,
                        stage_parameters(args, "paths") | {"inputs": inputs}, args.growth_rate)
    write_dataset(ds, out)
    rows = []
    for k in range(ds.sizes["p_target"]):
        r = ds.isel(p_target=k)
        lps = f", LPs = {int(r.n_lp)}" if "n_lp" in r else ""
        rows.append((f"p_tar = {float(r.p_target):g}", f"Q = {float(r.Q):.6g}, phi_J = {float(r.phi_J):.10f}{lps}"))
    print_summary(args, out, rows)
    return 0


def _jamming_table(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "overlap series")
    series = [read_dataset(p, "overlap-series") for p in inputs]
    ds = jamming_table(series, [read_dataset(p, "eos") for p in args.eos], args.fit_min,
                       args.fit_max, stage_parameters(args, "paths") | {"inputs": inputs})
    write_dataset(ds, out)
    print_summary(args, out)
    if not args.quiet:
        print(table_markdown(ds))
    return 0


def _rdf(args: argparse.Namespace) -> int:
    packing = _load_packing(args.packing, overlap_tol(args))
    ds = structure_dataset(packing, args.r_max, args.bins, stage_parameters(args, "out"))
    write_dataset(ds, args.out)
    crystal = [(k, f"{ds.attrs[k]:.4g}") for k in ("psi6_global", "psi6_local_mean", "Q6_global", "q6_local_mean",
                                                    "crystal_fraction") if k in ds.attrs]
    if ds.attrs["r_max_clipped"]:
        print(f"jamflow rdf: note: r_max {args.r_max:g} clipped to {ds.attrs['r_max']:.6g} mean diameters, below half "
              f"the smallest box width of {args.packing} ({ds.sizes['r']} of {args.bins} bins)", file=sys.stderr)
    print_summary(args, args.out, [("g(r)", f"{ds.sizes['r']} bins up to r = {ds.attrs['r_max']:.6g} mean diameters"),
                                   ("packing fraction", f"{ds.attrs['packing_fraction']:.10f}"), *crystal])
    return 0


def _flow_summary(args: argparse.Namespace) -> int:
    ds = flow_summary(read_dataset(args.run, "flow"), args.strain_min, args.strain_max, args.blocks,
                      stage_parameters(args, "out"))
    write_dataset(ds, args.out)
    a = ds.attrs
    print_summary(args, args.out, [
        ("steady window", f"strain {a['window_strain_min']:.6g} .. {a['window_strain_max']:.6g}"),
        *((f"<{q}>", f"{m:.6g} +- {e:.2g}")
          for q, m, e in zip(ds.quantity.values, ds.steady_mean.values, ds.steady_err.values, strict=True)),
        ("friction <sigma>/<p>", f"{a['friction_ratio_of_means']:.6g}"),
        ("contact lifetimes", f"{a['n_lifetimes']} (mean {a['mean_lifetime_strain']:.3g} strain)"),
    ])
    return 0


def _flow_curve(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "flow summary")
    ds = flow_curve([read_dataset(p, "flow-summary") for p in inputs], args.labels, stage_parameters(args, "paths"))
    write_dataset(ds, out)
    print_summary(args, out, [
        (f"{label}: I", f"{i:.4g} +- {di:.2g}   mu {mu:.4f} +- {dmu:.2g}   phi {phi:.5f} +- {dphi:.2g}")
        for label, i, di, mu, dmu, phi, dphi in zip(
            ds.label.values, ds.viscous_number.values, ds.viscous_number_err.values, ds.friction.values,
            ds.friction_err.values, ds.packing_fraction.values, ds.packing_fraction_err.values, strict=True)
    ])
    return 0


def _with_shape_rattlers(packing):
    """A shape packing with its rattlers marked (Sec. III B counting), when its family is counted."""
    from ..models.shapes import shape_family
    from ..shapes.counting import COUNTED_FAMILIES, count_constraints

    if packing.shapes is None or packing.rattler is not None or shape_family(packing.shapes.kind) not in COUNTED_FAMILIES:
        return packing
    return packing.evolve(rattler=count_constraints(packing)[1])


def _plot(args: argparse.Namespace) -> int:
    from .. import plots
    from ..shapes import figures as shape_figures

    inputs, out = split_paths(args.paths, "input", (".png", ".pdf"), distinct=False)
    if args.labels is not None and len(args.labels) != len(inputs):
        raise ValueError(f"--labels needs one label per input ({len(inputs)}), got {len(args.labels)}")
    single = {"packing": None, "forces": plots.plot_forces, "fit-windows": plots.plot_fit_windows,
              "phi-kappa": plots.plot_phi_kappa, "flow-curve": plots.plot_flow_curve,
              "pareto": plots.pareto, "jamming-table": plots.plot_jamming_table,
              "chains-moduli": plots.plot_chains_moduli,
              "phi-asphericity": lambda ds: shape_figures.plot_survey(ds, "phi_J"),
              "z-asphericity": lambda ds: shape_figures.plot_survey(ds, "z", args.convention),
              "feasible-region": shape_figures.plot_feasible_region}
    labelled = {"gaps": plots.plot_gaps, "rdf": plots.plot_rdf, "stress-strain": plots.plot_stress_strain,
                "eos": plots.plot_eos, "contact-angles": shape_figures.plot_contact_angles,
                "spectra": shape_figures.plot_spectra}
    if args.kind in single and len(inputs) != 1:
        raise ValueError(f"plot {args.kind} takes one input, got {len(inputs)}")
    if args.kind == "packing":
        fig = plots.plot_packing(_with_shape_rattlers(_load_packing(inputs[0], overlap_tol(args))), args.slab_axis)
    elif args.kind == "mode":
        from ..chains.figures import plot_mode

        if len(inputs) != 2:
            raise ValueError(f"plot mode takes a packing and its `jamflow modes` output, got {len(inputs)} inputs")
        fig = plot_mode(read_packing(inputs[0], None), read_dataset(inputs[1], "linked-modes"), args.mode)
    else:
        data = [read_dataset(p, PLOT_INPUT_KINDS[args.kind]) for p in inputs]
        if args.kind in single:
            fig = single[args.kind](data[0])
        elif args.kind in labelled:
            fig = labelled[args.kind](data, args.labels)
        elif args.kind == "quartic-pressure":
            fig = shape_figures.plot_quartic_pressure(data)
        else:
            fig = plots.plot_overlap_series(data)
    plots.save_figure(fig, out)
    print_summary(args, f"{out} and {Path(out).with_suffix('.pdf')}")
    return 0
