"""Polak-Ribiere conjugate gradient (scipy) for any model, finished by FIRE.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize as _scipy_minimize

from ..tolerances import MINIMIZE_FORCE_TOL
from .fire import MinimizeResult, minimize_fire
from .model import EnergyModel, pressure_of

__all__ = ["minimize_cg"]


def minimize_cg(
    model: EnergyModel,
    position: ArrayLike,
    force_tol: float = MINIMIZE_FORCE_TOL,
    max_steps: int = 100_000,
) -> MinimizeResult:
    """Polak–Ribière conjugate gradient (``scipy.optimize.minimize(method="CG")``).

    scipy stops on the largest gradient *component*; the run is continued with FIRE
    if the per-body norm criterion (largest force norm <= ``force_tol``) is not yet
    met. CG's line searches make it an independent check of FIRE's minimum. With
    constraints CG minimises ``U(R(q))``, ``R`` the re-affixing onto the constraint
    manifold, whose gradient on the manifold is the projected gradient ``P grad U``.
    """
    x0 = model.reproject(model.dofs(position))
    builds0 = model.neighbor_builds
    count = [0]

    def fun(flat: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        count[0] += 1
        q = model.reproject(flat)
        ev = model.evaluate(q)
        return ev.energy, model.project(ev.gradient, q)

    out = _scipy_minimize(fun, x0, jac=True, method="CG",
                          options={"gtol": force_tol / np.sqrt(model.box.d), "maxiter": max_steps})
    qf = model.reproject(out.x)
    ev = model.evaluate(qf)
    fmax = model.max_force(model.project(ev.gradient, qf))
    if fmax > force_tol:
        polished = minimize_fire(model, model.positions(qf), force_tol, max_steps)
        return MinimizeResult(polished.position, polished.box, polished.energy, polished.pressure,
                              polished.max_force, polished.n_contacts, count[0] + polished.steps,
                              polished.converged, model.neighbor_builds - builds0,
                              count[0] + 1 + polished.evaluations)
    box = model.current_box(qf)
    return MinimizeResult(model.positions(qf), box, ev.energy, pressure_of(ev, box), fmax,
                          ev.n_contacts, count[0], True, model.neighbor_builds - builds0, count[0] + 1)
