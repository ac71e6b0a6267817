"""Energy models: every body on one interface for every minimiser.

:mod:`.spheres` (soft spheres: power-law potential, compiled kernels, Hessian),
:mod:`.links` (linked spheres: holonomic links, projection and Newton re-affixing),
:mod:`.strain` (strain degrees of freedom with fixed volume: shear stabilisation),
:mod:`.shapes` (2D shaped bodies with orientations). :func:`model_for` is the one place
that maps a packing to its model; the protocol they share is
:class:`jamflow.minimize.model.EnergyModel`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..minimize.model import EnergyModel
from ..state.packing import Packing
from .links import LinkedSpheresModel
from .shapes import ShapeModel
from .spheres.model import SphereModel
from .spheres.potential import HARMONIC, PowerLawPotential
from .strain import ShearStabilizedModel

__all__ = ["LinkedSpheresModel", "ShapeModel", "ShearStabilizedModel", "SphereModel", "model_for"]


def model_for(packing: Packing, potential: PowerLawPotential = HARMONIC, *,
              shear_stabilized: bool = False) -> tuple[EnergyModel, NDArray[np.float64]]:
    """The energy model of a packing in its box, and its degree-of-freedom vector.

    Parameters
    ----------
    packing : Packing
        Spheres, linked spheres or shaped bodies (body kind ``walls`` has no energy model:
        hard walls are CALiPPSO's containers).
    potential : PowerLawPotential
        Contact potential of spheres and linked spheres; shaped bodies interact by the
        linear spring of VanderWerf et al. Eq. 1 with the packing's ``spring_constant``.
    shear_stabilized : bool
        Linked spheres with the strain degrees of freedom at fixed volume (chains paper
        Sec. II D); refused for other bodies.

    Returns
    -------
    model : EnergyModel
    q : ndarray, shape (model.n_dof,)
    """
    kind = packing.body_kind
    if kind == "walls":
        raise ValueError("a packing between hard walls has no energy model (jam it with calippso --walls)")
    if shear_stabilized and kind != "linked":
        raise ValueError(f"shear stabilisation is a model of linked spheres; this packing holds {kind}")
    if kind == "shapes":
        if potential != HARMONIC:
            raise ValueError(f"shaped bodies interact by the linear spring (Eq. 1) only, not exponent "
                             f"{potential.exponent:g}")
        model = ShapeModel(packing.box, packing.shapes, packing.shape_index,
                           k=float(packing.attrs.get("spring_constant", 1.0)),
                           mass=float(packing.attrs.get("mass", 1.0)),
                           rotations=not int(packing.attrs.get("frozen_orientations", 0)))
        return model, model.dofs(np.column_stack([packing.position, packing.orientation]))
    if kind == "linked":
        cls = ShearStabilizedModel if shear_stabilized else LinkedSpheresModel
        model = cls(packing.box, packing.diameter, packing.links, packing.position, potential)
        return model, model.dofs(packing.position)
    model = SphereModel(packing.box, packing.diameter, potential)
    return model, model.dofs(packing.position)
