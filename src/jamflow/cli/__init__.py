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

from ..io import check_output_paths, file_body_kind
from ..presets import preset_options
from ..provenance import jamflow_version
from ..stages import STAGES, refusal
from .common import path_arguments

#: Topic modules of this package that contribute subcommands.
COMMAND_MODULES: tuple[str, ...] = ("packings", "analysis", "soft", "flow", "certify", "tradeoff", "ls", "calippso",
                                     "summary", "minimize", "chains", "shapes")

#: Subcommand -> the topic module that registers it. A command line naming one of
#: these imports that module only: the others pull in every stage of the package
#: (0.4-0.6 s per command; a workflow runs the CLI once per job). A test checks the
#: table against the registrations.
COMMAND_MODULE: dict[str, str] = {
    **dict.fromkeys(("init", "import-dat", "export-xyz", "check"), "packings"),
    **dict.fromkeys(("gaps", "forces", "overlap", "overlap-series", "jamming-table", "rdf", "flow-summary",
                     "flow-curve", "plot"), "analysis"),
    **dict.fromkeys(("soft-jam", "aqs", "sd-shear", "moduli"), "soft"),
    **dict.fromkeys(("shear", "compress", "decompress", "drive"), "flow"),
    "certify": "certify", "tradeoff": "tradeoff", "ls": "ls", "calippso": "calippso", "summary": "summary",
    "pool": "summary", "reproduce": "summary", "minimize": "minimize",
    **dict.fromkeys(("init-chains", "link", "chains-moduli"), "chains"),
    **dict.fromkeys(("init-shapes", "contact-angles", "shape-survey", "modes"), "shapes"),
}


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


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser: every registered subcommand, or only those of ``command``'s module.

    The subcommand parsers are kept in ``parser.subcommands`` (name -> parser).

    Parameters
    ----------
    command : str, optional
        A subcommand of :data:`COMMAND_MODULE`: only its topic module is imported and
        registered. None, or an unknown name (whose error then lists every command):
        all of them.
    """
    parser = _Parser(
        prog="jamflow",
        description="Jammed packings of frictionless particles: hard and soft spheres, linked spheres, 2D shapes. "
                    "Generate, drive, certify, analyse.",
    )
    parser.add_argument("--version", action="version", version=f"jamflow {jamflow_version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in (COMMAND_MODULE[command],) if command in COMMAND_MODULE else COMMAND_MODULES:
        importlib.import_module(f"{__name__}.{name}").register(sub)
    parser.subcommands = dict(sub.choices)
    return parser


def check_bodies(command: str, inputs: Sequence[str]) -> None:
    """Refuse, before any work, an input packing whose bodies ``command`` cannot handle (:mod:`jamflow.stages`).

    Raises
    ------
    ValueError
        One line: the file, what the command takes and what to run instead.
    """
    if not STAGES[command].reads_packings:
        return
    for path in inputs:
        kind = file_body_kind(path)
        why = None if kind is None else refusal(command, kind)
        if why:
            raise ValueError(f"{path}: {why}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jamflow`` console script."""
    words = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(words[0] if words else None)
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
        check_bodies(args.command, path_arguments(args, reads))
        return int(args.handler(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError, OSError) as exc:
        print(f"jamflow {args.command}: error: {exc}", file=sys.stderr)
        return 1
