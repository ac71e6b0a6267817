"""Placing long chains by a growth walk with rejection and backtracking (chains paper Sec. II F, Fig. 4).

A chain drawn whole (all bond directions first, then a random position) almost never
fits once it is long: its random walk crosses itself in 2D, overlaps placed spheres, or
spans half the box. The growth walk places it sphere by sphere instead: the first
sphere at a uniform point, each next one at its bond length from the last in a
direction of the chain's bond-angle rule (uniform angle in the range, or the given
one; in 2D a random turn sense, alternating where two frozen angles follow each other,
whose angle links would cross otherwise; in 3D a uniform torsion). A candidate is rejected
when it overlaps a placed sphere (with ``no_overlap``; spheres linked to it are
exempt), when its new links cross a placed link (2D, paper Fig. 3), or when the chain
would span half the smallest box width (it would meet its own periodic image). After
:data:`GROWTH_TRIES` rejected candidates the walk backtracks :data:`GROWTH_BACKTRACK`
spheres; after :data:`GROWTH_RESTARTS` restarts of the whole chain it gives up.
"""

from __future__ import annotations

from collections.abc import Callable
from math import pi

import numpy as np
from numpy.typing import NDArray

from ..box import Box
from ..tolerances import OVERLAP_TOL

__all__ = ["GROWTH_BACKTRACK", "GROWTH_RESTARTS", "GROWTH_TRIES", "grow_chain"]

#: Candidate directions tried for one sphere before the walk backtracks.
GROWTH_TRIES: int = 50
#: Spheres removed from the chain's end when a sphere finds no place.
GROWTH_BACKTRACK: int = 3
#: Restarts of a chain from a new first sphere before placement gives up (each restart
#: allows ``10 m`` backtracks), so an impossible request fails in minutes, not hours.
GROWTH_RESTARTS: int = 20


def _turn(u: NDArray[np.float64], angle: float, sense: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """The next bond direction at bond angle ``angle`` [rad] after direction ``u`` (as chain_offsets);
    in 2D turning in the sense ``sense`` (+1 or -1)."""
    turn = pi - angle
    if len(u) == 2:
        turn *= sense
        c, s = np.cos(turn), np.sin(turn)
        return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
    w = rng.normal(size=len(u))
    w -= (w @ u) * u
    w /= np.linalg.norm(w)
    return np.cos(turn) * u + np.sin(turn) * w


def _image(box: Box) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """The minimum image of ``box`` (the cubic boxes of the builders in one line)."""
    if not box.is_orthogonal:
        return box.minimum_image
    side = np.diag(box.matrix).copy()
    return lambda dx: dx - side * np.round(dx / side)


def _segments_cross(p: NDArray[np.float64], r: NDArray[np.float64], q: NDArray[np.float64],
                    w: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether segment ``p + t r`` crosses each segment ``q_k + s w_k`` (2D, ``0 < t, s < 1``), shape (K,)."""
    den = r[0] * w[:, 1] - r[1] * w[:, 0]
    pq = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (pq[:, 0] * w[:, 1] - pq[:, 1] * w[:, 0]) / den
        s = (pq[:, 0] * r[1] - pq[:, 1] * r[0]) / den
    return (den != 0.0) & (t > 0.0) & (t < 1.0) & (s > 0.0) & (s < 1.0)


def _fits(y: NDArray[np.float64], k: int, chain: NDArray[np.float64], own_d: NDArray[np.float64], placed: NDArray[np.float64],
          placed_d: NDArray[np.float64], segments: tuple[NDArray[np.float64], NDArray[np.float64]], box: Box,
          frozen: NDArray[np.bool_], no_overlap: bool, image: Callable) -> bool:
    """Whether sphere ``k`` of the chain at ``y`` (unwrapped) passes the tests of the module doc."""
    angle = k >= 2 and bool(frozen[k - 2])
    if k and np.max(np.sum((chain[:k] - y) ** 2, axis=1)) >= (0.5 * float(np.min(box.widths))) ** 2:
        return False
    if no_overlap:
        if len(placed):
            r = np.linalg.norm(image(placed - y), axis=1)
            if np.any(r < 0.5 * (placed_d + own_d[k]) * (1.0 - OVERLAP_TOL)):
                return False
        others = np.arange(k - (2 if angle else 1))
        if others.size:
            r = np.linalg.norm(chain[others] - y, axis=1)
            if np.any(r < 0.5 * (own_d[others] + own_d[k]) * (1.0 - OVERLAP_TOL)):
                return False
    if box.d == 2 and k:
        starts, vectors = segments
        # the chain's own earlier links as index pairs: bonds, then frozen angles
        bonds = np.arange(k - 1)
        angles = np.flatnonzero(frozen[: max(k - 2, 0)])
        a = np.concatenate([bonds, angles])
        b = np.concatenate([bonds + 1, angles + 2])
        for j in ([k - 1, k - 2] if angle else [k - 1]):
            p, v = chain[j], y - chain[j]
            if len(starts) and np.any(_segments_cross(p, v, p + image(starts - p), vectors)):
                return False
            rest = (a != j) & (b != j)  # links sharing the new link's sphere do not cross it
            if np.any(rest) and np.any(_segments_cross(p, v, chain[a[rest]], chain[b[rest]] - chain[a[rest]])):
                return False
    return True


def grow_chain(m: int, bonds: NDArray[np.float64], diameter: NDArray[np.float64], angle: float | None,
               angle_range: tuple[float, float], placed: NDArray[np.float64], placed_d: NDArray[np.float64],
               segments: tuple[NDArray[np.float64], NDArray[np.float64]], box: Box, frozen: NDArray[np.bool_],
               no_overlap: bool, rng: np.random.Generator) -> NDArray[np.float64] | None:
    """Centres (m, d) of one chain grown into the box beside ``placed`` spheres (module doc), or None.

    Parameters
    ----------
    bonds : ndarray, shape (m - 1,)
        Bond lengths [length].
    diameter : ndarray, shape (m,)
        The chain's diameters [length].
    angle : float or None
        Every bond angle [rad]; None: uniform in ``angle_range``.
    placed, placed_d : ndarray, shapes (P, d), (P,)
        Centres and diameters of the spheres placed before.
    segments : (ndarray, ndarray), shapes (S, 2), (S, 2)
        2D: start points and vectors of the placed links (unused in 3D).
    frozen : ndarray of bool, shape (m - 2,)
        Frozen bond angles (their angle links are links: exempt from overlaps, tested for crossings).

    Returns
    -------
    ndarray or None
        Unwrapped centres of the chain (wrap them into the box), None after
        :data:`GROWTH_RESTARTS` restarts.
    """
    d = box.d
    image = _image(box)
    chain = np.zeros((m, d))
    sense = np.zeros(m)
    for _ in range(GROWTH_RESTARTS):
        chain[0] = box.to_cartesian(rng.random(d))
        if not _fits(chain[0], 0, chain, diameter, placed, placed_d, segments, box, frozen, no_overlap, image):
            continue
        k, direction, budget = 1, [np.zeros(d)] * m, 10 * m
        while 0 < k < m and budget > 0:
            for _ in range(GROWTH_TRIES):
                if k == 1:
                    u = rng.normal(size=d)
                    u /= np.linalg.norm(u)
                else:
                    # 2D: two frozen angles in a row turning the same way would cross their angle links
                    zigzag = d == 2 and k >= 3 and frozen[k - 2] and frozen[k - 3]
                    sense[k] = -sense[k - 1] if zigzag else rng.choice((-1.0, 1.0))
                    u = _turn(direction[k - 1], angle if angle is not None else rng.uniform(*angle_range),
                              sense[k], rng)
                y = chain[k - 1] + bonds[k - 1] * u
                if _fits(y, k, chain, diameter, placed, placed_d, segments, box, frozen, no_overlap, image):
                    chain[k], direction[k] = y, u
                    k += 1
                    break
            else:
                budget -= 1
                k = max(1, k - GROWTH_BACKTRACK)
        if k == m:
            return chain
    return None
