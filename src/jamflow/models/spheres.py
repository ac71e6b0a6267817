"""Soft repulsive spheres as an energy model: the first model, with the numbers of :mod:`jamflow.soft`.

Degrees of freedom are the centres ``x`` (N, d), flattened row-major; unit masses.
Energy, forces and virial come from :func:`jamflow.soft.potential.evaluate` (power-law
contact potential, Verlet list), so a model-generic minimiser sees exactly the numbers
of the sphere functions. The sphere minimisers keep their compiled loops
(:mod:`jamflow.soft._kernels`): :mod:`jamflow.soft.minimize` runs them for this model.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..soft.hessian import hessian
from ..soft.potential import HARMONIC, NeighborList, PowerLawPotential, evaluate
from .base import ModelEvaluation

__all__ = ["SphereBodies", "SphereModel"]


class SphereBodies:
    """Spheres with centres as their only degrees of freedom (unit masses), in a fixed box.

    The part of a sphere model that does not depend on how the spheres interact;
    :class:`SphereModel` and :class:`~jamflow.models.links.LinkedSpheresModel` share it.

    Parameters
    ----------
    box : Box
        Fixed periodic (possibly sheared) box.
    diameter : array_like, shape (N,)
        Diameters [length].
    potential : PowerLawPotential
        Contact potential [energy scale epsilon].
    nlist : NeighborList, optional
        Verlet list to (re)use; a new one by default.
    """

    def __init__(
        self,
        box: Box,
        diameter: ArrayLike,
        potential: PowerLawPotential = HARMONIC,
        nlist: NeighborList | None = None,
    ) -> None:
        self.box = box
        self.diameter = np.asarray(diameter, dtype=np.float64)
        self.potential = potential
        self.nlist = NeighborList(self.diameter) if nlist is None else nlist
        self.d = box.d
        self.n = len(self.diameter)
        self.n_dof = self.n * self.d
        self.inverse_mass = np.ones(self.n_dof)
        self.time_unit = float(self.diameter.mean()) / np.sqrt(potential.epsilon)

    @property
    def neighbor_builds(self) -> int:
        return self.nlist.builds

    def dofs(self, position: ArrayLike) -> NDArray[np.float64]:
        x = np.array(position, dtype=np.float64)
        if x.shape != (self.n, self.d):
            raise ValueError(f"position must have shape ({self.n}, {self.d}), got {x.shape}")
        return x.ravel()

    def positions(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return q.reshape(self.n, self.d)

    def max_force(self, g: NDArray[np.float64]) -> float:
        return float(np.sqrt(np.max(np.sum(g.reshape(self.n, self.d) ** 2, axis=1))))


class SphereModel(SphereBodies):
    """Soft spheres with a power-law contact potential (see :mod:`jamflow.soft.potential`).

    Parameters as :class:`SphereBodies`.
    """

    constrained = False

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        ev = evaluate(self.positions(q), self.box, self.diameter, self.potential, self.nlist)
        return ModelEvaluation(ev.energy, -ev.force.ravel(), ev.virial, ev.n_contacts)

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        return g

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return q

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        return hessian(self.positions(q), self.box, self.diameter, self.potential)

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple["SphereModel", NDArray[np.float64]]:
        """The model in the box scaled by ``factor`` (same neighbour list) and the centres moved affinely."""
        return SphereModel(self.box.scaled(factor), self.diameter, self.potential, self.nlist), position * factor
