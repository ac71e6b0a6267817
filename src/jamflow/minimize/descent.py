"""Steepest descent: overdamped relaxation with a fixed Euler step, for any model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .fire import MinimizeResult
from .model import EnergyModel, pressure_of

__all__ = ["DescentResult", "minimize_sd"]


@dataclass(frozen=True)
class DescentResult:
    """:class:`MinimizeResult` of steepest descent plus the energy trace (if recorded)."""

    result: MinimizeResult
    energies: NDArray[np.float64]


def minimize_sd(
    model: EnergyModel,
    position: ArrayLike,
    dt: float = 0.1,
    force_tol: float = 1e-9,
    max_steps: int = 10_000_000,
) -> MinimizeResult:
    """Overdamped relaxation ``dq/dt = -M^-1 P grad U`` of any model with a fixed Euler step.

    A model's compiled loop runs it when the model offers one
    (:meth:`EnergyModel.descent_fast_path`, e.g. soft spheres); otherwise the step is
    taken on the model's flat degrees of freedom, with the gradient projected onto the
    constraints (``P``) and the positions re-affixed after every step. ``dt`` as in
    :func:`jamflow.models.spheres.fast.steepest_descent` (used as given); stops when the largest per-body
    projected gradient norm is at most ``force_tol``.
    """
    q = model.dofs(position)
    fast = model.descent_fast_path(q, dt, force_tol, max_steps)
    if fast is not None:
        return fast
    builds0 = model.neighbor_builds
    q = model.reproject(q)
    ev = model.evaluate(q)
    force = -model.project(ev.gradient, q)
    fmax = model.max_force(force)
    step = 0
    while step < max_steps and fmax > force_tol:
        q = model.reproject(q + dt * model.inverse_mass * force)
        ev = model.evaluate(q)
        force = -model.project(ev.gradient, q)
        fmax = model.max_force(force)
        step += 1
    box = model.current_box(q)
    return MinimizeResult(np.array(model.positions(q)), box, ev.energy, pressure_of(ev, box), fmax,
                          ev.n_contacts, step, fmax <= force_tol, model.neighbor_builds - builds0, step + 1)
