"""The jamming hierarchy, tested backbone by backbone: rattlers removed in stages, then
the LP kinds in turn (:func:`certify`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ...network import (
    ContactSet,
    prune_rattlers,
    rigid_network,
    sphere_contacts,
    strain_basis,
    strain_motion,
)
from ...network.spheres import require_plain_spheres
from ...state.packing import Packing, near_pairs
from ...tolerances import CONTACT_GAP_TOL
from .lp import (
    COLLECTIVE,
    LOCAL,
    STRICT,
    LPKind,
    Motion,
    _Backbone,
    _backbone,
    _full_motion,
    _Search,
    random_loads,
)
from .record import RATTLER_STAGES, JammingCertificate, LPRecord

#: Default number of random loads; each is tried with both signs.
DEFAULT_LOADS: int = 2

#: Default HiGHS algorithm of the collective and strict LPs: interior point without
#: crossover, cold for every load; an LP it does not solve falls back to the simplex
#: (measured: docs/notes/certify-constants.md#default_solver).
DEFAULT_SOLVER: str = "ipm"

#: The Roth-Whiteley test (``self_stress_test``) is tried on backbones with at most this
#: many self stresses per contact: its self-stress basis is dense, and on a strongly
#: hyperstatic network the motion LPs are cheaper
#: (measured: docs/notes/certify-constants.md#self_stress_test_max_fraction).
SELF_STRESS_TEST_MAX_FRACTION: float = 0.05

#: Default largest rattling cluster, as a fraction of the current backbone.
DEFAULT_MAX_CLUSTER_FRACTION: float = 0.05


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


@dataclass
class _Verdict:
    """How one backbone ended: particles to remove (and at which stage), or a decision:
    collectively / strictly jammed, an unjamming motion (N, d) with its box strain."""

    remove: NDArray[np.bool_] | None = None
    stage: str = ""
    collective: bool = False
    strict: bool = False
    motion: NDArray[np.float64] | None = None
    strain: NDArray[np.float64] | None = None
    motion_stage: str = ""


class _Certification:
    """The tests of one :func:`certify` call: the settings, the random loads (one
    generator for all searches, drawn in the order the searches run), the LP records
    and the searches run (for the cage)."""

    def __init__(self, packing: Packing, options: dict[str, Any], unit: float, progress: Any) -> None:
        self.packing, self.unit, self.progress = packing, unit, progress
        self.strict, self.rhs, self.loads = options["strict"], options["rhs"], options["loads"]
        self.seed, self.solver, self.both_signs = options["seed"], options["solver"], options["both_signs"]
        self.self_stress_test, self.gap_tol = options["self_stress_test"], options["gap_tol"]
        self.max_cluster_fraction = options["max_cluster_fraction"]
        self.rng = np.random.default_rng(self.seed)
        self.records: list[LPRecord] = []
        self.searches: list[_Search] = []
        self.decisions = 0
        self.basis = strain_basis(packing.d, volume_preserving=True)

    def record(self, kind: str, rhs_kind: str, k: int, s: int, status: str, obj: float, t: float, it: int,
               size: float) -> None:
        self.records.append(LPRecord(kind, rhs_kind, k, s, status, obj, t, it, size))
        if self.progress is not None:
            self.progress.update(1)

    def search(self, kind: LPKind, bb: _Backbone) -> Motion | None:
        """Random loads (both signs) on the LP of ``kind``: the first motion found, or None."""
        A, rows_g, upper, lp_solver = kind.lp(bb, self.packing.n, self.unit, self.solver)
        srch = _Search(kind.name, A, rows_g, upper, bb.n_disp, bb.d, self.rhs, lp_solver, self.record)
        self.searches.append(srch)
        for k, b in enumerate(random_loads(self.rng, A.shape[1], self.loads)):
            for s in ((1, -1) if self.both_signs else (1,)):
                motion = srch.run(k, s, b)
                if motion is not None:
                    return motion
        return None

    def test(self, bb: _Backbone, contacts: NDArray[np.int64], dx: NDArray[np.float64]) -> _Verdict:
        """One backbone through the LP kinds: local, then (without a local motion, and
        unless the Roth-Whiteley test decides) strict and collective."""
        n = self.packing.n
        local = self.search(LOCAL, bb)
        if local is not None:
            return _Verdict(remove=bb.movers(local, n), stage="local_lp")
        verdict = self.self_stress_verdict(bb)
        if verdict is not None:
            return verdict
        motion = strict_motion = None
        if self.strict:
            # strain LP first: without a motion there, none exists at fixed box either
            motion = self.search(STRICT, bb)
            if motion is None:
                return _Verdict(collective=True, strict=True)
            if motion.needs_strain:
                # the motion needs the strain: the fixed-box test decides the rest
                strict_motion, motion = motion, None
        if motion is None:
            motion = self.search(COLLECTIVE, bb)
        if motion is None:
            return self.collectively_jammed(bb, strict_motion)
        return self.collective_motion(bb, motion, contacts, dx)

    def self_stress_verdict(self, bb: _Backbone) -> _Verdict | None:
        """With exact contacts, the Roth-Whiteley test of the backbone: its verdict, or
        None when it is not clear (the LPs decide)."""
        if not (self.self_stress_test and self.rhs == "zero"):
            return None
        free = bb.free
        # a soft packing's contact forces are (to its force tolerance) a positive self stress
        force = self.packing.force
        guess = force[bb.sel] if force is not None and self.gap_tol is None else None
        rigid = rigid_network(bb.R[:, free], self.seed, guess,
                              max_self_stresses=int(SELF_STRESS_TEST_MAX_FRACTION * bb.R.shape[0]))
        if rigid is None:
            return None
        verdict, strict_motion = "rigid", None
        if self.strict:
            strain_cols = bb.strain_columns(self.packing.n)[:, bb.n_disp:] / self.unit
            verdict, z = strain_motion(rigid, bb.R[:, free], strain_cols)
            if verdict == "motion":
                strict_motion = _full_motion(z, free, bb.d)
                if not strict_motion.needs_strain:
                    verdict, strict_motion = "unclear", None
        if verdict == "unclear":
            return None
        self.decisions += 1
        return self.collectively_jammed(bb, strict_motion, strict=self.strict and verdict == "rigid")

    def collectively_jammed(self, bb: _Backbone, strict_motion: Motion | None, strict: bool = False) -> _Verdict:
        """Collectively jammed; a motion that needs the box strain (strict test) comes with it."""
        if strict_motion is None:
            return _Verdict(collective=True, strict=strict)
        motion = np.zeros((self.packing.n, bb.d))
        motion[bb.idx] = strict_motion.displacement
        strain = np.einsum("k,kab->ab", strict_motion.strain, self.basis)
        return _Verdict(collective=True, strict=strict, motion=motion, strain=strain, motion_stage="strict")

    def collective_motion(self, bb: _Backbone, found: Motion, contacts: NDArray[np.int64],
                          dx: NDArray[np.float64]) -> _Verdict:
        """A motion of the backbone at a fixed box: rattling clusters to remove, or (a
        group that wraps around the box or is too large) an unjamming motion."""
        n, d = self.packing.n, bb.d
        movers = bb.movers(found, n)
        clusters = moving_clusters(movers, contacts[bb.sel], dx[bb.sel], 0.25 * float(self.packing.diameter.min()))
        limit = max(1, int(self.max_cluster_fraction * len(bb.idx)))
        if all((not wraps) and len(m) <= limit for m, wraps in clusters):
            return _Verdict(remove=movers, stage="rattling_cluster")
        motion = np.zeros((n, d))
        motion[bb.idx] = found.displacement
        return _Verdict(motion=motion, motion_stage="collective")


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
    """Classify a packing in the jamming hierarchy (see :mod:`jamflow.protocols.certify`).

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
    params = {"strict": strict, "gap_tol": gap_tol, "rhs": rhs, "loads": loads, "seed": seed,
              "max_cluster_fraction": max_cluster_fraction, "solver": solver, "both_signs": both_signs,
              "self_stress_test": self_stress_test}
    tests = _Certification(packing, params, unit, progress)
    stage = np.zeros(n, dtype=np.int8)
    active = np.ones(n, dtype=bool)
    verdict = _Verdict()
    while True:
        new = prune_rattlers(contacts, n, dofs_per_body=d, active=active)
        stage[new] = RATTLER_STAGES.index("coordination")
        active &= ~new
        if not active.any():
            break
        verdict = tests.test(_backbone(contacts, cs, g_abs / unit, active, n, d), contacts, dx)
        if verdict.remove is None:
            break
        stage[verdict.remove] = RATTLER_STAGES.index(verdict.stage)
        active &= ~verdict.remove
    return JammingCertificate(
        classification=_classification(active.any(), verdict),
        contacts=contacts,
        gap=gap,
        rhs=rhs,
        rattler_stage=stage,
        motion=verdict.motion,
        motion_strain=verdict.strain,
        motion_stage=verdict.motion_stage,
        strict_tested=strict and verdict.collective,
        cage=max((srch.cage for srch in tests.searches), default=0.0),
        cage_at_bound=sum(srch.cage_at_bound for srch in tests.searches),
        lp=tests.records,
        parameters=params,
        self_stress_decisions=tests.decisions,
    )


def _classification(any_backbone: bool, verdict: _Verdict) -> str:
    """The strongest category of :data:`CLASSIFICATIONS` the last backbone's verdict proves."""
    if not any_backbone:
        return "not_jammed"
    if verdict.strict:
        return "strictly_jammed"
    if verdict.collective:
        return "collectively_jammed"
    return "locally_jammed"
