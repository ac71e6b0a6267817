"""Jamming onset of shaped bodies at pressure ``P0``, with rotations.

The protocol of :mod:`jamflow.minimize.onset` on :class:`~jamflow.models.shapes.ShapeModel`
(VanderWerf et al. Sec. II): isotropic compress/decompress search on ``P(phi)``, each
step a fixed-box FIRE minimisation over centres and orientations (orientations with
their moments of inertia), to within ``bisection_rtol`` of ``P0``; then the enthalpy
``U + P0 V`` is minimised with an isotropic barostat (the compiled engine of
:mod:`jamflow.models.shapes.fast`) until ``|P - P0| <= pressure_rtol P0`` with
``max_i sqrt(F_i^2 + (tau_i / l)^2) <= force_tol`` (``l`` the mean bounding diameter,
:meth:`ShapeModel.max_force`); that stage ends with Newton iterations on the enthalpy
once FIRE is close enough (:mod:`jamflow.minimize.newton`: the quartic modes of
hypostatic packings, stiffness ~ P0, cost FIRE most of its steps), to the same
tolerances and only at a minimum. The box keeps its shape; shapes are never rescaled, so
the packing fraction is the search variable.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..minimize.onset import JammingSettings, jam_model_to_pressure
from ..models.shapes import ShapeModel
from ..protocols.soft_jam import JammingResult
from ..state.packing import Packing

__all__ = ["jam_shapes", "paper_units", "shape_packing"]


def shape_packing(model: ShapeModel, configuration: np.ndarray, template: Packing, parameters: dict,
                  attrs: dict) -> Packing:
    """Packing of a model configuration: wrapped centres, interacting pairs as contacts.

    Contact forces are the norms of the translational pair force [k length];
    ``max_force_sq`` and ``max_torque_sq`` (per body, from the total gradient) go to
    the attributes.
    """
    q = model.dofs(configuration)
    model.check_cores(q)
    pairs = model.pair_table(q)
    ev = model.evaluate(q)
    g = model.positions(model.project(ev.gradient, q))
    side = float(np.sqrt(model.box.volume))
    attrs = {**attrs, "max_force_sq": float(np.max(np.sum(g[:, :2] ** 2, axis=1))),
             "max_torque_sq": float(np.max(g[:, 2] ** 2)), "energy": ev.energy,
             "spring_constant": model.k, "mass": model.mass, "frozen_orientations": int(not model.rotations),
             **paper_units(side, model.k, ev.energy)}
    return Packing(
        position=model.box.wrap(configuration[:, :2]), diameter=model.bounding_diameter, box=model.box,
        contacts=np.stack([pairs["i"], pairs["j"]], axis=1), force=np.linalg.norm(pairs["gradient"][:, 3:5], axis=1),
        pressure=float(np.trace(ev.virial) / (2.0 * model.box.volume)), protocol=template.protocol + ">soft-shapes",
        seed=template.seed, parameters=parameters, attrs=attrs,
        orientation=np.mod(configuration[:, 2], 2.0 * np.pi), shapes=model.shapes, shape_index=model.shape_index,
    )


def paper_units(box_side: float, k: float, energy: float) -> dict:
    """The conversion to VanderWerf et al.'s units (lengths in the box side ``L``, energies in
    ``k L^2``, pressures in ``k``), as dataset attributes.

    jamflow's shapes have a mean area-equivalent diameter 1 and ``k = 1``; the paper's box
    has ``L = 1``. A pressure in units of ``k`` is ``P / k``, which does not depend on the
    length unit in 2D (``P`` and ``k`` are both energy / length^2): scaling every length
    by ``s`` scales overlaps, forces and the virial by ``s``, ``s`` and ``s^2``, the area by
    ``s^2``. So jamflow's ``P0 = 1e-9`` is the paper's ``P0 = 1e-9``, at every ``N``.
    Lengths divide by ``L``, energies by ``k L^2``; orientations are the same radians.
    """
    return {"paper_length_unit": box_side, "paper_energy": energy / (k * box_side**2)}


def jam_shapes(packing: Packing, pressure: float, settings: JammingSettings = JammingSettings(),
               progress: Callable[[dict], None] | None = None, rotations: bool = True) -> JammingResult:
    """Jam a shape packing to ``P0`` (module doc); lengths stay those of the input.

    Parameters
    ----------
    packing : Packing
        Shaped bodies (one family with an energy model), overlap-free or soft.
    pressure : float
        Target pressure ``P0`` [k length^0: energy / length^2 with k = 1].
    settings : JammingSettings
        Tolerances and budget (``box_dof`` is ignored: the box stays square).
    rotations : bool
        False jams with every orientation frozen (Fig. 3a), stored as the attribute
        ``frozen_orientations = 1``.
    """
    if packing.shapes is None:
        raise ValueError("jam_shapes needs a packing of shaped bodies (shape table and orientations)")
    if not (np.isfinite(pressure) and pressure > 0.0):
        raise ValueError(f"--pressure must be positive and finite, got {pressure}")
    model = ShapeModel(packing.box, packing.shapes, packing.shape_index, rotations=rotations)
    start = np.column_stack([packing.position, packing.orientation])
    model.check_cores(model.dofs(start))
    model, final, history, steps = jam_model_to_pressure(model, start, packing.packing_fraction, pressure,
                                                         replace(settings, box_dof="isotropic", newton_polish=True),
                                                         progress)
    # the enthalpy stage ends in a scaled box: the packing is that box's
    model = ShapeModel(final.box, model.shapes, model.shape_index, model.k, model.mass, rotations=rotations)
    c = settings
    params = {"pressure": pressure, "force_tol": c.force_tol, "pressure_rtol": c.pressure_rtol,
              "bisection_rtol": c.bisection_rtol, "bisection_force_factor": c.bisection_force_factor,
              "fire": c.fire_params.as_dict(), "family": model.family, "rotations": int(rotations),
              "onset": c.onset, "delta_phi": c.delta_phi, "newton_polish": 1}
    attrs = {"steps": steps, "bisection_steps": len(history["phi"]), "onset_method": c.onset,
             "converged": int(final.converged),
             "max_generalized_force": final.max_force}
    out = shape_packing(model, final.position, packing, params, attrs)
    return JammingResult(out, bool(final.converged), history, steps)
