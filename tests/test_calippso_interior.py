"""HiGHS interior point choice of CALiPPSO: IPX, or HiPO on the LP's explicit dual
(``highspy[extras]``, a dependency).

With HiPO the chain must jam (isostatic, balanced, no overlap) and every interior point
LP (with crossover) must end at a vertex: inactive duals exactly zero, the gap the
contact detection needs. In a highspy build without HiPO, asking for it is a clear
error naming what to install, and ``auto`` takes IPX.
"""

from __future__ import annotations

import highspy
import numpy as np
import pytest

from jamflow.analysis.contacts import summarize
from jamflow.cli import main
from jamflow.highs import new_highs
from jamflow.io import write_packing
from jamflow.network.spheres import force_balance_residual
from jamflow.protocols.calippso import calippso
from jamflow.protocols.calippso import solver as lp_solver
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import max_overlap
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL


class _WithoutHipo:
    """A HiGHS instance of a highspy build without HiPO: it refuses ``solver = hipo``."""

    def __init__(self, h: highspy.Highs) -> None:
        self._h = h

    def setOptionValue(self, name, value):
        if name == "solver" and value == "hipo":
            return highspy.HighsStatus.kError
        return self._h.setOptionValue(name, value)

    def __getattr__(self, name):
        return getattr(self._h, name)


@pytest.fixture(scope="module")
def start():
    return random_packing(48, 3, 0.3, "mono", seed=5)


def test_hipo_jams_with_vertex_duals(start):
    assert new_highs(1).setOptionValue("solver", "hipo") == highspy.HighsStatus.kOk
    # from a random start another optimal vertex of a degenerate early LP leads to another
    # jammed packing, so the packing is checked, not compared with IPX's
    res = calippso(start, solver="ipm", finish="lp", interior="hipo")
    p = res.packing
    assert res.converged and summarize(p).isostatic
    assert force_balance_residual(p)[~p.rattler].max() < FORCE_BALANCE_TOL
    assert max_overlap(p)[1] < OVERLAP_TOL
    # crossover kept: every LP's inactive duals are exactly zero (a vertex)
    assert np.all(res.history["max_inactive_dual"].values == 0.0)
    assert set(res.history["interior"].values) == {"hipo-dual"}


def test_cli_interior_hipo_runs(start, tmp_path):
    write_packing(start, tmp_path / "in.nc")
    assert main(["calippso", str(tmp_path / "in.nc"), str(tmp_path / "out.nc"), "--quiet", "--interior", "hipo"]) == 0
    assert (tmp_path / "out.nc").exists()


def test_without_hipo_in_highspy_hipo_is_refused_in_one_line_and_auto_takes_ipx(start, tmp_path, capsys,
                                                                                  monkeypatch):
    monkeypatch.setattr(lp_solver, "new_highs", lambda threads: _WithoutHipo(new_highs(threads)))
    monkeypatch.setattr(lp_solver, "HIPO_MIN_COLUMNS", 1)
    with pytest.raises(ValueError, match=r"pip install 'highspy\[extras\]'"):
        calippso(start, interior="hipo")
    write_packing(start, tmp_path / "in.nc")
    assert main(["calippso", str(tmp_path / "in.nc"), str(tmp_path / "out.nc"), "--quiet", "--interior", "hipo"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "highspy[extras]" in err[0]
    assert not (tmp_path / "out.nc").exists()
    res = calippso(start, solver="ipm", finish="lp")
    assert res.converged and set(res.history["interior"].values) == {"ipx"}


def test_unknown_interior_point_is_refused(start):
    with pytest.raises(ValueError, match="unknown interior point"):
        calippso(start, interior="barrier")
