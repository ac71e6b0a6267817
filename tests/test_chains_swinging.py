"""A jammed packing of rigid trimers with one trimer that touches only through one sphere and swings about it.

tests/data/bodies/swinging_trimer_2d.nc (make.sh): 12 trimers in 2D at a fixed box, P0 = 1e-6;
swinging_trimer_2d_shear.nc: the same shear-stabilised (another seed).
The paper counts the swinging trimer as a rattling cluster (Sec. II F); its force-bearing sphere
stays in the backbone as a sphere of two degrees of freedom. Before the counting by rank, jamflow
called this packing hypostatic (34 contacts against 35) and not jammed.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from jamflow.chains.certify import _subpacking, certify_linked
from jamflow.chains.hessian import HARMONIC, _geometry, extended_rigidity
from jamflow.chains.modes import linked_modes
from jamflow.cli import main
from jamflow.io import read_dataset, read_packing
from jamflow.network import count_bodies

PATH = Path(__file__).parent / "data" / "bodies" / "swinging_trimer_2d.nc"
SHEAR = PATH.with_name("swinging_trimer_2d_shear.nc")


@pytest.fixture(scope="module")
def packing():
    return read_packing(PATH, None)


@pytest.fixture(scope="module")
def count(packing):
    return count_bodies(packing.contacts, packing.n, 2, packing.links, packing.position, packing.box)


def test_the_swinging_trimer_is_one_rattling_cluster_and_the_backbone_isostatic(packing, count):
    z = np.bincount(packing.contacts.ravel(), minlength=packing.n)
    (swing,) = np.flatnonzero(count.free_dofs)
    members = np.flatnonzero(count.cluster == swing)
    # the case: all contacts of the trimer on one sphere (at least 3, so it is held)
    assert np.sum(z[members] > 0) == 1 and z[members].max() >= 3
    held = members[z[members] > 0][0]
    assert count.free_dofs[swing] == 1 and not count.removed.any()
    assert count.as_dict()["n_rattling_clusters"] == 1
    np.testing.assert_array_equal(np.flatnonzero(count.dangler), np.setdiff1d(members, [held]))
    # 11 rigid trimers (3 each) and the held sphere (2): N_iso = 35 - 2 + 1 = 34
    assert count.backbone_dofs == 3 * 11 + 2
    assert count.n_contacts == count.isostatic_count == 34 == len(packing.contacts)
    assert packing.attrs["isostatic_count"] == 34 and packing.attrs["n_danglers"] == 2


def test_check_says_isostatic(capsys):
    assert main(["check", str(PATH), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["isostatic"] is True and report["n_rattling_clusters"] == 1 and report["free_dofs"] == 1
    assert report["n_contacts"] == report["isostatic_count"] == 34


def test_certify_gives_the_papers_verdict_and_agrees_with_the_rank_of_the_rigidity_matrix(packing, count, tmp_path,
                                                                                           capsys):
    """Fixed box: collectively jammed (the strict LP finds a strain), with only the danglers outside.

    Independent check: after removing the free motion and the translations from the basis, the
    extended rigidity matrix (positions only) has full column rank (no floppy motion) and one state of
    self stress, the contact forces, all positive.
    """
    assert main(["certify", str(PATH), str(tmp_path / "c.nc"), "--strict"]) == 0
    ds = read_dataset(tmp_path / "c.nc", "chain-certificate")
    assert ds.attrs["classification"] == "collectively_jammed" and ds.attrs["motion_stage"] == "strict"
    np.testing.assert_array_equal(ds["chain_rattler"].values.astype(bool), count.dangler)
    assert "1 rattling clusters by counting" in capsys.readouterr().out
    RE, _, self_stress, _ = extended_rigidity(packing, strain=False, translations=True,
                                              exclude=count.free_motions.toarray())
    s = np.linalg.svd(RE, compute_uv=False)
    assert RE.shape == (34, 33) and s.min() > 1e-6 * s.max()
    assert self_stress.shape[1] == 1
    f = self_stress[:, 0] * np.sign(self_stress[0, 0])
    geo = _geometry(packing, HARMONIC)
    # balanced to max |F| <= 1e-13 against contact forces ~1e-6: the forces are a self stress to ~1e-7
    np.testing.assert_allclose(f, geo.force / np.linalg.norm(geo.force), atol=1e-6)
    assert f.min() > 0.0


def test_removing_the_swinging_trimer_whole_opens_a_real_motion(packing, count):
    """The issue's second cause: the held sphere bears three contacts of the backbone. Without the
    whole trimer (what the old counting removed) a neighbouring trimer rattles and the rest is
    hypostatic (28 contacts against 29) and not jammed; keeping the held sphere, it is jammed."""
    (swing,) = np.flatnonzero(count.free_dofs)
    rest, _ = _subpacking(packing, count.cluster != swing)
    cert = certify_linked(rest, strict=False)
    assert cert.classification == "not_jammed" and cert.motion is not None
    assert cert.count.n_contacts == 28 and cert.count.isostatic_count == 29
    assert certify_linked(packing, strict=False).classification == "collectively_jammed"


def test_zero_modes_are_the_translations_and_the_swing(packing, count):
    modes = linked_modes(packing)
    assert not modes.strain
    assert modes.n_label("translation") == 2 and modes.n_label("free_motion") == 1
    assert modes.n_label("rattling_cluster") == modes.n_label("floppy") == modes.unexplained == 0
    assert modes.n_zero == 3
    # the free-motion mode is the count's rotation about the held sphere (up to sign)
    k = int(np.flatnonzero(modes.label == 3)[0])
    swing = count.free_motions.toarray()[:, 0]
    assert abs(modes.vectors[:, k] @ swing) == pytest.approx(1.0, rel=1e-10)
    assert np.all(modes.eigenvalues[modes.label == 0] > 0.0)


def test_shear_stabilised_swinging_trimer_is_strictly_jammed(tmp_path):
    """Shear-stabilised (strain at fixed volume): isostatic with the strain, 36 = 35 - 2 + 1 + 2, and
    strictly jammed (before: 33 against 34 with the trimer removed whole, and not jammed)."""
    p = read_packing(SHEAR, None)
    count = count_bodies(p.contacts, p.n, 2, p.links, p.position, p.box, shear_stabilized=True)
    assert count.free_dofs.sum() == 1 and count.dangler.sum() == 2 and not count.removed.any()
    assert count.n_contacts == count.isostatic_count == 36
    assert main(["certify", str(SHEAR), str(tmp_path / "c.nc"), "--strict", "--quiet"]) == 0
    ds = read_dataset(tmp_path / "c.nc", "chain-certificate")
    assert ds.attrs["classification"] == "strictly_jammed"
    np.testing.assert_array_equal(ds["chain_rattler"].values.astype(bool), count.dangler)
    modes = linked_modes(p)
    assert modes.strain and modes.n_zero == 3 and modes.n_label("free_motion") == 1 and modes.unexplained == 0


def _rank_verdict(p, count, strain: bool) -> tuple[int, int, bool]:
    """(columns n_t, rank, positive self stress) of R_E on the backbone without translations and free motions."""
    import scipy.sparse as sp

    from jamflow.chains.hessian import ZERO_MODE_RTOL
    from jamflow.network import positive_self_stress

    sub, idx = _subpacking(p, ~count.removed[count.cluster])
    rows = (p.d * idx[:, None] + np.arange(p.d)).ravel()
    free = count.free_motions.tocsr()[rows].toarray()
    free = free[:, np.linalg.norm(free, axis=0) > 0.5]
    RE, _, _, _ = extended_rigidity(sub, strain=strain, translations=True, exclude=free)
    s = np.linalg.svd(RE, compute_uv=False)
    rank = int(np.sum(s > ZERO_MODE_RTOL * s.max()))
    return RE.shape[1], rank, positive_self_stress(sp.csr_matrix(RE), method="lp") is not None


@pytest.mark.slow
@pytest.mark.parametrize("d, clusters", [(2, 12), (3, 32)])
@pytest.mark.parametrize("stabilized", [False, True], ids=["fixed-box", "shear-stabilized"])
@pytest.mark.parametrize("seed", [1, 2])
def test_counting_and_certify_agree_with_the_rank_of_the_rigidity_matrix(d, clusters, stabilized, seed):
    """Trimers jammed at P0 = 1e-6: the count's N_iso is the true degrees of freedom plus one (n_t + 1, by
    rank), no floppy motion is left, and certify's verdict is the Roth-Whiteley one (full rank and a
    positive self stress), collectively with positions only and strictly with the strain."""
    from jamflow.chains.builders import linked_packing
    from jamflow.chains.jamming import jam_linked
    from jamflow.minimize.onset import JammingSettings

    start, _ = linked_packing(d, clusters, "trimer", np.random.default_rng(seed))
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    p = jam_linked(start, 1e-6, settings=settings, shear_stabilize=stabilized).packing
    count = count_bodies(p.contacts, p.n, d, p.links, p.position, p.box, shear_stabilized=stabilized)
    n_t, rank, positive = _rank_verdict(p, count, strain=stabilized)
    assert rank == n_t and count.isostatic_count == n_t + 1 and count.n_contacts >= count.isostatic_count
    cert = certify_linked(p, strict=True)
    collective = _rank_verdict(p, count, strain=False)
    strict = _rank_verdict(p, count, strain=True)
    rigid = [c[0] == c[1] and c[2] for c in (collective, strict)]
    want = "strictly_jammed" if all(rigid) else "collectively_jammed" if rigid[0] else "not_jammed"
    assert cert.classification == want
    assert cert.classification == ("strictly_jammed" if stabilized else "collectively_jammed")
