"""netCDF round trips, provenance, atomic writes, CALiPPSO .dat and extended XYZ."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
from math import gamma, pi
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from jamflow.box import Box
from jamflow.io import (
    new_dataset_attrs,
    read_dataset,
    read_packing,
    write_dataset,
    write_packing,
)
from jamflow.io.formats import read_dat, write_dat, write_xyz
from jamflow.state.packing import OverlapError, Packing

#: Packing fractions stated by the data's README (computed by the CALiPPSO authors).
README_PHI = {3: 0.64395, 4: 0.4675, 5: 0.3162}

PROVENANCE = ("Conventions", "jamflow_version", "git_sha", "created", "parameters", "title", "history", "source")


def _packing(box: Box | None = None, n: int = 30, seed: int = 3) -> Packing:
    box = box or Box.lees_edwards([1.0, 1.1, 0.9], 17.25)
    rng = np.random.default_rng(seed)
    return Packing(
        position=box.wrap(box.to_cartesian(rng.random((n, box.d)))),
        diameter=rng.uniform(0.001, 0.002, n),
        box=box,
        contacts=[[0, 2], [1, 29], [3, 4], [5, 6]],
        force=rng.random(4) * 1e-7,
        rattler=rng.random(n) < 0.3,
        pressure=3.3e11,
        protocol="random>ls>calippso",
        seed=2**40 + 1,
        parameters={"tol_s": 1e-13, "p_targets": [1e3, 1e6], "solver": {"name": "highs", "eps": 1e-9}},
        attrs={"force_unit": "1/p", "converged": True, "iterations": 12},
    )


# --- netCDF -----------------------------------------------------------------------------


def test_packing_round_trip_through_netcdf_is_exact(tmp_path: Path) -> None:
    p = _packing()
    path = write_packing(p, tmp_path / "p.nc")
    q = read_packing(path)
    for name in ("position", "diameter", "contacts", "force", "rattler"):
        a, b = getattr(p, name), getattr(q, name)
        assert a.dtype == b.dtype and a.shape == b.shape, name
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(q.box.matrix, p.box.matrix)
    assert q.pressure == p.pressure and q.seed == p.seed and q.protocol == p.protocol
    assert q.parameters == p.parameters
    assert q.attrs["force_unit"] == "1/p" and q.attrs["iterations"] == 12
    assert q.attrs["converged"] == 1  # booleans are stored as 0/1
    assert q.packing_fraction == p.packing_fraction


def test_round_trip_of_an_empty_contact_list(tmp_path: Path) -> None:
    p = _packing().evolve(contacts=np.zeros((0, 2), dtype=np.int64), force=np.zeros(0), rattler=np.ones(30, bool))
    q = read_packing(write_packing(p, tmp_path / "p.nc"))
    assert q.contacts.shape == (0, 2) and q.force.shape == (0,)
    assert q.rattler.all()


def test_stage_parameters_replace_the_packing_parameters(tmp_path: Path) -> None:
    p = _packing()
    q = read_packing(write_packing(p, tmp_path / "p.nc", {"phi": 0.5, "seed": 1}))
    assert q.parameters == {"phi": 0.5, "seed": 1}


def test_units_long_names_and_provenance_on_disk(tmp_path: Path) -> None:
    p = _packing()
    ds = read_dataset(write_packing(p, tmp_path / "p.nc"))
    for name, var in ds.variables.items():
        assert isinstance(var.attrs.get("units"), str) and var.attrs["units"], name
        assert isinstance(var.attrs.get("long_name"), str) and var.attrs["long_name"], name
        if var.dtype.kind == "f":
            assert var.encoding.get("zlib"), name
    for key in PROVENANCE + ("d", "N", "packing_fraction", "protocol", "seed", "pressure"):
        assert key in ds.attrs, key
    assert ds.attrs["Conventions"].startswith("CF-")
    assert ds.attrs["d"] == 3 and ds.attrs["N"] == p.n
    assert ds.attrs["packing_fraction"] == p.packing_fraction
    assert ds.attrs["protocol"] == p.protocol and ds.attrs["seed"] == p.seed
    assert json.loads(ds.attrs["parameters"]) == p.parameters
    assert len(ds.attrs["git_sha"]) >= 7
    assert ds.attrs["created"][:4].isdigit()
    assert ds.sizes["particle"] == p.n and ds.sizes["spatial"] == 3 and ds.sizes["contact"] == 4


def test_write_dataset_sanitises_attributes(tmp_path: Path) -> None:
    attrs = new_dataset_attrs("test product", {"a": 1, "b": [1.5, 2]}, flag=True, nothing=None,
                              table={"x": 1}, count=np.int32(3))
    ds = xr.Dataset({"v": ("bin", np.arange(3.0), {"units": "1", "long_name": "v", "ok": np.bool_(False)})},
                    attrs=attrs)
    back = read_dataset(write_dataset(ds, tmp_path / "x.nc"))
    assert json.loads(back.attrs["parameters"]) == {"a": 1, "b": [1.5, 2]}
    assert back.attrs["flag"] == 1 and back.attrs["nothing"] == ""
    assert json.loads(back.attrs["table"]) == {"x": 1} and back.attrs["count"] == 3
    assert back["v"].attrs["ok"] == 0
    for key in PROVENANCE:
        assert key in back.attrs
    # the caller's dataset is not modified
    assert ds.attrs["flag"] is True


def test_written_files_get_the_usual_permissions(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        mode = stat.S_IMODE(write_packing(_packing(), tmp_path / "p.nc").stat().st_mode)
        text_mode = stat.S_IMODE(write_xyz(_packing(), tmp_path / "p.xyz").stat().st_mode)
    finally:
        os.umask(old)
    assert mode == text_mode == 0o644


def test_reading_bad_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_dataset(tmp_path / "missing.nc")
    junk = tmp_path / "junk.nc"
    junk.write_bytes(b"CDF\x01 this is not netCDF" * 10)
    with pytest.raises(ValueError, match="not a readable netCDF"):
        read_dataset(junk)
    not_packing = write_dataset(xr.Dataset({"v": ("x", [1.0])}), tmp_path / "v.nc")
    with pytest.raises(ValueError, match="missing variable"):
        read_packing(not_packing)


def test_read_packing_checks_overlaps(tmp_path: Path) -> None:
    box = Box.cubic(2)
    p = Packing(np.array([[0.5, 0.5], [0.59, 0.5]]), np.full(2, 0.1), box)
    path = write_packing(p, tmp_path / "soft.nc")
    with pytest.raises(OverlapError, match=r"\(0, 1\)"):
        read_packing(path)
    assert read_packing(path, overlap_tol=None).n == 2
    assert read_packing(path, overlap_tol=0.2).n == 2


def test_failed_write_leaves_previous_file_and_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "p.nc"
    write_packing(_packing(), path)
    before = path.read_bytes()
    bad = xr.Dataset({"v": ("x", np.array([{"a": 1}], dtype=object))})
    with pytest.raises(ValueError):
        write_dataset(bad, path)
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["p.nc"]


_KILLED_WRITER = textwrap.dedent(
    """
    import sys
    import numpy as np
    import xarray as xr
    from jamflow.io import write_dataset
    # random numbers compress slowly: the write takes seconds; shaped as a packing, since
    # write_dataset refuses to replace a packing by another kind of dataset
    v = np.random.default_rng(0).random((2_500_000, 2))
    ds = xr.Dataset({"position": (("particle", "spatial"), v, {"units": "1", "long_name": "noise"}),
                     "diameter": (("particle",), np.full(len(v), 1e-4)),
                     "box": (("spatial", "lattice_vector"), np.eye(2))})
    print("ready", flush=True)
    write_dataset(ds, sys.argv[1])
    """
)


@pytest.mark.parametrize("existing", [False, True], ids=["new", "overwrite"])
def test_killed_write_leaves_no_valid_looking_file(tmp_path: Path, existing: bool) -> None:
    path = tmp_path / "big.nc"
    if existing:
        previous = _packing()
        write_packing(previous, path)
        before = path.read_bytes()
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        # wait until netCDF has started writing the temporary file: the writer is midway
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            tmps = [f for f in tmp_path.iterdir() if f.name.endswith(".tmp")]
            if tmps and tmps[0].stat().st_size > 0:
                break
            assert proc.poll() is None, "the writer finished before it could be killed"
            time.sleep(0.002)
        else:
            pytest.fail("no temporary file appeared")
        assert proc.poll() is None, "the writer finished before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    leftovers = [f.name for f in tmp_path.iterdir() if f.name != "big.nc"]
    # the only leftover is the hidden temporary, which no *.nc glob matches
    assert all(name.startswith(".big.nc.") and name.endswith(".tmp") for name in leftovers)
    if existing:
        assert path.read_bytes() == before
        q = read_packing(path)
        np.testing.assert_array_equal(q.position, previous.position)
    else:
        assert not path.exists()
        assert not list(tmp_path.glob("*.nc"))


# --- CALiPPSO .dat ------------------------------------------------------------------------


def test_read_calippso_ls_files(calippso_ls_file: Path) -> None:
    # independent reading of the raw text
    lines = calippso_ls_file.read_text().split("\n")
    d, n, sigma = int(lines[0]), int(lines[1]), float(lines[2])
    raw = np.array([[float(v) for v in ln.split()] for ln in lines[3:] if ln.strip()])
    phi = n * pi ** (d / 2) / gamma(d / 2 + 1) * (sigma / 2) ** d
    p = read_dat(calippso_ls_file)
    assert (p.n, p.d) == (n, d) == (1024, d)
    assert p.box == Box.cubic(d, 1.0)
    np.testing.assert_array_equal(p.diameter, sigma)
    assert np.all((raw >= 0) & (raw < 1))  # so wrapping must not change the centres
    np.testing.assert_array_equal(p.position, raw)
    assert p.packing_fraction == pytest.approx(phi, rel=1e-12)
    assert p.packing_fraction == pytest.approx(README_PHI[d], abs=1e-4)
    if d == 3:
        assert p.packing_fraction == pytest.approx(0.644, abs=5e-4)
    p.validate()  # an LS packing has no overlaps beyond round-off


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "not a CALiPPSO"),
        ("3\n", "not a CALiPPSO"),
        ("3\n2\n", "not a CALiPPSO"),
        ("three\n2\n0.1\n0 0 0\n0.5 0.5 0.5\n", "not a CALiPPSO"),
        ("3\n2\n0.1\n0 0 0\n0.5 0.5 x\n", "not a CALiPPSO"),
        ("3\n2\n0.1\n0 0 0\n0.5 0.5\n", "not a CALiPPSO|shape"),
        ("3\n3\n0.1\n0 0 0\n0.5 0.5 0.5\n", "N=3"),
        ("2\n2\n0.1\n0 0 0\n0.5 0.5 0.5\n", "d=2"),
        ("3\n2\n0.1\n0 0 nan\n0.5 0.5 0.5\n", "NaN"),
        ("3\n2\n-0.1\n0 0 0\n0.5 0.5 0.5\n", "diameter"),
        ("3\n2\n0.6\n0 0 0\n0.5 0.5 0.5\n", "half the smallest box width"),
    ],
)
def test_malformed_dat_files_raise(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.dat"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_dat(path)


def test_missing_dat_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        read_dat(tmp_path / "missing.dat")


@pytest.mark.parametrize("d", [2, 3, 5])
def test_write_dat_round_trip(tmp_path: Path, d: int) -> None:
    box = Box.cubic(d)
    x = np.random.default_rng(d).random((7, d))
    p = Packing(x, np.full(7, 0.0123456789012345), box)
    q = read_dat(write_dat(p, tmp_path / "p.dat"))
    np.testing.assert_array_equal(q.position, p.position)
    np.testing.assert_array_equal(q.diameter, p.diameter)
    assert q.box == p.box


def test_write_dat_refuses_what_the_format_cannot_hold(tmp_path: Path) -> None:
    x = np.random.default_rng(0).random((3, 2))
    with pytest.raises(ValueError, match="unit cubic"):
        write_dat(Packing(2 * x, np.full(3, 0.1), Box.cubic(2, 2.0)), tmp_path / "a.dat")
    with pytest.raises(ValueError, match="monodisperse"):
        write_dat(Packing(x, [0.1, 0.1, 0.2], Box.cubic(2)), tmp_path / "b.dat")
    assert not list(tmp_path.iterdir())


# --- extended XYZ -----------------------------------------------------------------------


def _parse_extxyz(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str], dict[str, str]]:
    """Strict reader of the extended XYZ written for one frame."""
    lines = path.read_text().split("\n")
    assert lines[-1] == "" and "" not in lines[:-1], "one frame, no blank lines"
    n = int(lines[0])
    assert len(lines) == n + 3
    header = lines[1]
    fields: dict[str, str] = {}
    rest = header
    while rest:
        key, rest = rest.split("=", 1)
        if rest.startswith('"'):
            value, rest = rest[1:].split('"', 1)
        else:
            value, _, rest = rest.partition(" ")
        fields[key.strip()] = value
        rest = rest.strip()
    assert fields["Properties"] == "type:S:1:pos:R:3:radius:R:1"
    lattice = np.array([float(v) for v in fields["Lattice"].split()]).reshape(3, 3)
    rows = [ln.split() for ln in lines[2 : 2 + n]]
    assert all(len(r) == 5 for r in rows)
    # size classes, never a chemical symbol (the old files said "S": sulfur)
    assert {r[0] for r in rows} <= {"sphere", "small", "large", "poly"}
    pos = np.array([[float(v) for v in r[1:4]] for r in rows])
    radius = np.array([float(r[4]) for r in rows])
    return lattice, pos, radius, fields["pbc"].split(), fields


def test_xyz_of_the_ls_packing(tmp_path: Path, calippso_ls_file: Path) -> None:
    p = read_dat(calippso_ls_file)
    path = write_xyz(p, tmp_path / "p.xyz")
    lattice, pos, radius, pbc, fields = _parse_extxyz(path)
    np.testing.assert_array_equal(lattice, np.eye(3))
    np.testing.assert_array_equal(pos, p.position[:, :3])
    np.testing.assert_array_equal(radius, p.diameter / 2)
    assert pbc == ["T", "T", "T"]
    assert float(fields["phi"]) == p.packing_fraction
    if p.d > 3:
        assert fields["projection"] == f"first 3 of {p.d} coordinates"


def test_xyz_of_a_sheared_2d_packing(tmp_path: Path) -> None:
    box = Box.lees_edwards([1.0, 2.0], 3.4)
    rng = np.random.default_rng(0)
    p = Packing(box.to_cartesian(rng.uniform(-1, 2, (9, 2))), rng.uniform(0.05, 0.1, 9), box)
    lattice, pos, radius, pbc, _ = _parse_extxyz(write_xyz(p, tmp_path / "p.xyz"))
    # rows of the Lattice field are the lattice vectors (columns of the box matrix)
    np.testing.assert_array_equal(lattice[:2, :2], box.matrix.T)
    assert lattice[2, 2] > 0 and pbc == ["T", "T", "F"]
    np.testing.assert_array_equal(pos[:, 2], 0.0)
    # centres are wrapped into the sheared cell, images of the input
    assert np.all(box.contains(pos[:, :2]))
    np.testing.assert_allclose(box.minimum_image(pos[:, :2] - p.position), 0.0, atol=1e-12)
    np.testing.assert_array_equal(radius, p.diameter / 2)


def test_xyz_read_by_ase(tmp_path: Path) -> None:
    import ase.io as ase_io

    box = Box.lees_edwards([1.0, 1.2, 0.8], 0.3)
    rng = np.random.default_rng(1)
    p = Packing(box.wrap(box.to_cartesian(rng.random((11, 3)))), rng.uniform(0.01, 0.02, 11), box)
    atoms = ase_io.read(write_xyz(p, tmp_path / "p.xyz"), format="extxyz")
    assert len(atoms) == p.n
    np.testing.assert_allclose(atoms.cell.array, box.matrix.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(atoms.get_positions(), p.position, rtol=0, atol=1e-15)
    np.testing.assert_allclose(atoms.arrays["radius"], p.diameter / 2, rtol=0, atol=1e-15)
    assert list(atoms.pbc) == [True, True, True]


def test_vendored_ls_data_is_present_and_a_missing_file_is_an_error() -> None:
    from ls_data import LS_DIMENSIONS, LS_DIR, ls_dat

    assert [ls_dat(d).name for d in LS_DIMENSIONS] == [f"Centers-after-LS--N-1024--d-{d}.dat" for d in (3, 4, 5)]
    assert "MIT" in (LS_DIR / "README.md").read_text()
    with pytest.raises(FileNotFoundError, match="d-6.dat"):
        ls_dat(6)
