"""Where the spheres live: a periodic box, or an orthogonal box whose faces are hard walls.

A wall is a body like a sphere: the row finder lists sphere-wall rows after the pair
rows, the matrix, the duals and the force balance treat both kinds of row alike, and a
wall contact counts like a pair contact. A wall face has the code ``2 * axis + side``
(:data:`LOWER` at 0, :data:`UPPER` at ``L_axis``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ...box import Box
from ...neighbors.pairs import pairs_within
from ...network import isostatic_count
from ...state.packing import Packing, max_overlap, near_pairs
from ...tolerances import CONTACT_GAP_TOL

#: Sides of a wall face code ``2 * axis + side``: the face at 0 and the face at ``L_axis``.
LOWER, UPPER = 0, 1

#: Room for one particle's face codes in a wall row's integer key (2 d faces, so d <= 32).
FACE_KEY_STRIDE: int = 64


def wall_key(particle: NDArray[np.int64], face: NDArray[np.int64]) -> NDArray[np.int64]:
    """One integer per sphere-wall pair ``(particle, face)``, distinct for distinct pairs."""
    return FACE_KEY_STRIDE * particle + face


#: Direct and minimum-image separations within this fraction of the box are the same
#: vector (round-off of a wrap), not a periodic image through a wall.
IMAGE_TOL: float = 1e-12


def _direct(dx_direct: NDArray[np.float64], dx_image: NDArray[np.float64], box: Box) -> NDArray[np.bool_]:
    """Pairs whose direct separation is their minimum image (no periodic image through a wall)."""
    return np.all(np.abs(dx_direct - dx_image) < IMAGE_TOL * box.lengths.max(), axis=1)


@dataclass(frozen=True)
class _Container:
    """A periodic box (``walls=False``) or an orthogonal box with hard walls on its faces:
    everything that differs between the two."""

    box: Box
    walls: bool

    @property
    def has_translation(self) -> bool:
        """Periodic: the global translation is a zero mode, removed by fixing one anchor
        particle; displacements are reported relative to the stable particles' mean."""
        return not self.walls

    def wrap(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Positions in the primary cell (between walls: unchanged)."""
        return x if self.walls else self.box.wrap(x)

    def displacement(self, dx: NDArray[np.float64]) -> NDArray[np.float64]:
        """Displacement vectors (minimum image in a periodic box)."""
        return dx if self.walls else self.box.minimum_image(dx)

    def pairs(self, x: NDArray[np.float64], cutoff: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Sphere pairs closer than ``cutoff`` [length]; between walls only direct ones."""
        pairs = pairs_within(x, self.box, cutoff)
        if not self.walls:
            return pairs.i, pairs.j
        keep = _direct(x[pairs.j] - x[pairs.i], pairs.dx, self.box)
        return pairs.i[keep], pairs.j[keep]

    def wall_bodies(self, x: NDArray[np.float64], D: NDArray[np.float64],
                    cutoff: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Sphere-wall rows within ``cutoff`` (centre-to-surface minus radius): particles
        and faces ``2 * axis + (0 lower, 1 upper)``; none in a periodic box."""
        if not self.walls:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        L = self.box.lengths
        pl, al = np.nonzero(x <= cutoff - 0.5 * D[:, None])
        pu, au = np.nonzero((L - x) <= cutoff - 0.5 * D[:, None])
        return (np.concatenate([pl, pu]).astype(np.int64),
                np.concatenate([2 * al + LOWER, 2 * au + UPPER]).astype(np.int64))

    def n_dof(self, d: int, n_stable: int) -> int:
        """Isostatic contact count: ``d (N_s - 1) + 1`` periodic, ``d N_s + 1`` between walls."""
        if self.walls:
            return d * n_stable + 1 if n_stable > 0 else 0
        return isostatic_count(n_stable, d, global_dofs=d)

    def packing(self, packing: Packing, x: NDArray[np.float64], D: NDArray[np.float64]) -> Packing:
        """``packing`` at positions ``x`` and diameters ``D``, without contacts."""
        return replace(packing, position=self.wrap(x), diameter=D, contacts=None, force=None, rattler=None)

    def max_overlap(self, p: Packing) -> float:
        """Largest relative overlap over ALL pairs (and walls), 0 if none."""
        if not self.walls:
            return max_overlap(p)[1]
        pairs, h = near_pairs(p, 0.0)
        if len(h):
            h = h[_direct(p.position[pairs.j] - p.position[pairs.i], pairs.dx, p.box)]
        ov = max(0.0, -float(h.min())) if len(h) else 0.0
        rad = 0.5 * p.diameter[:, None]
        wall_gap = np.minimum(p.position, p.box.lengths - p.position) / rad - 1.0
        return max(ov, -float(wall_gap.min()))

    def touching(self, p: Packing) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        """The geometric network: pairs (P, 2) and wall contacts (particles, faces) with
        relative gap at most :data:`~jamflow.tolerances.CONTACT_GAP_TOL`."""
        pairs, h = near_pairs(p, CONTACT_GAP_TOL)
        if not self.walls:
            return np.stack([pairs.i, pairs.j], axis=1), np.empty(0, np.int64), np.empty(0, np.int64)
        if len(h):
            pairs = pairs.select(_direct(p.position[pairs.j] - p.position[pairs.i], pairs.dx, p.box))
        rad = 0.5 * p.diameter[:, None]
        gap = np.stack([p.position / rad - 1.0, (p.box.lengths - p.position) / rad - 1.0], axis=2)  # (N, d, 2)
        wp, axis, side = np.nonzero(gap <= CONTACT_GAP_TOL)
        return np.stack([pairs.i, pairs.j], axis=1), wp.astype(np.int64), (2 * axis + side).astype(np.int64)

