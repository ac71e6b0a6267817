"""Numba kernels of rigid 2D clusters as rigid bodies under strain (shear-stabilised linked spheres).

A rigid 2D cluster (``n`` spheres, ``2 n - 3`` independent links) of
:class:`jamflow.models.strain.ShearStabilizedModel` is carried by its reference centre
``Y`` (2,) and an angle ``theta``: its spheres sit at the real-space (unrotated frame)
offsets ``r_s = R(theta) ref_s`` from the centre ``F Y``, so their reference centres are
``y_s = Y + F^-1 r_s - shift_s`` (``shift_s`` the periodic shift of the stored ``y_s``
from the unwrapped cluster, a lattice vector of the reference box). The strain moves the
centre affinely and leaves the shape alone: the links hold exactly, for every strain,
with no constraint, Gram factor or re-affixing.

Generalised forces at fixed ``(Y, theta)``, from the sphere forces ``fy_s = -dU/dy_s``
(``= F^T f_s``, ``f_s`` the real-space force) of the flat model: ``-dU/dY = sum_s fy_s``,
the torque ``-dU/dtheta = sum_s r_s x f_s``, and on the strain ``-dU/dF`` of the flat
model minus ``sum_s f_s rho_s^T`` (``rho_s = F^-1 r_s``: at fixed ``Y`` a sphere moves with
``dF (Y - shift_s)``, not with ``dF y_s``). The rods' stress is implicit: at force balance
this is the flat model's strain force with the link tensions' virial.

Mass metric: every sphere has unit mass, so a body's centre has mass ``n`` and its angle
the moment of inertia ``I = sum_s |ref_s|^2`` about the centroid (as the rigid path of
:func:`jamflow.models._link_kernels.rigid_project_2d`); the strain keeps unit mass.
At zero strain this is the flat model's metric on the bodies' own motions; the flat
metric also charges a strain velocity for the reference shifts ``-F^-1 dF rho_s`` of
the bodies' spheres, which this one does not. FIRE runs in this metric as the unit-mass
FIRE of ``M^(1/2) q`` (as the shapes' engine does). Bodies are ``(Y_x, Y_y, theta)``
rows (C, 3) with inverse masses (C, 3). All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit


@njit(cache=True)
def rigid_place(y, Finv, body, rptr, members, shift, ref, r):
    """Reference centres ``y_s = Y + F^-1 r_s - shift_s`` of every body's spheres, in place, and their
    real-space offsets ``r_s = R(theta) ref_s`` into ``r`` (M, 2) (for :func:`rigid_forces` at this point)."""
    for c in range(rptr.shape[0] - 1):
        cos = np.cos(body[c, 2])
        sin = np.sin(body[c, 2])
        for k in range(rptr[c], rptr[c + 1]):
            s = members[k]
            rx = cos * ref[k, 0] - sin * ref[k, 1]
            ry = sin * ref[k, 0] + cos * ref[k, 1]
            r[k, 0] = rx
            r[k, 1] = ry
            y[s, 0] = body[c, 0] + Finv[0, 0] * rx + Finv[0, 1] * ry - shift[k, 0]
            y[s, 1] = body[c, 1] + Finv[1, 0] * rx + Finv[1, 1] * ry - shift[k, 1]


@njit(cache=True)
def rigid_forces(Finv, rptr, members, r, scale, fy, fe, fb):
    """Body forces ``fb`` (C, 3) from the sphere forces ``fy`` (N, 2); ``fe`` (3,) made the strain force at fixed bodies.

    ``fy`` of the bodies' spheres is zeroed (they are not degrees of freedom);
    ``fe -= `` the strain components of ``C = sum_s f_s rho_s^T`` with ``f_s = F^-T fy_s``,
    ``rho_s = F^-1 r_s`` (module doc); ``r`` the offsets of :func:`rigid_place`.
    """
    if rptr.shape[0] < 2:
        return
    C00 = 0.0
    C01 = 0.0
    C10 = 0.0
    C11 = 0.0
    for c in range(rptr.shape[0] - 1):
        tx = 0.0
        ty = 0.0
        tau = 0.0
        for k in range(rptr[c], rptr[c + 1]):
            s = members[k]
            rx = r[k, 0]
            ry = r[k, 1]
            gx = fy[s, 0]
            gy = fy[s, 1]
            fx = Finv[0, 0] * gx + Finv[1, 0] * gy
            fyr = Finv[0, 1] * gx + Finv[1, 1] * gy
            px = Finv[0, 0] * rx + Finv[0, 1] * ry
            py = Finv[1, 0] * rx + Finv[1, 1] * ry
            tx += gx
            ty += gy
            tau += rx * fyr - ry * fx
            C00 += fx * px
            C01 += fx * py
            C10 += fyr * px
            C11 += fyr * py
            fy[s, 0] = 0.0
            fy[s, 1] = 0.0
        fb[c, 0] = tx
        fb[c, 1] = ty
        fb[c, 2] = tau
    # strain components in numpy.triu_indices order (xx, xy, yy), as strain_state
    fe[0] -= C00 / scale
    fe[1] -= (C01 + C10) / (np.sqrt(2.0) * scale)
    fe[2] -= C11 / scale


@njit(cache=True)
def rigid_max_force_sq(rptr, r, inv_mass, fb):
    """Largest squared per-sphere force of the bodies: ``|F / n + (tau / I) e_z x r_s|^2`` (the rigid-motion
    projection of the sphere forces, as :func:`jamflow.models._link_kernels.rigid_project_2d`)."""
    out = 0.0
    for c in range(rptr.shape[0] - 1):
        ax = fb[c, 0] * inv_mass[c, 0]
        ay = fb[c, 1] * inv_mass[c, 1]
        omega = fb[c, 2] * inv_mass[c, 2]
        for k in range(rptr[c], rptr[c + 1]):
            gx = ax - omega * r[k, 1]
            gy = ay + omega * r[k, 0]
            out = max(out, gx * gx + gy * gy)
    return out


@njit(cache=True)
def body_power_norms(fb, vb, inv_mass):
    """``(F . v, |v|_M^2, |F|_M^-1^2)`` of the bodies."""
    power = 0.0
    vnorm2 = 0.0
    fnorm2 = 0.0
    for c in range(fb.shape[0]):
        for a in range(3):
            power += fb[c, a] * vb[c, a]
            vnorm2 += vb[c, a] * vb[c, a] / inv_mass[c, a]
            fnorm2 += fb[c, a] * fb[c, a] * inv_mass[c, a]
    return power, vnorm2, fnorm2
