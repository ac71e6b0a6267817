"""``jamflow export-xyz`` read back with ASE: types, radii, cell, pbc, rattlers, forces, 2D, trajectories."""

from __future__ import annotations

from pathlib import Path

import ase.io
import numpy as np
import pytest
import xarray as xr

from jamflow.box import Box
from jamflow.cli import main
from jamflow.io import read_packing, write_packing
from jamflow.io.formats import size_classes, write_xyz
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import Packing
from jamflow.tolerances import FORCE_BALANCE_TOL


@pytest.fixture(scope="module")
def jammed_2d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A CALiPPSO-jammed 2D bidisperse packing (contacts, forces, rattlers) on disk."""
    p = calippso(random_packing(40, 2, 0.5, "bi", seed=5)).packing
    return write_packing(p, tmp_path_factory.mktemp("xyz") / "jammed.nc")


def _export(tmp_path: Path, src: Path, *extra: str) -> Path:
    out = tmp_path / "out.xyz"
    assert main(["export-xyz", str(src), str(out), "--quiet", *extra]) == 0
    return out


def test_a_2d_jammed_packing_reads_back_in_ase(tmp_path, jammed_2d):
    p = read_packing(jammed_2d)
    atoms = ase.io.read(_export(tmp_path, jammed_2d), format="extxyz")
    # 2D: periodic in x and y only, the box in the plane, the discs at z = 0
    assert list(atoms.pbc) == [True, True, False]
    np.testing.assert_array_equal(atoms.cell.array[:2, :2], p.box.matrix.T)
    np.testing.assert_array_equal(atoms.cell.array[2], [0.0, 0.0, p.diameter.max()])
    np.testing.assert_allclose(p.box.minimum_image(atoms.positions[:, :2] - p.position), 0.0, atol=1e-15)
    np.testing.assert_array_equal(atoms.positions[:, 2], 0.0)
    np.testing.assert_array_equal(atoms.arrays["radius"], p.diameter / 2)
    # no chemistry: ASE sees dummy atoms, the size class is the type
    assert set(atoms.get_chemical_symbols()) == {"X"}
    types = atoms.arrays["type"]
    assert set(types) == {"small", "large"}
    assert atoms.arrays["radius"][types == "small"].max() < atoms.arrays["radius"][types == "large"].min()
    np.testing.assert_array_equal(atoms.arrays["rattler"], p.rattler.astype(int))
    # per-particle forces: each contact force counted once on each of its two particles
    assert atoms.arrays["force_sum"].sum() == pytest.approx(2 * np.abs(p.force).sum(), rel=1e-14)
    i = int(np.argmax(atoms.arrays["force_sum"]))
    mine = (p.contacts[:, 0] == i) | (p.contacts[:, 1] == i)
    assert atoms.arrays["force_sum"][i] == pytest.approx(np.abs(p.force[mine]).sum(), rel=1e-14)
    # a jammed packing is in force balance: the residual column says so on the backbone
    assert atoms.arrays["force_residual"][~p.rattler].max() < FORCE_BALANCE_TOL
    assert np.all(atoms.arrays["force_sum"][p.rattler] == 0.0)
    assert atoms.info["phi"] == p.packing_fraction


def test_pos_2d_writes_two_position_columns_for_ovito(tmp_path, jammed_2d):
    header = _export(tmp_path, jammed_2d, "--pos-2d").read_text().splitlines()[1]
    assert "Properties=type:S:1:pos:R:2:radius:R:1" in header
    assert main(["export-xyz", str(tmp_path / "x.nc"), str(tmp_path / "x.xyz"), "--pos-2d"]) == 1


def test_a_sheared_3d_packing_keeps_its_tilted_cell(tmp_path):
    box = Box.lees_edwards([1.0, 1.2, 0.8], 0.3)
    rng = np.random.default_rng(1)
    p = Packing(box.wrap(box.to_cartesian(rng.random((11, 3)))), np.full(11, 0.015), box)
    atoms = ase.io.read(write_xyz(p, tmp_path / "p.xyz"), format="extxyz")
    np.testing.assert_array_equal(atoms.cell.array, box.matrix.T)
    assert list(atoms.pbc) == [True, True, True]
    assert set(atoms.arrays["type"]) == {"sphere"}
    assert "rattler" not in atoms.arrays and "force_sum" not in atoms.arrays


def test_size_classes_name_sizes_in_order_and_lump_continuous_distributions():
    names, index = size_classes(np.array([1.4, 1.0, 1.4, 1.0 * (1 + 1e-12)]))
    assert names == ["small", "large"] and list(index) == [1, 0, 1, 0]
    names, index = size_classes(np.array([3.0, 1.0, 2.0]))
    assert names == ["size1", "size2", "size3"] and list(index) == [2, 0, 1]
    names, index = size_classes(np.linspace(1.0, 1.3, 40))
    assert names == ["poly"] and not index.any()


def test_a_flow_run_exports_one_frame_per_snapshot(tmp_path):
    start = tmp_path / "start.nc"
    write_packing(random_packing(16, 2, 0.6, "bi", seed=2), start)
    series = tmp_path / "shear.nc"
    assert main(["shear", str(start), str(series), "--strain", "0.02", "--snapshots", "3", "--quiet"]) == 0
    snaps = xr.load_dataset(tmp_path / "shear.snapshots.nc")
    frames = ase.io.read(_export(tmp_path, tmp_path / "shear.snapshots.nc"), index=":", format="extxyz")
    assert len(frames) == snaps.sizes["snapshot"] >= 3
    for k, atoms in enumerate(frames):
        box = snaps["snapshot_box"].values[k]
        # Lees-Edwards: each frame has its own tilted cell and strain
        np.testing.assert_array_equal(atoms.cell.array[:2, :2], box.T)
        assert atoms.info["strain"] == float(snaps["snapshot_strain"].values[k])
        assert len(atoms) == snaps.sizes["particle"]
    strains = [a.info["strain"] for a in frames]
    assert strains == sorted(strains) and strains[-1] > strains[0]
    # the time series itself has no positions: a clear error, nothing written
    code = main(["export-xyz", str(series), str(tmp_path / "bad.xyz")])
    assert code == 1 and not (tmp_path / "bad.xyz").exists()
