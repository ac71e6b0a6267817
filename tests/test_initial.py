"""Random non-overlapping initial configurations (RSA) in d = 2..5."""

from __future__ import annotations

from math import gamma, pi

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.protocols.initial import UnreachableError, draw_diameters, random_packing

#: Packing fractions comfortably below RSA saturation in each dimension.
PHI = {2: 0.45, 3: 0.3, 4: 0.18, 5: 0.1}


def _phi(D: np.ndarray, d: int) -> float:
    """Sum of ball volumes in the unit box, written out independently."""
    return float(np.sum(pi ** (d / 2) / gamma(d / 2 + 1) * (D / 2) ** d))


def _min_relative_gap(x: np.ndarray, D: np.ndarray) -> float:
    """min over all pairs of r / sigma - 1 in the unit periodic box (brute force)."""
    i, j = np.triu_indices(len(x), 1)
    dx = x[j] - x[i]
    dx -= np.round(dx)
    return float(np.min(np.linalg.norm(dx, axis=1) / (0.5 * (D[i] + D[j])) - 1.0))


@pytest.mark.parametrize("d", [2, 3, 4, 5])
@pytest.mark.parametrize("dispersity", ["mono", "bi", "poly", "lognormal"])
def test_random_packing_is_exact_and_non_overlapping(d: int, dispersity: str) -> None:
    n = 256
    p = random_packing(n, d, PHI[d], dispersity, seed=11, width=0.2)
    assert (p.n, p.d) == (n, d)
    assert p.box == Box.cubic(d, 1.0)
    assert _phi(p.diameter, d) == pytest.approx(PHI[d], rel=1e-13)
    assert p.packing_fraction == pytest.approx(PHI[d], rel=1e-13)
    assert np.all((p.position >= 0.0) & (p.position < 1.0))
    assert _min_relative_gap(p.position, p.diameter) > 0.0
    p.validate(overlap_tol=0.0)
    assert p.protocol == "random" and p.seed == 11
    assert p.parameters["phi"] == PHI[d] and p.parameters["dispersity"] == dispersity
    if dispersity == "mono":
        assert np.ptp(p.diameter) == 0.0


@pytest.mark.parametrize("dispersity", ["mono", "bi", "lognormal"])
def test_same_seed_same_numbers_different_seed_different(dispersity: str) -> None:
    a = random_packing(100, 3, 0.2, dispersity, seed=5)
    b = random_packing(100, 3, 0.2, dispersity, seed=5)
    c = random_packing(100, 3, 0.2, dispersity, seed=6)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.diameter, b.diameter)
    assert not np.array_equal(a.position, c.position)
    if dispersity != "mono":
        assert not np.array_equal(a.diameter, c.diameter)


@pytest.mark.parametrize("n, ratio, fraction", [(200, 1.4, 0.5), (101, 1.2, 0.3), (64, 2.0, 0.75)])
def test_bidisperse_counts_and_ratio(n: int, ratio: float, fraction: float) -> None:
    p = random_packing(n, 2, 0.3, "bi", seed=1, ratio=ratio, fraction=fraction)
    small, large = np.unique(p.diameter)
    assert large / small == pytest.approx(ratio, rel=1e-14)
    assert np.sum(p.diameter == small) == round(fraction * n)
    assert np.sum(p.diameter == large) == n - round(fraction * n)
    # sizes are shuffled, not sorted by index
    assert not np.all(np.diff(p.diameter) >= 0)


def test_bidisperse_defaults_are_one_to_one_point_four_fifty_fifty() -> None:
    p = random_packing(100, 2, 0.3, "bi", seed=2)
    small, large = np.unique(p.diameter)
    assert large / small == pytest.approx(1.4, rel=1e-14)
    assert np.sum(p.diameter == small) == 50


def test_polydisperse_distributions() -> None:
    rng = np.random.default_rng(0)
    width = 0.15
    uniform = draw_diameters(20_000, "poly", rng, width=width)
    assert uniform.min() >= 1 - width and uniform.max() <= 1 + width
    # uniform on [1 - w, 1 + w]: mean 1, standard deviation w / sqrt(3)
    assert uniform.mean() == pytest.approx(1.0, abs=5 * width / np.sqrt(3 * 20_000))
    assert uniform.std() == pytest.approx(width / np.sqrt(3), rel=0.03)
    log = np.log(draw_diameters(20_000, "lognormal", rng, width=width))
    assert log.std() == pytest.approx(width, rel=0.03)
    # the mean diameter is 1: exp(mu + s^2 / 2) with mu = -s^2 / 2
    assert np.exp(log).mean() == pytest.approx(1.0, abs=5 * width / np.sqrt(20_000))
    # zero width is monodisperse
    np.testing.assert_array_equal(draw_diameters(10, "poly", rng, width=0.0), 1.0)
    np.testing.assert_array_equal(draw_diameters(10, "lognormal", rng, width=0.0), 1.0)


@pytest.mark.parametrize("d, phi", [(2, 0.7), (3, 0.5), (4, 0.4), (5, 0.3)])
def test_unreachable_phi_is_a_clear_error(d: int, phi: float) -> None:
    with pytest.raises(UnreachableError, match=rf"phi={phi}.*RSA saturates") as err:
        random_packing(400, d, phi, seed=0, max_trials_per_particle=50)
    assert isinstance(err.value, ValueError)


def test_unreachable_phi_with_the_default_trial_budget() -> None:
    with pytest.raises(UnreachableError, match=r"placed only \d+ of 100 spheres at phi=0.5 in d=3"):
        random_packing(100, 3, 0.5, seed=1)


def test_too_few_particles_for_the_box() -> None:
    with pytest.raises(UnreachableError, match="half the box"):
        random_packing(2, 3, 0.3, seed=0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(d=1), "d must be"),
        (dict(phi=0.0), "phi"),
        (dict(phi=1.2), "phi"),
        (dict(n=0), "n must be"),
        (dict(dispersity="gaussian"), "unknown dispersity"),
        (dict(dispersity="bi", ratio=0.8), "ratio"),
        (dict(dispersity="bi", fraction=1.0), "fraction"),
        (dict(dispersity="poly", width=1.0), "width"),
        (dict(dispersity="lognormal", width=-0.1), "width"),
    ],
)
def test_bad_arguments_raise(kwargs: dict, message: str) -> None:
    args = dict(n=50, d=2, phi=0.2, seed=0) | kwargs
    with pytest.raises(ValueError, match=message):
        random_packing(**args)


def test_bidisperse_species_spread_has_the_requested_relative_std():
    rng = np.random.default_rng(5)
    D = draw_diameters(20000, "bi", rng, ratio=1.4, fraction=0.5, species_spread=0.03)
    small = D < np.sqrt(1.4)
    assert small.sum() == 10000
    for species, mean in ((D[small], 1.0), (D[~small], 1.4)):
        assert abs(species.mean() / mean - 1) < 1e-3
        assert abs(species.std() / species.mean() - 0.03) < 1e-3
    with pytest.raises(ValueError):
        draw_diameters(10, "bi", rng, species_spread=0.6)


def test_zero_species_spread_reproduces_plain_bidisperse():
    a = draw_diameters(100, "bi", np.random.default_rng(3))
    b = draw_diameters(100, "bi", np.random.default_rng(3), species_spread=0.0)
    assert np.array_equal(a, b)
