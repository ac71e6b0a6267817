"""Shape packings: time to one jammed packing against bidisperse disks, and spectrum time.

For each N: bidisperse ellipses and circulo-lines at one asphericity (default
A = 1.1) from ``init-shapes``-style random starts, jammed to P0 with the generic
bisection + FIRE over centres and orientations, the paper's asymmetric dimers
(A = 1.349, rigid two-disk clusters of :mod:`jamflow.chains.dimers` from the dilute
``init-chains`` start, fixed-box bisection with projected FIRE; their "spectrum" is
the dense constrained Hessian of :mod:`jamflow.chains.hessian`), and bidisperse disks (1:1.4, the
sphere code's ``jam_to_pressure`` with its enthalpy minimisation) from a random start
of the same N and seed, all timed side by side in one run (2 shared cores: read the
ratios, not the seconds; process CPU times are recorded beside wall times because on
a loaded machine the wall time mostly measures the other jobs). For every jammed shape packing the full dynamical-matrix
spectrum (dense ``eigh`` of the complex-step Hessian, no fourth derivatives) is timed.

Writes ``benchmarks/output/shapes.nc`` and ``shapes.png`` and prints the numbers.

Usage: ``python benchmarks/shapes.py [--n 16 32] [--pressure 1e-6] [--asphericity 1.1] [--plot-only]``
(the issue's N = 100 and 480 at P0 = 1e-9 are hours on 2 shared cores).
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

from jamflow.chains.builders import linked_packing
from jamflow.chains.hessian import constrained_hessian
from jamflow.chains.jamming import jam_linked
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.minimize.onset import JammingSettings
from jamflow.models.spheres.potential import HARMONIC
from jamflow.plots import save_figure
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)
from jamflow.shapes.counting import count_constraints
from jamflow.shapes.spectrum import spectrum

OUT = Path(__file__).resolve().parent / "output"
FAMILIES = ("disk", "ellipse", "circulo-line", "dimer")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[16, 32])
    ap.add_argument("--pressure", type=float, default=1e-6)
    ap.add_argument("--asphericity", type=float, default=1.1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--plot-only", action="store_true", help="redraw shapes.png from benchmarks/output/shapes.nc")
    args = ap.parse_args()
    if args.plot_only:
        plot(xr.load_dataset(OUT / "shapes.nc"), OUT / "shapes.png")
        return
    settings = JammingSettings(delta_phi=1e-2, pressure_rtol=1e-2)
    # untimed warm-up: numba compiles every family's kernels (and the spectrum's) on first use
    for family in FAMILIES[1:3]:
        table = bidisperse_shapes(unit_shape(family, asphericity=args.asphericity))
        warm = jam_shapes(random_shape_packing(table, 16, 0.4, args.seed), 1e-3, settings).packing
        spectrum(warm, fourth=False)
    jam_to_pressure(random_packing(16, 2, 0.5, "bi", args.seed, 1.4, 0.5), 1e-3, HARMONIC)
    jam_linked(linked_packing(2, 8, "dimer", np.random.default_rng(args.seed))[0], 1e-3, settings=settings)
    shape = (len(FAMILIES), len(args.n))
    jam_time, phi, z, steps, spec_time, n_quartic, jam_cpu, spec_cpu = (np.full(shape, np.nan) for _ in range(8))
    for b, n in enumerate(args.n):
        for a, family in enumerate(FAMILIES):
            t0, c0 = time.perf_counter(), time.process_time()
            if family == "disk":
                start = random_packing(n, 2, 0.5, "bi", args.seed, 1.4, 0.5)
                res = jam_to_pressure(start, args.pressure, HARMONIC, settings.force_tol, settings.pressure_rtol,
                                      settings.delta_phi)
                jam_time[a, b], jam_cpu[a, b] = time.perf_counter() - t0, time.process_time() - c0
                phi[a, b], steps[a, b] = res.packing.packing_fraction, res.steps
            elif family == "dimer":
                res = jam_linked(linked_packing(2, n, "dimer", np.random.default_rng(args.seed))[0], args.pressure,
                                 settings=settings)
                jam_time[a, b], jam_cpu[a, b] = time.perf_counter() - t0, time.process_time() - c0
                phi[a, b], steps[a, b], z[a, b] = res.packing.packing_fraction, res.steps, res.packing.attrs["z"]
                t0, c0 = time.perf_counter(), time.process_time()
                constrained_hessian(res.packing, strain=False)
                spec_time[a, b], spec_cpu[a, b] = time.perf_counter() - t0, time.process_time() - c0
            else:
                table = bidisperse_shapes(unit_shape(family, asphericity=args.asphericity))
                start = random_shape_packing(table, n, 0.4, args.seed)
                res = jam_shapes(start, args.pressure, settings)
                jam_time[a, b], jam_cpu[a, b] = time.perf_counter() - t0, time.process_time() - c0
                phi[a, b], steps[a, b] = res.packing.packing_fraction, res.steps
                z[a, b] = count_constraints(res.packing, "twice")[0].z_eq3
                t0, c0 = time.perf_counter(), time.process_time()
                n_quartic[a, b] = spectrum(res.packing, fourth=False).n_quartic
                spec_time[a, b], spec_cpu[a, b] = time.perf_counter() - t0, time.process_time() - c0
            print(f"N={n:4d} {family:13s} jam {jam_time[a, b]:8.1f} s (CPU {jam_cpu[a, b]:.1f} s)  "
                  f"phi {phi[a, b]:.6f}  z {z[a, b]:.3f}  FIRE steps {int(steps[a, b])}  "
                  f"spectrum {spec_time[a, b]:.2f} s (CPU {spec_cpu[a, b]:.2f} s)  N_1 {n_quartic[a, b]:.0f}",
                  flush=True)
        for a, family in enumerate(FAMILIES[1:], start=1):
            # CPU time: on a loaded machine the wall time mostly measures the other jobs
            print(f"N={n:4d} {family:13s} time / disks: wall {jam_time[a, b] / jam_time[0, b]:.1f}, "
                  f"CPU {jam_cpu[a, b] / jam_cpu[0, b]:.1f}")
    dims = ("family", "N")
    ds = xr.Dataset(
        {"jam_time": (dims, jam_time, {"units": "s", "long_name": "wall time to one jammed packing"}),
         "phi_J": (dims, phi, {"units": "1", "long_name": "packing fraction at P0"}),
         "z": (dims, z, {"units": "1", "long_name": "<z> of Eq. 3 (parallel contacts twice; dimers: rotators 1/3)"}),
         "fire_steps": (dims, steps, {"units": "1", "long_name": "FIRE steps of the protocol"}),
         "spectrum_time": (dims, spec_time, {"units": "s", "long_name": "wall time of the full spectrum"}),
         "jam_cpu": (dims, jam_cpu, {"units": "s", "long_name": "CPU time of the process to one jammed packing"}),
         "spectrum_cpu": (dims, spec_cpu, {"units": "s", "long_name": "CPU time of the full spectrum"}),
         "n_quartic": (dims, n_quartic, {"units": "1", "long_name": "quartic modes N_1 (not counted for dimers)"})},
        coords={"family": list(FAMILIES), "N": args.n},
        attrs=new_dataset_attrs("jamflow shape benchmark", vars(args)),
    )
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "shapes.nc")
    plot(ds, OUT / "shapes.png")


def plot(ds: xr.Dataset, path: Path) -> None:
    """CPU time to a jammed packing and of the spectrum against N, one colour per family."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    for a, family in enumerate(ds.family.values):
        style = dict(marker="o", color=f"C{a}", label=str(family))
        ax1.loglog(ds.N, ds.jam_cpu[a], **style)
        if family != "disk":
            ax2.loglog(ds.N, ds.spectrum_cpu[a], **style)
    ax1.set_xlabel("number of bodies N [1]")
    ax1.set_ylabel("CPU time to a jammed packing [s]")
    params = json.loads(ds.attrs["parameters"])
    ax1.set_title(f"P0 = {params['pressure']:g}, A = {params['asphericity']:g} (dimers 1.349)")
    ax2.set_xlabel("number of bodies N [1]")
    ax2.set_ylabel("full-spectrum CPU time [s]")
    ax2.set_title("dense eigh (dimers: constrained Hessian)")
    ax1.legend()
    ax2.legend()
    fig.tight_layout()
    save_figure(fig, path)

if __name__ == "__main__":
    main()
