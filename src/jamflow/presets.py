"""Named accuracy presets per stage command: ``fast``, ``default``, ``publication``.

``default`` is each command's own defaults. The other two override a command's
accuracy knobs with values chosen from the speed-versus-accuracy measurements in
``benchmarks/`` (the guide's ``docs/presets.md``; the measurements in
``docs/notes/presets.md``). Explicit command-line options always win over a preset.
"""

from __future__ import annotations

from typing import Any

__all__ = ["PRESET_NAMES", "PRESETS", "preset_options"]

PRESET_NAMES: tuple[str, ...] = ("fast", "default", "publication")

_FLOW = {
    # step_drift bounds the relative constraint error of one step, correct_every the
    # accumulated drift (measured: docs/notes/presets.md#flow-commands)
    "fast": {"step_drift": 1e-6, "correct_every": 100},
    "publication": {"step_drift": 1e-10},
}

#: command -> preset -> {argparse dest: value}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # soft-jam: below 1e-10 contacts are not resolved reliably; the link re-affixing
    # precision of linked packings is no speed knob (measured: docs/notes/presets.md#soft-jam)
    "soft-jam": {"fast": {"force_tol": 1e-10}, "publication": {"force_tol": 10**-13.5}},
    # aqs: the stress error is set by the strain step, force_tol adds little to it
    # (measured: docs/notes/presets.md#aqs)
    "aqs": {"fast": {"force_tol": 1e-8}, "publication": {"force_tol": 1e-14}},
    "shear": _FLOW,
    "compress": _FLOW,
    "drive": _FLOW,
    # certify: one load with both signs missed no planted motion; more loads only cost
    # time (measured: docs/notes/presets.md#certify)
    "certify": {"fast": {"loads": 1}, "publication": {"loads": 4}},
    # calippso: no speed knob worth a preset; every preset runs the paper's tolerances
    # (measured: docs/notes/presets.md#calippso)
    "calippso": {},
    # ls: no numerical accuracy knob (collision times are exact to round-off); the growth
    # rate and target pressure are protocol parameters that change phi_J
    # (benchmarks/tradeoff.py, stage ls), so every preset runs the same dynamics.
    "ls": {},
}


def preset_options(command: str, preset: str) -> dict[str, Any]:
    """Option values a preset sets for a command (empty for ``default``)."""
    if preset not in PRESET_NAMES:
        raise ValueError(f"unknown preset {preset!r}; choose one of {', '.join(PRESET_NAMES)}")
    return dict(PRESETS.get(command, {}).get(preset, {}))
