"""Every option of every command is checked as it is parsed (jamflow.cli.types).

The parser walk fails on any numeric option without one of the checked types (plain
``float`` or ``int`` take ``nan``, ``inf`` and negative counts), and on any single output
path without a required suffix; the type tests pin what each type accepts.
"""

from __future__ import annotations

import argparse

import pytest

from jamflow.cli import build_parser
from jamflow.cli.types import (
    count,
    finite,
    integer,
    is_argument_type,
    non_negative,
    non_negative_int,
    packing_fraction,
    path_with_suffix,
    positive,
    probability,
    seed,
)


def _options():
    for command, parser in build_parser().subcommands.items():
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._StoreConstAction)):
                continue  # flags (store_true/false are store-const actions) take no value
            yield command, action


def _looks_numeric(action: argparse.Action) -> bool:
    default = action.default if not isinstance(action.default, list) else (action.default or [None])[0]
    if isinstance(default, bool):
        return False
    return action.type in (int, float) or isinstance(default, (int, float)) or (
        action.choices is not None and all(isinstance(c, (int, float)) for c in action.choices))


def test_every_numeric_option_has_a_checked_type():
    unchecked = [f"{c} {'/'.join(a.option_strings) or a.dest}" for c, a in _options()
                 if _looks_numeric(a) and not is_argument_type(a.type)]
    assert not unchecked, f"numeric options without a jamflow.cli.types type: {unchecked}"
    plain = [f"{c} {a.dest}" for c, a in _options() if a.type in (int, float)]
    assert not plain, f"options with plain int/float types: {plain}"


def test_every_typed_option_uses_the_shared_types():
    # an option with a type has one of jamflow.cli.types, never a local converter
    foreign = [f"{c} {a.dest}: {a.type!r}" for c, a in _options() if a.type is not None and not is_argument_type(a.type)]
    assert not foreign, foreign


def test_every_single_output_path_requires_a_suffix():
    missing = []
    for command, parser in build_parser().subcommands.items():
        _, writes, _ = parser.get_default("path_roles")
        kinds = parser.get_default("output_kinds")
        for action in parser._actions:
            if action.dest in writes and not getattr(action.type, "suffixes", None):
                missing.append(f"{command} {action.dest}")
        # every output declares what it holds: a packing, or kinds (an empty tuple: a text or image file)
        _, writes, packings = parser.get_default("path_roles")
        assert set(writes) == set(packings) | set(kinds), command
    assert not missing, f"outputs without a required suffix: {missing}"


@pytest.mark.parametrize("kind, good, bad", [
    (finite, ["0", "-1e300", "2.5"], ["nan", "inf", "-inf", "x", ""]),
    (positive, ["1e-300", "3"], ["0", "-1", "nan", "inf", "1e400"]),
    (non_negative, ["0", "1e12"], ["-1e-300", "nan", "inf"]),
    (probability, ["0", "1", "0.5"], ["-0.1", "1.0000001", "nan"]),
    (packing_fraction, ["0.64", "1e-9"], ["0", "1", "nan", "-0.5"]),
    (count, ["1", "1e3", "12"], ["0", "-1", "1.5", "nan", "inf", "x"]),
    (non_negative_int, ["0", "7"], ["-1", "0.5"]),
    (integer(2, 3), ["2", "3"], ["1", "4"]),
    (seed, ["0", str(2**64 - 1)], ["-1", str(2**64), "1.5", "nan"]),
])
def test_argument_types_accept_and_refuse(kind, good, bad):
    for text in good:
        kind(text)
    for text in bad:
        with pytest.raises(argparse.ArgumentTypeError, match="must be"):
            kind(text)


def test_a_count_written_in_exponent_notation_is_exact():
    assert count("1e3") == 1000 and isinstance(count("1e3"), int)
    assert seed(str(2**64 - 1)) == 2**64 - 1


def test_output_paths_need_their_suffix():
    nc = path_with_suffix(".nc")
    assert nc("dir/a.nc") == "dir/a.nc" and nc("A.NC") == "A.NC"
    for text in ("a.xyz", "a", "a.nc.tmp", "", "."):
        with pytest.raises(argparse.ArgumentTypeError, match=r"\.nc"):
            nc(text)
