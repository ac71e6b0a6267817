"""LS compression speed: collisions per CPU-second and CPU time to reach p = 1e6 and 1e12.

Cases (issue 8): 3D monodisperse N = 256 and 1024 (4096 with ``--full``), 2D
bidisperse 1:1.4 (equal numbers) N = 1024, and 4D and 5D monodisperse N = 1024 (small
boxes of ~5 and ~3.5 diameters, where the LS kernel uses neighbour lists). Each run
starts from a random (RSA) packing at phi0 (2D 0.50, 3D 0.30, 4D 0.20, 5D 0.10),
follows the paper's two-stage protocol (fast
kappa0 = 5e-3 to p = 500, then kappa = ``--growth-rate``) and snapshots p = 1e6 and
1e12 in one run of one sample. Reported per target: collisions, CPU seconds (process
time of the compression only) and collisions per CPU-second; the side-by-side ratio to
the C++ reference (PackingGeneration) is measured by ``benchmarks/ls_vs_reference.py``.
The figures quoted in the issue for that code on this machine (3D: ~250k, 2D: ~635k
collisions per CPU-second) are printed for orientation only.

Run: ``python benchmarks/ls.py [--quick | --full]``. Writes
``benchmarks/output/ls.nc`` and ``benchmarks/output/ls.png``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import xarray as xr

from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import compress

OUTPUT = Path(__file__).resolve().parent / "output"
TARGETS = (1e6, 1e12)
#: Collisions per CPU-second of PackingGeneration quoted in issue 8 (not measured here).
QUOTED_CPP = {2: 635e3, 3: 250e3}
#: Packing fraction of the RSA start per dimension (below RSA saturation).
START_PHI = {2: 0.5, 3: 0.3, 4: 0.2, 5: 0.1}


def _cases(quick: bool, full: bool) -> list[tuple[int, int, str]]:
    if quick:
        return [(3, 256, "mono"), (2, 256, "bi")]
    cases = [(3, 256, "mono"), (3, 1024, "mono"), (2, 1024, "bi"), (4, 1024, "mono"), (5, 1024, "mono")]
    if full:
        cases.insert(2, (3, 4096, "mono"))
    return cases


def run(quick: bool, full: bool, growth_rate: float, seed: int) -> xr.Dataset:
    cases = _cases(quick, full)
    targets = TARGETS[:1] if quick else TARGETS
    shape = (len(cases), len(targets))
    coll = np.zeros(shape, dtype=np.int64)
    cpu = np.full(shape, np.nan)
    phi = np.full(shape, np.nan)
    p = np.full(shape, np.nan)
    rate = np.full(len(cases), np.nan)
    for a, (d, n, disp) in enumerate(cases):
        pk = random_packing(n, d, START_PHI[d], dispersity=disp, ratio=1.4, seed=seed)
        res = compress(pk, growth_rate, targets, seed=seed)
        for b, snap in enumerate(res.snapshots):
            coll[a, b] = snap.attrs["collisions"]
            cpu[a, b] = snap.attrs["cpu_time"]
            phi[a, b] = snap.packing_fraction
            p[a, b] = snap.pressure
        rate[a] = res.collisions_per_second
        print(f"d={d} N={n:5d} {disp:4s}: " + ", ".join(
            f"p>={t:.0e}: {coll[a, b] / 1e6:7.2f} M coll, {cpu[a, b]:7.1f} CPU-s, phi={phi[a, b]:.6f}"
            for b, t in enumerate(targets))
              + f"; {rate[a] / 1e3:6.0f} k coll/CPU-s"
              + (f" (C++ quoted ~{QUOTED_CPP[d] / 1e3:.0f}k)" if d in QUOTED_CPP else ""))
    case = [f"d{d}-N{n}-{disp}" for d, n, disp in cases]
    one = {"units": "1"}
    return xr.Dataset(
        {
            "collisions": (("case", "p_target"), coll, {**one, "long_name": "collisions to reach the target"}),
            "cpu_time": (("case", "p_target"), cpu, {"units": "s", "long_name": "CPU time to reach the target"}),
            "packing_fraction": (("case", "p_target"), phi, {**one, "long_name": "packing fraction at the target"}),
            "pressure": (("case", "p_target"), p, {**one, "long_name": "reduced pressure at the snapshot"}),
            "collisions_per_second": ("case", rate, {"units": "1/s", "long_name": "collisions per CPU-second (whole run)"}),
            "d": ("case", np.array([c[0] for c in cases]), {**one, "long_name": "dimension"}),
            "N": ("case", np.array([c[1] for c in cases]), {**one, "long_name": "number of particles"}),
        },
        coords={"case": case, "p_target": ("p_target", np.array(targets), {**one, "long_name": "target pressure"})},
        attrs=new_dataset_attrs("LS compression speed", {"quick": quick, "full": full,
                                                        "growth_rate": growth_rate, "seed": seed}),
    )


def plot(ds: xr.Dataset, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4))
    x = np.arange(ds.sizes["case"])
    ax0.bar(x, ds.collisions_per_second.values / 1e3, color="C0", label="jamflow")
    quoted = [QUOTED_CPP.get(int(d), np.nan) / 1e3 for d in ds.d.values]
    ax0.plot(x, quoted, "k_", markersize=30, mew=2, label="C++ (quoted in issue 8)")
    ax0.set_xticks(x, ds.case.values, rotation=20)
    ax0.set_ylabel("collisions per CPU-second [k]")
    ax0.legend()
    for b, t in enumerate(ds.p_target.values):
        ax1.bar(x + 0.4 * b - 0.2, ds.cpu_time.values[:, b], width=0.4, label=f"p = {t:.0e}")
    ax1.set_xticks(x, ds.case.values, rotation=20)
    ax1.set_ylabel("CPU time to reach p [s]")
    ax1.set_yscale("log")
    ax1.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="N = 256 only, to p = 1e6")
    size.add_argument("--full", action="store_true", help="also 3D N = 4096")
    parser.add_argument("--growth-rate", type=float, default=1e-3, help="slow growth rate kappa (default 1e-3)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    ds = run(args.quick, args.full, args.growth_rate, args.seed)
    OUTPUT.mkdir(parents=True, exist_ok=True)
    write_dataset(ds, OUTPUT / "ls.nc")
    plot(ds, OUTPUT / "ls.png")
    print(f"wrote {OUTPUT / 'ls.nc'} and {OUTPUT / 'ls.png'}")


if __name__ == "__main__":
    main()
