"""Contact angles of shape packings (Fig. 14): tip contacts at 0, side contacts at pi/2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.io import read_packing
from jamflow.shapes.analysis import contact_angle_distribution, contact_angles
from jamflow.shapes.counting import count_constraints
from jamflow.state.bodies import ShapeTable
from jamflow.state.packing import Packing

LINES = ShapeTable.from_shapes([dict(kind="circulo_line", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.2)])


def _pair(conf) -> Packing:
    conf = np.asarray(conf, dtype=float)
    return Packing(position=conf[:, :2], diameter=np.full(len(conf), 1.4), box=Box.cubic(2, 6.0),
                   orientation=conf[:, 2], shapes=LINES, shape_index=np.zeros(len(conf), dtype=np.int64))


def test_t_contact_angles():
    # a periodic column of T's: vertical lines standing on the middle of horizontal
    # ones: psi = pi/2 on the horizontal (side contact), 0 on the vertical (tip);
    # every body is pinched between two antiparallel contacts along the column: it carries
    # force and slides across it, a slider and not a rattler, so its contacts count
    n = 8
    conf = []
    for k in range(n // 2):
        y = 1.5 * k
        conf.append([3.0, y, 0.0])
        conf.append([3.0, y + 0.75, np.pi / 2])
    p = _pair(conf).evolve(box=Box.orthogonal([6.0, 1.5 * n / 2]))
    # vertical line: centre 0.75 above, half length 0.5, radius 0.2: tips at 0.25 and 1.25
    # from the horizontal at 0 and the next at 1.5: overlaps 0.4 - 0.25 = 0.15 each
    counts, rattler, slider, _ = count_constraints(p)
    assert not rattler.any() and slider.all() and counts.n_sliders == n
    np.testing.assert_array_equal(contact_angles(p), contact_angles(p, rattlers=True))
    psi = contact_angles(p)
    assert psi.size == 2 * n
    np.testing.assert_allclose(np.sort(psi), np.repeat([0.0, np.pi / 2], n), atol=1e-12)
    centres, density = contact_angle_distribution(psi)
    assert np.sum(density) * (centres[1] - centres[0]) == pytest.approx(1.0)


def test_angles_of_a_jammed_packing_lie_in_range():
    p = read_packing(Path(__file__).parent / "data" / "shapes_circulo_line_a1.1_n16_p1e-6.nc", None)
    psi = contact_angles(p, "twice")
    assert psi.size == 2 * 45
    assert np.all((psi >= 0.0) & (psi <= np.pi / 2))


def test_polygons_have_no_contact_angle():
    tri = ShapeTable.from_shapes([dict(kind="circulo_polygon", radius=0.1,
                                       vertices=[(np.cos(a), np.sin(a)) for a in 2 * np.pi * np.arange(3) / 3])])
    p = Packing(position=np.array([[1.0, 1.0], [3.0, 3.0]]), diameter=np.full(2, 2.2), box=Box.cubic(2, 6.0),
                orientation=np.zeros(2), shapes=tri, shape_index=np.zeros(2, dtype=np.int64))
    with pytest.raises(ValueError, match="elongated"):
        contact_angles(p)
