"""Linked packings: jamming time against spheres, where the time goes, Hessian and compliance time against N.

Runs (2 shared cores; times are wall times of one process and only their ratios,
measured side by side in this run, mean anything):

1. jamming to P0 of 2D rigid trimers (fixed box and shear-stabilised) and of the
   sphere packing of the same N and packing-fraction start (compiled sphere FIRE);
   3D chains of 4 spheres with frozen angles likewise;
2. a profile of the linked runs: the share of wall time in projection, Newton
   re-affixing, energy evaluation (pair forces) and neighbour-list builds;
3. the constrained Hessian (dense) and the compliance against N, with the fitted
   exponent of time ~ N^a.

Writes ``benchmarks/output/chains.nc`` and ``chains.png`` and prints the numbers.

Usage: ``python benchmarks/chains.py [--sizes 2:150 3:256 ...] [--hessian-sizes 30 60 120]
[--pressure 1e-4] [--pressure-rtol 1e-3]``; defaults are small (the issue's N = 600
and N = 1024 are ``--sizes 2:600 3:1024``, hours in the pure-Python constrained FIRE).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import time
from pathlib import Path

# one BLAS thread: dense eigensolvers on 2 shared cores otherwise spin against other jobs
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.chains.builders import linked_packing
from jamflow.chains.compliance import compliance
from jamflow.chains.hessian import constrained_hessian
from jamflow.chains.jamming import jam_linked
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.soft.jamming import JammingSettings, jam_to_pressure
from jamflow.tolerances import LINK_LENGTH_RTOL

OUT = Path(__file__).resolve().parent / "output"

#: Function names (cProfile) whose cumulative time is reported, by what they do.
PROFILE_PARTS = {
    "projection": ("project",),
    "re-affixing": ("reproject",),
    "energy": ("evaluate",),
    "neighbour list": ("build",),
}


def _start(d: int, n: int, seed: int):
    if d == 2:
        return linked_packing(2, n // 3, "trimer", np.random.default_rng(seed))[0]
    return linked_packing(3, n // 4, "chain", np.random.default_rng(seed), chain_length=4, phi=0.6)[0]


def _profiled(func):
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    out = func()
    prof.disable()
    total = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats
    parts = {}
    for name, keys in PROFILE_PARTS.items():
        cum = [v[3] for (file, _, fn), v in stats.items() if fn in keys and "jamflow" in file]
        parts[name] = max(cum, default=0.0)
    return out, total, parts


def jamming_runs(sizes: list[tuple[int, int]], pressure: float, rtol: float, seed: int) -> list[dict]:
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=rtol, delta_phi=1e-2)
    rows = []
    for d, n in sizes:
        start = _start(d, n, seed)
        t0 = time.perf_counter()
        sphere = jam_to_pressure(start.evolve(links=None), pressure, force_tol=1e-12, pressure_rtol=rtol,
                                 delta_phi=1e-2)
        t_sphere = time.perf_counter() - t0
        for stabilize in (False, True):
            res, total, parts = _profiled(lambda s=start, k=stabilize: jam_linked(s, pressure, settings=settings,
                                                                                  shear_stabilize=k))
            p = res.packing
            rows.append({"d": d, "n": start.n, "shear": int(stabilize), "time_s": total, "sphere_time_s": t_sphere,
                         "ratio": total / t_sphere, "steps": res.steps, "phi": p.packing_fraction,
                         "sphere_phi": sphere.packing.packing_fraction, "n_contacts": p.attrs["n_contacts"],
                         "isostatic_count": p.attrs["isostatic_count"], "max_link_error": p.attrs["max_link_error"],
                         **{f"share_{k.replace(' ', '_').replace('-', '_')}": v / total for k, v in parts.items()}})
            r = rows[-1]
            print(f"d={d} N={start.n} {'shear-stabilised' if stabilize else 'fixed box'}: {total:.1f} s "
                  f"({r['ratio']:.1f} x spheres {t_sphere:.2f} s), {res.steps} FIRE steps, phi {r['phi']:.5f} "
                  f"(spheres {r['sphere_phi']:.5f}), N_c {r['n_contacts']} / iso {r['isostatic_count']}, "
                  f"link error {r['max_link_error']:.1e} (<= {LINK_LENGTH_RTOL:g}); shares "
                  + ", ".join(f"{k} {v / total:.0%}" for k, v in parts.items()))
    return rows


def hessian_runs(sizes: list[int], pressure: float, seed: int) -> list[dict]:
    settings = JammingSettings(force_tol=1e-11, pressure_rtol=1e-2, delta_phi=1e-2)
    rows = []
    for n in sizes:
        p = jam_linked(_start(2, n, seed), pressure, settings=settings, shear_stabilize=True).packing
        t0 = time.perf_counter()
        constrained_hessian(p, strain=True)
        t_h = time.perf_counter() - t0
        t0 = time.perf_counter()
        compliance(p)
        t_c = time.perf_counter() - t0
        rows.append({"n": p.n, "hessian_s": t_h, "compliance_s": t_c})
        print(f"2D trimers N={p.n}: constrained Hessian {t_h:.3f} s, compliance {t_c:.3f} s (dense)")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", default=["2:150"], help="d:N pairs of the jamming runs")
    ap.add_argument("--hessian-sizes", nargs="+", type=int, default=[30, 60, 120, 240])
    ap.add_argument("--pressure", type=float, default=1e-4)
    ap.add_argument("--pressure-rtol", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    sizes = [tuple(int(v) for v in s.split(":")) for s in args.sizes]
    jam = jamming_runs(sizes, args.pressure, args.pressure_rtol, args.seed)
    hess = hessian_runs(args.hessian_sizes, args.pressure, args.seed)
    n = np.array([r["n"] for r in hess], float)
    fits = {}
    for key in ("hessian_s", "compliance_s"):
        t = np.array([r[key] for r in hess])
        fits[key] = float(np.polyfit(np.log(n), np.log(t), 1)[0]) if len(n) > 1 else float("nan")
        print(f"{key.split('_')[0]} time ~ N^{fits[key]:.2f}")
    ds = xr.Dataset(
        {**{k: (("run",), [r[k] for r in jam], {"units": "1", "long_name": k.replace("_", " ")}) for k in jam[0]},
         **{k: (("size",), [r[k] for r in hess], {"units": "1", "long_name": k.replace("_", " ")}) for k in hess[0]}},
        attrs=new_dataset_attrs("jamflow chains benchmark", vars(args), hessian_exponent=fits["hessian_s"],
                                compliance_exponent=fits["compliance_s"],
                                note="wall times on 2 shared cores; compare ratios within this run"),
    )
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "chains.nc")
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.6))
    labels = [f"d={r['d']} N={r['n']}\n{'shear' if r['shear'] else 'fixed'}" for r in jam]
    a.bar(range(len(jam)), [r["ratio"] for r in jam])
    a.set_xticks(range(len(jam)), labels, fontsize=7)
    a.set_xlabel("linked packing (d, N spheres, box)")
    a.set_ylabel("jamming time / sphere jamming time (1)")
    b.loglog(n, [r["hessian_s"] for r in hess], "o-", label=f"constrained Hessian, N^{fits['hessian_s']:.2f}")
    b.loglog(n, [r["compliance_s"] for r in hess], "s-", label=f"compliance, N^{fits['compliance_s']:.2f}")
    b.set_xlabel("N (spheres)")
    b.set_ylabel("wall time (s)")
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "chains.png", dpi=120)
    print(f"wrote {OUT / 'chains.nc'} and {OUT / 'chains.png'}")


if __name__ == "__main__":
    main()
