"""Numba kernels of shear-stabilised linked spheres: link geometry, forces, list, re-affixing and the FIRE loop.

The model is :class:`jamflow.models.strain.ShearStabilizedModel` (its module doc has
the equations): degrees of freedom are reference centres ``y`` (N, d) and the scaled
strain components ``e`` (m,), ``F = 1 + eps(e)``; a link ``k`` has the constraint
gradient ``w_k = F^T u_k`` on its ends and ``Be_k`` on the strain, the volume
``ce = strain components of det F F^-T``. ``Gamma^T Gamma`` is solved with the
per-cluster Cholesky factors of ``A = B_y B_y^T`` (:mod:`._link_kernels`), Woodbury
for the rank-``m`` strain coupling ``K = A + Be Be^T`` and a Schur complement for the
volume row (:mod:`._woodbury_kernels`). Links are in the cluster order of
:class:`~jamflow.models.links.ClusterGram`. All kernels are single-threaded and cached.
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
    _dot,
    _fire_adapt,
    _fire_mixing,
    _max_force_sq,
    _mixed,
)
from ..neighbors._cell_kernels import cell_pairs_into, pair_buffers
from ._hinge_kernels import hinge_advance, hinge_place, hinge_project
from ._link_kernels import (
    is_linked,
    strain_state,
)
from ._rigid_kernels import (
    body_power_norms,
    rigid_forces,
    rigid_max_force_sq,
    rigid_place,
)
from ._woodbury_kernels import (
    _strain_multipliers,
    omega_t_subtract_pair,
    strain_project_pair,
    strain_solver,
    woodbury_back,
    woodbury_forward,
)
from .spheres._kernels import pair_forces_affine


@njit(cache=True, inline="always")
def _component(G, a, b, scale):
    """Strain component of ``dX/dF = G`` for the pair ``a <= b`` (``strain_components`` of :mod:`..strain`)."""
    if a == b:
        return G[a, a] / scale
    return (G[a, b] + G[b, a]) / (np.sqrt(2.0) * scale)


@njit(cache=True)
def strain_links(y, F, li, lj, offset, length, R0, u, rl):
    """Reference link vectors ``R0``, unit current vectors ``u`` of ``F R0`` and lengths ``rl``; returns ``max |r - l| / l``."""
    if y.shape[1] == 3:
        return _strain_links_3d(y, F, li, lj, offset, length, R0, u, rl)
    return _strain_links(y, F, li, lj, offset, length, R0, u, rl)


@njit(cache=True)
def _strain_links(y, F, li, lj, offset, length, R0, u, rl):
    """:func:`strain_links` in any dimension."""
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
        inv = 1.0 / r
        for a in range(d):
            u[k, a] *= inv
        err = max(err, abs(r / length[k] - 1.0))
    return err


@njit(cache=True)
def _strain_links_3d(y, F, li, lj, offset, length, R0, u, rl):
    """:func:`strain_links` for d = 3 with ``F`` and a link in registers (the same operations in the same order)."""
    f00, f01, f02 = F[0, 0], F[0, 1], F[0, 2]
    f10, f11, f12 = F[1, 0], F[1, 1], F[1, 2]
    f20, f21, f22 = F[2, 0], F[2, 1], F[2, 2]
    err = 0.0
    for k in range(li.shape[0]):
        i = li[k]
        j = lj[k]
        r0 = y[j, 0] - y[i, 0] + offset[k, 0]
        r1 = y[j, 1] - y[i, 1] + offset[k, 1]
        r2 = y[j, 2] - y[i, 2] + offset[k, 2]
        R0[k, 0] = r0
        R0[k, 1] = r1
        R0[k, 2] = r2
        t0 = f00 * r0 + f01 * r1 + f02 * r2
        t1 = f10 * r0 + f11 * r1 + f12 * r2
        t2 = f20 * r0 + f21 * r1 + f22 * r2
        r = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        rl[k] = r
        inv = 1.0 / r
        u[k, 0] = t0 * inv
        u[k, 1] = t1 * inv
        u[k, 2] = t2 * inv
        err = max(err, abs(r / length[k] - 1.0))
    return err


@njit(cache=True)
def strain_forces(y, Q, T, Finv, scale, offset, pi, pj, sigma, eps, w_exp, force, fy, fe):
    """Energy, contacts and generalised forces ``-dU/dy`` (N, d) into ``fy`` and ``-dU/de`` (m,) into ``fe``.

    The pair forces are those of the centres ``x = T y`` (rotated frame, ``T`` upper
    triangular) with the images ``T offset``
    (:func:`jamflow.models.spheres._kernels.pair_forces_affine`); ``force`` (N, d) is
    work space (``-dU/dx``).
    """
    d = y.shape[1]
    virial = np.zeros((d, d))
    energy, n_contact = pair_forces_affine(y, T, offset, pi, pj, sigma, eps, w_exp, force, virial)
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
def hinge_strain_place(y, Finv, spheres, shift, origin, r):
    """Reference centres ``y_s = Y + F^-1 r_s - shift_s`` of every hinged cluster's spheres, in place.

    ``origin`` (H, 3) the reference centres ``Y`` of the spheres ``b`` (unwrapped), ``r`` (4 H, 3)
    the real-space (unrotated frame) offsets from ``b`` placed by
    :func:`~._hinge_kernels.hinge_place` (cluster ``h``'s at rows ``4 h ... 4 h + 3``), ``shift``
    (H, 4, 3) the periodic shifts in the reference box.
    """
    for h in range(spheres.shape[0]):
        ox, oy, oz = origin[h, 0], origin[h, 1], origin[h, 2]
        for s in range(4):
            k = 4 * h + s
            i = spheres[h, s]
            rx, ry, rz = r[k, 0], r[k, 1], r[k, 2]
            y[i, 0] = ox + Finv[0, 0] * rx + Finv[0, 1] * ry + Finv[0, 2] * rz - shift[h, s, 0]
            y[i, 1] = oy + Finv[1, 0] * rx + Finv[1, 1] * ry + Finv[1, 2] * rz - shift[h, s, 1]
            y[i, 2] = oz + Finv[2, 0] * rx + Finv[2, 1] * ry + Finv[2, 2] * rz - shift[h, s, 2]


@njit(cache=True)
def hinge_strain_forces(Finv, spheres, r, scale, fy, fe, fh):
    """Real-space forces ``fh`` (4 H, 3) of the hinged spheres from ``fy`` (N, 3); ``fe`` made the strain force at fixed bodies.

    ``fh_s = f_s = F^-T fy_s`` (unrotated frame, rows as ``r`` of :func:`hinge_strain_place`);
    ``fy`` of those spheres is zeroed (they are not degrees of freedom); ``fe -= `` the strain
    components of ``C = sum_s f_s rho_s^T`` with ``rho_s = F^-1 r_s`` (at fixed bodies a sphere
    moves with ``dF (Y - shift_s)``, not with ``dF y_s``; as :func:`~._rigid_kernels.rigid_forces`).
    """
    if spheres.shape[0] == 0:
        return
    C = np.zeros((3, 3))
    for h in range(spheres.shape[0]):
        for s in range(4):
            k = 4 * h + s
            i = spheres[h, s]
            gx, gy, gz = fy[i, 0], fy[i, 1], fy[i, 2]
            fx = Finv[0, 0] * gx + Finv[1, 0] * gy + Finv[2, 0] * gz
            fyr = Finv[0, 1] * gx + Finv[1, 1] * gy + Finv[2, 1] * gz
            fz = Finv[0, 2] * gx + Finv[1, 2] * gy + Finv[2, 2] * gz
            rx, ry, rz = r[k, 0], r[k, 1], r[k, 2]
            px = Finv[0, 0] * rx + Finv[0, 1] * ry + Finv[0, 2] * rz
            py = Finv[1, 0] * rx + Finv[1, 1] * ry + Finv[1, 2] * rz
            pz = Finv[2, 0] * rx + Finv[2, 1] * ry + Finv[2, 2] * rz
            C[0, 0] += fx * px
            C[0, 1] += fx * py
            C[0, 2] += fx * pz
            C[1, 0] += fyr * px
            C[1, 1] += fyr * py
            C[1, 2] += fyr * pz
            C[2, 0] += fz * px
            C[2, 1] += fz * py
            C[2, 2] += fz * pz
            fh[k, 0], fh[k, 1], fh[k, 2] = fx, fyr, fz
            fy[i, 0] = 0.0
            fy[i, 1] = 0.0
            fy[i, 2] = 0.0
    p = 0
    for a in range(3):
        for b in range(a, 3):
            fe[p] -= _component(C, a, b, scale)
            p += 1


@njit(cache=True)
def hinge_strain_advance(local, geo, state, origin, r, zero, body, Finv, v, step):
    """Every hinged cluster moved by ``step * P v`` (``v`` (4 H, 3) real-space velocities at fixed strain) and placed.

    :func:`~._hinge_kernels.hinge_advance` on body origins kept at zero leaves the real-space
    displacement of ``b`` in ``state[:, :3]``; it moves the reference origin,
    ``Y += F^-1 d`` (so the move is ``F Y + r_s`` + ``step P v`` to first order at this strain),
    and :func:`~._hinge_kernels.hinge_place` sets the offsets ``r`` and the geometry ``geo`` of
    the new state (``local`` the rows ``4 h + s`` of ``r``, ``zero`` shifts of zero).
    """
    hinge_advance(local, geo, state, v, step)
    for h in range(local.shape[0]):
        dx, dy, dz = state[h, 0], state[h, 1], state[h, 2]
        for a in range(3):
            origin[h, a] += Finv[a, 0] * dx + Finv[a, 1] * dy + Finv[a, 2] * dz
        state[h, 0] = 0.0
        state[h, 1] = 0.0
        state[h, 2] = 0.0
    hinge_place(r, local, zero, body, state, geo)


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
def strain_reaffix(y, e, h0, scale, fixed_volume, li, lj, offset, length, sign, first, cptr, fptr, chol, pinv, R0, u,
                   rl, w, Be, Z, S, ce, sce, small, schur, z, t, q, length_rtol, max_sweeps, rank_rtol):
    """Newton re-affixing of links and ``det F = 1`` in place (:meth:`ShearStabilizedModel.reproject`).

    A sweep is the minimum-norm step ``(y, e) -= Gamma (lam, nu)`` with
    ``Gamma^T Gamma (lam, nu) = (r - l, det F - 1)``, solved as in
    :func:`strain_project_pair` (``z = L^-1 (r - l)``, ``t = Z^T z``, the strain
    correction ``q``, ``lam = L^-T (z - Z q)``). Chord sweeps with the given factorisation
    as long as each sweep at least halves the error, else the solver is refactorised at
    the iterate. On return ``R0``, ``u``, ``rl`` hold the geometry of the result; ``z``
    (L, 2), ``t``, ``q`` (m, 2) are work arrays. Returns ``(sweeps, err, bad, small,
    schur)`` (``sweeps`` -1 when ``max_sweeps`` did not suffice).
    """
    previous = np.inf
    err = 0.0
    chord = True
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
            bad, small, schur = strain_solver(F, det, Finv, R0, u, sign, first, cptr, fptr, chol, pinv, w, Be, Z, S,
                                              ce, sce, scale, rank_rtol)
            if bad >= 0:
                return sweep, err, bad, small, schur
        previous = err
        for k in range(li.shape[0]):
            z[k, 0] = rl[k] - length[k]
        woodbury_forward(first, cptr, fptr, chol, pinv, Z, z, t, 1)
        _strain_multipliers(small, ce, sce, schur, fixed_volume, t, c_vol, e, q, 0)
        woodbury_back(first, cptr, fptr, chol, pinv, Z, z, q, 1)
        omega_t_subtract_pair(w, li, lj, z, y, y, 1)
    return -1, err, -1, small, schur


@njit(cache=True)
def strain_fire(
    y, vy, e, ve, fire_state, fire_params, h0, scale, fixed_volume,
    offset, pi, pj, sigma, eps, w_exp, y_build, h_build_inv, reach, skin, diameter, adj_ptr, adj,
    li, lj, link_offset, length, sign, first, cptr, fptr, chol, rptr, members, shift, ref, body, vb, fb, inv_mass,
    hinge_spheres, hinge_local, hinge_shift, hinge_zero, hinge_body, hinge_state, hinge_geo, hinge_origin, hinge_r,
    vh, fh, free, length_rtol, max_sweeps, rank_rtol, force_tol, max_steps, energy_floor, pressure0, fy, fe,
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
    the volume are constraints. Hinged 3D clusters likewise (``hinge_*``: reference origins
    ``hinge_origin`` (H, 3) of their spheres ``b`` following the strain affinely, rotation and
    torsion in the real frame in the arrays of :mod:`._hinge_kernels` with body origins kept at
    zero, so ``hinge_place`` puts the real offsets ``hinge_r`` (4 H, 3) from ``b`` at rows
    ``hinge_local``; :func:`hinge_strain_place`, :func:`hinge_strain_forces`,
    :func:`hinge_strain_advance`): FIRE moves them by real-space sphere velocities at fixed
    strain ``vh`` (4 H, 3), kept tangent by :func:`~._hinge_kernels.hinge_project`, with the
    projected real forces ``fh`` (unit sphere masses: the fixed-box hinged path's metric).
    ``free`` are the spheres outside bodies: the FIRE sums and moves of ``y`` skip the bodies'
    spheres, whose forces and velocities there are zero (the same bits).

    The list lives in the deformed box (rotated frame, centres ``y T^T``): when
    displacements and the deformation since the build (``||U h_build^-1 - 1||_F``
    times the reach) use up the skin (:func:`_rebuild_due`), it is rebuilt before the
    forces are evaluated (:func:`sheared_list`; the build's reference centres ``y_build``
    and ``h_build_inv`` updated in place), or, in a
    box too sheared or small for it, the loop returns ``REBUILD`` for the caller's
    build. ``energy_floor`` > 0 stops the run (``BELOW``) once the pair energy plus the
    kinetic energy of FIRE's metric is at or below it. ``pressure0`` > 0 (``fixed_volume``
    false) minimises ``U + P0 V`` instead (:func:`_box_enthalpy`), and returns that energy.

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
    R0, u, w = np.zeros((L, d)), np.zeros((L, d)), np.zeros((L, d))
    rl, pinv = np.zeros(L), np.zeros(L)
    Be, Z, S = np.zeros((L, m)), np.zeros((L, m)), np.zeros((m, m))
    ce, sce = np.zeros(m), np.zeros(m)
    z, t_m, q_m = np.zeros((L, 2)), np.zeros((m, 2)), np.zeros((m, 2))
    force = np.zeros((n, d))
    small = np.eye(m)
    schur = 1.0
    r_body = np.empty_like(ref)
    hinged = hinge_spheres.shape[0] > 0
    h0_inv = np.linalg.inv(h0)
    volume0 = abs(np.linalg.det(h0))
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
        hinge_strain_place(y, Finv, hinge_spheres, hinge_shift, hinge_origin, hinge_r)
        if _rebuild_due(y, T, U @ h_build_inv, y_build, reach, skin):
            ok, pi_, pj_, offset_, sigma_, buffers = sheared_list(y, h0, h0_inv, U, T, diameter, skin, adj_ptr, adj,
                                                                 buffers)
            if not ok:
                status = REBUILD
                break
            pi, pj, offset, sigma = pi_, pj_, offset_, sigma_
            y_build[:, :] = y
            h_build_inv[:, :] = np.linalg.inv(U)
            builds += 1
        if step == 0:
            # later steps: the re-affixing that ended the last step left the geometry of (y, e) in R0, u, rl
            strain_links(y, F, li, lj, link_offset, length, R0, u, rl)
        bad, small, schur = strain_solver(F, det, Finv, R0, u, sign, first, cptr, fptr, chol, pinv, w, Be, Z, S, ce,
                                          sce, scale, rank_rtol)
        if bad >= 0:
            status = STALLED
            break
        energy, n_contact = strain_forces(y, Q, T, Finv, scale, offset, pi, pj, sigma, eps, w_exp, force, fy, fe)
        rigid_forces(Finv, rptr, members, r_body, scale, fy, fe, fb)
        if hinged:
            hinge_strain_forces(Finv, hinge_spheres, hinge_r, scale, fy, fe, fh)
            hinge_project(hinge_local, hinge_geo, fh)
            hinge_project(hinge_local, hinge_geo, vh)
        if pressure0 > 0.0:
            energy += _box_enthalpy(fe, ce, pressure0, volume0, det)
        strain_project_pair(w, Z, S, small, ce, sce, schur, fixed_volume, li, lj, first, cptr, fptr, chol, pinv,
                            fy, fe, vy, ve, z, t_m, q_m)
        fmax2 = max(_free_max_sq(fy, free), _dot1(fe, fe), rigid_max_force_sq(rptr, r_body, inv_mass, fb),
                    _max_force_sq(fh))
        if fmax2 <= force_tol * force_tol:
            status = CONVERGED
            break
        if energy_floor > 0.0 and energy + 0.5 * _speed_sq(vy, ve, vb, vh, inv_mass, free) <= energy_floor:
            status = BELOW
            break
        if step >= max_steps:
            break
        power = _free_dot(fy, vy, free) + _dot1(fe, ve) + body_power_norms(fb, vb, inv_mass)[0] + _dot(fh, vh)
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            if hinged:
                hinge_strain_advance(hinge_local, hinge_geo, hinge_state, hinge_origin, hinge_r, hinge_zero,
                                     hinge_body, Finv, vh, -0.5 * dt)
            _strain_step_back(y, vy, e, ve, body, vb, vh, free, dt)
            k_, err, bad, small, schur = strain_reaffix(
                y, e, h0, scale, fixed_volume, li, lj, link_offset, length, sign, first, cptr, fptr, chol, pinv, R0, u,
                rl, w, Be, Z, S, ce, sce, small, schur, z, t_m, q_m, length_rtol, max_sweeps, rank_rtol)
            sweeps += max(k_, 0)
            if k_ < 0 or bad >= 0:
                status = STALLED
                break
        _strain_move(y, vy, fy, e, ve, fe, body, vb, fb, inv_mass, vh, fh, free, dt, alpha)
        step += 1
        if hinged:
            hinge_strain_advance(hinge_local, hinge_geo, hinge_state, hinge_origin, hinge_r, hinge_zero, hinge_body,
                                 Finv, vh, dt)
        k_, err, bad, small, schur = strain_reaffix(
            y, e, h0, scale, fixed_volume, li, lj, link_offset, length, sign, first, cptr, fptr, chol, pinv, R0, u,
            rl, w, Be, Z, S, ce, sce, small, schur, z, t_m, q_m, length_rtol, max_sweeps, rank_rtol)
        sweeps += max(k_, 0)
        if k_ < 0 or bad >= 0:
            status = STALLED
            break
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    return status, step, energy, n_contact, fmax2, sweeps, bad, builds, pi, pj, offset, sigma


@njit(cache=True)
def _box_enthalpy(fe, ce, pressure0, volume0, det):
    """The box's share of ``U + P0 V``: ``-P0 V0 d(det F)/de`` added to the strain forces ``fe``
    (``ce = d(det F)/de`` of the loop's solver, ``V0 = det h0``); returns ``P0 V``."""
    for p in range(fe.shape[0]):
        fe[p] -= pressure0 * volume0 * ce[p]
    return pressure0 * volume0 * det


@njit(cache=True)
def _strain_step_back(y, vy, e, ve, body, vb, vh, free, dt):
    """FIRE's step back on an uphill step: half a step back along the velocity, which is zeroed (every group)."""
    for i in free:
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
    vh[:, :] = 0.0


@njit(cache=True)
def _strain_move(y, vy, fy, e, ve, fe, body, vb, fb, inv_mass, vh, fh, free, dt, alpha):
    """FIRE's semi-implicit Euler step of centres, strain (unit masses) and bodies (inverse masses ``inv_mass``):
    ``v += dt M^-1 F``, mixing with ``|v|_M`` and ``|F|_M^-1`` (the unit-mass FIRE of ``M^(1/2) q``), move.
    The hinged spheres' velocities ``vh`` (unit masses, forces ``fh``) are updated and mixed; their move is
    :func:`hinge_strain_advance`. Centres ``y`` of the spheres ``free`` alone (the others' forces and velocities
    are zero)."""
    for i in free:
        for a in range(y.shape[1]):
            vy[i, a] += dt * fy[i, a]
    for p in range(e.shape[0]):
        ve[p] += dt * fe[p]
    for c in range(body.shape[0]):
        for a in range(3):
            vb[c, a] += dt * fb[c, a] * inv_mass[c, a]
    for k in range(vh.shape[0]):
        for a in range(3):
            vh[k, a] += dt * fh[k, a]
    vnorm = np.sqrt(_speed_sq(vy, ve, vb, vh, inv_mass, free))
    fnorm = np.sqrt(_free_dot(fy, fy, free) + _dot1(fe, fe) + body_power_norms(fb, vb, inv_mass)[2] + _dot(fh, fh))
    keep, mix = _fire_mixing(alpha, vnorm, fnorm)
    for k in range(vh.shape[0]):
        for a in range(3):
            vh[k, a] = _mixed(keep, vh[k, a], mix, fh[k, a])
    for i in free:
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


@njit(cache=True, inline="always")
def _speed_sq(vy, ve, vb, vh, inv_mass, free):
    """``|v|_M^2`` in FIRE's metric: centres ``free`` and strain (unit masses), bodies (``1 / inv_mass``), hinged
    spheres (unit masses); twice the kinetic energy. (``body_power_norms`` with ``vb`` in the force slot: only its
    ``|v|_M^2`` is used.)"""
    return _free_dot(vy, vy, free) + _dot1(ve, ve) + body_power_norms(vb, vb, inv_mass)[1] + _dot(vh, vh)


@njit(cache=True)
def _rebuild_due(y, T, A, y_build, reach, skin):
    """Verlet test of the deformed-box list (:func:`jamflow.neighbors._verlet_kernels._needs_rebuild` fused).

    The build centres carried by the deformation ``A = U h_build^-1`` since the build are
    ``T y_build`` (``T = U h0^-1``), so a centre's displacement in the deformed box is
    ``T (y - y_build)``: the two largest, plus ``||A - 1||_F`` (``>= ||A - 1||_2``, no SVD
    per step) times the reach, against the skin. No copy of the centres.
    """
    d = y.shape[1]
    dev = 0.0
    for a in range(d):
        for c in range(d):
            t = A[a, c] - (1.0 if a == c else 0.0)
            dev += t * t
    m1 = 0.0
    m2 = 0.0
    three = d == 3
    for i in range(y.shape[0]):
        if three:  # the loop below unrolled: the same operations in the same order
            e0 = y[i, 0] - y_build[i, 0]
            e1 = y[i, 1] - y_build[i, 1]
            e2 = y[i, 2] - y_build[i, 2]
            t0 = T[0, 0] * e0 + T[0, 1] * e1 + T[0, 2] * e2
            t1 = T[1, 1] * e1 + T[1, 2] * e2
            t2 = T[2, 2] * e2
            d2 = t0 * t0 + t1 * t1 + t2 * t2
        else:
            d2 = 0.0
            for a in range(d):
                t = 0.0
                for c in range(a, d):
                    t += T[a, c] * (y[i, c] - y_build[i, c])
                d2 += t * t
        if d2 > m1:
            m1, m2 = d2, m1
        elif d2 > m2:
            m2 = d2
    return np.sqrt(m1) + np.sqrt(m2) + np.sqrt(dev) * reach >= skin


@njit(cache=True)
def _free_dot(a, b, rows):
    """``sum a_i . b_i`` over the ``rows`` of two (N, d) arrays."""
    s = 0.0
    for i in rows:
        for k in range(a.shape[1]):
            s += a[i, k] * b[i, k]
    return s


@njit(cache=True)
def _free_max_sq(a, rows):
    """Largest ``|a_i|^2`` over the ``rows`` of ``a`` (N, d)."""
    out = 0.0
    for i in rows:
        s = 0.0
        for k in range(a.shape[1]):
            s += a[i, k] * a[i, k]
        out = max(out, s)
    return out


@njit(cache=True)
def _dot1(a, b):
    """``a . b`` of two flat vectors."""
    s = 0.0
    for k in range(a.shape[0]):
        s += a[k] * b[k]
    return s
