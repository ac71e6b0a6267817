"""Rattling clusters and the isostatic count of bodies with motion spaces (chains paper Sec. II F, Fig. 4).

The counting convention of linked packings, decided by rank
------------------------------------------------------------
A **body** is a cluster of spheres: a connected component of the link graph (a
sphere without links is a cluster of one). Its **motion space** is the null space
of its link rows (:func:`~jamflow.network.jacobian.link_jacobian`) restricted to its
own centre columns, of dimension ``f_c = d n_c - L_c`` for ``n_c`` spheres and
``L_c`` independent links: ``d`` translations for a free sphere; translations and
the rotations that move sphere centres for a rigid cluster (3 in 2D; 6 in 3D, 5
for a straight one); for flexible chains also the internal motions.

With its neighbours held, the contacts of a cluster (rows of the contact Jacobian
on its columns) touch only its **contact-bearing** spheres: those with a contact to
a sphere still in the backbone (a contact inside the cluster makes both of its
spheres contact-bearing). The cluster's **free motions** are the motions of its
motion space that move no contact-bearing sphere: they change no gap, and the
subset they move interacts with nothing but its links (the paper: "a subset of the
cluster can move independently ... without affecting the system's energy").
Their dimension ``m_c = f_c - rank(N_c restricted to the contact-bearing spheres)``,
``N_c`` an orthonormal basis of the motion space, is decided by rank with the
relative tolerance :data:`~jamflow.tolerances.BODY_FREE_RTOL`. Examples: a
rigid trimer whose contacts all sit on one sphere swings about it (``m = 1`` in
2D, 3 in 3D); a chain end turns about its link partner (a dangler, Fig. 4); a
dimer held through one monomer is a rotator (``m = d - 1``); in 3D a rigid
cluster held only by collinear spheres spins about their axis (``m = 1``).
Spheres that move in a free motion are **danglers** here (free spheres): outside
the backbone, with their cluster still in it.

A cluster blocks ``f_c - m_c`` degrees of freedom; it is held only when its live
contacts (with backbone spheres; a contact inside the cluster counts once) number
at least ``f_c - m_c + 1`` (force balance of ``f_c - m_c`` components with
repulsive forces). Otherwise the **whole cluster rattles** and leaves the
backbone, which takes its contacts from its neighbours: the test repeats until
nothing changes. A **rattling cluster** in the paper's sense is a cluster that
rattles whole or has free motions (``m_c > 0``).

The **isostatic count** of the backbone (periodic box; chains paper Sec. IV) is

    N_iso = sum_c (f_c - m_c) - d + 1                                 (fixed box)
    N_iso = sum_c (f_c - m_c) - d + 1 + d (d + 1) / 2 - 1             (shear-stabilised, Tr eps = 0)

over the clusters in the backbone: degrees of freedom minus the ``d`` global
translations, plus the strain at fixed volume, plus one (the pressure). For free
spheres ``f_c = d``, ``m_c = 0`` when a sphere has a contact and ``m_c = d``
otherwise, so the test is the coordination pruning of
:func:`~jamflow.network.counting.prune_rattlers` (fewer than ``d + 1`` contacts) and
the count is ``d (N_s - 1) + 1`` (:func:`~jamflow.network.counting.isostatic_count`);
:func:`count_bodies` of a packing without links is that function (compiled on
request). Counting gives necessary conditions; the rank of the extended rigidity
matrix and the LPs of the certificate decide rigidity.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..state.bodies import Links
from ..tolerances import BODY_FREE_RTOL
from .contacts import ContactSet
from .counting import prune_rattlers
from .jacobian import link_jacobian

__all__ = ["BodyCount", "body_isostatic_count", "count_bodies", "motion_bases"]


@dataclass(frozen=True)
class BodyCount:
    """Backbone, free motions and isostatic count of a packing of clusters (module doc).

    Attributes
    ----------
    cluster : ndarray of int64, shape (N,)
        Cluster label per sphere (:meth:`~jamflow.state.bodies.Links.clusters`).
    rattler : ndarray of bool, shape (N,)
        Spheres outside the backbone: danglers and the spheres of clusters that rattle whole.
    dangler : ndarray of bool, shape (N,)
        Spheres moved by a free motion of a cluster in the backbone (a subset of ``rattler``).
    removed : ndarray of bool, shape (C,)
        Clusters that rattle whole.
    dofs : ndarray of int64, shape (C,)
        ``f_c``, the dimension of each cluster's motion space.
    free_dofs : ndarray of int64, shape (C,)
        ``m_c`` of the clusters in the backbone (0 for removed clusters).
    free_motions : scipy.sparse.csc_matrix, shape (N d, sum m_c)
        Orthonormal columns spanning the free motions of the backbone clusters, in
        centre coordinates (``d k + a``).
    rattling_motions : scipy.sparse.csc_matrix, shape (N d, sum f_c of removed clusters)
        Orthonormal columns spanning the motion spaces of the removed clusters.
    n_contacts : int
        Contacts between backbone spheres.
    isostatic_count : int
        ``N_iso`` of the backbone (module doc); 0 for an empty backbone.
    shear_stabilized : bool
        Whether ``isostatic_count`` includes the strain at fixed volume.
    """

    cluster: NDArray[np.int64]
    rattler: NDArray[np.bool_]
    dangler: NDArray[np.bool_]
    removed: NDArray[np.bool_]
    dofs: NDArray[np.int64]
    free_dofs: NDArray[np.int64]
    free_motions: sp.csc_matrix
    rattling_motions: sp.csc_matrix
    n_contacts: int
    isostatic_count: int
    shear_stabilized: bool

    @property
    def rattling_cluster(self) -> NDArray[np.bool_]:
        """Rattling clusters in the paper's sense, shape (C,): removed whole or with free motions."""
        return self.removed | (self.free_dofs > 0)

    @property
    def backbone_dofs(self) -> int:
        """``sum_c (f_c - m_c)`` over the clusters in the backbone."""
        return int(np.sum(np.where(self.removed, 0, self.dofs - self.free_dofs)))

    @property
    def counting(self) -> str:
        """``hypostatic``, ``isostatic``, ``hyperstatic``, or ``no backbone`` when every cluster rattles."""
        if self.isostatic_count == 0:
            return "no backbone"
        if self.n_contacts < self.isostatic_count:
            return "hypostatic"
        return "isostatic" if self.n_contacts == self.isostatic_count else "hyperstatic"

    @property
    def isostatic(self) -> bool:
        """Contacts equal the isostatic count of a non-empty backbone (an empty one is not isostatic)."""
        return self.isostatic_count > 0 and self.n_contacts == self.isostatic_count

    def as_dict(self) -> dict:
        """Scalars for ``jamflow check --json`` and dataset attributes."""
        return {"n_clusters": int(self.removed.size), "n_rattling_clusters": int(self.rattling_cluster.sum()),
                "n_clusters_removed": int(self.removed.sum()), "n_danglers": int(self.dangler.sum()),
                "n_rattlers": int(self.rattler.sum()), "free_dofs": int(self.free_dofs.sum()),
                "n_contacts": self.n_contacts, "isostatic_count": self.isostatic_count,
                "cluster_dofs": self.backbone_dofs, "isostatic": self.isostatic,
                "rigidity_counting": self.counting}


def body_isostatic_count(dofs: int, d: int, shear_stabilized: bool = False) -> int:
    """``N_iso`` of a backbone with ``dofs = sum_c (f_c - m_c)`` in a periodic box (module doc); 0 when empty."""
    if dofs <= 0:
        return 0
    return dofs - d + 1 + ((d * (d + 1)) // 2 - 1 if shear_stabilized else 0)


def motion_bases(links: Links, position: NDArray[np.float64], box: Box, cluster: NDArray[np.int64]
                 ) -> list[NDArray[np.float64]]:
    """Orthonormal basis ``N_c`` (d n_c, f_c) of every cluster's motion space (module doc).

    Rows follow the cluster's spheres in ascending index, ``d`` coordinates each.
    The null space of a cluster's link rows is taken by SVD (rank at the scale of
    unit link directions, as :func:`scipy.linalg.null_space`).
    """
    n, d = position.shape
    members = _members(cluster)
    L = link_jacobian(links, position, box).tocsr()
    link_cluster = cluster[links.i]
    order = np.argsort(link_cluster, kind="stable")
    bounds = np.searchsorted(link_cluster[order], np.arange(len(members) + 1))
    bases = []
    for c, spheres in enumerate(members):
        if spheres.size == 1:
            bases.append(np.eye(d))
            continue
        cols = (d * spheres[:, None] + np.arange(d)).ravel()
        rows = order[bounds[c]:bounds[c + 1]]
        bases.append(sla.null_space(L[rows][:, cols].toarray()))
    return bases


def _members(cluster: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Spheres of each cluster, ascending."""
    order = np.argsort(cluster, kind="stable")
    bounds = np.searchsorted(cluster[order], np.arange(int(cluster.max(initial=-1)) + 2))
    return [order[bounds[c]:bounds[c + 1]] for c in range(len(bounds) - 1)]


def _free_subspace(basis: NDArray[np.float64], bearing: NDArray[np.bool_], d: int, rtol: float
                   ) -> NDArray[np.float64]:
    """Coordinates (f_c, m_c) of the motions that move no contact-bearing sphere (module doc)."""
    f = basis.shape[1]
    rows = basis.reshape(-1, d, f)[bearing].reshape(-1, f)
    if rows.shape[0] == 0:
        return np.eye(f)
    _, s, vt = np.linalg.svd(rows, full_matrices=True)
    # the basis is orthonormal: singular values lie in [0, 1], a free motion's is round-off
    rank = int(np.sum(s > rtol))
    return vt[rank:].T


def count_bodies(
    contacts: ContactSet | ArrayLike,
    n: int,
    d: int,
    links: Links | None = None,
    position: NDArray[np.float64] | None = None,
    box: Box | None = None,
    *,
    shear_stabilized: bool = False,
    rtol: float = BODY_FREE_RTOL,
    compiled: bool = False,
    by_rank: bool = False,
) -> BodyCount:
    """Free motions, rattling clusters, backbone and isostatic count of a packing of clusters (module doc).

    Parameters
    ----------
    contacts : ContactSet or array_like of int, shape (n_c, 2)
        Contacts between spheres that are not linked (each pair once).
    n, d : int
        Spheres and dimension.
    links : Links, optional
        Independent links; None or empty for spheres.
    position : ndarray, shape (N, d), optional
        Centres [length]; needed with links (the motion spaces).
    box : Box, optional
        Periodic box; needed with links.
    shear_stabilized : bool
        Count the strain degrees of freedom at fixed volume.
    rtol : float
        Singular values of a motion basis restricted to contact-bearing spheres below
        this count as free motions (:data:`~jamflow.tolerances.BODY_FREE_RTOL`).
    compiled : bool
        Spheres only: prune with the compiled kernel of
        :func:`~jamflow.network.counting.prune_rattlers`.
    by_rank : bool
        Spheres only: run the rank test on every sphere instead of the coordination
        pruning it reduces to (for tests of that equivalence).
    """
    pairs = contacts.pairs if isinstance(contacts, ContactSet) else np.asarray(contacts, np.int64).reshape(-1, 2)
    if links is None:
        links = Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    if len(links) == 0 and not by_rank:
        rattler = prune_rattlers(pairs, n, dofs_per_body=d, compiled=compiled)
        return _sphere_count(pairs, rattler, n, d, shear_stabilized)
    if len(links) and (position is None or box is None):
        raise ValueError("count_bodies needs the centres and the box of a packing with links (motion spaces)")
    cluster = links.clusters(n)
    bases = motion_bases(links, position, box, cluster) if len(links) else [np.eye(d)] * n
    return _count(pairs, cluster, bases, n, d, shear_stabilized, rtol)


def _sphere_count(pairs: NDArray[np.int64], rattler: NDArray[np.bool_], n: int, d: int,
                  shear_stabilized: bool) -> BodyCount:
    """The :class:`BodyCount` of spheres from their coordination pruning (module doc)."""
    live = ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])
    eye = sp.identity(n * d, format="csc")
    rattling = sp.csc_matrix(eye[:, np.repeat(rattler, d)])
    dofs = np.full(n, d, np.int64)
    return BodyCount(np.arange(n, dtype=np.int64), rattler, np.zeros(n, bool), rattler.copy(), dofs,
                     np.zeros(n, np.int64), sp.csc_matrix((n * d, 0)), rattling, int(live.sum()),
                     body_isostatic_count(d * int((~rattler).sum()), d, shear_stabilized), shear_stabilized)


def _count(pairs: NDArray[np.int64], cluster: NDArray[np.int64], bases: list[NDArray[np.float64]], n: int, d: int,
           shear_stabilized: bool, rtol: float) -> BodyCount:
    """The iteration of the module doc: free motions, then clusters held by too few contacts, until stable."""
    members = _members(cluster)
    n_clusters = len(members)
    dofs = np.array([b.shape[1] for b in bases], np.int64)
    removed = np.zeros(n_clusters, bool)
    out = np.zeros(n, bool)  # spheres of removed clusters
    free: list[NDArray[np.float64]] = [np.zeros((f, 0)) for f in dofs]
    ci, cj = cluster[pairs[:, 0]], cluster[pairs[:, 1]]
    before = np.zeros(n, bool)
    stale = np.ones(n_clusters, bool)
    while True:
        live = ~(out[pairs[:, 0]] | out[pairs[:, 1]])
        bearing = np.bincount(pairs[live].ravel(), minlength=n) > 0
        held = (np.bincount(ci[live], minlength=n_clusters)
                + np.bincount(cj[live & (ci != cj)], minlength=n_clusters))
        # free motions change only where a sphere stopped bearing
        stale[np.unique(cluster[bearing != before])] = True
        for c in np.flatnonzero(stale & ~removed):
            free[c] = _free_subspace(bases[c], bearing[members[c]], d, rtol)
        stale[:] = False
        before = bearing
        blocked = dofs - np.array([f.shape[1] for f in free], np.int64)
        new = ~removed & (held < blocked + 1)
        if not np.any(new):
            break
        removed |= new
        out |= removed[cluster]
    free_dofs = np.where(removed, 0, [f.shape[1] for f in free]).astype(np.int64)
    dangler = np.zeros(n, bool)
    free_cols, rattling_cols = [], []
    for c in range(n_clusters):
        rows = (d * members[c][:, None] + np.arange(d)).ravel()
        if removed[c]:
            rattling_cols.append((rows, bases[c]))
        elif free_dofs[c]:
            motion = bases[c] @ free[c]
            moved = np.linalg.norm(motion.reshape(-1, d, motion.shape[1]), axis=(1, 2)) > rtol
            dangler[members[c][moved]] = True
            free_cols.append((rows, motion))
    rattler = out | dangler
    live = ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])
    backbone = int(np.sum(np.where(removed, 0, dofs - free_dofs)))
    return BodyCount(cluster, rattler, dangler, removed, dofs, free_dofs, _columns(free_cols, n * d),
                     _columns(rattling_cols, n * d), int(live.sum()),
                     body_isostatic_count(backbone, d, shear_stabilized), shear_stabilized)


def _columns(blocks: list[tuple[NDArray[np.int64], NDArray[np.float64]]], n_rows: int) -> sp.csc_matrix:
    """Block columns ``(rows, values)`` side by side in one sparse matrix of ``n_rows`` rows."""
    if not blocks:
        return sp.csc_matrix((n_rows, 0))
    r, c, v = [], [], []
    col = 0
    for rows, values in blocks:
        k = values.shape[1]
        r.append(np.repeat(rows, k))
        c.append(np.tile(np.arange(col, col + k), len(rows)))
        v.append(values.ravel())
        col += k
    return sp.csc_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(n_rows, col))
