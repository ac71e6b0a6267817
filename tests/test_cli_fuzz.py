"""Every command against bad values, wrong output suffixes and wrong kinds of input.

For every command and every numeric option the values NaN, inf, -1, 0 and 10**12; for
every output path a wrong suffix; for every input a dataset of another kind (one of each
kind is vendored in ``tests/data/kinds/``, made by its ``make.sh``). Each case ends with

- exit code 2 (usage) with one line on stderr naming the option, when the option's type
  (:mod:`jamflow.cli.types`) refuses the value, before any file is read;
- exit code 1 with one line on stderr (refused: the input, a target, the machine); or
- exit code 0 with every output written and readable as the kind the command declares,

never a traceback, with the inputs bitwise unchanged and no partial or temporary file
left, and within a hang guard (:data:`HANG_SECONDS`: not a timing, a run that never
ends). The body-kind axis is ``tests/test_stages.py`` (every command on every body kind,
from the stage table); its argument templates are reused here.

Cases that only parse are fast; cases that run a whole protocol are marked slow.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path

import pytest
from ls_data import ls_dat
from test_stages import DATA as BODIES
from test_stages import HARD, SOFT
from test_stages import TEMPLATES as PACKING_TEMPLATES

from jamflow.cli import build_parser, main
from jamflow.cli.types import is_argument_type
from jamflow.io import DATASET_KINDS, file_kind
from jamflow.stages import BODY_KINDS, STAGES

KINDS = Path(__file__).parent / "data" / "kinds"

#: Longest a case may run before it counts as hanging [s] (a guard against a run that never
#: ends, far above any case's time, not a timing).
HANG_SECONDS = 300

#: The values every numeric option is fed.
BAD_VALUES = ("nan", "inf", "-1", "0", str(10**12))

#: Commands that run a whole protocol (cases that pass the argument types run in the slow suite).
HEAVY = {"ls", "calippso", "certify", "shear", "compress", "drive", "aqs", "sd-shear", "overlap-series",
         "soft-jam", "tradeoff", "minimize", "modes", "moduli"}

#: Minimal arguments of the commands that read no packing. ``{kind}`` is the vendored dataset
#: of that kind, OUT the output stem.
OTHER_TEMPLATES: dict[str, list[str]] = {
    "init": ["OUT.nc", "--d", "2", "--n", "8", "--phi", "0.3", "--seed", "1"],
    "import-dat": ["{dat}", "OUT.nc"],
    "init-chains": ["OUT.nc", "--d", "2", "--clusters", "4", "--cluster", "trimer", "--seed", "1"],
    "init-shapes": ["OUT.nc", "--shape", "ellipse", "--asphericity", "1.1", "--n", "8", "--seed", "1"],
    "jamming-table": ["{overlap-series}", "OUT.nc", "--eos", "{eos}", "--fit-min", "1e1", "--fit-max", "1e3"],
    "flow-summary": ["{flow}", "OUT.nc", "--blocks", "2"],
    "flow-curve": ["{flow-summary}", "OUT.nc"],
    "plot": ["rdf", "{rdf}", "OUT.png"],
    "summary": ["{scene}"],
    "tradeoff": ["soft", "OUT.nc", "--quick"],
    "chains-moduli": ["{chain-moduli}", "OUT.nc"],
    "feasible-region": ["OUT.nc", "--samples", "2000", "--shrinks", "1e-3", "1e-2"],
    "pool": ["{gaps}", "OUT.nc", "--points", "base", "--study", "gaps"],
    "reproduce": ["OUT.md", "--results", "{scene}"],
}

#: Budgets that keep a case short whatever value it is fed (a budget reached is a result).
BUDGETS: dict[str, list[str]] = {
    "shear": ["--max-steps", "20"], "compress": ["--max-steps", "20"], "drive": ["--max-steps", "20"],
    "ls": ["--max-collisions", "100000"], "soft-jam": ["--max-steps", "200000"],
    "calippso": ["--max-iterations", "50"],
}

#: Options that exclude one of the template's: option -> the template option it replaces.
EXCLUSIVE = {"--forces": "--random-forces", "--self-propelled": "--random-forces", "--file": "--cement"}


def _packing_input(command: str) -> str:
    args, hard, _ = PACKING_TEMPLATES[command]
    kind = next(k for k in BODY_KINDS if k in STAGES[command].accepts)
    return str(BODIES / (HARD if hard else SOFT)[kind])


def _template(command: str) -> list[str]:
    if command in PACKING_TEMPLATES:
        args, hard, soft_flag = PACKING_TEMPLATES[command]
        src = _packing_input(command)
        argv = [src if a == "IN" else a for a in args]
        if soft_flag and src.endswith("_soft.nc"):
            argv.append(soft_flag)
        return argv + BUDGETS.get(command, [])
    return list(OTHER_TEMPLATES[command]) + BUDGETS.get(command, [])


def _scene(folder: Path) -> Path:
    """A scene results folder with one packing."""
    sample = folder / "scene" / "spheres" / "base" / "seed1"
    sample.mkdir(parents=True)
    shutil.copy(KINDS / "packing.nc", sample / "calippso.nc")
    return folder / "scene"


def _materialise(argv: list[str], tmp: Path) -> tuple[list[str], list[Path]]:
    """Copy every input into ``tmp`` (the command sees copies) and point OUT there; returns argv and the inputs."""
    inputs: list[Path] = []
    out = []
    for a in argv:
        if a.startswith("{") and a.endswith("}"):
            name = a[1:-1]
            if name == "scene":
                out.append(str(_scene(tmp)))
                continue
            src = ls_dat(3) if name == "dat" else KINDS / f"{name}.nc"
            a = str(src)
        if a.startswith(("/", str(BODIES))) and Path(a).is_file():
            copy = tmp / Path(a).name
            if not copy.exists():
                shutil.copy(a, copy)
                inputs.append(copy)
            a = str(copy)
        out.append(a.replace("OUT", str(tmp / "out")) if "OUT" in a else a)
    return out, inputs


@contextmanager
def _hang_guard(seconds: int):
    def expire(signum, frame):
        raise TimeoutError(f"no end after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _sha(paths: list[Path]) -> list[str]:
    return [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]


def _check(command: str, argv: list[str], tmp: Path, capsys, expect: set[int], named: str | None = None) -> int:
    """Run one case and check the common promises; returns the exit code."""
    argv, inputs = _materialise(argv, tmp)
    before = _sha(inputs)
    with _hang_guard(HANG_SECONDS):
        try:
            code = main([command, *argv])
        except SystemExit as exc:  # argparse's own usage errors
            code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert code in expect, (code, err)
    lines = [line for line in err.splitlines() if ": warning: " not in line and ": note: " not in line
             and " replaced " not in line and line.strip() and "it/s" not in line and "%|" not in line]
    if code:
        assert len(lines) == 1, err
        if named:
            assert named in lines[0], (named, lines[0])
    assert _sha(inputs) == before, "an input was modified"
    assert not [p for p in tmp.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")], "temporary left"
    outputs = [p for p in tmp.iterdir() if p.name.startswith("out")]
    if code == 0:
        for path in outputs:
            if path.suffix == ".nc":
                assert file_kind(path) in DATASET_KINDS, f"{path.name} is no jamflow dataset"
    else:
        assert all(".reached." in p.name for p in outputs), f"outputs after a refusal: {outputs}"
    return code


def _numeric_cases():
    parsers = build_parser().subcommands
    for command in sorted(parsers):
        for action in parsers[command]._actions:
            if not is_argument_type(action.type) or getattr(action.type, "suffixes", None) or not action.option_strings:
                continue
            for value in BAD_VALUES:
                try:
                    action.type(value)
                    accepted = True
                except argparse.ArgumentTypeError:
                    accepted = False
                marks = [pytest.mark.slow] if accepted and command in HEAVY else []
                yield pytest.param(command, action.option_strings[0], action.nargs, value, accepted, marks=marks,
                                   id=f"{command}{action.option_strings[0]}={value}")


def _with_option(template: list[str], option: str, nargs, value: str) -> list[str]:
    argv = list(template)
    for name in (option, EXCLUSIVE.get(option)):
        if name in argv:
            k = argv.index(name)
            end = k + 1
            while end < len(argv) and not argv[end].startswith("--"):
                end += 1
            del argv[k:end]
    return argv + [option] + [value] * (nargs if isinstance(nargs, int) else 1)


@pytest.mark.parametrize("command, option, nargs, value, accepted", list(_numeric_cases()))
def test_a_bad_number_is_refused_or_gives_a_checked_result(command, option, nargs, value, accepted, tmp_path, capsys):
    argv = _with_option(_template(command), option, nargs, value)
    if not accepted:
        _check(command, argv, tmp_path, capsys, {2}, named=option)
    else:
        _check(command, argv, tmp_path, capsys, {0, 1})


def _suffix_cases():
    for command, parser in sorted(build_parser().subcommands.items()):
        _, writes, _ = parser.get_default("path_roles")
        for role in writes:
            marks = [pytest.mark.slow] if command == "tradeoff" else []
            yield pytest.param(command, role, marks=marks, id=f"{command}-{role}")


@pytest.mark.parametrize("command, role", list(_suffix_cases()))
def test_an_output_with_the_wrong_suffix_is_a_usage_error(command, role, tmp_path, capsys):
    argv = _template(command)
    wrong = str(tmp_path / "out.wrong")
    if role == "paths[-1]":
        argv[max(k for k, a in enumerate(argv) if "OUT" in a)] = wrong
    elif any("OUT" in a for a in argv) and role == "out":
        argv[next(k for k, a in enumerate(argv) if "OUT" in a)] = wrong
    else:
        argv += [f"--{role.replace('_', '-')}", wrong]
    _check(command, argv, tmp_path, capsys, {2}, named="out.wrong")


def _kind_cases():
    for command in sorted(build_parser().subcommands):
        if command in ("init", "init-chains", "init-shapes", "tradeoff", "feasible-region", "summary", "reproduce",
                       "pool"):
            continue  # no input dataset; summary and reproduce read a folder, pool takes datasets of any kind
        marks = [pytest.mark.slow] if command in HEAVY else []
        yield pytest.param(command, marks=marks, id=command)


@pytest.mark.parametrize("command", list(_kind_cases()))
def test_an_input_of_another_kind_is_one_line(command, tmp_path, capsys):
    argv = _template(command)
    wrong = "gaps" if STAGES[command].reads_packings or command == "import-dat" else "packing"
    k = next(k for k, a in enumerate(argv) if a.startswith(("{", "/")) and "OUT" not in a)
    argv[k] = f"{{{wrong}}}"
    _check(command, argv, tmp_path, capsys, {1}, named=f"{wrong}.nc")


def test_every_command_has_a_template():
    assert set(build_parser().subcommands) == set(PACKING_TEMPLATES) | set(OTHER_TEMPLATES)
    assert {p.stem for p in KINDS.glob("*.nc")} == set(DATASET_KINDS), "tests/data/kinds/ holds one file per kind"
