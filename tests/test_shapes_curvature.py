"""Curvatures of the contact constraints (VanderWerf et al. Sec. III C, Table II) and the caged
circulo-line's feasible region (Figs. 12-13).

Physics checked: the gradient and Hessian of every gap (a vertex against a line, seen by
the vertex's body and by the line's body; two vertices) are those of the exact
point-to-segment distance (finite differences); a disk's constraint has the curvatures
-1 / (R_i + R_j) and 0; the middle particle's curvatures follow the closed form
``kappa_1 kappa_2 = -1 / (1 + gamma^2)^2`` and ``kappa_1 + kappa_2 = h / (1 + gamma^2)^(3/2)``
(App. C's second derivatives); on a jammed packing the end particle of a shaft contact has
an exactly flat direction, parallel ends are flat to the packing's misalignment and end-end
contacts are disks of radius R_i + R_j. Three points hold a short line (a bounded region
whose volume and surface scale as dR^(5/2) and dR^(3/2)) but not a long one, which escapes
along the free rotation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.io import read_packing
from jamflow.shapes.curvature import (
    _line_gap_end,
    _line_gap_middle,
    _point_gap,
    constraint_curvatures,
    curvature_dataset,
    principal_curvatures,
)
from jamflow.shapes.feasible import (
    cage_directions,
    cage_gaps,
    cage_points,
    cage_stability,
    feasible_scaling,
)

DATA = Path(__file__).parent / "data" / "shapes_circulo_line_a1.03_n32_p1e-7.nc"


def _rot(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def _derivatives(f, q, h=1e-5):
    """Central-difference gradient and Hessian of a scalar ``f`` of 3 coordinates."""
    g = np.zeros(3)
    hess = np.zeros((3, 3))
    for a in range(3):
        e = np.eye(3)[a] * h
        g[a] = (f(q + e) - f(q - e)) / (2 * h)
        for b in range(3):
            d = np.eye(3)[b] * h
            hess[a, b] = (f(q + e + d) - f(q + e - d) - f(q - e + d) + f(q - e - d)) / (4 * h * h)
    return g, hess


def _segment_distance(p, a, b):
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return float(np.linalg.norm(p - a - t * (b - a)))


def test_gap_derivatives_are_those_of_the_point_to_segment_distance():
    v = np.array([0.4, 0.0])            # a vertex of the moving body (body frame)
    s0, s1 = np.array([-0.5, 0.0]), np.array([0.5, 0.0])   # the other body's edge (its frame)
    other, theta_o = np.array([0.45, 0.6]), 0.1
    q0 = np.array([0.1, -0.05, 0.3])
    # the vertex on the other's shaft, the other body fixed
    S0, S1 = other + _rot(theta_o) @ s0, other + _rot(theta_o) @ s1
    f = lambda q: _segment_distance(q[:2] + _rot(q[2]) @ v, S0, S1)  # noqa: E731
    normal = np.array([[0.0, -1.0], [1.0, 0.0]]) @ (S1 - S0) / np.linalg.norm(S1 - S0)
    arm = _rot(q0[2]) @ v
    normal = normal if normal @ (q0[:2] + arm - S0) > 0 else -normal
    g, h = _line_gap_end(arm, normal)
    gn, hn = _derivatives(f, q0)
    np.testing.assert_allclose(g, gn, atol=1e-9)
    np.testing.assert_allclose(h, hn, atol=1e-5)
    # the same point, fixed, against the moving body's shaft
    point = q0[:2] + arm
    qm = np.array([*other, theta_o])
    fm = lambda q: _segment_distance(point, q[:2] + _rot(q[2]) @ s0, q[:2] + _rot(q[2]) @ s1)  # noqa: E731
    g, h = _line_gap_middle(point, qm[:2], _rot(theta_o) @ s0, normal if normal @ (point - S0) > 0 else -normal)
    gn, hn = _derivatives(fm, qm)
    np.testing.assert_allclose(np.abs(g), np.abs(gn), atol=1e-9)
    np.testing.assert_allclose(g, -gn if g @ gn < 0 else gn, atol=1e-9)
    np.testing.assert_allclose(h, hn, atol=1e-5)
    # two vertices (end-end)
    fixed = np.array([0.9, -0.2])
    fe = lambda q: float(np.linalg.norm(q[:2] + _rot(q[2]) @ v - fixed))  # noqa: E731
    g, h = _point_gap(arm, fixed, q0[:2])
    gn, hn = _derivatives(fe, q0)
    np.testing.assert_allclose(g, gn, atol=1e-9)
    np.testing.assert_allclose(h, hn, atol=1e-5)


def test_disk_constraint_and_middle_particle_closed_forms():
    # a disk (zero arm) against a point at distance sigma: -1 / sigma along the circle, 0 in theta
    g, h = _point_gap(np.zeros(2), np.array([0.0, -0.7]), np.zeros(2))
    np.testing.assert_allclose(principal_curvatures(g, h), [-1.0 / 0.7, 0.0], atol=1e-14)
    # the middle particle: a point at height h above the shaft, axial offset s (gamma = s)
    for height, s in ((0.35, 0.0), (0.35, 0.2), (0.8, -0.3)):
        g, hh = _line_gap_middle(np.array([s, height]), np.zeros(2), np.array([-0.5, 0.0]), np.array([0.0, 1.0]))
        k = principal_curvatures(g, hh)
        assert k[0] * k[1] == pytest.approx(-1.0 / (1.0 + s * s) ** 2, rel=1e-12)
        assert k[0] + k[1] == pytest.approx(height / (1.0 + s * s) ** 1.5, rel=1e-12)
        assert k[1] > 0.0  # convex: the constraint that stabilises hypostatic packings


@pytest.fixture(scope="module")
def packing():
    return read_packing(DATA, None)


def test_curvatures_of_a_jammed_circulo_line_packing(packing):
    r = constraint_curvatures(packing)
    side = np.sqrt(packing.box.volume)
    kinds = set(zip(r["type"].tolist(), r["particle"].tolist()))
    assert kinds == {("parallel", "end"), ("parallel", "middle"), ("end_middle", "end"), ("end_middle", "middle"),
                     ("end_end", "end")}
    end = r["zero_direction"]
    assert np.all((r["particle"] == "end") & (r["type"] != "end_end") == end)
    # the end particle of a shaft contact slides along the other's shaft: one curvature is 0
    assert np.all(np.min(np.abs(r["kappa"][end]), axis=1) < 1e-12)
    # a parallel end barely turns the gap: curvature ~ its misalignment (here < 1e-7 / L)
    par = end & (r["type"] == "parallel")
    assert np.all(np.max(np.abs(r["kappa"][par]), axis=1) < 1e-7)
    # end-end: two end caps, -1 / (R_i + R_j) in units of L, and a small concave theta part
    ee = r["type"] == "end_end"
    radius = packing.shapes.radius[packing.shape_index[r["body"][ee]]]
    assert np.all(r["kappa"][ee, 0] < 0.0) and np.all(r["kappa"][ee, 1] < 0.0)
    assert np.all(-1.0 / r["kappa"][ee, 0] * 1.0 / side <= 2.0 * 1.4 * radius.max() / side * 1.0001)
    # middle particles: a convex and a concave curvature, product -1 up to the contact's offset
    mid = r["particle"] == "middle"
    assert np.all(r["kappa"][mid, 1] > 0.0) and np.all(r["kappa"][mid, 0] < 0.0)
    np.testing.assert_allclose(r["kappa"][mid, 0] * r["kappa"][mid, 1], -1.0, atol=0.05)
    ds = curvature_dataset([packing], [str(DATA)])
    assert int(ds.n_contacts.sum()) == len(r["type"])
    assert ds.kappa1_mean.sel(contact_type="parallel (end particle)") == 0.0


def test_three_points_hold_a_short_line_not_a_long_one():
    assert cage_stability(0.2, np.pi / 4) < 0.0
    assert cage_stability(1.0, np.pi / 4) > 0.0
    # the long line escapes: along its free rotation every gap opens at zero shrink
    points = cage_points(1.0, 1.0, np.pi / 4)
    _, basis = cage_directions(points, 1.0)
    for s in (1e-3, 1e-2, 0.1):
        assert np.all(cage_gaps(points, s * basis[:, -1], 1.0, 1.0) > 0.0)
    with pytest.raises(ValueError, match="beta"):
        cage_points(0.2, 1.0, np.pi)


def test_feasible_region_scales_as_the_paper_finds():
    ds = feasible_scaling(np.array([1e-7, 1e-6, 1e-5, 1e-4]), samples=60_000, seed=3)
    assert ds.attrs["volume_exponent"] == pytest.approx(2.5, abs=0.03)
    assert ds.attrs["surface_exponent"] == pytest.approx(1.5, abs=0.05)
    # stiff extents ~ dR, the quartic one ~ dR^(1/2)
    w = ds.half_width.values
    np.testing.assert_allclose(w[1:, 0] / w[:-1, 0], 10.0, rtol=0.05)
    np.testing.assert_allclose(w[1:, 2] / w[:-1, 2], np.sqrt(10.0), rtol=0.05)


def test_ellipse_and_point_term_constraints():
    """Circles as ellipses (a = b): the Perram-Wertheim surface of a pair is the disk's,
    curvatures -1 / (R_i + R_j) and 0, from the finite differences to 1e-6; dumbbell and
    Reuleaux terms are distances of body-fixed points (or a lobe on a shaft line)."""
    from jamflow.box import Box
    from jamflow.models.shapes import ShapeModel
    from jamflow.shapes.curvature import _ellipse_views, _to_paper_units
    from jamflow.state.bodies import ShapeTable

    table = ShapeTable.from_shapes([dict(kind="ellipse", semi_axes=(0.5, 0.5)), dict(kind="ellipse", semi_axes=(0.7, 0.7))])
    m = ShapeModel(Box.cubic(2, 8.0), table, [0, 1])
    q = m.dofs([[2.0, 2.0, 0.3], [2.0 + 1.2 * np.cos(0.4) * (1 - 1e-9), 2.0 + 1.2 * np.sin(0.4) * (1 - 1e-9), 1.1]])
    views = _ellipse_views(m, q)
    assert len(views) == 2
    for view in views:
        k = principal_curvatures(*_to_paper_units(view[3], view[4], 1.0))
        np.testing.assert_allclose(k, [-1.0 / 1.2, 0.0], atol=1e-6)
    dumbbells = read_packing(Path(__file__).parent / "data" / "shapes_dumbbell_ar3_n32_p1e-9.nc", None)
    r = constraint_curvatures(dumbbells)
    assert set(zip(r["type"].tolist(), r["particle"].tolist())) <= {("lobe_lobe", "end"), ("lobe_shaft", "end"),
                                                                    ("lobe_shaft", "middle")}
    lobes = r["type"] == "lobe_lobe"
    # two lobes: a disk constraint seen from a body whose lobe is off-centre: one curvature -1 / (R_i + R_j)
    radius = dumbbells.shapes.radius[dumbbells.shape_index[r["body"][lobes]]]
    side = np.sqrt(dumbbells.box.volume)
    assert np.all(r["kappa"][lobes, 0] <= -side / (2.0 * 1.4 * radius.max()) * 0.9999)
