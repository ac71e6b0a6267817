"""Shared output of the per-start benchmarks (``chains.py``, ``linked_newton.py``): one
dataset row per run, and one bar per cell with each start's value as a dot."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import xarray as xr

from jamflow.io import new_dataset_attrs


def rows_dataset(rows: list[dict], title: str, args: argparse.Namespace, note: str) -> xr.Dataset:
    """One variable per key of ``rows`` along ``run`` (unit ``s`` for keys ending in ``_s``, else 1)."""
    data = {k: (("run",), [r[k] for r in rows], {"units": "s" if k.endswith("_s") else "1",
                                                 "long_name": k.replace("_", " ")}) for k in rows[0]}
    return xr.Dataset(data, attrs=new_dataset_attrs(title, vars(args), note=note))


def cell_bars(ax, heights: Sequence[float], points: Sequence[Sequence[float]], shear: Sequence[bool],
              labels: Sequence[str], fontsize: float | None = None) -> None:
    """A bar per cell (blue fixed box, orange shear-stabilised) with its starts' values as dots."""
    for k, (height, values, stabilized) in enumerate(zip(heights, points, shear)):
        ax.bar(k, height, color="C1" if stabilized else "C0")
        ax.plot([k] * len(values), values, "k.", ms=4)
    ax.set_xticks(range(len(labels)), labels, fontsize=fontsize)


def save_chart(fig, ax, xlabel: str, ylabel: str, stem: Path) -> None:
    """Label the axes, write ``<stem>.png`` and say where the dataset and the chart went."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    fig.tight_layout()
    fig.savefig(stem.with_suffix(".png"), dpi=120)
    print(f"wrote {stem}.nc and .png")
