"""Subcommand ``tradeoff``: sweep one stage's accuracy knobs against a tight reference."""

from __future__ import annotations

import argparse

from ..io import write_dataset
from ..tradeoff import STAGES, recommend, sweep
from .common import add_command, add_quiet, print_summary, progress_bar
from .types import path_with_suffix, seed


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "tradeoff", _tradeoff,
        "speed against accuracy: sweep a stage's accuracy knobs against a tight reference run",
        description="Runs the stage on fixed inputs built from --seed, once with a tight reference setting "
                    "and once per setting of its accuracy knobs; writes wall time and the errors against the "
                    "reference per setting (dim 'setting', coordinate 'label'), the Pareto front and the "
                    "recommended fast/default/publication settings (attributes). Stages: "
                    + "; ".join(f"{k}: {v.description}" for k, v in STAGES.items()),
        writes=("out",), makes={"out": ("tradeoff",)},
    )
    p.add_argument("stage", choices=sorted(STAGES), help="stage to sweep")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    p.add_argument("--quick", action="store_true", help="smaller inputs and grid (seconds to a minute per stage)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the fixed inputs (default 0)")
    add_quiet(p)


def _tradeoff(args: argparse.Namespace) -> int:
    n = 1 + len(STAGES[args.stage].grid(args.quick))
    with progress_bar(args.quiet, total=n, desc=f"tradeoff {args.stage}", unit="run") as bar:
        def step(label: str) -> None:
            bar.set_postfix_str(label)
            bar.update(1)

        ds = sweep(args.stage, seed=args.seed, quick=args.quick, progress=step)
    write_dataset(ds, args.out)
    print_summary(args, f"{args.out} (recommended settings of {args.stage})", recommend(ds).items())
    return 0
