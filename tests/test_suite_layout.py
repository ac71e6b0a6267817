"""The fast suite's layout: the xdist work unit of the shear-stabilised engine names every module that runs it."""

from __future__ import annotations

import re
from pathlib import Path

from conftest import STRAIN_ENGINE_MODULES

HERE = Path(__file__).parent

#: what a test module writes when it runs the shear-stabilised engine (model, engine, protocol or CLI flag)
STRAIN_ENGINE_USE = re.compile(r"ShearStabilizedModel|StrainFire|strain_fire|shear_stabilize|--shear-stabilize")


def test_the_strain_engine_unit_is_exactly_the_modules_that_run_the_engine():
    users = {p.stem for p in HERE.glob("test_*.py")
             if p.name != Path(__file__).name and STRAIN_ENGINE_USE.search(p.read_text())}
    assert users == set(STRAIN_ENGINE_MODULES), (sorted(users - STRAIN_ENGINE_MODULES),
                                                 sorted(STRAIN_ENGINE_MODULES - users))
