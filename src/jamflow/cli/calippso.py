"""Subcommand ``calippso``: jam a hard-sphere packing by a chain of LPs (CALiPPSO)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..io import read_packing, write_dataset
from ..protocols.calippso import (
    CHECKPOINT_EVERY,
    CRASH_MIN_COLUMNS,
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
    DUAL_FALLBACK,
    FINISHES,
    FIRST_LPS,
    HIPO_MIN_COLUMNS,
    INTERIOR_POINTS,
    NEAR_START_GAP,
    SOLVER_TOL,
    SOLVERS,
    WARM_ENGINE_MIN_COLUMNS,
    WARM_ENGINES,
    ChainStopped,
    calippso,
    result_to_dataset,
)
from .common import (
    add_command,
    add_preset,
    add_quiet,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .types import UsageError, count, integer, path_with_suffix, positive, real

#: Exit code of a run stopped by ``--stop-after`` (its chain is in the checkpoint).
STOPPED: int = 3

#: Options that manage the run, not the chain (a resumed chain's output equals the uninterrupted one's).
RUN_ONLY: tuple[str, ...] = ("checkpoint", "checkpoint_every", "stop_after")


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "calippso", _calippso,
        "jam a hard-sphere packing exactly by a chain of linear programs (CALiPPSO)",
        description="CALiPPSO (Artiaco et al., PRE 106, 055310 (2022), Algorithm 1): inflate the "
                    "spheres and move them by successive LPs until sqrt(Gamma)-1 < tol-gamma and "
                    "max|s| < tol-s; contacts and forces from the LP duals; a degenerate (hyperstatic, "
                    "crystalline) packing stores its geometric contacts with minimum-norm balanced forces "
                    "(attribute force_assignment). Writes the jammed packing with the per-LP history.",
        reads=("packing",), writes=("out", "checkpoint"), packings=("out",),
        makes={"checkpoint": ("calippso-checkpoint",)},
    )
    p.add_argument("packing", help="input netCDF packing (no overlaps)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF jammed packing")
    p.add_argument("--tol-s", type=positive, default=DEFAULT_TOL_S,
                   help=f"convergence: largest stable displacement in mean diameters (default {DEFAULT_TOL_S:g})")
    p.add_argument("--tol-gamma", type=positive, default=DEFAULT_TOL_GAMMA,
                   help=f"convergence: sqrt(Gamma)-1 (default {DEFAULT_TOL_GAMMA:g})")
    p.add_argument("--solver", choices=SOLVERS, default=DEFAULT_SOLVER,
                   help=f"HiGHS strategy (default {DEFAULT_SOLVER})")
    p.add_argument("--solver-tol", type=positive, default=SOLVER_TOL,
                   help=f"HiGHS feasibility/optimality tolerance of the scaled rows, 1e-10..2e-8 (default {SOLVER_TOL:g})")
    p.add_argument("--cutoff", type=positive, default=DEFAULT_CUTOFF,
                   help="neighbour cutoff far from jamming, in largest diameters; unused by a start near jamming "
                        f"(median nearest gap below {NEAR_START_GAP:g} of the contact distance) (default {DEFAULT_CUTOFF})")
    p.add_argument("--cutoff-near", type=positive, default=DEFAULT_CUTOFF_NEAR,
                   help="neighbour cutoff close to jamming (last bound phase, unbounded LPs, every LP of a start near "
                        f"jamming), in largest diameters (default {DEFAULT_CUTOFF_NEAR})")
    p.add_argument("--bound", type=positive, nargs=2, default=None, metavar=("MID", "NEAR"),
                   help="displacement bounds in mean radii for 5e-4 >= sqrt(Gamma)-1 > 1e-5 and below "
                        "(default 0.1 0.01)")
    p.add_argument("--relax", type=real(0.0, 1.0, lo_open=True, need="a number c with 0 < c <= 1"), default=None,
                   help="Sec. IV relaxation: sigma <- sqrt(1 + c gamma) sigma with 0 < c <= 1 (default off)")
    p.add_argument("--walls", action="store_true", help="hard walls on the box faces instead of periodic boundaries")
    p.add_argument("--max-iterations", type=count, default=DEFAULT_MAX_ITERATIONS,
                   help=f"largest number of LPs (default {DEFAULT_MAX_ITERATIONS})")
    p.add_argument("--threads", type=integer(1, os.cpu_count() or 1), default=1, help="HiGHS threads (default 1)")
    p.add_argument("--interior", choices=INTERIOR_POINTS, default=DEFAULT_INTERIOR,
                   help="HiGHS interior point method of the interior point LPs: ipx on the LP, or hipo on its "
                        "explicit dual (needs HiPO in highspy: highspy[extras]); auto takes hipo from "
                        f"{HIPO_MIN_COLUMNS} columns (d N + 1) on when highspy has it, else ipx "
                        f"(default {DEFAULT_INTERIOR})")
    p.add_argument("--warm-engine", choices=WARM_ENGINES, default=DEFAULT_WARM_ENGINE,
                   help="engine of the warm simplex LPs: highs, or jamflow (a simplex on a nested-dissection "
                        "sparse LU; HiGHS solves any LP it reports trouble on); auto takes jamflow from "
                        f"d N = {WARM_ENGINE_MIN_COLUMNS} on (default {DEFAULT_WARM_ENGINE})")
    p.add_argument("--first-lp", choices=FIRST_LPS, default=DEFAULT_FIRST_LP,
                   help="first LP of a start near jamming: highs (interior point with crossover), or crash "
                        "(jamflow.simplex from the start's smallest gaps; the interior point solves it after any "
                        f"trouble); auto takes crash from d N = {CRASH_MIN_COLUMNS} on (default {DEFAULT_FIRST_LP})")
    p.add_argument("--finish", choices=FINISHES, default=DEFAULT_FINISH,
                   help="newton: once the network is isostatic in the chain's tail, solve its square system by "
                        "Newton and keep it only if certified (positive forces, no overlap, same geometric "
                        f"network), else go on with LPs; lp: the pure LP chain (default {DEFAULT_FINISH})")
    p.add_argument("--checkpoint", type=path_with_suffix(".nc"), default=None,
                   help="checkpoint netCDF: written every --checkpoint-every seconds, resumed from if present (only "
                        "by the same input, options but --max-iterations, and jamflow version), removed once the "
                        "output is written; a resumed chain repeats the uninterrupted one bit for bit")
    p.add_argument("--checkpoint-every", type=real(0.0, need="a number of seconds >= 0"), default=CHECKPOINT_EVERY,
                   metavar="SECONDS", help=f"wall time between checkpoint writes (default {CHECKPOINT_EVERY:g})")
    p.add_argument("--stop-after", type=count, default=None, metavar="LPS",
                   help="stop this run after this many LPs, writing the checkpoint (resume later; needs --checkpoint)")
    add_quiet(p)
    add_preset(p)


def _calippso(args: argparse.Namespace) -> int:
    if args.stop_after is not None and args.checkpoint is None:
        raise UsageError("--stop-after needs --checkpoint (where the stopped chain is kept)")
    packing = read_packing(args.packing)
    if args.checkpoint and Path(args.checkpoint).exists() and not args.quiet:
        print(f"jamflow calippso: resuming from {args.checkpoint}", file=sys.stderr)
    kwargs = {}
    if args.bound is not None:
        kwargs["bound"] = ((5e-4, args.bound[0]), (1e-5, args.bound[1]))
    with progress_bar(args.quiet, desc="calippso", unit=" LP") as bar:
        def progress(rec) -> None:
            if rec.interior.startswith(DUAL_FALLBACK):
                bar.write(f"LP {rec.iteration}: HiPO on the dual reported {rec.interior[len(DUAL_FALLBACK):]!r}; "
                          "IPX solved the LP as it is")
            if rec.warm_fallback and rec.solver == "crash>ipm":
                bar.write(f"LP {rec.iteration}: jamflow.simplex from the crash basis reported {rec.warm_fallback!r}; "
                          "HiGHS's interior point solved it")
            elif rec.warm_fallback:
                bar.write(f"LP {rec.iteration}: jamflow.simplex reported {rec.warm_fallback!r}; HiGHS solved it "
                          "from the same basis")
            bar.update(1)
            bar.set_postfix(sqrtG_1=f"{rec.sqrt_gamma_minus_1:.2e}", s=f"{rec.max_displacement_stable:.2e}",
                            Nc=rec.n_contacts)

        try:
            result = calippso(
                packing, tol_s=args.tol_s, tol_gamma=args.tol_gamma, solver=args.solver, solver_tol=args.solver_tol,
                cutoff=args.cutoff, cutoff_near=args.cutoff_near, relax=args.relax, walls=args.walls,
                max_iterations=args.max_iterations, threads=args.threads, finish=args.finish, interior=args.interior,
                warm_engine=args.warm_engine, first_lp=args.first_lp, progress=progress, checkpoint=args.checkpoint,
                checkpoint_every=args.checkpoint_every, stop_after=args.stop_after, **kwargs,
            )
        except ChainStopped as stopped:
            print(f"jamflow calippso: {stopped}", file=sys.stderr)
            return STOPPED
    write_dataset(result_to_dataset(result, stage_parameters(args, "packing", "out", *RUN_ONLY)), args.out)
    if args.checkpoint and Path(args.checkpoint).exists():
        # the output is written: a finished chain's checkpoint could only be resumed by mistake
        Path(args.checkpoint).unlink()
    a = result.packing.attrs
    counting = "hyperstatic" if a["hyperstatic"] else "isostatic" if a["isostatic"] else "not isostatic"
    print_summary(args, args.out, [
        ("phi_J", f"{a['phi_J']:.10f}"),
        ("LPs", f"{a['n_lps']} (converged {bool(result.converged)}; "
                f"{'near-jamming start: near cutoff, interior point LPs without presolve' if a['near_start'] else 'far start'})"),
        ("warm LPs", (f"{a['warm_lps_jamflow']} by jamflow.simplex, {a['warm_fallbacks']} of its attempts re-solved "
                      f"by HiGHS after trouble ({a['warm_fallback_reasons']}); LU by {a['warm_lu']}")),
        ("first LP", f"{a['first_lp']} ({a['first_lp_fallbacks']} crash attempt(s) re-solved by the interior point)"),
        ("interior point LPs", f"{a['interior_lps']} ({a['interior_fallbacks']} HiPO dual attempt(s) re-solved by IPX)"),
        ("finish", f"{a['finish']} ({a['newton_attempts']} Newton attempt(s) in {a['newton_time']:.2f} s, "
                   f"{a['newton_rejections']} rejected, last because: {a['newton_last_rejection']})"),
        ("contacts N_c", f"{a['n_contacts']} (isostatic count d(N_s-1)+1 = {a['isostatic_count']}: {counting})"),
        ("rattlers", a["n_rattlers"]),
        ("forces", f"{a['force_assignment']} ({a['n_contacts_dual']} contacts carry a dual at the LP vertex, "
                   f"{a['n_contacts_geometric']} backbone contacts have gap <= {a['contact_gap_tol']:g}, "
                   f"{a['n_zero_force_contacts']} stored contacts have zero force)"),
        ("max overlap", f"{a['max_overlap']:.3g} (relative)"),
        ("force-balance residual", f"{a['force_balance_residual']:.3g}"),
        ("time", f"{a['total_time']:.1f} s"),
    ])
    return 0
