"""Periodic and sheared boxes: minimum image, wrap, reduction, volume, widths.

Property tests compare with brute force over neighbouring images, in d = 2..5,
for orthogonal and tilted boxes up to strain 50.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jamflow.box import Box

settings.register_profile("jamflow", deadline=None, max_examples=60)
settings.load_profile("jamflow")

WINDOW = 3  # brute force over integer combinations -3..3 of the lattice vectors


@st.composite
def boxes(draw: st.DrawFn, max_strain: float = 50.0) -> Box:
    """Upper-triangular boxes, d = 2..5, sides 0.1..2, tilts h[i, j] = strain * h[j, j]."""
    d = draw(st.integers(2, 5))
    lengths = draw(st.lists(st.floats(0.1, 2.0), min_size=d, max_size=d))
    h = np.diag(lengths)
    if draw(st.booleans()):
        for i, j in zip(*np.triu_indices(d, 1)):
            strain = draw(st.one_of(st.just(0.0), st.floats(-max_strain, max_strain)))
            h[i, j] = strain * h[j, j]
    return Box(h)


def vectors(d: int, scale: float = 100.0, n: int = 6, min_n: int = 1):
    """Arrays of shape (between min_n and n, d) with entries in [-scale, scale]."""
    return st.lists(
        st.lists(st.floats(-scale, scale), min_size=d, max_size=d), min_size=min_n, max_size=n
    ).map(lambda v: np.array(v, dtype=np.float64))


def _window(d: int) -> np.ndarray:
    return np.array(list(itertools.product(range(-WINDOW, WINDOW + 1), repeat=d)), dtype=np.float64)


def _lattice_coefficients(h: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Coefficients k with v = h k (rows of v)."""
    return np.linalg.solve(h, v.T).T


def _assert_lattice_vectors(h: np.ndarray, v: np.ndarray, atol: float = 1e-6) -> None:
    k = _lattice_coefficients(h, v)
    np.testing.assert_allclose(k, np.round(k), rtol=0, atol=atol)


@given(data=st.data(), box=boxes())
def test_minimum_image_is_the_shortest_image(data: st.DataObject, box: Box) -> None:
    dx = data.draw(vectors(box.d))
    m = box.minimum_image(dx)
    assert m.shape == dx.shape
    # the result is an image of the input ...
    _assert_lattice_vectors(box.matrix, dx - m)
    # ... and no image within -3..3 lattice steps, in the box's own lattice vectors or
    # in the reduced ones, is shorter
    n = _window(box.d)
    norm = np.linalg.norm(m, axis=1)
    for h in (box.matrix, box.reduced.matrix):
        images = m[:, None, :] - (n @ h.T)[None, :, :]
        brute = np.linalg.norm(images, axis=2).min(axis=1)
        assert np.all(norm <= brute * (1 + 1e-12) + 1e-12), (norm, brute)


@given(data=st.data(), box=boxes())
def test_minimum_image_shape_and_displacement(data: st.DataObject, box: Box) -> None:
    x = data.draw(vectors(box.d, 10.0, 4, min_n=4))
    y = data.draw(vectors(box.d, 10.0, 4, min_n=4))
    np.testing.assert_array_equal(box.displacement(x, y), box.minimum_image(y - x))
    # a single vector (shape (d,)) and a batch (shape (a, b, d)) give the same answer
    single = np.array([box.minimum_image(v) for v in x])
    np.testing.assert_allclose(single, box.minimum_image(x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(box.minimum_image(x[None]), box.minimum_image(x)[None], rtol=0, atol=1e-12)


def test_minimum_image_in_a_strongly_anisotropic_cell() -> None:
    # lattice (0.3 m + n, 0.01 m): the shortest image of (0.4, 0) is -2 a_1 + a_0 away
    box = Box(np.array([[1.0, 0.3], [0.0, 0.01]]))
    dx = np.array([0.4, 0.0])
    n = np.array(list(itertools.product(range(-100, 101), repeat=2)), dtype=np.float64)
    brute = np.linalg.norm(dx - n @ box.matrix.T, axis=1).min()
    assert brute == pytest.approx(0.02, abs=1e-12)
    assert np.linalg.norm(box.minimum_image(dx)) == pytest.approx(brute, rel=1e-12)


@given(data=st.data(), box=boxes())
def test_wrap_lands_in_primary_cell_by_a_lattice_vector(data: st.DataObject, box: Box) -> None:
    x = data.draw(vectors(box.d, 1000.0))
    w = box.wrap(x)
    s = np.linalg.solve(box.matrix, w.T).T
    assert np.all(s >= -1e-12) and np.all(s < 1.0 + 1e-12), s
    assert np.all(box.contains(w))
    _assert_lattice_vectors(box.matrix, x - w, atol=1e-6)
    np.testing.assert_allclose(box.wrap(w), w, rtol=0, atol=1e-9)


def test_wrap_is_idempotent_at_a_face_of_a_tilted_cell() -> None:
    """Hypothesis counterexample: s_0 = 2 - 2^-52 came back at 1 through H^-1 (H s)."""
    box = Box(np.array([[0.3125, -2.0], [0.0, 1.0]]))
    w = box.wrap(np.array([[0.0, 0.3125]]))
    np.testing.assert_array_equal(box.wrap(w), w)
    assert np.all(box.contains(w, tol=1e-15))


def test_wrap_edge_values() -> None:
    box = Box.cubic(3, 2.0)
    w = box.wrap(np.array([[-1e-300, 2.0, -2.0], [4.0 - 1e-17, 1.0, 0.0]]))
    s = box.to_fractional(w)
    assert np.all(s >= 0.0) and np.all(s < 1.0)


@given(box=boxes())
def test_reduced_spans_the_same_lattice(box: Box) -> None:
    red = box.reduced
    # h_red = h U with U integer and unimodular
    u = np.linalg.solve(box.matrix, red.matrix)
    np.testing.assert_allclose(u, np.round(u), rtol=0, atol=1e-6)
    assert abs(round(np.linalg.det(np.round(u)))) == 1
    assert np.allclose(np.tril(red.matrix, -1), 0.0)
    np.testing.assert_array_equal(np.diag(red.matrix), np.diag(box.matrix))
    i, j = np.triu_indices(box.d, 1)
    assert np.all(np.abs(red.matrix[i, j]) <= 0.5 * red.matrix[i, i] * (1 + 1e-12))
    assert red.volume == pytest.approx(box.volume, rel=1e-12)


@given(box=boxes())
def test_volume_and_widths(box: Box) -> None:
    assert box.volume == pytest.approx(abs(np.linalg.det(box.matrix)), rel=1e-9)
    # width k: volume over the (d-1)-volume of the face spanned by the other vectors
    h = box.reduced.matrix
    for k in range(box.d):
        face = np.delete(h, k, axis=1)
        area = np.sqrt(np.linalg.det(face.T @ face))
        assert box.widths[k] == pytest.approx(box.volume / area, rel=1e-9)
    # no two images of a point closer than the smallest width
    n = _window(box.d)
    n = n[np.any(n != 0, axis=1)]
    shortest = np.linalg.norm(n @ h.T, axis=1).min()
    assert shortest >= np.min(box.widths) * (1 - 1e-12)


@pytest.mark.parametrize("d", [2, 3, 4, 5])
def test_orthogonal_box_properties(d: int) -> None:
    lengths = np.linspace(1.0, 2.0, d)
    box = Box.orthogonal(lengths)
    assert box.d == d and box.is_orthogonal
    assert box.volume == pytest.approx(np.prod(lengths))
    np.testing.assert_allclose(box.widths, lengths)
    np.testing.assert_array_equal(box.lengths, lengths)
    assert Box.cubic(d, 2.0) == Box.orthogonal(np.full(d, 2.0))
    assert hash(Box.cubic(d, 2.0)) == hash(Box.orthogonal(np.full(d, 2.0)))


def test_lees_edwards_box_is_periodic_in_strain() -> None:
    lengths = np.array([1.5, 1.0, 0.8])
    rng = np.random.default_rng(1)
    dx = rng.normal(scale=3.0, size=(200, 3))
    gamma = 0.37
    base = Box.lees_edwards(lengths, gamma)
    assert base.shear_strain == pytest.approx(gamma)
    assert not base.is_orthogonal
    assert base.volume == pytest.approx(np.prod(lengths))
    ref = np.linalg.norm(base.minimum_image(dx), axis=1)
    # strain gamma + k L0/L1 is the same lattice
    for k in (1, -3, 33):
        other = base.with_shear(gamma + k * lengths[0] / lengths[1])
        assert other.shear_strain == pytest.approx(gamma + k * lengths[0] / lengths[1])
        np.testing.assert_allclose(np.linalg.norm(other.minimum_image(dx), axis=1), ref, rtol=1e-9)
        np.testing.assert_allclose(other.reduced.matrix, base.reduced.matrix, rtol=0, atol=1e-9)


def test_coordinates_and_scaling() -> None:
    box = Box.lees_edwards([2.0, 1.0], 7.3)
    x = np.random.default_rng(2).normal(size=(10, 2))
    np.testing.assert_allclose(box.to_cartesian(box.to_fractional(x)), x, atol=1e-12)
    big = box.scaled(2.0)
    assert big.volume == pytest.approx(4.0 * box.volume)
    assert big.shear_strain == pytest.approx(box.shear_strain)
    np.testing.assert_allclose(big.minimum_image(2 * x), 2 * box.minimum_image(x), atol=1e-12)


@pytest.mark.parametrize(
    "matrix, message",
    [
        (np.eye(3)[:2], "square"),
        (np.ones((1, 1)), ">= 2"),
        (np.ones((2, 2, 2)), "square"),
        (np.array([[1.0, 0.0], [0.1, 1.0]]), "upper triangular"),
        (np.array([[1.0, np.nan], [0.0, 1.0]]), "non-finite"),
        (np.array([[1.0, 0.0], [0.0, np.inf]]), "non-finite"),
        (np.diag([1.0, 0.0]), "positive"),
        (np.diag([1.0, -1.0, 1.0]), "positive"),
    ],
)
def test_bad_boxes_raise(matrix: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Box(matrix)


def test_box_is_immutable() -> None:
    box = Box.cubic(2)
    with pytest.raises(ValueError):
        box.matrix[0, 0] = 2.0
