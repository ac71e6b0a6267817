#!/usr/bin/env bash
# Regenerates the one small packing per body kind that tests/test_stages.py runs every command on,
# and the packings of named cases.
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
# the same start shear-stabilised (tests/test_models_tangent_newton.py)
jamflow soft-jam "$tmp/l0.nc" linked_soft_shear.nc --pressure 1e-3 --shear-stabilize --quiet
jamflow init-shapes "$tmp/e0.nc" --shape ellipse --asphericity 1.1 --n 12 --seed 1 --quiet
jamflow soft-jam "$tmp/e0.nc" shapes_soft.nc --pressure 1e-3 --quiet
# 12 rigid trimers, fixed box, P0 = 1e-6: one trimer touches only through one sphere and swings
# about it (tests/test_chains_swinging.py); seed 19 is the first of seeds 1-28 that gives one
jamflow init-chains "$tmp/t0.nc" --d 2 --clusters 12 --cluster trimer --seed 19 --quiet
jamflow soft-jam "$tmp/t0.nc" swinging_trimer_2d.nc --pressure 1e-6 --pressure-rtol 1e-3 --force-tol 1e-13 \
    --delta-phi 1e-2 --quiet
# the same, shear-stabilised: seed 5 is the first of seeds 1-5 that gives a swinging trimer
jamflow init-chains "$tmp/t1.nc" --d 2 --clusters 12 --cluster trimer --seed 5 --quiet
jamflow soft-jam "$tmp/t1.nc" swinging_trimer_2d_shear.nc --pressure 1e-6 --pressure-rtol 1e-3 --force-tol 1e-13 \
    --delta-phi 1e-2 --shear-stabilize --quiet
# 32 chains of four (3D, frozen angles), P0 = 1e-6: one contact short of the rank count, a minimum held by
# its prestress, not a saddle (tests/test_chains_saddle.py); seed 3 is the short one of seeds 1-5 from phi = 0.1
jamflow init-chains "$tmp/c0.nc" --d 3 --clusters 32 --cluster chain --chain-length 4 --phi 0.1 --seed 3 --quiet
jamflow soft-jam "$tmp/c0.nc" hypostatic_chains4_3d.nc --pressure 1e-6 --pressure-rtol 1e-3 --force-tol 1e-12 --quiet
# 4 flexible chains of 30 (3D, bidisperse by chain), P0 = 1e-12 at force_tol 1e-13: the bisection's final
# minimum, a saddle 4 contacts short (tests/test_extremes_bodies.py). soft-jam now refuses it, so it is written
# with the saddle guard's former bound, ZERO_MODE_RTOL times the largest eigenvalue alone
jamflow init-chains "$tmp/c30.nc" --d 3 --clusters 4 --cluster chain --chain-length 30 --free-angles \
    --dispersity bi --ratio 1.4 --seed 1 --quiet
python - "$tmp/c30.nc" <<'PY'
import sys

import jamflow.chains.jamming as jamming
from jamflow.io import read_packing, write_packing
from jamflow.minimize.onset import JammingSettings

jamming.SADDLE_CURVATURE_RATIO = float("inf")
settings = JammingSettings(force_tol=1e-13, pressure_rtol=1e-3, delta_phi=1e-2)
result = jamming.jam_linked(read_packing(sys.argv[1], None), 1e-12, settings=settings)
write_packing(result.packing, "saddle_chains30_3d_p1e-12.nc")
PY
rm -r "$tmp"

# FIRE's states at the Newton tries of a shape packing's enthalpy stage (P0 = 1e-6), each try stubbed out
# as failed without a step, so that FIRE's path is that of no tries: python $tmp/tries.py START K:NAME ...
# writes the state of the K-th try (from 0) to NAME.nc
tries_script() {
cat > "$1" <<'PY'
import sys

import numpy as np

from jamflow.io import read_packing, write_packing
from jamflow.minimize import onset
from jamflow.minimize.newton import NewtonPolish
from jamflow.shapes.jamming import jam_shapes, shape_packing

start = read_packing(sys.argv[1], None)
wanted = dict(arg.split(":") for arg in sys.argv[2:])
tries = []


class Recorded(Exception):
    pass


def record(model, config, *args, **kwargs):
    tries.append(1)
    name = wanted.pop(str(len(tries) - 1), None)
    if name is not None:
        write_packing(shape_packing(model, np.array(config), start, {"pressure": 1e-6}, {}), f"{name}.nc")
    if not wanted:
        raise Recorded
    return NewtonPolish(None, 0)


onset.polish_enthalpy = record
try:
    jam_shapes(start, 1e-6)
except Recorded:
    pass
if wanted:
    raise SystemExit(f"the stage made only {len(tries)} tries")
PY
}

# circulo_triangles_enthalpy_{valley,basin}.nc: tries 1 and 6 of circulo-triangles (A = 1.1, N = 100, seed 2):
# a flat valley without a minimum within reach, and the basin the 7th try lands in (docs/notes/shapes.md,
# "Why the Newton tries of circulo shapes fail"). The vendored files are an earlier tree's, whose FIRE path
# from this start differed (positions by up to 1e-3); the tests' measured trial steps are of those files.
tmp=$(mktemp -d)
tries_script "$tmp/tries.py"
jamflow init-shapes --shape circulo-polygon --sides 3 --asphericity 1.1 --phi 0.4 --seed 2 --n 100 --quiet "$tmp/t.nc"
python "$tmp/tries.py" "$tmp/t.nc" 1:circulo_triangles_enthalpy_valley 6:circulo_triangles_enthalpy_basin

# circulo_lines_enthalpy_slide.nc: try 1 of circulo-lines (A = 1.1, N = 480, seed 5), where bodies slide along
# the soft valley into neighbours the Hessian does not see (docs/notes/shapes.md, "Closing contacts along a
# step's line")
jamflow init-shapes --shape circulo-line --asphericity 1.1 --phi 0.4 --seed 5 --n 480 --quiet "$tmp/l.nc"
python "$tmp/tries.py" "$tmp/l.nc" 1:circulo_lines_enthalpy_slide
rm -r "$tmp"
