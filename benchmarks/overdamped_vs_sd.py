"""Event-driven overdamped shear against Lerner et al.'s steepest-descent protocol (Sec. V A 1, Fig. 6).

From one N = 100 bidisperse (1 : 1.4, 3 % polydisperse) 2D configuration brought to phi = 0.82 by
the event-driven compression, shear by (a) the event-driven dynamics and (b) strain steps followed
by steepest descent of the soft potential of Eq. 32 with stress from hard-sphere forces on the
tentative network (``jamflow.protocols.quasistatic.lerner_sd_shear``). Prints the stress agreement and the
running times, writes ``benchmarks/output/overdamped_vs_sd.nc`` and ``.png``.

With ``--sd-strain W`` (< ``--strain``) steepest descent runs only over the first W of strain and its
time is extrapolated linearly to ``--strain`` (SD's cost per strain step does not trend with strain in
steady flow; the window's own stress agreement is reported). The paper's comparison: ``--sd-step 1e-6``.

Usage: python benchmarks/overdamped_vs_sd.py [--strain 0.3] [--sd-step 1e-4] [--n 100] [--sd-strain W]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import xarray as xr

from jamflow.box import Box
from jamflow.io import new_dataset_attrs, write_dataset
from jamflow.protocols.initial import random_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, length_unit, run_flow
from jamflow.state.packing import Packing

OUT = Path(__file__).resolve().parent / "output"


def prepare(n: int, phi: float, seed: int) -> Packing:
    """RSA at phi = 0.5, then event-driven compression stopped exactly at ``phi``."""
    p = random_packing(n, 2, 0.5, "bi", seed=seed)
    rng = np.random.default_rng(seed)
    p = p.evolve(diameter=p.diameter * (1 - 0.03 * rng.uniform(size=p.n)))
    res = run_flow(p, Drive("compress"), Stop(packing_fraction=phi),
                   FlowOptions(dt_max=1e-2, step_drift=1e-7, drift_tol=1e-6), unit="small_diameter",
                   record_every=1000)
    if res.jammed:
        raise RuntimeError("jammed before the target packing fraction; choose another seed")
    return res.final


def in_lambda_units(p: Packing) -> Packing:
    lam = length_unit(p.diameter, "small_diameter")
    return Packing(position=p.position / lam, diameter=p.diameter / lam, box=Box(p.box.matrix / lam),
                   protocol=p.protocol, seed=p.seed)


def compare(ed: xr.Dataset, sd: xr.Dataset) -> dict[str, float]:
    """Event-driven stress interpolated at the SD strains (right-continuous: the post-collision value)."""
    g_ed = ed.strain.values
    s_ed = ed.shear_stress.values
    g_sd = sd.strain.values
    idx = np.searchsorted(g_ed, g_sd, side="right") - 1
    s_at = s_ed[np.clip(idx, 0, len(s_ed) - 1)]
    s_sd = sd.shear_stress.values
    rel = np.abs(s_sd - s_at) / np.maximum(np.abs(s_at), 1e-12)
    return {"median_rel_diff": float(np.median(rel)), "p90_rel_diff": float(np.quantile(rel, 0.9)),
            "corr": float(np.corrcoef(s_sd, s_at)[0, 1]), "mean_stress_ed": float(np.mean(s_at)),
            "mean_stress_sd": float(np.mean(s_sd))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--phi", type=float, default=0.82)
    ap.add_argument("--strain", type=float, default=0.3)
    ap.add_argument("--sd-step", type=float, default=1e-4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sd-strain", type=float, help="strain window of the SD run (time extrapolated to --strain)")
    ap.add_argument("--order", type=int, default=FlowOptions().order, help="FlowOptions.order of the event-driven run")
    ap.add_argument("--step-drift", type=float, default=FlowOptions().step_drift)
    args = ap.parse_args()
    sd_strain = args.strain if args.sd_strain is None else args.sd_strain
    from jamflow.protocols.quasistatic import lerner_sd_shear

    start = prepare(args.n, args.phi, args.seed)
    t0 = time.perf_counter()
    ed = run_flow(start, Drive("shear"), Stop(strain=args.strain),
                  FlowOptions(order=args.order, step_drift=args.step_drift), unit="small_diameter").series
    t_ed = time.perf_counter() - t0
    t0 = time.perf_counter()
    sd = lerner_sd_shear(in_lambda_units(start), sd_strain, step=args.sd_step)
    t_sd = (time.perf_counter() - t0) * args.strain / sd_strain
    stats = compare(ed, sd)
    print(f"N={args.n} phi={args.phi} strain={args.strain} SD step={args.sd_step:g} (SD measured over strain {sd_strain:g}"
          f"{', time extrapolated' if sd_strain < args.strain else ''}); ED order {args.order}, step_drift {args.step_drift:g}")
    print(f"event-driven: {t_ed:.1f} s, {ed.sizes['event']} events; steepest descent: {t_sd:.1f} s; "
          f"time ratio SD/ED = {t_sd / t_ed:.2f}")
    print("agreement:", {k: round(v, 4) for k, v in stats.items()})
    OUT.mkdir(exist_ok=True)
    ds = xr.Dataset(
        {"ed_shear_stress": (("ed_step",), ed.shear_stress.values, {"units": "1", "long_name": "event-driven shear stress"}),
         "ed_strain": (("ed_step",), ed.strain.values, {"units": "1", "long_name": "event-driven strain"}),
         "sd_shear_stress": (("sd_step",), sd.shear_stress.values, {"units": "1", "long_name": "steepest-descent shear stress"}),
         "sd_strain": (("sd_step",), sd.strain.values, {"units": "1", "long_name": "steepest-descent strain"})},
        attrs=new_dataset_attrs("overdamped vs steepest descent", vars(args), time_ed=t_ed, time_sd=t_sd,
                                sd_strain=sd_strain, **stats))
    write_dataset(ds, OUT / "overdamped_vs_sd.nc")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(ed.strain, ed.shear_stress, lw=0.8, label="event-driven")
    ax.plot(sd.strain, sd.shear_stress, lw=0.8, ls="--", label=f"steepest descent, dγ={args.sd_step:g}")
    ax.set_xlabel("strain γ")
    ax.set_ylabel("shear stress σ [λγ̇/ξ0]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "overdamped_vs_sd.png", dpi=150)


if __name__ == "__main__":
    main()
