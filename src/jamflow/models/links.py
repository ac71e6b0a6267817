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

import copy
import functools

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..minimize import _fire_kernels
from ..minimize.fire import FireParameters, MinimizeResult, _fire_params
from ..minimize.model import ModelEvaluation, pressure_of
from ..minimize.newton import TangentNewton
from ..neighbors import _verlet_kernels
from ..neighbors.verlet import NeighborList
from ..state.bodies import Links
from ..tolerances import LINK_LENGTH_RTOL, LINK_RANK_RTOL
from . import _hinge_kernels, _link_kernels
from .spheres import _kernels
from .spheres.model import SphereBodies
from .spheres.potential import HARMONIC, PowerLawPotential
from .tangent import cluster_tangent_basis, pair_hessian

__all__ = ["LINK_NEWTON_MAX_ITERATIONS", "ClusterGram", "LinkedFire", "LinkedSpheresModel"]

#: Newton sweeps allowed per re-affixing before it is declared failed: from a
#: violation of 1e-2 quadratic convergence needs ~4 sweeps to reach 1e-13.
LINK_NEWTON_MAX_ITERATIONS: int = 50


class ClusterGram:
    """The block-diagonal Gram matrix ``Omega Omega^T`` of links, one Cholesky block per cluster.

    Kernels in :mod:`jamflow.models._link_kernels` (numba), which take the links in
    cluster order (``order``: cluster by cluster, by their ends within a cluster, so a
    chain's factor has a narrow envelope); the methods here take and return arrays in
    the links' own order. Rows of ``Omega`` are ``-w_k`` on ``i_k`` and ``+w_k`` on
    ``j_k`` for any per-link vectors ``w`` (L, d) given to :meth:`factorise`.

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
            self.order = self.first = self.ci = self.cj = np.empty(0, np.int64)
            self.cptr = self.fptr = np.zeros(1, np.int64)
            self.chol = self.sign = np.empty(0)
            return
        self.labels = links.clusters(n)
        link_cluster = self.labels[self.i]
        self.order = np.lexsort((self.j, self.i, link_cluster)).astype(np.int64)
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
        self.ci, self.cj = self.i[self.order], self.j[self.order]
        self.sign = np.zeros(int(self.fptr[-1]))
        self.first = np.empty(len(links), np.int64)
        _link_kernels.gram_structure(self.ci, self.cj, self.cptr, self.fptr, self.sign, self.first)
        self.chol = np.zeros(int(self.fptr[-1]))

    def fresh(self) -> ClusterGram:
        """The same cluster structure (shared, read-only arrays) with factors of its own."""
        other = copy.copy(self)
        other.chol = np.zeros_like(self.chol)
        return other

    def _other_blocks(self, body: NDArray[np.bool_]) -> dict:
        """Cluster-order indices of the links and factor entries of the clusters not marked in ``body``, and their blocks.

        Keys ``links``, ``factor``, ``cptr``, ``fptr`` and ``cluster`` (their index among all blocks).
        """
        m = np.diff(self.cptr)
        keep = np.flatnonzero(~body)
        return {"links": np.concatenate([np.arange(self.cptr[c], self.cptr[c + 1]) for c in keep]
                                        or [np.empty(0, np.int64)]).astype(np.int64),
                "factor": np.concatenate([np.arange(self.fptr[c], self.fptr[c + 1]) for c in keep]
                                         or [np.empty(0, np.int64)]).astype(np.int64),
                "cptr": np.concatenate([[0], np.cumsum(m[keep])]).astype(np.int64),
                "fptr": np.concatenate([[0], np.cumsum(m[keep] ** 2)]).astype(np.int64), "cluster": keep}

    @functools.cached_property
    def rigid_layout(self) -> dict:
        """Which clusters are rigid in 2D, their spheres, and the Gram blocks of the others (:class:`LinkedFire`).

        A 2D cluster of ``n`` spheres with ``2 n - 3`` independent links has only rigid
        motions (two translations, one rotation). Keys: ``rptr``, ``members`` (the rigid
        clusters' spheres, cluster by cluster) and those of :meth:`_other_blocks`.
        """
        m = np.diff(self.cptr)
        if not len(m):
            empty = np.empty(0, np.int64)
            return {"rptr": np.zeros(1, np.int64), "members": empty, "links": empty, "factor": empty,
                    "cptr": np.zeros(1, np.int64), "fptr": np.zeros(1, np.int64), "cluster": empty}
        spheres = np.bincount(self.labels)[self.clusters]
        rigid = (spheres * self.d - m == 3) if self.d == 2 else np.zeros(len(m), bool)
        order = np.argsort(self.labels, kind="stable")
        starts = np.searchsorted(self.labels[order], self.clusters)
        members = np.concatenate([order[a:a + n] for a, n in zip(starts[rigid], spheres[rigid])]
                                 or [np.empty(0, np.int64)]).astype(np.int64)
        return {"rptr": np.concatenate([[0], np.cumsum(spheres[rigid])]).astype(np.int64), "members": members,
                **self._other_blocks(rigid)}

    @functools.cached_property
    def hinge_layout(self) -> dict:
        """The hinged 3D clusters and the Gram blocks of the others (:class:`LinkedFire`, :mod:`._hinge_kernels`).

        A hinged cluster is four spheres with five distinct links, every pair but one
        (two rigid triangles sharing an edge; a chain of four with frozen angles). Keys:
        ``spheres`` (H, 4) ``(a, b, c, t)`` with ``b -> c`` the shared edge and ``t`` the
        tip turned by the torsion, ``anchor`` (H, 3) the links (own order) from ``b`` to
        ``a``, ``c``, ``t`` with their signs ``+1`` when ``b`` is the link's first end,
        and those of :meth:`_other_blocks`.
        """
        m = np.diff(self.cptr)
        hinge = np.zeros(len(m), bool)
        rows, anchor, signs = [], [], []
        for c in np.flatnonzero(m == 5) if self.d == 3 else []:
            k = self.order[self.cptr[c]:self.cptr[c + 1]]
            ends = np.stack([self.i[k], self.j[k]], axis=1)
            nodes, degree = np.unique(ends, return_counts=True)
            link_of = {frozenset(e): int(q) for e, q in zip(ends.tolist(), k)}
            if len(nodes) != 4 or len(link_of) != 5:
                continue
            tips, axis = nodes[degree == 2], nodes[degree == 3]
            b, cc = int(axis[0]), int(axis[1])
            row = [int(tips[0]), b, cc, int(tips[1])]
            own = [link_of[frozenset((b, s))] for s in (row[0], cc, row[3])]
            hinge[c] = True
            rows.append(row)
            anchor.append(own)
            signs.append([1.0 if self.i[q] == b else -1.0 for q in own])
        return {"spheres": np.array(rows, np.int64).reshape(-1, 4), "anchor": np.array(anchor, np.int64).reshape(-1, 3),
                "anchor_sign": np.array(signs).reshape(-1, 3), **self._other_blocks(hinge)}

    def degenerate(self, c: int) -> ValueError:
        """The error for the degenerate links of cluster ``c`` (an index into the factor blocks)."""
        first = np.flatnonzero(self.labels == self.clusters[c])
        return ValueError(f"the links of the cluster of particles {first.tolist()} are degenerate "
                          f"(redundant constraints); remove a redundant link")

    def factorise(self, w: NDArray[np.float64]) -> None:
        """Cholesky factors of the Gram blocks of rows ``w`` (L, d); ValueError if a cluster is degenerate."""
        bad = _link_kernels.gram_factor(np.ascontiguousarray(w[self.order]), self.sign, self.first, self.cptr,
                                        self.fptr, self.chol, LINK_RANK_RTOL)
        if bad >= 0:
            raise self.degenerate(bad)

    def solve(self, rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """``G^-1 rhs`` for ``rhs`` (L,) or (L, k) (a new array)."""
        rhs = np.asarray(rhs, dtype=np.float64)
        if not rhs.size:
            return np.array(rhs)
        out = np.ascontiguousarray(rhs[self.order])
        _link_kernels.gram_solve(self.first, self.cptr, self.fptr, self.chol, out.reshape(len(out), -1))
        result = np.empty_like(out)
        result[self.order] = out
        return result

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
        _link_kernels.gram_project(np.ascontiguousarray(w[self.order]), self.ci, self.cj, self.first, self.cptr,
                                   self.fptr, self.chol, out, lam)
        result = np.empty_like(lam)
        result[self.order] = lam
        return out, result


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
    gram : ClusterGram, optional
        The cluster structure of the same links (shared by :meth:`rescaled`).
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
        gram: ClusterGram | None = None,
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
        self.gram = ClusterGram(links, self.n, self.d) if gram is None else gram.fresh()
        self._li, self._lj = self.gram.i, self.gram.j
        self._geometry_q: NDArray[np.float64] | None = None
        self._factor_q: NDArray[np.float64] | None = None
        self._u = np.zeros((len(links), self.d))
        self._r = np.zeros(len(links))
        self._err = 0.0
        self._pair_build = -1

    @functools.cached_property
    def lever(self) -> float:
        """Largest ratio of a contact's lever arm in the virial to its contact distance (:func:`.spheres.potential.energy_floor`).

        At force balance the link tensions turn the virial into a sum over contacts of
        ``f`` times the distance of the two clusters' centroids, at most the contact
        distance plus twice :meth:`~jamflow.state.bodies.Links.centroid_reach`.
        """
        return 1.0 + 2.0 * self.links.centroid_reach(self.n) / float(self.diameter.min())

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

    def listed_pairs(self, x: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64],
                                                         NDArray[np.float64]]:
        """``(i, j, offset, sigma)`` of the unlinked pairs of the neighbour list at centres ``x``, rebuilt if stale."""
        self._update_list(x)
        self._pairs()
        return self._pi, self._pj, self._offset, self._sigma

    def fire_engine(self, q: NDArray[np.float64], params: FireParameters, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> LinkedFire | None:
        """The compiled FIRE loop at fixed box (:class:`LinkedFire`); None for enthalpy (no box degree of freedom).

        None too for a subclass with an energy of its own (another :meth:`evaluate`): the
        loop computes this class's energy, not the subclass's.
        """
        if pressure0 is not None or type(self).evaluate is not LinkedSpheresModel.evaluate:
            return None
        return LinkedFire(self, q, params)

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
                                   self.nlist, self.length_rtol, self.gram)
        return model, x

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        raise NotImplementedError("the Hessian on the links' manifold is tangent_newton(q); the unconstrained one "
                                  "is not a Hessian of this model")

    def _lagrangian_pairs(self, x: NDArray[np.float64], R_links: NDArray[np.float64], tensions: NDArray[np.float64]
                          ) -> tuple[NDArray[np.float64], ...]:
        """Pair functions of the Lagrangian ``U - sum_k mu_k c_k`` at centres ``x`` (:func:`.tangent.pair_hessian`
        arguments ``i, j, R, phi', phi''``): the overlapping listed unlinked pairs (the list of the last
        :meth:`evaluate` at ``x``) and the links ``R_links`` as ``phi = -mu |r|``."""
        R = x[self._pj] - x[self._pi] + self._offset
        xi = 1.0 - np.linalg.norm(R, axis=1) / self._sigma
        c = xi > 0.0
        sigma = self._sigma[c]
        return (np.concatenate([self._pi[c], self.links.i]), np.concatenate([self._pj[c], self.links.j]),
                np.concatenate([R[c], R_links]), np.concatenate([-self.potential.force(xi[c], sigma), -tensions]),
                np.concatenate([self.potential.stiffness(xi[c], sigma), np.zeros(len(self.links))]))

    def tangent_newton(self, q: NDArray[np.float64]) -> TangentNewton:
        """The Newton system on the links' manifold at ``q`` (:class:`~jamflow.minimize.newton.TangentNewton`).

        Lagrangian Hessian ``H0 - sum_k mu_k grad^2 c_k`` with the tensions of :meth:`multipliers`
        (:mod:`.tangent`), reduced on the per-cluster orthonormal basis of ``Null(Omega)``;
        :meth:`reproject` is the retraction.
        """
        ev = self.evaluate(q)
        R = self.link_vectors(q)
        H = pair_hessian(self.n, self.d, *self._lagrangian_pairs(np.ascontiguousarray(self.positions(q)), R,
                                                                  self.multipliers(ev.gradient, q)))
        T = cluster_tangent_basis(self.gram.labels, self.links.i, self.links.j,
                                  R / np.linalg.norm(R, axis=1)[:, None])
        n, d = self.n, self.d
        return TangentNewton.reduce(H, T, ev, lambda dq: float(np.sqrt(np.max(np.sum(dq.reshape(n, d) ** 2, axis=1)))))


class LinkedFire:
    """FIRE steps of linked spheres at fixed box in one compiled loop (:func:`._link_kernels.linked_fire`).

    The steps of the flat-vector FIRE (:class:`~jamflow.minimize.fire._ModelFire`) on
    this model, in numba: move, re-affixing, Gram factors, pair forces and projections
    fused; re-affixing runs cluster by cluster, starting with chord sweeps on the last
    point's factors (:func:`._link_kernels.reaffix`). The loop rebuilds its neighbour list itself in
    an orthogonal box and returns to Python for the build otherwise; the state
    persists across calls. It keeps its own link geometry and factors (links in
    the cluster order of :class:`ClusterGram`), so the model's caches stay valid.

    Hinged 3D clusters (:attr:`ClusterGram.hinge_layout`: chains of four with frozen
    angles) move in generalised coordinates (:mod:`._hinge_kernels`): the same projection
    as the Gram path to round-off, no factorisation and no re-affixing, links held at
    every step to the start's error; another retraction, so another path at second order
    in the step (docs/notes/chains.md, "Hinged 3D clusters in generalised coordinates").
    ``hinged=False`` keeps them on the Gram path.
    """

    def __init__(self, model: LinkedSpheresModel, q: NDArray[np.float64], params: FireParameters,
                 hinged: bool = True) -> None:
        self.model = model
        self.builds0 = model.nlist.builds
        q = model.reproject(np.array(q, dtype=np.float64))
        self.x = np.ascontiguousarray(model.positions(q), dtype=np.float64)
        self.v = np.zeros_like(self.x)
        self.force = np.zeros_like(self.x)
        unit = model.time_unit
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.rigid, self.gram = _rigid_clusters(model, self.x, hinged)
        g = self.gram
        self.hinge = _hinge_bodies(model, self.x, hinged)
        h = self.hinge
        if len(h["spheres"]):
            model._factorise(q)  # degenerate links (a straight hinge) raise here: the Gram path's rank test
            _hinge_kernels.hinge_place(self.x, h["spheres"], h["shift"], h["body"], h["state"], h["geo"])
        # the link geometry (unit vectors, lengths) of x and its Gram factors, kept up to date by the loop
        self.w = np.zeros((len(g["ci"]), model.d))
        self.r = np.zeros(len(g["ci"]))
        self.chol = np.zeros_like(g["sign"])
        _link_kernels.link_geometry(self.x, g["ci"], g["cj"], g["offset"], g["length"], self.w, self.r)
        # the list in use (i, j, offset, sigma) and its build positions; the loop rebuilds it in an orthogonal box
        self.pairs: tuple[NDArray, ...] | None = None
        self.x_build = np.empty((0, model.d))
        self.lengths = np.diag(model.box.matrix).copy() if model.box.is_orthogonal else np.empty(0)
        self.adj_ptr = np.concatenate([[0], np.cumsum(np.bincount(model.links.i, minlength=model.n))]).astype(np.int64)
        self.inline_builds = 0

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)``.

        Lists are rebuilt inside the loop in an orthogonal box; else (``REBUILD``) the
        next call builds one here.
        """
        m, g, rigid, h = self.model, self.gram, self.rigid, self.hinge
        if self.pairs is None or rebuild:
            self.pairs = m.listed_pairs(self.x)
            self.x_build = np.array(m.nlist.x_build)
        nl = m.nlist
        status, n, _, _, _, _, bad, builds, *pairs = _link_kernels.linked_fire(
            self.x, self.v, self.fire_state, self.fparams, self.pairs[2], self.pairs[0], self.pairs[1], self.pairs[3],
            m.potential.epsilon, m.potential.exponent, self.x_build, nl.reach, nl.skin, self.lengths, m.diameter,
            self.adj_ptr, m.links.j, g["ci"], g["cj"], g["offset"], g["length"], g["sign"], g["first"], g["cptr"],
            g["fptr"], self.chol, self.w, self.r, rigid["rptr"], rigid["members"], rigid["shift"], rigid["ref"],
            h["spheres"], h["shift"], h["body"], h["state"], h["geo"], m.length_rtol, LINK_NEWTON_MAX_ITERATIONS,
            LINK_RANK_RTOL, float(force_tol), int(budget), float(energy_floor), self.force,
        )
        self.pairs = (pairs[0], pairs[1], pairs[2], pairs[3])
        self.inline_builds += builds
        if status == _fire_kernels.STALLED:
            if bad >= 0:
                raise m.gram.degenerate(int(g["cluster"][bad]))
            raise RuntimeError(f"Newton re-affixing of the links stalled (asked a relative length error "
                               f"{m.length_rtol:.3g}) after {LINK_NEWTON_MAX_ITERATIONS} sweeps")
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        """The run's outcome; energy, virial (pairs and link tensions) and force from one evaluation of the final state."""
        m = self.model
        q = self.x.ravel().copy()
        ev = m.evaluate(q)
        # from the final state itself: a run that ends on a rebuild has not evaluated it
        max_force = m.max_force(m.project(ev.gradient, q))
        return MinimizeResult(
            position=self.x.copy(), box=m.box, energy=ev.energy, pressure=pressure_of(ev, m.box),
            max_force=max_force, n_contacts=ev.n_contacts, steps=steps,
            converged=status == _fire_kernels.CONVERGED, rebuilds=m.nlist.builds - self.builds0 + self.inline_builds,
            evaluations=steps + 2, below=status == _fire_kernels.BELOW,
        )


def _rigid_clusters(model: LinkedSpheresModel, x: NDArray[np.float64], hinged: bool = False) -> tuple[dict, dict]:
    """The clusters of :class:`LinkedFire` at centres ``x`` (on the manifold): rigid 2D clusters and the Gram blocks of the others.

    Rigid clusters (:attr:`ClusterGram.rigid_layout`) are projected and placed rigidly
    (:func:`._link_kernels.rigid_project_2d`, :func:`._link_kernels.rigid_place_2d`),
    with their spheres' periodic shifts relative to each cluster's first sphere and
    their shapes (offsets from the centroid) taken from ``x``. The other clusters keep
    their Gram blocks (links in cluster order, sliced from ``model.gram``); ``hinged``
    leaves out the hinged 3D clusters too (:attr:`ClusterGram.hinge_layout`, :func:`_hinge_bodies`).
    """
    g = model.gram
    lay = g.rigid_layout
    blocks = g.hinge_layout if hinged and model.d == 3 else lay
    rptr, members = lay["rptr"], lay["members"]
    sizes = np.diff(rptr)
    anchor = np.repeat(members[rptr[:-1]], sizes)
    raw = x[members] - x[anchor]
    shift = model.box.minimum_image(raw) - raw if len(members) else np.zeros((0, model.d))
    y = x[members] + shift
    centroid = np.add.reduceat(y, rptr[:-1], axis=0) / sizes[:, None] if len(members) else y
    links, factor = blocks["links"], blocks["factor"]
    gram = {"ci": g.ci[links], "cj": g.cj[links], "offset": np.ascontiguousarray(model.link_offset[g.order[links]]),
            "length": np.ascontiguousarray(model.links.length[g.order[links]]), "sign": g.sign[factor],
            "first": g.first[links], "cptr": blocks["cptr"], "fptr": blocks["fptr"], "cluster": blocks["cluster"]}
    return ({"rptr": rptr, "members": members, "shift": np.ascontiguousarray(shift),
             "ref": np.ascontiguousarray(y - np.repeat(centroid, sizes, axis=0))}, gram)


def _hinge_bodies(model: LinkedSpheresModel, x: NDArray[np.float64], hinged: bool = True,
                  deformation: NDArray[np.float64] | None = None) -> dict:
    """The hinged 3D clusters of :class:`LinkedFire` at centres ``x`` (on the manifold) in the layout of :mod:`._hinge_kernels`.

    Body frame and origin from ``x``: the origin ``Y`` at sphere ``b``, no rotation, torsion
    angle 0; periodic shifts of ``a``, ``c``, ``t`` from the links to ``b``. Keys ``spheres``,
    ``shift`` (H, 4, 3), ``body``, ``state`` and ``geo`` (the geometry of the placement, set
    by :func:`._hinge_kernels.hinge_place`, which also puts the spheres back at ``x`` to round-off).
    None of them with ``hinged`` false or outside 3D. With a ``deformation`` ``F`` (d, d), ``x``
    are reference centres and the body frame is taken from the deformed offsets ``F (y_s - y_b)``
    (the shear-stabilised engine, :class:`jamflow.models.strain.StrainFire`).
    """
    lay = model.gram.hinge_layout
    H = len(lay["spheres"]) if hinged and model.d == 3 else 0
    spheres = lay["spheres"][:H]
    if not H:
        return {"spheres": spheres, "shift": np.zeros((0, 4, 3)), "body": np.zeros((0, _hinge_kernels.BODY_WIDTH)),
                "state": np.zeros((0, _hinge_kernels.STATE_WIDTH)), "geo": np.zeros((0, _hinge_kernels.GEO_WIDTH))}
    shift = np.zeros((H, 4, 3))
    shift[:, [0, 2, 3]] = model.link_offset[lay["anchor"]] * lay["anchor_sign"][..., None]
    y = x[spheres] + shift
    ref = y - y[:, 1:2] if deformation is None else (y - y[:, 1:2]) @ deformation.T
    axis = ref[:, 2] / np.linalg.norm(ref[:, 2], axis=1)[:, None]
    p = ref[:, 3]
    along = np.sum(p * axis, axis=1)[:, None] * axis
    body = np.ascontiguousarray(np.concatenate([ref[:, 0], ref[:, 2], axis, along, p - along, np.cross(axis, p)],
                                               axis=1).reshape(H, _hinge_kernels.BODY_WIDTH))
    state = np.zeros((H, _hinge_kernels.STATE_WIDTH))
    state[:, :3] = y[:, 1]
    state[:, 3] = state[:, 7] = 1.0
    geo = np.zeros((H, _hinge_kernels.GEO_WIDTH))
    return {"spheres": spheres, "shift": shift, "body": body, "state": state, "geo": geo}
