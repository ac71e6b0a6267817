"""Shared fixtures: the real LS configurations, the d = 3 one jammed once, and a seeded generator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ls_data import LS_DIMENSIONS, ls_dat


@pytest.fixture(params=LS_DIMENSIONS, ids=lambda d: f"Centers-after-LS--N-1024--d-{d}")
def calippso_ls_file(request: pytest.FixtureRequest) -> Path:
    """Each vendored CALiPPSO LS ``.dat`` file in turn (a missing one is an error)."""
    return ls_dat(request.param)


@pytest.fixture(scope="session")
def ls_d3_calippso():
    """The d = 3 LS configuration and its CALiPPSO result at the default settings, jammed
    once for every test that checks that run (a ``CalippsoResult``; tests must not modify it)."""
    from jamflow.io.formats import read_dat
    from jamflow.protocols.calippso import calippso

    start = read_dat(ls_dat(3))
    return start, calippso(start)


@pytest.fixture
def rng() -> np.random.Generator:
    """A generator with a fixed seed, so every test run draws the same numbers."""
    return np.random.default_rng(20240521)
