"""Checkpoint and resume of a CALiPPSO chain.

A chain of N = 8192-16384 spheres runs for hours, longer than many cluster jobs may.
A checkpoint is a netCDF file (written atomically with :func:`jamflow.io.write_dataset`)
holding everything Algorithm 1 carries from one LP to the next, taken at the top of an
iteration, before its LP is set up: the chain (:class:`~.state._Chain`: positions,
diameters, rows, bound phase, recovery and stall counters, every record so far) and
the solver's carried basis with the rows it belongs to. The solver's other settings
follow from the options, which the checkpoint must match (:func:`chain_binding`), and
:mod:`jamflow.simplex` draws its perturbation from a fixed seed per LP, so a resumed
chain repeats the uninterrupted one bit for bit.
"""

from __future__ import annotations

import json
import os
from dataclasses import fields
from typing import Any

import numpy as np
import xarray as xr

from ...io import new_dataset_attrs, read_dataset, write_dataset
from ...io.binding import arrays_sha256, check_binding
from ...provenance import git_sha, jamflow_version
from ...state.packing import Packing
from .lp import _Rows
from .options import _Options
from .record import IterationRecord, _NewtonAttempt
from .solver import _Basis, _Solver
from .state import _Chain

__all__ = ["CHECKPOINT_EVERY", "ChainStopped", "chain_binding", "load_checkpoint", "save_checkpoint"]

#: Wall time [s] between checkpoint writes: a job killed at any moment loses at most this
#: much. A write at N = 16384 (108155 rows) costs 0.13-0.21 s of CPU and 1 MB, a warm LP
#: there 20-110 s.
CHECKPOINT_EVERY: float = 60.0

#: The chain's lists of records and the dataclass of their entries.
_RECORD_LISTS: dict[str, type] = {"records": IterationRecord, "newton": _NewtonAttempt}

#: netCDF type and Python type of each record field's annotation (strings under
#: ``from __future__ import annotations``).
_FIELD_TYPES: dict[str, tuple[type, type]] = {"int": (np.int64, int), "float": (np.float64, float),
                                              "bool": (np.int8, bool), "str": (str, str)}

#: Options that may differ on resume: the total LP budget (a resumed chain may be given more).
_UNBOUND_OPTIONS: frozenset[str] = frozenset({"max_iterations"})


class ChainStopped(RuntimeError):
    """The chain stopped on its LP budget for this run (``stop_after``); its checkpoint holds it."""


def chain_binding(packing: Packing, opt: _Options) -> dict[str, str]:
    """What a checkpoint must match to be resumed: the start, every option of the path
    and the code (another version may take another path).

    Returns
    -------
    dict
        ``bound_input_sha256``: SHA-256 of the start's positions, diameters and box;
        ``bound_run``: JSON of the options but :data:`_UNBOUND_OPTIONS`; ``bound_code``:
        jamflow's version and git commit.
    """
    run = {k: v for k, v in opt.settings().items() if k not in _UNBOUND_OPTIONS}
    run["require_isostatic"] = opt.require_isostatic
    return {"bound_input_sha256": arrays_sha256(packing.position, packing.diameter, packing.box.matrix),
            "bound_run": json.dumps(run, sort_keys=True),
            "bound_code": f"jamflow {jamflow_version()} ({git_sha()})"}


def _array(name: str, value: np.ndarray, long_name: str) -> tuple[str, tuple]:
    dims = tuple(f"{name}_{k}" for k in range(value.ndim))
    return name, (dims, value, {"units": "1", "long_name": long_name})


def _rows_vars(prefix: str, rows: _Rows) -> dict[str, tuple]:
    return dict(_array(f"{prefix}_{f.name}", np.asarray(getattr(rows, f.name)), f"rows: {f.name}")
                for f in fields(_Rows) if f.name != "cutoff")


def _rows_from(ds: xr.Dataset, prefix: str, cutoff: float) -> _Rows:
    return _Rows(**{f.name: ds[f"{prefix}_{f.name}"].values.copy() for f in fields(_Rows) if f.name != "cutoff"},
                 cutoff=cutoff)


def _table_vars(name: str, entries: list, cls: type) -> dict[str, tuple]:
    out = {}
    for f in fields(cls):
        values = np.array([getattr(e, f.name) for e in entries], dtype=_FIELD_TYPES[f.type][0])
        out[f"{name}_{f.name}"] = ((f"{name}_entry",), values, {"units": "1", "long_name": f"{name}: {f.name}"})
    return out


def _table_from(ds: xr.Dataset, name: str, n: int, cls: type) -> list:
    columns = {f.name: (ds[f"{name}_{f.name}"].values, _FIELD_TYPES[f.type][1]) for f in fields(cls)}
    return [cls(**{k: cast(v[i]) for k, (v, cast) in columns.items()}) for i in range(n)]


def save_checkpoint(path: str | os.PathLike, iteration: int, chain: _Chain, solver: _Solver, elapsed: float,
                    binding: dict[str, str]) -> None:
    """Write the chain and the solver's carried basis at the top of ``iteration`` to ``path`` (atomic).

    Parameters
    ----------
    path : path-like
    iteration : int
        The LP the resumed chain starts with (1-based).
    chain, solver
        The chain's state and its solver (only the carried basis and ``crash_first`` are
        stored; the rest follows from the options).
    elapsed : float
        Wall time [s] the chain has taken so far, over every run.
    binding : dict
        :func:`chain_binding` of the start and options.

    Raises
    ------
    TypeError
        A field of the chain that this module cannot store (a new field must be added here).
    """
    data: dict[str, tuple] = {}
    scalars: dict[str, Any] = {}
    absent: list[str] = []
    for f in fields(_Chain):
        value = getattr(chain, f.name)
        if value is None:
            absent.append(f.name)
        elif f.name in _RECORD_LISTS:
            data.update(_table_vars(f.name, value, _RECORD_LISTS[f.name]))
            scalars[f"n_{f.name}"] = len(value)
        elif isinstance(value, _Rows):
            data.update(_rows_vars("chain_rows", value))
            scalars["rows_cutoff"] = value.cutoff
        elif isinstance(value, np.ndarray):
            data.update([_array(f"chain_{f.name}", value, f"chain: {f.name}")])
        elif isinstance(value, bytes):
            data.update([_array(f"chain_{f.name}", np.frombuffer(value, dtype=np.uint8), f"chain: {f.name} (bytes)")])
        elif isinstance(value, (bool, int, float, str)):
            scalars[f.name] = value
        else:
            raise TypeError(f"a checkpoint cannot store the chain's field {f.name!r} of type {type(value).__name__}")
    if solver.basis is not None:
        col, row = solver.basis.statuses()
        data.update([_array("basis_col", col, "carried basis: column statuses (HiGHS codes)"),
                     _array("basis_row", row, "carried basis: row statuses (HiGHS codes)")])
    rows = solver.basis_rows
    scalars["basis_rows"] = "none" if rows is None else "chain" if rows is chain.rows else "own"
    if scalars["basis_rows"] == "own":
        data.update(_rows_vars("basis_rows", rows))
        scalars["basis_rows_cutoff"] = rows.cutoff
    scalars["crash_first"] = solver.crash_first
    attrs = dict(iteration=iteration, elapsed=elapsed, chain_scalars=json.dumps(scalars), chain_absent=json.dumps(absent),
                 **binding)
    write_dataset(xr.Dataset(data, attrs=new_dataset_attrs("jamflow calippso checkpoint", {}, **attrs)), path)


def load_checkpoint(path: str | os.PathLike, chain: _Chain, solver: _Solver,
                    binding: dict[str, str]) -> tuple[int, float]:
    """Restore ``chain`` and ``solver``'s carried basis (in place) from a checkpoint of the same chain.

    Returns
    -------
    iteration : int
        The LP to go on with.
    elapsed : float
        Wall time [s] the chain took before the checkpoint.

    Raises
    ------
    ValueError
        The checkpoint is of another start or other options (one line naming what differs).
    """
    ds = read_dataset(path, "calippso-checkpoint")
    check_binding(path, ds.attrs, binding)
    scalars, absent = json.loads(ds.attrs["chain_scalars"]), set(json.loads(ds.attrs["chain_absent"]))
    for f in fields(_Chain):
        if f.name in absent:
            value = None
        elif f.name in _RECORD_LISTS:
            value = _table_from(ds, f.name, scalars[f"n_{f.name}"], _RECORD_LISTS[f.name])
        elif f.name == "rows":
            value = _rows_from(ds, "chain_rows", scalars["rows_cutoff"])
        elif f.name in scalars:
            value = scalars[f.name]
        elif ds[f"chain_{f.name}"].dtype == np.uint8 and f.type.startswith("bytes"):
            value = ds[f"chain_{f.name}"].values.tobytes()
        else:
            value = ds[f"chain_{f.name}"].values.copy()
        setattr(chain, f.name, value)
    solver.basis = (_Basis(col=ds["basis_col"].values.astype(np.int8), row=ds["basis_row"].values.astype(np.int8))
                    if "basis_col" in ds else None)
    solver.basis_rows = {"none": None, "chain": chain.rows}.get(scalars["basis_rows"])
    if scalars["basis_rows"] == "own":
        solver.basis_rows = _rows_from(ds, "basis_rows", scalars["basis_rows_cutoff"])
    solver.crash_first = scalars["crash_first"]
    return int(ds.attrs["iteration"]), float(ds.attrs["elapsed"])
