"""A checkpoint is bound to its run: the one check that a resumed run is the same run."""

from __future__ import annotations

import hashlib
import json
import os

import numpy as np

__all__ = ["arrays_sha256", "check_binding"]


def arrays_sha256(*arrays: np.ndarray | None) -> str:
    """SHA-256 (hex) of the arrays' bytes in order, ``None`` hashed as a marker: the
    ``bound_input_sha256`` of a checkpoint's start."""
    digest = hashlib.sha256()
    for a in arrays:
        digest.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
    return digest.hexdigest()


def _flat(value: object, prefix: str = "") -> dict[str, object]:
    if isinstance(value, dict):
        return {k: v for key, sub in value.items() for k, v in _flat(sub, f"{prefix}{key}.").items()}
    return {prefix.rstrip("."): value}


def check_binding(path: str | os.PathLike, attrs: dict, binding: dict[str, str]) -> None:
    """Refuse a checkpoint whose start, run parameters or code differ from ``binding``.

    Parameters
    ----------
    path : path-like
        The checkpoint (named in the message).
    attrs : dict
        The checkpoint's attributes.
    binding : dict
        The resuming run's: ``bound_input_sha256`` (the start's arrays), ``bound_run``
        (JSON of its parameters, compared key by key), and optionally ``bound_code``
        (the code that may change the path, compared as a string).

    Raises
    ------
    ValueError
        One line naming the checkpoint and what differs.
    """
    if "bound_run" not in attrs or ("bound_code" in binding and "bound_code" not in attrs):
        raise ValueError(f"checkpoint {path} records no start, parameters or code (older jamflow): "
                         "remove it or choose another --checkpoint")
    differ = []
    if attrs["bound_input_sha256"] != binding["bound_input_sha256"]:
        differ.append("input packing")
    if "bound_code" in binding and attrs["bound_code"] != binding["bound_code"]:
        differ.append(f"code: {attrs['bound_code']} -> {binding['bound_code']}")
    old, new = _flat(json.loads(attrs["bound_run"])), _flat(json.loads(binding["bound_run"]))
    differ += [f"{k} ({old.get(k)} -> {new.get(k)})" for k in sorted(old.keys() | new.keys()) if old.get(k) != new.get(k)]
    if differ:
        raise ValueError(f"checkpoint {path} belongs to another run (different {', '.join(differ)}): "
                         "remove it or choose another --checkpoint")
