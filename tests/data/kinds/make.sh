#!/usr/bin/env bash
# Regenerates one small dataset of every kind jamflow writes (jamflow.io.DATASET_KINDS), for the
# tests that feed each command every kind of input (tests/test_cli_fuzz.py).
# Run from this directory with jamflow on the path: bash make.sh
set -euo pipefail
bodies=../bodies
tmp=$(mktemp -d)
q=--quiet
cp "$bodies/spheres_hard.nc" packing.nc
jamflow gaps packing.nc gaps.nc --gap-tol 1e-8 --include-rattlers --bootstrap 4 $q
jamflow forces packing.nc forces.nc --bootstrap 4 $q
jamflow rdf packing.nc rdf.nc --r-max 1.5 $q
jamflow certify packing.nc certificate.nc $q
jamflow init "$tmp/s.nc" --d 2 --n 16 --phi 0.5 --dispersity bi --seed 2 $q
jamflow ls "$tmp/s.nc" "$tmp/p1.nc" "$tmp/p2.nc" --growth-rate 1e-2 --p-target 1e2 1e3 --eos eos.nc $q
jamflow calippso "$tmp/p1.nc" "$tmp/j1.nc" $q
jamflow calippso "$tmp/p2.nc" "$tmp/j2.nc" $q
jamflow calippso "$tmp/p2.nc" "$tmp/j3.nc" --checkpoint calippso-checkpoint.nc --checkpoint-every 0 \
    --stop-after 2 $q || [ $? -eq 3 ]  # 3: stopped, the chain kept in the checkpoint
jamflow overlap "$tmp/j1.nc" "$tmp/j2.nc" overlap.nc $q
jamflow overlap-series "$tmp/j1.nc" "$tmp/j2.nc" overlap-series.nc --p-target 1e2 1e3 --growth-rate 1e-2 $q
jamflow jamming-table overlap-series.nc jamming-table.nc --eos eos.nc --fit-min 1e1 --fit-max 1e3 $q
jamflow decompress packing.nc "$tmp/dec.nc" --phi 0.8 $q
jamflow shear "$tmp/dec.nc" flow.nc --strain 0.2 --record-every 10 --snapshots 2 --snapshot-file snapshots.nc $q
jamflow shear "$tmp/dec.nc" "$tmp/part.nc" --strain 0.05 --checkpoint checkpoint.nc --max-steps 5 --sync-every 2 $q
jamflow flow-summary flow.nc flow-summary.nc --blocks 2 $q
jamflow flow-curve flow-summary.nc flow-curve.nc $q
jamflow aqs "$bodies/spheres_soft.nc" aqs.nc --strain 1e-3 --step 5e-4 $q
jamflow moduli "$bodies/spheres_soft.nc" moduli.nc $q
jamflow certify "$bodies/linked_soft.nc" chain-certificate.nc --soft $q
jamflow link "$bodies/spheres_soft.nc" "$tmp/cemented.nc" --cement 2 --seed 1 $q
jamflow moduli "$tmp/cemented.nc" chain-moduli.nc $q
jamflow chains-moduli chain-moduli.nc chains-moduli-table.nc $q
jamflow contact-angles "$bodies/shapes_soft.nc" contact-angles.nc $q
jamflow shape-survey "$bodies/shapes_soft.nc" shape-survey.nc $q
jamflow modes "$bodies/shapes_soft.nc" modes.nc $q
jamflow modes "$bodies/linked_soft.nc" linked-modes.nc $q
jamflow constraint-curvature ../shapes_circulo_line_a1.1_n16_p1e-6.nc constraint-curvature.nc $q
jamflow feasible-region feasible-region.nc --samples 20000 --shrinks 1e-3 1e-2 $q
jamflow tradeoff soft tradeoff.nc --quick $q
rm -r "$tmp"
