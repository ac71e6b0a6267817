"""How much of the Verlet skin the event-driven motion has used since the list's build.

Collisions are predicted among listed pairs only (:mod:`.collisions`), so the list must
hold every pair that can meet before the next step ends. A minimiser checks its list
after the fact by comparing positions (:meth:`jamflow.neighbors.verlet.NeighborList.stale`);
the integrator must bound a step *before* taking it, from the velocities of the step.
Within one step every particle moves on a straight line with non-affine velocity
``U_i`` and velocity gradient ``E`` (:mod:`.collisions`), so a pair's separation
changes by at most ``|dU_i| + |dU_j|`` from the non-affine displacements and by
about ``s (1 + s) |R|`` from an affine deformation of accumulated norm
``s = integral |E|_2 dt``. Every unlisted pair was at least ``sigma_ij + skin``
apart at the build and ``|R| <= reach`` for the listed ones, so the list stays
valid while ``2 max_i |u_i| + s (1 + s) reach < skin`` (:class:`SkinBudget`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...neighbors.verlet import NeighborList
from .network import max_row_norm, spectral_norm

__all__ = ["SkinBudget"]


@dataclass
class SkinBudget:
    """Motion since the last build of the integrator's Verlet list.

    Attributes
    ----------
    displacement : ndarray, shape (N, d)
        Non-affine displacement accumulated since the build [lambda].
    strain_norm : float
        Accumulated ``integral |E|_2 dt`` since the build (affine change bound).
    """

    displacement: NDArray[np.float64]
    strain_norm: float = 0.0

    @classmethod
    def fresh(cls, x: NDArray[np.float64]) -> "SkinBudget":
        """Nothing used: the budget right after a build at positions ``x`` (N, d)."""
        return cls(np.zeros_like(x))

    def copy(self) -> "SkinBudget":
        """An independent copy (to restore after a trial move)."""
        return SkinBudget(self.displacement.copy(), self.strain_norm)

    def advance(self, velocity: NDArray[np.float64], gradient: NDArray[np.float64], dt: float) -> None:
        """Account for one straight-line step of length ``dt`` [time] with velocities ``velocity`` (N, d)
        and velocity gradient ``gradient`` (d, d)."""
        self.displacement += dt * velocity
        self.strain_norm += dt * spectral_norm(gradient)

    def valid(self, nl: NeighborList) -> bool:
        """Whether every pair closer than its contact distance is still guaranteed to be in ``nl``."""
        move = 2.0 * max_row_norm(self.displacement)
        # an affine deformation of size a changes |R| <= reach by at most ~a * reach
        move += self.strain_norm * (1.0 + self.strain_norm) * nl.reach
        return move < nl.skin

    def horizon(self, nl: NeighborList, velocity: NDArray[np.float64], gradient: NDArray[np.float64]) -> float:
        """Longest straight-line move [time] under ``velocity`` (N, d) and ``gradient`` (d, d)
        after which ``nl`` is still valid.

        The bound of :meth:`valid`, extended by the step: non-affine displacements grow
        by ``t max|U|``, the accumulated strain norm by ``t |E|_2``.
        """
        a, u = max_row_norm(self.displacement), max_row_norm(velocity)
        g = spectral_norm(gradient)
        s0, c = self.strain_norm, nl.reach
        # 2 (a + t u) + (s0 + t g) (1 + s0 + t g) c < skin, a quadratic A t^2 + B t + C < 0
        A = g * g * c
        B = 2.0 * u + g * c * (1.0 + 2.0 * s0)
        C = 2.0 * a + s0 * (1.0 + s0) * c - nl.skin
        if C >= 0.0:
            return 0.0
        if A > 0.0:
            return float(2.0 * -C / (B + np.sqrt(B * B - 4.0 * A * C)))
        return float(-C / B) if B > 0.0 else np.inf
