"""Newton polish of the enthalpy ``H = U + P0 V`` near its minimum (any model with a Hessian).

FIRE relaxes a mode of stiffness ``lambda`` in ``~ 1 / (dt sqrt(lambda))`` steps; the
quartic modes of hypostatic packings have ``lambda`` of order ``P0`` and below, so
the last decades of force balance cost FIRE most of its steps. Newton's method on
the degrees of freedom ``q`` and the isotropic box scale ``s`` (centres ``s x``,
``V = s^d V_ref``, shapes unchanged) reaches round-off in a few solves from a state
FIRE has brought close enough. Each iteration solves the bordered system

``[[K, b], [b^T, c]] [dq, ds] = -[g, dH/ds]``

with ``K`` the model's Hessian (:meth:`EnergyModel.hessian`), ``g`` the gradient,
``dH/ds = d V (P0 - P)`` and the border ``b = d g / ds``, ``c = d^2 H / ds^2``
from central differences of the model in the boxes scaled by ``1 +- h``
(:data:`SCALE_STEP`). Zero modes (rattlers, global translations) carry no force;
a shift of :data:`NEWTON_SHIFT` times the largest diagonal entry of ``K`` keeps the
system regular without moving them. A run is accepted only when every iteration
keeps the largest force below :data:`NEWTON_GROWTH` times the start's, the last one
meets both tolerances and the bordered Hessian there has no negative eigenvalue (a
minimum, not a saddle); otherwise the caller keeps its state (a failed polish changes
nothing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import NDArray

from .fire import MinimizeResult
from .model import EnergyModel, pressure_of

__all__ = ["NEGATIVE_CURVATURE", "NEWTON_GROWTH", "NEWTON_ITERATIONS", "NEWTON_SHIFT", "SCALE_STEP", "NewtonPolish",
           "polish_enthalpy", "positive_semidefinite"]

#: Relative step of the box scale in the central differences of the border [1]: far
#: below the overlaps of a packing at P0 >= 1e-12 relative to the centre distances, so no
#: contact opens or closes between the two boxes, and far above round-off of the
#: gradients it differences (their error, ~1e-16 |g|_max / h, stays below 1e-7 |b|).
SCALE_STEP: float = 1e-9

#: Levenberg shift of the Newton system relative to the largest diagonal entry of the
#: Hessian [1]: the zero modes of rattlers and global translations, which carry no force,
#: stay regular; a mode with eigenvalue ``lambda`` converges at the rate
#: ``shift / (lambda + shift)``, at most 1e-4 per iteration for ``lambda >= 1e-10 K_max``.
NEWTON_SHIFT: float = 1e-14

#: Largest number of Newton iterations of one polish: from a state in the quadratic
#: basin two to four reach round-off; more means the state was not in it.
NEWTON_ITERATIONS: int = 8

#: Growth of the largest force over the start's beyond which a polish gives up [1]: the
#: first full step along the soft modes may raise it by ~1e3 before the second lands
#: (docs/notes/shapes.md, "Newton polish of the enthalpy stage"); more means the state
#: was outside the quadratic basin (contacts opening).
NEWTON_GROWTH: float = 1e4

#: Eigenvalues of the bordered enthalpy Hessian below ``-NEGATIVE_CURVATURE`` times its
#: largest diagonal entry mark a saddle [1]: far above the round-off of a dense
#: eigen-decomposition (~1e-16 of the norm times the size's square root) and below the
#: quartic modes' eigenvalues at any P0 the protocol reaches.
NEGATIVE_CURVATURE: float = 1e-13


@dataclass(frozen=True)
class NewtonPolish:
    """Outcome of :func:`polish_enthalpy`: the final state (or None) and the iterations spent."""

    result: MinimizeResult | None
    iterations: int


def _state(model: EnergyModel, config: NDArray[np.float64], pressure0: float) -> tuple:
    """Gradient of ``H`` in ``q``, ``dH/ds``, largest projected force, pressure and energy at ``s = 1``."""
    q = model.dofs(config)
    ev = model.evaluate(q)
    g = model.project(ev.gradient, q)
    p = pressure_of(ev, model.box)
    d = model.box.d
    return q, g, d * model.box.volume * (pressure0 - p), model.max_force(g), p, ev


def _scaled_gradient(model: EnergyModel, config: NDArray[np.float64], pressure0: float,
                     s: float) -> tuple[NDArray[np.float64], float]:
    """``dH/dq`` in reference coordinates and ``dH/ds`` with the box scaled by ``s``."""
    scaled, c = model.rescaled(s, config)
    q = scaled.dofs(c)
    ev = scaled.evaluate(q)
    g = np.array(scaled.project(ev.gradient, q))
    # centres x' = s x: dH/dx = s dU/dx' (orientations and other body coordinates are not scaled)
    n_centre = scaled.positions(q).shape[0] * model.box.d
    g[:n_centre] *= s
    d = model.box.d
    # H = U + P0 V_ref s^d: dH/ds = -tr W / s + d P0 V_ref s^(d - 1)
    dhds = -float(np.trace(ev.virial)) / s + d * pressure0 * model.box.volume * s ** (d - 1)
    return g, dhds


def _bordered_hessian(model: EnergyModel, x: NDArray[np.float64], q: NDArray[np.float64],
                      pressure0: float) -> sp.csr_matrix:
    """``d^2 H / d(q, s)^2`` at ``s = 1``: the model's Hessian bordered by central differences in ``s``."""
    k = model.hessian(q)
    h = SCALE_STEP
    gp, hp = _scaled_gradient(model, x, pressure0, 1.0 + h)
    gm, hm = _scaled_gradient(model, x, pressure0, 1.0 - h)
    border = (gp - gm) / (2.0 * h)
    corner = (hp - hm) / (2.0 * h)
    return sp.bmat([[k, border[:, None]], [border[None, :], np.array([[corner]])]], format="csc")


def _is_minimum(model: EnergyModel, x: NDArray[np.float64], q: NDArray[np.float64], pressure0: float) -> bool:
    """Whether no eigenvalue of the bordered Hessian lies below ``-NEGATIVE_CURVATURE`` of its
    largest diagonal entry: the Hessian shifted up by that margin is :func:`positive_semidefinite`."""
    a = _bordered_hessian(model, x, q, pressure0)
    a = 0.5 * (a + a.T)
    margin = NEGATIVE_CURVATURE * float(np.abs(a.diagonal()).max())
    return positive_semidefinite((a + margin * sp.identity(a.shape[0])).tocsc())


def positive_semidefinite(a: sp.csc_matrix) -> bool:
    """Whether the symmetric sparse matrix ``a`` has no negative eigenvalue.

    Sylvester's law of inertia on ``P a P^T = L U`` with diagonal pivots only (SuperLU in
    symmetric mode): the number of negative pivots is the number of negative eigenvalues.
    When SuperLU pivots off the diagonal or meets an exactly zero pivot, the dense
    eigenvalues decide.
    """
    try:
        lu = sla.splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError:
        lu = None
    if lu is not None and np.array_equal(lu.perm_r, lu.perm_c):
        return not bool(np.any(lu.U.diagonal() < 0.0))
    return bool(np.linalg.eigvalsh(a.toarray())[0] >= 0.0)


def polish_enthalpy(model: EnergyModel, config: NDArray[np.float64], pressure0: float, force_tol: float,
                    pressure_rtol: float, max_iterations: int = NEWTON_ITERATIONS) -> NewtonPolish:
    """Newton iterations on ``H = U + P0 V`` (module doc) from ``config`` in ``model``'s box.

    Parameters
    ----------
    model : EnergyModel
        Needs ``hessian`` and ``rescaled``; the first ``N d`` entries of ``q`` are the
        centres (the order of :mod:`.model`). A model with constraints
        (``model.constrained``) is not polished.
    config : ndarray
        The model's configuration (``model.positions`` form).
    pressure0, force_tol, pressure_rtol : float
        Target pressure, and the tolerances of the result (largest projected force
        :meth:`EnergyModel.max_force`, ``|P - P0| <= pressure_rtol P0``).

    Returns
    -------
    NewtonPolish
        ``result`` holds the polished state (box scaled, ``steps = 0``) when the tolerances
        were met within ``max_iterations`` without the largest force growing past
        :data:`NEWTON_GROWTH` times the start's, at a minimum (no eigenvalue of the bordered
        Hessian below ``-NEGATIVE_CURVATURE`` of its largest diagonal entry); else None.
    """
    if getattr(model, "constrained", False):
        return NewtonPolish(None, 0)
    x = np.array(config, dtype=np.float64)
    q, g, dhds, fmax, p, ev = _state(model, x, pressure0)
    fmax0 = fmax
    for it in range(1, max_iterations + 1):
        system = _bordered_hessian(model, x, q, pressure0)
        shift = NEWTON_SHIFT * float(np.abs(system.diagonal()[:-1]).max())
        system = system + sp.diags(np.r_[np.full(system.shape[0] - 1, shift), 0.0], format="csc")
        step = sla.spsolve(system, -np.concatenate([g, [dhds]]))
        if not np.all(np.isfinite(step)):
            return NewtonPolish(None, it)
        trial_model, trial_x = model.rescaled(1.0 + float(step[-1]), model.positions(q + step[:-1]))
        tq, tg, tdhds, tfmax, tp, tev = _state(trial_model, trial_x, pressure0)
        if not tfmax < NEWTON_GROWTH * fmax0:
            return NewtonPolish(None, it)
        model, x, q, g, dhds, fmax, p, ev = trial_model, trial_x, tq, tg, tdhds, tfmax, tp, tev
        if fmax <= force_tol and abs(p - pressure0) <= pressure_rtol * pressure0:
            if not _is_minimum(model, x, q, pressure0):
                return NewtonPolish(None, it)
            return NewtonPolish(MinimizeResult(
                position=np.array(x), box=model.box, energy=ev.energy, pressure=p, max_force=fmax,
                n_contacts=ev.n_contacts, steps=0, converged=True, rebuilds=0, evaluations=3 * it + 1,
            ), it)
    return NewtonPolish(None, max_iterations)
