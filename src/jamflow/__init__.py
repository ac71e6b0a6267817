"""jamflow: jammed packings of frictionless particles: hard and soft spheres, linked spheres, 2D shapes.

The public API, importable from the package itself::

    import jamflow
    p = jamflow.random_packing(64, 2, 0.4, "bi", seed=1)
    jammed = jamflow.calippso_jam(p).packing
    jamflow.write_packing(jammed, "jammed.nc")

Every stage is a plain function on a :class:`Packing` (the same function its ``jamflow``
command calls). Names are resolved on first use, so ``import jamflow`` stays cheap: the
numba kernels, HiGHS and matplotlib load only with the stage that needs them.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    sys.stderr.write("jamflow: interrupted (Ctrl-C) while starting; nothing written\n")
    os._exit(130)


def _started_as_command() -> bool:
    """Whether this process is the ``jamflow`` console script or ``python -m jamflow``."""
    argv = getattr(sys, "orig_argv", sys.argv)
    if "-m" in argv[:-1] and argv[argv.index("-m") + 1] == "jamflow":
        return True
    return os.path.basename(sys.argv[0] if sys.argv else "") == "jamflow"


if _started_as_command() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
    # the command line's start-up: until jamflow.cli.main runs (it restores Ctrl-C as
    # KeyboardInterrupt), Ctrl-C ends the process in one line instead of an import traceback
    signal.signal(signal.SIGINT, _interrupted_while_starting)

import importlib
from typing import Any

from .box import Box
from .state.packing import Packing

#: Public name -> module (relative to this package) that defines it.
_LAZY: dict[str, str] = {
    # stages: Packing -> Packing / result / Dataset
    "random_packing": ".protocols.initial",
    "ls_compress": ".protocols.ls",
    "calippso_jam": ".protocols.calippso",
    "jam_to_pressure": ".protocols.soft_jam",
    "aqs_shear": ".protocols.quasistatic",
    "lerner_sd_shear": ".protocols.quasistatic",
    "elastic_moduli": ".models.spheres.hessian",
    "run_flow": ".protocols.overdamped.run",
    "Drive": ".protocols.overdamped.driving",
    "Stop": ".protocols.overdamped.run",
    "FlowOptions": ".protocols.overdamped.integrate",
    "certify": ".protocols.certify",
    # analyses
    "summarize": ".analysis.contacts",
    "gap_distribution": ".analysis.gaps",
    "force_distribution": ".analysis.forces",
    "overlap_dataset": ".analysis.overlap",
    "overlap_series": ".analysis.overlap",
    "structure_dataset": ".analysis.structure",
    "flow_summary": ".analysis.flow",
    "jamming_table": ".analysis.eos",
    # readers and writers
    "read_packing": ".io",
    "write_packing": ".io",
    "read_dataset": ".io",
    "write_dataset": ".io",
    "read_dat": ".io",
    "write_dat": ".io",
    "write_xyz": ".io",
    "write_gsd": ".io",
    "write_table": ".io",
    "load_scene": ".summary",
}

#: Names whose defining module calls them differently. A public name never equals a
#: submodule's (importing a submodule binds its name as an attribute of its package).
_RENAMED: dict[str, str] = {"ls_compress": "compress", "calippso_jam": "calippso"}

__all__ = ["Box", "Packing", *_LAZY]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'jamflow' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), _RENAMED.get(name, name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
