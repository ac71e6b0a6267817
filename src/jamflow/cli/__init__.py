"""The ``jamflow`` command line: one subcommand per stage or analysis.

Each topic module in this package exposes ``register(subparsers)``, adding its
subcommands; a subcommand's handler takes the parsed arguments and returns an exit
code. Every failure reaches the user as one line on stderr, without a traceback:

====  =====================================================================
code  meaning
====  =====================================================================
0     done (the outputs are written)
1     refused or failed: bad input file or value, impossible target, disk full
2     usage: an option missing, unknown or out of its range (:mod:`jamflow.cli.types`)
3     stopped on request (``calippso --stop-after``): no output yet, the checkpoint holds the run
130   interrupted by Ctrl-C (SIGINT); no partial output is left
141   stdout closed early (``jamflow check x.nc | head -1``); quiet
====  =====================================================================

Ctrl-C during start-up is one line too: until :func:`main` runs, the handler that
``jamflow/__init__.py`` installs for the command line ends the process; inside it the
imports of the command's modules and the compilation of kernels are covered, and a
Ctrl-C that a compiled extension's callback swallows is raised again
(:mod:`jamflow.cli.ctrl_c`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import typing
import warnings
from collections.abc import Sequence

from ..io import check_output_paths, file_body_kind
from ..presets import preset_options
from ..provenance import jamflow_version
from ..stages import STAGES, refusal
from .common import path_arguments
from .ctrl_c import catching_ctrl_c
from .types import UsageError

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
    **dict.fromkeys(("init-shapes", "contact-angles", "shape-survey", "modes", "constraint-curvature",
                     "feasible-region"), "shapes"),
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


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line (an OSError's own words, without ``[Errno n]``)."""
    if isinstance(exc, OSError) and exc.strerror and exc.filename is None:
        text = exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return "; ".join(part.strip() for part in text.splitlines() if part.strip())


def _run(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> int:
    """Parse, check paths and bodies before any work, run the handler, say what was replaced."""
    args = parser.parse_args(argv)
    preset = getattr(args, "preset", "default")
    if preset != "default":
        # a preset changes the defaults; options given explicitly still win
        parser.subcommands[args.command].set_defaults(**preset_options(args.command, preset))
        args = parser.parse_args(argv)
    reads, writes, packings = args.path_roles
    outputs = path_arguments(args, writes)
    kinds = {path: kinds for role, kinds in args.output_kinds.items() for path in path_arguments(args, (role,))}
    replaced = check_output_paths(path_arguments(args, reads), outputs, getattr(args, "in_place", False),
                                  path_arguments(args, packings), kinds)
    check_bodies(args.command, path_arguments(args, reads))
    with warnings.catch_warnings():
        # a refused fit is printed by the command as its own "jamflow: warning:" line
        warnings.filterwarnings("ignore", category=UserWarning, message="(fit refused|systematic error undefined)")
        code = int(args.handler(args) or 0)
    if code == 0:
        for line in replaced:
            if "checkpoint (" not in line:  # a checkpoint is resumed, not replaced
                print(f"jamflow {args.command}: replaced {line}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``jamflow`` console script (exit codes: module docstring)."""
    words = sys.argv[1:] if argv is None else [str(a) for a in argv]
    name = f"jamflow {words[0]}" if words and words[0] in COMMAND_MODULE else "jamflow"
    _restore_ctrl_c()
    try:
        with catching_ctrl_c():
            return _run(build_parser(words[0] if words else None), argv)
    except UsageError as exc:
        print(f"{name}: error: {_one_line(exc)} (see {name} --help)", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader of stdout has gone (| head): nothing more to say, and no traceback at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (KeyboardInterrupt, Exception) as exc:
        if _interrupted(exc):
            print(f"{name}: interrupted (Ctrl-C); no partial output is left", file=sys.stderr)
            return 130
        if not isinstance(exc, (ValueError, FileNotFoundError, RuntimeError, OSError)):
            raise  # a bug: its traceback is the report
        print(f"{name}: error: {_one_line(exc)}", file=sys.stderr)
        return 1


def _restore_ctrl_c() -> None:
    """Ctrl-C raises KeyboardInterrupt again once :func:`main` runs (the start-up handler exits at once)."""
    from .. import _interrupted_while_starting

    if signal.getsignal(signal.SIGINT) is _interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _interrupted(exc: BaseException | None) -> bool:
    """Whether Ctrl-C is anywhere in ``exc``'s chain (a compiled kernel wraps it in a SystemError)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False
