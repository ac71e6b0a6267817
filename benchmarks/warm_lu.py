"""Sparse LU libraries on the working-set matrices of CALiPPSO's warm LPs: factorisation
and solve CPU, fill and accuracy, per library.

For every captured warm LP taken (``benchmarks/warm_lp.py capture``;
``OUT/warm_lps/<tag>/lp_NNNN.npz``) the starting working-set matrix ``W`` (order
``d N + 1``) is built as :mod:`jamflow.simplex` builds it from the carried basis, and
each library factorises it and solves ``W x = b`` and ``W^T y = c``: ``b`` dense
(Gaussian), ``b = e_p`` (the sparse right-hand side of a pivot's step), ``c = -e_g`` (the
cost: the multipliers) and ``c`` = row ``k`` of ``W`` (then ``y = e_k`` exactly).
Accuracy: the norm-wise backward error ``|W x - b|_inf / | |W| |x| |_inf`` of the dense
solve and its transpose, and ``|y - e_k|_inf``. Times are CPU (``time.process_time``),
one thread (MKL's sequential layer), each solve the mean of ``--reps``.

Libraries (``LIBRARIES``): SuperLU with the METIS order and jamflow's numba triangular
solves (``superlu``, jamflow.simplex's fallback), with SuperLU's own solves (``superlu_gstrs``;
so are the variants): with COLAMD, other pivot thresholds, a smaller relax and larger
panel size (``relax`` = 16 or 32 with ``panel_size`` = 32 corrupts the heap in scipy
1.17's ``splu`` on these matrices: not measured);
MKL PARDISO (``pardiso``, :mod:`jamflow.simplex._pardiso`), without its matching and
scaling, with two steps of iterative refinement per solve; the corrected semi-normal
equations on PARDISO's Cholesky of ``W^T W`` with two steps of refinement (``csne``);
MUMPS (``python-mumps``) when it imports. Writes ``OUT/warm_lu.nc`` and ``OUT/warm_lu.png``.

Run: ``python benchmarks/warm_lu.py --tags near_N2048_s1 near_N4096_s1 --every 4``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import xarray as xr

from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.simplex import _pardiso
from jamflow.simplex import factor as F
from jamflow.simplex.state import State, Tolerances

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calippso import OUT
from warm_lp import captured, load, particles


class _SuperLU:
    """SuperLU with its own options (``splu``'s ``diag_pivot_thresh``, ``relax``,
    ``panel_size``) and its own triangular solves (``gstrs``), on the METIS order of
    :func:`~jamflow.simplex.factor.nested_dissection` or on COLAMD."""

    def __init__(self, n: int, ordering: str = "metis", **splu) -> None:
        self.n, self.ordering, self.splu = n, ordering, splu

    def factorise(self, W: sp.csr_matrix) -> None:
        q = F.nested_dissection(W) if self.ordering == "metis" else np.arange(self.n)
        spec = "NATURAL" if self.ordering == "metis" else "COLAMD"
        options = dict(diag_pivot_thresh=F.DIAG_PIVOT_THRESHOLD) | self.splu
        self.lu, self.q = sla.splu(W.tocsc()[:, q], permc_spec=spec, **options), q
        self.fill = self.lu.L.nnz + self.lu.U.nnz

    def ftran(self, b):
        x = np.empty(self.n)
        x[self.q] = self.lu.solve(np.asarray(b, float))
        return x

    def btran(self, c):
        return self.lu.solve(np.ascontiguousarray(np.asarray(c, float)[self.q]), trans="T")


class _Pardiso:
    """PARDISO on ``W`` with ``iparm`` overrides, or the corrected semi-normal equations
    on its Cholesky of ``W^T W`` (``csne``) with ``steps`` refinements against ``W``."""

    def __init__(self, n: int, options: dict[int, int] | None = None, csne: bool = False, steps: int = 2) -> None:
        self.csne, self.steps = csne, steps
        mtype = _pardiso.REAL_SPD if csne else _pardiso.REAL_NONSYMMETRIC
        self.lu = _pardiso.PardisoLU(mtype, options)

    def factorise(self, W: sp.csr_matrix) -> None:
        self.W = W.tocsr()
        self.lu.factorise(sp.triu(self.W.T @ self.W, format="csr") if self.csne else self.W)
        self.fill, self.perturbed = self.lu.fill, self.lu.perturbed

    def ftran(self, b):
        if not self.csne:
            return self.lu.solve(b)
        W = self.W
        x = self.lu.solve(W.T @ b)
        for _ in range(self.steps):
            x += self.lu.solve(W.T @ (b - W @ x))
        return x

    def btran(self, c):
        if not self.csne:
            return self.lu.solve(c, transposed=True)
        W = self.W
        y = W @ self.lu.solve(c)
        for _ in range(self.steps):
            y += W @ self.lu.solve(c - W.T @ y)
        return y


class _Mumps:
    """MUMPS (``python-mumps``), METIS order, its default threshold 0.01."""

    def __init__(self, n: int) -> None:
        import mumps

        self.ctx = mumps.Context()

    def factorise(self, W):
        self.ctx.factor(sp.coo_array(W), ordering="metis")
        self.fill = int(self.ctx.mumps_instance.infog[29])

    def _solve(self, b, transposed):
        self.ctx.mumps_instance.icntl[9] = 0 if transposed else 1
        return np.asarray(self.ctx.solve(np.array(b, float)), float).ravel()

    def ftran(self, b):
        return self._solve(b, False)

    def btran(self, c):
        return self._solve(c, True)


LIBRARIES = {
    "superlu": lambda n: F.Factor(n, lu="superlu"),
    "superlu_gstrs": lambda n: _SuperLU(n),
    "superlu_colamd": lambda n: _SuperLU(n, "colamd"),
    "superlu_thresh_0.01": lambda n: _SuperLU(n, diag_pivot_thresh=0.01),
    "superlu_thresh_1": lambda n: _SuperLU(n, diag_pivot_thresh=1.0),
    "superlu_relax_4_panel_16": lambda n: _SuperLU(n, relax=4, panel_size=16),
    "pardiso": lambda n: F.Factor(n, lu="pardiso"),
    "pardiso_no_matching": lambda n: _Pardiso(n, {10: 0, 12: 0}),
    "pardiso_refine_2": lambda n: _Pardiso(n, {7: 2}),
    "csne": lambda n: _Pardiso(n, csne=True),
    "mumps": lambda n: _Mumps(n),
}
MEASURES = {"factor_cpu": "s", "fill": "1", "perturbed": "1", "ftran_dense": "s", "ftran_unit": "s",
            "btran_cost": "s", "btran_row": "s", "backward_error": "1", "backward_error_T": "1", "row_error": "1"}


def working_set(path: Path) -> sp.csr_matrix:
    """The starting working-set matrix of a captured LP, as :mod:`jamflow.simplex` builds it."""
    w = load(path)
    st = State(w.A, w.rhs, w.col_lower, w.col_upper, np.zeros(w.A.shape[1]), Tolerances(), None, "metis", "superlu")
    st.set_working_set(w.col_status, w.row_status)
    return st.working_matrix()


def _cpu(f, args) -> float:
    """Mean CPU seconds of ``f`` over ``args``."""
    c0 = time.process_time()
    for a in args:
        f(a)
    return (time.process_time() - c0) / len(args)


def measure(lib: str, W: sp.csr_matrix, reps: int, rng: np.random.Generator) -> dict[str, float]:
    n = W.shape[0]
    f = LIBRARIES[lib](n)
    c0 = time.process_time()
    f.factorise(W)
    row = dict(factor_cpu=time.process_time() - c0, fill=float(f.fill), perturbed=float(getattr(f, "perturbed", getattr(f, "superlu_fallbacks", 0))))
    b = rng.standard_normal(n)
    cost = np.zeros(n)
    cost[-1] = -1.0
    units = [np.eye(1, n, int(p)).ravel() for p in rng.integers(0, n, reps)]
    ks = rng.integers(0, n, reps)
    rows_k = [W[int(k)].toarray().ravel() for k in ks]
    f.ftran(b), f.btran(cost)  # compile or warm up
    row.update(ftran_dense=_cpu(f.ftran, [b] * reps), ftran_unit=_cpu(f.ftran, units),
               btran_cost=_cpu(f.btran, [cost] * reps), btran_row=_cpu(f.btran, rows_k))
    x, y = f.ftran(b), f.btran(cost)
    row["backward_error"] = float(np.abs(W @ x - b).max() / (abs(W) @ np.abs(x)).max())
    row["backward_error_T"] = float(np.abs(W.T @ y - cost).max() / (abs(W.T) @ np.abs(y)).max())
    row["row_error"] = max(float(np.abs(f.btran(r) - (np.arange(n) == k)).max()) for r, k in zip(rows_k, ks))
    if hasattr(f, "release"):
        f.release()
    return row


def run(tags: list[str], every: int, libs: list[str], reps: int) -> xr.Dataset:
    rng = np.random.default_rng(1)
    names, values = [], {m: [] for m in MEASURES}
    for tag in tags:
        for path in captured(tag)[::every]:
            W = working_set(path)
            names.append(f"{tag}/{path.stem}")
            for m in MEASURES:
                values[m].append([np.nan] * len(libs))
            for j, lib in enumerate(libs):
                try:
                    row = measure(lib, W, reps, rng)
                except (ImportError, RuntimeError) as exc:
                    print(f"{names[-1]} {lib}: {type(exc).__name__}: {exc}", flush=True)
                    continue
                for m in MEASURES:
                    values[m][-1][j] = row[m]
                print(f"{names[-1]} (n = {W.shape[0]}) {lib}: factor {row['factor_cpu']:.3f} s fill {row['fill']:.3g} "
                      f"perturbed {row['perturbed']:.0f} | solves [ms] {1e3 * row['ftran_dense']:.2f} dense, "
                      f"{1e3 * row['ftran_unit']:.2f} unit, {1e3 * row['btran_cost']:.2f} T cost, "
                      f"{1e3 * row['btran_row']:.2f} T row | backward error {row['backward_error']:.1e} / "
                      f"{row['backward_error_T']:.1e}, |y - e_k| {row['row_error']:.1e}", flush=True)
    n_part = [particles(name.split("/")[0]) for name in names]
    data = {m: (("lp", "library"), np.array(v, float), {"units": u}) for m, (v, u) in
            ((m, (values[m], MEASURES[m])) for m in MEASURES)}
    return xr.Dataset(data, coords={"lp": names, "library": libs, "N": ("lp", n_part)}, attrs=new_dataset_attrs(
        "sparse LU libraries on the starting working sets of captured CALiPPSO warm LPs",
        {"tags": tags, "every": every, "reps": reps, "mkl": _pardiso.version()}))


def summary(ds: xr.Dataset) -> None:
    for n in np.unique(ds["N"].values):
        sel = ds.where(ds["N"] == n, drop=True)
        print(f"N = {n}, {sel.sizes['lp']} working sets: medians (backward errors: largest)")
        print(f"{'library':28s} {'factor [s]':>10s} {'fill':>9s} {'ftran':>7s} {'e_p':>7s} {'btran':>7s} {'row':>7s} "
              f"{'bwd err':>8s} {'bwd T':>8s} {'|y-e_k|':>8s} perturbed")
        for lib in ds["library"].values:
            s = sel.sel(library=lib)
            med = {m: float(s[m].median()) for m in MEASURES}
            mx = {m: float(s[m].max()) for m in MEASURES}
            print(f"{lib:28s} {med['factor_cpu']:10.3f} {med['fill']:9.3g} {1e3 * med['ftran_dense']:7.2f} "
                  f"{1e3 * med['ftran_unit']:7.2f} {1e3 * med['btran_cost']:7.2f} {1e3 * med['btran_row']:7.2f} "
                  f"{mx['backward_error']:8.1e} {mx['backward_error_T']:8.1e} {mx['row_error']:8.1e} "
                  f"{mx['perturbed']:.0f}")


def plot(ds: xr.Dataset, path: Path) -> None:
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.6))
    libs = list(ds["library"].values)
    for n, marker in zip(np.unique(ds["N"].values), "os^"):
        sel = ds.where(ds["N"] == n, drop=True)
        ax[0].plot(sel["fill"].median("lp"), sel["factor_cpu"].median("lp"), marker, label=f"N = {n}")
        for lib, x, y in zip(libs, sel["fill"].median("lp").values, sel["factor_cpu"].median("lp").values):
            ax[0].annotate(lib, (x, y), fontsize=6)
        solve = sel[["ftran_dense", "btran_cost"]].to_array().mean("variable").median("lp")
        ax[1].plot(range(len(libs)), 1e3 * solve, marker, label=f"N = {n}")
    ax[0].set_xscale("log")
    ax[0].set_yscale("log")
    ax[0].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax[0].set_xlabel("fill nnz(L + U) (median)")
    ax[0].set_ylabel("factorisation CPU time [s] (median)")
    ax[0].set_title("each library's median over the working sets", fontsize=9)
    ax[0].legend(fontsize=8)
    ax[1].set_xticks(range(len(libs)), libs, rotation=60, ha="right", fontsize=7)
    ax[1].set_yscale("log")
    ax[1].set_ylabel("dense solve CPU time [ms]")
    ax[1].set_title("W x = b and W^T y = c, mean of the two (median)", fontsize=9)
    ax[1].legend(fontsize=8)
    fig.suptitle("starting working sets W of captured CALiPPSO warm LPs (3D near starts), one thread")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tags", nargs="+", default=["near_N2048_s1", "near_N4096_s1"])
    ap.add_argument("--every", type=int, default=4, help="take every k-th captured LP")
    ap.add_argument("--libraries", nargs="+", default=list(LIBRARIES), choices=list(LIBRARIES))
    ap.add_argument("--reps", type=int, default=5, help="solves per kind, timed together")
    ap.add_argument("--output", default="warm_lu.nc")
    args = ap.parse_args()
    ds = run(args.tags, args.every, args.libraries, args.reps)
    write_dataset(ds, OUT / args.output)
    summary(ds)
    plot(ds, (OUT / args.output).with_suffix(".png"))


if __name__ == "__main__":
    main()
