"""A whole event-driven run: packing in, time series + final packing + snapshots out.

The time series follows the flow schema shared with the analyses: dim ``step`` with
coordinates ``strain`` and ``time``; ``shear_stress`` (Eq. 30), ``pressure``
(Eq. 24), ``packing_fraction``, ``kappa``, ``n_contacts``, ``z_bar`` (Eq. 29),
``volume``, ``constraint_error``; dim ``event`` with the contact changes. Units
(Sec. II D): lengths in lambda, time in ``1 / gamma_dot`` (deformations) or
``tau = lambda / (f_ext xi0)`` (forces), forces in ``lambda gamma_dot / xi0`` or
``f_ext``.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ...box import Box
from ...io import new_dataset_attrs
from ...io.binding import arrays_sha256
from ...network.spheres import find_rattlers
from ...stages import require
from ...state.packing import Packing, length_unit, near_pairs
from ...tolerances import OVERLAP_TOL
from .checkpoint import load_checkpoint, save_checkpoint
from .driving import Drive
from .integrate import FlowOptions, Integrator
from .recorder import SERIES, Recorder
from .starts import jammed_start

__all__ = ["FlowResult", "Stop", "run_flow", "snapshot_packings"]



@dataclass(frozen=True)
class Stop:
    """When a run ends (whichever comes first; a jammed network always ends it).

    Attributes
    ----------
    strain : float or None
        Accumulated imposed strain (``rate * time``).
    packing_fraction : float or None
        Target packing fraction (compression; reached exactly).
    time : float or None
        Elapsed time in the drive's time unit.
    max_steps : int or None
        Step budget of this invocation (a resumed run continues from its checkpoint).
    """

    strain: float | None = None
    packing_fraction: float | None = None
    time: float | None = None
    max_steps: int | None = None


@dataclass
class FlowResult:
    """Products of a run.

    Attributes
    ----------
    series : xarray.Dataset
        Time series and events (flow schema).
    final : Packing
        Last (or jammed) packing with contacts and forces, input length units.
    snapshots : xarray.Dataset or None
    complete : bool
        False when the run stopped on ``max_steps`` before its target.
    jammed : bool
    """

    series: xr.Dataset
    final: Packing
    snapshots: xr.Dataset | None
    complete: bool
    jammed: bool


_SERIES_META = {
    "strain": ("1", "accumulated imposed strain gamma (rate * time; shear strain for shear modes)"),
    "time": ("1", "time in units of 1/gamma_dot (deformation) or lambda/(f_ext xi0) (forces)"),
    "shear_stress": ("stress", "shear stress -(1/Omega) sum f r_x r_y / r (Eq. 30)"),
    "pressure": ("stress", "pressure <f|r>/(Omega d) (Eq. 24)"),
    "packing_fraction": ("1", "packing fraction"),
    "kappa": ("1", "ratio of isotropic compression rate to shear rate (Eq. 25); NaN unless fixed pressure"),
    "n_contacts": ("1", "number of contacts in the network"),
    "z_bar": ("1", "constrained coordination number z_bar (Eq. 29)"),
    "volume": ("1", "box volume in units of lambda^d"),
    "constraint_error": ("1", "max |r_ij - sigma_ij| / sigma_ij over contacts"),
}


def check_overlaps(packing: Packing, options: FlowOptions) -> None:
    """Refuse a start with interpenetrating hard spheres (ValueError naming the worst pairs).

    The packing's own contacts may overlap by up to the drift tolerance (the dynamics
    corrects them, Sec. IV C); any other pair by at most
    :data:`~jamflow.tolerances.OVERLAP_TOL` (relative).
    """
    pairs, h = near_pairs(packing.wrapped(), 0.0)
    allowed = np.full(len(h), OVERLAP_TOL)
    if packing.contacts is not None and len(packing.contacts) and len(h):
        key = pairs.i.astype(np.int64) * packing.n + pairs.j
        given = np.isin(key, packing.contacts[:, 0] * packing.n + packing.contacts[:, 1])
        allowed[given] = max(options.drift_tol, OVERLAP_TOL)
    bad = np.flatnonzero(-h > allowed)
    if bad.size:
        worst = bad[np.argsort(h[bad])[:3]]
        named = ", ".join(f"({pairs.i[k]}, {pairs.j[k]}): {-h[k]:.3g}" for k in worst)
        raise ValueError(f"{bad.size} pair(s) of hard spheres overlap beyond the tolerance (relative); worst {named}")


def _horizon(integ: Integrator, stop: Stop) -> float:
    st = integ.state
    drive = integ.drive
    hz = integ.next_switch()
    if stop.strain is not None and drive.deforms:
        hz = min(hz, (stop.strain - st.strain) / drive.rate)
    if stop.time is not None:
        hz = min(hz, stop.time * drive.time_unit - st.time)
    if stop.packing_fraction is not None and drive.compresses:
        phi = integ.packing_fraction()
        # h scales by (1 - rate t) within a step: phi grows as (1 - rate t)^-d
        hz = min(hz, (1.0 - (phi / stop.packing_fraction) ** (1.0 / integ.d)) / drive.rate)
    return max(hz, 0.0)


def _done(integ: Integrator, stop: Stop) -> bool:
    st = integ.state
    if st.jammed:
        return True
    tiny = 1e-12
    if stop.strain is not None and integ.drive.deforms and st.strain >= stop.strain - tiny * max(1.0, stop.strain):
        return True
    if stop.time is not None and st.time >= (stop.time - tiny * max(1.0, stop.time)) * integ.drive.time_unit:
        return True
    if stop.packing_fraction is not None and integ.drive.compresses:
        phi = integ.packing_fraction()
        if phi >= stop.packing_fraction * (1 - tiny):
            return True
    return False


def run_binding(packing: Packing, drive: Drive, stop: Stop, options: FlowOptions, unit: str,
                record_every: int, n_snapshots: int) -> dict[str, str]:
    """What a checkpoint must match to be resumed: the start and every trajectory parameter.

    Returns
    -------
    dict
        ``bound_input_sha256``: SHA-256 of the start's arrays (positions, diameters, box,
        contacts) and of the drive's arrays (external forces, permanent pairs, initial
        self-propulsion forces, which carry the seed); ``bound_run``: JSON of the drive,
        the targets of ``stop`` (not its step budget, which a resumed run may change),
        the options, the length unit and the recording choices.
    """
    digest = arrays_sha256(packing.position, packing.diameter, packing.box.matrix, packing.contacts, drive.external,
                           drive.permanent, None if drive.propulsion is None else drive.propulsion.force)
    run = {"drive": drive.describe(), "stop": {"strain": stop.strain, "packing_fraction": stop.packing_fraction,
                                               "time": stop.time},
           "options": asdict(options), "unit": unit, "record_every": record_every, "n_snapshots": n_snapshots}
    return {"bound_input_sha256": digest, "bound_run": json.dumps(run, sort_keys=True, default=str)}


def run_flow(
    packing: Packing,
    drive: Drive,
    stop: Stop,
    options: FlowOptions = FlowOptions(),
    unit: str = "mean_diameter",
    record_every: int = 1,
    n_snapshots: int = 0,
    checkpoint: str | os.PathLike | None = None,
    parameters: dict[str, Any] | None = None,
    progress: Any = None,
) -> FlowResult:
    """Drive a hard-sphere packing with the event-driven overdamped dynamics.

    Parameters
    ----------
    packing : Packing
        Non-overlapping start; its contacts (if any) seed the network.
    drive : Drive
    stop : Stop
    options : FlowOptions
    unit : str
        Choice of lambda (see :func:`length_unit`).
    record_every : int
        Record the time series every this many steps (and at the start and end).
    n_snapshots : int
        Number of evenly spaced packing snapshots over the target strain / time.
    checkpoint : path, optional
        Checkpoint file, written at every synchronisation point; if it exists the
        run resumes from it and produces the same numbers as an uninterrupted run.
        A checkpoint written from another start or with other parameters
        (:func:`run_binding`) is refused with a ``ValueError``.
    parameters : dict, optional
        Stage parameters for provenance.
    progress : callable, optional
        ``progress(fraction_done)`` after each recorded step (progress bars).

    Raises
    ------
    ValueError
        Overlapping spheres, a checkpoint of another run, or a fixed-volume shear of a
        start jammed against it (:func:`~jamflow.protocols.overdamped.starts.jammed_start`).
    """
    require("shear" if drive.mode.startswith("shear") else "compress" if drive.mode == "compress" else "drive",
            packing.body_kind)
    jammed = jammed_start(packing, drive)
    if jammed:
        raise ValueError(jammed)
    lam = length_unit(packing.diameter, unit)
    params = dict(parameters or {})
    params.update({"drive": drive.describe(), "lambda": lam, "unit": unit})
    recorder = Recorder()
    binding = run_binding(packing, drive, stop, options, unit, record_every, n_snapshots)
    if checkpoint is not None and Path(checkpoint).exists():
        integ, recorder = load_checkpoint(checkpoint, drive, options, binding)
    else:
        check_overlaps(packing, options)
        integ = Integrator.start(packing.position / lam, packing.box.matrix / lam,
                                 packing.diameter / (2 * lam), drive, options, packing.contacts)
        recorder.record(integ)
        if n_snapshots:
            recorder.snapshot(integ, lam)
    target = stop.strain if stop.strain is not None else stop.time
    steps = 0
    recorded_step = integ.state.step
    while not _done(integ, stop):
        if stop.max_steps is not None and steps >= stop.max_steps:
            break
        integ.step(_horizon(integ, stop))
        steps += 1
        st = integ.state
        done = _done(integ, stop)
        if st.step % record_every == 0 or done:
            recorder.record(integ)
            recorded_step = st.step
            if progress is not None:
                # a run at its target is done, within whatever round-off the target test allows
                progress(1.0 if done else fraction_done(st.strain if stop.strain is not None else st.time / drive.time_unit,
                                                        recorder.columns["packing_fraction"], stop))
        if n_snapshots and target:
            position = st.strain if stop.strain is not None else st.time / drive.time_unit
            while recorder.next_snapshot < n_snapshots and position >= (recorder.next_snapshot + 1) * target / n_snapshots * (1 - 1e-12):
                recorder.next_snapshot += 1
                recorder.snapshot(integ, lam)
        if checkpoint is not None and st.step % options.sync_every == 0:
            save_checkpoint(checkpoint, integ, recorder, binding)
    complete = _done(integ, stop)
    if complete and integ.state.contact.any():
        # the written packing satisfies its contact constraints to round-off (Sec. IV C)
        integ.correct()
    if complete or integ.state.step != recorded_step:
        recorder.record(integ)
    series = _series_dataset(integ, recorder, params, complete)
    snaps = _snapshot_dataset(recorder, integ, params) if n_snapshots else None
    final = _final_packing(integ, packing, lam, params)
    return FlowResult(series, final, snaps, complete, integ.state.jammed)


def fraction_done(position: float, phi: list[float], stop: Stop) -> float:
    """Fraction of a run done, for progress bars, in [0, 1].

    ``position`` is the strain (or time) reached. With a target packing fraction the
    fraction is the way travelled from the first recorded ``phi`` to the target (a
    compression stops there long before its strain limit, so the strain alone would
    sit near 0 % and jump); it is never less than the strain (time) fraction.
    """
    target = stop.strain if stop.strain is not None else stop.time
    done = position / target if target else 0.0
    if stop.packing_fraction is not None and phi:
        span = stop.packing_fraction - phi[0]
        if span > 0:
            done = max(done, (phi[-1] - phi[0]) / span)
    return float(min(1.0, max(0.0, done)))


#: Reference jamming densities of frictionless spheres per dimension (2D: bidisperse
#: 1:1.4 discs; 3D: monodisperse; 4D, 5D: Charbonneau et al. PRE 2011/CALiPPSO Table I ballpark).
PHI_J_REFERENCE: dict[int, float] = {2: 0.84, 3: 0.64, 4: 0.46, 5: 0.31}
#: A start below this fraction of the reference phi_J, without contacts, is "far below jamming".
DILUTE_FRACTION: float = 0.9


def dilute_start(packing: Packing) -> str | None:
    """Why a shear start is far below jamming, or None when it is dense or jammed.

    Lerner et al.'s shear flow is a dense-suspension model: its stress comes from the
    contact network. A start without contacts and at ``phi < DILUTE_FRACTION *
    PHI_J_REFERENCE[d]`` shears a gas of spheres that rarely touch, and the stress and
    friction of that trajectory say nothing about the jammed or dense states the
    method is for.
    """
    ref = PHI_J_REFERENCE.get(packing.d)
    n_contacts = 0 if packing.contacts is None else len(packing.contacts)
    if ref is None or n_contacts > 0 or packing.packing_fraction >= DILUTE_FRACTION * ref:
        return None
    return (f"start is far below jamming: phi = {packing.packing_fraction:.4f} < {DILUTE_FRACTION} x "
            f"{ref} (reference phi_J, d = {packing.d}) and no contacts; compress it first (jamflow compress) "
            f"or start from a jammed packing")


def _mode_name(drive: Drive) -> str:
    if drive.mode in ("forces", "self_propelled"):
        return "drive"
    if drive.mode in ("compress", "shear_compress"):
        return "compress"
    return drive.mode


def stress_unit(drive: Drive, d: int) -> str:
    """Unit of the recorded stresses: the force unit of Sec. II D per ``lambda^(d-1)``.

    Deformation: forces in ``lambda gamma_dot / xi0`` (``xi0`` the mobility of Eq. 31),
    so stress in ``gamma_dot / (xi0 lambda^(d-2))``; driven by forces: ``f_ext / lambda^(d-1)``.
    """
    if drive.deforms:
        return "gamma_dot / xi0" if d == 2 else f"gamma_dot / (xi0 lambda^{d - 2})"
    return f"f_ext / lambda^{d - 1}"


def _series_dataset(integ: Integrator, rec: Recorder, params: dict, complete: bool) -> xr.Dataset:
    cols = rec.columns
    data_vars = {}
    for k in SERIES[2:]:
        dtype = np.int64 if k == "n_contacts" else np.float64
        units, long_name = _SERIES_META[k]
        units = stress_unit(integ.drive, integ.d) if units == "stress" else units
        data_vars[k] = (("step",), np.asarray(cols[k], dtype=dtype), {"units": units, "long_name": long_name})
    ev = integ.state.events
    ev_arr = np.array(ev, dtype=np.float64).reshape(-1, 5)
    data_vars["event_strain"] = (("event",), ev_arr[:, 0], {"units": "1", "long_name": "strain at the event"})
    data_vars["event_time"] = (("event",), ev_arr[:, 1] / integ.drive.time_unit, {"units": "1", "long_name": "time of the event (units of the time series)"})
    data_vars["event_i"] = (("event",), ev_arr[:, 2].astype(np.int64), {"units": "1", "long_name": "first particle of the pair (i < j)"})
    data_vars["event_j"] = (("event",), ev_arr[:, 3].astype(np.int64), {"units": "1", "long_name": "second particle of the pair (i < j)"})
    data_vars["event_kind"] = (("event",), ev_arr[:, 4].astype(np.int8), {
        "units": "1", "long_name": "contact event kind",
        "flag_values": np.array([1, -1], dtype=np.int8), "flag_meanings": "contact_made contact_broken"})
    corr = np.array(integ.state.corrections, dtype=np.float64).reshape(-1, 3)
    data_vars["correction_strain"] = (("correction",), corr[:, 0], {"units": "1", "long_name": "strain of a drift correction (Sec. IV C)"})
    data_vars["correction_error_before"] = (("correction",), corr[:, 1], {"units": "1", "long_name": "max |r_ij - sigma_ij| / sigma_ij before the drift correction"})
    data_vars["correction_error_after"] = (("correction",), corr[:, 2], {"units": "1", "long_name": "max |r_ij - sigma_ij| / sigma_ij after the drift correction"})
    coords = {
        "strain": (("step",), np.asarray(cols["strain"]), {"units": "1", "long_name": _SERIES_META["strain"][1]}),
        "time": (("step",), np.asarray(cols["time"]), {"units": "1", "long_name": _SERIES_META["time"][1]}),
    }
    drive = integ.drive
    attrs = new_dataset_attrs(
        "jamflow event-driven overdamped flow time series", params,
        mode=_mode_name(drive), drive_mode=drive.mode, d=integ.d, N=integ.n,
        length_unit="lambda (global attribute lambda, in input length units)",
        time_unit="1/gamma_dot" if drive.deforms else "lambda/(f_ext xi0)",
        force_unit="lambda gamma_dot / xi0" if drive.deforms else "f_ext",
        jammed=int(integ.state.jammed), complete=int(complete), n_steps=integ.state.step,
        **{"lambda": params["lambda"]},
    )
    return xr.Dataset(data_vars=data_vars, coords=coords, attrs=attrs)


def _snapshot_dataset(rec: Recorder, integ: Integrator, params: dict) -> xr.Dataset:
    snaps = rec.snapshots
    counts = np.array([len(s["pairs"]) for s in snaps], dtype=np.int64)
    pairs = np.concatenate([s["pairs"] for s in snaps]).reshape(-1, 2)
    forces = np.concatenate([s["force"] for s in snaps])
    length = "input length units (lambda times global attribute lambda)"
    data_vars = {
        "snapshot_position": (("snapshot", "particle", "spatial"), np.stack([s["position"] for s in snaps]),
                              {"units": "1", "long_name": "particle centres", "comment": length}),
        "snapshot_box": (("snapshot", "spatial", "lattice_vector"), np.stack([s["box"] for s in snaps]),
                         {"units": "1", "long_name": "box lattice vectors as columns", "comment": length}),
        "snapshot_strain": (("snapshot",), np.array([s["strain"] for s in snaps]), {"units": "1", "long_name": "strain of the snapshot"}),
        "snapshot_time": (("snapshot",), np.array([s["time"] for s in snaps]), {"units": "1", "long_name": "time of the snapshot"}),
        "snapshot_contact_count": (("snapshot",), counts, {"units": "1", "long_name": "number of contacts of each snapshot",
                                                            "sample_dimension": "snapshot_contact"}),
        "snapshot_contact_i": (("snapshot_contact",), pairs[:, 0], {"units": "1", "long_name": "first particle of a contact (contiguous ragged by snapshot)"}),
        "snapshot_contact_j": (("snapshot_contact",), pairs[:, 1], {"units": "1", "long_name": "second particle of a contact"}),
        "snapshot_force": (("snapshot_contact",), forces, {"units": "1", "long_name": "contact force (force unit of the time series)"}),
        "diameter": (("particle",), 2 * integ.state.radius * params["lambda"], {"units": "1", "long_name": "particle diameter", "comment": length}),
    }
    attrs = new_dataset_attrs("jamflow event-driven flow snapshots", params, d=integ.d, N=integ.n,
                              **{"lambda": params["lambda"]})
    return xr.Dataset(data_vars=data_vars, attrs=attrs)


def snapshot_packings(ds: xr.Dataset) -> list[Packing]:
    """The packings of a snapshot dataset (``--snapshots N`` of compress, shear, drive), in order.

    Each packing holds the snapshot's centres, box (with its Lees-Edwards tilt), contacts
    and contact forces (force unit of the time series); ``attrs`` carry its ``strain``
    and ``time``. Lengths are the dataset's (input length units).
    """
    missing = [v for v in ("snapshot_position", "snapshot_box", "snapshot_contact_count", "diameter") if v not in ds]
    if missing:
        raise ValueError(f"not a flow snapshot dataset: missing variable(s) {', '.join(missing)}")
    ends = np.cumsum(ds["snapshot_contact_count"].values)
    starts = ends - ds["snapshot_contact_count"].values
    pairs = np.stack([ds["snapshot_contact_i"].values, ds["snapshot_contact_j"].values], axis=1)
    frames = []
    for k in range(ds.sizes["snapshot"]):
        box = Box(ds["snapshot_box"].values[k])
        frames.append(Packing(
            position=box.wrap(ds["snapshot_position"].values[k]), diameter=ds["diameter"].values, box=box,
            contacts=pairs[starts[k]:ends[k]], force=ds["snapshot_force"].values[starts[k]:ends[k]],
            protocol=str(ds.attrs.get("title", "flow snapshot")),
            attrs={"strain": float(ds["snapshot_strain"].values[k]), "time": float(ds["snapshot_time"].values[k])},
        ))
    return frames


def _final_packing(integ: Integrator, packing: Packing, lam: float, params: dict) -> Packing:
    st = integ.state
    pairs = st.nl.pairs[st.contact]
    force = integ.solution.force / integ.drive.force_unit
    sig = integ.stress() / integ.drive.force_unit
    x = (st.x * lam)
    box = Box(st.h * lam)
    return Packing(
        position=box.wrap(x), diameter=packing.diameter, box=box, contacts=pairs, force=force,
        rattler=find_rattlers(integ.n, integ.d, pairs), pressure=float(np.trace(sig)) / integ.d,
        protocol=f"{packing.protocol}>{_mode_name(integ.drive)}", seed=packing.seed, parameters=params,
        attrs={"force_unit": ("self-stress normalised to mean 1" if st.jammed else
                              ("lambda gamma_dot / xi0" if integ.drive.deforms else "f_ext")),
               "jammed": int(st.jammed), "strain": st.strain, "lambda": lam,
               "shear_stress": float(-sig[0, 1]), "constraint_error": integ.constraint_error()},
    )
