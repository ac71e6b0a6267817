"""A bounded simplex for LPs with many more rows than columns, warm-started from a
HiGHS basis.

The LP is ``min c.z`` subject to ``A z <= b`` (M rows) and ``lower <= z <= upper``
(n columns, M >> n: CALiPPSO's jamming LPs have about 3.6 rows per column). A vertex
is given by a *working set* of n constraints that hold with equality, each a row of
``A`` or a column at a bound (a free column may be held at a value); their normals
are the rows of the square matrix ``W`` of :mod:`jamflow.simplex.factor`, whose order
is n, not M. This is HiGHS's basis read the other way round: HiGHS's nonbasic rows
and columns are the working set, and its basis matrix of order M reduces to ``W``
after its slack columns are eliminated.

The multipliers ``y`` solve ``W^T y = -c``; at an optimum a row or an upper bound
has ``y >= 0``, a lower bound ``y <= 0`` and a free column ``y = 0`` (they are the
row duals and reduced costs, with HiGHS's signs flipped).

Method (``docs/notes/warm-simplex.md`` has the measurements behind each choice):

1. The carried basis is factorised (:class:`~jamflow.simplex.factor.Factor`). Rows
   and bounds it violates are shifted to the current point, and every constraint
   outside the working set is moved outwards by a small random amount
   (:data:`PERTURBATION`) against the stalling of degenerate vertices.
2. Primal simplex on the shifted LP: the member of the working set with the largest
   weighted dual infeasibility (:mod:`jamflow.simplex.pricing`) leaves, along
   ``d = W^-1 (sign(y_p) e_p)``; Harris's ratio test over every row and column picks
   the blocking constraint that enters. A boxed column whose opposite bound blocks
   first flips without a basis change.
3. The shifts are removed and the point recomputed; constraints it then violates by
   more than the primal tolerance are repaired by the dual simplex, whose multipliers
   do not depend on the right-hand sides. Steps 2 and 3 repeat until the point is
   primal and dual feasible to the tolerances, or the attempt is reported as trouble
   for the caller to solve the LP otherwise.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from . import _kernels as k
from .factor import SingularWorkingSet
from .pricing import Weights
from .state import (
    BASIC,
    FREE,
    LOWER,
    LOWER_SIDE,
    UPPER,
    UPPER_STATUS,
    ZERO,
    State,
    Stats,
    Tolerances,
    Trouble,
)

#: Outward perturbation of the constraints outside the working set at the start, in
#: the units of the rows: each gets ``PERTURBATION * (1 + u)``, ``u`` uniform in
#: [0, 1). Breaks the ties of degenerate vertices (zero steps); removed before the
#: answer (step 3).
PERTURBATION: float = 1e-9

#: Largest number of rounds of primal simplex and dual repair (step 3).
MAX_ROUNDS: int = 4

#: A pivot whose two computations of the pivot element, ``a_q . d`` from the column
#: and ``beta_p`` from the row, differ by more than this relative amount is redone on
#: a fresh factorisation (the eta file has lost accuracy); on a fresh one it is trouble.
PIVOT_AGREEMENT: float = 1e-8


@dataclass(frozen=True)
class Result:
    """The answer of :func:`solve`.

    Attributes
    ----------
    status : str
        ``optimal``, or the trouble: ``singular`` (the starting basis), ``unbounded``,
        ``infeasible``, ``iteration limit``, ``unstable pivot``, ``not converged``
        (:data:`MAX_ROUNDS` spent).
    col_value : ndarray, shape (n,)
    row_dual : ndarray, shape (M,)
        HiGHS's signs: ``<= 0`` on a tight row of a minimisation.
    col_dual : ndarray, shape (n,)
        Reduced costs of the columns at a bound, HiGHS's signs; 0 elsewhere.
    col_status, row_status : ndarray of int8, shapes (n,) and (M,)
        The final basis as HiGHS status codes.
    stats : Stats
    """

    status: str
    col_value: NDArray[np.float64]
    row_dual: NDArray[np.float64]
    col_dual: NDArray[np.float64]
    col_status: NDArray[np.int8]
    row_status: NDArray[np.int8]
    stats: Stats

    @property
    def optimal(self) -> bool:
        return self.status == "optimal"


# --- step 1: shifts and perturbation ----------------------------------------------------------


def _shift_and_perturb(st: State, rng: np.random.Generator, perturbation: float) -> None:
    """Make the point feasible for the working bounds: a violated row or bound outside
    the working set is moved to the point; then every row and bound outside it is moved
    outwards by ``perturbation (1 + u)``, ``u`` uniform in [0, 1)."""
    before = st.bw.copy()
    free_rows = st.row_slot < 0
    violated = free_rows & (st.s < 0.0)
    st.bw[violated] -= st.s[violated]
    free_cols = st.col_slot < 0
    low = free_cols & (st.z < st.lw)
    st.lw[low] = st.z[low]
    up = free_cols & (st.z > st.uw)
    st.uw[up] = st.z[up]
    if perturbation > 0.0:
        st.bw[free_rows] += perturbation * (1.0 + rng.random(int(free_rows.sum())))
        finite = free_cols & np.isfinite(st.lw)
        st.lw[finite] -= perturbation * (1.0 + rng.random(int(finite.sum())))
        finite = free_cols & np.isfinite(st.uw)
        st.uw[finite] += perturbation * (1.0 + rng.random(int(finite.sum())))
    st.s += st.bw - before


# --- step 2: the primal simplex --------------------------------------------------------------


def _agree(st: State, computed: float, expected: float) -> bool:
    """Whether the pivot element from the row eta agrees with the one from the column;
    if not, a fresh factorisation (trouble when it was fresh already)."""
    if abs(computed - expected) <= PIVOT_AGREEMENT * max(1.0, abs(expected)):
        return True
    if st.factor.count == 0:
        raise Trouble("unstable pivot")
    st.refactor()
    return False


def _enter(st: State, kind: int, q: int) -> tuple[float, int]:
    """The blocking constraint ``q`` (kind 0 row, 1 lower bound, 2 upper bound) becomes
    exactly tight at the new point; Harris's test may have let it overshoot within the
    tolerance, and then its working bound is shifted to the point. Returns its
    right-hand side and side."""
    if kind == 0:
        if st.s[q] < 0.0:
            st.bw[q] -= st.s[q]
        st.s[q] = 0.0
        return st.bw[q], UPPER
    side = LOWER_SIDE if kind == 1 else UPPER
    bound = st.lw if kind == 1 else st.uw
    if (st.z[q] - bound[q]) * side > 0.0:
        bound[q] = st.z[q]
    st.z[q] = bound[q]
    return bound[q], side


def _flip(st: State, p: int, t: float, d: NDArray[np.float64]) -> bool:
    """A boxed column leaving its bound whose other bound comes first (at most ``t``)
    moves there without a basis change."""
    if st.kind[p] != 1 or st.side[p] not in (LOWER_SIDE, UPPER):
        return False
    j = st.idx[p]
    span = st.uw[j] - st.lw[j]
    if not span <= t:
        return False
    st.z += span * d
    st.s -= span * st.alpha
    st.side[p] = -st.side[p]
    st.r[p] = st.uw[j] if st.side[p] == UPPER else st.lw[j]
    st.stats.flips += 1
    return True


def _pivot(st: State, weights: Weights, p: int, sigma: float, kind: int, q: int, t: float,
           d: NDArray[np.float64]) -> None:
    """Member ``p`` leaves along ``d`` (direction ``sigma``) by step ``t``; the blocking
    constraint ``q`` (kind 0 row, 1 lower bound, 2 upper bound) enters in its slot. A
    pivot element the row eta does not confirm refactorises instead (:func:`_agree`)."""
    pivot = st.alpha[q] if kind == 0 else d[q]
    beta = st.btran(st.normal(0 if kind == 0 else 1, q))
    if not _agree(st, beta[p], sigma * pivot):
        return
    st.z += t * d
    st.s -= t * st.alpha
    value, side = _enter(st, kind, q)
    ratio = st.y[p] / beta[p]
    st.y -= ratio * beta
    st.y[p] = ratio
    if weights.weight is not None:
        weights.update(p, beta)
    st.swap(p, 0 if kind == 0 else 1, q, side, value, beta)
    st.stats.primal_pivots += 1
    if st.factor.full:
        st.refactor()


def _primal(st: State, weights: Weights, rng: np.random.Generator, limit: int) -> None:
    """Primal simplex pivots until no member is dual infeasible beyond ``tol.dual``."""
    tol, n = st.tol, st.n
    infeas = np.empty(n)
    e = np.zeros(n)
    while True:
        k.dual_infeasibility(st.y, st.side, infeas)
        if float(infeas.max(initial=0.0)) <= tol.dual:
            return
        if st.stats.pivots + st.stats.flips >= limit:
            raise Trouble("iteration limit")
        if weights.weight is None:  # only an LP that pivots pays for its weights
            weights.start(n, st.A, st.btran_many, rng)
        p = k.devex_price(infeas, weights.weight, tol.dual)
        sigma = 1.0 if st.y[p] > 0.0 else -1.0
        d, kind, q, t = _move_out(st, e, p, sigma, tol)
        if _flip(st, p, t, d):
            continue
        if kind < 0:
            raise Trouble("unbounded")
        _pivot(st, weights, p, sigma, kind, q, t, d)


def _move_out(st: State, e: NDArray[np.float64], p: int, sigma: float,
              tol: Tolerances) -> tuple[NDArray[np.float64], int, int, float]:
    """The edge along which working-set member ``p`` leaves its constraint (direction ``sigma``):
    the step ``d`` in ``z`` (``st.alpha`` set to ``A d``) and the bounded ratio test's blocking
    kind, member and step length. ``e`` is a zero work vector of length ``n`` (left zero)."""
    e[p] = sigma
    d = st.ftran(e)
    e[p] = 0.0
    st.matvec(d, st.alpha)
    t0 = time.perf_counter()
    kind, q, t = k.primal_ratio(st.alpha, st.s, st.row_slot, d, st.z, st.lw, st.uw, st.col_slot,
                                tol.primal, tol.pivot)
    st.stats.seconds["ratio"] += time.perf_counter() - t0
    return d, kind, q, t


def _push(st: State, weights: Weights, limit: int) -> None:
    """Columns held at a value (side ``FREE``) that have a finite bound move to a vertex:
    each moves towards its nearer finite bound, the other members staying tight, until
    its bound (the member then stays, at the bound) or a blocking constraint (which
    enters in its place). At the primal simplex's end their multipliers are within
    ``tol.dual`` of zero, so the objective does not change beyond that."""
    lower, upper = st.lower, st.upper
    e = np.zeros(st.n)
    while True:
        slots = np.flatnonzero((st.kind == 1) & (st.side == FREE))
        j_held = st.idx[slots]
        slots = slots[np.isfinite(lower[j_held]) | np.isfinite(upper[j_held])]
        if not len(slots):
            return
        if st.stats.pivots + st.stats.flips >= limit:
            raise Trouble("iteration limit")
        p = int(slots[0])
        j = int(st.idx[p])
        up_gap, low_gap = upper[j] - st.z[j], st.z[j] - lower[j]
        sigma = 1.0 if up_gap <= low_gap else -1.0
        own = up_gap if sigma > 0 else low_gap
        d, kind, q, t = _move_out(st, e, p, sigma, st.tol)
        if kind < 0 or own <= t:
            t = max(own, 0.0)
            st.z += t * d
            st.s -= t * st.alpha
            st.side[p] = UPPER if sigma > 0 else LOWER_SIDE
            st.r[p] = upper[j] if sigma > 0 else lower[j]
            st.z[j] = st.r[p]
            st.stats.flips += 1
            continue
        _pivot(st, weights, p, sigma, kind, q, t, d)


# --- step 3: shifts removed, the dual simplex repairs --------------------------------------


def _restore(st: State) -> None:
    """The LP's right-hand sides and bounds back; the point recomputed on them."""
    st.bw[:] = st.b
    st.lw[:] = st.lower
    st.uw[:] = st.upper
    st.reset_rhs()
    st.recompute()


def _dual(st: State, limit: int) -> None:
    """Dual simplex pivots until no constraint outside the working set is violated by
    more than ``tol.primal``: the most violated enters, Harris's ratio test on the
    multipliers picks the member that leaves."""
    tol, n = st.tol, st.n
    e = np.zeros(n)
    while True:
        t0 = time.perf_counter()
        kind, q, _ = k.most_violated(st.s, st.row_slot, st.z, st.lw, st.uw, st.col_slot, tol.primal)
        st.stats.seconds["ratio"] += time.perf_counter() - t0
        if kind < 0:
            return
        if st.stats.pivots + st.stats.flips >= limit:
            raise Trouble("iteration limit")
        rho = -1.0 if kind == 1 else 1.0  # a lower bound is -z_j <= -l_j
        beta = st.btran(st.normal(0 if kind == 0 else 1, q))
        p, lam = k.dual_ratio(st.y, beta, rho, st.side, tol.dual, tol.pivot)
        if p < 0:
            raise Trouble("infeasible")
        e[p] = 1.0
        d = st.ftran(e)
        e[p] = 0.0
        st.matvec(d, st.alpha)
        if not _agree(st, beta[p], st.alpha[q] if kind == 0 else d[q]):
            continue
        if kind == 0:
            target, current = st.bw[q], st.bw[q] - st.s[q]
        else:
            target, current = (st.lw[q] if kind == 1 else st.uw[q]), st.z[q]
        theta = (target - current) / beta[p]
        st.z += theta * d
        st.s -= theta * st.alpha
        if kind == 0:
            st.s[q] = 0.0
        else:
            st.z[q] = target
        st.y -= (lam * rho) * beta
        st.y[p] = rho * lam
        st.swap(p, 0 if kind == 0 else 1, q, LOWER_SIDE if kind == 1 else UPPER, target, beta)
        st.stats.dual_pivots += 1
        if st.factor.full:
            st.refactor()


# --- the solve ---------------------------------------------------------------------------------


def _result(st: State, status: str) -> Result:
    """The answer in HiGHS's conventions (statuses, dual signs)."""
    n, M = st.n, st.M
    row_dual, col_dual = np.zeros(M), np.zeros(n)
    row_status = np.full(M, BASIC, dtype=np.int8)
    col_status = np.full(n, BASIC, dtype=np.int8)
    z = getattr(st, "z", np.zeros(n))
    if hasattr(st, "y"):
        rows = st.kind == 0
        row_dual[st.idx[rows]] = -st.y[rows]
        row_status[st.idx[rows]] = UPPER_STATUS
        cols = ~rows
        col_dual[st.idx[cols]] = -st.y[cols]
        side = st.side[cols]
        col_status[st.idx[cols]] = np.where(side == UPPER, UPPER_STATUS, np.where(side == FREE, ZERO, LOWER))
    return Result(status, z, row_dual, col_dual, col_status, row_status, st.stats)


def solve(A: sp.spmatrix, rhs: NDArray[np.float64], col_lower: NDArray[np.float64],
          col_upper: NDArray[np.float64], cost: NDArray[np.float64], col_status: NDArray[np.integer],
          row_status: NDArray[np.integer], tol: Tolerances | None = None, max_pivots: int | None = None,
          ordering: str = "metis", pricing: str = "sketch", perturbation: float = PERTURBATION,
          max_etas: int | None = None, seed: int = 0, lu: str = "auto",
          held: NDArray[np.bool_] | None = None) -> Result:
    """Solve ``min cost.z`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper`` from a basis.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (M, n)
        Constraint matrix; every row has only an upper side.
    rhs : ndarray, shape (M,)
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds, ``-inf`` / ``inf`` where absent.
    cost : ndarray, shape (n,)
    col_status, row_status : ndarray of int, shapes (n,) and (M,)
        The starting basis as HiGHS status codes (1 basic; 0 lower, 2 upper, 3 zero,
        4 nonbasic), M basic entries in all.
    tol : Tolerances, optional
        Default :class:`Tolerances` ().
    max_pivots : int, optional
        Pivots (and bound flips) before giving up with ``iteration limit``.
    ordering : str
        Column ordering of the LU (:data:`jamflow.simplex.factor.ORDERINGS`).
    pricing : str
        :data:`jamflow.simplex.pricing.PRICINGS`.
    perturbation : float
        See :data:`PERTURBATION`; 0 switches it off.
    max_etas : int, optional
        Product-form updates between factorisations; by default the rule of
        :data:`jamflow.simplex.factor.FACTOR_SOLVES`.
    seed : int
        Seed of the perturbation and the sketch: the same input gives the same answer.
    lu : str
        Library of the LU (:data:`jamflow.simplex.factor.LU_LIBRARIES`).
    held : ndarray of bool, shape (n,), optional
        Nonbasic columns held at zero between their bounds at the start (a crash basis);
        the answer has them at a vertex.

    Returns
    -------
    Result
        ``status`` is ``optimal`` or names the trouble; after trouble the caller should
        solve the LP otherwise.
    """
    t0 = time.perf_counter()
    st = State(A, rhs, col_lower, col_upper, cost, tol or Tolerances(), max_etas, ordering, lu)
    weights = Weights(pricing)
    rng = np.random.default_rng(seed)
    limit = max_pivots if max_pivots is not None else 2**62
    status = "optimal"
    try:
        st.set_working_set(np.asarray(col_status, np.int64), np.asarray(row_status, np.int64), held)
        st.refactor()
        _shift_and_perturb(st, rng, perturbation)
        for _ in range(MAX_ROUNDS):
            st.stats.rounds += 1
            _primal(st, weights, rng, limit)
            _push(st, weights, limit)
            _restore(st)
            _dual(st, limit)
            st.refine()
            if st.feasible():
                break
        else:
            status = "not converged"
    except SingularWorkingSet:
        status = "singular"
    except Trouble as trouble:
        status = str(trouble)
    finally:
        st.factor.release()
    st.stats.superlu_fallbacks = st.factor.superlu_fallbacks
    st.stats.transposed_lus = st.factor.transposed_lus
    st.stats.seconds["factor"] = st.factor.seconds_factor
    st.stats.seconds["order"] = st.factor.seconds_order
    st.stats.seconds["total"] = time.perf_counter() - t0
    return _result(st, status)
