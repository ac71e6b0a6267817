"""Linked jamming with and without the constrained Newton polish of the final fixed-box minimisations.

``jam_linked`` (the body of ``jamflow soft-jam`` on linked packings; bisection to ``P0``,
``--force-tol 1e-12 --pressure-rtol 1e-3 --delta-phi 1e-2``) of bidisperse 3D chains of four
with frozen angles (``jamflow init-chains --dispersity bi --ratio 1.4``), each start run with
``JammingSettings.newton_polish`` off and on, alternating, in one process after an untimed
warm-up of both. Per run: CPU time (``time.process_time``), FIRE steps, minimisations, the
polish's tries (successful, trial steps, CPU) and the checks of the result: converged, the
final pressure in the window, ``N_c >= N_iso`` by rank (``count_bodies``, the attributes of
``jam_linked``) and the largest link error. Writes ``benchmarks/output/linked_newton.nc`` and
``.png`` (other cells or seeds: ``linked_newton_<cells>``).

Usage: ``python benchmarks/linked_newton.py [--cells 1024:fixed 256:fixed] [--seeds 4] [--quick]``
(``--quick``: N = 256, one seed). Fixed boxes only: a shear-stabilised run ends with the enthalpy
stage (volume free), which the polish does not touch, and ``jam_linked`` refuses the pair.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _cells import cell_bars, rows_dataset, save_chart

import jamflow.minimize.onset as onset
from jamflow.chains.jamming import jam_linked
from jamflow.io import read_packing, write_dataset
from jamflow.minimize.onset import JammingSettings

OUT = Path(__file__).resolve().parent / "output"
JAMFLOW = str(Path(sys.executable).with_name("jamflow"))
P0 = 1e-4
CELLS = ["1024:fixed", "256:fixed"]
SEEDS = 4


def _start(tmp: Path, n: int, seed: int) -> Path:
    path = tmp / f"start_{n}_{seed}.nc"
    if not path.exists():
        subprocess.run([JAMFLOW, "init-chains", "--quiet", "--d", "3", "--cluster", "chain", "--chain-length", "4",
                        "--clusters", str(n // 4), "--dispersity", "bi", "--ratio", "1.4", "--seed", str(seed),
                        str(path)], check=True, stdout=subprocess.DEVNULL)
    return path


def _run(path: Path, shear: bool, polish: bool, tries: list) -> dict:
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2, newton_polish=polish)
    tries.clear()
    t = time.process_time()
    res = jam_linked(read_packing(path), P0, settings=settings, shear_stabilize=shear)
    cpu = time.process_time() - t
    a = res.packing.attrs
    return {"cpu_s": cpu, "steps": int(a["fire_steps"]), "minimisations": int(a["onset_minimizations"]),
            "polish_tries": len(tries), "polish_successes": sum(ok for ok, _, _ in tries),
            "polish_trial_steps": sum(k for _, k, _ in tries), "polish_cpu_s": sum(c for _, _, c in tries),
            "converged": int(res.converged), "pressure_error": abs(res.history["pressure"][-1] / P0 - 1.0),
            "phi": float(res.packing.packing_fraction), "n_contacts": int(a["n_contacts"]),
            "isostatic_count": int(a["isostatic_count"]), "max_link_error": float(a["max_link_error"]),
            "max_force": float(np.sqrt(a["max_force_sq"]))}


def runs(cells: list[tuple[int, bool]], seeds: int) -> list[dict]:
    tries: list = []
    original = onset.polish_constrained

    def counted(*args, **kwargs):
        t = time.process_time()
        out = original(*args, **kwargs)
        tries.append((out.result is not None, out.iterations, time.process_time() - t))
        return out

    onset.polish_constrained = counted
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for shear in sorted({s for _, s in cells}):  # untimed warm-up: every kernel loaded or compiled
            for polish in (False, True):
                _run(_start(tmp, 256, 1), shear, polish, tries)
        for n, shear in cells:
            for seed in range(1, seeds + 1):
                path = _start(tmp, n, seed)
                for polish in (False, True):
                    r = {"n": n, "shear": int(shear), "seed": seed, "polish": int(polish),
                         **_run(path, shear, polish, tries)}
                    rows.append(r)
                    print(f"N={n} {'shear' if shear else 'fixed'} seed {seed} polish {polish}: CPU {r['cpu_s']:.2f} s, "
                          f"{r['steps']} FIRE steps, {r['minimisations']} minimisations, polish {r['polish_successes']}"
                          f"/{r['polish_tries']} tries ({r['polish_trial_steps']} trial steps, {r['polish_cpu_s']:.2f} s); "
                          f"phi {r['phi']:.10f}, |P/P0-1| {r['pressure_error']:.1e}, max F {r['max_force']:.1e}, "
                          f"N_c {r['n_contacts']} / iso {r['isostatic_count']}, link error {r['max_link_error']:.1e}, "
                          f"converged {r['converged']}", flush=True)
    onset.polish_constrained = original
    for n, shear in cells:
        sel = {p: [r for r in rows if (r["n"], r["shear"], r["polish"]) == (n, int(shear), p)] for p in (0, 1)}
        cpu = {p: sum(r["cpu_s"] for r in sel[p]) for p in (0, 1)}
        steps = {p: sum(r["steps"] for r in sel[p]) for p in (0, 1)}
        print(f"N={n} {'shear' if shear else 'fixed'} over {seeds} seeds: CPU with/without polish {cpu[1]:.1f} / "
              f"{cpu[0]:.1f} s = {cpu[1] / cpu[0]:.3f}; FIRE steps {steps[1]} / {steps[0]} = {steps[1] / steps[0]:.3f}")
    return rows


def output(rows: list[dict], args: argparse.Namespace) -> None:
    default = args.cells == CELLS and args.seeds == SEEDS
    name = "linked_newton" if default else "linked_newton_" + "_".join(args.cells).replace(":", "-")
    ds = rows_dataset(rows, "jamflow benchmark: linked jamming with and without the Newton polish", args,
                      "CPU time in one process on 2 shared cores; compare the two variants of a start (run "
                      "alternating)")
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / f"{name}.nc")
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    cells = sorted({(r["n"], r["shear"]) for r in rows})
    heights, points = [], []
    for n, shear in cells:
        on = {r["seed"]: r["cpu_s"] for r in rows if (r["n"], r["shear"], r["polish"]) == (n, shear, 1)}
        off = {r["seed"]: r["cpu_s"] for r in rows if (r["n"], r["shear"], r["polish"]) == (n, shear, 0)}
        heights.append(sum(on.values()) / sum(off.values()))
        points.append([on[s] / off[s] for s in on])
    cell_bars(ax, heights, points, [s for _, s in cells], [f"N={n}\n{'shear' if s else 'fixed'}" for n, s in cells])
    ax.axhline(1.0, color="r", lw=1)
    save_chart(fig, ax, "3D chains of four (N spheres, box)", "CPU time with / without polish (1)", OUT / name)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", nargs="+", default=CELLS, help="N:fixed pairs (fixed boxes: see the module doc)")
    ap.add_argument("--seeds", type=int, default=SEEDS)
    ap.add_argument("--quick", action="store_true", help="N = 256, one seed")
    args = ap.parse_args()
    if args.quick:
        args.cells, args.seeds = ["256:fixed"], 1
    if any(not c.endswith(":fixed") for c in args.cells):
        ap.error("cells are N:fixed: the polish ends fixed-box minimisations only (module doc)")
    cells = [(int(c.split(":")[0]), c.split(":")[1] == "shear") for c in args.cells]
    output(runs(cells, args.seeds), args)


if __name__ == "__main__":
    main()
