"""Numba kernels of the Verlet list: the rebuild criterion and a list built inside a compiled loop."""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ._cell_kernels import cell_pairs_into, pair_buffers


@njit(cache=True)
def _needs_rebuild(y, y_build, s, s_build, reach, skin, slack):
    """Verlet criterion: the two largest non-affine displacements plus box deformation.

    An unlisted pair was at least ``sigma + skin`` apart at the build and closes by at
    most ``|u_i| + |u_j|``, at most the sum of the two largest displacements ``u1 + u2``
    (``<= 2 u1``, the textbook bound). ``y_build`` are the build-time positions mapped
    affinely to the current reference box and ``slack`` the deformation term
    accumulated before this call.
    """
    m1 = 0.0
    m2 = 0.0
    for i in range(y.shape[0]):
        d2 = 0.0
        for a in range(y.shape[1]):
            dd = y[i, a] - y_build[i, a]
            d2 += dd * dd
        if d2 > m1:
            m1, m2 = d2, m1
        elif d2 > m2:
            m2 = d2
    return s * (np.sqrt(m1) + np.sqrt(m2)) + abs(s / s_build - 1.0) * reach + slack >= skin


@njit(cache=True)
def _list_buffers(n, d):
    """Work arrays of :func:`_inline_list` for N particles: the cell search's, scaled positions, offsets and sigmas."""
    cells = pair_buffers(n, d)
    capacity = cells[5].shape[1]
    return cells, np.empty((n, d)), np.empty((capacity, d)), np.empty(capacity)


@njit(cache=True)
def _inline_list(y, s, lengths, diameter, reach, skin, buffers):
    """A Verlet list built inside the loop (orthogonal reference box ``lengths``, scale ``s``).

    The same call as :meth:`jamflow.neighbors.verlet.NeighborList.build` makes, so the
    same pairs in the same (lexicographic) order, in the work arrays ``buffers`` of
    :func:`_list_buffers`. Returns ``(pi, pj, image, offset, sigma, buffers)`` with
    ``offset = h_ref n``; the lists are views the next build overwrites.
    """
    cells, scaled, offset, sigma = buffers
    n, d = y.shape
    for i in range(n):
        for a in range(d):
            scaled[i, a] = s * y[i, a]
    pi, pj, image, cells = cell_pairs_into(scaled, s * lengths, reach, diameter, skin, cells)
    m = pi.shape[0]
    if offset.shape[0] < m:
        offset, sigma = np.empty((cells[5].shape[1], d)), np.empty(cells[5].shape[1])
    for p in range(m):
        for a in range(d):
            offset[p, a] = image[p, a] * lengths[a]
        sigma[p] = 0.5 * (diameter[pi[p]] + diameter[pj[p]])
    return pi, pj, image, offset[:m], sigma[:m], (cells, scaled, offset, sigma)
