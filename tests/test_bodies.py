"""Bodies in the packing: links, orientations and the 2D shape table.

Areas and perimeters are checked against shapely's independent polygon geometry;
round trips through netCDF must be bit for bit; every malformed input gets one
clear error.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry import box as shapely_box

from jamflow.box import Box
from jamflow.io import read_dataset, read_packing, write_dataset, write_packing
from jamflow.state.bodies import SHAPE_KINDS, Links, ShapeTable
from jamflow.state.packing import OverlapError, Packing


def _regular(n: int, circumradius: float, phase: float = 0.3) -> np.ndarray:
    a = phase + 2.0 * np.pi * np.arange(n) / n
    return circumradius * np.stack([np.cos(a), np.sin(a)], axis=1)


#: One shape per kind, with parameters away from special cases.
SHAPES = [
    {"kind": "disk", "radius": 0.031},
    {"kind": "ellipse", "semi_axes": (0.05, 0.021)},
    {"kind": "circulo_line", "vertices": [(-0.03, 0.01), (0.03, -0.01)], "radius": 0.012},
    {"kind": "circulo_polygon", "vertices": _regular(5, 0.03), "radius": 0.004},
    {"kind": "reuleaux", "vertices": _regular(3, 0.035)},
    {"kind": "dumbbell", "vertices": [(-0.04, 0.0), (0.04, 0.0)], "radius": 0.02, "shaft_half_width": 0.01},
]


def _shapely(shape: dict) -> shapely.Geometry:
    """The same shape built by shapely (buffers and Boolean operations of polygons)."""
    res = 4096  # segments per quarter circle: polygonal error ~1e-8 relative
    kind = shape["kind"]
    if kind == "disk":
        return Point(0, 0).buffer(shape["radius"], quad_segs=res)
    if kind == "ellipse":
        a, b = shape["semi_axes"]
        return affinity.scale(Point(0, 0).buffer(1.0, quad_segs=res), a, b)
    if kind == "circulo_line":
        return LineString(shape["vertices"]).buffer(shape["radius"], quad_segs=res)
    if kind == "circulo_polygon":
        return Polygon(shape["vertices"]).buffer(shape["radius"], quad_segs=res)
    if kind == "reuleaux":
        v = np.asarray(shape["vertices"])
        side = float(np.linalg.norm(v[1] - v[0]))
        disks = [Point(*p).buffer(side, quad_segs=res) for p in v]
        return disks[0].intersection(disks[1]).intersection(disks[2])
    (x0, _), (x1, _) = shape["vertices"]
    r, w = shape["radius"], shape["shaft_half_width"]
    lobes = Point(x0, 0).buffer(r, quad_segs=res).union(Point(x1, 0).buffer(r, quad_segs=res))
    return lobes.union(shapely_box(x0, -w, x1, w))


def _shaped_packing(n_per_shape: int = 2, seed: int = 4) -> Packing:
    table = ShapeTable.from_shapes(SHAPES)
    rng = np.random.default_rng(seed)
    index = np.repeat(np.arange(len(table)), n_per_shape)
    box = Box.cubic(2, 1.0)
    grid = (np.stack(np.meshgrid(np.arange(4), np.arange(4)), -1).reshape(-1, 2) + 0.5) / 4
    return Packing(
        position=grid[: index.size] + rng.uniform(-0.01, 0.01, (index.size, 2)),
        diameter=2.0 * table.bounding_radius[index],
        box=box,
        shapes=table,
        shape_index=index,
        orientation=rng.uniform(-np.pi, np.pi, index.size),
        protocol="test",
    )


def _linked_packing() -> Packing:
    box = Box.cubic(3, 1.0)
    x = np.array([[0.1, 0.1, 0.1], [0.15, 0.1, 0.1], [0.2, 0.1, 0.1], [0.6, 0.6, 0.6], [0.6, 0.65, 0.6], [0.9, 0.2, 0.5]])
    return Packing(position=x, diameter=np.full(6, 0.05), box=box,
                   links=Links([1, 0, 3], [2, 1, 4], [0.05, 0.05, 0.05]), protocol="test")


# --- geometry -------------------------------------------------------------------------


@pytest.mark.parametrize("shape", SHAPES, ids=[s["kind"] for s in SHAPES])
def test_area_and_perimeter_agree_with_shapely(shape: dict) -> None:
    table = ShapeTable.from_shapes([shape])
    ref = _shapely(shape)
    assert table.area[0] == pytest.approx(ref.area, rel=1e-6)
    assert table.perimeter[0] == pytest.approx(ref.length, rel=1e-6)
    far = np.max(np.linalg.norm(np.asarray(ref.exterior.coords), axis=1))
    assert table.bounding_radius[0] == pytest.approx(far, rel=1e-6)


def test_asphericity_of_a_disk_is_one_and_of_a_reuleaux_triangle_is_the_papers() -> None:
    table = ShapeTable.from_shapes([SHAPES[0], SHAPES[4]])
    assert table.asphericity[0] == pytest.approx(1.0, abs=1e-15)
    # VanderWerf et al. Table I: Reuleaux triangle A - 1 = 0.114 (pi^2 / (2 (pi - sqrt 3)) / pi - 1 exactly)
    assert table.asphericity[1] - 1.0 == pytest.approx(np.pi / (2.0 * (np.pi - np.sqrt(3.0))) - 1.0, rel=1e-12)
    assert round(table.asphericity[1] - 1.0, 3) == 0.114


def test_packing_fraction_of_shapes_is_the_area_sum() -> None:
    p = _shaped_packing()
    areas = np.array([_shapely(s).area for s in SHAPES])
    assert p.packing_fraction == pytest.approx(2 * areas.sum(), rel=1e-6)


def test_clusters_are_connected_components_in_order_of_first_member() -> None:
    links = Links([4, 0, 1, 6], [5, 2, 2, 7], [1.0, 1.0, 1.0, 1.0])
    np.testing.assert_array_equal(links.clusters(8), [0, 0, 0, 1, 2, 2, 3, 3])


def test_in_units_scales_links_and_shapes() -> None:
    p = _shaped_packing().in_units(0.5)
    np.testing.assert_allclose(p.shapes.radius, 2 * ShapeTable.from_shapes(SHAPES).radius)
    q = _linked_packing().in_units(0.05)
    np.testing.assert_allclose(q.links.length, 1.0)


# --- round trips ----------------------------------------------------------------------


def _assert_same_bodies(a: Packing, b: Packing) -> None:
    for name in ("position", "diameter", "orientation", "shape_index"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None)
        if x is not None:
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
    if a.links is not None:
        for name in ("i", "j", "length"):
            assert getattr(a.links, name).tobytes() == getattr(b.links, name).tobytes()
    if a.shapes is not None:
        np.testing.assert_array_equal(a.shapes.kind, b.shapes.kind)
        for name in ("radius", "semi_axes", "vertices", "n_vertices", "shaft_half_width"):
            x, y = getattr(a.shapes, name), getattr(b.shapes, name)
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name


def test_shaped_packing_round_trip_is_bit_for_bit(tmp_path: Path) -> None:
    p = _shaped_packing()
    assert set(p.shapes.kind) == set(SHAPE_KINDS)
    write_packing(p, tmp_path / "s.nc")
    q = read_packing(tmp_path / "s.nc", overlap_tol=None)
    _assert_same_bodies(p, q)
    ds = read_dataset(tmp_path / "s.nc")
    assert ds["orientation"].attrs["units"] == "rad"
    for name in ds.data_vars:
        assert ds[name].attrs.get("long_name"), name


def test_linked_packing_round_trip_is_bit_for_bit_and_cluster_is_derived(tmp_path: Path) -> None:
    p = _linked_packing()
    write_packing(p, tmp_path / "l.nc")
    ds = read_dataset(tmp_path / "l.nc")
    np.testing.assert_array_equal(ds["cluster"].values, [0, 0, 0, 1, 1, 2])
    ds["cluster"].values[:] = 0  # a tampered convenience variable is not trusted
    write_dataset(ds, tmp_path / "tampered.nc")
    q = read_packing(tmp_path / "tampered.nc")
    _assert_same_bodies(p, q)
    np.testing.assert_array_equal(q.clusters, [0, 0, 0, 1, 1, 2])


def test_sphere_packing_dataset_has_no_body_variables() -> None:
    box = Box.cubic(2, 1.0)
    p = Packing(position=[[0.1, 0.1], [0.5, 0.5]], diameter=[0.1, 0.1], box=box)
    assert set(p.to_dataset().variables) == {"position", "diameter", "box"}
    assert set(p.to_dataset().dims) == {"particle", "spatial", "lattice_vector"}


# --- validation -----------------------------------------------------------------------


def test_linked_pairs_are_exempt_from_the_overlap_check_but_others_are_not() -> None:
    box = Box.cubic(2, 1.0)
    x = [[0.3, 0.3], [0.34, 0.3], [0.8, 0.8]]
    linked = Packing(position=x, diameter=[0.05] * 3, box=box, links=Links([0], [1], [0.04]))
    linked.validate()
    with pytest.raises(OverlapError, match=r"\(0, 1\)"):
        Packing(position=x, diameter=[0.05] * 3, box=box).validate()


def test_hard_overlap_check_refuses_non_disk_shapes() -> None:
    with pytest.raises(ValueError, match="defined for spheres"):
        _shaped_packing().validate()


def _corrupt(tmp_path: Path, ds_edit, source: Packing) -> Path:
    ds = source.to_dataset()
    ds = ds_edit(ds)
    path = tmp_path / "bad.nc"
    write_dataset(ds, path)
    return path


def _set(name: str, index: tuple, value):
    def edit(ds):
        ds[name].values[index] = value
        return ds
    return edit


@pytest.mark.parametrize(
    "source, edit, message",
    [
        ("linked", _set("link_j", (0,), 9), r"link \(0, 9\) names a particle outside 0..5"),
        ("linked", _set("link_length", (1,), 0.0), r"link 1 \(1, 2\) has length 0.0"),
        ("linked", _set("link_j", (2,), 1), r"links must be pairs i < j"),
        ("linked", lambda ds: _set("link_j", (1,), 1)(_set("link_i", (1,), 0)(ds)), r"link \(0, 1\) is given twice"),
        ("shaped", _set("orientation", (3,), np.nan), r"orientation of particle 3 is nan"),
        ("shaped", _set("n_vertices", (3,), 2), r"shape 3 \(circulo_polygon\) has 2 vertices; it needs at least 3"),
        ("shaped", lambda ds: ds.assign(shape_kind=ds["shape_kind"].copy(data=np.array(
            ["disk", "ellipse", "blob", "circulo_polygon", "reuleaux", "dumbbell"], dtype=object))),
         r"shape 2 has unknown kind 'blob'"),
        ("shaped", _set("semi_axes", (1, 1), 0.06), r"semi-axes a >= b > 0"),
        ("shaped", _set("shape_vertex", (3, 0, 0), 0.0), r"strictly convex counter-clockwise"),
        ("shaped", _set("shape_index", (0,), 7), r"particle 0 has shape_index 7 outside 0..5"),
        ("shaped", _set("diameter", (0,), 0.07), r"particle 0: diameter 0.07 is not the bounding diameter"),
        ("shaped", _set("shaft_half_width", (5,), 0.03), r"shaft half-width 0 < w < radius"),
        ("shaped", lambda ds: ds.drop_vars("orientation"), r"lacks orientation"),
        ("linked", lambda ds: ds.drop_vars("link_length"), r"not all of link_i, link_j, link_length"),
        ("shaped", _set("position", (2, 0), 1.5), r"outside the box"),
    ],
)
def test_malformed_bodies_give_one_clear_error(tmp_path: Path, source: str, edit, message: str) -> None:
    packing = _linked_packing() if source == "linked" else _shaped_packing()
    path = _corrupt(tmp_path, edit, packing)
    with pytest.raises(ValueError, match=message):
        read_packing(path, overlap_tol=None)


def test_orientation_needs_shapes_and_shapes_are_2d() -> None:
    with pytest.raises(ValueError, match="must be given together"):
        Packing(position=[[0.1, 0.1], [0.5, 0.5]], diameter=[0.1, 0.1], box=Box.cubic(2, 1.0),
                orientation=[0.0, 1.0])
    table = ShapeTable.from_shapes([SHAPES[0]])
    with pytest.raises(ValueError, match="shaped particles are 2D"):
        Packing(position=[[0.1, 0.1, 0.1], [0.5, 0.5, 0.5]], diameter=[0.062, 0.062], box=Box.cubic(3, 1.0),
                shapes=table, shape_index=[0, 0], orientation=[0.0, 0.0])


def test_the_schema_documents_examples_run_and_mean_what_they_say() -> None:
    text = (Path(__file__).parents[1] / "docs" / "bodies.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2
    trimer: dict = {}
    exec(blocks[0], trimer)
    np.testing.assert_array_equal(trimer["p"].clusters, [0, 0, 0, 1, 1])
    x = trimer["p"].position
    for i, j, length in zip(trimer["links"].i, trimer["links"].j, trimer["links"].length):
        assert np.linalg.norm(x[j] - x[i]) == pytest.approx(length, rel=1e-12)
    shapes = dict(trimer)  # the page reads top to bottom: imports of the first block carry over
    exec(blocks[1], shapes)
    assert list(shapes["table"].kind) == list(SHAPE_KINDS)


@pytest.mark.parametrize("shape", SHAPES, ids=[s["kind"] for s in SHAPES])
def test_outline_is_the_shapes_boundary(shape: dict) -> None:
    table = ShapeTable.from_shapes([shape])
    outline = table.outline(0, points_per_turn=4096)
    ring = Polygon(outline)
    assert ring.is_valid and ring.exterior.is_ccw
    assert ring.area == pytest.approx(table.area[0], rel=1e-5)
    assert ring.length == pytest.approx(table.perimeter[0], rel=1e-5)
    assert ring.symmetric_difference(_shapely(shape)).area < 1e-5 * table.area[0]


# --- drawing --------------------------------------------------------------------------


def _polygon_area_centroid(v: np.ndarray) -> tuple[float, np.ndarray]:
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    area = 0.5 * cross.sum()
    return area, ((v + w) * cross[:, None]).sum(axis=0) / (6.0 * area)


def test_plot_packing_draws_each_shape_at_its_centre_and_orientation(tmp_path: Path) -> None:
    from matplotlib.collections import LineCollection, PolyCollection

    from jamflow.plots import plot_packing, save_figure

    p = _shaped_packing()
    fig = plot_packing(p)
    ax = fig.axes[0]
    polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(polys) == 9  # the primary cell and its eight periodic neighbours
    x = p.box.wrap(p.position)
    drawn = polys[4].get_paths()  # shift (0, 0) is the fifth of itertools.product((-1, 0, 1), repeat=2)
    assert len(drawn) == p.n
    for k, path in enumerate(drawn):
        area, centroid = _polygon_area_centroid(path.vertices[:-1])
        shape = p.shape_index[k]
        assert area == pytest.approx(p.shapes.area[shape], rel=5e-3)  # 64 points per turn
        np.testing.assert_allclose(centroid, x[k], atol=1e-9)
        if p.shapes.kind[shape] == "ellipse":
            # the long axis lies along the orientation (mod pi)
            far = path.vertices[np.argmax(np.linalg.norm(path.vertices - x[k], axis=1))] - x[k]
            assert abs(np.sin(np.arctan2(far[1], far[0]) - p.orientation[k])) < 0.05
    assert not [c for c in ax.collections if isinstance(c, LineCollection)]  # no contacts guessed from diameters
    save_figure(fig, tmp_path / "shapes.png")


def test_plot_packing_draws_links_at_their_length(tmp_path: Path) -> None:
    from matplotlib.collections import LineCollection

    from jamflow.plots import plot_packing, save_figure

    D = 0.05
    x = np.array([[0.3, 0.3], [0.35, 0.3], [0.325, 0.3 + D * np.sqrt(3) / 2], [0.925, 0.3 + D * np.sqrt(3) / 2]])
    p = Packing(position=x, diameter=np.full(4, D), box=Box.cubic(2, 1.0),
                links=Links([0, 1, 0, 2], [1, 2, 2, 3], [D, D, D, 0.4]))
    fig = plot_packing(p)
    lines = [c for c in fig.axes[0].collections if isinstance(c, LineCollection)]
    assert len(lines) == 9
    segments = np.asarray(lines[4].get_segments())  # shift (0, 0)
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    # the link 2-3 crosses the periodic boundary: drawn as its minimum image, at its length
    np.testing.assert_allclose(np.sort(lengths), np.sort(p.links.length), rtol=1e-12)
    assert "links (fixed length)" in fig.axes[0].get_legend_handles_labels()[1]
    save_figure(fig, tmp_path / "links.png")


# --- check --------------------------------------------------------------------------


def test_check_reports_how_well_links_hold_and_refuses_to_count_shape_contacts(tmp_path: Path, capsys) -> None:
    import json

    from jamflow.analysis.contacts import summarize
    from jamflow.cli import main
    from jamflow.protocols.certify import certify

    p = _linked_packing()
    stretched = p.position.copy()
    stretched[2, 0] += 0.05 * 1e-6  # link (1, 2) of length 0.05 stretched by 1e-6 relative
    p = p.evolve(position=stretched)
    write_packing(p, tmp_path / "l.nc")
    assert main(["check", str(tmp_path / "l.nc"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_links"] == 3 and report["n_clusters"] == 3
    assert report["max_link_error"] == pytest.approx(1e-6, rel=1e-6)
    for count in (summarize, lambda q: certify(q)):
        with pytest.raises(ValueError, match="links"):
            count(p)
    with pytest.raises(ValueError, match="shaped particles"):
        summarize(_shaped_packing())
    write_packing(_shaped_packing(), tmp_path / "s.nc")
    assert main(["check", str(tmp_path / "s.nc")]) == 0
    out = capsys.readouterr().out
    assert "2 circulo_line" in out and "not counted" in out
