"""Dynamical matrix, spectral regions and quartic modes of shape packings (Sec. III B).

Data: ``tests/data/shapes_circulo_line_a1.1_n16_p1e-6.nc``, made by
``jamflow init-shapes c0.nc --shape circulo-line --asphericity 1.1 --n 16 --phi 0.4
--seed 2`` and ``jamflow soft-jam c0.nc OUT --pressure 1e-6 --delta-phi 1e-2
--pressure-rtol 1e-2``.

Physics checked: the Hessian is the derivative of the gradient on the whole packing;
the zero modes are exactly the two global translations (no rattlers or sliders
here); ``N_c = N_c^0 - N_1`` with parallel contacts counted twice; region-1
eigenvalues scale linearly with the pressure while their fourth derivatives do not
change (Figs. 10-11); the modes CLI writes what it prints.
"""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import xarray as xr

from jamflow.cli import main
from jamflow.io import read_packing
from jamflow.minimize.fire import minimize_fire
from jamflow.shapes.counting import count_constraints, shape_model_of
from jamflow.shapes.jamming import shape_packing
from jamflow.shapes.spectrum import (
    FOURTH_DERIVATIVE_MIN_STEP,
    FOURTH_STEP_STABILITY_RTOL,
    contact_signature,
    energy_quartic_fit,
    exact_line,
    fourth_derivative_along,
    fourth_derivative_step,
    spectrum,
)

DATA = Path(__file__).parent / "data" / "shapes_circulo_line_a1.1_n16_p1e-6.nc"


@pytest.fixture(scope="module")
def packing():
    return read_packing(DATA, None)


@pytest.fixture(scope="module")
def spec(packing):
    return spectrum(packing)


def test_hessian_is_derivative_of_gradient_on_a_packing(packing):
    """Assembly of the pair Hessians (each checked to round-off in the model tests).

    The step stays below a tenth of the smallest overlap (9.6e-9 here), so no
    contact opens or closes inside the difference stencil (U'' jumps by k there);
    round-off of the central difference is then eps |q| |H| / h ~ 1e-6.
    """
    model, q = shape_model_of(packing)
    hess = model.hessian(q)
    rng = np.random.default_rng(0)
    v = rng.normal(size=q.size)
    v /= np.linalg.norm(v)
    h = min(1e-7, 0.1 * float(model.contact_terms(q)["delta"].min()))
    pairs = {(a, b) for a, b in zip(model.pair_table(q)["i"], model.pair_table(q)["j"])}
    for s in (-h, h):
        t = model.pair_table(q + s * v)
        assert {(a, b) for a, b in zip(t["i"], t["j"])} == pairs
    fd = (model.evaluate(q + h * v).gradient - model.evaluate(q - h * v).gradient) / (2.0 * h)
    np.testing.assert_allclose(hess @ v, fd, atol=2e-5 * abs(hess).max())


def test_zero_modes_are_the_translations(packing, spec):
    c, rattler, slider, _ = count_constraints(packing, "twice")
    assert c.n_rattlers == 0 and c.n_sliders == 0
    assert spec.n_zero == 2
    model, q = shape_model_of(packing)
    lam, vec = np.linalg.eigh(model.hessian(q).toarray())
    zero = vec[:, spec.region == 0]
    for axis in range(2):
        t = np.zeros(q.size)
        t[axis: 2 * model.n: 2] = 1.0 / np.sqrt(model.n)
        assert np.linalg.norm(zero.T @ t) == pytest.approx(1.0, abs=1e-10)


def test_contacts_equal_isostatic_count_minus_quartic_modes(packing, spec):
    twice, *_ = count_constraints(packing, "twice")
    once, *_ = count_constraints(packing, "once")
    assert spec.n_quartic >= 1
    assert twice.n_contacts == twice.isostatic_count - spec.n_quartic
    assert once.n_contacts < twice.n_contacts  # this packing has parallel contacts
    # regions 1 and 2 are separated by a wide gap (orders of magnitude)
    lam = spec.eigenvalue
    assert lam[spec.region == 2].min() / lam[spec.region == 1].max() > 100.0
    assert np.all(spec.fourth_derivative[spec.region == 1] > 0.0)


def test_quartic_eigenvalues_scale_with_pressure_fourth_derivatives_do_not(packing, spec):
    model, q = shape_model_of(packing)
    conf = model.positions(q)
    # compress slightly: the pressure grows by a factor ~3 (bulk modulus ~0.5 k)
    squeezed, start = model.rescaled(1.0 - 2e-6, conf)
    res = minimize_fire(squeezed, start, force_tol=1e-13, max_steps=200_000)
    assert res.converged
    denser = shape_packing(squeezed, res.position, packing, {}, {})
    ratio = denser.pressure / packing.pressure
    assert ratio > 2.0
    spec2 = spectrum(denser, spec.lambda_c)
    assert spec2.n_quartic == spec.n_quartic
    lam1, lam2 = spec.eigenvalue[spec.region == 1], spec2.eigenvalue[spec2.region == 1]
    # region 1: lambda proportional to P (Fig. 10), up to O(P) corrections
    np.testing.assert_allclose(lam2 / lam1, ratio, rtol=0.1)
    # region 2: independent of P
    np.testing.assert_allclose(spec2.eigenvalue[spec2.region == 2][:5], spec.eigenvalue[spec.region == 2][:5], rtol=0.05)
    np.testing.assert_allclose(spec2.fourth_derivative[spec2.region == 1],
                               spec.fourth_derivative[spec.region == 1], rtol=0.1)


def test_modes_cli(tmp_path, capsys, spec):
    out = tmp_path / "modes.nc"
    assert main(["modes", str(DATA), str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"quartic modes N_1 (region 1)  {spec.n_quartic}" in printed
    with xr.open_dataset(out) as ds:
        assert ds.attrs["n_quartic"] == spec.n_quartic
        assert ds.attrs["lambda_c"] == pytest.approx(spec.lambda_c, rel=1e-15)
        np.testing.assert_array_equal(ds["region"].values, spec.region)
        assert ds.attrs["isostatic_minus_quartic"] == ds.attrs["n_contacts_twice"]


def test_check_json_on_shapes(capsys):
    import json

    assert main(["check", str(DATA), "--json", "--parallel-contacts", "twice"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {"z_eq3", "z_contacts", "n_sliders", "isostatic_count", "n_contacts", "n_rattlers"} <= set(report)
    n_prime = report["N"] - report["n_rattlers"]
    assert report["isostatic_count"] == 3 * n_prime - 1 - report["n_sliders"]
    assert report["z_eq3"] == pytest.approx(2 * (report["n_contacts"] + 1) / (n_prime - report["n_sliders"] / 3))
    assert report["z_contacts"] == pytest.approx(2 * report["n_contacts"] / n_prime)


DISK_LIMIT = Path(__file__).parent / "data" / "shapes_ellipse_alpha1.001_n16_p1e-7.nc"


def test_disk_limit_of_ellipses():
    """Ellipses of aspect ratio 1.001 (A - 1 = 3.7e-7) at P0 = 1e-7 count as disks.

    Data: ``jamflow init-shapes e0.nc --shape ellipse --aspect-ratio 1.001 --n 16
    --phi 0.5 --seed 1`` then ``jamflow soft-jam e0.nc OUT --pressure 1e-7
    --delta-phi 1e-2 --pressure-rtol 1e-2``. The non-rattlers form an isostatic disk
    network, ``N_c = 2 N' - 1`` (``<z> = 4``, Fig. 8's small-A limit), hypostatic by
    ``N'`` against ``3 N' - 1``; the missing constraints are exactly the ``N'`` quartic
    (rotational) modes, and the zero modes are the two translations plus three per
    rattler.
    """
    p = read_packing(DISK_LIMIT, None)
    c, rattler, slider, _ = count_constraints(p)
    n_prime = p.n - c.n_rattlers
    assert c.n_contacts == 2 * n_prime - 1
    assert c.z_eq3 == pytest.approx(4.0, rel=1e-15)
    assert c.counting == "hypostatic"
    spec = spectrum(p, fourth=False)
    assert spec.n_quartic == n_prime == c.isostatic_count - c.n_contacts
    assert spec.n_zero == 2 + 3 * c.n_rattlers
    model, q = shape_model_of(p)
    lam, vec = np.linalg.eigh(model.hessian(q).toarray())
    zero = vec[:, spec.region == 0]
    expected = []
    for axis in range(2):
        t = np.zeros(q.size)
        t[axis: 2 * model.n: 2] = ~rattler  # the backbone translates rigidly
        expected.append(t / np.linalg.norm(t))
    for b in np.flatnonzero(rattler):
        for dof in (2 * b, 2 * b + 1, 2 * model.n + b):
            t = np.zeros(q.size)
            t[dof] = 1.0
            expected.append(t)
    for t in expected:
        assert np.linalg.norm(zero.T @ t) == pytest.approx(1.0, abs=1e-9)


def test_fourth_derivatives_do_not_depend_on_pressure_down_to_1e_7():
    # regression: one packing (32 circulo-lines, A = 1.03, the vanderwerf-fig10-11 scene)
    # jammed at P0 = 1e-7 and compressed to 1e-6; a fixed step 1e-3 opened contacts at
    # 1e-7 (overlaps ~1e-7 < h^2) and gave fourth derivatives 40 to 1e5 times larger
    data = Path(__file__).parent / "data"
    low, high = (spectrum(read_packing(data / f"shapes_circulo_line_a1.03_n32_p{p}.nc", None)) for p in ("1e-7", "1e-6"))
    assert low.n_quartic == high.n_quartic == 9
    np.testing.assert_allclose(high.eigenvalue[high.region == 1] / low.eigenvalue[low.region == 1], 10.0, rtol=1e-3)
    np.testing.assert_allclose(low.fourth_derivative[low.region == 1], high.fourth_derivative[high.region == 1],
                               rtol=1e-2)


def test_a_packing_without_a_quartic_band_has_no_region_1():
    # regression: 32 dumbbells (`jamflow init-shapes db.nc --shape dumbbell --aspect-ratio 3
    # --n 32 --seed 1`, `jamflow soft-jam db.nc OUT --pressure 1e-9`). The widest gap of the
    # lower spectrum lies between its two lowest nonzero modes (2e-3 and 4e-3, a factor 2),
    # and the bare widest-gap rule put the lowest one into region 1, with a negative fourth
    # derivative: 2e-3 is a million times the pressure, not a stress-scale quartic mode
    p = read_packing(Path(__file__).parent / "data" / "shapes_dumbbell_ar3_n32_p1e-9.nc", None)
    spec = spectrum(p)
    nonzero = spec.eigenvalue[spec.region > 0]
    assert nonzero.min() > 1e6 * 1e-9
    assert spec.n_quartic == 0
    assert spec.lambda_c == spec.lambda_0
    assert spec.n_zero == 2


def test_modes_warns_when_residual_forces_are_not_small_against_the_pressure(tmp_path, capsys):
    # the vendored packing (A = 1.1, P0 = 1e-6) has max F ~ 1e-14: balanced; shifting one
    # body by 1e-6 leaves forces ~1e-6 > 1e-3 P, which shift the quartic eigenvalues (~P)
    p = read_packing(DATA, None)
    assert spectrum(p, fourth=False).balanced
    moved = p.position.copy()
    moved[0, 0] += 1e-6
    spec = spectrum(p.evolve(position=moved), fourth=False)
    assert spec.max_force > 1e-3 * spec.pressure and not spec.balanced
    from jamflow.io import write_packing

    src = tmp_path / "moved.nc"
    write_packing(p.evolve(position=moved), src)
    assert main(["modes", str(src), str(tmp_path / "m.nc")]) == 0
    assert "N_1 may be wrong" in capsys.readouterr().err
    assert xr.open_dataset(tmp_path / "m.nc").attrs["force_balanced_for_spectrum"] == 0


def test_fourth_derivative_steps_around_a_contact_opening_next_to_the_mode(tmp_path, capsys):
    # 16 circulo-lines at A = 1.3, P0 = 1e-6 (the vanderwerf-fig7 scene, seed 1): one
    # quartic mode (lambda = 1.6e-6 ~ P, N_c(twice) = N_c^0 - 1) along which v^T M v jumps
    # between s = -1e-6 and 0 (a contact at the verge of opening): the central second
    # difference gave d^4U/ds^4 = -8e5, the right one-sided one is smooth
    src = Path(__file__).parent / "data" / "shapes_circulo_line_a1.3_n16_p1e-6.nc"
    assert main(["modes", str(src), str(tmp_path / "m.nc")]) == 0
    assert "fourth derivative" not in capsys.readouterr().err
    ds = xr.open_dataset(tmp_path / "m.nc")
    assert ds.attrs["n_quartic"] == 1 and ds.attrs["n_nonpositive_fourth_derivative"] == 0
    assert ds.attrs["n_unresolved_fourth_derivative"] == 0
    assert ds.attrs["n_contacts_twice"] == ds.attrs["isostatic_minus_quartic"]
    p = read_packing(src, None)
    model, q = shape_model_of(p)
    lam, vec = np.linalg.eigh(model.hessian(q).toarray())
    k = int(np.flatnonzero(ds.region.values == 1)[0])
    v = vec[:, k]

    def f(s):
        return float(v @ (model.hessian(q + s * v) @ v))

    # premise: the central difference at the module's step for this packing (its smallest,
    # 1e-6) straddles the jump
    h = FOURTH_DERIVATIVE_MIN_STEP
    assert (f(-h) - 2.0 * lam[k] + f(h)) / h**2 < -1e5
    # independent estimate: a least-squares cubic through 43 samples on the smooth side
    # (the jump lies between s = -2.5e-7 and -1.25e-7); its residual at the round-off
    # of f (~3e-16) shows that no jump falls inside. A central difference with a step
    # 16x smaller, the former reference here, is itself off by ~10 % from round-off
    # (a few eps ||M|| / h^2 ~ 1 at h = 6e-8): 10.6, 13.2 and 24 at h = 6e-8, 3e-8, 1.6e-8.
    s = np.linspace(-1e-7, 2e-6, 43)
    coef, residual, *_ = np.polyfit(s / h, [f(x) for x in s], 3, full=True)
    assert np.sqrt(residual[0] / s.size) < 1e-14
    fitted = 2.0 * coef[1] / h**2
    # the module's one-sided difference at step h: truncation ~ h U^(5) / U^(4) ~ 1e-3
    assert float(ds.fourth_derivative[k]) == pytest.approx(fitted, rel=1e-2) and fitted > 0


class _Quartic:
    """One degree of freedom with ``f(s) = M(s) = lam + c s^2 / 2`` plus jumps of ``M`` at ``s`` beyond ``left``/``right``."""

    def __init__(self, lam, c, left=-np.inf, right=np.inf, jump=1.0):
        self.lam, self.c, self.left, self.right, self.jump = lam, c, left, right, jump

    def hessian(self, q):
        s = float(q[0])
        return sp.csr_matrix([[self.lam + 0.5 * self.c * s * s + self.jump * ((s < self.left) + (s > self.right))]])


@pytest.mark.parametrize("left, right, expected", [(-np.inf, np.inf, 7.0), (-1.5e-6, np.inf, 7.0),
                                                   (-np.inf, 0.7e-6, 7.0), (-0.7e-6, 1.5e-6, np.nan)])
def test_fourth_derivative_along_picks_the_smooth_side(left, right, expected):
    model = _Quartic(1e-6, 7.0, left, right)
    d4 = fourth_derivative_along(model, np.zeros(1), np.ones(1), 1e-6)
    if np.isnan(expected):
        assert np.isnan(d4)
    else:
        assert d4 == pytest.approx(expected, rel=1e-6)

NEAR_DISKS = ["shapes_ellipse_alpha1.001_n16_p1e-7.nc", "shapes_ellipse_alpha1.0001_n16_p1e-7.nc"]


@pytest.fixture(scope="module", params=NEAR_DISKS)
def near_disk(request):
    """A near-disk ellipse packing, its spectrum, model, ``q``, eigenvectors and first step."""
    p = read_packing(Path(__file__).parent / "data" / request.param, None)
    spec = spectrum(p)
    model, q = shape_model_of(p)
    vec = np.linalg.eigh(model.hessian(q).toarray())[1]
    h = fourth_derivative_step(float(np.sqrt(2.0 * model.pair_table(q)["energy"].min())))
    return spec, model, q, vec, h


def test_fourth_derivatives_of_near_disk_quartic_modes_are_finite_positive_and_step_independent(near_disk):
    """Near disks the quartic modes are rotations with d^4U/ds^4 ~ k (alpha - 1)^2 (1e-6 at
    alpha - 1 = 1e-3, 1e-8 ... 1e-7 at 1e-4). Every region-1 mode gets a finite positive value,
    and the same within FOURTH_STEP_STABILITY_RTOL when the first step is 4 times larger: at
    1e-4 the round-off of v^T M v (~1e-9 of it) made the first steps' differences scatter by
    10 % and two of them agree by chance, 1.1 % off the converged value."""
    spec, model, q, vec, h = near_disk
    d4 = spec.fourth_derivative[spec.region == 1]
    assert spec.n_quartic >= 10 and np.all(np.isfinite(d4)) and np.all(d4 > 0.0)
    for k in np.flatnonzero(spec.region == 1):
        wide = fourth_derivative_along(model, q, vec[:, k], 4.0 * h, lambda x: contact_signature(model, x))
        assert wide == pytest.approx(spec.fourth_derivative[k], rel=FOURTH_STEP_STABILITY_RTOL)


def test_fourth_derivatives_of_near_disks_agree_with_a_quartic_fit_of_the_energy(near_disk):
    """Independent of v^T M v: the s^4 coefficient of a polynomial fitted to U(q + s v) - U(q)
    on |s| <= 2^-6 ... 2^-9 (energy_quartic_fit) is d^4U/ds^4, its s^2 coefficient the
    eigenvalue. Allowed: four standard errors of the fit (from its residual, the energy's
    round-off ~1e-22) plus the estimator's own error; the fit must resolve 1 % of the value."""
    spec, model, q, vec, _ = near_disk
    for k in np.flatnonzero(spec.region == 1):
        fitted, error, eigenvalue, w = energy_quartic_fit(model, q, vec[:, k], lambda x: contact_signature(model, x))
        d4 = spec.fourth_derivative[k]
        assert np.isfinite(fitted) and error < 1e-2 * d4, (k, w)
        assert abs(fitted - d4) <= 4.0 * error + FOURTH_STEP_STABILITY_RTOL * d4
        assert eigenvalue == pytest.approx(spec.eigenvalue[k], rel=1e-3)


def test_exact_line_puts_every_sample_on_the_line():
    """q + s v is exact for every node s = m h / 2 up to twice the largest step, and q, v move by at most
    half a grid unit (the ulp of the largest coordinate reached) and g / h."""
    rng = np.random.default_rng(3)
    q = rng.uniform(-6.0, 6.0, 48)
    v = rng.normal(size=48)
    v /= np.linalg.norm(v)
    x, u, h = exact_line(q, v, 1e-5, max_step=1e-2)
    grid = 2.0**-49  # |q| + 4e-2 |v| < 8
    assert h == 2.0**-17
    assert np.max(np.abs(x - q)) <= grid / 2 and np.max(np.abs(u - v)) <= grid / h
    s = np.concatenate([np.arange(-40, 41) * (h / 2), [2e-2 - h / 2, -(2e-2 - h / 2)]])
    s = np.round(s / (h / 2)) * (h / 2)
    for t in s:
        point = x + t * u
        # exact: subtracting the base point gives back the product, itself exact
        np.testing.assert_array_equal(point - x, t * u)
        assert np.all(np.round(point / grid) * grid == point)


class _NoisyQuartic(_Quartic):
    """``f(s) = lam + c s^2 / 2`` plus round-off-like noise: a deterministic function of the bits of ``q``."""

    def __init__(self, lam, c, noise, seed):
        super().__init__(lam, c)
        self.noise, self.seed = noise, seed

    def hessian(self, q):
        u = zlib.crc32(np.asarray(q, dtype=np.float64).tobytes(), self.seed) / 2.0**31 - 1.0
        return super().hessian(q) + sp.csr_matrix([[self.noise * u]])


@pytest.mark.parametrize("seed", range(40))
def test_fourth_derivative_along_takes_no_step_dominated_by_round_off(seed):
    """As mode 17 of the alpha - 1 = 1e-4 packing: d^4U/ds^4 = 1.46e-7, v^T M v = 2.9e-11 with
    round-off ~5e-20, first step 8e-6, where the round-off moves a second difference by ~10 %.
    Whatever the noise does, the estimate is within FOURTH_STEP_STABILITY_RTOL of the truth
    (without the round-off rule 2 of these 40 noise patterns gave chance agreements at the
    first steps, 1.1 % off)."""
    c = 1.46e-7
    model = _NoisyQuartic(2.9e-11, c, 5e-20, seed)
    d4 = fourth_derivative_along(model, np.full(1, 0.3), np.ones(1), 8e-6)
    assert d4 == pytest.approx(c, rel=FOURTH_STEP_STABILITY_RTOL)
