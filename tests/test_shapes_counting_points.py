"""Counting of dumbbell and Reuleaux packings (point-term contacts, VanderWerf et al. Sec. III B).

Physics checked: with every term its own contact (``parallel="twice"``) the contact
Jacobian built from the term points and normals reproduces the model gradient,
``g = -k J^T delta`` exactly, on many-body overlapping configurations (so normals and
arms are right for every term type); dumbbell lobes on one shaft count once or twice
as asked, while the distinct contacts of a lobe in the concave corner count twice in
both conventions.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.network import contact_jacobian
from jamflow.shapes.counting import shape_contacts
from jamflow.state.bodies import ShapeTable

_A = 2.0 * np.pi * np.arange(3) / 3
REULEAUX = ShapeTable.from_shapes([dict(kind="reuleaux", vertices=0.5 * np.stack([np.cos(_A), np.sin(_A)], 1)),
                                   dict(kind="reuleaux", vertices=0.7 * np.stack([np.cos(_A), np.sin(_A)], 1))])
DUMBBELLS = ShapeTable.from_shapes([dict(kind="dumbbell", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.25,
                                         shaft_half_width=0.125),
                                    dict(kind="dumbbell", vertices=[(-0.7, 0.0), (0.7, 0.0)], radius=0.35,
                                         shaft_half_width=0.175)])


def _overlapping(table, seed, n=30, side=9.0):
    """A random configuration with overlaps and no crossed cores."""
    rng = np.random.default_rng(seed)
    box = Box.cubic(2, side)
    for _ in range(1000):
        m = ShapeModel(box, table, rng.integers(0, 2, n))
        q = m.dofs(np.column_stack([rng.uniform(0, side, (n, 2)), rng.uniform(0, 2 * np.pi, n)]))
        try:
            m.check_cores(q)
        except ValueError:
            continue
        if m.evaluate(q).n_contacts >= 8:
            return m, q
    raise AssertionError("no configuration found")


@pytest.mark.parametrize("table", [REULEAUX, DUMBBELLS], ids=["reuleaux", "dumbbell"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_term_contacts_reproduce_the_gradient(table, seed):
    m, q = _overlapping(table, seed)
    cs = shape_contacts(m, q, "twice")
    t = m.point_terms(q)
    assert cs.n_contacts == len(t["delta"])
    jac = contact_jacobian(cs, m.n, 2, rotations=True).toarray()
    # with "twice" every term is kept, in the order of point_terms
    delta = t["delta"]
    g = m.evaluate(q).gradient
    np.testing.assert_allclose(-m.k * jac.T @ delta, g, atol=1e-12 * np.abs(g).max())


def test_term_contacts_reproduce_the_gradient_exactly_per_row():
    """Every contact row alone: a two-body configuration of each dumbbell term type."""
    box = Box.cubic(2, 8.0)
    for index, conf in [([0, 0], [[4.0, 4.0, 0.0], [5.0, 4.49, 0.0]]),
                        ([0, 1], [[4.0, 4.0, 0.0], [4.915, 4.0, np.pi / 2]]),
                        ([1, 0], [[4.0, 4.0, 0.0], [4.0, 4.915, np.pi / 2]])]:
        m = ShapeModel(box, DUMBBELLS, index)
        q = m.dofs(conf)
        cs = shape_contacts(m, q)
        assert cs.n_contacts == 1
        row = contact_jacobian(cs, 2, 2, rotations=True).toarray()[0]
        np.testing.assert_allclose(m.evaluate(q).gradient, -m.k * m.point_terms(q)["delta"][0] * row, atol=1e-15)


LONG = ShapeTable.from_shapes([dict(kind="dumbbell", vertices=[(-1.5, 0.0), (1.5, 0.0)], radius=0.35,
                                    shaft_half_width=0.175),
                               dict(kind="dumbbell", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.25,
                                    shaft_half_width=0.125)])


@pytest.mark.parametrize("table, index, conf, once, twice", [
    (LONG, [0, 1], [[4.0, 4.0, 0.0], [4.0, 4.415, 0.0]], 1, 2),          # both lobes on one flat shaft
    (DUMBBELLS, [1, 0], [[4.0, 4.0, 0.0], [4.28, 4.915, np.pi / 2]], 2, 2),  # concave corner: lobe + shaft
    (DUMBBELLS, [0, 0], [[4.0, 4.0, 0.0], [4.5, 4.365, 0.0]], 2, 2),     # a lobe on each other's shaft
])
def test_dumbbell_parallel_convention(table, index, conf, once, twice):
    m = ShapeModel(Box.cubic(2, 10.0), table, index)
    q = m.dofs(conf)
    assert len(m.point_terms(q)["delta"]) == twice
    assert shape_contacts(m, q, "once").n_contacts == once
    assert shape_contacts(m, q, "twice").n_contacts == twice
