"""Counting of clusters by rank (jamflow.network.bodies): free motions, rattling clusters, danglers, N_iso.

Hand-built clusters beside a held frame of free spheres (each frame sphere touches every
other one); only the links' geometry and which spheres touch enter the counting.
"""

from __future__ import annotations

import numpy as np
import pytest
from ls_data import ls_dat

from jamflow.box import Box
from jamflow.io.formats import read_dat
from jamflow.network import count_bodies, isostatic_count, prune_rattlers
from jamflow.state.bodies import Links
from jamflow.state.packing import near_pairs

FRAME = 6  # frame spheres, all touching each other


def _setup(d, cluster_position, links):
    """Cluster spheres first, then the frame far away; returns (position, box, links, frame indices, frame contacts)."""
    k = len(cluster_position)
    frame_position = 10.0 + np.random.default_rng(0).uniform(-1, 1, (FRAME, d))
    position = np.vstack([cluster_position, frame_position])
    frame = np.arange(k, k + FRAME)
    contacts = [(a, b) for a in frame for b in frame if a < b]
    L = Links(np.array([i for i, _ in links]), np.array([j for _, j in links]),
              np.linalg.norm(np.array([position[j] - position[i] for i, j in links]), axis=1))
    return position, Box.cubic(d, 40.0), L, frame, contacts


def _count(d, cluster_position, links, touching):
    """Count with ``touching`` = [(cluster sphere, number of frame spheres it touches)]."""
    position, box, L, frame, contacts = _setup(d, np.asarray(cluster_position, float), links)
    for sphere, k in touching:
        contacts += [(sphere, int(f)) for f in frame[:k]]
    return count_bodies(np.array(contacts), len(position), d, L, position, box), position


TRIMER_2D = [[0.0, 0.0], [1.0, 0.0], [1.5, 0.8]]
RIGID_TRIMER = [(0, 1), (1, 2), (0, 2)]


def test_trimer_touching_through_one_sphere_swings_about_it():
    """The issue's defect: 3 contacts on the middle sphere hold it; the trimer turns freely about it."""
    count, position = _count(2, TRIMER_2D, RIGID_TRIMER, [(1, 3)])
    assert count.dofs[0] == 3 and count.free_dofs[0] == 1 and not count.removed[0]
    assert count.dangler[:3].tolist() == [True, False, True]
    assert count.rattling_cluster[0] and count.as_dict()["n_rattling_clusters"] == 1
    # backbone: the held sphere (3 - 1 = 2) and the frame (2 each); N_iso = 14 - 2 + 1
    assert count.backbone_dofs == 2 + 2 * FRAME
    assert count.isostatic_count == 13 and count.n_contacts == 15 + 3
    # the free motion is the rotation about sphere 1: sphere 1 at rest, the others perpendicular to their arms
    motion = count.free_motions.toarray()[:, 0].reshape(-1, 2)
    assert np.allclose(motion[1], 0.0, atol=1e-14) and np.allclose(motion[3:], 0.0)
    for s in (0, 2):
        assert motion[s] @ (position[s] - position[1]) == pytest.approx(0.0, abs=1e-14)
    arm = np.linalg.norm(position[[0, 2]] - position[1], axis=1)
    np.testing.assert_allclose(np.linalg.norm(motion[[0, 2]], axis=1) / arm, 1.0 / np.linalg.norm(arm), rtol=1e-12)


def test_swinging_trimer_with_too_few_contacts_rattles_whole():
    """Two contacts on the held sphere cannot balance it (f - m + 1 = 3): the whole trimer leaves."""
    count, _ = _count(2, TRIMER_2D, RIGID_TRIMER, [(1, 2)])
    assert count.removed[0] and count.rattler[:3].all() and not count.dangler.any()
    assert count.n_contacts == 15 and count.isostatic_count == 2 * FRAME - 2 + 1


def test_trimer_touching_through_two_spheres_has_no_free_motion():
    """Two touching spheres fix a rigid body in 2D: m = 0, so it needs f + 1 = 4 contacts."""
    count, _ = _count(2, TRIMER_2D, RIGID_TRIMER, [(0, 2), (1, 2)])
    assert count.free_dofs[0] == 0 and not count.rattler[:3].any()
    count, _ = _count(2, TRIMER_2D, RIGID_TRIMER, [(0, 1), (1, 2)])
    assert count.removed[0]


def test_3d_trimer_held_by_two_spheres_spins_about_their_axis():
    """3D: contacts on spheres 0 and 1 leave the spin about the 0-1 axis (sphere 2 moves)."""
    trimer = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.5, 0.8, 0.1]]
    count, position = _count(3, trimer, RIGID_TRIMER, [(0, 3), (1, 3)])
    assert count.dofs[0] == 6 and count.free_dofs[0] == 1
    assert count.dangler[:3].tolist() == [False, False, True]
    motion = count.free_motions.toarray()[:9, 0].reshape(3, 3)
    axis = position[1] - position[0]
    assert abs(motion[2] @ axis) <= 1e-14 and abs(motion[2] @ (position[2] - position[0])) <= 1e-14
    # 6 contacts are f - m + 1: held; 5 are not
    assert not count.removed[0]
    assert _count(3, trimer, RIGID_TRIMER, [(0, 3), (1, 2)])[0].removed[0]


def test_3d_trimer_held_by_one_sphere_turns_three_ways():
    count, _ = _count(3, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.5, 0.8, 0.1]], RIGID_TRIMER, [(1, 4)])
    assert count.free_dofs[0] == 3 and count.dangler[:3].tolist() == [True, False, True]
    assert count.backbone_dofs == 3 + 3 * FRAME


def test_chain_end_dangles_and_a_held_chain_does_not():
    """Fig. 4: a flexible chain whose end touches nothing: the end turns about its link partner."""
    chain = [[0.0, 0.0], [1.0, 0.0], [1.6, 0.8]]
    bonds = [(0, 1), (1, 2)]
    count, _ = _count(2, chain, bonds, [(0, 2), (1, 2)])
    assert count.dofs[0] == 4 and count.free_dofs[0] == 1
    assert count.dangler[:3].tolist() == [False, False, True]
    count, _ = _count(2, chain, bonds, [(0, 2), (1, 2), (2, 1)])
    assert count.free_dofs[0] == 0 and not count.rattler[:3].any()


def test_middle_of_a_chain_held_at_both_ends_is_free():
    """A four-bar linkage: chain 0-1-2-3 held at 0 and 3 only; 1 and 2 move (old counting missed it)."""
    chain = [[0.0, 0.0], [0.8, 0.6], [1.8, 0.6], [2.4, 0.0]]
    count, _ = _count(2, chain, [(0, 1), (1, 2), (2, 3)], [(0, 3), (3, 3)])
    assert count.dofs[0] == 5 and count.free_dofs[0] == 1
    assert count.dangler[:4].tolist() == [False, True, True, False]
    assert count.backbone_dofs == 4 + 2 * FRAME


def test_a_contact_inside_a_cluster_counts_and_bears():
    """A contact between the ends of a flexible chain makes both ends contact-bearing and counts once."""
    chain = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]]
    position, box, L, frame, contacts = _setup(2, np.array(chain), [(0, 1), (1, 2)])
    contacts += [(0, 2)] + [(1, int(f)) for f in frame[:3]]
    count = count_bodies(np.array(contacts), len(position), 2, L, position, box)
    # f = 4; bearing spheres 0, 1, 2: no free motion; 4 live contacts < 5: rattles whole
    assert count.free_dofs[0] == 0 and count.removed[0]
    contacts.append((0, int(frame[0])))
    count = count_bodies(np.array(contacts), len(position), 2, L, position, box)
    assert not count.removed[0] and count.n_contacts == 15 + 5


def test_removing_a_cluster_frees_its_neighbour():
    """Iteration: trimer B (3 contacts, needs 4) rattles; then trimer A, which had 4 with B's, has 3 and rattles."""
    both = np.vstack([TRIMER_2D, np.array(TRIMER_2D) + 4.0])
    position, box, L, frame, contacts = _setup(2, both, RIGID_TRIMER + [(3, 4), (4, 5), (3, 5)])
    contacts += [(0, int(frame[0])), (0, int(frame[1])), (1, int(frame[2])), (2, 3), (4, int(frame[3])),
                 (4, int(frame[4]))]
    count = count_bodies(np.array(contacts), len(position), 2, L, position, box)
    assert count.removed[:2].all() and count.rattler[:6].all()
    assert count.n_contacts == 15 and count.isostatic_count == 2 * FRAME - 2 + 1


def test_no_contacts_is_not_isostatic():
    count, _ = _count(2, TRIMER_2D, RIGID_TRIMER, [])
    empty = count_bodies(np.empty((0, 2), np.int64), count.cluster.size, 2,
                         Links(np.array([0, 1, 0]), np.array([1, 2, 2]), np.ones(3)),
                         np.vstack([TRIMER_2D, np.zeros((FRAME, 2)) + 10 + np.arange(FRAME)[:, None]]),
                         Box.cubic(2, 40.0))
    assert empty.isostatic_count == 0 and empty.n_contacts == 0 and not empty.isostatic
    assert empty.as_dict()["isostatic"] is False and empty.as_dict()["rigidity_counting"] == "no backbone"


def test_links_need_geometry():
    with pytest.raises(ValueError, match="centres and the box"):
        count_bodies(np.empty((0, 2), np.int64), 3, 2, Links(np.array([0]), np.array([1]), np.ones(1)))


@pytest.mark.parametrize("d", [3, 4])
def test_spheres_by_rank_are_the_coordination_pruning(d):
    """Free spheres: the rank test reduces to fewer than d + 1 contacts, and N_iso to d (N_s - 1) + 1.

    A real LS configuration (CALiPPSO authors, N = 1024) with pairs within a gap of 1e-3
    (many rattlers), and random sparse graphs; numpy rounds, the compiled peel and the rank
    test agree.
    """
    pairs, _ = near_pairs(read_dat(ls_dat(d)), 1e-3)
    graphs = [np.stack([pairs.i, pairs.j], axis=1)]
    rng = np.random.default_rng(1)
    for m in (3500, 5000, 6000):
        c = np.sort(rng.integers(0, 1024, (m, 2)), axis=1)
        graphs.append(np.unique(c[c[:, 0] < c[:, 1]], axis=0))
    for c in graphs:
        want = prune_rattlers(c, 1024, dofs_per_body=d)
        assert 0 < want.sum() < 1024
        for kw in ({}, {"compiled": True}, {"by_rank": True}):
            count = count_bodies(c, 1024, d, **kw)
            assert np.array_equal(count.rattler, want)
            assert count.isostatic_count == isostatic_count(int((~want).sum()), d, global_dofs=d)
            live = ~(want[c[:, 0]] | want[c[:, 1]])
            assert count.n_contacts == live.sum()
