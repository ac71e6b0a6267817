"""Issue 17: trustworthy outputs. Inputs are never destroyed, every command checks the kind
of dataset it reads, impossible targets stop with one line, checkpoints are bound to
their run. Each test reproduces a reported case and fails on the code before its fix.
"""

from __future__ import annotations

import hashlib
import shutil
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


# --- issue 47: nothing wrong in print, nothing that hangs, every bad value refused -------------

KINDS = Path(__file__).parent / "data" / "kinds"


@pytest.mark.parametrize("argv, named", [
    (["gaps", "{s1}", "{out}", "--bootstrap", "-1"], "--bootstrap"),
    (["forces", "{s1}", "{out}", "--linear-bins", "0"], "--linear-bins"),
    (["shear", "{s1}", "{out}", "--strain", "0.1", "--snapshots", "-2"], "--snapshots"),
    (["moduli", "{s1}", "{out}", "--modes", "-1"], "--modes"),
    (["compress", "{s1}", "{out}", "--phi", "nan"], "--phi"),
    (["drive", "{s1}", "{out}", "--time", "1", "--random-forces", "nan"], "--random-forces"),
    (["init", "{out}", "--d", "2", "--n", "4", "--phi", "0.1", "--seed", str(2**64)], "--seed"),
    (["export-xyz", "{s1}", "{s2}"], ".xyz or .gsd"),
    (["rdf", "{s1}", "{s2}.xyz"], ".nc"),
])
def test_a_bad_value_of_the_issue_is_a_usage_error(capsys, tmp_path, two_packings, argv, named):
    s1, s2 = two_packings
    sums = (_sha(s1), _sha(s2))
    out = tmp_path / "o.nc"
    code, _, err = _run(capsys, *[a.format(s1=s1, s2=s2, out=out) for a in argv])
    assert code == 2
    _one_line_error(err, named)
    assert (_sha(s1), _sha(s2)) == sums and not out.exists()


def test_the_largest_seed_is_written_and_read_back(capsys, tmp_path):
    out = tmp_path / "s.nc"
    assert _run(capsys, "init", out, "--d", "2", "--n", "4", "--phi", "0.1", "--seed", str(2**64 - 1))[0] == 0
    from jamflow.io import read_packing

    assert read_packing(out).seed == 2**64 - 1


@pytest.mark.parametrize("how", ["same path", "symlink", "hard link", "copy"])
def test_a_pooled_analysis_refuses_one_packing_given_twice(capsys, tmp_path, two_packings, how):
    s1, _ = two_packings
    twin = {"same path": s1, "symlink": tmp_path / "twin.nc", "hard link": tmp_path / "twin.nc",
            "copy": tmp_path / "twin.nc"}[how]
    if how == "symlink":
        twin.symlink_to(s1)
    elif how == "hard link":
        twin.hardlink_to(s1)
    elif how == "copy":
        twin.write_bytes(s1.read_bytes())
    code, _, err = _run(capsys, "gaps", s1, twin, tmp_path / "g.nc", "--gap-tol", "0.5", "--include-rattlers",
                        "--quiet")
    assert code == (1 if how == "copy" else 2)
    _one_line_error(err, "twice")
    assert not (tmp_path / "g.nc").exists()


def test_an_existing_output_of_another_kind_is_refused_before_any_work(capsys, tmp_path, two_packings):
    s1, s2 = two_packings
    gaps, rdf = tmp_path / "g.nc", tmp_path / "r.nc"
    shutil.copy(KINDS / "rdf.nc", rdf)
    before = _sha(rdf)
    code, _, err = _run(capsys, "gaps", s1, s2, rdf, "--gap-tol", "0.5", "--include-rattlers", "--quiet")
    assert code == 1
    _one_line_error(err, rdf, "g(r) dataset", "gap distribution")
    assert _sha(rdf) == before
    # someone else's netCDF file and a text file under an output name are not replaced either
    foreign = tmp_path / "foreign.nc"
    import xarray as xr

    xr.Dataset({"temperature": ("t", [1.0, 2.0])}).to_netcdf(foreign)
    for target in (foreign, tmp_path / "notes.nc"):
        if target.name == "notes.nc":
            target.write_text("my notes\n")
        code, _, err = _run(capsys, "gaps", s1, s2, target, "--gap-tol", "0.5", "--include-rattlers", "--quiet")
        assert code == 1
        _one_line_error(err, target, "no jamflow dataset" if target == foreign else "no netCDF data")
    # an output of the same kind is replaced, and the command says so
    assert _run(capsys, "gaps", s1, s2, gaps, "--gap-tol", "0.5", "--include-rattlers", "--quiet")[0] == 0
    code, _, err = _run(capsys, "gaps", s1, s2, gaps, "--gap-tol", "0.5", "--include-rattlers", "--quiet")
    assert code == 0 and f"replaced {gaps} (a gap distribution" in err
    # and the writers refuse another kind too (a library caller, or an output no command declared)
    from jamflow.io import write_dataset

    with pytest.raises(ValueError, match="refusing to overwrite"):
        write_dataset(read_dataset(gaps), rdf)


def test_a_full_disk_is_named_as_such_and_leaves_nothing(capsys, tmp_path, two_packings, monkeypatch):
    # the netCDF library reports a full disk as "Permission denied" (or "HDF error")
    import os

    import xarray as xr

    s1, _ = two_packings
    statvfs = os.statvfs(tmp_path)

    class Full:
        f_bavail, f_frsize = 0, statvfs.f_frsize

    def full_write(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", full_write)
    monkeypatch.setattr(os, "statvfs", lambda path: Full)
    out = tmp_path / "o.nc"
    code, _, err = _run(capsys, "rdf", s1, out, "--r-max", "1")
    assert code == 1
    _one_line_error(err, "no space left", out)
    assert "Permission" not in err and not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_summary_refuses_a_flow_series_where_a_packing_should_be(capsys, tmp_path):
    sample = tmp_path / "scene" / "spheres" / "base" / "seed1"
    sample.mkdir(parents=True)
    shutil.copy(KINDS / "packing.nc", sample / "calippso.nc")
    shutil.copy(KINDS / "flow.nc", sample / "soft.nc")
    code, out, err = _run(capsys, "summary", tmp_path / "scene")
    assert code == 1 and out == ""
    _one_line_error(err, "soft.nc", "flow time series", "not a packing")


@pytest.mark.parametrize("argv", [
    ["init", "{out}", "--d", "3", "--n", "1e9", "--phi", "0.3", "--seed", "1"],
    ["init-shapes", "{out}", "--shape", "ellipse", "--asphericity", "1.1", "--n", "1000000000", "--seed", "1"],
    ["init-chains", "{out}", "--d", "3", "--clusters", "1000000000", "--cluster", "trimer", "--seed", "1"],
])
def test_a_start_that_does_not_fit_in_memory_is_refused_before_allocating(capsys, tmp_path, argv):
    import tracemalloc

    out = tmp_path / "o.nc"
    tracemalloc.start()
    code, _, err = _run(capsys, *[a.format(out=out) for a in argv])
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert code == 1
    _one_line_error(err, "of memory and this machine has")
    assert peak < 100e6 and not out.exists()


def test_resources_scale_with_the_system():
    from jamflow.resources import (
        INTERPRETER_BYTES,
        check_fits,
        machine_memory,
        stage_memory,
    )

    assert machine_memory() > INTERPRETER_BYTES
    for stage in ("init", "init-shapes", "init-chains"):
        small, large = stage_memory(stage, 10**3, 2), stage_memory(stage, 10**6, 2)
        assert INTERPRETER_BYTES < small < large
        assert stage_memory(stage, 10**6, 3) > large
        check_fits(stage, 10**3, 3)
        with pytest.raises(ValueError, match="use fewer particles"):
            check_fits(stage, 10**12, 3)


def test_rdf_beyond_half_the_box_is_clipped_and_said(capsys, tmp_path, two_packings):
    s1, _ = two_packings  # 16 discs: half the box is ~2 mean diameters
    out = tmp_path / "r.nc"
    code, stdout, err = _run(capsys, "rdf", s1, out, "--r-max", "3", "--bins", "150")
    assert code == 0
    assert "note: r_max 3 clipped to" in err
    ds = read_dataset(out, "rdf")
    assert ds.attrs["r_max_clipped"] == 1 and ds.attrs["r_max_requested"] == 3.0
    width = 3.0 / 150
    assert ds.sizes["r"] < 150 and ds.attrs["r_max"] == pytest.approx(ds.sizes["r"] * width)
    np.testing.assert_allclose(np.diff(ds["r"].values), width)  # the bins keep their width
    assert f"up to r = {ds.attrs['r_max']:.6g}" in stdout


def _mirrored(packing):
    """The mirror image x -> -x: every shear stress changes sign."""
    x = packing.position.copy()
    x[:, 0] = -x[:, 0]
    return packing.evolve(position=packing.box.wrap(x))


def test_shear_of_a_start_jammed_against_it_is_refused_in_one_line(capsys, tmp_path):
    from jamflow.io import read_packing
    from jamflow.protocols.overdamped.driving import Drive
    from jamflow.protocols.overdamped.starts import jammed_start

    jammed = read_packing(KINDS / "packing.nc")
    shear = Drive("shear", rate=1.0)
    against = jammed if jammed_start(jammed, shear) else _mirrored(jammed)
    unloading = _mirrored(against)
    assert jammed_start(against, shear) and jammed_start(unloading, shear) is None
    # the stored forces resist the shear: sum f_c n_c . E r_c < 0 (what makes it jammed)
    r = against.contact_vectors()
    n = r / np.linalg.norm(r, axis=1)[:, None]
    assert against.force @ np.einsum("ca,ab,cb->c", n, shear.gradient(2), r) < 0
    # a fixed-pressure shear and a decompressed start are not refused
    assert jammed_start(against, Drive("shear_fixed_pressure", rate=1.0, pressure=1.0)) is None
    assert jammed_start(against.evolve(contacts=None, force=None), shear) is None
    start, out = tmp_path / "jammed.nc", tmp_path / "o.nc"
    write_packing(against, start)
    code, _, err = _run(capsys, "shear", start, out, "--strain", "1e-6")
    assert code == 1
    _one_line_error(err, start, "jammed against this shear", "--pressure", "decompress")
    assert not out.exists()


def _started_its_kernels(pid: int) -> bool:
    """Whether process ``pid`` has loaded the kernel compiler (it does so inside jamflow.cli.main)."""
    return "llvmlite" in Path(f"/proc/{pid}/maps").read_text()


@pytest.mark.parametrize("after", [0.0, 3.0])
def test_ctrl_c_is_one_line_exit_130_and_no_output(tmp_path, after):
    # 0 s after the kernel compiler is loaded: while the command starts (imports, compiling);
    # 3 s later: while it compiles or compresses
    import signal
    import subprocess
    import sys
    import time

    start = tmp_path / "s.nc"
    write_packing(random_packing(2000, 3, 0.3, "mono", 3), start)
    out = tmp_path / "o.nc"
    # Ctrl-C of a foreground command: a suite started in the background (`pytest &`, nohup)
    # hands its children SIGINT ignored, which the command rightly keeps, so reset it here
    proc = subprocess.Popen([sys.executable, "-m", "jamflow", "ls", str(start), str(out), "--growth-rate", "1e-6",
                             "--p-target", "1e12", "--quiet"], stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        while proc.poll() is None and not _started_its_kernels(proc.pid):
            time.sleep(0.01)
        time.sleep(after)
        proc.send_signal(signal.SIGINT)
        err = proc.communicate(timeout=120)[1]
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.count("\n") == 1 and "interrupted (Ctrl-C)" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.nc"]


# Runs `jamflow ls` with numba's object-cache hook (a Python function LLVM calls through
# ctypes while it loads or compiles a kernel) sending SIGINT to its own process: Python then
# raises the KeyboardInterrupt inside the callback, where ctypes clears it.
_SWALLOWING_CHILD = """
import signal, sys
from pathlib import Path
import numba.core.codegen as codegen
from jamflow.cli import main

hook = codegen.JITCodeLibrary._object_getbuffer_hook.__func__

def interrupting_hook(cls, ll_module):
    marker = Path(sys.argv[1])
    if not marker.exists():
        marker.touch()
        signal.raise_signal(signal.SIGINT)
    return hook(cls, ll_module)

codegen.JITCodeLibrary._object_getbuffer_hook = classmethod(interrupting_hook)
sys.exit(main(sys.argv[2:]))
"""


def test_ctrl_c_inside_a_compiled_extensions_callback_still_ends_the_command(tmp_path):
    import signal
    import subprocess
    import sys

    start = tmp_path / "s.nc"
    write_packing(random_packing(2000, 3, 0.3, "mono", 3), start)
    marker = tmp_path / "hook-fired"
    proc = subprocess.Popen([sys.executable, "-c", _SWALLOWING_CHILD, str(marker), "ls", str(start),
                             str(tmp_path / "o.nc"), "--growth-rate", "1e-6", "--p-target", "1e12", "--quiet"],
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        err = proc.communicate(timeout=120)[1]
    finally:
        proc.kill()
    assert marker.exists(), "the kernel loader never called the object-cache hook: the case was not exercised"
    assert proc.returncode == 130, err
    assert err.count("\n") == 1 and "interrupted (Ctrl-C)" in err and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hook-fired", "s.nc"]


def test_a_closed_stdout_ends_quietly(tmp_path):
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "jamflow", "check", str(KINDS / "packing.nc")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader has gone, as `jamflow check x.nc | head -0`
    err = proc.communicate(timeout=600)[1]
    assert proc.returncode == 141 and err == b""


def test_a_job_log_holds_the_summary_without_bar_redraws_or_the_solver_banner(tmp_path):
    # stdout and stderr to one file, as a workflow job's log: no carriage-return redraws of a
    # progress bar, no HiGHS licence banner, and the printed summary is there
    import subprocess
    import sys

    log = tmp_path / "calippso.log"
    with log.open("w") as fh:
        code = subprocess.run([sys.executable, "-m", "jamflow", "calippso", str(KINDS / "packing.nc"),
                               str(tmp_path / "out.nc")], stdout=fh, stderr=subprocess.STDOUT).returncode
    text = log.read_text()
    assert code == 0, text
    # the licence banner opens with "Running HiGHS" (the summary may name HiGHS as a solver)
    assert "\r" not in text and "Running HiGHS" not in text and "Copyright (c)" not in text and "phi_J" in text
