"""Jamming onset from dilute starts: the search against O'Hern's bisection, every body kind.

For each body kind (2D bidisperse disks and 3D spheres, 2D rigid trimers at fixed box
and shear-stabilised, 3D chains of four, ellipses and circulo-lines of asphericity 1.1),
start packing fraction (0.1, 0.2) and seed, both ways of step 2 of
:mod:`jamflow.minimize.onset` (``onset="search"`` and ``"bisection"``, first step
``delta_phi = 1e-3``) jam the same start to ``P0``. Per run: minimisations (history
length), CPU time of the process, phi_J, the largest trial pressure over ``P0``, and
for spheres and linked spheres the backbone contacts against the isostatic count.

Writes ``benchmarks/output/onset_dilute.nc`` and ``onset_dilute.png`` (minimisations
and CPU time per kind, both methods; phi_J against the bisection's mean from the same start).

Usage: ``python benchmarks/onset_dilute.py [--quick] [--seeds 5] [--kinds ...] [--name STEM]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.analysis.contacts import summarize
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import jam_linked
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.minimize.onset import ONSET_METHODS, JammingSettings
from jamflow.plots import save_figure
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)

OUT = Path(__file__).resolve().parent / "output"
KINDS = ("disks 2D N=64", "spheres 3D N=64", "trimers fixed box K=50", "trimers shear-stab. K=50",
         "chains of 4, 3D K=32", "ellipses N=32", "circulo-lines N=32")


def _run(kind: str, phi0: float, seed: int, onset: str, pressure: float) -> dict:
    """One jamming run; returns its numbers."""
    s = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, onset=onset)
    rng = np.random.default_rng(seed)
    t0 = time.process_time()
    if kind.startswith(("disks", "spheres")):
        d = 2 if kind.startswith("disks") else 3
        res = jam_to_pressure(random_packing(64, d, phi0, "bi", seed=seed), pressure, force_tol=s.force_tol,
                              pressure_rtol=s.pressure_rtol, onset=onset)
        c = summarize(res.packing)
        nc, iso = c.n_contacts, c.isostatic_count
    elif kind.startswith(("trimers", "chains")):
        start = (linked_packing(2, 50, "trimer", rng, phi=phi0)[0] if kind.startswith("trimers")
                 else linked_packing(3, 32, "chain", rng, chain_length=4, phi=phi0)[0])
        res = jam_linked(start, pressure, settings=s, shear_stabilize="shear" in kind)
        nc, iso = res.packing.attrs["n_contacts"], res.packing.attrs["isostatic_count"]
    else:
        table = bidisperse_shapes(unit_shape("ellipse" if kind.startswith("ellipses") else "circulo-line",
                                             asphericity=1.1))
        res = jam_shapes(random_shape_packing(table, 32, phi0, seed), pressure, s)
        nc = iso = -1
    cpu = time.process_time() - t0
    h = res.history
    return {"minimizations": len(h["phi"]), "cpu": cpu, "phi_J": res.packing.packing_fraction,
            "max_trial_pressure": max(h["pressure"]) / pressure, "n_contacts": nc, "isostatic_count": iso,
            "converged": int(res.converged)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed, start 0.2 only")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--pressure", type=float, default=1e-6, help="P0 [epsilon / <D>^d]")
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--name", default="onset_dilute", help="stem of the output files in benchmarks/output")
    ap.add_argument("--plot-only", action="store_true", help="redraw the plot from benchmarks/output/NAME.nc")
    args = ap.parse_args()
    if args.plot_only:
        ds = xr.load_dataset(OUT / f"{args.name}.nc")
        summary(ds)
        plot(ds, OUT / f"{args.name}.png")
        return
    phis = [0.2] if args.quick else [0.1, 0.2]
    seeds = [1] if args.quick else list(range(1, args.seeds + 1))
    names = ("minimizations", "cpu", "phi_J", "max_trial_pressure", "n_contacts", "isostatic_count", "converged")
    data = {k: np.full((len(args.kinds), len(phis), len(ONSET_METHODS), len(seeds)), np.nan) for k in names}
    for a, kind in enumerate(args.kinds):
        _run(kind, 0.1, 99, "search", 1e-3)  # untimed: numba compiles this kind's kernels
        for b, phi0 in enumerate(phis):
            for m, onset in enumerate(ONSET_METHODS):
                for k, seed in enumerate(seeds):
                    row = _run(kind, phi0, seed, onset, args.pressure)
                    for key in names:
                        data[key][a, b, m, k] = row[key]
                    print(f"{kind:26s} phi0 {phi0:.1f} {onset:9s} seed {seed}: {row['minimizations']:5d} "
                          f"minimisations, CPU {row['cpu']:7.2f} s, phi_J {row['phi_J']:.6f}, max trial P/P0 "
                          f"{row['max_trial_pressure']:.3g}, N_c {row['n_contacts']} / iso {row['isostatic_count']}",
                          flush=True)
    dims = ("kind", "phi_start", "onset", "seed")
    meta = {"minimizations": ("1", "minimisations to P0 (history length)"),
            "cpu": ("s", "CPU time of the process for the whole jamming run"),
            "phi_J": ("1", "packing fraction at P0"),
            "max_trial_pressure": ("1", "largest pressure of any minimisation over P0"),
            "n_contacts": ("1", "backbone contacts (-1: not counted, shapes)"),
            "isostatic_count": ("1", "isostatic count of the backbone (-1: not counted, shapes)"),
            "converged": ("1", "final minimisation met both tolerances (1)")}
    ds = xr.Dataset({k: (dims, data[k], {"units": u, "long_name": ln}) for k, (u, ln) in meta.items()},
                    coords={"kind": args.kinds, "phi_start": phis, "onset": list(ONSET_METHODS), "seed": seeds},
                    attrs=new_dataset_attrs("jamflow onset from dilute starts", vars(args)))
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / f"{args.name}.nc")
    summary(ds)
    plot(ds, OUT / f"{args.name}.png")


def summary(ds: xr.Dataset) -> None:
    """Mean minimisations and CPU time, and phi_J mean +- standard error, per kind, start and method."""
    n = ds.sizes["seed"]
    for kind in ds.kind.values:
        for phi0 in ds.phi_start.values:
            cells = []
            for onset in ds.onset.values:
                r = ds.sel(kind=kind, phi_start=phi0, onset=onset)
                se = float(r.phi_J.std(ddof=1)) / np.sqrt(n) if n > 1 else np.nan
                cells.append(f"{onset}: {float(r.minimizations.mean()):6.1f} min., CPU {float(r.cpu.mean()):6.2f} s, "
                             f"phi_J {float(r.phi_J.mean()):.5f} +- {se:.5f}")
            print(f"{kind:26s} {phi0:.1f} | " + " | ".join(cells))


def plot(ds: xr.Dataset, path: Path) -> None:
    """Minimisations, CPU time and phi_J per body kind, both methods, from each start."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    x = np.arange(ds.sizes["kind"])
    width = 0.8 / (ds.sizes["onset"] * ds.sizes["phi_start"])
    n = ds.sizes["seed"]
    for j, (onset, phi0) in enumerate((o, p) for o in ds.onset.values for p in ds.phi_start.values):
        r = ds.sel(onset=onset, phi_start=phi0)
        style = dict(width=width, color=f"C{j}", label=f"{onset}, from phi = {phi0:.1f}")
        axes[0].bar(x + j * width, r.minimizations.mean("seed"), **style)
        axes[1].bar(x + j * width, r.cpu.mean("seed"), **style)
        se = r.phi_J.std("seed", ddof=1) / np.sqrt(n) if n > 1 else 0 * r.phi_J.mean("seed")
        reference = ds.phi_J.sel(onset="bisection", phi_start=phi0).mean("seed")
        axes[2].errorbar(x + j * width, r.phi_J.mean("seed") - reference, yerr=se, fmt="o", color=f"C{j}",
                         label=style["label"])
    for ax, label in zip(axes, ("minimisations to P0 [1]", "CPU time per jamming run [s]",
                                "phi_J - bisection mean phi_J (+- s.e.) [1]")):
        ax.set_xticks(x + 0.4 - width / 2)
        ax.set_xticklabels(ds.kind.values, rotation=35, ha="right", fontsize=8)
        ax.set_xlabel("body kind [-]")
        ax.set_ylabel(label)
    axes[0].set_yscale("log")
    axes[1].set_yscale("log")
    axes[0].legend(fontsize=7)
    axes[2].axhline(0.0, color="0.5", lw=0.8)
    pressure = json.loads(ds.attrs["parameters"])["pressure"]
    fig.suptitle(f"jamming onset from dilute starts, P0 = {pressure:g} epsilon / <D>^d (2 shared cores)")
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
