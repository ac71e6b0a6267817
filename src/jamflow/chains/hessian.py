"""Constrained Hessian and extended rigidity matrix of linked packings (chains paper Sec. IV).

Coordinates are those of :class:`~jamflow.models.strain.ShearStabilizedModel` at zero
strain: centres ``x`` (N d) and the scaled strain components ``e`` (m =
d (d + 1) / 2); the positions-only variant drops ``e``. For any pair function
``phi(|r|)`` with ``r = F R`` (``F = 1 + eps``, ``R`` the pair vector at zero strain)
the second derivatives at ``eps = 0`` are (Eqs. 24-26)

- ``d2 phi / dx dx``: the block ``k = phi'' u u^T + (phi' / r) (1 - u u^T)`` (``+k`` on
  ``ii, jj``, ``-k`` on ``ij``);
- ``d2 phi / dx_j dF_cd = k_bc R_d + delta_bd phi' u_c`` (minus on ``i``);
- ``d2 phi / dF_cd dF_ef = k_ce R_d R_f``;

and the strain part is mapped to ``e`` by the linear chain rule of
:func:`~jamflow.models.strain.strain_components` (``F`` is linear in ``e``, so no
further term). The extended Hessian ``H0`` (Eq. 27) sums the contact potential over
overlapping pairs that are not linked.

First derivatives come from THE contact Jacobian of :mod:`jamflow.network.jacobian`:
its link rows (:func:`~jamflow.network.jacobian.link_jacobian`, Eqs. 15-16) are the
columns of ``Gamma`` and its contact rows (:func:`~jamflow.network.jacobian.contact_jacobian`,
Eqs. 35-36) those of ``R0``, both with strain columns in the basis ``dF / de_k`` of the
model's strain coordinates (:func:`strain_coordinate_basis`); the energy gradient is
``-R0^T f``.

Change of basis (Eqs. 28-31): ``Gamma`` (n_dof x (L + 1), links and volume) is
factorised by a complete Householder QR, whose last ``n_dof - L - 1`` columns are an
orthonormal basis of ``Null(Gamma^T)``; their transpose is ``B`` (``y_t = B y``).

Constrained Hessian: the paper's ``H_E = B H0 B^T`` (Eq. 33) is the second derivative
on the constraint manifold only when the constraint forces vanish. At a force-balanced
state with link tensions ``mu`` and volume multiplier ``nu`` (``grad U = Gamma (mu, nu)``)
the second derivative of ``U`` along any curve on the manifold is
``B (H0 - sum_k mu_k grad^2 c_k - nu grad^2 det F) B^T`` (the curvature of the
constraints times their forces, a link being the pair function ``phi = |r|``, and
``d2 det F / dF_ab dF_cd = delta_ab delta_cd - delta_ad delta_bc`` at ``F = 1``).
:func:`constrained_hessian` includes that term by default (``tension_term=False``
gives Eq. 33 as printed); its test is the finite-difference second derivative of the
energy along ``B`` rows with Newton re-affixing onto the manifold.

Extended rigidity matrix (Eqs. 35-39): one row per contact (links excluded), the
gradient of its centre distance, ``R0 = (R_x, R_eps)`` with ``R_eps = n_a n_b r``
(the paper's ``sigma_ij`` is the contact distance ``r``), and ``R_E = R0 B^T``. States of
self stress are the left singular vectors of ``R_E`` with zero singular value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from numpy.typing import NDArray

from ..box import Box
from ..models.spheres.potential import HARMONIC, PowerLawPotential, overlapping_pairs
from ..models.strain import strain_components, strain_jacobian
from ..models.tangent import pair_hessian, volume_curvature
from ..network import contact_jacobian, link_jacobian, sphere_contacts
from ..state.bodies import Links
from ..state.packing import Packing

__all__ = [
    "ZERO_MODE_RTOL",
    "ConstrainedHessian",
    "constrained_hessian",
    "constraint_multipliers",
    "contact_virial",
    "extended_rigidity",
    "pair_second_derivatives",
    "strain_coordinate_basis",
]

#: An eigenvalue of a constrained Hessian (or a singular value of a rigidity matrix)
#: counts as zero below this fraction of the largest: dense float64 eigensolvers
#: resolve eigenvalues to ~1e-16 of the largest, and a jammed packing's softest
#: non-zero mode at P0 >= 1e-7 sits above ~1e-8 of it.
ZERO_MODE_RTOL: float = 1e-10


def strain_coordinate_basis(d: int, scale: float) -> NDArray[np.float64]:
    """``d eps / d e_k`` (m, d, d): the model's strain coordinates as a strain basis of
    :func:`~jamflow.network.jacobian.contact_jacobian` (``e_aa = q_s eps_aa``,
    ``e_ab = sqrt(2) q_s eps_ab``, upper-triangle order of :func:`~jamflow.models.strain.strain_matrix`)."""
    return strain_jacobian(d, scale).T.reshape(-1, d, d)


def pair_second_derivatives(n: int, d: int, i: NDArray[np.int64], j: NDArray[np.int64], R: NDArray[np.float64],
                            dphi: NDArray[np.float64], d2phi: NDArray[np.float64], strain_scale: float | None
                            ) -> NDArray[np.float64]:
    """Dense ``sum_p d2 phi_p(|F R_p|) / dq dq`` at zero strain (module doc), shape (n_dof, n_dof):
    :func:`jamflow.models.tangent.pair_hessian` in the strain coordinates of scale ``strain_scale``
    (None: positions only)."""
    J = None if strain_scale is None else strain_jacobian(d, strain_scale)
    return pair_hessian(n, d, i, j, R, dphi, d2phi, J).toarray()


@dataclass(frozen=True)
class ConstrainedHessian:
    """A constrained Hessian and its basis.

    Attributes
    ----------
    matrix : ndarray, shape (n_t, n_t)
        ``H_E`` in the basis of true degrees of freedom [epsilon / length^2].
    basis : ndarray, shape (n_t, n_dof)
        ``B`` (orthonormal rows spanning the tangent space).
    H0 : ndarray, shape (n_dof, n_dof)
        Extended (or positions-only) Hessian of the contact potential.
    eigenvalues : ndarray, shape (n_t,)
        Ascending.
    modes : ndarray, shape (n_dof, n_t)
        Normal modes mapped back to centres (and strain): ``B^T v``.
    n_zero : int
        Eigenvalues below :data:`ZERO_MODE_RTOL` times the largest.
    strain : bool
    """

    matrix: NDArray[np.float64]
    basis: NDArray[np.float64]
    H0: NDArray[np.float64]
    eigenvalues: NDArray[np.float64]
    modes: NDArray[np.float64]
    n_zero: int
    strain: bool

    @property
    def nonzero_eigenvalues(self) -> NDArray[np.float64]:
        """Eigenvalues above the zero threshold in magnitude, ascending (negative ones, if unstable, first)."""
        w = self.eigenvalues
        return w[np.abs(w) > ZERO_MODE_RTOL * np.abs(w).max()]


@dataclass(frozen=True)
class _Geometry:
    """First-order geometry of a packing at zero strain: contacts (unlinked overlapping pairs) and links."""

    n: int
    d: int
    position: NDArray[np.float64]  # (n, d) centres
    box: Box
    strain_scale: float
    pairs: object  # PairList of contacts
    force: NDArray[np.float64]  # (P,) repulsive contact forces
    k: NDArray[np.float64]  # (P,) contact stiffness phi''
    links: Links
    link_vector: NDArray[np.float64]  # (L, d) minimum image

    @property
    def m(self) -> int:
        return self.d * (self.d + 1) // 2


def _geometry(packing: Packing, potential: PowerLawPotential) -> _Geometry:
    links = packing.links if packing.links is not None else Links(np.empty(0, np.int64), np.empty(0, np.int64),
                                                                  np.empty(0))
    x, box, D = packing.position, packing.box, packing.diameter
    pairs, _, f = overlapping_pairs(x, box, D, potential)
    keep = ~links.contains(pairs.i, pairs.j)
    pairs, f = pairs.select(keep), f[keep]
    sigma = 0.5 * (D[pairs.i] + D[pairs.j])
    k = potential.stiffness(1.0 - pairs.distance / sigma, sigma)
    R = box.minimum_image(x[links.j] - x[links.i])
    return _Geometry(packing.n, packing.d, x, box, float(np.sqrt(packing.n) * D.mean()), pairs, f, k, links, R)


def gamma_matrix(geo: _Geometry, strain: bool, volume: bool = True) -> NDArray[np.float64]:
    """Dense ``Gamma`` (n_dof, L [+ 1]) at zero strain: link columns (and ``det F``), or ``Omega`` without strain.

    The link columns are the rows of :func:`~jamflow.network.jacobian.link_jacobian`.
    Built from geometry alone (no factorisation), so over-constrained position blocks
    (links closing loops around the box, which only the strain makes independent) are fine.
    """
    basis = strain_coordinate_basis(geo.d, geo.strain_scale) if strain else None
    G = link_jacobian(geo.links, geo.position, geo.box, strain=basis).toarray().T
    if strain and volume:
        # d det F / d e at F = 1: the strain columns of the trace, no position columns (Eq. 17)
        column = np.zeros(G.shape[0])
        column[geo.n * geo.d:] = strain_components(np.eye(geo.d), geo.strain_scale)
        G = np.hstack([G, column[:, None]])
    return G


def rigidity_rows(geo: _Geometry, strain: bool) -> NDArray[np.float64]:
    """Dense ``R0`` (n_c, n_dof): the contact rows of :func:`~jamflow.network.jacobian.contact_jacobian`
    (Eqs. 35-37) at zero strain, the paper's ``sigma_ij`` being the contact distance."""
    p = geo.pairs
    contacts = sphere_contacts(geo.position, geo.box, np.stack([p.i, p.j], axis=1), separation=p.dx)
    basis = strain_coordinate_basis(geo.d, geo.strain_scale) if strain else None
    return contact_jacobian(contacts, geo.n, geo.d, strain=basis).toarray()


def energy_gradient(geo: _Geometry, strain: bool) -> NDArray[np.float64]:
    """``dU/dq = -R0^T f`` of the contact potential at zero strain, shape (n_dof,) (``f`` repulsive)."""
    return -(geo.force @ rigidity_rows(geo, strain))


def contact_virial(geo: _Geometry) -> NDArray[np.float64]:
    """``W = sum f r r^T / r`` (d, d) of the contacts [epsilon]."""
    return np.einsum("p,pa,pb->ab", geo.force / geo.pairs.distance, geo.pairs.dx, geo.pairs.dx)


def constraint_multipliers(geo: _Geometry, strain: bool) -> tuple[NDArray[np.float64], float]:
    """Link tensions ``mu`` (L,) [epsilon / length] and the volume multiplier ``nu`` [epsilon].

    The tensions balance the position gradient exactly, ``Omega^T mu = dU/dx``: the
    centres are at force balance whatever holds the box. Where that leaves ``mu``
    free (links closing loops through the box, whose self-stress only the strain
    rows fix), the free part and ``nu`` are the least-squares balance of the strain
    gradient; that balance is exact for a shear-stabilised packing and leaves the
    deviatoric stress of a fixed-box packing to the box. ``nu = 0`` without strain.
    """
    n_x = geo.n * geo.d
    G = gamma_matrix(geo, strain, volume=True)
    g = energy_gradient(geo, strain)
    L = len(geo.links)
    if L == 0:
        mu = np.zeros(0)
    else:
        Gx = G[:n_x, :L]
        mu = np.linalg.lstsq(Gx, g[:n_x], rcond=None)[0]
    if not strain:
        return mu, 0.0
    loops = sla.null_space(G[:n_x, :L], rcond=ZERO_MODE_RTOL) if L else np.zeros((0, 0))
    columns = np.hstack([G[n_x:, :L] @ loops, G[n_x:, L:]])
    z = np.linalg.lstsq(columns, g[n_x:] - G[n_x:, :L] @ mu, rcond=None)[0]
    return mu + loops @ z[:-1], float(z[-1])


def tension_hessian(geo: _Geometry, strain: bool, volume: bool,
                    multipliers: tuple[NDArray[np.float64], float] | None = None) -> NDArray[np.float64]:
    """``M = H0 - sum_k mu_k grad^2 c_k [- nu grad^2 det F]`` with the multipliers of :func:`constraint_multipliers`.

    With ``volume`` the isotropic part of the strain gradient (the pressure) is
    carried by the constraint ``det F = 1``, whose curvature then enters; without, by
    an external load linear in the strain (the compliance of Sec. VI; no curvature).
    ``multipliers`` are ``constraint_multipliers(geo, strain)`` when already computed.
    """
    scale = geo.strain_scale if strain else None
    p = geo.pairs
    M = pair_second_derivatives(geo.n, geo.d, p.i, p.j, p.dx, -geo.force, geo.k, scale)
    mu, nu = constraint_multipliers(geo, strain) if multipliers is None else multipliers
    L = len(geo.links)
    if L:
        M -= pair_second_derivatives(geo.n, geo.d, geo.links.i, geo.links.j, geo.link_vector, mu,
                                     np.zeros(L), scale)
    if strain and volume:
        M[geo.n * geo.d:, geo.n * geo.d:] -= nu * volume_curvature(strain_jacobian(geo.d, geo.strain_scale))
    return M


def tangent_basis(gamma: NDArray[np.float64]) -> NDArray[np.float64]:
    """``B`` (n_dof - rank, n_dof): orthonormal rows spanning ``Null(Gamma^T)`` (complete QR, Eqs. 29-30).

    The rank is that of ``Gamma`` (links may be linearly dependent in position space
    when only the strain makes them independent, or be redundant outright).
    """
    Q, Rm, _ = sla.qr(gamma, mode="full", pivoting=True)
    diag = np.abs(np.diag(Rm))
    rank = int(np.sum(diag > ZERO_MODE_RTOL * diag.max())) if diag.size else 0
    return Q[:, rank:].T


def constrained_hessian(packing: Packing, potential: PowerLawPotential = HARMONIC, strain: bool = True,
                        tension_term: bool = True, volume: bool = True) -> ConstrainedHessian:
    """The constrained (extended) Hessian of a force-balanced linked packing (module doc).

    Parameters
    ----------
    packing : Packing
        At force balance (projected forces ~0); links optional.
    strain : bool
        Include the strain degrees of freedom (and, with ``volume``, ``det F = 1``).
    tension_term : bool
        Include the constraint-curvature term ``- sum mu_k grad^2 c_k - nu grad^2 det F``.
    volume : bool
        Keep the volume constraint among the constraints (``False``: ``B_-1`` of Sec. VI).
    """
    geo = _geometry(packing, potential)
    scale = geo.strain_scale if strain else None
    p = geo.pairs
    H0 = pair_second_derivatives(geo.n, geo.d, p.i, p.j, p.dx, -geo.force, geo.k, scale)
    H = tension_hessian(geo, strain, volume) if tension_term else H0
    B = tangent_basis(gamma_matrix(geo, strain, volume))
    HE = B @ H @ B.T
    HE = 0.5 * (HE + HE.T)
    w, v = np.linalg.eigh(HE)
    n_zero = int(np.sum(np.abs(w) <= ZERO_MODE_RTOL * np.abs(w).max()))
    return ConstrainedHessian(HE, B, H0, w, B.T @ v, n_zero, strain)


def extended_rigidity(packing: Packing, strain: bool = True, potential: PowerLawPotential = HARMONIC,
                      translations: bool = False, exclude: NDArray[np.float64] | None = None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Constrained extended rigidity matrix ``R_E = R0 B^T`` (Eqs. 35-39) and the states of self stress.

    Parameters
    ----------
    translations : bool
        Also remove the ``d`` uniform translations from the basis (the LP of Sec. V).
    exclude : ndarray, shape (N d, k), optional
        Further motions of the centres removed from the basis (no strain part): the free
        motions of clusters (:attr:`jamflow.network.BodyCount.free_motions`), which move
        no contact.

    Returns
    -------
    RE : ndarray, shape (n_c, n_t)
        One row per contact (overlapping unlinked pair).
    R0 : ndarray, shape (n_c, n_dof)
    self_stress : ndarray, shape (n_c, s)
        Orthonormal basis of the left null space of ``R_E`` (singular values below
        :data:`ZERO_MODE_RTOL` times the largest, and the ``n_c - n_t`` surplus rows).
    B : ndarray, shape (n_t, n_dof)
        The basis of true degrees of freedom.
    """
    geo = _geometry(packing, potential)
    n, d = geo.n, geo.d
    m = geo.m if strain else 0
    R0 = rigidity_rows(geo, strain)
    G = gamma_matrix(geo, strain)
    if translations:
        T = np.zeros((n * d + m, d))
        T[: n * d] = np.tile(np.eye(d), (n, 1))
        G = np.hstack([G, T])
    if exclude is not None and exclude.shape[1]:
        G = np.hstack([G, np.vstack([exclude, np.zeros((m, exclude.shape[1]))])])
    B = tangent_basis(G)
    RE = R0 @ B.T
    U, s, _ = np.linalg.svd(RE, full_matrices=True)
    rank = int(np.sum(s > ZERO_MODE_RTOL * s.max())) if s.size else 0
    return RE, R0, U[:, rank:], B
