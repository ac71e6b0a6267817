"""Every command prints what it computed (unless --quiet), and the printed numbers are the output's."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import xarray as xr

from jamflow.cli import build_parser, main


def _run(capsys: pytest.CaptureFixture[str], *argv: object) -> str:
    assert main([str(a) for a in argv]) == 0
    return capsys.readouterr().out


def _value(out: str, name: str) -> str:
    """The value printed on the summary row ``name``."""
    m = re.search(rf"^\s+{re.escape(name)}\s+(\S+)", out, re.MULTILINE)
    assert m, f"no row {name!r} in:\n{out}"
    return m.group(1)


@pytest.fixture
def jammed(tmp_path: Path) -> tuple[Path, Path]:
    """A small 2D bidisperse random packing and its CALiPPSO jammed packing."""
    start, out = tmp_path / "r.nc", tmp_path / "c.nc"
    assert main(["init", str(start), "--d", "2", "--n", "16", "--phi", "0.6", "--dispersity", "bi",
                 "--seed", "2", "--quiet"]) == 0
    assert main(["calippso", str(start), str(out), "--quiet"]) == 0
    return start, out


def test_every_command_accepts_quiet():
    parser = build_parser()
    missing = [name for name, sub in parser.subcommands.items()
               if not any("--quiet" in a.option_strings for a in sub._actions)]
    assert missing == []


def test_calippso_prints_phi_j_contacts_and_rattlers_of_its_output(capsys, jammed, tmp_path):
    start, _ = jammed
    out = _run(capsys, "calippso", start, tmp_path / "c2.nc")
    attrs = xr.load_dataset(tmp_path / "c2.nc").attrs
    assert f"calippso: {tmp_path / 'c2.nc'}" in out
    assert float(_value(out, "phi_J")) == pytest.approx(attrs["phi_J"], abs=1e-10)
    assert int(_value(out, "contacts N_c")) == attrs["n_contacts"]
    assert int(_value(out, "rattlers")) == attrs["n_rattlers"]


def test_quiet_prints_no_summary(capsys, jammed, tmp_path):
    start, _ = jammed
    assert _run(capsys, "calippso", start, tmp_path / "c2.nc", "--quiet") == ""
    assert _run(capsys, "init", tmp_path / "i.nc", "--d", "2", "--n", "8", "--phi", "0.3", "--seed", "1",
                "--quiet") == ""


def test_init_prints_its_packing_fraction(capsys, tmp_path):
    out = _run(capsys, "init", tmp_path / "i.nc", "--d", "3", "--n", "20", "--phi", "0.3", "--seed", "1")
    phi = xr.load_dataset(tmp_path / "i.nc").attrs["packing_fraction"]
    assert float(_value(out, "packing fraction")) == pytest.approx(phi, abs=1e-10)


def test_gaps_and_forces_print_their_exponents(capsys, jammed, tmp_path):
    _, packing = jammed
    out = _run(capsys, "gaps", packing, tmp_path / "g.nc", "--fit-min", "1e-3", "--fit-max", "1e-1")
    ds = xr.load_dataset(tmp_path / "g.nc")
    printed = _value(out, "gap exponent gamma")
    assert float(printed) == pytest.approx(ds.attrs["fit_exponent"], rel=1e-3, nan_ok=True)
    out = _run(capsys, "forces", packing, tmp_path / "f.nc")
    ds = xr.load_dataset(tmp_path / "f.nc")
    assert float(_value(out, "buckler fraction")) == pytest.approx(ds.attrs["buckler_fraction"], rel=1e-3)
    assert int(_value(out, "samples, forces").split(",")[0]) == 1


def test_check_accepts_quiet_and_still_reports(capsys, jammed):
    _, packing = jammed
    loud = _run(capsys, "check", packing)
    quiet = _run(capsys, "check", packing, "--quiet")
    assert quiet == loud
    assert re.search(r"^isostatic\s+true", quiet, re.MULTILINE)
