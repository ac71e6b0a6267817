"""Numba kernels of the cell-list neighbour search (:mod:`jamflow.neighbors.pairs`) and the LS lists.

Cells of an orthogonal periodic box, at least a cutoff wide: the flat cell index of
every particle, the counting sort of particles by cell (also used by the event-driven
LS lists, :mod:`jamflow.protocols._ls_kernels`), and the pair search. Kept apart from
:mod:`jamflow.neighbors.pairs` so that importing the package does not load numba.

A search can reuse the work arrays of the previous one (:func:`pair_buffers`,
:func:`cell_pairs_into`): a list rebuilt every hundred steps inside a compiled loop
otherwise pays for its fresh memory, whose first touch page-faults
(measured: docs/notes/energy-models.md#constants-of-the-neighbour-search).
"""

from __future__ import annotations

import numpy as np

from .._numba import njit

__all__ = ["cell_index", "cell_pairs", "cell_pairs_into", "pair_buffers", "sort_by_cell"]


@njit(cache=True)
def cell_index(x, L, ncell):
    """Flat cell index of every position, cells ``L_k / ncell_k`` wide (row-major, last axis fastest).

    ``x`` (N, d) must be wrapped into ``[0, L)``; round-off at the upper edge is
    clamped into the last cell. Returns int64 (N,).
    """
    return _cell_index_into(x, L, ncell, np.empty(x.shape[0], dtype=np.int64))


@njit(cache=True)
def _cell_index_into(x, L, ncell, out):
    """:func:`cell_index` written into ``out`` (int64, at least N long); returns ``out``."""
    n, d = x.shape
    for i in range(n):
        cid = 0
        for k in range(d):
            c = int(x[i, k] / L[k] * ncell[k])
            c = min(max(c, 0), ncell[k] - 1)
            cid = cid * ncell[k] + c
        out[i] = cid
    return out[:n]


@njit(cache=True)
def sort_by_cell(cell, n_cells):
    """Counting sort of particles by cell index (stable: by particle index within a cell).

    Parameters
    ----------
    cell : int64 (N,)
        Flat cell index of every particle, ``0 <= cell < n_cells``.

    Returns
    -------
    start : int64 (n_cells + 1,)
        The members of cell ``c`` are ``members[start[c]:start[c + 1]]``.
    members : int64 (N,)
        Particle indices in cell order.
    """
    n = cell.shape[0]
    return _sort_by_cell_into(cell, n_cells, np.empty(n_cells + 1, dtype=np.int64),
                              np.empty(n_cells, dtype=np.int64), np.empty(n, dtype=np.int64))


@njit(cache=True)
def _sort_by_cell_into(cell, n_cells, start, slot, members):
    """:func:`sort_by_cell` written into ``start`` (>= n_cells + 1), ``slot`` (>= n_cells, scratch) and ``members`` (>= N).

    Returns the views ``start[:n_cells + 1]`` and ``members[:N]``.
    """
    n = cell.shape[0]
    start[: n_cells + 1] = 0
    for i in range(n):
        start[cell[i] + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
        slot[c] = start[c]
    for i in range(n):
        members[slot[cell[i]]] = i
        slot[cell[i]] += 1
    return start[: n_cells + 1], members[:n]


@njit(inline="always")
def _tick(counter, limit):
    """Advance a multi-index ``counter`` (last axis fastest, ``0 <= counter < limit``) by one, wrapping."""
    k = counter.shape[0] - 1
    while k >= 0:
        counter[k] += 1
        if counter[k] < limit[k]:
            return
        counter[k] = 0
        k -= 1


@njit(inline="always")
def _periodic_cell(c, n, length):
    """Cell index ``c`` (one step outside ``[0, n)`` at most) wrapped, and the image shift of its members."""
    if c < 0:
        return c + n, -length
    if c >= n:
        return c - n, length
    return c, 0.0


@njit(inline="always")
def _keep(r2, p, q, Ds, skin, cut2, verlet):
    """Whether cell-ordered particles ``p, q`` at squared distance ``r2`` form a listed pair."""
    if verlet:
        reach = 0.5 * (Ds[p] + Ds[q]) + skin
        return r2 < reach * reach
    return r2 <= cut2


@njit(cache=True)
def pair_buffers(n, d):
    """Work arrays of :func:`cell_pairs_into` for N particles in d dimensions, allocated and not touched.

    The tuple ``(wrapped, ws, Ds, per_particle, per_cell, found, out, image)``: float
    (N, d) wrapped positions, (N, d) and (N,) positions and diameters in cell order;
    int64 (4, N + 1) cell, members, row starts, slots; int64 (2, C) cell starts and
    slots; int64 (2, P) pairs as found, (2, P) sorted pairs, (P, d) their images; room
    for C = 2 N + 10 cells and P = 8 N + 16 pairs, grown on demand.
    """
    capacity = 8 * n + 16
    return (np.empty((n, d)), np.empty((n, d)), np.empty(n), np.empty((4, n + 1), dtype=np.int64),
            np.empty((2, 2 * n + 10), dtype=np.int64), np.empty((2, capacity), dtype=np.int64),
            np.empty((2, capacity), dtype=np.int64), np.empty((capacity, d), dtype=np.int64))


@njit(cache=True)
def cell_pairs(x, L, cutoff, diameter, skin):
    """Pairs ``i < j`` closer than a cutoff in an orthogonal box, with their periodic images.

    ``x`` (N, d) are the positions (wrapped into ``[0, L)`` here), ``cutoff < min(L) / 2``.
    Kept are the pairs with minimum-image distance ``r <= cutoff`` (``diameter`` empty) or ``r < (D_i + D_j) / 2 + skin`` (a Verlet
    list; then ``cutoff`` must be at least ``max D + skin``). Cells are at least
    ``cutoff`` wide, so partners lie in the 3^d cells around a particle's (fewer
    distinct cells along an axis with fewer than 3); each pair of cells is swept once
    (half stencil) and the pairs are sorted afterwards (counting sort by ``i``, then
    by ``j``), so they come out lexicographically sorted.

    Returns
    -------
    i, j : int64 (P,)
    image : int64 (P, d)
        ``n`` with ``x_j - x_i + L n`` the minimum image.
    """
    i, j, image, _ = cell_pairs_into(x, L, cutoff, diameter, skin, pair_buffers(x.shape[0], x.shape[1]))
    return i.copy(), j.copy(), image.copy()


@njit(cache=True)
def cell_pairs_into(x, L, cutoff, diameter, skin, buffers):
    """:func:`cell_pairs` in the work arrays ``buffers`` of :func:`pair_buffers` (regrown as needed).

    Returns ``(i, j, image, buffers)``: the pairs as views of the returned buffers, which
    the next call overwrites.
    """
    n, d = x.shape
    if buffers[3].shape[1] < n + 1 or buffers[0].shape[1] != d:
        buffers = pair_buffers(n, d)
    wrapped, ws, Ds, per_particle, per_cell, found, out, image = buffers
    verlet = diameter.shape[0] > 0
    ncell, span, n_cells, n_stencil = _grid(L, cutoff, n, d)
    start, members, per_cell = _in_cell_order(x, L, ncell, n_cells, diameter, verlet, wrapped, ws, Ds,
                                              per_particle, per_cell)
    cut2 = cutoff * cutoff
    # half-stencil sweep in cell order over the contiguous cell-ordered positions
    # (no per-candidate j > i test); pairs are then sorted by (i, j) below
    capacity = found.shape[1]
    pa, pb = found[0], found[1]
    m = 0
    # with at least 3 cells along every axis all images are stencil shifts (no rounding)
    shifted = True
    for k in range(d):
        shifted &= span[k] == 3
    centre = np.empty(d)
    own = np.zeros(d, dtype=np.int64)
    step = np.zeros(d, dtype=np.int64)
    fwd, n_fwd, pre, n_pre = _forward_stencil(shifted, n_stencil, d)
    run_first = np.empty(n_fwd, dtype=np.int64)
    run_end = np.empty(n_fwd, dtype=np.int64)
    run_own = np.empty(n_fwd, dtype=np.bool_)
    run_shift = np.empty((n_fwd, d))
    last = d - 1
    # every cell's runs (ranges of cell-ordered particles, each with the image shift of
    # its members) are collected, then swept by one loop. Cells and stencil offsets are
    # counted like odometers (last axis fastest): the neighbour cell and its image shift
    # (-+L across the boundary along axes with at least 3 cells; fewer cells along an
    # axis round instead) follow without integer divisions. Without ``shifted`` the
    # distinct, symmetric stencil cells with a larger id are kept (pairs within a cell
    # once). The loop stays in one piece: helpers called per cell measured 1.2-1.9x
    # slower even inlined.
    for ci in range(n_cells):
        n_runs = 0
        if shifted and 1 <= own[last] <= ncell[last] - 2:
            run_first[0], run_end[0], run_own[0] = start[ci], start[ci + 2], True
            run_shift[0, :] = 0.0
            n_runs = 1
            for t in range(n_pre):
                cid = 0
                for k in range(last):
                    c, run_shift[n_runs, k] = _periodic_cell(own[k] + pre[t, k], ncell[k], L[k])
                    cid = cid * ncell[k] + c
                cid = cid * ncell[last] + own[last] - 1
                run_first[n_runs], run_end[n_runs], run_own[n_runs] = start[cid], start[cid + 3], False
                run_shift[n_runs, last] = 0.0
                n_runs += 1
        else:
            step[:] = 0
            for t in range(n_fwd):
                cid = 0
                for k in range(d):
                    if span[k] == 3:
                        c, run_shift[n_runs, k] = _periodic_cell(own[k] + (fwd[t, k] if shifted else step[k] - 1),
                                                                 ncell[k], L[k])
                    else:
                        c, run_shift[n_runs, k] = step[k], 0.0
                    cid = cid * ncell[k] + c
                if not shifted:
                    _tick(step, span)
                    if cid < ci:
                        continue
                run_first[n_runs], run_end[n_runs], run_own[n_runs] = start[cid], start[cid + 1], cid == ci
                n_runs += 1
        _tick(own, ncell)
        need = 0
        for t in range(n_runs):
            need += run_end[t] - run_first[t]
        need *= start[ci + 1] - start[ci]
        if m + need > capacity:
            # grown outside the candidate loop: arrays reassigned inside it
            # would be reference-counted on every candidate
            capacity = 2 * capacity + need
            grown = np.empty((2, capacity), dtype=np.int64)
            grown[:, :m] = found[:, :m]
            found = grown
            pa, pb = found[0], found[1]
        for t in range(n_runs):
            end = run_end[t]
            for p in range(start[ci], start[ci + 1]):
                # particle p seen from the run's image
                for k in range(d):
                    centre[k] = ws[p, k] - run_shift[t, k]
                first = p + 1 if run_own[t] else run_first[t]
                # d = 2 and 3 with the dimension a constant: the runtime loop over k is slower
                # (measured: docs/notes/energy-models.md#constants-of-the-neighbour-search)
                if shifted and d == 2:
                    c0, c1 = centre[0], centre[1]
                    for q in range(first, end):
                        dx, dy = ws[q, 0] - c0, ws[q, 1] - c1
                        if _keep(dx * dx + dy * dy, p, q, Ds, skin, cut2, verlet):
                            pa[m], pb[m] = p, q
                            m += 1
                elif shifted and d == 3:
                    c0, c1, c2 = centre[0], centre[1], centre[2]
                    for q in range(first, end):
                        dx, dy, dz = ws[q, 0] - c0, ws[q, 1] - c1, ws[q, 2] - c2
                        if _keep(dx * dx + dy * dy + dz * dz, p, q, Ds, skin, cut2, verlet):
                            pa[m], pb[m] = p, q
                            m += 1
                else:
                    for q in range(first, end):
                        r2 = 0.0
                        for k in range(d):
                            dx = ws[q, k] - centre[k]
                            if span[k] < 3:
                                dx -= L[k] * np.round(dx / L[k])
                            r2 += dx * dx
                        if _keep(r2, p, q, Ds, skin, cut2, verlet):
                            pa[m], pb[m] = p, q
                            m += 1
    out, image = _sorted_pairs(x, L, members, pa, pb, m, per_particle, out, image, capacity)
    out_i, out_j = out[0], out[1]
    return out_i[:m], out_j[:m], image[:m], (wrapped, ws, Ds, per_particle, per_cell, found, out, image)


@njit(inline="always")
def _grid(L, cutoff, n, d):
    """Cells per axis (at least ``cutoff`` wide, widened to about two particles per cell
    when sparse), their number, the stencil span per axis (3, or fewer cells) and the
    number of stencil cells."""
    ncell = np.empty(d, dtype=np.int64)
    span = np.empty(d, dtype=np.int64)
    n_stencil = 1
    n_cells = 1
    for k in range(d):
        ncell[k] = max(int(L[k] // cutoff), 1)
        n_cells *= ncell[k]
    if n_cells > 2 * n + 8:
        # sparse systems (small cutoff, high d): wider cells, about two particles per cell,
        # so the cell tables stay O(N)
        widen = (n_cells / (2.0 * n + 8.0)) ** (1.0 / d)
        n_cells = 1
        for k in range(d):
            ncell[k] = max(int(ncell[k] / widen), 1)
            n_cells *= ncell[k]
    for k in range(d):
        span[k] = 3 if ncell[k] >= 3 else ncell[k]
        n_stencil *= span[k]
    return ncell, span, n_cells, n_stencil


@njit(inline="always")
def _in_cell_order(x, L, ncell, n_cells, diameter, verlet, wrapped, ws, Ds, per_particle, per_cell):
    """Positions wrapped into ``[0, L)``, the particles sorted by cell, and the positions
    (and diameters) copied in cell order so that a cell's members are contiguous.

    Returns the cell starts, the members in cell order and ``per_cell`` (regrown if needed).
    """
    n, d = x.shape
    for i in range(n):
        for k in range(d):
            v = x[i, k] - L[k] * np.floor(x[i, k] / L[k])
            # round-off can put x - L floor(x / L) at L
            wrapped[i, k] = 0.0 if v >= L[k] else v
    cell = _cell_index_into(wrapped[:n], L, ncell, per_particle[0])
    if per_cell.shape[1] < n_cells + 1:
        per_cell = np.empty((2, n_cells + 1), dtype=np.int64)
    start, members = _sort_by_cell_into(cell, n_cells, per_cell[0], per_cell[1], per_particle[1])
    for q in range(n):
        for k in range(d):
            ws[q, k] = wrapped[members[q], k]
        if verlet:
            Ds[q] = diameter[members[q]]
    return start, members, per_cell


@njit(inline="always")
def _forward_stencil(shifted, n_stencil, d):
    """The forward half of the stencil and the prefixes of its runs.

    With 3 cells or more along every axis (``shifted``), each cell pair is visited once
    by the forward half of the stencil (offsets lexicographically >= 0; the pair
    ``(c, c + o)`` is met from ``c`` with ``o > 0``, never from ``c + o`` with ``-o``);
    the forward stencil of a cell off the boundary of the last axis is a few runs of
    consecutive cells (last axis fastest): the cell and its successor (prefix 0), and
    for every forward prefix of the other axes the 3 cells around it. Their members are
    contiguous, so each run is one scan: 2 in 2D and 5 in 3D instead of 5 and 14 cell
    visits. Otherwise every stencil cell is visited (``n_fwd = n_stencil``).

    Returns ``fwd`` (n_fwd, d) offsets, ``n_fwd``, ``pre`` (n_pre, d - 1) prefixes and ``n_pre``.
    """
    if shifted:
        n_fwd = (n_stencil - 1) // 2 + 1
        fwd = np.empty((n_fwd, d), dtype=np.int64)
        for t in range(n_fwd):
            tt = t + (n_stencil - 1) // 2
            for k in range(d - 1, -1, -1):
                fwd[t, k] = tt % 3 - 1
                tt //= 3
    else:
        n_fwd = n_stencil
        fwd = np.empty((0, d), dtype=np.int64)
    last = d - 1
    n_pre = 0
    pre = np.empty((0, last), dtype=np.int64)
    if shifted:
        n_pre = (3**last - 1) // 2
        pre = np.empty((n_pre, last), dtype=np.int64)
        for t in range(n_pre):
            tt = t + n_pre + 1
            for k in range(last - 1, -1, -1):
                pre[t, k] = tt % 3 - 1
                tt //= 3
    return fwd, n_fwd, pre, n_pre


@njit(inline="always")
def _sorted_pairs(x, L, members, pa, pb, m, per_particle, out, image, capacity):
    """The ``m`` found pairs as particle indices ``i < j`` in lexicographic order (a
    counting sort by ``i``, then each row's few partners by insertion) in ``out`` (2, P),
    and their periodic images in ``image`` (P, d); both regrown to ``capacity`` if needed."""
    n, d = x.shape
    row, slot = per_particle[2], per_particle[3]
    row[:] = 0
    for e in range(m):
        row[min(members[pa[e]], members[pb[e]]) + 1] += 1
    for i in range(n):
        row[i + 1] += row[i]
    slot[:n] = row[:n]
    if out.shape[1] < m:
        out = np.empty((2, capacity), dtype=np.int64)
        image = np.empty((capacity, d), dtype=np.int64)
    out_i, out_j = out[0], out[1]
    for e in range(m):
        a, b = members[pa[e]], members[pb[e]]
        i, j = min(a, b), max(a, b)
        out_i[slot[i]] = i
        out_j[slot[i]] = j
        slot[i] += 1
    for i in range(n):
        for q in range(row[i] + 1, row[i + 1]):
            key = out_j[q]
            r = q - 1
            while r >= row[i] and out_j[r] > key:
                out_j[r + 1] = out_j[r]
                r -= 1
            out_j[r + 1] = key
    for p in range(m):
        for k in range(d):
            raw = x[out_j[p], k] - x[out_i[p], k]
            image[p, k] = -int(np.floor(raw / L[k] + 0.5))
    return out, image
