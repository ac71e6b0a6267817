"""The packing subcommands: init, import-dat, export-xyz, check; help and error reporting."""

from __future__ import annotations

import json
import subprocess
from math import gamma, pi
from pathlib import Path

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.cli import build_parser, main
from jamflow.io import read_dataset, read_packing, write_packing
from jamflow.io.formats import read_dat
from jamflow.state.packing import Packing

CHECK_KEYS = {
    "N", "d", "phi", "n_contacts", "n_rattlers", "n_stable", "isostatic",
    "max_overlap", "max_overlap_rel", "force_balance_residual",
}


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """Run the CLI in-process; usage errors (SystemExit) count as exit codes."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(err: str) -> None:
    assert err.strip(), "an error message is expected"
    assert err.count("\n") == 1 and err.endswith("\n"), repr(err)
    assert "error" in err and "Traceback" not in err


def _raw_phi(path: Path) -> float:
    lines = path.read_text().split("\n")
    d, n, sigma = int(lines[0]), int(lines[1]), float(lines[2])
    return n * pi ** (d / 2) / gamma(d / 2 + 1) * (sigma / 2) ** d


def test_help_of_every_subcommand(capsys: pytest.CaptureFixture[str]) -> None:
    commands = build_parser().subcommands
    assert {"init", "import-dat", "export-xyz", "check"} <= set(commands)
    for name in [[]] + [[c] for c in commands]:
        with pytest.raises(SystemExit) as exc:
            main([*name, "--help"])
        assert exc.value.code == 0, name
        assert "usage: jamflow" in capsys.readouterr().out


def test_init_writes_a_seeded_packing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--d", "3", "--n", "120", "--phi", "0.25", "--dispersity", "bi", "--seed", "9", "--quiet"]
    for name in ("a.nc", "b.nc"):
        code, _, err = _run(capsys, "init", tmp_path / name, *args)
        assert code == 0, err
    a, b = read_packing(tmp_path / "a.nc"), read_packing(tmp_path / "b.nc")
    np.testing.assert_array_equal(a.position, b.position)
    assert (a.n, a.d, a.seed, a.protocol) == (120, 3, 9, "random")
    assert a.packing_fraction == pytest.approx(0.25, rel=1e-13)
    small, large = np.unique(a.diameter)
    assert large / small == pytest.approx(1.4) and np.sum(a.diameter == small) == 60
    # the stage's options are the provenance parameters
    params = a.parameters
    assert (params["d"], params["n"], params["phi"], params["seed"], params["dispersity"]) == (3, 120, 0.25, 9, "bi")
    assert "out" not in params and "handler" not in params


def test_import_export_check_on_the_ls_packings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], calippso_ls_file: Path
) -> None:
    nc = tmp_path / "ls.nc"
    code, _, err = _run(capsys, "import-dat", calippso_ls_file, nc, "--quiet")
    assert code == 0, err
    p = read_packing(nc)
    np.testing.assert_array_equal(p.position, read_dat(calippso_ls_file).position)
    assert read_dataset(nc).attrs["protocol"] == "import-dat"

    code, out, err = _run(capsys, "check", nc, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert CHECK_KEYS <= set(summary)
    assert summary["N"] == 1024 and summary["d"] == p.d
    assert summary["phi"] == pytest.approx(_raw_phi(calippso_ls_file), rel=1e-12)
    if p.d == 3:
        assert summary["phi"] == pytest.approx(0.644, abs=5e-4)
    assert summary["n_stable"] + summary["n_rattlers"] == 1024
    assert summary["max_overlap_rel"] < 1e-12
    assert summary["force_balance_residual"] is None  # an LS snapshot has no forces

    code, out, err = _run(capsys, "check", nc, "--json", "--gap-tol", "1e-3")
    loose = json.loads(out)
    assert code == 0 and loose["n_contacts"] > 2 * p.d * 1024 * 0.45  # z close to 2d

    code, out, err = _run(capsys, "check", nc)
    assert code == 0 and "packing fraction" in out and "isostatic" in out

    xyz = tmp_path / "ls.xyz"
    code, _, err = _run(capsys, "export-xyz", nc, xyz)
    assert code == 0, err
    lines = xyz.read_text().splitlines()
    assert int(lines[0]) == 1024 and len(lines) == 1026


def test_console_script(tmp_path: Path) -> None:
    out = tmp_path / "p.nc"
    run = subprocess.run(
        ["jamflow", "init", str(out), "--d", "2", "--n", "50", "--phi", "0.3", "--seed", "1"],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == 0, run.stderr
    run = subprocess.run(["jamflow", "check", str(out), "--json"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["N"] == 50
    run = subprocess.run(["jamflow", "check", str(tmp_path / "missing.nc")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1
    _one_line_error(run.stderr)


def test_missing_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (
        ["check", tmp_path / "missing.nc"],
        ["export-xyz", tmp_path / "missing.nc", tmp_path / "x.xyz"],
        ["import-dat", tmp_path / "missing.dat", tmp_path / "x.nc"],
    ):
        code, _, err = _run(capsys, *argv)
        assert code == 1, argv
        _one_line_error(err)
        assert "missing" in err
    assert not list(tmp_path.iterdir())


def test_nan_and_malformed_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dat = tmp_path / "nan.dat"
    dat.write_text("2\n2\n0.1\n0.1 nan\n0.5 0.5\n")
    code, _, err = _run(capsys, "import-dat", dat, tmp_path / "x.nc")
    assert code == 1
    _one_line_error(err)
    assert "NaN" in err
    junk = tmp_path / "junk.nc"
    junk.write_text("not netCDF\n")
    code, _, err = _run(capsys, "check", junk)
    assert code == 1
    _one_line_error(err)
    assert not (tmp_path / "x.nc").exists()


def test_wrong_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "p.nc"
    for argv in (
        ["init", out, "--d", "3", "--n", "10", "--phi", "0.1", "--seed", "1", "--bogus"],
        ["init", out, "--d", "three", "--n", "10", "--phi", "0.1", "--seed", "1"],
        ["init", out, "--d", "3", "--n", "10", "--phi", "0.1"],
        ["init", out, "--d", "3", "--n", "10", "--phi", "0.1", "--seed", "1", "--dispersity", "gaussian"],
        ["no-such-command"],
        [],
    ):
        code, _, err = _run(capsys, *argv)
        assert code == 2, argv
        _one_line_error(err)
    assert not out.exists()


def test_bad_values_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "p.nc"
    for argv, message, expected in (
        (["--d", "1", "--n", "10", "--phi", "0.1"], "--d", 2),
        (["--d", "2", "--n", "10", "--phi", "1.5"], "--phi", 2),
        (["--d", "2", "--n", "2", "--phi", "0.5"], "half the box", 1),
    ):
        code, _, err = _run(capsys, "init", out, *argv, "--seed", "0")
        assert code == expected, argv
        _one_line_error(err)
        assert message in err
    assert not out.exists()


def test_overlapping_packing_needs_soft(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    p = Packing(np.array([[0.5, 0.5], [0.58, 0.5], [0.2, 0.2]]), np.full(3, 0.1), Box.cubic(2))
    nc = write_packing(p, tmp_path / "soft.nc")
    code, _, err = _run(capsys, "export-xyz", nc, tmp_path / "a.xyz")
    assert code == 1
    _one_line_error(err)
    assert "(0, 1)" in err and not (tmp_path / "a.xyz").exists()
    code, _, err = _run(capsys, "export-xyz", nc, tmp_path / "a.xyz", "--soft")
    assert code == 0, err
    # check reports the overlap instead of refusing the file
    code, out, err = _run(capsys, "check", nc, "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["max_overlap"] == pytest.approx(0.02, rel=1e-9)
    assert summary["max_overlap_rel"] == pytest.approx(0.2, rel=1e-9)
    code, _, err = _run(capsys, "check", nc, "--overlap-tol", "1e-8")
    assert code == 1
    _one_line_error(err)


def test_the_command_table_names_the_module_that_registers_each_command() -> None:
    """``COMMAND_MODULE`` (which lets a command line import one topic module) lists
    every registered subcommand with its module, and nothing else."""
    import argparse
    import importlib

    from jamflow.cli import COMMAND_MODULE, COMMAND_MODULES

    registered = {}
    for module in COMMAND_MODULES:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(f"jamflow.cli.{module}").register(sub)
        registered.update(dict.fromkeys(sub.choices, module))
    assert registered == COMMAND_MODULE
    for command, module in COMMAND_MODULE.items():
        assert set(build_parser(command).subcommands) == {c for c, m in COMMAND_MODULE.items() if m == module}
