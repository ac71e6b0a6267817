"""Compiled FIRE loop of the shape models: pair forces of every family and the FIRE steps in one numba call.

Bodies are rows ``(x, y, theta)`` of one ``(N, 3)`` array: reference centres ``y`` in a
reference box ``h_ref`` and the orientation (an isotropic barostat scales centres by
``s``, never the shapes). The pair vector of pair ``p`` is
``s (y_j - y_i + offset_p)`` with ``offset_p = h_ref n_p``. The family's pair kernel
(:mod:`._kernels`) is chosen by a code, so the loop is one cached kernel for every
family; ellipses keep each listed pair's Perram–Wertheim multiplier from step to step
and warm-start its solve from it. All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from ..._numba import njit
from ...minimize._fire_kernels import (
    BELOW,
    CONVERGED,
    MAX_STEPS,
    REBUILD,
    _dot,
    _fire_adapt,
    _fire_mixing,
    _fire_step_back,
    _mixed,
)
from ...neighbors._verlet_kernels import _inline_list, _list_buffers, _needs_rebuild
from ._kernels import (
    CIRCULO,
    ELLIPSE,
    REULEAUX,
    _ellipse_matrix,
    circulo_vertex_edge,
    core_radius,
    dumbbell_pair,
    ellipse_terms_matrices,
    reuleaux_pair,
    rotate_vertices,
)


@njit(cache=True, inline="always")
def _pair(family, dx0, dx1, ti, tj, pa, pb, k, g):
    """Energy of one Reuleaux or dumbbell pair, gradient added to ``g``.

    Circulo and ellipse pairs take per-body terms of their orientations instead (:func:`shape_forces`).
    """
    if family == REULEAUX:
        return reuleaux_pair(dx0, dx1, ti, tj, pa, pb, k, g)
    return dumbbell_pair(dx0, dx1, ti, tj, pa, pb, k, g)


@njit(cache=True)
def _body_terms(y, family, params):
    """Per-body functions of the orientation used by every pair of the body, shape (N, W).

    Circulo: the vertices rotated to the orientation, relative to the centre, and the core
    radius (``x0, y0, x1, y1, ..., rho``; :func:`._kernels.core_radius`); ellipse: the shape
    matrix ``R diag(a^2, b^2) R^T`` (entries xx, xy, yy); other families none (zero rows).
    """
    n = y.shape[0] if family == CIRCULO or family == ELLIPSE else 0
    out = np.zeros((n, params.shape[1] - 1 if family == CIRCULO else 3))
    for i in range(n):
        if family == CIRCULO:
            rotate_vertices(params[i], np.cos(y[i, 2]), np.sin(y[i, 2]), out, i)
            out[i, out.shape[1] - 1] = core_radius(params[i])
        else:
            out[i, 0], out[i, 1], out[i, 2] = _ellipse_matrix(params[i, 0], params[i, 1], y[i, 2])
    return out


@njit(cache=True)
def shape_forces(y, s, offset, pi, pj, family, params, bound, lam, k, force, virial):
    """Energy, generalised forces ``-dU/d(x, y, theta)`` (N, 3) and virial of the listed pairs.

    Pairs whose bounding circles (radii ``bound``) do not overlap are skipped;
    circulo and ellipse bodies have the terms of their orientations computed once per
    body (:func:`_body_terms`); an ellipse pair updates its Perram–Wertheim multiplier
    ``lam[p]``. The virial is ``-sum dU/dx_j[a] dx[b]`` (:func:`._kernels.pair_sum`). Returns the energy
    and the number of interacting pairs.
    """
    for i in range(force.shape[0]):
        force[i, 0] = 0.0
        force[i, 1] = 0.0
        force[i, 2] = 0.0
    virial[:, :] = 0.0
    energy = 0.0
    n_contact = 0
    g = np.zeros(6)
    body = _body_terms(y, family, params)
    rho = body.shape[1] - 1
    for p in range(pi.shape[0]):
        a = pi[p]
        b = pj[p]
        dx0 = s * (y[b, 0] - y[a, 0] + offset[p, 0])
        dx1 = s * (y[b, 1] - y[a, 1] + offset[p, 1])
        reach = bound[a] + bound[b]
        if dx0 * dx0 + dx1 * dx1 >= reach * reach:
            continue
        g[:] = 0.0
        if family == CIRCULO:
            ra, rb = params[a, 0], params[b, 0]
            na, nb = int(params[a, 1]), int(params[b, 1])
            e = circulo_vertex_edge(dx0, dx1, body, a, b, ra, rb, na, nb, body[b, rho], k, g, 0, 3, None)[0]
            e += circulo_vertex_edge(-dx0, -dx1, body, b, a, rb, ra, nb, na, body[a, rho], k, g, 3, 0, None)[0]
        elif family == ELLIPSE:
            e, lam[p] = ellipse_terms_matrices(dx0, dx1, np.sqrt(dx0 * dx0 + dx1 * dx1), body[a, 0], body[a, 1],
                                               body[a, 2], body[b, 0], body[b, 1], body[b, 2], k, g, lam[p])
        else:
            e = _pair(family, dx0, dx1, y[a, 2], y[b, 2], params[a], params[b], k, g)
        if e > 0.0:
            energy += e
            n_contact += 1
            for c in range(3):
                force[a, c] -= g[c]
                force[b, c] -= g[3 + c]
            virial[0, 0] -= g[3] * dx0
            virial[0, 1] -= g[3] * dx1
            virial[1, 0] -= g[4] * dx0
            virial[1, 1] -= g[4] * dx1
    return energy, n_contact


@njit(cache=True)
def _max_generalized_sq(force, torque_arm):
    """``max_i |F_i|^2 + (tau_i / torque_arm)^2`` (the measure of :meth:`ShapeModel.max_force`)."""
    m = 0.0
    for i in range(force.shape[0]):
        t = force[i, 2] / torque_arm
        m = max(m, force[i, 0] * force[i, 0] + force[i, 1] * force[i, 1] + t * t)
    return m


@njit(cache=True, inline="always")
def _kinetic(v, inv_mass):
    """``2 K = sum v^2 / inv_mass`` over every degree of freedom."""
    twice = 0.0
    for i in range(v.shape[0]):
        for c in range(v.shape[1]):
            twice += v[i, c] * v[i, c] / inv_mass[i, c]
    return twice


@njit(cache=True)
def shape_fire(
    y, v, box_state, fire_state, fire_params, inv_mass,
    offset, pi, pj, lam, family, params, bound, k, torque_arm, rotations,
    y_build, s_build, reach, skin, lengths, diameter,
    barostat, pressure0, volume_ref, q_scale, force_tol, pressure_rtol, max_steps, energy_floor, force, virial,
):
    """FIRE 2.0 of shaped bodies in the mass metric (the steps of :class:`~jamflow.minimize.fire._ModelFire`).

    Parameters (arrays are updated in place so a run resumes after a return)
    ----------
    y, v : (N, 3) reference centres and orientations, and their velocities.
    box_state : (3,) ``[q, v_q, s]`` with ``s = exp(q / q_scale)`` (evolves only with ``barostat``).
    fire_state, fire_params : as :func:`jamflow.models.spheres._kernels.fire`.
    inv_mass : (N, 3) inverse masses of ``x``, ``y``, ``theta``.
    offset, pi, pj, lam : the list (reference offsets) and its pairs' Perram–Wertheim multipliers.
    family, params, bound, k : family code, per-body pair parameters, bounding radii, spring constant.
    torque_arm : length turning a torque into a force in the convergence test.
    rotations : bool
        False freezes the orientations (torques removed from the forces, so they never move).
    y_build, s_build, reach, skin : the list's build centres (reference), scale, reach and skin.
    lengths, diameter : sides of an orthogonal reference box (empty: a sheared box) and
        bounding diameters, for lists rebuilt inside the loop.
    barostat : bool
        Minimise ``H = U + P0 V`` with ``q`` (unit mass) as one more degree of freedom,
        generalised force ``d V (P - P0) / q_scale``.
    energy_floor : float
        At a fixed box, ``U + K`` (kinetic energy in the mass metric) at or below it stops
        the run with ``BELOW`` (0: never).

    The generalised force on reference centres is ``s F`` (chain rule); the step is
    the unit-mass FIRE of ``M^(1/2) q`` as in :class:`~jamflow.minimize.fire._ModelFire`.
    A move that uses up the skin rebuilds the list before forces are evaluated (inside
    the loop while ``reach`` fits half the scaled sides, else by returning ``REBUILD``
    with the forces not yet evaluated at ``y``).

    Returns
    -------
    status, steps, energy, n_contact, max_generalized_sq, pressure, builds, pi, pj, offset, lam, s_build
    """
    d = 2
    dt, alpha, npos = fire_state[0], fire_state[1], int(fire_state[2])
    done = int(fire_state[3])
    dt_max, dt_min, f_inc, f_dec = fire_params[0], fire_params[1], fire_params[2], fire_params[3]
    alpha0, f_alpha, n_delay = fire_params[4], fire_params[5], int(fire_params[6])
    initial_delay = fire_params[7] > 0.0
    q, vq, s = box_state[0], box_state[1], box_state[2]
    n = y.shape[0]
    centres = y[:, :2]
    accel = np.empty_like(y)
    gen = np.empty_like(y)
    buffers = _list_buffers(n if lengths.shape[0] else 0, d)
    shortest = np.inf if lengths.shape[0] else 0.0
    for a in range(lengths.shape[0]):
        shortest = min(shortest, lengths[a])
    builds = 0
    energy = 0.0
    n_contact = 0
    fmax2 = np.inf
    pressure = 0.0
    status = MAX_STEPS
    step = 0
    while True:
        # evaluation at y with a valid list
        if _needs_rebuild(centres, y_build, s, s_build, reach, skin, 0.0):
            if not reach < 0.5 * s * shortest:
                status = REBUILD
                break
            # a contiguous copy: the sphere engines' compiled list builder serves, not a second one
            pi, pj, _, offset, _, buffers = _inline_list(np.ascontiguousarray(centres), s, lengths, diameter,
                                                         reach, skin, buffers)
            lam = np.full(pi.shape[0], -1.0)
            for i in range(n):
                y_build[i, 0] = y[i, 0]
                y_build[i, 1] = y[i, 1]
            s_build = s
            builds += 1
        energy, n_contact = shape_forces(y, s, offset, pi, pj, family, params, bound, lam, k, force, virial)
        if not rotations:
            force[:, 2] = 0.0
        volume = volume_ref * s**d
        pressure = (virial[0, 0] + virial[1, 1]) / (d * volume)
        fmax2 = _max_generalized_sq(force, torque_arm)
        if fmax2 <= force_tol * force_tol and (
            not barostat or abs(pressure - pressure0) <= pressure_rtol * pressure0
        ):
            status = CONVERGED
            break
        if energy_floor > 0.0 and not barostat and energy + 0.5 * _kinetic(v, inv_mass) <= energy_floor:
            status = BELOW
            break
        if step >= max_steps:
            break
        fq = d * volume * (pressure - pressure0) / q_scale if barostat else 0.0
        for i in range(n):
            gen[i, 0] = s * force[i, 0]
            gen[i, 1] = s * force[i, 1]
            gen[i, 2] = force[i, 2]
        power = _dot(gen, v) + fq * vq
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            _fire_step_back(y, v, dt)
            if barostat:
                q -= 0.5 * dt * vq
                vq = 0.0
        # semi-implicit Euler in the mass metric: v += dt M^-1 F, mixing with |v|_M and |F|_M^-1
        vnorm2 = 0.0
        fnorm2 = 0.0
        for i in range(n):
            for c in range(3):
                acc = inv_mass[i, c] * gen[i, c]
                accel[i, c] = acc
                v[i, c] += dt * acc
                vnorm2 += v[i, c] * v[i, c] / inv_mass[i, c]
                fnorm2 += gen[i, c] * acc
        if barostat:
            vq += dt * fq
            vnorm2 += vq * vq
            fnorm2 += fq * fq
        keep, mix = _fire_mixing(alpha, np.sqrt(vnorm2), np.sqrt(fnorm2))
        for i in range(n):
            for c in range(3):
                vi = _mixed(keep, v[i, c], mix, accel[i, c])
                v[i, c] = vi
                y[i, c] += dt * vi
        if barostat:
            vq = _mixed(keep, vq, mix, fq)
            q += dt * vq
            s = np.exp(q / q_scale)
        step += 1
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    box_state[0], box_state[1], box_state[2] = q, vq, s
    return status, step, energy, n_contact, fmax2, pressure, builds, pi, pj, offset, lam, s_build
