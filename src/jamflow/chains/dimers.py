"""Asymmetric dimers: rigid unions of two spheres of different diameters (van der Werf et al. Sec. II, Fig. 3b).

A dimer is a small monomer of diameter ``D_s`` and a large one of diameter
``r D_s`` whose centres are a distance ``l`` apart, held by one link; the monomers
overlap when ``l < (1 + r) D_s / 2``. The paper's dimers (Table I, Fig. 3b) have the
monomer diameter ratio ``r = 1.4`` and the separation ``l = D_s`` (its
``alpha - 1 = 0.571`` and ``A - 1 = 0.349`` fix ``l``: :func:`dimer_aspect_ratio`,
:func:`dimer_asphericity`); the bidisperse mixture is half small and half large
dimers, the large ones the small ones scaled by 1.4 (area ratio 1.4^2), all with the
same mass. Monomers of different dimers interact by the sphere potential at
``r_ij`` against ``sigma_ij`` (the sum of their radii), monomers of one dimer do not.

Counting (the paper's Fig. 3b): a dimer is a rigid body with ``f = d m - L = 2 d - 1``
degrees of freedom (3 in 2D, 5 in 3D, where the turn about its axis is no degree of
freedom), so a jammed packing of ``N'`` non-rattling dimers in a fixed box is isostatic
with ``N_c = f N' - (d - 1) N_rot - d + 1`` contacts (2D: ``3 N' - 1 - N_rot``), where a
**rotator** is a dimer held only through one monomer (its other monomer touches
nothing): it keeps ``d - 1`` free rotations about the held monomer's centre. In the
counting of :mod:`jamflow.network.bodies` these are the dimer's free motions
(``m = d - 1``, the free monomer a dangler), which gives exactly this count; a
rattling dimer is a cluster that rattles whole. :func:`dimer_counting` names the rotators and gives
``<z>`` of the paper's Eq. 3 (2D) and its d-dimensional form, with a rotator counted as
the fraction ``(f - d + 1) / f`` of a particle that is held (like a slider in 2D, a
third missing), so an isostatic dimer packing has ``<z> = 2 f``: 6 in 2D, 10 in 3D.
"""

from __future__ import annotations

from math import acos, pi

import numpy as np

from ..network import BodyCount
from ..state.packing import lens_volume

__all__ = [
    "DIMER_DIAMETER_RATIO",
    "DIMER_SEPARATION",
    "DIMER_SIZE_RATIO",
    "check_dimer",
    "dimer_aspect_ratio",
    "dimer_asphericity",
    "dimer_counting",
    "dimer_perimeter_area",
    "dimer_report",
]

#: Diameter of the large monomer over the small one's, ``r`` (paper Fig. 3b).
DIMER_DIAMETER_RATIO: float = 1.4
#: Centre separation of the monomers in units of the small monomer's diameter (paper
#: Table I: ``alpha - 1 = 0.571``, ``A - 1 = 0.349``).
DIMER_SEPARATION: float = 1.0
#: Length ratio of large to small dimers (area ratio its square, paper Sec. II).
DIMER_SIZE_RATIO: float = 1.4


def check_dimer(diameter_ratio: float, separation: float) -> None:
    """Refuse a dimer that is not two overlapping or touching monomers, neither inside the other.

    ``separation`` is in units of the small monomer's diameter.
    """
    if not (np.isfinite(diameter_ratio) and diameter_ratio >= 1.0):
        raise ValueError(f"dimer diameter ratio (large over small monomer) must be >= 1, got {diameter_ratio}")
    lo, hi = 0.5 * (diameter_ratio - 1.0), 0.5 * (diameter_ratio + 1.0)
    if not (np.isfinite(separation) and lo < separation <= hi):
        raise ValueError(f"dimer separation must lie in ({lo:.6g}, {hi:.6g}] small-monomer diameters (monomers "
                         f"overlapping or touching, neither inside the other) for diameter ratio {diameter_ratio}, "
                         f"got {separation}")


def dimer_perimeter_area(r1: float, r2: float, separation: float) -> tuple[float, float]:
    """Exact perimeter and area of the union of two disks of radii ``r1``, ``r2`` at a centre distance.

    The boundary is the two circles outside their lens: arcs of ``2 (pi - theta_k)``
    with ``cos theta_1 = (l^2 + r1^2 - r2^2) / (2 l r1)``; the area is the two disks
    minus their lens (:func:`~jamflow.state.packing.lens_volume`).

    Returns
    -------
    perimeter : float
        [length].
    area : float
        [length^2].
    """
    if not (np.isfinite(r1) and np.isfinite(r2) and r1 > 0.0 and r2 > 0.0):
        raise ValueError(f"dimer monomer radii must be positive and finite, got {r1}, {r2}")
    lo, hi = min(r1, r2), max(r1, r2)
    check_dimer(hi / lo, separation / (2.0 * lo))
    l = separation
    t1 = acos(min(1.0, (l * l + r1 * r1 - r2 * r2) / (2.0 * l * r1)))
    t2 = acos(min(1.0, (l * l + r2 * r2 - r1 * r1) / (2.0 * l * r2)))
    perimeter = 2.0 * r1 * (pi - t1) + 2.0 * r2 * (pi - t2)
    return perimeter, float(pi * (r1 * r1 + r2 * r2) - lens_volume(2, 2.0 * r1, 2.0 * r2, l))


def dimer_asphericity(diameter_ratio: float = DIMER_DIAMETER_RATIO, separation: float = DIMER_SEPARATION) -> float:
    """Asphericity ``A = p^2 / (4 pi a)`` of a dimer (exact, :func:`dimer_perimeter_area`); scale free."""
    check_dimer(diameter_ratio, separation)
    p, a = dimer_perimeter_area(0.5, 0.5 * diameter_ratio, separation)
    return p * p / (4.0 * pi * a)


def dimer_aspect_ratio(diameter_ratio: float = DIMER_DIAMETER_RATIO, separation: float = DIMER_SEPARATION) -> float:
    """Length over width of a dimer, ``alpha = (l + (1 + r) / 2) / r`` in small-monomer diameters."""
    check_dimer(diameter_ratio, separation)
    return (separation + 0.5 * (1.0 + diameter_ratio)) / diameter_ratio


def dimer_counting(count: BodyCount, d: int = 2) -> dict:
    """Rotators and ``<z>`` (Eq. 3, rotators counted in part) of a dimer packing in d dimensions (module doc).

    Parameters
    ----------
    count : BodyCount
        Fixed-box count of the packing (:func:`jamflow.network.count_bodies`), whose clusters
        are dimers (two spheres each).
    d : int
        Dimension.

    Returns
    -------
    dict
        ``n_dimers``, ``n_rotators`` (dimers in the backbone with free motions: one monomer
        a dangler), ``n_rattling_dimers`` (dimers that rattle whole) and ``z``
        (``2 (N_c + d - 1) / (N - N_r - N_rot (d - 1) / f)`` with ``f = 2 d - 1``; in 2D
        the paper's ``2 (N_c + 1) / (N - N_r - N_rot / 3)``; NaN when every dimer rattles).
    """
    sizes = np.bincount(count.cluster)
    if np.any(sizes != 2):
        raise ValueError(f"a dimer packing has clusters of two spheres, found sizes {sorted(set(sizes.tolist()))}")
    n, n_rot, n_rat = sizes.size, int(np.sum(count.free_dofs > 0)), int(np.sum(count.removed))
    f = 2 * d - 1
    held = n - n_rat - n_rot * (d - 1) / f
    z = 2.0 * (count.n_contacts + d - 1) / held if held > 0 else float("nan")
    return {"n_dimers": n, "n_rotators": n_rot, "n_rattling_dimers": n_rat, "z": z}


def dimer_report(count: BodyCount, d: int) -> dict:
    """:func:`dimer_counting` for a packing whose clusters are all dimers, else an empty dict."""
    if count.cluster.size == 0 or np.any(np.bincount(count.cluster) != 2):
        return {}
    return dimer_counting(count, d)
