"""The event-driven package has no import cycle between its run driver and its checkpoints."""

from __future__ import annotations

import subprocess
import sys


def test_checkpoint_imports_without_the_run_driver() -> None:
    # run.py imports checkpoint.py; the reverse import made a cycle (only a deferred
    # import inside run_flow kept it working)
    code = ("import sys, jamflow.protocols.overdamped.checkpoint; "
            "print('jamflow.protocols.overdamped.run' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
