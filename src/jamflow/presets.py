"""Named accuracy presets per stage command: ``fast``, ``default``, ``publication``.

``default`` is each command's own defaults. The other two override a command's
accuracy knobs with values chosen from the speed-versus-accuracy measurements in
``benchmarks/`` (see the README's presets table). Explicit command-line options
always win over a preset.
"""

from __future__ import annotations

from typing import Any

__all__ = ["PRESET_NAMES", "PRESETS", "preset_options"]

PRESET_NAMES: tuple[str, ...] = ("fast", "default", "publication")

#: command -> preset -> {argparse dest: value}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {}


def preset_options(command: str, preset: str) -> dict[str, Any]:
    """Option values a preset sets for a command (empty for ``default``)."""
    if preset not in PRESET_NAMES:
        raise ValueError(f"unknown preset {preset!r}; choose one of {', '.join(PRESET_NAMES)}")
    return dict(PRESETS.get(command, {}).get(preset, {}))
