"""CALiPPSO's tail: how the LP count of one near-jamming start spreads under tiny perturbations.

A near start (LS to p = 1e7 at kappa = 1e-3, ``calippso.near_start``) is jammed as it is and with every
position moved by a Gaussian of ``--eps`` mean diameters (seeds 1 .. ``--perturbations``),
by each ``--engines`` warm engine, in-process. Per chain: LPs, simplex pivots, CPU
time, phi_J, contacts against the isostatic count, the largest overlap, and the two
tail relations of ``docs/notes/warm-simplex.md`` ("The wandering tail"): the median of
``(sqrt(Gamma*_{k+1}) - 1) / s_k^2`` and of ``s_k / sqrt(Gamma*_k - 1)`` (``s`` = largest
stable displacement, mean diameters). A rule meant to shorten the tail is judged
against this spread, not against one chain.

Writes ``benchmarks/output/calippso_tail.nc`` and ``calippso_tail.png``.
Run: ``python benchmarks/calippso_tail.py [--quick] [--n 2048] [--seed 2] [--perturbations 8]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.protocols.calippso import WARM_ENGINES, calippso
from jamflow.state.packing import Packing, max_overlap

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calippso import FAST_KAPPA, OUT, near_start

#: per-chain measures: name -> (units, long name)
MEASURES = {
    "lps": ("1", "LPs of the chain"),
    "pivots": ("1", "simplex pivots of the chain"),
    "cpu_time": ("s", "CPU time of calippso (in-process)"),
    "phi_J": ("1", "packing fraction of the jammed packing"),
    "n_contacts": ("1", "contacts between stable particles"),
    "isostatic_count": ("1", "isostatic count of the stable particles"),
    "max_overlap": ("1", "largest relative overlap over all pairs"),
    "growth_per_move2": ("1", "median (sqrt(Gamma*_{k+1}) - 1) / s_k^2"),
    "move_per_sqrt_g": ("1", "median s_k / sqrt(Gamma*_k - 1)"),
}


def perturbed(p: Packing, eps: float, seed: int) -> Packing:
    """``p`` with every coordinate moved by a Gaussian of ``eps`` mean diameters (seed 0: ``p``)."""
    if seed == 0:
        return p
    rng = np.random.default_rng(seed)
    return dataclasses.replace(p, position=p.position + eps * p.diameter.mean() * rng.standard_normal(p.position.shape))


def chain(p: Packing, engine: str) -> dict[str, float]:
    """One whole chain and its measures (:data:`MEASURES`)."""
    t0 = time.process_time()
    res = calippso(p, warm_engine=engine)
    cpu = time.process_time() - t0
    h = res.history
    sg = h["sqrt_gamma_minus_1"].values
    s = h["max_displacement_stable"].values
    g = sg * (sg + 2.0)  # Gamma* - 1 from sqrt(Gamma*) - 1
    a = res.packing.attrs
    return dict(lps=float(res.iterations), pivots=float(h["simplex_iterations"].sum()), cpu_time=cpu,
                phi_J=res.packing.packing_fraction, n_contacts=float(a["n_contacts"]),
                isostatic_count=float(a["isostatic_count"]), max_overlap=max_overlap(res.packing)[1],
                growth_per_move2=float(np.median(sg[1:] / s[:-1] ** 2)),
                move_per_sqrt_g=float(np.median(s[:-1] / np.sqrt(g[:-1]))))


def run(n: int, seed: int, perturbations: int, eps: float, engines: list[str]) -> xr.Dataset:
    start = near_start(n, seed, FAST_KAPPA)
    p = read_packing(start)
    rows = {e: [] for e in engines}
    for k in range(perturbations + 1):
        for e in engines:
            r = chain(perturbed(p, eps, k), e)
            rows[e].append(r)
            print(f"N = {n} s{seed}, perturbation {k} ({'none' if k == 0 else f'{eps:g}'}), {e}: {r['lps']:.0f} LPs, "
                  f"{r['pivots']:.0f} pivots, CPU {r['cpu_time']:.1f} s, phi_J {r['phi_J']:.10f}, contacts "
                  f"{r['n_contacts']:.0f} (isostatic {r['isostatic_count']:.0f}), max overlap {r['max_overlap']:.1e}, "
                  f"growth/s^2 {r['growth_per_move2']:.3f}, s/sqrt(g) {r['move_per_sqrt_g']:.1f}", flush=True)
    for e in engines:
        lps = np.array([r["lps"] for r in rows[e]])
        print(f"{e}: LPs min {lps.min():.0f}, median {np.median(lps):.0f}, max {lps.max():.0f} over {len(lps)} chains")
    data = {m: (("engine", "perturbation"), [[r[m] for r in rows[e]] for e in engines], {"units": u, "long_name": ln})
            for m, (u, ln) in MEASURES.items()}
    return xr.Dataset(data, coords={"engine": engines, "perturbation": np.arange(perturbations + 1)}).assign_attrs(
        new_dataset_attrs("CALiPPSO: LP counts of one near start under perturbations",
                          {"n": n, "seed": seed, "eps": eps, "perturbations": perturbations, "engines": engines,
                           "start": start.name}))


def plot(ds: xr.Dataset, title: str) -> Path:
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.8))
    for i, e in enumerate(ds.engine.values):
        d = ds.sel(engine=e)
        a1.plot(np.full(d.sizes["perturbation"], i) + 0.04 * np.arange(d.sizes["perturbation"]), d.lps, "o",
                label=str(e))
        a1.plot(i, float(d.lps[0]), "k*", ms=12)
        a2.plot(d.lps, d.cpu_time, "o", label=str(e))
    a1.set_xticks(range(ds.sizes["engine"]), [str(e) for e in ds.engine.values])
    a1.set_xlabel("warm engine (star: unperturbed start)")
    a1.set_ylabel("LPs of the chain [count]")
    a1.set_title(title, fontsize=9)
    a2.set_xlabel("LPs of the chain [count]")
    a2.set_ylabel("CPU time of calippso [s]")
    a2.legend(fontsize=8)
    fig.tight_layout()
    out = OUT / "calippso_tail.png"
    fig.savefig(out, dpi=120)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 256, 3 perturbations (a minute)")
    ap.add_argument("--n", type=int, default=2048, help="N of the near start (default 2048)")
    ap.add_argument("--seed", type=int, default=2, help="seed of the near start (default 2)")
    ap.add_argument("--perturbations", type=int, default=8, help="perturbed chains per engine (default 8)")
    ap.add_argument("--eps", type=float, default=1e-10, help="perturbation [mean diameters] (default 1e-10)")
    ap.add_argument("--engines", nargs="+", default=["jamflow", "highs"], choices=list(WARM_ENGINES),
                    help="--warm-engine values (default jamflow highs)")
    args = ap.parse_args()
    if args.perturbations < 0 or not args.eps > 0:
        ap.error("--perturbations must be >= 0 and --eps positive")
    n, k = (256, 3) if args.quick else (args.n, args.perturbations)
    OUT.mkdir(exist_ok=True)
    ds = run(n, args.seed, k, args.eps, args.engines)
    write_dataset(ds, OUT / "calippso_tail.nc")
    png = plot(ds, f"near start N = {n}, seed {args.seed}; perturbed by {args.eps:g} mean diameters")
    print(f"wrote {OUT / 'calippso_tail.nc'} and {png}")


if __name__ == "__main__":
    main()
