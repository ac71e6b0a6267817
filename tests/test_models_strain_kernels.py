"""Kernels of the shear-stabilised engine on 3D chains (Woodbury solve, deformed-frame forces, re-affixing)
against the flat model :class:`ShearStabilizedModel`, and its unrolled d = 3 loops against the generic ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from chain_starts import squeezed_chains

from jamflow.box import Box
from jamflow.io import read_packing
from jamflow.minimize.fire import DEFAULT_FIRE, _fire, _ModelFire
from jamflow.models import _hinge_kernels as hk
from jamflow.models import _strain_kernels as sk
from jamflow.models import _woodbury_kernels as wk
from jamflow.models._link_kernels import strain_state
from jamflow.models.spheres import _kernels
from jamflow.models.strain import ShearStabilizedModel, StrainFire
from jamflow.state.bodies import Links
from jamflow.tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL

DATA = Path(__file__).parent / "data" / "bodies"


def _squeezed(fixed_volume: bool, strain: float, f: float = 0.998, hinged: bool = False):
    """The 3D chains of four (frozen angles, N = 128) squeezed by the length factor ``f`` (soft overlaps), at a
    random strain of about ``strain`` put back on the manifold, with a :class:`StrainFire` at that point (its
    chains on the Gram/Woodbury path unless ``hinged``)."""
    p = read_packing(DATA / "hypostatic_chains4_3d.nc", None)
    s = p.in_units(float(p.diameter.mean()))
    model = ShearStabilizedModel(Box(s.box.matrix * f), s.diameter, s.links, s.position * f,
                                 fixed_volume=fixed_volume)
    q = model.dofs(s.position * f)
    q[-6:] += strain * model.strain_scale * np.random.default_rng(4).standard_normal(6)
    q = model.reproject(q)
    return model, q, StrainFire(model, q, DEFAULT_FIRE, hinged=hinged)


def _solved(model, engine):
    """The engine's geometry and factorisation at its point (:func:`strain_links`, :func:`strain_solver`)."""
    g, y, e = engine.gram, engine.y, engine.e
    n_links, d, m = len(g["ci"]), 3, 6
    F, Q, T, U, det, Finv = strain_state(e, model._h0, model.strain_scale)
    a = {"R0": np.zeros((n_links, d)), "u": np.zeros((n_links, d)), "rl": np.zeros(n_links),
         "w": np.zeros((n_links, d)), "Be": np.zeros((n_links, m)), "Z": np.zeros((n_links, m)),
         "S": np.zeros((m, m)), "ce": np.zeros(m), "sce": np.zeros(m), "chol": np.zeros_like(g["sign"]),
         "pinv": np.zeros(n_links), "F": F, "Q": Q, "T": T}
    sk.strain_links(y, F, g["ci"], g["cj"], g["offset"], g["length"], a["R0"], a["u"], a["rl"])
    bad, a["small"], a["schur"] = wk.strain_solver(
        F, det, Finv, a["R0"], a["u"], g["sign"], g["first"], g["cptr"], g["fptr"], a["chol"], a["pinv"], a["w"],
        a["Be"], a["Z"], a["S"], a["ce"], a["sce"], model.strain_scale, LINK_RANK_RTOL)
    assert bad == -1
    return a


@pytest.fixture(scope="module", params=[True, False], ids=["fixed-volume", "free-volume"])
def strained(request):
    model, q, engine = _squeezed(request.param, 0.02)
    return request.param, model, q, engine, _solved(model, engine)


def test_woodbury_projection_is_the_flat_models_projection(strained):
    """Force and velocity projected together by the engine's Woodbury/Schur solve on the forward-solved strain
    columns: the flat model's projection (dense solves of its own) to round-off, tangent to links and volume."""
    fixed, model, q, engine, a = strained
    g = engine.gram
    rng = np.random.default_rng(1)
    vectors = rng.standard_normal((2, model.n_dof))
    flat = [model.project(v, q) for v in vectors]
    gy, vy = (np.ascontiguousarray(v[:-6].reshape(-1, 3)) for v in vectors)
    ge, ve = (v[-6:].copy() for v in vectors)
    wk.strain_project_pair(a["w"], a["Z"], a["S"], a["small"], a["ce"], a["sce"], a["schur"], fixed, g["ci"], g["cj"],
                           g["first"], g["cptr"], g["fptr"], a["chol"], a["pinv"], gy, ge, vy, ve,
                           np.zeros((len(g["ci"]), 2)), np.zeros((6, 2)), np.zeros((6, 2)))
    for ours, theirs in zip((np.concatenate([gy.ravel(), ge]), np.concatenate([vy.ravel(), ve])), flat):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-13 * np.abs(theirs).max())
        rows, volume = model._gamma_t(q, ours)
        assert np.abs(rows).max() <= 1e-13 and abs(volume) <= (1e-13 if fixed else np.inf)


def test_deformed_frame_forces_are_the_flat_models_gradient(strained):
    """Pair forces formed in the deformed frame from the reference pair vectors: the flat model's energy,
    contacts and gradient on centres and strain."""
    _, model, q, engine, a = strained
    ev = model.evaluate(q)
    fy, fe, force = np.zeros((model.n, 3)), np.zeros(6), np.zeros((model.n, 3))
    energy, n_contact = sk.strain_forces(engine.y, a["Q"], a["T"], np.linalg.inv(a["F"]), model.strain_scale,
                                         model._offset, model._pi, model._pj, model._sigma, model.potential.epsilon,
                                         model.potential.exponent, force, fy, fe)
    assert ev.energy > 0.0 and n_contact == ev.n_contacts > 0
    assert abs(energy - ev.energy) <= 1e-13 * ev.energy
    ours = -np.concatenate([fy.ravel(), fe])
    np.testing.assert_allclose(ours, ev.gradient, rtol=0, atol=1e-13 * np.abs(ev.gradient).max())


@pytest.mark.parametrize("size", [1e-4, 3e-2])
def test_reaffixing_lands_on_the_manifold_next_to_newton(strained, size):
    """The engine's re-affixing of links and volume after a tangent step of ``size`` (chord sweeps on the
    point's factors): links and volume to LINK_LENGTH_RTOL, the flat model's Newton point to O(size^2)."""
    fixed, model, q, engine, a = strained
    g = engine.gram
    step = model.project(np.random.default_rng(2).standard_normal(model.n_dof), q)
    q2 = q + size * step / np.abs(step).max()
    newton = model.reproject(q2)
    y, e = np.ascontiguousarray(q2[:-6].reshape(-1, 3)), q2[-6:].copy()
    b = {k: np.array(v) for k, v in a.items()}
    sweeps, err, bad, _, _ = sk.strain_reaffix(
        y, e, model._h0, model.strain_scale, fixed, g["ci"], g["cj"], g["offset"], g["length"], g["sign"],
        g["first"], g["cptr"], g["fptr"], b["chol"], b["pinv"], b["R0"], b["u"], b["rl"], b["w"], b["Be"], b["Z"],
        b["S"], b["ce"], b["sce"], b["small"], float(b["schur"]), np.zeros((len(g["ci"]), 2)), np.zeros((6, 2)),
        np.zeros((6, 2)), LINK_LENGTH_RTOL, 50, LINK_RANK_RTOL)
    ours = np.concatenate([y.ravel(), e])
    assert bad == -1 and 1 <= sweeps <= 8 and err <= LINK_LENGTH_RTOL
    assert np.abs(model.link_errors(ours)).max() <= LINK_LENGTH_RTOL
    assert abs(model.volume_error(ours)) <= LINK_LENGTH_RTOL
    assert np.abs(ours - newton).max() <= 10 * size**2


def test_unrolled_loops_are_the_generic_loops_bit_for_bit(strained):
    """The d = 3 (m = 6) loops with the components in registers take the generic loops' operations in
    their order: link geometry, rows and strain columns, Z and S, forward and back substitutions."""
    _, model, q, engine, a = strained
    g = engine.gram
    n_links = len(g["ci"])
    args = (engine.y, a["F"], g["ci"], g["cj"], g["offset"], g["length"])
    links = [[np.zeros((n_links, 3)), np.zeros((n_links, 3)), np.zeros(n_links)] for _ in range(2)]
    errs = [sk._strain_links(*args, *links[0]), sk._strain_links_3d(*args, *links[1])]
    assert errs[0] == errs[1] and all(np.array_equal(x, y) for x, y in zip(*links))
    on, off = 1.0 / model.strain_scale, 1.0 / (np.sqrt(2.0) * model.strain_scale)
    rows = [[np.zeros((n_links, 3)), np.zeros((n_links, 6))] for _ in range(2)]
    wk._rows(a["F"], a["R0"], a["u"], on, off, *rows[0])
    wk._rows_3d(a["F"], a["R0"], a["u"], on, off, *rows[1])
    assert all(np.array_equal(x, y) for x, y in zip(*rows))
    factors = (g["first"], g["cptr"], g["fptr"], a["chol"], a["pinv"])
    zs = [[np.zeros((n_links, 6)), np.zeros((6, 6))] for _ in range(2)]
    wk._z_rows(*factors, a["Be"], *zs[0])
    wk._z_rows_6(*factors, a["Be"], *zs[1])
    assert np.array_equal(zs[0][0], zs[1][0]) and np.array_equal(np.triu(zs[0][1]), np.triu(zs[1][1]))
    rng = np.random.default_rng(3)
    for ncol in (1, 2):
        z0, q0 = rng.standard_normal((n_links, 2)), rng.standard_normal((6, 2))
        out = [[z0.copy(), np.zeros((6, 2))] for _ in range(2)]
        wk._forward(*factors, a["Z"], *out[0], ncol)
        wk._forward_6(*factors, a["Z"], *out[1], ncol)
        assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
        back = [z0.copy(), z0.copy()]
        wk._back(*factors, a["Z"], back[0], q0, ncol)
        wk._back_6(*factors, a["Z"], back[1], q0, ncol)
        assert np.array_equal(back[0], back[1]) and not np.array_equal(back[0], z0)


@pytest.mark.parametrize("hinged", [False, True], ids=["gram", "hinged"])
def test_strain_engine_minimum_of_3d_chains_is_a_minimum_of_the_flat_model(hinged):
    """The compiled engine (the kernels above, each the flat model's operation to round-off; or the chains as
    hinged bodies) from the chains squeezed by 3 % and strained: a state the flat model finds force-balanced
    (its own projection), with links and volume held and the total stress isotropic to what the strain's
    force tolerance resolves; with hinged bodies the contacts' pressure about each chain's sphere ``b`` (no
    link tensions: the rods' stress implicit in the bodies) is the flat evaluation's, tensions included."""
    model, q, engine = _squeezed(True, 0.005, 0.97, hinged)
    assert len(engine.vh) == (0 if not hinged else 128) and len(engine.gram["ci"]) == (160 if not hinged else 0)
    res = _fire(engine, 1e-12, 200_000)
    qa = engine.q()
    ev = model.evaluate(qa)
    assert res.converged and ev.energy > 0.0 and abs(res.energy - ev.energy) <= 1e-13 * ev.energy
    assert model.max_force(model.project(ev.gradient, qa)) <= 1e-12
    assert np.abs(model.link_errors(qa)).max() <= LINK_LENGTH_RTOL
    assert abs(model.volume_error(qa)) <= LINK_LENGTH_RTOL
    # |dU/de| <= F_tol bounds the deviatoric stress (pairs and link tensions) by ~sqrt(2) F_tol q_s / V
    volume = model.volume(qa)
    stress = -ev.virial / volume
    deviator = stress - np.trace(stress) / 3 * np.eye(3)
    assert -np.trace(stress) / 3 > 0.0
    assert np.abs(deviator).max() <= 2e-12 * model.strain_scale / volume
    if hinged:
        assert abs(_body_pressure(model, qa, engine.hinge) - res.pressure) <= 1e-9 * res.pressure


def _body_pressure(model, q, hinge):
    """``tr(W - sum_s f_s r_s^T) / (3 V)`` of hinged chains: the pair virial ``W`` and the contact forces
    ``f_s`` (real space) with the offsets ``r_s`` from each chain's sphere ``b``, no link tensions."""
    _, Q, T, _, _, F_inv = strain_state(q[-6:], model._h0, model.strain_scale)
    y = q[:-6].reshape(-1, 3)
    force, virial = np.zeros_like(y), np.zeros((3, 3))
    model.evaluate(q)  # the model's list at q
    _kernels.pair_forces_affine(y, T, model._offset, model._pi, model._pj, model._sigma, model.potential.epsilon,
                                model.potential.exponent, force, virial)
    f = force @ T @ F_inv  # -dU/dx in the unrotated frame: F^-T (T^T force)
    unwrapped = y[hinge["spheres"]] + hinge["shift"]
    r = (unwrapped - unwrapped[:, 1:2]) @ (Q @ T).T  # F (y_s + shift_s - y_b)
    return (np.trace(virial) - np.sum(f[hinge["spheres"]] * r)) / (3 * model.volume(q))


def _placed(model, engine, origin, state, e):
    """``q`` of hinged bodies with reference origins ``origin``, rotation and torsion ``state``, strain ``e``."""
    h = engine.hinge
    y, r, geo = engine.y.copy(), np.zeros_like(h["r"]), np.zeros_like(h["geo"])
    F_inv = strain_state(e, model._h0, model.strain_scale)[5]
    hk.hinge_place(r, h["local"], h["zero"], h["body"], state, geo)
    sk.hinge_strain_place(y, F_inv, h["spheres"], h["shift"], origin, r)
    return np.concatenate([y.ravel(), e])


def _turned(state, h, axis, angle):
    """``state`` with body ``h`` turned by ``angle`` about the real ``axis`` (through its sphere ``b``)."""
    out = state.copy()
    b = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * np.eye(3)[axis]])
    q = state[h, 3:7]
    out[h, 3:7] = [b[0] * q[0] - b[1:] @ q[1:], *(b[0] * q[1:] + q[0] * b[1:] + np.cross(b[1:], q[1:]))]
    return out


def _twisted(state, h, angle):
    """``state`` with body ``h``'s torsion turned by ``angle``."""
    out = state.copy()
    c, s = state[h, 7], state[h, 8]
    out[h, 7], out[h, 8] = c * np.cos(angle) - s * np.sin(angle), s * np.cos(angle) + c * np.sin(angle)
    return out


def test_hinged_generalised_forces_are_central_differences_of_the_flat_energy():
    """The engine's forces on strained, overlapping chains as hinged bodies (its loop's evaluation, projected
    onto the bodies' motions): translation of ``b``'s reference centre ``F^T sum f_s``, torque about ``b``,
    torsion ``f_t . (e x (y_t - y_b))`` and the strain at fixed bodies (``-dU/dF`` less ``sum f_s rho_s^T``)
    against central differences of the flat model's energy along each coordinate (free volume: the strain
    force unprojected)."""
    model, q, engine = _squeezed(False, 0.02, hinged=True)
    h = engine.hinge
    engine.advance(1e-12, 0, False)
    F = strain_state(engine.e, model._h0, model.strain_scale)[0]
    assert np.abs(engine.fy).max() == 0.0 and np.abs(engine.fh).max() > 1e-2
    energy = model.evaluate(engine.q()).energy
    origin, state, e = h["origin"], h["state"], engine.e
    assert np.abs(_placed(model, engine, origin, state, e) - engine.q()).max() <= 1e-13

    def slope(moved, size):
        return (model.evaluate(moved(size)).energy - model.evaluate(moved(-size)).energy) / (2 * size)

    fh, r = engine.fh.reshape(-1, 4, 3), h["r"].reshape(-1, 4, 3)
    ours, theirs = [], []
    for b in (0, 7, 19):
        for a in range(3):
            step = np.zeros_like(origin)
            step[b, a] = 1.0
            theirs.append(-slope(lambda t: _placed(model, engine, origin + t * step, state, e), 1e-6))
            ours.append((F.T @ fh[b].sum(axis=0))[a])
            theirs.append(-slope(lambda t: _placed(model, engine, origin, _turned(state, b, a, t), e), 1e-6))
            ours.append(np.sum(np.cross(np.eye(3)[a], r[b]) * fh[b]))
        theirs.append(-slope(lambda t: _placed(model, engine, origin, _twisted(state, b, t), e), 1e-6))
        ours.append(fh[b, 3] @ h["geo"][b, 27:30])
    for p in range(6):
        theirs.append(-slope(lambda t: _placed(model, engine, origin, state, e + t * np.eye(6)[p]), 1e-6))
        ours.append(engine.fe[p])
    ours, theirs = np.array(ours), np.array(theirs)
    assert np.abs(theirs).min() > 1e-3 and energy > 0.0
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-7 * np.abs(theirs).max())


def test_hinged_moves_under_strain_hold_the_links():
    """Hinged bodies moved by ``h P v`` and the strain changed at random, 2000 times: the real-space move of
    every sphere is ``h P v`` to first order (at fixed strain), and every link holds to round-off (no drift)."""
    model, q, engine = _squeezed(True, 0.02, hinged=True)
    h = engine.hinge
    rng = np.random.default_rng(2)
    e = engine.e.copy()
    state, origin, r, geo = h["state"].copy(), h["origin"].copy(), h["r"].copy(), h["geo"].copy()
    F, F_inv = (strain_state(e, model._h0, model.strain_scale)[k] for k in (0, 5))
    v = rng.standard_normal(r.shape)
    pv = v.copy()
    hk.hinge_project(h["local"], geo, pv)
    x0 = engine.y[h["spheres"]].reshape(-1, 3) @ F.T
    misses = []
    for size in (1e-3, 1e-4):
        s, o, rr, g = state.copy(), origin.copy(), r.copy(), geo.copy()
        sk.hinge_strain_advance(h["local"], g, s, o, rr, h["zero"], h["body"], F_inv, v, size)
        y = _placed(model, engine, o, s, e)[:-6].reshape(-1, 3)
        misses.append(np.abs(y[h["spheres"]].reshape(-1, 3) @ F.T - x0 - size * pv).max())
    assert misses[1] <= 1e-3 * np.abs(pv).max() * 1e-4 and misses[1] <= 0.02 * misses[0]
    for _ in range(2000):
        e = engine.e + 0.02 * model.strain_scale * rng.standard_normal(6)
        F_inv = strain_state(e, model._h0, model.strain_scale)[5]
        sk.hinge_strain_advance(h["local"], geo, state, origin, r, h["zero"], h["body"], F_inv,
                                rng.standard_normal(r.shape), 0.05)
    qa = _placed(model, engine, origin, state, e)
    assert np.abs(qa - engine.q()).max() > 1.0
    assert np.abs(model.link_errors(qa)).max() <= 1e-14


@pytest.mark.parametrize("mixed", [False, True], ids=["hinged", "mixed"])
def test_hinged_engine_reaches_the_flat_fire_minimum(mixed):
    """32 chains of four squeezed to phi = 0.66 (``mixed``: every second chain without its first angle link, a
    flexible chain on the Gram/Woodbury path beside the hinged ones): from a start near a minimum (the engine's
    minimum moved by 1e-3 per coordinate and 1e-4 in strain) the engine with hinged bodies reaches the flat
    FIRE's minimum: energy, strain, box, pressure, and the centres up to a common translation (a zero mode,
    which another metric moves along); links and volume held."""
    model, x = squeezed_chains(ShearStabilizedModel, mixed)
    start = _fire(StrainFire(model, model.dofs(x), DEFAULT_FIRE), 1e-12, 200_000)
    rng = np.random.default_rng(5)
    near, x = model.rescaled(1.0, start.position)
    q = near.dofs(x)
    q[:-6] += 1e-3 * rng.standard_normal(len(q) - 6)
    q[-6:] += 1e-4 * near.strain_scale * rng.standard_normal(6)
    q = near.reproject(q)
    runs = []
    for fast in (True, False):
        m, _ = model.rescaled(1.0, start.position)
        e = StrainFire(m, q, DEFAULT_FIRE) if fast else _ModelFire(m, q, DEFAULT_FIRE)
        runs.append((_fire(e, 1e-12, 200_000), e))
    (a, ea), (b, eb) = runs
    assert len(ea.vh) == (64 if mixed else 128) and len(ea.gram["ci"]) == (64 if mixed else 0)
    assert start.converged and a.converged and b.converged and b.energy > 0.0
    assert max(a.max_force, b.max_force) <= 1e-12
    # the volume holds to LINK_LENGTH_RTOL: energies differ by the work P dV of what it leaves (~1e-13 relative)
    assert abs(a.energy - b.energy + a.pressure * (a.box.volume - b.box.volume)) <= 1e-13 * b.energy
    assert abs(a.pressure - b.pressure) <= 1e-9 * b.pressure
    np.testing.assert_allclose(ea.e, eb.q[-6:], rtol=0, atol=1e-9 * model.strain_scale)
    np.testing.assert_allclose(a.box.matrix, b.box.matrix, rtol=0, atol=1e-10)
    shift = a.position - b.position
    assert np.abs(shift - shift.mean(axis=0)).max() <= 1e-9
    assert np.abs(m.link_errors(ea.q())).max() <= LINK_LENGTH_RTOL
    assert abs(m.volume_error(ea.q())) <= LINK_LENGTH_RTOL


@pytest.mark.parametrize("d", [2, 3])
def test_affine_pair_forces_unrolled_are_the_generic_loop_bit_for_bit(d):
    """The unrolled d = 2, 3 pair loop of ``x = A y`` (used by the shear-stabilised engines) takes the
    generic loop's operations in its order, and both give the harmonic forces and virial of numpy."""
    from jamflow.models.spheres import _kernels as sph

    rng = np.random.default_rng(11)
    n = 40
    y = rng.random((n, d)) * 3.0
    A = np.triu(np.eye(d) + 0.2 * rng.standard_normal((d, d)))
    pi, pj = (a.astype(np.int64) for a in np.triu_indices(n, 1))
    offset = rng.integers(-1, 2, (len(pi), d)) * 3.0
    sigma = np.full(len(pi), 1.2)
    out = []
    for kernel in (sph.pair_forces_affine, sph._affine_pairs_generic):
        force, virial = np.zeros((n, d)), np.zeros((d, d))
        energy, n_contact = kernel(y, A, offset, pi, pj, sigma, 1.0, 2.0, force, virial)
        out.append((energy, n_contact, force, virial))
    (e0, c0, f0, v0), (e1, c1, f1, v1) = out
    assert c0 == c1 > 0 and e0 == e1 and np.array_equal(f0, f1) and np.array_equal(v0, v1)
    dx = (y[pj] - y[pi] + offset) @ A.T
    r = np.linalg.norm(dx, axis=1)
    on = r < sigma
    f = ((1.0 - r / sigma) / sigma / r)[on, None] * dx[on]  # harmonic: -dU/dr / r along the pair vector
    ref = np.zeros((n, d))
    np.add.at(ref, pj[on], f)
    np.add.at(ref, pi[on], -f)
    assert c0 == on.sum() and e0 == pytest.approx(0.5 * np.sum((1.0 - r[on] / sigma[on]) ** 2), rel=1e-12)
    np.testing.assert_allclose(f0, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    np.testing.assert_allclose(v0, f.T @ dx[on], rtol=0, atol=1e-12 * np.abs(v0).max())


def test_a_straight_hinge_is_refused_as_degenerate():
    """A chain of four on a line with both angle links (a hinged cluster whose links are redundant) is refused
    with the Gram path's rank error before the engine moves it as a body."""
    x = np.array([[1.0, 1, 1], [2, 1, 1], [3, 1, 1], [4, 1, 1], [1, 4, 4], [2, 4, 4]])
    links = Links(np.array([0, 1, 2, 0, 1]), np.array([1, 2, 3, 2, 3]), np.array([1.0, 1, 1, 2, 2]))
    model = ShearStabilizedModel(Box(7.0 * np.eye(3)), np.ones(6), links, x)
    assert model.gram.hinge_layout["spheres"].tolist() == [[0, 1, 2, 3]]
    with pytest.raises(ValueError, match="degenerate"):
        StrainFire(model, model.dofs(x), DEFAULT_FIRE)
