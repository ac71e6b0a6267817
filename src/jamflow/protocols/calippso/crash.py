"""A crash basis for the first LP of a start near jamming, from its geometry alone.

Near jamming (an LS start compressed to a high pressure) the pairs with the smallest
gaps are nearly the contact network of the first LP's optimal vertex (at N = 2048:
5891 of the 5918 rows with a scaled gap below :data:`CRASH_GAP` carry a force there,
of 6019). The crash working set is those rows, made independent on the displacement
columns by HiGHS's rank repair of an alien basis (a dependent row leaves the working
set, a column no row fixes is held at zero: a rattler's, or a particle with fewer than
``d`` independent tight rows), and one row more, the next smallest gap, which fixes
``g``. :func:`jamflow.simplex.solve` starts from it; the held columns are moved to a
vertex at its end. Measurements: ``docs/notes/warm-simplex.md`` ("The first LP").
"""

from __future__ import annotations

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .lp import _highs_lp

#: Rows whose scaled right-hand side ``(r^2 - sigma^2) / sigma^2`` (about twice the
#: relative gap) is below this start in the crash working set. In the LS starts at
#: p = 1e7, 90 % of the d N smallest lie below 1.5e-6, and the (d N)-th is 1e-3
#: (measured: docs/notes/warm-simplex.md#the-first-lp-from-a-crash-basis).
CRASH_GAP: float = 1e-5

#: The crash is tried only when at least this fraction of the columns has a row below
#: :data:`CRASH_GAP`, between the measured cases: near starts at p = 1e7 (3D) and the
#: authors' d = 4, 5 LS examples have 0.93-0.99, a 2D LS packing at p = 1e6 0.85, the
#: d = 3 LS example 0.33 (its gaps do not separate; from its crash working set
#: jamflow.simplex met an unstable pivot)
#: (measured: docs/notes/warm-simplex.md#the-first-lp-from-a-crash-basis).
CRASH_MIN_TIGHT: float = 0.5

_BASIC, _UPPER, _ZERO = (int(highspy.HighsBasisStatus.kBasic), int(highspy.HighsBasisStatus.kUpper),
                         int(highspy.HighsBasisStatus.kZero))


def _crash_basis(h: highspy.Highs, A: sp.csc_matrix, rhs: NDArray[np.float64], col_lower: NDArray[np.float64],
                 col_upper: NDArray[np.float64]) -> tuple[NDArray[np.int8], NDArray[np.int8]] | None:
    """The crash basis of the LP ``min -g`` s.t. ``A z <= rhs`` (``g`` the last column):
    column and row statuses as HiGHS codes, held columns ``kZero``; None when fewer than
    :data:`CRASH_MIN_TIGHT` ``n`` rows are below :data:`CRASH_GAP` or no row is left for ``g``. ``h`` (the chain's HiGHS
    instance; its model is replaced) repairs the rank."""
    M, n = A.shape
    chosen = rhs < CRASH_GAP
    if chosen.sum() < CRASH_MIN_TIGHT * n:
        return None
    fixed = col_lower == col_upper
    col = np.where(fixed, int(highspy.HighsBasisStatus.kLower), _BASIC).astype(np.int8)
    col[-1] = _BASIC
    row = np.where(chosen, _UPPER, _BASIC).astype(np.int8)
    # rank repair on the displacement columns only (g's column zeroed), so that it is
    # never the column HiGHS holds
    displacement = sp.hstack([A[:, :-1], sp.csc_matrix((M, 1))], format="csc")
    h.clearSolver()
    h.passModel(_highs_lp(displacement, rhs, col_lower, col_upper))
    h.setOptionValue("simplex_scale_strategy", 0)
    alien = highspy.HighsBasis()
    alien.col_status = [highspy.HighsBasisStatus(int(v)) for v in col]
    alien.row_status = [highspy.HighsBasisStatus(int(v)) for v in row]
    alien.valid = True
    alien.alien = True
    h.setBasis(alien)
    h.getBasicVariables()  # factorises the alien basis: HiGHS's rank repair
    repaired = h.getBasis()
    row = np.array([int(v) for v in repaired.row_status], dtype=np.int8)
    repaired_col = np.array([int(v) for v in repaired.col_status], dtype=np.int8)
    held = (repaired_col != _BASIC) & (col == _BASIC)
    held[-1] = False
    col[held] = _ZERO
    extra = _row_for_g(rhs, row)
    if extra < 0:
        return None
    row[extra] = _UPPER
    return col, row


def _row_for_g(rhs: NDArray[np.float64], row: NDArray[np.int8]) -> int:
    """The row with the smallest right-hand side outside the working set, or -1. With
    the held columns' unit rows it eliminates, it makes the working set square; it is
    singular only if the row's displacement part is the combination of the working
    rows whose ``g`` coefficients sum to one, which the LU reports as trouble."""
    outside = np.flatnonzero(row == _BASIC)
    if not len(outside):
        return -1
    return int(outside[np.argmin(rhs[outside])])
