"""Time series, events and snapshots of an event-driven run, recorded step by step.

Its own module so that the run driver (:mod:`.run`) and the checkpoints
(:mod:`.checkpoint`), which both need the recorder, import it without importing
each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .integrate import Integrator

__all__ = ["SERIES", "Recorder"]

#: Columns of the time series, in dataset order.
SERIES = ("strain", "time", "shear_stress", "pressure", "packing_fraction", "kappa",
          "n_contacts", "z_bar", "volume", "constraint_error")


@dataclass
class Recorder:
    """Accumulates the time series, events and snapshots of a run."""

    columns: dict[str, list] = field(default_factory=lambda: {k: [] for k in SERIES})
    snapshots: list[dict[str, Any]] = field(default_factory=list)
    next_snapshot: int = 0

    def record(self, integ: Integrator) -> None:
        st = integ.state
        drive = integ.drive
        sig = integ.stress() / drive.force_unit
        row = {
            "strain": st.strain,
            "time": st.time / drive.time_unit,
            "shear_stress": -sig[0, 1],
            "pressure": float(sig.trace()) / integ.d,
            "packing_fraction": integ.packing_fraction(),
            "kappa": st.kappa,
            "n_contacts": integ.n_contacts(),
            "z_bar": integ.z_bar(),
            "volume": integ.volume(),
            "constraint_error": integ.constraint_error(),
        }
        for k, v in row.items():
            self.columns[k].append(v)

    def snapshot(self, integ: Integrator, scale: float) -> None:
        st = integ.state
        pairs = st.nl.pairs[st.contact]
        self.snapshots.append({
            "position": st.x * scale, "box": st.h * scale, "strain": st.strain,
            "time": st.time / integ.drive.time_unit, "pairs": pairs,
            "force": integ.solution.force / integ.drive.force_unit,
        })
