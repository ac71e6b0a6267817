"""Constraint counting of fresh shape packings against their spectra (VanderWerf et al. Secs. III A-B).

Three studies, each over fresh packings (``init-shapes`` random start at phi = 0.3, then
``soft-jam`` to P0 with the default tolerances, force_tol 1e-13), one row per packing:

- ``identity``: ellipses and circulo-lines at two asphericities, N = 64, P0 = 1e-9, five
  seeds each: contacts once and twice, rattlers, sliders (by rank), N_c^0 = 3N' - 1 - N_s,
  the quartic modes N_1 of the dynamical matrix and its zero modes; the paper's identity
  N_c = N_c^0 - N_1 (N_c counted twice) and <z> of Eq. 3 once / twice / spectral (Fig. 8's
  numbers). Also counted: near-aligned parallel pairs, whose energy convention differs from
  the paper's (docs/shapes.md, "Energy model").
- ``dumbbells``: the paper's dumbbells by shaft length X (lobe-centre distance in lobe
  radii; Table I, Fig. 4): X = 2, 2.4, 4, 8, four seeds each (N = 32, 64 for X = 8):
  is the short-shaft packing isostatic and the long-shaft one hypostatic?
- ``frozen``: non-rotating circulo-lines (Fig. 3a, A = 1.06), N = 10 and 32, five seeds:
  isostatic with N_c = 2N' - 1 - N_s?

Packings are kept in ``--data`` (default ``benchmarks/output/shapes_counting/``) and reused.
Writes ``benchmarks/output/shapes_counting_<study>.nc`` and ``.png`` and prints the table.

Usage: ``python benchmarks/shapes_counting.py identity|dumbbells|frozen [--seeds 1 2 3 4 5]
[--pressure 1e-9] [--data DIR] [--plot-only]``. The identity study is ~20 N = 64 jammings
(one to ten CPU minutes each).
"""

from __future__ import annotations

import argparse
import time
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
from jamflow.shapes.counting import count_constraints, shape_model_of
from jamflow.shapes.spectrum import spectrum

OUT = Path(__file__).resolve().parent / "output"

#: study -> list of (family, parameter name, value, N, frozen orientations)
STUDIES = {
    "identity": [(f, "asphericity", a, 64, False) for a in (1.1, 1.01) for f in ("circulo-line", "ellipse")],
    "dumbbells": [("dumbbell", "shaft_length", x, 64 if x > 4 else 32, False) for x in (2.0, 2.4, 4.0, 8.0)],
    "frozen": [("circulo-line", "asphericity", 1.06, n, True) for n in (10, 32)],
}


def packing_path(data: Path, family: str, name: str, value: float, n: int, frozen: bool, seed: int) -> Path:
    tag = {"asphericity": "a", "shaft_length": "x"}[name]
    return data / f"{family}_{tag}{value:g}_n{n}{'_frozen' if frozen else ''}_s{seed}_j.nc"


def jammed(data: Path, family: str, name: str, value: float, n: int, frozen: bool, seed: int,
           pressure: float) -> tuple:
    """The jammed packing (made and stored on first use) and the CPU time it took (NaN when reused)."""
    path = packing_path(data, family, name, value, n, frozen, seed)
    if path.exists():
        return read_packing(path, None), np.nan
    t0 = time.process_time()
    table = bidisperse_shapes(unit_shape(family, **{name: value}))
    start = random_shape_packing(table, n, 0.3, seed)
    res = jam_shapes(start, pressure, JammingSettings(), rotations=not frozen)
    if not res.converged:
        raise RuntimeError(f"{path.name}: soft-jam did not converge")
    write_packing(res.packing, path)
    return res.packing, time.process_time() - t0


def near_aligned_pairs(packing) -> int:
    """Circulo pairs with two end-middle terms of distinct vertices and an overlapping end-end term:
    where jamflow's energy (every vertex on every edge) differs from App. A's Fig. 20 rule."""
    model, q = shape_model_of(packing)
    if model.family != "circulo":
        return 0
    t = model.contact_terms(q)
    key = t["i"] * model.n + t["j"]
    middle = (t["t"] > 0.0) & (t["t"] < 1.0)
    count = 0
    for k in np.unique(key):
        rows = key == k
        em = {(b, v) for b, v, m in zip(t["vertex_body"][rows], t["vertex"][rows], middle[rows], strict=True) if m}
        count += int(len(em) >= 2 and np.any(~middle[rows]))
    return count


def row(packing, family: str, value: float, seed: int, cpu: float) -> dict:
    once, *_ = count_constraints(packing, "once")
    twice, rattler, slider, _ = count_constraints(packing, "twice")
    spec = spectrum(packing, fourth=False)
    n_c_spectral = twice.isostatic_count - spec.n_quartic
    backbone = packing.n - twice.n_rattlers
    z_spectral = 2.0 * (n_c_spectral + 1) / (backbone - twice.n_sliders / twice.dofs_per_body)
    # zero modes expected: the two translations, f per rattler, one per slider
    return dict(family=family, value=value, N=packing.n, seed=seed, phi=packing.packing_fraction,
                pressure=packing.pressure, n_contacts_once=once.n_contacts, n_contacts_twice=twice.n_contacts,
                n_rattlers=twice.n_rattlers, n_sliders=twice.n_sliders, isostatic_count=twice.isostatic_count,
                n_quartic=spec.n_quartic, n_zero=spec.n_zero,
                n_zero_expected=2 + twice.dofs_per_body * twice.n_rattlers + twice.n_sliders,
                identity=int(twice.n_contacts == n_c_spectral), z_once=once.z_eq3, z_twice=twice.z_eq3,
                z_spectral=z_spectral, balanced=int(spec.balanced), max_force=spec.max_force,
                near_aligned=near_aligned_pairs(packing), jam_cpu=cpu,
                counting_contacts=twice.counting, dofs=twice.dofs_per_body)


def dataset(rows: list[dict], study: str, pressure: float) -> xr.Dataset:
    p = ("packing",)
    one = {"units": "1"}
    names = {"value": "asphericity A, or the dumbbell shaft length X", "phi": "packing fraction at P0",
             "pressure": "pressure [k]", "n_contacts_once": "contacts N_c, parallel once",
             "n_contacts_twice": "contacts N_c, parallel twice", "n_rattlers": "rattlers (twice)",
             "n_sliders": "sliders (twice, by rank)", "isostatic_count": "N_c^0 = f N' - 1 - N_s",
             "n_quartic": "quartic modes N_1", "n_zero": "zero modes (region 0)",
             "n_zero_expected": "2 + f N_r + N_s", "identity": "1 if N_c (twice) = N_c^0 - N_1",
             "z_once": "<z> Eq. 3, contacts once", "z_twice": "<z> Eq. 3, contacts twice",
             "z_spectral": "<z> Eq. 3, N_c = N_c^0 - N_1", "balanced": "1 if max force <= 1e-3 P",
             "max_force": "largest generalised force [k length]", "near_aligned": "near-aligned parallel pairs",
             "jam_cpu": "CPU time of the jamming [s] (NaN: reused packing)", "N": "bodies", "seed": "seed",
             "dofs": "degrees of freedom per body"}
    data = {k: (p, np.array([r[k] for r in rows]), {**one, "long_name": v}) for k, v in names.items()}
    return xr.Dataset(data, coords={"family": (p, np.array([r["family"] for r in rows])),
                                    "counting": (p, np.array([r["counting_contacts"] for r in rows]))},
                      attrs=new_dataset_attrs(f"benchmarks/shapes_counting.py {study}",
                                              {"study": study, "pressure": pressure}))


def plot(ds: xr.Dataset, path: Path) -> None:
    fig = Figure(layout="constrained", figsize=(7.5, 4.6))
    ax = fig.add_subplot()
    groups = sorted({(str(f), float(v), int(n)) for f, v, n in zip(ds.family.values, ds.value.values, ds.N.values)})
    for k, (f, v, n) in enumerate(groups):
        sel = (ds.family.values == f) & (ds.value.values == v) & (ds.N.values == n)
        for j, (name, marker) in enumerate((("z_once", "v"), ("z_twice", "^"), ("z_spectral", "o"))):
            vals = ds[name].values[sel]
            ax.errorbar(k + 0.2 * (j - 1), vals.mean(), yerr=vals.std(ddof=1) / np.sqrt(vals.size) if vals.size > 1 else 0,
                        fmt=marker, color=f"C{j}", capsize=2, label=name.replace("z_", "<z>, ") if k == 0 else None)
    ax.set_xticks(range(len(groups)), [f"{f}\n{v:g}, N={n}\n({int(np.sum((ds.family.values == f) & (ds.value.values == v) & (ds.N.values == n)))} packings)"
                                        for f, v, n in groups], fontsize=7)
    for level in (4.0, 6.0):
        ax.axhline(level, color="grey", ls=":", lw=0.8)
    ax.set_ylabel("<z> of Eq. 3 (dimensionless)")
    ax.set_xlabel("family, A (or dumbbell shaft length X), N (dimensionless)")
    ax.set_title(f"{ds.attrs.get('source', '')}: mean and standard error per group, P0 = "
                 f"{float(np.mean(ds.pressure.values)):.2g} k; identity N_c = N_c^0 - N_1 holds on "
                 f"{int(ds.identity.sum())} of {ds.sizes['packing']}", fontsize=8)
    ax.legend(fontsize=7)
    save_figure(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("study", choices=sorted(STUDIES))
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="default 1-5 (dumbbells 1-4)")
    ap.add_argument("--pressure", type=float, default=1e-9)
    ap.add_argument("--data", type=Path, default=OUT / "shapes_counting")
    ap.add_argument("--plot-only", action="store_true")
    args = ap.parse_args()
    out = OUT / f"shapes_counting_{args.study}.nc"
    if args.plot_only:
        plot(xr.load_dataset(out), out.with_suffix(".png"))
        return
    seeds = args.seeds or ([1, 2, 3, 4] if args.study == "dumbbells" else [1, 2, 3, 4, 5])
    args.data.mkdir(parents=True, exist_ok=True)
    rows = []
    for family, name, value, n, frozen in STUDIES[args.study]:
        for seed in seeds:
            packing, cpu = jammed(args.data, family, name, value, n, frozen, seed, args.pressure)
            rows.append(row(packing, family, value, seed, cpu))
            r = rows[-1]
            print(f"{family:13s} {value:<6g} N={n:<3d} seed {seed}: N_c once {r['n_contacts_once']:4d} twice "
                  f"{r['n_contacts_twice']:4d}  N_r {r['n_rattlers']} N_s {r['n_sliders']}  N_c^0 "
                  f"{r['isostatic_count']:4d}  N_1 {r['n_quartic']:3d}  N_c^0-N_1 {r['isostatic_count'] - r['n_quartic']:4d}"
                  f"  zero {r['n_zero']} (2+fN_r+N_s = {r['n_zero_expected']})  <z> {r['z_once']:.3f}/"
                  f"{r['z_twice']:.3f}/{r['z_spectral']:.3f}  {r['counting_contacts']}  near-aligned "
                  f"{r['near_aligned']}  phi {r['phi']:.5f}", flush=True)
    ds = dataset(rows, args.study, args.pressure)
    write_dataset(ds, out)
    plot(ds, out.with_suffix(".png"))
    print(f"identity N_c (twice) = N_c^0 - N_1 on {int(ds.identity.sum())} of {ds.sizes['packing']} packings; {out}")


if __name__ == "__main__":
    main()
