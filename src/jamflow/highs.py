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

import highspy

__all__ = ["new_highs", "DEFAULT_THREADS"]

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
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", int(threads))
    if _scheduler_threads != threads:
        highspy.Highs.resetGlobalScheduler(True)
        _scheduler_threads = threads
    return h
