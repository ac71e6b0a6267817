"""A/B timing of the compiled sphere FIRE kernel of two versions in one process.

Loads ``jamflow/models/spheres/_kernels.py`` of an old source tree (``--old``, e.g. from
``git archive <sha> src | tar -x -C /tmp/base``, then ``--old /tmp/base/src``) as a
sibling module of this tree's kernels, so its relative imports resolve to this tree, and
runs the whole fixed-box :func:`jamflow.models.spheres.model.fire` with either kernel in
turn from the same compressed start (2D N = 1024 at phi = 0.86 and 3D N = 4096 at phi =
0.66, bidisperse, seed 1, ``--steps`` steps). The old kernel must take the arguments
this tree's ``fast.py`` passes. Reports the least CPU time per force evaluation of each
over ``--repeat`` alternations (the first is left out: compilation) and whether the two
runs end with the same energy bit for bit. Alternating in one process cancels most of
the load of a shared machine; run with ``NUMBA_NUM_THREADS=1``.

Writes ``benchmarks/output/fire_kernel_ab.nc`` and ``.png``.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

OUT = Path(__file__).resolve().parent / "output"
CASES = ((2, 1024, 0.86), (3, 4096, 0.66))


def _old_kernels(tree: Path):
    """The old tree's sphere kernels as ``jamflow.models.spheres._old_kernels``."""
    path = tree / "jamflow" / "models" / "spheres" / "_kernels.py"
    if not path.is_file():
        raise SystemExit(f"fire_kernel_ab: no {path}")
    spec = importlib.util.spec_from_file_location("jamflow.models.spheres._old_kernels", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def time_case(d: int, n: int, phi: float, kernels: dict, steps: int, repeat: int) -> dict:
    """Least CPU seconds per step and final energy of each kernel on one start."""
    import jamflow.models.spheres._kernels as current
    from jamflow.models.spheres.model import fire
    from jamflow.protocols.initial import random_packing

    start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=1)
    factor = (start.packing_fraction / phi) ** (1.0 / d)
    x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
    best = {name: np.inf for name in kernels}
    energy = {}
    own = current.fire
    try:
        for rep in range(repeat + 1):
            for name, kernel in kernels.items():
                current.fire = kernel
                t0 = time.process_time()
                res = fire(x, box, D, force_tol=0.0, max_steps=steps)
                if rep:
                    best[name] = min(best[name], (time.process_time() - t0) / steps)
                energy[name] = res.energy
    finally:
        current.fire = own
    return {"best": best, "equal": energy["old"] == energy["new"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="old source tree (the directory holding jamflow/)")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=4)
    args = parser.parse_args()
    import jamflow.models.spheres._kernels as current

    kernels = {"old": _old_kernels(args.old).fire, "new": current.fire}
    rows = []
    for d, n, phi in CASES:
        out = time_case(d, n, phi, kernels, args.steps, args.repeat)
        old, new = out["best"]["old"], out["best"]["new"]
        rows.append((old, new, out["equal"]))
        print(f"{d}D N = {n} phi = {phi}: old {1e6 * old:.1f} us, new {1e6 * new:.1f} us per force evaluation "
              f"(new/old = {new / old:.3f}); energies equal: {out['equal']}")
    labels = [f"{d}D N={n}" for d, n, _ in CASES]
    ds = xr.Dataset(
        {"us_per_step_old": ("case", [1e6 * r[0] for r in rows]),
         "us_per_step_new": ("case", [1e6 * r[1] for r in rows]),
         "energies_equal": ("case", [r[2] for r in rows])},
        coords={"case": labels},
        attrs={"old_tree": str(args.old), "steps": args.steps, "repeat": args.repeat},
    )
    OUT.mkdir(exist_ok=True)
    ds.to_netcdf(OUT / "fire_kernel_ab.nc")
    fig, ax = plt.subplots(figsize=(4.5, 3.2))
    pos = np.arange(len(labels))
    ax.bar(pos - 0.2, ds.us_per_step_old, 0.4, label="old")
    ax.bar(pos + 0.2, ds.us_per_step_new, 0.4, label="new")
    ax.set_xticks(pos, labels)
    ax.set_ylabel("CPU time per force evaluation [µs]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "fire_kernel_ab.png", dpi=120)
    print(f"wrote {OUT / 'fire_kernel_ab.nc'} and .png")


if __name__ == "__main__":
    main()
