"""``njit`` for the package's kernels: every kernel module imports it from here, so the on-disk
kernel caches are checked against the sources (:func:`._kernel_cache.ensure_fresh`) before the
first kernel of a process loads, and ``import jamflow`` itself never touches them."""

from numba import njit
from numpy.typing import NDArray

from ._kernel_cache import ensure_fresh

ensure_fresh()

__all__ = ["njit", "read_only"]


def read_only(a: NDArray) -> NDArray:
    """``a``, or a read-only view of it (no copy).

    numba compiles a kernel once per writability of each array argument; a kernel fed
    both stored (read-only) and freshly computed arrays is compiled twice. Passing every
    such argument through here keeps one compiled version.
    """
    if not a.flags.writeable:
        return a
    view = a.view()
    view.flags.writeable = False
    return view
