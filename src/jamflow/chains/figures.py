"""Figures of linked packings: a normal mode drawn as arrows (chains paper Sec. IV A).

Each function returns a matplotlib ``Figure`` labelled as :mod:`jamflow.plots` requires
(every axis a quantity with a unit); save with :func:`jamflow.plots.save_figure`.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ..state.packing import Packing
from .modes import MODE_LABELS

__all__ = ["plot_mode"]


def plot_mode(packing: Packing, modes: xr.Dataset, index: int | None = None) -> Figure:
    """One mode of a ``jamflow modes`` output of ``packing`` as arrows on the spheres.

    Spheres are drawn to scale (in 3D projected on the first two axes, every sphere,
    so whole clusters show), links as green lines, and each centre's displacement as
    an arrow scaled so the largest is one mean diameter long; spheres that move by
    less than 1e-3 of the largest displacement get no arrow. The title names the mode,
    its eigenvalue and label (translation, rattling cluster, free motion, floppy or
    vibration) and, with strain, its strain.

    Parameters
    ----------
    index : int, optional
        Mode index (ascending eigenvalue); default the lowest vibration (the softest
        mode that is not a zero mode).
    """
    labels = modes["mode_label"].values
    if index is None:
        vib = np.flatnonzero(labels == 0)
        index = int(vib[0]) if vib.size else 0
    if not 0 <= index < labels.size:
        raise ValueError(f"mode index {index} outside 0..{labels.size - 1}")
    if modes.sizes["particle"] != packing.n:
        raise ValueError(f"the modes are of {modes.sizes['particle']} spheres, the packing has {packing.n}")
    disp = modes["mode_displacement"].values[index][:, :2]
    x = packing.box.wrap(packing.position)[:, :2]
    D = packing.diameter
    scale = float(np.mean(D)) / max(float(np.linalg.norm(disp, axis=1).max()), 1e-300)
    fig = Figure(layout="constrained", figsize=(6.4, 6.8))
    ax = fig.add_subplot()
    h = packing.box.matrix[:2, :2]
    corners = np.array([[0.0, 0.0], h[:, 0], h[:, 0] + h[:, 1], h[:, 1]])
    ax.add_patch(Polygon(corners, closed=True, facecolor="none", edgecolor="k", lw=1.0))
    ax.add_collection(EllipseCollection(D, D, 0.0, units="xy", offsets=x, offset_transform=ax.transData,
                                        facecolors="#deebf7", edgecolors="#6b8fb3", linewidths=0.4, alpha=0.8))
    if packing.links is not None and len(packing.links):
        li, lj = packing.links.i, packing.links.j
        seg = np.stack([x[li], x[li] + packing.box.minimum_image(packing.position[lj] - packing.position[li])[:, :2]],
                       axis=1)
        ax.add_collection(LineCollection(seg, linewidths=1.5, colors="#1b7837", label="links"))
    size = np.linalg.norm(disp, axis=1)
    moving = size > 1e-3 * size.max()
    ax.quiver(x[moving, 0], x[moving, 1], scale * disp[moving, 0], scale * disp[moving, 1], angles="xy",
              scale_units="xy", scale=1.0, color="#b2182b", width=0.004,
              label=f"displacement x {scale:.3g} (largest = one mean diameter)")
    pad = 0.6 * float(np.max(D))
    ax.set_xlim(corners[:, 0].min() - pad, corners[:, 0].max() + pad)
    ax.set_ylim(corners[:, 1].min() - pad, corners[:, 1].max() + pad)
    ax.set_aspect("equal")
    unit = packing.attrs.get("length_unit", "length unit")
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    value = float(modes["eigenvalue"].values[index])
    title = (f"mode {index} of {labels.size}: {MODE_LABELS[int(labels[index])].replace('_', ' ')}, "
             f"eigenvalue {value:.4g} epsilon / length^2")
    if int(modes.attrs.get("hessian_strain", 0)):
        eps = modes["mode_strain"].values[index]
        names = modes["strain_component"].values
        title += "\nstrain " + ", ".join(f"eps_{n} = {e:.3g}" for n, e in zip(names, eps))
    if packing.d > 2:
        title += f"\nprojection of all {packing.n} spheres on (x, y)"
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    return fig
