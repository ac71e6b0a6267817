"""Soft-sphere jamming at a target pressure: the bisection of :mod:`jamflow.minimize.onset` on the sphere model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..box import Box
from ..minimize.fire import FireParameters, MinimizeResult, minimize_enthalpy_model
from ..minimize.onset import JammingSettings, jam_model_to_pressure
from ..models.spheres.model import SphereModel
from ..models.spheres.potential import HARMONIC, PowerLawPotential, overlapping_pairs
from ..neighbors.verlet import NeighborList
from ..network import count_bodies
from ..network.spheres import find_rattlers
from ..state.packing import Packing, sphere_volume

__all__ = ["JammingResult", "kick_off_saddle", "leave_saddle", "soft_packing", "jam_to_pressure"]

#: Random displacement [mean diameter] that moves a hypostatic force-balanced state off
#: its saddle before the enthalpy is minimised again: ten times the overlaps at
#: ``P0 <= 1e-7`` (``~P0`` for harmonic contacts), a thousandth of a typical gap; the
#: floppy mode then grows as FIRE descends (docs/notes/chains.md, "Dilute starts").
SADDLE_KICK: float = 1e-6

#: Kicks before a state that stays hypostatic is refused.
SADDLE_KICKS: int = 3


@dataclass(frozen=True)
class JammingResult:
    """A soft packing at the target pressure and how it was reached.

    Attributes
    ----------
    packing : Packing
        Wrapped centres in units of the mean diameter, overlapping pairs as contacts
        with their repulsive force magnitudes, rattlers, virial pressure.
    converged : bool
        Final enthalpy minimisation met both tolerances.
    history : dict of lists
        Per bisection step: ``phi``, ``pressure``, ``steps`` (FIRE steps).
    steps : int
        Total FIRE steps (force evaluations) of the whole protocol.
    """

    packing: Packing
    converged: bool
    history: dict[str, list] = field(default_factory=dict)
    steps: int = 0


def soft_packing(
    x: np.ndarray,
    box: Box,
    diameter: np.ndarray,
    potential: PowerLawPotential,
    template: Packing,
    protocol_suffix: str,
    parameters: dict,
    attrs: dict,
) -> Packing:
    """Packing with contacts = overlapping pairs, forces, rattlers and virial pressure.

    Centres are wrapped first, so the stored forces are those of the stored centres
    (wrapping moves centres by round-off, ~L 2^-53).
    """
    x = box.wrap(x)
    pairs, _, f = overlapping_pairs(x, box, diameter, potential)
    contacts = np.stack([pairs.i, pairs.j], axis=1)
    rattler = find_rattlers(len(x), box.d, contacts)
    pressure = float(np.sum(f * pairs.distance) / (box.d * box.volume))
    return Packing(
        position=x, diameter=diameter, box=box, contacts=contacts, force=f,
        rattler=rattler, pressure=pressure, protocol=template.protocol + protocol_suffix,
        seed=template.seed, parameters=parameters, attrs=attrs,
    )


def _backbone_shortfall(x: np.ndarray, box: Box, diameter: np.ndarray, potential: PowerLawPotential,
                        box_dof: str) -> int:
    """Backbone contacts missing to the isostatic count (``<= 0``: isostatic or hyperstatic, or no backbone).

    A free box shape adds the ``d (d + 1) / 2 - 1`` strain degrees of freedom at fixed
    pressure (Dagois-Bohy et al.), the count of a shear-stabilised backbone.
    """
    pairs, _, _ = overlapping_pairs(box.wrap(x), box, diameter, potential)
    count = count_bodies(np.stack([pairs.i, pairs.j], axis=1), len(x), box.d, shear_stabilized=box_dof == "full")
    return count.isostatic_count - count.n_contacts if count.isostatic_count else 0


def kick_off_saddle(
    final: MinimizeResult, shortfall: Callable[[MinimizeResult], int],
    reminimize: Callable[[MinimizeResult, np.ndarray], tuple[MinimizeResult, int]], seed: int, pressure: float,
    force_tol: float,
) -> tuple[MinimizeResult, int, int]:
    """The loop of :func:`leave_saddle` for any body kind.

    Parameters
    ----------
    final : MinimizeResult
        A minimum at the target pressure.
    shortfall : callable
        Backbone contacts missing to the isostatic count of a minimum (``<= 0``: none).
    reminimize : callable
        ``(minimum, kick) -> (new minimum at the target pressure, FIRE steps)`` from the
        centres ``minimum.position + kick``.
    seed : int
        Seed of the Gaussian kicks of :data:`SADDLE_KICK` (mean diameters).
    pressure, force_tol : float
        The target pressure and the minimisations' force tolerance (named in the error).

    Returns
    -------
    final, steps, kicks
        The minimum, the FIRE steps of the re-minimisations and the number of kicks.

    Raises
    ------
    RuntimeError
        Still hypostatic after :data:`SADDLE_KICKS` kicks.
    """
    steps = 0
    rng = np.random.default_rng(seed)
    for kick in range(SADDLE_KICKS + 1):
        missing = shortfall(final)
        if missing <= 0:
            return final, steps, kick
        if kick == SADDLE_KICKS:
            break
        final, more = reminimize(final, SADDLE_KICK * rng.standard_normal(final.position.shape))
        steps += more
    raise RuntimeError(f"the jammed packing stays hypostatic ({missing} backbone contacts short of isostatic) "
                       f"after {SADDLE_KICKS} kicks off the saddle: no stable packing at P0 = {pressure:g} with force "
                       f"tolerance {force_tol:g}; a smaller --force-tol (small against the contact forces, "
                       f"of order P0) may reach one")


def leave_saddle(
    final: MinimizeResult, diameter: np.ndarray, potential: PowerLawPotential, pressure: float,
    settings: JammingSettings, seed: int,
) -> tuple[MinimizeResult, int, int]:
    """The final enthalpy minimum, moved off a saddle if it is one.

    A packing at ``P > 0`` with fewer backbone contacts than the isostatic count has a
    floppy mode loaded by its contact forces: negative curvature ``~ -f / r`` (e.g. a
    straight column of discs across the box), a saddle at which FIRE stops because the
    force along that mode vanishes by symmetry. Such a state is kicked by
    :data:`SADDLE_KICK` (Gaussian, seeded) and the enthalpy minimised again, up to
    :data:`SADDLE_KICKS` times; returns and raises as :func:`kick_off_saddle`.
    """

    def shortfall(res: MinimizeResult) -> int:
        return _backbone_shortfall(res.position, res.box, diameter, potential, settings.box_dof)

    def reminimize(res: MinimizeResult, kick: np.ndarray) -> tuple[MinimizeResult, int]:
        model = SphereModel(res.box, diameter, potential, NeighborList(diameter))
        out = minimize_enthalpy_model(model, res.position + kick, pressure, settings.force_tol,
                                      settings.pressure_rtol, settings.max_steps, settings.fire_params,
                                      settings.box_dof)
        return out, out.steps

    return kick_off_saddle(final, shortfall, reminimize, seed, pressure, settings.force_tol)


def jam_to_pressure(
    packing: Packing,
    pressure: float = 1e-7,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = JammingSettings.force_tol,
    pressure_rtol: float = JammingSettings.pressure_rtol,
    delta_phi: float = JammingSettings.delta_phi,
    bisection_rtol: float = JammingSettings.bisection_rtol,
    bisection_force_factor: float = JammingSettings.bisection_force_factor,
    max_steps: int = JammingSettings.max_steps,
    fire_params: FireParameters = JammingSettings.fire_params,
    progress: Callable[[dict], None] | None = None,
    box_dof: str = JammingSettings.box_dof,
    onset: str = JammingSettings.onset,
) -> JammingResult:
    """Bring a packing to the jamming onset at pressure ``P0`` (see module doc).

    Parameters
    ----------
    packing : Packing
        Starting configuration (any packing fraction; overlaps allowed).
    pressure : float
        Target pressure ``P0`` [epsilon / <D>^d], > 0 (e.g. 1e-7 ... 1e-9).
    potential : PowerLawPotential
    force_tol : float
        Final ``max_i |F_i|`` [epsilon / <D>]; default 1e-13 (F^2 <= 1e-26 < 1e-25).
    pressure_rtol : float
        Final ``|P - P0| / P0``.
    delta_phi : float
        First packing-fraction step of the bisection.
    bisection_rtol : float
        Bisection stops when ``|P - P0| <= bisection_rtol * P0``.
    bisection_force_factor : float
        Bisection minimisations stop at ``max_i |F_i| <= factor * P0``.
    max_steps : int
        Budget of FIRE steps for the whole protocol; raises RuntimeError if exceeded.
    fire_params : FireParameters
    progress : callable, optional
        Called with a dict (``phi``, ``pressure``, ``delta_phi``, ``steps``) after each
        bisection step.
    box_dof : {"isotropic", "full"}
        Box freedom of the final enthalpy minimisation: isotropic scale, or the whole
        upper-triangular box so the final stress tensor is ``-P0 1`` (shear-stress
        free; the box may tilt). See :func:`~jamflow.models.spheres.model.minimize_enthalpy`.
        With the full box free the backbone needs ``d (N_s - 1) + d (d + 1) / 2``
        contacts instead of ``d (N_s - 1) + 1`` (Dagois-Bohy et al., PRL 109, 095703).
    onset : {"bisection", "search"}
        How step 2 chooses its packing fractions (:mod:`jamflow.minimize.onset`):
        O'Hern's compress/decompress bisection with fixed first step ``delta_phi``
        (default), or the search that keeps the last minimum below ``P0`` (far fewer
        minimisations from a dilute start, and a 0.4-2 % denser ``phi_J`` from one).

    Returns
    -------
    JammingResult
    """
    if packing.body_kind != "spheres":
        raise ValueError(f"jam_to_pressure jams plain periodic spheres; this packing holds {packing.body_kind} "
                         "(linked spheres: jamflow.chains.jamming.jam_linked; shapes: jamflow.shapes.jamming.jam_shapes)")
    if not (np.isfinite(pressure) and pressure > 0.0):
        raise ValueError(f"target pressure must be positive and finite, got {pressure}")
    if not (force_tol > 0.0 and pressure_rtol > 0.0 and delta_phi > 0.0):
        raise ValueError("force_tol, pressure_rtol and delta_phi must be positive")
    d = packing.d
    unit = float(packing.diameter.mean())
    D = packing.diameter / unit
    box = Box(packing.box.matrix / unit)
    x = packing.position / unit
    particle_volume = float(sphere_volume(d, D).sum())
    phi = particle_volume / box.volume
    model = SphereModel(box, D, potential, NeighborList(D))
    settings = JammingSettings(force_tol, pressure_rtol, delta_phi, bisection_rtol, bisection_force_factor,
                               max_steps, fire_params, box_dof, onset)
    model, final, history, steps = jam_model_to_pressure(model, x, phi, pressure, settings, progress)
    final, more, kicks = leave_saddle(final, D, potential, pressure, settings,
                                       packing.seed if packing.seed is not None and packing.seed >= 0 else 0)
    steps += more
    box = final.box
    fmax2 = final.max_force**2
    attrs = {
        "length_unit": "mean particle diameter",
        "force_unit": "epsilon / mean diameter",
        "pressure_unit": "epsilon / mean diameter^d",
        "energy": final.energy,
        "energy_unit": "epsilon",
        "max_force_sq": fmax2,
        "potential_exponent": potential.exponent,
        "target_pressure": pressure,
        "fire_steps": steps,
        "converged": int(final.converged),
        "onset_method": onset,
        "onset_minimizations": len(history["phi"]),
        "saddle_kicks": kicks,
    }
    params = {
        "pressure": pressure, "force_tol": force_tol, "pressure_rtol": pressure_rtol,
        "bisection_rtol": bisection_rtol, "bisection_force_factor": bisection_force_factor,
        "potential_exponent": potential.exponent, "fire": fire_params.as_dict(), "box_dof": box_dof,
        "onset": onset, "delta_phi": delta_phi,
    }
    out = soft_packing(final.position, box, D, potential, packing, ">soft", params, attrs)
    return JammingResult(out, bool(final.converged), history, steps)
