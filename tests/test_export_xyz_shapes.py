"""export-xyz of shaped bodies: orientation quaternions and ellipse shapes, read back with ASE."""

from __future__ import annotations

from pathlib import Path

import ase.io
import numpy as np

from jamflow.cli import main
from jamflow.io import read_packing

DATA = Path(__file__).parent / "data" / "shapes_circulo_line_a1.1_n16_p1e-6.nc"


def test_circulo_orientations_round_trip(tmp_path):
    out = tmp_path / "c.xyz"
    assert main(["export-xyz", str(DATA), str(out), "--quiet"]) == 0
    p = read_packing(DATA, None)
    atoms = ase.io.read(out, format="extxyz")
    q = atoms.arrays["orientation"]
    np.testing.assert_allclose(np.sum(q**2, axis=1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(q[:, :2], 0.0, atol=0.0)
    # the quaternion turns the body x axis onto (cos theta, sin theta)
    angle = 2.0 * np.arctan2(q[:, 2], q[:, 3])
    np.testing.assert_allclose(np.cos(angle), np.cos(p.orientation), atol=1e-14)
    np.testing.assert_allclose(np.sin(angle), np.sin(p.orientation), atol=1e-14)
    np.testing.assert_array_equal(atoms.arrays["shape_index"], p.shape_index)
    np.testing.assert_allclose(atoms.arrays["angle"], p.orientation, rtol=1e-15)
    assert "aspherical_shape" not in atoms.arrays


def test_ellipse_aspherical_shape(tmp_path):
    src = tmp_path / "e.nc"
    assert main(["init-shapes", str(src), "--shape", "ellipse", "--aspect-ratio", "1.7", "--n", "12",
                 "--seed", "4", "--quiet"]) == 0
    out = tmp_path / "e.xyz"
    assert main(["export-xyz", str(src), str(out), "--quiet"]) == 0
    p = read_packing(src, None)
    atoms = ase.io.read(out, format="extxyz")
    shape = atoms.arrays["aspherical_shape"]
    np.testing.assert_allclose(shape[:, :2], p.shapes.semi_axes[p.shape_index], rtol=1e-15)
    np.testing.assert_allclose(shape[:, 0] / shape[:, 1], 1.7, rtol=1e-13)
    np.testing.assert_allclose(atoms.arrays["radius"], shape[:, 0], rtol=1e-15)  # bounding radius = a
