"""Profile event-driven simple shear: cProfile of a whole run plus line timings of the step loop.

Shears a start packing for ``--steps`` steps (after a short untimed run that loads the numba
caches) and prints (1) the cProfile table by own time and by cumulative time, (2) with
``line_profiler`` (extra ``bench``) the per-line times of the step, the force refresh, the
network solve and the choice between CG and a factorisation (the CG itself is compiled).
Used for docs/overdamped-profile.md.

Usage: python benchmarks/overdamped_profile.py START.nc [--steps 300] [--record-every 1] [--no-lines]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

from jamflow.io import read_packing
from jamflow.overdamped import integrate, network, solver
from jamflow.overdamped.driving import Drive
from jamflow.overdamped.integrate import FlowOptions
from jamflow.overdamped.run import Stop, run_flow


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("start", help="start packing (netCDF)")
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--record-every", type=int, default=1, help="as the CLI's --record-every (default 1)")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--no-lines", action="store_true", help="skip the line-level profile")
    args = ap.parse_args()
    p = read_packing(args.start)

    def run():
        return run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=args.steps), FlowOptions(),
                        unit="small_diameter", record_every=args.record_every)

    run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=3), FlowOptions(), unit="small_diameter")
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


if __name__ == "__main__":
    main()
