"""Bitwise regression of the event-driven commands between two versions of jamflow.

Runs one chain of ``jamflow`` commands with whatever jamflow is on ``PYTHONPATH`` and
keeps every output file; ``compare`` then checks every variable and coordinate of every
netCDF file of two such runs byte for byte (dtype, shape and bytes) and every global
attribute except the provenance (creation time, version, git sha, history; the run's
folder in the recorded file paths is read as ``RUN``)::

    PYTHONPATH=/path/to/old/src python benchmarks/flow_bitwise.py run /tmp/flow-old
    PYTHONPATH=src python benchmarks/flow_bitwise.py run /tmp/flow-new
    python benchmarks/flow_bitwise.py compare /tmp/flow-old /tmp/flow-new

The chain (2D 1:1.4 bidisperse discs, so that pairs of different contact distances
meet; each command on the previous command's output of the same version):

1. ``init`` N discs at phi = 0.50 (random sequential addition);
2. ``compress`` to jamming (time series, snapshots, final jammed packing);
3. ``decompress`` the jammed packing to phi = 0.835 (gaps of about 0.2 %, so that shear
   makes contacts at once);
4. ``shear`` it to strain 0.02 at fixed volume (series, 4 snapshots, final packing);
5. ``shear --order 2`` (midpoint steps) to strain 0.01;
6. ``shear --pressure 1`` (fixed pressure) to strain 0.01;
7. ``compress --shear`` for 3000 steps (final packing);
8. a 3D ``compress`` of N / 2 monodisperse spheres from phi = 0.35 to 0.55.

``--n`` sets N (default 256); a run takes a few minutes on a quiet core.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import xarray as xr

#: global attributes that name the run rather than its numbers
PROVENANCE = {"created", "history", "git_sha", "jamflow_version", "source"}


def _jamflow(*args: str) -> None:
    cmd = [sys.executable, "-m", "jamflow", *args, "--quiet"]
    print(" ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True, env=os.environ.copy())


def run(out: Path, n: int) -> None:
    out.mkdir(parents=True, exist_ok=True)
    f = {name: str(out / f"{name}.nc") for name in (
        "start", "compress", "jammed", "dec", "shear", "shear_final", "shear2", "shear_p", "cshear", "cshear_final",
        "start3", "compress3")}
    _jamflow("init", f["start"], "--d", "2", "--n", str(n), "--phi", "0.50", "--dispersity", "bi", "--seed", "7")
    _jamflow("compress", f["start"], f["compress"], "--final", f["jammed"], "--snapshots", "3")
    _jamflow("decompress", f["jammed"], f["dec"], "--phi", "0.835")
    _jamflow("shear", f["dec"], f["shear"], "--strain", "0.02", "--snapshots", "4", "--final", f["shear_final"])
    _jamflow("shear", f["dec"], f["shear2"], "--strain", "0.01", "--order", "2")
    _jamflow("shear", f["dec"], f["shear_p"], "--strain", "0.01", "--pressure", "1")
    _jamflow("compress", f["dec"], f["cshear"], "--shear", "--max-steps", "3000", "--final", f["cshear_final"])
    _jamflow("init", f["start3"], "--d", "3", "--n", str(n // 2), "--phi", "0.35", "--seed", "3")
    _jamflow("compress", f["start3"], f["compress3"], "--phi", "0.55")


def _same(a: xr.DataArray | np.ndarray, b: xr.DataArray | np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind in "OUS":
        return bool(np.all(a == b))
    return np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()


def _in_run(value: object, run: Path) -> object:
    """An attribute with the run's own folder named ``RUN`` (the parameters record file paths)."""
    return value.replace(str(run), "RUN") if isinstance(value, str) else value


def compare(a: Path, b: Path) -> int:
    files = sorted({p.name for p in a.glob("*.nc")} | {p.name for p in b.glob("*.nc")})
    bad: list[str] = []
    total = 0
    for name in files:
        if not (a / name).exists() or not (b / name).exists():
            bad.append(f"{name}: only in one run")
            continue
        with xr.open_dataset(a / name, decode_times=False) as old, xr.open_dataset(b / name, decode_times=False) as new:
            names = sorted(set(old.variables) | set(new.variables))
            for v in names:
                total += 1
                if v not in old.variables or v not in new.variables:
                    bad.append(f"{name}:{v} only in one run")
                elif not _same(old[v].values, new[v].values):
                    bad.append(f"{name}:{v}")
            keys = (set(old.attrs) | set(new.attrs)) - PROVENANCE
            for k in sorted(keys):
                total += 1
                if k not in old.attrs or k not in new.attrs or not _same(_in_run(old.attrs[k], a), _in_run(new.attrs[k], b)):
                    bad.append(f"{name}:@{k}")
            print(f"{name:24s} {len(names)} arrays, {len(keys)} attributes")
    for item in bad:
        print("DIFFERENT", item)
    print(f"{total - len(bad)} of {total} arrays and attributes bitwise identical over {len(files)} files")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the chain with the jamflow on PYTHONPATH")
    r.add_argument("out", type=Path)
    r.add_argument("--n", type=int, default=256)
    c = sub.add_parser("compare", help="compare two runs byte for byte")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    if args.command == "run":
        run(args.out, args.n)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
