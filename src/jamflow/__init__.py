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

import importlib
import os
import warnings
from pathlib import Path
from typing import Any

from ._kernel_cache import refresh as _refresh_kernel_caches
from .box import Box
from .packing import Packing

# before any kernel module loads: numba's caches must not outlive a change of a kernel
# they inline from another module (see jamflow._kernel_cache); the package is named
# by its absolute, unresolved path, as numba names its NUMBA_CACHE_DIR entries
try:
    _refresh_kernel_caches(Path(os.path.abspath(__file__)).parent)
except OSError as _exc:
    warnings.warn(f"jamflow could not clear numba's kernel caches after a change of kernel code ({_exc}); "
                  f"clear them by hand: find {os.environ.get('NUMBA_CACHE_DIR') or Path(__file__).parent} "
                  "-name '*.nb[ci]' -delete", stacklevel=2)

#: Public name -> module (relative to this package) that defines it.
_LAZY: dict[str, str] = {
    # stages: Packing -> Packing / result / Dataset
    "random_packing": ".initial",
    "ls_compress": ".ls",
    "calippso_jam": ".calippso",
    "jam_to_pressure": ".soft.jamming",
    "aqs_shear": ".soft.shear",
    "lerner_sd_shear": ".soft.shear",
    "elastic_moduli": ".soft.hessian",
    "run_flow": ".overdamped.run",
    "Drive": ".overdamped.driving",
    "Stop": ".overdamped.run",
    "FlowOptions": ".overdamped.integrate",
    "certify": ".strict_jamming",
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
#: submodule's (``jamflow.calippso`` is the module; importing it rebinds that attribute).
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
