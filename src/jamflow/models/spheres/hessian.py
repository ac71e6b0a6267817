"""Dynamical matrix (Hessian) of soft-sphere packings, its low modes, elastic moduli.

For a pair vector ``R = x_j - x_i`` (minimum image), ``r = |R|``, ``n = R / r`` the
pair block is ``K = V''(r) n n^T + (V'(r) / r) (1 - n n^T)``; the Hessian has
``H_ii += K``, ``H_jj += K``, ``H_ij = H_ji = -K`` (units epsilon / length^2).

Moduli with the non-affine correction (Maloney & Lemaître 2004; the compliance form
in the chains-of-spheres paper): for a homogeneous strain parameter ``e`` that maps
every pair vector ``R -> R + e dR/de`` (simple shear ``dR/dgamma = R_y e_x``,
dilation ``dR/depsilon = R``), ``Xi = d^2 U / dx de`` and, at mechanical equilibrium,

    d^2U/de^2 (relaxed) = d^2U/de^2 (affine) - Xi^T H^+ Xi.

The shear modulus is ``G = (1/V) d^2U/dgamma^2`` and the bulk modulus
``B = -V dP/dV = (1/(d^2 V)) d^2U/depsilon^2 + (d - 1) P / d`` (``V ~ (1 + epsilon)^d``).
``H^+`` acts on the non-rattler subspace: rattlers and their pairs are dropped, one backbone particle is pinned to
remove the d translations (``Xi`` is orthogonal to them, so the pinned solve is the
pseudo-inverse solve).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from ...box import Box
from ...neighbors.pairs import PairList
from ...network.spheres import find_rattlers
from .potential import HARMONIC, PowerLawPotential, overlapping_pairs

__all__ = ["ElasticModuli", "backbone_pairs", "elastic_moduli", "hessian", "lowest_modes"]


def _pair_blocks(pairs: PairList, diameter: NDArray[np.float64], potential: PowerLawPotential):
    D = diameter
    sigma = 0.5 * (D[pairs.i] + D[pairs.j])
    r = pairs.distance
    xi = 1.0 - r / sigma
    n = pairs.dx / r[:, None]
    k = potential.stiffness(xi, sigma)
    t = -potential.force(xi, sigma) / r
    d = pairs.dx.shape[1]
    nn = n[:, :, None] * n[:, None, :]
    return k[:, None, None] * nn + t[:, None, None] * (np.eye(d) - nn), k, r, n, xi, sigma


def backbone_pairs(
    x: ArrayLike, box: Box, diameter: ArrayLike, potential: PowerLawPotential = HARMONIC
) -> tuple[PairList, NDArray[np.bool_]]:
    """Overlapping pairs between non-rattlers, and the rattler mask (shape (N,))."""
    x = np.asarray(x, dtype=np.float64)
    pairs, _, _ = overlapping_pairs(x, box, diameter, potential)
    rattler = find_rattlers(len(x), box.d, np.stack([pairs.i, pairs.j], axis=1))
    keep = ~(rattler[pairs.i] | rattler[pairs.j])
    return pairs.select(keep), rattler


def hessian(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    pairs: PairList | None = None,
) -> sp.csr_matrix:
    """Sparse Hessian ``d^2 U / dx_ia dx_jb``, shape (N d, N d), index ``i * d + a``.

    Parameters
    ----------
    x : array_like, shape (N, d)
    box : Box
    diameter : array_like, shape (N,)
    potential : PowerLawPotential
        Needs ``exponent >= 2`` (finite curvature at contact).
    pairs : PairList, optional
        Pairs to include (default: all overlapping pairs).
    """
    x = np.asarray(x, dtype=np.float64)
    D = np.asarray(diameter, dtype=np.float64)
    if potential.exponent < 2.0:
        raise ValueError("the Hessian diverges at contact for exponent w < 2")
    if pairs is None:
        pairs, _, _ = overlapping_pairs(x, box, D, potential)
    n_part, d = x.shape
    K = _pair_blocks(pairs, D, potential)[0]
    a = np.arange(d)
    ia = (pairs.i[:, None] * d + a)  # (P, d)
    ja = (pairs.j[:, None] * d + a)
    rows, cols, vals = [], [], []
    for r_idx, c_idx, sign in ((ia, ia, 1.0), (ja, ja, 1.0), (ia, ja, -1.0), (ja, ia, -1.0)):
        rows.append(np.broadcast_to(r_idx[:, :, None], K.shape).ravel())
        cols.append(np.broadcast_to(c_idx[:, None, :], K.shape).ravel())
        vals.append(sign * K.ravel())
    size = n_part * d
    H = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(size, size))
    return H.tocsr()


def lowest_modes(
    H: sp.spmatrix, d: int, k: int = 6, keep: NDArray[np.bool_] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The ``k`` lowest eigenpairs of ``H`` without the ``d`` global translations.

    Shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) just below zero; the ``d``
    computed modes with the largest weight on uniform translations are dropped.

    Parameters
    ----------
    H : sparse matrix, shape (N d, N d)
    d : int
    k : int
    keep : ndarray of bool, shape (N,), optional
        Particles to keep (e.g. non-rattlers); rows and columns of the others are
        removed first, so their zero modes do not appear.

    Returns
    -------
    eigenvalues : ndarray, shape (k,), ascending [epsilon / length^2 per unit mass]
    eigenvectors : ndarray, shape (N_kept d, k), normalised columns
    """
    if keep is not None:
        idx = (np.flatnonzero(keep)[:, None] * d + np.arange(d)).ravel()
        H = H[idx][:, idx]
    size = H.shape[0]
    m = k + d
    if m >= size - 1:
        w, v = np.linalg.eigh(H.toarray())
        w, v = w[:m], v[:, :m]
    else:
        scale = float(abs(H.diagonal()).mean()) or 1.0
        # a seeded start vector: ARPACK's own draws depend on the calls made before in the process
        start = np.random.default_rng(0).standard_normal(size)
        w, v = spla.eigsh(H.tocsc(), k=m, sigma=-1e-8 * scale, which="LM", v0=start)
    order = np.argsort(w)
    w, v = w[order], v[:, order]
    translations = np.zeros((size, d))
    for a in range(d):
        translations[a::d, a] = 1.0
    translations /= np.linalg.norm(translations, axis=0)
    weight = np.sum((translations.T @ v) ** 2, axis=0)
    drop = np.argsort(weight)[-d:]
    keep_modes = np.setdiff1d(np.arange(len(w)), drop)[:k]
    return w[keep_modes], v[:, keep_modes]


@dataclass(frozen=True)
class ElasticModuli:
    """Linear elastic moduli of a soft packing [epsilon / length^d].

    Attributes
    ----------
    bulk, shear : float
        Relaxed (affine minus non-affine) bulk and shear moduli.
    bulk_affine, shear_affine : float
        Affine (Born) parts.
    pressure : float
        Virial pressure of the backbone.
    n_rattlers : int
    """

    bulk: float
    shear: float
    bulk_affine: float
    shear_affine: float
    pressure: float
    n_rattlers: int

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def elastic_moduli(
    x: ArrayLike, box: Box, diameter: ArrayLike, potential: PowerLawPotential = HARMONIC
) -> ElasticModuli:
    """Bulk and shear moduli with the non-affine correction (see module doc).

    The configuration must be at force balance (e.g. from FIRE to 1e-12); shear is
    Lees–Edwards simple shear with flow axis 0 and gradient axis 1.
    """
    x = np.asarray(x, dtype=np.float64)
    D = np.asarray(diameter, dtype=np.float64)
    n_part, d = x.shape
    pairs, rattler = backbone_pairs(x, box, D, potential)
    if len(pairs) == 0:
        raise ValueError("no backbone contacts: the packing is not jammed")
    K, k, r, nvec, xi, sigma = _pair_blocks(pairs, D, potential)
    f = potential.force(xi, sigma)
    R = pairs.dx
    V = box.volume
    pressure = float(np.sum(f * r) / (d * V))
    # affine second derivatives
    dr_g = R[:, 0] * R[:, 1] / r
    d2r_g = R[:, 1] ** 2 / r - R[:, 0] ** 2 * R[:, 1] ** 2 / r**3
    u_gg = float(np.sum(k * dr_g**2 - f * d2r_g))
    u_ee = float(np.sum(k * r**2))
    # mixed derivatives Xi (force responses to the affine strain)
    xi_shear_pair = K[:, :, 0] * R[:, 1][:, None]
    xi_bulk_pair = (k * r)[:, None] * nvec
    Xi = np.zeros((2, n_part, d))
    for c, pair_term in enumerate((xi_shear_pair, xi_bulk_pair)):
        for a in range(d):
            Xi[c, :, a] = (np.bincount(pairs.j, pair_term[:, a], minlength=n_part)
                           - np.bincount(pairs.i, pair_term[:, a], minlength=n_part))
    H = hessian(x, box, D, potential, pairs)
    backbone = np.flatnonzero(~rattler)
    free = backbone[1:]  # pin the first backbone particle: removes the translations
    idx = (free[:, None] * d + np.arange(d)).ravel()
    Hf = H[idx][:, idx].tocsc()
    rhs = np.stack([Xi[0].ravel()[idx], Xi[1].ravel()[idx]], axis=1)
    sol = spla.spsolve(Hf, rhs)
    correction = np.einsum("kc,kc->c", rhs, sol)
    u_gg_relaxed = u_gg - correction[0]
    u_ee_relaxed = u_ee - correction[1]
    return ElasticModuli(
        bulk=u_ee_relaxed / (d * d * V) + (d - 1) * pressure / d,
        shear=u_gg_relaxed / V,
        bulk_affine=u_ee / (d * d * V) + (d - 1) * pressure / d,
        shear_affine=u_gg / V,
        pressure=pressure,
        n_rattlers=int(rattler.sum()),
    )
