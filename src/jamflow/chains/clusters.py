"""Rattling clusters, danglers and the isostatic count of linked packings (chains paper Sec. II F, Fig. 4).

Counting, with ``f_c = d n_c - L_c`` the degrees of freedom of a cluster of ``n_c``
spheres and ``L_c`` links (links are independent: degenerate ones are removed by
:func:`~jamflow.chains.builders.remove_degenerate_links` and refused by the model):

- a **dangler** is a sphere of a linked cluster with fewer than ``d`` constraints
  (links to non-dangling spheres plus contacts with non-rattlers): with its
  neighbours held it still has a free direction (the free end of a chain, Fig. 4; in
  3D also a chain end whose angle is frozen, which can turn about the torsion axis);
- a **rattling cluster** is a cluster (without its danglers) held by fewer than
  ``f_c + 1`` contacts with non-rattlers (contacts inside the cluster count: each
  removes one internal degree of freedom). For a cluster of one sphere this is the
  sphere rule, fewer than ``d + 1`` contacts (:func:`jamflow.analysis.contacts.find_rattlers`).

Both are removed together and the count repeats until nothing changes: removing a
dangler takes its links and contacts away from its cluster and neighbours. Counting
gives necessary conditions; the linear programme of Sec. V decides rigidity.

**Isostatic count of clusters** (degrees of freedom after links, minus the ``d``
global translations, plus strain and volume, plus one): a non-rattling backbone of
clusters is isostatic with

``N_iso = sum_c f_c - d + 1`` at fixed box, and
``N_iso = sum_c f_c - d + d (d + 1) / 2 - 1 + 1`` shear-stabilised (strain degrees of
freedom ``d (d + 1) / 2`` minus the volume constraint ``Tr eps = 0``).

With no links ``f_c = d`` and the fixed-box count is the spheres' ``d (N_s - 1) + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..state.bodies import Links

__all__ = ["ClusterCount", "count_clusters", "isostatic_cluster_count"]


@dataclass(frozen=True)
class ClusterCount:
    """Rattlers, danglers and the isostatic count of a linked packing.

    Attributes
    ----------
    cluster : ndarray of int64, shape (N,)
        Cluster label per sphere (connected components of the links).
    rattler : ndarray of bool, shape (N,)
        Spheres outside the backbone: danglers and members of rattling clusters.
    dangler : ndarray of bool, shape (N,)
        Danglers (a subset of ``rattler``).
    rattling_cluster : ndarray of bool, shape (C,)
        Clusters whose remaining members rattle.
    dofs : ndarray of int64, shape (C,)
        ``f_c`` of each cluster's backbone part (0 for rattling clusters).
    n_contacts : int
        Contacts between backbone spheres.
    isostatic_count : int
        ``N_iso`` of the backbone (module doc).
    """

    cluster: NDArray[np.int64]
    rattler: NDArray[np.bool_]
    dangler: NDArray[np.bool_]
    rattling_cluster: NDArray[np.bool_]
    dofs: NDArray[np.int64]
    n_contacts: int
    isostatic_count: int

    @property
    def counting(self) -> str:
        """``hypostatic``, ``isostatic`` or ``hyperstatic``."""
        if self.n_contacts < self.isostatic_count:
            return "hypostatic"
        return "isostatic" if self.n_contacts == self.isostatic_count else "hyperstatic"

    def as_dict(self) -> dict:
        """Scalars for ``jamflow check --json`` and dataset attributes."""
        return {"n_clusters": int(self.rattling_cluster.size), "n_rattling_clusters": int(self.rattling_cluster.sum()),
                "n_danglers": int(self.dangler.sum()), "n_rattlers": int(self.rattler.sum()),
                "n_contacts": self.n_contacts, "isostatic_count": self.isostatic_count,
                "cluster_dofs": int(self.dofs.sum()), "rigidity_counting": self.counting}


def isostatic_cluster_count(dofs: int, d: int, shear_stabilized: bool) -> int:
    """``N_iso`` of a backbone with ``dofs = sum_c f_c`` (module doc); 0 for an empty backbone."""
    if dofs == 0:
        return 0
    return dofs - d + 1 + ((d * (d + 1)) // 2 - 1 if shear_stabilized else 0)


def count_clusters(n: int, d: int, links: Links | None, contacts: NDArray[np.int64],
                   shear_stabilized: bool = False) -> ClusterCount:
    """Danglers, rattling clusters and the isostatic count (module doc).

    Parameters
    ----------
    n, d : int
        Spheres and dimension.
    links : Links or None
        Independent links (None: spheres only).
    contacts : ndarray of int, shape (Nc, 2)
        Contacts between spheres that are not linked.
    shear_stabilized : bool
        Whether the strain degrees of freedom (with fixed volume) are part of the count.
    """
    if links is None:
        links = Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))
    contacts = np.asarray(contacts, dtype=np.int64).reshape(-1, 2)
    cluster = links.clusters(n)
    n_clusters = int(cluster.max()) + 1
    linked = np.bincount(cluster, minlength=n_clusters)[cluster] > 1
    rattler = np.zeros(n, dtype=bool)
    dangler = np.zeros(n, dtype=bool)
    rattling = np.zeros(n_clusters, dtype=bool)
    while True:
        live_l = ~(rattler[links.i] | rattler[links.j])
        live_c = ~(rattler[contacts[:, 0]] | rattler[contacts[:, 1]])
        constraints = (np.bincount(np.concatenate([links.i[live_l], links.j[live_l]]), minlength=n)
                       + np.bincount(contacts[live_c].ravel(), minlength=n))
        new_dangler = linked & ~rattler & (constraints < d)
        if np.any(new_dangler):  # danglers first: a cluster is counted without them
            dangler |= new_dangler
            rattler |= new_dangler
            continue
        members = np.bincount(cluster[~rattler], minlength=n_clusters)
        dofs = d * members - np.bincount(cluster[links.i[live_l]], minlength=n_clusters)
        # a contact inside a cluster counts once; between clusters once for each
        ci, cj = cluster[contacts[live_c, 0]], cluster[contacts[live_c, 1]]
        held = np.bincount(ci, minlength=n_clusters) + np.bincount(cj[ci != cj], minlength=n_clusters)
        new_rattling = (members > 0) & ~rattling & (held < dofs + 1)
        if not np.any(new_rattling):
            break
        rattling |= new_rattling
        rattler |= rattling[cluster]
    dofs = np.where(rattling, 0, dofs)
    live_c = ~(rattler[contacts[:, 0]] | rattler[contacts[:, 1]])
    return ClusterCount(cluster, rattler, dangler, rattling, dofs.astype(np.int64), int(live_c.sum()),
                        isostatic_cluster_count(int(dofs.sum()), d, shear_stabilized))
