"""Energy models: bodies on one interface for every minimiser.

:mod:`~jamflow.models.base` (the protocol), :mod:`~jamflow.models.spheres` (soft
spheres, the numbers of :mod:`jamflow.soft`), :mod:`~jamflow.models.links` (linked
spheres: holonomic links, projection and Newton re-affixing).
"""

from .base import EnergyModel, ModelEvaluation, pressure_of, stress_of
from .links import LinkedSpheresModel
from .spheres import SphereModel

__all__ = ["EnergyModel", "LinkedSpheresModel", "ModelEvaluation", "SphereModel", "pressure_of", "stress_of"]
