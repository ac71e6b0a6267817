"""Subcommands on packings themselves: init, import-dat, export-xyz, check."""

from __future__ import annotations

import argparse
import json
import math

from tqdm import tqdm

from ..analysis.contacts import summarize
from ..initial import random_packing
from ..io import read_dat, read_packing, write_packing, write_xyz
from ..tolerances import OVERLAP_TOL
from .common import add_command, add_quiet, seed, stage_parameters


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "init", _init, "random non-overlapping packing at a packing fraction", writes=("out",), packings=("out",))
    p.add_argument("out", help="output netCDF")
    p.add_argument("--d", type=int, required=True, help="dimension (>= 2)")
    p.add_argument("--n", type=int, required=True, help="number of particles")
    p.add_argument("--phi", type=float, required=True, help="packing fraction")
    p.add_argument("--dispersity", choices=["mono", "bi", "poly", "lognormal"], default="mono")
    p.add_argument("--ratio", type=float, default=1.4, help="bidisperse size ratio (default 1.4)")
    p.add_argument("--fraction", type=float, default=0.5, help="bidisperse number fraction of small spheres (default 0.5)")
    p.add_argument("--width", type=float, default=0.1, help="polydisperse relative width (default 0.1)")
    p.add_argument("--species-spread", type=float, default=0.0,
                   help="bidisperse: relative standard deviation within each species (default 0)")
    p.add_argument("--seed", type=seed, required=True, help="random seed")
    p.add_argument("--walls", action="store_true",
                   help="every sphere inside the box (a start for calippso --walls, hard walls on the faces)")
    add_quiet(p)

    p = add_command(sub, "import-dat", _import_dat, "read a CALiPPSO .dat configuration",
                    reads=("dat",), writes=("out",), packings=("out",))
    p.add_argument("dat", help="input .dat file (d, N, diameter, positions)")
    p.add_argument("out", help="output netCDF")
    add_overlap_option(p)
    add_quiet(p)

    p = add_command(sub, "export-xyz", _export_xyz, "write extended XYZ (OVITO) with a radius column",
                    reads=("packing",), writes=("out",))
    p.add_argument("packing", help="input netCDF packing")
    p.add_argument("out", help="output .xyz")
    add_overlap_option(p)

    p = add_command(sub, "check", _check, "contacts, rattlers, isostaticity, overlaps, force balance",
                    reads=("packing",))
    p.add_argument("packing", help="input netCDF packing")
    p.add_argument("--gap-tol", type=float, default=None,
                   help="relative gap counted as contact; default: the packing's own contacts, "
                        "else jamflow.tolerances.CONTACT_GAP_TOL")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_overlap_option(p, default=None)


def add_overlap_option(p: argparse.ArgumentParser, default: float | None = OVERLAP_TOL) -> None:
    """``--overlap-tol`` / ``--soft`` for commands that read a packing."""
    p.add_argument("--overlap-tol", type=float, default=default,
                   help=f"largest accepted relative overlap when reading (default {default})")
    p.add_argument("--soft", action="store_true", help="accept overlaps (soft packings)")


def overlap_tol(args: argparse.Namespace) -> float | None:
    """The overlap tolerance chosen by ``--overlap-tol`` / ``--soft``."""
    return None if args.soft else args.overlap_tol


def _init(args: argparse.Namespace) -> int:
    # delay: no bar for quick runs, nor before a one-line error on bad input
    with tqdm(total=args.n, desc="init (RSA)", unit="sphere", disable=args.quiet, delay=1.0) as bar:
        p = random_packing(args.n, args.d, args.phi, args.dispersity, args.seed,
                           args.ratio, args.fraction, args.width, args.species_spread,
                           progress=bar.update, walls=args.walls)
    write_packing(p, args.out, stage_parameters(args, "out"))
    return 0


def _import_dat(args: argparse.Namespace) -> int:
    packing = read_dat(args.dat)
    try:
        # a hard-sphere file with overlaps is refused here, not by the first stage that reads it
        packing.validate(overlap_tol(args))
    except ValueError as exc:
        raise ValueError(f"{args.dat}: {exc} (--soft or --overlap-tol to accept)") from exc
    write_packing(packing, args.out)
    return 0


def _export_xyz(args: argparse.Namespace) -> int:
    write_xyz(read_packing(args.packing, overlap_tol(args)), args.out)
    return 0


def _check(args: argparse.Namespace) -> int:
    # check reports overlaps instead of refusing the file
    packing = read_packing(args.packing, overlap_tol(args))
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
        ("isostatic", f"{str(s.isostatic).lower()}  (N_c = {s.n_contacts}, d(N_s-1)+1 = {s.isostatic_count})"),
        ("coordination z", f"{s.z:.6f}"),
        ("max overlap", f"{s.max_overlap:.3e} (relative to the mean diameter: {s.max_overlap_rel:.3e})"),
        ("max force-balance residual", "no forces" if s.force_balance_residual is None
         else f"{s.force_balance_residual:.3e} (relative to mean force)"),
    ]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0
