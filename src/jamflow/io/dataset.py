"""Reading and writing: netCDF datasets (atomic), CALiPPSO ``.dat``, extended XYZ.

This is the only library module that touches files.
"""

from __future__ import annotations

import errno
import json
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from ..provenance import provenance_attrs
from ..state.packing import Packing, body_kind
from ..tolerances import OVERLAP_TOL

__all__ = [
    "DATASET_KINDS",
    "dataset_kind",
    "file_body_kind",
    "file_kind",
    "check_output_paths",
    "write_dataset",
    "read_dataset",
    "write_packing",
    "read_packing",
    "new_dataset_attrs",
    "write_table",
    "atomic_file",
]


#: Every kind of dataset jamflow writes: the variable or coordinate names its readers need
#: and what writes it. A dataset is of the first kind whose names it all holds, so the
#: more specific kinds come first (a jamming table also holds p_target and phi_J, a flow
#: series also holds packing_fraction and pressure). Commands name the kinds they read;
#: one check serves them all.
DATASET_KINDS: dict[str, tuple[frozenset[str], str]] = {
    "packing": (frozenset({"position", "diameter", "box"}),
                "a packing (jamflow init, import-dat, ls, calippso, soft-jam, --final)"),
    "gaps": (frozenset({"gap_density", "h"}), "a gap distribution (jamflow gaps)"),
    "forces": (frozenset({"P_linear", "f"}), "a force distribution (jamflow forces)"),
    "rdf": (frozenset({"g", "r"}), "a g(r) dataset (jamflow rdf)"),
    "jamming-table": (frozenset({"phi_J_LS", "kappa", "p_target"}), "a jamming table (jamflow jamming-table)"),
    "overlap-series": (frozenset({"p_target", "phi_J"}), "an overlap series (jamflow overlap-series)"),
    "overlap": (frozenset({"Q", "n_common"}), "a contact overlap (jamflow overlap)"),
    "flow-curve": (frozenset({"viscous_number", "friction", "packing_fraction"}),
                   "a flow curve mu(I), phi(I) (jamflow flow-curve)"),
    "flow-summary": (frozenset({"steady_mean", "strain", "shear_stress", "pressure"}),
                     "a flow summary (jamflow flow-summary)"),
    "flow": (frozenset({"strain", "time", "shear_stress", "pressure", "packing_fraction", "n_contacts"}),
             "a flow time series (jamflow compress, shear, drive, sd-shear)"),
    "aqs": (frozenset({"strain", "shear_stress", "pressure", "packing_fraction", "fire_steps"}),
            "an AQS stress-strain series (jamflow aqs)"),
    "eos": (frozenset({"packing_fraction", "pressure"}), "an LS equation of state (jamflow ls --eos)"),
    "certificate": (frozenset({"lp_objective", "unjamming_motion"}), "a jamming certificate (jamflow certify)"),
    "moduli": (frozenset({"bulk", "shear", "eigenvalue"}), "elastic moduli (jamflow moduli)"),
    "chain-certificate": (frozenset({"chain_rattler", "chain_motion"}),
                          "a jamming certificate of a linked packing (jamflow certify on links)"),
    "chain-moduli": (frozenset({"compliance", "bulk_hill", "shear_hill"}),
                     "compliance and moduli of a linked packing (jamflow moduli on links)"),
    "chains-moduli-table": (frozenset({"bulk_weighted", "shear_weighted", "n_packings"}),
                            "moduli of cemented packings against n_l / N (jamflow chains-moduli)"),
    "contact-angles": (frozenset({"P_psi", "psi"}), "a contact-angle distribution P(psi) (jamflow contact-angles)"),
    "shape-survey": (frozenset({"phi_J_mean", "z_eq3_mean", "group_asphericity"}),
                     "phi_J and <z> against asphericity (jamflow shape-survey)"),
    "constraint-curvature": (frozenset({"kappa1_mean", "kappa2_mean", "contact_type"}),
                             "constraint curvatures per contact type (jamflow constraint-curvature)"),
    "feasible-region": (frozenset({"volume", "surface", "shrink"}),
                        "the feasible region of a caged circulo-line (jamflow feasible-region)"),
    "modes": (frozenset({"eigenvalue", "region", "rotational_weight"}),
              "a dynamical-matrix spectrum of a shape packing (jamflow modes)"),
    "linked-modes": (frozenset({"eigenvalue", "mode_label", "mode_displacement"}),
                     "normal modes of a linked packing (jamflow modes on links)"),
    "tradeoff": (frozenset({"time", "on_front", "is_reference"}), "a speed/accuracy sweep (jamflow tradeoff)"),
    "checkpoint": (frozenset({"x", "h", "radius", "nl_pairs"}), "a flow checkpoint (--checkpoint)"),
    "calippso-checkpoint": (frozenset({"chain_x", "chain_D", "records_sqrt_gamma_minus_1"}),
                            "a CALiPPSO checkpoint (jamflow calippso --checkpoint)"),
    "snapshots": (frozenset({"snapshot_position", "snapshot_box"}), "flow snapshots (--snapshots)"),
}


def dataset_kind(ds: xr.Dataset) -> str | None:
    """The kind of a jamflow dataset (a key of :data:`DATASET_KINDS`), ``None`` if none fits."""
    names = set(ds.variables)
    for kind, (required, _) in DATASET_KINDS.items():
        if required <= names:
            return kind
    return None


def file_kind(path: str | os.PathLike) -> str | None:
    """The kind of dataset an existing file holds, without loading its data.

    A CALiPPSO ``.dat`` file is a packing; a file that is not netCDF (or is unreadable)
    is of no kind (``None``).
    """
    path = Path(path)
    if path.suffix == ".dat":
        return "packing"
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            return dataset_kind(ds)
    except (OSError, ValueError):
        return None


def check_output_paths(inputs: Sequence[str | os.PathLike], outputs: Sequence[str | os.PathLike],
                       allow_input: bool = False,
                       packing_outputs: Sequence[str | os.PathLike] = (),
                       kinds: Mapping[str, Sequence[str]] | None = None) -> list[str]:
    """Check output paths before any work is done; the one place of the overwrite policy.

    Refuses outputs that repeat each other, an output that is an input (unless
    ``allow_input``), and an existing file that an output would replace by another kind
    of file: a packing by anything but a packing; a jamflow dataset by another kind of
    dataset; a netCDF file that is no jamflow dataset (someone else's file, or a broken
    one); a jamflow dataset by a text or image file. An existing output of the kind the
    command writes is replaced (the writers then refuse another kind once more).

    Parameters
    ----------
    inputs, outputs : sequence of path-like
    allow_input : bool
        ``--in-place``: an output may be an input (of the same kind).
    packing_outputs : sequence of path-like
        The outputs that are packings.
    kinds : mapping of str to sequence of str, optional
        Output path -> the :data:`DATASET_KINDS` it may hold (an empty sequence: a file
        that is not netCDF, e.g. ``.xyz``, ``.png``, ``.csv``). Outputs missing here are
        checked only against clobbering a packing.

    Returns
    -------
    list of str
        One line per existing output that will be replaced (``path (what it holds)``).

    Raises
    ------
    ValueError
        One line naming the file.
    """
    kinds = {str(k): tuple(v) for k, v in (kinds or {}).items()}
    for out in packing_outputs:
        kinds[str(out)] = ("packing",)
    seen: dict[Path, str] = {}
    for out in outputs:
        key = Path(out).resolve()
        if key in seen:
            raise ValueError(f"{out} is given twice as an output")
        seen[key] = str(out)
    if not allow_input:
        for inp in inputs:
            for out in outputs:
                if Path(inp).resolve() == Path(out).resolve() or (
                        Path(inp).exists() and Path(out).exists() and os.path.samefile(inp, out)):
                    raise ValueError(f"output {out} is also an input: give another output path "
                                     "(or --in-place to replace the input)")
    replaced = []
    for out in outputs:
        held = _existing_output(Path(out), kinds.get(str(out)))
        if held is not None:
            replaced.append(f"{out} ({held})")
    return replaced


def _existing_output(path: Path, kinds: tuple[str, ...] | None) -> str | None:
    """What an existing output file holds, if it may be replaced; None when there is no file.

    Raises ``ValueError`` when the file is of another kind than ``kinds`` (see
    :func:`check_output_paths`).
    """
    if not path.exists():
        return None
    if not path.is_file():
        raise ValueError(f"output {path} exists and is not a file")
    held = file_kind(path)
    what = DATASET_KINDS[held][1] if held else None
    if kinds is None or held == "packing":
        if held == "packing" and kinds != ("packing",):
            _refuse_clobbering_a_packing(path, "this output is not a packing")
        return what or "a file"
    if not kinds:
        if held is not None:
            raise ValueError(f"refusing to overwrite {path}: it holds {what}, and this writes a {path.suffix} file")
        return f"a {path.suffix} file"
    if held in kinds:
        return what
    wanted = " or ".join(DATASET_KINDS[k][1] for k in kinds)
    holds = what or ("no jamflow dataset" if _is_netcdf(path) else "no netCDF data")
    raise ValueError(f"refusing to overwrite {path}: it holds {holds}, and this writes {wanted} "
                     "(remove it or give another output path)")


def _refuse_clobbering_a_packing(path: Path, writing: str) -> None:
    """Never replace a file that holds a packing by another kind of file."""
    if path.is_file() and file_kind(path) == "packing":
        raise ValueError(f"refusing to overwrite {path}: it holds a packing, and {writing}")


def _is_netcdf(path: Path) -> bool:
    """Whether ``path`` opens as netCDF (of any content)."""
    try:
        with xr.open_dataset(path, engine="netcdf4"):
            return True
    except (OSError, ValueError):
        return False


def new_dataset_attrs(title: str, parameters: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """Global attributes for a non-packing product: provenance, parameters as JSON."""
    attrs = provenance_attrs(title)
    attrs["parameters"] = json.dumps(parameters, sort_keys=True, default=str)
    attrs.update(extra)
    return attrs


def _netcdf_attr(value: Any) -> Any:
    """Attributes must be str, number or array: bools -> 0/1, dicts/lists -> JSON."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if value is None:
        return ""
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, sort_keys=True, default=str)
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_dataset(ds: xr.Dataset, path: str | os.PathLike) -> Path:
    """Write ``ds`` to netCDF4 atomically (temporary file in the same folder + rename).

    Variables are zlib-compressed. A process killed during the write leaves only a
    hidden ``.*.tmp`` file, never a partial file under ``path``.
    Raises ``ValueError`` rather than replace a file of another kind (:func:`check_output_paths`),
    and ``OSError`` (ENOSPC) naming the file when the disk is full.
    """
    path = Path(path)
    kind = dataset_kind(ds)
    if kind != "packing":
        _refuse_clobbering_a_packing(path, f"this writes {DATASET_KINDS[kind][1] if kind else 'a non-packing dataset'}")
    if path.is_file() and kind is not None:
        _existing_output(path, (kind,))
    path.parent.mkdir(parents=True, exist_ok=True)
    ds = ds.copy()
    for key, value in ds.attrs.items():
        if isinstance(value, int) and not isinstance(value, bool) and not -(2**63) <= value < 2**64:
            raise ValueError(f"attribute {key} = {value} does not fit a 64-bit netCDF integer (seeds are < 2**64)")
    ds.attrs = {k: _netcdf_attr(v) for k, v in ds.attrs.items()}
    for var in ds.variables.values():
        var.attrs = {k: _netcdf_attr(v) for k, v in var.attrs.items()}
    encoding = {
        name: {"zlib": True, "complevel": 4}
        for name, var in ds.data_vars.items()
        if var.dtype.kind in "biuf"
    }
    with _atomic(path) as (fd, tmp):
        os.close(fd)
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=encoding)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
    return path


def read_dataset(path: str | os.PathLike, kind: str | Sequence[str] | None = None) -> xr.Dataset:
    """Load a netCDF file fully into memory and close it.

    Parameters
    ----------
    path : path-like
    kind : str or sequence of str, optional
        Accepted kinds (keys of :data:`DATASET_KINDS`); any other dataset raises a
        ``ValueError`` naming the file, what it holds and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    try:
        ds = xr.load_dataset(path, engine="netcdf4")
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path} is not a readable netCDF file: {exc}") from exc
    if kind is not None:
        kinds = (kind,) if isinstance(kind, str) else tuple(kind)
        found = dataset_kind(ds)
        if found not in kinds:
            holds = DATASET_KINDS[found][1] if found else f"no jamflow dataset ({ds.attrs.get('title', 'no title')})"
            wanted = " or ".join(DATASET_KINDS[k][1] for k in kinds)
            missing = ", ".join(sorted(DATASET_KINDS[kinds[0]][0] - set(ds.variables)))
            raise ValueError(f"{path} holds {holds}, not {wanted} (missing variable(s) {missing})")
    return ds


def file_body_kind(path: str | os.PathLike) -> str | None:
    """The body kind (:attr:`Packing.body_kind`) of the packing in ``path``, read without loading its arrays.

    None when the file is not a readable packing dataset (its reader then says why).
    """
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            if dataset_kind(ds) != "packing":
                return None
            n_links = ds.sizes.get("link", 0) if "link_i" in ds.variables else 0
            return body_kind(ds.attrs.get("boundary"), n_links > 0, "shape_kind" in ds.variables)
    except (OSError, ValueError):
        return None


def write_packing(
    packing: Packing, path: str | os.PathLike, stage_parameters: dict[str, Any] | None = None
) -> Path:
    """Write a packing dataset atomically."""
    return write_dataset(packing.to_dataset(stage_parameters), path)


def read_packing(path: str | os.PathLike, overlap_tol: float | None = OVERLAP_TOL) -> Packing:
    """Read and validate a packing.

    Parameters
    ----------
    path : path-like
    overlap_tol : float or None
        Largest accepted relative overlap; ``None`` for soft packings.

    Raises
    ------
    ValueError, OverlapError
        Malformed file, bad shapes, non-finite values, centres outside the box,
        or overlaps beyond ``overlap_tol``.
    """
    packing = Packing.from_dataset(read_dataset(path, "packing"))
    packing.validate(overlap_tol)
    return packing


# --- CALiPPSO .dat ------------------------------------------------------------------


# --- extended XYZ (OVITO) -------------------------------------------------------------


def write_table(table: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a table atomically as CSV (``.csv``) or JSON records (``.json``; NaN as null)."""
    path = Path(path)
    if path.suffix == ".csv":
        text = table.to_csv(index=False)
    elif path.suffix == ".json":
        records = table.astype(object).where(table.notna(), None).to_dict(orient="records")
        text = json.dumps(records, indent=1, default=_netcdf_attr)
    else:
        raise ValueError(f"{path}: a table is written as .csv or .json")
    return _atomic_text(path, text)


@contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[Path]:
    """A hidden temporary path beside ``path`` to write to, renamed onto ``path`` on success.

    For writers that take a file name (figures): an exception or Ctrl-C leaves the
    previous file (or none) and no temporary; a full disk is named as such.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _atomic(path) as (fd, tmp):
        os.close(fd)
        yield Path(tmp)


def _atomic_text(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with _atomic(path) as (fd, _):
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    return path


@contextmanager
def _atomic(path: Path) -> Iterator[tuple[int, str]]:
    """Yield a temporary file beside ``path``; rename it onto ``path`` on success.

    Any exception (or a kill) leaves ``path`` untouched; the temporary is removed
    on exceptions.
    """
    try:
        fd, tmp = _temporary(path)
    except OSError as exc:
        raise _write_error(path, exc) from exc
    try:
        yield fd, tmp
        os.replace(tmp, path)
    except BaseException as exc:
        full = isinstance(exc, Exception) and _disk_full(path.parent)
        if os.path.exists(tmp):
            os.unlink(tmp)
        if full or isinstance(exc, OSError) and exc.errno in _FULL:
            raise _write_error(path, exc, full=True) from exc
        raise


#: errno values of a full disk or an exhausted quota
_FULL = {errno.ENOSPC, errno.EDQUOT}
#: A write that fails with less than this many bytes free [bytes] failed because the disk
#: is full: the netCDF library reports that as "Permission denied" or "HDF error".
_FULL_DISK_BYTES = 1 << 20


def _disk_full(folder: Path) -> bool:
    """Whether the file system of ``folder`` has (almost) no space left for a user."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < _FULL_DISK_BYTES


def _write_error(path: Path, exc: BaseException, full: bool = False) -> OSError:
    """The error of a failed write, naming the file and the reason the library hid (a full disk)."""
    if full or isinstance(exc, OSError) and exc.errno in _FULL or _disk_full(path.parent):
        return OSError(errno.ENOSPC, f"no space left on the device of {path.parent}: {path} not written "
                                     "(nothing half-written is left; free space and run again)")
    if isinstance(exc, PermissionError):
        return PermissionError(errno.EACCES, f"no permission to write in {path.parent}: {path} not written")
    return exc if isinstance(exc, OSError) else OSError(f"{path} not written: {exc}")


def _temporary(path: Path) -> tuple[int, str]:
    """Hidden temporary file beside ``path`` with the permissions a plain create gives.

    ``mkstemp`` creates mode 0600; the renamed result would otherwise be unreadable
    to the group (e.g. other users of a cluster project directory).
    """
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.fchmod(fd, 0o666 & ~umask)
    return fd, tmp
