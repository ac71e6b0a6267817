"""Numba kernels of shear-stabilised linked spheres: the constraint solve with strain columns and the FIRE loop.

The model is :class:`jamflow.models.strain.ShearStabilizedModel` (its module doc has
the equations): degrees of freedom are reference centres ``y`` (N, d) and the scaled
strain components ``e`` (m,), ``F = 1 + eps(e)``; a link ``k`` has the constraint
gradient ``w_k = F^T u_k`` on its ends and ``Be_k`` on the strain, the volume
``ce = strain components of det F F^-T``. ``Gamma^T Gamma`` is solved with the
per-cluster Cholesky factors of ``A = B_y B_y^T`` (:mod:`._link_kernels`), Woodbury
for the rank-``m`` strain coupling ``K = A + Be Be^T`` and a Schur complement for the
volume row. Links are in the cluster order of :class:`~jamflow.models.links.ClusterGram`.
All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ..minimize._fire_kernels import (
    CONVERGED,
    MAX_STEPS,
    REBUILD,
    STALLED,
    _dot,
    _fire_adapt,
    _fire_mixing,
    _max_force_sq,
    _mixed,
)
from ..neighbors._cell_kernels import cell_pairs_into, pair_buffers
from ..neighbors._verlet_kernels import _needs_rebuild
from ._link_kernels import (
    _det_inverse,
    gram_factor,
    gram_solve,
    is_linked,
    strain_state,
)
from ._rigid_kernels import (
    body_power_norms,
    rigid_forces,
    rigid_max_force_sq,
    rigid_place,
)
from .spheres._kernels import pair_forces


@njit(cache=True, inline="always")
def _component(G, a, b, scale):
    """Strain component of ``dX/dF = G`` for the pair ``a <= b`` (``strain_components`` of :mod:`..strain`)."""
    if a == b:
        return G[a, a] / scale
    return (G[a, b] + G[b, a]) / (np.sqrt(2.0) * scale)


@njit(cache=True)
def strain_links(y, F, li, lj, offset, length, R0, u, rl):
    """Reference link vectors ``R0``, unit current vectors ``u`` of ``F R0`` and lengths ``rl``; returns ``max |r - l| / l``."""
    d = y.shape[1]
    err = 0.0
    for k in range(li.shape[0]):
        s = 0.0
        for a in range(d):
            R0[k, a] = y[lj[k], a] - y[li[k], a] + offset[k, a]
        for a in range(d):
            t = 0.0
            for b in range(d):
                t += F[a, b] * R0[k, b]
            u[k, a] = t
            s += t * t
        r = np.sqrt(s)
        rl[k] = r
        for a in range(d):
            u[k, a] /= r
        err = max(err, abs(r / length[k] - 1.0))
    return err


@njit(cache=True)
def _k_solve(first, cptr, fptr, chol, Be, AiBe, small, rhs, out):
    """``out = K^-1 rhs`` by Woodbury: ``A^-1 rhs - AiBe small Be^T A^-1 rhs``."""
    m = Be.shape[1]
    out[:] = rhs
    gram_solve(first, cptr, fptr, chol, out.reshape(out.shape[0], 1))
    t = np.zeros(m)
    for k in range(out.shape[0]):
        for p in range(m):
            t[p] += Be[k, p] * out[k]
    t2 = np.zeros(m)
    for p in range(m):
        for q in range(m):
            t2[p] += small[p, q] * t[q]
    for k in range(out.shape[0]):
        s = 0.0
        for p in range(m):
            s += AiBe[k, p] * t2[p]
        out[k] -= s


@njit(cache=True)
def strain_solver(F, det, Finv, R0, u, li, lj, sign, first, cptr, fptr, chol, w, Be, AiBe, ce, b, Kib, scale,
                  rank_rtol):
    """The factorisation of ``Gamma^T Gamma`` at a point (geometry ``R0``, ``u`` of :func:`strain_links`).

    Fills ``w`` (rows ``F^T u``), ``Be``, the Gram factors ``chol``, ``AiBe = A^-1 Be``,
    ``ce``, ``b = Be ce`` and ``Kib = K^-1 b``. Returns ``(bad, small, schur)``: the first
    degenerate cluster or -1, ``(1 + Be^T A^-1 Be)^-1`` and the volume row's Schur
    complement ``ce . ce - b . K^-1 b``.
    """
    d = F.shape[0]
    L = li.shape[0]
    m = Be.shape[1]
    for k in range(L):
        for a in range(d):
            t = 0.0
            for c in range(d):
                t += F[c, a] * u[k, c]
            w[k, a] = t
        p = 0
        for a in range(d):
            for c in range(a, d):
                if a == c:
                    Be[k, p] = u[k, a] * R0[k, a] / scale
                else:
                    Be[k, p] = (u[k, a] * R0[k, c] + u[k, c] * R0[k, a]) / (np.sqrt(2.0) * scale)
                p += 1
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
    AiBe[:, :] = Be
    gram_solve(first, cptr, fptr, chol, AiBe)
    S = np.zeros((m, m))
    for k in range(L):  # one pass over the links; each sum in the order of k
        for p in range(m):
            for q in range(m):
                S[p, q] += Be[k, p] * AiBe[k, q]
    small += S
    small = _det_inverse(small)[1]
    # b = Be ce, so K^-1 b = AiBe (ce - small Be^T AiBe ce) = AiBe small ce (Woodbury): no solve
    sce = np.zeros(m)
    for p in range(m):
        for q in range(m):
            sce[p] += small[p, q] * ce[q]
    for k in range(L):
        s = 0.0
        t = 0.0
        for p in range(m):
            s += Be[k, p] * ce[p]
            t += AiBe[k, p] * sce[p]
        b[k] = s
        Kib[k] = t
    schur = ce @ ce - b @ Kib
    return -1, small, schur


@njit(cache=True)
def strain_solve(first, cptr, fptr, chol, Be, AiBe, small, b, Kib, schur, fixed_volume, r_links, r_vol, lam):
    """``(lam, nu)`` of ``Gamma^T Gamma (lam, nu) = (r_links, r_vol)`` into ``lam``; returns ``nu``."""
    _k_solve(first, cptr, fptr, chol, Be, AiBe, small, r_links, lam)
    if not fixed_volume:
        return 0.0
    nu = (r_vol - b @ lam) / schur
    for k in range(lam.shape[0]):
        lam[k] -= Kib[k] * nu
    return nu


@njit(cache=True)
def strain_subtract(w, Be, ce, li, lj, lam, nu, gy, ge):
    """``(gy, ge) -= Gamma (lam, nu)``: ``Omega_w^T lam`` on the centres, ``Be^T lam + ce nu`` on the strain."""
    d = w.shape[1]
    m = Be.shape[1]
    for k in range(li.shape[0]):
        for a in range(d):
            v = lam[k] * w[k, a]
            gy[lj[k], a] -= v
            gy[li[k], a] += v
        for p in range(m):
            ge[p] -= Be[k, p] * lam[k]
    for p in range(m):
        ge[p] -= ce[p] * nu


@njit(cache=True)
def strain_project_pair(w, Be, ce, li, lj, first, cptr, fptr, chol, AiBe, small, b, Kib, schur, fixed_volume, gy, ge,
                        vy, ve, links, t, t2):
    """``(gy, ge)`` and ``(vy, ve)`` projected in place onto the tangent space (Eq. 18), the force and
    the velocity of a step with one two-column solve; ``links`` (L, 2), ``t``, ``t2`` (m, 2) work arrays.

    Per column: ``lam = K^-1 Gamma^T g`` by Woodbury (``A^-1`` by the Gram factors, then
    ``- AiBe small Be^T``), the volume multiplier ``nu`` by the Schur complement, and
    ``g -= Gamma (lam, nu)`` (:func:`strain_subtract`).
    """
    d = w.shape[1]
    m = Be.shape[1]
    L = li.shape[0]
    for k in range(L):
        s = 0.0
        s2 = 0.0
        for a in range(d):
            s += w[k, a] * (gy[lj[k], a] - gy[li[k], a])
            s2 += w[k, a] * (vy[lj[k], a] - vy[li[k], a])
        for p in range(m):
            s += Be[k, p] * ge[p]
            s2 += Be[k, p] * ve[p]
        links[k, 0] = s
        links[k, 1] = s2
    gram_solve(first, cptr, fptr, chol, links)
    t[:, :] = 0.0
    t2[:, :] = 0.0
    for k in range(L):
        for p in range(m):
            t[p, 0] += Be[k, p] * links[k, 0]
            t[p, 1] += Be[k, p] * links[k, 1]
    for p in range(m):
        for q in range(m):
            t2[p, 0] += small[p, q] * t[q, 0]
            t2[p, 1] += small[p, q] * t[q, 1]
    for k in range(L):
        s = 0.0
        s2 = 0.0
        for p in range(m):
            s += AiBe[k, p] * t2[p, 0]
            s2 += AiBe[k, p] * t2[p, 1]
        links[k, 0] -= s
        links[k, 1] -= s2
    nu = 0.0
    nu2 = 0.0
    if fixed_volume:
        s = 0.0
        s2 = 0.0
        for k in range(L):
            s += b[k] * links[k, 0]
            s2 += b[k] * links[k, 1]
        nu = (ce @ ge - s) / schur
        nu2 = (ce @ ve - s2) / schur
        for k in range(L):
            links[k, 0] -= Kib[k] * nu
            links[k, 1] -= Kib[k] * nu2
    strain_subtract(w, Be, ce, li, lj, links[:, 0], nu, gy, ge)
    strain_subtract(w, Be, ce, li, lj, links[:, 1], nu2, vy, ve)


@njit(cache=True)
def strain_forces(y, Q, T, Finv, scale, offset, pi, pj, sigma, eps, w_exp, x, shifted, force, fy, fe):
    """Energy, contacts and generalised forces ``-dU/dy`` (N, d) into ``fy`` and ``-dU/de`` (m,) into ``fe``.

    The pair forces are those of the centres ``x = T y`` (rotated frame) with the
    images ``T offset`` (:func:`jamflow.models.spheres._kernels.pair_forces`, its loops
    unrolled for d = 2 and 3); ``x`` (N, d), ``shifted`` (at least (P, d)) and ``force``
    (N, d) are work space.
    """
    d = y.shape[1]
    for i in range(y.shape[0]):
        for a in range(d):
            t = 0.0
            for c in range(a, d):
                t += T[a, c] * y[i, c]
            x[i, a] = t
    for p in range(pi.shape[0]):
        for a in range(d):
            t = 0.0
            for c in range(a, d):
                t += T[a, c] * offset[p, c]
            shifted[p, a] = t
    virial = np.zeros((d, d))
    energy, n_contact = pair_forces(x, 1.0, shifted[:pi.shape[0]], pi, pj, sigma, eps, w_exp, force, virial, True)
    for i in range(y.shape[0]):
        for c in range(d):
            t = 0.0
            for a in range(c + 1):
                t += force[i, a] * T[a, c]
            fy[i, c] = t
    # -dU/dF = W F^-1 with W = Q virial Q^T the unrotated pair virial
    G = np.zeros((d, d))
    for a in range(d):
        for c in range(d):
            t = 0.0
            for p in range(d):
                for q in range(d):
                    t += Q[a, p] * virial[p, q] * Q[c, q]
            for b in range(d):
                G[a, b] += t * Finv[c, b]
    p = 0
    for a in range(d):
        for b in range(a, d):
            fe[p] = _component(G, a, b, scale)
            p += 1
    return energy, n_contact


@njit(cache=True)
def sheared_list(y, h0, h0_inv, U, T, diameter, skin, adj_ptr, adj, buffers):
    """The Verlet list of the deformed box ``U`` (centres ``T y``), built with the orthogonal cell search.

    Fractional coordinates ``s = h0^-1 y`` (the same in the reference and the deformed
    box) are stretched to ``z = s l`` with ``l`` the perpendicular widths of ``U``,
    where the cell search of :mod:`jamflow.neighbors._cell_kernels` lists every pair
    within ``(sigma + skin) / s_min`` (``s_min`` the smallest singular value of
    ``U diag(l)^-1``, so every pair closer than ``sigma + skin`` in the deformed box is
    among them); kept are the pairs closer than ``sigma + skin`` in the deformed box
    that are not linked (``adj_ptr``, ``adj``): the list of
    :class:`~jamflow.neighbors.verlet.NeighborList` in that box, in its order.

    Returns
    -------
    ok, pi, pj, offset, sigma, buffers
        ``ok`` False (nothing listed) when the stretched reach exceeds half a width;
        ``offset = h0 n`` the pairs' reference images.
    """
    n, d = y.shape
    U_inv = np.linalg.inv(U)
    ell = np.empty(d)
    for a in range(d):
        s = 0.0
        for b in range(d):
            s += U_inv[a, b] * U_inv[a, b]
        ell[a] = 1.0 / np.sqrt(s)
    M = np.empty((d, d))
    for a in range(d):
        for b in range(d):
            M[a, b] = U[a, b] / ell[b]
    smin = np.linalg.svd(M)[1].min()
    reach = diameter.max() + skin
    empty_i = np.empty(0, dtype=np.int64)
    if not reach / smin < 0.5 * ell.min():
        return False, empty_i, empty_i, np.empty((0, d)), np.empty(0), buffers
    z = np.empty((n, d))
    for i in range(n):
        for a in range(d):
            t = 0.0
            for b in range(d):
                t += h0_inv[a, b] * y[i, b]
            z[i, a] = t * ell[a]
    ci, cj, image, buffers = cell_pairs_into(z, ell, reach / smin, diameter / smin, skin / smin, buffers)
    m = ci.shape[0]
    pi = np.empty(m, dtype=np.int64)
    pj = np.empty(m, dtype=np.int64)
    offset = np.empty((m, d))
    sigma = np.empty(m)
    ref = np.empty(d)
    kept = 0
    for p in range(m):
        i = ci[p]
        j = cj[p]
        if is_linked(adj_ptr, adj, i, j):
            continue
        for a in range(d):
            t = 0.0
            for b in range(d):
                t += h0[a, b] * image[p, b]
            offset[kept, a] = t
            ref[a] = y[j, a] - y[i, a] + t
        r2 = 0.0
        for a in range(d):
            t = 0.0
            for b in range(d):
                t += T[a, b] * ref[b]
            r2 += t * t
        sig = 0.5 * (diameter[i] + diameter[j])
        if r2 < (sig + skin) * (sig + skin):
            pi[kept] = i
            pj[kept] = j
            sigma[kept] = sig
            kept += 1
    return True, pi[:kept], pj[:kept], offset[:kept], sigma[:kept], buffers


@njit(cache=True)
def strain_reaffix(y, e, h0, scale, fixed_volume, li, lj, offset, length, sign, first, cptr, fptr, chol, R0, u, rl,
                   w, Be, AiBe, ce, b, Kib, small, schur, lam, length_rtol, max_sweeps, rank_rtol, chord):
    """Newton re-affixing of links and ``det F = 1`` in place (:meth:`ShearStabilizedModel.reproject`).

    Chord sweeps with the given factorisation as long as each sweep at least halves
    the error, else the solver is refactorised at the iterate. On return ``R0``,
    ``u``, ``rl`` hold the geometry of the result. Returns
    ``(sweeps, err, bad, small, schur)`` (``sweeps`` -1 when ``max_sweeps`` did not suffice).
    """
    previous = np.inf
    err = 0.0
    for sweep in range(max_sweeps + 1):
        F, _, _, _, det, Finv = strain_state(e, h0, scale)
        err = strain_links(y, F, li, lj, offset, length, R0, u, rl)
        c_vol = det - 1.0 if fixed_volume else 0.0
        err = max(err, abs(c_vol))
        if err <= length_rtol:
            return sweep, err, -1, small, schur
        if sweep == max_sweeps:
            break
        chord = chord and err <= 0.5 * previous
        if not chord:
            bad, small, schur = strain_solver(F, det, Finv, R0, u, li, lj, sign, first, cptr, fptr, chol, w, Be,
                                              AiBe, ce, b, Kib, scale, rank_rtol)
            if bad >= 0:
                return sweep, err, bad, small, schur
        previous = err
        c_links = rl - length
        nu = strain_solve(first, cptr, fptr, chol, Be, AiBe, small, b, Kib, schur, fixed_volume, c_links, c_vol, lam)
        strain_subtract(w, Be, ce, li, lj, lam, nu, y, e)
    return -1, err, -1, small, schur


@njit(cache=True)
def strain_fire(
    y, vy, e, ve, fire_state, fire_params, h0, scale, fixed_volume,
    offset, pi, pj, sigma, eps, w_exp, x_build, h_build_inv, reach, skin, diameter, adj_ptr, adj,
    li, lj, link_offset, length, sign, first, cptr, fptr, chol, rptr, members, shift, ref, body, vb, fb, inv_mass,
    length_rtol, max_sweeps, rank_rtol, force_tol, max_steps, fy, fe,
):
    """FIRE 2.0 of shear-stabilised linked spheres in one compiled loop (the steps of :class:`~jamflow.minimize.fire._ModelFire`).

    Unit masses for centres and strain. Every step: FIRE control, move, re-affixing of
    links and volume (:func:`strain_reaffix`, chord sweeps with the last point's
    factorisation), the factorisation at the new point (:func:`strain_solver`), pair
    forces in the deformed box (:func:`strain_forces`) and the force and the velocity
    projected (:func:`strain_project_pair`). ``(y, e)`` must lie on the constraint manifold.
    Rigid 2D clusters are rigid bodies (:mod:`._rigid_kernels`: rows ``body`` (C, 3) of
    reference centre and angle, velocities ``vb``, forces ``fb``, inverse masses
    ``inv_mass``; spheres ``members[rptr[c]:rptr[c+1]]`` with shifts ``shift`` and
    shape ``ref``): their links are not among ``li``, ``lj``, their spheres' ``y`` are
    placed from the bodies and the strain at every evaluation (:func:`rigid_place`) and
    their forces gathered on the bodies (:func:`rigid_forces`); only the other links and
    the volume are constraints.

    The list lives in the deformed box (rotated frame, centres ``y T^T``): when
    displacements and the deformation since the build (``||U h_build^-1 - 1||_F``
    times the reach) use up the skin, it is rebuilt before the forces are evaluated
    (:func:`sheared_list`; ``x_build`` and ``h_build_inv`` updated in place), or, in a
    box too sheared or small for it, the loop returns ``REBUILD`` for the caller's
    build.

    Returns
    -------
    status, steps, energy, n_contact, max_force_sq, sweeps, bad, builds, pi, pj, offset, sigma
    """
    d = y.shape[1]
    n = y.shape[0]
    L = li.shape[0]
    m = e.shape[0]
    dt, alpha, npos = fire_state[0], fire_state[1], int(fire_state[2])
    done = int(fire_state[3])
    dt_max, dt_min, f_inc, f_dec = fire_params[0], fire_params[1], fire_params[2], fire_params[3]
    alpha0, f_alpha, n_delay = fire_params[4], fire_params[5], int(fire_params[6])
    initial_delay = fire_params[7] > 0.0
    R0 = np.zeros((L, d))
    u = np.zeros((L, d))
    rl = np.zeros(L)
    w = np.zeros((L, d))
    Be = np.zeros((L, m))
    AiBe = np.zeros((L, m))
    ce = np.zeros(m)
    b = np.zeros(L)
    Kib = np.zeros(L)
    lam = np.zeros(L)
    work2 = np.zeros((L, 2))
    t_m = np.zeros((m, 2))
    t2_m = np.zeros((m, 2))
    force = np.zeros((n, d))
    xr = np.zeros((n, d))
    shifted = np.zeros((2 * pi.shape[0] + 1, d))
    x = np.zeros((n, d))
    moved = np.zeros((n, d))
    small = np.eye(m)
    schur = 1.0
    r_body = np.empty_like(ref)
    h0_inv = np.linalg.inv(h0)
    buffers = pair_buffers(n, d)
    builds = 0
    energy = 0.0
    n_contact = 0
    fmax2 = np.inf
    sweeps = 0
    bad = -1
    status = MAX_STEPS
    step = 0
    while True:
        # evaluation at (y, e): a valid list, the factorisation, forces and velocity projected
        F, Q, T, U, det, Finv = strain_state(e, h0, scale)
        rigid_place(y, Finv, body, rptr, members, shift, ref, r_body)
        dev = _deformed(y, T, U @ h_build_inv, x_build, x, moved)
        if _needs_rebuild(x, moved, 1.0, 1.0, reach, skin, dev * reach):
            ok, pi_, pj_, offset_, sigma_, buffers = sheared_list(y, h0, h0_inv, U, T, diameter, skin, adj_ptr, adj,
                                                                 buffers)
            if not ok:
                status = REBUILD
                break
            pi, pj, offset, sigma = pi_, pj_, offset_, sigma_
            x_build[:, :] = x
            h_build_inv[:, :] = np.linalg.inv(U)
            builds += 1
        if step == 0:
            # later steps: the re-affixing that ended the last step left the geometry of (y, e) in R0, u, rl
            strain_links(y, F, li, lj, link_offset, length, R0, u, rl)
        bad, small, schur = strain_solver(F, det, Finv, R0, u, li, lj, sign, first, cptr, fptr, chol, w, Be, AiBe,
                                          ce, b, Kib, scale, rank_rtol)
        if bad >= 0:
            status = STALLED
            break
        if shifted.shape[0] < pi.shape[0]:
            shifted = np.empty((2 * pi.shape[0], d))
        energy, n_contact = strain_forces(y, Q, T, Finv, scale, offset, pi, pj, sigma, eps, w_exp, xr, shifted, force,
                                          fy, fe)
        rigid_forces(Finv, rptr, members, r_body, scale, fy, fe, fb)
        strain_project_pair(w, Be, ce, li, lj, first, cptr, fptr, chol, AiBe, small, b, Kib, schur, fixed_volume,
                            fy, fe, vy, ve, work2, t_m, t2_m)
        fmax2 = max(_max_force_sq(fy), _dot1(fe, fe), rigid_max_force_sq(rptr, r_body, inv_mass, fb))
        if fmax2 <= force_tol * force_tol:
            status = CONVERGED
            break
        if step >= max_steps:
            break
        power = _dot(fy, vy) + _dot1(fe, ve) + body_power_norms(fb, vb, inv_mass)[0]
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            _strain_step_back(y, vy, e, ve, body, vb, dt)
            k_, err, bad, small, schur = strain_reaffix(
                y, e, h0, scale, fixed_volume, li, lj, link_offset, length, sign, first, cptr, fptr, chol, R0, u, rl,
                w, Be, AiBe, ce, b, Kib, small, schur, lam, length_rtol, max_sweeps, rank_rtol, True)
            sweeps += max(k_, 0)
            if k_ < 0 or bad >= 0:
                status = STALLED
                break
        _strain_move(y, vy, fy, e, ve, fe, body, vb, fb, inv_mass, dt, alpha)
        step += 1
        k_, err, bad, small, schur = strain_reaffix(
            y, e, h0, scale, fixed_volume, li, lj, link_offset, length, sign, first, cptr, fptr, chol, R0, u, rl,
            w, Be, AiBe, ce, b, Kib, small, schur, lam, length_rtol, max_sweeps, rank_rtol, True)
        sweeps += max(k_, 0)
        if k_ < 0 or bad >= 0:
            status = STALLED
            break
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    return status, step, energy, n_contact, fmax2, sweeps, bad, builds, pi, pj, offset, sigma


@njit(cache=True)
def _strain_step_back(y, vy, e, ve, body, vb, dt):
    """FIRE's step back on an uphill step: half a step back along the velocity, which is zeroed (every group)."""
    for i in range(y.shape[0]):
        for a in range(y.shape[1]):
            y[i, a] -= 0.5 * dt * vy[i, a]
            vy[i, a] = 0.0
    for p in range(e.shape[0]):
        e[p] -= 0.5 * dt * ve[p]
        ve[p] = 0.0
    for c in range(body.shape[0]):
        for a in range(3):
            body[c, a] -= 0.5 * dt * vb[c, a]
            vb[c, a] = 0.0


@njit(cache=True)
def _strain_move(y, vy, fy, e, ve, fe, body, vb, fb, inv_mass, dt, alpha):
    """FIRE's semi-implicit Euler step of centres, strain (unit masses) and bodies (inverse masses ``inv_mass``):
    ``v += dt M^-1 F``, mixing with ``|v|_M`` and ``|F|_M^-1`` (the unit-mass FIRE of ``M^(1/2) q``), move."""
    for i in range(y.shape[0]):
        for a in range(y.shape[1]):
            vy[i, a] += dt * fy[i, a]
    for p in range(e.shape[0]):
        ve[p] += dt * fe[p]
    for c in range(body.shape[0]):
        for a in range(3):
            vb[c, a] += dt * fb[c, a] * inv_mass[c, a]
    _, vb2, fb2 = body_power_norms(fb, vb, inv_mass)
    vnorm = np.sqrt(_dot(vy, vy) + _dot1(ve, ve) + vb2)
    fnorm = np.sqrt(_dot(fy, fy) + _dot1(fe, fe) + fb2)
    keep, mix = _fire_mixing(alpha, vnorm, fnorm)
    for i in range(y.shape[0]):
        for a in range(y.shape[1]):
            vi = _mixed(keep, vy[i, a], mix, fy[i, a])
            vy[i, a] = vi
            y[i, a] += dt * vi
    for p in range(e.shape[0]):
        vi = _mixed(keep, ve[p], mix, fe[p])
        ve[p] = vi
        e[p] += dt * vi
    for c in range(body.shape[0]):
        for a in range(3):
            vi = _mixed(keep, vb[c, a], mix, fb[c, a] * inv_mass[c, a])
            vb[c, a] = vi
            body[c, a] += dt * vi


@njit(cache=True)
def _deformed(y, T, A, x_build, x, moved):
    """Centres ``x = y T^T`` in the deformed box, build centres ``moved = x_build A^T`` carried
    by the deformation ``A`` since the build; returns ``||A - 1||_F``."""
    d = y.shape[1]
    dev = 0.0
    for a in range(d):
        for c in range(d):
            t = A[a, c] - (1.0 if a == c else 0.0)
            dev += t * t
    for i in range(y.shape[0]):
        for a in range(d):
            t = 0.0
            t2 = 0.0
            for c in range(d):
                t += T[a, c] * y[i, c]
                t2 += A[a, c] * x_build[i, c]
            x[i, a] = t
            moved[i, a] = t2
    return np.sqrt(dev)


@njit(cache=True)
def _dot1(a, b):
    """``a . b`` of two flat vectors."""
    s = 0.0
    for k in range(a.shape[0]):
        s += a[k] * b[k]
    return s
