"""Linked soft spheres: pair repulsion plus holonomic fixed-length links.

Model of ``soft-chains-of-spheres-packings.md`` Sec. II. Spheres interact by the
power-law contact potential of :mod:`jamflow.models.spheres.potential` unless they are linked;
a link ``k = (i, j)`` is the constraint ``c_k = |x_ij| - l_k = 0`` with
``x_ij = x_j - x_i + h n_k`` (Eq. 1; the periodic image ``n_k`` is fixed by the
minimum image at construction, the box being fixed). Degrees of freedom are the
centres ``(N, d)`` flattened, unit masses.

Constraint Jacobian (Eq. 4, with the exact gradient): the row of link ``k`` is
``+u_k`` on ``j`` and ``-u_k`` on ``i``, ``u_k = x_ij / |x_ij|``. Clusters (connected
components of the link graph) share no degrees of freedom, so the Gram matrix
``G = Omega Omega^T`` is block diagonal, one ``m_c x m_c`` block per cluster of
``m_c`` links. Each block is Cholesky-factorised (:class:`ClusterGram`, numba
kernels in :mod:`jamflow.models._link_kernels`; the factor is the ``R`` of a QR of
``Omega_c^T``, so the orthonormal basis ``Omega_o = Omega^T L^-T`` of the paper is
implicit). One sweep over all clusters in a compiled loop replaced the batched
LAPACK QR (``numpy.linalg.qr`` per group of equal clusters): for the few-link
clusters of chains and rigid bodies the per-call overhead of LAPACK and numpy, not
arithmetic, was the cost (2D trimers N = 60: 23 % of the jamming time in
re-affixing, 9-15 % in projection). Then

- the tangent projection (Eq. 6) is ``P g = g - Omega^T G^-1 Omega g``, applied twice
  (one refinement step), which keeps ``Omega P g`` at round-off although the normal
  equations square the condition number of ``Omega``;
- Newton re-affixing (Eq. 7) takes the minimum-norm step solving
  ``Omega dx = -c``: ``dx = -Omega^T G^-1 c``, repeated until every link satisfies
  ``|r - l| / l <= LINK_LENGTH_RTOL``;
- the constraint forces are the least-squares multipliers ``mu = G^-1 Omega grad U``
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

from ..box import Box
from ..minimize import _fire_kernels
from ..minimize.model import ModelEvaluation
from ..neighbors import _verlet_kernels
from ..neighbors.verlet import NeighborList
from ..state.bodies import Links
from ..tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL
from . import _link_kernels
from .spheres import _kernels
from .spheres.model import SphereBodies
from .spheres.potential import HARMONIC, PowerLawPotential

__all__ = ["LINK_NEWTON_MAX_ITERATIONS", "ClusterGram", "LinkedSpheresModel"]

#: Newton sweeps allowed per re-affixing before it is declared failed: from a
#: violation of 1e-2 quadratic convergence needs ~4 sweeps to reach 1e-13.
LINK_NEWTON_MAX_ITERATIONS: int = 50


class ClusterGram:
    """The block-diagonal Gram matrix ``Omega Omega^T`` of links, one Cholesky block per cluster.

    Kernels in :mod:`jamflow.models._link_kernels` (numba). Rows of ``Omega`` are
    ``-w_k`` on ``i_k`` and ``+w_k`` on ``j_k`` for any per-link vectors ``w`` (L, d)
    given to :meth:`factorise`.

    Parameters
    ----------
    links : Links
    n, d : int
        Sphere count and dimension.
    """

    def __init__(self, links: Links, n: int, d: int) -> None:
        self.i = np.ascontiguousarray(links.i, dtype=np.int64)
        self.j = np.ascontiguousarray(links.j, dtype=np.int64)
        self.n, self.d = n, d
        if not len(links):
            self.labels = np.arange(n)
            self.order = np.empty(0, np.int64)
            self.cptr = self.fptr = np.zeros(1, np.int64)
            self.chol = np.empty(0)
            return
        self.labels = links.clusters(n)
        link_cluster = self.labels[self.i]
        self.order = np.argsort(link_cluster, kind="stable").astype(np.int64)
        clusters, m = np.unique(link_cluster, return_counts=True)
        spheres = np.bincount(self.labels)[clusters]
        over = np.flatnonzero(m > spheres * d)
        if over.size:
            c = over[0]
            raise ValueError(f"a cluster of {spheres[c]} particles has {m[c]} links, more than its "
                             f"{spheres[c] * d} coordinates: the links are redundant")
        self.clusters = clusters
        self.cptr = np.concatenate([[0], np.cumsum(m)]).astype(np.int64)
        self.fptr = np.concatenate([[0], np.cumsum(m * m)]).astype(np.int64)
        self.chol = np.zeros(int(self.fptr[-1]))

    def factorise(self, w: NDArray[np.float64]) -> None:
        """Cholesky factors of the Gram blocks of rows ``w`` (L, d); ValueError if a cluster is degenerate."""
        bad = _link_kernels.gram_factor(w, self.i, self.j, self.order, self.cptr, self.fptr, self.chol,
                                        LINK_RANK_RTOL)
        if bad >= 0:
            first = np.flatnonzero(self.labels == self.clusters[bad])
            raise ValueError(f"the links of the cluster of particles {first.tolist()} are degenerate "
                             f"(redundant constraints); remove a redundant link")

    def solve(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``G^-1 rhs`` for ``rhs`` (L,) or (L, k) (a new array)."""
        out = np.array(rhs, dtype=np.float64, order="C")
        if not out.size:
            return out
        _link_kernels.gram_solve(self.order, self.cptr, self.fptr, self.chol, out.reshape(len(out), -1))
        return out

    def apply(self, w: NDArray[np.float64], g: NDArray[np.float64]) -> NDArray[np.float64]:
        """``Omega g`` (L,) of ``g`` (N, d)."""
        out = np.empty(len(self.i))
        _link_kernels.omega_apply(w, self.i, self.j, g, out)
        return out

    def subtract_transpose(self, w: NDArray[np.float64], lam: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """``out -= Omega^T lam`` in place, ``out`` (N, d)."""
        _link_kernels.omega_t_subtract(w, self.i, self.j, lam, out)

    def project(self, w: NDArray[np.float64], g: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(g - Omega^T lam, lam)`` with ``lam = G^-1 Omega g``, ``g`` (N, d), in two passes.

        The second pass repeats the projection on what the first left: the normal
        equations lose ``cond(G) = cond(Omega)^2`` in relative accuracy, the second pass
        brings the residual ``Omega P g`` back to round-off of ``g``.
        """
        out = np.array(g, dtype=np.float64, order="C")
        lam = np.empty(len(self.i))
        _link_kernels.gram_project(w, self.i, self.j, self.order, self.cptr, self.fptr, self.chol, out, lam)
        return out, lam


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
        self.gram = ClusterGram(links, self.n, self.d)
        self._li, self._lj = self.gram.i, self.gram.j
        self._geometry_q: NDArray[np.float64] | None = None
        self._factor_q: NDArray[np.float64] | None = None
        self._u = np.zeros((len(links), self.d))
        self._r = np.zeros(len(links))
        self._err = 0.0
        self._pair_build = -1

    def link_vectors(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``x_ij`` of every link, shape (L, d) [length]."""
        x = self.positions(q)
        return x[self.links.j] - x[self.links.i] + self.link_offset

    def link_errors(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Relative link-length errors ``(|x_ij| - l) / l``, shape (L,)."""
        return np.linalg.norm(self.link_vectors(q), axis=1) / self.links.length - 1.0

    def _geometry(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit link vectors at ``q`` (L, d), with lengths and the largest relative error (cached for the last ``q``)."""
        if self._geometry_q is None or not _link_kernels.same(q, self._geometry_q):
            x = np.ascontiguousarray(self.positions(q))
            self._err = _link_kernels.link_geometry(x, self._li, self._lj, self.link_offset, self.links.length,
                                                    self._u, self._r)
            self._geometry_q = np.array(q)
        return self._u

    def _factorise(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The Gram factors at ``q`` (cached for the last ``q``); returns the constraint rows ``w = u``."""
        w = self._geometry(q)
        if self._factor_q is None or not _link_kernels.same(q, self._factor_q):
            self.gram.factorise(w)
            self._factor_q = self._geometry_q
        return w

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        if not len(self.links):
            return np.array(g, dtype=np.float64)
        w = self._factorise(q)
        return self.gram.project(w, np.asarray(g, dtype=np.float64).reshape(self.n, self.d))[0].ravel()

    def newton_step(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """One Newton sweep of Eq. 7: the minimum-norm ``dx`` with ``Omega dx = -c``."""
        w = self._factorise(q)
        out = np.array(q, dtype=np.float64)
        lam = self.gram.solve(self._r - self.links.length)
        self.gram.subtract_transpose(w, lam, out.reshape(self.n, self.d))
        return out

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Newton re-affixing until ``max |r - l| / l <= length_rtol`` (RuntimeError if it fails)."""
        if not len(self.links):
            return q
        out = np.array(q, dtype=np.float64)
        for _ in range(LINK_NEWTON_MAX_ITERATIONS + 1):
            self._geometry(out)
            err = self._err
            if err <= self.length_rtol:
                return out
            out = self.newton_step(out)
        raise RuntimeError(f"Newton re-affixing of the links stalled at a relative length error {err:.3g} "
                           f"(asked {self.length_rtol:.3g}) after {LINK_NEWTON_MAX_ITERATIONS} sweeps")

    def max_force(self, g: NDArray[np.float64]) -> float:
        """Largest per-sphere norm of ``g`` (compiled: the generic FIRE asks once per step)."""
        return float(np.sqrt(_fire_kernels._max_force_sq(np.asarray(g, dtype=np.float64).reshape(self.n, self.d))))

    def _update_list(self, x: NDArray[np.float64]) -> None:
        """``nlist.update`` in this fixed box: the Verlet criterion (:func:`jamflow.neighbors._verlet_kernels._needs_rebuild`) compiled.

        The box never deforms between builds here, so the affine map and its norm
        (an SVD and an inverse per call, a third of a 2D N = 60 trimer step) are skipped.
        """
        nl = self.nlist
        if (nl.x_build.shape != x.shape or not np.array_equal(nl.h_build, self.box.matrix)
                or _verlet_kernels._needs_rebuild(x, nl.x_build, 1.0, 1.0, nl.reach, nl.skin, 0.0)):
            nl.build(x, self.box)

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
        """Link tensions ``mu = G^-1 Omega grad U`` per link, shape (L,) [energy / length]."""
        if not len(self.links):
            return np.zeros(0)
        w = self._factorise(q)
        return self.gram.project(w, np.asarray(gradient, dtype=np.float64).reshape(self.n, self.d))[1]

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        x = np.ascontiguousarray(self.positions(q))
        self._update_list(x)
        self._pairs()
        force = np.zeros_like(x)
        virial = np.zeros((self.d, self.d))
        energy, n_contacts = _kernels.pair_forces(
            x, 1.0, self._offset, self._pi, self._pj, self._sigma,
            self.potential.epsilon, self.potential.exponent, force, virial,
        )
        gradient = -force.ravel()
        if len(self.links):
            mu = self.multipliers(gradient, q)
            u = self._u
            virial = virial + (u.T * (mu * self._r)) @ u
        return ModelEvaluation(float(energy), gradient, virial, int(n_contacts))

    def rescaled(self, factor: float, position: NDArray[np.float64]) -> tuple[LinkedSpheresModel, NDArray[np.float64]]:
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
