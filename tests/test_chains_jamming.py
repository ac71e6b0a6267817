"""Critically jammed linked packings (chains paper Secs. II-III): rigid-body motion, projection, links, counting."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.io import read_packing, write_packing
from jamflow.minimize.descent import minimize_sd
from jamflow.minimize.fire import minimize_fire
from jamflow.minimize.model import ModelEvaluation
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.model import SphereModel
from jamflow.network import count_bodies, isostatic_count
from jamflow.network.spheres import find_rattlers
from jamflow.state.bodies import Links
from jamflow.tolerances import LINK_LENGTH_RTOL


def _omega(model: LinkedSpheresModel, q: np.ndarray) -> np.ndarray:
    """Dense constraint Jacobian (L, N d) from the link vectors (Eq. 4 with the exact gradient)."""
    r = model.link_vectors(q)
    u = r / np.linalg.norm(r, axis=1)[:, None]
    out = np.zeros((len(model.links), model.n_dof)).reshape(len(model.links), model.n, model.d)
    k = np.arange(len(model.links))
    out[k, model.links.i] = -u
    out[k, model.links.j] = u
    return out.reshape(len(model.links), -1)


@pytest.mark.parametrize("d", [2, 3])
def test_projection_of_a_push_on_a_rigid_trimer_is_the_rigid_body_response(d):
    """P F on an isolated rigid trimer = t + omega x r with t = sum F / 3 and I omega = torque (unit masses)."""
    p, _ = linked_packing(d, 1, "trimer", np.random.default_rng(4), phi=0.01, no_overlap=False)
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    q = model.dofs(p.position)
    r = p.box.minimum_image(p.position - p.position[0])  # unwrapped across the boundary
    r -= r.mean(axis=0)
    force = np.random.default_rng(5).normal(size=(3, d))
    got = model.project(force.ravel(), q).reshape(3, d)
    t = force.mean(axis=0)
    if d == 2:
        inertia = np.sum(r**2)
        omega = np.sum(r[:, 0] * force[:, 1] - r[:, 1] * force[:, 0]) / inertia
        want = t + omega * np.stack([-r[:, 1], r[:, 0]], axis=1)
    else:
        inertia = np.sum(r**2) * np.eye(3) - r.T @ r
        omega = np.linalg.solve(inertia, np.cross(r, force).sum(axis=0))
        want = t + np.cross(omega, r)
    np.testing.assert_allclose(got, want, atol=1e-13 * np.abs(force).max())


class _Pushed(LinkedSpheresModel):
    """Linked spheres with a uniform external force ``push`` on every sphere (torque-free about the centroid)."""

    push = np.zeros(2)

    def evaluate(self, q):
        ev = super().evaluate(q)
        x = self.positions(q)
        return ModelEvaluation(ev.energy - float(np.sum(x @ self.push)), ev.gradient - np.tile(self.push, self.n),
                               ev.virial, ev.n_contacts)


def test_rigid_trimer_under_a_torque_free_push_translates_rigidly():
    p, _ = linked_packing(2, 1, "trimer", np.random.default_rng(6), phi=0.01, no_overlap=False)
    model = _Pushed(p.box, p.diameter, p.links, p.position)
    model.push = np.array([0.3, -0.2])
    steps, dt = 50, 0.1
    res = minimize_sd(model, p.position, dt=dt, force_tol=1e-300, max_steps=steps)
    assert res.steps == steps
    # explicit rigid-body motion: a pure translation by steps * dt * F (no rotation, no deformation)
    np.testing.assert_allclose(res.position, p.position + steps * dt * model.push, atol=1e-12)
    assert np.max(np.abs(model.link_errors(res.position.ravel()))) <= LINK_LENGTH_RTOL


@pytest.fixture(scope="module")
def jammed_trimers():
    start, _ = linked_packing(2, 12, "trimer", np.random.default_rng(1), no_overlap=False)
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    return start, jam_linked(start, 1e-4, settings=settings)


def test_jammed_rigid_trimers_are_force_balanced_on_the_manifold_and_isostatic(jammed_trimers):
    start, result = jammed_trimers
    p = result.packing
    assert result.converged and p.pressure == pytest.approx(1e-4, rel=1e-3)
    # every link held to the stated precision (mean diameter 1 already: lengths unchanged)
    np.testing.assert_allclose(p.links.length, start.links.length, rtol=1e-15)
    assert np.max(np.abs(p.links.length_errors(p.position, p.box))) <= LINK_LENGTH_RTOL
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    q = model.dofs(p.position)
    ev = model.evaluate(q)
    pf = model.project(ev.gradient, q)
    assert model.max_force(pf) <= 1e-13
    # the projected force is orthogonal to every constraint gradient (relative to the raw force)
    omega = _omega(model, q)
    assert np.max(np.abs(omega @ pf)) <= 1e-12 * np.linalg.norm(ev.gradient)
    # the raw gradient is not zero: the links carry the forces
    assert model.max_force(ev.gradient) > 1e3 * 1e-13
    # isostatic backbone of rigid trimers: N_c = 3 N_clusters - 2 + 1 after rattling clusters are removed
    count = count_bodies(p.contacts, p.n, 2, p.links, p.position, p.box)
    assert count.n_contacts == count.isostatic_count == 3 * (12 - count.removed.sum()) - count.free_dofs.sum() - 1
    assert p.attrs["n_contacts"] == count.n_contacts and np.array_equal(p.rattler, count.rattler)


def test_without_links_the_linked_model_is_the_sphere_model():
    p, _ = linked_packing(2, 10, "trimer", np.random.default_rng(2), no_overlap=False)
    empty = Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    linked = LinkedSpheresModel(p.box, p.diameter, empty, p.position)
    spheres = SphereModel(p.box, p.diameter)
    q = spheres.dofs(p.position)
    a, b = linked.evaluate(q), spheres.evaluate(q)
    assert a.energy == pytest.approx(b.energy, rel=1e-14) and a.n_contacts == b.n_contacts
    np.testing.assert_allclose(a.gradient, b.gradient, rtol=0, atol=1e-14 * np.abs(b.gradient).max())
    np.testing.assert_allclose(a.virial, b.virial, rtol=1e-13)
    ra, rb = minimize_fire(linked, p.position, 1e-12), minimize_fire(spheres, p.position, 1e-12)
    assert ra.energy == pytest.approx(rb.energy, rel=1e-9)
    # the cluster count of spheres is the sphere count: rattlers with < d + 1 contacts, d (N_s - 1) + 1
    rng = np.random.default_rng(0)
    c = np.unique(np.sort(rng.integers(0, 60, (150, 2)), axis=1), axis=0)
    c = c[c[:, 0] < c[:, 1]]
    count = count_bodies(c, 60, 2)
    rattler = find_rattlers(60, 2, c)
    assert np.array_equal(count.rattler, rattler)
    assert count.isostatic_count == isostatic_count(int((~rattler).sum()), 2, global_dofs=2)


def test_cli_soft_jam_and_check_of_a_linked_packing(tmp_path, capsys, jammed_trimers):
    start, result = jammed_trimers
    write_packing(start, tmp_path / "s.nc")
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "j.nc"), "--pressure", "1e-4",
                 "--pressure-rtol", "1e-3", "--delta-phi", "1e-2", "--quiet"]) == 0
    p = read_packing(tmp_path / "j.nc", None)
    # the same protocol as jam_linked: the same packing
    np.testing.assert_allclose(p.position, result.packing.position, atol=1e-12)
    assert main(["check", str(tmp_path / "j.nc"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_links"] == 36 and report["max_link_error"] <= LINK_LENGTH_RTOL
    assert report["n_contacts"] == report["isostatic_count"] and report["isostatic"] is True
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "x.nc"), "--pressure", "1e-4",
                 "--seed", "3"]) == 1
    assert "tear the links" in capsys.readouterr().err


def test_energy_scaling_protocol_ends_jammed_below_the_threshold(jammed_trimers, tmp_path, capsys):
    """Paper Sec. III: decompression by the energy scaling stops at 0 < U/N <= energy_tol, jammed and isostatic.

    The bisection of the same start at P0 = 1e-4 ends at U/N ~ 1e-8; with energy_tol 1e-10 the
    pressure must be lower (P ~ sqrt(U/N) for harmonic contacts: a factor ~10), the links held,
    and the backbone isostatic by the cluster count.
    """
    start, bisected = jammed_trimers
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    res = jam_linked(start, None, settings=settings, protocol="energy", energy_tol=1e-10)
    p = res.packing
    e = p.attrs["energy"] / p.n
    assert res.converged and 1e-14 < e <= 1e-10
    assert 0.0 < p.pressure < 0.3 * bisected.packing.pressure
    assert np.max(np.abs(p.links.length_errors(p.position, p.box))) <= LINK_LENGTH_RTOL
    assert p.attrs["n_contacts"] == p.attrs["isostatic_count"]
    # fewer minimisations than the bisection's halving steps
    assert len(res.history["phi"]) < len(bisected.history["phi"])
    write_packing(start, tmp_path / "s.nc")
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "e.nc"), "--jam-protocol", "energy",
                 "--energy-tol", "1e-10", "--force-tol", "1e-13", "--delta-phi", "1e-2", "--quiet"]) == 0
    np.testing.assert_allclose(read_packing(tmp_path / "e.nc", None).position, p.position, atol=1e-12)
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "x.nc"), "--jam-protocol", "energy"]) == 1
    assert "--energy-tol" in capsys.readouterr().err
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "x.nc")]) == 1
    assert "--pressure is required" in capsys.readouterr().err
    assert not (tmp_path / "x.nc").exists()
