"""Subcommands on packings themselves: init, import-dat, export-xyz, check."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from ..analysis.contacts import summarize
from ..analysis.structure import crystal_fraction, hexatic_order
from ..chains.dimers import dimer_report
from ..io import read_dataset, read_packing, write_packing
from ..io.formats import gsd_types, read_dat, size_classes, write_gsd, write_xyz
from ..network import count_bodies
from ..network.spheres import contact_network
from ..protocols.initial import random_packing
from ..protocols.overdamped.run import snapshot_packings
from ..resources import check_fits
from ..state.packing import Packing
from ..tolerances import OVERLAP_TOL
from .common import (
    add_command,
    add_quiet,
    format_rows,
    packing_rows,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .types import (
    count,
    integer,
    non_negative,
    packing_fraction,
    path_with_suffix,
    positive,
    probability,
    seed,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "init", _init, "random non-overlapping packing at a packing fraction", writes=("out",), packings=("out",))
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    p.add_argument("--d", type=integer(2), required=True, help="dimension (>= 2)")
    p.add_argument("--n", type=count, required=True, help="number of particles")
    p.add_argument("--phi", type=packing_fraction, required=True, help="packing fraction")
    p.add_argument("--dispersity", choices=["mono", "bi", "poly", "lognormal"], default="mono")
    p.add_argument("--ratio", type=positive, default=1.4, help="bidisperse size ratio (default 1.4)")
    p.add_argument("--fraction", type=probability, default=0.5,
                   help="bidisperse number fraction of small spheres (default 0.5)")
    p.add_argument("--width", type=non_negative, default=0.1, help="polydisperse relative width (default 0.1)")
    p.add_argument("--species-spread", type=non_negative, default=0.0,
                   help="bidisperse: relative standard deviation within each species (default 0)")
    p.add_argument("--seed", type=seed, required=True, help="random seed")
    p.add_argument("--walls", action="store_true",
                   help="every sphere inside the box (a start for calippso --walls, hard walls on the faces)")
    add_quiet(p)

    p = add_command(sub, "import-dat", _import_dat, "read a CALiPPSO .dat configuration",
                    reads=("dat",), writes=("out",), packings=("out",))
    p.add_argument("dat", help="input .dat file (d, N, diameter, positions)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "export-xyz", _export_xyz,
                    "write extended XYZ (OVITO, ASE) or, for links, HOOMD GSD (OVITO): types, radius, rattler, "
                    "forces, orientations, bonds",
                    "One frame for a packing; one frame per snapshot for a flow snapshot file (OUT.snapshots.nc "
                    "of compress, shear or drive --snapshots N). Columns: type (size class: sphere, small/large, "
                    "size1..sizeK, or poly), pos, radius, rattler (0/1, when known), force_sum (sum of contact-force "
                    "magnitudes) and force_residual (|net contact force| / mean force), when the input has forces; "
                    "shaped bodies add shape_index, angle, orientation (quaternion) and, with ellipses, "
                    "aspherical_shape. OUT ending in .gsd writes a HOOMD GSD file instead, which OVITO reads with "
                    "bonds: the links of chains and clusters (extended XYZ cannot hold bonds, so a packing with "
                    "links needs .gsd), orientations as quaternions, one particle type per shape with its "
                    "type_shapes entry, the other columns as log/particles/<name>; GSD stores positions in "
                    "single precision.",
                    reads=("packing",), writes=("out",), makes={"out": ()})
    p.add_argument("packing", help="input netCDF packing or flow snapshot file")
    p.add_argument("out", type=path_with_suffix(".xyz", ".gsd"),
                   help="output .xyz (extended XYZ) or .gsd (HOOMD GSD with links as bonds)")
    p.add_argument("--pos-2d", action="store_true",
                   help="2D: write x and y only (pos:R:2), which OVITO reads as a 2D system; ASE cannot read it")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "check", _check, "contacts, rattlers, isostaticity, overlaps, force balance",
                    reads=("packing",))
    p.add_argument("packing", help="input netCDF packing")
    p.add_argument("--gap-tol", type=non_negative, default=None,
                   help="relative gap counted as contact; default: the packing's own contacts, "
                        "else jamflow.tolerances.CONTACT_GAP_TOL")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true",
                   help="accepted like every command's --quiet; check has no progress output and always "
                        "prints its report, which is its result")
    p.add_argument("--parallel-contacts", choices=["once", "twice"], default="once",
                   help="shape packings: count a parallel or nearly parallel circulo contact once (default) "
                        "or twice (VanderWerf et al. Fig. 6)")
    add_overlap_option(p, default=None)


def add_overlap_option(p: argparse.ArgumentParser, default: float | None = OVERLAP_TOL) -> None:
    """``--overlap-tol`` / ``--soft`` for commands that read a packing."""
    p.add_argument("--overlap-tol", type=non_negative, default=default,
                   help=f"largest accepted relative overlap when reading (default {default})")
    p.add_argument("--soft", action="store_true", help="accept overlaps (soft packings)")


def overlap_tol(args: argparse.Namespace) -> float | None:
    """The overlap tolerance chosen by ``--overlap-tol`` / ``--soft``."""
    return None if args.soft else args.overlap_tol


def _init(args: argparse.Namespace) -> int:
    check_fits("init", args.n, args.d, "spheres")
    # delay: no bar for quick runs, nor before a one-line error on bad input
    with progress_bar(args.quiet, total=args.n, desc="init (RSA)", unit="sphere", delay=1.0) as bar:
        p = random_packing(args.n, args.d, args.phi, args.dispersity, args.seed,
                           args.ratio, args.fraction, args.width, args.species_spread,
                           progress=bar.update, walls=args.walls)
    write_packing(p, args.out, stage_parameters(args, "out"))
    print_summary(args, args.out, packing_rows(p))
    return 0


def _import_dat(args: argparse.Namespace) -> int:
    packing = read_dat(args.dat)
    try:
        # a hard-sphere file with overlaps is refused here, not by the first stage that reads it
        packing.validate(overlap_tol(args))
    except ValueError as exc:
        raise ValueError(f"{args.dat}: {exc} (--soft or --overlap-tol to accept)") from exc
    write_packing(packing, args.out)
    print_summary(args, args.out, packing_rows(packing))
    return 0


def _export_xyz(args: argparse.Namespace) -> int:
    ds = read_dataset(args.packing)
    if "snapshot_position" in ds:
        frames = snapshot_packings(ds)
        for frame in frames:
            frame.validate(overlap_tol(args))
    elif "step" in ds.dims:
        raise ValueError(f"{args.packing} is a flow time series without positions; export its snapshot file "
                         "(run with --snapshots N, written to OUT.snapshots.nc)")
    else:
        frame = read_packing(args.packing, None)
        if frame.shapes is None:
            # shaped bodies overlap by their energy model's contact distance, not the spheres' check
            frame.validate(overlap_tol(args))
        frames = [frame]
    if str(args.out).endswith(".gsd"):
        if args.pos_2d:
            raise ValueError("--pos-2d is for .xyz output; a .gsd file marks 2D itself")
        write_gsd(frames, args.out)
    else:
        if frames[0].links is not None:
            raise ValueError(f"{args.packing} has {len(frames[0].links)} links, which extended XYZ cannot hold; "
                             "write OUT.gsd (HOOMD GSD, links as bonds)")
        if args.pos_2d and frames[0].d != 2:
            raise ValueError(f"--pos-2d is for 2D packings, got d = {frames[0].d}")
        write_xyz(frames, args.out, pos_2d=args.pos_2d)
    gsd = str(args.out).endswith(".gsd")
    names = (gsd_types if gsd else lambda p: size_classes(p.diameter))(frames[0])[0]
    rows = packing_rows(frames[0]) if len(frames) == 1 else [("frames", len(frames)), ("N, d", f"{frames[0].n}, "
                                                                                             f"{frames[0].d}")]
    links = [] if frames[0].links is None else [("bonds (links)", len(frames[0].links))]
    print_summary(args, args.out, [*rows, ("particle types", " ".join(names)), *links])
    return 0


def _check_bodies(args: argparse.Namespace, packing: Packing) -> int:
    """What check can say of links and shapes: how well links hold, and the counting of each body model.

    Linked spheres get the cluster count of :func:`jamflow.network.count_bodies`
    (convention in :mod:`jamflow.network.bodies`) over the packing's stored contacts (or, with
    ``--gap-tol`` or none stored, pairs within the gap tolerance), never linked pairs;
    packings of dimers add rotators and ``<z>`` (:func:`jamflow.chains.dimers.dimer_report`).
    Shape packings of a family with an energy model get the counting of
    :mod:`jamflow.shapes.counting` (contacts, rattlers, sliders, ``<z>`` of Eq. 3,
    isostatic count ``3N' - 1 - N_s``). Linked shapes are not counted.
    """
    report: dict = {"N": packing.n, "d": packing.d, "phi": packing.packing_fraction}
    links_counted = packing.links is not None and packing.shapes is None
    shapes_counted = False
    if packing.links is not None:
        err = packing.links.length_errors(packing.position, packing.box)
        report.update(n_links=len(packing.links), n_clusters=int(packing.clusters.max(initial=-1)) + 1,
                      max_link_error=float(np.max(np.abs(err), initial=0.0)))
    if links_counted:
        source = "stored" if args.gap_tol is None and packing.contacts is not None else "gap"
        contacts = contact_network(packing, args.gap_tol)
        contacts = contacts[~packing.links.contains(contacts[:, 0], contacts[:, 1])]
        stabilized = bool(packing.attrs.get("shear_stabilized", 0))
        count = count_bodies(contacts, packing.n, packing.d, packing.links, packing.position, packing.box,
                             shear_stabilized=stabilized)
        if packing.d == 2:
            psi = hexatic_order(packing)
            report.update(psi6_local_mean=float(np.abs(psi).mean()), psi6_global=float(np.abs(psi.mean())),
                          crystal_fraction=crystal_fraction(packing))
        report.update({**count.as_dict(), "contact_source": source, "shear_stabilized": stabilized, **dimer_report(count, packing.d)})
    if packing.shapes is not None:
        kinds, counts = np.unique(packing.shapes.kind[packing.shape_index], return_counts=True)
        report["shapes"] = {str(k): int(c) for k, c in zip(kinds, counts)}
        if packing.links is None and _counted_family(kinds):
            from ..shapes.counting import count_constraints

            counting, *_ = count_constraints(packing, args.parallel_contacts)
            report.update(counting.as_dict())
            shapes_counted = True
    if args.json:
        print(json.dumps(report))
        return 0
    rows = [("N", report["N"]), ("d", report["d"]), ("packing fraction", f"{report['phi']:.10f}")]
    if "n_links" in report:
        rows += [("links", f"{report['n_links']} in {report['n_clusters']} clusters"),
                 ("max link-length error", f"{report['max_link_error']:.3e} (relative)")]
    if links_counted:
        rows += [("contacts (backbone)", f"{report['n_contacts']}  [{report['contact_source']}]"),
                 ("rattlers", f"{report['n_rattlers']} ({report['n_rattling_clusters']} rattling clusters: "
                              f"{report['n_clusters_removed']} removed whole, {report['n_danglers']} danglers "
                              f"with {report['free_dofs']} free motions)"),
                 ("isostatic", f"{str(report['isostatic']).lower()}  (N_c = {report['n_contacts']}, "
                               f"sum (f_c - m_c) - d + 1{' + d(d+1)/2 - 1' if stabilized else ''} = "
                               f"{report['isostatic_count']}: {report['rigidity_counting']})")]
        if "psi6_local_mean" in report:
            rows.append(("hexatic order |psi6|", f"local mean {report['psi6_local_mean']:.4f}, global "
                                                 f"{report['psi6_global']:.4f}, crystal-like fraction "
                                                 f"{report['crystal_fraction']:.4f} (sphere centres)"))
        if "n_dimers" in report:
            rows += [("dimers", f"{report['n_dimers']} ({report['n_rotators']} rotators, "
                                f"{report['n_rattling_dimers']} rattling)"),
                     ("coordination <z> (Eq. 3)", f"{report['z']:.6f} (isostatic: {2 * (2 * packing.d - 1)})")]
    if "shapes" in report:
        rows.append(("shapes", ", ".join(f"{c} {k}" for k, c in report["shapes"].items())))
    if shapes_counted:
        rows += [("contacts (non-rattlers)", f"{report['n_contacts']} (parallel contacts counted {report['parallel']})"),
                 ("rattlers, sliders", f"{report['n_rattlers']}, {report['n_sliders']}"),
                 ("z = 2 N_c / N'", f"{report['z_contacts']:.6f} (contacts per backbone body)"),
                 ("<z> Eq. 3 = 2 (N_c + 1) / (N - N_r - N_s / f)",
                  f"{report['z_eq3']:.6f} (isostatic: {2 * report['dofs_per_body']}; f = {report['dofs_per_body']})"),
                 ("isostatic count 3N' - 1 - N_s", f"{report['isostatic_count']} ({report['counting']})")]
    elif "shapes" in report:
        rows.append(("contacts, rattlers", "not counted for linked shapes"))
    print(format_rows(rows))
    return 0


def _counted_family(kinds: np.ndarray) -> bool:
    """Whether the shape counting covers these kinds (one family with contact points)."""
    from ..models.shapes import shape_family
    from ..shapes.counting import COUNTED_FAMILIES

    try:
        return shape_family(kinds) in COUNTED_FAMILIES
    except ValueError:
        return False


def _check(args: argparse.Namespace) -> int:
    # check reports overlaps instead of refusing the file
    packing = read_packing(args.packing, overlap_tol(args))
    if packing.links is not None or packing.shapes is not None:
        return _check_bodies(args, packing)
    s = summarize(packing, args.gap_tol)
    if args.json:
        out = s.as_dict()
        out = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}
        print(json.dumps(out))
        return 0
    rows = [
        ("N", s.N), ("d", s.d), ("packing fraction", f"{s.phi:.10f}"),
        ("pressure", "unknown" if s.pressure is None else f"{s.pressure:.6g}"),
        ("contacts (backbone)", f"{s.n_contacts}  [{s.contact_source}]"),
        ("rattlers", s.n_rattlers), ("non-rattlers", s.n_stable),
        ("isostatic", f"{str(s.isostatic).lower()}  (N_c = {s.n_contacts}, d(N_s-1)+1 = {s.isostatic_count}: "
                      f"{s.counting})"),
        ("z = 2 N_c / N'", f"{s.z:.6f} (contacts per non-rattler)"),
        *([("<z> Eq. 3 (VanderWerf) = 2 (N_c + 1) / N'", f"{2.0 * (s.n_contacts + 1) / s.n_stable:.6f} (isostatic: 4)")]
          if s.d == 2 and s.n_stable else []),
        ("max overlap", f"{s.max_overlap:.3e} (relative to the mean diameter: {s.max_overlap_rel:.3e})"),
        ("max force-balance residual", "no forces" if s.force_balance_residual is None
         else f"{s.force_balance_residual:.3e} (relative to mean force)"),
    ]
    if s.force_balance_residual is not None and "force_assignment" in packing.attrs:
        rows.append(("force assignment", packing.attrs["force_assignment"]))
    print(format_rows(rows))
    return 0
