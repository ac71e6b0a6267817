"""Curvature of the contact constraints of circulo-line packings (VanderWerf et al. Sec. III C, Table II).

Each contact term is an inequality ``F(q) = r - sigma >= 0`` among the coordinates of
the two bodies it joins (App. A: the distance from a vertex to the other body's edge,
or between two vertices). Seen by one body with the other held fixed, ``F = 0`` is a
surface in that body's configuration space ``(x, y, theta)``; its principal curvatures

    kappa = eigenvalues of  -T^T H T / |g|

(``g`` and ``H`` the gradient and Hessian of ``F`` in the body's coordinates, ``T`` an
orthonormal basis of the plane normal to ``g``) are negative where the constraint is
concave, as for disks (``-1 / (R_i + R_j)`` and 0), and positive where it is convex: a
convex constraint bounds the feasible region with fewer contacts, which is how
hypostatic packings are mechanically stable. Lengths are in the paper's unit, the box
side ``L`` (``x -> x / L``, ``F -> F / L``, ``theta`` unchanged), so the numbers compare
with Table II (``N = 24`` bidisperse circulo-lines at ``A = 1.04``).

Contact types (App. A, Table II), two entries per contact, one per body:

- ``end_end``: the foot is clamped to an end of the other's shaft (both bodies ``end``);
  the two views of one end-end contact are one contact;
- ``parallel``: an end-middle term of a pair with end-middle terms of two distinct
  vertices (a parallel or nearly parallel contact, the ``twice`` rule of
  :mod:`jamflow.shapes.counting`);
- ``end_middle``: every other end-middle term.

Each gives an ``end`` particle (whose vertex touches) and a ``middle`` particle (whose
shaft is touched). For an ``end`` particle of a shaft contact one principal curvature
is exactly 0 (a slide along the other's shaft changes nothing); it is reported as such.

Other families, one type per kind of term: dumbbells ``lobe_lobe`` (both ``end``) and
``lobe_shaft`` (``end``: the lobe, ``middle``: the shaft, a line as for circulo-lines);
Reuleaux triangles ``arc_arc`` and ``vertex_arc`` (distances between two body-fixed
points: arc centres and vertices, both ``end``); ellipses ``ellipse`` (both ``either``):
the surface ``F_PW = 1`` of the Perram–Wertheim contact function, whose gradient and
Hessian are central differences of ``r (1 - F^(-1/2))`` (step 1e-5 of the body size:
curvatures to ~1e-6 relative).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..state.packing import Packing
from .counting import FOOT_ROUNDOFF, shape_model_of
from .survey import check_jammed

__all__ = ["CONTACT_TYPES", "OTHER_TYPES", "constraint_curvatures", "curvature_dataset", "principal_curvatures"]

#: Rows of Table II: (contact type, particle).
CONTACT_TYPES: tuple[tuple[str, str], ...] = (("parallel", "end"), ("parallel", "middle"), ("end_middle", "end"),
                                              ("end_middle", "middle"), ("end_end", "end"))

#: Rows of the other families (module doc).
OTHER_TYPES: tuple[tuple[str, str], ...] = (("lobe_lobe", "end"), ("lobe_shaft", "end"), ("lobe_shaft", "middle"),
                                            ("arc_arc", "end"), ("vertex_arc", "end"), ("ellipse", "either"))

#: Step [length, relative to the bounding diameter] of the ellipses' finite differences:
#: truncation ~step^2 ~1e-10 and round-off ~eps / step^2 ~1e-6 of the Hessian.
ELLIPSE_STEP: float = 1e-5

_J = np.array([[0.0, -1.0], [1.0, 0.0]])


def _rot(theta: float) -> NDArray[np.float64]:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def principal_curvatures(gradient: NDArray[np.float64], hessian: NDArray[np.float64]) -> NDArray[np.float64]:
    """Principal curvatures (ascending) of the surface ``F = 0`` with gradient ``g`` and Hessian ``H`` (module doc)."""
    g = np.asarray(gradient, dtype=np.float64)
    norm = float(np.linalg.norm(g))
    # an orthonormal basis of g's complement: the last two right singular vectors of g
    t = np.linalg.svd(g[None, :])[2][1:].T
    return np.sort(np.linalg.eigvalsh(-t.T @ hessian @ t / norm))


def _point_gap(arm: NDArray[np.float64], other: NDArray[np.float64], centre: NDArray[np.float64]
               ) -> tuple[NDArray, NDArray]:
    """Gradient and Hessian over ``(x, y, theta)`` of ``|c + arm - other|`` for a body-fixed ``arm`` (world frame)."""
    d = centre + arm - other
    r = float(np.linalg.norm(d))
    u = d / r
    proj = (np.eye(2) - np.outer(u, u)) / r
    turn = _J @ arm
    g = np.array([*u, turn @ u])
    h = np.zeros((3, 3))
    h[:2, :2] = proj
    h[:2, 2] = h[2, :2] = proj @ turn
    h[2, 2] = turn @ proj @ turn - u @ arm
    return g, h


def _line_gap_end(arm: NDArray[np.float64], normal: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """``(P - S) . n`` for the vertex ``P = c + arm`` of the moving body against a fixed line with unit normal ``n``."""
    g = np.array([*normal, (_J @ arm) @ normal])
    h = np.zeros((3, 3))
    h[2, 2] = -arm @ normal
    return g, h


def _line_gap_middle(point: NDArray[np.float64], centre: NDArray[np.float64], start: NDArray[np.float64],
                     normal: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """``(P - c - R s0) . R n0`` for a fixed point ``P`` against the moving body's edge line.

    ``start = R s0`` (edge start relative to the centre) and ``normal = R n0``, world frame.
    """
    d = point - centre - start
    jn = _J @ normal
    g = np.array([*(-normal), -(_J @ start) @ normal + d @ jn])
    h = np.zeros((3, 3))
    h[:2, 2] = h[2, :2] = -jn
    h[2, 2] = -(point - centre) @ normal
    return g, h


def _to_paper_units(g: NDArray, h: NDArray, side: float) -> tuple[NDArray, NDArray]:
    """Gradient and Hessian in lengths of the box side ``L`` (module doc)."""
    s = np.array([1.0, 1.0, 1.0 / side])
    return g * s, side * (s[:, None] * h * s[None, :])


def constraint_curvatures(packing: Packing, paper_units: bool = True) -> dict[str, NDArray]:
    """Principal curvatures of every contact constraint of a circulo-line packing, two rows per contact.

    Returns
    -------
    dict of arrays, one entry per (contact, body) row
        ``type`` (``parallel``, ``end_middle``, ``end_end``), ``particle`` (``end`` or
        ``middle``), ``body``, ``kappa`` (rows, 2) ascending [1 / L with
        ``paper_units``, else 1 / length], ``zero_direction`` (bool: the body is the
        ``end`` of a shaft contact, one curvature is exactly 0 and ``kappa`` holds it).
    """
    check_jammed(packing)
    model, q = shape_model_of(packing)
    side = float(np.sqrt(packing.box.volume)) if paper_units else 1.0
    out: dict[str, list] = {"type": [], "particle": [], "body": [], "kappa": [], "zero_direction": []}
    if model.family == "circulo":
        if set(packing.shapes.kind) != {"circulo_line"}:
            raise ValueError("constraint curvatures of circulo-polygons are not implemented (App. A's edge pairs); "
                             "circulo-lines, dumbbells, Reuleaux triangles and ellipses are")
        views = _circulo_views(model, q)
    elif model.family == "ellipse":
        views = _ellipse_views(model, q)
    else:
        views = _point_views(model, q)
    for kind, particle, body, g, h, zero in views:
        g, h = _to_paper_units(g, h, side)
        out["type"].append(kind)
        out["particle"].append(particle)
        out["body"].append(body)
        out["kappa"].append(principal_curvatures(g, h))
        out["zero_direction"].append(zero)
    return {k: np.array(v) if k != "kappa" else np.array(v).reshape(-1, 2) for k, v in out.items()}


def _circulo_views(model, q) -> list[tuple]:
    """(type, particle, body, gradient, Hessian, zero direction) of every circulo-line contact (module doc)."""
    t = model.contact_terms(q)
    x = model.positions(q)
    params = model.params
    key = t["i"] * model.n + t["j"]
    em = (t["t"] > 0.0) & (t["t"] < 1.0)
    parallel_pairs = {k for k in np.unique(key)
                      if len({(int(t["vertex_body"][r]), int(t["vertex"][r])) for r in np.flatnonzero((key == k) & em)}) >= 2}
    found = []
    seen_end_end = set()
    for r in range(len(key)):
        a = int(t["vertex_body"][r])
        b = int(t["j"][r]) if a == int(t["i"][r]) else int(t["i"][r])
        arm_a = _rot(x[a, 2]) @ params[a, 2 + 2 * t["vertex"][r]: 4 + 2 * t["vertex"][r]]
        # b's centre in a's frame of the minimum image; a's centre at the origin
        cb = model.box.minimum_image(x[b, :2] - x[a, :2])
        e0 = int(t["edge"][r])
        s0 = _rot(x[b, 2]) @ params[b, 2 + 2 * e0: 4 + 2 * e0]
        s1 = _rot(x[b, 2]) @ params[b, 2 + 2 * ((e0 + 1) % int(params[b, 1])): 4 + 2 * ((e0 + 1) % int(params[b, 1]))]
        foot = float((arm_a - cb - s0) @ (s1 - s0) / ((s1 - s0) @ (s1 - s0)))
        if -FOOT_ROUNDOFF <= foot <= 1.0 + FOOT_ROUNDOFF:
            kind = "parallel" if int(key[r]) in parallel_pairs else "end_middle"
            edge = (s1 - s0) / np.linalg.norm(s1 - s0)
            normal = _J @ edge
            if normal @ (arm_a - cb - s0) < 0.0:
                normal = -normal
            views = [("end", a, *_line_gap_end(arm_a, normal), True),
                     ("middle", b, *_line_gap_middle(arm_a, cb, s0, normal), False)]
        else:
            end = s0 if foot < 0.5 else s1
            vertex_b = 0 if foot < 0.5 else (e0 + 1) % int(params[b, 1])
            contact = (min((a, int(t["vertex"][r])), (b, vertex_b)), max((a, int(t["vertex"][r])), (b, vertex_b)))
            if contact in seen_end_end:
                continue
            seen_end_end.add(contact)
            kind = "end_end"
            views = [("end", a, *_point_gap(arm_a, cb + end, np.zeros(2)), False),
                     ("end", b, *_point_gap(end, arm_a, cb), False)]
        found += [(kind, *view) for view in views]
    return found


def _point_views(model, q) -> list[tuple]:
    """Dumbbell and Reuleaux terms: two body-fixed points, or a dumbbell lobe on a shaft line."""
    t = model.point_terms(q)
    x = model.positions(q)
    names = {"dumbbell": ("lobe_lobe", "lobe_shaft", "lobe_shaft"), "reuleaux": ("arc_arc", "vertex_arc", "vertex_arc")}
    found = []
    for r in range(len(t["i"])):
        i, j, kind = int(t["i"][r]), int(t["j"][r]), int(t["type"][r])
        dx = model.box.minimum_image(x[j, :2] - x[i, :2])
        pi, pj = t["point_i"][r], t["point_j"][r]
        name = names[model.family][kind]
        if model.family == "dumbbell" and kind > 0:
            # a lobe centre against the other's shaft line (type 1: i's lobe on j's shaft)
            lobe, shaft = (i, j) if kind == 1 else (j, i)
            lobe_point, foot = (pi, pj) if kind == 1 else (pj, pi)
            centre = {i: np.zeros(2), j: dx}
            v = model.params[shaft, 2:6].reshape(2, 2)
            axis = _rot(x[shaft, 2]) @ (v[1] - v[0])
            normal = _J @ axis / np.linalg.norm(axis)
            if normal @ (lobe_point - foot) < 0.0:
                normal = -normal
            start = _rot(x[shaft, 2]) @ v[0]
            found.append((name, "end", lobe, *_line_gap_end(lobe_point - centre[lobe], normal), True))
            found.append((name, "middle", shaft, *_line_gap_middle(lobe_point, centre[shaft], start, normal), False))
            continue
        found.append((name, "end", i, *_point_gap(pi, pj, np.zeros(2)), False))
        found.append((name, "end", j, *_point_gap(pj - dx, pi, dx), False))
    return found


def _ellipse_views(model, q) -> list[tuple]:
    """Ellipse pairs: the level set ``F_PW = 1`` seen by each body, by central differences (module doc)."""
    from ..models.shapes import _kernels

    pairs = model.pair_table(q)
    x = model.positions(q)
    found = []
    for i, j, dx in zip(pairs["i"], pairs["j"], pairs["dx"], strict=True):
        scale = ELLIPSE_STEP * float(model.bounding_diameter[[i, j]].mean())
        steps = np.array([scale, scale, ELLIPSE_STEP])

        def gap(d, ti, tj, i=i, j=j):
            f = _kernels.perram_wertheim(d[0], d[1], ti, tj, model.params[i], model.params[j])[0]
            return float(np.hypot(*d)) * (1.0 - f ** -0.5)

        for body, sign in ((i, -1.0), (j, 1.0)):
            def moved(c, body=body, sign=sign, dx=dx, i=i, j=j):
                t_i = x[i, 2] + (c[2] if body == i else 0.0)
                t_j = x[j, 2] + (c[2] if body == j else 0.0)
                return gap(dx + sign * c[:2], t_i, t_j)

            g, h = _differences(moved, steps)
            found.append(("ellipse", "either", int(body), g, h, False))
    return found


def _differences(f, steps: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Central-difference gradient and Hessian of ``f`` at 0 with per-coordinate steps."""
    g = np.zeros(3)
    h = np.zeros((3, 3))
    e = np.diag(steps)
    f0 = f(np.zeros(3))
    for a in range(3):
        g[a] = (f(e[a]) - f(-e[a])) / (2.0 * steps[a])
        h[a, a] = (f(e[a]) - 2.0 * f0 + f(-e[a])) / steps[a] ** 2
        for b in range(a):
            h[a, b] = h[b, a] = (f(e[a] + e[b]) - f(e[a] - e[b]) - f(-e[a] + e[b]) + f(-e[a] - e[b])) \
                / (4.0 * steps[a] * steps[b])
    return g, h


def _row_stats(kappa: NDArray, zero: NDArray, kind: str, particle: str) -> tuple[float, float, float, float]:
    """Mean and RMS deviation of kappa_1 and kappa_2 for one Table II row (NaN without contacts).

    Table II's convention: for an ``end`` particle of a shaft contact one curvature is the
    analytic 0 (``zero``); it is kappa_2 for end-middle (and dumbbell lobe-shaft) and kappa_1
    for parallel contacts, whose other curvature changes sign and is averaged in magnitude
    (the paper's asterisk).
    """
    if not len(kappa):
        return (np.nan,) * 4
    if np.all(zero) and len(zero):
        # the curvature that is not the analytic zero
        other = np.where(np.abs(kappa[:, 0]) >= np.abs(kappa[:, 1]), kappa[:, 0], kappa[:, 1])
        if kind == "parallel":
            k1, k2 = np.zeros(len(other)), np.abs(other)
        else:
            k1, k2 = other, np.zeros(len(other))
    else:
        k1, k2 = kappa[:, 0], kappa[:, 1]
    return float(np.mean(k1)), float(np.std(k1)), float(np.mean(k2)), float(np.std(k2))


def curvature_dataset(packings: Sequence[Packing], sources: Sequence[str]) -> xr.Dataset:
    """Table II over ``packings``: per (type, particle) row present the mean and RMS deviation of
    ``kappa_1`` and ``kappa_2`` [1 / L] and the number of contact rows, pooled and per packing.
    """
    if not packings:
        raise ValueError("constraint curvatures need at least one packing")
    rows = [constraint_curvatures(p) for p in packings]
    present = {(str(k), str(p)) for r in rows for k, p in zip(r["type"], r["particle"], strict=True)}
    types = [t for t in CONTACT_TYPES + OTHER_TYPES if t in present]
    names = [f"{k} ({p} particle)" for k, p in types]
    pooled = np.zeros((len(types), 4))
    per = np.zeros((len(packings), len(types), 4))
    count = np.zeros((len(packings), len(types)), dtype=np.int64)
    for c, (kind, particle) in enumerate(types):
        sel = [(r["type"] == kind) & (r["particle"] == particle) for r in rows]
        pooled[c] = _row_stats(np.concatenate([r["kappa"][s] for r, s in zip(rows, sel, strict=True)]),
                               np.concatenate([r["zero_direction"][s] for r, s in zip(rows, sel, strict=True)]),
                               kind, particle)
        for k, (r, s) in enumerate(zip(rows, sel, strict=True)):
            per[k, c] = _row_stats(r["kappa"][s], r["zero_direction"][s], kind, particle)
            count[k, c] = int(s.sum())
    one = {"units": "1/L", "comment": "L the box side (the paper's length unit); theta in rad"}
    t, pk = ("contact_type",), ("packing", "contact_type")
    stats = {"kappa1_mean": 0, "kappa1_rms": 1, "kappa2_mean": 2, "kappa2_rms": 3}
    data = {}
    for name, col in stats.items():
        what = f"{'mean' if name.endswith('mean') else 'RMS deviation from the mean'} of {name[:6]}"
        data[name] = (t, pooled[:, col], {**one, "long_name": f"{what}, all packings"})
        data[f"packing_{name}"] = (pk, per[:, :, col], {**one, "long_name": f"{what}, per packing"})
    data["n_contacts"] = (pk, count, {"units": "1", "long_name": "contact-body rows of the type"})
    area = [float(np.sum(p.shapes.area[p.shape_index])) / p.box.volume for p in packings]
    return xr.Dataset(
        data_vars=data,
        coords={"contact_type": (t, np.array(names, dtype=str), {"long_name": "contact type (particle)"}),
                "source": (("packing",), np.array(sources, dtype=str), {"long_name": "input packing file"}),
                "phi": (("packing",), np.array(area), {"units": "1", "long_name": "packing fraction"})},
        attrs={"n_packings": len(packings), "N": int(max(p.n for p in packings)),
               "asphericity": float(np.mean([np.mean(p.shapes.asphericity[p.shape_index]) for p in packings]))},
    )
