"""All pairs of particles closer than a cutoff in periodic and sheared boxes.

Orthogonal boxes use a compiled cell list (cells at least ``cutoff`` wide, O(N),
pairs emitted already sorted). Sheared boxes are searched in their
reduced basis with ghost images: every particle whose periodic image lies within
the cutoff of the primary cell (a slab of ``cutoff / width_k`` in fractional
coordinate k) is added once per image, so the tree sees every pair within the
cutoff exactly once. Both paths cost O(N log N).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .box import Box

__all__ = ["PairList", "cell_index", "pairs_within", "pairs_within_brute_force", "sort_by_cell", "verlet_pairs"]


@dataclass(frozen=True)
class PairList:
    """Pairs ``i < j`` with their minimum-image separation.

    Attributes
    ----------
    i, j : ndarray of int64, shape (P,)
        Particle indices, ``i < j``, sorted lexicographically.
    dx : ndarray of float64, shape (P, d)
        Minimum-image vector ``x_j - x_i`` [length].
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    dx: NDArray[np.float64]

    @property
    def distance(self) -> NDArray[np.float64]:
        """Centre-to-centre distances, shape (P,) [length]."""
        return np.linalg.norm(self.dx, axis=1)

    def __len__(self) -> int:
        return len(self.i)

    def select(self, mask: NDArray[np.bool_]) -> "PairList":
        """Sub-list of the pairs where ``mask`` is true."""
        return PairList(self.i[mask], self.j[mask], self.dx[mask])


def _check_cutoff(box: Box, cutoff: float) -> None:
    if not np.isfinite(cutoff) or cutoff <= 0.0:
        raise ValueError(f"cutoff must be positive and finite, got {cutoff}")
    half = 0.5 * float(np.min(box.widths))
    if cutoff >= half:
        raise ValueError(
            f"cutoff {cutoff:.6g} must be below half the smallest box width ({half:.6g}): "
            "a larger cutoff would meet two images of the same particle"
        )


def _make(box: Box, positions: NDArray[np.float64], i: NDArray, j: NDArray) -> PairList:
    i, j = np.minimum(i, j).astype(np.int64), np.maximum(i, j).astype(np.int64)
    order = np.lexsort((j, i))
    i, j = i[order], j[order]
    return PairList(i, j, box.minimum_image(positions[j] - positions[i]))


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
def _cell_pairs(x, L, cutoff, diameter, skin):
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


def _checked_positions(positions: ArrayLike, box: Box) -> NDArray[np.float64]:
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != box.d:
        raise ValueError(f"positions must have shape (N, {box.d}), got {x.shape}")
    return x


def pairs_within(positions: ArrayLike, box: Box, cutoff: float) -> PairList:
    """All pairs with minimum-image distance at most ``cutoff``.

    Parameters
    ----------
    positions : array_like, shape (N, d)
        Particle centres [length]; need not be wrapped.
    box : Box
        Periodic (possibly sheared) box.
    cutoff : float
        Distance [length]; must be below half the smallest perpendicular box width.

    Returns
    -------
    PairList
        Each pair once, ``i < j``, lexicographically sorted.
    """
    x = _checked_positions(positions, box)
    _check_cutoff(box, cutoff)
    if len(x) < 2:
        return _make(box, x, np.empty(0, np.int64), np.empty(0, np.int64))
    if box.is_orthogonal:
        L = box.lengths
        i, j, _ = _cell_pairs(x, L, float(cutoff), np.empty(0), 0.0)
        return PairList(i, j, box.minimum_image(x[j] - x[i]))
    return _pairs_sheared(x, box, cutoff)


def _pairs_sheared(x: NDArray[np.float64], box: Box, cutoff: float) -> PairList:
    red = box.reduced
    s = red.to_fractional(x)
    s -= np.floor(s)
    margin = cutoff / red.widths
    points, owner = [s], [np.arange(len(s))]
    for n in itertools.product((-1, 0, 1), repeat=box.d):
        if not any(n):
            continue
        shifted = s + np.asarray(n, dtype=np.float64)
        keep = np.all((shifted > -margin) & (shifted < 1.0 + margin), axis=1)
        points.append(shifted[keep])
        owner.append(np.flatnonzero(keep))
    cart = red.to_cartesian(np.concatenate(points))
    owner_all = np.concatenate(owner)
    n_primary = len(s)
    tree = cKDTree(cart)
    pairs = tree.query_pairs(cutoff, output_type="ndarray")
    a, b = pairs[:, 0], pairs[:, 1]
    # keep pairs with a primary member; a pair seen from both sides is deduplicated
    primary = (a < n_primary) | (b < n_primary)
    a, b = owner_all[a[primary]], owner_all[b[primary]]
    distinct = a != b
    key = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)[distinct], axis=0)
    return _make(box, x, key[:, 0], key[:, 1])


def verlet_pairs(
    positions: ArrayLike, box: Box, diameter: ArrayLike, skin: float
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Pairs closer than their contact distance plus a skin, with their periodic images.

    Parameters
    ----------
    positions : array_like, shape (N, d)
        Centres [length], wrapped or not.
    box : Box
    diameter : array_like, shape (N,)
        Diameters [length]; the contact distance is ``sigma_ij = (D_i + D_j) / 2``.
    skin : float
        [length], > 0; ``max D + skin`` must be below half the smallest box width.

    Returns
    -------
    i, j : ndarray of int64, shape (P,)
        ``i < j``, lexicographically sorted, minimum-image distance ``< sigma_ij + skin``.
    image : ndarray of float64, shape (P, d)
        Integer lattice vectors ``n`` with ``x_j - x_i + h n`` the minimum image.
    """
    x = _checked_positions(positions, box)
    D = np.asarray(diameter, dtype=np.float64)
    reach = float(D.max()) + float(skin)
    _check_cutoff(box, reach)
    if box.is_orthogonal and len(x) >= 2:
        L = box.lengths
        i, j, image = _cell_pairs(x, L, reach, D, float(skin))
        return i, j, image.astype(np.float64)
    pairs = pairs_within(x, box, reach)
    keep = pairs.distance < 0.5 * (D[pairs.i] + D[pairs.j]) + skin
    pairs = pairs.select(keep)
    raw = x[pairs.j] - x[pairs.i]
    return pairs.i, pairs.j, np.round((pairs.dx - raw) @ box.inverse.T)


def pairs_within_brute_force(positions: ArrayLike, box: Box, cutoff: float) -> PairList:
    """O(N^2) reference for :func:`pairs_within` (tests and tiny systems)."""
    x = np.asarray(positions, dtype=np.float64)
    i, j = np.triu_indices(len(x), k=1)
    dx = box.minimum_image(x[j] - x[i])
    keep = np.einsum("pk,pk->p", dx, dx) <= cutoff**2
    return PairList(i[keep].astype(np.int64), j[keep].astype(np.int64), dx[keep])
