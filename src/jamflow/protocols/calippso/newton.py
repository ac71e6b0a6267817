"""The Newton finish (``finish="newton"``): solve an isostatic network's square system
by Newton's method and keep the result only under a certificate that it is the LP
chain's limit (see :func:`_newton_finish`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import NDArray

from ...box import Box
from ...network.spheres import find_rattlers
from ...state.packing import Packing, near_pairs
from ...tolerances import OVERLAP_TOL
from .container import _Container, _direct
from .lp import CONTACT_DUAL_REL_TOL, _matrix, _row_geometry, _RowGeometry, _Rows
from .network import _balance_residual, _final_checks, _Network, _same_backbone
from .options import _Options
from .record import IterationRecord, _NewtonAttempt
from .state import _Chain, _LPSetup, _record, _Step

#: Tried after every accepted LP from this ``sqrt(Gamma*) - 1`` down (the hybrid solver's tail).
NEWTON_FROM: float = 1e-5

#: Largest number of Newton steps (from ``sqrt(Gamma*) - 1 ~ 1e-7``, one to three steps
#: on one LU reach round-off).
NEWTON_MAX_STEPS: int = 8

#: The LU is kept for the next step (a chord step) while each step shrinks the largest
#: move at least by this factor; otherwise it is refactorised at the current configuration.
NEWTON_CONTRACTION: float = 0.1

#: The last step must leave every network contact touching to this relative tolerance,
#: ``|r^2 - sigma^2| / sigma^2``: above the round-off of squared distances in boxes up to
#: ~100 diameters (~4e-14). Chord steps converge linearly, so a small move alone does not say it.
NEWTON_GAP_TOL: float = 1e-13

#: The certificate's forces are accepted once each residual component of the transposed
#: system is at most this fraction of its scale ``(|B^T| |mu| + |e_g|)_k`` (a componentwise
#: backward error near round-off), after at most NEWTON_REFINEMENTS corrections (else a fresh LU).
NEWTON_FORCE_RESIDUAL: float = 1e-14
NEWTON_REFINEMENTS: int = 4

#: A step moving a stable particle by more than this [mean diameters] (the tightest
#: default bound) means the network is not that of a nearby jammed packing: rejected.
NEWTON_MAX_MOVE: float = 5e-3

#: Largest number of sweeps pushing rattlers off the neighbours the finish grew into
#: (measured: docs/notes/calippso-constants.md#rattler_pushes).
RATTLER_PUSHES: int = 50


class _Rejected(Exception):
    """A Newton finish refused: why, and after how many steps."""

    def __init__(self, reason: str, steps: int) -> None:
        super().__init__(reason)
        self.reason, self.steps = reason, steps


@dataclass(frozen=True)
class _SquareSystem:
    """The square system of an isostatic network: its rows (the backbone contacts of the
    LP's active set) and columns (the stable particles' coordinates, the anchor's left
    out in a periodic box, and ``g``), of ``n`` particles in ``d`` dimensions."""

    rows: _Rows
    cols: NDArray[np.int64]
    n: int
    d: int
    box: Box

    def geometry(self, x: NDArray[np.float64], D: NDArray[np.float64]) -> _RowGeometry:
        """The rows' geometry at positions ``x`` and diameters ``D``."""
        return _row_geometry(self.rows, x, D, self.box)

    def matrix(self, geo: _RowGeometry, unit: float) -> sp.csc_matrix:
        """The LP's basis matrix of the network rows, displacements in units of ``unit``."""
        return _matrix(self.rows, geo, self.n, self.d, unit)[:, self.cols].tocsc()

    def factorise(self, geo: _RowGeometry, unit: float, steps: int) -> sla.SuperLU:
        """Sparse LU (COLAMD ordering) of :meth:`matrix`; an exactly singular one is rejected."""
        try:
            return sla.splu(self.matrix(geo, unit), permc_spec="COLAMD")
        except RuntimeError as exc:
            raise _Rejected(f"singular network matrix ({exc})", steps) from exc

    def growth_load(self) -> NDArray[np.float64]:
        """``e_g``: the unit vector of the column ``g``."""
        e_g = np.zeros(len(self.cols))
        e_g[-1] = 1.0
        return e_g


def _finish_by_newton(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options, container: _Container,
                      packing: Packing, progress: Callable[[IterationRecord], None] | None) -> _Network | None:
    """Try the Newton finish after an accepted LP: the certified network that also passed
    the final checks, with the chain moved to its configuration and the finish recorded
    as one history entry; None (the chain unchanged) otherwise."""
    attempt, x, D, net = _newton_finish(chain, step, lp, opt, container, packing)
    if attempt.certified:
        ok, why = _final_checks(packing, x, D, container, net)
        if ok:
            chain.newton.append(attempt)
            _record(chain, progress, _newton_record(chain, container, net, attempt, x, D, lp))
            chain.x, chain.D = x, D
            return net
        attempt = replace(attempt, certified=False, reason=f"final checks: {why}")
    chain.newton.append(attempt)
    chain.newton_tried = chain.backbone_key
    return None


def _network_rows(step: _Step, lp: _LPSetup) -> _Rows:
    """The backbone rows of an LP's active set (pairs of stable particles, stable wall rows)."""
    rows = lp.rows
    P = rows.n_pairs
    stable = ~step.rattler
    pa = step.active[:P] & stable[rows.i] & stable[rows.j]
    wa = step.active[P:] & stable[rows.wall_particle]
    return _Rows(rows.i[pa], rows.j[pa], rows.wall_particle[wa], rows.wall_face[wa], rows.x_build, rows.cutoff)


def _square_columns(stable: NDArray[np.bool_], anchor: int, d: int) -> NDArray[np.int64]:
    """Columns of the square system: the stable particles' coordinates (without the
    anchor's in a periodic box) and ``g`` (column ``d N``)."""
    keep = stable.copy()
    if anchor >= 0:
        keep[anchor] = False
    cols = (np.flatnonzero(keep)[:, None] * d + np.arange(d)).ravel()
    return np.append(cols, d * len(stable))


def _positive(mu: NDArray[np.float64]) -> bool:
    """Whether every network force is above ``CONTACT_DUAL_REL_TOL`` of the largest."""
    return bool(mu.min() > CONTACT_DUAL_REL_TOL * mu.max())


def _n_not_positive(mu: NDArray[np.float64]) -> int:
    """How many network forces are not above ``CONTACT_DUAL_REL_TOL`` of the largest."""
    return int(np.sum(mu <= CONTACT_DUAL_REL_TOL * mu.max()))


def _transposed_solve(lu: sla.SuperLU, B: sp.csc_matrix, b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``B^T y = b`` by iterative refinement on ``lu``, the LU of a nearby matrix (the
    Newton finish's last factorisation, a few chord steps from ``B``).

    Refinement stops once every residual component is at most
    :data:`NEWTON_FORCE_RESIDUAL` of its own scale ``(|B^T| |y| + |b|)_k`` (the
    componentwise backward error of Oettli and Prager: each particle's balance to
    round-off of its own forces, not of the largest); when :data:`NEWTON_REFINEMENTS`
    corrections do not get there, ``B`` is factorised afresh.
    """
    BT = B.T.tocsr()
    absBT = abs(BT)

    def small(y: NDArray[np.float64], r: NDArray[np.float64]) -> bool:
        return bool(np.all(np.abs(r) <= NEWTON_FORCE_RESIDUAL * (absBT @ np.abs(y) + np.abs(b))))

    y = lu.solve(b, trans="T")
    for _ in range(NEWTON_REFINEMENTS):
        r = b - BT @ y
        if small(y, r):
            return y
        y = y + lu.solve(r, trans="T")
    if small(y, b - BT @ y):
        return y
    return sla.splu(B, permc_spec="COLAMD").solve(b, trans="T")



def _newton_finish(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options, container: _Container,
                   packing: Packing) -> tuple[_NewtonAttempt, NDArray[np.float64], NDArray[np.float64], _Network | None]:
    """Solve the isostatic network's square system by Newton's method and certify it.

    The unknowns are the stable particles' displacements (the anchor fixed in a
    periodic box) and ``g = Gamma - 1``; the equations say that every backbone contact
    of the LP's network touches after the update ``r <- r + s``, ``sigma <- sqrt(Gamma)
    sigma``. Linearised, they are the network rows of the jamming LP as equalities, so
    each Newton step solves ``B z = rhs`` with ``B`` the LP's basis matrix (sparse LU,
    COLAMD ordering) and updates like an LP of the chain. The LU is kept while each
    step shrinks the largest move by :data:`NEWTON_CONTRACTION` (chord steps: one
    pair of triangular solves each) and refactorised at the current configuration otherwise.
    Steps stop when one satisfies the chain's convergence test (``sqrt(Gamma) - 1 <
    tol_gamma``, ``max |s| < tol_s``), within :data:`NEWTON_MAX_STEPS` steps each
    moving no particle by more than :data:`NEWTON_MAX_MOVE`.

    Before any step, the network's forces at the LP's configuration, ``B^-T e_g``,
    must all be positive: a negative one means that the next LP, started from this
    network's basis, is not dual feasible and pivots that contact out, so the network
    is not the chain's last one. This early rejection spares the steps of most
    rejected attempts; a wrong one only leaves the chain to its LPs.

    Certificate that the result is the LP chain's limit: the forces
    ``mu = B^-T e_g`` at the finished configuration (paper Eqs. 9, 11: the dual basic
    solution of the LP at ``s = 0``; by iterative refinement on the kept LU, see
    :func:`_transposed_solve`) are all above ``CONTACT_DUAL_REL_TOL`` of the largest,
    and no pair overlaps by more than ``OVERLAP_TOL``; then ``s = 0, Gamma = 1`` is
    optimal for the next LP (primal feasible, dual feasible, complementary). The
    geometric network must also have the network's backbone and rattlers (else the
    final checks would switch to it).

    Returns the attempt, the finished positions and diameters, and the network (None
    when not certified; then positions and diameters are the chain's, unchanged).
    """
    t0 = time.perf_counter()
    stable = ~step.rattler
    cols = _square_columns(stable, chain.anchor if container.has_translation else -1, packing.d)
    system = _SquareSystem(_network_rows(step, lp), cols, packing.n, packing.d, container.box)
    try:
        x, D, geo, lu, steps = _newton_steps(system, chain.x, chain.D, stable, container, opt)
        net, x, mu = _certificate(system, x, D, geo, lu, step, container, packing, steps)
    except _Rejected as no:
        return _NewtonAttempt(False, no.reason, no.steps, time.perf_counter() - t0), chain.x, chain.D, None
    return _NewtonAttempt(True, "ok", steps, time.perf_counter() - t0, float(mu.min() / mu.max())), x, D, net


def _newton_steps(system: _SquareSystem, x: NDArray[np.float64], D: NDArray[np.float64],
                  stable: NDArray[np.bool_], container: _Container, opt: _Options):
    """Newton (chord) steps from the LP's configuration ``x, D`` until one passes the
    chain's convergence test with every network contact touching.

    Returns the positions, diameters, row geometry and LU of the last step and the
    number of steps; raises :class:`_Rejected` (a network that is not square, a force
    not positive at the start, a singular matrix, a step too large, no convergence).
    """
    rows, cols, n, d = system.rows, system.cols, system.n, system.d
    if len(rows) != len(cols):
        raise _Rejected(f"network has {len(rows)} backbone rows for {len(cols)} unknowns", 0)
    geo = system.geometry(x, D)
    unit = float(D.mean())  # of the factorised matrix: z is in these units
    lu = system.factorise(geo, unit, 0)
    mu = lu.solve(system.growth_load(), trans="T")
    if not _positive(mu):
        raise _Rejected(f"{_n_not_positive(mu)} network force(s) not positive at the LP's configuration", 0)
    last_move = move = np.inf
    for k in range(1, NEWTON_MAX_STEPS + 1):
        if move > NEWTON_CONTRACTION * last_move:
            unit = float(D.mean())
            lu = system.factorise(geo, unit, k)
        last_move = move
        z = lu.solve(geo.rhs)
        u = np.zeros(n * d)
        u[cols[:-1]] = z[:-1]
        u = u.reshape(n, d)
        g = float(z[-1])
        ref = u[stable].mean(axis=0) if container.has_translation else np.zeros(d)
        move = float(np.linalg.norm(u[stable] - ref, axis=1).max())
        if not (np.isfinite(move) and move <= NEWTON_MAX_MOVE and g > -1.0):
            raise _Rejected(f"Newton step {k} moves a particle by {move:.3g} mean diameters", k)
        x = container.wrap(x + u * unit)
        D = D * np.sqrt(1.0 + g)
        geo = system.geometry(x, D)
        if (g / (1.0 + np.sqrt(1.0 + g)) < opt.tol_gamma and move < opt.tol_s
                and np.abs(geo.rhs).max() <= NEWTON_GAP_TOL):
            return x, D, geo, lu, k
    raise _Rejected(f"Newton did not converge in {NEWTON_MAX_STEPS} steps", NEWTON_MAX_STEPS)


def _certificate(system: _SquareSystem, x: NDArray[np.float64], D: NDArray[np.float64], geo: _RowGeometry,
                 lu: sla.SuperLU, step: _Step, container: _Container, packing: Packing,
                 steps: int) -> tuple[_Network, NDArray[np.float64], NDArray[np.float64]]:
    """The certificate that the finished configuration is the LP chain's limit: positive
    forces of the transposed system, no overlap after freeing the rattlers, the same
    geometric backbone. Returns the network, the positions with the rattlers freed and
    the network's duals; raises :class:`_Rejected`.

    The rattlers are not in the system: they are freed only once the forces pass, which
    spares the all-pairs sweeps to the rejected attempts.
    """
    rows, n, d = system.rows, system.n, system.d
    mu = _transposed_solve(lu, system.matrix(geo, float(D.mean())), system.growth_load())
    if not _positive(mu):
        raise _Rejected(f"{_n_not_positive(mu)} network force(s) not positive", steps)
    x = _free_rattlers(x, D, step.rattler, container, packing)
    p = container.packing(packing, x, D)
    ov = container.max_overlap(p)
    if ov > OVERLAP_TOL:
        raise _Rejected(f"overlap {ov:.3g} (relative) > {OVERLAP_TOL:g}", steps)
    P = rows.n_pairs
    stable = ~step.rattler
    contacts = np.stack([rows.i, rows.j], axis=1)
    f_pair, f_wall = mu[:P] / geo.sig, mu[P:] / geo.rad
    resid = _balance_residual(x, container, contacts, f_pair, rows.wall_particle, rows.wall_face, f_wall, d, n)
    net = _Network(contacts=contacts, wall_particles=rows.wall_particle, wall_faces=rows.wall_face, f_pair=f_pair,
                   f_wall=f_wall, rattler=step.rattler, n_c=len(rows), n_s=step.n_s, iso=True,
                   force_balance_residual=float(resid.max(initial=0.0)),
                   residual_stable=float(resid[stable].max(initial=0.0)))
    geo_c, geo_wp, geo_wf = container.touching(p)
    if not _same_backbone(net, geo_c, geo_wp, geo_wf, find_rattlers(n, d, geo_c, geo_wp)):
        raise _Rejected("the geometric network has another backbone", steps)
    return net, x, mu


def _free_rattlers(x: NDArray[np.float64], D: NDArray[np.float64], rattler: NDArray[np.bool_],
                   container: _Container, packing: Packing) -> NDArray[np.float64]:
    """Push rattlers off the neighbours the Newton finish grew into.

    The finish moves only the stable particles; a rattler that rested on a neighbour
    at the last LP (gap ~0, zero dual) overlaps it by about the growth, ~1e-9, where the
    LP chain's next LP would have moved it. Each overlapping rattler moves away along
    the pair direction by twice the overlap (a pair of rattlers shares the move), for
    up to :data:`RATTLER_PUSHES` sweeps. A rattler wedged between neighbours on
    opposite sides can have its overlaps amplified by these sweeps
    (docs/notes/calippso-constants.md#rattler_pushes), so the sweep with the smallest
    largest rattler overlap, the input included, is returned: freeing never makes an
    overlap worse. What remains is caught by the certificate's overlap check.
    """
    best, best_overlap = x, np.inf
    for sweep in range(RATTLER_PUSHES + 1):
        p = container.packing(packing, x, D)
        pairs, h = near_pairs(p, 0.0)
        loose = (h < 0.0) & (rattler[pairs.i] | rattler[pairs.j])
        if container.walls and len(h):  # no periodic images through a wall
            loose &= _direct(p.position[pairs.j] - p.position[pairs.i], pairs.dx, p.box)
        overlap = float(-h[loose].min()) if np.any(loose) else 0.0
        if overlap < best_overlap:
            best, best_overlap = x, overlap
        if overlap == 0.0 or sweep == RATTLER_PUSHES:
            break
        i, j, dx, h = pairs.i[loose], pairs.j[loose], pairs.dx[loose], h[loose]
        sig = p.sigma(i, j)
        push = (-2.0 * h * sig / np.linalg.norm(dx, axis=1))[:, None] * dx  # along r_j - r_i
        share = np.where(rattler[i] & rattler[j], 0.5, 1.0)[:, None]
        move = np.zeros_like(x)
        np.add.at(move, i, -push * share * rattler[i][:, None])
        np.add.at(move, j, push * share * rattler[j][:, None])
        x = container.wrap(p.position + move)
    return best


def _newton_ready(chain: _Chain, step: _Step, lp: _LPSetup, n: int) -> bool:
    """Whether to try the Newton finish after this (accepted) LP: in the tail, an
    isostatic network without force-bearing rattlers, not the backbone of the last
    rejected finish unless the LP before had it too (a rejection by an overlap, e.g.
    of a rattler, may not recur closer to jamming)."""
    stable = ~step.rattler
    rows = lp.rows
    on_stable = np.concatenate([stable[rows.i] & stable[rows.j], stable[rows.wall_particle]])
    key = np.sort(rows.keys(n)[step.active & on_stable]).tobytes()
    same, chain.backbone_key = key == chain.backbone_key, key
    return (step.iso and step.sg <= NEWTON_FROM and (same or key != chain.newton_tried)
            and not np.any(step.active & ~on_stable))


def _newton_record(chain: _Chain, container: _Container, net: _Network, attempt: _NewtonAttempt,
                   x: NDArray[np.float64], D: NDArray[np.float64], lp: _LPSetup) -> IterationRecord:
    """The history entry of a certified Newton finish: its total growth and moves."""
    unit = float(chain.D.mean())
    s = container.displacement(x - chain.x) / unit
    stable = ~net.rattler
    ref = s[stable].mean(axis=0) if container.has_translation else np.zeros(s.shape[1])
    rel = np.linalg.norm(s - ref, axis=1)
    return IterationRecord(
        iteration=len(chain.records) + 1, sqrt_gamma_minus_1=float(D[0] / chain.D[0] - 1.0),
        max_displacement=float(rel.max()), max_displacement_stable=float(rel[stable].max()),
        n_constraints=net.n_c, n_contacts=net.n_c, n_stable=net.n_s, isostatic=True, lp_status="Certified",
        lp_time=attempt.seconds, solver="newton", cutoff=lp.ell / lp.sig_max, bound=np.inf,
        min_active_dual=attempt.min_dual, max_inactive_dual=np.nan, accepted=True, newton_steps=attempt.steps)

