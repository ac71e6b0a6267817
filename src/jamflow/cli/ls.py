"""Subcommand ``ls``: Lubachevsky–Stillinger compression to one or several pressures."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..io import read_packing, write_dataset, write_packing
from ..protocols.ls import (
    DEFAULT_BETA,
    DEFAULT_FAST_GROWTH_RATE,
    DEFAULT_FAST_UNTIL,
    MAX_PRESSURE,
    compress,
)
from .common import (
    add_command,
    add_preset,
    add_quiet,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .types import (
    count,
    non_negative,
    packing_fraction,
    path_with_suffix,
    positive,
    seed,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "ls", _ls,
        "Lubachevsky-Stillinger compression (event-driven hard spheres with growing diameters)",
        description="Compress a hard-sphere packing by event-driven molecular dynamics with "
                    "diameters growing at rate --growth-rate (CALiPPSO paper Sec. III, App. C): "
                    "first at --fast-growth-rate until p = --fast-until, then at --growth-rate up "
                    "to each --p-target in turn. One sample, several targets: give one output "
                    "file per pressure target, in the order of the targets (OUT1 for P1, OUT2 for "
                    "P2, ...); with --phi-target and no pressure target give one output for the "
                    "state at that packing fraction.",
        reads=("packing",), writes=("out", "eos"), packings=("out",), makes={"eos": ("eos",)},
    )
    p.add_argument("packing", help="input netCDF packing (orthogonal periodic box, no overlaps)")
    p.add_argument("out", nargs="+", type=path_with_suffix(".nc"),
                   help="output netCDF packings: one per --p-target, in the same order "
                        "(or one for --phi-target alone)")
    p.add_argument("--growth-rate", type=positive, required=True,
                   help="slow growth rate kappa of the mean diameter [input length per time unit, "
                        "mass 1, k_B T = 1/beta], e.g. 1e-4")
    p.add_argument("--p-target", type=positive, nargs="+", default=[],
                   help="strictly increasing reduced pressures beta P V / N; a snapshot is written "
                        "when each is first reached")
    p.add_argument("--phi-target", type=packing_fraction, default=None, help="stop at this packing fraction")
    p.add_argument("--max-collisions", type=count, default=None, help="collision budget")
    p.add_argument("--max-time", type=positive, default=None, help="simulated-time budget")
    p.add_argument("--fast-growth-rate", type=non_negative, default=DEFAULT_FAST_GROWTH_RATE,
                   help=f"growth rate of the fast first stage (default {DEFAULT_FAST_GROWTH_RATE:g}; "
                        "0 skips the stage, as the paper does in d >= 4)")
    p.add_argument("--fast-until", type=positive, default=DEFAULT_FAST_UNTIL,
                   help=f"reduced pressure ending the fast stage (default {DEFAULT_FAST_UNTIL:g})")
    p.add_argument("--beta", type=positive, default=DEFAULT_BETA,
                   help=f"inverse temperature set at every velocity rescaling (default {DEFAULT_BETA:g})")
    p.add_argument("--seed", type=seed, default=0, help="seed of the initial velocities (default 0)")
    p.add_argument("--eos", type=path_with_suffix(".nc"), default=None,
                   help="also write the equation of state (p vs phi) as netCDF")
    p.add_argument("--max-pressure", type=positive, default=MAX_PRESSURE,
                   help=f"stop as jammed at this reduced pressure (default {MAX_PRESSURE:g}, where the cages reach "
                        "the float64 resolution); a target beyond it is impossible"),
    add_quiet(p)
    add_preset(p)


#: stop reasons of :func:`jamflow.protocols.ls.compress` that make the remaining targets impossible
IMPOSSIBLE = {
    "max_pressure": "jammed before the target (p reached --max-pressure {max_pressure:g})",
    "box_width": "a contact distance reached half the box width: N = {n} is too few spheres to jam "
                 "in this periodic box (d = {d})",
}


def _ls(args: argparse.Namespace) -> int:
    expected = len(args.p_target) if args.p_target else (1 if args.phi_target is not None else 0)
    if expected == 0:
        raise ValueError("give --p-target P [P ...] (one output each) or --phi-target")
    if len(args.out) != expected:
        raise ValueError(f"{len(args.out)} output file(s) for {expected} target(s): give one output per "
                         "--p-target, in the order of the targets")
    packing = read_packing(args.packing)
    params = stage_parameters(args, "packing", "out", "eos")
    # delay: no bar before a one-line error on bad input
    with progress_bar(args.quiet, desc="LS", unit="coll", unit_scale=True, delay=1.0) as bar:
        def progress(info: dict[str, float]) -> None:
            bar.update(int(info["collisions"]) - bar.n)
            bar.set_postfix(p=f"{info['p']:.3g}", phi=f"{info['phi']:.6f}", refresh=False)

        result = compress(
            packing, args.growth_rate, args.p_target,
            phi_target=args.phi_target, max_collisions=args.max_collisions, max_time=args.max_time,
            beta=args.beta, fast_growth_rate=args.fast_growth_rate or None,
            fast_until=args.fast_until, seed=args.seed, progress=progress, max_pressure=args.max_pressure,
        )
    kind = "p" if args.p_target else "phi"
    snapshots = [s for s in result.snapshots if s.attrs["target_kind"] == kind]
    for snap, path in zip(snapshots, args.out, strict=False):
        write_packing(snap, path, params)
    if args.eos is not None:
        write_dataset(result.eos, args.eos)
    if len(snapshots) < expected:
        missing = args.out[len(snapshots):]
        why = IMPOSSIBLE.get(result.stop_reason)
        if why is None:
            raise RuntimeError(f"stopped by {result.stop_reason} before reaching every target; "
                               f"not written: {', '.join(missing)}")
        reached = str(Path(missing[0]).with_suffix(".reached.nc"))
        write_packing(result.final, reached, params)
        f = result.final
        raise RuntimeError(f"{why.format(n=f.n, d=f.d, max_pressure=args.max_pressure)}: stopped at "
                           f"phi = {f.packing_fraction:.8f}, p = {f.pressure:.4g}; reached state written to {reached}; "
                           f"not written: {', '.join(missing)}")
    print_summary(args, f"{len(snapshots)} snapshot(s) of {args.packing}", [
        *((path, f"p = {snap.pressure:.6g}, phi = {snap.packing_fraction:.10f}, "
                 f"collisions = {snap.attrs['collisions']}") for snap, path in zip(snapshots, args.out, strict=True)),
        ("collisions", f"{result.collisions} ({result.collisions_per_second:.3g} per CPU-second)"),
    ])
    return 0
