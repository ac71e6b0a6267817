"""Progress of overdamped runs towards their target, and the dilute-start warning of shear."""

from __future__ import annotations

import numpy as np

from jamflow.cli import main
from jamflow.protocols.initial import random_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.run import (
    DILUTE_FRACTION,
    PHI_J_REFERENCE,
    Stop,
    dilute_start,
    fraction_done,
    run_flow,
)


def test_fraction_done_follows_phi_towards_its_target():
    stop = Stop(strain=10.0, packing_fraction=0.75)
    # a quarter of the way in phi after 1 % of the strain budget
    assert fraction_done(0.1, [0.5, 0.5625], stop) == 0.25
    assert fraction_done(0.3, [0.5, 0.75], stop) == 1.0
    # without a phi target the strain decides
    assert fraction_done(0.1, [0.5, 0.6], Stop(strain=0.4)) == 0.25


def test_compression_progress_tracks_phi(tmp_path):
    start = random_packing(24, 2, 0.5, dispersity="bi", seed=4)
    seen: list[float] = []
    run_flow(start, Drive("compress"), Stop(strain=10.0, packing_fraction=0.55), progress=seen.append)
    print(f"{len(seen)} progress updates, first {seen[:3]}, last {seen[-1]}")
    assert seen[-1] == 1.0
    assert np.all(np.diff(seen) >= 0)
    # the bar moves through the run instead of sitting near 0 and jumping to 1
    assert np.any((np.array(seen) > 0.3) & (np.array(seen) < 0.7))


def test_shear_warns_on_a_dilute_start(tmp_path, capsys):
    rsa = tmp_path / "rsa.nc"
    assert main(["init", str(rsa), "--d", "2", "--n", "24", "--phi", "0.4", "--dispersity", "bi", "--seed", "4",
                 "--quiet"]) == 0
    assert 0.4 < DILUTE_FRACTION * PHI_J_REFERENCE[2]
    assert main(["shear", str(rsa), str(tmp_path / "s.nc"), "--strain", "0.001", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: start is far below jamming" in err


def test_start_with_contacts_is_not_dilute():
    dense = random_packing(24, 2, 0.5, dispersity="bi", seed=4)
    assert dilute_start(dense) is not None
    near = dense.evolve(contacts=np.array([[0, 1]]))
    assert dilute_start(near) is None  # a packing with a contact network is a physical start
