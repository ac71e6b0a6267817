"""The options of one :func:`~jamflow.protocols.calippso.calippso` call: their defaults,
the record the chain carries, and the checks of the input."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...state.packing import Packing
from ...tolerances import OVERLAP_TOL
from .container import _Container
from .lp import FAR_GROWTH

#: Solver strategies. ``ipm``: HiGHS interior point with crossover (vertex duals),
#: cold every LP; ``simplex``: the primal simplex from the previous LP's basis,
#: carried over to the new rows by pair (the cold first LP by the dual simplex);
#: ``hybrid``: interior point while ``sqrt(Gamma*) - 1 > HYBRID_SWITCH``, then the
#: warm primal simplex (a warm start slower than the last interior point solve is
#: abandoned for interior point, see :data:`WARM_PIVOTS_PER_ROW`); ``ipm-center``:
#: interior point without crossover on every bounded LP (a point inside the optimal
#: face: displacements along directions that do not change Gamma are not pushed onto
#: the bound as at a vertex) and with crossover on every unbounded LP, the only ones
#: whose duals give the contacts of the result.
SOLVERS: tuple[str, ...] = ("ipm", "simplex", "hybrid", "ipm-center")

#: Default solver: the fastest strategy on the LS examples and random starts
#: (measured: docs/notes/calippso-constants.md#default_solver).
DEFAULT_SOLVER: str = "hybrid"

#: Convergence: largest displacement of a stable particle [mean diameters].
DEFAULT_TOL_S: float = 1e-9

#: Convergence: ``sqrt(Gamma*) - 1`` (relative growth of the diameters in one LP).
DEFAULT_TOL_GAMMA: float = 1e-12

#: HiGHS primal and dual feasibility (and interior point optimality) tolerance, the
#: default of ``solver_tol``. Rows are relative-gap sized, so a row violation v is a
#: relative overlap of ~v / 2: ``solver_tol`` may range from HiGHS's smallest
#: feasibility tolerance, 1e-10, up to ``2 OVERLAP_TOL`` (overlaps up to OVERLAP_TOL).
SOLVER_TOL: float = 1e-10
MIN_SOLVER_TOL: float = 1e-10
MAX_SOLVER_TOL: float = 2.0 * OVERLAP_TOL

#: Default neighbour cutoff ``ell`` [current largest diameters], the reference
#: implementation's 3.4 R (measured: docs/notes/calippso-constants.md#default_cutoff).
DEFAULT_CUTOFF: float = 1.7

#: Cutoff in the last bound phase, for unbounded LPs and for a start near jamming
#: [current largest diameters]: the first shell and a rattler's cage (the paper's 1.4 sigma).
DEFAULT_CUTOFF_NEAR: float = 1.4

#: Displacement bound schedule: ``(threshold on sqrt(Gamma*) - 1, bound)`` with the
#: bound in mean radii; the first phase (``far``) bound is derived from the cutoff.
DEFAULT_BOUND_SCHEDULE: tuple[tuple[float, float], ...] = ((5e-4, 0.1), (1e-5, 0.01))

#: HiGHS interior point methods of the interior point LPs: ``ipx`` (in every highspy
#: wheel) on the LP as it is, and ``hipo`` (a nested-dissection Cholesky; needs HiPO in
#: the highspy build, ``highspy[extras]``) on the LP's explicit dual (:mod:`.dual`), whose
#: normal equations have the contact network's sparsity where the primal's are dense.
#: Without crossover (``ipm-nox``) HiPO solves the LP as it is. ``auto`` takes ``hipo``
#: from :data:`HIPO_MIN_COLUMNS` columns on when the build has it, else ``ipx``.
INTERIOR_POINTS: tuple[str, ...] = ("auto", "ipx", "hipo")
DEFAULT_INTERIOR: str = "auto"
#: ``auto``: HiPO on the dual from 6144 columns (``d N + 1``; 3D N = 2048 has 6145) on.
#: CPU time of a near start's first LP, IPX + crossover / HiPO on the dual + crossover,
#: one core: 3D N = 1024 0.69-0.81, N = 2048 1.20-1.37, N = 4096 2.43-2.64; the LS
#: examples (N = 1024) d = 3, 4, 5: 0.85, 0.78, 0.84, tiled to N = 2048 in d = 4, 5: 2.11,
#: 1.46; the same optimum and active set
#: (measured: docs/notes/calippso-constants.md#interior_points).
HIPO_MIN_COLUMNS: int = 6144
#: The ``interior`` of an LP that HiPO on the dual had trouble with, before the trouble;
#: IPX then solved the LP as it is.
DUAL_FALLBACK: str = "ipx after hipo-dual: "

#: Engines of the warm simplex LPs: ``highs`` (HiGHS's primal simplex) or ``jamflow``
#: (:mod:`jamflow.simplex`, a bounded simplex whose basis LU has a nested-dissection
#: ordering: at N = 4096 it factorises a contact network's basis several times faster
#: than HiGHS's Markowitz LU, and prices by a sketch of steepest edge; measurements in
#: ``docs/notes/warm-simplex.md``). ``auto`` takes ``jamflow`` for LPs of at least
#: :data:`WARM_ENGINE_MIN_COLUMNS` columns. A warm LP on which ``jamflow`` reports
#: trouble is solved by HiGHS from the same basis, and counted (``warm_fallbacks``).
WARM_ENGINES: tuple[str, ...] = ("auto", "highs", "jamflow")
DEFAULT_WARM_ENGINE: str = "auto"
#: ``auto``: jamflow.simplex from ``d N`` = 4096 on. The same warm LPs from the same
#: basis, CPU time HiGHS / jamflow: d = 3, N = 1024 0.5-1.1 (jamflow slower on the
#: median LP), N = 2048 1.1-1.4, N = 4096 2.0; d = 4 and 5, N = 1024 1.6 and 1.7.
#: Whole chains also depend on the path each engine's vertices lead to (more LPs with
#: jamflow at one N = 4096 start, fewer at one N = 2048 start): the note's "Whole chains".
WARM_ENGINE_MIN_COLUMNS: int = 4096

#: The first LP of a start near jamming (:data:`~.lp.NEAR_START_GAP`): ``highs`` (the
#: interior point with crossover, like every interior point LP) or ``crash`` (:mod:`.crash`:
#: :mod:`jamflow.simplex` from a working set of the start's smallest gaps; an LP on which
#: it reports trouble is solved by the interior point, counted in ``first_lp_fallbacks``).
#: ``auto`` takes ``crash`` from :data:`CRASH_MIN_COLUMNS` columns on. A far start's
#: first LP is always the interior point's.
FIRST_LPS: tuple[str, ...] = ("auto", "highs", "crash")
#: ``highs`` by default: CPU time of the first LP, IPX + crossover / crash, with the same
#: answers, is 2.5-3.1 at d = 3, N = 2048 and 4.0-4.1 on the LS examples d = 4 and 5, but
#: 1.89 at N = 4096 s1 (s2: about 2.3 against IPX alone), not the 2x on every start its
#: adoption asked for, and the crash's pivots grow faster with N than IPX's time; a
#: different first vertex also changes the chain's path
#: (measured: docs/notes/warm-simplex.md#the-first-lp-from-a-crash-basis).
DEFAULT_FIRST_LP: str = "highs"
#: ``auto``: the crash basis from ``d N`` = 4096 columns on (the LS examples d = 4 and 5,
#: d = 3 from N = 2048; at d = 3, N = 1024 the first LP is 2 s of CPU).
CRASH_MIN_COLUMNS: int = 4096

#: How a chain ends. ``newton``: once an LP in the tail (``sqrt(Gamma*) - 1 <=
#: NEWTON_FROM``) gives an isostatic network, the square system of that network is
#: solved by Newton's method and certified; a rejected finish leaves the chain to the
#: LPs. ``lp``: the pure LP chain of the paper.
FINISHES: tuple[str, ...] = ("newton", "lp")

#: The pure LP chain by default: the Newton finish saves LPs but not time
#: (measured: docs/notes/calippso-constants.md#default_finish).
DEFAULT_FINISH: str = "lp"

#: Default largest number of LPs.
DEFAULT_MAX_ITERATIONS: int = 1000


@dataclass(frozen=True)
class _Options:
    """The user's options of one :func:`~jamflow.protocols.calippso.calippso` call (its
    keyword arguments but ``progress``; ``walls`` says whether the faces are walls)."""

    tol_s: float
    tol_gamma: float
    solver: str
    solver_tol: float
    cutoff: float
    cutoff_near: float
    bound: tuple[tuple[float, float], ...]
    relax: float | None
    walls: bool
    max_iterations: int
    require_isostatic: bool
    threads: int
    finish: str
    interior: str
    warm_engine: str
    first_lp: str

    def settings(self) -> dict[str, Any]:
        """The options as the stage parameters stored with the result."""
        return dict(finish=self.finish, interior=self.interior, warm_engine=self.warm_engine, first_lp=self.first_lp,
                    tol_s=self.tol_s, tol_gamma=self.tol_gamma,
                    solver=self.solver, solver_tol=self.solver_tol, cutoff=self.cutoff,
                    cutoff_near=self.cutoff_near, bound=[list(b) for b in self.bound], relax=self.relax,
                    walls=self.walls, max_iterations=self.max_iterations, threads=self.threads)

    def check(self, packing: Packing) -> None:
        """Raise ``ValueError`` for a bad start or bad options (the interior point method
        is checked by the solver)."""
        _check_options(packing, self.tol_s, self.tol_gamma, self.solver, min(self.cutoff, self.cutoff_near),
                       self.bound, self.relax, self.walls, self.max_iterations)
        if not (MIN_SOLVER_TOL <= self.solver_tol <= MAX_SOLVER_TOL):
            raise ValueError(f"solver_tol must lie in [{MIN_SOLVER_TOL:g}, {MAX_SOLVER_TOL:g}], got {self.solver_tol}")
        if self.finish not in FINISHES:
            raise ValueError(f"unknown finish {self.finish!r}; choose one of {', '.join(FINISHES)}")
        if self.warm_engine not in WARM_ENGINES:
            raise ValueError(f"unknown warm engine {self.warm_engine!r}; choose one of {', '.join(WARM_ENGINES)}")
        if self.first_lp not in FIRST_LPS:
            raise ValueError(f"unknown first LP {self.first_lp!r}; choose one of {', '.join(FIRST_LPS)}")


def _engine_of_warm_lps(warm_engine: str, columns: int) -> str:
    """The engine of the warm simplex LPs: ``warm_engine`` (checked by :class:`_Options`), with ``auto``
    resolved by the LP's column count ``columns`` (``d N``, :data:`WARM_ENGINE_MIN_COLUMNS`)."""
    if warm_engine == "auto":
        return "jamflow" if columns >= WARM_ENGINE_MIN_COLUMNS else "highs"
    return warm_engine


def _crash_first(first_lp: str, columns: int) -> bool:
    """Whether the first LP of a near start is tried from a crash basis: ``first_lp``
    (checked by :class:`_Options`), with ``auto`` resolved by the column count ``columns``
    (``d N``, :data:`CRASH_MIN_COLUMNS`)."""
    if first_lp == "auto":
        return columns >= CRASH_MIN_COLUMNS
    return first_lp == "crash"


def _check_options(packing, tol_s, tol_gamma, solver, cutoff, bound, relax, walls, max_iterations) -> None:
    if not isinstance(packing, Packing):
        raise ValueError(f"calippso needs a Packing, got {type(packing).__name__}")
    if not (np.isfinite(tol_s) and tol_s > 0):
        raise ValueError(f"tol_s must be positive and finite, got {tol_s}")
    if not (np.isfinite(tol_gamma) and tol_gamma > 0):
        raise ValueError(f"tol_gamma must be positive and finite, got {tol_gamma}")
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    if not (np.isfinite(cutoff) and cutoff > FAR_GROWTH):
        raise ValueError(f"cutoff must exceed {FAR_GROWTH} largest diameters, got {cutoff}")
    th = [t for t, _ in bound]
    if any(not (np.isfinite(v) and v > 0) for pair in bound for v in pair) or th != sorted(th, reverse=True):
        raise ValueError(f"bound schedule must be positive (threshold, bound) pairs with decreasing thresholds, got {bound}")
    if relax is not None and not (0.0 < relax <= 1.0):
        raise ValueError(f"relax must lie in (0, 1], got {relax}")
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
    if packing.n < 2:
        raise ValueError("CALiPPSO needs at least two particles")
    if walls:
        if not packing.box.is_orthogonal:
            raise ValueError("walls need an orthogonal box")
        rad = 0.5 * packing.diameter[:, None]
        L = packing.box.lengths
        out = (packing.position < rad * (1 - OVERLAP_TOL)) | (packing.position > L - rad * (1 - OVERLAP_TOL))
        if np.any(out):
            bad = np.flatnonzero(out.any(axis=1))
            raise ValueError(f"{bad.size} sphere(s) cross a wall (e.g. index {bad[0]}); walls need every sphere inside the box")
    container = _Container(packing.box, walls)
    ov = container.max_overlap(container.packing(packing, packing.position, packing.diameter))
    if ov > OVERLAP_TOL:
        raise ValueError(f"input overlaps by {ov:.3g} (relative) > {OVERLAP_TOL:g}: CALiPPSO needs a hard-sphere start")

