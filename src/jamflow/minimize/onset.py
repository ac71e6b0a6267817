"""Jamming onset of any model: a search on the pressure P(phi) to a target pressure.

Protocol (O'Hern et al., PRE 68, 011306 (2003); VanderWerf et al., Sec. II):

1. lengths are rescaled so the mean diameter is 1 (the output's length unit);
2. the box is scaled isotropically (centres affinely) to a packing fraction chosen by
   :class:`PressureSearch`, each step followed by FIRE energy minimisation at fixed box
   to ``max_i |F_i| <= bisection_force_factor * P0``: below ``P0`` it compresses,
   above it decompresses. Steps double while no pressure tells the distance to the
   target (an unjammed packing has ``P = 0``); once two jammed minima give the
   slope ``dP/dphi``, the next ``phi`` is the secant (Newton) estimate of ``P = P0``;
   once ``P0`` is bracketed, the secant step is taken inside the bracket and a
   bisection where it would leave it or stalls. No step strains the box by more
   than ``max_strain_step`` (relative length), so a compression cannot create
   overlaps deeper than that fraction of the distances between bodies (clusters and
   rods must not pass through each other);
3. when ``|P - P0| <= bisection_rtol * P0`` the enthalpy ``H = U + P0 V`` is
   minimised with centres and box scale as degrees of freedom to
   ``max_i |F_i| <= force_tol`` and ``|P - P0| <= pressure_rtol * P0`` (models with
   box degrees of freedom), or the search continues at fixed box with ``force_tol``
   until ``|P - P0| <= pressure_rtol * P0``.

The search replaced a compress/decompress bisection with a fixed first step (halved
on every reversal): from dilute starts it stepped ``delta_phi`` at a time across
half the density range (50 rigid trimers from phi = 0.2: 606 minimisations); the
measurements are in docs/notes/onset-search.md.

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

__all__ = ["FORCE_TOL_VANDERWERF", "MAX_STRAIN_STEP", "JammingSettings", "PressureSearch", "bisect_to_pressure",
           "jam_model_to_pressure"]


#: Default final ``max_i |F_i|`` [epsilon / <D>]: VanderWerf et al.'s ``F_i^2 < 1e-25``
#: with a factor ten to spare (see :data:`jamflow.tolerances.SOFT_FORCE_TOL`).
FORCE_TOL_VANDERWERF: float = SOFT_FORCE_TOL

#: Largest relative change of the box length in one step of the search (compression
#: or decompression): an affine compression of a packing without overlaps creates
#: overlaps of at most this fraction of the centre distances, 5 % of a diameter for
#: touching spheres and rigid clusters, a quarter of the rounding radius for rods of
#: aspect ratio 10 (cores must not cross). From phi = 0.1 it reaches phi = 0.64 (3D)
#: in 12 steps, from 0.2 to 0.77 (2D) in 13 (docs/notes/onset-search.md).
MAX_STRAIN_STEP: float = 0.05

#: A minimum counts as jammed for the slope ``dP/dphi`` of the search when its pressure
#: exceeds this fraction of ``P0``: an unjammed minimum keeps overlaps of the order of
#: the force tolerance (``bisection_force_factor * P0``), so its pressure is no distance
#: to jamming.
JAMMED_PRESSURE_SHARE: float = 0.1

#: Bracketed steps after which the bracket must have halved, else the search bisects
#: (a secant whose slope is wrong shrinks the bracket from one side only).
STALL_STEPS: int = 3


@dataclass(frozen=True)
class JammingSettings:
    """Tolerances and budget of the jamming protocol (module doc; :func:`jam_model_to_pressure`).

    ``delta_phi`` is the first step of the search in packing fraction and
    ``max_strain_step`` the largest relative change of the box length per step.
    """

    force_tol: float = FORCE_TOL_VANDERWERF
    pressure_rtol: float = 1e-6
    delta_phi: float = 1e-3
    bisection_rtol: float = 0.1
    bisection_force_factor: float = 1e-2
    max_steps: int = 20_000_000
    fire_params: FireParameters = DEFAULT_FIRE
    box_dof: str = "isotropic"
    max_strain_step: float = MAX_STRAIN_STEP


class PressureSearch:
    """The next packing fraction of the search for ``P(phi) = P0`` (module doc, step 2).

    Keeps the last minimum below ``P0`` (``lo``) and above it (``hi``) and the slope
    ``dP/dphi`` of the last two jammed minima (pressure above
    :data:`JAMMED_PRESSURE_SHARE` ``P0``). Without a bracket the step is the secant
    (Newton) estimate when a slope is known and the minimum is jammed, else a step of
    ``step`` that doubles each time; either way the box length changes by at most
    ``max_strain`` (relative). With a bracket it is the secant estimate inside it, or
    the midpoint where that would leave the bracket or the bracket has not halved in
    :data:`STALL_STEPS` steps.

    Parameters
    ----------
    pressure : float
        ``P0``.
    step : float
        First step in packing fraction.
    max_strain : float
        Largest relative change of the box length per step.
    d : int
        Dimension (``phi ~ L^-d``).
    slope : float, optional
        A known ``dP/dphi`` (e.g. from an earlier, looser search), used until two jammed
        minima of this search give their own.
    """

    def __init__(self, pressure: float, step: float, max_strain: float, d: int, slope: float | None = None) -> None:
        if not (step > 0.0 and 0.0 < max_strain < 1.0):
            raise ValueError(f"the first step ({step}) must be positive and the strain per step ({max_strain}) in (0, 1)")
        self.pressure = pressure
        self.step = step
        self.max_strain = max_strain
        self.d = d
        self.slope = slope
        self.lo: tuple[float, float] | None = None
        self.hi: tuple[float, float] | None = None
        self.jammed: list[tuple[float, float]] = []
        self.width = np.inf
        self.stalled = 0

    def _record(self, phi: float, pressure: float) -> None:
        if pressure < self.pressure:
            self.lo = (phi, pressure)
        else:
            self.hi = (phi, pressure)
        if pressure > JAMMED_PRESSURE_SHARE * self.pressure:
            self.jammed = [*self.jammed[-1:], (phi, pressure)]
            if len(self.jammed) == 2:
                (p1, y1), (p2, y2) = self.jammed
                if p1 != p2 and (y2 - y1) / (p2 - p1) > 0.0:
                    self.slope = (y2 - y1) / (p2 - p1)

    def next_phi(self, phi: float, pressure: float) -> float:
        """The packing fraction of the next minimisation after one at ``phi`` gave ``pressure``."""
        self._record(phi, pressure)
        jammed = pressure > JAMMED_PRESSURE_SHARE * self.pressure
        secant = phi + (self.pressure - pressure) / self.slope if self.slope and jammed else np.nan
        if self.lo is not None and self.hi is not None and self.lo[0] < self.hi[0]:
            lo, hi = self.lo[0], self.hi[0]
            if hi - lo <= 0.5 * self.width:
                self.width, self.stalled = hi - lo, 0
            else:
                self.stalled += 1
            if lo < secant < hi and self.stalled < STALL_STEPS:
                return secant
            return 0.5 * (lo + hi)
        if np.isnan(secant):
            secant = phi + (self.step if pressure < self.pressure else -self.step)
            self.step *= 2.0
        # at most max_strain of box length per step: phi ~ L^-d
        return float(np.clip(secant, phi * (1.0 + self.max_strain) ** -self.d, phi * (1.0 - self.max_strain) ** -self.d))


def bisect_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    force_tol: float,
    rtol: float,
    search: PressureSearch,
    max_steps: int,
    fire_params: FireParameters = DEFAULT_FIRE,
    progress: Callable[[dict], None] | None = None,
    history: dict[str, list] | None = None,
) -> tuple[EnergyModel, MinimizeResult, float, int]:
    """Fixed-box FIRE minimisations at the packing fractions of ``search`` until ``|P - P0| <= rtol P0``.

    After each minimisation to ``force_tol`` the box is scaled by ``model.rescaled`` to
    the packing fraction :meth:`PressureSearch.next_phi` asks for. Stops also when the
    next packing fraction equals this one to round-off.

    Parameters
    ----------
    model : EnergyModel
        Needs ``rescaled(factor, position) -> (model, position)``.
    position : ndarray, shape (N, d)
    phi : float
        Packing fraction of the start (the search variable; ``phi ~ 1 / V``).
    search : PressureSearch
        The search (its state carries over between calls).
    progress : callable, optional
        Called after every minimisation with ``phi``, ``pressure``, ``steps``, the
        ``model`` and the minimum's centres ``position`` (so a caller can check the
        state, e.g. :mod:`jamflow.chains.entanglement`).
    history : dict of lists, optional
        ``phi``, ``pressure``, ``steps`` are appended per minimisation.

    Returns
    -------
    model, result, phi, steps
        The model in the last box, its FIRE result, its packing fraction and the FIRE steps taken.
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
            progress({"phi": phi, "pressure": res.pressure, "steps": steps, "model": model,
                      "position": res.position})
        if not res.converged:
            raise RuntimeError(f"FIRE step budget ({max_steps}) exhausted at phi = {phi:.10f}")
        if abs(res.pressure - pressure) <= rtol * pressure:
            break
        new_phi = search.next_phi(phi, res.pressure)
        if abs(new_phi - phi) < 4.0 * np.finfo(float).eps * phi:
            break
        factor = (phi / new_phi) ** (1.0 / d)
        model, x = model.rescaled(factor, x)
        phi = new_phi
    return model, res, phi, steps


def jam_model_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    settings: JammingSettings = JammingSettings(),
    progress: Callable[[dict], None] | None = None,
) -> tuple[EnergyModel, MinimizeResult, dict[str, list], int]:
    """Jamming onset of any model at pressure ``P0`` (module doc).

    Models with box degrees of freedom (``model.box_dofs``) end with the enthalpy
    minimisation of step 3; any other model continues the search with fixed-box FIRE
    to ``force_tol`` until ``|P - P0| <= pressure_rtol P0``, starting from the slope
    of the first stage.

    Returns
    -------
    model, result, history, steps
        The model in the final box, the final minimisation, the per-minimisation history
        (``phi``, ``pressure``, ``steps``) and the total FIRE steps.
    """
    c = settings
    d = model.box.d
    history: dict[str, list] = {"phi": [], "pressure": [], "steps": []}
    search = PressureSearch(pressure, c.delta_phi, c.max_strain_step, d)
    model, res, phi, steps = bisect_to_pressure(
        model, position, phi, pressure, c.bisection_force_factor * pressure, c.bisection_rtol, search,
        c.max_steps, c.fire_params, progress, history,
    )
    if model.box_dofs:
        final = minimize_enthalpy_model(model, res.position, pressure, c.force_tol, c.pressure_rtol,
                                        c.max_steps - steps, c.fire_params, c.box_dof)
        return model, final, history, steps + final.steps
    # the first stage's slope, and its bracket width as the step where the slope fails
    width = search.hi[0] - search.lo[0] if search.lo and search.hi and search.lo[0] < search.hi[0] else c.delta_phi
    fine = PressureSearch(pressure, max(width, 4.0 * np.finfo(float).eps * phi), c.max_strain_step, d, search.slope)
    model, final, _, more = bisect_to_pressure(
        model, res.position, phi, pressure, c.force_tol, c.pressure_rtol, fine, c.max_steps - steps,
        c.fire_params, progress, history,
    )
    return model, final, history, steps + more
