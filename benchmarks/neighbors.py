"""Neighbour search: time against N, orthogonal and sheared boxes, versus brute force.

Uniform random centres at unit number density (box side ``N**(1/d)``) with a cutoff
of 1.2, so the number of neighbours per particle is fixed and an O(N) search shows
up as time proportional to N. The O(N^2) reference (``pairs_within_brute_force``) is
timed in the same run for the sizes where it fits in memory; the ratio at equal N
and the fitted exponents ``t ~ N^alpha`` are printed and stored.

Run: ``python benchmarks/neighbors.py [--quick]``. Writes
``benchmarks/output/neighbors.nc`` and ``benchmarks/output/neighbors.png``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import xarray as xr

from jamflow.box import Box
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.neighbors.pairs import pairs_within, pairs_within_brute_force

OUTPUT = Path(__file__).resolve().parent / "output"
CUTOFF = 1.2
SHEAR_STRAIN = 0.37


def _best_time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(ns: list[int], dims: list[int], brute_max: int, seed: int) -> xr.Dataset:
    kinds = ["orthogonal", "sheared"]
    shape = (len(dims), len(kinds), len(ns))
    t_tree = np.full(shape, np.nan)
    t_brute = np.full(shape, np.nan)
    n_pairs = np.zeros(shape, dtype=np.int64)
    rng = np.random.default_rng(seed)
    for a, d in enumerate(dims):
        for b, kind in enumerate(kinds):
            for c, n in enumerate(ns):
                side = n ** (1.0 / d)
                box = Box.cubic(d, side) if kind == "orthogonal" else Box.lees_edwards(np.full(d, side), SHEAR_STRAIN)
                x = box.to_cartesian(rng.random((n, d)))
                repeats = 3 if n <= 10_000 else 1
                pl = pairs_within(x, box, CUTOFF)
                n_pairs[a, b, c] = len(pl)
                t_tree[a, b, c] = _best_time(lambda: pairs_within(x, box, CUTOFF), repeats)
                line = f"d={d} {kind:10s} N={n:7d} pairs={len(pl):8d} tree {t_tree[a, b, c]:.4f} s"
                if n <= brute_max:
                    ref = pairs_within_brute_force(x, box, CUTOFF)
                    if not (np.array_equal(ref.i, pl.i) and np.array_equal(ref.j, pl.j)):
                        raise RuntimeError(f"pair lists differ at d={d}, {kind}, N={n}")
                    t_brute[a, b, c] = _best_time(lambda: pairs_within_brute_force(x, box, CUTOFF), 1)
                    line += f"  brute {t_brute[a, b, c]:.4f} s  brute/tree {t_brute[a, b, c] / t_tree[a, b, c]:.1f}"
                print(line, flush=True)

    def exponent(t: np.ndarray, n_min: int) -> np.ndarray:
        out = np.full(t.shape[:2], np.nan)
        for a in range(t.shape[0]):
            for b in range(t.shape[1]):
                ok = np.isfinite(t[a, b]) & (np.asarray(ns) >= n_min)
                if ok.sum() >= 2:
                    out[a, b] = np.polyfit(np.log(np.asarray(ns)[ok]), np.log(t[a, b][ok]), 1)[0]
        return out

    # small N is dominated by fixed costs for the trees; brute force is fitted where run
    alpha_tree, alpha_brute = exponent(t_tree, 3000), exponent(t_brute, 0)
    for a, d in enumerate(dims):
        for b, kind in enumerate(kinds):
            print(f"d={d} {kind:10s} fitted exponent: tree (N >= 3000) {alpha_tree[a, b]:.2f}  brute (N <= {brute_max}) {alpha_brute[a, b]:.2f}")
    ds = xr.Dataset(
        {
            "time_tree": (("d", "box_kind", "n_particles"), t_tree,
                          {"units": "s", "long_name": "best wall time of pairs_within"}),
            "time_brute_force": (("d", "box_kind", "n_particles"), t_brute,
                                 {"units": "s", "long_name": "wall time of the O(N^2) reference (NaN: not run)"}),
            "speedup": (("d", "box_kind", "n_particles"), t_brute / t_tree,
                        {"units": "1", "long_name": "brute-force time over pairs_within time, same run"}),
            "n_pairs": (("d", "box_kind", "n_particles"), n_pairs,
                        {"units": "1", "long_name": "number of pairs within the cutoff"}),
            "exponent_tree": (("d", "box_kind"), alpha_tree,
                              {"units": "1", "long_name": "fitted alpha in t ~ N^alpha for pairs_within (N >= 3000)"}),
            "exponent_brute_force": (("d", "box_kind"), alpha_brute,
                                     {"units": "1", "long_name": "fitted alpha in t ~ N^alpha for brute force (sizes where it ran)"}),
        },
        coords={
            "d": ("d", np.array(dims), {"units": "1", "long_name": "spatial dimension"}),
            "box_kind": ("box_kind", np.array(kinds), {"long_name": "box type", "units": "1"}),
            "n_particles": ("n_particles", np.array(ns), {"units": "1", "long_name": "number of particles"}),
        },
        attrs=new_dataset_attrs(
            "jamflow benchmark: neighbour search scaling",
            {"ns": ns, "dims": dims, "brute_max": brute_max, "seed": seed, "cutoff": CUTOFF,
             "number_density": 1.0, "shear_strain": SHEAR_STRAIN},
            machine_cores=os.cpu_count(),
        ),
    )
    return ds


def plot(ds: xr.Dataset, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dims = ds["d"].values
    fig, axes = plt.subplots(1, len(dims), figsize=(4 * len(dims), 3.6), sharey=True, squeeze=False)
    ns = ds["n_particles"].values
    for ax, d in zip(axes[0], dims):
        for kind, marker in zip(ds["box_kind"].values, ("o", "s")):
            sel = ds.sel(d=d, box_kind=kind)
            alpha = float(sel["exponent_tree"])
            ax.loglog(ns, sel["time_tree"], marker + "-", label=f"pairs_within, {kind} (N^{alpha:.2f})")
            ax.loglog(ns, sel["time_brute_force"], marker + "--", mfc="none", label=f"brute force, {kind}")
        ref = ns / ns[0] * float(ds["time_tree"].sel(d=d).min())
        ax.loglog(ns, ref, "k:", lw=0.8, label="∝ N")
        ax.set_title(f"d = {d}")
        ax.set_xlabel("N")
    axes[0, 0].set_ylabel("wall time [s]")
    axes[0, -1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="N up to 1e4 only")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    ns = [1000, 2000, 3000, 10_000] if args.quick else [1000, 2000, 3000, 10_000, 30_000, 100_000]
    ds = run(ns, [2, 3, 5], brute_max=3000, seed=args.seed)
    OUTPUT.mkdir(parents=True, exist_ok=True)
    write_dataset(ds, OUTPUT / "neighbors.nc")
    plot(ds, OUTPUT / "neighbors.png")
    print(f"wrote {OUTPUT / 'neighbors.nc'} and {OUTPUT / 'neighbors.png'}")


if __name__ == "__main__":
    main()
