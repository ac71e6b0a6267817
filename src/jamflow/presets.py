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

_FLOW = {
    # step_drift bounds the relative constraint error one step may create; the stress
    # error against a 1e-11 reference scales like it (benchmarks/overdamped_speed.py,
    # N = 64, phi = 0.80: 1e-6 -> 4.7e-3 at 0.004x the reference time, 1e-8 -> 6.3e-4,
    # 1e-10 -> 4.3e-5 at 0.32x); correct_every caps the accumulated drift. With the
    # commands' drift_tol = 1e-7 the schedule changes neither error nor time measurably
    # except at step_drift 1e-10, where correcting every 10 steps cost 27 % more for the
    # same stress error 2.2e-5 (benchmarks/tradeoff.py, N = 64): publication keeps the
    # default schedule.
    "fast": {"step_drift": 1e-6, "correct_every": 100},
    "publication": {"step_drift": 1e-10},
}

#: command -> preset -> {argparse dest: value}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    # soft-jam: the final enthalpy minimisation is 22 % (P0 1e-7) to 49 % (P0 1e-4) of the
    # FIRE steps at 1e-13, 10 % to 48 % at 1e-10 (README); below 1e-10 contacts are not
    # resolved reliably
    # linked packings: the link re-affixing precision is no speed knob (docs/presets.md,
    # jamflow tradeoff chains): 1e-6 instead of 1e-13 saved 6-17 % CPU time on 2D trimers
    # (N = 60, fixed box and shear-stabilised) and cost phi_J to 5e-7
    "soft-jam": {"fast": {"force_tol": 1e-10}, "publication": {"force_tol": 10**-13.5}},
    # aqs: the stress error is set by the strain step (plastic events resolved at other
    # strains); at a step that resolves them, force_tol 1e-8 gives a largest stress error
    # 1e-3 at 0.8x the time of 1e-10 (benchmarks/tradeoff.py, N = 64)
    "aqs": {"fast": {"force_tol": 1e-8}, "publication": {"force_tol": 1e-14}},
    "shear": _FLOW,
    "compress": _FLOW,
    "drive": _FLOW,
    # certify: one load with both signs missed no planted motion (benchmarks/certify.py);
    # more loads only cost time
    "certify": {"fast": {"loads": 1}, "publication": {"loads": 4}},
    # calippso: no speed knob worth a preset (issue 19). Measured on the whole command, 2 shared
    # cores, publication vs fast side by side: d = 3 LS example (N = 1024) 8.4 s vs 9.8 s with
    # (tol_s, tol_gamma) = (1e-6, 1e-9) (4 LPs instead of 5: the LPs saved are the cheap
    # last ones); 3D N = 256 random start 10.8 s vs 16.3 s (99 vs 100 LPs). Other knobs were
    # not faster there either: --solver ipm-center 31 s (94 LPs), --solver-tol 2e-8 17.6 s
    # (84 LPs), --cutoff 1.5 23 s (94 LPs). Every preset runs the paper's tolerances
    # (the defaults); benchmarks/calippso.py part ``preset`` repeats the measurement.
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
