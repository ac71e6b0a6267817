"""Critically jammed linked packings: the jamming bisection of any model, applied to linked spheres.

Protocol (chains paper Sec. III, with the project's bisection to ``P0`` of
:mod:`jamflow.minimize.onset`): lengths are rescaled so the mean diameter is 1 (link
lengths with them); the box is scaled isotropically about the centres, each step
followed by fixed-box FIRE with constraint projection and Newton re-affixing
(:class:`~jamflow.models.links.LinkedSpheresModel`), compressing below ``P0`` and
decompressing above with halving steps, until ``|P - P0| <= pressure_rtol P0`` at
``max |P F| <= force_tol``. ``P`` is the virial pressure of the contact forces and
the link tensions. Shear-stabilised (``shear_stabilize``: the strain free at fixed volume in
every bisection step) the protocol ends, as the spheres' does, with ``U + P0 V`` minimised
over the centres and the whole box (:meth:`ShearStabilizedModel.with_free_volume`), at the
stress ``-P0 1``. Scaling the box scales the clusters' centres, not their shapes:
the affine move stretches links by the scale factor and the first re-affixing
restores them (the paper's "cluster size decreased while maintaining their average
positions", seen from the clusters' frame).

Two protocols (``protocol=``):

- ``"bisection"`` (default): the project's bisection to ``P0`` above;
- ``"energy"``: the paper's Sec. III steps (:func:`scale_to_energy`): from an
  overjammed minimum, decompress by the amount the energy scaling
  ``U / N = A (phi - phi_J)^w`` (O'Hern et al., ``w`` the potential exponent)
  predicts, until ``0 < U / N <= energy_tol``.

Default chosen by measurement (``benchmarks/chains.py --protocols``, same starts,
side by side; numbers in docs/notes/chains.md): see :data:`DEFAULT_PROTOCOL`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..box import Box
from ..minimize.fire import (
    FireParameters,
    MinimizeResult,
    minimize_enthalpy_model,
    minimize_fire,
)
from ..minimize.model import EnergyModel
from ..minimize.onset import JammingSettings, bisect_to_pressure, jam_model_to_pressure
from ..models.links import LinkedSpheresModel
from ..models.spheres.potential import HARMONIC, PowerLawPotential, overlapping_pairs
from ..models.strain import ShearStabilizedModel
from ..network import count_bodies
from ..protocols.soft_jam import JammingResult, kick_off_saddle
from ..state.bodies import Links
from ..state.packing import Packing, linked_volume
from ..tolerances import LINK_LENGTH_RTOL
from .builders import check_linked_start
from .dimers import dimer_report
from .entanglement import check_untangled
from .hessian import ZERO_MODE_RTOL, constrained_hessian

__all__ = ["DEFAULT_PROTOCOL", "ENERGY_FLOOR", "PROTOCOLS", "SADDLE_CURVATURE_RATIO", "is_saddle", "jam_linked",
           "leave_linked_saddle", "linked_soft_packing", "scale_to_energy"]

#: Jamming protocols of :func:`jam_linked`.
PROTOCOLS = ("bisection", "energy")

#: The default protocol: the bisection ends at a stated pressure (to pressure_rtol), which
#: contact numbers and moduli depend on; the energy steps are faster but end at an
#: uncontrolled pressure (measured: docs/notes/chains.md#bisection-against-the-energy-steps).
DEFAULT_PROTOCOL = "bisection"

#: A minimum whose energy per sphere is below ``ENERGY_FLOOR * energy_tol`` counts as
#: unjammed (the step overshot phi_J): with ``U ~ (phi - phi_J)^2`` its distance to
#: jamming, and so its pressure, is 100 times below the threshold's, while a FIRE
#: minimum of an unjammed packing keeps only overlaps of the order of the force tolerance.
ENERGY_FLOOR: float = 1e-4

#: A hypostatic linked minimum is a saddle when its constrained Hessian has an eigenvalue
#: below ``-SADDLE_CURVATURE_RATIO f_mean`` [epsilon / <D>^2] (``f_mean`` the mean contact
#: force [epsilon / <D>]; a floppy mode's prestress curvature is ``~ -f / r``, ``r ~ <D>``),
#: unless ``ZERO_MODE_RTOL`` times the largest eigenvalue is smaller: that relative bound
#: alone is ~6e-10 for chains, above every prestress curvature once ``P0 <~ 1e-9``.
#: Measured on 4 chains of 30 in 3D at ``P0 = 1e-12``: the saddle's eigenvalues -2.3e-12
#: ... -3.8e-12 at ``f_mean = 1.1e-12``; round-off and residual forces leave the zero modes
#: within 2e-14 (``force_tol = 1e-13``) and 1.1e-15 (``1e-15``)
#: (docs/notes/extremes.md, "Failures found and fixed").
SADDLE_CURVATURE_RATIO: float = 0.1

#: Largest reduction of the distance to the estimated phi_J in one decompression
#: step of :func:`scale_to_energy` (the estimate is an extrapolation of the scaling
#: from larger distances, where corrections to it are larger).
ENERGY_STEP_RATIO: float = 0.1


def linked_soft_packing(packing: Packing, model: LinkedSpheresModel, res: MinimizeResult, protocol_suffix: str,
                        attrs: dict, parameters: dict, shear_stabilized: bool = False) -> Packing:
    """A minimised linked packing: contacts are the overlapping pairs that are not linked.

    Rattlers are the danglers and the clusters that rattle whole, by the counting of
    :func:`jamflow.network.count_bodies`; their counts, the clusters'
    isostatic count (for dimers also rotators and ``<z>``, :func:`~jamflow.chains.dimers.dimer_report`), the largest relative link-length error and the stress
    anisotropy ``stress_deviation = max_ab |W_ab - P' delta_ab| / P'`` (``W`` the
    total virial of pairs and link tensions, ``P' = tr W / d``) go into the attributes.
    """
    box = res.box
    x = box.wrap(res.position)
    contacts, f, count = _linked_count(model, x, box, shear_stabilized)
    err = np.abs(model.links.length_errors(x, box))
    # total virial (pairs and link tensions) of the final configuration in its box
    W = LinkedSpheresModel(box, model.diameter, model.links, x, model.potential).evaluate(x.ravel()).virial
    p_virial = float(np.trace(W)) / box.d
    attrs = {**packing.attrs, **attrs, **count.as_dict(), **dimer_report(count, box.d),
             "shear_stabilized": int(shear_stabilized),
             "max_link_error": float(err.max(initial=0.0)),
             "stress_deviation": float(np.max(np.abs(W - p_virial * np.eye(box.d))) / p_virial) if p_virial else 0.0,
             "pressure_comment": "virial pressure of the contact forces and the link tensions"}
    return packing.evolve(position=x, box=box, diameter=model.diameter, links=model.links, contacts=contacts,
                          force=f, rattler=count.rattler, pressure=res.pressure,
                          protocol=packing.protocol + protocol_suffix, parameters=parameters, attrs=attrs)


def _linked_count(model: LinkedSpheresModel, x: np.ndarray, box: Box, shear_stabilized: bool):
    """Contacts (overlapping pairs that are not linked) (P, 2), their forces (P,) and
    :func:`~jamflow.network.count_bodies` of the centres ``x`` (wrapped) in ``box``."""
    pairs, _, f = overlapping_pairs(x, box, model.diameter, model.potential)
    free = ~model.links.contains(pairs.i, pairs.j)
    contacts = np.stack([pairs.i, pairs.j], axis=1)[free]
    return contacts, f[free], count_bodies(contacts, len(x), box.d, model.links, x, box,
                                           shear_stabilized=shear_stabilized)


def is_saddle(eigenvalues: np.ndarray, mean_contact_force: float) -> bool:
    """Whether a constrained Hessian's eigenvalues (ascending or not) show negative curvature.

    Below ``-min(ZERO_MODE_RTOL max |w|, SADDLE_CURVATURE_RATIO f_mean)``
    (:data:`SADDLE_CURVATURE_RATIO`): the prestress curvature of a floppy mode scales with
    the contact forces, so at small ``P0`` the bound follows them down (``f_mean <= 0``, no
    contacts: the relative bound alone).
    """
    w = np.asarray(eigenvalues, dtype=np.float64)
    tol = ZERO_MODE_RTOL * float(np.abs(w).max())
    if mean_contact_force > 0.0:
        tol = min(tol, SADDLE_CURVATURE_RATIO * mean_contact_force)
    return bool(w.min() < -tol)


def leave_linked_saddle(model: LinkedSpheresModel, final: MinimizeResult, template: Packing, pressure: float,
                        settings: JammingSettings, shear_stabilized: bool, seed: int,
                        progress: Callable[[dict], None] | None = None, history: dict[str, list] | None = None,
                        ) -> tuple[LinkedSpheresModel, MinimizeResult, int, int]:
    """The bisection's final minimum of linked spheres, moved off a saddle if it is one.

    The guard of :func:`~jamflow.protocols.soft_jam.leave_saddle` for linked spheres. A
    minimum whose backbone has fewer contacts than the isostatic count of its clusters
    (:func:`~jamflow.network.count_bodies`, by rank; shear-stabilised with the strain
    degrees of freedom) has a floppy mode of the contact network. For spheres its
    prestress curvature is always negative (a saddle); for flexible clusters (the free
    torsions of 3D chains) it can be positive, a stable minimum held at second order like
    a hypostatic ellipse packing (docs/notes/chains.md, "Saddles of linked packings").
    So a hypostatic minimum is a saddle only if its constrained Hessian
    (:func:`~jamflow.chains.hessian.constrained_hessian`) has a negative eigenvalue beyond
    round-off, at the scale of the contact forces (:func:`is_saddle`); a saddle is kicked by
    :data:`~jamflow.protocols.soft_jam.SADDLE_KICK` (Gaussian, seeded), its links
    re-affixed by the minimiser, and brought back to ``|P - P0| <= pressure_rtol P0`` by
    the bisection at fixed box shape from the kicked centres (first step
    ``pressure_rtol * delta_phi``, secant steps as the onset's final stage), or, for a model
    with the volume free (the shear-stabilised onset's enthalpy stage), by the enthalpy
    minimisation at ``P0`` over the whole box, up to :data:`~jamflow.protocols.soft_jam.SADDLE_KICKS`
    times.

    Parameters
    ----------
    template : Packing
        The start in the model's length unit (metadata of the packing the Hessian is taken of).

    Returns
    -------
    model, final, steps, kicks
        The model in the final box, the minimum (``box`` set), the FIRE steps of the
        re-minimisations and the number of kicks.
    """
    state = {"model": model}

    def shortfall(res: MinimizeResult) -> int:
        m = state["model"]
        x = res.box.wrap(res.position)
        contacts, f, count = _linked_count(m, x, res.box, shear_stabilized)
        missing = count.isostatic_count - count.n_contacts if count.isostatic_count else 0
        if missing <= 0:
            return 0
        at = template.evolve(position=x, box=res.box, diameter=m.diameter, links=m.links, contacts=contacts,
                             force=f, rattler=count.rattler)
        w = constrained_hessian(at, m.potential, strain=shear_stabilized).eigenvalues
        return missing if is_saddle(w, float(np.mean(f)) if len(f) else 0.0) else 0

    def reminimize(res: MinimizeResult, kick: np.ndarray) -> tuple[MinimizeResult, int]:
        m, x = state["model"].rescaled(1.0, res.position + kick)
        if m.box_dofs:
            # the onset ended with the enthalpy stage (volume free): so does each re-minimisation
            out = minimize_enthalpy_model(m, x, pressure, settings.force_tol, settings.pressure_rtol,
                                          settings.max_steps, settings.fire_params, "full")
            steps = out.steps
        else:
            phi = linked_volume(m.box.d, m.diameter, m.links) / m.box.volume
            m, out, _, _, _, steps, _ = bisect_to_pressure(
                m, x, phi, pressure, settings.force_tol, settings.pressure_rtol,
                settings.pressure_rtol * settings.delta_phi, settings.max_steps, settings.fire_params, progress,
                history, secant=True, polish=settings.newton_polish)
        state["model"] = m
        return replace(out, box=_current_box(m)), steps

    final, steps, kicks = kick_off_saddle(final, shortfall, reminimize, seed, pressure,
                                          settings.force_tol)
    return state["model"], final, steps, kicks


def jam_linked(
    packing: Packing,
    pressure: float | None,
    potential: PowerLawPotential = HARMONIC,
    settings: JammingSettings | None = None,
    progress: Callable[[dict], None] | None = None,
    shear_stabilize: bool = False,
    protocol: str = DEFAULT_PROTOCOL,
    energy_tol: float | None = None,
    length_rtol: float = LINK_LENGTH_RTOL,
) -> JammingResult:
    """Bring a linked packing to the jamming onset in a fixed-shape box or shear-stabilised (module doc).

    Parameters
    ----------
    packing : Packing
        Start with links (overlaps allowed; without links, spheres); checked by
        :func:`~jamflow.chains.builders.check_linked_start`.
    pressure : float or None
        ``P0`` [epsilon / <D>^d], > 0, of the bisection; None with ``protocol="energy"``.
    settings : JammingSettings, optional
        Default :class:`~jamflow.minimize.onset.JammingSettings`; ``force_tol`` bounds the largest projected force per
        sphere; ``box_dof="full"`` implies ``shear_stabilize``.
    protocol : {"bisection", "energy"}
        :data:`PROTOCOLS`; ``"energy"`` runs :func:`scale_to_energy` (uses
        ``settings.force_tol``, ``delta_phi`` and ``max_steps``).
    energy_tol : float, optional
        Energy per sphere [epsilon] at which ``"energy"`` stops.
    length_rtol : float
        Relative link-length precision kept by Newton re-affixing after every move
        (:meth:`~jamflow.models.links.LinkedSpheresModel.reproject`); default
        :data:`~jamflow.tolerances.LINK_LENGTH_RTOL`.

    Raises
    ------
    EntanglementError
        After any minimum (intermediate or final) whose clusters are entangled
        (:func:`~jamflow.chains.entanglement.check_untangled`): links passed through
        each other, so the state is not a jammed packing.
    """
    settings = JammingSettings() if settings is None else settings
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    if protocol == "bisection" and not (pressure is not None and np.isfinite(pressure) and pressure > 0.0):
        raise ValueError(f"target pressure must be positive and finite, got {pressure}")
    if protocol == "energy" and not (energy_tol is not None and np.isfinite(energy_tol) and energy_tol > 0.0):
        raise ValueError(f"energy_tol must be positive and finite for the energy protocol, got {energy_tol}")
    full_box = settings.box_dof == "full"
    if full_box and protocol != "bisection":
        raise ValueError("box_dof 'full' (enthalpy at P0 with the whole box free) follows the bisection to P0, not "
                         "the energy protocol")
    if settings.box_dof not in ("isotropic", "full"):
        raise ValueError(f"box_dof must be 'isotropic' or 'full', got {settings.box_dof!r}")
    shear_stabilize = shear_stabilize or full_box
    if packing.links is None:
        packing = packing.evolve(links=Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)))
    check_linked_start(packing)
    unit = float(packing.diameter.mean())
    scaled = packing.in_units(unit)
    D, box, x = scaled.diameter, Box(scaled.box.matrix), scaled.position
    phi = linked_volume(box.d, D, scaled.links) / box.volume
    kind = ShearStabilizedModel if shear_stabilize else LinkedSpheresModel
    model = kind(box, D, scaled.links, x, potential, length_rtol=length_rtol)

    def checked(info: dict) -> None:
        # refuse an entangled minimum as soon as it appears (module doc of .entanglement)
        m = info["model"]
        check_untangled(m.links, info["position"], _current_box(m), D, info["pressure"], potential, info["phi"])
        if progress is not None:
            progress(info)

    if protocol == "bisection":
        model, final, history, steps = jam_model_to_pressure(model, x, phi, pressure, settings, checked)
    else:
        history = {"phi": [], "pressure": [], "steps": []}
        model, final, _, steps = scale_to_energy(model, x, phi, energy_tol, settings.force_tol, settings.delta_phi,
                                                 settings.max_steps, potential.exponent, settings.fire_params,
                                                 checked, history)
    final = replace(final, box=_current_box(model))
    kicks = 0
    if protocol == "bisection":
        model, final, more, kicks = leave_linked_saddle(
            model, final, scaled, pressure, settings, shear_stabilize,
            packing.seed if packing.seed is not None and packing.seed >= 0 else 0, checked, history)
        steps += more
    check_untangled(model.links, final.position, final.box, D, final.pressure, potential)
    attrs = {
        "length_unit": "mean particle diameter", "force_unit": "epsilon / mean diameter",
        "pressure_unit": "epsilon / mean diameter^d", "energy": final.energy, "energy_unit": "epsilon",
        "max_force_sq": final.max_force**2, "potential_exponent": potential.exponent,
        "fire_steps": steps, "converged": int(final.converged), "jamming_protocol": protocol,
        "box_dof": settings.box_dof,
        # shear-stabilised bisections end with the enthalpy, volume free (jam_model_to_pressure)
        "final_minimization": "enthalpy, whole box free" if model.box_dofs else
                              ("fixed volume" if shear_stabilize else "fixed box"),
        **({"target_pressure": pressure, "onset_method": settings.onset,
            "onset_minimizations": len(history["phi"]), "saddle_kicks": kicks}
           if protocol == "bisection" else {"energy_tol": energy_tol}),
    }
    params = {"protocol": protocol, "force_tol": settings.force_tol, "delta_phi": settings.delta_phi,
              "potential_exponent": potential.exponent, "fire": settings.fire_params.as_dict(),
              "length_rtol": model.length_rtol,
              **({"pressure": pressure, "pressure_rtol": settings.pressure_rtol,
                  "bisection_rtol": settings.bisection_rtol, "onset": settings.onset,
                  "bisection_force_factor": settings.bisection_force_factor}
                 if protocol == "bisection" else {"energy_tol": energy_tol, "energy_floor": ENERGY_FLOOR,
                                                   "energy_step_ratio": ENERGY_STEP_RATIO})}
    suffix = ">soft-enthalpy" if full_box else (">soft-shear-stabilized" if shear_stabilize else ">soft")
    out = linked_soft_packing(scaled, model, final, suffix, attrs, params, shear_stabilize)
    if protocol == "bisection":
        converged = final.converged and abs(final.pressure - pressure) <= settings.pressure_rtol * pressure
    else:
        converged = final.converged and ENERGY_FLOOR * energy_tol < final.energy / model.n <= energy_tol
    return JammingResult(out, bool(converged), history, steps)


def _current_box(model: LinkedSpheresModel) -> Box:
    """The box of a model's last minimum: the strained box of a shear-stabilised model, else its fixed box."""
    return model.last_box() if isinstance(model, ShearStabilizedModel) else model.box


def scale_to_energy(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    energy_tol: float,
    force_tol: float,
    delta_phi: float,
    max_steps: int,
    exponent: float = 2.0,
    fire_params: FireParameters | None = None,
    progress: Callable[[dict], None] | None = None,
    history: dict[str, list] | None = None,
) -> tuple[EnergyModel, MinimizeResult, float, int]:
    """Decompress to the jamming onset by the energy scaling of ``phi - phi_J`` (chains paper Sec. III).

    After each fixed-box FIRE minimisation to ``force_tol``, with ``e = U / N`` (energy
    per sphere):

    - ``e <= ENERGY_FLOOR energy_tol`` (unjammed): compress by ``delta_phi`` if no jammed
      state was seen yet, else go halfway back to the last jammed ``phi``;
    - ``e <= energy_tol``: done (jammed at a low energy);
    - else decompress: ``phi_J`` is estimated from the two last jammed minima by
      extrapolating ``e^(1/w)``, linear in ``phi - phi_J``, to zero (one jammed minimum:
      ``phi_J = phi - delta_phi``), and the next ``phi`` is the distance at which the
      scaling predicts ``e = energy_tol / 2``, but at least ``ENERGY_STEP_RATIO`` of the
      present distance.

    Returns
    -------
    model, result, phi, steps
    """
    fire_params = FireParameters() if fire_params is None else fire_params
    d, n = model.box.d, model.n
    steps = 0
    x = position
    jammed: list[tuple[float, float]] = []  # (phi, e) of jammed minima, newest last
    while True:
        res = minimize_fire(model, x, force_tol, max_steps - steps, fire_params)
        steps += res.steps
        x = res.position
        e = res.energy / n
        if history is not None:
            history["phi"].append(phi)
            history["pressure"].append(res.pressure)
            history["steps"].append(res.steps)
        if progress is not None:
            progress({"phi": phi, "pressure": res.pressure, "energy_per_sphere": e, "steps": steps,
                      "model": model, "position": res.position})
        if not res.converged:
            raise RuntimeError(f"FIRE step budget ({max_steps}) exhausted at phi = {phi:.10f}")
        if e <= ENERGY_FLOOR * energy_tol:
            new_phi = phi + delta_phi if not jammed else 0.5 * (phi + jammed[-1][0])
        elif e <= energy_tol:
            break
        else:
            jammed.append((phi, e))
            if len(jammed) >= 2 and jammed[-2][1] > e:
                (p1, e1), (p2, e2) = jammed[-2], jammed[-1]
                s1, s2 = e1 ** (1.0 / exponent), e2 ** (1.0 / exponent)
                phi_j = p2 - s2 * (p1 - p2) / (s1 - s2)
            else:
                phi_j = phi - delta_phi
            distance = phi - phi_j
            if not distance > 0.0:
                phi_j, distance = phi - delta_phi, delta_phi
            target = distance * (0.5 * energy_tol / e) ** (1.0 / exponent)
            new_phi = phi_j + max(target, ENERGY_STEP_RATIO * distance)
        if abs(new_phi - phi) < 4.0 * np.finfo(float).eps * phi:
            break
        factor = (phi / new_phi) ** (1.0 / d)
        model, x = model.rescaled(factor, x)
        phi = new_phi
    return model, res, phi, steps
