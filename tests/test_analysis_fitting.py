"""Power-law exponents with statistical and systematic errors (jamflow.analysis.fitting)."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.analysis.fitting import (
    BREAK_Z,
    MIN_IN_WINDOW,
    analyse_exponent,
    bootstrap_error,
    density_prefactor,
    mle_exponent,
)


def power_law(rng: np.random.Generator, alpha: float, lo: float, hi: float, size: int) -> np.ndarray:
    """Samples with density proportional to x^alpha on [lo, hi] (inverse CDF)."""
    b = alpha + 1.0
    return (lo**b + rng.random(size) * (hi**b - lo**b)) ** (1.0 / b)


def test_mle_recovers_exponent_and_its_fisher_error_is_calibrated(rng):
    # 200 repetitions: the asymptotic error must cover the truth ~68 % of the time at 1 sigma
    hits = []
    for _ in range(200):
        fit = mle_exponent(power_law(rng, -0.41269, 1e-8, 1e-1, 2000), 1e-7, 1e-2)
        hits.append(abs(fit.alpha + 0.41269) < fit.alpha_err)
    assert 0.60 < np.mean(hits) < 0.76


def test_mle_ignores_samples_outside_the_window(rng):
    # a plateau below the window and a cut-off above it must not bias the window exponent
    inside = power_law(rng, 0.42, 1e-3, 1e-1, 20000)
    outside = np.concatenate([rng.uniform(0, 1e-3, 50000), rng.uniform(0.1, 5.0, 50000)])
    a = mle_exponent(np.concatenate([inside, outside]), 1e-3, 1e-1)
    assert a.n == len(inside)
    assert abs(a.alpha - 0.42) < 3 * a.alpha_err


def test_scan_on_noisy_power_law_contains_exponent_within_combined_error(rng):
    # 6 "packings" of 1500 samples: the reported gamma lies within its combined error
    truth = -0.41269
    for _ in range(5):
        samples = [power_law(rng, truth, 1e-9, 1e-1, 1500) for _ in range(6)]
        res = analyse_exponent(samples, 1e-8, 1e-2, n_boot=100, seed=1)
        assert not res.break_detected and np.isnan(res.break_at) and res.x_max == 1e-2
        assert res.stat > 0 and res.sys > 0 and len(res.scan_alpha) >= 10
        assert abs(res.alpha - truth) < 2.0 * res.total
        # bootstrap and Fisher errors are two estimates of the same scatter
        fisher = mle_exponent(np.concatenate(samples), 1e-8, 1e-2).alpha_err
        assert 0.6 < res.stat / fisher < 1.6


def test_scan_flags_a_broken_power_law_and_stops_the_window_below_the_break(rng):
    # p(x) ~ x^-0.4 below 1e-4, ~ x^+0.5 above, 4000 samples on each side
    lo = power_law(rng, -0.4, 1e-9, 1e-4, 4000)
    hi = power_law(rng, 0.5, 1e-4, 1e-1, 4000)
    res = analyse_exponent([np.concatenate([lo, hi])], 1e-8, 1e-1, n_boot=50)
    print(f"break z = {res.break_z:.1f} at {res.break_at:.2g}, window [{res.x_min:g}, {res.x_max:.3g}], "
          f"alpha = {res.alpha:.3f} +- {res.total:.3f}")
    assert res.break_detected and res.break_z > BREAK_Z
    assert 1e-5 <= res.break_at <= 1e-3
    assert res.x_max <= 1e-3
    assert abs(res.alpha + 0.4) < 3 * res.total
    # the same samples fitted blindly on the whole range give a wrong exponent
    assert abs(mle_exponent(np.concatenate([lo, hi]), 1e-8, 1e-1).alpha + 0.4) > 0.2


def test_refuses_with_reason_below_the_minimum_count(rng):
    res = analyse_exponent([power_law(rng, 0.42, 1e-3, 1.0, 300)], 1e-3, 1e-1)
    n = int(np.sum(res.n_in_window))
    assert n < MIN_IN_WINDOW
    assert np.isnan(res.alpha) and np.isnan(res.stat) and np.isnan(res.total)
    assert f"minimum {MIN_IN_WINDOW}" in res.reason


@pytest.mark.parametrize("lo, hi", [(1e-2, 1e-5), (1e-3, 1e-3), (0.0, 1e-2), (-1e-3, 1e-2)])
def test_invalid_window_is_an_error(lo, hi):
    with pytest.raises(ValueError, match="fit-min < fit-max"):
        analyse_exponent([np.linspace(1e-6, 1e-1, 100)], lo, hi)


def test_bootstrap_is_seeded(rng):
    samples = [power_law(rng, -0.4, 1e-8, 1e-1, 500) for _ in range(3)]
    assert bootstrap_error(samples, 1e-7, 1e-2, 50, seed=3) == bootstrap_error(samples, 1e-7, 1e-2, 50, seed=3)
    assert bootstrap_error(samples, 1e-7, 1e-2, 50, seed=3) != bootstrap_error(samples, 1e-7, 1e-2, 50, seed=4)


@pytest.mark.parametrize("alpha", [-0.41269, -1.0, 0.42311])
def test_density_prefactor_integrates_to_mass(alpha):
    c = density_prefactor(alpha, 1e-4, 1e-1, 2.5)
    x = np.logspace(-4, -1, 200001)
    y = c * x**alpha
    assert np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)) == pytest.approx(2.5, rel=1e-6)
