"""Compliance matrix and elastic moduli of linked packings (chains paper Sec. VI, Eqs. 43-49).

The constrained Hessian ``H_c = B_-1^T B_-1 M B_-1^T B_-1`` (Eq. 45) uses the basis
``B_-1`` of the link constraints with strain but without the volume constraint, and
``M = H0 - sum_k mu_k grad^2 c_k`` (the extended Hessian with the link tensions'
curvature, see :mod:`jamflow.chains.hessian`). Its Moore–Penrose pseudo-inverse
(Eq. 47) is ``B_-1^T (B_-1 M B_-1^T)^+ B_-1``: directions the links forbid get zero
strain for any stress, never an infinite stress. The strain block of it is the
compliance ``S`` (Eq. 49) in the model's strain coordinates ``e``; in the Mandel
basis (``eps_aa``, ``sqrt 2 eps_ab``) and per volume,
``S_M = V S_e / q_s^2`` [length^d / energy], so ``eps = S_M sigma`` with
``sigma = (1/V) dU/deps`` the stress conjugate to the strain (the loading is linear
in the strain, as in Eq. 44; at finite pressure moduli defined through ``P dV``
differ by terms of order the pressure).

Moduli (Voigt from the stiffness ``C = S_M^-1``, Reuss from ``S_M``, Hill their
mean; ``v`` the Mandel vector of the identity, ``K_dev = 1 - v v^T / d`` the
deviatoric projector, ``n_dev = d (d + 1) / 2 - 1`` its rank):

- ``K_V = v^T C v / d^2``, ``K_R = 1 / (v^T S v)``;
- ``G_V = tr(C K_dev) / (2 n_dev)``, ``G_R = n_dev / (2 tr(S K_dev))``;
- Poisson ratio from the Hill moduli, ``(3K - 2G) / (2 (3K + G))`` in 3D and
  ``(K - G) / (K + G)`` in 2D;
- universal anisotropy index ``A = n_dev G_V / G_R + K_V / K_R - (n_dev + 1)``
  (Ranganathan & Ostoja-Starzewski, PRL 101, 055504 (2008); 0 when isotropic).

Where ``S`` has zero eigenvalues (stresses the links carry without strain) the
stiffness is infinite along them: a Voigt modulus is ``inf`` when the null space of
``S`` has a component along its strain (volumetric ``v`` or deviatoric); a packing
with every contact a link has ``S = 0`` and every modulus infinite. Negative
eigenvalues of ``S`` are strains the packing is unstable to (a fixed-box packing
can have a negative shear modulus, Dagois-Bohy et al., PRL 109, 095703 (2012);
shear stabilisation removes them): they are kept, counted (``n_unstable``) and give
negative moduli, never infinite ones.

The moduli of :func:`jamflow.models.spheres.hessian.elastic_moduli` (``jamflow moduli`` of
spheres) follow from ``C`` without another solve. With ``W`` the total virial
(contacts and link tensions, ``P = tr W / (d V)``), ``F = 1 + eps`` linear:

- dilation ``F = (1 + e) 1``: ``B = -V dP/dV = K_V + (d - 1) P / d``;
- simple shear ``F = 1 + gamma e_x e_y^T`` is the symmetric strain
  ``eps_xy = gamma / 2`` up to a rotation and the second-order stretch
  ``gamma^2 (e_y e_y^T / 2 - (e_x e_x^T + e_y e_y^T) / 8)`` of its polar
  decomposition, so ``G_xy = (1/V) d^2U/dgamma^2 = C_xy,xy / 2 + (-W_yy + (W_xx + W_yy) / 4) / V``
  (``C_xy,xy`` the Mandel component): ``G_xy = C_xy,xy / 2 - P / 2`` at isotropic stress.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..models.spheres.potential import HARMONIC, PowerLawPotential
from ..models.strain import _upper
from ..state.packing import Packing
from .hessian import (
    ZERO_MODE_RTOL,
    _Geometry,
    _geometry,
    constraint_multipliers,
    contact_virial,
    gamma_matrix,
    tangent_basis,
    tension_hessian,
)

__all__ = ["Compliance", "compliance", "total_virial"]


@dataclass(frozen=True)
class Compliance:
    """Compliance and moduli of a packing (module doc); moduli in epsilon / length^d.

    Attributes
    ----------
    S : ndarray, shape (m, m)
        Compliance in the Mandel basis, per volume [length^d / epsilon].
    bulk_voigt, bulk_reuss, bulk_hill, shear_voigt, shear_reuss, shear_hill : float
        ``inf`` where infinite.
    poisson : float
        From the Hill moduli (NaN when a Hill modulus is infinite).
    anisotropy : float
        Universal anisotropy index (NaN when a modulus is infinite).
    n_rigid : int
        Zero eigenvalues of ``S`` (stress directions without strain).
    n_unstable : int
        Negative eigenvalues of ``S`` (strains of negative stiffness).
    bulk_dilation, shear_simple : float
        ``-V dP/dV`` and the simple-shear modulus in the x-y plane (module doc), the
        definitions of :func:`jamflow.models.spheres.hessian.elastic_moduli`; ``inf`` where infinite.
    pressure : float
        Virial pressure of contacts and link tensions [epsilon / length^d].
    """

    S: NDArray[np.float64]
    bulk_voigt: float
    bulk_reuss: float
    bulk_hill: float
    shear_voigt: float
    shear_reuss: float
    shear_hill: float
    poisson: float
    anisotropy: float
    n_rigid: int
    n_unstable: int
    bulk_dilation: float
    shear_simple: float
    pressure: float

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("bulk_voigt", "bulk_reuss", "bulk_hill", "shear_voigt", "shear_reuss",
                                               "shear_hill", "poisson", "anisotropy", "n_rigid", "n_unstable",
                                               "bulk_dilation", "shear_simple", "pressure")}


def strain_compliance(packing: Packing, potential: PowerLawPotential = HARMONIC
                      ) -> tuple[NDArray[np.float64], float, float]:
    """``S_e``, the strain block of ``H_c^+`` in the strain coordinates ``e`` (m, m), ``q_s`` and the stiffness scale.

    Eigenvalues of ``B_-1 M B_-1^T`` below :data:`~jamflow.chains.hessian.ZERO_MODE_RTOL`
    times the stiffness scale ``max |M_ij|`` (contact stiffnesses and tension
    curvatures, epsilon / length^2) are zero modes of the pseudo-inverse: a relative
    threshold on the eigenvalues alone would invert round-off when every mode is zero.
    """
    geo = _geometry(packing, potential)
    return _strain_compliance(geo, constraint_multipliers(geo, strain=True))


def _strain_compliance(geo: _Geometry, multipliers: tuple[NDArray[np.float64], float]
                       ) -> tuple[NDArray[np.float64], float, float]:
    n, d = geo.n, geo.d
    M = tension_hessian(geo, strain=True, volume=False, multipliers=multipliers)
    stiffness = float(np.abs(M).max(initial=0.0))
    B = tangent_basis(gamma_matrix(geo, strain=True, volume=False))
    HE = B @ M @ B.T
    w, v = np.linalg.eigh(0.5 * (HE + HE.T))
    keep = np.abs(w) > ZERO_MODE_RTOL * stiffness
    Vs = B[:, n * d:].T @ v[:, keep]
    return (Vs / w[keep]) @ Vs.T, geo.strain_scale, stiffness


def total_virial(packing: Packing, potential: PowerLawPotential = HARMONIC) -> NDArray[np.float64]:
    """``W`` (d, d) of the contacts and the link tensions [epsilon] (:class:`jamflow.minimize.model.ModelEvaluation`).

    The tensions are those of :func:`~jamflow.chains.hessian.constraint_multipliers`.
    """
    geo = _geometry(packing, potential)
    return _total_virial(geo, constraint_multipliers(geo, strain=True)[0])


def _total_virial(geo: _Geometry, mu: NDArray[np.float64]) -> NDArray[np.float64]:
    r = np.linalg.norm(geo.link_vector, axis=1)
    return contact_virial(geo) + np.einsum("k,ka,kb->ab", mu / r, geo.link_vector, geo.link_vector)


def compliance(packing: Packing, potential: PowerLawPotential = HARMONIC) -> Compliance:
    """Compliance matrix and Voigt, Reuss and Hill moduli of a force-balanced packing (module doc)."""
    geo = _geometry(packing, potential)
    multipliers = constraint_multipliers(geo, strain=True)
    S_e, scale, stiffness = _strain_compliance(geo, multipliers)
    d = packing.d
    to_mandel = packing.box.volume / scale**2
    S = to_mandel * S_e
    S = 0.5 * (S + S.T)
    a, b, _ = _upper(d)
    v = (a == b).astype(float)
    n_dev = a.size - 1
    dev = np.eye(a.size) - np.outer(v, v) / d
    w, U = np.linalg.eigh(S)
    # the smallest non-zero compliance is ~ 1 / (n_dof stiffness) in e units; zero below a tiny fraction of that
    scale = to_mandel / (max(stiffness, np.finfo(float).tiny) * S_e.shape[0] * packing.n * d)
    soft = np.abs(w) > ZERO_MODE_RTOL * scale
    null = U[:, ~soft]
    C = (U[:, soft] / w[soft]) @ U[:, soft].T
    tol = 1e-8
    inf = float("inf")
    bulk_voigt = inf if np.linalg.norm(null.T @ v) > tol else float(v @ C @ v) / d**2
    shear_voigt = inf if np.linalg.norm(dev @ null) > tol else float(np.trace(C @ dev)) / (2 * n_dev)
    vsv = float(v @ S @ v)
    bulk_reuss = inf if abs(vsv) <= ZERO_MODE_RTOL * scale else 1.0 / vsv
    tsd = float(np.trace(S @ dev))
    shear_reuss = inf if abs(tsd) <= ZERO_MODE_RTOL * scale else n_dev / (2.0 * tsd)
    bulk_hill, shear_hill = 0.5 * (bulk_voigt + bulk_reuss), 0.5 * (shear_voigt + shear_reuss)
    finite = np.isfinite([bulk_hill, shear_hill]).all()
    if not finite:
        poisson = float("nan")
    elif d == 3:
        poisson = (3 * bulk_hill - 2 * shear_hill) / (2 * (3 * bulk_hill + shear_hill))
    else:
        poisson = (bulk_hill - shear_hill) / (bulk_hill + shear_hill)
    anisotropy = (n_dev * shear_voigt / shear_reuss + bulk_voigt / bulk_reuss - (n_dev + 1)
                  if np.isfinite([bulk_voigt, shear_voigt, bulk_reuss, shear_reuss]).all() else float("nan"))
    W = _total_virial(geo, multipliers[0])
    V = packing.box.volume
    pressure = float(np.trace(W)) / (d * V)
    xy = int(np.flatnonzero((a == 0) & (b == 1))[0])
    simple = inf if np.linalg.norm(null[xy]) > tol else float(C[xy, xy]) / 2 + (-W[1, 1] + (W[0, 0] + W[1, 1]) / 4) / V
    return Compliance(S, bulk_voigt, bulk_reuss, bulk_hill, shear_voigt, shear_reuss, shear_hill, float(poisson),
                      float(anisotropy), int((~soft).sum()), int(np.sum(w[soft] < 0)),
                      bulk_voigt + (d - 1) * pressure / d, simple, pressure)
