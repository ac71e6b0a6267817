"""Analyses: time against N for p(h), g(r) + Q6, P(f) and Q, with an O(N^2) reference.

Configurations are uniform random centres in a cubic box (d = 3) at number density
one, with diameter 1 (packing fraction ~0.52; overlaps are irrelevant for timing,
the analyses do not validate). Each analysis is timed at every N; the gap
histogram is also computed from an all-pairs (brute-force) neighbour search in the
same run for the sizes where that fits in memory, which gives the speed-up ratio and
checks that both give the same histogram. Fitted exponents ``t ~ N^alpha`` are
printed and stored.

Run: ``python benchmarks/analysis.py [--quick]``. Writes
``benchmarks/output/analysis.nc`` and ``benchmarks/output/analysis.png``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from jamflow.analysis.forces import force_distribution
from jamflow.analysis.gaps import gap_histogram, non_contact_gaps
from jamflow.analysis.overlap import contact_overlap
from jamflow.analysis.structure import structure_dataset
from jamflow.box import Box
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.neighbors.pairs import pairs_within_brute_force
from jamflow.state.packing import Packing, near_pairs

OUTPUT = Path(__file__).resolve().parent / "output"
MAX_GAP = 0.1
ANALYSES = ("gaps", "gaps_brute_force", "rdf_q6", "forces", "overlap")


def _timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def _brute_gaps(p: Packing) -> np.ndarray:
    pairs = pairs_within_brute_force(p.position, p.box, float(p.diameter.max()) * (1 + MAX_GAP))
    h = pairs.distance / p.sigma(pairs.i, pairs.j) - 1.0
    h = h[h <= MAX_GAP]
    return h[h > 1e-8]


def run(ns: list[int], brute_max: int, seed: int) -> xr.Dataset:
    rng = np.random.default_rng(seed)
    times = np.full((len(ANALYSES), len(ns)), np.nan)
    for c, n in enumerate(ns):
        side = n ** (1.0 / 3.0)
        box = Box.cubic(3, side)
        p = Packing(rng.random((n, 3)) * side, np.ones(n), box)
        pairs, _ = near_pairs(p, 0.0)
        contacts = np.stack([pairs.i, pairs.j], axis=1)
        jammed = p.evolve(contacts=contacts, force=rng.random(len(contacts)))
        times[0, c], h = _timed(lambda: gap_histogram([non_contact_gaps(p, MAX_GAP)], [n], MAX_GAP, 1e-8, 5))
        if n <= brute_max:
            times[1, c], hb = _timed(lambda: gap_histogram([_brute_gaps(p)], [n], MAX_GAP, 1e-8, 5))
            if not np.array_equal(h[0]["count"].values, hb[0]["count"].values):
                raise AssertionError(f"N={n}: tree and brute-force gap histograms differ")
        times[2, c], _ = _timed(lambda: structure_dataset(p, r_max=min(3.0, 0.49 * side), bins=150))
        times[3, c], _ = _timed(lambda: force_distribution([jammed]))
        other = jammed.evolve(contacts=contacts[::2], force=None)
        times[4, c], _ = _timed(lambda: contact_overlap(other, jammed))
        print(f"N={n:7d}  " + "  ".join(f"{a} {t:.4f} s" for a, t in zip(ANALYSES, times[:, c])))
    alpha = []
    for k, name in enumerate(ANALYSES):
        ok = np.isfinite(times[k]) & (np.asarray(ns) >= 1000)
        a = np.polyfit(np.log(np.asarray(ns)[ok]), np.log(times[k][ok]), 1)[0] if ok.sum() >= 2 else np.nan
        alpha.append(a)
        print(f"{name:18s} t ~ N^{a:.2f}")
    both = np.isfinite(times[1])
    ratio = times[1][both] / times[0][both]
    for n, r in zip(np.asarray(ns)[both], ratio):
        print(f"gap histogram, brute force / tree at N={n}: {r:.1f}x")
    return xr.Dataset(
        data_vars={
            "time": (("analysis", "n"), times, {"units": "s", "long_name": "wall time of one call (2-core machine)"}),
            "exponent": ("analysis", np.array(alpha), {"units": "1", "long_name": "fitted exponent of t ~ N^alpha"}),
        },
        coords={"analysis": ("analysis", np.array(ANALYSES, dtype=object), {"long_name": "analysis"}),
                "n": ("n", np.array(ns), {"units": "1", "long_name": "number of particles"})},
        attrs=new_dataset_attrs("jamflow analysis benchmark", {"ns": ns, "brute_max": brute_max, "seed": seed}, d=3),
    )


def plot(ds: xr.Dataset) -> Figure:
    fig = Figure(layout="constrained", figsize=(6.4, 4.6))
    ax = fig.add_subplot()
    for k, name in enumerate(ds["analysis"].values):
        t = ds["time"].values[k]
        ok = np.isfinite(t)
        ax.loglog(ds["n"].values[ok], t[ok], "o-", label=f"{name} (N^{ds['exponent'].values[k]:.2f})")
    ax.set_xlabel("number of particles N (dimensionless)")
    ax.set_ylabel("wall time [s]")
    ax.set_title("jamflow analyses, d = 3, unit number density", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes only")
    args = parser.parse_args()
    ns = [1000, 4000, 16000] if args.quick else [1000, 4000, 16000, 64000]
    ds = run(ns, brute_max=16000, seed=3)
    OUTPUT.mkdir(parents=True, exist_ok=True)
    write_dataset(ds, OUTPUT / "analysis.nc")
    plot(ds).savefig(OUTPUT / "analysis.png", dpi=130)
    print(f"wrote {OUTPUT / 'analysis.nc'} and {OUTPUT / 'analysis.png'}")


if __name__ == "__main__":
    main()
