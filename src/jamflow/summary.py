"""One table of a whole scene: a row per packing or flow run, with its scan point and key numbers.

The workflow writes (``docs/scenes.md``, :mod:`jamflow.scenes.plan`)
``results/<scene>/<bodies>/<point>/<sample>/<step>.nc`` (one packing per bodies, scan point,
sample and step), ``<step>.series.nc`` beside a flow step's final packing,
``<step>.<analysis>.nc`` for the analyses of a packing and ``results/<scene>/studies/`` for
the studies. :func:`load_scene` reads them and returns one row per packing and per flow run:

- packings: parameters (bodies, scan point, sample, stage, kappa, p_target, N, d, protocol,
  seed, and one column ``point_<dimension>`` per scan dimension) and numbers (phi, phi_J,
  pressure, backbone contacts N_c, the isostatic count d(N_s - 1) + 1, rattlers, number of
  LPs, max overlap, force-balance residual, certificate); each row also carries the gap
  exponent gamma and force exponent theta of the study that pooled it (the same value on
  every row of one study point), with their statistical and systematic errors, and the
  reason where the fit was refused;
- flow runs: the last record of the time series (strain, time, phi, pressure, shear
  stress, contacts) and, when a flow summary exists, the steady-state friction.

Every file is read as the kind of dataset its folder says (a flow series where a packing
should be is an error naming the file, not a row of blanks). Every number is read from
the datasets' own attributes or variables; nothing is
recomputed except the backbone counts of a packing that has contacts and rattler flags
but no count attributes (soft packings), which are counted from those variables.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import xarray as xr

from .io import dataset_kind, read_dataset
from .network import isostatic_count

__all__ = ["COLUMNS", "load_scene", "scene_results_dir"]

#: Columns of the scene table and what each holds (all dimensionless; see the datasets for units).
COLUMNS: dict[str, str] = {
    "scene": "scene name (the results folder)",
    "kind": "'packing' or 'run' (flow time series)",
    "body": "body block of the scene (spheres, linked-trimer, shapes-ellipse, ...)",
    "point": "scan point of the packing (key=value,... or base)",
    "sample": "sample (seed<S>)",
    "stage": "step of the chain that wrote the file (init, ls, calippso, soft-jam, shear, ...)",
    "kappa": "LS growth rate of the sample (NaN without LS)",
    "p_target": "LS target reduced pressure of the snapshot (NaN without LS)",
    "N": "number of particles",
    "d": "dimension",
    "protocol": "chain of stages that produced the packing",
    "seed": "seed of the random choices (-1 if none)",
    "phi": "packing fraction (runs: at the last record)",
    "phi_J": "jamming packing fraction (CALiPPSO packings; soft packings: phi at the target pressure P0)",
    "pressure": "reduced pressure of the packing or run (NaN if the stage does not define one)",
    "n_contacts": "backbone contacts N_c (rattlers removed); runs: contacts at the last record",
    "isostatic_count": "d (N_s - 1) + 1 for the N_s backbone particles",
    "isostatic": "1 if N_c equals the isostatic count, 0 if not, NaN if unknown",
    "n_rattlers": "rattlers",
    "counting_note": "why N_c differs from the isostatic count (CALiPPSO's hyperstatic packings); empty otherwise",
    "n_lp": "linear programs CALiPPSO used",
    "max_overlap": "largest overlap relative to the pair diameter (CALiPPSO packings)",
    "force_balance_residual": "largest per-particle force-balance residual relative to the mean force",
    "classification": "LP jamming certificate (jamflow certify) of the packing, if run",
    "gamma": "gap exponent, p(h) ~ h^-gamma, of the gaps study point that pooled this packing",
    "gamma_stat": "statistical error of gamma (bootstrap)",
    "gamma_sys": "systematic error of gamma (spread over the scanned fit windows)",
    "gamma_err": "combined error of gamma, sqrt(stat^2 + sys^2) (not a standard error)",
    "gamma_note": "why the gamma fit was refused (gamma NaN) or an error is undefined; empty otherwise",
    "theta": "small-force exponent, P(f) ~ f^theta, of the forces study point that pooled this packing",
    "theta_stat": "statistical error of theta (bootstrap)",
    "theta_sys": "systematic error of theta (spread over the scanned fit windows)",
    "theta_err": "combined error of theta, sqrt(stat^2 + sys^2) (not a standard error)",
    "theta_note": "why the theta fit was refused (theta NaN) or an error is undefined; empty otherwise",
    "strain": "runs: accumulated strain at the last record",
    "time": "runs: time at the last record",
    "shear_stress": "runs: shear stress at the last record",
    "friction": "runs: steady-state macroscopic friction <sigma_xy>/<p> (flow summary)",
    "file": "the dataset, relative to the results folder",
}

#: file suffixes that are not packings: flow series, LS equations of state, analyses
_NOT_PACKINGS = (".series.nc", ".eos.nc")


def scene_results_dir(path: str | os.PathLike) -> Path:
    """The results folder of a scene: ``path`` itself, or ``results/<scene>`` for a scene YAML.

    A scene file's results are looked up relative to the current directory, as
    Snakemake writes them (run from the repository root).
    """
    path = Path(path)
    if path.suffix in (".yaml", ".yml"):
        import yaml

        if not path.is_file():
            raise FileNotFoundError(f"no such scene file: {path}")
        scene = (yaml.safe_load(path.read_text()) or {}).get("scene")
        if not scene:
            raise ValueError(f"{path}: no 'scene' key, cannot find its results folder")
        path = Path("results") / str(scene)
    if not path.is_dir():
        raise FileNotFoundError(f"no results folder {path} (run the scene first, from the repository root)")
    if not any(path.glob("*/*/*/*.nc")):
        raise ValueError(f"{path} holds no <bodies>/<point>/<sample>/<step>.nc: not a scene results folder")
    return path


def load_scene(
    path: str | os.PathLike, as_: Literal["dataframe", "dataset"] = "dataframe"
) -> pd.DataFrame | xr.Dataset:
    """The table of a scene: one row per packing and per flow run (see :data:`COLUMNS`).

    Parameters
    ----------
    path : path-like
        A scene's results folder (``results/<scene>``) or its scene YAML file.
    as_ : {"dataframe", "dataset"}
        Return a :class:`pandas.DataFrame`, or an :class:`xarray.Dataset` with one
        dimension ``row`` and a ``long_name`` per variable.

    Returns
    -------
    pandas.DataFrame or xarray.Dataset
        Rows sorted by kind, body, sample, stage (in chain order) and scan point; the
        columns of :data:`COLUMNS`, then one ``point_<dimension>`` per scan dimension.
    """
    if as_ not in ("dataframe", "dataset"):
        raise ValueError(f"as_ must be 'dataframe' or 'dataset', got {as_!r}")
    root = scene_results_dir(path)
    files = sorted(f for f in root.glob("*/*/*/*.nc") if f.parts[-4] not in ("studies", "figures", "logs"))
    rows = [_packing_row(root, f) for f in files if f.name.count(".") == 1]
    _attach_studies(root, rows)
    rows += [_run_row(root, f) for f in files if f.name.endswith(".series.nc")]
    if not rows:
        raise ValueError(f"{root}: no packings or flow runs found")
    dims = sorted({k for row in rows for k in row.get("_point", {})})
    for row in rows:
        row["scene"] = root.name
        for k in dims:
            row[f"point_{k}"] = row.get("_point", {}).get(k, np.nan)
        row.pop("_point", None)
    table = pd.DataFrame(rows, columns=[*COLUMNS, *(f"point_{k}" for k in dims)])
    # stages in chain order (init, ls, calippso): by the number of steps of their protocol
    depth = table["protocol"].astype(str).str.count(">")
    table = (table.assign(_depth=depth)
             .sort_values(["kind", "body", "sample", "_depth", "stage", "point"], kind="stable", na_position="first")
             .drop(columns="_depth").reset_index(drop=True))
    if as_ == "dataframe":
        return table
    ds = xr.Dataset.from_dataframe(table.rename_axis("row"))
    for name, text in COLUMNS.items():
        ds[name].attrs["long_name"] = text
    for k in dims:
        ds[f"point_{k}"].attrs["long_name"] = f"scan dimension {k}"
    ds.attrs["title"] = f"jamflow scene summary: {root.name}"
    return ds


def _location(root: Path, path: Path) -> dict[str, Any]:
    """Bodies, scan point and sample of a file from its path, and the point's values from its attributes."""
    body, point, sample = path.relative_to(root).parts[:3]
    return {"body": body, "point": point, "sample": sample, "stage": path.name.split(".")[0]}


def _scan_point(attrs: dict[str, Any]) -> dict[str, Any]:
    text = attrs.get("scan_point")
    if not text:
        return {}
    return {k: v for k, v in json.loads(text).items() if k not in ("body", "sample", "seed")}


def _attr(attrs: dict[str, Any], key: str, default: Any = np.nan) -> Any:
    value = attrs.get(key, default)
    return value.item() if isinstance(value, np.generic) else value


def _packing_row(root: Path, path: Path) -> dict[str, Any]:
    ds = read_dataset(path, "packing")
    a = ds.attrs
    is_p_target = _attr(a, "target_kind", "") == "p"
    row: dict[str, Any] = {
        "kind": "packing", **_location(root, path),
        "kappa": float(_attr(a, "kappa")), "p_target": float(_attr(a, "target")) if is_p_target else np.nan,
        "N": int(_attr(a, "N")), "d": int(_attr(a, "d")), "protocol": _attr(a, "protocol", ""),
        "seed": int(_attr(a, "seed", -1)), "phi": float(_attr(a, "packing_fraction")),
        "pressure": float(_attr(a, "pressure")), "phi_J": float(_attr(a, "phi_J")),
        "n_lp": _attr(a, "n_lps", _attr(a, "iterations")), "max_overlap": _attr(a, "max_overlap"),
        "force_balance_residual": _attr(a, "force_balance_residual"),
        "file": path.relative_to(root).as_posix(), "_point": _scan_point(a),
    }
    if str(row["protocol"]).endswith(">soft") and "target_pressure" in a:
        # a soft packing brought to the target pressure P0 sits at the jamming onset to O(P0)
        row["phi_J"] = row["phi"]
    row.update(_network_counts(ds))
    row["counting_note"] = _counting_note(a)
    row["classification"] = ""
    certificate = path.with_name(f"{row['stage']}.certify.nc")
    if certificate.is_file():
        row["classification"] = read_dataset(certificate, ("certificate", "chain-certificate")).attrs["classification"]
    return row


def _counting_note(a: Mapping[str, Any]) -> str:
    """Why a CALiPPSO packing is hyperstatic (its contacts are the near-touching pairs, some
    without force), from its attributes; empty for every other packing."""
    if not int(a.get("hyperstatic", 0)):
        return ""
    n_c, iso = int(a["n_contacts"]), int(a["isostatic_count"])
    return (f"hyperstatic by {n_c - iso}: contacts are the pairs with relative gap <= "
            f"{float(a['contact_gap_tol']):g} (the LP's dual vertex has {int(a['n_contacts_dual'])}), "
            f"{int(a['n_zero_force_contacts'])} of them without force")


def _network_counts(ds: xr.Dataset) -> dict[str, Any]:
    """Backbone contacts, isostatic count and rattlers: the stage's attributes, else its variables."""
    a = ds.attrs
    if all(k in a for k in ("n_contacts", "isostatic_count", "n_rattlers")):
        n_c, iso, n_r = int(a["n_contacts"]), int(a["isostatic_count"]), int(a["n_rattlers"])
    elif "contact_i" in ds and "rattler" in ds:
        rattler = ds["rattler"].values.astype(bool)
        i, j = ds["contact_i"].values, ds["contact_j"].values
        n_c = int(np.sum(~(rattler[i] | rattler[j])))
        n_r = int(rattler.sum())
        d = int(a["d"])
        iso = isostatic_count(int((~rattler).sum()), d, global_dofs=d)
    else:
        return {"n_contacts": np.nan, "isostatic_count": np.nan, "isostatic": np.nan, "n_rattlers": np.nan}
    return {"n_contacts": n_c, "isostatic_count": iso, "isostatic": int(n_c == iso), "n_rattlers": n_r}


def _attach_studies(root: Path, rows: list[dict[str, Any]]) -> None:
    """Copy gamma and theta of each gaps and forces study point onto the rows of the packings it pooled
    (its ``inputs`` parameter)."""
    by_file = {row["file"]: row for row in rows}
    for path in sorted((root / "studies").glob("*/*.nc")):
        ds = read_dataset(path)
        a = ds.attrs
        name = {"gaps": "gamma", "forces": "theta"}.get(dataset_kind(ds) or "")
        if name is None or "fit_exponent" not in a:
            continue
        kind = (name, f"{name}_stat", f"{name}_sys", f"{name}_err", f"{name}_note")
        values = (*(float(a.get(f"fit_exponent{end}", np.nan)) for end in ("", "_stat", "_sys", "_err")),
                  str(a.get("fit_exponent_reason", "")))
        for name in json.loads(a.get("parameters", "{}")).get("inputs", []):
            relative = Path(name).as_posix().split(f"{root.name}/", 1)[-1]
            if relative in by_file:
                by_file[relative].update(zip(kind, values, strict=True))


def _run_row(root: Path, path: Path) -> dict[str, Any]:
    ds = read_dataset(path, ("flow", "aqs"))
    a = ds.attrs
    row: dict[str, Any] = {
        "kind": "run", **_location(root, path),
        "kappa": np.nan, "p_target": np.nan, "N": int(_attr(a, "N")), "d": int(_attr(a, "d")),
        "protocol": _attr(a, "protocol", _attr(a, "mode", "")), "seed": int(_attr(a, "seed", -1)),
        "file": path.relative_to(root).as_posix(), "classification": "", "_point": _scan_point(a),
    }
    last = {"phi": "packing_fraction", "pressure": "pressure", "n_contacts": "n_contacts",
            "strain": "strain", "time": "time", "shear_stress": "shear_stress"}
    for column, name in last.items():
        row[column] = float(ds[name].values[-1]) if name in ds.variables and ds[name].size else np.nan
    summary = path.with_name(f"{row['stage']}.flow-summary.nc")
    if summary.is_file():
        row["friction"] = float(read_dataset(summary, "flow-summary").attrs["friction_ratio_of_means"])
    return row
