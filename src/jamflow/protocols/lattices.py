"""Crystal packings of unit-diameter spheres in periodic orthogonal boxes.

Every constructor tiles a rectangular (orthogonal) conventional cell ``cells`` times
along each axis, so nearest neighbours touch exactly (distance 1 up to round-off)
and the contact list is exact. The jamming category of a lattice packing depends on
the periodic cell (Donev et al., J. Comput. Phys. 197, 139 (2004)), so the cell
counts are part of each packing's ``parameters``.

=========== === ====================== ========== ===============
lattice      d   conventional cell      particles  contacts each
=========== === ====================== ========== ===============
triangular   2   1 x sqrt(3)            2          6
square       2   1 x 1                  1          4
honeycomb    2   sqrt(3) x 3            4          3
kagome       2   2 x 2 sqrt(3)          6          4
fcc          3   sqrt(2)^3              4          12
sc           3   1^3                    1          6
bcc          3   (2 / sqrt(3))^3        2          8
=========== === ====================== ========== ===============
"""

from __future__ import annotations

from collections.abc import Sequence
from math import sqrt

import numpy as np
from numpy.typing import NDArray

from ..box import Box
from ..network.spheres import contacts_from_gaps
from ..state.packing import Packing

__all__ = ["LATTICES", "lattice_packing"]

# cell side lengths and basis (Cartesian, inside the cell) for unit nearest-neighbour distance
_S3 = sqrt(3.0)
_CELLS: dict[str, tuple[tuple[float, ...], list[tuple[float, ...]]]] = {
    "triangular": ((1.0, _S3), [(0.0, 0.0), (0.5, 0.5 * _S3)]),
    "square": ((1.0, 1.0), [(0.0, 0.0)]),
    "honeycomb": ((_S3, 3.0), [(0.0, 0.0), (0.0, 1.0), (0.5 * _S3, 1.5), (0.5 * _S3, 2.5)]),
    "kagome": ((2.0, 2.0 * _S3), [(0.0, 0.0), (1.0, 0.0), (0.5, 0.5 * _S3),
                                  (1.0, _S3), (0.0, _S3), (1.5, 1.5 * _S3)]),
    "fcc": ((sqrt(2.0),) * 3, [tuple(sqrt(2.0) * np.array(v)) for v in
                                ((0, 0, 0), (0, 0.5, 0.5), (0.5, 0, 0.5), (0.5, 0.5, 0))]),
    "sc": ((1.0, 1.0, 1.0), [(0.0, 0.0, 0.0)]),
    "bcc": ((2.0 / _S3,) * 3, [(0.0, 0.0, 0.0), (1.0 / _S3,) * 3]),
}

#: Names accepted by :func:`lattice_packing`.
LATTICES: tuple[str, ...] = tuple(_CELLS)

#: Relative gap below which lattice neighbours are contacts (they touch up to round-off).
_LATTICE_GAP_TOL = 1e-9


def lattice_packing(name: str, cells: int | Sequence[int]) -> Packing:
    """Lattice packing of unit-diameter spheres with exact contacts.

    Parameters
    ----------
    name : str
        One of :data:`LATTICES`.
    cells : int or sequence of int
        Conventional cells along each axis; every box width must exceed 2 (two
        diameters) so that minimum images are unique.

    Returns
    -------
    Packing
        Wrapped positions, ``contacts`` from the exact geometry, protocol
        ``"lattice:<name>"`` and the cell counts in ``parameters``.
    """
    if name not in _CELLS:
        raise ValueError(f"unknown lattice {name!r}; choose one of {', '.join(LATTICES)}")
    side, basis = _CELLS[name]
    d = len(side)
    counts = np.broadcast_to(np.asarray(cells, dtype=np.int64), (d,))
    if np.any(counts < 1):
        raise ValueError(f"cells must be positive, got {cells}")
    lengths = np.asarray(side) * counts
    if np.any(lengths <= 2.0):
        raise ValueError(f"box widths {lengths.tolist()} must exceed 2 diameters; use more cells")
    grid = np.stack(np.meshgrid(*[np.arange(c) for c in counts], indexing="ij"), axis=-1).reshape(-1, d)
    origins = grid * np.asarray(side)
    position: NDArray[np.float64] = (origins[:, None, :] + np.asarray(basis)[None, :, :]).reshape(-1, d)
    box = Box.orthogonal(lengths)
    packing = Packing(
        position=box.wrap(position),
        diameter=np.ones(len(position)),
        box=box,
        protocol=f"lattice:{name}",
        parameters={"lattice": name, "cells": counts.tolist()},
    )
    return packing.evolve(contacts=contacts_from_gaps(packing, _LATTICE_GAP_TOL))
