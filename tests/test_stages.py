"""Every command against every body kind, from the stage table (jamflow.stages).

A command either handles a packing's bodies (the result keeps them) or refuses the
packing in one line, with exit code 1 and no output, before any work. The cases are
generated from the table, so the table and this test cannot disagree; a command without
an argument template below fails :func:`test_every_command_has_a_table_entry_and_a_template`.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from jamflow.cli import build_parser, main
from jamflow.io import dataset_kind, read_dataset, read_packing
from jamflow.stages import BODY_KINDS, STAGES, refusal

DATA = Path(__file__).parent / "data" / "bodies"

#: One small packing per body kind (tests/data/bodies/make.sh): soft ones overlap, hard ones do not.
SOFT = {"spheres": "spheres_soft.nc", "linked": "linked_soft.nc", "shapes": "shapes_soft.nc", "walls": "walls_hard.nc"}
HARD = {**SOFT, "spheres": "spheres_hard.nc"}

#: Minimal arguments of every packing command: IN is the input packing, OUT the output stem;
#: ``hard`` marks commands of hard (non-overlapping) spheres; ``soft_flag`` is the option that
#: lets them read an overlapping linked or shape packing.
TEMPLATES: dict[str, tuple[list[str], bool, str | None]] = {
    "export-xyz": (["IN", "OUT.gsd"], True, "--soft"),
    "link": (["IN", "OUT.nc", "--cement", "2", "--seed", "1"], False, None),
    "ls": (["IN", "OUT.nc", "--growth-rate", "1e-2", "--p-target", "1e2", "--seed", "1"], True, None),
    "calippso": (["IN", "OUT.nc"], True, None),
    "soft-jam": (["IN", "OUT.nc", "--pressure", "1e-3"], False, None),
    "minimize": (["IN", "OUT.nc"], False, None),
    "certify": (["IN", "OUT.nc"], True, "--soft"),
    "aqs": (["IN", "OUT.nc", "--strain", "1e-3", "--step", "1e-4"], False, None),
    "sd-shear": (["IN", "OUT.nc", "--strain", "1e-4"], False, None),
    "shear": (["IN", "OUT.nc", "--strain", "1e-4"], True, None),
    "compress": (["IN", "OUT.nc", "--final", "OUT_final.nc"], True, None),
    "decompress": (["IN", "OUT.nc", "--phi", "0.5"], True, None),
    "drive": (["IN", "OUT.nc", "--time", "0.01", "--random-forces", "0.1", "--seed", "1"], True, None),
    "check": (["IN"], True, "--soft"),
    "moduli": (["IN", "OUT.nc"], False, None),
    "modes": (["IN", "OUT.nc"], False, None),
    "gaps": (["IN", "OUT.nc"], True, None),
    "forces": (["IN", "OUT.nc"], True, None),
    "overlap": (["IN", "IN", "OUT.nc"], True, None),
    "overlap-series": (["IN", "OUT.nc", "--p-target", "1e2"], True, None),
    "rdf": (["IN", "OUT.nc", "--r-max", "1.5"], True, None),
    "shape-survey": (["IN", "OUT.nc"], False, None),
    "contact-angles": (["IN", "OUT.nc"], False, None),
    "constraint-curvature": (["IN", "OUT.nc"], False, None),
}

#: What a command's output holds when it is not the input's kind of packing.
MAKES = {"link": "linked", "check": None, "export-xyz": None}

_PACKING_COMMANDS = sorted(c for c, s in STAGES.items() if s.reads_packings)
_REFUSED = [(c, k) for c in _PACKING_COMMANDS for k in BODY_KINDS if refusal(c, k)]
_ACCEPTED = [(c, k) for c in _PACKING_COMMANDS for k in BODY_KINDS if not refusal(c, k)]
#: accepted cases that run a whole protocol: the slow suite
_HEAVY = {"ls", "calippso", "certify", "shear", "compress", "drive", "aqs", "sd-shear", "overlap-series",
          "soft-jam"}


def _argv(command: str, kind: str, tmp_path: Path) -> tuple[list[str], Path]:
    args, hard, soft_flag = TEMPLATES[command]
    name = (HARD if hard else SOFT)[kind]
    src = tmp_path / name
    shutil.copy(DATA / name, src)
    out = tmp_path / "out"
    argv = [command, *(str(src) if a == "IN" else a.replace("OUT", str(out)) for a in args)]
    if soft_flag and name.endswith("_soft.nc"):
        argv.append(soft_flag)
    return argv, src


def test_every_command_has_a_table_entry_and_a_template() -> None:
    commands = set(build_parser().subcommands)
    assert commands == set(STAGES), f"commands without a stage entry: {commands - set(STAGES)}; " \
                                    f"entries without a command: {set(STAGES) - commands}"
    assert set(_PACKING_COMMANDS) == set(TEMPLATES)
    assert all(STAGES[c].accepts <= set(BODY_KINDS) for c in STAGES)


@pytest.mark.parametrize("command, kind", _REFUSED, ids=[f"{c}-{k}" for c, k in _REFUSED])
def test_a_refused_body_kind_is_one_line_and_no_output(command, kind, tmp_path, capsys) -> None:
    argv, src = _argv(command, kind, tmp_path)
    before = src.read_bytes()
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{command} does not take" in err
    assert STAGES[command].instead.get(kind, "") in err
    assert not any(p.name.startswith("out") for p in tmp_path.iterdir())
    assert src.read_bytes() == before


#: The one body kind each packing command runs on in the smoke set (``pytest -m smoke``):
#: the first of :data:`BODY_KINDS` it takes. These cases run in the fast suite too.
SMOKE_KIND = {c: next(k for k in BODY_KINDS if not refusal(c, k)) for c in _PACKING_COMMANDS}


def _case(command: str, kind: str):
    if SMOKE_KIND[command] == kind:
        marks = [pytest.mark.smoke]
    else:
        marks = [pytest.mark.slow] if command in _HEAVY else []
    return pytest.param(command, kind, marks=marks, id=f"{command}-{kind}")


@pytest.mark.parametrize("command, kind", [_case(c, k) for c, k in _ACCEPTED])
def test_an_accepted_body_kind_keeps_its_bodies(command, kind, tmp_path) -> None:
    argv, src = _argv(command, kind, tmp_path)
    assert main(argv) == 0
    start = read_packing(src, None)
    outputs = sorted(p for p in tmp_path.iterdir() if p.name.startswith("out") and p.suffix == ".nc")
    if command in ("check",):
        return
    if command == "export-xyz":
        assert (tmp_path / "out.gsd").stat().st_size > 0
        return
    assert outputs, f"{command} wrote nothing"
    ds = read_dataset(outputs[0])
    if dataset_kind(ds) != "packing":
        return
    out = read_packing(outputs[0], None)
    assert out.body_kind == MAKES.get(command, kind)
    if start.links is not None and len(start.links):
        kept = set(zip(out.links.i.tolist(), out.links.j.tolist()))
        given = set(zip(start.links.i.tolist(), start.links.j.tolist()))
        # every stage keeps the links; `link` adds more
        assert given <= kept and (command == "link" or given == kept)
    if start.shapes is not None:
        np.testing.assert_array_equal(out.shape_index, start.shape_index)
        np.testing.assert_array_equal(out.shapes.kind, start.shapes.kind)
