"""Jamming onset against asphericity: phi_J and <z> over shapes (VanderWerf et al. Figs. 5, 6, 8).

One row per packing (family, asphericity ``A``, ``phi_J``, the counts of
:mod:`jamflow.shapes.counting` under each contact convention), then the mean and
standard error of the mean of ``phi_J`` and of the coordination numbers over the
jammed packings of each (family, ``A``) group.

Contact conventions (dimension ``convention``):

- ``once``: a parallel or nearly parallel circulo contact is one contact (Fig. 6,
  asterisks);
- ``twice``: it is two (Fig. 6, plus signs; App. A: two end-middle contacts);
- ``spectral``: ``N_c = N_c^0 - N_1`` with ``N_1`` the quartic (region-1) modes of the
  dynamical matrix (:mod:`jamflow.shapes.spectrum`) and ``N_c^0``, rattlers and
  sliders of the ``twice`` count: Fig. 8's definition for circulo shapes. Computed
  with ``spectral=True`` (NaN otherwise).

Ellipses, Reuleaux triangles and disks have no parallel contacts (``once`` equals
``twice``). Two coordination numbers per convention: ``z_contacts = 2 N_c / N'`` and
Eq. 3's ``z_eq3 = 2 (N_c + 1) / (N - N_r - N_s / f)``.

Bidisperse disk packings of the sphere code enter as the family ``disk`` at ``A = 1``,
counted from their stored contacts with the same rules (rattlers: fewer than three
contacts; no sliders; ``z_eq3`` exactly 4 for an isostatic disk backbone), one count in
every convention, so the disk limit ``A -> 1`` of the shapes can be compared with them.

Only packings jammed by ``soft-jam`` (a positive pressure and the ``soft`` protocol) are
accepted; a jammed packing whose every body rattles is kept as a row with
``jammed = 0`` and its reason, and left out of the group means.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from ..network import isostatic_count, prune_rattlers, rigidity_counting
from ..state.packing import Packing
from .counting import PARALLEL_MODES, coordination, count_constraints

__all__ = ["CONVENTIONS", "DISK_FAMILY", "check_jammed", "packing_asphericity", "shape_label", "survey_dataset",
           "survey_row"]

#: Family name of plain (sphere-code) disk packings in a survey.
DISK_FAMILY: str = "disk"

#: Contact conventions of a survey (module doc).
CONVENTIONS: tuple[str, ...] = (*PARALLEL_MODES, "spectral")

#: Packings whose asphericities agree to this many decimals form one group.
ASPHERICITY_DECIMALS: int = 12

#: Count columns stored per convention.
_COUNTS = ("n_contacts", "n_rattlers", "n_sliders", "isostatic_count", "z_contacts", "z_eq3")


def shape_label(packing: Packing) -> str:
    """The shape family of a packing as a label: ``ellipse``, ``circulo_line``,
    ``circulo_polygon_<n>`` (``n`` sides), ``reuleaux``, ``dumbbell``; ``disk`` without shapes."""
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


def packing_asphericity(packing: Packing) -> float:
    """The asphericity ``A`` of a shape packing's bodies (area-weighted mean; both species share it)."""
    areas = packing.shapes.area[packing.shape_index]
    return float(np.sum(packing.shapes.asphericity[packing.shape_index] * areas) / areas.sum())


def check_jammed(packing: Packing, source: str = "packing") -> None:
    """Refuse a packing that ``soft-jam`` did not jam (a random start, a minimised but unjammed state).

    Raises
    ------
    ValueError
        Without a positive pressure or without the ``soft`` jamming protocol in its history.
    """
    protocol = packing.protocol or ""
    if packing.pressure is None or not packing.pressure > 0.0 or "soft" not in protocol:
        raise ValueError(f"{source}: not jammed by soft-jam (protocol {protocol or 'unknown'!r}, pressure "
                         f"{packing.pressure}): jam it first (jamflow soft-jam IN OUT --pressure P0)")


def _disk_counts(packing: Packing) -> dict:
    if packing.contacts is None:
        raise ValueError("a disk packing in a survey needs its contacts (a soft-jam output)")
    n = packing.n
    rattler = prune_rattlers(packing.contacts, n, dofs_per_body=2)
    live = ~(rattler[packing.contacts[:, 0]] | rattler[packing.contacts[:, 1]])
    n_c, n_r = int(live.sum()), int(rattler.sum())
    z_contacts, z_eq3 = coordination(n_c, n, n_r, 0, 2)
    one = dict(n_contacts=n_c, n_rattlers=n_r, n_sliders=0, isostatic_count=isostatic_count(n - n_r, 2, global_dofs=2),
               z_contacts=z_contacts, z_eq3=z_eq3)
    return {c: one for c in CONVENTIONS}


def _shape_counts(packing: Packing, spectral: bool, lambda_c: float | None) -> tuple[dict, int]:
    counts = {}
    for mode in PARALLEL_MODES:
        c, *_ = count_constraints(packing, mode)
        counts[mode] = {k: getattr(c, k) for k in _COUNTS}
    dofs = c.dofs_per_body
    if not spectral:
        counts["spectral"] = {k: np.nan for k in _COUNTS}
        return counts, -1
    from .spectrum import spectrum

    spec = spectrum(packing, lambda_c, fourth=False)
    twice = counts["twice"]
    n_c = twice["isostatic_count"] - spec.n_quartic
    z_contacts, z_eq3 = coordination(n_c, packing.n, twice["n_rattlers"], twice["n_sliders"], dofs)
    counts["spectral"] = {**twice, "n_contacts": n_c, "z_contacts": z_contacts, "z_eq3": z_eq3}
    return counts, spec.n_quartic


def survey_row(packing: Packing, spectral: bool = False, lambda_c: float | None = None,
               source: str = "packing") -> dict:
    """``family``, ``asphericity``, ``N``, ``phi_J``, ``pressure``, ``jammed`` and the counts of one packing.

    Parameters
    ----------
    packing : Packing
        A ``soft-jam`` output (:func:`check_jammed`): shapes (counted by
        :func:`~jamflow.shapes.counting.count_constraints`) or disks (their stored contacts).
    spectral : bool
        Also the spectral count ``N_c^0 - N_1`` (a dense eigensolve of the ``3N x 3N``
        dynamical matrix).
    lambda_c : float, optional
        Region-1 cutoff of the spectrum (default: the widest admissible gap,
        :func:`jamflow.shapes.spectrum.spectrum`).
    source : str
        Name of the packing in error messages.

    Returns
    -------
    dict
        Scalars, ``counts`` (convention -> count columns) and ``n_quartic`` (-1 unless spectral).
    """
    check_jammed(packing, source)
    family = shape_label(packing)
    if family == DISK_FAMILY:
        counts, n_quartic, asphericity = _disk_counts(packing), -1, 1.0
    else:
        counts, n_quartic = _shape_counts(packing, spectral, lambda_c)
        asphericity = packing_asphericity(packing)
    backbone = packing.n - counts["once"]["n_rattlers"]
    status = "jammed" if backbone > 0 else "not jammed: every body is a rattler"
    return dict(family=family, asphericity=asphericity, N=packing.n, phi_J=packing.packing_fraction,
                pressure=float(packing.pressure), jammed=int(backbone > 0), status=status, counts=counts,
                n_quartic=n_quartic)


def _group_stats(values: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of the mean (0 for one value, NaN for none)."""
    values = values[np.isfinite(values)]
    if not values.size:
        return np.nan, np.nan
    sem = float(np.std(values, ddof=1) / np.sqrt(values.size)) if values.size > 1 else 0.0
    return float(np.mean(values)), sem


def survey_dataset(rows: Sequence[dict], sources: Sequence[str]) -> xr.Dataset:
    """The survey of ``rows`` (:func:`survey_row`) as a dataset.

    Dims ``packing`` (one per row, ``source`` the input file), ``convention``
    (:data:`CONVENTIONS`) and ``group`` (one per family and asphericity, sorted), with
    ``phi_J_mean``, ``phi_J_sem``, ``z_eq3_mean``, ``z_eq3_sem``, ``z_contacts_mean``,
    ``z_contacts_sem`` and ``n_packings`` per group over its jammed packings.
    """
    if not rows:
        raise ValueError("a survey needs at least one packing")
    col = {k: np.array([r[k] for r in rows]) for k in ("family", "asphericity", "N", "phi_J", "pressure", "jammed",
                                                       "status", "n_quartic")}
    per = {k: np.array([[float(r["counts"][c][k]) for c in CONVENTIONS] for r in rows]) for k in _COUNTS}
    # one shape parameter met by bisection gives A equal to round-off; 12 decimals resolve A - 1 ~ 1e-9
    group_a = np.round(col["asphericity"].astype(float), ASPHERICITY_DECIMALS)
    keys = sorted({(f, a) for f, a in zip(col["family"], group_a, strict=True)})
    stats: dict[str, list] = {name: [] for name in ("phi_J_mean", "phi_J_sem", "n_packings", "n_excluded", "N")}
    for q in ("z_eq3", "z_contacts"):
        stats[f"{q}_mean"], stats[f"{q}_sem"] = [], []
    for family, a in keys:
        sel = (col["family"] == family) & (group_a == a)
        use = sel & (col["jammed"] == 1)
        m, s = _group_stats(col["phi_J"][use].astype(float))
        stats["phi_J_mean"].append(m)
        stats["phi_J_sem"].append(s)
        for q in ("z_eq3", "z_contacts"):
            ms = [_group_stats(per[q][use, k]) for k in range(len(CONVENTIONS))]
            stats[f"{q}_mean"].append([x[0] for x in ms])
            stats[f"{q}_sem"].append([x[1] for x in ms])
        stats["n_packings"].append(int(use.sum()))
        stats["n_excluded"].append(int(sel.sum() - use.sum()))
        stats["N"].append(int(np.max(col["N"][sel])))
    p, g, c = ("packing",), ("group",), ("convention",)
    one = {"units": "1"}
    eq3 = "<z> of Eq. 3, 2 (N_c + 1) / (N - N_r - N_s / f)"
    contacts = "contacts per backbone body z = 2 N_c / N'"
    data = {
        "phi_J": (p, col["phi_J"].astype(float), {**one, "long_name": "packing fraction at P0 (phi_J)"}),
        "pressure": (p, col["pressure"].astype(float), {**one, "long_name": "pressure P0 [k]",
                                                        "comment": "P / k, the same number in the paper's units"}),
        "N": (p, col["N"].astype(np.int64), {**one, "long_name": "number of bodies"}),
        "jammed": (p, col["jammed"].astype(np.int64), {**one, "long_name": "1 if the packing has a backbone"}),
        "n_quartic": (p, col["n_quartic"].astype(np.int64),
                      {**one, "long_name": "quartic (region-1) modes N_1 (-1: spectrum not computed)"}),
        "phi_J_mean": (g, np.array(stats["phi_J_mean"]), {**one, "long_name": "mean phi_J of the group"}),
        "phi_J_sem": (g, np.array(stats["phi_J_sem"]), {**one, "long_name": "standard error of the mean phi_J"}),
        "n_packings": (g, np.array(stats["n_packings"], dtype=np.int64),
                       {**one, "long_name": "jammed packings in the group (entering the means)"}),
        "n_excluded": (g, np.array(stats["n_excluded"], dtype=np.int64),
                       {**one, "long_name": "packings of the group left out (not jammed)"}),
        "group_N": (g, np.array(stats["N"], dtype=np.int64), {**one, "long_name": "largest N in the group"}),
    }
    names = {"n_contacts": "contacts between non-rattlers N_c", "n_rattlers": "rattlers N_r",
             "n_sliders": "sliders N_s", "isostatic_count": "isostatic count N_c^0 (3N' - 1 - N_s; disks 2N' - 1)",
             "z_contacts": contacts, "z_eq3": eq3}
    for k in _COUNTS:
        data[k] = (p + c, per[k], {**one, "long_name": names[k], "comment": "NaN: convention not computed"})
    counting = [[rigidity_counting(int(a), int(b)) if np.isfinite(a) else "" for a, b in zip(nc, iso, strict=True)]
                for nc, iso in zip(per["n_contacts"], per["isostatic_count"], strict=True)]
    for q, text in (("z_eq3", eq3), ("z_contacts", contacts)):
        data[f"{q}_mean"] = (g + c, np.array(stats[f"{q}_mean"]), {**one, "long_name": f"group mean of {text}"})
        data[f"{q}_sem"] = (g + c, np.array(stats[f"{q}_sem"]), {**one, "long_name": f"standard error of the mean {q}"})
    return xr.Dataset(
        data_vars=data,
        coords={
            "convention": (c, np.array(CONVENTIONS, dtype=str),
                           {"long_name": "contact convention: parallel circulo contacts once, twice, or "
                                         "N_c = N_c^0 - N_1 (spectral)"}),
            "family": (p, col["family"].astype(str), {"long_name": "shape family"}),
            "asphericity": (p, col["asphericity"].astype(float), {**one, "long_name": "asphericity A = p^2 / (4 pi a)"}),
            "source": (p, np.array(sources, dtype=str), {"long_name": "input packing file"}),
            "status": (p, col["status"].astype(str), {"long_name": "jammed, or why the packing is left out"}),
            "counting": (p + c, np.array(counting, dtype=str), {"long_name": "hypostatic / isostatic / hyperstatic"}),
            "group_family": (g, np.array([k[0] for k in keys], dtype=str), {"long_name": "shape family of the group"}),
            "group_asphericity": (g, np.array([k[1] for k in keys]), {**one, "long_name": "asphericity of the group"}),
        },
    )
