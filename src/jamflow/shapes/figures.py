"""Figures of shape packings (VanderWerf et al. Figs. 5-8, 10, 11, 14).

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

__all__ = ["Z_CONVENTIONS", "plot_contact_angles", "plot_feasible_region", "plot_quartic_pressure", "plot_spectra",
           "plot_survey"]

_DL = "(dimensionless)"
_MARKERS = {"ellipse": "o", "circulo_line": "s", "reuleaux": "^", "circulo_polygon_3": "v",
            "circulo_polygon_5": "p", "circulo_polygon_8": "h", "circulo_polygon_10": "D", "dumbbell": "X"}

#: What each survey quantity is called on an axis.
_SURVEY = {"phi_J": "packing fraction at jamming phi_J", "z": "coordination number <z> (Eq. 3)"}

#: ``plot z-asphericity --convention``: each family's paper definition (Fig. 8: N_c = N_c^0 - N_1 for
#: circulo shapes, plain contacts for the rest), or one survey convention for all.
Z_CONVENTIONS = ("paper", "once", "twice", "spectral")


def _paper_convention(family: str) -> str:
    """Fig. 8's contact count of a family: spectral for circulo-lines and -polygons, else contacts."""
    return "spectral" if family.startswith("circulo") else "once"


def _counts_text(n: np.ndarray) -> str:
    return f"{int(n[0])} packings per point" if np.all(n == n[0]) else f"{', '.join(map(str, n))} packings"


def plot_survey(ds: xr.Dataset, quantity: str, convention: str = "paper") -> Figure:
    """``phi_J`` (Fig. 5) or ``<z>`` (Figs. 6, 8) against ``A - 1`` on a log axis, one series per family.

    Group means of the jammed packings with standard errors as points with error bars
    (no lines: neighbouring asphericities may be decades apart); the packings per point
    in the legend. Disk packings (``A = 1``) as a horizontal line with their standard-error
    band; for ``<z>`` the isostatic values 4 (disks) and 6 (rotating bodies) as dotted
    lines. ``convention`` picks the contact count of ``<z>`` (:data:`Z_CONVENTIONS`);
    ``paper`` is Fig. 8's (:func:`_paper_convention`), and the title says which was used.
    """
    if quantity not in _SURVEY:
        raise ValueError(f"survey quantity is one of {', '.join(_SURVEY)}, got {quantity!r}")
    if convention not in Z_CONVENTIONS:
        raise ValueError(f"--convention is one of {', '.join(Z_CONVENTIONS)}, got {convention!r}")
    fig = Figure(layout="constrained", figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    family = ds["group_family"].values
    a1 = ds["group_asphericity"].values - 1.0
    n = ds["n_packings"].values
    conventions = list(ds["convention"].values)
    used = {}
    for f in sorted(set(family)):
        sel = family == f
        conv = _paper_convention(f) if convention == "paper" else convention
        if quantity == "phi_J":
            mean, sem = ds["phi_J_mean"].values[sel], ds["phi_J_sem"].values[sel]
        else:
            k = conventions.index(conv)
            mean, sem = ds["z_eq3_mean"].values[sel, k], ds["z_eq3_sem"].values[sel, k]
            if f != DISK_FAMILY and np.any(~np.isfinite(mean) & (n[sel] > 0)):
                raise ValueError(f"the survey has no {conv} count of {f} (<z> by N_c = N_c^0 - N_1 needs "
                                 "jamflow shape-survey --spectral); plot with --convention once or twice")
            used[f] = conv
        if f == DISK_FAMILY:
            m, s_ = float(mean[0]), float(sem[0])
            ax.axhline(m, color="k", lw=1.0, ls="--", label=f"bidisperse disks ({n[sel][0]} packings): {m:.4f}")
            ax.axhspan(m - s_, m + s_, color="k", alpha=0.12, lw=0)
            continue
        order = np.argsort(a1[sel])
        name = f.replace("_", " ") + (f", {used[f]}" if quantity == "z" else "")
        ax.errorbar(a1[sel][order], mean[order], yerr=sem[order], fmt=_MARKERS.get(f, "o"), ms=5, capsize=2,
                    lw=0.8, label=f"{name} ({_counts_text(n[sel][order])})")
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
    title = f"N = {', '.join(map(str, sizes))}, P0 = {', '.join(sorted({f'{p:.2g}' for p in pressures}))} k"
    if quantity == "z":
        words = {"once": "contacts, a parallel contact once", "twice": "contacts, a parallel contact twice",
                 "spectral": "N_c^0 - N_1 (quartic modes N_1)"}
        title += "\nN_c: " + "; ".join(
            f"{f.replace('_', ' ')}: {words[c] if f.startswith(('circulo', 'dumbbell')) or c == 'spectral' else 'contacts'}"
            for f, c in sorted(used.items()) if f != DISK_FAMILY)
    ax.set_title(title, fontsize=8)
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
    curve per ``jamflow modes`` output, labelled by family, ``A - 1`` and ``P0``; region-0
    zero modes drawn as ``|lambda|`` (open markers) under their floor ``lambda_0``
    (dashed), ``lambda_c`` (dotted). The legend gives ``N_1`` and ``N_c^0 - N_c`` (contacts
    counted twice) and flags a packing where they differ."""
    fig = Figure(layout="constrained", figsize=(6.4, 5.0))
    ax = fig.add_subplot()
    for k, ds in enumerate(datasets):
        lam, region = ds["eigenvalue"].values, ds["region"].values
        index = np.arange(lam.size) / lam.size
        a = ds.attrs
        name = labels[k] if labels else (f"{str(a.get('family', '?')).replace('_', ' ')} A - 1 = "
                                         f"{a.get('asphericity', np.nan) - 1:.3g}, P0 = {a.get('pressure', np.nan):.3g}")
        missing = int(a["isostatic_count"]) - int(a["n_contacts_twice"])
        flag = "" if missing == a["n_quartic"] else "  MISMATCH"
        keep = region > 0
        line = ax.plot(index[keep], lam[keep], ".-", ms=3, lw=0.6,
                       label=f"{name}: N_1 = {a['n_quartic']}, N_c^0 - N_c = {missing}{flag}")[0]
        zero = region == 0
        ax.plot(index[zero], np.maximum(np.abs(lam[zero]), 1e-300), "o", ms=3, mfc="none", color=line.get_color())
        ax.axhline(a["lambda_c"], color=line.get_color(), ls=":", lw=0.8)
        ax.axhline(a["lambda_0"], color=line.get_color(), ls="--", lw=0.6)
    ax.set_yscale("log")
    ax.set_xlabel(f"mode index i / 3N {_DL}")
    ax.set_ylabel("eigenvalue lambda_i [k]; region 0: |lambda_i|")
    ax.set_title("open: region 0 (|lambda| <= lambda_0, dashed); dotted: lambda_c (regions 1 | 2)", fontsize=8)
    ax.legend(fontsize=7)
    return fig


def plot_quartic_pressure(datasets: Sequence[xr.Dataset]) -> Figure:
    """Region-1 eigenvalues (Fig. 10) and the signed fourth derivatives along them (Fig. 11)
    against ``P0``, one column of points per ``jamflow modes`` output; a slope-1 guide through
    the geometric mean of the eigenvalues. The fourth derivatives are drawn on a symmetric
    log axis, so a negative one (an unstable mode) shows below zero; unresolved ones (NaN)
    are counted in the title."""
    fig = Figure(layout="constrained", figsize=(10.0, 4.4))
    left, right = fig.subplots(1, 2)
    pressures, lams, fourth = [], [], []
    unresolved = 0
    for ds in datasets:
        p = float(ds.attrs["pressure"])
        r1 = ds["region"].values == 1
        lam, d4 = ds["eigenvalue"].values[r1], ds["fourth_derivative"].values[r1]
        left.plot(np.full(lam.size, p), lam, "o", ms=3, color="tab:blue")
        ok = np.isfinite(d4)
        unresolved += int(np.sum(~ok))
        right.plot(np.full(int(ok.sum()), p), d4[ok], "o", ms=3, color="tab:red")
        pressures.append(p)
        lams.extend(lam / p)
        fourth.extend(d4[ok])
    if lams:
        p = np.array(sorted(pressures))
        left.plot(p, np.exp(np.mean(np.log(lams))) * p, "k--", lw=0.8, label="lambda proportional to P0")
        left.legend(fontsize=7)
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_xlabel("pressure P0 [k]")
    left.set_yscale("log")
    magnitude = np.abs(np.array(fourth))
    if np.any(magnitude > 0):
        # symmetric about 0, so that a negative fourth derivative would sit as far below as a positive one above
        top = 3.0 * float(magnitude.max())
        right.set_yscale("symlog", linthresh=0.3 * float(magnitude[magnitude > 0].min()), linscale=1.0)
        right.set_ylim(-top, top)
    right.axhline(0.0, color="grey", lw=0.8)
    left.set_ylabel("region-1 eigenvalue lambda [k]")
    right.set_ylabel("d^4 U / ds^4 along region-1 modes [k] (symmetric log)")
    negative = int(np.sum(np.array(fourth) <= 0.0))
    right.set_title(f"{negative} non-positive, {unresolved} unresolved (NaN)", fontsize=8)
    n = sorted({int(ds.attrs["N"]) for ds in datasets})
    fig.suptitle(f"quartic modes, N = {', '.join(map(str, n))}, {len(datasets)} packings", fontsize=9)
    return fig


def plot_feasible_region(ds: xr.Dataset) -> Figure:
    """Figs. 12-13 of one ``jamflow feasible-region`` output: the caged circulo-line (12b), its
    feasible region at the smallest ``dR`` projected on the quartic and the softer stiff
    eigen-direction (12a), and volume and surface against ``dR / R`` with the fitted
    exponents and slope-5/2 and 3/2 guides (13)."""
    fig = Figure(layout="constrained", figsize=(13.0, 4.2))
    cage, region, scaling = fig.subplots(1, 3)
    a = ds.attrs
    half, pts = float(a["half_length"]), ds["points"].values
    t = np.linspace(0.0, 2.0 * np.pi, 256)
    outline = np.concatenate([np.column_stack([half + np.cos(t[:128] - 0.5 * np.pi), np.sin(t[:128] - 0.5 * np.pi)]),
                              np.column_stack([-half + np.cos(t[:128] + 0.5 * np.pi), np.sin(t[:128] + 0.5 * np.pi)])])
    cage.fill(*outline.T, color="tab:blue", alpha=0.3)
    cage.plot([-half, half], [0.0, 0.0], "k-", lw=1.0)
    cage.plot(pts[0, 0], pts[0, 1], "o", mfc="white", mec="k", ms=8, label="shaft contact (convex)")
    cage.plot(pts[1:, 0], pts[1:, 1], "ko", ms=8, label="end-cap contacts (concave)")
    cage.set_aspect("equal")
    cage.set_xlabel("x / R (dimensionless)")
    cage.set_ylabel("y / R (dimensionless)")
    cage.set_title(f"Fig. 12b: half-length {half:g} R, cap points {np.degrees(float(a['beta'])):.0f} deg below", fontsize=8)
    cage.legend(fontsize=7, loc="lower center")
    u = ds["feasible_sample"].values
    region.plot(u[:, 2], u[:, 1], ",", color="tab:blue", alpha=0.5)
    region.ticklabel_format(style="sci", scilimits=(-2, 2))
    region.set_xlabel("quartic eigen-direction lambda_3 (x / R, y / R, theta [rad]) (dimensionless)")
    region.set_ylabel("stiff eigen-direction lambda_2 (dimensionless)")
    region.set_title(f"Fig. 12a: feasible configurations at dR / R = {float(ds.shrink.values[0]):.0e} "
                     f"({u.shape[0]} samples)", fontsize=8)
    dr = ds["shrink"].values
    for name, marker, slope, key in (("volume", "s", 2.5, "volume_exponent"), ("surface", "o", 1.5, "surface_exponent")):
        y = ds[name].values
        scaling.errorbar(dr, y, yerr=ds[f"{name}_err"].values, fmt=marker, capsize=2,
                         label=f"{name} V (fit exponent {a[key]:.3f})" if name == "volume" else
                         f"{name} S (fit exponent {a[key]:.3f})")
        scaling.plot(dr, y[0] * (dr / dr[0]) ** slope, "k--" if slope == 2.5 else "k:", lw=0.8,
                     label=f"slope {slope:g}")
    scaling.set_xscale("log")
    scaling.set_yscale("log")
    scaling.set_xlabel("radius decrease dR / R (dimensionless)")
    scaling.set_ylabel("volume, surface of the feasible region (dimensionless)")
    scaling.set_title(f"Fig. 13: Monte Carlo, {a['samples']} samples per point", fontsize=8)
    scaling.legend(fontsize=7)
    return fig
