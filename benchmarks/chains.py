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
[--pressure 1e-4] [--pressure-rtol 1e-3]``; the defaults are the issue's sizes (2D rigid
trimers N = 150 and 600 spheres, 3D chains N = 256 and 1024). Each linked run is timed
without a profiler and repeated under cProfile for the shares (cumulative times of
``project``, ``reproject``, ``evaluate`` (energy, link tensions and the factorisation at
the new point) and neighbour-list ``build``; nested calls make them overlap).
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
from jamflow.minimize.onset import JammingSettings
from jamflow.protocols.soft_jam import jam_to_pressure
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
    # the default dilute starts without overlaps: from overlapping starts links pass through
    # each other and the run is refused as entangled (3D N = 1024 chains from phi = 0.6 were)
    if d == 2:
        return linked_packing(2, n // 3, "trimer", np.random.default_rng(seed))[0]
    return linked_packing(3, n // 4, "chain", np.random.default_rng(seed), chain_length=4)[0]


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
    # untimed warm-up: numba loads (or compiles) every kernel of both engines and the spheres' on first use
    for d in sorted({d for d, _ in sizes}):
        small = _start(d, 24 if d == 2 else 128, seed)
        jam_to_pressure(small.evolve(links=None), pressure, force_tol=1e-12, pressure_rtol=rtol, delta_phi=1e-2)
        for stabilize in (False, True):
            jam_linked(small, pressure, settings=settings, shear_stabilize=stabilize)
    for d, n in sizes:
        start = _start(d, n, seed)
        t0, c0 = time.perf_counter(), time.process_time()
        sphere = jam_to_pressure(start.evolve(links=None), pressure, force_tol=1e-12, pressure_rtol=rtol,
                                 delta_phi=1e-2)
        t_sphere, c_sphere = time.perf_counter() - t0, time.process_time() - c0
        for stabilize in (False, True):
            t0, c0 = time.perf_counter(), time.process_time()
            res = jam_linked(start, pressure, settings=settings, shear_stabilize=stabilize)
            total, cpu = time.perf_counter() - t0, time.process_time() - c0
            # shares from a second, profiled run of the same start (cProfile slows the many small calls)
            _, t_prof, parts = _profiled(lambda s=start, k=stabilize: jam_linked(s, pressure, settings=settings,
                                                                                 shear_stabilize=k))
            p = res.packing
            rows.append({"d": d, "n": start.n, "shear": int(stabilize), "time_s": total, "sphere_time_s": t_sphere,
                         "ratio": total / t_sphere, "cpu_s": cpu, "sphere_cpu_s": c_sphere,
                         "cpu_ratio": cpu / c_sphere, "steps": res.steps, "sphere_steps": sphere.steps,
                         "phi": p.packing_fraction, "sphere_phi": sphere.packing.packing_fraction,
                         "n_contacts": p.attrs["n_contacts"], "isostatic_count": p.attrs["isostatic_count"],
                         "max_link_error": p.attrs["max_link_error"],
                         **{f"share_{k.replace(' ', '_').replace('-', '_')}": v / t_prof for k, v in parts.items()}})
            r = rows[-1]
            print(f"d={d} N={start.n} {'shear-stabilised' if stabilize else 'fixed box'}: {total:.1f} s "
                  f"({r['ratio']:.1f} x spheres {t_sphere:.2f} s; CPU {cpu:.2f} s, {r['cpu_ratio']:.1f} x spheres "
                  f"{c_sphere:.2f} s), {res.steps} FIRE steps (spheres {sphere.steps}), "
                  f"phi {r['phi']:.5f} (spheres {r['sphere_phi']:.5f}), N_c {r['n_contacts']} / iso "
                  f"{r['isostatic_count']}, link error {r['max_link_error']:.1e} (<= {LINK_LENGTH_RTOL:g}); "
                  f"shares of the profiled run ({t_prof:.1f} s) " + ", ".join(f"{k} {v / t_prof:.0%}"
                                                                             for k, v in parts.items()), flush=True)
    return rows


def protocol_runs(sizes: list[tuple[int, int]], levels: list[tuple[float, float]], seeds: int) -> list[dict]:
    """Bisection to P0 against the energy-scaling decompression, same starts, interleaved (shear-stabilised)."""
    rows = []
    for d, n in sizes:
        for seed in range(1, seeds + 1):
            start = _start(d, n, seed)
            for p0, etol in levels:
                settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2)
                for protocol in ("bisection", "energy"):
                    t0 = time.perf_counter()
                    res = jam_linked(start, p0 if protocol == "bisection" else None, settings=settings,
                                     shear_stabilize=True, protocol=protocol, energy_tol=etol)
                    t = time.perf_counter() - t0
                    p = res.packing
                    rows.append({"d": d, "n": p.n, "seed": seed, "level_pressure": p0, "level_energy": etol,
                                 "energy_protocol": int(protocol == "energy"), "time_s": t, "steps": res.steps,
                                 "minimisations": len(res.history["phi"]), "phi": p.packing_fraction,
                                 "pressure": p.pressure, "energy_per_sphere": p.attrs["energy"] / p.n,
                                 "n_contacts": p.attrs["n_contacts"], "isostatic_count": p.attrs["isostatic_count"],
                                 "converged": int(res.converged)})
                    r = rows[-1]
                    print(f"protocols d={d} N={p.n} seed {seed} {protocol:9s} (P0 {p0:g} / U/N <= {etol:g}): "
                          f"{t:.2f} s, {res.steps} steps, {r['minimisations']} minimisations, phi {r['phi']:.6f}, "
                          f"P {r['pressure']:.3e}, U/N {r['energy_per_sphere']:.2e}, N_c {r['n_contacts']} / iso "
                          f"{r['isostatic_count']}", flush=True)
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
    ap.add_argument("--sizes", nargs="+", default=["2:150", "2:600", "3:256", "3:1024"],
                    help="d:N pairs of the jamming runs (2D rigid trimers, 3D chains of 4 with frozen angles)")
    ap.add_argument("--hessian-sizes", nargs="+", type=int, default=[30, 60, 120, 240])
    ap.add_argument("--pressure", type=float, default=1e-4)
    ap.add_argument("--pressure-rtol", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--protocol-sizes", nargs="*", default=["2:60", "3:128"],
                    help="d:N of the bisection vs energy-scaling comparison (shear-stabilised; none to skip)")
    ap.add_argument("--protocol-seeds", type=int, default=3)
    ap.add_argument("--skip-jamming", action="store_true", help="only the protocol comparison and Hessian parts")
    args = ap.parse_args()
    sizes = [tuple(int(v) for v in s.split(":")) for s in args.sizes]
    jam = [] if args.skip_jamming else jamming_runs(sizes, args.pressure, args.pressure_rtol, args.seed)
    proto_sizes = [tuple(int(v) for v in s.split(":")) for s in args.protocol_sizes]
    proto = protocol_runs(proto_sizes, [(1e-4, 2e-8), (1e-6, 2e-12)], args.protocol_seeds)
    for d, n in proto_sizes:
        for p0 in (1e-4, 1e-6):
            sel = [r for r in proto if r["d"] == d and r["level_pressure"] == p0]
            tb = sum(r["time_s"] for r in sel if not r["energy_protocol"])
            te = sum(r["time_s"] for r in sel if r["energy_protocol"])
            print(f"protocols d={d} N~{n} P0 {p0:g}: energy / bisection time {te / tb:.2f} "
                  f"(sums over {len(sel) // 2} starts: {te:.1f} s / {tb:.1f} s)")
    hess = hessian_runs(args.hessian_sizes, args.pressure, args.seed)
    n = np.array([r["n"] for r in hess], float)
    fits = {}
    for key in ("hessian_s", "compliance_s"):
        t = np.array([r[key] for r in hess])
        fits[key] = float(np.polyfit(np.log(n), np.log(t), 1)[0]) if len(n) > 1 else float("nan")
        print(f"{key.split('_')[0]} time ~ N^{fits[key]:.2f}")

    def block(rows: list[dict], dim: str) -> dict:
        return {(f"{dim}_{k}" if dim == "protocol_run" else k): ((dim,), [r[k] for r in rows],
                                                                   {"units": "1", "long_name": k.replace("_", " ")})
                for k in (rows[0] if rows else {})}

    ds = xr.Dataset(
        {**block(jam, "run"), **block(proto, "protocol_run"), **block(hess, "size")},
        attrs=new_dataset_attrs("jamflow chains benchmark", vars(args), hessian_exponent=fits["hessian_s"],
                                compliance_exponent=fits["compliance_s"],
                                note="wall times on 2 shared cores; compare ratios within this run"),
    )
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "chains.nc")
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 3.8))
    labels = [f"d={r['d']} N={r['n']}\n{'shear' if r['shear'] else 'fixed'}" for r in jam]
    a.bar(range(len(jam)), [r["cpu_ratio"] for r in jam])
    a.axhline(1.0, color="k", lw=0.8, ls=":")
    a.set_xticks(range(len(jam)), labels, fontsize=6, rotation=60)
    a.set_xlabel("linked packing (d, N spheres, box)")
    a.set_ylabel("jamming CPU time / spheres' (1)")
    for d, n0 in proto_sizes:
        for p0, marker in ((1e-4, "o"), (1e-6, "s")):
            sel = [r for r in proto if r["d"] == d and r["level_pressure"] == p0]
            tb = [r["time_s"] for r in sel if not r["energy_protocol"]]
            te = [r["time_s"] for r in sel if r["energy_protocol"]]
            c.loglog(tb, te, marker, label=f"d={d} N~{n0}, P0={p0:g}")
    lim = [min([r["time_s"] for r in proto], default=0.1), max([r["time_s"] for r in proto], default=1.0)]
    c.loglog(lim, lim, "k:", lw=1)
    c.set_xlabel("bisection to P0: wall time (s)")
    c.set_ylabel("energy-scaling steps: wall time (s)")
    if proto:
        c.legend(fontsize=7)
    else:
        c.text(0.5, 0.5, "protocol comparison not run", transform=c.transAxes, ha="center")
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
