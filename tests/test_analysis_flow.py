"""Flow summary on synthetic time series that follow the flow schema exactly."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from jamflow.analysis.flow import (
    block_average,
    contact_lifetimes,
    flow_curve,
    flow_summary,
    strain_average,
)
from jamflow.io import new_dataset_attrs, read_dataset, write_dataset


def flow_dataset(strain, shear_stress, pressure, events, n=64, d=2, kappa=None, mode="shear") -> xr.Dataset:
    """A flow time series with the variables, dims and attributes of the shared schema."""
    steps = len(strain)
    one = {"units": "1"}
    ev = np.array(events, dtype=np.float64).reshape(-1, 4)  # strain, i, j, kind
    order = np.argsort(ev[:, 0], kind="stable")
    ev = ev[order]
    return xr.Dataset(
        data_vars={
            "shear_stress": ("step", shear_stress, {**one, "long_name": "shear stress (Eq. 30)"}),
            "pressure": ("step", pressure, {**one, "long_name": "pressure (Eq. 24)"}),
            "packing_fraction": ("step", np.full(steps, 0.83), {**one, "long_name": "packing fraction"}),
            "kappa": ("step", np.full(steps, np.nan) if kappa is None else kappa, {**one, "long_name": "kappa"}),
            "n_contacts": ("step", np.full(steps, 100, dtype=np.int64), {**one, "long_name": "contacts"}),
            "z_bar": ("step", np.full(steps, 3.5), {**one, "long_name": "constrained coordination (Eq. 29)"}),
            "volume": ("step", np.full(steps, 50.0), {**one, "long_name": "box volume"}),
            "constraint_error": ("step", np.zeros(steps), {**one, "long_name": "max |r - sigma| / sigma"}),
            "event_strain": ("event", ev[:, 0], {**one, "long_name": "strain of the event"}),
            "event_time": ("event", ev[:, 0], {"units": "lambda xi0 / f", "long_name": "time of the event"}),
            "event_i": ("event", ev[:, 1].astype(np.int64), {**one, "long_name": "first particle"}),
            "event_j": ("event", ev[:, 2].astype(np.int64), {**one, "long_name": "second particle"}),
            "event_kind": ("event", ev[:, 3].astype(np.int8),
                           {**one, "long_name": "event kind", "flag_values": np.array([1, -1], dtype=np.int8),
                            "flag_meanings": "contact_made contact_broken"}),
        },
        coords={
            "strain": ("step", strain, {**one, "long_name": "accumulated shear strain"}),
            "time": ("step", strain.copy(), {"units": "lambda xi0 / f", "long_name": "time (unit shear rate)"}),
        },
        attrs=new_dataset_attrs("synthetic flow", {"gamma_dot": 1.0}, mode=mode, d=d, N=n),
    )


def test_trapezoid_average_is_unbiased_by_irregular_sampling(rng):
    # steps cluster where events happen; a plain mean over steps would be biased
    s = np.sort(np.concatenate([rng.random(20), 0.9 + 0.1 * rng.random(500), [0.0, 1.0]]))
    assert strain_average(s, s) == pytest.approx(0.5, abs=1e-12)
    assert abs(np.mean(s) - 0.5) > 0.2


def test_steady_state_mean_recovered_with_error(rng):
    n_steps = 20001
    strain = np.linspace(0.0, 2.0, n_steps)
    sigma = 2.0 + 0.3 * rng.standard_normal(n_steps)
    p = 10.0 + rng.standard_normal(n_steps)
    ds = flow_dataset(strain, sigma, p, [])
    out = flow_summary(ds, strain_min=1.0, strain_max=2.0, n_blocks=20)
    m, e = out.attrs["mean_shear_stress"], out.attrs["err_shear_stress"]
    print(f"<sigma> = {m:.5f} +- {e:.5f}, <p> = {out.attrs['mean_pressure']:.4f}, mu = {out.attrs['mean_friction']:.5f}")
    assert abs(m - 2.0) < 4 * e
    # white noise: the block error must match sigma_noise / sqrt(samples in window)
    assert e == pytest.approx(0.3 / np.sqrt(n_steps / 2), rel=0.5)
    assert out.attrs["friction_ratio_of_means"] == pytest.approx(0.2, abs=0.005)
    assert out["friction"].values == pytest.approx(sigma / p)


def test_default_window_is_second_half():
    strain = np.linspace(0, 4, 401)
    ds = flow_dataset(strain, strain.copy(), np.ones_like(strain), [])
    out = flow_summary(ds)
    assert out.attrs["window_strain_min"] == 2.0 and out.attrs["window_strain_max"] == 4.0
    assert out.attrs["mean_shear_stress"] == pytest.approx(3.0, abs=1e-12)
    assert np.isnan(out.attrs["mean_kappa"])


def test_block_average_of_constant_has_zero_error():
    s = np.linspace(0, 1, 101)
    m, e, nb = block_average(s, np.full(101, 7.0), 0.0, 1.0, 10)
    assert m == pytest.approx(7.0, rel=1e-14) and e < 1e-14 and nb == 10


def test_contact_lifetimes_and_event_rates():
    events = [
        (0.10, 1, 2, 1), (0.35, 1, 2, -1),      # lifetime 0.25
        (0.50, 1, 2, 1), (0.60, 1, 2, -1),      # same pair again: 0.10
        (0.20, 3, 7, -1),                       # present at start: censored
        (0.70, 4, 5, 1),                        # still present at end: censored
        (0.40, 0, 9, 1), (0.90, 0, 9, -1),      # 0.50
    ]
    strain = np.linspace(0, 1, 101)
    ds = flow_dataset(strain, np.ones(101), np.ones(101), events, n=10)
    life = contact_lifetimes(ds)
    assert sorted(np.round(life["strain"], 12).tolist()) == [0.1, 0.25, 0.5]
    assert life["n_open_at_start"] == 1 and life["n_open_at_end"] == 1 and life["n_inconsistent"] == 0
    out = flow_summary(ds, strain_min=0.0, strain_max=1.0)
    assert out.attrs["n_events_made"] == 4 and out.attrs["n_events_broken"] == 4
    assert out.attrs["made_per_strain"] == pytest.approx(4.0)
    assert out.attrs["made_per_strain_per_particle"] == pytest.approx(0.4)
    assert out.attrs["mean_lifetime_strain"] == pytest.approx((0.1 + 0.25 + 0.5) / 3)


def test_rejects_non_flow_dataset():
    with pytest.raises(ValueError, match="not a flow time series"):
        flow_summary(xr.Dataset({"x": ("step", np.zeros(3))}))


def test_flow_summary_cli_round_trip(tmp_path, rng):
    strain = np.linspace(0, 1, 1001)
    ds = flow_dataset(strain, 1.0 + 0.1 * rng.standard_normal(1001), np.full(1001, 5.0),
                      [(0.2, 0, 1, 1), (0.6, 0, 1, -1)], kappa=0.01 * rng.standard_normal(1001),
                      mode="shear_fixed_pressure")
    write_dataset(ds, tmp_path / "run.nc")
    from jamflow.cli import main

    assert main(["flow-summary", str(tmp_path / "run.nc"), str(tmp_path / "sum.nc"), "--strain-min", "0.5"]) == 0
    out = read_dataset(tmp_path / "sum.nc")
    assert out.attrs["mode"] == "shear_fixed_pressure"
    assert json.loads(out.attrs["parameters"])["strain_min"] == 0.5
    assert all("units" in v.attrs and "long_name" in v.attrs for v in out.data_vars.values())
    assert out["lifetime_strain"].values.tolist() == pytest.approx([0.4])


@pytest.mark.slow
def test_summary_of_a_real_overdamped_shear_run():
    from jamflow.protocols.initial import random_packing
    from jamflow.protocols.overdamped.driving import Drive
    from jamflow.protocols.overdamped.run import Stop, run_flow

    start = random_packing(32, 2, 0.5, "bi", 7, 1.4, 0.5, 0.1)
    res = run_flow(start, Drive(mode="shear_fixed_pressure", pressure=10.0), Stop(strain=1.0, max_steps=3000))
    out = flow_summary(res.series)
    print({k: out.attrs[k] for k in ("mean_shear_stress", "err_shear_stress", "mean_friction", "n_events_made",
                                     "n_lifetimes", "contact_count_change", "event_net_change")})
    assert out.attrs["n_events_made"] > 0
    assert out.attrs["contact_count_change"] == out.attrs["event_net_change"]
    assert out.attrs["n_inconsistent_events"] == 0
    assert np.all(out["lifetime_strain"].values > 0)
    # once contacts carry the load the imposed pressure holds (before the first collision p = 0)
    loaded = out["n_contacts"].values > 0
    assert loaded.any() and np.all(out["pressure"].values[loaded] == pytest.approx(10.0, rel=1e-9))


def _summary(pressure: float, stress: float, rng, mode: str = "shear_fixed_pressure", d: int = 2) -> xr.Dataset:
    strain = np.linspace(0, 1, 2001)
    noise = 0.01 * rng.standard_normal(2001)
    return flow_summary(flow_dataset(strain, stress * (1 + noise), pressure * (1 + noise), [(0.2, 0, 1, 1)],
                                     kappa=np.zeros(2001), mode=mode, d=d))


def test_flow_curve_viscous_number_is_inverse_mean_pressure_and_sorted(rng):
    """I = 1 / <p> in the runs' reduced units, mu = <sigma / p>, runs ordered by I."""
    runs = [_summary(p, mu * p, rng) for p, mu in ((100.0, 0.30), (10.0, 0.45), (30.0, 0.38))]
    curve = flow_curve(runs, ["p100", "p10", "p30"])
    assert curve["label"].values.tolist() == ["p100", "p30", "p10"]
    p_mean = np.array([runs[k].attrs["mean_pressure"] for k in (0, 2, 1)])
    assert curve["viscous_number"].values == pytest.approx(1.0 / p_mean, rel=1e-15)
    assert curve["friction"].values == pytest.approx([0.30, 0.38, 0.45], rel=1e-12)
    dp = np.array([runs[k].attrs["err_pressure"] for k in (0, 2, 1)])
    assert curve["viscous_number_err"].values == pytest.approx(dp / p_mean**2, rel=1e-15)
    assert np.all(curve["friction_err"].values > 0)
    assert all("units" in v.attrs and "long_name" in v.attrs for v in curve.data_vars.values())


@pytest.mark.parametrize("bad", ["compress", "dimension", "labels"])
def test_flow_curve_refuses_runs_without_a_viscous_number(rng, bad):
    runs = [_summary(10.0, 4.0, rng), _summary(30.0, 10.0, rng)]
    labels = None
    if bad == "compress":
        runs[1] = _summary(30.0, 10.0, rng, mode="compress")
    elif bad == "dimension":
        runs[1] = _summary(30.0, 10.0, rng, d=3)
    else:
        labels = ["one"]
    with pytest.raises(ValueError, match="flow curve"):
        flow_curve(runs, labels)


def test_flow_curve_cli_prints_and_plots(tmp_path, rng, capsys):
    from jamflow.cli import main

    paths = []
    for p, mu in ((10.0, 0.45), (100.0, 0.30)):
        path = tmp_path / f"sum{p:g}.nc"
        write_dataset(_summary(p, mu * p, rng), path)
        paths.append(str(path))
    out = tmp_path / "curve.nc"
    assert main(["flow-curve", *paths, str(out), "--labels", "p10", "p100"]) == 0
    printed = capsys.readouterr().out
    curve = read_dataset(out, "flow-curve")
    for label, i, mu in zip(curve.label.values, curve.viscous_number.values, curve.friction.values, strict=True):
        assert f"{label}: I" in printed and f"{i:.4g}" in printed and f"{mu:.4f}" in printed
    assert main(["plot", "flow-curve", str(out), str(tmp_path / "curve.png")]) == 0
    assert (tmp_path / "curve.png").stat().st_size > 0
