"""The jamming LP's explicit dual, for HiGHS's HiPO interior point, and its answer read
back as the primal LP's solution, forces and vertex basis.

An interior point method factorises the normal equations of the LP's constraint
matrix. The jamming LP ``min -g`` s.t. ``A z <= rhs``, ``l <= z <= u`` has more rows
than columns, and ``g``'s column has a 1 in every row, so ``A Theta A^T`` (rows by
rows) is dense. Its dual::

    min rhs . y - l . w_l + u . w_u   s.t.   A^T y - w_l + w_u = e_g,   y, w_l, w_u >= 0

has one equality row per free column of the primal; its normal matrix ``A^T Theta A``
(columns by columns) has the contact network's sparsity and one dense row, ``g``'s.
HiPO's nested-dissection Cholesky of it is what makes the first LP of a 3D near start
2.6 times faster at N = 4096 (measured: docs/notes/calippso-constants.md#interior_points).

The dual's row duals are the primal columns ``z`` (HiGHS's sign convention: reduced
costs ``c - M^T lambda``, so ``M^T z <= (rhs, -l, u)`` is the primal's feasibility),
its columns ``y`` are the primal's row forces, and its basis is the primal's by
complementarity: a basic ``y_i`` is an active row, a basic ``w_l`` (``w_u``) a column at
its lower (upper) bound. Columns with ``l == u`` (the anchor) have no dual row; they
stay at their bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ...highs import colwise_lp

_BASIC = int(highspy.HighsBasisStatus.kBasic)
_LOWER = int(highspy.HighsBasisStatus.kLower)
_UPPER = int(highspy.HighsBasisStatus.kUpper)


@dataclass(frozen=True)
class DualLP:
    """The dual of ``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper`` as
    HiGHS takes it, and what reading its answer back needs.

    Attributes
    ----------
    lp : highspy.HighsLp
        Columns ``(y, w_l, w_u)``, one equality row per free primal column.
    free : ndarray of int64, shape (k,)
        The primal columns with ``lower < upper``, one per dual row.
    with_lower, with_upper : ndarray of int64
        Positions in ``free`` of the columns whose lower (upper) bound is finite: the
        columns ``w_l`` (``w_u``) of the dual, in that order.
    col_lower, col_upper : ndarray, shape (n,)
        The primal column bounds (the fixed columns' values are read from them).
    """

    lp: highspy.HighsLp
    free: NDArray[np.int64]
    with_lower: NDArray[np.int64]
    with_upper: NDArray[np.int64]
    col_lower: NDArray[np.float64]
    col_upper: NDArray[np.float64]

    @property
    def n_rows(self) -> int:
        """Rows of the primal LP (the dual's ``y`` columns)."""
        return self.lp.num_col_ - len(self.with_lower) - len(self.with_upper)


def dual_lp(A: sp.csc_matrix, rhs: NDArray[np.float64], col_lower: NDArray[np.float64],
            col_upper: NDArray[np.float64]) -> DualLP:
    """The explicit dual of the jamming LP (module docstring); ``g`` is the last column.

    Parameters
    ----------
    A : scipy.sparse.csc_matrix, shape (m, n)
    rhs : ndarray, shape (m,)
    col_lower, col_upper : ndarray, shape (n,)
        Column bounds; ``g``'s must be free (``lower < upper``).
    """
    n = A.shape[1]
    free = np.flatnonzero(col_lower < col_upper)
    if len(free) == 0 or free[-1] != n - 1:
        raise ValueError("the jamming LP's dual needs a free g (the last column)")
    with_lower = np.flatnonzero(np.isfinite(col_lower[free]))
    with_upper = np.flatnonzero(np.isfinite(col_upper[free]))
    k = len(free)
    eye = sp.identity(k, format="csc")
    M = sp.hstack([A[:, free].T.tocsc(), -eye[:, with_lower], eye[:, with_upper]], format="csc")
    cost = np.concatenate([rhs, -col_lower[free][with_lower], col_upper[free][with_upper]])
    e_g = np.zeros(k)
    e_g[-1] = 1.0
    lp = colwise_lp(M, cost, np.zeros(M.shape[1]), np.full(M.shape[1], highspy.kHighsInf), e_g, e_g)
    return DualLP(lp, free, with_lower, with_upper, col_lower, col_upper)


def primal_answer(dual: DualLP, col_value: NDArray[np.float64], row_dual: NDArray[np.float64],
                  col_status: NDArray[np.int8]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                         NDArray[np.int8], NDArray[np.int8]] | None:
    """The primal LP's answer from the dual's: columns ``z``, row forces ``y`` (the
    chain's sign: HiGHS's primal row duals negated; non-negative up to the tolerance)
    and the vertex basis as HiGHS status codes (column statuses, row statuses).

    Parameters
    ----------
    dual : DualLP
    col_value, row_dual : ndarray
        HiGHS's solution of ``dual.lp``.
    col_status : ndarray of int8
        HiGHS's basis status of the dual's columns.

    Returns
    -------
    (z, y, col_status, row_status), or None when the dual's basis does not map to a
    primal vertex basis (not one basic variable per primal row; e.g. a basic logical of
    a dual row leaves its column nonbasic off its bounds).
    """
    m = dual.n_rows
    n = len(dual.col_lower)
    z = np.zeros(n)
    z[dual.free] = row_dual
    y = np.asarray(col_value[:m], dtype=np.float64)
    row_status = np.where(col_status[:m] == _BASIC, _UPPER, _BASIC).astype(np.int8)
    free_status = np.full(len(dual.free), _BASIC, dtype=np.int8)
    basic_w = col_status[m:] == _BASIC
    n_lower = len(dual.with_lower)
    free_status[dual.with_lower[basic_w[:n_lower]]] = _LOWER
    at_upper = dual.with_upper[basic_w[n_lower:]]
    if np.any(free_status[at_upper] != _BASIC):
        return None
    free_status[at_upper] = _UPPER
    col_status_primal = np.full(n, _LOWER, dtype=np.int8)
    col_status_primal[dual.free] = free_status
    if int(np.sum(row_status == _BASIC)) + int(np.sum(col_status_primal == _BASIC)) != m:
        return None
    # a nonbasic column's value is its bound (the dual's row duals carry its rounding)
    z = np.where(col_status_primal == _LOWER, dual.col_lower,
                 np.where(col_status_primal == _UPPER, dual.col_upper, z))
    return z, y, col_status_primal, row_status
