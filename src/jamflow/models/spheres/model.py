"""Soft repulsive spheres as an energy model: the first model, with the numbers of :mod:`jamflow.minimize`.

Degrees of freedom are the centres ``x`` (N, d), flattened row-major; unit masses.
Energy, forces and virial come from :func:`jamflow.models.spheres.potential.evaluate` (power-law
contact potential, Verlet list), so a model-generic minimiser sees exactly the numbers
of the sphere functions. The sphere minimisers keep their compiled loops
(:mod:`jamflow.models.spheres._kernels`): :mod:`jamflow.minimize.fire` runs them for this model.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ...box import Box
from ...minimize.cg import minimize_cg
from ...minimize.fire import (
    DEFAULT_FIRE,
    FireParameters,
    MinimizeResult,
    minimize_enthalpy_model,
    minimize_fire,
)
from ...minimize.model import ModelEvaluation, WithoutFastPaths
from ...neighbors.verlet import NeighborList
from ...tolerances import MINIMIZE_FORCE_TOL
from .fast import SphereFire, SphereFireFullBox, steepest_descent
from .hessian import hessian
from .potential import HARMONIC, PowerLawPotential, energy_floor, evaluate

__all__ = ["SphereBodies", "SphereModel", "conjugate_gradient", "fire", "minimize_enthalpy"]


class SphereBodies(WithoutFastPaths):
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

    #: Largest ratio of a contact's lever arm in the virial to its contact distance
    #: (:func:`.potential.energy_floor`): 1 for free spheres.
    lever: float = 1.0

    def energy_floor(self, pressure: float) -> float:
        """The energy of :func:`.potential.energy_floor` in this box (see :meth:`EnergyModel.energy_floor`)."""
        return energy_floor(self.potential, self.diameter, self.box.volume, self.d, pressure, self.lever)


class SphereModel(SphereBodies):
    """Soft spheres with a power-law contact potential (see :mod:`jamflow.models.spheres.potential`).

    Parameters as :class:`SphereBodies`.
    """

    constrained = False
    box_dofs = True

    def fire_engine(self, q: NDArray[np.float64], params: FireParameters, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> SphereFire | SphereFireFullBox:
        """The compiled FIRE loops of :mod:`.fast`: fixed box or isotropic barostat, or the whole box free."""
        if box_dof == "full":
            return SphereFireFullBox(self, self.positions(q), params, pressure0, pressure_rtol)
        return SphereFire(self, self.positions(q), params, pressure0, pressure_rtol)

    def descent_fast_path(self, q: NDArray[np.float64], dt: float, force_tol: float,
                          max_steps: int) -> MinimizeResult:
        """The compiled steepest descent of :func:`.fast.steepest_descent` on this model's list."""
        return steepest_descent(self.positions(q), self.box, self.diameter, self.potential, dt, force_tol,
                                max_steps, self.nlist).result

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


def fire(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    nlist: NeighborList | None = None,
) -> MinimizeResult:
    """Minimise the energy of soft spheres at fixed box with FIRE 2.0.

    Parameters
    ----------
    x : array_like, shape (N, d)
        Initial centres [length].
    box : Box
        Fixed periodic (possibly sheared) box.
    diameter : array_like, shape (N,)
    potential : PowerLawPotential
    force_tol : float
        Stop when ``max_i |F_i| <= force_tol`` [epsilon / length].
    max_steps : int
        Step budget; ``converged`` is False when it runs out.
    params : FireParameters
    nlist : NeighborList, optional
        Reused between calls (rebuilt only when stale); from :data:`SPATIAL_SORT_MIN_N`
        spheres on only its skin is used (the run keeps a list in cell order).
    """
    return minimize_fire(SphereModel(box, diameter, potential, nlist), x, force_tol, max_steps, params)


def minimize_enthalpy(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    pressure: float,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    pressure_rtol: float = 1e-6,
    max_steps: int = 1_000_000,
    params: FireParameters = DEFAULT_FIRE,
    nlist: NeighborList | None = None,
    box_dof: str = "isotropic",
) -> MinimizeResult:
    """Minimise ``H = U + P0 V`` over centres and the box (FIRE 2.0).

    ``box_dof = "isotropic"``:

    The box is ``s h`` with ``s = exp(q / q_s)``, ``q_s = sqrt(N) <D>``, and centres
    ``s y``; ``q`` is one more FIRE degree of freedom with generalised force
    ``-dH/dq = d V (P - P0) / q_s`` (``P`` the virial pressure), so at a minimum the
    virial pressure equals ``P0``. The choice of ``q_s`` gives the box mode a
    stiffness of the order of a particle's.

    ``box_dof = "full"``: the whole upper-triangular box ``A h`` is free (``d (d+1)/2``
    degrees of freedom ``q_s A_ab``, centres ``A y``), with generalised forces
    ``(W - P0 V 1) A^-T / q_s``, ``W = sum f R R^T / r``. At the minimum the stress
    tensor is ``-P0 1`` (no residual shear stress); ``pressure_rtol`` then bounds
    ``max_ab |W_ab / V - P0 delta_ab| / P0``.

    Parameters
    ----------
    pressure : float
        Target pressure ``P0`` [epsilon / length^d], > 0.
    pressure_rtol : float
        Converged also requires ``|P - P0| <= pressure_rtol * P0`` (isotropic) or the
        stress-tensor bound above (full).
    box_dof : {"isotropic", "full"}
    Other parameters as in :func:`fire`.
    """
    return minimize_enthalpy_model(SphereModel(box, diameter, potential, nlist), x, pressure, force_tol,
                                   pressure_rtol, max_steps, params, box_dof)


def conjugate_gradient(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 100_000,
    nlist: NeighborList | None = None,
) -> MinimizeResult:
    """:func:`minimize_cg` of soft spheres."""
    return minimize_cg(SphereModel(box, diameter, potential, nlist), x, force_tol, max_steps)
