"""Next-collision prediction among non-contacting pairs (Sec. IV A, step i).

Within one integration step every particle moves on a straight line: its velocity is
``E x_i + U_i`` with constant non-affine part U and velocity gradient E, and the box
follows ``dh/dt = E h``, so a pair's separation with fixed periodic image m moves as
``R(t) = R0 + t W`` with ``W = E R0 + U_j - U_i`` exactly. Its collision time is the
smallest root of ``|R0 + t W|^2 = sigma^2`` — the ballistic prediction of
event-driven hard spheres (Allen & Tildesley), restricted to pairs not in contact.

Pairs come from a Verlet list (``jamflow.neighbors.pairs.verlet_pairs``, the pair search of
the soft-sphere lists: compiled cell list, O(N)) with cutoff ``sigma_max + skin``; the
list stays valid while the largest possible change of any listed separation stays
below the skin (see :class:`NeighborList`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..._numba import njit
from ...box import Box
from ...neighbors.pairs import verlet_pairs
from .network import max_row_norm, spectral_norm

__all__ = ["next_collision", "NeighborList", "build_neighbor_list", "images_of"]


@njit(cache=True)
def _next_collision(x, h, pairs, images, sigma, skip, U, E, tmax):  # pragma: no cover - numba
    n_pairs = pairs.shape[0]
    d = x.shape[1]
    best = tmax
    best_k = -1
    R = np.empty(d)
    W = np.empty(d)
    for k in range(n_pairs):
        if skip[k]:
            continue
        i = np.uint64(pairs[k, 0])  # unsigned: no wraparound test per access
        j = np.uint64(pairs[k, 1])
        for a in range(d):
            s = x[j, a] - x[i, a]
            for b in range(d):
                s += h[a, b] * images[k, b]
            R[a] = s
        aa = 0.0
        bb = 0.0
        cc = 0.0
        for a in range(d):
            w = U[j, a] - U[i, a]
            for b in range(d):
                w += E[a, b] * R[b]
            W[a] = w
            aa += w * w
            bb += R[a] * w
            cc += R[a] * R[a]
        cc -= sigma[k] * sigma[k]
        if bb >= 0.0:
            continue
        if cc <= 0.0:
            # at contact or overlapping by round-off and approaching: collides now
            return 0.0, k
        disc = bb * bb - aa * cc
        if disc < 0.0:
            continue
        # cc / (-bb + sqrt(disc)) is the smaller root without cancellation
        t = cc / (-bb + np.sqrt(disc))
        if t < best:
            best = t
            best_k = k
    return best, best_k


def next_collision(
    x: NDArray[np.float64],
    h: NDArray[np.float64],
    pairs: NDArray[np.int64],
    images: NDArray[np.int64],
    sigma: NDArray[np.float64],
    skip: NDArray[np.bool_],
    velocity: NDArray[np.float64],
    gradient: NDArray[np.float64],
    tmax: float,
) -> tuple[float, int]:
    """Earliest collision among listed pairs not skipped, before ``tmax``.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Centres [lambda].
    h : ndarray, shape (d, d)
        Box matrix [lambda].
    pairs, images : ndarray of int64, shapes (P, 2), (P, d)
        Neighbour list with fixed periodic images.
    sigma : ndarray, shape (P,)
        Contact distances [lambda].
    skip : ndarray of bool, shape (P,)
        Pairs in contact (not candidates for collision).
    velocity : ndarray, shape (N, d)
        Non-affine velocities U [lambda / time].
    gradient : ndarray, shape (d, d)
        Velocity gradient E [1 / time].
    tmax : float
        Horizon [time].

    Returns
    -------
    t : float
        Collision time (``tmax`` if none).
    k : int
        Index of the colliding pair in the list, -1 if none.
    """
    t, k = _next_collision(
        np.ascontiguousarray(x), np.ascontiguousarray(h), pairs, images, sigma, skip,
        np.ascontiguousarray(velocity), np.ascontiguousarray(gradient), float(tmax),
    )
    return float(t), int(k)


def images_of(x: NDArray[np.float64], h: NDArray[np.float64], pairs: NDArray[np.int64], dx: NDArray[np.float64]) -> NDArray[np.int64]:
    """Integer lattice vectors m with ``dx = x_j - x_i + h m``, shape (P, d)."""
    raw = dx - (x[pairs[:, 1]] - x[pairs[:, 0]])
    return np.rint(raw @ np.linalg.inv(h).T).astype(np.int64)


@dataclass
class NeighborList:
    """Verlet list of near pairs with fixed periodic images.

    Attributes
    ----------
    pairs : ndarray of int64, shape (P, 2)
        ``i < j``, lexicographically sorted.
    images : ndarray of int64, shape (P, d)
    sigma : ndarray, shape (P,)
        Contact distances ``d_i + d_j`` (radii) [lambda].
    cutoff : float
        List cutoff [lambda].
    skin : float
        ``cutoff - max sigma`` [lambda].
    displacement : ndarray, shape (N, d)
        Non-affine displacement accumulated since the build [lambda].
    strain_norm : float
        Accumulated ``integral |E|_2 dt`` since the build (affine change bound).
    """

    pairs: NDArray[np.int64]
    images: NDArray[np.int64]
    sigma: NDArray[np.float64]
    cutoff: float
    skin: float
    displacement: NDArray[np.float64]
    strain_norm: float = 0.0

    def advance(self, velocity: NDArray[np.float64], gradient: NDArray[np.float64], dt: float) -> None:
        """Account for one straight-line step of length ``dt``."""
        self.displacement += dt * velocity
        self.strain_norm += dt * spectral_norm(gradient)

    @property
    def valid(self) -> bool:
        """Whether every pair closer than sigma is still guaranteed to be listed."""
        move = 2.0 * max_row_norm(self.displacement)
        # an affine deformation of size a changes |R| <= cutoff by at most ~a * cutoff
        move += self.strain_norm * (1.0 + self.strain_norm) * self.cutoff
        return move < self.skin

    def index_of(self, pairs: NDArray[np.int64], n: int) -> NDArray[np.int64]:
        """Positions of ``pairs`` (rows i < j) in the list; -1 where absent."""
        key = self.pairs[:, 0] * n + self.pairs[:, 1]
        q = pairs[:, 0] * n + pairs[:, 1]
        pos = np.searchsorted(key, q)
        pos = np.minimum(pos, len(key) - 1) if len(key) else pos
        found = (len(key) > 0) & (key[pos] == q) if len(key) else np.zeros(len(q), bool)
        return np.where(found, pos, -1)


def build_neighbor_list(x: NDArray[np.float64], box: Box, radius: NDArray[np.float64], skin: float) -> NeighborList:
    """Verlet list of pairs closer than ``2 max(radius) + skin``.

    The skin is reduced if needed to keep the cutoff below half the smallest box width.
    """
    smax = 2.0 * float(radius.max())
    half = 0.5 * float(np.min(box.widths))
    cutoff = min(smax + skin, smax + 0.9 * (half - smax))
    if cutoff <= smax:
        raise ValueError("box too small for the largest particles (2 * diameter >= box width)")
    # every pair within the cutoff: the Verlet pairs of spheres all of diameter smax
    i, j, image = verlet_pairs(x, box, np.full(len(x), smax), cutoff - smax)
    pairs = np.stack([i, j], axis=1).astype(np.int64)
    images = image.astype(np.int64)
    sigma = radius[pairs[:, 0]] + radius[pairs[:, 1]]
    return NeighborList(pairs, images, sigma, cutoff, cutoff - smax, np.zeros_like(x))
