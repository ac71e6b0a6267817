"""Numba kernels of the contact graph: pair incidence and coordination peeling.

Kept apart from :mod:`jamflow.network.counting` so that importing the package does not
load numba: only callers that prune thousands of times per run (the event-driven
network, which loads numba anyway) ask for the compiled peeling, and the event-driven
bordered preconditioners use the incidence.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit

__all__ = ["incidence", "peel"]


@njit(cache=True)
def incidence(pairs, n):  # pragma: no cover - numba
    """Pairs at every body, CSR: the pairs of body k are ``incident[ptr[k]:ptr[k + 1]]``.

    Parameters
    ----------
    pairs : ndarray of int64, shape (n_c, 2)
    n : int

    Returns
    -------
    ptr : ndarray of int64, shape (n + 1,)
    incident : ndarray of int64, shape (2 n_c,)
    """
    # indices read from the arrays index as unsigned: numba tests signed ones for wraparound
    ptr = np.zeros(n + 1, dtype=np.int64)
    for c in range(pairs.shape[0]):
        ptr[np.uint64(pairs[c, 0] + 1)] += 1
        ptr[np.uint64(pairs[c, 1] + 1)] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    fill = ptr[:-1].copy()
    incident = np.empty(2 * pairs.shape[0], dtype=np.int64)
    for c in range(pairs.shape[0]):
        for e in range(2):
            k = np.uint64(pairs[c, e])
            incident[np.uint64(fill[k])] = c
            fill[k] += 1
    return ptr, incident


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
    ptr, incident = incidence(pairs, n)
    z = z_extra + (ptr[1:] - ptr[:-1])
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
