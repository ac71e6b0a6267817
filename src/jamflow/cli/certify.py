"""Subcommand ``certify``: local, collective or strict jamming certificate of a packing."""

from __future__ import annotations

import argparse

from ..io import read_packing, write_dataset
from ..protocols.certify import (
    DEFAULT_LOADS,
    DEFAULT_MAX_CLUSTER_FRACTION,
    DEFAULT_SOLVER,
    certificate_to_dataset,
    certify,
)
from ..state.packing import OverlapError, Packing
from .common import (
    add_command,
    add_preset,
    add_quiet,
    print_summary,
    progress_bar,
    stage_parameters,
)
from .packings import add_overlap_option, overlap_tol
from .types import integer, non_negative, path_with_suffix, probability, seed

#: Most random loads per LP kind: each load is two LPs, and a certificate that 1000 loads
#: have not decided is not decided by more.
MAX_LOADS = 1000


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "certify", _certify,
        "certify a packing as not / locally / collectively / strictly jammed (randomized LPs)",
        description="Jamming certificate after Donev et al., J. Comput. Phys. 197, 139 (2004): "
                    "rattlers are removed, then random loads of both signs probe for unjamming "
                    "motions at fixed box (collective) and, with --strict, with a volume-preserving "
                    "box strain. Writes a dataset with attribute 'classification'.",
        reads=("packing",), writes=("out",), makes={"out": ("certificate", "chain-certificate")},
    )
    p.add_argument("packing", help="input netCDF packing")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF certificate")
    p.add_argument("--strict", action="store_true", help="also test strict jamming (box may deform at fixed volume)")
    p.add_argument("--gap-tol", type=non_negative, default=None,
                   help="pairs with relative gap <= T are contacts, with gap-aware constraints; "
                        "default: the packing's own contacts as exact contacts")
    p.add_argument("--exact", action="store_true",
                   help="with --gap-tol: treat the pairs as exact contacts (zero right-hand side)")
    p.add_argument("--loads", type=integer(1, MAX_LOADS), default=DEFAULT_LOADS,
                   help=f"random loads per LP kind, each with both signs (default {DEFAULT_LOADS})")
    p.add_argument("--seed", type=seed, default=0, help="seed of the random loads (default 0)")
    p.add_argument("--max-cluster-fraction", type=probability, default=DEFAULT_MAX_CLUSTER_FRACTION,
                   help="largest non-wrapping moving group removed as a rattling cluster, as a fraction "
                        f"of the backbone (default {DEFAULT_MAX_CLUSTER_FRACTION})")
    p.add_argument("--solver", choices=["ipm", "simplex", "choose"], default=DEFAULT_SOLVER,
                   help=f"HiGHS algorithm for the collective and strict LPs (default {DEFAULT_SOLVER})")
    p.add_argument("--lp-only", action="store_true",
                   help="decide every backbone by the motion LPs (default: a clear Roth-Whiteley test, "
                        "full rank and a positive self stress, decides exact-contact backbones without them)")
    add_overlap_option(p)
    add_quiet(p)
    add_preset(p)


def _certify(args: argparse.Namespace) -> int:
    if args.exact and args.gap_tol is None:
        raise ValueError("--exact needs --gap-tol (explicit contacts are always exact)")
    packing = read_packing(args.packing, None)
    if packing.links is not None and len(packing.links):
        from .chains import certify_linked_packing

        # the linked certificate's contacts are the overlapping pairs (soft-jam's contacts)
        return certify_linked_packing(args, packing)
    _check_overlaps(args, packing)
    with progress_bar(args.quiet, desc="certify LPs", unit="LP") as bar:
        cert = certify(
            packing,
            strict=args.strict,
            gap_tol=args.gap_tol,
            rhs="zero" if args.exact else None,
            loads=args.loads,
            seed=args.seed,
            max_cluster_fraction=args.max_cluster_fraction,
            solver=args.solver,
            self_stress_test=not args.lp_only,
            progress=bar,
        )
    write_dataset(certificate_to_dataset(cert, packing, stage_parameters(args, "packing", "out")), args.out)
    print_summary(args, args.out, [("classification", cert.classification),
                                   ("rattlers", int(cert.rattler.sum())), ("LPs", len(cert.lp)),
                                   ("self-stress decisions", cert.self_stress_decisions)])
    return 0


def _check_overlaps(args: argparse.Namespace, packing: Packing) -> None:
    """Refuse overlaps beyond the tolerance, saying how to certify a soft packing on its own contacts."""
    try:
        packing.validate(overlap_tol(args))
    except OverlapError as exc:
        soft = " (written by soft-jam)" if packing.protocol.split(">")[-1].startswith("soft") else ""
        raise OverlapError(f"{exc}: a soft packing{soft} is certified on its stored contacts with --soft") from None
