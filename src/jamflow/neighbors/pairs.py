"""All pairs of particles closer than a cutoff in periodic and sheared boxes.

Orthogonal boxes of up to :data:`KDTREE_MAX_N` particles use scipy's periodic k-d tree
(``boxsize``); larger ones a compiled cell list (:mod:`jamflow.neighbors._cell_kernels`,
imported on first use so that ``import jamflow`` stays light; cells at least
``cutoff`` wide, O(N), pairs emitted already sorted). Sheared boxes are searched in their
reduced basis with ghost images: every particle whose periodic image lies within
the cutoff of the primary cell (a slab of ``cutoff / width_k`` in fractional
coordinate k) is added once per image, so the tree sees every pair within the
cutoff exactly once. Both paths cost O(N log N).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ..box import Box

__all__ = ["KDTREE_MAX_N", "PairList", "pairs_within", "pairs_within_brute_force", "verlet_pairs"]

#: Orthogonal boxes with at most this many particles are searched with scipy's
#: periodic k-d tree, larger ones with the compiled cell list: a command that needs a
#: few searches then never pays for loading numba, and the tree costs at most a few ms
#: more per search (measured: docs/notes/energy-models.md#constants-of-the-neighbour-search).
KDTREE_MAX_N: int = 8192


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


def _checked_positions(positions: ArrayLike, box: Box) -> NDArray[np.float64]:
    # contiguous: numba compiles the cell kernels once more for every other layout
    x = np.ascontiguousarray(positions, dtype=np.float64)
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
    if not box.is_orthogonal:
        return _pairs_sheared(x, box, cutoff)
    L = box.lengths
    if len(x) <= KDTREE_MAX_N:
        # Box.wrap keeps every coordinate in [0, L), as the periodic tree requires
        ij = cKDTree(box.wrap(x), boxsize=L).query_pairs(cutoff, output_type="ndarray")
        return _make(box, x, ij[:, 0], ij[:, 1])
    from ._cell_kernels import cell_pairs

    i, j, _ = cell_pairs(x, L, float(cutoff), np.empty(0), 0.0)
    return PairList(i, j, box.minimum_image(x[j] - x[i]))


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
        from ._cell_kernels import cell_pairs

        i, j, image = cell_pairs(x, L, reach, D, float(skin))
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
