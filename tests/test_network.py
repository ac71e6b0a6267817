"""The contact-network core: Jacobian against finite differences, pruning, counts, self stress."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from jamflow.box import Box
from jamflow.network import (
    ContactSet,
    contact_jacobian,
    find_sliders,
    isostatic_count,
    jacobian_rank,
    link_jacobian,
    pair_rows,
    prune_rattlers,
    prune_unheld,
    self_stresses,
    sphere_contacts,
    strain_basis,
)
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure
from jamflow.state.bodies import Links

#: central finite-difference step [length, rad, strain]; truncation error ~ STEP^2
STEP = 1e-6
#: agreement of analytic and finite-difference derivatives (round-off of gap / STEP ~ 1e-10)
FD_TOL = 1e-8


def _fd(fun, q: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``q``, shape (len(fun(q)), len(q))."""
    cols = []
    for k in range(len(q)):
        e = np.zeros_like(q)
        e[k] = STEP
        cols.append((fun(q + e) - fun(q - e)) / (2 * STEP))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("d", [2, 3])
def test_sphere_jacobian_with_strain_matches_finite_differences(d: int) -> None:
    rng = np.random.default_rng(4)
    n = 12
    box = Box(np.triu(rng.uniform(-0.3, 0.3, (d, d)), 1) + np.diag(rng.uniform(2.5, 3.5, d)))
    x = rng.uniform(0, 1, (n, d)) @ box.matrix.T
    sigma = rng.uniform(0.8, 1.2, n)
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])[::3]
    cs = sphere_contacts(x, box, pairs)
    images = np.rint((x[pairs[:, 0]] + cs.separation - x[pairs[:, 1]]) @ box.inverse.T)
    basis = strain_basis(d, volume_preserving=False)
    n_dof = n * d + len(basis)

    def gaps(q: np.ndarray) -> np.ndarray:
        # strain maps centres and lattice alike: x -> (I + eps) x, h -> (I + eps) h
        F = np.eye(d) + np.einsum("k,kab->ab", q[n * d:], basis)
        y = (x + q[:n * d].reshape(n, d)) @ F.T
        h = F @ box.matrix
        s = y[pairs[:, 1]] - y[pairs[:, 0]] + images @ h.T
        return np.linalg.norm(s, axis=1) - 0.5 * (sigma[pairs[:, 0]] + sigma[pairs[:, 1]])

    J = contact_jacobian(cs, n, d, strain="symmetric")
    assert J.shape == (len(pairs), n_dof)
    assert J.has_canonical_format
    np.testing.assert_allclose(J.toarray(), _fd(gaps, np.zeros(n_dof)), atol=FD_TOL, rtol=0)


def _lobe_bodies():
    """Two 2D bodies, each a disk of radius a whose centre sits off the body centre.

    Body k has centre X_k, orientation theta_k and a lobe (disk of radius a_k) at
    X_k + R(theta_k) o_k, like one lobe of a dumbbell. The gap of the lobes,
    |c_j - c_i| - a_i - a_j, is the exact gap of the bodies where they touch.
    """
    X = np.array([[0.3, 0.2], [2.1, 0.9]])
    theta = np.array([0.4, -1.1])
    o = np.array([[0.35, 0.1], [-0.2, 0.3]])
    a = np.array([0.6, 0.5])
    return X, theta, o, a


def _rot(t: float) -> np.ndarray:
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def test_rotation_and_strain_columns_of_off_centre_bodies_match_finite_differences() -> None:
    X, theta, o, a = _lobe_bodies()
    basis = strain_basis(2, volume_preserving=False)

    def lobes(X_, th):
        return np.array([X_[k] + _rot(th[k]) @ o[k] for k in range(2)])

    c = lobes(X, theta)
    s_lobe = c[1] - c[0]
    normal = s_lobe / np.linalg.norm(s_lobe)
    arm_i = c[0] - X[0] + a[0] * normal
    arm_j = c[1] - X[1] - a[1] * normal
    cs = ContactSet([0], [1], normal[None], (X[1] - X[0])[None], arm_i[None], arm_j[None])

    def gaps(q: np.ndarray) -> np.ndarray:
        # strain moves the centres affinely; the bodies stay rigid
        F = np.eye(2) + np.einsum("k,kab->ab", q[6:], basis)
        Xq = (X + q[:4].reshape(2, 2)) @ F.T
        cq = lobes(Xq, theta + q[4:6])
        return np.array([np.linalg.norm(cq[1] - cq[0]) - a.sum()])

    J = contact_jacobian(cs, 2, 2, rotations=True, strain="symmetric")
    assert J.shape == (1, 2 * 2 + 2 + 3)
    fd = _fd(gaps, np.zeros(9))
    assert np.abs(fd[0, 4:6]).min() > 0.05  # the arms really exert torques
    np.testing.assert_allclose(J.toarray(), fd, atol=FD_TOL, rtol=0)
    # the same contact listed as (j, i) gives the same row
    swapped = ContactSet([1], [0], -normal[None], (X[0] - X[1])[None], arm_j[None], arm_i[None])
    np.testing.assert_allclose(contact_jacobian(swapped, 2, 2, rotations=True, strain="symmetric").toarray(),
                               J.toarray(), atol=1e-15, rtol=0)


def test_rotations_need_arms_and_two_dimensions() -> None:
    box = Box.cubic(2, 5.0)
    cs = sphere_contacts(np.array([[1.0, 1.0], [2.0, 1.0]]), box, [[0, 1]])
    with pytest.raises(ValueError, match="arms"):
        contact_jacobian(cs, 2, rotations=True)
    cs3 = sphere_contacts(np.array([[1.0, 1.0, 1.0], [2.0, 1.0, 1.0]]), Box.cubic(3, 5.0), [[0, 1]],
                          radius=np.array([0.5, 0.5]))
    with pytest.raises(ValueError, match="2D"):
        contact_jacobian(cs3, 2, rotations=True)


def test_link_rows_match_finite_differences_of_link_lengths() -> None:
    rng = np.random.default_rng(1)
    box = Box.cubic(3, 4.0)
    x = rng.uniform(0, 4.0, (5, 3))
    links = Links(np.array([0, 1, 2]), np.array([1, 3, 4]), np.ones(3))
    dx = box.minimum_image(x[links.j] - x[links.i])
    J = link_jacobian(links, x, box, strain="traceless")
    basis = strain_basis(3, volume_preserving=True)

    def lengths(q: np.ndarray) -> np.ndarray:
        F = np.eye(3) + np.einsum("k,kab->ab", q[15:], basis)
        y = q[:15].reshape(5, 3)
        return np.linalg.norm((dx + y[links.j] - y[links.i]) @ F.T, axis=1)

    np.testing.assert_allclose(J.toarray(), _fd(lengths, np.zeros(15 + len(basis))), atol=FD_TOL, rtol=0)


def _k4_plus_tail() -> np.ndarray:
    """K4 on 0..3 (three contacts each), body 4 on 0 and 1, body 5 on 4, 2 and 3."""
    return np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3], [0, 4], [1, 4], [2, 5], [3, 5], [4, 5]])


def test_pruning_cascades_and_walls_hold() -> None:
    c = _k4_plus_tail()
    # 2D: body 4 has 3 contacts (0, 1, 5), body 5 has 3: nothing rattles
    assert not prune_rattlers(c, 6, dofs_per_body=2).any()
    # without the contact 4-5 both have two: both rattle, the K4 stays
    r = prune_rattlers(c[:-1], 6, dofs_per_body=2)
    np.testing.assert_array_equal(r, [0, 0, 0, 0, 1, 1])
    # drop 1-4: body 4 rattles, then body 5 is left with two contacts (cascade)
    r = prune_rattlers(np.delete(c, 7, axis=0), 6, dofs_per_body=2)
    np.testing.assert_array_equal(r, [0, 0, 0, 0, 1, 1])
    # ... unless body 4 touches a wall
    r = prune_rattlers(np.delete(c, 7, axis=0), 6, dofs_per_body=2, wall_contacts=[4])
    assert not r.any()
    # rotating 2D bodies need four contacts: the whole graph rattles
    assert prune_rattlers(c, 6, dofs_per_body=3).all()
    # bodies removed earlier neither count nor are reported again
    active = np.array([1, 1, 1, 1, 0, 1], dtype=bool)
    np.testing.assert_array_equal(prune_rattlers(c, 6, dofs_per_body=2, active=active), [0, 0, 0, 0, 0, 1])


def test_compiled_peeling_removes_the_rattlers_of_the_numpy_rounds() -> None:
    """The numba kernel (one pass with a stack) and the numpy rounds remove the same bodies: on the
    cascade above with walls and earlier removals, and on 300 random graphs of every density."""
    c = _k4_plus_tail()
    cases = [(6, c, {}), (6, c[:-1], {}), (6, np.delete(c, 7, axis=0), {}),
             (6, np.delete(c, 7, axis=0), {"wall_contacts": [4]}),
             (6, c, {"active": np.array([1, 1, 1, 1, 0, 1], dtype=bool)}), (3, np.zeros((0, 2), dtype=np.int64), {})]
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(2, 60))
        m = int(rng.integers(0, 4 * n))
        pairs = np.sort(rng.integers(0, n, size=(m, 2)), axis=1)
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        kw = {"wall_contacts": rng.integers(0, n, size=int(rng.integers(0, 5)))} if rng.random() < 0.3 else {}
        if rng.random() < 0.3:
            kw["active"] = rng.random(n) < 0.8
        cases.append((n, pairs, kw))
    removed = 0
    for n, pairs, kw in cases:
        for f in (2, 3):
            ref = prune_rattlers(pairs, n, dofs_per_body=f, **kw)
            np.testing.assert_array_equal(prune_rattlers(pairs, n, dofs_per_body=f, compiled=True, **kw), ref)
            removed += int(ref.sum())
    assert removed > 1000  # the random graphs do peel


def test_slider_is_the_body_whose_normals_leave_one_translation_free() -> None:
    # 2D discs: body 0 pressed from above and below only (three normals along y)
    x = np.array([[0.0, 0.0], [0.3, 1.0], [-0.3, 1.0], [0.0, -1.0]])
    box = Box.cubic(2, 20.0)
    pairs = np.array([[0, 1], [0, 2], [0, 3]])
    cs = sphere_contacts(x, box, pairs)
    cs = ContactSet(cs.i, cs.j, np.tile([0.0, 1.0], (3, 1)) * np.sign(cs.separation[:, 1:2]), cs.separation)
    J = contact_jacobian(cs, 4)
    # (bodies 1-3 stand for fixed neighbours; only body 0 is asked about)
    assert find_sliders(J, cs, 4, 2)[0]
    # tilt one normal: the x translation is blocked too
    tilted = ContactSet(cs.i, cs.j, np.array([[0.6, 0.8], [0.0, 1.0], [0.0, -1.0]]), cs.separation)
    assert not find_sliders(contact_jacobian(tilted, 4), tilted, 4, 2)[0]


def test_a_body_pinched_between_two_antiparallel_contacts_is_held_not_a_rattler() -> None:
    """A periodic 4 x 4 square network (every body four contacts) and body 16 touching only
    bodies 0 and 1 (normals given): with antiparallel normals it carries force along their
    line, prune_unheld keeps it and find_sliders calls it a slider, while prune_rattlers'
    count removes it; tilted normals cannot balance it, nor can two pushing the same way,
    and one contact never can."""
    side = 4
    rows, normals = [], []
    for a in range(side * side):
        r, c = divmod(a, side)
        for b, n in ((r * side + (c + 1) % side, (1.0, 0.0)), (((r + 1) % side) * side + c, (0.0, 1.0))):
            rows.append((a, b))
            normals.append(n)

    def network(extra_normals):
        i = [p[0] for p in rows] + [0, 1][: len(extra_normals)]
        j = [p[1] for p in rows] + [16, 16][: len(extra_normals)]
        n = np.array(normals + list(extra_normals), dtype=float)
        return ContactSet(i, j, n, n)

    for extra, held in ((((0.0, 1.0), (0.0, -1.0)), True), (((0.0, 1.0), (0.3, -0.95)), False),
                        (((0.0, 1.0), (0.0, 1.0)), False), (((0.0, 1.0),), False)):
        cs = network(extra)
        rattler = prune_unheld(cs, 17)
        assert rattler[16] == (not held) and not rattler[:16].any()
        assert prune_rattlers(cs, 17, dofs_per_body=2)[16]
        if held:
            assert find_sliders(contact_jacobian(cs, 17), cs, 17, 2, rattler=rattler)[16]


@pytest.mark.parametrize("tilt, slides", [(1e-12, True), (1e-8, True), (1e-4, False)])
def test_slider_by_rank_within_the_zero_mode_floor(tilt, slides) -> None:
    """A normal tilted by ``tilt`` leaves the slide a stiffness ``~ k tilt^2``: below the
    spectrum's zero-mode floor (~1e-12 k, SLIDER_RTOL = 1e-6 on the singular values) the
    body slides; a numerically exact rank test (rtol 1e-10) missed tilts of 1e-8. The
    lever arms give the rotation column; with them the body's own block has rank 2 and its
    kernel is the slide (no rotation), whatever the arms."""
    from jamflow.tolerances import SLIDER_RTOL

    normal = np.array([[np.sin(tilt), np.cos(tilt)], [0.0, 1.0], [0.0, -1.0]])
    arm = np.array([[0.3, 0.2], [-0.4, 0.2], [0.1, -0.2]])
    sep = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, -1.0]])
    cs = ContactSet([0, 0, 0], [1, 2, 3], normal, sep, arm, arm - sep)
    J = contact_jacobian(cs, 4, 2, rotations=True)
    assert find_sliders(J, cs, 4, 2)[0] == slides
    s = np.linalg.svd(normal, compute_uv=False)
    assert (s[-1] <= SLIDER_RTOL * s[0]) == slides
    # a body with fewer contacts than d keeps a free translation by construction
    one = ContactSet([0], [1], normal[1:2], sep[1:2], arm[1:2], arm[1:2] - sep[1:2])
    assert find_sliders(contact_jacobian(one, 2, 2, rotations=True), one, 2, 2)[0]


def test_isostatic_count_conventions() -> None:
    for d in (2, 3, 4):
        for n in (1, 2, 17):
            assert isostatic_count(n, d, global_dofs=d) == d * (n - 1) + 1  # periodic spheres
            assert isostatic_count(n, d, global_dofs=0) == d * n + 1  # spheres between walls
    assert isostatic_count(10, 3, global_dofs=2) == 3 * 10 - 1  # rotating 2D bodies (van der Werf)
    # van der Werf et al. Fig. 3a: 10 non-rotating circulo-lines, one rattler, one slider: 2 N - 4
    assert isostatic_count(9, 2, global_dofs=2, n_sliders=1) == 2 * 10 - 4
    assert isostatic_count(0, 3, global_dofs=3) == 0


@pytest.fixture(scope="module")
def soft_jammed():
    """32 bidisperse soft discs jammed at P0 = 1e-6 (harmonic), with their overlapping pairs."""
    return jam_to_pressure(random_packing(32, 2, 0.3, "bi", 1, 1.4, 0.5, 0.1), pressure=1e-6).packing


def test_jammed_backbone_is_isostatic_with_one_positive_self_stress(soft_jammed) -> None:
    p = soft_jammed
    rattler = prune_rattlers(p.contacts, p.n, dofs_per_body=p.d)
    keep = ~(rattler[p.contacts[:, 0]] | rattler[p.contacts[:, 1]])
    stable = np.flatnonzero(~rattler)
    cs = sphere_contacts(p.position, p.box, p.contacts[keep])
    J = contact_jacobian(cs, p.n, bodies=stable)
    n_s = len(stable)
    # counting and linear algebra agree: rank = d N_s - d (only translations free), one self stress
    assert cs.n_contacts == isostatic_count(n_s, p.d, global_dofs=p.d)
    assert jacobian_rank(J)[0] == p.d * n_s - p.d
    ss = self_stresses(J)
    assert ss.shape == (cs.n_contacts, 1)
    f0 = ss[:, 0] * np.sign(ss[:, 0].sum())
    assert f0.min() > 0  # a jammed network's self stress is repulsive on every contact
    assert np.linalg.norm(J.T @ f0) < 1e-12
    # it is the soft packing's force network up to scale (force balance at P0)
    np.testing.assert_allclose(f0 / f0.sum(), p.force[keep] / p.force[keep].sum(), rtol=1e-5)
    # the sparse (shift-invert) mode finds the same null space
    ss_sparse = self_stresses(J, k=3, rtol=1e-7)
    assert ss_sparse.shape[1] == 1
    assert abs(abs(float(ss_sparse[:, 0] @ ss[:, 0])) - 1.0) < 1e-8


def test_self_stresses_count_is_contacts_minus_rank() -> None:
    rng = np.random.default_rng(0)
    J = sp.random(30, 20, density=0.2, random_state=rng, format="csr")
    assert self_stresses(J).shape == (30, 30 - jacobian_rank(J)[0])


def test_pair_rows_are_the_centre_block_of_the_contact_jacobian():
    # with unit normals the rows are the sphere Jacobian exactly; with any vectors
    # v_c = s_c n_c they are that Jacobian with row c scaled by s_c (CALiPPSO's LP rows)
    p = random_packing(40, 3, 0.3, "bi", seed=8, ratio=1.4)
    pairs = np.array([[0, 5], [3, 4], [7, 39], [2, 21]])
    cs = sphere_contacts(p.position, p.box, pairs)
    J = contact_jacobian(cs, p.n, p.d)
    R = pair_rows(pairs, cs.normal, p.n)
    assert R.shape == J.shape and (R != J).nnz == 0
    scale = np.array([0.5, 2.0, -3.0, 7.5])
    np.testing.assert_allclose(pair_rows(pairs, scale[:, None] * cs.normal, p.n).toarray(),
                               (sp.diags(scale) @ J).toarray(), rtol=1e-15, atol=0.0)
    assert pair_rows(np.zeros((0, 2), int), np.zeros((0, 3)), p.n).shape == (0, 3 * p.n)
