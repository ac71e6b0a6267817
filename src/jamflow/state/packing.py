"""The packing state and its xarray form.

A :class:`Packing` holds centres, diameters and the box, plus what a stage may know
about it: contacts (pairs ``i < j`` by particle identity), contact forces, a rattler
mask, the pressure, and provenance (protocol, seed, the stage's parameters).
Lengths are dimensionless; the unit is stated in ``length_unit`` (e.g. the side of
the initial box).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from math import gamma, pi
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..neighbors.pairs import PairList, pairs_within
from ..provenance import provenance_attrs
from ..tolerances import INSIDE_BOX_TOL, OVERLAP_TOL
from .bodies import SHAPE_GEOMETRY_RTOL, SHAPE_KINDS, Links, ShapeTable

__all__ = [
    "Packing",
    "OverlapError",
    "sphere_volume",
    "cap_volume",
    "lens_volume",
    "linked_volume",
    "near_pairs",
    "max_overlap",
    "LENGTH_UNITS",
    "length_unit",
]

#: Choices of the unit length lambda of the dynamics (see :func:`length_unit`).
LENGTH_UNITS = ("mean_diameter", "small_diameter")


class OverlapError(ValueError):
    """A hard-sphere packing has pairs overlapping beyond the tolerance."""


def sphere_volume(d: int, diameter: ArrayLike) -> NDArray[np.float64]:
    """Volume of d-dimensional balls of the given diameters [length^d]."""
    r = 0.5 * np.asarray(diameter, dtype=np.float64)
    return pi ** (d / 2) / gamma(d / 2 + 1) * r**d


def cap_volume(d: int, radius: ArrayLike, a: ArrayLike) -> NDArray[np.float64]:
    """Volume of the part of a d-ball beyond a hyperplane at signed distance ``a`` from its centre [length^d].

    ``V = V_ball I_{1 - a^2/R^2}((d + 1)/2, 1/2) / 2`` for ``0 <= a <= R`` (the
    regularised incomplete beta function; Li, Asian J. Math. Stat. 4, 66 (2011)) and
    ``V_ball - V(-a)`` for ``a < 0``; ``a`` is clipped to ``[-R, R]``.
    """
    from scipy.special import betainc

    R = np.asarray(radius, dtype=np.float64)
    t = np.clip(np.asarray(a, dtype=np.float64) / R, -1.0, 1.0)
    ball = sphere_volume(d, 2.0 * R)
    half = 0.5 * ball * betainc(0.5 * (d + 1), 0.5, 1.0 - t**2)
    return np.where(t >= 0.0, half, ball - half)


def lens_volume(d: int, diameter_i: ArrayLike, diameter_j: ArrayLike, distance: ArrayLike) -> NDArray[np.float64]:
    """Volume shared by two d-balls of the given diameters at a centre distance [length^d].

    Two caps cut by the radical hyperplane, at ``a_i = (r^2 + R_i^2 - R_j^2) / (2 r)``
    from centre ``i``; 0 for balls apart, the smaller ball's volume for one inside the other.
    """
    Ri = 0.5 * np.asarray(diameter_i, dtype=np.float64)
    Rj = 0.5 * np.asarray(diameter_j, dtype=np.float64)
    r = np.asarray(distance, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ai = (r**2 + Ri**2 - Rj**2) / (2.0 * r)
    lens = cap_volume(d, Ri, ai) + cap_volume(d, Rj, r - ai)
    lens = np.where(r >= Ri + Rj, 0.0, lens)
    return np.where(r <= np.abs(Ri - Rj), sphere_volume(d, 2.0 * np.minimum(Ri, Rj)), lens)


def linked_volume(d: int, diameter: ArrayLike, links: Links | None) -> float:
    """Volume of the union of spheres joined by links (dimers, chains, clusters) [length^d].

    Sum of the sphere volumes minus the lens of every linked pair at its link length:
    exact when no point lies in three linked spheres (dimers; chains and clusters whose
    links are contact distances or longer), otherwise short of the union by the volume
    shared by three or more (Bonferroni). Unlinked soft overlaps count whole, as in the
    packing fraction of soft spheres.
    """
    D = np.asarray(diameter, dtype=np.float64)
    total = float(sphere_volume(d, D).sum())
    if links is None or not len(links):
        return total
    return total - float(lens_volume(d, D[links.i], D[links.j], links.length).sum())


def body_kind(boundary: str | None, linked: bool, shaped: bool) -> str:
    """The body kind of :data:`jamflow.stages.BODY_KINDS` of a packing with this boundary, links and shapes."""
    if boundary == "walls":
        return "walls"
    if linked:
        return "linked"
    return "shapes" if shaped else "spheres"


def length_unit(diameter: NDArray[np.float64], which: str = "mean_diameter") -> float:
    """The unit lambda in input lengths.

    ``mean_diameter``: mean diameter (self-propelled discs, Sec. V B).
    ``small_diameter``: mean diameter of the particles below the mean diameter, i.e.
    the small species of a binary mixture (Sec. V A); the mean for monodisperse input.
    """
    if which not in LENGTH_UNITS:
        raise ValueError(f"length unit must be one of {LENGTH_UNITS}, got {which!r}")
    D = np.asarray(diameter, dtype=np.float64)
    if which == "small_diameter":
        small = D[D < D.mean() * (1 - 1e-12)]
        if small.size and D.max() / D.min() > 1.2:
            return float(small.mean())
    return float(D.mean())


@dataclass(frozen=True, eq=False)
class Packing:
    """State of N spheres in a periodic box.

    Attributes
    ----------
    position : ndarray, shape (N, d)
        Centres [length].
    diameter : ndarray, shape (N,)
        Diameters [length], all > 0.
    box : Box
        Periodic, possibly sheared box.
    contacts : ndarray of int64, shape (Nc, 2) or None
        Contact pairs by particle identity, each row ``i < j``, rows sorted.
    force : ndarray, shape (Nc,) or None
        Contact force magnitudes (positive = repulsive) in the units of the
        producing stage (``force_unit``).
    rattler : ndarray of bool, shape (N,) or None
        Particles outside the rigid backbone.
    pressure : float or None
        Reduced pressure if the producing stage knows it.
    protocol : str
        Chain of stages that produced the packing, e.g. ``"random>ls>calippso"``.
    seed : int or None
        Seed of the random choices of the producing chain.
    parameters : dict
        The producing stage's full parameters (stored as JSON).
    attrs : dict
        Further scalar attributes of the producing stage (stored verbatim).
    links : Links or None
        Fixed-length links between spheres (chains, rigid clusters); linked pairs
        are constraints, not contacts, and are exempt from the overlap check.
    orientation : ndarray, shape (N,) or None
        Orientation of shaped particles in 2D [rad]; given exactly when ``shapes`` is.
    shapes : ShapeTable or None
        Shape table of anisotropic 2D particles (see :mod:`jamflow.state.bodies`).
    shape_index : ndarray of int64, shape (N,) or None
        Row of ``shapes`` of each particle. A shaped particle's ``diameter`` is the
        diameter of its bounding circle.
    """

    position: NDArray[np.float64]
    diameter: NDArray[np.float64]
    box: Box
    contacts: NDArray[np.int64] | None = None
    force: NDArray[np.float64] | None = None
    rattler: NDArray[np.bool_] | None = None
    pressure: float | None = None
    protocol: str = "unknown"
    seed: int | None = None
    parameters: dict[str, Any] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)
    links: Links | None = None
    orientation: NDArray[np.float64] | None = None
    shapes: ShapeTable | None = None
    shape_index: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        x = np.array(self.position, dtype=np.float64)
        D = np.array(self.diameter, dtype=np.float64)
        if x.ndim != 2:
            raise ValueError(f"position must have shape (N, d), got {x.shape}")
        n, d = x.shape
        if d != self.box.d:
            raise ValueError(f"position has d={d} but the box has d={self.box.d}")
        if n < 1:
            raise ValueError("a packing needs at least one particle")
        if D.shape != (n,):
            raise ValueError(f"diameter must have shape ({n},), got {D.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("position contains NaN or infinite values")
        if not np.all(np.isfinite(D)) or np.any(D <= 0.0):
            raise ValueError("every diameter must be finite and > 0")
        if D.max() >= 0.5 * float(np.min(self.box.widths)):
            raise ValueError(
                f"largest diameter {D.max():.6g} must be below half the smallest box width "
                f"({0.5 * float(np.min(self.box.widths)):.6g}); use more particles"
            )
        object.__setattr__(self, "position", x)
        object.__setattr__(self, "diameter", D)
        if self.contacts is not None:
            c = np.asarray(self.contacts, dtype=np.int64).reshape(-1, 2)
            if np.any(c[:, 0] >= c[:, 1]) or np.any(c < 0) or np.any(c >= n):
                raise ValueError("contacts must be pairs i < j of valid particle indices")
            order = np.lexsort((c[:, 1], c[:, 0]))
            c = c[order]
            if len(c) > 1 and np.any(np.all(c[1:] == c[:-1], axis=1)):
                raise ValueError("contacts contain a duplicated pair")
            object.__setattr__(self, "contacts", c)
            if self.force is not None:
                f = np.asarray(self.force, dtype=np.float64)
                if f.shape != (len(c),):
                    raise ValueError(f"force must have shape ({len(c)},), got {f.shape}")
                if not np.all(np.isfinite(f)):
                    raise ValueError("force contains NaN or infinite values")
                object.__setattr__(self, "force", f[order])
        elif self.force is not None:
            raise ValueError("forces given without contacts")
        if self.rattler is not None:
            r = np.asarray(self.rattler, dtype=bool)
            if r.shape != (n,):
                raise ValueError(f"rattler must have shape ({n},), got {r.shape}")
            object.__setattr__(self, "rattler", r)
        if self.links is not None:
            self.links.check_indices(n)
        self._check_shapes()

    def _check_shapes(self) -> None:
        n, d = self.position.shape
        if (self.shapes is None) != (self.orientation is None) or (self.shapes is None) != (self.shape_index is None):
            raise ValueError("shapes, shape_index and orientation must be given together")
        if self.shapes is None:
            return
        if d != 2:
            raise ValueError(f"shaped particles are 2D; this packing has d={d}")
        theta = np.asarray(self.orientation, dtype=np.float64)
        if theta.shape != (n,):
            raise ValueError(f"orientation must have shape ({n},), got {theta.shape}")
        if not np.all(np.isfinite(theta)):
            k = int(np.flatnonzero(~np.isfinite(theta))[0])
            raise ValueError(f"orientation of particle {k} is {theta[k]}: angles must be finite")
        index = np.asarray(self.shape_index)
        if index.shape != (n,) or not np.issubdtype(index.dtype, np.integer):
            raise ValueError(f"shape_index must be {n} integers, got shape {index.shape} of {index.dtype}")
        index = index.astype(np.int64)
        if np.any(index < 0) or np.any(index >= len(self.shapes)):
            k = int(np.flatnonzero((index < 0) | (index >= len(self.shapes)))[0])
            raise ValueError(f"particle {k} has shape_index {index[k]} outside 0..{len(self.shapes) - 1}")
        bound = 2.0 * self.shapes.bounding_radius[index]
        wrong = np.abs(self.diameter - bound) > SHAPE_GEOMETRY_RTOL * bound
        if np.any(wrong):
            k = int(np.flatnonzero(wrong)[0])
            raise ValueError(
                f"particle {k}: diameter {float(self.diameter[k])!r} is not the bounding diameter "
                f"{float(bound[k])!r} of its shape {index[k]} ({self.shapes.kind[index[k]]})"
            )
        object.__setattr__(self, "orientation", theta)
        object.__setattr__(self, "shape_index", index)

    def __repr__(self) -> str:
        """One line (N, d, phi, bodies, contacts, pressure, box, protocol): ``print(packing)`` stays short."""
        parts = [f"N={self.n}", f"d={self.d}", f"phi={self.packing_fraction:.6g}", self._bodies_text()]
        if self.contacts is not None:
            # a walled packing keeps its wall contacts apart (attributes), not in ``contacts``
            what = "sphere-sphere contacts" if self.body_kind == "walls" else "contacts"
            parts.append(f"{len(self.contacts)} {what}" +
                         (f", {int(np.sum(self.rattler))} rattlers" if self.rattler is not None else ""))
        if self.pressure is not None:
            parts.append(f"P={self.pressure:.6g}")
        h = self.box.matrix
        sides = " x ".join(f"{x:.6g}" for x in np.diag(h))
        sheared = np.any(np.triu(h, 1) != 0.0)
        parts.append(f"box {sides}" + (" sheared" if sheared else ""))
        parts.append(f"protocol={self.protocol!r}")
        return f"Packing({', '.join(parts)})"

    def _bodies_text(self) -> str:
        kind = self.body_kind
        if kind == "linked":
            return f"{len(self.links)} links in {len(np.unique(self.clusters))} clusters"
        if kind == "shapes":
            names = np.unique(self.shapes.kind[self.shape_index])
            return "shapes: " + "/".join(str(k) for k in names)
        return "spheres between hard walls" if kind == "walls" else "spheres"

    # derived quantities -------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of particles N."""
        return self.position.shape[0]

    @property
    def d(self) -> int:
        """Spatial dimension d."""
        return self.position.shape[1]

    @property
    def packing_fraction(self) -> float:
        """Sum of particle volumes (shape areas for shaped particles) over box volume.

        Linked spheres count as the union of each linked pair (:func:`linked_volume`):
        the members of a dimer, whose link is shorter than the contact distance, share
        a lens counted once.
        """
        if self.shapes is not None:
            return float(self.shapes.area[self.shape_index].sum() / self.box.volume)
        return linked_volume(self.d, self.diameter, self.links) / self.box.volume

    @property
    def body_kind(self) -> str:
        """``"walls"``, ``"linked"``, ``"shapes"`` or ``"spheres"``: what the stage table checks (:mod:`jamflow.stages`)."""
        return body_kind(self.attrs.get("boundary"), self.links is not None and len(self.links) > 0,
                         self.shapes is not None)

    @property
    def clusters(self) -> NDArray[np.int64]:
        """Cluster label of each particle (connected components of the links), shape (N,)."""
        if self.links is None:
            return np.arange(self.n, dtype=np.int64)
        return self.links.clusters(self.n)

    def sigma(self, i: ArrayLike, j: ArrayLike) -> NDArray[np.float64]:
        """Contact distances ``(D_i + D_j) / 2`` for index arrays [length]."""
        return 0.5 * (self.diameter[np.asarray(i)] + self.diameter[np.asarray(j)])

    def contact_vectors(self) -> NDArray[np.float64]:
        """Minimum-image ``x_j - x_i`` for every contact, shape (Nc, d) [length]."""
        if self.contacts is None:
            raise ValueError("packing has no contacts")
        c = self.contacts
        return self.box.minimum_image(self.position[c[:, 1]] - self.position[c[:, 0]])

    def in_units(self, unit: float) -> "Packing":
        """Same packing with every length divided by ``unit`` (contacts kept).

        Forces are kept as they are: their unit is the producing stage's.
        """
        if not (np.isfinite(unit) and unit > 0.0):
            raise ValueError(f"length unit must be positive and finite, got {unit}")
        bodies: dict[str, Any] = {}
        if self.links is not None:
            bodies["links"] = self.links.scaled(1.0 / unit)
        if self.shapes is not None:
            bodies["shapes"] = self.shapes.scaled(1.0 / unit)
        return replace(self, position=self.position / unit, diameter=self.diameter / unit,
                       box=self.box.scaled(1.0 / unit), **bodies)

    def wrapped(self) -> "Packing":
        """Same packing with centres mapped into the primary cell."""
        return replace(self, position=self.box.wrap(self.position))

    def evolve(self, **changes: Any) -> "Packing":
        """Copy with fields replaced (``dataclasses.replace``)."""
        return replace(self, **changes)

    # validation ---------------------------------------------------------------------
    def validate(self, overlap_tol: float | None = OVERLAP_TOL) -> None:
        """Check centres lie in the box and no pair overlaps beyond ``overlap_tol``.

        Parameters
        ----------
        overlap_tol : float or None
            Largest accepted relative overlap ``(sigma_ij - r) / sigma_ij``; ``None``
            skips the check (soft packings).

        Raises
        ------
        ValueError
            Centres outside the primary cell.
        OverlapError
            Pairs overlapping beyond the tolerance, with the worst ones named.
        """
        inside = self.box.contains(self.position, INSIDE_BOX_TOL)
        if not np.all(inside):
            bad = np.flatnonzero(~inside)
            raise ValueError(f"{bad.size} particle(s) lie outside the box, e.g. index {bad[0]}")
        if overlap_tol is None:
            return
        if self.shapes is not None and np.any(self.shapes.kind != "disk"):
            raise ValueError(
                "the hard-particle overlap check is defined for spheres; shaped particles "
                "overlap by their shape model's contact distance (read with overlap_tol=None)"
            )
        pairs, h = near_pairs(self, 0.0)
        bad = -h > overlap_tol
        if self.links is not None:
            bad &= ~self.links.contains(pairs.i, pairs.j)
        if np.any(bad):
            worst = np.flatnonzero(bad)[np.argsort(h[bad])][:3]
            named = ", ".join(f"({pairs.i[k]}, {pairs.j[k]}): {-h[k]:.3g}" for k in worst)
            raise OverlapError(
                f"{int(bad.sum())} pair(s) overlap by more than {overlap_tol:g} (relative); "
                f"worst {named}"
            )

    # xarray form --------------------------------------------------------------------
    def to_dataset(self, stage_parameters: dict[str, Any] | None = None) -> xr.Dataset:
        """Dataset following DESIGN.md (units, long names, provenance)."""
        return packing_to_dataset(self, stage_parameters)

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> "Packing":
        """Inverse of :meth:`to_dataset` (no overlap validation; see ``io``)."""
        return packing_from_dataset(ds)

    # freud (optional extra ``freud``) -----------------------------------------------
    def to_freud(self) -> tuple[Any, NDArray[np.float64]]:
        """The box and points in freud's conventions, so freud's analyses run on this packing.

        freud boxes are centred on the origin (points in ``[-L/2, L/2)`` along each
        lattice vector) with tilt factors ``xy``, ``xz``, ``yz`` relative to the box
        lengths; jamflow's primary cell is ``[0, 1)`` in fractional coordinates. The
        lattice vectors are the same, so a Lees-Edwards tilt carries over; 2D packings
        give a 2D freud box and points with ``z = 0``. Only d = 2 and 3.

        Returns
        -------
        box : freud.box.Box
        points : ndarray, shape (N, 3)
            Centres shifted by minus the box centre [length].
        """
        import freud  # optional extra: pip install "jamflow[freud]"

        if self.d not in (2, 3):
            raise ValueError(f"freud handles d = 2 and 3, got d = {self.d}")
        matrix = np.zeros((3, 3))
        matrix[: self.d, : self.d] = self.box.matrix
        box = freud.box.Box.from_matrix(matrix, dimensions=self.d)
        points = np.zeros((self.n, 3))
        points[:, : self.d] = self.box.wrap(self.position) - self.box.to_cartesian(np.full(self.d, 0.5))
        return box, points

    @classmethod
    def from_freud(cls, box: Any, points: ArrayLike, diameter: ArrayLike, **fields: Any) -> "Packing":
        """A packing from a freud box and points (inverse of :meth:`to_freud`).

        Parameters
        ----------
        box : freud.box.Box or anything ``freud.box.Box.from_box`` accepts
        points : array_like, shape (N, 3)
            Centres in freud's origin-centred cell [length]; ``z`` ignored for 2D boxes.
        diameter : array_like, shape (N,)
            Diameters [length].
        **fields
            Further :class:`Packing` fields (``protocol``, ``seed``, ...).
        """
        import freud  # optional extra: pip install "jamflow[freud]"

        box = freud.box.Box.from_box(box)
        d = box.dimensions
        jbox = Box(np.asarray(box.to_matrix(), dtype=np.float64)[:d, :d])
        x = np.asarray(points, dtype=np.float64)[:, :d] + jbox.to_cartesian(np.full(d, 0.5))
        return cls(position=jbox.wrap(x), diameter=diameter, box=jbox, **fields)


def near_pairs(packing: Packing, max_gap: float) -> tuple[PairList, NDArray[np.float64]]:
    """Pairs with relative gap ``h = r / sigma_ij - 1`` at most ``max_gap``.

    Parameters
    ----------
    packing : Packing
    max_gap : float
        Largest relative gap kept (dimensionless); negative gaps are overlaps.

    Returns
    -------
    pairs : PairList
    h : ndarray, shape (P,)
        Relative gaps of the returned pairs.
    """
    cutoff = float(packing.diameter.max()) * (1.0 + max_gap)
    pairs = pairs_within(packing.position, packing.box, cutoff)
    h = pairs.distance / packing.sigma(pairs.i, pairs.j) - 1.0
    keep = h <= max_gap
    return pairs.select(keep), h[keep]


def max_overlap(packing: Packing) -> tuple[float, float]:
    """Largest overlap ``sigma_ij - r`` [length] and its relative value (0 if none)."""
    pairs, h = near_pairs(packing, 0.0)
    if len(h) == 0:
        return 0.0, 0.0
    k = int(np.argmin(h))
    rel = max(0.0, -float(h[k]))
    return rel * float(packing.sigma(pairs.i[k], pairs.j[k])), rel


# --- dataset conversion -----------------------------------------------------------

_LENGTH_COMMENT = "dimensionless; the unit length is given by the global attribute length_unit"


def packing_to_dataset(p: Packing, stage_parameters: dict[str, Any] | None = None) -> xr.Dataset:
    """Convert a packing to an ``xarray.Dataset`` (see :class:`Packing`)."""
    params = dict(p.parameters if stage_parameters is None else stage_parameters)
    data_vars: dict[str, Any] = {
        "position": (
            ("particle", "spatial"),
            p.position,
            {"units": "1", "long_name": "particle centre position", "comment": _LENGTH_COMMENT},
        ),
        "diameter": (
            ("particle",),
            p.diameter,
            {"units": "1", "long_name": "particle diameter", "comment": _LENGTH_COMMENT},
        ),
        "box": (
            ("spatial", "lattice_vector"),
            p.box.matrix,
            {
                "units": "1",
                "long_name": "box lattice vectors as columns (upper triangular; tilt = Lees-Edwards shear)",
                "comment": _LENGTH_COMMENT,
            },
        ),
    }
    if p.contacts is not None:
        data_vars["contact_i"] = (
            ("contact",),
            p.contacts[:, 0],
            {"units": "1", "long_name": "index of the first particle of a contact (i < j)"},
        )
        data_vars["contact_j"] = (
            ("contact",),
            p.contacts[:, 1],
            {"units": "1", "long_name": "index of the second particle of a contact (i < j)"},
        )
    if p.force is not None:
        data_vars["force"] = (
            ("contact",),
            p.force,
            {
                "units": "1",
                "long_name": "contact force magnitude (positive = repulsive)",
                "comment": "in the force unit of the producing stage, global attribute force_unit",
            },
        )
    if p.rattler is not None:
        data_vars["rattler"] = (
            ("particle",),
            p.rattler.astype(np.int8),
            {
                "units": "1",
                "long_name": "rattler flag (1 = outside the rigid backbone)",
                "flag_values": np.array([0, 1], dtype=np.int8),
                "flag_meanings": "backbone rattler",
            },
        )
    data_vars.update(_body_variables(p))
    attrs: dict[str, Any] = {
        "length_unit": "box side of the initial configuration",
        "force_unit": "stage-specific",
    }
    attrs.update(p.attrs)
    attrs.update(
        {
            "d": p.d,
            "N": p.n,
            "packing_fraction": p.packing_fraction,
            "pressure": np.nan if p.pressure is None else float(p.pressure),
            "protocol": p.protocol,
            "seed": -1 if p.seed is None else int(p.seed),
            "parameters": json.dumps(params, sort_keys=True, default=_json_default),
        }
    )
    attrs.update(provenance_attrs(title=f"jamflow packing ({p.protocol})"))
    return xr.Dataset(data_vars=data_vars, attrs=attrs)


def _length(dims: tuple[str, ...], values: Any, long_name: str) -> tuple:
    return (dims, values, {"units": "1", "long_name": long_name, "comment": _LENGTH_COMMENT})


def _body_variables(p: Packing) -> dict[str, Any]:
    """Dataset variables of links, orientations and shapes (none for plain spheres)."""
    out: dict[str, Any] = {}
    if p.links is not None:
        out["link_i"] = (("link",), p.links.i,
                         {"units": "1", "long_name": "index of the first particle of a link (i < j)"})
        out["link_j"] = (("link",), p.links.j,
                         {"units": "1", "long_name": "index of the second particle of a link (i < j)"})
        out["link_length"] = _length(("link",), p.links.length, "link length (fixed centre-to-centre distance)")
        out["cluster"] = (("particle",), p.clusters, {
            "units": "1", "long_name": "cluster label (connected component of the links)",
            "comment": "derived from link_i, link_j for convenience; recomputed on read",
        })
    if p.shapes is not None:
        t = p.shapes
        out["orientation"] = (("particle",), p.orientation,
                              {"units": "rad", "long_name": "orientation of the body frame (counter-clockwise)"})
        out["shape_index"] = (("particle",), p.shape_index,
                              {"units": "1", "long_name": "row of the shape table of each particle"})
        out["shape_kind"] = (("shape",), t.kind.astype(object),
                             {"long_name": "shape kind", "flag_meanings": " ".join(SHAPE_KINDS)})
        out["shape_radius"] = _length(("shape",), t.radius,
                                      "disk, rounding or lobe radius (NaN where not applicable)")
        out["semi_axes"] = _length(("shape", "axis"), t.semi_axes, "ellipse semi-axes a >= b (NaN for other kinds)")
        out["shape_vertex"] = _length(("shape", "vertex", "plane"), t.vertices,
                                      "body-frame vertex relative to the centroid (NaN padding beyond n_vertices)")
        out["n_vertices"] = (("shape",), t.n_vertices, {"units": "1", "long_name": "number of vertices of the shape"})
        out["shaft_half_width"] = _length(("shape",), t.shaft_half_width,
                                          "dumbbell shaft half-width (NaN for other kinds)")
        out["asphericity"] = (("shape",), t.asphericity, {
            "units": "1", "long_name": "asphericity A = p^2 / (4 pi a) (exact; 1 for a disk)",
            "comment": "derived from the shape parameters for convenience; recomputed on read",
        })
    return out


def _body_fields(ds: xr.Dataset) -> dict[str, Any]:
    """Inverse of :func:`_body_variables`; ``cluster`` is not read (links are the truth)."""
    fields: dict[str, Any] = {}
    link_vars = ("link_i", "link_j", "link_length")
    present = [v for v in link_vars if v in ds]
    if present and len(present) != len(link_vars):
        raise ValueError(f"dataset has {', '.join(present)} but not all of {', '.join(link_vars)}")
    if present:
        fields["links"] = Links(ds["link_i"].values, ds["link_j"].values, ds["link_length"].values)
    shape_vars = ("orientation", "shape_index", "shape_kind", "shape_radius", "semi_axes",
                  "shape_vertex", "n_vertices", "shaft_half_width")
    present = [v for v in shape_vars if v in ds]
    if present and len(present) != len(shape_vars):
        missing = [v for v in shape_vars if v not in ds]
        raise ValueError(f"dataset has shape variables but lacks {', '.join(missing)}")
    if present:
        fields["shapes"] = ShapeTable(
            kind=ds["shape_kind"].values.astype(str),
            radius=ds["shape_radius"].values,
            semi_axes=ds["semi_axes"].values,
            vertices=ds["shape_vertex"].values,
            n_vertices=ds["n_vertices"].values,
            shaft_half_width=ds["shaft_half_width"].values,
        )
        fields["orientation"] = ds["orientation"].values
        fields["shape_index"] = ds["shape_index"].values
    return fields


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"cannot store {type(obj).__name__} in parameters JSON")


_RESERVED = {
    "d", "N", "packing_fraction", "pressure", "protocol", "seed", "parameters",
    "Conventions", "title", "history", "source", "jamflow_version", "git_sha", "created",
}


def packing_from_dataset(ds: xr.Dataset) -> Packing:
    """Build a :class:`Packing` from a dataset written by :func:`packing_to_dataset`."""
    missing = [v for v in ("position", "diameter", "box") if v not in ds]
    if missing:
        raise ValueError(f"dataset is not a packing: missing variable(s) {', '.join(missing)}")
    contacts = force = rattler = None
    if ("contact_i" in ds) != ("contact_j" in ds):
        raise ValueError("dataset has only one of contact_i and contact_j")
    if "contact_i" in ds:
        contacts = np.stack([ds["contact_i"].values, ds["contact_j"].values], axis=1)
    if "force" in ds:
        force = ds["force"].values  # without contacts, Packing rejects it
    if "rattler" in ds:
        rattler = ds["rattler"].values.astype(bool)
    pressure = ds.attrs.get("pressure", np.nan)
    seed = int(ds.attrs.get("seed", -1))
    extra = {k: v for k, v in ds.attrs.items() if k not in _RESERVED}
    return Packing(
        position=ds["position"].values,
        diameter=ds["diameter"].values,
        box=Box(ds["box"].values),
        contacts=contacts,
        force=force,
        rattler=rattler,
        pressure=None if pressure is None or not np.isfinite(pressure) else float(pressure),
        protocol=str(ds.attrs.get("protocol", "unknown")),
        seed=None if seed < 0 else seed,
        parameters=json.loads(ds.attrs.get("parameters", "{}")),
        attrs=extra,
        **_body_fields(ds),
    )
