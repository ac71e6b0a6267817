"""The sparse LDL^T factor of ``N = S S^T`` of a contact network, and its ordering.

``P^T N P = (I + L) D (I + L)^T`` without pivoting: N is symmetric positive
(semi)definite, so D are the squared pivots of Cholesky and a self-stress shows as a
pivot that is round-off (:func:`jamflow.protocols.overdamped.solver._factorize` checks their
ratio). The fill-reducing ordering P is the expensive part: QDLDL (the OSQP project's
LDL^T) computes an approximate minimum degree (AMD) ordering on every call, about two
thirds of its 1.4 ms at N = 1024. An event-driven run factorises networks that differ
by a few pairs from the last one, so the AMD ordering of an earlier network, with the
pairs added since appended at the end (:class:`CarriedOrder`), orders the next one
almost as well: the factor is then built here, in compiled code, in about a third of
the time. QDLDL's numeric factorisation is the same up-looking algorithm as
:func:`_numeric` (T. A. Davis, *Direct Methods for Sparse Linear Systems*, SIAM 2006,
ch. 4), but its Python interface takes no ordering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import qdldl
import scipy.sparse as sp
from numpy.typing import NDArray

from ..._numba import njit, read_only
from ...network._graph_kernels import incidence

__all__ = ["CARRY_FILL", "CarriedOrder", "SingularNetworkError", "TriangularFactor", "locate"]

#: Largest ratio of the entries of a factor under a carried ordering to those of the
#: factor under the AMD ordering it was carried from. Each entry of L costs a
#: multiply-add in every preconditioner application, so beyond it a fresh AMD ordering
#: pays (measured: docs/notes/overdamped-constants.md#carry_fill-jamflowprotocolsoverdampedldl).
CARRY_FILL: float = 1.1


class SingularNetworkError(RuntimeError):
    """``N = S S^T`` is singular: the network carries a self-stress (potentially jammed)."""


@njit(cache=True)
def _pair_coupling(i, j, u, a, b, v):  # pragma: no cover - numba
    """``S_p . S_c`` of pairs p = (i, j) and c = (a, b) with unit vectors u, v (Eq. 2: -u at i, +u at j)."""
    uv = 0.0
    for k in range(u.shape[0]):
        uv += u[k] * v[k]
    s = 0.0
    if i == a:
        s += uv
    if i == b:
        s -= uv
    if j == a:
        s -= uv
    if j == b:
        s += uv
    return s


@njit(cache=True)
def _upper(pairs, unit, ptr, incident, position):  # pragma: no cover - numba
    """Upper triangle of ``P^T N P`` as CSC arrays (Ap, Ai, Ax): pair a is row and column
    ``position[a]``; pairs couple where they share a particle."""
    m = pairs.shape[0]
    order = np.empty(m, dtype=np.int64)
    for a in range(m):
        order[position[a]] = a
    cap = 0
    for a in range(m):
        for e in range(2):
            p = pairs[a, e]
            cap += ptr[p + 1] - ptr[p]
    Ap = np.zeros(m + 1, dtype=np.int64)
    Ai = np.empty(cap, dtype=np.int64)
    Ax = np.empty(cap)
    seen = np.full(m, -1, dtype=np.int64)
    nz = 0
    for col in range(m):
        a = np.uint64(order[col])  # unsigned indices: no wraparound tests
        for e in range(2):
            p = np.uint64(pairs[a, e])
            for q in range(np.uint64(ptr[p]), np.uint64(ptr[p + np.uint64(1)])):
                c = np.uint64(incident[q])
                row = position[c]
                if row <= col and seen[c] != col:  # a pair sharing both particles is met twice
                    seen[c] = col
                    Ai[nz] = row
                    Ax[nz] = _pair_coupling(pairs[a, 0], pairs[a, 1], unit[a], pairs[c, 0], pairs[c, 1], unit[c])
                    nz += 1
        Ap[col + 1] = nz
    return Ap, Ai[:nz], Ax[:nz]


@njit(cache=True)
def _elimination_tree(Ap, Ai):  # pragma: no cover - numba
    """Elimination tree (parent, -1 at roots) and the entries of every column of L, from
    the upper triangle (Ap, Ai)."""
    m = len(Ap) - 1
    visited = np.zeros(m, dtype=np.int64)
    counts = np.zeros(m, dtype=np.int64)
    parent = np.full(m, -1, dtype=np.int64)
    for j in range(m):
        visited[j] = j
        for p in range(np.uint64(Ap[j]), np.uint64(Ap[j + 1])):  # unsigned indices: no wraparound tests
            i = np.uint64(Ai[p])
            while visited[i] != j:  # walk up from row i to the column j, counting L[j, .]
                if parent[i] == -1:
                    parent[i] = j
                counts[i] += 1
                visited[i] = j
                i = np.uint64(parent[i])
    return parent, counts


@njit(cache=True)
def _numeric(Ap, Ai, Ax, parent, counts):  # pragma: no cover - numba
    """Up-looking LDL^T of the upper triangle (Ap, Ai, Ax): row k of L from a sparse
    triangular solve along the elimination tree. Returns (Lp, Li, Lx, D, k0), k0 the
    first exactly zero pivot or -1."""
    m = len(Ap) - 1
    Lp = np.zeros(m + 1, dtype=np.int64)
    for i in range(m):
        Lp[i + 1] = Lp[i] + counts[i]
    Li = np.empty(Lp[m], dtype=np.int64)
    Lx = np.empty(Lp[m])
    D = np.zeros(m)
    Dinv = np.zeros(m)
    marked = np.zeros(m, dtype=np.bool_)
    y = np.zeros(m)
    pattern = np.empty(m, dtype=np.int64)
    stack = np.empty(m, dtype=np.int64)
    next_free = Lp[:m].copy()
    for k in range(m):
        top = 0
        for p in range(np.uint64(Ap[k]), np.uint64(Ap[k + 1])):  # unsigned indices: no wraparound tests
            i = Ai[p]
            if i == k:
                D[k] = Ax[p]
                continue
            y[np.uint64(i)] = Ax[p]
            if marked[np.uint64(i)]:
                continue
            depth = 0
            while i != -1 and i < k and not marked[np.uint64(i)]:  # path up the tree to a marked node
                marked[np.uint64(i)] = True
                stack[depth] = i
                depth += 1
                i = parent[np.uint64(i)]
            while depth:  # the pattern in topological order
                depth -= 1
                pattern[top] = stack[depth]
                top += 1
        for t in range(top - 1, -1, -1):
            c = np.uint64(pattern[t])
            yc = y[c]
            for q in range(np.uint64(Lp[c]), np.uint64(next_free[c])):
                y[np.uint64(Li[q])] -= Lx[q] * yc
            q = np.uint64(next_free[c])
            Li[q] = k
            Lx[q] = yc * Dinv[c]
            D[k] -= yc * Lx[q]
            next_free[c] += 1
            y[c] = 0.0
            marked[c] = False
        if D[k] == 0.0:
            return Lp, Li, Lx, D, k
        Dinv[k] = 1.0 / D[k]
    return Lp, Li, Lx, D, -1


@njit(cache=True)
def _triangular_solve(Lp, Li, Lx, d, perm, b):  # pragma: no cover - numba
    """``x`` with ``N x = b`` from ``P^T N P = (I + L) D (I + L)^T`` (L strictly lower, CSC).

    ``perm`` is P as an index array: ``(P^T b)[k] = b[perm[k]]``. Indices read from the
    arrays index as unsigned integers: numba tests every signed index for wraparound,
    which made these loops almost twice as slow.
    """
    n = b.shape[0]
    one, two = np.uint64(1), np.uint64(2)
    y = np.empty(n)
    for k in range(n):
        y[k] = b[np.uint64(perm[k])]
    for j in range(n):
        yj = y[j]
        for p in range(np.uint64(Lp[j]), np.uint64(Lp[j + 1])):
            y[np.uint64(Li[p])] -= Lx[p] * yj
    for j in range(n - 1, -1, -1):
        # two partial sums: the back substitution is a chain of dependent subtractions
        s0, s1 = y[j] / d[j], 0.0
        p, end = np.uint64(Lp[j]), np.uint64(Lp[j + 1])
        while p + one < end:
            s0 -= Lx[p] * y[np.uint64(Li[p])]
            s1 -= Lx[p + one] * y[np.uint64(Li[p + one])]
            p += two
        if p < end:
            s0 -= Lx[p] * y[np.uint64(Li[p])]
        y[j] = s0 + s1
    x = np.empty(n)
    for k in range(n):
        x[np.uint64(perm[k])] = y[k]
    return x


@njit(cache=True)
def _ascending(codes):  # pragma: no cover - numba
    """Whether ``codes`` strictly increase."""
    for k in range(1, len(codes)):
        if codes[k] <= codes[k - 1]:
            return False
    return True


@njit(cache=True)
def _merge_positions(codes_from, codes_to):  # pragma: no cover - numba
    """:func:`locate` of two strictly increasing code arrays, by one merge pass."""
    out = np.full(len(codes_to), -1, dtype=np.int64)
    i = 0
    for k in range(len(codes_to)):
        c = codes_to[k]
        while i < len(codes_from) and codes_from[i] < c:
            i += 1
        if i < len(codes_from) and codes_from[i] == c:
            out[k] = i
    return out


def locate(codes_from: NDArray[np.int64], codes_to: NDArray[np.int64]) -> NDArray[np.int64]:
    """Position in ``codes_from`` of every entry of ``codes_to`` (-1 where absent).

    Pair codes of networks cut from a neighbour list increase along them; such pairs
    of arrays are merged in linear time, others searched after a sort.
    """
    if len(codes_from) == 0:
        return np.full(len(codes_to), -1, dtype=np.int64)
    if _ascending(codes_from) and _ascending(codes_to):
        return _merge_positions(codes_from, codes_to)
    order = np.argsort(codes_from, kind="stable")
    srt = codes_from[order]
    loc = np.minimum(np.searchsorted(srt, codes_to), len(srt) - 1)
    return np.where(srt[loc] == codes_to, order[loc], -1)


class TriangularFactor:
    """``P^T N P = (I + L) D (I + L)^T`` of a symmetric N, solved by compiled substitution.

    Made by :meth:`of_matrix` (any N, QDLDL with AMD) or :meth:`of_network` (N = S S^T
    of contact pairs, with AMD or a given ordering). The cached factor is applied inside
    compiled CG by :func:`_triangular_solve` on ``args``.

    Parameters
    ----------
    Lp, Li, Lx : ndarray
        L, strictly lower triangular, shape (m, m), as CSC arrays.
    d : ndarray, shape (m,)
        The pivots D.
    perm : ndarray of int64, shape (m,)
        The ordering P: row and column k of ``P^T N P`` are those of pair ``perm[k]``.

    Attributes
    ----------
    args : tuple
        ``(Lp, Li, Lx, d, perm)``: L strictly lower as CSC arrays, the pivots D and the
        ordering P (``(P^T b)[k] = b[perm[k]]``), as the compiled solvers take them.
    pivots : ndarray, shape (m,)
        D, in elimination order.
    shape : tuple
        ``(m, m)``.
    """

    def __init__(self, Lp: NDArray[np.int64], Li: NDArray[np.int64], Lx: NDArray[np.float64],
                 d: NDArray[np.float64], perm: NDArray[np.int64]) -> None:
        self.args = (np.asarray(Lp, dtype=np.int64), np.asarray(Li, dtype=np.int64),
                     np.asarray(Lx, dtype=np.float64), np.asarray(d, dtype=np.float64),
                     np.asarray(perm, dtype=np.int64))
        self.pivots = self.args[3]
        self.shape = (len(self.pivots), len(self.pivots))

    @property
    def fill(self) -> int:
        """Entries of L."""
        return int(self.args[0][-1])

    @classmethod
    def of_matrix(cls, N: sp.spmatrix) -> TriangularFactor:
        """QDLDL's factor of N (only its upper triangle is read) under its AMD ordering.

        Raises
        ------
        SingularNetworkError
            A pivot is exactly zero (QDLDL stops there).
        """
        try:
            L, d, perm = qdldl.Solver(sp.triu(N, format="csc"), upper=True).factors()
        except RuntimeError as exc:  # "not quasi-definite": a zero pivot
            raise SingularNetworkError(f"N = S S^T singular ({exc})") from exc
        L = sp.csc_matrix(L)
        return cls(L.indptr, L.indices, L.data, d, perm)

    @classmethod
    def of_network(cls, pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int,
                   order: NDArray[np.int64] | None = None, max_fill: float = np.inf) -> TriangularFactor | None:
        """The factor of ``N = S S^T`` of contact pairs.

        Parameters
        ----------
        pairs : ndarray of int64, shape (m, 2)
        unit : ndarray, shape (m, d)
            Unit vectors of the pairs.
        n : int
            Number of particles.
        order : ndarray of int64, shape (m,), optional
            Elimination order (pair indices); default QDLDL's AMD ordering.
        max_fill : float
            With ``order``: None instead of a factor with more entries in L.

        Raises
        ------
        SingularNetworkError
            A pivot is exactly zero.
        """
        m = len(pairs)
        pairs = read_only(pairs)
        ptr, incident = incidence(pairs, n)
        if order is None:
            Ap, Ai, Ax = _upper(pairs, unit, ptr, incident, np.arange(m))
            return cls.of_matrix(sp.csc_matrix((Ax, Ai, Ap), shape=(m, m)))
        position = np.empty(m, dtype=np.int64)
        position[order] = np.arange(m)
        Ap, Ai, Ax = _upper(pairs, unit, ptr, incident, position)
        parent, counts = _elimination_tree(Ap, Ai)
        if counts.sum() > max_fill:
            return None
        Lp, Li, Lx, d, zero = _numeric(Ap, Ai, Ax, parent, counts)
        if zero >= 0:
            raise SingularNetworkError(f"N = S S^T singular (zero pivot {zero} of {m})")
        return cls(Lp, Li, Lx, d, order)

    def solve(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """``N^-1 b`` for b of shape (m,) or (m, k)."""
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 1:
            return _triangular_solve(*self.args, np.ascontiguousarray(b))
        out = np.empty(b.shape)
        for k in range(b.shape[1]):
            out[:, k] = _triangular_solve(*self.args, np.ascontiguousarray(b[:, k]))
        return out


@dataclass(frozen=True)
class CarriedOrder:
    """An AMD ordering of one network, carried to networks that differ from it by a few pairs.

    Attributes
    ----------
    codes : ndarray of int64, shape (m,)
        Pair codes ``i n + j`` of the network it was computed for.
    rank : ndarray of int64, shape (m,)
        Elimination position of each of its pairs.
    fill : int
        Entries of L under it.
    """

    codes: NDArray[np.int64]
    rank: NDArray[np.int64]
    fill: int

    @classmethod
    def of(cls, codes: NDArray[np.int64], factor: TriangularFactor) -> CarriedOrder:
        """The ordering of ``factor``, made for the network ``codes``."""
        rank = np.empty(len(codes), dtype=np.int64)
        rank[factor.args[4]] = np.arange(len(codes))
        return cls(codes, rank, factor.fill)

    def order(self, codes: NDArray[np.int64]) -> NDArray[np.int64]:
        """Elimination order of the network ``codes``: its pairs of the AMD network in
        their order there, then the others in their order in ``codes``."""
        pos = locate(self.codes, codes)
        rank = np.where(pos >= 0, self.rank[pos], len(self.codes) + np.arange(len(codes)))
        return np.argsort(rank, kind="stable")
