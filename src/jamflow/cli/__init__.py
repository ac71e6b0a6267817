"""The ``jamflow`` command line: one subcommand per stage or analysis.

Each topic module in this package exposes ``register(subparsers)``, adding its
subcommands; a subcommand's handler takes the parsed arguments and returns an exit
code. Errors from bad input reach the user as one line on stderr and exit code 1.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import typing
from collections.abc import Sequence

from ..io import check_output_paths
from ..presets import preset_options
from ..provenance import jamflow_version
from .common import path_arguments

#: Topic modules of this package that contribute subcommands.
COMMAND_MODULES: tuple[str, ...] = ("packings", "analysis", "soft", "flow", "certify", "tradeoff", "ls", "calippso",
                                     "summary", "minimize", "chains", "shapes")


class _Parser(argparse.ArgumentParser):
    """Reports usage errors as one line (``prog: error: message``) with exit code 2.

    Negative numbers in scientific notation (``--p-target -1e3``) are read as values,
    not as options, so that the command's own check names the bad value.
    """

    def __init__(self, *args: typing.Any, **kwargs: typing.Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every registered subcommand.

    The subcommand parsers are kept in ``parser.subcommands`` (name -> parser).
    """
    parser = _Parser(
        prog="jamflow",
        description="Jammed packings of frictionless hard spheres: generate, drive, certify, analyse.",
    )
    parser.add_argument("--version", action="version", version=f"jamflow {jamflow_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    parser.subcommands = dict(sub.choices)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jamflow`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        preset = getattr(args, "preset", "default")
        if preset != "default":
            # a preset changes the defaults; options given explicitly still win
            parser.subcommands[args.command].set_defaults(**preset_options(args.command, preset))
            args = parser.parse_args(argv)
        reads, writes, packings = args.path_roles
        check_output_paths(path_arguments(args, reads), path_arguments(args, writes),
                           getattr(args, "in_place", False), path_arguments(args, packings))
        return int(args.handler(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError, OSError) as exc:
        print(f"jamflow {args.command}: error: {exc}", file=sys.stderr)
        return 1
