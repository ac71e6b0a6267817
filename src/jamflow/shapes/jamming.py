"""Jamming onset of shaped bodies at pressure ``P0``, with rotations.

The protocol of :mod:`jamflow.minimize.onset` on :class:`~jamflow.models.shapes.ShapeModel`
(VanderWerf et al. Sec. II): isotropic compress/decompress search on ``P(phi)``, each
step a fixed-box FIRE minimisation over centres and orientations (orientations with
their moments of inertia), to within ``bisection_rtol`` of ``P0``; then the enthalpy
``U + P0 V`` is minimised with an isotropic barostat (the compiled engine of
:mod:`jamflow.models.shapes.fast`) until ``|P - P0| <= pressure_rtol P0`` with
``max_i sqrt(F_i^2 + (tau_i / l)^2) <= force_tol`` (``l`` the mean bounding diameter,
:meth:`ShapeModel.max_force`). The box keeps its shape; shapes are never rescaled, so
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

__all__ = ["jam_shapes", "shape_packing"]


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
    g = model.positions(ev.gradient)
    attrs = {**attrs, "max_force_sq": float(np.max(np.sum(g[:, :2] ** 2, axis=1))),
             "max_torque_sq": float(np.max(g[:, 2] ** 2)), "energy": ev.energy,
             "spring_constant": model.k, "mass": model.mass}
    return Packing(
        position=model.box.wrap(configuration[:, :2]), diameter=model.bounding_diameter, box=model.box,
        contacts=np.stack([pairs["i"], pairs["j"]], axis=1), force=np.linalg.norm(pairs["gradient"][:, 3:5], axis=1),
        pressure=float(np.trace(ev.virial) / (2.0 * model.box.volume)), protocol=template.protocol + ">soft-shapes",
        seed=template.seed, parameters=parameters, attrs=attrs,
        orientation=np.mod(configuration[:, 2], 2.0 * np.pi), shapes=model.shapes, shape_index=model.shape_index,
    )


def jam_shapes(packing: Packing, pressure: float, settings: JammingSettings = JammingSettings(),
               progress: Callable[[dict], None] | None = None) -> JammingResult:
    """Jam a shape packing to ``P0`` (module doc); lengths stay those of the input.

    Parameters
    ----------
    packing : Packing
        Shaped bodies (one family with an energy model), overlap-free or soft.
    pressure : float
        Target pressure ``P0`` [k length^0: energy / length^2 with k = 1].
    settings : JammingSettings
        Tolerances and budget (``box_dof`` is ignored: the box stays square).
    """
    if packing.shapes is None:
        raise ValueError("jam_shapes needs a packing of shaped bodies (shape table and orientations)")
    if not (np.isfinite(pressure) and pressure > 0.0):
        raise ValueError(f"--pressure must be positive and finite, got {pressure}")
    model = ShapeModel(packing.box, packing.shapes, packing.shape_index)
    start = np.column_stack([packing.position, packing.orientation])
    model.check_cores(model.dofs(start))
    model, final, history, steps = jam_model_to_pressure(model, start, packing.packing_fraction, pressure,
                                                         replace(settings, box_dof="isotropic"), progress)
    # the enthalpy stage ends in a scaled box: the packing is that box's
    model = ShapeModel(final.box, model.shapes, model.shape_index, model.k, model.mass)
    c = settings
    params = {"pressure": pressure, "force_tol": c.force_tol, "pressure_rtol": c.pressure_rtol,
              "bisection_rtol": c.bisection_rtol, "bisection_force_factor": c.bisection_force_factor,
              "fire": c.fire_params.as_dict(), "family": model.family}
    attrs = {"steps": steps, "bisection_steps": len(history["phi"]), "converged": int(final.converged),
             "max_generalized_force": final.max_force}
    out = shape_packing(model, final.position, packing, params, attrs)
    return JammingResult(out, bool(final.converged), history, steps)
