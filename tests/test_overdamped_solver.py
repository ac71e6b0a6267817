"""The reused-factorisation solver of N f = rhs (``FactorCache``) against the direct sparse LU.

Between events the contact network is fixed and only its geometry drifts, so an earlier LU of
N = S S^T preconditions conjugate gradients on the current N. These tests check that the CG
path gives the forces of a fresh direct solve to 1e-10 relative (random networks in 2D and 3D,
every drive, and ill-conditioned networks close to a self-stress), that it falls back to a
fresh factorisation when the geometry has moved too far, and that singular networks are still
reported as singular.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box, lattice_volume
from jamflow.protocols.overdamped.collisions import build_neighbor_list
from jamflow.protocols.overdamped.ldl import SingularNetworkError
from jamflow.protocols.overdamped.network import FactorCache, solve_network

#: Relative agreement of the CG forces with the direct solve demanded by issue 20.
FORCE_REL = 1e-10


def _random_network(rng, n, d, n_contacts, length=5.0):
    x = rng.uniform(0, length, size=(n, d))
    box = Box.cubic(d, length)
    nl = build_neighbor_list(x, box, np.full(n, 0.5), skin=0.4 * length - 1.0)
    pick = np.sort(rng.choice(len(nl.pairs), size=n_contacts, replace=False))
    return x, box, nl.pairs[pick], nl.image[pick]


def _drive_kwargs(mode, n, d, rng):
    E = np.zeros((d, d))
    E[0, 1] = 1.0
    if mode == "shear":
        return {"gradient": E}
    if mode == "fixed_pressure":
        return {"gradient": E, "pressure": 2.5, "rate": 1.0}
    return {"gradient": np.zeros((d, d)), "external": rng.normal(size=(n, d)), "xi0": 0.7}


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("mode", ["shear", "fixed_pressure", "forces"])
def test_cg_on_cached_factor_matches_direct_solve(rng, d, mode):
    """Factor at one geometry, move every particle by ~1e-3, solve by CG: same forces as a direct LU."""
    n = 30
    for trial in range(3):
        x, box, pairs, images = _random_network(rng, n, d, n_contacts=(d * n) // 2 + trial)
        kw = _drive_kwargs(mode, n, d, rng)
        cache = FactorCache()
        solve_network(x, box.matrix, pairs, images, check_pivots=False, cache=cache, **kw)
        assert (cache.n_factor, cache.n_cg) == (1, 0)
        x1 = x + 1e-3 * rng.normal(size=x.shape)
        fast = solve_network(x1, box.matrix, pairs, images, check_pivots=False, cache=cache, **kw)
        assert (cache.n_factor, cache.n_cg) == (1, 1), "the CG path was not taken"
        direct = solve_network(x1, box.matrix, pairs, images, **kw)
        assert _rel(fast.force, direct.force) < FORCE_REL
        assert _rel(fast.velocity, direct.velocity) < FORCE_REL
        if mode == "fixed_pressure":
            assert fast.kappa == pytest.approx(direct.kappa, rel=FORCE_REL)


def _bent_ring(eps):
    """Four unit discs on a periodic line, the second lifted by ``eps``: near a collinear self-stress.

    At ``eps = 0`` the force chain wrapping the box is a self-stress and N is exactly singular;
    the smallest eigenvalue of N grows as eps^2, so eps = 1e-3 gives a condition number ~1e6.
    """
    x = np.array([[0.5, 1.0], [1.5, 1.0 + eps], [2.5, 1.0], [3.5, 1.0]])
    pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
    images = np.array([[0, 0], [0, 0], [0, 0], [-1, 0]])
    return x, Box.cubic(2, 4.0).matrix, pairs, images


@pytest.mark.parametrize("eps", [1e-2, 1e-3])
def test_cg_matches_direct_solve_near_a_self_stress(rng, eps):
    """Ill-conditioned N (cond ~ 1/eps^2): CG on the cached factor still agrees to 1e-10."""
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    F = rng.normal(size=(4, 2))
    x, h, pairs, images = _bent_ring(eps)
    cache = FactorCache()
    solve_network(x, h, pairs, images, E, external=F, check_pivots=False, cache=cache)
    x1 = x.copy()
    x1[1, 1] += 0.01 * eps
    x1[2, 0] += 1e-4
    fast = solve_network(x1, h, pairs, images, E, external=F, check_pivots=False, cache=cache)
    assert cache.n_cg == 1
    direct = solve_network(x1, h, pairs, images, E, external=F)
    assert _rel(fast.force, direct.force) < FORCE_REL


def test_far_moved_geometry_falls_back_to_a_fresh_factorisation(rng):
    """A cached factor of a very different geometry is not trusted: CG gives up, N is refactorised."""
    n, d = 30, 2
    x, box, pairs, images = _random_network(rng, n, d, n_contacts=n)
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    cache = FactorCache(max_iter=2)
    solve_network(x, box.matrix, pairs, images, E, check_pivots=False, cache=cache)
    x1 = x + 0.3 * rng.normal(size=x.shape)
    fast = solve_network(x1, box.matrix, pairs, images, E, check_pivots=False, cache=cache)
    assert (cache.n_factor, cache.n_cg) == (2, 0)
    direct = solve_network(x1, box.matrix, pairs, images, E)
    assert np.array_equal(fast.force, direct.force)


def test_singular_network_is_reported_with_a_cache():
    """The exactly collinear ring carries a self-stress: SingularNetworkError, and the cache keeps
    its previous factor (a failed factorisation is never reused)."""
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    cache = FactorCache()
    solve_network(*_bent_ring(1e-2), E, check_pivots=True, cache=cache)
    key = cache.key
    x, h, pairs, images = _bent_ring(0.0)
    # near potential jamming the caller asks for the pivot check: always a fresh factorisation
    with pytest.raises(SingularNetworkError):
        solve_network(x, h, pairs, images, E, check_pivots=True, cache=cache)
    assert cache.key == key and cache.n_factor == 1
    with pytest.raises(SingularNetworkError):
        solve_network(x, h, pairs, images, E, check_pivots=True, cache=FactorCache())


@pytest.mark.parametrize("mode", ["shear", "fixed_pressure", "forces"])
@pytest.mark.parametrize("change", ["add", "remove", "add_and_remove"])
def test_bordered_preconditioner_on_a_changed_network_matches_direct_solve(rng, mode, change):
    """A network one or two pairs away from the factorised one (a rewiring candidate), moved by
    ~1e-3: CG with the bordered preconditioner gives the direct solve's forces to 1e-10."""
    n, d = 30, 2
    x = rng.uniform(0, 5.0, size=(n, d))
    box = Box.cubic(d, 5.0)
    nl = build_neighbor_list(x, box, np.full(n, 0.5), skin=1.0)
    pick = np.sort(rng.choice(len(nl.pairs), size=n + 2, replace=False))
    base, spare = pick[:-2], pick[-2:]
    new = {"add": np.sort(np.concatenate([base, spare[:1]])),
           "remove": base[1:],
           "add_and_remove": np.sort(np.concatenate([base[2:], spare]))}[change]
    kw = _drive_kwargs(mode, n, d, rng)
    cache = FactorCache()
    solve_network(x, box.matrix, nl.pairs[base], nl.image[base], check_pivots=False, cache=cache, **kw)
    x1 = x + 1e-3 * rng.normal(size=x.shape)
    fast = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], check_pivots=False, cache=cache, **kw)
    assert (cache.n_factor, cache.n_bordered) == (1, 1), "the bordered CG path was not taken"
    direct = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], **kw)
    assert _rel(fast.force, direct.force) < FORCE_REL


def test_pair_closing_a_self_stress_is_not_solved_by_the_bordered_path():
    """Adding the pair that closes the collinear ring creates a self-stress: the Schur complement
    of the new pair vanishes, the bordered preconditioner is refused and the direct factorisation
    reports the singular network, as without a cache."""
    E = np.array([[0.0, 1.0], [0.0, 0.0]])
    x, h, pairs, images = _bent_ring(0.0)
    cache = FactorCache()
    solve_network(x, h, pairs[:3], images[:3], E, check_pivots=False, cache=cache)  # open chain: regular
    with pytest.raises(SingularNetworkError):
        solve_network(x, h, pairs, images, E, check_pivots=False, cache=cache)
    assert cache.n_bordered == 0 and cache.n_factor == 1


def _contact_network(rng, eps):
    """Pairs, unit vectors and particle count of a random 40-disc network (``eps`` None) or of
    the bent ring near a self-stress."""
    from jamflow.protocols.overdamped.network import pair_vectors

    if eps is None:
        x, box, pairs, images = _random_network(rng, 40, 2, n_contacts=45)
        h = box.matrix
    else:
        x, h, pairs, images = _bent_ring(eps)
    R = pair_vectors(x, h, pairs, images)
    return pairs, R / np.linalg.norm(R, axis=1)[:, None], len(x)


def _s_operator(rng, eps):
    """S of :func:`_contact_network`."""
    from jamflow.protocols.overdamped.solver import s_matrix

    return s_matrix(*_contact_network(rng, eps))


@pytest.mark.parametrize("eps", [None, 1e-3])
def test_compiled_triangular_solve_matches_a_dense_solve(rng, eps):
    """The cached factor's compiled substitution solves N x = b as a dense solve does (random and
    nearly singular N, one and several right-hand sides)."""
    from jamflow.protocols.overdamped.ldl import TriangularFactor

    S = _s_operator(rng, eps)
    N = (S @ S.T).tocsc()
    fac = TriangularFactor.of_matrix(N)
    B = rng.normal(size=(N.shape[0], 3))
    dense = np.linalg.solve(N.toarray(), B)
    cond = np.linalg.cond(N.toarray())
    # a backward-stable solve is accurate to ~ cond * machine epsilon
    assert _rel(fac.solve(B[:, 0]), dense[:, 0]) < 1e3 * cond * np.finfo(float).eps
    assert _rel(fac.solve(B), dense) < 1e3 * cond * np.finfo(float).eps


@pytest.mark.parametrize("mode", ["shear", "fixed_pressure"])
def test_extrapolated_warm_starts_and_memoised_borders_match_direct_solves(rng, mode):
    """A run-like sequence (geometry moving in time, then one pair added and the changed network
    solved again at later times) through one cache: every solve equals a fresh direct solve to
    1e-10, and the changed network is solved on the bordered preconditioner, built once."""
    n, d, length = 30, 2, 5.0
    x = rng.uniform(0, length, size=(n, d))
    box = Box.cubic(d, length)
    nl = build_neighbor_list(x, box, np.full(n, 0.5), skin=0.4 * length - 1.0)
    pick = rng.choice(len(nl.pairs), size=n + 4, replace=False)
    kw = _drive_kwargs(mode, n, d, rng)
    U = rng.normal(size=x.shape)
    cache = FactorCache()
    for step in range(8):
        t = 1e-3 * step
        sel = np.sort(pick[:-1] if step < 4 else pick)
        xt = x + t * U
        fast = solve_network(xt, box.matrix, nl.pairs[sel], nl.image[sel], check_pivots=False, cache=cache,
                             time=t, **kw)
        direct = solve_network(xt, box.matrix, nl.pairs[sel], nl.image[sel], **kw)
        assert _rel(fast.force, direct.force) < FORCE_REL, step
    assert cache.n_factor == 1 and cache.n_cg == 7 and cache.n_bordered == 4
    assert len(cache.bordered) == 1


def test_cg_returns_after_one_last_step_along_its_search_direction(rng):
    """Converged CG takes one more step along its search direction (a product with N, no further
    preconditioner solve): on networks moved 1e-4 from the factorised geometry the forces come back a
    hundred times inside the stopping tolerance (these draws: 6e-15 of a direct solve, 8e-13 without
    that step)."""
    cache_rtol = FactorCache().rtol
    worst = 0.0
    for d in (2, 3):
        for trial in range(5):
            n = 30
            x, box, pairs, images = _random_network(rng, n, d, n_contacts=(d * n) // 2 + trial)
            kw = _drive_kwargs("shear", n, d, rng)
            cache = FactorCache()
            solve_network(x, box.matrix, pairs, images, check_pivots=False, cache=cache, **kw)
            x1 = x + 1e-4 * rng.normal(size=x.shape)
            fast = solve_network(x1, box.matrix, pairs, images, check_pivots=False, cache=cache, **kw)
            assert cache.n_cg == 1
            worst = max(worst, _rel(fast.force, solve_network(x1, box.matrix, pairs, images, **kw).force))
    assert worst < cache_rtol / 100


def test_cg_from_a_start_far_larger_than_the_solution_still_meets_its_tolerance(rng):
    """A warm start 1e6 times the forces: the residual CG updates drifts from b - N x by round-off
    of the start's size (~1e-10 of the solution), so convergence is confirmed on the true
    residual; the forces still match a direct solve to 1e-10."""
    n, d = 30, 2
    x, box, pairs, images = _random_network(rng, n, d, n_contacts=n + 3)
    kw = _drive_kwargs("shear", n, d, rng)
    cache = FactorCache()
    solve_network(x, box.matrix, pairs, images, check_pivots=False, cache=cache, time=0.0, **kw)
    cache.remember(cache.codes, [1e6 * rng.normal(size=len(pairs))], 0.5)
    x1 = x + 1e-4 * rng.normal(size=x.shape)
    fast = solve_network(x1, box.matrix, pairs, images, check_pivots=False, cache=cache, time=1.0, **kw)
    assert cache.n_cg == 1, "the CG path was not taken"
    assert _rel(fast.force, solve_network(x1, box.matrix, pairs, images, **kw).force) < FORCE_REL


def test_warm_start_extrapolation_lowers_its_degree_rather_than_amplify(rng):
    """Four solves of a smooth solution, two of them 1e-9 apart (a collision right after a step):
    the cubic through them would multiply the solutions by ~1e9; the warm start lowers its degree
    until its weights sum to at most WARM_WEIGHT_LIMIT and stays close to the solution."""
    from jamflow.protocols.overdamped.solver import WARM_WEIGHT_LIMIT

    codes = np.array([2, 5, 9])
    a, b = rng.normal(size=(2, 3))
    cache = FactorCache()
    for t in (0.0, 1.0, 1.0 + 1e-9, 2.0):
        cache.remember(codes, [a + b * t + 1e-6 * rng.normal(size=3)], t)
    x0 = cache.warm_starts(codes, 1, 3.0)[0]
    assert np.max(np.abs(x0)) <= WARM_WEIGHT_LIMIT * np.max(np.abs(a + 2.0 * b)) + 1e-5
    assert _rel(x0, a + 3.0 * b) < 1e-4


@pytest.mark.parametrize("eps", [None, 1e-3])
def test_ldlt_factor_reproduces_n_and_solves_as_superlu_does(rng, eps):
    """The cached factor P^T N P = (I + L) D (I + L)^T rebuilds N to round-off, its pivots D lie
    between N's smallest eigenvalue and largest diagonal entry with product det N, and its solves
    agree with SuperLU's LU solve (random N and N near a self-stress, cond ~ 1e6) to the
    backward-stable bound."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from jamflow.protocols.overdamped.solver import _factorize, s_matrix

    pairs, unit, n = _contact_network(rng, eps)
    S = s_matrix(pairs, unit, n)
    fac, _ = _factorize(pairs, unit, n, pairs[:, 0] * n + pairs[:, 1], cond_limit=1e13)
    Lp, Li, Lx, d, perm = fac.args
    m = len(d)
    L = sp.csc_matrix((Lx, Li, Lp), shape=(m, m)).toarray()
    assert np.all(np.tril(L, -1) == L)  # strictly lower
    N = (S @ S.T).toarray()
    P = np.zeros((m, m))
    P[perm, np.arange(m)] = 1.0
    rebuilt = P @ (np.eye(m) + L) @ np.diag(d) @ (np.eye(m) + L).T @ P.T
    assert _rel(rebuilt, N) < 1e-13
    # LDL^T pivots of a positive definite N: between its smallest eigenvalue and largest diagonal
    # entry, with product det N
    eig = np.linalg.eigvalsh(N)
    assert d.min() >= eig[0] * (1 - 1e-6) and d.max() <= N.diagonal().max() * (1 + 1e-12)
    assert np.sum(np.log(d)) == pytest.approx(np.sum(np.log(eig)), rel=1e-8)
    lu = spla.splu(sp.csc_matrix(N))
    bound = 1e3 * np.linalg.cond(N) * np.finfo(float).eps
    for _ in range(3):
        b = rng.normal(size=m)
        assert _rel(fac.solve(b), lu.solve(b)) < bound
        assert _rel(fac.solve(b), np.linalg.solve(N, b)) < bound


@pytest.mark.parametrize("eps", [None, 1e-3])
def test_compiled_ldlt_equals_qdldl_under_the_same_ordering(rng, eps):
    """Two implementations of one factorisation: the compiled up-looking LDL^T under QDLDL's AMD
    ordering gives QDLDL's L and D to round-off (random N and N near a self-stress)."""
    from jamflow.protocols.overdamped.ldl import TriangularFactor

    pairs, unit, n = _contact_network(rng, eps)
    ref = TriangularFactor.of_network(pairs, unit, n)
    ours = TriangularFactor.of_network(pairs, unit, n, order=ref.args[4])
    assert np.array_equal(ours.args[0], ref.args[0]) and np.array_equal(ours.args[4], ref.args[4])
    m = len(pairs)
    as_dense = [_dense_l(f.args, m) for f in (ref, ours)]
    assert _rel(as_dense[1], as_dense[0]) < 1e-13
    assert _rel(ours.pivots, ref.pivots) < 1e-13


def _dense_l(args, m):
    """L of a factor's arrays as a dense matrix."""
    import scipy.sparse as sp

    Lp, Li, Lx = args[:3]
    return sp.csc_matrix((Lx, Li, Lp), shape=(m, m)).toarray()


def test_a_carried_ordering_factorises_a_changed_network_exactly(rng):
    """The AMD ordering of a network carried to one with three pairs removed and five added: the
    kept pairs are eliminated in their order there and the added ones last; the factor under it
    solves the changed network's N as a dense solve does, and a fill limit below its entries
    refuses it."""
    from jamflow.protocols.overdamped.ldl import CarriedOrder, TriangularFactor
    from jamflow.protocols.overdamped.network import pair_vectors
    from jamflow.protocols.overdamped.solver import s_matrix

    x, box, pairs, images = _random_network(rng, 40, 2, n_contacts=53)
    R = pair_vectors(x, box.matrix, pairs, images)
    unit = R / np.linalg.norm(R, axis=1)[:, None]
    n = len(x)
    codes = pairs[:, 0] * n + pairs[:, 1]
    base = np.arange(45)
    changed = np.concatenate([base[3:], np.arange(45, 53)[:5]])
    carried = CarriedOrder.of(codes[base], TriangularFactor.of_network(pairs[base], unit[base], n))
    order = carried.order(codes[changed])
    assert np.array_equal(np.sort(order), np.arange(len(changed)))
    kept_rank = carried.rank[changed[order][:-5]]
    assert np.all(np.diff(kept_rank) > 0), "kept pairs leave their carried order"
    assert np.array_equal(changed[order][-5:], changed[-5:]), "added pairs are not eliminated last"
    fac = TriangularFactor.of_network(pairs[changed], unit[changed], n, order=order)
    S = s_matrix(pairs[changed], unit[changed], n)
    N = (S @ S.T).toarray()
    b = rng.normal(size=len(changed))
    bound = 1e3 * np.linalg.cond(N) * np.finfo(float).eps
    assert _rel(fac.solve(b), np.linalg.solve(N, b)) < bound
    assert TriangularFactor.of_network(pairs[changed], unit[changed], n, order=order, max_fill=fac.fill - 1) is None


def test_locate_merges_increasing_codes_and_sorts_others_to_the_same_positions(rng):
    """Positions of pair codes in another network's codes: the linear merge (both increasing, as
    networks cut from a neighbour list are) and the sorted search (any order) agree with a
    search entry by entry, -1 for codes absent (pairs added), including codes beyond both ends."""
    from jamflow.protocols.overdamped.ldl import _ascending, locate

    old = np.unique(rng.integers(5, 10_000, 300))
    kept = old[rng.random(len(old)) < 0.9]
    new = np.unique(np.concatenate([kept, rng.integers(0, 10_020, 12), [0, 10_019]]))
    expected = np.array([np.flatnonzero(old == c)[0] if np.any(old == c) else -1 for c in new])
    assert _ascending(old) and _ascending(new) and np.any(expected < 0) and np.sum(expected >= 0) > 200
    assert np.array_equal(locate(old, new), expected)
    shuffled = rng.permutation(len(old))
    assert not _ascending(old[shuffled])
    back = np.full(len(new), -1)
    back[expected >= 0] = np.argsort(shuffled)[expected[expected >= 0]]
    assert np.array_equal(locate(old[shuffled], new), back)
    assert np.array_equal(locate(old[:0], new), np.full(len(new), -1))


def test_a_self_stress_under_a_carried_ordering_is_reported():
    """The pair that closes the collinear ring, factorised under the open chain's carried
    ordering (appended last), leaves a round-off pivot: reported as singular."""
    from jamflow.protocols.overdamped.ldl import CarriedOrder, TriangularFactor
    from jamflow.protocols.overdamped.network import pair_vectors
    from jamflow.protocols.overdamped.solver import _factorize

    x, h, pairs, images = _bent_ring(0.0)
    R = pair_vectors(x, h, pairs, images)
    unit = R / np.linalg.norm(R, axis=1)[:, None]
    n = len(x)
    codes = pairs[:, 0] * n + pairs[:, 1]
    carried = CarriedOrder.of(codes[:3], TriangularFactor.of_network(pairs[:3], unit[:3], n))
    with pytest.raises(SingularNetworkError):
        _factorize(pairs, unit, n, codes, 1e13, carried)


@pytest.mark.parametrize("mode", ["shear", "fixed_pressure"])
def test_the_cache_carries_its_ordering_and_forgets_it_on_reset(rng, mode):
    """Refactorising at every change (``max_changes`` 0), the cache factorises a changed network
    under the ordering carried from the first one, with the direct solve's forces to 1e-10; a
    reset forgets the ordering, so that a run resumed there computes a fresh one as the
    uninterrupted run did."""
    n, d, length = 400, 2, 20.0
    x = rng.uniform(0, length, size=(n, d))
    box = Box.cubic(d, length)
    nl = build_neighbor_list(x, box, np.full(n, 0.5), skin=1.0)
    pick = rng.choice(len(nl.pairs), size=n // 2 + 2, replace=False)  # half a pair per disc: no self-stress here
    base, new = np.sort(pick[:-2]), np.sort(pick[2:])
    kw = _drive_kwargs(mode, n, d, rng)
    cache = FactorCache(max_changes=0)
    solve_network(x, box.matrix, nl.pairs[base], nl.image[base], check_pivots=False, cache=cache, **kw)
    carried = cache.order
    assert np.array_equal(carried.codes, cache.codes)
    x1 = x + 1e-3 * rng.normal(size=x.shape)
    fast = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], check_pivots=False, cache=cache, **kw)
    assert cache.n_factor == 2 and cache.order is carried, "the changed network was not factorised under the carried ordering"
    direct = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], **kw)
    assert _rel(fast.force, direct.force) < FORCE_REL
    cache.reset()
    assert cache.order is None


@pytest.mark.parametrize("mode", ["shear", "fixed_pressure"])
def test_bordered_preconditioner_with_several_added_and_removed_pairs(rng, mode):
    """Three pairs added and three removed (within ``max_changes`` = 8): the bordered CG still gives
    the direct solve's forces to 1e-10; one more change than ``max_changes`` is refactorised."""
    n, d = 30, 2
    x = rng.uniform(0, 5.0, size=(n, d))
    box = Box.cubic(d, 5.0)
    nl = build_neighbor_list(x, box, np.full(n, 0.5), skin=1.0)
    pick = rng.choice(len(nl.pairs), size=n + 3, replace=False)
    base, spare = np.sort(pick[:n]), pick[n:]
    new = np.sort(np.concatenate([base[3:], spare]))
    kw = _drive_kwargs(mode, n, d, rng)
    x1 = x + 1e-3 * rng.normal(size=x.shape)
    cache = FactorCache(max_changes=8)
    solve_network(x, box.matrix, nl.pairs[base], nl.image[base], check_pivots=False, cache=cache, **kw)
    fast = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], check_pivots=False, cache=cache, **kw)
    assert (cache.n_factor, cache.n_bordered) == (1, 1), "the bordered CG path was not taken"
    direct = solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], **kw)
    assert _rel(fast.force, direct.force) < FORCE_REL
    few = FactorCache(max_changes=5)
    solve_network(x, box.matrix, nl.pairs[base], nl.image[base], check_pivots=False, cache=few, **kw)
    solve_network(x1, box.matrix, nl.pairs[new], nl.image[new], check_pivots=False, cache=few, **kw)
    assert (few.n_factor, few.n_bordered) == (2, 0)


def test_warm_starts_extrapolate_polynomials_of_their_order_exactly(rng):
    """Solutions that are a cubic in time are extrapolated exactly from four remembered solves (the
    default order), a quadratic from three, a linear one from two; a changed network gets the last
    solution on its kept pairs, zero on new ones; a solve at a remembered time gets that solution."""
    codes = np.array([3, 7, 11, 20])
    a, b, c, e = rng.normal(size=(4, 4))

    def f(t):
        return a + b * t + c * t * t + e * t ** 3

    cache = FactorCache()
    for t in (0.0, 0.4, 0.7, 1.0):
        cache.remember(codes, [f(t)], t)
    assert _rel(cache.warm_starts(codes, 1, 1.3)[0], f(1.3)) < 1e-12
    quad = FactorCache(warm_order=2)
    for t in (0.0, 0.4, 1.0):
        quad.remember(codes, [f(t) - e * t ** 3], t)
    assert _rel(quad.warm_starts(codes, 1, 1.7)[0], f(1.7) - e * 1.7 ** 3) < 1e-13
    lin = FactorCache(warm_order=1)
    for t in (0.4, 1.0):
        lin.remember(codes, [a + b * t], t)
    assert _rel(lin.warm_starts(codes, 1, 1.7)[0], a + b * 1.7) < 1e-13
    assert np.array_equal(cache.warm_starts(codes, 1, 1.0)[0], f(1.0))
    moved = np.array([3, 9, 20])
    assert np.array_equal(cache.warm_starts(moved, 1, 1.7)[0], np.array([f(1.0)[0], 0.0, f(1.0)[3]]))
    # a second solve at the newest time (the state changed, e.g. by a drift correction) replaces it
    cache.remember(codes, [f(1.0) + c], 1.0)
    assert len(cache.recent) == cache.warm_order + 1
    assert np.array_equal(cache.warm_starts(codes, 1, 1.0)[0], f(1.0) + c)


@pytest.mark.parametrize("d", [2, 3])
def test_compiled_pair_kernels_match_their_formulas(rng, d):
    """Separations, affine rates, pair rates, the step-drift rate, the constraint error, the stress
    tensor, the negative-force test and the straight-line move of positions and box from the
    compiled kernels agree with their formulas written in numpy; the box volume the dynamics use is
    det h."""
    from jamflow.protocols.overdamped.network import (
        Solution,
        advance_box,
        advance_positions,
        affine_rates,
        has_negative,
        max_relative_error,
        max_relative_rate,
        max_row_norm,
        pair_vectors,
        pair_velocities,
        stress_tensor,
    )

    n, m = 25, 40
    x = rng.uniform(0, 4.0, size=(n, d))
    h = np.triu(rng.uniform(0.5, 1.0, size=(d, d))) + 4.0 * np.eye(d)
    pairs = np.array([rng.choice(n, size=2, replace=False) for _ in range(m)])
    images = rng.integers(-1, 2, size=(m, d))
    E = rng.normal(size=(d, d))
    U = rng.normal(size=(n, d))
    f = rng.uniform(0.1, 1.0, size=m)
    sigma = rng.uniform(0.8, 1.2, size=m)
    R = x[pairs[:, 1]] - x[pairs[:, 0]] + images @ h.T
    r = np.linalg.norm(R, axis=1)
    sol = Solution(f, U, E, np.nan)
    W = R @ E.T + U[pairs[:, 1]] - U[pairs[:, 0]]
    assert _rel(pair_vectors(x, h, pairs, images), R) < 1e-14
    assert _rel(affine_rates(R, E), np.einsum("ck,kl,cl->c", R, E, R) / r) < 1e-13
    assert _rel(pair_velocities(R, pairs, sol), np.einsum("ck,ck->c", R, W) / r) < 1e-13
    assert max_relative_rate(R, pairs, sol, sigma) == pytest.approx(np.max(np.linalg.norm(W, axis=1) / sigma), rel=1e-14)
    assert _rel(stress_tensor(R, f, 3.0), np.einsum("c,ca,cb->ab", f / r, R, R) / 3.0) < 1e-14
    assert max_row_norm(U) == pytest.approx(np.max(np.linalg.norm(U, axis=1)), rel=1e-15)
    assert lattice_volume(h) == pytest.approx(np.linalg.det(h), rel=1e-13)
    assert max_row_norm(np.zeros((0, d))) == 0.0
    assert _rel(advance_positions(x, U, E, 0.3), x + 0.3 * (x @ E.T + U)) < 1e-14
    assert _rel(advance_box(h, E, 0.3), np.triu(h + 0.3 * E @ h)) < 1e-14
    assert max_relative_error(R, sigma) == pytest.approx(np.max(np.abs(r / sigma - 1.0)), rel=1e-14)
    g = f - 0.5
    free = rng.random(m) < 0.5
    for tol in (0.0, 0.3, 0.9):
        assert has_negative(g, free, tol) == bool(np.any((g < -tol * np.max(np.abs(g))) & free))
    # a NaN propagates through every maximum, as through numpy's
    Rn, Un = R.copy(), U.copy()
    Rn[3, 0], Un[pairs[7, 1], 1] = np.nan, np.nan
    assert np.isnan(max_row_norm(Un)) and np.isnan(max_relative_error(Rn, sigma))
    assert np.isnan(max_relative_rate(R, pairs, Solution(f, Un, E, np.nan), sigma))


def test_a_nan_right_hand_side_is_never_a_converged_cg_solve(rng):
    """NaN external forces: CG on the cached factor must not report convergence (its maxima see the
    NaN), the direct fallback reports the non-finite solve as SingularNetworkError."""
    n, d = 30, 2
    x, box, pairs, images = _random_network(rng, n, d, n_contacts=n)
    F = rng.normal(size=(n, d))
    cache = FactorCache()
    solve_network(x, box.matrix, pairs, images, np.zeros((d, d)), external=F, check_pivots=False, cache=cache)
    F[pairs[0, 0], 0] = np.nan
    with pytest.raises(SingularNetworkError):
        solve_network(x, box.matrix, pairs, images, np.zeros((d, d)), external=F, check_pivots=False, cache=cache)
    assert cache.n_cg == 0
