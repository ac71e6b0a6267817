"""Argument helpers shared by every subcommand module."""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .types import UsageError, require_suffix

__all__ = ["add_command", "add_quiet", "add_preset", "stage_parameters", "path_arguments", "split_paths",
           "format_rows", "print_summary", "packing_rows", "progress_bar"]


def add_command(sub: Any, name: str, handler: Any, help: str, description: str | None = None,
                reads: tuple[str, ...] = (), writes: tuple[str, ...] = (),
                packings: tuple[str, ...] = (),
                makes: dict[str, tuple[str, ...]] | None = None) -> argparse.ArgumentParser:
    """Add a subcommand whose handler is ``handler(args) -> int``.

    ``reads`` and ``writes`` name the arguments (``dest``) holding input and output
    paths; ``"paths[:-1]"`` and ``"paths[-1]"`` split an ``IN ... OUT`` list; ``packings``
    are the outputs (among ``writes``) that are packings, and ``makes`` gives the others'
    dataset kinds (:data:`jamflow.io.DATASET_KINDS`; an empty tuple for a text or image
    file). Before the handler runs, an output that is also an input is refused unless
    ``--in-place`` (added here to commands that both read and write) is given, and so is
    an existing file of another kind where an output goes
    (:func:`jamflow.io.check_output_paths`).
    """
    parser = sub.add_parser(name, help=help, description=description or help)
    parser.set_defaults(handler=handler, path_roles=(reads, writes, packings), output_kinds=dict(makes or {}))
    if reads and writes:
        parser.add_argument("--in-place", action="store_true",
                            help="allow an output to be one of the inputs (the input file is replaced)")
    return parser


def path_arguments(args: argparse.Namespace, roles: tuple[str, ...]) -> list[str]:
    """The paths held by the arguments named in ``roles`` (see :func:`add_command`)."""
    out: list[str] = []
    for role in roles:
        if role == "paths[:-1]":
            value = args.paths[:-1]
        elif role == "paths[-1]":
            value = args.paths[-1:]
        else:
            value = getattr(args, role)
        if value is None:
            continue
        out.extend([value] if isinstance(value, str) else value)
    return out


def split_paths(paths: Sequence[str], what: str, suffixes: tuple[str, ...] = (".nc",),
                distinct: bool = True) -> tuple[list[str], str]:
    """``IN ... OUT``: the inputs and the output, which must end in one of ``suffixes``.

    Raises
    ------
    UsageError
        No input, an output with another suffix, or (``distinct``: the inputs are pooled)
        one file given twice, under any name (a pooled analysis would count it twice).
    """
    if len(paths) < 2:
        raise UsageError(f"give at least one {what} and then the output path")
    inputs, out = list(paths[:-1]), paths[-1]
    try:
        require_suffix(out, suffixes)
    except ValueError as exc:
        raise UsageError(f"output {exc}") from None
    seen: dict[Any, str] = {}
    for path in inputs if distinct else ():
        key = _file_key(path)
        if key in seen:
            raise UsageError(f"{seen[key]} and {path} are the same file: an input given twice would be counted twice")
        seen[key] = path
    return inputs, out


def _file_key(path: str) -> Any:
    """What names one file: device and inode when it exists (symlinks, hard links), else its resolved path."""
    try:
        st = os.stat(path)
    except OSError:
        return Path(path).resolve()
    return (st.st_dev, st.st_ino)


def add_quiet(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars (they show only on a terminal anyway) and no printed summary."""
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bars and no printed summary (the output files hold every number)")


def progress_bar(quiet: bool, iterable: Iterable | None = None, **kwargs: Any) -> Any:
    """A tqdm bar on a terminal; none under ``--quiet`` or when stderr is a file or pipe (a job
    log: redraws would fill it with thousands of characters; the printed summary says the result).

    ``kwargs`` go to :class:`tqdm.tqdm` (``desc``, ``unit``, ``total``, ...).
    """
    import sys

    from tqdm import tqdm

    return tqdm(iterable, disable=quiet or not sys.stderr.isatty(), **kwargs)


def add_preset(parser: argparse.ArgumentParser) -> None:
    """``--preset fast|default|publication``; explicit options override the preset."""
    from ..presets import PRESET_NAMES

    parser.add_argument(
        "--preset", choices=PRESET_NAMES, default="default",
        help="accuracy preset (see README); explicit options override it",
    )


def stage_parameters(args: argparse.Namespace, *exclude: str) -> dict[str, Any]:
    """The parsed options of a stage as a JSON-able dict (for dataset provenance)."""
    skip = {"handler", "command", "quiet", "path_roles", "output_kinds", "in_place", *exclude}
    return {k: v for k, v in vars(args).items() if k not in skip}


def format_rows(rows: Iterable[tuple[str, Any]], indent: str = "") -> str:
    """``name  value`` lines with the names left-aligned in one column."""
    rows = [(str(k), str(v)) for k, v in rows]
    if not rows:
        return ""
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{indent}{k:<{width}}  {v}" for k, v in rows)


def print_summary(args: argparse.Namespace, what: str, rows: Iterable[tuple[str, Any]] = ()) -> None:
    """Print what a command computed, on stdout, unless ``--quiet``.

    One header line ``<command>: <what>`` (``what`` is usually the output path), then
    one indented ``name  value`` row per number. Snakemake rules send stdout to the
    job's ``log:``, so the numbers are readable without opening the netCDF attributes.
    """
    if getattr(args, "quiet", False):
        return
    print(f"{args.command}: {what}")
    text = format_rows(rows, indent="  ")
    if text:
        print(text, flush=True)


def packing_rows(packing: Any) -> list[tuple[str, Any]]:
    """Summary rows of a :class:`~jamflow.state.packing.Packing`: N, d, phi, pressure, contacts, rattlers."""
    rows: list[tuple[str, Any]] = [("N, d", f"{packing.n}, {packing.d}"),
                                   ("packing fraction", f"{packing.packing_fraction:.10f}")]
    if packing.pressure is not None:
        rows.append(("pressure", f"{packing.pressure:.6g}"))
    if packing.contacts is not None:
        rows.append(("contacts", len(packing.contacts)))
    if packing.rattler is not None:
        rows.append(("rattlers", int(packing.rattler.sum())))
    return rows

