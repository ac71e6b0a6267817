"""A box that changes volume: enthalpy ``H = U + P0 V`` of any model whose box deforms with its coordinates.

The wrapped model owns the box degrees of freedom (e.g. the strain of
:class:`~jamflow.models.strain.ShearStabilizedModel` with ``fixed_volume=False``) and
tells its volume ``V(q)`` and ``dV/dq``; :class:`EnthalpyModel` adds ``P0 V`` to its
energy and ``P0 dV/dq`` to its gradient and passes everything else through
(constraint projection and re-affixing, neighbour lists, positions). At a minimum of
``H`` the box carries the stress ``-P0 1``: the projected strain forces vanish when the
total virial (contacts and link tensions) equals ``P0 V 1``. This is the linked-sphere
counterpart of the spheres' enthalpy minimisation
(:func:`jamflow.models.spheres.model.minimize_enthalpy`) with the whole box free.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..box import Box
from ..minimize.model import EnergyModel, ModelEvaluation

__all__ = ["DeformableBox", "EnthalpyModel"]


class DeformableBox(Protocol):
    """What :class:`EnthalpyModel` needs beyond :class:`~jamflow.minimize.model.EnergyModel`."""

    def volume(self, q: NDArray[np.float64]) -> float:
        """Box volume at ``q`` [length^d]."""
        ...

    def volume_gradient(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``dV/dq``, shape (n_dof,)."""
        ...


class EnthalpyModel:
    """``H = U + P0 V`` of ``model`` (module doc); every other question goes to ``model``.

    Parameters
    ----------
    model : EnergyModel with ``volume`` and ``volume_gradient``
        A model whose box is among its degrees of freedom.
    pressure : float
        ``P0`` [epsilon / length^d], > 0.
    """

    box_dofs = False  # the box is in q; no compiled engine of its own

    def __init__(self, model: EnergyModel, pressure: float) -> None:
        if not (np.isfinite(pressure) and pressure > 0.0):
            raise ValueError(f"enthalpy needs a positive, finite pressure, got {pressure}")
        if not (hasattr(model, "volume") and hasattr(model, "volume_gradient")):
            raise TypeError(f"{type(model).__name__} has no box degrees of freedom (volume, volume_gradient)")
        self.model = model
        self.pressure = float(pressure)

    def __getattr__(self, name: str) -> Any:
        # n, d, box, n_dof, inverse_mass, time_unit, constrained, links, positions, last_box, ...
        return getattr(self.model, name)

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        ev = self.model.evaluate(q)
        return replace(ev, energy=ev.energy + self.pressure * self.model.volume(q),
                       gradient=ev.gradient + self.pressure * self.model.volume_gradient(q))

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        raise NotImplementedError("the enthalpy's Hessian: use jamflow.chains.hessian on the minimised packing")

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple[EnthalpyModel, NDArray[np.float64]]:
        model, x = self.model.rescaled(factor, position)
        return EnthalpyModel(model, self.pressure), x

    def fire_engine(self, q: NDArray[np.float64], params: Any, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> None:
        return None

    def descent_fast_path(self, q: NDArray[np.float64], dt: float, force_tol: float, max_steps: int) -> None:
        return None

    def energy_floor(self, pressure: float) -> float:
        return 0.0

    def current_box(self, q: NDArray[np.float64]) -> Box:
        return self.model.current_box(q)
