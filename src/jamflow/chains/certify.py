"""Collective and strict jamming of linked packings by randomized LPs (chains paper Sec. V, Eqs. 40-42).

The LP of :mod:`jamflow.protocols.certify` (its ``MotionLP``: maximise ``b . y`` subject
to ``A y >= 0``, ``|y_k| <= 1``, HiGHS) is run on the constrained extended rigidity
matrix ``A = R_E = R0 B^T`` (:func:`jamflow.chains.hessian.extended_rigidity`): ``y``
are the true degrees of freedom ``y_t`` (motions that keep every link, and with strain
the volume), ``R_E y_t >= 0`` keeps every contact from closing. The ``d`` uniform
translations are removed from the basis (they are added to ``Gamma`` as columns), so a
jammed backbone admits only ``y_t = 0``.

Loads are random (normal) and each is solved with both signs. A solution with a
coordinate above :data:`~jamflow.tolerances.CERTIFY_MOTION_TOL` is a motion; the
spheres that move in ``B^T y_t`` (displacement above the same tolerance) are
removed when they form rattling groups (connected through contacts and links,
not wrapping around the box, at most ``max_cluster_fraction`` of the backbone; the
moving end of a chain, a dangler, is removed alone, paper Fig. 4) and the LP is
run again on what remains; a larger or wrapping moving group, or a motion of the
box strain, is an unjamming motion. Collective jamming uses the positions-only
basis (fixed box), strict jamming the strain basis with ``det F = 1``. Before the LPs
the counting of :func:`~jamflow.chains.clusters.count_clusters` removes danglers and
rattling clusters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..models.spheres.potential import HARMONIC, PowerLawPotential
from ..protocols.certify import (
    DEFAULT_LOADS,
    DEFAULT_MAX_CLUSTER_FRACTION,
    DEFAULT_SOLVER,
    MotionLP,
    moving_clusters,
    random_loads,
)
from ..state.packing import Packing
from ..tolerances import CERTIFY_MOTION_TOL
from .clusters import count_clusters
from .hessian import _geometry, extended_rigidity

__all__ = ["LinkedCertificate", "certify_linked"]


@dataclass(frozen=True)
class LinkedCertificate:
    """Outcome of :func:`certify_linked`.

    Attributes
    ----------
    classification : str
        ``"strictly_jammed"``, ``"collectively_jammed"`` or ``"not_jammed"`` (a
        linked packing has no local stage here).
    rattler : ndarray of bool, shape (N,)
        Spheres outside the certified backbone (counting and LP removals).
    motion : ndarray, shape (N, d) or None
        Unjamming displacement of the backbone when one was found.
    motion_stage : str
        ``"collective"``, ``"strict"`` or ``""``.
    n_lp : int
        LPs solved.
    """

    classification: str
    rattler: NDArray[np.bool_]
    motion: NDArray[np.float64] | None
    motion_stage: str
    n_lp: int


def _subpacking(packing: Packing, keep: NDArray[np.bool_]) -> tuple[Packing, NDArray[np.int64]]:
    """The packing of the spheres ``keep`` (with the links among them), and their indices."""
    idx = np.flatnonzero(keep)
    new = -np.ones(packing.n, np.int64)
    new[idx] = np.arange(idx.size)
    links = packing.links
    if links is not None:
        both = keep[links.i] & keep[links.j]
        from ..state.bodies import Links

        links = Links(new[links.i[both]], new[links.j[both]], links.length[both])
    sub = Packing(packing.position[idx], packing.diameter[idx], packing.box, links=links)
    return sub, idx


def _search(packing: Packing, active: NDArray[np.bool_], strain: bool, loads: list, solver: str,
            max_cluster_fraction: float, potential: PowerLawPotential) -> tuple[NDArray[np.bool_], NDArray[np.float64] | None, int]:
    """Run one kind of LP with rattler removal; returns (active, unjamming motion or None, LPs solved)."""
    n_lp = 0
    while True:
        sub, idx = _subpacking(packing, active)
        RE, _, _, basis = extended_rigidity(sub, strain=strain, potential=potential, translations=True)
        if RE.shape[1] == 0:
            return active, None, n_lp
        lp = MotionLP(sp.csr_matrix(RE), np.zeros(RE.shape[0]), np.ones(RE.shape[1]), solver)
        motion = None
        for load in loads:
            b = load[: RE.shape[1]]  # loads are drawn for the largest basis (all spheres and strain)
            for sign in (1.0, -1.0):
                _, _, y, _, _ = lp.solve(sign * b)
                n_lp += 1
                if np.max(np.abs(y)) > CERTIFY_MOTION_TOL:
                    motion = basis.T @ y
                    break
            if motion is not None:
                break
        if motion is None:
            return active, None, n_lp
        nd = sub.n * sub.d
        disp = motion[:nd].reshape(sub.n, sub.d)
        moving = np.linalg.norm(disp, axis=1) > CERTIFY_MOTION_TOL
        strain_moves = strain and np.max(np.abs(motion[nd:]), initial=0.0) > CERTIFY_MOTION_TOL
        geo = _geometry(sub, potential)
        edges = np.concatenate([np.stack([geo.pairs.i, geo.pairs.j], axis=1),
                                np.stack([geo.links.i, geo.links.j], axis=1)])
        dx = np.concatenate([geo.pairs.dx, geo.link_vector])
        groups = moving_clusters(moving, edges, dx, 1e-6)
        small = all(not wraps and len(members) <= max_cluster_fraction * sub.n for members, wraps in groups)
        if strain_moves or not small or not np.any(moving):
            full = np.zeros((packing.n, packing.d))
            full[idx] = disp
            return active, full, n_lp
        active = active.copy()
        active[idx[moving]] = False


def certify_linked(packing: Packing, strict: bool = True, loads: int = DEFAULT_LOADS, seed: int = 0,
                   max_cluster_fraction: float = DEFAULT_MAX_CLUSTER_FRACTION, solver: str = DEFAULT_SOLVER,
                   potential: PowerLawPotential = HARMONIC) -> LinkedCertificate:
    """Classify a (soft, force-balanced or hard) linked packing in the jamming hierarchy (module doc).

    Contacts are the overlapping pairs that are not linked (soft packings at ``P0``).
    """
    if packing.contacts is None:
        raise ValueError("certify_linked needs the packing's contacts (a soft-jam output)")
    active = ~count_clusters(packing.n, packing.d, packing.links, packing.contacts).rattler
    rng = np.random.default_rng(seed)
    size = packing.n * packing.d + packing.d * (packing.d + 1) // 2
    load_list = random_loads(rng, size, loads)
    active, motion, n_lp = _search(packing, active, False, load_list, solver, max_cluster_fraction, potential)
    if motion is not None:
        return LinkedCertificate("not_jammed", ~active, motion, "collective", n_lp)
    if not strict:
        return LinkedCertificate("collectively_jammed", ~active, None, "", n_lp)
    active, motion, more = _search(packing, active, True, load_list, solver, max_cluster_fraction, potential)
    if motion is not None:
        return LinkedCertificate("collectively_jammed", ~active, motion, "strict", n_lp + more)
    return LinkedCertificate("strictly_jammed", ~active, None, "", n_lp + more)
