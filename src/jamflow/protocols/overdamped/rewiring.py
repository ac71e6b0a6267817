"""The rewiring procedure (Lerner, Düring & Wyart, Sec. IV B and Appendix A).

Starting from a set of candidate contacts Γ (the current network plus a new contact,
or a network in which forces turned negative), repeat

  (i)  remove the contact with the most negative force, recompute, until no force is
       negative;
  (ii) among the removed pairs, re-add the one approaching fastest (``v_ij < 0``,
       Eq. 26) and go back to (i); stop when no removed pair approaches.

The result A satisfies (A6) ``f_A > 0`` on A and (A8) ``v_A > 0`` on Γ \\ A, and is
unique (App. A). "Zero" is judged relative to the force and velocity scales of the
network (``REWIRE_REL_TOL`` in :mod:`jamflow.tolerances`); a contact with a force
below ``-tol`` is negative, a pair with a rate below ``-tol`` approaches.

Permanent contacts (composite particles, Sec. V C) are never removed and may carry
negative forces. When the network becomes potentially jammed (Sec. IV D) the
evaluator returns the self-stress ``f0`` in place of the forces; a positive ``f0``
ends the procedure with a jammed network.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...tolerances import REWIRE_REL_TOL
from .network import Solution

__all__ = ["Evaluation", "RewireResult", "RewiringError", "rewire", "admissible"]


class RewiringError(RuntimeError):
    """The rewiring procedure did not terminate."""


@dataclass(frozen=True)
class Evaluation:
    """Forces on an active subset, from Eq. 11/18 or (potentially jammed) the self-stress.

    Attributes
    ----------
    force : ndarray, shape (n_active,)
        In the order of ``np.flatnonzero(active)``.
    solution : Solution or None
        None when ``force`` is a self-stress (no velocities exist).
    self_stress : bool
    """

    force: NDArray[np.float64]
    solution: Solution | None
    self_stress: bool = False


@dataclass(frozen=True)
class RewireResult:
    """Outcome of :func:`rewire`.

    Attributes
    ----------
    active : ndarray of bool, shape (P,)
        The contact network A within Γ.
    evaluation : Evaluation
        Forces (and velocities) on A.
    jammed : bool
        A is potentially jammed with a self-stress of one sign.
    n_iterations : int
        Number of force evaluations.
    """

    active: NDArray[np.bool_]
    evaluation: Evaluation
    jammed: bool
    n_iterations: int


def _scale(values: NDArray[np.float64]) -> float:
    return float(np.max(np.abs(values), initial=0.0))


def rewire(
    active: NDArray[np.bool_],
    evaluate: Callable[[NDArray[np.bool_]], Evaluation],
    rates: Callable[[Solution, NDArray[np.int64]], NDArray[np.float64]],
    velocity_scale: Callable[[Solution], float],
    permanent: NDArray[np.bool_] | None = None,
    rel_tol: float = REWIRE_REL_TOL,
    max_iterations: int = 10_000,
) -> RewireResult:
    """Run the rewiring procedure of Sec. IV B on the candidate set Γ.

    Parameters
    ----------
    active : ndarray of bool, shape (P,)
        Initially active pairs of Γ (normally all of them).
    evaluate : callable
        ``evaluate(mask) -> Evaluation`` for the sub-network ``mask``.
    rates : callable
        ``rates(solution, idx) -> v`` pair rates ``dr/dt`` (Eq. 26) of pairs ``idx`` of Γ.
    velocity_scale : callable
        ``velocity_scale(solution)``: magnitude against which rates are judged zero.
    permanent : ndarray of bool, shape (P,), optional
        Pairs that are never removed (composite particles).
    rel_tol : float
        Relative tolerance for "negative" forces and rates.
    max_iterations : int
        Bound on force evaluations (cycling would be a bug; it raises).
    """
    active = np.array(active, dtype=bool)
    perm = np.zeros_like(active) if permanent is None else np.asarray(permanent, dtype=bool)
    removed = np.zeros_like(active)
    n_eval = 0
    while n_eval < max_iterations:
        # (i) strip negative forces one at a time, most negative first
        while True:
            ev = evaluate(active)
            n_eval += 1
            idx = np.flatnonzero(active)
            f = ev.force
            tol = rel_tol * _scale(f)
            neg = (f < -tol) & ~perm[idx]
            if ev.self_stress and not neg.any():
                return RewireResult(active, ev, True, n_eval)
            if not neg.any():
                break
            k = idx[np.argmin(np.where(perm[idx], np.inf, f))]
            active[k] = False
            removed[k] = True
            if n_eval >= max_iterations:
                raise RewiringError(f"rewiring did not terminate in {max_iterations} evaluations")
        # (ii) re-connect the fastest approaching removed pair, if any
        ridx = np.flatnonzero(removed)
        if ridx.size == 0:
            return RewireResult(active, ev, False, n_eval)
        v = rates(ev.solution, ridx)
        tol_v = rel_tol * velocity_scale(ev.solution)
        if not np.any(v < -tol_v):
            return RewireResult(active, ev, False, n_eval)
        k = ridx[np.argmin(v)]
        active[k] = True
        removed[k] = False
    raise RewiringError(f"rewiring did not terminate in {max_iterations} evaluations")


def admissible(
    active: NDArray[np.bool_],
    candidates: NDArray[np.bool_],
    evaluate: Callable[[NDArray[np.bool_]], Evaluation],
    rates: Callable[[Solution, NDArray[np.int64]], NDArray[np.float64]],
    velocity_scale: Callable[[Solution], float],
    rel_tol: float = REWIRE_REL_TOL,
) -> tuple[bool, float, float]:
    """Whether a subset A of Γ satisfies Appendix A's (A6) and (A8).

    (A6): forces on A positive (forces off A are zero by construction).
    (A8): rates on A zero (``S V = 0`` on A, checked to ``rel_tol``) and positive on Γ \\ A.

    Parameters
    ----------
    active, candidates : ndarray of bool, shape (P,)
        A and Γ (A within Γ).

    Returns
    -------
    ok : bool
    min_force : float
        Smallest force on A relative to the largest (inf when A is empty).
    min_rate : float
        Smallest rate on Γ \\ A relative to the velocity scale (inf when A = Γ).
    """
    active = np.asarray(active, dtype=bool)
    try:
        ev = evaluate(active)
    except Exception:  # a singular sub-network has no forces: not admissible
        return False, -np.inf, -np.inf
    if ev.solution is None:
        return False, -np.inf, -np.inf
    f = ev.force
    fmin = float(f.min() / _scale(f)) if f.size and _scale(f) > 0 else np.inf
    vs = velocity_scale(ev.solution)
    off = np.flatnonzero(np.asarray(candidates, dtype=bool) & ~active)
    on = np.flatnonzero(active)
    vmin = float(rates(ev.solution, off).min() / vs) if off.size else np.inf
    von = float(np.max(np.abs(rates(ev.solution, on))) / vs) if on.size else 0.0
    ok = (fmin > rel_tol) and (vmin > rel_tol) and (von < rel_tol)
    return ok, fmin, vmin
