"""Share of FIRE time spent building neighbour lists, and time per force evaluation, against a base tree.

The Bodies issue (#16) asks for neighbour rebuilds under 5 % of the minimisation time
at 2D N = 1024 and 16384 (phi = 0.86) and 3D N = 4096 (phi = 0.66), from the
affinely compressed RSA starts of ``benchmarks/minimize_vs_lammps.py``, FIRE to
``max|F| <= 1e-12``. Each run is a subprocess (``--worker``) so that a base tree
(``--base-src``, e.g. ``git archive <sha> src | tar -x -C /tmp/base``) runs the same
code path under ``PYTHONPATH``; the two trees alternate, ``--repeat`` times.

Build time: CPU time inside ``NeighborList.build`` (Python builds), plus, for the
lists the compiled FIRE loop builds itself (``_kernels._inline_list``, no Python
around them, not timeable from outside), the number of such builds times the mean of
the median CPU times of that kernel on the start and on the final configuration in
the run's particle order (51 calls each, each after a force evaluation, reusing one set
of work arrays as the loop does where the tree has them; the final
configuration builds 25-40 % slower than the start at 2D N = 16384). The share is the
build time over the run's CPU time.

Run: ``python benchmarks/neighbor_share.py [--base-src DIR] [--cases 0 1 2]
[--max-steps K] [--repeat R]``. Writes ``benchmarks/output/neighbor_share.nc`` and
``.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

OUTPUT = Path(__file__).resolve().parent / "output"
#: (d, N, phi) of the Bodies issue (#16), as in minimize_vs_lammps.py
CASES = ((2, 1024, 0.86), (3, 4096, 0.66), (2, 16384, 0.86))
FORCE_TOL = 1e-12


def worker(case: int, max_steps: int, seed: int) -> dict:
    """One FIRE run in this process's jamflow; the numbers as a dict."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from minimize_vs_lammps import start

    from jamflow.models.spheres.model import _kernels, fire
    from jamflow.neighbors.verlet import NeighborList

    d, n, phi = CASES[case]
    x, box, D = start(d, n, phi, seed)
    fire(x, box, D, force_tol=FORCE_TOL, max_steps=20)  # compile outside the timing
    spent = [0.0, 0]
    build = NeighborList.build

    def timed(self, *args, **kwargs):
        t0 = time.process_time()
        build(self, *args, **kwargs)
        spent[0] += time.process_time() - t0
        spent[1] += 1

    NeighborList.build = timed
    t0 = time.process_time()
    res = fire(x, box, D, force_tol=FORCE_TOL, max_steps=max_steps)
    total = time.process_time() - t0
    NeighborList.build = build
    kernel = 0.0
    if hasattr(_kernels, "_inline_list"):
        # the particles in the order the run used (sorted by cell in large systems)
        minimize = sys.modules["jamflow.models.spheres.fast"]
        order = (minimize._cell_order(x, box, float(D.max())) if n >= getattr(minimize, "SPATIAL_SORT_MIN_N", np.inf)
                 else np.arange(n))
        medians = []
        # builds happen all along the run: the start and the final configuration bracket them
        for y in (x[order], res.position[order]):
            nl = NeighborList(D[order])
            nl.build(y, box)
            offset = nl.image @ box.matrix.T
            force, virial = np.zeros_like(y), np.zeros((d, d))
            times = []
            # the list's work arrays are reused from build to build where the tree does so
            args = (y, 1.0, box.lengths, D[order], nl.reach, nl.skin)
            if hasattr(_kernels, "_list_buffers"):
                args += (_kernels._list_buffers(n, d),)
                _kernels._inline_list(*args)
            for _ in range(51):
                # a force evaluation between builds, as in the loop, so the caches are not the build's own
                _kernels.pair_forces(y, 1.0, offset, nl.i, nl.j, nl.sigma, 1.0, 2.0, force, virial, False)
                t1 = time.process_time()
                _kernels._inline_list(*args)
                times.append(time.process_time() - t1)
            medians.append(float(np.median(times)))
        kernel = float(np.mean(medians))
    return {"time": total, "evaluations": res.evaluations, "builds": res.rebuilds, "python_build_time": spent[0],
            "python_builds": spent[1], "kernel_build_time": kernel, "converged": res.converged, "energy": res.energy}


def _run(src: Path | None, case: int, max_steps: int, seed: int) -> dict:
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if src is not None:
        env["PYTHONPATH"] = str(src)
    out = subprocess.run([sys.executable, __file__, "--worker", str(case), "--max-steps", str(max_steps),
                          "--seed", str(seed)], env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _share(r: dict) -> float:
    """Build time over run time (module doc): Python builds timed, the compiled loop's counted."""
    inline_builds = r["builds"] - r["python_builds"]
    return (r["python_build_time"] + inline_builds * r["kernel_build_time"]) / r["time"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--base-src", type=Path, help="base source tree (the directory holding jamflow/)")
    parser.add_argument("--cases", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--max-steps", type=int, default=30000)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    if args.worker is not None:
        print(json.dumps(worker(args.worker, args.max_steps, args.seed)))
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import xarray as xr

    from jamflow.io import new_dataset_attrs, write_dataset

    trees = {"this": None} if args.base_src is None else {"base": args.base_src, "this": None}
    shape = (len(args.cases), len(trees), args.repeat)
    data = {k: np.full(shape, np.nan) for k in ("time", "evaluations", "builds", "share")}
    for c, case in enumerate(args.cases):
        for r in range(args.repeat):
            for t, (name, src) in enumerate(trees.items()):
                out = _run(src, case, args.max_steps, args.seed)
                share = _share(out)
                for key in ("time", "evaluations", "builds"):
                    data[key][c, t, r] = out[key]
                data["share"][c, t, r] = share
                d, n, phi = CASES[case]
                print(f"{d}D N = {n} phi = {phi} {name:4s} run {r}: {1e6 * out['time'] / out['evaluations']:7.1f} us per "
                      f"evaluation, {out['evaluations']} evaluations, {out['builds']} builds, build share "
                      f"{100 * share:.1f} %, converged {out['converged']}, energy {out['energy']:.12g}", flush=True)
    labels = [f"{CASES[c][0]}D N={CASES[c][1]} phi={CASES[c][2]}" for c in args.cases]
    per_eval = 1e6 * data["time"] / data["evaluations"]
    print("\nmedians:")
    for c, label in enumerate(labels):
        row = ", ".join(f"{name} {np.median(per_eval[c, t]):.1f} us/eval, share {100 * np.median(data['share'][c, t]):.1f} %"
                        for t, name in enumerate(trees))
        print(f"  {label}: {row}")
    dims = ("case", "tree", "repeat")
    ds = xr.Dataset(
        {
            "cpu_time": (dims, data["time"], {"units": "s", "long_name": "CPU time of the FIRE run"}),
            "evaluations": (dims, data["evaluations"], {"units": "1", "long_name": "force evaluations"}),
            "builds": (dims, data["builds"], {"units": "1", "long_name": "neighbour-list builds"}),
            "build_share": (dims, data["share"], {"units": "1", "long_name": "share of CPU time in list builds"}),
            "time_per_evaluation": (dims, per_eval, {"units": "microsecond", "long_name": "CPU time per force evaluation"}),
        },
        coords={"case": ("case", labels), "tree": ("tree", list(trees))},
        attrs=new_dataset_attrs("jamflow neighbour-list build share of FIRE", vars(args) | {"base_src": str(args.base_src)},
                                force_tol=FORCE_TOL, host_cpus=os.cpu_count()),
    )
    OUTPUT.mkdir(exist_ok=True)
    write_dataset(ds, OUTPUT / "neighbor_share.nc")
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    width = 0.8 / len(trees)
    for t, name in enumerate(trees):
        pos = np.arange(len(labels)) + (t - (len(trees) - 1) / 2) * width
        axes[0].bar(pos, 100 * np.median(data["share"][:, t], axis=1), width, label=name)
        axes[1].bar(pos, np.median(per_eval[:, t], axis=1), width, label=name)
    axes[0].axhline(5.0, color="k", ls="--", lw=1, label="target 5 %")
    axes[0].set_ylabel("neighbour-list build share of CPU time [%]")
    axes[1].set_ylabel("CPU time per force evaluation [µs]")
    axes[1].set_yscale("log")
    for ax in axes:
        ax.set_xticks(np.arange(len(labels)), labels, rotation=15)
        ax.set_xlabel("case: dimension, particles N, packing fraction phi [1]")
        ax.legend()
    fig.savefig(OUTPUT / "neighbor_share.png", dpi=120)
    print(f"wrote {OUTPUT / 'neighbor_share.nc'} and .png")


if __name__ == "__main__":
    main()
