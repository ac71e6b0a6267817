"""Soft repulsive contact potentials, their forces and stresses, and a Verlet list.

Convention
----------
A pair ``(i, j)`` at centre distance ``r`` with contact distance
``sigma_ij = (D_i + D_j) / 2`` has the *relative* overlap ``xi = 1 - r / sigma_ij``
(O'Hern et al. 2003; Lerner et al. Eq. 32 with their radii ``d_i + d_j = sigma_ij``)
and the energy

    V(r) = (epsilon / w) xi^w   for xi > 0,   0 otherwise,

so the total energy is ``U = (epsilon / w) sum_{xi > 0} xi^w``. ``w = 2`` is the
one-sided harmonic spring, ``w = 5/2`` Hertz. The energy unit is ``epsilon`` (the
spring constant of the harmonic case in units of ``epsilon / sigma_ij^2``); lengths
are those of the packing. Lerner et al.'s Eq. 32 ``epsilon_L xi^2`` is ``w = 2`` with
``epsilon = 2 epsilon_L``.

The repulsive pair force magnitude is ``f = -dV/dr = (epsilon / sigma_ij) xi^(w-1)``
[energy / length]. The stress tensor (Lerner et al. Eq. 30 sign, Allen & Tildesley)
is ``sigma_ab = -(1/V) sum_pairs f r_a r_b / r`` [energy / length^d], so the shear
stress ``sigma_xy = (1/V) dU/dgamma`` is positive when the packing resists a
positive Lees–Edwards strain, and the pressure is
``P = -tr(sigma) / d = (1/(d V)) sum_pairs f r`` (Eq. 24).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..neighbors import PairList, pairs_within, verlet_pairs
from . import _kernels

__all__ = [
    "DEFAULT_SKIN",
    "SMALL_BOX_SKIN_SHARE",
    "SPHERE_SKIN",
    "HARMONIC",
    "Evaluation",
    "NeighborList",
    "PowerLawPotential",
    "evaluate",
    "overlapping_pairs",
]

#: Verlet skin of sphere lists as a fraction of the mean diameter, by dimension (d > 3
#: takes the d = 3 value): pairs closer than ``sigma_ij + skin`` are listed, and the
#: list is rebuilt when displacements use up the skin. The skin changes no result (a
#: listed pair beyond contact adds nothing, and FIRE's state survives a rebuild), only
#: the split of time between pair loops and rebuilds. Measured with FIRE, CPU time
#: (docs/energy-models.md, "Neighbour rebuilds, third pass"): in 3D N = 4096 0.3 cuts
#: the rebuild share from 6.9 % to 2.5 % at an unchanged time per evaluation; in 2D a
#: larger skin helps N = 1024 (-4 %) but costs N = 16384 8-10 % per evaluation.
SPHERE_SKIN: dict[int, float] = {2: 0.15, 3: 0.3}
#: In a box too small for the skin (``max D + skin`` at or above half the smallest
#: width, e.g. a few shear-stabilised spheres compressed into a flattened box) a build
#: uses this share of the room ``min(widths) / 2 - max D`` instead: the list stays a
#: minimum-image list, and since the skin changes no result, nothing else changes.
SMALL_BOX_SKIN_SHARE: float = 0.5
#: Verlet skin of the bounding-diameter lists of non-spherical models, as a fraction
#: of the mean bounding diameter (their pair kernels cost more per listed pair).
DEFAULT_SKIN: float = 0.15


@dataclass(frozen=True)
class PowerLawPotential:
    """``V = (epsilon / w) (1 - r / sigma_ij)^w`` for overlapping pairs (see module doc).

    Attributes
    ----------
    epsilon : float
        Energy scale [energy], > 0.
    exponent : float
        ``w``; 2 = harmonic, 2.5 = Hertz. Must be >= 2 for a finite Hessian at contact.
    """

    epsilon: float = 1.0
    exponent: float = 2.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.epsilon) and self.epsilon > 0.0):
            raise ValueError(f"epsilon must be positive, got {self.epsilon}")
        if not (np.isfinite(self.exponent) and self.exponent > 1.0):
            raise ValueError(f"exponent w must be > 1, got {self.exponent}")

    def energy(self, xi: ArrayLike) -> NDArray[np.float64]:
        """Pair energies for relative overlaps ``xi`` (zero where ``xi <= 0``) [energy]."""
        xi = np.maximum(np.asarray(xi, dtype=np.float64), 0.0)
        return self.epsilon / self.exponent * xi**self.exponent

    def force(self, xi: ArrayLike, sigma: ArrayLike) -> NDArray[np.float64]:
        """Repulsive force magnitudes ``-dV/dr`` [energy / length]."""
        xi = np.maximum(np.asarray(xi, dtype=np.float64), 0.0)
        return self.epsilon * xi ** (self.exponent - 1.0) / np.asarray(sigma)

    def stiffness(self, xi: ArrayLike, sigma: ArrayLike) -> NDArray[np.float64]:
        """Second derivatives ``d^2V/dr^2`` [energy / length^2] (zero where ``xi <= 0``)."""
        xi = np.asarray(xi, dtype=np.float64)
        w = self.exponent
        out = np.zeros_like(xi)
        pos = xi > 0.0
        out[pos] = self.epsilon * (w - 1.0) * xi[pos] ** (w - 2.0) / np.asarray(sigma)[pos] ** 2
        return out


#: The one-sided harmonic potential with ``epsilon = 1`` (the default everywhere).
HARMONIC = PowerLawPotential()


class NeighborList:
    """Verlet list with a skin, in periodic and sheared boxes, built with ``verlet_pairs``.

    Stores each pair ``i < j`` with ``r < sigma_ij + skin`` at build time together with
    its periodic image as integer lattice coordinates ``n``, so the pair vector at any
    later time is ``x_j - x_i + h n`` for the current box ``h`` (positions are kept
    unwrapped between builds). The list stays valid while
    ``u1 + u2 + ||A - 1|| (D_max + skin) < skin``, with ``u1 >= u2`` the two largest
    non-affine displacements since the build and ``A = h h_build^-1`` the box
    deformation (:func:`jamflow.soft._kernels._needs_rebuild`).

    Parameters
    ----------
    diameter : array_like, shape (N,)
        Diameters [length].
    skin : float, optional
        Skin [length]; default :data:`SPHERE_SKIN` of the dimension of the first build
        times the mean diameter. A build in a box too small for it uses
        :data:`SMALL_BOX_SKIN_SHARE` of the room left; ``skin`` and ``reach`` are those
        of the last build.
    """

    def __init__(self, diameter: ArrayLike, skin: float | None = None) -> None:
        self.diameter = np.asarray(diameter, dtype=np.float64)
        self.requested_skin = np.nan if skin is None else float(skin)
        if skin is not None and not self.requested_skin > 0.0:
            raise ValueError(f"skin must be positive, got {self.requested_skin}")
        self.skin = self.requested_skin
        self.reach = float(self.diameter.max()) + self.skin
        self.builds = 0
        self.i = self.j = np.empty(0, np.int64)
        self.image = np.empty((0, 0))
        self.sigma = np.empty(0)
        self.x_build = np.empty((0, 0))
        self.h_build = np.empty((0, 0))

    def build(self, x: NDArray[np.float64], box: Box) -> None:
        """(Re)build the list for positions ``x`` (N, d) in ``box``."""
        skin = self.requested_skin
        if np.isnan(skin):
            skin = SPHERE_SKIN.get(box.d, SPHERE_SKIN[3]) * float(self.diameter.mean())
        room = 0.5 * float(np.min(box.widths)) - float(self.diameter.max())
        if 0.0 < room <= skin:
            skin = SMALL_BOX_SKIN_SHARE * room
        self.skin = skin
        self.reach = float(self.diameter.max()) + skin
        self.adopt(*verlet_pairs(x, box, self.diameter, self.skin), x, box)

    def adopt(self, i: NDArray[np.int64], j: NDArray[np.int64], image: NDArray[np.float64], x: NDArray[np.float64],
              box: Box, builds: int = 1) -> None:
        """Take a list built elsewhere with this skin (e.g. inside a compiled FIRE loop) at ``x`` in ``box``.

        ``i, j`` (P,) and ``image`` (P, d) as :func:`jamflow.neighbors.verlet_pairs`
        returns them; ``builds`` counts the lists made since this object's last one.
        """
        self.i, self.j, self.image = i, j, image
        self.sigma = 0.5 * (self.diameter[self.i] + self.diameter[self.j])
        self.x_build = np.array(x, dtype=np.float64)
        self.h_build = np.array(box.matrix)
        self.builds += builds

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
        return bool(_kernels._needs_rebuild(np.asarray(x, dtype=np.float64), affine, 1.0, 1.0, self.reach,
                                            self.skin, slack))

    def update(self, x: NDArray[np.float64], box: Box) -> None:
        """Rebuild only when :meth:`stale`."""
        if self.stale(x, box):
            self.build(x, box)


@dataclass(frozen=True)
class Evaluation:
    """Energy, forces and stress of a configuration.

    Attributes
    ----------
    energy : float
        Total energy U [energy].
    force : ndarray, shape (N, d)
        ``-dU/dx`` [energy / length].
    stress : ndarray, shape (d, d)
        ``-(1/V) sum f r_a r_b / r`` [energy / length^d].
    pressure : float
        ``-tr(stress) / d`` [energy / length^d].
    n_contacts : int
        Number of overlapping pairs.
    volume : float
        Box volume [length^d].
    virial : ndarray, shape (d, d)
        ``sum f r_a r_b / r`` [energy] (``stress = -virial / volume``).
    """

    energy: float
    force: NDArray[np.float64]
    stress: NDArray[np.float64]
    pressure: float
    n_contacts: int
    volume: float
    virial: NDArray[np.float64]

    @property
    def shear_stress(self) -> float:
        """``stress[0, 1]``: the Lees–Edwards shear stress (flow 0, gradient 1)."""
        return float(self.stress[0, 1])

    @property
    def max_force(self) -> float:
        """Largest per-particle force norm [energy / length]."""
        return float(np.sqrt(np.max(np.sum(self.force**2, axis=1))))


def evaluate(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    nlist: NeighborList | None = None,
) -> Evaluation:
    """Energy, forces, stress tensor and pressure (see the module doc for conventions).

    Parameters
    ----------
    x : array_like, shape (N, d)
        Centres [length], wrapped or not.
    box : Box
        Periodic, possibly sheared box.
    diameter : array_like, shape (N,)
    potential : PowerLawPotential
    nlist : NeighborList, optional
        Reused (and rebuilt only when stale) if given.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    if nlist is None:
        nlist = NeighborList(diameter)
    nlist.update(x, box)
    force = np.zeros_like(x)
    virial = np.zeros((box.d, box.d))
    energy, n_contacts = _kernels.pair_forces(
        x, 1.0, nlist.offsets(box), nlist.i, nlist.j, nlist.sigma,
        potential.epsilon, potential.exponent, force, virial,
    )
    volume = box.volume
    stress = -virial / volume
    return Evaluation(float(energy), force, stress, float(np.trace(virial) / (box.d * volume)),
                      int(n_contacts), volume, virial)


def overlapping_pairs(
    x: ArrayLike, box: Box, diameter: ArrayLike, potential: PowerLawPotential = HARMONIC
) -> tuple[PairList, NDArray[np.float64], NDArray[np.float64]]:
    """Overlapping pairs with their relative overlaps and repulsive force magnitudes.

    Returns
    -------
    pairs : PairList
        Pairs ``i < j`` with ``r < sigma_ij``.
    xi : ndarray, shape (P,)
        Relative overlaps ``1 - r / sigma_ij`` (> 0).
    force : ndarray, shape (P,)
        ``(epsilon / sigma_ij) xi^(w-1)`` [energy / length].
    """
    x = np.asarray(x, dtype=np.float64)
    D = np.asarray(diameter, dtype=np.float64)
    pairs = pairs_within(x, box, float(D.max()))
    sigma = 0.5 * (D[pairs.i] + D[pairs.j])
    xi = 1.0 - pairs.distance / sigma
    keep = xi > 0.0
    pairs = pairs.select(keep)
    return pairs, xi[keep], potential.force(xi[keep], sigma[keep])
