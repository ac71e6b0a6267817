"""What Algorithm 1 carries from one LP to the next (:class:`_Chain`), one LP as set up
(:class:`_LPSetup`, lines 4-7) and what a solved LP says (:class:`_Step`, lines 9-11)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .lp import _RowGeometry, _Rows
from .record import IterationRecord, _NewtonAttempt


@dataclass
class _Chain:
    """What Algorithm 1 carries from one LP to the next: the configuration, the rows
    (kept while particles move little, for warm starts), the bound phase and the
    recovery counters."""

    x: NDArray[np.float64]  # (N, d) positions [length]
    D: NDArray[np.float64]  # (N,) diameters [length]
    records: list[IterationRecord] = field(default_factory=list)
    rows: _Rows | None = None
    phase: int = 0  # 0 far, 1.. schedule entries; only tightens (hysteresis)
    cut_factor: float = 1.0
    bound_factor: float = 1.0
    recoveries: int = 0
    anchor: int = -1  # fixed particle (periodic box); -1 = none
    prev_rattler: NDArray[np.bool_] | None = None
    final_attempts: int = 0
    recovery_method: str | None = None  # cold solve forced by a failed final check
    unbounded_next: bool = False
    stalls: int = 0
    stall_from: int = 0  # records before this index are not compared by the stall test
    backbone_key: bytes | None = None  # backbone rows of the last accepted LP
    newton_tried: bytes | None = None  # backbone of the last rejected Newton finish
    newton: list[_NewtonAttempt] = field(default_factory=list)
    near_start: bool = False  # see NEAR_START_GAP


@dataclass(frozen=True)
class _LPSetup:
    """One jamming LP as set up (Algorithm 1, lines 4-7): rows, their geometry, the
    scaled matrix, column bounds, the cutoff ``ell`` [length], the displacement bound
    ``bound`` [mean diameters; inf = none], the mean diameter ``unit`` and the HiGHS method."""

    rows: _Rows
    geo: _RowGeometry
    A: sp.csc_matrix
    col_lower: NDArray[np.float64]
    col_upper: NDArray[np.float64]
    ell: float
    sig_max: float
    unit: float
    bound: float
    method: str


@dataclass(frozen=True)
class _Step:
    """What one solved LP says (Algorithm 1, lines 9-11): displacements ``u`` (N, d)
    [mean diameters], ``g = Gamma* - 1``, the row duals ``mu`` and their active set, the
    contacts and rattlers they give, and the convergence measures."""

    u: NDArray[np.float64]
    g: float
    sg: float  # sqrt(Gamma*) - 1
    mu: NDArray[np.float64]
    active: NDArray[np.bool_]
    contacts: NDArray[np.int64]
    wall_particles: NDArray[np.int64]
    rattler: NDArray[np.bool_]
    n_c: int
    n_s: int
    iso: bool
    max_s: float
    max_s_stable: float
    min_active_dual: float
    max_inactive_dual: float

    @property
    def backbone(self) -> NDArray[np.bool_]:
        """Contacts between two stable particles."""
        stable = ~self.rattler
        return stable[self.contacts[:, 0]] & stable[self.contacts[:, 1]]


def _record(chain: _Chain, progress: Callable[[IterationRecord], None] | None, rec: IterationRecord) -> None:
    """Append ``rec`` to the chain's history and report it."""
    chain.records.append(rec)
    if progress:
        progress(rec)
