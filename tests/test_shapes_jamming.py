"""Shape generation (init-shapes) and jamming with rotations (soft-jam on shapes).

Physics checked: asphericities against Table I of VanderWerf et al. (independent
numbers from the paper), the bidisperse area ratio 1.4^2 and unit mean
area-equivalent diameter, an overlap-free random start, and a jammed packing at the
target pressure with force and torque balance, whose virial pressure equals
``-dU/dV`` measured by rescaling the box.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.cli import main
from jamflow.io import read_packing
from jamflow.minimize.onset import JammingSettings
from jamflow.models.shapes import ShapeModel
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)
from jamflow.state.bodies import ShapeTable


@pytest.mark.parametrize("kind, alpha, a_minus_1, rel", [
    ("circulo-line", 1.0 + 1e-3, 4.05e-7, 2e-3),   # Table I lower end (3 digits)
    ("circulo-line", 5.0, 1.06, 5e-3),             # Table I upper end
    ("ellipse", 1.9, 0.161, 5e-3),                 # Table I upper end
    ("ellipse", 1.0001, 3.75e-9, 2e-3),            # Table I lower end
])
def test_asphericity_matches_table_one(kind, alpha, a_minus_1, rel):
    shape = ShapeTable.from_shapes([unit_shape(kind, aspect_ratio=alpha)])
    assert shape.asphericity[0] - 1.0 == pytest.approx(a_minus_1, rel=rel)


@pytest.mark.parametrize("shaft, a_minus_1", [(2.0, 0.514), (8.0, 2.405)])
def test_dumbbell_shaft_length_gives_table_one(shaft, a_minus_1):
    """Table I's dumbbell A - 1 from 0.514 to 2.405: the lobe-centre distance X from 2 R (touching
    lobes, Table I's alpha - 1 = 2) to 8 R, shaft half-width R / 2 (Fig. 4); the same shapes as
    ``--aspect-ratio 1 + X / 2``, tip to tip over the lobe diameter."""
    table = bidisperse_shapes(unit_shape("dumbbell", shaft_length=shaft))
    assert table.asphericity[0] - 1.0 == pytest.approx(a_minus_1, abs=5e-4)
    same = bidisperse_shapes(unit_shape("dumbbell", aspect_ratio=1.0 + 0.5 * shaft))
    np.testing.assert_array_equal(table.vertices, same.vertices)
    v = table.vertex_list(0)
    assert np.linalg.norm(v[1] - v[0]) == pytest.approx(shaft * table.radius[0], rel=1e-14)
    assert table.shaft_half_width[0] == pytest.approx(0.5 * table.radius[0], rel=1e-14)


def test_frozen_orientations_jam_and_count_two_degrees_of_freedom(tmp_path, capsys):
    """Non-rotating circulo-lines (Fig. 3a): soft-jam --frozen-orientations keeps every angle,
    balances forces (the torques are not asked), and counting uses 2 degrees of freedom per
    body: N_c^0 = 2 N' - 1 - N_s and <z> (Eq. 3) = 2 (N_c + 1) / (N' - N_s / 2)."""
    from jamflow.shapes.counting import count_constraints

    src = tmp_path / "start.nc"
    out = tmp_path / "j.nc"
    assert main(["init-shapes", str(src), "--shape", "circulo-line", "--asphericity", "1.06", "--n", "16",
                 "--seed", "2", "--quiet"]) == 0
    assert main(["soft-jam", str(src), str(out), "--pressure", "1e-5", "--frozen-orientations",
                 "--delta-phi", "1e-2", "--pressure-rtol", "1e-3"]) == 0
    assert "frozen (Fig. 3a)" in capsys.readouterr().out
    start, p = read_packing(src, None), read_packing(out, None)
    np.testing.assert_array_equal(p.orientation, np.mod(start.orientation, 2.0 * np.pi))
    assert p.attrs["frozen_orientations"] == 1 and p.attrs["max_force_sq"] <= 1e-26
    c, rattler, slider, _ = count_constraints(p, "once")
    n_prime = p.n - c.n_rattlers
    assert c.dofs_per_body == 2 and c.isostatic_count == 2 * n_prime - 1 - c.n_sliders
    assert c.z_eq3 == pytest.approx(2.0 * (c.n_contacts + 1) / (n_prime - c.n_sliders / 2.0), rel=1e-14)
    from jamflow.shapes.spectrum import spectrum

    spec = spectrum(p, fourth=False)
    assert spec.eigenvalue.size == 2 * p.n and np.all(spec.rotational_weight == 0.0)


def test_pressure_is_the_papers_at_box_side_one():
    """P / k does not depend on the length unit in 2D: the packing scaled to box side L = 1 (the
    paper's unit; k unchanged) has the same pressure, its energy divided by L^2 (the stored
    ``paper_energy``), and ``paper_length_unit`` is L."""
    from jamflow.minimize.model import pressure_of
    from jamflow.shapes.jamming import shape_packing

    table = bidisperse_shapes(unit_shape("ellipse", asphericity=1.1))
    res = jam_shapes(random_shape_packing(table, 16, 0.4, 4), 1e-4,
                     JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2))
    p = res.packing
    side = float(np.sqrt(p.box.volume))
    assert p.attrs["paper_length_unit"] == pytest.approx(side, rel=1e-15)
    small = ShapeModel(p.box.scaled(1.0 / side), table.scaled(1.0 / side), p.shape_index)
    q = small.dofs(np.column_stack([p.position / side, p.orientation]))
    ev = small.evaluate(q)
    assert pressure_of(ev, small.box) == pytest.approx(p.pressure, rel=1e-10)
    assert ev.energy == pytest.approx(p.attrs["paper_energy"], rel=1e-10)
    assert shape_packing(small, small.positions(q), p, {}, {}).attrs["paper_length_unit"] == pytest.approx(1.0)


@pytest.mark.parametrize("kind, sides", [("ellipse", None), ("circulo-line", None), ("circulo-polygon", 5),
                                         ("dumbbell", None)])
def test_target_asphericity_is_met_exactly(kind, sides):
    target = 1.6 if kind == "dumbbell" else 1.03
    table = bidisperse_shapes(unit_shape(kind, asphericity=target, sides=sides))
    np.testing.assert_allclose(table.asphericity, target, rtol=1e-12)
    assert table.area[1] / table.area[0] == pytest.approx(1.96, rel=1e-13)
    assert np.mean(2.0 * np.sqrt(table.area / np.pi)) == pytest.approx(1.0, rel=1e-13)


def test_reuleaux_asphericity():
    table = bidisperse_shapes(unit_shape("reuleaux"))
    np.testing.assert_allclose(table.asphericity, np.pi / (2.0 * (np.pi - np.sqrt(3.0))), rtol=1e-13)


def test_init_shapes_writes_overlap_free_start(tmp_path, capsys):
    out = tmp_path / "s.nc"
    assert main(["init-shapes", str(out), "--shape", "circulo-line", "--asphericity", "1.2", "--n", "40",
                 "--phi", "0.35", "--seed", "5"]) == 0
    assert "asphericity A" in capsys.readouterr().out
    p = read_packing(out, None)
    assert p.packing_fraction == pytest.approx(0.35, rel=1e-12)
    np.testing.assert_allclose(p.shapes.asphericity, 1.2, rtol=1e-12)
    import xarray as xr
    with xr.open_dataset(out) as ds:
        np.testing.assert_allclose(ds["asphericity"].values, 1.2, rtol=1e-12)
    m = ShapeModel(p.box, p.shapes, p.shape_index)
    q = m.dofs(np.column_stack([p.position, p.orientation]))
    assert m.evaluate(q).energy == 0.0
    m.check_cores(q)


@pytest.mark.parametrize("argv, needle", [
    (["--shape", "reuleaux", "--aspect-ratio", "2"], "no shape parameter"),
    (["--shape", "circulo-polygon", "--asphericity", "1.1"], "--sides"),
    (["--shape", "circulo-polygon", "--sides", "3", "--asphericity", "2.0"], "asphericity in"),
    (["--shape", "ellipse", "--asphericity", "0.9"], "--asphericity >"),
    (["--shape", "ellipse", "--aspect-ratio", "1.5", "--asphericity", "1.1"], "not both"),
    (["--shape", "dumbbell", "--aspect-ratio", "1.9"], "--aspect-ratio >="),
    (["--shape", "dumbbell", "--shaft-length", "1.5"], "at least 2"),
    (["--shape", "ellipse", "--shaft-length", "3"], "dumbbell"),
    (["--shape", "dumbbell", "--shaft-length", "3", "--aspect-ratio", "2.5"], "one of"),
])
def test_init_shapes_bad_input(tmp_path, capsys, argv, needle):
    out = tmp_path / "bad.nc"
    assert main(["init-shapes", str(out), *argv, "--n", "10", "--seed", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not out.exists()


def test_odd_n_is_refused():
    with pytest.raises(ValueError, match="even"):
        random_shape_packing(bidisperse_shapes(unit_shape("ellipse", aspect_ratio=1.5)), 7, 0.3, 1)


@pytest.mark.parametrize("kind", ["circulo-line", "ellipse"])
def test_jammed_shapes_balance_forces_and_torques(kind):
    table = bidisperse_shapes(unit_shape(kind, asphericity=1.1))
    start = random_shape_packing(table, 16, 0.4, 11)
    p0 = 1e-3
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-4, delta_phi=1e-2)
    res = jam_shapes(start, p0, settings)
    p = res.packing
    assert res.converged
    assert abs(p.pressure - p0) <= 1e-4 * p0
    m = ShapeModel(p.box, p.shapes, p.shape_index)
    # force_tol bounds sqrt(F^2 + (tau / l)^2) per body, l the mean bounding diameter
    assert p.attrs["max_force_sq"] <= 1e-24
    assert p.attrs["max_torque_sq"] <= (1e-12 * m.torque_arm) ** 2
    assert 0.7 < p.packing_fraction < 0.95
    # virial pressure = -dU/dV: rescale the box and centres, keep shapes and angles
    conf = np.column_stack([p.position, p.orientation])
    eps = 1e-6
    u = []
    for s in (1.0 - eps, 1.0 + eps):
        ms, cs = m.rescaled(s, conf)
        u.append((ms.evaluate(ms.dofs(cs)).energy, ms.box.volume))
    dudv = (u[1][0] - u[0][0]) / (u[1][1] - u[0][1])
    assert -dudv == pytest.approx(p.pressure, rel=1e-6)


def _start(tmp_path) -> str:
    # 16 bodies: with fewer, the box of the jammed packing is narrower than twice the
    # neighbour-list reach (bounding diameter + skin) and the model refuses it
    src = tmp_path / "start.nc"
    assert main(["init-shapes", str(src), "--shape", "circulo-line", "--asphericity", "1.2", "--n", "16",
                 "--seed", "3", "--quiet"]) == 0
    return str(src)


@pytest.mark.parametrize("extra, needle", [
    (["--exponent", "2.5"], "linear spring"),
    (["--seed", "4"], "init-shapes --seed"),
    (["--box-dof", "full"], "box stays square"),
])
def test_soft_jam_refuses_options_shapes_do_not_have(tmp_path, capsys, extra, needle):
    out = tmp_path / "j.nc"
    assert main(["soft-jam", _start(tmp_path), str(out), "--pressure", "1e-3", "--quiet", *extra]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not out.exists()


def test_soft_jam_refuses_crossed_cores(tmp_path, capsys):
    from jamflow.io import write_packing

    src = _start(tmp_path)
    p = read_packing(src, None)
    x = p.position.copy()
    x[1] = x[0]  # the second body's shaft now crosses the first's
    theta = p.orientation.copy()
    theta[1] = theta[0] + 1.0
    bad = tmp_path / "crossed.nc"
    write_packing(p.evolve(position=x, orientation=theta), bad)
    assert main(["soft-jam", str(bad), str(tmp_path / "j.nc"), "--pressure", "1e-3", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "intersecting cores" in err and "(0, 1)" in err


def test_soft_jam_cli_prints_its_numbers(tmp_path, capsys):
    out = tmp_path / "j.nc"
    assert main(["soft-jam", _start(tmp_path), str(out), "--pressure", "1e-2", "--delta-phi", "1e-2",
                 "--pressure-rtol", "1e-3", "--force-tol", "1e-12"]) == 0
    printed = capsys.readouterr().out
    p = read_packing(out, None)
    assert f"{p.packing_fraction:.10f}" in printed
    assert abs(p.pressure - 1e-2) <= 1e-3 * 1e-2
    assert "max |torque|" in printed


def test_reuleaux_triangles_jam_and_are_counted():
    """Reuleaux triangles jam; convex bodies touch once per pair, so contacts counted once
    are the interacting pairs between non-rattlers, and every non-rattler keeps >= 3."""
    from jamflow.shapes.counting import count_constraints

    table = bidisperse_shapes(unit_shape("reuleaux"))
    start = random_shape_packing(table, 16, 0.4, 2)
    res = jam_shapes(start, 1e-3, JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2))
    p = res.packing
    assert res.converged and abs(p.pressure - 1e-3) <= 1e-6
    assert p.attrs["max_force_sq"] <= 1e-24
    counting, rattler, _, cs = count_constraints(p)
    pairs = p.contacts
    live = ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])
    assert counting.n_contacts == int(live.sum()) == cs.n_contacts - int((rattler[cs.i] | rattler[cs.j]).sum())
    degree = np.bincount(pairs[live].ravel(), minlength=p.n)
    assert np.all(degree[~rattler] >= 3)
    assert counting.isostatic_count == 3 * (p.n - counting.n_rattlers) - 1 - counting.n_sliders



def test_minimize_command_takes_shapes_and_fire_and_cg_find_the_same_minimum(tmp_path, capsys):
    # the vendored 16 circulo-lines (A = 1.1, P0 = 1e-6) compressed by dphi = 1e-3 at fixed
    # shapes: FIRE (with moments of inertia) and Polak-Ribiere CG are independent
    # minimisers of the same energy and must meet in one minimum
    from pathlib import Path

    from jamflow.io import read_dataset, write_packing

    base = read_packing(Path(__file__).parent / "data" / "shapes_circulo_line_a1.1_n16_p1e-6.nc", None)
    s = (1.0 + 1e-3) ** -0.5
    src = tmp_path / "c.nc"
    write_packing(base.evolve(position=base.position * s, box=base.box.scaled(s)), src)
    out = {}
    for method in ("fire", "cg"):
        path = tmp_path / f"{method}.nc"
        assert main(["minimize", str(src), str(path), "--method", method, "--force-tol", "1e-12"]) == 0
        assert "n_force_evaluations" in capsys.readouterr().out
        ds = read_dataset(path)
        assert ds.attrs["max_force"] <= 1e-12
        out[method] = (read_packing(path, None), ds.attrs["energy"])
    (pf, ef), (pc, ec) = out["fire"], out["cg"]
    assert ec == pytest.approx(ef, rel=1e-10)
    assert ef > 10.0 * base.attrs["energy"]  # the compression stored energy: a real minimisation
    assert np.abs(pf.box.minimum_image(pc.position - pf.position)).max() < 1e-6
    assert np.abs(np.angle(np.exp(1j * (pc.orientation - pf.orientation)))).max() < 1e-6
    assert main(["minimize", str(src), str(tmp_path / "x.nc"), "--exponent", "2.5"]) == 1
    assert "linear spring" in capsys.readouterr().err
