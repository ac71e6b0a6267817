"""The state of a warm simplex solve: the LP, the working set, the point, the
multipliers and the factorised working-set matrix (:mod:`jamflow.simplex.factor`).

Working set: ``n`` constraints that hold with equality at the current vertex.
Member ``k`` (a *slot*) is row ``idx[k]`` of ``A z <= b`` when ``kind[k] == 0`` and
column ``idx[k]`` held at a bound when ``kind[k] == 1``; ``side[k]`` says which side
(:data:`UPPER` for every row). Row ``k`` of ``W`` is the member's normal (``a_i`` or
``e_j``) and ``r[k]`` its right-hand side, so the vertex is ``z = W^-1 r``.

Multipliers ``y`` solve ``W^T y = -c``. At an optimum a row or an upper bound has
``y >= 0``, a lower bound ``y <= 0``, a free column held at a value ``y = 0``, a fixed
column any sign: :func:`~jamflow.simplex._kernels.dual_infeasibility`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from . import _kernels as k
from .factor import Factor

#: HiGHS basis status codes (``highspy.HighsBasisStatus``), the interface's basis format.
LOWER, BASIC, UPPER_STATUS, ZERO, NONBASIC = 0, 1, 2, 3, 4

#: Sides of a working-set member: a row or a column at its upper bound, a column at
#: its lower bound, a free column held at a value, a fixed column.
UPPER, LOWER_SIDE, FREE, FIXED = 1, -1, 0, 2


@dataclass(frozen=True)
class Tolerances:
    """Tolerances of :func:`jamflow.simplex.solve`, in the units of the LP as given.

    Attributes
    ----------
    primal : float
        A row ``a.z - b`` or a bound may be violated by this much (HiGHS's
        ``primal_feasibility_tolerance``).
    dual : float
        A multiplier may have the wrong sign by this much (HiGHS's
        ``dual_feasibility_tolerance``).
    pivot : float
        Smallest ``|a_i . d|`` (primal ratio test) or ``|beta_k|`` (dual ratio test)
        accepted as a pivot element.
    """

    primal: float = 1e-10
    dual: float = 1e-10
    pivot: float = 1e-9


@dataclass
class Stats:
    """What a solve did: the LU library (``pardiso`` or ``superlu``,
    :data:`~jamflow.simplex.factor.LU_LIBRARIES`), how many of its factorisations PARDISO
    redid on ``W^T`` and how many SuperLU redid (PARDISO's perturbed pivots), pivots by
    kind, bound flips, factorisations, rounds of primal simplex and dual repair, the fill ``nnz(L + U)`` of
    the last LU, and wall seconds by part."""

    lu: str = ""
    transposed_lus: int = 0
    superlu_fallbacks: int = 0
    primal_pivots: int = 0
    dual_pivots: int = 0
    flips: int = 0
    factorisations: int = 0
    rounds: int = 0
    fill: int = 0
    seconds: dict[str, float] = field(default_factory=lambda: dict.fromkeys(
        ("factor", "order", "ftran", "btran", "ratio", "total"), 0.0))

    @property
    def pivots(self) -> int:
        return self.primal_pivots + self.dual_pivots


class Trouble(Exception):
    """Ends a solve with a status other than optimal (the message is the status)."""


def _ranges(starts: NDArray[np.int64], lengths: NDArray[np.int64]) -> NDArray[np.int64]:
    """``concatenate([arange(a, a + m) for a, m in zip(starts, lengths)])`` without the loop."""
    total = int(lengths.sum())
    if total == 0:
        return np.empty(0, dtype=np.int64)
    offsets = np.cumsum(lengths) - lengths
    return np.repeat(starts - offsets, lengths) + np.arange(total)


class State:
    """The LP, its working set, point ``z``, slacks ``s = bw - A z`` and multipliers ``y``.

    ``bw``, ``lw``, ``uw`` are the working right-hand sides and bounds: the LP's, shifted
    and perturbed during the primal phase (:func:`jamflow.simplex.warm.solve`).
    """

    def __init__(self, A: sp.spmatrix, b, lower, upper, c, tol: Tolerances, max_etas: int | None,
                 ordering: str, lu: str = "auto") -> None:
        self.M, self.n = A.shape
        csr = sp.csr_matrix(A)
        csr.sort_indices()
        self.A = csr
        self.Ap, self.Aj, self.Ax = csr.indptr.astype(np.int64), csr.indices.astype(np.int64), csr.data
        self.b, self.lower, self.upper = (np.array(v, dtype=np.float64) for v in (b, lower, upper))
        self.c = np.array(c, dtype=np.float64)
        self.tol = tol
        self.bw, self.lw, self.uw = self.b.copy(), self.lower.copy(), self.upper.copy()
        self.factor = Factor(self.n, max_etas, ordering, lu)
        self.stats = Stats(lu=self.factor.lu)
        self.alpha = np.empty(self.M)

    # --- the working set -----------------------------------------------------------------

    def set_working_set(self, col_status: NDArray[np.int64], row_status: NDArray[np.int64],
                        held: NDArray[np.bool_] | None = None) -> None:
        """Members from HiGHS statuses: the nonbasic rows, and the nonbasic columns at the
        bound their status names when it is finite, else at their finite bound, else
        held at zero (HiGHS's value of a nonbasic free column). Nonbasic columns marked
        in ``held`` (shape (n,)) are held at zero whatever their bounds (a crash basis's
        columns that no chosen row fixes); :func:`jamflow.simplex.warm.solve` moves them
        to a vertex."""
        rows = np.flatnonzero(row_status != BASIC)
        cols = np.flatnonzero(col_status != BASIC)
        if len(rows) + len(cols) != self.n:
            raise Trouble("singular")
        self.kind = np.concatenate([np.zeros(len(rows), np.int8), np.ones(len(cols), np.int8)])
        self.idx = np.concatenate([rows, cols]).astype(np.int64)
        lo, up = self.lower[cols], self.upper[cols]
        side = np.where(np.isfinite(lo), LOWER_SIDE, np.where(np.isfinite(up), UPPER, FREE))
        side = np.where((col_status[cols] == UPPER_STATUS) & np.isfinite(up), UPPER, side)
        if held is not None:
            side = np.where(held[cols], FREE, side)
        side = np.where(lo == up, FIXED, side)
        self.side = np.concatenate([np.full(len(rows), UPPER), side]).astype(np.int8)
        self.row_slot = np.full(self.M, -1, dtype=np.int64)
        self.row_slot[rows] = np.arange(len(rows))
        self.col_slot = np.full(self.n, -1, dtype=np.int64)
        self.col_slot[cols] = len(rows) + np.arange(len(cols))
        self.r = np.zeros(self.n)
        self.reset_rhs()

    def reset_rhs(self) -> None:
        """``r`` from the working bounds (a free member keeps its value)."""
        rows = self.kind == 0
        self.r[rows] = self.bw[self.idx[rows]]
        cols = ~rows
        j, side = self.idx[cols], self.side[cols]
        self.r[cols] = np.where(side == UPPER, self.uw[j], np.where(side == FREE, self.r[cols], self.lw[j]))

    def working_matrix(self) -> sp.csr_matrix:
        """``W`` (n, n): row ``k`` is ``a_i`` for a row member, ``e_j`` for a column."""
        rows = self.kind == 0
        lengths = np.ones(self.n, dtype=np.int64)
        i = self.idx[rows]
        lengths[rows] = self.Ap[i + 1] - self.Ap[i]
        indptr = np.concatenate([[0], np.cumsum(lengths)])
        indices = np.empty(indptr[-1], dtype=np.int64)
        data = np.ones(indptr[-1])
        starts = indptr[:-1]
        cols = ~rows
        indices[starts[cols]] = self.idx[cols]
        src = _ranges(self.Ap[i], lengths[rows])
        dst = _ranges(starts[rows], lengths[rows])
        indices[dst] = self.Aj[src]
        data[dst] = self.Ax[src]
        return sp.csr_matrix((data, indices, indptr), shape=(self.n, self.n))

    def normal(self, kind: int, index: int) -> NDArray[np.float64]:
        """Dense normal of a constraint: row ``index`` of ``A`` (kind 0) or ``e_index``."""
        w = np.zeros(self.n)
        if kind == 0:
            a, b = self.Ap[index], self.Ap[index + 1]
            w[self.Aj[a:b]] = self.Ax[a:b]
        else:
            w[index] = 1.0
        return w

    def swap(self, p: int, kind: int, index: int, side: int, value: float, beta: NDArray[np.float64]) -> None:
        """Member ``p`` leaves; constraint ``(kind, index)`` takes its slot at ``side`` with
        right-hand side ``value``; ``beta = W^-T w_new`` updates the factorisation."""
        if self.kind[p] == 0:
            self.row_slot[self.idx[p]] = -1
        else:
            self.col_slot[self.idx[p]] = -1
        self.kind[p], self.idx[p], self.side[p], self.r[p] = kind, index, side, value
        if kind == 0:
            self.row_slot[index] = p
        else:
            self.col_slot[index] = p
        self.factor.replace(p, beta)

    # --- solves ----------------------------------------------------------------------------

    def ftran(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W^-1 b``."""
        t0 = time.perf_counter()
        x = self.factor.ftran(b)
        self.stats.seconds["ftran"] += time.perf_counter() - t0
        return x

    def btran(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W^-T c``."""
        t0 = time.perf_counter()
        y = self.factor.btran(c)
        self.stats.seconds["btran"] += time.perf_counter() - t0
        return y

    def btran_many(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W^-T C`` for the columns of ``C`` (n, k)."""
        t0 = time.perf_counter()
        Y = self.factor.btran_many(C)
        self.stats.seconds["btran"] += time.perf_counter() - t0
        return Y

    def matvec(self, x: NDArray[np.float64], out: NDArray[np.float64]) -> NDArray[np.float64]:
        """``out = A x``."""
        t0 = time.perf_counter()
        k.csr_matvec(self.Ap, self.Aj, self.Ax, x, out)
        self.stats.seconds["ratio"] += time.perf_counter() - t0
        return out

    def refactor(self) -> None:
        """A fresh LU of ``W``; the point, slacks and multipliers recomputed on it."""
        self.factor.factorise(self.working_matrix())
        self.stats.factorisations += 1
        self.stats.fill = self.factor.fill
        self.recompute()

    def recompute(self) -> None:
        """``z = W^-1 r``, ``s = bw - A z``, ``y = W^-T (-c)``."""
        self.z = self.ftran(self.r)
        self.s = self.bw - self.matvec(self.z, np.empty(self.M))
        self.y = self.btran(-self.c)

    def refine(self) -> None:
        """The point and multipliers of the working set, each with one step of iterative
        refinement against ``W`` itself, and the slacks on the working bounds."""
        self.reset_rhs()
        W = self.working_matrix()
        z = self.ftran(self.r)
        self.z = z + self.ftran(self.r - W @ z)
        y = self.btran(-self.c)
        self.y = y + self.btran(-self.c - W.T @ y)
        cols = self.kind == 1
        self.z[self.idx[cols]] = self.r[cols]  # a column at a bound is exactly there
        self.s = self.bw - self.matvec(self.z, np.empty(self.M))

    def feasible(self) -> bool:
        """Primal feasible to ``tol.primal`` and dual feasible to ``tol.dual``."""
        infeas = np.empty(self.n)
        k.dual_infeasibility(self.y, self.side, infeas)
        kind, _, _ = k.most_violated(self.s, self.row_slot, self.z, self.lw, self.uw, self.col_slot,
                                     self.tol.primal)
        return kind < 0 and float(infeas.max(initial=0.0)) <= self.tol.dual
