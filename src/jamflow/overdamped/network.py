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

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

__all__ = [
    "pair_vectors",
    "s_matrix",
    "affine_rates",
    "Solution",
    "SingularNetworkError",
    "solve_network",
    "pair_velocities",
    "stress_tensor",
]


class SingularNetworkError(RuntimeError):
    """``N = S S^T`` is singular: the network carries a self-stress (potentially jammed)."""


def pair_vectors(
    x: NDArray[np.float64], h: NDArray[np.float64], pairs: NDArray[np.int64], images: NDArray[np.int64]
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
    images : ndarray of int64, shape (P, d)
        Lattice vector ``m`` of the image of j seen from i.

    Returns
    -------
    ndarray, shape (P, d)
    """
    return x[pairs[:, 1]] - x[pairs[:, 0]] + images @ h.T


def s_matrix(pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int) -> sp.csr_matrix:
    """The operator ``S = d r_ij / d R_k`` (Eq. 2), sparse, shape (Nc, N d).

    Parameters
    ----------
    pairs : ndarray of int64, shape (Nc, 2)
    unit : ndarray, shape (Nc, d)
        Unit vectors ``n_ij`` from i to j.
    n : int
        Number of particles.
    """
    nc, d = unit.shape
    # 2d entries per row, columns ascending because i < j: build CSR directly
    cols = np.concatenate(
        [pairs[:, :1] * d + np.arange(d), pairs[:, 1:] * d + np.arange(d)], axis=1
    ).ravel()
    vals = np.concatenate([-unit, unit], axis=1).ravel()
    indptr = np.arange(0, 2 * d * nc + 1, 2 * d)
    return sp.csr_matrix((vals, cols, indptr), shape=(nc, n * d))


def affine_rates(R: NDArray[np.float64], gradient: NDArray[np.float64]) -> NDArray[np.float64]:
    """``S V_aff`` for contacts with separations R: ``n . E R`` (Eq. 13), shape (Nc,)."""
    r = np.linalg.norm(R, axis=1)
    return np.einsum("ck,kl,cl->c", R, gradient, R) / r


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
    """

    force: NDArray[np.float64]
    velocity: NDArray[np.float64]
    gradient: NDArray[np.float64]
    kappa: float


def _factorize(S: sp.csr_matrix, cond_limit: float, check_pivots: bool = True):
    """Sparse LU of N = S S^T with an explicit singularity check.

    A self-stress makes N exactly singular in exact arithmetic; in floating point its
    smallest pivot is round-off. With ``check_pivots``, a ratio of the smallest to the
    largest |U_kk| below ``1 / cond_limit`` is treated as singular (extracting U costs
    about as much as the factorisation, so callers skip it far from jamming).
    """
    Nmat = (S @ S.T).tocsc()
    try:
        lu = spla.splu(Nmat, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0)
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularNetworkError(str(exc)) from exc
    if check_pivots:
        piv = np.abs(lu.U.diagonal())
        if piv.size and piv.min() < piv.max() / cond_limit:
            raise SingularNetworkError(f"N = S S^T nearly singular (pivot ratio {piv.min() / piv.max():.3g})")
    return lu


def solve_network(
    x: NDArray[np.float64],
    h: NDArray[np.float64],
    pairs: NDArray[np.int64],
    images: NDArray[np.int64],
    gradient: NDArray[np.float64],
    external: NDArray[np.float64] | None = None,
    xi0: float = 1.0,
    pressure: float | None = None,
    rate: float = 1.0,
    cond_limit: float = 1e13,
    check_pivots: bool = True,
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
        Check the pivots (else only an exactly singular factor or a solution whose
        residual exceeds ``1e-8`` relative is reported singular).

    Raises
    ------
    SingularNetworkError
        When N is singular (a self-stress exists); see :mod:`.jamming`.
    """
    n, d = x.shape
    nc = len(pairs)
    ext = np.zeros((n, d)) if external is None else external
    if nc == 0:
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
        if pressure is not None:
            # without contacts no pressure can be carried and Eq. 25 is undefined: the
            # gas is sheared at fixed volume (kappa = 0) until the first collision
            kappa = 0.0
        return Solution(np.zeros(0), xi0 * ext.copy(), E, kappa)
    R = pair_vectors(x, h, pairs, images)
    r = np.linalg.norm(R, axis=1)
    unit = R / r[:, None]
    S = s_matrix(pairs, unit, n)
    lu = _factorize(S, cond_limit, check_pivots)
    rhs = -(affine_rates(R, gradient) / xi0 + S @ ext.ravel())
    if not check_pivots:
        f = lu.solve(rhs)
        res = np.linalg.norm(S @ (S.T @ f) - rhs)
        if not np.all(np.isfinite(f)) or res > 1e-8 * max(np.linalg.norm(rhs), 1e-300):
            raise SingularNetworkError(f"N = S S^T solve inaccurate (relative residual {res / max(np.linalg.norm(rhs), 1e-300):.3g})")
    if pressure is None:
        f = lu.solve(rhs)
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
    else:
        # E = gradient - kappa * rate * I:  f = a + kappa * b with N b = rate r / xi0
        a = lu.solve(rhs)
        b = lu.solve(rate * r / xi0)
        omega = abs(np.linalg.det(h))
        kappa = float((pressure * omega * d - a @ r) / (b @ r))
        f = a + kappa * b
        E = np.array(gradient, dtype=np.float64) - kappa * rate * np.eye(d)
    U = xi0 * (ext.ravel() + S.T @ f)
    return Solution(f, U.reshape(n, d), E, kappa)


def pair_velocities(
    R: NDArray[np.float64], pairs: NDArray[np.int64], sol: Solution
) -> NDArray[np.float64]:
    """Rates ``dr_ij/dt = n_ij . (V_j - V_i)`` (Eq. 26) of pairs with separations R, shape (P,)."""
    r = np.linalg.norm(R, axis=1)
    dU = sol.velocity[pairs[:, 1]] - sol.velocity[pairs[:, 0]]
    return (np.einsum("pk,pk->p", R, dU) + np.einsum("pk,kl,pl->p", R, sol.gradient, R)) / r


def stress_tensor(R: NDArray[np.float64], force: NDArray[np.float64], volume: float) -> NDArray[np.float64]:
    """Contact stress ``Sigma_ab = (1/Omega) sum_c f_c R_a R_b / r`` (positive = compressive), shape (d, d).

    Pressure (Eq. 24) is ``trace / d``; the shear stress of Eq. 30 is ``-Sigma_01``.
    """
    r = np.linalg.norm(R, axis=1)
    return np.einsum("c,ca,cb->ab", force / r, R, R) / volume
