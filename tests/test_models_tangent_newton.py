"""Trust-region Newton on the constraint manifold of linked spheres (fixed box and shear-stabilised).

The reduced Lagrangian Hessian of ``tangent_newton`` against central differences of the
model's projected gradient along re-affixed tangent curves; the polish against tight FIRE
from the same start; a saddle refused; the final stage of the jamming protocol with it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jamflow.minimize.onset as onset
from jamflow.box import Box
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.io import read_packing
from jamflow.minimize.fire import minimize_fire
from jamflow.minimize.newton import _tangent_minimum, polish_constrained
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.strain import ShearStabilizedModel
from jamflow.state.bodies import Links

SETTINGS = JammingSettings(force_tol=1e-12, pressure_rtol=1e-2, delta_phi=1e-2)


DATA = Path(__file__).parent / "data" / "bodies"


@pytest.fixture(scope="module")
def start():
    return linked_packing(2, 8, "trimer", np.random.default_rng(1), phi=0.3, no_overlap=True)[0]


@pytest.fixture(scope="module", params=[False, True], ids=["fixed-box", "shear-stabilized"])
def jammed(request):
    """6 rigid trimers jammed at P0 = 1e-3 to force 1e-13 (tests/data/bodies/make.sh)."""
    name = "linked_soft_shear.nc" if request.param else "linked_soft.nc"
    return request.param, read_packing(DATA / name, None)


def _model(strain, p):
    kind = ShearStabilizedModel if strain else LinkedSpheresModel
    model = kind(p.box, p.diameter, p.links, p.position)
    q = model.dofs(p.position)
    model.evaluate(q)
    return model, q


def test_reduced_hessian_is_the_derivative_of_the_projected_gradient_on_the_manifold(jammed):
    strain, p = jammed
    model, q0 = _model(strain, p)
    system = model.tangent_newton(q0)
    K, T = system.hessian, system.basis
    assert np.abs((T.T @ T).toarray() - np.eye(T.shape[1])).max() < 1e-13  # orthonormal tangent basis
    # Gamma^T T = 0: a tangent step moves no link (nor det F) at first order
    step = 1e-7 * (T @ np.random.default_rng(2).standard_normal(T.shape[1]))
    assert np.abs(model.link_errors(q0 + step)).max() < 1e-12
    if strain:
        assert abs(model.volume_error(q0 + step)) < 1e-12

    def tangent_force(q):
        return T.T @ model.project(model.evaluate(q).gradient, q)

    # h: the O(h^2) error and the round-off of the re-affixed forces (1e-13 of a link) both ~1e-10 of K a;
    # 1e-4 moves a contact across its threshold in some directions
    h = 1e-5
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(4):
        a = rng.standard_normal(K.shape[0])
        v = T @ a
        numeric = (tangent_force(model.reproject(q0 + h * v)) - tangent_force(model.reproject(q0 - h * v))) / (2 * h)
        worst = max(worst, np.linalg.norm(numeric - K @ a) / np.linalg.norm(K @ a))
    assert worst < 1e-6
    # a minimum: no negative reduced eigenvalue beyond the zero modes (translations, rattlers)
    w = np.linalg.eigvalsh(K.toarray())
    assert w[0] > -1e-12 * w[-1] and _tangent_minimum(system)


def test_tension_term_matters_at_this_pressure(jammed):
    """Without the constraints' curvature (``mu grad^2 c``) the reduced Hessian is off by far more than
    the finite-difference test above resolves, so that test fails on a model that drops it."""
    strain, p = jammed
    model, q0 = _model(strain, p)
    system = model.tangent_newton(q0)
    tensions = model.multipliers(model.evaluate(q0).gradient, q0)
    assert np.abs(tensions).max() > 1e-4 * np.abs(system.hessian.diagonal()).max()


def test_polish_reaches_the_tight_fire_minimum_of_the_same_start(jammed):
    strain, p = jammed
    model, q = _model(strain, p)
    compressed, x = model.rescaled(1.0 - 1e-5, p.position)

    def squeezed():
        m, _ = _model(strain, p)
        return m.rescaled(1.0 - 1e-5, p.position)[0]

    # FIRE to 1e-14: its state then lies within F / lambda_min ~ 1e-11 of the minimum (1e-12 leaves
    # pressure errors of ~1e-9 relative, of the order of the comparison)
    ref = minimize_fire(squeezed(), x, 1e-14, 10**6)
    loose_model = squeezed()
    loose = minimize_fire(loose_model, x, 1e-6, 10**6)
    assert loose.max_force > 1e-8  # the polish has work to do: steps whose link errors need re-affixing
    base, xb = loose_model.rescaled(1.0, loose.position)
    polish = polish_constrained(base, xb, 1e-12)
    r = polish.result
    assert r is not None and r.max_force <= 1e-12 and polish.iterations <= 10
    assert r.energy == pytest.approx(ref.energy, rel=1e-10)
    assert r.pressure == pytest.approx(ref.pressure, rel=1e-9)
    np.testing.assert_allclose(r.box.matrix, ref.box.matrix, rtol=0, atol=1e-10)
    # spheres with contacts (a rattler sits anywhere in its cage), up to a common translation
    touching = np.bincount(np.concatenate([*_contacts(polish.model, r.position)]), minlength=p.n) > 0
    dx = (r.position - ref.position)[touching]
    assert np.abs(dx - np.median(dx, axis=0)).max() < 1e-9
    m = polish.model
    qf = m.dofs(r.position)
    assert np.abs(m.link_errors(qf)).max() <= m.length_rtol
    assert r.box.volume == pytest.approx(compressed.box.volume, rel=1e-12)


def _contacts(model, x):
    model.evaluate(model.dofs(x))
    xr = np.asarray(x)
    i, j, off, sigma = model._pi, model._pj, model._offset, model._sigma
    r = np.linalg.norm(xr[j] - xr[i] + off, axis=1)
    keep = r < sigma
    return i[keep], j[keep]


def _straight_chain(offset: float) -> tuple[LinkedSpheresModel, np.ndarray]:
    """Three unit spheres on a line along x with two links (free angle) and a free sphere between the
    chain's end and the periodic image of its start (box 3.8), ``offset`` off the midpoint: all on one
    line, so the forces stay along x; balanced, the compressed straight chain is a saddle (bending it
    relieves the overlaps)."""
    box = Box(np.diag([3.8, 6.0]))
    x = np.array([[0.0, 3.0], [1.0, 3.0], [2.0, 3.0], [2.9 + offset, 3.0]])
    links = Links(np.array([0, 1]), np.array([1, 2]), np.array([1.0, 1.0]))
    return LinkedSpheresModel(box, np.ones(4), links, x), x


def test_polish_does_not_accept_a_saddle():
    model, x = _straight_chain(1e-3)
    q = model.reproject(model.dofs(x))
    assert model.max_force(model.project(model.evaluate(q).gradient, q)) > 1e-6
    polish = polish_constrained(model, model.positions(q), 1e-12)
    assert polish.result is None
    # it did balance the forces (along x, by symmetry): the refusal is the minimum check's
    m = polish.model
    qs = m.dofs(polish.position)
    assert m.max_force(m.project(m.evaluate(qs).gradient, qs)) <= 1e-12
    system = m.tangent_newton(qs)
    assert np.linalg.eigvalsh(system.hessian.toarray())[0] < -1e-3 and not _tangent_minimum(system)


@pytest.mark.slow
def test_jamming_with_the_polish_ends_in_the_window_isostatic_by_rank(start, monkeypatch):
    # small packings converge within POLISH_CHECK steps: look every 50 so the polish ends minimisations
    monkeypatch.setattr(onset, "LINKED_POLISH_AFTER", 50)
    monkeypatch.setattr(onset, "LINKED_POLISH_CHECK", 50)
    monkeypatch.setattr(onset, "LINKED_POLISH_INTERVAL", 50)
    tries = []
    original = onset.polish_constrained

    def counted(*args, **kwargs):
        out = original(*args, **kwargs)
        tries.append(out.result is not None)
        return out

    monkeypatch.setattr(onset, "polish_constrained", counted)
    for polish in (False, True):
        settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2, newton_polish=polish)
        result = jam_linked(start, 1e-3, settings=settings)
        a = result.packing.attrs
        assert result.converged and a["max_force_sq"] <= 1e-24
        assert abs(result.history["pressure"][-1] / 1e-3 - 1.0) <= 1e-3
        assert a["n_contacts"] >= a["isostatic_count"]
        assert a["max_link_error"] <= 1e-13
    assert any(tries)  # the polish ended at least one minimisation of the final stage


def test_soft_jam_newton_polish_is_for_linked_packings(tmp_path, capsys):
    out = tmp_path / "j.nc"
    assert main(["soft-jam", str(DATA / "spheres_soft.nc"), str(out), "--pressure", "1e-3", "--newton-polish",
                 "--quiet"]) == 1
    assert "--newton-polish is for linked packings" in capsys.readouterr().err
    assert main(["soft-jam", str(DATA / "linked_soft.nc"), str(out), "--pressure", "1e-3", "--newton-polish",
                 "--quiet"]) == 0
    assert read_packing(out, None).attrs["n_contacts"] >= read_packing(out, None).attrs["isostatic_count"]
    # shear-stabilised, the bisection ends with the enthalpy minimisation: nothing for the polish to end
    assert main(["soft-jam", str(DATA / "linked_soft.nc"), str(out), "--pressure", "1e-3", "--newton-polish",
                 "--shear-stabilize", "--quiet"]) == 1
    assert "a shear-stabilised bisection ends with the enthalpy minimisation" in capsys.readouterr().err
