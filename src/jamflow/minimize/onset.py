"""Jamming onset of any model: compression to a target pressure, then enthalpy minimisation.

Protocol (O'Hern et al., PRE 68, 011306 (2003); VanderWerf et al., Sec. II):

1. lengths are rescaled so the mean diameter is 1 (the output's length unit);
2. the box is scaled isotropically (centres affinely) to a new packing fraction, each
   step followed by FIRE energy minimisation at fixed box to
   ``max_i |F_i| <= bisection_force_factor * P0``. Two ways to choose the steps
   (``JammingSettings.onset``):

   - ``"search"`` (:func:`search_to_pressure`): every trial compresses the
     last minimum found below ``P0`` (kept); a scout doubles the step from ``delta_phi``
     while the pressure stays below ``P0``, at most ``max_strain_step`` of box length per
     step, until it first passes ``P0``; the search then returns to the scout's minimum
     at ``RETURN_SHARE`` below and approaches in steps of at most
     ``APPROACH_STRAIN_STEP`` (the scout's steps alone jam denser packings). Even so its
     ``phi_J`` from a dilute start lies 0.4-2 % above the bisection's, near O'Hern's
     infinite-temperature quench (docs/notes/chains.md, "Dilute starts"). A minimum above ``P0`` is discarded: it bounds ``phi`` from above, and the
     next trial starts again from the kept minimum, at the secant estimate of
     ``P(phi) = P0`` inside the bracket (``P`` is linear in ``phi - phi_J`` for
     harmonic contacts) or at its midpoint. So the packing that is kept was never
     compressed above ``P0`` and decompressed: a pure compression, like the
     bisection's first crossing of ``P0`` with small steps. A start above ``P0``
     decompresses the same way until one minimum lies below it;
   - ``"bisection"`` (default, :func:`bisect_to_pressure`, O'Hern's): steps of ``delta_phi``
     from the current minimum, compressing below ``P0`` and decompressing above it,
     ``delta_phi`` halved whenever the direction reverses. From a dilute start it
     steps ``delta_phi`` at a time across the whole density range (docs/notes/chains.md,
     "Dilute starts").

   Either way a minimisation whose energy ``U + K`` falls below the model's floor
   (:meth:`~jamflow.minimize.model.EnergyModel.energy_floor`) for ``VERDICT_SHARE
   (1 - rtol) P0`` stops there: no minimum it can still reach has a pressure in the
   window or above it, so the verdict "below ``P0``" is the one its minimum would give
   (:data:`VERDICT_SHARE`);
3. when ``|P - P0| <= bisection_rtol * P0`` the enthalpy ``H = U + P0 V`` is
   minimised with centres and box scale as degrees of freedom to
   ``max_i |F_i| <= force_tol`` and ``|P - P0| <= pressure_rtol * P0`` (models with
   box degrees of freedom), or step 2 continues at fixed box with ``force_tol``
   until ``|P - P0| <= pressure_rtol * P0``; the bisection then shortens a step to
   the secant estimate of ``P(phi) = P0`` when that is shorter (``secant`` of
   :func:`bisect_to_pressure`, its first steps on the slope of the first stage's last
   bracket of ``P0``; the search has its own secant). With
   ``JammingSettings.newton_polish`` either may end with a Newton polish: the enthalpy
   stage by :func:`~jamflow.minimize.newton.polish_enthalpy`, the fixed-box minimisations
   of constrained models by :func:`~jamflow.minimize.newton.polish_constrained`
   (:func:`_polished_fire`).

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
from dataclasses import dataclass, replace

import numpy as np

from ..tolerances import SOFT_FORCE_TOL
from .fire import (
    DEFAULT_FIRE,
    FireParameters,
    MinimizeResult,
    _fire,
    _fire_engine,
    minimize_enthalpy_model,
    minimize_fire,
)
from .model import EnergyModel
from .newton import polish_constrained, polish_enthalpy

__all__ = ["FORCE_TOL_VANDERWERF", "MAX_STRAIN_STEP", "ONSET_METHODS", "JammingSettings", "bisect_to_pressure",
           "jam_model_to_pressure", "search_to_pressure"]


#: Default final ``max_i |F_i|`` [epsilon / <D>]: VanderWerf et al.'s ``F_i^2 < 1e-25``
#: with a factor ten to spare (see :data:`jamflow.tolerances.SOFT_FORCE_TOL`).
FORCE_TOL_VANDERWERF: float = SOFT_FORCE_TOL

#: The two ways of step 2 (module doc): the search that keeps the last minimum below
#: ``P0``, and O'Hern's compress/decompress bisection with a fixed first step.
ONSET_METHODS: tuple[str, ...] = ("bisection", "search")

#: Largest relative change of the box length in one step of the search: an affine
#: compression of a packing without overlaps creates overlaps of at most this fraction
#: of the centre distances (5 % of a diameter for touching spheres and clusters), so
#: links and rod cores cannot pass through each other in one step
#: (docs/notes/chains.md, "Dilute starts").
MAX_STRAIN_STEP: float = 0.05

#: Trials in a row below ``P0`` after which the upper bound of the search is dropped: a
#: minimum above ``P0`` reached by a long compression lies on another branch of ``P(phi)``
#: (it jams at a lower ``phi``), so a shorter compression of the kept minimum may stay
#: below ``P0`` up to that bound and past it (docs/notes/chains.md, "Dilute starts").
STALE_TRIALS: int = 3

#: Largest relative change of the box length per step on the approach to jamming: the
#: scout's steps (:data:`MAX_STRAIN_STEP`) alone jam denser packings than the bisection's
#: slow compression (3D spheres N = 64 from phi = 0.1: phi_J 0.6376 +- 0.0024 against
#: 0.6285 +- 0.0020); with the return and this step the gap is 0.4-1.2 % of phi_J over 20
#: seeds, at 40-60 minimisations (docs/notes/chains.md, "Dilute starts").
APPROACH_STRAIN_STEP: float = 0.0075

#: The approach starts from the last scouting minimum at or below ``(1 - RETURN_SHARE)``
#: times the ``phi`` of the scout's last minimum below ``P0`` (same measurement).
RETURN_SHARE: float = 0.15


#: A fixed-box minimisation of step 2 stops early, with the verdict "below ``P0``", once its
#: energy ``U + K`` falls under the model's floor (:meth:`EnergyModel.energy_floor`) for the
#: pressure ``VERDICT_SHARE (1 - rtol) P0``: every minimum it can still reach lies below that,
#: outside the window ``|P - P0| <= rtol P0``. The share covers the energy error of FIRE's
#: steps (``U + K`` is not strictly monotone; the bound on ``P`` grows as ``sqrt(U)`` for
#: harmonic contacts, so the energy may grow fourfold before a verdict could be wrong);
#: measured against the full minimisations in docs/notes/chains.md, "The onset's energy verdict and secant steps".
VERDICT_SHARE: float = 0.5

#: FIRE steps of the enthalpy stage between two looks at its largest force for a try of the
#: trust-region Newton polish (``JammingSettings.newton_polish``) [1].
POLISH_CHECK: int = 2000

#: A try is made when FIRE's largest force is at most this many times the force tolerance
#: [1]: at P0 = 1e-6 (force_tol 1e-13) the polish lands from FIRE states with largest force
#: 1e-12 ... 7e-11 at N = 480 and fails from most at 1e-10 ... 3e-8 (at N = 100 it lands from
#: the stage's start, 9e-9); a failed try (100 trial steps) costs ~10^4 FIRE steps at N = 480
#: (docs/notes/shapes.md, "Trust-region Newton for the enthalpy stage").
POLISH_FORCE: float = 1e3

#: Trial steps of the first try of the enthalpy stage's polish [1]; each try after a failed one gets
#: half of the one before, so a stage's tries cost at most twice its first. A try that fails after
#: descending hands its end state to FIRE, so it is a walk along the stage's flat valley rather than a
#: lost try, and it is not cut short by steps into indefinite regions (``max_indefinite=None``). On the
#: N = 480 circulo-lines of seed 2 (P0 = 1e-6) FIRE glides 3.5 million steps along one collective
#: soft mode; walks of up to 400 trial steps end that stage in 100471 steps and 41 s of CPU, against
#: 102178 steps with tries of 100 and at most 8 undone steps, handed over too (seed 1: 56266 against
#: 102178 steps; circulo-triangles N = 100: the same CPU): docs/notes/shapes.md, "Newton walks in the
#: enthalpy stage". The halving: the walks of near-disk ellipses (N = 100, aspect ratio 1 + 1e-3) creep
#: on modes softer than the polish's least shift and never land, ten of 400 trial steps in a stage whose
#: FIRE steps they do not change; the tries that land after a failed one take 8-49 trial steps (same
#: notes, "Closing contacts along a step's line").
STAGE_WALK_ITERATIONS: int = 400

#: Least FIRE steps between two tries of the polish [1], growing by :data:`POLISH_GROWTH`
#: after each further failed try: FIRE's largest force fluctuates, so without it a state that
#: failed would be followed by near copies of itself.
POLISH_INTERVAL: int = 20000

#: FIRE steps of a fixed-box minimisation of the final stage before the constrained Newton polish
#: is first considered (:func:`_polished_fire`) [1]: a minimisation that has not converged by then
#: is held up by soft modes, where the polish pays; at 3D chains of four, N = 1024, P0 = 1e-4 a try
#: from FIRE's largest force ~1e-9 (after ~2e4 steps) costs ~0.3 s of CPU, ~2000 FIRE steps, and
#: ends 3000-5000 steps early, while minimisations of N = 256 converge in 1000-2500 steps, fewer
#: than a try costs (docs/notes/chains.md, "A Newton polish for the last linked minimisations").
LINKED_POLISH_AFTER: int = 5000

#: FIRE steps between two looks at the largest force of a fixed-box minimisation of the final stage [1]
#: (each look is one evaluation; the force falls by about a decade per 2000 steps there, same notes).
LINKED_POLISH_CHECK: int = 500

#: Least FIRE steps between two tries of the constrained Newton polish in a fixed-box minimisation of
#: the final stage (:func:`_polished_fire`) [1], growing by :data:`POLISH_GROWTH` after each further
#: failed try.
LINKED_POLISH_INTERVAL: int = 2000

#: Trial steps of one try of the constrained polish [1]: from FIRE's states at largest force 1e-9 ...
#: 2e-8 it lands in 1-5 (N = 1024, same notes); a failed try stops there (each trial step costs
#: ~0.1 s at N = 1024, a sparse factorisation and a Hessian).
LINKED_NEWTON_ITERATIONS: int = 8

#: Growth of the interval between two tries of the Newton polish [1].
POLISH_GROWTH: float = 1.25


@dataclass(frozen=True)
class JammingSettings:
    """Tolerances and budget of the jamming protocol (module doc; :func:`jam_model_to_pressure`).

    ``onset`` is one of :data:`ONSET_METHODS`; ``delta_phi`` is the first step in
    packing fraction of either; ``max_strain_step`` caps the search's steps (relative
    change of the box length). ``newton_polish`` lets the enthalpy stage end with Newton
    iterations (:func:`jamflow.minimize.newton.polish_enthalpy`) once FIRE is close
    enough (tried when its largest force is within :data:`POLISH_FORCE` of the tolerance), to the same tolerances;
    for models without box degrees of freedom that offer ``tangent_newton`` (linked spheres) the
    fixed-box minimisations of the final stage likewise (:func:`jamflow.minimize.newton.polish_constrained`,
    :func:`_polished_fire`).
    """

    force_tol: float = FORCE_TOL_VANDERWERF
    pressure_rtol: float = 1e-6
    delta_phi: float = 1e-3
    bisection_rtol: float = 0.1
    bisection_force_factor: float = 1e-2
    max_steps: int = 20_000_000
    fire_params: FireParameters = DEFAULT_FIRE
    box_dof: str = "isotropic"
    onset: str = "bisection"
    max_strain_step: float = MAX_STRAIN_STEP
    newton_polish: bool = False

    def __post_init__(self) -> None:
        if self.onset not in ONSET_METHODS:
            raise ValueError(f"onset must be one of {', '.join(ONSET_METHODS)}, got {self.onset!r}")
        if not 0.0 < self.max_strain_step < 1.0:
            raise ValueError(f"max_strain_step must lie in (0, 1), got {self.max_strain_step}")


@dataclass
class _PolishTries:
    """When a paused FIRE run tries a Newton polish: its largest force within :data:`POLISH_FORCE` of
    ``force_tol`` and at least ``interval`` steps since the last failed try (the interval grows by
    :data:`POLISH_GROWTH` after each further failed try)."""

    force_tol: float
    interval: float
    last: int | None = None

    def due(self, steps: int, max_force: float) -> bool:
        return max_force <= POLISH_FORCE * self.force_tol and (self.last is None or steps - self.last >= self.interval)

    def failed(self, steps: int) -> None:
        if self.last is not None:
            self.interval *= POLISH_GROWTH
        self.last = steps


def _polished_fire(model: EnergyModel, x: np.ndarray, force_tol: float, budget: int, fire_params: FireParameters,
                   floor: float) -> tuple[EnergyModel, MinimizeResult]:
    """Fixed-box FIRE that pauses every :data:`LINKED_POLISH_CHECK` steps after the first
    :data:`LINKED_POLISH_AFTER` and, when its largest force is within :data:`POLISH_FORCE` of
    ``force_tol`` and :data:`LINKED_POLISH_INTERVAL` steps (growing by :data:`POLISH_GROWTH` after each
    further failed try) have passed since the last try, tries (:data:`LINKED_NEWTON_ITERATIONS` trial steps) the
    constrained Newton polish (:func:`~jamflow.minimize.newton.polish_constrained`) from its state; the
    first try that succeeds ends the run (its ``steps`` are FIRE's), a failed one changes nothing.
    Returns the model of the result (rebased on the polished state when the polish ended it)."""
    engine = _fire_engine(model, model.dofs(x), fire_params)
    steps, tries = 0, _PolishTries(force_tol, float(LINKED_POLISH_INTERVAL))
    while True:
        chunk = max(LINKED_POLISH_AFTER - steps, LINKED_POLISH_CHECK)
        res = _fire(engine, force_tol, min(chunk, budget - steps), floor)
        steps += res.steps
        if res.converged or res.below or steps >= budget:
            return model, replace(res, steps=steps)
        if not tries.due(steps, res.max_force):
            continue
        base, start = model.rescaled(1.0, res.position)
        polish = polish_constrained(base, start, force_tol, LINKED_NEWTON_ITERATIONS)
        if polish.result is not None:
            return polish.model, replace(polish.result, steps=steps)
        tries.failed(steps)


def _minimum(model: EnergyModel, x: np.ndarray, phi: float, force_tol: float, budget: int,
             fire_params: FireParameters, progress: Callable[[dict], None] | None, history: dict[str, list] | None,
             info: dict, pressure: float, rtol: float, polish: bool = False) -> tuple[EnergyModel, MinimizeResult]:
    """One fixed-box FIRE minimisation of step 2, recorded in ``history`` and reported to ``progress``
    (with ``info``: ``delta_phi`` and the protocol's ``steps`` before it); raises when the budget runs out.

    It stops early on the energy verdict (:data:`VERDICT_SHARE`); its ``pressure`` is then
    the least of the state's and the verdict's bound ``VERDICT_SHARE (1 - rtol) P0``, and
    ``below`` is set. With ``polish`` it may end with the constrained Newton polish
    (:func:`_polished_fire`; models without ``tangent_newton`` run FIRE alone). Returns the
    model of the result (the polish rebases it on its state) and the result."""
    ceiling = VERDICT_SHARE * (1.0 - rtol) * pressure
    floor = model.energy_floor(ceiling)
    if polish and getattr(model, "tangent_newton", None) is not None:
        model, res = _polished_fire(model, x, force_tol, budget, fire_params, floor)
    else:
        res = minimize_fire(model, x, force_tol, budget, fire_params, floor)
    if res.below:
        res = replace(res, pressure=min(res.pressure, ceiling))
    if history is not None:
        history["phi"].append(phi)
        history["pressure"].append(res.pressure)
        history["steps"].append(res.steps)
    if progress is not None:
        progress({**info, "phi": phi, "pressure": res.pressure, "steps": info["steps"] + res.steps,
                  "model": model, "position": res.position})
    if not (res.converged or res.below):
        raise RuntimeError(f"FIRE step budget ({budget + info['steps']}) exhausted at phi = {phi:.10f}")
    return model, res


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
    secant: bool = False,
    polish: bool = False,
    slope: float | None = None,
) -> tuple[EnergyModel, MinimizeResult, float, float, int, int, float | None]:
    """Compress/decompress bisection of any model to ``|P - P0| <= rtol P0`` (module doc, step 2).

    After each fixed-box FIRE minimisation to ``force_tol`` the box is scaled by
    ``model.rescaled`` to the next packing fraction ``phi +- delta_phi``; ``delta_phi``
    halves when the direction reverses. Stops also when the step underflows.

    With ``secant`` a step is shortened to the secant estimate ``|P0 - P| / (dP/dphi)``
    when that is shorter, the slope taken from the last two minima with ``P > 0`` (if
    it is positive): ``P`` is linear in ``phi - phi_J`` on one contact network for
    harmonic contacts, so near ``P0`` the bisection's halvings shrink to a few
    Newton steps, each still from the last minimum; a rearrangement between two minima
    gives a wrong slope for one step, which the next pair replaces. Before two minima of its
    own give a slope, ``slope`` (the bracket of an earlier stage) serves: without it the
    first step of a resumed bisection is the whole ``delta_phi`` of the stage before, which
    may cross back past the bracket's lower end and decompress the packing to a fragile
    state that rearranges (docs/notes/chains.md, "The final stage's first step").

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
    secant : bool
        Secant steps when shorter (above).
    polish : bool
        Let each minimisation end with the constrained Newton polish (:func:`_polished_fire`).
    slope : float, optional
        ``dP/dphi`` [epsilon / <D>^d] known from an earlier stage, > 0, for the secant steps
        (``secant`` must be set) until two minima of this run give one.

    Returns
    -------
    model, result, phi, delta_phi, direction, steps, slope
        The model in the last box, its FIRE result, the state to resume from, and the
        slope of the last bracket of ``P0``: the secant through the last minimum above
        ``P0`` and the last one below it with ``P > 0`` (stopped by the verdict, a minimum
        has only a bound on its pressure and does not count), or None when there is no
        such pair or its slope is not positive.
    """
    if slope is not None and not secant:
        raise ValueError("slope seeds the secant steps: pass secant=True with it")
    d = model.box.d
    steps = 0
    x = position
    last: tuple[float, float] | None = None
    side: dict[bool, tuple[float, float]] = {}  # the last minimum above (True) and below P0 with a true P > 0
    while True:
        model, res = _minimum(model, x, phi, force_tol, max_steps - steps, fire_params, progress, history,
                              {"delta_phi": delta_phi, "steps": steps}, pressure, rtol, polish)
        steps += res.steps
        x = res.position
        if res.pressure > 0.0 and not res.below:
            side[res.pressure > pressure] = (phi, res.pressure)
        if abs(res.pressure - pressure) <= rtol * pressure:
            break
        if secant and res.pressure > 0.0 and not res.below:
            if last is not None and phi != last[0]:
                rise = (res.pressure - last[1]) / (phi - last[0])
                slope = rise if rise > 0.0 else None
            last = (phi, res.pressure)
        new_direction = 1 if res.pressure < pressure else -1
        if direction and new_direction != direction:
            delta_phi *= 0.5
        direction = new_direction
        step = delta_phi if slope is None else min(delta_phi, abs(pressure - res.pressure) / slope)
        if step < 4.0 * np.finfo(float).eps * phi:
            break
        new_phi = phi + direction * step
        factor = (phi / new_phi) ** (1.0 / d)
        model, x = model.rescaled(factor, x)
        phi = new_phi
    return model, res, phi, delta_phi, direction, steps, _bracket_slope(side)


def _bracket_slope(side: dict[bool, tuple[float, float]]) -> float | None:
    """``dP/dphi`` of the secant through the last minima above (``side[True]``) and below ``P0``, if both
    exist and it is positive (a rearrangement between them can make ``P`` fall with ``phi``)."""
    if len(side) < 2 or side[True][0] == side[False][0]:
        return None
    (phi_hi, p_hi), (phi_lo, p_lo) = side[True], side[False]
    rise = (p_hi - p_lo) / (phi_hi - phi_lo)
    return rise if rise > 0.0 else None


class _Bracket:
    """Where the search for ``P(phi) = P0`` stands (module doc, step 2, ``"search"``).

    While ``scouting`` the steps double up to ``max_strain`` and every minimum below
    ``P0`` is kept; the first one above ``P0`` ends the scout: the search returns to the
    kept minimum below ``(1 - RETURN_SHARE)`` of the last one's ``phi``, forgets the scout's bounds
    (another branch of ``P(phi)``) and approaches in steps of at most
    :data:`APPROACH_STRAIN_STEP` of box length.

    ``lo`` is the kept minimum below ``P0`` (model, FIRE result, ``phi``); ``hi`` the
    ``(phi, P)`` of the last trial above ``P0`` since then, dropped after
    :data:`STALE_TRIALS` trials in a row below ``P0``; ``step`` the next compression of
    ``lo`` (doubled after a trial below ``P0`` when no bound is known, halved to the
    midpoint after one above). ``jammed`` holds the two last minima above ``P0`` and
    ``slope`` the ``dP/dphi`` they give.
    """

    def __init__(self, pressure: float, rtol: float, step: float, max_strain: float, d: int,
                 slope: float | None, scout: bool) -> None:
        self.pressure, self.step, self.max_strain, self.d, self.slope = pressure, step, max_strain, d, slope
        # the secant aims into the lower half of the window |P - P0| <= rtol P0: a trial that
        # lands below P0 becomes the kept minimum, close to the target
        self.aim = pressure * (1.0 - 0.5 * rtol)
        self.lo: tuple[EnergyModel, MinimizeResult, float] | None = None
        self.hi: tuple[float, float] | None = None
        self.jammed: list[tuple[float, float]] = []
        self.below = 0
        self.scouting = scout
        self.secant = False
        self.kept: list[tuple[EnergyModel, MinimizeResult, float]] = []

    def _return(self) -> None:
        """End the scout that has just passed ``P0`` (class doc)."""
        floor = (1.0 - RETURN_SHARE) * self.kept[-1][2]
        below = [state for state in self.kept if state[2] <= floor]
        self.lo = below[-1] if below else self.kept[0]
        self.kept, self.scouting = [], False
        self.hi, self.below, self.jammed = None, 0, []
        self.max_strain, self.step = APPROACH_STRAIN_STEP, np.inf

    def record(self, model: EnergyModel, res: MinimizeResult, phi: float) -> None:
        """Take in the minimum ``res`` of a trial at ``phi`` (class doc)."""
        if res.pressure >= self.pressure:
            # the slope of the branch above P0 only: below it a minimum may be one that
            # is not yet jammed (P ~ P0 / 4 falling under compression) and P(phi) jumps
            self.jammed = [*self.jammed[-1:], (phi, res.pressure)]
            (p1, y1), (p2, y2) = self.jammed[0], self.jammed[-1]
            if p1 != p2 and (y2 - y1) / (p2 - p1) > 0.0:
                self.slope = (y2 - y1) / (p2 - p1)
            if self.scouting and self.lo is not None:
                self._return()
                return
            self.scouting = False
            if self.lo is not None:
                self.step = 0.5 * (phi - self.lo[2])
            self.hi, self.below = (phi, res.pressure), 0
            return
        self.lo = (model, res, phi)
        if self.scouting:
            self.kept.append(self.lo)
        self.below += 1
        if self.hi is not None and self.below > STALE_TRIALS:
            self.hi = None

    def _secant(self, phi: float, pressure: float) -> float:
        """``phi`` where the line through ``(phi, pressure)`` with the known slope reaches the aim (NaN if none)."""
        if self.slope is None:
            return np.nan
        return phi + (self.aim - pressure) / self.slope

    def _capped(self, base: float, target: float) -> float:
        # at most max_strain of box length per step: phi ~ L^-d
        return float(np.clip(target, base * (1.0 + self.max_strain) ** -self.d,
                             base * (1.0 - self.max_strain) ** -self.d))

    def next_phi(self, phi: float, pressure: float) -> tuple[float, bool]:
        """The next trial's ``phi`` after a minimum at ``phi`` with ``pressure``, and whether it starts
        from the kept minimum below ``P0`` (else from this one: decompression of a start above ``P0``)."""
        if self.lo is None:
            target = self._secant(phi, pressure)
            if np.isnan(target):
                target = phi - self.step
                self.step *= 2.0
            return self._capped(phi, target), False
        base = self.lo[2]
        target = base + self.step
        if self.hi is None:
            self.step *= 2.0
        else:
            # interpolation towards a minimum above P0 (extrapolation from below
            # would crawl on a minimum that is not yet jammed, P ~ P0 / 2 not rising);
            # after a secant trial that stayed below P0 the midpoint, so the bracket shrinks
            # from both sides where P(phi) jumps (a rearrangement between lo and hi)
            secant = self._secant(*self.hi)
            use = base < secant < self.hi[0] and not (self.secant and self.below)
            target = secant if use else min(target, 0.5 * (base + self.hi[0]))
            self.secant = use
        return self._capped(base, target), True


def search_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    force_tol: float,
    rtol: float,
    delta_phi: float,
    max_strain: float,
    max_steps: int,
    fire_params: FireParameters = DEFAULT_FIRE,
    progress: Callable[[dict], None] | None = None,
    history: dict[str, list] | None = None,
    slope: float | None = None,
    scout: bool = True,
    polish: bool = False,
) -> tuple[EnergyModel, MinimizeResult, float, float | None, int]:
    """Fixed-box FIRE minima on a search for ``|P - P0| <= rtol P0`` that keeps the last minimum below ``P0``.

    Module doc, step 2, ``"search"``: every trial is the kept minimum below ``P0``
    scaled by ``model.rescaled`` to the next ``phi`` and minimised to ``force_tol``;
    minima above ``P0`` only bound ``phi``. Stops also when the bracket shrinks to
    round-off (returning its last minimum).

    Parameters
    ----------
    model : EnergyModel
        Needs ``rescaled(factor, position) -> (model, position)``.
    position : ndarray, shape (N, d)
    phi : float
        Packing fraction of the start (``phi ~ 1 / V``).
    delta_phi : float
        First step in packing fraction; it doubles while the pressure stays below (a
        start above ``P0``: above) ``P0`` and no slope is known.
    max_strain : float
        Largest relative change of the box length per step outside a bracket.
    progress, history
        As :func:`bisect_to_pressure` (every trial, kept or not, is one entry).
    slope : float, optional
        A known ``dP/dphi`` [pressure per packing fraction], e.g. of an earlier search
        at a looser force tolerance, used until two minima above ``P0`` give their own.
    scout : bool
        Scout with steps up to ``max_strain`` and approach again from ``RETURN_SHARE``
        below (:class:`_Bracket`); False for a start already close to ``P0``.
    polish : bool
        As :func:`bisect_to_pressure`.

    Returns
    -------
    model, result, phi, slope, steps
        The model in the last box, its FIRE result and packing fraction, the last slope
        ``dP/dphi`` (None if no two minima above ``P0`` were seen) and the FIRE steps taken.
    """
    d = model.box.d
    bracket = _Bracket(pressure, rtol, delta_phi, max_strain, d, slope, scout)
    steps = 0
    x = position
    while True:
        model, res = _minimum(model, x, phi, force_tol, max_steps - steps, fire_params, progress, history,
                              {"delta_phi": bracket.step, "steps": steps}, pressure, rtol, polish)
        steps += res.steps
        if abs(res.pressure - pressure) <= rtol * pressure:
            break
        bracket.record(model, res, phi)
        new_phi, from_kept = bracket.next_phi(phi, res.pressure)
        base_model, base_x, base_phi = (bracket.lo[0], bracket.lo[1].position, bracket.lo[2]) if from_kept \
            else (model, res.position, phi)
        if abs(new_phi - base_phi) < 4.0 * np.finfo(float).eps * base_phi:
            break
        model, x = base_model.rescaled((base_phi / new_phi) ** (1.0 / d), base_x)
        phi = new_phi
    return model, res, phi, bracket.slope, steps


def _enthalpy_stage(model: EnergyModel, position: np.ndarray, pressure: float, c: JammingSettings,
                    budget: int) -> MinimizeResult:
    """Step 3: FIRE on ``U + P0 V``; with ``c.newton_polish`` FIRE pauses every :data:`POLISH_CHECK` steps and
    tries a trust-region Newton polish when its largest force is within :data:`POLISH_FORCE` of ``c.force_tol``
    and at least :data:`POLISH_INTERVAL` steps (growing by :data:`POLISH_GROWTH` after each failed try) have
    passed since the last try; the stage ends with the first try that succeeds (its ``steps`` are FIRE's). A
    try of at most :data:`STAGE_WALK_ITERATIONS` trial steps (half the last try's after a failed one) that
    fails after lowering ``H`` is a walk along the valley: FIRE goes on from its end state, at rest."""
    if not c.newton_polish:
        return minimize_enthalpy_model(model, position, pressure, c.force_tol, c.pressure_rtol, budget,
                                       c.fire_params, c.box_dof)
    base = model
    engine = _fire_engine(base, base.dofs(position), c.fire_params, float(pressure), c.pressure_rtol, c.box_dof)
    steps, tries = 0, _PolishTries(c.force_tol, float(POLISH_INTERVAL))
    walk = STAGE_WALK_ITERATIONS
    while True:
        res = _fire(engine, c.force_tol, min(POLISH_CHECK, budget - steps))
        steps += res.steps
        if res.converged or steps >= budget:
            return replace(res, steps=steps)
        if not tries.due(steps, res.max_force):
            continue
        scale = (res.box.volume / base.box.volume) ** (1.0 / base.box.d)
        scaled, _ = base.rescaled(scale, res.position)
        polish = polish_enthalpy(scaled, res.position, pressure, c.force_tol, c.pressure_rtol, walk,
                                 max_indefinite=None)
        if polish.result is not None:
            return replace(polish.result, steps=steps)
        tries.failed(steps)
        walk = max(walk // 2, 1)
        if polish.descended:
            base = polish.model
            engine = _fire_engine(base, base.dofs(polish.position), c.fire_params, float(pressure),
                                  c.pressure_rtol, c.box_dof)


def jam_model_to_pressure(
    model: EnergyModel,
    position: np.ndarray,
    phi: float,
    pressure: float,
    settings: JammingSettings = JammingSettings(),
    progress: Callable[[dict], None] | None = None,
) -> tuple[EnergyModel, MinimizeResult, dict[str, list], int]:
    """Jamming onset of any model at pressure ``P0`` (the protocol of :func:`jam_to_pressure`).

    Step 2 by ``settings.onset`` (module doc). Models with box degrees of freedom
    (``model.box_dofs``, e.g. soft spheres) end with the enthalpy minimisation of step 3, and
    so do models that offer a twin with the volume free (``model.with_free_volume(position)``,
    shear-stabilised linked spheres: the stage frees their whole box); any other model
    continues step 2 with fixed-box FIRE to ``force_tol`` until ``|P - P0| <= pressure_rtol P0``
    (the search from the first stage's slope).

    Returns
    -------
    model, result, history, steps
        The model in the final box, the final minimisation, the per-step history
        (``phi``, ``pressure``, ``steps``) and the total FIRE steps.
    """
    c = settings
    free_volume = hasattr(model, "with_free_volume")
    if free_volume and c.newton_polish:
        # the constrained polish works at fixed volume; the enthalpy stage's twin has no Hessian for it
        raise ValueError("newton_polish polishes the fixed-box final stage of a linked packing; a shear-stabilised "
                         "bisection ends with the enthalpy minimisation (volume free), which it does not polish")
    history: dict[str, list] = {"phi": [], "pressure": [], "steps": []}
    loose = c.bisection_force_factor * pressure
    if c.onset == "search":
        model, res, phi, slope, steps = search_to_pressure(
            model, position, phi, pressure, loose, c.bisection_rtol, c.delta_phi, c.max_strain_step,
            c.max_steps, c.fire_params, progress, history,
        )
    else:
        model, res, phi, delta_phi, direction, steps, slope = bisect_to_pressure(
            model, position, phi, pressure, loose, c.bisection_rtol, c.delta_phi,
            c.max_steps, c.fire_params, progress, history,
        )
    x = res.position
    if free_volume:
        # a model whose volume is a constraint of the onset (shear-stabilised linked spheres) ends, as spheres
        # do, with the enthalpy minimisation, on its twin with the volume free (rebased on the last box)
        model, x = model.with_free_volume(x)
    if model.box_dofs:
        final = _enthalpy_stage(model, x, pressure, c, c.max_steps - steps)
        return model, final, history, steps + final.steps
    if c.onset == "search":
        # first step: the pressure window of the loose stage, on its slope
        step = c.bisection_rtol * pressure / slope if slope else c.delta_phi
        model, final, _, _, more = search_to_pressure(
            model, res.position, phi, pressure, c.force_tol, c.pressure_rtol, step, c.max_strain_step,
            c.max_steps - steps, c.fire_params, progress, history, slope, scout=False, polish=c.newton_polish,
        )
        return model, final, history, steps + more
    model, final, _, _, _, more, _ = bisect_to_pressure(
        model, res.position, phi, pressure, c.force_tol, c.pressure_rtol, delta_phi, c.max_steps - steps,
        c.fire_params, progress, history, direction, secant=True, polish=c.newton_polish, slope=slope,
    )
    return model, final, history, steps + more
