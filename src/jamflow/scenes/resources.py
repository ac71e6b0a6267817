"""What one job of a scene costs: expected CPU time, memory and threads, from one table.

Expected CPU times are fitted to runs on the 2-core development machine; the runs, the
numbers and the fits are in ``docs/notes/resources.md`` (CALiPPSO from
``docs/notes/calippso-scaling.md``, the overdamped dynamics from
``docs/notes/overdamped-profile.md``). A job asks a scheduler for
:data:`RUNTIME_SAFETY` times its expectation, at least :data:`RUNTIME_FLOOR_MIN`, and a
retry asks for ``attempt`` times both runtime and memory.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["COST", "Cost", "RUNTIME_FLOOR_MIN", "RUNTIME_SAFETY", "THREADS", "estimate", "machine_memory_mb",
           "request_mb", "request_minutes"]

#: a job asks for this many times its expected time (the fits scatter by ~2x between samples and load)
RUNTIME_SAFETY = 5
#: shortest runtime request [min]: the scheduler's granularity, not a measurement
RUNTIME_FLOOR_MIN = 2
#: every jamflow process holds ~0.25 GB (Python, numpy, xarray, numba, matplotlib); asked for with room
MEM_FLOOR_MB = 1000
#: start-up of one jamflow process [CPU-s]: interpreter, imports and the numba cache (resources.md)
PROCESS_SECONDS = 4.0
#: Threads per command (default 1): the LS, FIRE and event-driven kernels are serial numba, and
#: `jamflow calippso --threads 2` took the same 7.7 CPU-s as 1 on the authors' 3D N = 1024 LS
#: packing (HiGHS's IPX and simplex are serial); the plan passes calippso's threads to HiGHS
THREADS: dict[str, int] = {"calippso": 1}


@dataclass(frozen=True)
class Cost:
    """The fitted cost of one command: CPU seconds at a reference size and the exponent in N."""

    seconds: float
    n_ref: int
    exponent: float
    note: str


#: The table: CPU seconds = PROCESS_SECONDS + seconds (N / n_ref)^exponent x the command's factor
#: (:func:`estimate`); each note names the run it comes from (docs/notes/resources.md).
COST: dict[str, Cost] = {
    "ls": Cost(2e-3 * 1024, 1024, 1.0, "3D N = 1024 at kappa = 1e-3: 2 ms per sphere and decade of pressure "
                                       "(2D 1 ms, 4D 8 ms, 5D 30 ms); ~N / kappa per decade"),
    "calippso": Cost(694.0, 4096, 3.0, "near starts (LS snapshots): 694 s at N = 4096, ~N^3; a random start "
                                       "needs 44x more LPs (216 s against 4.9 s at N = 1024)"),
    "certify": Cost(1683.0, 4096, 3.0, "3D N = 4096 from soft jamming: 1683 s, the collective LP by dual simplex"),
    "soft-jam": Cost(1325.0, 4096, 2.0, "FIRE to P0 = 1e-8: 2D N = 1024 in 30 s, 3D N = 4096 in 1325 s; (d/3)^2"),
    "soft-jam:shapes": Cost(100.0, 480, 1.7, "2D shapes, whole soft-jam: N = 480 ellipses (A = 1.1) to P0 = 1e-9 "
                                             "in 51-97 CPU-s; N^1.6-1.7 between N = 100 and 480 at P0 = 1e-6 "
                                             "(ellipses 5.5 -> 68 s, circulo-lines 6.5 -> 93 s); at N = 100 "
                                             "circulo-polygons, Reuleaux triangles and dumbbells take 0.9-1.5x this "
                                             "row (6-11 s), near-disk ellipses (1 + 1e-3) 3.3x (23 s)"),
    "soft-jam:linked": Cost(20.0, 150, 2.0, "projected FIRE bisection: 50 3D trimers (N = 150) in 33 s wall loaded "
                                            "(chains-fig2), 32 dimers in 17 s (vanderwerf-fig3b); the N^2 is assumed"),
    "minimize": Cost(300.0, 4096, 2.0, "a fixed-box FIRE minimisation: a quarter of soft-jam's bisection"),
    "compress": Cost(75.0, 100, 2.0, "N = 100 2D discs from phi = 0.5 to 0.83: 75 s; N^2 is an assumption"),
    "shear": Cost(1017.0, 1024, 2.0, "per unit strain: N = 1024 2D discs at p = 100, 1017 s (fixed volume "
                                     "358 s); N^2 errs on the long side (N^1.1 measured between 100 and 1024)"),
    "aqs": Cost(200.0, 1024, 2.0, "per unit strain at step 1e-3: one FIRE minimisation per step"),
    "sd-shear": Cost(0.1, 100, 2.0, "per strain step: lerner-fig6 (N = 100, 500 steps of 1e-4) in ~1 minute"),
    "moduli": Cost(20.0, 1024, 2.0, "a sparse Hessian and its lowest modes: 3D N = 1024 in ~20 s"),
    "modes": Cost(30.0, 100, 2.0, "a dense dynamical matrix by automatic derivatives: N = 100 shapes in ~30 s"),
    "link": Cost(2.0, 1024, 1.0, "random contacts and the degeneracy test of the new links"),
    "init-shapes": Cost(2.0, 1024, 1.0, "random placement without overlap"),
}
#: constraint growth of an LP with the dimension, fitted to 5D N = 1024 (218 s) against 3D (4.9 s)
LP_DIMENSION_FACTOR: dict[int, float] = {2: 1.0, 3: 1.0, 4: 1.9, 5: 3.5}
#: LS seconds per sphere and per decade of pressure at kappa = 1e-3, by dimension (resources.md)
LS_SECONDS_PER_SPHERE: dict[int, float] = {2: 1e-3, 3: 2e-3, 4: 8e-3, 5: 3e-2}
#: a CALiPPSO run from a random start takes this many times one from an LS snapshot (216 s / 4.9 s)
CALIPPSO_RANDOM_START = 44


def _lp_size(n: int, d: int) -> float:
    return n * LP_DIMENSION_FACTOR.get(d, 3.5 ** ((d - 3) / 2))


def estimate(command: str, n: int, d: int, options: Mapping[str, Any], before: str | None,
             kind: str = "spheres") -> tuple[float, float]:
    """Expected CPU seconds and memory [MB] of one job.

    Parameters
    ----------
    command : str
        The ``jamflow`` command.
    n, d : int
        Particles of the packing and dimension.
    options : mapping
        The job's options as the scene gives them (one value each; ``p_target`` a list).
    before : str or None
        The command whose packing it reads (a CALiPPSO run from ``init`` is a random start).
    kind : str
        Body kind of the packing (:data:`jamflow.stages.BODY_KINDS`): a ``command:kind`` row
        of :data:`COST` takes precedence over the command's.
    """
    cost = COST.get(f"{command}:{kind}", COST.get(command))
    if command == "ls":
        kappa = float(options["growth_rate"])
        fast = options.get("fast_growth_rate", 5e-3)
        slow_from = options.get("fast_until", 500.0) if fast else 1.0
        decades = max(math.log10(max(options["p_target"]) / slow_from), 0.0)
        seconds = LS_SECONDS_PER_SPHERE.get(d, 3e-2) * n * (1 + decades) * (1e-3 / kappa)
    elif command in ("calippso", "certify"):
        start = CALIPPSO_RANDOM_START if command == "calippso" and before == "init" else 1
        seconds = cost.seconds * (_lp_size(n, d) / cost.n_ref) ** cost.exponent * start
    elif cost is not None:
        seconds = cost.seconds * (n / cost.n_ref) ** cost.exponent
        if command in ("shear", "aqs"):
            seconds *= float(options["strain"])
        if command == "sd-shear":
            seconds *= float(options["strain"]) / float(options.get("step", 1e-4))
        if command in ("soft-jam", "minimize") and kind == "spheres":
            seconds *= (d / 3) ** 2
    else:
        # init, import, check, analyses, studies and figures: a few seconds
        seconds = 1e-3 * n
    return PROCESS_SECONDS + seconds, MEM_FLOOR_MB + _extra_memory_mb(command, n, d)


def _extra_memory_mb(command: str, n: int, d: int) -> float:
    """Memory [MB] beyond the interpreter's."""
    if command in ("calippso", "certify"):
        # peak 0.27 GiB up to N = 1024, 0.59 GiB at 4096 and 3.4 GiB in the first LP at 16384
        # (3D near starts): ~0.35 GB (N / 4096)^1.6 above the interpreter, doubled
        return 2 * 350 * (_lp_size(n, d) / 4096) ** 1.6
    if command in ("moduli", "modes"):
        # a dense (d N)^2 matrix of float64 when the sparse path falls back, doubled for the eigensolver
        return 2 * 8 * (d * n) ** 2 / 1e6
    # neighbour lists, contact networks and time series: linear in N, ~1 kB per sphere
    return 1e-3 * n * d


def request_minutes(cpu_seconds: float, attempt: int = 1) -> int:
    """Runtime request [min] of a job expected to take ``cpu_seconds``."""
    return math.ceil(max(RUNTIME_FLOOR_MIN, RUNTIME_SAFETY * cpu_seconds / 60) * attempt)


def request_mb(mem_mb: float, attempt: int = 1) -> int:
    """Memory request [MB], in whole 100 MB so that requests read as round numbers."""
    return 100 * math.ceil(mem_mb * attempt / 100)


def machine_memory_mb() -> float:
    """Physical memory of this machine [MB] (the default limit of a scene's jobs)."""
    import os

    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e6
