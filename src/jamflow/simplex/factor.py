"""The factorised working-set matrix of the warm simplex, with product-form updates.

The simplex of :mod:`jamflow.simplex` keeps a *working set* of ``n`` constraints (as
many as there are columns) that hold with equality at the current vertex: tight rows
of ``A z <= b`` and columns held at a bound. Their normals are the rows of the square
working-set matrix ``W`` (n, n): ``a_i`` for a row, ``e_j`` for a column. For a
CALiPPSO LP, eliminating the unit rows leaves the contact network's rigidity matrix
and the column of ``g``: a 3D-network matrix whose LU fills as ``N^(4/3)`` under a
nested-dissection ordering, against much more under a Markowitz ordering without a
global view (``docs/notes/warm-simplex.md``).

``W`` is factorised by Intel MKL PARDISO when the ``mkl`` wheel is installed
(:mod:`jamflow.simplex._pardiso`; about three times cheaper at N = 4096; ``W^T`` when the
LU of ``W`` perturbed a pivot), else by SuperLU with a fill-reducing column ordering
(:data:`ORDERINGS`): :data:`LU_LIBRARIES`. Each pivot replaces one row of ``W`` and is kept as a row eta (product form): with
``W_k = E_k ... E_1 W_0`` and ``E`` the identity with row ``p`` replaced by
``beta = W_{k-1}^-T w_new``, ``W_k^-1 = W_0^-1 E_1^-1 ... E_k^-1``.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import NDArray

from . import _kernels as k
from . import _pardiso

#: Libraries of the LU of ``W``: ``auto`` takes ``pardiso`` (MKL PARDISO, its own METIS
#: order of ``W + W^T``) when the ``mkl`` wheel is installed and ``superlu`` otherwise.
#: A PARDISO factorisation with perturbed pivots is redone by PARDISO on ``W^T``, then by SuperLU.
LU_LIBRARIES: tuple[str, ...] = ("auto", "pardiso", "superlu")

#: Column orderings of the working-set matrix for SuperLU: ``metis``, a nested dissection of the
#: column graph of ``W^T W`` without its dense columns (``pymetis``; COLAMD when it is
#: not installed), or SuperLU's ``colamd``.
ORDERINGS: tuple[str, ...] = ("metis", "colamd")

#: A column of ``W`` with more entries than this fraction of its rows (the column of
#: ``g``, in every row) is ordered last, outside the nested dissection.
DENSE_COLUMN_FRACTION: float = 0.1

#: Refactorisation rule: a factorisation costs about this many solves with its
#: factors (measured, CPU, on N = 4096 working sets: SuperLU 0.86 s against 9.7 ms,
#: PARDISO 0.28 s against 3.2-4.5 ms; ``benchmarks/warm_lu.py``). The
#: product form then adds ``2 k n`` operations to the pivot after ``k`` updates, so
#: ``K`` updates between factorisations cost ``K^2 n`` and the optimum is
#: ``K = sqrt(FACTOR_SOLVES * nnz(L + U) / n)`` (:meth:`Factor.factorise`).
FACTOR_SOLVES: float = 100.0

#: Bounds of the rule above.
MIN_ETAS, MAX_ETAS = 16, 400

#: SuperLU's threshold partial pivoting: a diagonal entry is kept as pivot when at
#: least this fraction of the largest in its column (1.0: plain partial pivoting).
DIAG_PIVOT_THRESHOLD: float = 0.1


def _have_pymetis() -> bool:
    """Whether ``pymetis`` (the METIS ordering) is installed; without it COLAMD orders."""
    try:
        import pymetis  # noqa: F401
    except ImportError:
        return False
    return True


def lu_library(lu: str = "auto") -> str:
    """The library ``lu`` (one of :data:`LU_LIBRARIES`) resolves to on this installation.

    Raises
    ------
    ValueError
        ``lu`` is unknown.
    ImportError
        ``pardiso`` was asked for and the ``mkl`` wheel is not installed.
    """
    if lu not in LU_LIBRARIES:
        raise ValueError(f"unknown LU library {lu!r}; choose one of {', '.join(LU_LIBRARIES)}")
    have = _pardiso.library() is not None
    if lu == "pardiso" and not have:
        raise ImportError("lu='pardiso' needs MKL PARDISO: pip install 'jamflow[lp]' (the mkl wheel)")
    return "pardiso" if lu == "pardiso" or (lu == "auto" and have) else "superlu"


class SingularWorkingSet(RuntimeError):
    """The working-set matrix is singular to the LU (a zero pivot)."""


def nested_dissection(W: sp.csr_matrix) -> NDArray[np.int64]:
    """Column order of ``W``: METIS nested dissection of the graph of ``W^T W`` over the
    columns with at most :data:`DENSE_COLUMN_FRACTION` of the rows filled, the dense
    ones last."""
    import pymetis

    n = W.shape[1]
    counts = np.bincount(W.indices, minlength=n)
    dense = counts > max(DENSE_COLUMN_FRACTION * W.shape[0], 16)
    keep = np.flatnonzero(~dense)
    Wk = W.tocsc()[:, keep]
    G = (Wk.T @ Wk).tocsr()
    G.setdiag(0)
    G.eliminate_zeros()
    if G.nnz == 0:
        return np.concatenate([keep, np.flatnonzero(dense)])
    perm, _ = pymetis.nested_dissection(adjacency=pymetis.CSRAdjacency(G.indptr, G.indices))
    return np.concatenate([keep[np.asarray(perm, dtype=np.int64)], np.flatnonzero(dense)])


class Factor:
    """LU of the working-set matrix ``W`` (n, n) with row-eta updates.

    Parameters
    ----------
    n : int
        Order of ``W`` (the LP's column count).
    max_etas : int, optional
        Row etas between factorisations; by default the rule of :data:`FACTOR_SOLVES`.
    ordering : str
        One of :data:`ORDERINGS` (SuperLU's; PARDISO orders by its own METIS).
    lu : str
        One of :data:`LU_LIBRARIES`.
    """

    def __init__(self, n: int, max_etas: int | None = None, ordering: str = "metis", lu: str = "auto") -> None:
        if ordering not in ORDERINGS:
            raise ValueError(f"unknown ordering {ordering!r}; choose one of {', '.join(ORDERINGS)}")
        self.lu = lu_library(lu)
        self._pardiso = _pardiso.PardisoLU() if self.lu == "pardiso" else None
        self.on_pardiso = False  # whether the current factors are PARDISO's
        self.pardiso_transposed = False  # whether they are PARDISO's factors of W^T
        self.transposed_lus = 0  # PARDISO LUs of W with perturbed pivots, redone by PARDISO on W^T
        self.superlu_fallbacks = 0  # PARDISO factorisations with perturbed pivots, redone by SuperLU
        self.n = n
        self.ordering = ordering if ordering != "metis" or _have_pymetis() else "colamd"
        self.max_etas = max_etas
        self.limit = max_etas or MIN_ETAS
        self.eta_slot = np.zeros(0, dtype=np.int64)
        self.eta_beta = np.zeros((0, n))
        self.count = 0
        self.seconds_factor = 0.0  # [s] ordering + LU + extraction, summed
        self.seconds_order = 0.0  # [s] the ordering alone
        self.factorisations = 0
        self.fill = 0  # nnz(L + U) of the last LU

    def factorise(self, W: sp.csr_matrix) -> None:
        """Factorise ``W`` afresh (drops the etas).

        Raises
        ------
        SingularWorkingSet
            The LU found ``W`` singular.
        """
        t0 = time.perf_counter()
        if self._pardiso is not None and self._factorise_pardiso(W):
            self._after_factorisation(t0)
            return
        if self.ordering == "metis":
            q = nested_dissection(W)
            self.seconds_order += time.perf_counter() - t0
            Wq, spec = W.tocsc()[:, q], "NATURAL"
        else:
            q, Wq, spec = np.arange(self.n), W.tocsc(), "COLAMD"
        try:
            lu = sla.splu(Wq, permc_spec=spec, diag_pivot_thresh=DIAG_PIVOT_THRESHOLD)
        except RuntimeError as exc:
            raise SingularWorkingSet(str(exc)) from None
        L, U = lu.L, lu.U
        Ur = U.tocsr()
        Ur.sort_indices()
        self.Lp, self.Li, self.Lx = L.indptr.astype(np.int64), L.indices.astype(np.int64), L.data
        self.Up, self.Ui, self.Ux = U.indptr.astype(np.int64), U.indices.astype(np.int64), U.data
        self.Urp, self.Urj, self.Urx = Ur.indptr.astype(np.int64), Ur.indices.astype(np.int64), Ur.data
        self.perm_r = lu.perm_r.astype(np.int64)
        perm_c = np.empty(self.n, dtype=np.int64)
        perm_c[q] = lu.perm_c
        self.perm_c = perm_c
        self.fill = L.nnz + U.nnz
        self._after_factorisation(t0)

    def _factorise_pardiso(self, W: sp.csr_matrix) -> bool:
        """PARDISO's LU of ``W``, or, when that perturbed a pivot, of ``W^T`` (its matching,
        and so its pivots, are another: it rescued the perturbed sets measured in
        ``docs/notes/warm-simplex.md``, "Per pivot"); False (SuperLU's turn) when both
        perturbed a pivot."""
        for transposed in (False, True):
            try:
                self._pardiso.factorise(W.T.tocsr() if transposed else W)
            except _pardiso.PardisoError as exc:
                if exc.code == _pardiso.ZERO_PIVOT:
                    raise SingularWorkingSet(str(exc)) from None
                raise
            if self._pardiso.perturbed == 0:
                self.on_pardiso, self.pardiso_transposed = True, transposed
                self.transposed_lus += int(transposed)
                self.fill = self._pardiso.fill
                return True
            self._pardiso.release()
        self.on_pardiso = False
        self.superlu_fallbacks += 1
        return False

    def _after_factorisation(self, t0: float) -> None:
        """Drop the etas and set the refactorisation interval from the new fill."""
        self.count = 0
        rule = int(np.ceil(np.sqrt(FACTOR_SOLVES * self.fill / self.n)))
        self.limit = self.max_etas or min(max(rule, MIN_ETAS), MAX_ETAS)
        if len(self.eta_slot) < self.limit:
            self.eta_slot = np.zeros(self.limit, dtype=np.int64)
            self.eta_beta = np.zeros((self.limit, self.n))
        self.factorisations += 1
        self.seconds_factor += time.perf_counter() - t0

    @property
    def full(self) -> bool:
        return self.count >= self.limit

    def ftran(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W_k^-1 b``, shape (n,)."""
        v = np.array(b, dtype=np.float64)
        k.eta_forward(self.eta_slot, self.eta_beta, self.count, v)
        if self.on_pardiso:
            return self._pardiso.solve(v, transposed=self.pardiso_transposed)
        x = np.empty(self.n)
        k.lu_solve(self.Lp, self.Li, self.Lx, self.Up, self.Ui, self.Ux, self.perm_r, self.perm_c, v, x)
        return x

    def btran(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W_k^-T c``, shape (n,)."""
        if self.on_pardiso:
            y = self._pardiso.solve(c, transposed=not self.pardiso_transposed)
            k.eta_backward(self.eta_slot, self.eta_beta, self.count, y)
            return y
        y = np.empty(self.n)
        k.lu_solve_transposed(self.Lp, self.Li, self.Lx, self.Urp, self.Urj, self.Urx, self.perm_r, self.perm_c,
                              np.asarray(c, dtype=np.float64), y)
        k.eta_backward(self.eta_slot, self.eta_beta, self.count, y)
        return y

    def btran_many(self, C: NDArray[np.float64]) -> NDArray[np.float64]:
        """``W_k^-T C`` for the k columns of ``C`` (n, k), shape (n, k): on PARDISO in one pass
        over the factors, which costs about a third of k single solves for k = 16
        (``docs/notes/warm-simplex.md``, "Per pivot")."""
        if not self.on_pardiso:
            return np.stack([self.btran(C[:, j]) for j in range(C.shape[1])], axis=1)
        Y = self._pardiso.solve(C, transposed=not self.pardiso_transposed)
        for j in range(Y.shape[1]):
            k.eta_backward(self.eta_slot, self.eta_beta, self.count, Y[:, j])
        return Y

    def release(self) -> None:
        """Free the library's memory of the factors (PARDISO keeps them outside Python)."""
        if self._pardiso is not None:
            self._pardiso.release()
            self.on_pardiso = False

    def replace(self, p: int, beta: NDArray[np.float64]) -> None:
        """Row ``p`` of ``W`` is replaced by ``w`` with ``beta = W^-T w`` (from :meth:`btran`)."""
        self.eta_slot[self.count] = p
        self.eta_beta[self.count] = beta
        self.count += 1
