"""Compiled FIRE engines of bodies against the flat-vector FIRE on the same model and start."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import linked_volume
from jamflow.minimize.fire import DEFAULT_FIRE, _fire, _ModelFire
from jamflow.models import _link_kernels
from jamflow.models.links import LinkedFire, LinkedSpheresModel
from jamflow.models.shapes import _fire_kernels
from jamflow.models.shapes.fast import FAMILY_CODES, ShapeFire
from jamflow.models.shapes.model import ShapeModel
from jamflow.models.strain import ShearStabilizedModel, StrainFire
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape
from jamflow.tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL


def _compressed_trimers(kind, phi):
    p = linked_packing(2, 20, "trimer", np.random.default_rng(1))[0]
    s = p.in_units(float(p.diameter.mean()))
    box = Box(s.box.matrix)
    f = (linked_volume(2, s.diameter, s.links) / box.volume / phi) ** 0.5
    return kind(box.scaled(f), s.diameter, s.links, s.position * f), s.position * f


@pytest.mark.parametrize("engine", [LinkedFire, StrainFire])
def test_linked_engines_reach_the_flat_fire_minimum(engine):
    """Rigid 2D trimers squeezed to phi = 0.86: the same minimum, energy to round-off, links held."""
    kind = ShearStabilizedModel if engine is StrainFire else LinkedSpheresModel
    runs = []
    for fast in (True, False):
        model, x = _compressed_trimers(kind, 0.86)
        q = model.dofs(x)
        e = model.fire_engine(q, DEFAULT_FIRE) if fast else _ModelFire(model, q, DEFAULT_FIRE)
        assert isinstance(e, engine if fast else _ModelFire)
        runs.append(_fire(e, 1e-12, 200_000))
    a, b = runs
    assert a.converged and b.converged and b.energy > 0.0
    assert abs(a.energy - b.energy) <= 1e-12 * b.energy
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-8)


def test_a_subclass_with_its_own_energy_keeps_the_flat_fire():
    class Loaded(ShearStabilizedModel):
        def evaluate(self, q):
            return super().evaluate(q)

    model, x = _compressed_trimers(Loaded, 0.86)
    assert model.fire_engine(model.dofs(x), DEFAULT_FIRE) is None


@pytest.mark.parametrize("family", ["ellipse", "circulo-line", "reuleaux"])
def test_shape_engine_forces_and_minimum_match_the_model(family):
    """Compiled pair sums equal ShapeModel.evaluate; the engine's FIRE reaches the flat FIRE's minimum."""
    table = bidisperse_shapes(unit_shape(family) if family == "reuleaux" else unit_shape(family, asphericity=1.3))
    p = random_shape_packing(table, 24, 0.4, 3)
    # squeezed past jamming (soft overlaps): a minimum with positive energy
    squeeze = 0.66
    model, c = ShapeModel(p.box, p.shapes, p.shape_index).rescaled(squeeze, np.column_stack([p.position,
                                                                                            p.orientation]))
    q = model.dofs(c)
    ev = model.evaluate(q)
    model.nlist.build(c[:, :2], model.box)
    force, virial = np.zeros((model.n, 3)), np.zeros((2, 2))
    lam = np.full(len(model.nlist.i), -1.0)
    offset = np.ascontiguousarray(model.nlist.image @ model.box.matrix.T)
    for _ in range(2):  # cold, then warm-started Perram-Wertheim solves
        energy, n_contact = _fire_kernels.shape_forces(
            np.ascontiguousarray(c), 1.0, offset, model.nlist.i, model.nlist.j, FAMILY_CODES[model.family],
            model.params, 0.5 * model.bounding_diameter, lam, model.k, force, virial)
        g = np.column_stack([ev.gradient[: 2 * model.n].reshape(-1, 2), ev.gradient[2 * model.n:]])
        assert ev.energy > 0.0 and n_contact == ev.n_contacts
        assert abs(energy - ev.energy) <= 1e-13 * ev.energy
        np.testing.assert_allclose(force, -g, rtol=0, atol=1e-13 * np.abs(g).max())
        np.testing.assert_allclose(virial, ev.virial, rtol=0, atol=1e-13 * np.abs(ev.virial).max())
    a = _fire(ShapeFire(model, q, DEFAULT_FIRE, None, 0.0), 1e-12, 200_000)
    b = _fire(_ModelFire(model, q, DEFAULT_FIRE), 1e-12, 200_000)
    # the same steps: round-off (warm-started Perram-Wertheim solves) may move the crossing of
    # force_tol by a step
    assert a.converged and b.converged and abs(a.steps - b.steps) <= 2
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-8)
    assert b.energy > 0.0 and abs(a.energy - b.energy) <= 1e-12 * b.energy


def test_shape_barostat_reaches_the_target_pressure_in_force_balance():
    table = bidisperse_shapes(unit_shape("ellipse", asphericity=1.3))
    p = random_shape_packing(table, 24, 0.4, 3)
    model, c = ShapeModel(p.box, p.shapes, p.shape_index).rescaled(0.75, np.column_stack([p.position,
                                                                                          p.orientation]))
    res = _fire(model.fire_engine(model.dofs(c), DEFAULT_FIRE, 1e-4, 1e-6), 1e-12, 500_000)
    assert res.converged and abs(res.pressure - 1e-4) <= 1e-6 * 1e-4
    final = ShapeModel(res.box, p.shapes, p.shape_index)
    ev = final.evaluate(final.dofs(res.position))
    assert final.max_force(ev.gradient) <= 1e-12


def _chain_engine(clusters, chain_length, seed, phi=None):
    """A 3D linked engine of chains with frozen angles (dilute start) and its cluster-order link arrays."""
    p = linked_packing(3, clusters, "chain", np.random.default_rng(seed), chain_length=chain_length, phi=phi)[0]
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    engine = LinkedFire(model, model.dofs(p.position), DEFAULT_FIRE)
    return model, engine


@pytest.mark.parametrize("chain_length", [4, 30])
def test_paired_projection_is_the_single_projection_bit_for_bit(chain_length):
    """The engine's projection of force and velocity together (flat loops, two solves side by side)
    takes each vector through the operations of the single projection: the same bits; the result
    is tangent (``Omega P g`` at round-off)."""
    model, e = _chain_engine(8, 4, 3) if chain_length == 4 else _chain_engine(4, 30, 3, phi=0.02)
    g = e.gram
    _link_kernels.gram_factor(e.w, g["sign"], g["first"], g["cptr"], g["fptr"], e.chol, LINK_RANK_RTOL)
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=e.x.shape), rng.normal(size=e.x.shape)
    single = [a.copy(), b.copy()]
    for v in single:
        _link_kernels.gram_project(e.w, g["ci"], g["cj"], g["first"], g["cptr"], g["fptr"], e.chol, v,
                                   np.empty(len(g["ci"])))
    _link_kernels.gram_project_pair(e.w, g["ci"], g["cj"], g["first"], g["cptr"], g["fptr"], e.chol, a, b)
    assert np.array_equal(a, single[0]) and np.array_equal(b, single[1])
    rows = np.empty(len(g["ci"]))
    _link_kernels.omega_apply(e.w, g["ci"], g["cj"], a, rows)
    assert np.abs(rows).max() <= 1e-14 * np.abs(a).max()


@pytest.mark.parametrize("size", [1e-4, 3e-2])
def test_engine_reaffixing_lands_on_the_manifold_next_to_newton(size):
    """The engine's re-affixing (chord sweeps on the last point's factors, Newton when a sweep does
    not quarter the error) after a tangent step of ``size``: links to LINK_LENGTH_RTOL, the Gram
    factors of the result, and the point of the flat model's Newton re-affixing to O(size^2)."""
    model, e = _chain_engine(8, 4, 5)
    g = e.gram
    _link_kernels.gram_factor(e.w, g["sign"], g["first"], g["cptr"], g["fptr"], e.chol, LINK_RANK_RTOL)
    step = np.random.default_rng(1).normal(size=e.x.shape)
    _link_kernels.gram_project(e.w, g["ci"], g["cj"], g["first"], g["cptr"], g["fptr"], e.chol, step,
                               np.empty(len(g["ci"])))
    x = e.x + size * step / np.abs(step).max()
    newton = model.positions(model.reproject(x.ravel()))
    sweeps, bad = _link_kernels.reaffix(x, g["ci"], g["cj"], g["offset"], g["length"], g["sign"], g["first"],
                                        g["cptr"], g["fptr"], e.chol, e.w, e.r, LINK_LENGTH_RTOL, 50, LINK_RANK_RTOL)
    assert bad == -1 and 1 <= sweeps <= 8
    assert np.abs(model.link_errors(x.ravel())).max() <= LINK_LENGTH_RTOL
    assert np.abs(x - newton).max() <= 10 * size**2
    w, r, chol = np.empty_like(e.w), np.empty_like(e.r), np.zeros_like(e.chol)
    _link_kernels.link_geometry(x, g["ci"], g["cj"], g["offset"], g["length"], w, r)
    np.testing.assert_allclose(e.w, w, rtol=0, atol=1e-15)
    np.testing.assert_allclose(e.r, r, rtol=1e-15, atol=0)
    _link_kernels.gram_factor(e.w, g["sign"], g["first"], g["cptr"], g["fptr"], chol, LINK_RANK_RTOL)
    assert np.array_equal(e.chol, chol)
