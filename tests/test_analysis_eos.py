"""Equations of state and the LS extrapolation of phi_J (CALiPPSO paper Eq. 15, Table I)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from test_plots import check_figure

from jamflow import plots
from jamflow.analysis.eos import (
    carnahan_starling,
    fit_jamming_density,
    glass_pressure,
    jamming_table,
)
from jamflow.io import read_dataset, write_dataset


def eos_run(phi_j: float, d: int, rng, kappa: float, noise: float = 0.0) -> xr.Dataset:
    """A synthetic compression obeying Eq. 15 above p = 50, with relative pressure noise."""
    phi = phi_j * (1.0 - np.logspace(-12, -0.5, 400)[::-1])
    p = glass_pressure(phi, d, phi_j) * (1.0 + noise * rng.standard_normal(phi.size))
    return xr.Dataset({"packing_fraction": ("record", phi), "pressure": ("record", p)}, attrs={"d": d, "kappa": kappa})


def series(phi_js: list[float], kappa: float) -> xr.Dataset:
    return xr.Dataset({"phi_J": ("p_target", np.array(phi_js))}, coords={"p_target": [1e3, 1e5]},
                      attrs={"kappa": kappa})


def test_carnahan_starling_virial_expansion():
    # Z_CS = 1 + 4 phi + 10 phi^2 + 18 phi^3 + ...; the exact B2, B3 give 4 and 10
    phi = np.array([1e-4, 1e-3, 1e-2])
    assert np.allclose(carnahan_starling(phi), 1 + 4 * phi + 10 * phi**2 + 18 * phi**3, rtol=0, atol=30 * phi**4)
    assert carnahan_starling(0.0) == 1.0


@pytest.mark.parametrize("d", [2, 3, 5])
def test_fit_recovers_the_jamming_density(d, rng):
    ds = eos_run(0.6431, d, rng, 1e-5)
    exact = fit_jamming_density(ds["packing_fraction"], ds["pressure"], d)
    assert exact.phi_j == pytest.approx(0.6431, rel=1e-12) and exact.phi_j_err < 1e-12
    assert exact.prefactor == pytest.approx(d, rel=1e-6)
    noisy = eos_run(0.6431, d, rng, 1e-5, noise=0.01)
    fit = fit_jamming_density(noisy["packing_fraction"], noisy["pressure"], d, p_min=1e5, p_max=1e11)
    assert abs(fit.phi_j - 0.6431) < 5 * fit.phi_j_err + 1e-12
    assert fit.n_points == int(np.sum((noisy["pressure"] >= 1e5) & (noisy["pressure"] <= 1e11)))


def test_fit_refuses_an_unreached_window(rng):
    ds = eos_run(0.64, 3, rng, 1e-5)
    low = ds["pressure"].values < 1e4
    with pytest.raises(ValueError, match="need at least 3"):
        fit_jamming_density(ds["packing_fraction"].values[low], ds["pressure"].values[low], 3, p_min=1e5)
    with pytest.raises(ValueError, match="empty pressure window"):
        fit_jamming_density([0.6], [1e6], 3, p_min=1e6, p_max=1e5)


def test_table_averages_per_growth_rate(rng):
    truth = {1e-4: [0.6427, 0.6429, 0.6425], 1e-5: [0.6433, 0.6431, 0.6435]}
    runs, eos = [], []
    for kappa, phis in truth.items():
        for phi_j in phis:
            runs.append(series([phi_j - 2e-5, phi_j], kappa))
            eos.append(eos_run(phi_j, 3, rng, kappa))
    ds = jamming_table(runs, eos)
    assert list(ds["kappa"].values) == [1e-5, 1e-4]
    for a, kappa in enumerate(ds["kappa"].values):
        phis = np.array(truth[kappa])
        assert ds["phi_J_LS"].values[a] == pytest.approx(phis.mean(), rel=1e-12)
        assert ds["phi_J_LS_err"].values[a] == pytest.approx(phis.std(ddof=1) / np.sqrt(3), rel=1e-9)
        assert np.allclose(ds["difference"].values[a], [-2e-5, 0.0], atol=1e-12)
        assert ds["n_samples"].values[a] == 3
    with pytest.raises(ValueError, match="paired with an LS run"):
        jamming_table([runs[0]], [eos[-1]])
    with pytest.raises(ValueError, match="growth rate"):
        jamming_table([runs[0].drop_attrs()], [eos[0]])


def test_table_cli_and_figures(tmp_path, rng, capsys):
    from jamflow.cli import main

    paths = []
    for k, (kappa, phi_j) in enumerate([(1e-4, 0.6427), (1e-4, 0.6429), (1e-5, 0.6433)]):
        write_dataset(series([phi_j, phi_j], kappa), tmp_path / f"s{k}.nc")
        write_dataset(eos_run(phi_j, 3, rng, kappa, noise=1e-3), tmp_path / f"e{k}.nc")
        paths.append(k)
    out = tmp_path / "table.nc"
    assert main(["jamming-table", *(str(tmp_path / f"s{k}.nc") for k in paths), str(out),
                 "--eos", *(str(tmp_path / f"e{k}.nc") for k in paths)]) == 0
    assert "| 1e-05 | 0.6433" in capsys.readouterr().out
    ds = read_dataset(out)
    check_figure(plots.plot_jamming_table(ds), tmp_path / "table.png")
    check_figure(plots.plot_eos([read_dataset(tmp_path / f"e{k}.nc") for k in paths]), tmp_path / "eos.png")
    assert main(["plot", "eos", str(tmp_path / "e0.nc"), str(tmp_path / "e1.nc"), str(tmp_path / "eos2.png")]) == 0
