"""Edge weights of the primal pricing: which working-set member leaves.

Member ``k`` leaving moves the point along ``d_k = W^-1 e_k``; steepest edge prices
``y_k^2 / |d_k|^2``, the rate of descent per unit length of the step. Exact weights
would cost a solve per member to start and one more solve per pivot to update; two
cheaper estimates are offered (:data:`PRICINGS`):

``sketch``
    A Gaussian sketch (Johnson-Lindenstrauss) of the steepest-edge norms of the step in
    the columns *and* in every row: with ``G = R_z + R_A A`` for Gaussian ``R_z``
    (m, n) and ``R_A`` (m, M), row ``k`` of ``S = W^-T G^T`` is ``G d_k``, and
    ``|G d_k|^2 / m`` estimates ``|d_k|^2 + |A d_k|^2`` to a relative spread of about
    ``sqrt(2 / m)``. ``S`` costs m solves to start (only when the LP pivots at all)
    and follows each pivot exactly by the pivot's row eta, ``S <- E^-T S``, without a
    solve.
``devex``
    Forrest and Goldfarb's Devex reference weights (start at one, updated from the
    pivot's row ``beta``).

``docs/notes/warm-simplex.md`` has the measured pivot counts.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from . import _kernels as k

#: Pricing rules, the first the default.
PRICINGS: tuple[str, ...] = ("sketch", "devex")

#: Rows of the Gaussian sketch: the weights' relative spread is ``sqrt(2 / m)``.
SKETCH_ROWS: int = 16


class Weights:
    """Edge weights of the ``n`` working-set slots.

    Parameters
    ----------
    rule : str
        One of :data:`PRICINGS`.
    """

    def __init__(self, rule: str) -> None:
        if rule not in PRICINGS:
            raise ValueError(f"unknown pricing {rule!r}; choose one of {', '.join(PRICINGS)}")
        self.rule = rule
        self.weight: NDArray[np.float64] | None = None
        self.sketch: NDArray[np.float64] | None = None

    def start(self, n: int, A: sp.csr_matrix, btran_many, rng: np.random.Generator) -> None:
        """Initial weights; ``btran_many(C)`` solves ``W^T Y = C`` for the columns of ``C`` (n, m)."""
        if self.rule == "devex":
            self.weight = np.ones(n)
            return
        m = SKETCH_ROWS
        G = rng.standard_normal((m, n)) + (A.T @ rng.standard_normal((A.shape[0], m))).T
        self.sketch = np.ascontiguousarray(btran_many(G.T))
        self.weight = np.maximum((self.sketch**2).sum(axis=1) / m, 1e-300)

    def update(self, p: int, beta: NDArray[np.float64]) -> None:
        """After slot ``p`` pivoted with row ``beta = W^-T w_q`` (the old ``W``)."""
        if self.rule == "devex":
            k.devex_update(self.weight, beta, p)
        else:
            k.sketch_update(p, beta, self.sketch, self.weight)
