"""Constraint counting of shape packings (VanderWerf et al. Sec. III B).

- **Contacts**: every interacting body pair is one contact; with
  ``parallel="twice"`` a circulo pair whose overlap holds two end-middle terms
  from two different vertices (a parallel or nearly parallel contact, Figs. 16-17)
  counts as two (Fig. 6 shows both conventions). Dumbbells are not convex, so a
  pair can touch at distinct points (two lobes, or a lobe in the concave corner on a
  lobe and the shaft): every end-end term is its own contact, and the end-shaft
  terms of one pair on one shaft (two lobes on a flat shaft, the analogue of Fig. 6)
  count once or, with ``parallel="twice"``, once per lobe. Reuleaux triangles are
  convex, so a pair touches in one overlap region: one contact per pair (with
  ``"twice"``, one per term; the arc-arc and vertex-arc terms exclude each other, so
  two terms in one pair need two vertices in one overlap, which jammed packings at
  small ``P0`` do not show).
- **Rattlers** (free translation and rotation): bodies with fewer than three
  contacts, removed repeatedly (:func:`jamflow.network.prune_rattlers` with two
  translational degrees of freedom per body). Three contacts are the fewest that
  balance a 2D force with repulsive normal forces; torque balance does not add a
  fourth, because hypostatic packings hold bodies with three contacts through
  quartic modes (their normals meet in a point), so the rotating-body rule
  ``d + 2`` of isostatic counting would call stable bodies rattlers.
- **Sliders** (one free translation, Fig. 3): :func:`jamflow.network.find_sliders`
  on the contact Jacobian with rotation columns.
- ``<z> = 2 (N_c + 1) / (N - N_r - N_s / 3)`` (Eq. 3) with ``N_c`` the contacts
  between non-rattlers; isostatic count ``N_c^0 = 3 (N - N_r) - 1 - N_s``
  (:func:`jamflow.network.isostatic_count` with 3 degrees of freedom per body,
  2 global translations, the pressure degree of freedom, one constraint fewer per
  slider; Fig. 3 c: ``3N - 2`` with one slider).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from ..models import model_for
from ..models.shapes import POINT_TERM_FAMILIES, ShapeModel, _kernels
from ..network import (
    ContactSet,
    contact_jacobian,
    find_sliders,
    isostatic_count,
    prune_rattlers,
    rigidity_counting,
)
from ..state.packing import Packing

__all__ = ["COUNTED_FAMILIES", "PARALLEL_MODES", "ShapeCounting", "count_constraints", "shape_contacts", "shape_model_of"]

#: How a parallel or nearly parallel circulo contact is counted (Fig. 6).
PARALLEL_MODES = ("once", "twice")

#: Model families whose contacts (points, normals) are implemented.
COUNTED_FAMILIES = ("circulo", "ellipse", "reuleaux", "dumbbell")


def shape_model_of(packing: Packing) -> tuple[ShapeModel, NDArray[np.float64]]:
    """:func:`jamflow.models.model_for` of a packing that must hold shaped bodies."""
    if packing.body_kind != "shapes":
        raise ValueError(f"not a shape packing (it holds {packing.body_kind})")
    return model_for(packing)


def shape_contacts(model: ShapeModel, q: NDArray[np.float64], parallel: str = "once") -> ContactSet:
    """Contacts of a shape configuration with normals and arms (rotations).

    One row per interacting pair at its deepest term (circulo, Reuleaux) or
    Perram–Wertheim contact point (ellipse); with ``parallel="twice"`` a second row
    for the other end-middle term of a parallel circulo contact. Dumbbells: see the
    module doc (:func:`_point_contacts`).
    """
    if parallel not in PARALLEL_MODES:
        raise ValueError(f"parallel contacts are counted {' or '.join(PARALLEL_MODES)}, got {parallel!r}")
    if model.family not in COUNTED_FAMILIES:
        raise ValueError(f"contact points and normals of {model.family} bodies are not implemented; "
                         f"counting covers {', '.join(COUNTED_FAMILIES)}")
    if model.family == "ellipse":
        pairs = model.pair_table(q)
        geo = _kernels.ellipse_contact_geometry(pairs["i"], pairs["j"], pairs["dx"], q[2 * model.n:], model.params)
        return ContactSet(pairs["i"], pairs["j"], geo[:, 2:], pairs["dx"], geo[:, :2], geo[:, :2] - pairs["dx"])
    if model.family in POINT_TERM_FAMILIES:
        return _point_contacts(model, q, parallel)
    t = model.contact_terms(q)
    x = model.positions(q)[:, :2]
    dx = model.box.minimum_image(x[t["j"]] - x[t["i"]])
    on_i = t["vertex_body"] == t["i"]
    normal = np.where(on_i[:, None], -t["normal"], t["normal"])
    arm_i = np.where(on_i[:, None], t["point"], t["point"] + dx)
    arm_j = arm_i - dx
    key = t["i"] * model.n + t["j"]
    middle = (t["t"] > 0.0) & (t["t"] < 1.0)
    keep = np.zeros(len(key), dtype=bool)
    for k in np.unique(key):
        rows = np.flatnonzero(key == k)
        keep[rows[np.argmax(t["delta"][rows])]] = True
        if parallel == "twice":
            em = rows[middle[rows]]
            vertices = {(int(t["vertex_body"][r]), int(t["vertex"][r])) for r in em}
            if len(vertices) >= 2:
                # the two deepest end-middle terms of distinct vertices
                order = em[np.argsort(-t["delta"][em])]
                first = (int(t["vertex_body"][order[0]]), int(t["vertex"][order[0]]))
                second = next(r for r in order if (int(t["vertex_body"][r]), int(t["vertex"][r])) != first)
                keep[rows] = False
                keep[[order[0], second]] = True
    return ContactSet(t["i"][keep], t["j"][keep], normal[keep], dx[keep], arm_i[keep], arm_j[keep])


def _point_contacts(model: ShapeModel, q: NDArray[np.float64], parallel: str) -> ContactSet:
    """Contacts of a Reuleaux or dumbbell configuration from its point terms (module doc).

    A term joins two body-fixed points; the force acts along the line through them, so
    the normal (from ``i`` to ``j``) is their direction and ``i``'s point is an arm
    on that line. Terms of one contact are reduced to the deepest.
    """
    t = model.point_terms(q)
    x = model.positions(q)[:, :2]
    dx = model.box.minimum_image(x[t["j"]] - x[t["i"]])
    normal = (t["point_j"] - t["point_i"]) / t["r"][:, None]
    if model.family == "reuleaux":
        group = np.zeros(len(dx), dtype=np.int64) if parallel == "once" else np.arange(len(dx))
    else:
        # end-end terms alone; end-shaft terms together per shaft (type 1 or 2), or alone with "twice"
        group = np.where(t["type"] == 0, 3 + 2 * t["a"] + t["b"],
                         t["type"] if parallel == "once" else 10 + 3 * t["type"] + t["a"] + t["b"])
    key = (t["i"] * model.n + t["j"]) * 64 + group
    keep = np.zeros(len(key), dtype=bool)
    for k in np.unique(key):
        rows = np.flatnonzero(key == k)
        keep[rows[np.argmax(t["delta"][rows])]] = True
    return ContactSet(t["i"][keep], t["j"][keep], normal[keep], dx[keep], t["point_i"][keep],
                      t["point_i"][keep] - dx[keep])


@dataclass(frozen=True)
class ShapeCounting:
    """Counts of Sec. III B (see the module doc)."""

    n_contacts: int
    n_rattlers: int
    n_sliders: int
    z: float
    isostatic_count: int
    counting: str
    parallel: str

    def as_dict(self) -> dict:
        return asdict(self)


def count_constraints(packing: Packing, parallel: str = "once") -> tuple[ShapeCounting, NDArray[np.bool_],
                                                                         NDArray[np.bool_], ContactSet]:
    """Contacts, rattlers, sliders, ``<z>`` (Eq. 3) and the isostatic count of a shape packing.

    Returns
    -------
    counting, rattler (N,), slider (N,), contacts
        The counts, the rattler and slider masks, and the contact set (all contacts,
        rattlers' included).
    """
    model, q = shape_model_of(packing)
    cs = shape_contacts(model, q, parallel)
    n = packing.n
    rattler = prune_rattlers(cs, n, dofs_per_body=2)
    jac = contact_jacobian(cs, n, 2, rotations=True)
    slider = find_sliders(jac, cs, n, 2, rattler=rattler)
    live = ~(rattler[cs.i] | rattler[cs.j])
    n_c = int(np.count_nonzero(live))
    n_r, n_s = int(rattler.sum()), int(slider.sum())
    denominator = n - n_r - n_s / 3.0
    z = 2.0 * (n_c + 1) / denominator if denominator > 0 else 0.0
    n_iso = isostatic_count(n - n_r, 3, global_dofs=2, n_sliders=n_s) if n > n_r else 0
    return (ShapeCounting(n_c, n_r, n_s, z, n_iso, rigidity_counting(n_c, n_iso), parallel),
            rattler, slider, cs)
