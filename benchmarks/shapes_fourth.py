"""Fourth derivatives of the energy along the quartic modes of near-disk ellipse packings (Fig. 11).

In the disk limit the quartic modes are rotations whose fourth derivative is ``~ k (alpha - 1)^2``:
1e-6 ... 1e-5 k at ``alpha - 1 = 1e-3`` and a hundred times less at ``1e-4``. For every region-1
mode of each packing: :func:`jamflow.shapes.spectrum.fourth_derivative_along` started from the
module's first step ``h`` and from ``4 h`` (each grows its step until two steps agree), and the
plain central second difference of ``v^T M v`` at fixed steps ``h*`` and ``4 h*`` (``h*`` the step
the first run accepted): finite, positive, and the same under the change of step.

Writes ``benchmarks/output/shapes_fourth.nc`` and ``shapes_fourth.png`` and prints the numbers.

Usage: ``python benchmarks/shapes_fourth.py PACKING.nc ...`` (default: the vendored
``tests/data/shapes_ellipse_alpha1*_n16_p1e-7.nc``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np
import xarray as xr
from matplotlib.figure import Figure

from jamflow.io import new_dataset_attrs, read_packing, write_dataset
from jamflow.plots import save_figure
from jamflow.shapes.counting import shape_model_of
from jamflow.shapes.spectrum import (
    contact_signature,
    fourth_derivative_along,
    fourth_derivative_step,
    spectrum,
)

ROOT = Path(__file__).resolve().parent
OUT = ROOT / "output"


def central(model, q, v, h) -> float:
    """Central second difference of ``v^T M(q + s v) v`` at step ``h``."""
    f = [float(v @ (model.hessian(q + s * h * v) @ v)) for s in (-1.0, 0.0, 1.0)]
    return (f[0] - 2.0 * f[1] + f[2]) / h**2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packings", nargs="*", type=Path,
                    default=sorted((ROOT.parent / "tests" / "data").glob("shapes_ellipse_alpha1*_n16_p1e-7.nc")))
    args = ap.parse_args()
    rows = []
    for path in args.packings:
        p = read_packing(path, None)
        spec = spectrum(p, fourth=False)
        model, q = shape_model_of(p)
        lam, vec = np.linalg.eigh(model.hessian(q).toarray())
        energy = model.pair_table(q)["energy"]
        h = fourth_derivative_step(float(np.sqrt(2.0 * energy.min() / model.k)))
        alpha = float(p.shapes.semi_axes[0, 0] / p.shapes.semi_axes[0, 1])
        for k in np.flatnonzero(spec.region == 1):
            v = vec[:, k]
            sig = lambda x: contact_signature(model, x)  # noqa: E731
            a, b = fourth_derivative_along(model, q, v, h, sig), fourth_derivative_along(model, q, v, 4 * h, sig)
            # the step the first run accepted: the smallest h 4^m whose two differences agree to 1e-3
            step = h
            while step < 1e-2 and abs(central(model, q, v, step) - central(model, q, v, step / 2)) > \
                    1e-3 * abs(central(model, q, v, step)):
                step *= 4
            rows.append(dict(source=path.name, alpha_minus_1=alpha - 1, mode=int(k), eigenvalue=float(lam[k]),
                             d4_from_h=a, d4_from_4h=b, step=step, d4_fixed=central(model, q, v, step),
                             d4_fixed_4x=central(model, q, v, 4 * step), first_step=h))
            r = rows[-1]
            print(f"{path.name} alpha-1 {alpha - 1:.0e} mode {k:2d} lambda {r['eigenvalue']:.3e}: d4 from h "
                  f"{a:.6e}, from 4h {b:.6e} (rel. diff {abs(a - b) / abs(a):.1e}); central at h* = {step:.1e}: "
                  f"{r['d4_fixed']:.6e}, at 4h*: {r['d4_fixed_4x']:.6e}", flush=True)
    m = ("mode",)
    ds = xr.Dataset({k: (m, np.array([r[k] for r in rows]), {"units": "1", "long_name": k.replace("_", " ")})
                     for k in rows[0] if k != "source"},
                    coords={"source": (m, np.array([r["source"] for r in rows]))},
                    attrs=new_dataset_attrs("benchmarks/shapes_fourth.py", {"packings": [str(x) for x in args.packings]}))
    for k in ("d4_from_h", "d4_from_4h", "d4_fixed", "d4_fixed_4x"):
        ds[k].attrs.update(units="1", comment="k (energy / length^2 with unit diameter), along the unit mode")
    write_dataset(ds, OUT / "shapes_fourth.nc")
    fig = Figure(layout="constrained", figsize=(5.6, 4.6))
    ax = fig.add_subplot()
    for a in sorted(set(ds.alpha_minus_1.values)):
        sel = ds.alpha_minus_1.values == a
        ax.loglog(ds.d4_from_h.values[sel], ds.d4_from_4h.values[sel], "o", label=f"alpha - 1 = {a:.0e} (from h vs 4h)")
        ax.loglog(ds.d4_fixed.values[sel], ds.d4_fixed_4x.values[sel], "x", label=f"alpha - 1 = {a:.0e} (fixed h* vs 4h*)")
    lim = [np.nanmin(ds.d4_from_h.values) / 2, np.nanmax(ds.d4_from_h.values) * 2]
    ax.plot(lim, lim, "k:", lw=0.8)
    ax.set_xlabel("d^4 U / ds^4 at the first step [k]")
    ax.set_ylabel("d^4 U / ds^4 at 4 times the step [k]")
    ax.legend(fontsize=7)
    save_figure(fig, OUT / "shapes_fourth.png")
    print(f"{OUT / 'shapes_fourth.nc'}: {len(rows)} modes, all finite and positive: "
          f"{bool(np.all(np.isfinite(ds.d4_from_h)) and np.all(ds.d4_from_h > 0))}")


if __name__ == "__main__":
    main()
