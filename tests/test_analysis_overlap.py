"""Contact-network overlap Q (CALiPPSO Sec. III A) on packings with known shared contacts."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.analysis.overlap import contact_overlap, overlap_series
from jamflow.box import Box
from jamflow.io import read_dataset, write_packing
from jamflow.state.packing import Packing, near_pairs


def lattice_with_contacts(nx: int = 10, ny: int = 10) -> Packing:
    x = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2] for j in range(ny) for i in range(nx)]) + 0.1
    box = Box.orthogonal([nx, ny * np.sqrt(3) / 2])
    p = Packing(x, np.ones(len(x)), box)
    pairs, _ = near_pairs(p, 1e-9)
    return p.evolve(contacts=np.stack([pairs.i, pairs.j], axis=1))


def test_q_of_packing_with_itself_is_one():
    p = lattice_with_contacts()
    q, common, na, nb = contact_overlap(p, p)
    assert q == 1.0 and common == na == nb == 300


@pytest.mark.parametrize("k", [1, 7, 150])
def test_q_with_copy_missing_k_contacts(rng, k):
    ref = lattice_with_contacts()
    nc = len(ref.contacts)
    drop = rng.choice(nc, size=k, replace=False)
    partial = ref.evolve(contacts=np.delete(ref.contacts, drop, axis=0))
    q, common, _, nb = contact_overlap(partial, ref)
    assert q == pytest.approx(1.0 - k / nc, abs=1e-15)
    assert common == nc - k and nb == nc
    # the other way round every contact of the reference is found
    assert contact_overlap(ref, partial)[0] == 1.0


def test_contacts_are_matched_by_particle_identity_not_geometry(rng):
    ref = lattice_with_contacts()
    # relabel particles: same geometry, different identities -> few common contacts
    perm = rng.permutation(ref.n)
    inv = np.argsort(perm)
    relabelled_contacts = np.sort(inv[ref.contacts], axis=1)
    moved = ref.evolve(contacts=relabelled_contacts)
    q, *_ = contact_overlap(moved, ref)
    assert q < 0.1


def test_inflated_copy_is_the_same_sample_but_other_diameters_are_refused():
    ref = lattice_with_contacts()
    inflated = ref.evolve(diameter=ref.diameter * 1.0001)
    assert contact_overlap(inflated, ref)[0] == 1.0
    d = ref.diameter.copy()
    d[3] *= 1.1
    with pytest.raises(ValueError, match="same particles"):
        contact_overlap(ref.evolve(diameter=d), ref)
    small = Packing(ref.position[:50], ref.diameter[:50], ref.box)
    with pytest.raises(ValueError, match="differ in size"):
        contact_overlap(small, ref)


def test_series_against_largest_target_pressure(rng):
    ref = lattice_with_contacts()
    nc = len(ref.contacts)
    packings, p_target, missing = [], [1e11, 1e3, 1e5, 1e7], [0, 30, 10, 2]
    for k in missing:
        keep = np.delete(ref.contacts, rng.choice(nc, size=k, replace=False), axis=0)
        packings.append(ref.evolve(contacts=keep))
    ds = overlap_series(packings, p_target)
    assert list(ds["p_target"].values) == [1e3, 1e5, 1e7, 1e11]
    assert np.allclose(ds["one_minus_Q"].values, np.array([30, 10, 2, 0]) / nc)
    assert np.all(ds["abs_delta_phi_J"].values == 0.0)
    assert "n_lp" not in ds and "kappa" not in ds.attrs


def test_series_carries_lp_counts_and_growth_rate():
    ref = lattice_with_contacts()
    packings = [ref.evolve(attrs={"iterations": n}) for n in (9, 4, 2)]
    ds = overlap_series(packings, [1e3, 1e5, 1e7], growth_rate=3e-5)
    assert list(ds["n_lp"].values) == [9, 4, 2]
    assert ds.attrs["kappa"] == 3e-5
    mixed = [packings[0], ref, packings[2]]
    assert "n_lp" not in overlap_series(mixed, [1e3, 1e5, 1e7])


def test_overlap_cli(tmp_path):
    from jamflow.cli import main

    ref = lattice_with_contacts()
    # a packing of the same sample with five contacts fewer; translated by a thousandth of the
    # box, as overlap-series refuses one packing given twice (Q counts contacts by particle labels)
    part = ref.evolve(position=ref.box.wrap(ref.position + 1e-3 * ref.box.lengths), contacts=ref.contacts[5:])
    write_packing(ref, tmp_path / "b.nc")
    write_packing(part, tmp_path / "a.nc")
    assert main(["overlap", str(tmp_path / "a.nc"), str(tmp_path / "b.nc"), str(tmp_path / "q.nc")]) == 0
    ds = read_dataset(tmp_path / "q.nc")
    assert ds.attrs["Q"] == pytest.approx(1 - 5 / 300) and ds.attrs["n_common"] == 295
    assert main(["overlap-series", str(tmp_path / "a.nc"), str(tmp_path / "b.nc"), str(tmp_path / "s.nc"),
                 "--p-target", "1e4", "1e8"]) == 0
    s = read_dataset(tmp_path / "s.nc")
    assert s["Q"].values[0] == pytest.approx(1 - 5 / 300) and s["Q"].values[1] == 1.0
