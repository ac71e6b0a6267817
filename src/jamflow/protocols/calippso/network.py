"""The contact network of a converged LP and its final checks: isostaticity (or the
App. A hyperstatic case), force balance, and the dual contacts against the geometry.

The support of a dual vertex is the contact network only when the LP is not
degenerate; a hyperstatic (crystalline) packing is stored with its geometric network
and minimum-norm balanced forces (see the package docstring)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...network.forces import MIN_NORM, balance_matrix, min_norm_forces
from ...network.rigidity import contact_geometry
from ...network.spheres import find_rattlers
from ...state.packing import Packing
from ...tolerances import CONTACT_GAP_TOL
from .container import LOWER, _Container, wall_key
from .record import DUAL_VERTEX, DUAL_VERTEX_ON_GEOMETRIC
from .state import _LPSetup, _Step


@dataclass
class _Network:
    """The contact network of the converged LP and what the final checks found.

    Contacts are sphere pairs ``contacts`` (P, 2) and wall contacts
    (``wall_particles``, ``wall_faces``) with forces ``f_pair``, ``f_wall`` (paper
    Eq. 11); the remaining fields are the counts and residuals stored as attributes.
    """

    contacts: NDArray[np.int64]
    wall_particles: NDArray[np.int64]
    wall_faces: NDArray[np.int64]
    f_pair: NDArray[np.float64]
    f_wall: NDArray[np.float64]
    rattler: NDArray[np.bool_]
    n_c: int
    n_s: int
    iso: bool
    force_balance_residual: float
    residual_stable: float
    force_assignment: str = DUAL_VERTEX
    force_assignment_note: str = ""
    isostatic_count: int = 0
    hyperstatic: bool = False
    isostatic_appendix_a: bool = False
    n_contacts_with_rattlers: int = 0
    n_force_bearing_rattlers: int = 0
    n_contacts_dual: int = 0
    n_rattlers_dual: int = 0
    dual_not_geometric: int = 0
    geometric_not_dual: int = 0
    n_contacts_geometric: int = 0
    n_stable_geometric: int = 0
    why: str = "ok"


def _dual_network(step: _Step, lp: _LPSetup, x: NDArray[np.float64], container: _Container,
                  d: int, n: int) -> _Network:
    """Contacts and forces of a converged LP: forces from the duals (paper Eq. 11),
    ``f = mu / sigma_ij`` (a wall: ``mu / (sigma_i / 2)``), with the per-particle
    force-balance residual on the updated configuration ``x``."""
    rows = lp.rows
    P = rows.n_pairs
    pa, wa = step.active[:P], step.active[P:]
    f_pair = step.mu[:P][pa] / lp.geo.sig[pa]
    f_wall = step.mu[P:][wa] / lp.geo.rad[wa]
    faces = rows.wall_face[wa]
    resid = _balance_residual(x, container, step.contacts, f_pair, rows.wall_particle[wa], faces, f_wall, d, n)
    stable = ~step.rattler
    # rattlers may carry forces only in the App. A case; residual over all particles
    return _Network(contacts=step.contacts, wall_particles=step.wall_particles, wall_faces=faces, f_pair=f_pair,
                    f_wall=f_wall, rattler=step.rattler, n_c=step.n_c, n_s=step.n_s, iso=step.iso,
                    force_balance_residual=float(resid.max(initial=0.0)),
                    residual_stable=float(resid[stable].max(initial=0.0)))


def _balance_residual(x, container: _Container, c, f_pair, wp, faces, f_wall, d: int, n: int) -> NDArray[np.float64]:
    """Per-particle net contact force over the mean force, (N,), directions on ``x``."""
    dxc = container.box.minimum_image(x[c[:, 1]] - x[c[:, 0]]) if len(c) else np.empty((0, d))
    nij = dxc / np.linalg.norm(dxc, axis=1)[:, None] if len(c) else dxc
    net = np.zeros((n, d))
    np.add.at(net, c[:, 0], -f_pair[:, None] * nij)
    np.add.at(net, c[:, 1], f_pair[:, None] * nij)
    push = np.where(faces % 2 == LOWER, 1.0, -1.0) * f_wall
    np.add.at(net, (wp, faces // 2), push)
    scale = float(np.mean(np.concatenate([f_pair, f_wall]))) if len(f_pair) + len(f_wall) else 1.0
    return np.linalg.norm(net, axis=1) / scale


def _final_checks(packing: Packing, x, D, container: _Container, net: _Network) -> tuple[bool, str]:
    """Isostaticity (or App. A hyperstaticity), force balance and dual-vs-gap contacts.

    When the geometric network (gaps below :data:`~jamflow.tolerances.CONTACT_GAP_TOL`)
    has another backbone than the dual vertex (a degenerate, hyperstatic packing),
    ``net`` is switched to the geometric network with a balanced force assignment
    (:func:`_store_geometric`); otherwise the dual contacts and forces stay as they are.
    """
    d, n = packing.d, packing.n
    rattler, stable = net.rattler, ~net.rattler
    c = net.contacts
    iso_n = container.n_dof(d, net.n_s)
    # App. A counting: contacts between stable particles and between a stable particle
    # and a force-bearing rattler, all rattlers out of the degrees of freedom
    touches_stable = stable[c[:, 0]] | stable[c[:, 1]]
    n_c_a = int(touches_stable.sum()) + int(stable[net.wall_particles].sum())
    fb_rattler = np.zeros(n, bool)
    both_r = rattler[c[:, 0]] | rattler[c[:, 1]]
    fb_rattler[c[both_r].ravel()] = True
    fb_rattler &= rattler
    net.n_contacts_with_rattlers = n_c_a
    net.n_force_bearing_rattlers = int(fb_rattler.sum())
    net.isostatic_count = iso_n
    net.n_contacts_dual = len(c) + len(net.wall_particles)  # the vertex's support
    net.n_rattlers_dual = int(rattler.sum())
    hyper = net.n_c > iso_n
    net.isostatic_appendix_a = bool(n_c_a == iso_n)
    # dual contacts vs geometric contacts (gap below CONTACT_GAP_TOL)
    p = container.packing(packing, x, D)
    geo_c, geo_wp, geo_wf = container.touching(p)
    geo = set(zip(geo_c[:, 0].tolist(), geo_c[:, 1].tolist()))
    dual = set(map(tuple, c.tolist()))
    net.dual_not_geometric = len(dual - geo)
    net.geometric_not_dual = len(geo - dual)
    # the geometric network: a degenerate (crystalline) jammed packing has more
    # contacts than force-bearing duals at any vertex of its LP (App. A)
    geo_rattler = find_rattlers(n, d, geo_c, geo_wp)
    geo_stable = ~geo_rattler
    n_s_geo = int(geo_stable.sum())
    n_c_geo = (int((geo_stable[geo_c[:, 0]] & geo_stable[geo_c[:, 1]]).sum())
               + int(geo_stable[geo_wp].sum()))
    net.n_stable_geometric = n_s_geo
    net.n_contacts_geometric = n_c_geo
    geo_rigid_count = n_s_geo > 0 and n_c_geo >= container.n_dof(d, n_s_geo)
    net.hyperstatic = bool(hyper or n_c_geo > container.n_dof(d, n_s_geo))
    reasons = []
    if net.dual_not_geometric:
        reasons.append(f"{net.dual_not_geometric} dual contact(s) with gap > {CONTACT_GAP_TOL:g}")
    elif not _same_backbone(net, geo_c, geo_wp, geo_wf, geo_rattler):
        _store_geometric(p, container, net, geo_c, geo_wp, geo_wf, geo_rattler)
        if not geo_rigid_count:
            reasons.append(f"geometric network: N_c = {n_c_geo} but isostatic count "
                           f"{container.n_dof(d, n_s_geo)} (N_s = {n_s_geo})")
        return not reasons, "; ".join(reasons) or "ok"
    if not (net.iso or (net.hyperstatic and net.isostatic_appendix_a)):
        reasons.append(f"N_c = {net.n_c} but d(N_s-1)+1 = {iso_n} (N_s = {net.n_s})")
    return not reasons, "; ".join(reasons) or "ok"


def _same_backbone(net: _Network, geo_c, geo_wp, geo_wf, geo_rattler) -> bool:
    """Whether the dual vertex and the geometry give the same rattlers and backbone
    contacts (pairs and walls); a rattler resting on a neighbour with zero force
    makes no difference."""
    if not np.array_equal(net.rattler, geo_rattler):
        return False
    stable = ~net.rattler

    def backbone(c, wp, wf):
        pairs = {tuple(v) for v in c[stable[c[:, 0]] & stable[c[:, 1]]].tolist()}
        keep = stable[wp]
        return pairs, set(zip(wp[keep].tolist(), wf[keep].tolist()))

    return backbone(net.contacts, net.wall_particles, net.wall_faces) == backbone(geo_c, geo_wp, geo_wf)


def _store_geometric(p: Packing, container: _Container, net: _Network, geo_c, geo_wp, geo_wf, geo_rattler) -> None:
    """Replace the dual network in ``net`` by the geometric one, with rattlers from
    the geometric coordination and the minimum-norm balanced forces
    (:func:`jamflow.network.forces.min_norm_forces`, normalised like the duals,
    ``sum_c f_c sigma_c = 1``); when that QP fails, the dual vertex forces (zero on
    the contacts outside its support) are stored and ``force_assignment`` says so
    (:data:`DUAL_VERTEX_ON_GEOMETRIC`)."""
    d, n = p.d, p.n
    unit, _ = contact_geometry(p, geo_c)
    B = balance_matrix(unit, geo_c, n, d, geo_wp, geo_wf)
    weight = np.concatenate([p.sigma(geo_c[:, 0], geo_c[:, 1]), 0.5 * p.diameter[geo_wp]])
    try:
        f, _ = min_norm_forces(B, weight, d)
        net.force_assignment = MIN_NORM
    except RuntimeError as exc:
        f = _dual_on(net, geo_c, geo_wp, geo_wf)
        net.force_assignment = DUAL_VERTEX_ON_GEOMETRIC
        net.force_assignment_note = f" ({exc})"
    n_pairs = len(geo_c)
    stable = ~geo_rattler
    resid = np.linalg.norm(np.asarray(B @ f).reshape(n, d), axis=1) / float(f.mean())
    n_s = int(stable.sum())
    net.contacts, net.f_pair, net.rattler = geo_c, f[:n_pairs], geo_rattler
    net.wall_particles, net.wall_faces, net.f_wall = geo_wp, geo_wf, f[n_pairs:]
    net.n_c = int((stable[geo_c[:, 0]] & stable[geo_c[:, 1]]).sum()) + int(stable[geo_wp].sum())
    net.n_s = n_s
    net.isostatic_count = container.n_dof(d, n_s)
    net.iso = n_s > 0 and net.n_c == net.isostatic_count
    net.hyperstatic = net.n_c > net.isostatic_count
    net.force_balance_residual = float(resid.max(initial=0.0))
    net.residual_stable = float(resid[stable].max(initial=0.0))


def _dual_on(net: _Network, geo_c, geo_wp, geo_wf) -> NDArray[np.float64]:
    """The dual vertex forces on the geometric contacts (pairs then walls), zero off its support."""
    n = len(net.rattler)
    key_pair = {k: v for k, v in zip((net.contacts @ [n, 1]).tolist(), net.f_pair.tolist())}
    key_wall = {k: v for k, v in zip(wall_key(net.wall_particles, net.wall_faces).tolist(), net.f_wall.tolist())}
    fp = [key_pair.get(k, 0.0) for k in (geo_c @ [n, 1]).tolist()]
    fw = [key_wall.get(k, 0.0) for k in wall_key(geo_wp, geo_wf).tolist()]
    return np.array(fp + fw, dtype=np.float64)
