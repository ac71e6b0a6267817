"""Energy models of 2D shaped bodies (VanderWerf et al., hypostatic nonspherical packings).

:mod:`~jamflow.models.shapes.model` (the model: centres and orientations, one family
per packing), :mod:`~jamflow.models.shapes._kernels` (compiled pair kernels:
circulo-lines and -polygons, App. A; ellipses, Perram–Wertheim; Reuleaux triangles;
dumbbells).
"""

from .model import POINT_TERM_FAMILIES, SHAPE_FAMILIES, ShapeModel, shape_family

__all__ = ["POINT_TERM_FAMILIES", "SHAPE_FAMILIES", "ShapeModel", "shape_family"]
