"""Provenance attributes every jamflow dataset carries (version, git sha, time, scan point).

A workflow job runs with its scene's scan point in the environment variable
:data:`SCAN_POINT_ENV` (JSON, set by the rule's command line, :mod:`jamflow.scenes.plan`):
every dataset it writes carries it as ``scan_point`` (JSON) and one attribute
``point_<key>`` per dimension, so a file read alone still says where in the scan it sits.
"""

from __future__ import annotations

import json
import os
import subprocess
from datetime import datetime, timezone
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["SCAN_POINT_ENV", "git_sha", "jamflow_version", "provenance_attrs", "scan_point_attrs"]

#: Environment variable holding the scan point (a JSON object) of the workflow job that runs the command.
SCAN_POINT_ENV = "JAMFLOW_SCAN_POINT"


def jamflow_version() -> str:
    """Installed jamflow version, or ``"unknown"`` when run from an uninstalled tree."""
    try:
        return version("jamflow")
    except PackageNotFoundError:
        return "unknown"


@lru_cache(maxsize=1)
def git_sha() -> str:
    """Commit of the jamflow source tree (``-dirty`` if modified), or ``"unknown"``."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", str(here)],
            cwd=here, capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{sha}-dirty" if dirty else sha


def scan_point_attrs() -> dict[str, str | float]:
    """``scan_point`` and ``point_<key>`` attributes from :data:`SCAN_POINT_ENV` (none outside a workflow job)."""
    text = os.environ.get(SCAN_POINT_ENV)
    if not text:
        return {}
    try:
        point = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{SCAN_POINT_ENV} is not JSON ({error}): {text!r}") from None
    if not isinstance(point, dict):
        raise ValueError(f"{SCAN_POINT_ENV} must be a JSON object, got {text!r}")
    attrs: dict[str, str | float] = {"scan_point": json.dumps(point, sort_keys=True)}
    for key, value in point.items():
        attrs[f"point_{key}"] = value if isinstance(value, (int, float)) and not isinstance(value, bool) else str(value)
    return attrs


def provenance_attrs(title: str) -> dict[str, str]:
    """CF global attributes plus jamflow provenance (and a workflow job's scan point) for a new dataset."""
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return {
        **scan_point_attrs(),
        "Conventions": "CF-1.10",
        "title": title,
        "source": f"jamflow {jamflow_version()}",
        "jamflow_version": jamflow_version(),
        "git_sha": git_sha(),
        "created": created,
        "history": f"{created} created by jamflow {jamflow_version()} ({git_sha()})",
    }
