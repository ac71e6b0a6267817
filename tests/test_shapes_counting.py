"""Constraint counting of shape packings (VanderWerf et al. Sec. III B).

Physics checked: the contact Jacobian rows built from the shape contacts are the
gradients of the gaps (pair force = -k delta J_row); a parallel contact counts once
or twice as asked, also exactly aligned; a periodic stack of parallel circulo-lines is
all sliders when parallel contacts count twice (one free translation each: along the
axis), also when they count once (two antiparallel contacts pinch a line: a slider, not a
rattler); one short line in a brick wall is the one
slider, and the dynamical matrix's one extra zero mode is its slide; Eq. 3 and the
3N - 1 - N_s count.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.network import contact_jacobian
from jamflow.shapes.counting import count_constraints, shape_contacts, shape_model_of
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

    Every other line is shifted by 0.3 along the axis, so each neighbour pair has two
    end-middle terms and no end-end term (the shifted ends are sqrt(0.37^2 + 0.3^2) =
    0.48 > 0.4 apart): every line is free to slide along its axis.
    """
    side = 0.37 * n
    x = np.column_stack([0.5 * side + 0.3 * (np.arange(n) % 2), 0.37 * np.arange(n)])
    return Packing(position=x, diameter=np.full(n, 2 * LINES.bounding_radius[0]), box=Box.cubic(2, side),
                   orientation=np.zeros(n), shapes=LINES, shape_index=np.zeros(n, dtype=np.int64))


def test_stack_of_parallel_lines_is_all_sliders_when_counted_twice():
    n = 12
    c, rattler, slider, _ = count_constraints(_stack(n), "twice")
    assert c.n_rattlers == 0 and c.n_sliders == n and slider.all()
    assert c.n_contacts == 2 * n
    assert c.isostatic_count == 3 * n - 1 - n
    assert c.z_eq3 == pytest.approx(2.0 * (2 * n + 1) / (n - n / 3.0), rel=1e-15)
    assert c.z_contacts == pytest.approx(2.0 * 2 * n / n, rel=1e-15)
    # counted once, each line has one contact above and one below, antiparallel: pinched, held
    # along y and free along its axis, a slider (not a rattler)
    once, rattler, slider, _ = count_constraints(_stack(n), "once")
    assert once.n_rattlers == 0 and once.n_contacts == n and once.n_sliders == n and slider.all()


def _brick(slider_row: int | None = 2, overlap: float = 1e-8) -> Packing:
    """A periodic brick wall of horizontal circulo-lines, 8 rows of 3, touching end to end.

    Rows ``0.4 - overlap`` apart (two end-middle terms with each line above and below);
    in a row the lines touch end to end with the same overlap, so every line is held
    along its axis too. In row ``slider_row`` the third line is shorter (its ends 0.1
    short of its neighbours' ends): held from above and below only, it slides. The
    overlap is that of a packing near jamming: the slider's ends press on its
    neighbours' shafts, so sliding moves those contact points and turns the neighbours
    with a stress term ``~ (k overlap)^2``, below the zero-mode floor at 1e-8.
    """
    table = ShapeTable.from_shapes([dict(kind="circulo_line", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.2),
                                    dict(kind="circulo_line", vertices=[(-0.4, 0.0), (0.4, 0.0)], radius=0.2)])
    step, rise = 1.4 - overlap, 0.4 - overlap
    x, index = [], []
    for row in range(8):
        for k in range(3):
            x.append([(0.5 * step * (row % 2) + k * step) % (3 * step), row * rise])
            index.append(1 if (row, k) == (slider_row, 2) else 0)
    index = np.array(index)
    return Packing(position=np.array(x), diameter=2 * table.bounding_radius[index],
                   box=Box(np.diag([3 * step, 8 * rise])), orientation=np.zeros(len(x)), shapes=table,
                   shape_index=index)


@pytest.mark.parametrize("parallel", ["once", "twice"])
def test_a_line_between_two_parallel_rows_is_one_slider(parallel):
    """The short line of :func:`_brick` is the one slider, in both contact conventions, and
    the dynamical matrix has its slide as a zero mode.

    Zero modes of the wall: the two global translations, each of the 7 other rows sliding
    as a whole (a row is held along its axis by its own end-end contacts only: a
    collective motion, no single line is free, so no slider) and the short line's slide.
    """
    p = _brick()
    c, rattler, slider, _ = count_constraints(p, parallel)
    assert c.n_rattlers == 0 and c.n_sliders == 1 and np.flatnonzero(slider).tolist() == [8]
    assert c.isostatic_count == 3 * p.n - 1 - 1
    m, q = shape_model_of(p)
    slide = np.zeros(q.size)
    slide[2 * 8] = 1.0
    for packing, n_zero, slides in ((p, 2 + 7 + 1, True), (_brick(None), 2 + 7, False)):
        assert count_constraints(packing, parallel)[2].any() == slides
        lam, vec = np.linalg.eigh(shape_model_of(packing)[0].hessian(q).toarray())
        zero = np.abs(lam) <= 1e-13 * np.abs(lam).max()
        assert zero.sum() == n_zero
        if slides:
            assert np.linalg.norm(vec[:, zero].T @ slide) == pytest.approx(1.0, abs=1e-9)


def test_exactly_aligned_equal_lines_are_two_end_middle_contacts():
    """App. A (Fig. 16): two parallel equal lines side by side, ends aligned, are two end-middle
    contacts, as the slightly shifted pair on either side; all four feet sit at shaft ends.

    Energy convention (jamflow, stated in docs/shapes.md): every vertex meets every edge at
    its nearest point, so each aligned end pair is Fig. 19's end-middle + end-end case,
    ``U = (k/2)(delta_1^2 + delta_2^2)`` per end: ``2 k delta^2`` aligned, continuous in the
    shift down to ``k delta^2`` once the shifted ends are further apart than sigma."""
    m = ShapeModel(BOX, LINES, [0, 0])
    delta = 0.03
    for shift in (0.0, 1e-9, -1e-9, 0.3):
        q = m.dofs([[2.0, 2.0, 0.0], [2.0 + shift, 2.0 + 0.4 - delta, 0.0]])
        assert shape_contacts(m, q, "twice").n_contacts == 2
        assert shape_contacts(m, q, "once").n_contacts == 1
    energy = [m.evaluate(m.dofs([[2.0, 2.0, 0.0], [2.0 + s, 2.37, 0.0]])).energy for s in (0.0, 1e-6, 0.3)]
    assert energy[0] == pytest.approx(2.0 * delta**2, rel=1e-12)
    assert energy[1] == pytest.approx(energy[0], rel=1e-6)
    assert energy[2] == pytest.approx(delta**2, rel=1e-12)
