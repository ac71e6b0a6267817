"""Checkpoint and resume of an event-driven run.

A checkpoint is a netCDF file (written atomically with :func:`jamflow.io.write_dataset`)
holding the complete dynamical state at a synchronisation point — positions, box,
Verlet list with its images, the motion since its build (:class:`.skin.SkinBudget`),
contact network, dt-rule state, self-propulsion forces and generator state — plus
everything recorded so far. The list is restored as saved, built at the saved
positions and box: checkpoints are written at synchronisation points, right after a
rebuild.
Synchronisation points happen every ``sync_every`` steps whether or not a checkpoint
is written, and the solution is recomputed from the state there, so a resumed run
repeats the uninterrupted one bit for bit.
"""

from __future__ import annotations

import os

import numpy as np
import xarray as xr

from ...box import Box
from ...io import new_dataset_attrs, read_dataset, write_dataset
from ...io.binding import check_binding
from ...neighbors.verlet import NeighborList
from .collisions import FLOW_ROOM_SHARE
from .driving import Drive
from .integrate import FlowOptions, FlowState, Integrator
from .recorder import SERIES, Recorder
from .skin import SkinBudget

__all__ = ["load_checkpoint", "save_checkpoint"]


def _v(dims: tuple[str, ...], data, long_name: str) -> tuple:
    return (dims, np.asarray(data), {"units": "1", "long_name": long_name})


def save_checkpoint(path: str | os.PathLike, integ: Integrator, rec: Recorder,
                    binding: dict[str, str]) -> None:
    """Write the full state of ``integ`` and the records so far to ``path`` (atomic).

    ``binding`` (:func:`jamflow.protocols.overdamped.run.run_binding`) is stored as attributes, so
    that only the same run can resume from the file.
    """
    st = integ.state
    nl, budget = st.nl, st.budget
    ev = np.array(st.events, dtype=np.float64).reshape(-1, 5)
    snaps = rec.snapshots
    d = integ.d
    dv = {
        "x": _v(("particle", "spatial"), st.x, "centres [lambda]"),
        "h": _v(("spatial", "lattice_vector"), st.h, "box matrix [lambda]"),
        "radius": _v(("particle",), st.radius, "radii [lambda]"),
        "nl_pairs": _v(("pair", "two"), nl.pairs, "neighbour-list pairs"),
        "nl_images": _v(("pair", "spatial"), nl.image.astype(np.int64), "periodic images of listed pairs"),
        "nl_sigma": _v(("pair",), nl.sigma, "contact distances [lambda]"),
        "nl_displacement": _v(("particle", "spatial"), budget.displacement, "non-affine displacement since list build"),
        "contact": _v(("pair",), st.contact.astype(np.int8), "pair is a contact"),
        "permanent": _v(("pair",), st.permanent.astype(np.int8), "pair is a permanent contact"),
        "events": _v(("event", "event_field"), ev, "events (strain, time, i, j, kind)"),
        "corrections": _v(("correction", "correction_field"), np.array(st.corrections, dtype=np.float64).reshape(-1, 3),
                          "drift corrections (strain, error before, error after)"),
    }
    for k in SERIES:
        dv[f"record_{k}"] = _v(("record",), np.asarray(rec.columns[k], dtype=np.float64), f"recorded {k}")
    if snaps:
        dv["snap_position"] = _v(("snapshot", "particle", "spatial"), np.stack([s["position"] for s in snaps]), "snapshot centres")
        dv["snap_box"] = _v(("snapshot", "spatial", "lattice_vector"), np.stack([s["box"] for s in snaps]), "snapshot box")
        dv["snap_strain"] = _v(("snapshot",), [s["strain"] for s in snaps], "snapshot strain")
        dv["snap_time"] = _v(("snapshot",), [s["time"] for s in snaps], "snapshot time")
        dv["snap_count"] = _v(("snapshot",), [len(s["pairs"]) for s in snaps], "snapshot contact count")
        dv["snap_pairs"] = _v(("snap_contact", "two"), np.concatenate([s["pairs"] for s in snaps]).reshape(-1, 2), "snapshot contacts")
        dv["snap_force"] = _v(("snap_contact",), np.concatenate([s["force"] for s in snaps]), "snapshot forces")
    attrs = {
        "nl_cutoff": nl.reach, "nl_skin": nl.skin, "nl_strain_norm": budget.strain_norm,
        "time": st.time, "strain": st.strain, "step": st.step, "event_interval": st.event_interval,
        "last_event_time": st.last_event_time, "jammed": int(st.jammed), "kappa": st.kappa,
        "next_snapshot": rec.next_snapshot, "d": d, "drive_mode": integ.drive.mode,
        **binding,
    }
    sp = integ.drive.propulsion
    if sp is not None:
        dv["sp_force"] = _v(("particle", "spatial"), sp.force, "self-propulsion forces")
        dv["sp_switch_time"] = _v(("particle",), sp.switch_time, "self-propulsion redraw times")
        attrs["sp_rng_state"] = sp.rng_state()
    ds = xr.Dataset(dv, attrs=new_dataset_attrs("jamflow overdamped checkpoint", {}, **attrs))
    write_dataset(ds, path)


def load_checkpoint(path: str | os.PathLike, drive: Drive, options: FlowOptions,
                    binding: dict[str, str]) -> tuple[Integrator, Recorder]:
    """Rebuild the integrator and recorder from a checkpoint (``drive`` is updated in place).

    The checkpoint must have been written by the same run (``binding``, see
    :func:`jamflow.io.binding.check_binding`).
    """
    ds = read_dataset(path, "checkpoint")
    a = ds.attrs
    check_binding(path, a, binding)
    x, h, radius = ds["x"].values.copy(), ds["h"].values.copy(), ds["radius"].values.copy()
    nl = NeighborList(2.0 * radius, options.skin, room_share=FLOW_ROOM_SHARE)
    pairs = ds["nl_pairs"].values.astype(np.int64)
    nl.restore(pairs[:, 0], pairs[:, 1], ds["nl_images"].values.astype(np.float64), x, Box(h),
               float(a["nl_skin"]), float(a["nl_cutoff"]))
    if not np.array_equal(nl.sigma, ds["nl_sigma"].values):
        raise ValueError(f"checkpoint {path}: the contact distances of its neighbour list disagree with its radii")
    budget = SkinBudget(ds["nl_displacement"].values.copy(), float(a["nl_strain_norm"]))
    st = FlowState(
        x, h, radius, nl, budget,
        ds["contact"].values.astype(bool), ds["permanent"].values.astype(bool),
        time=float(a["time"]), strain=float(a["strain"]), step=int(a["step"]),
        event_interval=float(a["event_interval"]), last_event_time=float(a["last_event_time"]),
        jammed=bool(a["jammed"]), kappa=float(a["kappa"]),
        events=[tuple(row) for row in ds["events"].values.reshape(-1, 5)],
    )
    st.events = [(r[0], r[1], int(r[2]), int(r[3]), int(r[4])) for r in st.events]
    st.corrections = [tuple(float(v) for v in row) for row in ds["corrections"].values.reshape(-1, 3)]
    if drive.propulsion is not None:
        drive.propulsion.force = ds["sp_force"].values.copy()
        drive.propulsion.switch_time = ds["sp_switch_time"].values.copy()
        drive.propulsion.set_rng_state(a["sp_rng_state"])
    integ = Integrator(st, drive, options)
    rec = Recorder()
    for k in SERIES:
        vals = ds[f"record_{k}"].values
        rec.columns[k] = [int(v) for v in vals] if k == "n_contacts" else [float(v) for v in vals]
    rec.next_snapshot = int(a["next_snapshot"])
    if "snap_position" in ds:
        counts = ds["snap_count"].values.astype(np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        pairs = ds["snap_pairs"].values.astype(np.int64)
        forces = ds["snap_force"].values
        for s in range(len(counts)):
            rec.snapshots.append({
                "position": ds["snap_position"].values[s], "box": ds["snap_box"].values[s],
                "strain": float(ds["snap_strain"].values[s]), "time": float(ds["snap_time"].values[s]),
                "pairs": pairs[offsets[s]:offsets[s + 1]], "force": forces[offsets[s]:offsets[s + 1]],
            })
    ds.close()
    return integ, rec
