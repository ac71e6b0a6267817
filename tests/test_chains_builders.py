"""Builders of linked packings (chains paper Sec. II A, F): rigidity of clusters, no crossings, bad input."""

from __future__ import annotations

from math import pi

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.chains.builders import (
    BOND_ANGLE_RANGE,
    _cross,
    cement,
    check_linked_start,
    cluster_extent,
    crossing_links,
    linked_packing,
    read_link_file,
    remove_degenerate_links,
    rigid_cluster_links,
)
from jamflow.cli import main
from jamflow.io import read_packing, write_packing
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.state.bodies import Links
from jamflow.state.packing import Packing


def _floppy_modes(links: Links, x: np.ndarray, box: Box, members: np.ndarray) -> int:
    """Null-space dimension of the link Jacobian of one cluster (its degrees of freedom)."""
    d = box.d
    rows = []
    local = {int(p): k for k, p in enumerate(members)}
    for a, b in zip(links.i, links.j):
        if int(a) in local:
            u = box.minimum_image(x[b] - x[a])
            u /= np.linalg.norm(u)
            g = np.zeros(len(members) * d)
            g[local[int(a)] * d:(local[int(a)] + 1) * d] = -u
            g[local[int(b)] * d:(local[int(b)] + 1) * d] = u
            rows.append(g)
    s = np.linalg.svd(np.array(rows), compute_uv=False)
    rank = int(np.sum(s > 1e-8 * s.max()))
    assert rank == len(rows), "degenerate links left in the cluster"
    return len(members) * d - rank


@pytest.mark.parametrize("d", [2, 3])
def test_trimers_are_rigid_clusters_with_bond_angles_in_range(d):
    p, messages = linked_packing(d, 12, "trimer", np.random.default_rng(3), no_overlap=False)
    assert messages == [] and p.n == 36 and len(p.links) == 36
    labels = p.clusters
    for c in range(12):
        members = np.flatnonzero(labels == c)
        assert len(members) == 3
        # rigid: only the d (d + 1) / 2 rigid-body motions are free (a triangle spans a plane in 3D)
        assert _floppy_modes(p.links, p.position, p.box, members) == d * (d + 1) // 2
    # links hold exactly, bonds touch, angle links set angles in the documented range
    err = p.links.length_errors(p.position, p.box)
    assert np.max(np.abs(err)) <= 1e-14
    bonds = p.links.j - p.links.i == 1
    np.testing.assert_allclose(p.links.length[bonds], 1.0, rtol=1e-14)
    theta = 2.0 * np.arcsin(p.links.length[~bonds] / 2.0)
    assert np.all((theta >= BOND_ANGLE_RANGE[0]) & (theta <= BOND_ANGLE_RANGE[1]))
    # the packing fraction asked for
    assert p.packing_fraction == pytest.approx(0.86 if d == 2 else 0.66, rel=1e-12)


@pytest.mark.parametrize("free", [True, False])
def test_chains_have_the_degrees_of_freedom_of_their_links(free):
    m = 6
    p, _ = linked_packing(3, 10, "chain", np.random.default_rng(5), chain_length=m, free_angles=free, phi=0.3, no_overlap=False)
    assert len(p.links) == 10 * ((m - 1) if free else (2 * m - 3))
    members = np.flatnonzero(p.clusters == 4)
    # free: 3 m - (m - 1); frozen angles in 3D leave the m - 3 torsions + 6 rigid motions
    assert _floppy_modes(p.links, p.position, p.box, members) == (3 * m - (m - 1) if free else 6 + (m - 3))


def test_2d_placement_has_no_crossing_links_and_crossings_are_found():
    p, _ = linked_packing(2, 20, "chain", np.random.default_rng(7), chain_length=6, free_angles=True, phi=0.5, no_overlap=False)
    assert len(crossing_links(p.links, p.position, p.box)) == 0
    # two dimers crossing as an X (one of them across the periodic boundary) are found, touching ones are not
    box = Box.cubic(2, 10.0)
    x = np.array([[9.6, 5.0], [0.6, 5.0], [0.1, 4.5], [0.1, 5.5], [3.0, 3.0], [4.0, 3.0]])
    links = Links(np.array([0, 2, 1]), np.array([1, 3, 4]), np.array([1.0, 1.0, 2.83]))
    cross = crossing_links(links, x, box)
    assert [tuple(links.i[c]) for c in cross] == [(0, 2)]


@pytest.mark.parametrize("tilt", [0.0, 0.37])
def test_crossing_links_by_midpoint_pairs_agree_with_every_pair(tilt):
    # chains with their spheres scattered by about a diameter cross many times; the midpoint pair
    # query must find exactly the crossings of the test over every pair of links, also in a sheared box
    p, _ = linked_packing(2, 40, "chain", np.random.default_rng(3), chain_length=5, free_angles=True, phi=0.5,
                          no_overlap=False)
    x = p.position + np.random.default_rng(4).normal(0.0, 0.7, p.position.shape)
    h = np.array(p.box.matrix)
    h[0, 1] = tilt * h[1, 1]
    box = Box(h)
    every = np.arange(len(p.links))
    hit = _cross(p.links, every, every, x, box) & (every[None, :] > every[:, None])
    expected = np.stack(np.nonzero(hit), axis=1)
    found = crossing_links(p.links, x, box)
    assert len(expected) > 20
    assert np.array_equal(found[np.lexsort((found[:, 1], found[:, 0]))], expected)


def test_degenerate_links_are_removed_with_a_message():
    p, messages = linked_packing(2, 4, "trimer", np.random.default_rng(1), bond_angle=pi, phi=0.3, no_overlap=False)
    # a straight trimer's angle link depends linearly on its bonds
    assert len(messages) == 4 and all("degenerate link" in m for m in messages)
    assert len(p.links) == 8 and np.all(p.links.j - p.links.i == 1)
    # a rigid square: all six pairs offered, five independent kept (2 * 4 - 3)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pairs, _ = rigid_cluster_links(square)
    assert len(pairs) == 5
    links, messages = remove_degenerate_links(
        [(0, 1), (1, 2), (2, 3), (0, 3), (0, 2), (1, 3)], [1, 1, 1, 1, 2**0.5, 2**0.5], square + 3.0,
        Box.cubic(2, 10.0))
    assert len(links) == 5 and len(messages) == 1 and "(1, 3)" in messages[0]
    # a regular tetrahedron is rigid with its six edges
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    assert len(rigid_cluster_links(tet)[0]) == 6


@pytest.fixture(scope="module")
def jammed() -> Packing:
    start = random_packing(48, 2, 0.5, "bi", seed=11)
    return jam_to_pressure(start, 1e-3, force_tol=1e-11, pressure_rtol=1e-3).packing


def test_cementing_turns_contacts_into_links_and_freezes_their_angles(jammed):
    links, _ = cement(jammed, 12, np.random.default_rng(2))
    x, box = jammed.position, jammed.box
    contact = {tuple(c) for c in jammed.contacts}
    pairs = set(zip(links.i.tolist(), links.j.tolist()))
    bonds = pairs & contact
    assert len(bonds) == 12  # no contact link is ever redundant
    # every link holds at the current configuration
    assert np.max(np.abs(links.length_errors(x, box))) <= 1e-14
    # every bond angle is frozen, so in 2D every cemented cluster is rigid: 3 rigid-body modes
    labels = links.clusters(jammed.n)
    sizes = np.bincount(labels)
    assert sizes.max() >= 3  # some angle was created
    for c in np.flatnonzero(sizes > 1):
        assert _floppy_modes(links, x, box, np.flatnonzero(labels == c)) == 3


def test_link_file_and_bad_input(tmp_path, capsys, jammed):
    path = tmp_path / "j.nc"
    write_packing(jammed.evolve(contacts=None, force=None, rattler=None), path)
    good = tmp_path / "links.txt"
    c = jammed.contacts[0]
    good.write_text(f"# i j [length]\n{c[0]} {c[1]}\n")
    assert main(["link", str(path), str(tmp_path / "l.nc"), "--file", str(good), "--quiet"]) == 0
    out = read_packing(tmp_path / "l.nc", None)
    r = np.linalg.norm(jammed.box.minimum_image(jammed.position[c[1]] - jammed.position[c[0]]))
    assert len(out.links) == 1 and out.links.length[0] == pytest.approx(r, rel=1e-14)
    assert read_link_file(good, jammed.position, jammed.box)[0].tolist() == [c.tolist()]
    capsys.readouterr()
    # inconsistent lengths: a triangle 1, 1, 2.5 cannot close
    bad = tmp_path / "bad.txt"
    k = next(int(b) for a, b in jammed.contacts if a == c[1] and b != c[0])  # a neighbour of c[1]
    bad.write_text(f"{c[0]} {c[1]} 1.0\n{c[1]} {k} 1.0\n{c[0]} {k} 2.5\n")
    assert main(["link", str(path), str(tmp_path / "b.nc"), "--file", str(bad)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "link lengths are inconsistent" in err
    assert not (tmp_path / "b.nc").exists()
    bad.write_text("0 1 2 3\n")
    assert main(["link", str(path), str(tmp_path / "b.nc"), "--file", str(bad)]) == 1
    assert "expected 'i j [length]'" in capsys.readouterr().err


def test_crossing_links_and_huge_clusters_are_refused_at_the_start():
    box = Box.cubic(2, 10.0)
    x = np.array([[4.5, 5.0], [5.5, 5.0], [5.0, 4.5], [5.0, 5.5], [1.0, 1.0], [2.0, 1.0]])
    crossed = Packing(x, np.full(6, 0.5), box, links=Links(np.array([0, 2]), np.array([1, 3]), np.ones(2)))
    with pytest.raises(ValueError, match="links cross in 2D"):
        check_linked_start(crossed)
    # a chain of 9 bonds along x spans 9 > 10 / 2
    x = np.stack([np.arange(10) * 1.0 + 0.5, np.full(10, 5.0)], axis=1)
    chain = Links(np.arange(9), np.arange(1, 10), np.ones(9))
    assert cluster_extent(chain, x, box)[0] == pytest.approx(9.0, rel=1e-14)
    with pytest.raises(ValueError, match="more than half the smallest box width"):
        check_linked_start(Packing(x, np.ones(10), box, links=chain))
    # a ring winding around the box has infinite extent
    ring = Links(np.r_[np.arange(9), 0], np.r_[np.arange(1, 10), 9], np.ones(10))
    assert np.isinf(cluster_extent(ring, x, box)[0])


def test_cli_init_chains(tmp_path, capsys):
    out = tmp_path / "c.nc"
    assert main(["init-chains", str(out), "--d", "2", "--clusters", "30", "--cluster", "trimer", "--seed", "4"]) == 0
    text = capsys.readouterr().out
    p = read_packing(out, None)
    assert p.n == 90 and len(p.links) == 90 and p.seed == 4
    rows = dict(line.split(None, 1) for line in text.splitlines()[1:] if line.startswith("  links "))
    assert rows["links"].strip() == "90"
    assert len(crossing_links(p.links, p.position, p.box)) == 0
    # the default start is the dilute one without overlaps (overlapping starts entangle, docs/chains.md);
    # --overlap gives the paper's start above jamming, with overlaps
    from jamflow.chains.builders import DILUTE_PHI, OVERLAP_PHI
    from jamflow.tolerances import OVERLAP_TOL

    assert p.packing_fraction == pytest.approx(DILUTE_PHI[2], rel=1e-12)
    p.validate(OVERLAP_TOL)
    assert main(["init-chains", str(tmp_path / "o.nc"), "--d", "2", "--clusters", "30", "--cluster", "trimer",
                 "--overlap", "--seed", "4", "--quiet"]) == 0
    q = read_packing(tmp_path / "o.nc", None)
    assert q.packing_fraction == pytest.approx(OVERLAP_PHI[2], rel=1e-12)
    with pytest.raises(ValueError, match="overlap"):
        q.validate(OVERLAP_TOL)
    # and in 3D it places chains longer than trimers too (64 chains of 4 fail at 0.2)
    assert main(["init-chains", str(tmp_path / "c4.nc"), "--d", "3", "--clusters", "64", "--cluster", "chain",
                 "--chain-length", "4", "--seed", "2", "--quiet"]) == 0
    c4 = read_packing(tmp_path / "c4.nc", None)
    assert c4.packing_fraction == pytest.approx(DILUTE_PHI[3], rel=1e-12)
    c4.validate(OVERLAP_TOL)
    with pytest.raises(SystemExit) as usage:
        main(["init-chains", str(tmp_path / "x.nc"), "--d", "4", "--clusters", "3", "--cluster", "trimer",
              "--seed", "1"])
    assert usage.value.code == 2 and "--d" in capsys.readouterr().err


def test_cli_cement_records_the_cemented_contacts_not_the_angle_links(tmp_path, jammed):
    """n_l of paper Fig. 5 counts the contacts made links, not the links freezing bond angles."""
    write_packing(jammed, tmp_path / "j.nc")
    assert main(["link", str(tmp_path / "j.nc"), str(tmp_path / "c.nc"), "--cement", "12", "--seed", "2",
                 "--quiet"]) == 0
    p = read_packing(tmp_path / "c.nc", None)
    links, _ = cement(jammed, 12, np.random.default_rng(2))
    assert len(p.links) == len(links) > 12  # angle links were added
    assert p.attrs["n_cemented"] == 12
    # a second round adds to the count
    assert main(["link", str(tmp_path / "c.nc"), str(tmp_path / "c2.nc"), "--cement", "3", "--seed", "4",
                 "--quiet"]) == 0
    assert read_packing(tmp_path / "c2.nc", None).attrs["n_cemented"] == 15


@pytest.mark.parametrize("d", [2, 3])
def test_no_overlap_placement_is_a_hard_sphere_start(d, tmp_path):
    from jamflow.tolerances import OVERLAP_TOL

    p, _ = linked_packing(d, 30, "trimer", np.random.default_rng(2), phi=0.2, no_overlap=True)
    p.validate(OVERLAP_TOL)  # raises OverlapError on any overlap beyond the hard-sphere tolerance
    # the paper's placement with overlaps of the same draw does overlap
    q, _ = linked_packing(d, 30, "trimer", np.random.default_rng(2), phi=0.2, no_overlap=False)
    with pytest.raises(ValueError, match="overlap"):
        q.validate(OVERLAP_TOL)


@pytest.mark.parametrize("d", [2, 3])
def test_long_chains_grow_without_overlaps_or_crossings(d):
    """Paper Fig. 4: chains of 30 spheres placed by the growth walk (the whole-chain draw failed at
    M = 30 in 2D for every seed tried): a hard-sphere start, bonds of contact length, no crossing links,
    every chain within half the box (check_linked_start ran), f = d M - (M - 1) per flexible chain."""
    from jamflow.tolerances import OVERLAP_TOL

    p, messages = linked_packing(d, 4, "chain", np.random.default_rng(1), chain_length=30, free_angles=True)
    assert messages == [] and p.n == 120 and len(p.links) == 4 * 29
    p.validate(OVERLAP_TOL)
    np.testing.assert_allclose(np.linalg.norm(p.box.minimum_image(p.position[p.links.j] - p.position[p.links.i]),
                                              axis=1), 1.0, rtol=1e-14)
    if d == 2:
        assert len(crossing_links(p.links, p.position, p.box)) == 0
    members = np.flatnonzero(p.clusters == 2)
    assert _floppy_modes(p.links, p.position, p.box, members) == d * 30 - 29


def test_semi_flexible_chains_freeze_angles_by_rule_or_probability():
    m = 9
    p, _ = linked_packing(3, 6, "chain", np.random.default_rng(2), chain_length=m, frozen_every=2)
    angle = p.links.j - p.links.i == 2
    # the angles at spheres 2, 4, 6 of each chain: links (1, 3), (3, 5), (5, 7) in chain coordinates
    first = p.links.i[angle] % m
    assert sorted(set(first.tolist())) == [1, 3, 5] and angle.sum() == 6 * 3
    assert p.attrs["n_frozen_angles"] == 18 and p.attrs["frozen_angle_rule"] == "every 2"
    q, _ = linked_packing(3, 6, "chain", np.random.default_rng(2), chain_length=m, frozen_fraction=0.5)
    r, _ = linked_packing(3, 6, "chain", np.random.default_rng(2), chain_length=m, frozen_fraction=0.5)
    assert np.array_equal(q.links.i, r.links.i) and 0 < q.attrs["n_frozen_angles"] < 6 * (m - 2)
    # degrees of freedom: d m - bonds - frozen angles (3D: a frozen angle removes one)
    members = np.flatnonzero(q.clusters == 0)
    n_angles = int(np.sum((q.links.j - q.links.i == 2) & np.isin(q.links.i, members)))
    assert _floppy_modes(q.links, q.position, q.box, members) == 3 * m - (m - 1) - n_angles
    with pytest.raises(ValueError, match="semi-flexible"):
        linked_packing(2, 4, "trimer", np.random.default_rng(1), frozen_every=2)


@pytest.mark.parametrize("per", ["cluster", "sphere"])
def test_mixed_sizes_of_chains(per):
    """Bidisperse clusters (a scaled copy each, half small) or polydisperse spheres; bonds are contact distances."""
    from jamflow.chains.builders import Sizes
    from jamflow.tolerances import OVERLAP_TOL

    sizes = Sizes("bi", 1.4, 0.5, per=per) if per == "cluster" else Sizes("poly", width=0.2, per=per)
    p, _ = linked_packing(2, 20, "trimer", np.random.default_rng(4), sizes=sizes)
    p.validate(OVERLAP_TOL)
    D = p.diameter.reshape(20, 3)
    if per == "cluster":
        assert np.all(D == D[:, :1]) and sorted(set(D[:, 0].tolist())) == [1.0, 1.4]
        assert np.sum(D[:, 0] == 1.0) == 10 and p.attrs["length_unit"] == "small sphere diameter"
    else:
        assert 0.8 <= D.min() < D.max() <= 1.2 and len(set(D.ravel().tolist())) == 60
    bonds = p.links.j - p.links.i == 1
    r = np.linalg.norm(p.box.minimum_image(p.position[p.links.j] - p.position[p.links.i]), axis=1)
    np.testing.assert_allclose(r[bonds], 0.5 * (p.diameter[p.links.i] + p.diameter[p.links.j])[bonds], rtol=1e-14)
    # the box is set from whole spheres; unequal next-nearest spheres at a frozen angle may share a lens
    assert p.attrs["dispersity"] == sizes.dispersity and p.packing_fraction == pytest.approx(0.2, rel=1e-3)
    assert p.packing_fraction <= 0.2 * (1 + 1e-12)
    with pytest.raises(ValueError, match="dimers are bidisperse"):
        linked_packing(2, 4, "dimer", np.random.default_rng(1), sizes=sizes)


def test_check_of_a_dilute_start_is_not_isostatic(tmp_path, capsys):
    """0 contacts: every cluster rattles, there is no backbone, and that is not isostatic."""
    import json

    assert main(["init-chains", str(tmp_path / "s.nc"), "--d", "2", "--clusters", "10", "--cluster", "trimer",
                 "--seed", "1", "--quiet"]) == 0
    assert main(["check", str(tmp_path / "s.nc"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_contacts"] == 0 and report["isostatic_count"] == 0
    assert report["isostatic"] is False and report["rigidity_counting"] == "no backbone"
    assert report["n_rattling_clusters"] == report["n_clusters_removed"] == 10
