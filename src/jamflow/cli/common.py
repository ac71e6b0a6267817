"""Argument helpers shared by every subcommand module."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_command", "add_quiet", "add_preset", "stage_parameters"]


def add_command(sub: Any, name: str, handler: Any, help: str, description: str | None = None) -> argparse.ArgumentParser:
    """Add a subcommand whose handler is ``handler(args) -> int``."""
    parser = sub.add_parser(name, help=help, description=description or help)
    parser.set_defaults(handler=handler)
    return parser


def add_quiet(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars."""
    parser.add_argument("--quiet", action="store_true", help="no progress bars or progress messages")


def add_preset(parser: argparse.ArgumentParser) -> None:
    """``--preset fast|default|publication``; explicit options override the preset."""
    from ..presets import PRESET_NAMES

    parser.add_argument(
        "--preset", choices=PRESET_NAMES, default="default",
        help="accuracy preset (see README); explicit options override it",
    )


def stage_parameters(args: argparse.Namespace, *exclude: str) -> dict[str, Any]:
    """The parsed options of a stage as a JSON-able dict (for dataset provenance)."""
    skip = {"handler", "command", "quiet", *exclude}
    return {k: v for k, v in vars(args).items() if k not in skip}
