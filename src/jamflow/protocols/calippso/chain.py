"""The chain of LPs, Algorithm 1 of the paper line by line, and its entry point :func:`calippso`."""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

from ...stages import require
from ...state.packing import Packing
from ...tolerances import OVERLAP_TOL
from .checkpoint import (
    CHECKPOINT_EVERY,
    ChainStopped,
    chain_binding,
    load_checkpoint,
    save_checkpoint,
)
from .container import _Container
from .lp import _near_start
from .network import _dual_network, _final_checks, _Network
from .newton import _finish_by_newton, _newton_ready
from .options import (
    DEFAULT_BOUND_SCHEDULE,
    DEFAULT_CUTOFF,
    DEFAULT_CUTOFF_NEAR,
    DEFAULT_FINISH,
    DEFAULT_FIRST_LP,
    DEFAULT_INTERIOR,
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_SOLVER,
    DEFAULT_TOL_GAMMA,
    DEFAULT_TOL_S,
    DEFAULT_WARM_ENGINE,
    SOLVER_TOL,
    _crash_first,
    _engine_of_warm_lps,
    _Options,
)
from .record import CalippsoResult, IterationRecord, _diagnose, _result
from .recovery import (
    FINAL_RECOVERY_METHODS,
    _check_stall,
    _final_recovery,
    _recover,
    _schedule_next,
)
from .solver import NEAR_START_PRESOLVE, _Solution, _Solver
from .state import _Chain, _LPSetup, _record, _Step
from .steps import _growth, _read_solution, _set_up_lp, _small, _update


def calippso(
    packing: Packing,
    *,
    tol_s: float = DEFAULT_TOL_S,
    tol_gamma: float = DEFAULT_TOL_GAMMA,
    solver: str = DEFAULT_SOLVER,
    solver_tol: float = SOLVER_TOL,
    cutoff: float = DEFAULT_CUTOFF,
    cutoff_near: float = DEFAULT_CUTOFF_NEAR,
    bound: tuple[tuple[float, float], ...] = DEFAULT_BOUND_SCHEDULE,
    relax: float | None = None,
    walls: bool = False,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    require_isostatic: bool = True,
    threads: int = 1,
    finish: str = DEFAULT_FINISH,
    interior: str = DEFAULT_INTERIOR,
    warm_engine: str = DEFAULT_WARM_ENGINE,
    first_lp: str = DEFAULT_FIRST_LP,
    progress: Callable[[IterationRecord], None] | None = None,
    checkpoint: str | os.PathLike | None = None,
    checkpoint_every: float = CHECKPOINT_EVERY,
    stop_after: int | None = None,
) -> CalippsoResult:
    """Jam ``packing`` by CALiPPSO (Algorithm 1), see :mod:`jamflow.protocols.calippso`.

    Parameters
    ----------
    packing : Packing
        Non-overlapping start (relative overlap at most ``OVERLAP_TOL``); periodic, or
        with ``walls=True`` an orthogonal box whose faces are hard walls and every
        sphere inside (``sigma_i / 2 <= x_{i,mu} <= L_mu - sigma_i / 2``).
    tol_s : float
        Convergence: largest displacement of a stable particle in the last LP
        [mean diameters].
    tol_gamma : float
        Convergence: ``sqrt(Gamma*) - 1`` of the last LP (dimensionless).
    solver : {"ipm", "simplex", "hybrid", "ipm-center"}
        See :data:`SOLVERS`.
    solver_tol : float
        HiGHS primal/dual feasibility and interior point optimality tolerance, in
        units of the scaled rows (~2x relative gap), between :data:`MIN_SOLVER_TOL`
        and :data:`MAX_SOLVER_TOL`.
    cutoff : float
        Neighbour cutoff ``ell`` [current largest diameters] far from jamming, > 1.2.
    cutoff_near : float
        Cutoff in the last bound phase, for unbounded LPs and for every LP of a start
        near jamming (:data:`NEAR_START_GAP`) [current largest diameters].
    bound : tuple of (threshold, bound)
        Bound schedule: below each ``sqrt(Gamma*) - 1`` threshold the displacement
        bound (per coordinate) becomes ``bound`` mean radii; above the first threshold
        it is derived from the cutoff. The converging LP is always unbounded.
    relax : float or None
        Sec. IV relaxation ``sigma <- sqrt(1 + c g*) sigma`` with ``c = relax`` in (0, 1].
    walls : bool
        Hard walls on the box faces instead of periodic boundaries. A packing whose
        boundary is already walls (body kind ``walls``, e.g. ``init --walls``) is always
        jammed between them.
    max_iterations : int
        Largest number of LPs.
    require_isostatic : bool
        Raise when the converged network is neither isostatic nor the App. A
        hyperstatic case; False returns it with ``converged`` and the flags set.
    threads : int
        HiGHS threads.
    finish : {"newton", "lp"}
        How the chain ends, see :data:`FINISHES`.
    interior : {"auto", "ipx", "hipo"}
        HiGHS interior point method of the interior point LPs, see :data:`INTERIOR_POINTS`.
    warm_engine : {"auto", "highs", "jamflow"}
        Engine of the warm simplex LPs, see :data:`WARM_ENGINES`.
    first_lp : {"auto", "highs", "crash"}
        The first LP of a start near jamming, see :data:`FIRST_LPS`.
    progress : callable, optional
        Called with each :class:`IterationRecord`.
    checkpoint : path-like, optional
        Checkpoint netCDF (:mod:`.checkpoint`): resumed from when it exists (only one of
        the same start, options but ``max_iterations``, and jamflow code), written at the
        top of an LP once ``checkpoint_every`` seconds have passed since the last write.
        A resumed chain repeats the uninterrupted one bit for bit. Left in place at the end.
    checkpoint_every : float
        Wall time [s] between checkpoint writes (0: before every LP but the first).
    stop_after : int, optional
        LP budget of this call: after this many LPs the checkpoint is written and
        :class:`~.checkpoint.ChainStopped` raised (needs ``checkpoint``).

    Returns
    -------
    CalippsoResult

    Raises
    ------
    ValueError
        Bad input (overlaps, walls crossing particles, bad options).
    RuntimeError
        The chain did not converge, or the converged network failed its checks after
        the recoveries.
    ChainStopped
        ``stop_after`` LPs were solved; the chain is in ``checkpoint``.
    """
    require("calippso", packing.body_kind)
    opt = _Options(tol_s=tol_s, tol_gamma=tol_gamma, solver=solver, solver_tol=solver_tol, cutoff=cutoff,
                   cutoff_near=cutoff_near, bound=bound, relax=relax, walls=walls or packing.body_kind == "walls",
                   max_iterations=max_iterations, require_isostatic=require_isostatic, threads=threads,
                   finish=finish, interior=interior, warm_engine=warm_engine, first_lp=first_lp)
    opt.check(packing)
    if stop_after is not None and (checkpoint is None or stop_after < 1):
        raise ValueError(f"stop_after must be a positive LP count with a checkpoint, got {stop_after} "
                         f"(checkpoint {checkpoint})")
    if not checkpoint_every >= 0:
        raise ValueError(f"checkpoint_every must be >= 0 seconds, got {checkpoint_every}")
    t_start = time.perf_counter()
    container = _Container(packing.box, opt.walls)
    chain = _Chain(x=packing.position.copy() if opt.walls else packing.box.wrap(packing.position),
                   D=packing.diameter.copy())
    lp_solver = _Solver(threads, solver_tol, interior, _engine_of_warm_lps(warm_engine, packing.d * packing.n))
    lp_solver.cold_simplex_as_ipm = solver == "hybrid"  # a cold simplex is slower than ipm
    chain.near_start = _near_start(chain.x, chain.D, container)
    if chain.near_start:
        lp_solver.ipm_presolve = NEAR_START_PRESOLVE
        lp_solver.crash_first = _crash_first(first_lp, packing.d * packing.n)
    first, save = 1, None
    if checkpoint is not None:
        binding = chain_binding(packing, opt)
        if os.path.exists(checkpoint):
            first, elapsed = load_checkpoint(checkpoint, chain, lp_solver, binding)
            t_start -= elapsed
        save = _Saver(checkpoint, checkpoint_every, chain, lp_solver, t_start, binding)
    network, converged = _run_chain(chain, lp_solver, container, opt, packing, progress, first, save, stop_after)
    total = time.perf_counter() - t_start
    if network is None:
        raise RuntimeError(_diagnose(f"not converged in {max_iterations} LPs", chain.records))
    if not converged and require_isostatic:
        raise RuntimeError(_diagnose(f"converged LP failed the final checks: {network.why}", chain.records))
    return _result(packing, chain, container, network, converged, total, opt.settings())


class _Saver:
    """Writes the chain's checkpoint at the top of an LP when due (every ``every`` seconds)."""

    def __init__(self, path: str | os.PathLike, every: float, chain: _Chain, solver: _Solver, t_start: float,
                 binding: dict[str, str]) -> None:
        self.path, self.every, self.chain, self.solver = path, every, chain, solver
        self.t_start, self.binding = t_start, binding
        self.last = time.perf_counter()

    def __call__(self, it: int, force: bool = False) -> None:
        now = time.perf_counter()
        if force or now - self.last >= self.every:
            save_checkpoint(self.path, it, self.chain, self.solver, now - self.t_start, self.binding)
            self.last = time.perf_counter()


def _run_chain(chain: _Chain, lp_solver: _Solver, container: _Container, opt: _Options, packing: Packing,
               progress: Callable[[IterationRecord], None] | None, first: int = 1, save: _Saver | None = None,
               stop_after: int | None = None) -> tuple[_Network | None, bool]:
    """Algorithm 1, lines 3-16, from LP ``first``: LPs until one converges and its network
    passes the final checks (or fails them for good), or the Newton finish is certified.
    ``save`` writes the checkpoint at the top of an LP; after ``stop_after`` LPs it is
    written and :class:`ChainStopped` raised.

    Returns the network of the jammed packing (None when ``opt.max_iterations`` LPs did
    not converge) and whether it passed the final checks; the chain holds its configuration.
    """
    d, n = packing.d, packing.n
    for it in range(first, opt.max_iterations + 1):
        if save is not None and it > first:
            if stop_after is not None and it - first >= stop_after:
                save(it, force=True)
                raise ChainStopped(f"stopped after {it - first} LP(s) of this run (LP {it - 1} of the chain); "
                                   f"{save.path} holds the chain: run again with it to resume")
            save(it)
        lp = _set_up_lp(chain, container, opt, d, n)  # lines 4-7
        sol = lp_solver.solve(lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper, lp.method, lp.rows)  # line 8
        if sol.col is None:
            _record(chain, progress, _failed_record(it, lp, sol))
            _recover(chain, f"LP status {sol.status!r}")
            continue
        step = _read_solution(lp, sol.col, sol.dual, container, d, n)  # lines 9-11
        overlap = _update_overlap(chain, step, lp, opt, container, packing)
        accepted = overlap <= OVERLAP_TOL
        _record(chain, progress, _lp_record(it, lp, sol, step, accepted))
        if not accepted:
            _recover(chain, f"update overlaps by {overlap:.3g} (relative)")
            continue
        _update(chain, step, lp, opt, container, n)  # lines 12-13
        if opt.finish == "newton" and _newton_ready(chain, step, lp, n):
            network = _finish_by_newton(chain, step, lp, opt, container, packing, progress)
            if network is not None:
                return network, True
        if _small(step, opt) and np.isinf(lp.bound):  # line 15, certified by an unbounded LP
            network = _dual_network(step, lp, chain.x, container, d, n)
            converged, network.why = _final_checks(packing, chain.x, chain.D, container, network)
            if converged or not opt.require_isostatic or chain.final_attempts >= len(FINAL_RECOVERY_METHODS):
                return network, converged
            _final_recovery(chain)
            continue
        _schedule_next(chain, step, lp, opt)
        _check_stall(chain)
    return None, False


def _update_overlap(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options, container: _Container,
                    packing: Packing) -> float:
    """Largest relative overlap over ALL pairs (and walls) after the update the LP proposes."""
    return container.max_overlap(container.packing(
        packing, chain.x + step.u * lp.unit, chain.D * _growth(step.g, opt.relax)))


def _lp_record(it: int, lp: _LPSetup, sol: _Solution, step: _Step, accepted: bool) -> IterationRecord:
    """The history entry of a solved LP."""
    return IterationRecord(
        iteration=it, sqrt_gamma_minus_1=step.sg, max_displacement=step.max_s,
        max_displacement_stable=step.max_s_stable, n_constraints=len(lp.rows), n_contacts=step.n_c,
        n_stable=step.n_s, isostatic=step.iso, lp_status=sol.status, lp_time=sol.seconds, solver=sol.method,
        cutoff=lp.ell / lp.sig_max, bound=lp.bound, min_active_dual=step.min_active_dual,
        max_inactive_dual=step.max_inactive_dual, accepted=accepted, warm_start=sol.warm,
        simplex_iterations=sol.simplex_iterations, ipm_iterations=sol.ipm_iterations, engine=sol.engine,
        warm_fallback=sol.fallback, warm_lu=sol.lu, interior=sol.interior)


def _failed_record(it: int, lp: _LPSetup, sol: _Solution) -> IterationRecord:
    """The history entry of an LP without an optimal solution."""
    return IterationRecord(
        iteration=it, sqrt_gamma_minus_1=np.nan, max_displacement=np.nan, max_displacement_stable=np.nan,
        n_constraints=len(lp.rows), n_contacts=0, n_stable=0, isostatic=False, lp_status=sol.status,
        lp_time=sol.seconds, solver=sol.method, cutoff=lp.ell / lp.sig_max, bound=lp.bound,
        min_active_dual=np.nan, max_inactive_dual=np.nan, accepted=False, warm_start=sol.warm,
        simplex_iterations=sol.simplex_iterations, ipm_iterations=sol.ipm_iterations, engine=sol.engine,
        warm_fallback=sol.fallback, warm_lu=sol.lu, interior=sol.interior)
