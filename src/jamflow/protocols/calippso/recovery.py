"""The bound schedule after an accepted LP, and the recoveries: from a failed LP or a
rejected update, from a converged LP that failed its final checks, and from a stall."""

from __future__ import annotations

import numpy as np

from .options import _Options
from .record import IterationRecord, _diagnose
from .state import _Chain, _LPSetup, _Step
from .steps import _small

#: Recovery from a failed LP or an overlapping update: the cutoff grows and the bound
#: shrinks by these factors, at most MAX_RECOVERIES times in a row.
CUTOFF_GROWTH: float = 1.3
BOUND_SHRINK: float = 0.25
MAX_RECOVERIES: int = 4

#: In the last bound phase the next LP is unbounded once the stable particles moved less
#: than this fraction of the bound (the bound then holds only rattlers).
UNBOUND_FRACTION: float = 1e-3

#: In the last bound phase a stable particle moving by more than this fraction of the
#: bound means the bound is active (an external force): the next LP is unbounded.
BOUND_ACTIVE_FRACTION: float = 0.5

#: Stall test: a chain stalls when the smallest ``sqrt(Gamma*) - 1`` of its last
#: STALL_WINDOW accepted LPs exceeds STALL_PROGRESS times the smallest before them; each
#: stall gets one recovery, the chain stops after MAX_STALL_RECOVERIES
#: (measured: docs/notes/calippso-constants.md#stall_window).
STALL_WINDOW: int = 100
STALL_PROGRESS: float = 0.5
MAX_STALL_RECOVERIES: int = 3

#: Methods of the cold re-solves after a converged LP failed its final checks:
#: interior point with crossover, then the dual simplex.
FINAL_RECOVERY_METHODS: tuple[str, ...] = ("ipm", "dual")


def _schedule_next(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options) -> None:
    """Whether the next LP is bounded."""
    # the converging LP must be unbounded: go unbounded once the network is
    # isostatic or the tightest bound is far from active for the stable particles;
    # stay unbounded only while isostatic with moves the bound would have allowed
    # (a large unbounded move wanders along soft directions: bounded again after it)
    tight = 0.5 * opt.bound[-1][1]
    if np.isfinite(lp.bound):
        leave_bound = (step.iso or step.max_s_stable < UNBOUND_FRACTION * tight
                       or step.max_s_stable > BOUND_ACTIVE_FRACTION * tight)
    else:
        leave_bound = step.iso and step.max_s_stable <= BOUND_ACTIVE_FRACTION * tight
    chain.unbounded_next = _small(step, opt) or (chain.phase == len(opt.bound) and leave_bound)


def _check_stall(chain: _Chain) -> None:
    """A stalled chain (:func:`_stalled`) gets its next recovery, or the diagnostics when spent."""
    if _stalled(chain.records, chain.stall_from):
        chain.stalls += 1
        if chain.stalls > MAX_STALL_RECOVERIES:
            raise RuntimeError(_diagnose(
                f"stalled: sqrt(Gamma*)-1 did not halve in {STALL_WINDOW} LPs, {MAX_STALL_RECOVERIES} times",
                chain.records))
        # recovery: an unbounded LP (no bound pins floppy motions) with fresh rows
        chain.stall_from = len(chain.records)
        chain.unbounded_next = True
        chain.rows = None


def _recover(chain: _Chain, reason: str) -> None:
    """After a failed LP or a rejected update: one more recovery, a larger cutoff and a
    smaller bound with fresh rows, or the diagnostics when spent."""
    if chain.recoveries + 1 > MAX_RECOVERIES:
        raise RuntimeError(_diagnose(f"{reason} after {MAX_RECOVERIES} recoveries", chain.records))
    chain.recoveries += 1
    chain.cut_factor *= CUTOFF_GROWTH
    chain.bound_factor *= BOUND_SHRINK
    chain.unbounded_next = False
    chain.rows = None


def _final_recovery(chain: _Chain) -> None:
    """A converged LP failed its final checks: re-solve with a larger cutoff, cold. A
    degenerate (e.g. App. A hyperstatic) LP has many dual optima: by interior point with
    crossover, then by the dual simplex."""
    chain.final_attempts += 1
    chain.cut_factor *= CUTOFF_GROWTH
    chain.recovery_method = FINAL_RECOVERY_METHODS[chain.final_attempts - 1]
    chain.rows = None


def _stalled(records: list[IterationRecord], start: int) -> bool:
    """No progress: the smallest ``sqrt(Gamma*) - 1`` of the last :data:`STALL_WINDOW`
    accepted LPs is above :data:`STALL_PROGRESS` times the smallest before them
    (only LPs from index ``start`` on count)."""
    sg = [r.sqrt_gamma_minus_1 for r in records[start:] if r.accepted]
    if len(sg) <= STALL_WINDOW:
        return False
    return min(sg[-STALL_WINDOW:]) > STALL_PROGRESS * min(sg[:-STALL_WINDOW])
