"""Contact sets: which bodies touch, along which normal, at which contact points.

One row per touching body pair ``(i, j)``. The normal points from ``i`` to ``j``
(for spheres the unit centre-to-centre vector), ``separation`` is the
centre-to-centre vector ``r_j - r_i`` of the periodic image in contact, and the
optional arms locate the contact point relative to each centre (needed only for
rotational degrees of freedom: the torque arm). The gap of a contact is the
distance between the two surfaces along the normal, positive when open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..box import Box

__all__ = ["ContactSet", "sphere_contacts"]


@dataclass(frozen=True)
class ContactSet:
    """Touching body pairs with their normals, separations and (optional) contact arms.

    Attributes
    ----------
    i, j : ndarray of int64, shape (n_c,)
        Body indices. ``i < j`` is the convention of every producer in the package
        but not required (a pair's row is the same with ``i`` and ``j`` swapped and
        the normal reversed).
    normal : ndarray, shape (n_c, d)
        Unit normal pointing from ``i`` to ``j``.
    separation : ndarray, shape (n_c, d)
        Centre-to-centre vector ``r_j - r_i`` of the touching image [length].
    arm_i, arm_j : ndarray, shape (n_c, d), or None
        Contact point minus the centre of ``i`` (resp. ``j``) [length]; None for
        central contacts (spheres: the normal is the separation direction, and a
        rotation moves no contact point).
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    normal: NDArray[np.float64]
    separation: NDArray[np.float64]
    arm_i: NDArray[np.float64] | None = None
    arm_j: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        i = np.asarray(self.i, dtype=np.int64).reshape(-1)
        j = np.asarray(self.j, dtype=np.int64).reshape(-1)
        n = np.asarray(self.normal, dtype=np.float64)
        s = np.asarray(self.separation, dtype=np.float64)
        if len(j) != len(i) or n.ndim != 2 or n.shape[0] != len(i) or s.shape != n.shape:
            raise ValueError(f"contact set: i {i.shape}, j {j.shape}, normal {n.shape} and separation {s.shape} "
                             "must describe the same contacts, normal and separation of shape (n_c, d)")
        if (self.arm_i is None) != (self.arm_j is None):
            raise ValueError("contact set: give both arms (arm_i and arm_j) or neither")
        object.__setattr__(self, "i", i)
        object.__setattr__(self, "j", j)
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "separation", s)
        for name in ("arm_i", "arm_j"):
            arm = getattr(self, name)
            if arm is not None:
                arm = np.asarray(arm, dtype=np.float64)
                if arm.shape != n.shape:
                    raise ValueError(f"contact set: {name} has shape {arm.shape}, expected {n.shape}")
                object.__setattr__(self, name, arm)

    @property
    def n_contacts(self) -> int:
        """Number of contacts ``n_c``."""
        return len(self.i)

    @property
    def d(self) -> int:
        """Spatial dimension."""
        return self.normal.shape[1]

    @property
    def central(self) -> bool:
        """True when the contacts have no arms (normals along the separations: spheres)."""
        return self.arm_i is None

    @property
    def pairs(self) -> NDArray[np.int64]:
        """Body pairs as one array, shape (n_c, 2)."""
        return np.stack([self.i, self.j], axis=1)

    def select(self, keep: ArrayLike) -> ContactSet:
        """The contacts selected by a boolean mask or index array."""
        keep = np.asarray(keep)
        arm = (None, None) if self.central else (self.arm_i[keep], self.arm_j[keep])
        return ContactSet(self.i[keep], self.j[keep], self.normal[keep], self.separation[keep], *arm)


def sphere_contacts(position: NDArray[np.float64], box: Box, pairs: ArrayLike,
                    radius: NDArray[np.float64] | None = None,
                    separation: NDArray[np.float64] | None = None) -> ContactSet:
    """Contacts of spheres: normals along the minimum-image centre-to-centre vectors.

    Parameters
    ----------
    position : ndarray, shape (N, d)
        Centres [length].
    box : Box
        Periodic box (minimum image).
    pairs : array_like of int, shape (n_c, 2)
        Touching pairs.
    radius : ndarray, shape (N,), optional
        Radii [length]; when given, the arms ``+a_i n`` and ``-a_j n`` are stored (a
        sphere's contact point; rotation columns of spheres are then zero).
    separation : ndarray, shape (n_c, d), optional
        Separations of fixed periodic images (event-driven dynamics) instead of the
        minimum image [length].

    Raises
    ------
    ValueError
        When a contact joins two coincident centres (no normal).
    """
    c = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    dx = box.minimum_image(position[c[:, 1]] - position[c[:, 0]]) if separation is None else separation
    r = np.linalg.norm(dx, axis=1)
    if np.any(r <= 0.0):
        raise ValueError("a contact joins two coincident centres")
    unit = dx / r[:, None]
    arms = (None, None) if radius is None else (radius[c[:, 0], None] * unit, -radius[c[:, 1], None] * unit)
    return ContactSet(c[:, 0], c[:, 1], unit, dx, *arms)
