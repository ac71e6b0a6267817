"""Compiled FIRE of shaped bodies: the shape model's fast path (fixed box, or an isotropic barostat)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ...minimize import _fire_kernels
from ...minimize.fire import (
    FireParameters,
    MinimizeResult,
    _fire_params,
    no_energy_floor,
)
from ...minimize.model import pressure_of
from . import _fire_kernels as _loop
from ._kernels import FAMILY_CODES

if TYPE_CHECKING:
    from .model import ShapeModel

__all__ = ["FAMILY_CODES", "ShapeFire"]



class ShapeFire:
    """FIRE steps of shaped bodies in one compiled loop (:func:`._fire_kernels.shape_fire`).

    The steps of the flat-vector FIRE (:class:`~jamflow.minimize.fire._ModelFire`) on
    the model, in its mass metric, with the family's pair kernel and, for ellipses,
    warm-started Perram–Wertheim solves; frozen orientations (``model.rotations``
    false) lose their torques as in :meth:`ShapeModel.project`. Fixed box, or an isotropic barostat
    (``pressure0``: enthalpy ``U + P0 V``, centres scaled with the box, shapes not;
    the box mode's scale ``q_s = sqrt(N) <D_b>`` as for spheres). The loop rebuilds
    its bounding-circle list itself in an orthogonal box and returns here for the
    build otherwise; the state persists across calls.
    """

    def __init__(self, model: ShapeModel, q: NDArray[np.float64], params: FireParameters,
                 pressure0: float | None, pressure_rtol: float) -> None:
        n = model.n
        self.model = model
        self.builds0 = model.nlist.builds
        self.y = np.ascontiguousarray(np.column_stack([q[: 2 * n].reshape(n, 2), q[2 * n:]]))
        self.v = np.zeros_like(self.y)
        self.inv_mass = np.ascontiguousarray(np.column_stack([model.inverse_mass[: 2 * n].reshape(n, 2),
                                                              model.inverse_mass[2 * n:]]))
        unit = model.time_unit
        self.barostat = pressure0 is not None
        self.pressure0 = 0.0 if pressure0 is None else float(pressure0)
        self.pressure_rtol = float(pressure_rtol)
        self.box_state = np.array([0.0, 0.0, 1.0])
        self.fire_state = np.array([params.dt * unit, params.alpha0, 0.0, 0.0])
        self.fparams = _fire_params(params, unit)
        self.q_scale = float(np.sqrt(n) * model.bounding_diameter.mean())
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((2, 2))
        self.lengths = np.diag(model.box.matrix).copy() if model.box.is_orthogonal else np.empty(0)
        self.bound = 0.5 * model.bounding_diameter
        self.family = FAMILY_CODES[model.family]
        self.pairs: tuple[NDArray, ...] | None = None
        self.y_build = np.empty((n, 2))
        self.s_build = 1.0
        self.inline_builds = 0

    def _build(self) -> None:
        """The bounding-circle list at the present centres (the model's list, reference offsets)."""
        m, s = self.model, float(self.box_state[2])
        m.nlist.build(s * self.y[:, :2], m.box if s == 1.0 else m.box.scaled(s))
        self.pairs = (m.nlist.i, m.nlist.j, np.ascontiguousarray(m.nlist.image @ m.box.matrix.T),
                      np.full(len(m.nlist.i), -1.0))
        self.y_build = np.array(self.y[:, :2])
        self.s_build = s

    def advance(self, force_tol: float, budget: int, rebuild: bool, energy_floor: float = 0.0) -> tuple[int, int]:
        """At most ``budget`` steps; returns ``(status, steps)`` (status of :mod:`jamflow.minimize._fire_kernels`)."""
        if self.barostat:
            no_energy_floor(self, energy_floor)
        m = self.model
        if self.pairs is None or rebuild:
            self._build()
        pi, pj, offset, lam = self.pairs
        status, n, *last, builds, pi, pj, offset, lam, self.s_build = _loop.shape_fire(
            self.y, self.v, self.box_state, self.fire_state, self.fparams, self.inv_mass, offset, pi, pj, lam,
            self.family, m.params, self.bound, m.k, m.torque_arm, m.rotations, self.y_build, self.s_build,
            m.nlist.reach, m.nlist.skin, self.lengths, m.bounding_diameter, self.barostat, self.pressure0,
            m.box.volume, self.q_scale, float(force_tol), self.pressure_rtol, int(budget), float(energy_floor),
            self.force, self.virial,
        )
        self.pairs = (pi, pj, offset, lam)
        self.inline_builds += builds
        if status != _fire_kernels.REBUILD:
            # energy, interacting pairs, largest squared generalised force, pressure at the present state
            self.last = tuple(last)
        return status, n

    def result(self, steps: int, calls: int, status: int) -> MinimizeResult:
        """The run's outcome: energy, pressure and largest generalised force of the loop's last evaluation,
        which is of the final state (the loop evaluates before it stops)."""
        s = float(self.box_state[2])
        if status == _fire_kernels.REBUILD:
            # the budget ran out at a rebuild, before the loop evaluated the state
            return self._evaluated(s, steps, status)
        config = self.y.copy()
        config[:, :2] *= s
        energy, n_contact, fmax2, pressure = self.last
        return MinimizeResult(
            position=config, box=self.model.box.scaled(s) if self.barostat else self.model.box, energy=float(energy),
            pressure=float(pressure), max_force=float(np.sqrt(fmax2)), n_contacts=int(n_contact), steps=steps,
            converged=status == _fire_kernels.CONVERGED,
            rebuilds=self.model.nlist.builds - self.builds0 + self.inline_builds, evaluations=steps + 1,
            below=status == _fire_kernels.BELOW,
        )

    def _evaluated(self, s: float, steps: int, status: int) -> MinimizeResult:
        """:meth:`result` from one evaluation of the model at the present state."""
        model, config = self.model.rescaled(s, self.y) if self.barostat else (self.model, self.y.copy())
        q = model.dofs(config)
        ev = model.evaluate(q)
        return MinimizeResult(
            position=config, box=model.box, energy=ev.energy, pressure=pressure_of(ev, model.box),
            max_force=model.max_force(model.project(ev.gradient, q)), n_contacts=ev.n_contacts, steps=steps,
            converged=status == _fire_kernels.CONVERGED,
            rebuilds=self.model.nlist.builds - self.builds0 + self.inline_builds, evaluations=steps + 2,
        )
