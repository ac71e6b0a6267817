"""The feasible region of one circulo-line held by three fixed points (VanderWerf et al. Sec. III C, Figs. 12-13).

A circulo-line (core half-length ``l``, radius ``R``) touches three fixed points: one on
the middle of its shaft and one on each end cap, the cap points at an angle ``beta``
below the axis (Fig. 12b). The three contact forces balance force and torque (the cap
forces are equal, the shaft force ``2 f sin(beta)``), and the three contact normals meet
in one point, so the rigidity matrix has rank 2: a rotation about that point is free at
first order. Three contacts for three degrees of freedom are one fewer than the isostatic
four, yet the cage holds a short line: the shaft contact's constraint is convex (Table
II) and, weighted by the contact forces, outweighs the concave caps along the free
rotation, which is then blocked at second order, a quartic mode (:func:`cage_stability`;
the paper does not give its cage's dimensions: ``l = 0.2 R``, ``beta = pi/4`` here).

Shrinking the line's radius by ``dR`` (the points fixed) opens the feasible region: the
configurations ``(x, y, theta)`` at which every point lies outside the line. Along the
two stiff directions it extends ``~ dR``, along the quartic one ``~ dR^(1/2)``, so its
volume scales as ``dR^(5/2)`` and its surface as ``dR^(3/2)`` (Fig. 13): the region
shrinks to a point as ``dR -> 0``, the line is jammed.

Coordinates: ``x / R``, ``y / R`` and ``theta`` [rad], rotated onto the eigenvectors of
the rigidity Gram matrix ``J^T J`` (the dynamical matrix at the onset, where the forces
vanish), ordered by eigenvalue (the last is the quartic direction). Volume and surface
are estimated by Monte Carlo in a box around the region: the volume from the fraction
of feasible samples, the surface from the shell of samples at most ``eps`` outside (in
normal distance, the gap over its gradient norm), ``S ~ V_shell / eps``.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import NDArray

__all__ = ["cage_directions", "cage_gaps", "cage_points", "cage_stability", "feasible_region", "feasible_scaling"]

_J = np.array([[0.0, -1.0], [1.0, 0.0]])


def cage_points(half_length: float, radius: float, beta: float) -> NDArray[np.float64]:
    """The three fixed points (rows) touching the line at the origin, angle 0 (module doc), lengths in ``R``."""
    if not (0.0 < beta < 0.5 * np.pi and half_length > 0.0 and radius > 0.0):
        raise ValueError(f"a cage needs half_length > 0, radius > 0 and 0 < beta < pi/2, got {half_length}, "
                         f"{radius}, {beta}")
    return np.array([[0.0, radius],
                     [-half_length - radius * np.cos(beta), -radius * np.sin(beta)],
                     [half_length + radius * np.cos(beta), -radius * np.sin(beta)]])


def cage_gaps(points: NDArray[np.float64], conf: NDArray[np.float64], half_length: float,
              radius: float) -> NDArray[np.float64]:
    """Gaps ``dist(point, core) - radius`` of the three points for configurations ``conf`` (M, 3), shape (M, 3)."""
    conf = np.atleast_2d(conf)
    c, s = np.cos(conf[:, 2]), np.sin(conf[:, 2])
    axis = np.stack([c, s], axis=1)
    out = np.empty((len(conf), len(points)))
    for k, p in enumerate(points):
        d = p[None, :] - conf[:, :2]
        t = np.clip(np.sum(d * axis, axis=1), -half_length, half_length)
        out[:, k] = np.linalg.norm(d - t[:, None] * axis, axis=1) - radius
    return out


def _normal_gaps(points, conf, half_length, radius, step=1e-7):
    """Gaps over their gradient norms in ``(x, y, theta)``: a first-order normal distance."""
    g = cage_gaps(points, conf, half_length, radius)
    grad2 = np.zeros_like(g)
    for a in range(3):
        e = np.zeros(3)
        e[a] = step
        grad2 += ((cage_gaps(points, conf + e, half_length, radius)
                   - cage_gaps(points, conf - e, half_length, radius)) / (2.0 * step)) ** 2
    return g / np.sqrt(grad2)


def cage_directions(points: NDArray[np.float64], half_length: float) -> tuple[NDArray, NDArray]:
    """Eigenvalues (descending) and eigenvectors (columns) of ``J^T J`` of the cage at the onset."""
    rows = []
    for p in points:
        t = float(np.clip(p[0], -half_length, half_length))
        d = p - np.array([t, 0.0])
        n = d / np.linalg.norm(d)
        # the gap grows when the line moves away from the point: d gap = -n . (dx + dtheta J c), c the foot
        rows.append([-n[0], -n[1], -(_J @ np.array([t, 0.0])) @ n])
    w, v = np.linalg.eigh(np.array(rows).T @ np.array(rows))
    order = np.argsort(-w)
    return w[order], v[:, order]


def cage_stability(half_length: float, beta: float, step: float = 1e-4) -> float:
    """Stress-weighted curvature of the gaps along the quartic direction ``u`` (per unit force).

    With the self stress ``lambda`` of the cage (its contact forces, ``J^T lambda = 0``) the
    gaps along ``u`` plus any correction ``w`` in the stiff directions obey
    ``sum_k lambda_k g_k = (s^2 / 2) sum_k lambda_k u^T H_k u`` (the ``J w`` terms cancel):
    when this is negative no motion along ``u`` keeps every gap open, so the cage holds the
    line at quartic order (prestress stability); when it is positive the line escapes.
    Three points hold short lines (``half_length = 0.2``, ``beta = pi/4``: -0.20) and
    not long ones (``1``, ``pi/4``: the shaft point sits where the normals meet).
    """
    points = cage_points(half_length, 1.0, beta)
    _, basis = cage_directions(points, half_length)
    u = basis[:, -1]
    curvature = (cage_gaps(points, step * u, half_length, 1.0) + cage_gaps(points, -step * u, half_length, 1.0)
                 - 2.0 * cage_gaps(points, np.zeros(3), half_length, 1.0))[0] / step**2
    force = np.array([2.0 * np.sin(beta), 1.0, 1.0])
    return float(force @ curvature / np.linalg.norm(force))


def _extents(points, basis, half_length, radius, directions, start):
    """Per direction (rows) the largest ``s`` with ``s * basis @ direction`` feasible: doubling from
    ``start`` (far below the region's size) to the first infeasible point, then bisection. Far
    away, outside the cage, the line is free again; doubling from a small step finds the cage's
    own boundary."""

    def feasible(s, rows=slice(None)):
        return np.all(cage_gaps(points, (s[:, None] * directions[rows]) @ basis.T, half_length, radius) >= 0.0, axis=1)

    lo = np.zeros(len(directions))
    hi = np.full(len(directions), start)
    grow = feasible(hi)
    while np.any(grow):
        lo[grow], hi[grow] = hi[grow], 2.0 * hi[grow]
        grow[grow] = feasible(hi[grow], grow)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = feasible(mid)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return lo


def feasible_region(half_length: float, beta: float, shrink: float, samples: int, seed: int,
                    shell: float = 0.02) -> dict:
    """Volume and surface of the feasible region at radius ``1 - shrink`` (lengths in ``R``).

    Parameters
    ----------
    half_length : float
        Core half-length over the radius ``R``.
    beta : float
        Angle of the cap points below the axis [rad].
    shrink : float
        ``dR / R``.
    samples : int
        Monte Carlo samples (uniform in the bounding box in eigen-coordinates).
    seed : int
    shell : float
        Shell thickness for the surface, as a fraction of the smallest box half-width.

    Returns
    -------
    dict
        ``volume``, ``surface`` and their Monte Carlo standard errors, ``half_widths``
        (3,) of the box along the eigen-directions, ``feasible`` (K, 3) the feasible
        samples in eigen-coordinates (at most 20000, for Fig. 12a).
    """
    if not 0.0 < shrink < 0.5:
        raise ValueError(f"the radius shrinks by a fraction in (0, 0.5), got {shrink}")
    points = cage_points(half_length, 1.0, beta)
    _, basis = cage_directions(points, half_length)
    radius = 1.0 - shrink
    rng = np.random.default_rng(seed)
    # the box: the region's reach along many directions, projected on the eigen-axes
    dirs = rng.normal(size=(400, 3))
    dirs = np.vstack([np.eye(3), -np.eye(3), dirs / np.linalg.norm(dirs, axis=1)[:, None]])
    reach = _extents(points, basis, half_length, radius, dirs, 1e-3 * shrink)[:, None] * np.abs(dirs)
    half = 1.25 * reach.max(axis=0)
    u = (rng.random((samples, 3)) * 2.0 - 1.0) * half
    conf = u @ basis.T
    gap = cage_gaps(points, conf, half_length, radius).min(axis=1)
    inside = gap >= 0.0
    box = float(np.prod(2.0 * half))
    frac = float(inside.mean())
    eps = shell * float(half.min())
    outside = np.flatnonzero(~inside)
    normal = _normal_gaps(points, conf[outside], half_length, radius).min(axis=1)
    near = float(np.sum(normal >= -eps)) / samples
    return {"volume": box * frac, "volume_err": box * np.sqrt(frac * (1.0 - frac) / samples),
            "surface": box * near / eps, "surface_err": box * np.sqrt(near * (1.0 - near) / samples) / eps,
            "half_widths": half, "feasible": u[inside][:20000]}


def feasible_scaling(shrinks: NDArray[np.float64], half_length: float = 0.2, beta: float = np.pi / 4,
                     samples: int = 400_000, seed: int = 0) -> xr.Dataset:
    """Fig. 13: volume and surface of the feasible region against ``dR / R``, with fitted exponents.

    Exponents: least squares of ``log V`` and ``log S`` against ``log dR`` (expected 5/2 and
    3/2, module doc). The feasible samples at the smallest ``dR`` are kept for Fig. 12a.
    """
    shrinks = np.sort(np.asarray(shrinks, dtype=np.float64))
    if np.unique(shrinks).size < 2:
        raise ValueError(f"the scaling exponents need at least two distinct radius decreases, got {shrinks.tolist()}")
    rows = [feasible_region(half_length, beta, s, samples, seed + k) for k, s in enumerate(shrinks)]
    vol = np.array([r["volume"] for r in rows])
    surf = np.array([r["surface"] for r in rows])
    fit_v = np.polyfit(np.log(shrinks), np.log(vol), 1)
    fit_s = np.polyfit(np.log(shrinks), np.log(surf), 1)
    points = cage_points(half_length, 1.0, beta)
    lam, basis = cage_directions(points, half_length)
    s, e, c = ("shrink",), ("sample",), ("eigen",)
    one = {"units": "1"}
    return xr.Dataset(
        data_vars={
            "volume": (s, vol, {**one, "long_name": "volume of the feasible region",
                                "comment": "in (x / R, y / R, theta [rad]) along the eigen-directions"}),
            "volume_err": (s, np.array([r["volume_err"] for r in rows]), {**one, "long_name": "Monte Carlo error of the volume"}),
            "surface": (s, surf, {**one, "long_name": "surface area of the feasible region"}),
            "surface_err": (s, np.array([r["surface_err"] for r in rows]),
                            {**one, "long_name": "Monte Carlo error of the surface (counting only)"}),
            "half_width": (s + c, np.array([r["half_widths"] for r in rows]),
                           {**one, "long_name": "half-width of the sampling box along each eigen-direction"}),
            "feasible_sample": (e + c, rows[0]["feasible"],
                                {**one, "long_name": f"feasible configurations at dR / R = {shrinks[0]:.3g}, eigen-coordinates"}),
            "gram_eigenvalue": (c, lam, {**one, "long_name": "eigenvalue of J^T J (the last: the quartic direction)"}),
            "eigenvector": (("coordinate",) + c, basis, {**one, "long_name": "eigen-directions in (x / R, y / R, theta)"}),
            "points": (("point", "spatial"), points, {**one, "long_name": "fixed points of the cage, in R"}),
        },
        coords={"shrink": (s, shrinks, {**one, "long_name": "radius decrease dR / R"})},
        attrs={"half_length": half_length, "beta": beta, "samples": samples, "seed": seed,
               "volume_exponent": float(fit_v[0]), "surface_exponent": float(fit_s[0])},
    )
