"""Periodic simulation boxes in any dimension, orthogonal or sheared.

A box is the lattice spanned by the columns of the matrix ``h`` (shape ``(d, d)``).
Orthogonal boxes have a diagonal ``h``; a Lees–Edwards box sheared by strain
``gamma`` in the plane of the first two axes (flow along axis 0, gradient along
axis 1) has ``h[0, 1] = gamma * L_1``. Any upper-triangular ``h`` is accepted.

Minimum-image displacements are exact at any strain: the lattice spanned by ``h``
does not change when the tilt ``h[0, 1]`` moves by a multiple of ``h[0, 0]``, so the
search runs on a basis whose tilts are reduced to ``|h[i, j]| <= h[i, i] / 2``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Box", "lattice_volume"]


def lattice_volume(h: NDArray[np.float64]) -> float:
    """Volume of the box with upper-triangular lattice matrix h, shape (d, d) [length^d].

    ``det h``, the product of the diagonal (the form every box here takes; :class:`Box`
    rejects others). For code that carries h as a bare array along a trajectory.
    """
    return float(np.prod(np.diagonal(h)))


@dataclass(frozen=True, eq=False)
class Box:
    """A periodic box with lattice vectors as the columns of ``matrix``.

    Parameters
    ----------
    matrix : array_like, shape (d, d)
        Upper-triangular lattice matrix [length]; column ``k`` is lattice vector k.
    """

    matrix: NDArray[np.float64]

    def __post_init__(self) -> None:
        h = np.array(self.matrix, dtype=np.float64)
        if h.ndim != 2 or h.shape[0] != h.shape[1]:
            raise ValueError(f"box matrix must be square (d, d), got shape {h.shape}")
        if h.shape[0] < 2:
            raise ValueError(f"box dimension must be >= 2, got {h.shape[0]}")
        if not np.all(np.isfinite(h)):
            raise ValueError("box matrix contains non-finite entries")
        if np.any(np.tril(h, -1) != 0.0):
            raise ValueError("box matrix must be upper triangular (tilt above the diagonal)")
        if np.any(np.diag(h) <= 0.0):
            raise ValueError(f"box side lengths must be positive, got {np.diag(h)}")
        h.setflags(write=False)
        object.__setattr__(self, "matrix", h)

    # constructors -----------------------------------------------------------------
    @classmethod
    def cubic(cls, d: int, length: float = 1.0) -> "Box":
        """Orthogonal box with all sides equal to ``length`` [length]."""
        return cls(np.eye(d) * float(length))

    @classmethod
    def orthogonal(cls, lengths: ArrayLike) -> "Box":
        """Orthogonal box with side lengths ``lengths`` (shape (d,)) [length]."""
        return cls(np.diag(np.asarray(lengths, dtype=np.float64)))

    @classmethod
    def lees_edwards(cls, lengths: ArrayLike, gamma: float) -> "Box":
        """Orthogonal box of side ``lengths`` sheared by strain ``gamma`` (dimensionless).

        Flow is along axis 0 and the gradient along axis 1: ``h[0, 1] = gamma * L_1``.
        """
        h = np.diag(np.asarray(lengths, dtype=np.float64))
        h[0, 1] = float(gamma) * h[1, 1]
        return cls(h)

    # basic properties -------------------------------------------------------------
    @property
    def d(self) -> int:
        """Spatial dimension."""
        return self.matrix.shape[0]

    @property
    def lengths(self) -> NDArray[np.float64]:
        """Diagonal of the lattice matrix, shape (d,) [length]."""
        return np.diag(self.matrix).copy()

    @property
    def volume(self) -> float:
        """Box volume [length^d]."""
        return lattice_volume(self.matrix)

    @property
    def is_orthogonal(self) -> bool:
        """True when the lattice matrix is diagonal."""
        return not np.any(np.triu(self.matrix, 1))

    @property
    def shear_strain(self) -> float:
        """Lees–Edwards strain ``h[0, 1] / h[1, 1]`` (dimensionless)."""
        return float(self.matrix[0, 1] / self.matrix[1, 1])

    @cached_property
    def inverse(self) -> NDArray[np.float64]:
        """Inverse lattice matrix, shape (d, d) [1/length]."""
        inv = np.linalg.inv(self.matrix)
        inv.setflags(write=False)
        return inv

    @cached_property
    def reduced(self) -> "Box":
        """The same lattice with every tilt reduced to ``|h[i, j]| <= h[i, i] / 2``.

        Column operations ``a_j -= n a_i`` (i < j) leave the lattice unchanged; applied
        from the first column onwards they reduce an upper-triangular basis
        (Lees–Edwards strain modulo ``L_0 / L_1``).
        """
        h = np.array(self.matrix)
        for j in range(1, self.d):
            for i in range(j - 1, -1, -1):
                h[:, j] -= np.round(h[i, j] / h[i, i]) * h[:, i]
        return Box(h)

    @cached_property
    def widths(self) -> NDArray[np.float64]:
        """Perpendicular widths between opposite faces, shape (d,) [length].

        A sphere of radius ``r < min(widths) / 2`` never meets two images of a point.
        """
        return 1.0 / np.linalg.norm(self.reduced.inverse, axis=1)

    # coordinates ------------------------------------------------------------------
    def to_fractional(self, x: ArrayLike) -> NDArray[np.float64]:
        """Cartesian [length] -> fractional coordinates, shape (..., d)."""
        return np.asarray(x, dtype=np.float64) @ self.inverse.T

    def to_cartesian(self, s: ArrayLike) -> NDArray[np.float64]:
        """Fractional -> Cartesian coordinates [length], shape (..., d)."""
        return np.asarray(s, dtype=np.float64) @ self.matrix.T

    def wrap(self, x: ArrayLike) -> NDArray[np.float64]:
        """Map positions into the primary cell (fractional coordinates in [0, 1))."""
        s = self.to_fractional(x)
        s -= np.floor(s)
        # floor leaves 1.0 after a tiny negative number, and a coordinate within the
        # round-off of H^-1 (H s) below 1 would come back at 1 (wrap would not be
        # idempotent in a tilted cell): both go to the face at 0, a move by _face_tol
        # in fractional units (2e-15 in an orthogonal box)
        s[s >= 1.0 - self._face_tol] = 0.0
        return self.to_cartesian(s)

    @cached_property
    def _face_tol(self) -> float:
        """Fractional band below 1 that :meth:`wrap` puts at 0: 8 eps times the condition number of ``h``."""
        return 8.0 * float(np.finfo(np.float64).eps) * float(np.linalg.cond(self.matrix, np.inf))

    def contains(self, x: ArrayLike, tol: float = 1e-12) -> NDArray[np.bool_]:
        """Whether fractional coordinates lie in [-tol, 1 + tol), shape (...,)."""
        s = self.to_fractional(x)
        return np.all((s >= -tol) & (s < 1.0 + tol), axis=-1)

    # displacements ----------------------------------------------------------------
    def minimum_image(self, dx: ArrayLike) -> NDArray[np.float64]:
        """Shortest periodic image of displacement vectors, shape (..., d) [length].

        Exact for any vector and any strain. Sequential rounding in the reduced
        basis (last axis first) already gives the shortest image whenever the result
        is shorter than half the smallest width; the remaining vectors get an exact
        closest-lattice-point search (see :func:`_closest_image`).
        """
        dx = np.asarray(dx, dtype=np.float64)
        if self.is_orthogonal:
            L = np.diag(self.matrix)
            return dx - L * np.round(dx / L)
        red = self.reduced
        out = red._round_upper_triangular(dx)
        flat = out.reshape(-1, self.d)
        far = np.einsum("pk,pk->p", flat, flat) >= (0.5 * float(np.min(self.widths))) ** 2
        if np.any(far):
            flat[far] = _closest_image(flat[far], red.matrix)
        return flat.reshape(out.shape)

    def _round_upper_triangular(self, dx: NDArray[np.float64]) -> NDArray[np.float64]:
        """Lees–Edwards style rounding: last axis first, subtracting whole columns."""
        out = np.array(dx, dtype=np.float64, copy=True)
        h = self.matrix
        for k in range(self.d - 1, -1, -1):
            n = np.round(out[..., k] / h[k, k])
            out -= n[..., None] * h[:, k]
        return out

    def displacement(self, xi: ArrayLike, xj: ArrayLike) -> NDArray[np.float64]:
        """Minimum-image vector ``x_j - x_i``, shape (..., d) [length]."""
        return self.minimum_image(np.asarray(xj) - np.asarray(xi))

    # deformations -----------------------------------------------------------------
    def scaled(self, factor: float) -> "Box":
        """Box with every lattice vector multiplied by ``factor``."""
        return Box(self.matrix * float(factor))

    def with_shear(self, gamma: float) -> "Box":
        """Same box with Lees–Edwards strain set to ``gamma``."""
        h = np.array(self.matrix)
        h[0, 1] = float(gamma) * h[1, 1]
        return Box(h)

    def __repr__(self) -> str:
        return f"Box(d={self.d}, matrix={self.matrix.tolist()})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Box) and np.array_equal(self.matrix, other.matrix)

    def __hash__(self) -> int:
        return hash(self.matrix.tobytes())


def _closest_image(y: NDArray[np.float64], h: NDArray[np.float64]) -> NDArray[np.float64]:
    """Shortest vectors ``y - h n`` over integer ``n`` (sphere decoding), shape (M, d).

    For upper-triangular ``h`` the squared norm of ``y - h n`` is a sum of terms
    ``(r_k - h[k, k] n_k)^2`` in which ``r_k`` depends only on ``n_j``, ``j > k``.
    Enumerating ``n_k`` from the last axis down, keeping every partial choice whose
    partial norm stays within ``|y|``, visits every lattice point in the ball of
    radius ``|y|`` around ``y`` (``n = 0`` among them) and nothing else
    (Fincke–Pohst enumeration); the shortest candidate per vector is returned.
    """
    m, d = y.shape
    radius2 = np.einsum("pk,pk->p", y, y) * (1.0 + 1e-12)
    owner = np.arange(m)
    res = y.copy()
    acc = np.zeros(m)
    for k in range(d - 1, -1, -1):
        slack = np.sqrt(np.maximum(radius2[owner] - acc, 0.0))
        lo = np.ceil((res[:, k] - slack) / h[k, k]).astype(np.int64)
        hi = np.floor((res[:, k] + slack) / h[k, k]).astype(np.int64)
        count = np.maximum(hi - lo + 1, 0)
        parent = np.repeat(np.arange(len(owner)), count)
        start = np.cumsum(count) - count
        n_k = lo[parent] + np.arange(len(parent)) - start[parent]
        owner, res = owner[parent], res[parent] - n_k[:, None] * h[:, k]
        acc = acc[parent] + res[:, k] ** 2
    best = np.full(m, np.inf)
    np.minimum.at(best, owner, acc)
    pick = np.flatnonzero(acc == best[owner])
    out = y.copy()
    out[owner[pick]] = res[pick]
    return out
