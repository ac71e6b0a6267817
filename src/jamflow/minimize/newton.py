"""Trust-region Newton polish of the enthalpy ``H = U + P0 V`` (any model with a Hessian).

FIRE relaxes a mode of stiffness ``lambda`` in ``~ 1 / (dt sqrt(lambda))`` steps; the
quartic modes of hypostatic packings have ``lambda`` of order ``P0`` and below, so
the last decades of force balance cost FIRE most of its steps. Newton's method on
the degrees of freedom ``q`` and the isotropic box scale ``s`` (centres ``s x``,
``V = s^d V_ref``, shapes unchanged) reaches round-off in a few solves near the
minimum. Each iteration solves the bordered, shifted system

``([[K, b], [b^T, c]] + mu M) [dq, ds] = -[g, dH/ds]``

with ``K`` the model's Hessian (:meth:`EnergyModel.hessian`), ``g`` the gradient,
``dH/ds = d V (P0 - P)`` and the border ``b = d g / ds``, ``c = d^2 H / ds^2``
from central differences of the model in the boxes scaled by ``1 +- h``
(:data:`SCALE_STEP`); ``M`` is FIRE's mass metric (and a squared neighbour distance
for ``s``), ``mu`` a Levenberg–Marquardt shift (never below :data:`NEWTON_SHIFT`,
which keeps the zero modes of rattlers and global translations regular).

Far from the minimum the full Newton step leaves the region the Hessian describes:
along the soft modes it closes pairs at small gaps, which the Hessian does not see,
and the enthalpy rises. So the step is globalised (Nielsen's update of ``mu`` on the
ratio of the actual to the predicted decrease of ``H``): a step is tried at full
length, then at quarter lengths (:data:`TRUST_BACKTRACK`, which stops short of a
closing pair) and kept when it decreases ``H`` by at least :data:`TRUST_ACCEPT` of the
quadratic prediction; else ``mu`` grows. A step kept only at a shortened length stopped short
of a contact the Hessian does not see (a body sliding along a soft valley into a neighbour):
the minimum along its line lies between the kept length and the next longer, refused one,
where the slope ``dH/dt`` changes sign, and is found there by Brent's method on the slope
(:data:`LINE_XTOL`, :data:`LINE_ITERATIONS`), which needs no enthalpy differences; the point
found is kept when it passes the same test as any trial step. Only a shifted matrix with positive
pivots (a descent direction) is used, and no body moves by more than
:data:`TRUST_MOVE` of a neighbour distance in one step. Below the round-off of the
enthalpy (:data:`ENTHALPY_ROUNDOFF`) the decrease is measured by the trapezoid rule on the
slopes ``dH/dt`` at both ends of the step instead of the difference of the enthalpies. A step
after which the Hessian, shifted as for it, is no longer positive definite is undone (it
went past a contact that holds the packing); after :data:`TRUST_INDEFINITE` of them the
polish gives up.
A run is accepted only when both tolerances hold and the bordered Hessian there has
no negative eigenvalue (a minimum, not a saddle); otherwise the caller keeps its own
state (a failed polish changes nothing; the last state it reached, of lower ``H``,
is reported).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import NDArray
from scipy.optimize import brentq

from ..box import Box
from .fire import MinimizeResult
from .model import EnergyModel, ModelEvaluation, pressure_of

__all__ = ["ENTHALPY_ROUNDOFF", "LINE_ITERATIONS", "LINE_XTOL", "NEGATIVE_CURVATURE", "NEWTON_ITERATIONS",
           "NEWTON_SHIFT", "SCALE_STEP", "TRUST_ACCEPT",
           "TRUST_BACKTRACK", "TRUST_INDEFINITE", "TRUST_MOVE", "TRUST_SHIFT", "NewtonPolish", "TangentNewton",
           "polish_constrained", "polish_enthalpy", "positive_semidefinite"]

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

#: Largest number of trial steps (accepted or rejected) of one polish [1]: from the states
#: it lands from it takes 5-90 (N = 100 and 480 ellipses and circulo-lines, P0 = 1e-6;
#: docs/notes/shapes.md, "Trust-region Newton for the enthalpy stage").
NEWTON_ITERATIONS: int = 100

#: Starting Levenberg shift of a polish relative to the largest diagonal entry of the
#: Hessian, in the mass metric [1]: about the stiffness of the soft modes at P0 ~ 1e-6 ...
#: 1e-8, so the first step is short along them; Nielsen's update takes it to Newton's step.
TRUST_SHIFT: float = 1e-8

#: Smallest ratio of the actual to the predicted decrease of ``H`` for which a step is
#: kept [1]: any clear decrease (a step that stops just short of a closing pair decreases
#: ``H`` by less than the quadratic model says, and is still progress).
TRUST_ACCEPT: float = 1e-4

#: Largest Levenberg shift relative to the largest diagonal entry of the Hessian [1]: the
#: step is then below ``eps |g| / K_max``, under the round-off of the configuration, so a
#: polish whose shift grew this far has no step left and gives up (the shift doubles its
#: growth after each rejection and would otherwise overflow within the trial budget).
TRUST_SHIFT_MAX: float = 1.0 / float(np.finfo(np.float64).eps)

#: Largest displacement of a body's surface in one trial step, relative to the mean
#: distance between neighbours [1]: a step that would move a body further is treated as
#: rejected, so no step can carry a body through another's core.
TRUST_MOVE: float = 0.05

#: Steps undone because the Hessian at their end, shifted as for the step, is not positive definite,
#: after which :func:`polish_enthalpy` gives up [1]: such a step overshot a contact whose overlap is far
#: below the others' (the packing without it is unstable); many of them mark a flat valley without a
#: minimum within reach, which FIRE leaves by a rearrangement. Measured: 8 within 13-36 trial steps of
#: each try that failed (circulo-triangles N = 100, P0 = 1e-6), at most 4 in a try that lands (2 there,
#: 4 for the N = 24 ellipses of the tests from force 1e-6); docs/notes/shapes.md, "Why the Newton tries
#: of circulo shapes fail".
TRUST_INDEFINITE: int = 8

#: Round-off of an enthalpy difference in units of ``eps tr W`` (virial trace ``tr W = d P V``) [1]:
#: a predicted decrease below it is measured from the slopes at both ends (:func:`polish_enthalpy`) or
#: judged by the largest force (:func:`polish_constrained`) instead. Measured: predicted and actual
#: differences agree to 1e-19 at ``tr W = 8.6e-4`` (N = 480 circulo-lines, P0 = 1e-6).
ENTHALPY_ROUNDOFF: float = 4.0

#: Smallest ratio of the actual to the predicted decrease of ``U`` after which :func:`polish_constrained`
#: takes its next step with the same factors and tangent basis (a chord step) [1]: the quadratic model
#: then holds over the step, so it holds over the next, shorter one to first order in the step.
CHORD_RATIO: float = 0.5

#: Fractions of a rejected step tried along its direction before the shift grows [1]:
#: a step that closes a contact the Hessian does not see overshoots, a part of it does not.
TRUST_BACKTRACK: tuple[float, ...] = tuple(0.25**k for k in range(12))

#: Width, relative to the refused length, to which the sign change of the slope ``dH/dt`` along a step cut
#: short is located [1]: a contact that closes inside the bracket then carries its balancing overlap to this
#: share of the step, and the next Newton step, whose Hessian holds the contact, corrects the rest. Measured
#: on the enthalpy stage of N = 480 circulo-lines (seeds 5 and 2, P0 = 1e-6): 1e-8, 1e-6 and 1e-4 land at
#: the same tries (polish CPU 6.4-9.4 and 16.7-18.7 s); without the trapezoid rule below round-off 1e-4 took
#: 1.6-4.9 times the stage's FIRE steps (docs/notes/shapes.md, "Closing contacts along a step's line").
LINE_XTOL: float = 1e-6

#: Largest number of evaluations of Brent's method on the slope along a step cut short [1]; a search that
#: reaches it keeps its best point. Measured with :data:`LINE_XTOL`: 30 evaluations (to 1e-8) and 8 (to 1e-4)
#: land the same stages at the same tries as 12.
LINE_ITERATIONS: int = 12

#: Eigenvalues of the bordered enthalpy Hessian below ``-NEGATIVE_CURVATURE`` times its
#: largest diagonal entry mark a saddle [1]: far above the round-off of a dense
#: eigen-decomposition (~1e-16 of the norm times the size's square root) and below the
#: quartic modes' eigenvalues at any P0 the protocol reaches.
NEGATIVE_CURVATURE: float = 1e-13


@dataclass(frozen=True)
class NewtonPolish:
    """Outcome of a polish: the final state (or None), the trial steps spent and the last state reached
    (``position`` in ``box``, of ``model``, the model in that box; ``descended`` when a step was kept, so
    its energy or enthalpy is below the start's)."""

    result: MinimizeResult | None
    iterations: int
    position: NDArray[np.float64] | None = None
    box: Box | None = None
    descended: bool = False
    model: EnergyModel | None = None


@dataclass(frozen=True)
class TangentNewton:
    """The Newton system of a constrained model on the tangent space of its manifold at a point ``q``.

    A model with constraints offers it as ``model.tangent_newton(q)`` (None where it has
    none); :func:`polish_constrained` steps along ``basis @ a`` and returns to the manifold
    with the model's ``reproject``.

    Attributes
    ----------
    hessian : scipy.sparse.csc_matrix, shape (n_t, n_t)
        ``B H_L B^T``: the Lagrangian Hessian ``H0 - sum_k mu_k grad^2 c_k`` (multipliers
        of the model's projection) on the tangent basis [energy / length^2].
    basis : scipy.sparse.csr_matrix, shape (n_dof, n_t)
        ``B^T``: orthonormal columns spanning the tangent space (unit masses: the metric
        of the model's projection).
    gradient : ndarray, shape (n_dof,)
        ``grad U`` at ``q`` [energy / length].
    energy, virial_trace : float
        ``U`` [energy] and ``tr W`` [energy] at ``q``.
    move : callable
        ``move(dq)``: the largest change of a pair or link vector under ``dq`` at linear order [length].
    """

    hessian: sp.csc_matrix
    basis: sp.csr_matrix
    gradient: NDArray[np.float64]
    energy: float
    virial_trace: float
    move: Callable[[NDArray[np.float64]], float]

    @classmethod
    def reduce(cls, lagrangian: sp.spmatrix, basis: sp.spmatrix, ev: ModelEvaluation,
               move: Callable[[NDArray[np.float64]], float]) -> TangentNewton:
        """The system of the Lagrangian Hessian (n_dof, n_dof) on ``basis`` (n_dof, n_t) at the evaluation ``ev``."""
        basis = sp.csr_matrix(basis)
        reduced = sp.csc_matrix(basis.T @ (sp.csr_matrix(lagrangian) @ basis))
        return cls(_symmetric(reduced), basis, np.asarray(ev.gradient, dtype=np.float64), float(ev.energy),
                   float(np.trace(ev.virial)), move)


class _State(NamedTuple):
    """A state of :func:`polish_enthalpy` at ``s = 1`` of its own box: coordinates ``q``, the projected gradient
    ``g`` of ``H`` in ``q``, ``dH/ds``, the largest projected force, the pressure, the model's evaluation, the
    model and its configuration."""

    q: NDArray[np.float64]
    g: NDArray[np.float64]
    dhds: float
    fmax: float
    p: float
    ev: ModelEvaluation
    model: EnergyModel
    config: NDArray[np.float64]


def _state(model: EnergyModel, config: NDArray[np.float64], pressure0: float) -> _State:
    """The :class:`_State` of ``config`` in ``model``'s box."""
    q = model.dofs(config)
    ev = model.evaluate(q)
    g = model.project(ev.gradient, q)
    p = pressure_of(ev, model.box)
    d = model.box.d
    return _State(q, g, d * model.box.volume * (pressure0 - p), model.max_force(g), p, ev, model, config)


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


def _symmetric(a: sp.csc_matrix) -> sp.csc_matrix:
    return (0.5 * (a + a.T)).tocsc()


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


def _shifted_factor(a: sp.csc_matrix, metric: NDArray[np.float64], shift: float) -> sla.SuperLU | None:
    """Factors of ``a + shift diag(metric)`` when that matrix is positive definite (all diagonal pivots of a
    symmetric-mode SuperLU positive, Sylvester's inertia), else None."""
    try:
        lu = sla.splu((a + sp.diags(shift * metric)).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options={"SymmetricMode": True})
    except RuntimeError:
        return None
    if not np.array_equal(lu.perm_r, lu.perm_c) or not np.all(lu.U.diagonal() > 0.0):
        return None
    return lu


def _solve(lu: sla.SuperLU | None, rhs: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``lu``'s solution of ``rhs`` when factors exist and the solution is finite, else None."""
    if lu is None:
        return None
    step = lu.solve(rhs)
    return step if np.all(np.isfinite(step)) else None


def _shifted_solve(a: sp.csc_matrix, metric: NDArray[np.float64], shift: float,
                   rhs: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``(a + shift diag(metric))^-1 rhs`` when that matrix is positive definite (:func:`_shifted_factor`), else None."""
    return _solve(_shifted_factor(a, metric, shift), rhs)


def _largest_move(model: EnergyModel, step: NDArray[np.float64], arm: float, spacing: float) -> float:
    """Largest displacement of a body's surface under ``step = (dq, ds)``: centre plus ``arm`` times its
    orientation change, plus the change ``spacing * |ds|`` of a contact distance with the box [length]."""
    d, n = model.box.d, model.positions(step[:-1]).shape[0]
    move = np.sqrt(np.sum(step[: n * d].reshape(n, d) ** 2, axis=1))
    rot = step[n * d: -1]
    if rot.size == n:
        move = move + arm * np.abs(rot)
    return float(move.max()) + spacing * abs(float(step[-1]))


def _enthalpy_system(model: EnergyModel, x: NDArray[np.float64], q: NDArray[np.float64], pressure0: float,
                     spacing: float) -> tuple[sp.csc_matrix, NDArray[np.float64]]:
    """The symmetrised bordered Hessian at ``q`` and its metric: FIRE's masses, and for the box scale the square
    of a contact distance ``spacing``, both times the Hessian's largest diagonal entry."""
    system = _symmetric(_bordered_hessian(model, x, q, pressure0))
    kmax = float(np.abs(system.diagonal()[:-1]).max())
    return system, kmax * np.r_[1.0 / model.inverse_mass, spacing**2]


def _trial(model: EnergyModel, q: NDArray[np.float64], step: NDArray[np.float64], length: float,
           pressure0: float) -> _State:
    """The state (:func:`_state`) at ``length`` along ``step = (dq, ds)`` from ``q`` at ``s = 1``, in its own box."""
    return _state(*model.rescaled(1.0 + length * float(step[-1]), model.positions(q + length * step[:-1])), pressure0)


def _slope(step: NDArray[np.float64], length: float, trial: _State) -> float:
    """``dH/dt`` at ``length`` along ``step = (dq, ds)``, from the :func:`_trial` state there.

    That state's gradient is taken in its box, scaled by ``s = 1 + t ds``: its centres are ``s`` times the
    reference ones, so ``dH/dx = s dH/dx'``, and at fixed reference coordinates ``dH/ds = (dH/ds') / s``.
    """
    s = 1.0 + length * float(step[-1])
    g = trial.g
    n_centre = trial.model.positions(trial.q).shape[0] * trial.model.box.d
    return float(s * (g[:n_centre] @ step[:n_centre]) + g[n_centre:] @ step[n_centre:-1] + trial.dhds / s * step[-1])


def _decrease(ev: ModelEvaluation, trial: _State, pressure0: float, volume: float, length: float,
              step: NDArray[np.float64], gain: float, predicted: float, resolution: float) -> float:
    """Decrease of ``H`` from ``s = 1`` (evaluation ``ev``, box ``volume``) to the trial state at ``length`` along
    ``step`` [energy].

    The difference of the two enthalpies (the box term as ``expm1``, without cancellation) where the predicted
    decrease is above their round-off ``resolution``; below it, the trapezoid rule on the slopes at both ends,
    ``t (gain - dH/dt(t)) / 2`` (``gain = -dH/dt(0)``): exact to third order in ``t``, and resolved to the
    round-off of the gradients, so that a step along a flat valley, whose largest force does not change, is
    judged by what it gains.
    """
    if predicted > resolution:
        d = trial.model.box.d
        return ev.energy - trial.ev.energy - pressure0 * volume * float(np.expm1(d * np.log1p(length * step[-1])))
    return 0.5 * length * (gain - _slope(step, length, trial))


def _line_minimum(model: EnergyModel, q: NDArray[np.float64], step: NDArray[np.float64], pressure0: float,
                  kept: tuple[float, _State], refused: tuple[float, _State]) -> tuple[list[tuple[float, _State]], int]:
    """Points ``(t, state)`` between a kept length and the refused one after it where ``|dH/dt|`` is below its value
    at the kept length, nearest the slope's sign change first (none when the slope does not change sign there),
    and the number of states evaluated.

    Brent's method on ``dH/dt`` (:data:`LINE_XTOL` of the refused length, at most :data:`LINE_ITERATIONS`
    evaluations): the slope needs no enthalpy differences, so it resolves the line below their round-off.
    """
    (lo, state_lo), (hi, state_hi) = kept, refused
    slope_lo, slope_hi = _slope(step, lo, state_lo), _slope(step, hi, state_hi)
    if not slope_lo < 0.0 < slope_hi:
        return [], 0
    points: list[tuple[float, float, _State]] = []

    def slope(t: float) -> float:
        if t in (lo, hi):
            return slope_lo if t == lo else slope_hi
        state = _trial(model, q, step, t, pressure0)
        points.append((t, _slope(step, t, state), state))
        return points[-1][1]

    brentq(slope, lo, hi, xtol=LINE_XTOL * hi, maxiter=LINE_ITERATIONS, disp=False)
    closer = [(t, state) for t, value, state in sorted(points, key=lambda point: abs(point[1]))
              if abs(value) < abs(slope_lo)]
    return closer, len(points)


def polish_enthalpy(model: EnergyModel, config: NDArray[np.float64], pressure0: float, force_tol: float,
                    pressure_rtol: float, max_iterations: int = NEWTON_ITERATIONS,
                    max_indefinite: int | None = TRUST_INDEFINITE) -> NewtonPolish:
    """Levenberg–Marquardt trust-region Newton on ``H = U + P0 V`` (module doc) from ``config`` in ``model``'s box.

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
    max_iterations : int
        Largest number of trial steps (accepted or not; each backtracking length is one
        evaluation of the model, each accepted step one Hessian).
    max_indefinite : int or None
        Steps undone because the Hessian at their end is indefinite after which the polish
        gives up (:data:`TRUST_INDEFINITE`); None walks on, each such step counting as rejected
        (a walk along a flat valley whose end state a caller continues from).

    Returns
    -------
    NewtonPolish
        ``result`` holds the polished state (box scaled, ``steps = 0``) when the tolerances
        were met within ``max_iterations`` trial steps at a minimum (no eigenvalue of the
        bordered Hessian below ``-NEGATIVE_CURVATURE`` of its largest diagonal entry); else None.
    """
    if getattr(model, "constrained", False):
        return NewtonPolish(None, 0)
    x = np.array(config, dtype=np.float64)
    q, g, dhds, fmax, p, ev, _, _ = _state(model, x, pressure0)
    d = model.box.d
    spacing = (model.box.volume / model.positions(q).shape[0]) ** (1.0 / d)
    arm = float(getattr(model, "torque_arm", spacing))
    mu = TRUST_SHIFT
    evaluations = 1
    nu = 2.0
    system = None
    descended = False
    undone = 0
    for it in range(1, max_iterations + 1):
        if system is None:
            system, metric = _enthalpy_system(model, x, q, pressure0, spacing)
            rhs = -np.concatenate([g, [dhds]])
        mu = max(mu, NEWTON_SHIFT)
        step = _shifted_solve(system, metric, mu, rhs)
        if step is None or _largest_move(model, step, arm, spacing) > TRUST_MOVE * spacing:
            mu, nu = mu * nu, 2.0 * nu
            if mu > TRUST_SHIFT_MAX:
                break
            continue
        gain, curvature = float(rhs @ step), float(step @ (system @ step))
        # below the round-off of the energy sums their difference cannot judge a step; the slopes can
        resolution = ENTHALPY_ROUNDOFF * np.finfo(float).eps * abs(p) * d * model.box.volume
        refused = None
        for length in TRUST_BACKTRACK:
            predicted = length * gain - 0.5 * length**2 * curvature
            trial = _trial(model, q, step, length, pressure0)
            evaluations += 1
            decrease = _decrease(ev, trial, pressure0, model.box.volume, length, step, gain, predicted, resolution)
            rho = decrease / predicted
            accepted = rho >= TRUST_ACCEPT
            if accepted:
                break
            refused = (length, trial)
        if accepted and refused is not None:
            # cut short by a contact the Hessian does not see: the line's minimum is where that contact has closed
            closer, spent = _line_minimum(model, q, step, pressure0, (length, trial), refused)
            evaluations += spent
            for t, state in closer:
                t_predicted = t * gain - 0.5 * t**2 * curvature
                t_rho = _decrease(ev, state, pressure0, model.box.volume, t, step, gain, t_predicted,
                                  resolution) / t_predicted
                if t_rho >= TRUST_ACCEPT:
                    length, trial, rho = t, state, t_rho
                    break
        tq, tg, tdhds, tfmax, tp, tev, trial_model, trial_x = trial
        converged = accepted and tfmax <= force_tol and abs(tp - pressure0) <= pressure_rtol * pressure0
        next_system = None
        if accepted and not converged:
            # a step into a region where the model, shifted as for this step, is no longer positive
            # definite left the quadratic model's region (a contact whose overlap the step overshot
            # opened): it is undone, as a rejected step
            next_system = _enthalpy_system(trial_model, trial_x, tq, pressure0, spacing)
            accepted = _shifted_factor(*next_system, mu) is not None
            undone += not accepted
            if max_indefinite is not None and undone >= max_indefinite:
                break
        if not accepted:
            mu, nu = mu * nu, 2.0 * nu
            if mu > TRUST_SHIFT_MAX:
                break
            continue
        if length == 1.0:
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        model, x, q, g, dhds, fmax, p, ev = trial_model, trial_x, tq, tg, tdhds, tfmax, tp, tev
        system = None
        if next_system is not None:
            system, metric = next_system
            rhs = -np.concatenate([g, [dhds]])
        descended = True
        evaluations += 2
        if converged:
            if not _is_minimum(model, x, q, pressure0):
                return NewtonPolish(None, it, x, model.box, True, model)
            return NewtonPolish(MinimizeResult(
                position=np.array(x), box=model.box, energy=ev.energy, pressure=p, max_force=fmax,
                n_contacts=ev.n_contacts, steps=0, converged=True, rebuilds=0, evaluations=evaluations,
            ), it, x, model.box, True, model)
    return NewtonPolish(None, it, x, model.box, descended, model)


def _tangent_state(model: EnergyModel, q: NDArray[np.float64]) -> tuple:
    """Energy evaluation at ``q``, largest projected force, and the centres there."""
    ev = model.evaluate(q)
    return ev, model.max_force(model.project(ev.gradient, q)), np.array(model.positions(q))


def _rebased(model: EnergyModel, q: NDArray[np.float64]) -> tuple:
    """The model rebased on the state ``q`` (``rescaled`` by 1: a strained box becomes the reference at
    zero strain) with that state's ``q``, evaluation, largest projected force and centres."""
    model.evaluate(q)
    base, x = model.rescaled(1.0, model.positions(q))
    qb = base.dofs(x)
    return (base, qb, *_tangent_state(base, qb))


def _tangent_minimum(system: TangentNewton) -> bool:
    """Whether no eigenvalue of the reduced Hessian lies below ``-NEGATIVE_CURVATURE`` of its largest diagonal entry."""
    a = system.hessian
    margin = NEGATIVE_CURVATURE * float(np.abs(a.diagonal()).max(initial=0.0))
    return positive_semidefinite((a + margin * sp.identity(a.shape[0])).tocsc())


def polish_constrained(model: EnergyModel, config: NDArray[np.float64], force_tol: float,
                       max_iterations: int = NEWTON_ITERATIONS) -> NewtonPolish:
    """Levenberg–Marquardt trust-region Newton on ``U`` at fixed volume on a constrained model's manifold.

    Each iteration takes the model's :class:`TangentNewton` system at ``q`` (``model.tangent_newton``)
    and solves ``(K + mu k_max 1) a = -B grad U`` on the tangent basis (``K`` the reduced
    Lagrangian Hessian, ``k_max`` its largest diagonal entry, ``mu`` Nielsen's shift of
    :func:`polish_enthalpy`); the trial state is ``reproject(q + B^T a)`` (and quarter lengths
    of it, :data:`TRUST_BACKTRACK`), kept when ``U`` decreases by :data:`TRUST_ACCEPT` of the
    quadratic prediction (exact to second order on the manifold: the multipliers' term is the
    constraints' curvature) or, below the round-off of ``U`` (:data:`ENTHALPY_ROUNDOFF` of
    ``eps tr W``), when the largest projected force falls. After each kept step the model is
    rebased on the new state (``rescaled`` by 1). The run is accepted once the largest projected
    force is at most ``force_tol`` and the reduced Hessian there has no eigenvalue below
    ``-NEGATIVE_CURVATURE`` of its largest diagonal entry (a minimum, not a saddle).
    A full step at a shift of at most :data:`TRUST_SHIFT` whose decrease was at least
    :data:`CHORD_RATIO` of the prediction is followed
    by chord steps (the factors and basis of the last system with the new gradient; the old
    tangent basis is tangent at the new point to first order in the step) until one fails,
    which is retried from a fresh system: from FIRE's states near the minimum most steps then
    cost a solve, not a factorisation.

    Parameters
    ----------
    model : EnergyModel
        A constrained model in the box of ``config`` (for strain coordinates: rebased, zero
        strain), with ``tangent_newton``; without it (or where it returns None) nothing is polished.
    config : ndarray
        Centres (``model.positions`` form) on the manifold to the model's precision.
    force_tol : float
        Largest projected force of the result (:meth:`EnergyModel.max_force`) [energy / length].
    max_iterations : int
        Largest number of trial steps (each backtracking length one; each kept step one system).

    Returns
    -------
    NewtonPolish
        ``result`` (``steps = 0``) and ``model`` (rebased on it) when accepted, else ``result``
        None; ``position`` and ``descended`` as :func:`polish_enthalpy`.
    """
    if getattr(model, "tangent_newton", None) is None:
        return NewtonPolish(None, 0)
    q = model.dofs(np.array(config, dtype=np.float64))
    ev, fmax, x = _tangent_state(model, q)
    spacing = (model.box.volume / len(x)) ** (1.0 / model.box.d)
    mu, nu = TRUST_SHIFT, 2.0
    evaluations, descended, system, chord = 1, False, None, False
    it = 0
    for it in range(1, max_iterations + 1):
        if system is None:
            system = model.tangent_newton(q)
            if system is None:
                return NewtonPolish(None, it - 1)
            kmax = float(np.abs(system.hessian.diagonal()).max(initial=0.0))
            metric = np.full(system.hessian.shape[0], kmax)
            rhs = -(system.basis.T @ system.gradient)
            resolution = ENTHALPY_ROUNDOFF * np.finfo(float).eps * abs(system.virial_trace)
            factors = None
        mu = max(mu, NEWTON_SHIFT)
        if factors is None or factors[0] != mu:
            factors = (mu, _shifted_factor(system.hessian, metric, mu))
        a = _solve(factors[1], rhs)
        dq = None if a is None else system.basis @ a
        if dq is None or system.move(dq) > TRUST_MOVE * spacing:
            mu, nu = mu * nu, 2.0 * nu
            if mu > TRUST_SHIFT_MAX:
                break
            continue
        gain, curvature = float(rhs @ a), float(a @ (system.hessian @ a))
        accepted = False
        for length in TRUST_BACKTRACK:
            predicted = length * gain - 0.5 * length**2 * curvature
            try:
                trial = _rebased(model, model.reproject(q + length * dq))
            except RuntimeError:  # re-affixing failed: too long a step
                continue
            evaluations += 2
            actual = ev.energy - trial[2].energy
            rho = actual / predicted if predicted > resolution else 0.0
            accepted = rho >= TRUST_ACCEPT if predicted > resolution else trial[3] < fmax
            if accepted:
                break
        if not accepted and chord:
            system, chord = None, False  # a chord step that fails is retried from a fresh system
            continue
        if not accepted:
            mu, nu = mu * nu, 2.0 * nu
            if mu > TRUST_SHIFT_MAX:
                break
            continue
        model, q, ev, fmax, x = trial
        descended = True
        # a full Newton step (shift at most the starting one) that the quadratic model predicted well (or that
        # lowered the force below the energy's round-off) is followed by chord steps: the same factors and
        # tangent basis, the new gradient; under a larger shift the shift must fall first
        chord = length == 1.0 and mu <= TRUST_SHIFT and (rho >= CHORD_RATIO or predicted <= resolution)
        if chord:
            rhs = -(system.basis.T @ ev.gradient)
        else:
            if length == 1.0:
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3) if predicted > resolution else 1.0 / 3.0
                nu = 2.0
            system = None
        if fmax <= force_tol:
            final = model.tangent_newton(q)
            ev, fmax, x = _tangent_state(model, q)  # the model's last evaluation is the final state
            if final is None or not _tangent_minimum(final):
                return NewtonPolish(None, it, x, model.box, True, model)
            return NewtonPolish(MinimizeResult(
                position=x, box=model.box, energy=ev.energy, pressure=pressure_of(ev, model.box), max_force=fmax,
                n_contacts=ev.n_contacts, steps=0, converged=True, rebuilds=0, evaluations=evaluations,
            ), it, x, model.box, True, model)
    return NewtonPolish(None, it, x, model.box, descended, model)
