"""Speed against accuracy, measured: per-stage sweeps of the accuracy knobs.

Every stage in :data:`STAGES` has

* fixed inputs built deterministically from a seed (small sizes: the whole set of
  stages runs in a few minutes with ``quick=True``, in about a quarter of an hour
  without);
* a tight *reference* setting, run once on those inputs;
* a grid of settings of its accuracy knobs, each run on the *same* inputs, with the
  wall time and the errors against the reference recorded.

:func:`sweep` returns one ``xarray.Dataset`` per stage (dim ``setting``, coordinate
``label``, one variable per knob, ``time`` and every error metric, ``on_front``);
:func:`pareto_front` marks the settings no other setting beats in both time and
the stage's primary error, and :func:`recommend` picks the ``fast``, ``default`` and
``publication`` settings by the stated rule: the fastest setting whose primary error
(and any further metric the preset limits, e.g. a force-balance criterion) is at
most the stage's threshold for that preset (:attr:`StageSweep.thresholds`), else
the reference.

Times are wall-clock seconds on the machine that ran the sweep (numba kernels are
compiled by an untimed warm-up run first; runs under :data:`TIMING_BUDGET` are
repeated and the shortest time kept). Errors are dimensionless; each
variable's ``long_name`` says against what.

Modules: ``stages`` (what each stage sweeps, :data:`STAGES`), ``sweep`` (the engine:
:func:`sweep`, :func:`pareto_front`, :func:`recommend`).
"""

from .stages import FLOW_PHI, STAGES, StageSweep, cut_backbone_contact, flow_start
from .sweep import TIMING_BUDGET, TIMING_REPEATS, pareto_front, recommend, sweep

__all__ = [
    "FLOW_PHI",
    "STAGES",
    "TIMING_BUDGET",
    "TIMING_REPEATS",
    "StageSweep",
    "cut_backbone_contact",
    "flow_start",
    "pareto_front",
    "recommend",
    "sweep",
]
