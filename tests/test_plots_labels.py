"""Every figure kind of ``jamflow plot`` labels every axis with a quantity and a unit.

The check lives in :func:`jamflow.plots.save_figure` (a figure with an unlabelled axis
is not written); here every kind is drawn on small synthetic inputs and rendered.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from matplotlib.figure import Figure
from test_analysis_eos import eos_run, series
from test_analysis_flow import flow_dataset
from test_plots import lattice

from jamflow import plots
from jamflow.analysis.eos import jamming_table
from jamflow.analysis.flow import flow_curve, flow_summary
from jamflow.analysis.forces import force_distribution
from jamflow.analysis.gaps import gap_histogram
from jamflow.analysis.overlap import overlap_series
from jamflow.analysis.structure import structure_dataset
from jamflow.chains.averages import moduli_against_links
from jamflow.chains.figures import plot_mode
from jamflow.chains.modes import linked_modes, modes_dataset
from jamflow.cli.analysis import PLOT_KINDS
from jamflow.io import read_dataset, read_packing
from jamflow.shapes import figures as shape_figures
from jamflow.shapes.survey import survey_dataset

KINDS = Path(__file__).parent / "data" / "kinds"


def _gaps(rng) -> xr.Dataset:
    h = [(1e-9 ** 0.6 + rng.random(3000) * (0.1 ** 0.6 - 1e-9 ** 0.6)) ** (1 / 0.6) for _ in range(3)]
    ds, summary = gap_histogram(h, [500] * 3, fit_min=1e-8, fit_max=1e-2, n_boot=20)
    ds.attrs.update(summary)
    return ds


def _forces(rng) -> xr.Dataset:
    p = lattice(20, 20)
    return force_distribution([p.evolve(force=rng.random(len(p.contacts))) for _ in range(3)], n_boot=20)


def _modes(rng, pressure: float) -> xr.Dataset:
    lam = np.sort(np.concatenate([[0.0, 0.0], pressure * rng.random(4), 1e-2 + rng.random(42)]))
    region = np.array([0, 0] + [1] * 4 + [2] * 20 + [3] * 22)
    d4 = np.where(region == 1, rng.random(48), np.nan)
    return xr.Dataset({"eigenvalue": ("mode", lam), "region": ("mode", region), "fourth_derivative": ("mode", d4),
                       "rotational_weight": ("mode", rng.random(48))},
                      attrs={"pressure": pressure, "n_quartic": 4, "lambda_c": 1e-3, "lambda_0": 1e-14, "N": 16,
                             "isostatic_count": 47, "n_contacts_twice": 43, "family": "circulo_line",
                             "asphericity": 1.1})


def _shape_figures(rng) -> dict[str, Figure]:
    def counts():
        return dict(n_contacts=40, n_rattlers=1, n_sliders=0, isostatic_count=44, z_contacts=4.4 + rng.random(),
                    z_eq3=4.5 + rng.random())

    rows = [dict(family=f, asphericity=a, N=16, phi_J=0.85 + 0.01 * rng.random(), pressure=1e-6, jammed=1,
                 status="jammed", n_quartic=4, counts={c: counts() for c in ("once", "twice", "spectral")})
            for f, a in [("disk", 1.0), ("ellipse", 1.01), ("ellipse", 1.01), ("circulo_line", 1.1)]]
    survey = survey_dataset(rows, ["a", "b", "c", "d"])
    angles = xr.Dataset({"P_psi": ("bin", 2 / np.pi * np.ones(9)), "P_psi_err": ("bin", 0.1 * np.ones(9))},
                        coords={"psi": ("bin", (np.arange(9) + 0.5) * np.pi / 18)},
                        attrs={"family": "ellipse", "asphericity": 1.01, "N": 16, "n_packings": 2, "n_angles": 90})
    return {
        "phi-asphericity": shape_figures.plot_survey(survey, "phi_J"),
        "z-asphericity": shape_figures.plot_survey(survey, "z"),
        "contact-angles": shape_figures.plot_contact_angles([angles]),
        "spectra": shape_figures.plot_spectra([_modes(rng, 1e-6), _modes(rng, 1e-5)], ["a", "b"]),
        "quartic-pressure": shape_figures.plot_quartic_pressure([_modes(rng, 1e-6), _modes(rng, 1e-5)]),
        "feasible-region": shape_figures.plot_feasible_region(read_dataset(KINDS / "feasible-region.nc")),
    }


def _figures(rng) -> dict[str, Figure]:
    s = np.linspace(0, 1, 201)
    run = flow_dataset(s, 1 + 0.1 * rng.standard_normal(201), 5 + 0.1 * rng.standard_normal(201), [],
                       kappa=0.01 * rng.standard_normal(201), mode="shear_fixed_pressure")
    run["shear_stress"].attrs["units"] = "gamma_dot / xi0"
    slower = flow_dataset(s, 15 + rng.standard_normal(201), 50 + rng.standard_normal(201), [],
                          kappa=0.01 * rng.standard_normal(201), mode="shear_fixed_pressure")
    p = lattice()
    overlaps = [overlap_series([p.evolve(contacts=p.contacts[3:], force=None, attrs={"iterations": 4}), p],
                               [1e4, 1e8], growth_rate=1e-4)]
    eos = [eos_run(0.643, 3, rng, 1e-4), eos_run(0.644, 3, rng, 1e-4)]
    table = jamming_table([series([0.643, 0.643], 1e-4), series([0.644, 0.644], 1e-4)], eos)
    tradeoff = xr.Dataset({"time": ("setting", [1.0, 2.0, 4.0]), "err": ("setting", [1e-3, 1e-6, 0.0]),
                           "on_front": ("setting", [True, True, True]),
                           "is_reference": ("setting", [False, False, True])},
                          coords={"label": ("setting", ["a", "b", "ref"])},
                          attrs={"primary_error": "err", "stage": "synthetic"})
    gaps, forces = _gaps(rng), _forces(rng)
    swing = read_packing(Path(__file__).parent / "data" / "bodies" / "swinging_trimer_2d.nc", None)
    cemented = [xr.Dataset({f"{m}_{b}": ((), v) for m in ("bulk", "shear") for b, v in
                            (("voigt", 2.0 + k + rng.random()), ("reuss", 1.0 + k + rng.random()))},
                           attrs={"N": 64, "n_cemented": 8 * k, "d": 3, "n_unstable": 0}) for k in range(3) for _ in range(2)]
    return {
        "packing": plots.plot_packing(p),
        "gaps": plots.plot_gaps([gaps], ["synthetic"]),
        "forces": plots.plot_forces(forces),
        "fit-windows": plots.plot_fit_windows(gaps),
        "rdf": plots.plot_rdf([structure_dataset(lattice(12, 12), 2.5, 100)]),
        "stress-strain": plots.plot_stress_strain([run, flow_summary(run)]),
        "phi-kappa": plots.plot_phi_kappa(flow_summary(run)),
        "flow-curve": plots.plot_flow_curve(flow_curve([flow_summary(run), flow_summary(slower)], ["p5", "p50"])),
        "overlap": plots.plot_overlap_series(overlaps),
        "pareto": plots.pareto(tradeoff),
        "jamming-table": plots.plot_jamming_table(table),
        "eos": plots.plot_eos(eos),
        "chains-moduli": plots.plot_chains_moduli(moduli_against_links(cemented)),
        "mode": plot_mode(swing, modes_dataset(linked_modes(swing), swing)),
        "fit-windows (forces)": plots.plot_fit_windows(forces),
        **_shape_figures(rng),
    }


def test_every_plot_kind_labels_every_axis_with_a_unit(tmp_path, rng):
    figures = _figures(rng)
    assert set(PLOT_KINDS) <= set(figures), "a plot kind without a label test"
    for kind, fig in figures.items():
        assert plots.unlabelled_axes(fig) == [], kind
        # rendering lays out every label (a mathtext error shows only here); a coarse PNG in
        # memory costs a third of save_figure's PNG and PDF, which the first kind still takes
        png = io.BytesIO()
        fig.savefig(png, format="png", dpi=72)
        assert png.tell() > 5_000, kind
    png, pdf = plots.save_figure(next(iter(figures.values())), tmp_path / "first.png")
    assert png.stat().st_size > 5_000 and pdf.stat().st_size > 5_000


def test_stress_axis_carries_the_stage_unit(rng):
    s = np.linspace(0, 1, 51)
    run = flow_dataset(s, np.ones(51), np.ones(51), [])
    run["shear_stress"].attrs["units"] = "epsilon / length^2"
    fig = plots.plot_stress_strain([run])
    assert "[epsilon / length^2]" in fig.axes[0].get_ylabel()


@pytest.mark.parametrize("xlabel, ylabel", [("", "y (dimensionless)"), ("time [s]", ""), ("time", "y [m]")])
def test_save_refuses_a_figure_without_unit_labels(tmp_path, xlabel, ylabel):
    fig = Figure()
    ax = fig.add_subplot()
    ax.plot([1, 2], [1, 2])
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    with pytest.raises(ValueError, match="no quantity with a unit"):
        plots.save_figure(fig, tmp_path / "bad.png")
    assert not (tmp_path / "bad.png").exists()
