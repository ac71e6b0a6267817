"""CALiPPSO: jamming by a chain of LPs (jamflow.protocols.calippso).

Every jammed packing is checked with independent tools: isostaticity with
jamflow.analysis.contacts, force balance with force_balance_residual, overlaps over
all pairs with jamflow.state.packing.max_overlap, contacts from duals against contacts
from gaps, and the duality identity sum_c f_c sigma_c = 1 (paper Eq. 9).
"""

from __future__ import annotations

import highspy
import numpy as np
import pytest
from ls_data import ls_dat

import jamflow.protocols.calippso as cal
import jamflow.protocols.calippso.chain as cal_chain
import jamflow.protocols.calippso.container as cal_container
import jamflow.protocols.calippso.lp as cal_lp
import jamflow.protocols.calippso.recovery as cal_recovery
import jamflow.protocols.calippso.solver as cal_solver
from jamflow.analysis.contacts import summarize
from jamflow.analysis.overlap import contact_overlap
from jamflow.box import Box
from jamflow.cli import main
from jamflow.io import read_dataset, read_packing, write_packing
from jamflow.io.formats import read_dat
from jamflow.network import isostatic_count
from jamflow.network.spheres import (
    contacts_from_gaps,
    find_rattlers,
    force_balance_residual,
)
from jamflow.protocols.calippso import (
    WARM_PIVOTS_PER_ROW,
    IterationRecord,
    calippso,
    jamming_lp,
    result_to_dataset,
)
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import compress
from jamflow.state.packing import Packing, max_overlap, near_pairs
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL

#: two independent contact definitions agree: pairs closer than this relative gap
GEOMETRIC_GAP = 1e-9


def _check_jammed(res, start: Packing, walls: bool = False) -> None:
    """A jammed result: isostatic with the dual vertex's contacts and forces, or (a
    degenerate packing, e.g. N = 8 in 2D where 18 pairs touch) hyperstatic with its
    geometric contacts and minimum-norm forces; the checks below hold for both."""
    p = res.packing
    assert res.converged
    degenerate = p.attrs["force_assignment"] == "min_norm_balanced"
    assert p.attrs["force_assignment"] in ("lp_dual_vertex", "min_norm_balanced")
    # isostaticity counted independently from the stored contacts
    if not walls:
        s = summarize(p)
        if degenerate:
            assert s.n_contacts > s.isostatic_count, (s.n_contacts, s.isostatic_count)
        else:
            assert s.isostatic, (s.n_contacts, s.isostatic_count)
        assert s.n_contacts == p.attrs["n_contacts"]
        # rattlers are those of the geometric network, not of one dual vertex
        np.testing.assert_array_equal(p.rattler, find_rattlers(p.n, p.d, contacts_from_gaps(p, GEOMETRIC_GAP)))
        # force balance on every stable particle, independent residual
        r = force_balance_residual(p)[~p.rattler]
        assert r.max() < FORCE_BALANCE_TOL
    # no overlap over all pairs
    _, rel = max_overlap(p)
    assert rel < OVERLAP_TOL
    assert p.packing_fraction > start.packing_fraction
    # duality (paper Eq. 9): sum_c f_c sigma_c = 1
    sig = p.sigma(p.contacts[:, 0], p.contacts[:, 1])
    total = float(np.sum(p.force * sig))
    if walls:
        total += float(np.sum(res.wall_force * 0.5 * p.diameter[res.wall_contacts[:, 0]]))
    assert total == pytest.approx(1.0, rel=1e-6)
    # a vertex's duals are positive on its contacts; the minimum-norm assignment of a
    # degenerate network may leave a contact without force
    assert np.all(p.force >= 0) if degenerate else np.all(p.force > 0)
    # dual contacts == geometric contacts (gap < 1e-9) between stable particles, two
    # independent methods (a rattler may touch a neighbour with zero force)
    if not walls:
        geo = contacts_from_gaps(p, GEOMETRIC_GAP)
        stable = ~p.rattler
        geo = geo[stable[geo[:, 0]] & stable[geo[:, 1]]]
        dual = p.contacts[stable[p.contacts[:, 0]] & stable[p.contacts[:, 1]]]
        assert set(map(tuple, geo.tolist())) == set(map(tuple, dual.tolist()))


def test_ls_d3_jams(ls_d3_calippso):
    start, res = ls_d3_calippso
    _check_jammed(res, start)
    assert res.iterations <= 8
    hist = res.history
    assert hist.sizes["iteration"] == res.iterations
    assert float(hist["bound"].values[-1]) == np.inf  # the converging LP is unbounded
    assert hist["sqrt_gamma_minus_1"].values[-1] < 1e-12
    # iteration counts: interior point LPs iterate, warm simplex LPs pivot within the
    # per-row limit and never reach the interior point fallback
    solver = hist["solver"].values
    ipm_lp = solver == "ipm"
    warm = hist["warm_start"].values.astype(bool)
    assert ipm_lp.any() and warm.any()
    assert np.all(hist["ipm_iterations"].values[ipm_lp] > 0)
    assert np.all(hist["ipm_iterations"].values[warm] == 0)
    assert np.all(hist["simplex_iterations"].values[warm] <= WARM_PIVOTS_PER_ROW * hist["n_constraints"].values[warm])


@pytest.mark.slow
@pytest.mark.parametrize("d", [4, 5])
def test_ls_high_d_jams(d):
    start = read_dat(ls_dat(d))
    res = calippso(start)
    _check_jammed(res, start)


def test_random_2d_bidisperse():
    start = random_packing(128, 2, 0.4, "bi", seed=3, ratio=1.4)
    res = calippso(start)
    _check_jammed(res, start)
    assert 0.80 < res.packing.packing_fraction < 0.87


@pytest.fixture(scope="module")
def mono_3d():
    """A 3D monodisperse N = 128 start and its chain (shared: jammed once for the module)."""
    start = random_packing(128, 3, 0.25, "mono", seed=5)
    return start, calippso(start)


def test_random_3d_mono(mono_3d):
    start, res = mono_3d
    _check_jammed(res, start)
    assert 0.60 < res.packing.packing_fraction < 0.68


def test_polydisperse_small_and_fixed_point():
    start = random_packing(16, 2, 0.3, "poly", seed=2, width=0.2)
    res = calippso(start)
    _check_jammed(res, start)
    # fed back, the jammed packing is a fixed point: 1-2 LPs, same network (Q = 1)
    again = calippso(res.packing.evolve(contacts=None, force=None, rattler=None))
    assert again.iterations <= 2
    q, *_ = contact_overlap(res.packing, again.packing)
    assert q == 1.0
    assert again.packing.packing_fraction == pytest.approx(res.packing.packing_fraction, rel=1e-9)


@pytest.mark.parametrize("n,d", [(8, 2), (32, 2), (32, 3)])
def test_small_n(n, d):
    start = random_packing(n, d, 0.3, "bi", seed=n, ratio=1.4)
    res = calippso(start)
    _check_jammed(res, start)


def test_walls_2d():
    start = random_packing(64, 2, 0.3, "bi", seed=7, ratio=1.4)
    D = start.diameter * 0.8
    x = 0.5 * D.max() + start.position * (1.0 - D.max())
    start = start.evolve(position=x, diameter=D)
    res = calippso(start, walls=True)
    _check_jammed(res, start, walls=True)
    p = res.packing
    assert len(res.wall_contacts) > 0
    # every sphere inside the walls
    rad = 0.5 * p.diameter[:, None]
    assert np.all(p.position >= rad * (1 - OVERLAP_TOL)) and np.all(p.position <= 1 - rad * (1 - OVERLAP_TOL))
    # isostatic between walls: no translation symmetry, N_c = d N_s + 1
    assert p.attrs["n_contacts"] == 2 * p.attrs["n_stable"] + 1
    assert p.attrs["force_balance_residual"] < FORCE_BALANCE_TOL


def test_2d_monodisperse_reported():
    start = random_packing(64, 2, 0.5, "mono", seed=11)
    res = calippso(start)  # never a crash; hyperstaticity (App. A) is reported
    a = res.packing.attrs
    assert res.converged
    # independent count of the geometric network (gaps below 1e-9 relative)
    p = res.packing
    pairs, _ = near_pairs(p, 1e-9)
    geo = np.stack([pairs.i, pairs.j], axis=1)
    stable = ~find_rattlers(p.n, 2, geo)
    n_c_geo = int((stable[geo[:, 0]] & stable[geo[:, 1]]).sum())
    assert (a["n_contacts_geometric"], a["n_stable_geometric"]) == (n_c_geo, int(stable.sum()))
    geo_hyper = n_c_geo > isostatic_count(int(stable.sum()), 2, global_dofs=2)
    # every dual contact touches; the dual network is isostatic, or the packing is
    # hyperstatic (App. A count, or a degenerate crystal whose geometric network is)
    assert a["dual_not_geometric"] == 0
    assert a["isostatic"] == 1 or (a["hyperstatic"] == 1 and (a["isostatic_appendix_a"] == 1 or geo_hyper))
    for key in ("n_contacts_with_rattlers", "n_force_bearing_rattlers"):
        assert key in a
    _, rel = max_overlap(res.packing)
    assert rel < OVERLAP_TOL


def test_bad_inputs():
    start = random_packing(16, 2, 0.3, "mono", seed=1)
    with pytest.raises(ValueError, match="solver"):
        calippso(start, solver="pdlp-magic")
    with pytest.raises(ValueError, match="tol_s"):
        calippso(start, tol_s=-1.0)
    with pytest.raises(ValueError, match="relax"):
        calippso(start, relax=1.5)
    with pytest.raises(ValueError, match="solver_tol"):
        calippso(start, solver_tol=1e-6)  # row violations of 1e-6 are overlaps of ~5e-7
    with pytest.raises(ValueError, match="cutoff"):
        calippso(start, cutoff=1.0)
    x = start.position.copy()
    x[1] = x[0] + 0.5 * start.diameter[0] * np.array([1.0, 0.0])
    with pytest.raises(ValueError, match="overlap"):
        calippso(start.evolve(position=Box.cubic(2).wrap(x)))
    with pytest.raises(ValueError, match="wall"):
        calippso(start, walls=True)  # spheres cross the faces of the unit box


def test_max_iterations_error_is_clear():
    start = random_packing(64, 3, 0.2, "mono", seed=1)
    with pytest.raises(RuntimeError, match="not converged in 2 LPs"):
        calippso(start, max_iterations=2)


def test_relaxation_option():
    start = random_packing(64, 3, 0.3, "mono", seed=4)
    res = calippso(start, relax=0.5)
    _check_jammed(res, start)


@pytest.mark.parametrize("solver", ["ipm", "simplex", "ipm-center"])
def test_solvers_agree(solver):
    start = random_packing(48, 3, 0.3, "mono", seed=9)
    a = calippso(start)
    b = calippso(start, solver=solver)
    _check_jammed(b, start)
    # different vertex paths may reach different jammed states; both must be valid
    assert abs(a.packing.packing_fraction - b.packing.packing_fraction) < 0.05


def test_cli_roundtrip(tmp_path):
    # about 1 in 80 of these starts jams with one pair more within the 1e-8 contact gap
    # than the isostatic count, carrying no force (seed 38 with HiGHS presolve on the
    # interior point LPs, seed 6 without; 40 seeds each in 2D and 3D), which
    # summarize rightly calls hyperstatic: this start is isostatic either way
    start = random_packing(48, 2, 0.4, "bi", seed=7, ratio=1.4)
    src = write_packing(start, tmp_path / "in.nc")
    out = tmp_path / "out.nc"
    assert main(["calippso", str(src), str(out), "--quiet"]) == 0
    p = read_packing(out)
    ds = read_dataset(out)
    assert ds.attrs["converged"] == 1
    assert ds.attrs["protocol"].endswith(">calippso")
    assert "sqrt_gamma_minus_1" in ds and ds.sizes["iteration"] == ds.attrs["iterations"]
    assert summarize(p).isostatic
    assert ds.attrs["phi_J"] == pytest.approx(p.packing_fraction)
    # result_to_dataset carries the history and the settings
    assert "lp_time" in ds and "tol_s" in ds.attrs["parameters"]
    assert main(["calippso", str(tmp_path / "missing.nc"), str(out), "--quiet"]) == 1


def test_an_ls_start_keeps_its_phi_and_p_under_start_names():
    """A jammed packing's attributes describe the jammed packing: the LS snapshot's
    ``phi`` and ``p`` come back as ``phi_start`` and ``p_start``, and the stored packing
    fraction is phi_J, above the start's. The typed diagnostics carry the same numbers."""
    snap = compress(random_packing(32, 2, 0.5, "bi", seed=2), 1e-3, (1e3,), seed=2).snapshots[0]
    res = calippso(snap)
    a = res.packing.attrs
    assert "phi" not in a and "p" not in a
    assert a["phi_start"] == snap.attrs["phi"] and a["p_start"] == snap.attrs["p"] >= 1e3
    ds = result_to_dataset(res)
    assert "phi" not in ds.attrs and "p" not in ds.attrs
    assert ds.attrs["packing_fraction"] == a["phi_J"] == res.packing.packing_fraction > a["phi_start"]
    diag = res.diagnostics
    assert (diag.phi_J, diag.n_contacts, diag.isostatic_count) == (a["phi_J"], a["n_contacts"], a["isostatic_count"])
    assert diag.isostatic and diag.why == "ok" and diag.max_overlap == a["max_overlap"] < OVERLAP_TOL


def _record(it: int, sg: float, accepted: bool = True) -> IterationRecord:
    return IterationRecord(it, sg, 0.0, 0.0, 10, 0, 0, False, "Optimal", 0.0, "ipm", 1.7, 0.1,
                           np.nan, np.nan, accepted)


def test_stall_test_compares_window_with_earlier_best(monkeypatch):
    monkeypatch.setattr(cal_recovery, "STALL_WINDOW", 3)
    falling = [_record(k, 10.0 ** -k) for k in range(1, 8)]
    assert not cal_recovery._stalled(falling, 0)
    plateau = [_record(k, 1e-3 * (1 + 0.1 * (k % 2))) for k in range(1, 8)]
    assert cal_recovery._stalled(plateau, 0)
    # rejected LPs do not count, and nothing before ``start`` is compared
    assert not cal_recovery._stalled(plateau[:3] + [_record(9, 1e-9, accepted=False)], 0)
    assert not cal_recovery._stalled(plateau, 4)


def test_stalled_chain_recovers_unbounded_then_raises(monkeypatch):
    # every window counts as a stall: the first gets an unbounded LP, the third raises
    monkeypatch.setattr(cal_recovery, "STALL_WINDOW", 1)
    monkeypatch.setattr(cal_recovery, "STALL_PROGRESS", -np.inf)
    monkeypatch.setattr(cal_recovery, "MAX_STALL_RECOVERIES", 2)
    seen = []
    start = random_packing(64, 2, 0.4, "bi", seed=3)
    with pytest.raises(RuntimeError, match="stalled"):
        calippso(start, progress=seen.append)
    assert len(seen) == 6  # stalls after LPs 2, 4 and 6
    assert np.isinf(seen[2].bound) and np.isinf(seen[4].bound)


def test_loosest_solver_tolerance_still_jams_without_overlap():
    # solver_tol = 2 OVERLAP_TOL: row violations up to 2e-8, i.e. overlaps up to ~1e-8
    start = random_packing(64, 2, 0.4, "bi", seed=5)
    res = calippso(start, solver_tol=cal.MAX_SOLVER_TOL)
    s = summarize(res.packing)
    assert res.converged and s.isostatic
    assert max_overlap(res.packing)[1] <= OVERLAP_TOL
    assert force_balance_residual(res.packing)[~res.packing.rattler].max() < FORCE_BALANCE_TOL


def test_same_input_same_chain(mono_3d):
    # no decision of the chain depends on wall-clock time (warm starts are limited
    # by pivots, not seconds): two runs give bitwise identical packings and histories
    start, a = mono_3d
    b = calippso(start)
    assert np.array_equal(a.packing.position, b.packing.position)
    assert np.array_equal(a.history["sqrt_gamma_minus_1"].values, b.history["sqrt_gamma_minus_1"].values)
    assert list(a.history["solver"].values) == list(b.history["solver"].values)
    assert np.array_equal(a.history["simplex_iterations"].values, b.history["simplex_iterations"].values)


def test_jamming_lp_is_the_first_lp_of_the_chain():
    """``jamming_lp`` rebuilds the chain's first LP: solved independently it gives the
    chain's first sqrt(Gamma*) - 1, and its solution creates no overlap (the
    linearisation is conservative)."""
    start = random_packing(64, 3, 0.3, "mono", seed=2)
    lp = jamming_lp(start)
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("solver", "ipx")
    h.passModel(lp.to_highs())
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    z = np.asarray(h.getSolution().col_value)
    g = z[-1]
    res = calippso(start)
    assert np.sqrt(1.0 + g) - 1.0 == pytest.approx(float(res.history["sqrt_gamma_minus_1"].values[0]), rel=1e-7)
    moved = start.evolve(position=start.position + z[:-1].reshape(start.n, 3) * start.diameter.mean(),
                         diameter=start.diameter * np.sqrt(1.0 + g))
    assert max_overlap(moved)[1] <= OVERLAP_TOL


def _assert_same_packing(p: Packing, ref: Packing) -> None:
    """Two chains from one start ended in the same packing: the same contacts (Q = 1,
    as many), phi_J to 1e-12 and, since both stop within tol_s = 1e-9 of the jammed
    packing, force vectors equal to 1e-8 in norm (a small force alone can differ by
    ~1e-7 of itself)."""
    q, _, n_p, n_ref = contact_overlap(p, ref)
    assert q == 1.0 and n_p == n_ref
    force = {tuple(c): f for c, f in zip(ref.contacts.tolist(), ref.force)}
    f_ref = np.array([force[tuple(c)] for c in p.contacts.tolist()])
    assert np.linalg.norm(p.force - f_ref) <= 1e-8 * np.linalg.norm(f_ref)
    assert p.packing_fraction == pytest.approx(ref.packing_fraction, rel=1e-12)


def test_unscaled_warm_simplex_lps_end_in_the_packing_of_scaled_ones(ls_d3_calippso, monkeypatch):
    """The warm simplex LPs run without HiGHS's scaling (``WARM_SIMPLEX_SCALE``): on the
    LS example the chain takes as many LPs as with HiGHS's equilibration, its warm LPs
    pivot, and it ends in the same packing: same contacts (Q = 1), forces to 1e-8 in
    norm, phi_J to 1e-12. Both results pass every check of a jammed packing."""
    start, unscaled = ls_d3_calippso  # the default settings: unscaled warm simplex LPs
    assert cal_solver.WARM_SIMPLEX_SCALE != cal_solver._HIGHS_SCALE
    monkeypatch.setattr(cal_solver, "WARM_SIMPLEX_SCALE", cal_solver._HIGHS_SCALE)
    scaled = calippso(start)
    for res in (unscaled, scaled):
        _check_jammed(res, start)
        warm = res.history["warm_start"].values.astype(bool)
        assert warm.any() and res.history["simplex_iterations"].values[warm].sum() > 0
    assert unscaled.iterations == scaled.iterations
    # the premise: the two chains solved their warm LPs differently (99 pivots in all
    # unscaled against 121 scaled with highspy 1.16)
    pivots = [int(r.history["simplex_iterations"].values.sum()) for r in (unscaled, scaled)]
    assert pivots[0] != pivots[1]
    _assert_same_packing(unscaled.packing, scaled.packing)


def test_a_near_start_takes_the_near_cutoff_and_jams_to_the_packing_of_the_far_settings(ls_d3_calippso, monkeypatch):
    """The LS example is a near-jamming start (median nearest gap ~1e-6), a random start
    is not; the near start's first LP uses ``cutoff_near`` (fewer rows) and its
    interior point LPs skip presolve, and the chain ends in the same packing as with
    the far settings: same contacts (Q = 1) and forces to 1e-8 in norm."""
    start, near = ls_d3_calippso  # the default settings: the near-start rule on
    container = cal_container._Container(start.box, False)
    assert cal_lp._near_start(start.box.wrap(start.position), start.diameter, container)
    far = random_packing(128, 3, 0.3, "mono", seed=1)
    assert not cal_lp._near_start(far.box.wrap(far.position), far.diameter, container)
    monkeypatch.setattr(cal_chain, "_near_start", lambda *args: False)
    ref = calippso(start)
    assert near.packing.attrs["near_start"] == 1 and ref.packing.attrs["near_start"] == 0
    assert float(near.history["cutoff"].values[0]) == cal.DEFAULT_CUTOFF_NEAR
    assert float(ref.history["cutoff"].values[0]) == cal.DEFAULT_CUTOFF
    assert near.history["n_constraints"].values[0] < 0.7 * ref.history["n_constraints"].values[0]
    _assert_same_packing(near.packing, ref.packing)
