"""Numba kernels of the cell-list neighbour search (:mod:`jamflow.neighbors`) and the LS lists.

Cells of an orthogonal periodic box, at least a cutoff wide: the flat cell index of
every particle, the counting sort of particles by cell (also used by the event-driven
LS lists, :mod:`jamflow._ls_kernels`), and the pair search. Kept apart from
:mod:`jamflow.neighbors` so that importing the package does not load numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["cell_index", "cell_pairs", "sort_by_cell"]


@njit(cache=True)
def cell_index(x, L, ncell):
    """Flat cell index of every position, cells ``L_k / ncell_k`` wide (row-major, last axis fastest).

    ``x`` (N, d) must be wrapped into ``[0, L)``; round-off at the upper edge is
    clamped into the last cell. Returns int64 (N,).
    """
    n, d = x.shape
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        cid = 0
        for k in range(d):
            c = int(x[i, k] / L[k] * ncell[k])
            c = min(max(c, 0), ncell[k] - 1)
            cid = cid * ncell[k] + c
        out[i] = cid
    return out


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
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        start[cell[i] + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    members = np.empty(n, dtype=np.int64)
    slot = start[:n_cells].copy()
    for i in range(n):
        members[slot[cell[i]]] = i
        slot[cell[i]] += 1
    return start, members


@njit(cache=True)
def cell_pairs(x, L, cutoff, diameter, skin):
    """Pairs ``i < j`` closer than a cutoff in an orthogonal box, with their periodic images.

    ``x`` (N, d) are the positions (wrapped into ``[0, L)`` here), ``cutoff < min(L) / 2``.
    Kept are the pairs with minimum-image distance ``r <= cutoff`` (``diameter`` empty) or ``r < (D_i + D_j) / 2 + skin`` (a Verlet
    list; then ``cutoff`` must be at least ``max D + skin``). Cells are at least
    ``cutoff`` wide, so partners lie in the 3^d cells around a particle's (fewer
    distinct cells along an axis with fewer than 3); each particle collects its
    partners ``j > i`` and sorts them, so the pairs come out lexicographically sorted.

    Returns
    -------
    i, j : int64 (P,)
    image : int64 (P, d)
        ``n`` with ``x_j - x_i + L n`` the minimum image.
    """
    n, d = x.shape
    verlet = diameter.shape[0] > 0
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
    wrapped = np.empty((n, d))
    for i in range(n):
        for k in range(d):
            v = x[i, k] - L[k] * np.floor(x[i, k] / L[k])
            # round-off can put x - L floor(x / L) at L
            wrapped[i, k] = 0.0 if v >= L[k] else v
    cell = cell_index(wrapped, L, ncell)
    start, members = sort_by_cell(cell, n_cells)
    # positions and diameters in cell order, so a cell's members are contiguous
    ws = np.empty((n, d))
    Ds = np.empty(n if verlet else 0)
    for q in range(n):
        for k in range(d):
            ws[q, k] = wrapped[members[q], k]
        if verlet:
            Ds[q] = diameter[members[q]]
    cut2 = cutoff * cutoff
    capacity = 8 * n + 16
    out_i = np.empty(capacity, dtype=np.int64)
    out_j = np.empty(capacity, dtype=np.int64)
    found = np.empty(n, dtype=np.int64)
    # stencil of every cell once (integer divisions per cell, not per particle): the
    # neighbour cell ids and the image shift of their members (-+L across the boundary
    # along axes with at least 3 cells; fewer cells along an axis round instead)
    nb = np.empty((n_cells, n_stencil), dtype=np.int64)
    nb_shift = np.zeros((n_cells, n_stencil, d))
    own = np.empty(d, dtype=np.int64)
    for ci in range(n_cells):
        rest = ci
        for k in range(d - 1, -1, -1):
            own[k] = rest % ncell[k]
            rest //= ncell[k]
        for t in range(n_stencil):
            rest = t
            cid = 0
            for k in range(d):
                step = rest % span[k]
                rest //= span[k]
                if span[k] == 3:
                    c = own[k] + step - 1
                    nb_shift[ci, t, k] = -L[k] if c < 0 else (L[k] if c >= ncell[k] else 0.0)
                    c %= ncell[k]
                else:
                    c = step
                cid = cid * ncell[k] + c
            nb[ci, t] = cid
    wi = np.empty(d)
    m = 0
    for i in range(n):
        ci = cell[i]
        for k in range(d):
            wi[k] = wrapped[i, k]
        n_found = 0
        for t in range(n_stencil):
            cid = nb[ci, t]
            shift = nb_shift[ci, t]
            for q in range(start[cid], start[cid + 1]):
                j = members[q]
                if j <= i:
                    continue
                r2 = 0.0
                for k in range(d):
                    if span[k] == 3:
                        dx = ws[q, k] + shift[k] - wi[k]
                    else:
                        dx = ws[q, k] - wi[k]
                        dx -= L[k] * np.round(dx / L[k])
                    r2 += dx * dx
                if verlet:
                    reach = 0.5 * (diameter[i] + Ds[q]) + skin
                    keep = r2 < reach * reach
                else:
                    keep = r2 <= cut2
                if keep:
                    found[n_found] = j
                    n_found += 1
        if m + n_found > capacity:
            capacity = 2 * capacity + n_found
            out_i = np.concatenate((out_i[:m], np.empty(capacity - m, dtype=np.int64)))
            out_j = np.concatenate((out_j[:m], np.empty(capacity - m, dtype=np.int64)))
        # insertion sort of the few partners in place (no allocation per particle)
        for q in range(1, n_found):
            key = found[q]
            r = q - 1
            while r >= 0 and found[r] > key:
                found[r + 1] = found[r]
                r -= 1
            found[r + 1] = key
        for q in range(n_found):
            out_i[m] = i
            out_j[m] = found[q]
            m += 1
    image = np.empty((m, d), dtype=np.int64)
    for p in range(m):
        for k in range(d):
            raw = x[out_j[p], k] - x[out_i[p], k]
            image[p, k] = -int(np.round(raw / L[k]))
    return out_i[:m].copy(), out_j[:m].copy(), image
