"""Gap distribution p(h): histogram normalisation, power-law fit, contact exclusion, real LS data."""

from __future__ import annotations

import numpy as np
import pytest
from ls_data import ls_dat

from jamflow.analysis.fitting import FitWarning
from jamflow.analysis.gaps import (
    MEAN_FIELD_GAP_EXPONENT,
    gap_distribution,
    gap_histogram,
    log_bin_edges,
    non_contact_gaps,
)
from jamflow.box import Box
from jamflow.io import read_dataset
from jamflow.io.formats import read_dat
from jamflow.state.packing import Packing, near_pairs


def power_law_gaps(rng: np.random.Generator, gamma: float, lo: float, hi: float, size: int) -> np.ndarray:
    """Draw h with density proportional to h^-gamma on [lo, hi] by inverting the CDF."""
    a, b = lo ** (1.0 - gamma), hi ** (1.0 - gamma)
    return (a + rng.random(size) * (b - a)) ** (1.0 / (1.0 - gamma))


def triangular(nx: int, ny: int, spacing: float = 1.0) -> tuple[np.ndarray, Box]:
    x = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2] for j in range(ny) for i in range(nx)]) * spacing
    return x + 0.1 * spacing, Box.orthogonal([nx * spacing, ny * spacing * np.sqrt(3) / 2])


def test_log_bin_edges_cover_range_exactly():
    e = log_bin_edges(1e-13, 0.1, 5)
    assert e[0] == pytest.approx(1e-13) and e[-1] == pytest.approx(0.1)
    assert len(e) - 1 == 60
    assert np.allclose(np.diff(np.log10(e)), 0.2)


def test_power_law_exponent_recovered_within_reported_error(rng):
    gaps = [power_law_gaps(rng, MEAN_FIELD_GAP_EXPONENT, 1e-9, 1e-1, 4000) for _ in range(8)]
    ds, fit = gap_histogram(gaps, [1000] * 8, max_gap=0.1, min_gap=1e-10, bins_per_decade=4,
                            fit_min=1e-8, fit_max=5e-2)
    print("gamma fit", fit["fit_exponent"], "+-", fit["fit_exponent_stat"], "(stat) +-", fit["fit_exponent_sys"], "(sys)")
    assert abs(fit["fit_exponent"] - MEAN_FIELD_GAP_EXPONENT) < 2.0 * fit["fit_exponent_err"]
    assert fit["fit_exponent_stat"] < 0.02  # 32 000 gaps over 7 decades pin gamma to about a percent


def test_reported_fit_error_is_calibrated(rng):
    # over independent repetitions about 95 % of fits should land within 2 sigma
    inside = 0
    reps = 40
    for _ in range(reps):
        h = power_law_gaps(rng, 0.3, 1e-7, 1e-1, 3000)
        _, fit = gap_histogram([h], [500], max_gap=0.1, min_gap=1e-7, bins_per_decade=3, fit_min=1e-7, fit_max=0.1)
        inside += abs(fit["fit_exponent"] - 0.3) < 2.0 * fit["fit_exponent_stat"]
    assert inside >= 0.8 * reps


def test_density_integrates_to_neighbours_per_particle(rng):
    n = 200
    samples = [rng.uniform(1e-6, 0.05, 700), rng.uniform(1e-6, 0.05, 500)]
    ds, _ = gap_histogram(samples, [n, n], max_gap=0.1, min_gap=1e-7, bins_per_decade=6)
    width = ds["h_upper"].values - ds["h_lower"].values
    per_particle = np.mean([2.0 * len(s) / n for s in samples])
    assert np.sum(ds["gap_density"].values * width) == pytest.approx(per_particle, rel=1e-12)
    assert np.sum(ds["gap_pdf"].values * width) == pytest.approx(1.0, rel=1e-12)


def test_sample_error_is_standard_error_of_the_mean(rng):
    samples = [rng.uniform(1e-3, 0.1, 400) for _ in range(5)]
    ds, fit = gap_histogram(samples, [100] * 5, max_gap=0.1, min_gap=1e-3, bins_per_decade=2)
    width = ds["h_upper"].values - ds["h_lower"].values
    per = 2.0 * ds["count"].values / (100 * width)
    assert np.allclose(ds["gap_density_err"].values, per.std(axis=0, ddof=1) / np.sqrt(5))
    assert fit["error_method"].startswith("sample standard error")


def test_fit_refuses_too_few_gaps_in_window(rng):
    # 30 gaps: below the stated minimum, gamma is NaN with the reason in the summary
    h = power_law_gaps(rng, 0.4, 1e-6, 1e-2, 30)
    with pytest.warns(FitWarning, match="fit refused: 30 samples") as caught:  # in API use, not only a CLI line
        _, fit = gap_histogram([h], [100], fit_min=1e-6, fit_max=1e-2)
    assert np.isnan(fit["fit_exponent"]) and "fewer than the minimum" in fit["fit_exponent_reason"]
    assert str(caught[0].message) == fit["fit_exponent_reason"]


def test_explicit_contacts_are_excluded_and_other_gaps_kept():
    x, box = triangular(8, 8)
    D = 1.0 / (1.0 + 1e-4)  # nearest neighbours at gap h = 1e-4
    full = Packing(x, np.full(len(x), D), box)
    pairs, h = near_pairs(full, 1e-3)
    assert np.allclose(h, 1e-4) and len(h) == 3 * 64
    contacts = np.stack([pairs.i, pairs.j], axis=1)[::2]
    with_contacts = full.evolve(contacts=contacts)
    kept, _ = non_contact_gaps(with_contacts, 1e-3, include_rattlers=True)
    assert len(kept) == len(h) - len(contacts)
    # without stored contacts the gap tolerance decides: none below 1e-5, all below 1e-3
    assert len(non_contact_gaps(full, 1e-3, gap_tol=1e-5, include_rattlers=True)[0]) == len(h)
    assert len(non_contact_gaps(full, 1e-3, gap_tol=1e-3)[0]) == 0




@pytest.mark.parametrize("d", [4, 5])
def test_ls_snapshot_shows_plateau_and_mean_field_regime(d):
    # d = 3 is at lower pressure: its plateau reaches 1e-6 and the power law is hidden
    packing = read_dat(ls_dat(d))
    # an LS snapshot has no contacts: count every positive gap (gap_tol = 0)
    ds = gap_distribution([packing], max_gap=0.1, min_gap=1e-13, bins_per_decade=2,
                          fit_min=1e-4, fit_max=3e-2, gap_tol=0.0, include_rattlers=True)
    h, p = ds["h"].values, ds["gap_density"].values
    smallest = h[np.flatnonzero(p > 0)[0]]
    print(f"d={d}: smallest populated bin h={smallest:.2e}; gamma = {ds.attrs['fit_exponent']:.3f} "
          f"+- {ds.attrs['fit_exponent_err']:.3f}")
    # gaps reach down to 1e-12..1e-10 at finite pressure, never to round-off
    assert 1e-13 < smallest < 1e-10
    # regime (i): plateau for h << 1/p, flat within a factor 3 over 1e-10..1e-8
    plateau = p[(h > 1e-10) & (h < 1e-8)]
    assert plateau.min() > 0 and plateau.max() / plateau.min() < 3.0
    # regime (ii): p(h) ~ h^-gamma with gamma near the mean-field value for 1/p << h
    assert abs(ds.attrs["fit_exponent"] - MEAN_FIELD_GAP_EXPONENT) < 0.1


def test_gaps_cli_writes_dataset(tmp_path, calippso_ls_file):
    from jamflow.cli import main

    out = tmp_path / "gaps.nc"
    assert main(["gaps", str(calippso_ls_file), str(out), "--gap-tol", "0", "--max-gap", "0.05",
                 "--fit-min", "1e-4", "--fit-max", "3e-2", "--include-rattlers", "--quiet"]) == 0
    ds = read_dataset(out)
    for v in ds.data_vars.values():
        assert "units" in v.attrs and "long_name" in v.attrs
    for key in ("fit_exponent", "fit_exponent_err", "fit_min", "fit_max", "git_sha", "parameters"):
        assert key in ds.attrs


def test_planted_rattlers_pairs_are_excluded_by_default():
    # triangular lattice at nearest-neighbour gap 1e-4; every nearest pair is a contact except
    # those of two planted particles, which keep no contact at all and are rattlers
    x, box = triangular(8, 8)
    full = Packing(x, np.full(len(x), 1.0 / (1.0 + 1e-4)), box)
    pairs, h = near_pairs(full, 1e-3)
    planted = [9, 42]
    loose = np.isin(pairs.i, planted) | np.isin(pairs.j, planted)
    assert loose.sum() == 12  # 6 neighbours each, not neighbours of each other
    packing = full.evolve(contacts=np.stack([pairs.i, pairs.j], axis=1)[~loose])
    kept, n_counted = non_contact_gaps(packing, 1e-3)
    assert len(kept) == 0 and n_counted == 64 - 2
    with_rattlers, n_all = non_contact_gaps(packing, 1e-3, include_rattlers=True)
    assert len(with_rattlers) == 12 and n_all == 64
    assert np.allclose(with_rattlers, 1e-4)
    ds = gap_distribution([packing], max_gap=1e-3, min_gap=1e-6, fit_min=1e-6, fit_max=1e-3)
    assert int(ds["count"].sum()) == 0 and ds.attrs["rattlers_included"] == 0
    ds = gap_distribution([packing], max_gap=1e-3, min_gap=1e-6, fit_min=1e-6, fit_max=1e-3, include_rattlers=True)
    assert int(ds["count"].sum()) == 12 and ds.attrs["rattlers_included"] == 1


def test_rattler_exclusion_without_a_contact_network_is_an_error():
    x, box = triangular(8, 8)
    snapshot = Packing(x, np.full(len(x), 1.0 / (1.0 + 1e-4)), box)  # no contacts, all gaps 1e-4
    with pytest.raises(ValueError, match="include-rattlers"):
        non_contact_gaps(snapshot, 1e-3, gap_tol=0.0)


@pytest.mark.parametrize("command", ["gaps", "forces"])
def test_inverted_fit_window_is_a_one_line_error(tmp_path, capsys, command):
    from jamflow.cli import main
    from jamflow.io import write_packing

    x, box = triangular(6, 6)
    packing = tmp_path / "p.nc"
    write_packing(Packing(x, np.full(len(x), 0.99), box), packing)
    out = tmp_path / "out.nc"
    assert main([command, str(packing), str(out), "--fit-min", "1e-2", "--fit-max", "1e-5", "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--fit-min/--fit-max" in err[0] and "fit-min < fit-max" in err[0]
    assert not out.exists()


def test_a_soft_packing_s_pressure_does_not_move_the_fit_window():
    """The 1/p plateau is of LS snapshots (hard spheres at a reduced pressure); a soft packing at
    P0 = 1e-3 (an energy density) keeps the window it was given, where 1/P0 = 1e3 would lie above it."""
    from pathlib import Path

    from jamflow.io import read_packing

    soft = read_packing(Path(__file__).parent / "data" / "bodies" / "spheres_soft.nc", None)
    assert soft.protocol.endswith(">soft") and soft.pressure == pytest.approx(1e-3)
    ds = gap_distribution([soft], fit_min=1e-5, fit_max=1e-2)
    assert ds.attrs["fit_min"] == 1e-5 and ds.attrs["fit_max"] == 1e-2
