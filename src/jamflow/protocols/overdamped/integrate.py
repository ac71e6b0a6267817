"""The event-driven integration loop (Lerner, Düring & Wyart, Sec. IV A–C).

One step: predict the next collision among non-contacting listed pairs under the
current velocities, move everything on straight lines to ``min(t_col, t + dt)``
(positions ``x += t (E x + U)``, box ``h += t E h``), then

- on a collision, add the pair and run the rewiring procedure (Sec. IV B);
- otherwise recompute the forces on the moved network and rewire if any turned
  negative.

The step ``dt`` follows the rule of Sec. IV A: about ``steps_per_event`` steps
between events (a running mean of the event interval), bounded by ``dt_max``.
Every ``correct_every`` steps (and whenever the constraint error exceeds
``drift_tol``) the drift correction of Sec. IV C (Eq. 28) projects the contacts back
to ``r_ij = d_i + d_j``, handling collisions during the correction.

Lengths are in units of lambda, time in units of ``1 / rate`` (deformation) or
``tau`` (forces); the integrator itself works in the drive's own units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from ...box import Box, lattice_volume
from ...neighbors.verlet import NeighborList
from ...state.packing import sphere_volume
from ...tolerances import CONTACT_DRIFT_TOL, REWIRE_REL_TOL
from .collisions import build_neighbor_list, images_of, next_collision
from .driving import Drive
from .jamming import constrained_subset, self_stress
from .network import (
    Solution,
    advance_box,
    advance_positions,
    affine_rates,
    has_negative,
    max_relative_error,
    max_relative_rate,
    pair_normals,
    pair_vectors,
    pair_velocities,
    solve_network,
    spectral_norm,
    stress_tensor,
    tangent_velocities,
)
from .rewiring import Evaluation, rewire
from .skin import SkinBudget
from .solver import (
    COND_LIMIT,
    FactorCache,
    SingularNetworkError,
    s_matrix,
    solve_contact_system,
)

__all__ = ["FlowOptions", "FlowState", "Integrator", "EVENT_MADE", "EVENT_BROKEN"]

EVENT_MADE = 1
EVENT_BROKEN = -1
#: Relative accuracy of each Newton step of the drift correction on the cached factor:
#: a step solved to relative error eps leaves about eps * err + O(err^2) of a constraint
#: error err (<= drift_tol), and the steps repeat until the error reaches their target.
CORRECTION_RTOL: float = 1e-6
#: Relative accuracy of the midpoint step's two solves on the cached factor (the probe
#: and the projection of its velocities on the contacts). The velocities only move the
#: particles: an error eps shifts a step by eps * dt * |U|, far below the step's own
#: error, and leaves contact rates of eps times the projected rates, themselves O(dt):
#: gaps change by O(eps dt^2), below round-off. The probe's forces only choose between
#: the midpoint and the Euler step; every state's forces come from a full solve.
MIDPOINT_RTOL: float = 1e-9


@dataclass(frozen=True)
class FlowOptions:
    """Accuracy and bookkeeping knobs of the event-driven dynamics.

    Attributes
    ----------
    dt_max : float
        Upper bound of the integration step [time unit of the drive]. The paper uses
        1e-5; the constraint error per step is O(dt^2) and is corrected anyway.
    steps_per_event : float
        Target mean number of steps between events (paper: 10).
    dt_min : float
        Lower bound of the step.
    step_drift : float
        Largest relative constraint error one step may create: a contact moving
        with relative velocity W perpendicular to it opens by ``dt^2 |W|^2 / (2 sigma)``
        (Sec. IV C, Fig. 3), so ``dt <= sigma sqrt(2 step_drift) / max |W|``. Near
        jamming non-affine velocities diverge and this bound, not the event rule,
        sets the step (an addition to the paper's rule).
    correct_every : int
        Apply the drift correction every this many steps (0: only on ``drift_tol``).
    drift_tol : float
        Relative constraint error that triggers a correction regardless.
    skin : float
        Verlet-list skin [lambda].
    sync_every : int
        Steps between synchronisation points (neighbour-list rebuild, box reduction,
        checkpoints). Results do not depend on whether checkpoints are written.
    cond_limit : float
        Pivot ratio of N = S S^T treated as singular.
    rel_tol : float
        Rewiring tolerance (see :mod:`.rewiring`).
    order : int
        1: each step moves on a straight line with the velocities at its start (the
        paper's scheme; trajectory error O(dt)). 2: explicit midpoint — the velocities
        are re-solved on the same network at the half step, projected on the contacts
        of the step's start (so that contacts only open, as in the Euler step) and the
        whole step moves with those (two extra CG solves on the cached factorisation);
        a half-step probe that meets a negative force or a singular network, and a
        network that may carry a self-stress, fall back to the order-1 step.
    """

    dt_max: float = 1e-3
    steps_per_event: float = 10.0
    dt_min: float = 1e-14
    step_drift: float = 1e-9
    correct_every: int = 100
    drift_tol: float = CONTACT_DRIFT_TOL
    skin: float = 0.3
    sync_every: int = 2000
    cond_limit: float = COND_LIMIT
    rel_tol: float = REWIRE_REL_TOL
    order: int = 1

    def __post_init__(self) -> None:
        if not (0 < self.dt_min <= self.dt_max):
            raise ValueError("need 0 < dt_min <= dt_max")
        if self.steps_per_event <= 0:
            raise ValueError("steps_per_event must be positive")
        if self.correct_every < 0 or self.sync_every < 1:
            raise ValueError("correct_every >= 0 and sync_every >= 1 required")
        if self.skin <= 0:
            raise ValueError("skin must be positive")
        if self.order not in (1, 2):
            raise ValueError("order must be 1 (Euler) or 2 (midpoint)")


@dataclass
class FlowState:
    """Complete dynamical state (everything a checkpoint must hold).

    Attributes
    ----------
    x : ndarray, shape (N, d)
        Centres [lambda] (wrapped at synchronisation points only).
    h : ndarray, shape (d, d)
        Box matrix [lambda].
    radius : ndarray, shape (N,)
        Radii d_i [lambda] (contact at ``r_ij = d_i + d_j``).
    nl : NeighborList
        The Verlet list (:func:`.collisions.build_neighbor_list`).
    budget : SkinBudget
        Motion since the list's build (its validity bound).
    contact : ndarray of bool, shape (P,)
        Which listed pairs form the contact network.
    permanent : ndarray of bool, shape (P,)
        Listed pairs that are permanent contacts (composite particles).
    time, strain : float
        Elapsed time and accumulated imposed strain (``rate * time`` for deformations).
    step : int
    event_interval : float
        Running mean time between events (dt rule).
    last_event_time : float
    jammed : bool
    kappa : float
        Last compression-to-shear rate ratio (fixed pressure).
    events : list of (strain, time, i, j, kind)
    corrections : list of (strain, error before, error after)
        Drift corrections (Sec. IV C) with the largest relative constraint error.
    """

    x: NDArray[np.float64]
    h: NDArray[np.float64]
    radius: NDArray[np.float64]
    nl: NeighborList
    budget: SkinBudget
    contact: NDArray[np.bool_]
    permanent: NDArray[np.bool_]
    time: float = 0.0
    strain: float = 0.0
    step: int = 0
    event_interval: float = np.inf
    last_event_time: float = 0.0
    jammed: bool = False
    kappa: float = np.nan
    events: list = field(default_factory=list)
    corrections: list = field(default_factory=list)


class Integrator:
    """Event-driven overdamped dynamics of one packing under one drive.

    Parameters
    ----------
    state : FlowState
    drive : Drive
    options : FlowOptions
    """

    def __init__(self, state: FlowState, drive: Drive, options: FlowOptions) -> None:
        self._setup(state, drive, options)
        self.solution: Solution = self._solution_now()

    def _setup(self, state: FlowState, drive: Drive, options: FlowOptions) -> None:
        """Everything but the solution: derived constants, empty memos and factorisation cache."""
        self.state, self.drive, self.options = state, drive, options
        self.n, self.d = state.x.shape
        self.base_gradient = drive.gradient(self.d)
        self.pressure_internal = None if drive.pressure is None else drive.pressure * drive.force_unit
        self.particle_volume = float(sphere_volume(self.d, 2 * state.radius).sum())
        self.last_correction: tuple[float, float] = (np.nan, np.nan)
        self._count_key = None
        self._count = None
        self._nl_version = 0
        self._pairs_key = None
        self._sigma_value = None
        self._free_value = None
        self._volume_of = None
        self._sep_key = None
        self._solved_at = (None, None, None)
        self._err_key = None
        self.factor_cache = FactorCache()

    # ---------------------------------------------------------------- construction
    @classmethod
    def start(
        cls,
        x: NDArray[np.float64],
        h: NDArray[np.float64],
        radius: NDArray[np.float64],
        drive: Drive,
        options: FlowOptions,
        contacts: NDArray[np.int64] | None = None,
    ) -> "Integrator":
        """Set up from positions; initial contacts are the given ones (or none) plus
        permanent ones, filtered by the rewiring procedure."""
        box = Box(h).reduced
        x = box.wrap(x)
        nl = build_neighbor_list(x, box, radius, options.skin)
        contact = np.zeros(len(nl.i), bool)
        permanent = np.zeros(len(nl.i), bool)
        for arr, mask in ((contacts, contact), (drive.permanent, permanent)):
            if arr is not None and len(arr):
                pos = nl.index_of(np.sort(np.asarray(arr, np.int64), axis=1))
                if np.any(pos < 0):
                    raise ValueError("a given contact is farther apart than its contact distance plus the "
                                     "neighbour-list skin")
                mask[pos] = True
        contact |= permanent
        state = FlowState(x, np.array(box.matrix), np.asarray(radius, float), nl, SkinBudget.fresh(x), contact,
                          permanent)
        state.event_interval = options.dt_max * options.steps_per_event
        integ = cls.__new__(cls)
        integ._setup(state, drive, options)
        if contact.any():
            integ._rewire(contact.copy())
            # the initial network is the reference state, not a sequence of events
            state.events.clear()
            state.event_interval = options.dt_max * options.steps_per_event
            state.last_event_time = 0.0
        else:
            integ.solution = integ._solve(contact)
        return integ

    # ------------------------------------------------------------- network algebra
    def _listed(self, idx: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Pairs (k, 2) and images (k, d) of the listed pairs at positions ``idx``."""
        # np.take: ten times faster than fancy indexing of these rows
        # (measured: docs/notes/overdamped-constants.md)
        nl = self.state.nl
        return np.take(nl.pairs, idx, axis=0), np.take(nl.image, idx, axis=0)

    def _pairs(self, mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Pairs and images of the sub-network ``mask`` (memoised on the last mask; read-only)."""
        key = (mask.tobytes(), self._nl_version, id(self.state.nl))
        if self._pairs_key != key:
            self._pairs_key = key
            self._pairs_value = self._listed(np.flatnonzero(mask))
            for a in self._pairs_value:
                a.flags.writeable = False  # read-only: the solver's cache knows the network by identity
            self._sigma_value = None
            self._free_value = None
        return self._pairs_value

    def _contact_sigma(self) -> NDArray[np.float64]:
        """Contact distances ``sigma_ij`` of the current network, shape (Nc,) (memoised with its pairs; read-only)."""
        self._pairs(self.state.contact)
        if self._sigma_value is None:
            self._sigma_value = self.state.nl.sigma[self.state.contact]
        return self._sigma_value

    def _separations(self, mask: NDArray[np.bool_]) -> NDArray[np.float64]:
        """Separations ``R`` of the sub-network ``mask`` at the current positions, shape (Nc, d) (read-only).

        Memoised on the last (mask, positions, box): the step rule, the solve, the
        constraint error and the recorder all need them at the same state. Positions
        and box are replaced, never modified in place, and the memo holds the arrays
        it was computed from, so their identities name the state.
        """
        st = self.state
        pairs, images = self._pairs(mask)
        key = (self._pairs_key, id(st.x), id(st.h))
        if self._sep_key != key:
            self._sep_key = key
            self._sep_value = (pair_vectors(st.x, st.h, pairs, images), st.x, st.h)
        return self._sep_value[0]

    def _solve(self, mask: NDArray[np.bool_], check_pivots: bool = True, rtol: float | None = None) -> Solution:
        pairs, images = self._pairs(mask)
        separations = self._separations(mask)
        sol = solve_network(
            self.state.x, self.state.h, pairs, images, self.base_gradient,
            external=self.drive.external_forces(), xi0=self.drive.xi0,
            pressure=self.pressure_internal, rate=self.drive.rate, cond_limit=self.options.cond_limit,
            check_pivots=check_pivots, cache=self.factor_cache, time=self.state.time,
            separations=separations, rtol=rtol,
        )
        self._solved_at = (sol, self._sep_key, self._sep_value)  # the memo's arrays keep its ids unique
        return sol

    def count(self, mask: NDArray[np.bool_]):
        """Constrained subset of the sub-network ``mask`` (memoised with its pairs)."""
        pairs, _ = self._pairs(mask)
        if self._count_key is not self._pairs_key:
            self._count_key = self._pairs_key
            self._count = constrained_subset(self.n, self.d, pairs)
        return self._count

    def _drive_rates(self, pairs: NDArray[np.int64], images: NDArray[np.float64]) -> NDArray[np.float64]:
        """``S V_aff / xi0 + S F_ext`` on a network (for the self-stress sign)."""
        R = pair_vectors(self.state.x, self.state.h, pairs, images)
        E = self.base_gradient
        if self.drive.pressure is not None:
            E = E - self.drive.rate * np.eye(self.d)  # pressure pushes inward
        out = affine_rates(R, E) / self.drive.xi0
        ext = self.drive.external_forces()
        if ext is not None:
            out = out + s_matrix(pairs, pair_normals(R), self.n) @ ext.ravel()
        return out

    def evaluate(self, mask: NDArray[np.bool_], rtol: float | None = None) -> Evaluation:
        """Forces on the sub-network ``mask``, or its self-stress if potentially jammed
        (``rtol``: CG tolerance on the cached factor, default the cache's)."""
        pairs, images = self._pairs(mask)
        count = self.count(mask)
        singular = count.potentially_jammed and not self.state.permanent.any()
        if not singular:
            try:
                sol = self._solve(mask, check_pivots=count.may_self_stress, rtol=rtol)
                return Evaluation(sol.force, sol)
            except SingularNetworkError:
                singular = True
        f0, _ = self_stress(self.state.x, self.state.h, pairs, images, self._drive_rates(pairs, images))
        return Evaluation(f0, None, True)

    def rates(self, sol: Solution, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        """Pair rates dr/dt (Eq. 26) of listed pairs ``idx``."""
        pairs, images = self._listed(idx)
        R = pair_vectors(self.state.x, self.state.h, pairs, images)
        return pair_velocities(R, pairs, sol)

    def velocity_scale(self, sol: Solution) -> float:
        """Scale against which pair rates are judged zero [lambda / time]."""
        u = float(np.max(np.abs(sol.velocity), initial=0.0))
        return max(u, spectral_norm(sol.gradient) * self.state.nl.reach, 1e-300)

    def _rewire(self, candidate: NDArray[np.bool_]) -> None:
        res = rewire(candidate, self.evaluate, self.rates, self.velocity_scale,
                     permanent=self.state.permanent, rel_tol=self.options.rel_tol)
        old = self.state.contact
        new = res.active
        self._record_events(old, new)
        self.state.contact = new
        if res.jammed:
            self.state.jammed = True
            f0 = res.evaluation.force
            self.solution = Solution(f0 / np.mean(f0), np.zeros((self.n, self.d)), np.zeros((self.d, self.d)), np.nan)
        else:
            self.solution = res.evaluation.solution
        self.state.kappa = self.solution.kappa

    def _record_events(self, old: NDArray[np.bool_], new: NDArray[np.bool_]) -> None:
        st = self.state
        made = np.flatnonzero(new & ~old)
        broken = np.flatnonzero(old & ~new)
        for idx, kind in ((made, EVENT_MADE), (broken, EVENT_BROKEN)):
            for k in idx:
                st.events.append((st.strain, st.time, int(st.nl.i[k]), int(st.nl.j[k]), kind))
        if made.size or broken.size:
            gap = st.time - st.last_event_time
            if gap > 0:
                # running mean of the time between events (dt rule of Sec. IV A)
                st.event_interval = gap if not np.isfinite(st.event_interval) else 0.8 * st.event_interval + 0.2 * gap
            st.last_event_time = st.time

    def _solution_now(self) -> Solution:
        ev = self.evaluate(self.state.contact)
        if ev.solution is None:
            self.state.jammed = True
            return Solution(ev.force / np.mean(ev.force), np.zeros((self.n, self.d)), np.zeros((self.d, self.d)), np.nan)
        return ev.solution

    # -------------------------------------------------------------------- motion
    def _move(self, t: float, velocity: NDArray[np.float64], gradient: NDArray[np.float64]) -> None:
        st = self.state
        st.x, st.h = advance_positions(st.x, velocity, gradient, t), advance_box(st.h, gradient, t)
        st.budget.advance(velocity, gradient, t)

    def dt(self) -> float:
        """Current integration step (Sec. IV A rule)."""
        o = self.options
        st = self.state
        dt = min(o.dt_max, st.event_interval / o.steps_per_event) * self.drive.time_unit
        if st.contact.any() and self.solution.velocity.shape == st.x.shape:
            pairs, _ = self._pairs(st.contact)
            w = max_relative_rate(self._separations(st.contact), pairs, self.solution, self._contact_sigma())
            if w > 0:
                dt = min(dt, np.sqrt(2.0 * o.step_drift) / w)
        return float(max(o.dt_min * self.drive.time_unit, dt))

    def list_horizon(self, sol: Solution) -> float:
        """Longest straight-line move under ``sol`` after which the Verlet list is still valid
        (:meth:`.skin.SkinBudget.horizon`): collisions are predicted among listed pairs only."""
        return self.state.budget.horizon(self.state.nl, sol.velocity, sol.gradient)

    def step(self, horizon: float = np.inf) -> bool:
        """One integration step, at most to ``time + horizon``. Returns True on a collision."""
        st = self.state
        sol = self.solution
        limit = self.list_horizon(sol)
        tmax = min(self.dt(), horizon, limit)
        if self.options.order == 2:
            sol = self._midpoint(sol, tmax)
            # the midpoint velocities may be larger: keep the move within the list horizon
            tmax = min(tmax, self.list_horizon(sol))
        t, k = next_collision(st.x, st.h, st.nl.pairs, st.nl.image, st.nl.sigma, st.contact,
                              sol.velocity, sol.gradient, tmax)
        self._move(t, sol.velocity, sol.gradient)
        st.time += t
        if self.drive.deforms:
            st.strain += t * self.drive.rate
        st.step += 1
        if k >= 0:
            cand = st.contact.copy()
            cand[k] = True
            self._rewire(cand)
        else:
            self._refresh()
        if self.drive.mode == "self_propelled":
            due = np.flatnonzero(self.drive.propulsion.switch_time <= st.time)
            if due.size:
                self.drive.propulsion.redraw(due, st.time)
                self._refresh()
        if self.options.correct_every and st.step % self.options.correct_every == 0:
            self.correct()
        elif st.contact.any() and self.constraint_error() > self.options.drift_tol:
            self.correct()
        if st.step % self.options.sync_every == 0:
            self.synchronize()
        elif not st.budget.valid(st.nl) or (k < 0 and t >= limit):
            # a step cut short by the list horizon ends on a rebuild (else the next
            # steps would shrink towards the same horizon)
            self.rebuild()
        return k >= 0

    def _midpoint(self, sol: Solution, dt: float) -> Solution:
        """Velocities of the midpoint step of length ``dt`` from the current state.

        The state is moved half a step with ``sol``, solved on the same network (a probe
        that ignores collisions), and restored exactly; the probe's velocities are then
        projected on the contacts of the current state (:func:`tangent_velocities`).
        Moved with the raw probe velocities, contacts would drift by O(dt^3) of either
        sign and could leave the network overlapping; projected, they drift like the
        Euler step's, by ``+dt^2 |W|^2 / (2 sigma)`` (contacts only open), and the
        motion along the contacts keeps the midpoint's second order.

        Returns ``sol`` itself (the Euler step) without contacts, under self-propulsion,
        on a network that may carry a self-stress, or when the probe meets a singular
        network or a negative force (the rewiring at the step's end handles the event).
        """
        st = self.state
        if not st.contact.any() or self.drive.mode == "self_propelled" or self.count(st.contact).may_self_stress:
            return sol
        saved = (st.x, st.h, st.budget.copy(), st.time)
        self._move(0.5 * dt, sol.velocity, sol.gradient)
        st.time = saved[3] + 0.5 * dt
        try:
            ev = self.evaluate(st.contact, rtol=MIDPOINT_RTOL)
        finally:
            st.x, st.h, st.budget, st.time = saved
        if ev.solution is None or self._has_negative_force(ev.force):
            return sol
        pairs, _ = self._pairs(st.contact)
        try:
            return tangent_velocities(self._separations(st.contact), pairs, ev.solution, self.factor_cache,
                                      self.options.cond_limit, rtol=MIDPOINT_RTOL)
        except SingularNetworkError:
            return sol

    def _refresh(self) -> None:
        """Forces on the moved network; rewire if some turned negative (Sec. IV A ii.b)."""
        ev = self.evaluate(self.state.contact)
        if ev.solution is not None and not self._has_negative_force(ev.force):
            self.solution = ev.solution
            self.state.kappa = ev.solution.kappa
            return
        self._rewire(self.state.contact.copy())

    def _has_negative_force(self, force: NDArray[np.float64]) -> bool:
        """Whether a non-permanent contact of the current network carries a force below
        ``-rel_tol max |f|`` (the rewiring's "negative")."""
        st = self.state
        self._pairs(st.contact)
        if self._free_value is None:
            self._free_value = ~st.permanent[st.contact]
        return has_negative(force, self._free_value, self.options.rel_tol)

    def next_switch(self) -> float:
        """Time until the next self-propulsion redraw (inf otherwise)."""
        if self.drive.mode != "self_propelled":
            return np.inf
        return float(self.drive.propulsion.switch_time.min() - self.state.time)

    # -------------------------------------------------------------- diagnostics
    def constraint_error(self) -> float:
        """Largest ``|r_ij - sigma_ij| / sigma_ij`` over contacts (0 without contacts).

        Memoised per state: the step's drift check and the recorder ask at the same state.
        """
        st = self.state
        R = self._separations(st.contact)
        if self._err_key != self._sep_key:
            self._err_key = self._sep_key
            self._err_value = max_relative_error(R, self._contact_sigma())
        return self._err_value

    def stress(self) -> NDArray[np.float64]:
        """Contact stress tensor [force / lambda^(d-1)] (see :func:`stress_tensor`)."""
        st = self.state
        R = self._separations(st.contact)
        sol, key, _ = self._solved_at
        if sol is self.solution and key == self._sep_key and sol.virial is not None:
            return sol.virial / self.volume()  # solved at these separations: its virial is theirs
        return stress_tensor(R, self.solution.force, self.volume())

    def packing_fraction(self) -> float:
        """Volume fraction of the particles in the current box."""
        return self.particle_volume / self.volume()

    def volume(self) -> float:
        """Box volume ``det h`` [lambda^d] (memoised on the box array, which is replaced, never modified)."""
        h = self.state.h
        if self._volume_of is not h:
            self._volume_of, self._volume = h, lattice_volume(h)
        return self._volume

    def n_contacts(self) -> int:
        """Contacts of the current network."""
        return len(self._pairs(self.state.contact)[0])

    def z_bar(self) -> float:
        """Constrained coordination of the current network (Eq. 29)."""
        return self.count(self.state.contact).z_bar

    # --------------------------------------------------------- drift correction
    def correct(self, max_rounds: int = 50, target: float = 1e-13) -> tuple[float, float]:
        """Drift correction of Sec. IV C (Eq. 28). Returns the error before and after.

        Eq. 28 is the linear (Newton) step for ``r_ij = sigma_ij``; it is repeated while
        the error decreases and exceeds ``target`` (near jamming N is ill-conditioned
        and one linear step can overshoot; a step that increases the error is undone).
        Collisions during the correction join the network (steps iii.a, iv), and the
        network is rewired at the end (step v).
        """
        st = self.state
        before = self.constraint_error()
        if not st.contact.any():
            self.last_correction = (before, before)
            return self.last_correction
        zero = np.zeros((self.d, self.d))
        err = before
        for _ in range(max_rounds):
            if err <= target:
                break
            pairs, images = self._pairs(st.contact)
            R = pair_vectors(st.x, st.h, pairs, images)
            r = np.linalg.norm(R, axis=1)
            dr = r - st.nl.sigma[st.contact]
            unit = R / r[:, None]
            S = s_matrix(pairs, unit, self.n)
            grad = zero
            try:
                # on the cached factor unless a self-stress is possible (as the force solves)
                dx = solve_contact_system(pairs, unit, self.n, [dr], self.options.cond_limit,
                                          check_pivots=self.count(st.contact).may_self_stress,
                                          cache=self.factor_cache, warm=False, rtol=CORRECTION_RTOL)[0]
                dR = -(S.T @ dx)
            except SingularNetworkError:
                # a self-stress f0 (jammed network): S^T f0 = 0 makes the error component
                # along f0 unreachable by particle moves, so the box scale joins the
                # unknowns (a dilation ds changes every r by ds * r); minimum-norm solution
                A = sp.hstack([S, sp.csr_matrix(r[:, None])]).tocsr()
                sol = spla.lsqr(A, -dr, atol=1e-16, btol=1e-16, iter_lim=20 * A.shape[0])[0]
                dR, grad = sol[:-1], sol[-1] * np.eye(self.d)
            dR = dR.reshape(self.n, self.d)
            saved = (st.x.copy(), st.h.copy(), st.contact.copy(), len(st.events), st.budget.copy())
            t, k = next_collision(st.x, st.h, st.nl.pairs, st.nl.image, st.nl.sigma, st.contact, dR, grad, 1.0)
            self._move(t, dR, grad)
            if k >= 0:
                old = st.contact
                st.contact = old.copy()
                st.contact[k] = True
                self._record_events(old, st.contact)
            new_err = self.constraint_error()
            if k < 0 and new_err >= err:
                st.x, st.h, st.contact = saved[0], saved[1], saved[2]
                del st.events[saved[3]:]
                st.budget = saved[4]
                break
            err = new_err
        self._rewire(st.contact.copy())
        after = self.constraint_error()
        self.last_correction = (before, after)
        st.corrections.append((st.strain, before, after))
        return self.last_correction

    # ------------------------------------------------------ neighbour list upkeep
    def rebuild(self) -> None:
        """Wrap positions, reduce the box, rebuild the Verlet list and remap the network."""
        st = self.state
        old_pairs = st.nl.pairs
        contacts = old_pairs[st.contact]
        perm = old_pairs[st.permanent]
        box = Box(st.h).reduced
        # separations of contacts before the remap fix their new images unambiguously
        R_contact = pair_vectors(st.x, st.h, contacts, st.nl.image[st.contact])
        x = box.wrap(st.x)
        st.h = np.array(box.matrix)
        st.x = x
        st.nl.build(x, box)
        st.budget = SkinBudget.fresh(x)
        self._nl_version += 1
        pos = st.nl.index_of(contacts)
        if np.any(pos < 0):
            raise RuntimeError("a contact fell outside the neighbour list (skin too small)")
        st.nl.image[pos] = images_of(x, st.h, contacts, R_contact)
        st.contact = np.zeros(len(st.nl.i), bool)
        st.contact[pos] = True
        st.permanent = np.zeros(len(st.nl.i), bool)
        if len(perm):
            st.permanent[st.nl.index_of(perm)] = True

    def synchronize(self) -> None:
        """Synchronisation point: rebuild and recompute the solution from the state alone.

        The factorisation cache is dropped, so the solves after this point depend on
        the state only (a run resumed from a checkpoint written here repeats them
        bit for bit).
        """
        self.rebuild()
        self.factor_cache.reset()
        self.solution = self._solution_now()
        self.state.kappa = self.solution.kappa
