"""The energy-model protocol: what a minimiser may ask of a body model, and nothing more.

A minimiser (FIRE, CG, steepest descent; :mod:`jamflow.minimize.fire`) sees a model
only through this protocol (jax-md's energy + shift, pele's ``BasePotential``):

- the degrees of freedom as one flat vector ``q`` (float64, shape ``(n_dof,)``):
  centres ``(N, d)`` row-major first, then orientations (one angle per body in 2D),
  then, when a model has them, strain degrees of freedom;
- ``inverse_mass`` per degree of freedom: 1 for centres (unit masses), ``1 / I`` for
  an orientation with moment of inertia ``I`` [mass length^2], so FIRE's time step
  (in units of :attr:`EnergyModel.time_unit`) means the same thing for rotations;
- energy ``U(q)`` and gradient ``dU/dq`` with the pair virial (:class:`ModelEvaluation`);
- an optional tangent projection of a gradient or velocity onto the constraint
  manifold (:meth:`EnergyModel.project`) and a re-projection of ``q`` onto it
  (:meth:`EnergyModel.reproject`); both are the identity for an unconstrained model;
- the convergence measure ``max_force`` (largest per-body force norm), pressure and
  stress from the evaluation, and a Hessian on request;
- the same model in a box scaled isotropically (``rescaled``), for the jamming-onset
  bisection of :mod:`jamflow.minimize.onset`.

The model owns its box, neighbour list and kernels: a minimiser never reaches into them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..box import Box

__all__ = ["EnergyModel", "ModelEvaluation", "WithoutFastPaths", "pressure_of", "stress_of"]


@dataclass(frozen=True)
class ModelEvaluation:
    """Energy, gradient and virial of one configuration of a model.

    Attributes
    ----------
    energy : float
        ``U(q)`` [energy].
    gradient : ndarray, shape (n_dof,)
        ``dU/dq`` (unprojected) [energy / length for centres, energy / rad for angles].
    virial : ndarray, shape (d, d)
        ``W = sum f r_a r_b / r`` over repulsive pairs (and constraint forces, if the
        model has constraints) [energy]; stress ``-W / V``, pressure ``tr W / (d V)``.
    n_contacts : int
        Number of interacting (overlapping) pairs.
    """

    energy: float
    gradient: NDArray[np.float64]
    virial: NDArray[np.float64]
    n_contacts: int


def stress_of(evaluation: ModelEvaluation, box: Box) -> NDArray[np.float64]:
    """Stress tensor ``-W / V`` [energy / length^d] (sign convention of :mod:`jamflow.models.spheres.potential`)."""
    return -evaluation.virial / box.volume


def pressure_of(evaluation: ModelEvaluation, box: Box) -> float:
    """Virial pressure ``tr W / (d V)`` [energy / length^d]."""
    return float(np.trace(evaluation.virial) / (box.d * box.volume))


@runtime_checkable
class EnergyModel(Protocol):
    """What FIRE, CG and steepest descent need of a body model (see the module doc).

    Attributes
    ----------
    box : Box
        The (fixed) periodic box.
    n_dof : int
        Length of the degree-of-freedom vector.
    inverse_mass : ndarray, shape (n_dof,)
        ``1 / m`` per degree of freedom (1 for centres).
    time_unit : float
        ``<D> sqrt(m / epsilon)``: FIRE time steps are given in this unit.
    constrained : bool
        Whether :meth:`project` and :meth:`reproject` do anything.
    box_dofs : bool
        Whether the model can minimise enthalpy (its box is a degree of freedom of
        :meth:`fire_engine` with ``pressure0``).
    neighbor_builds : int
        Neighbour-list builds so far (a minimiser reports the difference).
    """

    box: Box
    n_dof: int
    inverse_mass: NDArray[np.float64]
    time_unit: float
    constrained: bool
    box_dofs: bool

    @property
    def neighbor_builds(self) -> int: ...

    def dofs(self, position: NDArray[np.float64]) -> NDArray[np.float64]:
        """Flat degree-of-freedom vector of centres ``(N, d)`` [length]."""
        ...

    def positions(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Centres ``(N, d)`` [length] of a degree-of-freedom vector."""
        ...

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        """Energy, gradient and virial at ``q``."""
        ...

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Component of ``g`` (a gradient or velocity) tangent to the constraints at ``q``."""
        ...

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``q`` moved onto the constraint manifold (a copy; ``q`` itself when unconstrained)."""
        ...

    def max_force(self, g: NDArray[np.float64]) -> float:
        """Largest per-body norm of ``g`` (a projected force or gradient)."""
        ...

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        """Second derivatives ``d^2 U / dq dq``, shape ``(n_dof, n_dof)``."""
        ...

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple["EnergyModel", NDArray[np.float64]]:
        """The model in its box scaled by ``factor`` and the matching start (jamming bisection)."""
        ...

    def current_box(self, q: NDArray[np.float64]) -> Box:
        """The box of the state ``q``: :attr:`box`, or the deformed box of a model whose strain is a degree of freedom."""
        ...

    def fire_engine(self, q: NDArray[np.float64], params: Any, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> Any:
        """The model's compiled FIRE engine from ``q`` (a :class:`~jamflow.minimize.fire.FireEngine`), or None.

        ``pressure0`` asks for enthalpy minimisation at that pressure with the box
        degrees of freedom ``box_dof`` (``"isotropic"`` or ``"full"``). None means
        the minimiser steps the flat vector itself.
        """
        ...

    def descent_fast_path(self, q: NDArray[np.float64], dt: float, force_tol: float,
                          max_steps: int) -> Any:
        """Steepest descent from ``q`` in a compiled loop (a :class:`~jamflow.minimize.fire.MinimizeResult`), or None."""
        ...

    def energy_floor(self, pressure: float) -> float:
        """An energy [epsilon] below which no force-balanced state in :attr:`box` has a pressure of ``pressure`` or more.

        0 when the model knows no such bound. A fixed-box minimisation whose energy
        ``U + K`` has fallen below it can end early with the verdict "below ``pressure``"
        (:func:`jamflow.minimize.fire.minimize_fire`, ``energy_floor``).
        """
        ...


class WithoutFastPaths:
    """What a model without compiled minimisers or box degrees of freedom answers (mix in)."""

    box_dofs: bool = False

    def current_box(self, q: NDArray[np.float64]) -> Box:
        return self.box

    def fire_engine(self, q: NDArray[np.float64], params: Any, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> None:
        return None

    def descent_fast_path(self, q: NDArray[np.float64], dt: float, force_tol: float, max_steps: int) -> None:
        return None

    def energy_floor(self, pressure: float) -> float:
        return 0.0
