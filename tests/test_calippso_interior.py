"""HiGHS interior point choice of CALiPPSO (issue 19): HiPO is opt-in (the ``hipo`` extra).

Without HiPO in the installed highspy, asking for it is a clear error naming the extra;
with it, the chain must jam (isostatic, balanced, no overlap) and every interior point
LP (with crossover) must end at a vertex: inactive duals exactly zero, the gap the
contact detection needs.
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
from jamflow.protocols.initial import random_packing
from jamflow.state.packing import max_overlap
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL


def _hipo_available() -> bool:
    return new_highs(1).setOptionValue("solver", "hipo") == highspy.HighsStatus.kOk


@pytest.fixture(scope="module")
def start():
    return random_packing(48, 3, 0.3, "mono", seed=5)


def test_hipo_jams_with_vertex_duals_or_is_a_clear_error(start):
    if not _hipo_available():
        with pytest.raises(ValueError, match=r"pip install 'jamflow\[hipo\]'"):
            calippso(start, interior="hipo")
        return
    # from a random start another optimal vertex of a degenerate early LP leads to another
    # jammed packing, so the packing is checked, not compared with IPX's
    res = calippso(start, solver="ipm", finish="lp", interior="hipo")
    p = res.packing
    assert res.converged and summarize(p).isostatic
    assert force_balance_residual(p)[~p.rattler].max() < FORCE_BALANCE_TOL
    assert max_overlap(p)[1] < OVERLAP_TOL
    # crossover kept: every LP's inactive duals are exactly zero (a vertex)
    assert np.all(res.history["max_inactive_dual"].values == 0.0)


def test_cli_interior_hipo_runs_or_is_refused_in_one_line(start, tmp_path, capsys):
    write_packing(start, tmp_path / "in.nc")
    code = main(["calippso", str(tmp_path / "in.nc"), str(tmp_path / "out.nc"), "--quiet", "--interior", "hipo"])
    if _hipo_available():
        assert code == 0 and (tmp_path / "out.nc").exists()
        return
    assert code != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "jamflow[hipo]" in err[0]
    assert not (tmp_path / "out.nc").exists()


def test_unknown_interior_point_is_refused(start):
    with pytest.raises(ValueError, match="unknown interior point"):
        calippso(start, interior="barrier")
