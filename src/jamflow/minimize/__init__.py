"""Minimisers of any energy model: FIRE 2.0, steepest descent, conjugate gradient, the onset bisection.

Algorithms only: a minimiser sees a model through :class:`~.model.EnergyModel` and asks
it for a compiled fast path (:meth:`~.model.EnergyModel.fire_engine`,
:meth:`~.model.EnergyModel.descent_fast_path`); it never inspects a model's type or
internals.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from ..tolerances import MINIMIZE_FORCE_TOL
from .cg import minimize_cg
from .descent import minimize_sd
from .fire import MinimizeResult, minimize_fire
from .model import EnergyModel

__all__ = ["METHODS", "SD_STEP", "minimize"]

#: Minimisers of :func:`minimize` by name.
METHODS = ("fire", "cg", "sd")

#: Steepest-descent step of :func:`minimize` in units of ``<D>^2 / (xi_0 epsilon)``
#: (the time unit squared at unit mass): below ``2 / lambda_max ~ 1 / (2 d)`` of the
#: harmonic Hessian with unit mean diameter.
SD_STEP: float = 0.1


def minimize(
    model: EnergyModel,
    position: ArrayLike,
    method: str = "fire",
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 1_000_000,
) -> MinimizeResult:
    """Minimise a model's energy at fixed box with ``method`` in :data:`METHODS`.

    ``"fire"``: :func:`~.fire.minimize_fire` (default parameters); ``"cg"``:
    :func:`~.cg.minimize_cg`; ``"sd"``: :func:`~.descent.minimize_sd` with the step
    :data:`SD_STEP` ``model.time_unit^2`` (``0.1 <D>^2 / (xi_0 epsilon)``).
    """
    if method == "fire":
        return minimize_fire(model, position, force_tol, max_steps)
    if method == "cg":
        return minimize_cg(model, position, force_tol, max_steps)
    if method == "sd":
        return minimize_sd(model, position, SD_STEP * model.time_unit**2, force_tol, max_steps)
    raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
