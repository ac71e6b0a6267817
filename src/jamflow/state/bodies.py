"""Bodies: fixed-length links between spheres, and 2D particle shapes.

Two extensions of a sphere packing, both optional on :class:`~jamflow.state.packing.Packing`:

- :class:`Links`: spheres ``i < j`` joined at a fixed centre distance (holonomic
  constraints of the chains model, ``soft-chains-of-spheres-packings.md`` Sec. II).
  Clusters are the connected components of the link graph; they are derived, never
  stored as the truth.
- :class:`ShapeTable`: the shapes of 2D anisotropic particles
  (``vanderwerf-et-al-hypostatic-nonspherical-packings.md``, Table I), each particle
  pointing into the table by ``shape_index`` and carrying an ``orientation`` [rad].

Shape parameters, all lengths in the packing's unit and in the body frame (the
particle's centroid at the origin, orientation 0):

=================  ==========================================================
kind               parameters
=================  ==========================================================
``disk``           ``radius`` R
``ellipse``        ``semi_axes`` (a, b), a >= b > 0, a along the body x axis
``circulo_line``   2 ``vertices`` (the segment ends, +-v) and rounding ``radius``
``circulo_polygon``  n >= 3 ``vertices`` (convex, counter-clockwise, area
                   centroid at the origin) and rounding ``radius`` > 0
``reuleaux``       3 ``vertices`` of an equilateral triangle centred on the origin;
                   each arc is centred on the opposite vertex with radius = side
``dumbbell``       2 ``vertices`` (lobe centres, +-v), lobe ``radius`` R and shaft
                   half-width ``shaft_half_width`` w, 0 < w < R, ``|2v| >= 2R``
=================  ==========================================================

A shaped particle's ``diameter`` is the diameter of its bounding circle (twice the
largest distance from the centroid to the surface): neighbour searches on bounding
radii then need nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import asin, pi, sqrt
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from ..box import Box
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.special import ellipe

__all__ = ["SHAPE_KINDS", "Links", "ShapeTable", "SHAPE_GEOMETRY_RTOL"]

#: Shape kinds, in the order of Table I families.
SHAPE_KINDS = ("disk", "ellipse", "circulo_line", "circulo_polygon", "reuleaux", "dumbbell")

#: Relative tolerance of the geometric consistency checks of a shape table (vertex
#: centroid at the origin, equal sides of a Reuleaux triangle, bounding diameter of a
#: shaped particle): parameters are stored in float64 and built from closed forms,
#: so anything beyond round-off (~1e-15) times a safety factor is an input error.
SHAPE_GEOMETRY_RTOL: float = 1e-9

_VERTEX_COUNT = {"disk": (0, 0), "ellipse": (0, 0), "circulo_line": (2, 2),
                 "circulo_polygon": (3, None), "reuleaux": (3, 3), "dumbbell": (2, 2)}


@dataclass(frozen=True, eq=False)
class Links:
    """Fixed-length links between particles.

    Attributes
    ----------
    i, j : ndarray of int64, shape (L,)
        Linked particles, ``i < j``; rows sorted lexicographically on construction.
    length : ndarray, shape (L,)
        Centre-to-centre link lengths [length], finite and > 0.
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    length: NDArray[np.float64]

    def __post_init__(self) -> None:
        i = np.asarray(self.i).reshape(-1)
        j = np.asarray(self.j).reshape(-1)
        length = np.asarray(self.length, dtype=np.float64).reshape(-1)
        if not (i.shape == j.shape == length.shape):
            raise ValueError(
                f"link_i, link_j and link_length must have one length, got {i.size}, {j.size}, {length.size}"
            )
        if i.size and not (np.issubdtype(i.dtype, np.integer) and np.issubdtype(j.dtype, np.integer)):
            raise ValueError("link indices must be integers")
        i, j = i.astype(np.int64), j.astype(np.int64)
        if np.any(i >= j):
            k = int(np.flatnonzero(i >= j)[0])
            raise ValueError(f"link {k} joins {i[k]} and {j[k]}: links must be pairs i < j")
        if not np.all(np.isfinite(length)) or np.any(length <= 0.0):
            k = int(np.flatnonzero(~(np.isfinite(length) & (length > 0.0)))[0])
            raise ValueError(f"link {k} ({i[k]}, {j[k]}) has length {length[k]}: lengths must be finite and > 0")
        order = np.lexsort((j, i))
        i, j, length = i[order], j[order], length[order]
        same = (i[1:] == i[:-1]) & (j[1:] == j[:-1])
        if np.any(same):
            k = int(np.flatnonzero(same)[0])
            raise ValueError(f"link ({i[k]}, {j[k]}) is given twice")
        object.__setattr__(self, "i", i)
        object.__setattr__(self, "j", j)
        object.__setattr__(self, "length", length)

    def __len__(self) -> int:
        return int(self.i.size)

    def scaled(self, factor: float) -> "Links":
        """Links with every length multiplied by ``factor``."""
        return Links(self.i, self.j, self.length * factor)

    def check_indices(self, n: int) -> None:
        """Raise ``ValueError`` if a link names a particle outside ``0 .. n-1``."""
        bad = (self.i < 0) | (self.j >= n)
        if np.any(bad):
            k = int(np.flatnonzero(bad)[0])
            raise ValueError(f"link ({self.i[k]}, {self.j[k]}) names a particle outside 0..{n - 1}")

    def contains(self, i: ArrayLike, j: ArrayLike) -> NDArray[np.bool_]:
        """Which pairs ``(i[k], j[k])``, ``i < j``, are links, shape (P,)."""
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        return np.isin((i << 32) | j, (self.i << 32) | self.j)

    def length_errors(self, position: NDArray[np.float64], box: "Box") -> NDArray[np.float64]:
        """Relative link-length errors ``|x_j - x_i| / l - 1`` (minimum image), shape (L,)."""
        r = np.linalg.norm(box.minimum_image(position[self.j] - position[self.i]), axis=1)
        return r / self.length - 1.0

    def clusters(self, n: int) -> NDArray[np.int64]:
        """Cluster label per particle: connected components of the link graph.

        Labels are ``0 .. C-1`` in order of each cluster's lowest particle index, so
        unlinked particles are clusters of one and the labelling is deterministic.
        """
        self.check_indices(n)
        graph = coo_matrix((np.ones(len(self)), (self.i, self.j)), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        _, first = np.unique(labels, return_index=True)
        relabel = np.empty(first.size, np.int64)
        relabel[np.argsort(first)] = np.arange(first.size)
        return relabel[labels]

    def centroid_reach(self, n: int) -> float:
        """An upper bound on the distance [length] of a particle from its cluster's centroid, links held.

        ``|x_s - X| <= (1/m) sum_t |x_s - x_t|`` over the cluster's ``m`` particles, and
        ``|x_s - x_t|`` is at most the links' path between them, at most the total length
        ``Lambda`` of a spanning tree of the cluster: so ``(m - 1) Lambda / m``, the
        largest over the clusters (0 without links).
        """
        if not len(self):
            return 0.0
        labels = self.clusters(n)
        tree = minimum_spanning_tree(coo_matrix((self.length, (self.i, self.j)), shape=(n, n))).tocoo()
        spans = np.bincount(labels[tree.row], weights=tree.data, minlength=labels.max() + 1)
        sizes = np.bincount(labels)
        return float(np.max((sizes - 1) / sizes * spans))


@dataclass(frozen=True, eq=False)
class ShapeTable:
    """A table of 2D particle shapes (see the module docstring for parameters).

    Attributes
    ----------
    kind : ndarray of str, shape (S,)
        One of :data:`SHAPE_KINDS` per shape.
    radius : ndarray, shape (S,)
        Disk radius, rounding radius (circulo-shapes) or lobe radius (dumbbell)
        [length]; NaN where it does not apply (ellipse, Reuleaux triangle).
    semi_axes : ndarray, shape (S, 2)
        Ellipse semi-axes (a, b) [length]; NaN for other kinds.
    vertices : ndarray, shape (S, V, 2)
        Body-frame vertices [length], padded with NaN beyond ``n_vertices``.
    n_vertices : ndarray of int64, shape (S,)
    shaft_half_width : ndarray, shape (S,)
        Dumbbell shaft half-width [length]; NaN for other kinds.
    """

    kind: NDArray[np.str_]
    radius: NDArray[np.float64]
    semi_axes: NDArray[np.float64]
    vertices: NDArray[np.float64]
    n_vertices: NDArray[np.int64]
    shaft_half_width: NDArray[np.float64]

    def __post_init__(self) -> None:
        kind = np.asarray(self.kind, dtype=str).reshape(-1)
        s = kind.size
        if s == 0:
            raise ValueError("a shape table needs at least one shape")
        radius = _float_array(self.radius, (s,), "shape_radius")
        semi = _float_array(self.semi_axes, (s, 2), "semi_axes")
        nv = np.asarray(self.n_vertices).reshape(-1)
        if nv.shape != (s,) or not np.issubdtype(nv.dtype, np.integer):
            raise ValueError(f"n_vertices must be {s} integers, got {nv!r}")
        nv = nv.astype(np.int64)
        verts = np.asarray(self.vertices, dtype=np.float64)
        if verts.ndim != 3 or verts.shape[0] != s or verts.shape[2] != 2:
            raise ValueError(f"vertices must have shape ({s}, V, 2), got {verts.shape}")
        if np.any(nv < 0) or np.any(nv > verts.shape[1]):
            raise ValueError(f"n_vertices must lie in 0..{verts.shape[1]} (the vertex dimension)")
        width = _float_array(self.shaft_half_width, (s,), "shaft_half_width")
        for k in range(s):
            _check_shape(k, str(kind[k]), radius[k], semi[k], verts[k, : nv[k]], width[k])
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "semi_axes", semi)
        object.__setattr__(self, "vertices", verts)
        object.__setattr__(self, "n_vertices", nv)
        object.__setattr__(self, "shaft_half_width", width)

    @classmethod
    def from_shapes(cls, shapes: list[dict]) -> "ShapeTable":
        """Build a table from one dict per shape.

        Each dict has ``kind`` and the keys its kind needs: ``radius``, ``semi_axes``,
        ``vertices`` (sequence of (x, y)), ``shaft_half_width``.
        """
        s = len(shapes)
        v_max = max((len(sh.get("vertices", ())) for sh in shapes), default=0)
        verts = np.full((s, v_max, 2), np.nan)
        nv = np.zeros(s, np.int64)
        for k, sh in enumerate(shapes):
            v = np.asarray(sh.get("vertices", np.empty((0, 2))), dtype=np.float64).reshape(-1, 2)
            verts[k, : len(v)] = v
            nv[k] = len(v)
        return cls(
            kind=np.array([sh["kind"] for sh in shapes], dtype=str),
            radius=np.array([sh.get("radius", np.nan) for sh in shapes], dtype=np.float64),
            semi_axes=np.array([sh.get("semi_axes", (np.nan, np.nan)) for sh in shapes], dtype=np.float64),
            vertices=verts,
            n_vertices=nv,
            shaft_half_width=np.array([sh.get("shaft_half_width", np.nan) for sh in shapes], dtype=np.float64),
        )

    def __len__(self) -> int:
        return int(self.kind.size)

    def scaled(self, factor: float) -> "ShapeTable":
        """Table with every length multiplied by ``factor``."""
        return ShapeTable(self.kind, self.radius * factor, self.semi_axes * factor,
                          self.vertices * factor, self.n_vertices, self.shaft_half_width * factor)

    def vertex_list(self, k: int) -> NDArray[np.float64]:
        """Body-frame vertices of shape ``k``, shape (n_k, 2) [length]."""
        return self.vertices[k, : self.n_vertices[k]]

    def outline(self, k: int, points_per_turn: int = 256) -> NDArray[np.float64]:
        """Body-frame boundary of shape ``k`` as a closed counter-clockwise polygon.

        Curved parts are sampled with ``points_per_turn`` points per full turn (the
        polygon's area converges to :attr:`area` as ``points_per_turn**-2``); for
        drawing and export, not for contact geometry.

        Returns
        -------
        ndarray, shape (M, 2) [length]
            Boundary points, the first not repeated at the end.
        """
        kind = self.kind[k]
        r = float(self.radius[k])
        v = self.vertex_list(k)
        if kind == "disk":
            return _arc(np.zeros(2), r, 0.0, 2.0 * pi, points_per_turn, closed=False)
        if kind == "ellipse":
            a, b = self.semi_axes[k]
            t = np.linspace(0.0, 2.0 * pi, points_per_turn, endpoint=False)
            return np.stack([a * np.cos(t), b * np.sin(t)], axis=1)
        if kind == "reuleaux":
            return np.concatenate([
                _arc(v[m], float(np.linalg.norm(v[(m + 1) % 3] - v[m])), _angle(v[(m + 1) % 3] - v[m]),
                     pi / 3.0, points_per_turn, closed=False) for m in range(3)
            ])
        if kind == "dumbbell":
            u = v[1] / np.linalg.norm(v[1])
            alpha = asin(float(self.shaft_half_width[k]) / r)
            start = _angle(u) - (pi - alpha)
            return np.concatenate([_arc(v[1], r, start, 2.0 * (pi - alpha), points_per_turn),
                                   _arc(v[0], r, start + pi, 2.0 * (pi - alpha), points_per_turn)])
        # circulo-line and -polygon: at each vertex, an arc between the outward normals
        # of its two edges (a half turn at each end of a circulo-line)
        edge = np.roll(v, -1, axis=0) - v
        normal = np.stack([edge[:, 1], -edge[:, 0]], axis=1)
        out = []
        for m in range(len(v)):
            a0, a1 = _angle(normal[m - 1]), _angle(normal[m])
            out.append(_arc(v[m], r, a0, (a1 - a0) % (2.0 * pi) or 2.0 * pi, points_per_turn))
        return np.concatenate(out)

    @property
    def area(self) -> NDArray[np.float64]:
        """Exact area of each shape, shape (S,) [length^2]."""
        return np.array([_area_perimeter(self, k)[0] for k in range(len(self))])

    @property
    def perimeter(self) -> NDArray[np.float64]:
        """Exact perimeter of each shape, shape (S,) [length] (ellipses by the
        complete elliptic integral of the second kind)."""
        return np.array([_area_perimeter(self, k)[1] for k in range(len(self))])

    @property
    def asphericity(self) -> NDArray[np.float64]:
        """Asphericity ``A = p^2 / (4 pi a)`` of each shape (1 for a disk)."""
        return self.perimeter**2 / (4.0 * pi * self.area)

    @property
    def gyration_squared(self) -> NDArray[np.float64]:
        """Polar second moment of area about the centroid per unit area, shape (S,) [length^2].

        A body of uniform density and mass ``m`` has the moment of inertia
        ``m * gyration_squared`` about its centroid. Exact for every kind:
        circulo-shapes as polygon + edge rectangles + vertex sectors, a Reuleaux
        triangle as three sectors minus twice the triangle, a dumbbell as two disks
        plus the shaft minus the shaft's caps inside the lobes (closed form).
        """
        return np.array([_gyration_squared(self, k) for k in range(len(self))])

    @property
    def bounding_radius(self) -> NDArray[np.float64]:
        """Largest distance from the centroid to the surface, shape (S,) [length]."""
        out = np.empty(len(self))
        for k, kind in enumerate(self.kind):
            v = self.vertex_list(k)
            far = float(np.max(np.linalg.norm(v, axis=1))) if len(v) else 0.0
            if kind == "ellipse":
                out[k] = self.semi_axes[k, 0]
            elif kind == "reuleaux":
                out[k] = far
            else:
                out[k] = far + self.radius[k]
        return out


def _angle(vec: NDArray[np.float64]) -> float:
    return float(np.arctan2(vec[1], vec[0]))


def _arc(centre: NDArray[np.float64], radius: float, start: float, sweep: float, points_per_turn: int,
         closed: bool = True) -> NDArray[np.float64]:
    """Points on a counter-clockwise arc, both ends included when ``closed``."""
    n = max(2, int(np.ceil(points_per_turn * sweep / (2.0 * pi))) + 1)
    t = start + np.linspace(0.0, sweep, n, endpoint=closed)
    return centre + radius * np.stack([np.cos(t), np.sin(t)], axis=1)


def _float_array(values: ArrayLike, shape: tuple[int, ...], name: str) -> NDArray[np.float64]:
    a = np.asarray(values, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    return a


def _check_shape(k: int, kind: str, radius: float, semi: NDArray[np.float64],
                 v: NDArray[np.float64], width: float) -> None:
    """One clear error for the first inconsistent parameter of shape ``k``."""
    name = f"shape {k} ({kind})"
    if kind not in SHAPE_KINDS:
        raise ValueError(f"shape {k} has unknown kind {kind!r}; known: {', '.join(SHAPE_KINDS)}")
    lo, hi = _VERTEX_COUNT[kind]
    if len(v) < lo or (hi is not None and len(v) > hi):
        want = f"{lo}" if lo == hi else f"at least {lo}"
        raise ValueError(f"{name} has {len(v)} vertices; it needs {want}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} has non-finite vertices")
    if kind in ("disk", "circulo_line", "circulo_polygon", "dumbbell"):
        if not (np.isfinite(radius) and radius > 0.0):
            raise ValueError(f"{name} needs a finite radius > 0, got {radius}")
    if kind == "ellipse":
        a, b = semi
        if not (np.isfinite(a) and np.isfinite(b) and a >= b > 0.0):
            raise ValueError(f"{name} needs semi-axes a >= b > 0, got ({a}, {b})")
        return
    if len(v) == 0:
        return
    scale = float(np.max(np.linalg.norm(v, axis=1)))
    if scale == 0.0:
        raise ValueError(f"{name} has all vertices at the centroid")
    if kind in ("circulo_line", "dumbbell"):
        if np.linalg.norm(v[0] + v[1]) > SHAPE_GEOMETRY_RTOL * scale:
            raise ValueError(f"{name} must have its two vertices at +-v about the centroid")
    if kind == "dumbbell":
        half = float(np.linalg.norm(v[0]))
        if not (np.isfinite(width) and 0.0 < width < radius):
            raise ValueError(f"{name} needs a shaft half-width 0 < w < radius, got {width}")
        if half < radius * (1.0 - SHAPE_GEOMETRY_RTOL):
            raise ValueError(f"{name} lobes overlap: lobe centre distance {2 * half} < 2 radius {2 * radius}")
    if kind in ("circulo_polygon", "reuleaux"):
        _check_convex_polygon(name, v, scale)
    if kind == "reuleaux":
        sides = np.linalg.norm(v - np.roll(v, -1, axis=0), axis=1)
        if np.ptp(sides) > SHAPE_GEOMETRY_RTOL * sides.max():
            raise ValueError(f"{name} vertices must form an equilateral triangle, sides {sides}")


def _check_convex_polygon(name: str, v: NDArray[np.float64], scale: float) -> None:
    edge = np.roll(v, -1, axis=0) - v
    cross = edge[:, 0] * np.roll(edge, -1, axis=0)[:, 1] - edge[:, 1] * np.roll(edge, -1, axis=0)[:, 0]
    if np.any(cross <= SHAPE_GEOMETRY_RTOL * scale**2):
        raise ValueError(f"{name} vertices must form a strictly convex counter-clockwise polygon")
    area, centroid = _polygon_area_centroid(v)
    if np.linalg.norm(centroid) > SHAPE_GEOMETRY_RTOL * scale:
        raise ValueError(f"{name} area centroid {centroid} must be at the origin (vertices relative to it)")


def _polygon_area_centroid(v: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    area = 0.5 * float(cross.sum())
    centroid = ((v + w) * cross[:, None]).sum(axis=0) / (6.0 * area)
    return area, centroid


def _area_perimeter(table: ShapeTable, k: int) -> tuple[float, float]:
    kind = table.kind[k]
    r = float(table.radius[k])
    v = table.vertex_list(k)
    if kind == "disk":
        return pi * r * r, 2.0 * pi * r
    if kind == "ellipse":
        a, b = (float(x) for x in table.semi_axes[k])
        return pi * a * b, 4.0 * a * float(ellipe(1.0 - (b / a) ** 2))
    if kind == "circulo_line":
        length = float(np.linalg.norm(v[1] - v[0]))
        return 2.0 * r * length + pi * r * r, 2.0 * length + 2.0 * pi * r
    if kind == "circulo_polygon":
        area, _ = _polygon_area_centroid(v)
        p = float(np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1).sum())
        return area + p * r + pi * r * r, p + 2.0 * pi * r
    if kind == "reuleaux":
        s = float(np.linalg.norm(v[1] - v[0]))
        return 0.5 * (pi - sqrt(3.0)) * s * s, pi * s
    # dumbbell: two disjoint lobes joined by a rectangular shaft of width 2w; each lobe
    # hides the shaft's end cap of area w sqrt(R^2 - w^2) + R^2 asin(w / R).
    w = float(table.shaft_half_width[k])
    length = float(np.linalg.norm(v[1] - v[0]))
    cap = w * sqrt(r * r - w * w) + r * r * asin(w / r)
    area = 2.0 * pi * r * r + 2.0 * w * length - 2.0 * cap
    perimeter = 2.0 * r * (2.0 * pi - 2.0 * asin(w / r)) + 2.0 * (length - 2.0 * sqrt(r * r - w * w))
    return area, perimeter


def _polygon_moment(v: NDArray[np.float64]) -> tuple[float, float]:
    """Area and polar second moment about the origin of a simple polygon (either orientation)."""
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    area = 0.5 * float(cross.sum())
    j = float(np.sum(cross * (v[:, 0] ** 2 + v[:, 0] * w[:, 0] + w[:, 0] ** 2
                              + v[:, 1] ** 2 + v[:, 1] * w[:, 1] + w[:, 1] ** 2))) / 12.0
    return abs(area), j if area >= 0.0 else -j


def _sector_moment(apex: NDArray[np.float64], radius: float, start: float, sweep: float) -> tuple[float, float]:
    """Area and polar second moment about the origin of a circular sector.

    About its apex the sector has ``J = r^4 phi / 4``; its centroid lies on the
    bisector at ``4 r sin(phi/2) / (3 phi)``; shifting to the origin adds
    ``A |apex|^2 + 2 apex . A c``.
    """
    area = 0.5 * radius * radius * sweep
    mid = start + 0.5 * sweep
    arm = 4.0 * radius * np.sin(0.5 * sweep) / (3.0 * sweep)
    centroid = arm * np.array([np.cos(mid), np.sin(mid)])
    j = radius**4 * sweep / 4.0 + area * float(apex @ apex) + 2.0 * area * float(apex @ centroid)
    return area, j


def _gyration_squared(table: ShapeTable, k: int) -> float:
    kind = table.kind[k]
    r = float(table.radius[k])
    v = table.vertex_list(k)
    if kind == "disk":
        return 0.5 * r * r
    if kind == "ellipse":
        a, b = (float(x) for x in table.semi_axes[k])
        return 0.25 * (a * a + b * b)
    if kind in ("circulo_line", "circulo_polygon"):
        area, j = _polygon_moment(v) if len(v) > 2 else (0.0, 0.0)
        edge = np.roll(v, -1, axis=0) - v
        normal = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / np.linalg.norm(edge, axis=1)[:, None]
        for m in range(len(v)):
            w = v[(m + 1) % len(v)]
            a_rect, j_rect = _polygon_moment(np.array([v[m], w, w + r * normal[m], v[m] + r * normal[m]]))
            a0, a1 = _angle(normal[m - 1]), _angle(normal[m])
            a_sec, j_sec = _sector_moment(v[m], r, a0, (a1 - a0) % (2.0 * pi) or 2.0 * pi)
            area += a_rect + a_sec
            j += j_rect + j_sec
        return j / area
    if kind == "reuleaux":
        side = float(np.linalg.norm(v[1] - v[0]))
        area, j = -2.0 * np.array(_polygon_moment(v))
        for m in range(3):
            a_sec, j_sec = _sector_moment(v[m], side, _angle(v[(m + 1) % 3] - v[m]), pi / 3.0)
            area += a_sec
            j += j_sec
        return float(j / area)
    return _dumbbell_gyration_squared(r, float(table.shaft_half_width[k]), 0.5 * float(np.linalg.norm(v[1] - v[0])))


def _dumbbell_gyration_squared(r: float, w: float, h: float) -> float:
    """Polar second moment per unit area of a dumbbell: lobes ``r`` at ``+-h`` on x, shaft half-width ``w``.

    Two disks (``J = pi r^4 / 2 + pi r^2 h^2`` each) plus the shaft rectangle
    ``[-h, h] x [-w, w]`` minus twice its part inside a lobe, the cap
    ``{|y| <= w, -h <= x <= -h + s(y)}``, ``s = sqrt(r^2 - y^2)``, whose moment about
    the origin is ``int (s^3/3 - h s^2 + h^2 s + y^2 s) dy`` over ``[-w, w]`` in closed form.
    """
    s = sqrt(r * r - w * w)
    angle = asin(w / r)
    int_s = w * s + r * r * angle                                          # int s dy
    int_s2 = 2.0 * w * r * r - 2.0 * w**3 / 3.0                            # int s^2 dy
    int_s3 = w * (5.0 * r * r - 2.0 * w * w) * s / 4.0 + 3.0 * r**4 * angle / 4.0  # int s^3 dy
    int_y2s = w * (2.0 * w * w - r * r) * s / 4.0 + r**4 * angle / 4.0    # int y^2 s dy
    cap_area = int_s
    cap_j = int_s3 / 3.0 - h * int_s2 + h * h * int_s + int_y2s
    rect_area = 4.0 * h * w
    rect_j = rect_area * (4.0 * h * h + 4.0 * w * w) / 12.0
    area = 2.0 * pi * r * r + rect_area - 2.0 * cap_area
    j = 2.0 * (0.5 * pi * r**4 + pi * r * r * h * h) + rect_j - 2.0 * cap_j
    return j / area
