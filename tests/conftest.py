"""Shared fixtures: the real LS configurations, the d = 3 one jammed once, and a seeded generator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ls_data import LS_DIMENSIONS, ls_dat

#: Test modules that run the shear-stabilised engine (``StrainFire``): one xdist work unit, so
#: that one worker compiles its kernels on a clean checkout (26-44 CPU-s, the largest
#: compile of the suite) instead of both at once; docs/notes/test-times.md.
STRAIN_ENGINE_MODULES = frozenset({
    "test_chains_certify", "test_chains_compliance", "test_chains_entanglement", "test_chains_hessian",
    "test_chains_saddle", "test_chains_shear", "test_chains_swinging", "test_extremes_bodies", "test_models_engines",
    "test_models_strain_kernels", "test_models_tangent_newton", "test_onset_search", "test_onset_verdict",
})


#: The test that runs every command on each body kind it takes: one work unit per command, so
#: that the engines those commands compile on a clean checkout (sphere FIRE, LS, the overdamped
#: solver, shapes) spread over both workers; the smoke set is mostly this test.
PER_COMMAND_TEST = "test_stages.py::test_an_accepted_body_kind_keeps_its_bodies["


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadfile`` with :data:`STRAIN_ENGINE_MODULES` as one unit and
    :data:`PER_COMMAND_TEST` split by command (other modes unchanged)."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class SharedKernelScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            if PER_COMMAND_TEST in nodeid:
                # the parameter id is "<command>-<body kind>"
                return f"{scope}::{nodeid.rsplit('[', 1)[1].rsplit('-', 1)[0]}"
            return "strain-engine" if Path(scope).stem in STRAIN_ENGINE_MODULES else scope

    return SharedKernelScheduling(config, log)


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
