"""Ellipse energy model: Perram–Wertheim contact distance, forces, torques, Hessian.

Physics checked: the contact distance ``sigma`` at fixed orientations against closed
forms (aligned and crossed ellipses, the disk limit) and against a brute-force
bisection on the centre distance with finely sampled boundaries (shapely); forces and
torques are minus the gradient; the Hessian is the derivative of the gradient.
"""

from __future__ import annotations

import numpy as np
import pytest
from shape_numerics import numerical_gradient, numerical_hessian
from shapely.geometry import Polygon

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.models.shapes._kernels import perram_wertheim
from jamflow.state.bodies import ShapeTable

BOX = Box.cubic(2, 8.0)
TABLE = ShapeTable.from_shapes([
    dict(kind="ellipse", semi_axes=(0.8, 0.35)),
    dict(kind="ellipse", semi_axes=(0.5, 0.45)),
    dict(kind="ellipse", semi_axes=(0.6, 0.6)),
])


def contact_distance(si: int, sj: int, ti: float, tj: float, direction: float) -> float:
    """``sigma = r / sqrt(F)`` along ``direction`` (any r: F is homogeneous of degree 2)."""
    r = 3.0
    f, *_ = perram_wertheim(r * np.cos(direction), r * np.sin(direction), ti, tj,
                            TABLE.semi_axes[si], TABLE.semi_axes[sj])
    return r / np.sqrt(f)


def brute_force_contact_distance(si, sj, ti, tj, direction, points=20_000) -> float:
    """Bisection on the centre distance until the sampled boundaries just touch.

    Boundaries are polygons of ``points`` vertices inscribed in the ellipses, so the
    result is short by at most the sagitta ``a (pi / points)^2 / 2 ~ 1e-8``.
    """
    def outline(s, t, centre):
        a, b = TABLE.semi_axes[s]
        u = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
        p = np.stack([a * np.cos(u), b * np.sin(u)], axis=1)
        c, s_ = np.cos(t), np.sin(t)
        return Polygon(p @ np.array([[c, s_], [-s_, c]]) + centre)

    e = np.array([np.cos(direction), np.sin(direction)])
    pi = outline(si, ti, np.zeros(2))
    lo, hi = 0.0, 4.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if pi.intersects(outline(sj, tj, mid * e)):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_contact_distance_closed_forms():
    a0, b0 = TABLE.semi_axes[0]
    a1, b1 = TABLE.semi_axes[1]
    assert contact_distance(0, 1, 0.0, 0.0, 0.0) == pytest.approx(a0 + a1, rel=1e-14)
    assert contact_distance(0, 1, 0.0, 0.0, np.pi / 2) == pytest.approx(b0 + b1, rel=1e-14)
    assert contact_distance(0, 1, 0.0, np.pi / 2, 0.0) == pytest.approx(a0 + b1, rel=1e-14)
    # a disk against an ellipse along an axis; two disks in any direction
    assert contact_distance(2, 0, 0.3, 0.0, 0.0) == pytest.approx(0.6 + a0, rel=1e-14)
    assert contact_distance(2, 2, 0.3, -1.1, 0.77) == pytest.approx(1.2, rel=1e-14)


def test_contact_distance_against_brute_force_sampling():
    rng = np.random.default_rng(2323)
    for _ in range(12):
        si, sj = rng.integers(0, 2, 2)
        ti, tj, direction = rng.uniform(0.0, 2.0 * np.pi, 3)
        exact = contact_distance(si, sj, ti, tj, direction)
        brute = brute_force_contact_distance(si, sj, ti, tj, direction)
        # inscribed polygons touch later: brute <= exact, by at most two sagittas
        assert -1e-10 <= exact - brute <= 4e-8


CONFIGS = [
    ((0, 1), [[3.0, 3.0, 0.3], [3.9, 3.4, 1.4]]),
    ((0, 0), [[3.0, 3.0, 0.0], [3.0, 3.65, 0.05]]),
    ((1, 2), [[3.0, 3.0, 2.0], [3.7, 2.4, 0.0]]),
    ((0, 1), [[3.0, 3.0, 1.0], [2.5, 3.6, -0.7]]),
]


@pytest.mark.parametrize("shapes, conf", CONFIGS)
def test_ellipse_forces_torques_and_hessian(shapes, conf):
    m = ShapeModel(BOX, TABLE, list(shapes))
    q = m.dofs(conf)
    ev = m.evaluate(q)
    assert ev.energy > 0.0 and ev.n_contacts == 1
    np.testing.assert_allclose(ev.gradient, numerical_gradient(m, q, 1e-6), atol=1e-9)
    g = m.positions(ev.gradient)
    x = m.positions(q)
    np.testing.assert_allclose(g[:, :2].sum(axis=0), 0.0, atol=1e-14)
    assert abs(g[:, 2].sum() + np.sum(x[:, 0] * g[:, 1] - x[:, 1] * g[:, 0])) < 1e-13
    hess = m.hessian(q).toarray()
    h_num = numerical_hessian(m, q, 1e-6)
    np.testing.assert_allclose(hess, h_num, atol=1e-8)
    np.testing.assert_allclose(hess, hess.T, atol=1e-13)


def test_disk_limit_has_no_torque_and_sphere_energy():
    m = ShapeModel(BOX, TABLE, [2, 2])
    q = m.dofs([[3.0, 3.0, 0.4], [4.1, 3.0, -0.9]])
    ev = m.evaluate(q)
    assert ev.energy == pytest.approx(0.5 * 0.1**2, rel=1e-13)
    np.testing.assert_allclose(m.positions(ev.gradient)[:, 2], 0.0, atol=1e-15)
