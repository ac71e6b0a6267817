"""Central differences of shape-model energies and gradients, and contact onsets (test helpers)."""

from __future__ import annotations

import numpy as np


def numerical_gradient(model, q: np.ndarray, h: float) -> np.ndarray:
    """``dU/dq`` by central differences of the energy with step ``h``."""
    out = np.zeros_like(q)
    for a in range(q.size):
        e = np.zeros_like(q)
        e[a] = h
        out[a] = (model.evaluate(q + e).energy - model.evaluate(q - e).energy) / (2.0 * h)
    return out


def numerical_hessian(model, q: np.ndarray, h: float) -> np.ndarray:
    """``d^2U/dq dq`` by central differences of the analytic gradient with step ``h``."""
    out = np.zeros((q.size, q.size))
    for a in range(q.size):
        e = np.zeros_like(q)
        e[a] = h
        out[:, a] = (model.evaluate(q + e).gradient - model.evaluate(q - e).gradient) / (2.0 * h)
    return out


def onset_distances(model, outline, index, ti: float, tj: float, direction: np.ndarray, origin,
                    lo: float, hi: float, steps: int = 50) -> tuple[float, float] | None:
    """Centre distances along ``direction`` at which the model's energy switches on and at
    which the outlines (``outline(shape, theta, centre)``, shapely) first intersect.

    Body 0 sits at ``origin`` with angle ``ti``, body 1 at ``origin + r direction`` with
    angle ``tj``; each distance is bisected ``steps`` times on ``[lo, hi]``. None when
    either side does not touch at ``lo``.
    """
    origin = np.asarray(origin, dtype=float)
    first = outline(index[0], ti, origin)

    def touching(model_side: bool, r: float) -> bool:
        centre = origin + r * direction
        if model_side:
            return model.evaluate(model.dofs([[*origin, ti], [*centre, tj]])).energy > 0.0
        return first.intersects(outline(index[1], tj, centre))

    found = []
    for side in (True, False):
        a, b = lo, hi
        if not touching(side, a):
            return None
        for _ in range(steps):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if touching(side, mid) else (a, mid)
        found.append(0.5 * (a + b))
    return found[0], found[1]
