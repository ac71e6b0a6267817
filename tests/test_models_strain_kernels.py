"""Kernels of the shear-stabilised engine on 3D chains (Woodbury solve, deformed-frame forces, re-affixing)
against the flat model :class:`ShearStabilizedModel`, and its unrolled d = 3 loops against the generic ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.io import read_packing
from jamflow.minimize.fire import DEFAULT_FIRE, _fire
from jamflow.models import _strain_kernels as sk
from jamflow.models import _woodbury_kernels as wk
from jamflow.models._link_kernels import strain_state
from jamflow.models.strain import ShearStabilizedModel, StrainFire
from jamflow.tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL

DATA = Path(__file__).parent / "data" / "bodies"


def _squeezed(fixed_volume: bool, strain: float, f: float = 0.998):
    """The 3D chains of four (frozen angles, N = 128) squeezed by the length factor ``f`` (soft overlaps), at a
    random strain of about ``strain`` put back on the manifold, with a :class:`StrainFire` at that point."""
    p = read_packing(DATA / "hypostatic_chains4_3d.nc", None)
    s = p.in_units(float(p.diameter.mean()))
    model = ShearStabilizedModel(Box(s.box.matrix * f), s.diameter, s.links, s.position * f,
                                 fixed_volume=fixed_volume)
    q = model.dofs(s.position * f)
    q[-6:] += strain * model.strain_scale * np.random.default_rng(4).standard_normal(6)
    q = model.reproject(q)
    return model, q, StrainFire(model, q, DEFAULT_FIRE)


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
        np.zeros((6, 2)), LINK_LENGTH_RTOL, 50, LINK_RANK_RTOL, True)
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


def test_strain_engine_minimum_of_3d_chains_is_a_minimum_of_the_flat_model():
    """The compiled engine (the kernels above, each the flat model's operation to round-off) from the chains
    squeezed by 3 % and strained: a state the flat model finds force-balanced (its own projection), with
    links and volume held and the total stress isotropic to what the strain's force tolerance resolves."""
    model, q, engine = _squeezed(True, 0.005, 0.97)
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
