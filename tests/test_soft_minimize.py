"""Minimisers: monotone steepest descent, FIRE/CG/SD agreement, enthalpy at P0."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.minimize.onset import FORCE_TOL_VANDERWERF
from jamflow.models.spheres.fast import steepest_descent
from jamflow.models.spheres.model import conjugate_gradient, fire, minimize_enthalpy
from jamflow.models.spheres.potential import evaluate
from jamflow.protocols.initial import random_packing
from jamflow.protocols.quasistatic import affine_shear
from jamflow.protocols.soft_jam import jam_to_pressure


@lru_cache
def _jammed(n: int, d: int, pressure: float, seed: int):
    start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=seed)
    return jam_to_pressure(start, pressure).packing


def _perturbed(seed: int = 7, amplitude: float = 0.02):
    p = _jammed(32, 2, 1e-2, seed)
    rng = np.random.default_rng(seed)
    return p.position + rng.normal(scale=amplitude, size=p.position.shape), p


def test_steepest_descent_lowers_energy_monotonically():
    x, p = _perturbed()
    out = steepest_descent(x, p.box, p.diameter, dt=0.05, force_tol=1e-10, record=100_000)
    e = out.energies
    assert out.result.converged
    assert len(e) > 100
    # round-off floor: centres carry ~L 2^-53 errors, each contact changes U by ~f dx
    start = evaluate(x, p.box, p.diameter)
    floor = start.n_contacts * start.max_force * p.box.lengths.max() * np.finfo(float).eps
    assert np.all(np.diff(e) <= floor)
    assert e[-1] < 0.5 * e[0]


def test_fire_cg_and_descent_reach_the_same_minimum():
    x, p = _perturbed()
    tol = 1e-12
    a = fire(x, p.box, p.diameter, force_tol=tol)
    b = steepest_descent(x, p.box, p.diameter, dt=0.1, force_tol=tol).result
    c = conjugate_gradient(x, p.box, p.diameter, force_tol=tol)
    for r in (a, b, c):
        assert r.converged and r.max_force <= tol
    for r in (b, c):
        assert r.energy == pytest.approx(a.energy, rel=1e-8)
        # same minimum up to a rigid translation (the d zero modes)
        shift = np.mean(r.position - a.position, axis=0)
        assert np.abs(r.position - a.position - shift).max() < 1e-6


def test_fire_meets_the_vanderwerf_force_criterion():
    p = _jammed(64, 2, 1e-7, 3)
    ev = evaluate(p.position, p.box, p.diameter)
    assert np.max(np.sum(ev.force**2, axis=1)) < 1e-25
    assert ev.max_force <= FORCE_TOL_VANDERWERF


@pytest.mark.parametrize("d, p0", [(2, 1e-4), (3, 1e-3)])
def test_enthalpy_minimum_has_virial_pressure_p0(d, p0):
    p = _jammed(48, d, 1e-2, 5)
    res = minimize_enthalpy(p.position, p.box, p.diameter, p0, force_tol=1e-13, pressure_rtol=1e-8)
    assert res.converged
    ev = evaluate(res.position, res.box, p.diameter)
    assert ev.pressure == pytest.approx(p0, rel=1e-8)
    assert ev.max_force <= 1e-13
    assert res.box.volume > p.box.volume  # lower pressure: the box expanded
    assert res.box.shear_strain == p.box.shear_strain


def test_enthalpy_minimisation_rejects_nonpositive_pressure():
    p = _jammed(32, 2, 1e-2, 7)
    with pytest.raises(ValueError):
        minimize_enthalpy(p.position, p.box, p.diameter, 0.0)


def _square_lattice(strain: float):
    """Nine unit spheres on a square lattice of spacing 1.0667 in a box 3.2 wide, sheared by ``strain``.

    The harmonic repulsion is bounded and of finite range: the spheres touch once the
    box has shrunk by 0.9375, and it holds them (two diameters across) down to 0.625,
    where their pressure is at most ~0.55 epsilon / D^2.
    """
    g = (np.arange(3) + 0.5) * 3.2 / 3
    return affine_shear(np.array([[a, b] for a in g for b in g]), Box(np.diag([3.2, 3.2])), strain)


@pytest.mark.parametrize("strain", [0.0, 0.1])
@pytest.mark.parametrize("p0", [1e12, 10.0])
def test_a_pressure_beyond_the_soft_repulsion_is_refused_in_one_line(p0, strain):
    """The barostat drives the box down until it no longer holds the spheres: over a few
    steps at P0 = 10, in the first at 1e12, where the box scale underflows to 0 and every
    pair distance with it. Both are refused in one line, not divided by r = 0, with the
    orthogonal box (lists rebuilt in the compiled loop) and a sheared one (in Python)."""
    x, box = _square_lattice(strain)
    with pytest.raises(ValueError, match="collapsed the box") as refused:
        minimize_enthalpy(x, box, np.ones(9), p0)
    assert "\n" not in str(refused.value) and f"target pressure {p0:.6g}" in str(refused.value)


@pytest.mark.parametrize("strain", [0.0, 0.1])
def test_a_pressure_the_soft_repulsion_holds_is_reached(strain):
    x, box = _square_lattice(strain)
    res = minimize_enthalpy(x, box, np.ones(9), 0.1, force_tol=1e-13, pressure_rtol=1e-8)
    assert res.converged
    assert evaluate(res.position, res.box, np.ones(9)).pressure == pytest.approx(0.1, rel=1e-8)


@pytest.mark.parametrize("d", [2, 3])
def test_full_box_enthalpy_minimum_has_isotropic_stress_p0(d):
    """With the whole box free the residual shear stress of a strained packing relaxes:
    the stress tensor becomes -P0 1 (the isotropic box alone leaves sigma_xy != 0)."""
    from jamflow.protocols.quasistatic import affine_shear

    p = _jammed(48, d, 1e-2, 5)
    x, box = affine_shear(p.position, p.box, 0.02)
    p0 = 1e-3
    full = minimize_enthalpy(x, box, p.diameter, p0, force_tol=1e-13, pressure_rtol=1e-8, box_dof="full")
    iso = minimize_enthalpy(x, box, p.diameter, p0, force_tol=1e-13, pressure_rtol=1e-8)
    assert full.converged and iso.converged
    ev = evaluate(full.position, full.box, p.diameter)
    np.testing.assert_allclose(ev.stress, -p0 * np.eye(d), atol=1e-8 * p0)
    assert ev.max_force <= 1e-13
    assert abs(evaluate(iso.position, iso.box, p.diameter).shear_stress) > 1e-3 * p0


@pytest.mark.parametrize("enthalpy", [False, True])
def test_fire_trajectory_does_not_depend_on_the_neighbour_list_skin(enthalpy):
    """A rebuild pauses the compiled FIRE loop; the run must continue as if it had not.

    Skins 0.1 and 0.4 <D> rebuild at different steps but list the same overlapping
    pairs in the same order, so FIRE (fixed box, and enthalpy with the isotropic
    barostat) must take the same steps to bitwise the same end. FIRE 2.0's initial
    delay (no dt cut on uphill steps) covers the run's first ``n_delay`` steps, not
    the first steps after every rebuild (regression: it restarted at each rebuild).
    """
    from jamflow.neighbors.verlet import NeighborList

    start = random_packing(256, 2, 0.5, "bi", seed=3)
    factor = (start.packing_fraction / 0.86) ** 0.5
    x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
    runs = []
    for skin in (0.1, 0.4):
        nlist = NeighborList(D, skin * D.mean())
        if enthalpy:
            # a budget, not convergence (the barostat is slow): the same path is the point
            runs.append(minimize_enthalpy(x, box, D, 1e-2, force_tol=1e-10, max_steps=5_000, nlist=nlist))
        else:
            runs.append(fire(x, box, D, force_tol=1e-10, max_steps=20_000, nlist=nlist))
    a, b = runs
    assert a.rebuilds > 2 * b.rebuilds > 0
    assert a.steps == b.steps and a.converged == b.converged == (not enthalpy)
    np.testing.assert_array_equal(a.position, b.position)
    assert a.box == b.box
    assert a.energy == b.energy


@pytest.mark.parametrize("pressure", [None, 1e-2])
def test_lists_rebuilt_inside_the_compiled_loop_give_the_path_of_python_rebuilds(pressure):
    """An orthogonal box lets the FIRE kernel rebuild its list itself; the path, the
    evaluations and the builds must be those of returning to Python for every rebuild."""
    from jamflow.minimize.fire import DEFAULT_FIRE, _fire
    from jamflow.models.spheres.fast import SphereFire
    from jamflow.models.spheres.model import SphereModel

    start = random_packing(256, 2, 0.5, "bi", seed=3)
    factor = (start.packing_fraction / 0.86) ** 0.5
    x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
    runs = []
    for inline in (True, False):
        engine = SphereFire(SphereModel(box, D), x, DEFAULT_FIRE, pressure, 1e-6)
        if not inline:
            engine.lengths = np.empty(0)  # what a sheared box passes: every rebuild returns to Python
        runs.append((_fire(engine, 1e-10, 5_000 if pressure else 20_000), engine.inline_builds))
    (a, inline_builds), (b, none) = runs
    assert inline_builds == a.rebuilds - 1 > 10 and none == 0
    assert a.rebuilds == b.rebuilds and a.steps == b.steps and a.evaluations == b.evaluations
    np.testing.assert_array_equal(a.position, b.position)
    assert a.box == b.box and a.energy == b.energy and a.pressure == b.pressure


def test_large_runs_sorted_by_cell_return_the_callers_order_and_differ_by_round_off(monkeypatch):
    """At N >= SPATIAL_SORT_MIN_N FIRE runs on the spheres sorted by cell: its path is
    independent of the skin (bitwise), its result comes back in the caller's order, and
    a short run agrees with the caller-order run to round-off (the sums are reordered)."""
    import sys

    from jamflow.neighbors.verlet import NeighborList

    minimize = sys.modules["jamflow.models.spheres.fast"]
    start = random_packing(minimize.SPATIAL_SORT_MIN_N, 2, 0.5, "bi", seed=1)
    factor = (start.packing_fraction / 0.86) ** 0.5
    x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
    order = minimize._cell_order(x, box, float(D.max()))
    assert np.array_equal(np.sort(order), np.arange(len(x))) and not np.array_equal(order, np.arange(len(x)))
    runs = [fire(x, box, D, force_tol=1e-12, max_steps=300, nlist=NeighborList(D, skin * D.mean()))
            for skin in (0.1, 0.4)]
    np.testing.assert_array_equal(runs[0].position, runs[1].position)
    assert runs[0].rebuilds > runs[1].rebuilds
    monkeypatch.setattr(minimize, "SPATIAL_SORT_MIN_N", len(x) + 1)
    caller = fire(x, box, D, force_tol=1e-12, max_steps=300, nlist=NeighborList(D, 0.1 * D.mean()))
    assert caller.rebuilds == runs[0].rebuilds and caller.energy > 0.0
    assert not np.array_equal(caller.position, runs[0].position)
    # 300 steps from an overlapping start: measured 8.5e-12 <D> and 9e-14 relative
    np.testing.assert_allclose(runs[0].position, caller.position, rtol=0, atol=1e-10 * D.mean())
    assert runs[0].energy == pytest.approx(caller.energy, rel=1e-12)
