"""Soft 2D shaped bodies (VanderWerf et al., Eq. 1) as an energy model with rotations.

Degrees of freedom ``q`` (shape ``(3N,)``): centres ``(N, 2)`` row-major, then one
orientation per body [rad] (the order of :mod:`jamflow.minimize.model`). A
*configuration* is the ``(N, 3)`` array of rows ``(x, y, theta)``: it is what
:meth:`ShapeModel.dofs` takes and :meth:`ShapeModel.positions` returns, so that
the generic minimisers and the bisection to ``P0`` (which hand ``positions(q)`` back
to ``rescaled``) carry the orientations along.

Pair energy ``U = (k/2) (sigma_ij - r_ij)^2`` for ``sigma_ij > r_ij`` with ``r, sigma``
per shape family:

- ``circulo`` (circulo-lines and circulo-polygons, mixed freely): App. A, each
  vertex against each edge of the other body (:func:`._kernels.circulo_vertex_edge`);
- ``ellipse``: centre distance and the Perram–Wertheim contact distance
  (:func:`._kernels.perram_wertheim`);
- ``reuleaux``: arc-arc and vertex-arc distances of Fig. 2 (:func:`._kernels.reuleaux_pair`);
- ``dumbbell``: end-end and end-shaft distances of Sec. II (:func:`._kernels.dumbbell_terms`).

Masses are equal (``mass``, default 1); the moment of inertia of body ``i`` is
``mass * gyration_squared`` of its shape (uniform density), entering as the inverse
mass of its orientation, so FIRE's time step means the same for rotations; the time
unit is ``sqrt(mass / (K k))``: ``K = 1`` for Reuleaux triangles and dumbbells, for
circulo-polygons 4 (the curvature of a face-to-face contact, :data:`POLYGON_STIFFNESS`), for
ellipses and circulo-lines the curvature of their stiffest contact in the mass metric
(:func:`.time_unit.contact_stiffness`: 2.7, 19, 79 for ellipses of aspect ratio 2, 5, 10)
where it exceeds :data:`FREE_STIFFNESS`, else 1.
The Hessian is the complex-step derivative of the analytic pair gradients
(:func:`._kernels.pair_hessian_blocks`), exact to round-off.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ...box import Box
from ...minimize.fire import FireParameters
from ...minimize.model import ModelEvaluation, WithoutFastPaths
from ...neighbors.verlet import DEFAULT_SKIN, NeighborList
from ...state.bodies import ShapeTable
from . import _kernels
from .fast import ShapeFire
from .time_unit import contact_stiffness

__all__ = ["POINT_TERM_FAMILIES", "SHAPE_FAMILIES", "ShapeModel", "shape_family"]

#: Shape kinds each model family handles (one family per packing).
SHAPE_FAMILIES: dict[str, tuple[str, ...]] = {
    "circulo": ("circulo_line", "circulo_polygon"),
    "ellipse": ("ellipse",),
    "reuleaux": ("reuleaux",),
    "dumbbell": ("dumbbell",),
}

#: Families whose pair terms are distances of two body-fixed points (:meth:`ShapeModel.point_terms`).
POINT_TERM_FAMILIES = ("reuleaux", "dumbbell")

#: Stiffness of the time unit of circulo-polygon packings over ``k`` [1]: the normal
#: curvature of a face-to-face contact (two vertex-edge terms of weight 2, App. A 2).
#: FIRE ran freely at ``dt_max omega_max <= 1.1`` and restarted every few tens of steps,
#: stalling, at ``>= 1.4``; disks run at 0.76 (``omega_max`` 2.5), polygon packings reach
#: ``omega_max`` 5.2-6.6, so their ``dt_max`` is 0.15 (0.77-0.98) (docs/notes/shapes.md,
#: "Circulo-polygons and Reuleaux triangles at N = 100").
POLYGON_STIFFNESS: float = 4.0

_PAIR = {"circulo": _kernels.circulo_pair, "ellipse": _kernels.ellipse_pair, "reuleaux": _kernels.reuleaux_pair,
         "dumbbell": _kernels.dumbbell_pair}
_TERMS = {"reuleaux": (_kernels.reuleaux_terms, 27), "dumbbell": (_kernels.dumbbell_terms, 8)}


def shape_family(kinds: ArrayLike) -> str:
    """The one family of :data:`SHAPE_FAMILIES` holding every kind in ``kinds``.

    Raises
    ------
    ValueError
        If the kinds are not all of one implemented family.
    """
    present = set(np.asarray(kinds, dtype=str).tolist())
    for family, members in SHAPE_FAMILIES.items():
        if present <= set(members):
            return family
    raise ValueError(
        f"shape kinds {sorted(present)} have no energy model; implemented families: "
        + "; ".join(f"{f}: {', '.join(m)}" for f, m in SHAPE_FAMILIES.items())
    )


def _shape_parameters(shapes: ShapeTable, family: str) -> NDArray[np.float64]:
    """Per-shape flat parameter rows of the pair kernels, shape (S, P)."""
    if family == "ellipse":
        return np.array(shapes.semi_axes, dtype=np.float64)
    width = 2 + 2 * int(shapes.n_vertices.max())
    if family == "dumbbell":
        # [R, 2, v0, v1, w]: the lobe radius, the lobe centres and the shaft half-width
        return np.column_stack([shapes.radius, np.full(len(shapes), 2.0), shapes.vertices[:, :2].reshape(-1, 4),
                                shapes.shaft_half_width])
    out = np.zeros((len(shapes), width))
    for k in range(len(shapes)):
        v = shapes.vertex_list(k)
        # circulo: rounding radius; Reuleaux: arc radius = side
        out[k, 0] = shapes.radius[k] if family == "circulo" else np.linalg.norm(v[1] - v[0])
        out[k, 1] = len(v)
        out[k, 2: 2 + 2 * len(v)] = v.ravel()
    return out


#: Vertex-edge terms of an end-end contact of two circulo-lines [1]: each end against the other's
#: edge, so two round circulo-lines (length 0) touch with ``contact_stiffness`` 2, not the disks' 1.
END_END_TERMS: int = 2

#: Contact stiffness (over the disks') up to which ellipses and circulo-lines keep the disks' time
#: unit [1]: disks run at ``dt_max omega_max = 0.76``, contacts at most twice as stiff at most
#: ``0.76 sqrt(2) = 1.07``, below the ~1.1 at which FIRE still runs without restarts (``POLYGON_STIFFNESS``);
#: stiffer contacts set the unit themselves, back at the disks' 0.76 (ellipses of aspect ratio 10
#: ran at 4.7 and circulo-lines at 1.4 with the disks' unit, restarting and stalling: docs/notes/shapes.md,
#: "Aspect ratio 10: the time unit of long bodies").
FREE_STIFFNESS: float = 2.0


def _time_stiffness(shapes: ShapeTable, shape_index: NDArray[np.int64], family: str, rotations: bool) -> float:
    """Spring constant over ``k`` that sets FIRE's time unit ``sqrt(m / (K k))`` [1].

    Ellipses: their :func:`.time_unit.contact_stiffness` (1 for disks); circulo-lines: theirs over
    :data:`END_END_TERMS` (1 for round ones); either only above :data:`FREE_STIFFNESS`, else 1.
    With a circulo-polygon present at least :data:`POLYGON_STIFFNESS`. Reuleaux triangles and
    dumbbells: 1.
    """
    present = np.unique(shape_index)
    stiff = 1.0
    if family == "ellipse":
        stiff = contact_stiffness(_kernels.ELLIPSE, _shape_parameters(shapes, family)[present],
                                  shapes.gyration_squared[present], shapes.bounding_radius[present], rotations)
    elif family == "circulo":
        lines = present[shapes.n_vertices[present] == 2]
        if len(lines):
            stiff = contact_stiffness(_kernels.CIRCULO, _shape_parameters(shapes, family)[lines],
                                      shapes.gyration_squared[lines], shapes.bounding_radius[lines],
                                      rotations) / END_END_TERMS
    if stiff <= FREE_STIFFNESS:
        stiff = 1.0
    if family == "circulo" and int(shapes.n_vertices[present].max()) >= 3:
        stiff = max(stiff, POLYGON_STIFFNESS)
    return stiff


class ShapeModel(WithoutFastPaths):
    """Soft shaped bodies in 2D with translations and rotations (see the module doc).

    Parameters
    ----------
    box : Box
        Fixed periodic 2D box.
    shapes : ShapeTable
        Shapes, all of one family of :data:`SHAPE_FAMILIES`.
    shape_index : array_like of int, shape (N,)
        Row of ``shapes`` of each body.
    k : float
        Spring constant [energy / length^2].
    mass : float
        Mass of every body [mass].
    nlist : NeighborList, optional
        Verlet list on bounding diameters (reused by :meth:`rescaled`).
    rotations : bool
        False freezes every orientation (VanderWerf et al. Fig. 3a, non-rotating
        circulo-lines): :meth:`project` removes the torques from forces and velocities.
    """

    box_dofs = True

    def __init__(self, box: Box, shapes: ShapeTable, shape_index: ArrayLike, k: float = 1.0,
                 mass: float = 1.0, nlist: NeighborList | None = None, rotations: bool = True) -> None:
        if box.d != 2:
            raise ValueError(f"shaped bodies are 2D; the box has d = {box.d}")
        if not (np.isfinite(k) and k > 0.0 and np.isfinite(mass) and mass > 0.0):
            raise ValueError(f"spring constant and mass must be finite and > 0, got k = {k}, mass = {mass}")
        self.box = box
        self.shapes = shapes
        self.shape_index = np.asarray(shape_index, dtype=np.int64)
        self.family = shape_family(shapes.kind[np.unique(self.shape_index)])
        self.k = float(k)
        self.mass = float(mass)
        self.n = int(self.shape_index.size)
        self.d = 2
        self.n_dof = 3 * self.n
        self.bounding_diameter = 2.0 * shapes.bounding_radius[self.shape_index]
        self.nlist = (NeighborList(self.bounding_diameter, DEFAULT_SKIN * float(self.bounding_diameter.mean()))
                      if nlist is None else nlist)
        self.params = np.ascontiguousarray(_shape_parameters(shapes, self.family)[self.shape_index])
        inertia = self.mass * shapes.gyration_squared[self.shape_index]
        self.inverse_mass = np.concatenate([np.full(2 * self.n, 1.0 / self.mass), 1.0 / inertia])
        #: length that turns a torque into a force in :meth:`max_force` [length]
        self.torque_arm = float(self.bounding_diameter.mean())
        self._pair = _PAIR[self.family]
        self._code = _kernels.FAMILY_CODES[self.family]
        self.rotations = bool(rotations)
        self.constrained = not self.rotations
        self._time_unit: float | None = None

    @property
    def time_unit(self) -> float:
        """FIRE's time unit ``sqrt(m / (K k))`` [time]: periods of the stiffest contact (module doc;
        computed on first use, as the contact sampling of long bodies costs a fraction of a second once)."""
        if self._time_unit is None:
            stiff = _time_stiffness(self.shapes, self.shape_index, self.family, self.rotations)
            self._time_unit = float(np.sqrt(self.mass / (self.k * stiff)))
        return self._time_unit

    @property
    def neighbor_builds(self) -> int:
        return self.nlist.builds

    def fire_engine(self, q: NDArray[np.float64], params: FireParameters, pressure0: float | None = None,
                    pressure_rtol: float = 0.0, box_dof: str = "isotropic") -> ShapeFire:
        """The compiled FIRE loop of :mod:`.fast`: fixed box, or an isotropic barostat (the box keeps its shape)."""
        if pressure0 is not None and box_dof != "isotropic":
            raise ValueError(f"shaped bodies minimise the enthalpy with an isotropic box only, not box_dof {box_dof!r}")
        return ShapeFire(self, q, params, pressure0, pressure_rtol)

    def dofs(self, configuration: ArrayLike) -> NDArray[np.float64]:
        """Flat ``q`` from a configuration ``(N, 3)`` of rows ``(x, y, theta)``."""
        c = np.asarray(configuration, dtype=np.float64)
        if c.shape != (self.n, 3):
            raise ValueError(f"configuration must have shape ({self.n}, 3) (x, y, theta), got {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("configuration has non-finite centres or orientations")
        return np.concatenate([c[:, :2].ravel(), c[:, 2]])

    def positions(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Configuration ``(N, 3)`` of rows ``(x, y, theta)`` of ``q``."""
        return np.column_stack([q[: 2 * self.n].reshape(self.n, 2), q[2 * self.n:]])

    def _pairs(self, q: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        x = np.ascontiguousarray(q[: 2 * self.n].reshape(self.n, 2))
        self.nlist.update(x, self.box)
        i, j = self.nlist.i, self.nlist.j
        dx = np.ascontiguousarray(x[j] - x[i] + self.nlist.offsets(self.box))
        return i, j, dx, np.ascontiguousarray(q[2 * self.n:])

    def energy_floor(self, pressure: float) -> float:
        """An energy [energy] below which no state in :attr:`box` has a virial pressure of ``pressure`` or more.

        Ellipses and circulo-shapes (0 for the other families). A term of energy
        ``(k/2) w delta^2`` pushes along a unit normal (circulo) or gives ``f . dx = k delta r``
        (ellipses: the Perram–Wertheim distance does not change along ``dx``), so each
        pair's ``F . dx <= l k sum_t w_t delta_t`` with ``l = 2 b_max`` (the largest centre
        distance of two overlapping bodies, ``b`` the bounding radii). Over terms of total
        weight ``W``, Hölder gives ``P <= l k sqrt(W) sqrt(2 U / k) / (d V)``. ``W`` counts
        every vertex-edge term of a pair (``w`` = 1 on circulo-lines, 2 on polygons) times
        the pairs: each body touches at most ``z`` others, which with it lie inside the disk
        of radius ``3 b_max`` about its centre and overlap each other by at most
        ``2 b_max delta_max`` of area, so ``(z + 1)(A_min - z b_max delta_max) <= 9 pi b_max^2``.
        """
        if not pressure > 0.0:
            raise ValueError(f"pressure must be > 0, got {pressure}")
        if self.family not in ("ellipse", "circulo"):
            return 0.0
        kinds = np.unique(self.shape_index)
        b_max = float(self.shapes.bounding_radius[kinds].max())
        area_min = float(self.shapes.area[kinds].min())
        if self.family == "ellipse":
            per_pair = 1.0
        else:
            nv = self.shapes.n_vertices[kinds]
            edges, weight = np.where(nv == 2, 1, nv), np.where(nv == 2, 1.0, 2.0)
            per_pair = float(2 * nv.max() * edges.max() * weight.max())
        lever = 2.0 * b_max
        disk = 9.0 * np.pi * b_max**2
        scale = (pressure * self.d * self.box.volume) ** 2 / (self.k * lever**2 * per_pair * self.n)
        # without overlaps z <= disk / A_min - 1; that floor is the largest, so its overlap bounds the final one's
        delta = np.sqrt(2.0 * scale / max(np.floor(disk / area_min) - 1.0, 1.0) / self.k)
        # the overlaps among z + 1 <= 2 disk / A_min bodies cost at most half a body's area here
        z_cap = 2.0 * disk / area_min
        if z_cap * b_max * delta > 0.5 * area_min:
            return 0.0
        z = np.floor(disk / (area_min - z_cap * b_max * delta)) - 1.0
        return float(scale / z)

    def evaluate(self, q: NDArray[np.float64]) -> ModelEvaluation:
        """Energy, gradient ``(3N,)`` and virial (``-sum dU/dx_j dx``, see :mod:`._kernels`)."""
        i, j, dx, theta = self._pairs(q)
        grad = np.zeros((self.n, 3))
        virial = np.zeros((2, 2))
        energy, n = _kernels.pair_sum(self._code, i, j, dx, theta, self.params, self.k, grad, virial)
        return ModelEvaluation(float(energy), np.concatenate([grad[:, :2].ravel(), grad[:, 2]]), virial, int(n))

    def pair_table(self, q: NDArray[np.float64]) -> dict[str, NDArray]:
        """Interacting pairs (energy > 0) with their energies and gradients.

        Returns
        -------
        dict of arrays
            ``i, j`` (P,), ``i < j``; ``energy`` (P,) [energy]; ``gradient`` (P, 6),
            ``dU / d(x_i, y_i, theta_i, x_j, y_j, theta_j)``; ``dx`` (P, 2) the
            minimum-image ``x_j - x_i`` [length].
        """
        i, j, dx, theta = self._pairs(q)
        table = _kernels.pair_table(self._code, i, j, dx, theta, self.params, self.k)
        keep = table[:, 0] > 0.0
        order = np.lexsort((j[keep], i[keep]))
        return {"i": i[keep][order], "j": j[keep][order], "energy": table[keep, 0][order],
                "gradient": table[keep, 1:][order], "dx": dx[keep][order]}

    def check_cores(self, q: NDArray[np.float64]) -> None:
        """Raise ``ValueError`` if two circulo cores or dumbbell shafts cross (outside the contact model)."""
        if self.family not in ("circulo", "dumbbell"):
            return
        i, j, dx, theta = self._pairs(q)
        crossed = _kernels.circulo_crossed_pairs(i, j, dx, theta, self.params)
        if np.any(crossed):
            k = int(np.flatnonzero(crossed)[0])
            raise ValueError(
                f"{int(crossed.sum())} pair(s) of {self.family} bodies have intersecting cores, e.g. "
                f"({i[k]}, {j[k]}): an overlap deeper than the rounding radius or shaft, outside the contact model"
            )

    def contact_terms(self, q: NDArray[np.float64]) -> dict[str, NDArray]:
        """Overlapping vertex–edge terms of a circulo packing (see :func:`._kernels.circulo_terms`).

        Returns
        -------
        dict of arrays, one entry per row
            ``i, j`` (bodies of the pair, ``i < j``), ``vertex_body`` (``i`` or ``j``:
            the body whose vertex overlaps), ``vertex``, ``edge``, ``r``, ``delta``
            [length], ``weight``, ``point`` (N_t, 2) contact point relative to the
            vertex body's centre [length], ``normal`` (N_t, 2) unit normal from the edge
            body to the vertex body, ``t`` (foot parameter on the edge).
        """
        if self.family != "circulo":
            raise ValueError(f"contact terms are defined for circulo packings, not {self.family}")
        i, j, dx, theta = self._pairs(q)
        rows = _kernels.circulo_terms(i, j, dx, theta, self.params, self.k)
        pair = rows[:, 0].astype(np.int64)
        side = rows[:, 1].astype(np.int64)
        return {
            "i": i[pair], "j": j[pair], "vertex_body": np.where(side == 0, i[pair], j[pair]),
            "vertex": rows[:, 2].astype(np.int64), "edge": rows[:, 3].astype(np.int64),
            "r": rows[:, 4], "delta": rows[:, 5], "weight": rows[:, 6], "point": rows[:, 7:9],
            "normal": rows[:, 9:11], "t": rows[:, 11],
        }

    def point_terms(self, q: NDArray[np.float64]) -> dict[str, NDArray]:
        """Overlapping terms of a Reuleaux or dumbbell packing, one row each.

        Returns
        -------
        dict of arrays, one entry per row
            ``i, j`` (``i < j``), ``type`` (see :func:`._kernels.dumbbell_terms` and
            :func:`._kernels.reuleaux_terms`), ``a, b`` (lobe / arc / vertex index on
            ``i`` and ``j``, -1 for a shaft), ``point_i, point_j`` (N_t, 2) the two
            body-fixed points of the term relative to ``i``'s centre [length] (the line
            of the force joins them), ``r``, ``delta`` [length].
        """
        if self.family not in POINT_TERM_FAMILIES:
            raise ValueError(f"point terms are defined for {', '.join(POINT_TERM_FAMILIES)} packings, not {self.family}")
        i, j, dx, theta = self._pairs(q)
        terms, most = _TERMS[self.family]
        rows = _kernels.point_terms(terms, i, j, dx, theta, self.params, self.k, most)
        pair = rows[:, 0].astype(np.int64)
        return {"i": i[pair], "j": j[pair], "type": rows[:, 1].astype(np.int64), "a": rows[:, 2].astype(np.int64),
                "b": rows[:, 3].astype(np.int64), "point_i": rows[:, 4:6], "point_j": rows[:, 6:8],
                "r": rows[:, 8], "delta": rows[:, 9]}

    def project(self, g: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``g`` itself, or with frozen orientations a copy without its orientation components."""
        if self.rotations:
            return g
        out = np.array(g, dtype=np.float64)
        out[2 * self.n:] = 0.0
        return out

    def reproject(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        return q

    def max_force(self, g: NDArray[np.float64]) -> float:
        """Largest per-body ``sqrt(|F_i|^2 + (tau_i / torque_arm)^2)`` [energy / length].

        ``torque_arm`` is the mean bounding diameter, so force and torque balance are
        asked to one relative accuracy.
        """
        f = g[: 2 * self.n].reshape(self.n, 2)
        tau = g[2 * self.n:] / self.torque_arm
        return float(np.sqrt(np.max(np.sum(f * f, axis=1) + tau * tau)))

    def hessian(self, q: NDArray[np.float64]) -> sp.csr_matrix:
        """``d^2 U / dq dq`` (complex-step of the analytic gradient), shape ``(3N, 3N)``."""
        i, j, dx, theta = self._pairs(q)
        blocks = _kernels.pair_hessian_blocks(self._code, i, j, dx, theta, self.params, self.k,
                                              _kernels.COMPLEX_STEP)
        n = self.n
        index = np.stack([2 * i, 2 * i + 1, 2 * n + i, 2 * j, 2 * j + 1, 2 * n + j], axis=1)
        rows = np.repeat(index, 6, axis=1).ravel()
        cols = np.tile(index, (1, 6)).ravel()
        h = sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(self.n_dof, self.n_dof)).tocsr()
        h.sum_duplicates()
        h.eliminate_zeros()
        return h

    def rescaled(self, factor: float, configuration: NDArray[np.float64]) -> tuple["ShapeModel", NDArray[np.float64]]:
        """The model in the box scaled by ``factor`` (shapes unchanged), centres moved affinely."""
        c = np.array(configuration, dtype=np.float64)
        c[:, :2] *= factor
        model = ShapeModel(self.box.scaled(factor), self.shapes, self.shape_index, self.k, self.mass, self.nlist,
                           self.rotations)
        return model, c
