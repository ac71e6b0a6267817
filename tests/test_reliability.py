"""Issue 17: trustworthy outputs. Inputs are never destroyed, every command checks the kind
of dataset it reads, impossible targets stop with one line, checkpoints are bound to
their run. Each test reproduces a reported case and fails on the code before its fix.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from test_cli_packings import _run

from jamflow.cli import build_parser
from jamflow.io import (
    DATASET_KINDS,
    dataset_kind,
    file_kind,
    read_dataset,
    write_packing,
)
from jamflow.protocols.initial import random_packing


def _one_line_error(err: str, *names: object) -> None:
    # warnings about the input (e.g. a dilute start for shear) may precede the error line
    lines = [line for line in err.splitlines(keepends=True) if ": warning: " not in line]
    assert len(lines) == 1 and lines[0].endswith("\n") and "Traceback" not in err, repr(err)
    for name in names:
        assert str(name) in err, (name, err)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _random_starts(folder: Path, n: int, phi: float, seeds: tuple[int, int], prefix: str) -> tuple[Path, Path]:
    """Two 2D bidisperse random packings written to ``folder/<prefix><seed>.nc``."""
    paths = [folder / f"{prefix}{seed}.nc" for seed in seeds]
    for seed, path in zip(seeds, paths):
        write_packing(random_packing(n, 2, phi, "bi", seed), path)
    return paths[0], paths[1]


@pytest.fixture
def two_packings(tmp_path: Path) -> tuple[Path, Path]:
    return _random_starts(tmp_path, 16, 0.4, (1, 2), "s")


# --- item 3: an input packing is never destroyed ------------------------------------------


@pytest.mark.parametrize("command, code, named", [("gaps", 1, "packing"), ("forces", 1, "packing"),
                                                  ("export-xyz", 2, ".xyz or .gsd")])
def test_a_forgotten_output_does_not_overwrite_the_second_packing(capsys, two_packings, command, code, named):
    s1, s2 = two_packings
    before = _sha(s2)
    exit_code, _, err = _run(capsys, command, s1, s2)
    assert exit_code == code
    _one_line_error(err, s2, named)
    assert _sha(s2) == before and file_kind(s2) == "packing"
    assert [p.name for p in s2.parent.iterdir() if p.name.startswith(".")] == []  # no temporary left


@pytest.mark.parametrize("argv", [
    ["calippso", "{s1}", "{s1}", "--quiet"],
    ["gaps", "{s1}", "{s2}", "{s2}", "--quiet"],
    ["ls", "{s1}", "{s1}", "--growth-rate", "1e-3", "--p-target", "1e3"],
    ["soft-jam", "{s1}", "{s1}", "--pressure", "1e-3"],
    ["compress", "{s1}", "{out}", "--final", "{s1}"],
    ["shear", "{s1}", "{out}", "--strain", "0.1", "--checkpoint", "{s1}"],
])
def test_an_output_that_is_an_input_is_refused_before_any_work(capsys, tmp_path, two_packings, argv):
    s1, s2 = two_packings
    sums = (_sha(s1), _sha(s2))
    code, _, err = _run(capsys, *[a.format(s1=s1, s2=s2, out=tmp_path / "out.nc") for a in argv])
    assert code == 1
    _one_line_error(err, "s1.nc" if "{s1}" in argv[2:] else "s2.nc")
    assert (_sha(s1), _sha(s2)) == sums
    assert not (tmp_path / "out.nc").exists()


def test_in_place_replaces_an_input_only_when_asked(capsys, two_packings):
    s1, _ = two_packings
    phi = read_dataset(s1).attrs["packing_fraction"]
    code, _, err = _run(capsys, "ls", s1, s1, "--growth-rate", "1e-2", "--p-target", "1e2", "--quiet", "--in-place")
    assert code == 0, err
    ds = read_dataset(s1, "packing")
    assert ds.attrs["pressure"] >= 1e2 and ds.attrs["packing_fraction"] > phi


def test_two_outputs_on_one_path_are_refused(capsys, tmp_path, two_packings):
    s1, _ = two_packings
    out = tmp_path / "same.nc"
    code, _, err = _run(capsys, "ls", s1, out, out, "--growth-rate", "1e-3", "--p-target", "1e2", "1e3")
    assert code == 1
    _one_line_error(err, out, "twice")
    assert not out.exists()


def test_every_command_declares_its_path_arguments():
    # the output/input guard only knows the paths a command declares: a positional path
    # argument left out of reads/writes would escape it
    not_paths = {"kind", "stage"}
    for name, parser in build_parser().subcommands.items():
        reads, writes, packings = parser.get_default("path_roles")
        declared = {r.split("[")[0] for r in (*reads, *writes)}
        dests = {a.dest for a in parser._actions}
        positional = {a.dest for a in parser._actions if not a.option_strings and a.dest != "help"}
        assert positional - not_paths <= declared <= dests, name
        assert set(packings) <= set(writes), name
        has_flag = any("--in-place" in a.option_strings for a in parser._actions)
        assert has_flag == bool(reads and writes), name


# --- item 5: every command checks the kind of dataset it reads ------------------------------


@pytest.mark.parametrize("kind", ["gaps", "eos", "forces", "rdf", "overlap", "phi-kappa", "stress-strain",
                                  "jamming-table", "pareto"])
def test_plot_of_a_packing_as_another_kind_is_one_line(capsys, tmp_path, two_packings, kind):
    s1, _ = two_packings
    code, _, err = _run(capsys, "plot", kind, s1, tmp_path / "out.png")
    assert code == 1
    _one_line_error(err, s1, "holds a packing")
    assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("argv, named", [
    (["jamming-table", "{s1}", "{out}", "--eos", "{s1}"], "{s1}"),
    (["flow-summary", "{s1}", "{out}"], "{s1}"),
])
def test_analyses_refuse_a_packing_in_place_of_their_dataset(capsys, tmp_path, two_packings, argv, named):
    s1, _ = two_packings
    out = tmp_path / "o.nc"
    code, _, err = _run(capsys, *[a.format(s1=s1, out=out) for a in argv])
    assert code == 1
    _one_line_error(err, named.format(s1=s1), "packing")
    assert not out.exists()


def test_a_stage_refuses_an_analysis_output_as_its_packing(capsys, tmp_path, two_packings):
    s1, s2 = two_packings
    gaps = tmp_path / "gaps.nc"
    assert _run(capsys, "gaps", s1, s2, gaps, "--gap-tol", "0.5", "--include-rattlers", "--quiet")[0] == 0
    assert file_kind(gaps) == "gaps"
    for argv in (["calippso", gaps, tmp_path / "c.nc"], ["check", gaps], ["export-xyz", gaps, tmp_path / "g.xyz"]):
        code, _, err = _run(capsys, *argv)
        assert code == 1
        _one_line_error(err, gaps, "gap distribution", "not a packing")


def test_dataset_kinds_are_told_apart_by_their_own_names():
    # each kind's required names identify it and no earlier kind (first match wins)
    import xarray as xr

    for k, (names, _) in DATASET_KINDS.items():
        ds = xr.Dataset({n: ((), 0.0) for n in names})
        assert dataset_kind(ds) == k, (k, dataset_kind(ds))
    # a dataset of none of the kinds is named as such
    assert dataset_kind(xr.Dataset({"foo": ((), 1.0)})) is None


# --- items 4 and 5: impossible LS targets stop with one line and the reached state ------------


def test_ls_of_one_sphere_is_one_line(capsys, tmp_path):
    start = tmp_path / "one.nc"
    assert _run(capsys, "init", start, "--d", "2", "--n", "1", "--phi", "0.1", "--seed", "1")[0] == 0
    code, _, err = _run(capsys, "ls", start, tmp_path / "o.nc", "--growth-rate", "1e-3", "--p-target", "1e3")
    assert code == 1
    _one_line_error(err, "N = 1")
    assert not (tmp_path / "o.nc").exists()


@pytest.mark.parametrize("n", [2, 3, 4])
def test_ls_with_too_few_discs_to_jam_stops_at_half_the_box(capsys, tmp_path, n):
    # N <= 4 monodisperse discs in the unit box cannot form cages before a diameter reaches
    # half the box width (phi = N pi / 16); the run used to spin forever at 100 % CPU
    start, out = tmp_path / "s.nc", tmp_path / "o.nc"
    assert _run(capsys, "init", start, "--d", "2", "--n", n, "--phi", "0.1", "--seed", "1")[0] == 0
    code, _, err = _run(capsys, "ls", start, out, "--growth-rate", "1e-3", "--p-target", "1e3", "--quiet")
    assert code == 1
    _one_line_error(err, f"N = {n}", "too few", "o.reached.nc")
    assert not out.exists()
    reached = read_dataset(tmp_path / "o.reached.nc", "packing")
    assert reached.attrs["packing_fraction"] == pytest.approx(n * np.pi / 16, rel=1e-8)
    assert reached.attrs["pressure"] < 1e3


def test_ls_phi_target_beyond_jamming_stops_as_jammed(capsys, tmp_path):
    from jamflow.io import read_packing
    from jamflow.state.packing import max_overlap

    start, out = tmp_path / "s.nc", tmp_path / "o.nc"
    assert _run(capsys, "init", start, "--d", "3", "--n", "32", "--phi", "0.2", "--seed", "1")[0] == 0
    code, _, err = _run(capsys, "ls", start, out, "--growth-rate", "1e-2", "--phi-target", "0.8",
                        "--max-pressure", "1e8", "--quiet")
    assert code == 1
    _one_line_error(err, "jammed before the target", "o.reached.nc")
    reached = read_packing(tmp_path / "o.reached.nc")
    # jammed: p past the limit, phi within ~d/p of a 3D random packing's phi_J, far below 0.8
    assert reached.pressure >= 1e8
    assert 0.6 < reached.packing_fraction < 0.7
    assert max_overlap(reached)[1] < 1e-8


def test_ls_target_beyond_the_largest_pressure_is_refused(capsys, two_packings, tmp_path):
    s1, _ = two_packings
    code, _, err = _run(capsys, "ls", s1, tmp_path / "o.nc", "--growth-rate", "1e-3", "--p-target", "1e15")
    assert code == 1
    _one_line_error(err, "1e+15")


# --- item 2: a checkpoint is bound to its input and trajectory parameters --------------------


@pytest.fixture
def starts(tmp_path: Path) -> tuple[Path, Path]:
    """Two different 2D bidisperse random starts at phi = 0.5 (shear makes contacts)."""
    return _random_starts(tmp_path, 24, 0.5, (4, 5), "start")


SHEAR = {"--strain": "0.02", "--rate": "1", "--sync-every": "10"}


def _shear(start: Path, out: Path, *extra: object, changes: dict[str, str] | None = None) -> list[object]:
    options = {**SHEAR, **(changes or {})}
    return ["shear", start, out, *[x for kv in options.items() for x in kv], "--quiet", *extra]


@pytest.mark.parametrize("change, differs", [
    ({}, "input packing"),
    ({"--strain": "0.03"}, "stop.strain"),
    ({"--rate": "2"}, "drive.rate"),
    ({"--step-drift": "1e-6"}, "options.step_drift"),
    ({"--order": "2"}, "options.order"),
])
def test_a_checkpoint_of_another_run_is_refused(capsys, tmp_path, starts, change, differs):
    ck = tmp_path / "ck.nc"
    code, _, err = _run(capsys, *_shear(starts[0], tmp_path / "part.nc", "--checkpoint", ck, "--max-steps", "25"))
    assert code == 0 and ck.exists(), err
    before = _sha(ck)
    other = starts[1] if not change else starts[0]
    code, _, err = _run(capsys, *_shear(other, tmp_path / "x.nc", "--checkpoint", ck, changes=change))
    assert code == 1
    _one_line_error(err, ck, differs)
    assert not (tmp_path / "x.nc").exists() and _sha(ck) == before


@pytest.mark.parametrize("order", ["1", "2"])
def test_a_resumed_run_equals_the_uninterrupted_one_and_removes_its_checkpoint(capsys, tmp_path, starts, order):
    ck = tmp_path / "ck.nc"
    full, part, resumed = tmp_path / "full.nc", tmp_path / "part.nc", tmp_path / "resumed.nc"
    step = {"--order": order}
    assert _run(capsys, *_shear(starts[0], full, changes=step))[0] == 0
    assert _run(capsys, *_shear(starts[0], part, "--checkpoint", ck, "--max-steps", "25", changes=step))[0] == 0
    assert ck.exists() and read_dataset(part).attrs["complete"] == 0
    code, _, err = _run(capsys, *_shear(starts[0], resumed, "--checkpoint", ck, changes=step))
    assert code == 0, err
    assert not ck.exists()
    a, b = read_dataset(full, "flow"), read_dataset(resumed, "flow")
    assert a.attrs["complete"] == b.attrs["complete"] == 1
    assert a.sizes["step"] > 25 and a.sizes["event"] > 0
    for name in ("strain", "shear_stress", "pressure", "n_contacts", "event_i", "event_j"):
        assert np.array_equal(a[name].values, b[name].values), name


def test_overdamped_compress_past_jamming_stops_jammed_with_one_line(capsys, tmp_path):
    from jamflow.analysis.contacts import summarize
    from jamflow.io import read_packing

    start, out, final = tmp_path / "s.nc", tmp_path / "o.nc", tmp_path / "f.nc"
    write_packing(random_packing(8, 2, 0.5, "bi", 4), start)
    code, _, err = _run(capsys, "compress", start, out, "--phi", "0.95", "--final", final, "--preset", "fast",
                        "--quiet")
    assert code == 1
    _one_line_error(err, "jammed at phi", "o.reached.nc", "f.reached.nc")
    assert not out.exists() and not final.exists()
    reached = read_packing(tmp_path / "f.reached.nc")
    assert reached.attrs["jammed"] == 1 and reached.packing_fraction < 0.9
    s = summarize(reached)
    assert s.isostatic and s.n_contacts == s.isostatic_count, (s.n_contacts, s.isostatic_count)
    assert read_dataset(tmp_path / "o.reached.nc", "flow").attrs["jammed"] == 1


# --- item 7: smaller ones -------------------------------------------------------------------


@pytest.mark.parametrize("argv, named", [
    (["shear", "{s1}", "{out}", "--strain", "-0.1"], "--strain"),
    (["aqs", "{s1}", "{out}", "--strain", "-0.1", "--step", "1e-3"], "--strain"),
    (["init", "{out}", "--d", "2", "--n", "4", "--phi", "0.1", "--seed", "-1"], "--seed"),
    (["ls", "{s1}", "{out}", "--growth-rate", "1e-3", "--p-target", "-1e3"], "--p-target"),
])
def test_negative_values_are_named(capsys, tmp_path, two_packings, argv, named):
    s1, _ = two_packings
    out = tmp_path / "o.nc"
    code, _, err = _run(capsys, *[a.format(s1=s1, out=out) for a in argv])
    assert code in (1, 2)
    _one_line_error(err, named)
    assert not out.exists()


def test_import_dat_names_a_binary_file(capsys, tmp_path):
    dat = tmp_path / "binary.dat"
    dat.write_bytes(bytes(range(256)) * 4)
    code, _, err = _run(capsys, "import-dat", dat, tmp_path / "o.nc")
    assert code == 1
    _one_line_error(err, dat, "not text")


def test_import_dat_refuses_overlapping_spheres_unless_soft(capsys, tmp_path):
    dat, out = tmp_path / "ov.dat", tmp_path / "o.nc"
    # two discs of diameter 0.3 at distance 0.1: relative overlap 2/3
    dat.write_text("2\n2\n0.3\n0.1 0.1\n0.2 0.1\n")
    code, _, err = _run(capsys, "import-dat", dat, out)
    assert code == 1
    _one_line_error(err, dat, "overlap", "--soft")
    assert not out.exists()
    assert _run(capsys, "import-dat", dat, out, "--soft")[0] == 0
    assert read_dataset(out, "packing")["position"].shape == (2, 2)


# --- item 8: a walled packing is never counted as a periodic one ------------------------


def test_check_and_certify_refuse_a_walled_packing_instead_of_printing_rattlers(capsys, tmp_path):
    # calippso --walls keeps its wall contacts outside the Packing: periodic counting
    # called every sphere a rattler and printed it with exit 0
    start, jammed = tmp_path / "w.nc", tmp_path / "wj.nc"
    assert _run(capsys, "init", start, "--d", "2", "--n", "24", "--phi", "0.3", "--seed", "3", "--walls",
                "--quiet")[0] == 0
    assert _run(capsys, "calippso", start, jammed, "--walls", "--quiet")[0] == 0
    for argv in (["check", jammed], ["certify", jammed, tmp_path / "c.nc", "--quiet"]):
        code, out, err = _run(capsys, *argv)
        assert code == 1 and out == ""
        _one_line_error(err, "walls")
    assert not (tmp_path / "c.nc").exists()
