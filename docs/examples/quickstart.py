"""Quickstart: jam a small packing by LS + CALiPPSO, check it, and read the numbers back.

Run it from anywhere: ``python docs/examples/quickstart.py [OUT_DIR]``. It writes two
netCDF files and an extended XYZ into OUT_DIR (default: a temporary folder), checks the
physics of the result and prints the key numbers. The test suite runs it, so it cannot
drift away from the library.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import xarray as xr

import jamflow
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL


def main(out: Path) -> dict[str, float]:
    """Random start -> LS to p = 1e4 -> CALiPPSO; returns the key numbers."""
    # 32 bidisperse discs (ratio 1.4, half small) at phi = 0.4, seed 7
    start = jamflow.random_packing(32, 2, 0.4, "bi", seed=7)
    # Lubachevsky-Stillinger: grow the diameters at rate 1e-2 until the reduced pressure reaches 1e4
    ls = jamflow.ls_compress(start, 1e-2, [1e4], seed=7)
    (snapshot,) = ls.snapshots
    # CALiPPSO: jam exactly by a chain of linear programs; contacts and forces from the duals
    result = jamflow.calippso_jam(snapshot)
    jammed = result.packing
    path = jamflow.write_packing(jammed, out / "jammed.nc")
    jamflow.write_xyz(jammed, out / "jammed.xyz")

    # the same checks `jamflow check` prints
    s = jamflow.summarize(jamflow.read_packing(path))
    assert s.isostatic and s.n_contacts == 2 * (s.n_stable - 1) + 1, "an LS+CALiPPSO packing is isostatic"
    assert s.max_overlap_rel < OVERLAP_TOL and s.force_balance_residual < FORCE_BALANCE_TOL

    # the dataset holds the same numbers, with units and provenance
    ds = xr.load_dataset(path)
    numbers = {
        "phi_LS": snapshot.packing_fraction,
        "p_LS": snapshot.pressure,
        "phi_J": ds.attrs["phi_J"],
        "LPs": ds.attrs["iterations"],
        "N_c": s.n_contacts,
        "isostatic count": s.isostatic_count,
        "rattlers": s.n_rattlers,
        "max overlap": s.max_overlap_rel,
    }
    for name, value in numbers.items():
        print(f"{name:16s} {value:.10g}")
    return numbers


if __name__ == "__main__":
    if len(sys.argv) > 1:
        target = Path(sys.argv[1])
        target.mkdir(parents=True, exist_ok=True)
        main(target)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(tmp))
