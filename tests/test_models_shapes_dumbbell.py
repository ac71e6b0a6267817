"""Dumbbell energy model (VanderWerf et al. Sec. II: end-end and end-shaft terms).

Physics checked: forces and torques are minus the numerical gradient for each contact
type (end-end, end-shaft with the foot inside the shaft, both at once, the foot at the
shaft's end) and the Hessian is the derivative of the gradient; energy, forces and
torques are continuous through the type boundaries (jumps shrink with the scan step);
the energy switches on where the exact outlines first touch (shapely); the spectrum of
an isolated overlapping pair has exactly the zero modes of its symmetries; the
exact moment of inertia matches the sampled outline.
"""

from __future__ import annotations

import numpy as np
import pytest
from shape_numerics import numerical_gradient, numerical_hessian, onset_distances
from shapely.geometry import Polygon

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.state.bodies import ShapeTable, _polygon_moment

# lobes R at +-h, shaft half-width R/2 (Fig. 4 a: shaft length 2h = 4R), small and large
TABLE = ShapeTable.from_shapes([dict(kind="dumbbell", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.25,
                                     shaft_half_width=0.125),
                                dict(kind="dumbbell", vertices=[(-0.7, 0.0), (0.7, 0.0)], radius=0.35,
                                     shaft_half_width=0.175)])
BOX = Box.cubic(2, 8.0)


def _terms(m, q):
    return sorted(set(m.point_terms(q)["type"].tolist()))


# (index, conf, the term types present): 0 end-end, 1 lobe of i on j's shaft, 2 the mirror
CASES = [
    ([0, 0], [[4.0, 4.0, 0.0], [5.0, 4.49, 0.0]], [0]),               # end-end, lobes side by side
    ([0, 1], [[4.0, 4.0, 0.0], [4.915, 4.0, np.pi / 2]], [1]),        # a lobe on the middle of a shaft
    ([1, 0], [[4.0, 4.0, 0.0], [4.0, 4.915, np.pi / 2]], [2]),        # the mirror
    ([0, 0], [[4.0, 4.0, 0.0], [4.5, 4.365, 0.0]], [1, 2]),           # parallel, a lobe on each shaft
    ([1, 0], [[4.0, 4.0, 0.0], [4.28, 4.915, np.pi / 2]], [0, 2]),    # in the concave lobe-shaft corner
    ([0, 1], [[4.0, 4.0, 0.3], [4.9, 4.5, 1.2]], None),               # tilted, generic
]


@pytest.mark.parametrize("index, conf, types", CASES)
def test_gradient_and_hessian_per_contact_type(index, conf, types):
    m = ShapeModel(BOX, TABLE, index)
    q = m.dofs(conf)
    m.check_cores(q)
    if types is not None:
        assert _terms(m, q) == types
    ev = m.evaluate(q)
    assert ev.energy > 0.0
    np.testing.assert_allclose(ev.gradient, numerical_gradient(m, q, 1e-6), atol=1e-9)
    hess = m.hessian(q).toarray()
    np.testing.assert_allclose(hess, numerical_hessian(m, q, 1e-7), atol=1e-6)
    np.testing.assert_allclose(hess, hess.T, atol=1e-13)


def test_gradient_over_random_contacts():
    rng = np.random.default_rng(11)
    seen = set()
    checked = 0
    while checked < 30:
        index = list(rng.integers(0, 2, 2))
        m = ShapeModel(BOX, TABLE, index)
        conf = [[4.0, 4.0, rng.uniform(0, 2 * np.pi)],
                [4.0 + rng.uniform(-2, 2), 4.0 + rng.uniform(-2, 2), rng.uniform(0, 2 * np.pi)]]
        q = m.dofs(conf)
        if m.evaluate(q).energy == 0.0:
            continue
        try:
            m.check_cores(q)
        except ValueError:
            continue
        checked += 1
        seen.update(_terms(m, q))
        np.testing.assert_allclose(m.evaluate(q).gradient, numerical_gradient(m, q, 1e-6), atol=1e-8)
    assert seen == {0, 1, 2}


def test_gradient_with_foot_at_the_shaft_end():
    """A lobe deep enough that its foot on the other shaft clamps to the lobe centre (t = 0)."""
    m = ShapeModel(BOX, TABLE, [0, 0])
    # i's right lobe at (4.5, 4); j's left lobe centre at (4.5 + 0.3, 4 + 0.05), j along +x
    q = m.dofs([[4.0, 4.0, 0.0], [5.3, 4.05, 0.0]])
    t = m.point_terms(q)
    foot = t["point_j"][t["type"] == 1]
    np.testing.assert_allclose(foot, [[0.8, 0.05]], atol=1e-14)   # j's left lobe centre
    np.testing.assert_allclose(m.evaluate(q).gradient, numerical_gradient(m, q, 1e-7), atol=1e-8)


@pytest.mark.parametrize("start, end", [
    # a lobe slides along the shaft past its end into the lobe: foot t from inside to clamped
    ([[4.0, 4.0, 0.0], [4.2, 4.865, np.pi / 2]], [[4.0, 4.0, 0.0], [4.9, 4.865, np.pi / 2]]),
    # rotating j so that an end-end term and an end-shaft term switch on and off
    ([[4.0, 4.0, 0.0], [4.9, 4.55, 0.0]], [[4.0, 4.0, 0.0], [4.9, 4.55, 2.0]]),
])
def test_continuous_through_type_boundaries(start, end):
    m = ShapeModel(BOX, TABLE, [0, 0])
    a, b = m.dofs(start), m.dofs(end)

    def jumps(steps):
        vals = [m.evaluate(a + s * (b - a)) for s in np.linspace(0.0, 1.0, steps)]
        e = np.array([v.energy for v in vals])
        g = np.array([v.gradient for v in vals])
        return np.max(np.abs(np.diff(e))), np.max(np.abs(np.diff(g, axis=0)))

    coarse, fine = jumps(201), jumps(2001)
    # continuous: the largest jump shrinks ~ with the step (a discontinuity would stay)
    assert fine[0] < 0.2 * coarse[0] and fine[1] < 0.2 * coarse[1]
    assert coarse[0] > 0.0


def _outline(shape: int, theta: float, centre) -> Polygon:
    c, s = np.cos(theta), np.sin(theta)
    return Polygon(TABLE.outline(shape, 40_000) @ np.array([[c, s], [-s, c]]) + np.asarray(centre))


def test_contact_distance_against_exact_outlines():
    """Energy onset along a direction = first touch of the outlines (within the sagitta, 1e-8)."""
    rng = np.random.default_rng(5)
    done = 0
    while done < 10:
        index = list(rng.integers(0, 2, 2))
        ti, tj, phi = rng.uniform(0.0, 2.0 * np.pi, 3)
        e = np.array([np.cos(phi), np.sin(phi)])
        onsets = onset_distances(ShapeModel(BOX, TABLE, index), _outline, index, ti, tj, e, (4.0, 4.0), 0.05, 2.2)
        if onsets is None:  # a side does not touch at the smallest distance: no onset to compare
            continue
        done += 1
        assert abs(onsets[0] - onsets[1]) <= 1e-8


def test_zero_modes_of_an_overlapping_pair():
    """An isolated pair in the concave corner (two contacts): the zero modes are exactly the
    two translations; the rigid rotation of the pair is not one (the pair is not in
    equilibrium) but its curvature is fixed by invariance, ``v.H.v = -g.a`` with ``a``
    the second derivative of the rotated coordinates."""
    m = ShapeModel(BOX, TABLE, [1, 0])
    conf = np.array(CASES[4][1])
    q = m.dofs(conf)
    hess = m.hessian(q).toarray()
    lam, vec = np.linalg.eigh(hess)
    zero = np.abs(lam) <= 1e-12 * np.abs(lam).max()
    assert np.count_nonzero(zero) == 2
    translations = np.stack([m.dofs([[1, 0, 0], [1, 0, 0]]), m.dofs([[0, 1, 0], [0, 1, 0]])], axis=1)
    null = vec[:, zero]
    assert np.max(np.abs(translations - null @ (null.T @ translations))) < 1e-10
    arm = conf[:, :2] - conf[:, :2].mean(axis=0)
    v = m.dofs(np.column_stack([-arm[:, 1], arm[:, 0], [1.0, 1.0]]))
    a = m.dofs(np.column_stack([-arm, [0.0, 0.0]]))
    g = m.evaluate(q).gradient
    assert v @ hess @ v == pytest.approx(-g @ a, rel=1e-10)


def test_crossed_shafts_refused():
    m = ShapeModel(BOX, TABLE, [0, 1])
    with pytest.raises(ValueError, match="intersecting cores"):
        m.check_cores(m.dofs([[4.0, 4.0, 0.0], [4.0, 4.0, np.pi / 2]]))


def test_moment_of_inertia_against_sampled_outline():
    for k in range(2):
        area, j = _polygon_moment(TABLE.outline(k, 200_000))
        assert TABLE.gyration_squared[k] == pytest.approx(j / area, rel=1e-8)
        assert TABLE.area[k] == pytest.approx(area, rel=1e-8)
