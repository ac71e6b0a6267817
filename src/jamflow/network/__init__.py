"""The one contact-network core: contacts, Jacobian, rattler/slider pruning, counts, self stress.

Every stage that needs a rigidity matrix, a rattler set or an isostatic count asks
this package (``docs/network.md``):

- :mod:`.contacts`: :class:`ContactSet` (body pairs, normals, separations, contact
  arms) and :func:`sphere_contacts`;
- :mod:`.jacobian`: :func:`contact_jacobian` (``d gap / d q`` with optional
  rotation and strain columns), :func:`pair_rows` (its centre block for any row
  vectors), :func:`link_jacobian`, :func:`strain_basis`;
- :mod:`.counting`: :func:`prune_rattlers`, :func:`prune_unheld`, :func:`find_sliders`,
  :func:`isostatic_count`, :func:`rigidity_counting`;
- :mod:`.bodies`: :func:`count_bodies` (free motions, rattling clusters, danglers and the
  isostatic count of clusters of linked spheres, by rank; spheres reduce to
  :func:`prune_rattlers`), :class:`BodyCount`, :func:`body_isostatic_count`;
- :mod:`.self_stress`: :func:`self_stresses`, :func:`positive_self_stress`,
  :func:`jacobian_rank`, :func:`rigid_network` and :func:`strain_motion` (Roth-Whiteley).
"""

from .bodies import BodyCount, body_isostatic_count, count_bodies
from .contacts import ContactSet, sphere_contacts
from .counting import (
    find_sliders,
    isostatic_count,
    prune_rattlers,
    prune_unheld,
    rigidity_counting,
)
from .jacobian import contact_jacobian, link_jacobian, n_strain, pair_rows, strain_basis
from .self_stress import (
    RigidNetwork,
    jacobian_rank,
    positive_self_stress,
    rigid_network,
    self_stresses,
    strain_motion,
)

__all__ = [
    "BodyCount",
    "ContactSet",
    "RigidNetwork",
    "body_isostatic_count",
    "contact_jacobian",
    "count_bodies",
    "find_sliders",
    "isostatic_count",
    "jacobian_rank",
    "link_jacobian",
    "n_strain",
    "pair_rows",
    "positive_self_stress",
    "prune_rattlers",
    "prune_unheld",
    "rigid_network",
    "rigidity_counting",
    "self_stresses",
    "sphere_contacts",
    "strain_basis",
    "strain_motion",
]
