"""Steps per event against stress error: the dt rule of Sec. IV A measured on the trade-off start.

The step is ``min(dt_max, event_interval / steps_per_event, sqrt(2 step_drift) / max|W|)``.
From the start of the trade-off harness's overdamped stage (:func:`jamflow.tradeoff.flow_start`,
2D 1:1.4 bidisperse discs at phi = 0.80) this shears with the harness's tight reference
(``step_drift = 1e-11``, correction every 10 steps, order 1) and with a grid of ``order`` (1: the
paper's straight-line step, 2: explicit midpoint), ``steps_per_event`` and ``step_drift``, and prints per setting the wall time, steps per event and the harness's errors
(:func:`jamflow.tradeoff._flow_compare`: median and largest stress error relative to the mean
|stress|, event-sequence disagreement).

Usage: python benchmarks/overdamped_steps.py [--n 64] [--strain 0.01]
"""

from __future__ import annotations

import argparse
import itertools
import time

from jamflow.overdamped.driving import Drive
from jamflow.overdamped.integrate import FlowOptions
from jamflow.overdamped.run import Stop, run_flow
from jamflow.tradeoff import FLOW_PHI, _flow_compare, flow_start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--strain", type=float, default=0.01)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps-per-event", type=float, nargs="+", default=[10.0, 5.0, 3.0, 2.0, 1.0])
    ap.add_argument("--step-drift", type=float, nargs="+", default=[1e-9, 1e-8, 1e-7])
    ap.add_argument("--orders", type=int, nargs="+", default=[1, 2], help="FlowOptions.order values")
    args = ap.parse_args()
    start = flow_start(args.n, FLOW_PHI, args.seed)

    def run(opts):
        t0 = time.perf_counter()
        res = run_flow(start, Drive("shear"), Stop(strain=args.strain), opts, unit="small_diameter")
        return res, time.perf_counter() - t0

    run_flow(start, Drive("shear"), Stop(strain=10.0, max_steps=3), FlowOptions(), unit="small_diameter")
    ref, t_ref = run(FlowOptions(step_drift=1e-11, correct_every=10, drift_tol=1e-9))
    n_ref = int(ref.series.sizes["event"])
    print(f"N = {args.n}, phi = {FLOW_PHI}, strain {args.strain}: reference {t_ref:.1f} s, {n_ref} events")
    for order, sd, spe in itertools.product(args.orders, args.step_drift, args.steps_per_event):
        res, wall = run(FlowOptions(step_drift=sd, steps_per_event=spe, order=order))
        m = _flow_compare(res, ref)
        steps = int(res.series.attrs["n_steps"])
        n_ev = int(res.series.sizes["event"])
        st = f"{steps / max(n_ev, 1):.1f}"
        print(f"order {order} step_drift {sd:.0e} steps_per_event {spe:4.1f}: {wall:6.2f} s ({wall / t_ref:.3f} of ref), "
              f"{n_ev} events, {st} steps/event; stress error median {m['error']:.2e} max "
              f"{m['max_stress_error']:.2e}; event disagreement {m['event_disagreement']:.3f}", flush=True)


if __name__ == "__main__":
    main()
