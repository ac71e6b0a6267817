"""Figures: one function per figure, each returning a matplotlib ``Figure``.

Figures are built on ``matplotlib.figure.Figure`` directly (no pyplot state, no GUI
backend), so they render headless and in parallel jobs. :func:`save_figure`
writes a PNG and a PDF next to each other. Every axis names a quantity and its unit:
a dimensional quantity carries the unit its dataset states (``units`` attribute),
a ratio says "(dimensionless)"; lengths are in the packing's length unit.
"""

from __future__ import annotations

import itertools
import os
import re
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.collections import EllipseCollection, LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Polygon
from matplotlib.ticker import NullFormatter

from .analysis.forces import THETA_EXTENDED, THETA_LOCALISED
from .analysis.gaps import MEAN_FIELD_GAP_EXPONENT
from .io import atomic_file
from .network import count_bodies
from .network.spheres import contact_network, find_rattlers
from .state.packing import Packing
from .tolerances import CONTACT_GAP_TOL

__all__ = [
    "unlabelled_axes",
    "save_figure",
    "plot_packing",
    "plot_gaps",
    "plot_forces",
    "plot_fit_windows",
    "plot_rdf",
    "plot_stress_strain",
    "plot_phi_kappa",
    "plot_overlap_series",
    "plot_jamming_table",
    "plot_eos",
    "pareto",
]

_DL = "(dimensionless)"


#: An axis label states its unit as "[unit]" or says "(dimensionless)".
_UNIT = re.compile(r"\[[^\]]+\]|\(dimensionless\)")


def unlabelled_axes(fig: Figure) -> list[str]:
    """Axes of ``fig`` whose x or y label is empty or names no unit (empty list: all fine).

    An x axis shared with a labelled sibling (stacked panels) counts as labelled;
    a colour bar needs a label with a unit on its long axis.
    """
    problems = []
    for k, ax in enumerate(fig.axes):
        if ax.get_label() == "<colorbar>":
            label = ax.get_ylabel() or ax.get_xlabel()
            if not _UNIT.search(label):
                problems.append(f"colour bar {k}: label {label!r} has no quantity with a unit")
            continue
        x_labels = [ax.get_xlabel()] + [o.get_xlabel() for o in ax.get_shared_x_axes().get_siblings(ax)]
        if not any(_UNIT.search(t) for t in x_labels):
            problems.append(f"axes {k}: x label {ax.get_xlabel()!r} has no quantity with a unit")
        if not _UNIT.search(ax.get_ylabel()):
            problems.append(f"axes {k}: y label {ax.get_ylabel()!r} has no quantity with a unit")
    return problems


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int = 150) -> tuple[Path, Path]:
    """Write ``fig`` as ``<stem>.png`` and ``<stem>.pdf``; returns both paths.

    Raises
    ------
    ValueError
        An axis has no label with a unit (:func:`unlabelled_axes`); nothing is written.
    """
    problems = unlabelled_axes(fig)
    if problems:
        raise ValueError(f"figure {path} not saved: " + "; ".join(problems))
    path = Path(path)
    png, pdf = path.with_suffix(".png"), path.with_suffix(".pdf")
    for target, options in ((png, {"dpi": dpi}), (pdf, {})):
        with atomic_file(target) as tmp:  # an interrupted save leaves no half-written figure
            fig.savefig(tmp, format=target.suffix[1:], bbox_inches="tight", **options)
    return png, pdf


# --- packings -------------------------------------------------------------------------


def plot_packing(packing: Packing, slab_axis: int = 2, title: str | None = None) -> Figure:
    """Discs to scale in the (possibly sheared) box with the contact network.

    2D: every disc, periodic images clipped to the box. d >= 3: the slab of
    particles whose centre lies within one radius of the mid-plane of coordinate
    ``slab_axis``, drawn as their cross-sections with that plane, projected on the
    first two axes; with links, every sphere of each cluster that crosses the slab is
    drawn whole (its projection, nearer spheres on top), so no cluster is cut. Linked
    packings count rattling clusters by :func:`jamflow.network.count_bodies`. Contacts are lines between centres, their width proportional
    to the force when the packing has forces; rattlers are drawn in orange.
    Shaped particles are drawn as their outlines at their orientations and links as
    green lines between centres; a packing with shapes or links shows only its stored
    contacts and rattlers (contacts between bodies are not guessed from diameters).
    """
    fig = Figure(layout="constrained", figsize=(6.4, 6.4 * min(2.0, packing.box.lengths[1] / packing.box.lengths[0]) + 0.6))
    ax = fig.add_subplot()
    h = packing.box.matrix
    x = packing.box.wrap(packing.position)
    radius = 0.5 * packing.diameter
    bodies = packing.shapes is not None or packing.links is not None
    if bodies:
        contacts = packing.contacts if packing.contacts is not None else np.empty((0, 2), np.int64)
    else:
        contacts = contact_network(packing)
    count = None
    if packing.links is not None and len(packing.links) and packing.contacts is not None:
        count = count_bodies(packing.contacts, packing.n, packing.d, packing.links, packing.position, packing.box)
    # without stored contacts (e.g. an LS snapshot) near contacts are only geometric: flag no rattlers
    if count is not None:
        rattler = count.rattler
    elif packing.rattler is not None:
        rattler = packing.rattler
    elif packing.contacts is not None and not bodies:
        rattler = find_rattlers(packing.n, packing.d, contacts)
    else:
        rattler = np.zeros(packing.n, dtype=bool)
    source = "" if packing.contacts is not None or bodies else f" with h <= {CONTACT_GAP_TOL:g}"
    shown = np.ones(packing.n, dtype=bool)
    linked = packing.links is not None and len(packing.links) > 0
    order = np.arange(packing.n)
    if packing.d >= 3:
        mid = 0.5 * h[slab_axis, slab_axis]
        dz = x[:, slab_axis] - mid
        shown = np.abs(dz) < radius
        if linked:
            shown = np.isin(packing.clusters, packing.clusters[shown])
            order = np.argsort(dz, kind="stable")
        else:
            radius = np.sqrt(np.clip(radius**2 - dz**2, 0.0, None))
    a1, a2 = h[:2, 0], h[:2, 1]
    corners = np.array([[0.0, 0.0], a1, a1 + a2, a2])
    clip = Polygon(corners, closed=True, facecolor="none", edgecolor="k", lw=1.2)
    ax.add_patch(clip)
    big = packing.diameter > np.median(packing.diameter) * (1 + 1e-9)
    colours = np.where(rattler, "tab:orange", np.where(big, "#9ecae1", "#c6dbef"))
    shifts = [i * a1 + j * a2 for i, j in itertools.product((-1, 0, 1), repeat=2)]
    idx = order[shown[order]]
    outlines = _body_outlines(packing, x) if packing.shapes is not None else None
    for s in shifts:
        if outlines is None:
            col = EllipseCollection(2 * radius[idx], 2 * radius[idx], 0.0, units="xy", offsets=x[idx, :2] + s,
                                    offset_transform=ax.transData, facecolors=colours[idx], edgecolors="#3b5b7a",
                                    linewidths=0.4, alpha=0.75 if linked and packing.d >= 3 else None)
        else:
            col = PolyCollection([o + s for o in outlines], facecolors=colours, edgecolors="#3b5b7a", linewidths=0.4)
        col.set_clip_path(clip)
        ax.add_collection(col)
    if packing.links is not None and len(packing.links):
        li, lj = packing.links.i, packing.links.j
        link_seg = np.stack([x[li, :2], x[li, :2] + packing.box.minimum_image(x[lj] - x[li])[:, :2]], axis=1)
        link_seg = link_seg[shown[li] & shown[lj]]
        for s in shifts:
            lc = LineCollection(link_seg + s, linewidths=2.0, colors="#1b7837")
            lc.set_clip_path(clip)
            ax.add_collection(lc)
        ax.plot([], [], color="#1b7837", lw=2.0, label="links (fixed length)")
    drawn_contacts = 0
    if len(contacts):
        ci, cj = contacts[:, 0], contacts[:, 1]
        dx = packing.box.minimum_image(x[cj] - x[ci])
        keep = shown[ci] & shown[cj]
        drawn_contacts = int(keep.sum())
        if packing.force is not None and packing.contacts is not None and len(packing.force) == len(contacts):
            width = 3.0 * packing.force / max(float(np.max(packing.force)), 1e-300)
            label = "contacts (width proportional to force)"
        else:
            width = np.full(len(contacts), 0.8)
            label = "contacts"
        seg = np.stack([x[ci, :2], x[ci, :2] + dx[:, :2]], axis=1)[keep]
        if drawn_contacts:
            for s in shifts:
                lc = LineCollection(seg + s, linewidths=width[keep], colors="#8b0000")
                lc.set_clip_path(clip)
                ax.add_collection(lc)
            ax.plot([], [], color="#8b0000", lw=1.5, label=label)
    # in linked packings the free spheres are rattling clusters and danglers (a dimer's free monomer: a rotator)
    free = "rattlers" if packing.links is None else "rattlers and danglers"
    if np.any(rattler[shown]):
        ax.plot([], [], "o", color="tab:orange", label=free)
    pad = 0.03 * max(packing.box.lengths[:2])
    xs = corners[:, 0]
    ax.set_xlim(xs.min() - pad, xs.max() + pad)
    ax.set_ylim(-pad, corners[:, 1].max() + pad)
    ax.set_aspect("equal")
    unit = packing.attrs.get("length_unit", "length unit")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    slab = "" if packing.d == 2 else (f", clusters crossing |x_{slab_axis} - L/2| < D/2 drawn whole "
                                       f"({int(shown.sum())} spheres)" if linked else
                                       f", slab |x_{slab_axis} - L/2| < D/2 ({int(shown.sum())} particles)")
    n_r = int(np.sum(rattler))
    counted = f"{n_r} {free}"
    if count is not None:
        counted = (f"{int(count.rattling_cluster.sum())} rattling cluster(s) ({int(count.removed.sum())} whole, "
                   f"{int(count.dangler.sum())} dangler(s))")
    shown_contacts = f"{len(contacts)} contacts{source}"
    if packing.body_kind == "walls":
        # the wall contacts are not drawn; the tables' N_c (the packing's n_contacts) counts them
        n_all = packing.attrs.get("n_contacts")
        shown_contacts = f"{len(contacts)} sphere-sphere contacts{source} (wall contacts not drawn" + (
            f"; N_c with them {int(n_all)})" if n_all is not None else ")")
    ax.set_title(title or "\n".join(textwrap.wrap(f"d={packing.d}, N={packing.n}, phi={packing.packing_fraction:.5f}, "
                                                  f"{shown_contacts}, {counted}{slab}", 90)),
                 fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    return fig


def _body_outlines(packing: Packing, x: np.ndarray) -> list[np.ndarray]:
    """Outline polygon of every shaped particle at its centre ``x`` and orientation [length]."""
    table = packing.shapes
    shapes = [table.outline(k, points_per_turn=64) for k in range(len(table))]
    out = []
    for centre, k, theta in zip(x[:, :2], packing.shape_index, packing.orientation, strict=True):
        c, s = np.cos(theta), np.sin(theta)
        out.append(shapes[k] @ np.array([[c, s], [-s, c]]) + centre)
    return out


# --- distributions ----------------------------------------------------------------------


def _labels(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None) -> list[str]:
    return list(labels) if labels else [f"{ds.attrs.get('n_samples', 1)} sample(s), d={ds.attrs.get('d', '?')}" for ds in datasets]


def _exponent_label(ds: xr.Dataset, name: str, symbol: str) -> str:
    """``symbol = value ± stat (stat) ± sys (sys)``, or why it is missing."""
    a = ds.attrs
    value = a.get(name, np.nan)
    if not np.isfinite(value):
        return (f"{symbol}: no fit ({a.get(f'{name}_n_in_window', 0)} samples in the window, "
                f"fewer than {a.get('fit_min_in_window', '?')})")
    stat, sys_ = a.get(f"{name}_stat", np.nan), a.get(f"{name}_sys", np.nan)
    sys_text = f"± {sys_:.3f} (sys)" if np.isfinite(sys_) else "(sys undefined: window too short to scan)"
    return f"{symbol} = {value:.3f} ± {stat:.3f} (stat) {sys_text}"


def plot_gaps(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """Gap distributions (``jamflow gaps`` outputs) on log–log axes with fits (CALiPPSO Fig. 10).

    Each fit is drawn over its chosen window, with gamma, its statistical and
    systematic errors in the legend; the mean-field slope is a guide to the eye.
    """
    fig = Figure(layout="constrained", figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    for ds, label in zip(datasets, _labels(datasets, labels)):
        y, e = ds["gap_density"].values, ds["gap_density_err"].values
        ok = y > 0
        rattlers = "" if not ds.attrs.get("rattlers_included", 0) else " (with rattlers)"
        refused = "" if np.isfinite(ds.attrs.get("fit_exponent", np.nan)) else (
            ": " + _exponent_label(ds, "fit_exponent", "gamma"))
        bars = ax.errorbar(ds["h"].values[ok], y[ok], yerr=np.minimum(e[ok], 0.999 * y[ok]), fmt="o", ms=3,
                           capsize=2, label=label + rattlers + refused)
        if np.isfinite(ds.attrs.get("fit_exponent", np.nan)):
            hf = np.logspace(np.log10(ds.attrs["fit_min"]), np.log10(ds.attrs["fit_max"]), 20)
            ax.plot(hf, ds.attrs["fit_prefactor"] * hf ** (-ds.attrs["fit_exponent"]), "-",
                    color=bars[0].get_color(), label=f"{label}: " + _exponent_label(ds, "fit_exponent", "gamma"))
    h_all = np.concatenate([ds["h"].values[ds["gap_density"].values > 0] for ds in datasets])
    if len(h_all):
        ref = datasets[0]
        y0 = ref["gap_density"].values
        k = int(np.argmin(np.abs(np.log(ref["h"].values / 1e-2)) + np.where(y0 > 0, 0, np.inf)))
        hh = np.logspace(np.log10(h_all.min()), np.log10(h_all.max()), 20)
        ax.plot(hh, 0.5 * y0[k] * (hh / ref["h"].values[k]) ** (-MEAN_FIELD_GAP_EXPONENT), "k--", lw=1,
                label=f"mean field h^-{MEAN_FIELD_GAP_EXPONENT} (guide, shifted down)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("relative gap h = r_ij/sigma_ij - 1 (dimensionless)")
    ax.set_ylabel("gap density: non-contact neighbours\nper particle per unit h (dimensionless)")
    if len(datasets) > 2:
        # many curves: the legend goes below the axes instead of over the data
        handles, texts = ax.get_legend_handles_labels()
        ncols = 1 if max(len(t) for t in texts) > 60 else 2
        fig.set_size_inches(6.4, 4.8 + 0.17 * (len(texts) / ncols + 1))
        fig.legend(handles, texts, loc="outside lower center", fontsize=7, ncols=ncols)
    else:
        ax.legend(fontsize=7)
    ax.grid(True, which="major", alpha=0.3)
    return fig


def plot_fit_windows(ds: xr.Dataset) -> Figure:
    """Exponent against fit window: the diagnostic behind its systematic error.

    ``ds`` is a ``jamflow gaps`` (gamma) or ``jamflow forces`` (theta) output. Left:
    the exponent of every scanned window (spanning at least 1.5 decades) against its
    lower edge, one line per upper edge, coloured by the upper edge. Right: the same
    against the upper edge, coloured by the lower edge. Bands: the reported value ±
    its statistical error (dark) and ± the combined error (light); dotted lines mark
    the chosen window, an orange line a detected power-law break.
    """
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    gaps = "gap_density" in ds
    symbol, variable = ("gamma", "relative gap h") if gaps else ("theta", "f / <f>")
    fig = Figure(layout="constrained", figsize=(11.0, 4.6))
    left, right = fig.subplots(1, 2)
    a = ds.attrs
    lo, hi, g = ds["window_lower"].values, ds["window_upper"].values, ds["window_exponent"].values
    err = ds["window_exponent_err"].values
    cmap = colormaps["viridis"]
    for ax, x, key, other in ((left, lo, hi, "upper"), (right, hi, lo, "lower")):
        if len(g) == 0:
            ax.text(0.5, 0.5, textwrap.fill(a.get("fit_exponent_reason", "") or "no window scanned", 50),
                    ha="center", va="center", transform=ax.transAxes, fontsize=8)
            continue
        norm = LogNorm(key.min(), key.max() * (1 + 1e-9))
        for u in np.unique(key):
            sel = key == u
            ax.errorbar(x[sel], g[sel], yerr=err[sel], fmt="o-", ms=3, lw=0.8, capsize=1.5, color=cmap(norm(u)))
        bar = fig.colorbar(ax.scatter([], [], c=[], cmap=cmap, norm=norm), ax=ax, pad=0.01)
        bar.set_label(f"{other} edge of the window, {variable} (dimensionless)", fontsize=8)
    value = a.get("fit_exponent", np.nan)
    refs = ([(MEAN_FIELD_GAP_EXPONENT, "mean field")] if gaps else
            [(THETA_EXTENDED, "extended, mean field"), (THETA_LOCALISED, "localised")])
    for ax in (left, right):
        if np.isfinite(value):
            total = a.get("fit_exponent_err", np.nan)
            if np.isfinite(total):
                ax.axhspan(value - total, value + total, color="grey", alpha=0.12, label="± combined error")
            ax.axhspan(value - a["fit_exponent_stat"], value + a["fit_exponent_stat"], color="grey", alpha=0.3,
                       label="± statistical error")
            ax.axhline(value, color="k", lw=1, label=f"reported {symbol} = {value:.3f}")
        for ref, name in refs:
            ax.axhline(ref, color="C3", ls="--", lw=1, label=f"{name} {ref}")
        ax.set_xscale("log")
        ax.set_ylabel(f"{symbol} fitted on the window (dimensionless)")
    left.axvline(a["fit_min"], color="k", ls=":", lw=1, label="chosen lower edge")
    right.axvline(a["fit_max"], color="k", ls=":", lw=1, label="chosen upper edge")
    if a.get("fit_break_detected", 0):
        right.axvline(a["fit_break_at"], color="C1", lw=1.2, label=f"power-law break (z = {a['fit_break_z']:.1f})")
    left.set_xlabel(f"lower edge of the fit window, {variable} (dimensionless)")
    right.set_xlabel(f"upper edge of the fit window, {variable} (dimensionless)")
    for ax in (left, right):
        ax.legend(fontsize=7)
    fig.suptitle(f"{_exponent_label(ds, 'fit_exponent', symbol)} on [{a['fit_min']:.3g}, {a['fit_max']:.3g}], "
                 f"{a.get('fit_exponent_n_in_window', 0)} samples; {len(g)} windows spanning >= 1.5 decades",
                 fontsize=9)
    return fig


def plot_forces(ds: xr.Dataset) -> Figure:
    """Force distribution (``jamflow forces`` output): linear P(f) and log–log tails by population."""
    fig = Figure(layout="constrained", figsize=(10.5, 4.2))
    ax1, ax2 = fig.subplots(1, 2)
    ax1.errorbar(ds["f"].values, ds["P_linear"].values, yerr=ds["P_linear_err"].values, fmt="o-", ms=3, capsize=2,
                 label=f"{ds.attrs.get('contacts_used', 'backbone contacts')} ({ds.attrs.get('n_samples', 1)} sample(s))")
    ax1.set_xlabel("contact force f / <f> (dimensionless)")
    ax1.set_ylabel("probability density P(f / <f>) (dimensionless)")
    ax1.set_yscale("log")
    ax1.legend(fontsize=8)
    x = ds["f_log"].values
    lo, hi = float(ds.attrs.get("fit_min", 1e-3)), float(ds.attrs.get("fit_max", 1e-1))
    populations = (("", "all", "o"), ("_buckler", "contacts with a buckler", "s"),
                   ("_extended", "extended (no buckler)", "^"))
    for name, label, marker in populations:
        y, e = ds[f"P_log{name}"].values, ds[f"P_log{name}_err"].values
        ok = y > 0
        if not np.any(ok):
            continue
        th = ds.attrs.get(f"fit_exponent{name}", np.nan)
        fit = ": " + _exponent_label(ds, f"fit_exponent{name}", "theta")
        bars = ax2.errorbar(x[ok], y[ok], yerr=np.minimum(e[ok], 0.999 * y[ok]), fmt=marker, ms=4, mfc="none",
                            capsize=2, label=label + fit)
        if np.isfinite(th):
            xf = np.logspace(np.log10(max(lo, float(x[ok].min()))), np.log10(hi), 10)
            ax2.plot(xf, ds.attrs[f"fit_prefactor{name}"] * xf**th, "-", color=bars[0].get_color(), lw=1.2)
    if np.isfinite(ds.attrs.get("fit_prefactor", np.nan)):
        # mean-field slopes drawn through the all-contact fit at the top of the fit window
        y0 = ds.attrs["fit_prefactor"] * hi ** ds.attrs["fit_exponent"]
        xx = np.logspace(np.log10(x.min()), np.log10(hi), 10)
        ax2.plot(xx, 0.5 * y0 * (xx / hi) ** THETA_EXTENDED, "k--", lw=1,
                 label=f"f^{THETA_EXTENDED} (extended, mean field)")
        ax2.plot(xx, 0.5 * y0 * (xx / hi) ** THETA_LOCALISED, "k:", lw=1, label=f"f^{THETA_LOCALISED} (localised)")
    ax2.axvspan(lo, hi, color="grey", alpha=0.1, label="chosen fit window")
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("contact force f / <f> (dimensionless)")
    ax2.set_ylabel("probability density P(f / <f>) (dimensionless)")
    ax2.legend(fontsize=7)
    fig.suptitle(f"buckler fraction {ds.attrs.get('buckler_fraction', np.nan):.3f} of non-rattlers", fontsize=9)
    return fig


def plot_rdf(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """g(r) of ``jamflow rdf`` outputs, with the crystallinity numbers in the legend."""
    fig = Figure(layout="constrained", figsize=(6.4, 4.4))
    ax = fig.add_subplot()
    for k, ds in enumerate(datasets):
        label = labels[k] if labels else f"d={ds.attrs.get('d')}, phi={ds.attrs.get('packing_fraction', np.nan):.4f}"
        if "psi6_global" in ds.attrs:
            label += f", |psi6| global {ds.attrs['psi6_global']:.3f}, local {ds.attrs['psi6_local_mean']:.3f}"
        if "Q6_global" in ds.attrs:
            label += f", Q6 {ds.attrs['Q6_global']:.3f}, crystal-like {ds.attrs['crystal_fraction']:.3f}"
        ax.plot(ds["r"].values, ds["g"].values, "-", lw=1.2, label=label)
    ax.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("r / mean diameter (dimensionless)")
    ax.set_ylabel("g(r) (dimensionless)")
    ax.legend(fontsize=7)
    return fig


# --- flow -----------------------------------------------------------------------------------


def _window(ax, ds: xr.Dataset, name: str) -> None:
    if "window_strain_min" in ds.attrs and f"mean_{name}" in ds.attrs:
        lo, hi = ds.attrs["window_strain_min"], ds.attrs["window_strain_max"]
        m, e = ds.attrs[f"mean_{name}"], ds.attrs[f"err_{name}"]
        ax.axvspan(lo, hi, color="grey", alpha=0.12, label="steady-state window")
        ax.hlines(m, lo, hi, colors="k", linestyles="--", lw=1, label=f"mean {m:.4g} ± {e:.2g}")


def plot_stress_strain(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """Shear stress, pressure and friction against strain (Lerner et al. Figs. 4 and 6).

    Accepts flow time series or ``jamflow flow-summary`` outputs (then the
    steady-state window and means are drawn).
    """
    fig = Figure(layout="constrained", figsize=(7.0, 7.5))
    axes = fig.subplots(3, 1, sharex=True)
    for k, ds in enumerate(datasets):
        label = labels[k] if labels else f"run {k} ({ds.attrs.get('mode', 'flow')})"
        s = ds["strain"].values
        axes[0].plot(s, ds["shear_stress"].values, lw=0.8, label=label)
        axes[1].plot(s, ds["pressure"].values, lw=0.8, label=label)
        p = ds["pressure"].values
        with np.errstate(divide="ignore", invalid="ignore"):
            mu = ds["friction"].values if "friction" in ds else np.where(p != 0, ds["shear_stress"].values / p, np.nan)
        axes[2].plot(s, mu, lw=0.8, label=label)
    if len(datasets) == 1:
        for ax, name in zip(axes, ("shear_stress", "pressure", "friction")):
            _window(ax, datasets[0], name)
    unit = datasets[0]["shear_stress"].attrs.get("units", "1")
    unit = _DL if unit == "1" else f"[{unit}]"
    axes[0].set_ylabel(f"shear stress sigma\n{unit}")
    axes[1].set_ylabel(f"pressure p\n{unit}")
    axes[2].set_ylabel(f"friction mu = sigma / p\n{_DL}")
    axes[2].set_xlabel(f"shear strain gamma {_DL}")
    for ax in axes:
        _widen_flat_axis(ax)
        ax.legend(fontsize=7)
    fig.align_ylabels(axes)
    return fig


def plot_flow_curve(ds: xr.Dataset) -> Figure:
    """Friction mu and packing fraction phi against the viscous number I (flow curve, block errors)."""
    fig = Figure(layout="constrained", figsize=(6.0, 6.0))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    i, di = ds["viscous_number"].values, ds["viscous_number_err"].values
    ax1.errorbar(i, ds["friction"].values, xerr=di, yerr=ds["friction_err"].values, fmt="o-", ms=4, capsize=3)
    ax2.errorbar(i, ds["packing_fraction"].values, xerr=di, yerr=ds["packing_fraction_err"].values,
                 fmt="s-", ms=4, capsize=3)
    for x, y, label in zip(i, ds["friction"].values, ds["label"].values, strict=True):
        ax1.annotate(str(label), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax1.set_ylabel(f"friction mu = <sigma / p>\n{_DL}")
    ax2.set_ylabel(f"packing fraction phi\n{_DL}")
    ax2.set_xlabel(f"viscous number I = gamma_dot / (xi0 lambda^(d-2) p) {_DL}")
    ax2.set_xscale("log")
    for ax in (ax1, ax2):
        ax.ticklabel_format(axis="y", useOffset=False)
    fig.align_ylabels((ax1, ax2))
    fig.suptitle(f"flow curve, d = {ds.attrs.get('d', '?')}, N = {', '.join(str(n) for n in np.unique(ds['n_particles'].values))}",
                 fontsize=9)
    return fig


def _widen_flat_axis(ax) -> None:
    """Show a signal held constant (a fixed pressure, to 1e-12) as a flat line at its value.

    Without this matplotlib zooms into round-off and labels the axis with an offset.
    """
    lo, hi = ax.get_ylim()
    centre = 0.5 * (lo + hi)
    if hi - lo < 1e-6 * max(abs(centre), 1e-300):
        ax.set_ylim(centre - 0.05 * abs(centre), centre + 0.05 * abs(centre))
    ax.ticklabel_format(axis="y", useOffset=False)


def plot_phi_kappa(ds: xr.Dataset) -> Figure:
    """Packing fraction and compression-to-shear rate ratio kappa against strain (Lerner et al. Fig. 7)."""
    fig = Figure(layout="constrained", figsize=(7.0, 5.5))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    s = ds["strain"].values
    ax1.plot(s, ds["packing_fraction"].values, lw=0.9)
    _window(ax1, ds, "packing_fraction")
    ax1.set_ylabel(f"packing fraction phi\n{_DL}")
    if "kappa" in ds and np.any(np.isfinite(ds["kappa"].values)):
        ax2.plot(s, ds["kappa"].values, lw=0.9)
        _window(ax2, ds, "kappa")
        ax2.axhline(0.0, color="grey", lw=0.8, ls=":")
    else:
        ax2.text(0.5, 0.5, "kappa not defined (run not at fixed pressure)", ha="center", transform=ax2.transAxes)
    ax2.set_ylabel(f"kappa = compression / shear rate\n{_DL}")
    ax2.set_xlabel(f"shear strain gamma {_DL}")
    for ax in (ax1, ax2):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    fig.align_ylabels((ax1, ax2))
    p = ds.attrs.get("mean_pressure")
    unit = ds["pressure"].attrs.get("units", "1") if "pressure" in ds else "1"
    unit = "" if unit == "1" else f" [{unit}]"
    fig.suptitle(f"mode {ds.attrs.get('mode', '?')}" + (f", <p> = {p:.4g}{unit}" if p is not None else ""), fontsize=9)
    return fig


def _symlog_to_zero(ax, smallest: float, largest: float) -> None:
    """Logarithmic y above a decade below ``smallest``, linear down to 0, up to ``largest``.

    At most five decade ticks (plus 0), so the labels of a wide range do not overlap.
    """
    low = np.floor(np.log10(smallest)) - 1
    high = np.ceil(np.log10(largest))
    ax.set_yscale("symlog", linthresh=10.0**low)
    step = max(1, int(np.ceil((high - low) / 4)))
    ax.set_yticks([0.0, *(10.0 ** np.arange(low, high + 1, step))])
    ax.set_ylim(0.0, 10.0**high)


def plot_overlap_series(datasets: Sequence[xr.Dataset]) -> Figure:
    """<phi_J>, |Delta phi_J|, 1 - Q and n against p_target over samples (CALiPPSO Fig. 3).

    One ``jamflow overlap-series`` dataset per sample. Samples are grouped by their
    growth rate (attribute ``kappa``, one curve each); points are group means with
    standard errors over samples. The reference pressure itself (where
    |Delta phi_J| = 1 - Q = 0 by definition) is left out of the middle panels; the
    number of LPs is drawn when every dataset has ``n_lp``.
    """
    groups: dict[float, list[xr.Dataset]] = {}
    for ds in datasets:
        groups.setdefault(float(ds.attrs.get("kappa", np.nan)), []).append(ds)
    names = ["phi_J", "abs_delta_phi_J", "one_minus_Q"]
    ylabels = [f"<phi_J>\n{_DL}", f"<|Delta phi_J|>\n{_DL}", f"1 - <Q>\n{_DL}"]
    if all("n_lp" in ds for ds in datasets):
        names.append("n_lp")
        ylabels.append(f"<n> linear\noptimisations {_DL}")
    fig = Figure(layout="constrained", figsize=(6.4, 2.4 * len(names)))
    axes = fig.subplots(len(names), 1, sharex=True)
    means: dict[str, list[float]] = {name: [] for name in names}
    tops: dict[str, list[float]] = {name: [] for name in names}
    for kappa, members in sorted(groups.items()):
        merged = xr.concat([ds[names] for ds in members], dim="sample")
        m = len(members)
        x = merged["p_target"].values
        label = (f"kappa = {kappa:g}, " if np.isfinite(kappa) else "") + f"{m} sample(s)"
        for ax, name in zip(axes, names):
            ok = x < x.max() if name in ("abs_delta_phi_J", "one_minus_Q") else np.ones(len(x), dtype=bool)
            y = merged[name].mean("sample").values.astype(float)
            e = merged[name].std("sample", ddof=1).values / np.sqrt(m) if m > 1 else np.zeros_like(y)
            # non-negative quantities: the lower error bar stops at zero
            lower = np.minimum(e, y) if name != "phi_J" else e
            ax.errorbar(x[ok], y[ok], yerr=[lower[ok], e[ok]], fmt="o-", ms=4, capsize=2, label=label)
            means[name] += list(y[ok])
            tops[name] += list((y + e)[ok])
    for ax, name, ylabel in zip(axes, names, ylabels):
        ax.set_xscale("log")
        if name in ("abs_delta_phi_J", "one_minus_Q"):
            positive = [v for v in means[name] if v > 0]
            if positive:
                _symlog_to_zero(ax, min(positive), max(tops[name]))
            ax.set_ylim(bottom=0.0)
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=8)
    fig.align_ylabels(axes)
    axes[-1].set_xlabel(f"LS target pressure p_tar {_DL}")
    return fig


def pareto(ds: xr.Dataset) -> Figure:
    """Wall time against error of a ``jamflow tradeoff`` sweep, one point per setting.

    Time on a log x axis, the stage's primary error (attribute ``primary_error``) on a
    log y axis; each point is labelled by its setting, the Pareto front is joined and
    highlighted, the reference is marked. Errors of exactly zero (e.g. the reference
    against itself) are drawn on the lower edge at a tenth of the smallest positive
    error and say so.
    """
    name = ds.attrs.get("primary_error", "error")
    if name not in ds or "time" not in ds or "label" not in ds.coords:
        raise ValueError("not a tradeoff sweep: needs variables 'time' and the primary error, coordinate 'label'")
    t = ds["time"].values.astype(float)
    e = ds[name].values.astype(float)
    positive = e[np.isfinite(e) & (e > 0)]
    floor = positive.min() / 10 if positive.size else 1e-16
    y = np.where(e > 0, e, floor)
    front = ds["on_front"].values.astype(bool) if "on_front" in ds else np.zeros(len(t), dtype=bool)
    ref = ds["is_reference"].values.astype(bool) if "is_reference" in ds else np.zeros(len(t), dtype=bool)
    fig = Figure(layout="constrained", figsize=(7.0, 5.0))
    ax = fig.subplots()
    ax.scatter(t[~front], y[~front], s=22, color="0.55", label="setting", zorder=2)
    order = np.argsort(t[front])
    ax.plot(t[front][order], y[front][order], "o-", color="C3", ms=6, lw=1.2, label="Pareto front", zorder=3)
    ax.scatter(t[ref], y[ref], s=120, facecolors="none", edgecolors="k", label="reference", zorder=4)
    # labels of points closer than ~0.2 decades are stacked instead of overprinted
    lt, ly = np.log10(t), np.log10(y)
    for k, label in enumerate(ds["label"].values):
        crowd = int(np.sum((np.abs(lt[:k] - lt[k]) < 0.4) & (np.abs(ly[:k] - ly[k]) < 0.2)))
        ax.annotate(str(label) + (" (error 0)" if e[k] == 0 else ""), (t[k], y[k]), fontsize=6,
                    xytext=(3, 3 - 8 * crowd), textcoords="offset points", color="C3" if front[k] else "0.3")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel(f"{name} {_DL}\n" + textwrap.fill(ds[name].attrs.get("long_name", ""), 70), fontsize=7)
    ax.legend(fontsize=7)
    ax.set_title(f"{ds.attrs.get('stage', '')}: speed against accuracy", fontsize=9)
    return fig


def plot_jamming_table(ds: xr.Dataset) -> Figure:
    """phi_J^(LS) from Eq. 15 against LS+CALiPPSO phi_J per growth rate (CALiPPSO Table I).

    ``ds`` is a ``jamflow jamming-table`` output. Top: sample means with standard errors,
    the LS extrapolation as black squares and one marker per target pressure (shifted
    slightly along kappa for legibility). Bottom: within-sample differences
    ``phi_J(p_tar) - phi_J^(LS)``.
    """
    fig = Figure(layout="constrained", figsize=(6.4, 6.4))
    top, bottom = fig.subplots(2, 1, sharex=True)
    kappa = ds["kappa"].values
    targets = ds["p_target"].values
    shift = np.exp(0.04 * (np.arange(len(targets) + 1) - len(targets) / 2))
    n = ds["n_samples"].values
    top.errorbar(kappa * shift[0], ds["phi_J_LS"].values, yerr=ds["phi_J_LS_err"].values, fmt="ks", ms=6,
                 capsize=3, label="LS, Eq. 15 extrapolated to 1/p = 0")
    for b, p in enumerate(targets):
        top.errorbar(kappa * shift[b + 1], ds["phi_J"].values[:, b], yerr=ds["phi_J_err"].values[:, b], fmt="o",
                     ms=4, capsize=2, label=f"LS+CALiPPSO from p_tar = {p:g}")
        bottom.errorbar(kappa * shift[b + 1], ds["difference"].values[:, b], yerr=ds["difference_err"].values[:, b],
                        fmt="o", ms=4, capsize=2, label=f"p_tar = {p:g}")
    bottom.axhline(0.0, color="k", lw=0.8, ls=":")
    top.set_ylabel(f"<phi_J> {_DL}")
    bottom.set_ylabel(f"<phi_J(p_tar) - phi_J^(LS)>\n{_DL}")
    bottom.set_xlabel(f"LS growth rate kappa {_DL}")
    for ax in (top, bottom):
        ax.set_xscale("log")
        # one labelled tick per growth rate; minor-tick labels of a narrow log range overprint
        ax.set_xticks(kappa, [f"{k:g}" for k in kappa])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7)
    fig.align_ylabels((top, bottom))
    counts = f"{int(n.min())}" if n.min() == n.max() else f"{int(n.min())}-{int(n.max())}"
    fig.suptitle(f"{counts} samples per kappa; fit window "
                 f"{ds.attrs.get('fit_min', float('nan')):g} <= p <= {ds.attrs.get('fit_max', float('nan')):g}",
                 fontsize=9)
    return fig


def plot_eos(datasets: Sequence[xr.Dataset], labels: Sequence[str] | None = None) -> Figure:
    """Equation of state of LS compressions (CALiPPSO Fig. 9).

    Left: reduced pressure ``p`` against ``phi`` on a log axis with Carnahan–Starling
    (d = 3) for the liquid. Right: ``d/p`` against ``phi`` near jamming, where the glass
    law Eq. 15 is the straight line ``d/p = 1 - phi/phi_J`` (drawn from a fit on
    ``p >= 1e3`` of each run) reaching zero at ``phi_J``.
    """
    from .analysis.eos import carnahan_starling, fit_jamming_density

    fig = Figure(layout="constrained", figsize=(10.0, 4.4))
    left, right = fig.subplots(1, 2)
    names = list(labels) if labels else [
        f"kappa = {ds.attrs['kappa']:g}" if "kappa" in ds.attrs else f"run {k}" for k, ds in enumerate(datasets)]
    for ds, name in zip(datasets, names):
        phi, p, d = ds["packing_fraction"].values, ds["pressure"].values, int(ds.attrs["d"])
        ok = np.isfinite(p) & (p > 0)
        line = left.plot(phi[ok], p[ok], ".", ms=2, label=name)[0]
        glass = ok & (p >= 1e3)
        right.plot(phi[glass], d / p[glass], ".", ms=2, color=line.get_color())
        try:
            fit = fit_jamming_density(phi, p, d, p_min=1e3)
        except ValueError:
            continue
        x = np.linspace(phi[glass].min(), fit.phi_j, 50)
        right.plot(x, 1.0 - x / fit.phi_j, "-", lw=0.8, color=line.get_color(),
                   label=f"{name}: Eq. 15, phi_J = {fit.phi_j:.5f}")
    if datasets and int(datasets[0].attrs["d"]) == 3:
        x = np.linspace(0.05, 0.55, 100)
        left.plot(x, carnahan_starling(x), "k--", lw=1, label="Carnahan-Starling liquid")
    left.set_yscale("log")
    left.set_xlabel(f"packing fraction phi {_DL}")
    left.set_ylabel(f"reduced pressure p = beta P V / N {_DL}")
    right.set_xlabel(f"packing fraction phi {_DL}")
    right.set_ylabel(f"d / p {_DL}")
    right.axhline(0.0, color="grey", lw=0.8, ls=":")
    for ax in (left, right):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    return fig


def plot_chains_moduli(ds: xr.Dataset) -> Figure:
    """Shear and bulk moduli of cemented packings against added links per sphere (chains paper Fig. 5).

    ``ds`` is a ``jamflow chains-moduli`` output: Reuss-Voigt weighted values with
    weighted standard errors (points), the mean Voigt and Reuss bounds (dashed and
    dotted). An infinite modulus has no height: every group with packings of infinite
    modulus gets an upward triangle just above the axes (outside the data
    scale) labelled with their count, ``inf x k/n``; filled when every packing of the
    group is infinite, open when the point below averages the finite rest.
    """
    fig = Figure(layout="constrained", figsize=(8.4, 3.6))
    axes = fig.subplots(1, 2)
    x = ds["links_per_sphere"].values
    d = int(ds.attrs.get("d", 3))
    for ax, name, symbol in zip(axes, ("shear", "bulk"), ("G", "K")):
        y, err = ds[f"{name}_weighted"].values, ds[f"{name}_se"].values
        finite = np.isfinite(y)
        ax.errorbar(x[finite], y[finite], yerr=np.nan_to_num(err[finite]), fmt="o", ms=4, capsize=3,
                    label="Reuss-Voigt weighted, standard error")
        for part, style in (("voigt_mean", "--"), ("reuss_mean", ":")):
            v = ds[f"{name}_{part}"].values
            ok = np.isfinite(v)
            ax.plot(x[ok], v[ok], style, color="0.4", lw=1, label=f"mean {part.split('_')[0].capitalize()} bound")
        n_inf = ds[f"{name}_infinite"].values
        n_all = ds["n_packings"].values - ds["n_unstable"].values
        edge = ax.get_xaxis_transform()  # x in data, y in axes fraction: off the modulus scale
        for fill, pick, label in (("C3", n_inf >= n_all, "infinite in every packing"),
                                  ("none", (n_inf > 0) & (n_inf < n_all), "infinite in some packings")):
            if pick.any():
                ax.plot(x[pick], np.full(pick.sum(), 1.04), "^", transform=edge, ms=8, color="C3",
                        markerfacecolor=fill, clip_on=False, label=label)
        for xi, k, n in zip(x[n_inf > 0], n_inf[n_inf > 0], n_all[n_inf > 0]):
            ax.annotate(f"inf x {int(k)}/{int(n)}", (xi, 1.04), xycoords=edge, xytext=(0, 7),
                        textcoords="offset points", ha="center", fontsize=7, color="C3")
        ax.set_xlabel(f"added links per sphere n_l / N {_DL}")
        ax.set_ylabel(f"{name} modulus {symbol} [epsilon / <D>^{d}]")
        ax.legend(fontsize=7)
    n = ds["n_packings"].values
    fig.suptitle(f"{int(n.min())}-{int(n.max())} packings per point" if n.min() != n.max()
                 else f"{int(n.min())} packings per point", fontsize=9)
    return fig
