"""CALiPPSO: time to jam, LP counts, solver strategies, relaxation, tolerances.

Parts (all d = 3 monodisperse unless stated; one run, ratios measured in the same run):

1. ``scaling``: time to jam, number of LPs and median LP time against N from a random
   start (RSA at phi0 = 0.3, N = 256..1024) and from a near-jamming start (the LS
   example tiled 1, 2, 4 times: N = 1024..4096, box 1x1x1 .. 2x2x1), with
   least-squares exponents next to the paper's (total ~ N^3, t_LP ~ N^2.34, n ~ N^1.04).
2. ``ls``: the LS examples of the CALiPPSO authors (N = 1024, d = 3, 4, 5).
3. ``solvers``: ipm (with crossover), dual simplex (warm), hybrid, on one input.
4. ``relax``: LP counts with and without the Sec. IV relaxation c.
5. ``tolerances``: tol_s / tol_gamma sweep: time against max overlap, force-balance
   residual and isostaticity.

Writes ``benchmarks/output/calippso.nc`` and ``calippso.png``; peak memory from
``resource.getrusage``. Run: ``python benchmarks/calippso.py [--quick]``.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.analysis.contacts import force_balance_residual, summarize
from jamflow.box import Box
from jamflow.calippso import calippso
from jamflow.initial import random_packing
from jamflow.io import new_dataset_attrs, read_dat, write_dataset
from jamflow.packing import Packing, max_overlap

OUT = Path(__file__).resolve().parent / "output"
LS = Path(__file__).resolve().parents[2] / "shared" / "data" / "calippso-ls"
if not LS.is_dir():
    LS = Path("/work/shared/data/calippso-ls")


def run(p, **kw) -> dict:
    t0 = time.perf_counter()
    try:
        r = calippso(p, **kw)
    except RuntimeError as exc:
        print("   failed:", str(exc)[:200], flush=True)
        return dict(time=time.perf_counter() - t0, lps=np.nan, t_lp=np.nan, overlap=np.nan, fb=np.nan, iso=0, phi=np.nan)
    t = time.perf_counter() - t0
    q = r.packing
    s = summarize(q)
    fb = float(force_balance_residual(q)[~q.rattler].max())
    out = dict(time=t, lps=r.iterations, t_lp=float(np.median(r.history["lp_time"].values)),
               overlap=max_overlap(q)[1], fb=fb, iso=int(s.isostatic), phi=q.packing_fraction, result=r)
    print(f"   {t:7.2f} s  {r.iterations:3d} LPs  median LP {out['t_lp']:.3f} s  phi_J {out['phi']:.6f}  "
          f"iso {s.isostatic} (Nc {s.n_contacts} vs {s.isostatic_count})  overlap {out['overlap']:.1e}  fb {fb:.1e}", flush=True)
    return out


def tiled_ls(k: int):
    """The d = 3 LS example (N = 1024) repeated k times along x, then y, then z."""
    p = read_dat(LS / "Centers-after-LS--N-1024--d-3.dat")
    reps = [1, 1, 1]
    for i in range(int(np.log2(k))):
        reps[i % 3] *= 2
    shifts = np.stack(np.meshgrid(*[np.arange(r) for r in reps], indexing="ij"), -1).reshape(-1, 3)
    x = (p.position[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
    return Packing(position=x, diameter=np.full(len(x), p.diameter[0]), box=Box.orthogonal(reps), protocol="ls-tiled")


def fit(N, y):
    ok = np.isfinite(y)
    return float(np.polyfit(np.log(N[ok]), np.log(y[ok]), 1)[0]) if ok.sum() >= 2 else np.nan


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small sizes only (a few minutes)")
    args = ap.parse_args()
    sizes = np.array([128, 256] if args.quick else [256, 512, 1024])
    near_sizes = np.array([1024, 2048] if args.quick else [1024, 2048, 4096])
    data = {}
    # 1. scaling: random starts, and near-jamming starts (the LS example tiled)
    rows = {"random": [], "near": []}
    for n in sizes:
        print(f"N = {n} random start phi0 = 0.3", flush=True)
        rows["random"].append(run(random_packing(int(n), 3, 0.3, "mono", seed=1)))
    for n in near_sizes:
        print(f"N = {n} near-jamming start (LS example tiled {n // 1024}x)", flush=True)
        rows["near"].append(run(tiled_ls(int(n) // 1024)))
    for start, rs in rows.items():
        for key in ("time", "lps", "t_lp"):
            data[f"{start}_{key}"] = ((f"N_{start}",), np.array([r[key] for r in rs], float))
    exps = {f"exponent_{s}_{k}": fit(sizes if s == "random" else near_sizes, data[f"{s}_{k}"][1])
            for s in rows for k in ("time", "lps", "t_lp")}
    print("fitted exponents:", {k: round(v, 2) for k, v in exps.items()}, "(paper: time 3, t_LP 2.34, n 1.04)")
    # 2. LS examples
    ds_ls = [3] if args.quick else [3, 4, 5]
    ls = []
    for d in ds_ls:
        print(f"LS example d = {d}", flush=True)
        ls.append(run(read_dat(LS / f"Centers-after-LS--N-1024--d-{d}.dat")))
    for key in ("time", "lps", "t_lp", "overlap", "fb", "iso", "phi"):
        data[f"ls_{key}"] = (("d",), np.array([r[key] for r in ls], float))
    # 3. solvers on the d = 3 LS example (quick: N = 256 random start)
    base = read_dat(LS / "Centers-after-LS--N-1024--d-3.dat") if not args.quick else random_packing(128, 3, 0.3, "mono", seed=1)
    solvers = ["ipm", "simplex", "hybrid", "ipm-center"]
    sol = []
    for s in solvers:
        print(f"solver {s}", flush=True)
        sol.append(run(base, solver=s))
    for key in ("time", "lps", "t_lp", "overlap", "fb", "iso"):
        data[f"solver_{key}"] = (("solver",), np.array([r[key] for r in sol], float))
    # 4. relaxation
    relaxes = [1.0, 0.5]
    rel = []
    for c in relaxes:
        print(f"relax c = {c}", flush=True)
        rel.append(run(random_packing(128 if args.quick else 256, 3, 0.3, "mono", seed=3), relax=None if c == 1.0 else c))
    data["relax_lps"] = (("relax",), np.array([r["lps"] for r in rel], float))
    data["relax_time"] = (("relax",), np.array([r["time"] for r in rel], float))
    # 5. tolerances
    tols = [(1e-6, 1e-9), (1e-7, 1e-10), (1e-9, 1e-12)]
    tol_in = base
    tl = []
    for ts, tg in tols:
        print(f"tol_s {ts:g} tol_gamma {tg:g}", flush=True)
        tl.append(run(tol_in, tol_s=ts, tol_gamma=tg))
    for key in ("time", "lps", "overlap", "fb", "iso"):
        data[f"tol_{key}"] = (("tolerance",), np.array([r[key] for r in tl], float))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0
    ds = xr.Dataset(
        {k: (v[0], v[1], {"long_name": k.replace("_", " ")}) for k, v in data.items()},
        coords={"N_random": sizes, "N_near": near_sizes, "d": ds_ls, "solver": solvers, "relax": relaxes,
                "tol_s": ("tolerance", [t[0] for t in tols]), "tol_gamma": ("tolerance", [t[1] for t in tols])},
        attrs=new_dataset_attrs("CALiPPSO benchmark", {"quick": args.quick}, peak_memory=peak, **exps),
    )
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "calippso.nc")
    fig, ax = plt.subplots(1, 3, figsize=(13, 4))
    for s, m in (("random", "o"), ("near", "s")):
        nn = sizes if s == "random" else near_sizes
        ax[0].loglog(nn, ds[f"{s}_time"], m + "-", label=f"{s}: total")
        ax[0].loglog(nn, ds[f"{s}_t_lp"], m + "--", label=f"{s}: median LP")
    ax[0].set_xlabel("N"); ax[0].set_ylabel("time [s]"); ax[0].legend(fontsize=7)
    ax[1].bar(solvers, ds["solver_time"]); ax[1].set_ylabel("time to jam [s]"); ax[1].set_title("solvers")
    ax[2].loglog(ds["tol_time"], ds["tol_overlap"], "o-", label="max overlap")
    ax[2].loglog(ds["tol_time"], ds["tol_fb"], "s-", label="force-balance residual")
    ax[2].set_xlabel("time [s]"); ax[2].legend(fontsize=7); ax[2].set_title("tol_s / tol_gamma sweep")
    fig.tight_layout()
    fig.savefig(OUT / "calippso.png", dpi=120)
    print(f"peak memory {peak / 2**30:.2f} GiB; wrote {OUT / 'calippso.nc'} and calippso.png")


if __name__ == "__main__":
    main()
