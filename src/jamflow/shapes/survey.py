"""Jamming onset against asphericity: phi_J and <z> over shapes (VanderWerf et al. Figs. 5, 8).

One row per jammed packing (family, asphericity ``A``, ``phi_J``, the counts of
:mod:`jamflow.shapes.counting`), then the mean and standard error of the mean of
``phi_J`` and ``<z>`` over the packings of each (family, ``A``) group. Bidisperse
disk packings of the sphere code enter as the family ``disk`` at ``A = 1``, counted
with the same rules (rattlers: fewer than three contacts; Eq. 3 with no sliders,
``<z> = 2 (N_c + 1) / (N - N_r)``, exactly 4 for an isostatic disk backbone), so the
disk limit ``A -> 1`` of the shapes can be compared with them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from ..network import isostatic_count, prune_rattlers, rigidity_counting
from ..state.packing import Packing
from .counting import count_constraints

__all__ = ["DISK_FAMILY", "shape_label", "survey_dataset", "survey_row"]

#: Count stored for families without contact points (their <z> is NaN).

#: Family name of plain (sphere-code) disk packings in a survey.
DISK_FAMILY: str = "disk"


def shape_label(packing: Packing) -> str:
    """The shape family of a packing as a label: ``ellipse``, ``circulo_line``,
    ``circulo_polygon_<n>`` (``n`` sides), ``reuleaux``; ``disk`` without shapes."""
    if packing.shapes is None:
        if packing.d != 2:
            raise ValueError(f"a shape survey takes 2D packings, got d = {packing.d}")
        return DISK_FAMILY
    kinds = sorted(set(packing.shapes.kind))
    if len(kinds) != 1:
        raise ValueError(f"a survey row needs one shape kind per packing, got {kinds}")
    if kinds[0] == "circulo_polygon":
        sides = sorted({int(v) for v in packing.shapes.n_vertices})
        return f"circulo_polygon_{sides[0]}" if len(sides) == 1 else "circulo_polygon"
    return kinds[0]


def survey_row(packing: Packing, parallel: str = "once") -> dict:
    """``family``, ``asphericity``, ``N``, ``phi_J``, ``pressure`` and the counts of one packing.

    A shape packing is counted by :func:`~jamflow.shapes.counting.count_constraints`
    (contacts from its energy model); a disk packing from its stored contacts.
    """
    family = shape_label(packing)
    n = packing.n
    if family == DISK_FAMILY:
        if packing.contacts is None:
            raise ValueError("a disk packing in a survey needs its contacts (a soft-jam output)")
        rattler = prune_rattlers(packing.contacts, n, dofs_per_body=2)
        live = ~(rattler[packing.contacts[:, 0]] | rattler[packing.contacts[:, 1]])
        n_c, n_r, n_s = int(live.sum()), int(rattler.sum()), 0
        n_iso = isostatic_count(n - n_r, 2, global_dofs=2) if n > n_r else 0
        z = 2.0 * (n_c + 1) / (n - n_r) if n > n_r else 0.0
        asphericity = 1.0
    else:
        c, _, _, _ = count_constraints(packing, parallel)
        n_c, n_r, n_s, z, n_iso = c.n_contacts, c.n_rattlers, c.n_sliders, c.z, c.isostatic_count
        areas = packing.shapes.area[packing.shape_index]
        # both species share A (bidisperse copies of one shape); the area-weighted mean guards the rest
        asphericity = float(np.sum(packing.shapes.asphericity[packing.shape_index] * areas) / areas.sum())
    return dict(family=family, asphericity=asphericity, N=n, phi_J=packing.packing_fraction,
                pressure=float(packing.pressure if packing.pressure is not None else np.nan),
                n_contacts=n_c, n_rattlers=n_r, n_sliders=n_s, z=z, isostatic_count=n_iso,
                counting=rigidity_counting(n_c, n_iso))


def _group_stats(values: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the mean (0 for one value)."""
    sem = float(np.std(values, ddof=1) / np.sqrt(values.size)) if values.size > 1 else 0.0
    return float(np.mean(values)), sem


def survey_dataset(rows: Sequence[dict], sources: Sequence[str]) -> xr.Dataset:
    """The survey of ``rows`` (:func:`survey_row`) as a dataset.

    Dims ``packing`` (one per row, ``source`` the input file) and ``group`` (one per
    family and asphericity, sorted), with ``phi_J_mean``, ``phi_J_sem``, ``z_mean``,
    ``z_sem`` and ``n_packings`` per group.
    """
    if not rows:
        raise ValueError("a survey needs at least one packing")
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    keys = sorted({(r["family"], r["asphericity"]) for r in rows})
    stats = {name: [] for name in ("phi_J_mean", "phi_J_sem", "z_mean", "z_sem", "n_packings", "N")}
    for family, a in keys:
        sel = (col["family"] == family) & (col["asphericity"] == a)
        for q in ("phi_J", "z"):
            m, s = _group_stats(col[q][sel].astype(float))
            stats[f"{q}_mean"].append(m)
            stats[f"{q}_sem"].append(s)
        stats["n_packings"].append(int(sel.sum()))
        stats["N"].append(int(np.max(col["N"][sel])))
    p, g = ("packing",), ("group",)
    one = {"units": "1"}
    return xr.Dataset(
        data_vars={
            "phi_J": (p, col["phi_J"].astype(float), {**one, "long_name": "packing fraction at P0 (phi_J)"}),
            "z": (p, col["z"].astype(float), {**one, "long_name": "mean contact number <z> (Eq. 3)"}),
            "n_contacts": (p, col["n_contacts"].astype(np.int64), {**one, "long_name": "contacts between non-rattlers"}),
            "n_rattlers": (p, col["n_rattlers"].astype(np.int64), {**one, "long_name": "rattlers"}),
            "n_sliders": (p, col["n_sliders"].astype(np.int64), {**one, "long_name": "sliders"}),
            "isostatic_count": (p, col["isostatic_count"].astype(np.int64),
                                {**one, "long_name": "isostatic contact count N_c^0 (3N' - 1 - N_s; disks 2N' - 1)"}),
            "pressure": (p, col["pressure"].astype(float), {**one, "long_name": "pressure P0 [k]"}),
            "N": (p, col["N"].astype(np.int64), {**one, "long_name": "number of bodies"}),
            "phi_J_mean": (g, np.array(stats["phi_J_mean"]), {**one, "long_name": "mean phi_J of the group"}),
            "phi_J_sem": (g, np.array(stats["phi_J_sem"]), {**one, "long_name": "standard error of the mean phi_J"}),
            "z_mean": (g, np.array(stats["z_mean"]), {**one, "long_name": "mean <z> of the group"}),
            "z_sem": (g, np.array(stats["z_sem"]), {**one, "long_name": "standard error of the mean <z>"}),
            "n_packings": (g, np.array(stats["n_packings"], dtype=np.int64), {**one, "long_name": "packings in the group"}),
            "group_N": (g, np.array(stats["N"], dtype=np.int64), {**one, "long_name": "largest N in the group"}),
        },
        coords={
            "family": (p, col["family"].astype(str), {"long_name": "shape family"}),
            "asphericity": (p, col["asphericity"].astype(float), {**one, "long_name": "asphericity A = p^2 / (4 pi a)"}),
            "source": (p, np.array(sources, dtype=str), {"long_name": "input packing file"}),
            "counting": (p, col["counting"].astype(str), {"long_name": "hypostatic / isostatic / hyperstatic"}),
            "group_family": (g, np.array([k[0] for k in keys], dtype=str), {"long_name": "shape family of the group"}),
            "group_asphericity": (g, np.array([k[1] for k in keys]), {**one, "long_name": "asphericity of the group"}),
        },
    )
