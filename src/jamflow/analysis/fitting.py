"""Power-law exponents of sampled distributions with statistical and systematic errors.

One source of truth for the gap exponent ``gamma`` (``p(h) ~ h^-gamma``,
:mod:`jamflow.analysis.gaps`) and the small-force exponent ``theta``
(``P(f) ~ f^theta``, :mod:`jamflow.analysis.forces`). Everything here works on
the raw samples (gaps, forces), never on a histogram.

Method
------
*Estimator.* Inside a window ``[a, b]`` the samples are modelled by a power law
``p(x) ∝ x^alpha`` truncated to the window; ``alpha`` is its maximum-likelihood
estimate. Equivalently, ``alpha`` is the exponent whose conditional cumulative
distribution ``F(x) = (x^(alpha+1) - a^(alpha+1)) / (b^(alpha+1) - a^(alpha+1))``
has the same mean of ``log x`` as the empirical cumulative distribution of the
samples in the window. No binning enters, so there is no bin-width bias, and the
samples below ``a`` and above ``b`` (plateau, cut-off) do not bias it either
(Clauset, Shalizi & Newman, SIAM Rev. 51, 661 (2009), for the doubly truncated case).
The asymptotic error ``1 / sqrt(n Var(log x))`` (Fisher information) is used only to
weigh windows against each other in the break test.

*Statistical error* ``stat``: the standard deviation (ddof = 1) of ``alpha`` over
``n_boot`` bootstrap resamples that first draw packings with replacement, then the
samples (pairs, contacts) of each drawn packing with replacement, with a seeded
generator; the window stays fixed. This keeps the correlations within a packing.

*Systematic error* ``sys``: windows ``[a', b']`` with edges on a logarithmic grid of
:data:`GRID_PER_DECADE` points per decade inside the chosen window, spanning at least
``min_decades`` (default :data:`MIN_WINDOW_DECADES` = 1.5) decades and holding at least
``min_count`` samples; ``sys`` is the standard deviation (ddof = 0) of their
exponents. It also contains the sampling scatter of the smaller windows, so it is an
upper bound on the window dependence (for an exact power law with ~3e4 samples over
seven decades it is ~0.03 while ``stat`` is ~0.005). Half the range over the windows
is stored as ``_sys_half_range`` for comparison.

*Chosen window.* The caller gives the scaling range ``[lo, hi]`` (for gaps, ``lo`` is
raised to ``1/p`` of an LS snapshot at pressure ``p``, where its plateau ends). The
upper edge is then lowered to where the distribution departs from one power law:
while the break test flags a break in ``[lo, hi]`` at ``s`` and ``[lo, s]`` still
spans ``min_decades``, ``hi <- s``.

*Break test.* For every grid point ``s`` with at least ``min_decades / 2`` decades
on both sides, the exponents of the disjoint windows ``[lo, s]`` and ``[s, hi]``
(independent samples) are compared, ``z(s) = |alpha_L - alpha_R| /
sqrt(err_L^2 + err_R^2)`` with Fisher errors; a break is flagged when
``max_s z(s) > BREAK_Z`` (= 4: with ~10 correlated splits the false-alarm rate of a
single power law is below 1e-3). The break is placed at the split of largest profile
likelihood of the two-piece model.

*Refusal.* With fewer than ``min_count`` (default :data:`MIN_IN_WINDOW` = 50) samples
in the window the exponent is NaN and ``reason`` says why: below that the error of
``alpha`` over two decades exceeds ~0.1, the size of the difference a fit is meant
to resolve (e.g. theta = 0.42 against 0.17).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

__all__ = [
    "BREAK_Z",
    "GRID_PER_DECADE",
    "MIN_IN_WINDOW",
    "MIN_WINDOW_DECADES",
    "FIT_METHOD",
    "ExponentFit",
    "ExponentAnalysis",
    "FitWarning",
    "check_window",
    "mle_exponent",
    "bootstrap_error",
    "break_test",
    "analyse_exponent",
    "density_prefactor",
]

#: Fewest samples inside a fit window for an exponent to be reported.
MIN_IN_WINDOW: int = 50
#: Smallest span of a window entering the systematic error [decades].
MIN_WINDOW_DECADES: float = 1.5
#: Window edges per decade of the scan grid.
GRID_PER_DECADE: int = 4
#: z-score above which two sides of a split are declared different power laws.
BREAK_Z: float = 4.0

FIT_METHOD: str = (
    "maximum likelihood of a power law truncated to the window (no binning); stat = std over "
    "bootstrap resamples of packings then samples within packings; sys = std over windows "
    f"spanning >= {MIN_WINDOW_DECADES} decades inside the chosen window (edges {GRID_PER_DECADE} per decade); "
    f"upper edge lowered to a power-law break (split test z > {BREAK_Z:g})"
)


class FitWarning(UserWarning):
    """A power-law fit was refused (exponent NaN) or its systematic error is undefined; the
    message says why (the same text as the analysis' ``reason``). The command line prints it
    as its own ``jamflow: warning:`` line instead."""


def check_window(x_min: float, x_max: float, what: str = "fit window") -> None:
    """Raise ValueError unless ``0 < x_min < x_max < inf`` (one line naming the edges)."""
    if not (np.isfinite(x_min) and np.isfinite(x_max) and 0.0 < x_min < x_max):
        raise ValueError(f"{what} needs 0 < fit-min < fit-max, got fit-min={x_min:g}, fit-max={x_max:g}")


def _mean_frac(t: float) -> float:
    """Mean of v on [0, 1] under the density ∝ exp(t v)."""
    if abs(t) < 1e-6:
        return 0.5 + t / 12.0
    return -1.0 / np.expm1(-t) - 1.0 / t


def _var_frac(t: float) -> float:
    """Variance of v on [0, 1] under the density ∝ exp(t v)."""
    if abs(t) < 1e-3:
        return 1.0 / 12.0 - t * t / 720.0
    return 1.0 / (t * t) - 1.0 / (4.0 * np.sinh(0.5 * t) ** 2)


@dataclass(frozen=True)
class ExponentFit:
    """Maximum-likelihood ``alpha`` of ``p(x) ∝ x^alpha`` on ``[x_min, x_max]``.

    ``alpha_err`` is the asymptotic (Fisher) error; ``n`` the samples in the window.
    """

    alpha: float
    alpha_err: float
    x_min: float
    x_max: float
    n: int


def mle_exponent(x: ArrayLike, x_min: float, x_max: float) -> ExponentFit:
    """Maximum-likelihood exponent of the samples ``x`` in ``[x_min, x_max]``.

    In ``v = log(x / x_min) / log(x_max / x_min)`` the truncated power law is the
    density ``∝ exp(t v)`` on ``[0, 1]`` with ``t = (alpha + 1) log(x_max / x_min)``;
    the likelihood is maximal where its mean equals the sample mean of ``v``.

    Raises
    ------
    ValueError
        Invalid window, or fewer than two distinct samples in it.
    """
    check_window(x_min, x_max)
    x = np.asarray(x, dtype=np.float64)
    x = x[(x >= x_min) & (x <= x_max)]
    n = len(x)
    span = np.log(x_max / x_min)
    v = np.log(x / x_min) / span if n else x
    m = float(np.mean(v)) if n else np.nan
    if n < 2 or not 0.0 < m < 1.0 or np.ptp(v) == 0.0:
        raise ValueError(f"{n} sample(s) in [{x_min:g}, {x_max:g}]: no exponent")
    bound = min(700.0, max(50.0, 4.0 / min(m, 1.0 - m)))
    t = brentq(lambda s: _mean_frac(s) - m, -bound, bound, xtol=1e-12)
    err = 1.0 / (span * np.sqrt(n * _var_frac(t)))
    return ExponentFit(alpha=t / span - 1.0, alpha_err=float(err), x_min=float(x_min), x_max=float(x_max), n=n)


def bootstrap_error(samples: Sequence[NDArray[np.float64]], x_min: float, x_max: float,
                    n_boot: int = 200, seed: int = 0) -> float:
    """Std (ddof = 1) of the window exponent over hierarchical bootstrap resamples.

    Each resample draws ``len(samples)`` packings with replacement, then the samples
    of every drawn packing with replacement. Resamples with fewer than two samples
    in the window are dropped; NaN when fewer than two resamples remain. Each
    packing's samples are sorted first, so the error does not depend on the order in
    which its pairs were listed (a relabelling of the particles).
    """
    samples = [np.sort(np.asarray(s, dtype=np.float64)) for s in samples]
    rng = np.random.default_rng(seed)
    m = len(samples)
    alphas = []
    for _ in range(n_boot):
        pick = rng.integers(0, m, m)
        pooled = np.concatenate([samples[k][rng.integers(0, len(samples[k]), len(samples[k]))] for k in pick])
        try:
            alphas.append(mle_exponent(pooled, x_min, x_max).alpha)
        except ValueError:
            continue
    return float(np.std(alphas, ddof=1)) if len(alphas) >= 2 else np.nan


def _grid(lo: float, hi: float) -> NDArray[np.float64]:
    """Points 10^(k / GRID_PER_DECADE) strictly inside (lo, hi), plus lo and hi."""
    k = np.arange(np.ceil(np.log10(lo) * GRID_PER_DECADE), np.floor(np.log10(hi) * GRID_PER_DECADE) + 1)
    inner = 10.0 ** (k / GRID_PER_DECADE)
    inner = inner[(inner > lo * (1 + 1e-9)) & (inner < hi * (1 - 1e-9))]
    return np.concatenate([[lo], inner, [hi]])


def _log_likelihood(x: NDArray[np.float64], fit: ExponentFit) -> float:
    """Log-likelihood of the samples in the window under the fitted truncated power law.

    Written for ``u = log x`` (the Jacobian ``-sum log x`` is common to every model of
    the same samples and is left out): ``n log(t / expm1(t) / span) + t sum v``.
    """
    span = np.log(fit.x_max / fit.x_min)
    x = x[(x >= fit.x_min) & (x <= fit.x_max)]
    t = (fit.alpha + 1.0) * span
    norm = 0.0 if abs(t) < 1e-12 else np.log(t / np.expm1(t))
    return float(len(x) * (norm - np.log(span)) + t * np.sum(np.log(x / fit.x_min) / span))


def break_test(x: NDArray[np.float64], lo: float, hi: float,
               min_decades: float = MIN_WINDOW_DECADES) -> tuple[float, float]:
    """Largest split z-score in ``[lo, hi]`` and the most likely break (see module docstring).

    Splits are the grid points with at least ``min_decades / 2`` decades on both
    sides. The z-score decides whether there is a break; its location is the split
    of largest profile likelihood of the two-piece model (the two truncated power
    laws and the binomial share of samples on each side), which, unlike the largest
    z, is not pulled towards the side with the longer clean stretch.

    Returns ``(z_max, split)``; ``(0, nan)`` when no split has two samples on both sides.
    """
    best_z, best_ll, where = 0.0, -np.inf, np.nan
    half = 0.5 * min_decades
    for s in _grid(lo, hi)[1:-1]:
        if np.log10(s / lo) < half - 1e-9 or np.log10(hi / s) < half - 1e-9:
            continue
        try:
            left, right = mle_exponent(x, lo, s), mle_exponent(x, s, hi)
        except ValueError:
            continue
        best_z = max(best_z, float(abs(left.alpha - right.alpha) / np.hypot(left.alpha_err, right.alpha_err)))
        n = left.n + right.n
        ll = (_log_likelihood(x, left) + _log_likelihood(x, right)
              + left.n * np.log(left.n / n) + right.n * np.log(right.n / n))
        if ll > best_ll:
            best_ll, where = ll, float(s)
    return best_z, where


@dataclass(frozen=True)
class ExponentAnalysis:
    """Exponent ``alpha`` of ``p(x) ∝ x^alpha`` with its errors and window scan.

    ``alpha`` is NaN when refused; ``reason`` then says why (empty otherwise).
    ``break_z`` is the largest split z-score in the searched range; ``break_at`` the
    most likely break, NaN unless ``break_detected``.
    ``scan_*`` arrays, shape (W,), hold every window of the systematic scan.
    """

    alpha: float
    stat: float
    sys: float
    x_min: float
    x_max: float
    n_in_window: int
    reason: str
    break_detected: bool
    break_at: float
    break_z: float
    range_min: float
    range_max: float
    n_boot: int
    seed: int
    sys_half_range: float = np.nan
    scan_lower: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    scan_upper: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    scan_alpha: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    scan_alpha_err: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    scan_n: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def total(self) -> float:
        """Combined error ``sqrt(stat^2 + sys^2)``; NaN when either is undefined."""
        return float(np.hypot(self.stat, self.sys))

    def exponent_attrs(self, name: str, sign: float = 1.0) -> dict:
        """Attributes ``<name>`` (= ``sign * alpha``), ``<name>_stat``, ``_sys``, ``_err``, counts, reason."""
        return {
            name: sign * self.alpha,
            f"{name}_stat": self.stat,
            f"{name}_sys": self.sys,
            f"{name}_sys_half_range": self.sys_half_range,
            f"{name}_err": self.total,
            f"{name}_n_in_window": self.n_in_window,
            f"{name}_n_windows": len(self.scan_alpha),
            f"{name}_reason": self.reason,
        }

    def window_attrs(self, prefix: str = "fit") -> dict:
        """Attributes of the chosen window, the searched range, the break test and the method."""
        return {
            f"{prefix}_min": self.x_min,
            f"{prefix}_max": self.x_max,
            f"{prefix}_scaling_range_min": self.range_min,
            f"{prefix}_scaling_range_max": self.range_max,
            f"{prefix}_break_detected": int(self.break_detected),
            f"{prefix}_break_at": self.break_at,
            f"{prefix}_break_z": self.break_z,
            f"{prefix}_method": FIT_METHOD,
            f"{prefix}_min_in_window": MIN_IN_WINDOW,
            f"{prefix}_bootstrap_resamples": self.n_boot,
            f"{prefix}_bootstrap_seed": self.seed,
        }

    def scan_variables(self, sign: float, symbol: str, unit: str) -> dict:
        """Variables on dim ``window`` for the diagnostic figure (exponent ``sign * alpha``)."""
        u = {"units": unit}
        return {
            "window_lower": ("window", self.scan_lower, {**u, "long_name": "lower edge of a scanned fit window"}),
            "window_upper": ("window", self.scan_upper, {**u, "long_name": "upper edge of a scanned fit window"}),
            "window_exponent": ("window", sign * self.scan_alpha,
                                {"units": "1", "long_name": f"{symbol} fitted on the window"}),
            "window_exponent_err": ("window", self.scan_alpha_err,
                                    {"units": "1", "long_name": f"asymptotic (Fisher) error of {symbol} on the window"}),
            "window_n": ("window", self.scan_n, {"units": "1", "long_name": "samples in the window"}),
        }


def analyse_exponent(
    samples: Sequence[ArrayLike],
    lo: float,
    hi: float,
    *,
    choose_window: bool = True,
    min_count: int = MIN_IN_WINDOW,
    min_decades: float = MIN_WINDOW_DECADES,
    n_boot: int = 200,
    seed: int = 0,
) -> ExponentAnalysis:
    """Exponent, statistical and systematic error, chosen window and break flag.

    Parameters
    ----------
    samples : sequence of array_like, each shape (P_s,)
        Positive samples (gaps, normalised forces) of each packing.
    lo, hi : float
        Scaling range to search (same unit as the samples).
    choose_window : bool
        True: lower ``hi`` to a detected break (module docstring). False: fit on
        ``[lo, hi]`` as given (still scanned, break still reported).
    min_count, min_decades, n_boot, seed
        Refusal threshold, smallest scanned span [decades], bootstrap resamples and
        their seed.

    Raises
    ------
    ValueError
        ``lo >= hi`` or a non-positive edge.
    """
    check_window(lo, hi)
    arrays = [np.asarray(s, dtype=np.float64) for s in samples]
    if not arrays:
        raise ValueError("no samples to fit")
    pooled = np.concatenate(arrays)
    z, split = break_test(pooled, lo, hi, min_decades)
    broken = z > BREAK_Z
    a, b = lo, hi
    if choose_window:
        while True:
            z_w, s_w = break_test(pooled, a, b, min_decades)
            if not (z_w > BREAK_Z and np.log10(s_w / a) >= min_decades - 1e-9):
                break
            b = s_w
    n_in = int(np.sum((pooled >= a) & (pooled <= b)))
    common = dict(x_min=a, x_max=b, n_in_window=n_in, break_detected=bool(broken),
                  break_at=split if broken else np.nan, break_z=z,
                  range_min=float(lo), range_max=float(hi), n_boot=n_boot, seed=seed)
    if n_in < min_count:
        reason = f"fit refused: {n_in} samples in [{a:g}, {b:g}], fewer than the minimum {min_count}"
        warnings.warn(reason, FitWarning, stacklevel=2)
        return ExponentAnalysis(alpha=np.nan, stat=np.nan, sys=np.nan, reason=reason, **common)
    alpha = mle_exponent(pooled, a, b).alpha
    stat = bootstrap_error(arrays, a, b, n_boot, seed)
    grid = _grid(a, b)
    rows = []
    for i, w_lo in enumerate(grid):
        for w_hi in grid[i + 1:]:
            if np.log10(w_hi / w_lo) < min_decades - 1e-9:
                continue
            try:
                fit = mle_exponent(pooled, w_lo, w_hi)
            except ValueError:
                continue
            if fit.n >= min_count:
                rows.append((w_lo, w_hi, fit.alpha, fit.alpha_err, fit.n))
    scan = np.array(rows, dtype=np.float64).reshape(-1, 5)
    if len(scan) >= 2:
        sys_err, half_range = float(np.std(scan[:, 2])), 0.5 * float(np.ptp(scan[:, 2]))
    else:
        sys_err = half_range = np.nan
    reason = "" if len(scan) >= 2 else (
        f"systematic error undefined: fewer than two windows spanning >= {min_decades:g} decades "
        f"with >= {min_count} samples inside [{a:g}, {b:g}]")
    if reason:
        warnings.warn(reason, FitWarning, stacklevel=2)
    return ExponentAnalysis(alpha=float(alpha), stat=stat, sys=sys_err, sys_half_range=half_range, reason=reason,
                            scan_lower=scan[:, 0], scan_upper=scan[:, 1], scan_alpha=scan[:, 2],
                            scan_alpha_err=scan[:, 3], scan_n=scan[:, 4].astype(np.int64), **common)


def density_prefactor(alpha: float, x_min: float, x_max: float, mass: float) -> float:
    """``C`` such that ``C x^alpha`` integrates to ``mass`` over ``[x_min, x_max]``.

    Used to draw a fit over a histogram whose window holds ``mass`` (e.g. a fraction
    of all samples, or neighbours per particle).
    """
    beta = alpha + 1.0
    if abs(beta) < 1e-12:
        return mass / np.log(x_max / x_min)
    return mass * beta / (x_max**beta - x_min**beta)
