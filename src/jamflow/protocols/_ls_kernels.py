"""Numba kernels of the Lubachevsky–Stillinger event-driven dynamics (:mod:`jamflow.protocols.ls`).

State (all float64 unless stated; ``N`` particles, ``d`` dimensions):

* ``x (N, d)``: centre of particle ``i`` at its own last-update time ``tl[i]``
  ("lazy" positions: ``x_i(t) = x[i] + v[i] (t - tl[i])``).
* ``a (N,)``: diameter ratios; the diameter at time ``t`` is ``a[i] * s(t)`` with the
  common scale ``s(t) = s_w + rate * t`` (``t`` counts from the start of the current
  measuring window, so that short flight times are never lost against a large
  absolute time).
* Cell grid: ``ncell (d,)`` cells of width ``w (d,)`` per axis, ``cc (N, d)`` integer
  cell coordinates, doubly linked lists ``head / nxt / prv`` per flat cell index.
  Neighbour cells are the offsets ``offs (noff, d)`` (``-1, 0, 1`` along axes with at
  least three cells, every cell along axes with fewer).
* Events: per particle the earliest predicted collision (``coll_time``,
  ``coll_partner``, ``coll_pcount`` = partner's collision counter when predicted) and
  the next cell crossing (``cross_time``, ``cross_dim``); ``ev_time = min`` of both,
  kept in a complete binary tournament tree ``tree`` (leaves ``M + i``, root 1).
  A collision is valid only if the partner has not collided since it was predicted
  (counter ``count``); otherwise the particle is rescanned (Isobe's scheme).
* Verlet neighbour lists (``Lists.use``; the cells then only serve to build them): the
  partners of ``i`` are ``idx[start[i]:start[i + 1]]`` (CSR, symmetric), every
  ``j`` with ``|r_ij| < sigma_ij(t_b) + delta`` at the build time ``t_b``, where ``xb``
  are the positions at the build; the :data:`LIST_BUILD` record holds ``t_b``,
  ``delta / 2`` and ``g_max = rate max(a) / 2``. Positions are not wrapped in this mode (no cell
  crossings; the minimum image takes care of the periodicity), and ``cross_time`` holds
  each particle's *leave* time (``cross_dim = -1``): the first time at which
  ``|x_i(t) - xb_i| + g_max (t - t_b)`` may reach ``delta / 2``, bounded linearly from
  ``|v_i|`` after every velocity change. The first leave event ends :func:`run_events`
  with :data:`LIST_EXPIRED`, and the caller rebuilds all lists.

  Guarantee: a pair not in the list cannot touch before the first leave event. It had
  ``|r_ij(t_b)| >= sigma_ij(t_b) + delta``; until then each particle moved less than
  ``delta / 2 - g_max (t - t_b)``, so ``|r_ij(t)| > sigma_ij(t_b) + 2 g_max (t - t_b)
  >= sigma_ij(t_b) + (a_i + a_j) rate (t - t_b) / 2 = sigma_ij(t)``.

The arrays travel in a few records (:class:`Spheres`, :class:`PeriodicBox`,
:class:`Cells`, :class:`Events`, :class:`Lists`; NamedTuples, which numba passes as their
fields) and the run's scalars in one :data:`CLOCK` record, updated in place.

Collision rule for growing spheres (equal masses ``m = 1``): with ``n`` the unit
vector from ``i`` to ``j``, ``u_n = (v_j - v_i) . n`` and ``g = d sigma_ij / dt``,
the impulse ``J = g - u_n`` (``v_j += J n``, ``v_i -= J n``) reverses the rate of
change of the gap, ``u_n - g -> -(u_n - g)``, so the pair separates faster than it
grows. The kinetic energy increases by ``J g`` per collision and the collision
virial ``r_ij J`` is accumulated for the pressure.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._numba import njit
from ..neighbors._cell_kernels import sort_by_cell

#: Status codes of :func:`run_events`: collision budget used, time limit reached, a
#: particle may leave the neighbour-list skin (rebuild the lists before continuing).
WINDOW_DONE, TIME_LIMIT, LIST_EXPIRED = 0, 1, 2

#: The run's clock and sums, one record updated in place by :func:`run_events`: the time
#: ``t`` since the start of the window, the diameter scale ``s_w`` at ``t = 0`` and its
#: growth rate ``rate`` (``s(t) = s_w + rate t``), the kinetic energy ``kinetic``, its time
#: integral ``kinetic_integral`` over the window and the collision virial ``virial``
#: (the sum of ``r_ij J`` over the window's collisions).
CLOCK = np.dtype([("t", np.float64), ("s_w", np.float64), ("rate", np.float64), ("kinetic", np.float64),
                  ("kinetic_integral", np.float64), ("virial", np.float64)])

#: The neighbour lists' build, one record: the build time ``t_build`` (window time), half
#: the skin ``half_skin`` and ``g_max = rate max(a) / 2``, the fastest growth of a radius.
LIST_BUILD = np.dtype([("t_build", np.float64), ("half_skin", np.float64), ("g_max", np.float64)])


class Spheres(NamedTuple):
    """Lazy centres ``x`` (N, d) at the particles' own times ``tl`` (N,), velocities ``v``
    (N, d) and diameter ratios ``a`` (N,)."""

    x: NDArray[np.float64]
    v: NDArray[np.float64]
    tl: NDArray[np.float64]
    a: NDArray[np.float64]


class PeriodicBox(NamedTuple):
    """Sides ``L`` (d,) of the orthogonal periodic box and their inverses ``invL``."""

    L: NDArray[np.float64]
    invL: NDArray[np.float64]


class Cells(NamedTuple):
    """The cell grid: widths ``w`` (d,), integer cell coordinates ``cc`` (N, d) and flat
    cell ``cell`` (N,) of every particle, cells per axis ``ncell`` (d,) and their flat
    ``stride``, neighbour offsets ``offs`` (noff, d), and the doubly linked lists
    ``head`` (per cell), ``nxt``, ``prv`` (per particle)."""

    w: NDArray[np.float64]
    cc: NDArray[np.int64]
    cell: NDArray[np.int64]
    ncell: NDArray[np.int64]
    stride: NDArray[np.int64]
    offs: NDArray[np.int64]
    head: NDArray[np.int64]
    nxt: NDArray[np.int64]
    prv: NDArray[np.int64]


class Events(NamedTuple):
    """Per particle: collision counter ``count``, predicted collision (``coll_time``,
    ``coll_partner``, the partner's counter ``coll_pcount``), next cell crossing or list
    leave (``cross_time``, ``cross_dim``), ``ev_time`` (N + 1,) the earlier of the two;
    the tournament tree ``tree`` (2 M,) over ``M`` leaves."""

    count: NDArray[np.int64]
    coll_time: NDArray[np.float64]
    coll_partner: NDArray[np.int64]
    coll_pcount: NDArray[np.int64]
    cross_time: NDArray[np.float64]
    cross_dim: NDArray[np.int64]
    ev_time: NDArray[np.float64]
    tree: NDArray[np.int64]
    M: int


class Lists(NamedTuple):
    """Verlet neighbour lists: in use (``use``), CSR partners ``start`` (N + 1,), ``idx``,
    positions at the build ``xb`` (N, d) and the :data:`LIST_BUILD` record ``build`` (1,)."""

    use: bool
    start: NDArray[np.int64]
    idx: NDArray[np.int64]
    xb: NDArray[np.float64]
    build: NDArray[np.void]


@njit(cache=True, inline="always")
def _root(A, B, C):
    """Earliest tau >= 0 with ``A tau^2 + 2 B tau + C = 0`` entering contact, or inf.

    ``A = |u|^2 - g^2``, ``B = r.u - sigma g``, ``C = |r|^2 - sigma^2`` for relative
    position ``r``, relative velocity ``u``, contact distance ``sigma`` growing at
    rate ``g``. Roots are taken in the cancellation-free forms
    ``C / (-B + sqrt(D))`` (for ``B < 0``) and ``(B + sqrt(D)) / (-A)`` (for ``B >= 0``,
    ``A < 0``) with ``D = B^2 - A C``.
    """
    if C <= 0.0:
        # in contact or overlapping by round-off
        if B < 0.0:
            return 0.0
        if A >= 0.0:
            return np.inf
        D = B * B - A * C
        if D < 0.0:
            return 0.0
        return (B + np.sqrt(D)) / (-A)
    if B < 0.0:
        D = B * B - A * C
        if D < 0.0:
            return np.inf
        return C / (-B + np.sqrt(D))
    if A < 0.0:
        D = B * B - A * C
        return (B + np.sqrt(D)) / (-A)
    return np.inf


@njit(cache=True)
def collision_time(dx, u, sigma, g):
    """Time until two spheres touch (inf if never).

    Parameters
    ----------
    dx : ndarray, shape (d,)
        Relative position ``x_j - x_i`` [length] (non-overlapping: ``|dx| >= sigma``).
    u : ndarray, shape (d,)
        Relative velocity ``v_j - v_i`` [length/time].
    sigma : float
        Contact distance now [length].
    g : float
        Growth rate of the contact distance [length/time], >= 0.
    """
    A = 0.0
    B = 0.0
    C = 0.0
    for k in range(dx.shape[0]):
        A += u[k] * u[k]
        B += dx[k] * u[k]
        C += dx[k] * dx[k]
    return _root(A - g * g, B - sigma * g, C - sigma * sigma)


@njit(cache=True, inline="always")
def _pair(i, j, t, sph, box, s_t, rate):
    """Collision time (absolute) of the pair i, j from time t."""
    x, v, tl, a = sph.x, sph.v, sph.tl, sph.a
    L, invL = box.L, box.invL
    A = 0.0
    B = 0.0
    C = 0.0
    dti = t - tl[i]
    dtj = t - tl[j]
    for k in range(x.shape[1]):
        dx = (x[j, k] + v[j, k] * dtj) - (x[i, k] + v[i, k] * dti)
        dx -= L[k] * np.floor(dx * invL[k] + 0.5)
        u = v[j, k] - v[i, k]
        A += u * u
        B += dx * u
        C += dx * dx
    S = 0.5 * (a[i] + a[j])
    sig = S * s_t
    g = S * rate
    return t + _root(A - g * g, B - sig * g, C - sig * sig)


@njit(cache=True)
def _scan(i, t, only_dim, only_off, sph, box, s_t, rate, cells, ev):
    """Lower particle i's predicted collision by scanning neighbour cells.

    ``only_dim < 0``: all neighbour cells, starting from no prediction. Otherwise only
    the cells at offset ``only_off`` along axis ``only_dim`` (the layer that became
    adjacent after a cell crossing), keeping the current prediction together with its
    partner counter: re-stamping that counter would validate a prediction that the
    partner's own collision since then has made stale.
    """
    cc, ncell, stride, offs, head, nxt = cells.cc, cells.ncell, cells.stride, cells.offs, cells.head, cells.nxt
    coll_time, coll_partner = ev.coll_time, ev.coll_partner
    d = sph.x.shape[1]
    found = False
    if only_dim < 0:
        best = np.inf
        partner = -1
    else:
        best = coll_time[i]
        partner = coll_partner[i]
    for q in range(offs.shape[0]):
        if only_dim >= 0 and offs[q, only_dim] != only_off:
            continue
        cid = 0
        for k in range(d):
            c = cc[i, k] + offs[q, k]
            if c < 0:
                c += ncell[k]
            elif c >= ncell[k]:
                c -= ncell[k]
            cid += c * stride[k]
        j = head[cid]
        while j >= 0:
            if j != i:
                tc = _pair(i, j, t, sph, box, s_t, rate)
                if tc < best:
                    best = tc
                    partner = j
                    found = True
            j = nxt[j]
    coll_time[i] = best
    coll_partner[i] = partner
    if found:
        ev.coll_pcount[i] = ev.count[partner]


@njit(cache=True)
def _scan_list(i, t, sph, box, s_t, rate, lists, ev):
    """Predict particle i's next collision from its neighbour list."""
    best = np.inf
    partner = -1
    for q in range(lists.start[i], lists.start[i + 1]):
        j = lists.idx[q]
        tc = _pair(i, j, t, sph, box, s_t, rate)
        if tc < best:
            best = tc
            partner = j
    ev.coll_time[i] = best
    ev.coll_partner[i] = partner
    if partner >= 0:
        ev.coll_pcount[i] = ev.count[partner]


@njit(cache=True)
def _leave(i, t, sph, lists, ev):
    """Conservative time at which particle i may exhaust its half skin.

    With ``D = |x_i(t) - xb_i|`` and ``r = delta / 2 - D - g_max (t - t_b)``, the bound
    ``|x_i(t + tau) - xb_i| <= D + |v_i| tau`` gives the leave time
    ``t + r / (|v_i| + g_max)`` (``t`` if ``r <= 0``; never if nothing moves or grows).
    """
    x, v, xb = sph.x, sph.v, lists.xb
    build = lists.build[0]
    cross_time = ev.cross_time
    dt = t - sph.tl[i]
    disp2 = 0.0
    v2 = 0.0
    for k in range(x.shape[1]):
        dk = x[i, k] + v[i, k] * dt - xb[i, k]
        disp2 += dk * dk
        v2 += v[i, k] * v[i, k]
    rest = build.half_skin - np.sqrt(disp2) - build.g_max * (t - build.t_build)
    speed = np.sqrt(v2) + build.g_max
    if rest <= 0.0:
        cross_time[i] = t
    elif speed > 0.0:
        cross_time[i] = t + rest / speed
    else:
        cross_time[i] = np.inf
    ev.cross_dim[i] = -1


@njit(cache=True)
def _cross(i, t, sph, cells, ev):
    """Next time particle i leaves its cell, and along which axis."""
    x, v, cc, w = sph.x, sph.v, cells.cc, cells.w
    best = np.inf
    bd = -1
    dt = t - sph.tl[i]
    for k in range(x.shape[1]):
        vk = v[i, k]
        xk = x[i, k] + vk * dt
        if vk > 0.0:
            tau = ((cc[i, k] + 1) * w[k] - xk) / vk
        elif vk < 0.0:
            tau = (cc[i, k] * w[k] - xk) / vk
        else:
            continue
        if tau < best:
            best = tau
            bd = k
    best = max(best, 0.0)
    ev.cross_time[i] = t + best
    ev.cross_dim[i] = bd


@njit(cache=True, inline="always")
def _update_tree(i, ev):
    """Replay the tournament above leaf ``i`` after its event time changed."""
    ev_time, tree = ev.ev_time, ev.tree
    pos = (ev.M + i) >> 1
    while pos >= 1:
        l = tree[2 * pos]
        r = tree[2 * pos + 1]
        tree[pos] = l if ev_time[l] <= ev_time[r] else r
        pos >>= 1


@njit(cache=True, inline="always")
def _link(i, cid, cells):
    """Put particle i at the head of cell cid's doubly linked list."""
    head, nxt, prv = cells.head, cells.nxt, cells.prv
    cells.cell[i] = cid
    prv[i] = -1
    nxt[i] = head[cid]
    if head[cid] >= 0:
        prv[head[cid]] = i
    head[cid] = i


@njit(cache=True)
def build_cells(x, L, cells):
    """Assign every particle (positions already in [0, L)) to its cell."""
    ncell, cc, stride = cells.ncell, cells.cc, cells.stride
    n, d = x.shape
    cells.head[:] = -1
    for i in range(n):
        cid = 0
        for k in range(d):
            c = int(np.floor(x[i, k] / L[k] * ncell[k]))
            if c < 0:
                c = 0
            elif c >= ncell[k]:
                c = ncell[k] - 1
            cc[i, k] = c
            cid += c * stride[k]
        _link(i, cid, cells)


@njit(cache=True)
def build_neighbor_lists(x, a, L, invL, s_t, skin, cell, ncell, stride, offs):
    """Symmetric CSR neighbour lists: all j with ``|r_ij| < sigma_ij + skin``.

    The particles are counting-sorted by cell (:func:`jamflow.neighbors._cell_kernels.sort_by_cell`,
    the binning the soft-sphere Verlet lists use too) into contiguous copies of their positions
    and diameters; every pair of neighbour cells ``c <= c'`` is then swept once over
    contiguous ranges (cells at least ``max sigma + skin`` wide, positions synced), and
    a counting sort of the pairs gives the CSR arrays. Cost ``O(N * stencil)``; the
    contiguous, branch-free inner loop is faster than walking the linked cell lists
    (measured: docs/notes/ls-constants.md#building-the-lists-by-cell-order).

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions [length].
    a : ndarray, shape (N,)
        Diameter ratios.
    L, invL : ndarray, shape (d,)
        Box lengths [length] and their inverses.
    s_t : float
        Diameter scale now [length] (``sigma_ij = (a_i + a_j) s_t / 2``).
    skin : float
        Skin ``delta`` [length].
    cell : ndarray of int64, shape (N,)
        Flat cell index of every particle (:func:`build_cells`).

    Returns
    -------
    nl_start : ndarray of int64, shape (N + 1,)
    nl_idx : ndarray of int64, shape (nl_start[N],)
        Partners of ``i`` are ``nl_idx[nl_start[i]:nl_start[i + 1]]``.
    """
    n, d = x.shape
    ncells = 1
    for k in range(d):
        ncells *= ncell[k]
    cstart, order = sort_by_cell(cell, ncells)
    xs = np.empty((n, d))
    as_ = np.empty(n)
    for p in range(n):
        xs[p] = x[order[p]]
        as_[p] = a[order[p]]
    pairs = np.empty((8 * n, 2), dtype=np.int64)
    npair = 0
    ccoord = np.empty(d, dtype=np.int64)
    for ci in range(ncells):
        if cstart[ci] == cstart[ci + 1]:
            continue
        for k in range(d):
            ccoord[k] = (ci // stride[k]) % ncell[k]
        for q in range(offs.shape[0]):
            cj = 0
            for k in range(d):
                c = ccoord[k] + offs[q, k]
                if c < 0:
                    c += ncell[k]
                elif c >= ncell[k]:
                    c -= ncell[k]
                cj += c * stride[k]
            if cj < ci:
                continue
            for p in range(cstart[ci], cstart[ci + 1]):
                lo = p + 1 if cj == ci else cstart[cj]
                for r in range(lo, cstart[cj + 1]):
                    r2 = 0.0
                    for k in range(d):
                        dx = xs[r, k] - xs[p, k]
                        dx -= L[k] * np.floor(dx * invL[k] + 0.5)
                        r2 += dx * dx
                    lim = 0.5 * (as_[p] + as_[r]) * s_t + skin
                    if r2 < lim * lim:
                        if npair == pairs.shape[0]:
                            grown = np.empty((2 * npair, 2), dtype=np.int64)
                            grown[:npair] = pairs
                            pairs = grown
                        pairs[npair, 0] = order[p]
                        pairs[npair, 1] = order[r]
                        npair += 1
    nl_start = np.zeros(n + 1, dtype=np.int64)
    for p in range(npair):
        nl_start[pairs[p, 0] + 1] += 1
        nl_start[pairs[p, 1] + 1] += 1
    for i in range(n):
        nl_start[i + 1] += nl_start[i]
    nl_idx = np.empty(nl_start[n], dtype=np.int64)
    fill = nl_start[:n].copy()
    for p in range(npair):
        i = pairs[p, 0]
        j = pairs[p, 1]
        nl_idx[fill[i]] = j
        fill[i] += 1
        nl_idx[fill[j]] = i
        fill[j] += 1
    return nl_start, nl_idx


@njit(cache=True, inline="always")
def _predict(i, t, sph, box, s_t, rate, cells, ev, lists):
    """Predict particle i's next collision and its list-leave (or cell-crossing) time."""
    if lists.use:
        _scan_list(i, t, sph, box, s_t, rate, lists, ev)
        _leave(i, t, sph, lists, ev)
    else:
        _scan(i, t, -1, 0, sph, box, s_t, rate, cells, ev)
        _cross(i, t, sph, cells, ev)
    ev.ev_time[i] = min(ev.coll_time[i], ev.cross_time[i])


@njit(cache=True)
def init_events(t, s_t, rate, sph, box, cells, ev, lists):
    """Predict every particle's next events at time t (diameter scale ``s_t``, growth
    ``rate``) and build the tree."""
    n = sph.x.shape[0]
    ev_time, tree, M = ev.ev_time, ev.tree, ev.M
    for i in range(n):
        _predict(i, t, sph, box, s_t, rate, cells, ev, lists)
    ev_time[n] = np.inf
    for p in range(M):
        tree[M + p] = min(p, n)
    for pos in range(M - 1, 0, -1):
        l = tree[2 * pos]
        r = tree[2 * pos + 1]
        tree[pos] = l if ev_time[l] <= ev_time[r] else r


@njit(cache=True)
def sync_all(t, x, v, tl):
    """Move every particle to time t (``tl[:] = t``)."""
    n, d = x.shape
    for i in range(n):
        dt = t - tl[i]
        for k in range(d):
            x[i, k] += v[i, k] * dt
        tl[i] = t


@njit(cache=True)
def kinetic_energy(v):
    """``sum_i |v_i|^2 / 2`` (unit masses)."""
    e = 0.0
    for i in range(v.shape[0]):
        for k in range(v.shape[1]):
            e += v[i, k] * v[i, k]
    return 0.5 * e


@njit(cache=True, inline="always")
def _cross_cell(i, t, s_t, rate, sph, box, cells, ev):
    """Move particle i into the neighbouring cell it reaches at time t (wrapping its
    centre across the box) and predict again: its next crossing, and collisions with
    the layer of cells that became adjacent."""
    x, v, tl = sph.x, sph.v, sph.tl
    cc, ncell, stride, head, nxt, prv = cells.cc, cells.ncell, cells.stride, cells.head, cells.nxt, cells.prv
    d = x.shape[1]
    dt = t - tl[i]
    for k in range(d):
        x[i, k] += v[i, k] * dt
    tl[i] = t
    k = ev.cross_dim[i]
    off = 1 if v[i, k] > 0.0 else -1
    cid = cells.cell[i]
    if prv[i] >= 0:
        nxt[prv[i]] = nxt[i]
    else:
        head[cid] = nxt[i]
    if nxt[i] >= 0:
        prv[nxt[i]] = prv[i]
    c = cc[i, k] + off
    if c >= ncell[k]:
        c = 0
        x[i, k] -= box.L[k]
    elif c < 0:
        c = ncell[k] - 1
        x[i, k] += box.L[k]
    cid += (c - cc[i, k]) * stride[k]
    cc[i, k] = c
    _link(i, cid, cells)
    _cross(i, t, sph, cells, ev)
    if ncell[k] >= 3:
        _scan(i, t, k, off, sph, box, s_t, rate, cells, ev)
    ev.ev_time[i] = min(ev.coll_time[i], ev.cross_time[i])
    _update_tree(i, ev)


@njit(cache=True, inline="always")
def _collide(i, j, t, s_t, rate, sph, box):
    """Bring i and j to time t and apply the collision impulse ``J`` (module docstring).

    Returns ``J`` (not positive: the pair was already separating, nothing changed) and
    the pair's centre distance ``r`` and normal relative velocity ``u_n`` before it.
    """
    x, v, tl, a = sph.x, sph.v, sph.tl, sph.a
    L, invL = box.L, box.invL
    d = x.shape[1]
    dti = t - tl[i]
    dtj = t - tl[j]
    for k in range(d):
        x[i, k] += v[i, k] * dti
        x[j, k] += v[j, k] * dtj
    tl[i] = t
    tl[j] = t
    r2 = 0.0
    un = 0.0
    for k in range(d):
        dx = x[j, k] - x[i, k]
        dx -= L[k] * np.floor(dx * invL[k] + 0.5)
        r2 += dx * dx
        un += dx * (v[j, k] - v[i, k])
    r = np.sqrt(r2)
    un /= r
    S = 0.5 * (a[i] + a[j])
    g = S * rate
    # an overlap of round-off size (r < sigma) reflects the rate of |r|^2 - sigma^2
    # instead, so that the pair is separating by both measures afterwards
    J = g * max(1.0, S * s_t / r) - un
    if J > 0.0:
        for k in range(d):
            dx = x[j, k] - x[i, k]
            dx -= L[k] * np.floor(dx * invL[k] + 0.5)
            nk = dx / r
            v[i, k] -= J * nk
            v[j, k] += J * nk
    return J, r, un


@njit(cache=True)
def run_events(max_coll, t_limit, clock, sph, box, cells, ev, lists):
    """Process events until ``max_coll`` collisions or time ``t_limit``.

    ``clock`` (one :data:`CLOCK` record) is read and updated in place. With
    ``lists.use`` the partners come from the neighbour lists (module docstring);
    otherwise from the cells.

    Returns
    -------
    status : int
        :data:`WINDOW_DONE`, :data:`TIME_LIMIT` (then ``t = t_limit``) or
        :data:`LIST_EXPIRED` (then ``t`` is the first leave time; rebuild the lists).
    ncoll : int
        Collisions processed.
    """
    c = clock[0]
    t = c.t
    s_w = c.s_w
    rate = c.rate
    K = c.kinetic
    Kint = c.kinetic_integral
    vir = c.virial
    count, coll_time, coll_partner, coll_pcount = ev.count, ev.coll_time, ev.coll_partner, ev.coll_pcount
    ncoll = 0
    status = WINDOW_DONE
    while ncoll < max_coll:
        i = ev.tree[1]
        te = ev.ev_time[i]
        if te >= t_limit:
            Kint += K * (t_limit - t)
            t = t_limit
            status = TIME_LIMIT
            break
        Kint += K * (te - t)
        t = te
        s_t = s_w + rate * t
        if ev.cross_time[i] <= coll_time[i]:
            if lists.use:
                status = LIST_EXPIRED
                break
            _cross_cell(i, t, s_t, rate, sph, box, cells, ev)
            continue
        j = coll_partner[i]
        if count[j] != coll_pcount[i]:
            # the partner collided since the prediction: predict again
            if lists.use:
                _scan_list(i, t, sph, box, s_t, rate, lists, ev)
            else:
                _scan(i, t, -1, 0, sph, box, s_t, rate, cells, ev)
            ev.ev_time[i] = min(coll_time[i], ev.cross_time[i])
            _update_tree(i, ev)
            continue
        J, r, un = _collide(i, j, t, s_t, rate, sph, box)
        if J > 0.0:
            K += J * (un + J)
            vir += r * J
            count[i] += 1
            count[j] += 1
            ncoll += 1
        for p in (i, j):
            _predict(p, t, sph, box, s_t, rate, cells, ev, lists)
            _update_tree(p, ev)
    c.t = t
    c.kinetic = K
    c.kinetic_integral = Kint
    c.virial = vir
    return status, ncoll
