"""The CALiPPSO authors' LS configurations vendored in ``tests/data/calippso-ls/``.

One place names them; a missing file is an error (``FileNotFoundError``), never a skip,
so a test that reads them cannot silently vanish.
"""

from __future__ import annotations

from pathlib import Path

#: folder of the vendored ``.dat`` files (MIT, CALiPPSO.jl; licence in its README.md)
LS_DIR = Path(__file__).resolve().parent / "data" / "calippso-ls"
#: dimensions of the three configurations (N = 1024 each)
LS_DIMENSIONS = (3, 4, 5)


def ls_dat(d: int) -> Path:
    """Path of the LS configuration in dimension ``d``; raises if it is missing."""
    path = LS_DIR / f"Centers-after-LS--N-1024--d-{d}.dat"
    if not path.is_file():
        raise FileNotFoundError(f"vendored test data missing: {path}")
    return path
