"""CALiPPSO: jam hard spheres exactly by a chain of linear programs.

Implements Algorithm 1 of Artiaco, Díaz Hernández Rojas, Parisi and Ricci-Tersenghi,
Phys. Rev. E 106, 055310 (2022) (Sec. II, III, IV, App. A), with HiGHS via
``highspy``, for mono-, bi- and polydisperse spheres in d >= 2, in a periodic box or
between hard walls on the faces of an orthogonal box.

The LP (paper Eq. 2)
--------------------
Each LP maximises the inflation factor ``Gamma`` over displacements ``s`` subject
to the linearised non-overlap constraint of every pair closer than the cutoff ``ell``::

    F_ij = -2 r_ij . (s_i - s_j) + Gamma sigma_ij^2 - |r_ij|^2 <= 0,   r_ij = r_i - r_j.

``G_ij = F_ij - |s_ij|^2`` is the exact constraint, so an LP solution never creates
an overlap among listed pairs. Rows are built as whole arrays (one CSC matrix, no
per-row Python loop) in a well-scaled form: every row is divided by
``sigma_ij^2``, displacements are measured in mean diameters (``u = s / <D>``) and
the variable is ``g = Gamma - 1`` so that the right-hand side is the small number
``(|r_ij|^2 - sigma_ij^2) / sigma_ij^2`` (about twice the relative gap) instead of
``|r_ij|^2``, whose leading digits would cancel against ``Gamma sigma^2``::

    2 <D> / sigma_ij^2 (x_j - x_i) . (u_i - u_j) + g <= (|r_ij|^2 - sigma_ij^2) / sigma_ij^2.

``g >= -1`` (``Gamma >= 0``, not ``>= 1``: a round-off overlap of 1e-13 must not make
the LP infeasible). In a periodic box the global translation is removed by fixing
the displacement of one *anchor* particle (the particle with most contacts in the
previous LP, initially the one with most neighbours); every reported displacement is
taken relative to the mean displacement of the stable particles, so the choice of
anchor changes no reported number. With ``walls=True`` the box faces are hard walls
(paper text after Eq. 1): for a particle at distance ``a = x_{i,mu}`` from the lower
face the exact constraint ``Gamma sigma_i^2 / 4 <= (a + s_{i,mu})^2`` is linearised in
the same conservative way, ``-2 a s_{i,mu} + Gamma sigma_i^2 / 4 - a^2 <= 0`` (and
likewise for the upper face with ``L_mu - x_{i,mu}``); walls remove the translation
symmetry, so no particle is fixed.

Duals, contacts and forces
--------------------------
The row duals ``mu_k >= 0`` of the scaled rows are ``mu = lambda sigma_ij^2`` in terms
of the paper's multipliers, and the dual constraint of the column ``g`` is
``sum_k mu_k = 1`` (paper Eq. 9). Contacts are rows with
``mu_k > CONTACT_DUAL_REL_TOL * max(mu)``: a vertex solution (simplex, or interior
point with crossover) has inactive duals exactly zero and active ones of order
``1 / N_c`` down to ~1e-4 of that in the tail of the force distribution, so a relative
threshold of 1e-10 sits orders of magnitude inside the gap; the smallest active and
largest inactive dual are recorded after every LP. Forces follow paper Eq. 11,
``f_ij = lambda_ij sigma_ij = mu_k / sigma_ij`` (a wall contact: ``mu_k / (sigma_i/2)``),
in units of 1/length, normalised by Eq. 9 as ``sum_c f_c sigma_c = 1``.

Degenerate (hyperstatic) packings
---------------------------------
The support of a dual vertex is the contact network only when the LP is not
degenerate. A crystal or a 2D monodisperse packing with crystalline patches is
hyperstatic: more pairs touch than the ``d (N_s - 1) + 1`` a vertex can hold
forces on, and the vertex leaves the others at zero dual, so its support can strip
force-bearing particles into "rattlers" (a perfect triangular crystal came back
with no contact). After convergence the geometric network, every pair (and wall)
with relative gap at most :data:`~jamflow.tolerances.CONTACT_GAP_TOL`, is compared
with the dual one. When both give the same rattlers and the same contacts between
non-rattlers (an isostatic packing: only rattlers resting on a neighbour with zero
dual differ), the dual contacts and forces are stored unchanged
(``force_assignment = "lp_dual_vertex"``). Otherwise the geometric contacts are
stored, rattlers are the particles with fewer than ``d + 1`` of them (iterated,
:func:`jamflow.analysis.contacts.find_rattlers`), and the forces are the
minimum-norm non-negative forces that balance every particle with the same
normalisation (:mod:`jamflow.network.forces`, ``force_assignment =
"min_norm_balanced"``; a perfect crystal gets equal forces). Attributes record
the choice: ``force_assignment`` (and a ``force_assignment_comment``),
``contact_gap_tol``, ``n_contacts_dual`` (pair and wall contacts with a positive
dual at the vertex), ``n_rattlers_dual`` (rattlers of that support) and
``n_zero_force_contacts`` (stored contacts without force).

Iteration
---------
``r <- r + s*`` and every diameter ``sigma <- sqrt(Gamma*) sigma`` (the box is kept;
the packing fraction rises by ``Gamma^(d/2)``), or with the Sec. IV relaxation
``sigma <- sqrt(1 + c g*) sigma``. The displacement bound and the neighbour cutoff
follow the reference implementation's schedule (bound ``far`` while
``sqrt(Gamma*) - 1 > 5e-4``, 0.1 R while ``> 1e-5``, then 0.01 R, R = mean radius),
with hysteresis: the phase only tightens. Convergence (Algorithm 1, line 15) needs
``sqrt(Gamma*) - 1 < tol_gamma`` and ``max_i |s_i| < tol_s`` over stable particles
[mean diameters]. The LP that certifies convergence is always solved without
displacement bounds (paper Sec. II C: an active bound acts as an external force);
after it the contact network is checked for isostaticity, force balance and, over
all pairs, overlaps. In the last bound phase a bounded LP is followed by an
unbounded one when it gave an isostatic network (the bound then holds no stable
particle) or its stable particles moved by less than :data:`UNBOUND_FRACTION` of
the bound or by more than :data:`BOUND_ACTIVE_FRACTION` of it; an unbounded LP is
followed by another only when it was isostatic and its stable particles moved by at
most :data:`BOUND_ACTIVE_FRACTION` of the bound (larger moves wander along soft
directions). The previous LP's rattlers get the far bound so that they are not
pinned on it.
The cutoff is ``cutoff`` (1.7 largest diameters) far from jamming and
``cutoff_near`` (1.4) in the last phase; rows are kept from LP to LP (which lets the
dual simplex start from the previous basis) while the particles moved little.
A start near jamming (attribute ``near_start``: the median particle's nearest gap
below :data:`NEAR_START_GAP`) moves little: it takes ``cutoff_near`` from the first
LP on (the growth cap ``sqrt(Gamma) <= (ell - 2 sqrt(d) b) / sigma_max`` keeps every
LP safe with any cutoff; d = 5 LS example: the first LP has 26413 rows instead of
71567 and took 23-30 s instead of 33-38 s), and solves its interior point LPs without
HiGHS presolve, whose vertex is the better warm start (:data:`NEAR_START_PRESOLVE`).

Newton finish
-------------
In the tail the chain fine-tunes positions of a network that no longer changes. With
``finish="newton"`` (opt-in), after every accepted LP with ``sqrt(Gamma*) - 1 <=``
:data:`NEWTON_FROM` whose network is isostatic, the square system "every backbone
contact touches, one inflation factor" (the network rows of the LP as equalities over
the stable particles' coordinates and ``g``; the LP's basis matrix) is solved by
Newton's method with a sparse LU, kept over chord steps while they converge fast
(:func:`_newton_finish`). A network whose forces at the LP's configuration are not all
positive is rejected before any step (the next LP, started from its basis, would not
be dual feasible). The result is kept only under a certificate that it is the LP
chain's limit: the forces of the transposed system at the finished configuration are
all positive, no pair overlaps beyond :data:`~jamflow.tolerances.OVERLAP_TOL` and the
geometric network has the same backbone; then ``s = 0, Gamma = 1`` solves the next
LP. Otherwise the chain goes on with LPs. Rattlers are not part of the system; those
the finish's growth pressed into a neighbour are pushed off it first
(:func:`_free_rattlers`). The finish is one history entry with solver ``newton``;
attributes ``finish``, ``n_lps``, ``newton_attempts``,
``newton_rejections``, ``newton_last_rejection`` and ``newton_time`` [s, all
attempts] say what happened.

Robustness
----------
After each LP: a status other than optimal (e.g. an LP without bounds that HiGHS
reports unbounded because a particle has no cage within the cutoff), or an update
that creates an overlap beyond
:data:`~jamflow.tolerances.OVERLAP_TOL` in the all-pairs check is undone and retried
with a cutoff larger by :data:`CUTOFF_GROWTH` and a bound smaller by
:data:`BOUND_SHRINK`, up to :data:`MAX_RECOVERIES` times in a row. A converged LP
whose network is not isostatic (and not hyperstatic as in App. A: either the dual
count with force-bearing rattlers is isostatic, or the geometric network, which
holds every dual contact, has at least the isostatic count of contacts) or whose
dual contacts disagree with the geometry is re-solved with a
larger cutoff, cold: by interior point with crossover, then by the dual simplex
(:data:`FINAL_RECOVERY_METHODS`). When recovery fails a
``RuntimeError`` carries the diagnostics; a non-jammed packing is never returned as
jammed (``require_isostatic=False`` returns it with ``converged = False``). A stall
(:func:`_stalled`: no halving of ``sqrt(Gamma*) - 1`` in :data:`STALL_WINDOW` LPs)
gets an unbounded LP with fresh rows; after :data:`MAX_STALL_RECOVERIES` stalls, or at
``max_iterations``, the chain stops with the same kind of error.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import highspy
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import xarray as xr
from numpy.typing import NDArray

from ..box import Box
from ..highs import new_highs
from ..neighbors.pairs import pairs_within
from ..network import isostatic_count, pair_rows
from ..network.forces import MIN_NORM, balance_matrix, min_norm_forces
from ..network.rigidity import contact_geometry
from ..network.spheres import find_rattlers
from ..stages import require
from ..state.packing import Packing, max_overlap, near_pairs
from ..tolerances import CONTACT_GAP_TOL, OVERLAP_TOL

__all__ = [
    "SOLVERS",
    "CalippsoResult",
    "JammingLP",
    "calippso",
    "jamming_lp",
    "result_to_dataset",
]

#: Solver strategies. ``ipm``: HiGHS interior point with crossover (vertex duals),
#: cold every LP; ``simplex``: the primal simplex from the previous LP's basis,
#: carried over to the new rows by pair (the cold first LP by the dual simplex);
#: ``hybrid``: interior point while ``sqrt(Gamma*) - 1 > HYBRID_SWITCH``, then the
#: warm primal simplex (a warm start slower than the last interior point solve is
#: abandoned for interior point, see :data:`WARM_PIVOTS_PER_ROW`); ``ipm-center``:
#: interior point without crossover on every bounded LP (a point inside the optimal
#: face: displacements along directions that do not change Gamma are not pushed onto
#: the bound as at a vertex) and with crossover on every unbounded LP, the only ones
#: whose duals give the contacts of the result.
SOLVERS: tuple[str, ...] = ("ipm", "simplex", "hybrid", "ipm-center")

#: Default solver, chosen by ``benchmarks/calippso.py`` (part ``solvers``): on the
#: d = 3 LS example (N = 1024) hybrid needs 2-3 interior point LPs (~1.5 s each) and
#: then warm primal simplex LPs of 0.07-0.8 s; a cold simplex LP takes 20-80 s. From
#: a carried basis the primal simplex needs a few pivots where the dual simplex needs
#: thousands (d = 4 example: 2 against 5184 pivots, 0.4 s against 26 s). PDLP is not
#: a strategy: on the first LP of the d = 3 example (part ``lp``) it took 11.7 s
#: against 1.5 s for interior point with crossover and its duals are not a vertex's
#: (3003 above 1e-10 of the largest, against 3004 for every vertex method); interior
#: point without crossover leaves 10302 duals above 1e-10 (no gap between active and
#: inactive rows).
DEFAULT_SOLVER: str = "hybrid"

#: Convergence: largest displacement of a stable particle [mean diameters].
DEFAULT_TOL_S: float = 1e-9

#: Convergence: ``sqrt(Gamma*) - 1`` (relative growth of the diameters in one LP).
DEFAULT_TOL_GAMMA: float = 1e-12

#: HiGHS primal and dual feasibility (and interior point optimality) tolerance, the
#: default of ``solver_tol``. Rows are relative-gap sized, so a row violation v is a
#: relative overlap of ~v / 2: ``solver_tol`` may range from HiGHS's smallest
#: feasibility tolerance, 1e-10, up to ``2 OVERLAP_TOL`` (overlaps up to OVERLAP_TOL).
SOLVER_TOL: float = 1e-10
MIN_SOLVER_TOL: float = 1e-10
MAX_SOLVER_TOL: float = 2.0 * OVERLAP_TOL

#: Default neighbour cutoff ``ell`` [current largest diameters]: the reference
#: implementation's 3.4 R. (The paper's "3.5 sigma" costs ~4x more rows for no
#: fewer LPs.)
DEFAULT_CUTOFF: float = 1.7

#: Cutoff in the last bound phase and for unbounded LPs [current largest diameters]:
#: there displacements are at most ~0.005 diameters, so the first shell (and the
#: cage of a rattler) suffices; the paper uses 1.4 sigma, the reference 2.7 R.
DEFAULT_CUTOFF_NEAR: float = 1.4

#: Smallest usable cutoff [largest diameters] (the periodic box must hold it).
MIN_CUTOFF: float = 1.1

#: Displacement bound schedule: ``(threshold on sqrt(Gamma*) - 1, bound)`` with the
#: bound in mean radii; the first phase (``far``) bound is derived from the cutoff.
DEFAULT_BOUND_SCHEDULE: tuple[tuple[float, float], ...] = ((5e-4, 0.1), (1e-5, 0.01))

#: Largest growth of the diameters allowed in one LP far from jamming,
#: ``sqrt(Gamma) <= FAR_GROWTH``; it fixes the far bound through the cutoff (see
#: :func:`_far_bound`) so that no pair beyond the cutoff can overlap.
FAR_GROWTH: float = 1.2

#: Contacts: rows whose dual exceeds this fraction of the largest dual.
CONTACT_DUAL_REL_TOL: float = 1e-10

#: ``hybrid``: switch from interior point to warm dual simplex below this ``sqrt(Gamma*) - 1``.
HYBRID_SWITCH: float = 1e-5

#: A start is near jamming when the median over particles of the smallest relative
#: gap ``r / sigma - 1`` to a neighbour is below this: LS packings (the authors'
#: examples 1e-8 to 1.3e-6) against random starts (4e-2 to 6e-2 at phi = 0.3-0.4).
NEAR_START_GAP: float = 1e-3

#: HiGHS presolve of the interior point LPs of a start near jamming. Off: the
#: crossover vertex of the unreduced LP is a far better start for the warm simplex LPs
#: that follow than the postsolved vertex (LS examples, N = 1024: d = 3 the first warm
#: LP 200 pivots and 0.22 s against 1130 and 1.0 s; d = 4 86 against 865 pivots, 0.9 s
#: against 3.9 s), and the interior point LPs are no slower (every row is a distinct
#: pair: presolve removes little; d = 4 first LP 8.9 s against 10.6 s). From random
#: starts the chain takes its LPs by interior point for long and presolve stays on
#: ("choose"): without it, 4 of 6 chains from 3D N = 256 random starts (seeds 1-6)
#: took more LPs, up to 2.5 times as many, and the six 20 % more time.
NEAR_START_PRESOLVE: str = "off"
#: HiGHS's own presolve setting, kept by every other LP.
_HIGHS_PRESOLVE: str = "choose"

#: HiGHS's scaling of a warm simplex LP (``simplex_scale_strategy``): 0, none. The rows
#: are built well scaled (module docstring: coefficients ``2 <D> |r_ij| / sigma_ij^2``
#: ~ 2, the column of ``g`` ones), so HiGHS's equilibration only multiplies rows and
#: columns by powers of two, and without it the feasibility tolerances act on the rows
#: as built, where ``solver_tol`` has its stated meaning. From the carried basis the
#: unscaled primal simplex reaches the same optimum in fewer pivots: the chains of the
#: LS examples and of six 3D N = 1024 and one N = 2048 near starts took the same LPs
#: and ended in the same packings (Q = 1, forces to 1e-10) with 0-40 % fewer pivots
#: and up to 33 % less LP time; a captured N = 4096 warm LP took 673 against 1144
#: pivots, 10-12 s against 20-21 s (``docs/notes/calippso-scaling.md``). Cold LPs keep
#: HiGHS's equilibration (``_HIGHS_SCALE``): the cold dual simplex of ``solver =
#: "simplex"`` on an N = 1024 near start took 65012 pivots unscaled against 27651.
WARM_SIMPLEX_SCALE: int = 0
#: HiGHS's own scaling (equilibration), kept by every other LP.
_HIGHS_SCALE: int = 2

#: A warm simplex may take this many pivots per row before the LP is re-solved by
#: interior point (a pivot limit, not a time limit, so that the same input always
#: gives the same chain). Measured on the d = 4 LS example (13826 rows): a warm
#: start that pays needs a few pivots (0.4 s); the dual simplex that did not needed
#: 5184 pivots and 26 s against 5.6 s for interior point. From a random start (3D
#: N = 512) a limit of 0.25 per row sent 20 LPs to interior point and needed 454 LPs
#: (89 s), a limit of 1 per row none and 305 LPs (47 s).
WARM_PIVOTS_PER_ROW: float = 1.0

#: HiGHS interior point methods for the interior point LPs: ``ipx`` (HiGHS's default,
#: in every highspy wheel) and ``hipo`` (nested-dissection factorisation; needs the
#: ``hipo`` extra, ``highspy[extras]``, which exists only for highspy <= 1.15.1).
#: Measured on the first LP of the d = 3 LS example (N = 1024, one thread, side by
#: side, loaded machine): IPX + crossover 36.7 s, HiPO + crossover 32.0 s, the same
#: vertex (3004 active duals); the issue's N = 4096 measurement 51.1 s against 49.9 s.
#: HiPO wins only at N = 16384 (the first LP in ~593 s where IPX did not finish in 58 min),
#: which is not worth pinning highspy to 1.15.1 for everyone: opt-in.
INTERIOR_POINTS: tuple[str, ...] = ("ipx", "hipo")
DEFAULT_INTERIOR: str = "ipx"

#: Methods of the cold re-solves after a converged LP failed its final checks:
#: interior point with crossover, then the dual simplex.
FINAL_RECOVERY_METHODS: tuple[str, ...] = ("ipm", "dual")

_NO_PIVOT_LIMIT: int = 2**31 - 1  # HiGHS's default simplex_iteration_limit

#: Rows (the pair list) are reused while every particle moved less than this fraction
#: of ``ell - sigma_max`` since they were built (lets the simplex warm start).
REUSE_FRACTION: float = 0.05

#: Recovery: cutoff growth and bound shrink factors per failed LP, and how many
#: consecutive recoveries are allowed before giving up.
CUTOFF_GROWTH: float = 1.3
BOUND_SHRINK: float = 0.25
MAX_RECOVERIES: int = 4

#: In the last bound phase the next LP is solved without bounds once the stable
#: particles moved less than this fraction of the bound (the bound is then inactive
#: for them and only holds rattlers).
UNBOUND_FRACTION: float = 1e-3

#: In the last bound phase a stable particle moving by more than this fraction of the
#: bound means the bound is active (an external force, non-isostatic network): the
#: next LP is then tried without bounds, which typically lands on the jammed vertex.
BOUND_ACTIVE_FRACTION: float = 0.5

#: Stall test: a chain stalls when the smallest ``sqrt(Gamma*) - 1`` of its last
#: STALL_WINDOW accepted LPs exceeds STALL_PROGRESS times the smallest before them.
#: Each stall gets one recovery (an unbounded LP with fresh rows, counted anew);
#: after MAX_STALL_RECOVERIES the chain stops with a RuntimeError. Healthy chains
#: from random starts hover at 1e-5..1e-4 for up to ~100 LPs before converging
#: (3D N = 256, seed 1: 156 LPs), hence the window.
STALL_WINDOW: int = 100
STALL_PROGRESS: float = 0.5
MAX_STALL_RECOVERIES: int = 3

#: How a chain ends. ``newton``: once an LP in the tail (``sqrt(Gamma*) - 1 <=
#: NEWTON_FROM``) gives an isostatic network (see :func:`_newton_ready`), the square system of that network is solved by Newton's method and certified
#: (:func:`_newton_finish`); a rejected finish leaves the chain to the LPs. ``lp``: the
#: pure LP chain of the paper.
FINISHES: tuple[str, ...] = ("newton", "lp")
#: ``lp`` by default: the finish saves LPs (d = 3, 4, 5 LS examples: 1, 2, 2), but the
#: LPs it saves are the cheapest of the chain and its attempts (one sparse LU each)
#: cost about as much: the whole command was not faster on any of the three examples
#: (docs/notes/calippso-scaling.md).
DEFAULT_FINISH: str = "lp"

#: Newton finish: tried from this ``sqrt(Gamma*) - 1`` down (the hybrid solver's tail).
NEWTON_FROM: float = 1e-5

#: Newton finish: largest number of steps (from ``sqrt(Gamma*) - 1 ~ 1e-7`` one to
#: three steps on one LU reach round-off).
NEWTON_MAX_STEPS: int = 8

#: Newton finish: the LU of the network's matrix is kept for the next step while each
#: step shrinks the largest move at least by this factor (chord steps, one pair of
#: triangular solves each; Newton proper shrinks it quadratically); a step that shrinks
#: it less refactorises at the current configuration.
NEWTON_CONTRACTION: float = 0.1

#: Newton finish: besides the chain's convergence test, the last step must leave every
#: network contact touching to this relative tolerance, ``|r^2 - sigma^2| / sigma^2``
#: (chord steps converge linearly, so a small last move alone does not say that): above
#: the round-off of squared distances in boxes up to ~100 diameters (~4e-14).
NEWTON_GAP_TOL: float = 1e-13

#: Newton finish: the certificate's forces solve the finished network's transposed
#: system by iterative refinement on the last LU; accepted once each residual
#: component is at most this fraction of its scale ``(|B^T| |mu| + |e_g|)_k`` (a
#: componentwise backward error near round-off), after at most NEWTON_REFINEMENTS
#: corrections (else a fresh LU).
NEWTON_FORCE_RESIDUAL: float = 1e-14
NEWTON_REFINEMENTS: int = 4

#: Newton finish: a step moving a stable particle by more than this [mean diameters]
#: (the tightest default bound) means the network is not the one of a nearby jammed
#: packing: rejected.
NEWTON_MAX_MOVE: float = 5e-3

#: Newton finish: largest number of sweeps pushing rattlers off the neighbours the finish
#: grew into (a rattler between two neighbours may need several; the d = 5 LS example kept
#: an overlap of 2e-10 after 5 sweeps, which one more sweep removed)
#: (:func:`_free_rattlers`).
RATTLER_PUSHES: int = 50

#: Default largest number of LPs.
DEFAULT_MAX_ITERATIONS: int = 1000

#: ``force_assignment`` of a result whose forces are the LP's dual vertex (paper Eq. 11).
DUAL_VERTEX: str = "lp_dual_vertex"

#: ``force_assignment`` of a degenerate packing whose minimum-norm QP failed: its
#: geometric contacts carry the dual vertex forces (zero off the vertex's support).
DUAL_VERTEX_ON_GEOMETRIC: str = "lp_dual_vertex_on_geometric"

#: What each ``force_assignment`` means (stored as ``force_assignment_comment``).
FORCE_ASSIGNMENTS: dict[str, str] = {
    DUAL_VERTEX: "forces are the duals of the converged LP's vertex (paper Eq. 11); contacts are the "
                 "active rows with positive dual",
    MIN_NORM: "contacts are the pairs with relative gap <= contact_gap_tol (the dual vertex of this "
              "degenerate, hyperstatic packing leaves some without force); forces are the minimum-norm "
              "non-negative forces balancing every particle with sum_c f_c sigma_c = 1",
    DUAL_VERTEX_ON_GEOMETRIC: "contacts are the pairs with relative gap <= contact_gap_tol; forces are the "
                              "duals of the converged LP's vertex (paper Eq. 11), zero on the contacts outside "
                              "its support, because the minimum-norm force QP failed",
}

#: Face codes of wall contacts: ``2 * axis + (0 lower, 1 upper)``.
_LOWER, _UPPER = 0, 1


@dataclass(frozen=True)
class IterationRecord:
    """One LP of the chain (units: displacements in mean diameters)."""

    iteration: int
    sqrt_gamma_minus_1: float
    max_displacement: float
    max_displacement_stable: float
    n_constraints: int
    n_contacts: int
    n_stable: int
    isostatic: bool
    lp_status: str
    lp_time: float
    solver: str
    cutoff: float  # [current largest diameters]
    bound: float  # [mean diameters]; inf = unbounded
    min_active_dual: float  # relative to the largest dual
    max_inactive_dual: float  # relative to the largest dual
    accepted: bool
    warm_start: bool = False  # simplex started from the previous LP's basis
    simplex_iterations: int = 0  # simplex pivots, crossover pivots included
    ipm_iterations: int = 0
    newton_steps: int = 0  # Newton steps of a certified finish (its own record, solver "newton")


@dataclass(frozen=True)
class CalippsoResult:
    """Outcome of :func:`calippso`.

    Attributes
    ----------
    packing : Packing
        Jammed packing: contacts (pairs from duals, or the geometric network of a
        degenerate packing), forces (paper Eq. 11, 1/length, ``sum_c f_c sigma_c = 1``
        including wall contacts; ``attrs["force_assignment"]`` says which), rattlers,
        protocol ``'...>calippso'`` and attrs (``phi_J``, counts, residuals).
    history : xarray.Dataset
        Per-LP records on dimension ``iteration``.
    converged : bool
    iterations : int
        Number of LPs solved (including rejected ones).
    wall_contacts : ndarray of int64, shape (Nw, 2)
        ``(particle, face)`` with face ``2 * axis + (0 lower, 1 upper)``; empty
        without walls.
    wall_force : ndarray, shape (Nw,)
    diagnostics : dict
        Final checks: counts, isostaticity, residuals, overlaps, timings, memory.
    """

    packing: Packing
    history: xr.Dataset
    converged: bool
    iterations: int
    wall_contacts: NDArray[np.int64]
    wall_force: NDArray[np.float64]
    diagnostics: dict[str, Any] = field(default_factory=dict)


# --- the container: periodic box or hard walls --------------------------------------------


def _direct(dx_direct: NDArray[np.float64], dx_image: NDArray[np.float64], box: Box) -> NDArray[np.bool_]:
    """Pairs whose direct separation is their minimum image (no periodic image through a wall)."""
    return np.all(np.abs(dx_direct - dx_image) < 1e-12 * box.lengths.max(), axis=1)


@dataclass(frozen=True)
class _Container:
    """Where the spheres live: a periodic box, or an orthogonal box whose faces are hard
    walls. Everything that differs between the two is here. A wall is a body like a
    sphere: the row finder lists sphere-wall rows after the pair rows, the matrix, the
    duals and the force balance treat both kinds of row alike, and a wall contact
    counts like a pair contact.
    """

    box: Box
    walls: bool

    @property
    def has_translation(self) -> bool:
        """Periodic: the global translation is a zero mode, removed by fixing one anchor
        particle; displacements are reported relative to the stable particles' mean."""
        return not self.walls

    def wrap(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Positions in the primary cell (between walls: unchanged)."""
        return x if self.walls else self.box.wrap(x)

    def displacement(self, dx: NDArray[np.float64]) -> NDArray[np.float64]:
        """Displacement vectors (minimum image in a periodic box)."""
        return dx if self.walls else self.box.minimum_image(dx)

    def pairs(self, x: NDArray[np.float64], cutoff: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Sphere pairs closer than ``cutoff`` [length]; between walls only direct ones."""
        pairs = pairs_within(x, self.box, cutoff)
        if not self.walls:
            return pairs.i, pairs.j
        keep = _direct(x[pairs.j] - x[pairs.i], pairs.dx, self.box)
        return pairs.i[keep], pairs.j[keep]

    def wall_bodies(self, x: NDArray[np.float64], D: NDArray[np.float64],
                    cutoff: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Sphere-wall rows within ``cutoff`` (centre-to-surface minus radius): particles
        and faces ``2 * axis + (0 lower, 1 upper)``; none in a periodic box."""
        if not self.walls:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        L = self.box.lengths
        pl, al = np.nonzero(x <= cutoff - 0.5 * D[:, None])
        pu, au = np.nonzero((L - x) <= cutoff - 0.5 * D[:, None])
        return (np.concatenate([pl, pu]).astype(np.int64),
                np.concatenate([2 * al + _LOWER, 2 * au + _UPPER]).astype(np.int64))

    def n_dof(self, d: int, n_stable: int) -> int:
        """Isostatic contact count: ``d (N_s - 1) + 1`` periodic, ``d N_s + 1`` between walls."""
        if self.walls:
            return d * n_stable + 1 if n_stable > 0 else 0
        return isostatic_count(n_stable, d, global_dofs=d)

    def packing(self, packing: Packing, x: NDArray[np.float64], D: NDArray[np.float64]) -> Packing:
        """``packing`` at positions ``x`` and diameters ``D``, without contacts."""
        return replace(packing, position=self.wrap(x), diameter=D, contacts=None, force=None, rattler=None)

    def max_overlap(self, p: Packing) -> float:
        """Largest relative overlap over ALL pairs (and walls), 0 if none."""
        if not self.walls:
            return max_overlap(p)[1]
        pairs, h = near_pairs(p, 0.0)
        if len(h):
            h = h[_direct(p.position[pairs.j] - p.position[pairs.i], pairs.dx, p.box)]
        ov = max(0.0, -float(h.min())) if len(h) else 0.0
        rad = 0.5 * p.diameter[:, None]
        wall_gap = np.minimum(p.position, p.box.lengths - p.position) / rad - 1.0
        return max(ov, -float(wall_gap.min()))

    def touching(self, p: Packing) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        """The geometric network: pairs (P, 2) and wall contacts (particles, faces) with
        relative gap at most :data:`~jamflow.tolerances.CONTACT_GAP_TOL`."""
        pairs, h = near_pairs(p, CONTACT_GAP_TOL)
        if not self.walls:
            return np.stack([pairs.i, pairs.j], axis=1), np.empty(0, np.int64), np.empty(0, np.int64)
        if len(h):
            pairs = pairs.select(_direct(p.position[pairs.j] - p.position[pairs.i], pairs.dx, p.box))
        rad = 0.5 * p.diameter[:, None]
        gap = np.stack([p.position / rad - 1.0, (p.box.lengths - p.position) / rad - 1.0], axis=2)  # (N, d, 2)
        wp, axis, side = np.nonzero(gap <= CONTACT_GAP_TOL)
        return np.stack([pairs.i, pairs.j], axis=1), wp.astype(np.int64), (2 * axis + side).astype(np.int64)


# --- rows: the LP row builder ------------------------------------------------------------


@dataclass
class _Rows:
    """Constraint rows: particle pairs then sphere-wall rows."""

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    wall_particle: NDArray[np.int64]
    wall_face: NDArray[np.int64]
    x_build: NDArray[np.float64]
    cutoff: float  # absolute [length]

    @property
    def n_pairs(self) -> int:
        return len(self.i)

    def __len__(self) -> int:
        return len(self.i) + len(self.wall_particle)

    def keys(self, n: int) -> NDArray[np.int64]:
        """One integer per row naming its pair ``(i, j)`` or its wall ``(particle, face)``."""
        return np.concatenate([self.i * n + self.j, n * n + 64 * self.wall_particle + self.wall_face])


def _find_rows(x: NDArray[np.float64], D: NDArray[np.float64], container: _Container, cutoff: float) -> _Rows:
    """Algorithm 1, lines 4-6: every pair (and wall) within ``cutoff`` [length]."""
    i, j = container.pairs(x, cutoff)
    wp, wf = container.wall_bodies(x, D, cutoff)
    return _Rows(i, j, wp, wf, x.copy(), cutoff)


@dataclass(frozen=True)
class _RowGeometry:
    """Geometry of the rows at the current state: pair vectors ``dx`` (P, d) [length],
    contact distances ``sig`` (P,), scaled right-hand sides ``rhs`` (M,), wall distances
    ``a`` (W,) and radii ``rad`` (W,) of the sphere-wall rows."""

    dx: NDArray[np.float64]
    sig: NDArray[np.float64]
    rhs: NDArray[np.float64]
    a: NDArray[np.float64]
    rad: NDArray[np.float64]


def _near_start(x: NDArray[np.float64], D: NDArray[np.float64], container: _Container) -> bool:
    """Whether the median particle's smallest relative gap to a neighbour is below :data:`NEAR_START_GAP`."""
    i, j = container.pairs(x, MIN_CUTOFF * float(D.max()))
    sig = 0.5 * (D[i] + D[j])
    gap = np.linalg.norm(container.box.minimum_image(x[j] - x[i]), axis=1) / sig - 1.0
    nearest = np.full(len(D), np.inf)
    np.minimum.at(nearest, i, gap)
    np.minimum.at(nearest, j, gap)
    return bool(np.median(nearest) < NEAR_START_GAP)


def _row_geometry(rows: _Rows, x: NDArray[np.float64], D: NDArray[np.float64], box: Box) -> _RowGeometry:
    """Pair vectors, contact distances and right-hand sides for the current state."""
    dx = box.minimum_image(x[rows.j] - x[rows.i]) if rows.n_pairs else np.empty((0, x.shape[1]))
    sig = 0.5 * (D[rows.i] + D[rows.j])
    r = np.linalg.norm(dx, axis=1)
    rhs = (r - sig) * (r + sig) / sig**2
    axis = rows.wall_face // 2
    upper = rows.wall_face % 2 == _UPPER
    xa = x[rows.wall_particle, axis]
    a = np.where(upper, box.lengths[axis] - xa, xa)
    rad = 0.5 * D[rows.wall_particle]
    wrhs = (a - rad) * (a + rad) / rad**2
    return _RowGeometry(dx, sig, np.concatenate([rhs, wrhs]), a, rad)


def _matrix(rows: _Rows, geo: _RowGeometry, n: int, d: int, unit: float) -> sp.csc_matrix:
    """Scaled constraint matrix (rows x (d N + 1)), column ``d N`` is ``g``."""
    coef = 2.0 * unit * geo.dx / geo.sig[:, None] ** 2  # (P, d)
    pairs = pair_rows(np.stack([rows.i, rows.j], axis=1), -coef, n)
    W = len(rows.wall_particle)
    sign = np.where(rows.wall_face % 2 == _UPPER, 1.0, -1.0)
    wcoef = sign * 2.0 * unit * geo.a / geo.rad**2
    walls = sp.csr_matrix((wcoef, (np.arange(W), rows.wall_particle * d + rows.wall_face // 2)), shape=(W, d * n))
    m = rows.n_pairs + W
    A = sp.hstack([sp.vstack([pairs, walls]), sp.csr_matrix(np.ones((m, 1)))], format="csc")
    A.sort_indices()
    return A


def _most_neighbours(rows: _Rows, n: int) -> int:
    """The first anchor: the particle with most rows."""
    return int(np.argmax(np.bincount(np.concatenate([rows.i, rows.j]), minlength=n)))


def _column_bounds(b_part: NDArray[np.float64], d: int, anchor: int, ell: float, sig_max: float,
                   unit: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Column bounds: per-particle displacement bounds ``b_part`` [mean diameters] on
    every coordinate, the anchor fixed (``anchor < 0``: none), ``g >= -1`` and the cap
    ``sqrt(Gamma) <= min(FAR_GROWTH, (ell - 2 sqrt(d) b) / sigma_max)`` that keeps
    every pair beyond the cutoff apart in a bounded LP."""
    col_upper = np.append(np.repeat(b_part, d), 0.0)
    col_lower = -col_upper
    if anchor >= 0:
        col_lower[anchor * d:(anchor + 1) * d] = 0.0
        col_upper[anchor * d:(anchor + 1) * d] = 0.0
    col_lower[-1] = -1.0
    b_max = float(b_part.max())
    reach = (ell - 2.0 * np.sqrt(d) * b_max * unit) / sig_max if np.isfinite(b_max) else FAR_GROWTH
    col_upper[-1] = min(FAR_GROWTH, max(reach, 1.0)) ** 2 - 1.0
    return col_lower, col_upper


@dataclass(frozen=True)
class JammingLP:
    """One jamming LP in the scaled form of the module docstring: minimise ``-g``
    subject to ``A z <= rhs`` and ``col_lower <= z <= col_upper``, with
    ``z = (u_1, ..., u_N, g)`` (displacements in mean diameters, particle-major).

    Attributes
    ----------
    A : scipy.sparse.csc_matrix, shape (M, d N + 1)
    rhs : ndarray, shape (M,)
    col_lower, col_upper : ndarray, shape (d N + 1,)
    pairs : ndarray of int64, shape (P, 2)
        Particle pairs of the first P rows (wall rows follow).
    """

    A: sp.csc_matrix
    rhs: NDArray[np.float64]
    col_lower: NDArray[np.float64]
    col_upper: NDArray[np.float64]
    pairs: NDArray[np.int64]

    def to_highs(self) -> highspy.HighsLp:
        """The LP as a ``highspy.HighsLp``."""
        return _highs_lp(self.A, self.rhs, self.col_lower, self.col_upper)


def _highs_lp(A: sp.csc_matrix, rhs, col_lower, col_upper) -> highspy.HighsLp:
    """``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper`` (``g`` last)."""
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = A.shape[1], A.shape[0]
    cost = np.zeros(A.shape[1])
    cost[-1] = -1.0
    lp.col_cost_ = cost
    lp.col_lower_ = col_lower
    lp.col_upper_ = col_upper
    lp.row_lower_ = np.full(A.shape[0], -highspy.kHighsInf)
    lp.row_upper_ = rhs
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = A.indptr.astype(np.int32)
    lp.a_matrix_.index_ = A.indices.astype(np.int32)
    lp.a_matrix_.value_ = A.data.astype(np.float64)
    return lp


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


# --- LP solve --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Solution:
    """Outcome of one LP: HiGHS status, wall time [s], columns and row duals (None
    unless optimal), whether the simplex started warm, the method that produced it
    and the iterations it took."""

    status: str
    seconds: float
    col: NDArray[np.float64] | None
    dual: NDArray[np.float64] | None
    warm: bool
    method: str
    simplex_iterations: int
    ipm_iterations: int


class _Solver:
    """One HiGHS instance; keeps the last basis for warm starts on unchanged rows.

    A warm simplex is given :data:`WARM_PIVOTS_PER_ROW` pivots per row; when they run
    out the LP is solved by interior point instead, so a warm start that does not
    pay costs about one interior point solve more.
    """

    def __init__(self, threads: int = 1, tol: float = SOLVER_TOL, interior: str = DEFAULT_INTERIOR) -> None:
        self.h = new_highs(threads)
        if interior not in INTERIOR_POINTS:
            raise ValueError(f"unknown interior point {interior!r}; choose one of {', '.join(INTERIOR_POINTS)}")
        if self.h.setOptionValue("solver", interior) != highspy.HighsStatus.kOk:
            raise ValueError(f"interior point {interior!r} is not in this highspy build: HiPO needs "
                             "`pip install 'jamflow[hipo]'` (highspy[extras]==1.15.1, which must match highspy)")
        self.interior = interior
        for option in ("primal_feasibility_tolerance", "dual_feasibility_tolerance", "ipm_optimality_tolerance"):
            if self.h.setOptionValue(option, tol) != highspy.HighsStatus.kOk:
                raise ValueError(f"HiGHS refused {option} = {tol:g}")
        self.basis = None
        self.basis_rows: _Rows | None = None
        #: hybrid: a simplex LP without a basis to carry is solved by interior point
        self.cold_simplex_as_ipm = False
        #: HiGHS presolve of the interior point LPs (see NEAR_START_PRESOLVE)
        self.ipm_presolve = _HIGHS_PRESOLVE

    def solve(self, A: sp.csc_matrix, rhs, col_lower, col_upper, method: str, rows: _Rows) -> _Solution:
        """Solve the LP ``min -g`` s.t. ``A z <= rhs``, ``col_lower <= z <= col_upper``."""
        lp = _highs_lp(A, rhs, col_lower, col_upper)
        cold = method == "dual"
        method = "simplex" if cold else method
        basis = self._carried_basis(rows, A.shape[1]) if method == "simplex" and not cold else None
        warm = basis is not None
        if method == "simplex" and not warm and not cold and self.cold_simplex_as_ipm:
            method = "ipm"
        status, elapsed = self._run(lp, method, basis)
        pivots, ipm_its = self._iterations()
        if warm and status == highspy.HighsModelStatus.kIterationLimit:
            warm = False
            method = "simplex>ipm"
            status, t_ipm = self._run(lp, "ipm", None)
            elapsed += t_ipm
            more_pivots, ipm_its = self._iterations()
            pivots += more_pivots
        h = self.h
        name = h.modelStatusToString(status)
        # without crossover HiGHS may stop with status "Unknown" at a primal-feasible
        # interior point; only its primal part is used (the overlap check follows)
        interior_ok = (method == "ipm-nox" and status == highspy.HighsModelStatus.kUnknown
                       and int(h.getInfo().primal_solution_status) == 2)
        if status != highspy.HighsModelStatus.kOptimal and not interior_ok:
            self.basis = None
            return _Solution(name, elapsed, None, None, warm, method, pivots, ipm_its)
        sol = h.getSolution()
        self.basis = h.getBasis() if method != "ipm-nox" else None
        self.basis_rows = rows
        return _Solution(name, elapsed, np.asarray(sol.col_value), -np.asarray(sol.row_dual), warm, method,
                         pivots, ipm_its)

    def _iterations(self) -> tuple[int, int]:
        """Simplex pivots (crossover included) and interior point iterations of the last run."""
        info = self.h.getInfo()
        return (max(int(info.simplex_iteration_count), 0) + max(int(info.crossover_iteration_count), 0),
                max(int(info.ipm_iteration_count), 0))

    def _carried_basis(self, rows: _Rows, n_cols: int):
        """The last basis carried over to ``rows``: rows kept by pair keep their status,
        new rows enter with a basic slack (inactive); None when there is no basis or
        the carried one does not have one basic variable per row."""
        if self.basis is None or self.basis_rows is None:
            return None
        if rows is self.basis_rows:
            return self.basis
        col = self.basis.col_status
        if len(col) != n_cols:
            return None
        n = len(rows.x_build)
        old_keys = self.basis_rows.keys(n)
        old_status = np.array([int(v) for v in self.basis.row_status], dtype=np.int64)
        order = np.argsort(old_keys)
        new_keys = rows.keys(n)
        pos = np.clip(np.searchsorted(old_keys, new_keys, sorter=order), 0, max(len(old_keys) - 1, 0))
        found = old_keys[order[pos]] == new_keys if len(old_keys) else np.zeros(len(new_keys), bool)
        basic = int(highspy.HighsBasisStatus.kBasic)
        status = np.where(found, old_status[order[pos]], basic)
        n_basic = int(np.sum(status == basic)) + sum(1 for v in col if v == highspy.HighsBasisStatus.kBasic)
        if n_basic != len(rows):
            return None
        carried = highspy.HighsBasis()
        carried.col_status = list(col)
        carried.row_status = [highspy.HighsBasisStatus(int(v)) for v in status]
        carried.valid = True
        return carried

    def _run(self, lp: highspy.HighsLp, method: str, basis):
        h = self.h
        h.clearSolver()
        if method in ("ipm", "ipm-nox"):
            h.setOptionValue("solver", self.interior)
            h.setOptionValue("run_crossover", "on" if method == "ipm" else "off")
            h.setOptionValue("presolve", self.ipm_presolve)
        else:
            # from a carried basis the primal simplex needs a few pivots where the
            # dual simplex needed thousands (d = 4 LS example: 2 against 5184)
            h.setOptionValue("solver", "simplex")
            h.setOptionValue("simplex_strategy", 4 if basis is not None else 1)
            h.setOptionValue("presolve", _HIGHS_PRESOLVE)
        h.setOptionValue("simplex_scale_strategy", WARM_SIMPLEX_SCALE if basis is not None else _HIGHS_SCALE)
        h.passModel(lp)
        limit = _NO_PIVOT_LIMIT
        if basis is not None:
            h.setBasis(basis)
            limit = max(int(WARM_PIVOTS_PER_ROW * lp.num_row_), 1)
        h.setOptionValue("simplex_iteration_limit", limit)
        t0 = time.perf_counter()
        h.run()
        return h.getModelStatus(), time.perf_counter() - t0


# --- schedules -----------------------------------------------------------------------------


def _far_bound(cutoff: float, d: int) -> float:
    """Far-phase bound [current largest diameters] so that, with ``sqrt(Gamma) <= FAR_GROWTH``,
    no pair beyond the cutoff can reach contact: ``cutoff - 2 sqrt(d) b >= FAR_GROWTH``."""
    return max((cutoff - FAR_GROWTH) / (2.0 * np.sqrt(d)), 0.0)


# --- Algorithm 1: state and steps ------------------------------------------------------------


@dataclass(frozen=True)
class _Options:
    """The user's options of one :func:`calippso` call."""

    tol_s: float
    tol_gamma: float
    solver: str
    cutoff: float
    cutoff_near: float
    bound: tuple[tuple[float, float], ...]
    relax: float | None
    require_isostatic: bool
    finish: str


@dataclass
class _Chain:
    """What Algorithm 1 carries from one LP to the next: the configuration, the rows
    (kept while particles move little, for warm starts), the bound phase and the
    recovery counters."""

    x: NDArray[np.float64]  # (N, d) positions [length]
    D: NDArray[np.float64]  # (N,) diameters [length]
    records: list[IterationRecord] = field(default_factory=list)
    rows: _Rows | None = None
    phase: int = 0  # 0 far, 1.. schedule entries; only tightens (hysteresis)
    cut_factor: float = 1.0
    bound_factor: float = 1.0
    recoveries: int = 0
    anchor: int = -1  # fixed particle (periodic box); -1 = none
    prev_rattler: NDArray[np.bool_] | None = None
    final_attempts: int = 0
    recovery_method: str | None = None  # cold solve forced by a failed final check
    unbounded_next: bool = False
    stalls: int = 0
    stall_from: int = 0  # records before this index are not compared by the stall test
    backbone_key: bytes | None = None  # backbone rows of the last accepted LP
    newton_tried: bytes | None = None  # backbone of the last rejected Newton finish
    newton: list[_NewtonAttempt] = field(default_factory=list)
    near_start: bool = False  # see NEAR_START_GAP


@dataclass(frozen=True)
class _LPSetup:
    """One jamming LP as set up (Algorithm 1, lines 4-7): rows, their geometry, the
    scaled matrix, column bounds, the cutoff ``ell`` [length], the displacement bound
    ``bound`` [mean diameters; inf = none], the mean diameter ``unit`` and the HiGHS method."""

    rows: _Rows
    geo: _RowGeometry
    A: sp.csc_matrix
    col_lower: NDArray[np.float64]
    col_upper: NDArray[np.float64]
    ell: float
    sig_max: float
    unit: float
    bound: float
    method: str


@dataclass(frozen=True)
class _Step:
    """What one solved LP says (Algorithm 1, lines 9-11): displacements ``u`` (N, d)
    [mean diameters], ``g = Gamma* - 1``, the row duals ``mu`` and their active set, the
    contacts and rattlers they give, and the convergence measures."""

    u: NDArray[np.float64]
    g: float
    sg: float  # sqrt(Gamma*) - 1
    mu: NDArray[np.float64]
    active: NDArray[np.bool_]
    contacts: NDArray[np.int64]
    wall_particles: NDArray[np.int64]
    rattler: NDArray[np.bool_]
    n_c: int
    n_s: int
    iso: bool
    max_s: float
    max_s_stable: float
    min_active_dual: float
    max_inactive_dual: float

    @property
    def backbone(self) -> NDArray[np.bool_]:
        """Contacts between two stable particles."""
        stable = ~self.rattler
        return stable[self.contacts[:, 0]] & stable[self.contacts[:, 1]]


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
    return _LPSetup(rows, geo, A, col_lower, col_upper, ell, sig_max, unit, b, method)


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
    return _Step(u, g, sg, mu, active, contacts, wall_particles, rattler, n_c, n_s, iso, max_s, max_s_stable,
                 min_act, max_inact)


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
    # phase schedule with hysteresis: a phase never loosens (measured: loosening
    # again above 10x the threshold cost more LPs from random starts)
    while chain.phase < len(opt.bound) and step.sg <= opt.bound[chain.phase][0]:
        chain.phase += 1


def _growth(g: float, relax: float | None) -> float:
    """Diameter factor of one LP: ``sqrt(Gamma*)``, or ``sqrt(1 + c g*)`` with relaxation ``c``."""
    return np.sqrt(1.0 + (relax if relax is not None else 1.0) * g)


def _small(step: _Step, opt: _Options) -> bool:
    """Algorithm 1, line 15: ``sqrt(Gamma*) - 1 < tol_gamma`` and ``max |s| < tol_s``."""
    return step.sg < opt.tol_gamma and step.max_s_stable < opt.tol_s


def _schedule_next(chain: _Chain, step: _Step, lp: _LPSetup, opt: _Options) -> None:
    """Whether the next LP is bounded, and the stall recovery."""
    # the converging LP must be unbounded: go unbounded once the network is
    # isostatic or the tightest bound is far from active for the stable particles;
    # stay unbounded only while isostatic with moves the bound would have allowed
    # (a large unbounded move wanders along soft directions: bounded again after it)
    tight = 0.5 * opt.bound[-1][1]
    if np.isfinite(lp.bound):
        leave_bound = (step.iso or step.max_s_stable < UNBOUND_FRACTION * tight
                       or step.max_s_stable > BOUND_ACTIVE_FRACTION * tight)
    else:
        leave_bound = step.iso and step.max_s_stable <= BOUND_ACTIVE_FRACTION * tight
    chain.unbounded_next = _small(step, opt) or (chain.phase == len(opt.bound) and leave_bound)
    if _stalled(chain.records, chain.stall_from):
        chain.stalls += 1
        if chain.stalls > MAX_STALL_RECOVERIES:
            raise RuntimeError(_diagnose(
                f"stalled: sqrt(Gamma*)-1 did not halve in {STALL_WINDOW} LPs, {MAX_STALL_RECOVERIES} times",
                chain.records))
        # recovery: an unbounded LP (no bound pins floppy motions) with fresh rows
        chain.stall_from = len(chain.records)
        chain.unbounded_next = True
        chain.rows = None


def _recover(chain: _Chain, reason: str) -> None:
    """After a failed LP or a rejected update: one more recovery, a larger cutoff and a
    smaller bound with fresh rows, or the diagnostics when spent."""
    if chain.recoveries + 1 > MAX_RECOVERIES:
        raise RuntimeError(_diagnose(f"{reason} after {MAX_RECOVERIES} recoveries", chain.records))
    chain.recoveries += 1
    chain.cut_factor *= CUTOFF_GROWTH
    chain.bound_factor *= BOUND_SHRINK
    chain.unbounded_next = False
    chain.rows = None


def _final_recovery(chain: _Chain) -> None:
    """A converged LP failed its final checks: re-solve with a larger cutoff, cold. A
    degenerate (e.g. App. A hyperstatic) LP has many dual optima: by interior point with
    crossover, then by the dual simplex."""
    chain.final_attempts += 1
    chain.cut_factor *= CUTOFF_GROWTH
    chain.recovery_method = FINAL_RECOVERY_METHODS[chain.final_attempts - 1]
    chain.rows = None


# --- the Newton finish ----------------------------------------------------------------------


@dataclass(frozen=True)
class _NewtonAttempt:
    """Outcome of one Newton finish attempt (:func:`_newton_finish`).

    Attributes
    ----------
    certified : bool
        The square system converged and its certificate holds: every network force
        positive, no overlap beyond ``OVERLAP_TOL``, and the geometric network (gaps
        at most ``CONTACT_GAP_TOL``) has the same backbone and rattlers.
    reason : str
        Why it was rejected ("ok" when certified).
    steps : int
        Newton steps taken.
    seconds : float
        Wall time [s].
    min_dual : float
        Smallest network dual over the largest (NaN when not reached).
    """

    certified: bool
    reason: str
    steps: int
    seconds: float
    min_dual: float = np.nan


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
    d, n = packing.d, packing.n
    rows = _network_rows(step, lp)
    stable = ~step.rattler
    cols = _square_columns(stable, chain.anchor if container.has_translation else -1, d)
    x, D = chain.x, chain.D

    def reject(reason: str, steps: int):
        return _NewtonAttempt(False, reason, steps, time.perf_counter() - t0), chain.x, chain.D, None

    def matrix(geo: _RowGeometry, unit: float) -> sp.csc_matrix:
        return _matrix(rows, geo, n, d, unit)[:, cols].tocsc()

    if len(rows) != len(cols):
        return reject(f"network has {len(rows)} backbone rows for {len(cols)} unknowns", 0)
    e_g = np.zeros(len(cols))
    e_g[-1] = 1.0
    geo = _row_geometry(rows, x, D, container.box)
    unit = float(D.mean())  # of the factorised matrix: z is in these units
    try:
        lu = sla.splu(matrix(geo, unit), permc_spec="COLAMD")
    except RuntimeError as exc:  # exactly singular basis
        return reject(f"singular network matrix ({exc})", 0)
    mu = lu.solve(e_g, trans="T")
    if not _positive(mu):
        return reject(f"{_n_not_positive(mu)} network force(s) not positive at the LP's configuration", 0)
    last_move = move = np.inf
    for k in range(1, NEWTON_MAX_STEPS + 1):
        if move > NEWTON_CONTRACTION * last_move:
            unit = float(D.mean())
            try:
                lu = sla.splu(matrix(geo, unit), permc_spec="COLAMD")
            except RuntimeError as exc:
                return reject(f"singular network matrix ({exc})", k)
        last_move = move
        z = lu.solve(geo.rhs)
        u = np.zeros(n * d)
        u[cols[:-1]] = z[:-1]
        u = u.reshape(n, d)
        g = float(z[-1])
        ref = u[stable].mean(axis=0) if container.has_translation else np.zeros(d)
        move = float(np.linalg.norm(u[stable] - ref, axis=1).max())
        if not (np.isfinite(move) and move <= NEWTON_MAX_MOVE and g > -1.0):
            return reject(f"Newton step {k} moves a particle by {move:.3g} mean diameters", k)
        x = container.wrap(x + u * unit)
        D = D * np.sqrt(1.0 + g)
        geo = _row_geometry(rows, x, D, container.box)
        if (g / (1.0 + np.sqrt(1.0 + g)) < opt.tol_gamma and move < opt.tol_s
                and np.abs(geo.rhs).max() <= NEWTON_GAP_TOL):
            break
    else:
        return reject(f"Newton did not converge in {NEWTON_MAX_STEPS} steps", NEWTON_MAX_STEPS)
    # certificate: forces from the transposed system at the finished configuration
    # (rattlers are not in it: they are freed only once the forces pass, which spares
    # the all-pairs sweeps to the rejected attempts)
    mu = _transposed_solve(lu, matrix(geo, float(D.mean())), e_g)
    if not _positive(mu):
        return reject(f"{_n_not_positive(mu)} network force(s) not positive", k)
    x = _free_rattlers(x, D, step.rattler, container, packing)
    p = container.packing(packing, x, D)
    ov = container.max_overlap(p)
    if ov > OVERLAP_TOL:
        return reject(f"overlap {ov:.3g} (relative) > {OVERLAP_TOL:g}", k)
    P = rows.n_pairs
    contacts = np.stack([rows.i, rows.j], axis=1)
    f_pair, f_wall = mu[:P] / geo.sig, mu[P:] / geo.rad
    resid = _balance_residual(x, container, contacts, f_pair, rows.wall_particle, rows.wall_face, f_wall, d, n)
    net = _Network(contacts, rows.wall_particle, rows.wall_face, f_pair, f_wall, step.rattler, len(rows),
                   step.n_s, True, force_balance_residual=float(resid.max(initial=0.0)),
                   residual_stable=float(resid[stable].max(initial=0.0)))
    geo_c, geo_wp, geo_wf = container.touching(p)
    if not _same_backbone(net, geo_c, geo_wp, geo_wf, find_rattlers(n, d, geo_c, geo_wp)):
        return reject("the geometric network has another backbone", k)
    return _NewtonAttempt(True, "ok", k, time.perf_counter() - t0, float(mu.min() / mu.max())), x, D, net


def _free_rattlers(x: NDArray[np.float64], D: NDArray[np.float64], rattler: NDArray[np.bool_],
                   container: _Container, packing: Packing) -> NDArray[np.float64]:
    """Push rattlers off the neighbours the Newton finish grew into.

    The finish moves only the stable particles; a rattler that rested on a neighbour
    at the last LP (gap ~0, zero dual) overlaps it by about the growth, ~1e-9, where the
    LP chain's next LP would have moved it. Each overlapping rattler moves away along
    the pair direction by twice the overlap (a pair of rattlers shares the move), for
    up to :data:`RATTLER_PUSHES` sweeps. A rattler wedged between neighbours on
    opposite sides can have its overlaps amplified by these sweeps (at N = 4096 a cage
    turned 6e-13 into 3.6e-7), so the sweep with the smallest largest rattler overlap,
    the input included, is returned: freeing never makes an overlap worse. What
    remains is caught by the certificate's overlap check.
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
        len(chain.records) + 1, float(D[0] / chain.D[0] - 1.0), float(rel.max()), float(rel[stable].max()),
        net.n_c, net.n_c, net.n_s, True, "Certified", attempt.seconds, "newton", lp.ell / lp.sig_max, np.inf,
        attempt.min_dual, np.nan, True, newton_steps=attempt.steps)


def _record(chain: _Chain, progress, rec: IterationRecord) -> None:
    chain.records.append(rec)
    if progress:
        progress(rec)


def calippso(
    packing: Packing,
    *,
    tol_s: float = DEFAULT_TOL_S,
    tol_gamma: float = DEFAULT_TOL_GAMMA,
    solver: str = DEFAULT_SOLVER,
    solver_tol: float = SOLVER_TOL,
    cutoff: float = DEFAULT_CUTOFF,
    cutoff_near: float = DEFAULT_CUTOFF_NEAR,
    bound: tuple[tuple[float, float], ...] = DEFAULT_BOUND_SCHEDULE,
    relax: float | None = None,
    walls: bool = False,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    require_isostatic: bool = True,
    threads: int = 1,
    finish: str = DEFAULT_FINISH,
    interior: str = DEFAULT_INTERIOR,
    progress: Callable[[IterationRecord], None] | None = None,
) -> CalippsoResult:
    """Jam ``packing`` by CALiPPSO (Algorithm 1), see the module docstring.

    Parameters
    ----------
    packing : Packing
        Non-overlapping start (relative overlap at most ``OVERLAP_TOL``); periodic, or
        with ``walls=True`` an orthogonal box whose faces are hard walls and every
        sphere inside (``sigma_i / 2 <= x_{i,mu} <= L_mu - sigma_i / 2``).
    tol_s : float
        Convergence: largest displacement of a stable particle in the last LP
        [mean diameters].
    tol_gamma : float
        Convergence: ``sqrt(Gamma*) - 1`` of the last LP (dimensionless).
    solver : {"ipm", "simplex", "hybrid", "ipm-center"}
        See :data:`SOLVERS`.
    solver_tol : float
        HiGHS primal/dual feasibility and interior point optimality tolerance, in
        units of the scaled rows (~2x relative gap), between :data:`MIN_SOLVER_TOL`
        and :data:`MAX_SOLVER_TOL`.
    cutoff : float
        Neighbour cutoff ``ell`` [current largest diameters] far from jamming, > 1.2.
    cutoff_near : float
        Cutoff in the last bound phase, for unbounded LPs and for every LP of a start
        near jamming (:data:`NEAR_START_GAP`) [current largest diameters].
    bound : tuple of (threshold, bound)
        Bound schedule: below each ``sqrt(Gamma*) - 1`` threshold the displacement
        bound (per coordinate) becomes ``bound`` mean radii; above the first threshold
        it is derived from the cutoff. The converging LP is always unbounded.
    relax : float or None
        Sec. IV relaxation ``sigma <- sqrt(1 + c g*) sigma`` with ``c = relax`` in (0, 1].
    walls : bool
        Hard walls on the box faces instead of periodic boundaries. A packing whose
        boundary is already walls (body kind ``walls``, e.g. ``init --walls``) is always
        jammed between them.
    max_iterations : int
        Largest number of LPs.
    require_isostatic : bool
        Raise when the converged network is neither isostatic nor the App. A
        hyperstatic case; False returns it with ``converged`` and the flags set.
    threads : int
        HiGHS threads.
    finish : {"newton", "lp"}
        How the chain ends, see :data:`FINISHES`.
    interior : {"ipx", "hipo"}
        HiGHS interior point method of the interior point LPs, see :data:`INTERIOR_POINTS`.
    progress : callable, optional
        Called with each :class:`IterationRecord`.

    Returns
    -------
    CalippsoResult

    Raises
    ------
    ValueError
        Bad input (overlaps, walls crossing particles, bad options).
    RuntimeError
        The chain did not converge, or the converged network failed its checks after
        the recoveries.
    """
    require("calippso", packing.body_kind)
    walls = walls or packing.body_kind == "walls"
    _check_options(packing, tol_s, tol_gamma, solver, min(cutoff, cutoff_near), bound, relax, walls, max_iterations)
    if not (MIN_SOLVER_TOL <= solver_tol <= MAX_SOLVER_TOL):
        raise ValueError(f"solver_tol must lie in [{MIN_SOLVER_TOL:g}, {MAX_SOLVER_TOL:g}], got {solver_tol}")
    t_start = time.perf_counter()
    d, n = packing.d, packing.n
    container = _Container(packing.box, walls)
    if finish not in FINISHES:
        raise ValueError(f"unknown finish {finish!r}; choose one of {', '.join(FINISHES)}")
    opt = _Options(tol_s, tol_gamma, solver, cutoff, cutoff_near, bound, relax, require_isostatic, finish)
    chain = _Chain(x=packing.position.copy() if walls else packing.box.wrap(packing.position),
                   D=packing.diameter.copy())
    solver_obj = _Solver(threads, solver_tol, interior)
    solver_obj.cold_simplex_as_ipm = solver == "hybrid"  # a cold simplex is slower than ipm
    chain.near_start = _near_start(chain.x, chain.D, container)
    if chain.near_start:
        solver_obj.ipm_presolve = NEAR_START_PRESOLVE
    network: _Network | None = None
    converged = False
    for it in range(1, max_iterations + 1):
        lp = _set_up_lp(chain, container, opt, d, n)
        sol = solver_obj.solve(lp.A, lp.geo.rhs, lp.col_lower, lp.col_upper, lp.method, lp.rows)  # line 8
        counts = dict(warm_start=sol.warm, simplex_iterations=sol.simplex_iterations,
                      ipm_iterations=sol.ipm_iterations)
        if sol.col is None:
            _record(chain, progress, IterationRecord(
                it, np.nan, np.nan, np.nan, len(lp.rows), 0, 0, False, sol.status, sol.seconds, sol.method,
                lp.ell / lp.sig_max, lp.bound, np.nan, np.nan, False, **counts))
            _recover(chain, f"LP status {sol.status!r}")
            continue
        step = _read_solution(lp, sol.col, sol.dual, container, d, n)
        # the update must not create an overlap among ALL pairs (and walls)
        ov = container.max_overlap(container.packing(
            packing, chain.x + step.u * lp.unit, chain.D * _growth(step.g, relax)))
        accepted = ov <= OVERLAP_TOL
        _record(chain, progress, IterationRecord(
            it, step.sg, step.max_s, step.max_s_stable, len(lp.rows), step.n_c, step.n_s, step.iso, sol.status,
            sol.seconds, sol.method, lp.ell / lp.sig_max, lp.bound, step.min_active_dual, step.max_inactive_dual,
            accepted, **counts))
        if not accepted:
            _recover(chain, f"update overlaps by {ov:.3g} (relative)")
            continue
        _update(chain, step, lp, opt, container, n)
        if opt.finish == "newton" and _newton_ready(chain, step, lp, n):
            attempt, x, D, net = _newton_finish(chain, step, lp, opt, container, packing)
            if attempt.certified:
                ok, why = _final_checks(packing, x, D, container, net)
                if ok:
                    chain.newton.append(attempt)
                    _record(chain, progress, _newton_record(chain, container, net, attempt, x, D, lp))
                    chain.x, chain.D, network, converged = x, D, net, True
                    break
                attempt = replace(attempt, certified=False, reason=f"final checks: {why}")
            chain.newton.append(attempt)
            chain.newton_tried = chain.backbone_key
        if _small(step, opt) and np.isinf(lp.bound):
            network = _dual_network(step, lp, chain.x, container, d, n)
            converged, network.why = _final_checks(packing, chain.x, chain.D, container, network)
            if converged or not require_isostatic or chain.final_attempts >= 2:
                break
            _final_recovery(chain)
            continue
        _schedule_next(chain, step, lp, opt)
    total = time.perf_counter() - t_start
    history = _history(chain.records)
    if network is None:
        raise RuntimeError(_diagnose(f"not converged in {max_iterations} LPs", chain.records))
    if not converged and require_isostatic:
        raise RuntimeError(_diagnose(f"converged LP failed the final checks: {network.why}", chain.records))
    return _result(packing, chain.x, chain.D, container, network, chain, history, converged, total, dict(
        finish=finish, interior=interior, tol_s=tol_s, tol_gamma=tol_gamma, solver=solver, solver_tol=solver_tol, cutoff=cutoff, cutoff_near=cutoff_near, bound=[list(b) for b in bound],
        relax=relax, walls=walls, max_iterations=max_iterations, threads=threads))


def _stalled(records: list[IterationRecord], start: int) -> bool:
    """No progress: the smallest ``sqrt(Gamma*) - 1`` of the last :data:`STALL_WINDOW`
    accepted LPs is above :data:`STALL_PROGRESS` times the smallest before them
    (only LPs from index ``start`` on count)."""
    sg = [r.sqrt_gamma_minus_1 for r in records[start:] if r.accepted]
    if len(sg) <= STALL_WINDOW:
        return False
    return min(sg[-STALL_WINDOW:]) > STALL_PROGRESS * min(sg[:-STALL_WINDOW])


def _method(solver: str, records: list[IterationRecord], bounded: bool) -> str:
    if solver == "ipm-center":
        return "ipm-nox" if bounded else "ipm"
    if solver == "hybrid":
        accepted = [r for r in records if r.accepted]
        if accepted and accepted[-1].sqrt_gamma_minus_1 <= HYBRID_SWITCH:
            return "simplex"
        return "ipm"
    return solver


def _moved(rows: _Rows, x: NDArray[np.float64], container: _Container, rattler: NDArray[np.bool_] | None) -> float:
    """Largest displacement since the rows were built [length]; a rattler of the last
    LP counts with a tenth of its displacement (it roams its cage; an overlap it
    might cause with an unlisted pair is caught by the all-pairs check)."""
    dxs = container.displacement(x - rows.x_build)
    m = np.sqrt(np.einsum("ij,ij->i", dxs, dxs))
    if rattler is not None:
        m[rattler] *= 0.1
    return float(m.max())


# --- the converged network and its checks -----------------------------------------------------


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
    return _Network(step.contacts, step.wall_particles, faces, f_pair, f_wall, step.rattler, step.n_c, step.n_s,
                    step.iso, force_balance_residual=float(resid.max(initial=0.0)),
                    residual_stable=float(resid[stable].max(initial=0.0)))


def _balance_residual(x, container: _Container, c, f_pair, wp, faces, f_wall, d: int, n: int) -> NDArray[np.float64]:
    """Per-particle net contact force over the mean force, (N,), directions on ``x``."""
    dxc = container.box.minimum_image(x[c[:, 1]] - x[c[:, 0]]) if len(c) else np.empty((0, d))
    nij = dxc / np.linalg.norm(dxc, axis=1)[:, None] if len(c) else dxc
    net = np.zeros((n, d))
    np.add.at(net, c[:, 0], -f_pair[:, None] * nij)
    np.add.at(net, c[:, 1], f_pair[:, None] * nij)
    push = np.where(faces % 2 == _LOWER, 1.0, -1.0) * f_wall
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
    key_wall = {k: v for k, v in zip((net.wall_particles * 64 + net.wall_faces).tolist(), net.f_wall.tolist())}
    fp = [key_pair.get(k, 0.0) for k in (geo_c @ [n, 1]).tolist()]
    fw = [key_wall.get(k, 0.0) for k in (geo_wp * 64 + geo_wf).tolist()]
    return np.array(fp + fw, dtype=np.float64)


_COUNTS = ("n_constraints", "n_contacts", "n_stable", "simplex_iterations", "ipm_iterations", "newton_steps")


def _history(records: list[IterationRecord]) -> xr.Dataset:
    def col(name):
        return np.array([getattr(r, name) for r in records])

    spec = {
        "sqrt_gamma_minus_1": ("1", "sqrt(Gamma*) - 1 of the LP"),
        "max_displacement": ("1", "largest displacement relative to the stable mean [mean diameters]"),
        "max_displacement_stable": ("1", "largest displacement of a stable particle [mean diameters]"),
        "n_constraints": ("1", "LP rows (pairs within the cutoff, plus wall rows)"),
        "n_contacts": ("1", "contacts (active duals) of the backbone"),
        "n_stable": ("1", "stable (non-rattler) particles"),
        "simplex_iterations": ("1", "simplex pivots of the LP (crossover pivots included)"),
        "ipm_iterations": ("1", "interior point iterations of the LP"),
        "newton_steps": ("1", "Newton steps of the certified finish (0 for an LP)"),
        "lp_time": ("s", "LP (or Newton finish) wall time"),
        "cutoff": ("1", "neighbour cutoff [largest diameters]"),
        "bound": ("1", "displacement bound per coordinate [mean diameters]; inf = none"),
        "min_active_dual": ("1", "smallest active dual / largest dual"),
        "max_inactive_dual": ("1", "largest inactive dual / largest dual"),
    }
    data = {k: (("iteration",), col(k).astype(np.int64 if k in _COUNTS else float),
                {"units": u, "long_name": ln}) for k, (u, ln) in spec.items()}
    data["isostatic"] = (("iteration",), col("isostatic").astype(np.int8), {"units": "1", "long_name": "N_c == isostatic count after the LP (1 = yes)"})
    data["accepted"] = (("iteration",), col("accepted").astype(np.int8), {"units": "1", "long_name": "update accepted (0 = undone by a recovery)"})
    data["warm_start"] = (("iteration",), col("warm_start").astype(np.int8), {"units": "1", "long_name": "simplex warm-started from the previous basis (1 = yes)"})
    data["lp_status"] = (("iteration",), col("lp_status").astype(str), {"long_name": "HiGHS model status"})
    data["solver"] = (("iteration",), col("solver").astype(str), {"long_name": "HiGHS method of the LP"})
    return xr.Dataset(data, coords={"iteration": np.arange(1, len(records) + 1)})


def _diagnose(message: str, records: list[IterationRecord]) -> str:
    tail = records[-3:]
    info = "; ".join(
        f"LP {r.iteration}: {r.lp_status}, sqrtG-1={r.sqrt_gamma_minus_1:.3g}, max|s|={r.max_displacement_stable:.3g}, "
        f"Nc={r.n_contacts}, Ns={r.n_stable}, iso={int(r.isostatic)}, cutoff={r.cutoff:.3g}, bound={r.bound:.3g}"
        for r in tail
    )
    return f"CALiPPSO failed: {message} [{info}]"


def _result(packing, x, D, container: _Container, net: _Network, chain: _Chain, history, converged, total,
            settings) -> CalippsoResult:
    records = chain.records
    newton = chain.newton
    p = container.packing(packing, x, D)
    ov_rel = container.max_overlap(p)
    n_rattlers = int(net.rattler.sum())
    attrs = dict(packing.attrs)
    attrs.update(
        phi_J=p.packing_fraction,
        phi_initial=packing.packing_fraction,
        iterations=len(records),
        converged=int(converged),
        n_contacts=int(net.n_c),
        n_stable=int(net.n_s),
        n_rattlers=n_rattlers,
        isostatic_count=int(net.isostatic_count),
        isostatic=int(net.iso),
        hyperstatic=int(net.hyperstatic),
        isostatic_appendix_a=int(net.isostatic_appendix_a),
        n_contacts_with_rattlers=int(net.n_contacts_with_rattlers),
        n_force_bearing_rattlers=int(net.n_force_bearing_rattlers),
        force_balance_residual=float(net.force_balance_residual),
        max_overlap=float(ov_rel),
        dual_not_geometric=int(net.dual_not_geometric),
        geometric_not_dual=int(net.geometric_not_dual),
        n_contacts_geometric=int(net.n_contacts_geometric),
        n_stable_geometric=int(net.n_stable_geometric),
        contact_gap_tol=CONTACT_GAP_TOL,
        n_contacts_dual=int(net.n_contacts_dual),
        n_rattlers_dual=int(net.n_rattlers_dual),
        force_assignment=net.force_assignment,
        force_assignment_comment=FORCE_ASSIGNMENTS[net.force_assignment]
        + net.force_assignment_note,
        n_zero_force_contacts=int(np.sum(net.f_pair <= 0.0) + np.sum(net.f_wall <= 0.0)),
        boundary="walls" if container.walls else "periodic",
        finish="newton" if any(a.certified for a in newton) else "lp",
        n_lps=sum(r.solver != "newton" for r in records),
        near_start=int(chain.near_start),
        newton_attempts=len(newton),
        newton_rejections=sum(not a.certified for a in newton),
        newton_last_rejection=next((a.reason for a in reversed(newton) if not a.certified), "none"),
        newton_time=float(sum(a.seconds for a in newton)),
        force_unit="CALiPPSO dual scaling (paper Eq. 11): f = lambda sigma_ij [1/length], sum_c f_c sigma_c = 1",
        total_time=total,
        peak_memory=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0,
        lp_time_total=float(np.nansum(history["lp_time"].values)),
    )
    if container.walls:
        attrs["walls"] = "hard walls on every face of the orthogonal box [0, L_mu]; wall contacts in wall_contact_*"
    out = Packing(
        position=p.position,
        diameter=D,
        box=packing.box,
        contacts=net.contacts,
        force=net.f_pair,
        rattler=net.rattler,
        pressure=None,
        protocol=f"{packing.protocol}>calippso",
        seed=packing.seed,
        parameters=settings,
        attrs=attrs,
    )
    wc = np.stack([net.wall_particles, net.wall_faces], axis=1).astype(np.int64)
    diag = {k: attrs[k] for k in ("phi_J", "n_contacts", "n_stable", "isostatic_count", "isostatic", "hyperstatic",
                                  "force_balance_residual", "max_overlap", "total_time", "peak_memory")}
    diag["residual_stable"] = net.residual_stable
    diag["why"] = net.why
    return CalippsoResult(out, history, converged, len(records), wc, net.f_wall, diag)


def _check_options(packing, tol_s, tol_gamma, solver, cutoff, bound, relax, walls, max_iterations) -> None:
    if not isinstance(packing, Packing):
        raise ValueError(f"calippso needs a Packing, got {type(packing).__name__}")
    if not (np.isfinite(tol_s) and tol_s > 0):
        raise ValueError(f"tol_s must be positive and finite, got {tol_s}")
    if not (np.isfinite(tol_gamma) and tol_gamma > 0):
        raise ValueError(f"tol_gamma must be positive and finite, got {tol_gamma}")
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    if not (np.isfinite(cutoff) and cutoff > FAR_GROWTH):
        raise ValueError(f"cutoff must exceed {FAR_GROWTH} largest diameters, got {cutoff}")
    th = [t for t, _ in bound]
    if any(not (np.isfinite(v) and v > 0) for pair in bound for v in pair) or th != sorted(th, reverse=True):
        raise ValueError(f"bound schedule must be positive (threshold, bound) pairs with decreasing thresholds, got {bound}")
    if relax is not None and not (0.0 < relax <= 1.0):
        raise ValueError(f"relax must lie in (0, 1], got {relax}")
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be >= 1, got {max_iterations}")
    if packing.n < 2:
        raise ValueError("CALiPPSO needs at least two particles")
    if walls:
        if not packing.box.is_orthogonal:
            raise ValueError("walls need an orthogonal box")
        rad = 0.5 * packing.diameter[:, None]
        L = packing.box.lengths
        out = (packing.position < rad * (1 - OVERLAP_TOL)) | (packing.position > L - rad * (1 - OVERLAP_TOL))
        if np.any(out):
            bad = np.flatnonzero(out.any(axis=1))
            raise ValueError(f"{bad.size} sphere(s) cross a wall (e.g. index {bad[0]}); walls need every sphere inside the box")
    container = _Container(packing.box, walls)
    ov = container.max_overlap(container.packing(packing, packing.position, packing.diameter))
    if ov > OVERLAP_TOL:
        raise ValueError(f"input overlaps by {ov:.3g} (relative) > {OVERLAP_TOL:g}: CALiPPSO needs a hard-sphere start")


def result_to_dataset(result: CalippsoResult, stage_parameters: dict[str, Any] | None = None) -> xr.Dataset:
    """The jammed packing (``Packing.to_dataset``) plus the history on ``iteration``.

    Wall contacts (``walls=True``) are stored as ``wall_contact_particle``,
    ``wall_contact_face`` (``2 * axis + 0 lower / 1 upper``) and ``wall_force`` on the
    dimension ``wall_contact``; ``jamflow.io.read_packing`` ignores them.
    """
    ds = result.packing.to_dataset(stage_parameters)
    for name in result.history.data_vars:
        ds[name] = result.history[name]
    ds = ds.assign_coords(iteration=result.history["iteration"].values)
    if len(result.wall_contacts) or result.packing.attrs.get("boundary") == "walls":
        ds["wall_contact_particle"] = (("wall_contact",), result.wall_contacts[:, 0], {"units": "1", "long_name": "particle of a wall contact"})
        ds["wall_contact_face"] = (("wall_contact",), result.wall_contacts[:, 1], {"units": "1", "long_name": "wall face: 2*axis + (0 lower at 0, 1 upper at L)"})
        ds["wall_force"] = (("wall_contact",), result.wall_force, {"units": "1", "long_name": "wall contact force (paper Eq. 11 scaling)"})
    ds.attrs["converged"] = int(result.converged)
    ds.attrs["iterations"] = int(result.iterations)
    return ds
