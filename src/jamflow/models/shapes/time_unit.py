"""FIRE's time unit of elongated shapes: the curvature of their stiffest contact in the mass metric.

FIRE's steps are stable while ``dt omega_max`` stays below ~1 (``omega_max^2`` the largest
eigenvalue of the mass-weighted Hessian ``M^-1/2 H M^-1/2``); disks run at ``dt_max
omega_max = 0.76`` with the time unit ``sqrt(m / k)``. One contact of two disks has
curvature ``2 k / m`` in that metric (the relative coordinate, reduced mass ``m / 2``); a
contact of elongated bodies is stiffer: an ellipse's Perram–Wertheim overlap is measured
along the centre line, so a contact whose centre line grazes the bodies' long axes moves
by ``~ alpha / 2`` per unit of sideways displacement (``alpha`` the aspect ratio), and a
contact at the tip of a long body turns it with a lever of half its length against a
moment of inertia ``~ m (length / 2)^2 / 3``. :func:`contact_stiffness` is the largest
such curvature over the relative orientations and centre-line directions of two shapes,
in units of ``2 k / m``: 1 for disks. :attr:`ShapeModel.time_unit` is ``sqrt(m / (K k))`` with
``K`` that stiffness (circulo-lines: over the two terms of their end-end contact) where it
exceeds ``FREE_STIFFNESS`` (:mod:`.model`; docs/notes/shapes.md, "Aspect ratio 10: the time
unit of long bodies").
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from . import _kernels

__all__ = ["CONTACT_BISECTIONS", "SAMPLE_OVERLAP", "STIFFNESS_ANGLES", "contact_stiffness"]

#: Relative orientations (and, as many, centre-line directions) sampled per pair of shapes,
#: at half-steps of ``2 pi / STIFFNESS_ANGLES`` so that no sample is exactly parallel [1]:
#: the largest curvature of ellipses of aspect ratio 10 is 57.3, 78.9, 79.2 with 32, 64, 128
#: (docs/notes/shapes.md, "Aspect ratio 10: the time unit of long bodies").
STIFFNESS_ANGLES: int = 64

#: Overlap of a sampled contact over the sum of the two bounding radii [1]: the Hessian is
#: ``k (g g^T + delta d^2 delta)``, so its second term is of this relative order.
SAMPLE_OVERLAP: float = 1e-8

#: Halvings of the bisection for the touching distance along a direction [1]: it ends
#: within ``2^-36`` (1.5e-11) of the bounding radii, below :data:`SAMPLE_OVERLAP`.
CONTACT_BISECTIONS: int = 36


def contact_stiffness(code: int, params: NDArray[np.float64], gyration_squared: NDArray[np.float64],
                      bounding_radius: NDArray[np.float64], rotations: bool = True) -> float:
    """Largest mass-weighted curvature of one contact between two of the given shapes, in units of ``2 k / m``.

    Every pair of the shapes (each with itself too) is put at every one of
    ``STIFFNESS_ANGLES^2`` relative orientations and centre-line directions, touching with
    an overlap :data:`SAMPLE_OVERLAP` of their bounding radii (:func:`_touching`); the largest eigenvalue of
    ``M^-1/2 H M^-1/2`` of the pair's ``6 x 6`` Hessian (:func:`._kernels.pair_hessian_blocks`,
    masses ``m``, moments of inertia ``m gyration_squared``) is taken over all of them.

    Parameters
    ----------
    code : int
        Family code (:data:`._kernels.FAMILY_CODES`) of a family whose overlap grows
        monotonically as two bodies approach along a direction (convex shapes).
    params : ndarray, shape (S, P)
        Pair-kernel parameter rows of the shapes.
    gyration_squared, bounding_radius : ndarray, shape (S,)
        Squared radii of gyration [length^2] and bounding radii [length].
    rotations : bool
        False: frozen orientations (their rows and columns left out).

    Returns
    -------
    float
        ``max lambda m / (2 k)`` [1]; 1 for two disks.
    """
    p = np.ascontiguousarray(params, dtype=np.float64)
    g = np.ascontiguousarray(gyration_squared, dtype=np.float64)
    r = np.ascontiguousarray(bounding_radius, dtype=np.float64)
    return _stiffness(int(code), p.tobytes(), p.shape, g.tobytes(), r.tobytes(), bool(rotations))


@lru_cache(maxsize=64)
def _stiffness(code: int, params: bytes, shape: tuple[int, int], gyration: bytes, reach: bytes,
               rotations: bool) -> float:
    """:func:`contact_stiffness` on hashable arguments (a model is rebuilt at every box rescaling)."""
    p = np.frombuffer(params).reshape(shape)
    g = np.frombuffer(gyration)
    rb = np.frombuffer(reach)
    best = 0.0
    for a in range(len(g)):
        for b in range(a, len(g)):
            best = max(best, _pair_stiffness(code, p[a], p[b], g[a], g[b], rb[a] + rb[b], rotations))
    return best


def _pair_stiffness(code: int, pa: NDArray[np.float64], pb: NDArray[np.float64], ga: float, gb: float,
                    reach: float, rotations: bool) -> float:
    """Largest mass-weighted curvature of a contact of shapes ``pa`` (orientation 0) and ``pb``, in ``2 k / m``."""
    angles = 2.0 * np.pi * (np.arange(STIFFNESS_ANGLES) + 0.5) / STIFFNESS_ANGLES
    turn, direction = (t.ravel() for t in np.meshgrid(angles, angles, indexing="ij"))
    ns = turn.size
    i = 2 * np.arange(ns)
    j = i + 1
    theta = np.zeros(2 * ns)
    theta[j] = turn
    params = np.empty((2 * ns, pa.size))
    params[i] = pa
    params[j] = pb
    unit = np.column_stack([np.cos(direction), np.sin(direction)])
    touch = _touching(code, i, j, unit, theta, params, reach)
    dx = np.ascontiguousarray((touch - SAMPLE_OVERLAP * reach)[:, None] * unit)
    h = _kernels.pair_hessian_blocks(code, i, j, dx, theta, params, 1.0, _kernels.COMPLEX_STEP)
    rot = 1.0 if rotations else 0.0
    w = np.array([1.0, 1.0, rot / np.sqrt(ga), 1.0, 1.0, rot / np.sqrt(gb)])
    return float(np.linalg.eigvalsh(h * w[None, :, None] * w[None, None, :])[:, -1].max() / 2.0)


def _touching(code: int, i: NDArray[np.int64], j: NDArray[np.int64], unit: NDArray[np.float64],
              theta: NDArray[np.float64], params: NDArray[np.float64], reach: float) -> NDArray[np.float64]:
    """Centre distance at which each listed pair touches along its direction ``unit`` (P, 2) [length].

    Ellipses: ``U = (k / 2) (sigma - r)^2`` at any ``r < sigma``, so one evaluation at half the
    sum of the semi-minor axes (``sigma`` is at least that sum) gives ``sigma``. Other families: bisection on ``(0, reach)``, on
    which the overlap is an interval ``[0, r_c)`` (convex shapes; crossed circulo cores overlap),
    ending on the side without overlap.
    """
    if code == _kernels.ELLIPSE:
        r = 0.5 * (params[i, 1] + params[j, 1])  # semi-axes (a, b), a >= b
        energy = _kernels.pair_table(code, i, j, np.ascontiguousarray(r[:, None] * unit), theta, params, 1.0)[:, 0]
        return r + np.sqrt(2.0 * energy)
    inside, outside = np.zeros(len(i)), np.full(len(i), reach)
    for _ in range(CONTACT_BISECTIONS):
        mid = 0.5 * (inside + outside)
        dx = np.ascontiguousarray(mid[:, None] * unit)
        overlap = _kernels.pair_table(code, i, j, dx, theta, params, 1.0)[:, 0] > 0.0
        if code == _kernels.CIRCULO:
            apart = np.flatnonzero(~overlap)
            overlap[apart] = _kernels.circulo_crossed_pairs(i[apart], j[apart], dx[apart], theta, params)
        inside = np.where(overlap, mid, inside)
        outside = np.where(overlap, outside, mid)
    return outside
