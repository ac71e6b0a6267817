"""Minimum-norm balanced contact forces (jamflow.network.forces)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import jamflow.network.forces as forces
from jamflow.network.forces import balance_matrix, min_norm_forces
from jamflow.network.rigidity import contact_geometry, rigidity_matrix
from jamflow.network.spheres import contacts_from_gaps, find_rattlers
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing


def test_balance_matrix_is_the_transpose_of_the_rigidity_matrix():
    p = random_packing(20, 2, 0.45, "bi", seed=4, ratio=1.4)
    c = contacts_from_gaps(p, 0.3)
    unit, _ = contact_geometry(p, c)
    B = balance_matrix(unit, c, p.n, p.d)
    # the net force of repulsive contact forces f is R^T f (virtual work: a motion y
    # that opens contacts, R y > 0, is pushed along by them)
    np.testing.assert_allclose(B.toarray(), rigidity_matrix(p, c).toarray().T, atol=1e-15)


def test_isostatic_network_gets_its_unique_dual_forces():
    """On an isostatic network the balanced forces are unique: the QP must return
    CALiPPSO's dual vertex forces (two independent solutions)."""
    res = calippso(random_packing(32, 2, 0.3, "bi", seed=32, ratio=1.4))
    p = res.packing
    assert p.attrs["force_assignment"] == "lp_dual_vertex" and p.attrs["isostatic"] == 1
    stable = ~p.rattler
    c = p.contacts[stable[p.contacts[:, 0]] & stable[p.contacts[:, 1]]]
    f_dual = p.force[stable[p.contacts[:, 0]] & stable[p.contacts[:, 1]]]
    unit, _ = contact_geometry(p, c)
    f, residual = min_norm_forces(balance_matrix(unit, c, p.n, p.d), p.sigma(c[:, 0], c[:, 1]), p.d)
    np.testing.assert_allclose(f, f_dual, rtol=1e-8)
    assert residual < 1e-12


def test_particle_between_two_walls_gets_equal_forces():
    # one particle touching the lower and upper x walls: equal and opposite pushes
    B = balance_matrix(np.zeros((0, 2)), np.zeros((0, 2), int), 1, 2, np.array([0, 0]), np.array([0, 1]))
    np.testing.assert_array_equal(B.toarray(), [[1.0, -1.0], [0.0, 0.0]])
    f, _ = min_norm_forces(B, np.array([0.5, 0.5]), 2)
    np.testing.assert_allclose(f, [1.0, 1.0], rtol=1e-12)


def test_network_without_balanced_forces_is_an_error():
    # a lone pair cannot carry a balanced non-zero force with sum w f = 1
    B = balance_matrix(np.array([[1.0, 0.0]]), np.array([[0, 1]]), 2, 2)
    with pytest.raises(RuntimeError, match="not solved|balance"):
        min_norm_forces(B, np.array([1.0]), 2)


def test_newton_and_highs_qp_give_the_same_minimum_norm_forces():
    """Two independent solvers of the same strictly convex QP agree, on a degenerate
    2D monodisperse network where some contacts end up without force."""
    res = calippso(random_packing(64, 2, 0.5, "mono", seed=3))
    p = res.packing
    assert p.attrs["force_assignment"] == "min_norm_balanced"
    unit, _ = contact_geometry(p, p.contacts)
    B = balance_matrix(unit, p.contacts, p.n, p.d)
    w = p.sigma(p.contacts[:, 0], p.contacts[:, 1])
    f_newton, r_newton = min_norm_forces(B, w, p.d)
    f_qp, r_qp = min_norm_forces(B, w, p.d, method="qp")
    assert (f_newton == 0).sum() > 0 and (f_newton >= 0).all()
    np.testing.assert_allclose(f_newton, f_qp, rtol=0, atol=1e-9 * f_qp.max())
    assert max(r_newton, r_qp) < 1e-11
    np.testing.assert_allclose(p.force, f_newton, rtol=0, atol=1e-12 * f_qp.max())


def _vendored_hyperstatic_network() -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Balance matrix, weights and pair contacts of the geometric network of a CALiPPSO
    packing hyperstatic by one contact (3D N = 2048 from an LS start at kappa = 1e-4, seed
    2: 6008 backbone contacts, 130 contacts of rattlers)."""
    z = np.load(Path(__file__).parent / "data" / "min_norm_stall_n2048.npz")
    B = sp.csr_matrix((z["data"], z["indices"], z["indptr"]), shape=tuple(z["shape"]))
    Bc = B.tocsc()
    contacts = np.array([np.unique(Bc.indices[Bc.indptr[c]:Bc.indptr[c + 1]] // 3) for c in range(B.shape[1])])
    return B, z["weight"], contacts


def _counting_lus(monkeypatch) -> list[int]:
    """Record every sparse LU of :mod:`jamflow.network.forces` (one per Newton step)."""
    calls, lu = [], forces.splu
    monkeypatch.setattr(forces, "splu", lambda *a, **k: calls.append(1) or lu(*a, **k))
    return calls


@pytest.mark.slow
def test_the_dual_newton_solves_a_near_singular_hyperstatic_network_without_the_qp(monkeypatch):
    """On the vendored network the Newton alone must give the QP's forces to 1e-9 of the
    largest, both on the whole network and on its backbone, with exact zeros on the
    rattlers' contacts. Its dual is large (~1e3), so a residual of 1e-10 still leaves
    forces wrong by ~3e-8: the steps past the tolerance are what make the two agree; and
    near the optimum the dual function's increments are far below its own round-off."""
    B, w, contacts = _vendored_hyperstatic_network()
    rattler = find_rattlers(B.shape[0] // 3, 3, contacts)
    backbone = ~(rattler[contacts[:, 0]] | rattler[contacts[:, 1]])
    assert backbone.sum() == 6008 and (~backbone).sum() == 130
    f_qp = min_norm_forces(B, w, 3, method="qp")[0]
    qp_calls = []
    qp = forces._highs_qp
    monkeypatch.setattr(forces, "_highs_qp", lambda *a: qp_calls.append(1) or qp(*a))
    lus = _counting_lus(monkeypatch)
    f, residual = min_norm_forces(B, w, 3)
    assert not qp_calls and len(lus) <= 12
    assert residual < 1e-10 and (f >= 0).all() and (f[~backbone] == 0).all()
    np.testing.assert_allclose(f, f_qp, rtol=0, atol=1e-9 * f_qp.max())
    f_bb, residual_bb = min_norm_forces(B[:, backbone], w[backbone], 3)
    assert not qp_calls and residual_bb < 1e-10
    np.testing.assert_allclose(f_bb, f_qp[backbone], rtol=0, atol=1e-9 * f_qp.max())


def test_a_dual_newton_without_progress_stops_after_its_stall_limit(monkeypatch):
    """With a tolerance it cannot reach, the Newton must give up ``_NEWTON_STALL`` steps
    after its smallest residual (the QP decides then), not after ``_NEWTON_MAX_ITER``."""
    p = calippso(random_packing(64, 2, 0.5, "mono", seed=3)).packing
    unit, _ = contact_geometry(p, p.contacts)
    B = balance_matrix(unit, p.contacts, p.n, p.d)
    w = p.sigma(p.contacts[:, 0], p.contacts[:, 1])
    monkeypatch.setattr(forces, "_QP_TOL", -1.0)
    lus = _counting_lus(monkeypatch)
    assert forces._dual_newton(B, w / w.mean(), float(len(w))) is None
    assert forces._NEWTON_STALL < len(lus) < forces._NEWTON_MAX_ITER // 2
