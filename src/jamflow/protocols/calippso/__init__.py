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
:func:`jamflow.network.spheres.find_rattlers`), and the forces are the
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
LP safe with any cutoff; measured: docs/notes/calippso-constants.md#near_start_gap),
and solves its interior point LPs without HiGHS presolve, whose vertex is the better
warm start (:data:`NEAR_START_PRESOLVE`).

An interior point LP with crossover is solved by IPX as it is, or by HiPO as its
explicit dual (:mod:`~jamflow.protocols.calippso.dual`; ``interior``, default ``auto``:
HiPO from :data:`HIPO_MIN_COLUMNS` columns on). The primal's normal equations are dense
(``g``'s column touches every row); the dual's have the contact network's sparsity.
The dual's answer is read back as the LP's columns, forces and vertex basis; trouble
there (a status other than optimal, a basis that maps to no primal vertex basis) is
re-solved by IPX, recorded per LP in ``interior`` and counted in ``interior_fallbacks``.

Newton finish
-------------
In the tail the chain fine-tunes positions of a network that no longer changes. With
``finish="newton"`` (opt-in), after every accepted LP with ``sqrt(Gamma*) - 1 <=``
:data:`NEWTON_FROM` whose network is isostatic, the square system "every backbone
contact touches, one inflation factor" (the network rows of the LP as equalities over
the stable particles' coordinates and ``g``; the LP's basis matrix) is solved by
Newton's method with a sparse LU, kept over chord steps while they converge fast
(:mod:`~jamflow.protocols.calippso.newton`). A network whose forces at the LP's configuration are not all
positive is rejected before any step (the next LP, started from its basis, would not
be dual feasible). The result is kept only under a certificate that it is the LP
chain's limit: the forces of the transposed system at the finished configuration are
all positive, no pair overlaps beyond :data:`~jamflow.tolerances.OVERLAP_TOL` and the
geometric network has the same backbone; then ``s = 0, Gamma = 1`` solves the next
LP. Otherwise the chain goes on with LPs. Rattlers are not part of the system; those
the finish's growth pressed into a neighbour are pushed off it first. The finish is one history entry with solver ``newton``;
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
(no halving of ``sqrt(Gamma*) - 1`` in :data:`STALL_WINDOW` LPs)
gets an unbounded LP with fresh rows; after :data:`MAX_STALL_RECOVERIES` stalls, or at
``max_iterations``, the chain stops with the same kind of error.

Modules
-------
``chain`` (:func:`calippso` and the loop of Algorithm 1), ``steps`` (its lines: set-up,
solution, update, convergence; :func:`jamming_lp`), ``lp`` (rows, geometry, matrix,
bounds, :class:`JammingLP`), ``solver`` (HiGHS, and :mod:`jamflow.simplex` for the warm
simplex LPs, :data:`WARM_ENGINES`), ``crash`` (the first LP's crash basis, :data:`FIRST_LPS`), ``newton`` (the Newton finish),
``recovery`` (bound schedule, recoveries, stalls), ``network`` (the converged network
and its final checks), ``container`` (periodic box or walls), ``options`` (defaults and
checks), ``record`` (history, :class:`CalippsoResult`), ``state`` (what the chain carries).
"""

from .chain import calippso
from .checkpoint import CHECKPOINT_EVERY, ChainStopped
from .container import FACE_KEY_STRIDE, LOWER, UPPER
from .crash import CRASH_GAP
from .lp import CONTACT_DUAL_REL_TOL, FAR_GROWTH, MIN_CUTOFF, NEAR_START_GAP, JammingLP
from .newton import (
    NEWTON_CONTRACTION,
    NEWTON_FORCE_RESIDUAL,
    NEWTON_FROM,
    NEWTON_GAP_TOL,
    NEWTON_MAX_MOVE,
    NEWTON_MAX_STEPS,
    NEWTON_REFINEMENTS,
    RATTLER_PUSHES,
)
from .options import (
    CRASH_MIN_COLUMNS,
    DEFAULT_BOUND_SCHEDULE,
    DEFAULT_CUTOFF,
    DEFAULT_CUTOFF_NEAR,
    DEFAULT_FINISH,
    DEFAULT_FIRST_LP,
    DEFAULT_INTERIOR,
    DEFAULT_MAX_ITERATIONS,
    DEFAULT_SOLVER,
    DEFAULT_TOL_GAMMA,
    DEFAULT_TOL_S,
    DEFAULT_WARM_ENGINE,
    DUAL_FALLBACK,
    FINISHES,
    FIRST_LPS,
    HIPO_MIN_COLUMNS,
    INTERIOR_POINTS,
    MAX_SOLVER_TOL,
    MIN_SOLVER_TOL,
    SOLVER_TOL,
    SOLVERS,
    WARM_ENGINE_MIN_COLUMNS,
    WARM_ENGINES,
)
from .record import (
    DUAL_VERTEX,
    DUAL_VERTEX_ON_GEOMETRIC,
    FORCE_ASSIGNMENTS,
    START_ATTRS,
    CalippsoDiagnostics,
    CalippsoResult,
    IterationRecord,
    result_to_dataset,
)
from .recovery import (
    BOUND_ACTIVE_FRACTION,
    BOUND_SHRINK,
    CUTOFF_GROWTH,
    FINAL_RECOVERY_METHODS,
    MAX_RECOVERIES,
    MAX_STALL_RECOVERIES,
    STALL_PROGRESS,
    STALL_WINDOW,
    UNBOUND_FRACTION,
)
from .solver import (
    HYBRID_SWITCH,
    NEAR_START_PRESOLVE,
    WARM_PIVOTS_PER_ROW,
    WARM_SIMPLEX_SCALE,
)
from .steps import RATTLER_MOVE_WEIGHT, REUSE_FRACTION, jamming_lp

__all__ = [
    "BOUND_ACTIVE_FRACTION",
    "BOUND_SHRINK",
    "CHECKPOINT_EVERY",
    "CONTACT_DUAL_REL_TOL",
    "CUTOFF_GROWTH",
    "CalippsoDiagnostics",
    "CalippsoResult",
    "ChainStopped",
    "CRASH_GAP",
    "CRASH_MIN_COLUMNS",
    "DEFAULT_BOUND_SCHEDULE",
    "DEFAULT_CUTOFF",
    "DEFAULT_CUTOFF_NEAR",
    "DEFAULT_FINISH",
    "DEFAULT_FIRST_LP",
    "DEFAULT_INTERIOR",
    "DEFAULT_MAX_ITERATIONS",
    "DEFAULT_SOLVER",
    "DEFAULT_TOL_GAMMA",
    "DEFAULT_TOL_S",
    "DEFAULT_WARM_ENGINE",
    "DUAL_FALLBACK",
    "DUAL_VERTEX",
    "DUAL_VERTEX_ON_GEOMETRIC",
    "FACE_KEY_STRIDE",
    "FAR_GROWTH",
    "FINAL_RECOVERY_METHODS",
    "FINISHES",
    "FIRST_LPS",
    "FORCE_ASSIGNMENTS",
    "HYBRID_SWITCH",
    "HIPO_MIN_COLUMNS",
    "INTERIOR_POINTS",
    "IterationRecord",
    "JammingLP",
    "LOWER",
    "MAX_RECOVERIES",
    "MAX_SOLVER_TOL",
    "MAX_STALL_RECOVERIES",
    "MIN_CUTOFF",
    "MIN_SOLVER_TOL",
    "NEAR_START_GAP",
    "NEAR_START_PRESOLVE",
    "NEWTON_CONTRACTION",
    "NEWTON_FORCE_RESIDUAL",
    "NEWTON_FROM",
    "NEWTON_GAP_TOL",
    "NEWTON_MAX_MOVE",
    "NEWTON_MAX_STEPS",
    "NEWTON_REFINEMENTS",
    "RATTLER_MOVE_WEIGHT",
    "RATTLER_PUSHES",
    "REUSE_FRACTION",
    "SOLVERS",
    "SOLVER_TOL",
    "STALL_PROGRESS",
    "STALL_WINDOW",
    "START_ATTRS",
    "UNBOUND_FRACTION",
    "UPPER",
    "WARM_ENGINES",
    "WARM_ENGINE_MIN_COLUMNS",
    "WARM_PIVOTS_PER_ROW",
    "WARM_SIMPLEX_SCALE",
    "calippso",
    "jamming_lp",
    "result_to_dataset",
]
