"""Bitwise regression of CALiPPSO and LS between two versions of jamflow.

Jams fixed inputs and stores every resulting array in one ``.npz``: the d = 3 LS
example (``tests/data/calippso-ls/``) with the LP chain and with the Newton finish, a
2D N = 64 random start (also with the Sec. IV relaxation), a 2D walled start
(``random_packing(walls=True)`` + ``calippso(walls=True)``) and a triangular crystal
(the degenerate, geometric-network path); and LS compressions on fixed seeds in d = 2
and 3, with the neighbour lists and with the cell scan (snapshots, final state and the
equation of state), each jammed by CALiPPSO. Stored: positions, diameters,
contacts, forces, rattlers, wall contacts and forces, the per-LP history (every
variable but the wall time ``lp_time``) and every numeric attribute except the timings
(``total_time``, ``peak_memory``, ``lp_time_total``, ``newton_time``, ``cpu_time``,
``collisions_per_second``, ``created``). Run it once with each version on
``PYTHONPATH`` and compare::

    PYTHONPATH=/path/to/old/src python benchmarks/calippso_bitwise.py run /tmp/old.npz
    PYTHONPATH=src python benchmarks/calippso_bitwise.py run /tmp/new.npz
    python benchmarks/calippso_bitwise.py compare /tmp/old.npz /tmp/new.npz

``compare`` lists the arrays that differ and the names found in one file only; the
CALiPPSO output's start values ``phi`` and ``p`` are compared with ``phi_start`` and
``p_start`` of the other file (the one renamed output).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"

#: Attributes that measure time or memory, not the packing.
TIMINGS = {"total_time", "peak_memory", "lp_time_total", "newton_time", "cpu_time", "collisions_per_second"}

#: Renamed output: the start's values in a CALiPPSO output (old name -> new name).
RENAMED = {"phi": "phi_start", "p": "p_start"}


def _attrs(prefix: str, attrs: dict, out: dict[str, np.ndarray]) -> None:
    for k, v in attrs.items():
        if k in TIMINGS or isinstance(v, (str, bytes, dict, list)) or v is None:
            continue
        out[f"{prefix}.attr.{k}"] = np.asarray(v, dtype=np.float64)


def _packing(prefix: str, p, out: dict[str, np.ndarray]) -> None:
    out[f"{prefix}.position"] = p.position
    out[f"{prefix}.diameter"] = p.diameter
    out[f"{prefix}.box"] = p.box.matrix
    for name in ("contacts", "force", "rattler"):
        value = getattr(p, name)
        if value is not None:
            out[f"{prefix}.{name}"] = np.asarray(value)
    _attrs(prefix, p.attrs, out)


def _calippso(prefix: str, res, out: dict[str, np.ndarray]) -> None:
    _packing(prefix, res.packing, out)
    out[f"{prefix}.wall_contacts"] = res.wall_contacts
    out[f"{prefix}.wall_force"] = res.wall_force
    out[f"{prefix}.converged"] = np.array([res.converged, res.iterations], dtype=np.int64)
    for name in res.history.data_vars:
        if name != "lp_time":
            out[f"{prefix}.history.{name}"] = res.history[name].values
    print(f"{prefix}: {res.iterations} LPs, phi_J = {res.packing.attrs['phi_J']!r}")


def run(path: str) -> None:
    import jamflow
    from jamflow.io import read_dat
    from jamflow.protocols.calippso import calippso
    from jamflow.protocols.initial import random_packing
    from jamflow.protocols.lattices import lattice_packing
    from jamflow.protocols.ls import compress

    print("jamflow from", jamflow.__file__)
    out: dict[str, np.ndarray] = {}
    ls3 = read_dat(DATA / "calippso-ls" / "Centers-after-LS--N-1024--d-3.dat")
    _calippso("ls3d", calippso(ls3), out)
    _calippso("ls3d_newton", calippso(ls3, finish="newton"), out)
    start = random_packing(64, 2, 0.4, "bi", seed=7)
    _calippso("random2d", calippso(start), out)
    _calippso("random2d_relax", calippso(start, relax=0.5, solver="ipm"), out)
    walled = random_packing(64, 2, 0.4, "bi", seed=8, walls=True)
    _calippso("walls2d", calippso(walled, walls=True), out)
    _calippso("triangular", calippso(lattice_packing("triangular", (6, 4))), out)
    for d, n, phi, lists in ((2, 128, 0.5, None), (3, 128, 0.3, None), (2, 128, 0.5, False), (3, 128, 0.3, False)):
        res = compress(random_packing(n, d, phi, "bi", seed=3), 1e-3, (1e3, 1e6), seed=4, neighbor_list=lists)
        tag = f"lsrun{d}d" + ("_cells" if lists is False else "")
        for k, snap in enumerate(res.snapshots):
            _packing(f"{tag}.snapshot{k}", snap, out)
        _packing(f"{tag}.final", res.final, out)
        for name in res.eos.data_vars:
            out[f"{tag}.eos.{name}"] = res.eos[name].values
        out[f"{tag}.collisions"] = np.array([res.collisions])
        print(f"{tag}: {res.collisions} collisions, stop {res.stop_reason}")
        _calippso(f"{tag}.calippso", calippso(res.snapshots[-1]), out)
    np.savez(path, **out)
    print(f"wrote {len(out)} arrays to {path}")


def _renamed(key: str) -> str:
    head, _, name = key.rpartition(".attr.")
    return f"{head}.attr.{RENAMED[name]}" if _ and name in RENAMED else key


def compare(a: str, b: str) -> int:
    old, new = np.load(a), np.load(b)
    old_keys, new_keys = set(old.files), set(new.files)
    mapped = {k: k if k in new_keys else _renamed(k) for k in old_keys}
    same, differ = [], []
    for k in sorted(old_keys):
        m = mapped[k]
        if m not in new_keys:
            continue
        x, y = old[k], new[m]
        (same if x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes() else differ).append(k)
    only_old = sorted(k for k in old_keys if mapped[k] not in new_keys)
    only_new = sorted(new_keys - set(mapped.values()))
    renamed = sorted(f"{k} -> {m}" for k, m in mapped.items() if m != k and m in new_keys)
    print(f"{len(same)} of {len(same) + len(differ)} arrays bitwise identical")
    if renamed:
        print("compared under a new name:", ", ".join(renamed))
    for label, keys in (("differ", differ), ("only in the first file", only_old), ("only in the second file", only_new)):
        if keys:
            print(f"{label}: {', '.join(keys)}")
    return 1 if differ or only_old or only_new else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        run(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
