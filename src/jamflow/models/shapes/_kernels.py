"""Compiled pair kernels of the shape models (2D bodies with an orientation).

Every pair function has one signature,
``pair(dx0, dx1, ti, tj, pi, pj, k, g) -> energy``: the minimum-image centre
separation ``x_j - x_i = (dx0, dx1)`` [length], the orientations ``ti, tj`` [rad],
the per-body shape parameters ``pi, pj`` (flat float arrays, layout per family), the
spring constant ``k`` [energy / length^2]; it returns the pair energy and *adds* the
gradient ``dU / d(x_i, y_i, theta_i, x_j, y_j, theta_j)`` to ``g`` (shape (6,)).

The functions are written for float64 *and* complex128 arguments (branches and
clamps test real parts only), so that a complex-step derivative of the analytic
gradient, ``Im g(q + i h e_m) / h`` with ``h = 1e-30``, gives the Hessian to
round-off (Squire & Trapp, SIAM Rev. 40, 110 (1998)): automatic-derivative grade,
with no subtraction error, which the eigenvalues of hypostatic packings
(1e-14 ... 1e-8, VanderWerf et al. Sec. III B) need.
"""

from __future__ import annotations

import numpy as np

from ..._numba import njit

#: Family codes of the compiled kernels (the order of :data:`jamflow.models.shapes.model.SHAPE_FAMILIES`).
CIRCULO, ELLIPSE, REULEAUX, DUMBBELL = 0, 1, 2, 3

#: Family code of each model family.
FAMILY_CODES: dict[str, int] = {"circulo": CIRCULO, "ellipse": ELLIPSE, "reuleaux": REULEAUX, "dumbbell": DUMBBELL}

#: Complex step [length or rad]: far below round-off of any coordinate, so the
#: derivative carries no truncation error (the real part is untouched).
COMPLEX_STEP: float = 1e-30


@njit(cache=True, inline="always")
def core_radius(p):
    """Distance from a circulo body's centre to its farthest vertex (real), bounding its core."""
    rho2 = 0.0
    for e in range(int(p[1].real)):
        rho2 = max(rho2, p[2 + 2 * e].real * p[2 + 2 * e].real + p[3 + 2 * e].real * p[3 + 2 * e].real)
    return np.sqrt(rho2)


@njit(cache=True, inline="always")
def rotate_vertices(p, c, s, out, row):
    """A circulo body's vertices rotated by cosine ``c``, sine ``s``, to ``out[row] = (x0, y0, x1, ...)``."""
    for m in range(int(p[1].real)):
        out[row, 2 * m] = c * p[2 + 2 * m] - s * p[3 + 2 * m]
        out[row, 2 * m + 1] = s * p[2 + 2 * m] + c * p[3 + 2 * m]


@njit(cache=True, inline="always")
def circulo_vertex_edge(dx0, dx1, world, a, b, ra, rb, na, nb, rho_b, k, g, oa, ob, out):
    """Vertices of body ``a`` (centre at 0) against the edges of body ``b`` (centre ``dx``).

    ``world[a]``, ``world[b]``: the bodies' vertices rotated to their orientations, relative to their
    centres (:func:`rotate_vertices`; callers rotate each body once, not once per pair); ``ra, rb``
    their rounding radii, ``na, nb`` their vertex counts (parameters ``p = [R, n, v0x, v0y, ...]``:
    rounding radius, vertex count, body-frame vertices); ``rho_b`` is :func:`core_radius` of ``b``.
    Body ``a``'s vertex ``P`` meets edge ``[S0, S1]`` of ``b`` at distance ``r = min_t |P - S0 - t (S1 -
    S0)|``, ``t`` in [0, 1]: the perpendicular distance for an end-middle contact (foot inside the
    edge), the distance to an end of the edge for an end-end contact (VanderWerf et al. App. A).
    Each overlapping term has energy ``(k/2) w (R_a + R_b - r)^2`` with ``w`` the number of edges of
    ``a`` that share the vertex (1 on a circulo-line, 2 on a polygon, App. A 2). Gradient slots:
    ``oa`` for ``a`` and ``ob`` for ``b`` in ``g``. When ``out`` is an array (not None), one row per
    overlapping term is written to it (rows: vertex, edge, r, delta, w, contact point x, y relative
    to ``a``'s centre, unit normal x, y from ``b`` to ``a``, foot parameter t) and the row count
    returned second.
    """
    sigma = ra + rb
    w = 1.0 if na == 2 else 2.0
    n_edges = 1 if nb == 2 else nb
    # every edge point of b lies within rho_b of b's centre, so a vertex of a at least
    # rho_b + sigma from that centre is at least sigma from every edge: its terms are all
    # zero and it is skipped before the edge loop
    reach = rho_b + sigma.real
    energy = 0.0 * dx0
    rows = 0
    for m in range(na):
        px = world[a, 2 * m]
        py = world[a, 2 * m + 1]
        wx = (px - dx0).real
        wy = (py - dx1).real
        if wx * wx + wy * wy >= reach * reach:
            continue
        # the end of edge e is the start of edge e + 1
        s1x = dx0 + world[b, 0]
        s1y = dx1 + world[b, 1]
        for e in range(n_edges):
            f = e + 1 if e + 1 < nb else 0
            s0x = s1x
            s0y = s1y
            s1x = dx0 + world[b, 2 * f]
            s1y = dx1 + world[b, 2 * f + 1]
            ex = s1x - s0x
            ey = s1y - s0y
            t = ((px - s0x) * ex + (py - s0y) * ey) / (ex * ex + ey * ey)
            if t.real < 0.0:
                t = 0.0 * t
            elif t.real > 1.0:
                t = 0.0 * t + 1.0
            cx = s0x + t * ex
            cy = s0y + t * ey
            qx = px - cx
            qy = py - cy
            if (qx * qx + qy * qy).real >= (sigma * sigma).real:
                continue
            # envelope theorem: r is a minimum over t (or t is clamped), so dr/dq is
            # the derivative at fixed t: that of two body-fixed points P and C
            u, r, delta, nx, ny = _point_term(px, py, cx, cy, dx0, dx1, sigma, k * w, g, oa, ob)
            energy += u
            if out is not None:
                out[rows, 0] = m
                out[rows, 1] = e
                out[rows, 2] = r.real
                out[rows, 3] = delta.real
                out[rows, 4] = w
                out[rows, 5] = (px - ra * nx).real
                out[rows, 6] = (py - ra * ny).real
                out[rows, 7] = nx.real
                out[rows, 8] = ny.real
                out[rows, 9] = t.real
                rows += 1
    return energy, rows


@njit(cache=True)
def circulo_pair(dx0, dx1, ti, tj, pi, pj, k, g):
    """Circulo-line / circulo-polygon pair (App. A): vertices of each against edges of the other."""
    # rows 0 and 1: the two bodies' rotated vertices, complex when the angles carry a complex step
    world = np.zeros((2, max(pi.shape[0], pj.shape[0]) - 2)) + 0.0 * (ti + tj)
    rotate_vertices(pi, np.cos(ti), np.sin(ti), world, 0)
    rotate_vertices(pj, np.cos(tj), np.sin(tj), world, 1)
    ni = int(pi[1].real)
    nj = int(pj[1].real)
    e1, _ = circulo_vertex_edge(dx0, dx1, world, 0, 1, pi[0], pj[0], ni, nj, core_radius(pj), k, g, 0, 3, None)
    e2, _ = circulo_vertex_edge(-dx0, -dx1, world, 1, 0, pj[0], pi[0], nj, ni, core_radius(pi), k, g, 3, 0, None)
    return e1 + e2


@njit(cache=True)
def _ellipse_matrix(a, b, t):
    """Shape matrix ``R diag(a^2, b^2) R^T`` of an ellipse (entries xx, xy, yy)."""
    c = np.cos(t)
    s = np.sin(t)
    a2 = a * a
    b2 = b * b
    return a2 * c * c + b2 * s * s, (a2 - b2) * c * s, a2 * s * s + b2 * c * c


#: Newton iterations on the Perram–Wertheim multiplier after bisection to a bracket of width 1e-3:
#: quadratic convergence from a bracket of width < 1e-3 reaches round-off in ~4, and
#: the complex-step (derivative) part converges with the real part.
_PW_NEWTON = 8


@njit(cache=True)
def _pw_terms(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy):
    """``s = C(l)^-1 r``, ``C`` (xx, xy, yy, det), and ``dF/dl`` of the Perram–Wertheim function at ``l``.

    ``dF/dl = (1 - 2 l) r.s - l (1 - l) s.D.s`` with ``D = B - A``.
    """
    cxx = axx + lam * dxx
    cxy = axy + lam * dxy
    cyy = ayy + lam * dyy
    det = cxx * cyy - cxy * cxy
    s0 = (cyy * dx0 - cxy * dx1) / det
    s1 = (cxx * dx1 - cxy * dx0) / det
    rs = dx0 * s0 + dx1 * s1
    sds = s0 * (dxx * s0 + dxy * s1) + s1 * (dxy * s0 + dyy * s1)
    return s0, s1, cxx, cxy, cyy, det, rs, sds, (1.0 - 2.0 * lam) * rs - lam * (1.0 - lam) * sds


#: Newton steps below this size [1] end a warm-started Perram–Wertheim solve: the
#: iteration converges quadratically, so the multiplier after such a step is exact to
#: round-off.
_PW_WARM_STEP = 1e-10


@njit(cache=True)
def _pw_newton(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy):
    """One Newton step on ``dF/dl = 0`` at ``l``: returns ``-F'(l) / F''(l)``."""
    s0, s1, cxx, cxy, cyy, det, rs, sds, d1 = _pw_terms(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy)
    # u = D s; F'' = -2 r.s - 2 (1 - 2 l) s.D.s + 2 l (1 - l) u.C^-1.u
    ux = dxx * s0 + dxy * s1
    uy = dxy * s0 + dyy * s1
    ucu = (cyy * ux * ux - 2.0 * cxy * ux * uy + cxx * uy * uy) / det
    d2 = -2.0 * rs - 2.0 * (1.0 - 2.0 * lam) * sds + 2.0 * lam * (1.0 - lam) * ucu
    return -d1 / d2


@njit(cache=True)
def perram_wertheim(dx0, dx1, ti, tj, pi, pj, lam0=-1.0):
    """Perram–Wertheim contact function of two ellipses and its multiplier.

    ``F(A, B) = max_{0<=l<=1} l (1 - l) r^T C(l)^-1 r``, ``C = (1 - l) A + l B``
    (Perram & Wertheim, J. Comput. Phys. 58, 409 (1985)); in 2D ``C`` is 2 x 2 and
    inverted in closed form. ``F < 1`` iff the ellipses overlap, and ``F`` is
    homogeneous of degree 2 in ``r``, so the contact distance along ``r`` at fixed
    orientations is ``sigma = |r| / sqrt(F)``. ``F(l)`` is strictly concave: the
    maximum is bracketed by bisection on ``dF/dl`` and polished by Newton. With a
    previous multiplier ``0 < lam0 < 1`` (a minimiser's last step, real arguments)
    Newton starts from it and stops after a step below :data:`_PW_WARM_STEP`; a
    start that leaves ``(0, 1)`` or does not converge in :data:`_PW_NEWTON` steps
    falls back to the bracket.

    Returns
    -------
    F, l, s0, s1 : scalars
        The contact function, the maximising ``l`` and ``s = C(l)^-1 r``.
    """
    axx, axy, ayy = _ellipse_matrix(pi[0], pi[1], ti)
    bxx, bxy, byy = _ellipse_matrix(pj[0], pj[1], tj)
    return perram_wertheim_matrices(dx0, dx1, axx, axy, ayy, bxx, bxy, byy, lam0)


@njit(cache=True, inline="always")
def perram_wertheim_matrices(dx0, dx1, axx, axy, ayy, bxx, bxy, byy, lam0):
    """:func:`perram_wertheim` from the two shape matrices ``A``, ``B`` (entries xx, xy, yy; :func:`_ellipse_matrix`)."""
    dxx = bxx - axx
    dxy = bxy - axy
    dyy = byy - ayy
    warm = False
    lam = lam0 + 0.0 * dx0
    if 0.0 < lam0 < 1.0:
        for _ in range(_PW_NEWTON):
            step = _pw_newton(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy)
            lam = lam + step
            if not 0.0 < lam.real < 1.0:
                break
            if abs(step) < _PW_WARM_STEP:
                warm = True
                break
    if not warm:
        lo = 0.0
        hi = 1.0
        while hi - lo > 1e-3:
            mid = 0.5 * (lo + hi)
            slope = _pw_terms(mid, dx0.real, dx1.real, axx.real, axy.real, ayy.real, dxx.real, dxy.real, dyy.real)[8]
            if slope > 0.0:
                lo = mid
            else:
                hi = mid
        lam = 0.5 * (lo + hi) + 0.0 * dx0
        for _ in range(_PW_NEWTON):
            lam = lam + _pw_newton(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy)
    s0, s1 = _pw_terms(lam, dx0, dx1, axx, axy, ayy, dxx, dxy, dyy)[:2]
    f = lam * (1.0 - lam) * (dx0 * s0 + dx1 * s1)
    return f, lam, s0, s1


@njit(cache=True)
def _commutator_form(mxx, mxy, myy, s0, s1):
    """``s^T (Omega M - M Omega) s`` for symmetric ``M``, ``Omega`` the rotation generator."""
    # Omega M - M Omega = [[-2 mxy, mxx - myy], [mxx - myy, 2 mxy]]
    return -2.0 * mxy * s0 * s0 + 2.0 * (mxx - myy) * s0 * s1 + 2.0 * mxy * s1 * s1


@njit(cache=True)
def ellipse_terms(dx0, dx1, ti, tj, pi, pj, k, g, lam0):
    """Ellipse pair, ``U = (k/2) (sigma - r)^2`` for ``sigma > r`` (Eq. 1), and its Perram–Wertheim multiplier.

    ``r = |x_j - x_i|``, ``sigma = r / sqrt(F)`` (Perram–Wertheim, see
    :func:`perram_wertheim`, warm-started from ``lam0``); parameters ``p = [a, b]``
    (semi-axes). The gradient of ``F`` follows from the envelope theorem at the
    maximising ``l``: ``dF/dr = 2 l (1 - l) s`` and
    ``dF/dtheta_i = -l (1 - l)^2 s^T [Omega, A] s``, ``dF/dtheta_j = -l^2 (1 - l) s^T [Omega, B] s``.
    Returns the energy and ``l`` (-1 when the bounding circles do not overlap).
    """
    r = np.sqrt(dx0 * dx0 + dx1 * dx1)
    if r.real >= (pi[0] + pj[0]).real:
        return 0.0 * dx0, -1.0 + 0.0 * dx0
    axx, axy, ayy = _ellipse_matrix(pi[0], pi[1], ti)
    bxx, bxy, byy = _ellipse_matrix(pj[0], pj[1], tj)
    return ellipse_terms_matrices(dx0, dx1, r, axx, axy, ayy, bxx, bxy, byy, k, g, lam0)


@njit(cache=True, inline="always")
def ellipse_terms_matrices(dx0, dx1, r, axx, axy, ayy, bxx, bxy, byy, k, g, lam0):
    """:func:`ellipse_terms` of a pair whose bounding circles overlap, from ``r = |dx|`` and the shape matrices
    ``A``, ``B`` (:func:`_ellipse_matrix`; a loop computes them once per body)."""
    f, lam, s0, s1 = perram_wertheim_matrices(dx0, dx1, axx, axy, ayy, bxx, bxy, byy, lam0)
    if f.real >= 1.0:
        return 0.0 * dx0, lam
    root = np.sqrt(f)
    delta = r / root - r
    w = lam * (1.0 - lam)
    df0 = 2.0 * w * s0
    df1 = 2.0 * w * s1
    dfi = -w * (1.0 - lam) * _commutator_form(axx, axy, ayy, s0, s1)
    dfj = -w * lam * _commutator_form(bxx, bxy, byy, s0, s1)
    # d delta = (1/sqrt F - 1) dr - r / (2 F^(3/2)) dF
    a = 1.0 / root - 1.0
    b = -0.5 * r / (f * root)
    kd = k * delta
    gx = kd * (a * dx0 / r + b * df0)
    gy = kd * (a * dx1 / r + b * df1)
    g[0] -= gx
    g[1] -= gy
    g[2] += kd * b * dfi
    g[3] += gx
    g[4] += gy
    g[5] += kd * b * dfj
    return 0.5 * k * delta * delta, lam


@njit(cache=True)
def ellipse_pair(dx0, dx1, ti, tj, pi, pj, k, g):
    """Ellipse pair energy and gradient (:func:`ellipse_terms` from a cold Perram–Wertheim solve)."""
    return ellipse_terms(dx0, dx1, ti, tj, pi, pj, k, g, -1.0)[0]


@njit(cache=True, inline="always")
def _family_pair(family, dx0, dx1, ti, tj, pi, pj, k, g):
    """The pair kernel of a family code (:data:`FAMILY_CODES`)."""
    if family == CIRCULO:
        return circulo_pair(dx0, dx1, ti, tj, pi, pj, k, g)
    if family == ELLIPSE:
        return ellipse_pair(dx0, dx1, ti, tj, pi, pj, k, g)
    if family == REULEAUX:
        return reuleaux_pair(dx0, dx1, ti, tj, pi, pj, k, g)
    return dumbbell_pair(dx0, dx1, ti, tj, pi, pj, k, g)


# the pair kernel is chosen by a family code (_family_pair), not passed: a cached kernel that
# takes a jitted function as an argument corrupts numba's cache index across processes
# (numba issue #2956), and an uncached one compiles for seconds in every process
@njit(cache=True)
def pair_sum(family, i, j, dx, theta, params, k, grad, virial):
    """Energy, gradient ``(N, 3)`` (x, y, theta) and virial of all listed pairs of a family (code of
    :data:`FAMILY_CODES`).

    ``virial[a, b] = -sum dU/dx_j[a] dx[b]`` [energy]: ``sum f r_a r_b / r`` for
    central forces, so that the pressure is ``tr W / (2 V)``. Returns the energy and
    the number of interacting pairs.
    """
    energy = 0.0
    n = 0
    g = np.zeros(6)
    for p in range(i.size):
        a = i[p]
        b = j[p]
        g[:] = 0.0
        e = _family_pair(family, dx[p, 0], dx[p, 1], theta[a], theta[b], params[a], params[b], k, g)
        if e > 0.0:
            n += 1
            energy += e
            for c in range(3):
                grad[a, c] += g[c]
                grad[b, c] += g[3 + c]
            for u in range(2):
                for v in range(2):
                    virial[u, v] -= g[3 + u] * dx[p, v]
    return energy, n


# chosen by a family code, not by passing the pair kernel: a cached kernel that takes a
# jitted function as an argument corrupts numba's cache index across processes (numba
# issue #2956), and an uncached one compiles for seconds in every process
@njit(cache=True)
def pair_hessian_blocks(family, i, j, dx, theta, params, k, h):
    """Complex-step Hessian blocks ``d^2 U / dq dq`` of every listed pair of a family, shape (P, 6, 6).

    ``family`` is a code of :data:`FAMILY_CODES`. Local order ``(x_i, y_i, theta_i,
    x_j, y_j, theta_j)``; each column is ``Im g(q + i h e_m) / h`` of the analytic pair
    gradient ``g``.
    """
    out = np.zeros((i.size, 6, 6))
    g = np.zeros(6, dtype=np.complex128)
    pa = np.zeros(params.shape[1], dtype=np.complex128)
    pb = np.zeros(params.shape[1], dtype=np.complex128)
    for p in range(i.size):
        a = i[p]
        b = j[p]
        pa[:] = params[a]
        pb[:] = params[b]
        for m in range(6):
            d0 = dx[p, 0] + 0j
            d1 = dx[p, 1] + 0j
            ta = theta[a] + 0j
            tb = theta[b] + 0j
            if m == 0:
                d0 -= 1j * h
            elif m == 1:
                d1 -= 1j * h
            elif m == 2:
                ta += 1j * h
            elif m == 3:
                d0 += 1j * h
            elif m == 4:
                d1 += 1j * h
            else:
                tb += 1j * h
            g[:] = 0.0
            _family_pair(family, d0, d1, ta, tb, pa, pb, k, g)
            for c in range(6):
                out[p, c, m] = g[c].imag / h
    return out


#: Columns of a circulo contact-term table (see :func:`circulo_terms`).
CIRCULO_TERM_COLUMNS = ("pair", "vertex_body", "vertex", "edge", "r", "delta", "weight",
                        "point_x", "point_y", "normal_x", "normal_y", "t")


@njit(cache=True)
def circulo_terms(i, j, dx, theta, params, k):
    """Every overlapping vertex–edge term of the listed circulo pairs, one row each.

    Columns :data:`CIRCULO_TERM_COLUMNS`: pair row, the body whose vertex overlaps
    (0: ``i``, 1: ``j``), vertex and edge indices, ``r`` and ``delta = sigma - r``
    [length], the energy weight ``w``, the contact point on the vertex body's surface
    relative to *that body's* centre [length], the unit normal pointing from the edge
    body to the vertex body, and the foot parameter ``t`` on the edge (0 or 1 for an
    end-end term, inside for end-middle).
    """
    nv = params.shape[1] // 2
    buf = np.zeros((2 * nv * nv, 10))
    rows = []
    g = np.zeros(6)
    world = np.zeros((2, params.shape[1] - 2))
    for p in range(i.size):
        a = i[p]
        b = j[p]
        rotate_vertices(params[a], np.cos(theta[a]), np.sin(theta[a]), world, 0)
        rotate_vertices(params[b], np.cos(theta[b]), np.sin(theta[b]), world, 1)
        na = int(params[a, 1])
        nb = int(params[b, 1])
        for side in range(2):
            if side == 0:
                _, n = circulo_vertex_edge(dx[p, 0], dx[p, 1], world, 0, 1, params[a, 0], params[b, 0], na, nb,
                                           core_radius(params[b]), k, g, 0, 3, buf)
            else:
                _, n = circulo_vertex_edge(-dx[p, 0], -dx[p, 1], world, 1, 0, params[b, 0], params[a, 0], nb, na,
                                           core_radius(params[a]), k, g, 3, 0, buf)
            for r in range(n):
                row = np.empty(12)
                row[0] = p
                row[1] = side
                row[2:] = buf[r]
                rows.append(row)
    out = np.empty((len(rows), 12))
    for r in range(len(rows)):
        out[r] = rows[r]
    return out


@njit(cache=True)
def _segments_cross(ax, ay, bx, by, cx, cy, dx, dy):
    """Whether the closed segments ``ab`` and ``cd`` intersect (orientation tests)."""
    d1 = (dx - cx) * (ay - cy) - (dy - cy) * (ax - cx)
    d2 = (dx - cx) * (by - cy) - (dy - cy) * (bx - cx)
    d3 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    d4 = (bx - ax) * (dy - ay) - (by - ay) * (dx - ax)
    return d1 * d2 <= 0.0 and d3 * d4 <= 0.0


@njit(cache=True)
def _world_vertices(p, t, ox, oy):
    """Vertices ``(n, 2)`` of a body at angle ``t`` and centre ``(ox, oy)``, real or complex."""
    n = int(p[1].real)
    c = np.cos(t)
    s = np.sin(t)
    out = np.zeros((n, 2)) + 0.0 * (c + ox)
    for m in range(n):
        out[m, 0] = ox + c * p[2 + 2 * m] - s * p[3 + 2 * m]
        out[m, 1] = oy + s * p[2 + 2 * m] + c * p[3 + 2 * m]
    return out


@njit(cache=True)
def _inside_convex(x, y, v):
    """Whether ``(x, y)`` lies inside the counter-clockwise convex polygon ``v`` (n >= 3)."""
    n = v.shape[0]
    for m in range(n):
        f = (m + 1) % n
        if (v[f, 0] - v[m, 0]) * (y - v[m, 1]) - (v[f, 1] - v[m, 1]) * (x - v[m, 0]) < 0.0:
            return False
    return True


@njit(cache=True)
def circulo_cores_intersect(dx0, dx1, ti, tj, pi, pj):
    """Whether the cores (segment or polygon) of two circulo bodies intersect.

    The vertex–edge potential of App. A sees only vertices near edges, so crossed
    shafts (an overlap deeper than the rounding radius) would cost no energy: such
    configurations are outside the model and are refused by the callers.
    """
    vi = _world_vertices(pi, ti, 0.0, 0.0)
    vj = _world_vertices(pj, tj, dx0, dx1)
    ni = vi.shape[0]
    nj = vj.shape[0]
    ei = 1 if ni == 2 else ni
    ej = 1 if nj == 2 else nj
    for a in range(ei):
        b = (a + 1) % ni
        for c in range(ej):
            d = (c + 1) % nj
            if _segments_cross(vi[a, 0], vi[a, 1], vi[b, 0], vi[b, 1], vj[c, 0], vj[c, 1], vj[d, 0], vj[d, 1]):
                return True
    if nj >= 3 and _inside_convex(vi[0, 0], vi[0, 1], vj):
        return True
    if ni >= 3 and _inside_convex(vj[0, 0], vj[0, 1], vi):
        return True
    return False


@njit(cache=True)
def circulo_crossed_pairs(i, j, dx, theta, params):
    """Mask of listed pairs whose cores intersect (see :func:`circulo_cores_intersect`)."""
    out = np.zeros(i.size, dtype=np.bool_)
    for p in range(i.size):
        out[p] = circulo_cores_intersect(dx[p, 0], dx[p, 1], theta[i[p]], theta[j[p]], params[i[p]], params[j[p]])
    return out


@njit(cache=True)
def pair_table(family, i, j, dx, theta, params, k):
    """Energy and gradient ``(x_i, y_i, theta_i, x_j, y_j, theta_j)`` of every listed pair of a family
    (code of :data:`FAMILY_CODES`), shape (P, 7)."""
    out = np.zeros((i.size, 7))
    g = np.zeros(6)
    for p in range(i.size):
        g[:] = 0.0
        out[p, 0] = _family_pair(family, dx[p, 0], dx[p, 1], theta[i[p]], theta[j[p]], params[i[p]], params[j[p]],
                                 k, g)
        out[p, 1:] = g
    return out


@njit(cache=True)
def ellipse_contact_geometry(i, j, dx, theta, params):
    """Contact point and normal of ellipse pairs (Perram–Wertheim), shape (P, 4).

    Columns: arm of ``i`` (contact point minus centre of ``i``) ``(1 - l) A s`` and
    the unit normal from ``i`` to ``j`` along ``s = C(l)^-1 r``, the gradient of
    ``i``'s shape function at the contact point of the two ellipses scaled to touch.
    """
    out = np.zeros((i.size, 4))
    for p in range(i.size):
        a = i[p]
        b = j[p]
        _, lam, s0, s1 = perram_wertheim(dx[p, 0], dx[p, 1], theta[a], theta[b], params[a], params[b])
        axx, axy, ayy = _ellipse_matrix(params[a, 0], params[a, 1], theta[a])
        out[p, 0] = (1.0 - lam) * (axx * s0 + axy * s1)
        out[p, 1] = (1.0 - lam) * (axy * s0 + ayy * s1)
        norm = np.sqrt(s0 * s0 + s1 * s1)
        out[p, 2] = s0 / norm
        out[p, 3] = s1 / norm
    return out


@njit(cache=True)
def _in_arc(ux, uy, ax, ay, bx, by):
    """Whether direction ``u`` lies in the (< pi) angle spanned from ``a`` to ``b`` (either sense)."""
    cab = ax * by - ay * bx
    return (ax * uy - ay * ux) * cab >= 0.0 and (ux * by - uy * bx) * cab >= 0.0


@njit(cache=True)
def _point_term(pax, pay, pbx, pby, dx0, dx1, sigma, k, g, oa, ob):
    """``(k/2)(sigma - r)^2`` of two body-fixed points, and its gradient added to ``g``.

    ``P_a`` on body ``a`` and ``P_b`` on body ``b`` are given relative to ``a``'s
    centre (``b``'s centre at ``dx``); ``r = |P_a - P_b|``. Returns the energy, ``r``,
    ``delta = sigma - r`` and the unit normal from ``P_b`` to ``P_a``.
    """
    qx = pax - pbx
    qy = pay - pby
    r = np.sqrt(qx * qx + qy * qy)
    delta = sigma - r
    nx = qx / r
    ny = qy / r
    fr = -k * delta
    g[oa] += fr * nx
    g[oa + 1] += fr * ny
    g[oa + 2] += fr * (pax * ny - pay * nx)
    g[ob] -= fr * nx
    g[ob + 1] -= fr * ny
    g[ob + 2] -= fr * ((pbx - dx0) * ny - (pby - dx1) * nx)
    return 0.5 * k * delta * delta, r, delta, nx, ny


@njit(cache=True)
def reuleaux_pair(dx0, dx1, ti, tj, pi, pj, k, g):
    """Reuleaux pair energy and gradient (see :func:`reuleaux_terms`)."""
    return reuleaux_terms(dx0, dx1, ti, tj, pi, pj, k, g, False, np.empty((0, 9)))[0]


@njit(cache=True)
def reuleaux_terms(dx0, dx1, ti, tj, pi, pj, k, g, record, out):
    """Reuleaux-triangle pair (VanderWerf et al. Fig. 2); parameters ``[s, 3, vertices]`` (``s`` the side).

    Arc ``m`` of a body is centred on its vertex ``m`` with radius ``s`` and joins the
    other two vertices. Terms, each ``(k/2)(sigma - r)^2`` when positive and valid:

    - arc-arc: ``r`` = distance of the two arc centres, ``sigma = s_i + s_j``, valid
      when the contact point (on the line of centres, ``s`` from each centre) lies on
      both arcs and ``r > max(s_i, s_j)`` (an overlap shallower than the larger side;
      deeper, an arc centre lies in the other body's sector: crossed corners, whose
      overlap the vertex-arc terms carry);
    - vertex-arc: ``r`` = distance from the arc's centre to the other body's vertex,
      ``sigma`` = the arc's radius, valid when the vertex lies in the arc's angle and
      the contact normal lies in the vertex's normal cone (between the normals of the
      two arcs meeting there), where no arc-arc term of those arcs is valid.

    At a validity boundary the arc-arc contact point is the vertex of the vertex-arc
    term, so the two ``delta`` agree and share a normal: ``U`` and its gradient are
    continuous. All terms are distances between body-fixed points. Returns the energy
    and the number of terms; when ``record`` is true one row per term goes to ``out``
    (:data:`POINT_TERM_COLUMNS` without ``pair``: type 0 arc-arc, 1 a vertex of ``i``
    on an arc of ``j``, 2 a vertex of ``j`` on an arc of ``i``; the arc or vertex
    index on ``i`` and on ``j``; the two arc centres / vertices relative to ``i``'s
    centre; r; delta).
    """
    si = pi[0]
    sj = pj[0]
    vi = _world_vertices(pi, ti, 0.0 * dx0, 0.0 * dx1)
    vj = _world_vertices(pj, tj, dx0, dx1)
    energy = 0.0 * dx0
    rows = 0
    for m in range(3):
        m1 = (m + 1) % 3
        m2 = (m + 2) % 3
        for n in range(3):
            n1 = (n + 1) % 3
            n2 = (n + 2) % 3
            # arc m of i (centre vi[m]) against arc n of j (centre vj[n])
            ux = vj[n, 0] - vi[m, 0]
            uy = vj[n, 1] - vi[m, 1]
            r = np.sqrt(ux * ux + uy * uy)
            # an arc-arc overlap deeper than the larger side is no contact of the two arcs:
            # an arc centre (a vertex) then lies in the other body's sector, as when two
            # corners cross tip to tip (their vertex-arc terms carry that overlap), and the
            # term would jump in at delta ~ s_i + s_j
            if max(si.real, sj.real) < r.real < (si + sj).real:
                ok_i = _in_arc(ux.real, uy.real, (vi[m1, 0] - vi[m, 0]).real, (vi[m1, 1] - vi[m, 1]).real,
                               (vi[m2, 0] - vi[m, 0]).real, (vi[m2, 1] - vi[m, 1]).real)
                ok_j = _in_arc(-ux.real, -uy.real, (vj[n1, 0] - vj[n, 0]).real, (vj[n1, 1] - vj[n, 1]).real,
                               (vj[n2, 0] - vj[n, 0]).real, (vj[n2, 1] - vj[n, 1]).real)
                if ok_i and ok_j:
                    u, rr, delta, _, _ = _point_term(vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], dx0, dx1, si + sj,
                                                     k, g, 0, 3)
                    energy += u
                    rows = _record_point(out, rows, record, 0, m, n, vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1],
                                         rr, delta)
            # vertex n of j against arc m of i: u in the arc's angle and -u in the
            # vertex's normal cone (between the normals of the two arcs ending there),
            # exclusive with the arc-arc terms of the arcs meeting at the vertex
            if r.real < si.real and _in_arc(ux.real, uy.real, (vi[m1, 0] - vi[m, 0]).real,
                                            (vi[m1, 1] - vi[m, 1]).real, (vi[m2, 0] - vi[m, 0]).real,
                                            (vi[m2, 1] - vi[m, 1]).real) \
                    and _in_arc(-ux.real, -uy.real, (vj[n, 0] - vj[n1, 0]).real, (vj[n, 1] - vj[n1, 1]).real,
                                (vj[n, 0] - vj[n2, 0]).real, (vj[n, 1] - vj[n2, 1]).real):
                u, rr, delta, _, _ = _point_term(vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], dx0, dx1, si, k, g, 0, 3)
                energy += u
                rows = _record_point(out, rows, record, 2, m, n, vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], rr, delta)
            # vertex m of i against arc n of j (the mirror image)
            if r.real < sj.real and _in_arc(-ux.real, -uy.real, (vj[n1, 0] - vj[n, 0]).real,
                                            (vj[n1, 1] - vj[n, 1]).real, (vj[n2, 0] - vj[n, 0]).real,
                                            (vj[n2, 1] - vj[n, 1]).real) \
                    and _in_arc(ux.real, uy.real, (vi[m, 0] - vi[m1, 0]).real, (vi[m, 1] - vi[m1, 1]).real,
                                (vi[m, 0] - vi[m2, 0]).real, (vi[m, 1] - vi[m2, 1]).real):
                u, rr, delta, _, _ = _point_term(vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], dx0, dx1, sj, k, g, 0, 3)
                energy += u
                rows = _record_point(out, rows, record, 1, m, n, vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], rr, delta)
    return energy, rows


#: Columns of a point-term table (dumbbells, Reuleaux triangles; see :func:`point_terms`).
POINT_TERM_COLUMNS = ("pair", "type", "a", "b", "point_i_x", "point_i_y", "point_j_x", "point_j_y", "r", "delta")


# inlined: called with constant kinds and indices, it would otherwise compile once per combination
@njit(cache=True, inline="always")
def _record_point(out, rows, record, kind, a, b, pix, piy, pjx, pjy, r, delta):
    """Write one point-term row (see :data:`POINT_TERM_COLUMNS`, without the pair column)."""
    if record:
        out[rows, 0] = kind
        out[rows, 1] = a
        out[rows, 2] = b
        out[rows, 3] = pix.real
        out[rows, 4] = piy.real
        out[rows, 5] = pjx.real
        out[rows, 6] = pjy.real
        out[rows, 7] = r.real
        out[rows, 8] = delta.real
        return rows + 1
    return rows


@njit(cache=True)
def dumbbell_terms(dx0, dx1, ti, tj, pi, pj, k, g, record, out):
    """Dumbbell pair terms (VanderWerf et al. Sec. II); parameters ``[R, 2, v0x, v0y, v1x, v1y, w]``.

    A dumbbell is two lobes of radius ``R`` centred on ``v0, v1`` joined by a shaft of
    half-width ``w < R`` along the segment ``[v0, v1]``. Terms, each
    ``(k/2)(sigma - r)^2`` when ``r < sigma`` (Eq. 1), all added:

    - end-end (type 0): ``r`` = distance of a lobe centre of ``i`` and one of ``j``,
      ``sigma = R_i + R_j``;
    - end-shaft (type 1: a lobe of ``i`` on the shaft of ``j``; type 2: the mirror):
      ``r`` = distance from the lobe centre to the nearest point of the other's
      segment ``[v0, v1]`` (foot parameter clamped to [0, 1]), ``sigma = R + w``.

    The distance to a segment is C^1 away from it, so ``U``, forces and torques are
    continuous everywhere (the second derivative jumps where the foot reaches a segment
    end or a term switches on). Where the foot is clamped, the end-shaft term is a disk
    of radius ``w`` inside the lobe: it only acts when the lobes overlap by more than
    ``R - w``, far beyond any jammed packing. Shaft against shaft has no term: two
    shafts closer than ``2 w`` without crossing have a segment end (a lobe centre)
    within ``2 w <= R + w`` of the other shaft, so an end-shaft term acts; crossed
    shafts are refused by the callers (:func:`circulo_cores_intersect`). Every term is
    a distance between two body-fixed points (the foot at fixed ``t``, envelope
    theorem), added through :func:`_point_term`. When ``record`` is true one row per
    term goes to ``out`` (:data:`POINT_TERM_COLUMNS` without ``pair``: type, lobe of
    ``i`` or -1, lobe of ``j`` or -1, the two points relative to ``i``'s centre, r, delta).
    """
    ri = pi[0]
    rj = pj[0]
    wi = pi[6]
    wj = pj[6]
    vi = _world_vertices(pi, ti, 0.0 * dx0, 0.0 * dx1)
    vj = _world_vertices(pj, tj, dx0, dx1)
    energy = 0.0 * dx0
    rows = 0
    sigma = ri + rj
    for m in range(2):
        for n in range(2):
            qx = vi[m, 0] - vj[n, 0]
            qy = vi[m, 1] - vj[n, 1]
            if (qx * qx + qy * qy).real < (sigma * sigma).real:
                u, r, delta, _, _ = _point_term(vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], dx0, dx1, sigma, k, g, 0, 3)
                energy += u
                rows = _record_point(out, rows, record, 0, m, n, vi[m, 0], vi[m, 1], vj[n, 0], vj[n, 1], r, delta)
    for side in range(2):
        # side 0: lobes of i on the shaft of j; side 1: lobes of j on the shaft of i
        if side == 0:
            lobes = vi
            shaft = vj
            sigma = ri + wj
        else:
            lobes = vj
            shaft = vi
            sigma = rj + wi
        ex = shaft[1, 0] - shaft[0, 0]
        ey = shaft[1, 1] - shaft[0, 1]
        for m in range(2):
            px = lobes[m, 0]
            py = lobes[m, 1]
            t = ((px - shaft[0, 0]) * ex + (py - shaft[0, 1]) * ey) / (ex * ex + ey * ey)
            if t.real < 0.0:
                t = 0.0 * t
            elif t.real > 1.0:
                t = 0.0 * t + 1.0
            cx = shaft[0, 0] + t * ex
            cy = shaft[0, 1] + t * ey
            qx = px - cx
            qy = py - cy
            if (qx * qx + qy * qy).real >= (sigma * sigma).real:
                continue
            if side == 0:
                u, r, delta, _, _ = _point_term(px, py, cx, cy, dx0, dx1, sigma, k, g, 0, 3)
                rows = _record_point(out, rows, record, 1, m, -1, px, py, cx, cy, r, delta)
            else:
                u, r, delta, _, _ = _point_term(cx, cy, px, py, dx0, dx1, sigma, k, g, 0, 3)
                rows = _record_point(out, rows, record, 2, -1, m, cx, cy, px, py, r, delta)
            energy += u
    return energy, rows


@njit(cache=True)
def dumbbell_pair(dx0, dx1, ti, tj, pi, pj, k, g):
    """Dumbbell pair energy and gradient (see :func:`dumbbell_terms`)."""
    return dumbbell_terms(dx0, dx1, ti, tj, pi, pj, k, g, False, np.empty((0, 9)))[0]


@njit(cache=True)
def point_terms(terms, i, j, dx, theta, params, k, max_terms):
    """Every term of the listed pairs of a point-term family, one row each.

    ``terms`` is :func:`dumbbell_terms` or :func:`reuleaux_terms`; columns
    :data:`POINT_TERM_COLUMNS` (pair row first; points relative to ``i``'s centre).
    """
    buf = np.zeros((max_terms, 9))
    rows = []
    g = np.zeros(6)
    for p in range(i.size):
        _, n = terms(dx[p, 0], dx[p, 1], theta[i[p]], theta[j[p]], params[i[p]], params[j[p]], k, g, True, buf)
        for r in range(n):
            row = np.empty(10)
            row[0] = p
            row[1:] = buf[r]
            rows.append(row)
    out = np.empty((len(rows), 10))
    for r in range(len(rows)):
        out[r] = rows[r]
    return out
