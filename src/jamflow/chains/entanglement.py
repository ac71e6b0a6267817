"""Entangled linked packings: links that passed through each other during a soft minimisation.

Soft spheres may overlap, so a link (a rigid distance between two sphere centres) can
pass through a sphere or another link while a minimisation starts from, or goes
through, an overlapping configuration. The clusters then end entangled: in 2D two
links cross (a state no minimisation undoes, chains paper Fig. 3), in any dimension
spheres of different clusters stay pushed into each other with overlaps far beyond
the pressure's, their contact forces balanced by link tensions instead of the
pressure. Such a state is not a jammed packing; :func:`check_untangled` refuses it
with one clear error, after every minimum of the jamming protocols
(:mod:`jamflow.chains.jamming`).

Criteria (each tolerance with its meaning in :mod:`jamflow.tolerances`):

- (2D) any pair of crossing links (:func:`~jamflow.chains.builders.crossing_links`);
- (any d) a pair that is not linked with relative overlap above
  :data:`~jamflow.tolerances.ENTANGLED_OVERLAP` *and* force above
  :data:`~jamflow.tolerances.ENTANGLED_FORCE_RATIO` times the pressure's force scale
  ``f_P = d V P / sum_c r_c`` (the mean contact force if contacts alone carried the
  pressure ``P``; a pressure ``P <= 0`` makes every such overlap count).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..box import Box
from ..models.spheres.potential import HARMONIC, PowerLawPotential, overlapping_pairs
from ..state.bodies import Links
from ..tolerances import ENTANGLED_FORCE_RATIO, ENTANGLED_OVERLAP
from .builders import crossing_links

__all__ = ["EntanglementError", "check_untangled"]

#: The remedy named by every entanglement error.
REMEDY = ("start from the dilute placement without overlaps (jamflow init-chains --no-overlap, its default) so "
          "that links cannot pass through spheres")


class EntanglementError(RuntimeError):
    """Clusters of a linked packing ended entangled (module doc): not a jammed packing."""


def check_untangled(links: Links, position: ArrayLike, box: Box, diameter: ArrayLike, pressure: float,
                    potential: PowerLawPotential = HARMONIC, phi: float | None = None) -> None:
    """Raise :class:`EntanglementError` if the linked configuration is entangled (module doc).

    Parameters
    ----------
    links : Links
    position : array_like, shape (N, d)
        Centres [length] in ``box``.
    box : Box
    diameter : array_like, shape (N,)
        Diameters [length].
    pressure : float
        Virial pressure of the configuration (contacts and link tensions) [energy / length^d].
    potential : PowerLawPotential
        Pair potential (the contact forces).
    phi : float, optional
        Packing fraction named in the message.
    """
    if not len(links):
        return
    x = np.asarray(position, dtype=np.float64)
    labels = links.clusters(len(x))
    at = f" at phi = {phi:.6f}" if phi is not None else ""
    if box.d == 2:
        cross = crossing_links(links, x, box)
        if len(cross):
            a, b = cross[0]
            raise EntanglementError(
                f"{len(cross)} pair(s) of links cross{at}, e.g. link ({links.i[a]}, "
                f"{links.j[a]}) of cluster {labels[links.i[a]]} and ({links.i[b]}, {links.j[b]}) of cluster "
                f"{labels[links.i[b]]}: links passed through each other during the minimisation; {REMEDY}")
    pairs, xi, f = overlapping_pairs(x, box, diameter, potential)
    free = ~links.contains(pairs.i, pairs.j)
    if not np.any(free):
        return
    xi, f, r = xi[free], f[free], pairs.distance[free]
    i, j = pairs.i[free], pairs.j[free]
    scale = box.d * box.volume * pressure / r.sum()
    trapped = (xi > ENTANGLED_OVERLAP) & ((f > ENTANGLED_FORCE_RATIO * scale) if scale > 0.0 else True)
    if np.any(trapped):
        worst = np.flatnonzero(trapped)[np.argsort(-xi[trapped])][:3]
        named = ", ".join(f"({i[k]}, {j[k]}) of clusters ({labels[i[k]]}, {labels[j[k]]}): {xi[k]:.3g}" for k in worst)
        raise EntanglementError(
            f"{int(trapped.sum())} pair(s) of spheres are trapped in overlaps beyond {ENTANGLED_OVERLAP:g} "
            f"diameters{at} with forces above {ENTANGLED_FORCE_RATIO:g} times the pressure's (P = {pressure:.3g}), "
            f"worst {named}: entangled clusters; {REMEDY}")
