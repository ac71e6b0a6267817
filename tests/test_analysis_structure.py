"""g(r), hexatic psi6 and Steinhardt Q6 on configurations with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from ls_data import ls_dat

from jamflow.analysis.structure import (
    crystal_like,
    hexatic_order,
    radial_distribution,
    steinhardt_q,
    structure_dataset,
)
from jamflow.box import Box
from jamflow.io import read_dataset
from jamflow.io.formats import read_dat
from jamflow.state.packing import Packing


def triangular(nx: int, ny: int, spacing: float = 1.0, shift: float = 0.1) -> Packing:
    x = np.array([[i + 0.5 * (j % 2), j * np.sqrt(3) / 2] for j in range(ny) for i in range(nx)]) * spacing
    box = Box.orthogonal([nx * spacing, ny * spacing * np.sqrt(3) / 2])
    return Packing(box.wrap(x + shift), np.full(len(x), spacing), box)


def fcc(cells: int, a: float = 1.0) -> Packing:
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    grid = np.array([[i, j, k] for i in range(cells) for j in range(cells) for k in range(cells)])
    x = ((grid[:, None, :] + base[None]) * a).reshape(-1, 3) + 0.01 * a
    return Packing(x, np.full(len(x), a / np.sqrt(2)), Box.cubic(3, cells * a))


def ideal_gas(rng: np.random.Generator, n: int, d: int, length: float) -> Packing:
    # point-like particles: diameters only set the length unit of g(r)
    return Packing(rng.random((n, d)) * length, np.full(n, 0.01 * length), Box.cubic(d, length))


@pytest.mark.parametrize("d", [2, 3])
def test_ideal_gas_rdf_is_one(rng, d):
    n = 3000
    p = ideal_gas(rng, n, d, 1.0)
    r, g, edges = radial_distribution(p, r_max=30.0, bins=15)  # r up to 0.3 box lengths
    pairs_per_bin = 0.5 * n * (n - 1) * np.diff(edges ** d) * (np.pi if d == 2 else 4 * np.pi / 3) * 0.01**d
    err = 1.0 / np.sqrt(pairs_per_bin)
    print(f"d={d}: max |g-1|/err = {np.max(np.abs(g - 1) / err):.2f}")
    assert np.all(np.abs(g - 1.0) < 5.0 * err)


def test_triangular_lattice_rdf_peaks_at_shell_distances():
    p = triangular(20, 20)
    r, g, edges = radial_distribution(p, r_max=3.2, bins=320)
    peaks = r[g > 0]
    expected = np.array([1.0, np.sqrt(3.0), 2.0, np.sqrt(7.0), 3.0])
    for s in expected:
        assert np.min(np.abs(peaks - s)) <= 0.0051  # within a bin width of the shell
    # no weight anywhere else, and 6 first neighbours per particle
    assert all(np.min(np.abs(expected - q)) <= 0.0051 for q in peaks)
    shell = (r > 0.9) & (r < 1.1)
    rho = p.n / p.box.volume
    n_first = np.sum(g[shell] * rho * np.pi * np.diff(edges**2)[shell])
    assert n_first == pytest.approx(6.0, rel=1e-9)


def test_psi6_triangular_is_one_and_random_is_small(rng):
    psi = hexatic_order(triangular(12, 12))
    assert np.allclose(np.abs(psi), 1.0, atol=1e-12)
    assert abs(psi.mean()) == pytest.approx(1.0, abs=1e-12)
    n = 2000
    psi_r = hexatic_order(ideal_gas(rng, n, 2, 1.0))
    print(f"random: global |psi6| = {abs(psi_r.mean()):.4f}, local mean {np.abs(psi_r).mean():.3f}")
    assert abs(psi_r.mean()) < 3.0 / np.sqrt(n)
    assert np.abs(psi_r).mean() < 0.6


def test_psi6_of_triangular_lattice_in_a_sheared_box_is_one():
    # a Lees-Edwards tilt of a whole number of lattice spacings maps the lattice onto itself,
    # so neighbours found through the tilted images must still give |psi6| = 1
    p = triangular(12, 12)
    box = Box.lees_edwards(p.box.lengths, 3.0 / p.box.lengths[1])
    sheared = Packing(box.wrap(p.position), p.diameter, box)
    assert np.allclose(np.abs(hexatic_order(sheared)), 1.0, atol=1e-12)


def test_q6_fcc_and_crystal_fraction():
    q, Q, _ = steinhardt_q(fcc(4))
    assert Q == pytest.approx(0.57452, abs=1e-4)
    assert np.allclose(q, 0.57452, atol=1e-4)
    crystal, connected = crystal_like(fcc(4))
    assert crystal.all() and np.all(connected == 12)


def test_q6_random_is_small_and_not_crystal(rng):
    n = 2000
    q, Q, _ = steinhardt_q(ideal_gas(rng, n, 3, 1.0))
    crystal, _ = crystal_like(ideal_gas(rng, n, 3, 1.0))
    print(f"random: Q6 = {Q:.4f}, <q6> = {q.mean():.3f}, crystal fraction {crystal.mean():.4f}")
    assert Q < 0.05
    assert crystal.mean() < 0.02


def test_ls_packing_is_amorphous():
    p = read_dat(ls_dat(3))
    ds = structure_dataset(p, r_max=2.5, bins=250)
    print(f"LS d=3: Q6 = {ds.attrs['Q6_global']:.4f}, crystal fraction {ds.attrs['crystal_fraction']:.4f}")
    assert ds.attrs["Q6_global"] < 0.1
    assert ds.attrs["crystal_fraction"] < 0.05
    # contact peak: g is largest in the first bin at or beyond one diameter
    k = int(np.argmax(ds["g"].values))
    assert 1.0 <= ds["r"].values[k] < 1.02


def test_rdf_rejects_r_max_beyond_half_box():
    with pytest.raises(ValueError, match="half the smallest box width"):
        radial_distribution(triangular(6, 6), r_max=3.5)


def test_rdf_cli_in_four_dimensions_reports_g_only(tmp_path):
    from jamflow.cli import main

    out = tmp_path / "rdf.nc"
    assert main(["rdf", str(ls_dat(4)), str(out), "--r-max", "1.3"]) == 0
    ds = read_dataset(out)
    assert "not computed" in ds.attrs["crystallinity"]
    assert set(ds.data_vars) == {"g", "r_lower"}
    assert all("units" in v.attrs and "long_name" in v.attrs for v in ds.data_vars.values())


def test_a_2d_packing_never_reaches_the_3d_code_paths(monkeypatch):
    # "model only what a scene requires": the 2D crystallinity analyses use psi6 only
    import jamflow.analysis.structure as structure

    def forbidden(*args, **kwargs):
        raise AssertionError("3D Steinhardt code called for a 2D packing")

    monkeypatch.setattr(structure, "steinhardt_q", forbidden)
    monkeypatch.setattr(structure, "crystal_like", forbidden)
    monkeypatch.setattr(structure, "bond_order_vectors", forbidden)
    p = triangular(12, 12)
    ds = structure.structure_dataset(p, 2.5, 100)
    assert "psi6_abs" in ds and "Q6_global" not in ds.attrs
    assert structure.crystal_fraction(p) == 1.0
