"""Summaries of flow time series: stress–strain, friction, steady state, events.

Input is the flow dataset written by the overdamped (event-driven) stage, dims
``step`` and ``event``: coordinates
``strain(step)``, ``time(step)``; variables ``shear_stress`` (Lerner et al. Eq. 30),
``pressure`` (Eq. 24), ``packing_fraction``, ``kappa``, ``n_contacts``, ``z_bar``
(Eq. 29); events ``event_strain``, ``event_time``, ``event_i``, ``event_j``,
``event_kind`` (+1 contact made, -1 contact broken).

Steady-state averages are strain averages over a window ``[strain_min,
strain_max]``: the trapezoid integral of the signal over strain divided by the
window length, so irregular sampling (steps cluster at events) does not bias them.
Their error is a block estimate: the window is cut into ``n_blocks`` equal strain
blocks, and the standard error of the block means (ddof = 1) is reported, which
absorbs correlations shorter than a block.

Contact lifetimes pair each ``contact_made`` event with the next
``contact_broken`` event of the same pair ``(i, j)``. Contacts already present at
the start (first event of the pair is a break) or still present at the end (last
event is a make) are *censored*: they are counted, not given a lifetime.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..io import new_dataset_attrs

__all__ = ["SIGNALS", "SHEAR_MODES", "strain_average", "block_average", "contact_lifetimes", "flow_summary", "flow_curve"]

#: Flow modes whose stresses are in units of ``gamma_dot / (xi0 lambda^(d-2))`` under shear.
SHEAR_MODES: tuple[str, ...] = ("shear", "shear_fixed_pressure")

#: Step variables summarised by :func:`flow_summary` (``friction`` is derived).
SIGNALS: tuple[str, ...] = ("shear_stress", "pressure", "friction", "packing_fraction", "kappa", "z_bar", "n_contacts")

_REQUIRED_STEP = ("shear_stress", "pressure", "packing_fraction", "n_contacts", "z_bar")
_REQUIRED_EVENT = ("event_strain", "event_time", "event_i", "event_j", "event_kind")


def strain_average(strain: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """Trapezoid average of ``y`` over ``strain`` (plain mean when the span is zero or one point)."""
    ok = np.isfinite(y)
    s, y = strain[ok], y[ok]
    if len(y) == 0:
        return np.nan
    span = s[-1] - s[0]
    if len(y) < 2 or span <= 0.0:
        return float(np.mean(y))
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(s)) / span)


def block_average(
    strain: NDArray[np.float64], y: NDArray[np.float64], lo: float, hi: float, n_blocks: int
) -> tuple[float, float, int]:
    """Strain average of ``y`` over ``[lo, hi]`` and its block standard error.

    Returns
    -------
    mean, stderr : float
        ``stderr`` is NaN with fewer than two populated blocks.
    n_used : int
        Number of populated blocks.
    """
    inside = (strain >= lo) & (strain <= hi)
    mean = strain_average(strain[inside], y[inside])
    edges = np.linspace(lo, hi, n_blocks + 1)
    means = []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (strain >= a) & (strain <= b) & np.isfinite(y)
        if np.any(sel):
            means.append(strain_average(strain[sel], y[sel]))
    means_arr = np.asarray(means)
    if len(means_arr) < 2:
        return mean, np.nan, len(means_arr)
    return mean, float(np.std(means_arr, ddof=1) / np.sqrt(len(means_arr))), len(means_arr)


def contact_lifetimes(ds: xr.Dataset) -> dict[str, NDArray | int]:
    """Pair made -> broken events per contact.

    Returns
    -------
    dict with
        ``strain``, ``time`` : ndarray, shape (L,) — lifetimes in strain and time units;
        ``i``, ``j`` : ndarray of int, shape (L,) — the pair of each lifetime;
        ``n_open_at_start``, ``n_open_at_end``, ``n_inconsistent`` : int.
    """
    i = ds["event_i"].values.astype(np.int64)
    j = ds["event_j"].values.astype(np.int64)
    kind = ds["event_kind"].values.astype(np.int64)
    es = ds["event_strain"].values.astype(np.float64)
    et = ds["event_time"].values.astype(np.float64)
    if np.any(i >= j):
        raise ValueError("events must name pairs with event_i < event_j")
    if not np.all(np.isin(kind, (1, -1))):
        raise ValueError("event_kind must be +1 (contact made) or -1 (contact broken)")
    key = i * (int(max(j.max(initial=0), i.max(initial=0))) + 1) + j
    order = np.lexsort((np.arange(len(key)), et, key))
    key, kind, es, et, i, j = key[order], kind[order], es[order], et[order], i[order], j[order]
    same = key[1:] == key[:-1]
    life = same & (kind[:-1] == 1) & (kind[1:] == -1)
    first = np.ones(len(key), dtype=bool)
    first[1:] = ~same
    last = np.ones(len(key), dtype=bool)
    last[:-1] = ~same
    return {
        "strain": (es[1:] - es[:-1])[life],
        "time": (et[1:] - et[:-1])[life],
        "i": i[:-1][life],
        "j": j[:-1][life],
        "n_open_at_start": int(np.sum(first & (kind == -1))),
        "n_open_at_end": int(np.sum(last & (kind == 1))),
        "n_inconsistent": int(np.sum(same & (kind[:-1] == kind[1:]))),
    }


def _check_flow(ds: xr.Dataset) -> None:
    missing = [v for v in (*_REQUIRED_STEP, *_REQUIRED_EVENT) if v not in ds.variables]
    if "strain" not in ds.variables or "time" not in ds.variables:
        missing += [c for c in ("strain", "time") if c not in ds.variables]
    if missing:
        raise ValueError(f"not a flow time series: missing {', '.join(missing)}")
    strain = ds["strain"].values
    if len(strain) < 2:
        raise ValueError("flow time series needs at least two steps")
    if np.any(np.diff(ds["time"].values) < 0):
        raise ValueError("flow time series: time must be non-decreasing")
    if np.any(np.diff(ds["event_time"].values) < 0):
        raise ValueError("flow time series: events must be in time order")


def flow_summary(
    ds: xr.Dataset,
    strain_min: float | None = None,
    strain_max: float | None = None,
    n_blocks: int = 10,
    parameters: dict | None = None,
) -> xr.Dataset:
    """Stress–strain signals, steady-state averages, contact lifetimes and event rates.

    Parameters
    ----------
    ds : xarray.Dataset
        A flow time series (module docstring).
    strain_min, strain_max : float or None
        Steady-state window (default: the second half of the strain range).
    n_blocks : int
        Blocks of the error estimate.
    parameters : dict or None
        Stage parameters recorded in the provenance attributes.

    Returns
    -------
    xarray.Dataset
        dim ``step``: the input signals plus ``friction = shear_stress / pressure``
        (macroscopic friction mu, NaN where p = 0); dim ``quantity``:
        ``steady_mean``, ``steady_err`` for :data:`SIGNALS`; dim ``lifetime``:
        ``lifetime_strain``, ``lifetime_time``; attributes ``mean_<q>`` /
        ``err_<q>``, ``friction_ratio_of_means`` (<sigma>/<p>), event counts and
        rates per unit strain and time in the window (``*_per_particle`` divided
        by N), censored-lifetime counts, and ``contact_count_change`` (last minus
        first ``n_contacts``) beside ``event_net_change`` (made minus broken over the
        whole run), equal for a consistent event list.
    """
    _check_flow(ds)
    strain = ds["strain"].values.astype(np.float64)
    time = ds["time"].values.astype(np.float64)
    lo = float(strain[0] + 0.5 * (strain[-1] - strain[0])) if strain_min is None else float(strain_min)
    hi = float(strain[-1]) if strain_max is None else float(strain_max)
    if not hi >= lo:
        raise ValueError(f"steady-state window [{lo:g}, {hi:g}] is empty")
    p = ds["pressure"].values.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        friction = np.where(p != 0.0, ds["shear_stress"].values / p, np.nan)
    signals = {name: ds[name].values.astype(np.float64) for name in SIGNALS if name in ds and name != "friction"}
    signals["friction"] = friction
    names = [q for q in SIGNALS if q in signals]
    means, errs, attrs_avg = [], [], {}
    if hi > lo:
        for q in names:
            m, e, _ = block_average(strain, signals[q], lo, hi, n_blocks)
            means.append(m)
            errs.append(e)
    else:
        # a zero-length strain window (compression at fixed shear): average over time instead
        inside = (strain >= lo) & (strain <= hi)
        for q in names:
            m, e, _ = block_average(time[inside], signals[q][inside], time[inside][0], time[inside][-1], n_blocks)
            means.append(m)
            errs.append(e)
    for q, m, e in zip(names, means, errs):
        attrs_avg[f"mean_{q}"] = m
        attrs_avg[f"err_{q}"] = e
    ratio = (attrs_avg["mean_shear_stress"] / attrs_avg["mean_pressure"]
             if attrs_avg.get("mean_pressure") else np.nan)

    life = contact_lifetimes(ds)
    kind = ds["event_kind"].values
    es = ds["event_strain"].values
    inside_ev = (es >= lo) & (es <= hi)
    in_window = (strain >= lo) & (strain <= hi)
    d_strain = hi - lo
    d_time = float(time[in_window][-1] - time[in_window][0]) if np.any(in_window) else 0.0
    n = int(ds.attrs.get("N", 0)) or None
    made = int(np.sum(inside_ev & (kind == 1)))
    broken = int(np.sum(inside_ev & (kind == -1)))
    rates = {
        "n_events_made": made,
        "n_events_broken": broken,
        "made_per_strain": made / d_strain if d_strain > 0 else np.nan,
        "broken_per_strain": broken / d_strain if d_strain > 0 else np.nan,
        "made_per_time": made / d_time if d_time > 0 else np.nan,
        "broken_per_time": broken / d_time if d_time > 0 else np.nan,
    }
    if n:
        rates.update({f"{k}_per_particle": v / n for k, v in list(rates.items()) if k.endswith(("strain", "time"))})
    one = {"units": "1"}
    time_units = ds["time"].attrs.get("units", "1")
    step_vars = {
        name: ("step", signals[name], {**ds[name].attrs} if name in ds else {})
        for name in names
    }
    step_vars["friction"] = ("step", friction, {**one, "long_name": "macroscopic friction mu = shear_stress / pressure"})
    for name, (_, _, a) in step_vars.items():
        a.setdefault("units", "1")
        a.setdefault("long_name", name.replace("_", " "))
    return xr.Dataset(
        data_vars={
            **step_vars,
            "steady_mean": ("quantity", np.array(means), {**one, "long_name": "strain average over the steady-state window"}),
            "steady_err": ("quantity", np.array(errs), {**one, "long_name": "block standard error of steady_mean"}),
            "lifetime_strain": ("lifetime", life["strain"], {**one, "long_name": "contact lifetime in shear strain"}),
            "lifetime_time": ("lifetime", life["time"], {"units": time_units, "long_name": "contact lifetime in time"}),
            "lifetime_i": ("lifetime", life["i"], {**one, "long_name": "first particle of the contact"}),
            "lifetime_j": ("lifetime", life["j"], {**one, "long_name": "second particle of the contact"}),
        },
        coords={
            "strain": ("step", strain, {**one, "long_name": "accumulated shear strain"}),
            "time": ("step", time, {"units": time_units, "long_name": "time"}),
            "quantity": ("quantity", np.array(names, dtype=object), {"long_name": "summarised signal"}),
        },
        attrs=new_dataset_attrs(
            "jamflow flow summary",
            parameters or {},
            mode=str(ds.attrs.get("mode", "unknown")),
            d=int(ds.attrs.get("d", 0)),
            N=int(ds.attrs.get("N", 0)),
            window_strain_min=lo,
            window_strain_max=hi,
            n_blocks=n_blocks,
            averaging="trapezoid strain average; error = std(block means, ddof=1)/sqrt(blocks)",
            friction_ratio_of_means=ratio,
            n_lifetimes=len(life["strain"]),
            mean_lifetime_strain=float(np.mean(life["strain"])) if len(life["strain"]) else np.nan,
            n_open_at_start=life["n_open_at_start"],
            n_open_at_end=life["n_open_at_end"],
            n_inconsistent_events=life["n_inconsistent"],
            # bookkeeping check: contacts gained over the run must equal made minus broken events
            contact_count_change=float(ds["n_contacts"].values[-1] - ds["n_contacts"].values[0]),
            event_net_change=int(np.sum(kind == 1) - np.sum(kind == -1)),
            **attrs_avg,
            **rates,
        ),
    )


def flow_curve(summaries: list[xr.Dataset], labels: list[str] | None = None,
               parameters: dict | None = None) -> xr.Dataset:
    """Friction and packing fraction against the viscous number over shear runs (Lerner et al. Sec. V A).

    In the reduced units of the shear runs stresses are measured in
    ``gamma_dot / (xi0 lambda^(d-2))`` (``xi0`` the mobility of Eq. 31), so the viscous
    number of a run, ``I = gamma_dot / (xi0 lambda^(d-2) p)``, is ``1 / <p>`` with
    ``<p>`` its steady-state mean pressure in those units, whatever ``gamma_dot``.
    Its error follows from the block error of ``<p>``: ``dI = d<p> / <p>^2``.

    Parameters
    ----------
    summaries : list of xarray.Dataset
        ``jamflow flow-summary`` outputs of shear runs (fixed volume or fixed pressure),
        all with the same ``d``.
    labels : list of str or None
        One label per run (default ``run<k>``).
    parameters : dict or None
        Stage parameters recorded in the provenance attributes.

    Returns
    -------
    xarray.Dataset
        dim ``run`` sorted by increasing ``I``: ``viscous_number`` and its error,
        ``pressure``, ``friction`` (mu = <sigma / p>), ``friction_ratio_of_means``
        (<sigma> / <p>), ``packing_fraction``, ``z_bar`` with block errors, the
        steady-state window and ``N`` per run; ``label(run)`` names the runs.

    Raises
    ------
    ValueError
        If a run is not a shear run, has a non-positive mean pressure, or the runs
        differ in dimension.
    """
    if not summaries:
        raise ValueError("flow curve needs at least one flow summary")
    labels = list(labels) if labels is not None else [f"run{k}" for k in range(len(summaries))]
    if len(labels) != len(summaries):
        raise ValueError(f"flow curve: {len(labels)} labels for {len(summaries)} runs")
    dims = {int(s.attrs.get("d", 0)) for s in summaries}
    if len(dims) != 1:
        raise ValueError(f"flow curve: runs of different dimensions {sorted(dims)}")
    for label, s in zip(labels, summaries, strict=True):
        if s.attrs.get("mode") not in SHEAR_MODES:
            raise ValueError(f"flow curve: run {label} is not a shear run (mode {s.attrs.get('mode')!r})")
        if not s.attrs["mean_pressure"] > 0:
            raise ValueError(f"flow curve: run {label} has mean pressure {s.attrs['mean_pressure']:g} <= 0 "
                             "(no viscous number)")

    def column(name: str) -> NDArray[np.float64]:
        return np.array([float(s.attrs.get(name, np.nan)) for s in summaries])

    p, dp = column("mean_pressure"), column("err_pressure")
    order = np.argsort(1.0 / p, kind="stable")
    one = {"units": "1"}
    stress_unit = summaries[0]["pressure"].attrs.get("units", "1")
    variables = {
        "viscous_number": (1.0 / p, {**one, "long_name": "viscous number I = gamma_dot / (xi0 lambda^(d-2) <p>)"}),
        "viscous_number_err": (dp / p**2, {**one, "long_name": "block error of I (from the error of <p>)"}),
        "pressure": (p, {"units": stress_unit, "long_name": "steady-state mean pressure <p>"}),
        "pressure_err": (dp, {"units": stress_unit, "long_name": "block error of <p>"}),
        "friction": (column("mean_friction"), {**one, "long_name": "steady-state mean friction mu = <sigma / p>"}),
        "friction_err": (column("err_friction"), {**one, "long_name": "block error of mu"}),
        "friction_ratio_of_means": (column("friction_ratio_of_means"), {**one, "long_name": "<sigma> / <p>"}),
        "packing_fraction": (column("mean_packing_fraction"), {**one, "long_name": "steady-state mean packing fraction"}),
        "packing_fraction_err": (column("err_packing_fraction"), {**one, "long_name": "block error of phi"}),
        "z_bar": (column("mean_z_bar"), {**one, "long_name": "steady-state mean coordination (Eq. 29)"}),
        "z_bar_err": (column("err_z_bar"), {**one, "long_name": "block error of z_bar"}),
        "window_strain_min": (column("window_strain_min"), {**one, "long_name": "start of the steady-state window"}),
        "window_strain_max": (column("window_strain_max"), {**one, "long_name": "end of the steady-state window"}),
        "n_particles": (column("N").astype(np.int64), {**one, "long_name": "number of particles N"}),
    }
    return xr.Dataset(
        data_vars={name: ("run", values[order], attrs) for name, (values, attrs) in variables.items()},
        coords={"label": ("run", np.array(labels, dtype=object)[order], {"long_name": "run label"})},
        attrs=new_dataset_attrs("jamflow flow curve", parameters or {}, d=dims.pop(), n_runs=len(summaries),
                                stress_unit=stress_unit),
    )
