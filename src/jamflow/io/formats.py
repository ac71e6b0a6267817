"""Other file formats: CALiPPSO ``.dat``, extended XYZ (OVITO, ASE) and HOOMD GSD.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..box import Box
from ..state.packing import Packing
from ..tolerances import SIZE_CLASS_RTOL
from .dataset import _atomic, _atomic_text, _refuse_clobbering_a_packing

__all__ = [
    "read_dat",
    "write_dat",
    "MAX_SIZE_CLASSES",
    "size_classes",
    "write_xyz",
    "write_gsd",
    "gsd_types",
]


def read_dat(path: str | os.PathLike) -> Packing:
    """Read a CALiPPSO.jl ``.dat`` configuration (monodisperse, unit periodic box).

    Format: line 1 d, line 2 N, line 3 diameter, then N lines of d coordinates.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a CALiPPSO .dat file (not text)") from None
    lines = [ln.split() for ln in text.splitlines() if ln.strip()]
    try:
        d, n, diameter = int(lines[0][0]), int(lines[1][0]), float(lines[2][0])
        x = np.array([[float(v) for v in ln] for ln in lines[3:]], dtype=np.float64)
    except (IndexError, ValueError) as exc:
        raise ValueError(f"{path}: not a CALiPPSO .dat file ({exc})") from exc
    if x.shape != (n, d):
        raise ValueError(f"{path}: header says N={n}, d={d} but found positions of shape {x.shape}")
    box = Box.cubic(d, 1.0)
    return Packing(
        position=box.wrap(x),
        diameter=np.full(n, diameter),
        box=box,
        protocol="import-dat",
        parameters={"source_file": path.name},
        attrs={"length_unit": "side of the periodic box"},
    )


def write_dat(packing: Packing, path: str | os.PathLike) -> Path:
    """Write a monodisperse packing in a unit cubic box as a CALiPPSO ``.dat`` file."""
    if not np.allclose(packing.box.matrix, np.eye(packing.d)):
        raise ValueError("the .dat format needs a unit cubic box")
    if np.ptp(packing.diameter) != 0.0:
        raise ValueError("the .dat format holds one diameter (monodisperse packings)")
    header = f"{packing.d}\n{packing.n}\n{float(packing.diameter[0])!r}\n"
    body = "\n".join(" ".join(repr(float(v)) for v in row) for row in packing.position)
    return _atomic_text(Path(path), header + body + "\n")


#: More distinct diameters than this are a continuous size distribution: one particle type.
MAX_SIZE_CLASSES: int = 8


def size_classes(diameter: np.ndarray) -> tuple[list[str], np.ndarray]:
    """Particle-type names by size class and each particle's class, for viewers.

    Diameters equal to :data:`~jamflow.tolerances.SIZE_CLASS_RTOL` form one class,
    named in increasing size: ``sphere`` (monodisperse), ``small``/``large``
    (bidisperse), ``size1`` ... ``sizeK`` (up to :data:`MAX_SIZE_CLASSES`). A wider
    (continuous) distribution is one type ``poly``: the radius column carries each
    size. None of these names is a chemical symbol, so viewers do not draw the
    particles as an element.

    Returns
    -------
    names : list of str
    index : ndarray of int, shape (N,)
        Class of each particle (into ``names``).
    """
    order = np.argsort(diameter, kind="stable")
    d = diameter[order]
    new_class = np.concatenate([[True], np.diff(d) > SIZE_CLASS_RTOL * d[1:]])
    k = np.cumsum(new_class) - 1
    n_classes = int(k[-1]) + 1
    if n_classes > MAX_SIZE_CLASSES:
        return ["poly"], np.zeros(len(diameter), dtype=np.int64)
    names = {1: ["sphere"], 2: ["small", "large"]}.get(n_classes, [f"size{c + 1}" for c in range(n_classes)])
    index = np.empty(len(diameter), dtype=np.int64)
    index[order] = k
    return names, index


def _frames(frames: Packing | Sequence[Packing]) -> list[Packing]:
    frames = [frames] if isinstance(frames, Packing) else list(frames)
    if not frames:
        raise ValueError("no packing to write")
    return frames


def _frame_scalars(packing: Packing) -> dict[str, float]:
    """Per-frame numbers of an export: ``phi`` and, when known, ``strain``, ``time``, ``pressure``."""
    scalars = {"phi": packing.packing_fraction}
    scalars.update({key: float(packing.attrs[key]) for key in ("strain", "time") if key in packing.attrs})
    if packing.pressure is not None and np.isfinite(packing.pressure):
        scalars["pressure"] = float(packing.pressure)
    return scalars


def _particle_columns(packing: Packing) -> dict[str, np.ndarray]:
    """Per-particle export columns after the centres, each of shape (N, width), in file order.

    ``radius``; ``rattler`` (0/1) when known; for shaped bodies ``shape_index``,
    ``angle`` [rad], ``orientation`` (quaternion ``(x, y, z, w)`` of the rotation
    about z) and, with ellipses, ``aspherical_shape`` (semi-axes ``(a, b, b)``, zeros
    for other bodies); with contact forces ``force_sum`` and ``force_residual``.
    """
    from ..network.spheres import force_balance_residual

    n = packing.n
    columns: dict[str, np.ndarray] = {"radius": 0.5 * packing.diameter[:, None]}
    if packing.rattler is not None:
        columns["rattler"] = packing.rattler.astype(np.int64)[:, None]
    if packing.shapes is not None:
        theta = np.asarray(packing.orientation, dtype=np.float64)
        quat = np.zeros((n, 4))
        quat[:, 2], quat[:, 3] = np.sin(0.5 * theta), np.cos(0.5 * theta)
        columns.update(shape_index=packing.shape_index.astype(np.int64)[:, None], angle=theta[:, None],
                       orientation=quat)
        kind = packing.shapes.kind[packing.shape_index]
        if np.any(kind == "ellipse"):
            semi = np.where((kind == "ellipse")[:, None], packing.shapes.semi_axes[packing.shape_index], 0.0)
            columns["aspherical_shape"] = np.column_stack([semi, semi[:, 1]])
    if packing.force is not None:
        load = np.zeros(n)
        np.add.at(load, packing.contacts[:, 0], np.abs(packing.force))
        np.add.at(load, packing.contacts[:, 1], np.abs(packing.force))
        columns.update(force_sum=load[:, None], force_residual=force_balance_residual(packing)[:, None])
    return columns


def write_xyz(frames: Packing | Sequence[Packing], path: str | os.PathLike, pos_2d: bool = False) -> Path:
    """Write extended XYZ readable by OVITO and ASE: one frame per packing.

    Columns: ``type`` (size class, :func:`size_classes`; OVITO's particle type, ASE's
    ``atoms.arrays["type"]`` with chemically neutral ``X`` atoms), ``pos``, ``radius``;
    with rattler flags ``rattler`` (0/1); with contact forces ``force_sum`` (sum of
    the magnitudes of the particle's contact forces, in the dataset's force unit) and
    ``force_residual`` (norm of the vector sum of its contact forces relative to the
    mean contact force: the per-particle force-balance residual of ``jamflow check``).
    Each frame's header has ``Lattice`` (box vectors), ``pbc``, ``phi`` and, when
    known, ``strain``, ``time`` and ``pressure``.

    Shaped bodies (2D) add ``shape_index:I:1``, ``angle:R:1`` (orientation [rad]) and
    ``orientation:R:4``, the unit quaternion ``(X, Y, Z, W) = (0, 0, sin(theta/2),
    cos(theta/2))`` of the rotation about z, which OVITO maps to its ``Orientation``
    property; with ellipses also ``aspherical_shape:R:3`` (OVITO's ``Aspherical
    Shape``: semi-axes ``(a, b, b)`` for an ellipse, zeros for other bodies, which
    OVITO then draws with their ``radius``, the bounding radius).

    2D packings are written with ``pbc="T T F"``, ``z = 0`` and a third lattice vector
    ``(0, 0, max diameter)``: ASE reads them as periodic in x and y only, and OVITO
    needs every lattice vector non-zero to load the cell. OVITO marks a system 2D only
    when the file has no z column; ``pos_2d=True`` writes ``pos:R:2`` for that (ASE
    cannot read such files). d > 3 keeps the first three coordinates and says so.
    """
    frames = _frames(frames)
    lines: list[str] = []
    for packing in frames:
        d, n = packing.d, packing.n
        k = min(d, 3)
        h = np.zeros((3, 3))
        h[:k, :k] = packing.box.matrix[:k, :k]
        if d == 2:
            h[2, 2] = float(packing.diameter.max())
        pos = np.zeros((n, 3))
        pos[:, :k] = packing.box.wrap(packing.position)[:, :k]
        names, index = size_classes(packing.diameter)
        width = 2 if (d == 2 and pos_2d) else 3
        columns = _particle_columns(packing)
        props = [f"type:S:1:pos:R:{width}"]
        props += [f"{name}:{'I' if c.dtype.kind == 'i' else 'R'}:{c.shape[1]}" for name, c in columns.items()]
        columns = {"pos": pos[:, :width], **columns}
        info = [f'Lattice="{" ".join(repr(float(v)) for v in h.T.ravel())}"', f"Properties={':'.join(props)}",
                f'pbc="T T {"T" if d > 2 else "F"}"']
        info += [f"{key}={value!r}" for key, value in _frame_scalars(packing).items()]
        if d > 3:
            info.append(f'projection="first 3 of {d} coordinates"')
        table = np.hstack(list(columns.values()))
        kinds = [c.dtype.kind for c in columns.values() for _ in range(c.shape[1])]
        lines += [str(n), " ".join(info)]
        lines += [" ".join([names[t], *(str(int(v)) if kind == "i" else repr(float(v)) for v, kind in zip(row, kinds))])
                  for t, row in zip(index.tolist(), table.tolist())]
    path = Path(path)
    _refuse_clobbering_a_packing(path, "this writes an extended XYZ file")
    return _atomic_text(path, "\n".join(lines) + "\n")


def write_gsd(frames: Packing | Sequence[Packing], path: str | os.PathLike) -> Path:
    """Write a HOOMD-blue GSD trajectory readable by OVITO: one frame per packing, links as bonds.

    The format for packings with links (extended XYZ has no bonds). Per frame:
    ``configuration/box`` (``[Lx, Ly, Lz, xy, xz, yz]``, HOOMD tilt factors; ``Lz = 0``
    and ``dimensions = 2`` in 2D), ``particles/position`` centred on the box origin as
    HOOMD stores it, ``particles/diameter``; ``bonds/group`` = the links (bond type
    ``link``); ``log/<name>`` for ``phi`` and, when known, ``strain``, ``time`` and
    ``pressure``; ``log/particles/<name>`` for every other column of
    :func:`write_xyz` (``rattler``, ``shape_index``, ``angle``, ``force_sum``,
    ``force_residual``), which OVITO reads as particle properties of that name.

    Spheres get the size-class types of :func:`size_classes`. Shaped bodies get one
    type per row of the shape table (``<kind><row>``) with its ``particles/type_shapes``
    entry (``Ellipsoid`` with semi-axes ``(a, b, b)``, ``Sphere`` for disks,
    ``Polygon`` with the rounding radius for circulo-polygons; other kinds ``{}``,
    drawn as their bounding disk) and ``particles/orientation``, the quaternion
    ``(w, x, y, z) = (cos(theta/2), 0, 0, sin(theta/2))``.

    The GSD schema stores the box, positions, diameters and orientations in single precision
    (relative 6e-8): enough to look at a packing, not to recount its contacts.

    Raises
    ------
    ValueError
        d not 2 or 3, or a box that is not upper triangular (HOOMD's box form).
    ModuleNotFoundError
        Without the ``gsd`` package (``pip install gsd``, the ``gsd`` extra).
    """
    import gsd.hoomd

    snapshots = [_gsd_frame(packing, gsd.hoomd.Frame()) for packing in _frames(frames)]
    path = Path(path)
    _refuse_clobbering_a_packing(path, "this writes a GSD file")
    path.parent.mkdir(parents=True, exist_ok=True)
    with _atomic(path) as (fd, tmp):
        os.close(fd)
        with gsd.hoomd.open(tmp, mode="w") as trajectory:
            trajectory.extend(snapshots)
    return path


def _gsd_frame(packing: Packing, frame: Any) -> Any:
    """Fill a ``gsd.hoomd.Frame`` with one packing (see :func:`write_gsd`)."""
    d, n = packing.d, packing.n
    if d not in (2, 3):
        raise ValueError(f"GSD holds 2D and 3D systems, got d = {d}")
    h = packing.box.matrix
    if np.any(np.tril(h, -1) != 0.0):
        raise ValueError("GSD needs an upper-triangular box matrix (HOOMD's box form)")
    lz = h[2, 2] if d == 3 else 0.0
    frame.configuration.dimensions = d
    frame.configuration.box = [h[0, 0], h[1, 1], lz, h[0, 1] / h[1, 1],
                               h[0, 2] / lz if d == 3 else 0.0, h[1, 2] / lz if d == 3 else 0.0]
    s = packing.box.to_fractional(packing.box.wrap(packing.position)) - 0.5
    position = np.zeros((n, 3))
    position[:, :d] = packing.box.to_cartesian(s)
    frame.particles.N = n
    frame.particles.position = position
    columns = _particle_columns(packing)
    frame.particles.diameter = 2.0 * columns.pop("radius")[:, 0]
    frame.particles.types, frame.particles.typeid = gsd_types(packing)
    if packing.shapes is not None:
        table = packing.shapes
        frame.particles.type_shapes = [_type_shape(table, k) for k in range(len(table))]
        frame.particles.orientation = columns.pop("orientation")[:, [3, 0, 1, 2]]
        columns.pop("aspherical_shape", None)  # in type_shapes
    if packing.links is not None:
        frame.bonds.N = len(packing.links)
        frame.bonds.types = ["link"]
        frame.bonds.typeid = np.zeros(len(packing.links), dtype=np.uint32)
        frame.bonds.group = np.column_stack([packing.links.i, packing.links.j])
    frame.log = {name: np.array([value]) for name, value in _frame_scalars(packing).items()}
    frame.log.update({f"particles/{name}": column[:, 0] for name, column in columns.items()})
    return frame


def gsd_types(packing: Packing) -> tuple[list[str], np.ndarray]:
    """Particle-type names and each particle's type in :func:`write_gsd`.

    Spheres: the size classes of :func:`size_classes`. Shaped bodies: one type per
    row ``k`` of the shape table, named ``<kind><k>`` (GSD attaches shapes to types).
    """
    if packing.shapes is None:
        return size_classes(packing.diameter)
    return [f"{kind}{k}" for k, kind in enumerate(packing.shapes.kind)], packing.shape_index


def _type_shape(table: Any, k: int) -> dict[str, Any]:
    """HOOMD ``type_shapes`` entry of shape row ``k`` (``{}`` where OVITO has no such shape)."""
    kind = str(table.kind[k])
    if kind == "ellipse":
        a, b = (float(v) for v in table.semi_axes[k])
        return {"type": "Ellipsoid", "a": a, "b": b, "c": b}
    if kind == "disk":
        return {"type": "Sphere", "diameter": 2.0 * float(table.radius[k])}
    if kind == "circulo_polygon":
        return {"type": "Polygon", "rounding_radius": float(table.radius[k]),
                "vertices": table.vertex_list(k).tolist()}
    return {}
