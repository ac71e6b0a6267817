"""The Newton finish of CALiPPSO (issue 19): the tail of the LP chain replaced by Newton
on the isostatic network's square system, accepted only under a certificate.

The reference is the pure LP chain (``finish="lp"``) on the same input: the finish
must give the same contacts (contact overlap Q = 1), the same forces (to 1e-8 of the
largest), an isostatic network, force balance and no overlap; a planted wrong
network must be rejected and the chain must go on to the LP chain's packing.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

import jamflow.protocols.calippso as cal
import jamflow.protocols.calippso.container as cal_container
import jamflow.protocols.calippso.lp as cal_lp
import jamflow.protocols.calippso.newton as cal_newton
from jamflow.analysis.contacts import summarize
from jamflow.analysis.overlap import contact_overlap
from jamflow.box import Box
from jamflow.network.spheres import force_balance_residual
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import Packing, max_overlap
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL

#: forces of the finish against the LP chain's, relative to the largest force (issue 19)
FORCE_RTOL = 1e-8


@pytest.fixture(scope="module", params=[(2, "bi", 3, False), (3, "mono", 2, False), (2, "bi", 3, True)],
                ids=["2d-bi-64", "3d-mono-64", "2d-bi-64-walls"])
def start(request):
    d, dispersity, seed, walls = request.param
    return random_packing(64, d, 0.5 if d == 2 else 0.3, dispersity, seed=seed, walls=walls)


def _walls(p) -> bool:
    return p.attrs.get("boundary") == "walls"


@pytest.fixture(scope="module")
def lp_chain(start):
    return calippso(start, finish="lp", walls=_walls(start))


def _forces_by_pair(p) -> dict[tuple[int, int], float]:
    return dict(zip(map(tuple, np.sort(p.contacts, axis=1).tolist()), p.force.tolist()))


def _assert_same_packing(res, ref) -> None:
    """Same contacts (Q = 1 both ways), forces and rattlers as the LP chain, and jammed."""
    p, q = res.packing, ref.packing
    if p.attrs["boundary"] == "walls":
        # Q compares periodic networks only (the overlap stage refuses walls): Q = 1 both
        # ways is the same set of pairs
        assert set(_forces_by_pair(p)) == set(_forces_by_pair(q))
    else:
        assert contact_overlap(p, q)[0] == 1.0 and contact_overlap(q, p)[0] == 1.0
    np.testing.assert_array_equal(p.rattler, q.rattler)
    fp, fq = _forces_by_pair(p), _forces_by_pair(q)
    assert max(abs(fp[k] - fq[k]) for k in fq) <= FORCE_RTOL * max(fq.values())
    assert res.converged and np.all(p.force > 0)
    total = float(np.sum(p.force * p.sigma(p.contacts[:, 0], p.contacts[:, 1])))
    if p.attrs["boundary"] == "walls":
        # wall contacts: same (particle, face) and forces; N_c = d N_s + 1
        np.testing.assert_array_equal(res.wall_contacts, ref.wall_contacts)
        assert np.max(np.abs(res.wall_force - ref.wall_force)) <= FORCE_RTOL * max(fq.values())
        assert p.attrs["isostatic"] == 1 and p.attrs["n_contacts"] == p.d * int((~p.rattler).sum()) + 1
        assert p.attrs["max_overlap"] < OVERLAP_TOL and p.attrs["force_balance_residual"] < FORCE_BALANCE_TOL
        total += float(np.sum(res.wall_force * 0.5 * p.diameter[res.wall_contacts[:, 0]]))
    else:
        assert summarize(p).isostatic
        assert force_balance_residual(p)[~p.rattler].max() < FORCE_BALANCE_TOL
        assert max_overlap(p)[1] < OVERLAP_TOL
    # duality (paper Eq. 9): sum_c f_c sigma_c = 1
    assert total == pytest.approx(1.0, rel=1e-9)


def test_newton_finish_gives_the_lp_chains_network_and_forces(start, lp_chain):
    res = calippso(start, finish="newton", walls=_walls(start))
    a = res.packing.attrs
    assert a["finish"] == "newton" and lp_chain.packing.attrs["finish"] == "lp"
    _assert_same_packing(res, lp_chain)
    # the finish replaced LPs of the tail and is recorded as its own history entry
    solver = res.history["solver"].values
    assert solver[-1] == "newton" and "newton" not in solver[:-1]
    assert int(res.history["newton_steps"].values[-1]) >= 1
    assert a["n_lps"] == res.iterations - 1 < lp_chain.packing.attrs["n_lps"]


def _plant(monkeypatch, change) -> list[int]:
    """Make every Newton finish start from a wrong network: ``change(rows, lp)`` edits
    the backbone rows of the LP's active set; returns the list of planted attempts."""
    planted = []
    original = cal_newton._network_rows

    def wrong(step, lp):
        planted.append(1)
        return change(original(step, lp), step, lp)

    monkeypatch.setattr(cal_newton, "_network_rows", wrong)
    return planted


def test_network_with_a_contact_removed_is_rejected_and_the_chain_continues(start, lp_chain, monkeypatch):
    def drop_first(rows, step, lp):
        return cal_lp._Rows(rows.i[1:], rows.j[1:], rows.wall_particle, rows.wall_face, rows.x_build, rows.cutoff)

    planted = _plant(monkeypatch, drop_first)
    res = calippso(start, finish="newton", walls=_walls(start))
    assert planted, "no Newton finish was tried"
    a = res.packing.attrs
    assert a["finish"] == "lp" and a["newton_attempts"] == len(planted)
    assert a["newton_rejections"] == len(planted)
    assert "backbone rows for" in a["newton_last_rejection"]
    _assert_same_packing(res, lp_chain)
    assert a["n_lps"] == lp_chain.packing.attrs["n_lps"]


def test_network_with_a_contact_swapped_for_a_gap_is_rejected(start, lp_chain, monkeypatch):
    """Still square (so Newton runs), but one contact replaced by the closest pair of
    stable particles that is not a contact: the certificate must refuse the result."""

    def swap_first(rows, step, lp):
        stable = ~step.rattler
        network = set(zip(rows.i.tolist(), rows.j.tolist()))
        candidates = [(i, j) for i, j in zip(lp.rows.i.tolist(), lp.rows.j.tolist())
                      if stable[i] and stable[j] and (i, j) not in network]
        gap = [lp.geo.rhs[k] for k, (i, j) in enumerate(zip(lp.rows.i.tolist(), lp.rows.j.tolist()))
               if stable[i] and stable[j] and (i, j) not in network]
        i, j = candidates[int(np.argmin(gap))]
        return cal_lp._Rows(np.append(rows.i[1:], i), np.append(rows.j[1:], j), rows.wall_particle, rows.wall_face,
                         rows.x_build, rows.cutoff)

    planted = _plant(monkeypatch, swap_first)
    res = calippso(start, finish="newton", walls=_walls(start))
    assert planted
    a = res.packing.attrs
    assert a["finish"] == "lp" and a["newton_attempts"] == len(planted)
    assert a["newton_rejections"] == len(planted)
    _assert_same_packing(res, lp_chain)


def _dense_newton_forces(chain, step, lp, container, packing):
    """The network's forces after full Newton by dense algebra, independent of the
    finish's sparse LU, chord steps and refinement: ``None`` when Newton leaves the
    neighbourhood (a move above twice ``NEWTON_MAX_MOVE``, looser than the finish) or
    does not converge in 30 steps."""
    d, n = packing.d, packing.n
    rows = cal_newton._network_rows(step, lp)
    cols = cal_newton._square_columns(~step.rattler, chain.anchor if container.has_translation else -1, d)
    if len(rows) != len(cols):
        return None
    x, D = chain.x.copy(), chain.D.copy()
    for _ in range(30):
        geo = cal_lp._row_geometry(rows, x, D, container.box)
        B = cal_lp._matrix(rows, geo, n, d, float(D.mean()))[:, cols].toarray()
        if np.abs(geo.rhs).max() < cal.NEWTON_GAP_TOL:
            e_g = np.zeros(len(cols))
            e_g[-1] = 1.0
            return np.linalg.solve(B.T, e_g)
        z = np.linalg.solve(B, geo.rhs)
        u = np.zeros(n * d)
        u[cols[:-1]] = z[:-1]
        u = u.reshape(n, d)
        if np.linalg.norm(u, axis=1).max() > 2 * cal.NEWTON_MAX_MOVE or z[-1] <= -1.0:
            return None
        x = container.wrap(x + u * float(D.mean()))
        D = D * np.sqrt(1.0 + z[-1])
    return None


@pytest.mark.parametrize("n, dispersity, seed", [(64, "mono", 2), pytest.param(128, "poly", 4, marks=pytest.mark.slow)],
                         ids=["3d-mono-64", "3d-poly-128"])
def test_early_rejection_agrees_with_full_newton(n, dispersity, seed, monkeypatch):
    """An attempt rejected before any step (a network force not positive at the LP's
    configuration) is one that full Newton by dense algebra refuses too, and a
    certified finish has the dense forces (to 1e-8 of the largest). These starts
    try several wrong networks before the right one."""
    start = random_packing(n, 3, 0.3, dispersity, seed=seed)
    verdicts = []
    finish = cal_newton._newton_finish

    def both(chain, step, lp, opt, container, packing):
        out = finish(chain, step, lp, opt, container, packing)
        verdicts.append((out, _dense_newton_forces(chain, step, lp, container, packing)))
        return out

    monkeypatch.setattr(cal_newton, "_newton_finish", both)
    calippso(start, finish="newton")
    early = [mu for (attempt, *_), mu in verdicts if attempt.steps == 0 and "LP's configuration" in attempt.reason]
    assert early, "no attempt was rejected before a Newton step"
    for mu in early:
        assert mu is None or mu.min() <= cal.CONTACT_DUAL_REL_TOL * mu.max()
    certified = [(out, mu) for out, mu in verdicts if out[0].certified]
    assert len(certified) == 1
    (_, _, D, net), mu = certified[0]
    # the finish's duals (forces times contact distances, paper Eq. 11) against the dense ones
    sig = 0.5 * (D[net.contacts[:, 0]] + D[net.contacts[:, 1]])
    mu_finish = np.concatenate([net.f_pair * sig, net.f_wall * 0.5 * D[net.wall_particles]])
    assert mu.min() > cal.CONTACT_DUAL_REL_TOL * mu.max()
    assert np.abs(mu_finish - mu).max() <= FORCE_RTOL * mu.max()


def test_transposed_solve_refines_on_a_nearby_lu_and_refactorises_a_far_one(monkeypatch):
    """The certificate's forces: ``B^T y = b`` from the LU of a nearby matrix (chord
    steps away) by refinement, to a componentwise backward error of round-off and the
    dense solution; from the LU of a far matrix by a fresh factorisation."""
    rng = np.random.default_rng(5)
    n = 300
    B = (sp.random(n, n, density=0.02, random_state=rng) + 4.0 * sp.eye(n)).tocsc()
    b = rng.standard_normal(n)
    exact = np.linalg.solve(B.toarray().T, b)
    factorisations = []
    splu = sla.splu
    monkeypatch.setattr(sla, "splu", lambda *a, **k: factorisations.append(1) or splu(*a, **k))
    for other, fresh in ((B + 1e-7 * sp.random(n, n, density=0.02, random_state=rng), 0), (B + 3.0 * sp.eye(n), 1)):
        factorisations.clear()
        y = cal_newton._transposed_solve(splu(other.tocsc()), B, b)
        assert len(factorisations) == fresh
        np.testing.assert_allclose(y, exact, rtol=1e-11, atol=0)
        backward = np.abs(b - B.T @ y) / (abs(B.T) @ np.abs(y) + np.abs(b))
        assert backward.max() <= cal.NEWTON_FORCE_RESIDUAL


def _cage(h: float, gap_behind: float):
    """A rattler (particle 0) overlapped by ``h`` by two neighbours at +-45 degrees of
    +x, with a third neighbour on -x at relative gap ``gap_behind``; unit spheres."""
    c = np.full(3, 5.0)
    a = np.radians(45.0)
    to = np.array([[np.cos(a), np.sin(a), 0.0], [np.cos(a), -np.sin(a), 0.0], [-1.0, 0.0, 0.0]])
    x = np.vstack([c, c + to * np.array([1.0 - h, 1.0 - h, 1.0 + gap_behind])[:, None]])
    box = Box.cubic(3, 10.0)
    return x, np.ones(4), Packing(x, np.ones(4), box), cal_container._Container(box, False)


@pytest.mark.parametrize("h", [1e-13, 1e-9])
def test_freeing_rattlers_clears_a_loose_cage_and_never_worsens_a_tight_one(h):
    """Pushing a rattler off the neighbours it overlaps: with room behind it the
    overlaps go to round-off; wedged (no room behind), the sweeps must not amplify
    them (the summed pushes turned 1e-9 into 5e-8 here, 6e-13 into 3.6e-7 at N = 4096)."""
    rattler = np.array([True, False, False, False])
    for gap_behind in (3 * h, 0.0):
        x, D, p, container = _cage(h, gap_behind)
        before = container.max_overlap(p)
        freed = cal_newton._free_rattlers(x, D, rattler, container, p)
        after = container.max_overlap(container.packing(p, freed, D))
        assert before == pytest.approx(h, rel=1e-3)
        assert after <= (1e-15 if gap_behind > 0 else before)
        assert np.array_equal(freed[1:], x[1:])  # only the rattler moves


def test_unknown_finish_is_refused(start):
    with pytest.raises(ValueError, match="unknown finish"):
        calippso(start, finish="bisection")
