"""Compiled minimisers of soft spheres: the sphere model's fast paths for FIRE, enthalpy and steepest descent.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...box import Box
from ...minimize import _fire_kernels
from ...minimize.descent import DescentResult
from ...minimize.fire import (
    FireParameters,
    MinimizeResult,
    _fire_params,
    no_energy_floor,
)
from ...neighbors.verlet import NeighborList
from . import _kernels
from .potential import HARMONIC, PowerLawPotential

if TYPE_CHECKING:
    from .model import SphereModel

__all__ = ["SPATIAL_SORT_MIN_N", "SphereFire", "SphereFireFullBox", "steepest_descent"]


#: Sphere FIRE runs of at least this many spheres work on them sorted by cell (as
#: LAMMPS's ``atom_modify sort``) and return them in the caller's order: the pair and
#: particle arrays are then walked nearly in memory order
#: (measured: docs/notes/energy-models.md#constants-of-the-neighbour-search).
#: The order is fixed for the run, taken from the start (a minimisation moves spheres little), so a
#: run stays deterministic and independent of the skin; its sums differ from the
#: caller-order run's by round-off. Smaller systems fit the cache and keep the
#: caller's order, and their paths.
SPATIAL_SORT_MIN_N: int = 4096


def _cell_order(x: NDArray[np.float64], box: Box, size: float) -> NDArray[np.int64]:
    """Particles ordered by cell (cells at least ``size`` wide, last axis fastest; by index within a cell), shape (N,)."""
    from ...neighbors._cell_kernels import cell_index, sort_by_cell

    frac = box.to_fractional(x)
    frac -= np.floor(frac)
    ncell = np.maximum((box.widths // size).astype(np.int64), 1)
    _, order = sort_by_cell(cell_index(frac, np.ones(box.d), ncell), int(np.prod(ncell)))
    return order


class SphereFire:
    """FIRE steps of soft spheres in the compiled loop (:func:`jamflow.models.spheres._kernels.fire`).

    Fixed box, or an isotropic barostat (``pressure0``). Runs until convergence, the
    step budget or a neighbour-list rebuild; the state persists across calls. A barostat
    that shrinks the box until it no longer holds the spheres raises ``ValueError``.
    """

    def __init__(self, model: SphereModel, x: NDArray[np.float64], params: FireParameters,
                 pressure0: float | None, pressure_rtol: float) -> None:
        self.model = model
        # large systems run sorted by cell, on a list of their own (SPATIAL_SORT_MIN_N)
        self.order = (_cell_order(x, model.box, float(model.diameter.max())) if len(x) >= SPATIAL_SORT_MIN_N
                      else None)
        if self.order is None:
            self.nlist = model.nlist
        else:
            skin = model.nlist.requested_skin
            self.nlist = NeighborList(model.diameter[self.order], None if np.isnan(skin) else skin,
                                      model.nlist.room_share)
            x = x[self.order]
        self.builds0 = self.nlist.builds
        unit = model.time_unit
        self.barostat = pressure0 is not None
        self.pressure0 = 0.0 if pressure0 is None else float(pressure0)
        self.pressure_rtol = float(pressure_rtol)
        self.y = np.array(x, dtype=np.float64)
        self.v = np.zeros_like(self.y)
        self.q_scale = float(np.sqrt(len(self.y)) * model.diameter.mean())
        self.box_state = np.array([0.0, 0.0, 1.0])
        # the box scale at which the barostat's box stops holding the spheres (the kernel stops there)
        self.scale_min = self.nlist.smallest_scale(model.box)
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((model.box.d, model.box.d))
        # an orthogonal box lets the compiled loop rebuild the list itself
        self.lengths = np.diag(model.box.matrix).copy() if model.box.is_orthogonal else np.empty(0)
        self.inline_builds = 0

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)`` (status of :mod:`._kernels`).

        Raises
        ------
        ValueError
            The barostat shrank the box to :attr:`scale_min` or below (``COLLAPSED``): the
            target pressure is beyond what the spheres' repulsion, bounded and of finite
            range, exerts in any box that holds them.
        """
        nlist, potential, h_ref = self.nlist, self.model.potential, self.model.box
        s = self.box_state[2]
        # the reference box itself at s = 1 (fixed box): its cached widths serve every build
        current = h_ref if s == 1.0 else h_ref.scaled(s)
        if rebuild:
            nlist.build(s * self.y, current)
        else:
            nlist.update(s * self.y, current)
        affine, slack = nlist.affine_reference(current)
        status, n, *self.last, builds, i, j, image, y_build, s_build = _kernels.fire(
            self.y, self.v, self.box_state, self.fire_state, self.fparams,
            _kernels.PairList(nlist.image @ h_ref.matrix.T, nlist.i, nlist.j, nlist.sigma),
            _kernels.Potential(potential.epsilon, potential.exponent),
            _kernels.ListBuild(affine / s, nlist.reach, nlist.skin, slack), s,
            _kernels.Enthalpy(self.barostat, self.pressure0, h_ref.volume, self.q_scale, self.scale_min),
            _kernels.Stop(float(force_tol), self.pressure_rtol, int(budget), float(energy_floor)), self.force,
            self.virial, self.lengths, nlist.diameter,
        )
        if builds:
            nlist.adopt(i, j, image.astype(np.float64), s_build * y_build, h_ref.scaled(s_build), builds)
            self.inline_builds += builds
        if status == _fire_kernels.COLLAPSED:
            raise ValueError(
                f"target pressure {self.pressure0:.6g} collapsed the box: the enthalpy minimisation shrank it to "
                f"{self.box_state[2]:.3g} times its size, at or below {self.scale_min:.3g}, where it is two largest "
                f"diameters across and holds the spheres no more; their bounded, finite-range repulsion exerts no "
                f"such pressure in a box that holds them (last pressure {self.last[3]:.6g})")
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        energy, n_contacts, fmax2, pressure = self.last
        s = self.box_state[2]
        box = self.model.box
        position = s * self.y
        if self.order is not None:
            position[self.order] = position.copy()
        return MinimizeResult(
            position=position, box=box.scaled(s) if self.barostat else box, energy=float(energy),
            pressure=float(pressure), max_force=float(np.sqrt(fmax2)), n_contacts=int(n_contacts),
            steps=steps, converged=status == _fire_kernels.CONVERGED, rebuilds=self.nlist.builds - self.builds0,
            evaluations=steps + calls + self.inline_builds, below=status == _fire_kernels.BELOW,
        )


class SphereFireFullBox:
    """FIRE steps of soft spheres with the whole upper-triangular box free (:func:`._kernels.fire_stress`)."""

    def __init__(self, model: SphereModel, x: NDArray[np.float64], params: FireParameters,
                 pressure0: float, stress_rtol: float) -> None:
        d = model.box.d
        self.model = model
        self.builds0 = model.nlist.builds
        unit = model.time_unit
        self.pressure0, self.stress_rtol = float(pressure0), float(stress_rtol)
        self.y = np.array(x, dtype=np.float64)
        self.v = np.zeros_like(self.y)
        self.A = np.eye(d)
        self.vA = np.zeros((d, d))
        self.q_scale = float(np.sqrt(len(self.y)) * model.diameter.mean())
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((d, d))

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        no_energy_floor(self, energy_floor)
        nlist, potential, h_ref = self.model.nlist, self.model.potential, self.model.box
        A = self.A
        current = Box(A @ h_ref.matrix)
        if rebuild:
            nlist.build(self.y @ A.T, current)
        else:
            nlist.update(self.y @ A.T, current)
        offset = nlist.image @ h_ref.matrix.T
        affine, slack = nlist.affine_reference(current)
        A_inv = np.linalg.inv(A)
        status, n, *self.last = _kernels.fire_stress(
            self.y, self.v, A, self.vA, self.fire_state, self.fparams,
            _kernels.PairList(offset, nlist.i, nlist.j, nlist.sigma),
            _kernels.Potential(potential.epsilon, potential.exponent),
            _kernels.ListBuild(affine @ A_inv.T, nlist.reach, nlist.skin, slack), A_inv,
            _kernels.Enthalpy(True, self.pressure0, h_ref.volume, self.q_scale, 0.0),
            _kernels.Stop(float(force_tol), self.stress_rtol, int(budget), 0.0), self.force, self.virial,
        )
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        energy, n_contacts, fmax2, _ = self.last
        d = self.model.box.d
        final = Box(np.triu(self.A) @ self.model.box.matrix)
        return MinimizeResult(
            position=self.y @ self.A.T, box=final, energy=float(energy),
            pressure=float(np.trace(self.virial) / (d * final.volume)), max_force=float(np.sqrt(fmax2)),
            n_contacts=int(n_contacts), steps=steps, converged=status == _fire_kernels.CONVERGED,
            rebuilds=self.model.nlist.builds - self.builds0, evaluations=steps + calls,
        )


def steepest_descent(
    x: ArrayLike,
    box: Box,
    diameter: ArrayLike,
    potential: PowerLawPotential = HARMONIC,
    dt: float = 0.1,
    force_tol: float = 1e-9,
    max_steps: int = 10_000_000,
    nlist: NeighborList | None = None,
    record: int = 0,
) -> DescentResult:
    """Overdamped relaxation ``dx/dt = -xi_0 grad U`` with a fixed Euler step.

    Lerner, During & Wyart Eq. 31 with ``xi_0 = 1``: ``x += dt F``. Stable for ``dt``
    below ``2 / lambda_max`` of the Hessian (``dt = 0.1`` in units of
    ``sigma^2 / (xi_0 epsilon)`` for the harmonic potential of unit diameters).

    Parameters
    ----------
    dt : float
        Step [time, in units of length^2 / (xi_0 epsilon)]; used as given (no scaling).
    force_tol : float
        Stop when ``max_i |grad_i U| <= force_tol`` [epsilon / length].
    record : int
        Number of leading steps whose energy is recorded (0: none).
    """
    y = np.array(x, dtype=np.float64)
    diameter = np.asarray(diameter, dtype=np.float64)
    if nlist is None:
        nlist = NeighborList(diameter)
    builds0 = nlist.builds
    force = np.zeros_like(y)
    virial = np.zeros((box.d, box.d))
    energies = np.full(max(record, 1), np.nan)
    traces = []
    steps = 0
    calls = 0
    status = _fire_kernels.MAX_STEPS
    while True:
        if status == _fire_kernels.REBUILD:
            nlist.build(y, box)
        else:
            nlist.update(y, box)
        affine, slack = nlist.affine_reference(box)
        buf = np.full(max(record - steps, 1), np.nan)
        status, n, energy, n_contacts, fmax2 = _kernels.steepest_descent(
            y, _kernels.PairList(nlist.offsets(box), nlist.i, nlist.j, nlist.sigma),
            _kernels.Potential(potential.epsilon, potential.exponent),
            _kernels.ListBuild(affine, nlist.reach, nlist.skin, slack), float(dt),
            _kernels.Stop(float(force_tol), 0.0, int(max_steps - steps), 0.0), force, virial, buf,
        )
        if record > steps:
            traces.append(buf[: min(n + 1, record - steps)] if status != _fire_kernels.REBUILD else buf[:n])
        steps += n
        calls += 1
        if status != _fire_kernels.REBUILD or steps >= max_steps:
            break
    if traces:
        energies = np.concatenate(traces)
    pressure = float(np.trace(virial) / (box.d * box.volume))
    res = MinimizeResult(y, box, float(energy), pressure, float(np.sqrt(fmax2)), int(n_contacts),
                         steps, status == _fire_kernels.CONVERGED, nlist.builds - builds0, steps + calls)
    return DescentResult(res, energies if record else np.empty(0))
