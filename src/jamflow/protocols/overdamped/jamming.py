"""Jammed and potentially jammed contact networks (Lerner, Düring & Wyart, Sec. IV D).

The constrained subset is found by iteratively discarding particles with fewer than
``d + 1`` contacts among the remaining ones. With ``N_bar`` particles and ``N_c_bar``
contacts in it, the constrained coordination (Eq. 29) is
``z_bar = (2 (d - 1) + 2 N_c_bar) / N_bar``; the network is *potentially jammed*
when ``z_bar = 2 d``, i.e. ``N_c_bar = d N_bar - d + 1`` — compared in integers.
Then ``S^T`` has a one-dimensional kernel, the self-stress ``f0``; the packing is
jammed when ``f0`` has one sign.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...network import isostatic_count, prune_rattlers
from .network import pair_normals, pair_vectors
from .solver import s_matrix

__all__ = ["ConstrainedCount", "constrained_subset", "self_stress"]


@dataclass(frozen=True)
class ConstrainedCount:
    """Integer bookkeeping of Eq. 29.

    Attributes
    ----------
    member : ndarray of bool, shape (N,)
        Particles of the constrained subset.
    n_particles : int
        ``N_bar``.
    n_contacts : int
        Contacts between members, ``N_c_bar = sum_i z_bar_i / 2``.
    d : int
    """

    member: NDArray[np.bool_]
    n_particles: int
    n_contacts: int
    d: int

    @property
    def z_bar(self) -> float:
        """Constrained coordination (Eq. 29); 0 for an empty subset."""
        if self.n_particles == 0:
            return 0.0
        return (2 * (self.d - 1) + 2 * self.n_contacts) / self.n_particles

    @property
    def potentially_jammed(self) -> bool:
        """``z_bar == 2 d`` in integer arithmetic (``N_c_bar = d N_bar - d + 1``)."""
        return self.n_particles > 0 and self.n_contacts == isostatic_count(self.n_particles, self.d, global_dofs=self.d)

    @property
    def may_self_stress(self) -> bool:
        """Whether the network may carry a self-stress: the constrained count is within d of
        potential jamming, or hyperstatic (solves then check N's pivots).

        An empty constrained subset carries none: a particle with at most d contacts
        balances nonzero forces only in degenerate (collinear) geometry, which an
        unchecked solve still reports as singular.
        """
        return self.n_particles > 0 and self.excess >= -self.d

    @property
    def excess(self) -> int:
        """``N_c_bar - (d N_bar - d + 1)``: > 0 hyperstatic, 0 potentially jammed; -1 if empty."""
        if self.n_particles == 0:
            return -1
        return self.n_contacts - isostatic_count(self.n_particles, self.d, global_dofs=self.d)


def constrained_subset(n: int, d: int, pairs: NDArray[np.int64]) -> ConstrainedCount:
    """Constrained subset of a contact network (Sec. IV D): the non-rattlers of
    :func:`jamflow.network.prune_rattlers` (fewer than ``d + 1`` contacts, iterated).

    Parameters
    ----------
    n, d : int
        Number of particles and dimension.
    pairs : ndarray of int64, shape (Nc, 2)
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    member = ~prune_rattlers(pairs, n, dofs_per_body=d, compiled=True)
    alive = member[pairs[:, 0]] & member[pairs[:, 1]]
    return ConstrainedCount(member, int(member.sum()), int(alive.sum()), d)


def self_stress(
    x: NDArray[np.float64],
    h: NDArray[np.float64],
    pairs: NDArray[np.int64],
    images: NDArray[np.float64],
    drive_rates: NDArray[np.float64],
) -> tuple[NDArray[np.float64], float]:
    """Null vector ``f0`` of ``S^T`` (footnote 23: by diagonalisation), signed to resist the drive.

    The kernel vector is the right singular vector of ``S^T`` with the smallest
    singular value (dense SVD; the network is at most a few thousand contacts when
    this is called). Its sign is chosen so that the drive does positive work against
    it, ``-<f0 | S V_drive> > 0``; with the drive orthogonal to it (no work), so that
    its sum is positive.

    Parameters
    ----------
    drive_rates : ndarray, shape (Nc,)
        ``S V_aff / xi0 + S F_ext`` on the network (the right-hand side of Eq. 18 / 11
        with the sign flipped).

    Returns
    -------
    f0 : ndarray, shape (Nc,)
        Unit-norm self-stress.
    residual : float
        ``|S^T f0|`` relative to ``|f0|``: close to zero when a self-stress exists.
    """
    n = len(x)
    R = pair_vectors(x, h, pairs, images)
    S = s_matrix(pairs, pair_normals(R), n).toarray()
    # smallest right singular vector of S^T (shape (Nd, Nc)) = smallest left singular vector of S
    u, s, _ = np.linalg.svd(S, full_matrices=True)
    f0 = u[:, -1] if len(s) < S.shape[0] else u[:, np.argmin(s)]
    work = -float(f0 @ drive_rates)
    scale = float(np.linalg.norm(drive_rates))
    if abs(work) > 1e-12 * max(scale, 1e-300):
        f0 = f0 * np.sign(work)
    elif f0.sum() < 0:
        f0 = -f0
    residual = float(np.linalg.norm(S.T @ f0))
    return f0, residual
