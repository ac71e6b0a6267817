"""Provenance attributes every jamflow dataset carries (version, git sha, time)."""

from __future__ import annotations

import subprocess
from datetime import datetime, timezone
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["jamflow_version", "git_sha", "provenance_attrs"]


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


def provenance_attrs(title: str) -> dict[str, str]:
    """CF global attributes plus jamflow provenance for a new dataset."""
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return {
        "Conventions": "CF-1.10",
        "title": title,
        "source": f"jamflow {jamflow_version()}",
        "jamflow_version": jamflow_version(),
        "git_sha": git_sha(),
        "created": created,
        "history": f"{created} created by jamflow {jamflow_version()} ({git_sha()})",
    }
