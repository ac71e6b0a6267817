"""``njit`` for the package's kernels: every kernel module imports it from here, so the on-disk
kernel caches are checked against the sources (:func:`._kernel_cache.ensure_fresh`) before the
first kernel of a process loads, and ``import jamflow`` itself never touches them."""

from numba import njit

from ._kernel_cache import ensure_fresh

ensure_fresh()

__all__ = ["njit"]
