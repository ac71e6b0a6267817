"""The instantaneous contact network: the operator S, N = S S^T, forces and velocities.

Lerner, Düring & Wyart, Sec. II. For contacts ``c = (i, j)`` with separation
``R_c = x_j - x_i`` (the periodic image fixed by an integer lattice vector ``m_c``,
``R_c = x_j - x_i + h m_c``) and unit vector ``n_c``, ``S`` maps particle velocities
(length ``N d``) to the rates of change of contact distances (Eq. 1–3):
``(S V)_c = n_c . (V_j - V_i)``. Contact forces act on particles through ``S^T``
(Eq. 8).

With an imposed velocity-gradient tensor ``E`` (affine field ``V_aff = E x``) and
external forces ``F_ext``, overdamped force balance with drag ``-(V - V_aff)/xi0``
(Eqs. 5, 14) and rigid contacts ``S V = 0`` (Eq. 4) give

    N f = -(S V_aff / xi0 + S F_ext)              (Eqs. 11, 18)
    V   = V_aff + xi0 (F_ext + S^T f)             (Eqs. 9, 16)

which reduce to Eqs. 11–12 (forces only) and 18–19 (deformation only). Units: xi0 = 1
and rate 1 unless given; lengths in units of lambda.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..._numba import njit
from ...box import lattice_volume
from .solver import (
    COND_LIMIT,
    FactorCache,
    _s_apply,
    _st_apply,
    solve_contact_system,
)

# FactorCache and s_matrix live in .solver, SingularNetworkError and TriangularFactor in .ldl;
# they are part of this module's API (solve_network takes and raises them)
__all__ = [
    "Solution",
    "advance_box",
    "advance_positions",
    "affine_rates",
    "has_negative",
    "max_relative_error",
    "max_relative_rate",
    "max_row_norm",
    "pair_normals",
    "pair_vectors",
    "pair_velocities",
    "solve_network",
    "spectral_norm",
    "stress_tensor",
    "tangent_velocities",
]


def pair_vectors(
    x: NDArray[np.float64], h: NDArray[np.float64], pairs: NDArray[np.int64], images: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Separations ``x_j - x_i + h m`` of pairs with fixed periodic images.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Particle centres [lambda] (not necessarily wrapped).
    h : ndarray, shape (d, d)
        Box lattice matrix (columns = lattice vectors) [lambda].
    pairs : ndarray of int64, shape (P, 2)
        Pairs ``(i, j)``.
    images : ndarray, shape (P, d)
        Lattice vector ``m`` of the image of j seen from i (integer-valued; integer
        arrays are converted exactly).

    Returns
    -------
    ndarray, shape (P, d)
    """
    return _pair_vectors(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(h, dtype=np.float64),
                         np.ascontiguousarray(pairs, dtype=np.int64), np.ascontiguousarray(images, dtype=np.float64))


@njit(cache=True)
def _pair_vectors(x, h, pairs, images):  # pragma: no cover - numba
    npairs = pairs.shape[0]
    d = x.shape[1]
    out = np.empty((npairs, d))
    for c in range(npairs):
        i, j = np.uint64(pairs[c, 0]), np.uint64(pairs[c, 1])  # unsigned: no wraparound test per access
        for k in range(d):
            shift = 0.0
            for m in range(d):
                shift += images[c, m] * h[k, m]
            out[c, k] = x[j, k] - x[i, k] + shift
    return out


def _pressure_forces(sols, r, load):
    """``(kappa, f, gain)`` of fixed-pressure shear from ``N a = -S V_aff / xi0`` and ``N b = rate r / xi0``.

    ``kappa`` makes the contact virial ``f . r`` equal ``load = p Omega d`` (Eq. 25);
    ``f = a + kappa b``; ``gain = max(|a|, |kappa b|) / |f|`` is the factor by which
    errors of a and b grow in f through cancellation.
    """
    a, b = sols
    kappa = float((load - a @ r) / (b @ r))
    f = a + kappa * b
    size = max(float(np.max(np.abs(a))), abs(kappa) * float(np.max(np.abs(b))))
    return kappa, f, size / max(float(np.max(np.abs(f))), np.finfo(np.float64).tiny)


def pair_normals(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit vectors ``n_ij = r_ij / |r_ij|`` of separations R, shape (P, d) (the rows of S)."""
    return R / np.linalg.norm(R, axis=1)[:, None]


def advance_positions(
    x: NDArray[np.float64], velocity: NDArray[np.float64], gradient: NDArray[np.float64], t: float
) -> NDArray[np.float64]:
    """Positions after a straight-line move of duration t: ``x + t (E x + U)``, shape (N, d) (a new array)."""
    return _advance_positions(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(velocity, dtype=np.float64),
                              np.ascontiguousarray(gradient, dtype=np.float64), float(t))


@njit(cache=True)
def _advance_positions(x, U, E, t):  # pragma: no cover - numba
    n, d = x.shape
    out = np.empty((n, d))
    for i in range(n):
        for k in range(d):
            v = 0.0
            for m in range(d):
                v += x[i, m] * E[k, m]
            out[i, k] = x[i, k] + t * (v + U[i, k])
    return out


def advance_box(h: NDArray[np.float64], gradient: NDArray[np.float64], t: float) -> NDArray[np.float64]:
    """Box after a move of duration t, ``h + t E h`` with its lower triangle set to zero (a new array).

    The Lees–Edwards Euler update must keep h upper triangular exactly.
    """
    return _advance_box(np.ascontiguousarray(h, dtype=np.float64), np.ascontiguousarray(gradient, dtype=np.float64),
                        float(t))


@njit(cache=True)
def _advance_box(h, E, t):  # pragma: no cover - numba
    d = h.shape[0]
    out = np.zeros((d, d))
    for a in range(d):
        for b in range(a, d):
            s = 0.0
            for m in range(d):
                s += E[a, m] * h[m, b]
            out[a, b] = h[a, b] + t * s
    return out


def has_negative(force: NDArray[np.float64], free: NDArray[np.bool_], rel_tol: float) -> bool:
    """Whether a free entry of ``force`` is below ``-rel_tol max |force|`` (all entries count in the max)."""
    return bool(_has_negative(np.ascontiguousarray(force, dtype=np.float64), np.ascontiguousarray(free), float(rel_tol)))


@njit(cache=True)
def _has_negative(f, free, rel_tol):  # pragma: no cover - numba
    top = 0.0
    for c in range(f.shape[0]):
        v = abs(f[c])
        if v > top or v != v:  # NaN propagates, as in numpy's max
            top = v
    for c in range(f.shape[0]):
        if free[c] and f[c] < -rel_tol * top:
            return True
    return False


def max_relative_error(R: NDArray[np.float64], sigma: NDArray[np.float64]) -> float:
    """Largest ``|r_c - sigma_c| / sigma_c`` over pairs with separations R, shape (P, d) (0 when empty)."""
    return _max_relative_error(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(sigma, dtype=np.float64))


@njit(cache=True)
def _max_relative_error(R, sigma):  # pragma: no cover - numba
    top = 0.0
    for c in range(R.shape[0]):
        rr = 0.0
        for k in range(R.shape[1]):
            rr += R[c, k] * R[c, k]
        v = abs(np.sqrt(rr) / sigma[c] - 1.0)
        if v > top or v != v:  # NaN propagates, as in numpy's max
            top = v
    return top


def max_row_norm(a: NDArray[np.float64]) -> float:
    """Largest Euclidean norm of the rows of an (n, d) array (0 when empty)."""
    return _max_row_norm(np.ascontiguousarray(a, dtype=np.float64))


@njit(cache=True)
def _max_row_norm(a):  # pragma: no cover - numba
    top = 0.0
    for i in range(a.shape[0]):
        s = 0.0
        for k in range(a.shape[1]):
            s += a[i, k] * a[i, k]
        if s > top or s != s:  # NaN propagates, as in numpy's max
            top = s
    return np.sqrt(top)


@functools.lru_cache(maxsize=64)
def _spectral_norm(data: bytes, d: int) -> float:
    return float(np.linalg.norm(np.frombuffer(data).reshape(d, d), 2))


def spectral_norm(E: NDArray[np.float64]) -> float:
    """Largest singular value ``|E|_2`` of a (d, d) velocity gradient [1/time].

    Memoised on the matrix: the integrator asks several times per step for the same
    (or one of a few) gradients, and an SVD costs more than the rest of the query.
    """
    E = np.ascontiguousarray(E, dtype=np.float64)
    return _spectral_norm(E.tobytes(), E.shape[0])


def affine_rates(R: NDArray[np.float64], gradient: NDArray[np.float64]) -> NDArray[np.float64]:
    """``S V_aff`` for contacts with separations R: ``n . E R`` (Eq. 13), shape (Nc,)."""
    return -_normals_and_drive(np.ascontiguousarray(R, dtype=np.float64),
                               np.ascontiguousarray(gradient, dtype=np.float64), 1.0)[2]


@njit(cache=True)
def _normals_and_drive(R, E, xi0):  # pragma: no cover - numba
    """Lengths r, shape (P,), unit vectors ``R / r``, shape (P, d), and ``-S V_aff / xi0`` of separations R."""
    nc, d = R.shape
    r = np.empty(nc)
    unit = np.empty((nc, d))
    rhs = np.empty(nc)
    for c in range(nc):
        rr = 0.0
        q = 0.0
        for k in range(d):
            rr += R[c, k] * R[c, k]
            for m in range(d):
                q += R[c, k] * E[k, m] * R[c, m]
        r[c] = np.sqrt(rr)
        for k in range(d):
            unit[c, k] = R[c, k] / r[c]
        rhs[c] = -(q / r[c] / xi0)
    return r, unit, rhs


@dataclass(frozen=True)
class Solution:
    """Contact forces and particle velocities on one contact network.

    Attributes
    ----------
    force : ndarray, shape (Nc,)
        Contact forces [lambda gamma_dot / xi0]; positive = repulsive.
    velocity : ndarray, shape (N, d)
        Non-affine velocity ``V - E x`` [lambda gamma_dot]; the full velocity of
        particle i is ``gradient @ x_i + velocity[i]``.
    gradient : ndarray, shape (d, d)
        Velocity-gradient tensor E of the affine flow (box: ``dh/dt = E h``).
    kappa : float
        Compression-to-shear rate ratio of fixed-pressure shear (Eq. 25); NaN otherwise.
    virial : ndarray, shape (d, d), or None
        Contact virial ``sum_c f_c r_c n_c n_c^T`` at the separations solved at (the
        stress tensor times the volume, :func:`stress_tensor`); None where not computed.
    """

    force: NDArray[np.float64]
    velocity: NDArray[np.float64]
    gradient: NDArray[np.float64]
    kappa: float
    virial: NDArray[np.float64] | None = None


def solve_network(
    x: NDArray[np.float64],
    h: NDArray[np.float64],
    pairs: NDArray[np.int64],
    images: NDArray[np.float64],
    gradient: NDArray[np.float64],
    external: NDArray[np.float64] | None = None,
    xi0: float = 1.0,
    pressure: float | None = None,
    rate: float = 1.0,
    cond_limit: float = COND_LIMIT,
    check_pivots: bool = True,
    cache: FactorCache | None = None,
    time: float | None = None,
    separations: NDArray[np.float64] | None = None,
    rtol: float | None = None,
) -> Solution:
    """Forces and velocities of a contact network (Eqs. 11–12, 18–19, 23–25).

    Parameters
    ----------
    x, h, pairs, images
        See :func:`pair_vectors`; ``pairs`` is the contact network (Nc, 2).
    gradient : ndarray, shape (d, d)
        Imposed velocity gradient E [1/time]; for fixed pressure, the shear part
        ``rate * e_0 e_1^T`` only (the compression ``-kappa * rate * I`` is solved for).
    external : ndarray, shape (N, d), optional
        External forces [lambda gamma_dot / xi0].
    xi0 : float
        Mobility (velocity per force).
    pressure : float, optional
        Imposed pressure p (Eq. 24) [force / lambda^(d-1)]: fixed-pressure shear.
    rate : float
        Shear rate gamma_dot (fixed-pressure mode only).
    cond_limit : float
        Pivot ratio of N beyond which the network counts as singular.
    check_pivots : bool
        Near potential jamming: solve by a fresh factorisation, whose pivot ratio decides
        singularity. Without it the cached CG path may be taken, and a direct solve is
        checked by its pivots and its residual (``1e-8`` relative).
    cache : FactorCache, optional
        Reuse of an earlier factorisation as a CG preconditioner, on the same network
        or on one at most ``cache.max_changes`` pairs away (bordered preconditioner);
        only when ``check_pivots`` is False: near potential jamming every solve is a
        fresh factorisation with its pivot check. CG that does not converge within
        ``cache.max_iter`` iterations falls back to the direct solve, which refreshes
        the cache.
    time : float, optional
        Time of the state (any monotonic clock of the caller): lets the cache
        extrapolate its warm starts in time. Never changes which network is solved.
    separations : ndarray, shape (Nc, d), optional
        ``pair_vectors(x, h, pairs, images)`` if the caller has them already.
    rtol : float, optional
        CG tolerance on the cached factor (default ``cache.rtol``).

    Raises
    ------
    SingularNetworkError
        When N is singular (a self-stress exists); see :mod:`.jamming`.
    """
    n, d = x.shape
    nc = len(pairs)
    if nc == 0:
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
        if pressure is not None:
            # without contacts no pressure can be carried and Eq. 25 is undefined: the
            # gas is sheared at fixed volume (kappa = 0) until the first collision
            kappa = 0.0
        velocity = np.zeros((n, d)) if external is None else xi0 * np.array(external, dtype=np.float64)
        return Solution(np.zeros(0), velocity, E, kappa)
    R = pair_vectors(x, h, pairs, images) if separations is None else separations
    r, unit, rhs = _normals_and_drive(np.ascontiguousarray(R, dtype=np.float64),
                                      np.ascontiguousarray(gradient, dtype=np.float64), float(xi0))
    pairs = np.ascontiguousarray(pairs, dtype=np.int64)
    if external is not None:
        rhs -= _s_apply(pairs, unit, np.ascontiguousarray(external, dtype=np.float64).ravel())
    if pressure is None:
        f = solve_contact_system(pairs, unit, n, [rhs], cond_limit, check_pivots, cache, time, rtol=rtol)[0]
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
    else:
        # E = gradient - kappa * rate * I:  f = a + kappa * b with N b = rate r / xi0; where a
        # and b cancel in f, CG solves them to its tolerance relative to f (``gain``)
        load = pressure * lattice_volume(h) * d
        sols = solve_contact_system(pairs, unit, n, [rhs, rate * r / xi0], cond_limit, check_pivots, cache, time,
                                    rtol=rtol, gain=lambda ab: _pressure_forces(ab, r, load)[2])
        kappa, f, _ = _pressure_forces(sols, r, load)
        E = np.array(gradient, dtype=np.float64) - kappa * rate * np.eye(d)
    U = _st_apply(pairs, unit, f, n)
    if external is not None:
        U += np.ravel(external)
    U *= xi0
    return Solution(f, U.reshape(n, d), E, kappa, _virial(unit, r, f))


@njit(cache=True)
def _virial(unit, r, f):  # pragma: no cover - numba
    """Contact virial ``sum_c f_c r_c n_c n_c^T`` of unit vectors, lengths and forces, shape (d, d)."""
    nc, d = unit.shape
    virial = np.zeros((d, d))
    for c in range(nc):
        w = f[c] * r[c]
        for a in range(d):
            for b in range(d):
                virial[a, b] += w * unit[c, a] * unit[c, b]
    return virial


def tangent_velocities(
    R: NDArray[np.float64],
    pairs: NDArray[np.int64],
    sol: Solution,
    cache: FactorCache | None = None,
    cond_limit: float = COND_LIMIT,
    rtol: float | None = None,
) -> Solution:
    """``sol`` with the least change of its non-affine velocities that leaves every
    contact with separation R at rate zero: ``U - S^T N^-1 (dr/dt)``.

    Parameters
    ----------
    R : ndarray, shape (Nc, d)
        Separations of the contacts (need not be those ``sol`` was solved at).
    pairs : ndarray of int64, shape (Nc, 2)
    sol : Solution
    cache, cond_limit, rtol
        As in :func:`solve_network` (the solve never checks pivots: callers project only
        networks that carry no self-stress).

    Raises
    ------
    SingularNetworkError
    """
    n, d = sol.velocity.shape
    if len(pairs) == 0:
        return sol
    R = np.ascontiguousarray(R, dtype=np.float64)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64)
    rates = pair_velocities(R, pairs, sol)
    unit = pair_normals(R)
    y = solve_contact_system(pairs, unit, n, [rates], cond_limit, False, cache, warm=False, rtol=rtol)[0]
    U = sol.velocity - _st_apply(pairs, unit, y, n).reshape(n, d)
    return Solution(sol.force, U, sol.gradient, sol.kappa)


def pair_velocities(
    R: NDArray[np.float64], pairs: NDArray[np.int64], sol: Solution
) -> NDArray[np.float64]:
    """Rates ``dr_ij/dt = n_ij . (V_j - V_i)`` (Eq. 26) of pairs with separations R, shape (P,)."""
    return _pair_rates(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(pairs, dtype=np.int64),
                       np.ascontiguousarray(sol.velocity), np.ascontiguousarray(sol.gradient))


@njit(cache=True)
def _pair_rates(R, pairs, U, E):  # pragma: no cover - numba
    nc, d = R.shape
    out = np.empty(nc)
    for c in range(nc):
        i, j = np.uint64(pairs[c, 0]), np.uint64(pairs[c, 1])  # unsigned: no wraparound test per access
        s = 0.0
        rr = 0.0
        for k in range(d):
            w = U[j, k] - U[i, k]
            for m in range(d):
                w += E[k, m] * R[c, m]
            s += R[c, k] * w
            rr += R[c, k] * R[c, k]
        out[c] = s / np.sqrt(rr)
    return out


def max_relative_rate(
    R: NDArray[np.float64], pairs: NDArray[np.int64], sol: Solution, sigma: NDArray[np.float64]
) -> float:
    """Largest ``|W_c| / sigma_c`` over contacts, W the full relative velocity ``E R + U_j - U_i`` [1/time].

    A contact moving on a straight line with relative velocity W perpendicular to it
    opens by ``dt^2 |W|^2 / (2 sigma)`` in a step dt (the step-drift bound of the step rule).
    """
    return _max_relative_rate(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(pairs, dtype=np.int64),
                              np.ascontiguousarray(sol.velocity), np.ascontiguousarray(sol.gradient),
                              np.ascontiguousarray(sigma, dtype=np.float64))


@njit(cache=True)
def _max_relative_rate(R, pairs, U, E, sigma):  # pragma: no cover - numba
    nc, d = R.shape
    top = 0.0
    for c in range(nc):
        i, j = np.uint64(pairs[c, 0]), np.uint64(pairs[c, 1])  # unsigned: no wraparound test per access
        ww = 0.0
        for k in range(d):
            w = U[j, k] - U[i, k]
            for m in range(d):
                w += E[k, m] * R[c, m]
            ww += w * w
        v = ww / (sigma[c] * sigma[c])
        if v > top or v != v:  # NaN propagates, as in numpy's max
            top = v
    return np.sqrt(top)


def stress_tensor(R: NDArray[np.float64], force: NDArray[np.float64], volume: float) -> NDArray[np.float64]:
    """Contact stress ``Sigma_ab = (1/Omega) sum_c f_c R_a R_b / r`` (positive = compressive), shape (d, d).

    Pressure (Eq. 24) is ``trace / d``; the shear stress of Eq. 30 is ``-Sigma_01``.
    """
    return _stress_sum(np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(force, dtype=np.float64)) / volume


@njit(cache=True)
def _stress_sum(R, force):  # pragma: no cover - numba
    nc, d = R.shape
    out = np.zeros((d, d))
    for c in range(nc):
        rr = 0.0
        for k in range(d):
            rr += R[c, k] * R[c, k]
        w = force[c] / np.sqrt(rr)
        for a in range(d):
            for b in range(d):
                out[a, b] += w * R[c, a] * R[c, b]
    return out
