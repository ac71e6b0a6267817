"""Solving ``N x = b`` on a contact network, ``N = S S^T`` (Lerner, Düring & Wyart, Eq. 11).

The operator S (Eq. 2) and its products, the singularity check on the sparse LDL^T
factor of N (:mod:`.ldl`), and what makes the repeated solves of an event-driven run
cheap: the factor of the last factorised network kept as a conjugate-gradient
preconditioner between events (:class:`FactorCache`; the paper solves Eq. 11 by CG),
its fill-reducing ordering carried to the next factorisation, and bordered preconditioners for
networks a few pairs away from the factorised one (:class:`Border`,
:class:`BorderSolves`). :func:`solve_contact_system` chooses between CG and a fresh
factorisation; :func:`jamflow.protocols.overdamped.network.solve_network` builds the right-hand
sides of the physics on it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..._numba import njit, read_only
from ...network import pair_rows
from ...network._graph_kernels import incidence
from .ldl import (
    CARRY_FILL,
    CarriedOrder,
    SingularNetworkError,
    TriangularFactor,
    _pair_coupling,
    _triangular_solve,
    locate,
)

__all__ = ["COND_LIMIT", "Border", "BorderSolves", "FactorCache", "s_matrix", "solve_contact_system"]

#: Default ratio of the largest to the smallest pivot of N = S S^T above which the
#: network is treated as singular (a self-stress: potentially jammed).
COND_LIMIT: float = 1e13

#: Largest sum of the magnitudes of the extrapolation weights of a warm start (its
#: Lebesgue constant: how much it amplifies the remembered solutions). Equally spaced
#: solves extrapolated one spacing ahead give 3, 7 and 15 at degree 1, 2 and 3;
#: clustered times (a collision right after a step, a midpoint probe) give up to
#: 1e34, a start far larger than the solution. Above the limit the degree is lowered.
WARM_WEIGHT_LIMIT: float = 50.0

#: Machine epsilon of float64 (the round-off unit of the CG residual updates).
EPS: float = float(np.finfo(np.float64).eps)


def s_matrix(pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int) -> sp.csr_matrix:
    """The operator ``S = d r_ij / d R_k`` (Eq. 2), sparse, shape (Nc, N d): the contact Jacobian's
    centre block (:func:`jamflow.network.pair_rows`).

    Parameters
    ----------
    pairs : ndarray of int64, shape (Nc, 2)
    unit : ndarray, shape (Nc, d)
        Unit vectors ``n_ij`` from i to j.
    n : int
        Number of particles.
    """
    return pair_rows(pairs, unit, n)


@njit(cache=True)
def _s_apply(pairs, unit, v):  # pragma: no cover - numba
    """``S v`` for a flat velocity ``v`` (length N d), shape (Nc,)."""
    nc, d = unit.shape
    out = np.empty(nc)
    for c in range(nc):
        i = np.uint64(pairs[c, 0] * d)  # unsigned: no wraparound test per access (see ldl._triangular_solve)
        j = np.uint64(pairs[c, 1] * d)
        s = 0.0
        for a in range(d):
            s += unit[c, a] * (v[j + np.uint64(a)] - v[i + np.uint64(a)])
        out[c] = s
    return out


@njit(cache=True)
def _st_apply(pairs, unit, f, n):  # pragma: no cover - numba
    """``S^T f`` for contact forces ``f`` (Nc,), flat shape (N d,)."""
    nc, d = unit.shape
    out = np.zeros(n * d)
    for c in range(nc):
        i = np.uint64(pairs[c, 0] * d)  # unsigned: no wraparound test per access
        j = np.uint64(pairs[c, 1] * d)
        for a in range(d):
            out[i + np.uint64(a)] -= unit[c, a] * f[c]
            out[j + np.uint64(a)] += unit[c, a] * f[c]
    return out


@dataclass
class FactorCache:
    """A factorisation of ``N = S S^T`` kept for later solves on the same contact network.

    Between events the network is fixed and its geometry drifts slowly, so the factor of
    N at an earlier geometry is an excellent preconditioner: conjugate gradients on
    the current N (the paper solves Eq. 11 by CG), warm-started from the last
    solution, converge in a few iterations. A cache only ever changes *how* a
    solution is computed, not which network is solved; callers reset it at points
    from which a run can be resumed, so a resumed run repeats the same solves.

    Attributes
    ----------
    rtol : float
        CG stops when the preconditioned residual ``|M^-1 r|_inf`` (≈ the error of
        the solution when M ≈ N) is below ``rtol |f|_inf``. The default 1e-11 keeps the
        forces within 1e-10 relative of a direct solve, with a factor 10 to spare; the
        contacts then drift by about ``1e-11`` of the step's displacement per step, far
        below ``step_drift``.
    max_iter : int
        Iterations after which CG gives up and N is refactorised directly.
    max_changes : int
        A network that differs from the factorised one by at most this many added plus
        removed pairs (the candidates of the rewiring after a collision) is solved by CG
        with a bordered preconditioner built from the cached factor (:func:`_bordered`);
        beyond, it is factorised. Under a carried ordering a factorisation costs about a
        third of one with a fresh AMD ordering, and 4 gave the shortest runs at N = 1024
        (8 before the ordering was carried).
    key : bytes or None
        Identity of the factorised network (its pairs).
    codes : ndarray of int64 or None
        Pair codes ``i N + j`` of the factorised network, in its order.
    lu : TriangularFactor or None
    order : CarriedOrder or None
        The fill-reducing ordering carried from one factorisation to the next
        (:class:`~jamflow.protocols.overdamped.ldl.CarriedOrder`).
    solves : BorderSolves or None
        The solves with ``lu`` that the bordered preconditioners share.
    recent : list of (codes, time, solutions)
        The last solves, newest first (at most ``warm_order + 1``): pair codes, time of
        the state (None when the caller gave none) and solutions per right-hand side.
    warm_order : int
        Degree of the extrapolation in time of warm starts: on an unchanged network the
        initial guess is the polynomial through the last ``warm_order + 1`` solutions
        (the forces vary smoothly between events; at N = 1024 quadratic saves about a
        third of the CG iterations of linear, cubic another tenth: 1.46 -> 1.30
        iterations per solve at ``rtol`` 1e-11).
    bordered : dict
        Bordered preconditioners (:class:`Border`, None where refused) built on the
        current factorisation, by network (pair codes as bytes): the network after an
        event is solved at every step until the next factorisation, and its set-up is
        done once. A preconditioner built at an earlier geometry of the same network is
        still an approximate inverse; CG converges to the same tolerance on the current one.
    iterations : int
        CG iterations of the last cached solve (diagnostic).
    n_factor, n_cg, n_bordered : int
        Counts of direct factorisations, of CG solves, and of those CG solves on a
        changed network (diagnostic).
    """

    rtol: float = 1e-11
    max_iter: int = 8
    max_changes: int = 4
    key: bytes | None = None
    codes: NDArray[np.int64] | None = None
    lu: Any = None
    order: CarriedOrder | None = None
    solves: Any = None
    recent: list = field(default_factory=list)
    warm_order: int = 3
    bordered: dict = field(default_factory=dict)
    iterations: int = 0
    n_factor: int = 0
    n_cg: int = 0
    n_bordered: int = 0
    _named: tuple | None = field(default=None, init=False, repr=False)

    def network(self, pairs: NDArray[np.int64], n: int) -> tuple[bytes, NDArray[np.int64]]:
        """Key and pair codes ``i n + j`` of the network ``pairs``.

        Memoised on a read-only ``pairs`` array: a caller that solves one network at
        every step passes the same read-only array, whose identity then names its
        content (the memo holds the array, so the identity cannot be reused). The same
        codes object then also lets the warm starts recognise the network by identity.
        """
        named = self._named
        if named is not None and named[0] is pairs and named[1] == n:
            return named[2], named[3]
        key, codes = _network_key(pairs, n), pairs[:, 0] * n + pairs[:, 1]
        if not pairs.flags.writeable:
            self._named = (pairs, n, key, codes)
        return key, codes

    def reset(self) -> None:
        """Forget the factorisation (the next solve factorises from scratch)."""
        self.key, self.codes, self.lu, self.solves, self.recent, self.bordered = None, None, None, None, [], {}
        self.order = None

    def remember(self, codes: NDArray[np.int64], solutions: list[NDArray[np.float64]], time: float | None) -> None:
        """Keep the solutions of a solve for the next warm starts (a second solve of the
        same network at the same time replaces the first)."""
        if self.recent and (self.recent[0][0] is codes or np.array_equal(self.recent[0][0], codes)):
            codes = self.recent[0][0]  # one array per network: later comparisons by identity
            if time is not None and self.recent[0][1] == time:
                self.recent[0] = (codes, time, solutions)
                return
        self.recent = [(codes, time, solutions)] + self.recent[:self.warm_order]

    def warm_starts(self, codes: NDArray[np.int64], count: int, time: float | None = None) -> list[NDArray[np.float64]]:
        """Initial guesses for a solve on the pairs ``codes`` at ``time``.

        On the network of the last solve: the polynomial extrapolation in time through
        the last solves on it at known distinct times (Lagrange form, up to degree
        ``warm_order``, lowered until its weights sum in magnitude to at most
        ``WARM_WEIGHT_LIMIT``), or the last solutions themselves. On another network: the last
        solutions carried over to the pairs ``codes`` (zero on new pairs).
        """
        m = len(codes)
        if not self.recent or len(self.recent[0][2]) < count:
            return [np.zeros(m) for _ in range(count)]
        last_codes, _, last = self.recent[0]
        if last_codes is not codes and not np.array_equal(last_codes, codes):
            pos = locate(last_codes, codes)
            out = []
            for g in last[:count]:
                x0 = np.zeros(m)
                x0[pos >= 0] = g[pos[pos >= 0]]
                out.append(x0)
            return out
        times: list[float] = []
        for c, t, sols in self.recent:
            if (time is None or t is None or t == time or t in times or len(sols) < count
                    or (c is not last_codes and not np.array_equal(c, codes))):
                break
            times.append(t)
        weights = _lagrange_weights(times, time)
        if len(weights) < 2:
            return last[:count]
        out = []
        for k in range(count):
            x0 = weights[0] * self.recent[0][2][k]
            for w, (_, _, sols) in zip(weights[1:], self.recent[1:]):
                x0 += w * sols[k]
            out.append(x0)
        return out


def _lagrange_weights(times: list[float], time: float) -> list[float]:
    """Weights of the values at ``times`` (newest first) in their polynomial extrapolation to ``time``.

    The degree is the highest (through the newest points) whose weights sum in magnitude
    to at most ``WARM_WEIGHT_LIMIT``; a single point has weight 1.
    """
    for k in range(len(times), 1, -1):
        ts = times[:k]
        weights = [math.prod((time - u) / (t - u) for u in ts if u != t) for t in ts]
        if sum(abs(w) for w in weights) <= WARM_WEIGHT_LIMIT:
            return weights
    return [1.0]


def _network_key(pairs: NDArray[np.int64], n: int) -> bytes:
    return np.int64(n).tobytes() + np.ascontiguousarray(pairs, dtype=np.int64).tobytes()


class Border(NamedTuple):
    """A preconditioner for N on a network a few pairs away from the factorised one.

    Applies the exact inverse of ``K = [[M_CC, G_CP], [G_PC, G_PP]]`` (G: the couplings
    of the added pairs, see :func:`_bordered`) with the cached factor of M; the network the
    factor was made for has the trivial border (:func:`_plain_border`: every pair kept,
    none removed or added).

    Attributes
    ----------
    size : int
        Pairs of the factorised network.
    pos_c, kept : ndarray of int64, shape (|C|,)
        Kept pairs: their position in the factorised network and in the new one.
    removed : ndarray of int64, shape (|Q|,)
        Removed pairs Q (positions in the factorised network).
    W, WQQ_inv : ndarray, shapes (size, |Q|) and (|Q|, |Q|)
        ``M^-1 e_Q`` and the inverse of its Q rows (capacitance trick).
    added : ndarray of int64, shape (|P|,)
        Added pairs P (positions in the new network).
    NCP, B, T_inv : ndarray, shapes (|C|, |P|), (|C|, |P|), (|P|, |P|)
        ``G_CP``, ``M_CC^-1 G_CP`` and the inverse of the Schur complement T.
    """

    size: int
    pos_c: NDArray[np.int64]
    kept: NDArray[np.int64]
    removed: NDArray[np.int64]
    W: NDArray[np.float64]
    WQQ_inv: NDArray[np.float64]
    added: NDArray[np.int64]
    NCP: NDArray[np.float64]
    B: NDArray[np.float64]
    T_inv: NDArray[np.float64]


def _plain_border(m: int) -> Border:
    """The border of the factorised network itself (``M^-1`` unchanged)."""
    every = np.arange(m, dtype=np.int64)
    none = np.zeros(0, dtype=np.int64)
    return Border(m, every, every, none, np.zeros((m, 0)), np.zeros((0, 0)), none,
                  np.zeros((m, 0)), np.zeros((m, 0)), np.zeros((0, 0)))


class BorderSolves:
    """The solves with a cached factor M that bordered preconditioners share.

    Between two factorisations the networks differ from the factorised one by a few
    pairs, mostly the same ones (a pair added at an event stays; a removed one stays
    removed). ``M^-1 e_q`` of a removed pair q and ``M^-1 g_p`` of an added pair p
    (``g_p`` its column of N against every factorised pair) do not depend on the other
    changes, so each is solved once per factorisation and every border is assembled
    from them without further solves. ``g_p`` uses the geometry M was made at for the
    factorised pairs and p's unit vector when it was first added: one consistent
    symmetric matrix near N, which is all a preconditioner needs.

    Parameters
    ----------
    lu : TriangularFactor
        Factor of N on the pairs ``pairs`` with unit vectors ``unit``.
    pairs : ndarray of int64, shape (m, 2)
    unit : ndarray, shape (m, d)
    n : int
        Number of particles.

    Attributes
    ----------
    plain : Border
        The trivial border (the factorised network itself).
    """

    def __init__(self, lu: TriangularFactor, pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int) -> None:
        self.lu, self.pairs, self.unit = lu, pairs, unit
        self.plain = _plain_border(len(pairs))
        self.ptr, self.incident = incidence(pairs, n)
        self.removed: dict[int, NDArray[np.float64]] = {}
        self.added: dict[int, tuple[int, int, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]] = {}

    def removal(self, q: int) -> NDArray[np.float64]:
        """``M^-1 e_q`` for the factorised pair at position q, shape (m,)."""
        if q not in self.removed:
            e = np.zeros(len(self.pairs))
            e[q] = 1.0
            self.removed[q] = self.lu.solve(e)
        return self.removed[q]

    def addition(self, code: int, i: int, j: int, u: NDArray[np.float64]):
        """``(i, j, u, g, M^-1 g)`` of the added pair ``code`` (first unit vector u kept)."""
        if code not in self.added:
            u = np.array(u, dtype=np.float64)
            g = _coupling(i, j, u, self.pairs, self.unit, self.ptr, self.incident)
            self.added[code] = (i, j, u, g, self.lu.solve(g))
        return self.added[code]


@njit(cache=True)
def _coupling(i, j, u, pairs, unit, ptr, incident):  # pragma: no cover - numba
    """Column of N of a pair (i, j) with unit vector u against the pairs ``pairs``, shape (m,)."""
    g = np.zeros(pairs.shape[0])
    for end in (i, j):
        for p in range(ptr[end], ptr[end + 1]):
            c = incident[p]
            g[c] = _pair_coupling(i, j, u, pairs[c, 0], pairs[c, 1], unit[c])
    return g


def _bordered(solves, old_codes, codes, pairs, unit, cond_limit, max_changes):
    """Bordered preconditioner for N on a network a few pairs away from the factorised one, or None.

    With C the kept pairs, Q the removed and P the added ones, it applies the exact
    inverse of ``K = [[M_CC, G_CP], [G_PC, G_PP]]`` (G: couplings of the added pairs,
    :class:`BorderSolves`): ``M_CC^-1`` from the cached factor by the capacitance trick
    (solve with M, then cancel the Q components with ``(M^-1)_QQ``), the added pairs by
    their Schur complement ``T = G_PP - G_PC M_CC^-1 G_CP``. The solves come from
    ``solves`` (one per pair not seen before since the factorisation). A Schur
    complement below ``diag(G_PP) / cond_limit`` means an added pair is (nearly)
    dependent on the others — a possible self-stress — and returns None so that the
    caller factorises directly with its singularity checks.

    Returns
    -------
    Border or None
    """
    pos = locate(old_codes, codes)
    C = np.flatnonzero(pos >= 0)
    P = np.flatnonzero(pos < 0)
    pos_c = pos[C]
    kept = np.zeros(len(old_codes), dtype=bool)
    kept[pos_c] = True
    Q = np.flatnonzero(~kept)
    if len(P) + len(Q) > max_changes or len(C) == 0:
        return None
    m = len(old_codes)
    W = np.zeros((m, 0))
    if len(Q):
        W = np.column_stack([solves.removal(q) for q in Q])
    d = unit.shape[1]
    ends, units = np.zeros((len(P), 2), dtype=np.int64), np.zeros((len(P), d))
    G, Y = np.zeros((m, len(P))), np.zeros((m, len(P)))
    for e, k in enumerate(P):
        ends[e, 0], ends[e, 1], units[e], G[:, e], Y[:, e] = solves.addition(
            int(codes[k]), int(pairs[k, 0]), int(pairs[k, 1]), unit[k])
    ok, WQQ_inv, NCP, B, T_inv = _border_blocks(W, Q, G, Y, pos_c, ends, units, float(cond_limit))
    return Border(m, pos_c, C, Q, W, WQQ_inv, P, NCP, B, T_inv) if ok else None


@njit(cache=True)
def _border_blocks(W, Q, G, Y, pos_c, ends, units, cond_limit):  # pragma: no cover - numba
    """The dense blocks of a :class:`Border`, ``(ok, WQQ_inv, NCP, B, T_inv)``; ok is False where
    the Schur complement of an added pair falls below ``diag(G_PP) / cond_limit``.

    W: ``M^-1 e_Q`` (m, |Q|); G, Y: couplings g_p of the added pairs and ``M^-1 g_p`` (m, |P|);
    ends, units: the added pairs' particles and unit vectors.
    """
    nq, npp, nc = len(Q), G.shape[1], len(pos_c)
    WQQ_inv = np.zeros((nq, nq))
    if nq:
        WQQ = np.empty((nq, nq))
        for a in range(nq):
            for b in range(nq):
                WQQ[a, b] = W[Q[a], b]
        WQQ_inv = np.ascontiguousarray(np.linalg.inv(WQQ))  # C like every Border array: one compiled _pcg
        if npp:
            # M^-1 of the couplings with the removed pairs' rows cut, then M_CC^-1 by capacitance
            Y = Y - W @ np.ascontiguousarray(G[Q])
            Y = Y - W @ (WQQ_inv @ np.ascontiguousarray(Y[Q]))
    NCP, B = np.empty((nc, npp)), np.empty((nc, npp))
    for k in range(nc):
        for e in range(npp):
            NCP[k, e] = G[pos_c[k], e]
            B[k, e] = Y[pos_c[k], e]
    if npp == 0:
        return True, WQQ_inv, NCP, B, np.zeros((0, 0))
    T = NCP.T @ B
    for e in range(npp):
        for f in range(npp):
            T[e, f] = _pair_coupling(ends[e, 0], ends[e, 1], units[e], ends[f, 0], ends[f, 1], units[f]) - T[e, f]
        if T[e, e] <= _pair_coupling(ends[e, 0], ends[e, 1], units[e], ends[e, 0], ends[e, 1], units[e]) / cond_limit:
            return False, WQQ_inv, NCP, B, T
    return True, WQQ_inv, NCP, B, np.ascontiguousarray(np.linalg.inv(T))


@njit(cache=True)
def _solve_cc(lu, border, g):  # pragma: no cover - numba
    """``M_CC^-1 g`` for g on the kept pairs C, shape (|C|,): the capacitance trick on the cached factor."""
    Lp, Li, Lx, d, perm = lu
    pos_c, Q, W, WQQ_inv = border.pos_c, border.removed, border.W, border.WQQ_inv
    G = np.zeros(border.size)
    for k in range(len(pos_c)):
        G[np.uint64(pos_c[k])] = g[k]  # unsigned: no wraparound test per access
    y = _triangular_solve(Lp, Li, Lx, d, perm, G)
    nq = len(Q)
    if nq:
        t = np.zeros(nq)
        for a in range(nq):
            for b in range(nq):
                t[a] += WQQ_inv[a, b] * y[np.uint64(Q[b])]
        for i in range(border.size):
            s = 0.0
            for a in range(nq):
                s += W[i, a] * t[a]
            y[i] -= s
    out = np.empty(len(pos_c))
    for k in range(len(pos_c)):
        out[k] = y[np.uint64(pos_c[k])]
    return out


@njit(cache=True)
def _precondition(lu, border, g):  # pragma: no cover - numba
    """The bordered preconditioner applied to g (length of the new network)."""
    C, P = border.kept, border.added
    gc = np.empty(len(C))
    for k in range(len(C)):
        gc[k] = g[np.uint64(C[k])]  # unsigned: no wraparound test per access
    a = _solve_cc(lu, border, gc)
    out = np.empty(len(g))
    npp = len(P)
    if npp == 0:
        for k in range(len(C)):
            out[np.uint64(C[k])] = a[k]
        return out
    NCP, B, T_inv = border.NCP, border.B, border.T_inv
    u = np.empty(npp)
    for e in range(npp):
        s = g[np.uint64(P[e])]
        for k in range(len(C)):
            s -= NCP[k, e] * a[k]
        u[e] = s
    xp = np.zeros(npp)
    for e in range(npp):
        for f in range(npp):
            xp[e] += T_inv[e, f] * u[f]
        out[np.uint64(P[e])] = xp[e]
    for k in range(len(C)):
        s = a[k]
        for e in range(npp):
            s -= B[k, e] * xp[e]
        out[np.uint64(C[k])] = s
    return out


@njit(cache=True)
def _n_apply(pairs, unit, n, v):  # pragma: no cover - numba
    """``N v = S S^T v`` for contact values v, shape (Nc,)."""
    return _s_apply(pairs, unit, _st_apply(pairs, unit, v, n))


@njit(cache=True)
def _max_abs(v):  # pragma: no cover - numba
    """``max |v|``, NaN if any entry is NaN (a NaN solve must never count as converged)."""
    m = 0.0
    for k in range(len(v)):
        a = abs(v[k])
        if a > m or a != a:
            m = a
    return m


@njit(cache=True)
def _pcg(pairs, unit, n, lu, border, b, x0, rtol, max_iter):  # pragma: no cover - numba
    """Conjugate gradients on ``N x = b`` preconditioned by the bordered cached factor.

    Returns (x, iterations), iterations = -1 without convergence within ``max_iter``.
    Converged when ``|M^-1 r|_inf <= rtol |x|_inf``: with M close to N the
    preconditioned residual estimates the error ``N^-1 r`` of x itself. The residual
    CG updates drifts from ``b - N x`` by round-off of the size of the largest iterate;
    after a start much larger than the solution (by ``rtol / (100 eps)``) convergence
    is therefore confirmed on the true residual, and CG goes on from it if not.
    Converged, x takes one last step along the search direction (a product with N, no
    preconditioner solve), which shrinks its error by the preconditioner's contraction:
    the solutions later warm starts extrapolate are then far inside ``rtol``, and most
    solves along a run converge on the warm start itself (N = 1024 shear: 68 % of them,
    against 20 % without the last step).
    """
    x = x0.copy()
    r, z, p, rz = _residual(pairs, unit, n, lu, border, b, x)
    start = _max_abs(x0)
    for it in range(max_iter + 1):
        if _max_abs(z) <= rtol * _max_abs(x):
            if not 100.0 * EPS * start > rtol * _max_abs(x):
                return _last_step(pairs, unit, n, x, p, rz), it
            start = 0.0
            r, z, p, rz = _residual(pairs, unit, n, lu, border, b, x)
            if _max_abs(z) <= rtol * _max_abs(x):
                return _last_step(pairs, unit, n, x, p, rz), it
        if it == max_iter or not rz > 0.0:
            break
        q = _n_apply(pairs, unit, n, p)
        pq = np.dot(p, q)
        if not pq > 0.0:
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        z = _precondition(lu, border, r)
        rz_new = np.dot(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, -1


@njit(cache=True)
def _residual(pairs, unit, n, lu, border, b, x):  # pragma: no cover - numba
    """CG's state at x: residual ``b - N x``, preconditioned residual z, direction z, ``r . z``."""
    r = b - _n_apply(pairs, unit, n, x)
    z = _precondition(lu, border, r)
    return r, z, z.copy(), np.dot(r, z)


@njit(cache=True)
def _last_step(pairs, unit, n, x, p, rz):  # pragma: no cover - numba
    """x moved along the search direction p by the CG step length (one product with N)."""
    q = _n_apply(pairs, unit, n, p)
    pq = np.dot(p, q)
    if pq > 0.0 and rz > 0.0:
        x += (rz / pq) * p
    return x


def _factorize(pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int, codes: NDArray[np.int64],
               cond_limit: float, carried: CarriedOrder | None = None) -> tuple[TriangularFactor, CarriedOrder]:
    """LDL^T factorisation of N = S S^T with an explicit singularity check, and the
    ordering to carry to the next one.

    A self-stress makes N exactly singular in exact arithmetic; in floating point its
    smallest pivot is round-off. A ratio of the smallest to the largest |D_kk| below
    ``1 / cond_limit`` is treated as singular. The pivots come with the factor, so
    every factorisation is checked.

    With ``carried`` (the AMD ordering of an earlier network) the factor is built under
    that ordering while L has at most ``CARRY_FILL`` times its entries there; otherwise
    under a fresh AMD ordering, which is returned to be carried.
    """
    factor = None
    if carried is not None:
        factor = TriangularFactor.of_network(pairs, unit, n, carried.order(codes), max_fill=CARRY_FILL * carried.fill)
    if factor is None:
        factor = TriangularFactor.of_network(pairs, unit, n)
        carried = CarriedOrder.of(codes, factor)
    piv = np.abs(factor.pivots)
    if piv.size and piv.min() < piv.max() / cond_limit:
        raise SingularNetworkError(f"N = S S^T nearly singular (pivot ratio {piv.min() / piv.max():.3g})")
    return factor, carried


def _cg_each(pairs, unit, n, cache, border, rhs_list, starts, rtol):
    """CG on the cached factor for every right-hand side from its start, or None if one does
    not converge within ``cache.max_iter`` (``cache.iterations``: the last solve's)."""
    sols = []
    for b, x0 in zip(rhs_list, starts):
        x, it = _pcg(pairs, unit, n, cache.lu.args, border, b, x0, rtol, cache.max_iter)
        if it < 0:
            return None
        cache.iterations = it
        sols.append(x)
    return sols


def solve_contact_system(
    pairs: NDArray[np.int64],
    unit: NDArray[np.float64],
    n: int,
    rhs_list: list[NDArray[np.float64]],
    cond_limit: float = COND_LIMIT,
    check_pivots: bool = True,
    cache: FactorCache | None = None,
    time: float | None = None,
    warm: bool = True,
    rtol: float | None = None,
    gain: Callable[[list[NDArray[np.float64]]], float] | None = None,
) -> list[NDArray[np.float64]]:
    """Solutions of ``N x = b``, ``N = S S^T`` of one contact network, for every b of ``rhs_list``.

    Parameters
    ----------
    pairs : ndarray of int64, shape (Nc, 2)
    unit : ndarray, shape (Nc, d)
        Unit vectors of the contacts.
    n : int
        Number of particles.
    rhs_list : list of ndarray, shape (Nc,)
    cond_limit, check_pivots, cache, time
        As in :func:`solve_network`.
    warm : bool
        Start CG from the cache's warm starts and remember the solutions for later ones
        (solves of forces along a trajectory); False starts from zero and leaves them
        alone (other right-hand sides, e.g. the drift correction's).
    rtol : float, optional
        CG tolerance on the cached factor (default the cache's); a fresh factorisation
        solves exactly.
    gain : callable, optional
        ``gain(solutions)``: the factor by which errors of the solutions grow in what the
        caller forms from them (cancellation). Where it exceeds 1, CG goes on from its
        solutions to ``rtol / gain``, so that the tolerance holds for that quantity.

    Raises
    ------
    SingularNetworkError
    """
    pairs = read_only(pairs)
    key, codes = cache.network(pairs, n) if cache is not None else (None, pairs[:, 0] * n + pairs[:, 1])
    sols = None
    if cache is not None and not check_pivots and cache.lu is not None:
        same = cache.key == key
        if same:
            border = cache.solves.plain
        elif key in cache.bordered:
            border = cache.bordered[key]
        else:
            border = cache.bordered[key] = _bordered(
                cache.solves, cache.codes, codes, pairs, unit, cond_limit, cache.max_changes)
        if border is not None:
            starts = (cache.warm_starts(codes, len(rhs_list), time) if warm
                      else [np.zeros(len(codes)) for _ in rhs_list])
            tol = cache.rtol if rtol is None else rtol
            sols = _cg_each(pairs, unit, n, cache, border, rhs_list, starts, tol)
            factor = gain(sols) if sols is not None and gain is not None else 1.0
            if factor > 1.0:
                sols = _cg_each(pairs, unit, n, cache, border, rhs_list, sols, tol / factor)
            if sols is not None:
                cache.n_cg += 1
                cache.n_bordered += not same
    if sols is None:
        lu, order = _factorize(pairs, unit, n, codes, cond_limit, cache.order if cache is not None else None)
        sols = [lu.solve(b) for b in rhs_list]
        if not check_pivots:
            f, rhs = sols[0], rhs_list[0]
            res = np.linalg.norm(_n_apply(pairs, unit, n, f) - rhs)
            if not np.all(np.isfinite(f)) or res > 1e-8 * max(np.linalg.norm(rhs), 1e-300):
                raise SingularNetworkError(f"N = S S^T solve inaccurate (relative residual {res / max(np.linalg.norm(rhs), 1e-300):.3g})")
        if cache is not None:
            cache.key, cache.codes, cache.lu, cache.order, cache.iterations = key, codes, lu, order, 0
            cache.solves = BorderSolves(cache.lu, pairs, unit, n)
            cache.bordered = {}
            cache.n_factor += 1
    if cache is not None and warm:
        cache.remember(codes, sols, time)
    return sols
