"""HiGHS instances agree on the process's thread scheduler (jamflow.highs)."""

from __future__ import annotations

import highspy
import numpy as np
import pytest

from jamflow.highs import new_highs


def _tiny_lp_status(h: highspy.Highs) -> highspy.HighsModelStatus:
    """min x, 0 <= x <= 1 (optimum x = 0)."""
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = 1, 0
    lp.col_cost_, lp.col_lower_, lp.col_upper_ = np.array([1.0]), np.array([0.0]), np.array([1.0])
    h.passModel(lp)
    h.run()
    return h.getModelStatus()


def test_a_later_instance_with_another_thread_count_still_solves():
    # a certificate at 2 threads then a CALiPPSO chain at 1 thread, in one process: HiGHS's
    # global scheduler refused the second ('Not Set') before new_highs reset it
    for threads in (2, 1, 2, 1):
        h = new_highs(threads)
        assert _tiny_lp_status(h) == highspy.HighsModelStatus.kOptimal
        assert h.getSolution().col_value[0] == 0.0


def test_a_bare_instance_after_another_thread_count_is_what_new_highs_prevents():
    # the failure mode itself (if HiGHS ever drops the global scheduler, this documents it)
    assert _tiny_lp_status(new_highs(2)) == highspy.HighsModelStatus.kOptimal
    bare = highspy.Highs()
    bare.setOptionValue("output_flag", False)
    bare.setOptionValue("threads", 1)
    assert _tiny_lp_status(bare) == highspy.HighsModelStatus.kNotset


def test_thread_count_must_be_positive():
    with pytest.raises(ValueError, match="at least 1"):
        new_highs(0)


def test_a_new_instance_prints_no_banner_on_the_process_stdout():
    # HiGHS's first instance prints its version and licence banner from C to file
    # descriptor 1, whatever Python's sys.stdout is; new_highs sends it to the null device
    import subprocess
    import sys

    code = "from jamflow.highs import new_highs; print('before'); new_highs(); new_highs(2); print('after')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout == "before\nafter\n" and "HiGHS" not in out.stderr
