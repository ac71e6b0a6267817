"""What a chain records: one entry per LP, the Newton finish attempts, the history
dataset, and the result (the jammed packing with its attributes, typed diagnostics)."""

from __future__ import annotations

import resource
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ...network.forces import MIN_NORM
from ...state.packing import Packing
from ...tolerances import CONTACT_GAP_TOL
from .options import DUAL_FALLBACK

if TYPE_CHECKING:
    from .container import _Container
    from .network import _Network
    from .state import _Chain

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

#: The start's attributes that a jammed packing keeps under another name: the packing
#: fraction and pressure of an LS snapshot describe the start, not the jammed packing.
START_ATTRS: dict[str, str] = {"phi": "phi_start", "p": "p_start"}


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
    engine: str = "highs"  # engine of the LP (highs or jamflow; interior point LPs are HiGHS's), or "newton"
    warm_fallback: str = ""  # the trouble jamflow.simplex reported before HiGHS solved the LP
    warm_lu: str = ""  # jamflow.simplex's LU library on this LP (pardiso, superlu; "+superlu": a PARDISO LU redone)
    interior: str = ""  # interior point of the LP: ipx, hipo, hipo-dual (HiPO on its dual), DUAL_FALLBACK + why


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


@dataclass(frozen=True)
class CalippsoDiagnostics:
    """Final checks of a :func:`~jamflow.protocols.calippso.calippso` result (the same
    numbers as the packing's attributes of these names, plus ``residual_stable`` and ``why``).

    Attributes
    ----------
    phi_J : float
        Packing fraction of the jammed packing.
    n_contacts, n_stable, isostatic_count : int
        Backbone contacts, stable particles and the isostatic count of the stored network.
    isostatic, hyperstatic : bool
    force_balance_residual : float
        Largest per-particle net force over the mean force, all particles.
    residual_stable : float
        The same over the stable particles.
    max_overlap : float
        Largest relative overlap over all pairs (and walls).
    total_time : float
        Wall time of the call [s].
    peak_memory : float
        Peak resident memory of the process [bytes].
    why : str
        Why the final checks failed (``"ok"`` when they passed).
    """

    phi_J: float
    n_contacts: int
    n_stable: int
    isostatic_count: int
    isostatic: bool
    hyperstatic: bool
    force_balance_residual: float
    residual_stable: float
    max_overlap: float
    total_time: float
    peak_memory: float
    why: str


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
    diagnostics : CalippsoDiagnostics
        Final checks: counts, isostaticity, residuals, overlaps, timings, memory.
    """

    packing: Packing
    history: xr.Dataset
    converged: bool
    iterations: int
    wall_contacts: NDArray[np.int64]
    wall_force: NDArray[np.float64]
    diagnostics: CalippsoDiagnostics


_COUNTS = ("n_constraints", "n_contacts", "n_stable", "simplex_iterations", "ipm_iterations", "newton_steps")


def _history(records: list[IterationRecord]) -> xr.Dataset:
    """The records as variables on the dimension ``iteration``."""
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
    data["engine"] = (("iteration",), col("engine").astype(str), {"long_name": "engine of the LP: highs, or jamflow "
                                                                              "(jamflow.simplex, warm simplex LPs); "
                                                                              "newton for the Newton finish"})
    data["warm_fallback"] = (("iteration",), col("warm_fallback").astype(str), {
        "long_name": "trouble jamflow.simplex reported on this warm LP before HiGHS solved it ('' = none)"})
    data["warm_lu"] = (("iteration",), col("warm_lu").astype(str), {
        "long_name": "LU library of jamflow.simplex on this warm LP: pardiso (MKL) or superlu; '+superlu': "
                     "a PARDISO LU with perturbed pivots was redone by SuperLU ('' = not jamflow.simplex)"})
    data["interior"] = (("iteration",), col("interior").astype(str), {
        "long_name": "interior point of the LP: ipx, hipo (the LP), hipo-dual (HiPO on its explicit dual), "
                     "'ipx after hipo-dual: <trouble>' (IPX re-solved it); '' = no interior point"})
    return xr.Dataset(data, coords={"iteration": np.arange(1, len(records) + 1)})


def _diagnose(message: str, records: list[IterationRecord]) -> str:
    """The error message of a failed chain: ``message`` and its last three LPs."""
    tail = records[-3:]
    info = "; ".join(
        f"LP {r.iteration}: {r.lp_status}, sqrtG-1={r.sqrt_gamma_minus_1:.3g}, max|s|={r.max_displacement_stable:.3g}, "
        f"Nc={r.n_contacts}, Ns={r.n_stable}, iso={int(r.isostatic)}, cutoff={r.cutoff:.3g}, bound={r.bound:.3g}"
        for r in tail
    )
    return f"CALiPPSO failed: {message} [{info}]"


def _result(packing: Packing, chain: _Chain, container: _Container, net: _Network, converged: bool,
            total: float, settings: dict[str, Any]) -> CalippsoResult:
    """The jammed packing at the chain's configuration with the network ``net``, its
    attributes (the start's, :data:`START_ATTRS` renamed, then the chain's), history and
    diagnostics; ``total`` is the wall time of the call [s]."""
    records = chain.records
    newton = chain.newton
    history = _history(records)
    D = chain.D
    p = container.packing(packing, chain.x, D)
    ov_rel = container.max_overlap(p)
    n_rattlers = int(net.rattler.sum())
    attrs = {START_ATTRS.get(k, k): v for k, v in packing.attrs.items()}
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
        warm_lps_jamflow=sum(r.engine == "jamflow" and r.solver != "crash" for r in records),
        first_lp=records[0].solver if records else "none",
        first_lp_fallbacks=sum(r.solver == "crash>ipm" for r in records),
        warm_fallbacks=sum(bool(r.warm_fallback) and r.solver != "crash>ipm" for r in records),
        warm_fallback_reasons=", ".join(sorted({r.warm_fallback for r in records if r.warm_fallback})) or "none",
        warm_lu=", ".join(sorted({r.warm_lu for r in records if r.warm_lu})) or "none",
        interior_lps=", ".join(f"{k} {sum(r.interior == k for r in records)}"
                               for k in sorted({r.interior for r in records if r.interior})) or "none",
        interior_fallbacks=sum(r.interior.startswith(DUAL_FALLBACK) for r in records),
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
    diag = CalippsoDiagnostics(
        phi_J=attrs["phi_J"], n_contacts=attrs["n_contacts"], n_stable=attrs["n_stable"],
        isostatic_count=attrs["isostatic_count"], isostatic=bool(net.iso), hyperstatic=bool(net.hyperstatic),
        force_balance_residual=attrs["force_balance_residual"], residual_stable=net.residual_stable,
        max_overlap=attrs["max_overlap"], total_time=total, peak_memory=attrs["peak_memory"], why=net.why)
    return CalippsoResult(packing=out, history=history, converged=converged, iterations=len(records),
                          wall_contacts=wc, wall_force=net.f_wall, diagnostics=diag)


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

