"""Accuracy presets: every preset names real options, explicit options win."""

from __future__ import annotations

import pytest

from jamflow.cli import build_parser, main
from jamflow.presets import PRESET_NAMES, PRESETS, preset_options


@pytest.mark.parametrize("command", sorted(PRESETS))
def test_every_preset_sets_existing_options_of_its_command(command):
    sub = build_parser().subcommands[command]
    dests = {a.dest for a in sub._actions}
    assert "preset" in dests
    for preset in PRESET_NAMES:
        assert set(preset_options(command, preset)) <= dests


def test_preset_changes_defaults_and_explicit_options_win(monkeypatch):
    seen = {}
    parser = build_parser()
    sub = parser.subcommands["certify"]
    monkeypatch.setattr(sub, "_defaults", dict(sub._defaults, handler=lambda args: seen.update(vars(args)) or 0))
    monkeypatch.setattr("jamflow.cli.build_parser", lambda command=None: parser)
    assert main(["certify", "in.nc", "out.nc", "--preset", "publication"]) == 0
    assert seen["loads"] == PRESETS["certify"]["publication"]["loads"]
    assert main(["certify", "in.nc", "out.nc", "--preset", "publication", "--loads", "3"]) == 0
    assert seen["loads"] == 3


def test_unknown_preset_is_refused():
    with pytest.raises(ValueError):
        preset_options("certify", "sloppy")


@pytest.mark.parametrize("command", ["soft-jam", "aqs", "compress", "shear", "drive", "certify", "calippso", "ls"])
def test_every_stage_command_takes_a_preset(command):
    assert command in PRESETS
    assert "preset" in {a.dest for a in build_parser().subcommands[command]._actions}


def test_ls_presets_leave_the_dynamics_alone():
    assert all(preset_options("ls", name) == {} for name in PRESET_NAMES)


def test_calippso_presets_all_run_the_papers_tolerances():
    # issue 19: the former fast preset (tol_s 1e-6, tol_gamma 1e-9) was not faster on the
    # whole command, so no preset may change CALiPPSO's convergence tolerances
    assert all(preset_options("calippso", name) == {} for name in PRESET_NAMES)
