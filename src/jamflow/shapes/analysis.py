"""Analyses of shape packings: the contact-angle distribution P(psi) (VanderWerf et al. Fig. 14)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..state.packing import Packing
from .counting import count_constraints

__all__ = ["contact_angle_dataset", "contact_angle_distribution", "contact_angles"]

_ELONGATED = ("ellipse", "circulo_line")


def contact_angles(packing: Packing, parallel: str = "once", rattlers: bool = False) -> NDArray[np.float64]:
    """Contact angles ``psi`` in [0, pi/2] [rad], two per contact (between non-rattlers unless ``rattlers``).

    ``psi`` is the angle between a body's long axis (the body-frame x axis: an
    ellipse's major axis, a circulo-line's shaft) and the vector from its centre to the
    contact point (Fig. 14 inset): 0 at the tip, pi/2 at the side.

    Raises
    ------
    ValueError
        Bodies without a long axis (circulo-polygons, disks).
    """
    kinds = set(packing.shapes.kind[packing.shape_index]) if packing.shapes is not None else set()
    if not kinds or not kinds <= set(_ELONGATED):
        raise ValueError(f"contact angles need elongated bodies ({', '.join(_ELONGATED)}), got {sorted(kinds)}")
    _, rattler, _, cs = count_constraints(packing, parallel)
    live = np.ones(cs.n_contacts, dtype=bool) if rattlers else ~(rattler[cs.i] | rattler[cs.j])
    out = []
    for body, arm in ((cs.i, cs.arm_i), (cs.j, cs.arm_j)):
        theta = packing.orientation[body[live]]
        axis = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        a = arm[live]
        cos = np.abs(np.sum(a * axis, axis=1)) / np.linalg.norm(a, axis=1)
        out.append(np.arccos(np.clip(cos, 0.0, 1.0)))
    return np.concatenate(out)


def contact_angle_distribution(psi: NDArray[np.float64], bins: int = 18) -> tuple[NDArray, NDArray]:
    """Normalised histogram ``P(psi)`` on [0, pi/2]: bin centres [rad] and densities [1/rad]."""
    density, edges = np.histogram(psi, bins=bins, range=(0.0, 0.5 * np.pi), density=True)
    return 0.5 * (edges[1:] + edges[:-1]), density


def contact_angle_dataset(packings: Sequence[Packing], parallel: str = "once", bins: int = 18) -> xr.Dataset:
    """``P(psi)`` pooled over packings (Fig. 14): ``P_psi(bin)`` [1/rad] at ``psi(bin)`` [rad].

    Two angles per contact between non-rattlers (one per body). ``P_psi_err`` is the
    counting (Poisson) error of each bin, ``sqrt(n_bin) / (n width)``; the density
    integrates to 1 over [0, pi/2], and a contact direction uniform relative to the
    body axis gives the flat ``2 / pi``.
    """
    if not packings:
        raise ValueError("contact angles need at least one packing")
    psi = np.concatenate([contact_angles(p, parallel) for p in packings])
    if psi.size == 0:
        raise ValueError("no contacts between non-rattlers in the input packings")
    centres, density = contact_angle_distribution(psi, bins)
    width = 0.5 * np.pi / bins
    counts = density * psi.size * width
    a = np.concatenate([p.shapes.asphericity[p.shape_index] for p in packings])
    b = ("bin",)
    return xr.Dataset(
        data_vars={
            "P_psi": (b, density, {"units": "1/rad", "long_name": "contact-angle density P(psi)"}),
            "P_psi_err": (b, np.sqrt(counts) / (psi.size * width),
                          {"units": "1/rad", "long_name": "counting error of P(psi)"}),
            "count": (b, np.rint(counts).astype(np.int64), {"units": "1", "long_name": "angles in the bin"}),
        },
        coords={"psi": (b, centres, {"units": "rad", "long_name": "contact angle psi (bin centre), 0 at the tip"})},
        attrs={"n_angles": int(psi.size), "n_packings": len(packings), "parallel": parallel,
               "asphericity": float(np.mean(a)), "family": ",".join(sorted(set(packings[0].shapes.kind))),
               "N": int(max(p.n for p in packings)), "psi_mean": float(np.mean(psi)),
               "tip_fraction": float(np.mean(psi < np.pi / 4))},
    )
