"""The packing state: validation, derived quantities, gaps and overlaps, dataset form."""

from __future__ import annotations

import json
from math import pi

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.state.packing import (
    OverlapError,
    Packing,
    length_unit,
    max_overlap,
    near_pairs,
    sphere_volume,
)
from jamflow.tolerances import OVERLAP_TOL


def _dilute(n: int = 20, d: int = 3, seed: int = 0, box: Box | None = None) -> Packing:
    """Spheres of diameter 0.01 at random: no overlaps (checked by the tests that need it)."""
    box = box or Box.cubic(d)
    x = box.to_cartesian(np.random.default_rng(seed).random((n, d)))
    return Packing(position=x, diameter=np.full(n, 0.01), box=box)


def _pair(distance: float, d: int = 2, D: float = 0.1, box: Box | None = None) -> Packing:
    box = box or Box.cubic(d)
    x = np.full((2, d), 0.5)
    x[1, 0] += distance
    return Packing(position=x, diameter=np.full(2, D), box=box)


# --- geometry ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "d, unit_ball", [(2, pi), (3, 4 * pi / 3), (4, pi**2 / 2), (5, 8 * pi**2 / 15)]
)
def test_sphere_volume_known_values(d: int, unit_ball: float) -> None:
    np.testing.assert_allclose(sphere_volume(d, [2.0, 1.0]), [unit_ball, unit_ball / 2**d], rtol=1e-14)


def test_packing_fraction_in_a_sheared_box() -> None:
    box = Box.lees_edwards([2.0, 1.5], 3.7)
    D = np.array([0.1, 0.2, 0.3])
    p = Packing(box.to_cartesian([[0.1, 0.1], [0.5, 0.5], [0.9, 0.2]]), D, box)
    assert p.packing_fraction == pytest.approx(pi * np.sum((D / 2) ** 2) / 3.0, rel=1e-14)
    assert p.n == 3 and p.d == 2


def test_near_pairs_relative_gaps_against_brute_force(rng: np.random.Generator) -> None:
    box = Box.lees_edwards([1.0, 1.0, 1.0], 0.8)
    n = 150
    D = rng.uniform(0.05, 0.1, n)
    p = Packing(box.to_cartesian(rng.random((n, 3))), D, box)
    pairs, h = near_pairs(p, 0.5)
    i, j = np.triu_indices(n, 1)
    r = np.linalg.norm(box.minimum_image(p.position[j] - p.position[i]), axis=1)
    h_ref = r / (0.5 * (D[i] + D[j])) - 1.0
    keep = h_ref <= 0.5
    np.testing.assert_array_equal(np.stack([pairs.i, pairs.j], 1), np.stack([i[keep], j[keep]], 1))
    np.testing.assert_allclose(h, h_ref[keep], rtol=0, atol=1e-13)
    # overlaps are the negative gaps
    overlap_abs, overlap_rel = max_overlap(p)
    k = np.argmin(h_ref)
    assert overlap_rel == pytest.approx(max(0.0, -h_ref[k]), abs=1e-13)
    assert overlap_abs == pytest.approx(max(0.0, -h_ref[k]) * 0.5 * (D[i[k]] + D[j[k]]), abs=1e-13)


def test_max_overlap_of_a_constructed_pair() -> None:
    assert max_overlap(_pair(0.2)) == (0.0, 0.0)
    absolute, relative = max_overlap(_pair(0.1 - 0.003))
    assert absolute == pytest.approx(0.003, rel=1e-9)
    assert relative == pytest.approx(0.03, rel=1e-9)


def test_contact_vectors_use_the_minimum_image() -> None:
    box = Box.lees_edwards([1.0, 1.0], 0.25)
    x = np.array([[0.5, 0.97], [0.27, 0.02]])
    p = Packing(x, np.full(2, 0.1), box, contacts=[[0, 1]])
    np.testing.assert_allclose(p.contact_vectors(), [[0.27 + 0.25 - 0.5, 0.05]], atol=1e-12)
    with pytest.raises(ValueError, match="no contacts"):
        Packing(x, np.full(2, 0.1), box).contact_vectors()


def test_wrapped_and_evolve() -> None:
    box = Box.lees_edwards([1.0, 1.0], 2.5)
    p = _dilute(d=2, box=box)
    moved = p.evolve(position=p.position + np.array([3.3, -7.1]))
    with pytest.raises(ValueError, match="outside the box"):
        moved.validate()
    back = moved.wrapped()
    back.validate()
    np.testing.assert_allclose(box.minimum_image(back.position - moved.position), 0.0, atol=1e-12)
    assert back.diameter is moved.diameter or np.array_equal(back.diameter, moved.diameter)


# --- validation ---------------------------------------------------------------------

BOX = Box.cubic(3)
X = np.random.default_rng(0).random((4, 3))
D = np.full(4, 0.01)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(position=X[:, :2]), "d=2"),
        (dict(position=X.ravel()), "shape"),
        (dict(position=np.zeros((0, 3)), diameter=np.zeros(0)), "at least one"),
        (dict(diameter=D[:3]), "diameter must have shape"),
        (dict(position=np.where(np.arange(12).reshape(4, 3) == 5, np.nan, X)), "NaN"),
        (dict(position=np.where(np.arange(12).reshape(4, 3) == 5, np.inf, X)), "NaN or infinite"),
        (dict(diameter=np.array([0.01, np.nan, 0.01, 0.01])), "diameter"),
        (dict(diameter=np.array([0.01, 0.0, 0.01, 0.01])), "diameter"),
        (dict(diameter=np.array([0.01, -0.01, 0.01, 0.01])), "diameter"),
        (dict(diameter=np.array([0.01, 0.5, 0.01, 0.01])), "half the smallest box width"),
        (dict(contacts=[[1, 0]]), "i < j"),
        (dict(contacts=[[1, 1]]), "i < j"),
        (dict(contacts=[[-1, 2]]), "i < j"),
        (dict(contacts=[[0, 4]]), "i < j"),
        (dict(contacts=[[0, 1], [2, 3], [0, 1]]), "duplicated"),
        (dict(force=[1.0]), "without contacts"),
        (dict(contacts=[[0, 1], [2, 3]], force=[1.0]), "force must have shape"),
        (dict(contacts=[[0, 1]], force=[np.nan]), "force contains NaN"),
        (dict(rattler=[True, False]), "rattler must have shape"),
    ],
)
def test_bad_packings_raise(kwargs: dict, message: str) -> None:
    args = dict(position=X, diameter=D, box=BOX) | kwargs
    with pytest.raises(ValueError, match=message):
        Packing(**args)


def test_diameter_limit_uses_the_sheared_width() -> None:
    # at strain 0.5 the smallest width of a unit square box is 1/sqrt(1.25)
    box = Box.lees_edwards([1.0, 1.0], 0.5)
    half_width = 0.5 / np.sqrt(1.25)
    Packing(np.zeros((1, 2)), [0.99 * half_width], box)
    with pytest.raises(ValueError, match="half the smallest box width"):
        Packing(np.zeros((1, 2)), [1.01 * half_width], box)


def test_contacts_are_sorted_and_forces_follow_them() -> None:
    p = Packing(X, D, BOX, contacts=[[2, 3], [0, 3], [0, 1]], force=[23.0, 3.0, 1.0])
    np.testing.assert_array_equal(p.contacts, [[0, 1], [0, 3], [2, 3]])
    np.testing.assert_array_equal(p.force, [1.0, 3.0, 23.0])
    assert p.contacts.dtype == np.int64


def test_positions_outside_the_box_fail_validation() -> None:
    p = Packing(X + np.array([0.0, 1.5, 0.0]), D, BOX)
    with pytest.raises(ValueError, match="outside the box"):
        p.validate()
    with pytest.raises(ValueError, match="outside the box"):
        p.validate(None)


def test_overlaps_beyond_the_tolerance_raise_naming_the_pairs() -> None:
    sigma = 0.1
    _pair(sigma * (1 - 0.1 * OVERLAP_TOL)).validate()
    bad = _pair(sigma * (1 - 10 * OVERLAP_TOL))
    with pytest.raises(OverlapError, match=r"1 pair\(s\).*\(0, 1\)"):
        bad.validate()
    bad.validate(overlap_tol=100 * OVERLAP_TOL)
    # soft packings: any overlap accepted
    _pair(0.5 * sigma).validate(None)
    # several overlapping pairs in a sheared box, across the boundary
    box = Box.lees_edwards([1.0, 1.0], 0.3)
    x = np.array([[0.1, 0.5], [0.15, 0.5], [0.8, 0.99], [0.53, 0.02], [0.3, 0.3]])
    p = Packing(box.wrap(x), np.full(5, 0.1), box)
    with pytest.raises(OverlapError) as err:
        p.validate()
    assert "2 pair(s)" in str(err.value)
    assert "(0, 1)" in str(err.value) and "(2, 3)" in str(err.value)
    assert isinstance(err.value, ValueError)


def test_random_dilute_packing_validates() -> None:
    p = _dilute(50)
    _, h = near_pairs(p, 0.0)
    i, j = np.triu_indices(p.n, 1)
    r = np.linalg.norm(p.box.minimum_image(p.position[j] - p.position[i]), axis=1)
    assert np.all(r > 0.01)  # the premise: no overlaps
    assert len(h) == 0
    p.validate()


# --- dataset form ---------------------------------------------------------------------


def _full_packing() -> Packing:
    box = Box.lees_edwards([1.0, 1.2, 0.9], 4.321)
    rng = np.random.default_rng(7)
    n = 12
    return Packing(
        position=box.to_cartesian(rng.random((n, 3))),
        diameter=rng.uniform(0.01, 0.02, n),
        box=box,
        contacts=[[0, 1], [1, 5], [3, 11]],
        force=rng.random(3),
        rattler=rng.random(n) < 0.5,
        pressure=1.234567890123e12,
        protocol="random>soft>calippso",
        seed=42,
        parameters={"n": n, "tol": 1e-13, "nested": {"a": [1, 2]}, "name": "x"},
        attrs={"force_unit": "p sigma^(d-1)", "iterations": 17},
    )


def test_dataset_round_trip_in_memory() -> None:
    p = _full_packing()
    ds = p.to_dataset()
    q = Packing.from_dataset(ds)
    for name in ("position", "diameter", "contacts", "force", "rattler"):
        np.testing.assert_array_equal(getattr(q, name), getattr(p, name))
    assert q.box == p.box
    assert (q.pressure, q.protocol, q.seed) == (p.pressure, p.protocol, p.seed)
    assert q.parameters == p.parameters
    assert q.attrs["force_unit"] == p.attrs["force_unit"] and q.attrs["iterations"] == 17
    for var in ds.data_vars.values():
        assert var.attrs["units"] and var.attrs["long_name"], var.name
    assert json.loads(ds.attrs["parameters"]) == p.parameters
    assert ds.attrs["d"] == 3 and ds.attrs["N"] == p.n
    assert ds.attrs["packing_fraction"] == p.packing_fraction


def test_dataset_with_stage_parameters_and_missing_fields() -> None:
    p = _dilute(5)
    ds = p.to_dataset({"stage": "init", "phi": 0.1})
    assert json.loads(ds.attrs["parameters"]) == {"stage": "init", "phi": 0.1}
    assert "contact_i" not in ds and "force" not in ds and "rattler" not in ds
    q = Packing.from_dataset(ds)
    assert q.contacts is None and q.force is None and q.rattler is None
    assert q.pressure is None and q.seed is None
    with pytest.raises(ValueError, match="missing variable"):
        Packing.from_dataset(ds.drop_vars("box"))


def test_malformed_contact_variables_in_a_dataset() -> None:
    ds = _full_packing().to_dataset()
    with pytest.raises(ValueError, match="only one of contact_i and contact_j"):
        Packing.from_dataset(ds.drop_vars("contact_j"))
    # forces without contacts are an error, not silently dropped
    with pytest.raises(ValueError, match="forces given without contacts"):
        Packing.from_dataset(ds.drop_vars(["contact_i", "contact_j"]))


def test_in_units_scales_every_length_and_keeps_phi_and_contacts():
    box = Box.lees_edwards([2.0, 2.0], 0.3)
    p = Packing(position=[[0.1, 0.1], [0.5, 0.1], [1.2, 1.5]], diameter=[0.4, 0.56, 0.4], box=box,
                contacts=[[0, 1]], force=[2.0])
    lam = length_unit(p.diameter, "small_diameter")
    assert lam == pytest.approx(0.4)
    q = p.in_units(lam)
    assert q.packing_fraction == pytest.approx(p.packing_fraction, rel=1e-14)
    np.testing.assert_allclose(q.box.matrix, box.matrix / 0.4)
    np.testing.assert_allclose(q.diameter, [1.0, 1.4, 1.0])
    np.testing.assert_array_equal(q.contacts, p.contacts)
    np.testing.assert_array_equal(q.force, p.force)
    assert length_unit(p.diameter, "mean_diameter") == pytest.approx(np.mean(p.diameter))
    with pytest.raises(ValueError):
        p.in_units(0.0)
    with pytest.raises(ValueError):
        length_unit(p.diameter, "largest")


@pytest.mark.parametrize("name, bodies", [("spheres_hard", "spheres,"), ("linked_soft", "18 links in 6 clusters"),
                                          ("shapes_soft", "shapes: ellipse"),
                                          ("walls_hard", "spheres between hard walls")])
def test_repr_is_one_line_with_n_d_phi_bodies_and_box(name, bodies) -> None:
    from pathlib import Path

    from jamflow.io import read_packing

    p = read_packing(Path(__file__).parent / "data" / "bodies" / f"{name}.nc", None)
    text = repr(p)
    assert "\n" not in text and len(text) < 200
    assert f"N={p.n}, d={p.d}, phi={p.packing_fraction:.6g}" in text and bodies in text
    assert f"box {p.box.matrix[0, 0]:.6g} x" in text and str(p) == text
    assert f"{len(p.contacts)} {'sphere-sphere contacts' if name == 'walls_hard' else 'contacts'}" in text


def test_repr_of_a_large_packing_stays_one_short_line() -> None:
    x = np.random.default_rng(1).uniform(size=(1000, 3))
    text = repr(Packing(position=x, diameter=np.full(1000, 1e-3), box=Box.cubic(3)))
    assert "\n" not in text and len(text) < 200 and text.startswith("Packing(N=1000, d=3, phi=")
