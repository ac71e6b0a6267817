"""Contact detection, rattler removal, isostatic counting, force balance, summary."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.analysis.contacts import summarize
from jamflow.box import Box
from jamflow.network.counting import isostatic_count
from jamflow.network.spheres import (
    contact_network,
    contacts_from_gaps,
    find_rattlers,
    force_balance_residual,
)
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import Packing
from jamflow.tolerances import FORCE_BALANCE_TOL

SUMMARY_KEYS = {
    "N", "d", "phi", "pressure", "n_contacts", "n_rattlers", "n_stable", "isostatic",
    "isostatic_count", "counting", "z", "max_overlap", "max_overlap_rel", "force_balance_residual",
    "contact_source",
}


def _triangular_lattice(m: int = 6, rows: int = 6, a: float = 0.1, gamma: float = 0.0) -> Packing:
    """Touching discs (diameter a) on a triangular lattice filling a periodic box.

    With an even number of rows the lattice is periodic in an m a x rows a sqrt(3)/2
    box; a Lees-Edwards strain that shifts the top image by a whole number of
    spacings keeps it periodic (gamma * L_y = k a).
    """
    assert rows % 2 == 0
    dy = a * np.sqrt(3) / 2
    ij = np.stack(np.meshgrid(np.arange(m), np.arange(rows), indexing="ij"), -1).reshape(-1, 2)
    x = np.stack([ij[:, 0] * a + 0.5 * a * (ij[:, 1] % 2), ij[:, 1] * dy], axis=1)
    box = Box.lees_edwards([m * a, rows * dy], gamma)
    return Packing(box.wrap(x), np.full(len(x), a), box)


def _with_gap_contacts(p: Packing, gap_tol: float, force: float | None = 1.0) -> Packing:
    c = contacts_from_gaps(p, gap_tol)
    return p.evolve(contacts=c, force=None if force is None else np.full(len(c), force))


# --- contacts from gaps -------------------------------------------------------------------


@pytest.mark.parametrize("box", [Box.cubic(3), Box.lees_edwards([1.0, 1.0, 1.0], 5.6)])
def test_contacts_from_gaps_match_brute_force(box: Box) -> None:
    base = random_packing(300, 3, 0.3, "poly", seed=4, width=0.2)
    p = Packing(box.to_cartesian(base.position), base.diameter, box)
    i, j = np.triu_indices(p.n, 1)
    r = np.linalg.norm(box.minimum_image(p.position[j] - p.position[i]), axis=1)
    h = r / (0.5 * (p.diameter[i] + p.diameter[j])) - 1.0
    for gap_tol in (1e-3, 0.05, 0.3):
        c = contacts_from_gaps(p, gap_tol)
        ref = np.stack([i[h <= gap_tol], j[h <= gap_tol]], axis=1)
        np.testing.assert_array_equal(c, ref)
        assert c.dtype == np.int64
    assert len(contacts_from_gaps(p, 0.3)) > 0


def test_contacts_of_the_triangular_lattice() -> None:
    p = _triangular_lattice()
    c = contacts_from_gaps(p, 1e-9)
    assert len(c) == 3 * p.n
    np.testing.assert_array_equal(np.bincount(c.ravel(), minlength=p.n), 6)
    # second neighbours sit at sqrt(3) a: a gap of 0.73
    assert len(contacts_from_gaps(p, 0.7)) == 3 * p.n
    with pytest.raises(ValueError, match="gap_tol"):
        contacts_from_gaps(p, np.nan)


def test_contact_network_prefers_explicit_contacts() -> None:
    p = _triangular_lattice()
    explicit = p.evolve(contacts=[[0, 1]])
    np.testing.assert_array_equal(contact_network(explicit), [[0, 1]])
    assert len(contact_network(explicit, gap_tol=1e-9)) == 3 * p.n
    assert len(contact_network(p)) == 3 * p.n


# --- rattlers -----------------------------------------------------------------------------


def test_rattler_removal_cascades_along_a_chain() -> None:
    # d = 2: stable needs >= 3 contacts. Core: complete graph on 0..3 (3 contacts each).
    # Chain 4-5-6-7 hangs on the core: 7 and 6 go first, which leaves 5 with two
    # contacts, and then 4 with two; the core keeps three each.
    core = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    chain = [[0, 4], [1, 4], [4, 5], [2, 5], [5, 6], [6, 7]]
    rattler = find_rattlers(8, 2, np.array(core + chain))
    np.testing.assert_array_equal(np.flatnonzero(rattler), [4, 5, 6, 7])
    # without the cascade, 4 and 5 would have looked stable
    z = np.bincount(np.array(core + chain).ravel(), minlength=8)
    assert z[4] == 3 and z[5] == 3


def test_rattlers_in_three_dimensions() -> None:
    # d = 3: stable needs >= 4 contacts. K5 core (4 each); 5 touches 0, 1, 2, 6;
    # 6 touches 5, 3 only -> 6 goes, then 5 (three left); 8 has no contact at all.
    core = [[a, b] for a in range(5) for b in range(a + 1, 5)]
    extra = [[0, 5], [1, 5], [2, 5], [5, 6], [3, 6]]
    rattler = find_rattlers(9, 3, np.array(core + extra))
    np.testing.assert_array_equal(np.flatnonzero(rattler), [5, 6, 7, 8])
    assert find_rattlers(4, 2, np.zeros((0, 2), int)).all()


def test_wall_contacts_count_and_never_rattle() -> None:
    # d = 2, the chain of the cascade test: a wall under 6 and two walls at 7 (a
    # corner) hold the chain end, so nothing cascades; the wall contacts of a
    # particle that still rattles do not hold it
    core = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    chain = [[0, 4], [1, 4], [4, 5], [2, 5], [5, 6], [6, 7]]
    c = np.array(core + chain)
    assert not find_rattlers(8, 2, c, np.array([6, 7, 7])).any()
    np.testing.assert_array_equal(np.flatnonzero(find_rattlers(8, 2, c, np.array([7, 7]))), [4, 5, 6, 7])
    np.testing.assert_array_equal(find_rattlers(8, 2, c, np.zeros(0, int)), find_rattlers(8, 2, c))


def test_isostatic_count() -> None:
    assert isostatic_count(10, 2, global_dofs=2) == 19
    assert isostatic_count(4, 3, global_dofs=3) == 10
    assert isostatic_count(1024, 5, global_dofs=5) == 5 * 1023 + 1
    assert isostatic_count(0, 3, global_dofs=3) == 0
    for d in (2, 3, 4, 5):
        for n in (1, 2, 50):
            assert isostatic_count(n, d, global_dofs=d) == d * (n - 1) + 1


def test_summary_of_an_isostatic_graph() -> None:
    # K5 minus one edge in d = 2: N_c = 9 = 2 (5 - 1) + 1, every degree >= 3
    contacts = [[a, b] for a in range(5) for b in range(a + 1, 5) if (a, b) != (3, 4)]
    box = Box.cubic(2)
    x = np.random.default_rng(0).random((6, 2))
    p = Packing(x, np.full(6, 0.01), box, contacts=contacts)  # particle 5 has no contact
    s = summarize(p)
    assert (s.n_contacts, s.n_stable, s.n_rattlers, s.isostatic_count) == (9, 5, 1, 9)
    assert s.isostatic and s.z == pytest.approx(2 * 9 / 5)
    assert s.force_balance_residual is None
    assert s.contact_source == "packing"
    # one contact fewer: hypostatic
    assert not summarize(p.evolve(contacts=contacts[:-1])).isostatic


# --- force balance ------------------------------------------------------------------------


@pytest.mark.parametrize("k", [0, 1, 7])
def test_equal_forces_on_a_triangular_lattice_balance(k: int) -> None:
    gamma = k / (6 * np.sqrt(3) / 2)  # shifts the top image by k spacings
    p = _with_gap_contacts(_triangular_lattice(gamma=gamma), 1e-9)
    assert len(p.contacts) == 3 * p.n
    residual = force_balance_residual(p)
    assert residual.shape == (p.n,)
    assert np.max(residual) < FORCE_BALANCE_TOL
    s = summarize(p)
    assert s.n_rattlers == 0 and s.n_contacts == 3 * p.n
    assert not s.isostatic  # z = 6: hyperstatic
    assert s.force_balance_residual < FORCE_BALANCE_TOL
    assert s.max_overlap < 1e-15


def test_perturbed_forces_do_not_balance() -> None:
    p = _with_gap_contacts(_triangular_lattice(), 1e-9)
    delta = 0.3
    f = p.force.copy()
    f[7] += delta
    q = p.evolve(force=f)
    residual = force_balance_residual(q)
    i, j = q.contacts[7]
    # only the two ends of the changed contact feel a net force delta / <f>
    expected = np.zeros(p.n)
    expected[[i, j]] = delta / f.mean()
    np.testing.assert_allclose(residual, expected, rtol=1e-12, atol=1e-14)
    assert summarize(q).force_balance_residual == pytest.approx(delta / f.mean(), rel=1e-12)


def test_simple_cubic_lattice_with_equal_forces_balances() -> None:
    m, a = 5, 0.1
    grid = np.stack(np.meshgrid(*[np.arange(m)] * 3, indexing="ij"), -1).reshape(-1, 3) * a
    p = _with_gap_contacts(Packing(grid, np.full(m**3, a), Box.cubic(3, m * a)), 1e-9, force=2.5)
    assert len(p.contacts) == 3 * m**3
    assert np.max(force_balance_residual(p)) < FORCE_BALANCE_TOL
    f = p.force.copy()
    f[0] = 0.0
    assert np.max(force_balance_residual(p.evolve(force=f))) == pytest.approx(2.5 / f.mean())


def test_force_balance_needs_forces() -> None:
    p = _triangular_lattice()
    with pytest.raises(ValueError, match="no contact forces"):
        force_balance_residual(p)
    with pytest.raises(ValueError, match="no contact forces"):
        force_balance_residual(_with_gap_contacts(p, 1e-9, force=None))
    empty = p.evolve(contacts=np.zeros((0, 2), int), force=np.zeros(0))
    np.testing.assert_array_equal(force_balance_residual(empty), 0.0)


# --- summary ------------------------------------------------------------------------------


def test_summary_keys_and_values_of_a_real_ls_packing(calippso_ls_file) -> None:
    from jamflow.io.formats import read_dat

    p = read_dat(calippso_ls_file)
    s = summarize(p, gap_tol=1e-3)
    out = s.as_dict()
    assert set(out) == SUMMARY_KEYS
    assert (out["N"], out["d"]) == (1024, p.d)
    assert out["phi"] == p.packing_fraction
    assert out["n_stable"] + out["n_rattlers"] == 1024
    assert out["isostatic_count"] == isostatic_count(out["n_stable"], p.d, global_dofs=p.d)
    expected = ("hypostatic", "isostatic", "hyperstatic")[int(np.sign(out["n_contacts"] - out["isostatic_count"])) + 1]
    assert out["counting"] == expected
    assert out["z"] == pytest.approx(2 * out["n_contacts"] / out["n_stable"])
    # an LS packing near jamming: mean backbone coordination close to 2d, few rattlers
    assert 2 * p.d - 0.5 < out["z"] < 2 * p.d + 1.0
    assert out["n_rattlers"] < 0.05 * 1024
    # the largest overlap against an all-pairs minimum-image search (unit cubic box)
    i, j = np.triu_indices(p.n, 1)
    dx = p.position[i] - p.position[j]
    dx -= np.round(dx)
    h = np.sqrt(np.einsum("ij,ij->i", dx, dx)) / p.diameter[0] - 1.0
    assert out["max_overlap"] == pytest.approx(max(0.0, -h.min()) * p.diameter[0], rel=1e-12, abs=1e-300)
    assert out["max_overlap_rel"] < 1e-12
    assert out["contact_source"] == "gap <= 0.001"
