#!/usr/bin/env bash
# Regenerates the one small packing per body kind that tests/test_stages.py runs every command on.
# Run from this directory with jamflow on the path: bash make.sh
set -euo pipefail
tmp=$(mktemp -d)
jamflow init "$tmp/s0.nc" --d 2 --n 16 --phi 0.5 --dispersity bi --seed 1 --quiet
jamflow soft-jam "$tmp/s0.nc" spheres_soft.nc --pressure 1e-3 --quiet
jamflow calippso "$tmp/s0.nc" spheres_hard.nc --quiet
jamflow init "$tmp/w0.nc" --d 2 --n 16 --phi 0.5 --dispersity bi --seed 1 --walls --quiet
jamflow calippso "$tmp/w0.nc" walls_hard.nc --walls --quiet
jamflow init-chains "$tmp/l0.nc" --d 2 --clusters 6 --cluster trimer --seed 1 --quiet
jamflow soft-jam "$tmp/l0.nc" linked_soft.nc --pressure 1e-3 --quiet
jamflow init-shapes "$tmp/e0.nc" --shape ellipse --asphericity 1.1 --n 12 --seed 1 --quiet
jamflow soft-jam "$tmp/e0.nc" shapes_soft.nc --pressure 1e-3 --quiet
rm -r "$tmp"
