"""Reuss-Voigt weighted moduli of cemented packings against n_l / N (chains paper Fig. 5)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from jamflow.chains.averages import moduli_against_links, weighted_modulus


def _moduli(n_cemented: int, bulk: tuple[float, float], shear: tuple[float, float], n: int = 100,
            n_unstable: int = 0) -> xr.Dataset:
    return xr.Dataset({"bulk_voigt": ((), bulk[0]), "bulk_reuss": ((), bulk[1]),
                       "shear_voigt": ((), shear[0]), "shear_reuss": ((), shear[1])},
                      attrs={"N": n, "n_cemented": n_cemented, "d": 3, "n_unstable": n_unstable})


def test_weighted_average_favours_the_packing_with_tighter_bounds():
    """Two packings, Hill values 1.5 (spread 1) and 3 (spread 0.5): weights 1/s^2 with s = spread / sqrt 12."""
    value, se, n_inf = weighted_modulus(np.array([2.0, 3.25]), np.array([1.0, 2.75]))
    w = np.array([1.0, 4.0])  # ratio of 1 / spread^2
    want = np.sum(w * [1.5, 3.0]) / w.sum()
    assert value == pytest.approx(want, rel=1e-14) and n_inf == 0
    assert se == pytest.approx(np.sqrt(np.sum(w**2 * (np.array([1.5, 3.0]) - want) ** 2)) / w.sum(), rel=1e-14)
    # identical packings: the Hill value, no scatter
    value, se, _ = weighted_modulus(np.full(4, 2.0), np.full(4, 1.0))
    assert value == pytest.approx(1.5, rel=1e-15) and se <= 1e-15


def test_infinite_moduli_are_counted_not_averaged_and_groups_follow_links_per_sphere():
    table = moduli_against_links([_moduli(0, (2, 1), (1, 0.5)), _moduli(0, (2, 1), (1, 0.5)),
                                  _moduli(50, (4, 3), (np.inf, 2.0)), _moduli(50, (4, 3), (3.0, 2.0))])
    np.testing.assert_array_equal(table.links_per_sphere.values, [0.0, 0.5])
    np.testing.assert_array_equal(table.n_packings.values, [2, 2])
    np.testing.assert_array_equal(table.shear_infinite.values, [0, 1])
    assert table.shear_weighted.values[1] == pytest.approx(2.5) and np.isnan(table.shear_se.values[1])
    assert table.bulk_weighted.values[0] == pytest.approx(1.5)
    every = moduli_against_links([_moduli(90, (np.inf, np.inf), (np.inf, np.inf))])
    assert np.isinf(every.shear_weighted.values[0]) and int(every.shear_infinite.values[0]) == 1


def test_unstable_packings_are_counted_and_left_out_of_the_averages():
    """A negative compliance eigenvalue: no Reuss-Voigt bracket, so the packing is not averaged."""
    table = moduli_against_links([_moduli(0, (2, 1), (1, 0.5)), _moduli(0, (0.5, -3.0), (-0.2, -1.0), n_unstable=1)])
    assert int(table.n_packings.values[0]) == 2 and int(table.n_unstable.values[0]) == 1
    assert table.shear_weighted.values[0] == pytest.approx(0.75) and table.bulk_weighted.values[0] == pytest.approx(1.5)
    assert table.shear_reuss_mean.values[0] == pytest.approx(0.5)


def test_the_figure_draws_infinite_moduli_off_scale_with_their_counts():
    """An infinite modulus has no height: its marker sits above the axes (axes fraction > 1), labelled k/n."""
    from jamflow.plots import plot_chains_moduli

    table = moduli_against_links([_moduli(0, (2, 1), (1, 0.5)), _moduli(0, (2, 1), (1, 0.5)),
                                  _moduli(50, (4, 3), (np.inf, np.inf)), _moduli(50, (4, 3), (3.0, 2.0)),
                                  _moduli(90, (np.inf, np.inf), (np.inf, np.inf))])
    fig = plot_chains_moduli(table)
    shear = fig.axes[0]
    markers = [line for line in shear.lines if line.get_marker() == "^"]
    assert markers and all(np.all(line.get_ydata() > 1.0) for line in markers)
    assert all(line.get_transform() != shear.transData for line in markers)
    assert sorted(t.get_text() for t in shear.texts) == ["inf x 1/1", "inf x 1/2"]
    # the finite points stay on the data scale, below the top of the axes
    finite = shear.get_ylim()[1]
    assert np.isfinite(finite) and finite < 10
