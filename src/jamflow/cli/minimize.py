"""``jamflow minimize``: plain energy minimisation at a fixed box, for any body model (LAMMPS ``minimize``)."""

from __future__ import annotations

import argparse

import numpy as np

from ..chains.entanglement import check_untangled
from ..chains.jamming import linked_soft_packing
from ..io import read_packing, write_packing
from ..minimize import METHODS, minimize
from ..minimize.model import EnergyModel
from ..models import model_for
from ..models.links import LinkedSpheresModel
from ..models.shapes import ShapeModel
from ..models.spheres.potential import PowerLawPotential
from ..protocols.soft_jam import soft_packing
from ..shapes.jamming import shape_packing
from ..state.packing import Packing
from ..tolerances import MINIMIZE_FORCE_TOL
from .common import add_command, add_quiet, print_summary, stage_parameters
from .soft import EXPONENT
from .types import count, path_with_suffix, positive


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "minimize", _minimize,
                    "minimise the energy at a fixed box (soft spheres, linked spheres, shaped bodies with "
                    "rotations) with FIRE, CG or steepest descent", reads=("input",), writes=("out",), packings=("out",))
    p.add_argument("input", help="input netCDF packing (overlaps allowed; links make it a linked-spheres model, "
                                 "a shape table a shaped-body model)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF packing (contacts = overlapping unlinked pairs with their forces)")
    p.add_argument("--force-tol", type=positive, default=MINIMIZE_FORCE_TOL,
                   help=f"stop when the largest per-particle (projected) force norm is at most this "
                        f"[epsilon / length] (default {MINIMIZE_FORCE_TOL:g})")
    p.add_argument("--max-steps", type=count, default=1_000_000, help="step budget (default 1000000)")
    p.add_argument("--method", choices=METHODS, default="fire", help="minimiser (default fire)")
    p.add_argument("--exponent", type=EXPONENT, default=2.0,
                   help="contact potential exponent w of spheres (2 harmonic, 2.5 Hertz; shapes: linear spring only)")
    add_quiet(p)


def _minimize(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, None)
    model, start = _model(args, packing)
    res = minimize(model, start, args.method, args.force_tol, args.max_steps)
    if not res.converged:
        raise RuntimeError(f"{args.method} did not reach --force-tol {args.force_tol:g} within "
                           f"--max-steps {args.max_steps} (max_force {res.max_force:.3g}); nothing written")
    shaped = isinstance(model, ShapeModel)
    energy_unit = "k" if shaped else "epsilon"
    attrs = {"energy": res.energy, "energy_unit": energy_unit, "max_force": res.max_force,
             "n_force_evaluations": res.evaluations, "minimize_steps": res.steps, "converged": 1}
    parameters = stage_parameters(args, "input", "out")
    if shaped:
        out = shape_packing(model, res.position, packing, parameters, {**packing.attrs, **attrs})
    elif isinstance(model, LinkedSpheresModel):
        attrs["potential_exponent"] = model.potential.exponent
        check_untangled(model.links, res.position, model.box, packing.diameter, res.pressure, model.potential)
        out = linked_soft_packing(packing, model, res, ">minimize", attrs, parameters)
    else:
        attrs["potential_exponent"] = model.potential.exponent
        out = soft_packing(res.position, packing.box, packing.diameter, model.potential, packing, ">minimize",
                           parameters, {**packing.attrs, **attrs})
    write_packing(out, args.out, parameters)
    print_summary(args, args.out, [
        ("method", f"{args.method}, converged after {res.steps} steps"),
        ("n_force_evaluations", res.evaluations),
        ("energy", f"{res.energy:.15g} {energy_unit}"),
        ("max_force", f"{res.max_force:.3g} " + ("k length (force and torque / mean bounding diameter)" if shaped
                                                 else "epsilon/length")),
        ("pressure", f"{res.pressure:.10g} " + ("k" if shaped else "epsilon/length^d")),
        ("contacts", res.n_contacts),
    ])
    return 0


def _model(args: argparse.Namespace, packing: Packing) -> tuple[EnergyModel, np.ndarray]:
    """The energy model of a packing (:func:`jamflow.models.model_for`) and its start."""
    model, q = model_for(packing, PowerLawPotential(exponent=args.exponent))
    return model, model.positions(q)
