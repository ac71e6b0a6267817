"""Numba kernels of the constraint solve of shear-stabilised linked spheres: Woodbury and Schur on the Gram factors.

``Gamma^T Gamma`` of :class:`jamflow.models.strain.ShearStabilizedModel` (links and the
volume; the module doc of :mod:`jamflow.models.strain` has the equations) is
``[[K, b], [b^T, ce . ce]]`` with ``K = A + Be Be^T``, ``A = L L^T`` the per-cluster Gram
factors of the link rows ``w = F^T u`` (:func:`jamflow.models._link_kernels.gram_factor`),
``Be`` (L, m) the links' strain columns and ``b = Be ce``. With ``Z = L^-1 Be`` and
``S = Z^T Z`` the Woodbury identity gives ``K^-1 r = L^-T (z - Z small Z^T z)``
(``z = L^-1 r``, ``small = (1 + S)^-1``), ``Be^T K^-1 r = small Z^T z`` and
``Be^T K^-1 Be = 1 - small``, so the volume row's Schur complement is ``ce . small ce``
and a solve needs one forward and one back substitution per column, no ``A^-1 Be``
and no vector of link length beyond ``Z``. Links in cluster order (:mod:`._link_kernels`).

The per-link loops over the strain components have d = 3 (``m = 6``) versions with the
components unrolled into registers (:func:`_rows_3d`, :func:`_z_rows_6`,
:func:`_forward_6`, :func:`_back_6`): the same operations in the same order as the
generic loops, so the same bits, without the generic loops' memory round trips
(docs/notes/chains.md, "3D chains shear-stabilised: the Woodbury solve and the deformed frame").
All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ._link_kernels import _all_pivots_inverse, _det_inverse, gram_factor


@njit(cache=True)
def strain_solver(F, det, Finv, R0, u, sign, first, cptr, fptr, chol, pinv, w, Be, Z, S, ce, sce, scale, rank_rtol):
    """The factorisation of ``Gamma^T Gamma`` at a point (geometry ``R0``, ``u`` of
    :func:`jamflow.models._strain_kernels.strain_links`; module doc).

    Fills ``w`` (rows ``F^T u``), ``Be``, the Gram factors ``chol`` (``A = L L^T``) and the
    reciprocals ``pinv`` of their pivots, ``Z = L^-1 Be`` (forward substitution only),
    ``S = Z^T Z = Be^T A^-1 Be`` (accumulated in the same pass), ``ce`` and ``sce = small ce``.
    Returns ``(bad, small, schur)``: the first degenerate cluster or -1, the capacitance
    inverse ``small = (1 + S)^-1`` and the volume row's Schur complement ``ce . small ce``.
    """
    d = F.shape[0]
    L = w.shape[0]
    m = Be.shape[1]
    on = 1.0 / scale  # the weights of the components, multiplied per link (no division per link)
    off = 1.0 / (np.sqrt(2.0) * scale)
    if d == 3:
        _rows_3d(F, R0, u, on, off, w, Be)
    else:
        _rows(F, R0, u, on, off, w, Be)
    p = 0
    for a in range(d):
        for c in range(a, d):
            # G = det F F^-T: G[a, c] = det Finv[c, a]
            if a == c:
                ce[p] = det * Finv[a, a] / scale
            else:
                ce[p] = det * (Finv[c, a] + Finv[a, c]) / (np.sqrt(2.0) * scale)
            p += 1
    small = np.eye(m)
    if L:
        bad = gram_factor(w, sign, first, cptr, fptr, chol, rank_rtol)
        if bad >= 0:
            return bad, small, 1.0
        _all_pivots_inverse(cptr, fptr, chol, pinv)
    if m == 6:
        _z_rows_6(first, cptr, fptr, chol, pinv, Be, Z, S)
    else:
        _z_rows(first, cptr, fptr, chol, pinv, Be, Z, S)
    for a in range(m):
        for b in range(a):
            S[a, b] = S[b, a]
    small += S
    small = _det_inverse(small)[1]
    schur = 0.0
    for a in range(m):
        t = 0.0
        for b in range(m):
            t += small[a, b] * ce[b]
        sce[a] = t
        schur += ce[a] * t
    return -1, small, schur


@njit(cache=True)
def _rows(F, R0, u, on, off, w, Be):
    """Link rows ``w = F^T u`` (L, d) and strain columns ``Be`` (L, m): ``u R0^T`` symmetrised, weighted ``on`` on
    and ``off`` off the diagonal (``1 / q_s``, ``1 / (sqrt 2 q_s)``), components in ``numpy.triu_indices`` order."""
    d = F.shape[0]
    for k in range(w.shape[0]):
        for a in range(d):
            t = 0.0
            for c in range(d):
                t += F[c, a] * u[k, c]
            w[k, a] = t
        p = 0
        for a in range(d):
            for c in range(a, d):
                if a == c:
                    Be[k, p] = u[k, a] * R0[k, a] * on
                else:
                    Be[k, p] = (u[k, a] * R0[k, c] + u[k, c] * R0[k, a]) * off
                p += 1


@njit(cache=True)
def _rows_3d(F, R0, u, on, off, w, Be):
    """:func:`_rows` for d = 3, unrolled (the same operations in the same order)."""
    for k in range(w.shape[0]):
        u0 = u[k, 0]
        u1 = u[k, 1]
        u2 = u[k, 2]
        r0 = R0[k, 0]
        r1 = R0[k, 1]
        r2 = R0[k, 2]
        w[k, 0] = F[0, 0] * u0 + F[1, 0] * u1 + F[2, 0] * u2
        w[k, 1] = F[0, 1] * u0 + F[1, 1] * u1 + F[2, 1] * u2
        w[k, 2] = F[0, 2] * u0 + F[1, 2] * u1 + F[2, 2] * u2
        Be[k, 0] = u0 * r0 * on
        Be[k, 1] = (u0 * r1 + u1 * r0) * off
        Be[k, 2] = (u0 * r2 + u2 * r0) * off
        Be[k, 3] = u1 * r1 * on
        Be[k, 4] = (u1 * r2 + u2 * r1) * off
        Be[k, 5] = u2 * r2 * on


@njit(cache=True, inline="always")
def _forward_entry(first, chol, pinv, X, k0, i, mc, base, col):
    """Row ``i`` of one cluster's forward substitution ``L_c x = b`` in column ``col`` of ``X`` (rows above solved,
    row ``i`` holding ``b``): the solved entry, by the reciprocal pivot."""
    k = k0 + i
    s = X[k, col]
    for p in range(first[k], i):
        s -= chol[base + i * mc + p] * X[k0 + p, col]
    return s * pinv[k]


@njit(cache=True)
def _z_rows(first, cptr, fptr, chol, pinv, Be, Z, S):
    """``Z = L^-1 Be`` (L, m) cluster by cluster and the upper triangle of ``S = Z^T Z`` (m, m), summed in link order."""
    m = Be.shape[1]
    S[:, :] = 0.0
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(mc):
            k = k0 + i
            for col in range(m):
                Z[k, col] = Be[k, col]
                Z[k, col] = _forward_entry(first, chol, pinv, Z, k0, i, mc, base, col)
            for a in range(m):
                za = Z[k, a]
                for b in range(a, m):
                    S[a, b] += za * Z[k, b]


@njit(cache=True)
def _z_rows_6(first, cptr, fptr, chol, pinv, Be, Z, S):
    """:func:`_z_rows` for m = 6 with a row and the 21 sums of ``S`` in registers (the same operations in the same order)."""
    s00 = s01 = s02 = s03 = s04 = s05 = s11 = s12 = s13 = s14 = s15 = 0.0
    s22 = s23 = s24 = s25 = s33 = s34 = s35 = s44 = s45 = s55 = 0.0
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(mc):
            k = k0 + i
            a0 = Be[k, 0]
            a1 = Be[k, 1]
            a2 = Be[k, 2]
            a3 = Be[k, 3]
            a4 = Be[k, 4]
            a5 = Be[k, 5]
            for p in range(first[k], i):
                f = chol[base + i * mc + p]
                kp = k0 + p
                a0 -= f * Z[kp, 0]
                a1 -= f * Z[kp, 1]
                a2 -= f * Z[kp, 2]
                a3 -= f * Z[kp, 3]
                a4 -= f * Z[kp, 4]
                a5 -= f * Z[kp, 5]
            r = pinv[k]
            a0 *= r
            a1 *= r
            a2 *= r
            a3 *= r
            a4 *= r
            a5 *= r
            Z[k, 0] = a0
            Z[k, 1] = a1
            Z[k, 2] = a2
            Z[k, 3] = a3
            Z[k, 4] = a4
            Z[k, 5] = a5
            s00 += a0 * a0
            s01 += a0 * a1
            s02 += a0 * a2
            s03 += a0 * a3
            s04 += a0 * a4
            s05 += a0 * a5
            s11 += a1 * a1
            s12 += a1 * a2
            s13 += a1 * a3
            s14 += a1 * a4
            s15 += a1 * a5
            s22 += a2 * a2
            s23 += a2 * a3
            s24 += a2 * a4
            s25 += a2 * a5
            s33 += a3 * a3
            s34 += a3 * a4
            s35 += a3 * a5
            s44 += a4 * a4
            s45 += a4 * a5
            s55 += a5 * a5
    S[0, 0], S[0, 1], S[0, 2], S[0, 3], S[0, 4], S[0, 5] = s00, s01, s02, s03, s04, s05
    S[1, 1], S[1, 2], S[1, 3], S[1, 4], S[1, 5] = s11, s12, s13, s14, s15
    S[2, 2], S[2, 3], S[2, 4], S[2, 5] = s22, s23, s24, s25
    S[3, 3], S[3, 4], S[3, 5] = s33, s34, s35
    S[4, 4], S[4, 5] = s44, s45
    S[5, 5] = s55


@njit(cache=True)
def woodbury_forward(first, cptr, fptr, chol, pinv, Z, z, t, ncol):
    """``z <- L^-1 z`` (first ``ncol`` columns of ``z`` (L, 2)) and ``t = Z^T z`` (m, 2) (:func:`_forward_6` for m = 6)."""
    if Z.shape[1] == 6:
        _forward_6(first, cptr, fptr, chol, pinv, Z, z, t, ncol)
    else:
        _forward(first, cptr, fptr, chol, pinv, Z, z, t, ncol)


@njit(cache=True)
def woodbury_back(first, cptr, fptr, chol, pinv, Z, z, q, ncol):
    """``z <- L^-T (z - Z q)`` (first ``ncol`` columns; ``q`` (m, 2)) (:func:`_back_6` for m = 6)."""
    if Z.shape[1] == 6:
        _back_6(first, cptr, fptr, chol, pinv, Z, z, q, ncol)
    else:
        _back(first, cptr, fptr, chol, pinv, Z, z, q, ncol)


@njit(cache=True)
def _forward(first, cptr, fptr, chol, pinv, Z, z, t, ncol):
    """``z <- L^-1 z`` (first ``ncol`` columns of ``z`` (L, 2)) and ``t = Z^T z`` (m, 2), cluster by cluster."""
    m = Z.shape[1]
    t[:, :] = 0.0
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(mc):
            k = k0 + i
            for col in range(ncol):
                s = _forward_entry(first, chol, pinv, z, k0, i, mc, base, col)
                z[k, col] = s
                for a in range(m):
                    t[a, col] += Z[k, a] * s


@njit(cache=True)
def _back(first, cptr, fptr, chol, pinv, Z, z, q, ncol):
    """``z <- L^-T (z - Z q)`` (first ``ncol`` columns; ``q`` (m, 2)), cluster by cluster."""
    m = Z.shape[1]
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(mc):
            k = k0 + i
            for col in range(ncol):
                s = z[k, col]
                for a in range(m):
                    s -= Z[k, a] * q[a, col]
                z[k, col] = s
        for i in range(mc - 1, -1, -1):
            k = k0 + i
            for col in range(ncol):
                s = z[k, col] * pinv[k]
                z[k, col] = s
                for p in range(first[k], i):
                    z[k0 + p, col] -= chol[base + i * mc + p] * s


@njit(cache=True)
def _strain_multipliers(small, ce, sce, schur, fixed_volume, t, r_vol, ge, q, col):
    """The strain and volume part of one column's solve: ``q = s + nu sce`` (``s = small t``), the strain
    correction, with ``nu = (r_vol - ce . s) / schur`` (0 with a free volume); ``ge -= q``; returns ``nu``.

    ``s = Be^T K^-1 r`` and ``ce . s = b . K^-1 r`` (Woodbury), so ``Be^T lam + ce nu = q`` for
    ``lam = K^-1 r - nu K^-1 b`` and ``K^-1 r - nu K^-1 b = L^-T (L^-1 r - Z q)``.
    """
    m = small.shape[0]
    cs = 0.0
    for a in range(m):
        s = 0.0
        for b in range(m):
            s += small[a, b] * t[b, col]
        q[a, col] = s
        cs += ce[a] * s
    nu = (r_vol - cs) / schur if fixed_volume else 0.0
    for a in range(m):
        q[a, col] += nu * sce[a]
        ge[a] -= q[a, col]
    return nu


@njit(cache=True)
def strain_project_pair(w, Z, S, small, ce, sce, schur, fixed_volume, li, lj, first, cptr, fptr, chol, pinv,
                        gy, ge, vy, ve, z, t, q):
    """``(gy, ge)`` and ``(vy, ve)`` projected in place onto the tangent space (Eq. 18), the force and
    the velocity of a step with one two-column solve; ``z`` (L, 2), ``t``, ``q`` (m, 2) work arrays.

    Per column ``g``: the multipliers ``(lam, nu)`` of ``Gamma^T Gamma (lam, nu) = Gamma^T g`` by
    Woodbury on the factors of :func:`strain_solver`: ``z = L^-1 Omega_w g_y``,
    ``t = Z^T z + S g_e`` (``= Be^T A^-1 (Omega_w g_y + Be g_e)``), the strain correction ``q``
    (:func:`_strain_multipliers`), ``lam = L^-T (z - Z (q - g_e))``; then ``g_y -= Omega_w^T lam``
    and ``g_e -= q``. Flat loops over the links (``Omega_w g``, the forward and the back
    substitutions, the subtraction) with both columns side by side; no ``A^-1 Be`` and no
    vector of link length for the volume.
    """
    d = w.shape[1]
    m = Z.shape[1]
    L = li.shape[0]
    three = d == 3
    for k in range(L):
        i = li[k]
        j = lj[k]
        if three:  # the loop below unrolled: the same operations in the same order
            w0 = w[k, 0]
            w1 = w[k, 1]
            w2 = w[k, 2]
            z[k, 0] = w0 * (gy[j, 0] - gy[i, 0]) + w1 * (gy[j, 1] - gy[i, 1]) + w2 * (gy[j, 2] - gy[i, 2])
            z[k, 1] = w0 * (vy[j, 0] - vy[i, 0]) + w1 * (vy[j, 1] - vy[i, 1]) + w2 * (vy[j, 2] - vy[i, 2])
            continue
        s = 0.0
        s2 = 0.0
        for a in range(d):
            s += w[k, a] * (gy[j, a] - gy[i, a])
            s2 += w[k, a] * (vy[j, a] - vy[i, a])
        z[k, 0] = s
        z[k, 1] = s2
    woodbury_forward(first, cptr, fptr, chol, pinv, Z, z, t, 2)
    rg = 0.0
    rv = 0.0
    for a in range(m):
        for b in range(m):
            t[a, 0] += S[a, b] * ge[b]
            t[a, 1] += S[a, b] * ve[b]
        rg += ce[a] * ge[a]
        rv += ce[a] * ve[a]
    _strain_multipliers(small, ce, sce, schur, fixed_volume, t, rg, ge, q, 0)
    _strain_multipliers(small, ce, sce, schur, fixed_volume, t, rv, ve, q, 1)
    for a in range(m):  # q - g_e of the entry g_e is minus the corrected g_e
        q[a, 0] = -ge[a]
        q[a, 1] = -ve[a]
    woodbury_back(first, cptr, fptr, chol, pinv, Z, z, q, 2)
    omega_t_subtract_pair(w, li, lj, z, gy, vy, 2)


@njit(cache=True)
def omega_t_subtract_pair(w, li, lj, z, gy, vy, ncol):
    """``gy -= Omega_w^T z[:, 0]`` and, with ``ncol`` 2, ``vy -= Omega_w^T z[:, 1]`` (d = 3 unrolled)."""
    d = w.shape[1]
    two = ncol == 2
    for k in range(li.shape[0]):
        i = li[k]
        j = lj[k]
        if d == 3:  # the loop below unrolled: the same operations in the same order
            w0 = w[k, 0]
            w1 = w[k, 1]
            w2 = w[k, 2]
            c = z[k, 0]
            v0 = c * w0
            v1 = c * w1
            v2 = c * w2
            gy[j, 0] -= v0
            gy[i, 0] += v0
            gy[j, 1] -= v1
            gy[i, 1] += v1
            gy[j, 2] -= v2
            gy[i, 2] += v2
            if two:
                c = z[k, 1]
                v0 = c * w0
                v1 = c * w1
                v2 = c * w2
                vy[j, 0] -= v0
                vy[i, 0] += v0
                vy[j, 1] -= v1
                vy[i, 1] += v1
                vy[j, 2] -= v2
                vy[i, 2] += v2
            continue
        for a in range(d):
            v = z[k, 0] * w[k, a]
            gy[j, a] -= v
            gy[i, a] += v
            if two:
                v = z[k, 1] * w[k, a]
                vy[j, a] -= v
                vy[i, a] += v


@njit(cache=True)
def _forward_6(first, cptr, fptr, chol, pinv, Z, z, t, ncol):
    """:func:`_forward` for m = 6 with the sums of ``t`` in registers (the same operations in the same order)."""
    t0 = t1 = t2 = t3 = t4 = t5 = 0.0
    v0 = v1 = v2 = v3 = v4 = v5 = 0.0
    two = ncol == 2
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for i in range(mc):
            k = k0 + i
            s = _forward_entry(first, chol, pinv, z, k0, i, mc, base, 0)
            z[k, 0] = s
            t0 += Z[k, 0] * s
            t1 += Z[k, 1] * s
            t2 += Z[k, 2] * s
            t3 += Z[k, 3] * s
            t4 += Z[k, 4] * s
            t5 += Z[k, 5] * s
            if two:
                s = _forward_entry(first, chol, pinv, z, k0, i, mc, base, 1)
                z[k, 1] = s
                v0 += Z[k, 0] * s
                v1 += Z[k, 1] * s
                v2 += Z[k, 2] * s
                v3 += Z[k, 3] * s
                v4 += Z[k, 4] * s
                v5 += Z[k, 5] * s
    t[0, 0], t[1, 0], t[2, 0], t[3, 0], t[4, 0], t[5, 0] = t0, t1, t2, t3, t4, t5
    t[:, 1] = 0.0
    if two:
        t[0, 1], t[1, 1], t[2, 1], t[3, 1], t[4, 1], t[5, 1] = v0, v1, v2, v3, v4, v5


@njit(cache=True)
def _back_6(first, cptr, fptr, chol, pinv, Z, z, q, ncol):
    """:func:`_back` for m = 6 with ``q`` in registers (the same operations in the same order)."""
    q0, q1, q2, q3, q4, q5 = q[0, 0], q[1, 0], q[2, 0], q[3, 0], q[4, 0], q[5, 0]
    p0, p1, p2, p3, p4, p5 = q[0, 1], q[1, 1], q[2, 1], q[3, 1], q[4, 1], q[5, 1]
    two = ncol == 2
    for c in range(cptr.shape[0] - 1):
        k0 = cptr[c]
        mc = cptr[c + 1] - k0
        base = fptr[c]
        for k in range(k0, k0 + mc):
            z[k, 0] = z[k, 0] - Z[k, 0] * q0 - Z[k, 1] * q1 - Z[k, 2] * q2 - Z[k, 3] * q3 - Z[k, 4] * q4 - Z[k, 5] * q5
            if two:
                z[k, 1] = (z[k, 1] - Z[k, 0] * p0 - Z[k, 1] * p1 - Z[k, 2] * p2 - Z[k, 3] * p3 - Z[k, 4] * p4
                           - Z[k, 5] * p5)
        for i in range(mc - 1, -1, -1):
            k = k0 + i
            s = z[k, 0] * pinv[k]
            z[k, 0] = s
            for p in range(first[k], i):
                z[k0 + p, 0] -= chol[base + i * mc + p] * s
            if two:
                s = z[k, 1] * pinv[k]
                z[k, 1] = s
                for p in range(first[k], i):
                    z[k0 + p, 1] -= chol[base + i * mc + p] * s
