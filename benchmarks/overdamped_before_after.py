"""Event-driven shear speed of this tree against another source tree, side by side in one run.

The machine is shared, so absolute times drift: the two trees shear the same start for the
same number of steps in alternation (``--repeats`` rounds, each a fresh interpreter), and the
ratio of events per second is reported per round. Also prints the relative difference of the
final shear stress (both runs must follow the same trajectory to round-off over a short run).

``--options`` changes this tree's FlowOptions (e.g. a larger ``step_drift``): then the runs
cover different strains in the same number of steps and the stress difference is not a check.
``--strain`` runs both trees to the same strain instead, each with its own step rule (the
trees' defaults may differ): events per second then compare the same stretch of flow.

Start packings: ``--start FILE.nc`` (any jamflow packing; contacts need not be set) or, by
default, the trade-off harness's start (:func:`jamflow.tradeoff.flow_start`, event-driven
compression of 2D 1:1.4 bidisperse 3 % polydisperse discs to ``--phi``).

Writes ``benchmarks/output/overdamped_before_after.nc`` (events/s, wall time, steps and strain
per tree and round) and ``.png`` (events per second of both trees and their ratio per round).

Usage::

    git worktree add /tmp/base 68bf334
    python benchmarks/overdamped_before_after.py --base-src /tmp/base/src --n 256 --phi 0.83 --steps 600
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SRC = HERE.parent / "src"
OUTPUT = HERE / "output"

CHILD = r"""
import json, sys, time
from jamflow.io import read_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, run_flow
path, steps, strain = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
opts = FlowOptions(**json.loads(sys.argv[4]))
p = read_packing(path)
run_flow(p, Drive("shear"), Stop(strain=10.0, max_steps=5), FlowOptions(), unit="small_diameter")  # numba caches
stop = Stop(strain=strain) if strain > 0 else Stop(strain=10.0, max_steps=steps)
t0 = time.perf_counter()
res = run_flow(p, Drive("shear"), stop, opts, unit="small_diameter")
wall = time.perf_counter() - t0
s = res.series
print(json.dumps({"wall": wall, "events": int(s.sizes["event"]), "strain": float(s.strain.values[-1]),
                  "stress": float(s.shear_stress.values[-1]), "steps": int(s.sizes["step"]) - 1}))
"""


def run_child(src: Path, start: Path, steps: int, strain: float, options: str = "{}") -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = subprocess.run([sys.executable, "-c", CHILD, str(start), str(steps), str(strain), options], env=env,
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base-src", type=Path, required=True, help="src/ directory of the tree to compare against")
    ap.add_argument("--start", type=Path, help="start packing (netCDF); default: flow_start(N, phi)")
    ap.add_argument("--n", type=int, default=256)
    ap.add_argument("--phi", type=float, default=0.83)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--strain", type=float, default=0.0,
                    help="run both trees to this strain instead of --steps steps (each with its own step rule)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--options", default="{}", help="FlowOptions of this tree's run as JSON, e.g. '{\"step_drift\": 1e-7}' "
                    "(the base tree always runs the defaults)")
    args = ap.parse_args()
    if not (args.base_src / "jamflow").is_dir():
        sys.exit(f"--base-src {args.base_src}: no jamflow package there")
    with tempfile.TemporaryDirectory() as tmp:
        start = args.start
        if start is None:
            sys.path.insert(0, str(SRC))
            from jamflow.io import write_packing
            from jamflow.tradeoff import flow_start

            start = Path(tmp) / "start.nc"
            write_packing(flow_start(args.n, args.phi, args.seed), start)
        runs = []
        for r in range(args.repeats):
            base = run_child(args.base_src, start, args.steps, args.strain)
            new = run_child(SRC, start, args.steps, args.strain, args.options)
            runs.append((base, new))
            rates = [x["events"] / x["wall"] for x in (base, new)]
            print(f"round {r}: base {rates[0]:.2f} events/s ({base['wall']:.2f} s), this tree {rates[1]:.2f} events/s "
                  f"({new['wall']:.2f} s): ratio {rates[1] / rates[0]:.2f}; {new['events']} events over strain "
                  f"{new['strain']:.4g} in {new['steps']} steps ({new['steps'] / max(new['events'], 1):.1f} steps/event; "
                  f"base {base['events']} events, {base['steps']} steps); "
                  f"strain/min {60 * base['strain'] / base['wall']:.3g} -> {60 * new['strain'] / new['wall']:.3g}; "
                  f"final stress rel. difference {abs(new['stress'] - base['stress']) / abs(base['stress']):.1e}",
                  flush=True)
        write_outputs(runs, args, start)


def write_outputs(runs: list[tuple[dict, dict]], args: argparse.Namespace, start: Path) -> None:
    """The rounds as a dataset (tree x round) and a figure of events/s and their ratio."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import xarray as xr

    sys.path.insert(0, str(SRC))
    from jamflow.io import new_dataset_attrs, read_packing, write_dataset
    from jamflow.protocols.overdamped.driving import Drive
    from jamflow.protocols.overdamped.run import stress_unit

    d = read_packing(start).d

    def table(key: str) -> np.ndarray:
        return np.array([[run[t][key] for run in runs] for t in range(2)], dtype=float)

    events, wall = table("events"), table("wall")
    dims = ("tree", "round")
    ds = xr.Dataset(
        {
            "events_per_second": (dims, events / wall, {"units": "1/s", "long_name": "rewiring events per wall second"}),
            "wall_time": (dims, wall, {"units": "s", "long_name": "wall time of the timed run"}),
            "events": (dims, events, {"units": "1", "long_name": "events in the timed run"}),
            "strain": (dims, table("strain"), {"units": "1", "long_name": "shear strain reached"}),
            "steps": (dims, table("steps"), {"units": "1", "long_name": "integration steps of the timed run"}),
            "final_shear_stress": (dims, table("stress"), {"units": stress_unit(Drive("shear"), d),
                                                            "long_name": "shear stress at the last step"}),
        },
        coords={"tree": ("tree", ["base", "this"]), "round": ("round", np.arange(len(runs)))},
        attrs=new_dataset_attrs("jamflow event-driven shear speed, two source trees side by side", vars(args),
                                host_cpus=os.cpu_count()),
    )
    OUTPUT.mkdir(exist_ok=True)
    write_dataset(ds, OUTPUT / "overdamped_before_after.nc")
    rates = events / wall
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    rounds = np.arange(len(runs))
    for t, name in enumerate(("base", "this tree")):
        axes[0].bar(rounds + (t - 0.5) * 0.4, rates[t], 0.4, label=name)
    axes[0].set_yscale("log")
    axes[0].set_ylim(top=5 * float(np.nanmax(rates)))  # room for the legend
    axes[0].set_ylabel("events per second [1/s]")
    axes[1].bar(rounds, rates[1] / rates[0], 0.6, color="C2")
    axes[1].axhline(30.0, color="k", ls="--", lw=1, label="issue 20 target 30x")
    axes[1].set_ylim(0, 1.35 * max(30.0, float(np.nanmax(rates[1] / rates[0]))))
    axes[1].set_ylabel("events/s ratio, this tree / base [1]")
    for ax in axes:
        ax.set_xlabel("round [1]")
        ax.set_xticks(rounds)
        ax.legend(loc="upper left", ncols=2)
    fig.savefig(OUTPUT / "overdamped_before_after.png", dpi=120)
    print(f"wrote {OUTPUT / 'overdamped_before_after.nc'} and .png")


if __name__ == "__main__":
    main()
