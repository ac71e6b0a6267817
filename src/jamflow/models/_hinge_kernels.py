"""Numba kernels of hinged 3D clusters: two rigid triangles sharing an edge, moved as a rigid body and a torsion.

A hinged cluster is four spheres ``(a, b, c, t)`` linked by every pair but ``(a, t)``
(a chain of four with frozen bond angles: bonds ``ab``, ``bc``, ``ct``, angle links
``ac``, ``bt``). Its 12 coordinates carry 5 independent links, leaving 7 degrees of
freedom: the rigid motions (6) and the torsion of the tip ``t`` about the axis ``b -> c``.
Its tangent space is spanned by those motions, so the Euclidean projection of the Gram
path (:func:`jamflow.models._link_kernels.gram_project`) has a closed form without a
factorisation: with the centroid ``c``, offsets ``r_s``, inertia ``I = sum |r_s|^2 1 - r_s r_s^T``
and the torsion mode ``T`` (``e x (y_t - y_b)`` on the tip, ``e`` the unit axis, zero
elsewhere) made orthogonal to the rigid motions, ``T~ = T - P_rigid T``,

    ``P g = F / 4 + (I^-1 tau) x r_s + (g . T~ / |T~|^2) T~_s``

(``F`` the total force and ``tau`` the torque of ``g`` about ``c``): the orthogonal
projection onto the same 7-dimensional space, equal to the Gram projection to round-off.

Positions are generalised coordinates: the body origin ``Y`` (the sphere ``b``), a unit
quaternion ``q`` of the body's rotation ``R`` and the torsion angle as ``(cos, sin)``
(``state`` rows of 9: ``Y``, ``q``, ``cos``, ``sin``), with the body frame taken from the
start (``body`` rows of 18: ``ref_a``, ``ref_c``, the unit axis ``e0 = ref_c / |ref_c|``,
and the tip's offset from ``b`` split as ``p_par`` along ``e0``, ``p_perp`` across and
``e0 x p``). A sphere sits at ``y_s = Y + R ref_s``, the tip at
``ref_t = p_par + cos p_perp + sin (e0 x p)``; ``x_s = y_s - shift_s`` (``shift`` the periodic
shifts of the unwrapped cluster). So the links hold at every step to the start's error
plus the round-off of one placement: no constraint solve and no re-affixing, and no
drift (the quaternion and ``(cos, sin)`` are renormalised at every move).

A move by ``h v`` decomposes ``P v`` into the rigid velocity ``(V, omega)`` about the
centroid and the torsion rate ``theta`` (``P v = V + omega x r_s + theta T_s``), turns the
tip by ``theta h``, the body by ``omega h`` about the centroid and moves it by ``V h``
(Cayley steps: rotations by ``2 atan(|omega h| / 2)`` and ``atan(theta h)``, rational and
exactly orthogonal). To first order in ``h`` this is ``x + h P v``, the step of the Gram
path before its re-affixing; the two retractions differ at second order (which nearby
point of the manifold a step reaches), as the chord sweeps of :func:`reaffix` do.

Geometry at the current point, ``geo`` rows of 34: centroid (3), offsets ``r_s`` (12), the
inverse inertia (6: xx, yy, zz, xy, xz, yz), the rigid part of ``T``: velocity ``V_T`` (3)
and angular velocity ``omega_T`` (3), the tip's ``T_t`` (3), ``1 / |T~|^2`` (1) and the unit axis ``e`` (3).
All kernels are single-threaded and cached.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit

#: Widths of the rows of ``state``, ``body`` and ``geo`` (module doc).
STATE_WIDTH, BODY_WIDTH, GEO_WIDTH = 9, 18, 34


@njit(cache=True, inline="always")
def _rotation(q0, q1, q2, q3, R):
    """Rotation matrix ``R`` (3, 3) of the unit quaternion ``(q0, q1, q2, q3)``."""
    R[0, 0] = 1.0 - 2.0 * (q2 * q2 + q3 * q3)
    R[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    R[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    R[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    R[1, 1] = 1.0 - 2.0 * (q1 * q1 + q3 * q3)
    R[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    R[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    R[2, 1] = 2.0 * (q2 * q3 + q0 * q1)
    R[2, 2] = 1.0 - 2.0 * (q1 * q1 + q2 * q2)


@njit(cache=True, inline="always")
def _inverse_apply(G, h, ax, ay, az):
    """``I^-1 a`` with the inverse inertia of ``geo`` row ``h`` (symmetric: xx, yy, zz, xy, xz, yz at 15:21)."""
    return (G[h, 15] * ax + G[h, 18] * ay + G[h, 19] * az,
            G[h, 18] * ax + G[h, 16] * ay + G[h, 20] * az,
            G[h, 19] * ax + G[h, 20] * ay + G[h, 17] * az)


@njit(cache=True)
def hinge_place(x, spheres, shift, body, state, geo):
    """Every hinged cluster's spheres placed from its ``state`` into ``x`` (N, 3), and its geometry into ``geo``.

    ``spheres`` (H, 4) are ``(a, b, c, t)``, ``shift`` (H, 4, 3) their periodic shifts.
    """
    R = np.empty((3, 3))
    y = np.empty((4, 3))
    for h in range(spheres.shape[0]):
        B = body[h]
        S = state[h]
        _rotation(S[3], S[4], S[5], S[6], R)
        cs, sn = S[7], S[8]
        for a in range(3):
            y[0, a] = S[a]
            y[1, a] = S[a]
            y[2, a] = S[a]
            y[3, a] = S[a]
        for a in range(3):
            for k in range(3):
                y[0, a] += R[a, k] * B[k]
                y[2, a] += R[a, k] * B[3 + k]
                y[3, a] += R[a, k] * (B[9 + k] + cs * B[12 + k] + sn * B[15 + k])
        cx = 0.25 * (y[0, 0] + y[1, 0] + y[2, 0] + y[3, 0])
        cy = 0.25 * (y[0, 1] + y[1, 1] + y[2, 1] + y[3, 1])
        cz = 0.25 * (y[0, 2] + y[1, 2] + y[2, 2] + y[3, 2])
        G = geo[h]
        G[0], G[1], G[2] = cx, cy, cz
        ixx = iyy = izz = ixy = ixz = iyz = 0.0
        for s in range(4):
            i = spheres[h, s]
            for a in range(3):
                x[i, a] = y[s, a] - shift[h, s, a]
            rx, ry, rz = y[s, 0] - cx, y[s, 1] - cy, y[s, 2] - cz
            G[3 + 3 * s], G[4 + 3 * s], G[5 + 3 * s] = rx, ry, rz
            ixx += ry * ry + rz * rz
            iyy += rx * rx + rz * rz
            izz += rx * rx + ry * ry
            ixy -= rx * ry
            ixz -= rx * rz
            iyz -= ry * rz
        # inverse inertia by cofactors (symmetric)
        c00 = iyy * izz - iyz * iyz
        c11 = ixx * izz - ixz * ixz
        c22 = ixx * iyy - ixy * ixy
        c01 = ixz * iyz - ixy * izz
        c02 = ixy * iyz - ixz * iyy
        c12 = ixy * ixz - ixx * iyz
        inv = 1.0 / (ixx * c00 + ixy * c01 + ixz * c02)
        G[15], G[16], G[17], G[18], G[19], G[20] = c00 * inv, c11 * inv, c22 * inv, c01 * inv, c02 * inv, c12 * inv
        # torsion mode on the tip: e x (y_t - y_b), e = R e0
        ex = R[0, 0] * B[6] + R[0, 1] * B[7] + R[0, 2] * B[8]
        ey = R[1, 0] * B[6] + R[1, 1] * B[7] + R[1, 2] * B[8]
        ez = R[2, 0] * B[6] + R[2, 1] * B[7] + R[2, 2] * B[8]
        px, py, pz = y[3, 0] - y[1, 0], y[3, 1] - y[1, 1], y[3, 2] - y[1, 2]
        tx, ty, tz = ey * pz - ez * py, ez * px - ex * pz, ex * py - ey * px
        G[27], G[28], G[29] = tx, ty, tz
        G[31], G[32], G[33] = ex, ey, ez
        vx, vy, vz = 0.25 * tx, 0.25 * ty, 0.25 * tz
        rx, ry, rz = G[12], G[13], G[14]
        wx, wy, wz = _inverse_apply(geo, h, ry * tz - rz * ty, rz * tx - rx * tz, rx * ty - ry * tx)
        G[21], G[22], G[23], G[24], G[25], G[26] = vx, vy, vz, wx, wy, wz
        norm = 0.0
        for s in range(4):
            rx, ry, rz = G[3 + 3 * s], G[4 + 3 * s], G[5 + 3 * s]
            ux = -vx - (wy * rz - wz * ry)
            uy = -vy - (wz * rx - wx * rz)
            uz = -vz - (wx * ry - wy * rx)
            if s == 3:
                ux += tx
                uy += ty
                uz += tz
            norm += ux * ux + uy * uy + uz * uz
        G[30] = 1.0 / norm


@njit(cache=True, inline="always")
def _decompose(geo, h, u):
    """``P u`` of hinged cluster ``h`` (``u`` (4, 3): its spheres' rows) as ``(V, omega, theta)``:
    ``P u = V + omega x r_s + theta T~_s``."""
    G = geo[h]
    fx = fy = fz = tx = ty = tz = dot = 0.0
    for s in range(4):
        gx, gy, gz = u[s, 0], u[s, 1], u[s, 2]
        rx, ry, rz = G[3 + 3 * s], G[4 + 3 * s], G[5 + 3 * s]
        fx += gx
        fy += gy
        fz += gz
        tx += ry * gz - rz * gy
        ty += rz * gx - rx * gz
        tz += rx * gy - ry * gx
        ux = -G[21] - (G[25] * rz - G[26] * ry)
        uy = -G[22] - (G[26] * rx - G[24] * rz)
        uz = -G[23] - (G[24] * ry - G[25] * rx)
        if s == 3:
            ux += G[27]
            uy += G[28]
            uz += G[29]
        dot += gx * ux + gy * uy + gz * uz
    wx, wy, wz = _inverse_apply(geo, h, tx, ty, tz)
    return 0.25 * fx, 0.25 * fy, 0.25 * fz, wx, wy, wz, dot * G[30]


@njit(cache=True, inline="always")
def _gather(spheres, h, g, u):
    """Rows of hinged cluster ``h``'s spheres of ``g`` (N, 3) into ``u`` (4, 3)."""
    for s in range(4):
        i = spheres[h, s]
        u[s, 0], u[s, 1], u[s, 2] = g[i, 0], g[i, 1], g[i, 2]


@njit(cache=True, inline="always")
def _rates(geo, h, u):
    """``(V, omega, theta)`` of the move ``V + omega x r_s + theta T_s`` (``T`` on the tip alone) that is ``P u``."""
    vx, vy, vz, wx, wy, wz, theta = _decompose(geo, h, u)
    G = geo[h]
    return (vx - theta * G[21], vy - theta * G[22], vz - theta * G[23],
            wx - theta * G[24], wy - theta * G[25], wz - theta * G[26], theta)


@njit(cache=True)
def hinge_project(spheres, geo, g):
    """``g`` (N, 3) projected in place onto the tangent space of every hinged cluster (module doc)."""
    u = np.empty((4, 3))
    for h in range(spheres.shape[0]):
        _gather(spheres, h, g, u)
        vx, vy, vz, wx, wy, wz, theta = _rates(geo, h, u)
        G = geo[h]
        for s in range(4):
            i = spheres[h, s]
            rx, ry, rz = G[3 + 3 * s], G[4 + 3 * s], G[5 + 3 * s]
            g[i, 0] = vx + wy * rz - wz * ry
            g[i, 1] = vy + wz * rx - wx * rz
            g[i, 2] = vz + wx * ry - wy * rx
        i = spheres[h, 3]
        g[i, 0] += theta * G[27]
        g[i, 1] += theta * G[28]
        g[i, 2] += theta * G[29]


@njit(cache=True)
def hinge_advance(spheres, geo, state, v, step):
    """Every hinged cluster's ``state`` moved by ``step * P v`` (``v`` (N, 3) at the point of ``geo``; module doc).

    The rates are corrected at second order, ``P v - (step / 2) P a`` with ``a`` the
    acceleration of the move along its rotations (``omega x (omega x r_s)``, and on the
    tip ``theta^2 e x T + 2 theta omega x T``): the move is then ``x + step P v`` plus a
    normal term at second order, as the closest-point re-affixing of the Gram path
    (which has no tangential term at that order). The spheres are not placed:
    :func:`hinge_place` does that (after the caller's move of the other spheres).
    """
    u = np.empty((4, 3))
    for h in range(spheres.shape[0]):
        _gather(spheres, h, v, u)
        vx, vy, vz, wx, wy, wz, theta = _rates(geo, h, u)
        G = geo[h]
        S = state[h]
        for s in range(4):
            rx, ry, rz = G[3 + 3 * s], G[4 + 3 * s], G[5 + 3 * s]
            cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx
            u[s, 0], u[s, 1], u[s, 2] = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
        tx, ty, tz, ex, ey, ez = G[27], G[28], G[29], G[31], G[32], G[33]
        u[3, 0] += theta * (theta * (ey * tz - ez * ty) + 2.0 * (wy * tz - wz * ty))
        u[3, 1] += theta * (theta * (ez * tx - ex * tz) + 2.0 * (wz * tx - wx * tz))
        u[3, 2] += theta * (theta * (ex * ty - ey * tx) + 2.0 * (wx * ty - wy * tx))
        ax, ay, az, bx, by, bz, phi = _rates(geo, h, u)
        half = 0.5 * step
        vx, vy, vz = vx - half * ax, vy - half * ay, vz - half * az
        wx, wy, wz = wx - half * bx, wy - half * by, wz - half * bz
        theta -= half * phi
        # torsion: (cos + i sin) (1 + i theta step) / |.|
        a = theta * step
        cs = S[7] - a * S[8]
        sn = S[8] + a * S[7]
        norm = 1.0 / np.sqrt(cs * cs + sn * sn)
        S[7], S[8] = cs * norm, sn * norm
        # rotation about the centroid: the unit quaternion of (1, omega step / 2), applied after q
        b0 = 1.0
        b1, b2, b3 = 0.5 * step * wx, 0.5 * step * wy, 0.5 * step * wz
        norm = 1.0 / np.sqrt(1.0 + b1 * b1 + b2 * b2 + b3 * b3)
        b0, b1, b2, b3 = b0 * norm, b1 * norm, b2 * norm, b3 * norm
        q0, q1, q2, q3 = S[3], S[4], S[5], S[6]
        n0 = b0 * q0 - b1 * q1 - b2 * q2 - b3 * q3
        n1 = b0 * q1 + b1 * q0 + b2 * q3 - b3 * q2
        n2 = b0 * q2 - b1 * q3 + b2 * q0 + b3 * q1
        n3 = b0 * q3 + b1 * q2 - b2 * q1 + b3 * q0
        norm = 1.0 / np.sqrt(n0 * n0 + n1 * n1 + n2 * n2 + n3 * n3)
        S[3], S[4], S[5], S[6] = n0 * norm, n1 * norm, n2 * norm, n3 * norm
        # origin: Y <- c + V step + R_inc (Y - c)
        dx, dy, dz = S[0] - G[0], S[1] - G[1], S[2] - G[2]
        s00 = 1.0 - 2.0 * (b2 * b2 + b3 * b3)
        s01 = 2.0 * (b1 * b2 - b0 * b3)
        s02 = 2.0 * (b1 * b3 + b0 * b2)
        s10 = 2.0 * (b1 * b2 + b0 * b3)
        s11 = 1.0 - 2.0 * (b1 * b1 + b3 * b3)
        s12 = 2.0 * (b2 * b3 - b0 * b1)
        s20 = 2.0 * (b1 * b3 - b0 * b2)
        s21 = 2.0 * (b2 * b3 + b0 * b1)
        s22 = 1.0 - 2.0 * (b1 * b1 + b2 * b2)
        S[0] = G[0] + step * vx + s00 * dx + s01 * dy + s02 * dz
        S[1] = G[1] + step * vy + s10 * dx + s11 * dy + s12 * dz
        S[2] = G[2] + step * vz + s20 * dx + s21 * dy + s22 * dz
