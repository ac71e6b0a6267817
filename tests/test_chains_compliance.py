"""Compliance and moduli of linked packings (chains paper Sec. VI)."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.chains.builders import cement, linked_packing
from jamflow.chains.compliance import compliance, strain_compliance, total_virial
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.io import read_dataset, write_packing
from jamflow.minimize.fire import minimize_fire
from jamflow.minimize.model import ModelEvaluation
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.hessian import elastic_moduli
from jamflow.models.strain import ShearStabilizedModel
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure


@pytest.fixture(scope="module")
def stabilized():
    start, _ = linked_packing(2, 8, "trimer", np.random.default_rng(1), phi=0.3, no_overlap=True)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-2, delta_phi=1e-2)
    return jam_linked(start, 1e-3, settings=settings, shear_stabilize=True).packing


class _Loaded(ShearStabilizedModel):
    """Free volume and strain, with a stress load linear in the strain: U - load . e."""

    load = np.zeros(3)

    def evaluate(self, q):
        ev = super().evaluate(q)
        g = ev.gradient.copy()
        g[-self.m:] -= self.load
        return ModelEvaluation(ev.energy - float(self.load @ q[-self.m:]), g, ev.virial, ev.n_contacts)


def test_compliance_predicts_the_strain_of_a_small_stress(stabilized):
    """S sigma against the strain measured by minimising under the stress (links held, volume free)."""
    p = stabilized
    S_e, _, _ = strain_compliance(p)
    fixed = ShearStabilizedModel(p.box, p.diameter, p.links, p.position)
    q0 = fixed.dofs(p.position)
    _, nu = fixed.constraint_multipliers(fixed.evaluate(q0).gradient, q0)
    balance = nu * fixed._solver(q0)["ce"]  # the load that holds the start at equilibrium (its pressure)
    model = _Loaded(p.box, p.diameter, p.links, p.position, fixed_volume=False)
    for k in range(3):
        ds = np.zeros(3)
        ds[k] = 1e-3 * np.linalg.norm(balance)
        model.load = balance + ds
        res = minimize_fire(model, p.position, force_tol=1e-14, max_steps=200_000)
        assert res.converged
        measured = model._last_q[-3:]
        # linear response: agreement to O(load) = 1e-3 relative
        np.testing.assert_allclose(measured, S_e @ ds, rtol=0, atol=2e-3 * np.abs(S_e @ ds).max())
    c = compliance(p)
    assert c.n_rigid == 0 and np.all(np.linalg.eigvalsh(c.S) > 0)
    # Reuss <= Hill <= Voigt, anisotropy index >= 0
    for kind in ("bulk", "shear"):
        assert getattr(c, f"{kind}_reuss") <= getattr(c, f"{kind}_hill") <= getattr(c, f"{kind}_voigt")
    assert c.anisotropy >= -1e-12


def test_every_contact_a_link_has_zero_compliance_and_infinite_moduli(stabilized):
    p = stabilized
    # cement every unlinked contact of the trimer packing
    n_free = len(p.contacts)
    links, _ = cement(p, n_free, np.random.default_rng(0), strain=True)
    rigid = p.evolve(links=links, contacts=np.empty((0, 2), np.int64), force=np.empty(0), rattler=None)
    c = compliance(rigid)
    assert np.max(np.abs(c.S)) <= 1e-12 * np.max(np.abs(compliance(p).S))
    assert c.n_rigid == 3
    assert np.isinf([c.bulk_voigt, c.bulk_reuss, c.shear_voigt, c.shear_reuss]).all()


def test_cli_moduli_of_a_linked_packing(tmp_path, capsys, stabilized):
    write_packing(stabilized, tmp_path / "p.nc")
    assert main(["moduli", str(tmp_path / "p.nc"), str(tmp_path / "m.nc"), "--modes", "4"]) == 0
    out = capsys.readouterr().out
    ds = read_dataset(tmp_path / "m.nc", "chain-moduli")
    c = compliance(stabilized)
    np.testing.assert_allclose(ds["compliance"].values, c.S, rtol=1e-12)
    assert float(ds["bulk_hill"]) == pytest.approx(c.bulk_hill, rel=1e-12)
    assert f"{c.bulk_hill:.6g}" in out and ds.attrs["n_zero_modes"] == 2
    assert np.all(ds["eigenvalue"].values > 0)


@pytest.mark.parametrize("d", [2, 3])
def test_without_links_the_moduli_are_those_of_jamflow_moduli(d):
    """C with the stress terms of the module doc gives -V dP/dV and the simple-shear G of the sphere code.

    Fixed-box packings of few spheres can be unstable to shear (negative G): the
    negative compliance is kept and counted, not reported as an infinite modulus.
    """
    # starts whose jammed packings are unstable to simple shear (a property of their path)
    start = random_packing(64, d, 0.5 if d == 2 else 0.3, "bi", seed=3 if d == 2 else 8)
    p = jam_to_pressure(start, 1e-3, force_tol=1e-13, pressure_rtol=1e-3).packing
    spheres = elastic_moduli(p.position, p.box, p.diameter)
    c = compliance(p)
    assert c.pressure == pytest.approx(spheres.pressure, rel=1e-12)
    assert c.bulk_dilation == pytest.approx(spheres.bulk, rel=1e-10)
    assert c.shear_simple == pytest.approx(spheres.shear, rel=1e-10)
    # these fixed-box starts are unstable to simple shear: the negative compliance is
    # counted and its moduli stay finite (no links, so nothing is rigid)
    assert spheres.shear < 0
    assert c.n_rigid == 0 and c.n_unstable == int(np.sum(np.linalg.eigvalsh(c.S) < 0)) > 0
    assert np.isfinite([c.bulk_voigt, c.bulk_reuss, c.shear_voigt, c.shear_reuss]).all()


def _relaxed_virial(p, F):
    """Total virial after minimising at fixed links in the box and centres deformed by ``F``."""
    model = LinkedSpheresModel(Box(F @ p.box.matrix), p.diameter, p.links, p.position @ F.T)
    res = minimize_fire(model, p.position @ F.T, force_tol=1e-14, max_steps=400_000)
    assert res.converged
    return model.evaluate(model.dofs(res.position)).virial


@pytest.fixture(scope="module")
def fixed_box():
    start, _ = linked_packing(2, 8, "trimer", np.random.default_rng(4), phi=0.3, no_overlap=True)
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-2, delta_phi=1e-2)
    return jam_linked(start, 1e-3, settings=settings).packing


@pytest.mark.parametrize("name", ["fixed_box", "stabilized"])
def test_dilation_and_simple_shear_moduli_of_linked_packings_against_finite_strains(name, request):
    """B and G_xy from C and the link tensions' stress against relaxed central differences of the virial."""
    p = request.getfixturevalue(name)
    c = compliance(p)
    W = total_virial(p)
    V = p.box.volume
    assert c.pressure == pytest.approx(np.trace(W) / (2 * V), rel=1e-12)
    assert c.pressure == pytest.approx(p.pressure, rel=1e-6)
    # central differences at h = 1e-6: truncation ~h^2, minimiser noise (|F| <= 1e-14) ~1e-8 relative
    h = 1e-6
    # simple shear x-y: G = -(1/V) dW_xy / dgamma (volume unchanged)
    shear = np.array([[0.0, 1.0], [0.0, 0.0]])
    dW = _relaxed_virial(p, np.eye(2) + h * shear) - _relaxed_virial(p, np.eye(2) - h * shear)
    assert c.shear_simple == pytest.approx(-dW[0, 1] / (2 * h * V), rel=1e-6)
    # dilation: B = -V dP/dV = -(1/d) dP/de, P = tr W / (d V (1 + e)^d)
    pressures = [np.trace(_relaxed_virial(p, (1 + e) * np.eye(2))) / (2 * V * (1 + e) ** 2) for e in (h, -h)]
    assert c.bulk_dilation == pytest.approx(-(pressures[0] - pressures[1]) / (2 * h * 2), rel=1e-6)


def test_cli_moduli_warns_of_strains_a_fixed_box_packing_is_unstable_to(fixed_box, tmp_path, capsys):
    write_packing(fixed_box, tmp_path / "p.nc")
    assert main(["moduli", str(tmp_path / "p.nc"), str(tmp_path / "m.nc"), "--modes", "4"]) == 0
    captured = capsys.readouterr()
    ds = read_dataset(tmp_path / "m.nc", "chain-moduli")
    c = compliance(fixed_box)
    assert c.n_unstable > 0 and ds.attrs["n_unstable"] == c.n_unstable
    assert "negative stiffness" in captured.err
    assert float(ds["shear_simple"]) == pytest.approx(c.shear_simple, rel=1e-12)
    # at its fixed box the packing (no rattlers) is stable: the positions-only
    # constrained Hessian has the 2 translations as zero modes and positive eigenvalues
    assert ds.attrs["hessian_strain"] == 0 and not fixed_box.rattler.any()
    assert ds.attrs["n_zero_modes"] == 2 and np.all(ds["eigenvalue"].values > 0)
