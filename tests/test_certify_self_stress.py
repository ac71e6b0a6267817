"""The certificate's Roth-Whiteley test agrees with the LP-only certificate."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from jamflow.network import contact_jacobian, rigid_network, sphere_contacts
from jamflow.protocols.certify import certify
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure


@pytest.fixture(scope="module", params=[(2, 64, "bi"), (3, 128, "mono")], ids=["2d-N64", "3d-N128"])
def soft_jammed(request):
    """Soft harmonic packing jammed at P0 = 1e-4 (overlapping pairs are its contacts)."""
    d, n, dispersity = request.param
    res = jam_to_pressure(random_packing(n, d, 0.3 if d == 2 else 0.2, dispersity, 1, 1.4, 0.5, 0.1), pressure=1e-4)
    assert res.converged
    return res.packing


def test_self_stress_decision_matches_the_lp_certificate(soft_jammed):
    p = soft_jammed
    fast = certify(p, strict=True, loads=1, seed=0)
    slow = certify(p, strict=True, loads=1, seed=0, self_stress_test=False)
    assert fast.self_stress_decisions >= 1 and slow.self_stress_decisions == 0
    assert len(fast.lp) < len(slow.lp)
    assert fast.classification == slow.classification
    assert fast.motion_stage == slow.motion_stage
    np.testing.assert_array_equal(fast.rattler_stage, slow.rattler_stage)
    if fast.motion_stage == "strict":
        # the constructed strain motion closes no backbone contact and really strains the box
        c = fast.backbone_contacts
        cs = sphere_contacts(p.position, p.box, c)
        y, eps = fast.motion, fast.motion_strain
        change = (np.einsum("ca,ca->c", cs.normal, y[c[:, 1]] - y[c[:, 0]])
                  + np.einsum("ca,ab,cb->c", cs.normal, eps, cs.separation))
        assert change.min() >= -1e-9
        assert np.abs(np.trace(eps)) < 1e-12 and np.abs(eps).max() > 1e-3


def test_rigid_network_of_a_soft_backbone_and_floppy_ones_left_to_the_lps(soft_jammed):
    p = soft_jammed
    cert = certify(p)
    keep = ~cert.rattler
    bc = cert.backbone_contacts
    idx = np.flatnonzero(keep)
    J = contact_jacobian(sphere_contacts(p.position, p.box, bc), p.n, bodies=idx)[:, p.d:]  # first particle pinned
    rigid = rigid_network(J)
    assert rigid is not None and rigid.self_stress.min() > 0
    assert np.abs(J.T @ rigid.self_stress).max() < 1e-12
    # the soft force network is a self stress: it lies in the computed self-stress space
    f = p.force[keep[p.contacts[:, 0]] & keep[p.contacts[:, 1]]]
    assert np.linalg.norm(rigid.null @ (rigid.null.T @ f) - f) < 1e-8 * np.linalg.norm(f)
    assert rigid.null.shape[1] == J.shape[0] - J.shape[1]
    # fewer contacts than degrees of freedom: floppy, left to the LPs
    assert rigid_network(J[: J.shape[1]]) is None
    # a floppy mode: one column emptied
    floppy = sp.lil_matrix(J)
    floppy[:, 0] = 0.0
    assert rigid_network(sp.csr_matrix(floppy)) is None


def test_cut_backbone_is_decided_by_the_lps(soft_jammed):
    p = soft_jammed
    cert = certify(p)
    bc = cert.backbone_contacts
    k = len(bc) // 2
    drop = (p.contacts[:, 0] == bc[k, 0]) & (p.contacts[:, 1] == bc[k, 1])
    cut = p.evolve(contacts=p.contacts[~drop], force=None)
    fast, slow = certify(cut, seed=0), certify(cut, seed=0, self_stress_test=False)
    assert fast.classification == slow.classification
    np.testing.assert_array_equal(fast.rattler_stage, slow.rattler_stage)
