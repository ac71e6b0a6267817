"""Shared fixtures: the real LS configurations and a seeded generator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

#: Real LS-compressed configurations (N = 1024, d = 3, 4, 5) beside the repository.
CALIPPSO_LS_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "calippso-ls"
CALIPPSO_LS_FILES = sorted(CALIPPSO_LS_DIR.glob("Centers-after-LS--N-*--d-*.dat"))


@pytest.fixture(params=CALIPPSO_LS_FILES, ids=lambda p: p.stem)
def calippso_ls_file(request: pytest.FixtureRequest) -> Path:
    """Each CALiPPSO LS ``.dat`` file in turn."""
    return request.param


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test run draws the same numbers."""
    return np.random.default_rng(20240521)
