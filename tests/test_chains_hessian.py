"""Constrained Hessian and extended rigidity matrix of linked packings (chains paper Sec. IV)."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.chains.builders import linked_packing
from jamflow.chains.hessian import (
    constrained_hessian,
    extended_rigidity,
    pair_second_derivatives,
)
from jamflow.chains.jamming import jam_linked
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.hessian import hessian
from jamflow.models.spheres.potential import HARMONIC, overlapping_pairs
from jamflow.models.strain import ShearStabilizedModel


@pytest.fixture(scope="module", params=[False, True], ids=["fixed-box", "shear-stabilized"])
def jammed(request):
    start, _ = linked_packing(2, 8, "trimer", np.random.default_rng(1), phi=0.3, no_overlap=True)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-2, delta_phi=1e-2)
    return request.param, jam_linked(start, 1e-3, settings=settings, shear_stabilize=request.param).packing


def _manifold_energy(model, q0, b, t):
    """U on the constraint manifold: q0 + t b re-affixed by three full Newton sweeps (to round-off)."""
    q = q0 + t * b
    for _ in range(3):
        q = model.newton_step(q)
    return model.evaluate(q).energy


def test_constrained_hessian_is_the_second_derivative_on_the_manifold(jammed):
    strain, p = jammed
    ch = constrained_hessian(p, strain=strain)
    plain = constrained_hessian(p, strain=strain, tension_term=False)
    kind = ShearStabilizedModel if strain else LinkedSpheresModel
    model = kind(p.box, p.diameter, p.links, p.position)
    q0 = model.dofs(p.position)
    # h: large enough that round-off of the raw (link-carried) forces times re-affixing errors
    # stays below 1e-6 of H (measured: h = 1e-6 leaves errors of ~3e-4), small enough that
    # the O(h^2) error is ~1e-6; a pair at the contact threshold would make the difference
    # one-sided, none does here
    h = 1e-5
    rng = np.random.default_rng(0)
    for k, l in rng.choice(ch.matrix.shape[0], size=(4, 2), replace=False):
        for b, want in ((ch.basis[k], ch.matrix[k, k]),
                        (ch.basis[k] + ch.basis[l], ch.matrix[k, k] + 2 * ch.matrix[k, l] + ch.matrix[l, l])):
            num = (_manifold_energy(model, q0, b, h) - 2 * _manifold_energy(model, q0, b, 0.0)
                   + _manifold_energy(model, q0, b, -h)) / h**2
            assert num == pytest.approx(want, rel=1e-4)
    # the link tensions' curvature matters at this pressure: Eq. 33 without it is off by more
    assert np.max(np.abs(ch.matrix - plain.matrix)) > 1e-4 * np.abs(ch.matrix).max()


def test_extended_hessian_against_finite_differences_of_the_gradient(jammed):
    """H0 (positions and strain blocks, Eqs. 24-27) against central differences of the model's gradient."""
    _, p = jammed
    model = ShearStabilizedModel(p.box, p.diameter, p.links, p.position)
    q0 = model.dofs(p.position)
    pairs, _, f = overlapping_pairs(p.position, p.box, p.diameter)
    keep = ~p.links.contains(pairs.i, pairs.j)
    pairs, f = pairs.select(keep), f[keep]
    sigma = 0.5 * (p.diameter[pairs.i] + p.diameter[pairs.j])
    k = HARMONIC.stiffness(1.0 - pairs.distance / sigma, sigma)
    H0 = pair_second_derivatives(p.n, 2, pairs.i, pairs.j, pairs.dx, -f, k, model.strain_scale)
    # the positions block is the sphere Hessian of the same pairs
    np.testing.assert_allclose(H0[: 2 * p.n, : 2 * p.n], hessian(p.position, p.box, p.diameter, pairs=pairs).toarray(),
                               atol=1e-12)
    h = 1e-7  # far below the contact overlaps that matter, the gradient is smooth elsewhere
    for col in [0, 7, 2 * p.n, 2 * p.n + 1, 2 * p.n + 2]:  # two centre columns, the three strain columns
        v = np.zeros(q0.size)
        v[col] = 1.0
        g = model.evaluate(q0 + h * v).gradient - model.evaluate(q0 - h * v).gradient
        np.testing.assert_allclose(H0[:, col], g / (2 * h), atol=1e-6 * np.abs(H0).max())


def test_zero_modes_are_the_global_translations_and_self_stress(jammed):
    strain, p = jammed
    ch = constrained_hessian(p, strain=strain)
    assert p.attrs["n_rattlers"] == 0
    assert ch.n_zero == 2
    zero = ch.modes[: 2 * p.n, : ch.n_zero]
    uniform = np.kron(np.ones((p.n, 1)), np.eye(2)) / np.sqrt(p.n)
    # the zero modes span the uniform translations (and carry no strain)
    np.testing.assert_allclose(uniform @ (uniform.T @ zero), zero, atol=1e-8)
    assert np.all(ch.eigenvalues[ch.n_zero:] > 0.0)
    # rigidity matrix: n_c rows, n_t columns; rank n_t - d (translations), so the
    # states of self stress number n_c - (n_t - d)
    RE, _, sss, _ = extended_rigidity(p, strain=strain)
    n_t = ch.matrix.shape[0]
    assert RE.shape == (len(p.contacts), n_t)
    assert sss.shape[1] == len(p.contacts) - (n_t - 2)
    np.testing.assert_allclose(sss.T @ RE, 0.0, atol=1e-10)
    # contact forces are a state of self stress: f^T R_E = 0 at force balance (up to the force tolerance)
    f = p.force / np.linalg.norm(p.force)
    assert np.max(np.abs(f @ RE)) <= 1e-8


def test_rigidity_link_columns_and_gradient_are_the_papers_first_derivatives(jammed):
    """R0, Gamma and dU/dq come from the network core's Jacobian; they equal the paper's
    Eqs. 15-16 (links), 17 (volume) and 35-36 (contacts) written out here in the model's strain
    coordinates (e_aa = q_s eps_aa, e_ab = sqrt(2) q_s eps_ab), and the gradient equals the
    energy model's, to round-off."""
    from jamflow.chains.hessian import _geometry, energy_gradient, gamma_matrix
    from jamflow.models.strain import strain_components

    stabilized, p = jammed
    geo = _geometry(p, HARMONIC)
    n, d = p.n, 2

    def rows(i, j, dx):
        u = dx / np.linalg.norm(dx, axis=1)[:, None]
        R = np.zeros((len(i), n * d + 3))
        Rx = R[:, : n * d].reshape(len(i), n, d)
        Rx[np.arange(len(i)), j] = u
        Rx[np.arange(len(i)), i] -= u
        # d |F R| / d e at F = 1: u_a R_b through the chain rule of the symmetric strain
        R[:, n * d:] = strain_components(u[:, :, None] * dx[:, None, :], geo.strain_scale)
        return R

    _, R0, _, _ = extended_rigidity(p, strain=True)
    want = rows(geo.pairs.i, geo.pairs.j, geo.pairs.dx)
    np.testing.assert_allclose(R0, want, rtol=0, atol=1e-15 * np.abs(want).max())
    G = gamma_matrix(geo, strain=True, volume=True)
    links = rows(p.links.i, p.links.j, p.box.minimum_image(p.position[p.links.j] - p.position[p.links.i]))
    volume = np.r_[np.zeros(n * d), strain_components(np.eye(d), geo.strain_scale)]
    np.testing.assert_allclose(G, np.column_stack([links.T, volume]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(gamma_matrix(geo, strain=False), links[:, : n * d].T, rtol=0, atol=1e-15)
    model = ShearStabilizedModel(p.box, p.diameter, p.links, p.position)
    raw = model.evaluate(model.dofs(p.position)).gradient
    # each side rounds pair vectors of coordinates up to the box width in its own order: up to
    # an ulp of the box width times the pair stiffness eps / sigma^2 (eps = 1) each (0.9-3.5e-16
    # against a long-double sum on the shear-stabilised packing), above 1e-13 of the largest
    # force at P = 1e-3
    roundoff = 2 * np.spacing(float(np.max(p.box.widths))) / p.diameter.min() ** 2
    np.testing.assert_allclose(energy_gradient(geo, strain=True), raw, rtol=0,
                               atol=max(1e-13 * np.abs(raw).max(), roundoff))


def test_modes_keep_the_constraints_and_are_the_second_derivative_along_them(jammed, tmp_path):
    """linked_modes (jamflow modes): every mode mapped back by B^T keeps every link (and the volume)
    to first order, |Gamma^T y| <= 1e-12, and U'' along a mode on the manifold is its eigenvalue."""
    from jamflow.chains.hessian import _geometry, gamma_matrix
    from jamflow.chains.modes import linked_modes
    from jamflow.cli import main
    from jamflow.io import read_dataset, write_packing

    strain, p = jammed
    modes = linked_modes(p, strain=strain)
    G = gamma_matrix(_geometry(p, HARMONIC), strain)
    assert np.max(np.abs(G.T @ modes.vectors)) <= 1e-12
    np.testing.assert_allclose(modes.vectors.T @ modes.vectors, np.eye(modes.vectors.shape[1]), atol=1e-12)
    assert modes.n_zero == 2 == modes.n_label("translation")
    kind = ShearStabilizedModel if strain else LinkedSpheresModel
    model = kind(p.box, p.diameter, p.links, p.position)
    q0 = model.dofs(p.position)
    h = 1e-5  # as in test_constrained_hessian_is_the_second_derivative_on_the_manifold
    for k in (2, 3, modes.eigenvalues.size // 2, modes.eigenvalues.size - 1):
        y = modes.vectors[:, k]
        num = (_manifold_energy(model, q0, y, h) - 2 * _manifold_energy(model, q0, y, 0.0)
               + _manifold_energy(model, q0, y, -h)) / h**2
        assert num == pytest.approx(modes.eigenvalues[k], rel=1e-4)
    # the command stores them, with strain components when the strain is a degree of freedom
    write_packing(p, tmp_path / "p.nc")
    assert main(["modes", str(tmp_path / "p.nc"), str(tmp_path / "m.nc"), "--quiet"]) == 0
    ds = read_dataset(tmp_path / "m.nc", "linked-modes")
    np.testing.assert_allclose(ds["eigenvalue"].values, modes.eigenvalues, rtol=1e-12, atol=1e-15)
    assert ds.attrs["max_constraint_violation"] <= 1e-12 and ds.attrs["n_translation"] == 2
    assert ds.attrs["hessian_strain"] == int(strain)
    assert (np.abs(ds["mode_strain"].values).max() > 0) == strain
    assert main(["plot", "mode", str(tmp_path / "p.nc"), str(tmp_path / "m.nc"), str(tmp_path / "m.png"),
                 "--quiet"]) == 0
