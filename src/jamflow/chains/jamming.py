"""Critically jammed linked packings: the jamming bisection of any model, applied to linked spheres.

Protocol (chains paper Sec. III, with the project's bisection to ``P0`` of
:mod:`jamflow.soft.jamming`): lengths are rescaled so the mean diameter is 1 (link
lengths with them); the box is scaled isotropically about the centres, each step
followed by fixed-box FIRE with constraint projection and Newton re-affixing
(:class:`~jamflow.models.links.LinkedSpheresModel`), compressing below ``P0`` and
decompressing above with halving steps, until ``|P - P0| <= pressure_rtol P0`` at
``max |P F| <= force_tol``. ``P`` is the virial pressure of the contact forces and
the link tensions. Scaling the box scales the clusters' centres, not their shapes:
the affine move stretches links by the scale factor and the first re-affixing
restores them (the paper's "cluster size decreased while maintaining their average
positions", seen from the clusters' frame).

The bisection is the default (not the paper's energy-scaling steps of
``phi - phi_J``): it is the project's one jamming protocol, it ends at a stated
pressure, and its fixed-box continuation needs no box degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..bodies import Links
from ..box import Box
from ..models.links import LinkedSpheresModel
from ..packing import Packing, sphere_volume
from ..soft.jamming import JammingResult, JammingSettings, jam_model_to_pressure
from ..soft.minimize import MinimizeResult
from ..soft.potential import HARMONIC, PowerLawPotential, overlapping_pairs
from .builders import check_linked_start
from .clusters import count_clusters
from .shear import ShearStabilizedModel

__all__ = ["jam_linked", "linked_soft_packing"]


def linked_soft_packing(packing: Packing, model: LinkedSpheresModel, res: MinimizeResult, protocol_suffix: str,
                        attrs: dict, parameters: dict, shear_stabilized: bool = False) -> Packing:
    """A minimised linked packing: contacts are the overlapping pairs that are not linked.

    Rattlers are the danglers and rattling clusters of
    :func:`~jamflow.chains.clusters.count_clusters`; their counts, the clusters'
    isostatic count, the largest relative link-length error and the stress
    anisotropy ``stress_deviation = max_ab |W_ab - P' delta_ab| / P'`` (``W`` the
    total virial of pairs and link tensions, ``P' = tr W / d``) go into the attributes.
    """
    box = res.box
    x = box.wrap(res.position)
    pairs, _, f = overlapping_pairs(x, box, model.diameter, model.potential)
    linked = model.links.contains(pairs.i, pairs.j)
    contacts = np.stack([pairs.i, pairs.j], axis=1)[~linked]
    count = count_clusters(len(x), box.d, model.links, contacts, shear_stabilized)
    err = np.abs(model.links.length_errors(x, box))
    # total virial (pairs and link tensions) of the final configuration in its box
    W = LinkedSpheresModel(box, model.diameter, model.links, x, model.potential).evaluate(x.ravel()).virial
    p_virial = float(np.trace(W)) / box.d
    attrs = {**packing.attrs, **attrs, **count.as_dict(), "shear_stabilized": int(shear_stabilized),
             "max_link_error": float(err.max(initial=0.0)),
             "stress_deviation": float(np.max(np.abs(W - p_virial * np.eye(box.d))) / p_virial) if p_virial else 0.0,
             "pressure_comment": "virial pressure of the contact forces and the link tensions"}
    return packing.evolve(position=x, box=box, diameter=model.diameter, links=model.links, contacts=contacts,
                          force=f[~linked], rattler=count.rattler, pressure=res.pressure,
                          protocol=packing.protocol + protocol_suffix, parameters=parameters, attrs=attrs)


def jam_linked(
    packing: Packing,
    pressure: float,
    potential: PowerLawPotential = HARMONIC,
    settings: JammingSettings | None = None,
    progress: Callable[[dict], None] | None = None,
    shear_stabilize: bool = False,
) -> JammingResult:
    """Bring a linked packing to the jamming onset at pressure ``P0`` in a fixed-shape box (module doc).

    Parameters
    ----------
    packing : Packing
        Start with links (overlaps allowed; without links, spheres); checked by
        :func:`~jamflow.chains.builders.check_linked_start`.
    pressure : float
        ``P0`` [epsilon / <D>^d], > 0.
    settings : JammingSettings, optional
        Default :class:`~jamflow.soft.jamming.JammingSettings`; ``force_tol`` bounds the largest projected force per sphere; ``box_dof`` must
        be ``"isotropic"`` (a fixed-shape box).
    """
    settings = JammingSettings() if settings is None else settings
    if not (np.isfinite(pressure) and pressure > 0.0):
        raise ValueError(f"target pressure must be positive and finite, got {pressure}")
    if settings.box_dof != "isotropic":
        raise ValueError("linked packings are jammed in a fixed-shape box or shear-stabilised, not with box_dof 'full'")
    if packing.links is None:
        packing = packing.evolve(links=Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)))
    check_linked_start(packing)
    unit = float(packing.diameter.mean())
    scaled = packing.in_units(unit)
    D, box, x = scaled.diameter, Box(scaled.box.matrix), scaled.position
    phi = float(sphere_volume(box.d, D).sum()) / box.volume
    kind = ShearStabilizedModel if shear_stabilize else LinkedSpheresModel
    model = kind(box, D, scaled.links, x, potential)
    model, final, history, steps = jam_model_to_pressure(model, x, phi, pressure, settings, progress)
    if shear_stabilize:
        final = replace(final, box=model.last_box())
    attrs = {
        "length_unit": "mean particle diameter", "force_unit": "epsilon / mean diameter",
        "pressure_unit": "epsilon / mean diameter^d", "energy": final.energy, "energy_unit": "epsilon",
        "max_force_sq": final.max_force**2, "potential_exponent": potential.exponent, "target_pressure": pressure,
        "fire_steps": steps, "converged": int(final.converged),
    }
    params = {"pressure": pressure, "force_tol": settings.force_tol, "pressure_rtol": settings.pressure_rtol,
              "bisection_rtol": settings.bisection_rtol, "bisection_force_factor": settings.bisection_force_factor,
              "delta_phi": settings.delta_phi, "potential_exponent": potential.exponent,
              "fire": settings.fire_params.as_dict(), "length_rtol": model.length_rtol}
    suffix = ">soft-shear-stabilized" if shear_stabilize else ">soft"
    out = linked_soft_packing(scaled, model, final, suffix, attrs, params, shear_stabilize)
    converged = final.converged and abs(final.pressure - pressure) <= settings.pressure_rtol * pressure
    return JammingResult(out, bool(converged), history, steps)
