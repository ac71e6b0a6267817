"""Jamming certificates: rigidity matrix, lattices of known category, soft and LS packings.

Independent check used throughout (Roth-Whiteley, see ``jamflow.network.rigidity``): a strut
framework is rigid iff its rigidity matrix has rank ``d (N_s - 1)`` (fixed box; plus
the strain coordinates for strict jamming) and a strictly positive self-stress
exists. Rank comes from a dense SVD, the self-stress from non-negative least squares;
the certificate itself uses randomized interior-point / simplex LPs.
"""

from __future__ import annotations

import numpy as np
import pytest
from ls_data import ls_dat

from jamflow.cli import main
from jamflow.io import read_dataset, write_packing
from jamflow.io.formats import read_dat
from jamflow.network import jacobian_rank
from jamflow.network.jacobian import strain_basis
from jamflow.network.rigidity import rigidity_matrix
from jamflow.network.self_stress import positive_self_stress
from jamflow.network.spheres import force_balance_residual
from jamflow.protocols.certify import CLASSIFICATIONS, MotionLP, certify
from jamflow.protocols.initial import random_packing
from jamflow.protocols.lattices import LATTICES, lattice_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.state.packing import near_pairs


def _independent(packing, contacts, backbone, strain, method="nnls"):
    """(rank == full, positive self-stress exists) for the backbone network."""
    idx = np.flatnonzero(backbone)
    keep = backbone[contacts[:, 0]] & backbone[contacts[:, 1]]
    R = rigidity_matrix(packing, contacts[keep], strain=strain, particles=idx)
    rank, _ = jacobian_rank(R)
    full = packing.d * (len(idx) - 1) + (R.shape[1] - packing.d * len(idx))
    return rank == full, positive_self_stress(R, method=method) is not None


def _assert_motion_allowed(packing, cert):
    """The reported unjamming motion closes no contact and is not a translation."""
    y = cert.motion
    assert y is not None
    backbone = ~cert.rattler
    c = cert.backbone_contacts
    eps = np.zeros((packing.d, packing.d)) if cert.motion_strain is None else cert.motion_strain
    dx = packing.box.minimum_image(packing.position[c[:, 1]] - packing.position[c[:, 0]])
    n = dx / np.linalg.norm(dx, axis=1)[:, None]
    # first-order separation change, written out directly (not via rigidity_matrix)
    change = np.einsum("ca,ca->c", n, y[c[:, 1]] - y[c[:, 0]]) + np.einsum("ca,ab,cb->c", n, eps, dx)
    assert change.min() >= -1e-7
    rel = y[backbone] - y[backbone].mean(axis=0)
    assert max(np.abs(rel).max(), np.abs(eps).max()) > 1e-3


# --- rigidity matrix --------------------------------------------------------------------


def test_rigidity_matrix_is_first_order_change_of_distances():
    p = random_packing(40, 3, 0.3, "bi", 3, 1.4, 0.5, 0.1)
    pairs, _ = near_pairs(p, 0.5)
    contacts = np.stack([pairs.i, pairs.j], axis=1)
    rng = np.random.default_rng(0)
    basis = strain_basis(3, volume_preserving=False)
    y = rng.standard_normal((p.n, 3))
    e = rng.standard_normal(len(basis))
    R = rigidity_matrix(p, contacts, strain=True, volume_preserving=False)
    lin = R @ np.concatenate([y.ravel(), e])
    eps = np.einsum("k,kab->ab", e, basis)

    def dist(t):
        # box and centres deformed by (I + t eps), centres displaced by t y
        F = np.eye(3) + t * eps
        dx = pairs.dx @ F.T + t * (y[pairs.j] - y[pairs.i])
        return np.linalg.norm(dx, axis=1)

    t = 1e-6
    fd = (dist(t) - dist(-t)) / (2 * t)
    assert np.allclose(lin, fd, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("max_gap", [0.2, 0.6, 1.0])
def test_self_stress_searches_agree_and_balance_forces(max_gap):
    p = random_packing(40, 2, 0.5, "bi", 4, 1.4, 0.5, 0.1)
    pairs, _ = near_pairs(p, max_gap)
    R = rigidity_matrix(p, np.stack([pairs.i, pairs.j], axis=1))
    lam_nnls = positive_self_stress(R)
    lam_lp = positive_self_stress(R, method="lp", rtol=1e-7)
    assert (lam_nnls is None) == (lam_lp is None)
    for lam in (lam_nnls, lam_lp):
        if lam is not None:
            assert lam.min() > 0
            assert np.linalg.norm(R.T @ lam) < 1e-8 * np.linalg.norm(lam)


def test_strain_basis_is_traceless_symmetric_and_complete():
    for d in (2, 3, 4):
        full = strain_basis(d, volume_preserving=False)
        vol = strain_basis(d, volume_preserving=True)
        assert len(full) == d * (d + 1) // 2 and len(vol) == len(full) - 1
        assert np.allclose(vol, np.transpose(vol, (0, 2, 1)))
        assert np.allclose(np.trace(vol, axis1=1, axis2=2), 0.0)
        assert np.linalg.matrix_rank(vol.reshape(len(vol), -1)) == len(vol)


# --- lattices -------------------------------------------------------------------------


@pytest.mark.parametrize("name", LATTICES)
def test_lattice_contacts_are_exact(name):
    p = lattice_packing(name, 3)
    z = np.bincount(p.contacts.ravel(), minlength=p.n)
    expected = {"triangular": 6, "square": 4, "honeycomb": 3, "kagome": 4, "fcc": 12, "sc": 6, "bcc": 8}[name]
    assert np.all(z == expected)
    _, h = near_pairs(p, 1e-9)
    assert np.abs(h).max() < 1e-12


# literature (Torquato & Stillinger, Rev. Mod. Phys. 82, 2633 (2010), Table; Donev et al.
# 2004): triangular and FCC strictly jammed; square and simple cubic only locally jammed
# (rows / planes slide); honeycomb only locally jammed in cells larger than its
# two-particle primitive cell
KNOWN = [
    ("triangular", (4, 3), "strictly_jammed"),
    ("fcc", (2, 2, 2), "strictly_jammed"),
    ("square", (4, 4), "locally_jammed"),
    ("sc", (3, 3, 3), "locally_jammed"),
    ("honeycomb", (3, 2), "locally_jammed"),
]


@pytest.mark.parametrize("name,cells,expected", KNOWN)
def test_lattice_categories_from_literature(name, cells, expected):
    p = lattice_packing(name, cells)
    cert = certify(p, strict=True, seed=1)
    assert cert.classification == expected
    assert not cert.rattler.any()
    if expected != "strictly_jammed":
        _assert_motion_allowed(p, cert)


def test_square_lattice_unjamming_motion_slides_whole_rows():
    p = lattice_packing("square", (4, 4))
    cert = certify(p, seed=2)
    y = cert.motion
    # a sliding row moves along itself: every moving particle's row moves rigidly
    rows = np.round(p.position[:, 1]).astype(int) % 4
    cols = np.round(p.position[:, 0]).astype(int) % 4
    for axis, line in ((0, rows), (1, cols)):
        for k in range(4):
            comp = y[line == k, axis]
            assert np.ptp(comp) < 1e-6


@pytest.mark.parametrize(
    "name,cells",
    [("triangular", (3, 2)), ("square", (3, 3)), ("honeycomb", (2, 1)), ("honeycomb", (4, 3)),
     ("kagome", (2, 1)), ("kagome", (3, 2)), ("fcc", (2, 2, 2)), ("sc", (3, 3, 3)), ("bcc", (2, 2, 2))],
)
def test_lattice_certificate_agrees_with_rank_and_self_stress(name, cells):
    p = lattice_packing(name, cells)
    cert = certify(p, strict=True, seed=3)
    backbone = np.ones(p.n, dtype=bool)
    rigid_fixed = all(_independent(p, p.contacts, backbone, strain=False))
    rigid_strain = all(_independent(p, p.contacts, backbone, strain=True))
    assert (cert.classification in ("collectively_jammed", "strictly_jammed")) == rigid_fixed
    assert (cert.classification == "strictly_jammed") == (rigid_fixed and rigid_strain)
    # the two self-stress searches (active-set NNLS and LP) agree
    R = rigidity_matrix(p, p.contacts)
    assert (positive_self_stress(R) is None) == (positive_self_stress(R, method="lp", rtol=1e-7) is None)


# --- soft packings ----------------------------------------------------------------------


@pytest.fixture(scope="module", params=[(2, 64, "bi"), (3, 128, "mono")], ids=["2d-N64", "3d-N128"])
def soft_jammed(request):
    """Soft harmonic packing jammed at P0 = 1e-4: overlapping pairs are its contacts."""
    d, n, dispersity = request.param
    p0 = random_packing(n, d, 0.3 if d == 2 else 0.2, dispersity, 1, 1.4, 0.5, 0.1)
    res = jam_to_pressure(p0, pressure=1e-4)
    assert res.converged
    return res.packing


def test_soft_jammed_packing_is_collectively_jammed(soft_jammed):
    p = soft_jammed
    cert = certify(p, strict=True)
    assert cert.classification in ("collectively_jammed", "strictly_jammed")
    backbone = ~cert.rattler
    full_rank, _ = _independent(p, p.contacts, backbone, strain=False)
    assert full_rank
    # the soft contact forces are themselves a strictly positive self-stress
    keep = backbone[p.contacts[:, 0]] & backbone[p.contacts[:, 1]]
    assert np.all(p.force[keep] > 0)
    assert np.max(force_balance_residual(p)[backbone]) < 1e-6
    # a backbone with fewer contacts than d (N_s - 1) + d (d + 1) / 2 - 1 cannot resist
    # the volume-preserving strains as well
    d, n_s, n_c = p.d, int(backbone.sum()), len(cert.backbone_contacts)
    if n_c < d * (n_s - 1) + d * (d + 1) // 2 - 1:
        assert cert.classification == "collectively_jammed"
        _assert_motion_allowed(p, cert)


def test_cutting_below_the_isostatic_count_unjams(soft_jammed):
    """With d (N_s - 1) backbone contacts no positive self-stress can hold N_s particles.

    An isostatic backbone loses one contact; a hyperstatic one loses its excess plus
    one, at evenly spread positions (two different cuts per packing).
    """
    p = soft_jammed
    cert = certify(p)
    bc = cert.backbone_contacts
    n_s = int((~cert.rattler).sum())
    n_cut = len(bc) - p.d * (n_s - 1)
    assert n_cut >= 1
    for shift in (0, 1):
        picks = (np.linspace(0, len(bc) - 1, n_cut, dtype=np.int64) + shift) % len(bc)
        drop = np.zeros(len(p.contacts), dtype=bool)
        for k in picks:
            drop |= (p.contacts[:, 0] == bc[k, 0]) & (p.contacts[:, 1] == bc[k, 1])
        assert drop.sum() == n_cut
        cut = p.evolve(contacts=p.contacts[~drop], force=None)
        c2 = certify(cut, seed=shift)
        # either a collective motion is reported or more rattlers had to go
        assert c2.classification == "locally_jammed" or c2.rattler.sum() > cert.rattler.sum()
        if c2.classification == "locally_jammed":
            _assert_motion_allowed(cut, c2)


# --- unjammed and LS packings -----------------------------------------------------------


def test_random_low_density_packing_is_not_jammed():
    p = random_packing(200, 3, 0.3, "mono", 7, 1.4, 0.5, 0.1)
    cert = certify(p, gap_tol=0.05)
    assert cert.classification == "not_jammed"
    assert cert.rattler.all()


def test_ls_snapshot_with_too_small_gap_tolerance_is_not_jammed():
    p = read_dat(ls_dat(3))
    for tol in (1e-6, 1e-4):
        cert = certify(p, gap_tol=tol)
        assert cert.classification == "not_jammed"
        # fewer near contacts than an isostatic network of all particles needs
        assert len(cert.contacts) < 3 * (p.n - 1) + 1


@pytest.mark.slow
def test_ls_snapshot_near_contact_network_is_jammed():
    p = read_dat(ls_dat(3))
    cert = certify(p, gap_tol=3e-3, strict=True)
    assert cert.classification in ("collectively_jammed", "strictly_jammed")
    full_rank, positive = _independent(p, cert.contacts, ~cert.rattler, strain=False, method="lp")
    assert full_rank and positive


# --- reproducibility, CLI -----------------------------------------------------------------


def test_same_seed_same_certificate():
    p = lattice_packing("kagome", (3, 2))
    a, b = certify(p, seed=5), certify(p, seed=5)
    assert a.classification == b.classification in CLASSIFICATIONS
    assert np.array_equal(a.motion, b.motion)


def test_cli_certify_writes_dataset(tmp_path, capsys):
    src = tmp_path / "square.nc"
    out = tmp_path / "cert.nc"
    write_packing(lattice_packing("square", (4, 3)), src)
    assert main(["certify", str(src), str(out), "--strict", "--loads", "1", "--seed", "2", "--quiet"]) == 0
    ds = read_dataset(out)
    assert ds.attrs["classification"] == "locally_jammed"
    assert ds["unjamming_motion"].dims == ("particle", "spatial")
    assert ds.attrs["n_lp"] == ds.sizes["lp"]
    for v in ds.data_vars.values():
        assert "units" in v.attrs and "long_name" in v.attrs
    assert main(["certify", str(src), str(out), "--exact"]) == 1
    assert "--exact needs --gap-tol" in capsys.readouterr().err


def test_warm_primal_cone_solves_match_cold_solves(soft_jammed):
    """Loads change only the costs: on the cone LP of a jammed network the primal
    simplex from the previous basis must reach the same optimum (a rigid translation,
    no relative motion) as a cold dual simplex, in fewer pivots."""
    p = soft_jammed
    cert = certify(p)
    A = rigidity_matrix(p, cert.backbone_contacts, particles=np.flatnonzero(~cert.rattler))
    zero, upper = np.zeros(A.shape[0]), np.ones(A.shape[1])
    rng = np.random.default_rng(5)
    loads = [s * rng.standard_normal(A.shape[1]) for _ in range(3) for s in (1, -1)]
    warm = MotionLP(A, zero, upper, "simplex")
    warm_its = cold_its = 0
    for k, load in enumerate(loads):
        _, obj_warm, y, _, it_warm = warm.solve(load)
        _, obj_cold, _, _, it_cold = MotionLP(A, zero, upper, "simplex").solve(load)
        # jammed: the only first-order motions are translations, which a load can
        # exploit only through its net component
        net = np.abs(load.reshape(-1, p.d).sum(axis=0)).sum()
        assert obj_cold == pytest.approx(net, rel=1e-7)
        assert obj_warm == pytest.approx(obj_cold, abs=1e-9 * net)
        assert np.all(A @ y >= -1e-9) and np.all(np.abs(y) <= 1 + 1e-9)
        if k:
            warm_its += it_warm
            cold_its += it_cold
    assert warm_its < cold_its
