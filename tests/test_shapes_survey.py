"""phi_J and <z> against asphericity (Figs. 5, 6, 8) and P(psi) datasets (Fig. 14): disk limits,
the three contact conventions, refusal of unjammed starts, normalisation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.cli import main
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
    e, d = ellipses["counts"]["once"], disk["counts"]["once"]
    assert disk["family"] == "disk" and d["n_contacts"] == d["isostatic_count"]
    assert d["z_eq3"] == e["z_eq3"] == 4.0
    # z = 2 N_c / N' is 4 - 2 / N' for an isostatic disk backbone (N_c = 2 N' - 1)
    assert d["z_contacts"] == pytest.approx(4.0 - 2.0 / (q.n - d["n_rattlers"]), rel=1e-15)
    assert d["n_contacts"] == e["n_contacts"] and d["n_rattlers"] == e["n_rattlers"]
    assert abs(disk["phi_J"] - ellipses["phi_J"]) < 2 * ALPHA_MINUS_1
    _, rattler, _, cs = count_constraints(q)
    live = ~(rattler[cs.i] | rattler[cs.j])
    assert set(map(tuple, cs.pairs[live])) <= set(map(tuple, np.sort(disks.contacts, axis=1)))


def test_survey_groups_means_and_errors():
    q, lines = read_packing(NEAR_DISKS, None), read_packing(LINES, None)
    rows = [survey_row(q, spectral=True), survey_row(lines, spectral=True), survey_row(lines, spectral=True)]
    ds = survey_dataset(rows, ["a", "b", "c"])
    assert list(ds.group_family.values) == ["circulo_line", "ellipse"]
    assert list(ds.n_packings.values) == [2, 1]
    assert ds.phi_J_mean.values[0] == pytest.approx(lines.packing_fraction)
    assert list(ds.convention.values) == ["once", "twice", "spectral"]
    assert np.all(ds.z_eq3_sem.values[0] == 0.0)
    for r in rows:
        for c in ("once", "twice", "spectral"):
            n = r["counts"][c]
            # Eq. 3 with the counts of the packing: <z> = 2 (N_c + 1) / (N - N_r - N_s / 3)
            assert n["z_eq3"] == pytest.approx(2 * (n["n_contacts"] + 1) / (r["N"] - n["n_rattlers"] - n["n_sliders"] / 3))
            assert n["z_contacts"] == pytest.approx(2 * n["n_contacts"] / (r["N"] - n["n_rattlers"]))
        # the spectral count N_c^0 - N_1 equals the contacts counted twice on both packings (Sec. III B)
        assert r["counts"]["spectral"]["n_contacts"] == r["counts"]["twice"]["n_contacts"]
    # the circulo-lines have parallel contacts: counted once they are fewer
    assert rows[1]["counts"]["once"]["n_contacts"] < rows[1]["counts"]["twice"]["n_contacts"]
    k = list(ds.convention.values).index("spectral")
    assert ds.z_eq3_mean.values[0, k] == pytest.approx(rows[1]["counts"]["spectral"]["z_eq3"])


def test_shape_survey_and_contact_angles_commands(tmp_path, capsys):
    out = tmp_path / "survey.nc"
    assert main(["shape-survey", str(NEAR_DISKS), str(LINES), str(out)]) == 0
    printed = capsys.readouterr().out
    assert "phi_J 0.83631" in printed and "4.0000 ± 0.0000 / 4.0000 ± 0.0000" in printed
    assert "z = 2 N_c / N' once/twice" in printed
    ds = read_dataset(out, "shape-survey")
    assert ds.sizes["group"] == 2 and np.all(np.isnan(ds.z_eq3.sel(convention="spectral").values))
    angles = tmp_path / "angles.nc"
    assert main(["contact-angles", str(LINES), str(angles)]) == 0
    assert read_dataset(angles, "contact-angles").attrs["n_angles"] == 2 * 40
    capsys.readouterr()
    assert main(["contact-angles", str(angles)]) != 0
    assert "at least one shape packing" in capsys.readouterr().err


def test_survey_and_modes_refuse_unjammed_starts(tmp_path, capsys):
    """A random start (init-shapes) is refused in one line before any work, never counted
    as a packing with every body a rattler at the start's packing fraction."""
    from jamflow.io import write_packing
    from jamflow.shapes.generation import (
        bidisperse_shapes,
        random_shape_packing,
        unit_shape,
    )

    p = random_shape_packing(bidisperse_shapes(unit_shape("reuleaux", None, None, None)), 8, 0.3, 1)
    with pytest.raises(ValueError, match="not jammed by soft-jam"):
        survey_row(p)
    start = tmp_path / "start.nc"
    write_packing(p, start)
    for command in (["shape-survey", str(start), str(tmp_path / "s.nc")], ["modes", str(start), str(tmp_path / "m.nc")]):
        assert main(command) == 1
        err = capsys.readouterr().err
        assert "not jammed by soft-jam" in err and "lambda" not in err
        assert len(err.strip().splitlines()) == 1
        assert not Path(command[-1]).exists()


def test_a_jammed_packing_without_backbone_is_left_out_of_the_means():
    lines = read_packing(LINES, None)
    # the same packing with its box doubled: nothing touches, yet it carries the soft-jam history
    far = lines.evolve(position=2.0 * lines.position, box=lines.box.scaled(2.0))
    rows = [survey_row(lines), survey_row(far)]
    assert rows[1]["jammed"] == 0 and "rattler" in rows[1]["status"]
    ds = survey_dataset(rows, ["jammed", "apart"])
    assert ds.n_packings.values.tolist() == [1] and ds.n_excluded.values.tolist() == [1]
    assert ds.phi_J_mean.values[0] == pytest.approx(lines.packing_fraction)
