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
from scipy.special import betainc

from ...box import Box
from ...neighbors.pairs import PairList, pairs_within
from ...neighbors.verlet import NeighborList
from . import _kernels

__all__ = ["HARMONIC", "Evaluation", "PowerLawPotential", "energy_floor", "evaluate", "max_contacts",
           "overlapping_pairs"]


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


def max_contacts(d: int, diameter: ArrayLike, overlap: float = 0.0) -> int:
    """An upper bound on the overlapping pairs of ``N`` spheres whose relative overlaps are at most ``overlap``.

    Seen from a sphere, two of its neighbours are at least ``sigma_min (1 - overlap)``
    apart and at most ``(D_max + D_min) / 2`` away, so their directions differ by at
    least ``2 beta`` with ``sin beta = sigma_min (1 - overlap) / (D_max + D_min)``: caps of
    angular radius ``beta`` around them do not overlap on the unit sphere ``S^(d-1)``, whose
    area they share (a cap covers ``I_(sin^2 beta)((d - 1) / 2, 1 / 2) / 2`` of it). Each sphere
    then has at most ``z = ceil(1 / that share)`` neighbours (d = 3, size ratio 1.4: 22), and the
    pairs number at most ``N z / 2``.

    Parameters
    ----------
    d : int
    diameter : array_like, shape (N,)
        Diameters [length].
    overlap : float
        Largest relative overlap ``1 - r / sigma_ij`` of a pair, in [0, 1).
    """
    diameter = np.asarray(diameter, dtype=np.float64)
    if not 0.0 <= overlap < 1.0:
        raise ValueError(f"overlap must lie in [0, 1), got {overlap}")
    small, large = float(diameter.min()), float(diameter.max())
    beta = np.arcsin(small * (1.0 - overlap) / (large + small))
    share = 0.5 * betainc(0.5 * (d - 1), 0.5, np.sin(beta) ** 2)
    # ceil, not floor: equality (six touching disks around one) must not round down
    return int(len(diameter) * np.ceil(1.0 / share) // 2)


def energy_floor(potential: PowerLawPotential, diameter: ArrayLike, volume: float, d: int, pressure: float,
                 lever: float = 1.0) -> float:
    """An energy [epsilon] below which no force-balanced state has a virial pressure of ``pressure`` or more.

    Every contact carries ``f r <= epsilon xi^(w - 1)``; for bodies, whose link tensions
    enter the virial, a contact's lever arm ``r`` is replaced at force balance by the
    distance of the two bodies' centroids, at most ``lever`` times the contact distance.
    With ``n`` contacts (:func:`max_contacts`) Hölder's inequality gives
    ``sum xi^(w-1) <= n^(1/w) (w U / epsilon)^(1 - 1/w)``, so
    ``P <= lever epsilon n^(1/w) (w U / epsilon)^(1 - 1/w) / (d V)``. The returned energy
    makes that bound equal to ``pressure``; the largest overlap it allows sets ``n``
    (0 when it would allow overlaps of a whole diameter).

    Parameters
    ----------
    potential : PowerLawPotential
    diameter : array_like, shape (N,)
        Diameters [length].
    volume : float
        Box volume [length^d].
    d : int
    pressure : float
        The pressure to stay below [epsilon / length^d], > 0.
    lever : float
        Largest ratio of a contact's lever arm in the virial to its contact distance (>= 1).
    """
    if not pressure > 0.0 or not lever >= 1.0:
        raise ValueError(f"pressure must be > 0 and lever >= 1, got {pressure}, {lever}")
    eps, w = potential.epsilon, potential.exponent
    overlap = 0.0
    # the floor shrinks as the contact bound grows, so the overlap of the first pass bounds the second's
    for _ in range(2):
        n = max(max_contacts(d, diameter, overlap), 1)
        floor = eps / w * (pressure * d * volume / (lever * eps * n ** (1.0 / w))) ** (w / (w - 1.0))
        overlap = (w * floor / eps) ** (1.0 / w)
        if overlap >= 1.0:
            # spheres could pass through each other: no bound on the contacts, no floor
            return 0.0
    return float(floor)


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
