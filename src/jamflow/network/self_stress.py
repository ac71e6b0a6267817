"""States of self stress: contact forces in equilibrium without external load.

A self stress of a network with Jacobian ``J`` (:func:`~jamflow.network.jacobian.contact_jacobian`)
is a vector of contact forces ``lambda`` with ``J^T lambda = 0``: ``J^T`` maps
contact forces to net body forces and torques (and, with strain columns, to the
contact stress). Their number is ``n_c - rank J``.

Roth-Whiteley theorem (used as an independent check of the LP certificate): a
framework of struts (contacts that may open but not close) is first-order rigid if
and only if the Jacobian has full rank (kernel = trivial motions only) and a
self stress exists that is strictly positive on every contact. For hard spheres
first-order rigidity is rigidity (Connelly), because ``|r + dr| >= n . (r + dr)``
makes every first-order motion a finite one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import highspy
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.optimize import linprog, nnls

from ..highs import colwise_lp, new_highs
from ..tolerances import RIGID_PIVOT_RTOL, SELF_STRESS_POSITIVE_RTOL

__all__ = ["RigidNetwork", "jacobian_rank", "positive_self_stress", "rigid_network", "self_stresses", "strain_motion"]


def jacobian_rank(J: sp.spmatrix) -> tuple[int, NDArray[np.float64]]:
    """Rank of ``J`` from its singular values (dense SVD), and the singular values.

    The threshold is numpy's default, ``s_max * max(shape) * eps``.
    """
    dense = J.toarray() if sp.issparse(J) else np.asarray(J)
    s = np.linalg.svd(dense, compute_uv=False)
    tol = (s.max() if s.size else 0.0) * max(dense.shape) * np.finfo(float).eps
    return int(np.sum(s > tol)), s


def self_stresses(J: sp.spmatrix, *, k: int | None = None, rtol: float | None = None) -> NDArray[np.float64]:
    """Orthonormal basis of the self stresses ``{lambda : J^T lambda = 0}``, shape (n_c, n_ss).

    Parameters
    ----------
    J : sparse matrix, shape (n_c, n_dof)
    k : int, optional
        Sparse mode for large networks: the ``k`` smallest eigenpairs of ``J J^T``
        (shift-invert Lanczos around a small negative shift, one sparse LU), of
        which those below the threshold are returned. Default: the whole null
        space from a dense SVD.
    rtol : float, optional
        Singular values ``s <= rtol s_max`` count as zero; default numpy's rank
        threshold ``max(shape) eps``.
    """
    nc = J.shape[0]
    if nc == 0:
        return np.zeros((0, 0))
    tol = max(J.shape) * np.finfo(float).eps if rtol is None else rtol
    if k is None:
        dense = J.toarray() if sp.issparse(J) else np.asarray(J)
        u, s, _ = np.linalg.svd(dense, full_matrices=True)
        s_max = s.max(initial=0.0)
        rank = int(np.sum(s > tol * s_max)) if s_max > 0 else 0
        return u[:, rank:]
    G = sp.csc_matrix(J @ J.T)
    scale = float(abs(G).sum(axis=1).max())  # >= largest eigenvalue s_max^2
    shift = -1e-8 * scale
    # a seeded start vector: ARPACK's own draws depend on the calls made before in the process
    start = np.random.default_rng(0).standard_normal(nc)
    w, v = spla.eigsh(G, k=min(k, nc - 1), sigma=shift, which="LM", v0=start)
    keep = w <= (tol**2) * scale
    return v[:, keep]


def positive_self_stress(J: sp.spmatrix, rtol: float = 1e-9, method: str = "nnls") -> NDArray[np.float64] | None:
    """A self stress strictly positive on every contact (``J^T lambda = 0``), or None.

    Parameters
    ----------
    J : sparse matrix, shape (n_c, n_dof)
    rtol : float
        ``"nnls"``: residual ``|J^T lambda| / (|J| |lambda|)`` regarded as zero;
        ``"lp"``: smallest accepted ``min lambda`` when ``max lambda = 1``.
    method : {"nnls", "lp"}
        ``"nnls"``: any strictly positive self stress can be scaled to
        ``min lambda = 1``, so one exists iff ``min_{mu >= 0} |J^T (1 + mu)|``
        vanishes, a non-negative least-squares problem (Lawson-Hanson active set,
        dense; small networks). ``"lp"``: maximise ``t`` subject to
        ``J^T lambda = 0``, ``t <= lambda <= 1`` (sparse, HiGHS via scipy; the dual
        certificate of the motion LPs, for large networks).

    Returns
    -------
    ndarray, shape (n_c,) or None
        The self stress (``min = 1`` for nnls, ``max <= 1`` for lp).
    """
    if method == "nnls":
        A = (J.T.toarray() if sp.issparse(J) else np.asarray(J).T)
        ones = np.ones(A.shape[1])
        mu, _ = nnls(A, -A @ ones, maxiter=50 * A.shape[1])
        lam = ones + mu
        scale = np.linalg.norm(A, ord=2) * np.linalg.norm(lam)
        residual = np.linalg.norm(A @ lam)
        return lam if residual <= rtol * scale else None
    if method != "lp":
        raise ValueError(f"method must be 'nnls' or 'lp', got {method!r}")
    nc, ndof = J.shape
    At = sp.csr_matrix(J.T)
    A_eq = sp.hstack([At, sp.csr_matrix((ndof, 1))], format="csr")
    A_ub = sp.hstack([-sp.identity(nc, format="csr"), sp.csr_matrix(np.ones((nc, 1)))], format="csr")
    cost = np.zeros(nc + 1)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=A_ub, b_ub=np.zeros(nc), A_eq=A_eq, b_eq=np.zeros(ndof),
                  bounds=[(0.0, 1.0)] * nc + [(None, None)], method="highs")
    if res.status != 0:
        raise RuntimeError(f"self-stress LP failed: {res.message}")
    return res.x[:nc] if res.x[-1] > rtol else None


@dataclass(frozen=True)
class RigidNetwork:
    """A first-order rigid network (Roth-Whiteley) with its self-stress space.

    Attributes
    ----------
    self_stress : ndarray, shape (n_c,)
        A strictly positive self stress (``J^T lambda = 0``), unit maximum.
    null : ndarray, shape (n_c, n_ss)
        Orthonormal basis of all self stresses.
    lu : scipy.sparse.linalg.SuperLU
        Factorisation of ``J^T J``: ``J y = w`` for any ``w`` orthogonal to every
        self stress is solved by ``y = (J^T J)^-1 J^T w``.
    """

    self_stress: NDArray[np.float64]
    null: NDArray[np.float64]
    lu: Any


def _null_space(J: sp.csr_matrix, lu: Any, k: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """Orthonormal basis of ker J^T (dimension k): projected random vectors, QR."""
    V = rng.standard_normal((J.shape[0], k))
    for _ in range(2):  # one refinement for round-off
        V = V - J @ lu.solve(np.asarray(J.T @ V))
    Q, _ = np.linalg.qr(V)
    return Q


def rigid_network(J: sp.spmatrix, seed: int = 0, guess: NDArray[np.float64] | None = None,
                  max_self_stresses: int | None = None) -> RigidNetwork | None:
    """Roth-Whiteley test: full column rank and a strictly positive self stress.

    ``J`` (shape ``(n_c, m)``, trivial motions removed, e.g. one particle pinned)
    describes a first-order rigid strut framework if and only if it has full column
    rank and some self stress is strictly positive; then the cone
    ``{y : J y >= 0}`` is ``{0}`` and no load moves the network. Full rank is read
    from the pivots of the sparse LU of ``J^T J``
    (:data:`~jamflow.tolerances.RIGID_PIVOT_RTOL`); the positive self stress is the
    solution of a small LP over the ``n_c - m`` dimensional self-stress space
    (maximise ``min lambda``), accepted when ``min / max`` exceeds
    :data:`~jamflow.tolerances.SELF_STRESS_POSITIVE_RTOL`. A ``guess`` (shape
    (n_c,), e.g. the contact forces of a soft packing in force balance) is
    projected onto the self-stress space first and used when that projection is
    already strictly positive (no LP). The self-stress basis is dense
    (``n_c x (n_c - m)``): with ``max_self_stresses`` a more hyperstatic network
    returns None at once (its motion LPs are cheaper than the dense basis).

    Returns
    -------
    RigidNetwork or None
        None when the test is not clearly passed (floppy, ill-conditioned or
        without a positive self stress: ask the motion LPs).
    """
    nc, m = J.shape
    if nc <= m or m == 0 or (max_self_stresses is not None and nc - m > max_self_stresses):
        return None
    J = sp.csr_matrix(J)
    try:
        # J^T J is symmetric positive definite when J has full rank: a symmetric
        # ordering with diagonal pivots keeps the fill of a Cholesky factor
        lu = spla.splu(sp.csc_matrix(J.T @ J), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return None
    piv = np.abs(lu.U.diagonal())
    if not piv.size or piv.min() <= RIGID_PIVOT_RTOL * piv.max():
        return None
    null = _null_space(J, lu, nc - m, np.random.default_rng(seed))
    lam = None
    if guess is not None:
        lam = null @ (null.T @ guess)
        lam = lam / np.abs(lam).max() if lam.min() > SELF_STRESS_POSITIVE_RTOL * np.abs(lam).max() else None
    if lam is None:
        lam = _positive_combination(null)
    if lam is None:
        return None
    residual = np.abs(J.T @ lam).max() / max(float(abs(J).sum(axis=0).max()), 1e-300)
    if lam.min() <= SELF_STRESS_POSITIVE_RTOL or residual > SELF_STRESS_POSITIVE_RTOL:
        return None
    return RigidNetwork(lam, null, lu)


def _positive_combination(null: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``lambda = null @ a`` maximising ``min lambda`` at ``max |a| <= 1``, unit maximum; None if not positive."""
    nc, k = null.shape
    if k == 1:
        lam = null[:, 0] * np.sign(null[:, 0].sum())
        return lam / np.abs(lam).max()
    # max t  s.t.  null a - t >= 0,  -1 <= a <= 1  (k + 1 columns)
    cost = np.zeros(k + 1)
    cost[-1] = 1.0
    x = _max_lp(cost, np.hstack([null, -np.ones((nc, 1))]), np.zeros(nc), np.full(nc, np.inf),
                np.r_[-np.ones(k), -np.inf], np.r_[np.ones(k), np.inf])
    if x is None or x[-1] <= 0:
        return None
    lam = null @ x[:k]
    return lam / np.abs(lam).max()


def strain_motion(rigid: RigidNetwork, J: sp.spmatrix, E: sp.spmatrix,
                  rtol: float = SELF_STRESS_POSITIVE_RTOL) -> tuple[str, NDArray[np.float64] | None]:
    """Whether strain columns ``E`` unjam a rigid network, and a motion if they do.

    With ``J`` first-order rigid (:func:`rigid_network`) the motions of ``[J E]``
    are ``(y, e)`` with ``J y + E e = c >= 0``. Either ``[J E]`` has a kernel (a
    motion with ``c = 0``: the Schur complement ``E^T E - E^T J (J^T J)^-1 J^T E``
    is singular), or a motion opens contacts: ``c - E e`` must lie in the range of
    ``J``, i.e. ``N^T c = N^T E e`` with ``N`` the self stresses, a small LP
    (``n_ss`` rows): maximise ``lambda_0 . c`` over ``0 <= c <= 1``, ``|e| <= 1``. Neither:
    no motion (strictly rigid).

    Returns
    -------
    verdict : {"rigid", "motion", "unclear"}
    motion : ndarray, shape (m + n_strain,) or None
        ``(y, e)`` scaled to largest coordinate 1, for ``"motion"``.
    """
    J = sp.csr_matrix(J)
    E = sp.csr_matrix(E)
    k = E.shape[1]
    JE = np.asarray((J.T @ E).todense())
    W = rigid.lu.solve(JE)
    S = np.asarray((E.T @ E).todense()) - JE.T @ W
    S = 0.5 * (S + S.T)
    w, v = np.linalg.eigh(S)
    scale = max(float(np.abs(np.diag(np.asarray((E.T @ E).todense()))).max()), 1e-300)
    if w[0] <= rtol * scale:
        if w[0] > 1e-3 * rtol * scale:
            return "unclear", None
        e = v[:, 0]
        y = -W @ e
        return _scaled(J, E, y, e)
    N = rigid.null
    NE = np.asarray(E.T @ N).T  # (n_ss, k) = N^T E
    nc = J.shape[0]
    zero = np.zeros(N.shape[1])
    # objective lambda_0 . c (> 0 at every opening motion since lambda_0 > 0): it equals
    # lambda_0^T E e on the feasible set, so the simplex moves e, not every c to its
    # bound as sum(c) would (measured: docs/notes/network-constants.md)
    x = _max_lp(np.r_[rigid.self_stress, np.zeros(k)], np.hstack([N.T, -NE]), zero, zero,
                np.r_[np.zeros(nc), -np.ones(k)], np.ones(nc + k))
    if x is None:
        return "unclear", None
    c, e = x[:nc], x[nc:]
    if c.sum() <= rtol * nc:
        return "rigid", None
    y = rigid.lu.solve(np.asarray(J.T @ (c - E @ e)))
    return _scaled(J, E, y, e)


def _max_lp(cost, A, row_lower, row_upper, col_lower, col_upper) -> NDArray[np.float64] | None:
    """``argmax cost . x`` subject to ``row_lower <= A x <= row_upper`` and column bounds
    (dense ``A``; dual simplex, one thread), or None when not solved to optimality."""
    csc = sp.csc_matrix(A)
    csc.sort_indices()
    lp = colwise_lp(csc, -np.asarray(cost, dtype=np.float64), col_lower, col_upper, row_lower, row_upper)
    h = new_highs()
    h.setOptionValue("solver", "simplex")
    h.passModel(lp)
    h.run()
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return None
    return np.asarray(h.getSolution().col_value, dtype=np.float64)


def _scaled(J, E, y, e) -> tuple[str, NDArray[np.float64] | None]:
    z = np.concatenate([y, e])
    size = float(np.abs(z).max())
    if size == 0.0:
        return "unclear", None
    opening = (J @ y + E @ e) / size
    return ("motion", z / size) if opening.min() >= -1e-9 else ("unclear", None)
