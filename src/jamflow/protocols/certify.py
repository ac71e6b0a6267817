"""Jamming certificates: local, collective and strict jamming by randomized LPs.

Implements the randomized linear-programming test of Donev, Torquato, Stillinger and
Connelly, J. Comput. Phys. 197, 139 (2004), in the form of the soft-chains paper,
Sec. V (Eqs. 40-42), for the jamming hierarchy of Torquato and Stillinger:

* **locally jammed**: no particle can move with all others held fixed;
* **collectively jammed**: no subset of particles can move, the periodic box fixed;
* **strictly jammed**: collectively jammed, and no motion exists even when the box
  may also deform at fixed volume (symmetric strain with ``Tr eps = 0``).

A motion ``(y, eps)`` is allowed to first order when no contact closes,
``R (y, eps) >= -g`` with ``R`` the rigidity matrix (:mod:`jamflow.network.rigidity`) and
``g`` either zero (exact contacts) or the contacts' actual gaps ("gap-aware"; the
linearised constraint is conservative because ``|r + dr| >= n . (r + dr)``). The
LP maximises a random load ``b . y`` over the allowed motions with every
coordinate bounded by one mean diameter; the packing (or its backbone) is jammed
when no load of either sign finds a motion. With exact contacts the allowed motions
form a cone ``C``; the optimum for ``+b`` and ``-b`` is zero only when ``b`` is
orthogonal to ``C``, which has probability zero unless ``C`` is trivial, so one
load of both signs decides in exact arithmetic; further loads guard against
motions that round-off hides. With gaps the allowed set is a polytope (the
first-order cage), bounded exactly when the cone of the same network is trivial;
a load that meets a recession direction drives the solution to the bound. The
cage of a rigid network can still be much larger than the gaps when the network
is nearly floppy; its size is reported, and a gap-aware solution at the bound is
decided by the exact-contact LP with the same load (see :class:`_Search`).

Rattlers are removed in stages and each removal is recorded: (1) particles with
fewer than ``d + 1`` backbone contacts, (2) particles that move in the local LP
(all others fixed), (3) rattling clusters: moving connected groups of the
collective LP that neither wrap around the periodic box nor exceed a stated
fraction of the backbone. A moving group that wraps around the box (a sliding row
or plane) or is larger is a collective unjamming motion and is reported.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import highspy
import numpy as np
import scipy.sparse as sp
import xarray as xr
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ..highs import new_highs
from ..io import new_dataset_attrs
from ..network import (
    ContactSet,
    contact_jacobian,
    isostatic_count,
    prune_rattlers,
    rigid_network,
    sphere_contacts,
    strain_basis,
    strain_motion,
)
from ..network.spheres import require_plain_spheres
from ..state.packing import Packing, near_pairs
from ..tolerances import CERTIFY_BOUND_TOL, CERTIFY_MOTION_TOL, CONTACT_GAP_TOL

__all__ = [
    "CLASSIFICATIONS",
    "RATTLER_STAGES",
    "JammingCertificate",
    "LPRecord",
    "MotionLP",
    "certificate_to_dataset",
    "certify",
    "moving_clusters",
    "random_loads",
]

#: Jamming categories, weakest first.
CLASSIFICATIONS: tuple[str, ...] = ("not_jammed", "locally_jammed", "collectively_jammed", "strictly_jammed")

#: Why a particle left the backbone (index = code stored in ``rattler_stage``).
RATTLER_STAGES: tuple[str, ...] = ("backbone", "coordination", "local_lp", "rattling_cluster")

#: LP kinds (index = code stored in ``lp_stage``).
LP_STAGES: tuple[str, ...] = ("local", "collective", "strict")

#: Default number of random loads; each is tried with both signs.
DEFAULT_LOADS: int = 2

#: Default HiGHS algorithm for the collective and strict LPs: the cone LPs are
#: massively degenerate (every constraint is tight at y = 0); the interior-point
#: method without crossover (cold for every load) beat the simplex (a cold dual
#: simplex, then primal simplex warm starts) on 3D soft packings at P0 = 1e-5
#: (``benchmarks/certify.py``): 6.9 s against 15.1 s at N = 1024, and the simplex's
#: cold first solve at N = 4096 was stopped after 14 min (interior point: 552 s for
#: the whole certificate). When interior point fails
#: (status not optimal) the LP falls back to the simplex and stays there. On a
#: jammed network the cone LP's feasible set is the point y = 0 (no interior), which
#: is what makes every LP method slow; exact-contact backbones that pass the
#: Roth-Whiteley test skip these LPs (``self_stress_test``, ``benchmarks/certify_speed.py``).
DEFAULT_SOLVER: str = "ipm"

_DUAL, _PRIMAL = 1, 4  # HiGHS simplex_strategy values

#: The Roth-Whiteley test (``self_stress_test``) is tried on backbones with at most
#: this many self stresses per contact: its self-stress basis is dense, and on a
#: strongly hyperstatic network the motion LPs are cheaper (triangular lattice
#: 12 x 8, 34 % self stresses: 0.4 s by LPs, 5-9 s by the test on a loaded machine;
#: soft 3D N = 4096 at P0 = 1e-5: 0.6 %).
SELF_STRESS_TEST_MAX_FRACTION: float = 0.05

#: Default largest rattling cluster, as a fraction of the current backbone.
DEFAULT_MAX_CLUSTER_FRACTION: float = 0.05


@dataclass(frozen=True)
class LPRecord:
    """One solved LP: kind, load index and sign, HiGHS status, optimum, cost."""

    stage: str
    rhs: str  # "gaps" (screening) or "zero" (exact contacts)
    load: int
    sign: int
    status: str
    objective: float
    time: float  # wall time [s]
    iterations: int
    max_displacement: float  # largest displacement (or strain coordinate) [mean diameters]


@dataclass(frozen=True)
class JammingCertificate:
    """Outcome of :func:`certify`.

    Attributes
    ----------
    classification : str
        Strongest category that holds, one of :data:`CLASSIFICATIONS`.
    contacts : ndarray of int64, shape (Nc, 2)
        Contact network tested (all particles).
    gap : ndarray, shape (Nc,)
        Relative gaps ``r / sigma_ij - 1`` of those contacts.
    rhs : str
        ``"zero"`` (exact contacts) or ``"gaps"`` (gap-aware constraints).
    rattler_stage : ndarray of int8, shape (N,)
        Index into :data:`RATTLER_STAGES` (0 = backbone).
    motion : ndarray, shape (N, d) or None
        Unjamming displacement [mean diameters, every coordinate at most 1]; zero on
        rattlers. None when no unjamming motion of the backbone was found.
    motion_strain : ndarray, shape (d, d) or None
        Box strain of the unjamming motion (strict test only).
    motion_stage : str
        ``"collective"``, ``"strict"`` or ``""``.
    strict_tested : bool
        Whether the strain LP ran.
    cage : float
        Gap-aware only: largest coordinate of the gap-aware LP solutions that found
        no unjamming motion [mean diameters], i.e. the first-order cage; 1 when a
        cage reaches the displacement bound.
    cage_at_bound : int
        Gap-aware loads whose cage reached the bound although the exact-contact
        cone is trivial (the cage is then at least one mean diameter).
    lp : list of LPRecord
    parameters : dict
    self_stress_decisions : int
        Backbones decided without LPs by the Roth-Whiteley test (see :func:`certify`).
    """

    classification: str
    contacts: NDArray[np.int64]
    gap: NDArray[np.float64]
    rhs: str
    rattler_stage: NDArray[np.int8]
    motion: NDArray[np.float64] | None
    motion_strain: NDArray[np.float64] | None
    motion_stage: str
    strict_tested: bool
    cage: float
    cage_at_bound: int
    lp: list[LPRecord] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)
    self_stress_decisions: int = 0

    @property
    def rattler(self) -> NDArray[np.bool_]:
        """Particles outside the certified backbone, shape (N,)."""
        return self.rattler_stage > 0

    @property
    def backbone_contacts(self) -> NDArray[np.int64]:
        """Contacts between backbone particles, shape (Nb, 2)."""
        r = self.rattler
        keep = ~(r[self.contacts[:, 0]] | r[self.contacts[:, 1]])
        return self.contacts[keep]


# --- LP models ---------------------------------------------------------------------


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
        self.h.setOptionValue("solver", solver)
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
        last basis needs a few pivots where a cold dual simplex needed thousands (3D N = 1024: 5 against 4285; N = 2048: 4
        against 7632). Loose gap LPs move their optimum to another corner of the
        displacement box with every load; there the cold dual simplex is faster
        (3D N = 96 at gap 0.1: 412 against 994 pivots), so they always start cold.
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


# --- helpers -------------------------------------------------------------------------


def _network(packing: Packing, gap_tol: float | None) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Contacts (explicit, else gap <= gap_tol) and their relative gaps."""
    if gap_tol is None and packing.contacts is not None:
        c = packing.contacts
        r = np.linalg.norm(sphere_contacts(packing.position, packing.box, c).separation, axis=1)
        return c, r / packing.sigma(c[:, 0], c[:, 1]) - 1.0
    tol = CONTACT_GAP_TOL if gap_tol is None else float(gap_tol)
    if not np.isfinite(tol):
        raise ValueError(f"gap tolerance must be finite, got {gap_tol}")
    pairs, h = near_pairs(packing, tol)
    return np.stack([pairs.i, pairs.j], axis=1), h


def moving_clusters(
    movers: NDArray[np.bool_], contacts: NDArray[np.int64], dx: NDArray[np.float64], tol: float
) -> list[tuple[NDArray[np.int64], bool]]:
    """Connected groups of moving particles (through contacts) and whether each wraps.

    Centres are unwrapped along a breadth-first spanning tree of each group; the
    group closes a loop around the periodic box when some contact disagrees with
    the unwrapped centres (by a lattice vector, i.e. by more than ``tol``).
    """
    n = len(movers)
    both = movers[contacts[:, 0]] & movers[contacts[:, 1]]
    c, e_dx = contacts[both], dx[both]
    e = np.arange(1, len(c) + 1, dtype=np.float64)
    # +(e+1) at (i, j) and -(e+1) at (j, i): edge index and direction in one matrix
    edge = sp.csr_matrix(
        (np.concatenate([e, -e]), (np.concatenate([c[:, 0], c[:, 1]]), np.concatenate([c[:, 1], c[:, 0]]))),
        shape=(n, n),
    )
    graph = sp.csr_matrix(abs(edge))
    _, label = connected_components(graph, directed=False)
    u = np.zeros((n, dx.shape[1]))
    groups = []
    for lab in np.unique(label[movers]):
        members = np.flatnonzero(label == lab)
        groups.append((lab, members))
        if len(members) == 1:
            continue
        order, pred = breadth_first_order(graph, int(members[0]), directed=False, return_predecessors=True)
        k = np.asarray(edge[pred[order[1:]], order[1:]]).ravel()
        step = np.sign(k)[:, None] * e_dx[np.abs(k).astype(np.int64) - 1]
        # predecessors precede their children in breadth-first order
        for v, p, st in zip(order[1:], pred[order[1:]], step):
            u[v] = u[p] + st
    mismatch = np.linalg.norm(u[c[:, 1]] - u[c[:, 0]] - e_dx, axis=1) > tol
    wrapping = set(label[c[mismatch, 0]].tolist())
    return [(members, bool(lab in wrapping)) for lab, members in groups]


def random_loads(rng: np.random.Generator, n: int, loads: int) -> list[NDArray[np.float64]]:
    """``loads`` random load vectors of length ``n`` (standard normal components) from ``rng``."""
    return [rng.standard_normal(n) for _ in range(loads)]


# --- the certificate -----------------------------------------------------------------


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

    def _motion(self, z: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        y = z[: self.n_disp].reshape(-1, self.d)
        # local LPs move each particle alone; otherwise the majority's motion is a translation
        rel = y if self.kind == "local" else y - np.median(y, axis=0)
        return rel, z[self.n_disp:]

    def run(self, k: int, s: int, load: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """Motion ``(displacements (Ns, d), strain coordinates)`` for one load and sign, or None."""
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
        rel, e = self._motion(z)
        size = max(float(np.linalg.norm(rel, axis=1).max(initial=0.0)), float(np.abs(e).max(initial=0.0)))
        self.record(self.kind, "zero", k, s, status, obj, t, it, size)
        if size > CERTIFY_MOTION_TOL:
            return rel, e
        if self.gap_lp is not None:
            # bounded cone, but the first-order cage reaches the displacement bound
            self.cage = max(self.cage, 1.0)
            self.cage_at_bound += 1
        return None


def certify(
    packing: Packing,
    *,
    strict: bool = False,
    gap_tol: float | None = None,
    rhs: str | None = None,
    loads: int = DEFAULT_LOADS,
    seed: int = 0,
    max_cluster_fraction: float = DEFAULT_MAX_CLUSTER_FRACTION,
    solver: str = DEFAULT_SOLVER,
    both_signs: bool = True,
    self_stress_test: bool = True,
    progress: Any = None,
) -> JammingCertificate:
    """Classify a packing in the jamming hierarchy (see module docstring).

    Parameters
    ----------
    packing : Packing
        Any packing; overlaps (soft packings) are allowed and count as contacts
        with zero gap.
    strict : bool
        Also test strict jamming (box strain at fixed volume).
    gap_tol : float, optional
        Pairs with relative gap ``r / sigma_ij - 1 <= gap_tol`` are the contact
        network; default: the packing's explicit contacts, else
        :data:`~jamflow.tolerances.CONTACT_GAP_TOL`.
    rhs : {"zero", "gaps"}, optional
        Right-hand side of the non-overlap constraints: exact contacts, or the
        pairs' actual (non-negative) gaps. Default ``"gaps"`` when ``gap_tol`` is
        given, else ``"zero"``.
    loads : int
        Random loads per LP kind, each solved with both signs.
    seed : int
        Seed of the random loads.
    max_cluster_fraction : float
        Largest moving group (fraction of the current backbone) removed as a
        rattling cluster; a larger or box-wrapping group is an unjamming motion.
    solver : str
        HiGHS ``solver`` option for the collective and strict LPs ("ipm",
        "simplex", "choose"); the decoupled local LPs use simplex.
    both_signs : bool
        Solve every load with both signs (Donev et al.). ``False`` is an ablation
        for benchmarks only: a motion confined to a pointed cone is then missed
        whenever the load points into its polar cone.
    self_stress_test : bool
        With exact contacts (``rhs="zero"``), decide a backbone without the large
        motion LPs when the Roth-Whiteley test is clear
        (:func:`jamflow.network.rigid_network`: full rank after pinning one
        particle and a strictly positive self stress, so every cone LP would return
        no motion): collectively jammed; with ``strict``, the strain columns are
        decided by :func:`jamflow.network.strain_motion` (a kernel of ``[R E]``, or
        an LP with one row per self stress), which also gives the unjamming motion.
        Unclear cases and ``False`` run the motion LPs.
    progress : tqdm-like, optional
        Object with ``update(n)``; advanced once per LP.

    Returns
    -------
    JammingCertificate
    """
    require_plain_spheres(packing, "the jamming certificate")
    if loads < 1:
        raise ValueError(f"loads must be >= 1, got {loads}")
    if not 0.0 <= max_cluster_fraction < 1.0:
        raise ValueError(f"max_cluster_fraction must be in [0, 1), got {max_cluster_fraction}")
    rhs = rhs or ("gaps" if gap_tol is not None else "zero")
    if rhs not in ("zero", "gaps"):
        raise ValueError(f"rhs must be 'zero' or 'gaps', got {rhs!r}")
    n, d = packing.n, packing.d
    unit = float(np.mean(packing.diameter))
    contacts, gap = _network(packing, gap_tol)
    if len(contacts):
        cs = sphere_contacts(packing.position, packing.box, contacts)
        unit_vec, dist = cs.normal, np.linalg.norm(cs.separation, axis=1)
        g_abs = np.maximum(gap, 0.0) * packing.sigma(contacts[:, 0], contacts[:, 1])
    else:
        cs = ContactSet(contacts[:, 0], contacts[:, 1], np.zeros((0, d)), np.zeros((0, d)))
        unit_vec, dist, g_abs = cs.normal, np.zeros(0), np.zeros(0)
    dx = unit_vec * dist[:, None]
    g = g_abs / unit
    rng = np.random.default_rng(seed)
    records: list[LPRecord] = []
    stage = np.zeros(n, dtype=np.int8)
    active = np.ones(n, dtype=bool)
    searches: list[_Search] = []
    motion = motion_strain = None
    motion_stage = ""
    params = {"strict": strict, "gap_tol": gap_tol, "rhs": rhs, "loads": loads, "seed": seed,
                  "max_cluster_fraction": max_cluster_fraction, "solver": solver, "both_signs": both_signs,
              "self_stress_test": self_stress_test}

    def record(kind: str, rhs_kind: str, k: int, s: int, status: str, obj: float, t: float, it: int,
               size: float) -> None:
        records.append(LPRecord(kind, rhs_kind, k, s, status, obj, t, it, size))
        if progress is not None:
            progress.update(1)

    def search(kind: str, A: sp.spmatrix, rows_g: NDArray[np.float64], upper: NDArray[np.float64],
               n_disp: int, lp_solver: str):
        srch = _Search(kind, A, rows_g, upper, n_disp, d, rhs, lp_solver, record)
        searches.append(srch)
        for k, b in enumerate(random_loads(rng, A.shape[1], loads)):
            for s in ((1, -1) if both_signs else (1,)):
                found = srch.run(k, s, b)
                if found is not None:
                    return found
        return None

    collective_jammed = strictly_jammed = False
    strict_motion = None
    decisions = 0
    basis = strain_basis(d, volume_preserving=True)
    while True:
        new = prune_rattlers(contacts, n, dofs_per_body=d, active=active)
        stage[new] = RATTLER_STAGES.index("coordination")
        active &= ~new
        if not active.any():
            break
        sel = active[contacts[:, 0]] & active[contacts[:, 1]]
        idx = np.flatnonzero(active)
        n_disp = d * len(idx)

        # local jamming: every contact end constrains one particle, the other held fixed
        R_fixed_box = contact_jacobian(cs.select(sel), n, d, bodies=idx)
        A_local = _local_rows(R_fixed_box, contacts[sel, 0], idx, n, d)
        found = search("local", A_local, np.concatenate([g[sel], g[sel]]), np.ones(n_disp), n_disp, "simplex")
        if found is not None:
            moved = np.linalg.norm(found[0], axis=1) > CERTIFY_MOTION_TOL
            stage[idx[moved]] = RATTLER_STAGES.index("local_lp")
            active[idx[moved]] = False
            continue

        # the best-connected particle is pinned (removes the translations)
        p = _pin(contacts[sel], idx, n)
        found = strict_motion = None
        free = np.ones(n_disp, dtype=bool)
        free[d * p:d * p + d] = False
        rigid = None
        if self_stress_test and rhs == "zero":
            # a soft packing's contact forces are (to its force tolerance) a positive self stress
            guess = packing.force[sel] if packing.force is not None and gap_tol is None else None
            rigid = rigid_network(R_fixed_box[:, free], seed, guess,
                                  max_self_stresses=int(SELF_STRESS_TEST_MAX_FRACTION * R_fixed_box.shape[0]))
        if rigid is not None:
            verdict = "rigid"
            if strict:
                strain_cols = contact_jacobian(cs.select(sel), n, d, strain="traceless", bodies=idx)[:, n_disp:] / unit
                verdict, z = strain_motion(rigid, R_fixed_box[:, free], strain_cols)
                if verdict == "motion":
                    strict_motion = _full_motion(z, free, d)
                    if np.abs(strict_motion[1]).max() <= CERTIFY_MOTION_TOL:
                        verdict, strict_motion = "unclear", None
            if verdict != "unclear":
                decisions += 1
                collective_jammed = True
                strictly_jammed = strict and verdict == "rigid"
                break
        if strict:
            # strain LP first: without a motion there, none exists at fixed box either
            R = contact_jacobian(cs.select(sel), n, d, strain="traceless", bodies=idx)
            # strain columns carry |r| [length]; per mean diameter like the displacements
            scale = np.ones(R.shape[1])
            scale[n_disp:] = 1.0 / unit
            R = sp.csr_matrix(R @ sp.diags(scale))
            upper = np.ones(R.shape[1])
            upper[d * p:d * p + d] = 0.0
            found = search("strict", R, g[sel], upper, n_disp, solver)
            if found is None:
                collective_jammed = strictly_jammed = True
                break
            if np.abs(found[1]).max(initial=0.0) > CERTIFY_MOTION_TOL:
                # the motion needs the strain: the fixed-box test decides the rest
                strict_motion, found = found, None
        if found is None:
            R = R_fixed_box
            upper = np.ones(n_disp)
            upper[d * p:d * p + d] = 0.0
            found = search("collective", R, g[sel], upper, n_disp, solver)
        if found is None:
            collective_jammed = True
            break
        y = found[0]
        movers = np.zeros(n, dtype=bool)
        movers[idx] = np.linalg.norm(y, axis=1) > CERTIFY_MOTION_TOL
        clusters = moving_clusters(movers, contacts[sel], dx[sel], 0.25 * float(packing.diameter.min()))
        limit = max(1, int(max_cluster_fraction * len(idx)))
        if all((not wraps) and len(m) <= limit for m, wraps in clusters):
            stage[movers] = RATTLER_STAGES.index("rattling_cluster")
            active &= ~movers
            continue
        motion = np.zeros((n, d))
        motion[idx] = y
        motion_stage = "collective"
        break

    if not active.any():
        classification = "not_jammed"
    elif strictly_jammed:
        classification = "strictly_jammed"
    elif collective_jammed:
        classification = "collectively_jammed"
        if strict_motion is not None:
            motion = np.zeros((n, d))
            motion[idx] = strict_motion[0]
            motion_strain = np.einsum("k,kab->ab", strict_motion[1], basis)
            motion_stage = "strict"
    else:
        classification = "locally_jammed"
    strict_tested = strict and collective_jammed
    return JammingCertificate(
        classification=classification,
        contacts=contacts,
        gap=gap,
        rhs=rhs,
        rattler_stage=stage,
        motion=motion,
        motion_strain=motion_strain,
        motion_stage=motion_stage,
        strict_tested=strict_tested,
        cage=max((srch.cage for srch in searches), default=0.0),
        cage_at_bound=sum(srch.cage_at_bound for srch in searches),
        lp=records,
        parameters=params,
        self_stress_decisions=decisions,
    )


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


def _full_motion(z: NDArray[np.float64], free: NDArray[np.bool_],
                 d: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(y_free, e)`` to (relative displacements (Ns, d), strain coordinates), as :class:`_Search` returns them."""
    y = np.zeros(len(free))
    y[free] = z[:free.sum()]
    y = y.reshape(-1, d)
    return y - np.median(y, axis=0), z[free.sum():]


def _pin(contacts: NDArray[np.int64], idx: NDArray[np.int64], n: int) -> int:
    """Position in ``idx`` of the best-connected particle (least likely to rattle)."""
    z = np.bincount(contacts.ravel(), minlength=n)[idx]
    return int(np.argmax(z))


# --- dataset -------------------------------------------------------------------------


def certificate_to_dataset(cert: JammingCertificate, packing: Packing, parameters: dict[str, Any] | None = None) -> xr.Dataset:
    """The certificate as a dataset (variables with units and long names, provenance)."""
    n, d = packing.n, packing.d
    c = cert.contacts
    rattler = cert.rattler
    n_backbone = int((~rattler).sum())
    n_bc = len(cert.backbone_contacts)
    flag = {"units": "1"}
    motion = np.zeros((n, d)) if cert.motion is None else cert.motion
    strain = np.zeros((d, d)) if cert.motion_strain is None else cert.motion_strain
    recs = cert.lp
    data_vars = {
        "contact_i": (("contact",), c[:, 0], {**flag, "long_name": "first particle of a tested contact (i < j)"}),
        "contact_j": (("contact",), c[:, 1], {**flag, "long_name": "second particle of a tested contact (i < j)"}),
        "contact_gap": (("contact",), cert.gap, {**flag, "long_name": "relative gap r / sigma_ij - 1 of a tested contact"}),
        "rattler": (("particle",), rattler.astype(np.int8), {
            **flag, "long_name": "rattler flag (1 = outside the certified backbone)",
            "flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "backbone rattler"}),
        "rattler_stage": (("particle",), cert.rattler_stage, {
            **flag, "long_name": "stage at which a particle was removed as a rattler",
            "flag_values": np.arange(len(RATTLER_STAGES), dtype=np.int8),
            "flag_meanings": " ".join(RATTLER_STAGES)}),
        "unjamming_motion": (("particle", "spatial"), motion, {
            **flag, "long_name": "unjamming displacement found by the LP (zero if none)",
            "comment": "in mean diameters, every coordinate bounded by 1; only the direction is "
                       "meaningful for exact contacts; zero on rattlers"}),
        "unjamming_strain": (("spatial", "spatial_2"), strain, {
            **flag, "long_name": "symmetric box strain of the unjamming motion (strict test; zero if none)"}),
        "lp_stage": (("lp",), np.array([LP_STAGES.index(r.stage) for r in recs], dtype=np.int8), {
            **flag, "long_name": "kind of LP", "flag_values": np.arange(len(LP_STAGES), dtype=np.int8),
            "flag_meanings": " ".join(LP_STAGES)}),
        "lp_rhs": (("lp",), np.array([r.rhs == "gaps" for r in recs], dtype=np.int8), {
            **flag, "long_name": "right-hand side of the LP", "flag_values": np.array([0, 1], dtype=np.int8),
            "flag_meanings": "zero_exact_contacts gaps"}),
        "lp_load": (("lp",), np.array([r.load for r in recs], dtype=np.int32), {**flag, "long_name": "random load index"}),
        "lp_sign": (("lp",), np.array([r.sign for r in recs], dtype=np.int8), {**flag, "long_name": "sign of the load"}),
        "lp_optimal": (("lp",), np.array([r.status == "Optimal" for r in recs], dtype=np.int8), {
            **flag, "long_name": "HiGHS model status is Optimal (1) or not (0)"}),
        "lp_objective": (("lp",), np.array([r.objective for r in recs]), {
            **flag, "long_name": "optimum of the load times the displacement (mean diameters)"}),
        "lp_time": (("lp",), np.array([r.time for r in recs]), {"units": "s", "long_name": "wall time of the LP solve"}),
        "lp_iterations": (("lp",), np.array([r.iterations for r in recs], dtype=np.int64), {
            **flag, "long_name": "simplex plus interior-point iterations"}),
        "lp_max_displacement": (("lp",), np.array([r.max_displacement for r in recs]), {
            **flag, "long_name": "largest particle displacement (or strain) of the LP solution, in mean diameters"}),
    }
    attrs = new_dataset_attrs(
        f"jamflow jamming certificate: {cert.classification}",
        parameters if parameters is not None else cert.parameters,
        classification=cert.classification,
        rhs=cert.rhs,
        strict_tested=cert.strict_tested,
        motion_stage=cert.motion_stage,
        has_unjamming_motion=cert.motion is not None,
        d=d,
        N=n,
        n_rattlers=int(rattler.sum()),
        n_backbone=n_backbone,
        n_contacts=len(c),
        n_backbone_contacts=n_bc,
        isostatic_count=isostatic_count(n_backbone, d, global_dofs=d),
        n_lp=len(recs),
        lp_time_total=float(sum(r.time for r in recs)),
        cage=cert.cage,
        cage_at_bound=cert.cage_at_bound,
        n_self_stress_decisions=cert.self_stress_decisions,
        packing_protocol=packing.protocol,
    )
    return xr.Dataset(data_vars=data_vars, attrs=attrs)
