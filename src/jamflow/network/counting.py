"""Counting on a contact network: rattlers by pruning (by count, or by what contacts hold), sliders by rank,
the isostatic count.

Isostatic count convention
--------------------------
A backbone of ``N_s`` bodies with ``f`` degrees of freedom each (``d`` for spheres,
``d + 1`` for 2D bodies that rotate) is held by exactly

    N_c^0 = f N_s - g + 1 - N_sliders

contacts, where ``g`` counts the motions of the whole packing that change no gap
(``d`` global translations in a periodic box, none between hard walls), the ``+1``
is the inflation (CALiPPSO) or compression degree of freedom, equally the
positive-pressure constraint of a soft packing at a fixed box, and every slider
(see :func:`find_sliders`) has one degree of freedom no contact constrains.
Spheres in a periodic box: ``d (N_s - 1) + 1`` (2D: ``2 N_s - 1``); spheres
between walls: ``d N_s + 1``; rotating 2D bodies: ``3 N_s - 1`` (van der Werf et
al., Fig. 3 and Eq. 3). Contacts are counted once per pair. An empty backbone has
count 0.

Clusters of linked spheres (bodies with a motion space of their own, free motions
and rattling clusters decided by rank; chains paper Sec. II F) are counted by
:func:`jamflow.network.bodies.count_bodies`, whose module docstring states that
convention; for free spheres it is :func:`prune_rattlers` and this count.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..tolerances import SLIDER_RTOL
from .contacts import ContactSet

__all__ = ["find_sliders", "isostatic_count", "prune_rattlers", "prune_unheld", "rigidity_counting"]


def _pairs(contacts: ContactSet | ArrayLike) -> NDArray[np.int64]:
    if isinstance(contacts, ContactSet):
        return contacts.pairs
    return np.asarray(contacts, dtype=np.int64).reshape(-1, 2)


def prune_rattlers(
    contacts: ContactSet | ArrayLike,
    n_bodies: int,
    *,
    dofs_per_body: int,
    wall_contacts: ArrayLike | None = None,
    active: NDArray[np.bool_] | None = None,
    compiled: bool = False,
) -> NDArray[np.bool_]:
    """Rattlers by iterative removal of bodies with fewer than ``dofs_per_body + 1`` contacts.

    A body with at most ``f = dofs_per_body`` frictionless contacts cannot be held
    in place (force balance of ``f`` components needs ``f + 1`` repulsive
    contacts); removing it may leave neighbours under-coordinated, so the removal
    repeats until no body changes. This is the one coordination pruning of the
    package (``jamflow check``, CALiPPSO, the jamming certificate, the event-driven
    network, Hessians and moduli call it).

    Parameters
    ----------
    contacts : ContactSet or array_like of int, shape (n_c, 2)
        Body pairs in contact.
    n_bodies : int
    dofs_per_body : int
        ``d`` for spheres, ``d + 1`` for rotating 2D bodies.
    wall_contacts : array_like of int, shape (n_w,), optional
        The body of each contact with a hard wall; a wall never rattles, so these
        contacts always count.
    active : ndarray of bool, shape (n_bodies,), optional
        Bodies still in the network; the others were removed earlier (their
        contacts do not count) and are not reported again.
    compiled : bool
        Peel with the numba kernel (:mod:`._graph_kernels`, one pass with a stack) instead of
        numpy rounds. Same result (the core that survives is unique); for callers that
        prune thousands of times and load numba anyway (the event-driven network, where
        a flowing packing peels in ~15 rounds). Off by default so that a command
        pruning once does not load numba.

    Returns
    -------
    ndarray of bool, shape (n_bodies,)
        True for rattlers (among ``active`` bodies).
    """
    pairs = _pairs(contacts)
    if active is not None:
        pairs = pairs[active[pairs[:, 0]] & active[pairs[:, 1]]]
    z_wall = (np.zeros(n_bodies, dtype=np.int64) if wall_contacts is None
              else np.bincount(np.asarray(wall_contacts, dtype=np.int64), minlength=n_bodies))
    if compiled:
        from .._numba import read_only
        from ._graph_kernels import peel

        rattler = peel(read_only(np.ascontiguousarray(pairs, dtype=np.int64)), n_bodies, dofs_per_body + 1, z_wall)
        return rattler if active is None else rattler & active
    rattler = np.zeros(n_bodies, dtype=bool)
    alive = np.ones(len(pairs), dtype=bool)
    while True:
        z = np.bincount(pairs[alive].ravel(), minlength=n_bodies) + z_wall
        new = (~rattler) & (z < dofs_per_body + 1)
        if not np.any(new):
            return rattler if active is None else rattler & active
        rattler |= new
        alive &= ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])


def prune_unheld(contacts: ContactSet, n_bodies: int, *, rtol: float = SLIDER_RTOL) -> NDArray[np.bool_]:
    """Rattlers by what their contacts can hold: :func:`prune_rattlers`' rule (fewer than
    ``d + 1`` contacts, removed repeatedly) except for a body *pinched* between two contacts
    whose normals are antiparallel.

    Two repulsive contacts balance a body only along one line: force balance needs
    ``n_1 = -n_2``, and then the lines of action coincide (torque balance) in a balanced
    packing. Such a body carries force and holds its two neighbours apart like a strut; it
    is free only to slide across the line, one degree of freedom, which
    :func:`find_sliders` finds (a slider, Eq. 3 of VanderWerf et al.: "a single
    unconstrained translational degree of freedom"; a rattler has all its degrees of
    freedom unconstrained). Counted as a rattler it would take its two contacts and all its
    degrees of freedom: the same net constraint for rotating 2D bodies (3 against 2) but one
    constraint too few for bodies that do not rotate (2 against 2, while the strut holds
    one). Measured on non-rotating circulo-lines: every packing with a pinched body came out
    hypostatic by exactly its number of pinched bodies with the contact-count rule, while its
    dynamical matrix had no floppy mode (docs/notes/shapes.md).

    Parameters
    ----------
    contacts : ContactSet
        Every contact point of the bodies (normals needed).
    n_bodies : int
    rtol : float
        Antiparallel within ``|n_1 + n_2| <= rtol`` (the rank test of :func:`find_sliders`).

    Returns
    -------
    ndarray of bool, shape (n_bodies,)
        True for rattlers.
    """
    pairs, normal = contacts.pairs, contacts.normal
    d = normal.shape[1] if len(normal) else 2
    rattler = np.zeros(n_bodies, dtype=bool)
    while True:
        alive = ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])
        z = np.bincount(pairs[alive].ravel(), minlength=n_bodies)
        weak = np.flatnonzero((~rattler) & (z < d + 1))
        new = []
        for b in weak:
            if z[b] == 2:
                rows = np.flatnonzero(alive & ((pairs[:, 0] == b) | (pairs[:, 1] == b)))
                # the normal pointing into b from each contact
                into = np.where((pairs[rows, 1] == b)[:, None], normal[rows], -normal[rows])
                if np.linalg.norm(into[0] + into[1]) <= rtol:
                    continue
            new.append(b)
        if not new:
            return rattler
        rattler[new] = True


def find_sliders(jacobian: sp.spmatrix, contacts: ContactSet | ArrayLike, n_bodies: int, d: int, *,
                 rattler: NDArray[np.bool_] | None = None, rtol: float = SLIDER_RTOL) -> NDArray[np.bool_]:
    """Sliders: backbone bodies whose contacts leave a translation free, found by rank.

    A body's contacts constrain its own motion (neighbours held fixed) through their
    rows of the contact Jacobian restricted to its columns: ``-n_c`` (or ``+n_c``) on
    its centre, the lever arm ``a_c x n_c`` on its orientation. A translation ``t``
    with ``n_c . t = 0`` for every contact changes no gap at first order: the body
    slides. So the body is a slider when the matrix of its contacts' normals (the
    translation block) has rank below ``d``, i.e. its smallest singular value is at
    most ``rtol`` times the largest. Lever arms do not enter: a kernel vector of the
    whole block that turns the body (a rotation about the point where the normals
    meet) is a rotation free at linear order, which the curvature of the contacts
    holds at quartic order -- a quartic mode of the dynamical matrix (region 1), not
    a slider and not a rattler.

    Convention (VanderWerf et al. 2018, Eq. 3 and Fig. 3): rattlers, bodies with all
    degrees of freedom unconstrained (fewer than ``d + 1 = 3`` contacts, except two
    antiparallel ones, :func:`prune_unheld`), are removed first and take all their degrees
    of freedom and contacts with them; a slider keeps its contacts and removes one degree
    of freedom, so the isostatic count of rotating 2D bodies is ``N_c^0 = 3 N' - 1 - N_s``
    (:func:`isostatic_count`) and ``<z> = 2 (N_c + 1) / (N - N_r - N_s / 3)``;
    non-rotating bodies (Fig. 3a): ``2 N' - 1 - N_s``. A 2D body with contacts keeps at
    most one free translation; in ``d >= 3`` a flagged body may keep up to ``d - 1``.

    Parameters
    ----------
    jacobian : sparse matrix, shape (n_c, n_bodies * f)
        :func:`~jamflow.network.jacobian.contact_jacobian` of ``contacts`` with all
        bodies as columns and no strain columns; ``f = n_cols / n_bodies`` is ``d``
        (translations only) or ``d + 1`` (with the rotation columns, which follow
        all centre columns). Only the centre columns are read. Give every contact
        point of a body (e.g. both end-middle terms of a parallel circulo contact),
        not a reduced count: a normal left out can fake a free translation.
    contacts : ContactSet or array_like of int, shape (n_c, 2)
    n_bodies, d : int
    rattler : ndarray of bool, shape (n_bodies,), optional
        Bodies already removed (not tested; their contacts do not count).
    rtol : float
        Relative singular-value threshold of the translation block
        (:data:`jamflow.tolerances.SLIDER_RTOL`).

    Returns
    -------
    ndarray of bool, shape (n_bodies,)
    """
    pairs = _pairs(contacts)
    J = sp.csr_matrix(jacobian)
    f = J.shape[1] // n_bodies if n_bodies else d
    if J.shape[1] != f * n_bodies or f not in (d, d + 1):
        raise ValueError(f"jacobian has {J.shape[1]} columns; expected {d} or {d + 1} per body for {n_bodies} bodies")
    rattler = np.zeros(n_bodies, dtype=bool) if rattler is None else rattler
    live = ~(rattler[pairs[:, 0]] | rattler[pairs[:, 1]])
    slider = np.zeros(n_bodies, dtype=bool)
    for b in np.flatnonzero(~rattler):
        rows = np.flatnonzero(live & ((pairs[:, 0] == b) | (pairs[:, 1] == b)))
        if not len(rows):
            continue
        s = np.linalg.svd(J[rows][:, d * b: d * b + d].toarray(), compute_uv=False)
        # fewer contacts than d leave d - len(s) singular values at zero
        slider[b] = len(s) < d or s[-1] <= rtol * s[0]
    return slider


def isostatic_count(n_bodies: int, dofs_per_body: int, *, global_dofs: int, n_sliders: int = 0) -> int:
    """Contacts of an isostatic backbone, ``f N_s - g + 1 - N_sliders`` (module docstring).

    Parameters
    ----------
    n_bodies : int
        Backbone bodies ``N_s`` (non-rattlers; sliders included).
    dofs_per_body : int
        ``f``: ``d`` for spheres, ``d + 1`` for rotating 2D bodies.
    global_dofs : int
        ``g``: gap-preserving motions of the whole packing (``d`` periodic, 0 between walls).
    n_sliders : int
        Backbone bodies with one unconstrained degree of freedom.
    """
    if n_bodies <= 0:
        return 0
    return dofs_per_body * n_bodies - global_dofs + 1 - n_sliders


def rigidity_counting(n_contacts: int, n_isostatic: int) -> str:
    """``"hypostatic"``, ``"isostatic"`` or ``"hyperstatic"``: backbone contacts below,
    at or above the isostatic count."""
    if n_contacts < n_isostatic:
        return "hypostatic"
    return "isostatic" if n_contacts == n_isostatic else "hyperstatic"
