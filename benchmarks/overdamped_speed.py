"""Speed and accuracy of the event-driven overdamped dynamics.

1. Events per second and strain per minute of simple shear for 2D bidisperse discs
   (1 : 1.4, 3 % polydisperse) at phi = 0.80 and 0.83, N = 64, 256, 1024, with a fitted
   power law in N (start configurations from the event-driven compression itself).
2. The trade of the step accuracy (``step_drift``, which sets dt) and the correction
   frequency against constraint drift and stress error, measured against the tightest
   setting from the same start (N = 64, phi = 0.80).

Writes benchmarks/output/overdamped_speed.nc and .png and prints the numbers.
Usage: python benchmarks/overdamped_speed.py [--sizes 64 256 1024] [--budget 60]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import xarray as xr

from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.protocols.initial import random_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, run_flow
from jamflow.state.packing import Packing

OUT = Path(__file__).resolve().parent / "output"
PREP = FlowOptions(dt_max=1e-2, step_drift=1e-6, drift_tol=1e-5)


def prepare(n: int, phis: list[float], seed: int = 1) -> tuple[dict[float, Packing], float]:
    """Compress one RSA start through the packing fractions in turn (another seed if it jams)."""
    for s in range(seed, seed + 10):
        p = random_packing(n, 2, 0.5, "bi", seed=s)
        rng = np.random.default_rng(s)
        p = p.evolve(diameter=p.diameter * (1 - 0.03 * rng.uniform(size=p.n)))
        t0 = time.perf_counter()
        out = {}
        for phi in sorted(phis):
            res = run_flow(p, Drive("compress"), Stop(packing_fraction=phi), PREP, unit="small_diameter",
                           record_every=10_000)
            if res.jammed:
                break
            p = out[phi] = res.final
        else:
            return out, time.perf_counter() - t0
    raise RuntimeError(f"N={n}: every seed jammed below phi={max(phis)}")


def shear_speed(p: Packing, budget: float, options: FlowOptions = FlowOptions()) -> dict[str, float]:
    """Shear in chunks until ``budget`` seconds are spent; events/s and strain/min."""
    t0 = time.perf_counter()
    res = run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=200), options, unit="small_diameter",
                   record_every=1000)
    steps_per_s = 200 / (time.perf_counter() - t0)
    # choose the number of steps that fits the budget, then measure one run
    n_steps = max(200, int(steps_per_s * budget))
    t0 = time.perf_counter()
    res = run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=n_steps), options, unit="small_diameter",
                   record_every=1000)
    wall = time.perf_counter() - t0
    s = res.series
    strain = float(s.strain.values[-1])
    return {"wall": wall, "events_per_s": s.sizes["event"] / wall, "strain_per_min": 60 * strain / wall,
            "steps_per_s": n_steps / wall, "strain": strain, "events": s.sizes["event"]}


def accuracy_trade(p: Packing, strain: float) -> list[dict[str, float]]:
    ref_opts = FlowOptions(step_drift=1e-11, correct_every=10, drift_tol=1e-9)
    t0 = time.perf_counter()
    ref = run_flow(p, Drive("shear"), Stop(strain=strain), ref_opts, unit="small_diameter").series
    t_ref = time.perf_counter() - t0
    grid = np.linspace(0, strain, 401)[1:-1]

    def at(ds):
        idx = np.searchsorted(ds.strain.values, grid, side="right") - 1
        return ds.shear_stress.values[idx]

    s_ref = at(ref)
    rows = []
    for step_drift in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10):
        for correct_every in (10, 100, 1000):
            opts = FlowOptions(step_drift=step_drift, correct_every=correct_every, drift_tol=1e-3)
            t0 = time.perf_counter()
            ds = run_flow(p, Drive("shear"), Stop(strain=strain), opts, unit="small_diameter").series
            wall = time.perf_counter() - t0
            err = np.abs(at(ds) - s_ref) / np.abs(s_ref)
            rows.append({"step_drift": step_drift, "correct_every": correct_every, "wall": wall,
                         "time_ratio": wall / t_ref, "max_constraint_error": float(ds.constraint_error.max()),
                         "median_stress_error": float(np.median(err)), "p90_stress_error": float(np.quantile(err, 0.9))})
            r = rows[-1]
            print(f"  step_drift={step_drift:.0e} correct_every={correct_every:5d}: time/ref {r['time_ratio']:.3f}, "
                  f"max drift {r['max_constraint_error']:.2e}, stress error median {r['median_stress_error']:.2e} "
                  f"p90 {r['p90_stress_error']:.2e}")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 1024])
    ap.add_argument("--phis", type=float, nargs="+", default=[0.80, 0.83])
    ap.add_argument("--budget", type=float, default=30.0, help="seconds of shear per (N, phi)")
    ap.add_argument("--trade-strain", type=float, default=0.05)
    args = ap.parse_args()
    OUT.mkdir(exist_ok=True)
    speed = {}
    for n in args.sizes:
        starts, t_prep = prepare(n, args.phis)
        for phi in args.phis:
            r = shear_speed(starts[phi], args.budget)
            r["prep_time"] = t_prep
            speed[(n, phi)] = r
            print(f"N={n:5d} phi={phi:.2f}: prep {t_prep:7.1f} s; {r['events_per_s']:8.1f} events/s, "
                  f"{r['strain_per_min']:.4g} strain/min, {r['steps_per_s']:.0f} steps/s "
                  f"({r['events']} events over strain {r['strain']:.3g})")
    fits = {}
    for phi in args.phis:
        ns = np.array(args.sizes, float)
        for key in ("events_per_s", "strain_per_min", "steps_per_s"):
            vals = np.array([speed[(n, phi)][key] for n in args.sizes])
            if len(ns) > 1 and np.all(vals > 0):
                fits[(phi, key)] = float(np.polyfit(np.log(ns), np.log(vals), 1)[0])
                print(f"phi={phi:.2f}: {key} ~ N^{fits[(phi, key)]:.2f}")
    print("accuracy trade (N=64, phi=0.80), errors against step_drift=1e-11, correction every 10 steps:")
    p64, _ = prepare(64, [0.80])
    trade = accuracy_trade(p64[0.80], args.trade_strain)

    ds = xr.Dataset(
        {k: (("phi", "N"), np.array([[speed[(n, phi)][k] for n in args.sizes] for phi in args.phis]),
             {"units": "1", "long_name": k.replace("_", " ")})
         for k in ("events_per_s", "strain_per_min", "steps_per_s", "prep_time")}
        | {f"trade_{k}": (("setting",), np.array([r[k] for r in trade]), {"units": "1", "long_name": k.replace("_", " ")})
           for k in trade[0]},
        coords={"phi": args.phis, "N": args.sizes},
        attrs=new_dataset_attrs("overdamped speed and accuracy", vars(args),
                                **{f"exponent_{k}_phi{phi}": v for (phi, k), v in fits.items()}))
    write_dataset(ds, OUT / "overdamped_speed.nc")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.5))
    for phi in args.phis:
        a.loglog(args.sizes, [speed[(n, phi)]["events_per_s"] for n in args.sizes], "o-", label=f"events/s φ={phi}")
        a.loglog(args.sizes, [speed[(n, phi)]["strain_per_min"] for n in args.sizes], "s--", label=f"strain/min φ={phi}")
    a.set_xlabel("N")
    a.legend(fontsize=7)
    for ce in (10, 100, 1000):
        sel = [r for r in trade if r["correct_every"] == ce]
        b.loglog([r["time_ratio"] for r in sel], [r["median_stress_error"] for r in sel], "o-", label=f"correct every {ce}")
    b.set_xlabel("time / reference time")
    b.set_ylabel("median relative stress error")
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "overdamped_speed.png", dpi=150)


if __name__ == "__main__":
    main()
