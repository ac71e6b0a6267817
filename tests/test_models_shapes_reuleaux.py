"""Reuleaux-triangle energy model (VanderWerf et al. Fig. 2).

Physics checked: forces and torques are minus the gradient and the Hessian is the
derivative of the gradient; the contact distance at which the energy switches on
agrees with a brute-force bisection on finely sampled outlines (shapely); energy,
forces and torques stay continuous when a contact moves from arc-arc to vertex-arc.
"""

from __future__ import annotations

import numpy as np
from shape_numerics import numerical_gradient, numerical_hessian, onset_distances
from shapely.geometry import Polygon

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.state.bodies import ShapeTable

_A = 2.0 * np.pi * np.arange(3) / 3
TABLE = ShapeTable.from_shapes([dict(kind="reuleaux", vertices=0.5 * np.stack([np.cos(_A), np.sin(_A)], 1)),
                                dict(kind="reuleaux", vertices=0.7 * np.stack([np.cos(_A), np.sin(_A)], 1))])
BOX = Box.cubic(2, 6.0)


def test_gradient_and_hessian_over_random_contacts():
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 8:
        index = list(rng.integers(0, 2, 2))
        m = ShapeModel(BOX, TABLE, index)
        conf = [[3.0, 3.0, rng.uniform(0, 2 * np.pi)],
                [3.0 + rng.uniform(-1.2, 1.2), 3.0 + rng.uniform(-1.2, 1.2), rng.uniform(0, 2 * np.pi)]]
        q = m.dofs(conf)
        if m.evaluate(q).energy == 0.0:
            continue
        checked += 1
        np.testing.assert_allclose(m.evaluate(q).gradient, numerical_gradient(m, q, 1e-6), atol=1e-8)
        hess = m.hessian(q).toarray()
        np.testing.assert_allclose(hess, numerical_hessian(m, q, 1e-6), atol=1e-7)
        np.testing.assert_allclose(hess, hess.T, atol=1e-12)


def _outline(shape: int, theta: float, centre) -> Polygon:
    c, s = np.cos(theta), np.sin(theta)
    return Polygon(TABLE.outline(shape, 20_000) @ np.array([[c, s], [-s, c]]) + np.asarray(centre))


def test_contact_distance_against_sampled_outlines():
    """Energy onset along a direction = first touch of the outlines (within their sagitta ~1e-8)."""
    rng = np.random.default_rng(3)
    for _ in range(8):
        index = list(rng.integers(0, 2, 2))
        ti, tj, phi = rng.uniform(0.0, 2.0 * np.pi, 3)
        e = np.array([np.cos(phi), np.sin(phi)])
        model_r, outline_r = onset_distances(ShapeModel(BOX, TABLE, index), _outline, index, ti, tj, e,
                                             (3.0, 3.0), 0.2, 2.5)
        assert -1e-10 <= model_r - outline_r <= 4e-8


def test_continuous_from_arc_arc_to_vertex_arc():
    m = ShapeModel(BOX, TABLE, [0, 0])
    # the first shows an arc to the right (theta = pi); the second turns from showing an
    # arc to the left (theta = 0) towards a vertex (theta = 1): arc-arc, then vertex-arc
    start, end = m.dofs([[3.0, 3.0, np.pi], [3.72, 3.0, 0.0]]), m.dofs([[3.0, 3.0, np.pi], [3.72, 3.0, 1.0]])
    side = float(np.linalg.norm(TABLE.vertex_list(0)[1] - TABLE.vertex_list(0)[0]))

    def vertices(conf):
        c, s_ = np.cos(conf[2]), np.sin(conf[2])
        return TABLE.vertex_list(0) @ np.array([[c, s_], [-s_, c]]) + np.asarray(conf[:2])

    a0 = vertices([3.0, 3.0, np.pi])[0]  # centre of the first's right arc
    # start: arc-arc between the arcs centred on vertex 0 of each, sigma = 2 s
    r_start = np.linalg.norm(vertices([3.72, 3.0, 0.0])[0] - a0)
    assert abs(m.evaluate(start).energy - 0.5 * (2 * side - r_start) ** 2) < 1e-15
    # end: a vertex of the second on the first's arc, sigma = s
    r_end = np.min(np.linalg.norm(vertices([3.72, 3.0, 1.0]) - a0, axis=1))
    assert abs(m.evaluate(end).energy - 0.5 * (side - r_end) ** 2) < 1e-15
    jumps = []
    for n in (401, 4001):
        u, g = [], []
        for a in np.linspace(0.0, 1.0, n):
            ev = m.evaluate((1 - a) * start + a * end)
            u.append(ev.energy)
            g.append(ev.gradient)
        u, g = np.array(u), np.array(g)
        assert np.all(u > 0.0)
        jumps.append((np.max(np.abs(np.diff(u))), np.max(np.abs(np.diff(g, axis=0)))))
    for coarse, fine in zip(*jumps):
        assert fine < coarse / 5.0, jumps


def test_corners_crossing_tip_to_tip_cost_their_small_overlap():
    """Two corners whose tips cross by ``eps`` overlap by ``O(eps)``: the energy stays of order ``k eps^2``
    (an arc-arc term of the two arcs centred on the tips would add ``(k/2) (s_i + s_j - eps)^2``)."""
    m = ShapeModel(BOX, TABLE, [0, 1])
    rng = np.random.default_rng(11)
    tip_i = TABLE.vertex_list(0)[0]
    for _ in range(40):
        tilt = rng.uniform(-0.3, 0.3)
        c, s_ = np.cos(np.pi + tilt), np.sin(np.pi + tilt)
        rot = np.array([[c, -s_], [s_, c]])
        # the tip of j (its vertex 0, pointing back at i) placed eps inside i's tip
        gap = rng.uniform(-1e-3, 1e-3, 2)
        centre = np.array([3.0, 3.0]) + tip_i + gap - rot @ TABLE.vertex_list(1)[0]
        ev = m.evaluate(m.dofs([[3.0, 3.0, 0.0], [*centre, np.pi + tilt]]))
        assert ev.energy <= 4.0 * float(gap @ gap), (tilt, gap, ev.energy)
