"""Contact network algebra, collision prediction and rewiring of the overdamped dynamics.

Physics checked: rigid contacts (S V = 0), overdamped force balance (V - V_aff = xi0 S^T f),
the velocities as the orthogonal projection of the drive (Eq. 19, against a dense pseudo-inverse),
fixed-pressure forces reproduce p (Eq. 24), collision times against a brute-force scan, and the
rewiring result satisfies Appendix A's (A6) and (A8) and is the only subset that does (brute force
over all subsets).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.protocols.overdamped.collisions import (
    FLOW_ROOM_SHARE,
    build_neighbor_list,
    next_collision,
)
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions, Integrator
from jamflow.protocols.overdamped.jamming import constrained_subset, self_stress
from jamflow.protocols.overdamped.network import (
    advance_box,
    advance_positions,
    affine_rates,
    pair_vectors,
    pair_velocities,
    solve_network,
)
from jamflow.protocols.overdamped.rewiring import admissible, rewire
from jamflow.protocols.overdamped.skin import SkinBudget
from jamflow.protocols.overdamped.solver import s_matrix


def _random_network(rng, n=10, d=2, length=5.0, n_contacts=12):
    """Random centres in a box and a random set of near pairs (geometry need not be at contact:
    Eqs. 11-19 and App. A only use S)."""
    x = rng.uniform(0, length, size=(n, d))
    box = Box.cubic(d, length)
    radius = np.full(n, 0.5)
    nl = build_neighbor_list(x, box, radius, skin=0.4 * length - 1.0)
    k = min(n_contacts, len(nl.pairs))
    pick = rng.choice(len(nl.pairs), size=k, replace=False)
    return x, box, radius, nl, pick


def _dense_projection(S):
    """I - S^T (S S^T)^+ S with a dense pseudo-inverse (an independent formula for Eq. 19)."""
    return np.eye(S.shape[1]) - S.T @ np.linalg.pinv(S @ S.T) @ S


@pytest.mark.parametrize("d", [2, 3])
def test_shear_forces_and_velocities_are_rigid_and_balanced(rng, d):
    x, box, radius, nl, pick = _random_network(rng, n=12, d=d, n_contacts=3 * d)
    pairs, images = nl.pairs[pick], nl.image[pick]
    E = np.zeros((d, d))
    E[0, 1] = 1.0
    xi0 = 0.7
    sol = solve_network(x, box.matrix, pairs, images, E, xi0=xi0)
    R = pair_vectors(x, box.matrix, pairs, images)
    S = s_matrix(pairs, R / np.linalg.norm(R, axis=1)[:, None], len(x)).toarray()
    # rigid contacts: S V = 0 with V = E x + U
    v = pair_velocities(R, pairs, sol)
    assert np.max(np.abs(v)) < 1e-12
    # drag balances contact forces: U = xi0 S^T f
    assert np.allclose(sol.velocity.ravel(), xi0 * S.T @ sol.force, atol=1e-12)
    # Eq. 19 with a dense pseudo-inverse: U = -S^T N^+ S V_aff, where S V_aff uses the contact's
    # periodic image (n . E R, Eq. 13) rather than absolute positions
    Udense = -S.T @ np.linalg.pinv(S @ S.T) @ affine_rates(R, E)
    assert np.allclose(sol.velocity.ravel(), Udense, atol=1e-10)


def test_external_force_velocities_match_projection(rng):
    x, box, radius, nl, pick = _random_network(rng, n=10, d=2, n_contacts=8)
    pairs, images = nl.pairs[pick], nl.image[pick]
    F = rng.normal(size=x.shape)
    sol = solve_network(x, box.matrix, pairs, images, np.zeros((2, 2)), external=F, xi0=2.0)
    R = pair_vectors(x, box.matrix, pairs, images)
    S = s_matrix(pairs, R / np.linalg.norm(R, axis=1)[:, None], len(x)).toarray()
    # Eq. 12: V = xi0 (I - S^T N^-1 S) F_ext
    assert np.allclose(sol.velocity.ravel(), 2.0 * _dense_projection(S) @ F.ravel(), atol=1e-10)
    assert np.max(np.abs(S @ sol.velocity.ravel())) < 1e-12


def test_fixed_pressure_forces_reproduce_pressure(rng):
    x, box, radius, nl, pick = _random_network(rng, n=12, d=2, n_contacts=14)
    pairs, images = nl.pairs[pick], nl.image[pick]
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    p = 3.5
    sol = solve_network(x, box.matrix, pairs, images, E, pressure=p, rate=1.0)
    R = pair_vectors(x, box.matrix, pairs, images)
    r = np.linalg.norm(R, axis=1)
    assert sol.force @ r / (box.volume * 2) == pytest.approx(p, rel=1e-12)
    # the compression part enters the gradient as -kappa I (Eq. 21 with inward sign of Eq. 22)
    assert np.allclose(sol.gradient, E - sol.kappa * np.eye(2))
    assert np.max(np.abs(pair_velocities(R, pairs, sol))) < 1e-12


def test_affine_rates_lees_edwards_across_boundary():
    """A contact crossing the sheared boundary changes at n . E R with its image vector."""
    box = Box.lees_edwards([4.0, 4.0], 0.3)
    x = np.array([[0.2, 0.1], [0.2 + 0.3 * 4.0 - 4.0 + 0.5, 3.9]])
    pairs = np.array([[0, 1]])
    dx = box.minimum_image(x[1] - x[0])
    images = np.rint(np.linalg.solve(box.matrix, dx - (x[1] - x[0]))).astype(np.int64)[None]
    R = pair_vectors(x, box.matrix, pairs, images)
    assert np.allclose(R[0], dx)
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    assert affine_rates(R, E)[0] == pytest.approx(R[0, 0] * R[0, 1] / np.linalg.norm(R[0]))


@pytest.mark.parametrize("d", [2, 3])
def test_next_collision_matches_brute_force_scan(rng, d):
    n = 40
    length = 8.0
    box = Box.lees_edwards([length] * d, 0.2)
    radius = rng.uniform(0.3, 0.45, size=n)
    x = rng.uniform(0, length, size=(n, d))
    nl = build_neighbor_list(x, box, radius, skin=1.0)
    # only initially separated pairs are candidates
    R0 = pair_vectors(x, box.matrix, nl.pairs, nl.image)
    skip = np.linalg.norm(R0, axis=1) <= nl.sigma
    U = rng.normal(size=(n, d))
    E = np.zeros((d, d))
    E[0, 1] = 0.8
    t, k = next_collision(x, box.matrix, nl.pairs, nl.image, nl.sigma, skip, U, E, 0.2)
    # brute force: sample the straight-line motion finely, then bisect the first crossing
    W = R0 @ E.T + U[nl.pairs[:, 1]] - U[nl.pairs[:, 0]]
    ts = np.linspace(0, 0.2, 20001)
    gaps = np.linalg.norm(R0[None] + ts[:, None, None] * W[None], axis=2) - nl.sigma[None]
    gaps[:, skip] = np.inf
    hit = np.argmax(gaps <= 0, axis=0)
    has = np.any(gaps <= 0, axis=0)
    if not has.any():
        assert k == -1
        return
    first = np.where(has, ts[hit], np.inf)
    kb = int(np.argmin(first))
    assert k == kb
    assert abs(t - first[kb]) <= ts[1]
    Rt = R0[k] + t * W[k]
    assert np.linalg.norm(Rt) == pytest.approx(nl.sigma[k], rel=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_the_flow_list_holds_every_pair_within_its_contact_distance_plus_skin(rng, d):
    """The integrator's list is the one Verlet list: each pair with r < d_i + d_j + skin, once,
    contact distances exactly d_i + d_j, images giving the minimum image, positions by index_of."""
    n, length = 80, 6.0
    box = Box.lees_edwards([length] * d, 0.3)
    radius = rng.uniform(0.25, 0.5, size=n)
    x = rng.uniform(0, length, size=(n, d))
    nl = build_neighbor_list(x, box, radius, skin=0.4)
    a, b = np.triu_indices(n, k=1)
    r = np.linalg.norm(box.minimum_image(x[b] - x[a]), axis=1)
    want = r < radius[a] + radius[b] + nl.skin
    assert want.sum() > n and (~want & (r < 2 * radius.max() + nl.skin)).any()  # per pair, not one cutoff
    assert list(zip(nl.i.tolist(), nl.j.tolist())) == list(zip(a[want].tolist(), b[want].tolist()))
    np.testing.assert_array_equal(nl.sigma, radius[nl.i] + radius[nl.j])
    assert nl.reach == 2.0 * radius.max() + nl.skin and abs(nl.skin - 0.4) < 1e-15
    np.testing.assert_allclose(pair_vectors(x, box.matrix, nl.pairs, nl.image),
                               box.minimum_image(x[nl.j] - x[nl.i]), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(nl.index_of(nl.pairs), np.arange(len(nl.i)))
    assert np.all(nl.index_of(np.stack([a[~want], b[~want]], axis=1)) == -1)


def test_the_flow_list_caps_its_skin_in_a_small_box():
    """A box with room 0.5 beside unit discs: the skin is FLOW_ROOM_SHARE of it; no room at all is refused."""
    rng = np.random.default_rng(4)
    box = Box.cubic(2, 3.0)  # half width 1.5, largest contact distance 1.0
    x = rng.uniform(0, 3.0, size=(6, 2))
    nl = build_neighbor_list(x, box, np.full(6, 0.5), skin=1.0)
    assert nl.reach == 1.0 + FLOW_ROOM_SHARE * 0.5 and nl.skin == nl.reach - 1.0
    with pytest.raises(ValueError, match="box too small"):
        build_neighbor_list(x, box, np.full(6, 0.75), skin=0.1)


def test_the_skin_budget_horizon_is_tight_for_a_head_on_pair():
    """Two discs closing head-on at the largest speed u, no shear: the horizon is skin / (2 u), and
    there the pair that was just outside the list stands at its contact distance."""
    box = Box.cubic(2, 20.0)
    x = np.array([[5.0, 5.0], [6.3 + 1e-9, 5.0], [12.0, 12.0]])  # r = sigma + skin (+1e-9): unlisted
    nl = build_neighbor_list(x, box, np.full(3, 0.5), skin=0.3)
    assert nl.index_of(np.array([[0, 1]]))[0] == -1
    U = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 0.3]])
    E = np.zeros((2, 2))
    budget = SkinBudget.fresh(x)
    t = budget.horizon(nl, U, E)
    assert t == pytest.approx(nl.skin / 2.0, rel=1e-14)
    r = np.linalg.norm(pair_vectors(advance_positions(x, U, E, t), box.matrix, np.array([[0, 1]]),
                                    np.zeros((1, 2))))
    assert 0.0 <= r - 1.0 < 1e-8


@pytest.mark.parametrize("d", [2, 3])
def test_no_unlisted_pair_meets_within_the_skin_budget_horizon(rng, d):
    """Moved on straight lines under shear to the horizon, every pair closer than its contact
    distance is listed; the budget is valid just before the horizon and spent just after."""
    n, length = 150, 6.0
    box = Box.lees_edwards([length] * d, 0.2)
    radius = rng.uniform(0.3, 0.4, size=n)
    x = rng.uniform(0, length, size=(n, d))
    nl = build_neighbor_list(x, box, radius, skin=0.3)
    U = rng.normal(size=(n, d))
    E = np.zeros((d, d))
    E[0, 1] = 2.0
    budget = SkinBudget.fresh(x)
    t = budget.horizon(nl, U, E)
    assert 0.0 < t < np.inf
    before, after = SkinBudget.fresh(x), SkinBudget.fresh(x)
    before.advance(U, E, t * (1.0 - 1e-9))
    after.advance(U, E, t * (1.0 + 1e-6))
    assert before.valid(nl) and not after.valid(nl)
    x1, h1 = advance_positions(x, U, E, t), Box(advance_box(box.matrix, E, t))
    a, b = np.triu_indices(n, k=1)
    r1 = np.linalg.norm(h1.minimum_image(x1[b] - x1[a]), axis=1)
    close = r1 < radius[a] + radius[b]
    assert close.sum() > 0
    assert np.all(nl.index_of(np.stack([a[close], b[close]], axis=1)) >= 0)
    r0 = np.linalg.norm(box.minimum_image(x[b] - x[a]), axis=1)
    # the motion used the skin: some listed pair closed by more than a third of it
    assert np.max(r0 - r1) > nl.skin / 3.0


def _integrator_for(x, box, radius, drive, skin):
    return Integrator.start(x, box.matrix, radius, drive, FlowOptions(skin=skin))


def _drives(n, d, rng):
    ext = rng.normal(size=(n, d))
    return {
        "shear": Drive("shear"),
        "compress": Drive("compress"),
        "fixed_pressure": Drive("shear_fixed_pressure", pressure=2.0),
        "forces": Drive("forces", external=ext),
    }


def _check_rewiring_unique(rng, mode, n, d, size, trials):
    found_nontrivial = 0
    for trial in range(trials):
        x, box, radius, nl, _ = _random_network(rng, n=n, d=d, length=5.0)
        drive = _drives(n, d, rng)[mode]
        integ = _integrator_for(x, box, radius, drive, skin=0.4 * 5.0 - 1.0)
        P = len(integ.state.nl.pairs)
        gamma = np.zeros(P, bool)
        gamma[rng.choice(P, size=min(size, P), replace=False)] = True
        if constrained_subset(n, d, integ.state.nl.pairs[gamma]).excess >= 0:
            continue
        res = rewire(gamma, integ.evaluate, integ.rates, integ.velocity_scale)
        assert not res.jammed
        ok, fmin, vmin = admissible(res.active, gamma, integ.evaluate, integ.rates, integ.velocity_scale)
        assert ok, (fmin, vmin)
        assert not np.any(res.active & ~gamma)
        # brute force: every subset of Γ
        idx = np.flatnonzero(gamma)
        winners = []
        for bits in itertools.product((False, True), repeat=len(idx)):
            mask = np.zeros(P, bool)
            mask[idx[np.array(bits, bool)]] = True
            if admissible(mask, gamma, integ.evaluate, integ.rates, integ.velocity_scale)[0]:
                winners.append(mask)
        assert len(winners) == 1
        assert np.array_equal(winners[0], res.active)
        found_nontrivial += int(res.active.sum() < gamma.sum())
    assert found_nontrivial >= 1  # the procedure had to remove contacts at least once


@pytest.mark.parametrize("mode", ["shear", "compress", "fixed_pressure", "forces"])
def test_rewiring_result_satisfies_a6_a8_and_is_unique(rng, mode):
    """App. A: the rewired network is the unique subset of Γ with (A6) and (A8) — checked by brute
    force over all 2^|Γ| subsets on random networks (the theorem needs only S)."""
    _check_rewiring_unique(rng, mode, n=9, d=2, size=9, trials=4)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["shear", "compress", "fixed_pressure", "forces"])
@pytest.mark.parametrize("d", [2, 3])
def test_rewiring_unique_larger_networks(rng, mode, d):
    _check_rewiring_unique(rng, mode, n=10, d=d, size=13, trials=5)


def test_permanent_contacts_survive_rewiring_with_negative_force(rng):
    n, d = 9, 2
    for _ in range(20):
        x, box, radius, nl, _ = _random_network(rng, n=n, d=d, length=5.0)
        integ = _integrator_for(x, box, radius, Drive("shear"), skin=1.0)
        P = len(integ.state.nl.pairs)
        if P < 6:
            continue
        gamma = np.zeros(P, bool)
        gamma[rng.choice(P, size=6, replace=False)] = True
        ev = integ.evaluate(gamma)
        idx = np.flatnonzero(gamma)
        if ev.solution is None or ev.force.min() >= 0:
            continue
        perm = np.zeros(P, bool)
        perm[idx[np.argmin(ev.force)]] = True
        res = rewire(gamma, integ.evaluate, integ.rates, integ.velocity_scale, permanent=perm)
        assert res.active[perm].all()
        f = res.evaluation.force
        free = ~perm[res.active]
        assert np.all(f[free] > 0)
        return
    raise AssertionError("the seeded draws gave no network with a negative force: the test checked nothing")


def test_self_stress_of_isostatic_triangle_lattice_is_positive():
    """A potentially jammed network (z_bar = 2d) has a one-signed self-stress with S^T f0 = 0."""
    # a hexagonal patch of 4 x 4 discs in a periodic box at contact, all 3N contacts
    nx = 4
    a = 1.0
    L = np.array([nx * a, nx * a * np.sqrt(3) / 2])
    pts = np.array([[(i + 0.5 * (j % 2)) * a, j * a * np.sqrt(3) / 2] for j in range(nx) for i in range(nx)])
    box = Box.orthogonal(L)
    radius = np.full(len(pts), 0.5)
    nl = build_neighbor_list(pts, box, radius, skin=0.2)
    R = pair_vectors(pts, box.matrix, nl.pairs, nl.image)
    touching = np.abs(np.linalg.norm(R, axis=1) - 1.0) < 1e-12
    pairs, images = nl.pairs[touching], nl.image[touching]
    assert len(pairs) == 3 * len(pts)  # hyperstatic: 2N - 1 < 3N
    # remove contacts until exactly isostatic in the constrained sense, keeping rigidity
    count = constrained_subset(len(pts), 2, pairs)
    assert count.excess == 3 * 16 - (2 * 16 - 1)
    rates = affine_rates(R[touching], -np.eye(2))
    f0, resid = self_stress(pts, box.matrix, pairs, images, rates)
    assert resid < 1e-12
    # compression does positive work against the chosen sign
    assert -(f0 @ rates) > 0
