"""Asymmetric dimers (van der Werf et al. Sec. II, Table I, Fig. 3b) as rigid two-sphere clusters."""

from __future__ import annotations

import json
from math import acos, pi, sqrt

import numpy as np
import pytest
from scipy.integrate import quad
from shapely.geometry import Point
from shapely.ops import unary_union

from jamflow.chains.builders import linked_packing
from jamflow.chains.dimers import (
    dimer_aspect_ratio,
    dimer_asphericity,
    dimer_perimeter_area,
)
from jamflow.chains.hessian import constrained_hessian
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.network import count_bodies
from jamflow.state.bodies import Links
from jamflow.state.packing import lens_volume, linked_volume, sphere_volume

#: Segments per quarter circle of the shapely reference: its polygon perimeter and area
#: are below the circle's by ~(pi / 2 / 4096)^2 / 6 ~ 2.5e-8 relative.
QUAD_SEGS = 4096


def _union(r1: float, r2: float, l: float):
    return Point(0.0, 0.0).buffer(r1, quad_segs=QUAD_SEGS).union(Point(l, 0.0).buffer(r2, quad_segs=QUAD_SEGS))


@pytest.mark.parametrize("r1, r2, l", [(0.5, 0.7, 1.0), (0.5, 0.5, 0.3), (0.5, 0.9, 0.45), (0.5, 0.7, 1.2),
                                       (1.0, 3.0, 2.5)])
def test_dimer_perimeter_and_area_match_the_polygon_union(r1, r2, l):
    p, a = dimer_perimeter_area(r1, r2, l)
    ref = _union(r1, r2, l)
    assert p == pytest.approx(ref.length, rel=1e-7)
    assert a == pytest.approx(ref.area, rel=1e-7)


def test_the_papers_dimer_has_the_table_I_aspect_ratio_and_asphericity():
    # Table I: alpha - 1 = 0.571, A - 1 = 0.349 (monomer ratio 1.4, separation = small diameter)
    assert dimer_aspect_ratio() - 1.0 == pytest.approx(4.0 / 7.0, rel=1e-14)
    assert round(dimer_asphericity() - 1.0, 3) == 0.349
    # touching disks of equal size: p = 2 pi D, a = pi D^2 / 2, A = 2
    assert dimer_asphericity(1.0, 1.0) == pytest.approx(2.0, rel=1e-14)


@pytest.mark.parametrize("ratio, separation", [(0.9, 1.0), (1.4, 1.25), (1.4, 0.15), (1.4, 0.0), (np.nan, 1.0)])
def test_bad_dimers_are_refused(ratio, separation):
    with pytest.raises(ValueError, match="dimer"):
        dimer_asphericity(ratio, separation)
    with pytest.raises(ValueError, match="dimer"):
        linked_packing(2, 4, "dimer", np.random.default_rng(0), diameter_ratio=ratio, separation=separation)


def test_bad_dimer_size_ratio_is_refused():
    with pytest.raises(ValueError, match="size ratio"):
        linked_packing(2, 4, "dimer", np.random.default_rng(0), size_ratio=0.8)


def _cap_2d(R: float, a: float) -> float:
    return R * R * acos(a / R) - a * sqrt(R * R - a * a)


def test_lens_volume_closed_forms_and_limits():
    # 2D: two circular segments cut by the radical line
    R1, R2, r = 0.5, 0.7, 1.0
    a1 = (r * r + R1 * R1 - R2 * R2) / (2 * r)
    assert lens_volume(2, 2 * R1, 2 * R2, r) == pytest.approx(_cap_2d(R1, a1) + _cap_2d(R2, r - a1), rel=1e-13)
    # 3D: pi (R1 + R2 - r)^2 (r^2 + 2 r R2 - 3 R2^2 + 2 r R1 + 6 R1 R2 - 3 R1^2) / (12 r)
    v3 = pi * (R1 + R2 - r) ** 2 * (r * r + 2 * r * R2 - 3 * R2**2 + 2 * r * R1 + 6 * R1 * R2 - 3 * R1**2) / (12 * r)
    assert lens_volume(3, 2 * R1, 2 * R2, r) == pytest.approx(v3, rel=1e-13)
    # 4D: integrate the 3-ball cross-sections of the intersection along the axis
    lo, hi = r - R2, R1

    def section(t: float) -> float:
        rho = min(R1 * R1 - t * t, R2 * R2 - (r - t) ** 2)
        return float(sphere_volume(3, 2 * sqrt(max(rho, 0.0))))

    v4, _ = quad(section, lo, hi, points=[a1], epsabs=0.0, epsrel=1e-13)
    assert lens_volume(4, 2 * R1, 2 * R2, r) == pytest.approx(v4, rel=1e-10)
    # a centre inside the other sphere (negative cap distance): 2D against shapely
    ref = Point(0, 0).buffer(0.5, quad_segs=QUAD_SEGS).intersection(Point(0.3, 0).buffer(0.9, quad_segs=QUAD_SEGS))
    assert lens_volume(2, 1.0, 1.8, 0.3) == pytest.approx(ref.area, rel=1e-7)
    # apart, touching, one inside the other, concentric
    assert lens_volume(3, 1.0, 1.4, 1.3) == 0.0 and lens_volume(3, 1.0, 1.4, 1.2) == pytest.approx(0.0, abs=1e-15)
    assert lens_volume(3, 1.0, 1.4, 0.1) == pytest.approx(sphere_volume(3, 1.0))
    assert lens_volume(2, 1.0, 1.0, 0.0) == pytest.approx(sphere_volume(2, 1.0))


@pytest.mark.parametrize("d", [2, 3])
def test_dimer_start_is_bidisperse_without_overlaps_at_the_exact_packing_fraction(d):
    k = 12
    p, messages = linked_packing(d, k, "dimer", np.random.default_rng(3))
    assert not messages and p.n == 2 * k and len(p.links) == k
    scale = np.where(np.arange(k) % 2 == 1, 1.4, 1.0)
    np.testing.assert_allclose(p.diameter.reshape(k, 2), np.stack([scale, 1.4 * scale], axis=1), rtol=1e-15)
    np.testing.assert_allclose(p.links.length, scale, rtol=1e-15)
    np.testing.assert_allclose(np.abs(p.links.length_errors(p.position, p.box)), 0.0, atol=1e-14)
    # the monomers of a dimer overlap, those of different dimers do not
    x, D = p.position, p.diameter
    r = np.linalg.norm(p.box.minimum_image(x[:, None] - x[None]), axis=2)
    sigma = 0.5 * (D[:, None] + D[None])
    own = np.equal.outer(np.arange(p.n) // 2, np.arange(p.n) // 2)
    assert np.all(r[own & ~np.eye(p.n, dtype=bool)] < sigma[own & ~np.eye(p.n, dtype=bool)])
    assert np.min((r / sigma)[~own]) >= 1.0 - 1e-12
    assert p.packing_fraction == pytest.approx(0.2 if d == 2 else 0.1, rel=1e-13)
    if d == 2:  # the union of the dimers, drawn by shapely at their (non-overlapping) positions
        v = p.box.minimum_image(x[1::2] - x[0::2])
        area = unary_union([Point(*x[2 * c]).buffer(0.5 * D[2 * c], quad_segs=QUAD_SEGS).union(
            Point(*(x[2 * c] + v[c])).buffer(0.5 * D[2 * c + 1], quad_segs=QUAD_SEGS)) for c in range(k)]).area
        assert p.packing_fraction * p.box.volume == pytest.approx(area, rel=1e-7)
        assert p.attrs["asphericity"] == dimer_asphericity()


def test_linked_volume_counts_the_lens_once_and_spheres_without_links_whole():
    D = np.array([1.0, 1.4, 1.0])
    links = Links(np.array([0]), np.array([1]), np.array([1.0]))
    assert linked_volume(2, D, links) == pytest.approx(dimer_perimeter_area(0.5, 0.7, 1.0)[1] + pi / 4, rel=1e-14)
    assert linked_volume(2, D, None) == pytest.approx(float(sphere_volume(2, D).sum()), rel=1e-15)


@pytest.fixture(scope="module")
def jammed_dimers():
    start, _ = linked_packing(2, 24, "dimer", np.random.default_rng(5))
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    return jam_linked(start, 1e-6, settings=settings)


def test_jammed_dimers_are_force_balanced_and_isostatic_with_rotators(jammed_dimers):
    result = jammed_dimers
    p = result.packing
    assert result.converged and p.pressure == pytest.approx(1e-6, rel=1e-3)
    # rigid dimers: link lengths (rescaled to the mean diameter) held to round-off
    assert np.max(np.abs(p.links.length_errors(p.position, p.box))) <= 1e-13
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    q = model.dofs(p.position)
    assert model.max_force(model.project(model.evaluate(q).gradient, q)) <= 1e-13
    # contacts between different dimers only, with overlaps set by the pressure (harmonic, k = 1)
    own = p.links.contains(p.contacts[:, 0], p.contacts[:, 1])
    assert not np.any(own)
    r = np.linalg.norm(p.contact_vectors(), axis=1)
    assert np.max(1.0 - r / p.sigma(p.contacts[:, 0], p.contacts[:, 1])) < 1e-4
    # Fig. 3b: N_c = 3 N' - 1 - N_rot with N' the non-rattling dimers; <z> of Eq. 3 is 6
    count = count_bodies(p.contacts, p.n, 2, p.links, p.position, p.box)
    n_rot, n_rat, z = p.attrs["n_rotators"], p.attrs["n_rattling_dimers"], p.attrs["z"]
    assert count.n_contacts == count.isostatic_count == 3 * (24 - n_rat) - 1 - n_rot
    assert z == pytest.approx(6.0, rel=1e-14)
    # a rotator's free monomer touches nothing; its other monomer holds the dimer
    contacts_per_sphere = np.bincount(p.contacts.ravel(), minlength=p.n)
    free = count.dangler  # dimers are spheres (2c, 2c + 1)
    assert free.sum() == n_rot and np.all(contacts_per_sphere[free] == 0)
    assert np.all(count.free_dofs[count.cluster[free]] == 1)
    assert np.all(contacts_per_sphere[free.reshape(-1, 2)[:, ::-1].ravel()] >= 3)


def test_zero_modes_of_jammed_dimers_are_translations_rotators_and_rattlers(jammed_dimers):
    """The constrained Hessian (an independent route to the counting) has 2 + N_rot + 3 N_rat zero modes."""
    p = jammed_dimers.packing
    h = constrained_hessian(p, strain=False)
    assert h.n_zero == 2 + p.attrs["n_rotators"] + 3 * p.attrs["n_rattling_dimers"]
    # every rotator's free rotation is a zero mode: its free monomer moving perpendicular to the link
    count = count_bodies(p.contacts, p.n, 2, p.links, p.position, p.box)
    free = np.flatnonzero(count.dangler)
    assert free.size == p.attrs["n_rotators"]
    zero = h.modes[:, :h.n_zero]
    for s in free:
        partner = s ^ 1
        u = p.box.minimum_image(p.position[partner] - p.position[s])
        t = np.zeros(2 * p.n)
        t[2 * s:2 * s + 2] = np.array([-u[1], u[0]]) / np.linalg.norm(u)
        assert np.linalg.norm(zero.T @ t) == pytest.approx(1.0, rel=1e-8)


def test_jammed_3d_dimers_are_isostatic_with_z_10_and_rotator_zero_modes():
    """3D: f = 5 per dimer, a rotator keeps 2 free turns; N_c = 5 N' - 2 N_rot - 2 and <z> = 10."""
    start, _ = linked_packing(3, 24, "dimer", np.random.default_rng(5))
    result = jam_linked(start, 1e-6, settings=JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2))
    p = result.packing
    assert result.converged
    count = count_bodies(p.contacts, p.n, 3, p.links, p.position, p.box)
    n_rot, n_rat = p.attrs["n_rotators"], p.attrs["n_rattling_dimers"]
    assert n_rot > 0  # the case under test
    assert count.n_contacts == count.isostatic_count == 5 * (24 - n_rat) - 2 * n_rot - 2
    assert p.attrs["z"] == pytest.approx(10.0, rel=1e-14)
    assert constrained_hessian(p, strain=False).n_zero == 3 + 2 * n_rot + 5 * n_rat


def test_cli_dimers_init_jam_check(tmp_path, capsys):
    start, out = tmp_path / "d0.nc", tmp_path / "d1.nc"
    assert main(["init-chains", str(start), "--d", "2", "--clusters", "16", "--cluster", "dimer", "--seed", "2"]) == 0
    assert "dimer asphericity A       1.348716" in capsys.readouterr().out
    assert main(["soft-jam", str(start), str(out), "--pressure", "1e-5", "--quiet"]) == 0
    assert main(["check", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["isostatic"] and report["n_dimers"] == 16
    assert report["n_contacts"] == 3 * (16 - report["n_rattling_dimers"]) - 1 - report["n_rotators"]
    assert report["z"] == pytest.approx(6.0, rel=1e-14)
    assert main(["check", str(out)]) == 0
    assert "rotators" in capsys.readouterr().out
