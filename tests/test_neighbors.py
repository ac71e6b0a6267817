"""Neighbour search against O(N^2) brute force in periodic and sheared boxes, d = 2..5."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.neighbors.pairs import (
    PairList,
    pairs_within,
    pairs_within_brute_force,
    verlet_pairs,
)


def _box(d: int, strain: float, rng: np.random.Generator) -> Box:
    """Box with sides 0.8..1.25 and, for nonzero strain, every tilt h[i, j] = strain * h[j, j]."""
    h = np.diag(rng.uniform(0.8, 1.25, d))
    i, j = np.triu_indices(d, 1)
    h[i, j] = strain * h[j, j] * rng.uniform(0.5, 1.0, len(i))
    return Box(h)


def _brute_pairs(x: np.ndarray, box: Box, cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """Independent of the k-d trees: every pair, minimum image by the box."""
    i, j = np.triu_indices(len(x), k=1)
    dx = box.minimum_image(x[j] - x[i])
    keep = np.linalg.norm(dx, axis=1) <= cutoff
    return np.stack([i[keep], j[keep]], axis=1), dx[keep]


def _assert_same(pl: PairList, x: np.ndarray, box: Box, cutoff: float) -> None:
    ref, ref_dx = _brute_pairs(x, box, cutoff)
    got = np.stack([pl.i, pl.j], axis=1)
    assert pl.i.dtype == np.int64 and pl.j.dtype == np.int64
    assert np.all(pl.i < pl.j)
    assert np.array_equal(np.lexsort((pl.j, pl.i)), np.arange(len(pl)))
    np.testing.assert_array_equal(got, ref)
    np.testing.assert_allclose(pl.dx, ref_dx, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pl.distance, np.linalg.norm(ref_dx, axis=1), rtol=0, atol=1e-12)
    assert np.all(pl.distance <= cutoff)


@pytest.mark.parametrize("d", [2, 3, 4, 5])
@pytest.mark.parametrize("strain", [0.0, 0.3, -0.5, 7.7, 50.0])
@pytest.mark.parametrize("cutoff_fraction", [0.05, 0.3, 0.499])
def test_pairs_match_brute_force(d: int, strain: float, cutoff_fraction: float) -> None:
    rng = np.random.default_rng([d, int(strain * 10) % 1000, int(cutoff_fraction * 1000)])
    box = _box(d, strain, rng)
    n = 300
    # unwrapped centres: some far outside the primary cell
    x = box.to_cartesian(rng.uniform(-3.0, 4.0, (n, d)))
    cutoff = cutoff_fraction * float(np.min(box.widths))
    pl = pairs_within(x, box, cutoff)
    _assert_same(pl, x, box, cutoff)
    if cutoff_fraction > 0.1:
        assert len(pl) > 0
    lib_brute = pairs_within_brute_force(x, box, cutoff)
    np.testing.assert_array_equal(lib_brute.i, pl.i)
    np.testing.assert_array_equal(lib_brute.j, pl.j)


@pytest.mark.parametrize("d", [2, 3])
def test_cutoff_just_below_half_the_width_in_a_tiny_box(d: int) -> None:
    rng = np.random.default_rng(5)
    for box in (Box.cubic(d, 0.01), Box.lees_edwards(np.full(d, 0.01), 12.25)):
        x = box.to_cartesian(rng.random((40, d)))
        cutoff = 0.5 * float(np.min(box.widths)) * (1 - 1e-9)
        _assert_same(pairs_within(x, box, cutoff), x, box, cutoff)


def test_few_particles() -> None:
    box = Box.lees_edwards([1.0, 1.0], 0.4)
    for n in (0, 1):
        pl = pairs_within(np.zeros((n, 2)), box, 0.3)
        assert len(pl) == 0 and pl.dx.shape == (0, 2)
    # two particles across the sheared boundary: the image through the top face is
    # displaced by the tilt
    x = np.array([[0.55, 0.98], [0.15, 0.03]])
    pl = pairs_within(x, box, 0.2)
    assert len(pl) == 1
    np.testing.assert_allclose(pl.dx[0], [0.15 + 0.4 - 0.55, 0.03 + 1.0 - 0.98], atol=1e-12)
    np.testing.assert_allclose(pl.distance, [np.hypot(0.0, 0.05)], atol=1e-12)


@pytest.mark.parametrize("gamma", [0.0, 0.5, 1.0, 23.0])
def test_square_lattice_has_four_neighbours(gamma: float) -> None:
    # a 10 x 10 square lattice stays periodic under Lees-Edwards strain k/2 (k integer)
    # because the image shift (10 gamma a, 10 a) is a lattice vector
    a, m = 0.1, 10
    grid = np.stack(np.meshgrid(np.arange(m), np.arange(m), indexing="ij"), -1).reshape(-1, 2) * a
    box = Box.lees_edwards([m * a, m * a], gamma)
    pl = pairs_within(grid, box, 1.01 * a)
    assert len(pl) == 2 * m * m
    assert np.all(np.bincount(np.concatenate([pl.i, pl.j]), minlength=m * m) == 4)
    np.testing.assert_allclose(pl.distance, a, rtol=1e-9)


def test_select() -> None:
    rng = np.random.default_rng(3)
    box = Box.cubic(3)
    pl = pairs_within(rng.random((200, 3)), box, 0.2)
    mask = pl.distance < 0.1
    sub = pl.select(mask)
    np.testing.assert_array_equal(sub.i, pl.i[mask])
    np.testing.assert_array_equal(sub.dx, pl.dx[mask])


@pytest.mark.parametrize("box", [Box.cubic(3), Box.lees_edwards([1.0, 1.0, 1.0], 3.3)])
def test_bad_cutoffs_and_shapes_raise(box: Box) -> None:
    x = np.random.default_rng(0).random((10, 3))
    half = 0.5 * float(np.min(box.widths))
    for cutoff in (half, 1.5 * half, 0.0, -0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="cutoff"):
            pairs_within(x, box, cutoff)
    with pytest.raises(ValueError, match="shape"):
        pairs_within(x[:, :2], box, 0.1)
    with pytest.raises(ValueError, match="shape"):
        pairs_within(x[0], box, 0.1)


@pytest.mark.parametrize("d", [2, 3, 4])
@pytest.mark.parametrize("strain", [0.0, 0.3])
@pytest.mark.parametrize("skin_fraction", [0.05, 0.4])
def test_verlet_pairs_match_brute_force(d: int, strain: float, skin_fraction: float) -> None:
    """Verlet pairs (r < (D_i + D_j) / 2 + skin) and their images against every pair by the box.

    A skin of 0.4 makes some axes hold fewer than 3 cells (the cell list must not count
    a pair twice); unwrapped positions several boxes away check the images.
    """
    rng = np.random.default_rng(d + 10 * int(10 * strain) + int(100 * skin_fraction))
    box = _box(d, strain, rng)
    n = 150
    x = box.to_cartesian(rng.uniform(-2.0, 3.0, (n, d)))
    half = 0.5 * float(np.min(box.widths))
    D = rng.choice([0.35, 0.49], n) * half
    skin = skin_fraction * half
    i, j, image = verlet_pairs(x, box, D, skin)
    a, b = np.triu_indices(n, k=1)
    dx = box.minimum_image(x[b] - x[a])
    keep = np.linalg.norm(dx, axis=1) < 0.5 * (D[a] + D[b]) + skin
    np.testing.assert_array_equal(np.stack([i, j], 1), np.stack([a[keep], b[keep]], 1))
    assert np.array_equal(image, np.round(image))
    np.testing.assert_allclose(x[j] - x[i] + image @ box.matrix.T, dx[keep], rtol=0, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("strain", [0.0, 0.3])
def test_a_verlet_list_misses_no_contact_within_its_rebuild_criterion(d: int, strain: float) -> None:
    """After moves with ``u1 + u2 < skin`` (NeighborList.stale false) every overlap is a listed pair.

    Dense random spheres (many pairs within the skin), each moved by just under
    ``skin / 2`` in a random direction, and unlisted pairs within 2 % of the skin
    edge pushed straight towards each other (they end within 2 % of the skin from
    contact): the brute-force contacts (r < sigma_ij) with their minimum images must
    all be in the list built before the moves.
    """
    from jamflow.neighbors.verlet import NeighborList

    rng = np.random.default_rng(7 + d + int(10 * strain))
    box = _box(d, strain, rng)
    n = 400
    half = 0.5 * float(np.min(box.widths))
    D = rng.choice([0.1, 0.14] if d == 2 else [0.25, 0.35], n) * half  # dense: hundreds of overlaps
    x = box.to_cartesian(rng.uniform(0.0, 1.0, (n, d)))
    nlist = NeighborList(D, skin=0.3 * D.mean())
    nlist.build(x, box)
    u = rng.normal(size=(n, d))
    u *= (0.5 - 1e-9) * nlist.skin / np.linalg.norm(u, axis=1, keepdims=True)
    # pairs just outside sigma + skin: each partner moves skin / 2 straight towards the other
    a, b = np.triu_indices(n, k=1)
    dx = box.minimum_image(x[b] - x[a])
    r = np.linalg.norm(dx, axis=1)
    edge = np.flatnonzero((r >= 0.5 * (D[a] + D[b]) + nlist.skin) & (r < 0.5 * (D[a] + D[b]) + 1.02 * nlist.skin))
    used = np.zeros(n, dtype=bool)
    for k in edge:
        if not used[a[k]] and not used[b[k]]:
            step = (0.5 - 1e-9) * nlist.skin * dx[k] / r[k]
            u[a[k]], u[b[k]] = step, -step
            used[a[k]] = used[b[k]] = True
    assert used.sum() >= 20  # the worst case is exercised
    y = x + u
    assert not nlist.stale(y, box)
    dy = box.minimum_image(y[b] - y[a])
    contact = np.linalg.norm(dy, axis=1) < 0.5 * (D[a] + D[b])
    assert contact.sum() > n  # dense enough to mean something
    listed = {(i, j): k for k, (i, j) in enumerate(zip(nlist.i.tolist(), nlist.j.tolist()))}
    for i, j, v in zip(a[contact].tolist(), b[contact].tolist(), dy[contact]):
        k = listed[(i, j)]
        np.testing.assert_allclose(y[j] - y[i] + nlist.image[k] @ box.matrix.T, v, rtol=0, atol=1e-12)


def test_a_box_too_small_for_the_skin_builds_with_a_smaller_skin_and_the_same_minimum() -> None:
    """max D + skin >= half the width > max D: the build takes SMALL_BOX_SKIN_SHARE of the room; results unchanged."""
    from jamflow.minimize.fire import minimize_fire
    from jamflow.models.spheres.model import SphereModel
    from jamflow.neighbors.verlet import SMALL_BOX_SKIN_SHARE, SPHERE_SKIN, NeighborList

    rng = np.random.default_rng(3)
    box = Box.cubic(3, 2.5)  # half width 1.25: room 0.25 for unit spheres, below the 3D skin 0.3
    D = np.ones(24)  # phi = 0.80: jammed, the minimum has overlaps
    x = box.to_cartesian(rng.uniform(0.0, 1.0, (24, 3)))
    nlist = NeighborList(D)
    nlist.build(x, box)
    assert SPHERE_SKIN[3] > 0.25 and nlist.skin == SMALL_BOX_SKIN_SHARE * 0.25 and nlist.reach == 1.0 + nlist.skin
    a, b = np.triu_indices(24, k=1)
    r = np.linalg.norm(box.minimum_image(x[b] - x[a]), axis=1)
    want = {(i, j) for i, j, keep in zip(a.tolist(), b.tolist(), r < 1.0 + nlist.skin) if keep}
    assert set(zip(nlist.i.tolist(), nlist.j.tolist())) == want
    # a build in a roomy box is back at the default skin (as the difference reach - max D)
    nlist.build(2.0 * x, box.scaled(2.0))
    assert nlist.reach == 1.0 + SPHERE_SKIN[3] and nlist.skin == nlist.reach - 1.0
    # the skin changes no result: FIRE from an overlapping start ends bitwise where an explicit small skin does
    ends = [minimize_fire(SphereModel(box, D, nlist=NeighborList(D, skin)), x, force_tol=1e-12)
            for skin in (None, 0.02)]
    assert all(end.converged for end in ends) and ends[0].energy > 0.0
    np.testing.assert_array_equal(ends[0].position, ends[1].position)


def test_the_rebuild_criterion_is_the_sum_of_the_two_largest_displacements() -> None:
    """One sphere moved by 0.6 skin and the rest by 0.3: u1 + u2 = 0.9 skin keeps the list
    (2 u1 = 1.2 skin would not); one more sphere pushed to 0.41 skin makes it stale."""
    from jamflow.neighbors.verlet import NeighborList

    rng = np.random.default_rng(5)
    box = Box.cubic(2, 10.0)
    D = np.ones(60)
    x = box.to_cartesian(rng.uniform(0.0, 1.0, (60, 2)))
    nlist = NeighborList(D, skin=0.4)
    nlist.build(x, box)
    u = rng.normal(size=(60, 2))
    u *= 0.3 * nlist.skin / np.linalg.norm(u, axis=1, keepdims=True)
    u[7] *= 2.0
    y = x + u
    assert not nlist.stale(y, box)
    y[8] += 0.11 * nlist.skin * u[8] / np.linalg.norm(u[8])  # u1 + u2 = 1.01 skin
    assert nlist.stale(y, box)


def test_a_search_reusing_its_work_arrays_finds_the_pairs_of_a_fresh_one() -> None:
    """``cell_pairs_into`` with the buffers of earlier searches (other N, other d, more
    pairs than the buffers hold, more cells) returns what a search with fresh buffers
    returns, and every pair by brute force; the buffers grow where needed."""
    from jamflow.neighbors._cell_kernels import (
        cell_pairs,
        cell_pairs_into,
        pair_buffers,
    )

    rng = np.random.default_rng(17)
    buffers = pair_buffers(40, 2)
    grown = []
    # dense (about 20 pairs per particle: the pair arrays grow), fewer particles than the
    # buffers hold, then 3D in a long box (more cells than 2 N + 10: the cell table grows)
    # with the particles in a short stretch of it, so that they have neighbours
    for n, L, D, skin in ((300, [6.0, 7.0], 1.0, 0.4), (25, [8.0, 8.0], 1.2, 0.3), (20, [300.0, 2.5, 2.5], 1.0, 0.1)):
        L = np.array(L)
        x = rng.uniform(-1.0, 2.0, (n, L.size)) * np.minimum(L, 10.0)
        diameter = np.full(n, D)
        i, j, image, buffers = cell_pairs_into(x, L, D + skin, diameter, skin, buffers)
        grown.append((buffers[5].shape[1], buffers[4].shape[1]))
        fresh = cell_pairs(x, L, D + skin, diameter, skin)
        for got, want in zip((i, j, image), fresh):
            np.testing.assert_array_equal(got, want)
        a, b = np.triu_indices(n, k=1)
        dx = x[b] - x[a]
        dx -= L * np.round(dx / L)
        keep = np.linalg.norm(dx, axis=1) < D + skin
        assert keep.sum() > 0
        np.testing.assert_array_equal(np.stack([i, j], 1), np.stack([a[keep], b[keep]], 1))
        np.testing.assert_allclose(x[j] - x[i] + image * L, dx[keep], rtol=0, atol=1e-12)
    assert grown[0][0] > 8 * 300 + 16 and grown[1] == grown[0] and grown[2][1] > 2 * 20 + 10


@pytest.mark.parametrize("d", [2, 3, 4, 5])
def test_the_tree_and_the_cell_list_find_the_same_pairs(d: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Orthogonal boxes are searched by the periodic k-d tree up to KDTREE_MAX_N particles
    and by the compiled cell list above: both give the same pairs, in the same order,
    with the same separations, for unwrapped positions and coordinates a rounding error
    below 0 (which wrap to the box's upper face)."""
    import jamflow.neighbors.pairs as neighbors

    rng = np.random.default_rng(40 + d)
    L = rng.uniform(4.0, 6.0, d)
    box = Box.orthogonal(L)
    x = rng.uniform(-2.0, 3.0, (300, d)) * L
    x[:5, 0] = -1e-17
    cutoff = 0.45 * float(L.min()) * (0.6 if d < 4 else 1.0)
    tree = pairs_within(x, box, cutoff)
    monkeypatch.setattr(neighbors, "KDTREE_MAX_N", 0)
    cells = pairs_within(x, box, cutoff)
    assert len(tree.i) > 300
    np.testing.assert_array_equal(tree.i, cells.i)
    np.testing.assert_array_equal(tree.j, cells.j)
    np.testing.assert_array_equal(tree.dx, cells.dx)
