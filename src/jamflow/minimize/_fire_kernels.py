"""Numba kernels of FIRE 2.0's control: time-step adaptation, velocity mixing, the step back.

Shared by the flat-vector FIRE of :mod:`jamflow.minimize.fire` and the compiled loops that
models offer as fast paths (:mod:`jamflow.models.spheres._kernels`).
"""

from __future__ import annotations

from .._numba import njit

__all__ = ["BELOW", "COLLAPSED", "CONVERGED", "REBUILD", "MAX_STEPS", "STALLED"]

#: Status codes returned by the iterative kernels; ``BELOW``: a fixed-box run stopped
#: because its energy ``U + K`` fell below the floor it was given (``minimize_fire``'s ``energy_floor``);
#: ``COLLAPSED``: a barostat shrank the box until it no longer holds the bodies (the target
#: pressure is beyond what their repulsion exerts in any box that does).
CONVERGED, REBUILD, MAX_STEPS, STALLED, BELOW, COLLAPSED = 0, 1, 2, 3, 4, 5


@njit(cache=True)
def _max_force_sq(force):
    m = 0.0
    for i in range(force.shape[0]):
        f2 = 0.0
        for a in range(force.shape[1]):
            f2 += force[i, a] * force[i, a]
        m = max(m, f2)
    return m


@njit(cache=True)
def _dot(a, b):
    acc = 0.0
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            acc += a[i, k] * b[i, k]
    return acc


@njit(cache=True)
def _axpy(c, a, b):
    """``b += c * a`` in place."""
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            b[i, k] += c * a[i, k]


@njit(cache=True, inline="always")
def _fire_adapt(power, step, npos, dt, alpha, n_delay, f_inc, f_dec, f_alpha, alpha0, dt_max, dt_min, initial_delay):
    """FIRE 2.0 step-size and mixing control; returns ``(npos, dt, alpha)``.

    Downhill (``power > 0``) for more than ``n_delay`` steps grows ``dt`` and shrinks
    ``alpha``; uphill resets ``npos`` and ``alpha`` and shrinks ``dt`` (not below
    ``dt_min``, and not during the initial delay).
    """
    if power > 0.0:
        npos += 1
        if npos > n_delay:
            dt = min(dt * f_inc, dt_max)
            alpha *= f_alpha
    else:
        npos = 0
        if not (initial_delay and step < n_delay):
            if dt * f_dec >= dt_min:
                dt *= f_dec
            alpha = alpha0
    return npos, dt, alpha


@njit(cache=True, inline="always")
def _fire_mixing(alpha, vnorm, fnorm):
    """FIRE velocity mixing ``v <- keep v + mix F``; returns ``(keep, mix)``.

    ``vnorm`` and ``fnorm`` are the norms of the velocity and force over every degree
    of freedom (in the metric of the masses); with no force the velocity is kept.
    """
    mix = alpha * vnorm / fnorm if fnorm > 0.0 else 0.0
    keep = 1.0 - alpha if fnorm > 0.0 else 1.0
    return keep, mix


@njit(cache=True, inline="always")
def _mixed(keep, v, c, f):
    """One mixed velocity component ``keep v + c f`` (``c`` = mixing coefficient x force scale)."""
    return keep * v + c * f


@njit(cache=True, inline="always")
def _mix_velocity(v, f, keep, c):
    """``v <- keep v + c f`` in place."""
    for i in range(v.shape[0]):
        for k in range(v.shape[1]):
            v[i, k] = _mixed(keep, v[i, k], c, f[i, k])


@njit(cache=True, inline="always")
def _mix_and_move(v, f, keep, c, x, dt):
    """``v <- keep v + c f`` and then ``x += dt v``, fused in one pass (no second sweep)."""
    for i in range(v.shape[0]):
        for k in range(v.shape[1]):
            vi = _mixed(keep, v[i, k], c, f[i, k])
            v[i, k] = vi
            x[i, k] += dt * vi


@njit(cache=True, inline="always")
def _fire_step_back(x, v, dt):
    """FIRE 2.0 correction after an uphill step: move back half a step and stop."""
    _axpy(-0.5 * dt, v, x)
    v[:, :] = 0.0
