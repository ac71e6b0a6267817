"""Circulo-line and circulo-polygon energy model (VanderWerf et al. App. A).

Physics checked: forces and torques are minus the gradient of the energy for every
contact type (end-middle, parallel, nearly parallel, end-end, the end-middle/end-end
boundary of Fig. 19, polygon vertex-edge and vertex-vertex), also astride the
type boundaries; energy, forces and torques are continuous across them (the jumps of
a scan shrink with the scan step); overlaps agree with exact polygon-offset geometry
(shapely); the Hessian is the derivative of the gradient and annihilates rigid
translations; the parallel / end-end weights of App. A; the energy equals a NumPy sum
over every vertex-edge term (the kernel skips far vertices).
"""

from __future__ import annotations

import numpy as np
import pytest
from shape_numerics import numerical_gradient, numerical_hessian
from shapely.geometry import LineString, Polygon

from jamflow.box import Box
from jamflow.models.shapes import ShapeModel
from jamflow.state.bodies import ShapeTable

BOX = Box.cubic(2, 6.0)
LINE = dict(kind="circulo_line", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.2)
SHORT = dict(kind="circulo_line", vertices=[(-0.3, 0.0), (0.3, 0.0)], radius=0.15)


def _regular(n: int, size: float, radius: float) -> dict:
    a = 2.0 * np.pi * np.arange(n) / n
    return dict(kind="circulo_polygon", vertices=np.stack([size * np.cos(a), size * np.sin(a)], 1), radius=radius)


TABLE = ShapeTable.from_shapes([LINE, SHORT, _regular(3, 0.4, 0.1), _regular(5, 0.35, 0.08)])


def model(shapes: tuple[int, int]) -> ShapeModel:
    return ShapeModel(BOX, TABLE, list(shapes))


# (shapes, configuration rows (x, y, theta), expected number of vertex-edge terms, label)
CONTACTS = [
    ((0, 1), [[2.0, 2.0, 0.0], [2.1, 2.0 + 0.2 + 0.15 + 0.3 - 0.05, np.pi / 2]], 1, "end-middle"),
    ((0, 1), [[2.0, 2.0, 0.0], [2.0, 2.3, 0.0]], 2, "parallel"),
    ((0, 1), [[2.0, 2.0, 0.0], [2.0, 2.3, 0.02]], 2, "nearly parallel"),
    ((0, 1), [[2.0, 2.0, 0.0], [2.0 + 0.5 + 0.3 + 0.3, 2.05, 0.02]], 2, "end-end"),
    # end of 1 just inside the shaft of 0, end of 0 beyond the end of 1: Fig. 19 (EM + EE)
    ((0, 1), [[2.0, 2.0, 0.0], [2.0 + 0.5 + 0.3 - 0.05, 2.3, 0.0]], 2, "end-middle + end-end"),
    ((2, 3), [[2.0, 2.0, 0.3], [2.0 + 0.2 + 0.35 + 0.1, 2.05, 0.1]], None, "triangle-pentagon"),
    ((2, 2), [[2.0, 2.0, 0.0], [2.0 + 0.8 + 0.15, 2.0, np.pi / 3]], None, "vertex-vertex"),
    ((0, 3), [[2.0, 2.0, 0.7], [2.3, 2.5, -0.4]], None, "line-pentagon"),
]


@pytest.mark.parametrize("shapes, conf, n_terms, label", CONTACTS, ids=[c[3] for c in CONTACTS])
def test_force_and_torque_are_minus_the_gradient(shapes, conf, n_terms, label):
    m = model(shapes)
    q = m.dofs(conf)
    ev = m.evaluate(q)
    assert ev.energy > 0.0, f"{label}: the configuration must overlap"
    if n_terms is not None:
        assert len(m.contact_terms(q)["r"]) == n_terms
    # central differences: truncation h^2 U''' ~ 1e-12, round-off eps U / h ~ 1e-10
    num = numerical_gradient(m, q, 1e-6)
    np.testing.assert_allclose(ev.gradient, num, atol=1e-8)
    # Newton's third law and no net torque about the origin for the pair
    g = m.positions(ev.gradient)
    np.testing.assert_allclose(g[:, :2].sum(axis=0), 0.0, atol=1e-14)
    x = m.positions(q)
    total_torque = g[:, 2].sum() + np.sum(x[:, 0] * g[:, 1] - x[:, 1] * g[:, 0])
    assert abs(total_torque) < 1e-13


def test_parallel_contact_is_two_end_middle_terms_of_equal_overlap():
    m = model((0, 0))
    # two identical lines, parallel, offset along the axis by 0.4, 0.3 apart
    q = m.dofs([[2.0, 2.0, 0.0], [2.4, 2.3, 0.0]])
    terms = m.contact_terms(q)
    np.testing.assert_allclose(terms["delta"], 0.1, rtol=1e-13)
    assert np.all((terms["t"] > 0.0) & (terms["t"] < 1.0))  # both end-middle
    np.testing.assert_allclose(m.evaluate(q).energy, 2 * 0.5 * 0.1**2, rtol=1e-12)


def test_end_end_contact_has_energy_k_delta_squared():
    m = model((0, 0))
    q = m.dofs([[2.0, 2.0, 0.0], [2.0 + 1.0 + 0.3, 2.0, 0.0]])  # collinear, ends 0.3 apart
    terms = m.contact_terms(q)
    assert np.all((terms["t"] == 0.0) | (terms["t"] == 1.0))
    np.testing.assert_allclose(m.evaluate(q).energy, 0.1**2, rtol=1e-12)  # k delta^2, App. A c


def test_polygon_vertex_counts_twice():
    # App. A 2: a polygon vertex belongs to two edges, so an end-middle overlap costs k delta^2
    m = model((2, 0))
    tri = TABLE.vertex_list(2)
    conf = [[2.0, 2.0, 0.0], [2.0 + 0.4 + 0.3 - 0.05, 2.0 - 1e-3, np.pi / 2]]
    q = m.dofs(conf)
    terms = m.contact_terms(q)
    vertex_terms = terms["vertex_body"] == 0
    assert np.count_nonzero(vertex_terms) == 1 and terms["weight"][vertex_terms][0] == 2.0
    assert np.allclose(tri[terms["vertex"][vertex_terms][0]], (0.4, 0.0))
    np.testing.assert_allclose(m.evaluate(q).energy, terms["delta"][0] ** 2, rtol=1e-12)



def test_time_unit_is_the_period_of_a_face_contact():
    """FIRE's time unit ``sqrt(m / (K k))``: a polygon's face on a line (two vertex terms of weight 2) has
    normal curvature ``4 k`` (``K`` of polygons); a line's end on another's middle ``k``, at most the
    lines' ``K`` (their stiffest contact, with rotations: tests/test_models_shapes_time_unit.py)."""
    long_line = dict(kind="circulo_line", vertices=[(-1.0, 0.0), (1.0, 0.0)], radius=0.2)
    table = ShapeTable.from_shapes([_regular(3, 0.4, 0.1), long_line, LINE, SHORT])
    cases = [((0, 1), [[2.0, 2.0, 0.0], [2.0 - 0.2 - 0.3 + 0.05, 2.0, np.pi / 2]], 2),
             ((2, 3), [[2.0, 2.0, 0.0], [2.0 + 0.5 + 0.35 - 0.05, 2.0 - 1e-3, np.pi / 2]], 1)]
    for index, conf, n_terms in cases:
        m = ShapeModel(BOX, table, list(index))
        q = m.dofs(conf)
        assert len(m.contact_terms(q)["delta"]) == n_terms
        # body 1 moves along x, the terms' normal
        curvature = m.hessian(q).toarray()[2, 2] * m.time_unit**2 / m.mass
        if n_terms == 2:
            np.testing.assert_allclose(curvature, 1.0, rtol=1e-9)
        else:
            np.testing.assert_allclose(m.hessian(q).toarray()[2, 2], m.k, rtol=1e-9)
            assert curvature <= 1.0

# scans through contact-type boundaries: (shapes, start, end, label); the pair moves
# linearly in (x, y, theta) from start to end
SCANS = [
    # slide a parallel neighbour off the end: 2 EM -> EM + EE (Fig. 19) -> EE (Fig. 18)
    ((0, 1), [[2.0, 2.0, 0.0], [2.0, 2.32, 0.0]], [[2.0, 2.0, 0.0], [2.85, 2.32, 0.0]], "parallel to end-end"),
    # rotate a neighbour through parallel: EM -> 2 EM (Fig. 17) -> EM
    ((0, 0), [[2.0, 2.0, 0.0], [2.5, 2.35, -0.3]], [[2.0, 2.0, 0.0], [2.5, 2.35, 0.3]], "through nearly parallel"),
    # slide an end-middle contact over the end of the shaft (Fig. 15 -> 19 -> 18)
    ((0, 1), [[2.0, 2.0, 0.0], [2.3, 2.6, np.pi / 2]], [[2.0, 2.0, 0.0], [2.6, 2.6, np.pi / 2]], "end-middle to end-end"),
    # roll a triangle vertex over a pentagon's vertices
    ((2, 3), [[2.0, 2.0, 0.0], [2.78, 1.7, 0.2]], [[2.0, 2.0, 0.0], [2.78, 2.3, 0.2]], "polygon vertex over vertex"),
]


def _signature(m: ShapeModel, q: np.ndarray) -> tuple:
    """Which vertex meets which edge, and whether at its middle (the contact type)."""
    t = m.contact_terms(q)
    middle = (t["t"] > 0.0) & (t["t"] < 1.0)
    return tuple(zip(t["vertex_body"].tolist(), t["vertex"].tolist(), t["edge"].tolist(), middle.tolist()))


def _scan(m: ShapeModel, start, end, n: int) -> tuple[np.ndarray, np.ndarray, set]:
    q0, q1 = m.dofs(start), m.dofs(end)
    u = np.empty(n)
    g = np.empty((n, q0.size))
    types = set()
    for s, a in enumerate(np.linspace(0.0, 1.0, n)):
        q = (1 - a) * q0 + a * q1
        ev = m.evaluate(q)
        u[s], g[s] = ev.energy, ev.gradient
        types.add(_signature(m, q))
    return u, g, types


@pytest.mark.parametrize("shapes, start, end, label", SCANS, ids=[s[3] for s in SCANS])
def test_energy_force_torque_continuous_across_boundaries(shapes, start, end, label):
    m = model(shapes)
    jumps = []
    for n in (401, 4001):
        u, g, types = _scan(m, start, end, n)
        assert np.all(u > 0.0), f"{label}: the pair must stay in contact along the scan"
        assert len(types) >= 2, f"{label}: the scan must cross contact-type boundaries, saw {types}"
        jumps.append((np.max(np.abs(np.diff(u))), np.max(np.abs(np.diff(g, axis=0)))))
    # a discontinuity would leave the largest jump unchanged when the step shrinks
    # tenfold; for U in C^1 with bounded second derivatives both shrink ~tenfold
    for coarse, fine in zip(jumps[0], jumps[1]):
        assert fine < coarse / 5.0, f"{label}: largest jumps of (U, gradient) at steps 1/400, 1/4000: {jumps}"


def _core(shape: int, conf) -> tuple:
    v = TABLE.vertex_list(shape)
    c, s = np.cos(conf[2]), np.sin(conf[2])
    w = v @ np.array([[c, s], [-s, c]]) + np.asarray(conf[:2])
    return (LineString(w) if len(v) == 2 else Polygon(w)), float(TABLE.radius[shape])


def test_overlap_agrees_with_exact_polygon_offset_geometry():
    """Overlap iff the cores are closer than R_i + R_j; deepest term = R_i + R_j - core distance.

    The circulo-shape is the Minkowski sum of its core with a disk (App. B), so two
    shapes overlap exactly when their cores are closer than the sum of the radii; for
    convex cores the closest points are a vertex and an edge, which the model scans.
    """
    rng = np.random.default_rng(23)
    overlapping = 0
    for _ in range(300):
        shapes = tuple(rng.integers(0, len(TABLE), 2))
        conf = [[2.0, 2.0, rng.uniform(0, 2 * np.pi)],
                [2.0 + rng.uniform(-1.3, 1.3), 2.0 + rng.uniform(-1.3, 1.3), rng.uniform(0, 2 * np.pi)]]
        (ci, ri), (cj, rj) = _core(shapes[0], conf[0]), _core(shapes[1], conf[1])
        if ci.intersects(cj):
            continue  # crossing cores: outside the model's domain (deep overlap)
        gap = ci.distance(cj) - ri - rj
        m = model(shapes)
        q = m.dofs(conf)
        terms = m.contact_terms(q)
        assert (m.evaluate(q).energy > 0.0) == (gap < 0.0)
        if gap < 0.0:
            overlapping += 1
            np.testing.assert_allclose(terms["delta"].max(), -gap, rtol=1e-12, atol=1e-14)
    assert overlapping > 50


@pytest.mark.parametrize("shapes, conf, n_terms, label", CONTACTS, ids=[c[3] for c in CONTACTS])
def test_hessian_is_derivative_of_gradient(shapes, conf, n_terms, label):
    m = model(shapes)
    q = m.dofs(conf)
    h_model = m.hessian(q).toarray()
    h_num = numerical_hessian(m, q, 1e-6)
    # finite differences of the gradient: truncation ~h^2 g''' plus round-off eps g / h
    np.testing.assert_allclose(h_model, h_num, atol=1e-7)
    # the complex step carries no truncation: symmetric to round-off
    np.testing.assert_allclose(h_model, h_model.T, atol=1e-12)
    for axis in range(2):
        t = np.zeros(q.size)
        t[axis: 2 * m.n: 2] = 1.0
        assert np.max(np.abs(h_model @ t)) < 1e-13


@pytest.mark.parametrize("shapes, start, end, label", SCANS, ids=[s[3] for s in SCANS])
def test_gradient_astride_contact_type_boundaries(shapes, start, end, label):
    """Minus the gradient at configurations within 1e-9 of a type boundary.

    Across a boundary U is C^1 but its second derivative jumps, so the central
    difference with step h errs by at most ~h max|U''| (|U''| <~ 2k = 2): h = 1e-7
    gives <~ 2e-7, round-off eps U / h ~ 1e-11; tolerance 1e-6.
    """
    m = model(shapes)
    q0, q1 = m.dofs(start), m.dofs(end)
    grid = np.linspace(0.0, 1.0, 201)
    sig = [_signature(m, (1 - a) * q0 + a * q1) for a in grid]
    crossings = 0
    for s in range(len(grid) - 1):
        if sig[s] == sig[s + 1]:
            continue
        lo, hi = grid[s], grid[s + 1]
        for _ in range(60):  # bisect the boundary to ~1e-12 in the scan parameter
            mid = 0.5 * (lo + hi)
            if _signature(m, (1 - mid) * q0 + mid * q1) == sig[s]:
                lo = mid
            else:
                hi = mid
        for a in (lo - 1e-9, hi + 1e-9):
            q = (1 - a) * q0 + a * q1
            np.testing.assert_allclose(m.evaluate(q).gradient, numerical_gradient(m, q, 1e-7), atol=1e-6)
        crossings += 1
    assert crossings >= 1


def _all_vertex_edge_energy(m: ShapeModel, conf: np.ndarray) -> float:
    """Every vertex of each body against every edge of the other, nothing skipped (NumPy)."""
    total = 0.0
    for a, b in ((0, 1), (1, 0)):
        va, vb = (TABLE.vertex_list(m.shape_index[c]) for c in (a, b))
        rot = [np.array([[np.cos(conf[c][2]), -np.sin(conf[c][2])], [np.sin(conf[c][2]), np.cos(conf[c][2])]])
               for c in (a, b)]
        p = va @ rot[0].T + conf[a][:2]
        s = vb @ rot[1].T + conf[b][:2]
        edges = [(0, 1)] if len(vb) == 2 else [(e, (e + 1) % len(vb)) for e in range(len(vb))]
        sigma = TABLE.radius[m.shape_index[a]] + TABLE.radius[m.shape_index[b]]
        weight = 1.0 if len(va) == 2 else 2.0
        for e, f in edges:
            d = s[f] - s[e]
            t = np.clip((p - s[e]) @ d / (d @ d), 0.0, 1.0)
            r = np.linalg.norm(p - s[e] - t[:, None] * d, axis=1)
            total += float(np.sum(0.5 * weight * np.clip(sigma - r, 0.0, None) ** 2))
    return total


@pytest.mark.parametrize("shapes", [(0, 1), (2, 3), (3, 3), (0, 2)], ids=["lines", "tri-pent", "pent-pent", "line-tri"])
def test_energy_equals_the_sum_over_every_vertex_edge_term(shapes):
    # the kernel skips vertices beyond the other body's vertex radius plus sigma; a sum
    # over every vertex and edge must give the same energy, in and near contact
    m = model(shapes)
    rng = np.random.default_rng(7)
    bound = TABLE.bounding_radius[list(shapes)].sum()
    touching = 0
    for _ in range(200):
        angle, dist = rng.uniform(0.0, 2.0 * np.pi), rng.uniform(0.5, 1.02) * bound
        conf = np.array([[2.0, 2.0, rng.uniform(0.0, 2.0 * np.pi)],
                         [2.0 + dist * np.cos(angle), 2.0 + dist * np.sin(angle), rng.uniform(0.0, 2.0 * np.pi)]])
        q = m.dofs(conf)
        try:
            m.check_cores(q)
        except ValueError:
            continue  # crossed cores are outside the contact model
        energy = m.evaluate(q).energy
        assert energy == pytest.approx(_all_vertex_edge_energy(m, conf), rel=1e-12, abs=1e-15)
        touching += energy > 0.0
    assert touching > 50
