"""A warm-started bounded simplex on a fill-reducing sparse LU, for LPs with many more
rows than columns (CALiPPSO's jamming LPs): :func:`solve`.

Depends on numpy, scipy (SuperLU) and numba; the nested-dissection ordering on
``pymetis``; the LU is Intel MKL PARDISO's when the ``mkl`` wheel is installed
(``pip install 'jamflow[lp]'``), SuperLU's otherwise.
"""

from .state import Stats, Tolerances
from .warm import Result, solve

__all__ = ["Result", "Stats", "Tolerances", "solve"]
