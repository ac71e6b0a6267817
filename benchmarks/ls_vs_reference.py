"""jamflow's Lubachevsky–Stillinger compression against the C++ reference, side by side.

The reference is PackingGeneration by V. Baranau (public repository
VasiliBaranov/packing-generation, MIT licence), built on this machine from its source by
``benchmarks/build_packing_generation.sh SOURCE_DIR BIN_DIR`` (nothing of it is committed
here). For each case this script, in one run:

1. makes the start: the reference's documented sequence (README Sec. 4 and its Colab
   notebook) begins with ``-fba`` (force-biased algorithm) from Poisson points in a box
   sized for a nominal packing fraction ``PHI_NOMINAL[d]`` with contraction rate 1e-3;
   its ``packing.xyzd`` is the common start of both codes;
2. runs the reference ``-ls`` (constant contraction rate ``CONTRACTION_RATE = 1e-3``) from
   that start: once with the executable built from the unmodified source, timed, and once
   with the build that only switches on the author's own per-step event counters, to count
   collisions and to read the packing fraction after every step; the two runs must print
   the same reduced pressure after every step (same seed, deterministic dynamics) or the
   script stops;
3. runs ``jamflow.protocols.ls.compress`` from the same positions and diameters with the mapped
   growth rate, temperature and pressure window (below), single stage;
4. records collisions, CPU time, collisions per CPU-second, the CPU time and collisions to
   each pressure target, p and phi there, and the ratios jamflow / reference.

Protocol mapping (read from the reference's source, ``LubachevsckyStillingerStep.cpp``,
``ParticleCollisionService.cpp``, ``VelocityService.cpp``)
----------------------------------------------------------------------------------------
* Reference growth: diameters ``sigma_i(t) = D_i s(t)`` with ``D_i`` the diameters stored in
  packing.xyzd (never rescaled in the file), ``s(0)`` the ratio at which the closest pair
  touches, and ``ds/dt = gamma``, the "Contraction rate"; so ``d sigma_i / dt = gamma D_i``.
  Masses 1, ``k_B T = 0.2`` (``VelocityService::temperature``); velocities are rescaled to
  that temperature after every "step" of ``20 N`` events (collisions, cell transfers,
  periodic-wall crossings, moves), and the pressure is measured over the same step.
* jamflow growth: ``sigma_i(t) = a_i s(t)`` with ``a_i = D_i / <D>`` and ``ds/dt = kappa``
  (the mean diameter), masses 1, ``k_B T = 1 / beta``: ``d sigma_i / dt = kappa D_i / <D>``.
* The dynamics depends on the growth only through the ratio of the growth speed to the
  thermal speed, ``(d sigma_i / dt) / sqrt(k_B T / m)``, for every particle. jamflow is run
  on the reference's own lengths (box side and ``D_i`` of packing.xyzd, scaled by ``s(0)``),
  at the reference's temperature ``beta = 1 / 0.2 = 5`` and with ``kappa = gamma <D>``
  (``<D>`` the mean of the file's ``D_i``): then ``d sigma_i / dt`` and the thermal speed
  are identical for every particle, in the same units, so both codes follow the same
  protocol to the same simulated times. At the paper's ``beta = 10`` the same protocol
  is ``kappa = gamma <D> / sqrt(2)`` (only ``kappa sqrt(beta)`` matters).
* Pressure window and thermostat: jamflow's ``window`` (collisions per pressure window and
  between velocity rescalings) is set to the reference's mean number of collisions per
  step in the same case (about 17 per particle in 3D), so both rescale equally often.
* Reduced pressure: both report ``p = beta P V / N`` from the collision virial. The reference
  leaves the growth part of the impulse out of the virial and divides by the kinetic energy
  at the end of the step; jamflow includes it and uses the time-averaged kinetic energy.
  The difference is of order ``gamma / |u_n|`` and invisible on the plots.
* Stops: the reference stops after the first step with ``p >= 1e12`` (hard-coded
  ``maxPressure``); lower targets are read from its per-step log (the timed process is
  ended once the highest target is passed). jamflow stops at the first window with
  ``p >= target``. Targets above 1e12 are not supported by the reference.
* CPU time: the reference's process CPU time (user + system, ``psutil``, the kernel's 10 ms
  ticks) at the moment its log line reporting the step that crossed the target appears
  (stdout line-buffered with ``stdbuf -oL``), including its start-up; jamflow's
  ``time.process_time`` as reported by ``compress`` (numba kernels compiled beforehand by
  a warm-up run that is not counted).
* Initial velocities are drawn by each code from its own generator, so the trajectories
  are statistically equivalent, not identical: compare rates and times, not individual
  collisions.

Writes ``benchmarks/output/ls_vs_reference.nc`` and ``ls_vs_reference.png`` (collision rates
side by side; p against phi of both codes) and prints a table.

Usage::

    benchmarks/build_packing_generation.sh /path/to/packing-generation /tmp/pgbin
    python benchmarks/ls_vs_reference.py --reference-bin /tmp/pgbin [--quick] [--cases ...]

``--quick``: 3D monodisperse N = 256 to p = 1e6 only. Needs ``stdbuf`` (GNU coreutils).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import psutil
import xarray as xr

from jamflow.box import Box
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.protocols.ls import compress
from jamflow.state.packing import Packing, max_overlap, near_pairs, sphere_volume

OUT = Path(__file__).resolve().parent / "output"

#: The reference's "Contraction rate" for -ls (its documented sequence) and for -fba.
CONTRACTION_RATE: float = 1e-3
#: Reference temperature k_B T (VelocityService::temperature in its source).
REFERENCE_TEMPERATURE: float = 0.2
#: Reference pressure at which -ls stops (LubachevsckyStillingerStep::maxPressure).
REFERENCE_MAX_PRESSURE: float = 1e12
#: Nominal packing fraction of the box given to -fba (the Colab notebook uses 0.5 in 3D;
#: 2D: a similar fraction of the bidisperse disc jamming density ~0.84).
PHI_NOMINAL: dict[int, float] = {2: 0.65, 3: 0.5}
#: Seed in generation.conf (Poisson points, velocities) and of jamflow's velocities.
SEED: int = 1
#: Pressure targets of a full run and of --quick.
P_TARGETS: tuple[float, ...] = (1e6, 1e12)
QUICK_TARGETS: tuple[float, ...] = (1e6,)
#: Relative gap (file diameters) within which the closest pair of the -fba output is sought.
START_GAP_SEARCH: float = 0.5

_RE_STEP = re.compile(r"^Time: (\S+), reduced pressure: (\S+), actual temperature: (\S+)")
_RE_COLL = re.compile(r"^Collision occurrence count: (\d+)")
_RE_RATIO = re.compile(r"^Step (\d+)\. Inner diameter ratio is (\S+)\.")
_RE_GLOBAL_MIN = re.compile(r"^Global minimum is (\S+)")


@dataclass(frozen=True)
class Case:
    """One benchmark system: dimension, N and the large/small diameter ratio (1 = mono)."""

    d: int
    n: int
    size_ratio: float

    @property
    def diameters(self) -> np.ndarray:
        """Nominal diameters D_i: 1, or half 1 and half ``size_ratio``."""
        D = np.ones(self.n)
        D[self.n // 2:] = self.size_ratio
        return D


CASES: dict[str, Case] = {
    "3d_mono_256": Case(3, 256, 1.0),
    "3d_mono_1024": Case(3, 1024, 1.0),
    "3d_mono_4096": Case(3, 4096, 1.0),
    "2d_bi_1024": Case(2, 1024, 1.4),
}
DEFAULT_CASES = ("3d_mono_256", "3d_mono_1024", "2d_bi_1024")


# --- the reference's files ---------------------------------------------------------------
def write_conf(folder: Path, case: Case, box_length: float, start: bool, steps_to_write: int) -> None:
    """generation.conf in the reference's fixed line format (README Sec. 1.2)."""
    (folder / "generation.conf").write_text(
        f"Particles count: {case.n}\n"
        f"Packing size: {box_length!r} {box_length!r} {box_length!r}\n"
        f"Generation start: {1 if start else 0}\n"
        f"Seed: {SEED}\n"
        f"Steps to write: {steps_to_write}\n"
        "Boundaries mode: 1\n"
        f"Contraction rate: {CONTRACTION_RATE!r}\n"
    )


def read_xyzd(path: Path, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, d) and file diameters (N,) of a packing.xyzd (little-endian float64,
    d coordinates and the diameter per particle)."""
    data = np.fromfile(path, dtype="<f8")
    if data.size % (d + 1):
        raise ValueError(f"{path}: {data.size} numbers is not a multiple of d + 1 = {d + 1}")
    data = data.reshape(-1, d + 1)
    return data[:, :d].copy(), data[:, d].copy()


def box_length(case: Case) -> float:
    """Cubic box side giving the nominal packing fraction PHI_NOMINAL[d] for the D_i."""
    return float((sphere_volume(case.d, case.diameters).sum() / PHI_NOMINAL[case.d]) ** (1.0 / case.d))


def make_start(case: Case, exe: Path, folder: Path) -> Path:
    """Run the reference -fba from Poisson points; return its packing.xyzd."""
    folder.mkdir(parents=True)
    write_conf(folder, case, box_length(case), start=True, steps_to_write=10**9)
    np.savetxt(folder / "diameters.txt", case.diameters)
    subprocess.run([str(exe), "-fba"], cwd=folder, check=True, stdout=subprocess.DEVNULL)
    if not (folder / "packing.nfo").is_file():
        raise RuntimeError(f"reference -fba did not finish in {folder}")
    return folder / "packing.xyzd"


def start_packing(case: Case, xyzd: Path) -> tuple[Packing, float]:
    """The common start as a jamflow Packing: file diameters scaled by the ratio s0 at which
    the closest pair touches (what the reference's -ls starts from); returns (packing, s0)."""
    L = box_length(case)
    x, D = read_xyzd(xyzd, case.d)
    if x.shape[0] != case.n:
        raise ValueError(f"{xyzd}: {x.shape[0]} particles, expected {case.n}")
    box = Box.cubic(case.d, L)
    probe = Packing(position=box.wrap(x), diameter=D, box=box)
    # s0 = min_ij r_ij / sigma_ij over the file diameters (-fba leaves it near 1)
    _, h = near_pairs(probe, START_GAP_SEARCH)
    if h.size == 0:
        raise RuntimeError(f"{xyzd}: no pair within a relative gap {START_GAP_SEARCH}")
    s0 = 1.0 + float(h.min())
    if not s0 > 0.0:
        raise RuntimeError(f"{xyzd}: coincident centres")
    return Packing(position=probe.position, diameter=D * s0, box=box, protocol="fba",
                   seed=SEED), s0


# --- running the reference ---------------------------------------------------------------
def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process [s] (psutil, a snakemake dependency)."""
    times = psutil.Process(pid).cpu_times()
    return times.user + times.system


def run_reference(exe: Path, case: Case, xyzd: Path, folder: Path, targets: tuple[float, ...],
                  counting: bool) -> dict:
    """Run the reference -ls from ``xyzd`` and parse its log step by step.

    Returns per-step arrays ``p`` (and, with ``counting``, ``collisions`` and the diameter
    ratio ``ratio`` at the end of the step), ``cpu`` (process CPU seconds when the step's
    pressure line was read), ``s0`` and ``finished``. The timed run is ended at the pressure
    line of the step that passes the highest target; the counting run (which writes its
    packing after every step) after that step's ratio line, and only when the highest
    target is below the reference's own stop.
    """
    folder.mkdir(parents=True)
    write_conf(folder, case, box_length(case), start=False, steps_to_write=1 if counting else 10**9)
    shutil.copyfile(xyzd, folder / "packing.xyzd")
    stop_early = not counting or max(targets) < REFERENCE_MAX_PRESSURE
    proc = subprocess.Popen(["stdbuf", "-oL", str(exe), "-ls"], cwd=folder, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, bufsize=1)
    p, cpu, coll, ratio, s0 = [], [], [], [], math.nan
    log = []
    try:
        for line in proc.stdout:
            log.append(line)
            if m := _RE_STEP.match(line):
                cpu.append(_cpu_seconds(proc.pid))
                p.append(float(m.group(2)))
                if stop_early and not counting and p[-1] >= max(targets):
                    proc.send_signal(signal.SIGKILL)
                    break
            elif m := _RE_COLL.match(line):
                coll.append(int(m.group(1)))
            elif m := _RE_RATIO.match(line):
                ratio.append(float(m.group(2)))
                # the counting run is ended after the ratio line of the step reaching the target
                if stop_early and p and p[-1] >= max(targets):
                    proc.send_signal(signal.SIGKILL)
                    break
            elif m := _RE_GLOBAL_MIN.match(line):
                s0 = float(m.group(1))
    finally:
        proc.stdout.close()
        rc = proc.wait()
    (folder / "log.txt").write_text("".join(log))
    finished = rc == 0 and (folder / "packing.nfo").is_file()
    if not stop_early and not finished:
        raise RuntimeError(f"reference -ls failed (exit {rc}); log in {folder / 'log.txt'}")
    if not p or max(p) < max(targets):
        raise RuntimeError(f"reference -ls never reached p = {max(targets):g}; log in {folder}")
    out = {"p": np.array(p), "cpu": np.array(cpu), "s0": s0, "finished": finished, "folder": folder}
    if counting:
        k = len(p)
        if len(coll) < k or len(ratio) < k:
            raise RuntimeError(f"counting run: {len(coll)} collision counts, {len(ratio)} ratios for {k} steps")
        out["collisions"] = np.array(coll[:k], dtype=np.int64)
        out["ratio"] = np.array(ratio[:k])
    return out


def reference_side(case: Case, bin_dir: Path, xyzd: Path, work: Path, targets: tuple[float, ...]) -> dict:
    """Counting run (collisions, phi per step) and timed run; check they agree."""
    tag = f"{case.d}d"
    counting = run_reference(bin_dir / f"PackingGeneration{tag}_counting.exe", case, xyzd,
                             work / "ref_counting", targets, counting=True)
    timed = run_reference(bin_dir / f"PackingGeneration{tag}.exe", case, xyzd, work / "ref_timed",
                          targets, counting=False)
    k = len(timed["p"])
    if len(counting["p"]) < k or not np.array_equal(counting["p"][:k], timed["p"]):
        raise RuntimeError("the timed and the counting reference builds printed different pressures: "
                           f"the trajectories differ (see {work})")
    phi_file = float(sphere_volume(case.d, case.diameters).sum() / box_length(case) ** case.d)
    phi = phi_file * counting["ratio"] ** case.d
    cum = np.cumsum(counting["collisions"])
    res = {"steps": k, "events": 20 * case.n * np.arange(1, k + 1), "collisions_cum": cum[:k],
           "p": timed["p"], "cpu": timed["cpu"], "phi": phi[:k], "s0": timed["s0"],
           "collisions_per_step": float(cum[k - 1] / k)}
    res["targets"] = []
    for target in targets:
        i = int(np.argmax(timed["p"] >= target))
        res["targets"].append({"collisions": int(cum[i]), "cpu_time": float(timed["cpu"][i]),
                               "p": float(timed["p"][i]),
                               "phi": float(phi[i])})
    res["collisions"] = res["targets"][-1]["collisions"]
    res["cpu_time"] = res["targets"][-1]["cpu_time"]
    if counting["finished"]:
        res["final_overlap"] = _final_overlap(case, counting["folder"])
    return res


def _final_overlap(case: Case, folder: Path) -> float:
    """Largest relative overlap of the reference's final packing at its final diameters."""
    x, D = read_xyzd(folder / "packing.xyzd", case.d)
    log = (folder / "log.txt").read_text()
    ratio = float(re.findall(r"Inner diameter ratio is\s+(\S+)", log)[-1])
    box = Box.cubic(case.d, box_length(case))
    return max_overlap(Packing(position=box.wrap(x), diameter=D * ratio, box=box))[1]


# --- running jamflow -----------------------------------------------------------------------
def jamflow_side(start: Packing, case: Case, targets: tuple[float, ...], window: int) -> dict:
    """jamflow.protocols.ls.compress with the mapped protocol (module docstring)."""
    kappa = CONTRACTION_RATE * float(case.diameters.mean())
    beta = 1.0 / REFERENCE_TEMPERATURE
    res = compress(start, kappa, list(targets), beta=beta, fast_growth_rate=None, seed=SEED,
                   window=window)
    eos = res.eos
    out = {"kappa": kappa, "beta": beta, "window": window, "collisions": res.collisions,
           "cpu_time": res.cpu_time, "phi": eos.packing_fraction.values, "p": eos.pressure.values,
           "collisions_cum": eos.collisions.values,
           "final_overlap": max(max_overlap(s)[1] for s in res.snapshots)}
    out["targets"] = [{"collisions": int(s.attrs["collisions"]), "cpu_time": float(s.attrs["cpu_time"]),
                       "p": float(s.attrs["p"]), "phi": float(s.attrs["phi"])} for s in res.snapshots]
    return out


def warm_up(d: int) -> None:
    """Compile jamflow's numba kernels outside the timed runs."""
    from jamflow.protocols.initial import random_packing

    compress(random_packing(64, d, 0.3, seed=0), 1e-3, [1e3], fast_growth_rate=None)


# --- the benchmark --------------------------------------------------------------------------
def run_case(name: str, case: Case, bin_dir: Path, targets: tuple[float, ...], work: Path) -> dict:
    tag = f"{case.d}d"
    load = os.getloadavg()[0]
    xyzd = make_start(case, bin_dir / f"PackingGeneration{tag}.exe", work / "fba")
    start, s0 = start_packing(case, xyzd)
    print(f"[{name}] start phi = {start.packing_fraction:.4f} (s0 = {s0:.12g})", flush=True)
    ref = reference_side(case, bin_dir, xyzd, work, targets)
    if abs(ref["s0"] - s0) > 1e-5 * s0:
        raise RuntimeError(f"start scale differs: reference {ref['s0']:.9g}, here {s0:.9g}")
    print(f"[{name}] reference: {ref['collisions']} collisions, {ref['cpu_time']:.2f} CPU-s", flush=True)
    window = max(1, round(ref["collisions_per_step"]))
    jf = jamflow_side(start, case, targets, window)
    print(f"[{name}] jamflow:   {jf['collisions']} collisions, {jf['cpu_time']:.2f} CPU-s", flush=True)
    return {"name": name, "case": case, "start_phi": start.packing_fraction, "ref": ref, "jf": jf,
            "load": (load, os.getloadavg()[0])}


def to_dataset(results: list[dict], targets: tuple[float, ...], parameters: dict) -> xr.Dataset:
    codes = ["jamflow", "reference"]
    nrec = max(max(len(r["ref"]["p"]), len(r["jf"]["p"])) for r in results)
    shape = (len(results), 2)
    coll, cpu = np.zeros(shape, dtype=np.int64), np.zeros(shape)
    t_coll = np.zeros(shape + (len(targets),), dtype=np.int64)
    t_cpu, t_p, t_phi = (np.full(shape + (len(targets),), np.nan) for _ in range(3))
    eos_phi, eos_p = np.full(shape + (nrec,), np.nan), np.full(shape + (nrec,), np.nan)
    eos_coll = np.full(shape + (nrec,), -1, dtype=np.int64)
    overlap = np.full(shape, np.nan)
    for i, r in enumerate(results):
        for j, side in enumerate((r["jf"], r["ref"])):
            coll[i, j], cpu[i, j] = side["collisions"], side["cpu_time"]
            for k, t in enumerate(side["targets"]):
                t_coll[i, j, k], t_cpu[i, j, k], t_p[i, j, k], t_phi[i, j, k] = (
                    t["collisions"], t["cpu_time"], t["p"], t["phi"])
            m = len(side["p"])
            eos_phi[i, j, :m], eos_p[i, j, :m], eos_coll[i, j, :m] = side["phi"], side["p"], side["collisions_cum"]
            overlap[i, j] = side.get("final_overlap", np.nan)
    rate = coll / cpu
    dims = ("case", "code")
    ds = xr.Dataset(
        {
            "collisions": (dims, coll, {"units": "1", "long_name": "collisions to the highest pressure target"}),
            "cpu_time": (dims, cpu, {"units": "s", "long_name": "process CPU time to the highest pressure target"}),
            "collisions_per_cpu_second": (dims, rate, {"units": "s-1", "long_name": "collisions per CPU-second"}),
            "collisions_to_target": (dims + ("p_target",), t_coll, {"units": "1", "long_name": "collisions to reach the target"}),
            "cpu_time_to_target": (dims + ("p_target",), t_cpu, {"units": "s", "long_name": "CPU time to reach the target"}),
            "pressure_at_target": (dims + ("p_target",), t_p, {"units": "1", "long_name": "reduced pressure of the window/step that reached the target"}),
            "phi_at_target": (dims + ("p_target",), t_phi, {"units": "1", "long_name": "packing fraction when the target was reached"}),
            "rate_ratio": (("case",), rate[:, 0] / rate[:, 1], {"units": "1", "long_name": "collisions per CPU-second, jamflow / reference"}),
            "cpu_time_ratio": (("case", "p_target"), t_cpu[:, 0] / t_cpu[:, 1], {"units": "1", "long_name": "CPU time to the target, jamflow / reference"}),
            "max_relative_overlap": (dims, overlap, {"units": "1", "long_name": "largest relative overlap in the snapshots (jamflow) / final packing (reference)"}),
            "eos_packing_fraction": (dims + ("record",), eos_phi, {"units": "1", "long_name": "packing fraction per pressure window (jamflow) / step (reference)"}),
            "eos_pressure": (dims + ("record",), eos_p, {"units": "1", "long_name": "reduced pressure beta P V / N per window / step"}),
            "eos_collisions": (dims + ("record",), eos_coll, {"units": "1", "long_name": "collisions since the start at the end of the window / step (-1: none)"}),
            "start_packing_fraction": (("case",), np.array([r["start_phi"] for r in results]), {"units": "1", "long_name": "packing fraction of the common start"}),
            "jamflow_growth_rate": (("case",), np.array([r["jf"]["kappa"] for r in results]), {"units": "1", "long_name": "jamflow kappa (mean-diameter growth rate, reference length and time units)"}),
            "jamflow_window": (("case",), np.array([r["jf"]["window"] for r in results]), {"units": "1", "long_name": "jamflow collisions per pressure window (= reference mean collisions per step)"}),
            "reference_events": (("case",), np.array([int(r["ref"]["events"][-1]) for r in results]), {"units": "1", "long_name": "reference events (all types) to the highest target"}),
            "load_average": (("case", "moment"), np.array([r["load"] for r in results]), {"units": "1", "long_name": "1-minute load average of the machine (2 cores) before and after the case: CPU times are per process, but a loaded machine slows both codes"}),
            "dimension": (("case",), np.array([r["case"].d for r in results]), {"units": "1", "long_name": "dimension d"}),
            "n_particles": (("case",), np.array([r["case"].n for r in results]), {"units": "1", "long_name": "number of particles N"}),
            "size_ratio": (("case",), np.array([r["case"].size_ratio for r in results]), {"units": "1", "long_name": "large/small diameter ratio"}),
        },
        coords={"case": [r["name"] for r in results], "code": codes, "p_target": list(targets),
                "moment": ["before", "after"]},
        attrs=new_dataset_attrs("LS compression: jamflow against PackingGeneration (C++), same start and protocol", parameters),
    )
    ds.p_target.attrs.update(units="1", long_name="reduced pressure target")
    return ds


def plot(ds: xr.Dataset, path: Path) -> None:
    cases = list(ds.case.values)
    fig, axes = plt.subplots(1, 1 + len(cases), figsize=(4.2 * (1 + len(cases)), 3.8))
    ax = axes[0]
    xpos = np.arange(len(cases))
    for j, (code, colour) in enumerate(zip(ds.code.values, ("C0", "C1"))):
        vals = ds.collisions_per_cpu_second.sel(code=code).values / 1e3
        ax.bar(xpos + (j - 0.5) * 0.38, vals, 0.38, color=colour, label=str(code))
    for i, c in enumerate(cases):
        ax.text(i, ds.collisions_per_cpu_second.sel(case=c).max() / 1e3, f"x{float(ds.rate_ratio.sel(case=c)):.2f}",
                ha="center", va="bottom", fontsize=8)
    ax.set_xticks(xpos, cases, rotation=20, fontsize=8)
    ax.set_ylabel("collisions per CPU-second [10^3]")
    ax.set_title("collision rate (ratio jamflow/reference)", fontsize=9)
    ax.legend(fontsize=8)
    for ax, c in zip(axes[1:], cases):
        for code, colour in zip(ds.code.values, ("C0", "C1")):
            e = ds.sel(case=c, code=code)
            ok = np.isfinite(e.eos_pressure.values) & np.isfinite(e.eos_packing_fraction.values)
            ax.semilogy(e.eos_packing_fraction.values[ok], e.eos_pressure.values[ok], ".", ms=2, color=colour,
                        label=str(code))
        ax.set_xlabel("packing fraction phi")
        ax.set_ylabel("reduced pressure p")
        ax.set_title(c, fontsize=9)
        ax.legend(fontsize=8, markerscale=4)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reference-bin", type=Path, required=True,
                    help="folder with the executables of benchmarks/build_packing_generation.sh")
    ap.add_argument("--cases", nargs="+", choices=sorted(CASES), default=list(DEFAULT_CASES))
    ap.add_argument("--p-targets", nargs="+", type=float, default=list(P_TARGETS))
    ap.add_argument("--quick", action="store_true", help="3d_mono_256 to p = 1e6 only")
    ap.add_argument("--keep", type=Path, help="keep the reference's run folders here")
    args = ap.parse_args()
    names = ["3d_mono_256"] if args.quick else args.cases
    targets = tuple(sorted(QUICK_TARGETS if args.quick else args.p_targets))
    if max(targets) > REFERENCE_MAX_PRESSURE:
        raise SystemExit(f"targets above {REFERENCE_MAX_PRESSURE:g} are not supported by the reference")
    for exe in {f"PackingGeneration{CASES[n].d}d{s}.exe" for n in names for s in ("", "_counting")}:
        if not (args.reference_bin / exe).is_file():
            raise SystemExit(f"{args.reference_bin / exe} missing: run benchmarks/build_packing_generation.sh")
    for d in sorted({CASES[n].d for n in names}):
        warm_up(d)
    base = Path(tempfile.mkdtemp(prefix="ls_vs_reference_")) if args.keep is None else args.keep
    results = []
    try:
        for name in names:
            results.append(run_case(name, CASES[name], args.reference_bin, targets, base / name))
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    parameters = {"contraction_rate": CONTRACTION_RATE, "reference_temperature": REFERENCE_TEMPERATURE,
                  "phi_nominal": PHI_NOMINAL, "seed": SEED, "p_targets": list(targets), "cases": names,
                  "host_cpu": _cpu_model(), "timestamp": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    ds = to_dataset(results, targets, parameters)
    OUT.mkdir(parents=True, exist_ok=True)
    write_dataset(ds, OUT / "ls_vs_reference.nc")
    plot(ds, OUT / "ls_vs_reference.png")
    print_table(ds)


def _cpu_model() -> str:
    """The machine as the standard library reports it (architecture, processor, CPU count)."""
    return f"{platform.machine()} {platform.processor() or 'unknown processor'}, {os.cpu_count()} CPUs"


def print_table(ds: xr.Dataset) -> None:
    print(f"\n{'case':14s} {'code':10s} {'collisions':>11s} {'CPU s':>8s} {'coll/CPU-s':>11s}"
          + "".join(f" {'t(p=' + format(t, 'g') + ')':>11s} {'phi':>7s}" for t in ds.p_target.values))
    for c in ds.case.values:
        for code in ds.code.values:
            e = ds.sel(case=c, code=code)
            row = (f"{c:14s} {code:10s} {int(e.collisions):11d} {float(e.cpu_time):8.2f} "
                   f"{float(e.collisions_per_cpu_second):11.0f}")
            for t in ds.p_target.values:
                row += f" {float(e.cpu_time_to_target.sel(p_target=t)):11.2f} {float(e.phi_at_target.sel(p_target=t)):7.4f}"
            print(row)
        print(f"{c:14s} {'ratio':10s} rate jamflow/reference = {float(ds.rate_ratio.sel(case=c)):.3f}; CPU time "
              + ", ".join(f"p={t:g}: {float(ds.cpu_time_ratio.sel(case=c, p_target=t)):.2f}" for t in ds.p_target.values))


if __name__ == "__main__":
    main()
