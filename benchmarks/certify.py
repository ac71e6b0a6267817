"""Jamming certificate: time against N, and random loads against false "jammed" answers.

Part 1 (time). ``certify(strict=True, loads=1)`` (one load, both signs) on 3D packings of N = 1024 and 4096:
soft-sphere packings jammed at P0 = 1e-5 (``jamflow.protocols.soft_jam.jam_to_pressure``,
harmonic, monodisperse; generated once and cached in ``benchmarks/output``), and the
LS snapshot of the CALiPPSO examples (N = 1024, d = 3; contacts = pairs with relative
gap <= 3e-3 as exact contacts) replicated 2 x 2 x 1 for N = 4096. The interior-point
solver without crossover (default, cold for every load) is compared with the simplex
(a cold dual simplex for the first load, then the primal simplex from the last basis,
since loads change only the costs) on the same inputs in the same run (simplex only
at N = 1024: its cold first solve grows too fast; at soft N = 4096 it was stopped
after 14 min).

Part 2 (loads). Packings with planted unjamming motions; for each number of loads K
and with or without the opposite sign of every load, the fraction of seeds for which
the certificate misses the planted motion (a false "jammed" answer):

* ``ray``: triangular lattice, 12 x 8 rectangular cells (N = 192), one particle
  without its two upper contacts: it keeps four contacts but can move straight up
  (its motions form a ray, the case where the sign of the load matters: a one-sided
  load misses it with probability 1/2); missed = that particle not flagged;
* ``cut_contact_2d`` / ``_3d``: soft packings (2D bidisperse N = 256 and 3D N = 1024,
  P0 = 1e-5) with one contact removed from their isostatic backbone (a
  full-dimensional simplicial cone of motions); missed = certified collectively
  jammed with no rattler beyond those of the intact packing.

Run: ``python benchmarks/certify.py`` (about 10-20 minutes on 2 cores).
"""

from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.box import Box
from jamflow.io import new_dataset_attrs, read_packing, write_dataset, write_packing
from jamflow.io.formats import read_dat
from jamflow.protocols.certify import certify
from jamflow.protocols.initial import random_packing
from jamflow.protocols.lattices import lattice_packing
from jamflow.state.packing import Packing

OUT = Path(__file__).resolve().parent / "output"
LS = Path(__file__).resolve().parents[1] / "tests" / "data" / "calippso-ls" / "Centers-after-LS--N-1024--d-3.dat"
LS_GAP_TOL = 3e-3


def soft_packing(n: int) -> Packing:
    """Soft 3D packing at P0 = 1e-5, cached (the soft jamming itself is not timed)."""
    path = OUT / f"soft_3d_N{n}_P1e-5.nc"
    if not path.exists():
        from jamflow.protocols.soft_jam import jam_to_pressure

        res = jam_to_pressure(random_packing(n, 3, 0.2, "mono", 11, 1.4, 0.5, 0.1), pressure=1e-5)
        write_packing(res.packing, path)
    return read_packing(path, overlap_tol=None)


def soft_packing_2d() -> Packing:
    """Soft 2D bidisperse packing, N = 256 at P0 = 1e-5 (cached)."""
    path = OUT / "soft_2d_N256_P1e-5.nc"
    if not path.exists():
        from jamflow.protocols.soft_jam import jam_to_pressure

        res = jam_to_pressure(random_packing(256, 2, 0.3, "bi", 1, 1.4, 0.5, 0.1), pressure=1e-5)
        write_packing(res.packing, path)
    return read_packing(path, overlap_tol=None)


def replicate(p: Packing, reps: tuple[int, ...]) -> Packing:
    """Periodic images of a packing in an orthogonal box, ``reps`` copies per axis."""
    L = p.box.lengths
    shifts = np.stack(np.meshgrid(*[np.arange(r) for r in reps], indexing="ij"), -1).reshape(-1, p.d) * L
    x = (p.position[None] + shifts[:, None]).reshape(-1, p.d)
    return Packing(position=x, diameter=np.tile(p.diameter, len(shifts)),
                   box=Box.orthogonal(L * np.asarray(reps)), protocol=p.protocol + ">replicated")


def planted_ray() -> tuple[Packing, int]:
    """Triangular lattice with the two upper contacts of one particle removed.

    The particle keeps contacts at 0, 180, 240 and 300 degrees (enough for the
    coordination test) but can move straight up: its motions form a ray.
    """
    p = lattice_packing("triangular", (12, 8))
    i = p.n // 2
    dx = p.box.minimum_image(p.position[p.contacts[:, 1]] - p.position[p.contacts[:, 0]])
    up_from_i = np.where(p.contacts[:, 0] == i, dx[:, 1], np.where(p.contacts[:, 1] == i, -dx[:, 1], 0.0))
    return p.evolve(contacts=p.contacts[~(up_from_i > 0.5)]), i


def cut_contact(p: Packing, base) -> Packing:
    """``p`` without the middle contact of its certified isostatic backbone."""
    bc = base.backbone_contacts
    k = len(bc) // 2
    drop = (p.contacts[:, 0] == bc[k, 0]) & (p.contacts[:, 1] == bc[k, 1])
    return p.evolve(contacts=p.contacts[~drop], force=None)


def time_certify(label: str, p: Packing, gap_tol: float | None, solver: str) -> dict:
    t0 = time.perf_counter()
    cert = certify(p, strict=True, gap_tol=gap_tol, rhs="zero", loads=1, seed=0, solver=solver)
    wall = time.perf_counter() - t0
    row = {"case": label, "N": p.n, "solver": solver, "time": wall, "n_lp": len(cert.lp),
               "lp_time": sum(r.time for r in cert.lp), "classification": cert.classification,
               "n_rattlers": int(cert.rattler.sum())}
    print(f"  {label:22s} N={p.n:5d} {solver:8s} {wall:8.2f} s  ({len(cert.lp)} LPs, "
          f"{row['lp_time']:.2f} s in HiGHS)  -> {cert.classification}, {row['n_rattlers']} rattlers", flush=True)
    return row


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    print("Part 1: time to certify (strict, 1 load x 2 signs)")
    soft = {n: soft_packing(n) for n in (1024, 4096)}
    ls = read_dat(LS)
    rows = [
        time_certify("soft P0=1e-5", soft[1024], None, "simplex"),
        time_certify("soft P0=1e-5", soft[1024], None, "ipm"),
        time_certify("soft P0=1e-5", soft[4096], None, "ipm"),
        time_certify("LS gap<=3e-3", ls, LS_GAP_TOL, "simplex"),
        time_certify("LS gap<=3e-3", ls, LS_GAP_TOL, "ipm"),
        time_certify("LS 2x2x1 gap<=3e-3", replicate(ls, (2, 2, 1)), LS_GAP_TOL, "ipm"),
    ]
    for case in ("soft P0=1e-5", "LS gap<=3e-3"):
        ref = next(r["time"] for r in rows if r["case"] == case and r["solver"] == "simplex")
        ipm = next(r["time"] for r in rows if r["case"] == case and r["solver"] == "ipm" and r["N"] == 1024)
        big = next(r["time"] for r in rows if r["case"].startswith(case.split()[0]) and r["N"] == 4096)
        print(f"  {case}: ipm / simplex at N=1024 = {ipm / ref:.2f}; ipm N=4096 / N=1024 = {big / ipm:.1f}")

    print("Part 2: planted unjamming motions, fraction of seeds missing them")
    ray, ray_particle = planted_ray()
    soft2d = soft_packing_2d()
    base2d = certify(soft2d, loads=1, seed=0)
    base3d = certify(soft[1024], loads=1, seed=0)
    # (name, packing, seeds, intact certificate, loads tried); the N = 1024 case only at K = 1 (cost)
    plants = [("ray", ray, 40, None, (1, 2, 4)), ("cut_contact_2d", cut_contact(soft2d, base2d), 20, base2d, (1, 2, 4)),
              ("cut_contact_3d", cut_contact(soft[1024], base3d), 3, base3d, (1,))]
    loads_list = (1, 2, 4)
    miss = np.full((len(plants), len(loads_list), 2), np.nan)
    cost = np.full_like(miss, np.nan)
    for a, (name, p, seeds, base, tried) in enumerate(plants):
        for b, loads in enumerate(loads_list):
            if loads not in tried:
                continue
            for c, both in enumerate((True, False)):
                wrong, t0 = 0, time.perf_counter()
                for seed in range(seeds):
                    cert = certify(p, loads=loads, seed=seed, both_signs=both)
                    if name == "ray":
                        wrong += not cert.rattler[ray_particle]
                    else:
                        # missed: jammed with no particle removed beyond the intact backbone's rattlers
                        wrong += (cert.classification == "collectively_jammed"
                                  and int(cert.rattler.sum()) == int(base.rattler.sum()))
                miss[a, b, c] = wrong / seeds
                cost[a, b, c] = (time.perf_counter() - t0) / seeds
                print(f"  {name:13s} loads={loads} {'both signs' if both else 'one sign  '}: "
                      f"missed {wrong}/{seeds}  ({cost[a, b, c]:.2f} s per certificate)", flush=True)

    ds = xr.Dataset(
        {
            "time": (("run",), np.array([r["time"] for r in rows]), {"units": "s", "long_name": "wall time of certify"}),
            "lp_time": (("run",), np.array([r["lp_time"] for r in rows]), {"units": "s", "long_name": "time inside HiGHS"}),
            "n_lp": (("run",), np.array([r["n_lp"] for r in rows]), {"units": "1", "long_name": "number of LPs"}),
            "N": (("run",), np.array([r["N"] for r in rows]), {"units": "1", "long_name": "number of particles"}),
            "case": (("run",), np.array([f"{r['case']} [{r['solver']}] -> {r['classification']}" for r in rows]),
                     {"units": "1", "long_name": "input, solver and classification"}),
            "miss_fraction": (("plant", "loads", "signs"), miss,
                              {"units": "1", "long_name": "fraction of seeds that missed the planted motion"}),
            "time_per_certificate": (("plant", "loads", "signs"), cost,
                                     {"units": "s", "long_name": "mean wall time per certificate"}),
        },
        coords={"plant": [p[0] for p in plants], "loads": list(loads_list), "signs": ["both", "one"]},
        attrs=new_dataset_attrs("jamflow benchmark: certify", {"ls_gap_tol": LS_GAP_TOL}),
    )
    write_dataset(ds, OUT / "certify.nc")

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for solver, marker in (("ipm", "o"), ("simplex", "s")):
        for case in ("soft", "LS"):
            sel = [r for r in rows if r["solver"] == solver and r["case"].startswith(case)]
            if sel:
                ax1.loglog([r["N"] for r in sel], [r["time"] for r in sel], marker=marker, label=f"{case} ({solver})")
    ax1.set_xlabel("N (d = 3)")
    ax1.set_ylabel("time to certify [s]")
    ax1.legend()
    for a, (name, *_) in enumerate(plants):
        for c, style in enumerate(("-", "--")):
            ax2.plot(loads_list, miss[a, :, c], style, marker="o", label=f"{name}, {'both signs' if c == 0 else 'one sign'}")
    ax2.set_xlabel("random loads K")
    ax2.set_ylabel("fraction of false 'jammed' answers")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "certify.png", dpi=120)
    print(f"wrote {OUT / 'certify.nc'} and {OUT / 'certify.png'}")


if __name__ == "__main__":
    main()
