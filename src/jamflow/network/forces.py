"""Balanced non-negative contact forces on a given (possibly hyperstatic) network.

A jammed hard-sphere packing whose contact network is hyperstatic (a crystal, a 2D
monodisperse packing with crystalline patches) has a whole polytope of contact
forces that balance every particle: non-negative ``f`` with ``B f = 0``, ``B`` the
balance matrix (the transpose of the rigidity matrix, :mod:`jamflow.network.rigidity`), and
a normalisation. A vertex of the jamming LP, which is what CALiPPSO's duals are,
puts zero force on all but about ``d (N - 1) + 1`` of the contacts; its support is
not the contact network. This module picks one well-defined member of the polytope,
the **minimum-norm** assignment::

    minimise |f|^2   subject to   B f = 0,   sum_c w_c f_c = 1,   f >= 0,

with ``w_c = sigma_ij`` for a pair and ``sigma_i / 2`` for a wall contact, the
normalisation of CALiPPSO's forces (paper Eq. 9: ``sum_c f_c sigma_c = 1``, forces
in units of 1/length). The objective is strictly convex, so the assignment is
unique and inherits every symmetry of the packing (a perfect crystal gets equal
forces on equal contacts); on an isostatic network with a unique positive solution
it is that solution. It is a convex quadratic program, solved by a semismooth
Newton method on its dual (sparse LU solves; HiGHS's active-set QP solver is the
fallback and the reference it is tested against); the support found is then
polished by the minimum-norm solution of the equality constraints restricted to
it (LSQR), which balances forces to ~1e-11 relative.
"""

from __future__ import annotations

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.linalg import lsqr, splu

from ..highs import colwise_lp, new_highs
from ..tolerances import FORCE_BALANCE_TOL
from . import pair_rows

__all__ = ["MIN_NORM", "balance_matrix", "min_norm_forces"]

#: Name of the assignment of :func:`min_norm_forces` (stored as ``force_assignment``).
MIN_NORM: str = "min_norm_balanced"

#: Feasibility tolerance of the QP (HiGHS, and the Newton stopping test), in units of
#: the rescaled forces (mean 1); the polish step then restores balance to round-off.
_QP_TOL: float = 1e-10

#: Dual Newton: Tikhonov term of the normal matrix (its entries are O(1) per contact)
#: and the largest number of steps, which grow with the contacts left without force
#: (measured: docs/notes/network-constants.md#dual-newton-of-the-minimum-norm-forces-jamflownetworkforces).
_NEWTON_REG: float = 1e-12
_NEWTON_MAX_ITER: int = 200
#: Dual Newton: steps without a new smallest residual after which it stops (the QP decides),
#: a guard against a line search that makes no progress
#: (measured: docs/notes/network-constants.md#dual-newton-of-the-minimum-norm-forces-jamflownetworkforces).
_NEWTON_STALL: int = 10
#: Dual Newton: steps taken past :data:`_QP_TOL` while each at least halves the residual.
#: A residual of 1e-10 still leaves forces wrong by up to ~1e-8 of the largest on a
#: near-singular network (the dual is large); on a settled support the next step solves the
#: support's equalities to round-off.
_NEWTON_REFINE: int = 3


def balance_matrix(
    unit: NDArray[np.float64],
    contacts: NDArray[np.int64],
    n: int,
    d: int,
    wall_particles: NDArray[np.int64] | None = None,
    wall_faces: NDArray[np.int64] | None = None,
) -> sp.csr_matrix:
    """Net force on every particle per unit contact force, shape (d n, Nc + Nw).

    Parameters
    ----------
    unit : ndarray, shape (Nc, d)
        Unit vectors ``n_ij`` from ``i`` to ``j`` of the pair contacts.
    contacts : ndarray of int, shape (Nc, 2)
    n, d : int
        Number of particles and dimension.
    wall_particles, wall_faces : ndarray of int, shape (Nw,), optional
        Wall contacts: particle and face ``2 * axis + (0 lower, 1 upper)``; a lower
        wall pushes along ``+axis``, an upper one along ``-axis``.

    Returns
    -------
    scipy.sparse.csr_matrix
        Row ``d i + a`` is component ``a`` of the net force on ``i``: a repulsive pair
        force ``f`` adds ``-f n_ij`` on ``i`` and ``+f n_ij`` on ``j``.
    """
    # the pair columns are the transposed contact Jacobian (virtual work)
    pairs = pair_rows(contacts, np.asarray(unit, dtype=np.float64).reshape(-1, d), n).T
    if wall_particles is None or not len(wall_particles):
        return pairs.tocsr()
    wp = np.asarray(wall_particles, dtype=np.int64)
    wf = np.asarray(wall_faces, dtype=np.int64)
    walls = sp.csc_matrix((np.where(wf % 2 == 0, 1.0, -1.0), (d * wp + wf // 2, np.arange(len(wp)))),
                          shape=(d * n, len(wp)))
    return sp.hstack([pairs, walls], format="csr")


def min_norm_forces(B: sp.spmatrix, weight: NDArray[np.float64], d: int,
                    method: str = "newton") -> tuple[NDArray[np.float64], float]:
    """The minimum-norm non-negative balanced forces (see module docstring).

    Parameters
    ----------
    B : sparse matrix, shape (d N, Nc)
        Balance matrix (:func:`balance_matrix`).
    weight : ndarray, shape (Nc,)
        Normalisation weights ``w_c`` [length] (``sum_c w_c f_c = 1``).
    d : int
        Dimension (rows of ``B`` per particle).
    method : {"newton", "qp"}
        ``"newton"``: semismooth Newton on the dual (:func:`_dual_newton`; sparse
        solves: 0.07 s for a 1024-particle triangular crystal, one step; 5-8 s for a
        2D monodisperse N = 1024 packing, ~80 steps; 5 s for a 3D N = 2048 packing
        hyperstatic by one, 8 steps), falling back to the QP when it
        does not converge; ``"qp"``: HiGHS's QP solver only (an independent
        reference for small networks: 22 s for the 1024-particle crystal, and
        "Solve error" on the 2D monodisperse N = 1024 network).

    Returns
    -------
    f : ndarray, shape (Nc,)
        Forces [1/length], every one ``>= 0``.
    residual : float
        Largest net force on a particle divided by the mean force.

    Raises
    ------
    RuntimeError
        No balanced non-negative forces exist on this network (the QP is
        infeasible), HiGHS does not solve it, or the result is not balanced to
        :data:`~jamflow.tolerances.FORCE_BALANCE_TOL`.
    """
    if method not in ("newton", "qp"):
        raise ValueError(f"method must be 'newton' or 'qp', got {method!r}")
    B = sp.csr_matrix(B)
    w = np.asarray(weight, dtype=np.float64)
    nc = B.shape[1]
    if nc == 0:
        raise RuntimeError("no contacts to carry forces")
    # variables phi = f / f0 with f0 = 1 / sum(w): the uniform assignment is phi = 1
    f0 = 1.0 / float(w.sum())
    wn = w / float(w.mean())
    A = sp.vstack([B, sp.csr_matrix(wn[None, :])], format="csc")
    A.sort_indices()
    rhs = np.zeros(A.shape[0])
    rhs[-1] = float(nc)
    phi = _dual_newton(B, wn, float(nc)) if method == "newton" else None
    if phi is None:
        phi = _highs_qp(A, rhs)
    phi = _polish(A, rhs, phi)
    f = phi * f0
    net = np.linalg.norm(np.asarray(B @ f).reshape(-1, d), axis=1)
    residual = float(net.max(initial=0.0)) / float(f.mean())
    if not residual <= FORCE_BALANCE_TOL:
        raise RuntimeError(f"minimum-norm forces balance only to {residual:.3g} relative (> {FORCE_BALANCE_TOL:g})")
    return f, residual


def _dual_newton(B: sp.csr_matrix, wn: NDArray[np.float64], total: float) -> NDArray[np.float64] | None:
    """``argmin |phi|^2`` s.t. ``B phi = 0``, ``wn . phi = total``, ``phi >= 0`` by
    Newton on the dual.

    With ``A = [B; wn]`` and ``rhs = (0, total)`` the dual function
    ``g(lam) = rhs . lam - |max(A^T lam, 0)|^2 / 2`` is concave and piecewise
    quadratic; its maximiser gives ``phi = max(A^T lam, 0)``, non-negative and
    complementary by construction, so only ``A phi = rhs`` is left to reach. A
    generalised Newton step solves ``(A_S A_S^T + delta I) dlam = rhs - A phi`` on the
    support ``S = {A^T lam > 0}`` (``delta`` regularises the translations and the
    floppy modes of ``S``), by block elimination of the dense normalisation row around
    one sparse LU of ``B_S B_S^T + delta I`` (symmetric positive definite: a symmetric
    ordering with diagonal pivots, the fill of a Cholesky factor), with an Armijo
    backtracking line search on ``g``, from the unconstrained minimum-norm solution.
    The line search evaluates the increment ``g(lam + t dlam) - g(lam)`` as
    one sum: near the optimum it is ~ residual^2, far below the round-off of ``g``
    itself (~ N_c eps), and the difference of two values of ``g`` would be noise.
    Past :data:`_QP_TOL` it goes on while each step at least halves the residual, at most
    :data:`_NEWTON_REFINE` steps, and returns the best iterate, every component of
    ``A^T lam`` inside its rounding error set to zero (a rattler's contact, or one the
    optimum leaves without force, would otherwise keep a force of ~1e-14). Returns
    None when :data:`_NEWTON_MAX_ITER` steps do not reach :data:`_QP_TOL`,
    :data:`_NEWTON_STALL` steps in a row do not lower the smallest residual, or a factor
    meets an exactly zero pivot (the QP decides then).
    """
    A = sp.vstack([B, sp.csr_matrix(wn[None, :])], format="csr")
    At = sp.csr_matrix(A.T)
    # floating-point error bound of z = A^T lam, per contact: gamma_k |A^T| |lam| with
    # k = the column's entries
    abs_At, gamma = abs(At), (np.diff(At.indptr) + 1) * np.finfo(np.float64).eps
    rhs = np.zeros(A.shape[0])
    rhs[-1] = total
    Bc = sp.csc_matrix(B)
    reg = _NEWTON_REG * sp.identity(B.shape[0], format="csc")

    def step(support: NDArray[np.bool_], r: NDArray[np.float64]) -> NDArray[np.float64]:
        Bs, ws = Bc[:, support], wn[support]
        lu = splu(sp.csc_matrix(Bs @ Bs.T) + reg, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
        u = Bs @ ws
        a, b = lu.solve(r[:-1]), lu.solve(u)
        y = (r[-1] - u @ a) / (ws @ ws + _NEWTON_REG - u @ b)
        return np.append(a - b * y, y)

    def gain(z: NDArray[np.float64], phi: NDArray[np.float64], dz: NDArray[np.float64],
             rise: float, t: float) -> float:
        # g(lam + t dlam) - g(lam), with |a|^2 - |b|^2 = (a - b) . (a + b)
        moved = np.maximum(z + t * dz, 0.0)
        return t * rise - 0.5 * float((moved - phi) @ (moved + phi))

    try:
        lam = step(np.ones(A.shape[1], dtype=bool), rhs)
        best, best_phi, since, refined = np.inf, None, 0, 0
        for _ in range(_NEWTON_MAX_ITER):
            z = At @ lam
            phi = np.maximum(z, 0.0)
            r = rhs - A @ phi
            residual = float(np.abs(r).max())
            halved = residual <= 0.5 * best
            if residual < best:  # a z inside its rounding error is zero, not a force
                best, best_phi, since = residual, np.where(z > gamma * (abs_At @ np.abs(lam)), z, 0.0), 0
            else:
                since += 1
            if best <= _QP_TOL:
                if not halved or refined == _NEWTON_REFINE:
                    return best_phi
                refined += 1
            if since >= _NEWTON_STALL:
                return None
            dlam = step(phi > 0.0, r)
            dz, rise, slope, t = At @ dlam, float(rhs @ dlam), float(r @ dlam), 1.0
            while gain(z, phi, dz, rise, t) < 1e-4 * t * slope and t > 1e-12:
                t *= 0.5
            lam = lam + t * dlam
    except RuntimeError:  # an exactly zero pivot
        return None
    return best_phi if best <= _QP_TOL else None


def _highs_qp(A: sp.csc_matrix, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
    """``argmin |phi|^2 / 2`` s.t. ``A phi = rhs``, ``phi >= 0`` by HiGHS's QP solver."""
    nc = A.shape[1]
    lp = colwise_lp(A, np.zeros(nc), np.zeros(nc), np.full(nc, highspy.kHighsInf), rhs, rhs)
    hess = highspy.HighsHessian()
    hess.dim_ = nc
    hess.format_ = highspy.HessianFormat.kTriangular
    hess.start_ = np.arange(nc + 1, dtype=np.int32)
    hess.index_ = np.arange(nc, dtype=np.int32)
    hess.value_ = np.ones(nc)
    h = new_highs()
    for option in ("primal_feasibility_tolerance", "dual_feasibility_tolerance"):
        h.setOptionValue(option, _QP_TOL)
    h.passModel(lp)
    h.passHessian(hess)
    h.run()
    status = h.getModelStatus()
    if status != highspy.HighsModelStatus.kOptimal:
        raise RuntimeError(f"minimum-norm force QP not solved: HiGHS status {h.modelStatusToString(status)!r}")
    return np.maximum(np.asarray(h.getSolution().col_value, dtype=np.float64), 0.0)


def _polish(A: sp.csc_matrix, rhs: NDArray[np.float64], phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Minimum-norm solution of the equalities on the QP's support, if it stays >= 0.

    On the optimal face (``phi_c = 0`` off the support ``S``, ``phi_S > 0``) the QP
    optimum is the minimum-norm solution of ``A_S phi_S = rhs``; LSQR from zero
    converges to it and removes the QP's feasibility error. A support misjudged by
    the QP tolerance would give a negative component: the QP solution is kept then,
    as it is when LSQR does not reduce the constraint residual.
    """
    support = phi > _QP_TOL * float(phi.max(initial=0.0))
    sol = lsqr(A[:, support], rhs, atol=1e-15, btol=1e-15, conlim=0.0, iter_lim=20 * A.shape[0])[0]
    out = np.zeros_like(phi)
    out[support] = sol
    if np.all(sol >= 0.0) and np.abs(A @ out - rhs).max() < np.abs(A @ phi - rhs).max():
        return out
    return phi
