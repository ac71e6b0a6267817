"""The first LP of a start near jamming by jamflow.simplex from a crash basis of the
start's smallest gaps (``jamflow.protocols.calippso.crash``), against HiGHS's interior
point with crossover, the first LP's solver before.

``tests/data/calippso_near_start_n256.nc``: a 3D near start (LS to p = 1e7, N = 256).
``tests/data/ls_2d_mono_n64_p1e6.nc``: a 2D monodisperse LS packing at p = 1e6 (N = 64),
hyperstatic, so its LP is degenerate (its optimal duals are not unique).
"""

from __future__ import annotations

from pathlib import Path

import highspy
import numpy as np
import pytest

from jamflow import simplex
from jamflow.highs import new_highs
from jamflow.io import read_packing
from jamflow.io.formats import read_dat
from jamflow.protocols.calippso import (
    CONTACT_DUAL_REL_TOL,
    CRASH_MIN_COLUMNS,
    DEFAULT_CUTOFF_NEAR,
    SOLVER_TOL,
    calippso,
    jamming_lp,
)
from jamflow.protocols.calippso import crash as crash_module
from jamflow.protocols.calippso.crash import _crash_basis
from jamflow.protocols.calippso.lp import _highs_lp
from jamflow.protocols.calippso.options import _crash_first

DATA = Path(__file__).parent / "data"
TOL = simplex.Tolerances(primal=SOLVER_TOL, dual=SOLVER_TOL)
ZERO = int(highspy.HighsBasisStatus.kZero)


def _first_lp(name: str) -> dict:
    lp = jamming_lp(read_packing(DATA / name), cutoff=DEFAULT_CUTOFF_NEAR)
    return dict(A=lp.A, rhs=lp.rhs, lower=lp.col_lower, upper=lp.col_upper)


@pytest.fixture(scope="module", params=["calippso_near_start_n256.nc", "ls_2d_mono_n64_p1e6.nc"])
def solved(request):
    """The first LP, HiGHS's answer (interior point with crossover, presolve off as for a
    near start) and jamflow.simplex's from the crash basis."""
    lp = _first_lp(request.param)
    h = highspy.Highs()
    h.silent()
    for option, value in (("solver", "ipx"), ("run_crossover", "on"), ("presolve", "off"), ("threads", 1),
                          ("primal_feasibility_tolerance", SOLVER_TOL), ("dual_feasibility_tolerance", SOLVER_TOL),
                          ("ipm_optimality_tolerance", SOLVER_TOL)):
        h.setOptionValue(option, value)
    h.passModel(_highs_lp(lp["A"], lp["rhs"], lp["lower"], lp["upper"]))
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    sol = h.getSolution()
    crash = _crash_basis(new_highs(1), lp["A"], lp["rhs"], lp["lower"], lp["upper"])
    assert crash is not None
    cost = np.zeros(lp["A"].shape[1])
    cost[-1] = -1.0
    ours = simplex.solve(lp["A"], lp["rhs"], lp["lower"], lp["upper"], cost, crash[0], crash[1], TOL,
                         held=crash[0] == ZERO)
    return request.param, lp, crash, np.asarray(sol.col_value), np.asarray(sol.row_dual), ours


def _kkt(lp: dict, col: np.ndarray, row_dual: np.ndarray) -> None:
    """Optimality on its own: rows and bounds hold, non-negative forces on tight rows
    only, balancing every column off its bounds (``A^T mu = e_g``)."""
    A, mu = lp["A"], -row_dual
    assert np.max(A @ col - lp["rhs"]) <= SOLVER_TOL
    assert np.all(col >= lp["lower"] - SOLVER_TOL) and np.all(col <= lp["upper"] + SOLVER_TOL)
    assert mu.min() >= -SOLVER_TOL
    assert np.max(mu * (lp["rhs"] - A @ col)) <= 1e-14
    e_g = np.zeros(A.shape[1])
    e_g[-1] = 1.0
    off = (col > lp["lower"] + SOLVER_TOL) & (col < lp["upper"] - SOLVER_TOL)
    assert np.max(np.abs((A.T @ mu - e_g)[off])) <= 1e-12


def test_the_crash_basis_is_the_tight_rows_with_held_columns(solved):
    _, lp, (col, row), *_ = solved
    n = lp["A"].shape[1]
    basic = int(highspy.HighsBasisStatus.kBasic)
    assert np.sum(row != basic) + np.sum(col != basic) == n  # a square working set
    assert col[-1] == basic  # g is never held
    held = col == ZERO
    assert np.all(lp["lower"][held] < 0.0) and np.all(lp["upper"][held] > 0.0)


def test_the_crash_first_lp_agrees_with_highs(solved):
    name, lp, _, col_h, dual_h, ours = solved
    assert ours.optimal
    g, g_h = ours.col_value[-1], col_h[-1]
    assert abs(g - g_h) <= 1e-12 * (1.0 + g_h)
    _kkt(lp, ours.col_value, ours.row_dual)
    _kkt(lp, col_h, dual_h)
    # the answer is a vertex: no column is left held between its bounds
    assert not np.any(ours.col_status == ZERO)
    if name.startswith("calippso"):  # nondegenerate: the same contacts and forces
        mu, mu_h = -ours.row_dual, -dual_h
        assert np.array_equal(mu > CONTACT_DUAL_REL_TOL * mu.max(), mu_h > CONTACT_DUAL_REL_TOL * mu_h.max())
        assert np.max(np.abs(mu - mu_h)) <= 1e-9 * mu_h.max()


def test_a_chain_with_the_crash_first_lp_ends_jammed():
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    ours = calippso(start, first_lp="crash")
    a = ours.packing.attrs
    assert ours.converged and a["isostatic"] and a["first_lp"] == "crash" and a["first_lp_fallbacks"] == 0
    assert ours.packing.parameters["first_lp"] == "crash"
    assert a["max_overlap"] <= 1e-13


@pytest.mark.parametrize("trouble", ["no crash basis", "unstable pivot"])
def test_trouble_in_the_first_lp_falls_back_to_the_interior_point_and_is_counted(monkeypatch, trouble):
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    highs = calippso(start, first_lp="highs")
    if trouble == "no crash basis":
        monkeypatch.setattr(crash_module, "CRASH_GAP", 0.0)
    else:
        solve = simplex.solve

        def troubled(*args, **kwargs):
            res = solve(*args, **kwargs)
            return simplex.Result(trouble, res.col_value, res.row_dual, res.col_dual, res.col_status,
                                  res.row_status, res.stats)

        monkeypatch.setattr(simplex, "solve", troubled)
    ours = calippso(start, first_lp="crash", warm_engine="highs")
    assert ours.history["solver"].values[0] == "crash>ipm"
    assert ours.history["warm_fallback"].values[0] == trouble
    a = ours.packing.attrs
    assert a["first_lp_fallbacks"] == 1 and a["first_lp"] == "crash>ipm" and a["warm_fallbacks"] == 0
    pa, pb = ours.packing, highs.packing
    assert np.array_equal(np.sort(pa.contacts, axis=1), np.sort(pb.contacts, axis=1))
    assert abs(pa.attrs["phi_J"] - pb.attrs["phi_J"]) <= 1e-12


def test_the_first_lp_option_is_checked_and_auto_follows_the_lp_size():
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    with pytest.raises(ValueError, match="first LP"):
        calippso(start, first_lp="gurobi")
    assert _crash_first("auto", CRASH_MIN_COLUMNS) and not _crash_first("auto", CRASH_MIN_COLUMNS - 1)
    assert _crash_first("crash", 3) and not _crash_first("highs", CRASH_MIN_COLUMNS)


def test_no_crash_basis_where_the_gaps_do_not_separate():
    """The authors' d = 3 LS example: a third of its columns have a row below CRASH_GAP."""
    lp = jamming_lp(read_dat(DATA / "calippso-ls" / "Centers-after-LS--N-1024--d-3.dat"), cutoff=DEFAULT_CUTOFF_NEAR)
    assert np.sum(lp.rhs < crash_module.CRASH_GAP) < crash_module.CRASH_MIN_TIGHT * lp.A.shape[1]
    assert _crash_basis(new_highs(1), lp.A, lp.rhs, lp.col_lower, lp.col_upper) is None
