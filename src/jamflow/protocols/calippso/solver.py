"""The solver of the chain's LPs: interior point, cold or warm simplex by HiGHS, warm
simplex by :mod:`jamflow.simplex` (``warm_engine``), the basis carried from one LP's rows
to the next."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ...highs import new_highs
from .crash import _crash_basis
from .dual import dual_lp, primal_answer
from .lp import _highs_lp, _Rows
from .options import (
    DEFAULT_INTERIOR,
    DUAL_FALLBACK,
    HIPO_MIN_COLUMNS,
    INTERIOR_POINTS,
    SOLVER_TOL,
    WARM_ENGINES,
)

#: ``hybrid``: from interior point to the warm simplex below this ``sqrt(Gamma*) - 1``.
HYBRID_SWITCH: float = 1e-5

#: HiGHS presolve of the interior point LPs of a start near jamming: off, whose vertex
#: is the better warm start (measured: docs/notes/calippso-constants.md#near_start_presolve).
NEAR_START_PRESOLVE: str = "off"
#: HiGHS's own presolve setting, kept by every other LP.
_HIGHS_PRESOLVE: str = "choose"

#: HiGHS's scaling of a warm simplex LP (``simplex_scale_strategy``): 0, none; the rows
#: are built well scaled, so ``solver_tol`` acts on them as built
#: (measured: docs/notes/calippso-constants.md#warm_simplex_scale).
WARM_SIMPLEX_SCALE: int = 0
#: HiGHS's own scaling (equilibration), kept by every other LP.
_HIGHS_SCALE: int = 2

#: Pivots per row a warm simplex may take before the LP is re-solved by interior point
#: (a pivot limit, not a time limit: the same input gives the same chain)
#: (measured: docs/notes/calippso-constants.md#warm_pivots_per_row).
WARM_PIVOTS_PER_ROW: float = 1.0

_NO_PIVOT_LIMIT: int = 2**31 - 1  # HiGHS's default simplex_iteration_limit


@dataclass(frozen=True)
class _Solution:
    """Outcome of one LP: HiGHS status, wall time [s], columns and row duals (None
    unless optimal), whether the simplex started warm, the method that produced it
    and the iterations it took."""

    status: str
    seconds: float
    col: NDArray[np.float64] | None
    dual: NDArray[np.float64] | None
    warm: bool
    method: str
    simplex_iterations: int
    ipm_iterations: int
    engine: str = "highs"  # which engine produced the answer (see WARM_ENGINES)
    fallback: str = ""  # jamflow.simplex's trouble on this LP, which HiGHS then solved
    lu: str = ""  # jamflow.simplex's LU library; "+superlu" when a PARDISO LU was redone by SuperLU
    interior: str = ""  # the interior point that solved it: ipx, hipo (the LP), hipo-dual (its dual); "" for none


@dataclass
class _Basis:
    """A simplex basis, as HiGHS returned it (not alien: ``setBasis`` does not
    factorise it) or as HiGHS status codes; each form is made from the other when asked."""

    highs: highspy.HighsBasis | None = None
    col: NDArray[np.int8] | None = None
    row: NDArray[np.int8] | None = None

    def statuses(self) -> tuple[NDArray[np.int8], NDArray[np.int8]]:
        """Column and row statuses as HiGHS status codes."""
        if self.col is None:
            self.col = np.array([int(v) for v in self.highs.col_status], dtype=np.int8)
            self.row = np.array([int(v) for v in self.highs.row_status], dtype=np.int8)
        return self.col, self.row

    def for_highs(self) -> highspy.HighsBasis:
        """The basis as HiGHS takes it (``setBasis``)."""
        if self.highs is None:
            self.highs = highspy.HighsBasis()
            self.highs.col_status = [highspy.HighsBasisStatus(int(v)) for v in self.col]
            self.highs.row_status = [highspy.HighsBasisStatus(int(v)) for v in self.row]
            self.highs.valid = True
        return self.highs


class _Solver:
    """One HiGHS instance; keeps the last basis for warm starts on unchanged rows.

    A warm simplex is given :data:`WARM_PIVOTS_PER_ROW` pivots per row; when they run
    out the LP is solved by interior point instead, so a warm start that does not
    pay costs about one interior point solve more. With ``warm_engine="jamflow"``
    (resolved: ``auto`` is not taken here) the warm simplex LPs are solved by
    :mod:`jamflow.simplex` at the same tolerances and pivot limit; an LP on which it
    reports trouble is solved by HiGHS from the same basis, and the trouble recorded.
    """

    def __init__(self, threads: int = 1, tol: float = SOLVER_TOL, interior: str = DEFAULT_INTERIOR,
                 warm_engine: str = "highs") -> None:
        if warm_engine == "auto" or warm_engine not in WARM_ENGINES:
            raise ValueError(f"warm engine {warm_engine!r}: the solver takes highs or jamflow (auto resolved)")
        self.h = new_highs(threads)
        self.tol = tol
        self.warm_engine = warm_engine
        if interior not in INTERIOR_POINTS:
            raise ValueError(f"unknown interior point {interior!r}; choose one of {', '.join(INTERIOR_POINTS)}")
        hipo = self.h.setOptionValue("solver", "hipo") == highspy.HighsStatus.kOk
        if interior == "hipo" and not hipo:
            raise ValueError(f"interior point {interior!r} is not in this highspy build: HiPO needs "
                             "`pip install 'highspy[extras]'` (highspy-extras of highspy's version)")
        self.interior = interior
        #: HiPO is in this highspy build
        self.hipo = hipo
        for option in ("primal_feasibility_tolerance", "dual_feasibility_tolerance", "ipm_optimality_tolerance"):
            if self.h.setOptionValue(option, tol) != highspy.HighsStatus.kOk:
                raise ValueError(f"HiGHS refused {option} = {tol:g}")
        self.basis: _Basis | None = None
        self.basis_rows: _Rows | None = None
        #: hybrid: a simplex LP without a basis to carry is solved by interior point
        self.cold_simplex_as_ipm = False
        #: HiGHS presolve of the interior point LPs (see NEAR_START_PRESOLVE)
        self.ipm_presolve = _HIGHS_PRESOLVE
        #: the first interior point LP is tried from a crash basis (:mod:`.crash`) first
        self.crash_first = False

    def solve(self, A: sp.csc_matrix, rhs, col_lower, col_upper, method: str, rows: _Rows) -> _Solution:
        """Solve the LP ``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper``."""
        cold = method == "dual"
        method = "simplex" if cold else method
        carried = self._carried_basis(rows, A.shape[1]) if method == "simplex" and not cold else None
        warm = carried is not None
        fallback = ""
        if warm and self.warm_engine == "jamflow":
            sol = self._solve_jamflow(A, rhs, col_lower, col_upper, carried, rows)
            if sol.col is not None:
                return sol
            fallback = sol.status
        spent = 0.0  # wall time [s] of an attempt that failed before HiGHS's solve below
        crashed = False
        if method == "ipm" and self.crash_first and self.basis is None:
            self.crash_first = False
            crashed = True
            sol = self._solve_crash(A, rhs, col_lower, col_upper, rows)
            if sol.col is not None:
                return sol
            fallback = sol.status
            spent += sol.seconds
        if method == "simplex" and not warm and not cold and self.cold_simplex_as_ipm:
            method = "ipm"
        lp = _highs_lp(A, rhs, col_lower, col_upper)
        if method == "ipm":
            sol = self._interior_point(A, rhs, col_lower, col_upper, rows, lp)
            return replace(sol, seconds=sol.seconds + spent, method="crash>ipm" if crashed else "ipm",
                           fallback=fallback)
        status, elapsed = self._run(lp, method, carried.for_highs() if warm else None)
        elapsed += spent
        pivots, ipm_its = self._iterations()
        extra = dict(interior=self._primal_interior()) if method == "ipm-nox" else {}
        if warm and status == highspy.HighsModelStatus.kIterationLimit:
            sol = self._interior_point(A, rhs, col_lower, col_upper, rows, lp)
            return replace(sol, seconds=sol.seconds + elapsed, method="simplex>ipm",
                           simplex_iterations=sol.simplex_iterations + pivots, fallback=fallback)
        return self._highs_answer(status, elapsed, warm, method, pivots, ipm_its, rows, fallback=fallback, **extra)

    def _highs_answer(self, status, elapsed: float, warm: bool, method: str, pivots: int, ipm_its: int,
                      rows: _Rows, **extra) -> _Solution:
        """The answer of HiGHS's last run on the LP as it is; keeps its basis for the next LP."""
        h = self.h
        name = h.modelStatusToString(status)
        # without crossover HiGHS may stop with status "Unknown" at a primal-feasible
        # interior point; only its primal part is used (the overlap check follows)
        interior_ok = (method == "ipm-nox" and status == highspy.HighsModelStatus.kUnknown
                       and int(h.getInfo().primal_solution_status) == 2)
        if status != highspy.HighsModelStatus.kOptimal and not interior_ok:
            self.basis = None
            return _Solution(name, elapsed, None, None, warm, method, pivots, ipm_its, **extra)
        sol = h.getSolution()
        self.basis = _Basis(highs=h.getBasis()) if method != "ipm-nox" else None
        self.basis_rows = rows
        return _Solution(name, elapsed, np.asarray(sol.col_value), -np.asarray(sol.row_dual), warm, method,
                         pivots, ipm_its, **extra)

    def _interior_point(self, A: sp.csc_matrix, rhs, col_lower, col_upper, rows: _Rows,
                        lp: highspy.HighsLp) -> _Solution:
        """The LP by an interior point with crossover: HiPO on its explicit dual where
        :attr:`interior` takes it (:meth:`_on_dual`), else (and after any trouble there,
        recorded in ``interior``) IPX or HiPO on the LP as it is."""
        spent, run = 0.0, self._primal_interior()
        interior = run
        if self._on_dual(A.shape[1]):
            sol = self._solve_dual(A, rhs, col_lower, col_upper, rows)
            if sol.col is not None:
                return sol
            spent, run, interior = sol.seconds, "ipx", DUAL_FALLBACK + sol.status
        status, elapsed = self._run(lp, "ipm", None, run)
        pivots, ipm_its = self._iterations()
        return self._highs_answer(status, elapsed + spent, False, "ipm", pivots, ipm_its, rows, interior=interior)

    def _on_dual(self, columns: int) -> bool:
        """Whether an interior point LP with crossover of ``columns`` columns is solved as its dual by HiPO."""
        return self.interior == "hipo" or (self.interior == "auto" and self.hipo and columns >= HIPO_MIN_COLUMNS)

    def _primal_interior(self) -> str:
        """The interior point of the LP as it is: HiPO when asked for by name, else IPX."""
        return "hipo" if self.interior == "hipo" else "ipx"

    def _solve_dual(self, A: sp.csc_matrix, rhs, col_lower, col_upper, rows: _Rows) -> _Solution:
        """The LP as its explicit dual (:mod:`.dual`) by HiPO with crossover, read back as
        the LP's solution and vertex basis; on trouble the solution has no columns and
        its status names the trouble."""
        dual = dual_lp(A, rhs, col_lower, col_upper)
        status, elapsed = self._run(dual.lp, "ipm", None, "hipo")
        pivots, ipm_its = self._iterations()
        h = self.h
        if status != highspy.HighsModelStatus.kOptimal:
            return _Solution(h.modelStatusToString(status), elapsed, None, None, False, "ipm", pivots, ipm_its,
                             interior="hipo-dual")
        sol, basis = h.getSolution(), h.getBasis()
        answer = primal_answer(dual, np.asarray(sol.col_value), np.asarray(sol.row_dual),
                               np.array([int(v) for v in basis.col_status], dtype=np.int8))
        if answer is None:
            return _Solution("dual basis not a primal basis", elapsed, None, None, False, "ipm", pivots, ipm_its,
                             interior="hipo-dual")
        z, y, col_status, row_status = answer
        self.basis = _Basis(col=col_status, row=row_status)
        self.basis_rows = rows
        return _Solution("Optimal", elapsed, z, y, False, "ipm", pivots, ipm_its, interior="hipo-dual")

    def _solve_jamflow(self, A: sp.csc_matrix, rhs, col_lower, col_upper, carried: _Basis,
                       rows: _Rows, held: NDArray[np.bool_] | None = None) -> _Solution:
        """The warm LP by :mod:`jamflow.simplex` from the carried basis, at HiGHS's
        tolerances and pivot limit; on trouble the solution has no columns and its status
        names the trouble."""
        # imported here: it loads numba, which only chains that use the engine pay for
        from ... import simplex

        cost = np.zeros(A.shape[1])
        cost[-1] = -1.0
        col, row = carried.statuses()
        res = simplex.solve(A, rhs, col_lower, col_upper, cost, col, row,
                            simplex.Tolerances(primal=self.tol, dual=self.tol),
                            max_pivots=max(int(WARM_PIVOTS_PER_ROW * A.shape[0]), 1), held=held)
        seconds = res.stats.seconds["total"]
        lu = res.stats.lu + ("+superlu" if res.stats.superlu_fallbacks else "")
        if not res.optimal:
            return _Solution(status=res.status, seconds=seconds, col=None, dual=None, warm=True, method="simplex",
                             simplex_iterations=res.stats.pivots, ipm_iterations=0, engine="jamflow", lu=lu)
        self.basis = _Basis(col=res.col_status, row=res.row_status)
        self.basis_rows = rows
        return _Solution(status="Optimal", seconds=seconds, col=res.col_value, dual=-res.row_dual, warm=True,
                         method="simplex", simplex_iterations=res.stats.pivots, ipm_iterations=0, engine="jamflow",
                         lu=lu)

    def _solve_crash(self, A: sp.csc_matrix, rhs, col_lower, col_upper, rows: _Rows) -> _Solution:
        """The first LP by :mod:`jamflow.simplex` from the crash basis of the start's
        geometry (:mod:`.crash`); on trouble (no crash basis, or the simplex's) the
        solution has no columns and its status names the trouble."""
        t0 = time.perf_counter()
        crash = _crash_basis(self.h, A, rhs, col_lower, col_upper)
        if crash is None:
            return _Solution(status="no crash basis", seconds=time.perf_counter() - t0, col=None, dual=None,
                             warm=False, method="crash", simplex_iterations=0, ipm_iterations=0, engine="jamflow")
        col, row = crash
        sol = self._solve_jamflow(A, rhs, col_lower, col_upper, _Basis(col=col, row=row), rows,
                                  held=col == int(highspy.HighsBasisStatus.kZero))
        return replace(sol, seconds=time.perf_counter() - t0, warm=False, method="crash")

    def _iterations(self) -> tuple[int, int]:
        """Simplex pivots (crossover included) and interior point iterations of the last run."""
        info = self.h.getInfo()
        return (max(int(info.simplex_iteration_count), 0) + max(int(info.crossover_iteration_count), 0),
                max(int(info.ipm_iteration_count), 0))

    def _carried_basis(self, rows: _Rows, n_cols: int) -> _Basis | None:
        """The last basis carried over to ``rows``: rows kept by pair keep their status,
        new rows enter with a basic slack (inactive); None when there is no basis or
        the carried one does not have one basic variable per row."""
        if self.basis is None or self.basis_rows is None:
            return None
        if rows is self.basis_rows:
            return self.basis
        col, old_status = self.basis.statuses()
        if len(col) != n_cols:
            return None
        n = len(rows.x_build)
        old_keys = self.basis_rows.keys(n)
        order = np.argsort(old_keys)
        new_keys = rows.keys(n)
        pos = np.clip(np.searchsorted(old_keys, new_keys, sorter=order), 0, max(len(old_keys) - 1, 0))
        found = old_keys[order[pos]] == new_keys if len(old_keys) else np.zeros(len(new_keys), bool)
        basic = int(highspy.HighsBasisStatus.kBasic)
        status = np.where(found, old_status[order[pos]], basic).astype(np.int8)
        if int(np.sum(status == basic)) + int(np.sum(col == basic)) != len(rows):
            return None
        return _Basis(col=col, row=status)

    def _run(self, lp: highspy.HighsLp, method: str, basis, interior: str | None = None):
        """Run HiGHS on ``lp`` by ``method`` (``interior``: the interior point's name, by
        default that of the LP as it is); model status and wall time [s]."""
        h = self.h
        h.clearSolver()
        if method in ("ipm", "ipm-nox"):
            h.setOptionValue("solver", interior or self._primal_interior())
            h.setOptionValue("run_crossover", "on" if method == "ipm" else "off")
            h.setOptionValue("presolve", self.ipm_presolve)
        else:
            # from a carried basis the primal simplex needs a few pivots where the
            # dual simplex needed thousands (d = 4 LS example: 2 against 5184)
            h.setOptionValue("solver", "simplex")
            h.setOptionValue("simplex_strategy", 4 if basis is not None else 1)
            h.setOptionValue("presolve", _HIGHS_PRESOLVE)
        h.setOptionValue("simplex_scale_strategy", WARM_SIMPLEX_SCALE if basis is not None else _HIGHS_SCALE)
        h.passModel(lp)
        limit = _NO_PIVOT_LIMIT
        if basis is not None:
            h.setBasis(basis)
            limit = max(int(WARM_PIVOTS_PER_ROW * lp.num_row_), 1)
        h.setOptionValue("simplex_iteration_limit", limit)
        t0 = time.perf_counter()
        h.run()
        return h.getModelStatus(), time.perf_counter() - t0

