"""One netCDF of a study: its datasets along the scan dimensions they keep.

A scene's study (:mod:`jamflow.scenes`) runs one command per kept scan point (gaps of
the packings at one growth rate and target pressure, say) and pools the outputs here,
so that ``xarray.open_dataset`` of one file gives a labelled table: dimension ``point``
with one coordinate per kept scan dimension, every variable of the inputs along it, and
every numeric scalar attribute that differs between inputs (a fitted exponent, its
error) as a variable along ``point`` too.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence

import numpy as np
import xarray as xr

from .dataset import new_dataset_attrs, read_dataset

__all__ = ["parse_point", "pool_datasets"]


def parse_point(text: str) -> dict[str, float | str]:
    """``growth_rate=0.001,p_target=1000`` -> ``{"growth_rate": 0.001, "p_target": 1000.0}``; ``base``: no dimension.

    Values that read as numbers are numbers; others stay strings (a shape family, a sample).
    """
    point: dict[str, float | str] = {}
    if text in ("", "base"):
        return point
    for part in text.split(","):
        key, sep, value = part.partition("=")
        if not sep or not key:
            raise ValueError(f"scan point {text!r}: {part!r} is not key=value")
        try:
            point[key] = float(value)
        except ValueError:
            point[key] = value
    return point


def _numeric_attrs(ds: xr.Dataset) -> dict[str, float]:
    # point_<key> attributes repeat the scan point, which the coordinates already hold
    return {k: float(v) for k, v in ds.attrs.items()
            if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            and not k.startswith("point_")}


def pool_datasets(paths: Sequence[str | os.PathLike], points: Sequence[Mapping[str, float | str]],
                  study: str) -> xr.Dataset:
    """Concatenate the datasets at ``paths`` along ``point``, labelled by their scan ``points``.

    Parameters
    ----------
    paths : sequence of path-like
        One dataset per kept scan point.
    points : sequence of mapping
        The scan point of each dataset (same keys for all).
    study : str
        Name of the study (stored as attribute ``study``).

    Returns
    -------
    xarray.Dataset
        Dimension ``point`` (size ``len(paths)``), one coordinate per key of the points,
        the inputs' variables along ``point`` (outer join on indexed dimensions), and
        ``attr_<name>(point)`` for each numeric attribute that is not the same in all inputs.
    """
    if len(paths) != len(points) or not paths:
        raise ValueError(f"pool: {len(paths)} datasets and {len(points)} scan points; give one point per dataset")
    keys = list(points[0])
    if any(list(p) != keys for p in points):
        raise ValueError(f"pool: every scan point needs the keys {keys}, got {[list(p) for p in points]}")
    datasets = [read_dataset(p) for p in paths]
    numeric = [_numeric_attrs(ds) for ds in datasets]
    varying = sorted(k for k in set().union(*numeric)
                     if len({n.get(k, np.nan) for n in numeric}) > 1 or any(k not in n for n in numeric))
    parts = []
    for ds, attrs in zip(datasets, numeric):
        ds = ds.copy()
        for k in varying:
            ds[f"attr_{k}"] = xr.DataArray(attrs.get(k, np.nan), attrs={"long_name": f"attribute {k} of the input"})
        ds.attrs = {}
        parts.append(ds)
    pooled = xr.concat(parts, dim="point", join="outer", data_vars="all", coords="different", compat="equals")
    for key in keys:
        values = [p[key] for p in points]
        pooled = pooled.assign_coords({key: ("point", np.asarray(values))})
        pooled[key].attrs["long_name"] = f"scan dimension {key}"
    pooled.attrs = new_dataset_attrs(f"jamflow study {study}", {"inputs": [str(p) for p in paths]},
                                     study=study, scan_dims=json.dumps(keys),
                                     inputs_attrs=json.dumps([dict(ds.attrs) for ds in datasets], default=str))
    return pooled
