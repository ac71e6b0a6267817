"""The jamming LP (paper Eq. 2) in its well-scaled form: rows, their geometry, the
constraint matrix, the column bounds, and the LP as HiGHS takes it.

Rows are every pair (then every sphere-wall pair) within the cutoff ``ell``; each row
is divided by ``sigma_ij^2``, displacements are in mean diameters (``u = s / <D>``)
and the variable is ``g = Gamma - 1`` (the package docstring has the derivation)::

    2 <D> / sigma_ij^2 (x_j - x_i) . (u_i - u_j) + g <= (|r_ij|^2 - sigma_ij^2) / sigma_ij^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ...box import Box
from ...network import pair_rows
from .container import UPPER, _Container, wall_key

#: Largest diameter growth of one bounded LP, ``sqrt(Gamma) <= FAR_GROWTH``; it sets
#: the far bound through the cutoff so that no pair beyond the cutoff can overlap.
FAR_GROWTH: float = 1.2

#: Smallest usable cutoff [largest diameters]; the periodic box must hold it.
MIN_CUTOFF: float = 1.1

#: A start is near jamming when the median particle's smallest relative gap to a
#: neighbour is below this (measured: docs/notes/calippso-constants.md#near_start_gap).
NEAR_START_GAP: float = 1e-3

#: Contacts are the rows whose dual exceeds this fraction of the largest dual
#: (measured: docs/notes/calippso-constants.md#contact_dual_rel_tol).
CONTACT_DUAL_REL_TOL: float = 1e-10


@dataclass
class _Rows:
    """Constraint rows: particle pairs then sphere-wall rows."""

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    wall_particle: NDArray[np.int64]
    wall_face: NDArray[np.int64]
    x_build: NDArray[np.float64]
    cutoff: float  # absolute [length]

    @property
    def n_pairs(self) -> int:
        return len(self.i)

    def __len__(self) -> int:
        return len(self.i) + len(self.wall_particle)

    def keys(self, n: int) -> NDArray[np.int64]:
        """One integer per row naming its pair ``(i, j)`` or its wall ``(particle, face)``."""
        return np.concatenate([self.i * n + self.j, n * n + wall_key(self.wall_particle, self.wall_face)])


def _find_rows(x: NDArray[np.float64], D: NDArray[np.float64], container: _Container, cutoff: float) -> _Rows:
    """Algorithm 1, lines 4-6: every pair (and wall) within ``cutoff`` [length]."""
    i, j = container.pairs(x, cutoff)
    wp, wf = container.wall_bodies(x, D, cutoff)
    return _Rows(i, j, wp, wf, x.copy(), cutoff)


@dataclass(frozen=True)
class _RowGeometry:
    """Geometry of the rows at the current state: pair vectors ``dx`` (P, d) [length],
    contact distances ``sig`` (P,), scaled right-hand sides ``rhs`` (M,), wall distances
    ``a`` (W,) and radii ``rad`` (W,) of the sphere-wall rows."""

    dx: NDArray[np.float64]
    sig: NDArray[np.float64]
    rhs: NDArray[np.float64]
    a: NDArray[np.float64]
    rad: NDArray[np.float64]


def _near_start(x: NDArray[np.float64], D: NDArray[np.float64], container: _Container) -> bool:
    """Whether the median particle's smallest relative gap to a neighbour is below :data:`NEAR_START_GAP`."""
    i, j = container.pairs(x, MIN_CUTOFF * float(D.max()))
    sig = 0.5 * (D[i] + D[j])
    gap = np.linalg.norm(container.box.minimum_image(x[j] - x[i]), axis=1) / sig - 1.0
    nearest = np.full(len(D), np.inf)
    np.minimum.at(nearest, i, gap)
    np.minimum.at(nearest, j, gap)
    return bool(np.median(nearest) < NEAR_START_GAP)


def _row_geometry(rows: _Rows, x: NDArray[np.float64], D: NDArray[np.float64], box: Box) -> _RowGeometry:
    """Pair vectors, contact distances and right-hand sides for the current state."""
    dx = box.minimum_image(x[rows.j] - x[rows.i]) if rows.n_pairs else np.empty((0, x.shape[1]))
    sig = 0.5 * (D[rows.i] + D[rows.j])
    r = np.linalg.norm(dx, axis=1)
    rhs = (r - sig) * (r + sig) / sig**2
    axis = rows.wall_face // 2
    upper = rows.wall_face % 2 == UPPER
    xa = x[rows.wall_particle, axis]
    a = np.where(upper, box.lengths[axis] - xa, xa)
    rad = 0.5 * D[rows.wall_particle]
    wrhs = (a - rad) * (a + rad) / rad**2
    return _RowGeometry(dx, sig, np.concatenate([rhs, wrhs]), a, rad)


def _matrix(rows: _Rows, geo: _RowGeometry, n: int, d: int, unit: float) -> sp.csc_matrix:
    """Scaled constraint matrix (rows x (d N + 1)), column ``d N`` is ``g``."""
    coef = 2.0 * unit * geo.dx / geo.sig[:, None] ** 2  # (P, d)
    pairs = pair_rows(np.stack([rows.i, rows.j], axis=1), -coef, n)
    W = len(rows.wall_particle)
    sign = np.where(rows.wall_face % 2 == UPPER, 1.0, -1.0)
    wcoef = sign * 2.0 * unit * geo.a / geo.rad**2
    walls = sp.csr_matrix((wcoef, (np.arange(W), rows.wall_particle * d + rows.wall_face // 2)), shape=(W, d * n))
    m = rows.n_pairs + W
    A = sp.hstack([sp.vstack([pairs, walls]), sp.csr_matrix(np.ones((m, 1)))], format="csc")
    A.sort_indices()
    return A


def _most_neighbours(rows: _Rows, n: int) -> int:
    """The first anchor: the particle with most rows."""
    return int(np.argmax(np.bincount(np.concatenate([rows.i, rows.j]), minlength=n)))


def _column_bounds(b_part: NDArray[np.float64], d: int, anchor: int, ell: float, sig_max: float,
                   unit: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Column bounds: per-particle displacement bounds ``b_part`` [mean diameters] on
    every coordinate, the anchor fixed (``anchor < 0``: none), ``g >= -1`` and the cap
    ``sqrt(Gamma) <= min(FAR_GROWTH, (ell - 2 sqrt(d) b) / sigma_max)`` that keeps
    every pair beyond the cutoff apart in a bounded LP."""
    col_upper = np.append(np.repeat(b_part, d), 0.0)
    col_lower = -col_upper
    if anchor >= 0:
        col_lower[anchor * d:(anchor + 1) * d] = 0.0
        col_upper[anchor * d:(anchor + 1) * d] = 0.0
    col_lower[-1] = -1.0
    b_max = float(b_part.max())
    reach = (ell - 2.0 * np.sqrt(d) * b_max * unit) / sig_max if np.isfinite(b_max) else FAR_GROWTH
    col_upper[-1] = min(FAR_GROWTH, max(reach, 1.0)) ** 2 - 1.0
    return col_lower, col_upper


@dataclass(frozen=True)
class JammingLP:
    """One jamming LP in the scaled form of the module docstring: minimise ``-g``
    subject to ``A z <= rhs`` and ``col_lower <= z <= col_upper``, with
    ``z = (u_1, ..., u_N, g)`` (displacements in mean diameters, particle-major).

    Attributes
    ----------
    A : scipy.sparse.csc_matrix, shape (M, d N + 1)
    rhs : ndarray, shape (M,)
    col_lower, col_upper : ndarray, shape (d N + 1,)
    pairs : ndarray of int64, shape (P, 2)
        Particle pairs of the first P rows (wall rows follow).
    """

    A: sp.csc_matrix
    rhs: NDArray[np.float64]
    col_lower: NDArray[np.float64]
    col_upper: NDArray[np.float64]
    pairs: NDArray[np.int64]

    def to_highs(self) -> highspy.HighsLp:
        """The LP as a ``highspy.HighsLp``."""
        return _highs_lp(self.A, self.rhs, self.col_lower, self.col_upper)


def _highs_lp(A: sp.csc_matrix, rhs, col_lower, col_upper) -> highspy.HighsLp:
    """``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper`` (``g`` last)."""
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = A.shape[1], A.shape[0]
    cost = np.zeros(A.shape[1])
    cost[-1] = -1.0
    lp.col_cost_ = cost
    lp.col_lower_ = col_lower
    lp.col_upper_ = col_upper
    lp.row_lower_ = np.full(A.shape[0], -highspy.kHighsInf)
    lp.row_upper_ = rhs
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = A.indptr.astype(np.int32)
    lp.a_matrix_.index_ = A.indices.astype(np.int32)
    lp.a_matrix_.value_ = A.data.astype(np.float64)
    return lp


def _far_bound(cutoff: float, d: int) -> float:
    """Far-phase bound [current largest diameters] so that, with ``sqrt(Gamma) <= FAR_GROWTH``,
    no pair beyond the cutoff can reach contact: ``cutoff - 2 sqrt(d) b >= FAR_GROWTH``."""
    return max((cutoff - FAR_GROWTH) / (2.0 * np.sqrt(d)), 0.0)
