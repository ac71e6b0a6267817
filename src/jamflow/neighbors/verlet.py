"""The one Verlet list: pairs within their contact distance plus a skin, with periodic images.

Every model and the event-driven dynamics keep their near pairs in a
:class:`NeighborList`. How a list's owner decides that it is still valid differs: a
minimiser compares the current positions with the build positions (:meth:`NeighborList.stale`),
an event-driven integrator bounds its next step in advance from the velocities
(:class:`jamflow.protocols.overdamped.skin.SkinBudget`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from . import _verlet_kernels
from .pairs import verlet_pairs

__all__ = ["SPHERE_SKIN", "SMALL_BOX_SKIN_SHARE", "DEFAULT_SKIN", "NeighborList"]


#: Verlet skin of sphere lists as a fraction of the mean diameter, by dimension (d > 3
#: takes the d = 3 value): pairs closer than ``sigma_ij + skin`` are listed, and the
#: list is rebuilt when displacements use up the skin. The skin changes no result (a
#: listed pair beyond contact adds nothing, and FIRE's state survives a rebuild), only
#: the split of time between pair loops and rebuilds
#: (measured: docs/notes/energy-models.md#constants-of-the-neighbour-search).
SPHERE_SKIN: dict[int, float] = {2: 0.15, 3: 0.3}


#: In a box too small for the requested skin (``max D + skin`` at or above half the
#: smallest width, e.g. a few shear-stabilised spheres compressed into a flattened box)
#: a build of a list without ``room_share`` uses this share of the room
#: ``min(widths) / 2 - max D`` instead: the list stays a minimum-image list, and since
#: the skin changes no minimiser's result, nothing else changes.
SMALL_BOX_SKIN_SHARE: float = 0.5


#: Verlet skin of the bounding-diameter lists of non-spherical models, as a fraction
#: of the mean bounding diameter (their pair kernels cost more per listed pair).
DEFAULT_SKIN: float = 0.15


class NeighborList:
    """Verlet list with a skin, in periodic and sheared boxes, built with ``verlet_pairs``.

    Stores each pair ``i < j`` (lexicographically sorted) with ``r < sigma_ij + skin``
    at build time together with its periodic image as integer lattice coordinates
    ``n``, so the pair vector at any later time is ``x_j - x_i + h n`` for the current
    box ``h`` (positions are kept unwrapped between builds). For a minimiser the list
    stays valid while ``u1 + u2 + ||A - 1|| (D_max + skin) < skin``, with ``u1 >= u2``
    the two largest non-affine displacements since the build and ``A = h h_build^-1``
    the box deformation (:meth:`stale`,
    :func:`jamflow.neighbors._verlet_kernels._needs_rebuild`).

    Parameters
    ----------
    diameter : array_like, shape (N,)
        Diameters [length]; the contact distance of a pair is ``(D_i + D_j) / 2``.
    skin : float, optional
        Requested skin [length]; default :data:`SPHERE_SKIN` of the dimension of each
        build times the mean diameter.
    room_share : float, optional
        If given, every build caps the skin at this share of the room
        ``min(widths) / 2 - max D`` (the event-driven integrator, whose skin is part of
        its trajectory). Otherwise the requested skin is kept whenever it fits below the
        room, and a box too small for it gets :data:`SMALL_BOX_SKIN_SHARE` of the room.

    Attributes
    ----------
    i, j : ndarray of int64, shape (P,)
        Listed pairs, ``i < j``, lexicographically sorted.
    image : ndarray of float64, shape (P, d)
        Integer-valued lattice coordinates ``n`` of each pair's image.
    sigma : ndarray, shape (P,)
        Contact distances ``(D_i + D_j) / 2`` [length].
    skin, reach : float
        Skin and cutoff ``reach = max D + skin`` of the last build [length]; the skin
        is the difference ``reach - max D`` as computed, so that the two agree
        exactly in floating point.
    x_build : ndarray, shape (N, d)
        Positions of the last build [length].
    h_build : ndarray, shape (d, d)
        Box matrix of the last build [length].
    builds : int
        Lists made so far.
    """

    def __init__(self, diameter: ArrayLike, skin: float | None = None, room_share: float | None = None) -> None:
        self.diameter = np.asarray(diameter, dtype=np.float64)
        self.requested_skin = np.nan if skin is None else float(skin)
        if skin is not None and not self.requested_skin > 0.0:
            raise ValueError(f"skin must be positive, got {self.requested_skin}")
        if room_share is not None and not 0.0 < room_share < 1.0:
            raise ValueError(f"room_share must lie in (0, 1), got {room_share}")
        self.room_share = room_share
        self.skin = self.requested_skin
        self.reach = float(self.diameter.max()) + self.skin
        self.builds = 0
        self.i = self.j = np.empty(0, np.int64)
        self.image = np.empty((0, 0))
        self.sigma = np.empty(0)
        self.x_build = np.empty((0, 0))
        self.h_build = np.empty((0, 0))
        self._pairs: NDArray[np.int64] | None = None

    def build(self, x: NDArray[np.float64], box: Box) -> None:
        """(Re)build the list for positions ``x`` (N, d) in ``box``.

        Raises
        ------
        ValueError
            If the largest diameter reaches half the smallest box width (no skin fits).
        """
        skin = self.requested_skin
        if np.isnan(skin):
            skin = SPHERE_SKIN.get(box.d, SPHERE_SKIN[3]) * float(self.diameter.mean())
        d_max = float(self.diameter.max())
        room = 0.5 * float(np.min(box.widths)) - d_max
        if self.room_share is not None:
            skin = min(skin, self.room_share * room)
        elif skin >= room:
            skin = SMALL_BOX_SKIN_SHARE * room
        reach = d_max + skin
        if not reach > d_max:
            raise ValueError(f"box too small for the largest particles: max diameter {d_max:.6g} leaves no skin "
                             f"below half the smallest box width ({0.5 * float(np.min(box.widths)):.6g})")
        self.reach = reach
        self.skin = reach - d_max
        self.adopt(*verlet_pairs(x, box, self.diameter, self.skin), x, box)

    def smallest_scale(self, box: Box) -> float:
        """The factor at or below which ``box`` scaled by it holds no list (:meth:`build` refuses it).

        Half the scaled box's smallest width is then at most the largest diameter, so no
        skin fits and a sphere may meet two images of another.
        """
        return 2.0 * float(self.diameter.max()) / float(np.min(box.widths))

    def adopt(self, i: NDArray[np.int64], j: NDArray[np.int64], image: NDArray[np.float64], x: NDArray[np.float64],
              box: Box, builds: int = 1) -> None:
        """Take a list built elsewhere with this skin (e.g. inside a compiled FIRE loop) at ``x`` in ``box``.

        ``i, j`` (P,) and ``image`` (P, d) as :func:`jamflow.neighbors.pairs.verlet_pairs`
        returns them; ``builds`` counts the lists made since this object's last one.
        """
        self.i, self.j, self.image = i, j, image
        self._pairs = None
        self.sigma = 0.5 * (self.diameter[self.i] + self.diameter[self.j])
        self.x_build = np.array(x, dtype=np.float64)
        self.h_build = np.array(box.matrix)
        self.builds += builds

    def restore(self, i: NDArray[np.int64], j: NDArray[np.int64], image: NDArray[np.float64], x: NDArray[np.float64],
                box: Box, skin: float, reach: float) -> None:
        """Take a saved list (a checkpoint) built at ``x`` in ``box`` with ``skin`` and ``reach`` [length]."""
        if not (0.0 < skin and reach > float(self.diameter.max())):
            raise ValueError(f"a saved list needs a positive skin and a reach beyond max D, got {skin}, {reach}")
        self.skin, self.reach = float(skin), float(reach)
        self.adopt(np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64),
                   np.ascontiguousarray(image, dtype=np.float64), x, box)

    @property
    def pairs(self) -> NDArray[np.int64]:
        """Listed pairs as rows ``(i, j)``, shape (P, 2) (made once per build; do not modify)."""
        if self._pairs is None:
            self._pairs = np.stack([self.i, self.j], axis=1).astype(np.int64, copy=False)
        return self._pairs

    def index_of(self, pairs: ArrayLike) -> NDArray[np.int64]:
        """Positions of ``pairs`` (rows ``i < j``, shape (k, 2)) in the list, shape (k,); -1 where absent."""
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        n = len(self.diameter)
        key = self.i * n + self.j
        q = pairs[:, 0] * n + pairs[:, 1]
        if not len(key):
            return np.full(len(q), -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(key, q), len(key) - 1)
        return np.where(key[pos] == q, pos, -1)

    def offsets(self, box: Box) -> NDArray[np.float64]:
        """Image offsets ``h n`` of every listed pair for ``box``, shape (P, d) [length]."""
        return self.image @ box.matrix.T

    def affine_reference(self, box: Box) -> tuple[NDArray[np.float64], float]:
        """Build-time positions mapped affinely into ``box``, and the deformation slack.

        Returns ``(x_build A^T, ||A - 1||_2 (D_max + skin))`` with ``A = h h_build^-1``.
        """
        if np.array_equal(box.matrix, self.h_build):
            # the box of the build (every fixed-box run): A = 1 exactly, no inverse or SVD
            return self.x_build, 0.0
        deform = box.matrix @ np.linalg.inv(self.h_build)
        slack = float(np.linalg.norm(deform - np.eye(box.d), 2)) * self.reach
        return self.x_build @ deform.T, slack

    def stale(self, x: NDArray[np.float64], box: Box) -> bool:
        """Whether the list may miss a pair (never built, or skin used up)."""
        if self.x_build.shape != np.shape(x):
            return True
        affine, slack = self.affine_reference(box)
        return bool(_verlet_kernels._needs_rebuild(np.asarray(x, dtype=np.float64), affine, 1.0, 1.0, self.reach,
                                            self.skin, slack))

    def update(self, x: NDArray[np.float64], box: Box) -> None:
        """Rebuild only when :meth:`stale`."""
        if self.stale(x, box):
            self.build(x, box)
