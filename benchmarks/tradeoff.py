"""Speed against accuracy for every stage: sweeps, Pareto plots, recommended presets.

Runs :func:`jamflow.tradeoff.sweep` for every stage of :data:`jamflow.tradeoff.STAGES`
(the same as ``jamflow tradeoff STAGE OUT.nc``), writes

* ``benchmarks/output/tradeoff_<stage>.nc`` and ``tradeoff_<stage>.png`` (Pareto plot);
* ``benchmarks/output/tradeoff.md``: per stage the measured table, the recommended
  ``fast`` / ``default`` / ``publication`` settings (rule: the fastest setting meeting
  every limit the stage sets for the preset, see ``StageSweep.thresholds``) and how
  they compare with ``jamflow.presets.PRESETS`` and the commands' defaults.

Usage: ``python benchmarks/tradeoff.py [--quick] [--seed S] [--stages soft aqs ...]``
(``--quick``: about a minute on 2 cores; full: a few minutes).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import xarray as xr

from jamflow import plots
from jamflow.cli import build_parser
from jamflow.io import read_dataset, write_dataset
from jamflow.presets import PRESETS
from jamflow.tradeoff import STAGES, recommend, sweep

OUT = Path(__file__).resolve().parent / "output"


def _fmt(v: float) -> str:
    return "nan" if not np.isfinite(v) else ("0" if v == 0 else f"{v:.2g}")


def _setting_options(ds: xr.Dataset, label: str, options: dict[str, str]) -> dict:
    k = int(np.flatnonzero(ds.label.values == label)[0])
    out = {}
    for knob, dest in options.items():
        v = ds[knob].values[k]
        out[dest] = v.item() if isinstance(v, np.generic) else v
    return out


def _current(command: str, preset: str, dests: list[str]) -> dict:
    """Values of ``dests`` a command runs with under a preset (its defaults where the preset is silent)."""
    sub = build_parser().subcommands[command]
    preset_values = PRESETS.get(command, {}).get(preset, {})
    return {dest: preset_values.get(dest, sub.get_default(dest)) for dest in dests}


def stage_markdown(ds: xr.Dataset) -> list[str]:
    sw = STAGES[ds.attrs["stage"]]
    metrics = list(sw.metrics)
    lines = [f"## {sw.name}", "", ds.attrs["description"] + ".", "",
             f"Reference: `{ds.attrs['reference']}`. Primary error `{sw.primary}`: {sw.metrics[sw.primary]}.", "",
             "| setting | time [s] | " + " | ".join(metrics) + " | front |",
             "|---|---|" + "---|" * len(metrics) + "---|"]
    for k in range(ds.sizes["setting"]):
        ref = " (reference)" if ds.is_reference.values[k] else ""
        vals = " | ".join(_fmt(float(ds[m].values[k])) for m in metrics)
        lines.append(f"| `{ds.label.values[k]}`{ref} | {ds.time.values[k]:.3g} | {vals} | "
                     f"{'yes' if ds.on_front.values[k] else ''} |")
    lines += ["", "| preset | limits | measured choice | command options | current preset (`"
              + "`, `".join(sw.commands) + "`) |", "|---|---|---|---|---|"]
    rec = recommend(ds, sw)
    for preset, label in rec.items():
        limits = ", ".join(f"{m} <= {v:g}" for m, v in sw.thresholds[preset].items())
        opts = _setting_options(ds, label, sw.preset_options)
        now = _current(sw.commands[0], preset, list(opts))
        lines.append(f"| {preset} | {limits} | `{label}` | `{json.dumps(opts)}` | `{json.dumps(now)}` |")
    lines.append("")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small inputs and grids (about a minute)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the fixed inputs")
    ap.add_argument("--stages", nargs="+", choices=sorted(STAGES), default=list(STAGES))
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    md = ["# Speed against accuracy (`python benchmarks/tradeoff.py [--quick] [--stages ...]`)", "",
          ("Wall times on the machine that ran it (2 shared cores); errors against a tight reference run on the "
           "same input. Recommended setting per preset: the fastest setting meeting every limit of the preset "
           "(the reference if none does). `front`: on the Pareto front of time and the primary error."), ""]
    for name in args.stages:
        t0 = time.perf_counter()
        ds = sweep(name, seed=args.seed, quick=args.quick, progress=lambda label, stage=name: print(f"  {stage}: {label}", flush=True))
        write_dataset(ds, OUT / f"tradeoff_{name}.nc")
        plots.save_figure(plots.pareto(ds), OUT / f"tradeoff_{name}.png")
        print(f"{name}: {time.perf_counter() - t0:.1f} s; " + "; ".join(f"{p} -> {lab}" for p, lab in recommend(ds).items()),
              flush=True)
    # the summary covers every stage swept so far (a run of some stages keeps the others')
    for name in STAGES:
        if (OUT / f"tradeoff_{name}.nc").exists():
            ds = read_dataset(OUT / f"tradeoff_{name}.nc")
            run = json.loads(ds.attrs["parameters"])
            md += [*stage_markdown(ds), f"(`{name}` measured with quick = {bool(run['quick'])}, seed {run['seed']}.)", ""]
    path = OUT / "tradeoff.md"
    path.write_text("\n".join(md) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
