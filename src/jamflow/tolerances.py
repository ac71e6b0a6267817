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
CONTACT_GAP_TOL: float = 1e-8

#: Position tolerance in fractional coordinates when checking that particles lie
#: inside the primary cell (absorbs round-off of wrapping).
INSIDE_BOX_TOL: float = 1e-12

#: Relative force-balance residual ``|sum_c f_c n_c| / <|f|>`` regarded as zero.
FORCE_BALANCE_TOL: float = 1e-8
