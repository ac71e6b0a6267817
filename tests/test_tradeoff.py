"""Speed/accuracy harness: the Pareto front, the recommendation rule, the CLI and the plot."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from jamflow.box import Box
from jamflow.cli import main
from jamflow.io import read_dataset
from jamflow.state.packing import Packing
from jamflow.tradeoff import STAGES, pareto_front, recommend
from jamflow.tradeoff.stages import _flow_compare


def test_pareto_front_against_brute_force(rng):
    t = rng.uniform(1, 10, 40)
    e = rng.uniform(0, 1, 40)
    e[5] = np.nan
    front = pareto_front(t, e)
    for k in range(40):
        dominated = any(
            np.isfinite(e[m]) and t[m] <= t[k] and e[m] <= e[k] and (t[m] < t[k] or e[m] < e[k]) for m in range(40)
        )
        assert front[k] == (np.isfinite(e[k]) and not dominated)
    # the fastest and the most accurate settings are always on the front
    ok = np.isfinite(e)
    assert front[np.flatnonzero(ok)[np.argmin(t[ok])]] and front[np.flatnonzero(ok)[np.argmin(e[ok])]]
    with pytest.raises(ValueError):
        pareto_front(t, e[:3])


def test_cli_sweep_recommendation_and_pareto_plot(tmp_path, capsys):
    out = tmp_path / "certify.nc"
    assert main(["tradeoff", "certify", str(out), "--quick", "--quiet"]) == 0
    ds = read_dataset(out)
    sw = STAGES["certify"]
    assert int(ds.is_reference.values[0]) == 1 and float(ds[sw.primary].values[0]) == 0.0
    assert ds.sizes["setting"] == 1 + len(sw.grid(True))
    assert np.all(ds.time.values > 0)
    # the recommended settings obey the rule: fastest meeting every limit of the preset
    for preset, label in recommend(ds).items():
        assert ds.attrs[f"recommended_{preset}"] == label
        ok = np.ones(ds.sizes["setting"], bool)
        for metric, limit in sw.thresholds[preset].items():
            ok &= ds[metric].values <= limit
        k = int(np.flatnonzero(ds.label.values == label)[0])
        assert ok[k] and ds.time.values[k] == ds.time.values[ok].min()
    png = tmp_path / "pareto.png"
    assert main(["plot", "pareto", str(out), str(png)]) == 0
    assert png.stat().st_size > 5_000 and png.with_suffix(".pdf").exists()


def test_unknown_stage_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["tradeoff", "nonsense", str(tmp_path / "x.nc")])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()


def test_shapes_stage_errors_and_grid():
    # phi_J error relative to the reference, N_1 error in modes, force from the packing's
    # max_force_sq; the grid always holds soft-jam's default tolerance at every P0
    from jamflow.box import Box
    from jamflow.state.bodies import ShapeTable
    from jamflow.state.packing import Packing
    from jamflow.tolerances import SOFT_FORCE_TOL
    from jamflow.tradeoff.stages import _shapes_compare

    lines = ShapeTable.from_shapes([dict(kind="circulo_line", vertices=[(-0.5, 0.0), (0.5, 0.0)], radius=0.2)])

    def packing(side: float, force_sq: float) -> Packing:
        return Packing(position=np.array([[0.5, 0.5], [2.0, 2.0]]), diameter=np.full(2, 1.4), box=Box.cubic(2, side),
                       orientation=np.zeros(2), shapes=lines, shape_index=np.zeros(2, dtype=np.int64),
                       attrs={"max_force_sq": force_sq})

    ref, out = packing(4.0, 1e-30), packing(4.0 * (1 - 1e-6), 1e-24)
    m = _shapes_compare((out, 3), (ref, 5))
    assert m["phi_J_error"] == pytest.approx((1 - 1e-6) ** -2 - 1, rel=1e-6)
    assert m["n_quartic_error"] == 2.0 and m["max_force"] == pytest.approx(1e-12)
    sw = STAGES["shapes"]
    for quick in (True, False):
        grid = sw.grid(quick)
        assert {g["pressure"] for g in grid if g["force_tol"] == SOFT_FORCE_TOL} == {g["pressure"] for g in grid}
        assert sw.reference(quick)["pressure"] < min(g["pressure"] for g in grid)


def test_chains_stage_keeps_the_asked_link_precision():
    # the swept knob reaches the model: each jammed packing's links, measured from its
    # positions, hold to the asked length_rtol, and the loose setting really is looser;
    # the packings are jammed at the stage's P0 and agree in phi_J to the loose precision
    from jamflow.tradeoff.stages import CHAINS_P0, _chains_compare

    sw = STAGES["chains"]
    start = sw.prepare(0, True)
    out = {}
    for rtol in (1e-6, 1e-14):
        p = sw.run(start, {"length_rtol": rtol, "force_tol": 1e-13}, True)
        links = p.links
        r = np.linalg.norm(p.box.displacement(p.position[links.i], p.position[links.j]), axis=1)
        err = np.abs(r - links.length) / links.length
        assert err.max() <= rtol and err.max() == pytest.approx(p.attrs["max_link_error"], rel=1e-6, abs=1e-15)
        assert abs(p.pressure - CHAINS_P0) <= 1e-6 * CHAINS_P0
        out[rtol] = (p, err.max())
    assert out[1e-6][1] > 1e3 * out[1e-14][1]
    m = _chains_compare(out[1e-6][0], out[1e-14][0])
    assert m["phi_J_error"] <= 1e-6 and m["one_minus_Q"] == 0.0
    assert m["max_link_error"] == pytest.approx(out[1e-6][1], rel=1e-6)


def test_flow_errors_separate_the_computed_values_from_the_step_spacing():
    # a run that computes the reference's stress exactly but records it at a tenth of the
    # steps: the held error counts the spacing, the error at its own steps is round-off;
    # an offset of 1e-6 in every computed value shows in both
    def run(strain: np.ndarray, offset: float = 0.0) -> SimpleNamespace:
        stress = 1.0 + 0.3 * np.sin(40.0 * strain) + offset
        empty = np.zeros(0, dtype=np.int64)
        series = xr.Dataset({"strain": ("step", strain), "shear_stress": ("step", stress),
                             "constraint_error": ("step", np.zeros_like(strain)),
                             "event_strain": ("event", np.zeros(0)), "event_i": ("event", empty),
                             "event_j": ("event", empty), "event_kind": ("event", empty)})
        final = Packing(position=np.array([[0.5, 0.5], [1.5, 0.5]]), diameter=np.ones(2), box=Box.cubic(2, 3.0),
                        contacts=np.array([[0, 1]]))
        return SimpleNamespace(series=series, final=final)

    ref = run(np.linspace(0.0, 0.1, 10_001))
    sparse = _flow_compare(run(np.linspace(0.0, 0.1, 1_001)), ref)
    assert sparse["error"] > 1e-5 and sparse["error_at_steps"] < 1e-12 and sparse["p90_error_at_steps"] < 1e-12
    shifted = _flow_compare(run(np.linspace(0.0, 0.1, 10_001), 1e-6), ref)
    scale = float(np.mean(np.abs(ref.series.shear_stress.values)))  # errors are relative to <|sigma_ref|>
    assert shifted["error_at_steps"] == pytest.approx(1e-6 / scale, rel=1e-6)
    assert shifted["error"] == pytest.approx(1e-6 / scale, rel=1e-6)
    assert shifted["one_minus_Q"] == 0.0 and shifted["event_disagreement"] == 0.0
