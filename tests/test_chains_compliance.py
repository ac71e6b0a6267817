"""Compliance and moduli of linked packings (chains paper Sec. VI)."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.chains.builders import cement, linked_packing
from jamflow.chains.compliance import compliance, strain_compliance
from jamflow.chains.jamming import jam_linked
from jamflow.chains.shear import ShearStabilizedModel
from jamflow.cli import main
from jamflow.io import read_dataset, write_packing
from jamflow.models.base import ModelEvaluation
from jamflow.soft.jamming import JammingSettings
from jamflow.soft.minimize import minimize_fire


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
