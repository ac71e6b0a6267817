"""Lubachevsky–Stillinger (LS) compression: event-driven hard spheres with growing diameters.

CALiPPSO paper (Artiaco et al.), Sec. III and Appendix C: hard spheres move ballistically
and collide elastically while every diameter grows linearly in time; the velocities are
rescaled to the temperature ``1/beta`` at regular intervals and the reduced pressure
``p = beta P V / N`` is measured from the collision virial. The run stops when ``p``
reaches each target of an increasing list (one snapshot per target from the *same*
sample), a packing fraction, or a budget of collisions or time. The paper's two-stage
protocol is a fast growth ``kappa0 = 5e-3`` until ``p = 500`` followed by the slow rate
``kappa`` up to the targets.

Units
-----
Lengths are those of the input packing (the side of the unit box for packings from
:func:`jamflow.protocols.initial.random_packing` and the CALiPPSO/LS data, as in the paper's
LS code), masses are 1 and ``k_B T = 1 / beta``; the time unit follows.

Growth law
----------
``sigma_i(t) = a_i s(t)`` with ``a_i = D_i / <D>`` the diameters of the input relative
to their mean and ``s(t) = <D>(t)`` growing linearly, ``ds/dt = kappa``: the mean
diameter grows at the paper's uniform rate ``sigma_dot = kappa`` (exactly the paper's law
for monodisperse systems). Polydisperse diameters grow *proportionally*
(``sigma_dot_i = kappa a_i``), as in the LS code of Skoge et al. used by the paper,
so the size distribution (e.g. the ratio 1:1.4 of a binary mixture) is preserved and
the packing fraction is ``phi(t) = phi(0) (s(t) / s(0))^d``. (That LS code grows
*radii* at its parameter ``growthrate``; if a quoted rate is that parameter, the
diameter rate here is twice it.)

Dynamics
--------
Exact collision times of growing spheres: ``|r + u t|^2 = (sigma + g t)^2`` with
``g = (a_i + a_j) kappa / 2`` is solved in cancellation-free form (see
:func:`jamflow.protocols._ls_kernels.collision_time`). At contact the impulse ``J = g - u_n``
along the unit vector ``n`` reverses the rate of change of the gap,
``u_n - g -> -(u_n - g)`` (``u_n`` the normal relative velocity): the pair separates
faster than it grows, the kinetic energy rises by ``J g``, and momentum is conserved.
Events use cell lists (cells at least one largest diameter wide, rebuilt when the
diameters outgrow them), per-particle predictions with collision counters to discard
outdated ones, and a binary tournament tree; positions are updated lazily. Where the
3^d neighbour cells hold many more particles than the contact shell (``NL_MIN_GAIN``;
in practice in every d >= 2, most of all in d >= 4 where a box of N = 1024 is only a
few diameters wide), the partners come instead from Verlet neighbour lists with a skin
of ``NL_SKIN`` mean diameters, rebuilt globally at the first time any particle may
have moved (plus grown) by half the skin; see :mod:`jamflow.protocols._ls_kernels` for the
guarantee that no collision is missed.

Pressure
--------
Over a measuring window of ``window`` collisions (default ``WINDOW_COLLISIONS_PER_PARTICLE
N``) lasting ``Delta t``, the virial theorem gives

    p = beta P V / N = 1 + sum_c r_c J_c / (2 int K dt)

with ``J_c`` the impulse and ``r_c`` the centre distance of collision ``c`` (growth part
of the impulse included) and ``K`` the kinetic energy, i.e. ``k_B T`` is the kinetic
temperature ``2 K / (d N)`` time-averaged over the window. At the end of each window the
velocities are rescaled to ``K = d N / (2 beta)`` and the record (time, mid-window
packing fraction, p, collisions) is appended to the equation of state.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np
import xarray as xr

from ..io import new_dataset_attrs
from ..stages import require
from ..state.packing import Packing, sphere_volume
from ..tolerances import OVERLAP_TOL
from . import _ls_kernels as _k

__all__ = [
    "CELL_SLACK",
    "DEFAULT_BETA",
    "DEFAULT_FAST_GROWTH_RATE",
    "DEFAULT_FAST_UNTIL",
    "NL_MIN_GAIN",
    "NL_SKIN",
    "WINDOW_COLLISIONS_PER_PARTICLE",
    "MAX_PRESSURE",
    "LSResult",
    "compress",
]

#: Inverse temperature of the paper's LS runs.
DEFAULT_BETA: float = 10.0
#: Growth rate of the fast first stage (paper, Sec. III step 2).
DEFAULT_FAST_GROWTH_RATE: float = 5e-3
#: Reduced pressure ending the fast stage (paper, Sec. III step 2).
DEFAULT_FAST_UNTIL: float = 500.0
#: Collisions per particle in one pressure window (and between velocity rescalings).
WINDOW_COLLISIONS_PER_PARTICLE: int = 10
#: Cells are built this factor wider than the largest diameter, so that the grid is
#: rebuilt only after the diameters have grown by this factor.
CELL_SLACK: float = 1.02
#: Skin delta of the Verlet neighbour lists in mean diameters at the build: a pair is
#: listed when its centre distance is below its contact distance plus delta
#: (measured: docs/notes/ls-constants.md#nl_skin).
NL_SKIN: float = 0.2
#: Neighbour lists replace the cell scan when the neighbour cells hold on average at
#: least this many times more particles than a list would (estimated from the mean
#: diameter and the density) (measured: docs/notes/ls-constants.md#nl_min_gain).
NL_MIN_GAIN: float = 2.0
#: Reduced pressure at which a run stops as jammed (stop reason ``"max_pressure"``)
#: when its targets lie beyond: the relative gaps of the cages, ~d/p, are then ~1e-14,
#: a hundred times the float64 resolution of the centres (~1e-16 of the box), and the
#: pressure no longer rises (measured: docs/notes/ls-constants.md#max_pressure).
MAX_PRESSURE: float = 1e14


@dataclass
class LSResult:
    """Outcome of :func:`compress`.

    Attributes
    ----------
    snapshots : list of Packing
        One per reached pressure target, in the order of the targets, then one at the
        packing-fraction target if the run stopped there. Any stop ends the run: all
        pressure targets reached, ``phi_target``, ``max_collisions`` or ``max_time``.
        Each has ``pressure`` set and attrs ``p, phi, kappa, collisions, time,
        cpu_time``, ``target_kind`` (``"p"`` or ``"phi"``) and ``target``; protocol
        ``<input>>ls``.
    eos : xarray.Dataset
        Equation of state along the run, dim ``record`` (one per window): ``time``,
        ``packing_fraction``, ``pressure``, ``collisions``, ``growth_rate``,
        ``temperature`` (kinetic, before rescaling).
    final : Packing
        State at the end of the run.
    stop_reason : str
        ``"p_targets"``, ``"phi_target"``, ``"max_collisions"``, ``"max_time"``, or a
        target found impossible: ``"max_pressure"`` (jammed first: ``p`` reached
        ``max_pressure``) or ``"box_width"`` (a contact distance reached half the
        smallest box width, where a sphere would touch two images of a neighbour: too
        few spheres to jam in this box).
    collisions : int
    cpu_time : float
        Process CPU time of the run [s].
    collisions_per_second : float
        Collisions per CPU-second.
    """

    snapshots: list[Packing]
    eos: xr.Dataset
    final: Packing
    stop_reason: str
    collisions: int
    cpu_time: float
    collisions_per_second: float


class _State:
    """Arrays of the event-driven simulation (see :mod:`jamflow.protocols._ls_kernels`),
    handed to the kernels as its records; the scalars in the :data:`~jamflow.protocols._ls_kernels.CLOCK`
    record ``clock``, read through the properties ``t``, ``s_w``, ``rate``, ``kinetic``,
    ``kinetic_integral`` and ``virial``."""

    def __init__(self, packing: Packing, beta: float, rng: np.random.Generator,
                 neighbor_list: bool | None = None) -> None:
        n, d = packing.n, packing.d
        self.n, self.d = n, d
        self.L = packing.box.lengths
        self.invL = 1.0 / self.L
        self.x = packing.box.wrap(packing.position)
        mean_D = float(packing.diameter.mean())
        self.a = packing.diameter / mean_D
        self.phi_unit = float(sphere_volume(d, self.a).sum() / packing.box.volume)
        v = rng.standard_normal((n, d))
        v -= v.mean(axis=0)
        self.v = v
        self.K_target = 0.5 * d * n / beta
        self.v *= math.sqrt(self.K_target / _k.kinetic_energy(self.v))
        self.tl = np.zeros(n)
        self.clock = np.zeros(1, dtype=_k.CLOCK)
        self.clock["s_w"] = mean_D
        self.clock["kinetic"] = _k.kinetic_energy(self.v)
        self.count = np.zeros(n, dtype=np.int64)
        self.coll_time = np.empty(n)
        self.coll_partner = np.empty(n, dtype=np.int64)
        self.coll_pcount = np.zeros(n, dtype=np.int64)
        self.cross_time = np.empty(n)
        self.cross_dim = np.empty(n, dtype=np.int64)
        self.ev_time = np.empty(n + 1)
        self.M = 1 << max(1, (n - 1).bit_length())
        self.tree = np.empty(2 * self.M, dtype=np.int64)
        self.cc = np.empty((n, d), dtype=np.int64)
        self.cell = np.empty(n, dtype=np.int64)
        self.nxt = np.empty(n, dtype=np.int64)
        self.prv = np.empty(n, dtype=np.int64)
        self.t_rebuild = math.inf
        self.window_coll = 0
        # neighbour lists: None chooses by NL_MIN_GAIN at every rebuild
        self.neighbor_list = neighbor_list
        self.use_nl = False
        self.nl_start = np.zeros(n + 1, dtype=np.int64)
        self.nl_idx = np.empty(0, dtype=np.int64)
        self.xb = np.zeros((n, d))
        self.list_build = np.zeros(1, dtype=_k.LIST_BUILD)
        self.list_builds = 0

    # the clock ------------------------------------------------------------------------
    @property
    def t(self) -> float:
        """Time since the start of the window."""
        return float(self.clock["t"][0])

    @property
    def s_w(self) -> float:
        """Mean diameter at the start of the window."""
        return float(self.clock["s_w"][0])

    @property
    def rate(self) -> float:
        """Growth rate of the mean diameter, ``ds/dt``."""
        return float(self.clock["rate"][0])

    @property
    def kinetic(self) -> float:
        """Kinetic energy (unit masses)."""
        return float(self.clock["kinetic"][0])

    @property
    def kinetic_integral(self) -> float:
        """Time integral of the kinetic energy over the window."""
        return float(self.clock["kinetic_integral"][0])

    @property
    def virial(self) -> float:
        """Sum of ``r_ij J`` over the window's collisions."""
        return float(self.clock["virial"][0])

    # scale and packing fraction --------------------------------------------------
    def scale(self, t: float | None = None) -> float:
        """Mean diameter s at window time t (default: now)."""
        t = self.t if t is None else t
        return float(self.s_w + self.rate * t)

    def phi(self, t: float | None = None) -> float:
        return self.phi_unit * self.scale(t) ** self.d

    # the kernels' records -----------------------------------------------------------
    def _records(self) -> tuple[_k.Spheres, _k.PeriodicBox, _k.Cells, _k.Events, _k.Lists]:
        """The arrays as the kernels take them."""
        return (_k.Spheres(self.x, self.v, self.tl, self.a), _k.PeriodicBox(self.L, self.invL), self._cells(),
                _k.Events(self.count, self.coll_time, self.coll_partner, self.coll_pcount, self.cross_time,
                          self.cross_dim, self.ev_time, self.tree, self.M),
                _k.Lists(self.use_nl, self.nl_start, self.nl_idx, self.xb, self.list_build))

    def _cells(self) -> _k.Cells:
        return _k.Cells(self.w, self.cc, self.cell, self.ncell, self.stride, self.offs, self.head, self.nxt,
                        self.prv)

    # cells and events --------------------------------------------------------------
    def _lists_pay(self, ncell: np.ndarray, skin: float) -> bool:
        """Whether the neighbour cells hold ``NL_MIN_GAIN`` times more than a list would."""
        if self.neighbor_list is not None:
            return self.neighbor_list
        in_stencil = self.n * float(np.prod(np.minimum(ncell, 3) / ncell))
        in_list = (self.n - 1) * float(sphere_volume(self.d, 2.0 * (self.scale() + skin))
                                       / np.prod(self.L))
        return in_stencil >= NL_MIN_GAIN * in_list

    def rebuild(self) -> None:
        """Sync positions, wrap them, size the cell grid for the current diameters.

        Chooses cells or neighbour lists (``neighbor_list``, else :data:`NL_MIN_GAIN`);
        lists are built with the cells at least ``max sigma + delta`` wide, and all
        events are predicted again.
        """
        _k.sync_all(self.t, self.x, self.v, self.tl)
        self.x -= self.L * np.floor(self.x * self.invL)
        self.x[self.x >= self.L] = 0.0
        sig_max = float(self.a.max()) * self.scale()
        skin = NL_SKIN * self.scale()
        ncell = np.maximum(np.floor(self.L / (sig_max * CELL_SLACK)).astype(np.int64), 1)
        self.use_nl = self._lists_pay(ncell, skin)
        if self.use_nl:
            ncell = np.maximum(np.floor(self.L / (sig_max + skin)).astype(np.int64), 1)
        self.ncell = ncell
        self.w = self.L / ncell
        self.stride = np.cumprod(np.concatenate([[1], ncell[:-1]])).astype(np.int64)
        self.head = np.empty(int(np.prod(ncell)), dtype=np.int64)
        per_axis = [np.array([-1, 0, 1]) if m >= 3 else np.arange(m) for m in ncell]
        grids = np.meshgrid(*per_axis, indexing="ij")
        self.offs = np.stack([g.ravel() for g in grids], axis=1).astype(np.int64)
        _k.build_cells(self.x, self.L, self._cells())
        constrained = ncell >= 3
        if self.use_nl:
            self.nl_start, self.nl_idx = _k.build_neighbor_lists(
                self.x, self.a, self.L, self.invL, self.scale(), skin, self.cell, self.ncell,
                self.stride, self.offs)
            self.xb[:] = self.x
            self.list_build[0] = (self.t, 0.5 * skin, 0.5 * self.rate * float(self.a.max()))
            self.list_builds += 1
            self.t_rebuild = math.inf
        elif np.any(constrained) and self.rate > 0.0:
            w_min = float(self.w[constrained].min())
            self.t_rebuild = self.t + (w_min / float(self.a.max()) - self.scale()) / self.rate
        else:
            self.t_rebuild = math.inf
        self.predict()

    def predict(self) -> None:
        _k.init_events(self.t, self.scale(), self.rate, *self._records())

    def run(self, max_coll: int, t_limit: float) -> tuple[int, int]:
        return _k.run_events(max_coll, t_limit, self.clock, *self._records())

    def set_rate(self, rate: float) -> None:
        self.clock["rate"] = rate
        self.rebuild()

    def new_window(self, rescale: bool) -> None:
        """Sync everything, restart the window clock at 0, rescale velocities."""
        t = self.t
        _k.sync_all(t, self.x, self.v, self.tl)
        self.clock["s_w"] = self.scale(t)
        self.tl[:] = 0.0
        self.clock["t"] = 0.0
        self.t_rebuild -= t
        self.list_build["t_build"] -= t
        if rescale:
            self.v *= math.sqrt(self.K_target / self.kinetic)
            self.clock["kinetic"] = _k.kinetic_energy(self.v)
        self.clock["kinetic_integral"] = 0.0
        self.clock["virial"] = 0.0
        self.predict()

    def packing(self, template: Packing, **attrs: Any) -> Packing:
        """The current configuration as a packing (centres wrapped into the box)."""
        dt = self.t - self.tl
        x = self.x + self.v * dt[:, None]
        x -= self.L * np.floor(x * self.invL)
        x[x >= self.L] = 0.0
        return Packing(
            position=x,
            diameter=self.a * self.scale(),
            box=template.box,
            pressure=attrs.get("p"),
            protocol=f"{template.protocol}>ls",
            seed=attrs.get("seed", template.seed),
            parameters=attrs.pop("parameters", {}),
            attrs={k: v for k, v in attrs.items() if k != "seed"},
        )


def _check_inputs(packing: Packing, growth_rate: float, p_targets: Sequence[float],
                  phi_target: float | None, max_collisions: int | None, max_time: float | None,
                  beta: float, fast_growth_rate: float | None, fast_until: float,
                  max_pressure: float | None) -> list[float]:
    if packing.d < 2:
        raise ValueError(f"LS needs d >= 2, got d={packing.d}")
    if packing.n < 2:
        raise ValueError(f"LS needs at least 2 spheres (one alone never collides), got N = {packing.n}")
    if not packing.box.is_orthogonal:
        raise ValueError("LS runs in orthogonal periodic boxes only; the input box is sheared "
                         f"(strain {packing.box.shear_strain:g})")
    if not (math.isfinite(growth_rate) and growth_rate >= 0.0):
        raise ValueError(f"growth rate kappa must be finite and >= 0, got {growth_rate}")
    if fast_growth_rate is not None and not (math.isfinite(fast_growth_rate) and fast_growth_rate >= 0.0):
        raise ValueError(f"fast growth rate must be finite and >= 0 (or None to skip), got {fast_growth_rate}")
    if not (math.isfinite(beta) and beta > 0.0):
        raise ValueError(f"beta must be positive and finite, got {beta}")
    if not (math.isfinite(fast_until) and fast_until > 0.0):
        raise ValueError(f"fast_until must be positive, got {fast_until}")
    targets = [float(p) for p in p_targets]
    if any(not (math.isfinite(p) and p > 0.0) for p in targets):
        raise ValueError(f"pressure targets must be positive and finite, got {targets}")
    if any(b <= a for a, b in pairwise(targets)):
        raise ValueError(f"pressure targets must be strictly increasing, got {targets}")
    if max_pressure is not None and targets and targets[-1] >= max_pressure:
        raise ValueError(f"pressure target {targets[-1]:g} is not below the largest LS pressure "
                         f"{max_pressure:g} (float64 resolution of the cages)")
    if phi_target is not None:
        if not 0.0 < phi_target < 1.0:
            raise ValueError(f"phi_target must lie in (0, 1), got {phi_target}")
        if phi_target <= packing.packing_fraction:
            raise ValueError(f"phi_target {phi_target} is not above the input packing fraction "
                             f"{packing.packing_fraction:.6g}")
    if max_collisions is not None and max_collisions < 1:
        raise ValueError(f"max_collisions must be >= 1, got {max_collisions}")
    if max_time is not None and not max_time > 0.0:
        raise ValueError(f"max_time must be > 0, got {max_time}")
    if not targets and phi_target is None and max_collisions is None and max_time is None:
        raise ValueError("give at least one stop: p_targets, phi_target, max_collisions or max_time")
    if growth_rate == 0.0 and max_collisions is None and max_time is None:
        raise ValueError("with growth rate 0 the pressure and density never rise: give max_collisions or max_time")
    try:
        packing.validate(OVERLAP_TOL)
    except ValueError as exc:
        raise ValueError(f"LS input: {exc}") from exc
    return targets


def compress(
    packing: Packing,
    growth_rate: float,
    p_targets: Sequence[float] = (),
    *,
    phi_target: float | None = None,
    max_collisions: int | None = None,
    max_time: float | None = None,
    beta: float = DEFAULT_BETA,
    fast_growth_rate: float | None = DEFAULT_FAST_GROWTH_RATE,
    fast_until: float = DEFAULT_FAST_UNTIL,
    seed: int = 0,
    progress: Callable[[dict[str, float]], None] | None = None,
    window: int | None = None,
    neighbor_list: bool | None = None,
    max_pressure: float | None = MAX_PRESSURE,
) -> LSResult:
    """Compress a hard-sphere packing by LS event-driven dynamics with growing spheres.

    Parameters
    ----------
    packing : Packing
        Non-overlapping start (relative overlaps up to ``OVERLAP_TOL``) in an orthogonal
        periodic box, any dimension >= 2, any diameters.
    growth_rate : float
        Slow growth rate ``kappa`` of the mean diameter [length/time] (see the module
        docstring for units); 0 runs plain hard-sphere dynamics.
    p_targets : sequence of float
        Strictly increasing reduced pressures; the snapshot of a target is the
        configuration at the end of the first window whose mean pressure is ``>= target``
        (several targets may share a window).
    phi_target : float, optional
        Stop (with a snapshot) when the packing fraction reaches this value (exactly).
    max_collisions : int, optional
        Stop after exactly this many collisions (the last window may be shorter).
    max_time : float, optional
        Stop at this simulated time [time unit].
    beta : float
        Inverse temperature ``1 / k_B T`` set at every rescaling.
    fast_growth_rate : float or None
        Growth rate of the first stage, run until ``p >= fast_until``; ``None`` or 0
        skips it (paper: skippable in d >= 4).
    fast_until : float
        Reduced pressure ending the fast stage.
    seed : int
        Seed of the initial Maxwell–Boltzmann velocities.
    progress : callable, optional
        Called after every window with a dict ``collisions, time, phi, p, kappa``.
    window : int, optional
        Collisions per pressure window; default ``WINDOW_COLLISIONS_PER_PARTICLE * N``.
    neighbor_list : bool, optional
        Force Verlet neighbour lists (True) or the cell scan (False); by default lists
        are used when the neighbour cells hold ``NL_MIN_GAIN`` times more particles.
        Same dynamics either way (up to round-off).
    max_pressure : float or None
        Stop as jammed when a window's pressure reaches this (stop reason
        ``"max_pressure"``); pressure targets must lie below it. ``None``: no limit.
        A contact distance reaching half the smallest box width always stops the run
        (stop reason ``"box_width"``).

    Returns
    -------
    LSResult
    """
    require("ls", packing.body_kind)
    targets = _check_inputs(packing, growth_rate, p_targets, phi_target, max_collisions, max_time,
                            beta, fast_growth_rate, fast_until, max_pressure)
    n = packing.n
    window = WINDOW_COLLISIONS_PER_PARTICLE * n if window is None else int(window)
    if window < 1:
        raise ValueError(f"window must be >= 1 collision, got {window}")
    parameters = {
        "growth_rate": growth_rate, "p_targets": targets, "phi_target": phi_target,
        "max_collisions": max_collisions, "max_time": max_time, "beta": beta,
        "fast_growth_rate": fast_growth_rate, "fast_until": fast_until, "seed": seed,
        "window": window, "growth_law": "proportional: sigma_i = a_i s(t), ds/dt = kappa (mean diameter)",
        "neighbor_list": "auto" if neighbor_list is None else bool(neighbor_list),
        "max_pressure": max_pressure,
    }
    state = _State(packing, beta, np.random.default_rng(seed), neighbor_list)
    fast = fast_growth_rate is not None and fast_growth_rate > 0.0
    state.clock["rate"] = fast_growth_rate if fast else growth_rate
    state.rebuild()
    run = _Run(state, packing, parameters, _Stops(targets, phi_target, max_collisions, max_time, max_pressure,
                                                   window, packing), progress)
    while True:
        t_limit, limit_kind = run.time_limit()
        status, ncoll = state.run(run.todo(), t_limit)
        run.collisions += ncoll
        state.window_coll += ncoll
        if status == _k.LIST_EXPIRED or (status == _k.TIME_LIMIT and limit_kind == "rebuild"):
            state.rebuild()
            continue
        p = run.measure()
        if run.stop(p, status, limit_kind):
            break
        switch = fast and state.rate == fast_growth_rate and p >= fast_until
        run.elapsed += state.t
        state.window_coll = 0
        state.new_window(rescale=True)
        if switch:
            state.set_rate(growth_rate)
    cpu = time.process_time() - run.cpu0
    final = state.packing(packing, p=run.last_p, phi=state.phi(), kappa=state.rate,
                          collisions=run.collisions, time=run.elapsed + state.t, cpu_time=cpu,
                          parameters=parameters)
    rate = run.collisions / cpu if cpu > 0 else math.nan
    eos = _eos_dataset(run.records, new_dataset_attrs(
        "LS equation of state", parameters, N=n, d=packing.d, beta=beta, kappa=growth_rate,
        stop_reason=run.stop_reason, collisions=run.collisions, cpu_time=cpu, collisions_per_second=rate))
    return LSResult(snapshots=run.snapshots, eos=eos, final=final, stop_reason=run.stop_reason,
                    collisions=run.collisions, cpu_time=cpu, collisions_per_second=rate)


@dataclass(frozen=True)
class _Stops:
    """When a run stops: pressure targets (increasing), a packing fraction, a budget of
    collisions or simulated time, the largest pressure; ``window`` collisions per
    pressure window; the input packing fixes the box."""

    p_targets: list[float]
    phi_target: float | None
    max_collisions: int | None
    max_time: float | None
    max_pressure: float | None
    window: int
    packing: Packing

    @property
    def half_width(self) -> float:
        """Largest contact distance [length]: a packing's diameters stay below half the
        smallest box width (Packing); a relative 1e-9 short of it, far above the
        round-off of s(t)."""
        return 0.5 * float(self.packing.box.widths.min()) * (1.0 - 1e-9)


class _Run:
    """The counters of one :func:`compress` run: simulated time before the window,
    collisions, the equation-of-state records, the snapshots and the stop reason."""

    def __init__(self, state: _State, packing: Packing, parameters: dict[str, Any], stops: _Stops,
                 progress: Callable[[dict[str, float]], None] | None) -> None:
        self.state, self.packing, self.parameters, self.stops, self.progress = state, packing, parameters, stops, progress
        self.half_width = stops.half_width
        self.a_max = float(state.a.max())
        self.cpu0 = time.process_time()
        self.elapsed = 0.0  # simulated time before the current window
        self.collisions = 0
        self.records: dict[str, list[float]] = {k: [] for k in
                                                ("time", "packing_fraction", "pressure", "collisions",
                                                 "growth_rate", "temperature")}
        self.snapshots: list[Packing] = []
        self.next_target = 0
        self.stop_reason = ""
        self.last_p = math.nan

    def time_limit(self) -> tuple[float, str]:
        """The next window time at which the kernel must stop, and why: a rebuild of the
        cells, ``max_time``, ``phi_target``, or the box width."""
        state, stops = self.state, self.stops
        t_limit = state.t_rebuild
        limit_kind = "rebuild"
        if stops.max_time is not None and stops.max_time - self.elapsed < t_limit:
            t_limit, limit_kind = stops.max_time - self.elapsed, "max_time"
        if stops.phi_target is not None and state.rate > 0.0:
            t_phi = ((stops.phi_target / state.phi_unit) ** (1.0 / state.d) - state.s_w) / state.rate
            if t_phi < t_limit:
                t_limit, limit_kind = t_phi, "phi_target"
        if state.rate > 0.0:
            # the largest contact distance a_max s reaches half the smallest box width
            t_box = (self.half_width / self.a_max - state.s_w) / state.rate
            if t_box < t_limit:
                t_limit, limit_kind = t_box, "box_width"
        return t_limit, limit_kind

    def todo(self) -> int:
        """Collisions left in the window (and in the budget)."""
        todo = self.stops.window - self.state.window_coll
        if self.stops.max_collisions is not None:
            todo = min(todo, self.stops.max_collisions - self.collisions)
        return todo

    def measure(self) -> float:
        """The window's pressure (NaN without a collision), recorded with the state."""
        state = self.state
        d, n = state.d, state.n
        dt = state.t
        if dt > 0.0 and state.kinetic_integral > 0.0 and state.window_coll > 0:
            p = 1.0 + state.virial / (2.0 * state.kinetic_integral)
            temperature = 2.0 * state.kinetic_integral / dt / (d * n)
            self.records["time"].append(self.elapsed + 0.5 * dt)
            self.records["packing_fraction"].append(state.phi(0.5 * dt))
            self.records["pressure"].append(p)
            self.records["collisions"].append(self.collisions)
            self.records["growth_rate"].append(state.rate)
            self.records["temperature"].append(temperature)
            self.last_p = p
        else:
            p = math.nan
        if self.progress is not None:
            self.progress({"collisions": self.collisions, "time": self.elapsed + dt, "phi": state.phi(),
                           "p": self.last_p, "kappa": state.rate})
        return p

    def snapshot(self, p: float, kind: str, target: float) -> Packing:
        snap = self.state.packing(
            self.packing, p=p, phi=self.state.phi(), kappa=self.state.rate, collisions=self.collisions,
            target_kind=kind, target=target,
            time=self.elapsed + self.state.t, cpu_time=time.process_time() - self.cpu0,
            parameters=self.parameters,
        )
        snap.validate(OVERLAP_TOL)
        return snap

    def stop(self, p: float, status: int, limit_kind: str) -> bool:
        """Snapshots of the targets reached; whether the run stops (``stop_reason`` says why)."""
        stops = self.stops
        targets = stops.p_targets
        while self.next_target < len(targets) and p >= targets[self.next_target]:
            self.snapshots.append(self.snapshot(p, "p", targets[self.next_target]))
            self.next_target += 1
        if targets and self.next_target == len(targets):
            self.stop_reason = "p_targets"
        elif status == _k.TIME_LIMIT and limit_kind == "phi_target":
            self.snapshots.append(self.snapshot(self.last_p, "phi", float(stops.phi_target)))
            self.stop_reason = "phi_target"
        elif status == _k.TIME_LIMIT and limit_kind == "max_time":
            self.stop_reason = "max_time"
        elif stops.max_collisions is not None and self.collisions >= stops.max_collisions:
            self.stop_reason = "max_collisions"
        elif status == _k.TIME_LIMIT and limit_kind == "box_width":
            self.stop_reason = "box_width"
        elif stops.max_pressure is not None and p >= stops.max_pressure:
            self.stop_reason = "max_pressure"
        return bool(self.stop_reason)


def _eos_dataset(records: dict[str, list[float]], attrs: dict[str, Any]) -> xr.Dataset:
    """The equation of state along the run, one record per pressure window."""
    return xr.Dataset(
        {
            "time": ("record", np.array(records["time"]),
                     {"units": "1", "long_name": "simulated time at the middle of the window",
                      "comment": "unit: length unit * sqrt(mass / (k_B T)) with mass 1, k_B T = 1/beta"}),
            "packing_fraction": ("record", np.array(records["packing_fraction"]),
                                 {"units": "1", "long_name": "packing fraction at the middle of the window"}),
            "pressure": ("record", np.array(records["pressure"]),
                         {"units": "1", "long_name": "reduced pressure beta P V / N from the collision virial"}),
            "collisions": ("record", np.array(records["collisions"], dtype=np.int64),
                           {"units": "1", "long_name": "collisions since the start at the end of the window"}),
            "growth_rate": ("record", np.array(records["growth_rate"]),
                            {"units": "1", "long_name": "growth rate kappa of the mean diameter"}),
            "temperature": ("record", np.array(records["temperature"]),
                            {"units": "1", "long_name": "time-averaged kinetic temperature 2K/(dN) before rescaling"}),
        },
        attrs=attrs,
    )
