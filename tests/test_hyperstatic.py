"""Hyperstatic (degenerate) packings through CALiPPSO, ``check`` and ``certify`` (issue 17).

A crystal or a 2D monodisperse packing has more touching pairs than a vertex of the
jamming LP can put forces on; the stored contacts must be the geometric ones, the
rattlers those of the geometric network, the forces non-negative and balanced, and
``check`` / ``certify`` must agree with the geometry. Independent references: the
pairs' gaps (``contacts_from_gaps``), the crystal's symmetry (equal forces), the
KKT conditions of the minimum-norm problem, and the Roth-Whiteley rank / positive
self-stress test of rigidity (``jamflow.network.rigidity``).

``tests/data/ls_2d_mono_n64_p1e6.nc`` is the issue's LS case, made by
``jamflow init m.nc --d 2 --n 64 --phi 0.5 --dispersity mono --seed 1`` and
``jamflow ls m.nc out.nc --growth-rate 1e-3 --p-target 1e6`` (27 s, hence vendored).
"""

from __future__ import annotations

import json
from math import pi, sqrt
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from jamflow.analysis.contacts import summarize
from jamflow.cli import main
from jamflow.io import read_dataset, read_packing, write_packing
from jamflow.network import isostatic_count, jacobian_rank
from jamflow.network.rigidity import rigidity_matrix
from jamflow.network.self_stress import positive_self_stress
from jamflow.network.spheres import (
    contacts_from_gaps,
    find_rattlers,
    force_balance_residual,
)
from jamflow.protocols.calippso import calippso
from jamflow.protocols.certify import certify
from jamflow.protocols.initial import random_packing
from jamflow.protocols.lattices import lattice_packing
from jamflow.state.packing import near_pairs
from jamflow.tolerances import CONTACT_GAP_TOL, FORCE_BALANCE_TOL, OVERLAP_TOL

LS_MONO = Path(__file__).parent / "data" / "ls_2d_mono_n64_p1e6.nc"


def _pairs(c: np.ndarray) -> set[tuple[int, int]]:
    return set(map(tuple, np.asarray(c).tolist()))


def _balanced_and_normalised(p) -> None:
    """Non-negative forces, balanced on every particle, ``sum_c f_c sigma_c = 1``."""
    assert np.all(p.force >= 0.0)
    assert force_balance_residual(p).max() < FORCE_BALANCE_TOL
    sig = p.sigma(p.contacts[:, 0], p.contacts[:, 1])
    assert float(np.sum(p.force * sig)) == pytest.approx(1.0, rel=1e-12)


def _rigid_fixed_box(p) -> bool:
    """Roth-Whiteley: rank d (N_s - 1) and a strictly positive self-stress."""
    idx = np.flatnonzero(~p.rattler)
    c = p.contacts[~(p.rattler[p.contacts[:, 0]] | p.rattler[p.contacts[:, 1]])]
    R = rigidity_matrix(p, c, particles=idx)
    rank, _ = jacobian_rank(R)
    return rank == p.d * (len(idx) - 1) and positive_self_stress(R) is not None


# --- a perfect triangular crystal ---------------------------------------------------------


@pytest.fixture(scope="module")
def crystal():
    lattice = lattice_packing("triangular", (8, 4))
    res = calippso(lattice.evolve(contacts=None))
    return lattice, res


def test_crystal_keeps_all_3n_contacts_and_no_rattler(crystal):
    lattice, res = crystal
    p = res.packing
    assert res.converged
    # the crystal is the densest packing of its box: it cannot grow nor move
    assert p.packing_fraction == pytest.approx(pi / sqrt(12.0), rel=1e-12)
    np.testing.assert_allclose(p.position, lattice.position, atol=1e-12)
    # every nearest-neighbour pair, 3 N = 192 of them, and nothing else
    assert len(p.contacts) == 3 * p.n == 192
    assert _pairs(p.contacts) == _pairs(lattice.contacts)
    assert not p.rattler.any()
    a = p.attrs
    assert (a["n_contacts"], a["n_stable"], a["n_rattlers"]) == (192, 64, 0)
    assert a["hyperstatic"] == 1 and a["isostatic"] == 0
    assert a["isostatic_count"] == isostatic_count(64, 2, global_dofs=2) == 127
    # the LP's vertex itself holds fewer contacts; the attrs say which forces are stored
    assert a["n_contacts_dual"] < 192
    assert a["force_assignment"] == "min_norm_balanced"


def test_crystal_forces_are_uniform_and_balanced(crystal):
    _, res = crystal
    p = res.packing
    _balanced_and_normalised(p)
    # all 192 contacts are equivalent by symmetry and the minimum-norm assignment is
    # unique, so each carries 1 / (N_c sigma)
    np.testing.assert_allclose(p.force, 1.0 / (192 * p.diameter[0]), rtol=1e-12)
    assert p.attrs["n_zero_force_contacts"] == 0


def test_crystal_check_and_certify_agree_with_geometry(crystal, tmp_path, capsys):
    _, res = crystal
    src = tmp_path / "crystal.nc"
    write_packing(res.packing, src)
    assert main(["check", str(src), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert (s["n_contacts"], s["n_rattlers"], s["counting"], s["isostatic"]) == (192, 0, "hyperstatic", False)
    # the geometric count (no stored contacts) gives the same numbers
    assert main(["check", str(src), "--json", "--gap-tol", str(CONTACT_GAP_TOL)]) == 0
    g = json.loads(capsys.readouterr().out)
    assert (g["n_contacts"], g["n_rattlers"]) == (192, 0)
    # triangular crystal: strictly jammed (Torquato & Stillinger, Rev. Mod. Phys. 82,
    # 2633 (2010); as test_strict_jamming for the lattice itself)
    cert = tmp_path / "cert.nc"
    assert main(["certify", str(src), str(cert), "--strict", "--quiet"]) == 0
    attrs = read_dataset(cert).attrs
    assert attrs["classification"] == "strictly_jammed"
    assert (attrs["n_rattlers"], attrs["n_backbone_contacts"]) == (0, 192)


# --- the 2D monodisperse LS case of the issue -----------------------------------------------


@pytest.fixture(scope="module")
def mono(tmp_path_factory):
    src = read_packing(LS_MONO)
    out = tmp_path_factory.mktemp("mono") / "mcal.nc"
    assert main(["calippso", str(LS_MONO), str(out), "--quiet"]) == 0
    return src, read_packing(out)


def test_mono_ls_stores_geometric_contacts(mono):
    _, p = mono
    assert p.attrs["converged"] == 1
    assert near_pairs(p, 0.0)[1].min(initial=0.0) > -OVERLAP_TOL
    # contacts == pairs with gap <= CONTACT_GAP_TOL, and the tolerance is not fudged:
    # the next pair is orders of magnitude further
    geo = contacts_from_gaps(p, CONTACT_GAP_TOL)
    assert _pairs(p.contacts) == _pairs(geo)
    _, h = near_pairs(p, 1e-3)
    assert np.sort(h)[len(geo)] > 1e-6
    # rattlers are those of the geometric network (the dual vertex had 5)
    np.testing.assert_array_equal(p.rattler, find_rattlers(p.n, 2, geo))
    assert p.attrs["n_rattlers_dual"] > p.attrs["n_rattlers"]
    n_c = summarize(p).n_contacts
    assert n_c == p.attrs["n_contacts"] > isostatic_count(int((~p.rattler).sum()), 2, global_dofs=2)
    assert p.attrs["force_assignment"] == "min_norm_balanced"


def test_mono_ls_forces_are_the_minimum_norm_balanced_ones(mono):
    _, p = mono
    _balanced_and_normalised(p)
    # KKT conditions of min |f|^2 s.t. B f = 0, w . f = 1, f >= 0 (independent of the
    # QP): f = A^T lambda + nu with nu >= 0 and nu f = 0, A = [B; w]
    unit = p.contact_vectors() / np.linalg.norm(p.contact_vectors(), axis=1)[:, None]
    c = p.contacts
    B = np.zeros((2 * p.n, len(c)))
    for k, (i, j) in enumerate(c):
        B[2 * i:2 * i + 2, k] = -unit[k]
        B[2 * j:2 * j + 2, k] = unit[k]
    A = np.vstack([B, p.sigma(c[:, 0], c[:, 1])[None, :]])
    on = p.force > 1e-9 * p.force.max()
    assert (~on).any()  # the non-negativity bounds matter here
    # multipliers exist iff this feasibility LP is: A_S^T lam = f_S, A_off^T lam <= 0
    # (nu_off = -A_off^T lam >= 0); lam is not unique when the support is floppy
    tol = 1e-9 * float(p.force.max())
    kkt = linprog(np.zeros(A.shape[0]), A_ub=A[:, ~on].T, b_ub=np.full(int((~on).sum()), tol),
                  A_eq=A[:, on].T, b_eq=p.force[on], bounds=[(None, None)] * A.shape[0], method="highs")
    assert kkt.status == 0, kkt.message


def test_mono_ls_check_and_certify_agree(mono, tmp_path, capsys):
    src, p = mono
    # the issue: the stored network certified not_jammed (strict) although the
    # packing is jammed; the independent rigidity test (fixed box) agrees now
    cert = certify(p, strict=True, seed=1)
    assert not cert.rattler.any()
    assert cert.classification in ("collectively_jammed", "strictly_jammed")
    assert _rigid_fixed_box(p)
    # check: no hypostatic claim, the certificate's backbone
    out = tmp_path / "m.nc"
    write_packing(p, out)
    assert main(["check", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["counting"] == "hyperstatic" and s["n_rattlers"] == 0
    assert s["n_contacts"] == p.attrs["n_contacts"] == len(cert.backbone_contacts)
    # the gap-aware certificate on the geometric network says the same
    assert certify(p.evolve(contacts=None, force=None), gap_tol=CONTACT_GAP_TOL, seed=1).classification \
        in ("collectively_jammed", "strictly_jammed")
    assert p.packing_fraction > src.packing_fraction


# --- between hard walls ------------------------------------------------------------------


def test_walls_mono_stores_geometric_pair_and_wall_contacts():
    """2D monodisperse between walls. Which optimal vertex HiGHS returns decides whether
    the duals strip force-bearing particles; with seed 1 they do (highspy 1.15.1: 17
    rattlers of the dual vertex, 2 of the geometric network), the case under test."""
    p0 = random_packing(64, 2, 0.5, "mono", seed=1)
    D = 0.9 * p0.diameter
    res = calippso(p0.evolve(position=0.5 * D.max() + p0.position * (1.0 - D.max()), diameter=D), walls=True)
    p, wc, fw = res.packing, res.wall_contacts, res.wall_force
    assert res.converged
    # geometric pairs (direct separations only: no periodic images through a wall)
    i, j = np.triu_indices(p.n, 1)
    dx = p.position[j] - p.position[i]
    h = np.linalg.norm(dx, axis=1) / p.sigma(i, j) - 1.0
    assert _pairs(p.contacts) == _pairs(np.stack([i[h <= CONTACT_GAP_TOL], j[h <= CONTACT_GAP_TOL]], axis=1))
    rad = 0.5 * p.diameter[:, None]
    gap = np.stack([p.position / rad - 1.0, (1.0 - p.position) / rad - 1.0], axis=2)
    wp, axis, side = np.nonzero(gap <= CONTACT_GAP_TOL)
    assert _pairs(wc) == _pairs(np.stack([wp, 2 * axis + side], axis=1))
    np.testing.assert_array_equal(p.rattler, find_rattlers(p.n, 2, p.contacts, wc[:, 0]))
    assert p.attrs["n_rattlers"] < p.attrs["n_rattlers_dual"]
    assert p.attrs["force_assignment"] == "min_norm_balanced"
    # balanced with the wall pushes, non-negative, sum f sigma + sum f_w sigma_i / 2 = 1
    assert np.all(p.force >= 0) and np.all(fw >= 0)
    unit = p.contact_vectors() / np.linalg.norm(p.contact_vectors(), axis=1)[:, None]
    net = np.zeros((p.n, 2))
    np.add.at(net, p.contacts[:, 0], -p.force[:, None] * unit)
    np.add.at(net, p.contacts[:, 1], p.force[:, None] * unit)
    np.add.at(net, (wc[:, 0], wc[:, 1] // 2), np.where(wc[:, 1] % 2 == 0, 1.0, -1.0) * fw)
    mean_f = np.mean(np.concatenate([p.force, fw]))
    assert np.linalg.norm(net, axis=1).max() / mean_f < FORCE_BALANCE_TOL
    total = np.sum(p.force * p.sigma(p.contacts[:, 0], p.contacts[:, 1])) + np.sum(fw * 0.5 * p.diameter[wc[:, 0]])
    assert total == pytest.approx(1.0, rel=1e-12)
    # between walls the isostatic count is d N_s + 1
    n_s = int((~p.rattler).sum())
    assert p.attrs["n_contacts"] > 2 * n_s + 1


def test_failed_force_qp_falls_back_to_the_dual_vertex_and_says_so(monkeypatch):
    """Should the QP fail, the geometric contacts carry the vertex's (balanced) duals."""
    import jamflow.protocols.calippso.network as cal_network

    def fail(*args, **kwargs):
        raise RuntimeError("minimum-norm force QP not solved: HiGHS status 'Infeasible'")

    monkeypatch.setattr(cal_network, "min_norm_forces", fail)
    lattice = lattice_packing("triangular", (8, 4))
    res = calippso(lattice.evolve(contacts=None))
    p = res.packing
    assert p.attrs["force_assignment"] == "lp_dual_vertex_on_geometric"
    assert "Infeasible" in p.attrs["force_assignment_comment"]
    assert _pairs(p.contacts) == _pairs(lattice.contacts) and not p.rattler.any()
    _balanced_and_normalised(p)
    assert p.attrs["n_zero_force_contacts"] == 192 - p.attrs["n_contacts_dual"]
