"""Dense starts: a jammed packing decompressed to a lower packing fraction.

Checked: the target packing fraction is met to round-off, every former contact opens by the
same relative gap (1 - s) and no pair overlaps (brute force over all pairs), event-driven
shear runs from it, and a target at or above the packing's own density is refused.
"""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.neighbors.pairs import pairs_within_brute_force
from jamflow.protocols.initial import random_packing
from jamflow.protocols.overdamped.driving import Drive
from jamflow.protocols.overdamped.integrate import FlowOptions
from jamflow.protocols.overdamped.run import Stop, run_flow
from jamflow.protocols.overdamped.starts import decompressed

OPTS = FlowOptions(dt_max=1e-2, step_drift=1e-6, drift_tol=1e-5)


@pytest.fixture(scope="module")
def jammed16():
    p = random_packing(16, 2, 0.5, "bi", seed=2)
    p = p.evolve(diameter=p.diameter * (1 - 0.03 * np.random.default_rng(2).uniform(size=p.n)))
    res = run_flow(p, Drive("compress"), Stop(strain=5.0), OPTS, unit="small_diameter", record_every=100)
    assert res.jammed
    return res.final


def test_decompressed_meets_phi_and_opens_every_contact(jammed16):
    phi0 = jammed16.packing_fraction
    phi = phi0 - 0.02
    q = decompressed(jammed16, phi)
    assert q.packing_fraction == pytest.approx(phi, rel=1e-14)
    assert q.contacts is None and q.force is None
    assert q.parameters["decompressed_from"] == pytest.approx(phi0, rel=1e-15)
    s = (phi / phi0) ** 0.5
    pl = pairs_within_brute_force(q.position, q.box, 2 * q.diameter.max())
    r = np.linalg.norm(pl.dx, axis=1)
    sigma = 0.5 * (q.diameter[pl.i] + q.diameter[pl.j])
    gap = r / sigma - 1.0
    # no overlap; the former contacts (r = old sigma to round-off) open by 1/s - 1
    assert gap.min() == pytest.approx(1 / s - 1, rel=1e-6)
    assert gap.min() > 0


def test_shear_runs_from_a_decompressed_start(jammed16):
    q = decompressed(jammed16, jammed16.packing_fraction - 0.02)
    res = run_flow(q, Drive("shear"), Stop(strain=0.3), OPTS, unit="small_diameter", record_every=100)
    assert res.complete and not res.jammed
    assert res.series.sizes["event"] > 0
    assert float(res.series.constraint_error.max()) <= OPTS.drift_tol


@pytest.mark.parametrize("offset", [None, 0.0, 0.01])
def test_decompression_target_outside_range_is_refused(jammed16, offset):
    """phi = 0, phi = phi_0 (nothing to decompress) and phi > phi_0 (overlaps) are refused."""
    phi = 0.0 if offset is None else jammed16.packing_fraction + offset
    with pytest.raises(ValueError, match="decompression target"):
        decompressed(jammed16, phi)


def test_decompress_cli_writes_the_start_and_prints_its_numbers(jammed16, tmp_path, capsys):
    from jamflow.cli import main
    from jamflow.io import read_packing, write_packing

    write_packing(jammed16, tmp_path / "jammed.nc")
    phi = jammed16.packing_fraction - 0.02
    assert main(["decompress", str(tmp_path / "jammed.nc"), str(tmp_path / "start.nc"), "--phi", str(phi)]) == 0
    start = read_packing(tmp_path / "start.nc")
    assert start.packing_fraction == pytest.approx(phi, rel=1e-14)
    assert start.position == pytest.approx(jammed16.position, abs=0)
    s = (phi / jammed16.packing_fraction) ** 0.5
    printed = capsys.readouterr().out
    assert f"{s:.10f}" in printed and f"{phi:.10f}" in printed
    assert "smallest relative gap" in printed


def test_decompress_cli_refuses_a_denser_target_and_writes_nothing(jammed16, tmp_path, capsys):
    from jamflow.cli import main
    from jamflow.io import write_packing

    write_packing(jammed16, tmp_path / "jammed.nc")
    code = main(["decompress", str(tmp_path / "jammed.nc"), str(tmp_path / "start.nc"),
                 "--phi", str(jammed16.packing_fraction + 0.01)])
    assert code != 0
    assert "decompression target" in capsys.readouterr().err
    assert not (tmp_path / "start.nc").exists()
