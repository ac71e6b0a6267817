"""Table II of VanderWerf et al.: principal curvatures of the contact constraints per contact type.

Fresh packings of N = 24 bidisperse circulo-lines at A = 1.04 (``init-shapes`` random start
at phi = 0.3, ``soft-jam`` to P0 = 1e-9 with the default tolerances), then
:func:`jamflow.shapes.curvature.curvature_dataset`: per contact type (parallel, end-middle,
end-end; end or middle particle) the mean and RMS deviation of kappa_1 and kappa_2 in units
of the box side L, for the first packing alone and for the ensemble, beside the paper's
values. Packings are kept in ``--data`` and reused.

Writes ``benchmarks/output/shapes_table2.nc`` and ``shapes_table2.png`` and prints the table.

Usage: ``python benchmarks/shapes_table2.py [--seeds 1 ... 20] [--pressure 1e-9] [--plot-only]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from jamflow.io import new_dataset_attrs, read_packing, write_dataset, write_packing
from jamflow.minimize.onset import JammingSettings
from jamflow.plots import save_figure
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)
from jamflow.shapes.curvature import CONTACT_TYPES, curvature_dataset

OUT = Path(__file__).resolve().parent / "output"

#: Table II (kappa_1, error, kappa_2, error); None where the paper gives an analytic zero
#: without an error. Parallel (end): kappa_2 is the mean magnitude (the paper's asterisk).
PAPER = {("parallel", "end"): (0.0, None, 7.93e-9, 1.40e-9),
         ("parallel", "middle"): (-1.292, 0.005, 0.774, 0.003),
         ("end_middle", "end"): (-0.0261, 0.0004, 0.0, None),
         ("end_middle", "middle"): (-1.292, 0.002, 0.774, 0.001),
         ("end_end", "end"): (-5.69, 0.01, -0.0246, 0.0002)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 21)))
    ap.add_argument("--pressure", type=float, default=1e-9)
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--asphericity", type=float, default=1.04)
    ap.add_argument("--data", type=Path, default=OUT / "shapes_table2")
    ap.add_argument("--plot-only", action="store_true")
    args = ap.parse_args()
    out = OUT / "shapes_table2.nc"
    if args.plot_only:
        plot(xr.load_dataset(out), out.with_suffix(".png"))
        return
    args.data.mkdir(parents=True, exist_ok=True)
    packings, sources = [], []
    for seed in args.seeds:
        path = args.data / f"circulo-line_a{args.asphericity:g}_n{args.n}_s{seed}_j.nc"
        if not path.exists():
            table = bidisperse_shapes(unit_shape("circulo-line", asphericity=args.asphericity))
            res = jam_shapes(random_shape_packing(table, args.n, 0.3, seed), args.pressure, JammingSettings())
            if not res.converged:
                raise RuntimeError(f"{path.name}: soft-jam did not converge")
            write_packing(res.packing, path)
        packings.append(read_packing(path, None))
        sources.append(str(path))
        print(f"seed {seed}: phi {packings[-1].packing_fraction:.5f}", flush=True)
    ds = curvature_dataset(packings, sources)
    ds.attrs.update(new_dataset_attrs("benchmarks/shapes_table2.py", vars(args) | {"data": str(args.data)}))
    write_dataset(ds, out)
    plot(ds, out.with_suffix(".png"))
    print(table_text(ds))


def table_text(ds: xr.Dataset) -> str:
    lines = [f"Table II, N = {ds.attrs['N']}, A = {ds.attrs['asphericity']:.4g}: first packing | "
             f"{ds.attrs['n_packings']} packings | paper (mean +- RMS deviation, 1/L)"]
    for c, key in enumerate(CONTACT_TYPES):
        if c >= ds.sizes["contact_type"]:
            break
        first = ds.packing_kappa1_mean.values[0, c], ds.packing_kappa1_rms.values[0, c], \
            ds.packing_kappa2_mean.values[0, c], ds.packing_kappa2_rms.values[0, c]
        pooled = ds.kappa1_mean.values[c], ds.kappa1_rms.values[c], ds.kappa2_mean.values[c], ds.kappa2_rms.values[c]
        paper = PAPER[key]
        lines.append(f"{ds.contact_type.values[c]:28s} k1 {first[0]:+.4g} ± {first[1]:.2g} | {pooled[0]:+.4g} ± "
                     f"{pooled[1]:.2g} | {paper[0]:+.4g}{'' if paper[1] is None else f' ± {paper[1]:.2g}'}   "
                     f"k2 {first[2]:+.4g} ± {first[3]:.2g} | {pooled[2]:+.4g} ± {pooled[3]:.2g} | "
                     f"{paper[2]:+.4g}{'' if paper[3] is None else f' ± {paper[3]:.2g}'}   "
                     f"({int(ds.n_contacts.values[0, c])} | {int(ds.n_contacts.values[:, c].sum())} rows)")
    return "\n".join(lines)


def plot(ds: xr.Dataset, path: Path) -> None:
    fig = Figure(layout="constrained", figsize=(9.0, 4.4))
    axes = fig.subplots(1, 2)
    x = np.arange(len(CONTACT_TYPES))
    for k, ax in enumerate(axes):
        mean, rms = ds[f"kappa{k + 1}_mean"].values, ds[f"kappa{k + 1}_rms"].values
        ax.errorbar(x - 0.1, mean, yerr=rms, fmt="o", capsize=3, label=f"jamflow ({ds.attrs['n_packings']} packings)")
        paper = np.array([PAPER[key][2 * k] for key in CONTACT_TYPES])
        err = np.array([PAPER[key][2 * k + 1] or 0.0 for key in CONTACT_TYPES])
        ax.errorbar(x + 0.1, paper, yerr=err, fmt="s", capsize=3, label="VanderWerf et al. Table II")
        ax.axhline(0.0, color="grey", lw=0.8)
        ax.set_yscale("symlog", linthresh=1e-2)
        ax.set_xticks(x, [t.replace(" particle", "") for t in ds.contact_type.values], rotation=30, fontsize=7,
                      ha="right")
        ax.set_ylabel(f"principal curvature kappa_{k + 1} [1/L] (symmetric log)")
        ax.set_xlabel("contact type (particle) [category]")
        ax.legend(fontsize=7)
    fig.suptitle(f"constraint curvatures, N = {ds.attrs['N']} circulo-lines, A = {ds.attrs['asphericity']:.3g}; "
                 "bars: RMS deviation", fontsize=9)
    save_figure(fig, path)


if __name__ == "__main__":
    main()
