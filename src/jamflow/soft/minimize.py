"""Energy and enthalpy minimisers for soft spheres: FIRE, steepest descent, CG.

Units: masses are 1; time steps are given in units of ``<D> sqrt(m / epsilon)`` with
``<D>`` the mean diameter, so the same defaults work whatever the length unit of
the packing. Force tolerances are absolute, in ``epsilon / length`` of the packing;
convergence means that the largest per-particle force norm ``max_i |F_i|`` is at
most ``force_tol``. The criterion of VanderWerf et al. (Sec. II), squared forces per
particle below 1e-25 in units of the spring constant, is ``force_tol = 10**-12.5``
for a packing whose mean diameter is 1; the jamming stage uses 1e-13 (see
:mod:`jamflow.soft.jamming`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize as _scipy_minimize

from ..box import Box
from ..models.base import EnergyModel, pressure_of
from ..models.spheres import SphereModel
from ..tolerances import MINIMIZE_FORCE_TOL
from . import _kernels
from .potential import HARMONIC, NeighborList, PowerLawPotential

__all__ = [
    "DEFAULT_FIRE",
    "METHODS",
    "SD_STEP",
    "DescentResult",
    "FireParameters",
    "MinimizeResult",
    "conjugate_gradient",
    "fire",
    "minimize",
    "minimize_cg",
    "minimize_enthalpy",
    "minimize_enthalpy_model",
    "minimize_fire",
    "minimize_sd",
    "steepest_descent",
]


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

#: Sphere FIRE runs of at least this many spheres work on them sorted by cell (as
#: LAMMPS's ``atom_modify sort``) and return them in the caller's order: the pair and
#: particle arrays are then walked nearly in memory order (2D N = 16384: about 4 % less
#: time per force evaluation; 3D N = 4096: no measurable change; docs/energy-models.md).
#: The order is fixed for the run, taken from the start (a minimisation moves spheres little), so a
#: run stays deterministic and independent of the skin; its sums differ from the
#: caller-order run's by round-off. Smaller systems fit the cache and keep the
#: caller's order, and their paths.
SPATIAL_SORT_MIN_N: int = 4096


def _cell_order(x: NDArray[np.float64], box: Box, size: float) -> NDArray[np.int64]:
    """Particles ordered by cell (cells at least ``size`` wide, last axis fastest; by index within a cell), shape (N,)."""
    from .._cell_kernels import cell_index, sort_by_cell

    frac = box.to_fractional(x)
    frac -= np.floor(frac)
    ncell = np.maximum((box.widths // size).astype(np.int64), 1)
    _, order = sort_by_cell(cell_index(frac, np.ones(box.d), ncell), int(np.prod(ncell)))
    return order


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


def _fire_params(params: FireParameters, unit: float) -> NDArray[np.float64]:
    return np.array([params.dt_max * unit, params.dt_min * unit, params.f_inc, params.f_dec,
                     params.alpha0, params.f_alpha, params.n_delay, float(params.initial_delay)])


class _SphereFire:
    """FIRE steps of soft spheres in the compiled loop (:func:`jamflow.soft._kernels.fire`).

    Fixed box, or an isotropic barostat (``pressure0``). Runs until convergence, the
    step budget or a neighbour-list rebuild; the state persists across calls.
    """

    def __init__(self, model: SphereModel, x: NDArray[np.float64], params: FireParameters,
                 pressure0: float | None, pressure_rtol: float) -> None:
        self.model = model
        # large systems run sorted by cell, on a list of their own (SPATIAL_SORT_MIN_N)
        self.order = (_cell_order(x, model.box, float(model.diameter.max())) if len(x) >= SPATIAL_SORT_MIN_N
                      else None)
        if self.order is None:
            self.nlist = model.nlist
        else:
            skin = model.nlist.requested_skin
            self.nlist = NeighborList(model.diameter[self.order], None if np.isnan(skin) else skin)
            x = x[self.order]
        self.builds0 = self.nlist.builds
        unit = model.time_unit
        self.barostat = pressure0 is not None
        self.pressure0 = 0.0 if pressure0 is None else float(pressure0)
        self.pressure_rtol = float(pressure_rtol)
        self.y = np.array(x, dtype=np.float64)
        self.v = np.zeros_like(self.y)
        self.q_scale = float(np.sqrt(len(self.y)) * model.diameter.mean())
        self.box_state = np.array([0.0, 0.0, 1.0])
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((model.box.d, model.box.d))
        # an orthogonal box lets the compiled loop rebuild the list itself
        self.lengths = np.diag(model.box.matrix).copy() if model.box.is_orthogonal else np.empty(0)
        self.inline_builds = 0

    def advance(self, force_tol: float, budget: int, rebuild: bool) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)`` (status of :mod:`._kernels`)."""
        nlist, potential, h_ref = self.nlist, self.model.potential, self.model.box
        s = self.box_state[2]
        # the reference box itself at s = 1 (fixed box): its cached widths serve every build
        current = h_ref if s == 1.0 else h_ref.scaled(s)
        if rebuild:
            nlist.build(s * self.y, current)
        else:
            nlist.update(s * self.y, current)
        affine, slack = nlist.affine_reference(current)
        status, n, *self.last, builds, i, j, image, y_build, s_build = _kernels.fire(
            self.y, self.v, self.box_state, self.fire_state, self.fparams,
            nlist.image @ h_ref.matrix.T, nlist.i, nlist.j, nlist.sigma,
            potential.epsilon, potential.exponent,
            affine / s, s, nlist.reach, nlist.skin, slack,
            self.barostat, self.pressure0, h_ref.volume, self.q_scale,
            float(force_tol), self.pressure_rtol, int(budget), self.force, self.virial,
            self.lengths, nlist.diameter,
        )
        if builds:
            nlist.adopt(i, j, image.astype(np.float64), s_build * y_build, h_ref.scaled(s_build), builds)
            self.inline_builds += builds
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        energy, n_contacts, fmax2, pressure = self.last
        s = self.box_state[2]
        box = self.model.box
        position = s * self.y
        if self.order is not None:
            position[self.order] = position.copy()
        return MinimizeResult(
            position=position, box=box.scaled(s) if self.barostat else box, energy=float(energy),
            pressure=float(pressure), max_force=float(np.sqrt(fmax2)), n_contacts=int(n_contacts),
            steps=steps, converged=status == _kernels.CONVERGED, rebuilds=self.nlist.builds - self.builds0,
            evaluations=steps + calls + self.inline_builds,
        )


class _SphereFireFullBox:
    """FIRE steps of soft spheres with the whole upper-triangular box free (:func:`._kernels.fire_stress`)."""

    def __init__(self, model: SphereModel, x: NDArray[np.float64], params: FireParameters,
                 pressure0: float, stress_rtol: float) -> None:
        d = model.box.d
        self.model = model
        self.builds0 = model.nlist.builds
        unit = model.time_unit
        self.pressure0, self.stress_rtol = float(pressure0), float(stress_rtol)
        self.y = np.array(x, dtype=np.float64)
        self.v = np.zeros_like(self.y)
        self.A = np.eye(d)
        self.vA = np.zeros((d, d))
        self.q_scale = float(np.sqrt(len(self.y)) * model.diameter.mean())
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((d, d))

    def advance(self, force_tol: float, budget: int, rebuild: bool) -> tuple[int, int]:
        nlist, potential, h_ref = self.model.nlist, self.model.potential, self.model.box
        A = self.A
        current = Box(A @ h_ref.matrix)
        if rebuild:
            nlist.build(self.y @ A.T, current)
        else:
            nlist.update(self.y @ A.T, current)
        offset = nlist.image @ h_ref.matrix.T
        affine, slack = nlist.affine_reference(current)
        A_inv = np.linalg.inv(A)
        status, n, *self.last = _kernels.fire_stress(
            self.y, self.v, A, self.vA, self.fire_state, self.fparams, offset, nlist.i, nlist.j, nlist.sigma,
            potential.epsilon, potential.exponent, affine @ A_inv.T, A_inv, nlist.reach, nlist.skin,
            slack, self.pressure0, h_ref.volume, self.q_scale, float(force_tol), self.stress_rtol,
            int(budget), self.force, self.virial,
        )
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        energy, n_contacts, fmax2, _ = self.last
        d = self.model.box.d
        final = Box(np.triu(self.A) @ self.model.box.matrix)
        return MinimizeResult(
            position=self.y @ self.A.T, box=final, energy=float(energy),
            pressure=float(np.trace(self.virial) / (d * final.volume)), max_force=float(np.sqrt(fmax2)),
            n_contacts=int(n_contacts), steps=steps, converged=status == _kernels.CONVERGED,
            rebuilds=self.model.nlist.builds - self.builds0, evaluations=steps + calls,
        )


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

    def advance(self, force_tol: float, budget: int, rebuild: bool) -> tuple[int, int]:
        model, params = self.model, self.params
        q, v, force, inv_mass, mass = self.q, self.v, self.force, self.inv_mass, self.mass
        dt, alpha, npos, step, fmax = self.dt, self.alpha, self.npos, self.step, self.fmax
        ev = self.ev
        taken = 0
        while taken < budget and fmax > force_tol:
            power = float(force @ v)
            npos, dt, alpha = _kernels._fire_adapt(
                power, step, npos, dt, alpha, params.n_delay, params.f_inc, params.f_dec, params.f_alpha,
                params.alpha0, self.dt_max, self.dt_min, params.initial_delay,
            )
            if not power > 0.0:
                _kernels._fire_step_back(_as_column(q), _as_column(v), dt)
                q = model.reproject(q)
            accel = inv_mass * force
            _kernels._axpy(dt, _as_column(accel), _as_column(v))
            vnorm = float(np.sqrt(np.sum(mass * v * v)))
            fnorm = float(np.sqrt(force @ accel))
            keep, mix = _kernels._fire_mixing(alpha, vnorm, fnorm)
            _kernels._mix_and_move(_as_column(v), _as_column(accel), keep, mix, _as_column(q), dt)
            q = model.reproject(q)
            ev = model.evaluate(q)
            force = -model.project(ev.gradient, q)
            v = model.project(v, q)
            fmax = model.max_force(force)
            step += 1
            taken += 1
        self.q, self.v, self.force, self.ev = q, v, force, ev
        self.dt, self.alpha, self.npos, self.step, self.fmax = dt, alpha, npos, step, fmax
        return (_kernels.CONVERGED if fmax <= force_tol else _kernels.MAX_STEPS), taken

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        model, ev = self.model, self.ev
        return MinimizeResult(
            position=np.array(model.positions(self.q)), box=model.box, energy=ev.energy,
            pressure=pressure_of(ev, model.box), max_force=self.fmax, n_contacts=ev.n_contacts, steps=steps,
            converged=status == _kernels.CONVERGED, rebuilds=model.neighbor_builds - self.builds0,
            evaluations=steps + 1,
        )


def _fire(engine: _SphereFire | _SphereFireFullBox | _ModelFire, force_tol: float, max_steps: int) -> MinimizeResult:
    """The one FIRE driver: advance ``engine`` until convergence or the budget, rebuilding lists on request.

    An engine holds the whole FIRE state (positions, velocities, ``dt``, ``alpha``,
    the count of downhill steps) across calls, so a run that stops for a neighbour
    rebuild continues where it stopped.
    """
    steps = 0
    calls = 0
    status = _kernels.MAX_STEPS
    while True:
        status, n = engine.advance(force_tol, max_steps - steps, status == _kernels.REBUILD)
        steps += n
        calls += 1
        if status != _kernels.REBUILD or steps >= max_steps:
            break
    return engine.result(steps, calls, status)


def _fire_engine(model: EnergyModel, q: NDArray[np.float64], params: FireParameters,
                 pressure0: float | None = None, pressure_rtol: float = 0.0, box_dof: str = "isotropic"):
    """The FIRE engine of a model: the compiled loops for soft spheres, the flat-vector steps otherwise."""
    if isinstance(model, SphereModel):
        x = model.positions(q)
        if box_dof == "full":
            return _SphereFireFullBox(model, x, params, pressure0, pressure_rtol)
        return _SphereFire(model, x, params, pressure0, pressure_rtol)
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
) -> MinimizeResult:
    """Minimise a model's energy at fixed box with FIRE 2.0.

    One driver (:func:`_fire`) for every model: soft spheres advance in the compiled
    loop of :mod:`jamflow.soft._kernels`, any other model takes the same steps on its
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
    """
    return _fire(_fire_engine(model, model.dofs(position), params), force_tol, max_steps)


def fire(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    nlist: NeighborList | None = None,
) -> MinimizeResult:
    """Minimise the energy of soft spheres at fixed box with FIRE 2.0.

    Parameters
    ----------
    x : array_like, shape (N, d)
        Initial centres [length].
    box : Box
        Fixed periodic (possibly sheared) box.
    diameter : array_like, shape (N,)
    potential : PowerLawPotential
    force_tol : float
        Stop when ``max_i |F_i| <= force_tol`` [epsilon / length].
    max_steps : int
        Step budget; ``converged`` is False when it runs out.
    params : FireParameters
    nlist : NeighborList, optional
        Reused between calls (rebuilt only when stale); from :data:`SPATIAL_SORT_MIN_N`
        spheres on only its skin is used (the run keeps a list in cell order).
    """
    return minimize_fire(SphereModel(box, diameter, potential, nlist), x, force_tol, max_steps, params)


def minimize_enthalpy(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    pressure: float,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    pressure_rtol: float = 1e-6,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    nlist: NeighborList | None = None,
    box_dof: str = "isotropic",
) -> MinimizeResult:
    """Minimise ``H = U + P0 V`` over centres and the box (FIRE 2.0).

    ``box_dof = "isotropic"``:

    The box is ``s h`` with ``s = exp(q / q_s)``, ``q_s = sqrt(N) <D>``, and centres
    ``s y``; ``q`` is one more FIRE degree of freedom with generalised force
    ``-dH/dq = d V (P - P0) / q_s`` (``P`` the virial pressure), so at a minimum the
    virial pressure equals ``P0``. The choice of ``q_s`` gives the box mode a
    stiffness of the order of a particle's.

    ``box_dof = "full"``: the whole upper-triangular box ``A h`` is free (``d (d+1)/2``
    degrees of freedom ``q_s A_ab``, centres ``A y``), with generalised forces
    ``(W - P0 V 1) A^-T / q_s``, ``W = sum f R R^T / r``. At the minimum the stress
    tensor is ``-P0 1`` (no residual shear stress); ``pressure_rtol`` then bounds
    ``max_ab |W_ab / V - P0 delta_ab| / P0``.

    Parameters
    ----------
    pressure : float
        Target pressure ``P0`` [epsilon / length^d], > 0.
    pressure_rtol : float
        Converged also requires ``|P - P0| <= pressure_rtol * P0`` (isotropic) or the
        stress-tensor bound above (full).
    box_dof : {"isotropic", "full"}
    Other parameters as in :func:`fire`.
    """
    return minimize_enthalpy_model(SphereModel(box, diameter, potential, nlist), x, pressure, force_tol,
                                   pressure_rtol, max_steps, params, box_dof)


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
    """:func:`minimize_enthalpy` for a model (box degrees of freedom as documented there).

    Only soft spheres have box degrees of freedom so far: any other model raises
    ``NotImplementedError``, since scaling a box with links or shapes needs the
    model's strain degrees of freedom (shear stabilisation, chains paper Sec. II D).
    """
    if not pressure > 0.0:
        raise ValueError(f"target pressure must be positive, got {pressure}")
    if box_dof not in ("isotropic", "full"):
        raise ValueError(f"box_dof must be 'isotropic' or 'full', got {box_dof!r}")
    if not isinstance(model, SphereModel):
        raise NotImplementedError(f"enthalpy minimisation needs box degrees of freedom, which "
                                  f"{type(model).__name__} does not have yet")
    engine = _fire_engine(model, model.dofs(position), params, float(pressure), pressure_rtol, box_dof)
    return _fire(engine, force_tol, max_steps)


@dataclass(frozen=True)
class DescentResult:
    """:class:`MinimizeResult` of steepest descent plus the energy trace (if recorded)."""

    result: MinimizeResult
    energies: NDArray[np.float64]


def steepest_descent(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    dt: float = 0.1,
    force_tol: float = 1e-9,
    max_steps: int = 10_000_000,
    nlist: NeighborList | None = None,
    record: int = 0,
) -> DescentResult:
    """Overdamped relaxation ``dx/dt = -xi_0 grad U`` with a fixed Euler step.

    Lerner, During & Wyart Eq. 31 with ``xi_0 = 1``: ``x += dt F``. Stable for ``dt``
    below ``2 / lambda_max`` of the Hessian (``dt = 0.1`` in units of
    ``sigma^2 / (xi_0 epsilon)`` for the harmonic potential of unit diameters).

    Parameters
    ----------
    dt : float
        Step [time, in units of length^2 / (xi_0 epsilon)]; used as given (no scaling).
    force_tol : float
        Stop when ``max_i |grad_i U| <= force_tol`` [epsilon / length].
    record : int
        Number of leading steps whose energy is recorded (0: none).
    """
    y = np.array(x, dtype=np.float64)
    diameter = np.asarray(diameter, dtype=np.float64)
    if nlist is None:
        nlist = NeighborList(diameter)
    builds0 = nlist.builds
    force = np.zeros_like(y)
    virial = np.zeros((box.d, box.d))
    energies = np.full(max(record, 1), np.nan)
    traces = []
    steps = 0
    calls = 0
    status = _kernels.MAX_STEPS
    while True:
        if status == _kernels.REBUILD:
            nlist.build(y, box)
        else:
            nlist.update(y, box)
        affine, slack = nlist.affine_reference(box)
        buf = np.full(max(record - steps, 1), np.nan)
        status, n, energy, n_contacts, fmax2 = _kernels.steepest_descent(
            y, nlist.offsets(box), nlist.i, nlist.j, nlist.sigma,
            potential.epsilon, potential.exponent, affine, nlist.reach, nlist.skin, slack,
            float(dt), float(force_tol), int(max_steps - steps), force, virial, buf,
        )
        if record > steps:
            traces.append(buf[: min(n + 1, record - steps)] if status != _kernels.REBUILD else buf[:n])
        steps += n
        calls += 1
        if status != _kernels.REBUILD or steps >= max_steps:
            break
    if traces:
        energies = np.concatenate(traces)
    pressure = float(np.trace(virial) / (box.d * box.volume))
    res = MinimizeResult(y, box, float(energy), pressure, float(np.sqrt(fmax2)), int(n_contacts),
                         steps, status == _kernels.CONVERGED, nlist.builds - builds0, steps + calls)
    return DescentResult(res, energies if record else np.empty(0))


def minimize_sd(
    model: EnergyModel,
    position: ArrayLike,
    dt: float = 0.1,
    force_tol: float = 1e-9,
    max_steps: int = 10_000_000,
) -> MinimizeResult:
    """Overdamped relaxation ``dq/dt = -M^-1 P grad U`` of any model with a fixed Euler step.

    Soft spheres run the compiled loop of :func:`steepest_descent`; other models take
    the step on their flat degrees of freedom, with the gradient projected onto the
    constraints (``P``) and the positions re-affixed after every step. ``dt`` as in
    :func:`steepest_descent` (used as given); stops when the largest per-body
    projected gradient norm is at most ``force_tol``.
    """
    q = model.dofs(position)
    if isinstance(model, SphereModel):
        return steepest_descent(model.positions(q), model.box, model.diameter, model.potential, dt,
                                force_tol, max_steps, model.nlist).result
    builds0 = model.neighbor_builds
    q = model.reproject(q)
    ev = model.evaluate(q)
    force = -model.project(ev.gradient, q)
    fmax = model.max_force(force)
    step = 0
    while step < max_steps and fmax > force_tol:
        q = model.reproject(q + dt * model.inverse_mass * force)
        ev = model.evaluate(q)
        force = -model.project(ev.gradient, q)
        fmax = model.max_force(force)
        step += 1
    return MinimizeResult(np.array(model.positions(q)), model.box, ev.energy, pressure_of(ev, model.box), fmax,
                          ev.n_contacts, step, fmax <= force_tol, model.neighbor_builds - builds0, step + 1)


def conjugate_gradient(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 100_000,
    nlist: NeighborList | None = None,
) -> MinimizeResult:
    """:func:`minimize_cg` of soft spheres."""
    return minimize_cg(SphereModel(box, diameter, potential, nlist), x, force_tol, max_steps)


def minimize_cg(
    model: EnergyModel,
    position: ArrayLike,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 100_000,
) -> MinimizeResult:
    """Polak–Ribière conjugate gradient (``scipy.optimize.minimize(method="CG")``).

    scipy stops on the largest gradient *component*; the run is continued with FIRE
    if the per-body norm criterion (largest force norm <= ``force_tol``) is not yet
    met. CG's line searches make it an independent check of FIRE's minimum. With
    constraints CG minimises ``U(R(q))``, ``R`` the re-affixing onto the constraint
    manifold, whose gradient on the manifold is the projected gradient ``P grad U``.
    """
    x0 = model.reproject(model.dofs(position))
    builds0 = model.neighbor_builds
    count = [0]

    def fun(flat: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        count[0] += 1
        q = model.reproject(flat)
        ev = model.evaluate(q)
        return ev.energy, model.project(ev.gradient, q)

    out = _scipy_minimize(fun, x0, jac=True, method="CG",
                          options={"gtol": force_tol / np.sqrt(model.box.d), "maxiter": max_steps})
    qf = model.reproject(out.x)
    ev = model.evaluate(qf)
    fmax = model.max_force(model.project(ev.gradient, qf))
    if fmax > force_tol:
        polished = minimize_fire(model, model.positions(qf), force_tol, max_steps)
        return MinimizeResult(polished.position, model.box, polished.energy, polished.pressure,
                              polished.max_force, polished.n_contacts, count[0] + polished.steps,
                              polished.converged, model.neighbor_builds - builds0,
                              count[0] + 1 + polished.evaluations)
    return MinimizeResult(model.positions(qf), model.box, ev.energy, pressure_of(ev, model.box), fmax,
                          ev.n_contacts, count[0], True, model.neighbor_builds - builds0, count[0] + 1)


#: Minimisers of :func:`minimize` by name.
METHODS = ("fire", "cg", "sd")

#: Steepest-descent step of :func:`minimize` in units of ``<D>^2 / (xi_0 epsilon)``
#: (the time unit squared at unit mass): below ``2 / lambda_max ~ 1 / (2 d)`` of the
#: harmonic Hessian with unit mean diameter, as :func:`steepest_descent`'s default.
SD_STEP: float = 0.1


def minimize(
    model: EnergyModel,
    position: ArrayLike,
    method: str = "fire",
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 1_000_000,
) -> MinimizeResult:
    """Minimise a model's energy at fixed box with ``method`` in :data:`METHODS`.

    ``"fire"``: :func:`minimize_fire` (default parameters); ``"cg"``:
    :func:`minimize_cg`; ``"sd"``: :func:`minimize_sd` with the step
    :data:`SD_STEP` ``model.time_unit^2`` (``0.1 <D>^2 / (xi_0 epsilon)``).
    """
    if method == "fire":
        return minimize_fire(model, position, force_tol, max_steps)
    if method == "cg":
        return minimize_cg(model, position, force_tol, max_steps)
    if method == "sd":
        return minimize_sd(model, position, SD_STEP * model.time_unit**2, force_tol, max_steps)
    raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
