"""Numba kernel of the coordination pruning (:func:`jamflow.network.prune_rattlers`).

Kept apart from :mod:`jamflow.network.counting` so that importing the package does not
load numba: only callers that prune thousands of times per run (the event-driven
network, which loads numba anyway) ask for it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["peel"]


@njit(cache=True)
def peel(pairs, n, k_min, z_extra):  # pragma: no cover - numba
    """Bodies outside the ``k_min``-core of the contact graph, by peeling with a stack.

    Parameters
    ----------
    pairs : ndarray of int64, shape (n_c, 2)
    n : int
    k_min : int
        A body with fewer than ``k_min`` remaining contacts is removed.
    z_extra : ndarray of int64, shape (n,)
        Contacts that never go away (walls).

    Returns
    -------
    ndarray of bool, shape (n,)
        The core is unique, so the result equals that of removing all under-coordinated
        bodies round by round.
    """
    nc = pairs.shape[0]
    z = z_extra.copy()
    for c in range(nc):
        z[pairs[c, 0]] += 1
        z[pairs[c, 1]] += 1
    ptr = np.zeros(n + 1, dtype=np.int64)
    for c in range(nc):
        ptr[pairs[c, 0] + 1] += 1
        ptr[pairs[c, 1] + 1] += 1
    for b in range(n):
        ptr[b + 1] += ptr[b]
    fill = ptr[:-1].copy()
    incident = np.empty(2 * nc, dtype=np.int64)
    for c in range(nc):
        for e in range(2):
            b = pairs[c, e]
            incident[fill[b]] = c
            fill[b] += 1
    rattler = np.zeros(n, dtype=np.bool_)
    alive = np.ones(nc, dtype=np.bool_)
    stack = np.empty(n, dtype=np.int64)
    top = 0
    for b in range(n):
        if z[b] < k_min:
            rattler[b] = True
            stack[top] = b
            top += 1
    while top > 0:
        top -= 1
        b = stack[top]
        for p in range(ptr[b], ptr[b + 1]):
            c = incident[p]
            if not alive[c]:
                continue
            alive[c] = False
            o = pairs[c, 1] if pairs[c, 0] == b else pairs[c, 0]
            z[o] -= 1
            if not rattler[o] and z[o] < k_min:
                rattler[o] = True
                stack[top] = o
                top += 1
    return rattler
