"""CALiPPSO's first LP of a start near jamming: HiGHS's interior point (IPX) without
and with crossover, HiPO with crossover on the LP's explicit dual
(``jamflow.protocols.calippso.dual``), and jamflow.simplex from the crash basis of the
start's smallest gaps (``jamflow.protocols.calippso.crash``), all on one core.

For each start the first LP is set up as the chain sets it up (``_set_up_lp``) and
solved by the four methods in one process, the order rotating from start to start;
CPU time (``time.process_time``) of each, interior point iterations, crossover and
simplex pivots, and the agreement of HiPO's and the crash's answers with IPX's
crossover vertex: ``g`` (relative), the active set (rows with a dual above
``CONTACT_DUAL_REL_TOL`` of the largest) and the duals (largest difference over the
largest dual). Writes ``OUT/first_lp.nc`` and
``OUT/first_lp.png``.

Run: ``python benchmarks/first_lp.py --starts benchmarks/output/calippso_start_ls_p1e+07_N2048_s1.nc ...``
(near starts of ``benchmarks/calippso.py``'s ``near_start``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow import simplex
from jamflow.highs import new_highs
from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.protocols.calippso import CONTACT_DUAL_REL_TOL, SOLVER_TOL
from jamflow.protocols.calippso.chain import _Chain, _Container
from jamflow.protocols.calippso.crash import _crash_basis
from jamflow.protocols.calippso.lp import _highs_lp, _near_start
from jamflow.protocols.calippso.options import _Options
from jamflow.protocols.calippso.solver import NEAR_START_PRESOLVE, _Solver
from jamflow.protocols.calippso.steps import _set_up_lp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calippso import OUT

METHODS = ("ipm-nox", "ipm", "hipo-dual", "crash")
UNITS = {"cpu": "s", "basis_cpu": "s"}


def first_lp(start: Path):
    """The first LP of the chain on ``start`` as :func:`calippso` sets it up (defaults)."""
    p = read_packing(start)
    opt = _Options(tol_s=1e-9, tol_gamma=1e-12, solver="hybrid", solver_tol=SOLVER_TOL, cutoff=1.7, cutoff_near=1.4,
                   bound=((5e-4, 0.1), (1e-5, 0.01)), relax=None, walls=False, max_iterations=1,
                   require_isostatic=True, threads=1, finish="lp", interior="ipx", warm_engine="auto",
                   first_lp="auto")
    container = _Container(p.box, False)
    chain = _Chain(x=p.box.wrap(p.position), D=p.diameter.copy())
    chain.near_start = _near_start(chain.x, chain.D, container)
    if not chain.near_start:
        raise SystemExit(f"{start} is not a start near jamming")
    return p, _set_up_lp(chain, container, opt, p.d, p.n)


def highs(lp, method: str) -> dict:
    s = _Solver(1)
    s.ipm_presolve = NEAR_START_PRESOLVE
    c0 = time.process_time()
    status, _ = s._run(_highs_lp(lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper), method, None)
    cpu = time.process_time() - c0
    info, sol = s.h.getInfo(), s.h.getSolution()
    return dict(cpu=cpu, status=s.h.modelStatusToString(status), ipm_its=int(info.ipm_iteration_count),
                pivots=int(max(info.crossover_iteration_count, 0)), col=np.asarray(sol.col_value),
                dual=-np.asarray(sol.row_dual))


def hipo_dual(lp) -> dict:
    """The LP as its explicit dual by HiPO with crossover, read back (the chain's ``_solve_dual``)."""
    s = _Solver(1, interior="hipo")
    s.ipm_presolve = NEAR_START_PRESOLVE
    c0 = time.process_time()
    sol = s._solve_dual(lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper, lp.rows)
    cpu = time.process_time() - c0
    n, m = lp.A.shape[1], lp.A.shape[0]
    return dict(cpu=cpu, status=sol.status, ipm_its=sol.ipm_iterations, pivots=sol.simplex_iterations,
                col=sol.col if sol.col is not None else np.full(n, np.nan),
                dual=sol.dual if sol.dual is not None else np.full(m, np.nan))


def crash(lp) -> dict:
    c0 = time.process_time()
    basis = _crash_basis(new_highs(1), lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper)
    crash_cpu = time.process_time() - c0
    if basis is None:
        return dict(cpu=crash_cpu, basis_cpu=crash_cpu, status="no crash basis", ipm_its=0, pivots=0, dual_pivots=0,
                    flips=0, factorisations=0, held=0, crash_rows=0, col=np.full(lp.A.shape[1], np.nan),
                    dual=np.full(lp.A.shape[0], np.nan))
    col, row = basis
    cost = np.zeros(lp.A.shape[1])
    cost[-1] = -1.0
    res = simplex.solve(lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper, cost, col, row,
                        simplex.Tolerances(primal=SOLVER_TOL, dual=SOLVER_TOL), held=col == 3)
    st = res.stats
    return dict(cpu=time.process_time() - c0, basis_cpu=crash_cpu, status=res.status, ipm_its=0,
                pivots=st.pivots, dual_pivots=st.dual_pivots, flips=st.flips, factorisations=st.factorisations,
                held=int(np.sum(col == 3)), crash_rows=int(np.sum(row != 1)), col=res.col_value, dual=-res.row_dual)


def agreement(ours: dict, ref: dict) -> dict:
    mu, mu_h = ours["dual"], ref["dual"]
    act, act_h = mu > CONTACT_DUAL_REL_TOL * mu.max(), mu_h > CONTACT_DUAL_REL_TOL * mu_h.max()
    return dict(gamma_rel=abs(ours["col"][-1] - ref["col"][-1]) / (1.0 + ref["col"][-1]),
                active_diff=float(np.sum(act ^ act_h)), dual_diff=float(np.max(np.abs(mu - mu_h)) / mu_h.max()),
                contacts=float(act_h.sum()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--starts", nargs="+", type=Path, required=True, help="near starts (netCDF packings)")
    ap.add_argument("--output", default="first_lp.nc")
    args = ap.parse_args()
    fields = ["N", "rows"] + [f"{m}_{k}" for m in METHODS for k in ("cpu", "pivots", "ipm_its")] + [
        "basis_cpu", "crash_rows", "held", "dual_pivots", "flips", "factorisations", "gamma_rel", "active_diff",
        "dual_diff", "contacts", "crash_optimal", "hipo_gamma_rel", "hipo_active_diff", "hipo_dual_diff"]
    rows = []
    for k, start in enumerate(args.starts):
        p, lp = first_lp(start)
        order = METHODS[k % len(METHODS):] + METHODS[:k % len(METHODS)]
        solve = dict(crash=crash, **{"hipo-dual": hipo_dual})
        runs = {m: solve[m](lp) if m in solve else highs(lp, m) for m in order}
        row = dict(N=p.n, rows=lp.A.shape[0], crash_optimal=float(runs["crash"]["status"] == "optimal"))
        for m in METHODS:
            row.update({f"{m}_{q}": runs[m][q] for q in ("cpu", "pivots", "ipm_its")})
        row.update({q: runs["crash"][q] for q in ("basis_cpu", "crash_rows", "held", "dual_pivots", "flips",
                                                   "factorisations")})
        row.update(agreement(runs["crash"], runs["ipm"]))
        row.update({f"hipo_{q}": v for q, v in agreement(runs["hipo-dual"], runs["ipm"]).items() if q != "contacts"})
        rows.append(row)
        print(f"{start.name}: IPX {row['ipm-nox_cpu']:.2f} s ({row['ipm-nox_ipm_its']} its) | IPX + crossover "
              f"{row['ipm_cpu']:.2f} s ({row['ipm_ipm_its']} its, {row['ipm_pivots']} crossover pivots) | "
              f"HiPO on the dual + crossover {row['hipo-dual_cpu']:.2f} s ({row['hipo-dual_ipm_its']} its, "
              f"{row['hipo-dual_pivots']} crossover pivots; Gamma {row['hipo_gamma_rel']:.1e} active "
              f"{row['hipo_active_diff']:.0f} duals {row['hipo_dual_diff']:.1e}) | crash "
              f"{runs['crash']['status']} {row['crash_cpu']:.2f} s (basis {row['basis_cpu']:.2f} s, "
              f"{row['crash_rows']} rows, {row['held']} held; {row['crash_pivots']} pivots, {row['dual_pivots']} dual, "
              f"{row['flips']} flips, {row['factorisations']} LUs) | HiGHS/crash {row['ipm_cpu'] / row['crash_cpu']:.2f} "
              f"| Gamma {row['gamma_rel']:.1e} active {row['active_diff']:.0f} of {row['contacts']:.0f} duals "
              f"{row['dual_diff']:.1e}", flush=True)
    data = {f: (("start",), np.array([r[f] for r in rows], float), {"units": UNITS.get(f.split("_", 1)[-1], "1")})
            for f in fields}
    ds = xr.Dataset(data, coords={"start": [s.name for s in args.starts]}, attrs=new_dataset_attrs(
        "CALiPPSO first LP: IPX without and with crossover, HiPO on the dual, jamflow.simplex from a crash basis",
        {"starts": [str(s) for s in args.starts]}))
    write_dataset(ds, OUT / args.output)
    fig, ax = plt.subplots(figsize=(6, 4))
    x = np.arange(len(rows))
    for i, (m, label) in enumerate((("ipm-nox", "IPX, no crossover"), ("ipm", "IPX + crossover"),
                                    ("hipo-dual", "HiPO on the dual + crossover"),
                                    ("crash", "crash basis + jamflow.simplex"))):
        ax.bar(x + (i - 1.5) * 0.2, ds[f"{m}_cpu"].values, 0.2, label=label)
    ax.set_xticks(x, [f"N = {int(n)}\n{s.split('_')[-1][:-3]}" for n, s in zip(ds.N.values, ds.start.values)])
    ax.set_ylabel("CPU time of the first LP [s]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / Path(args.output).with_suffix(".png").name, dpi=120)


if __name__ == "__main__":
    main()
