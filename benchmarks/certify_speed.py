"""Certificate speed: ``certify(strict=True)`` with and without the Roth-Whiteley test.

Issue 19's target: the certificate of a soft 3D N = 4096 packing (P0 = 1e-5,
harmonic) under 60 s (it took 552 s). The profile of the LP-only certificate is
99.9 % inside HiGHS's interior-point solves of the cone LPs (``max b . y`` subject
to ``R y >= 0``): on a jammed network their feasible set is the single point
``y = 0`` (no interior), where IPX needs ~40 iterations of growing cost, the
simplex (dual cold, or primal from ``y = 0``) needs tens of thousands of
degenerate pivots, and presolve or a second thread change little (measured on the
first strict LP of the d = 3 LS example: IPX 34 / 28 s per sign, presolve on
29 / 20 s, two threads 45 / 37 s, split primal simplex 170 s for one sign, on a
loaded machine). The Roth-Whiteley test (:func:`jamflow.network.isostatic_rigidity`)
decides an isostatic backbone by one sparse LU instead.

For each packing the two variants run side by side in one process (same load,
same seed): ``self_stress_test=True`` (default) and ``False`` (the LP-only
certificate, i.e. the code before); the verdicts (classification, rattlers,
motion stage) must agree. Packings: the soft 3D N = 1024 packing of
``benchmarks/certify.py`` (cached in ``benchmarks/output``), and N = 4096: the soft
N = 4096 packing when it is cached there, otherwise the N = 1024 one replicated
2 x 2 x 1 (a force-balanced jammed packing at the same P0 and the same LP size;
the dataset says which).

Run: ``python benchmarks/certify_speed.py [--skip-lp-only-4096]`` (writes
``benchmarks/output/certify_speed.nc`` and ``.png``; the LP-only N = 4096 run alone
takes ~10 min on 2 cores).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from certify import OUT, replicate, soft_packing  # noqa: E402

from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.protocols.certify import certify


def packing_4096():
    path = OUT / "soft_3d_N4096_P1e-5.nc"
    if path.exists():
        return read_packing(path, overlap_tol=None), "soft N=4096"
    return replicate(soft_packing(1024), (2, 2, 1)), "soft N=1024 tiled 2x2x1"


def timed(p, shortcut: bool, profile: bool):
    prof = cProfile.Profile() if profile else None
    t0 = time.perf_counter()
    if prof:
        prof.enable()
    cert = certify(p, strict=True, loads=1, seed=0, self_stress_test=shortcut)
    if prof:
        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(8)
    return time.perf_counter() - t0, cert


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-lp-only-4096", action="store_true", help="skip the slow LP-only run at N = 4096")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    big, big_label = packing_4096()
    cases = [("soft N=1024", soft_packing(1024)), (big_label, big)]
    rows = []
    for label, p in cases:
        for shortcut in (True, False):
            if not shortcut and p.n == 4096 and args.skip_lp_only_4096:
                continue
            wall, cert = timed(p, shortcut, profile=shortcut and p.n == 4096)
            row = {"case": label, "N": p.n, "variant": "self-stress test" if shortcut else "LP only",
                   "time": wall, "n_lp": len(cert.lp), "classification": cert.classification,
                   "motion_stage": cert.motion_stage, "n_rattlers": int(cert.rattler.sum()),
                   "decisions": cert.self_stress_decisions}
            rows.append(row)
            print(f"{label:26s} N={p.n:5d} {row['variant']:17s} {wall:8.2f} s  {len(cert.lp)} LPs, "
                  f"{cert.self_stress_decisions} self-stress decisions -> {cert.classification} "
                  f"(motion: {cert.motion_stage or 'none'}), {row['n_rattlers']} rattlers", flush=True)
        both = [r for r in rows if r["case"] == label]
        if len(both) == 2:
            same = all(both[0][k] == both[1][k] for k in ("classification", "motion_stage", "n_rattlers"))
            print(f"  {label}: verdicts agree: {same}; speed-up {both[1]['time'] / both[0]['time']:.1f}x", flush=True)
    ds = xr.Dataset(
        {
            "time": (("run",), np.array([r["time"] for r in rows]), {"units": "s", "long_name": "wall time of certify"}),
            "n_lp": (("run",), np.array([r["n_lp"] for r in rows]), {"units": "1", "long_name": "number of LPs"}),
            "N": (("run",), np.array([r["N"] for r in rows]), {"units": "1", "long_name": "number of particles"}),
            "self_stress_decisions": (("run",), np.array([r["decisions"] for r in rows]),
                                      {"units": "1", "long_name": "backbones decided by the Roth-Whiteley test"}),
            "case": (("run",), np.array([f"{r['case']} [{r['variant']}] -> {r['classification']}" for r in rows]),
                     {"units": "1", "long_name": "input, variant and classification"}),
        },
        attrs=new_dataset_attrs("jamflow benchmark: certify speed", {"strict": True, "loads": 1, "seed": 0,
                                                                      "n4096_input": big_label}),
    )
    write_dataset(ds, OUT / "certify_speed.nc")
    fig, ax = plt.subplots(figsize=(5, 4))
    for variant, marker in (("self-stress test", "o"), ("LP only", "s")):
        sel = [r for r in rows if r["variant"] == variant]
        ax.loglog([r["N"] for r in sel], [r["time"] for r in sel], marker=marker, label=variant)
    ax.axhline(60.0, color="grey", ls=":", label="target 60 s")
    ax.set_xlabel("N (d = 3, soft, P0 = 1e-5)")
    ax.set_ylabel("time to certify, strict [s]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "certify_speed.png", dpi=120)
    print(f"wrote {OUT / 'certify_speed.nc'} and {OUT / 'certify_speed.png'}")


if __name__ == "__main__":
    main()
