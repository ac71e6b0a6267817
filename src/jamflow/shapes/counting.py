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
- **Rattlers** (every degree of freedom unconstrained, Eq. 3): bodies with fewer than
  three contacts, removed repeatedly, except a body pinched between two antiparallel
  contacts (:func:`jamflow.network.prune_unheld`). Three contacts are the fewest that
  balance a 2D force with repulsive normal forces; torque balance does not add a
  fourth, because hypostatic packings hold bodies with three contacts through
  quartic modes (their normals meet in a point), so the rotating-body rule
  ``d + 2`` of isostatic counting would call stable bodies rattlers. A pinched body
  carries force along its line and slides across it: a slider.
- **Sliders** (one free translation, Fig. 3): :func:`jamflow.network.find_sliders`,
  by rank: the normals of *every* contact point of the body (:func:`contact_points`:
  both end-middle terms of a parallel contact, whatever ``parallel`` says) leave a
  translation free.
- Two coordination numbers, never one word for both: ``z_contacts = 2 N_c / N'``
  (contacts per backbone body, ``N' = N - N_r``; ``jamflow check`` of spheres calls
  it ``z``) and ``z_eq3 = 2 (N_c + 1) / (N - N_r - N_s / f)`` (Eq. 3; 6 for an
  isostatic backbone of rotating bodies, ``f = 3``, and 4 for disks or bodies whose
  orientations are frozen, ``f = 2``), ``N_c`` the contacts between non-rattlers.
- Isostatic count ``N_c^0 = f (N - N_r) - 1 - N_s``
  (:func:`jamflow.network.isostatic_count` with ``f`` degrees of freedom per body,
  2 global translations, the pressure degree of freedom, one constraint fewer per
  slider; Fig. 3c: ``3N - 2`` with one slider; Fig. 3a, non-rotating: ``2N - 4``
  with a rattler and a slider).
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
    prune_unheld,
    rigidity_counting,
)
from ..state.packing import Packing

__all__ = ["COUNTED_FAMILIES", "PARALLEL_MODES", "ShapeCounting", "contact_points", "count_constraints",
           "coordination", "dofs_per_body", "shape_contacts", "shape_model_of"]

#: How a parallel or nearly parallel circulo contact is counted (Fig. 6).
PARALLEL_MODES = ("once", "twice")

#: A circulo foot parameter within this of 0 or 1 lies at the edge's end: the parameter is
#: a ratio of O(1) lengths computed to round-off (~1e-16); an end-end foot beyond the end
#: by less than 1e-12 edge lengths would need the pair aligned to 1e-12.
FOOT_ROUNDOFF: float = 1e-12

#: Model families whose contacts (points, normals) are implemented.
COUNTED_FAMILIES = ("circulo", "ellipse", "reuleaux", "dumbbell")


def shape_model_of(packing: Packing) -> tuple[ShapeModel, NDArray[np.float64]]:
    """:func:`jamflow.models.model_for` of a packing that must hold shaped bodies."""
    if packing.body_kind != "shapes":
        raise ValueError(f"not a shape packing (it holds {packing.body_kind})")
    return model_for(packing)


def dofs_per_body(packing: Packing) -> int:
    """3 for rotating bodies, 2 when the packing was jammed with frozen orientations (Fig. 3a)."""
    return 2 if int(packing.attrs.get("frozen_orientations", 0)) else 3


def _check_family(model: ShapeModel) -> None:
    if model.family not in COUNTED_FAMILIES:
        raise ValueError(f"contact points and normals of {model.family} bodies are not implemented; "
                         f"counting covers {', '.join(COUNTED_FAMILIES)}")


def _circulo_rows(model: ShapeModel, q: NDArray[np.float64]) -> tuple[dict, ContactSet]:
    """Every overlapping vertex-edge term of a circulo configuration as a contact row."""
    t = model.contact_terms(q)
    x = model.positions(q)[:, :2]
    dx = model.box.minimum_image(x[t["j"]] - x[t["i"]])
    on_i = t["vertex_body"] == t["i"]
    normal = np.where(on_i[:, None], -t["normal"], t["normal"])
    arm_i = np.where(on_i[:, None], t["point"], t["point"] + dx)
    return t, ContactSet(t["i"], t["j"], normal, dx, arm_i, arm_i - dx)


def _point_rows(model: ShapeModel, q: NDArray[np.float64]) -> tuple[dict, ContactSet]:
    """Every term of a Reuleaux or dumbbell configuration as a contact row.

    A term joins two body-fixed points; the force acts along the line through them, so
    the normal (from ``i`` to ``j``) is their direction and ``i``'s point is an arm
    on that line.
    """
    t = model.point_terms(q)
    x = model.positions(q)[:, :2]
    dx = model.box.minimum_image(x[t["j"]] - x[t["i"]])
    normal = (t["point_j"] - t["point_i"]) / t["r"][:, None]
    return t, ContactSet(t["i"], t["j"], normal, dx, t["point_i"], t["point_i"] - dx)


def _ellipse_rows(model: ShapeModel, q: NDArray[np.float64]) -> ContactSet:
    pairs = model.pair_table(q)
    geo = _kernels.ellipse_contact_geometry(pairs["i"], pairs["j"], pairs["dx"], q[2 * model.n:], model.params)
    return ContactSet(pairs["i"], pairs["j"], geo[:, 2:], pairs["dx"], geo[:, :2], geo[:, :2] - pairs["dx"])


def _rows(cs: ContactSet, keep: NDArray[np.bool_]) -> ContactSet:
    return ContactSet(cs.i[keep], cs.j[keep], cs.normal[keep], cs.separation[keep], cs.arm_i[keep], cs.arm_j[keep])


def contact_points(model: ShapeModel, q: NDArray[np.float64]) -> ContactSet:
    """Every contact point of a shape configuration, one row per energy term (ellipses: per pair).

    What a body's contacts block at first order (:func:`jamflow.network.find_sliders`)
    needs every point, not a count that merges two end-middle terms of a parallel
    contact into one.
    """
    _check_family(model)
    if model.family == "ellipse":
        return _ellipse_rows(model, q)
    return (_point_rows if model.family in POINT_TERM_FAMILIES else _circulo_rows)(model, q)[1]


def shape_contacts(model: ShapeModel, q: NDArray[np.float64], parallel: str = "once") -> ContactSet:
    """Contacts of a shape configuration with normals and arms (rotations).

    One row per interacting pair at its deepest term (circulo, Reuleaux) or
    Perram–Wertheim contact point (ellipse); with ``parallel="twice"`` a second row
    for the other end-middle term of a parallel circulo contact. Dumbbells: see the
    module doc (:func:`_point_contacts`).
    """
    if parallel not in PARALLEL_MODES:
        raise ValueError(f"parallel contacts are counted {' or '.join(PARALLEL_MODES)}, got {parallel!r}")
    _check_family(model)
    if model.family == "ellipse":
        return _ellipse_rows(model, q)
    if model.family in POINT_TERM_FAMILIES:
        return _point_contacts(model, q, parallel)
    t, rows = _circulo_rows(model, q)
    key = t["i"] * model.n + t["j"]
    # a foot exactly at a shaft end counts as end-middle: exactly aligned equal lines (all four
    # feet at shaft ends) are the paper's two end-middle contacts, the limit of a small shift
    middle = _foot_on_edge(model, q, t)
    keep = np.zeros(len(key), dtype=bool)
    for k in np.unique(key):
        rows_k = np.flatnonzero(key == k)
        keep[rows_k[np.argmax(t["delta"][rows_k])]] = True
        if parallel == "twice":
            em = rows_k[middle[rows_k]]
            vertices = {(int(t["vertex_body"][r]), int(t["vertex"][r])) for r in em}
            if len(vertices) >= 2:
                # the two deepest end-middle terms of distinct vertices
                order = em[np.argsort(-t["delta"][em])]
                first = (int(t["vertex_body"][order[0]]), int(t["vertex"][order[0]]))
                second = next(r for r in order if (int(t["vertex_body"][r]), int(t["vertex"][r])) != first)
                keep[rows_k] = False
                keep[[order[0], second]] = True
    return _rows(rows, keep)


def _foot_on_edge(model: ShapeModel, q: NDArray[np.float64], t: dict) -> NDArray[np.bool_]:
    """Whether each circulo term's unclamped foot lies on its edge, ends included (``0 <= t <= 1``).

    The kernel reports the clamped foot, so a foot at 0 or 1 is tested again: the
    vertex projects onto the edge's line within its end points.
    """
    on = (t["t"] > 0.0) & (t["t"] < 1.0)
    ends = np.flatnonzero(~on)
    if not ends.size:
        return on
    x = model.positions(q)
    for r in ends:
        a, b = (t["i"][r], t["j"][r]) if t["vertex_body"][r] == t["i"][r] else (t["j"][r], t["i"][r])
        pa, pb = model.params[a], model.params[b]
        va = _rotate(pa[2 + 2 * t["vertex"][r]: 4 + 2 * t["vertex"][r]], x[a, 2])
        e0, e1 = t["edge"][r], (t["edge"][r] + 1) % int(pb[1])
        s0 = _rotate(pb[2 + 2 * e0: 4 + 2 * e0], x[b, 2]) + model.box.minimum_image(x[b, :2] - x[a, :2])
        s1 = _rotate(pb[2 + 2 * e1: 4 + 2 * e1], x[b, 2]) + model.box.minimum_image(x[b, :2] - x[a, :2])
        e = s1 - s0
        foot = float((va - s0) @ e / (e @ e))
        on[r] = -FOOT_ROUNDOFF <= foot <= 1.0 + FOOT_ROUNDOFF
    return on


def _rotate(v: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _point_contacts(model: ShapeModel, q: NDArray[np.float64], parallel: str) -> ContactSet:
    """Contacts of a Reuleaux or dumbbell configuration from its point terms (module doc).

    Terms of one contact are reduced to the deepest.
    """
    t, rows = _point_rows(model, q)
    if model.family == "reuleaux":
        group = np.zeros(len(t["i"]), dtype=np.int64) if parallel == "once" else np.arange(len(t["i"]))
    else:
        # end-end terms alone; end-shaft terms together per shaft (type 1 or 2), or alone with "twice"
        group = np.where(t["type"] == 0, 3 + 2 * t["a"] + t["b"],
                         t["type"] if parallel == "once" else 10 + 3 * t["type"] + t["a"] + t["b"])
    key = (t["i"] * model.n + t["j"]) * 64 + group
    keep = np.zeros(len(key), dtype=bool)
    for k in np.unique(key):
        rows_k = np.flatnonzero(key == k)
        keep[rows_k[np.argmax(t["delta"][rows_k])]] = True
    return _rows(rows, keep)


@dataclass(frozen=True)
class ShapeCounting:
    """Counts of Sec. III B (see the module doc).

    ``z_contacts = 2 N_c / N'`` and ``z_eq3`` (Eq. 3) are the two coordination
    numbers; ``dofs_per_body`` is 3 (rotating) or 2 (frozen orientations, Fig. 3a).
    """

    n_contacts: int
    n_rattlers: int
    n_sliders: int
    z_contacts: float
    z_eq3: float
    isostatic_count: int
    counting: str
    parallel: str
    dofs_per_body: int

    def as_dict(self) -> dict:
        return asdict(self)


def coordination(n_contacts: int, n: int, n_rattlers: int, n_sliders: int, dofs: int) -> tuple[float, float]:
    """``z_contacts = 2 N_c / N'`` and Eq. 3's ``z_eq3 = 2 (N_c + 1) / (N - N_r - N_s / f)``; 0 without a backbone."""
    backbone = n - n_rattlers
    if backbone <= 0:
        return 0.0, 0.0
    return 2.0 * n_contacts / backbone, 2.0 * (n_contacts + 1) / (backbone - n_sliders / dofs)


def count_constraints(packing: Packing, parallel: str = "once") -> tuple[ShapeCounting, NDArray[np.bool_],
                                                                         NDArray[np.bool_], ContactSet]:
    """Contacts, rattlers, sliders, ``z_contacts``, ``z_eq3`` and the isostatic count of a shape packing.

    Returns
    -------
    counting, rattler (N,), slider (N,), contacts
        The counts, the rattler and slider masks, and the contact set (all contacts,
        rattlers' included).
    """
    model, q = shape_model_of(packing)
    cs = shape_contacts(model, q, parallel)
    n = packing.n
    f = dofs_per_body(packing)
    rattler = prune_unheld(cs, n)
    points = contact_points(model, q)
    slider = find_sliders(contact_jacobian(points, n, 2), points, n, 2, rattler=rattler)
    live = ~(rattler[cs.i] | rattler[cs.j])
    n_c = int(np.count_nonzero(live))
    n_r, n_s = int(rattler.sum()), int(slider.sum())
    z_contacts, z_eq3 = coordination(n_c, n, n_r, n_s, f)
    n_iso = isostatic_count(n - n_r, f, global_dofs=2, n_sliders=n_s)
    return (ShapeCounting(n_c, n_r, n_s, z_contacts, z_eq3, n_iso, rigidity_counting(n_c, n_iso), parallel, f),
            rattler, slider, cs)
