"""The onset's energy verdict (a bound on the pressure of any minimum below an energy) and its secant steps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import betainc

from jamflow.box import Box
from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import linked_volume
from jamflow.minimize.fire import DEFAULT_FIRE, minimize_fire
from jamflow.minimize.onset import (
    VERDICT_SHARE,
    JammingSettings,
    bisect_to_pressure,
    jam_model_to_pressure,
)
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.shapes.model import ShapeModel
from jamflow.models.spheres.model import SphereModel
from jamflow.models.spheres.potential import (
    HARMONIC,
    PowerLawPotential,
    energy_floor,
    evaluate,
    max_contacts,
)
from jamflow.models.strain import ShearStabilizedModel
from jamflow.shapes import bidisperse_shapes, random_shape_packing, unit_shape
from jamflow.state.bodies import Links

P0 = 1e-4


def _disks(phi: float, n: int = 64, seed: int = 3):
    """Bidisperse disks (1 : 1.4, mean diameter 1) at random in a square box of packing fraction ``phi``."""
    rng = np.random.default_rng(seed)
    D = np.where(np.arange(n) % 2 == 0, 1.0, 1.4)
    D /= D.mean()
    side = np.sqrt(np.pi / 4 * np.sum(D**2) / phi)
    return SphereModel(Box(side * np.eye(2)), D), rng.random((n, 2)) * side


def _shapes(family: str, phi: float):
    """24 bidisperse bodies (asphericity 1.1) placed at phi 0.4, squeezed affinely to ``phi``."""
    p = random_shape_packing(bidisperse_shapes(unit_shape(family, asphericity=1.1)), 24, 0.4, 1)
    model = ShapeModel(p.box, p.shapes, p.shape_index)
    f = (0.4 / phi) ** 0.5
    model, start = model.rescaled(f, np.column_stack([p.position, p.orientation]))
    return model, start


def _trimers(phi: float, flexible: bool, kind: type = LinkedSpheresModel):
    """16 rigid 2D trimers (``flexible``: chains of 3 without the angle link) squeezed to ``phi`` (a ``kind`` model)."""
    p = linked_packing(2, 16, "trimer", np.random.default_rng(2))[0]
    s = p.in_units(float(p.diameter.mean()))
    links = s.links
    if flexible:
        keep = links.j == links.i + 1
        links = Links(links.i[keep], links.j[keep], links.length[keep])
    box = Box(s.box.matrix)
    f = (linked_volume(2, s.diameter, links) / box.volume / phi) ** 0.5
    return kind(box.scaled(f), s.diameter, links, s.position * f), s.position * f


def test_max_contacts_is_the_cap_bound_and_covers_the_kissing_numbers():
    """The cap share by the incomplete beta function against its closed forms in d = 2 (beta / pi) and
    d = 3 ((1 - cos beta) / 2); six neighbours per disk exactly, at least the twelve of spheres."""
    D = np.r_[np.ones(50), 1.4 * np.ones(50)]
    beta = np.arcsin(1.0 / 2.4)
    assert max_contacts(2, D) == 100 * int(np.ceil(np.pi / beta)) // 2
    assert max_contacts(3, D) == 100 * int(np.ceil(2.0 / (1.0 - np.cos(beta)))) // 2
    assert 0.5 * betainc(1.0, 0.5, np.sin(beta) ** 2) == pytest.approx((1.0 - np.cos(beta)) / 2, rel=1e-14)
    assert max_contacts(2, np.ones(10)) == 30
    assert 12 * 10 // 2 <= max_contacts(3, np.ones(10)) <= 15 * 10 // 2
    # overlaps let neighbours sit closer: more of them
    assert max_contacts(3, D, overlap=0.2) > max_contacts(3, D)


@pytest.mark.parametrize("potential", [HARMONIC, PowerLawPotential(exponent=2.5)], ids=["harmonic", "hertz"])
def test_energy_floor_is_tight_on_a_compressed_triangular_crystal(potential):
    """Every disk of a compressed triangular crystal overlaps its six neighbours by the same ``xi``: Hölder's
    inequality is an equality there, so the floor lies just below the crystal's energy (the contact bound
    may count a seventh neighbour, and ``f r = epsilon xi^(w-1) (1 - xi)``)."""
    rows, cols, xi = 8, 8, 1e-3
    a = 1.0 - xi
    x = np.array([[(c + 0.5 * (r % 2)) * a, r * a * np.sqrt(3) / 2] for r in range(rows) for c in range(cols)])
    box = Box(np.diag([cols * a, rows * a * np.sqrt(3) / 2]))
    D = np.ones(len(x))
    ev = evaluate(x, box, D, potential)
    assert ev.n_contacts == 3 * len(x)
    floor = energy_floor(potential, D, box.volume, 2, ev.pressure)
    assert floor < ev.energy
    assert energy_floor(potential, D, box.volume, 2, ev.pressure * (7 / 6) / (1.0 - xi)) >= ev.energy


@pytest.mark.parametrize("flexible", [False, True], ids=["rigid-trimers", "chains-of-3"])
def test_linked_minimum_pressure_is_the_centroid_virial_within_the_lever(flexible):
    """At a force-balanced linked minimum the pressure with link tensions equals the contacts' virial with the
    clusters' centroid distances as lever arms (1e-9), every such arm is within ``lever`` times the contact
    distance, and the energy lies above the floor of that pressure."""
    model, x = _trimers(0.86, flexible)
    res = minimize_fire(model, x, 1e-12, 200_000)
    assert res.converged and res.pressure > 0.0
    labels = model.links.clusters(model.n)
    # each cluster unwrapped about its first sphere (clusters are far smaller than the box), then centroids
    first = np.array([np.flatnonzero(labels == c)[0] for c in range(labels.max() + 1)])
    y = res.position[first[labels]] + model.box.minimum_image(res.position - res.position[first[labels]])
    to_centroid = np.array([y[labels == c].mean(axis=0) for c in range(labels.max() + 1)])[labels] - y
    nl = SphereModel(model.box, model.diameter).nlist
    nl.update(res.position, model.box)
    keep = ~model.links.contains(nl.i, nl.j)
    i, j, sigma = nl.i[keep], nl.j[keep], nl.sigma[keep]
    rij = res.position[j] - res.position[i] + nl.image[keep] @ model.box.matrix.T
    r = np.linalg.norm(rij, axis=1)
    on = r < sigma
    i, j, rij, r, sigma = i[on], j[on], rij[on], r[on], sigma[on]
    f = (1.0 - r / sigma) / sigma
    arm = rij + to_centroid[j] - to_centroid[i]
    virial = np.sum(f / r * np.sum(rij * arm, axis=1))
    assert virial / (2 * model.box.volume) == pytest.approx(res.pressure, rel=1e-9)
    assert np.max(np.linalg.norm(arm, axis=1) / sigma) <= model.lever
    assert res.energy > model.energy_floor(res.pressure)


def test_centroid_reach_of_known_clusters():
    """A dimer's spheres lie half a link from its centroid (the bound is exact); a straight chain of four
    reaches 1.5 links, within the bound 3 x 3 / 4; random chains of four stay within it."""
    assert Links([0], [1], [2.0]).centroid_reach(2) == pytest.approx(1.0, rel=1e-15)
    chain = Links([0, 1, 2], [1, 2, 3], [1.0, 1.0, 1.0])
    assert chain.centroid_reach(4) == pytest.approx(2.25, rel=1e-15)
    rng = np.random.default_rng(4)
    for _ in range(200):
        steps = rng.standard_normal((3, 3))
        x = np.vstack([np.zeros(3), np.cumsum(steps / np.linalg.norm(steps, axis=1, keepdims=True), axis=0)])
        assert np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)) <= chain.centroid_reach(4)


@pytest.mark.parametrize("family", ["ellipse", "circulo-line"])
def test_shape_energy_floor_lies_below_the_energy_of_minima_near_jamming(family):
    """Minima of a shape packing decompressed in steps towards jamming: each one's energy lies above the floor of
    its own pressure (where the bound applies, pressures below ~1e-2 here)."""
    model, x = _shapes(family, 0.95)
    x = minimize_fire(model, x, 1e-10, 200_000).position
    phi, checked = 0.95, 0
    for new in np.arange(0.90, 0.86, -0.002):
        model, x = model.rescaled((phi / new) ** 0.5, x)
        phi = new
        res = minimize_fire(model, x, 1e-10, 200_000)
        x = res.position
        if res.pressure <= 0.0:
            break
        floor = model.energy_floor(res.pressure)
        assert res.energy > floor >= 0.0
        checked += floor > 0.0
    assert checked >= 2


@pytest.mark.parametrize("case", ["disks-unjammed", "trimers-unjammed", "trimers-shear-stabilised-unjammed",
                                  "ellipses-unjammed", "circulo-lines-unjammed", "disks-jammed"])
def test_energy_verdict_agrees_with_the_full_minimisation(case):
    """A minimisation stopped by the verdict ends, when continued to its minimum, below the verdict's pressure;
    one whose minimum lies above it never stops early. Each run gets a model of its own (a model's lists and
    caches carry over between runs and change the path by round-off)."""
    starts = {
        "disks-unjammed": lambda: _disks(0.80),
        "trimers-unjammed": lambda: _trimers(0.70, flexible=False),
        "trimers-shear-stabilised-unjammed": lambda: _trimers(0.74, flexible=True, kind=ShearStabilizedModel),
        "ellipses-unjammed": lambda: _shapes("ellipse", 0.86),
        "circulo-lines-unjammed": lambda: _shapes("circulo-line", 0.86),
        "disks-jammed": lambda: _disks(0.90),
    }
    ceiling = VERDICT_SHARE * (1.0 - 0.1) * P0
    model, x = starts[case]()
    floor = model.energy_floor(ceiling)
    assert floor > 0.0
    early = minimize_fire(model, x, 1e-2 * P0, 1_000_000, DEFAULT_FIRE, floor)
    full = minimize_fire(*starts[case](), 1e-2 * P0, 1_000_000, DEFAULT_FIRE)
    assert full.converged
    if case == "disks-jammed":
        assert full.pressure > P0 and early.converged and not early.below
        assert early.steps == full.steps and early.energy == full.energy
        return
    assert early.below and not early.converged and early.steps < full.steps
    assert early.energy <= floor
    assert full.pressure < ceiling


def test_secant_steps_reach_the_window_in_fewer_minimisations():
    """The fixed-box stage at the final force tolerance: with secant steps the same window ``|P - P0| <= 1e-3 P0``
    and force balance, in fewer minimisations than the halving bisection from the same loose minimum."""
    model, x = _disks(0.86)
    loose = bisect_to_pressure(model, x, 0.86, P0, 1e-2 * P0, 0.1, 1e-2, 1_000_000)
    model1, res1, phi1, delta, direction, _, _ = loose
    runs = {}
    for secant in (False, True):
        history = {"phi": [], "pressure": [], "steps": []}
        m, res, phi, *_ = bisect_to_pressure(model1, res1.position, phi1, P0, 1e-12, 1e-3, delta, 2_000_000,
                                             history=history, direction=direction, secant=secant)
        assert res.converged and res.max_force <= 1e-12
        assert abs(res.pressure - P0) <= 1e-3 * P0
        runs[secant] = len(history["phi"])
    assert runs[True] < runs[False]


def _last_bracket(phi: list[float], pressure: list[float]) -> float:
    """``dP/dphi`` of the secant through the last minimum above ``P0`` and the last one below it."""
    above = max(k for k, p in enumerate(pressure) if p > P0)
    below = max(k for k, p in enumerate(pressure) if 0.0 < p < P0)
    return (pressure[above] - pressure[below]) / (phi[above] - phi[below])


def test_a_resumed_bisection_steps_on_the_slope_of_the_loose_bracket():
    """The loose bisection returns the slope of its last bracket of ``P0`` (read back from its history), and the
    fixed-box stage at the final force tolerance resumed with it takes the secant step from its first minimum:
    ``P`` is linear in ``phi`` on one contact network, so that step lands in ``|P - P0| <= 1e-3 P0`` at once.
    Without it the stage first steps the loose stage's whole ``delta_phi`` and needs more minimisations. A slope
    without secant steps is refused."""
    model, x = _disks(0.86)
    loose = {"phi": [], "pressure": [], "steps": []}
    model1, res1, phi1, delta, direction, _, slope = bisect_to_pressure(model, x, 0.86, P0, 1e-2 * P0, 0.1, 1e-2,
                                                                        1_000_000, history=loose)
    assert slope == pytest.approx(_last_bracket(loose["phi"], loose["pressure"]), rel=1e-12)
    runs = {}
    for seeded in (None, slope):
        history = {"phi": [], "pressure": [], "steps": []}
        _, res, *_ = bisect_to_pressure(model1, res1.position, phi1, P0, 1e-12, 1e-3, delta, 2_000_000,
                                        history=history, direction=direction, secant=True, slope=seeded)
        assert res.converged and res.max_force <= 1e-12 and abs(res.pressure - P0) <= 1e-3 * P0
        runs[seeded is not None] = history
    seeded = runs[True]
    assert len(seeded["phi"]) == 2 < len(runs[False]["phi"])
    assert seeded["phi"][1] - seeded["phi"][0] == pytest.approx((P0 - seeded["pressure"][0]) / slope, rel=1e-12)
    with pytest.raises(ValueError, match="secant"):
        bisect_to_pressure(model1, res1.position, phi1, P0, 1e-12, 1e-3, delta, 10, slope=slope)


def test_the_final_fixed_box_stage_of_jamming_starts_on_the_loose_slope():
    """``jam_model_to_pressure`` of linked trimers in a fixed box: the final stage's first minimisation (at the
    loose stage's last ``phi``) is followed by the secant step on the slope of the loose stage's last bracket,
    not by the loose stage's ``delta_phi``, and that step lands in the pressure window."""
    model, x = _trimers(0.7, False)
    _, final, history, _ = jam_model_to_pressure(model, x, 0.7, P0, JammingSettings(1e-12, 1e-3, 1e-2))
    phi, pressure = history["phi"], history["pressure"]
    first = next(k for k in range(1, len(phi)) if phi[k] == phi[k - 1])  # the final stage resumes at the same phi
    slope = _last_bracket(phi[:first], pressure[:first])
    assert phi[first + 1] - phi[first] == pytest.approx((P0 - pressure[first]) / slope, rel=1e-12)
    assert len(phi) == first + 2 and final.converged and abs(final.pressure - P0) <= 1e-3 * P0
