"""Compiled FIRE engines of bodies against the flat-vector FIRE on the same model and start."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import linked_volume
from jamflow.minimize.fire import DEFAULT_FIRE, _fire, _ModelFire
from jamflow.models.links import LinkedFire, LinkedSpheresModel
from jamflow.models.shapes import _fire_kernels
from jamflow.models.shapes.fast import FAMILY_CODES, ShapeFire
from jamflow.models.shapes.model import ShapeModel
from jamflow.models.strain import ShearStabilizedModel, StrainFire
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape


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
    # the same steps: after 400 of them both engines are at the same state up to amplified round-off
    # (warm-started Perram-Wertheim solves); later FIRE's restart decisions amplify it (the
    # ellipses differ by 2e-14 after 200 steps, 1e-11 after 400, 1e-7 after 900), so the steps to
    # force_tol may differ, but not the minimum
    a = _fire(ShapeFire(model, q, DEFAULT_FIRE, None, 0.0), 1e-12, 400)
    b = _fire(_ModelFire(model, q, DEFAULT_FIRE), 1e-12, 400)
    assert a.steps == b.steps == 400 and a.max_force > 1e-6
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-9)
    a = _fire(ShapeFire(model, q, DEFAULT_FIRE, None, 0.0), 1e-12, 200_000)
    b = _fire(_ModelFire(model, q, DEFAULT_FIRE), 1e-12, 200_000)
    assert a.converged and b.converged
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
