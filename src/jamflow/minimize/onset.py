"""Jamming onset of soft spheres: compress/decompress bisection to a target pressure.

Protocol (O'Hern et al., PRE 68, 011306 (2003); VanderWerf et al., Sec. II):

1. lengths are rescaled so the mean diameter is 1 (the output's length unit);
2. the box is scaled isotropically (centres affinely) in steps of packing fraction
   ``delta_phi``, each followed by FIRE energy minimisation at fixed box to
   ``max_i |F_i| <= bisection_force_factor * P0``; if the virial pressure is below
   ``P0`` the next step compresses, above it decompresses, and ``delta_phi`` halves
   whenever the direction reverses;
3. when ``|P - P0| <= bisection_rtol * P0`` (or ``delta_phi`` underflows) the
   enthalpy ``H = U + P0 V`` is minimised with centres and box scale as degrees of
   freedom to ``max_i |F_i| <= force_tol`` and ``|P - P0| <= pressure_rtol * P0``.

Units: energy ``epsilon`` (see :mod:`jamflow.models.spheres.potential`), length the mean
diameter ``<D>``, pressure ``epsilon / <D>^d``, force ``epsilon / <D>``.

Force-balance floor of float64: VanderWerf et al. ask for squared forces per particle
below 1e-25; the default ``force_tol = 1e-13`` gives ``F^2 <= 1e-26``. With
``<D> = 1`` and box sides ``L ~ N^(1/d)``, pair vectors carry a round-off of
``~ L 2^-53``, so per-particle forces cannot be balanced much below ``~1e-14``
(measured: docs/notes/soft-constants.md#soft_force_tol).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..tolerances import SOFT_FORCE_TOL
from .fire import (
    DEFAULT_FIRE,
    FireParameters,
    MinimizeResult,
    minimize_enthalpy_model,
    minimize_fire,
)
from .model import EnergyModel

__all__ = ["FORCE_TOL_VANDERWERF", "JammingSettings", "bisect_to_pressure", "jam_model_to_pressure"]


#: Default final ``max_i |F_i|`` [epsilon / <D>]: VanderWerf et al.'s ``F_i^2 < 1e-25``
#: with a factor ten to spare (see :data:`jamflow.tolerances.SOFT_FORCE_TOL`).
FORCE_TOL_VANDERWERF: float = SOFT_FORCE_TOL


@dataclass(frozen=True)
class JammingSettings:
    """Tolerances and budget of the jamming protocol (see :func:`jam_to_pressure`)."""

    force_tol: float = FORCE_TOL_VANDERWERF
    pressure_rtol: float = 1e-6
    delta_phi: float = 1e-3
    bisection_rtol: float = 0.1
    bisection_force_factor: float = 1e-2
    max_steps: int = 20_000_000
    fire_params: FireParameters = DEFAULT_FIRE
    box_dof: str = "isotropic"


def bisect_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    force_tol: float,
    rtol: float,
    delta_phi: float,
    max_steps: int,
    fire_params: FireParameters = DEFAULT_FIRE,
    progress: Callable[[dict], None] | None = None,
    history: dict[str, list] | None = None,
    direction: int = 0,
) -> tuple[EnergyModel, MinimizeResult, float, float, int, int]:
    """Compress/decompress bisection of any model to ``|P - P0| <= rtol P0`` (module doc, step 2).

    After each fixed-box FIRE minimisation to ``force_tol`` the box is scaled by
    ``model.rescaled`` to the next packing fraction ``phi +- delta_phi``; ``delta_phi``
    halves when the direction reverses. Stops also when ``delta_phi`` underflows.

    Parameters
    ----------
    model : EnergyModel
        Needs ``rescaled(factor, position) -> (model, position)``.
    position : ndarray, shape (N, d)
    phi : float
        Packing fraction of the start (the bisection variable; ``phi ~ 1 / V``).
    progress : callable, optional
        Called after every minimisation with ``phi``, ``pressure``, ``delta_phi``,
        ``steps``, the ``model`` and the minimum's centres ``position`` (so a caller can
        check the state, e.g. :mod:`jamflow.chains.entanglement`).
    history : dict of lists, optional
        ``phi``, ``pressure``, ``steps`` are appended per bisection step.
    direction : int
        Direction of the previous step (0: none), to resume a bisection.

    Returns
    -------
    model, result, phi, delta_phi, direction, steps
        The model in the last box, its FIRE result, and the state to resume from.
    """
    d = model.box.d
    steps = 0
    x = position
    while True:
        res = minimize_fire(model, x, force_tol, max_steps - steps, fire_params)
        steps += res.steps
        x = res.position
        if history is not None:
            history["phi"].append(phi)
            history["pressure"].append(res.pressure)
            history["steps"].append(res.steps)
        if progress is not None:
            progress({"phi": phi, "pressure": res.pressure, "delta_phi": delta_phi, "steps": steps,
                      "model": model, "position": res.position})
        if not res.converged:
            raise RuntimeError(f"FIRE step budget ({max_steps}) exhausted at phi = {phi:.10f}")
        if abs(res.pressure - pressure) <= rtol * pressure:
            break
        new_direction = 1 if res.pressure < pressure else -1
        if direction and new_direction != direction:
            delta_phi *= 0.5
        direction = new_direction
        if delta_phi < 4.0 * np.finfo(float).eps * phi:
            break
        new_phi = phi + direction * delta_phi
        factor = (phi / new_phi) ** (1.0 / d)
        model, x = model.rescaled(factor, x)
        phi = new_phi
    return model, res, phi, delta_phi, direction, steps


def jam_model_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    settings: JammingSettings = JammingSettings(),
    progress: Callable[[dict], None] | None = None,
) -> tuple[EnergyModel, MinimizeResult, dict[str, list], int]:
    """Jamming onset of any model at pressure ``P0`` (the protocol of :func:`jam_to_pressure`).

    Models with box degrees of freedom (``model.box_dofs``, e.g. soft spheres) end with the enthalpy
    minimisation of step 3; any other model continues the bisection with fixed-box
    FIRE to ``force_tol`` until ``|P - P0| <= pressure_rtol P0``.

    Returns
    -------
    model, result, history, steps
        The model in the final box, the final minimisation, the per-step history
        (``phi``, ``pressure``, ``steps``) and the total FIRE steps.
    """
    c = settings
    history: dict[str, list] = {"phi": [], "pressure": [], "steps": []}
    model, res, phi, delta_phi, direction, steps = bisect_to_pressure(
        model, position, phi, pressure, c.bisection_force_factor * pressure, c.bisection_rtol, c.delta_phi,
        c.max_steps, c.fire_params, progress, history,
    )
    if model.box_dofs:
        final = minimize_enthalpy_model(model, res.position, pressure, c.force_tol, c.pressure_rtol,
                                        c.max_steps - steps, c.fire_params, c.box_dof)
        return model, final, history, steps + final.steps
    model, final, _, _, _, more = bisect_to_pressure(
        model, res.position, phi, pressure, c.force_tol, c.pressure_rtol, delta_phi, c.max_steps - steps,
        c.fire_params, progress, history, direction,
    )
    return model, final, history, steps + more
