"""Shear stabilisation of linked packings: strain degrees of freedom at fixed volume (chains paper Sec. II D-E).

Degrees of freedom ``q = (y, e)``: reference centres ``y`` (N, d) in the reference box
``H0`` and the ``m = d (d + 1) / 2`` independent components of a symmetric strain
``eps`` (Eqs. 11-12), scaled to lengths, ``e_aa = q_s eps_aa`` and
``e_ab = sqrt(2) q_s eps_ab`` (a < b), so that ``|e|^2 = q_s^2 ||eps||_F^2`` and a
unit-mass Euclidean projection is the mass-metric one; ``q_s = sqrt(N) <D>`` gives
the strain mode a stiffness of the order of a particle's (as the enthalpy
minimiser's box mode, :func:`jamflow.models.spheres.model.minimize_enthalpy`). The
deformation is ``F = 1 + eps``: centres ``F y``, lattice ``F H0`` (Eq. 23), pair and
link vectors ``F (y_j - y_i + H0 n)`` (Eq. 13). Unlike the paper, the strain is not
reset to zero after every step: ``F`` is kept exactly (the energy is that of the
finite deformation), which gives the same minima without re-linearising, and the
volume constraint is kept exactly, ``det F = 1``, instead of ``Tr eps = 0`` plus a
rescaling (its gradient ``det F F^-T`` is ``1`` at ``eps = 0``, Eq. 17).

Constraints ``Gamma`` (Eqs. 15-17): link ``k`` has gradient ``+-F^T u_k`` on its
ends and ``u_k R0_k^T`` (symmetrised) on the strain, ``u_k`` the current unit link
vector and ``R0_k`` the reference one (Eq. 16 at ``eps = 0``: ``tau_a tau_b l``);
the volume has ``det F F^-T`` on the strain only. The strain columns couple every
cluster, so the per-cluster Cholesky factors of :mod:`jamflow.models.links` are kept for the
link block ``A = B_y B_y^T = L L^T`` and the Gram matrix ``Gamma^T Gamma`` is solved by
Woodbury for the rank-``m`` strain coupling and a Schur complement for the volume
row. Projection (Eq. 18) ``P g = g - Gamma (Gamma^T Gamma)^-1 Gamma^T g`` and Newton
re-affixing (Eq. 7) ``dq = -Gamma (Gamma^T Gamma)^-1 c`` use that one solve.

Energy gradient on the strain: ``dU/dF = -W F^-1`` with ``W = sum f r r^T / r`` the
pair virial (Eq. 22 at ``eps = 0``). The reported virial adds the link tensions
(the multipliers of the projection), so at a shear-stabilised minimum the total
stress ``-W / V`` is isotropic: its deviatoric part is the volume multiplier's
residue, zero to the force tolerance.

Neighbours are searched in the rotated frame where the lattice ``F H0 = Q U`` is
upper triangular (``U``); energies are rotation invariant, and packings are written
in that frame (centres ``Q^T F y``, box ``U``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..minimize import _fire_kernels
from ..minimize.fire import (
    FireParameters,
    MinimizeResult,
    _fire_params,
    no_energy_floor,
)
from ..minimize.model import ModelEvaluation, pressure_of
from ..minimize.newton import TangentNewton
from ..neighbors import _verlet_kernels
from ..neighbors.verlet import NeighborList
from ..state.bodies import Links
from ..tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL
from . import _hinge_kernels, _link_kernels, _strain_kernels
from .links import (
    LINK_NEWTON_MAX_ITERATIONS,
    ClusterGram,
    LinkedSpheresModel,
    _hinge_bodies,
    _rigid_clusters,
)
from .spheres import _kernels
from .spheres.potential import HARMONIC, PowerLawPotential
from .tangent import cluster_tangent_basis, pair_hessian, volume_curvature

__all__ = ["ShearStabilizedModel", "StrainFire", "strain_components", "strain_jacobian", "strain_matrix"]


@lru_cache(maxsize=8)
def _upper(d: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Row and column of each independent strain component and its weight (1 on, sqrt 2 off the diagonal)."""
    a, b = np.triu_indices(d)
    return a, b, np.where(a == b, 1.0, np.sqrt(2.0))


def strain_matrix(e: NDArray[np.float64], d: int, scale: float) -> NDArray[np.float64]:
    """Symmetric strain ``eps`` (d, d) from the scaled components ``e`` (m,) (module doc)."""
    eps = np.zeros((d, d))
    a, b, weight = _upper(d)
    value = e / (scale * weight)
    eps[a, b] = value
    eps[b, a] = value
    return eps


def strain_components(G: NDArray[np.float64], scale: float) -> NDArray[np.float64]:
    """``dX/de`` (..., m) of scalars ``X`` with ``dX/dF = G`` (..., d, d): the chain rule of :func:`strain_matrix`."""
    a, b, weight = _upper(G.shape[-1])
    return (G[..., a, b] + G[..., b, a]) / (weight * scale) * np.where(a == b, 0.5, 1.0)


def strain_jacobian(d: int, scale: float) -> NDArray[np.float64]:
    """``dF / de``, shape (d * d, m): ``F`` is linear in ``e`` (:func:`strain_matrix`)."""
    a, b, weight = _upper(d)
    J = np.zeros((d * d, a.size))
    J[a * d + b, np.arange(a.size)] = 1.0 / (scale * weight)
    J[b * d + a, np.arange(a.size)] = 1.0 / (scale * weight)
    return J


class ShearStabilizedModel(LinkedSpheresModel):
    """Linked spheres with strain degrees of freedom at fixed volume (module doc).

    Parameters
    ----------
    box : Box
        Reference box ``H0``.
    diameter, links, position, potential, nlist, length_rtol
        As :class:`~jamflow.models.links.LinkedSpheresModel` (``links`` may be empty:
        shear-stabilised spheres).
    fixed_volume : bool
        Keep ``det F = 1`` (shear stabilisation); False frees the volume (the
        compliance of Sec. VI and its stress-controlled check).
    gram : ClusterGram, optional
        The cluster structure of the same links (shared by :meth:`rescaled`).
    """

    def __init__(self, box: Box, diameter: ArrayLike, links: Links, position: ArrayLike,
                 potential: PowerLawPotential = HARMONIC, nlist: NeighborList | None = None,
                 length_rtol: float = LINK_LENGTH_RTOL, fixed_volume: bool = True,
                 gram: ClusterGram | None = None) -> None:
        super().__init__(box, diameter, links, position, potential, nlist, length_rtol, gram)
        self.fixed_volume = fixed_volume
        self.m = self.d * (self.d + 1) // 2
        self.strain_scale = float(np.sqrt(self.n) * self.diameter.mean())
        self.n_dof = self.n * self.d + self.m
        self.inverse_mass = np.ones(self.n_dof)
        self._last_q: NDArray[np.float64] | None = None
        self._solver_q: NDArray[np.float64] | None = None
        self._strain_key: bytes | None = None
        self._h0 = np.ascontiguousarray(self.box.matrix)
        self._h_build_key: NDArray[np.float64] | None = None

    @property
    def box_dofs(self) -> bool:
        """With the volume free, every strain component is a box degree of freedom of the enthalpy engine."""
        return not self.fixed_volume

    def with_free_volume(self, position: NDArray[np.float64]) -> tuple[ShearStabilizedModel, NDArray[np.float64]]:
        """The model rebased on its last evaluated box (:meth:`rescaled` by 1) with the volume free, and the centres.

        The enthalpy stage of the jamming onset minimises ``U + P0 V`` on it
        (:func:`jamflow.minimize.onset.jam_model_to_pressure`): the shape is free already,
        so the stage frees the whole box and ends at the stress ``-P0 1``.
        """
        return self._rebased(1.0, position, fixed_volume=False)

    def energy_floor(self, pressure: float) -> float:
        """The linked spheres' floor at fixed volume (the box's shape changes, its volume not); 0 with the volume free."""
        return super().energy_floor(pressure) if self.fixed_volume else 0.0

    # --- degrees of freedom -----------------------------------------------------------
    def dofs(self, position: ArrayLike) -> NDArray[np.float64]:
        """``q`` of centres ``position`` in the reference box at zero strain."""
        return np.concatenate([super().dofs(position), np.zeros(self.m)])

    def _strain_state(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        """``(F, Q, T, U, det F, F^-1)`` of the strain part of ``q``, cached for the last strain.

        A minimiser asks for these several times per step at one strain (positions,
        link vectors, constraint columns, volume error); each is a few small LAPACK calls.
        """
        e = q[self.n * self.d:]
        key = e.tobytes()
        if key != self._strain_key:
            self._strain = _link_kernels.strain_state(np.ascontiguousarray(e), self._h0, self.strain_scale)
            self._strain_key = key
        return self._strain

    def deformation(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``F = 1 + eps`` (d, d)."""
        return self._strain_state(q)[0].copy()

    def current_box(self, q: NDArray[np.float64]) -> Box:
        """The deformed box ``U`` in the rotated frame."""
        return Box(self._strain_state(q)[3])

    def positions(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Centres in the rotated frame of :meth:`current_box`, shape (N, d)."""
        T = self._strain_state(q)[2]
        return q[: self.n * self.d].reshape(self.n, self.d) @ T.T

    def last_box(self) -> Box:
        """:meth:`current_box` of the last evaluated ``q`` (a minimiser's final state)."""
        if self._last_q is None:
            raise RuntimeError("the model has not been evaluated yet")
        return self.current_box(self._last_q)

    def _split(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return q[: self.n * self.d].reshape(self.n, self.d), q[self.n * self.d:]

    def link_vectors(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Current (unrotated) link vectors ``F R0_k``, shape (L, d)."""
        return self._reference_links(q) @ self._strain_state(q)[0].T

    def _reference_links(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        y, _ = self._split(q)
        return y[self.links.j] - y[self.links.i] + self.link_offset

    def volume(self, q: NDArray[np.float64]) -> float:
        """Box volume ``det F V_0`` at ``q`` [length^d] (an enthalpy wrapper, :mod:`jamflow.models.box`)."""
        return float(self._strain_state(q)[4]) * self.box.volume

    def volume_gradient(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``dV/dq`` (n_dof,): ``V_0 det F F^-T`` on the strain, zero on the centres."""
        _, _, _, _, det, F_inv = self._strain_state(q)
        return np.concatenate([np.zeros(self.n * self.d),
                               strain_components(self.box.volume * det * F_inv.T, self.strain_scale)])

    def volume_error(self, q: NDArray[np.float64]) -> float:
        """``det F - 1`` (0 when the volume is free)."""
        return self._strain_state(q)[4] - 1.0 if self.fixed_volume else 0.0

    # --- constraints ------------------------------------------------------------------
    def _solver(self, q: NDArray[np.float64]) -> dict:
        """Factorisation of ``Gamma^T Gamma`` at ``q`` (cached for the last ``q``)."""
        if self._solver_q is not None and _link_kernels.same(q, self._solver_q):
            return self._cache
        F, _, _, _, det, F_inv = self._strain_state(q)
        R0 = self._reference_links(q)
        r = R0 @ F.T
        u = r / np.linalg.norm(r, axis=1)[:, None]
        w = u @ F  # F^T u per link (rows)
        Be = strain_components(u[:, :, None] * R0[:, None, :], self.strain_scale)
        ce = strain_components(det * F_inv.T, self.strain_scale)
        w = np.ascontiguousarray(w)
        self.gram.factorise(w)
        cache = {"w": w, "Be": Be, "ce": ce}
        self._cache = cache
        AiBe = self._a_inverse(Be)
        cache["AiBe"] = AiBe
        cache["small"] = np.linalg.inv(np.eye(self.m) + Be.T @ AiBe)
        b = Be @ ce
        cache["b"], cache["Kib"] = b, self._k_inverse(b)
        cache["schur"] = float(ce @ ce - b @ cache["Kib"])
        self._solver_q = np.array(q)
        return cache

    def _a_inverse(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``A^-1 rhs`` for ``A = B_y B_y^T`` (block diagonal, Cholesky per cluster); rhs (L,) or (L, k)."""
        return self.gram.solve(rhs)

    def _k_inverse(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(A + B_e B_e^T)^-1 rhs`` by Woodbury, rhs (L,)."""
        c = self._cache
        a = self._a_inverse(rhs)
        return a - c["AiBe"] @ (c["small"] @ (c["Be"].T @ a))

    def _gram_solve(self, q: NDArray[np.float64], r_links: NDArray[np.float64], r_vol: float
                    ) -> tuple[NDArray[np.float64], float]:
        """``(lambda, nu)`` solving ``Gamma^T Gamma (lambda, nu) = (r_links, r_vol)`` (Schur on the volume row)."""
        c = self._solver(q)
        Kir = self._k_inverse(r_links)
        if not self.fixed_volume:
            return Kir, 0.0
        nu = (r_vol - c["b"] @ Kir) / c["schur"]
        return Kir - c["Kib"] * nu, float(nu)

    def _gamma_t(self, q: NDArray[np.float64], g: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        """``Gamma^T g``: (links (L,), volume)."""
        c = self._solver(q)
        gy, ge = self._split(np.asarray(g, dtype=np.float64))
        links = self.gram.apply(c["w"], np.ascontiguousarray(gy)) + c["Be"] @ ge
        return links, float(c["ce"] @ ge)

    def _gamma(self, q: NDArray[np.float64], lam: NDArray[np.float64], nu: float) -> NDArray[np.float64]:
        """``Gamma (lambda, nu)``, shape (n_dof,)."""
        c = self._solver(q)
        out = np.zeros(self.n_dof)
        self.gram.subtract_transpose(c["w"], -lam, out[: self.n * self.d].reshape(self.n, self.d))
        out[self.n * self.d:] = c["Be"].T @ lam + c["ce"] * nu
        return out

    def constraint_multipliers(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        """Least-squares multipliers ``(mu, nu)`` of ``g`` on the constraint gradients (link tensions, volume)."""
        return self._gram_solve(q, *self._gamma_t(q, g))

    def _centre_tensions(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Link tensions from the centres' rows alone, ``mu = A^-1 B_y g_y`` (L,).

        With a free volume the model's own strain row is not stationary (the enthalpy's
        ``P0 V`` balances it), so the least squares over every row would pass the
        unbalanced pair stress on to the rods; at a minimum of ``U + P0 V`` these are the
        tensions of ``g_y = B_y^T mu``, which the centres' rows fix alone.
        """
        c = self._solver(q)
        gy, _ = self._split(np.asarray(g, dtype=np.float64))
        return self._a_inverse(self.gram.apply(c["w"], np.ascontiguousarray(gy)))

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        lam, nu = self.constraint_multipliers(g, q)
        return np.asarray(g, dtype=np.float64) - self._gamma(q, lam, nu)

    def newton_step(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """One minimum-norm Newton sweep on the links and ``det F = 1``."""
        c_links = np.linalg.norm(self.link_vectors(q), axis=1) - self.links.length
        lam, nu = self._gram_solve(q, c_links, self.volume_error(q))
        return q - self._gamma(q, lam, nu)

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Newton re-affixing until every link and ``det F`` hold to ``length_rtol`` (relative).

        Chord iterations: the sweeps reuse the last factorised ``Gamma`` (a minimiser's
        previous point, one FIRE step away) as long as each sweep at least halves the
        error, and refactorise at the current point otherwise. Any fixed point lies on
        the constraint manifold; the chord only changes which nearby point of it is
        reached (by the square of the step), and saves the factorisation of the moved
        point, which the next evaluation would discard.
        """
        out = np.array(q, dtype=np.float64)
        chord = self._solver_q is not None
        previous = np.inf
        for _ in range(LINK_NEWTON_MAX_ITERATIONS + 1):
            c_links = np.linalg.norm(self.link_vectors(out), axis=1) - self.links.length
            c_volume = self.volume_error(out)
            err = max(float(np.max(np.abs(c_links / self.links.length), initial=0.0)), abs(c_volume))
            if err <= self.length_rtol:
                return out
            chord = chord and err <= 0.5 * previous
            base = self._solver_q if chord else out
            previous = err
            lam, nu = self._gram_solve(base, c_links, c_volume)
            out = out - self._gamma(base, lam, nu)
        raise RuntimeError(f"Newton re-affixing of links and volume stalled at a relative error {err:.3g} "
                           f"(asked {self.length_rtol:.3g}) after {LINK_NEWTON_MAX_ITERATIONS} sweeps")

    def multipliers(self, gradient: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.constraint_multipliers(gradient, q)[0]

    # --- energy -----------------------------------------------------------------------
    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        y, _ = self._split(q)
        _, Q, T, U, _, F_inv = self._strain_state(q)
        self._update_strained_list(np.ascontiguousarray(y @ T.T), U)
        self._pairs()
        force = np.zeros((self.n, self.d))
        virial = np.zeros((self.d, self.d))
        energy, n_contacts = _kernels.pair_forces_affine(
            np.ascontiguousarray(y), T, self._offset, self._pi, self._pj, self._sigma,
            self.potential.epsilon, self.potential.exponent, force, virial)
        W = Q @ virial @ Q.T  # unrotated pair virial
        gradient = np.concatenate([-(force @ T).ravel(), strain_components(-W @ F_inv, self.strain_scale)])
        if len(self.links):
            r = self.link_vectors(q)
            mu = self.multipliers(gradient, q) if self.fixed_volume else self._centre_tensions(gradient, q)
            W = W + np.einsum("k,ka,kb->ab", mu / np.linalg.norm(r, axis=1), r, r)
        self._last_q = np.array(q)
        return ModelEvaluation(float(energy), gradient, Q.T @ W @ Q, int(n_contacts))

    def _update_strained_list(self, x: NDArray[np.float64], U: NDArray[np.float64]) -> None:
        """``nlist.update`` in the deformed box ``U``, with the Verlet test compiled.

        The deformation since the build, ``A = U h_build^-1``, enters through the
        Frobenius norm ``||A - 1||_F >= ||A - 1||_2`` (no SVD per step; a list is at
        worst rebuilt a little earlier than needed), and the box object is made only
        when the list is rebuilt.
        """
        nl = self.nlist
        if nl.x_build.shape == x.shape:
            if self._h_build_key is not nl.h_build:
                self._h_build_inv, self._h_build_key = np.linalg.inv(nl.h_build), nl.h_build
            A = U @ self._h_build_inv
            slack = float(np.sqrt(np.sum((A - np.eye(self.d)) ** 2))) * nl.reach
            if not _verlet_kernels._needs_rebuild(x, nl.x_build @ A.T, 1.0, 1.0, nl.reach, nl.skin, slack):
                return
        nl.build(x, Box(U))

    def fire_engine(self, q: NDArray[np.float64], params: FireParameters, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> StrainFire | None:
        """The compiled FIRE loop (:class:`StrainFire`); with ``pressure0`` on ``U + P0 V`` over every
        strain component (the volume must be free; ``box_dof`` is "full" for this model whatever is
        asked, since its shape is free by construction), else None at fixed volume.

        None too for a subclass with an energy of its own (another :meth:`evaluate`): the
        loop computes this class's energy, not the subclass's.
        """
        if type(self).evaluate is not ShearStabilizedModel.evaluate:
            return None
        if pressure0 is None:
            return StrainFire(self, q, params)
        return None if self.fixed_volume else StrainFire(self, q, params, pressure0=pressure0)

    def max_force(self, g: NDArray[np.float64]) -> float:
        """Largest per-sphere norm of the centre part and the norm of the strain part of ``g``."""
        gy, ge = self._split(g)
        return max(float(np.sqrt(np.max(np.sum(gy**2, axis=1)))), float(np.linalg.norm(ge)))

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple[ShearStabilizedModel, NDArray[np.float64]]:
        """The model rebased on the last evaluated box (rotated frame), scaled by ``factor``, at zero strain.

        ``position`` are the centres a minimiser returned (:meth:`positions` of the
        last evaluated ``q``), so the pair of (box, centres) is consistent.
        """
        return self._rebased(factor, position, self.fixed_volume)

    def _rebased(self, factor: float, position: NDArray[np.float64], fixed_volume: bool
                 ) -> tuple[ShearStabilizedModel, NDArray[np.float64]]:
        """The model on the last evaluated box scaled by ``factor``, at zero strain, with ``fixed_volume``."""
        box = self.last_box().scaled(factor)
        x = np.asarray(position) * factor
        model = ShearStabilizedModel(box, self.diameter, self.links, x, self.potential, self.nlist, self.length_rtol,
                                     fixed_volume, self.gram)
        return model, x

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        raise NotImplementedError("the Hessian on the manifold of links and det F = 1 is tangent_newton(q) "
                                  "(jamflow.chains.hessian for a packing's dense one)")

    def tangent_newton(self, q: NDArray[np.float64]) -> TangentNewton | None:
        """The Newton system on the manifold of links and ``det F = 1`` at ``q`` of zero strain
        (:class:`~jamflow.minimize.newton.TangentNewton`); None with the volume free.

        Lagrangian Hessian ``H0 - sum_k mu_k grad^2 c_k - nu grad^2 det F`` with the multipliers
        of :meth:`constraint_multipliers` (:mod:`.tangent`). Tangent basis: the per-cluster
        orthonormal basis of ``Null(Omega)`` with no strain part, and ``m - 1`` columns for the
        strains ``de`` that keep the volume (``ce . de = 0``), their centres following by the
        minimum-norm ``dy = -Omega^T A^-1 B_e de`` (orthogonal to the first block), orthonormalised.
        Zero strain: a minimiser rebases the model on its deformed box (:meth:`rescaled` by 1).
        """
        if not self.fixed_volume:
            return None
        nd, m = self.n * self.d, self.m
        if np.any(q[nd:] != 0.0):
            raise ValueError("tangent_newton is taken at zero strain: rebase the model with rescaled(1.0, positions)")
        ev = self.evaluate(q)
        J = strain_jacobian(self.d, self.strain_scale)
        mu, nu = self.constraint_multipliers(ev.gradient, q)
        R = self._reference_links(q)
        H = pair_hessian(self.n, self.d, *self._lagrangian_pairs(np.ascontiguousarray(q[:nd].reshape(self.n, self.d)),
                                                                  R, mu), J)
        H = H - sp.block_diag([sp.csr_matrix((nd, nd)), nu * volume_curvature(J)], format="csr")
        Z = cluster_tangent_basis(self.gram.labels, self.links.i, self.links.j, R / np.linalg.norm(R, axis=1)[:, None])
        c = self._solver(q)
        keep = np.linalg.svd(c["ce"][None, :])[2][1:].T  # (m, m - 1): strains of constant volume
        centres = np.zeros((m - 1, self.n, self.d))
        lam = self._a_inverse(c["Be"] @ keep) if len(self.links) else np.zeros((0, m - 1))
        for t in range(m - 1):
            self.gram.subtract_transpose(c["w"], lam[:, t], centres[t])
        S = np.vstack([centres.reshape(m - 1, nd).T, keep])
        S = S @ np.linalg.inv(np.linalg.cholesky(S.T @ S)).T
        T = sp.bmat([[Z, sp.csr_matrix(S[:nd])], [None, sp.csr_matrix(S[nd:])]], format="csr")
        diameter = float(self.diameter.max())

        def move(dq: NDArray[np.float64]) -> float:
            # a pair vector r changes by dy_j - dy_i + eps r, |r| at most a diameter
            eps = np.linalg.norm(strain_matrix(dq[nd:], self.d, self.strain_scale), 2)
            return float(np.sqrt(np.max(np.sum(dq[:nd].reshape(self.n, self.d) ** 2, axis=1)))) + eps * diameter

        return TangentNewton.reduce(H, T, ev, move)


class StrainFire:
    """FIRE steps of shear-stabilised linked spheres in one compiled loop (:func:`._strain_kernels.strain_fire`).

    The steps of the flat-vector FIRE (:class:`~jamflow.minimize.fire._ModelFire`) on
    the model: move, re-affixing of links and volume (chord sweeps on the last point's
    factorisation), the Woodbury/Schur factorisation at the new point, pair forces in
    the deformed box and both projections, in numba. The loop rebuilds its list in the
    deformed (sheared) box itself (:func:`._strain_kernels.sheared_list`) and returns
    here for a build only in a box too sheared for it; the state persists across calls. Links in the cluster order of the model's
    :class:`~jamflow.models.links.ClusterGram`, with factors of its own.

    Rigid 2D clusters are rigid bodies, reference centre and angle (:mod:`._rigid_kernels`,
    :func:`_rigid_bodies`): no Gram factor, Woodbury column or re-affixing for them; the
    other clusters and the volume keep the constraint path. In the mass metric of unit
    sphere masses (centre mass ``n``, moment of inertia ``sum |r_s|^2``), which is the
    flat FIRE's on the bodies' motions at zero strain; the strain's mass stays 1.

    Hinged 3D clusters (chains of four with frozen angles, :attr:`ClusterGram.hinge_layout`)
    are bodies too (:func:`_strain_hinges`): the reference centre of their sphere ``b`` follows
    the strain affinely, their rotation (quaternion) and torsion live in the real frame
    (:mod:`._hinge_kernels`), so their links hold for every strain; they move by the real-space
    sphere velocities at fixed strain (unit sphere masses, the fixed-box hinged path's metric).
    ``hinged=False`` keeps them on the Gram/Woodbury path (docs/notes/chains.md, "Hinged 3D
    bodies in the shear-stabilised engine").
    """

    def __init__(self, model: ShearStabilizedModel, q: NDArray[np.float64], params: FireParameters,
                 hinged: bool = True, pressure0: float = 0.0) -> None:
        if pressure0 > 0.0 and model.fixed_volume:
            raise ValueError("enthalpy minimisation needs the volume free (fixed_volume=False)")
        self.model = model
        self.pressure0 = float(pressure0)
        self.builds0 = model.nlist.builds
        q = model.reproject(np.array(q, dtype=np.float64))
        y, e = model._split(q)
        self.y = np.ascontiguousarray(y, dtype=np.float64)
        self.e = np.array(e, dtype=np.float64)
        self.vy = np.zeros_like(self.y)
        self.ve = np.zeros_like(self.e)
        self.fy = np.zeros_like(self.y)
        self.fe = np.zeros_like(self.e)
        unit = model.time_unit
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.rigid, self.gram = _rigid_bodies(model, self.y, self.e, hinged)
        self.vb = np.zeros_like(self.rigid["body"])
        self.fb = np.zeros_like(self.vb)
        self.hinge = _strain_hinges(model, q, self.y, self.e, hinged)
        self.vh = np.zeros_like(self.hinge["r"])
        self.fh = np.zeros_like(self.vh)
        in_body = np.zeros(model.n, bool)
        in_body[self.rigid["members"]] = True
        in_body[self.hinge["spheres"].ravel()] = True
        self.free = np.flatnonzero(~in_body).astype(np.int64)  # the spheres that are degrees of freedom
        self.tol_scale = 1.0  # the loop's tolerance over the asked one (:meth:`advance`)
        self.chol = np.zeros_like(self.gram["sign"])
        self.adj_ptr = np.concatenate([[0], np.cumsum(np.bincount(model.links.i, minlength=model.n))]).astype(np.int64)
        # the list in use (i, j, reference offset, sigma), its build centres (reference frame) and box
        self.pairs: tuple[NDArray, ...] | None = None
        self.y_build = np.empty((0, model.d))
        self.h_build_inv = np.eye(model.d)
        self.inline_builds = 0

    def q(self) -> NDArray[np.float64]:
        """The present degree-of-freedom vector."""
        return np.concatenate([self.y.ravel(), self.e])

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)``; ``energy_floor`` at fixed volume only.

        Lists are rebuilt inside the loop; in a box too sheared or small for that
        (``REBUILD``) the next call builds one here. With rigid bodies the loop measures
        their forces as rigid-motion fields in their own metric
        (:func:`._rigid_kernels.rigid_max_force_sq`), not as the model's flat
        projection (:meth:`ShearStabilizedModel.max_force`, which :meth:`result` reports):
        a state the loop calls converged is checked against the model's measure, and the
        loop goes on with its tolerance scaled down until both hold. Hinged bodies likewise (the
        loop measures their real-space forces projected onto their motions at fixed strain).
        """
        if not self.model.fixed_volume:
            no_energy_floor(self, energy_floor)
        status, n = self._steps(force_tol * self.tol_scale, budget, rebuild, energy_floor)
        while status == _fire_kernels.CONVERGED and (len(self.vb) or len(self.vh)):
            q = self.q()
            flat = self._max_force(q, self.model.evaluate(q))
            if flat <= force_tol:
                break
            self.tol_scale *= 0.9 * force_tol / flat
            status, k = self._steps(force_tol * self.tol_scale, budget - n, False, energy_floor)
            n += k
        return status, n

    def _steps(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float) -> tuple[int, int]:
        """At most ``budget`` steps of the compiled loop to its own ``force_tol``; returns ``(status, steps)``."""
        m, g, rigid, h = self.model, self.gram, self.rigid, self.hinge
        if self.pairs is None or rebuild:
            q = self.q()
            _, _, T, U, _, _ = m._strain_state(q)
            m._update_strained_list(np.ascontiguousarray(self.y @ T.T), U)
            m._pairs()
            self.pairs = (m._pi, m._pj, m._offset, m._sigma)
            self.h_build_inv = np.linalg.inv(m.nlist.h_build)
            # reference centres of the build: x_build = T_b y_build with T_b = h_build h0^-1
            self.y_build = np.ascontiguousarray(m.nlist.x_build @ (m._h0 @ self.h_build_inv).T)
        nl = m.nlist
        pi, pj, offset, sigma = self.pairs
        status, n, _, _, _, _, bad, builds, *pairs = _strain_kernels.strain_fire(
            self.y, self.vy, self.e, self.ve, self.fire_state, self.fparams, m._h0, m.strain_scale, m.fixed_volume,
            offset, pi, pj, sigma, m.potential.epsilon, m.potential.exponent, self.y_build, self.h_build_inv,
            nl.reach, nl.skin, m.diameter, self.adj_ptr, m.links.j, g["ci"], g["cj"], g["offset"], g["length"],
            g["sign"], g["first"], g["cptr"], g["fptr"], self.chol, rigid["rptr"], rigid["members"], rigid["shift"],
            rigid["ref"], rigid["body"], self.vb, self.fb, rigid["inv_mass"], h["spheres"], h["local"], h["shift"],
            h["zero"], h["body"], h["state"], h["geo"], h["origin"], h["r"], self.vh, self.fh, self.free, m.length_rtol,
            LINK_NEWTON_MAX_ITERATIONS, LINK_RANK_RTOL, float(force_tol), int(budget), float(energy_floor),
            self.pressure0, self.fy, self.fe,
        )
        self.pairs = (pairs[0], pairs[1], pairs[2], pairs[3])
        self.inline_builds += builds
        if status == _fire_kernels.STALLED:
            if bad >= 0:
                raise m.gram.degenerate(int(g["cluster"][bad]))
            raise RuntimeError(f"Newton re-affixing of links and volume stalled (asked a relative error "
                               f"{m.length_rtol:.3g}) after {LINK_NEWTON_MAX_ITERATIONS} sweeps")
        return status, n

    def _max_force(self, q: NDArray[np.float64], ev: ModelEvaluation) -> float:
        """The model's largest projected force of what the loop minimises at ``q``: ``U`` (evaluated in
        ``ev``), plus ``P0 V`` with ``pressure0`` (:meth:`ShearStabilizedModel.volume_gradient`)."""
        m = self.model
        g = ev.gradient + self.pressure0 * m.volume_gradient(q) if self.pressure0 > 0.0 else ev.gradient
        return m.max_force(m.project(g, q))

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        """The run's outcome; energy ``U``, virial (pairs, link tensions) and the force of what the loop
        minimises (:meth:`_max_force`) from one evaluation of the final state."""
        m = self.model
        q = self.q()
        ev = m.evaluate(q)
        box = m.current_box(q)
        return MinimizeResult(
            position=np.array(m.positions(q)), box=box, energy=ev.energy, pressure=pressure_of(ev, box),
            max_force=self._max_force(q, ev), n_contacts=ev.n_contacts, steps=steps,
            converged=status == _fire_kernels.CONVERGED, rebuilds=m.nlist.builds - self.builds0 + self.inline_builds,
            evaluations=steps + 2, below=status == _fire_kernels.BELOW,
        )


def _rigid_bodies(model: ShearStabilizedModel, y: NDArray[np.float64], e: NDArray[np.float64],
                  hinged: bool = False) -> tuple[dict, dict]:
    """The rigid 2D clusters of :class:`StrainFire` as bodies at ``(y, e)`` (on the manifold), and the other clusters' Gram blocks.

    Bodies (:mod:`._rigid_kernels`): reference centre ``Y`` the mean of the unwrapped
    reference centres, angle 0, shape ``ref = F (y_s + shift_s - Y)`` (real space),
    inverse masses ``(1 / n, 1 / n, 1 / I)`` with ``I = sum |ref_s|^2``. The periodic
    shifts and the other clusters' blocks are those of :func:`.links._rigid_clusters` in
    the reference box (``hinged``: without the hinged 3D clusters, :func:`_strain_hinges`).
    """
    rigid, gram = _rigid_clusters(model, y, hinged)
    rptr, members = rigid["rptr"], rigid["members"]
    sizes = np.diff(rptr)
    F = _link_kernels.strain_state(np.ascontiguousarray(e), model._h0, model.strain_scale)[0]
    offset = rigid["ref"]  # reference offsets from the reference centroid
    ref = np.ascontiguousarray(offset @ F.T)
    body = np.zeros((len(sizes), 3))
    inv_mass = np.ones((len(sizes), 3))
    if len(sizes):
        body[:, :2] = (y[members] + rigid["shift"] - offset)[rptr[:-1]]
        inv_mass[:, :2] = 1.0 / sizes[:, None]
        inv_mass[:, 2] = 1.0 / np.add.reduceat(np.sum(ref**2, axis=1), rptr[:-1])
    rigid.update(ref=ref, body=body, inv_mass=inv_mass)
    return rigid, gram


def _strain_hinges(model: ShearStabilizedModel, q: NDArray[np.float64], y: NDArray[np.float64],
                   e: NDArray[np.float64], hinged: bool = True) -> dict:
    """The hinged 3D clusters of :class:`StrainFire` at ``(y, e)`` (on the manifold; ``q`` the same point).

    The arrays of :func:`.links._hinge_bodies` with the body frame from the deformed offsets
    ``F (y_s + shift_s - y_b)``, body origins at zero (``state``), and: ``origin`` (H, 3) the
    reference centres of the spheres ``b``, ``local`` (H, 4) the rows ``4 h + s`` of the real
    offsets ``r`` (4 H, 3) from ``b``, and ``zero`` shifts (placed here by
    :func:`._hinge_kernels.hinge_place` with the geometry ``geo``). Degenerate links (a straight
    hinge) raise the Gram path's rank error.
    """
    F = _link_kernels.strain_state(np.ascontiguousarray(e), model._h0, model.strain_scale)[0]
    h = _hinge_bodies(model, y, hinged, deformation=F)
    spheres = h["spheres"]
    H = len(spheres)
    h["origin"] = np.ascontiguousarray(y[spheres[:, 1]])
    h["state"][:, :3] = 0.0
    h["local"] = np.arange(4 * H, dtype=np.int64).reshape(H, 4)
    h["zero"] = np.zeros((H, 4, 3))
    h["r"] = np.zeros((4 * H, 3))
    if H:
        r = model.link_vectors(q)
        model.gram.fresh().factorise(r / np.linalg.norm(r, axis=1)[:, None])  # not the model's cached factors
        _hinge_kernels.hinge_place(h["r"], h["local"], h["zero"], h["body"], h["state"], h["geo"])
    return h
