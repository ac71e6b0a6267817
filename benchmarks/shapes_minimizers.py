"""FIRE against conjugate gradients for shaped bodies with rotations (issue 23, Generation).

The paper minimises with CG; jamflow's shape jamming uses FIRE 2.0 over centres and
orientations (orientations with their moments of inertia). Both minimisers run on the
same model from the same starts: each vendored jammed shape packing (``tests/data``)
compressed affinely by a relative packing-fraction step ``dphi`` (centres and box
scaled by ``(1 + dphi)^(-1/2)``, shapes unchanged), then minimised at the fixed box
to ``max sqrt(F^2 + (tau / l)^2) <= FORCE_TOL``. Recorded per run: force evaluations,
CPU time, the final energy and largest generalised force; the two minima are compared
by their energies and by the largest centre and orientation difference.

Run: ``python benchmarks/shapes_minimizers.py`` (about a minute); writes
``benchmarks/output/shapes_minimizers.nc`` and ``.png``.
"""

from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.minimize import minimize
from jamflow.plots import save_figure
from jamflow.shapes.counting import shape_model_of

OUT = Path(__file__).resolve().parent / "output"
DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
PACKINGS = ("shapes_ellipse_alpha1.001_n16_p1e-7.nc", "shapes_circulo_line_a1.1_n16_p1e-6.nc",
            "shapes_circulo_line_a1.03_n32_p1e-7.nc", "shapes_dumbbell_ar3_n32_p1e-9.nc")
#: relative compressions of the jammed packings [1]
DPHI = (1e-4, 1e-3)
METHODS = ("fire", "cg")
#: generalised force tolerance [k length]; above the F / tau floors of these packings (< 1e-13)
FORCE_TOL = 1e-12


def compressed(packing, dphi: float):
    """The packing with centres and box scaled by ``(1 + dphi)^(-1/2)`` (2D), shapes unchanged."""
    s = (1.0 + dphi) ** -0.5
    return packing.evolve(position=packing.position * s, box=packing.box.scaled(s))


def main() -> None:
    shape = (len(PACKINGS), len(DPHI), len(METHODS))
    evals, cpu, energy, fmax = (np.full(shape, np.nan) for _ in range(4))
    dx, dtheta = (np.full(shape[:2], np.nan) for _ in range(2))
    for a, name in enumerate(PACKINGS):
        base = read_packing(DATA / name, None)
        for b, dphi in enumerate(DPHI):
            model, q = shape_model_of(compressed(base, dphi))
            start = model.positions(q)
            for method in METHODS:  # untimed: numba compiles the family's kernels on first use
                minimize(model, start, method, FORCE_TOL, max_steps=5)
            ends = []
            for c, method in enumerate(METHODS):
                t0 = time.process_time()
                res = minimize(model, start, method, FORCE_TOL)
                cpu[a, b, c] = time.process_time() - t0
                evals[a, b, c], energy[a, b, c], fmax[a, b, c] = res.evaluations, res.energy, res.max_force
                ends.append(res.position)
                print(f"{name:42s} dphi {dphi:.0e} {method:4s} {res.evaluations:7d} evaluations "
                      f"{cpu[a, b, c]:7.2f} s CPU  U {res.energy:.12e}  max F {res.max_force:.2e}  "
                      f"converged {res.converged}", flush=True)
            diff = model.box.minimum_image(ends[1][:, :2] - ends[0][:, :2])
            dx[a, b] = float(np.abs(diff).max())
            dtheta[a, b] = float(np.abs(np.angle(np.exp(1j * (ends[1][:, 2] - ends[0][:, 2])))).max())
            print(f"{'':42s} CG / FIRE: evaluations {evals[a, b, 1] / evals[a, b, 0]:.2f}, CPU "
                  f"{cpu[a, b, 1] / cpu[a, b, 0]:.2f}; |dU|/U {abs(energy[a, b, 1] / energy[a, b, 0] - 1):.1e}, "
                  f"max |dx| {dx[a, b]:.1e}, max |dtheta| {dtheta[a, b]:.1e}", flush=True)
    dims = ("packing", "dphi", "method")
    ds = xr.Dataset(
        {
            "evaluations": (dims, evals, {"units": "1", "long_name": "force evaluations"}),
            "cpu_time": (dims, cpu, {"units": "s", "long_name": "process CPU time of the minimisation"}),
            "energy": (dims, energy, {"units": "k", "long_name": "final energy"}),
            "max_force": (dims, fmax, {"units": "k length", "long_name": "final largest generalised force"}),
            "max_position_difference": (dims[:2], dx, {"units": "length",
                                                      "long_name": "largest centre difference, CG against FIRE"}),
            "max_orientation_difference": (dims[:2], dtheta, {"units": "rad",
                                                             "long_name": "largest orientation difference"}),
        },
        coords={"packing": list(PACKINGS), "dphi": list(DPHI), "method": list(METHODS)},
        attrs=new_dataset_attrs("shapes_minimizers", {"force_tol": FORCE_TOL},
                                note="CPU times on a shared 2-core machine: read the ratios"),
    )
    OUT.mkdir(exist_ok=True)
    write_dataset(ds, OUT / "shapes_minimizers.nc")
    fig, ax = plt.subplots(figsize=(8.5, 4.0))
    x = np.arange(len(PACKINGS) * len(DPHI))
    for c, method in enumerate(METHODS):
        ax.bar(x + (c - 0.5) * 0.38, cpu[:, :, c].ravel(), 0.38, label=method.upper())
    ax.set_xticks(x, ["\n".join(p.split("_")[1:4]) + f"\ndphi {d:.0e}" for p in PACKINGS for d in DPHI], fontsize=7)
    ax.set_yscale("log")
    ax.set_xlabel("packing and compression dphi [1]")
    ax.set_ylabel("CPU time to max F <= 1e-12 [s]")
    ax.legend()
    save_figure(fig, OUT / "shapes_minimizers.png")
    print(f"wrote {OUT / 'shapes_minimizers.nc'} and .png")


if __name__ == "__main__":
    main()
