"""Stress error against step size and step order of the event-driven shear (Sec. IV A dt rule).

The step is ``min(dt_max, event_interval / steps_per_event, sqrt(2 step_drift) / max|W|)``.
From a start (default: the trade-off harness's, :func:`jamflow.tradeoff.flow_start`, 2D 1:1.4
bidisperse discs at phi = 0.80; or ``--start FILE.nc``) this shears with a tight reference
(``step_drift = 1e-11``, ``steps_per_event = --ref-steps-per-event``, correction every 10 steps,
order 1) and with a grid of ``order`` (1: the paper's straight-line step, 2: explicit midpoint),
``steps_per_event`` and ``step_drift``. Per setting it prints the wall time, steps per event, the
harness's errors (:func:`jamflow.tradeoff.stages._flow_compare`: the recorded stress compared as a step
function, i.e. the value of the last step before each of 399 grid strains) and the same median
error with the stress interpolated linearly between steps (the stress is continuous between
events), both relative to the reference's mean |stress|.

Usage: python benchmarks/overdamped_steps.py [--n 64] [--strain 0.01] [--start FILE.nc]
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

from jamflow.io import read_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, run_flow
from jamflow.tradeoff import FLOW_PHI, flow_start
from jamflow.tradeoff.stages import _flow_compare


def interpolated_error(series, ref) -> tuple[float, float]:
    """Median and 90th percentile of |sigma - sigma_ref| / <|sigma_ref|>, both interpolated linearly."""
    grid = np.linspace(0.0, float(ref.strain.values[-1]), 401)[1:-1]
    s = np.interp(grid, series.strain.values, series.shear_stress.values)
    s_ref = np.interp(grid, ref.strain.values, ref.shear_stress.values)
    err = np.abs(s - s_ref) / float(np.mean(np.abs(ref.shear_stress.values)))
    return float(np.median(err)), float(np.quantile(err, 0.9))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--start", help="start packing (netCDF) instead of flow_start(N, 0.80)")
    ap.add_argument("--strain", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps-per-event", type=float, nargs="+", default=[10.0, 3.0, 1.0])
    ap.add_argument("--step-drift", type=float, nargs="+", default=[1e-9, 1e-8, 1e-7])
    ap.add_argument("--orders", type=int, nargs="+", default=[1, 2], help="FlowOptions.order values")
    ap.add_argument("--ref-steps-per-event", type=float, default=10.0)
    args = ap.parse_args()
    start = read_packing(args.start) if args.start else flow_start(args.n, FLOW_PHI, args.seed)

    def run(opts):
        t0 = time.perf_counter()
        res = run_flow(start, Drive("shear"), Stop(strain=args.strain), opts, unit="small_diameter")
        return res, time.perf_counter() - t0

    run_flow(start, Drive("shear"), Stop(strain=10.0, max_steps=3), FlowOptions(), unit="small_diameter")
    ref, t_ref = run(FlowOptions(step_drift=1e-11, steps_per_event=args.ref_steps_per_event, correct_every=10,
                                 drift_tol=1e-9))
    n_ref = int(ref.series.sizes["event"])
    print(f"N = {start.n}, phi = {start.packing_fraction:.4f}, strain {args.strain}: reference {t_ref:.1f} s, "
          f"{n_ref} events, {int(ref.series.attrs['n_steps'])} steps", flush=True)
    for order, sd, spe in itertools.product(args.orders, args.step_drift, args.steps_per_event):
        res, wall = run(FlowOptions(step_drift=sd, steps_per_event=spe, order=order))
        m = _flow_compare(res, ref)
        med, p90 = interpolated_error(res.series, ref.series)
        steps = int(res.series.attrs["n_steps"])
        n_ev = int(res.series.sizes["event"])
        print(f"order {order} step_drift {sd:.0e} steps_per_event {spe:4.1f}: {wall:6.2f} s ({wall / t_ref:.3f} of ref), "
              f"{n_ev} events, {steps / max(n_ev, 1):.1f} steps/event; harness error median {m['error']:.2e} "
              f"max {m['max_stress_error']:.2e}; interpolated median {med:.2e} p90 {p90:.2e}; "
              f"event disagreement {m['event_disagreement']:.3f}", flush=True)


if __name__ == "__main__":
    main()
