"""CALiPPSO's warm LPs: capture them from real chains, and solve them by HiGHS and by
jamflow's own bounded simplex (:mod:`jamflow.simplex`) from the same carried basis.

Two steps, each one command:

``capture``
    Runs ``jamflow.protocols.calippso.calippso`` on near starts (LS to p = 1e7 at kappa = 1e-3, cached by
    ``benchmarks/calippso.py``: ``near_start``) and the authors' LS examples, and saves
    every warm simplex LP as HiGHS gets it, with what HiGHS made of it:
    ``OUT/warm_lps/<start>/lp_<k>.npz`` holds the matrix ``A`` (CSC arrays), ``rhs``,
    ``col_lower``, ``col_upper``, the carried basis (``col_status``, ``row_status``,
    HiGHS's codes), and HiGHS's answer: model status, ``col_value``, ``row_dual``,
    ``col_dual``, the optimal basis, pivots and wall time [s]. The chain itself runs
    unchanged with ``warm_engine="highs"`` (the capture wraps ``_Solver._run``, the chain's
    one HiGHS call; ``auto`` would hand the warm LPs of d N >= 4096 to jamflow.simplex).
``compare``
    For every captured LP (or a sample of them per start): HiGHS's warm primal simplex
    from the carried basis as the chain runs it, and ``jamflow.simplex`` from the same
    basis, alternated in one process; wall times, pivots, the starting basis's
    factorisation time, and the agreement: ``g`` (relative), the active set (rows with a
    dual above ``CONTACT_DUAL_REL_TOL`` of the largest) and the duals (largest
    difference over the largest dual). Writes ``OUT/warm_lp.nc`` and ``OUT/warm_lp.png``.

Run: ``python benchmarks/warm_lp.py capture --sizes 1024 2048 --seeds 1 2`` then
``python benchmarks/warm_lp.py compare``.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import highspy
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
import xarray as xr

import jamflow.protocols.calippso.solver as cal_solver
from jamflow import simplex
from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.protocols.calippso import CONTACT_DUAL_REL_TOL, SOLVER_TOL, calippso
from jamflow.protocols.calippso.lp import _highs_lp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calippso import FAST_KAPPA, OUT, ls_example, near_start

CAPTURE = OUT / "warm_lps"


@dataclass(frozen=True)
class WarmLP:
    """One captured warm LP: ``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper``
    (``g`` the last column), the basis the chain carried to it and HiGHS's answer."""

    A: sp.csc_matrix
    rhs: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    col_status: np.ndarray  # carried basis, HiGHS codes (0 lower, 1 basic, 2 upper, 3 zero, 4 nonbasic)
    row_status: np.ndarray
    status: str  # HiGHS model status of the chain's solve
    col_value: np.ndarray
    row_dual: np.ndarray  # HiGHS's sign: <= 0 for a tight row of a minimisation
    col_dual: np.ndarray
    opt_col_status: np.ndarray
    opt_row_status: np.ndarray
    pivots: int
    seconds: float
    alien: bool  # HiGHS's flag of the carried basis (alien: rows rebuilt, setBasis factorises)
    path: Path

    @property
    def g(self) -> float:
        return float(self.col_value[-1])


def save(path: Path, lp: highspy.HighsLp, basis, h: highspy.Highs, status, seconds: float) -> None:
    a = lp.a_matrix_
    sol, opt = h.getSolution(), h.getBasis()
    info = h.getInfo()
    np.savez(path, indptr=np.asarray(a.start_), indices=np.asarray(a.index_), data=np.asarray(a.value_),
             shape=np.array([lp.num_row_, lp.num_col_]), rhs=np.asarray(lp.row_upper_),
             col_lower=np.asarray(lp.col_lower_), col_upper=np.asarray(lp.col_upper_),
             col_status=np.array([int(v) for v in basis.col_status], np.int8),
             row_status=np.array([int(v) for v in basis.row_status], np.int8),
             status=h.modelStatusToString(status), col_value=np.asarray(sol.col_value),
             row_dual=np.asarray(sol.row_dual), col_dual=np.asarray(sol.col_dual),
             opt_col_status=np.array([int(v) for v in opt.col_status], np.int8),
             opt_row_status=np.array([int(v) for v in opt.row_status], np.int8),
             pivots=int(info.simplex_iteration_count), seconds=seconds, alien=bool(basis.alien))


def save_ours(path: Path, A: sp.spmatrix, rhs, col_lower, col_upper, col_status, row_status,
              r: simplex.Result, seconds: float) -> None:
    """A warm LP as the chain hands it to :func:`jamflow.simplex.solve`, in :func:`save`'s
    format, with jamflow.simplex's answer in place of HiGHS's (``compare`` solves it by
    HiGHS afresh)."""
    a = sp.csc_matrix(A)
    np.savez(path, indptr=a.indptr, indices=a.indices, data=a.data, shape=np.array(a.shape), rhs=np.asarray(rhs),
             col_lower=np.asarray(col_lower), col_upper=np.asarray(col_upper),
             col_status=np.asarray(col_status, np.int8), row_status=np.asarray(row_status, np.int8),
             status="Optimal" if r.optimal else r.status, col_value=r.col_value, row_dual=r.row_dual,
             col_dual=r.col_dual, opt_col_status=r.col_status, opt_row_status=r.row_status, pivots=r.stats.pivots,
             seconds=seconds, alien=False)


def load(path: Path) -> WarmLP:
    z = np.load(path)
    m, n = (int(v) for v in z["shape"])
    A = sp.csc_matrix((z["data"], z["indices"], z["indptr"]), shape=(m, n))
    return WarmLP(A, z["rhs"], z["col_lower"], z["col_upper"], z["col_status"].astype(np.int64),
                  z["row_status"].astype(np.int64), str(z["status"]), z["col_value"], z["row_dual"], z["col_dual"],
                  z["opt_col_status"].astype(np.int64), z["opt_row_status"].astype(np.int64), int(z["pivots"]),
                  float(z["seconds"]), bool(z["alien"]) if "alien" in z else False, path)


class Enough(Exception):
    """Enough warm LPs were captured: the chain stops."""


def capture_ours(start: Path, tag: str, max_warm: int) -> int:
    """Run the chain on ``start`` with ``warm_engine="jamflow"``; save the first ``max_warm``
    warm LPs that jamflow.simplex solves (with its answer, :func:`save_ours`) under
    ``CAPTURE/tag``. No HiGHS warm LP runs: for N where HiGHS's chain is slow. Returns how
    many were saved."""
    folder = CAPTURE / tag
    folder.mkdir(parents=True, exist_ok=True)
    solve = simplex.solve
    count = [0]

    def capturing_solve(A, rhs, col_lower, col_upper, cost, col_status, row_status, *args, **kw):
        t0 = time.process_time()
        r = solve(A, rhs, col_lower, col_upper, cost, col_status, row_status, *args, **kw)
        if kw.get("held") is None:
            count[0] += 1
            save_ours(folder / f"lp_{count[0]:04d}.npz", A, rhs, col_lower, col_upper, col_status, row_status, r,
                      time.process_time() - t0)
            print(f"{tag}: warm LP {count[0]}: {r.status}, {r.stats.pivots} pivots, "
                  f"{time.process_time() - t0:.1f} s CPU", flush=True)
            if count[0] >= max_warm:
                raise Enough
        return r

    simplex.solve = capturing_solve
    t0 = time.perf_counter()
    try:
        res = calippso(read_packing(start), warm_engine="jamflow")
        print(f"{tag}: chain of {res.iterations} LPs done in {time.perf_counter() - t0:.1f} s, {count[0]} warm LPs",
              flush=True)
    except Enough:
        print(f"{tag}: stopped after {count[0]} warm LPs ({time.perf_counter() - t0:.1f} s)", flush=True)
    finally:
        simplex.solve = solve
    return count[0]


def capture(start: Path, tag: str, max_warm: int) -> int:
    """Run the chain on ``start``; save its first ``max_warm`` warm simplex LPs under
    ``CAPTURE/tag``. Returns how many were saved."""
    folder = CAPTURE / tag
    folder.mkdir(parents=True, exist_ok=True)
    run = cal_solver._Solver._run
    count = [0]

    def capturing_run(self, lp, method, basis):
        status, seconds = run(self, lp, method, basis)
        if basis is not None and method == "simplex":
            count[0] += 1
            save(folder / f"lp_{count[0]:04d}.npz", lp, basis, self.h, status, seconds)
            if count[0] >= max_warm:
                raise Enough
        return status, seconds

    cal_solver._Solver._run = capturing_run
    t0 = time.perf_counter()
    try:
        res = calippso(read_packing(start), warm_engine="highs")  # every warm LP goes through _run
        print(f"{tag}: chain of {res.iterations} LPs done in "
              f"{time.perf_counter() - t0:.1f} s, {count[0]} warm LPs", flush=True)
    except Enough:
        print(f"{tag}: stopped after {count[0]} warm LPs ({time.perf_counter() - t0:.1f} s)", flush=True)
    finally:
        cal_solver._Solver._run = run
    return count[0]


def captured(tag: str) -> list[Path]:
    return sorted((CAPTURE / tag).glob("lp_*.npz"))


def highs_solve(w: WarmLP) -> tuple[float, float, int, str, np.ndarray, np.ndarray]:
    """HiGHS's warm primal simplex from the carried basis, set up as the chain's
    ``_Solver._run`` does: wall and CPU time of ``setBasis`` + ``run`` [s] (``setBasis``
    factorises an alien basis), pivots, status, columns and row duals."""
    solver = cal_solver._Solver()
    h = solver.h
    lp = _highs_lp(w.A, w.rhs, w.col_lower, w.col_upper)
    h.clearSolver()
    h.setOptionValue("solver", "simplex")
    h.setOptionValue("simplex_strategy", 4)
    h.setOptionValue("presolve", cal_solver._HIGHS_PRESOLVE)
    h.setOptionValue("simplex_scale_strategy", cal_solver.WARM_SIMPLEX_SCALE)
    h.setOptionValue("simplex_iteration_limit", max(int(cal_solver.WARM_PIVOTS_PER_ROW * lp.num_row_), 1))
    h.passModel(lp)
    basis = highspy.HighsBasis()
    basis.col_status = [highspy.HighsBasisStatus(int(v)) for v in w.col_status]
    basis.row_status = [highspy.HighsBasisStatus(int(v)) for v in w.row_status]
    basis.valid = True
    basis.alien = w.alien
    t0, c0 = time.perf_counter(), time.process_time()
    h.setBasis(basis)
    h.run()
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    sol = h.getSolution()
    return (seconds, cpu, int(h.getInfo().simplex_iteration_count), h.modelStatusToString(h.getModelStatus()),
            np.asarray(sol.col_value), np.asarray(sol.row_dual))


def ours_solve(w: WarmLP, **options) -> tuple[float, float, simplex.Result]:
    """:func:`jamflow.simplex.solve` from the carried basis at the chain's tolerances:
    wall and CPU time [s] and the result."""
    cost = np.zeros(w.A.shape[1])
    cost[-1] = -1.0
    tol = simplex.Tolerances(primal=SOLVER_TOL, dual=SOLVER_TOL)
    t0, c0 = time.perf_counter(), time.process_time()
    r = simplex.solve(w.A, w.rhs, w.col_lower, w.col_upper, cost, w.col_status, w.row_status, tol, **options)
    return time.perf_counter() - t0, time.process_time() - c0, r


def agreement(w: WarmLP, col: np.ndarray, row_dual: np.ndarray, col_ref: np.ndarray,
              row_dual_ref: np.ndarray) -> dict[str, float]:
    """How an answer compares with a reference answer to the same LP: ``Gamma* = 1 + g``
    (relative difference), the active sets (rows whose dual exceeds
    ``CONTACT_DUAL_REL_TOL`` of the largest; size of the symmetric difference), the duals
    (largest difference over the largest reference dual), and each answer's own
    residuals: the largest row violation and the dual residual ``|A^T mu - e_g|`` over the
    columns off their bounds."""
    mu, mu_ref = -row_dual, -row_dual_ref
    act = mu > CONTACT_DUAL_REL_TOL * mu.max()
    act_ref = mu_ref > CONTACT_DUAL_REL_TOL * mu_ref.max()
    e_g = np.zeros(w.A.shape[1])
    e_g[-1] = 1.0
    off = (col_ref > w.col_lower) & (col_ref < w.col_upper)

    def residuals(z, m):
        return float((w.A @ z - w.rhs).max()), float(np.abs((w.A.T @ m - e_g)[off]).max())

    viol, dres = residuals(col, mu)
    viol_ref, dres_ref = residuals(col_ref, mu_ref)
    return dict(gamma_rel=abs(col[-1] - col_ref[-1]) / (1.0 + col_ref[-1]),
                g_rel=abs(col[-1] - col_ref[-1]) / max(abs(col_ref[-1]), 1e-300),
                active_diff=float(np.sum(act != act_ref)), dual_diff=float(np.abs(mu - mu_ref).max() / mu_ref.max()),
                violation=viol, violation_ref=viol_ref, dual_residual=dres, dual_residual_ref=dres_ref)


FIELDS = ("N", "highs_time", "highs_cpu", "highs_pivots", "ours_time", "ours_cpu", "ours_pivots", "ours_dual_pivots", "ours_flips",
          "ours_factor", "ours_order", "ours_ftran", "ours_btran", "ours_ratio", "ours_factorisations", "fill",
          "rows", "gamma_rel", "g_rel", "active_diff", "dual_diff", "violation", "violation_ref", "dual_residual",
          "dual_residual_ref", "ours_optimal")
UNITS = {"highs_time": "s", "ours_time": "s", "highs_cpu": "s", "ours_cpu": "s", "ours_factor": "s", "ours_order": "s", "ours_ftran": "s",
         "ours_btran": "s", "ours_ratio": "s"}


def particles(tag: str) -> int:
    """N of a captured chain from its tag (the authors' LS examples have N = 1024)."""
    found = re.search(r"_N(\d+)_", tag)
    return int(found.group(1)) if found else 1024


def compare(tags: list[str], max_lps: int, every: int, options: dict) -> xr.Dataset:
    """HiGHS and :mod:`jamflow.simplex` on the first ``max_lps`` captured LPs of ``tags``
    (every ``every``-th), alternating which runs first."""
    rows, names = [], []
    for tag in tags:
        for count, path in enumerate(captured(tag)[:max_lps:every]):
            w = load(path)
            runs = {}
            for which in (("highs", "ours") if count % 2 == 0 else ("ours", "highs")):
                runs[which] = highs_solve(w) if which == "highs" else ours_solve(w, **options)
            t_h, c_h, piv_h, status_h, col_h, dual_h = runs["highs"]
            t_o, c_o, r = runs["ours"]
            st = r.stats
            row = dict(N=particles(tag), highs_time=t_h, highs_cpu=c_h, highs_pivots=piv_h, ours_time=t_o,
                       ours_cpu=c_o,
                       ours_pivots=st.pivots, ours_dual_pivots=st.dual_pivots, ours_flips=st.flips,
                       ours_factor=st.seconds["factor"], ours_order=st.seconds["order"],
                       ours_ftran=st.seconds["ftran"], ours_btran=st.seconds["btran"], ours_ratio=st.seconds["ratio"],
                       ours_factorisations=st.factorisations, fill=st.fill, rows=w.A.shape[0],
                       ours_optimal=float(r.optimal))
            row.update(agreement(w, r.col_value, r.row_dual, col_h, dual_h) if r.optimal and status_h == "Optimal"
                       else dict.fromkeys(FIELDS[17:25], np.nan))
            rows.append(row)
            names.append(f"{tag}/{path.stem}")
            print(f"{names[-1]}: HiGHS {t_h:.3f} s (cpu {c_h:.3f}) {piv_h} pivots | ours {r.status} {t_o:.3f} s "
                  f"(cpu {c_o:.3f}) "
                  f"{st.pivots} pivots ({st.dual_pivots} dual, {st.flips} flips; {st.lu} factor "
                  f"{st.seconds['factor']:.3f} s x{st.factorisations}, {st.transposed_lus} of W^T, {st.superlu_fallbacks} by SuperLU) | Gamma {row['gamma_rel']:.1e} active {row['active_diff']:.0f} "
                  f"duals {row['dual_diff']:.1e} (residuals {row['dual_residual']:.1e} / {row['dual_residual_ref']:.1e})",
                  flush=True)
    data = {f: (("lp",), np.array([r[f] for r in rows], float), {"units": UNITS.get(f, "1")}) for f in FIELDS}
    return xr.Dataset(data, coords={"lp": names}, attrs=new_dataset_attrs(
        "CALiPPSO warm LPs: HiGHS against jamflow.simplex from the same basis", {"tags": tags, **options}))


def plot(ds: xr.Dataset) -> None:
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for n, m in zip(np.unique(ds["N"].values), "os^Dv"):
        sel = ds.where(ds["N"] == n, drop=True)
        ax[0].loglog(sel["highs_time"], sel["ours_time"], m, ms=4, alpha=0.7, label=f"N = {n:.0f}")
    lim = [float(min(ds["highs_time"].min(), ds["ours_time"].min())) / 1.5,
           float(max(ds["highs_time"].max(), ds["ours_time"].max())) * 1.5]
    ax[0].loglog(lim, lim, "k:", label="equal")
    ax[0].loglog(lim, np.array(lim) / 2, "k--", lw=0.8, label="2x faster")
    ax[0].set_xlabel("HiGHS warm LP time [s]")
    ax[0].set_ylabel("jamflow.simplex warm LP time [s]")
    ax[0].set_title("same LP, same starting basis")
    ax[0].legend(fontsize=8)
    sizes = np.unique(ds["N"].values)
    def med(k):
        return [float(ds[k].where(ds["N"] == n, drop=True).median()) for n in sizes]

    ax[1].loglog(sizes, med("highs_time"), "o-", label="HiGHS (median LP)")
    ax[1].loglog(sizes, med("ours_time"), "s-", label="jamflow.simplex (median LP)")
    ax[1].loglog(sizes, med("ours_factor"), "s--", label="  of which factorisation")
    ax[1].set_xticks(sizes, [f"{n:.0f}" for n in sizes])
    ax[1].set_xlabel("particles N (3D near starts)")
    ax[1].set_ylabel("time per warm LP [s]")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "warm_lp.png", dpi=120)
    print(f"wrote {OUT / 'warm_lp.png'}")


def carried(tags: list[str]) -> xr.Dataset:
    """What the carried basis of each captured LP keeps: rows and bounds its vertex
    violates by more than ``SOLVER_TOL`` (primal infeasibilities), members of its working
    set whose multiplier has the wrong sign by more than ``SOLVER_TOL`` (dual
    infeasibilities), and how many members HiGHS's optimal working set replaces."""
    from jamflow.simplex import _kernels
    from jamflow.simplex.state import State, Tolerances

    rows, names = [], []
    for tag in tags:
        for path in captured(tag):
            w = load(path)
            cost = np.zeros(w.A.shape[1])
            cost[-1] = -1.0
            st = State(w.A, w.rhs, w.col_lower, w.col_upper, cost, Tolerances(), None, "metis")
            st.set_working_set(w.col_status, w.row_status)
            st.refactor()
            infeas = np.empty(st.n)
            _kernels.dual_infeasibility(st.y, st.side, infeas)
            primal = int(np.sum((st.row_slot < 0) & (st.s < -SOLVER_TOL))
                         + np.sum((st.col_slot < 0) & ((st.z < st.lower - SOLVER_TOL) | (st.z > st.upper + SOLVER_TOL))))
            m = w.A.shape[0]
            before = set(np.flatnonzero(w.row_status != 1)) | set(m + np.flatnonzero(w.col_status != 1))
            after = set(np.flatnonzero(w.opt_row_status != 1)) | set(m + np.flatnonzero(w.opt_col_status != 1))
            rows.append((particles(tag), primal, int(np.sum(infeas > SOLVER_TOL)), len(before - after), w.pivots))
            names.append(f"{tag}/{path.stem}")
            print(names[-1], "primal infeasible", primal, "dual infeasible", rows[-1][2], "replaced", rows[-1][3],
                  "HiGHS pivots", w.pivots, flush=True)
    fields = ("N", "primal_infeasible", "dual_infeasible", "replaced", "highs_pivots")
    data = {f: (("lp",), np.array([r[k] for r in rows], float), {"units": "1"}) for k, f in enumerate(fields)}
    return xr.Dataset(data, coords={"lp": names}, attrs=new_dataset_attrs(
        "CALiPPSO warm LPs: feasibility of the carried basis", {"tags": tags}))


#: ``profile``: the leaf calls of jamflow.simplex timed by CPU, by part: (module, name, part).
#: Kernels are looked up through each module's ``k``; PARDISO's calls are methods.
PROFILED = (("factor", "eta_forward", "eta_forward"), ("factor", "eta_backward", "eta_backward"),
            ("factor", "lu_solve", "superlu_solve"), ("factor", "lu_solve_transposed", "superlu_solve"),
            ("state", "csr_matvec", "matvec"), ("warm", "primal_ratio", "ratio"), ("warm", "dual_ratio", "ratio"),
            ("warm", "most_violated", "ratio"), ("state", "most_violated", "ratio"),
            ("warm", "dual_infeasibility", "pricing"), ("state", "dual_infeasibility", "pricing"),
            ("warm", "devex_price", "pricing"), ("pricing", "sketch_update", "pricing"),
            ("pricing", "devex_update", "pricing"))
PARTS = ("factorise", "solve_N", "solve_T", "superlu_solve", "eta_forward", "eta_backward", "matvec", "ratio",
         "pricing", "other")


def _profiled(seconds: dict, calls: dict):
    """Patch jamflow.simplex's leaf calls with CPU timers adding into ``seconds`` and
    ``calls`` (by part); returns the undo."""
    import types

    from jamflow.simplex import _kernels, _pardiso, factor, pricing, state, warm

    mods = {"factor": factor, "state": state, "warm": warm, "pricing": pricing}
    saved = [(m, m.k) for m in mods.values()]
    spaces = {name: types.SimpleNamespace(**{f: getattr(_kernels, f) for f in dir(_kernels) if not f.startswith("_")})
              for name in mods}

    def timed(part, f):
        def g(*args, **kw):
            c0 = time.process_time()
            try:
                return f(*args, **kw)
            finally:
                seconds[part] += time.process_time() - c0
                calls[part] += 1
        return g

    for mod, fname, part in PROFILED:
        setattr(spaces[mod], fname, timed(part, getattr(_kernels, fname)))
    for name, m in mods.items():
        m.k = spaces[name]
    solve, fact = _pardiso.PardisoLU.solve, _pardiso.PardisoLU.factorise
    sl_fact = factor.Factor.factorise

    def psolve(self, b, transposed=False):
        return timed("solve_T" if transposed else "solve_N", solve)(self, b, transposed)

    _pardiso.PardisoLU.solve = psolve
    factor.Factor.factorise = timed("factorise", sl_fact)

    def undo():
        for m, kk in saved:
            m.k = kk
        _pardiso.PardisoLU.solve, _pardiso.PardisoLU.factorise = solve, fact
        factor.Factor.factorise = sl_fact
    return undo


def profile(tags: list[str], max_lps: int, every: int) -> xr.Dataset:
    """CPU time of :mod:`jamflow.simplex` on captured LPs split by part (:data:`PARTS`):
    the factorisations (PARDISO's analysis and factorisation, or SuperLU's with its
    ordering), PARDISO's solves with ``W`` and ``W^T`` (a block of right-hand sides
    counts as one call), SuperLU's numba solves, the product-form eta passes, ``A d``,
    the ratio tests, the pricing (dual infeasibilities, choice, weight updates) and
    the rest; with the pivots, solves and etas applied per transposed solve."""
    from collections import Counter, defaultdict

    ours_solve(load(captured(tags[0])[0]))  # loads the compiled kernels outside the timings
    rows, names = [], []
    for tag in tags:
        for path in captured(tag)[:max_lps:every]:
            w = load(path)
            seconds, calls = defaultdict(float), Counter()
            undo = _profiled(seconds, calls)
            try:
                _, cpu, r = ours_solve(w)
            finally:
                undo()
            st = r.stats
            row = {part: seconds[part] for part in PARTS[:-1]}
            row["other"] = cpu - sum(row.values())
            row.update(N=particles(tag), cpu=cpu, pivots=st.pivots, factorisations=st.factorisations, fill=st.fill,
                       transposed_lus=getattr(st, "transposed_lus", 0), superlu_lus=st.superlu_fallbacks,
                       solves_N=calls["solve_N"], solves_T=calls["solve_T"], optimal=float(r.optimal))
            rows.append(row)
            names.append(f"{tag}/{path.stem}")
            print(f"{names[-1]}: {r.status} {st.pivots} pivots, {st.factorisations} LUs ({getattr(st, 'transposed_lus', 0)} of W^T, "
                  f"{st.superlu_fallbacks} by SuperLU), CPU {cpu:.3f} s: " +
                  ", ".join(f"{k} {row[k]:.3f}" for k in PARTS) +
                  f" | per solve N {1e3 * row['solve_N'] / max(calls['solve_N'], 1):.2f} ms, "
                  f"T {1e3 * row['solve_T'] / max(calls['solve_T'], 1):.2f} ms", flush=True)
    fields = (*PARTS, "N", "cpu", "pivots", "factorisations", "transposed_lus", "superlu_lus", "fill", "solves_N",
              "solves_T", "optimal")
    data = {f: (("lp",), np.array([r[f] for r in rows], float), {"units": "s" if f in PARTS or f == "cpu" else "1"})
            for f in fields}
    return xr.Dataset(data, coords={"lp": names}, attrs=new_dataset_attrs(
        "jamflow.simplex on captured CALiPPSO warm LPs: CPU time by part", {"tags": tags, "every": every}))


def plot_profile(ds: xr.Dataset, path: Path) -> None:
    """CPU per LP by part (mean over the LPs of each N) and CPU per pivot of the per-pivot parts."""
    sizes = np.unique(ds["N"].values)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    x = np.arange(len(sizes))
    bottom = np.zeros(len(sizes))
    for part in PARTS:
        v = np.array([float(ds[part].where(ds["N"] == n, drop=True).mean()) for n in sizes])
        ax[0].bar(x, v, bottom=bottom, label=part)
        bottom += v
    ax[0].set_xticks(x, [f"{n:.0f}" for n in sizes])
    ax[0].set_xlabel("particles N (3D near starts)")
    ax[0].set_ylabel("CPU per warm LP [s] (mean)")
    ax[0].legend(fontsize=7)
    per_pivot = ("solve_N", "solve_T", "eta_backward", "matvec", "ratio", "pricing")
    width = 0.8 / len(per_pivot)
    for i, part in enumerate(per_pivot):
        v = [1e3 * float(ds[part].where(ds["N"] == n, drop=True).sum() / ds["pivots"].where(ds["N"] == n, drop=True).sum())
             for n in sizes]
        ax[1].bar(x + (i - len(per_pivot) / 2 + 0.5) * width, v, width, label=part)
    ax[1].set_xticks(x, [f"{n:.0f}" for n in sizes])
    ax[1].set_xlabel("particles N (3D near starts)")
    ax[1].set_ylabel("CPU per pivot [ms] (all of the LP's calls / its pivots)")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


#: ``sweep``: the variants of jamflow.simplex's measured choices, each against the default
VARIANTS: dict[str, dict] = {
    "default": {},
    "devex": {"pricing": "devex"},
    "colamd": {"ordering": "colamd"},
    "no_perturbation": {"perturbation": 0.0},
    "perturbation_1e-7": {"perturbation": 1e-7},
    "etas_50": {"max_etas": 50},
    "etas_400": {"max_etas": 400},
    "sketch_8": {"sketch_rows": 8},
    "sketch_32": {"sketch_rows": 32},
}


def sweep(tags: list[str], every: int, variants: list[str]) -> xr.Dataset:
    """Every ``every``-th captured LP of ``tags`` by each variant of :data:`VARIANTS`
    (the order rotating from LP to LP): pivots and CPU time."""
    from jamflow.simplex import pricing

    rows, names = [], []
    for tag in tags:
        for count, path in enumerate(captured(tag)[::every]):
            w = load(path)
            order = variants[count % len(variants):] + variants[:count % len(variants)]
            out = {}
            for v in order:
                options = dict(VARIANTS[v])
                pricing.SKETCH_ROWS = options.pop("sketch_rows", 16)
                _, cpu, r = ours_solve(w, **options)
                out[v] = (cpu, r.stats.pivots, float(r.optimal))
            pricing.SKETCH_ROWS = 16
            rows.append(out)
            names.append(f"{tag}/{path.stem}")
            print(names[-1], " ".join(f"{v} {out[v][0]:.2f}s/{out[v][1]}" for v in variants), flush=True)
    data = {}
    for k, (field, unit) in enumerate((("cpu", "s"), ("pivots", "1"), ("optimal", "1"))):
        data[field] = (("lp", "variant"), np.array([[r[v][k] for v in variants] for r in rows]), {"units": unit})
    ds = xr.Dataset(data, coords={"lp": names, "variant": variants},
                    attrs=new_dataset_attrs("jamflow.simplex variants on captured CALiPPSO warm LPs", {"tags": tags}))
    for v in variants:
        print(f"{v}: CPU {ds['cpu'].sel(variant=v).sum().item():.1f} s, pivots {ds['pivots'].sel(variant=v).sum().item():.0f}, "
              f"optimal {ds['optimal'].sel(variant=v).sum().item():.0f} of {len(names)}", flush=True)
    return ds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="step", required=True)
    cap = sub.add_parser("capture", help="run chains and save their warm LPs")
    cap.add_argument("--sizes", type=int, nargs="*", default=[1024, 2048, 4096])
    cap.add_argument("--seeds", type=int, nargs="+", default=[1])
    cap.add_argument("--ls", type=int, nargs="*", default=[], help="dimensions of the authors' LS examples")
    cap.add_argument("--max-warm", type=int, default=10**6, help="warm LPs per chain")
    cap.add_argument("--engine", choices=("highs", "jamflow"), default="highs",
                     help="whose warm LPs: HiGHS's chain (with HiGHS's answers) or jamflow.simplex's "
                          "(tags prefixed 'ours_')")
    cmp = sub.add_parser("compare", help="HiGHS against jamflow.simplex on the captured LPs")
    cmp.add_argument("--tags", nargs="+", default=None, help="captured chains (default: all)")
    cmp.add_argument("--max-lps", type=int, default=10**6, help="LPs per chain")
    cmp.add_argument("--every", type=int, default=1, help="take every k-th captured LP")
    cmp.add_argument("--ordering", default="metis")
    cmp.add_argument("--pricing", default="sketch")
    cmp.add_argument("--lu", default="auto", choices=simplex.factor.LU_LIBRARIES, help="library of the LU")
    cmp.add_argument("--output", default="warm_lp.nc")
    swp = sub.add_parser("sweep", help="variants of jamflow.simplex's choices on a sample of captured LPs")
    swp.add_argument("--tags", nargs="+", required=True)
    swp.add_argument("--every", type=int, default=1, help="take every k-th captured LP")
    swp.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    swp.add_argument("--output", default="warm_lp_sweep.nc")
    prf = sub.add_parser("profile", help="jamflow.simplex's CPU time by part on captured LPs")
    prf.add_argument("--tags", nargs="+", required=True)
    prf.add_argument("--max-lps", type=int, default=10**6, help="LPs per chain")
    prf.add_argument("--every", type=int, default=1, help="take every k-th captured LP")
    prf.add_argument("--output", default="warm_lp_profile.nc")
    car = sub.add_parser("carried", help="feasibility of the carried bases of the captured LPs")
    car.add_argument("--tags", nargs="+", required=True)
    car.add_argument("--output", default="warm_lp_carried.nc")
    args = ap.parse_args()
    if args.step == "profile":
        ds = profile(args.tags, args.max_lps, args.every)
        write_dataset(ds, OUT / args.output)
        plot_profile(ds, (OUT / args.output).with_suffix(".png"))
    if args.step == "carried":
        write_dataset(carried(args.tags), OUT / args.output)
    if args.step == "sweep":
        write_dataset(sweep(args.tags, args.every, args.variants), OUT / args.output)
    if args.step == "compare":
        tags = args.tags or sorted(p.name for p in CAPTURE.iterdir() if p.is_dir())
        ds = compare(tags, args.max_lps, args.every, {"ordering": args.ordering, "pricing": args.pricing,
                                                         "lu": args.lu})
        write_dataset(ds, OUT / args.output)
        plot(ds)
    if args.step == "capture":
        for d in args.ls:
            capture(ls_example(d), f"ls_d{d}", args.max_warm)
        for n in args.sizes:
            for s in args.seeds:
                if args.engine == "jamflow":
                    capture_ours(near_start(n, s, FAST_KAPPA), f"ours_near_N{n}_s{s}", args.max_warm)
                else:
                    capture(near_start(n, s, FAST_KAPPA), f"near_N{n}_s{s}", args.max_warm)


if __name__ == "__main__":
    main()
