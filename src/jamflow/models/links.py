"""Linked soft spheres: pair repulsion plus holonomic fixed-length links.

Model of ``soft-chains-of-spheres-packings.md`` Sec. II. Spheres interact by the
power-law contact potential of :mod:`jamflow.soft.potential` unless they are linked;
a link ``k = (i, j)`` is the constraint ``c_k = |x_ij| - l_k = 0`` with
``x_ij = x_j - x_i + h n_k`` (Eq. 1; the periodic image ``n_k`` is fixed by the
minimum image at construction, the box being fixed). Degrees of freedom are the
centres ``(N, d)`` flattened, unit masses.

Constraint Jacobian (Eq. 4, with the exact gradient): the row of link ``k`` is
``+u_k`` on ``j`` and ``-u_k`` on ``i``, ``u_k = x_ij / |x_ij|``. Clusters (connected
components of the link graph) share no degrees of freedom, so ``Omega^T`` is block
diagonal. Each block is factorised as ``Omega_c^T = Q_c R_c`` (LAPACK Householder QR
via ``numpy.linalg.qr``, batched over clusters of one size and link count: chains and
rigid bodies of one kind come in many copies, and a dense QR of a block of
``n_c d`` rows costs microseconds, while a sparse factorisation of the whole
``Omega`` would couple nothing that is not already decoupled). ``Q_c`` is the
orthonormal constraint basis ``Omega_o`` of the paper, and

- the tangent projection (Eq. 6) is ``P g = g - Q (Q^T g)`` per cluster;
- Newton re-affixing (Eq. 7) takes the minimum-norm step solving
  ``Omega dx = -c``: ``dx = -Q R^-T c``, repeated until every link satisfies
  ``|r - l| / l <= LINK_LENGTH_RTOL``;
- the constraint forces are the least-squares multipliers ``mu = R^-1 Q^T grad U``
  (the link tensions, positive when a link pushes its ends apart); they enter the
  virial as ``mu_k r_k u_k u_k^T``, so the pressure of a linked packing at force
  balance includes the rods' stress.

Projections use the Euclidean metric, which is the mass metric because every
sphere has unit mass.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..bodies import Links
from ..box import Box
from ..soft import _kernels
from ..soft.potential import HARMONIC, NeighborList, PowerLawPotential
from ..tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL
from .base import ModelEvaluation
from .spheres import SphereBodies

__all__ = ["LINK_NEWTON_MAX_ITERATIONS", "LinkedSpheresModel"]

#: Newton sweeps allowed per re-affixing before it is declared failed: from a
#: violation of 1e-2 quadratic convergence needs ~4 sweeps to reach 1e-13.
LINK_NEWTON_MAX_ITERATIONS: int = 50


class _ClusterGroup:
    """Clusters of one particle count ``nc`` and link count ``lc`` (batched QR)."""

    def __init__(self, particles: NDArray[np.int64], links: NDArray[np.int64],
                 local_i: NDArray[np.int64], local_j: NDArray[np.int64], d: int) -> None:
        self.particles = particles  # (G, nc)
        self.links = links  # (G, lc) global link indices
        g, lc = links.shape
        a = np.arange(d)
        self.rows_i = local_i[:, :, None] * d + a  # (G, lc, d)
        self.rows_j = local_j[:, :, None] * d + a
        self.shape = (g, particles.shape[1] * d, lc)

    def factorise(self, u: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``Q, R`` of ``Omega^T`` of every cluster from unit link vectors ``u`` (L, d)."""
        g, m, lc = self.shape
        omega_t = np.zeros(self.shape)
        gi = np.arange(g)[:, None, None]
        ki = np.arange(lc)[None, :, None]
        uu = u[self.links]  # (G, lc, d)
        omega_t[gi, self.rows_i, ki] = -uu
        omega_t[gi, self.rows_j, ki] = uu
        q, r = np.linalg.qr(omega_t)
        diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
        bad = diag.min(axis=1) < LINK_RANK_RTOL * diag.max(axis=1)
        if np.any(bad):
            first = self.particles[int(np.flatnonzero(bad)[0])]
            raise ValueError(f"the links of the cluster of particles {first.tolist()} are degenerate "
                             f"(redundant constraints); remove a redundant link")
        return q, r


class LinkedSpheresModel(SphereBodies):
    """Soft spheres joined by fixed-length links (see the module doc).

    Parameters
    ----------
    box : Box
        Fixed periodic box.
    diameter : array_like, shape (N,)
        Diameters [length].
    links : Links
        Linked pairs and lengths [length]; every length below half the smallest box
        width (the periodic image of a link is then unique).
    position : array_like, shape (N, d)
        Centres [length] fixing each link's periodic image (minimum image).
    potential : PowerLawPotential
        Contact potential between spheres that are not linked.
    nlist : NeighborList, optional
    length_rtol : float
        Relative link-length precision kept by :meth:`reproject`.
    """

    constrained = True

    def __init__(
        self,
        box: Box,
        diameter: ArrayLike,
        links: Links,
        position: ArrayLike,
        potential: PowerLawPotential = HARMONIC,
        nlist: NeighborList | None = None,
        length_rtol: float = LINK_LENGTH_RTOL,
    ) -> None:
        super().__init__(box, diameter, potential, nlist)
        self.links = links
        if not length_rtol > 0.0:
            raise ValueError(f"length_rtol must be positive, got {length_rtol}")
        self.length_rtol = float(length_rtol)
        links.check_indices(self.n)
        if len(links) and links.length.max() >= 0.5 * float(np.min(box.widths)):
            raise ValueError(f"link length {links.length.max():.6g} must be below half the smallest box "
                             f"width ({0.5 * float(np.min(box.widths)):.6g})")
        x = np.asarray(position, dtype=np.float64).reshape(self.n, self.d)
        raw = x[links.j] - x[links.i]
        image = np.round((box.minimum_image(raw) - raw) @ box.inverse.T)
        self.link_offset = image @ box.matrix.T
        self._groups = self._cluster_groups()
        self._pair_build = -1
        self._geometry_q: NDArray[np.float64] | None = None
        self._geometry: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []

    def _cluster_groups(self) -> list[_ClusterGroup]:
        links, n = self.links, self.n
        if not len(links):
            return []
        labels = links.clusters(n)
        counts = np.bincount(labels)
        link_cluster = labels[links.i]
        link_counts = np.bincount(link_cluster, minlength=counts.size)
        order_p = np.argsort(labels, kind="stable")
        start_p = np.concatenate([[0], np.cumsum(counts)])
        local = np.empty(n, np.int64)
        local[order_p] = np.arange(n) - start_p[labels[order_p]]
        order_l = np.argsort(link_cluster, kind="stable")
        start_l = np.concatenate([[0], np.cumsum(link_counts)])
        linked = np.flatnonzero(link_counts > 0)
        kinds = np.unique(np.stack([counts[linked], link_counts[linked]], axis=1), axis=0)
        groups = []
        for nc, lc in kinds:
            if lc > nc * self.d:
                raise ValueError(f"a cluster of {nc} particles has {lc} links, more than its {nc * self.d} "
                                 f"coordinates: the links are redundant")
            cl = linked[(counts[linked] == nc) & (link_counts[linked] == lc)]
            particles = order_p[start_p[cl][:, None] + np.arange(nc)]
            glinks = order_l[start_l[cl][:, None] + np.arange(lc)]
            groups.append(_ClusterGroup(particles, glinks, local[links.i[glinks]], local[links.j[glinks]], self.d))
        return groups

    def link_vectors(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x_ij`` of every link, shape (L, d) [length]."""
        x = self.positions(q)
        return x[self.links.j] - x[self.links.i] + self.link_offset

    def link_errors(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Relative link-length errors ``(|x_ij| - l) / l``, shape (L,)."""
        return np.linalg.norm(self.link_vectors(q), axis=1) / self.links.length - 1.0

    def _factorise(self, q: NDArray[np.float64]) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per-group ``(Q, R)`` at ``q``, cached for the last ``q`` asked for."""
        if self._geometry_q is None or not np.array_equal(q, self._geometry_q):
            rvec = self.link_vectors(q)
            u = rvec / np.linalg.norm(rvec, axis=1)[:, None]
            self._geometry = [group.factorise(u) for group in self._groups]
            self._geometry_q = np.array(q)
        return self._geometry

    def _blocks(self, g: NDArray[np.float64], group: _ClusterGroup) -> NDArray[np.float64]:
        return g.reshape(self.n, self.d)[group.particles].reshape(group.shape[0], -1)

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.array(g, dtype=np.float64)
        view = out.reshape(self.n, self.d)
        for group, (Q, _) in zip(self._groups, self._factorise(q)):
            block = self._blocks(out, group)
            block -= np.einsum("gmk,gk->gm", Q, np.einsum("gmk,gm->gk", Q, block))
            view[group.particles] = block.reshape(group.particles.shape + (self.d,))
        return out

    def newton_step(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """One Newton sweep of Eq. 7: the minimum-norm ``dx`` with ``Omega dx = -c``."""
        out = np.array(q, dtype=np.float64)
        view = out.reshape(self.n, self.d)
        c = np.linalg.norm(self.link_vectors(q), axis=1) - self.links.length
        for group, (Q, R) in zip(self._groups, self._factorise(q)):
            y = np.linalg.solve(np.swapaxes(R, 1, 2), -c[group.links][:, :, None])[:, :, 0]
            dx = np.einsum("gmk,gk->gm", Q, y)
            view[group.particles] += dx.reshape(group.particles.shape + (self.d,))
        return out

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Newton re-affixing until ``max |r - l| / l <= length_rtol`` (RuntimeError if it fails)."""
        if not len(self.links):
            return q
        out = np.array(q, dtype=np.float64)
        for _ in range(LINK_NEWTON_MAX_ITERATIONS + 1):
            err = float(np.max(np.abs(self.link_errors(out))))
            if err <= self.length_rtol:
                return out
            out = self.newton_step(out)
        raise RuntimeError(f"Newton re-affixing of the links stalled at a relative length error {err:.3g} "
                           f"(asked {self.length_rtol:.3g}) after {LINK_NEWTON_MAX_ITERATIONS} sweeps")

    def _pairs(self) -> None:
        """Listed pairs minus linked pairs, refreshed after each neighbour-list build."""
        nl = self.nlist
        if self._pair_build == nl.builds:
            return
        keep = ~self.links.contains(nl.i, nl.j)
        self._pi, self._pj, self._sigma = nl.i[keep], nl.j[keep], nl.sigma[keep]
        self._offset = nl.image[keep] @ self.box.matrix.T
        self._pair_build = nl.builds

    def multipliers(self, gradient: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Link tensions ``mu = R^-1 Q^T grad U`` per link, shape (L,) [energy / length]."""
        mu = np.zeros(len(self.links))
        for group, (Q, R) in zip(self._groups, self._factorise(q)):
            rhs = np.einsum("gmk,gm->gk", Q, self._blocks(gradient, group))
            mu[group.links] = np.linalg.solve(R, rhs[:, :, None])[:, :, 0]
        return mu

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        x = np.ascontiguousarray(self.positions(q))
        self.nlist.update(x, self.box)
        self._pairs()
        force = np.zeros_like(x)
        virial = np.zeros((self.d, self.d))
        energy, n_contacts = _kernels.pair_forces(
            x, 1.0, self._offset, self._pi, self._pj, self._sigma,
            self.potential.epsilon, self.potential.exponent, force, virial,
        )
        gradient = -force.ravel()
        if len(self.links):
            rvec = self.link_vectors(q)
            r = np.linalg.norm(rvec, axis=1)
            mu = self.multipliers(gradient, q)
            virial = virial + np.einsum("k,ka,kb->ab", mu / r, rvec, rvec)
        return ModelEvaluation(float(energy), gradient, virial, int(n_contacts))

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple["LinkedSpheresModel", NDArray[np.float64]]:
        """The model in the box scaled by ``factor`` and the centres moved affinely.

        The affine move changes link lengths by ``factor - 1``; minimisers re-affix
        them (:meth:`reproject`) before their first step.
        """
        x = position * factor
        model = LinkedSpheresModel(self.box.scaled(factor), self.diameter, self.links, x, self.potential,
                                   self.nlist, self.length_rtol)
        return model, x

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        raise NotImplementedError("the constrained Hessian of linked spheres is not implemented yet")
