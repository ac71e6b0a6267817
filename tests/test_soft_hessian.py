"""Hessian modes and elastic moduli of soft packings against independent calculations."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from jamflow.models.spheres.hessian import (
    backbone_pairs,
    elastic_moduli,
    hessian,
    lowest_modes,
)
from jamflow.models.spheres.model import fire
from jamflow.models.spheres.potential import PowerLawPotential, evaluate
from jamflow.protocols.initial import random_packing
from jamflow.protocols.quasistatic import affine_shear
from jamflow.protocols.soft_jam import jam_to_pressure


@lru_cache
def _jammed(n: int, d: int, pressure: float, seed: int, w: float = 2.0):
    start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=seed)
    return jam_to_pressure(start, pressure, PowerLawPotential(exponent=w)).packing


@pytest.mark.parametrize("d, w", [(2, 2.0), (3, 2.0), (2, 2.5)])
def test_moduli_match_finite_deformation_with_relaxation(d, w):
    """Non-affine moduli equal the slope of stress after a tiny strain and FIRE relaxation."""
    pot = PowerLawPotential(exponent=w)
    p = _jammed(64, d, 1e-2, 3, w)
    m = elastic_moduli(p.position, p.box, p.diameter, pot)
    x, box, D = p.position, p.box, p.diameter
    e0 = evaluate(x, box, D, pot)
    g = 1e-7
    xs, bs = affine_shear(x, box, box.shear_strain + g)
    es = evaluate(fire(xs, bs, D, pot, force_tol=1e-14).position, bs, D, pot)
    assert m.shear == pytest.approx((es.shear_stress - e0.shear_stress) / g, rel=1e-4)
    f = 1.0 + 1e-7
    bc = box.scaled(f)
    ec = evaluate(fire(x * f, bc, D, pot, force_tol=1e-14).position, bc, D, pot)
    bulk_fd = -box.volume * (ec.pressure - e0.pressure) / (bc.volume - box.volume)
    assert m.bulk == pytest.approx(bulk_fd, rel=1e-4)
    # the non-affine relaxation only lowers the moduli
    assert 0.0 < m.shear < m.shear_affine
    assert 0.0 < m.bulk < m.bulk_affine


def test_lowest_modes_match_dense_diagonalisation():
    p = _jammed(64, 2, 1e-4, 2)
    pairs, rattler = backbone_pairs(p.position, p.box, p.diameter)
    H = hessian(p.position, p.box, p.diameter, pairs=pairs)
    w, v = lowest_modes(H, 2, k=5, keep=~rattler)
    idx = (np.flatnonzero(~rattler)[:, None] * 2 + np.arange(2)).ravel()
    dense = np.linalg.eigvalsh(H.toarray()[np.ix_(idx, idx)])
    assert np.abs(dense[:2]).max() < 1e-10 * dense[-1]  # the two translations
    np.testing.assert_allclose(w, dense[2:7], rtol=1e-8)
    assert np.all(w > 0.0)  # jammed: no floppy mode on the backbone
    Hk = H.toarray()[np.ix_(idx, idx)]
    np.testing.assert_allclose(Hk @ v, v * w, atol=1e-8 * dense[-1])


def test_moduli_of_an_unjammed_state_are_refused():
    p = random_packing(32, 2, 0.3, "bi", seed=1)
    with pytest.raises(ValueError, match="not jammed"):
        elastic_moduli(p.position, p.box, p.diameter)
