"""The smoke set (``pytest -m smoke``, well under a minute): every ``jamflow`` command once.

The commands that read a packing run in ``tests/test_stages.py`` on the first body kind
they take (:data:`test_stages.SMOKE_KIND`: the result keeps its bodies); the others run
here on the vendored datasets of ``tests/data/kinds/`` with the argument templates of
``tests/test_cli_fuzz.py``: exit code 0, every output a jamflow dataset (or the file
the command writes), and the numbers printed on stdout. A test checks that the marked
cases together cover every command of the stage table.
"""

from __future__ import annotations

import pytest
import test_stages
from test_cli_fuzz import BUDGETS, OTHER_TEMPLATES, _hang_guard, _materialise

from jamflow.cli import main
from jamflow.io import DATASET_KINDS, file_kind
from jamflow.stages import STAGES

#: Longest a smoke case may run before it counts as hanging [s] (a guard, not a timing).
HANG_SECONDS = 300

#: The commands that read no packing, each run once here.
OTHER = sorted(c for c in STAGES if not STAGES[c].reads_packings)
#: Their arguments: the fuzz test's, with the quickest tradeoff sweep (CALiPPSO's, a few seconds)
ARGS = {**OTHER_TEMPLATES, "tradeoff": ["calippso", "OUT.nc", "--quick"]}


@pytest.mark.smoke
@pytest.mark.parametrize("command", OTHER)
def test_a_command_without_a_packing_input_runs_and_prints_its_numbers(command, tmp_path, capsys):
    argv, _ = _materialise(ARGS[command] + BUDGETS.get(command, []), tmp_path)
    with _hang_guard(HANG_SECONDS):
        code = main([command, *argv])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert out.strip(), f"{command} printed nothing on stdout"
    if command == "summary":
        return  # a table on stdout, no file
    written = [p for p in tmp_path.iterdir() if p.name.startswith("out")]
    assert written, f"{command} wrote nothing"
    for path in written:
        assert path.stat().st_size > 0
        if path.suffix == ".nc":
            assert file_kind(path) in DATASET_KINDS, f"{path.name} is no jamflow dataset"


def _smoke_commands(test, position: int) -> set[str]:
    """Commands of the cases of a parametrized ``test`` that carry the smoke mark."""
    found = set()
    for mark in getattr(test, "pytestmark", []):
        if mark.name != "parametrize":
            continue
        for case in mark.args[1]:
            if any(m.name == "smoke" for m in getattr(case, "marks", ())):
                found.add(case.values[position])
    return found


@pytest.mark.smoke
def test_the_smoke_set_runs_every_command_of_the_stage_table():
    packing = _smoke_commands(test_stages.test_an_accepted_body_kind_keeps_its_bodies, 0)
    assert packing == {c for c in STAGES if STAGES[c].reads_packings}
    other = set(OTHER) if any(m.name == "smoke" for m in
                              test_a_command_without_a_packing_input_runs_and_prints_its_numbers.pytestmark) else set()
    missing = set(STAGES) - packing - other
    assert not missing, f"commands no smoke case runs: {sorted(missing)}"
