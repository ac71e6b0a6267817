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

import jamflow.calippso as cal
from jamflow.analysis.contacts import force_balance_residual, summarize
from jamflow.analysis.overlap import contact_overlap
from jamflow.calippso import calippso
from jamflow.initial import random_packing
from jamflow.packing import max_overlap
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
    original = cal._network_rows

    def wrong(step, lp):
        planted.append(1)
        return change(original(step, lp), step, lp)

    monkeypatch.setattr(cal, "_network_rows", wrong)
    return planted


def test_network_with_a_contact_removed_is_rejected_and_the_chain_continues(start, lp_chain, monkeypatch):
    def drop_first(rows, step, lp):
        return cal._Rows(rows.i[1:], rows.j[1:], rows.wall_particle, rows.wall_face, rows.x_build, rows.cutoff)

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
        return cal._Rows(np.append(rows.i[1:], i), np.append(rows.j[1:], j), rows.wall_particle, rows.wall_face,
                         rows.x_build, rows.cutoff)

    planted = _plant(monkeypatch, swap_first)
    res = calippso(start, finish="newton", walls=_walls(start))
    assert planted
    a = res.packing.attrs
    assert a["finish"] == "lp" and a["newton_attempts"] == len(planted)
    assert a["newton_rejections"] == len(planted)
    _assert_same_packing(res, lp_chain)


def test_unknown_finish_is_refused(start):
    with pytest.raises(ValueError, match="unknown finish"):
        calippso(start, finish="bisection")
