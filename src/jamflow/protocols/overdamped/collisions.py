"""Next-collision prediction among non-contacting pairs (Sec. IV A, step i).

Within one integration step every particle moves on a straight line: its velocity is
``E x_i + U_i`` with constant non-affine part U and velocity gradient E, and the box
follows ``dh/dt = E h``, so a pair's separation with fixed periodic image m moves as
``R(t) = R0 + t W`` with ``W = E R0 + U_j - U_i`` exactly. Its collision time is the
smallest root of ``|R0 + t W|^2 = sigma^2`` — the ballistic prediction of
event-driven hard spheres (Allen & Tildesley), restricted to pairs not in contact.

Pairs come from the Verlet list of every model (:class:`jamflow.neighbors.verlet.NeighborList`,
pairs closer than ``sigma_ij + skin``, compiled cell list, O(N)); the list stays valid
while the largest possible change of any listed separation stays below the skin
(:class:`.skin.SkinBudget`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..._numba import njit
from ...box import Box
from ...neighbors.verlet import NeighborList

__all__ = ["FLOW_ROOM_SHARE", "next_collision", "build_neighbor_list", "images_of"]

#: Largest share of the room ``min(widths) / 2 - max D`` the integrator's list gives
#: its skin (:class:`~jamflow.neighbors.verlet.NeighborList` ``room_share``). Unlike a
#: minimiser's, the integrator's skin is part of its trajectory: a step cut short by
#: the list horizon (:meth:`.skin.SkinBudget.horizon`) ends on a rebuild.
FLOW_ROOM_SHARE: float = 0.9


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
    images: NDArray[np.float64],
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
    pairs : ndarray of int64, shape (P, 2)
        Listed pairs (:attr:`NeighborList.pairs`).
    images : ndarray, shape (P, d)
        Their fixed periodic images, integer-valued lattice vectors (:attr:`NeighborList.image`).
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


def images_of(x: NDArray[np.float64], h: NDArray[np.float64], pairs: NDArray[np.int64],
              dx: NDArray[np.float64]) -> NDArray[np.float64]:
    """Integer-valued lattice vectors m with ``dx = x_j - x_i + h m``, shape (P, d)."""
    raw = dx - (x[pairs[:, 1]] - x[pairs[:, 0]])
    return np.rint(raw @ np.linalg.inv(h).T)


def build_neighbor_list(x: NDArray[np.float64], box: Box, radius: NDArray[np.float64], skin: float) -> NeighborList:
    """The integrator's Verlet list: pairs closer than ``d_i + d_j + skin`` at ``x`` in ``box``.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Centres [lambda].
    box : Box
    radius : ndarray, shape (N,)
        Radii d_i [lambda] (contact at ``r_ij = d_i + d_j``).
    skin : float
        Requested skin [lambda]; at most :data:`FLOW_ROOM_SHARE` of the room left by
        the largest particles in ``box``.
    """
    nl = NeighborList(2.0 * np.asarray(radius, dtype=np.float64), skin, room_share=FLOW_ROOM_SHARE)
    nl.build(x, box)
    return nl
