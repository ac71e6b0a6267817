"""The lines of Algorithm 1 (paper Sec. II): set up the LP (lines 4-7), read its solution
(lines 9-11), update the configuration (lines 12-13), test convergence (line 15)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...network.spheres import find_rattlers
from ...state.packing import Packing
from .container import _Container
from .lp import (
    CONTACT_DUAL_REL_TOL,
    MIN_CUTOFF,
    JammingLP,
    _column_bounds,
    _far_bound,
    _find_rows,
    _matrix,
    _most_neighbours,
    _row_geometry,
    _Rows,
)
from .options import (
    DEFAULT_BOUND_SCHEDULE,
    DEFAULT_CUTOFF,
    DEFAULT_SOLVER,
    DEFAULT_TOL_GAMMA,
    DEFAULT_TOL_S,
    _check_options,
    _Options,
)
from .record import IterationRecord
from .solver import HYBRID_SWITCH
from .state import _Chain, _LPSetup, _Step

#: Rows (the pair list) are kept while every particle moved less than this fraction of
#: ``ell - sigma_max`` since they were built, which lets the simplex start warm.
REUSE_FRACTION: float = 0.05

#: Weight of a rattler's displacement in that test: it roams its cage, and an overlap
#: it might cause with an unlisted pair is caught by the all-pairs check.
RATTLER_MOVE_WEIGHT: float = 0.1


def _set_up_lp(chain: _Chain, container: _Container, opt: _Options, d: int, n: int) -> _LPSetup:
    """Algorithm 1, lines 4-7: cutoff, bounds, rows within the cutoff and the LP matrix."""
    x, D = chain.x, chain.D
    unit = float(D.mean())
    sig_max = float(D.max())
    near = chain.near_start or chain.phase == len(opt.bound) or chain.unbounded_next
    c_rel = opt.cutoff_near if near else opt.cutoff
    ell = min(c_rel * chain.cut_factor * sig_max, 0.499 * float(np.min(container.box.widths)))
    if ell < MIN_CUTOFF * sig_max:
        raise RuntimeError(
            f"CALiPPSO failed: largest diameter {sig_max:.4g} is too close to half the box width "
            f"({0.5 * float(np.min(container.box.widths)):.4g}) for a neighbour cutoff; use more particles"
        )
    # bound for this LP [mean diameters]
    if chain.unbounded_next:
        b = np.inf
    elif chain.phase == 0:
        b = _far_bound(ell / sig_max, d) * sig_max / unit * chain.bound_factor
    else:
        b = 0.5 * opt.bound[chain.phase - 1][1] * chain.bound_factor
    # rows (and with them a simplex basis) are kept while the cutoff changed by less
    # than REUSE_FRACTION relatively and every particle moved less than
    # REUSE_FRACTION (ell - sigma_max) since they were built
    rows = chain.rows
    if rows is None or abs(rows.cutoff / ell - 1.0) > REUSE_FRACTION or _moved(
        rows, x, container, chain.prev_rattler
    ) > REUSE_FRACTION * (ell - sig_max):
        rows = chain.rows = _find_rows(x, D, container, ell)
    ell = rows.cutoff
    geo = _row_geometry(rows, x, D, container.box)
    A = _matrix(rows, geo, n, d, unit)
    # per-particle bound: the previous LP's rattlers get the far bound, so that a
    # rattler is not pinned on its bound (an active bound is an external force that
    # it would pass on to the stable particle it touches)
    b_far = _far_bound(ell / sig_max, d) * sig_max / unit
    b_part = np.full(n, b)
    if chain.prev_rattler is not None and np.isfinite(b):
        b_part[chain.prev_rattler] = max(b, b_far)
    if container.has_translation and chain.anchor < 0:
        chain.anchor = _most_neighbours(rows, n)
    col_lower, col_upper = _column_bounds(b_part, d, chain.anchor, ell, sig_max, unit)
    method = chain.recovery_method or _method(opt.solver, chain.records, bool(np.isfinite(b)))
    return _LPSetup(rows=rows, geo=geo, A=A, col_lower=col_lower, col_upper=col_upper, ell=ell, sig_max=sig_max,
                    unit=unit, bound=b, method=method)


def _read_solution(lp: _LPSetup, col: NDArray[np.float64], dual: NDArray[np.float64],
                   container: _Container, d: int, n: int) -> _Step:
    """Algorithm 1, lines 9-11: Gamma*, the contacts (active duals) and the displacements."""
    u = col[:-1].reshape(n, d)
    g = float(col[-1])
    mu = np.maximum(dual, 0.0)
    mu_max = float(mu.max()) if len(mu) else 0.0
    active = mu > CONTACT_DUAL_REL_TOL * mu_max if mu_max > 0 else np.zeros(len(mu), bool)
    min_act = float(mu[active].min() / mu_max) if np.any(active) else np.nan
    max_inact = float(mu[~active].max() / mu_max) if (mu_max > 0 and np.any(~active)) else 0.0
    rows = lp.rows
    P = rows.n_pairs
    pair_act = active[:P]
    contacts = np.stack([rows.i[pair_act], rows.j[pair_act]], axis=1)
    wall_particles = rows.wall_particle[active[P:]]
    rattler = find_rattlers(n, d, contacts, wall_particles)
    stable = ~rattler
    n_s = int(stable.sum())
    n_c = int((stable[contacts[:, 0]] & stable[contacts[:, 1]]).sum()) + int(stable[wall_particles].sum())
    iso = n_s > 0 and n_c == container.n_dof(d, n_s)
    ref = u[stable].mean(axis=0) if (n_s and container.has_translation) else np.zeros(d)
    rel = np.linalg.norm(u - ref, axis=1)
    max_s = float(rel.max())
    max_s_stable = float(rel[stable].max()) if n_s else max_s
    sg = g / (1.0 + np.sqrt(1.0 + g))
    return _Step(u=u, g=g, sg=sg, mu=mu, active=active, contacts=contacts, wall_particles=wall_particles,
                 rattler=rattler, n_c=n_c, n_s=n_s, iso=iso, max_s=max_s, max_s_stable=max_s_stable,
                 min_active_dual=min_act, max_inactive_dual=max_inact)


def _update(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options, container: _Container, n: int) -> None:
    """Algorithm 1, lines 12-13 for an accepted LP: ``r <- r + s*``, ``sigma <- sqrt(Gamma*) sigma``
    (or the Sec. IV relaxation), the next anchor and the bound phase."""
    chain.recoveries = 0
    chain.prev_rattler = step.rattler
    chain.x = container.wrap(chain.x + step.u * lp.unit)
    chain.D = chain.D * _growth(step.g, opt.relax)
    if container.has_translation and len(step.contacts):
        zc = np.bincount(step.contacts[step.backbone].ravel(), minlength=n)
        chain.anchor = int(np.argmax(zc))
    # the phase only tightens (measured: docs/notes/calippso-constants.md#bound-phase-hysteresis)
    while chain.phase < len(opt.bound) and step.sg <= opt.bound[chain.phase][0]:
        chain.phase += 1


def _growth(g: float, relax: float | None) -> float:
    """Diameter factor of one LP: ``sqrt(Gamma*)``, or ``sqrt(1 + c g*)`` with relaxation ``c``."""
    return np.sqrt(1.0 + (relax if relax is not None else 1.0) * g)


def _small(step: _Step, opt: _Options) -> bool:
    """Algorithm 1, line 15: ``sqrt(Gamma*) - 1 < tol_gamma`` and ``max |s| < tol_s``."""
    return step.sg < opt.tol_gamma and step.max_s_stable < opt.tol_s


def _method(solver: str, records: list[IterationRecord], bounded: bool) -> str:
    """The HiGHS method of the next LP under the strategy ``solver`` (:data:`SOLVERS`)."""
    if solver == "ipm-center":
        return "ipm-nox" if bounded else "ipm"
    if solver == "hybrid":
        accepted = [r for r in records if r.accepted]
        if accepted and accepted[-1].sqrt_gamma_minus_1 <= HYBRID_SWITCH:
            return "simplex"
        return "ipm"
    return solver


def _moved(rows: _Rows, x: NDArray[np.float64], container: _Container, rattler: NDArray[np.bool_] | None) -> float:
    """Largest displacement since the rows were built [length], a rattler of the last LP
    weighted by :data:`RATTLER_MOVE_WEIGHT`."""
    dxs = container.displacement(x - rows.x_build)
    m = np.sqrt(np.einsum("ij,ij->i", dxs, dxs))
    if rattler is not None:
        m[rattler] *= RATTLER_MOVE_WEIGHT
    return float(m.max())


def jamming_lp(packing: Packing, cutoff: float = DEFAULT_CUTOFF, walls: bool = False) -> JammingLP:
    """The first LP :func:`calippso` solves for ``packing``: rows within ``cutoff``
    [largest diameters], the far-phase displacement bound and, in a periodic box, the
    particle with most neighbours fixed (for comparing LP methods on a real instance).
    """
    _check_options(packing, DEFAULT_TOL_S, DEFAULT_TOL_GAMMA, DEFAULT_SOLVER, cutoff, DEFAULT_BOUND_SCHEDULE,
                   None, walls, 1)
    d, n = packing.d, packing.n
    x = packing.position.copy() if walls else packing.box.wrap(packing.position)
    D = packing.diameter
    unit, sig_max = float(D.mean()), float(D.max())
    ell = min(cutoff * sig_max, 0.499 * float(np.min(packing.box.widths)))
    rows = _find_rows(x, D, _Container(packing.box, walls), ell)
    geo = _row_geometry(rows, x, D, packing.box)
    A = _matrix(rows, geo, n, d, unit)
    b_part = np.full(n, _far_bound(ell / sig_max, d) * sig_max / unit)
    anchor = -1 if walls else _most_neighbours(rows, n)
    col_lower, col_upper = _column_bounds(b_part, d, anchor, ell, sig_max, unit)
    return JammingLP(A, geo.rhs, col_lower, col_upper, np.stack([rows.i, rows.j], axis=1))

