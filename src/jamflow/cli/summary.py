"""Subcommands ``summary`` (one table of a whole scene, a row per packing or flow run) and ``pool``
(one netCDF of a study along its kept scan dimensions)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pandas as pd

from ..io import DATASET_KINDS, parse_point, pool_datasets, write_dataset, write_table
from ..summary import load_scene
from .common import add_command, add_quiet, split_paths
from .types import path_with_suffix

#: Columns printed (those with at least one value); --json / --csv write every column.
PRINTED = ("kind", "body", "point", "sample", "stage", "kappa", "p_target", "N", "d", "phi", "phi_J", "pressure", "n_contacts",
           "isostatic_count", "n_rattlers", "n_lp", "classification", "gamma", "gamma_stat", "gamma_sys", "gamma_err",
           "theta", "theta_stat", "theta_sys", "theta_err", "strain", "shear_stress", "friction",
           "counting_note", "gamma_note", "theta_note")
#: Significant digits of printed floats: packing fractions in full, exponents and the rest short.
DIGITS = {"phi": 10, "phi_J": 10}


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "summary", _summary, "one table of a whole scene: a row per packing or flow run with its key numbers",
        description="Reads results/<scene> (or the results of a scene YAML, relative to the current directory) and "
                    "prints one row per packing and per flow run: parameters (sample, stage, kappa, p_target) and "
                    "numbers (phi, phi_J, pressure, backbone contacts, isostatic count, rattlers, LPs, certificate, "
                    "the scene's gap exponent gamma and force exponent theta with their statistical, systematic and "
                    "combined errors, or why the fit was refused). The same table "
                    "from Python: jamflow.load_scene(PATH).",
        reads=("path",), writes=("json", "csv"), makes={"json": (), "csv": ()},
    )
    p.add_argument("path", help="a scene's results folder (results/<scene>) or its scene YAML")
    p.add_argument("--json", type=path_with_suffix(".json"), default=None, metavar="OUT.json", help="also write every column as JSON records")
    p.add_argument("--csv", type=path_with_suffix(".csv"), default=None, metavar="OUT.csv", help="also write every column as CSV")
    add_quiet(p)
    p = add_command(
        sub, "pool", _pool, "one netCDF of a study: its datasets along the scan dimensions they keep",
        description="Concatenates datasets along a dimension 'point' with one coordinate per scan dimension "
                    "(from --points, one per input: key=value,key=value or 'base'); numeric attributes that differ "
                    "between the inputs become variables attr_<name>(point). The workflow pools every study "
                    "this way (jamflow.io.pool).",
        reads=("paths[:-1]",), writes=("paths[-1]",),
        # a pooled study holds the kind of the datasets it pools
        makes={"paths[-1]": tuple(k for k in DATASET_KINDS if k != "packing")},
    )
    p.add_argument("paths", nargs="+", metavar="IN.nc ... OUT.nc", help="datasets, then the output")
    p.add_argument("--points", nargs="+", required=True, help="the scan point of each input, same order")
    p.add_argument("--study", required=True, help="name of the study")
    add_quiet(p)
    p = add_command(
        sub, "reproduce", _reproduce, "the reproduced-figures page: each paper scene's figure and numbers beside the paper's",
        description="Reads results/<scene> (laptop scale) and results/<scene>-paper (paper scale) of every paper "
                    "scene, copies the laptop figures beside OUT and writes one table per scene: quantity | paper | "
                    "laptop scale | paper scale (jamflow.reproduce).",
        writes=("out",), makes={"out": ()},
    )
    p.add_argument("out", type=path_with_suffix(".md"), help="the markdown page, e.g. docs/reproduced.md")
    p.add_argument("--results", default="results", help="the results folder (default results)")
    p.add_argument("--scenes", default="config/scenes", help="the scene files (default config/scenes)")
    add_quiet(p)


def _reproduce(args: argparse.Namespace) -> int:
    from ..reproduce import SCENES, reproduced_page

    out = reproduced_page(args.results, args.out, args.scenes)
    if not args.quiet:
        ran = sum((Path(args.results) / page.scene).is_dir() for page in SCENES)
        print(f"reproduce: {ran} of {len(SCENES)} paper scenes have laptop-scale outputs under {args.results} -> {out}")
    return 0


def _pool(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "dataset")
    ds = pool_datasets(inputs, [parse_point(p) for p in args.points], args.study)
    write_dataset(ds, out)
    if not args.quiet:
        dims = ", ".join(str(k) for k in ds.coords if ds[k].dims == ("point",))
        print(f"pool: {args.study}: {len(inputs)} datasets along point ({dims or 'no scan dimension'}) -> {out}")
    return 0


def _format(column: str, value: object) -> str:
    """A table cell: '-' for missing, integers without a decimal point, floats to DIGITS digits."""
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if value.is_integer() and column not in DIGITS and abs(value) < 1e15:
            return str(int(value))
        return f"{value:.{DIGITS.get(column, 4)}g}"
    return str(value) if value != "" else "-"


def _summary(args: argparse.Namespace) -> int:
    table = load_scene(args.path)
    if args.json:
        write_table(table, args.json)
    if args.csv:
        write_table(table, args.csv)
    if args.quiet:
        return 0
    shown = [c for c in PRINTED if table[c].replace("", pd.NA).notna().any()]
    text = table[shown].apply(lambda col: col.map(lambda v: _format(col.name, v))).to_string(index=False)
    print(f"summary: {table['scene'].iloc[0]} ({len(table)} rows)")
    print(text)
    return 0
