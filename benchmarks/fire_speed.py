"""Time per FIRE step (one force evaluation each) of soft spheres, for comparing two versions.

Cases of the Bodies issue: 2D N = 1024 at phi = 0.86 and 3D N = 4096 at phi = 0.66,
bidisperse, from an RSA start compressed affinely and relaxed by FIRE to a force of
1e-4 (same seed in every version), one thread. Each case runs ``--steps`` FIRE steps (no convergence) ``--repeat`` times and
reports the best time per step in microseconds (the first call pays numba's cache load)::

    NUMBA_NUM_THREADS=1 PYTHONPATH=/path/to/old/src python benchmarks/fire_speed.py
    NUMBA_NUM_THREADS=1 PYTHONPATH=src python benchmarks/fire_speed.py

Run both in one session, one after the other, and compare the ratio (absolute
times depend on the machine's load).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    import jamflow
    from jamflow.models.spheres.model import fire
    from jamflow.protocols.initial import random_packing

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print("jamflow from", jamflow.__file__)
    for d, n, phi in ((2, 1024, 0.86), (3, 4096, 0.66)):
        start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=1)
        factor = (start.packing_fraction / phi) ** (1.0 / d)
        x, box, D = start.position * factor, start.box.scaled(factor), start.diameter
        # relax the affine compression first, so the timed steps are force evaluations
        # and not neighbour-list builds (the list is rebuilt rarely near a minimum)
        x = fire(x, box, D, force_tol=1e-4 * start.diameter.mean()).position
        best = np.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = fire(x, box, D, force_tol=0.0, max_steps=args.steps)
            best = min(best, (time.perf_counter() - t0) / res.steps)
        print(f"{d}D N = {n} phi = {phi}: {1e6 * best:.1f} us per FIRE step "
              f"({res.steps} steps, {res.rebuilds} list builds, energy {res.energy:.12g})")


if __name__ == "__main__":
    main()
