"""Shear stabilisation of linked packings (chains paper Sec. II D-E): derivatives, projection, isotropic stress."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import jam_linked
from jamflow.minimize.onset import JammingSettings
from jamflow.models.spheres.model import SphereModel
from jamflow.models.strain import ShearStabilizedModel
from jamflow.network import count_bodies
from jamflow.state.bodies import Links
from jamflow.tolerances import LINK_LENGTH_RTOL


def _model(seed: int = 3, strain: float = 0.02):
    p, _ = linked_packing(2, 8, "trimer", np.random.default_rng(seed), no_overlap=False)
    model = ShearStabilizedModel(p.box, p.diameter, p.links, p.position)
    q = model.dofs(p.position)
    q[-model.m:] = np.random.default_rng(seed + 1).normal(scale=strain * model.strain_scale, size=model.m)
    return model, q


def _constraints(model: ShearStabilizedModel, q: np.ndarray) -> np.ndarray:
    return np.r_[np.linalg.norm(model.link_vectors(q), axis=1) - model.links.length, model.volume_error(q)]


def test_energy_gradient_and_constraint_gradients_match_finite_differences():
    """At a finite strain, dU/dq (centres and strain, Eq. 22) and Gamma (Eqs. 15-17) against central differences."""
    model, q = _model()
    ev = model.evaluate(q)
    assert ev.n_contacts > 10
    rng = np.random.default_rng(7)
    h = 1e-6
    for _ in range(5):
        v = rng.normal(size=q.size)
        v /= np.linalg.norm(v)
        num = (model.evaluate(q + h * v).energy - model.evaluate(q - h * v).energy) / (2 * h)
        assert num == pytest.approx(ev.gradient @ v, rel=1e-6, abs=1e-10)
        # Gamma^T v against the change of every constraint
        dc = (_constraints(model, q + h * v) - _constraints(model, q - h * v)) / (2 * h)
        links, vol = model._gamma_t(q, v)
        np.testing.assert_allclose(np.r_[links, vol], dc, atol=1e-8)
    # the strain block alone: a pure strain direction
    v = np.zeros(q.size)
    v[-model.m:] = rng.normal(size=model.m)
    num = (model.evaluate(q + h * v).energy - model.evaluate(q - h * v).energy) / (2 * h)
    assert num == pytest.approx(ev.gradient @ v, rel=1e-6)


def test_projection_is_orthogonal_to_every_constraint_gradient_and_idempotent():
    model, q = _model()
    g = np.random.default_rng(2).normal(size=q.size)
    pg = model.project(g, q)
    links, vol = model._gamma_t(q, pg)
    assert max(np.max(np.abs(links)), abs(vol)) <= 1e-12 * np.linalg.norm(g)
    np.testing.assert_allclose(model.project(pg, q), pg, atol=1e-13 * np.linalg.norm(g))
    # Newton re-affixing brings links and volume back from a perturbation
    r = model.reproject(q + np.random.default_rng(3).normal(scale=1e-3, size=q.size))
    assert np.max(np.abs(model.link_errors(r))) <= LINK_LENGTH_RTOL
    assert abs(model.volume_error(r)) <= LINK_LENGTH_RTOL


def test_without_links_at_zero_strain_the_positions_part_is_the_sphere_model():
    p, _ = linked_packing(2, 8, "trimer", np.random.default_rng(4), no_overlap=False)
    empty = Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    model = ShearStabilizedModel(p.box, p.diameter, empty, p.position)
    spheres = SphereModel(p.box, p.diameter)
    a = model.evaluate(model.dofs(p.position))
    b = spheres.evaluate(spheres.dofs(p.position))
    assert a.energy == pytest.approx(b.energy, rel=1e-14)
    np.testing.assert_allclose(a.gradient[: -model.m], b.gradient, atol=1e-14 * np.abs(b.gradient).max())
    np.testing.assert_allclose(a.virial, b.virial, rtol=1e-13)



def test_shear_stabilised_spheres_without_links_project_onto_fixed_volume():
    """Regression (empty link Gram solve): spheres alone project only the volume row, Tr-free strain forces.

    The projected strain force is orthogonal to grad det F = (1, 0, 1) / q_s at zero strain,
    the centre part is untouched, and a strain off the volume manifold is re-affixed to det F = 1.
    """
    p, _ = linked_packing(2, 8, "trimer", np.random.default_rng(4), no_overlap=False)
    empty = Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    model = ShearStabilizedModel(p.box, p.diameter, empty, p.position)
    q = model.dofs(p.position)
    g = np.random.default_rng(5).normal(size=model.n_dof)
    pg = model.project(g, q)
    np.testing.assert_array_equal(pg[: -model.m], g[: -model.m])
    assert abs(pg[-3] + pg[-1]) <= 1e-14 * np.abs(g).max()
    assert pg[-2] == g[-2]
    q[-3] += 0.01 * model.strain_scale
    assert abs(model.volume_error(model.reproject(q))) <= LINK_LENGTH_RTOL


@pytest.fixture(scope="module")
def stabilized():
    start, _ = linked_packing(2, 8, "trimer", np.random.default_rng(1), phi=0.3, no_overlap=True)
    settings = JammingSettings(force_tol=1e-11, pressure_rtol=1e-2, delta_phi=1e-2)
    return start, jam_linked(start, 1e-4, settings=settings, shear_stabilize=True)


def test_shear_stabilized_trimers_have_vanishing_strain_forces_and_isotropic_stress(stabilized):
    start, result = stabilized
    p = result.packing
    assert result.converged
    # the last minimisation is the enthalpy's, volume free: a diagonal strain force (W_aa - P0 V) / q_s within
    # F_tol puts P within q_s F_tol / V of P0 (the bisection's window is 1e-2)
    model = ShearStabilizedModel(p.box, p.diameter, p.links, p.position)
    assert abs(p.pressure - 1e-4) <= model.strain_scale * 1e-11 / p.box.volume
    assert p.packing_fraction != result.history["phi"][-1]
    assert np.max(np.abs(p.links.length_errors(p.position, p.box))) <= LINK_LENGTH_RTOL
    # re-evaluated in its own box at zero strain: positions and strain forces balanced on the manifold
    q = model.dofs(p.position)
    ev = model.evaluate(q)
    pg = model.project(ev.gradient, q)
    assert model.max_force(pg) <= 1e-11
    assert np.linalg.norm(pg[-model.m:]) <= 1e-11  # strain forces
    assert np.linalg.norm(ev.gradient[-model.m:]) > 1e-6  # the raw strain gradient is the pressure's
    # isotropic total stress: |W_dev| <= 2 q_s F_tol (strain force bound) relative to P V
    W = ev.virial
    P = np.trace(W) / 2
    bound = 2 * model.strain_scale * 1e-11 / P
    assert np.max(np.abs(W - P * np.eye(2))) / P <= bound
    assert p.attrs["stress_deviation"] <= bound
    # the box changed shape, not volume
    assert not np.allclose(p.box.matrix / p.box.matrix[0, 0], start.box.matrix / start.box.matrix[0, 0])
    # rigid: at least the shear-stabilised isostatic count sum f_c - d + 1 + d(d+1)/2 - 1
    count = count_bodies(p.contacts, p.n, 2, p.links, p.position, p.box, shear_stabilized=True)
    assert count.isostatic_count == 3 * (8 - count.removed.sum()) - count.free_dofs.sum() - 2 + 1 + 2
    assert count.n_contacts >= count.isostatic_count


def test_enthalpy_of_linked_spheres_relaxes_the_whole_box_to_the_pressure():
    """models.box.EnthalpyModel on the strain model with the volume free: the gradient of U + P0 V is the
    finite difference of it, and FIRE ends with the total stress -P0 1 (contacts and link tensions),
    the links held; a model without a deformable box is refused."""
    from pathlib import Path

    from jamflow.io import read_packing
    from jamflow.minimize.fire import minimize_fire
    from jamflow.models.box import EnthalpyModel
    from jamflow.models.links import LinkedSpheresModel

    p = read_packing(Path(__file__).parent / "data" / "bodies" / "linked_soft.nc", None)
    P0 = 2e-3
    free = ShearStabilizedModel(p.box, p.diameter, p.links, p.position, fixed_volume=False)
    model = EnthalpyModel(free, P0)
    q = model.dofs(p.position)
    q[-3:] = [0.01, -0.02, 0.015]  # a finite strain
    g = model.evaluate(q).gradient
    h = 1e-7
    for k in (0, 5, q.size - 3, q.size - 2, q.size - 1):
        e = np.zeros(q.size)
        e[k] = h
        num = (model.evaluate(q + e).energy - model.evaluate(q - e).energy) / (2 * h)
        assert num == pytest.approx(g[k], abs=1e-7 * np.abs(g).max())
    res = minimize_fire(model, p.position, 1e-12, 2_000_000)
    assert res.converged
    box = free.last_box()
    W = LinkedSpheresModel(box, p.diameter, p.links, res.position).evaluate(res.position.ravel()).virial
    # strain forces below the tolerance: |W / V - P0 1| <= q_s F_tol / V per component (scaled strain)
    np.testing.assert_allclose(W / box.volume, P0 * np.eye(2), rtol=0, atol=2 * free.strain_scale * 1e-12 / box.volume)
    assert np.max(np.abs(p.links.length_errors(res.position, box))) <= LINK_LENGTH_RTOL
    assert box.volume != pytest.approx(p.box.volume, rel=1e-3)  # the volume moved to reach P0
    with pytest.raises(TypeError, match="no box degrees of freedom"):
        EnthalpyModel(LinkedSpheresModel(p.box, p.diameter, p.links, p.position), P0)


@pytest.mark.slow
def test_cli_soft_jam_box_dof_full_of_a_linked_packing(tmp_path):
    """soft-jam --box-dof full: the shear-stabilised bisection to P0, then the enthalpy with the box free."""
    from pathlib import Path

    from jamflow.cli import main
    from jamflow.io import read_packing

    src = Path(__file__).parent / "data" / "bodies" / "linked_soft.nc"
    assert main(["soft-jam", str(src), str(tmp_path / "f.nc"), "--pressure", "1e-3", "--box-dof", "full",
                 "--quiet"]) == 0
    p = read_packing(tmp_path / "f.nc", None)
    assert p.protocol.endswith(">soft-enthalpy") and p.attrs["box_dof"] == "full"
    assert p.pressure == pytest.approx(1e-3, rel=1e-9) and p.attrs["stress_deviation"] <= 1e-8
    assert p.attrs["n_contacts"] >= p.attrs["isostatic_count"] > 0
