"""Soft-sphere jamming onset: time to P0 = 1e-7, and accuracy knobs against time.

Runs (2 cores, single-threaded numba kernels):

1. time to the jamming onset at P0 = 1e-7 for 2D and 3D, N = 1024, 1:1.4 bidisperse;
2. the float64 force-balance floor: FIRE continued on the 2D packing with ever
   smaller tolerances until it stalls;
3. a scan on 2D N = 256 (two seeds) of the final force tolerance and of the FIRE time
   step (dt, dt_max = 10 dt, dt_min = dt / 50) against wall time and the error of
   phi_J relative to the tightest setting on the same input.

Writes ``benchmarks/output/soft_jamming.nc`` and ``soft_jamming.png`` (Pareto plot)
and prints the numbers, times as ratios to the default setting measured in the same
run.

Usage: ``python benchmarks/soft_jamming.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.analysis.contacts import summarize
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.minimize.fire import FireParameters
from jamflow.minimize.onset import FORCE_TOL_VANDERWERF
from jamflow.models.spheres.model import fire
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure

OUT = Path(__file__).resolve().parent / "output"
P0 = 1e-7


def _fire_params(dt: float) -> FireParameters:
    return FireParameters(dt=dt, dt_max=10 * dt, dt_min=dt / 50)


def _run(n: int, d: int, seed: int, force_tol: float, dt: float) -> dict:
    start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=seed)
    t0 = time.perf_counter()
    res = jam_to_pressure(start, P0, force_tol=force_tol, fire_params=_fire_params(dt))
    elapsed = time.perf_counter() - t0
    p = res.packing
    s = summarize(p)
    return {
        "n": n, "d": d, "seed": seed, "force_tol": force_tol, "dt": dt, "time_s": elapsed,
        "phi": p.packing_fraction, "steps": res.steps, "max_force_sq": p.attrs["max_force_sq"],
        "n_contacts": s.n_contacts, "isostatic_count": s.isostatic_count, "converged": res.converged,
        "packing": p,
    }


def _float64_floor(p) -> list[tuple[float, bool, float]]:
    """Continue FIRE with decreasing tolerances; report reached max |F|^2."""
    out = []
    x = p.position
    for tol in (1e-13, 1e-14, 1e-15, 1e-16):
        r = fire(x, p.box, p.diameter, force_tol=tol, max_steps=200_000)
        x = r.position
        out.append((tol, r.converged, r.max_force**2))
        if not r.converged:
            break
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 256 instead of 1024 for the timing runs")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    big = 256 if args.quick else 1024
    default_dt = FireParameters().dt
    for d in (2, 3):
        r = _run(big, d, 0, FORCE_TOL_VANDERWERF, default_dt)
        r["scan"] = "onset"
        rows.append(r)
        print(f"onset d={d} N={big}: {r['time_s']:.1f} s, {r['steps']} FIRE steps, phi_J = {r['phi']:.5f}, "
              f"N_c = {r['n_contacts']} (iso {r['isostatic_count']}), max F^2 = {r['max_force_sq']:.2e}")
        if d == 2:
            floor = _float64_floor(r["packing"])
            for tol, ok, f2 in floor:
                print(f"  float64 floor: force_tol {tol:.0e} -> {'reached' if ok else 'stalled'}, max F^2 = {f2:.2e}")
            floor_f2 = min(f2 for _, _, f2 in floor)
    scan = [(tol, default_dt) for tol in (1e-8, 1e-10, 10**-12.5, FORCE_TOL_VANDERWERF, 10**-13.5)]
    scan += [(FORCE_TOL_VANDERWERF, dt) for dt in (0.01, 0.05)]
    reference = (10**-13.5, default_dt)
    scan_rows = []
    for seed in (0, 1):
        for tol, dt in scan:
            r = _run(256, 2, seed, tol, dt)
            r["scan"] = "knobs"
            scan_rows.append(r)
    ref_phi = {r["seed"]: r["phi"] for r in scan_rows if (r["force_tol"], r["dt"]) == reference}
    default_time = {r["seed"]: r["time_s"] for r in scan_rows
                    if (r["force_tol"], r["dt"]) == (FORCE_TOL_VANDERWERF, default_dt)}
    print("\n2D N=256 scan (phi error vs force_tol = 10^-13.5 on the same input; time / default setting):")
    for r in scan_rows:
        r["phi_error"] = abs(r["phi"] - ref_phi[r["seed"]])
        r["time_ratio"] = r["time_s"] / default_time[r["seed"]]
        print(f"  seed {r['seed']} force_tol {r['force_tol']:.1e} dt {r['dt']:.2f}: time x{r['time_ratio']:.2f} "
              f"({r['time_s']:.1f} s), |dphi_J| = {r['phi_error']:.1e}, steps {r['steps']}, "
              f"N_c - iso = {r['n_contacts'] - r['isostatic_count']}")
    for r in rows:
        r["phi_error"] = np.nan
        r["time_ratio"] = np.nan
    allrows = rows + scan_rows
    keys = ["n", "d", "seed", "force_tol", "dt", "time_s", "time_ratio", "phi", "phi_error", "steps",
            "max_force_sq", "n_contacts", "isostatic_count"]
    units = {"time_s": "s"}
    names = {
        "n": "number of particles", "d": "dimension", "seed": "seed of the RSA start",
        "force_tol": "final max per-particle force tolerance [epsilon / mean diameter]",
        "dt": "FIRE initial time step [mean diameter sqrt(m / epsilon)]", "time_s": "wall time to the onset",
        "time_ratio": "wall time / default setting on the same input", "phi": "packing fraction at P0",
        "phi_error": "|phi_J - phi_J(force_tol = 10^-13.5)| on the same input",
        "steps": "FIRE steps of the whole protocol", "max_force_sq": "final max per-particle |F|^2",
        "n_contacts": "backbone contacts", "isostatic_count": "d (N_s - 1) + 1",
    }
    ds = xr.Dataset(
        {k: ("run", np.array([r[k] for r in allrows]), {"units": units.get(k, "1"), "long_name": names[k]})
         for k in keys},
        coords={"scan": ("run", np.array([r["scan"] for r in allrows]), {"long_name": "benchmark part"})},
        attrs=new_dataset_attrs("soft-sphere jamming benchmark", {"P0": P0, "N_onset": big, "quick": args.quick},
                                float64_floor_max_force_sq=floor_f2, cores=2),
    )
    write_dataset(ds, OUT / "soft_jamming.nc")
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for seed, marker in ((0, "o"), (1, "s")):
        sel = [r for r in scan_rows if r["seed"] == seed and r["phi_error"] > 0]
        for r in sel:
            ax.scatter(r["time_ratio"], r["phi_error"], marker=marker, color="C0" if r["dt"] == default_dt else "C1")
            ax.annotate(f"tol {r['force_tol']:.0e}\ndt {r['dt']}", (r["time_ratio"], r["phi_error"]), fontsize=6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"wall time / default (force_tol {FORCE_TOL_VANDERWERF:.0e}, dt {default_dt})")
    ax.set_ylabel(r"$|\phi_J - \phi_J^{\rm ref}|$")
    ax.set_title("2D N=256, P0=1e-7: accuracy vs time (circles seed 0, squares seed 1)", fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "soft_jamming.png", dpi=150)
    print(f"\nwrote {OUT / 'soft_jamming.nc'} and {OUT / 'soft_jamming.png'}")


if __name__ == "__main__":
    main()
