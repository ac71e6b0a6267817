"""Compiled FIRE engines of bodies against the flat-vector FIRE on the same model and start."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from chain_starts import squeezed_chains

from jamflow.box import Box
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import linked_volume
from jamflow.minimize.fire import DEFAULT_FIRE, _fire, _ModelFire
from jamflow.models import _hinge_kernels, _link_kernels
from jamflow.models.box import EnthalpyModel
from jamflow.models.links import LinkedFire, LinkedSpheresModel, _rigid_clusters
from jamflow.models.shapes import _fire_kernels
from jamflow.models.shapes.fast import FAMILY_CODES, ShapeFire
from jamflow.models.shapes.model import ShapeModel
from jamflow.models.spheres.model import SphereModel
from jamflow.models.strain import ShearStabilizedModel, StrainFire
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape
from jamflow.state.bodies import Links
from jamflow.tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL


def _compressed_trimers(kind, phi, flexible=False):
    """20 rigid 2D trimers squeezed to ``phi``; ``flexible``: every second one loses its angle link (a chain of 3)."""
    p = linked_packing(2, 20, "trimer", np.random.default_rng(1))[0]
    s = p.in_units(float(p.diameter.mean()))
    links = s.links
    if flexible:
        keep = ~((links.i % 6 == 0) & (links.j == links.i + 2))
        links = Links(links.i[keep], links.j[keep], links.length[keep])
    box = Box(s.box.matrix)
    f = (linked_volume(2, s.diameter, links) / box.volume / phi) ** 0.5
    return kind(box.scaled(f), s.diameter, links, s.position * f), s.position * f


def test_linked_engine_reaches_the_flat_fire_minimum():
    """Rigid 2D trimers squeezed to phi = 0.86: the same minimum, energy to round-off, links held."""
    runs = []
    for fast in (True, False):
        model, x = _compressed_trimers(LinkedSpheresModel, 0.86)
        q = model.dofs(x)
        e = model.fire_engine(q, DEFAULT_FIRE) if fast else _ModelFire(model, q, DEFAULT_FIRE)
        assert isinstance(e, LinkedFire if fast else _ModelFire)
        runs.append(_fire(e, 1e-12, 200_000))
    a, b = runs
    assert a.converged and b.converged and b.energy > 0.0
    assert abs(a.energy - b.energy) <= 1e-12 * b.energy
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-8)


def _body_pressure(model, res):
    """Pressure of the contacts alone with every rigid trimer's contact forces taken about its centroid,
    ``tr(W - sum_s f_s r_s^T) / (d V)``: no link tensions (the rods' stress implicit in the rigid bodies)."""
    spheres = SphereModel(res.box, model.diameter)
    ev = spheres.evaluate(spheres.dofs(res.position))
    force = -ev.gradient.reshape(-1, 2)
    x = res.position.reshape(-1, 3, 2)
    r = res.box.minimum_image(x - x[:, :1]).reshape(-1, 2)
    r = (r.reshape(-1, 3, 2) - r.reshape(-1, 3, 2).mean(axis=1, keepdims=True)).reshape(-1, 2)
    return (np.trace(ev.virial) - np.sum(force * r)) / (2 * res.box.volume)


def _near_minimum(model, flat):
    """``q`` of a start near the minimum ``flat`` of a 2D strain model: centres moved by 0.02 and the three
    strains by 1e-3 (Gaussian, seed 5) in the model rebased on that minimum, put back on the manifold."""
    near, x = model.rescaled(1.0, flat.position)
    rng = np.random.default_rng(5)
    q = near.dofs(x)
    q[:-3] += 0.02 * rng.standard_normal(len(q) - 3)
    q[-3:] += 1e-3 * near.strain_scale * rng.standard_normal(3)
    return near.reproject(q)


@pytest.fixture(scope="module", params=[False, True], ids=["rigid", "mixed"])
def strain_minima(request):
    """The compiled shear-stabilised engine and the flat FIRE from one start near a minimum of squeezed 2D
    trimers (all rigid bodies, or half of them flexible chains of 3 on the Gram path), and from the squeezed start."""
    model, x = _compressed_trimers(ShearStabilizedModel, 0.86, request.param)
    flat = _fire(_ModelFire(model, model.dofs(x), DEFAULT_FIRE), 1e-12, 200_000)
    q = _near_minimum(model, flat)
    runs = []
    for fast in (True, False):
        m, _ = model.rescaled(1.0, flat.position)
        e = m.fire_engine(q, DEFAULT_FIRE) if fast else _ModelFire(m, q, DEFAULT_FIRE)
        runs.append((_fire(e, 1e-12, 200_000), m, e))
    model, x = _compressed_trimers(ShearStabilizedModel, 0.86, request.param)
    squeezed = model.fire_engine(model.dofs(x), DEFAULT_FIRE)
    return request.param, runs, (_fire(squeezed, 1e-12, 200_000), model, squeezed), flat


def test_strain_engine_with_rigid_bodies_reaches_the_flat_fire_minimum(strain_minima):
    """Rigid trimers as rigid bodies under strain: the flat FIRE's minimum from the same start (energy, strain,
    centres, pressure), force balance by the flat projection, links held; in the mixed packing the chains of 3
    stay on the Gram path."""
    flexible, ((a, ma, ea), (b, mb, eb)), _, _ = strain_minima
    assert isinstance(ea, StrainFire) and len(ea.vb) == (10 if flexible else 20)
    assert len(ea.gram["ci"]) == (20 if flexible else 0)
    assert a.converged and b.converged and b.energy > 0.0
    assert max(a.max_force, b.max_force) <= 1e-12
    assert abs(a.energy - b.energy) <= 1e-12 * b.energy
    np.testing.assert_allclose(ea.e, eb.q[-3:], rtol=0, atol=1e-8)
    np.testing.assert_allclose(a.box.matrix, b.box.matrix, rtol=0, atol=1e-8)
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-8)
    assert abs(a.pressure - b.pressure) <= 1e-9 * b.pressure
    assert np.abs(ma.link_errors(ea.q())).max() <= LINK_LENGTH_RTOL
    assert np.abs(mb.link_errors(eb.q)).max() <= LINK_LENGTH_RTOL
    assert abs(ma.volume(ea.q()) - ma.box.volume) <= LINK_LENGTH_RTOL * ma.box.volume
    if not flexible:
        assert abs(_body_pressure(ma, a) - a.pressure) <= 1e-9 * a.pressure


def test_flat_fire_reports_the_deformed_box_of_a_strained_minimum(strain_minima):
    """A minimiser's result carries the box of its final state: the deformed box of a shear-stabilised minimum,
    not the model's reference box."""
    flexible, (_, (b, mb, eb)), _, flat = strain_minima
    reference = _compressed_trimers(ShearStabilizedModel, 0.86, flexible)[0].box
    # the fixture's flat run from the squeezed start strained its box; mb was built on that run's last box
    assert np.abs(flat.box.matrix - reference.matrix).max() > 1e-3
    np.testing.assert_array_equal(flat.box.matrix, mb.box.matrix)
    np.testing.assert_array_equal(b.box.matrix, mb.current_box(eb.q).matrix)


def test_flat_fire_of_the_enthalpy_reports_the_pressure_of_its_own_box():
    """Flat FIRE on the enthalpy U + P0 V of free-volume shear-stabilised trimers: at force balance the box
    stress is P0, and the result's pressure (virial over the final box's volume) is P0 to the force tolerance."""
    model, x = _compressed_trimers(functools.partial(ShearStabilizedModel, fixed_volume=False), 0.86)
    p0 = 1e-2
    res = _fire(_ModelFire(EnthalpyModel(model, p0), model.dofs(x), DEFAULT_FIRE), 1e-12, 200_000)
    assert res.converged
    assert abs(res.box.volume - model.box.volume) > 1e-3 * model.box.volume
    assert res.box.volume == pytest.approx(model.last_box().volume, rel=1e-15)
    assert abs(res.pressure - p0) <= 1e-6 * p0


def test_strain_engine_enthalpy_force_is_minus_the_derivative_of_u_plus_p0_v():
    """The compiled loop's strain force with ``pressure0`` (volume free, spheres without links, so nothing is
    projected) against central differences of ``H = U + P0 V`` of the model's own energy and volume."""
    rng = np.random.default_rng(3)
    box = Box(np.array([[4.0, 0.7], [0.0, 4.3]]))
    D = np.where(np.arange(16) % 2 == 0, 1.0, 1.4)
    x = rng.uniform(0.0, 4.0, (16, 2))
    model = ShearStabilizedModel(box, D, Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)), x,
                                 fixed_volume=False)
    q = model.dofs(x)
    q[-3:] = model.strain_scale * np.array([0.02, -0.01, 0.03])
    p0 = 0.05
    engine = model.fire_engine(q, DEFAULT_FIRE, p0)
    assert isinstance(engine, StrainFire)
    engine.advance(1e-30, 0, False)  # one evaluation, no step

    def enthalpy(e):
        qe = q.copy()
        qe[-3:] = e
        return model.evaluate(qe).energy + p0 * model.volume(qe)

    h = 1e-5 * model.strain_scale
    numeric = np.array([-(enthalpy(q[-3:] + h * u) - enthalpy(q[-3:] - h * u)) / (2 * h) for u in np.eye(3)])
    assert model.evaluate(q).n_contacts > 0
    # the central differences' truncation error is O(h^2) of the third derivative
    np.testing.assert_allclose(engine.fe, numeric, rtol=1e-7, atol=1e-9 * np.abs(numeric).max())


@pytest.mark.parametrize("flexible", [False, True], ids=["rigid", "mixed"])
def test_strain_engine_enthalpy_reaches_the_flat_enthalpy_minimum(flexible):
    """The compiled engine on ``U + P0 V`` (volume free) and the flat FIRE of :class:`EnthalpyModel`, from one
    start near a minimum of ``H``: the same minimum (centres, box, enthalpy), the pressure P0 to the force
    tolerance, links held; the rigid trimers move as bodies, the flexible chains on the Gram path."""
    model, x = _compressed_trimers(functools.partial(ShearStabilizedModel, fixed_volume=False), 0.86, flexible)
    p0 = 1e-2
    flat = _fire(_ModelFire(EnthalpyModel(model, p0), model.dofs(x), DEFAULT_FIRE), 1e-12, 200_000)
    q = _near_minimum(model, flat)
    runs = []
    for fast in (True, False):
        m, _ = model.rescaled(1.0, flat.position)
        e = m.fire_engine(q, DEFAULT_FIRE, p0) if fast else _ModelFire(EnthalpyModel(m, p0), q, DEFAULT_FIRE)
        runs.append((_fire(e, 1e-12, 200_000), m, e))
    (a, ma, ea), (b, mb, eb) = runs
    assert isinstance(ea, StrainFire) and len(ea.vb) == (10 if flexible else 20)
    assert a.converged and b.converged
    assert max(a.max_force, b.max_force) <= 1e-12
    # the engine reports U, the flat FIRE of the wrapper U + P0 V
    assert abs(a.energy + p0 * a.box.volume - b.energy) <= 1e-12 * b.energy
    np.testing.assert_allclose(a.box.matrix, b.box.matrix, rtol=0, atol=1e-8)
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-8)
    assert abs(a.pressure - p0) <= 1e-9 * p0 and abs(b.pressure - p0) <= 1e-9 * p0
    assert np.abs(ma.link_errors(ea.q())).max() <= LINK_LENGTH_RTOL
    assert abs(a.box.volume - flat.box.volume) <= 1e-9 * flat.box.volume


def test_strain_engine_from_the_squeezed_start_reaches_a_valid_minimum(strain_minima):
    """From the squeezed start the rigid bodies' metric takes another path than the flat FIRE (docs/notes/chains.md):
    its minimum is force-balanced by the flat projection, with links and volume held."""
    flexible, _, (res, model, engine), flat = strain_minima
    q = engine.q()
    assert res.converged and flat.converged and res.energy > 0.0
    assert res.max_force <= 1e-12
    ev = model.evaluate(q)
    assert model.max_force(model.project(ev.gradient, q)) <= 1e-12
    assert np.abs(model.link_errors(q)).max() <= LINK_LENGTH_RTOL
    assert abs(model.volume(q) - model.box.volume) <= LINK_LENGTH_RTOL * model.box.volume
    if not flexible:
        assert abs(_body_pressure(model, res) - res.pressure) <= 1e-9 * res.pressure


def test_a_subclass_with_its_own_energy_keeps_the_flat_fire():
    class Loaded(ShearStabilizedModel):
        def evaluate(self, q):
            return super().evaluate(q)

    model, x = _compressed_trimers(Loaded, 0.86)
    assert model.fire_engine(model.dofs(x), DEFAULT_FIRE) is None


@pytest.mark.parametrize("family", ["ellipse", "circulo-line", "circulo-polygon", "reuleaux"])
def test_shape_engine_forces_and_minimum_match_the_model(family):
    """Compiled pair sums equal ShapeModel.evaluate; the engine's FIRE reaches the flat FIRE's minimum.

    The engine rotates each circulo body's vertices once per evaluation, the model once per pair side."""
    parameters = {"reuleaux": {}, "circulo-polygon": {"asphericity": 1.1, "sides": 5}}
    table = bidisperse_shapes(unit_shape(family, **parameters.get(family, {"asphericity": 1.3})))
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
    # the same steps: after 200 of them both engines are at the same state up to round-off (the two
    # sum the pair terms in different orders; warm-started Perram-Wertheim solves), which FIRE's
    # dynamics and restart decisions then amplify chaotically (largest difference of the four
    # families <= 2e-13 after 200 steps, 4e-12 ... 1e-9 after 400, up to 1e-7 after 900, with the
    # size depending on the processor's rounding), so the steps to force_tol may differ, but not the minimum
    a = _fire(ShapeFire(model, q, DEFAULT_FIRE, None, 0.0), 1e-12, 200)
    b = _fire(_ModelFire(model, q, DEFAULT_FIRE), 1e-12, 200)
    assert a.steps == b.steps == 200 and a.max_force > 1e-6
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-11)
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


def _chain_engine(clusters, chain_length, seed, phi=None, hinged=False):
    """A 3D linked engine of chains with frozen angles (dilute start) and its cluster-order link arrays
    (every cluster on the Gram path unless ``hinged``: then chains of four are hinged bodies)."""
    p = linked_packing(3, clusters, "chain", np.random.default_rng(seed), chain_length=chain_length, phi=phi)[0]
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    engine = LinkedFire(model, model.dofs(p.position), DEFAULT_FIRE, hinged=hinged)
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


def test_hinge_layout_finds_chains_of_four_with_frozen_angles():
    """Chains of four with frozen angles are hinged clusters ``(a, b, c, t)``: ``b - c`` the shared edge
    (linked to all three others), ``a`` and ``t`` the unlinked tips; free angles or longer chains are not."""
    model, e = _chain_engine(8, 4, 3, hinged=True)
    s = e.hinge["spheres"]
    assert s.shape == (8, 4) and len(e.gram["ci"]) == 0
    links = {tuple(sorted(k)) for k in zip(model.links.i.tolist(), model.links.j.tolist())}
    for a, b, c, t in s.tolist():
        assert {(min(p, q), max(p, q)) for p, q in ((a, b), (a, c), (b, c), (b, t), (c, t))} <= links
        assert (min(a, t), max(a, t)) not in links
    for kind in ({"free_angles": True}, {"chain_length": 5}):
        p = linked_packing(3, 4, "chain", np.random.default_rng(3), **{"chain_length": 4, **kind})[0]
        assert not len(LinkedSpheresModel(p.box, p.diameter, p.links, p.position).gram.hinge_layout["spheres"])


def test_hinge_projection_is_the_gram_projection():
    """The closed-form projection of hinged clusters (rigid motions and the torsion) is the Gram
    path's projection of the same links to round-off, for a force-like and a random vector."""
    model, e = _chain_engine(8, 4, 3, hinged=True)
    _, g = _rigid_clusters(model, e.x)
    w, r, chol = np.empty((len(g["ci"]), 3)), np.empty(len(g["ci"])), np.zeros_like(g["sign"])
    _link_kernels.link_geometry(e.x, g["ci"], g["cj"], g["offset"], g["length"], w, r)
    _link_kernels.gram_factor(w, g["sign"], g["first"], g["cptr"], g["fptr"], chol, LINK_RANK_RTOL)
    rng = np.random.default_rng(0)
    for vector in (rng.normal(size=e.x.shape), np.cross(e.x, rng.normal(size=3)) + rng.normal(size=3)):
        gram, hinge = vector.copy(), vector.copy()
        _link_kernels.gram_project(w, g["ci"], g["cj"], g["first"], g["cptr"], g["fptr"], chol, gram,
                                   np.empty(len(g["ci"])))
        _hinge_kernels.hinge_project(e.hinge["spheres"], e.hinge["geo"], hinge)
        assert np.abs(gram - hinge).max() <= 1e-14 * np.abs(vector).max()
        assert np.abs(gram).max() >= 0.1 * np.abs(vector).max()


def test_hinge_moves_hold_the_links_and_follow_the_tangent_step():
    """A move of the generalised coordinates by ``h P v`` is ``x + h P v`` to O(h^2), with no tangential
    term at that order (O(h^3), as the closest-point re-affixing of the Gram path), and 3000 random
    moves keep every link to round-off (no drift)."""
    model, e = _chain_engine(8, 4, 5, hinged=True)
    h = e.hinge
    rng = np.random.default_rng(1)
    v = rng.normal(size=e.x.shape)
    pv = v.copy()
    _hinge_kernels.hinge_project(h["spheres"], h["geo"], pv)
    misses, tangential = [], []
    for size in (1e-2, 1e-3):
        x, state, geo = e.x.copy(), h["state"].copy(), h["geo"].copy()
        _hinge_kernels.hinge_advance(h["spheres"], geo, state, v, size)
        _hinge_kernels.hinge_place(x, h["spheres"], h["shift"], h["body"], state, geo)
        miss = x - e.x - size * pv
        misses.append(np.abs(miss).max())
        _hinge_kernels.hinge_project(h["spheres"], h["geo"], miss)
        tangential.append(np.abs(miss).max())
    assert misses[1] <= 1e-4 * np.abs(pv).max() and misses[1] <= 0.02 * misses[0]  # O(h^2): 0.01 per decade
    assert tangential[1] <= 0.002 * tangential[0] and tangential[1] <= 0.02 * misses[1]  # O(h^3): 0.001 per decade
    x, state, geo = e.x.copy(), h["state"].copy(), h["geo"].copy()
    for _ in range(3000):
        _hinge_kernels.hinge_advance(h["spheres"], geo, state, rng.normal(size=x.shape), 0.05)
        _hinge_kernels.hinge_place(x, h["spheres"], h["shift"], h["body"], state, geo)
    assert np.abs(x - e.x).max() > 1.0
    assert np.abs(model.link_errors(x.ravel())).max() <= 1e-14


@pytest.mark.parametrize("mixed", [False, True], ids=["hinged", "mixed"])
def test_hinged_engine_reaches_the_gram_engine_minimum(mixed):
    """32 chains of four squeezed to phi = 0.66 (``mixed``: every second chain without its first angle
    link, a flexible chain on the Gram path beside the hinged ones): from a start near the Gram engine's
    minimum (moved by 1e-3 per coordinate) the hinged engine reaches the same minimum (energy to 1e-12,
    centres to 1e-7), converged by the model's own projection, links to LINK_LENGTH_RTOL."""
    model, x = squeezed_chains(LinkedSpheresModel, mixed)
    hinges = len(model.gram.hinge_layout["spheres"])
    assert hinges == (16 if mixed else 32)
    ref = _fire(LinkedFire(model, model.dofs(x), DEFAULT_FIRE, hinged=False), 1e-12, 200_000)
    q = model.reproject(ref.position.ravel() + 1e-3 * np.random.default_rng(4).normal(size=ref.position.size))
    runs = [_fire(LinkedFire(model, q, DEFAULT_FIRE, hinged=h), 1e-12, 200_000) for h in (True, False)]
    (a, b) = runs
    assert ref.converged and a.converged and b.converged and b.energy > 0.0
    assert a.max_force <= 1e-12 and np.abs(model.link_errors(a.position.ravel())).max() <= LINK_LENGTH_RTOL
    assert abs(a.energy - b.energy) <= 1e-12 * b.energy
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-7)
