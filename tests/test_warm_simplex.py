"""jamflow.simplex, the warm simplex of CALiPPSO's LPs, against HiGHS.

``tests/data/calippso_warm_lps.npz`` holds three warm LPs captured from 3D near-start
chains (LS to p = 1e7 from RSA at phi = 0.3, ``benchmarks/calippso.py``'s
``near_start``; ``benchmarks/warm_lp.py capture``): N = 256 seed 2 LP 1 (HiGHS: 45
pivots), N = 512 seed 2 LP 1 (51) and LP 15 (139, after its rows were rebuilt), each
with the basis the chain carried to it. ``tests/data/calippso_near_start_n256.nc`` is
the N = 256 seed 2 start.

The physics the chain reads from an LP are Gamma* = 1 + g, the active set (rows with a
dual above ``CONTACT_DUAL_REL_TOL`` of the largest: the contacts) and the duals (the
forces), so those are compared with HiGHS's answer from the same basis.
"""

from __future__ import annotations

from pathlib import Path

import highspy
import numpy as np
import pytest
import scipy.sparse as sp

from jamflow import simplex
from jamflow.io import read_packing
from jamflow.protocols.calippso import (
    CONTACT_DUAL_REL_TOL,
    SOLVER_TOL,
    WARM_ENGINE_MIN_COLUMNS,
    WARM_SIMPLEX_SCALE,
    calippso,
    jamming_lp,
)
from jamflow.protocols.calippso.lp import _highs_lp
from jamflow.protocols.calippso.options import _engine_of_warm_lps
from jamflow.protocols.lattices import lattice_packing

DATA = Path(__file__).parent / "data"
TOL = simplex.Tolerances(primal=SOLVER_TOL, dual=SOLVER_TOL)
LPS = ("n256_a", "n512_a", "n512_b")


def _lp(name: str) -> dict:
    z = np.load(DATA / "calippso_warm_lps.npz")
    get = {k: z[f"{name}_{k}"] for k in ("indptr", "indices", "data", "shape", "rhs", "col_lower", "col_upper",
                                         "col_status", "row_status")}
    A = sp.csc_matrix((get["data"], get["indices"], get["indptr"]), shape=tuple(get["shape"]))
    return dict(A=A, rhs=get["rhs"], lower=get["col_lower"], upper=get["col_upper"],
                col_status=get["col_status"].astype(np.int64), row_status=get["row_status"].astype(np.int64))


def _cost(n: int) -> np.ndarray:
    c = np.zeros(n)
    c[-1] = -1.0  # min -g
    return c


def _ours(lp: dict, **options) -> simplex.Result:
    return simplex.solve(lp["A"], lp["rhs"], lp["lower"], lp["upper"], _cost(lp["A"].shape[1]), lp["col_status"],
                         lp["row_status"], TOL, **options)


def _starting_state(name: str, lu: str = "auto"):
    """The solver's state of a captured LP at its carried working set, not factorised."""
    from jamflow.simplex.state import State

    lp = _lp(name)
    st = State(lp["A"], lp["rhs"], lp["lower"], lp["upper"], _cost(lp["A"].shape[1]), TOL, None, "metis", lu)
    st.set_working_set(lp["col_status"], lp["row_status"])
    return st


def _highs(lp: dict, warm: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """HiGHS's columns and row duals: the primal simplex from the carried basis, set up as
    the chain's warm LPs (unscaled, the chain's tolerances), or cold."""
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 1)
    for option in ("primal_feasibility_tolerance", "dual_feasibility_tolerance"):
        h.setOptionValue(option, SOLVER_TOL)
    h.setOptionValue("solver", "simplex")
    h.setOptionValue("simplex_strategy", 4)
    h.setOptionValue("simplex_scale_strategy", WARM_SIMPLEX_SCALE)
    h.passModel(_highs_lp(lp["A"], lp["rhs"], lp["lower"], lp["upper"]))
    if warm:
        basis = highspy.HighsBasis()
        basis.col_status = [highspy.HighsBasisStatus(int(v)) for v in lp["col_status"]]
        basis.row_status = [highspy.HighsBasisStatus(int(v)) for v in lp["row_status"]]
        basis.valid = True
        h.setBasis(basis)
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    sol = h.getSolution()
    return np.asarray(sol.col_value), np.asarray(sol.row_dual)


def _kkt(lp: dict, col: np.ndarray, row_dual: np.ndarray) -> None:
    """Optimality of an answer on its own, to the chain's tolerances: rows and bounds
    hold, the duals of ``min -g`` are non-negative forces on tight rows only and balance
    every column off its bounds (``A^T mu = e_g``, paper Eq. 9 for the column of g)."""
    A, mu = lp["A"], -row_dual
    assert np.max(A @ col - lp["rhs"]) <= SOLVER_TOL
    assert np.all(col >= lp["lower"] - SOLVER_TOL) and np.all(col <= lp["upper"] + SOLVER_TOL)
    assert mu.min() >= -SOLVER_TOL
    slack = lp["rhs"] - A @ col
    assert np.max(mu * slack) <= 1e-14  # complementarity
    e_g = np.zeros(A.shape[1])
    e_g[-1] = 1.0
    off = (col > lp["lower"] + SOLVER_TOL) & (col < lp["upper"] - SOLVER_TOL)
    assert np.max(np.abs((A.T @ mu - e_g)[off])) <= 1e-12


def _agree(lp: dict, ours: simplex.Result, col_h: np.ndarray, dual_h: np.ndarray) -> None:
    """Gamma* to 1e-12 relative, the same active set, duals to 1e-9 of the largest."""
    assert ours.optimal
    g, g_h = ours.col_value[-1], col_h[-1]
    assert abs(g - g_h) <= 1e-12 * (1.0 + g_h)
    mu, mu_h = -ours.row_dual, -dual_h
    assert np.array_equal(mu > CONTACT_DUAL_REL_TOL * mu.max(), mu_h > CONTACT_DUAL_REL_TOL * mu_h.max())
    assert np.max(np.abs(mu - mu_h)) <= 1e-9 * mu_h.max()
    _kkt(lp, ours.col_value, ours.row_dual)


@pytest.mark.parametrize("lu", ("pardiso", "superlu"))
@pytest.mark.parametrize("name", LPS)
def test_warm_lps_end_where_highs_ends_from_the_same_basis(name, lu):
    lp = _lp(name)
    ours = _ours(lp, lu=lu)
    assert ours.stats.lu == lu and ours.stats.superlu_fallbacks == 0
    _agree(lp, ours, *_highs(lp))
    assert ours.stats.pivots > 0  # the carried basis is not optimal
    # the final basis names n constraints: M basic variables in all
    assert int(np.sum(ours.row_status == 1) + np.sum(ours.col_status == 1)) == lp["A"].shape[0]


def test_many_refactorisations_and_either_pricing_give_the_same_answer():
    lp = _lp("n512_a")
    col_h, dual_h = _highs(lp)
    often = _ours(lp, max_etas=2)
    assert often.stats.factorisations >= 5 and often.stats.pivots >= 10
    _agree(lp, often, col_h, dual_h)
    _agree(lp, _ours(lp, pricing="devex"), col_h, dual_h)
    _agree(lp, _ours(lp, ordering="colamd", lu="superlu"), col_h, dual_h)
    _agree(lp, _ours(lp, max_etas=2, lu="superlu"), col_h, dual_h)


#: Backward error of one solve, ``|W x - b|_inf / | |W| |x| |_inf``, per LU library. SuperLU (partial
#: pivoting) is at rounding level (measured 3e-15 ... 7e-15 on working sets); PARDISO pivots only
#: inside supernodes after a matching, measured up to 9.7e-12 (N = 4096) and 4.9e-11 (N = 2048) on
#: working sets, 1.8e-12 on ``n512_b`` on an AMD EPYC (docs/notes/warm-simplex.md, "The libraries on
#: the working sets"): ``jamflow.simplex`` refines its last solution against ``W`` for that reason.
#: The same bounds serve the forward error of ``W^T y = (row k of W)`` against ``e_k``.
SOLVE_BACKWARD_ERROR = {"superlu": 1e-12, "pardiso": 1e-10}


def test_the_two_lu_libraries_solve_a_working_set_alike():
    # the starting working set of a captured LP, factorised by each library: the solves
    # W x = b and W^T y = c (dense, and sparse: a unit vector, a row of W) agree, each has
    # the backward error of its library, and one step of iterative refinement on the
    # factors (what the simplex's last step does) brings every one to rounding level
    W = _starting_state("n512_b").working_matrix()
    n = W.shape[0]
    rng = np.random.default_rng(3)
    b, k = rng.standard_normal(n), int(rng.integers(n))
    unit = np.zeros(n)
    unit[k] = 1.0
    row_k = W[k].toarray().ravel()

    def backward(M, x, rhs):
        return np.max(np.abs(M @ x - rhs)) / np.max(abs(M) @ np.abs(x))

    answers = {}
    for lu in ("pardiso", "superlu"):
        f = simplex.factor.Factor(n, lu=lu)
        f.factorise(W)
        assert f.lu == lu and f.on_pardiso == (lu == "pardiso") and f.fill > W.nnz
        x, y, d, e = f.ftran(b), f.btran(b), f.ftran(unit), f.btran(row_k)  # W^T e_k is row k of W
        assert backward(W, x, b) <= SOLVE_BACKWARD_ERROR[lu] and backward(W.T, y, b) <= SOLVE_BACKWARD_ERROR[lu]
        assert backward(W, d, unit) <= SOLVE_BACKWARD_ERROR[lu] and np.max(np.abs(e - unit)) <= SOLVE_BACKWARD_ERROR[lu]
        x, y = x + f.ftran(b - W @ x), y + f.btran(b - W.T @ y)
        assert backward(W, x, b) <= 1e-14 and backward(W.T, y, b) <= 1e-14
        answers[lu] = np.concatenate([x, y, d])
        f.release()
    assert np.max(np.abs(answers["pardiso"] - answers["superlu"])) <= 1e-9 * np.max(np.abs(answers["superlu"]))


def test_a_block_of_transposed_solves_is_the_column_by_column_one():
    # btran_many (the pricing sketch's start: PARDISO solves the block in one pass) equals
    # btran column by column, on fresh factors and after three row etas, and solves W_k^T Y = C;
    # PARDISO's block kernels round differently, so "equal" is to its accuracy (backward
    # errors up to 1e-11 on working sets, docs/notes/warm-simplex.md)
    st = _starting_state("n512_b", "pardiso")
    f = st.factor
    f.factorise(st.working_matrix())
    n = st.n
    C = np.random.default_rng(5).standard_normal((n, 6))
    free_rows = np.flatnonzero(st.row_slot < 0)
    for count in (0, 3):
        Y = f.btran_many(C)
        assert Y.shape == (n, 6) and f.count == count
        for j in range(6):
            assert np.max(np.abs(Y[:, j] - f.btran(C[:, j]))) <= 1e-10 * np.max(np.abs(Y[:, j]))
        W = st.working_matrix()
        assert np.max(np.abs(W.T @ Y - C)) <= 1e-9 * np.max(abs(W.T) @ np.abs(Y))
        if count == 0:
            for p, i in zip((3, 40, 200), free_rows[:3]):  # three rows of A replace three members
                beta = f.btran(st.normal(0, i))
                if abs(beta[p]) > 1e-3:
                    st.swap(p, 0, i, 1, st.b[i], beta)
            assert f.count == 3
    f.release()


def _perturbing_every_other_lu(monkeypatch):
    """PARDISO reports a perturbed pivot on its 1st, 3rd, ... factorisation: each LU of W
    is then redone on W^T, which is not perturbed."""
    from jamflow.simplex import _pardiso

    factorise, calls = _pardiso.PardisoLU.factorise, [0]

    def perturbing(self, W):
        factorise(self, W)
        calls[0] += 1
        if calls[0] % 2 == 1:
            self.perturbed = 1
    monkeypatch.setattr(_pardiso.PardisoLU, "factorise", perturbing)


def test_a_perturbed_pardiso_lu_is_redone_on_the_transpose_and_solves_alike(monkeypatch):
    # the factors of W^T serve both solves with their roles swapped: the same x, y and
    # block of y as from the factors of W (to PARDISO's accuracy), with backward errors at rounding level
    W = _starting_state("n512_b").working_matrix()
    n = W.shape[0]
    rng = np.random.default_rng(4)
    b, C = rng.standard_normal(n), rng.standard_normal((n, 3))
    plain = simplex.factor.Factor(n, lu="pardiso")
    plain.factorise(W)
    assert not plain.pardiso_transposed and plain.transposed_lus == 0
    expected = np.concatenate([plain.ftran(b), plain.btran(b), plain.btran_many(C).ravel()])
    plain.release()
    _perturbing_every_other_lu(monkeypatch)
    f = simplex.factor.Factor(n, lu="pardiso")
    f.factorise(W)
    assert f.on_pardiso and f.pardiso_transposed and f.transposed_lus == 1 and f.superlu_fallbacks == 0
    x, y, Y = f.ftran(b), f.btran(b), f.btran_many(C)
    assert np.max(np.abs(W @ x - b)) <= 1e-12 * np.max(abs(W) @ np.abs(x))
    assert np.max(np.abs(W.T @ y - b)) <= 1e-12 * np.max(abs(W.T) @ np.abs(y))
    got = np.concatenate([x, y, Y.ravel()])
    assert np.max(np.abs(got - expected)) <= 1e-10 * np.max(np.abs(expected))
    f.release()


def test_a_warm_lp_on_transposed_lus_ends_where_highs_ends(monkeypatch):
    lp = _lp("n512_a")
    col_h, dual_h = _highs(lp)
    _perturbing_every_other_lu(monkeypatch)
    ours = _ours(lp, max_etas=8)
    assert ours.stats.factorisations >= 2 and ours.stats.transposed_lus == ours.stats.factorisations
    assert ours.stats.superlu_fallbacks == 0
    _agree(lp, ours, col_h, dual_h)


def test_a_pardiso_lu_with_perturbed_pivots_is_redone_by_superlu():
    # PARDISO factorises a singular matrix by perturbing a pivot instead of failing;
    # that LU is not of W, so SuperLU redoes it (and here finds W singular)
    f = simplex.factor.Factor(2, lu="pardiso")
    with pytest.raises(simplex.factor.SingularWorkingSet):
        f.factorise(sp.csr_matrix(np.ones((2, 2))))
    assert f.superlu_fallbacks == 1 and not f.on_pardiso
    f.factorise(sp.csr_matrix(np.array([[2.0, 1.0], [1.0, 3.0]])))
    assert f.superlu_fallbacks == 1 and f.on_pardiso
    assert np.allclose(f.ftran(np.array([3.0, 4.0])), [1.0, 1.0], rtol=0, atol=1e-15)
    f.release()


def test_the_lu_library_is_checked_and_auto_takes_pardiso_when_installed():
    with pytest.raises(ValueError, match="LU library"):
        simplex.factor.lu_library("umfpack")
    assert simplex.factor.lu_library("auto") == "pardiso"  # the test extra installs mkl
    assert simplex.factor.lu_library("superlu") == "superlu"


def test_a_degenerate_crystal_lp_from_a_cold_basis():
    # every nearest-neighbour row of an FCC crystal at contact has a zero right-hand
    # side: each vertex is degenerate, and the crystal is jammed (Gamma* = 1)
    lp_ = jamming_lp(lattice_packing("fcc", 2))
    M, n = lp_.A.shape
    lp = dict(A=lp_.A, rhs=lp_.rhs, lower=lp_.col_lower, upper=lp_.col_upper,
              col_status=np.zeros(n, np.int64), row_status=np.ones(M, np.int64))  # all rows slack
    assert np.sum(np.abs(lp["rhs"]) < 1e-12) > n  # more tight rows than a vertex needs
    for perturbation in (simplex.warm.PERTURBATION, 0.0):
        ours = _ours(lp, perturbation=perturbation)
        assert ours.optimal
        col_h, _ = _highs(lp, warm=False)
        assert abs(ours.col_value[-1] - col_h[-1]) <= 1e-12 and abs(ours.col_value[-1]) <= 1e-12
        _kkt(lp, ours.col_value, ours.row_dual)


def _tiny(rows, rhs, lower, upper, col_status, row_status) -> dict:
    return dict(A=sp.csc_matrix(np.array(rows, float)), rhs=np.array(rhs, float), lower=np.array(lower, float),
                upper=np.array(upper, float), col_status=np.array(col_status), row_status=np.array(row_status))


@pytest.mark.parametrize(("lp", "status"), [
    # x <= -1 and x >= 1
    (_tiny([[1.0], [-1.0]], [-1.0, -1.0], [-np.inf], [np.inf], [1], [2, 1]), "infeasible"),
    # min -x with x >= 0 only
    (_tiny([[-1.0]], [0.0], [-np.inf], [np.inf], [1], [2]), "unbounded"),
    # the same row twice in the working set
    (_tiny([[1.0, 1.0], [1.0, 1.0]], [1.0, 1.0], [-np.inf] * 2, [np.inf] * 2, [1, 1], [2, 2]), "singular"),
    # a working set of the wrong size
    (_tiny([[1.0, 1.0]], [1.0], [-np.inf] * 2, [np.inf] * 2, [1, 1], [2]), "singular"),
])
@pytest.mark.parametrize("lu", ("pardiso", "superlu"))
def test_trouble_is_reported_not_answered(lp, status, lu):
    res = simplex.solve(lp["A"], lp["rhs"], lp["lower"], lp["upper"], _cost(lp["A"].shape[1]), lp["col_status"],
                        lp["row_status"], TOL, lu=lu)
    assert res.status == status and not res.optimal


def test_a_pivot_limit_is_trouble():
    assert _ours(_lp("n512_a"), max_pivots=3).status == "iteration limit"


def _same_packing(a, b) -> None:
    pa, pb = a.packing, b.packing
    key = lambda p: {tuple(c): f for c, f in zip(np.sort(p.contacts, axis=1).tolist(), p.force)}  # noqa: E731
    fa, fb = key(pa), key(pb)
    assert fa.keys() == fb.keys()
    f_max = max(fb.values())
    assert max(abs(fa[c] - fb[c]) for c in fb) <= 1e-9 * f_max
    assert abs(pa.attrs["phi_J"] - pb.attrs["phi_J"]) <= 1e-12


def test_a_chain_with_the_jamflow_engine_ends_in_the_packing_of_highs():
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    highs = calippso(start, warm_engine="highs")
    ours = calippso(start, warm_engine="jamflow")
    engines = ours.history["engine"].values[ours.history["warm_start"].values.astype(bool)]
    assert len(engines) > 0 and np.all(engines == "jamflow")
    assert ours.packing.attrs["warm_fallbacks"] == 0 and ours.converged
    assert ours.packing.attrs["warm_lu"] == "pardiso" and highs.packing.attrs["warm_lu"] == "none"
    _same_packing(ours, highs)


def test_trouble_in_the_chain_falls_back_to_highs_and_is_counted(monkeypatch):
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    highs = calippso(start, warm_engine="highs")
    solve = simplex.solve

    def troubled(*args, **kwargs):
        res = solve(*args, **kwargs)
        return simplex.Result("unstable pivot", res.col_value, res.row_dual, res.col_dual, res.col_status,
                              res.row_status, res.stats)

    monkeypatch.setattr(simplex, "solve", troubled)
    ours = calippso(start, warm_engine="jamflow")
    warm = ours.history["warm_start"].values.astype(bool)
    assert warm.any() and np.all(ours.history["warm_fallback"].values[warm] == "unstable pivot")
    assert ours.packing.attrs["warm_fallbacks"] == warm.sum()
    assert ours.packing.attrs["warm_lps_jamflow"] == 0
    _same_packing(ours, highs)


def test_the_engine_option_is_checked_and_auto_follows_the_lp_size():
    start = read_packing(DATA / "calippso_near_start_n256.nc")
    with pytest.raises(ValueError, match="warm engine"):
        calippso(start, warm_engine="gurobi")
    assert _engine_of_warm_lps("auto", WARM_ENGINE_MIN_COLUMNS) == "jamflow"
    assert _engine_of_warm_lps("auto", WARM_ENGINE_MIN_COLUMNS - 1) == "highs"
    assert _engine_of_warm_lps("highs", WARM_ENGINE_MIN_COLUMNS) == "highs"
