"""The motion LPs of the certificate: one HiGHS model per network (:class:`MotionLP`),
the random-load search on it (:class:`_Search`), the backbone the LPs are built on and
the LP kinds, each building its own LP (local, collective, strict)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Protocol

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ...highs import new_highs
from ...network import ContactSet, contact_jacobian
from ...tolerances import CERTIFY_BOUND_TOL, CERTIFY_MOTION_TOL

_DUAL, _PRIMAL = 1, 4  # HiGHS simplex_strategy values


class MotionLP:
    """``max b . y`` subject to ``A y >= -g``, ``|y_k| <= 1``, built once per network.

    Columns are scaled so one unit of displacement is one mean diameter.
    """

    def __init__(self, A: sp.spmatrix, rhs: NDArray[np.float64], upper: NDArray[np.float64], solver: str) -> None:
        csc = sp.csc_matrix(A)
        csc.sort_indices()
        lp = highspy.HighsLp()
        lp.num_col_, lp.num_row_ = csc.shape[1], csc.shape[0]
        lp.col_cost_ = np.zeros(csc.shape[1])
        lp.col_lower_ = -upper
        lp.col_upper_ = upper
        lp.row_lower_ = -rhs
        lp.row_upper_ = np.full(csc.shape[0], highspy.kHighsInf)
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = csc.indptr.astype(np.int32)
        lp.a_matrix_.index_ = csc.indices.astype(np.int32)
        lp.a_matrix_.value_ = csc.data.astype(np.float64)
        self.h = new_highs()
        # displacements are O(1) and motions are thresholded at CERTIFY_MOTION_TOL
        self.h.setOptionValue("primal_feasibility_tolerance", 1e-9)
        self.h.setOptionValue("dual_feasibility_tolerance", 1e-9)
        self.solver = solver
        # IPX by name: a highspy build with HiPO takes HiPO for "ipm"
        self.h.setOptionValue("solver", "ipx" if solver == "ipm" else solver)
        if solver == "ipm":
            # any optimal point is a valid motion, so no vertex (crossover) is needed;
            # HiGHS 1.x IPX stalled with presolve on some symmetric lattice LPs, and
            # the iteration limit turns any other stall into a simplex fallback
            self.h.setOptionValue("run_crossover", "off")
            self.h.setOptionValue("presolve", "off")
            self.h.setOptionValue("ipm_iteration_limit", 1000)
        self.h.passModel(lp)
        self.n = csc.shape[1]
        self._idx = np.arange(self.n, dtype=np.int32)
        # primal simplex from the last optimal basis, for the cone LPs only (rhs = 0;
        # see solve); False until a simplex solve left an optimal basis
        self._cone = not np.any(rhs)
        self._warm = False

    def solve(self, load: NDArray[np.float64]) -> tuple[str, float, NDArray[np.float64], float, int]:
        """Maximise ``load . y``; returns status, optimum, y, wall time, iterations.

        Loads change only the costs, so the last optimal simplex basis stays primal
        feasible. For a cone LP (rhs = 0) of a jammed network the optimum of every load
        is a rigid translation (no relative motion), and the primal simplex from the
        last basis needs a few pivots where a cold dual simplex needs thousands. Loose
        gap LPs move their optimum to another corner of the displacement box with every
        load; there the cold dual simplex is faster, so they always start cold
        (measured: docs/notes/certify-constants.md#warm-starts-of-the-motion-lps).
        """
        self.h.changeColsCost(self.n, self._idx, -load)
        t0 = time.perf_counter()
        self._run()
        if self.h.getModelStatus() != highspy.HighsModelStatus.kOptimal and self.solver != "simplex":
            self.solver = "simplex"
            self.h.setOptionValue("solver", "simplex")
            self.h.setOptionValue("presolve", "choose")
            self._run()
        elapsed = time.perf_counter() - t0
        status = self.h.modelStatusToString(self.h.getModelStatus())
        if self.h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
            raise RuntimeError(f"jamming LP not solved to optimality: HiGHS status {status!r}")
        self._warm = self._cone and self.solver == "simplex"
        info = self.h.getInfo()
        y = np.asarray(self.h.getSolution().col_value, dtype=np.float64)
        return status, -float(info.objective_function_value), y, elapsed, int(info.simplex_iteration_count + info.ipm_iteration_count)

    def _run(self) -> None:
        if self.solver == "simplex":
            self.h.setOptionValue("simplex_strategy", _PRIMAL if self._warm else _DUAL)
        self.h.run()


def random_loads(rng: np.random.Generator, n: int, loads: int) -> list[NDArray[np.float64]]:
    """``loads`` random load vectors of length ``n`` (standard normal components) from ``rng``."""
    return [rng.standard_normal(n) for _ in range(loads)]


@dataclass(frozen=True)
class Motion:
    """A motion an LP allows: relative displacements ``displacement`` (Ns, d) of the
    backbone particles [mean diameters] and strain coordinates ``strain`` (k,) on the
    traceless strain basis (empty without strain columns)."""

    displacement: NDArray[np.float64]
    strain: NDArray[np.float64]

    @property
    def size(self) -> float:
        """Largest particle displacement or strain coordinate [mean diameters]."""
        return max(float(np.linalg.norm(self.displacement, axis=1).max(initial=0.0)),
                   float(np.abs(self.strain).max(initial=0.0)))

    @property
    def needs_strain(self) -> bool:
        """Whether the motion deforms the box (a strain coordinate above ``CERTIFY_MOTION_TOL``)."""
        return float(np.abs(self.strain).max(initial=0.0)) > CERTIFY_MOTION_TOL


class _Search:
    """Random-load LPs of one kind on one network: gap-aware screening, exact decision.

    With ``rhs == "gaps"`` each load is first solved with the gaps as right-hand
    side. A solution that stays inside the displacement bound proves that this load
    meets no recession direction (the cone LP of the same load would be zero), and
    its size is the cage. A solution at the bound is resolved by the exact-contact
    (cone) LP with the same load, which decides and gives the moving particles. With
    ``rhs == "zero"`` only the cone LP runs.
    """

    def __init__(self, kind: str, A: sp.spmatrix, g: NDArray[np.float64], upper: NDArray[np.float64],
                 n_disp: int, d: int, rhs: str, solver: str, record: Any) -> None:
        self.kind, self.A, self.upper, self.n_disp, self.d = kind, A, upper, n_disp, d
        self.solver, self.record = solver, record
        self.gap_lp = MotionLP(A, g, upper, solver) if rhs == "gaps" else None
        self.cone_lp: MotionLP | None = None
        self.cage = 0.0
        self.cage_at_bound = 0

    def _motion(self, z: NDArray[np.float64]) -> Motion:
        y = z[: self.n_disp].reshape(-1, self.d)
        # local LPs move each particle alone; otherwise the majority's motion is a translation
        rel = y if self.kind == "local" else y - np.median(y, axis=0)
        return Motion(rel, z[self.n_disp:])

    def run(self, k: int, s: int, load: NDArray[np.float64]) -> Motion | None:
        """The motion found for one load and sign, or None."""
        if self.gap_lp is not None:
            status, obj, z, t, it = self.gap_lp.solve(s * load)
            size = float(np.abs(z).max(initial=0.0))
            self.record(self.kind, "gaps", k, s, status, obj, t, it, size)
            if size < 1.0 - CERTIFY_BOUND_TOL:
                self.cage = max(self.cage, size)
                return None
        if self.cone_lp is None:
            self.cone_lp = MotionLP(self.A, np.zeros(self.A.shape[0]), self.upper, self.solver)
        status, obj, z, t, it = self.cone_lp.solve(s * load)
        motion = self._motion(z)
        size = motion.size
        self.record(self.kind, "zero", k, s, status, obj, t, it, size)
        if size > CERTIFY_MOTION_TOL:
            return motion
        if self.gap_lp is not None:
            # bounded cone, but the first-order cage reaches the displacement bound
            self.cage = max(self.cage, 1.0)
            self.cage_at_bound += 1
        return None


@dataclass(frozen=True)
class _Backbone:
    """The particles still tested (``idx``, indices into the packing) and their contacts
    (``sel`` over all contacts): the rigidity matrix at a fixed box ``R`` (columns
    ``d`` per backbone particle), the gaps ``g`` [mean diameters] and the position in
    ``idx`` of the pinned (best-connected) particle."""

    idx: NDArray[np.int64]
    sel: NDArray[np.bool_]
    contacts: ContactSet
    first: NDArray[np.int64]
    R: sp.csr_matrix
    g: NDArray[np.float64]
    pin: int
    d: int

    @property
    def n_disp(self) -> int:
        """Displacement columns, ``d`` per backbone particle."""
        return self.d * len(self.idx)

    @property
    def free(self) -> NDArray[np.bool_]:
        """Displacement columns without the pinned particle's."""
        free = np.ones(self.n_disp, dtype=bool)
        free[self.d * self.pin:self.d * self.pin + self.d] = False
        return free

    def pinned_bounds(self, n_cols: int) -> NDArray[np.float64]:
        """Column bounds: one mean diameter, zero on the pinned particle's displacements."""
        upper = np.ones(n_cols)
        upper[self.d * self.pin:self.d * self.pin + self.d] = 0.0
        return upper

    def movers(self, motion: Motion, n: int) -> NDArray[np.bool_]:
        """Backbone particles that move by more than ``CERTIFY_MOTION_TOL``, shape (N,)."""
        moving = np.zeros(n, dtype=bool)
        moving[self.idx] = np.linalg.norm(motion.displacement, axis=1) > CERTIFY_MOTION_TOL
        return moving

    def strain_columns(self, n: int) -> sp.csr_matrix:
        """The rigidity matrix with the traceless strain columns [length], shape (Nc, d Ns + k)."""
        return contact_jacobian(self.contacts, n, self.d, strain="traceless", bodies=self.idx)


def _backbone(contacts: NDArray[np.int64], cs: ContactSet, g: NDArray[np.float64], active: NDArray[np.bool_],
              n: int, d: int) -> _Backbone:
    """The backbone of the ``active`` particles."""
    sel = active[contacts[:, 0]] & active[contacts[:, 1]]
    idx = np.flatnonzero(active)
    selected = cs.select(sel)
    R = contact_jacobian(selected, n, d, bodies=idx)
    return _Backbone(idx, sel, selected, contacts[sel, 0], R, g[sel], _pin(contacts[sel], idx, n), d)


class LPKind(Protocol):
    """A kind of motion LP: its name (stored in ``lp_stage``) and the LP it builds on a backbone."""

    name: str

    def lp(self, bb: _Backbone, n: int, unit: float,
           solver: str) -> tuple[sp.spmatrix, NDArray[np.float64], NDArray[np.float64], str]:
        """Matrix ``A`` of ``A y >= -g``, gaps ``g`` [mean diameters], column bounds and HiGHS solver."""
        ...


class _LocalLP:
    """Local jamming: every contact end constrains one particle, the other held fixed."""

    name = "local"

    def lp(self, bb: _Backbone, n: int, unit: float, solver: str):
        """The LP of this kind: matrix, gaps, column bounds and HiGHS solver."""
        A = _local_rows(bb.R, bb.first, bb.idx, n, bb.d)
        return A, np.concatenate([bb.g, bb.g]), np.ones(bb.n_disp), "simplex"


class _CollectiveLP:
    """Collective jamming: the backbone moves together, the box fixed, one particle pinned."""

    name = "collective"

    def lp(self, bb: _Backbone, n: int, unit: float, solver: str):
        """The LP of this kind: matrix, gaps, column bounds and HiGHS solver."""
        return bb.R, bb.g, bb.pinned_bounds(bb.n_disp), solver


class _StrictLP:
    """Strict jamming: the collective LP with the box strain at fixed volume as columns."""

    name = "strict"

    def lp(self, bb: _Backbone, n: int, unit: float, solver: str):
        """The LP of this kind: matrix, gaps, column bounds and HiGHS solver."""
        R = bb.strain_columns(n)
        # strain columns carry |r| [length]; per mean diameter like the displacements
        scale = np.ones(R.shape[1])
        scale[bb.n_disp:] = 1.0 / unit
        R = sp.csr_matrix(R @ sp.diags(scale))
        return R, bb.g, bb.pinned_bounds(R.shape[1]), solver


LOCAL, COLLECTIVE, STRICT = _LocalLP(), _CollectiveLP(), _StrictLP()


def _local_rows(R: sp.csr_matrix, first: NDArray[np.int64], idx: NDArray[np.int64], n: int,
                d: int) -> sp.csr_matrix:
    """Rows of the rigidity matrix split per end, shape (2 Nc, d Ns): ``-n . y_i`` then ``+n . y_j``.

    Each contact seen from one particle, the other held fixed (the local LP);
    ``first`` is the particle ``i`` of every row, ``idx`` the column particles.
    """
    col_of = np.full(n, -1, dtype=np.int64)
    col_of[idx] = np.arange(len(idx))
    coo = R.tocoo()
    nc = R.shape[0]
    rows = np.where(coo.col // d == col_of[first][coo.row], coo.row, coo.row + nc)
    return sp.csr_matrix((coo.data, (rows, coo.col)), shape=(2 * nc, R.shape[1]))


def _full_motion(z: NDArray[np.float64], free: NDArray[np.bool_], d: int) -> Motion:
    """``(y_free, e)`` to the motion (relative displacements (Ns, d), strain coordinates), as :class:`_Search` gives it."""
    y = np.zeros(len(free))
    y[free] = z[:free.sum()]
    y = y.reshape(-1, d)
    return Motion(y - np.median(y, axis=0), z[free.sum():])


def _pin(contacts: NDArray[np.int64], idx: NDArray[np.int64], n: int) -> int:
    """Position in ``idx`` of the best-connected particle (least likely to rattle)."""
    z = np.bincount(contacts.ravel(), minlength=n)[idx]
    return int(np.argmax(z))
