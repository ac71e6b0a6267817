"""Numba kernels of the link constraints: link geometry, per-cluster Gram factorisation and solves,
Newton re-affixing and the compiled FIRE loop of linked spheres.

A link ``k = (i_k, j_k)`` has the constraint-gradient row ``-w_k`` on sphere ``i_k`` and
``+w_k`` on ``j_k`` (``w_k = u_k`` in a fixed box, ``F^T u_k`` with strain). Clusters
(connected components of the link graph) share no spheres, so the Gram matrix
``G = Omega Omega^T`` is block diagonal with one ``m_c x m_c`` block per cluster of
``m_c`` links, ``G_kl = s_kl w_k . w_l`` with ``s_kl`` the signed count of shared
ends. Each block is Cholesky-factorised in place (``G_c = L_c L_c^T``); ``L_c`` has the
diagonal of the ``R`` of a Householder QR of ``Omega_c^T`` (``R^T R = G_c``), so the
rank test ``min L_kk < rtol max L_kk`` is the QR test, resolvable down to
``rtol ~ sqrt(machine epsilon) = 1e-8`` (:data:`jamflow.tolerances.LINK_RANK_RTOL`).

Layout (cluster order): the factor kernels take the links sorted cluster by cluster
(by their ends within a cluster, so a chain's links couple only near neighbours),
cluster ``c`` owning links ``cptr[c]:cptr[c+1]``; its factor is
``chol[fptr[c]:fptr[c+1]]`` (row-major ``m_c x m_c``, lower triangle) with the signs
``s_kl`` beside it in ``sign``. Row ``a`` of a block is zero left of its first
coupled link ``first[a]`` (local index), and the Cholesky factor keeps that envelope,
so factors and solves cost ``m`` times the squared envelope width, not ``m^3``
(chains of 30 spheres with frozen angles: width 3, not 57). All kernels are
single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ..minimize._fire_kernels import (
    BELOW,
    CONVERGED,
    MAX_STEPS,
    REBUILD,
    STALLED,
    _axpy,
    _dot,
    _fire_adapt,
    _fire_mixing,
    _fire_step_back,
    _max_force_sq,
    _mix_and_move,
)
from ..neighbors._verlet_kernels import _inline_list, _list_buffers, _needs_rebuild
from ._hinge_kernels import hinge_advance, hinge_place, hinge_project
from .spheres._kernels import pair_forces


@njit(cache=True)
def _link_lengths(x, li, lj, offset, length, v, r):
    """Link vectors ``v`` (L, d) and lengths ``r`` (L,) of centres ``x`` (N, d), not normalised; returns ``max |r - l| / l``."""
    d = x.shape[1]
    err = 0.0
    for k in range(li.shape[0]):
        s = 0.0
        for a in range(d):
            t = x[lj[k], a] - x[li[k], a] + offset[k, a]
            v[k, a] = t
            s += t * t
        rk = np.sqrt(s)
        r[k] = rk
        err = max(err, abs(rk - length[k]) / length[k])
    return err


@njit(cache=True, inline="always")
def _unit_rows(v, r, w):
    """Rows ``w`` (L, d) set to the unit vectors of the link vectors ``v`` of lengths ``r``."""
    for k in range(v.shape[0]):
        s = 1.0 / r[k]
        for a in range(v.shape[1]):
            w[k, a] = v[k, a] * s


@njit(cache=True)
def link_geometry(x, li, lj, offset, length, u, r):
    """Unit link vectors ``u`` (L, d) and lengths ``r`` (L,) of centres ``x`` (N, d); returns ``max |r - l| / l``."""
    err = _link_lengths(x, li, lj, offset, length, u, r)
    _unit_rows(u, r, u)
    return err


@njit(cache=True)
def gram_structure(li, lj, cptr, fptr, sign, first):
    """Signs ``s_kl`` (shared ends of links ``k``, ``l``; cluster order) into ``sign`` and each row's first coupled link."""
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        base = fptr[c]
        for a in range(m):
            ka = k0 + a
            first[ka] = a
            for b in range(a + 1):
                kb = k0 + b
                s = 0.0
                if lj[ka] == lj[kb]:
                    s += 1.0
                if li[ka] == li[kb]:
                    s += 1.0
                if lj[ka] == li[kb]:
                    s -= 1.0
                if li[ka] == lj[kb]:
                    s -= 1.0
                sign[base + a * m + b] = s
                if s != 0.0 and b < first[ka]:
                    first[ka] = b


@njit(cache=True, inline="always")
def _factor_block(w, sign, first, k0, m, base, chol, rank_rtol):
    """Cholesky factor of one cluster's Gram block (links ``k0:k0+m``) into ``chol[base:]``; whether it has full rank.

    Full rank: every pivot positive and the smallest at least ``rank_rtol`` of the largest.
    """
    d = w.shape[1]
    lmax = 0.0
    lmin = np.inf
    for a in range(m):
        fa = first[k0 + a]
        for b in range(fa, a + 1):
            fb = first[k0 + b]
            t = 0.0
            s = sign[base + a * m + b]
            if s != 0.0:
                for e in range(d):
                    t += w[k0 + a, e] * w[k0 + b, e]
                t *= s
            for p in range(max(fa, fb), b):
                t -= chol[base + a * m + p] * chol[base + b * m + p]
            if b < a:
                chol[base + a * m + b] = t / chol[base + b * m + b]
            else:
                if not t > 0.0:
                    return False
                laa = np.sqrt(t)
                chol[base + a * m + a] = laa
                lmax = max(lmax, laa)
                lmin = min(lmin, laa)
    return not lmin < rank_rtol * lmax


@njit(cache=True)
def gram_factor(w, sign, first, cptr, fptr, chol, rank_rtol):
    """Cholesky factors of every cluster's Gram block (rows ``w`` in cluster order) in ``chol``.

    Returns the first degenerate cluster (smallest pivot below ``rank_rtol`` of the
    largest, or not positive) or -1.
    """
    for c in range(cptr.shape[0] - 1):
        if not _factor_block(w, sign, first, cptr[c], cptr[c + 1] - cptr[c], fptr[c], chol, rank_rtol):
            return c
    return -1


@njit(cache=True, inline="always")
def _pivots_inverse(chol, base, m, out):
    """Reciprocals of the pivots of one cluster's factor into ``out[:m]``."""
    for a in range(m):
        out[a] = 1.0 / chol[base + a * m + a]


@njit(cache=True, inline="always")
def _all_pivots_inverse(cptr, fptr, chol, pinv):
    """The reciprocal pivots of every cluster's factor into ``pinv`` (L,), cluster order."""
    for c in range(cptr.shape[0] - 1):
        _pivots_inverse(chol, fptr[c], cptr[c + 1] - cptr[c], pinv[cptr[c]:])


@njit(cache=True, inline="always")
def _block_solve_inv(first, k0, m, base, chol, pinv, b):
    """``b <- G_c^-1 b`` for one cluster's local vector ``b`` (m,), through its envelope factor and the
    reciprocals ``pinv`` of its pivots (multiplied, not divided: the solves of small blocks are
    chains of dependent operations, and a division is the slowest link)."""
    for i in range(m):
        t = b[i]
        for p in range(first[k0 + i], i):
            t -= chol[base + i * m + p] * b[p]
        b[i] = t * pinv[i]
    for i in range(m - 1, -1, -1):
        t = b[i] * pinv[i]
        b[i] = t
        for p in range(first[k0 + i], i):
            b[p] -= chol[base + i * m + p] * t


@njit(cache=True)
def gram_solve(first, cptr, fptr, chol, rhs):
    """``rhs <- G^-1 rhs`` in place, ``rhs`` (L, k) in cluster order.

    A forward and a back substitution per column, dividing by the pivots (the
    shear-stabilised engine's solves; :func:`_block_solve_inv` multiplies by their
    reciprocals, which measured no faster here and would change this path's round-off);
    the columns are the inner loop, so a cluster's factor is read once for all of them.
    """
    ncol = rhs.shape[1]
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(m):  # L z = b
            f = first[k0 + i]
            pivot = chol[base + i * m + i]
            for col in range(ncol):
                t = rhs[k0 + i, col]
                for p in range(f, i):
                    t -= chol[base + i * m + p] * rhs[k0 + p, col]
                rhs[k0 + i, col] = t / pivot
        for i in range(m - 1, -1, -1):  # L^T y = z, by columns
            f = first[k0 + i]
            pivot = chol[base + i * m + i]
            for col in range(ncol):
                t = rhs[k0 + i, col] / pivot
                rhs[k0 + i, col] = t
                for p in range(f, i):
                    rhs[k0 + p, col] -= chol[base + i * m + p] * t


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
def _det_inverse(F):
    """``det F`` and ``F^-1`` of a small matrix: closed forms for d = 2 and 3 (no LAPACK call per step)."""
    d = F.shape[0]
    if d == 2:
        det = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
        inv = np.empty((2, 2))
        inv[0, 0] = F[1, 1] / det
        inv[0, 1] = -F[0, 1] / det
        inv[1, 0] = -F[1, 0] / det
        inv[1, 1] = F[0, 0] / det
        return det, inv
    if d == 3:
        inv = np.empty((3, 3))
        for a in range(3):
            a1, a2 = (a + 1) % 3, (a + 2) % 3
            for b in range(3):
                b1, b2 = (b + 1) % 3, (b + 2) % 3
                # cofactor of F[b, a]
                inv[a, b] = F[b1, a1] * F[b2, a2] - F[b1, a2] * F[b2, a1]
        det = F[0, 0] * inv[0, 0] + F[0, 1] * inv[1, 0] + F[0, 2] * inv[2, 0]
        for a in range(3):
            for b in range(3):
                inv[a, b] /= det
        return det, inv
    # C order like the closed forms: one compiled layout for every caller of the inverse
    return np.linalg.det(F), np.ascontiguousarray(np.linalg.inv(F))


@njit(cache=True)
def strain_state(e, h0, scale):
    """Deformation of scaled strain components ``e`` (m,) in the reference box ``h0`` (d, d).

    Returns ``F = 1 + eps`` (``eps_aa = e / scale``, ``eps_ab = e / (sqrt 2 scale)``, components in
    ``numpy.triu_indices`` order), ``Q`` and ``T = Q^T F`` with ``F h0 = Q U`` (``U`` upper
    triangular with a positive diagonal, zeros below it), ``U``, ``det F`` and ``F^-1``. The
    QR is Gram–Schmidt applied twice (orthogonal to round-off for the well-conditioned
    boxes of a packing; no LAPACK call, which cost more than the arithmetic at d <= 3).
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
    M = F @ h0
    Q = np.zeros((d, d))
    U = np.zeros((d, d))
    v = np.empty(d)
    for k in range(d):
        for a in range(d):
            v[a] = M[a, k]
        for _ in range(2):
            for j in range(k):
                t = 0.0
                for a in range(d):
                    t += Q[a, j] * v[a]
                U[j, k] += t
                for a in range(d):
                    v[a] -= t * Q[a, j]
        norm = 0.0
        for a in range(d):
            norm += v[a] * v[a]
        norm = np.sqrt(norm)
        U[k, k] = norm
        for a in range(d):
            Q[a, k] = v[a] / norm
    T = np.zeros((d, d))
    for a in range(d):
        for b in range(a, d):
            t = 0.0
            for c in range(d):
                t += Q[c, a] * F[c, b]
            T[a, b] = t
    det, inv = _det_inverse(F)
    return F, Q, T, U, det, inv


@njit(cache=True)
def gram_project(w, li, lj, first, cptr, fptr, chol, g, lam):
    """``g <- g - Omega^T lam`` with ``lam = G^-1 Omega g`` in place, cluster by cluster, two passes.

    Links in cluster order. The second pass projects what the first left (``Omega g``
    at round-off times ``cond(G)``) and its multipliers are added to ``lam`` (L,), so
    ``lam`` are the least-squares multipliers of the input ``g`` (N, d).
    """
    d = w.shape[1]
    mmax = 0
    for c in range(cptr.shape[0] - 1):
        mmax = max(mmax, cptr[c + 1] - cptr[c])
    b = np.empty(mmax)
    pinv = np.empty(mmax)
    for k in range(lam.shape[0]):
        lam[k] = 0.0
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        m = cptr[c + 1] - k0
        _pivots_inverse(chol, fptr[c], m, pinv)
        for _ in range(2):
            for a in range(m):
                k = k0 + a
                s = 0.0
                for e in range(d):
                    s += w[k, e] * (g[lj[k], e] - g[li[k], e])
                b[a] = s
            _block_solve_inv(first, k0, m, fptr[c], chol, pinv, b)
            for a in range(m):
                k = k0 + a
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


@njit(cache=True, inline="always")
def _block_solve_pair(first, k0, m, base, chol, pinv, b, c):
    """``b <- G_c^-1 b`` and ``c <- G_c^-1 c`` side by side (:func:`_block_solve_inv` twice, interleaved)."""
    for i in range(m):
        t = b[i]
        s = c[i]
        for p in range(first[k0 + i], i):
            f = chol[base + i * m + p]
            t -= f * b[p]
            s -= f * c[p]
        b[i] = t * pinv[i]
        c[i] = s * pinv[i]
    for i in range(m - 1, -1, -1):
        t = b[i] * pinv[i]
        s = c[i] * pinv[i]
        b[i] = t
        c[i] = s
        for p in range(first[k0 + i], i):
            f = chol[base + i * m + p]
            b[p] -= f * t
            c[p] -= f * s


@njit(cache=True)
def gram_project_pair(w, li, lj, first, cptr, fptr, chol, g, v):
    """``g`` and ``v`` (N, d) projected in place onto the tangent space, links in cluster order.

    The projection of :func:`gram_project` (two passes) applied to both vectors of a
    FIRE step at once, each pass in flat loops over all links (``Omega g``, ``Omega v``),
    all clusters (the two solves side by side) and all links again (the subtraction).
    Clusters share no spheres, so every vector takes :func:`gram_project`'s operations
    in its order: the same bits. A cluster's solve is a chain of dependent operations;
    flat loops and two interleaved solves keep independent work in flight
    (docs/notes/chains.md, "3D chains: the cost of a linked step").
    """
    d = w.shape[1]
    L = li.shape[0]
    b = np.empty(L)
    bv = np.empty(L)
    pinv = np.empty(L)
    _all_pivots_inverse(cptr, fptr, chol, pinv)
    for _ in range(2):
        for k in range(L):
            s = 0.0
            s2 = 0.0
            for e in range(d):
                s += w[k, e] * (g[lj[k], e] - g[li[k], e])
                s2 += w[k, e] * (v[lj[k], e] - v[li[k], e])
            b[k] = s
            bv[k] = s2
        for c in range(cptr.shape[0] - 1):
            k0 = cptr[c]
            _block_solve_pair(first, k0, cptr[c + 1] - k0, fptr[c], chol, pinv[k0:], b[k0:], bv[k0:])
        for k in range(L):
            for e in range(d):
                t = b[k] * w[k, e]
                g[lj[k], e] -= t
                g[li[k], e] += t
                t = bv[k] * w[k, e]
                v[lj[k], e] -= t
                v[li[k], e] += t


@njit(cache=True)
def reaffix(x, li, lj, offset, length, sign, first, cptr, fptr, chol, w, r, length_rtol, max_sweeps, rank_rtol):
    """Newton re-affixing of ``x`` (N, d) in place, and the Gram factors of the result.

    Links in cluster order. On entry ``w`` (L, d) and ``chol`` are the rows and factors
    of a nearby point (a minimiser's last point, one step away). Minimum-norm sweeps
    ``x -= Omega_w^T G_w^-1 (r - l)`` until ``max |r - l| / l <= length_rtol``: chord
    sweeps on the entry factors (convergence at the rate ``|step| / l``, no
    factorisation) as long as each at least quarters the error, else every sweep first
    factorises at the iterate (``w <- u``: Newton). Any fixed point lies on the
    constraint manifold; the chord changes only which nearby point of it is reached,
    by the square of the step. Every sweep runs over all links and clusters in flat
    loops (independent iterations: a sweep cluster by cluster is a chain of dependent
    square roots and solves, measured slower). On return ``w`` holds the unit link
    vectors of ``x``, ``r`` their lengths and ``chol`` their factors.

    Returns
    -------
    sweeps, bad
        ``sweeps`` -1 when ``max_sweeps`` did not suffice; ``bad`` the first degenerate
        cluster or -1.
    """
    v = np.empty_like(w)
    lam = np.empty(li.shape[0])
    pinv = np.empty(li.shape[0])
    _all_pivots_inverse(cptr, fptr, chol, pinv)
    chord = True
    previous = np.inf
    for sweep in range(max_sweeps + 1):
        err = _link_lengths(x, li, lj, offset, length, v, r)
        if err <= length_rtol:
            _unit_rows(v, r, w)
            return sweep, gram_factor(w, sign, first, cptr, fptr, chol, rank_rtol)
        if sweep == max_sweeps:
            break
        chord = chord and err <= 0.25 * previous
        if not chord:
            _unit_rows(v, r, w)
            bad = gram_factor(w, sign, first, cptr, fptr, chol, rank_rtol)
            if bad >= 0:
                return sweep, bad
            _all_pivots_inverse(cptr, fptr, chol, pinv)
        previous = err
        for k in range(lam.shape[0]):
            lam[k] = r[k] - length[k]
        for c in range(cptr.shape[0] - 1):
            k0 = cptr[c]
            _block_solve_inv(first, k0, cptr[c + 1] - k0, fptr[c], chol, pinv[k0:], lam[k0:])
        omega_t_subtract(w, li, lj, lam, x)
    return -1, -1


@njit(cache=True, inline="always")
def _centroid_2d(x, members, shift, a, b):
    """Centroid of the unwrapped positions ``x + shift`` of cluster members ``members[a:b]``."""
    cx = 0.0
    cy = 0.0
    for k in range(a, b):
        s = members[k]
        cx += x[s, 0] + shift[k, 0]
        cy += x[s, 1] + shift[k, 1]
    return cx / (b - a), cy / (b - a)


@njit(cache=True, inline="always")
def is_linked(adj_ptr, adj, i, j):
    """Whether ``j`` is among the partners ``adj[adj_ptr[i]:adj_ptr[i + 1]]`` linked to ``i``."""
    for k in range(adj_ptr[i], adj_ptr[i + 1]):
        if adj[k] == j:
            return True
    return False


@njit(cache=True)
def rigid_project_2d(x, rptr, members, shift, g):
    """``g`` (N, 2) projected in place onto the rigid motions of each rigid 2D cluster.

    Cluster ``c`` holds spheres ``members[rptr[c]:rptr[c+1]]`` at the unwrapped
    positions ``x + shift``. Its tangent space is spanned by the two translations and
    the rotation about the centroid (orthogonal to each other), so the projection is
    ``g_s <- F / n + (tau / I) e_z x r_s`` with the total force ``F``, the torque
    ``tau`` and ``I = sum |r_s|^2`` about the centroid: the projection ``P g`` of the
    Gram path, without a factorisation.
    """
    for c in range(rptr.shape[0] - 1):
        a, b = rptr[c], rptr[c + 1]
        n = b - a
        cx, cy = _centroid_2d(x, members, shift, a, b)
        fx = 0.0
        fy = 0.0
        tau = 0.0
        inertia = 0.0
        for k in range(a, b):
            s = members[k]
            rx = x[s, 0] + shift[k, 0] - cx
            ry = x[s, 1] + shift[k, 1] - cy
            fx += g[s, 0]
            fy += g[s, 1]
            tau += rx * g[s, 1] - ry * g[s, 0]
            inertia += rx * rx + ry * ry
        omega = tau / inertia
        for k in range(a, b):
            s = members[k]
            rx = x[s, 0] + shift[k, 0] - cx
            ry = x[s, 1] + shift[k, 1] - cy
            g[s, 0] = fx / n - omega * ry
            g[s, 1] = fy / n + omega * rx


@njit(cache=True)
def rigid_place_2d(x, rptr, members, shift, ref):
    """Each rigid 2D cluster moved in place to the rigid placement of its shape ``ref`` nearest to ``x``.

    ``ref`` (M, 2) are the members' offsets from the centroid in the body frame.
    The least-squares placement (Kabsch) keeps the centroid and turns ``ref`` by the
    angle of ``sum ref_s . r_s`` and ``sum ref_s x r_s``: the closest point of the
    constraint manifold (the limit Newton re-affixing approaches), exact to round-off.
    """
    for c in range(rptr.shape[0] - 1):
        a, b = rptr[c], rptr[c + 1]
        cx, cy = _centroid_2d(x, members, shift, a, b)
        dot = 0.0
        cross = 0.0
        for k in range(a, b):
            s = members[k]
            rx = x[s, 0] + shift[k, 0] - cx
            ry = x[s, 1] + shift[k, 1] - cy
            dot += ref[k, 0] * rx + ref[k, 1] * ry
            cross += ref[k, 0] * ry - ref[k, 1] * rx
        h = np.sqrt(dot * dot + cross * cross)
        cos = dot / h
        sin = cross / h
        for k in range(a, b):
            s = members[k]
            x[s, 0] = cx + cos * ref[k, 0] - sin * ref[k, 1] - shift[k, 0]
            x[s, 1] = cy + sin * ref[k, 0] + cos * ref[k, 1] - shift[k, 1]


@njit(cache=True)
def unlinked_pairs(pi, pj, offset, sigma, adj_ptr, adj):
    """Drop linked pairs from a pair list in place (compacted); returns the count kept.

    ``adj[adj_ptr[i]:adj_ptr[i + 1]]`` are the partners ``j > i`` linked to ``i`` (any
    periodic image: a linked pair never interacts).
    """
    kept = 0
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        if is_linked(adj_ptr, adj, i, j):
            continue
        pi[kept] = i
        pj[kept] = j
        sigma[kept] = sigma[p]
        for a in range(offset.shape[1]):
            offset[kept, a] = offset[p, a]
        kept += 1
    return kept


@njit(cache=True)
def linked_fire(
    x, v, fire_state, fire_params,
    offset, pi, pj, sigma, eps, w_exp, x_build, reach, skin, lengths, diameter, adj_ptr, adj,
    li, lj, link_offset, length, sign, first, cptr, fptr, chol, w, r, rptr, members, shift, ref,
    hinge_spheres, hinge_shift, hinge_body, hinge_state, hinge_geo,
    length_rtol, max_sweeps, rank_rtol, force_tol, max_steps, energy_floor, force,
):
    """FIRE 2.0 of linked spheres at fixed box in one compiled loop (the steps of :class:`~jamflow.minimize.fire._ModelFire`).

    Unit masses; links in cluster order. Every step: FIRE control
    (:mod:`jamflow.minimize._fire_kernels`), move, re-affixing and the Gram factors at
    the new point (:func:`reaffix`, cluster by cluster, chord sweeps with the last
    point's factors), pair forces of the unlinked listed pairs (exponent ``w_exp``),
    and the force and the velocity projected onto the tangent space
    (:func:`gram_project_pair`). Rigid 2D
    clusters (``rptr``, ``members``, ``shift``, ``ref`` of :func:`rigid_place_2d`; their
    links are not among ``li``, ``lj``) are projected onto their rigid motions
    (:func:`rigid_project_2d`) and placed rigidly instead. Hinged 3D clusters
    (``hinge_*``: the arrays of :mod:`._hinge_kernels`, their links not among ``li``, ``lj``,
    ``hinge_geo`` set at ``x`` on entry) are projected in closed form
    (:func:`~._hinge_kernels.hinge_project`) and moved in their generalised coordinates
    (:func:`~._hinge_kernels.hinge_advance`, :func:`~._hinge_kernels.hinge_place`). ``x`` (N, d)
    must lie on the constraint manifold with ``w``, ``r`` its link geometry (unit
    vectors, lengths) on entry;
    the velocity is projected at ``x`` on entry (after a return for a rebuild it was
    not yet).

    A move whose displacements use up the skin rebuilds the list before the forces
    are evaluated, so every force comes from a valid list (as in the model's own
    :meth:`evaluate`): inside the loop in an orthogonal box of sides ``lengths`` (the
    call of :class:`~jamflow.neighbors.verlet.NeighborList`, without the linked pairs
    of ``adj_ptr``, ``adj``; :func:`unlinked_pairs`), else by returning ``REBUILD``
    (``lengths`` empty, or a box too small for the reach) for the caller's build and
    re-entry. ``x_build`` is updated in place. ``energy_floor`` > 0 stops the run
    (``BELOW``) once the pair energy plus the kinetic energy is at or below it.

    Returns
    -------
    status, steps, energy, n_contact, max_force_sq, sweeps, bad, builds, pi, pj, offset, sigma
        ``status`` of :mod:`jamflow.minimize._fire_kernels` (``STALLED``: re-affixing did
        not converge, or the links of cluster ``bad`` are degenerate); ``sweeps`` the
        re-affixing sweeps (per re-affixing the most any cluster took) and ``builds``
        the lists built in the call; the list in use.
    """
    d = x.shape[1]
    dt, alpha, npos = fire_state[0], fire_state[1], int(fire_state[2])
    done = int(fire_state[3])
    dt_max, dt_min, f_inc, f_dec = fire_params[0], fire_params[1], fire_params[2], fire_params[3]
    alpha0, f_alpha, n_delay = fire_params[4], fire_params[5], int(fire_params[6])
    initial_delay = fire_params[7] > 0.0
    links = li.shape[0] > 0
    rigid = rptr.shape[0] > 1
    hinged = hinge_spheres.shape[0] > 0
    virial = np.zeros((d, d))
    shortest = np.inf if lengths.shape[0] else 0.0
    for a in range(lengths.shape[0]):
        shortest = min(shortest, lengths[a])
    buffers = _list_buffers(x.shape[0] if lengths.shape[0] else 0, d)
    builds = 0
    energy = 0.0
    n_contact = 0
    fmax2 = np.inf
    sweeps = 0
    bad = -1
    status = MAX_STEPS
    step = 0
    if links:
        bad = gram_factor(w, sign, first, cptr, fptr, chol, rank_rtol)
        if bad >= 0:
            status = STALLED
    while status != STALLED:
        # evaluation at x (re-affixing left its Gram factors): a valid list, forces and velocity projected
        if _needs_rebuild(x, x_build, 1.0, 1.0, reach, skin, 0.0):
            if not reach < 0.5 * shortest:
                status = REBUILD
                break
            pi, pj, _, offset, sigma, buffers = _inline_list(x, 1.0, lengths, diameter, reach, skin, buffers)
            kept = unlinked_pairs(pi, pj, offset, sigma, adj_ptr, adj)
            pi, pj, offset, sigma = pi[:kept], pj[:kept], offset[:kept], sigma[:kept]
            x_build[:, :] = x
            builds += 1
        energy, n_contact = pair_forces(x, 1.0, offset, pi, pj, sigma, eps, w_exp, force, virial, False)
        if links:
            gram_project_pair(w, li, lj, first, cptr, fptr, chol, force, v)
        if rigid:
            rigid_project_2d(x, rptr, members, shift, force)
            rigid_project_2d(x, rptr, members, shift, v)
        if hinged:
            hinge_project(hinge_spheres, hinge_geo, force)
            hinge_project(hinge_spheres, hinge_geo, v)
        fmax2 = _max_force_sq(force)
        if fmax2 <= force_tol * force_tol:
            status = CONVERGED
            break
        # unit masses: the kinetic energy of the projected velocity
        if energy_floor > 0.0 and energy + 0.5 * _dot(v, v) <= energy_floor:
            status = BELOW
            break
        if step >= max_steps:
            break
        power = _dot(force, v)
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            if hinged:
                hinge_advance(hinge_spheres, hinge_geo, hinge_state, v, -0.5 * dt)
            _fire_step_back(x, v, dt)
            if hinged:
                hinge_place(x, hinge_spheres, hinge_shift, hinge_body, hinge_state, hinge_geo)
            if rigid:
                rigid_place_2d(x, rptr, members, shift, ref)
            if links:
                n, bad = reaffix(x, li, lj, link_offset, length, sign, first, cptr, fptr, chol, w, r, length_rtol,
                                 max_sweeps, rank_rtol)
                sweeps += max(n, 0)
                if n < 0 or bad >= 0:
                    status = STALLED
                    break
        _axpy(dt, force, v)
        vnorm = np.sqrt(_dot(v, v))
        fnorm = np.sqrt(_dot(force, force))
        keep, mix = _fire_mixing(alpha, vnorm, fnorm)
        _mix_and_move(v, force, keep, mix, x, dt)
        step += 1
        if hinged:
            hinge_advance(hinge_spheres, hinge_geo, hinge_state, v, dt)
            hinge_place(x, hinge_spheres, hinge_shift, hinge_body, hinge_state, hinge_geo)
        if rigid:
            rigid_place_2d(x, rptr, members, shift, ref)
        if links:
            n, bad = reaffix(x, li, lj, link_offset, length, sign, first, cptr, fptr, chol, w, r, length_rtol,
                             max_sweeps, rank_rtol)
            sweeps += max(n, 0)
            if n < 0 or bad >= 0:
                status = STALLED
                break
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    return status, step, energy, n_contact, fmax2, sweeps, bad, builds, pi, pj, offset, sigma
