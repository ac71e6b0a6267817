"""Rigidity matrix of a contact network, with and without strain degrees of freedom.

For a contact ``c = (i, j)`` with minimum-image vector ``r_ij = x_j - x_i`` and unit
vector ``n_ij = r_ij / |r_ij|``, displacements ``y_i`` and a symmetric strain ``eps``
of the periodic box (``x -> (I + eps) x + y``) change the separation to first order by

    delta |r_ij| = n_ij . (y_j - y_i) + |r_ij| n_ij^T eps n_ij

(soft-chains paper, Eqs. 35-38: ``R_x`` and ``R_eps``). The rigidity matrix ``R``
has one row per contact and maps a motion ``(y, eps)`` to these separation changes,
so a hard-sphere contact allows exactly the motions with ``R y >= -gap``. Its
transpose maps contact forces to net particle forces (and the contact stress), so a
self-stress is a ``lambda`` with ``R^T lambda = 0``.

Strains are coordinates in a basis of symmetric matrices: the ``d (d + 1) / 2``
elementary symmetric matrices, or, for strict jamming at fixed volume, a basis of
the ``d (d + 1) / 2 - 1`` traceless ones (``Tr eps = 0``). At first order a motion
with ``Tr eps < 0`` can always be completed by the isotropic expansion
``a I`` (``a > 0``), which opens every contact, into one with ``Tr eps = 0``, so the
volume-preserving basis tests the same thing as "volume non-increasing" in the
Torquato-Stillinger definition of strict jamming.

Roth-Whiteley theorem (used as an independent check of the LP certificate): a
framework of struts (contacts that may open but not close) is first-order rigid if
and only if the rigidity matrix has full rank (kernel = trivial motions only) and a
self-stress exists that is strictly positive on every contact. For hard spheres
first-order rigidity is rigidity (Connelly), because ``|r + dr| >= n . (r + dr)``
makes every first-order motion a finite one.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.optimize import linprog, nnls

from .packing import Packing

__all__ = [
    "contact_geometry",
    "positive_self_stress",
    "rigidity_matrix",
    "rigidity_rank",
    "strain_basis",
]


def strain_basis(d: int, volume_preserving: bool = True) -> NDArray[np.float64]:
    """Basis of symmetric strain tensors, shape (n_strain, d, d).

    Parameters
    ----------
    d : int
        Dimension.
    volume_preserving : bool
        If true, a basis of the traceless symmetric matrices (``d (d + 1) / 2 - 1``
        elements: ``E_aa - E_dd`` for ``a < d`` and ``E_ab + E_ba`` for ``a < b``);
        otherwise all ``d (d + 1) / 2`` elementary symmetric matrices.
    """
    mats = []
    for a in range(d):
        m = np.zeros((d, d))
        m[a, a] = 1.0
        if volume_preserving:
            if a == d - 1:
                continue
            m[d - 1, d - 1] = -1.0
        mats.append(m)
    for a in range(d):
        for b in range(a + 1, d):
            m = np.zeros((d, d))
            m[a, b] = m[b, a] = 1.0
            mats.append(m)
    return np.array(mats)


def contact_geometry(packing: Packing, contacts: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit vectors ``n_ij`` (Nc, d) and distances ``|r_ij|`` (Nc,) [length] of contacts."""
    c = np.asarray(contacts, dtype=np.int64).reshape(-1, 2)
    dx = packing.box.minimum_image(packing.position[c[:, 1]] - packing.position[c[:, 0]])
    r = np.linalg.norm(dx, axis=1)
    if np.any(r <= 0.0):
        raise ValueError("a contact joins two coincident centres")
    return dx / r[:, None], r


def rigidity_matrix(
    packing: Packing,
    contacts: NDArray[np.int64],
    strain: bool = False,
    volume_preserving: bool = True,
    particles: NDArray[np.int64] | None = None,
) -> sp.csr_matrix:
    """Rigidity matrix ``R`` of a contact network (see module docstring).

    Parameters
    ----------
    packing : Packing
    contacts : ndarray of int, shape (Nc, 2)
        Contact pairs; both particles must be among ``particles``.
    strain : bool
        Append strain columns (coordinates in :func:`strain_basis`).
    volume_preserving : bool
        Traceless strain basis (strict jamming at fixed volume).
    particles : ndarray of int, shape (Ns,), optional
        Particles whose displacements are columns, in this order (default: all).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (Nc, d Ns [+ n_strain])
        Row ``c`` times a motion ``(y, eps)`` is the first-order change of the
        separation ``|r_ij|`` [length]; displacement columns are particle-major
        (``d k + a`` for the ``k``-th listed particle), strain columns follow.
    """
    d, n = packing.d, packing.n
    c = np.asarray(contacts, dtype=np.int64).reshape(-1, 2)
    if particles is None:
        col_of = np.arange(n)
        ns = n
    else:
        particles = np.asarray(particles, dtype=np.int64)
        col_of = np.full(n, -1, dtype=np.int64)
        col_of[particles] = np.arange(len(particles))
        ns = len(particles)
    ci, cj = col_of[c[:, 0]], col_of[c[:, 1]]
    if np.any(ci < 0) or np.any(cj < 0):
        raise ValueError("a contact involves a particle that is not among the listed particles")
    unit, dist = contact_geometry(packing, c)
    nc = len(c)
    axis = np.arange(d)
    rows = np.repeat(np.arange(nc), 2 * d)
    cols = np.concatenate([d * ci[:, None] + axis, d * cj[:, None] + axis], axis=1).ravel()
    vals = np.concatenate([-unit, unit], axis=1).ravel()
    n_cols = d * ns
    if strain:
        basis = strain_basis(d, volume_preserving)
        # |r| n^T E_k n for every contact and basis element
        coef = dist[:, None] * np.einsum("ca,kab,cb->ck", unit, basis, unit)
        k = len(basis)
        rows = np.concatenate([rows, np.repeat(np.arange(nc), k)])
        cols = np.concatenate([cols, np.tile(n_cols + np.arange(k), nc)])
        vals = np.concatenate([vals, coef.ravel()])
        n_cols += k
    return sp.csr_matrix((vals, (rows, cols)), shape=(nc, n_cols))


def rigidity_rank(R: sp.spmatrix) -> tuple[int, NDArray[np.float64]]:
    """Rank of ``R`` from its singular values (dense SVD), and the singular values.

    The threshold is numpy's default, ``s_max * max(shape) * eps``.
    """
    dense = R.toarray() if sp.issparse(R) else np.asarray(R)
    s = np.linalg.svd(dense, compute_uv=False)
    tol = (s.max() if s.size else 0.0) * max(dense.shape) * np.finfo(float).eps
    return int(np.sum(s > tol)), s


def positive_self_stress(R: sp.spmatrix, rtol: float = 1e-9, method: str = "nnls") -> NDArray[np.float64] | None:
    """A self-stress strictly positive on every contact (``R^T lambda = 0``), or None.

    Parameters
    ----------
    R : sparse matrix, shape (Nc, n_dof)
    rtol : float
        ``"nnls"``: residual ``|R^T lambda| / (|R| |lambda|)`` regarded as zero;
        ``"lp"``: smallest accepted ``min lambda`` when ``max lambda = 1``.
    method : {"nnls", "lp"}
        ``"nnls"``: any strictly positive self-stress can be scaled to
        ``min lambda = 1``, so one exists iff ``min_{mu >= 0} |R^T (1 + mu)|``
        vanishes, a non-negative least-squares problem (Lawson-Hanson active set,
        dense; small networks). ``"lp"``: maximise ``t`` subject to
        ``R^T lambda = 0``, ``t <= lambda <= 1`` (sparse, HiGHS via scipy; the dual
        certificate of the motion LPs, for large networks).

    Returns
    -------
    ndarray, shape (Nc,) or None
        The self-stress (``min = 1`` for nnls, ``max <= 1`` for lp).
    """
    if method == "nnls":
        A = (R.T.toarray() if sp.issparse(R) else np.asarray(R).T)
        ones = np.ones(A.shape[1])
        mu, _ = nnls(A, -A @ ones, maxiter=50 * A.shape[1])
        lam = ones + mu
        scale = np.linalg.norm(A, ord=2) * np.linalg.norm(lam)
        residual = np.linalg.norm(A @ lam)
        return lam if residual <= rtol * scale else None
    if method != "lp":
        raise ValueError(f"method must be 'nnls' or 'lp', got {method!r}")
    nc, ndof = R.shape
    At = sp.csr_matrix(R.T)
    A_eq = sp.hstack([At, sp.csr_matrix((ndof, 1))], format="csr")
    A_ub = sp.hstack([-sp.identity(nc, format="csr"), sp.csr_matrix(np.ones((nc, 1)))], format="csr")
    cost = np.zeros(nc + 1)
    cost[-1] = -1.0
    res = linprog(cost, A_ub=A_ub, b_ub=np.zeros(nc), A_eq=A_eq, b_eq=np.zeros(ndof),
                  bounds=[(0.0, 1.0)] * nc + [(None, None)], method="highs")
    if res.status != 0:
        raise RuntimeError(f"self-stress LP failed: {res.message}")
    return res.x[:nc] if res.x[-1] > rtol else None
