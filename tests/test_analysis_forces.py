"""Contact-force distribution: normalisation, small-force exponent, bucklers."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.analysis.fitting import FitWarning
from jamflow.analysis.forces import (
    THETA_EXTENDED,
    bucklers,
    force_distribution,
    normalised_forces,
)
from jamflow.box import Box
from jamflow.io import read_dataset, write_packing
from jamflow.state.packing import Packing, near_pairs


def lattice(nx: int, ny: int) -> Packing:
    """Triangular lattice of touching unit discs with all 3 N contacts (z = 6)."""
    x = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2] for j in range(ny) for i in range(nx)]) + 0.1
    p = Packing(x, np.ones(len(x)), Box.orthogonal([nx, ny * np.sqrt(3) / 2]))
    pairs, _ = near_pairs(p, 1e-9)
    return p.evolve(contacts=np.stack([pairs.i, pairs.j], axis=1))


def with_forces(p: Packing, f: np.ndarray) -> Packing:
    return p.evolve(force=f)


def test_distribution_integrates_to_one(rng):
    base = lattice(30, 30)
    samples = [with_forces(base, rng.exponential(2.5, len(base.contacts))) for _ in range(4)]
    ds = force_distribution(samples, f_max=30.0, linear_bins=300, log_min=1e-9, bins_per_decade=4)
    df = np.diff(np.linspace(0, 30.0, 301))
    lin = np.sum(ds["P_linear"].values * df)
    log_w = np.diff(np.append(ds["f_log_lower"].values, 30.0))
    below = np.mean([np.mean(normalised_forces(s)[0] < 1e-9) for s in samples])
    print(f"integral linear {lin:.12f}, log {np.sum(ds['P_log'].values * log_w):.12f}")
    assert lin == pytest.approx(1.0 - ds.attrs["fraction_above_f_max"], abs=1e-12)
    assert np.sum(ds["P_log"].values * log_w) == pytest.approx(1.0 - ds.attrs["fraction_above_f_max"] - below, abs=1e-12)
    # forces are in units of their mean: the first moment is one up to binning
    assert np.sum(ds["f"].values * ds["P_linear"].values * df) == pytest.approx(1.0, abs=0.01)
    # exponential forces: P(x) = exp(-x) in units of the mean, within 4 Poisson errors per bin
    x, p = ds["f"].values, ds["P_linear"].values
    n_total = 4 * len(base.contacts)
    expected_err = np.sqrt(np.exp(-x) / (n_total * df))
    sel = x < 3
    assert np.all(np.abs(p[sel] - np.exp(-x[sel])) < 4 * expected_err[sel] + 0.01)


def test_small_force_exponent_recovered(rng):
    base = lattice(40, 40)
    theta = THETA_EXTENDED
    samples = [with_forces(base, rng.random(len(base.contacts)) ** (1.0 / (1.0 + theta))) for _ in range(10)]
    ds = force_distribution(samples, fit_min=1e-3, fit_max=0.3, bins_per_decade=4)
    print(f"theta = {ds.attrs['fit_exponent']:.3f} +- {ds.attrs['fit_exponent_err']:.3f}")
    assert abs(ds.attrs["fit_exponent"] - theta) < 2.5 * ds.attrs["fit_exponent_err"]
    assert ds.attrs["fit_exponent_err"] < 0.1


def test_bucklers_and_rattlers_are_classified():
    p = lattice(8, 8)
    c = p.contacts
    buckler, rattler = 10, 40
    drop_b = np.flatnonzero((c == buckler).any(axis=1))[:3]  # 6 -> 3 = d + 1 contacts
    drop_r = np.flatnonzero((c == rattler).any(axis=1))[:5]  # 6 -> 1 contact: rattler
    keep = np.delete(c, np.concatenate([drop_b, drop_r]), axis=0)
    q = Packing(p.position, p.diameter, p.box, contacts=keep, force=np.arange(1.0, len(keep) + 1))
    b = bucklers(q)
    assert np.flatnonzero(b).tolist() == [buckler]
    f, on_buckler = normalised_forces(q)
    assert len(f) == len(keep) - 1  # the rattler's last contact is not in the backbone
    assert on_buckler.sum() == 3
    assert f.mean() == pytest.approx(1.0)


def test_needs_forces():
    with pytest.raises(ValueError, match="contacts and forces"):
        force_distribution([lattice(6, 6)])


def test_forces_cli(tmp_path, rng):
    p = lattice(10, 10)
    write_packing(with_forces(p, rng.random(len(p.contacts))), tmp_path / "p.nc")
    from jamflow.cli import main

    assert main(["forces", str(tmp_path / "p.nc"), str(tmp_path / "f.nc"), "--quiet"]) == 0
    ds = read_dataset(tmp_path / "f.nc")
    for key in ("fit_exponent", "fit_exponent_buckler", "fit_exponent_extended", "buckler_definition"):
        assert key in ds.attrs
    assert all("units" in v.attrs and "long_name" in v.attrs for v in ds.data_vars.values())


def test_buckler_and_extended_tails_are_separated(rng):
    # triangular lattice; every third particle of every other row loses three of its six
    # contacts and becomes a buckler (d + 1 = 3); its neighbours keep four or more
    nx, ny = 36, 36
    p = lattice(nx, ny)
    c = p.contacts
    centres = np.array([j * nx + i for j in range(0, ny, 2) for i in range(0, nx, 3)])
    drop = []
    for k in centres:
        mine = np.flatnonzero((c == k).any(axis=1))
        drop.extend(mine[:3])
    keep = np.delete(c, drop, axis=0)
    z = np.bincount(keep.ravel(), minlength=p.n)
    expected = z == 3  # independent count: no rattlers here (min z is 3)
    assert z.min() >= 3 and expected.sum() == len(centres)
    on_buckler = expected[keep[:, 0]] | expected[keep[:, 1]]
    theta_l, theta_e = 0.17462, THETA_EXTENDED
    samples = []
    for _ in range(12):
        f = np.empty(len(keep))
        f[on_buckler] = rng.random(on_buckler.sum()) ** (1.0 / (1.0 + theta_l))
        f[~on_buckler] = rng.random((~on_buckler).sum()) ** (1.0 / (1.0 + theta_e))
        samples.append(Packing(p.position, p.diameter, p.box, contacts=keep, force=f))
    assert np.array_equal(bucklers(samples[0]), expected)
    ds = force_distribution(samples, log_min=1e-5, fit_min=1e-4, fit_max=0.3, bins_per_decade=3)
    tl, tle = ds.attrs["fit_exponent_buckler"], ds.attrs["fit_exponent_buckler_err"]
    te, tee = ds.attrs["fit_exponent_extended"], ds.attrs["fit_exponent_extended_err"]
    print(f"buckler theta = {tl:.3f} +- {tle:.3f} (true {theta_l}); extended {te:.3f} +- {tee:.3f} (true {theta_e})")
    assert abs(tl - theta_l) < 2.5 * tle and abs(te - theta_e) < 2.5 * tee
    assert te - tl > 3.0 * np.hypot(tle, tee)  # the two populations are told apart
    assert ds.attrs["buckler_fraction"] == pytest.approx(len(centres) / p.n)


def test_hypostatic_network_needs_all_contacts(rng):
    # keep only the horizontal bonds of the lattice: z = 2 < d + 1, rattler removal empties it
    p = lattice(10, 10)
    dx = p.contact_vectors()
    horizontal = p.contacts[np.abs(dx[:, 1]) < 1e-9]
    q = Packing(p.position, p.diameter, p.box, contacts=horizontal, force=rng.random(len(horizontal)) + 0.1)
    with pytest.raises(ValueError, match="no backbone contacts"):
        force_distribution([q])
    ds = force_distribution([q], backbone_only=False)
    assert ds.attrs["n_forces"] == len(horizontal) == 100
    assert ds.attrs["buckler_fraction"] == 0.0  # every particle has 2 contacts, none has d + 1 = 3


def test_theta_refuses_too_few_forces_in_window(tmp_path, rng, capsys):
    # 300 contacts with a uniform P(f): ~5 forces below 0.1 <f>, far too few for theta
    p = lattice(10, 10)
    q = with_forces(p, rng.random(len(p.contacts)))
    with pytest.warns(FitWarning, match="fit refused"):  # in API use, not only a CLI line
        ds = force_distribution([q], fit_min=1e-3, fit_max=1e-1)
    assert ds.attrs["fit_exponent_n_in_window"] < 50
    assert np.isnan(ds.attrs["fit_exponent"]) and "fewer than the minimum" in ds.attrs["fit_exponent_reason"]
    write_packing(q, tmp_path / "p.nc")
    from jamflow.cli import main

    assert main(["forces", str(tmp_path / "p.nc"), str(tmp_path / "f.nc"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: theta (all)" in err and "FitWarning" not in err  # the command's line, not Python's
