"""Bodies at their limits: shapes of aspect ratio 10, near-disk ellipses, chains of 30, P0 down to 1e-12.

Every case goes through the entry points of ``jamflow soft-jam`` (:func:`jamflow.shapes.jam_shapes`,
:func:`jamflow.chains.jamming.jam_linked`) and asserts the physics of the bodies' own tests:
converged; ``|P - P0| <= pressure_rtol P0``; the largest generalised force (forces and torques
per body; projected forces of linked spheres, the link constraint forces removed) recomputed
from the stored packing within ``force_tol``; every pair repulsive, its virial summing to the
stored pressure, and no overlap beyond the scale set by P0 (:func:`overlap_scale`); link
lengths within ``LINK_LENGTH_RTOL``; counting by rank (shapes: ``N_c = N_c^0 - N_1`` with
``N_1`` the quartic modes of the dynamical matrix; linked spheres: the cluster count, with a
hypostatic verdict accepted only where the constrained Hessian shows a stable minimum). Cases
out of range are refused in one line before any work. Measured limits and times:
docs/extremes.md ("Bodies"), docs/notes/extremes.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from jamflow.chains.hessian import ZERO_MODE_RTOL, constrained_hessian
from jamflow.chains.jamming import SADDLE_CURVATURE_RATIO, is_saddle, jam_linked
from jamflow.cli import main
from jamflow.io import read_packing
from jamflow.minimize.onset import JammingSettings
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.potential import HARMONIC, overlapping_pairs
from jamflow.network import count_bodies
from jamflow.shapes import (
    bidisperse_shapes,
    jam_shapes,
    random_shape_packing,
    unit_shape,
)
from jamflow.shapes.counting import count_constraints, shape_model_of
from jamflow.shapes.spectrum import spectrum
from jamflow.tolerances import ENTANGLED_FORCE_RATIO, LINK_LENGTH_RTOL


def overlap_scale(force: np.ndarray, arm: np.ndarray, volume: float, d: int, pressure: float) -> float:
    """``f_P = d V P / sum_c r_c`` [energy / length]: the mean contact force if the pressure
    ``P`` (of contacts and link tensions together) were carried by the contacts alone (``r_c``
    each contact's virial arm), as in :data:`~jamflow.tolerances.ENTANGLED_FORCE_RATIO`.

    The bound asserted with it: every contact force, hence every overlap (``delta = f / k``
    for the linear springs of every body kind here), is at most ``ENTANGLED_FORCE_RATIO f_P``.
    Jammed packings reach 2-10 ``f_P``; an overlap held by anything but the pressure (links
    threaded through a sphere, crossed cores, a contact left over from a denser state) is
    beyond it. Every contact must be repulsive (``f_c > 0``, ``r_c > 0``).
    """
    assert np.all(force > 0.0) and np.all(arm > 0.0)
    return d * volume * pressure / float(np.sum(arm))


def check_shapes(result, p0: float, settings: JammingSettings, quartic: bool = True) -> dict:
    """The physics of a jammed shape packing (module doc): with ``quartic``, ``N_c = N_c^0 - N_1``
    from the dynamical matrix (``parallel="twice"``, every contact point as the matrix sees it)."""
    p = result.packing
    assert result.converged
    assert abs(p.pressure - p0) <= settings.pressure_rtol * p0
    model, q = shape_model_of(p)
    ev = model.evaluate(q)
    assert model.max_force(model.project(ev.gradient, q)) <= settings.force_tol
    pairs = model.pair_table(q)
    force = np.linalg.norm(pairs["gradient"][:, 3:5], axis=1)
    # pair virial w = F_j . (x_j - x_i) > 0 for a repulsive pair of convex bodies; its arm w / |F|
    virial = -np.sum(pairs["gradient"][:, 3:5] * pairs["dx"], axis=1)
    # the stored pressure is the virial of these overlaps
    assert float(np.sum(virial)) == pytest.approx(2.0 * p.box.volume * p.pressure, rel=1e-9)
    f_p = overlap_scale(force, virial / force, p.box.volume, 2, p.pressure)
    delta = np.sqrt(2.0 * pairs["energy"] / model.k)  # U = (k / 2) delta^2 per pair (deepest terms)
    assert delta.max() <= ENTANGLED_FORCE_RATIO * f_p / model.k
    counting, *_ = count_constraints(p, "twice")
    spec = spectrum(p, fourth=False)
    if quartic:
        # every constraint missing to the isostatic count is a quartic mode (Sec. III B)
        assert spec.balanced
        assert counting.n_contacts == counting.isostatic_count - spec.n_quartic
    return {"counting": counting, "spectrum": spec, "max_overlap": float(delta.max()),
            "f_max_over_f_p": float(force.max() / f_p)}


def check_linked(result, p0: float, settings: JammingSettings, shear_stabilized: bool = False,
                 below_excess: bool = True, chain_length: int = 30) -> dict:
    """The physics of a jammed linked packing (module doc); ``below_excess``: ``P0`` low enough
    for no excess contact, so the packing is isostatic or hypostatic and stable; ``chain_length``:
    the packing is of flexible chains of that many spheres, whose isostatic count is checked
    against its closed form (0: not checked)."""
    p = result.packing
    assert result.converged
    assert abs(p.pressure - p0) <= settings.pressure_rtol * p0
    assert np.max(np.abs(p.links.length_errors(p.position, p.box))) <= LINK_LENGTH_RTOL
    if shear_stabilized:
        assert p.attrs["max_force_sq"] <= settings.force_tol**2
    else:
        model = LinkedSpheresModel(p.box, p.diameter, p.links, p.position)
        q = model.dofs(p.position)
        assert model.max_force(model.project(model.evaluate(q).gradient, q)) <= settings.force_tol
    pairs, xi, f = overlapping_pairs(p.position, p.box, p.diameter, HARMONIC)
    free = ~p.links.contains(pairs.i, pairs.j)
    # the stored contacts are the overlapping pairs that are not linked, with their harmonic forces
    assert len(p.contacts) == int(free.sum())
    np.testing.assert_allclose(np.sort(p.force), np.sort(f[free]), rtol=1e-12)
    f_p = overlap_scale(f[free], pairs.distance[free], p.box.volume, p.d, p.pressure)
    # relative overlap of a harmonic contact: xi = f sigma / epsilon (epsilon = 1)
    assert f[free].max() <= ENTANGLED_FORCE_RATIO * f_p
    count = count_bodies(p.contacts, p.n, p.d, p.links, p.position, p.box, shear_stabilized=shear_stabilized)
    assert count.n_contacts == p.attrs["n_contacts"] and count.isostatic_count == p.attrs["isostatic_count"]
    if chain_length:
        # flexible chains of M spheres: f_c = d M - (M - 1) per chain in the backbone, minus free
        # motions and the d translations, plus the pressure (or the strain at fixed volume)
        chains = p.n // chain_length - int(count.removed.sum())
        extra = p.d * (p.d + 1) // 2 - 1 if shear_stabilized else 0
        f_c = p.d * chain_length - (chain_length - 1)
        assert count.isostatic_count == f_c * chains - int(count.free_dofs.sum()) - p.d + 1 + extra
    missing = count.isostatic_count - count.n_contacts
    if below_excess:
        # N P0^(1/2) << 1: no finite-pressure excess contact expected (O'Hern et al.)
        assert missing >= 0, count
    if missing > 0:
        # hypostatic by rank: only a stable minimum (the floppy mode held by its prestress) is a
        # packing; a negative curvature at the scale of the contact forces is a saddle
        w = constrained_hessian(p, HARMONIC, strain=shear_stabilized).eigenvalues
        assert w.min() >= -SADDLE_CURVATURE_RATIO * float(f[free].mean()), (missing, w.min())
    return {"n_contacts": count.n_contacts, "isostatic_count": count.isostatic_count,
            "n_rattlers": int(count.rattler.sum()), "max_overlap": float(xi[free].max()),
            "f_max_over_f_p": float(f[free].max() / f_p)}


DATA = Path(__file__).parent / "data" / "bodies"
#: The pressure sweep of the issue.
PRESSURES = [1e-3, 1e-6, 1e-9, 1e-12]


# --- shapes -----------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["ellipse", "circulo-line"])
def test_aspect_ratio_10_in_a_box_too_small_is_refused_in_one_line(tmp_path, capsys, kind):
    """16 bodies of aspect ratio 10 at phi = 0.3 leave a box narrower than two of the large
    bodies' bounding diameters (3.69 and 3.31 against a box of 6.56): refused before any
    placement, nothing written."""
    out = tmp_path / "s.nc"
    assert main(["init-shapes", str(out), "--shape", kind, "--aspect-ratio", "10", "--n", "16", "--seed", "1",
                 "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "half the smallest box width" in err[0]
    assert not out.exists()


def test_aspect_ratio_10_whose_box_shrinks_below_the_bodies_is_refused_in_one_line(tmp_path, capsys):
    """32 ellipses of aspect ratio 10 fit at phi = 0.3 (box 9.28 against bounding diameters up to
    3.69), but compression shrinks the box below twice that long before jamming: soft-jam stops in
    one line as soon as it does (a few compression steps), nothing written."""
    src, out = tmp_path / "s.nc", tmp_path / "j.nc"
    assert main(["init-shapes", str(src), "--shape", "ellipse", "--aspect-ratio", "10", "--n", "32", "--seed", "1",
                 "--quiet"]) == 0
    capsys.readouterr()
    assert main(["soft-jam", str(src), str(out), "--pressure", "1e-4", "--delta-phi", "1e-2", "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "box too small for the largest particles" in err[0]
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ellipse", "circulo-line"])
def test_aspect_ratio_10_jams_at_n_64(kind):
    """64 bodies of aspect ratio 10 (the start of ``init-shapes --aspect-ratio 10 --n 64 --seed 1``)
    at P0 = 1e-4: forces, torques, pressure and overlaps as every case here, no crossed cores, and
    a stable minimum, hypostatic by rank (contacts counted twice): the dynamical matrix has only
    the two translations as zero modes and no negative eigenvalue. Ellipses: exactly
    ``N_c^0 - N_c`` eigenvalues lie below ``sqrt(P0 k)`` (the band held by the pressure, ~P0,
    against the contacts' ~k; measured 0.16 ... 46 P0, the next 372 P0), so ``N_c = N_c^0 - N_1``
    (Sec. III B). Circulo-lines (3 short, eigenvalues from 3.5 P0 rising without a gap through
    ``sqrt(P0 k)``) have no band the spectrum can split at this P0. Measured: docs/extremes.md
    ("Bodies")."""
    p0 = 1e-4
    start = random_shape_packing(bidisperse_shapes(unit_shape(kind, aspect_ratio=10.0)), 64, 0.3, 1)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-3, delta_phi=1e-2)
    result = jam_shapes(start, p0, settings)
    check_shapes(result, p0, settings, quartic=False)
    model, q = shape_model_of(result.packing)
    model.check_cores(q)
    counting, *_ = count_constraints(result.packing, "twice")
    spec = spectrum(result.packing, lambda_c=float(np.sqrt(p0 * model.k)), fourth=False)
    assert spec.balanced
    assert counting.counting == "hypostatic"
    assert spec.n_zero == 2 + 3 * counting.n_rattlers + counting.n_sliders
    assert np.sort(spec.eigenvalue)[spec.n_zero] > 0.0
    if kind == "ellipse":
        assert counting.n_contacts == counting.isostatic_count - spec.n_quartic


@pytest.fixture(scope="module")
def ellipse_sweep():
    """16 ellipses of A = 1.1 (the start of tests/test_shapes_jamming.py) jammed to every P0 of the sweep."""
    start = random_shape_packing(bidisperse_shapes(unit_shape("ellipse", asphericity=1.1)), 16, 0.4, 11)
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    return settings, {p0: jam_shapes(start, p0, settings) for p0 in PRESSURES}


def test_ellipse_pressure_sweep_from_1e_3_to_1e_12(ellipse_sweep):
    """Forces, torques, pressure and overlaps at every P0; the missing constraints are quartic
    modes at every P0: the ``N_c^0 - N_c`` lowest non-trivial eigenvalues of the dynamical matrix
    scale with P0 (Fig. 10) while the next one does not (region 2).

    The spectrum's own split (``N_c = N_c^0 - N_1``) is asserted where it can resolve the band:
    at 1e-3 the band (lambda / P0 = 0.18, 0.46) lies within a factor 7 of region 2 (3.2e-3),
    under ``REGION_GAP_MIN_RATIO``; at 1e-12 it lies below the zero-mode floor
    ``ZERO_EIGENVALUE_RTOL lambda_max`` = 7.5e-13 and the residual forces are 2 % of P0, which
    the spectrum reports as unbalanced (its warning that ``N_1`` may be wrong).
    """
    settings, results = ellipse_sweep
    bands, region2 = [], []
    for p0, result in results.items():
        out = check_shapes(result, p0, settings, quartic=p0 in (1e-6, 1e-9))
        c, spec = out["counting"], out["spectrum"]
        assert c.counting == "hypostatic"
        missing = c.isostatic_count - c.n_contacts
        trivial = 2 + 3 * c.n_rattlers + c.n_sliders
        lam = np.sort(spec.eigenvalue)
        assert np.all(np.abs(lam[:trivial]) <= 1e-14 * lam[-1])
        bands.append(lam[trivial:trivial + missing] / p0)
        region2.append(lam[trivial + missing])
        if p0 == 1e-12:
            assert not spec.balanced
    np.testing.assert_allclose(bands, np.broadcast_to(bands[2], np.shape(bands)), rtol=0.1)
    np.testing.assert_allclose(region2, region2[2], rtol=0.05)


@pytest.mark.slow
def test_near_disk_ellipses_are_hypostatic_by_their_quartic_rotations():
    """Ellipses with alpha - 1 = 1e-5 (A - 1 = 3.75e-11) at P0 = 1e-6: the backbone is a disk
    network, ``N_c = 2 N' - 1``, hypostatic by ``N'`` against ``3 N' - 1``, and the ``N'``
    missing constraints are the quartic rotations (region 1, eigenvalues ~ P0 (alpha - 1)
    = 1e-11, here 2.4e-12 ... 3.6e-11 against the zero floor 5e-13)."""
    start = random_shape_packing(bidisperse_shapes(unit_shape("ellipse", aspect_ratio=1.0 + 1e-5)), 16, 0.5, 1)
    settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
    out = check_shapes(jam_shapes(start, 1e-6, settings), 1e-6, settings)
    c, spec = out["counting"], out["spectrum"]
    n_prime = 16 - c.n_rattlers
    assert c.n_contacts == 2 * n_prime - 1 and spec.n_quartic == n_prime
    assert spec.n_zero == 2 + 3 * c.n_rattlers


# --- linked spheres ---------------------------------------------------------------------


def chains_of_30(tmp_path_factory, d: int):
    """4 flexible chains of 30 spheres (bidisperse by chain, 1:1.4), the dilute start of ``init-chains``."""
    path = tmp_path_factory.mktemp(f"chains{d}") / "c.nc"
    assert main(["init-chains", str(path), "--d", str(d), "--clusters", "4", "--cluster", "chain",
                 "--chain-length", "30", "--free-angles", "--dispersity", "bi", "--ratio", "1.4", "--seed", "1",
                 "--quiet"]) == 0
    return read_packing(path, None)


@pytest.mark.slow
def test_one_chain_of_30_in_2d_that_cannot_fit_in_half_its_box_is_refused_in_one_line(tmp_path, capsys):
    """One chain of 30 at the dilute phi = 0.2 has a box of 10.85: the growth walk must fit it
    within half the box (5.43), i.e. 30 discs in a 5.43 x 5.43 window at an area fraction of 0.8,
    which a random walk does not find; init-chains gives up in one line (after its restarts),
    nothing written. Four chains of 30 fit (the box is twice as wide)."""
    out = tmp_path / "one.nc"
    assert main(["init-chains", str(out), "--d", "2", "--clusters", "1", "--cluster", "chain", "--chain-length",
                 "30", "--free-angles", "--seed", "1", "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "could not grow chain 0 of 30 spheres" in err[0]
    assert not out.exists()


@pytest.fixture(scope="module")
def chains_3d(tmp_path_factory):
    return chains_of_30(tmp_path_factory, 3)


LINKED = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)


@pytest.mark.slow
def test_chains_of_30_in_3d_jam_isostatic(chains_3d):
    """N = 120 at P0 = 1e-6 (N P0^(1/2) = 0.12): links held, projected forces balanced, isostatic by rank."""
    out = check_linked(jam_linked(chains_3d, 1e-6, settings=LINKED), 1e-6, LINKED)
    assert out["n_contacts"] == out["isostatic_count"]


@pytest.mark.slow
@pytest.mark.parametrize("p0", [1e-3, 1e-9])
def test_chains_of_30_pressure_sweep(chains_3d, p0):
    """The rest of the sweep with the default force tolerance: at 1e-3 finite-pressure excess
    contacts are allowed (not a saddle), at 1e-9 isostatic or a stable hypostatic minimum."""
    check_linked(jam_linked(chains_3d, p0, settings=LINKED), p0, LINKED, below_excess=p0 < 1e-6)


@pytest.mark.slow
def test_chains_of_30_at_1e_12_with_force_tolerance_1e_15(chains_3d):
    """P0 = 1e-12 needs residual forces far below the contact forces (~1e-12): with force_tol =
    1e-15 (the float64 floor of the projected forces, ~1e-15 for box sides ~10) the packing is
    isostatic or a stable hypostatic minimum (measured: one contact short, lowest constrained
    eigenvalue -1.1e-15, round-off)."""
    settings = JammingSettings(force_tol=1e-15, pressure_rtol=1e-3, delta_phi=1e-2)
    result = jam_linked(chains_3d, 1e-12, settings=settings)
    # the stored (wrapped) centres carry the round-off of wrapping: the recomputed forces are
    # checked against twice the tolerance there, the minimiser's own against the tolerance
    assert result.packing.attrs["max_force_sq"] <= settings.force_tol**2
    check_linked(result, 1e-12, JammingSettings(force_tol=2e-15, pressure_rtol=1e-3))


@pytest.mark.slow
def test_chains_of_30_at_1e_12_with_force_tolerance_1e_13_is_refused(chains_3d):
    """With force_tol = 1e-13, a tenth of the contact forces at P0 = 1e-12, the bisection ends on
    a saddle (4 contacts short, three eigenvalues -2.3e-12 ... -3.8e-12 of the fixed-box
    constrained Hessian); the saddle guard must see it (the relative bound ``ZERO_MODE_RTOL
    max |w|`` = 6e-10 alone did not, and the saddle was returned as the jammed packing) and,
    as kicks do not stabilise it at that tolerance, refuse in one line."""
    with pytest.raises(RuntimeError, match="stays hypostatic.*with force tolerance 1e-13; a smaller --force-tol"):
        jam_linked(chains_3d, 1e-12, settings=LINKED)


def test_saddle_guard_follows_the_contact_forces_down_to_p0_1e_12():
    """The saddle of the case above (stored: the bisection's final minimum at P0 = 1e-12,
    force_tol = 1e-13) has negative curvature at the scale of its contact forces, below the
    relative bound ``ZERO_MODE_RTOL max |w|``; the guard calls it a saddle. The hypostatic 3D
    chains of four (P0 = 1e-6), held by their prestress, stay a stable minimum."""
    saddle = read_packing(DATA / "saddle_chains30_3d_p1e-12.nc", None)
    count = count_bodies(saddle.contacts, saddle.n, 3, saddle.links, saddle.position, saddle.box)
    assert count.isostatic_count - count.n_contacts == 4
    w = constrained_hessian(saddle, strain=False).eigenvalues
    f_mean = float(saddle.force.mean())
    assert -ZERO_MODE_RTOL * np.abs(w).max() < w.min() < -f_mean
    assert is_saddle(w, f_mean)
    stable = read_packing(DATA / "hypostatic_chains4_3d.nc", None)
    assert not is_saddle(constrained_hessian(stable, strain=False).eigenvalues, float(stable.force.mean()))


@pytest.mark.slow
def test_chains_of_30_in_2d_fixed_box_and_3d_shear_stabilised(tmp_path_factory, chains_3d):
    """2D chains of 30 (fixed box) and the 3D ones shear-stabilised, P0 = 1e-6."""
    check_linked(jam_linked(chains_of_30(tmp_path_factory, 2), 1e-6, settings=LINKED), 1e-6, LINKED)
    result = jam_linked(chains_3d, 1e-6, settings=LINKED, shear_stabilize=True)
    check_linked(result, 1e-6, LINKED, shear_stabilized=True)
