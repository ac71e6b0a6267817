"""Driving modes of the overdamped dynamics (Lerner, Düring & Wyart, Secs. II, V B, V C).

- ``shear``: simple shear ``V_aff = rate * y x_hat`` with Lees–Edwards boundaries
  (Sec. II B); the box tilt ``h[0, 1]`` grows at ``rate * h[1, 1]``.
- ``compress``: isotropic compression ``V_aff = -rate * R`` (Sec. II B); the box
  shrinks as ``dh/dt = -rate h``.
- ``shear_compress``: both at once.
- ``shear_fixed_pressure``: simple shear plus ``-kappa * rate * R`` with kappa solved
  from the imposed pressure at every force computation (Sec. II C, Eqs. 20–25, A15).
- ``forces``: constant external forces ``F_ext`` (Sec. II A).
- ``self_propelled``: per-particle random forces, redrawn after random persistence
  times (Sec. V B).

Composite particles (Sec. V C) are given as permanent contacts in any mode.
Time is in units of ``1 / rate`` for deformations and ``tau = lambda / (f_ext xi0)``
for forces; forces in units of ``lambda rate / xi0`` or ``f_ext`` (Sec. II D).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["MODES", "Drive", "SelfPropulsion"]

MODES = ("shear", "compress", "shear_compress", "shear_fixed_pressure", "forces", "self_propelled")


@dataclass
class SelfPropulsion:
    """Random propelling forces with random persistence times (Sec. V B).

    Each particle's force has independent components uniform in ``[-a, a]`` with
    ``a = f_ext sqrt(3 / d)``, so that its mean square is ``f_ext^2`` (the paper's
    ``f_ext``, read per particle); it persists for a time uniform in
    ``[0, tau_max]`` with ``tau_max`` in units of ``tau = lambda / (f_ext xi0)``.

    Attributes
    ----------
    force : ndarray, shape (N, d)
        Current propelling forces.
    switch_time : ndarray, shape (N,)
        Times at which each force is redrawn.
    rng : numpy.random.Generator
        Seeded generator; its state is checkpointed.
    """

    f_ext: float
    tau_max: float
    xi0: float
    force: NDArray[np.float64]
    switch_time: NDArray[np.float64]
    rng: np.random.Generator

    @classmethod
    def start(cls, n: int, d: int, f_ext: float, tau_max: float, xi0: float, seed: int) -> "SelfPropulsion":
        """Draw initial forces and persistence times at time 0."""
        rng = np.random.Generator(np.random.PCG64(seed))
        sp = cls(f_ext, tau_max, xi0, np.zeros((n, d)), np.zeros(n), rng)
        sp.redraw(np.arange(n), 0.0)
        return sp

    @property
    def tau(self) -> float:
        """Time unit ``lambda / (f_ext xi0)`` (lambda = 1)."""
        return 1.0 / (self.f_ext * self.xi0)

    def redraw(self, which: NDArray[np.int64], now: float) -> None:
        """New forces and persistence times for particles ``which``."""
        d = self.force.shape[1]
        a = self.f_ext * np.sqrt(3.0 / d)
        self.force[which] = self.rng.uniform(-a, a, size=(len(which), d))
        self.switch_time[which] = now + self.rng.uniform(0.0, self.tau_max * self.tau, size=len(which))

    def rng_state(self) -> str:
        """Generator state as JSON (for checkpoints)."""
        return json.dumps(self.rng.bit_generator.state)

    def set_rng_state(self, state: str) -> None:
        self.rng.bit_generator.state = json.loads(state)


@dataclass
class Drive:
    """What drives the packing.

    Attributes
    ----------
    mode : str
        One of :data:`MODES`.
    rate : float
        Shear / compression rate gamma_dot [1 / time].
    xi0 : float
        Mobility (velocity per force).
    pressure : float or None
        Imposed pressure (``shear_fixed_pressure``) [lambda rate / xi0 per lambda^(d-1)].
    external : ndarray, shape (N, d) or None
        Constant external forces (``forces``).
    propulsion : SelfPropulsion or None
        (``self_propelled``).
    permanent : ndarray of int64, shape (K, 2)
        Permanent contacts (composite particles), rows i < j.
    """

    mode: str
    rate: float = 1.0
    xi0: float = 1.0
    pressure: float | None = None
    external: NDArray[np.float64] | None = None
    propulsion: SelfPropulsion | None = None
    permanent: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"unknown drive mode {self.mode!r}; choose from {MODES}")
        if not (self.rate > 0 and np.isfinite(self.rate)):
            raise ValueError(f"rate must be positive, got {self.rate}")
        if not (self.xi0 > 0 and np.isfinite(self.xi0)):
            raise ValueError(f"xi0 must be positive, got {self.xi0}")
        if self.mode == "shear_fixed_pressure" and (self.pressure is None or not self.pressure > 0):
            raise ValueError("shear_fixed_pressure needs a positive pressure")
        if self.mode == "forces" and self.external is None:
            raise ValueError("mode 'forces' needs external forces")
        if self.mode == "self_propelled" and self.propulsion is None:
            raise ValueError("mode 'self_propelled' needs a SelfPropulsion")
        self.permanent = np.asarray(self.permanent, dtype=np.int64).reshape(-1, 2)

    @property
    def shears(self) -> bool:
        return self.mode in ("shear", "shear_compress", "shear_fixed_pressure")

    @property
    def compresses(self) -> bool:
        return self.mode in ("compress", "shear_compress")

    @property
    def deforms(self) -> bool:
        return self.shears or self.compresses

    def gradient(self, d: int) -> NDArray[np.float64]:
        """Imposed velocity gradient E [1/time] (without the fixed-pressure kappa part)."""
        E = np.zeros((d, d))
        if self.shears:
            E[0, 1] = self.rate
        if self.compresses:
            E -= self.rate * np.eye(d)
        return E

    def external_forces(self) -> NDArray[np.float64] | None:
        """Current external forces [force], or None."""
        if self.mode == "forces":
            return self.external
        if self.mode == "self_propelled":
            return self.propulsion.force
        return None

    @property
    def force_unit(self) -> float:
        """Force scale of Sec. II D: ``lambda rate / xi0`` or ``f_ext``."""
        if self.deforms:
            return self.rate / self.xi0
        if self.mode == "self_propelled":
            return self.propulsion.f_ext
        return float(np.sqrt(np.mean(np.sum(self.external**2, axis=1))))

    @property
    def time_unit(self) -> float:
        """Time scale of Sec. II D: ``1 / rate`` or ``lambda / (f_ext xi0)``."""
        if self.deforms:
            return 1.0 / self.rate
        return 1.0 / (self.force_unit * self.xi0)

    def describe(self) -> dict[str, Any]:
        """Scalar parameters for provenance."""
        out: dict[str, Any] = {"mode": self.mode, "rate": self.rate, "xi0": self.xi0}
        if self.pressure is not None:
            out["pressure"] = self.pressure
        if self.propulsion is not None:
            out["f_ext"] = self.propulsion.f_ext
            out["tau_max"] = self.propulsion.tau_max
        out["n_permanent"] = int(len(self.permanent))
        return out
