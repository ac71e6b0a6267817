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

from ..network import isostatic_count, rigidity_counting
from ..network.spheres import (
    contact_network,
    find_rattlers,
    force_balance_residual,
    require_plain_spheres,
)
from ..state.packing import Packing, max_overlap
from ..tolerances import CONTACT_GAP_TOL

__all__ = ["ContactSummary", "summarize"]


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
    iso = isostatic_count(n_s, packing.d, global_dofs=packing.d)
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
