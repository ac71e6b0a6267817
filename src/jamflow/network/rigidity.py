"""Rigidity matrix of a sphere packing's contact network, with and without strain.

Thin sphere-packing front end of :mod:`jamflow.network` (the one contact-network
core): for a contact ``c = (i, j)`` with minimum-image vector ``r_ij = x_j - x_i``
and unit vector ``n_ij``, displacements ``y_i`` and a symmetric strain ``eps`` of the
periodic box (``x -> (I + eps) x + y``) change the separation to first order by

    delta |r_ij| = n_ij . (y_j - y_i) + |r_ij| n_ij^T eps n_ij

(soft-chains paper, Eqs. 35-38: ``R_x`` and ``R_eps``). A hard-sphere contact
allows exactly the motions with ``R y >= -gap``; ``R^T`` maps contact forces to net
particle forces, so a self-stress is a ``lambda`` with ``R^T lambda = 0``
(:mod:`jamflow.network.self_stress`, with the Roth-Whiteley theorem used as an
independent check of the LP certificate).

Strains are coordinates in a basis of symmetric matrices
(:func:`~jamflow.network.jacobian.strain_basis`): all ``d (d + 1) / 2``, or, for
strict jamming at fixed volume, the ``d (d + 1) / 2 - 1`` traceless ones. At first
order a motion with ``Tr eps < 0`` can always be completed by the isotropic
expansion ``a I`` (``a > 0``), which opens every contact, into one with
``Tr eps = 0``, so the volume-preserving basis tests the same thing as "volume
non-increasing" in the Torquato-Stillinger definition of strict jamming.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..state.packing import Packing
from . import contact_jacobian, sphere_contacts

__all__ = ["contact_geometry", "rigidity_matrix"]


def contact_geometry(packing: Packing, contacts: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit vectors ``n_ij`` (Nc, d) and distances ``|r_ij|`` (Nc,) [length] of contacts."""
    cs = sphere_contacts(packing.position, packing.box, contacts)
    return cs.normal, np.linalg.norm(cs.separation, axis=1)


def rigidity_matrix(
    packing: Packing,
    contacts: NDArray[np.int64],
    strain: bool = False,
    volume_preserving: bool = True,
    particles: NDArray[np.int64] | None = None,
) -> sp.csr_matrix:
    """Rigidity matrix ``R`` of a contact network (see module docstring).

    Parameters
    ----------
    packing : Packing
    contacts : ndarray of int, shape (Nc, 2)
        Contact pairs; both particles must be among ``particles``.
    strain : bool
        Append strain columns (coordinates in :func:`strain_basis`).
    volume_preserving : bool
        Traceless strain basis (strict jamming at fixed volume).
    particles : ndarray of int, shape (Ns,), optional
        Particles whose displacements are columns, in this order (default: all).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (Nc, d Ns [+ n_strain])
        Row ``c`` times a motion ``(y, eps)`` is the first-order change of the
        separation ``|r_ij|`` [length]; displacement columns are particle-major
        (``d k + a`` for the ``k``-th listed particle), strain columns follow.
    """
    cs = sphere_contacts(packing.position, packing.box, contacts)
    kind = None if not strain else ("traceless" if volume_preserving else "symmetric")
    return contact_jacobian(cs, packing.n, packing.d, strain=kind, bodies=particles)
