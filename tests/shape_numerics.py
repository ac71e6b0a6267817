"""Central differences of shape-model energies and gradients (test helpers)."""

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
