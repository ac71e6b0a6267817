"""Default numerical tolerances, in one place, each with its meaning.

Gaps and overlaps are *relative*: for a pair at distance ``r`` with contact
distance ``sigma_ij = (D_i + D_j) / 2`` the gap is ``h = r / sigma_ij - 1``
(CALiPPSO paper, App. D) and the overlap is ``-h`` when positive.
"""

#: Largest relative overlap ``(sigma_ij - r) / sigma_ij`` accepted for a hard-sphere
#: packing when it is read or checked. LP-based jamming leaves overlaps of the order
#: of the solver's primal feasibility tolerance times the step bound (~1e-9); 1e-8
#: leaves a margin of ten and still flags any genuine interpenetration.
OVERLAP_TOL: float = 1e-8

#: Relative gap below which a pair counts as a contact when a packing carries no
#: explicit contact list. Suits packings from LP jamming or LS at pressures above
#: ~1e8; LS snapshots at lower pressure need a larger, explicitly stated value.
#: CALiPPSO's geometric contact network (compared with its dual contacts, and stored
#: for degenerate, hyperstatic packings) uses it too: contacts there sit at gaps of
#: ~1e-15 (at most ~solver_tol / 2 <= OVERLAP_TOL); the closest pair of non-rattlers
#: without a dual in the jammed d = 3 LS example is at 1.4e-7.
CONTACT_GAP_TOL: float = 1e-8

#: Histograms of distances (g(r)): a value within this relative distance of a bin edge
#: counts in the bin above the edge. Contacts sit on their contact distance to
#: :data:`CONTACT_GAP_TOL` (and round-off ~1e-15), so a contact distance on an edge (the
#: small-large contacts of a 1:1.4 mixture at r = 1 mean diameter) never straddles it
#: under a rigid shift or a relabelling; the same holds for lattice distances of crystals.
BIN_EDGE_RTOL: float = CONTACT_GAP_TOL

#: Position tolerance in fractional coordinates when checking that particles lie
#: inside the primary cell (absorbs round-off of wrapping).
INSIDE_BOX_TOL: float = 1e-12

#: Relative force-balance residual ``|sum_c f_c n_c| / <|f|>`` regarded as zero.
FORCE_BALANCE_TOL: float = 1e-8

#: Relative tolerance of the overdamped rewiring procedure (Lerner et al., Sec. IV B):
#: a contact force below ``-REWIRE_REL_TOL * max|f|`` counts as negative and a pair
#: rate below ``-REWIRE_REL_TOL * (velocity scale)`` as approaching. Sparse LU solves
#: of ``N f = b`` are accurate to ~1e-13 relative away from jamming; 1e-9 keeps
#: round-off from flipping signs while resolving any physical sign change.
REWIRE_REL_TOL: float = 1e-9

#: Largest relative constraint error ``|r_ij - sigma_ij| / sigma_ij`` of a contact in
#: the overdamped event-driven dynamics before the drift correction (Sec. IV C) is
#: applied regardless of its schedule; errors per step are O(dt^2).
CONTACT_DRIFT_TOL: float = 1e-7

#: Jamming certificate (``strict_jamming``): a particle moves in an LP solution when
#: its displacement relative to the median one exceeds this many mean diameters.
#: LP displacements are bounded by one mean diameter and solved to a feasibility
#: tolerance of 1e-9, so genuine unjamming motions are O(1) and noise is <~1e-8.
CERTIFY_MOTION_TOL: float = 1e-6

#: Roth-Whiteley decision of the certificate (:func:`jamflow.network.rigid_network`):
#: the Jacobian of an isostatic network counts as having full column rank when the
#: smallest pivot of the sparse LU of ``J^T J`` exceeds this fraction of the largest.
#: A floppy mode leaves a pivot at round-off (~1e-16 relative); a rigid but
#: ill-conditioned network (condition number of J above ~1e6) falls back to the LPs.
RIGID_PIVOT_RTOL: float = 1e-12

#: Roth-Whiteley decision: the self stress counts as strictly positive when its
#: smallest entry exceeds this fraction of its largest (and its residual
#: ``|J^T lambda| / (|J|_1 |lambda|)`` is below the same number); closer calls go to the LPs.
SELF_STRESS_POSITIVE_RTOL: float = 1e-8

#: Gap-aware jamming certificate: an LP solution whose largest coordinate is within
#: this (relative) distance of the displacement bound of one mean diameter counts as
#: reaching the bound, i.e. as a possible unjamming motion to be checked exactly.
CERTIFY_BOUND_TOL: float = 1e-6

#: Force balance of soft-sphere packings: largest per-particle force norm
#: ``max_i |F_i|`` in units of ``epsilon / <D>`` (mean diameter). VanderWerf et al.
#: ask for ``F_i^2 < 1e-25`` (``|F_i| < 3.2e-13``); 1e-13 meets it with a factor ten
#: in ``F^2`` to spare, above the float64 floor of ~1e-14
#: (measured: docs/notes/soft-constants.md#soft_force_tol).
SOFT_FORCE_TOL: float = 1e-13

#: Default ``max_i |F_i|`` [epsilon / <D>] at which a single soft-sphere minimisation
#: (FIRE, CG, enthalpy, one AQS strain step) counts as converged: ten times the
#: protocol tolerance :data:`SOFT_FORCE_TOL`, since an intermediate minimum is
#: refined again by the next step of its protocol.
MINIMIZE_FORCE_TOL: float = 1e-12

#: Relative tolerance on diameter ratios when deciding that two packings hold the
#: same particles (the contact overlap Q): jamming one sample from different target
#: pressures rescales every diameter by one common factor.
DIAMETER_RATIO_RTOL: float = 1e-8

#: Relative diameter difference below which two particles belong to one size class
#: (``jamflow export-xyz`` particle types). Every stage scales all diameters by one
#: common factor, so the classes of a mono- or bidisperse packing stay exact to rounding.
SIZE_CLASS_RTOL: float = 1e-8

#: Relative rounding of single precision (float32 machine epsilon, 2^-23): freud stores
#: boxes and points in float32, so lengths exchanged with freud agree to this relative
#: accuracy (per coordinate; a distance between two points to a few times it).
FLOAT32_RTOL: float = 2.0**-23

#: Linked spheres (holonomic links, soft-chains paper Sec. II C): largest relative
#: link-length error ``|r_ij - l_ij| / l_ij`` that Newton re-affixing (Eq. 7) leaves
#: after every position update of a minimiser. Newton converges quadratically, so a
#: sweep ends one or two iterations above the float64 floor of pair vectors
#: (~L 2^-53, i.e. ~1e-14 for box sides L ~ 30 link lengths); 1e-13 sits above that
#: floor and far below any physical tolerance.
LINK_LENGTH_RTOL: float = 1e-13

#: A cluster's link Jacobian counts as degenerate (redundant links, e.g. both
#: diagonals of a rigid square in 2D, or a straight rigid chain) when its smallest
#: QR diagonal ``|R_kk|`` falls below this fraction of the largest: the constraint
#: basis would then carry a direction set by round-off. Unit link directions give
#: ``|R_kk| ~ 1``; 1e-8 keeps projections accurate to ~1e-8 relative at worst.
LINK_RANK_RTOL: float = 1e-8

#: Entangled linked packings (:mod:`jamflow.chains.entanglement`): a pair of spheres that
#: are not linked counts as trapped (links of soft spheres passed through each other
#: during a minimisation from an overlapping start) when its relative overlap exceeds
#: this bound *and* its force exceeds :data:`ENTANGLED_FORCE_RATIO` times the pressure's
#: force scale. Onset overlaps are of the order of P0, threaded links hold overlaps of
#: 0.16-0.45 diameters (measured: docs/notes/chains.md#entanglement-thresholds).
ENTANGLED_OVERLAP: float = 0.1

#: Largest ratio of a contact force to the pressure's force scale ``f_P = d V P / sum_c r_c``
#: (the mean contact force if the pressure P, contacts and link tensions together, were
#: carried by the contacts alone) before a pair counts as trapped (with
#: :data:`ENTANGLED_OVERLAP`): a factor ten above the largest ratio of jammed packings and
#: below that of entangled ones (measured: docs/notes/chains.md#entanglement-thresholds).
ENTANGLED_FORCE_RATIO: float = 100.0

#: Rattling clusters (:mod:`jamflow.network.bodies`): a singular value of a cluster's
#: orthonormal motion basis restricted to its contact-bearing spheres below this counts
#: as zero, i.e. as a free motion that moves no contact-bearing sphere (a swinging
#: trimer, a dangler, a rotator). A free motion leaves a singular value at round-off
#: (~1e-16); a held motion moves the contact-bearing spheres by a fraction of its norm
#: set by the geometry (sines of bond angles, which the link-degeneracy test keeps above
#: :data:`LINK_RANK_RTOL`), so the same 1e-8 separates the two.
BODY_FREE_RTOL: float = 1e-8
#: Sliders (:func:`jamflow.network.find_sliders`): a body's translation ``t`` is free
#: when the matrix of its contacts' unit normals has its smallest singular value
#: ``sqrt(sum_c (n_c . t)^2)`` at most this fraction of the largest. The stiffness
#: along ``t``, ``k sum_c (n_c . t)^2``, is then at most 1e-12 of the body's stiffest
#: translation: the dynamical matrix's zero-mode floor (1e-13 of its largest
#: eigenvalue, ~10 k) in the shapes' spectrum. Measured on 64 circulo-lines
#: (A = 1.1, P0 = 1e-9, three seeds): 1e-17 ... 1e-16 for every sliding body, 0.28 and
#: above for every other (docs/notes/shapes.md, "Sliders").
SLIDER_RTOL: float = 1e-6
