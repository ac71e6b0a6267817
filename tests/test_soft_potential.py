"""Soft potential: forces, stress and Hessian against numerical derivatives; Verlet list."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.models.spheres.hessian import hessian
from jamflow.models.spheres.potential import (
    PowerLawPotential,
    evaluate,
    overlapping_pairs,
)
from jamflow.neighbors.verlet import NeighborList
from jamflow.protocols.quasistatic import affine_shear


def _overlapping_config(d: int, rng: np.random.Generator, gamma: float = 0.3):
    """Random centres in a Lees-Edwards box, polydisperse, with a dozen or more overlaps."""
    n = {2: 24, 3: 30, 4: 40, 5: 60}[d]
    L = 4.0
    box = Box.lees_edwards([L] * d, gamma)
    x = box.to_cartesian(rng.random((n, d)))
    D = rng.uniform(0.9, 1.4, n)
    return x, box, D


def _energy(x, box, D, pot, nl=None):
    return evaluate(x, box, D, pot, nl).energy


@pytest.mark.parametrize("d", [2, 3, 4, 5])
@pytest.mark.parametrize("w", [2.0, 2.5])
def test_forces_are_minus_numerical_gradient(d, w, rng):
    pot = PowerLawPotential(epsilon=1.7, exponent=w)
    x, box, D = _overlapping_config(d, rng)
    ev = evaluate(x, box, D, pot)
    assert ev.n_contacts >= 5
    nl = NeighborList(D)  # one list for all the tiny displacements below
    h = 1e-6
    grad = np.zeros_like(x)
    for i in range(len(x)):
        for a in range(d):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += h
            xm[i, a] -= h
            grad[i, a] = (_energy(xp, box, D, pot, nl) - _energy(xm, box, D, pot, nl)) / (2 * h)
    np.testing.assert_allclose(ev.force, -grad, atol=1e-7 * np.abs(grad).max())


@pytest.mark.parametrize("d", [2, 3, 5])
def test_stress_is_strain_derivative_of_energy(d, rng):
    """sigma_xy = (1/V) dU/dgamma and P = -dU/dV under affine deformation."""
    pot = PowerLawPotential()
    x, box, D = _overlapping_config(d, rng, gamma=0.1)
    ev = evaluate(x, box, D, pot)
    g0, h = box.shear_strain, 1e-6
    up = _energy(*affine_shear(x, box, g0 + h), D, pot)
    dn = _energy(*affine_shear(x, box, g0 - h), D, pot)
    assert ev.shear_stress == pytest.approx((up - dn) / (2 * h) / box.volume, rel=1e-6)
    f = 1e-6
    up = _energy(x * (1 + f), box.scaled(1 + f), D, pot)
    dn = _energy(x * (1 - f), box.scaled(1 - f), D, pot)
    dV = box.volume * ((1 + f) ** d - (1 - f) ** d)
    assert ev.pressure == pytest.approx(-(up - dn) / dV, rel=1e-6)
    assert ev.pressure == pytest.approx(-np.trace(ev.stress) / d)


@pytest.mark.parametrize("d", [2, 3, 4, 5])
def test_hessian_is_numerical_jacobian_of_forces(d, rng):
    pot = PowerLawPotential(exponent=2.5)
    x, box, D = _overlapping_config(d, rng)
    H = hessian(x, box, D, pot).toarray()
    nl = NeighborList(D)
    h = 1e-6
    J = np.zeros_like(H)
    for i in range(len(x)):
        for a in range(d):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += h
            xm[i, a] -= h
            J[:, i * d + a] = -(evaluate(xp, box, D, pot, nl).force - evaluate(xm, box, D, pot, nl).force).ravel() / (2 * h)
    np.testing.assert_allclose(H, J, atol=1e-6 * np.abs(H).max())
    np.testing.assert_allclose(H, H.T, atol=1e-14 * np.abs(H).max())
    # translations are zero modes
    for a in range(d):
        t = np.zeros((len(x), d))
        t[:, a] = 1.0
        assert np.abs(H @ t.ravel()).max() < 1e-12 * np.abs(H).max()


def test_verlet_list_tracks_displacement_and_strain(rng):
    """A reused list gives the energy of a fresh all-pairs search until it reports stale."""
    pot = PowerLawPotential()
    x, box, D = _overlapping_config(3, rng, gamma=0.0)
    nl = NeighborList(D, skin=0.2)
    nl.build(x, box)
    for k in range(30):
        x = x + rng.normal(scale=0.004, size=x.shape)
        x, box = affine_shear(x, box, box.shear_strain + 0.003)
        reused = evaluate(x, box, D, pot, nl)
        fresh = evaluate(x, box, D, pot)
        assert reused.energy == pytest.approx(fresh.energy, rel=1e-12)
    assert nl.builds >= 2  # the skin was used up on the way


def test_overlapping_pairs_forces_and_convention():
    """Two discs of diameter 1 at distance 0.9: xi = 0.1, f = eps xi / sigma, U = eps xi^2 / 2."""
    box = Box.cubic(2, 5.0)
    x = np.array([[1.0, 1.0], [1.9, 1.0]])
    D = np.ones(2)
    pot = PowerLawPotential(epsilon=3.0)
    _, xi, f = overlapping_pairs(x, box, D, pot)
    assert xi == pytest.approx([0.1])
    assert f == pytest.approx([0.3])
    ev = evaluate(x, box, D, pot)
    assert ev.energy == pytest.approx(0.5 * 3.0 * 0.01)
    assert ev.force[1] == pytest.approx([0.3, 0.0])
    assert ev.pressure == pytest.approx(0.3 * 0.9 / (2 * 25.0))


def test_bad_potential_parameters():
    with pytest.raises(ValueError):
        PowerLawPotential(epsilon=-1.0)
    with pytest.raises(ValueError):
        PowerLawPotential(exponent=1.0)
