"""``Packing.to_freud`` / ``from_freud``: freud's box conventions, checked by freud's own neighbour search.

freud holds boxes and points in single precision, so every comparison with freud's
numbers allows a few float32 roundings (``FLOAT32_RTOL``) of the box size.
"""

from __future__ import annotations

import freud
import numpy as np
import pytest

from jamflow.box import Box
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import Packing, near_pairs
from jamflow.tolerances import FLOAT32_RTOL

#: a few float32 roundings of a unit-size box (coordinates, then differences of them)
TOL = 8 * FLOAT32_RTOL


def _sheared(d: int, seed: int = 4) -> Packing:
    box = Box.lees_edwards([1.0, 1.3, 0.9][:d], 0.37)
    rng = np.random.default_rng(seed)
    return Packing(box.wrap(box.to_cartesian(rng.random((60, d)))), rng.uniform(0.05, 0.08, 60), box)


@pytest.mark.parametrize("d", [2, 3])
def test_box_conventions_and_round_trip(d):
    p = _sheared(d)
    box, points = p.to_freud()
    assert box.dimensions == d and box.is2D == (d == 2)
    np.testing.assert_allclose(box.to_matrix()[:d, :d], p.box.matrix, rtol=FLOAT32_RTOL, atol=0)
    # freud's cell is centred on the origin: its fractional coordinates are jamflow's
    np.testing.assert_allclose(box.make_fractional(points)[:, :d], p.box.to_fractional(p.position), atol=TOL)
    np.testing.assert_allclose(box.wrap(points), points, atol=TOL)
    if d == 2:
        np.testing.assert_array_equal(points[:, 2], 0.0)
    back = Packing.from_freud(box, points, p.diameter, protocol="freud")
    np.testing.assert_allclose(back.box.matrix, p.box.matrix, rtol=FLOAT32_RTOL, atol=0)
    np.testing.assert_allclose(back.box.minimum_image(back.position - p.position), 0.0, atol=TOL)
    assert back.protocol == "freud"


@pytest.mark.parametrize("d", [2, 3])
def test_freud_finds_the_same_near_pairs_in_a_sheared_box(d):
    p = _sheared(d)
    box, points = p.to_freud()
    # freud's cutoff above the largest 1.5 sigma_ij by far more than float32 rounding
    r_max = 1.6 * float(p.diameter.max())
    nlist = freud.locality.AABBQuery(box, points).query(points, {"r_max": r_max, "exclude_ii": True}).toNeighborList()
    theirs = {(min(i, j), max(i, j)): r for i, j, r in zip(nlist.query_point_indices, nlist.point_indices,
                                                           nlist.distances)}
    pairs, h = near_pairs(p, 0.5)  # r <= 1.5 sigma_ij <= r_max
    mine = {(i, j): r for i, j, r in zip(pairs.i, pairs.j, pairs.distance)}
    assert mine and set(mine) <= set(theirs)
    assert all(abs(theirs[k] - r) < TOL for k, r in mine.items())


def test_freud_counts_the_contacts_of_a_jammed_packing():
    p = calippso(random_packing(40, 2, 0.5, "bi", seed=5)).packing
    box, points = p.to_freud()
    nlist = freud.locality.AABBQuery(box, points).query(
        points, {"r_max": float(p.diameter.max()) * (1 + 1e-3), "exclude_ii": True}).toNeighborList()
    i, j = nlist.query_point_indices, nlist.point_indices
    h = nlist.distances / (0.5 * (p.diameter[i] + p.diameter[j])) - 1
    # CALiPPSO's contacts touch to ~1e-9; in float32 a touching pair has |h| within a few roundings
    touching = {(min(a, b), max(a, b)) for a, b, g in zip(i, j, h) if abs(g) <= TOL / p.diameter.min()}
    assert {tuple(c) for c in p.contacts.tolist()} <= touching


def test_freud_hexatic_order_equals_jamflows_in_a_sheared_box():
    # two independent psi6 codes on one sheared packing: they agree where the 6th neighbour is unambiguous
    from jamflow.analysis.structure import hexatic_order, nearest_neighbours

    p = _sheared(2, seed=11)
    box, points = p.to_freud()
    op = freud.order.Hexatic(k=6)
    op.compute((box, points), neighbors={"num_neighbors": 6})
    _, dx = nearest_neighbours(p, 7)
    r = np.linalg.norm(dx, axis=2)
    clear = r[:, 6] - r[:, 5] > 100 * TOL  # float32 distances cannot swap the 6th and 7th neighbours
    assert clear.sum() > 0.8 * p.n
    np.testing.assert_allclose(op.particle_order[clear], hexatic_order(p)[clear], atol=100 * TOL)
