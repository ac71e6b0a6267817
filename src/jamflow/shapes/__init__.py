"""Packings of 2D shaped bodies (VanderWerf et al.): generation, jamming, counting.

:mod:`~jamflow.shapes.generation` (bidisperse shapes at a target asphericity, random
initial packings), :mod:`~jamflow.shapes.jamming` (bisection to ``P0`` with rotations).
"""

from .generation import (
    SHAPE_CHOICES,
    bidisperse_shapes,
    random_shape_packing,
    unit_shape,
)
from .jamming import jam_shapes

__all__ = ["SHAPE_CHOICES", "bidisperse_shapes", "jam_shapes", "random_shape_packing", "unit_shape"]
