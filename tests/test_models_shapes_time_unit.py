"""FIRE's time unit of shaped bodies: the period of their stiffest contact in the mass metric.

Physics checked: round ellipses (disks) have the disks' contact stiffness, and near-round shapes
keep the unit ``sqrt(m / k)``; the sampled stiffness of frozen ellipses reaches, from below, the closed form
``1 + (alpha - 1 / alpha)^2 / 4`` of two parallel ellipses whose centre line grazes their axes;
the model's own mass-weighted Hessian of two long bodies touching at random never exceeds
``2 / time_unit^2`` (beyond the sampling grid's shortfall) and comes close to it; circulo-polygons
keep the face contact's unit.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.models.shapes._kernels import ELLIPSE
from jamflow.models.shapes.model import END_END_TERMS, FREE_STIFFNESS, POLYGON_STIFFNESS
from jamflow.models.shapes.time_unit import contact_stiffness
from jamflow.shapes import bidisperse_shapes, unit_shape
from jamflow.state.bodies import ShapeTable

BOX = Box.cubic(2, 20.0)


def ellipse(alpha: float) -> dict:
    return dict(kind="ellipse", semi_axes=(0.5 * np.sqrt(alpha), 0.5 / np.sqrt(alpha)))


def line(alpha: float, radius: float = 0.1) -> dict:
    """A circulo-line of length over width ``(l + 2R) / 2R = alpha``."""
    half = radius * (alpha - 1.0)
    return dict(kind="circulo_line", vertices=[(-half, 0.0), (half, 0.0)], radius=radius)


def stiffness(shapes: list[dict], rotations: bool = True, mass: float = 1.0, k: float = 1.0) -> float:
    """``K`` of the time unit ``sqrt(m / (K k))`` of a packing of these shapes."""
    m = ShapeModel(BOX, ShapeTable.from_shapes(shapes), np.arange(len(shapes)), k=k, mass=mass,
                   rotations=rotations)
    return m.mass / (m.k * m.time_unit**2)


def test_disks_and_near_round_shapes_keep_the_unit_of_disks():
    """Round ellipses: contact stiffness 1, with and without rotations (a disk's contact does not
    turn it); the benchmark's shapes of asphericity 1.1 (stiffness 1.87 and 1.44, at most
    ``FREE_STIFFNESS``) keep ``K = 1``; mass and spring constant enter only as ``sqrt(m / k)``."""
    table = ShapeTable.from_shapes([ellipse(1.0)])
    for rotations in (True, False):
        assert contact_stiffness(ELLIPSE, table.semi_axes, table.gyration_squared, table.bounding_radius,
                                 rotations) == pytest.approx(1.0, rel=1e-6)
    for kind in ("ellipse", "circulo-line"):
        shapes = bidisperse_shapes(unit_shape(kind, asphericity=1.1))
        assert ShapeModel(BOX, shapes, [0, 1]).time_unit == 1.0
    assert stiffness([ellipse(10.0)]) > FREE_STIFFNESS
    m = ShapeModel(BOX, ShapeTable.from_shapes([ellipse(10.0)]), [0], k=4.0, mass=9.0)
    assert m.time_unit == pytest.approx(np.sqrt(9.0 / (4.0 * stiffness([ellipse(10.0)]))), rel=1e-12)
    m = ShapeModel(BOX, ShapeTable.from_shapes([ellipse(1.0)]), [0], k=4.0, mass=9.0)
    assert m.time_unit == pytest.approx(1.5, rel=1e-6)


@pytest.mark.parametrize("alpha", [2.0, 10.0])
def test_frozen_ellipses_reach_the_grazing_parallel_contact(alpha):
    """Translations only: two parallel ellipses touch at ``sigma(psi)`` (centre-line angle ``psi``
    to the axes), an ellipse of doubled axes, so the overlap ``sigma - r`` changes by
    ``sigma' / sigma`` per unit of sideways motion, at most ``(alpha - 1 / alpha) / 2`` (at
    ``tan psi = 1 / alpha``): curvature ``2 k / m (1 + (alpha - 1 / alpha)^2 / 4)``. The sampled
    grid approaches it from below (0.91 of it at alpha = 10, the samples miss exact parallels)."""
    table = ShapeTable.from_shapes([ellipse(alpha)])

    def sampled(rotations: bool) -> float:
        return contact_stiffness(ELLIPSE, table.semi_axes, table.gyration_squared, table.bounding_radius, rotations)

    exact = 1.0 + (alpha - 1.0 / alpha) ** 2 / 4.0
    assert 0.9 * exact <= sampled(False) <= exact * (1.0 + 1e-9)
    # rotations only add stiffness: a contact at the tip turns the body
    assert sampled(True) > sampled(False)


def touching(model: ShapeModel, rng: np.random.Generator, overlap: float) -> np.ndarray:
    """Configuration of the model's two bodies at a random relative orientation and direction,
    overlapping by ``overlap`` along the centre line (bisection on the model's energy)."""
    turn, psi = rng.uniform(0.0, 2.0 * np.pi, 2)
    u = np.array([np.cos(psi), np.sin(psi)])
    inside, outside = 0.0, float(model.bounding_diameter.sum())
    conf = np.array([[10.0, 10.0, 0.0], [10.0, 10.0, turn]])
    for _ in range(45):
        mid = 0.5 * (inside + outside)
        conf[1, :2] = conf[0, :2] + mid * u
        hit = model.evaluate(model.dofs(conf)).energy > 0.0
        if model.family == "circulo":
            try:
                model.check_cores(model.dofs(conf))
            except ValueError:
                hit = True
        inside, outside = (mid, outside) if hit else (inside, mid)
    conf[1, :2] = conf[0, :2] + (outside - overlap) * u
    return conf


@pytest.mark.parametrize("shape", [ellipse(10.0), line(10.0)], ids=["ellipse", "circulo-line"])
def test_time_unit_bounds_the_mass_weighted_hessian_of_long_bodies(shape):
    """Two bodies of aspect ratio 10 touching at 100 random (seeded) relative orientations and
    directions: the largest eigenvalue of ``M^-1/2 H M^-1/2`` of the model's Hessian, times
    ``time_unit^2``, stays below that of two round bodies of the family (2 for disks, 2
    ``END_END_TERMS`` for round circulo-lines, whose end-end contact is two terms) up to the
    grid's shortfall (5 %), and its largest value is near it (above 0.6 of it: the unit is not
    vacuously small)."""
    model = ShapeModel(BOX, ShapeTable.from_shapes([shape]), [0, 0])
    rng = np.random.default_rng(3)
    s = np.sqrt(model.inverse_mass)
    top = []
    for _ in range(100):
        q = model.dofs(touching(model, rng, 1e-9))
        h = model.hessian(q).toarray()
        top.append(np.linalg.eigvalsh(s[:, None] * h * s[None, :])[-1] * model.time_unit**2)
    round_pair = 2.0 * (END_END_TERMS if model.family == "circulo" else 1)
    assert max(top) <= round_pair * 1.05
    assert max(top) >= 0.6 * round_pair


def test_polygons_keep_the_face_contact_unit():
    """Circulo-polygons: ``POLYGON_STIFFNESS`` (the face contact's curvature, measured for FIRE),
    alone and with circulo-lines whose own stiffness is below it."""
    tri = dict(kind="circulo_polygon", vertices=[(0.3, 0.0), (-0.15, 0.26), (-0.15, -0.26)], radius=0.1)
    assert stiffness([tri]) == POLYGON_STIFFNESS
    assert stiffness([line(3.0)]) < POLYGON_STIFFNESS
    assert stiffness([tri, line(3.0)]) == POLYGON_STIFFNESS
