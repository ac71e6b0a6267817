"""Bidisperse shapes at a target aspect ratio or asphericity, and random initial packings.

VanderWerf et al. Sec. II: half the particles small, half large, areas ``a_L = 1.4^2
a_S``, equal masses; the large shape is the small one scaled by 1.4 (one asphericity).
Lengths are set so that the mean area-equivalent diameter ``2 sqrt(a / pi)`` is 1 (a
bidisperse disk packing in the units of the sphere code).

Shape families and their aspect ratio ``alpha`` (length over width):

- ``ellipse``: ``alpha = a / b``;
- ``circulo-line``: segment of length ``l``, radius ``R``: ``alpha = (l + 2R) / (2R)``
  (Table I: ``alpha - 1 = 1e-3`` gives ``A - 1 = 4.05e-7``);
- ``circulo-polygon``: regular ``n``-gon of circumradius ``rho`` rounded by ``R``; only
  the asphericity is a parameter (``R / rho`` is solved for it); or App. B's random
  polygons, one shape per body (:func:`random_polygon_shapes`);
- ``dumbbell``: lobes of radius ``R`` at ``+-v``, shaft half-width ``R / 2`` (Fig. 4),
  aspect ratio (tip to tip over the lobe diameter) ``alpha = (2 |v| + 2R) / (2R) >= 2``
  (lobes disjoint or touching), or the paper's *shaft length* ``X = 2 |v| / R``, the
  lobe-centre distance in lobe radii (Fig. 4: 2.4, isostatic, and 4, hypostatic), with
  ``alpha = 1 + X / 2``. Table I's dumbbell ``alpha - 1`` is this ``X``: ``X = 2`` (touching
  lobes) gives its ``A - 1 = 0.514``, ``X = 4`` gives 1.141; its upper ``A - 1 = 2.405`` is
  ``X = 8`` (``alpha - 1 = 4`` tip to tip), so the table's two columns disagree at the top;
- ``reuleaux``: no parameter (``A = pi / (2 (pi - sqrt 3)) = 1.1140``).

The asphericity ``A = p^2 / (4 pi a)`` of each is exact (:attr:`ShapeTable.asphericity`)
and a target ``A`` is met by bisection on the shape parameter to round-off.
"""

from __future__ import annotations

from math import pi, sqrt

import numpy as np

from ..box import Box
from ..models.shapes import ShapeModel, _kernels
from ..state.bodies import SHAPE_GEOMETRY_RTOL, ShapeTable, _polygon_area_centroid
from ..state.packing import Packing

__all__ = ["AREA_RATIO", "SHAPE_CHOICES", "SIZE_RATIO", "bidisperse_shapes", "random_circulo_polygon",
           "random_polygon_shapes", "random_shape_packing", "unit_shape"]

#: Shape families of ``jamflow init-shapes --shape`` (command-line spelling).
SHAPE_CHOICES = ("ellipse", "circulo-line", "circulo-polygon", "dumbbell", "reuleaux")

#: Linear size ratio large / small, so that ``a_L = 1.4^2 a_S`` (Sec. II).
SIZE_RATIO: float = 1.4
AREA_RATIO: float = SIZE_RATIO**2

#: Dumbbell shaft half-width over lobe radius (VanderWerf et al. Fig. 4).
DUMBBELL_WIDTH_RATIO: float = 0.5


def _shape(kind: str, x: float, sides: int) -> dict:
    """Shape of family ``kind`` with shape parameter ``x`` (aspect ratio, or ``R / rho``), unit width scale."""
    if kind == "ellipse":
        return dict(kind="ellipse", semi_axes=(x, 1.0))
    if kind == "circulo-line":
        return dict(kind="circulo_line", vertices=[(-(x - 1.0), 0.0), (x - 1.0, 0.0)], radius=1.0)
    if kind == "circulo-polygon":
        a = 2.0 * pi * np.arange(sides) / sides
        return dict(kind="circulo_polygon", vertices=np.stack([np.cos(a), np.sin(a)], axis=1), radius=x)
    if kind == "dumbbell":
        return dict(kind="dumbbell", vertices=[(-(x - 1.0), 0.0), (x - 1.0, 0.0)], radius=1.0,
                    shaft_half_width=DUMBBELL_WIDTH_RATIO)
    a = 2.0 * pi * np.arange(3) / 3
    return dict(kind="reuleaux", vertices=np.stack([np.cos(a), np.sin(a)], axis=1))


def _asphericity(kind: str, x: float, sides: int) -> float:
    return float(ShapeTable.from_shapes([_shape(kind, x, sides)]).asphericity[0])


def unit_shape(kind: str, aspect_ratio: float | None = None, asphericity: float | None = None,
               sides: int | None = None, shaft_length: float | None = None) -> dict:
    """One shape of family ``kind`` (see the module doc) at the given parameter, any scale.

    ``shaft_length`` (dumbbells only) is the paper's ``X``, the lobe-centre distance in
    lobe radii, the same shape as ``aspect_ratio = 1 + X / 2``.

    Raises
    ------
    ValueError
        Unknown family, a parameter the family does not take or lacks, or a target
        outside the family's range.
    """
    if kind not in SHAPE_CHOICES:
        raise ValueError(f"--shape must be one of {', '.join(SHAPE_CHOICES)}, got {kind!r}")
    if shaft_length is not None:
        if kind != "dumbbell":
            raise ValueError(f"--shaft-length is the dumbbell's lobe-centre distance, not a parameter of {kind}")
        if aspect_ratio is not None or asphericity is not None:
            raise ValueError("give one of --shaft-length, --aspect-ratio and --asphericity")
        if not (np.isfinite(shaft_length) and shaft_length >= 2.0):
            raise ValueError(f"--shaft-length is at least 2 (touching lobes), got {shaft_length}")
        aspect_ratio = 1.0 + 0.5 * shaft_length
    if aspect_ratio is not None and asphericity is not None:
        raise ValueError("give --aspect-ratio or --asphericity, not both")
    if kind == "circulo-polygon":
        if sides is None or sides < 3:
            raise ValueError(f"circulo-polygon needs --sides n >= 3, got {sides}")
    elif sides is not None:
        raise ValueError(f"--sides applies to circulo-polygon only, not {kind}")
    if kind == "reuleaux":
        if aspect_ratio is not None or asphericity is not None:
            raise ValueError("a Reuleaux triangle has no shape parameter (A = 1.1140): drop --aspect-ratio/--asphericity")
        return _shape(kind, 0.0, 0)
    low = 2.0 if kind == "dumbbell" else 1.0
    if kind == "circulo-polygon":
        if aspect_ratio is not None:
            raise ValueError("a circulo-polygon is set by --asphericity (and --sides), not --aspect-ratio")
        if asphericity is None:
            raise ValueError("circulo-polygon needs --asphericity")
        top = sides * np.tan(pi / sides) / pi  # the sharp polygon, R -> 0
        if not 1.0 < asphericity < top:
            raise ValueError(f"a rounded regular {sides}-gon has asphericity in (1, {top:.6g}), got {asphericity}")
        # A decreases from the polygon's to 1 as R / rho grows: bisect log(R / rho)
        lo, hi = -30.0, 30.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if _asphericity(kind, np.exp(mid), sides) > asphericity:
                lo = mid
            else:
                hi = mid
        return _shape(kind, np.exp(0.5 * (lo + hi)), sides)
    if aspect_ratio is None and asphericity is None:
        raise ValueError(f"{kind} needs --aspect-ratio or --asphericity")
    if aspect_ratio is not None:
        # an ellipse at 1 is a disk; a dumbbell at 2 has touching lobes; a circulo-line needs a core
        closed = kind in ("ellipse", "dumbbell")
        ok = aspect_ratio >= low if closed else aspect_ratio > low
        if not (np.isfinite(aspect_ratio) and ok):
            raise ValueError(f"{kind} needs --aspect-ratio {'>=' if closed else '>'} {low:g}, got {aspect_ratio}")
        return _shape(kind, aspect_ratio, 0)
    a_low = _asphericity(kind, low, 0) if kind == "dumbbell" else 1.0
    if not (np.isfinite(asphericity) and asphericity > a_low):
        raise ValueError(f"{kind} needs --asphericity > {a_low:.6g}, got {asphericity}")
    # A grows monotonically with the aspect ratio: bisect log(alpha - low)
    lo, hi = -60.0, 12.0
    if _asphericity(kind, low + np.exp(hi), 0) < asphericity:
        raise ValueError(f"--asphericity {asphericity} needs an aspect ratio beyond {low + np.exp(hi):.3g}")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if _asphericity(kind, low + np.exp(mid), 0) < asphericity:
            lo = mid
        else:
            hi = mid
    return _shape(kind, low + np.exp(0.5 * (lo + hi)), 0)


def bidisperse_shapes(shape: dict) -> ShapeTable:
    """Small and large copies of ``shape`` (rows 0 and 1), areas in ratio 1.4^2, mean area-equivalent diameter 1."""
    area = float(ShapeTable.from_shapes([shape]).area[0])
    small = (1.0 / (0.5 * (1.0 + SIZE_RATIO))) * 0.5 * sqrt(pi) / sqrt(area)
    rows = []
    for scale in (small, small * SIZE_RATIO):
        rows.append({key: (np.asarray(value, dtype=np.float64) * scale
                           if key in ("semi_axes", "vertices", "radius", "shaft_half_width") else value)
                     for key, value in shape.items()})
    return ShapeTable.from_shapes(rows)


def random_shape_packing(shapes: ShapeTable, n: int, phi: float, seed: int,
                         max_attempts: int = 10_000) -> Packing:
    """Random sequential addition of ``n`` bodies at packing fraction ``phi``.

    With two shapes, half the bodies are of row 0 and half of row 1; with ``n``
    shapes (App. B random polygons), body ``b`` is of row ``b``.

    Each body gets a uniform centre in the square box and a uniform orientation and is
    kept only if it overlaps no body placed before (exact shape test of the energy
    model, plus intersecting cores for circulo-shapes and dumbbell shafts), so the
    start has no overlap.

    Raises
    ------
    ValueError
        Bad ``n`` or ``phi``, a family without an energy model, or a body that finds
        no free place in ``max_attempts`` tries (``phi`` too high for addition).
    """
    if n < 2 or n % 2:
        raise ValueError(f"--n must be an even number >= 2 (half small, half large), got {n}")
    if not 0.0 < phi < 0.6:
        raise ValueError(f"--phi must lie in (0, 0.6) for random sequential addition, got {phi}")
    if len(shapes) == n:
        index = np.arange(n, dtype=np.int64)
    elif len(shapes) == 2:
        index = np.repeat(np.arange(2, dtype=np.int64), n // 2)
    else:
        raise ValueError(f"random_shape_packing needs 2 shapes (small, large) or one per body ({n}), got {len(shapes)}")
    side = float(np.sqrt(shapes.area[index].sum() / phi))
    box = Box.cubic(2, side)
    rng = np.random.default_rng(seed)
    bound = shapes.bounding_radius[index]
    model = ShapeModel(box, shapes, index)
    pair, params = model._pair, model.params
    cores = model.family in ("circulo", "dumbbell")
    conf = np.zeros((n, 3))
    done = np.zeros(n, dtype=bool)
    g = np.zeros(6)
    for b in rng.permutation(n):
        placed = np.flatnonzero(done)
        for _ in range(max_attempts):
            trial = np.array([*rng.uniform(0.0, side, 2), rng.uniform(0.0, 2.0 * pi)])
            dx = box.minimum_image(conf[placed, :2] - trial[:2])
            near = np.flatnonzero(np.hypot(dx[:, 0], dx[:, 1]) < bound[b] + bound[placed])
            if not any(pair(dx[m, 0], dx[m, 1], trial[2], conf[placed[m], 2], params[b], params[placed[m]], 1.0, g) > 0.0
                       or (cores and _kernels.circulo_cores_intersect(dx[m, 0], dx[m, 1], trial[2],
                                                                      conf[placed[m], 2], params[b],
                                                                      params[placed[m]]))
                       for m in near):
                conf[b] = trial
                done[b] = True
                break
        else:
            raise ValueError(f"random sequential addition found no free place for body {b} in {max_attempts} "
                             f"tries at phi = {phi}: lower --phi")
    return Packing(position=conf[:, :2], diameter=2.0 * bound, box=box, protocol="random-shapes", seed=seed,
                   orientation=conf[:, 2], shapes=shapes, shape_index=index)


#: Step-2 deformations tried before a random circulo-polygon is given up.
RANDOM_POLYGON_MAX_STEPS: int = 100_000


def _polygon_perimeter_area(v: np.ndarray) -> tuple[float, float]:
    w = np.roll(v, -1, axis=0)
    return float(np.linalg.norm(w - v, axis=1).sum()), 0.5 * float(np.sum(v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]))


def _rounded_asphericity(v: np.ndarray, r: float) -> float:
    """``A`` of the polygon ``v`` rounded by ``r`` (Minkowski sum with a disk)."""
    p, a = _polygon_perimeter_area(v)
    return (p + 2.0 * pi * r) ** 2 / (4.0 * pi * (a + p * r + pi * r * r))


def _radius_for_asphericity(v: np.ndarray, target: float) -> float:
    """The rounding radius giving ``A = target`` exactly: the positive root of
    ``4 pi^2 (1 - A) r^2 + 4 pi p (1 - A) r + p^2 - 4 pi A a = 0`` (from ``A = p_r^2 / 4 pi a_r``)."""
    p, a = _polygon_perimeter_area(v)
    qa = 4.0 * pi * pi * (1.0 - target)
    qb = 4.0 * pi * p * (1.0 - target)
    qc = p * p - 4.0 * pi * target * a
    # qa < 0 and qc > 0 (the polygon's own A exceeds the target): one positive root;
    # the form below avoids cancellation
    return float(2.0 * qc / (-qb + sqrt(qb * qb - 4.0 * qa * qc)))


def _strictly_convex(v: np.ndarray) -> bool:
    edge = np.roll(v, -1, axis=0) - v
    cross = edge[:, 0] * np.roll(edge, -1, axis=0)[:, 1] - edge[:, 1] * np.roll(edge, -1, axis=0)[:, 0]
    scale = float(np.max(np.linalg.norm(v, axis=1)))
    return bool(np.all(cross > 1e3 * SHAPE_GEOMETRY_RTOL * scale**2))


def random_circulo_polygon(sides: int, asphericity: float, rng: np.random.Generator,
                           max_steps: int = RANDOM_POLYGON_MAX_STEPS) -> dict:
    """One random circulo-polygon at asphericity ``asphericity`` (VanderWerf et al. App. B).

    1. ``sides`` uniform random points on the unit circle in angular order (a convex
       polygon), rounding radius ``n`` percent of its perimeter.
    2. While ``A`` is below the target, a random vertex ``J`` moves along the line
       from the circle's centre ``O`` through ``J``, outwards or inwards at random, by
       a uniform distance up to ``|J X|``, ``X`` the intersection of ``JO`` with the
       chord of ``J``'s two neighbours; the move is kept only if ``A`` gets closer to
       the target and the polygon stays strictly convex (the circulo-polygon is then
       convex: effectively convex in the paper's words, no concave contact surface).
       Once ``A`` exceeds the target the radius is increased to meet it exactly
       (closed form, :func:`_radius_for_asphericity`).

    The vertices are returned relative to the polygon's area centroid (the
    :class:`~jamflow.state.bodies.ShapeTable` convention); any scale.

    Raises
    ------
    ValueError
        ``sides < 3``, ``asphericity <= 1``, or no polygon within ``max_steps`` moves.
    """
    if sides < 3:
        raise ValueError(f"a random circulo-polygon needs --sides n >= 3, got {sides}")
    if not (np.isfinite(asphericity) and asphericity > 1.0):
        raise ValueError(f"a random circulo-polygon needs --asphericity > 1, got {asphericity}")
    angle = np.sort(rng.uniform(0.0, 2.0 * pi, sides))
    v = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    while not _strictly_convex(v):  # coincident draws: redraw
        angle = np.sort(rng.uniform(0.0, 2.0 * pi, sides))
        v = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    r = 0.01 * sides * _polygon_perimeter_area(v)[0]  # n percent of the perimeter
    a = _rounded_asphericity(v, r)
    for _ in range(max_steps):
        if a >= asphericity:
            r = _radius_for_asphericity(v, asphericity)
            _, centroid = _polygon_area_centroid(v)
            return dict(kind="circulo_polygon", vertices=v - centroid, radius=r)
        j = int(rng.integers(sides))
        p, q, s = v[j - 1], v[j], v[(j + 1) % sides]
        # X = q t on the line O J with X on the chord p s: solve q t = p + u (s - p)
        m = np.array([[q[0], p[0] - s[0]], [q[1], p[1] - s[1]]])
        if abs(np.linalg.det(m)) < 1e-12:  # J O parallel to the chord: no intersection
            continue
        t = np.linalg.solve(m, p)[0]
        reach = abs(1.0 - t) * float(np.linalg.norm(q))
        trial = v.copy()
        trial[j] = q + rng.choice((-1.0, 1.0)) * rng.uniform(0.0, reach) * q / np.linalg.norm(q)
        if not _strictly_convex(trial):
            continue
        a_trial = _rounded_asphericity(trial, r)
        if abs(a_trial - asphericity) < abs(a - asphericity):
            v, a = trial, a_trial
    raise ValueError(f"no random {sides}-sided circulo-polygon reached asphericity {asphericity} in {max_steps} "
                     f"moves (App. B): lower --asphericity")


def random_polygon_shapes(n: int, sides: int, asphericity: float, seed: int) -> ShapeTable:
    """``n`` random circulo-polygons (App. B), one shape per body: rows ``0 .. n/2 - 1`` small,
    the rest large (areas ``1.4^2`` apart), all at ``A = asphericity``, mean area-equivalent diameter 1."""
    if n < 2 or n % 2:
        raise ValueError(f"--n must be an even number >= 2 (half small, half large), got {n}")
    rng = np.random.default_rng(seed)
    small_area = pi * (0.5 / (0.5 * (1.0 + SIZE_RATIO))) ** 2
    rows = []
    for b in range(n):
        shape = random_circulo_polygon(sides, asphericity, rng)
        area = float(ShapeTable.from_shapes([shape]).area[0])
        scale = sqrt(small_area * (AREA_RATIO if b >= n // 2 else 1.0) / area)
        rows.append(dict(kind="circulo_polygon", vertices=shape["vertices"] * scale, radius=shape["radius"] * scale))
    return ShapeTable.from_shapes(rows)
