"""CALiPPSO's interior point LPs as their explicit dual (``jamflow.protocols.calippso.dual``).

The dual's answer, read back, must be the LP's own: the same optimum as HiGHS's IPX
with crossover on the LP as it is, feasible rows and bounds, balanced non-negative
forces, and a vertex basis that HiGHS's primal simplex accepts as optimal without a
pivot. In the chain, HiPO on the dual must jam the packing, and any trouble there is
re-solved by IPX on the LP as it is, printed and counted.
"""

from __future__ import annotations

from pathlib import Path

import highspy
import numpy as np
import pytest

from jamflow.analysis.contacts import summarize
from jamflow.cli import main
from jamflow.highs import new_highs
from jamflow.io import read_packing, write_packing
from jamflow.network.spheres import force_balance_residual
from jamflow.protocols.calippso import (
    DEFAULT_CUTOFF_NEAR,
    SOLVER_TOL,
    calippso,
    jamming_lp,
)
from jamflow.protocols.calippso import solver as lp_solver
from jamflow.protocols.calippso.dual import dual_lp, primal_answer
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import max_overlap
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL

DATA = Path(__file__).parent / "data"
BASIC, LOWER, UPPER = (int(s) for s in (highspy.HighsBasisStatus.kBasic, highspy.HighsBasisStatus.kLower,
                                       highspy.HighsBasisStatus.kUpper))


def _highs(solver: str) -> highspy.Highs:
    h = new_highs(1)
    for option, value in (("solver", solver), ("run_crossover", "on"), ("presolve", "off"),
                          ("primal_feasibility_tolerance", SOLVER_TOL), ("dual_feasibility_tolerance", SOLVER_TOL),
                          ("ipm_optimality_tolerance", SOLVER_TOL)):
        h.setOptionValue(option, value)
    return h


def _lp(name: str):
    if name == "random":
        return jamming_lp(random_packing(48, 3, 0.3, "mono", seed=5))
    return jamming_lp(read_packing(DATA / name), cutoff=DEFAULT_CUTOFF_NEAR)


@pytest.fixture(scope="module", params=["calippso_near_start_n256.nc", "ls_2d_mono_n64_p1e6.nc", "random"])
def answers(request):
    """The LP, IPX's answer on it and IPX's answer on its dual (both with crossover, which
    ends at a vertex; independent of HiPO), read back."""
    lp = _lp(request.param)
    h = _highs("ipx")
    h.passModel(lp.to_highs())
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    z_ipx = np.asarray(h.getSolution().col_value)
    dual = dual_lp(lp.A, lp.rhs, lp.col_lower, lp.col_upper)
    h = _highs("ipx")
    h.passModel(dual.lp)
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    sol, basis = h.getSolution(), h.getBasis()
    answer = primal_answer(dual, np.asarray(sol.col_value), np.asarray(sol.row_dual),
                           np.array([int(v) for v in basis.col_status], dtype=np.int8))
    assert answer is not None
    return lp, z_ipx, answer


def test_the_duals_answer_is_the_lps_optimum(answers):
    lp, z_ipx, (z, y, col_status, row_status) = answers
    # the same optimum: g of two exact vertices of one LP
    assert z[-1] == pytest.approx(z_ipx[-1], rel=1e-10)
    # feasible: rows (relative-gap units) and bounds
    assert np.max(lp.A @ z - lp.rhs) <= SOLVER_TOL
    assert np.all(z >= lp.col_lower - SOLVER_TOL) and np.all(z <= lp.col_upper + SOLVER_TOL)
    # forces: non-negative, summing to 1 (g's column), balanced on every column off its bounds
    assert y.min() >= -SOLVER_TOL
    assert np.sum(y) == pytest.approx(1.0, abs=1e-12)
    inside = (z > lp.col_lower + 1e-12) & (z < lp.col_upper - 1e-12)
    inside[-1] = False
    assert np.max(np.abs((lp.A.T @ y)[inside])) <= 1e-12 * np.max(np.abs(lp.A.T) @ np.abs(y))


def test_the_duals_basis_is_an_optimal_vertex_basis_of_the_lp(answers):
    lp, _, (z, y, col_status, row_status) = answers
    m = lp.A.shape[0]
    assert int(np.sum(row_status == BASIC) + np.sum(col_status == BASIC)) == m
    # complementarity: active rows are tight, nonbasic columns sit on their bound
    assert np.max(np.abs((lp.A @ z - lp.rhs)[row_status == UPPER])) <= 1e-12
    assert np.all(z[col_status == LOWER] == lp.col_lower[col_status == LOWER])
    assert np.all(z[col_status == UPPER] == lp.col_upper[col_status == UPPER])
    assert np.all(y[row_status == BASIC] == 0.0)
    # HiGHS's primal simplex from this basis: optimal without a pivot, the same g
    h = _highs("simplex")
    h.setOptionValue("simplex_strategy", 4)
    h.passModel(lp.to_highs())
    b = highspy.HighsBasis()
    b.col_status = [highspy.HighsBasisStatus(int(v)) for v in col_status]
    b.row_status = [highspy.HighsBasisStatus(int(v)) for v in row_status]
    b.valid = True
    h.setBasis(b)
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    assert h.getInfo().simplex_iteration_count == 0
    assert h.getSolution().col_value[-1] == pytest.approx(z[-1], rel=1e-12)


def test_a_dual_basis_that_is_no_primal_basis_is_refused(answers):
    lp, _, (z, y, col_status, row_status) = answers
    dual = dual_lp(lp.A, lp.rhs, lp.col_lower, lp.col_upper)
    m, k = dual.n_rows, len(dual.free)
    n_lower = len(dual.with_lower)
    status = np.zeros(dual.lp.num_col_, dtype=np.int8)  # every dual column at zero: no basic variable
    status[:m] = np.where(row_status == UPPER, BASIC, LOWER)
    # w_l and w_u of one column both basic: the column cannot be at both bounds
    both = int(np.flatnonzero(np.isin(dual.with_lower, dual.with_upper))[0])
    status[m + both] = BASIC
    status[m + n_lower + int(np.searchsorted(dual.with_upper, dual.with_lower[both]))] = BASIC
    assert primal_answer(dual, np.zeros(dual.lp.num_col_), np.zeros(k), status) is None
    # one basic variable too few
    status = np.full(dual.lp.num_col_, LOWER, dtype=np.int8)
    assert primal_answer(dual, np.zeros(dual.lp.num_col_), np.zeros(k), status) is None


def test_the_dual_needs_a_free_g():
    lp = _lp("random")
    upper = lp.col_upper.copy()
    upper[-1] = lp.col_lower[-1]
    with pytest.raises(ValueError, match="free g"):
        dual_lp(lp.A, lp.rhs, lp.col_lower, upper)


@pytest.fixture(scope="module")
def near_start():
    return read_packing(DATA / "calippso_near_start_n256.nc")


def _jammed(res) -> None:
    p = res.packing
    assert res.converged and summarize(p).isostatic
    assert force_balance_residual(p)[~p.rattler].max() < FORCE_BALANCE_TOL
    assert max_overlap(p)[1] < OVERLAP_TOL


def test_hipo_on_the_dual_jams_a_near_start_with_ipxs_first_optimum(near_start):
    ipx = calippso(near_start, interior="ipx")
    hipo = calippso(near_start, interior="hipo")
    _jammed(hipo)
    assert list(hipo.history["interior"].values[:1]) == ["hipo-dual"]
    assert hipo.packing.attrs["interior_lps"] == "hipo-dual 1" and hipo.packing.attrs["interior_fallbacks"] == 0
    assert list(ipx.history["interior"].values[:1]) == ["ipx"]
    g = [float(r.history["sqrt_gamma_minus_1"].values[0]) for r in (ipx, hipo)]
    assert g[1] == pytest.approx(g[0], rel=1e-9)


def test_auto_takes_hipo_on_the_dual_from_its_column_count(near_start, monkeypatch):
    assert list(calippso(near_start).history["interior"].values[:1]) == ["ipx"]  # 769 columns
    monkeypatch.setattr(lp_solver, "HIPO_MIN_COLUMNS", 769)
    assert list(calippso(near_start).history["interior"].values[:1]) == ["hipo-dual"]


def test_trouble_on_the_dual_is_solved_by_ipx_printed_and_counted(near_start, monkeypatch, tmp_path, capsys):
    ipx = calippso(near_start, interior="ipx")
    monkeypatch.setattr(lp_solver, "primal_answer", lambda *args: None)
    res = calippso(near_start, interior="hipo")
    _jammed(res)
    # IPX solved the LP as it is: the IPX chain, LP for LP
    assert res.packing.attrs["interior_fallbacks"] == 1
    assert res.history["interior"].values[0] == "ipx after hipo-dual: dual basis not a primal basis"
    assert res.history["simplex_iterations"].values.tolist() == ipx.history["simplex_iterations"].values.tolist()
    np.testing.assert_array_equal(res.packing.position, ipx.packing.position)
    write_packing(near_start, tmp_path / "in.nc")
    assert main(["calippso", str(tmp_path / "in.nc"), str(tmp_path / "out.nc"), "--interior", "hipo"]) == 0
    out = capsys.readouterr()
    line = "LP 1: HiPO on the dual reported 'dual basis not a primal basis'; IPX solved the LP as it is"
    assert line in out.out + out.err
    assert "(1 HiPO dual attempt(s) re-solved by IPX)" in out.out
