"""Checkpoint and resume of a CALiPPSO chain: a chain stopped every few LPs and resumed
from its checkpoint each time must end in the uninterrupted chain's packing bit for bit
(positions, contacts, forces, every LP of the history), with either warm engine, with
walls and with the Newton finish; a checkpoint of another start, other options or other
code must be refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from jamflow.cli import main
from jamflow.io import read_packing, write_packing
from jamflow.protocols.calippso import ChainStopped, calippso
from jamflow.protocols.initial import random_packing

DATA = Path(__file__).parent / "data"

#: History entries that are clocks, not the chain's path.
CLOCKS = {"lp_time"}
#: Result attributes that are clocks or the process's memory.
CLOCK_ATTRS = {"total_time", "peak_memory", "lp_time_total", "newton_time"}

#: start, options, LPs per run, and whether a warm LP starts a resumed run (the carried basis crosses a stop)
CASES = {
    # far start, HiGHS's warm simplex, every bound phase
    "3d-far-highs": (lambda: random_packing(64, 3, 0.3, "mono", seed=2), dict(warm_engine="highs"), 8, True),
    # hard walls (wall rows) and the Newton finish (its attempts are chain state); no warm LP
    "2d-walls-newton": (lambda: random_packing(64, 2, 0.5, "bi", seed=3, walls=True),
                        dict(walls=True, finish="newton"), 3, False),
    # a start near jamming, jamflow.simplex's warm LPs from the carried working set
    "3d-near-jamflow": (lambda: read_packing(DATA / "calippso_near_start_n256.nc"), dict(warm_engine="jamflow"), 2,
                        True),
}


def _stopped_and_resumed(start, kwargs: dict, every: int, path: Path):
    """The chain run ``every`` LPs at a time, each run resumed from ``path``; its result and the
    stops. Only the stops write (a write per LP is the CLI test's)."""
    stops = 0
    while True:
        try:
            return calippso(start, checkpoint=path, checkpoint_every=1e9, stop_after=every, **kwargs), stops
        except ChainStopped:
            stops += 1


@pytest.fixture(scope="module", params=list(CASES), ids=list(CASES))
def chains(request, tmp_path_factory):
    make, kwargs, every, _ = CASES[request.param]
    start = make()
    whole = calippso(start, **kwargs)
    resumed, stops = _stopped_and_resumed(start, kwargs, every, tmp_path_factory.mktemp("ck") / "chain.nc")
    return request.param, whole, resumed, {k * every + 1 for k in range(1, stops + 1)}


def test_resumed_chain_is_the_uninterrupted_one(chains):
    _, whole, resumed, resumed_at = chains
    assert len(resumed_at) >= 2, "the chain must have been stopped and resumed more than once"
    p, q = whole.packing, resumed.packing
    np.testing.assert_array_equal(q.position, p.position)
    np.testing.assert_array_equal(q.diameter, p.diameter)
    np.testing.assert_array_equal(q.contacts, p.contacts)
    np.testing.assert_array_equal(q.force, p.force)
    np.testing.assert_array_equal(q.rattler, p.rattler)
    np.testing.assert_array_equal(resumed.wall_contacts, whole.wall_contacts)
    for name in whole.history.data_vars:
        if name not in CLOCKS:
            np.testing.assert_array_equal(resumed.history[name].values, whole.history[name].values, err_msg=name)
    for key, value in p.attrs.items():
        if key not in CLOCK_ATTRS:
            assert q.attrs[key] == value or (value != value and q.attrs[key] != q.attrs[key]), key
    assert resumed.packing.attrs["max_overlap"] <= 1e-13


def test_each_case_exercises_its_state(chains):
    """Each case carries the state it is there for across its stops: Newton attempts, wall
    rows, and a carried basis that a resumed run's first LP starts its engine from
    (otherwise the equality above would not test them)."""
    case, whole, _, resumed_at = chains
    _, kwargs, _, carries_basis = CASES[case]
    a = whole.packing.attrs
    if kwargs.get("finish") == "newton":
        assert a["newton_attempts"] >= 1
    if kwargs.get("walls"):
        assert len(whole.wall_contacts) > 0
    if carries_basis:
        warm = whole.history["warm_start"].values.astype(bool)
        assert set(whole.history["engine"].values[warm]) == {kwargs["warm_engine"]}
        assert resumed_at & set(whole.history["iteration"].values[warm].tolist())


def test_checkpoint_of_another_chain_is_refused(tmp_path):
    start = random_packing(64, 3, 0.3, "mono", seed=2)
    path = tmp_path / "ck.nc"
    with pytest.raises(ChainStopped):
        calippso(start, checkpoint=path, checkpoint_every=0.0, stop_after=2)
    with pytest.raises(ValueError, match=r"another run \(different tol_s \(1e-09 -> 1e-08\)\)"):
        calippso(start, tol_s=1e-8, checkpoint=path, stop_after=1)
    other = random_packing(64, 3, 0.3, "mono", seed=4)
    with pytest.raises(ValueError, match="different input packing"):
        calippso(other, checkpoint=path, stop_after=1)
    ds = xr.load_dataset(path)
    ds.attrs["bound_code"] = "jamflow 0.0.0 (another commit)"
    ds.to_netcdf(path)
    with pytest.raises(ValueError, match=r"different code: jamflow 0\.0\.0 \(another commit\) -> jamflow"):
        calippso(start, checkpoint=path, stop_after=1)


def test_max_iterations_may_change_on_resume(tmp_path):
    """The LP budget is left out of the binding, every option of the path is in it."""
    start = random_packing(64, 3, 0.3, "mono", seed=2)
    path = tmp_path / "ck.nc"
    with pytest.raises(ChainStopped):
        calippso(start, max_iterations=5, checkpoint=path, checkpoint_every=0.0, stop_after=2)
    run = json.loads(xr.load_dataset(path).attrs["bound_run"])
    assert "max_iterations" not in run
    assert {"tol_s", "tol_gamma", "solver", "solver_tol", "cutoff", "cutoff_near", "bound", "relax", "walls",
            "threads", "finish", "interior", "warm_engine", "first_lp", "require_isostatic"} <= set(run)
    assert calippso(start, max_iterations=200, checkpoint=path).converged


def test_stop_after_needs_a_checkpoint():
    start = random_packing(64, 3, 0.3, "mono", seed=2)
    with pytest.raises(ValueError, match="stop_after must be a positive LP count with a checkpoint"):
        calippso(start, stop_after=2)
    with pytest.raises(ValueError, match="checkpoint_every must be >= 0"):
        calippso(start, checkpoint="x.nc", checkpoint_every=-1.0)


def test_cli_stops_resumes_and_removes_the_checkpoint(tmp_path, capsys):
    start = tmp_path / "start.nc"
    write_packing(random_packing(32, 2, 0.5, "bi", seed=1), start)
    whole, out, ck = tmp_path / "whole.nc", tmp_path / "out.nc", tmp_path / "ck.nc"
    assert main(["calippso", str(start), str(whole), "--quiet"]) == 0
    assert main(["calippso", str(start), str(out), "--checkpoint", str(ck), "--stop-after", "3", "--quiet"]) == 3
    assert "stopped after 3 LP(s) of this run" in capsys.readouterr().err
    assert ck.exists() and not out.exists()
    assert main(["calippso", str(start), str(out), "--checkpoint", str(ck), "--checkpoint-every", "0"]) == 0
    assert f"resuming from {ck}" in capsys.readouterr().err
    assert not ck.exists()
    a, b = xr.load_dataset(whole), xr.load_dataset(out)
    for name in a.data_vars:
        if name not in CLOCKS:
            np.testing.assert_array_equal(b[name].values, a[name].values, err_msg=name)
    assert a.attrs["parameters"] == b.attrs["parameters"]


def test_cli_stop_after_without_checkpoint_is_a_usage_error(tmp_path, capsys):
    start = tmp_path / "start.nc"
    write_packing(random_packing(16, 2, 0.5, "mono", seed=1), start)
    assert main(["calippso", str(start), str(tmp_path / "out.nc"), "--stop-after", "2"]) == 2
    assert "--stop-after needs --checkpoint" in capsys.readouterr().err
