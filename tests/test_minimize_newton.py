"""Newton polish of the enthalpy (jamflow.minimize.newton) against FIRE on the same shaped packing."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from jamflow.io import read_packing
from jamflow.minimize import newton
from jamflow.minimize.fire import DEFAULT_FIRE, _fire
from jamflow.minimize.newton import polish_enthalpy, positive_semidefinite
from jamflow.models.shapes.model import ShapeModel
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape

P0 = 1e-4
DATA = Path(__file__).parent / "data" / "bodies"
#: Pressure of the vendored enthalpy-stage states of circulo-triangles and circulo-lines [k].
P0_STAGE = 1e-6


def _squeezed(family):
    p = random_shape_packing(bidisperse_shapes(unit_shape(family, asphericity=1.3)), 24, 0.4, 3)
    return ShapeModel(p.box, p.shapes, p.shape_index).rescaled(0.75, np.column_stack([p.position, p.orientation]))


@functools.cache
def _fire_minimum(family):
    """FIRE on U + P0 V from the squeezed start to the stage's tolerances (shared by the tests)."""
    model, c = _squeezed(family)
    fire = _fire(model.fire_engine(model.dofs(c), DEFAULT_FIRE, P0, 1e-6), 1e-13, 1_000_000)
    assert fire.converged
    return fire


def _at_tolerances(model, res, p0):
    """``res`` at the stage's tolerances (largest force 1e-13, pressure 1e-6 of ``p0``) in a fresh model of
    its box; returns that model, its coordinates and its evaluation."""
    assert res is not None
    final = ShapeModel(res.box, model.shapes, model.shape_index)
    q = final.dofs(res.position)
    ev = final.evaluate(q)
    assert final.max_force(ev.gradient) <= 1e-13
    assert abs(np.trace(ev.virial) / (2.0 * res.box.volume) - p0) <= 1e-6 * p0
    return final, q, ev


def _assert_fires_minimum(model, family, res):
    """``res`` meets the stage's tolerances in a fresh model of its box and is FIRE's minimum: the same
    contacts, box volume and configuration (measured: volumes to 6e-13, centres and angles to 4e-8).
    Returns the fresh model's evaluation."""
    _, _, ev = _at_tolerances(model, res, P0)
    fire = _fire_minimum(family)
    assert ev.n_contacts == fire.n_contacts
    assert abs(res.box.volume / fire.box.volume - 1.0) <= 1e-11
    np.testing.assert_allclose(res.position, fire.position, rtol=0, atol=1e-6)
    return ev


@pytest.mark.parametrize("family", ["ellipse", "circulo-line"])
def test_polish_ends_where_fire_ends(family):
    """FIRE on U + P0 V to 1e-9, then Newton: the tolerances hold in a fresh model of the final box, and the
    box, energy, configuration and contacts are those of FIRE run to the same tolerance from the same start."""
    model, c = _squeezed(family)
    q = model.dofs(c)
    loose = _fire(model.fire_engine(q, DEFAULT_FIRE, P0, 1e-6), 1e-9, 500_000)
    scale = (loose.box.volume / model.box.volume) ** 0.5
    polished = polish_enthalpy(model.rescaled(scale, loose.position)[0], loose.position, P0, 1e-13, 1e-6)
    assert polished.result is not None and 1 <= polished.iterations <= 8
    ev = _assert_fires_minimum(model, family, polished.result)
    # the same energy (measured: to 6e-9)
    assert abs(ev.energy / _fire_minimum(family).energy - 1.0) <= 1e-7


def _enthalpy(model, c):
    return model.evaluate(model.dofs(c)).energy + P0 * model.box.volume


@pytest.mark.parametrize("family", ["ellipse", "circulo-line"])
def test_trust_region_lands_where_the_full_newton_step_overshoots(family):
    """From FIRE's state at force 1e-6 the full Newton step on U + P0 V raises the enthalpy (it leaves the
    region where the Hessian describes H); the trust-region polish lands on FIRE's minimum to 1e-13."""
    model, c = _squeezed(family)
    q = model.dofs(c)
    early = _fire(model.fire_engine(q, DEFAULT_FIRE, P0, 1e-6), 1e-6, 500_000)
    start, x = model.rescaled((early.box.volume / model.box.volume) ** 0.5, early.position)[0], early.position
    s = start.dofs(x)
    ev = start.evaluate(s)
    dhds = 2.0 * start.box.volume * (P0 - np.trace(ev.virial) / (2.0 * start.box.volume))
    system = newton._bordered_hessian(start, x, s, P0)
    shift = newton.NEWTON_SHIFT * float(np.abs(system.diagonal()[:-1]).max())
    system = system + sp.diags(np.r_[np.full(system.shape[0] - 1, shift), 0.0])
    full = sla.spsolve(system.tocsc(), -np.concatenate([ev.gradient, [dhds]]))
    after, y = start.rescaled(1.0 + full[-1], start.positions(s + full[:-1]))
    assert _enthalpy(after, y) > _enthalpy(start, x)
    polished = polish_enthalpy(start, x, P0, 1e-13, 1e-6)
    _assert_fires_minimum(model, family, polished.result)


@pytest.mark.parametrize("family", ["ellipse", "circulo-line"])
def test_polish_from_far_away_returns_a_minimum_at_tolerance_or_nothing(family):
    """From the squeezed start (forces ~1e-1, P ~ 1e2 P0): no result, or one at both tolerances whose bordered
    Hessian has no negative eigenvalue (dense) and whose circulo cores do not cross, with H below the start's."""
    model, c = _squeezed(family)
    ev = model.evaluate(model.dofs(c))
    assert model.max_force(ev.gradient) > 1e-3
    polished = polish_enthalpy(model, c, P0, 1e-13, 1e-6)
    if polished.descended:
        moved, y = model.rescaled((polished.box.volume / model.box.volume) ** 0.5, c)[0], polished.position
        assert _enthalpy(moved, y) < _enthalpy(model, c)
    res = polished.result
    if res is None:
        return
    final, q, _ = _at_tolerances(model, res, P0)
    final.check_cores(q)
    a = newton._bordered_hessian(final, res.position, q, P0).toarray()
    a = 0.5 * (a + a.T)
    assert np.linalg.eigvalsh(a)[0] >= -newton.NEGATIVE_CURVATURE * np.abs(np.diag(a)).max()


def test_the_inertia_check_agrees_with_dense_eigenvalues_and_survives_a_zero_pivot():
    # [[1, 1], [1, 1]] has eigenvalues 0 and 2 and a zero second pivot (SuperLU raises)
    assert positive_semidefinite(sp.csc_matrix(np.ones((2, 2))))
    assert not positive_semidefinite(sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]])))
    # sparse symmetric matrices whose lowest eigenvalue is +-1e-3 of an O(1) spectrum
    rng = np.random.default_rng(0)
    signs = rng.permutation(np.repeat([-1.0, 1.0], 20))
    for sign in signs:
        b = rng.standard_normal((12, 12)) * (rng.random((12, 12)) < 0.3)
        g = b @ b.T
        a = g - (np.linalg.eigvalsh(g)[0] - sign * 1e-3) * np.eye(12)
        assert positive_semidefinite(sp.csc_matrix(a)) == (sign > 0)


def test_a_polish_whose_every_step_is_refused_gives_up_before_its_shift_overflows(monkeypatch):
    """No step may move a body (TRUST_MOVE = 0): the shift grows after every refusal, and the polish must
    stop once it exceeds TRUST_SHIFT_MAX (the step is then below round-off) without a float overflow,
    within far fewer trial steps than its budget."""
    monkeypatch.setattr(newton, "TRUST_MOVE", 0.0)
    model, c = _squeezed("ellipse")
    with np.errstate(over="raise", invalid="raise"):
        polished = polish_enthalpy(model, c, P0, 1e-13, 1e-6)
    assert polished.result is None and not polished.descended
    # the shift starts at TRUST_SHIFT and grows by 2, 4, 8, ...: past 1 / eps after about 10 refusals
    assert polished.iterations < 20


def _enthalpy_try(name):
    """Model and configuration of a vendored enthalpy-stage state of circulo-triangles (tests/data/bodies/make.sh)."""
    p = read_packing(DATA / f"circulo_triangles_enthalpy_{name}.nc", overlap_tol=None)
    model = ShapeModel(p.box, p.shapes, p.shape_index)
    return model, np.column_stack([p.position, p.orientation])


def test_a_walk_in_the_flat_valley_goes_on_past_indefinite_steps_and_lowers_the_enthalpy():
    """The enthalpy stage's tries (``max_indefinite=None``) do not give up at TRUST_INDEFINITE undone steps:
    from the same valley state a walk spends its whole budget, every kept step lowers ``H = U + P0 V``, and
    it returns its end state with the model of that state's box, from which FIRE goes on."""
    model, config = _enthalpy_try("valley")

    def enthalpy(m, c):
        return m.evaluate(m.dofs(c)).energy + P0_STAGE * m.box.volume

    walk = polish_enthalpy(model, config, P0_STAGE, 1e-13, 1e-6, 40, max_indefinite=None)
    assert walk.result is None and walk.iterations == 40 and walk.descended
    # the walk moved the box, so its end state is only meaningful in the model of that box it returns
    assert walk.box.volume != model.box.volume and walk.model.box == walk.box
    assert enthalpy(walk.model, walk.position) < enthalpy(model, config)
    # the cap stays where a caller keeps it
    assert polish_enthalpy(model, config, P0_STAGE, 1e-13, 1e-6, 40).iterations <= 20


def test_a_polish_in_a_flat_valley_gives_up_early_and_one_in_the_basin_lands_on_a_minimum():
    """Circulo-triangles at P0 = 1e-6, FIRE's states at two Newton tries of one enthalpy stage. In the valley
    (largest force 2e-11, 0.1 neighbour distances from the minimum FIRE reaches) every step that grows goes
    past a corner contact of overlap ~1e-11 into a region where the Hessian is indefinite: the polish gives
    up after TRUST_INDEFINITE such steps (14 trial steps; 87 before such steps were undone). From the basin it
    lands (9 trial steps; 25 before):
    both tolerances in a fresh model of the final box, and no negative eigenvalue of the bordered Hessian."""
    model, config = _enthalpy_try("valley")
    polished = polish_enthalpy(model, config, P0_STAGE, 1e-13, 1e-6)
    assert polished.result is None and polished.iterations <= 20
    model, config = _enthalpy_try("basin")
    res = polish_enthalpy(model, config, P0_STAGE, 1e-13, 1e-6).result
    final, q, _ = _at_tolerances(model, res, P0_STAGE)
    a = newton._bordered_hessian(final, res.position, q, P0_STAGE).toarray()
    a = 0.5 * (a + a.T)
    assert np.linalg.eigvalsh(a)[0] >= -newton.NEGATIVE_CURVATURE * np.abs(np.diag(a)).max()


@pytest.mark.parametrize("ds", [0.0, 2e-3])
def test_the_slope_along_a_step_is_the_derivative_of_the_enthalpy_along_it(ds):
    """``dH/dt`` along a step ``(dq, ds)`` from a trial state in its own scaled box (centres ``s`` times the
    reference ones, ``dH/ds`` at fixed reference coordinates ``(dH/ds') / s``) against central differences of
    ``H = U + P0 V`` along the same line, on the squeezed circulo-lines (forces ~1e-1: every term moves)."""
    model, c = _squeezed("circulo-line")
    q = model.dofs(c)
    rng = np.random.default_rng(5)
    step = np.r_[1e-3 * rng.standard_normal(q.size), ds]

    def enthalpy(t):
        trial = newton._trial(model, q, step, t, P0)
        return trial.ev.energy + P0 * trial.model.box.volume

    for t in (0.5, 1.0):
        h = 1e-4
        want = (enthalpy(t + h) - enthalpy(t - h)) / (2.0 * h)
        got = newton._slope(step, t, newton._trial(model, q, step, t, P0))
        # central differences: error ~h^2 H''' / 6 plus round-off eps H / h (measured 7e-11 ... 3e-9 of the slope)
        assert abs(got - want) <= 1e-7 * abs(want)


def test_a_walk_that_slides_bodies_into_unseen_neighbours_closes_those_contacts_and_lands():
    """N = 480 circulo-lines at P0 = 1e-6, FIRE's state at the second Newton try of an enthalpy stage
    (largest force 5.0e-12, tolerance 1e-13). Its last forces lie along valleys of near-zero stiffness
    (a line sliding along its axis between parallel neighbours) that end where the body meets a neighbour
    the Hessian does not see: full steps overshoot into that contact. The polish lands when a step cut short
    goes on to the slope's sign change along its line (the contact closed) and, below the enthalpy's
    round-off, a step is judged by the trapezoid of the slopes, which a slide with a constant force passes.
    Measured: 48 trial steps, 1244 -> 1247 contacts; without the line search 141; without both (steps below
    round-off judged by the largest force) it gives up after 59."""
    p = read_packing(DATA / "circulo_lines_enthalpy_slide.nc", overlap_tol=None)
    model = ShapeModel(p.box, p.shapes, p.shape_index)
    config = np.column_stack([p.position, p.orientation])
    ev = model.evaluate(model.dofs(config))
    assert model.max_force(ev.gradient) > 5e-13
    res = polish_enthalpy(model, config, P0_STAGE, 1e-13, 1e-6, 100, max_indefinite=None).result
    final, q, fev = _at_tolerances(model, res, P0_STAGE)
    final.check_cores(q)
    assert fev.n_contacts > ev.n_contacts
    assert fev.energy + P0_STAGE * res.box.volume < ev.energy + P0_STAGE * p.box.volume
