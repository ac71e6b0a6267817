"""Fourth derivatives of the energy along the quartic modes of near-disk ellipse packings (Fig. 11).

In the disk limit the quartic modes are rotations whose fourth derivative is ``~ k (alpha - 1)^2``:
1e-6 ... 1e-5 k at ``alpha - 1 = 1e-3`` and a hundred times less at ``1e-4``. For every region-1
mode of each packing: :func:`jamflow.shapes.spectrum.fourth_derivative_along` started from the
module's first step ``h`` and from ``4 h`` (each grows its step until two steps agree above the
round-off of ``v^T M v``); the plain central second difference of ``v^T M v`` on the exact line at
fixed steps ``h*`` and ``4 h*`` (``h*`` the smallest ``h 4^m`` whose round-off bound is below
``FOURTH_ROUNDOFF_RTOL`` of it and whose two differences agree to ``FOURTH_TARGET_RTOL``); and the
quartic coefficient of a fit of the energy itself (:func:`energy_quartic_fit`): finite, positive,
and the same under the change of step and method.

Writes ``benchmarks/output/shapes_fourth.nc`` and ``shapes_fourth.png`` and prints the numbers.

Usage: ``python benchmarks/shapes_fourth.py [PACKING.nc ...]`` (default: the vendored
``tests/data/shapes_ellipse_alpha1*_n16_p1e-7.nc``, ``alpha - 1 = 1e-3`` and ``1e-4``).
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
    FOURTH_DERIVATIVE_STEP,
    FOURTH_ROUNDOFF_RTOL,
    FOURTH_STEP_STABILITY_RTOL,
    FOURTH_TARGET_RTOL,
    contact_signature,
    energy_quartic_fit,
    exact_line,
    fourth_derivative_along,
    fourth_derivative_step,
    roundoff_of_form,
    spectrum,
)

ROOT = Path(__file__).resolve().parent
OUT = ROOT / "output"


def central(model, q, v, h) -> float:
    """Central second difference of ``v^T M(q + s v) v`` at step ``h`` (``q, v`` on an exact line for ``h``)."""
    f = [float(v @ (model.hessian(q + s * h * v) @ v)) for s in (-1.0, 0.0, 1.0)]
    return (f[0] - 2.0 * f[1] + f[2]) / h**2


def resolved_step(model, q, v, h, noise) -> float:
    """Smallest ``h 4^m`` whose central differences at it and half of it lie above round-off and agree."""
    step = h
    while step < FOURTH_DERIVATIVE_STEP:
        coarse, fine = central(model, q, v, step), central(model, q, v, step / 2)
        if 4.0 * noise / (step / 2) ** 2 <= FOURTH_ROUNDOFF_RTOL * abs(fine) and \
                abs(coarse - fine) <= FOURTH_TARGET_RTOL * abs(coarse):
            break
        step *= 4.0
    return step


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
        sig = lambda x: contact_signature(model, x)  # noqa: E731
        for k in np.flatnonzero(spec.region == 1):
            a, b = fourth_derivative_along(model, q, vec[:, k], h, sig), fourth_derivative_along(model, q, vec[:, k], 4 * h, sig)
            x, v, h2 = exact_line(q, vec[:, k], h)
            noise = roundoff_of_form(lambda y: float(v @ (model.hessian(y) @ v)), x)  # noqa: B023
            step = resolved_step(model, x, v, h2, noise)
            fit, fit_error, fit_lambda, window = energy_quartic_fit(model, q, vec[:, k], sig)
            rows.append(dict(source=path.name, alpha_minus_1=alpha - 1, mode=int(k), eigenvalue=float(lam[k]),
                             form_roundoff=noise, d4_from_h=a, d4_from_4h=b, rel_diff=abs(a - b) / abs(a), step=step,
                             d4_fixed=central(model, x, v, step), d4_fixed_4x=central(model, x, v, 4 * step),
                             d4_energy_fit=fit, d4_energy_fit_error=fit_error, energy_fit_window=window, first_step=h))
            r = rows[-1]
            print(f"{path.name} alpha-1 {alpha - 1:.0e} mode {k:2d} lambda {r['eigenvalue']:.3e} (round-off of "
                  f"v^T M v {noise:.1e}): d4 from h {a:.6e}, from 4h {b:.6e} (rel. diff {r['rel_diff']:.1e}); "
                  f"central at h* = {step:.1e}: {r['d4_fixed']:.6e}, at 4h*: {r['d4_fixed_4x']:.6e}; "
                  f"energy fit (|s| <= {window:.1e}): {fit:.6e} +- {fit_error:.1e}", flush=True)
    m = ("mode",)
    ds = xr.Dataset({k: (m, np.array([r[k] for r in rows]), {"units": "1", "long_name": k.replace("_", " ")})
                     for k in rows[0] if k != "source"},
                    coords={"source": (m, np.array([r["source"] for r in rows]))},
                    attrs=new_dataset_attrs("benchmarks/shapes_fourth.py", {"packings": [str(x) for x in args.packings]}))
    for k in ("eigenvalue", "form_roundoff", "d4_from_h", "d4_from_4h", "d4_fixed", "d4_fixed_4x", "d4_energy_fit",
              "d4_energy_fit_error"):
        ds[k].attrs.update(units="1", comment="k (energy / length^2 with unit diameter), along the unit mode")
    for k in ("step", "first_step", "energy_fit_window"):
        ds[k].attrs.update(units="1", comment="length (unit diameter) or rad, along the unit mode")
    write_dataset(ds, OUT / "shapes_fourth.nc")
    fig = Figure(layout="constrained", figsize=(10, 4.4))
    ax, bx = fig.subplots(1, 2)
    for a in sorted(set(ds.alpha_minus_1.values)):
        sel = ds.alpha_minus_1.values == a
        ref = ds.d4_from_h.values[sel]
        ax.loglog(ref, ds.d4_from_4h.values[sel], "o", mfc="none", label=f"alpha - 1 = {a:.0e}: from 4h")
        ax.loglog(ref, ds.d4_energy_fit.values[sel], "+", label=f"alpha - 1 = {a:.0e}: energy fit")
        lam = ds.eigenvalue.values[sel]
        bx.loglog(lam, ds.rel_diff.values[sel], "o", mfc="none", label=f"alpha - 1 = {a:.0e}: from 4h")
        bx.loglog(lam, np.abs(ds.d4_fixed_4x.values[sel] / ds.d4_fixed.values[sel] - 1), "x",
                  label=f"alpha - 1 = {a:.0e}: central, 4h* vs h*")
        bx.loglog(lam, np.abs(ds.d4_energy_fit.values[sel] / ref - 1), "+", label=f"alpha - 1 = {a:.0e}: energy fit")
    lim = [np.nanmin(ds.d4_from_h.values) / 2, np.nanmax(ds.d4_from_h.values) * 2]
    ax.plot(lim, lim, "k:", lw=0.8)
    ax.set_xlabel("d^4 U / ds^4 from the first step h [k]")
    ax.set_ylabel("d^4 U / ds^4, other estimate [k]")
    ax.legend(fontsize=7)
    bx.axhline(FOURTH_STEP_STABILITY_RTOL, color="k", ls=":", lw=0.8, label="FOURTH_STEP_STABILITY_RTOL")
    bx.set_xlabel("eigenvalue lambda of the mode [k]")
    bx.set_ylabel("relative difference to the estimate from h [1]")
    bx.set_ylim(top=1.0)
    bx.legend(fontsize=6, ncols=2, loc="upper center")
    save_figure(fig, OUT / "shapes_fourth.png")
    print(f"{OUT / 'shapes_fourth.nc'}: {len(rows)} modes, all finite and positive: "
          f"{bool(np.all(np.isfinite(ds.d4_from_h)) and np.all(ds.d4_from_h > 0))}; largest relative difference "
          f"from 4h {np.max(ds.rel_diff.values):.1e}, fixed 4h* vs h* "
          f"{np.max(np.abs(ds.d4_fixed_4x.values / ds.d4_fixed.values - 1)):.1e}, energy fit "
          f"{np.nanmax(np.abs(ds.d4_energy_fit.values / ds.d4_from_h.values - 1)):.1e}")


if __name__ == "__main__":
    main()
