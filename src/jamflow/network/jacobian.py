"""The contact Jacobian (rigidity matrix) ``d gap / d q`` and the link-constraint rows.

Degrees of freedom ``q`` are ordered as in the energy models (:mod:`jamflow.models`):
centres (body-major, ``d k + a`` for the ``k``-th column body), then one orientation
per body (2D only), then strain coordinates. To first order a motion changes the
gap of contact ``c = (i, j)`` with normal ``n`` by

    delta gap = n . (y_j - y_i) + theta_j (a_j x n) - theta_i (a_i x n) + n^T eps s

with ``y`` the centre displacements, ``theta`` the rotation angles [rad], ``a`` the
contact arms (contact point minus centre), ``a x n = a_0 n_1 - a_1 n_0`` the 2D cross
product (the torque arm), and ``s = r_j - r_i`` the separation. The strain term
follows the box convention of :mod:`jamflow.box`: a symmetric strain ``eps`` maps
the lattice matrix ``h -> (I + eps) h`` and every centre ``x -> (I + eps) x``, so
every separation ``s -> (I + eps) s`` while bodies translate rigidly (they do not
deform). For spheres ``n^T eps s = |s| n^T eps n`` (soft-chains paper, Eqs. 35-38),
evaluated in that form for central contacts.

The derivative of a gap with respect to the normal's own rotation vanishes at
contact (the normal is perpendicular to both surfaces), so the same rows hold for
any pair of smooth convex bodies whose contact arms are given.

Rows of a rigid link ``k = (i, j)`` (the holonomic constraint ``|x_ij| - l_k = 0``
of :mod:`jamflow.models.links`) are the sphere rows of the link's unit vector:
``-u`` on ``i``, ``+u`` on ``j`` (plus ``|x_ij| u^T eps u`` on strain columns).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..state.bodies import Links
from .contacts import ContactSet, sphere_contacts

__all__ = ["contact_jacobian", "link_jacobian", "n_strain", "pair_rows", "strain_basis"]


def strain_basis(d: int, volume_preserving: bool = True) -> NDArray[np.float64]:
    """Basis of symmetric strain tensors, shape (n_strain, d, d).

    Parameters
    ----------
    d : int
        Dimension.
    volume_preserving : bool
        If true, a basis of the traceless symmetric matrices (``d (d + 1) / 2 - 1``
        elements: ``E_aa - E_dd`` for ``a < d`` and ``E_ab + E_ba`` for ``a < b``);
        otherwise all ``d (d + 1) / 2`` elementary symmetric matrices (``E_aa``,
        then ``E_ab + E_ba`` for ``a < b``).
    """
    mats = []
    for a in range(d):
        m = np.zeros((d, d))
        m[a, a] = 1.0
        if volume_preserving:
            if a == d - 1:
                continue
            m[d - 1, d - 1] = -1.0
        mats.append(m)
    for a in range(d):
        for b in range(a + 1, d):
            m = np.zeros((d, d))
            m[a, b] = m[b, a] = 1.0
            mats.append(m)
    return np.array(mats)


def _basis(strain: str | ArrayLike | None, d: int) -> NDArray[np.float64] | None:
    if strain is None:
        return None
    if isinstance(strain, str):
        if strain not in ("symmetric", "traceless"):
            raise ValueError(f"strain must be 'symmetric', 'traceless', a basis array or None, got {strain!r}")
        return strain_basis(d, volume_preserving=strain == "traceless")
    basis = np.asarray(strain, dtype=np.float64)
    if basis.ndim != 3 or basis.shape[1:] != (d, d):
        raise ValueError(f"strain basis must have shape (n_strain, {d}, {d}), got {basis.shape}")
    return basis


def n_strain(strain: str | ArrayLike | None, d: int) -> int:
    """Number of strain columns for a ``strain`` argument of :func:`contact_jacobian`."""
    basis = _basis(strain, d)
    return 0 if basis is None else len(basis)


def _cross(a: NDArray[np.float64], n: NDArray[np.float64]) -> NDArray[np.float64]:
    """2D cross product ``a_0 n_1 - a_1 n_0``, shape (n_c,)."""
    return a[:, 0] * n[:, 1] - a[:, 1] * n[:, 0]


def contact_jacobian(
    contacts: ContactSet,
    n_bodies: int,
    d: int | None = None,
    *,
    rotations: bool = False,
    strain: str | ArrayLike | None = None,
    bodies: ArrayLike | None = None,
) -> sp.csr_matrix:
    """Jacobian ``d gap_c / d q`` of a contact set (see the module docstring).

    Parameters
    ----------
    contacts : ContactSet
        Both bodies of every contact must be among ``bodies``.
    n_bodies : int
        Number of bodies of the packing.
    d : int, optional
        Dimension (checked against the contact normals when given).
    rotations : bool
        Add one orientation column per column body (2D; needs contact arms).
    strain : {"symmetric", "traceless"} or ndarray of shape (n_strain, d, d), optional
        Add strain columns: coordinates in the ``d (d + 1) / 2`` elementary
        symmetric matrices, in the traceless basis (strain at fixed volume), or in
        a given basis; see :func:`strain_basis`.
    bodies : array_like of int, shape (n_s,), optional
        Bodies whose degrees of freedom are columns, in this order (default: all).

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_c, d n_s [+ n_s] [+ n_strain])
        Canonical CSR (sorted column indices). Row ``c`` times a motion is the
        first-order change of gap ``c`` [length] (per radian for orientation
        columns, per unit strain coordinate for strain columns).
    """
    dim = contacts.d if contacts.n_contacts or d is None else d
    if d is not None and d != dim:
        raise ValueError(f"contact normals are {dim}-dimensional, but d = {d}")
    d = dim
    if rotations and d != 2:
        raise ValueError(f"rotation columns are implemented in 2D (one angle per body), got d = {d}")
    if rotations and contacts.central:
        raise ValueError("rotation columns need contact arms (ContactSet.arm_i / arm_j)")
    if bodies is None:
        col_of = np.arange(n_bodies, dtype=np.int64)
        ns = n_bodies
    else:
        bodies = np.asarray(bodies, dtype=np.int64)
        col_of = np.full(n_bodies, -1, dtype=np.int64)
        col_of[bodies] = np.arange(len(bodies))
        ns = len(bodies)
    ci, cj = col_of[contacts.i], col_of[contacts.j]
    if np.any(ci < 0) or np.any(cj < 0):
        raise ValueError("a contact involves a body that is not among the column bodies")
    unit = contacts.normal
    nc = contacts.n_contacts
    axis = np.arange(d)
    # per row: the lower body's block first, so every row's columns ascend
    lo = np.minimum(ci, cj)
    hi = np.maximum(ci, cj)
    swap = (ci > cj)[:, None]
    cols = [lo[:, None] * d + axis, hi[:, None] * d + axis]
    vals = [np.where(swap, unit, -unit), np.where(swap, -unit, unit)]
    n_cols = d * ns
    if rotations:
        ti = -_cross(contacts.arm_i, unit)
        tj = _cross(contacts.arm_j, unit)
        cols += [(n_cols + lo)[:, None], (n_cols + hi)[:, None]]
        vals += [np.where(swap[:, 0], tj, ti)[:, None], np.where(swap[:, 0], ti, tj)[:, None]]
        n_cols += ns
    basis = _basis(strain, d)
    if basis is not None:
        if contacts.central:
            dist = np.linalg.norm(contacts.separation, axis=1)
            coef = dist[:, None] * np.einsum("ca,kab,cb->ck", unit, basis, unit)
        else:
            coef = np.einsum("ca,kab,cb->ck", unit, basis, contacts.separation)
        cols.append(np.broadcast_to(n_cols + np.arange(len(basis)), (nc, len(basis))))
        vals.append(coef)
        n_cols += len(basis)
    col = np.concatenate(cols, axis=1)
    val = np.concatenate(vals, axis=1)
    if np.any(ci == cj):
        # a body touching its own periodic image: its two blocks share columns and sum
        rows = np.repeat(np.arange(nc), col.shape[1])
        return sp.csr_matrix((val.ravel(), (rows, col.ravel())), shape=(nc, n_cols))
    indptr = np.arange(0, col.size + 1, col.shape[1]) if nc else np.zeros(1, dtype=np.int64)
    return sp.csr_matrix((val.ravel(), col.ravel(), indptr), shape=(nc, n_cols))


def pair_rows(pairs: ArrayLike, vectors: ArrayLike, n_bodies: int) -> sp.csr_matrix:
    """Rows ``-v_c`` on the centre columns of body ``i`` and ``+v_c`` on those of ``j``.

    The centre block of :func:`contact_jacobian` with any row vectors ``v_c`` in place
    of the unit normals: the gradient of any function of the separation ``r_j - r_i``.
    CALiPPSO's LP rows are these with ``v = -2 <D> r_ij / sigma_ij^2`` (the scaled
    gradient of ``-|r_ij|^2 / sigma_ij^2``).

    Parameters
    ----------
    pairs : array_like of int, shape (n_c, 2)
        Body pairs ``(i, j)``.
    vectors : array_like, shape (n_c, d)
        Row vectors ``v_c``.
    n_bodies : int

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_c, d n_bodies)
        Canonical CSR.
    """
    c = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    v = np.asarray(vectors, dtype=np.float64)
    # the separation enters only strain columns, which these rows do not have
    return contact_jacobian(ContactSet(c[:, 0], c[:, 1], v, v), n_bodies, v.shape[1])


def link_jacobian(links: Links, position: NDArray[np.float64], box: Box, *,
                  strain: str | ArrayLike | None = None, rotations: bool = False) -> sp.csr_matrix:
    """Rows ``d c_k / d q`` of the link constraints ``c_k = |x_ij| - l_k``, shape (n_links, n_dof).

    The link vector is the minimum image ``x_j - x_i`` at ``position`` (links are
    shorter than half the smallest box width, :class:`~jamflow.models.links.LinkedSpheresModel`).
    Columns are those of :func:`contact_jacobian` for all bodies with the same
    ``rotations`` and ``strain`` (orientation columns of a link between sphere
    centres are zero), so the extended rigidity matrix of a linked packing is
    ``scipy.sparse.vstack([contact_jacobian(...), link_jacobian(...)])``.
    """
    n, d = position.shape
    pairs = np.stack([links.i, links.j], axis=1)
    rows = sphere_contacts(position, box, pairs) if len(pairs) else ContactSet(
        links.i, links.j, np.zeros((0, d)), np.zeros((0, d)))
    if rotations:
        # a link joins two centres: no torque arm, zero orientation columns
        zero = np.zeros_like(rows.normal)
        rows = ContactSet(rows.i, rows.j, rows.normal, rows.separation, zero, zero)
    return contact_jacobian(rows, n, d, rotations=rotations, strain=strain)
