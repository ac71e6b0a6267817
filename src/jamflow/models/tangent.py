"""Second derivatives on the constraint manifold of linked spheres, sparse (chains paper Sec. IV, Eqs. 24-33).

For any pair function ``phi(|r|)`` with ``r = F R`` (``F = 1 + eps``, ``R`` the pair
vector at zero strain, ``u = R / r``) the second derivatives at ``eps = 0`` are

- ``d2 phi / dx dx``: the block ``k = phi'' u u^T + (phi' / r) (1 - u u^T)`` (``+k`` on
  ``ii, jj``, ``-k`` on ``ij``);
- ``d2 phi / dx_j dF_cd = k_bc R_d + delta_bd phi' u_c`` (minus on ``i``);
- ``d2 phi / dF_cd dF_ef = k_ce R_d R_f``;

mapped to strain coordinates ``e`` by a linear ``dF / de`` (``J``, shape (d d, m); ``F``
is linear in ``e``, so no further term). A link is the pair function ``phi = |r|``
(its constraint ``|r| - l``); the volume constraint ``det F - 1`` has
``d2 det F / dF_ab dF_cd = delta_ab delta_cd - delta_ad delta_bc`` at ``F = 1``.

The Lagrangian Hessian ``H0 - sum_k mu_k grad^2 c_k - nu grad^2 det F`` with the
multipliers of the projection (``grad U = Gamma (mu, nu) + P grad U``) is the second
derivative of ``U`` along the manifold in any tangent direction ``v``: for a retraction
``q(s)`` with ``q'(0) = v``, ``B d(P grad U)/ds = B (H0 - sum mu_k grad^2 c_k) v`` for
rows ``B`` of the tangent space (``B Gamma = 0``), at any point, balanced or not.

Tangent bases (:func:`cluster_tangent_basis`): clusters (connected components of the
link graph) share no coordinates, so ``Null(Omega)`` is block diagonal: per cluster of
``n_c`` spheres and ``m_c`` independent links the last ``n_c d - m_c`` right singular
vectors of its ``m_c x n_c d`` block of link rows (batched over clusters of one shape).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

__all__ = ["cluster_tangent_basis", "pair_hessian", "volume_curvature"]


def pair_hessian(n: int, d: int, i: NDArray[np.int64], j: NDArray[np.int64], R: NDArray[np.float64],
                 dphi: NDArray[np.float64], d2phi: NDArray[np.float64],
                 strain_jacobian: NDArray[np.float64] | None = None) -> sp.csr_matrix:
    """``sum_p d2 phi_p(|F R_p|) / dq dq`` at zero strain (module doc), sparse (n_dof, n_dof).

    Parameters
    ----------
    n, d : int
        Sphere count and dimension.
    i, j : ndarray of int, shape (P,)
    R : ndarray, shape (P, d)
        Pair vectors ``x_j - x_i`` (periodic image included) [length].
    dphi, d2phi : ndarray, shape (P,)
        ``phi'(r)`` and ``phi''(r)``.
    strain_jacobian : ndarray, shape (d d, m), optional
        ``dF / de`` of the strain coordinates; None: centres only (``n_dof = n d``).
    """
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    r = np.linalg.norm(R, axis=1)
    u = R / r[:, None]
    uu = u[:, :, None] * u[:, None, :]
    k = d2phi[:, None, None] * uu + (dphi / r)[:, None, None] * (np.eye(d) - uu)
    m = 0 if strain_jacobian is None else strain_jacobian.shape[1]
    size = n * d + m
    a = np.arange(d)
    rows, cols, vals = [], [], []
    for I, Jx, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
        rows.append(np.broadcast_to((I[:, None] * d + a)[:, :, None], k.shape).ravel())
        cols.append(np.broadcast_to((Jx[:, None] * d + a)[:, None, :], k.shape).ravel())
        vals.append(sign * k.ravel())
    if m:
        J = strain_jacobian
        xF = np.einsum("pbc,pd->pbcd", k, R) + np.einsum("bd,pc->pbcd", np.eye(d), dphi[:, None] * u)
        xe = xF.reshape(len(i), d, d * d) @ J  # (P, d, m)
        strain_cols = n * d + np.arange(m)
        for I, sign in ((j, 1.0), (i, -1.0)):
            row = np.broadcast_to((I[:, None] * d + a)[:, :, None], xe.shape).ravel()
            col = np.broadcast_to(strain_cols[None, None, :], xe.shape).ravel()
            rows += [row, col]
            cols += [col, row]
            vals += [sign * xe.ravel(), sign * xe.ravel()]
        FF = np.einsum("pce,pd,pf->cdef", k, R, R).reshape(d * d, d * d)
        ee = J.T @ FF @ J
        rows.append(np.repeat(strain_cols, m))
        cols.append(np.tile(strain_cols, m))
        vals.append(ee.ravel())
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(size, size)).tocsr()


def volume_curvature(strain_jacobian: NDArray[np.float64]) -> NDArray[np.float64]:
    """``d2 det F / de de`` at ``F = 1``, shape (m, m), for ``dF / de`` (d d, m) (module doc)."""
    d = int(round(np.sqrt(strain_jacobian.shape[0])))
    eye = np.eye(d)
    det2 = (np.einsum("ab,cd->abcd", eye, eye) - np.einsum("ad,bc->abcd", eye, eye)).reshape(d * d, d * d)
    return strain_jacobian.T @ det2 @ strain_jacobian


def cluster_tangent_basis(labels: NDArray[np.int64], i: NDArray[np.int64], j: NDArray[np.int64],
                          w: NDArray[np.float64]) -> sp.csr_matrix:
    """Orthonormal basis of ``Null(Omega)`` (columns), sparse (N d, N d - rank), block diagonal by cluster.

    ``Omega`` has one row per link ``k``: ``-w_k`` on the coordinates of ``i_k``, ``+w_k`` on
    those of ``j_k`` (module doc). Clusters of one sphere keep their ``d`` coordinates. The
    rank of each cluster's block is its link count (the models' Gram factorisation refuses
    degenerate links before any Hessian is asked for).

    Parameters
    ----------
    labels : ndarray of int, shape (N,)
        Cluster label per sphere (:meth:`~jamflow.state.bodies.Links.clusters`).
    i, j : ndarray of int, shape (L,)
    w : ndarray, shape (L, d)
        Link rows (unit link vectors, or ``F^T u`` in strain coordinates).
    """
    n, d = len(labels), w.shape[1] if w.ndim == 2 else 0
    order = np.argsort(labels, kind="stable")
    size = np.bincount(labels)
    start = np.concatenate([[0], np.cumsum(size)])
    local = np.empty(n, np.int64)
    local[order] = np.arange(n) - start[labels[order]]
    n_links = np.bincount(labels[i], minlength=len(size)) if len(i) else np.zeros(len(size), np.int64)
    link_order = np.argsort(labels[i], kind="stable") if len(i) else np.empty(0, np.int64)
    link_start = np.concatenate([[0], np.cumsum(n_links)])
    rows, cols, vals = [], [], []
    col0 = 0
    shapes = np.stack([size, n_links], axis=1)
    for s, mc in np.unique(shapes, axis=0):
        clusters = np.flatnonzero((size == s) & (n_links == mc))
        C, width = len(clusters), int(s) * d
        block = np.zeros((C, int(mc), width))
        if mc:
            k = link_order[link_start[clusters][:, None] + np.arange(mc)]  # (C, mc) links of each cluster
            c_idx = np.arange(C)[:, None, None]
            r_idx = np.arange(mc)[None, :, None]
            span = np.arange(d)[None, None, :]
            block[c_idx, r_idx, local[i[k]][:, :, None] * d + span] -= w[k]
            block[c_idx, r_idx, local[j[k]][:, :, None] * d + span] += w[k]
            basis = np.linalg.svd(block, full_matrices=True)[2][:, mc:, :]  # (C, width - mc, width)
        else:
            basis = np.broadcast_to(np.eye(width), (C, width, width))
        t = width - int(mc)
        spheres = order[start[clusters][:, None] + np.arange(s)]  # (C, s) in local order
        coord = (spheres[:, :, None] * d + np.arange(d)).reshape(C, width)
        rows.append(np.broadcast_to(coord[:, None, :], basis.shape).ravel())
        cols.append(np.broadcast_to((col0 + np.arange(C)[:, None] * t + np.arange(t))[:, :, None],
                                    basis.shape).ravel())
        vals.append(basis.ravel())
        col0 += C * t
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n * d, col0)).tocsr()
