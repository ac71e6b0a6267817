"""Numba kernels of the soft-sphere package: pair forces, FIRE and steepest descent.

Positions enter as ``x = s * y``: ``y`` are coordinates in a reference box ``h_ref``
and ``s`` an isotropic scale factor (``s = 1`` and no box degree of freedom for
fixed-box minimisation). The pair vector of pair ``p`` is
``s * (y[j] - y[i] + offset[p])`` with ``offset[p] = h_ref @ n_p`` the periodic image
fixed when the neighbour list was built. All kernels are single-threaded and cached.

The minimisers take their inputs in a few records (NamedTuples, which numba passes as
their fields): the neighbour list (:class:`PairList`), when it was built
(:class:`ListBuild`), the potential (:class:`Potential`), the enthalpy terms
(:class:`Enthalpy`) and the stopping rule (:class:`Stop`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..._numba import njit
from ...minimize._fire_kernels import (
    BELOW,
    COLLAPSED,
    CONVERGED,
    MAX_STEPS,
    REBUILD,
    _axpy,
    _dot,
    _fire_adapt,
    _fire_mixing,
    _fire_step_back,
    _max_force_sq,
    _mix_and_move,
    _mix_velocity,
    _mixed,
)
from ...neighbors._verlet_kernels import _inline_list, _list_buffers, _needs_rebuild


class PairList(NamedTuple):
    """A neighbour list as the kernels read it: per pair the image offset ``offset``
    (P, d) [reference-box lengths], the particles ``pi``, ``pj`` (P,) and the contact
    distance ``sigma`` (P,)."""

    offset: NDArray[np.float64]
    pi: NDArray[np.int64]
    pj: NDArray[np.int64]
    sigma: NDArray[np.float64]


class ListBuild(NamedTuple):
    """When the list is due: the reference coordinates ``y_build`` (N, d) it was built
    at, its reach and skin [length], and the ``slack`` [length] its build already used."""

    y_build: NDArray[np.float64]
    reach: float
    skin: float
    slack: float


class Potential(NamedTuple):
    """The pair potential ``epsilon / w (1 - r / sigma)^w``: ``epsilon`` [energy] and the exponent ``w``."""

    epsilon: float
    exponent: float


class Enthalpy(NamedTuple):
    """The enthalpy ``H = U + P0 V`` of a free box: whether it is minimised (``on``; fixed
    box otherwise), the pressure ``pressure0``, the reference volume ``volume_ref``, the
    box coordinate's scale ``q_scale`` [length] and the box scale ``scale_min`` at or below
    which the box holds the spheres no more
    (:meth:`jamflow.neighbors.verlet.NeighborList.smallest_scale`)."""

    on: bool
    pressure0: float
    volume_ref: float
    q_scale: float
    scale_min: float


class Stop(NamedTuple):
    """When a run stops: the largest force ``force_tol`` [energy / length], the relative
    tolerance ``rtol`` of the pressure (or stress) to ``P0``, the step budget ``max_steps``,
    and at a fixed box the energy floor [energy] (``U + K`` at or below it stops the run
    with ``BELOW``; 0: never)."""

    force_tol: float
    rtol: float
    max_steps: int
    energy_floor: float


@njit(cache=True, inline="always")
def _pair_magnitude(r2, sig, eps, w, harmonic):
    """Energy, force magnitude ``-dV/dr`` and ``1 / r`` of one overlapping pair (``r < sig``)."""
    r = np.sqrt(r2)
    xi = 1.0 - r / sig
    if harmonic:
        energy = 0.5 * eps * xi * xi
        fmag = eps * xi / sig
    else:
        energy = eps / w * xi**w
        fmag = eps * xi ** (w - 1.0) / sig
    return energy, fmag, 1.0 / r


@njit(cache=True, inline="always")
def _add_pair(i, j, dx, r2, sig, eps, w, harmonic, force, virial):
    """Add one overlapping pair (``r < sig``) to forces and virial; return its energy."""
    energy, fmag, inv_r = _pair_magnitude(r2, sig, eps, w, harmonic)
    for a in range(dx.shape[0]):
        fa = fmag * dx[a] * inv_r
        force[j, a] += fa
        force[i, a] -= fa
        for b in range(dx.shape[0]):
            virial[a, b] += fmag * dx[a] * dx[b] * inv_r
    return energy


@njit(cache=True, inline="always")
def _pair_loop(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial, three):
    """:func:`pair_forces` for d = 2 (``three`` False) or 3 with the coordinates unrolled.

    Inlined into :func:`_pair_forces_2d` and :func:`_pair_forces_3d` with ``three`` a
    constant, so each compiles without the other's branches. In 2D the third pair
    vector component is 0.0 and ``r2 + 0.0 == r2`` exactly, so both dimensions add
    the same terms in the same order as the generic loop.
    """
    energy = 0.0
    n_contact = 0
    harmonic = w == 2.0
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        dx0 = s * (y[j, 0] - y[i, 0] + offset[p, 0])
        dx1 = s * (y[j, 1] - y[i, 1] + offset[p, 1])
        dx2 = s * (y[j, 2] - y[i, 2] + offset[p, 2]) if three else 0.0
        r2 = dx0 * dx0 + dx1 * dx1 + dx2 * dx2
        sig = sigma[p]
        if r2 < sig * sig:
            e, fmag, inv_r = _pair_magnitude(r2, sig, eps, w, harmonic)
            energy += e
            n_contact += 1
            f0 = fmag * dx0 * inv_r
            f1 = fmag * dx1 * inv_r
            force[j, 0] += f0
            force[i, 0] -= f0
            force[j, 1] += f1
            force[i, 1] -= f1
            if three:
                f2 = fmag * dx2 * inv_r
                force[j, 2] += f2
                force[i, 2] -= f2
            if with_virial:
                virial[0, 0] += fmag * dx0 * dx0 * inv_r
                virial[0, 1] += fmag * dx0 * dx1 * inv_r
                virial[1, 0] += fmag * dx1 * dx0 * inv_r
                virial[1, 1] += fmag * dx1 * dx1 * inv_r
                if three:
                    virial[0, 2] += fmag * dx0 * dx2 * inv_r
                    virial[1, 2] += fmag * dx1 * dx2 * inv_r
                    virial[2, 0] += fmag * dx2 * dx0 * inv_r
                    virial[2, 1] += fmag * dx2 * dx1 * inv_r
                    virial[2, 2] += fmag * dx2 * dx2 * inv_r
    return energy, n_contact


@njit(cache=True)
def _pair_forces_2d(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial):
    return _pair_loop(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial, False)


@njit(cache=True)
def _pair_forces_3d(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial):
    return _pair_loop(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial, True)


@njit(cache=True)
def pair_forces(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial=True):
    """Energy, forces and virial of the power-law contact potential.

    ``U = (eps / w) sum_{r < sigma} (1 - r / sigma)^w``. Fills ``force`` (N, d) with
    ``-dU/dx`` and, when ``with_virial``, ``virial`` (d, d) with ``sum f r_a r_b / r``
    (f = repulsive pair force magnitude); otherwise ``virial`` is left zero (a
    fixed-box minimiser needs no stress on every step). Returns
    ``(U, number of overlapping pairs)``. d = 2 and 3 run loops with the coordinates
    unrolled (no per-pair temporary, no runtime dimension loop): the same terms in the
    same order, so the same bits.
    """
    d = y.shape[1]
    force[:, :] = 0.0
    virial[:, :] = 0.0
    if d == 2:
        return _pair_forces_2d(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial)
    if d == 3:
        return _pair_forces_3d(y, s, offset, pi, pj, sigma, eps, w, force, virial, with_virial)
    energy = 0.0
    n_contact = 0
    dx = np.empty(d)
    # the virial of a run without stress goes to a scratch matrix
    target = virial if with_virial else np.zeros((d, d))
    harmonic = w == 2.0
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        r2 = 0.0
        for a in range(d):
            dx[a] = s * (y[j, a] - y[i, a] + offset[p, a])
            r2 += dx[a] * dx[a]
        if r2 < sigma[p] * sigma[p]:
            energy += _add_pair(i, j, dx, r2, sigma[p], eps, w, harmonic, force, target)
            n_contact += 1
    return energy, n_contact


@njit(cache=True)
def fire(y, v, box_state, fire_state, fire_params, pairs, potential, built, s_build, enthalpy, stop,
         force, virial, lengths, diameter):
    """FIRE 2.0 (Guénolé et al. 2020, Algorithm 2; Bitzek et al. 2006) with unit masses.

    Parameters (arrays are updated in place so a run can resume after a rebuild)
    ----------
    y, v : (N, d) reference-box coordinates and velocities.
    box_state : (3,) ``[q, v_q, s]`` with ``s = exp(q / q_scale)`` the box scale
        (only evolves when ``enthalpy.on``).
    fire_state : (4,) ``[dt, alpha, n_positive, steps]``, ``steps`` taken by the run before this call.
    fire_params : (8,) ``[dt_max, dt_min, f_inc, f_dec, alpha0, f_alpha, n_delay,
        initial_delay]``.
    pairs : PairList
    potential : Potential
    built : ListBuild
        With ``s_build`` the box scale at the build.
    enthalpy : Enthalpy
        With ``on``, minimise the enthalpy ``H = U + P0 V`` with ``q`` as a degree of
        freedom, whose generalised force is ``d V (P - P0) / q_scale``. A step that takes
        ``s`` to ``scale_min`` or below stops the run with ``COLLAPSED`` before the forces
        are evaluated, ``box_state`` holding that ``s`` and the returned values those
        before the step.
    stop : Stop
        ``rtol`` bounds ``|P - P0| / P0`` (with ``enthalpy.on``); ``energy_floor`` is
        used at a fixed box only, tested after the list test.
    force, virial : (N, d), (d, d) work arrays, the last evaluation's on return.
    lengths : (d,) or (0,)
        Sides of an orthogonal reference box: the list is rebuilt inside the loop
        (:func:`_inline_list`) while ``reach`` stays below half the scaled sides; empty
        (a sheared box), or a box too small, returns ``REBUILD`` to the caller instead.
        Either way the forces are evaluated again with the new list (one evaluation per
        build) and the convergence test repeated, so the path is the same.
    diameter : (N,)

    Returns
    -------
    status, steps, energy, n_contact, max_force_sq, pressure, builds, pi, pj, image, y_build, s_build
        ``builds`` lists made inside the loop (each with one more force evaluation); the
        last one's pairs, integer images, build positions (reference coordinates) and
        scale (the inputs when ``builds`` is 0).
    """
    offset, pi, pj, sigma = pairs
    eps, w = potential
    y_build, reach, skin, slack = built
    barostat, pressure0, volume_ref, q_scale, scale_min = enthalpy
    force_tol, pressure_rtol, max_steps, energy_floor = stop
    floor = energy_floor if not barostat else 0.0
    d = y.shape[1]
    dt, alpha, npos = fire_state[0], fire_state[1], int(fire_state[2])
    # steps of the run before this call: the initial delay counts from the run's start,
    # not from the last neighbour-list rebuild
    done = int(fire_state[3])
    dt_max, dt_min, f_inc, f_dec = fire_params[0], fire_params[1], fire_params[2], fire_params[3]
    alpha0, f_alpha, n_delay = fire_params[4], fire_params[5], int(fire_params[6])
    initial_delay = fire_params[7] > 0.0
    q, vq, s = box_state[0], box_state[1], box_state[2]
    builds = 0
    image = np.empty((0, d), dtype=np.int64)
    # reused by every build of this call (fresh memory page-faults on first touch)
    buffers = _list_buffers(y.shape[0] if lengths.shape[0] else 0, d)
    # no sides (a sheared box): shortest 0, so every rebuild goes back to the caller
    shortest = np.inf if lengths.shape[0] else 0.0
    for a in range(lengths.shape[0]):
        shortest = min(shortest, lengths[a])
    # at a fixed box the virial is needed only once, at the end
    energy, n_contact = pair_forces(y, s, offset, pi, pj, sigma, eps, w, force, virial, barostat)
    volume = volume_ref * s**d
    pressure = (np.trace(virial)) / (d * volume)
    fmax2 = _max_force_sq(force)
    status = MAX_STEPS
    step = 0
    # the generalised force on reference coordinates is s * F (chain rule)
    while step < max_steps:
        if fmax2 <= force_tol * force_tol and (
            not barostat or abs(pressure - pressure0) <= pressure_rtol * pressure0
        ):
            status = CONVERGED
            break
        if _needs_rebuild(y, y_build, s, s_build, reach, skin, slack):
            if not reach < 0.5 * s * shortest:
                status = REBUILD
                break
            pi, pj, image, offset, sigma, buffers = _inline_list(y, s, lengths, diameter, reach, skin, buffers)
            y_build, s_build, slack = y.copy(), s, 0.0
            builds += 1
            # the forces at y came from the used-up list: evaluate again, then test again
            energy, n_contact = pair_forces(y, s, offset, pi, pj, sigma, eps, w, force, virial, barostat)
            pressure = np.trace(virial) / (d * volume)
            fmax2 = _max_force_sq(force)
            continue
        # the energy of a valid list (the test above) and the kinetic energy of unit masses
        if floor > 0.0 and energy + 0.5 * _dot(v, v) <= floor:
            status = BELOW
            break
        fq = d * volume * (pressure - pressure0) / q_scale if barostat else 0.0
        power = s * _dot(force, v) + fq * vq
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            _fire_step_back(y, v, dt)
            if barostat:
                q -= 0.5 * dt * vq
                vq = 0.0
        # semi-implicit Euler with FIRE velocity mixing; the generalised force s F is
        # never formed (mix * s * F keeps the rounding of the fused original)
        _axpy(dt * s, force, v)
        if barostat:
            vq += dt * fq
        vnorm = np.sqrt(_dot(v, v) + vq * vq)
        fnorm = np.sqrt(s * s * _dot(force, force) + fq * fq)
        keep, mix = _fire_mixing(alpha, vnorm, fnorm)
        vq = _mixed(keep, vq, mix, fq)
        _mix_and_move(v, force, keep, mix * s, y, dt)
        if barostat:
            q += dt * vq
            s = np.exp(q / q_scale)
            volume = volume_ref * s**d
            # a P0 beyond what the finite-range repulsion exerts drives the box down without
            # end (in one step when P0 is huge: s underflows to 0, every pair distance with
            # it, and the forces would divide by r = 0); at scale_min the list is stale from
            # the scale change alone and no new one fits, so no run stopped here could go on
            if not s > scale_min:
                status = COLLAPSED
                break
        energy, n_contact = pair_forces(y, s, offset, pi, pj, sigma, eps, w, force, virial, barostat)
        pressure = np.trace(virial) / (d * volume)
        fmax2 = _max_force_sq(force)
        step += 1
    if not barostat:
        energy, n_contact = pair_forces(y, s, offset, pi, pj, sigma, eps, w, force, virial)
        pressure = np.trace(virial) / (d * volume)
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    box_state[0], box_state[1], box_state[2] = q, vq, s
    return status, step, energy, n_contact, fmax2, pressure, builds, pi, pj, image, y_build, s_build


@njit(cache=True)
def steepest_descent(y, pairs, potential, built, dt, stop, force, virial, energies):
    """Overdamped integrator ``dx/dt = -grad U`` (Lerner et al. Eq. 31, xi_0 = 1), fixed step.

    Stops when the largest per-particle ``|grad U|`` falls below ``stop.force_tol``
    (a fixed box: ``stop.rtol`` is not used). ``energies`` (K,) receives the energy
    before each of the first K steps.

    Returns
    -------
    status, steps, energy, n_contact, max_force_sq
    """
    offset, pi, pj, sigma = pairs
    eps, w = potential
    y_build, reach, skin, slack = built
    force_tol, _, max_steps, _ = stop
    energy, n_contact = pair_forces(y, 1.0, offset, pi, pj, sigma, eps, w, force, virial, False)
    fmax2 = _max_force_sq(force)
    status = MAX_STEPS
    step = 0
    while True:
        if step < energies.shape[0]:
            energies[step] = energy
        if fmax2 <= force_tol * force_tol:
            status = CONVERGED
            break
        if step >= max_steps:
            break
        if _needs_rebuild(y, y_build, 1.0, 1.0, reach, skin, slack):
            status = REBUILD
            break
        _axpy(dt, force, y)
        energy, n_contact = pair_forces(y, 1.0, offset, pi, pj, sigma, eps, w, force, virial, False)
        fmax2 = _max_force_sq(force)
        step += 1
    # the virial (pressure) only of the final state
    energy, n_contact = pair_forces(y, 1.0, offset, pi, pj, sigma, eps, w, force, virial)
    return status, step, energy, n_contact, fmax2


@njit(cache=True)
def pair_forces_affine(y, A, offset, pi, pj, sigma, eps, w, force, virial):
    """:func:`pair_forces` for centres ``x = A y`` with a general (upper-triangular) ``A``.

    Pair vectors are ``A (y_j - y_i + offset)``, each formed in the deformed frame from
    its reference vector (no transformed copy of the centres or images); ``force`` is
    ``-dU/dx`` (N, d); the virial's upper triangle is summed and mirrored. d = 2 and 3 run
    with the coordinates unrolled (:func:`_affine_pair_loop`), the same operations in the
    same order.
    """
    force[:, :] = 0.0
    virial[:, :] = 0.0
    if y.shape[1] == 3:
        return _affine_pair_loop(y, A, offset, pi, pj, sigma, eps, w, force, virial, True)
    if y.shape[1] == 2:
        return _affine_pair_loop(y, A, offset, pi, pj, sigma, eps, w, force, virial, False)
    return _affine_pairs_generic(y, A, offset, pi, pj, sigma, eps, w, force, virial)


@njit(cache=True)
def _affine_pairs_generic(y, A, offset, pi, pj, sigma, eps, w, force, virial):
    """:func:`pair_forces_affine` in any d, adding to ``force`` and ``virial``."""
    d = y.shape[1]
    energy = 0.0
    n_contact = 0
    ref = np.empty(d)
    dx = np.empty(d)
    harmonic = w == 2.0
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        for a in range(d):
            ref[a] = y[j, a] - y[i, a] + offset[p, a]
        r2 = 0.0
        for a in range(d):
            acc = 0.0
            for b in range(a, d):
                acc += A[a, b] * ref[b]
            dx[a] = acc
            r2 += acc * acc
        if r2 < sigma[p] * sigma[p]:
            e, fmag, inv_r = _pair_magnitude(r2, sigma[p], eps, w, harmonic)
            energy += e
            n_contact += 1
            c = fmag * inv_r
            for a in range(d):
                fa = c * dx[a]
                force[j, a] += fa
                force[i, a] -= fa
                for b in range(a, d):
                    virial[a, b] += fa * dx[b]
    _mirror(virial)
    return energy, n_contact


@njit(cache=True, inline="always")
def _mirror(virial):
    """The lower triangle of ``virial`` set from the upper one (the pair virial is symmetric)."""
    for a in range(virial.shape[0]):
        for b in range(a):
            virial[a, b] = virial[b, a]


@njit(cache=True, inline="always")
def _affine_pair_loop(y, A, offset, pi, pj, sigma, eps, w, force, virial, three):
    """:func:`_affine_pairs_generic` for d = 2 (``three`` False) or 3 with the coordinates unrolled:
    the generic loop's operations in its order (``0.0 + a == a`` exactly), so the same bits."""
    energy = 0.0
    n_contact = 0
    harmonic = w == 2.0
    a00, a01, a11 = A[0, 0], A[0, 1], A[1, 1]
    a02 = A[0, 2] if three else 0.0
    a12 = A[1, 2] if three else 0.0
    a22 = A[2, 2] if three else 0.0
    for p in range(pi.shape[0]):
        i = pi[p]
        j = pj[p]
        r0 = y[j, 0] - y[i, 0] + offset[p, 0]
        r1 = y[j, 1] - y[i, 1] + offset[p, 1]
        if three:
            r2 = y[j, 2] - y[i, 2] + offset[p, 2]
            dx0 = a00 * r0 + a01 * r1 + a02 * r2
            dx1 = a11 * r1 + a12 * r2
            dx2 = a22 * r2
        else:
            dx0 = a00 * r0 + a01 * r1
            dx1 = a11 * r1
            dx2 = 0.0
        rr = dx0 * dx0 + dx1 * dx1 + dx2 * dx2
        sig = sigma[p]
        if rr < sig * sig:
            e, fmag, inv_r = _pair_magnitude(rr, sig, eps, w, harmonic)
            energy += e
            n_contact += 1
            c = fmag * inv_r
            f0 = c * dx0
            f1 = c * dx1
            force[j, 0] += f0
            force[i, 0] -= f0
            force[j, 1] += f1
            force[i, 1] -= f1
            virial[0, 0] += f0 * dx0
            virial[0, 1] += f0 * dx1
            virial[1, 1] += f1 * dx1
            if three:
                f2 = c * dx2
                force[j, 2] += f2
                force[i, 2] -= f2
                virial[0, 2] += f0 * dx2
                virial[1, 2] += f1 * dx2
                virial[2, 2] += f2 * dx2
    _mirror(virial)
    return energy, n_contact


@njit(cache=True)
def _box_force(virial, A, volume, pressure0, q_scale, out):
    """``-dH/dA`` on the upper triangle, ``(W - P0 V 1) A^-T / q_scale``."""
    d = A.shape[0]
    Ainv = np.linalg.inv(A)
    for a in range(d):
        for b in range(d):
            out[a, b] = 0.0
            if b < a:
                continue
            acc = 0.0
            for c in range(d):
                stress = virial[a, c] - (pressure0 * volume if a == c else 0.0)
                acc += stress * Ainv[b, c]
            out[a, b] = acc / q_scale


@njit(cache=True)
def fire_stress(y, v, A, vA, fire_state, fire_params, pairs, potential, built, A_build_inv, enthalpy, stop,
                force, virial):
    """FIRE 2.0 on ``H = U + P0 V`` with centres and the full upper-triangular box.

    Centres are ``x = A y`` and the box ``A h_ref``; the box degrees of freedom are
    ``q_scale A_ab`` (a <= b) with generalised forces ``(W - P0 V 1) A^-T / q_scale``
    (``W = sum f R R^T / r``), so at the minimum the stress tensor is ``-P0 1``.
    Converged when ``max_i |F_i| <= stop.force_tol`` and
    ``max_ab |W_ab / V - P0 delta_ab| <= stop.rtol * P0``. ``A_build_inv`` is the
    inverse of ``A`` at the list's build (``built``); ``enthalpy.on`` and ``enthalpy.scale_min``
    are not read.

    Returns
    -------
    status, steps, energy, n_contact, max_force_sq, max_stress_error
    """
    offset, pi, pj, sigma = pairs
    eps, w = potential
    y_build, reach, skin, slack = built
    _, pressure0, volume_ref, q_scale, _ = enthalpy
    force_tol, stress_tol, max_steps, _ = stop
    d = y.shape[1]
    dt, alpha, npos = fire_state[0], fire_state[1], int(fire_state[2])
    # steps of the run before this call: the initial delay counts from the run's start,
    # not from the last neighbour-list rebuild
    done = int(fire_state[3])
    dt_max, dt_min, f_inc, f_dec = fire_params[0], fire_params[1], fire_params[2], fire_params[3]
    alpha0, f_alpha, n_delay = fire_params[4], fire_params[5], int(fire_params[6])
    initial_delay = fire_params[7] > 0.0
    fA = np.zeros((d, d))
    fy = np.empty_like(y)
    status = MAX_STEPS
    step = 0
    energy, n_contact = pair_forces_affine(y, A, offset, pi, pj, sigma, eps, w, force, virial)
    while True:
        volume = volume_ref * np.prod(np.diag(A))
        fmax2 = _max_force_sq(force)
        err = 0.0
        for a in range(d):
            for b in range(d):
                e = abs(virial[a, b] / volume - (pressure0 if a == b else 0.0))
                err = max(err, e)
        if fmax2 <= force_tol * force_tol and err <= stress_tol * pressure0:
            status = CONVERGED
            break
        if step >= max_steps:
            break
        # rebuild test: non-affine displacement in x plus the box deformation since the build
        m = 0.0
        for i in range(y.shape[0]):
            d2 = 0.0
            for a in range(d):
                acc = 0.0
                for b in range(a, d):
                    acc += A[a, b] * (y[i, b] - y_build[i, b])
                d2 += acc * acc
            m = max(m, d2)
        deform = A @ A_build_inv
        dev = 0.0
        for a in range(d):
            for b in range(d):
                e = deform[a, b] - (1.0 if a == b else 0.0)
                dev += e * e
        if 2.0 * np.sqrt(m) + np.sqrt(dev) * reach + slack >= skin:
            status = REBUILD
            break
        _box_force(virial, A, volume, pressure0, q_scale, fA)
        # generalised force on y: A^T F
        for i in range(y.shape[0]):
            for b in range(d):
                acc = 0.0
                for a in range(b + 1):
                    acc += A[a, b] * force[i, a]
                fy[i, b] = acc
        power = _dot(fy, v) + _dot(fA, vA)
        npos, dt, alpha = _fire_adapt(
            power, done + step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min,
            initial_delay,
        )
        if not power > 0.0:
            _axpy(-0.5 * dt / q_scale, vA, A)
            _fire_step_back(y, v, dt)
            vA[:, :] = 0.0
        _axpy(dt, fy, v)
        _axpy(dt, fA, vA)
        vnorm = np.sqrt(_dot(v, v) + _dot(vA, vA))
        fnorm = np.sqrt(_dot(fy, fy) + _dot(fA, fA))
        keep, mix = _fire_mixing(alpha, vnorm, fnorm)
        _mix_and_move(v, fy, keep, mix, y, dt)
        # the box lower triangle has zero force and velocity, so mixing leaves it zero
        _mix_velocity(vA, fA, keep, mix)
        for a in range(d):
            for b in range(a, d):
                A[a, b] += dt * vA[a, b] / q_scale
        energy, n_contact = pair_forces_affine(y, A, offset, pi, pj, sigma, eps, w, force, virial)
        step += 1
    fire_state[0], fire_state[1], fire_state[2], fire_state[3] = dt, alpha, npos, done + step
    return status, step, energy, n_contact, fmax2, err
