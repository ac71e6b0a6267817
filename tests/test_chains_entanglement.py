"""Entangled linked packings are refused (links of soft spheres passed through each other).

Regression of chains-fig2 (2D, 50 trimers from an overlapping start at phi = 0.86): the
bisection ended with 8 pairs of crossing links and overlaps up to 0.445 diameters at
P = 1e-4 (forces balanced by link tensions), silently written as a jammed packing.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.chains.builders import crossing_links, rigid_cluster_links
from jamflow.chains.entanglement import EntanglementError, check_untangled
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.io import write_packing
from jamflow.minimize.fire import minimize_fire
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.potential import overlapping_pairs
from jamflow.state.bodies import Links
from jamflow.state.packing import Packing
from jamflow.tolerances import ENTANGLED_OVERLAP


def _packing(x: np.ndarray, side: float, clusters: list[np.ndarray]) -> Packing:
    """Unit spheres at ``x`` in a cubic box, each group of ``clusters`` made rigid by links."""
    pairs, lengths = [], []
    for members in clusters:
        p, r = rigid_cluster_links(x[members], int(members[0]))
        pairs += p
        lengths += r
    p = np.array(pairs)
    links = Links(p[:, 0], p[:, 1], np.array(lengths, dtype=np.float64))
    return Packing(x, np.ones(len(x)), Box.cubic(x.shape[1], side), links=links, protocol="test")


def _threaded_trimers() -> Packing:
    """3D: a bent trimer whose first link threads the triangle of another (off-centre by ~0.1)."""
    t = 2.0 * np.pi * np.arange(3) / 3.0
    triangle = np.stack([np.cos(t), np.sin(t), np.zeros(3)], axis=1) / np.sqrt(3.0)
    b = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, -0.5], [np.sin(np.pi / 3.0), 0.0, -0.5 - np.cos(np.pi / 3.0)]])
    x = np.concatenate([triangle, b + np.array([0.08, -0.05, 0.1])]) + 2.0
    return _packing(x, 4.0, [np.arange(3), np.arange(3, 6)])


def test_threaded_trimers_are_a_trapped_minimum_refused_by_the_jamming_bisection(tmp_path, capsys):
    start = _threaded_trimers()
    # the state is a stable trap: FIRE from the off-centre start comes back to overlaps of 0.236
    # (distance sqrt(1/3 + 1/4) from a threading sphere to each corner), far above the pressure's
    model = LinkedSpheresModel(start.box, start.diameter, start.links, start.position)
    res = minimize_fire(model, start.position, 1e-12, 100_000)
    _, xi, _ = overlapping_pairs(res.position, start.box, start.diameter)
    assert res.converged and np.sort(xi)[-6:] == pytest.approx(1.0 - np.sqrt(1.0 / 3.0 + 0.25), rel=1e-6)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2, max_steps=200_000)
    with pytest.raises(EntanglementError, match=r"6 pair\(s\) of spheres are trapped .* clusters \(0, 1\)"):
        jam_linked(start, 1e-4, settings=settings)
    with pytest.raises(EntanglementError, match="trapped"):
        jam_linked(start, 1e-4, settings=settings, shear_stabilize=True)
    write_packing(start, tmp_path / "s.nc")
    assert main(["soft-jam", str(tmp_path / "s.nc"), str(tmp_path / "j.nc"), "--pressure", "1e-4", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "entangled clusters" in err and "--no-overlap" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "j.nc").exists()
    # a plain minimisation of the same start is refused as well
    assert main(["minimize", str(tmp_path / "s.nc"), str(tmp_path / "m.nc"), "--quiet"]) == 1
    assert "entangled clusters" in capsys.readouterr().err and not (tmp_path / "m.nc").exists()


def test_crossed_trimers_in_2d_are_refused_naming_the_clusters():
    # trimer 1's first link (3, 4) crosses trimer 0's link (0, 1) at right angles, no sphere shared
    x = np.array([[2.0, 2.0], [3.0, 2.0], [2.5, 2.0 + np.sqrt(0.75)],
                  [2.5, 1.5], [2.5, 2.5], [2.5 + np.sqrt(0.75), 2.0]])
    p = _packing(x, 6.0, [np.arange(3), np.arange(3, 6)])
    assert len(crossing_links(p.links, p.position, p.box)) > 0
    with pytest.raises(EntanglementError, match=r"of cluster 0 and .* of cluster 1"):
        check_untangled(p.links, p.position, p.box, p.diameter, 1e-4)


def test_separated_trimers_at_the_soft_contact_level_pass():
    # the same two trimers side by side, touching with an overlap of the order of P0 = 1e-4
    x = np.array([[2.0, 2.0], [3.0, 2.0], [2.5, 2.0 + np.sqrt(0.75)],
                  [3.9999, 2.0], [4.9999, 2.0], [4.4999, 2.0 + np.sqrt(0.75)]])
    p = _packing(x, 8.0, [np.arange(3), np.arange(3, 6)])
    check_untangled(p.links, p.position, p.box, p.diameter, 1e-4)
    # and a deep overlap is not refused when the pressure carries it (an overcompressed soft packing)
    x[3:, 0] -= 0.2 - 1e-4
    _, xi, f = overlapping_pairs(x, p.box, p.diameter)
    assert xi.max() > ENTANGLED_OVERLAP
    pressure = float(f.max()) / p.box.volume  # d V P / sum r = 2 f_max / 0.8 > f_max / 100
    check_untangled(p.links, x, p.box, p.diameter, pressure)
    # at P = 1e-6 the force scale is 2 V P / 0.8 = 1.6e-4: the force 0.2 is 1250 times it
    with pytest.raises(EntanglementError, match="trapped"):
        check_untangled(p.links, x, p.box, p.diameter, 1e-6)
