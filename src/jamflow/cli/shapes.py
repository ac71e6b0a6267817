"""Subcommands on packings of 2D shaped bodies: init-shapes (soft-jam handles jamming)."""

from __future__ import annotations

import argparse

import numpy as np

from ..io import write_packing
from ..shapes.generation import SHAPE_CHOICES, bidisperse_shapes, random_shape_packing, unit_shape
from .common import add_command, add_quiet, packing_rows, print_summary, seed, stage_parameters

#: Default packing fraction of the random start: random sequential addition of
#: elongated bodies (up to aspect ratio ~5) still finds free places quickly.
INIT_SHAPES_PHI: float = 0.3


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(sub, "init-shapes", _init_shapes,
                    "random bidisperse packing of 2D shaped bodies (VanderWerf et al.): areas 1.4^2 apart, "
                    "equal masses, mean area-equivalent diameter 1, no overlap",
                    writes=("out",), packings=("out",))
    p.add_argument("out", help="output netCDF packing")
    p.add_argument("--shape", choices=SHAPE_CHOICES, required=True, help="shape family")
    p.add_argument("--aspect-ratio", type=float, default=None,
                   help="length over width (ellipse a/b; circulo-line (l + 2R)/2R; dumbbell (2|v| + 2R)/2R)")
    p.add_argument("--asphericity", type=float, default=None,
                   help="target asphericity A = p^2 / (4 pi a) > 1 (met exactly by bisection on the shape parameter)")
    p.add_argument("--sides", type=int, default=None, help="circulo-polygon: number of sides n >= 3 (regular polygon)")
    p.add_argument("--n", type=int, required=True, help="number of bodies (even: half small, half large)")
    p.add_argument("--phi", type=float, default=INIT_SHAPES_PHI,
                   help=f"packing fraction of the random start (default {INIT_SHAPES_PHI})")
    p.add_argument("--seed", type=seed, required=True, help="random seed")
    add_quiet(p)


def _init_shapes(args: argparse.Namespace) -> int:
    shape = unit_shape(args.shape, args.aspect_ratio, args.asphericity, args.sides)
    table = bidisperse_shapes(shape)
    packing = random_shape_packing(table, args.n, args.phi, args.seed)
    params = stage_parameters(args, "out")
    packing = packing.evolve(parameters=params)
    write_packing(packing, args.out, params)
    print_summary(args, args.out, packing_rows(packing) + [
        ("shape", f"{args.shape} ({', '.join(sorted(set(table.kind)))})"),
        ("asphericity A", f"{table.asphericity[0]:.12g} (A - 1 = {table.asphericity[0] - 1.0:.6g})"),
        ("areas small, large", f"{table.area[0]:.10g}, {table.area[1]:.10g} (ratio {table.area[1] / table.area[0]:.6g})"),
        ("bounding diameters", ", ".join(f"{2 * r:.6g}" for r in table.bounding_radius)),
        ("mean area-equivalent diameter", f"{np.mean(2.0 * np.sqrt(table.area[packing.shape_index] / np.pi)):.12g}"),
    ])
    return 0
