"""A/B timing of the compiled sphere FIRE kernel of two versions in one process.

Loads ``soft/_kernels.py`` of an old source tree (``--old``, e.g. from
``git archive 68bf334 src | tar -x -C /tmp/base``) under another module name beside
this tree's, and calls both kernels alternately on the same relaxed state (2D
N = 1024 at phi = 0.86 and 3D N = 4096 at phi = 0.66, bidisperse, no list rebuilds),
reporting the best time per force evaluation of each and the two final energies
(which must be equal). Alternating in one process cancels most of the load of a
shared machine; run with ``NUMBA_NUM_THREADS=1``.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import time
from pathlib import Path

import numpy as np


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    from jamflow.minimize.fire import DEFAULT_FIRE, _fire_params
    from jamflow.models.spheres.model import _kernels, fire
    from jamflow.neighbors.verlet import NeighborList
    from jamflow.protocols.initial import random_packing

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="old source tree (the directory holding jamflow/)")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=8)
    args = parser.parse_args()
    kernels = {
        "old": _load(args.old / "jamflow" / "soft" / "_kernels.py", "old_kernels"),
        "new": _kernels,
    }
    for d, n, phi in ((2, 1024, 0.86), (3, 4096, 0.66)):
        start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=1)
        factor = (start.packing_fraction / phi) ** (1.0 / d)
        x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
        x = fire(x, box, D, force_tol=1e-4 * D.mean()).position
        nlist = NeighborList(D)
        nlist.build(x, box)
        affine, slack = nlist.affine_reference(box)
        unit = float(D.mean())
        best = {name: np.inf for name in kernels}
        energy = {}
        for _ in range(args.repeat):
            for name, module in kernels.items():
                y, v = x.copy(), np.zeros_like(x)
                # [dt, alpha, n_positive, steps]; kernels before the run step count read three
                fire_state = np.array([DEFAULT_FIRE.dt * unit, DEFAULT_FIRE.alpha0, 0.0, 0.0])
                # infinite skin: the timed steps never stop for a rebuild
                # kernels since the in-loop rebuild also take the box sides and diameters
                inline = "lengths" in inspect.signature(module.fire.py_func).parameters
                extra = (box.lengths, D) if inline else ()
                t0 = time.perf_counter()
                out = module.fire(y, v, np.array([0.0, 0.0, 1.0]), fire_state, _fire_params(DEFAULT_FIRE, unit),
                                  nlist.image @ box.matrix.T, nlist.i, nlist.j, nlist.sigma, 1.0, 2.0,
                                  affine, 1.0, nlist.reach, np.inf, slack, False, 0.0, box.volume, 1.0,
                                  0.0, 0.0, args.steps, np.zeros_like(x), np.zeros((d, d)), *extra)
                best[name] = min(best[name], (time.perf_counter() - t0) / out[1])
                energy[name] = out[2]
        print(f"{d}D N = {n} phi = {phi}: old {1e6 * best['old']:.1f} us, new {1e6 * best['new']:.1f} us per "
              f"force evaluation (new/old = {best['new'] / best['old']:.3f}); energies equal: "
              f"{energy['old'] == energy['new']}")


if __name__ == "__main__":
    main()
