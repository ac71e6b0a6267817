"""One table of a whole scene: a row per packing or flow run, with its parameters and key numbers.

The workflow writes ``results/<scene>/packings/<sample>/<stage>[_k<kappa>_p<p_tar>].nc``
(one packing per sample and stage), ``results/<scene>/flow/<sample>/<run>.nc`` (flow time
series) and scene-level analyses in ``results/<scene>/analysis/`` (``gaps*.nc``,
``forces*.nc`` over samples, ``<sample>/certify*.nc`` per packing). :func:`load_scene`
reads them and returns one row per packing and per flow run:

- packings: parameters (sample, stage, kappa, p_target, N, d, protocol, seed) and numbers
  (phi, phi_J, pressure, backbone contacts N_c, the isostatic count d(N_s - 1) + 1,
  rattlers, number of LPs, max overlap, force-balance residual, certificate); each
  row also carries the scene-level gap exponent gamma and force exponent theta of the
  analysis over the samples of its stage and variant (the same value on every sample's
  row), with their standard errors;
- flow runs: the last record of the time series (strain, time, phi, pressure, shear
  stress, contacts) and, when a flow summary exists, the steady-state friction.

Every file is read as the kind of dataset its folder says (a flow series where a packing
should be is an error naming the file, not a row of blanks). Every number is read from
the datasets' own attributes or variables; nothing is
recomputed except the backbone counts of a packing that has contacts and rattler flags
but no count attributes (soft packings), which are counted from those variables.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import xarray as xr

from .io import read_dataset
from .network import isostatic_count

__all__ = ["COLUMNS", "load_scene", "scene_results_dir"]

#: Columns of the scene table and what each holds (all dimensionless; see the datasets for units).
COLUMNS: dict[str, str] = {
    "scene": "scene name (the results folder)",
    "kind": "'packing' or 'run' (flow time series)",
    "sample": "sample (seed<S> or import name)",
    "stage": "stage that wrote the file (init, ls, calippso, soft, shear_<condition>, ...)",
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
    "n_lp": "linear programs CALiPPSO used",
    "max_overlap": "largest overlap relative to the pair diameter (CALiPPSO packings)",
    "force_balance_residual": "largest per-particle force-balance residual relative to the mean force",
    "classification": "LP jamming certificate (jamflow certify) of the packing, if run",
    "gamma": "gap exponent, p(h) ~ h^-gamma, fitted over the samples of this stage and variant",
    "gamma_err": "standard error of gamma",
    "theta": "small-force exponent, P(f) ~ f^theta, over the samples of this stage and variant",
    "theta_err": "standard error of theta",
    "strain": "runs: accumulated strain at the last record",
    "time": "runs: time at the last record",
    "shear_stress": "runs: shear stress at the last record",
    "friction": "runs: steady-state macroscopic friction <sigma_xy>/<p> (flow summary)",
    "file": "the dataset, relative to the results folder",
}

_VARIANT = re.compile(r"^(?P<stage>.+?)(?P<variant>_k[^_]+_p[^_]+)?$")


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
    if not (path / "packings").is_dir() and not (path / "flow").is_dir():
        raise ValueError(f"{path} has neither packings/ nor flow/: not a scene results folder")
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
        Rows sorted by kind, sample, stage (in chain order), kappa and p_target.
    """
    if as_ not in ("dataframe", "dataset"):
        raise ValueError(f"as_ must be 'dataframe' or 'dataset', got {as_!r}")
    root = scene_results_dir(path)
    rows = [_packing_row(root, f) for f in sorted(root.glob("packings/*/*.nc")) if not f.name.endswith(".eos.nc")]
    _attach_scene_analyses(root, rows)
    rows += [_run_row(root, f) for f in sorted(root.glob("flow/*/*.nc")) if _is_series(f)]
    if not rows:
        raise ValueError(f"{root}: no packings or flow runs found")
    for row in rows:
        row["scene"] = root.name
    table = pd.DataFrame(rows, columns=list(COLUMNS))
    # stages in chain order (init, ls, calippso): by the number of steps of their protocol
    depth = table["protocol"].astype(str).str.count(">")
    table = (table.assign(_depth=depth)
             .sort_values(["kind", "sample", "_depth", "stage", "kappa", "p_target"], kind="stable", na_position="first")
             .drop(columns="_depth").reset_index(drop=True))
    if as_ == "dataframe":
        return table
    ds = xr.Dataset.from_dataframe(table.rename_axis("row"))
    for name, text in COLUMNS.items():
        ds[name].attrs["long_name"] = text
    ds.attrs["title"] = f"jamflow scene summary: {root.name}"
    return ds


def _split_name(name: str) -> tuple[str, str]:
    """``calippso_k0.001_p1e+06`` -> (``calippso``, ``_k0.001_p1e+06``)."""
    m = _VARIANT.match(name)
    return m["stage"], m["variant"] or ""


def _attr(attrs: dict[str, Any], key: str, default: Any = np.nan) -> Any:
    value = attrs.get(key, default)
    return value.item() if isinstance(value, np.generic) else value


def _packing_row(root: Path, path: Path) -> dict[str, Any]:
    ds = read_dataset(path, "packing")
    a = ds.attrs
    stage, variant = _split_name(path.stem)
    is_p_target = _attr(a, "target_kind", "") == "p"
    row: dict[str, Any] = {
        "kind": "packing", "sample": path.parent.name, "stage": stage,
        "kappa": float(_attr(a, "kappa")), "p_target": float(_attr(a, "target")) if is_p_target else np.nan,
        "N": int(_attr(a, "N")), "d": int(_attr(a, "d")), "protocol": _attr(a, "protocol", ""),
        "seed": int(_attr(a, "seed", -1)), "phi": float(_attr(a, "packing_fraction")),
        "pressure": float(_attr(a, "pressure")), "phi_J": float(_attr(a, "phi_J")),
        "n_lp": _attr(a, "n_lps", _attr(a, "iterations")), "max_overlap": _attr(a, "max_overlap"),
        "force_balance_residual": _attr(a, "force_balance_residual"),
        "file": path.relative_to(root).as_posix(), "_variant": variant,
    }
    if str(row["protocol"]).endswith(">soft") and "target_pressure" in a:
        # a soft packing brought to the target pressure P0 sits at the jamming onset to O(P0)
        row["phi_J"] = row["phi"]
    row.update(_network_counts(ds))
    row["classification"] = ""
    certificate = root / "analysis" / path.parent.name / f"certify{variant}.nc"
    if certificate.is_file():
        cert = read_dataset(certificate, ("certificate", "chain-certificate")).attrs
        # a sample's certificate is of one stage's packing (the chain's last), named by its protocol
        if cert.get("packing_protocol") == row["protocol"]:
            row["classification"] = cert["classification"]
    return row


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


def _attach_scene_analyses(root: Path, rows: list[dict[str, Any]]) -> None:
    """Copy gamma and theta of each scene-level analysis onto the rows of its stage and variant.

    ``analysis/gaps<variant>.nc`` and ``forces<variant>.nc`` analyse the packings of the
    last stage of the chain; ``analysis/ls-gaps<variant>.nc`` the LS snapshots.
    """
    if not rows:
        return
    # the chain's last stage: the one whose protocol has the most steps
    final = max(rows, key=lambda r: str(r["protocol"]).count(">"))["stage"]
    for kind, stage_of, columns in (("gaps", lambda p: "ls" if p == "ls-gaps" else final, ("gamma", "gamma_err")),
                                    ("forces", lambda p: final, ("theta", "theta_err"))):
        for path in sorted((root / "analysis").glob(f"*{kind}*.nc")):
            prefix, variant = _split_name(path.stem)
            if prefix not in (kind, f"ls-{kind}"):
                continue
            a = read_dataset(path, kind).attrs
            values = (float(a["fit_exponent"]), float(a["fit_exponent_err"]))
            for row in rows:
                if row["stage"] == stage_of(prefix) and row["_variant"] == variant:
                    row.update(zip(columns, values, strict=True))
    for row in rows:
        del row["_variant"]


def _is_series(path: Path) -> bool:
    """A flow time series (not a final packing, snapshots or checkpoint)."""
    return not path.name.endswith(("_final.nc", ".snapshots.nc")) and "checkpoint" not in path.name


def _run_row(root: Path, path: Path) -> dict[str, Any]:
    ds = read_dataset(path, ("flow", "aqs"))
    a = ds.attrs
    row: dict[str, Any] = {
        "kind": "run", "sample": path.parent.name, "stage": path.stem,
        "kappa": np.nan, "p_target": np.nan, "N": int(_attr(a, "N")), "d": int(_attr(a, "d")),
        "protocol": _attr(a, "protocol", _attr(a, "mode", "")), "seed": int(_attr(a, "seed", -1)),
        "file": path.relative_to(root).as_posix(), "classification": "",
    }
    last = {"phi": "packing_fraction", "pressure": "pressure", "n_contacts": "n_contacts",
            "strain": "strain", "time": "time", "shear_stress": "shear_stress"}
    for column, name in last.items():
        row[column] = float(ds[name].values[-1]) if name in ds.variables and ds[name].size else np.nan
    summary = root / "analysis" / path.parent.name / f"{path.stem}_summary.nc"
    if summary.is_file():
        row["friction"] = float(read_dataset(summary, "flow-summary").attrs["friction_ratio_of_means"])
    return row
