"""Linked-packing subcommands: init-chains (random chains and rigid clusters), link (cement, link files)."""

from __future__ import annotations

import argparse
import sys
from math import radians

import numpy as np
import xarray as xr

from ..chains.averages import moduli_against_links
from ..chains.builders import (
    CLUSTER_KINDS,
    DILUTE_PHI,
    OVERLAP_PHI,
    SIZE_CLASSES,
    Sizes,
    cement_links,
    cement_pairs,
    check_linked_start,
    linked_packing,
    read_link_file,
    remove_degenerate_links,
)
from ..chains.certify import certify_linked
from ..chains.dimers import DIMER_DIAMETER_RATIO, DIMER_SEPARATION, DIMER_SIZE_RATIO
from ..io import (
    new_dataset_attrs,
    read_dataset,
    read_packing,
    write_dataset,
    write_packing,
)
from ..resources import check_fits
from .common import (
    add_command,
    add_quiet,
    packing_rows,
    print_summary,
    split_paths,
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
    real,
    seed,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "init-chains", _init_chains,
                    "random start of chains or rigid trimers of unit spheres, or of bidisperse asymmetric dimers "
                    "(links, no overlaps unless --overlap; no crossing links in 2D)", writes=("out",),
                    packings=("out",))
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF packing with links")
    p.add_argument("--d", type=integer(2, 3), required=True, help="dimension (2 or 3)")
    p.add_argument("--clusters", type=count, required=True, help="number of clusters K (N = K M spheres)")
    p.add_argument("--cluster", choices=CLUSTER_KINDS, required=True,
                   help="trimer: three spheres with the bond angle frozen (rigid); chain: --chain-length spheres; "
                        "dimer: a small and a large monomer at a fixed distance (van der Werf et al. Fig. 3b), "
                        "half of the dimers scaled by --size-ratio")
    p.add_argument("--chain-length", type=integer(2), default=3, help="spheres per chain M (default 3)")
    p.add_argument("--free-angles", action="store_true",
                   help="bonds only (flexible); default: every bond angle frozen by an angle link")
    semi = p.add_mutually_exclusive_group()
    semi.add_argument("--frozen-fraction", type=probability, default=None,
                      help="chain: semi-flexible, each bond angle frozen with this probability (seeded)")
    semi.add_argument("--frozen-every", type=count, default=None,
                      help="chain: semi-flexible, the bond angle at every k-th sphere frozen (k = 1: all)")
    p.add_argument("--bond-angle", type=real(0.0, 180.0, lo_open=True, need="an angle in (0, 180] degrees"),
                   default=None,
                   help="every bond angle [degrees]; default uniform in [60, 150] degrees")
    p.add_argument("--diameter-ratio", type=positive, default=DIMER_DIAMETER_RATIO,
                   help=f"dimer: large over small monomer diameter (default {DIMER_DIAMETER_RATIO})")
    p.add_argument("--separation", type=positive, default=DIMER_SEPARATION,
                   help=f"dimer: monomer centre distance in small-monomer diameters (default {DIMER_SEPARATION}, "
                        f"the paper's A - 1 = 0.349)")
    p.add_argument("--size-ratio", type=positive, default=DIMER_SIZE_RATIO,
                   help=f"dimer: length of large over small dimers (default {DIMER_SIZE_RATIO})")
    p.add_argument("--dispersity", choices=["mono", "bi", "poly", "lognormal"], default="mono",
                   help="chains and trimers: size mixture as `jamflow init` (default mono: unit spheres; equal "
                        "spheres partly crystallise in 2D)")
    p.add_argument("--ratio", type=real(1.0, lo_open=True, need="a size ratio > 1"), default=1.4,
                   help="bidisperse size ratio large / small (default 1.4)")
    p.add_argument("--fraction", type=probability, default=0.5,
                   help="bidisperse number fraction of small clusters (or spheres) (default 0.5)")
    p.add_argument("--width", type=non_negative, default=0.1, help="poly / lognormal relative width (default 0.1)")
    p.add_argument("--sizes-per", choices=SIZE_CLASSES, default="cluster",
                   help="one size class per cluster (a scaled copy, default) or per sphere (bonds are the "
                        "contact distances)")
    p.add_argument("--phi", type=packing_fraction, default=None,
                   help=f"packing fraction of the union of each cluster's spheres (default without overlaps {DILUTE_PHI[2]} in 2D, {DILUTE_PHI[3]} in 3D; "
                        f"with --overlap "
                        f"{OVERLAP_PHI[2]} in 2D, {OVERLAP_PHI[3]} in 3D)")
    start = p.add_mutually_exclusive_group()
    start.add_argument("--no-overlap", dest="no_overlap", action="store_true", default=True,
                       help="place clusters without overlaps (random sequential placement, dilute; the default)")
    start.add_argument("--overlap", dest="no_overlap", action="store_false",
                       help="the paper's Sec. III start above jamming with overlaps: links can pass through each "
                            "other during soft-jam and a third of such starts end entangled, which soft-jam refuses "
                            "(docs/notes/chains.md)")
    p.add_argument("--seed", type=seed, required=True, help="random seed")
    add_quiet(p)

    p = add_command(sub, "link", _link,
                    "add links to a packing: cement K random contacts (freezing the bond angles they create) "
                    "or read a link file", reads=("input", "file"), writes=("out",), packings=("out",))
    p.add_argument("input", help="input netCDF packing (with contacts for --cement)")
    p.add_argument("out", type=path_with_suffix(".nc"), help="output netCDF packing with links")
    group = p.add_mutually_exclusive_group(required=True)
    group.add_argument("--cement", type=count, default=None, help="number of random contacts turned into links")
    group.add_argument("--file", default=None,
                       help="text file of links, one 'i j [length]' per line (length: current distance if omitted)")
    p.add_argument("--seed", type=seed, default=None, help="random seed of --cement")
    p.add_argument("--with-strain", action="store_true",
                   help="judge degenerate links with the strain degrees of freedom (keeps links that close loops "
                        "around the box and fix its shape: for moduli; such packings cannot be minimised in a "
                        "fixed box)")
    add_quiet(p)

    p = add_command(sub, "chains-moduli", _chains_moduli,
                    "moduli of cemented packings against the added links per sphere n_l / N (chains paper Fig. 5)",
                    "Groups `jamflow moduli` outputs of packings made by `jamflow link --cement` by n_l / N and "
                    "averages each group's Hill moduli weighted by their Reuss-Voigt spread, with the weighted "
                    "standard error; infinite moduli are counted, not averaged (jamflow.chains.averages).",
                    reads=("paths[:-1]",), writes=("paths[-1]",),
                    makes={"paths[-1]": ("chains-moduli-table",)})
    p.add_argument("paths", nargs="+", metavar="MODULI.nc ... OUT.nc", help="moduli datasets, then the output")
    add_quiet(p)


def _messages(messages: list[str]) -> None:
    for line in messages:
        print(f"jamflow: {line}", file=sys.stderr)


def _link_rows(packing) -> list[tuple[str, object]]:
    links = packing.links
    err = np.abs(links.length_errors(packing.position, packing.box))
    clusters = packing.clusters
    sizes = np.bincount(clusters)
    return [*packing_rows(packing), ("links", len(links)),
            ("clusters", f"{int((sizes > 1).sum())} linked (+ {int((sizes == 1).sum())} free spheres)"),
            ("max link-length error", f"{float(err.max(initial=0.0)):.3e} (relative)")]


def _init_chains(args: argparse.Namespace) -> int:
    per_cluster = {"trimer": 3, "dimer": 2}.get(args.cluster, args.chain_length)
    check_fits("init-chains", args.clusters * per_cluster, args.d, "spheres")
    angle = None if args.bond_angle is None else radians(args.bond_angle)
    sizes = Sizes(args.dispersity, args.ratio, args.fraction, args.width, args.sizes_per)
    packing, messages = linked_packing(args.d, args.clusters, args.cluster, np.random.default_rng(args.seed),
                                       args.chain_length, args.free_angles, args.phi, angle,
                                       args.no_overlap, args.diameter_ratio, args.size_ratio, args.separation,
                                       sizes=None if args.cluster == "dimer" and args.dispersity == "mono" else sizes,
                                       frozen_fraction=args.frozen_fraction, frozen_every=args.frozen_every)
    _messages(messages)
    packing = packing.evolve(seed=args.seed)
    write_packing(packing, args.out, stage_parameters(args, "out"))
    shape = [("dimer asphericity A", f"{packing.attrs['asphericity']:.6f}")] if "asphericity" in packing.attrs else []
    if "frozen_angle_rule" in packing.attrs:
        shape.append(("frozen bond angles", f"{packing.attrs['n_frozen_angles']} of "
                                            f"{args.clusters * (packing.attrs['chain_length'] - 2)} "
                                            f"({packing.attrs['frozen_angle_rule']})"))
    if packing.attrs.get("dispersity", "mono") != "mono":
        D = packing.diameter
        shape.append(("diameters", f"{args.dispersity} per {args.sizes_per}: {D.min():.4g} .. {D.max():.4g} "
                                   f"(mean {D.mean():.4g})"))
    print_summary(args, args.out, [*_link_rows(packing), *shape, ("degenerate links removed", len(messages))])
    return 0


def _link(args: argparse.Namespace) -> int:
    packing = read_packing(args.input, None)
    if args.cement is not None:
        if args.seed is None:
            raise ValueError("--cement needs --seed")
        new = cement_pairs(packing, args.cement, np.random.default_rng(args.seed))
        links, messages = cement_links(packing, new, args.with_strain)
        protocol = f">cement({args.cement})"
    else:
        pairs, lengths = read_link_file(args.file, packing.position, packing.box)
        if packing.links is not None:
            pairs = np.concatenate([np.stack([packing.links.i, packing.links.j], axis=1), pairs])
            lengths = np.concatenate([packing.links.length, lengths])
        links, messages = remove_degenerate_links(pairs, lengths, packing.position, packing.box, args.with_strain)
        protocol = ">link-file"
    _messages(messages)
    keep = None
    if packing.contacts is not None:
        keep = ~links.contains(packing.contacts[:, 0], packing.contacts[:, 1])
    # paper Fig. 5's n_l: cemented contacts kept as links (angle links not counted)
    attrs = dict(packing.attrs)
    if args.cement is not None:
        attrs["n_cemented"] = int(packing.attrs.get("n_cemented", 0)) + int(links.contains(new[:, 0], new[:, 1]).sum())
    out = packing.evolve(
        links=links, protocol=packing.protocol + protocol, attrs=attrs,
        contacts=None if keep is None else packing.contacts[keep],
        force=None if keep is None or packing.force is None else packing.force[keep], rattler=None,
        seed=args.seed if args.cement is not None else packing.seed,
    )
    if args.file is not None:
        check_linked_start(out)
    write_packing(out, args.out, stage_parameters(args, "input", "out"))
    rows = [*_link_rows(out), ("degenerate links removed", len(messages))]
    if args.cement is not None:
        rows.append(("cemented contacts n_l", f"{attrs['n_cemented']} (n_l / N = {attrs['n_cemented'] / out.n:.4g})"))
    print_summary(args, args.out, rows)
    return 0


def _chains_moduli(args: argparse.Namespace) -> int:
    inputs, out = split_paths(args.paths, "moduli dataset")
    datasets = [read_dataset(path, "chain-moduli") for path in inputs]
    for path, ds in zip(inputs, datasets):
        if "n_cemented" not in ds.attrs:
            raise ValueError(f"{path} has no n_cemented attribute (moduli of a packing made by jamflow link --cement)")
        if "n_unstable" not in ds.attrs:
            raise ValueError(f"{path} has no n_unstable attribute (written by an older jamflow moduli: rerun it)")
    table = moduli_against_links(datasets)
    table.attrs = new_dataset_attrs("jamflow moduli of cemented packings against n_l / N",
                                    stage_parameters(args, "paths"), d=int(datasets[0].attrs["d"]),
                                    method=("Reuss-Voigt weighted average (chains paper Fig. 5): Hill values "
                                            "weighted by 1 / ((V - R)^2 / 12), scatter standard error"))
    write_dataset(table, out)
    rows = []
    for k in range(table.sizes["links_per_sphere"]):
        t = table.isel(links_per_sphere=k)
        value = (f"G = {float(t.shear_weighted):.5g} +- {float(t.shear_se):.2g}, "
                 f"K = {float(t.bulk_weighted):.5g} +- {float(t.bulk_se):.2g} epsilon / <D>^d "
                 f"(infinite: G {int(t.shear_infinite)}, K {int(t.bulk_infinite)})")
        label = f"n_l / N = {float(t.links_per_sphere):.4g} ({int(t.n_packings)} packings"
        label += f", {int(t.n_unstable)} unstable, not averaged)" if int(t.n_unstable) else ")"
        rows.append((label, value))
    print_summary(args, out, rows)
    return 0


def certify_linked_packing(args: argparse.Namespace, packing) -> int:
    """``jamflow certify`` of a linked packing: the chain LP of Sec. V on ``R_E`` (collective, and strict
    with ``--strict``); contacts are the overlapping unlinked pairs."""
    if args.gap_tol is not None or args.exact:
        raise ValueError("--gap-tol and --exact are for spheres; a linked packing is certified on its "
                         "overlapping (soft) contacts")
    cert = certify_linked(packing, strict=args.strict, loads=args.loads, seed=args.seed,
                          max_cluster_fraction=args.max_cluster_fraction, solver=args.solver)
    motion = np.zeros((packing.n, packing.d)) if cert.motion is None else cert.motion
    ds = xr.Dataset(
        data_vars={
            "chain_rattler": (("particle",), cert.rattler.astype(np.int8),
                              {"units": "1", "long_name": "outside the certified backbone (1) or in it (0)"}),
            "chain_motion": (("particle", "spatial"), motion,
                             {"units": "1", "long_name": "unjamming displacement (zero if none was found)",
                              "comment": "mean diameters, tangent coordinates bounded by 1"}),
        },
        attrs=new_dataset_attrs("jamflow chain jamming certificate", stage_parameters(args, "packing", "out"),
                                classification=cert.classification, motion_stage=cert.motion_stage,
                                n_lp=cert.n_lp, strict_tested=int(args.strict), d=packing.d, N=packing.n,
                                n_links=len(packing.links), n_clusters_removed_by_lp=int(cert.lp_removed.sum()),
                                **{k: v for k, v in cert.count.as_dict().items()
                                   if k in ("n_rattling_clusters", "n_clusters_removed", "n_danglers", "free_dofs")}),
    )
    write_dataset(ds, args.out)
    c = cert.count.as_dict()
    print_summary(args, args.out, [
        ("classification", cert.classification),
        ("contacts", "overlapping pairs that are not linked"),
        ("rattlers", f"{int(cert.rattler.sum())} spheres ({c['n_rattling_clusters']} rattling clusters by counting: "
                     f"{c['n_clusters_removed']} removed whole, {c['n_danglers']} danglers with {c['free_dofs']} "
                     f"free motions; {int(cert.lp_removed.sum())} clusters removed by the LPs)"),
        ("LPs", cert.n_lp)])
    return 0


def linked_modes_command(args: argparse.Namespace, packing) -> int:
    """``jamflow modes`` of a linked packing: constrained-Hessian modes mapped to centres and strain, zero
    modes named (:mod:`jamflow.chains.modes`)."""
    from ..chains.modes import linked_modes, modes_dataset

    if args.lambda_c is not None:
        raise ValueError("--lambda-c is for shape packings (quartic modes); a linked packing's modes are not split")
    strain = None if args.strain == "auto" else args.strain == "yes"
    modes = linked_modes(packing, strain=strain)
    ds = modes_dataset(modes, packing)
    ds.attrs.update(new_dataset_attrs("jamflow linked-packing normal modes", stage_parameters(args, "input", "out")))
    write_dataset(ds, args.out)
    a = ds.attrs
    if modes.unexplained or a["n_floppy"]:
        print(f"jamflow modes: warning: {args.input}: {a['n_floppy']} floppy zero mode(s) no counting explains, "
              f"{modes.unexplained} counted motion(s) that are not zero modes: certify the packing", file=sys.stderr)
    nonzero = modes.eigenvalues[modes.label == 0]
    print_summary(args, args.out, [
        ("N, modes", f"{packing.n}, {modes.eigenvalues.size} "
                     f"({'with strain at fixed volume' if modes.strain else 'fixed box'})"),
        ("zero modes", f"{modes.n_zero}: {a['n_translation']} translations, {a['n_rattling_cluster']} of rattling "
                       f"clusters, {a['n_free_motion']} free motions (swings, danglers, rotators), "
                       f"{a['n_floppy']} floppy"),
        ("lowest vibration", f"{nonzero.min():.4g} epsilon / length^2" if nonzero.size else "none"),
        ("max |Gamma^T mode|", f"{a['max_constraint_violation']:.2e} (links and volume kept to first order)"),
    ])
    return 0
