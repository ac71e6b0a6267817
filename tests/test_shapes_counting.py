"""Constraint counting of shape packings (VanderWerf et al. Sec. III B).

Physics checked: the contact Jacobian rows built from the shape contacts are the
gradients of the gaps (pair force = -k delta J_row); a parallel contact counts once
or twice as asked; a periodic stack of parallel circulo-lines is all sliders when
parallel contacts count twice (one free translation each: along the axis) and all
rattlers when they count once; Eq. 3 and the 3N - 1 - N_s count.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.network import contact_jacobian
from jamflow.shapes.counting import count_constraints, shape_contacts
from jamflow.state.bodies import ShapeTable
from jamflow.state.packing import Packing

LINES = ShapeTable.from_shapes([dict(kind="circulo_line", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.2)])
ELLIPSES = ShapeTable.from_shapes([dict(kind="ellipse", semi_axes=(0.8, 0.35)), dict(kind="ellipse", semi_axes=(0.5, 0.45))])
BOX = Box.cubic(2, 6.0)


@pytest.mark.parametrize("table, index, conf", [
    (LINES, [0, 0], [[2.0, 2.0, 0.0], [2.1, 2.0 + 0.65 - 0.03, np.pi / 2]]),      # end-middle
    (LINES, [0, 0], [[2.0, 2.0, 0.3], [3.25, 2.45, 0.2]]),                           # end-end
    (ELLIPSES, [0, 1], [[3.0, 3.0, 0.3], [3.9, 3.4, 1.4]]),
    (ELLIPSES, [0, 0], [[3.0, 3.0, 1.0], [3.5, 3.6, -0.7]]),
])
def test_jacobian_rows_are_gap_gradients(table, index, conf):
    """Each contact's Jacobian row is the gradient of its gap.

    Circulo terms: ``U = (k/2) w delta^2`` with ``delta = sigma - r`` the gap, so
    ``g = -k w delta J_row`` exactly. Ellipses: ``delta = r (F^-1/2 - 1)`` has the
    gradient of ``F`` (the Perram–Wertheim normal and arms) only on the contact
    surface; off it the ``grad r`` part tilts it by O(delta / r), so the pair is
    moved to an overlap of ``1e-8`` of the contact distance (tilt ~1e-8).
    """
    m = ShapeModel(BOX, table, index)
    q = m.dofs(conf)
    if table is ELLIPSES:
        dx = q[2:4] - q[0:2]
        r = np.linalg.norm(dx)
        sigma = r + m.pair_table(q)["energy"][0] ** 0.5 * np.sqrt(2.0)  # U = delta^2 / 2 at k = 1
        q[2:4] = q[0:2] + dx * sigma * (1.0 - 1e-8) / r
    cs = shape_contacts(m, q)
    assert cs.n_contacts == 1
    row = contact_jacobian(cs, 2, 2, rotations=True).toarray()[0]
    g = m.evaluate(q).gradient
    # the pair force is repulsive along the gap gradient: g = -c J_row with c > 0
    c = -(g @ row) / (row @ row)
    assert c > 0.0
    np.testing.assert_allclose(g, -c * row, atol=(1e-6 if table is ELLIPSES else 1e-12) * np.abs(g).max())
    if table is LINES:
        t = m.contact_terms(q)
        # one vertex-edge geometry (an end-end contact appears from both ends, same r)
        assert np.ptp(t["r"]) < 1e-14
        assert c == pytest.approx(float(np.sum(t["weight"] * t["delta"])), rel=1e-12)


def test_parallel_contact_counted_once_or_twice():
    m = ShapeModel(BOX, LINES, [0, 0])
    q = m.dofs([[2.0, 2.0, 0.0], [2.2, 2.37, 0.01]])
    assert shape_contacts(m, q, "once").n_contacts == 1
    twice = shape_contacts(m, q, "twice")
    assert twice.n_contacts == 2
    # the two rows are the two end-middle contacts: distinct contact points
    assert np.linalg.norm(twice.arm_i[0] - twice.arm_i[1]) > 0.5
    with pytest.raises(ValueError, match="once or twice"):
        shape_contacts(m, q, "thrice")


def _stack(n: int) -> Packing:
    """A periodic column of ``n`` horizontal circulo-lines, neighbours 0.37 apart (overlap 0.03).

    Every other line is shifted by 0.1 along the axis, so each neighbour pair has
    two end-middle terms (exactly aligned ends would sit on the end-end boundary).
    """
    side = 0.37 * n
    x = np.column_stack([0.5 * side + 0.1 * (np.arange(n) % 2), 0.37 * np.arange(n)])
    return Packing(position=x, diameter=np.full(n, 2 * LINES.bounding_radius[0]), box=Box.cubic(2, side),
                   orientation=np.zeros(n), shapes=LINES, shape_index=np.zeros(n, dtype=np.int64))


def test_stack_of_parallel_lines_is_all_sliders_when_counted_twice():
    n = 12
    c, rattler, slider, _ = count_constraints(_stack(n), "twice")
    assert c.n_rattlers == 0 and c.n_sliders == n and slider.all()
    assert c.n_contacts == 2 * n
    assert c.isostatic_count == 3 * n - 1 - n
    assert c.z == pytest.approx(2.0 * (2 * n + 1) / (n - n / 3.0), rel=1e-15)
    once, rattler, slider, _ = count_constraints(_stack(n), "once")
    assert once.n_rattlers == n and once.n_contacts == 0 and not slider.any()
