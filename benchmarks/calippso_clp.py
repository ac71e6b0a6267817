"""CALiPPSO's warm LPs by HiGHS and by COIN-OR CLP: is another simplex the way to large N?

The warm LPs of a near-jamming start cost the LU factorisation of the simplex basis
(``docs/notes/calippso-scaling.md``). This benchmark asks whether CLP, the other open-source
simplex on PyPI with a warm-basis interface (``cylp``; OR-Tools' GLOP takes no
starting basis through its Python solver wrapper), factorises or pivots these bases
better. For each near start (LS to p = 1e7 at kappa = 1e-3, cached by ``benchmarks/calippso.py``) the
chain runs as ``jamflow calippso`` does and its first warm LPs are captured as HiGHS
is given them: matrix, bounds and the carried basis. Each is then solved by CLP's primal simplex from the same basis at
the chain's feasibility tolerances (``SOLVER_TOL``). Per LP:

- the chain's HiGHS solve (time, pivots) against CLP (time, iterations), and the
  objective ``-g`` of both, printed side by side;
- the basis factorisation alone: a re-solve from each solver's own optimal basis
  (zero pivots), with the exponent of its growth with N.

Writes ``benchmarks/output/calippso_clp.nc`` and ``calippso_clp.png``.
Run: ``pip install -e ".[bench]"`` (adds ``cylp``), then
``python benchmarks/calippso_clp.py [--sizes 1024 2048 4096] [--warm-lps 3]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import highspy
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
import xarray as xr

import jamflow.protocols.calippso.lp as cal_lp
import jamflow.protocols.calippso.solver as cal_solver
from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.protocols.calippso import SOLVER_TOL, calippso

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calippso import FAST_KAPPA, OUT, fit, near_start  # noqa: E402

try:
    from cylp.cy import CyClpSimplex
    from cylp.cy.CyCoinPackedMatrix import CyCoinPackedMatrix
except ImportError as err:
    raise SystemExit(f"this benchmark needs cylp: pip install -e \".[bench]\" ({err})") from None

#: HiGHS basis status -> CLP's (getBasisStatus / setBasisStatus: 0 free, 1 basic,
#: 2 at upper, 3 at lower); HiGHS kZero (free, nonbasic) -> free, kNonbasic -> at lower
HIGHS_TO_CLP = {0: 3, 1: 1, 2: 2, 3: 0, 4: 3}
#: CLP's infinity
CLP_INF = 1e30


@dataclass(frozen=True)
class WarmLP:
    """One warm LP as the chain gave it to HiGHS, and what HiGHS made of it."""

    A: sp.csc_matrix
    row_upper: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    col_status: np.ndarray
    row_status: np.ndarray
    optimal_basis: highspy.HighsBasis
    seconds: float
    pivots: int
    objective: float


class _Enough(Exception):
    """Stops the chain once the warm LPs to compare are captured."""


def capture(start: Path, n_warm: int) -> list[WarmLP]:
    """Run the chain on ``start`` and capture its first ``n_warm`` warm simplex LPs.

    The capture wraps the chain's one HiGHS call (``_Solver._run``, private: this
    benchmark has to see the LP and basis exactly as HiGHS gets them); the chain itself
    is unchanged."""
    captured: list[WarmLP] = []
    run = cal_solver._Solver._run

    def capturing_run(self, lp, method, basis):
        status, seconds = run(self, lp, method, basis)
        # warm LPs that ran out of pivots go on by interior point: only optimal vertices compare
        if basis is not None and method == "simplex" and status == highspy.HighsModelStatus.kOptimal:
            a = lp.a_matrix_
            info = self.h.getInfo()
            captured.append(WarmLP(
                sp.csc_matrix((np.asarray(a.value_), np.asarray(a.index_), np.asarray(a.start_)),
                              shape=(lp.num_row_, lp.num_col_)),
                np.asarray(lp.row_upper_), np.asarray(lp.col_lower_), np.asarray(lp.col_upper_),
                np.array([int(v) for v in basis.col_status]), np.array([int(v) for v in basis.row_status]),
                self.h.getBasis(), seconds, int(info.simplex_iteration_count), float(info.objective_function_value)))
            if len(captured) == n_warm:
                raise _Enough
        return status, seconds

    cal_solver._Solver._run = capturing_run
    try:
        calippso(read_packing(start))
    except _Enough:
        pass
    finally:
        cal_solver._Solver._run = run
    return captured


def clp_model(w: WarmLP) -> CyClpSimplex:
    """``min -g`` s.t. ``A z <= row_upper`` and the column bounds, at the chain's tolerances."""
    coo = w.A.tocoo()
    s = CyClpSimplex()
    s.loadProblem(CyCoinPackedMatrix(True, coo.row.astype(np.int32), coo.col.astype(np.int32), coo.data),
                  np.nan_to_num(w.col_lower, neginf=-CLP_INF), np.nan_to_num(w.col_upper, posinf=CLP_INF),
                  np.eye(1, w.A.shape[1], w.A.shape[1] - 1).ravel() * -1.0,
                  np.full(w.A.shape[0], -CLP_INF), np.nan_to_num(w.row_upper, posinf=CLP_INF))
    s.logLevel = 0
    s.primalTolerance = SOLVER_TOL
    s.dualTolerance = SOLVER_TOL
    return s


def clp_solve(w: WarmLP, col_status, row_status) -> tuple[float, int, float, tuple]:
    """CLP's primal simplex from a basis: time [s], iterations, objective, final basis."""
    s = clp_model(w)
    s.setBasisStatus(np.asarray(col_status, np.int32), np.asarray(row_status, np.int32))
    t0 = time.perf_counter()
    s.primal()
    seconds = time.perf_counter() - t0
    if s.getStatusString() != "optimal":
        raise RuntimeError(f"CLP ended with {s.getStatusString()}")
    # copies: cylp's arrays view CLP's memory, freed with the model
    return seconds, int(s.iteration), float(s.objectiveValue), tuple(np.array(v, copy=True) for v in s.getBasisStatus())


def highs_refactor(w: WarmLP) -> float:
    """HiGHS from its own optimal basis (zero pivots), solved as the chain solves a warm
    LP (``_Solver._run``): the basis factorisation [s]."""
    solver = cal_solver._Solver()
    lp = cal_lp._highs_lp(w.A, w.row_upper, w.col_lower, w.col_upper)
    _, seconds = solver._run(lp, "simplex", w.optimal_basis)
    if solver.h.getInfo().simplex_iteration_count != 0:
        raise RuntimeError("HiGHS pivoted from its own optimal basis")
    return seconds


def compare(n: int, n_warm: int) -> xr.Dataset:
    lps = capture(near_start(n, 1, FAST_KAPPA), n_warm)
    rows = []
    for k, w in enumerate(lps):
        col = [HIGHS_TO_CLP[int(v)] for v in w.col_status]
        row = [HIGHS_TO_CLP[int(v)] for v in w.row_status]
        t_clp, its, obj, (c_opt, r_opt) = clp_solve(w, col, row)
        t_clp_factor, its0, _, _ = clp_solve(w, c_opt, r_opt)
        if its0 != 0:
            raise RuntimeError("CLP pivoted from its own optimal basis")
        t_highs_factor = highs_refactor(w)
        rows.append((w.seconds, w.pivots, w.objective, t_clp, its, obj, t_highs_factor, t_clp_factor))
        print(f"N = {n}, warm LP {k + 1} ({w.A.shape[0]} rows): HiGHS {w.seconds:.2f} s, {w.pivots} pivots; "
              f"CLP {t_clp:.2f} s, {its} iterations; objective -g {w.objective:.12g} / {obj:.12g}; "
              f"factorisation alone HiGHS {t_highs_factor:.2f} s, CLP {t_clp_factor:.2f} s", flush=True)
    names = ("highs_time", "highs_pivots", "highs_objective", "clp_time", "clp_iterations", "clp_objective",
             "highs_factor_time", "clp_factor_time")
    data = np.array(rows, dtype=float)
    return xr.Dataset({name: (("N", "lp"), data[None, :, k], {"units": "s" if name.endswith("time") else "1"})
                       for k, name in enumerate(names)},
                      coords={"N": [n], "lp": np.arange(1, len(rows) + 1)})


def plot(ds: xr.Dataset) -> None:
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for i, n in enumerate(ds["N"].values):
        sel = ds.sel(N=n)
        ax[0].loglog(sel["highs_time"], sel["clp_time"], "os^"[i % 3], label=f"N = {n}")
    lim = [float(min(ds["highs_time"].min(), ds["clp_time"].min())) / 1.5,
           float(max(ds["highs_time"].max(), ds["clp_time"].max())) * 1.5]
    ax[0].loglog(lim, lim, "k:", label="equal")
    ax[0].set_xlabel("HiGHS warm LP time [s]")
    ax[0].set_ylabel("CLP warm LP time [s]")
    ax[0].set_title("same LP, same starting basis")
    ax[0].legend(fontsize=8)
    for name, label, m in (("highs_factor_time", "HiGHS", "o-"), ("clp_factor_time", "CLP", "s-")):
        med = ds[name].median("lp")
        ax[1].loglog(ds["N"], med, m, label=f"{label}: N^{ds.attrs[name + '_exponent']:.2f}")
    ax[1].set_xlabel("N (3D near start)")
    ax[1].set_ylabel("basis factorisation [s] (median over LPs)")
    ax[1].set_title("re-solve from the optimal basis (0 pivots)")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "calippso_clp.png", dpi=120)
    print(f"wrote {OUT / 'calippso_clp.png'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096],
                    help="N of the 3D near starts (4096 takes about 10 min, most of it HiGHS)")
    ap.add_argument("--warm-lps", type=int, default=2, help="warm LPs captured per start")
    args = ap.parse_args()
    OUT.mkdir(exist_ok=True)
    ds = xr.concat([compare(n, args.warm_lps) for n in args.sizes], dim="N")
    for name in ("highs_factor_time", "clp_factor_time"):
        ds.attrs[name + "_exponent"] = fit(ds["N"].values, ds[name].median("lp").values)  # NaN below two sizes
        print(f"{name}: exponent {ds.attrs[name + '_exponent']:.2f} over N = {list(ds['N'].values)}")
    ds.attrs.update(new_dataset_attrs("benchmark calippso_clp", {"sizes": args.sizes, "warm_lps": args.warm_lps,
                                                                 "solver_tol": SOLVER_TOL}))
    write_dataset(ds, OUT / "calippso_clp.nc")
    plot(ds)


if __name__ == "__main__":
    main()
