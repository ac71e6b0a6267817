"""Verlet neighbour lists of the LS kernel (jamflow.protocols._ls_kernels, jamflow.protocols.ls): the same
dynamics as the cell scan, the no-missed-pair guarantee, conservation over many
rebuilds, and no overlaps up to jamming in d = 4, 5."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jamflow.protocols import _ls_kernels as kern
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import _State, compress
from jamflow.state.packing import max_overlap
from jamflow.tolerances import OVERLAP_TOL


def _state(packing, rate, neighbor_list, seed=0):
    st = _State(packing, 10.0, np.random.default_rng(seed), neighbor_list)
    st.set_rate(rate)
    return st


def _collision_sequence(st, ncoll):
    """The colliding pairs, one collision at a time, rebuilding when the kernel asks."""
    pairs = []
    while len(pairs) < ncoll:
        before = st.count.copy()
        status, done = st.run(1, st.t_rebuild)
        if status != kern.WINDOW_DONE:
            st.rebuild()
            continue
        assert done == 1
        pairs.append(tuple(np.flatnonzero(st.count != before)))
    return pairs


def _pair_gaps(st):
    """Centre distance minus contact distance of every pair now, shape (N, N) [length]."""
    x = st.x + st.v * (st.t - st.tl)[:, None]
    dx = x[None, :, :] - x[:, None, :]
    dx -= st.L * np.floor(dx * st.invL + 0.5)
    sigma = 0.5 * (st.a[:, None] + st.a[None, :]) * st.scale()
    return np.linalg.norm(dx, axis=2) - sigma


@pytest.mark.parametrize("d,n,phi", [(4, 256, 0.25), (5, 256, 0.15)])
def test_lists_and_cells_give_the_same_collisions(d, n, phi):
    pk = random_packing(n, d, phi, seed=d, dispersity="bi", ratio=1.4)
    cells = _state(pk, 1e-3, False)
    lists = _state(pk, 1e-3, True)
    assert not cells.use_nl and lists.use_nl
    a = _collision_sequence(cells, 4000)
    b = _collision_sequence(lists, 4000)
    assert lists.list_builds > 10
    assert a == b
    # the same state at the end, up to round-off
    assert lists.t == pytest.approx(cells.t, rel=1e-9)
    assert np.allclose(lists.v, cells.v, atol=1e-9)


@pytest.mark.parametrize("d", [4, 5])
def test_lists_and_cells_give_the_same_pressure(d):
    # plain hard-sphere dynamics of a dense liquid: the mean pressure over 40 windows
    # agrees within 4 combined standard errors (the trajectories decorrelate by chaos)
    start = random_packing(128, d, 0.2 if d == 4 else 0.12, seed=10 + d)
    pk = compress(start, 5e-3, phi_target=0.35 if d == 4 else 0.25, fast_growth_rate=None).final
    runs = [compress(pk, 0.0, max_collisions=128 * 10 * 41, fast_growth_rate=None, seed=3,
                     neighbor_list=nl) for nl in (False, True)]
    means, errs = [], []
    for res in runs:
        p = res.eos.pressure.values[1:]
        assert p.size == 40
        means.append(p.mean())
        errs.append(p.std(ddof=1) / math.sqrt(p.size))
    assert abs(means[0] - means[1]) < 4.0 * math.hypot(*errs)
    assert abs(means[0] - means[1]) < 0.05 * means[0]


def test_no_pair_outside_the_lists_comes_near_contact():
    # brute force over all pairs at many times, including the first leave time (the
    # latest moment the lists are used): every pair within 1e-3 mean diameters of
    # contact is listed; with growth, so that the growth allowance is tested too
    pk = random_packing(200, 4, 0.2, seed=21, dispersity="bi", ratio=1.4)
    st = _state(pk, 5e-2, True)
    rng = np.random.default_rng(5)
    close = 1e-3
    checks = expired = 0
    while checks < 300:
        t_stop = st.t + rng.exponential(2e-3)
        status, _ = st.run(10**9, t_stop)
        listed = np.zeros((st.n, st.n), dtype=bool)
        rows = np.repeat(np.arange(st.n), np.diff(st.nl_start))
        listed[rows, st.nl_idx] = True
        gaps = _pair_gaps(st)
        np.fill_diagonal(gaps, np.inf)
        near = gaps < close * st.scale()
        assert np.all(listed[near])
        assert gaps.min() > -1e-12 * st.scale()
        checks += 1
        if status == kern.LIST_EXPIRED:
            expired += 1
            st.rebuild()
    assert expired > 20
    assert np.array_equal(listed, listed.T)


def test_energy_and_momentum_conserved_over_many_rebuilds():
    start = random_packing(256, 5, 0.12, seed=8)
    pk = compress(start, 5e-3, phi_target=0.3, fast_growth_rate=None).final
    st = _state(pk, 0.0, True)
    K0 = kern.kinetic_energy(st.v)
    P0 = st.v.sum(axis=0)
    total = 0
    while st.list_builds < 100:
        status, ncoll = st.run(10**9, math.inf)
        total += ncoll
        assert status == kern.LIST_EXPIRED
        st.rebuild()
    assert total > 50_000
    assert kern.kinetic_energy(st.v) == pytest.approx(K0, rel=1e-12)
    assert np.abs(st.v.sum(axis=0) - P0).max() < 1e-12
    assert max_overlap(st.packing(pk))[1] <= OVERLAP_TOL


@pytest.mark.parametrize("d,phi", [(2, 0.5), (3, 0.3), (4, 0.2), (5, 0.1)])
def test_rule_chooses_lists_where_they_were_measured_faster(d, phi):
    # measured at N = 1024 (benchmarks/ls.py protocol): lists 1.7x (2D) to 10x (5D)
    # faster; the neighbour cells hold 2.9 (2D) to 30 (5D) times more than a list
    st = _state(random_packing(1024, d, phi, seed=0), 1e-3, None)
    assert st.use_nl and st.t_rebuild == math.inf
    assert not _state(random_packing(1024, d, phi, seed=0), 1e-3, False).use_nl


@pytest.mark.parametrize("d,n", [(4, 64), (5, 64)])
def test_compression_to_jamming_with_lists_has_no_overlap(d, n):
    pk = random_packing(n, d, 0.2 if d == 4 else 0.1, seed=30 + d)
    res = compress(pk, 1e-2, [1e6, 1e12], seed=0, neighbor_list=True)
    assert res.stop_reason == "p_targets"
    for snap in res.snapshots:
        assert max_overlap(snap)[1] <= OVERLAP_TOL
    assert res.snapshots[-1].pressure >= 1e12
