"""Profile event-driven simple shear: cProfile of a whole run plus line timings of the step loop.

Shears a start packing for ``--steps`` steps (after a short untimed run that loads the numba
caches) and prints (1) the cProfile table by own time and by cumulative time, (2) with
``line_profiler`` (extra ``bench``) the per-line times of the step, the force refresh, the
network solve and the choice between CG and a factorisation (the CG itself is compiled),
(3) with ``--timers`` instead of both, real time per function from timing wrappers (no
profiler, so compiled kernels and short Python calls keep their weights) and the CG
iterations per solve. Used for docs/notes/overdamped-profile.md.

Usage: python benchmarks/overdamped_profile.py START.nc [--steps 300] [--record-every 1] [--no-lines] [--timers]
"""

from __future__ import annotations

import argparse
import collections
import cProfile
import functools
import io
import pstats
import time

import numpy as np

from jamflow.io import read_packing
from jamflow.protocols.overdamped import integrate, network, recorder, solver
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, run_flow


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("start", help="start packing (netCDF)")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--record-every", type=int, default=1, help="as the CLI's --record-every (default 1)")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--no-lines", action="store_true", help="skip the line-level profile")
    ap.add_argument("--timers", action="store_true", help="real time per function instead of the profilers")
    args = ap.parse_args()
    p = read_packing(args.start)

    def run():
        return run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=args.steps), FlowOptions(),
                        unit="small_diameter", record_every=args.record_every)

    run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=3), FlowOptions(), unit="small_diameter")
    if args.timers:
        timed(run)
        return
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    res = run()
    prof.disable()
    wall = time.perf_counter() - t0
    s = res.series
    n_ev = int(s.sizes["event"])
    print(f"N = {p.n}, phi = {p.packing_fraction:.4f}: {args.steps} steps in {wall:.2f} s (under cProfile), "
          f"{n_ev} events, {args.steps / max(n_ev, 1):.1f} steps/event, strain {float(s.strain.values[-1]):.4g}")
    for key in ("tottime", "cumulative"):
        out = io.StringIO()
        pstats.Stats(prof, stream=out).sort_stats(key).print_stats(args.top)
        print(out.getvalue())
    if args.no_lines:
        return
    from line_profiler import LineProfiler

    lp = LineProfiler()
    targets = [integrate.Integrator.step, integrate.Integrator._refresh, network.solve_network,
               solver.solve_contact_system]
    for f in targets:
        lp.add_function(f)
    lp.runcall(run)
    out = io.StringIO()
    lp.print_stats(stream=out, output_unit=1e-3, stripzeros=True)
    print(out.getvalue())


#: (owner, attribute) of the functions the timers wrap: the step and its parts.
TIMED = [(integrate.Integrator, name) for name in ("step", "_refresh", "_rewire", "dt", "list_horizon", "_move",
                                                    "constraint_error", "correct", "count", "rebuild", "synchronize")]
TIMED += [(integrate, "next_collision"), (integrate, "solve_network"), (network, "solve_contact_system"),
          (solver, "_pcg"), (solver, "_bordered"), (solver, "_factorize"), (solver.FactorCache, "warm_starts"),
          (recorder.Recorder, "record")]


def timed(run) -> None:
    """Run with timing wrappers on ``TIMED``; print real time per function and CG iterations per solve."""
    total, calls, iterations = collections.Counter(), collections.Counter(), []

    def wrap(owner, name):
        f = getattr(owner, name)

        @functools.wraps(f)
        def w(*a, **k):
            t = time.perf_counter()
            try:
                out = f(*a, **k)
            finally:
                total[name] += time.perf_counter() - t
                calls[name] += 1
            if name == "_pcg":
                iterations.append(out[1])
            return out

        setattr(owner, name, w)
        return f

    saved = [(owner, name, wrap(owner, name)) for owner, name in TIMED]
    try:
        t0 = time.perf_counter()
        run()
        wall = time.perf_counter() - t0
    finally:
        for owner, name, f in saved:
            setattr(owner, name, f)
    print(f"{wall:.3f} s in all (timing wrappers add ~0.5 us per call)")
    print(f"{'function':24s} {'calls':>7s} {'total [ms]':>11s} {'share':>6s} {'per call [us]':>14s}")
    for name, t in total.most_common():
        print(f"{name:24s} {calls[name]:7d} {1e3 * t:11.1f} {t / wall:6.1%} {1e6 * t / calls[name]:14.1f}")
    its = np.array(iterations)
    done = its[its >= 0]
    print(f"CG: {len(its)} solves, {np.count_nonzero(its < 0)} fell back to a factorisation; iterations "
          f"{np.bincount(done).tolist()} (count per 0, 1, 2, ...), mean {done.mean():.2f}")


if __name__ == "__main__":
    main()
