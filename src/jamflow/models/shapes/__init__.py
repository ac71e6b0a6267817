"""Energy models of 2D shaped bodies (VanderWerf et al., hypostatic nonspherical packings).

:mod:`~jamflow.models.shapes.model` (the model: centres and orientations, one family
per packing), :mod:`~jamflow.models.shapes._kernels` (compiled pair kernels:
circulo-lines and -polygons, App. A; ellipses, Perram–Wertheim).
"""

from .model import SHAPE_FAMILIES, ShapeModel, shape_family

__all__ = ["SHAPE_FAMILIES", "ShapeModel", "shape_family"]
