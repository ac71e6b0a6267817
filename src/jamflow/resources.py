"""What a stage needs for N particles in d dimensions, against what this machine has, before it allocates.

The commands that make packings (``init``, ``init-shapes``, ``init-chains``) call
:func:`check_fits` before drawing a single number, so ``jamflow init --n 1000000000``
is refused in one line instead of allocating for minutes; the workflow's plan-time
checks call the same function for a scene's ``system.n``. Time series whose length is
known in advance (``aqs``, ``sd-shear``: strain / step records) and flow snapshots are
checked with :func:`series_memory` and :func:`check_memory`. The per-particle numbers are
measured (``docs/notes/resources.md``, "Memory and time of the starts").
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["INTERPRETER_BYTES", "RECORD_BYTES", "check_fits", "check_memory", "machine_memory", "series_memory",
           "stage_memory", "stage_seconds"]

#: Resident memory of a jamflow process before its arrays [bytes]: Python, numpy, scipy,
#: xarray, netCDF4 and the kernel compiler (measured 0.21 GB for ``jamflow init`` of 1000 spheres).
INTERPRETER_BYTES: float = 0.3e9

#: Bytes per particle and per (coordinate + 1) of the random starts [bytes]: four times the
#: measured peak (RSA of 10^6 spheres in 3D: 60 B per sphere above the interpreter), since
#: the netCDF write copies the arrays and compresses them (docs/notes/resources.md).
_START_BYTES_PER_ENTRY: float = 64.0

#: CPU seconds per particle of the random starts, rounded up from the slowest measured
#: (docs/notes/resources.md, "Memory and time of the starts"): an order of magnitude.
_START_SECONDS: dict[str, float] = {"init": 2.5e-3, "init-shapes": 1e-3, "init-chains": 1.5e-3}


#: Bytes of one record of a time series (a dozen float64 columns, the events between
#: records, the Python lists they are gathered in), rounded up.
RECORD_BYTES: float = 1000.0


#: The kernel's memory-limit files of a cgroup v2 and a cgroup v1 hierarchy (operating-system
#: interfaces, not files of the repository): a SLURM job or a container sees its limit there.
CGROUP_MEMORY_LIMITS: tuple[Path, ...] = (Path("/sys/fs/cgroup/memory.max"),
                                          Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"))


def machine_memory() -> int:
    """Memory this process may use [bytes]: physical memory, or less under a cgroup limit (a SLURM job)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for limit in CGROUP_MEMORY_LIMITS:
        try:
            text = limit.read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return int(total)


def stage_memory(stage: str, n: int, d: int) -> float:
    """Peak resident memory [bytes] of ``stage`` making ``n`` particles in ``d`` dimensions.

    Raises
    ------
    KeyError
        A stage without a memory model here.
    """
    if stage not in _START_SECONDS:
        raise KeyError(f"no memory model of {stage!r}; the modelled stages are {', '.join(_START_SECONDS)}")
    # shapes carry an orientation and a shape index beside the centre: d + 1 -> d + 3
    entries = d + (3 if stage == "init-shapes" else 1)
    return INTERPRETER_BYTES + _START_BYTES_PER_ENTRY * entries * float(n)


def stage_seconds(stage: str, n: int, d: int) -> float:
    """Expected CPU time [s] of ``stage`` making ``n`` particles in ``d`` dimensions (an order of magnitude)."""
    return _START_SECONDS[stage] * float(n)


def check_fits(stage: str, n: int, d: int, what: str = "particles") -> None:
    """Refuse (``ValueError``, one line) a start whose memory exceeds this machine's.

    Parameters
    ----------
    stage : str
        ``init``, ``init-shapes`` or ``init-chains``.
    n : int
        Number of particles (spheres of all clusters, or bodies).
    d : int
        Dimension.
    what : str
        What ``n`` counts, for the message.
    """
    check_memory(f"{stage} of N = {n:.4g} {what} in d = {d}", stage_memory(stage, n, d),
                 f"(and it would take about {_duration(stage_seconds(stage, n, d))}): use fewer particles")


def check_memory(what: str, need: float, advice: str = "") -> None:
    """Refuse (``ValueError``, one line) ``what`` when its ``need`` [bytes] exceeds :func:`machine_memory`."""
    have = machine_memory()
    if need > have:
        raise ValueError(f"{what} needs about {_bytes(need)} of memory and this machine has {_bytes(have)}"
                         + (f" {advice}" if advice else ""))


def series_memory(n_records: float, n: int = 0, d: int = 0, snapshots: float = 0) -> float:
    """Memory [bytes] of a time series of ``n_records`` records and ``snapshots`` packings of ``n`` particles in ``d``."""
    return INTERPRETER_BYTES + RECORD_BYTES * float(n_records) + _START_BYTES_PER_ENTRY * (d + 1) * n * float(snapshots)


def _bytes(b: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b:.3g} B"


def _duration(s: float) -> str:
    for unit, size in (("years", 3.15e7), ("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if s >= size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"
