"""jamflow: jammed packings of frictionless hard spheres, driven, certified and analysed."""

from .box import Box
from .packing import Packing

__all__ = ["Box", "Packing"]
