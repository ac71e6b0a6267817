"""Every figure kind renders headless, is labelled, and is written as PNG and PDF."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_analysis_flow import flow_dataset

from jamflow import plots
from jamflow.analysis.flow import flow_summary
from jamflow.analysis.forces import force_distribution
from jamflow.analysis.gaps import gap_histogram
from jamflow.analysis.overlap import overlap_series
from jamflow.analysis.structure import structure_dataset
from jamflow.box import Box
from jamflow.io import write_dataset, write_packing
from jamflow.state.packing import Packing, near_pairs


def lattice(nx: int = 8, ny: int = 8, gamma: float = 0.0) -> Packing:
    x = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2] for j in range(ny) for i in range(nx)]) + 0.1
    box = Box.lees_edwards([nx, ny * np.sqrt(3) / 2], gamma)
    p = Packing(box.wrap(x + np.array([gamma * x[:, 1], np.zeros(len(x))]).T), np.ones(len(x)), box)
    pairs, _ = near_pairs(p, 1e-9)
    contacts = np.stack([pairs.i, pairs.j], axis=1)
    return p.evolve(contacts=contacts, force=np.linspace(0.1, 1.0, len(contacts)))


def check_figure(fig, path: Path) -> None:
    data_axes = [ax for ax in fig.axes if ax.has_data()]
    assert data_axes and all(ax.get_ylabel() for ax in data_axes), "every data axis needs a y label"
    assert any(ax.get_xlabel() for ax in data_axes), "shared x axes need a label on one of them"
    png, pdf = plots.save_figure(fig, path)
    assert png.stat().st_size > 5_000 and pdf.stat().st_size > 2_000


@pytest.mark.parametrize("gamma", [0.0, 0.3])
def test_packing_figure_2d(tmp_path, gamma):
    fig = plots.plot_packing(lattice(gamma=gamma))
    check_figure(fig, tmp_path / f"packing_{gamma}.png")
    assert (tmp_path / f"packing_{gamma}.pdf").exists()


def test_packing_figure_3d_slab(tmp_path, rng):
    x = rng.random((300, 3)) * 10.0
    check_figure(plots.plot_packing(Packing(x, np.full(300, 0.8), Box.cubic(3, 10.0))), tmp_path / "p3.png")


def test_distribution_figures(tmp_path, rng):
    h = [(1e-9 ** 0.6 + rng.random(3000) * (0.1 ** 0.6 - 1e-9 ** 0.6)) ** (1 / 0.6) for _ in range(3)]
    ds, summary = gap_histogram(h, [500] * 3, fit_min=1e-8, fit_max=1e-2)
    ds.attrs.update(summary)
    check_figure(plots.plot_gaps([ds], ["synthetic"]), tmp_path / "gaps.png")
    p = lattice(20, 20)
    fs = [p.evolve(force=rng.random(len(p.contacts))) for _ in range(3)]
    check_figure(plots.plot_forces(force_distribution(fs)), tmp_path / "forces.png")
    check_figure(plots.plot_rdf([structure_dataset(lattice(12, 12), 2.5, 100)]), tmp_path / "rdf.png")


def test_flow_and_overlap_figures(tmp_path, rng):
    s = np.linspace(0, 1, 501)
    ds = flow_dataset(s, 1 + 0.1 * rng.standard_normal(501), 5 + 0.1 * rng.standard_normal(501), [],
                      kappa=0.01 * rng.standard_normal(501), mode="shear_fixed_pressure")
    summary = flow_summary(ds)
    check_figure(plots.plot_stress_strain([ds, summary], ["raw", "summary"]), tmp_path / "ss.png")
    check_figure(plots.plot_phi_kappa(summary), tmp_path / "pk.png")
    p = lattice()
    series = [overlap_series([p.evolve(contacts=p.contacts[k:], force=None, attrs={"iterations": 10 - k}),
                              p.evolve(contacts=p.contacts[1:], force=None, attrs={"iterations": 3}),
                              p.evolve(attrs={"iterations": 2})],
                             [1e4, 1e6, 1e8], growth_rate=kappa) for k in (3, 5) for kappa in (1e-4, 1e-5)]
    fig = plots.plot_overlap_series(series)
    assert len(fig.axes) == 4, "phi_J, |Delta phi_J|, 1 - Q and n panels"
    assert all(len(ax.get_legend().get_texts()) == 2 for ax in fig.axes), "one curve per growth rate"
    check_figure(fig, tmp_path / "q.png")


def test_plot_cli(tmp_path):
    from jamflow.cli import main

    write_packing(lattice(), tmp_path / "p.nc")
    assert main(["plot", "packing", str(tmp_path / "p.nc"), str(tmp_path / "fig.png")]) == 0
    assert (tmp_path / "fig.png").exists() and (tmp_path / "fig.pdf").exists()
    s = np.linspace(0, 1, 101)
    write_dataset(flow_dataset(s, np.ones(101), np.ones(101), []), tmp_path / "run.nc")
    assert main(["plot", "phi-kappa", str(tmp_path / "run.nc"), str(tmp_path / "pk.png")]) == 0
    assert main(["plot", "forces", str(tmp_path / "p.nc"), str(tmp_path / "x.nc"), str(tmp_path / "f.png")]) == 1


def test_a_walled_packing_s_title_counts_its_contacts_as_the_tables_do():
    # the drawn sphere-sphere contacts and the N_c of the tables (wall contacts included)
    from jamflow.io import read_packing

    p = read_packing(Path(__file__).parent / "data" / "bodies" / "walls_hard.nc", None)
    title = " ".join(plots.plot_packing(p).axes[0].get_title().split())
    assert f"{len(p.contacts)} sphere-sphere contacts (wall contacts not drawn; N_c with them " \
           f"{p.attrs['n_contacts']})" in title
    assert p.attrs["n_contacts"] > len(p.contacts)
