"""phi_J and <z> against asphericity (Figs. 5, 8) and P(psi) datasets (Fig. 14): disk limits and normalisation."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jamflow.io import read_dataset, read_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.shapes.analysis import contact_angle_dataset, contact_angles
from jamflow.shapes.counting import count_constraints
from jamflow.shapes.survey import survey_dataset, survey_row
from jamflow.state.packing import Packing

DATA = Path(__file__).parent / "data"
NEAR_DISKS = DATA / "shapes_ellipse_alpha1.001_n16_p1e-7.nc"  # A - 1 = 3.7e-7, P0 = 1e-7
LINES = DATA / "shapes_circulo_line_a1.1_n16_p1e-6.nc"
ALPHA_MINUS_1 = 1e-3


def _disks_like(q: Packing) -> Packing:
    """Bidisperse disks of the bodies' areas at the bodies' centres."""
    return Packing(position=q.position, diameter=2.0 * np.sqrt(q.shapes.area[q.shape_index] / np.pi), box=q.box)


def test_near_disk_contact_angles_are_the_radial_direction():
    # for disks the contact point lies on the line of centres: psi is the angle between the
    # body axis and the bond, up to the contact point's offset O(alpha - 1)
    q = read_packing(NEAR_DISKS, None)
    _, rattler, _, cs = count_constraints(q)
    live = ~(rattler[cs.i] | rattler[cs.j])
    bond = cs.separation[live] / np.linalg.norm(cs.separation[live], axis=1)[:, None]
    expected = []
    for body in (cs.i[live], cs.j[live]):
        axis = np.stack([np.cos(q.orientation[body]), np.sin(q.orientation[body])], axis=1)
        expected.append(np.arccos(np.clip(np.abs(np.sum(axis * bond, axis=1)), 0.0, 1.0)))
    psi = contact_angles(q)
    assert psi.size == 2 * 27
    np.testing.assert_allclose(psi, np.concatenate(expected), atol=2 * ALPHA_MINUS_1)


def test_contact_angle_density_is_normalised_with_counting_errors():
    ds = contact_angle_dataset([read_packing(LINES, None)], "twice", bins=9)
    width = 0.5 * np.pi / 9
    assert float(ds.P_psi.sum()) * width == pytest.approx(1.0, rel=1e-12)
    assert int(ds["count"].sum()) == ds.attrs["n_angles"] == 2 * 45
    np.testing.assert_allclose(ds.P_psi_err * ds.attrs["n_angles"] * width, np.sqrt(ds["count"]), rtol=1e-9)


def test_disk_limit_of_phi_j_and_z_matches_the_sphere_code():
    # the sphere code jams disks of the same areas from the near-disk ellipse packing at the
    # same P0: the same contact network and <z> = 4, phi_J within the contact-distance
    # difference of alpha = 1.001 ellipses and disks (relative O(alpha - 1))
    q = read_packing(NEAR_DISKS, None)
    disks = jam_to_pressure(_disks_like(q), 1e-7).packing
    ellipses, disk = survey_row(q), survey_row(disks)
    assert disk["family"] == "disk" and disk["counting"] == "isostatic"
    assert disk["z"] == ellipses["z"] == 4.0
    assert disk["n_contacts"] == ellipses["n_contacts"] and disk["n_rattlers"] == ellipses["n_rattlers"]
    assert abs(disk["phi_J"] - ellipses["phi_J"]) < 2 * ALPHA_MINUS_1
    _, rattler, _, cs = count_constraints(q)
    live = ~(rattler[cs.i] | rattler[cs.j])
    assert set(map(tuple, cs.pairs[live])) <= set(map(tuple, np.sort(disks.contacts, axis=1)))


def test_survey_groups_means_and_errors():
    q, lines = read_packing(NEAR_DISKS, None), read_packing(LINES, None)
    rows = [survey_row(q), survey_row(lines), survey_row(lines)]
    ds = survey_dataset(rows, ["a", "b", "c"])
    assert list(ds.group_family.values) == ["circulo_line", "ellipse"]
    assert list(ds.n_packings.values) == [2, 1]
    assert ds.phi_J_mean.values[0] == pytest.approx(lines.packing_fraction)
    assert ds.z_sem.values[0] == 0.0
    # Eq. 3 with the counts of the packing: <z> = 2 (N_c + 1) / (N - N_r - N_s / 3)
    r = rows[1]
    assert r["z"] == pytest.approx(2 * (r["n_contacts"] + 1) / (r["N"] - r["n_rattlers"] - r["n_sliders"] / 3))


def test_shape_survey_and_contact_angles_commands(tmp_path):
    out = tmp_path / "survey.nc"
    run = subprocess.run([sys.executable, "-m", "jamflow", "shape-survey", str(NEAR_DISKS), str(LINES), str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "phi_J 0.83631" in run.stdout and "<z> 4.0000" in run.stdout
    assert read_dataset(out, "shape-survey").sizes["group"] == 2
    angles = tmp_path / "angles.nc"
    run = subprocess.run([sys.executable, "-m", "jamflow", "contact-angles", str(LINES), str(angles)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert read_dataset(angles, "contact-angles").attrs["n_angles"] == 2 * 40
    bad = subprocess.run([sys.executable, "-m", "jamflow", "contact-angles", str(angles)],
                         capture_output=True, text=True)
    assert bad.returncode != 0 and "at least one input" in bad.stderr


def test_reuleaux_rows_are_counted_from_their_contact_points():
    from jamflow.shapes.generation import (
        bidisperse_shapes,
        random_shape_packing,
        unit_shape,
    )

    p = random_shape_packing(bidisperse_shapes(unit_shape("reuleaux", None, None, None)), 8, 0.3, 1)
    row = survey_row(p)
    c, _, _, _ = count_constraints(p, "once")
    assert row["family"] == "reuleaux" and row["phi_J"] == pytest.approx(0.3)
    assert (row["n_contacts"], row["n_rattlers"]) == (c.n_contacts, c.n_rattlers)
    # a dilute non-overlapping start touches nowhere: every body rattles
    assert (row["n_contacts"], row["n_rattlers"]) == (0, 8)
    assert row["asphericity"] == pytest.approx(np.pi / (2 * (np.pi - np.sqrt(3))), rel=1e-12)
