"""Collective and strict jamming of linked packings by randomized LPs (chains paper Sec. V, Eqs. 40-42).

The LP of :mod:`jamflow.protocols.certify` (its ``MotionLP``: maximise ``b . y`` subject
to ``A y >= 0``, ``|y_k| <= 1``, HiGHS) is run on the constrained extended rigidity
matrix ``A = R_E = R0 B^T`` (:func:`jamflow.chains.hessian.extended_rigidity`): ``y``
are the true degrees of freedom ``y_t`` (motions that keep every link, and with strain
the volume), ``R_E y_t >= 0`` keeps every contact from closing. The ``d`` uniform
translations are removed from the basis (they are added to ``Gamma`` as columns), so a
jammed backbone admits only ``y_t = 0``.

Loads are random (normal) and each is solved with both signs. Before the LPs the
counting of :func:`jamflow.network.count_bodies` takes out what it decides by rank:
clusters that rattle whole leave the packing, and the free motions of held clusters
(a trimer swinging about its only touching sphere, a dangling chain end, a rotator)
are removed from the basis like the translations, so their spheres move with the
rest of their cluster and the contacts of the force-bearing spheres stay.

A solution with a coordinate above :data:`~jamflow.tolerances.CERTIFY_MOTION_TOL` is
a motion. ``B^T y_t`` is defined up to a uniform translation (removed from the
basis, which spreads a local motion over every sphere by its mean), so the median
displacement of the backbone is subtracted before the moving spheres (displacement
above the same tolerance, danglers ignored) are read off. When they form rattling
groups (connected through contacts and links, not wrapping around the box, at most
``max_cluster_fraction`` of the backbone) their whole clusters are removed, as the
paper's Sec. V removes rattling clusters, and the LP runs again on the rest; a
larger or wrapping moving group, or a motion of the box strain, is an unjamming
motion. Collective jamming uses the positions-only basis (fixed box), strict jamming
the strain basis with ``det F = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..models.spheres.potential import HARMONIC, PowerLawPotential
from ..network import BodyCount, count_bodies
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
from .hessian import _Geometry, _geometry, extended_rigidity

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
        Spheres outside the certified backbone: danglers and the spheres of removed
        clusters (by counting or by the LPs).
    motion : ndarray, shape (N, d) or None
        Unjamming displacement of the backbone when one was found.
    motion_stage : str
        ``"collective"``, ``"strict"`` or ``""``.
    n_lp : int
        LPs solved.
    count : BodyCount
        The counting the LPs started from (fixed box).
    lp_removed : ndarray of bool, shape (C,)
        Clusters the LPs removed as rattling (moving groups).
    """

    classification: str
    rattler: NDArray[np.bool_]
    motion: NDArray[np.float64] | None
    motion_stage: str
    n_lp: int
    count: BodyCount
    lp_removed: NDArray[np.bool_]


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


def _backbone_free_motions(count: BodyCount, idx: NDArray[np.int64], d: int) -> NDArray[np.float64]:
    """Free motions of the clusters kept in the subpacking ``idx``, in its centre coordinates (n_sub d, k)."""
    rows = (d * idx[:, None] + np.arange(d)).ravel()
    free = count.free_motions.tocsr()[rows].toarray()
    # every column lives on one cluster: all of it is kept, or none
    return free[:, np.linalg.norm(free, axis=0) > 0.5]


def _moving_groups(geo: _Geometry, moving: NDArray[np.bool_]) -> list[tuple[NDArray[np.int64], bool]]:
    """Connected groups of moving spheres through contacts and links, and whether each wraps."""
    edges = np.concatenate([np.stack([geo.pairs.i, geo.pairs.j], axis=1),
                            np.stack([geo.links.i, geo.links.j], axis=1)])
    dx = np.concatenate([geo.pairs.dx, geo.link_vector])
    return moving_clusters(moving, edges, dx, 1e-6)


def _search(packing: Packing, count: BodyCount, removed: NDArray[np.bool_], strain: bool, loads: list, solver: str,
            max_cluster_fraction: float, potential: PowerLawPotential
            ) -> tuple[NDArray[np.bool_], NDArray[np.float64] | None, int]:
    """Run one kind of LP, removing rattling clusters; returns (removed clusters, unjamming motion or None, LPs)."""
    n_lp = 0
    while True:
        sub, idx = _subpacking(packing, ~removed[count.cluster])
        free = _backbone_free_motions(count, idx, packing.d)
        RE, _, _, basis = extended_rigidity(sub, strain=strain, potential=potential, translations=True, exclude=free)
        if RE.shape[1] == 0:
            return removed, None, n_lp
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
            return removed, None, n_lp
        nd = sub.n * sub.d
        held = ~count.dangler[idx]
        disp = motion[:nd].reshape(sub.n, sub.d)
        # the basis has no uniform translation: take the one that leaves most spheres at rest
        disp = disp - np.median(disp[held], axis=0)
        moving = held & (np.linalg.norm(disp, axis=1) > CERTIFY_MOTION_TOL)
        strain_moves = strain and np.max(np.abs(motion[nd:]), initial=0.0) > CERTIFY_MOTION_TOL
        groups = _moving_groups(_geometry(sub, potential), moving)
        small = all(not wraps and len(members) <= max_cluster_fraction * sub.n for members, wraps in groups)
        if strain_moves or not small or not np.any(moving):
            full = np.zeros((packing.n, packing.d))
            full[idx] = disp
            return removed, full, n_lp
        removed = removed.copy()
        removed[count.cluster[idx[moving]]] = True


def certify_linked(packing: Packing, strict: bool = True, loads: int = DEFAULT_LOADS, seed: int = 0,
                   max_cluster_fraction: float = DEFAULT_MAX_CLUSTER_FRACTION, solver: str = DEFAULT_SOLVER,
                   potential: PowerLawPotential = HARMONIC) -> LinkedCertificate:
    """Classify a (soft, force-balanced or hard) linked packing in the jamming hierarchy (module doc).

    Contacts are the overlapping pairs that are not linked (soft packings at ``P0``).
    """
    geo = _geometry(packing, potential)
    count = count_bodies(np.stack([geo.pairs.i, geo.pairs.j], axis=1), packing.n, packing.d, packing.links,
                         packing.position, packing.box)
    rng = np.random.default_rng(seed)
    size = packing.n * packing.d + packing.d * (packing.d + 1) // 2
    load_list = random_loads(rng, size, loads)
    removed, motion, n_lp = _search(packing, count, count.removed, False, load_list, solver, max_cluster_fraction,
                                    potential)

    def result(kind: str, stage: str, n: int) -> LinkedCertificate:
        rattler = removed[count.cluster] | count.dangler
        return LinkedCertificate(kind, rattler, motion, stage, n, count, removed & ~count.removed)

    if motion is not None:
        return result("not_jammed", "collective", n_lp)
    if not strict:
        return result("collectively_jammed", "", n_lp)
    removed, motion, more = _search(packing, count, removed, True, load_list, solver, max_cluster_fraction, potential)
    if motion is not None:
        return result("collectively_jammed", "strict", n_lp + more)
    return result("strictly_jammed", "", n_lp + more)
