"""Contact networks: detection, rattler removal, isostaticity, force balance.

Isostatic count convention
--------------------------
For N_s stable (non-rattler) frictionless spheres in a periodic box the rigid
backbone needs ``N_c = d (N_s - 1) + 1`` contacts: ``d N_s`` translational degrees
of freedom, minus ``d`` global translations, plus one. The ``+1`` is the inflation
(or compression) degree of freedom of CALiPPSO, and equally the positive-pressure
constraint of a soft packing at fixed box (2D: ``2 (N - N_r) - 1``); both give the
same number. Contacts are counted once per pair (``i < j``). The count and the
rattler pruning are those of the contact-network core,
:func:`jamflow.network.isostatic_count` and :func:`jamflow.network.prune_rattlers`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..network import isostatic_count as network_isostatic_count
from ..network import prune_rattlers, rigidity_counting
from ..packing import Packing, max_overlap, near_pairs
from ..tolerances import CONTACT_GAP_TOL

__all__ = [
    "ContactSummary",
    "contact_network",
    "contacts_from_gaps",
    "find_rattlers",
    "force_balance_residual",
    "isostatic_count",
    "rattler_mask",
    "require_plain_spheres",
    "rigidity_counting",
    "summarize",
]


def contacts_from_gaps(packing: Packing, gap_tol: float = CONTACT_GAP_TOL) -> NDArray[np.int64]:
    """Pairs with relative gap ``r / sigma_ij - 1 <= gap_tol``, shape (Nc, 2), ``i < j``."""
    if not np.isfinite(gap_tol):
        raise ValueError(f"gap_tol must be finite, got {gap_tol}")
    pairs, _ = near_pairs(packing, gap_tol)
    return np.stack([pairs.i, pairs.j], axis=1)


def contact_network(packing: Packing, gap_tol: float | None = None) -> NDArray[np.int64]:
    """The packing's explicit contacts, or contacts from ``gap_tol`` when it has none.

    An explicit ``gap_tol`` always recomputes the network from geometry.
    """
    if gap_tol is None and packing.contacts is not None:
        return packing.contacts
    return contacts_from_gaps(packing, CONTACT_GAP_TOL if gap_tol is None else gap_tol)


def find_rattlers(n: int, d: int, contacts: NDArray[np.int64],
                  wall_particles: NDArray[np.int64] | None = None) -> NDArray[np.bool_]:
    """Rattlers of ``n`` spheres in ``d`` dimensions: :func:`jamflow.network.prune_rattlers`
    with ``d`` degrees of freedom per particle (fewer than ``d + 1`` contacts, iterated).

    ``wall_particles`` lists the particle of each hard-wall contact (always counts).
    Returns a boolean mask of shape (n,), True for rattlers.
    """
    return prune_rattlers(contacts, n, dofs_per_body=d, wall_contacts=wall_particles)


def rattler_mask(packing: Packing, contacts: NDArray[np.int64] | None = None) -> NDArray[np.bool_]:
    """Rattlers of ``packing`` for the contact network ``contacts``, shape (N,).

    ``None`` (or the packing's own contacts) uses the rattlers the producing stage
    stored, when it stored them; otherwise :func:`find_rattlers` on the network.
    """
    own = contacts is None or contacts is packing.contacts
    if own and packing.rattler is not None:
        return packing.rattler
    network = packing.contacts if contacts is None else contacts
    if network is None:
        raise ValueError("packing has no contact network to find rattlers from")
    return find_rattlers(packing.n, packing.d, network)


def isostatic_count(d: int, n_stable: int) -> int:
    """Contacts of an isostatic backbone of periodic spheres, ``d (N_s - 1) + 1``
    (:func:`jamflow.network.isostatic_count` with ``d`` global translations)."""
    return network_isostatic_count(n_stable, d, global_dofs=d)


def force_balance_residual(packing: Packing) -> NDArray[np.float64]:
    """Per-particle net contact force relative to the mean force, shape (N,).

    The force on ``i`` from a repulsive contact ``(i, j)`` is ``-f n_ij`` with
    ``n_ij`` the unit vector from ``i`` to ``j``. Returns ``|F_i| / <f>``.
    """
    if packing.contacts is None or packing.force is None:
        raise ValueError("packing has no contact forces")
    if len(packing.force) == 0:
        return np.zeros(packing.n)
    dx = packing.contact_vectors()
    nij = dx / np.linalg.norm(dx, axis=1)[:, None]
    fv = packing.force[:, None] * nij
    net = np.zeros((packing.n, packing.d))
    np.add.at(net, packing.contacts[:, 0], -fv)
    np.add.at(net, packing.contacts[:, 1], fv)
    scale = float(np.mean(np.abs(packing.force)))
    return np.linalg.norm(net, axis=1) / (scale if scale > 0 else 1.0)


@dataclass(frozen=True)
class ContactSummary:
    """What ``jamflow check`` reports (keys of its ``--json`` output)."""

    N: int
    d: int
    phi: float
    pressure: float | None
    n_contacts: int
    n_rattlers: int
    n_stable: int
    isostatic: bool
    isostatic_count: int
    counting: str  # "hypostatic", "isostatic", "hyperstatic" or "no backbone"
    z: float
    max_overlap: float  # largest sigma_ij - r_ij [length]
    max_overlap_rel: float  # max_overlap / mean diameter
    force_balance_residual: float | None
    contact_source: str

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def require_plain_spheres(packing: Packing, what: str) -> None:
    """Refuse what periodic sphere contact counting would get wrong.

    A packing jammed between hard walls (attribute ``boundary = "walls"``) keeps its
    wall contacts outside the :class:`Packing` (CALiPPSO's ``wall_contact``
    variables), so every sphere touching a wall would look under-coordinated. Linked
    spheres and shaped particles have constraints and contact distances that the
    sphere network does not know (their counting comes with their energy models).
    """
    if packing.attrs.get("boundary") == "walls":
        raise ValueError(f"{what} counts contacts of periodic packings; this packing is jammed between hard "
                         "walls (its wall contacts are the calippso output's wall_contact variables)")
    if packing.links is not None and len(packing.links):
        raise ValueError(f"{what} counts contacts of unlinked spheres; this packing has {len(packing.links)} "
                         "links (linked pairs are constraints, not contacts)")
    if packing.shapes is not None and np.any(packing.shapes.kind != "disk"):
        raise ValueError(f"{what} counts contacts of spheres; this packing has shaped particles, whose contact "
                         "distances are not their bounding diameters")


def summarize(packing: Packing, gap_tol: float | None = None) -> ContactSummary:
    """Contacts, rattlers, isostaticity, overlap and force balance of a packing.

    Contacts come from the packing when it has them, else from ``gap_tol``
    (default :data:`~jamflow.tolerances.CONTACT_GAP_TOL`). ``n_contacts`` counts the
    backbone after rattler removal; ``isostatic`` compares it with
    :func:`isostatic_count` and ``counting`` says on which side it lies (a
    crystal's backbone is hyperstatic).
    """
    require_plain_spheres(packing, "check")
    explicit = gap_tol is None and packing.contacts is not None
    contacts = contact_network(packing, gap_tol)
    rattler = find_rattlers(packing.n, packing.d, contacts)
    backbone = ~(rattler[contacts[:, 0]] | rattler[contacts[:, 1]])
    n_c = int(backbone.sum())
    n_s = int((~rattler).sum())
    iso = isostatic_count(packing.d, n_s)
    overlap_abs, _ = max_overlap(packing)
    residual = None
    if packing.force is not None and explicit:
        residual = float(np.max(force_balance_residual(packing)[~rattler], initial=0.0))
    return ContactSummary(
        N=packing.n,
        d=packing.d,
        phi=packing.packing_fraction,
        pressure=packing.pressure,
        n_contacts=n_c,
        n_rattlers=int(rattler.sum()),
        n_stable=n_s,
        isostatic=bool(n_s > 0 and n_c == iso),
        isostatic_count=iso,
        counting=rigidity_counting(n_c, iso) if n_s else "no backbone",
        z=2.0 * n_c / n_s if n_s else 0.0,
        max_overlap=overlap_abs,
        max_overlap_rel=overlap_abs / float(np.mean(packing.diameter)),
        force_balance_residual=residual,
        contact_source="packing" if explicit else f"gap <= {CONTACT_GAP_TOL if gap_tol is None else gap_tol:g}",
    )
