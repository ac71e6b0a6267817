"""The sweep engine: run a stage's grid against its reference, time every run, mark the
Pareto front and recommend the presets' settings."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..io import new_dataset_attrs
from .stages import STAGES, StageSweep


def _label(knobs: dict[str, Any]) -> str:
    return " ".join(f"{k}={v:.0e}" if isinstance(v, float) else f"{k}={v}" for k, v in knobs.items())


TIMING_BUDGET: float = 1.0
TIMING_REPEATS: int = 5


def _timed(run: Callable, *args: Any) -> tuple[Any, float]:
    """Output of ``run(*args)`` and its wall time, the minimum over repeats of short runs."""
    t0 = time.perf_counter()
    out = run(*args)
    best = spent = time.perf_counter() - t0
    repeats = 1
    while spent < TIMING_BUDGET and repeats < TIMING_REPEATS:
        t0 = time.perf_counter()
        run(*args)
        t = time.perf_counter() - t0
        best, spent, repeats = min(best, t), spent + t, repeats + 1
    return out, best


def pareto_front(time_s: ArrayLike, error: ArrayLike) -> NDArray[np.bool_]:
    """Settings not dominated in (time, error): no other is at least as fast and as
    accurate and strictly better in one of the two.

    Parameters
    ----------
    time_s, error : array_like, shape (M,)
        Wall time [s] and error (NaN errors are never on the front).

    Returns
    -------
    ndarray of bool, shape (M,)
    """
    t = np.asarray(time_s, dtype=np.float64)
    e = np.asarray(error, dtype=np.float64)
    if t.shape != e.shape or t.ndim != 1:
        raise ValueError(f"time and error must be 1-D of equal length, got {t.shape} and {e.shape}")
    ok = np.isfinite(t) & np.isfinite(e)
    front = np.zeros(len(t), dtype=bool)
    for k in np.flatnonzero(ok):
        better_eq = ok & (t <= t[k]) & (e <= e[k])
        strictly = better_eq & ((t < t[k]) | (e < e[k]))
        front[k] = not strictly.any()
    return front



def sweep(
    stage: str,
    seed: int = 0,
    quick: bool = False,
    progress: Callable[[str], None] | None = None,
) -> xr.Dataset:
    """Run one stage's sweep (see module docstring).

    Parameters
    ----------
    stage : str
        Key of :data:`STAGES`.
    seed : int
        Seed of the fixed inputs.
    quick : bool
        Smaller inputs and grid (a few minutes for all stages on 2 cores).
    progress : callable, optional
        Called with the label of each setting after it ran.

    Returns
    -------
    xarray.Dataset
        Dim ``setting`` (the reference first), coordinate ``label``; one variable per
        knob, ``time`` [s], every metric of the stage, ``is_reference`` and
        ``on_front``; attributes ``stage``, ``primary_error``, ``reference``,
        ``thresholds``, ``recommended_<preset>`` and provenance.
    """
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}; choose one of {', '.join(STAGES)}")
    sw = STAGES[stage]
    inputs = sw.prepare(seed, quick)
    grid = sw.grid(quick)
    sw.run(inputs, grid[0], quick)  # untimed warm-up: numba compilation, caches
    ref_knobs = sw.reference(quick)
    settings = [ref_knobs] + grid
    rows, outputs = [], []
    ref_out = None
    for k, knobs in enumerate(settings):
        out, elapsed = _timed(sw.run, inputs, knobs, quick)
        if progress is not None:
            progress(_label(knobs))
        if k == 0:
            ref_out = out
        rows.append({"time": elapsed, **sw.compare(out, ref_out)})
        outputs.append(out)
    labels = [_label(s) for s in settings]
    data = {
        "time": (("setting",), np.array([r["time"] for r in rows]), {"units": "s", "long_name": "wall time of the run"}),
        "is_reference": (("setting",), np.array([1] + [0] * len(grid), dtype=np.int8),
                         {"units": "1", "long_name": "1 for the reference setting"}),
    }
    for m, long_name in sw.metrics.items():
        data[m] = (("setting",), np.array([r[m] for r in rows], dtype=np.float64), {"units": "1", "long_name": long_name})
    coords = {"label": (("setting",), np.array(labels), {"long_name": "setting of the accuracy knobs"})}
    for knob, long_name in sw.knobs.items():
        vals = np.array([s.get(knob, ref_knobs.get(knob)) for s in settings])
        coords[knob] = (("setting",), vals, {"long_name": long_name})
    ds = xr.Dataset(data, coords=coords)
    ds["on_front"] = (("setting",), pareto_front(ds.time.values, ds[sw.primary].values).astype(np.int8),
                      {"units": "1", "long_name": f"1 on the Pareto front of time and {sw.primary}"})
    rec = recommend(ds, sw)
    ds.attrs = new_dataset_attrs(
        f"jamflow speed/accuracy sweep: {stage}",
        {"stage": stage, "seed": seed, "quick": quick},
        stage=stage, description=sw.description, primary_error=sw.primary,
        primary_error_long_name=sw.metrics[sw.primary], reference=json.dumps(ref_knobs, sort_keys=True),
        thresholds=json.dumps(sw.thresholds), commands=json.dumps(list(sw.commands)),
        preset_options=json.dumps(sw.preset_options),
        recommendation_rule="fastest setting meeting every limit of the preset (thresholds); the reference if none",
        **{f"recommended_{p}": label for p, label in rec.items()},
    )
    return ds


def recommend(ds: xr.Dataset, sw: StageSweep | None = None) -> dict[str, str]:
    """Label of the recommended setting per preset: the fastest setting meeting all
    of the preset's limits (:attr:`StageSweep.thresholds`), else the reference.

    With only the primary error limited the choice lies on the Pareto front.

    Parameters
    ----------
    ds : xarray.Dataset
        Output of :func:`sweep` (``on_front`` and the primary error present).
    sw : StageSweep, optional
        The stage (default: from ``ds.attrs['stage']``).
    """
    sw = sw or STAGES[ds.attrs["stage"]]
    t = ds.time.values
    ref = int(np.flatnonzero(ds.is_reference.values)[0])
    out = {}
    for preset, limits in sw.thresholds.items():
        good = np.ones(len(t), dtype=bool)
        for metric, limit in limits.items():
            good &= ds[metric].values <= limit
        ok = np.flatnonzero(good)
        out[preset] = str(ds.label.values[ok[np.argmin(t[ok])]] if ok.size else ds.label.values[ref])
    return out
