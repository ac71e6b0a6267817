"""Figures of shape packings (VanderWerf et al. Figs. 5, 7, 8, 10, 11, 14).

Each function returns a matplotlib ``Figure`` labelled as :mod:`jamflow.plots` requires
(every axis a quantity with a unit or "(dimensionless)"); save with
:func:`jamflow.plots.save_figure`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from .survey import DISK_FAMILY

__all__ = ["plot_contact_angles", "plot_quartic_pressure", "plot_spectra", "plot_survey"]

_DL = "(dimensionless)"
_MARKERS = {"ellipse": "o", "circulo_line": "s", "reuleaux": "^", "circulo_polygon_3": "v",
            "circulo_polygon_5": "p", "circulo_polygon_8": "h", "circulo_polygon_10": "D"}

#: What each survey quantity is called on an axis, and its reference lines.
_SURVEY = {"phi_J": "packing fraction at jamming phi_J", "z": "mean contact number <z> (Eq. 3)"}


def plot_survey(ds: xr.Dataset, quantity: str) -> Figure:
    """``phi_J`` (Fig. 5) or ``<z>`` (Fig. 8) against ``A - 1`` on a log axis, one series per family.

    Group means with standard errors; disk packings (``A = 1``) as a horizontal line
    with their standard-error band; for ``<z>`` the isostatic values 4 (disks) and 6
    (rotating bodies) as dotted lines.
    """
    if quantity not in _SURVEY:
        raise ValueError(f"survey quantity is one of {', '.join(_SURVEY)}, got {quantity!r}")
    fig = Figure(layout="constrained", figsize=(6.4, 4.6))
    ax = fig.add_subplot()
    family = ds["group_family"].values
    a1 = ds["group_asphericity"].values - 1.0
    mean, sem = ds[f"{quantity}_mean"].values, ds[f"{quantity}_sem"].values
    n = ds["n_packings"].values
    for f in sorted(set(family)):
        sel = family == f
        if f == DISK_FAMILY:
            m, s = float(mean[sel][0]), float(sem[sel][0])
            ax.axhline(m, color="k", lw=1.0, ls="--", label=f"bidisperse disks ({n[sel][0]} packings): {m:.4f}")
            ax.axhspan(m - s, m + s, color="k", alpha=0.12, lw=0)
            continue
        order = np.argsort(a1[sel])
        ax.errorbar(a1[sel][order], mean[sel][order], yerr=sem[sel][order], fmt=_MARKERS.get(f, "o") + "-", ms=5,
                    capsize=2, lw=0.8, label=f"{f.replace('_', ' ')} ({int(n[sel].min())}-{int(n[sel].max())} per A)")
    if quantity == "z":
        for value, text in ((4.0, "isostatic disks 4"), (6.0, "isostatic rotating bodies 6")):
            ax.axhline(value, color="grey", lw=0.8, ls=":")
            ax.annotate(text, (0.01, value), xycoords=("axes fraction", "data"), fontsize=7, va="bottom")
    ax.set_xscale("log")
    # minor-tick labels of a narrow log range overprint each other
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel(f"asphericity A - 1 {_DL}")
    ax.set_ylabel(f"{_SURVEY[quantity]} {_DL}")
    ax.legend(fontsize=7)
    pressures = sorted({float(p) for p in ds["pressure"].values if np.isfinite(p)})
    sizes = sorted({int(v) for v in ds["N"].values})
    ax.set_title(f"N = {', '.join(map(str, sizes))}, P0 = {', '.join(sorted({f'{p:.2g}' for p in pressures}))}", fontsize=9)
    return fig


def plot_contact_angles(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """``P(psi)`` of one or more ``jamflow contact-angles`` outputs (Fig. 14), with counting errors;
    the flat ``2 / pi`` of contact directions uniform relative to the body axis as a dotted line."""
    fig = Figure(layout="constrained", figsize=(6.4, 4.6))
    ax = fig.add_subplot()
    for k, ds in enumerate(datasets):
        a = ds.attrs
        name = labels[k] if labels else f"{a['family']} A - 1 = {a['asphericity'] - 1:.3g}"
        ax.errorbar(np.degrees(ds["psi"].values), ds["P_psi"].values, yerr=ds["P_psi_err"].values, fmt="o-", ms=4,
                    lw=0.8, capsize=2, label=f"{name} (N = {a['N']}, {a['n_packings']} packings, {a['n_angles']} angles)")
    ax.axhline(2.0 / np.pi, color="grey", ls=":", lw=1.0, label="uniform directions 2/pi")
    ax.set_xlim(0.0, 90.0)
    ax.set_xlabel("contact angle psi [degree] (0: tip, 90: side)")
    ax.set_ylabel("P(psi) [1/rad]")
    ax.legend(fontsize=7)
    return fig


def plot_spectra(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """Sorted dynamical-matrix eigenvalues against their normalised index (Fig. 7), one
    curve per ``jamflow modes`` output; zero modes (region 0) left out, ``lambda_c`` marked."""
    fig = Figure(layout="constrained", figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    for k, ds in enumerate(datasets):
        lam, region = ds["eigenvalue"].values, ds["region"].values
        index = np.arange(lam.size) / lam.size
        keep = region > 0
        a = ds.attrs
        name = labels[k] if labels else f"P0 = {a.get('pressure', np.nan):.3g}"
        line = ax.plot(index[keep], lam[keep], ".-", ms=3, lw=0.6,
                       label=f"{name}: N_1 = {a['n_quartic']}, N_c^0 - N_c = {a['isostatic_count'] - a['n_contacts_twice']}")[0]
        ax.axhline(a["lambda_c"], color=line.get_color(), ls=":", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel(f"mode index i / 3N {_DL}")
    ax.set_ylabel("eigenvalue lambda_i [k]")
    ax.set_title("dotted: lambda_c (regions 1 | 2); region-0 zero modes not drawn", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def plot_quartic_pressure(datasets: Sequence[xr.Dataset]) -> Figure:
    """Region-1 eigenvalues (Fig. 10) and fourth derivatives along them (Fig. 11) against
    ``P0``, one column of points per ``jamflow modes`` output; a slope-1 guide through the
    geometric mean of the eigenvalues."""
    fig = Figure(layout="constrained", figsize=(10.0, 4.4))
    left, right = fig.subplots(1, 2)
    pressures, lams = [], []
    for ds in datasets:
        p = float(ds.attrs["pressure"])
        r1 = ds["region"].values == 1
        lam, d4 = ds["eigenvalue"].values[r1], ds["fourth_derivative"].values[r1]
        left.plot(np.full(lam.size, p), lam, "o", ms=3, color="tab:blue")
        right.plot(np.full(d4.size, p), np.abs(d4), "o", ms=3, color="tab:red")
        pressures.append(p)
        lams.extend(lam / p)
    if lams:
        p = np.array(sorted(pressures))
        left.plot(p, np.exp(np.mean(np.log(lams))) * p, "k--", lw=0.8, label="lambda proportional to P0")
        left.legend(fontsize=7)
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("pressure P0 [k]")
    left.set_ylabel("region-1 eigenvalue lambda [k]")
    right.set_ylabel("|d^4 U / ds^4| along region-1 modes [k]")
    n = sorted({int(ds.attrs["N"]) for ds in datasets})
    fig.suptitle(f"quartic modes, N = {', '.join(map(str, n))}, {len(datasets)} packings", fontsize=9)
    return fig
