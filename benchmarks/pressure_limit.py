"""Largest LS target pressure from which CALiPPSO still returns an isostatic packing.

One sample per system is compressed by LS (fast stage to p = 500, then kappa = 1e-3)
towards p_tar = 1e12 ... 1e16 in one run, within a collision budget; CALiPPSO (default
settings) jams every snapshot reached. Records p reached, LPs, isostaticity, max overlap
and phi_J - phi(snapshot).

    python benchmarks/pressure_limit.py [--budget 30000000]

Writes benchmarks/output/pressure_limit.nc and pressure_limit.png.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from jamflow.analysis.contacts import summarize
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.plots import save_figure
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import compress
from jamflow.state.packing import max_overlap

OUT = Path(__file__).parent / "output"
TARGETS = [1e12, 1e13, 1e14, 1e15, 1e16]
SYSTEMS = {"2D bi N=64": (2, 64, "bi"), "3D mono N=128": (3, 128, "mono")}


def run(name: str, budget: int) -> dict[str, np.ndarray]:
    d, n, dispersity = SYSTEMS[name]
    start = random_packing(n, d, 0.2, dispersity=dispersity, seed=5)
    res = compress(start, 1e-3, TARGETS, fast_growth_rate=5e-3, seed=5, max_collisions=budget,
                   max_pressure=None)
    rows = {k: np.full(len(TARGETS), np.nan) for k in ("p", "n_lp", "isostatic", "max_overlap", "dphi", "time")}
    for k, snap in enumerate(res.snapshots):
        t0 = time.perf_counter()
        out = calippso(snap)
        summary = summarize(out.packing)
        rows["p"][k] = snap.pressure
        rows["n_lp"][k] = out.iterations
        rows["isostatic"][k] = float(summary.isostatic)
        rows["max_overlap"][k] = max_overlap(out.packing)[1]
        rows["dphi"][k] = out.packing.packing_fraction - snap.packing_fraction
        rows["time"][k] = time.perf_counter() - t0
        print(f"{name} p_tar {TARGETS[k]:.0e}: p = {snap.pressure:.3g}, {out.iterations} LPs, "
              f"isostatic {summary.isostatic}, overlap {rows['max_overlap'][k]:.1e}, dphi {rows['dphi'][k]:.2e}")
    print(f"{name}: LS stopped by {res.stop_reason} after {res.collisions} collisions")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=30_000_000, help="LS collision budget per system")
    args = parser.parse_args()
    results = {name: run(name, args.budget) for name in SYSTEMS}
    names = list(results)
    one = {"units": "1"}
    data = {k: (("system", "p_target"), np.array([results[s][k] for s in names]), {**one, "long_name": k})
            for k in results[names[0]]}
    ds = xr.Dataset(data, coords={"system": names, "p_target": TARGETS},
                    attrs=new_dataset_attrs("CALiPPSO from LS snapshots at extreme pressure", vars(args)))
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "pressure_limit.nc")
    fig = Figure(layout="constrained", figsize=(6.4, 4.4))
    ax = fig.add_subplot()
    for s in names:
        ax.loglog(ds["p"].sel(system=s), ds["max_overlap"].sel(system=s), "o-", label=f"{s}: max overlap")
    ax.axhline(1e-8, color="k", ls=":", label="OVERLAP_TOL")
    ax.set_xlabel("LS pressure of the snapshot (dimensionless)")
    ax.set_ylabel("max relative overlap after CALiPPSO (dimensionless)")
    ax.legend(fontsize=8)
    save_figure(fig, OUT / "pressure_limit.png")


if __name__ == "__main__":
    main()
