"""Saddle guard of linked packings (:func:`jamflow.chains.jamming.leave_linked_saddle`).

Physics checked: a hypostatic linked minimum whose floppy mode has negative curvature (a
saddle at which FIRE stops because the force along the mode vanishes by symmetry) is
kicked off it and ends isostatic by rank at P0 with no negative curvature left; a
hypostatic minimum whose floppy mode is held by its prestress (3D chains of four, a free
torsion) has no negative curvature and is kept as it is, not kicked.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from jamflow.chains import jamming
from jamflow.chains.hessian import constrained_hessian
from jamflow.chains.jamming import leave_linked_saddle
from jamflow.io import read_packing
from jamflow.minimize.fire import minimize_enthalpy_model, minimize_fire
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.potential import HARMONIC, overlapping_pairs
from jamflow.models.strain import ShearStabilizedModel
from jamflow.network import count_bodies
from jamflow.state.bodies import Links

DATA = Path(__file__).parent / "data"


def _at_minimum(p, settings):
    model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
    res = minimize_fire(model, p.position, settings.force_tol, 10**6, settings.fire_params)
    return model, replace(res, box=p.box)


def _count(p, res):
    pairs, _, _ = overlapping_pairs(res.box.wrap(res.position), res.box, p.diameter, HARMONIC)
    free = ~p.links.contains(pairs.i, pairs.j)
    contacts = np.stack([pairs.i, pairs.j], axis=1)[free]
    return count_bodies(contacts, p.n, p.d, p.links, res.box.wrap(res.position), res.box)


@pytest.mark.slow
@pytest.mark.parametrize("newton_polish", [False, True])
def test_a_linked_saddle_is_kicked_to_an_isostatic_stable_minimum(newton_polish, monkeypatch):
    # the 8-disk saddle of tests/test_onset_search.py as a linked packing without links at fixed box:
    # 8 contacts against the isostatic 9, an eigenvalue ~ -f/r, forces balanced by symmetry
    p0 = 1e-7
    p = read_packing(DATA / "saddle_8disks_p1e-7.nc", None)
    p = p.evolve(links=Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)))
    settings = JammingSettings(pressure_rtol=1e-3, newton_polish=newton_polish)
    # the re-bisection after a kick ends its minimisations as the settings ask
    polished = []
    bisect = jamming.bisect_to_pressure
    monkeypatch.setattr(jamming, "bisect_to_pressure",
                        lambda *a, **k: polished.append(k.get("polish", False)) or bisect(*a, **k))
    model, at_saddle = _at_minimum(p, settings)
    assert at_saddle.converged and at_saddle.steps == 0
    before = _count(p, at_saddle)
    assert before.isostatic_count - before.n_contacts == 1
    w = constrained_hessian(p.evolve(position=at_saddle.position), strain=False).eigenvalues
    assert w.min() < -p0
    model, final, steps, kicks = leave_linked_saddle(model, at_saddle, p, p0, settings, False, seed=0)
    assert kicks >= 1 and steps > 0 and final.converged
    assert polished and set(polished) == {newton_polish}
    assert abs(final.pressure - p0) <= settings.pressure_rtol * p0
    after = _count(p, final)
    assert after.n_contacts >= after.isostatic_count > 0
    w = constrained_hessian(p.evolve(position=final.position, box=final.box), strain=False).eigenvalues
    assert w.min() > -1e-12  # round-off of the zero translations


def test_a_shear_stabilised_saddle_is_kicked_and_re_minimised_at_p0_with_the_box_free():
    """Shear-stabilised, the onset ends with the enthalpy (volume free): the 8-disk saddle minimised there is
    still a saddle of the Hessian with the strain, and the guard re-minimises the kicked state by the enthalpy
    too, to a stable minimum at P0."""
    p0 = 1e-7
    p = read_packing(DATA / "saddle_8disks_p1e-7.nc", None)
    p = p.evolve(links=Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0)))
    settings = JammingSettings(pressure_rtol=1e-3)
    model = ShearStabilizedModel(p.box, p.diameter, p.links, p.position, fixed_volume=False)
    res = minimize_enthalpy_model(model, p.position, p0, settings.force_tol, settings.pressure_rtol, 10**6,
                                  settings.fire_params, "full")
    assert res.converged
    assert constrained_hessian(p.evolve(position=res.position, box=res.box), strain=True).eigenvalues.min() < -p0
    model, final, steps, kicks = leave_linked_saddle(model, res, p, p0, settings, True, seed=0)
    assert kicks >= 1 and steps > 0 and final.converged and model.box_dofs
    # a diagonal strain force (W_aa - P0 V) / q_s within F_tol puts P within q_s F_tol / V of P0
    assert abs(final.pressure - p0) <= model.strain_scale * settings.force_tol / final.box.volume
    w = constrained_hessian(p.evolve(position=final.position, box=final.box), strain=True).eigenvalues
    assert w.min() > -1e-12  # round-off of the zero translations


def test_a_hypostatic_chain_packing_held_by_its_prestress_is_not_kicked():
    # 32 chains of four in 3D (frozen angles, free torsions) at P0 = 1e-6 one contact short of the
    # rank count (tests/data/bodies/make.sh): its floppy mode has positive curvature of the order of
    # the contact forces (the prestress), so it is a stable minimum, not a saddle
    p = read_packing(DATA / "bodies" / "hypostatic_chains4_3d.nc", None)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3)
    model, res = _at_minimum(p, settings)
    assert res.converged
    c = _count(p, res)
    assert c.isostatic_count - c.n_contacts == 1
    w = np.sort(constrained_hessian(p.evolve(position=res.position), strain=False).eigenvalues)
    # three translations and the torsion of one dangling end sphere are zero modes; the next mode,
    # floppy for the contact network, is held at the pressure scale, far below the stiff modes
    assert np.all(np.abs(w[:4]) < 1e-10) and w.min() > -1e-12
    assert 0.0 < w[4] < 10 * 1e-6 and w[4] < 0.05 * w[5]
    _, final, steps, kicks = leave_linked_saddle(model, res, p, 1e-6, settings, False, seed=0)
    assert kicks == 0 and steps == 0 and final is res
