"""Numba kernels of the link constraints: link geometry, per-cluster Gram factorisation and solves.

A link ``k = (i_k, j_k)`` has the constraint-gradient row ``-w_k`` on sphere ``i_k`` and
``+w_k`` on ``j_k`` (``w_k = u_k`` in a fixed box, ``F^T u_k`` with strain). Clusters
(connected components of the link graph) share no spheres, so the Gram matrix
``G = Omega Omega^T`` is block diagonal with one ``m_c x m_c`` block per cluster of
``m_c`` links, ``G_kl = s_kl w_k . w_l`` with ``s_kl`` the signed count of shared
ends. Each block is Cholesky-factorised in place (``G_c = L_c L_c^T``); ``L_c`` has the
diagonal of the ``R`` of a Householder QR of ``Omega_c^T`` (``R^T R = G_c``), so the
rank test ``min L_kk < rtol max L_kk`` is the QR test, resolvable down to
``rtol ~ sqrt(machine epsilon) = 1e-8`` (:data:`jamflow.tolerances.LINK_RANK_RTOL`).

Layout: ``order`` lists the links cluster by cluster, cluster ``c`` owning
``order[cptr[c]:cptr[c+1]]``; its factor is ``chol[fptr[c]:fptr[c+1]]`` (row-major
``m_c x m_c``, lower triangle). All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit


@njit(cache=True)
def link_geometry(x, li, lj, offset, length, u, r):
    """Unit link vectors ``u`` (L, d) and lengths ``r`` (L,) of centres ``x`` (N, d); returns ``max |r - l| / l``."""
    d = x.shape[1]
    err = 0.0
    for k in range(li.shape[0]):
        s = 0.0
        for a in range(d):
            v = x[lj[k], a] - x[li[k], a] + offset[k, a]
            u[k, a] = v
            s += v * v
        rk = np.sqrt(s)
        r[k] = rk
        for a in range(d):
            u[k, a] /= rk
        e = abs(rk / length[k] - 1.0)
        err = max(err, e)
    return err


@njit(cache=True)
def gram_factor(w, li, lj, order, cptr, fptr, chol, rank_rtol):
    """Cholesky factors of every cluster's Gram block in ``chol``; returns the first degenerate cluster or -1."""
    d = w.shape[1]
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        base = fptr[c]
        for a in range(m):
            ka = order[k0 + a]
            for b in range(a + 1):
                kb = order[k0 + b]
                s = 0.0
                if lj[ka] == lj[kb]:
                    s += 1.0
                if li[ka] == li[kb]:
                    s += 1.0
                if lj[ka] == li[kb]:
                    s -= 1.0
                if li[ka] == lj[kb]:
                    s -= 1.0
                dot = 0.0
                if s != 0.0:
                    for e in range(d):
                        dot += w[ka, e] * w[kb, e]
                chol[base + a * m + b] = s * dot
        lmax = 0.0
        lmin = np.inf
        for j in range(m):
            s = chol[base + j * m + j]
            for p in range(j):
                s -= chol[base + j * m + p] ** 2
            if not s > 0.0:
                return c
            ljj = np.sqrt(s)
            chol[base + j * m + j] = ljj
            lmax = max(lmax, ljj)
            lmin = min(lmin, ljj)
            for i in range(j + 1, m):
                t = chol[base + i * m + j]
                for p in range(j):
                    t -= chol[base + i * m + p] * chol[base + j * m + p]
                chol[base + i * m + j] = t / ljj
        if lmin < rank_rtol * lmax:
            return c
    return -1


@njit(cache=True)
def gram_solve(order, cptr, fptr, chol, rhs):
    """``rhs <- G^-1 rhs`` in place, ``rhs`` (L, k) indexed by link."""
    ncol = rhs.shape[1]
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        base = fptr[c]
        for col in range(ncol):
            for i in range(m):  # L z = b
                t = rhs[order[k0 + i], col]
                for p in range(i):
                    t -= chol[base + i * m + p] * rhs[order[k0 + p], col]
                rhs[order[k0 + i], col] = t / chol[base + i * m + i]
            for i in range(m - 1, -1, -1):  # L^T y = z
                t = rhs[order[k0 + i], col]
                for p in range(i + 1, m):
                    t -= chol[base + p * m + i] * rhs[order[k0 + p], col]
                rhs[order[k0 + i], col] = t / chol[base + i * m + i]


@njit(cache=True)
def omega_apply(w, li, lj, g, out):
    """``out = Omega g``: ``w_k . (g_j - g_i)`` per link, ``g`` (N, d), ``out`` (L,)."""
    for k in range(li.shape[0]):
        s = 0.0
        for a in range(w.shape[1]):
            s += w[k, a] * (g[lj[k], a] - g[li[k], a])
        out[k] = s


@njit(cache=True)
def omega_t_subtract(w, li, lj, lam, out):
    """``out -= Omega^T lam``: ``-lam_k w_k`` on ``j_k``, ``+lam_k w_k`` on ``i_k``; ``out`` (N, d)."""
    for k in range(li.shape[0]):
        for a in range(w.shape[1]):
            v = lam[k] * w[k, a]
            out[lj[k], a] -= v
            out[li[k], a] += v


@njit(cache=True)
def strain_state(e, h0, scale):
    """Deformation of scaled strain components ``e`` (m,) in the reference box ``h0`` (d, d).

    Returns ``F = 1 + eps`` (``eps_aa = e / scale``, ``eps_ab = e / (sqrt 2 scale)``, components in
    ``numpy.triu_indices`` order), ``Q`` and ``T = Q^T F`` with ``F h0 = Q U`` (``U`` upper
    triangular with a positive diagonal, zeros below it), ``U``, ``det F`` and ``F^-1``.
    """
    d = h0.shape[0]
    F = np.eye(d)
    p = 0
    for a in range(d):
        for b in range(a, d):
            if a == b:
                F[a, a] += e[p] / scale
            else:
                v = e[p] / (np.sqrt(2.0) * scale)
                F[a, b] += v
                F[b, a] += v
            p += 1
    Q, U = np.linalg.qr(F @ h0)
    for a in range(d):
        if U[a, a] < 0.0:
            for b in range(d):
                Q[b, a] = -Q[b, a]
                U[a, b] = -U[a, b]
    T = np.ascontiguousarray(Q.T) @ F
    for a in range(d):
        for b in range(a):
            T[a, b] = 0.0
            U[a, b] = 0.0
    return F, Q, T, U, np.linalg.det(F), np.linalg.inv(F)


@njit(cache=True)
def gram_project(w, li, lj, order, cptr, fptr, chol, g, lam):
    """``g <- g - Omega^T lam`` with ``lam = G^-1 Omega g`` in place, cluster by cluster, two passes.

    The second pass projects what the first left (``Omega g`` at round-off times
    ``cond(G)``) and its multipliers are added to ``lam`` (L,), so ``lam`` are the
    least-squares multipliers of the input ``g`` (N, d).
    """
    d = w.shape[1]
    mmax = 0
    for c in range(cptr.shape[0] - 1):
        mmax = max(mmax, cptr[c + 1] - cptr[c])
    b = np.empty(mmax)
    for k in range(lam.shape[0]):
        lam[k] = 0.0
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        base = fptr[c]
        for _ in range(2):
            for a in range(m):
                k = order[k0 + a]
                s = 0.0
                for e in range(d):
                    s += w[k, e] * (g[lj[k], e] - g[li[k], e])
                b[a] = s
            for i in range(m):
                t = b[i]
                for p in range(i):
                    t -= chol[base + i * m + p] * b[p]
                b[i] = t / chol[base + i * m + i]
            for i in range(m - 1, -1, -1):
                t = b[i]
                for p in range(i + 1, m):
                    t -= chol[base + p * m + i] * b[p]
                b[i] = t / chol[base + i * m + i]
            for a in range(m):
                k = order[k0 + a]
                lam[k] += b[a]
                for e in range(d):
                    v = b[a] * w[k, e]
                    g[lj[k], e] -= v
                    g[li[k], e] += v


@njit(cache=True)
def same(a, b):
    """Whether flat arrays ``a`` and ``b`` are equal element by element (the cache test of the link models)."""
    if a.shape[0] != b.shape[0]:
        return False
    for k in range(a.shape[0]):
        if a[k] != b[k]:
            return False
    return True
