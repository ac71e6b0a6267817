"""Whole ``jamflow soft-jam`` of shaped bodies against bidisperse disks, side by side in one run.

For each N and each kind, one start (``jamflow init-shapes --phi 0.4 --seed S`` or, for
disks, ``jamflow init --d 2 --dispersity bi --phi 0.4 --seed S``) and the whole command
``jamflow soft-jam IN OUT --pressure P0 --quiet`` (default bisection onset, default
tolerances) in its own process with a wall-clock limit; the kinds of one N run one after
the other, so they share the machine's load. Recorded per run: the command's CPU time
(``getrusage`` of the child, start-up included) and wall time, FIRE steps and bisection
minimisations, ``phi_J`` and the contact number ``2 N_c / N``, or that it did not finish
within ``--timeout``. The ratio to the disks' CPU time of the same N is printed.

Kinds: ``disk``, ``ellipse``, ``circulo-line`` (``--asphericity``), ``reuleaux``,
``circulo-polygon-3/5`` (regular, ``--asphericity``), ``circulo-polygon-8`` (regular,
``A = 1.03``: a rounded 8-gon stays below 1.055), ``dumbbell`` (the paper's shaft
``X = 2``), ``ellipse-1e-3`` and ``ellipse-1e-4`` (near-disk ellipses, aspect ratio
``1 + 1e-3``, ``1 + 1e-4``).

Writes ``benchmarks/output/shapes_soft_jam.nc`` and ``shapes_soft_jam.png``.

Usage: ``python benchmarks/shapes_soft_jam.py [--n 100 480] [--kinds disk ellipse circulo-line]
[--pressure 1e-6] [--timeout 900] [--quick] [--plot-only]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.plots import save_figure

OUT = Path(__file__).resolve().parent / "output"

#: ``jamflow init-shapes`` arguments of each shaped kind (``{A}``: ``--asphericity``).
SHAPE_ARGS: dict[str, list[str]] = {
    "ellipse": ["--shape", "ellipse", "--asphericity", "{A}"],
    "circulo-line": ["--shape", "circulo-line", "--asphericity", "{A}"],
    "reuleaux": ["--shape", "reuleaux"],
    "circulo-polygon-3": ["--shape", "circulo-polygon", "--sides", "3", "--asphericity", "{A}"],
    "circulo-polygon-5": ["--shape", "circulo-polygon", "--sides", "5", "--asphericity", "{A}"],
    # a rounded regular 8-gon has A < 1.0548
    "circulo-polygon-8": ["--shape", "circulo-polygon", "--sides", "8", "--asphericity", "1.03"],
    "dumbbell": ["--shape", "dumbbell", "--shaft-length", "2"],
    "ellipse-1e-3": ["--shape", "ellipse", "--aspect-ratio", "1.001"],
    "ellipse-1e-4": ["--shape", "ellipse", "--aspect-ratio", "1.0001"],
}
KINDS = ("disk", *SHAPE_ARGS)


def _child_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def init_command(kind: str, n: int, seed: int, asphericity: float, path: Path) -> list[str]:
    """The ``jamflow init`` / ``init-shapes`` command of one start at phi = 0.4."""
    if kind == "disk":
        return ["jamflow", "init", "--d", "2", "--dispersity", "bi", "--phi", "0.4", "--seed", str(seed),
                "--n", str(n), "--quiet", str(path)]
    shape = [a.format(A=asphericity) for a in SHAPE_ARGS[kind]]
    return ["jamflow", "init-shapes", *shape, "--phi", "0.4", "--seed", str(seed), "--n", str(n), "--quiet", str(path)]


def run_one(kind: str, n: int, args: argparse.Namespace, work: Path) -> dict:
    """One start and its whole ``soft-jam``; NaNs and ``finished = 0`` past the time limit."""
    start, out = work / f"{kind}_{n}.nc", work / f"{kind}_{n}_jammed.nc"
    subprocess.run(init_command(kind, n, args.seed, args.asphericity, start), check=True)
    cmd = ["jamflow", "soft-jam", str(start), str(out), "--pressure", f"{args.pressure:g}", "--quiet"]
    c0, t0 = _child_cpu(), time.perf_counter()
    try:
        subprocess.run(cmd, check=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        # subprocess.run kills and waits for the child, so its CPU time is counted
        return {"cpu": _child_cpu() - c0, "wall": time.perf_counter() - t0, "finished": 0}
    row = {"cpu": _child_cpu() - c0, "wall": time.perf_counter() - t0, "finished": 1}
    p = read_packing(out, overlap_tol=None)
    row["steps"] = float(p.attrs.get("steps", p.attrs.get("fire_steps", np.nan)))
    row["minimizations"] = float(p.attrs.get("bisection_steps", p.attrs.get("onset_minimizations", np.nan)))
    row["phi_J"] = p.packing_fraction
    row["z"] = 2.0 * len(p.contacts) / p.n
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 480])
    ap.add_argument("--kinds", nargs="+", choices=KINDS, default=["disk", "ellipse", "circulo-line"])
    ap.add_argument("--pressure", type=float, default=1e-6)
    ap.add_argument("--asphericity", type=float, default=1.1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=900.0, help="wall-clock limit of one soft-jam [s]")
    ap.add_argument("--quick", action="store_true", help="N = 32, disks, ellipses and circulo-lines")
    ap.add_argument("--output", type=Path, default=OUT / "shapes_soft_jam.nc")
    ap.add_argument("--plot-only", action="store_true", help="redraw the plot from --output")
    args = ap.parse_args()
    if args.plot_only:
        plot(xr.load_dataset(args.output), args.output.with_suffix(".png"))
        return
    if args.quick:
        args.n, args.kinds = [32], ["disk", "ellipse", "circulo-line"]
    kinds = ["disk", *[k for k in args.kinds if k != "disk"]]
    names = ("cpu", "wall", "finished", "steps", "minimizations", "phi_J", "z")
    data = {name: np.full((len(kinds), len(args.n)), np.nan) for name in names}
    # untimed warm-up: numba compiles every kernel of the kinds on first use
    with tempfile.TemporaryDirectory() as tmp:
        warm = argparse.Namespace(**{**vars(args), "pressure": 1e-3})
        for kind in kinds:
            run_one(kind, 16, warm, Path(tmp))
    with tempfile.TemporaryDirectory() as tmp:
        for b, n in enumerate(args.n):
            for a, kind in enumerate(kinds):
                row = run_one(kind, n, args, Path(tmp))
                for name, value in row.items():
                    data[name][a, b] = value
                ratio = row["cpu"] / data["cpu"][0, b]
                done = (f"phi_J {row['phi_J']:.6f}  2Nc/N {row['z']:.3f}  steps {row['steps']:.0f}  "
                        f"minimisations {row['minimizations']:.0f}" if row["finished"] else
                        f"did not finish in {args.timeout:g} s wall")
                print(f"N={n:4d} {kind:18s} CPU {row['cpu']:7.1f} s ({ratio:5.1f}x disks)  wall {row['wall']:7.1f} s  "
                      f"{done}", flush=True)
    dims = ("kind", "N")
    units = {"cpu": ("s", "CPU time of the whole soft-jam command"), "wall": ("s", "wall time of the command"),
             "finished": ("1", "1 if the command finished within the time limit"),
             "steps": ("1", "FIRE steps of the protocol"), "minimizations": ("1", "bisection minimisations"),
             "phi_J": ("1", "packing fraction at P0"), "z": ("1", "2 N_c / N (contacting pairs)")}
    ds = xr.Dataset({name: (dims, data[name], {"units": units[name][0], "long_name": units[name][1]})
                     for name in names}, coords={"kind": kinds, "N": args.n},
                    attrs={**new_dataset_attrs("jamflow shape soft-jam benchmark",
                                               {**vars(args), "output": str(args.output)}),
                           "load_average": json.dumps(os.getloadavg()), "python": sys.version.split()[0]})
    args.output.parent.mkdir(parents=True, exist_ok=True)
    write_dataset(ds, args.output)
    plot(ds, args.output.with_suffix(".png"))


def plot(ds: xr.Dataset, path: Path) -> None:
    """CPU time of the command against N (left) and its ratio to the disks' (right), one colour per kind."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    for a, kind in enumerate(ds.kind.values):
        done = ds.finished[a].values == 1
        style = dict(marker="o", color=f"C{a}", label=str(kind))
        ax1.loglog(ds.N[done], ds.cpu[a][done], **style)
        ax1.loglog(ds.N[~done], ds.cpu[a][~done], marker="x", ls="none", color=f"C{a}")
        if kind != "disk":
            ax2.semilogx(ds.N[done], (ds.cpu[a] / ds.cpu[0])[done], **style)
    params = json.loads(ds.attrs["parameters"])
    ax1.set_xlabel("number of bodies N [1]")
    ax1.set_ylabel("CPU time of soft-jam [s]")
    ax1.set_title(f"P0 = {params['pressure']:g}, A = {params['asphericity']:g} (x: not finished)")
    ax2.set_xlabel("number of bodies N [1]")
    ax2.set_ylabel("CPU time / disks' CPU time [1]")
    ax2.axhline(10.0, color="0.6", ls="--", lw=0.8)
    ax1.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
