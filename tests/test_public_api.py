"""``import jamflow`` exposes the public API, lazily: every name in ``__all__`` resolves, nothing heavy at import."""

from __future__ import annotations

import subprocess
import sys

import jamflow
from jamflow.tolerances import FORCE_BALANCE_TOL, OVERLAP_TOL


def test_every_public_name_resolves_to_a_documented_callable():
    for name in jamflow.__all__:
        obj = getattr(jamflow, name)
        assert callable(obj), name
        assert obj.__doc__ and obj.__doc__.strip(), f"{name} has no docstring"


def test_unknown_names_raise_attribute_error():
    try:
        jamflow.no_such_stage  # noqa: B018
    except AttributeError as exc:
        assert "no_such_stage" in str(exc)
    else:
        raise AssertionError("jamflow.no_such_stage resolved")


def test_import_is_cheap():
    code = ("import sys, jamflow; heavy = [m for m in ('numba', 'highspy', 'matplotlib', 'yaml') "
            "if m in sys.modules]; print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == ""


def test_public_names_survive_importing_the_submodules():
    # a submodule import binds its name on the package: jamflow.protocols.calippso must stay the function
    code = ("import importlib, pkgutil, jamflow\n"
            "for m in pkgutil.iter_modules(jamflow.__path__):\n"
            "    if m.name != '__main__':\n"
            "        importlib.import_module('jamflow.' + m.name)\n"
            "import types\n"
            "print([n for n in jamflow.__all__ if isinstance(getattr(jamflow, n), types.ModuleType)])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_public_api_jams_a_packing_isostatically(tmp_path):
    start = jamflow.random_packing(24, 2, 0.5, "bi", seed=3)
    jammed = jamflow.calippso_jam(start).packing
    path = jamflow.write_packing(jammed, tmp_path / "j.nc")
    s = jamflow.summarize(jamflow.read_packing(path))
    # LP jamming of frictionless discs: an isostatic backbone, N_c = d (N_s - 1) + 1, no overlap
    assert s.isostatic and s.n_contacts == 2 * (s.n_stable - 1) + 1
    assert s.max_overlap_rel < OVERLAP_TOL and s.force_balance_residual < FORCE_BALANCE_TOL
