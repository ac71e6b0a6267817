"""Keep numba's on-disk kernel caches consistent with the package's sources.

numba caches a compiled kernel beside its source (``__pycache__/*.nbi``, ``*.nbc``)
and invalidates it only when that source file changes. A kernel that calls kernels of
other modules holds compiled copies of them, so after an edit of
``overdamped/ldl.py`` the cached kernels of ``overdamped/solver.py`` kept running the
old substitution (47.9 against 33.9 us per call until the caches were cleared). An
editable install that pulls such a change would silently mix old and new code.

:func:`refresh` stamps the caches with a hash of every module of the package that
uses numba and deletes all of them when the hash changes, so the next use compiles
afresh. It runs on ``import jamflow``, before any kernel module loads, and costs a few
milliseconds (reading the ~15 kernel modules).

Limits: caches that numba writes elsewhere (``NUMBA_CACHE_DIR`` set, or a package
directory that is not writable) are not stamped. A regular (non-editable) install
rewrites every source file, so numba's own per-file check invalidates all of them.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

#: stamp file, in the package's top ``__pycache__``
STAMP_NAME = "numba-kernels.stamp"


def kernel_sources_hash(package_dir: Path) -> str:
    """SHA-256 over the relative path and bytes of every ``.py`` file under
    ``package_dir`` that mentions numba (the modules that can hold kernels)."""
    h = hashlib.sha256()
    for path in sorted(package_dir.rglob("*.py")):
        source = path.read_bytes()
        if b"numba" in source:
            h.update(path.relative_to(package_dir).as_posix().encode())
            h.update(b"\0")
            h.update(source)
    return h.hexdigest()


def refresh(package_dir: Path) -> bool:
    """Delete numba's in-tree caches under ``package_dir`` when its kernel sources
    changed since the last stamp (or there is no stamp yet); returns whether it did.

    Nothing happens when the package directory is not writable (numba then caches
    elsewhere, see the module docstring)."""
    if not os.access(package_dir, os.W_OK):
        return False
    digest = kernel_sources_hash(package_dir)
    stamp = package_dir / "__pycache__" / STAMP_NAME
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    for pattern in ("*.nbi", "*.nbc"):
        for cached in package_dir.rglob(f"__pycache__/{pattern}"):
            cached.unlink(missing_ok=True)
    stamp.parent.mkdir(exist_ok=True)
    # written atomically: a concurrent import reads the old stamp or the new one
    fd, tmp = tempfile.mkstemp(dir=stamp.parent, prefix=STAMP_NAME)
    with os.fdopen(fd, "w") as f:
        f.write(digest)
    os.replace(tmp, stamp)
    return True
