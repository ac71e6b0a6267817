"""Speed/accuracy harness: the Pareto front, the recommendation rule, the CLI and the plot."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.cli import main
from jamflow.io import read_dataset
from jamflow.tradeoff import STAGES, pareto_front, recommend


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
