"""CALiPPSO: time to jam, LP counts, scaling with N, solver strategies, relaxation, tolerances.

Every timed run is the whole ``jamflow calippso IN OUT`` command in a child process
(its wall time and peak resident memory from ``os.wait4``), as in the issue's targets.
Parts (d = 3 monodisperse unless stated):

``scaling``
    Time to jam, number of LPs and median LP time against N = 256 ... 4096 (``--sizes``) from
    random starts (RSA at phi0 = 0.3) and from near-jamming starts (an LS compression,
    fast stage kappa0 = 5e-3 to p = 500 then kappa = ``--near-kappa``, 1e-4 by default, to
    p = ``NEAR_PRESSURE``; at 1e-4 a start obeys ``(phi_J - phi) / phi = d / p`` as the
    paper's starts do, at 1e-3 it is 6-66 times further below its phi_J than its pressure
    says and its chain takes 5-25 times more LPs: ``--near-kappa 1e-3`` gives the starts of the
    warm-LP studies),
    ``--seeds`` starts of each kind per N (the LP count of a chain moves with the
    vertex each LP ends at, so one seed per N can put the exponent anywhere), with
    least-squares exponents over every (N, seed) and their standard errors, over all
    N and over N >= 1024, next to the paper's (total ~ N^3, t_LP ~ N^2.34,
    n ~ N^1.04).
``ls``
    The LS examples of the CALiPPSO authors (N = 1024, d = 3, 4, 5) against the
    targets 5 s, 15 s and 40 s.
``large``
    N = 16384 (``--large-n``) from a near-jamming start: target 30 min, 8 GB. The chain is
    checkpointed: run the part again to go on with a chain that was stopped or killed.
``fit``
    The exponents of total time, LPs and median LP time against N over every stored chain
    of the near starts of ``--near-kappa`` (the outputs of ``scaling`` and ``large``, which
    may come from several runs), with their standard errors; runs nothing.
``factor``
    Profile of a warm LP: its time is the LU factorisation of the simplex basis (perf:
    ~95 % in HiGHS ``HFactor::buildKernel`` at N = 4096), not the pivots. For each
    converged near-start output of ``scaling`` the final basis (the isostatic contact
    rows over the stable particles' coordinates and ``g``, a square sparse matrix) is
    factorised by HiGHS (a run stopped after its first factorisation) and by SuperLU
    with the COLAMD ordering and, when ``pymetis`` is installed (``pip install -e
    ".[bench]"``), with a METIS nested-dissection ordering of the contact graph, with
    the fill of the LU factors and fitted exponents.
``solvers``
    ipm, simplex, hybrid and ipm-center on the d = 3 LS example.
``lp``
    One LP, the first of the d = 3 LS example (``jamming_lp``), by every HiGHS method:
    interior point with and without crossover, PDLP, cold dual and primal simplex.
    Time, status, g and how the row duals split into active and inactive (counts
    above 1e-10, 1e-6 and 1e-3 of the largest): only a vertex solution has inactive
    duals exactly zero, which the contact detection needs.
``preset``
    Whether a ``fast`` preset is worth having: the former fast setting (``--tol-s 1e-6
    --tol-gamma 1e-9``) against the defaults (the paper's tolerances, the
    ``publication`` setting), run alternately side by side on the d = 3 LS example and a
    3D N = 256 random start; the issue asked for at least 1.5x on both, or no preset.
``finish``
    The Newton finish against the pure LP chain (``--finish newton`` vs ``--finish lp``)
    on the whole command, side by side: the authors' LS examples (N = 1024, d = 3, 4, 5)
    and the d = 3 one tiled 2x1x1 (N = 2048) and 2x2x1 (N = 4096; near-jamming starts
    without an LS run, but the tiling's symmetry can make the packing degenerate); LPs, time, the Newton attempts and whether both give the same contacts
    (Q) and forces (largest difference over the largest force).
``scale``
    The warm simplex LPs unscaled (``WARM_SIMPLEX_SCALE``, the default) against HiGHS's
    equilibration, in-process, one after the other: the LS examples and six 3D
    N = 1024 near starts (and N = 2048 with ``--max-scale 2048``); LPs, pivots, LP time
    and whether both end in the same packing (Q, largest force difference, phi_J).
``engine``
    Whole chains with the warm LPs by HiGHS and by jamflow.simplex (``--warm-engine
    highs`` / ``jamflow``), one after the other: the LS examples and ``--seeds`` near
    starts per N of ``--engine-cases``; wall and CPU time, LPs, pivots, fallbacks, whether
    both end in the same packing (Q, forces, phi_J), and ``jamflow certify`` of every
    output. ``--engines auto highs`` compares another pair (e.g. the default against HiGHS).
``relax``
    LP counts with and without the Sec. IV relaxation c = 0.5 (random starts).
``tolerances``
    tol_s / tol_gamma and the HiGHS tolerance: time against max overlap, force-balance
    residual and isostaticity on the d = 3 LS example.

Each part writes ``benchmarks/output/calippso_<part>.nc``; ``calippso.png`` plots
every part found. Starts are cached as ``benchmarks/output/calippso_start_*.nc``.
Run: ``python benchmarks/calippso.py [--quick] [--parts PART ...]``. ``--jobs 2`` runs the
whole commands of ``scaling`` two at a time, each a child process with one HiGHS
thread: LP counts and results do not depend on it, times include the other run's
memory traffic (the fourth measurement of ``docs/notes/calippso-scaling.md`` ran so).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import highspy
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import scipy.stats
import xarray as xr
from matplotlib.ticker import NullFormatter
from numpy.typing import NDArray

import jamflow.protocols.calippso as cal
import jamflow.protocols.calippso.solver as cal_solver
from jamflow.analysis.contacts import summarize
from jamflow.analysis.overlap import contact_overlap
from jamflow.box import Box
from jamflow.highs import new_highs
from jamflow.io import (
    new_dataset_attrs,
    read_dataset,
    read_packing,
    write_dataset,
    write_packing,
)
from jamflow.io.formats import read_dat
from jamflow.network.rigidity import rigidity_matrix
from jamflow.network.spheres import force_balance_residual
from jamflow.protocols.calippso import (
    CONTACT_DUAL_REL_TOL,
    SOLVER_TOL,
    JammingLP,
    jamming_lp,
)
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import compress
from jamflow.state.packing import Packing, max_overlap

OUT = Path(__file__).resolve().parent / "output"
#: the CALiPPSO authors' LS examples, vendored with the tests (MIT, licence in its README.md)
LS = Path(__file__).resolve().parents[1] / "tests" / "data" / "calippso-ls"

PARTS = ("scaling", "ls", "preset", "finish", "scale", "engine", "solvers", "lp", "relax", "tolerances", "large",
         "fit", "factor")
#: the former ``fast`` preset of ``jamflow calippso`` (dropped: not faster, part ``preset``)
FORMER_FAST = ("--tol-s", "1e-6", "--tol-gamma", "1e-9")
#: LS pressure of the near-jamming starts: the paper's Sec. IV value. (At 1e6 the
#: chain is longer: 3D N = 2048 needed 220 LPs from p = 1e6 and 86 from 1e7 of the
#: same compression.)
NEAR_PRESSURE = 1e7
#: LS growth rate of the near-jamming starts (``--near-kappa``). Its starts obey the
#: free-volume equation of state (phi_J - phi) / phi = d / p to 0.5-11 %, as the paper's do;
#: the paper's own 1e-5 (its Fig. 5) would add hours of LS at N = 16384
#: (docs/notes/warm-simplex.md, "The start's compression rate").
NEAR_KAPPA = 1e-4
#: The faster compression of the warm-LP studies (``warm_lp.py``, ``calippso_tail.py``,
#: ``calippso_clp.py``): its starts lie 6-66 times further below phi_J than d / p, and
#: their chains have the long wandering tail those studies measure. Its files keep the
#: plain ``near`` names.
FAST_KAPPA = 1e-3
#: Issue 19 targets for the whole command on the LS examples [s] (issue 9 had 10, 40, 120).
LS_TARGETS = {3: 5.0, 4: 15.0, 5: 40.0}
PAPER_EXPONENTS = {"time": 3.0, "t_lp": 2.34, "lps": 1.04}
#: N of the 'scaling' part by default (``--sizes``)
SCALING_SIZES = (256, 512, 1024, 2048, 4096)
METRICS = ("time", "cpu_time", "peak_memory", "lps", "t_lp", "phi", "overlap", "fb", "iso")
#: units of the quantities the parts store that have one (the others are counts or ratios)
UNITS = {"time": "s", "cpu_time": "s", "peak_memory": "B", "t_lp": "s", "t_lps": "s"}


def command(start: Path, tag: str, *options: str) -> dict[str, float]:
    """Run ``jamflow calippso`` on ``start``; wall and CPU time, peak memory and the checks."""
    out = OUT / f"calippso_out_{tag}.nc"
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "jamflow", "calippso", str(start), str(out), "--quiet", *options])
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    row = dict.fromkeys(METRICS, np.nan)
    row.update(time=wall, cpu_time=usage.ru_utime + usage.ru_stime, peak_memory=usage.ru_maxrss * 1024.0)
    if os.waitstatus_to_exitcode(status) != 0:
        print(f"   {tag}: failed after {wall:.1f} s", flush=True)
        return row
    ds = read_dataset(out)
    q = read_packing(out)
    s = summarize(q)
    row.update(lps=float(ds.attrs["iterations"]), t_lp=float(np.median(ds["lp_time"].values)), phi=q.packing_fraction,
               overlap=max_overlap(q)[1], fb=float(force_balance_residual(q)[~q.rattler].max()), iso=float(s.isostatic))
    print(f"   {tag}: {wall:7.2f} s (CPU {row['cpu_time']:.2f} s)  {int(row['lps']):3d} LPs  median LP {row['t_lp']:.3f} s  phi_J {row['phi']:.7f}  "
          f"iso {s.isostatic} (Nc {s.n_contacts} vs {s.isostatic_count})  overlap {row['overlap']:.1e}  "
          f"fb {row['fb']:.1e}  peak {row['peak_memory'] / 2**30:.2f} GiB", flush=True)
    return row


def random_start(n: int, seed: int = 1) -> Path:
    path = OUT / f"calippso_start_random_N{n}_s{seed}.nc"
    if not path.exists():
        write_packing(random_packing(n, 3, 0.3, "mono", seed=seed), path)
    return path


def near_tag(kappa: float | None = None) -> str:
    """``near`` for starts compressed at :data:`FAST_KAPPA`, ``near_k<kappa>`` for others
    (``kappa`` is :data:`NEAR_KAPPA` when not given)."""
    kappa = NEAR_KAPPA if kappa is None else kappa
    return "near" if kappa == FAST_KAPPA else f"near_k{kappa:.0e}"


def near_start(n: int, seed: int = 1, kappa: float | None = None) -> Path:
    """The LS compression of a random start to :data:`NEAR_PRESSURE` at growth rate
    ``kappa`` (:data:`NEAR_KAPPA` when not given), cached."""
    kappa = NEAR_KAPPA if kappa is None else kappa
    rate = "" if kappa == FAST_KAPPA else f"_k{kappa:.0e}"
    path = OUT / f"calippso_start_ls{rate}_p{NEAR_PRESSURE:.0e}_N{n}_s{seed}.nc"
    if not path.exists():
        t0 = time.perf_counter()
        snap = compress(random_packing(n, 3, 0.3, "mono", seed=seed), kappa, [NEAR_PRESSURE],
                        seed=seed).snapshots[0]
        write_packing(snap, path)
        print(f"   LS start N = {n}: p = {snap.pressure:.3g}, phi = {snap.packing_fraction:.5f} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    return path


def ls_example(d: int) -> Path:
    path = OUT / f"calippso_start_authors_d{d}.nc"
    if not path.exists():
        write_packing(read_dat(LS / f"Centers-after-LS--N-1024--d-{d}.dat"), path)
    return path


def tiled_ls_example(reps: tuple[int, int, int]) -> Path:
    """The d = 3 LS example repeated ``reps`` times along the axes of its unit box."""
    path = OUT / f"calippso_start_authors_d3_tiled{'x'.join(map(str, reps))}.nc"
    if not path.exists():
        p = read_packing(ls_example(3))
        shifts = np.stack(np.meshgrid(*[np.arange(r) for r in reps], indexing="ij"), -1).reshape(-1, 3)
        x = (p.position[None, :, :] + shifts[:, None, :].astype(float)).reshape(-1, 3)
        write_packing(Packing(position=x, diameter=np.tile(p.diameter, len(shifts)),
                              box=Box.orthogonal(np.array(reps, dtype=float)), protocol="import-dat>tile",
                              parameters={"tiles": list(reps)}), path)
    return path


def table(rows: list[dict[str, float]], dim: str, coords, attrs: dict) -> xr.Dataset:
    data = {m: ((dim,), np.array([r[m] for r in rows], float), {"units": UNITS.get(m, "1")}) for m in METRICS}
    return xr.Dataset(data, coords={dim: coords}, attrs=attrs)


def fit(n, y) -> float:
    """Least-squares exponent of ``y ~ n^a`` over the finite points."""
    return fit_with_error(n, y)[0]


def fit_with_error(n, y) -> tuple[float, float]:
    """Least-squares exponent of ``y ~ n^a`` over the finite points (repeated n allowed)
    and its standard error; the error is NaN with fewer than three points, both are NaN
    with fewer than two distinct n."""
    n, y = np.ravel(n).astype(float), np.ravel(y).astype(float)
    ok = np.isfinite(y) & (y > 0)
    if len(np.unique(n[ok])) < 2:
        return np.nan, np.nan
    r = scipy.stats.linregress(np.log(n[ok]), np.log(y[ok]))
    return float(r.slope), float(r.stderr) if ok.sum() >= 3 else np.nan


def median_over_seeds(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Median over the last axis (seeds) of the finite values; NaN where there are none."""
    return np.array([np.median(v[np.isfinite(v)]) if np.isfinite(v).any() else np.nan for v in values])


def part_scaling(quick: bool, max_random: int, seeds: int, jobs: int,
                 sizes: tuple[int, ...] = SCALING_SIZES, first_seed: int = 1) -> xr.Dataset:
    sizes = np.array([128, 256] if quick else sorted(sizes))
    kinds = {"random": random_start, "near": near_start}
    seed_list = list(range(first_seed, seeds + 1))
    tasks = [(kind, int(n), seed) for kind in kinds for n in sizes for seed in seed_list
             if not (kind == "random" and n > max_random)]
    starts = {t: kinds[t[0]](t[1], t[2]) for t in tasks}  # LS compressions run here, one at a time

    def run(task: tuple[str, int, int]) -> dict[str, float]:
        kind, n, seed = task
        print(f"N = {n}, {kind} start, seed {seed}", flush=True)
        return command(starts[task], f"{near_tag() if kind == 'near' else kind}_N{n}_s{seed}")

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        done = dict(zip(tasks, pool.map(run, tasks)))
    missing = dict.fromkeys(METRICS, np.nan)
    data = {m: (("start", "N", "seed"), np.array([[[done.get((kind, int(n), seed), missing)[m] for seed in seed_list]
                                                   for n in sizes] for kind in kinds]),
                {"units": UNITS.get(m, "1")}) for m in METRICS}
    ds = xr.Dataset(data, coords={"start": list(kinds), "N": sizes, "seed": seed_list})
    exps = {}
    grid = np.broadcast_to(sizes[:, None], (len(sizes), len(seed_list)))
    for kind in sorted({t[0] for t in tasks}, key=list(kinds).index):
        for k in PAPER_EXPONENTS:
            y = ds[k].sel(start=kind).values
            for suffix, keep in (("", sizes > 0), ("_from_1024", sizes >= 1024)):
                a, err = fit_with_error(grid[keep], y[keep])
                exps[f"exponent_{kind}_{k}{suffix}"], exps[f"exponent_{kind}_{k}{suffix}_err"] = a, err
        times, lps = (median_over_seeds(ds[k].sel(start=kind).values) for k in ("time", "lps"))
        print(f"{kind} starts, medians over {len(seed_list)} seed(s): "
              + ", ".join(f"N = {n}: {t:.2f} s, {l:.0f} LPs" for n, t, l in zip(sizes, times, lps) if np.isfinite(t)),
              flush=True)
        print(f"{kind} starts, fitted exponents (all N | N >= 1024), paper in brackets: "
              + "; ".join(f"{k} {exps[f'exponent_{kind}_{k}']:.2f} ± {exps[f'exponent_{kind}_{k}_err']:.2f} | "
                          f"{exps[f'exponent_{kind}_{k}_from_1024']:.2f} ± {exps[f'exponent_{kind}_{k}_from_1024_err']:.2f}"
                          f" ({PAPER_EXPONENTS[k]:g})" for k in PAPER_EXPONENTS), flush=True)
    ds.attrs.update(new_dataset_attrs("CALiPPSO scaling with N",
                                      {"quick": quick, "near_pressure": NEAR_PRESSURE, "near_kappa": NEAR_KAPPA,
                                       "seeds": seed_list, "jobs": jobs,
                                       "max_random": max_random},
                                      **exps, **{f"paper_exponent_{k}": v for k, v in PAPER_EXPONENTS.items()}))
    return ds


def part_ls(quick: bool) -> xr.Dataset:
    dims = [3] if quick else [3, 4, 5]
    rows = []
    for d in dims:
        print(f"LS example d = {d} (target {LS_TARGETS[d]:g} s)", flush=True)
        rows.append(command(ls_example(d), f"authors_d{d}"))
    ds = table(rows, "d", dims, new_dataset_attrs("CALiPPSO on the authors' LS examples", {"quick": quick}))
    ds["target_time"] = (("d",), np.array([LS_TARGETS[d] for d in dims]), {"units": "s"})
    return ds


def part_preset(quick: bool) -> xr.Dataset:
    starts = {"ls_d3": ls_example(3), "random_N256": random_start(128 if quick else 256)}
    parts = []
    for name, start in starts.items():
        rows = []
        for setting, options in (("publication", ()), ("former_fast", FORMER_FAST)):
            print(f"{name}: {setting}", flush=True)
            rows.append(command(start, f"preset_{name}_{setting}", *options))
        ds = table(rows, "setting", ["publication", "former_fast"], {})
        speedup = float(ds["time"][0] / ds["time"][1])
        print(f"   {name}: speed-up of the former fast setting {speedup:.2f}x (target >= 1.5x)", flush=True)
        parts.append(ds.expand_dims(start=[name]).assign(speedup=(("start",), [speedup], {"units": "1"})))
    return xr.concat(parts, "start").assign_attrs(new_dataset_attrs(
        "CALiPPSO: former fast preset against the paper's tolerances", {"quick": quick}))


def force_difference(p: Packing, ref: Packing) -> float:
    """Largest difference of a contact's force between ``p`` and ``ref`` over the
    largest force of ``ref`` (a contact of ``ref`` absent from ``p`` counts with force 0)."""
    f_ref = dict(zip(map(tuple, np.sort(ref.contacts, axis=1).tolist()), ref.force))
    f_p = dict(zip(map(tuple, np.sort(p.contacts, axis=1).tolist()), p.force))
    return max(abs(f_p.get(k, 0.0) - v) for k, v in f_ref.items()) / max(f_ref.values())


def part_finish(quick: bool, max_n: int) -> xr.Dataset:
    starts = {"ls_d3": (1024, ls_example(3)), "ls_d4": (1024, ls_example(4)), "ls_d5": (1024, ls_example(5)),
              "ls_d3_tiled2x1x1": (2048, tiled_ls_example((2, 1, 1))),
              "ls_d3_tiled2x2x1": (4096, tiled_ls_example((2, 2, 1)))}
    cases = ["ls_d3"] if quick else [c for c, (n, _) in starts.items() if n <= max_n]
    parts = []
    for case in cases:
        start = starts[case][1]
        rows = []
        for finish in ("lp", "newton"):
            print(f"{case}: --finish {finish}", flush=True)
            row = command(start, f"finish_{case}_{finish}", "--finish", finish)
            ds = read_dataset(OUT / f"calippso_out_finish_{case}_{finish}.nc")
            row.update(newton_attempts=float(ds.attrs["newton_attempts"]), newton_time=float(ds.attrs["newton_time"]),
                       lps=float(ds.attrs["n_lps"]))
            rows.append(row)
        lp, nw = (read_packing(OUT / f"calippso_out_finish_{case}_{f}.nc") for f in ("lp", "newton"))
        q = contact_overlap(nw, lp)[0]
        df = force_difference(nw, lp)
        print(f"   {case}: Q = {q:.6f}, max |df| / max f = {df:.2e}, LPs {rows[0]['lps']:.0f} -> {rows[1]['lps']:.0f}, "
              f"time {rows[0]['time']:.1f} -> {rows[1]['time']:.1f} s (x{rows[0]['time'] / rows[1]['time']:.2f})",
              flush=True)
        ds = table(rows, "finish", ["lp", "newton"], {})
        ds = ds.assign(newton_attempts=(("finish",), [r["newton_attempts"] for r in rows], {"units": "1"}),
                       newton_time=(("finish",), [r["newton_time"] for r in rows], {"units": "s"}),
                       contact_overlap=((), q, {"units": "1", "long_name": "Q of the Newton finish against the LP chain"}),
                       force_difference=((), df, {"units": "1", "long_name": "max |f_newton - f_lp| / max f_lp"}),
                       n=((), lp.n, {"units": "1", "long_name": "number of spheres"}))
        parts.append(ds.expand_dims(case=[case]))
    return xr.concat(parts, "case").assign_attrs(new_dataset_attrs(
        "CALiPPSO: Newton finish against the pure LP chain (the authors' LS examples and tilings)", {"quick": quick}))


def part_scale(quick: bool, max_n: int) -> xr.Dataset:
    starts = {"ls_d3": ls_example(3)}
    if not quick:
        starts.update({"ls_d4": ls_example(4), "ls_d5": ls_example(5)})
        starts.update({f"{near_tag()}_N1024_s{seed}": near_start(1024, seed) for seed in range(1, 7)})
        if max_n >= 2048:
            starts[f"{near_tag()}_N2048_s1"] = near_start(2048)
    # HiGHS's own scaling is the module's private default for cold LPs
    variants = {"scaled": cal_solver._HIGHS_SCALE, "unscaled": cal_solver.WARM_SIMPLEX_SCALE}
    parts = []
    for case, path in starts.items():
        start = read_packing(path)
        results, rows = {}, []
        for name, scale in variants.items():
            cal_solver.WARM_SIMPLEX_SCALE = scale
            try:
                t0 = time.perf_counter()
                res = cal.calippso(start)
                wall = time.perf_counter() - t0
            finally:
                cal_solver.WARM_SIMPLEX_SCALE = variants["unscaled"]
            h = res.history
            results[name] = res.packing
            rows.append(dict(time=wall, t_lps=float(h["lp_time"].sum()), lps=float(res.iterations),
                             pivots=float(h["simplex_iterations"].sum()), phi=res.packing.packing_fraction))
        a, b = results["scaled"], results["unscaled"]
        q = contact_overlap(b, a)[0]
        df = force_difference(b, a)
        print(f"   {case}: LPs {rows[0]['lps']:.0f} -> {rows[1]['lps']:.0f}, pivots {rows[0]['pivots']:.0f} -> "
              f"{rows[1]['pivots']:.0f}, LP time {rows[0]['t_lps']:.2f} -> {rows[1]['t_lps']:.2f} s, "
              f"Q = {q:.4f}, max |df| / max f = {df:.1e}, phi_J {rows[0]['phi']:.10f} -> {rows[1]['phi']:.10f}",
              flush=True)
        data = {k: (("scaling",), [r[k] for r in rows], {"units": UNITS.get(k, "1")}) for k in rows[0]}
        ds = xr.Dataset(data, coords={"scaling": list(variants)})
        ds = ds.assign(contact_overlap=((), q, {"units": "1", "long_name": "Q of unscaled against scaled"}),
                       force_difference=((), df, {"units": "1", "long_name": "max |f_unscaled - f_scaled| / max f"}))
        parts.append(ds.expand_dims(case=[case]))
    return xr.concat(parts, "case").assign_attrs(new_dataset_attrs(
        "CALiPPSO: warm simplex LPs with and without HiGHS's scaling", {"quick": quick, "max_n": max_n}))


def certified(out: Path) -> str:
    """``jamflow certify``'s classification of a CALiPPSO output (collective jamming)."""
    cert = out.with_name(out.stem + "_certificate.nc")
    subprocess.run([sys.executable, "-m", "jamflow", "certify", str(out), str(cert), "--quiet"], check=True)
    return str(read_dataset(cert).attrs["classification"])


def part_engine(quick: bool, cases: list[str], seeds: int,
                engines: tuple[str, str] = ("highs", "jamflow")) -> xr.Dataset:
    """Whole chains with the warm LPs by two engines (``--warm-engine``; by default HiGHS
    and jamflow.simplex), the two commands one after the other, their order alternating
    between starts: time, LPs, pivots, jamflow's fallbacks to HiGHS, and whether they end
    in the same packing (Q, largest force difference over the largest force, phi_J); every
    output is also checked (isostatic, overlap, force balance) and certified by ``jamflow
    certify``."""
    starts = {"ls_d3": ls_example(3)} if quick or "ls" in cases else {}
    if not quick:
        if "ls" in cases:
            starts.update({"ls_d4": ls_example(4), "ls_d5": ls_example(5)})
        for n in sorted(int(c) for c in cases if c != "ls"):
            starts.update({f"{near_tag()}_N{n}_s{seed}": near_start(n, seed) for seed in range(1, seeds + 1)})
    ref, alt = engines
    parts = []
    for k, (case, start) in enumerate(starts.items()):
        rows = {}
        for engine in (engines if k % 2 == 0 else engines[::-1]):
            print(f"{case}: --warm-engine {engine}", flush=True)
            row = command(start, f"engine_{case}_{engine}", "--warm-engine", engine)
            out = OUT / f"calippso_out_engine_{case}_{engine}.nc"
            ds = read_dataset(out)
            row.update(pivots=float(ds["simplex_iterations"].sum()), fallbacks=float(ds.attrs["warm_fallbacks"]),
                       warm_jamflow=float(ds.attrs["warm_lps_jamflow"]), lps=float(ds.attrs["n_lps"]),
                       t_lps=float(ds.attrs["lp_time_total"]))
            row["certified"] = certified(out)
            rows[engine] = row
        a, b = (read_packing(OUT / f"calippso_out_engine_{case}_{e}.nc") for e in engines)
        q, df = contact_overlap(b, a)[0], force_difference(b, a)
        dphi = b.packing_fraction - a.packing_fraction
        print(f"   {case}: {ref} -> {alt}: Q = {q:.6f}, max |df| / max f = {df:.1e}, phi_J "
              f"{a.packing_fraction:.10f} -> {b.packing_fraction:.10f}, LPs {rows[ref]['lps']:.0f} -> "
              f"{rows[alt]['lps']:.0f}, time {rows[ref]['time']:.1f} -> {rows[alt]['time']:.1f} s (CPU "
              f"{rows[ref]['cpu_time']:.1f} -> {rows[alt]['cpu_time']:.1f} s), warm LPs by jamflow "
              f"{rows[ref]['warm_jamflow']:.0f} / {rows[alt]['warm_jamflow']:.0f}, fallbacks "
              f"{rows[ref]['fallbacks']:.0f} / {rows[alt]['fallbacks']:.0f}, certified {rows[ref]['certified']} / "
              f"{rows[alt]['certified']}", flush=True)
        numeric = [m for m in rows[ref] if m != "certified"]
        data = {m: (("engine",), [rows[e][m] for e in engines], {"units": UNITS.get(m, "1")}) for m in numeric}
        data["certified"] = (("engine",), [rows[e]["certified"] for e in engines])
        ds = xr.Dataset(data, coords={"engine": list(engines)})
        ds = ds.assign(contact_overlap=((), q, {"units": "1", "long_name": f"Q of {alt}'s packing against {ref}'s"}),
                       force_difference=((), df, {"units": "1", "long_name": f"max |f_{alt} - f_{ref}| / max f"}),
                       phi_difference=((), dphi, {"units": "1", "long_name": f"phi_J({alt}) - phi_J({ref})"}),
                       n=((), a.n, {"units": "1", "long_name": "number of spheres"}))
        parts.append(ds.expand_dims(case=[case]))
    return xr.concat(parts, "case").assign_attrs(new_dataset_attrs(
        f"CALiPPSO: warm LPs by {ref} against {alt}, whole chains", {"quick": quick, "cases": cases,
                                                                    "seeds": seeds, "engines": list(engines)}))


def part_large(n: int, options: tuple[str, ...] = ()) -> xr.Dataset:
    """One chain at large N, checkpointed: a run stopped or killed goes on where it was
    when the part is run again; ``chain_time`` is the chain's wall time over all runs."""
    tag = f"{near_tag()}_N{n}"
    ckpt = OUT / f"calippso_ckpt_{tag}.nc"
    print(f"N = {n}, near-jamming start (N = 16384 target: < 2 h, < 12 GB), options {' '.join(options) or 'none'}; "
          f"checkpoint {ckpt}{' (resumed)' if ckpt.exists() else ''}", flush=True)
    row = command(near_start(n), tag, *options, "--checkpoint", str(ckpt))
    chain_time = np.nan
    if np.isfinite(row["lps"]):
        chain_time = float(read_dataset(OUT / f"calippso_out_{tag}.nc").attrs["total_time"])
        print(f"   chain wall time over all runs: {chain_time:.1f} s", flush=True)
    ds = table([row], "N", [n], new_dataset_attrs("CALiPPSO at large N", {"near_pressure": NEAR_PRESSURE,
                                                                          "near_kappa": NEAR_KAPPA}))
    return ds.assign(chain_time=(("N",), [chain_time], {"units": "s", "long_name": "chain wall time over all runs"}))


def part_solvers(quick: bool) -> xr.Dataset:
    start = random_start(128) if quick else ls_example(3)
    solvers = ["ipm", "simplex", "hybrid", "ipm-center"]
    rows = []
    for s in solvers:
        print(f"solver {s}", flush=True)
        rows.append(command(start, f"solver_{s}", "--solver", s))
    return table(rows, "solver", solvers, new_dataset_attrs("CALiPPSO solver strategies", {"start": start.name}))


#: HiGHS settings of each LP method of part ``lp``.
LP_METHODS = {
    "ipm": {"solver": "ipm", "run_crossover": "on"},
    "ipm-nox": {"solver": "ipm", "run_crossover": "off"},
    "pdlp": {"solver": "pdlp"},
    "dual": {"solver": "simplex", "simplex_strategy": 1},
    "primal": {"solver": "simplex", "simplex_strategy": 4},
}
#: Relative dual levels of part ``lp``.
DUAL_LEVELS = (CONTACT_DUAL_REL_TOL, 1e-6, 1e-3)


def part_lp(quick: bool) -> xr.Dataset:
    start = random_start(128) if quick else ls_example(3)
    lp = jamming_lp(read_packing(start))
    rows = []
    for name, options in LP_METHODS.items():
        h = new_highs(1)
        for key, value in {"time_limit": 600.0,
                           "primal_feasibility_tolerance": SOLVER_TOL, "dual_feasibility_tolerance": SOLVER_TOL,
                           **options}.items():
            h.setOptionValue(key, value)
        h.passModel(lp.to_highs())
        t0 = time.perf_counter()
        h.run()
        wall = time.perf_counter() - t0
        mu = np.maximum(-np.asarray(h.getSolution().row_dual), 0.0)
        counts = [int(np.sum(mu > level * mu.max())) if mu.max() > 0 else 0 for level in DUAL_LEVELS]
        g = float(h.getSolution().col_value[-1])
        rows.append(dict(time=wall, g=g, status=h.modelStatusToString(h.getModelStatus()), counts=counts))
        print(f"   {name:8s} {wall:7.2f} s  {rows[-1]['status']:10s} sqrt(Gamma)-1 {np.sqrt(1 + g) - 1:.6e}  "
              f"duals above {', '.join(f'{lv:g}: {c}' for lv, c in zip(DUAL_LEVELS, counts))}", flush=True)
    names = list(LP_METHODS)
    return xr.Dataset(
        {"time": (("method",), np.array([r["time"] for r in rows]), {"units": "s"}),
         "g": (("method",), np.array([r["g"] for r in rows]), {"units": "1", "long_name": "Gamma* - 1"}),
         "status": (("method",), np.array([r["status"] for r in rows]), {"long_name": "HiGHS model status"}),
         "n_duals_above": (("method", "level"), np.array([r["counts"] for r in rows]),
                           {"units": "1", "long_name": "row duals above level x largest dual"})},
        coords={"method": names, "level": list(DUAL_LEVELS)},
        attrs=new_dataset_attrs("One CALiPPSO LP by every HiGHS method", {"start": start.name, "rows": lp.A.shape[0]}))


def part_relax(quick: bool) -> xr.Dataset:
    seeds = [3] if quick else [1, 2, 3]
    n = 128 if quick else 256
    parts = []
    for c in (1.0, 0.5):
        rows = []
        for seed in seeds:
            print(f"relax c = {c}, seed {seed}", flush=True)
            rows.append(command(random_start(n, seed), f"relax{c}_s{seed}", *(() if c == 1.0 else ("--relax", str(c)))))
        parts.append(table(rows, "seed", seeds, {}).expand_dims(relax=[c]))
    return xr.concat(parts, "relax").assign_attrs(new_dataset_attrs("CALiPPSO Sec. IV relaxation", {"N": n}))


def part_tolerances(quick: bool) -> xr.Dataset:
    start = random_start(128) if quick else ls_example(3)
    settings = [(1e-6, 1e-9, 1e-10), (1e-7, 1e-10, 1e-10), (1e-9, 1e-12, 1e-10), (1e-9, 1e-12, 1e-9), (1e-9, 1e-12, 2e-8)]
    rows = []
    for ts, tg, tl in settings:
        print(f"tol_s {ts:g}, tol_gamma {tg:g}, solver_tol {tl:g}", flush=True)
        rows.append(command(start, f"tol_{ts:g}_{tg:g}_{tl:g}", "--tol-s", str(ts), "--tol-gamma", str(tg),
                            "--solver-tol", str(tl)))
    ds = table(rows, "setting", np.arange(len(settings)), new_dataset_attrs("CALiPPSO tolerances", {"start": start.name}))
    for k, name in enumerate(("tol_s", "tol_gamma", "solver_tol")):
        ds = ds.assign_coords({name: ("setting", [s[k] for s in settings])})
    return ds


def backbone(q: Packing) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Stable particles and the contacts between them of a CALiPPSO output."""
    stable = np.flatnonzero(~q.rattler)
    return stable, q.contacts[~q.rattler[q.contacts[:, 0]] & ~q.rattler[q.contacts[:, 1]]]


def basis_kernel(q: Packing) -> sp.csc_matrix:
    """The simplex basis of the converged LP of ``q`` without its slack part: the
    backbone contact rows over the stable particles' coordinates (one anchor particle
    fixed) and the column of ``g``; square for an isostatic network. Rows are
    rigidity-matrix rows (the LP's rows up to a positive factor per row, the same
    sparsity)."""
    stable, c = backbone(q)
    R = rigidity_matrix(q, c, particles=stable).tocsc()[:, q.d:]
    return sp.hstack([R, np.ones((R.shape[0], 1))], format="csc")


def nested_dissection_columns(q: Packing) -> NDArray[np.int64] | None:
    """Columns of :func:`basis_kernel` in METIS nested-dissection order of the stable
    particles' contact graph (each particle's coordinates together, ``g`` last), or
    None without ``pymetis``."""
    try:
        import pymetis
    except ImportError:
        return None
    stable, c = backbone(q)
    col_of = np.full(q.n, -1)
    col_of[stable] = np.arange(len(stable))
    i, j = col_of[c[:, 0]], col_of[c[:, 1]]
    G = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(len(stable), len(stable)))
    G = (G + G.T).tocsr()
    perm, _ = pymetis.nested_dissection(adjacency=pymetis.CSRAdjacency(G.indptr, G.indices))
    perm = np.asarray(perm)
    perm = perm[perm > 0] - 1  # the anchor (first stable particle) has no columns
    cols = (q.d * perm[:, None] + np.arange(q.d)).ravel()
    return np.append(cols, q.d * (len(stable) - 1))


def superlu(K: sp.csc_matrix, permc_spec: str) -> tuple[float, int]:
    """Seconds and nnz(L + U) of a SuperLU factorisation."""
    t0 = time.perf_counter()
    lu = sla.splu(K, permc_spec=permc_spec)
    return time.perf_counter() - t0, lu.L.nnz + lu.U.nnz


def highs_factor_time(K: sp.csc_matrix) -> float:
    """Seconds of a HiGHS primal simplex run from the all-structural basis of ``K``
    stopped by a zero pivot limit: setup plus the first factorisation of the basis,
    with the chain's scaling of warm LPs (``WARM_SIMPLEX_SCALE``)."""
    free = np.full(K.shape[1], highspy.kHighsInf)
    lp = JammingLP(K, np.zeros(K.shape[0]), -free, free, np.empty((0, 2), np.int64)).to_highs()
    h = new_highs(1)
    for option, value in (("solver", "simplex"),
                          ("simplex_strategy", 4), ("simplex_iteration_limit", 0),
                          ("simplex_scale_strategy", cal_solver.WARM_SIMPLEX_SCALE)):
        h.setOptionValue(option, value)
    h.passModel(lp)
    basis = highspy.HighsBasis()
    basis.col_status = [highspy.HighsBasisStatus.kBasic] * K.shape[1]
    basis.row_status = [highspy.HighsBasisStatus.kUpper] * K.shape[0]
    basis.valid = True
    h.setBasis(basis)
    t0 = time.perf_counter()
    h.run()
    return time.perf_counter() - t0


FACTOR_REPEATS = 3


def _stored_chains(tag: str) -> tuple[NDArray[np.float64], NDArray[np.float64], list[int]]:
    """N, (chain wall time [s], LPs, median LP time [s]) and seed of every stored chain of the
    starts ``tag`` (``calippso_out_<tag>_N<n>_s<seed>.nc`` of ``scaling``; ``..._N<n>.nc`` of
    ``large`` is seed 1 where ``scaling`` has none). The time is the chain's own wall time
    (``total_time``, over all runs of a checkpointed chain)."""
    found = [(m, path) for path in OUT.glob(f"calippso_out_{tag}_N*.nc")
             if (m := re.fullmatch(rf"calippso_out_{tag}_N(\d+)(?:_s(\d+))?\.nc", path.name))]
    runs = {}
    for m, path in sorted(found, key=lambda mp: mp[0][2] is None):  # the seeded names first
        runs.setdefault((int(m[1]), int(m[2] or 1)), path)
    keys = sorted(runs)
    rows = []
    for key in keys:
        ds = read_dataset(runs[key])
        rows.append((ds.attrs["total_time"], ds.attrs["n_lps"], float(np.median(ds["lp_time"].values))))
    return np.array([k[0] for k in keys], float), np.array(rows, float).reshape(-1, 3), [k[1] for k in keys]


def part_fit() -> xr.Dataset:
    """Exponents over the stored chains of the near starts of ``--near-kappa`` (see
    :func:`_stored_chains`), and a figure of their time against N beside the :data:`FAST_KAPPA` starts'."""
    n, values, seeds = _stored_chains(near_tag())
    if not len(n):
        raise SystemExit(f"no stored chains of {near_tag()} starts in {OUT}")
    exps = {}
    for j, name in enumerate(("time", "lps", "t_lp")):
        a, err = fit_with_error(n, values[:, j])
        exps[f"exponent_{name}"], exps[f"exponent_{name}_error"] = a, err
    print(f"{near_tag()} starts, {len(n)} chains at N = {', '.join(map(str, sorted(set(n.astype(int)))))}: "
          + ", ".join(f"{k} ~ N^({exps[f'exponent_{k}']:.2f} ± {exps[f'exponent_{k}_error']:.2f}) "
                      f"(paper {PAPER_EXPONENTS[k]:g})" for k in ("time", "lps", "t_lp")), flush=True)
    print("chain wall time, medians over seeds: " + ", ".join(
        f"N = {m}: {np.median(values[n == m, 0]):.1f} s, {np.median(values[n == m, 1]):.0f} LPs ({(n == m).sum()} seeds)"
        for m in sorted(set(n.astype(int)))), flush=True)
    fig, ax = plt.subplots(figsize=(5, 4))
    if near_tag() != near_tag(FAST_KAPPA):
        n0, v0, _ = _stored_chains(near_tag(FAST_KAPPA))
        ax.loglog(n0, v0[:, 0], "o", mfc="none", color="C3", label=f"LS kappa = {FAST_KAPPA:.0e} starts")
    ax.loglog(n, values[:, 0], "s", color="C0", label=f"LS kappa = {NEAR_KAPPA:.0e} starts")
    grid = np.geomspace(n.min(), n.max(), 20)
    scale = np.exp(np.mean(np.log(values[:, 0]) - exps["exponent_time"] * np.log(n)))
    ax.loglog(grid, scale * grid ** exps["exponent_time"], "-", color="C0",
              label=f"N^({exps['exponent_time']:.2f} ± {exps['exponent_time_error']:.2f})")
    ax.set_xlabel("number of spheres N")
    ax.set_ylabel("CALiPPSO chain wall time [s]")
    ax.set_title(f"3D near starts, p = {NEAR_PRESSURE:.0e}", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / f"calippso_fit_{near_tag()}.png", dpi=120)
    plt.close(fig)
    print(f"wrote {OUT / f'calippso_fit_{near_tag()}.png'}")
    data = {"time": (("run",), values[:, 0], {"units": "s", "long_name": "chain wall time"}),
            "lps": (("run",), values[:, 1], {"units": "1"}),
            "t_lp": (("run",), values[:, 2], {"units": "s", "long_name": "median LP time"}),
            "N": (("run",), n.astype(int), {"units": "1"}),
            "seed": (("run",), seeds, {"units": "1"})}
    return xr.Dataset(data, attrs=new_dataset_attrs("CALiPPSO exponents over stored chains",
                                                     {"near_kappa": NEAR_KAPPA, "near_pressure": NEAR_PRESSURE},
                                                     **exps))


def part_factor(quick: bool) -> xr.Dataset:
    sizes = [128, 256] if quick else [256, 512, 1024, 2048, 4096]
    rows = []
    for n in sizes:
        out = OUT / f"calippso_out_{near_tag()}_N{n}_s1.nc"
        if not out.exists():
            command(near_start(n), f"{near_tag()}_N{n}_s1")
        q = read_packing(out)
        K = basis_kernel(q)
        # best of FACTOR_REPEATS: the first call of each library includes its set-up
        t_highs = min(highs_factor_time(K) for _ in range(FACTOR_REPEATS))
        t_colamd, fill_colamd = min(superlu(K, "COLAMD") for _ in range(FACTOR_REPEATS))
        nd = nested_dissection_columns(q)
        t_nd, fill_nd = (min(superlu(K[:, nd].tocsc(), "NATURAL") for _ in range(FACTOR_REPEATS))
                         if nd is not None else (np.nan, np.nan))
        rows.append(dict(size=K.shape[0], nnz=K.nnz, highs=t_highs, superlu=t_colamd, fill=fill_colamd,
                         superlu_nd=t_nd, fill_nd=fill_nd))
        print(f"   N = {n}: basis {K.shape[0]}x{K.shape[1]}, nnz {K.nnz}; HiGHS factorisation {t_highs:.3f} s; "
              f"SuperLU COLAMD {t_colamd:.3f} s, nnz(L+U) {fill_colamd}; METIS ND {t_nd:.3f} s, nnz(L+U) {fill_nd}",
              flush=True)
    units = {"highs": "s", "superlu": "s", "superlu_nd": "s"}
    data = {k: (("N",), np.array([r[k] for r in rows], float), {"units": units.get(k, "1")}) for k in rows[0]}
    n = np.array(sizes)
    exps = {f"exponent_{k}": fit(n, data[k][1]) for k in ("highs", "superlu", "fill", "superlu_nd", "fill_nd")}
    print("fitted exponents:", {k: round(v, 2) for k, v in exps.items()}, flush=True)
    return xr.Dataset(data, coords={"N": n}, attrs=new_dataset_attrs(
        "Factorisation of the final CALiPPSO simplex basis (near starts, d = 3)", {"quick": quick}, **exps))


def _plot_scaling(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    n = ds["N"].values
    for (s, m), color in zip((("random", "o"), ("near", "s")), ("C0", "C1")):
        sel = ds.sel(start=s)
        for k, style, what in (("time", "-", "total"), ("t_lp", "--", "median LP")):
            values = sel[k].values
            ax.loglog(np.repeat(n, values.shape[1]), values.ravel(), m, color=color, ms=3, alpha=0.4)
            ax.loglog(n, median_over_seeds(values), m + style, color=color, label=f"{s}: {what} (median of seeds)")
    if "large" in found:
        ax.loglog(found["large"]["N"], found["large"]["time"], "s", color="C1", mfc="none", label="near: large N")
    _label_sizes(ax, ds["N"].values)
    ax.set_xlabel("particles N"); ax.set_ylabel("time [s]"); ax.legend(fontsize=7); ax.set_title("d = 3 scaling")


def _label_sizes(ax, sizes) -> None:
    """Tick labels at the system sizes only (log axes label minor ticks over each other)."""
    ax.set_xticks(sizes, [str(int(n)) for n in sizes])
    ax.xaxis.set_minor_formatter(NullFormatter())


def _plot_ls(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    ax.bar(ds["d"] - 0.2, ds["time"], 0.4, label="measured")
    ax.bar(ds["d"] + 0.2, ds["target_time"], 0.4, label="target")
    ax.set_xticks(ds["d"].values)
    ax.set_xlabel("dimension d"); ax.set_ylabel("time to jam [s]"); ax.legend(fontsize=7)
    ax.set_title("authors' LS examples")


def _plot_solvers(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    ax.bar([str(s) for s in ds["solver"].values], ds["time"])
    ax.set_xlabel("HiGHS strategy"); ax.set_ylabel("time to jam [s]"); ax.set_title("solver strategies")


def _plot_tolerances(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    ax.loglog(ds["time"], ds["overlap"], "o", label="max overlap")
    ax.loglog(ds["time"], ds["fb"], "s", label="force-balance residual")
    for k in range(ds.sizes["setting"]):
        ax.annotate(f"{float(ds.tol_s[k]):g}/{float(ds.tol_gamma[k]):g}/{float(ds.solver_tol[k]):g}",
                    (float(ds["time"][k]), float(ds["fb"][k])), fontsize=6)
    ax.set_xlabel("time to jam [s]"); ax.set_ylabel("relative overlap, residual [1]"); ax.legend(fontsize=7)
    ax.set_title("tol_s / tol_gamma / solver_tol")


def _plot_factor(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    ax.loglog(ds["N"], ds["highs"], "o-", label="HiGHS factorisation [s]")
    ax.loglog(ds["N"], ds["superlu"], "s-", label="SuperLU COLAMD [s]")
    ax.loglog(ds["N"], ds["superlu_nd"], "D-", label="SuperLU METIS ND [s]")
    ax.loglog(ds["N"], ds["fill"] / ds["nnz"], "^--", label="SuperLU fill nnz(L+U)/nnz")
    _label_sizes(ax, ds["N"].values)
    ax.set_xlabel("particles N"); ax.set_ylabel("time [s], fill ratio [1]"); ax.legend(fontsize=7)
    ax.set_title("warm LP: basis factorisation")


def _plot_finish(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    pos = np.arange(ds.sizes["case"])
    for k, finish in enumerate(("lp", "newton")):
        ax.bar(pos + (k - 0.5) * 0.4, ds["time"].sel(finish=finish), 0.4, label=f"--finish {finish}")
        for x, (t, lps) in enumerate(zip(ds["time"].sel(finish=finish).values, ds["lps"].sel(finish=finish).values)):
            ax.annotate(f"{lps:.0f} LPs", (x + (k - 0.5) * 0.4, t), ha="center", fontsize=6)
    ax.set_xticks(pos, [str(c).replace("ls_", "") for c in ds["case"].values], fontsize=6)
    ax.set_xlabel("start (authors' LS examples, N = 1024, and tilings)"); ax.set_ylabel("time to jam [s]")
    ax.legend(fontsize=7); ax.set_title("Newton finish vs LP chain")


def _plot_scale(ax, ds: xr.Dataset, found: dict[str, xr.Dataset]) -> None:
    pos = np.arange(ds.sizes["case"])
    for k, scaling in enumerate(ds["scaling"].values):
        t = ds["t_lps"].sel(scaling=scaling).values
        ax.bar(pos + (k - 0.5) * 0.4, t, 0.4, label=f"warm LPs {scaling}")
        for x, (y, pivots) in enumerate(zip(t, ds["pivots"].sel(scaling=scaling).values)):
            ax.annotate(f"{pivots:.0f}", (x + (k - 0.5) * 0.4, y), ha="center", fontsize=5, rotation=90)
    ax.set_yscale("log")
    ax.set_xticks(pos, [str(c).replace("near_", "").replace("ls_", "") for c in ds["case"].values], fontsize=6,
                  rotation=45)
    ax.set_xlabel("start (LS examples; near starts N, seed)"); ax.set_ylabel("LP time of the chain [s]")
    ax.legend(fontsize=7); ax.set_title("HiGHS scaling of warm LPs (numbers: pivots)")


#: one panel per part that has a plot, drawn when its netCDF is in ``OUT``
PLOTS = {"scaling": _plot_scaling, "ls": _plot_ls, "solvers": _plot_solvers, "tolerances": _plot_tolerances,
         "factor": _plot_factor, "finish": _plot_finish, "scale": _plot_scale}


def plot() -> None:
    found = {p: xr.open_dataset(OUT / f"calippso_{p}.nc") for p in PARTS if (OUT / f"calippso_{p}.nc").exists()}
    drawn = [p for p in PLOTS if p in found]
    if not drawn:
        print(f"no part with a plot in {OUT}")
        return
    fig, axes = plt.subplots(1, len(drawn), figsize=(4.4 * len(drawn), 4), squeeze=False)
    for ax, part in zip(axes[0], drawn):
        PLOTS[part](ax, found[part], found)
    fig.tight_layout()
    fig.savefig(OUT / "calippso.png", dpi=120)
    print(f"wrote {OUT / 'calippso.png'} from parts {', '.join(drawn)}")


def main() -> None:
    global NEAR_KAPPA
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes only (a few minutes)")
    ap.add_argument("--parts", nargs="+", choices=PARTS, default=[p for p in PARTS],
                    help="parts to run (default all; 'large' takes tens of minutes)")
    ap.add_argument("--large-n", type=int, default=16384, help="N of the 'large' part (default 16384)")
    ap.add_argument("--seeds", type=int, default=3,
                    help="starts of each kind and N in 'scaling' (seeds FIRST_SEED .. SEEDS; default 3)")
    ap.add_argument("--first-seed", type=int, default=1,
                    help="first seed of 'scaling' (default 1; a larger one adds seeds to stored chains)")
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SCALING_SIZES),
                    help=f"N of 'scaling' (default {' '.join(map(str, SCALING_SIZES))}; 8192 and up take hours)")
    ap.add_argument("--jobs", type=int, default=1, help="whole commands of 'scaling' run at once (default 1)")
    ap.add_argument("--max-random", type=int, default=4096,
                    help="largest N of the random starts in 'scaling' (3D N = 1024 takes ~200 LPs, ~6 min)")
    ap.add_argument("--large-options", default="",
                    help="extra jamflow calippso options of the 'large' part, e.g. \"--interior hipo --threads 2\"")
    ap.add_argument("--max-finish", type=int, default=4096, help="largest N of the 'finish' part (1024: the LS examples; 2048, 4096: tilings)")
    ap.add_argument("--max-scale", type=int, default=1024, help="largest N of the 'scale' part (1024 or 2048)")
    ap.add_argument("--near-kappa", type=float, default=NEAR_KAPPA,
                    help=f"LS growth rate of the near starts (default {NEAR_KAPPA:g}; the paper's 1e-5)")
    ap.add_argument("--suffix", default="", help="appended to the parts' output names (runs side by side)")
    ap.add_argument("--engine-cases", nargs="+", default=["ls", "1024", "2048"],
                    choices=["ls", "1024", "2048", "4096", "8192"],
                    help="starts of the 'engine' part: the LS examples and/or near starts of these N")
    ap.add_argument("--engines", nargs=2, default=["highs", "jamflow"], choices=list(cal.WARM_ENGINES),
                    help="the two --warm-engine values the 'engine' part compares (default highs jamflow)")
    args = ap.parse_args()
    if args.seeds < 1 or args.jobs < 1:
        ap.error("--seeds and --jobs must be at least 1")
    if not 1 <= args.first_seed <= args.seeds:
        ap.error("--first-seed must be between 1 and --seeds")
    if min(args.sizes) < 2 or len(set(args.sizes)) != len(args.sizes):
        ap.error("--sizes must be distinct particle numbers of at least 2")
    if not args.near_kappa > 0:
        ap.error("--near-kappa must be a positive growth rate")
    NEAR_KAPPA = args.near_kappa
    OUT.mkdir(exist_ok=True)
    runners = {"scaling": lambda: part_scaling(args.quick, args.max_random, args.seeds, args.jobs,
                                                   tuple(args.sizes), args.first_seed),
               "ls": lambda: part_ls(args.quick),
               "preset": lambda: part_preset(args.quick),
               "finish": lambda: part_finish(args.quick, args.max_finish),
               "scale": lambda: part_scale(args.quick, args.max_scale),
               "engine": lambda: part_engine(args.quick, args.engine_cases, args.seeds, tuple(args.engines)),
               "solvers": lambda: part_solvers(args.quick), "lp": lambda: part_lp(args.quick),
               "relax": lambda: part_relax(args.quick),
               "tolerances": lambda: part_tolerances(args.quick),
               "large": lambda: part_large(1024 if args.quick else args.large_n, tuple(args.large_options.split())),
               "fit": part_fit,
               "factor": lambda: part_factor(args.quick)}
    for part in args.parts:
        write_dataset(runners[part](), OUT / f"calippso_{part}{args.suffix}.nc")
    plot()


if __name__ == "__main__":
    main()
