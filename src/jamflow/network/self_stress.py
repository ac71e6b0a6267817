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

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.optimize import linprog, nnls

__all__ = ["jacobian_rank", "positive_self_stress", "self_stresses"]


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
    w, v = spla.eigsh(G, k=min(k, nc - 1), sigma=shift, which="LM")
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
