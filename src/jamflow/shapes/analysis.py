"""Analyses of shape packings: the contact-angle distribution P(psi) (VanderWerf et al. Fig. 14)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..packing import Packing
from .counting import count_constraints

__all__ = ["contact_angles", "contact_angle_distribution"]

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
