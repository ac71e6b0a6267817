"""Keep numba's on-disk kernel caches consistent with the package's sources.

numba caches a compiled kernel beside its source (``__pycache__/*.nbi``, ``*.nbc``)
and invalidates it only when that source file changes. A kernel that calls kernels of
other modules holds compiled copies of them, so after an edit of
``overdamped/ldl.py`` the cached kernels of ``overdamped/solver.py`` kept running the
old substitution (47.9 against 33.9 us per call until the caches were cleared). An
editable install that pulls such a change would silently mix old and new code.

:func:`refresh` stamps the caches with a hash of every module of the package that
uses numba and deletes all of them when the hash changes, so the next use compiles
afresh. :func:`ensure_fresh` runs it once per process when the first kernel module
is imported (they import ``njit`` from :mod:`jamflow._numba`), so it costs a few
milliseconds (reading the kernel modules) only where numba is used.

With ``NUMBA_CACHE_DIR`` set numba keeps every cache there instead, one directory
per source directory (``<name>_<sha1 of its absolute path>``, numba's
``_CacheLocator.get_suitable_cache_subpath``); the stamp then lives in that directory
too and covers those caches.

Limit: without ``NUMBA_CACHE_DIR`` a package directory that is not writable is not
stamped (numba then caches in a user-wide directory). A regular (non-editable)
install rewrites every source file, so numba's own per-file check invalidates all of
them.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import warnings
from pathlib import Path

#: stamp file, in the package's top ``__pycache__`` (see :func:`stamp_path`)
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


def _writable(directory: Path) -> bool:
    """Whether ``directory`` can be written, or created in its nearest existing parent."""
    while not directory.exists() and directory != directory.parent:
        directory = directory.parent
    return os.access(directory, os.W_OK)


def _sha1(path: Path) -> str:
    """numba's name for a source directory under ``NUMBA_CACHE_DIR`` hashes its absolute path."""
    return hashlib.sha1(os.path.abspath(path).encode()).hexdigest()


def cache_dirs(package_dir: Path) -> list[Path]:
    """Where numba caches the kernels of every directory under ``package_dir``:
    ``__pycache__`` beside the sources, or under ``NUMBA_CACHE_DIR`` when it is set."""
    sources = [package_dir, *sorted(p for p in package_dir.rglob("*") if p.is_dir() and p.name != "__pycache__")]
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return [Path(user) / f"{src.name}_{_sha1(src)}" for src in sources]
    return [src / "__pycache__" for src in sources]


def stamp_path(package_dir: Path) -> Path:
    """The stamp of ``package_dir``'s caches: in its top ``__pycache__``, or in
    ``NUMBA_CACHE_DIR`` (named by the package's path) when that is set."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return Path(user) / f"{package_dir.name}_{_sha1(package_dir)}.{STAMP_NAME}"
    return package_dir / "__pycache__" / STAMP_NAME


def refresh(package_dir: Path) -> bool:
    """Delete numba's caches of ``package_dir`` (:func:`cache_dirs`) when its kernel
    sources changed since the last stamp (or there is no stamp yet); returns whether
    it did.

    Nothing happens when the stamp's directory cannot be written (a read-only
    package without ``NUMBA_CACHE_DIR``: numba then caches elsewhere, see the module
    docstring)."""
    stamp = stamp_path(package_dir)
    if not _writable(stamp.parent):
        return False
    digest = kernel_sources_hash(package_dir)
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    for cache in cache_dirs(package_dir):
        for pattern in ("*.nbi", "*.nbc"):
            for cached in cache.glob(pattern):
                cached.unlink(missing_ok=True)
    stamp.parent.mkdir(parents=True, exist_ok=True)
    # written atomically: a concurrent import reads the old stamp or the new one
    fd, tmp = tempfile.mkstemp(dir=stamp.parent, prefix=STAMP_NAME)
    with os.fdopen(fd, "w") as f:
        f.write(digest)
    os.replace(tmp, stamp)
    return True


_checked = False


def ensure_fresh() -> None:
    """:func:`refresh` this package's caches, once per process (a failure to clear them is a warning)."""
    global _checked
    if _checked:
        return
    _checked = True
    package = Path(os.path.abspath(__file__)).parent
    try:
        refresh(package)
    except OSError as exc:
        warnings.warn(f"jamflow could not clear numba's kernel caches after a change of kernel code ({exc}); "
                      f"clear them by hand: find {os.environ.get('NUMBA_CACHE_DIR') or package} "
                      "-name '*.nb[ci]' -delete", stacklevel=2)
