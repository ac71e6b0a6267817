"""Subcommands of the event-driven overdamped dynamics: shear, compress, drive, and the decompress start."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..io import read_packing, write_dataset, write_packing
from ..protocols.overdamped.driving import Drive, SelfPropulsion
from ..protocols.overdamped.integrate import FlowOptions
from ..protocols.overdamped.run import Stop, dilute_start, run_flow
from ..protocols.overdamped.starts import decompressed, jammed_start
from ..state.packing import LENGTH_UNITS, near_pairs
from ..tolerances import OVERLAP_TOL
from .common import (
    add_command,
    add_preset,
    add_quiet,
    packing_rows,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .packings import add_overlap_option, overlap_tol
from .types import (
    count,
    non_negative_int,
    packing_fraction,
    path_with_suffix,
    positive,
    seed,
)

#: path arguments of the flow runs (the checkpoint is written, and must not be an input)
FLOW_READS = ("input", "composite")
FLOW_WRITES = ("out", "final", "snapshot_file", "checkpoint")
#: the dataset kinds of the non-packing outputs of the flow runs
FLOW_MAKES = {"out": ("flow",), "snapshot_file": ("snapshots",), "checkpoint": ("checkpoint",)}


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "shear", _shear, "event-driven overdamped simple shear (fixed volume or fixed pressure)",
                    "Lerner-During-Wyart event-driven overdamped hard-sphere shear with Lees-Edwards boundaries. "
                    "Physical starts are dense or jammed packings (e.g. from jamflow compress, or with a contact "
                    "network): a start without contacts below 0.9 phi_J (reference phi_J 0.84 in 2D, 0.64 in 3D) "
                    "shears a dilute gas and a warning is printed.",
                    reads=FLOW_READS, writes=FLOW_WRITES, packings=("final",),
                    makes=FLOW_MAKES)
    _io_options(p)
    p.add_argument("--strain", type=positive, required=True,
                   help="total shear strain gamma (> 0)")
    p.add_argument("--pressure", type=positive, default=None,
                   help="shear at this fixed pressure (units gamma_dot xi0^-1 lambda^(2-d)); default fixed volume")
    p.add_argument("--rate", type=positive, default=1.0, help="shear rate gamma_dot (default 1)")
    _common_options(p)

    p = add_command(sub, "compress", _compress, "event-driven overdamped compression (to a packing fraction or jamming)",
                    "Isotropic compression V_aff = -rate R until the target packing fraction or a jammed packing.",
                    reads=FLOW_READS, writes=FLOW_WRITES, packings=("final",),
                    makes=FLOW_MAKES)
    _io_options(p)
    p.add_argument("--phi", type=packing_fraction, default=None,
                   help="stop at this packing fraction (default: run to jamming)")
    p.add_argument("--strain", type=positive, default=10.0, help="give up after this compressive strain rate*t (default 10)")
    p.add_argument("--shear", action="store_true", help="shear while compressing (Sec. IV D: jamming under both)")
    p.add_argument("--rate", type=positive, default=1.0, help="compression rate (default 1)")
    _common_options(p)

    p = add_command(sub, "decompress", _decompress, "dense flow start: a jammed packing decompressed to a packing fraction",
                    "Shrinks every diameter by (phi / phi_J)^(1/d) about fixed centres (jamflow.protocols.overdamped.starts): "
                    "an LS + CALiPPSO (or soft-jammed) packing becomes a start at any phi below its own in one "
                    "step, instead of minutes of event-driven compression. It is a marginally stable state with "
                    "every gap opened by the same relative amount, not a liquid at that phi: discard the initial "
                    "transient of a flow run from it.",
                    reads=("input",), writes=("out",), packings=("out",))
    p.add_argument("input", help="input packing netCDF (jammed: LS + CALiPPSO, or soft-jam with --soft)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output packing netCDF")
    p.add_argument("--phi", type=packing_fraction, required=True, help="target packing fraction, below the input's")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "drive", _drive, "event-driven overdamped dynamics under external or self-propelling forces",
                    reads=(*FLOW_READS, "forces"), writes=FLOW_WRITES, packings=("final",),
                    makes=FLOW_MAKES)
    _io_options(p)
    p.add_argument("--time", type=positive, required=True, help="duration in units of tau = lambda/(f_ext xi0)")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--forces", default=None, help="external forces: .npy file of shape (N, d) [input force units]")
    g.add_argument("--random-forces", type=positive, default=None, metavar="F_EXT",
                   help="constant random forces, components uniform, rms magnitude F_EXT (seeded)")
    g.add_argument("--self-propelled", type=positive, default=None, metavar="F_EXT",
                   help="self-propelled discs (Sec. V B): rms force F_EXT, redrawn after random persistence times")
    p.add_argument("--tau-max", type=positive, default=10.0,
                   help="persistence times uniform in [0, TAU_MAX tau] (default 10)")
    _common_options(p)


def _io_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="input packing netCDF (non-overlapping)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output time-series netCDF (flow schema)")
    p.add_argument("--final", type=path_with_suffix(".nc"), default=None,
                   help="write the last (or jammed) packing with contacts and forces here")
    p.add_argument("--snapshots", type=non_negative_int, default=0, metavar="N",
                   help="number of evenly spaced packing snapshots")
    p.add_argument("--snapshot-file", type=path_with_suffix(".nc"), default=None,
                   help="snapshot netCDF (default OUT with suffix .snapshots.nc)")
    p.add_argument("--checkpoint", type=path_with_suffix(".nc"), default=None,
                   help="checkpoint netCDF: written periodically, resumed from if present (only by the same input "
                        "and trajectory parameters), removed after a complete run")
    p.add_argument("--seed", type=seed, default=0, help="seed of random choices (self-propulsion, random forces)")
    add_overlap_option(p)
    add_quiet(p)
    add_preset(p)


def _common_options(p: argparse.ArgumentParser) -> None:
    d = FlowOptions()
    p.add_argument("--xi0", type=positive, default=1.0, help="mobility xi0 (default 1)")
    p.add_argument("--dt", type=positive, default=d.dt_max, dest="dt_max",
                   help=f"largest integration step in units of 1/rate or tau (default {d.dt_max}; paper 1e-5)")
    p.add_argument("--steps-per-event", type=positive, default=d.steps_per_event,
                   help=f"target steps between events (default {d.steps_per_event:g})")
    p.add_argument("--step-drift", type=positive, default=d.step_drift,
                   help=f"largest relative constraint error created per step (default {d.step_drift:g})")
    p.add_argument("--order", type=count, choices=(1, 2), default=d.order,
                   help=f"1: Euler step (the paper's), 2: explicit midpoint step (default {d.order})")
    p.add_argument("--correct-every", type=non_negative_int, default=d.correct_every, metavar="M",
                   help=f"drift correction every M steps, 0 = only on --drift-tol (default {d.correct_every})")
    p.add_argument("--drift-tol", type=positive, default=d.drift_tol,
                   help=f"constraint error forcing a correction (default {d.drift_tol:g})")
    p.add_argument("--sync-every", type=count, default=d.sync_every,
                   help=f"steps between list rebuilds / checkpoints (default {d.sync_every})")
    p.add_argument("--record-every", type=count, default=1, help="record the time series every K steps (default 1)")
    p.add_argument("--unit", choices=LENGTH_UNITS, default="small_diameter",
                   help="length unit lambda (default small_diameter, as in the paper's shear runs)")
    p.add_argument("--composite", default=None,
                   help="permanent contacts (composite rigid particles, Sec. V C): text file of 'i j' rows")
    p.add_argument("--max-steps", type=count, default=None,
                   help="stop this invocation after this many steps (resume later)")


def _options(args: argparse.Namespace) -> FlowOptions:
    return FlowOptions(dt_max=args.dt_max, steps_per_event=args.steps_per_event, step_drift=args.step_drift,
                       order=args.order, correct_every=args.correct_every, drift_tol=args.drift_tol,
                       sync_every=args.sync_every)


def _permanent(args: argparse.Namespace) -> np.ndarray:
    if args.composite is None:
        return np.zeros((0, 2), np.int64)
    pairs = np.loadtxt(args.composite, dtype=np.int64, ndmin=2)
    if pairs.shape[1] != 2:
        raise ValueError(f"{args.composite}: expected rows 'i j'")
    return np.sort(pairs, axis=1)


def _run(args: argparse.Namespace, drive: Drive, stop: Stop, packing) -> int:
    params = stage_parameters(args)
    bar = None
    progress = None
    if not args.quiet and sys.stderr.isatty():
        bar = progress_bar(args.quiet, total=1000, desc=args.command, unit="‰")

        def progress(frac: float) -> None:
            bar.update(int(frac * 1000) - bar.n)

    try:
        res = run_flow(packing, drive, stop, _options(args), unit=args.unit, record_every=args.record_every,
                       n_snapshots=args.snapshots, checkpoint=args.checkpoint, parameters=params, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    short = _jammed_short(res, drive, stop)
    if short:
        # jammed before the target: the outputs hold a state the target never describes
        out = str(Path(args.out).with_suffix(".reached.nc"))
        write_dataset(res.series, out)
        written = [out]
        if args.final:
            written.append(str(Path(args.final).with_suffix(".reached.nc")))
            write_packing(res.final, written[-1], params)
        if args.checkpoint and Path(args.checkpoint).exists():
            Path(args.checkpoint).unlink()
        raise RuntimeError(f"{short}; reached state written to {', '.join(written)}")
    write_dataset(res.series, args.out)
    if args.final:
        write_packing(res.final, args.final, params)
    if res.snapshots is not None:
        path = args.snapshot_file or str(Path(args.out).with_suffix(".snapshots.nc"))
        write_dataset(res.snapshots, path)
    if res.complete and args.checkpoint and Path(args.checkpoint).exists():
        # the outputs are written: a finished run's checkpoint could only be resumed by mistake
        Path(args.checkpoint).unlink()
    s = res.series
    rows = [("records, events", f"{s.sizes['step']}, {s.sizes['event']}"),
            ("strain", f"{float(s.strain[-1]):.6g}"), ("time", f"{float(s.time[-1]):.6g}"),
            ("packing fraction", f"{float(s.packing_fraction[-1]):.10f}")]
    rows += [(name.replace("_", " "), f"{float(s[name][-1]):.6g}")
             for name in ("pressure", "shear_stress", "n_contacts") if name in s]
    rows += [("jammed, complete", f"{res.jammed}, {res.complete}")]
    print_summary(args, args.out, rows)
    return 0


def _jammed_short(res, drive: Drive, stop: Stop) -> str | None:
    """Why a run that ended jammed missed its target (a packing fraction, or a fixed-volume strain), or None."""
    if not res.jammed:
        return None
    phi = res.final.packing_fraction
    if stop.packing_fraction is not None and phi < stop.packing_fraction * (1 - 1e-12):
        return f"jammed at phi = {phi:.8f} before the target phi {stop.packing_fraction:g}"
    strain = float(res.series.strain[-1])
    if drive.mode == "shear" and stop.strain is not None and strain < stop.strain * (1 - 1e-12):
        return (f"jammed at strain {strain:.6g} before the target strain {stop.strain:g}: hard spheres at fixed "
                "volume cannot flow past this state (shear at fixed pressure, --pressure P)")
    return None


def _shear(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, overlap_tol(args))
    warning = dilute_start(packing)
    if warning:
        print(f"jamflow shear: warning: {warning}", file=sys.stderr)
    mode = "shear" if args.pressure is None else "shear_fixed_pressure"
    drive = Drive(mode, rate=args.rate, xi0=args.xi0, pressure=args.pressure, permanent=_permanent(args))
    jammed = jammed_start(packing, drive)
    if jammed:
        raise ValueError(f"{args.input}: {jammed}")
    return _run(args, drive, Stop(strain=args.strain, max_steps=args.max_steps), packing)


def _compress(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, overlap_tol(args))
    if args.phi is not None and args.phi <= packing.packing_fraction:
        raise ValueError(f"target phi {args.phi} is not above the input's {packing.packing_fraction:.6g}")
    mode = "shear_compress" if args.shear else "compress"
    drive = Drive(mode, rate=args.rate, xi0=args.xi0, permanent=_permanent(args))
    return _run(args, drive, Stop(strain=args.strain, packing_fraction=args.phi, max_steps=args.max_steps), packing)


def _drive(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, overlap_tol(args))
    n, d = packing.n, packing.d
    perm = _permanent(args)
    if args.self_propelled is not None:
        sp = SelfPropulsion.start(n, d, args.self_propelled, args.tau_max, args.xi0, args.seed)
        drive = Drive("self_propelled", xi0=args.xi0, propulsion=sp, permanent=perm)
    else:
        if args.forces is not None:
            F = np.load(args.forces)
            if F.shape != (n, d):
                raise ValueError(f"{args.forces}: forces must have shape ({n}, {d}), got {F.shape}")
        else:
            rng = np.random.Generator(np.random.PCG64(args.seed))
            F = rng.uniform(-1, 1, size=(n, d)) * args.random_forces * np.sqrt(3.0 / d)
        drive = Drive("forces", xi0=args.xi0, external=np.asarray(F, dtype=np.float64), permanent=perm)
    return _run(args, drive, Stop(time=args.time, max_steps=args.max_steps), packing)


#: decompress reports the smallest relative gap r / sigma - 1 if it is below this
_GAP_REPORTED = 0.1


def _decompress(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, overlap_tol(args))
    if packing.attrs.get("boundary") == "walls" or (packing.links is not None and len(packing.links)) \
            or packing.shapes is not None:
        raise ValueError(f"decompress shrinks periodic plain spheres; {args.input} has walls, links or shapes")
    start = decompressed(packing, args.phi)
    # a soft input's overlaps must have been opened by the shrink: the flow stages are hard-sphere
    start.validate(OVERLAP_TOL)
    _, h = near_pairs(start, _GAP_REPORTED)
    write_packing(start, args.out, stage_parameters(args, "out"))
    print_summary(args, args.out, [
        ("decompressed from phi", f"{packing.packing_fraction:.10f}"),
        ("diameter scale", f"{(args.phi / packing.packing_fraction) ** (1.0 / packing.d):.10f}"),
        *packing_rows(start),
        ("smallest relative gap", f"{h.min():.4g}" if h.size else f"above {_GAP_REPORTED}"),
    ])
    return 0
