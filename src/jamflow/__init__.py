"""jamflow: jammed packings of frictionless hard spheres, driven, certified and analysed."""

from .box import Box
from .packing import Packing
from .summary import load_scene

__all__ = ["Box", "Packing", "load_scene"]
