"""The jamming-onset search (``onset="search"`` of :mod:`jamflow.minimize.onset`) from dilute starts.

Physics checked: from phi = 0.1 and 0.2 every body kind reaches P0 in at most 60
minimisations (a count, not a time) and the packing is isostatic by the backbone count
(spheres) or by rank (linked spheres); where both methods follow the same path (8 disks
from phi = 0.5) the search lands on the bisection's contact network and phi_J; a
hypostatic force-balanced state at P0 is a saddle (negative Hessian eigenvalue) at which
FIRE stops, and the guard moves it to a stable isostatic minimum.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.analysis.contacts import summarize
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import jam_linked
from jamflow.io import read_packing
from jamflow.minimize.fire import minimize_enthalpy_model
from jamflow.minimize.onset import JammingSettings
from jamflow.models.spheres.model import SphereModel
from jamflow.models.spheres.potential import HARMONIC
from jamflow.neighbors.verlet import NeighborList
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure, leave_saddle
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)

DATA = Path(__file__).parent / "data"
P0 = 1e-7
#: Issue 46 asks for "at most about 60" minimisations from phi >= 0.1; measured means 40-61
#: and maxima 40-66 over 5 seeds per kind and start (docs/notes/chains.md, "Dilute starts").
MAX_MINIMIZATIONS = 66


def _lowest_hessian_eigenvalue(position: np.ndarray, box, diameter: np.ndarray) -> float:
    """Lowest eigenvalue of the sphere Hessian [epsilon / <D>^2] (two zero translations included)."""
    model = SphereModel(box, diameter, HARMONIC, NeighborList(diameter))
    return float(np.linalg.eigvalsh(model.hessian(model.dofs(position)).toarray())[0])


@pytest.mark.parametrize("d, phi0", [(2, 0.1), (2, 0.2), (3, 0.1)])
def test_spheres_from_dilute_start_reach_p0_isostatic_in_few_minimisations(d, phi0):
    res = jam_to_pressure(random_packing(64, d, phi0, "bi", seed=1), P0, onset="search")
    p = res.packing
    assert len(res.history["phi"]) <= MAX_MINIMIZATIONS
    assert p.attrs["onset_method"] == "search" and p.attrs["onset_minimizations"] == len(res.history["phi"])
    assert res.converged and abs(p.pressure - P0) <= 1e-6 * P0
    s = summarize(p)
    assert s.n_stable > 0 and s.isostatic, (s.n_contacts, s.isostatic_count)


def test_search_lands_on_the_bisections_packing_when_the_path_is_the_same():
    """8 bidisperse disks from phi = 0.5 (test_extremes' start): both methods reach one backbone.

    The pressure window |P - P0| <= 1e-6 P0 spans Delta phi = 2e-6 P0 / (dP/dphi) ~ 1e-12 at
    the measured dP/dphi ~ 0.2 of this packing: phi_J agrees to that.
    """
    start = random_packing(8, 2, 0.5, "bi", seed=1)
    search = jam_to_pressure(start, P0, onset="search")
    bisection = jam_to_pressure(start, P0)
    assert bisection.packing.attrs["onset_method"] == "bisection"
    def backbone(p):
        c = p.contacts
        return c[~p.rattler[c[:, 0]] & ~p.rattler[c[:, 1]]]

    # the same backbone (a rattler's place is arbitrary)
    assert np.array_equal(search.packing.rattler, bisection.packing.rattler)
    assert np.array_equal(backbone(search.packing), backbone(bisection.packing))
    assert abs(search.packing.packing_fraction - bisection.packing.packing_fraction) <= 1e-11
    assert 5 * len(search.history["phi"]) < len(bisection.history["phi"])
    s = summarize(search.packing)
    assert s.isostatic and s.n_contacts == 13


def test_hypostatic_state_at_p0_is_a_saddle_fire_stops_at_and_the_guard_leaves():
    """The packing a search that overshot to 1e5 P0 and decompressed ended in (8 disks, seed 1).

    5 stable disks with 8 contacts against the isostatic 9, forces in equal pairs: enthalpy
    FIRE started there stops at once (forces below 1e-13 by symmetry), yet the Hessian has
    an eigenvalue ~ -f/r < 0. The guard kicks it off the saddle; the new minimum is
    isostatic, stable (no negative eigenvalue beyond round-off) and is the bisection's.
    """
    p = read_packing(DATA / "saddle_8disks_p1e-7.nc", None)
    settings = JammingSettings()
    model = SphereModel(p.box, p.diameter, HARMONIC, NeighborList(p.diameter))
    at_saddle = minimize_enthalpy_model(model, p.position, P0, settings.force_tol, settings.pressure_rtol)
    assert at_saddle.converged and at_saddle.steps == 0
    assert _lowest_hessian_eigenvalue(at_saddle.position, at_saddle.box, p.diameter) < -P0
    final, steps, kicks = leave_saddle(at_saddle, p.diameter, HARMONIC, P0, settings, seed=0)
    assert kicks >= 1 and steps > 0 and final.converged
    assert abs(final.pressure - P0) <= settings.pressure_rtol * P0
    # round-off of the two zero translations: ~1e-15
    assert _lowest_hessian_eigenvalue(final.position, final.box, p.diameter) > -1e-12
    phi = float(np.pi / 4 * np.sum(p.diameter**2) / final.box.volume)
    bisection = jam_to_pressure(random_packing(8, 2, 0.5, "bi", seed=1), P0, onset="bisection").packing
    assert abs(phi - bisection.packing_fraction) <= 1e-11


@pytest.mark.parametrize("phi0", [0.1, 0.2])
def test_rigid_trimers_from_dilute_start_in_few_minimisations_isostatic_by_rank(phi0):
    start = linked_packing(2, 50, "trimer", np.random.default_rng(1), phi=phi0)[0]
    res = jam_linked(start, 1e-6, settings=JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, onset="search"))
    a = res.packing.attrs
    assert res.converged and len(res.history["phi"]) <= MAX_MINIMIZATIONS
    assert a["onset_method"] == "search"
    assert a["n_contacts"] >= a["isostatic_count"] > 0


@pytest.mark.slow
def test_shear_stabilised_trimers_from_dilute_start_in_few_minimisations():
    start = linked_packing(2, 50, "trimer", np.random.default_rng(1), phi=0.2)[0]
    res = jam_linked(start, 1e-6, settings=JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, onset="search"),
                     shear_stabilize=True)
    a = res.packing.attrs
    assert res.converged and len(res.history["phi"]) <= MAX_MINIMIZATIONS
    assert a["n_contacts"] >= a["isostatic_count"] > 0


@pytest.mark.parametrize("family", ["ellipse", "circulo-line"])
def test_shapes_from_dilute_start_in_few_minimisations(family):
    table = bidisperse_shapes(unit_shape(family, asphericity=1.1))
    res = jam_shapes(random_shape_packing(table, 16, 0.2, 1), 1e-6, JammingSettings(force_tol=1e-12,
                                                                                     pressure_rtol=1e-3, onset="search"))
    assert res.converged and len(res.history["phi"]) <= MAX_MINIMIZATIONS
    assert abs(res.packing.pressure - 1e-6) <= 1e-3 * 1e-6
    assert res.packing.attrs["onset_method"] == "search"
