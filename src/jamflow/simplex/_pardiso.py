"""Intel MKL PARDISO through ``ctypes``: the sparse LU of the working-set matrix when the
``mkl`` wheel is installed (``pip install 'jamflow[lp]'``).

PARDISO orders ``W + W^T`` by METIS nested dissection, scales and permutes ``W`` by a
maximum weighted matching and factorises it supernodally with pivoting inside the
supernodes; a pivot it cannot find is *perturbed* to ``1e-13`` of the matrix's norm
instead of failing. A factorisation with perturbed pivots is of a different matrix, so
:class:`PardisoLU` reports it (``perturbed``) and the caller factorises otherwise
(:meth:`jamflow.simplex.factor.Factor.factorise`: ``W^T`` by PARDISO, then SuperLU). It runs on one thread (MKL's sequential layer), like the chain's HiGHS.
Not through ``pypardiso``: its ``solve`` compares (or hashes) the whole matrix and
re-indexes it on every call, and solves with ``W^T`` only by being handed a CSC copy,
which it takes for a new matrix and factorises again; the simplex needs both
solves of one factorisation, and the perturbed-pivot count, at every pivot.
Measured against SuperLU with a METIS order on the working sets of captured CALiPPSO
LPs: ``docs/notes/warm-simplex.md`` ("A cheaper factorisation").
"""

from __future__ import annotations

import ctypes
import glob
import os
import sys
from ctypes.util import find_library

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

#: PARDISO's matrix types: real and nonsymmetric (``W``), real symmetric positive
#: definite (only the upper triangle is passed).
REAL_NONSYMMETRIC, REAL_SPD = 11, 2

#: ``mkl_set_threading_layer``'s code of the sequential layer.
_MKL_THREADING_SEQUENTIAL = 1

_ANALYSE_FACTORISE, _SOLVE, _RELEASE = 12, 33, -1
#: PARDISO's error code of a zero pivot (a singular matrix).
ZERO_PIVOT = -4


def _iparm() -> NDArray[np.int32]:
    """PARDISO's integer parameters (0-based positions of the manual's ``iparm(i+1)``)."""
    iparm = np.zeros(64, dtype=np.int32)
    iparm[0] = 1  # the values below, not PARDISO's defaults
    iparm[1] = 2  # METIS nested dissection of W + W^T
    iparm[9] = 13  # perturb a pivot below 1e-13 |W| (reported in iparm[13], then refused)
    iparm[10] = 1  # scale ...
    iparm[12] = 1  # ... and permute by a maximum weighted matching (nonsymmetric default)
    iparm[17] = -1  # report nnz(L + U) in iparm[17]
    iparm[34] = 1  # zero-based indices
    return iparm


def _load() -> ctypes.CDLL | None:
    """``libmkl_rt`` from the ``mkl`` wheel (``sys.prefix/lib``) or the system, else None."""
    paths = [find_library("mkl_rt")] + sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
    for path in paths:
        if not path:
            continue
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        lib.MKL_Set_Threading_Layer(ctypes.c_int(_MKL_THREADING_SEQUENTIAL))
        i32, f64 = ctypes.POINTER(ctypes.c_int32), ctypes.POINTER(ctypes.c_double)
        lib.pardiso.argtypes = [ctypes.POINTER(ctypes.c_int64), i32, i32, i32, i32, i32, f64, i32, i32, i32, i32,
                                i32, i32, f64, f64, i32]
        lib.pardiso.restype = None
        lib.MKL_Get_Version_String.argtypes = [ctypes.c_char_p, ctypes.c_int]
        return lib
    return None


_LIB: list[ctypes.CDLL | None] = []


def library() -> ctypes.CDLL | None:
    """The loaded MKL runtime (loaded once), or None when it is not installed."""
    if not _LIB:
        _LIB.append(_load())
    return _LIB[0]


def version() -> str:
    """MKL's version string, e.g. ``Intel(R) oneAPI Math Kernel Library Version 2026.2 ...``."""
    lib = library()
    if lib is None:
        return ""
    buf = ctypes.create_string_buffer(256)
    lib.MKL_Get_Version_String(buf, 256)
    return buf.value.decode().strip()


class PardisoError(RuntimeError):
    """PARDISO returned an error code."""

    def __init__(self, code: int, phase: int) -> None:
        super().__init__(f"PARDISO error {code} in phase {phase}")
        self.code = code


class PardisoLU:
    """One PARDISO factorisation of a square matrix ``W`` (n, n) and its solves.

    Parameters
    ----------
    matrix_type : int
        :data:`REAL_NONSYMMETRIC`, or :data:`REAL_SPD` (pass the upper triangle).
    options : dict, optional
        ``iparm`` entries (0-based) that replace :func:`_iparm`'s, e.g. ``{12: 0}``
        (no matching) or ``{7: 2}`` (two steps of iterative refinement in each solve).

    Attributes
    ----------
    fill : int
        ``nnz(L + U)`` (of ``L`` for :data:`REAL_SPD`).
    perturbed : int
        Pivots PARDISO perturbed; a factorisation with any is not of ``W``.
    """

    def __init__(self, matrix_type: int = REAL_NONSYMMETRIC, options: dict[int, int] | None = None) -> None:
        lib = library()
        if lib is None:
            raise ImportError("MKL PARDISO needs the mkl wheel: pip install 'jamflow[lp]'")
        self._lib = lib
        self._pt = np.zeros(64, dtype=np.int64)  # PARDISO's handle, zero before the first call
        self._iparm = _iparm()
        for key, value in (options or {}).items():
            self._iparm[key] = value
        self._mtype = matrix_type
        self._perm = np.zeros(1, dtype=np.int32)
        self._n = 0
        self.fill = 0
        self.perturbed = 0

    def _call(self, phase: int, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """One PARDISO call; ``b`` is (n,) or (n, k) in column-major order (k right-hand sides)."""
        i32 = ctypes.POINTER(ctypes.c_int32)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        one = ctypes.c_int32(1)
        nrhs = ctypes.c_int32(1 if b.ndim == 1 else b.shape[1])
        self._lib.pardiso(self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), ctypes.byref(one),
                          ctypes.byref(one), ctypes.byref(ctypes.c_int32(self._mtype)),
                          ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(self._n)),
                          self._a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), self._ia.ctypes.data_as(i32),
                          self._ja.ctypes.data_as(i32), self._perm.ctypes.data_as(i32), ctypes.byref(nrhs),
                          self._iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(0)),
                          b.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                          x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), ctypes.byref(err))
        if err.value != 0:
            raise PardisoError(err.value, phase)
        return x

    def factorise(self, W: sp.csr_matrix) -> None:
        """Order, analyse and factorise ``W`` (replaces an earlier factorisation).

        Raises
        ------
        PardisoError
            PARDISO failed (code :data:`ZERO_PIVOT`: ``W`` is singular to it).
        """
        self.release()
        W = sp.csr_matrix(W, dtype=np.float64, copy=True)
        W.sort_indices()
        self._n = W.shape[0]
        self._a, self._ia, self._ja = W.data, W.indptr.astype(np.int32), W.indices.astype(np.int32)
        self._call(_ANALYSE_FACTORISE, np.zeros(self._n))
        self.fill = int(self._iparm[17])
        self.perturbed = int(self._iparm[13])

    def solve(self, b: NDArray[np.float64], transposed: bool = False) -> NDArray[np.float64]:
        """``W^-1 b``, or ``W^-T b`` when ``transposed``; ``b`` of shape (n,), or (n, k) for
        k right-hand sides in one pass over the factors (returned in column-major order)."""
        self._iparm[11] = 2 if transposed else 0
        return self._call(_SOLVE, np.asfortranarray(b, dtype=np.float64))

    def release(self) -> None:
        """Free PARDISO's memory of this factorisation (no-op when there is none)."""
        if self._pt.any():
            self._call(_RELEASE, np.zeros(max(self._n, 1)))
            self._pt[:] = 0

    def __del__(self) -> None:
        if getattr(self, "_pt", None) is not None and self._pt.any():
            self.release()
