"""The stages the harness sweeps: each stage's inputs, tight reference, grid of accuracy
knobs, run and error metrics (:class:`StageSweep`, the registry :data:`STAGES`)."""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..analysis.contacts import summarize
from ..analysis.overlap import contact_overlap
from ..protocols.initial import random_packing
from ..state.packing import Packing
from ..tolerances import CONTACT_DRIFT_TOL, SOFT_FORCE_TOL


@dataclass(frozen=True)
class StageSweep:
    """One stage's sweep: inputs, reference, grid, metrics.

    Attributes
    ----------
    name : str
        Registry key (``jamflow tradeoff NAME``).
    description : str
        What is run on which inputs.
    commands : tuple of str
        ``jamflow`` commands whose presets the recommendations map to.
    knobs : dict
        Knob name -> long name with units.
    preset_options : dict
        Knob name -> argparse dest of the commands (knobs without a command-line
        option are left out of preset recommendations).
    metrics : dict
        Error metric -> long name (all dimensionless).
    primary : str
        Metric that defines the Pareto front and the recommendations.
    thresholds : dict
        Preset -> {metric: largest accepted value}; the primary error is always
        limited, other metrics (e.g. a force-balance criterion) may be.
    prepare : callable
        ``prepare(seed, quick) -> inputs`` (deterministic in ``seed``).
    reference : callable
        ``reference(quick) -> knobs`` of the tight reference run.
    grid : callable
        ``grid(quick) -> list of knobs``; the first entry also serves as the untimed
        warm-up (put a cheap one first).
    run : callable
        ``run(inputs, knobs, quick) -> output``.
    compare : callable
        ``compare(output, reference_output) -> {metric: value}``.
    """

    name: str
    description: str
    commands: tuple[str, ...]
    knobs: dict[str, str]
    preset_options: dict[str, str]
    metrics: dict[str, str]
    primary: str
    thresholds: dict[str, dict[str, float]]
    prepare: Callable[[int, bool], Any]
    reference: Callable[[bool], dict[str, Any]]
    grid: Callable[[bool], list[dict[str, Any]]]
    run: Callable[[Any, dict[str, Any], bool], Any]
    compare: Callable[[Any, Any], dict[str, float]]



# --- soft spheres: jamming onset -------------------------------------------------------

#: Target pressure of the soft-jamming sweep [epsilon / <D>^d].
SOFT_P0: float = 1e-7


def _soft_prepare(seed: int, quick: bool) -> Packing:
    return random_packing(64 if quick else 256, 2, 0.5, "bi", seed=seed)


def _fire(dt: float):
    from ..minimize.fire import FireParameters

    return FireParameters(dt=dt, dt_max=10 * dt, dt_min=dt / 50)


def _soft_run(start: Packing, knobs: dict[str, Any], quick: bool) -> Packing:
    from ..protocols.soft_jam import jam_to_pressure

    return jam_to_pressure(start, SOFT_P0, force_tol=knobs["force_tol"], fire_params=_fire(knobs["dt"])).packing


def _q(a: Packing, b: Packing) -> float:
    """Contact overlap of ``a`` with the reference ``b`` (NaN without reference contacts)."""
    if b.contacts is None or len(b.contacts) == 0:
        return np.nan
    return contact_overlap(a, b)[0]


def _soft_compare(out: Packing, ref: Packing) -> dict[str, float]:
    s = summarize(out)
    rel_phi = abs(out.packing_fraction - ref.packing_fraction) / ref.packing_fraction
    one_minus_q = 1.0 - _q(out, ref)
    return {
        "error": max(rel_phi, one_minus_q),
        "phi_J_error": rel_phi,
        "one_minus_Q": one_minus_q,
        "max_force": float(np.sqrt(out.attrs["max_force_sq"])),
        "hyperstatic_excess": float(s.n_contacts - s.isostatic_count),
    }


_SOFT_METRICS = {
    "error": "max(phi_J_error, one_minus_Q)",
    "phi_J_error": "|phi_J - phi_J(reference)| / phi_J(reference)",
    "one_minus_Q": "1 - Q, Q = contacts shared with the reference / reference contacts",
    "max_force": "final max_i |F_i| [epsilon / mean diameter] (force-balance residual)",
    "hyperstatic_excess": "backbone contacts minus d (N_s - 1) + 1",
}


def _soft_grid(quick: bool) -> list[dict[str, Any]]:
    # the default final tolerance of soft-jam (SOFT_FORCE_TOL) is always a grid point: the
    # final enthalpy minimisation to it is a measured share of soft-jam's time (docs/notes/presets.md)
    tols = (1e-8, 1e-10, 1e-12, SOFT_FORCE_TOL) if quick else (1e-6, 1e-8, 1e-10, 1e-12, SOFT_FORCE_TOL)
    # dt = 0.1 (dt_max = 1, beyond FIRE's stability limit) is slower at every tolerance:
    # two tolerances show it
    return [{"force_tol": t, "dt": 0.03} for t in tols] + [{"force_tol": t, "dt": 0.1} for t in (1e-8, SOFT_FORCE_TOL)]


# --- soft spheres: athermal quasistatic shear ------------------------------------------

#: Strain of the AQS sweep (quick, full).
AQS_STRAIN: tuple[float, float] = (0.01, 0.02)
#: Strain spacing on which AQS stresses are compared (a multiple of every step swept).
AQS_GRID: float = 1e-3


def _aqs_prepare(seed: int, quick: bool) -> Packing:
    from ..protocols.soft_jam import jam_to_pressure

    return jam_to_pressure(random_packing(64 if quick else 128, 2, 0.5, "bi", seed=seed), 1e-4).packing


def _aqs_run(start: Packing, knobs: dict[str, Any], quick: bool) -> tuple[xr.Dataset, Packing]:
    from ..protocols.quasistatic import aqs_shear

    return aqs_shear(start, AQS_STRAIN[0 if quick else 1], knobs["step"], force_tol=knobs["force_tol"])


def _on_grid(strain: NDArray[np.float64], values: NDArray[np.float64], total: float) -> NDArray[np.float64]:
    grid = np.arange(1, round(total / AQS_GRID) + 1) * AQS_GRID
    idx = np.array([int(np.argmin(np.abs(strain - g))) for g in grid])
    if np.any(np.abs(strain[idx] - grid) > 1e-9 * AQS_GRID):
        raise ValueError(f"AQS strain steps must divide {AQS_GRID}")
    return values[idx]


def _aqs_compare(out: tuple[xr.Dataset, Packing], ref: tuple[xr.Dataset, Packing]) -> dict[str, float]:
    (s, p), (sr, pr) = out, ref
    total = float(sr.strain.values[-1])
    a = _on_grid(s.strain.values, s.shear_stress.values, total)
    b = _on_grid(sr.strain.values, sr.shear_stress.values, total)
    scale = float(np.mean(np.abs(sr.shear_stress.values)))
    err = np.abs(a - b) / scale
    return {
        "error": float(err.max()),
        "median_stress_error": float(np.median(err)),
        "one_minus_Q": 1.0 - _q(p, pr),
        "max_force": float(s.max_force.values.max()),
    }


_AQS_METRICS = {
    "error": "largest |sigma_xy - sigma_xy(reference)| / <|sigma_xy(reference)|> over strains k 1e-3 "
             "(a plastic event resolved at another strain shows here)",
    "median_stress_error": "median of the same over the strains k 1e-3",
    "one_minus_Q": "1 - Q of the final contact network against the reference's",
    "max_force": "largest max_i |F_i| after a strain step [epsilon / mean diameter]",
}


def _aqs_grid(quick: bool) -> list[dict[str, Any]]:
    steps = (1e-3, 2e-4, 5e-5) if quick else (1e-3, 5e-4, 2e-4, 1e-4, 5e-5)
    tols = (1e-8, 1e-10, 1e-12) if quick else (1e-8, 1e-10, 1e-12, 1e-13)
    return [{"step": s, "force_tol": t} for s in steps for t in tols]


# --- overdamped event-driven flow ------------------------------------------------------

#: Packing fraction of the flow sweep's start (Lerner et al.'s lower density).
FLOW_PHI: float = 0.80
#: Options that prepare the start by event-driven compression (as in the benchmarks).
_FLOW_PREP = {"dt_max": 1e-2, "step_drift": 1e-6, "drift_tol": 1e-5}
#: Shear strain of the flow sweep (quick, full).
FLOW_STRAIN: tuple[float, float] = (0.01, 0.04)


def flow_start(n: int, phi: float, seed: int) -> Packing:
    """2D 1:1.4 bidisperse, 3 % polydisperse discs compressed event-driven to ``phi``.

    Tries seeds ``seed, seed + 1, ...`` (up to ten) until one does not jam below ``phi``.
    """
    from ..protocols.overdamped.driving import Drive
    from ..protocols.overdamped.integrate import FlowOptions
    from ..protocols.overdamped.run import Stop, run_flow

    for s in range(seed, seed + 10):
        p = random_packing(n, 2, 0.5, "bi", seed=s, species_spread=0.03)
        res = run_flow(p, Drive("compress"), Stop(packing_fraction=phi), FlowOptions(**_FLOW_PREP),
                       unit="small_diameter", record_every=10_000)
        if not res.jammed:
            return res.final
    raise RuntimeError(f"N={n}: every seed from {seed} jammed below phi={phi}")


def _flow_prepare(seed: int, quick: bool) -> Packing:
    return flow_start(64 if quick else 128, FLOW_PHI, seed)


def _flow_run(start: Packing, knobs: dict[str, Any], quick: bool):
    from ..protocols.overdamped.driving import Drive
    from ..protocols.overdamped.integrate import FlowOptions
    from ..protocols.overdamped.run import Stop, run_flow

    opts = FlowOptions(step_drift=knobs["step_drift"], correct_every=knobs["correct_every"],
                       drift_tol=knobs.get("drift_tol", CONTACT_DRIFT_TOL))
    return run_flow(start, Drive("shear"), Stop(strain=FLOW_STRAIN[0 if quick else 1]), opts, unit="small_diameter")


def _events(ds: xr.Dataset) -> list[tuple[int, int, int]]:
    """Net contact changes ``(i, j, kind)`` in order.

    Events at one instant (one rewiring) are reduced to their net effect per pair: a
    pair broken, made and broken again within one rewiring counts once as broken, a
    pair made and broken at one instant not at all.
    """
    strain = ds.event_strain.values
    out: list[tuple[int, int, int]] = []
    start = 0
    while start < len(strain):
        stop = start
        while stop < len(strain) and strain[stop] == strain[start]:
            stop += 1
        net: dict[tuple[int, int], int] = {}
        for k in range(start, stop):
            key = (int(ds.event_i.values[k]), int(ds.event_j.values[k]))
            net[key] = net.get(key, 0) + int(ds.event_kind.values[k])
        out += [(i, j, int(np.sign(v))) for (i, j), v in net.items() if v != 0]
        start = stop
    return out


def _flow_compare(out, ref) -> dict[str, float]:
    s, sr = out.series, ref.series
    total = float(sr.strain.values[-1])
    scale = float(np.mean(np.abs(sr.shear_stress.values)))
    grid = np.linspace(0.0, total, 401)[1:-1]

    def at(ds: xr.Dataset) -> NDArray[np.float64]:
        idx = np.searchsorted(ds.strain.values, grid, side="right") - 1
        return ds.shear_stress.values[idx]

    err = np.abs(at(s) - at(sr)) / scale
    # the values the run computed, at its own steps, against the dense reference
    # interpolated there: the held error above also counts how far apart the steps are
    own = (s.strain.values > 0.0) & (s.strain.values < total)
    at_steps = np.abs(s.shear_stress.values[own] - np.interp(s.strain.values[own], sr.strain.values,
                                                             sr.shear_stress.values)) / scale
    a, b = _events(s), _events(sr)
    agree = difflib.SequenceMatcher(None, a, b, autojunk=False).ratio() if (a or b) else 1.0
    return {
        "error": float(np.median(err)),
        "max_stress_error": float(err.max()),
        "error_at_steps": float(np.median(at_steps)),
        "p90_error_at_steps": float(np.quantile(at_steps, 0.9)),
        "constraint_drift": float(s.constraint_error.max()),
        "event_disagreement": 1.0 - agree,
        "one_minus_Q": 1.0 - _q(out.final, ref.final),
    }


_FLOW_METRICS = {
    "error": "median over 399 strains of |sigma_xy - sigma_xy(reference)| / <|sigma_xy(reference)|>, both series "
             "held constant between recorded steps (counts the spacing of the steps too)",
    "max_stress_error": "largest |sigma_xy - sigma_xy(reference)| / <|sigma_xy(reference)|>",
    "error_at_steps": "median over the run's recorded steps of |sigma_xy - sigma_xy(reference)| / "
                      "<|sigma_xy(reference)|>, the reference interpolated at each step's strain",
    "p90_error_at_steps": "90th percentile of the same (steps at events: event timing)",
    "constraint_drift": "largest relative constraint error max |r_ij - sigma_ij| / sigma_ij of the run",
    "event_disagreement": "1 - 2M / (n + n_ref), M = net contact changes (i, j, made/broken) per rewiring "
                          "matched in order with the reference's (difflib)",
    "one_minus_Q": "1 - Q of the final contact network against the reference's",
}


def _flow_grid(quick: bool) -> list[dict[str, Any]]:
    drifts = (1e-6, 1e-8, 1e-10) if quick else (1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
    every = (10, 1000) if quick else (10, 100, 1000)
    return [{"step_drift": s, "correct_every": c} for s in drifts for c in every]


# --- jamming certificate ---------------------------------------------------------------

#: Seeds of the random loads per input and setting (quick, full).
CERTIFY_SEEDS: tuple[int, int] = (2, 4)


def cut_backbone_contact(packing: Packing, contacts: NDArray[np.int64]) -> Packing:
    """``packing`` without the middle pair of ``contacts`` (e.g. its certified backbone).

    A jammed isostatic backbone with one contact removed has a cone of unjamming
    motions: a planted case a certificate must not call jammed.
    """
    k = len(contacts) // 2
    pc = packing.contacts
    drop = (pc[:, 0] == contacts[k, 0]) & (pc[:, 1] == contacts[k, 1])
    if not drop.any():
        raise ValueError("the contact to cut is not a contact of the packing")
    return packing.evolve(contacts=pc[~drop], force=None)


def _certify_prepare(seed: int, quick: bool) -> dict[str, Packing]:
    from ..protocols.certify import certify
    from ..protocols.soft_jam import jam_to_pressure

    starts = {"2d": random_packing(64 if quick else 256, 2, 0.5, "bi", seed=seed)}
    if not quick:
        starts["3d"] = random_packing(128, 3, 0.3, "bi", seed=seed)
    out = {}
    for name, start in starts.items():
        jammed = jam_to_pressure(start, 1e-5).packing
        base = certify(jammed, loads=4, seed=seed, solver="simplex")
        out[f"{name}_jammed"] = jammed
        out[f"{name}_cut_contact"] = cut_backbone_contact(jammed, base.backbone_contacts)
    return out


def _certify_run(inputs: dict[str, Packing], knobs: dict[str, Any], quick: bool) -> dict[tuple[str, int], tuple]:
    from ..protocols.certify import certify

    out = {}
    for name, p in inputs.items():
        for seed in range(CERTIFY_SEEDS[0 if quick else 1]):
            c = certify(p, strict=True, loads=knobs["loads"], seed=seed, solver=knobs["solver"])
            out[(name, seed)] = (c.classification, c.rattler.tobytes())
    return out


def _certify_compare(out: dict, ref: dict) -> dict[str, float]:
    truth = {name: v for (name, _), v in ref.items()}
    wrong_class = [v[0] != truth[name][0] for (name, _), v in out.items()]
    wrong = [v != truth[name] for (name, _), v in out.items()]
    return {"error": float(np.mean(wrong)), "classification_disagreement": float(np.mean(wrong_class))}


_CERTIFY_METRICS = {
    "error": "fraction of (input, load seed) whose classification or rattler set differs from the reference",
    "classification_disagreement": "fraction of (input, load seed) whose classification differs from the reference",
}


def _certify_grid(quick: bool) -> list[dict[str, Any]]:
    return [{"solver": s, "loads": k} for s in ("ipm", "simplex", "choose") for k in (1, 2, 4)]


# --- CALiPPSO ---------------------------------------------------------------------------

#: LS pressure of the CALiPPSO sweep's start.
CALIPPSO_START_P: float = 1e3


def _calippso_prepare(seed: int, quick: bool) -> Packing:
    from ..protocols.ls import compress

    start = random_packing(64 if quick else 256, 2, 0.5, "bi", seed=seed)
    return compress(start, 1e-3, p_targets=[CALIPPSO_START_P], seed=seed).snapshots[0]


def _calippso_run(start: Packing, knobs: dict[str, Any], quick: bool):
    from ..protocols.calippso import calippso

    return calippso(start, tol_s=knobs["tol_s"], tol_gamma=knobs["tol_gamma"], solver=knobs["solver"],
                    solver_tol=knobs["solver_tol"])


def _calippso_compare(out, ref) -> dict[str, float]:
    p, pr = out.packing, ref.packing
    rel_phi = abs(p.packing_fraction - pr.packing_fraction) / pr.packing_fraction
    one_minus_q = 1.0 - _q(p, pr)
    diag = out.diagnostics
    return {
        "error": max(rel_phi, one_minus_q),
        "phi_J_error": rel_phi,
        "one_minus_Q": one_minus_q,
        "n_lp": float(out.iterations),
        "max_overlap": float(diag.max_overlap),
        "force_balance_residual": float(diag.force_balance_residual),
        "not_isostatic": float(not diag.isostatic),
    }


_CALIPPSO_METRICS = {
    "error": "max(phi_J_error, one_minus_Q)",
    "phi_J_error": "|phi_J - phi_J(reference)| / phi_J(reference)",
    "one_minus_Q": "1 - Q of the jammed contact network against the reference's",
    "n_lp": "number of LPs solved",
    "max_overlap": "largest relative overlap of the jammed packing",
    "force_balance_residual": "force-balance residual of the jammed packing (CALiPPSO diagnostics)",
    "not_isostatic": "1 if the backbone is not isostatic",
}


def _calippso_grid(quick: bool) -> list[dict[str, Any]]:
    from ..protocols.calippso import SOLVER_TOL

    tols = [(1e-5, 1e-8), (1e-7, 1e-10), (1e-9, 1e-12)] + ([] if quick else [(1e-10, 1e-13)])
    grid = [{"tol_s": a, "tol_gamma": b, "solver": sv, "solver_tol": SOLVER_TOL}
            for sv in ("simplex", "ipm", "hybrid") for a, b in tols]
    # the HiGHS tolerances at the paper's convergence tolerances
    return grid + [{"tol_s": 1e-9, "tol_gamma": 1e-12, "solver": "hybrid", "solver_tol": t} for t in (1e-9, 1e-8)]


# --- LS compression ---------------------------------------------------------------------


def _ls_prepare(seed: int, quick: bool) -> Packing:
    return random_packing(64 if quick else 128, 2, 0.5, "bi", seed=seed)


def _ls_run(start: Packing, knobs: dict[str, Any], quick: bool) -> Packing:
    from ..protocols.calippso import calippso
    from ..protocols.ls import compress

    snap = compress(start, knobs["growth_rate"], p_targets=[knobs["p_target"]], seed=0).snapshots[0]
    return calippso(snap).packing


def _ls_compare(out: Packing, ref: Packing) -> dict[str, float]:
    from ..analysis.structure import crystal_fraction

    rel_phi = abs(out.packing_fraction - ref.packing_fraction) / ref.packing_fraction
    return {"error": rel_phi, "phi_J": out.packing_fraction, "crystal_fraction": crystal_fraction(out)}


_LS_METRICS = {
    "error": "|phi_J - phi_J(reference)| / phi_J(reference), phi_J after CALiPPSO (a slower compression "
             "jams denser: the distance from the slowest protocol, not a numerical error)",
    "phi_J": "jamming packing fraction after CALiPPSO (default settings)",
    "crystal_fraction": "fraction of crystal-like particles (jamflow.analysis.structure.crystal_fraction)",
}


def _ls_grid(quick: bool) -> list[dict[str, Any]]:
    rates = (1e-2, 1e-3) if quick else (3e-2, 1e-2, 3e-3, 1e-3)
    ps = (1e3, 1e5) if quick else (1e3, 1e5, 1e7)
    return [{"growth_rate": k, "p_target": p} for k in rates for p in ps]


#: The registry: stage name -> sweep.
# --- shaped bodies: jamming onset and quartic modes ------------------------------------

#: Circulo-line asphericity of the shapes sweep (hypostatic, regions 1 and 2 separate).
SHAPES_ASPHERICITY: float = 1.1


def _shapes_prepare(seed: int, quick: bool) -> Packing:
    from ..shapes.generation import bidisperse_shapes, random_shape_packing, unit_shape

    table = bidisperse_shapes(unit_shape("circulo-line", None, SHAPES_ASPHERICITY, None))
    return random_shape_packing(table, 16 if quick else 32, 0.5, seed)


def _shapes_run(start: Packing, knobs: dict[str, Any], quick: bool) -> tuple[Packing, int]:
    from ..minimize.onset import JammingSettings
    from ..shapes.jamming import jam_shapes
    from ..shapes.spectrum import spectrum

    out = jam_shapes(start, knobs["pressure"], JammingSettings(force_tol=knobs["force_tol"])).packing
    return out, spectrum(out).n_quartic


def _shapes_compare(out: tuple[Packing, int], ref: tuple[Packing, int]) -> dict[str, float]:
    (p, n1), (p_ref, n1_ref) = out, ref
    return {
        "phi_J_error": abs(p.packing_fraction - p_ref.packing_fraction) / p_ref.packing_fraction,
        "n_quartic_error": float(abs(n1 - n1_ref)),
        "max_force": float(np.sqrt(p.attrs["max_force_sq"])),
    }


def _shapes_grid(quick: bool) -> list[dict[str, Any]]:
    tols = (1e-10, 1e-12, SOFT_FORCE_TOL)
    pressures = (1e-6, 1e-7) if quick else (1e-5, 1e-6, 1e-7, 1e-8)
    return [{"force_tol": t, "pressure": p} for p in pressures for t in tols]


# --- linked packings: re-affixing precision ---------------------------------------------

#: Target pressure of the chains sweep [epsilon / <D>^d].
CHAINS_P0: float = 1e-4


def _chains_prepare(seed: int, quick: bool) -> Packing:
    from ..chains.builders import linked_packing

    # the dilute start without overlaps (docs/notes/chains.md): links cannot pass through each other
    return linked_packing(2, 10 if quick else 20, "trimer", np.random.default_rng(seed), phi=0.2,
                          no_overlap=True)[0]


def _chains_run(start: Packing, knobs: dict[str, Any], quick: bool) -> Packing:
    from ..chains.jamming import jam_linked
    from ..minimize.onset import JammingSettings

    return jam_linked(start, CHAINS_P0, settings=JammingSettings(force_tol=knobs["force_tol"]),
                      length_rtol=knobs["length_rtol"]).packing


def _stored_q(a: Packing, b: Packing) -> float:
    """``|C_a ∩ C_b| / N_c(b)`` of the packings' stored contact pairs (by particle
    identity) against the reference ``b``, NaN without reference contacts. For linked
    packings from one start, which the overlap stage (:func:`_q`) refuses: its Q
    recomputes contact networks of free spheres."""
    if b.contacts is None or len(b.contacts) == 0 or a.contacts is None:
        return np.nan
    ka, kb = ({tuple(c) for c in np.sort(p.contacts, axis=1).tolist()} for p in (a, b))
    return len(ka & kb) / len(kb)


def _chains_compare(out: Packing, ref: Packing) -> dict[str, float]:
    rel_phi = abs(out.packing_fraction - ref.packing_fraction) / ref.packing_fraction
    return {
        "phi_J_error": rel_phi,
        "pressure_error": abs(out.pressure - ref.pressure) / ref.pressure,
        "one_minus_Q": 1.0 - _stored_q(out, ref),
        "max_link_error": float(out.attrs["max_link_error"]),
    }


_CHAINS_METRICS = {
    "phi_J_error": "|phi_J - phi_J(reference)| / phi_J(reference)",
    "pressure_error": "|P - P(reference)| / P(reference)",
    "one_minus_Q": "1 - Q of the contact network against the reference's",
    "max_link_error": "largest relative link-length error of the jammed packing",
}


def _chains_grid(quick: bool) -> list[dict[str, Any]]:
    from ..tolerances import LINK_LENGTH_RTOL

    # re-affixing runs after every move but only sweeps while a link is off by more than
    # length_rtol: the precision also sets how often Newton runs (no separate frequency knob)
    rtols = (1e-6, 1e-9, LINK_LENGTH_RTOL) if quick else (1e-4, 1e-6, 1e-8, 1e-10, LINK_LENGTH_RTOL)
    return [{"length_rtol": r, "force_tol": SOFT_FORCE_TOL} for r in rtols] + [
        {"length_rtol": 1e-6, "force_tol": 1e-10}]


STAGES: dict[str, StageSweep] = {
    "soft": StageSweep(
        name="soft",
        description=f"soft-sphere jamming onset at P0 = {SOFT_P0:g}: 2D 1:1.4 bidisperse RSA start "
                    "(N = 64 quick, 256 full, phi = 0.5), FIRE 2.0 with dt_max = 10 dt, dt_min = dt / 50",
        commands=("soft-jam",),
        knobs={"force_tol": "final max_i |F_i| [epsilon / mean diameter]",
               "dt": "FIRE initial time step [mean diameter sqrt(m / epsilon)]"},
        preset_options={"force_tol": "force_tol"},
        metrics=_SOFT_METRICS,
        primary="error",
        thresholds={"fast": {"error": 1e-3}, "default": {"error": 1e-6},
                    "publication": {"error": 1e-9, "max_force": SOFT_FORCE_TOL}},
        prepare=_soft_prepare,
        reference=lambda quick: {"force_tol": 10**-13.5, "dt": 0.01},
        grid=_soft_grid,
        run=_soft_run,
        compare=_soft_compare,
    ),
    "shapes": StageSweep(
        name="shapes",
        description=f"jamming of 2D bidisperse circulo-lines (A = {SHAPES_ASPHERICITY:g}, N = 16 quick, 32 full, "
                    "RSA start at phi = 0.5) with rotations to P0, then the dynamical-matrix spectrum "
                    "(VanderWerf et al.); errors against a tight reference at the lowest P0",
        commands=("soft-jam",),
        knobs={"force_tol": "final max_i sqrt(F_i^2 + (tau_i / l)^2) [k length]",
               "pressure": "target pressure P0 [k]"},
        preset_options={"force_tol": "force_tol"},
        metrics={"phi_J_error": "|phi_J - phi_J(reference)| / phi_J(reference)",
                 "n_quartic_error": "|N_1 - N_1(reference)|, quartic modes (region 1)",
                 "max_force": "final max generalised force [k length]"},
        primary="phi_J_error",
        thresholds={"fast": {"phi_J_error": 1e-4}, "default": {"phi_J_error": 1e-6, "n_quartic_error": 0.0},
                    "publication": {"phi_J_error": 1e-7, "n_quartic_error": 0.0}},
        prepare=_shapes_prepare,
        reference=lambda quick: {"force_tol": 10**-13.5, "pressure": 1e-8 if quick else 1e-9},
        grid=_shapes_grid,
        run=_shapes_run,
        compare=_shapes_compare,
    ),
    "chains": StageSweep(
        name="chains",
        description=f"fixed-box jamming of 2D rigid trimers at P0 = {CHAINS_P0:g} (10 trimers quick, 20 full, "
                    "dilute start without overlaps at phi = 0.2): bisection with constraint projection and "
                    "Newton re-affixing to length_rtol after every FIRE move",
        commands=("soft-jam",),
        knobs={"length_rtol": "relative link-length precision of Newton re-affixing (also sets how often it sweeps)",
               "force_tol": "final max_i |P F_i| [epsilon / mean diameter]"},
        preset_options={"force_tol": "force_tol"},
        metrics=_CHAINS_METRICS,
        primary="phi_J_error",
        thresholds={"fast": {"phi_J_error": 1e-4}, "default": {"phi_J_error": 1e-6},
                    "publication": {"phi_J_error": 1e-9, "max_link_error": 1e-12}},
        prepare=_chains_prepare,
        reference=lambda quick: {"length_rtol": 1e-14, "force_tol": 10**-13.5},
        grid=_chains_grid,
        run=_chains_run,
        compare=_chains_compare,
    ),
    "aqs": StageSweep(
        name="aqs",
        description="athermal quasistatic shear of a soft 2D 1:1.4 bidisperse packing jammed at P0 = 1e-4 "
                    f"(N = 64 quick, 128 full) to strain {AQS_STRAIN[0]} (quick) / {AQS_STRAIN[1]} (full)",
        commands=("aqs",),
        knobs={"step": "strain step delta gamma", "force_tol": "max_i |F_i| per step [epsilon / mean diameter]"},
        preset_options={"force_tol": "force_tol"},
        metrics=_AQS_METRICS,
        primary="error",
        thresholds={"fast": {"error": 1e-2}, "default": {"error": 1e-3},
                    "publication": {"error": 1e-4, "max_force": SOFT_FORCE_TOL}},
        prepare=_aqs_prepare,
        reference=lambda quick: {"step": 1e-5, "force_tol": 1e-13},
        grid=_aqs_grid,
        run=_aqs_run,
        compare=_aqs_compare,
    ),
    "overdamped": StageSweep(
        name="overdamped",
        description=f"event-driven simple shear of 2D 1:1.4 bidisperse 3 % polydisperse discs (N = 64 quick, 128 full, "
                    f"phi = {FLOW_PHI}, start by event-driven compression) to strain {FLOW_STRAIN[0]} (quick) / "
                    f"{FLOW_STRAIN[1]} (full); swept settings keep the commands' drift_tol = {CONTACT_DRIFT_TOL:g}",
        commands=("shear", "compress", "drive"),
        knobs={"step_drift": "largest relative constraint error one step may create (sets the step dt)",
               "correct_every": "steps between drift corrections"},
        preset_options={"step_drift": "step_drift", "correct_every": "correct_every"},
        metrics=_FLOW_METRICS,
        primary="error",
        thresholds={"fast": {"error": 1e-2}, "default": {"error": 1e-3}, "publication": {"error": 1e-4}},
        prepare=_flow_prepare,
        reference=lambda quick: {"step_drift": 1e-11, "correct_every": 10, "drift_tol": 1e-9},
        grid=_flow_grid,
        run=_flow_run,
        compare=_flow_compare,
    ),
    "certify": StageSweep(
        name="certify",
        description="strict jamming certificate of soft 1:1.4 bidisperse packings jammed at P0 = 1e-5 "
                    "(2D N = 64 quick; 2D N = 256 and 3D N = 128 full), each also with one backbone contact cut "
                    f"(planted unjamming motion); {CERTIFY_SEEDS[0]} (quick) / {CERTIFY_SEEDS[1]} (full) "
                    "load seeds per input; time = all certificates of a setting",
        commands=("certify",),
        knobs={"solver": "HiGHS algorithm of the collective and strict LPs",
               "loads": "random loads per LP kind, each with both signs"},
        preset_options={"solver": "solver", "loads": "loads"},
        metrics=_CERTIFY_METRICS,
        primary="error",
        thresholds={p: {"error": 0.0} for p in ("fast", "default", "publication")},
        prepare=_certify_prepare,
        reference=lambda quick: {"solver": "simplex", "loads": 8},
        grid=_certify_grid,
        run=_certify_run,
        compare=_certify_compare,
    ),
    "calippso": StageSweep(
        name="calippso",
        description="CALiPPSO from an LS snapshot at p = 1e3 (growth rate 1e-3) of 2D 1:1.4 bidisperse discs "
                    "(N = 64 quick, 256 full)",
        commands=("calippso",),
        knobs={"tol_s": "convergence: largest stable displacement of the last LP [mean diameters]",
               "tol_gamma": "convergence: sqrt(Gamma*) - 1 of the last LP",
               "solver": "HiGHS strategy (jamflow.protocols.calippso.SOLVERS)",
               "solver_tol": "HiGHS primal/dual feasibility and IPM optimality tolerance (scaled rows)"},
        preset_options={"tol_s": "tol_s", "tol_gamma": "tol_gamma", "solver": "solver", "solver_tol": "solver_tol"},
        metrics=_CALIPPSO_METRICS,
        primary="error",
        thresholds={"fast": {"error": 1e-3, "not_isostatic": 0.0}, "default": {"error": 1e-6, "not_isostatic": 0.0},
                    "publication": {"error": 1e-9, "not_isostatic": 0.0}},
        prepare=_calippso_prepare,
        reference=lambda quick: {"tol_s": 1e-11, "tol_gamma": 1e-14, "solver": "simplex", "solver_tol": 1e-10},
        grid=_calippso_grid,
        run=_calippso_run,
        compare=_calippso_compare,
    ),
    "ls": StageSweep(
        name="ls",
        description="LS compression of a 2D 1:1.4 bidisperse RSA start (N = 64 quick, 128 full, phi = 0.5) to "
                    "p_target, then CALiPPSO with its defaults; time = LS + CALiPPSO",
        commands=("ls",),
        knobs={"growth_rate": "LS growth rate kappa (after the fast phase to p = 500)",
               "p_target": "LS target pressure handed to CALiPPSO"},
        preset_options={},
        metrics=_LS_METRICS,
        primary="error",
        thresholds={"fast": {"error": 1e-2}, "default": {"error": 3e-3}, "publication": {"error": 1e-3}},
        prepare=_ls_prepare,
        reference=lambda quick: {"growth_rate": 1e-4, "p_target": 1e7},
        grid=_ls_grid,
        run=_ls_run,
        compare=_ls_compare,
    ),
}


#: Runs shorter than this [s] are repeated (same output) until this much time is
