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
from ..tolerances import MINIMIZE_FORCE_TOL
from . import _kernels
from .potential import HARMONIC, NeighborList, PowerLawPotential, evaluate

__all__ = [
    "DEFAULT_FIRE",
    "DescentResult",
    "FireParameters",
    "MinimizeResult",
    "conjugate_gradient",
    "fire",
    "minimize_enthalpy",
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


def _fire_params(params: FireParameters, unit: float) -> NDArray[np.float64]:
    return np.array([params.dt_max * unit, params.dt_min * unit, params.f_inc, params.f_dec,
                     params.alpha0, params.f_alpha, params.n_delay, float(params.initial_delay)])


def _run_fire(
    x: NDArray[np.float64], box: Box, diameter: NDArray[np.float64], potential: PowerLawPotential,
    force_tol: float, max_steps: int, params: FireParameters, nlist: NeighborList | None,
    pressure0: float | None, pressure_rtol: float,
) -> MinimizeResult:
    d = box.d
    diameter = np.asarray(diameter, dtype=np.float64)
    if nlist is None:
        nlist = NeighborList(diameter)
    builds0 = nlist.builds
    unit = float(diameter.mean()) / np.sqrt(potential.epsilon)
    barostat = pressure0 is not None
    h_ref = box
    y = np.array(x, dtype=np.float64)
    v = np.zeros_like(y)
    q_scale = float(np.sqrt(len(y)) * diameter.mean())
    box_state = np.array([0.0, 0.0, 1.0])
    fire_state = np.array([params.dt * unit, params.alpha0, 0.0])
    fparams = _fire_params(params, unit)
    force = np.zeros_like(y)
    virial = np.zeros((d, d))
    steps = 0
    status = _kernels.MAX_STEPS
    while True:
        s = box_state[2]
        current = h_ref.scaled(s)
        if status == _kernels.REBUILD:
            nlist.build(s * y, current)
        else:
            nlist.update(s * y, current)
        affine, slack = nlist.affine_reference(current)
        status, n, energy, n_contacts, fmax2, pressure = _kernels.fire(
            y, v, box_state, fire_state, fparams,
            nlist.image @ h_ref.matrix.T, nlist.i, nlist.j, nlist.sigma,
            potential.epsilon, potential.exponent,
            affine / s, s, nlist.reach, nlist.skin, slack,
            barostat, 0.0 if pressure0 is None else float(pressure0), h_ref.volume, q_scale,
            float(force_tol), float(pressure_rtol), int(max_steps - steps), force, virial,
        )
        steps += n
        if status != _kernels.REBUILD or steps >= max_steps:
            break
    s = box_state[2]
    return MinimizeResult(
        position=s * y, box=h_ref.scaled(s) if barostat else box, energy=float(energy),
        pressure=float(pressure), max_force=float(np.sqrt(fmax2)), n_contacts=int(n_contacts),
        steps=steps, converged=status == _kernels.CONVERGED, rebuilds=nlist.builds - builds0,
    )


def _run_fire_full(
    x: NDArray[np.float64], box: Box, diameter: NDArray[np.float64], potential: PowerLawPotential,
    force_tol: float, max_steps: int, params: FireParameters, nlist: NeighborList | None,
    pressure0: float, stress_rtol: float,
) -> MinimizeResult:
    d = box.d
    if nlist is None:
        nlist = NeighborList(diameter)
    builds0 = nlist.builds
    unit = float(diameter.mean()) / np.sqrt(potential.epsilon)
    h_ref = box
    y = np.array(x, dtype=np.float64)
    v = np.zeros_like(y)
    A = np.eye(d)
    vA = np.zeros((d, d))
    q_scale = float(np.sqrt(len(y)) * diameter.mean())
    fire_state = np.array([params.dt * unit, params.alpha0, 0.0])
    fparams = _fire_params(params, unit)
    force = np.zeros_like(y)
    virial = np.zeros((d, d))
    steps = 0
    status = _kernels.MAX_STEPS
    while True:
        current = Box(A @ h_ref.matrix)
        if status == _kernels.REBUILD:
            nlist.build(y @ A.T, current)
        else:
            nlist.update(y @ A.T, current)
        offset = nlist.image @ h_ref.matrix.T
        affine, slack = nlist.affine_reference(current)
        A_inv = np.linalg.inv(A)
        status, n, energy, n_contacts, fmax2, _ = _kernels.fire_stress(
            y, v, A, vA, fire_state, fparams, offset, nlist.i, nlist.j, nlist.sigma,
            potential.epsilon, potential.exponent, affine @ A_inv.T, A_inv, nlist.reach, nlist.skin,
            slack, pressure0, h_ref.volume, q_scale, float(force_tol), float(stress_rtol),
            int(max_steps - steps), force, virial,
        )
        steps += n
        if status != _kernels.REBUILD or steps >= max_steps:
            break
    final = Box(np.triu(A) @ h_ref.matrix)
    return MinimizeResult(
        position=y @ A.T, box=final, energy=float(energy),
        pressure=float(np.trace(virial) / (d * final.volume)), max_force=float(np.sqrt(fmax2)),
        n_contacts=int(n_contacts), steps=steps, converged=status == _kernels.CONVERGED,
        rebuilds=nlist.builds - builds0,
    )


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
    """Minimise the energy at fixed box with FIRE 2.0.

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
        Reused between calls (rebuilt only when stale).
    """
    return _run_fire(np.asarray(x, dtype=np.float64), box, np.asarray(diameter, dtype=np.float64),
                     potential, force_tol, max_steps, params, nlist, None, 0.0)


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
    if not pressure > 0.0:
        raise ValueError(f"target pressure must be positive, got {pressure}")
    if box_dof == "full":
        return _run_fire_full(np.asarray(x, dtype=np.float64), box, np.asarray(diameter, dtype=np.float64),
                              potential, force_tol, max_steps, params, nlist, float(pressure), pressure_rtol)
    if box_dof != "isotropic":
        raise ValueError(f"box_dof must be 'isotropic' or 'full', got {box_dof!r}")
    return _run_fire(np.asarray(x, dtype=np.float64), box, np.asarray(diameter, dtype=np.float64),
                     potential, force_tol, max_steps, params, nlist, float(pressure), pressure_rtol)


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
        if status != _kernels.REBUILD or steps >= max_steps:
            break
    if traces:
        energies = np.concatenate(traces)
    pressure = float(np.trace(virial) / (box.d * box.volume))
    res = MinimizeResult(y, box, float(energy), pressure, float(np.sqrt(fmax2)), int(n_contacts),
                         steps, status == _kernels.CONVERGED, nlist.builds - builds0)
    return DescentResult(res, energies if record else np.empty(0))


def conjugate_gradient(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 100_000,
    nlist: NeighborList | None = None,
) -> MinimizeResult:
    """Polak–Ribière conjugate gradient (``scipy.optimize.minimize(method="CG")``).

    scipy stops on the largest gradient *component*; the run is continued with FIRE
    if the per-particle norm criterion ``max_i |F_i| <= force_tol`` is not yet met.
    CG's line searches make it an independent check of FIRE's minimum.
    """
    x0 = np.array(x, dtype=np.float64)
    diameter = np.asarray(diameter, dtype=np.float64)
    if nlist is None:
        nlist = NeighborList(diameter)
    builds0 = nlist.builds
    shape = x0.shape
    count = [0]

    def fun(flat: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        count[0] += 1
        ev = evaluate(flat.reshape(shape), box, diameter, potential, nlist)
        return ev.energy, -ev.force.ravel()

    out = _scipy_minimize(fun, x0.ravel(), jac=True, method="CG",
                          options={"gtol": force_tol / np.sqrt(box.d), "maxiter": max_steps})
    xf = out.x.reshape(shape)
    ev = evaluate(xf, box, diameter, potential, nlist)
    if ev.max_force > force_tol:
        polished = fire(xf, box, diameter, potential, force_tol, max_steps, nlist=nlist)
        return MinimizeResult(polished.position, box, polished.energy, polished.pressure,
                              polished.max_force, polished.n_contacts, count[0] + polished.steps,
                              polished.converged, nlist.builds - builds0)
    return MinimizeResult(xf, box, ev.energy, ev.pressure, ev.max_force, ev.n_contacts, count[0],
                          True, nlist.builds - builds0)
