"""Energy models: the sphere model's numbers, linked spheres (projection, Newton, FIRE), masses."""

from __future__ import annotations

import re

import numpy as np
import pytest

from jamflow.box import Box
from jamflow.minimize import minimize
from jamflow.minimize.cg import minimize_cg
from jamflow.minimize.descent import minimize_sd
from jamflow.minimize.fire import (
    DEFAULT_FIRE,
    _fire_generic,
    minimize_enthalpy_model,
    minimize_fire,
)
from jamflow.minimize.model import EnergyModel, ModelEvaluation, WithoutFastPaths
from jamflow.models.links import LinkedSpheresModel
from jamflow.models.spheres.model import SphereModel, fire
from jamflow.models.spheres.potential import HARMONIC, evaluate
from jamflow.protocols.initial import random_packing
from jamflow.state.bodies import Links
from jamflow.tolerances import LINK_LENGTH_RTOL


def _compressed(n: int, d: int, phi: float, seed: int):
    start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=seed)
    factor = (start.packing_fraction / phi) ** (1.0 / d)
    unit = start.diameter.mean()
    return start.position * factor / unit, start.box.scaled(factor / unit), start.diameter / unit


def _triangular(nx: int, ny: int, a: float) -> tuple[np.ndarray, Box]:
    """Triangular lattice of spacing ``a``, ``nx`` x ``ny`` sites (ny even), in its periodic box."""
    rows = []
    for r in range(ny):
        for c in range(nx):
            rows.append(((c + 0.5 * (r % 2)) * a, r * a * np.sqrt(3.0) / 2.0))
    return np.array(rows), Box.orthogonal([nx * a, ny * a * np.sqrt(3.0) / 2.0])


def _omega(model: LinkedSpheresModel, q: np.ndarray) -> np.ndarray:
    """Dense constraint Jacobian ``dc_k / dx`` (L, N d), built independently of the model's QR."""
    x = q.reshape(model.n, model.d)
    links = model.links
    out = np.zeros((len(links), x.size))
    for k, (i, j) in enumerate(zip(links.i, links.j)):
        r = model.box.minimum_image(x[j] - x[i])
        u = r / np.linalg.norm(r)
        out[k, i * model.d:(i + 1) * model.d] = -u
        out[k, j * model.d:(j + 1) * model.d] = u
    return out


# --- the sphere model ---------------------------------------------------------------

def test_sphere_model_matches_evaluate_and_finite_differences():
    x, box, D = _compressed(24, 2, 0.88, seed=3)
    model = SphereModel(box, D)
    q = model.dofs(x)
    ev = model.evaluate(q)
    old = evaluate(x, box, D)
    assert ev.energy == old.energy and ev.n_contacts == old.n_contacts > 0
    assert np.array_equal(ev.gradient, -old.force.ravel())
    assert np.array_equal(ev.virial, old.virial)
    rng = np.random.default_rng(0)
    direction = rng.normal(size=q.size)
    h = 1e-6
    fd = (model.evaluate(q + h * direction).energy - model.evaluate(q - h * direction).energy) / (2 * h)
    # central differences: error ~ h^2 U''' ~ 1e-12 relative to the slope
    assert fd == pytest.approx(ev.gradient @ direction, rel=1e-7)
    assert isinstance(model, EnergyModel)


def test_generic_fire_on_spheres_reaches_the_compiled_minimum():
    """The Python FIRE path (shared control kernels) and the compiled sphere loop agree."""
    x, box, D = _compressed(32, 2, 0.9, seed=5)
    # start near a minimum so that both runs fall into the same basin
    x = fire(x, box, D, force_tol=1e-8).position
    x = x + np.random.default_rng(0).normal(scale=1e-3, size=x.shape)
    compiled = fire(x, box, D, force_tol=1e-12)
    generic = _fire_generic(SphereModel(box, D), x.ravel(), 1e-12, 1_000_000, DEFAULT_FIRE)
    assert compiled.converged and generic.converged
    assert generic.max_force <= 1e-12
    assert generic.energy == pytest.approx(compiled.energy, rel=1e-9)
    # same trajectory up to the rounding of the dot products (numpy vs loop sums)
    assert abs(generic.steps - compiled.steps) <= 0.2 * compiled.steps


# --- masses: a time step means the same thing for every degree of freedom -----------

class _Oscillator(WithoutFastPaths):
    """One 2D harmonic degree of freedom ``U = k |q|^2 / 2`` with mass ``m`` (toy model)."""

    constrained = False
    neighbor_builds = 0
    time_unit = 1.0

    def __init__(self, k: float, m: float) -> None:
        self.k = k
        self.box = Box.cubic(2, 10.0)
        self.n_dof = 2
        self.inverse_mass = np.full(2, 1.0 / m)

    def dofs(self, position):
        return np.array(position, dtype=np.float64).ravel()

    def positions(self, q):
        return q.reshape(1, 2)

    def evaluate(self, q):
        return ModelEvaluation(0.5 * self.k * float(q @ q), self.k * q, np.zeros((2, 2)), 0)

    def project(self, g, q):
        return g

    def reproject(self, q):
        return q

    def max_force(self, g):
        return float(np.linalg.norm(g))

    def hessian(self, q):
        raise NotImplementedError


def test_fire_time_step_is_measured_in_the_mass_metric():
    """(k, m) and (c k, c m) share omega = sqrt(k / m): FIRE takes identical steps."""
    start = np.array([[0.3, -0.2]])
    a = minimize_fire(_Oscillator(1.0, 1.0), start, force_tol=1e-12)
    b = minimize_fire(_Oscillator(100.0, 100.0), start, force_tol=1e-10)
    stiff = minimize_fire(_Oscillator(100.0, 1.0), start, force_tol=1e-10)
    assert a.converged and b.converged
    assert b.steps == a.steps
    np.testing.assert_allclose(b.position, a.position, atol=1e-13)
    # the same stiffness with unit mass is a different (faster) oscillator
    assert stiff.steps != a.steps


# --- linked spheres ------------------------------------------------------------------

def _chains(seed: int = 2):
    """A compressed 2D packing with a dimer, a free-angle trimer chain and a rigid trimer."""
    x, box, D = _compressed(40, 2, 0.86, seed=seed)
    pairs = [(0, 1), (2, 3), (3, 4), (5, 6), (6, 7), (5, 7)]
    i, j = np.array(pairs).T
    # place linked particles at their link length from their partner (close to a contact)
    for a, b in pairs:
        r = box.minimum_image(x[b] - x[a])
        x[b] = x[a] + r / np.linalg.norm(r) * 0.5 * (D[a] + D[b])
    # the rigid trimer as an equilateral triangle of side D[5] + D[6] over (5, 6, 7)
    side = 0.5 * (D[5] + D[6])
    x[6] = x[5] + [side, 0.0]
    x[7] = x[5] + [0.5 * side, side * np.sqrt(3.0) / 2.0]
    length = np.linalg.norm(np.array([box.minimum_image(x[b] - x[a]) for a, b in pairs]), axis=1)
    return x, box, D, Links(i, j, length)


def test_projection_is_idempotent_and_orthogonal_to_the_constraint_rows():
    x, box, D, links = _chains()
    model = LinkedSpheresModel(box, D, links, x)
    q = model.dofs(x) + np.random.default_rng(1).normal(scale=1e-3, size=x.size)
    g = np.random.default_rng(2).normal(size=q.size)
    pg = model.project(g, q)
    omega = _omega(model, q)
    scale = np.linalg.norm(g)
    assert np.max(np.abs(omega @ pg)) <= 1e-14 * scale
    np.testing.assert_allclose(model.project(pg, q), pg, atol=1e-14 * scale)
    # what is removed lies in the row space of Omega (least-squares residual zero)
    removed = g - pg
    coef, *_ = np.linalg.lstsq(omega.T, removed, rcond=None)
    assert np.linalg.norm(omega.T @ coef - removed) <= 1e-13 * scale
    # unlinked particles are untouched
    free = np.setdiff1d(np.arange(model.n), np.concatenate([links.i, links.j]))
    assert np.array_equal(pg.reshape(-1, 2)[free], g.reshape(-1, 2)[free])


def test_newton_reaffixing_converges_quadratically():
    x, box, D, links = _chains()
    model = LinkedSpheresModel(box, D, links, x)
    q = model.dofs(x) + np.random.default_rng(3).normal(scale=3e-3, size=x.size)
    errors = [np.max(np.abs(model.link_errors(q)))]
    for _ in range(4):
        q = model.newton_step(q)
        errors.append(np.max(np.abs(model.link_errors(q))))
    assert errors[0] > 1e-4
    # e_{k+1} <= C e_k^2 with C of order 1 / (link length) until the float64 floor
    for before, after in zip(errors, errors[1:]):
        assert after <= max(10.0 * before**2, 1e-15)
    assert errors[-1] <= LINK_LENGTH_RTOL
    assert np.max(np.abs(model.link_errors(model.reproject(q)))) <= LINK_LENGTH_RTOL


class _Recording(LinkedSpheresModel):
    """Records the largest relative link error at every energy evaluation."""

    def evaluate(self, q):
        self.worst = max(getattr(self, "worst", 0.0), float(np.max(np.abs(self.link_errors(q)))))
        return super().evaluate(q)


def test_fire_keeps_links_and_reaches_the_analytic_minimum_of_a_pushed_dimer():
    """A dimer in a compressed triangular crystal: its link replaces one compressed bond.

    Spheres of diameter sigma on a triangular lattice of spacing a < sigma: every
    particle has six neighbours at distance a and relative overlap xi = 1 - a / sigma.
    With particles 0 and 1 linked at length a, the lattice is still force balanced
    (the link carries the bond force f = epsilon xi / sigma as a tension pushing the
    dimer apart) and stable, so FIRE from a perturbed lattice must return to it:
    U = (3N - 1) xi^2 / 2 (one bond fewer), every neighbour distance a, and the
    pressure with the link's tension equals the crystal's, P = 3 N f a / (2 V).
    """
    a, sigma = 1.0, 1.03
    x0, box = _triangular(6, 6, a)
    n = len(x0)
    D = np.full(n, sigma)
    links = Links(np.array([0]), np.array([1]), np.array([a]))
    start = x0 + np.random.default_rng(4).normal(scale=0.03, size=x0.shape)
    model = _Recording(box, D, links, start)
    res = minimize_fire(model, start, force_tol=1e-13)
    assert res.converged
    assert model.worst <= 1e-12
    assert abs(np.linalg.norm(box.minimum_image(res.position[1] - res.position[0])) - a) <= 1e-12 * a
    xi = 1.0 - a / sigma
    assert res.energy == pytest.approx((3 * n - 1) * xi**2 / 2, rel=1e-10)
    f = xi / sigma
    assert res.pressure == pytest.approx(3 * n * f * a / (2 * box.volume), rel=1e-9)
    # the lattice up to a translation
    shift = box.minimum_image(res.position - x0)
    np.testing.assert_allclose(box.minimum_image(shift - shift[0]), 0.0, atol=1e-9)


@pytest.mark.parametrize("method, tol", [("fire", 1e-10), ("cg", 1e-10), ("sd", 1e-7)])
def test_rigid_trimer_keeps_its_shape(method, tol):
    x, box, D, links = _chains()
    model = LinkedSpheresModel(box, D, links, x)
    start = x
    if method == "sd":
        # steepest descent crawls along soft modes: start it near FIRE's minimum
        near = minimize_fire(model, x, force_tol=1e-4).position
        x = near + np.random.default_rng(5).normal(scale=1e-3, size=x.shape)
    res = minimize(model, x, method=method, force_tol=tol, max_steps=2_000_000)
    assert res.converged and res.max_force <= tol
    q = res.position.ravel()
    assert np.max(np.abs(model.link_errors(q))) <= 1e-12
    tri = res.position[[5, 6, 7]]
    sides = [np.linalg.norm(box.minimum_image(tri[b] - tri[c])) for b, c in ((0, 1), (1, 2), (0, 2))]
    np.testing.assert_allclose(sides, sides[0], rtol=1e-12)
    # the trimer was pushed: it moved as a rigid body
    assert np.max(np.linalg.norm(box.minimum_image(tri - start[[5, 6, 7]]), axis=1)) > 1e-2
    # force balance on the manifold: the projected gradient vanishes, the raw one need not
    ev = model.evaluate(q)
    assert model.max_force(model.project(ev.gradient, q)) <= tol
    assert model.max_force(ev.gradient) > 1e3 * tol


def test_fire_and_cg_agree_on_a_linked_minimum():
    x, box, D, links = _chains(seed=7)
    model = LinkedSpheresModel(box, D, links, x)
    a = minimize_fire(model, x, force_tol=1e-12)
    b = minimize_cg(model, a.position + 1e-4 * np.random.default_rng(0).normal(size=x.shape), force_tol=1e-12)
    assert a.converged and b.converged
    assert b.energy == pytest.approx(a.energy, rel=1e-8)


def test_degenerate_links_are_refused():
    x, box = _triangular(6, 6, 1.0)
    D = np.full(len(x), 0.9)
    # a straight rigid chain 0-1-2 with the long link 0-2: three links, rank two
    x[2] = x[0] + [2.0, 0.0]
    links = Links(np.array([0, 1, 0]), np.array([1, 2, 2]), np.array([1.0, 1.0, 2.0]))
    model = LinkedSpheresModel(box, D, links, x)
    with pytest.raises(ValueError, match="degenerate"):
        model.project(np.ones(x.size), model.dofs(x))


def test_sd_on_spheres_is_the_compiled_descent():
    x, box, D = _compressed(24, 2, 0.88, seed=3)
    res = minimize_sd(SphereModel(box, D, HARMONIC), x, dt=0.05, force_tol=1e-9)
    assert res.converged and res.max_force <= 1e-9
    assert res.energy == pytest.approx(evaluate(res.position, box, D).energy, rel=1e-14)


# --- jamflow minimize ----------------------------------------------------------------

@pytest.mark.parametrize("method, bodies", [("fire", "both"), ("cg", "both"), ("sd", "spheres")])
def test_cli_minimize_spheres_and_linked_spheres(tmp_path, capsys, method, bodies):
    from jamflow.cli import main
    from jamflow.io import read_dataset, read_packing, write_packing
    from jamflow.state.packing import Packing

    x, box, D, links = _chains()
    # steepest descent of the linked packing crawls (test_rigid_trimer_keeps_its_shape covers it)
    cases = (("spheres", None), ("linked", links)) if bodies == "both" else (("spheres", None),)
    for name, lk in cases:
        src = tmp_path / f"{name}.nc"
        write_packing(Packing(position=box.wrap(x), diameter=D, box=box, links=lk, protocol="test"), src)
        out = tmp_path / f"{name}_{method}.nc"
        tol = 1e-7 if method == "sd" else 1e-11
        assert main(["minimize", str(src), str(out), "--method", method, "--force-tol", str(tol),
                     "--max-steps", "2000000"]) == 0
        printed = capsys.readouterr().out
        ds = read_dataset(out)
        p = read_packing(out, None)
        # the summary rows print the stored numbers
        rows = dict(re.findall(r"^\s+(n_force_evaluations|max_force|energy)\s+(\S+)", printed, re.MULTILINE))
        assert int(rows["n_force_evaluations"]) == ds.attrs["n_force_evaluations"]
        for key in ("max_force", "energy"):
            assert float(rows[key]) == pytest.approx(float(ds.attrs[key]), rel=1e-2)
        assert ds.attrs["max_force"] <= tol and ds.attrs["n_force_evaluations"] > 1
        # the stored numbers are those of the stored configuration
        if lk is None:
            model = SphereModel(box, D)
        else:
            model = LinkedSpheresModel(box, D, p.links, p.position)
            assert np.max(np.abs(model.link_errors(model.dofs(p.position)))) <= 1e-12
            linked = set(zip(p.links.i.tolist(), p.links.j.tolist()))
            assert not linked & set(map(tuple, p.contacts.tolist()))
        q = model.dofs(p.position)
        ev = model.evaluate(q)
        assert ev.energy == pytest.approx(ds.attrs["energy"], rel=1e-10)
        assert model.max_force(model.project(ev.gradient, q)) <= 2 * tol


def test_cli_minimize_refuses_bad_options(tmp_path, capsys):
    from jamflow.cli import main
    from jamflow.io import write_packing
    from jamflow.state.packing import Packing

    x, box, D = _compressed(16, 2, 0.85, seed=1)
    src = tmp_path / "s.nc"
    write_packing(Packing(position=box.wrap(x), diameter=D, box=box), src)
    with pytest.raises(SystemExit) as usage:  # refused by the option's type: a usage error
        main(["minimize", str(src), str(tmp_path / "o.nc"), "--force-tol", "-1"])
    assert usage.value.code == 2
    assert "argument --force-tol: must be a positive finite number, got -1" in capsys.readouterr().err
    assert main(["minimize", str(src), str(tmp_path / "o.nc"), "--max-steps", "3"]) == 1
    assert "did not reach" in capsys.readouterr().err
    assert not (tmp_path / "o.nc").exists()


def test_jamming_bisection_of_linked_spheres_reaches_the_target_pressure():
    """The compress/decompress bisection takes any model: linked spheres end at P0 with links intact."""
    from jamflow.minimize.onset import JammingSettings, jam_model_to_pressure

    x, box, D, links = _chains(seed=4)
    start = LinkedSpheresModel(box, D, links, x)
    factor = 1.06  # decompress so the bisection must compress
    model, start_x = start.rescaled(factor, x)
    phi = float(np.sum(np.pi * D**2 / 4) / model.box.volume)
    p0 = 1e-3
    settings = JammingSettings(force_tol=1e-10, pressure_rtol=1e-2, delta_phi=5e-3)
    model, res, history, steps = jam_model_to_pressure(model, start_x, phi, p0, settings)
    assert res.converged and res.max_force <= 1e-10
    assert abs(res.pressure - p0) <= 1e-2 * p0
    q = res.position.ravel()
    assert np.max(np.abs(model.link_errors(q))) <= 1e-12
    # the reported pressure is the virial pressure (pairs + link tensions) of the final state
    ev = model.evaluate(q)
    assert np.trace(ev.virial) / (2 * model.box.volume) == pytest.approx(res.pressure, rel=1e-12)
    assert len(history["phi"]) > 2 and steps == sum(history["steps"])


def test_rigid_tetrahedron_in_3d_keeps_its_shape():
    x, box, D = _compressed(32, 3, 0.6, seed=8)
    side = 0.5 * (D[0] + D[1])
    # a regular tetrahedron of edge `side` on particles 0..3, all six edges linked
    corners = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) * side / (2 * np.sqrt(2))
    x[:4] = x[0] + corners
    pairs = [(a, b) for a in range(4) for b in range(a + 1, 4)]
    i, j = np.array(pairs).T
    links = Links(i, j, np.full(len(pairs), side))
    model = LinkedSpheresModel(box, D, links, x)
    res = minimize_fire(model, x, force_tol=1e-11)
    assert res.converged
    assert np.max(np.abs(model.link_errors(res.position.ravel()))) <= 1e-12
    with pytest.raises(NotImplementedError, match="box degrees of freedom"):
        minimize_enthalpy_model(model, res.position, 1e-3)
