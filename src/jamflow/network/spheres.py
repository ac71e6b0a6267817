"""Contact networks of spheres: contacts from gaps, rattlers, force balance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..state.packing import Packing, near_pairs
from ..tolerances import CONTACT_GAP_TOL
from . import prune_rattlers

__all__ = [
    "contacts_from_gaps",
    "contact_network",
    "find_rattlers",
    "rattler_mask",
    "force_balance_residual",
    "require_plain_spheres",
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
