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

``--whole`` instead times the whole ``jamflow soft-jam`` command (a process each, CPU time
of the child, start-up included) of bidisperse linked starts (size ratio 1.4, half the
clusters large; ``jamflow init-chains --dispersity bi``) at fixed box and shear-stabilised
against the same start with the links dropped (bidisperse spheres), the three runs of a
start alternating, ``--seeds`` starts per size; writes ``chains_whole.nc`` and ``.png``
(``chains_whole_newton`` with ``--newton-polish``: the fixed-box linked runs end their final minimisations by Newton).

Usage: ``python benchmarks/chains.py [--sizes 2:150 3:256 ...] [--hessian-sizes 30 60 120]
[--pressure 1e-4] [--pressure-rtol 1e-3] [--whole [--seeds 3] [--boxes fixed shear]]``; the defaults are the issue's sizes (2D rigid
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
import resource
import subprocess
import sys
import tempfile
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
from _cells import cell_bars, rows_dataset, save_chart

from jamflow.chains.builders import linked_packing
from jamflow.chains.compliance import compliance
from jamflow.chains.hessian import constrained_hessian
from jamflow.chains.jamming import jam_linked
from jamflow.io import (
    new_dataset_attrs,
    read_dataset,
    read_packing,
    write_dataset,
    write_packing,
)
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

#: Whole-command targets of issue 46: linked CPU time over the spheres' (fixed box, shear-stabilised).
WHOLE_TARGETS = {0: 2.0, 1: 3.0}

#: The console script of the running interpreter's environment.
JAMFLOW = str(Path(sys.executable).with_name("jamflow"))


def _child_cpu(cmd: list[str]) -> float:
    """CPU time (user + system) of one child process running ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def whole_runs(sizes: list[tuple[int, int]], seeds: int, pressure: float, rtol: float,
               boxes: tuple[str, ...] = ("fixed", "shear"), polish: bool = False) -> list[dict]:
    """``jamflow soft-jam`` of linked starts (``boxes``: fixed box, shear-stabilised; ``polish``: the fixed-box
    runs with ``--newton-polish``, which a shear-stabilised run refuses) and of the same starts without links."""
    linked = ["--newton-polish"] if polish else []
    jam = [JAMFLOW, "soft-jam", "--quiet", "--pressure", f"{pressure:g}", "--force-tol",
           "1e-12", "--pressure-rtol", f"{rtol:g}", "--delta-phi", "1e-2"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        # untimed warm-up: a run of every engine (spheres too) loads (or compiles) the kernels into the on-disk cache
        for d, n in sizes[:1] + [(3, 128)]:
            start = _whole_start(tmp, d, n if d == 2 else 128, 1)
            unlinked = tmp / "w_spheres.nc"
            write_packing(read_packing(start).evolve(links=None), unlinked)
            for src, extra in [(start, linked)] * ("fixed" in boxes) \
                    + [(start, ["--shear-stabilize"])] * ("shear" in boxes) \
                    + [(unlinked, [])]:
                subprocess.run(jam + [str(src), str(tmp / "w.nc"), "--in-place", *extra], check=True,
                               stdout=subprocess.DEVNULL)
        for d, n in sizes:
            for seed in range(1, seeds + 1):
                start = _whole_start(tmp, d, n, seed)
                spheres = tmp / "spheres.nc"
                write_packing(read_packing(start).evolve(links=None), spheres)
                cpu, attrs = {}, {}
                cases = [("spheres", spheres, []), ("fixed", start, linked),
                         ("shear", start, ["--shear-stabilize"])]
                for case, src, extra in [c for c in cases if c[0] in ("spheres", *boxes)]:
                    out = tmp / f"{case}_out.nc"
                    cpu[case] = _child_cpu(jam + [str(src), str(out), "--in-place", *extra])
                    attrs[case] = read_dataset(out).attrs
                for shear, case in [(s, c) for s, c in ((0, "fixed"), (1, "shear")) if c in boxes]:
                    a, b = attrs[case], attrs["spheres"]
                    rows.append({"d": d, "n": n, "seed": seed, "shear": shear, "cpu_s": cpu[case],
                                 "sphere_cpu_s": cpu["spheres"], "cpu_ratio": cpu[case] / cpu["spheres"],
                                 "steps": int(a["fire_steps"]), "sphere_steps": int(b["fire_steps"]),
                                 "minimisations": int(a["onset_minimizations"]),
                                 "sphere_minimisations": int(b["onset_minimizations"]),
                                 "phi": float(a["packing_fraction"]), "sphere_phi": float(b["packing_fraction"]),
                                 "n_contacts": int(a["n_contacts"]), "isostatic_count": int(a["isostatic_count"]),
                                 "max_link_error": float(a["max_link_error"])})
                    r = rows[-1]
                    print(f"whole soft-jam d={d} N={n} seed {seed} {'shear-stabilised' if shear else 'fixed box'}: "
                          f"CPU {r['cpu_s']:.2f} s / spheres {r['sphere_cpu_s']:.2f} s = {r['cpu_ratio']:.2f} "
                          f"(target <= {WHOLE_TARGETS[shear]:g}); FIRE steps {r['steps']} / {r['sphere_steps']}, "
                          f"minimisations {r['minimisations']} / {r['sphere_minimisations']}, phi {r['phi']:.5f} / "
                          f"{r['sphere_phi']:.5f}, N_c {r['n_contacts']} / iso {r['isostatic_count']}, "
                          f"link error {r['max_link_error']:.1e}", flush=True)
    for d, n in sizes:
        for shear in [s for s, c in ((0, "fixed"), (1, "shear")) if c in boxes]:
            sel = [r for r in rows if r["d"] == d and r["n"] == n and r["shear"] == shear]
            ratio = sum(r["cpu_s"] for r in sel) / sum(r["sphere_cpu_s"] for r in sel)
            per_step = [1e6 * r["cpu_s"] / r["steps"] for r in sel]
            print(f"whole soft-jam d={d} N={n} {'shear-stabilised' if shear else 'fixed box'}: CPU ratio of the sums "
                  f"over {len(sel)} starts {ratio:.2f} ({'met' if ratio <= WHOLE_TARGETS[shear] else 'MISSED'}, "
                  f"target <= {WHOLE_TARGETS[shear]:g}; per-start {min(r['cpu_ratio'] for r in sel):.2f}-"
                  f"{max(r['cpu_ratio'] for r in sel):.2f}); steps {sum(r['steps'] for r in sel)} against "
                  f"{sum(r['sphere_steps'] for r in sel)}; whole-command CPU per step {min(per_step):.0f}-"
                  f"{max(per_step):.0f} us", flush=True)
    return rows


def _whole_start(tmp: Path, d: int, n: int, seed: int) -> Path:
    """A bidisperse dilute linked start by ``jamflow init-chains``: 2D rigid trimers, 3D chains of 4 (frozen angles)."""
    path = tmp / f"start_{d}_{n}_{seed}.nc"
    shape = ["--cluster", "trimer", "--clusters", str(n // 3)] if d == 2 else \
        ["--cluster", "chain", "--chain-length", "4", "--clusters", str(n // 4)]
    subprocess.run([JAMFLOW, "init-chains", "--quiet", "--d", str(d), *shape,
                    "--dispersity", "bi", "--ratio", "1.4", "--seed", str(seed), str(path)], check=True,
                   stdout=subprocess.DEVNULL)
    return path


def whole_output(rows: list[dict], args: argparse.Namespace) -> None:
    """``chains_whole.nc`` (``chains_whole_newton.nc`` with ``--newton-polish``) and a bar chart of the CPU ratios
    against the targets."""
    ds = rows_dataset(rows, "jamflow chains benchmark: whole soft-jam against spheres", args,
                      "CPU time of each soft-jam process on 2 shared cores, start-up included; compare ratios "
                      "within this run")
    OUT.mkdir(exist_ok=True)
    name = "chains_whole_newton" if args.newton_polish else "chains_whole"
    write_dataset(ds, OUT / f"{name}.nc")
    fig, ax = plt.subplots(figsize=(7, 3.8))
    cells = sorted({(r["d"], r["n"], r["shear"]) for r in rows})
    points = [[r["cpu_ratio"] for r in rows if (r["d"], r["n"], r["shear"]) == cell] for cell in cells]
    cell_bars(ax, [float(np.median(p)) for p in points], points, [s for *_, s in cells],
              [f"d={d} N={n}\n{'shear' if s else 'fixed'}" for d, n, s in cells], fontsize=7)
    for k, (*_, shear) in enumerate(cells):
        ax.hlines(WHOLE_TARGETS[shear], k - 0.4, k + 0.4, colors="r", lw=1.2)
    save_chart(fig, ax, "linked packing (d, N spheres, box); red: target", "soft-jam CPU time / spheres' (1)",
               OUT / name)


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
    ap.add_argument("--whole", action="store_true",
                    help="only the whole soft-jam command against spheres (bidisperse starts, CPU of each process)")
    ap.add_argument("--seeds", type=int, default=2, help="starts per size of --whole")
    ap.add_argument("--boxes", nargs="+", choices=("fixed", "shear"), default=["fixed", "shear"],
                    help="linked cells of --whole: fixed box, shear-stabilised")
    ap.add_argument("--newton-polish", action="store_true",
                    help="fixed-box linked runs of --whole with soft-jam --newton-polish (the constrained Newton polish)")
    args = ap.parse_args()
    sizes = [tuple(int(v) for v in s.split(":")) for s in args.sizes]
    if args.whole:
        whole_output(whole_runs(sizes, args.seeds, args.pressure, args.pressure_rtol, tuple(args.boxes),
                                args.newton_polish), args)
        return
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
