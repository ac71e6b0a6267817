"""One way to make a HiGHS instance: silent, with a thread count the process agrees on.

HiGHS runs every instance of a process on one global task scheduler, created by the
first solve with that instance's ``threads``. A later instance asking for another
thread count fails its ``run()`` with model status 'Not Set' (HiGHS 1.16: "Option
'threads' is set to 1 but global scheduler has already been initialized to use 2
threads"), so a certificate solved at HiGHS's default thread count made a later
CALiPPSO chain of the same process fail. :func:`new_highs` resets the scheduler when
the requested count changes (jamflow never solves two LPs at once).
"""

from __future__ import annotations

import ctypes
import os
import sys

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

__all__ = ["new_highs", "colwise_lp", "DEFAULT_THREADS"]

#: HiGHS threads when a stage does not ask for more: one thread is reproducible, and a
#: second one gained nothing (measured: docs/notes/resources.md).
DEFAULT_THREADS: int = 1

_scheduler_threads: int | None = None


def new_highs(threads: int = DEFAULT_THREADS) -> highspy.Highs:
    """A HiGHS instance with logging off and ``threads`` threads.

    Parameters
    ----------
    threads : int
        Threads of the global scheduler, >= 1; a change from the last instance's
        count resets the scheduler first.
    """
    global _scheduler_threads
    if threads < 1:
        raise ValueError(f"HiGHS threads must be at least 1, got {threads}")
    h = _without_banner()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", int(threads))
    if _scheduler_threads != threads:
        highspy.Highs.resetGlobalScheduler(True)
        _scheduler_threads = threads
    return h


def _without_banner() -> highspy.Highs:
    """``highspy.Highs()`` with the version and licence banner its first instance prints to the
    process's C-level stdout (before any option can turn logging off) sent to the null device,
    so a command's stdout holds only what jamflow prints."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.close(null)
        try:
            return highspy.Highs()
        finally:
            ctypes.CDLL(None).fflush(None)  # the banner may sit in C's stdout buffer
            os.dup2(saved, 1)
    finally:
        os.close(saved)


def colwise_lp(A: sp.csc_matrix, cost: ArrayLike, col_lower: ArrayLike, col_upper: ArrayLike,
               row_lower: ArrayLike, row_upper: ArrayLike) -> highspy.HighsLp:
    """The LP ``min cost . x`` s.t. ``row_lower <= A x <= row_upper``, ``col_lower <= x <= col_upper``.

    Parameters
    ----------
    A : scipy.sparse.csc_matrix, shape (m, n)
        Constraint matrix, passed to HiGHS column-wise as it is (sorted indices
        are the caller's choice).
    cost, col_lower, col_upper : array_like, shape (n,)
    row_lower, row_upper : array_like, shape (m,)
        Bounds; ``highspy.kHighsInf`` for none.
    """
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = A.shape[1], A.shape[0]
    lp.col_cost_ = np.asarray(cost, dtype=np.float64)
    lp.col_lower_, lp.col_upper_ = np.asarray(col_lower, np.float64), np.asarray(col_upper, np.float64)
    lp.row_lower_, lp.row_upper_ = np.asarray(row_lower, np.float64), np.asarray(row_upper, np.float64)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = A.indptr.astype(np.int32)
    lp.a_matrix_.index_ = A.indices.astype(np.int32)
    lp.a_matrix_.value_ = A.data.astype(np.float64)
    return lp
