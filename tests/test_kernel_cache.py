"""numba's kernel caches follow changes of the kernels they inline (jamflow._kernel_cache)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from jamflow._kernel_cache import STAMP_NAME, refresh


def _caches(root: Path) -> list[Path]:
    return sorted(p for pattern in ("*.nbi", "*.nbc") for p in root.rglob(f"__pycache__/{pattern}"))


def _plant_caches(root: Path) -> None:
    for sub in (root, root / "sub"):
        (sub / "__pycache__").mkdir(parents=True, exist_ok=True)
        for name in ("k.f-1.py311.nbi", "k.f-1.py311.0.nbc"):
            (sub / "__pycache__" / name).write_bytes(b"compiled")


def test_refresh_deletes_caches_only_when_a_numba_module_changes(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)  # the caches beside the sources
    (tmp_path / "sub").mkdir()
    (tmp_path / "kernels.py").write_text("import numba\n")
    (tmp_path / "sub" / "more.py").write_text("from numba import njit\n")
    (tmp_path / "plain.py").write_text("x = 1\n")
    _plant_caches(tmp_path)
    assert refresh(tmp_path) and _caches(tmp_path) == []  # no stamp yet: nothing is known
    assert (tmp_path / "__pycache__" / STAMP_NAME).exists()
    _plant_caches(tmp_path)
    assert not refresh(tmp_path) and len(_caches(tmp_path)) == 4
    (tmp_path / "plain.py").write_text("x = 2\n")  # no kernels there
    assert not refresh(tmp_path) and len(_caches(tmp_path)) == 4
    (tmp_path / "sub" / "more.py").write_text("from numba import njit  # edited\n")
    assert refresh(tmp_path) and _caches(tmp_path) == []
    _plant_caches(tmp_path)
    assert not refresh(tmp_path) and len(_caches(tmp_path)) == 4


def _package(root: Path, name: str, stamped: bool) -> Path:
    """``g = 2 f`` with ``f`` in another module, both cached by numba; ``stamped``
    packages call :func:`refresh` on import as jamflow does."""
    pkg = root / name
    pkg.mkdir()
    init = "from pathlib import Path\nfrom jamflow._kernel_cache import refresh\nrefresh(Path(__file__).parent)\n"
    (pkg / "__init__.py").write_text(init if stamped else "")
    (pkg / "f.py").write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    (pkg / "g.py").write_text(textwrap.dedent("""\
        from numba import njit
        from .f import f

        @njit(cache=True)
        def g(x):
            return 2 * f(x)
        """))
    return pkg


def _g_of_1(root: Path, name: str, user_cache: Path | None) -> int:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), *sys.path]))
    env.pop("NUMBA_CACHE_DIR", None)
    if user_cache is not None:
        env["NUMBA_CACHE_DIR"] = str(user_cache)
    out = subprocess.run([sys.executable, "-c", f"from {name}.g import g; print(g(1))"], env=env,
                         capture_output=True, text=True, check=True)
    return int(out.stdout.strip())


# each case compiles its kernels three times in fresh processes: the cache-directory variant is slow
@pytest.mark.parametrize("user_cache", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["in_tree", "NUMBA_CACHE_DIR"])
def test_an_edit_of_an_inlined_kernel_reaches_its_callers(tmp_path, user_cache):
    """Without the stamp, numba keeps ``g``'s cache with the old ``f`` inlined (the
    hazard); with it, ``g`` is recompiled with the new ``f``; both with the caches
    beside the sources and under ``NUMBA_CACHE_DIR``."""
    cache = tmp_path / "numba-cache" if user_cache else None
    results = {}
    for name, stamped in (("stale_pkg", False), ("stamped_pkg", True)):
        pkg = _package(tmp_path, name, stamped)
        assert _g_of_1(tmp_path, name, cache) == 4
        written = sorted(cache.rglob("*.nb[ci]")) if user_cache else _caches(pkg)
        assert written, "numba wrote no cache"
        if user_cache:
            assert not _caches(pkg)
        (pkg / "f.py").write_text((pkg / "f.py").read_text().replace("x + 1", "x + 2"))
        results[name] = _g_of_1(tmp_path, name, cache)
    assert results["stale_pkg"] == 4, "numba now invalidates callers' caches itself: the premise of this test changed"
    assert results["stamped_pkg"] == 6


def test_import_jamflow_leaves_numba_and_its_caches_alone_until_a_kernel_module_loads():
    """``import jamflow`` does no work on the kernel caches; the first kernel module checks them."""
    code = ("import sys, jamflow, jamflow._kernel_cache as kc; "
            "before = ('numba' in sys.modules, kc._checked); "
            "import jamflow.neighbors._cell_kernels; "
            "print(before, kc._checked)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(False, False) True"
