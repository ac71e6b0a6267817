"""Energy and enthalpy minimisers for soft spheres: FIRE, steepest descent, CG.

Units: masses are 1; time steps are given in units of ``<D> sqrt(m / epsilon)`` with
``<D>`` the mean diameter, so the same defaults work whatever the length unit of
the packing. Force tolerances are absolute, in ``epsilon / length`` of the packing;
convergence means that the largest per-particle force norm ``max_i |F_i|`` is at
most ``force_tol``. The criterion of VanderWerf et al. (Sec. II), squared forces per
particle below 1e-25 in units of the spring constant, is ``force_tol = 10**-12.5``
for a packing whose mean diameter is 1; the jamming stage uses 1e-13 (see
:mod:`jamflow.minimize.onset`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..tolerances import MINIMIZE_FORCE_TOL
from . import _fire_kernels
from .model import EnergyModel, pressure_of

__all__ = ["DEFAULT_FIRE", "FireParameters", "MinimizeResult", "minimize_enthalpy_model", "minimize_fire", "no_energy_floor"]


@dataclass(frozen=True)
class FireParameters:
    """FIRE 2.0 parameters (Guénolé et al., Comput. Mater. Sci. 175, 109584 (2020)).

    Time steps in units of ``<D> sqrt(m / epsilon)``; the others are the published
    defaults (``alpha0 = 0.25``, ``N_delay = 20``, ``f_inc = 1.1``, ``f_dec = 0.5``,
    ``f_alpha = 0.99``, ``dt_max = 10 dt``, ``dt_min = 0.02 dt``). ``dt_max = 0.3``
    stays below the explicit-Euler stability limit ``2 / omega_max`` of the harmonic
    potential up to d = 5 (``omega_max^2 ~ 2 z epsilon / sigma^2`` with z <= 2d + a few).
    """

    dt: float = 0.03
    dt_max: float = 0.3
    dt_min: float = 0.0006
    f_inc: float = 1.1
    f_dec: float = 0.5
    alpha0: float = 0.25
    f_alpha: float = 0.99
    n_delay: int = 20
    initial_delay: bool = True

    def as_dict(self) -> dict:
        return asdict(self)


#: FIRE 2.0 with the default parameters.
DEFAULT_FIRE = FireParameters()


@dataclass(frozen=True)
class MinimizeResult:
    """Outcome of a minimisation.

    Attributes
    ----------
    position : ndarray, shape (N, d)
        Final centres [length], unwrapped.
    box : Box
        Final box (changed only by enthalpy minimisation).
    energy : float
        Final energy U [epsilon].
    pressure : float
        Final virial pressure [epsilon / length^d].
    max_force : float
        Final ``max_i |F_i|`` [epsilon / length].
    n_contacts : int
        Overlapping pairs at the end.
    steps : int
        Force evaluations / integration steps taken.
    converged : bool
    rebuilds : int
        Neighbour-list builds during the run.
    evaluations : int
        Energy/force evaluations during the run.
    below : bool
        The run stopped before convergence because its energy ``U + K`` fell below the
        ``energy_floor`` it was given (:func:`minimize_fire`): every minimum it can still
        reach has a pressure below the one the floor was made for.
    """

    position: NDArray[np.float64]
    box: Box
    energy: float
    pressure: float
    max_force: float
    n_contacts: int
    steps: int
    converged: bool
    rebuilds: int
    evaluations: int
    below: bool = False


def _fire_params(params: FireParameters, unit: float) -> NDArray[np.float64]:
    return np.array([params.dt_max * unit, params.dt_min * unit, params.f_inc, params.f_dec,
                     params.alpha0, params.f_alpha, params.n_delay, float(params.initial_delay)])


def _as_column(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """A (n, 1) view of a flat vector, the array shape of the FIRE control kernels."""
    return a.reshape(-1, 1)


class _ModelFire:
    """FIRE steps of any model on its flat degree-of-freedom vector (the control kernels of the compiled loop).

    Mass metric: with ``M`` the diagonal masses, the run is the unit-mass FIRE of the
    coordinates ``M^(1/2) q`` (so a time step means the same for every degree of
    freedom): power ``F . v``, Euler step ``v += dt M^-1 F``, mixing
    ``v <- (1 - alpha) v + alpha |v|_M / |F|_M^-1 M^-1 F``. With constraints the force
    and, after every move, the velocity are projected onto the tangent space, and
    positions are re-affixed onto the constraint manifold after every move. The
    model owns its neighbour list, so a run never stops for a rebuild.
    """

    def __init__(self, model: EnergyModel, q0: NDArray[np.float64], params: FireParameters) -> None:
        self.model = model
        self.params = params
        unit = model.time_unit
        self.dt_max, self.dt_min = params.dt_max * unit, params.dt_min * unit
        self.inv_mass = model.inverse_mass
        self.mass = 1.0 / self.inv_mass
        self.builds0 = model.neighbor_builds
        self.q = np.array(model.reproject(np.array(q0, dtype=np.float64)), dtype=np.float64)
        self.v = np.zeros_like(self.q)
        self.dt, self.alpha, self.npos = params.dt * unit, params.alpha0, 0
        self.ev = model.evaluate(self.q)
        self.force = -model.project(self.ev.gradient, self.q)
        self.fmax = model.max_force(self.force)
        self.step = 0

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        model, params = self.model, self.params
        q, v, force, inv_mass, mass = self.q, self.v, self.force, self.inv_mass, self.mass
        dt, alpha, npos, step, fmax = self.dt, self.alpha, self.npos, self.step, self.fmax
        ev = self.ev
        taken = 0
        while taken < budget and fmax > force_tol:
            if energy_floor > 0.0 and ev.energy + 0.5 * float(np.sum(mass * v * v)) <= energy_floor:
                self.q, self.v, self.force, self.ev, self.fmax = q, v, force, ev, fmax
                self.dt, self.alpha, self.npos, self.step = dt, alpha, npos, step
                return _fire_kernels.BELOW, taken
            power = float(force @ v)
            npos, dt, alpha = _fire_kernels._fire_adapt(
                power, step, npos, dt, alpha, params.n_delay, params.f_inc, params.f_dec, params.f_alpha,
                params.alpha0, self.dt_max, self.dt_min, params.initial_delay,
            )
            if not power > 0.0:
                _fire_kernels._fire_step_back(_as_column(q), _as_column(v), dt)
                q = model.reproject(q)
            accel = inv_mass * force
            _fire_kernels._axpy(dt, _as_column(accel), _as_column(v))
            vnorm = float(np.sqrt(np.sum(mass * v * v)))
            fnorm = float(np.sqrt(force @ accel))
            keep, mix = _fire_kernels._fire_mixing(alpha, vnorm, fnorm)
            _fire_kernels._mix_and_move(_as_column(v), _as_column(accel), keep, mix, _as_column(q), dt)
            q = model.reproject(q)
            ev = model.evaluate(q)
            force = -model.project(ev.gradient, q)
            v = model.project(v, q)
            fmax = model.max_force(force)
            step += 1
            taken += 1
        self.q, self.v, self.force, self.ev = q, v, force, ev
        self.dt, self.alpha, self.npos, self.step, self.fmax = dt, alpha, npos, step, fmax
        return (_fire_kernels.CONVERGED if fmax <= force_tol else _fire_kernels.MAX_STEPS), taken

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        model, ev = self.model, self.ev
        box = model.current_box(self.q)
        return MinimizeResult(
            position=np.array(model.positions(self.q)), box=box, energy=ev.energy,
            pressure=pressure_of(ev, box), max_force=self.fmax, n_contacts=ev.n_contacts, steps=steps,
            converged=status == _fire_kernels.CONVERGED, rebuilds=model.neighbor_builds - self.builds0,
            evaluations=steps + 1, below=status == _fire_kernels.BELOW,
        )


class FireEngine(Protocol):
    """A FIRE run's whole state, advanced in steps (:class:`_ModelFire`, or a model's compiled fast path)."""

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)`` with a status of :mod:`._fire_kernels`.

        ``energy_floor`` > 0 (fixed box) also stops with ``BELOW`` once ``U + K`` is at
        or below it; an engine that cannot test it raises (:func:`no_energy_floor`).
        """
        ...

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        """The run's outcome after ``steps`` steps in ``calls`` calls of :meth:`advance`."""
        ...


def no_energy_floor(engine: FireEngine, energy_floor: float) -> None:
    """Refuse an energy floor in an engine that does not test one (a run with box degrees of freedom)."""
    if energy_floor > 0.0:
        raise NotImplementedError(f"{type(engine).__name__} does not stop on an energy floor")


def _fire(engine: FireEngine, force_tol: float, max_steps: int, energy_floor: float = 0.0) -> MinimizeResult:
    """The one FIRE driver: advance ``engine`` until convergence, the energy floor or the budget, rebuilding lists on request.

    An engine holds the whole FIRE state (positions, velocities, ``dt``, ``alpha``,
    the count of downhill steps) across calls, so a run that stops for a neighbour
    rebuild continues where it stopped.
    """
    steps = 0
    calls = 0
    status = _fire_kernels.MAX_STEPS
    while True:
        status, n = engine.advance(force_tol, max_steps - steps, status == _fire_kernels.REBUILD, energy_floor)
        steps += n
        calls += 1
        if status != _fire_kernels.REBUILD or steps >= max_steps:
            break
    return engine.result(steps, calls, status)


def _fire_engine(model: EnergyModel, q: NDArray[np.float64], params: FireParameters,
                 pressure0: float | None = None, pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> FireEngine:
    """The model's compiled engine when it offers one (:meth:`EnergyModel.fire_engine`), else FIRE on its flat vector."""
    engine = model.fire_engine(q, params, pressure0, pressure_rtol, box_dof)
    if engine is not None:
        return engine
    if pressure0 is not None:
        raise NotImplementedError(f"enthalpy minimisation needs box degrees of freedom, which "
                                  f"{type(model).__name__} does not have")
    return _ModelFire(model, q, params)


def _fire_generic(
    model: EnergyModel, q0: NDArray[np.float64], force_tol: float, max_steps: int, params: FireParameters,
) -> MinimizeResult:
    """FIRE on the flat degree-of-freedom vector of any model, spheres included (see :class:`_ModelFire`)."""
    return _fire(_ModelFire(model, q0, params), force_tol, max_steps)


def minimize_fire(
    model: EnergyModel,
    position: ArrayLike,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    energy_floor: float = 0.0,
) -> MinimizeResult:
    """Minimise a model's energy at fixed box with FIRE 2.0.

    One driver (:func:`_fire`) for every model: soft spheres advance in the compiled
    loop of :mod:`jamflow.models.spheres._kernels`, any other model takes the same steps on its
    flat degree-of-freedom vector (same control kernels: ``_fire_adapt``,
    ``_fire_step_back``, ``_fire_mixing``, ``_mix_and_move``), with masses and
    constraint projections (see :class:`_ModelFire`).

    Parameters
    ----------
    model : EnergyModel
    position : array_like, shape (N, d)
        Initial centres [length].
    force_tol : float
        Stop when the largest per-body (projected) force norm is at most this
        [epsilon / length].
    max_steps : int
        Step budget; ``converged`` is False when it runs out.
    params : FireParameters
        Time steps in units of ``model.time_unit``.
    energy_floor : float
        Stop early (``below``) once the energy ``U + K`` [epsilon] is at or below this
        (0: never); with ``model.energy_floor(P)`` every minimum the run can still reach
        then has a pressure below ``P``. FIRE dissipates: its velocity mixing keeps ``|v|``
        or shrinks it, an uphill step zeroes it, and its symplectic Euler steps conserve
        a nearby energy; so ``U + K`` does not grow beyond that step error, which a caller
        covers by a margin on ``P`` (:data:`jamflow.minimize.onset.VERDICT_SHARE`).
    """
    return _fire(_fire_engine(model, model.dofs(position), params), force_tol, max_steps, energy_floor)


def minimize_enthalpy_model(
    model: EnergyModel,
    position: ArrayLike,
    pressure: float,
    force_tol: float = MINIMIZE_FORCE_TOL,
    pressure_rtol: float = 1e-6,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    box_dof: str = "isotropic",
) -> MinimizeResult:
    """Minimise ``H = U + P0 V`` over a model's degrees of freedom and its box (FIRE 2.0).

    The model's compiled engine runs it (:meth:`EnergyModel.fire_engine` with
    ``pressure0``; the box degrees of freedom are documented at
    :func:`jamflow.models.spheres.model.minimize_enthalpy`). A model without box
    degrees of freedom (``model.box_dofs`` false) raises ``NotImplementedError``.
    """
    if not pressure > 0.0:
        raise ValueError(f"target pressure must be positive, got {pressure}")
    if box_dof not in ("isotropic", "full"):
        raise ValueError(f"box_dof must be 'isotropic' or 'full', got {box_dof!r}")
    engine = _fire_engine(model, model.dofs(position), params, float(pressure), pressure_rtol, box_dof)
    return _fire(engine, force_tol, max_steps)
