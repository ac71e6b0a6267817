"""``jamflow export-xyz OUT.gsd``: HOOMD GSD with links as bonds, read back with ``gsd`` (and OVITO, slow)."""

from __future__ import annotations

from pathlib import Path

import gsd.hoomd
import numpy as np
import pytest

from jamflow.box import Box
from jamflow.cli import main
from jamflow.io import read_packing, write_packing
from jamflow.io.formats import size_classes, write_gsd, write_xyz
from jamflow.state.packing import Packing

DATA = Path(__file__).parent / "data"
CIRCULO = DATA / "shapes_circulo_line_a1.1_n16_p1e-6.nc"
#: GSD stores the box, positions, diameters and orientations as float32: relative round-off 2**-24.
FLOAT32 = 2.0**-24


@pytest.fixture(scope="module")
def chains(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2D packing of 12 rigid trimers (a random start: non-linked spheres may overlap)."""
    out = tmp_path_factory.mktemp("gsd") / "trimers.nc"
    assert main(["init-chains", str(out), "--d", "2", "--clusters", "12", "--cluster", "trimer", "--seed", "4",
                 "--overlap", "--quiet"]) == 0
    return out


def _read(path: Path) -> list:
    with gsd.hoomd.open(path, mode="r") as trajectory:
        return list(trajectory)


def _box_matrix(frame) -> np.ndarray:
    """The box vectors (columns) of a HOOMD box ``[Lx, Ly, Lz, xy, xz, yz]`` (tilt factors)."""
    lx, ly, lz, xy, xz, yz = frame.configuration.box
    return np.array([[lx, xy * ly, xz * lz], [0.0, ly, yz * lz], [0.0, 0.0, lz]])


def _positions_in_jamflow_cell(frame, d: int) -> np.ndarray:
    """GSD positions shifted from HOOMD's centred cell to jamflow's cell at the origin."""
    h = _box_matrix(frame)[:d, :d]
    return frame.particles.position[:, :d].astype(np.float64) + 0.5 * h.sum(axis=1)


def test_links_are_the_bonds(tmp_path, chains):
    p = read_packing(chains, None)
    out = tmp_path / "c.gsd"
    assert main(["export-xyz", str(chains), str(out), "--soft", "--quiet"]) == 0
    (frame,) = _read(out)
    assert frame.particles.N == p.n and frame.configuration.dimensions == 2
    assert frame.bonds.N == len(p.links) == 3 * 12  # a rigid trimer: a triangle of three links
    assert frame.bonds.types == ["link"] and not frame.bonds.typeid.any()
    np.testing.assert_array_equal(frame.bonds.group, np.column_stack([p.links.i, p.links.j]))
    # every bond joins spheres of one trimer, at the link length (to the float32 positions)
    x = _positions_in_jamflow_cell(frame, 2)
    length = np.linalg.norm(p.box.minimum_image(x[p.links.j] - x[p.links.i]), axis=1)
    np.testing.assert_allclose(length, p.links.length, rtol=0, atol=4 * FLOAT32 * p.box.lengths.max())
    np.testing.assert_allclose(p.box.minimum_image(x - p.position), 0.0, atol=FLOAT32 * p.box.lengths.max())
    np.testing.assert_allclose(_box_matrix(frame)[:2, :2], p.box.matrix, rtol=FLOAT32)
    assert frame.log["phi"][0] == p.packing_fraction


def test_a_packing_with_links_is_refused_as_xyz(tmp_path, chains, capsys):
    out = tmp_path / "c.xyz"
    assert main(["export-xyz", str(chains), str(out), "--soft"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "links" in err[0] and ".gsd" in err[0]
    assert not out.exists()


def test_orientations_and_shapes_round_trip(tmp_path):
    src = tmp_path / "e.nc"
    assert main(["init-shapes", str(src), "--shape", "ellipse", "--aspect-ratio", "1.7", "--n", "12",
                 "--seed", "4", "--quiet"]) == 0
    for shaped in (src, CIRCULO):
        p = read_packing(shaped, None)
        out = tmp_path / f"{shaped.stem}.gsd"
        assert main(["export-xyz", str(shaped), str(out), "--quiet"]) == 0
        (frame,) = _read(out)
        q = frame.particles.orientation.astype(np.float64)  # (w, x, y, z)
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=4 * FLOAT32)
        np.testing.assert_array_equal(q[:, 1:3], 0.0)
        angle = 2.0 * np.arctan2(q[:, 3], q[:, 0])
        np.testing.assert_allclose(np.exp(1j * angle), np.exp(1j * p.orientation), atol=8 * FLOAT32)
        np.testing.assert_array_equal(frame.particles.typeid, p.shape_index)
        assert frame.particles.types == [f"{kind}{k}" for k, kind in enumerate(p.shapes.kind)]
        np.testing.assert_array_equal(frame.log["particles/angle"], p.orientation)
        for k, shape in enumerate(frame.particles.type_shapes):
            if p.shapes.kind[k] == "ellipse":
                a, b = p.shapes.semi_axes[k]
                assert shape == {"type": "Ellipsoid", "a": a, "b": b, "c": b}
                assert a / b == pytest.approx(1.7, rel=1e-13)
            else:
                assert shape == {}  # circulo-lines: drawn as their bounding disk
        np.testing.assert_allclose(frame.particles.diameter, p.diameter, rtol=FLOAT32)


def test_sphere_columns_match_the_xyz_export(tmp_path):
    # a sheared 3D box with rattlers and forces: the same numbers as in the XYZ file
    box = Box.lees_edwards([1.0, 1.2, 0.8], 0.3)
    rng = np.random.default_rng(1)
    x = box.wrap(box.to_cartesian(rng.random((11, 3))))
    contacts = np.array([[0, 1], [1, 2], [2, 5]])
    p = Packing(x, np.where(np.arange(11) % 2, 0.02, 0.014), box, contacts=contacts,
                force=np.array([1.0, 2.0, 0.5]), rattler=np.arange(11) > 8)
    (frame,) = _read(write_gsd(p, tmp_path / "p.gsd"))
    np.testing.assert_allclose(_box_matrix(frame), box.matrix, rtol=2 * FLOAT32)
    np.testing.assert_allclose(box.minimum_image(_positions_in_jamflow_cell(frame, 3) - x), 0.0, atol=FLOAT32)
    names, index = size_classes(p.diameter)
    assert frame.particles.types == names == ["small", "large"]
    np.testing.assert_array_equal(frame.particles.typeid, index)
    np.testing.assert_array_equal(frame.log["particles/rattler"], p.rattler.astype(int))
    load = frame.log["particles/force_sum"]
    assert load.sum() == pytest.approx(2 * p.force.sum(), rel=1e-15) and load[2] == 2.5
    text = write_xyz(p, tmp_path / "p.xyz").read_text().splitlines()
    column = text[1].split("Properties=")[1].split()[0].split(":")
    at = sum(int(w) for w in column[2::3][: column[0::3].index("force_residual")])
    residual = [float(row.split()[at]) for row in text[2:]]
    np.testing.assert_array_equal(frame.log["particles/force_residual"], residual)
    assert frame.bonds.N == 0 and frame.configuration.dimensions == 3


def test_bad_inputs_write_nothing(tmp_path):
    src = write_packing(Packing(np.array([[0.1] * 4, [0.5] * 4]), np.full(2, 0.1), Box.cubic(4)), tmp_path / "d4.nc")
    assert main(["export-xyz", str(src), str(tmp_path / "d4.gsd")]) == 1
    assert not (tmp_path / "d4.gsd").exists()
    assert main(["export-xyz", str(CIRCULO), str(tmp_path / "c.gsd"), "--pos-2d"]) == 1
    assert not (tmp_path / "c.gsd").exists()
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.slow
def test_ovito_reads_bonds_and_orientations(tmp_path, chains):
    import ovito.io as ovito_io  # the ovito extra: heavy, so only in this slow test
    p = read_packing(chains, None)
    data = ovito_io.import_file(write_gsd(p, tmp_path / "c.gsd")).compute()
    assert data.particles.count == p.n and data.cell.is2D
    np.testing.assert_array_equal(np.asarray(data.particles.bonds.topology), np.column_stack([p.links.i, p.links.j]))
    origin = np.asarray(data.cell)[:2, 3]
    x = np.asarray(data.particles.positions)[:, :2] - origin
    np.testing.assert_allclose(p.box.minimum_image(x - p.position), 0.0, atol=FLOAT32 * p.box.lengths.max())
    shaped = read_packing(CIRCULO, None)
    data = ovito_io.import_file(write_gsd(shaped, tmp_path / "s.gsd")).compute()
    q = np.asarray(data.particles.orientations)  # OVITO's order (x, y, z, w)
    angle = 2.0 * np.arctan2(q[:, 2], q[:, 3])
    np.testing.assert_allclose(np.exp(1j * angle), np.exp(1j * shaped.orientation), atol=8 * FLOAT32)
    np.testing.assert_array_equal(np.asarray(data.particles["shape_index"]), shaped.shape_index)
