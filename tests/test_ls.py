"""Lubachevsky–Stillinger compression (jamflow.protocols.ls): exact events, conservation laws,
equation of state against Carnahan–Starling and Eq. 15, targets, inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jamflow.analysis.eos import carnahan_starling, fit_jamming_density
from jamflow.analysis.structure import CRYSTAL_FRACTION_THRESHOLD, crystal_fraction
from jamflow.box import Box
from jamflow.protocols import _ls_kernels as kern
from jamflow.protocols.initial import random_packing
from jamflow.protocols.ls import _State, compress
from jamflow.state.packing import Packing, max_overlap
from jamflow.tolerances import OVERLAP_TOL


def _brute_force_contact_time(dx, u, sigma, g, t_max=50.0, samples=200_001):
    """First t with |dx + u t| = sigma + g t by a fine scan and bisection (inf if none)."""
    t = np.linspace(0.0, t_max, samples)
    f = np.linalg.norm(dx[None, :] + t[:, None] * u[None, :], axis=1) - (sigma + g * t)
    neg = np.flatnonzero(f <= 0.0)
    if neg.size == 0:
        return math.inf
    k = neg[0]
    lo, hi = t[k - 1], t[k]
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if np.linalg.norm(dx + mid * u) - (sigma + g * mid) > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@pytest.mark.parametrize("d", [2, 3, 5])
def test_collision_time_matches_brute_force_root(d, rng):
    checked = 0
    for _ in range(60):
        sigma = rng.uniform(0.5, 1.5)
        dx = rng.standard_normal(d)
        dx *= sigma * rng.uniform(1.0001, 3.0) / np.linalg.norm(dx)
        # random relative velocity, biased towards approach in half the draws
        u = rng.standard_normal(d) * rng.uniform(0.05, 2.0)
        u -= rng.choice([0.0, 1.0]) * rng.uniform(0.0, 2.0) * dx / np.linalg.norm(dx)
        g = rng.choice([0.0, rng.uniform(0.0, 0.5), rng.uniform(0.5, 3.0)])
        got = kern.collision_time(dx, u, sigma, g)
        ref = _brute_force_contact_time(dx, u, sigma, g)
        if math.isinf(ref):
            # no contact inside the scanned window: the prediction must lie beyond it
            assert got > 50.0 * (1 - 1e-12)
            continue
        checked += 1
        assert got == pytest.approx(ref, rel=1e-9, abs=1e-12)
        # and it is a contact: distance equals the grown contact distance
        r = np.linalg.norm(dx + got * u)
        assert r == pytest.approx(sigma + g * got, rel=1e-10)
    assert checked >= 20


def test_collision_time_near_contact_is_accurate():
    # a gap of 1e-13 sigma approached head on: the stable root keeps full precision
    sigma, h = 1.0, 1e-13
    dx = np.array([sigma * (1 + h), 0.0, 0.0])
    u = np.array([-0.3, 0.01, 0.0])
    g = 1e-4
    t = kern.collision_time(dx, u, sigma, g)
    # first order: gap closing speed 0.3 + g
    assert t == pytest.approx(sigma * h / (0.3 + g), rel=1e-3)
    # separating pair of non-growing spheres never collides; growing ones do
    assert math.isinf(kern.collision_time(dx, -u, sigma, 0.0))
    assert math.isinf(kern.collision_time(dx, np.array([0.3, 0.0, 0.0]), sigma, 1e-4))
    assert kern.collision_time(dx, np.array([1e-5, 0.0, 0.0]), sigma, 1e-4) > 0.0


def _state(packing, rate, seed=0, beta=10.0, neighbor_list=None):
    st = _State(packing, beta, np.random.default_rng(seed), neighbor_list)
    st.set_rate(rate)
    return st


def _run(st, max_coll, t_limit):
    """Run like the driver: rebuild whenever the kernel stops for cells or lists."""
    total = 0
    while total < max_coll:
        status, ncoll = st.run(max_coll - total, min(t_limit, st.t_rebuild))
        total += ncoll
        if status == kern.WINDOW_DONE or st.t >= t_limit:
            break
        st.rebuild()
    return total


@pytest.mark.parametrize("neighbor_list", [False, True])
def test_energy_and_momentum_conserved_without_growth(neighbor_list):
    pk = random_packing(200, 3, 0.35, seed=3)
    st = _state(pk, 0.0, neighbor_list=neighbor_list)
    K0 = kern.kinetic_energy(st.v)
    P0 = st.v.sum(axis=0)
    ncoll = _run(st, 20_000, math.inf)
    assert ncoll == 20_000
    assert kern.kinetic_energy(st.v) == pytest.approx(K0, rel=1e-12)
    assert np.abs(st.v.sum(axis=0) - P0).max() < 1e-12
    assert np.abs(P0).max() < 1e-12
    snap = st.packing(pk)
    assert max_overlap(snap)[1] <= OVERLAP_TOL


@pytest.mark.parametrize("neighbor_list", [False, True])
def test_energy_gain_with_growth_is_growth_rate_times_impulse(neighbor_list):
    # monodisperse: every collision adds J g with g = kappa, and the virial sums r J with
    # r = sigma(t_c) between sigma(0) and sigma(t): so dK / kappa lies in [vir/sigma(t), vir/sigma(0)]
    pk = random_packing(200, 3, 0.35, seed=4)
    kappa = 5e-3
    st = _state(pk, kappa, neighbor_list=neighbor_list)
    K0 = kern.kinetic_energy(st.v)
    s0 = st.scale()
    ncoll = _run(st, 5_000, math.inf)
    assert ncoll > 1000
    K1 = kern.kinetic_energy(st.v)
    assert K1 == pytest.approx(st.kinetic, rel=1e-12)  # bookkeeping of the kernel
    dK, vir = K1 - K0, st.virial
    assert dK > 0.0
    assert vir / st.scale() * (1 - 1e-12) <= dK / kappa <= vir / s0 * (1 + 1e-12)
    assert np.abs(st.v.sum(axis=0)).max() < 1e-12
    assert max_overlap(st.packing(pk))[1] <= OVERLAP_TOL


@pytest.mark.slow  # N = 256 in 3D compressed to phi = 0.46: the heaviest LS test
def test_carnahan_starling_liquid_3d():
    pk = random_packing(256, 3, 0.28, seed=1)
    res = compress(pk, 1e-4, phi_target=0.46, fast_growth_rate=None, seed=0)
    assert res.stop_reason == "phi_target"
    assert res.snapshots[-1].attrs["phi"] == pytest.approx(0.46, rel=1e-12)
    phi = res.eos.packing_fraction.values
    p = res.eos.pressure.values
    worst = 0.0
    for lo in np.arange(0.30, 0.45, 0.025):
        m = (phi >= lo) & (phi < lo + 0.025)
        assert m.sum() >= 10
        dev = float(np.mean(p[m] / carnahan_starling(phi[m]) - 1.0))
        worst = max(worst, abs(dev))
    print(f"largest mean deviation from Carnahan-Starling over phi 0.30-0.45: {worst:.3%}")
    assert worst < 0.03
    # temperature is held at 1/beta by rescaling
    assert np.allclose(res.eos.temperature.values, 0.1, rtol=0.05)


def test_pressure_targets_give_ordered_snapshots_without_overlap():
    pk = random_packing(128, 3, 0.3, seed=2)
    targets = [20.0, 100.0, 1e3, 1e4]
    res = compress(pk, 2e-3, targets, fast_growth_rate=None, seed=5)
    assert res.stop_reason == "p_targets"
    assert len(res.snapshots) == len(targets)
    last_phi, last_coll = 0.0, -1
    for target, snap in zip(targets, res.snapshots):
        assert snap.pressure >= target and snap.attrs["p"] == snap.pressure
        assert snap.attrs["phi"] == pytest.approx(snap.packing_fraction, rel=1e-12)
        assert snap.attrs["phi"] > last_phi and snap.attrs["collisions"] > last_coll
        last_phi, last_coll = snap.attrs["phi"], snap.attrs["collisions"]
        assert snap.protocol == "random>ls"
        assert snap.attrs["kappa"] == 2e-3
        assert max_overlap(snap)[1] <= OVERLAP_TOL
        snap.validate(OVERLAP_TOL)
        # diameters grow proportionally: the ratios of the input are kept
        assert np.allclose(snap.diameter / snap.diameter.mean(), pk.diameter / pk.diameter.mean(), rtol=1e-12)


def test_two_stage_protocol_switches_rate_at_fast_until():
    pk = random_packing(128, 3, 0.3, seed=6, dispersity="bi")
    res = compress(pk, 5e-4, [500.0], fast_growth_rate=5e-3, fast_until=100.0, seed=1)
    rate = res.eos.growth_rate.values
    p = res.eos.pressure.values
    switch = int(np.argmax(rate == 5e-4))
    assert switch > 0 and np.all(rate[:switch] == 5e-3) and np.all(rate[switch:] == 5e-4)
    assert p[switch - 1] >= 100.0 and np.all(p[: switch - 1] < 100.0)
    assert res.snapshots[0].attrs["kappa"] == 5e-4


@pytest.mark.parametrize("d,n", [(2, 128), (3, 128), (4, 128), (5, 200)])
def test_runs_in_d_2_to_5_without_overlap(d, n):
    pk = random_packing(n, d, 0.1 if d == 5 else 0.2, seed=d, dispersity="poly")
    res = compress(pk, 5e-3, [50.0], fast_growth_rate=None, seed=0)
    snap = res.snapshots[0]
    assert snap.pressure >= 50.0 and snap.d == d
    assert max_overlap(snap)[1] <= OVERLAP_TOL
    assert res.collisions > 0 and np.all(np.diff(res.eos.packing_fraction.values) > 0)


def test_same_seed_same_numbers():
    pk = random_packing(100, 3, 0.3, seed=7)
    a = compress(pk, 2e-3, [100.0], fast_growth_rate=None, seed=11)
    b = compress(pk, 2e-3, [100.0], fast_growth_rate=None, seed=11)
    c = compress(pk, 2e-3, [100.0], fast_growth_rate=None, seed=12)
    assert np.array_equal(a.snapshots[0].position, b.snapshots[0].position)
    assert np.array_equal(a.eos.pressure.values, b.eos.pressure.values)
    assert not np.array_equal(a.snapshots[0].position, c.snapshots[0].position)


def test_glass_branch_follows_eq15():
    # fast compression to high pressure: 1/p is linear in phi on the glass branch
    pk = random_packing(128, 3, 0.3, seed=8)
    res = compress(pk, 1e-3, [1e7], fast_growth_rate=5e-3, fast_until=500.0, seed=0)
    eos = res.eos
    fit = fit_jamming_density(eos.packing_fraction.values, eos.pressure.values, 3, p_min=1e3)
    phi_J = fit.phi_j
    print(f"phi_J = {phi_J:.6f} +- {fit.phi_j_err:.1e}, prefactor {fit.prefactor:.3f} (Eq. 15: 3)")
    assert eos.attrs["kappa"] == 1e-3
    snap = res.snapshots[0]
    # the fit extrapolates beyond the last state and stays below random close packing-ish bounds
    assert snap.packing_fraction < phi_J < 0.75
    # at p = 1e7 Eq. 15 puts the state within 3/p of phi_J
    assert (phi_J - snap.packing_fraction) / phi_J == pytest.approx(3.0 / snap.pressure, rel=0.3, abs=1e-6)
    assert max_overlap(snap)[1] <= OVERLAP_TOL


def test_fit_jamming_density_recovers_eq15():
    phi = np.linspace(0.60, 0.639, 40)
    p = 3.0 / (1.0 - phi / 0.64)
    fit = fit_jamming_density(phi, p, 3, p_min=1e2)
    assert fit.phi_j == pytest.approx(0.64, rel=1e-10) and fit.prefactor == pytest.approx(3.0, rel=1e-8)
    with pytest.raises(ValueError, match="at least 3"):
        fit_jamming_density(phi[:2], p[:2], 3, p_min=1.0)


def test_bad_inputs_are_refused():
    pk = random_packing(64, 3, 0.3, seed=9)
    with pytest.raises(ValueError, match="growth rate"):
        compress(pk, -1e-3, [100.0])
    with pytest.raises(ValueError, match="increasing"):
        compress(pk, 1e-3, [1e3, 1e2])
    with pytest.raises(ValueError, match="at least one stop"):
        compress(pk, 1e-3)
    with pytest.raises(ValueError, match="max_collisions or max_time"):
        compress(pk, 0.0, [100.0], fast_growth_rate=None)
    sheared = Packing(pk.position, pk.diameter, Box.lees_edwards([1.0, 1.0, 1.0], 0.1))
    with pytest.raises(ValueError, match="sheared"):
        compress(sheared, 1e-3, [100.0])
    x = pk.position.copy()
    x[1] = x[0] + np.array([0.5 * pk.diameter[0], 0.0, 0.0])
    overlapping = Packing(pk.box.wrap(x), pk.diameter, pk.box)
    with pytest.raises(ValueError, match="overlap"):
        compress(overlapping, 1e-3, [100.0])
    with pytest.raises(ValueError, match="phi_target"):
        compress(pk, 1e-3, phi_target=0.1)


def test_budget_stops():
    pk = random_packing(64, 3, 0.3, seed=10)
    res = compress(pk, 1e-3, [1e9], max_collisions=3000, fast_growth_rate=None)
    assert res.stop_reason == "max_collisions" and res.snapshots == []
    assert res.collisions == 3000
    res = compress(pk, 1e-3, [1e9], max_time=0.5, fast_growth_rate=None)
    assert res.stop_reason == "max_time"
    assert res.final.attrs["time"] == pytest.approx(0.5, rel=1e-12)
    assert max_overlap(res.final)[1] <= OVERLAP_TOL


@pytest.mark.slow
def test_crystallisation_detector_slow_versus_fast_compression():
    # 3D monodisperse: slow compression without the fast stage crystallises; the paper's
    # fast stage to p = 500 keeps the glass amorphous
    pk = random_packing(512, 3, 0.3, seed=12)
    slow = compress(pk, 1e-4, [300.0], fast_growth_rate=None, seed=0).snapshots[0]
    fast = compress(pk, 5e-3, [300.0], fast_growth_rate=None, seed=0).snapshots[0]
    f_slow, f_fast = crystal_fraction(slow), crystal_fraction(fast)
    print(f"crystal fraction: slow {f_slow:.3f} (phi {slow.packing_fraction:.4f}), "
          f"fast {f_fast:.3f} (phi {fast.packing_fraction:.4f})")
    assert f_slow > CRYSTAL_FRACTION_THRESHOLD > f_fast


def test_cli_writes_one_output_per_target_and_eos(tmp_path):
    from jamflow.cli import main
    from jamflow.io import read_dataset, read_packing, write_packing

    src = tmp_path / "in.nc"
    write_packing(random_packing(96, 3, 0.3, seed=13), src)
    outs = [tmp_path / "p100.nc", tmp_path / "p1000.nc"]
    rc = main(["ls", str(src), *map(str, outs), "--growth-rate", "2e-3", "--p-target", "100", "1000",
               "--fast-growth-rate", "0", "--eos", str(tmp_path / "eos.nc"), "--quiet"])
    assert rc == 0
    packs = [read_packing(o) for o in outs]
    assert [p.pressure >= t for p, t in zip(packs, (100.0, 1000.0), strict=True)] == [True, True]
    assert packs[0].packing_fraction < packs[1].packing_fraction
    eos = read_dataset(tmp_path / "eos.nc")
    assert eos.pressure.values.max() >= 1000.0 and eos.sizes["record"] > 5
    # the number of outputs must match the targets
    assert main(["ls", str(src), str(outs[0]), "--growth-rate", "2e-3", "--p-target", "100", "1000",
                 "--quiet"]) == 1


def test_real_ls_configurations_stay_without_overlap(calippso_ls_file):
    # the CALiPPSO authors' LS packings (N = 1024, d = 3, 4, 5, relative gaps down to
    # ~1e-11): hard-sphere dynamics at fixed diameters keeps energy, momentum and
    # non-overlap, and measures a pressure in the glass regime (p >> 1) in both windows
    from jamflow.io.formats import read_dat

    pk = read_dat(calippso_ls_file)
    res = compress(pk, 0.0, max_collisions=20 * pk.n, fast_growth_rate=None, seed=0)
    p = res.eos.pressure.values
    assert len(p) == 2 and np.all(p > 1e4)
    assert p[1] == pytest.approx(p[0], rel=0.2)
    assert np.allclose(res.eos.temperature.values, 0.1, rtol=1e-12)  # no growth: no heating
    assert max_overlap(res.final)[1] <= OVERLAP_TOL
