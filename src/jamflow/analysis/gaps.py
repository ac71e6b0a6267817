"""Gap distribution p(h) of jammed and nearly jammed packings, with a power-law fit.

The relative gap of a pair is ``h_ij = r_ij / sigma_ij - 1`` (CALiPPSO paper, App. D).
Contacts are excluded: they are the packing's explicit contacts when it has them,
otherwise pairs with ``h <= gap_tol``. Near jamming the remaining gaps follow
``p(h) ~ h^(-gamma)`` over many decades with the mean-field exponent
``gamma = 0.41269`` (Charbonneau, Kurchan, Parisi, Urbani, Zamponi 2014); an LS
snapshot at finite pressure ``p`` instead shows a plateau for ``h < 1/p``.

Normalisation
-------------
``gap_density`` counts *neighbours per particle per unit h*: a pair is a neighbour of
both its particles, so ``gap_density = 2 n_pairs(bin) / (N dh)`` and its integral up
to ``h`` is the mean number of non-contact neighbours within gap ``h``
(the cumulative ``Z(h) - z`` of Charbonneau et al.). ``gap_pdf`` is the same
histogram normalised to unit integral over the binned range.

The histogram, sample-average and fit helpers here are shared by
:mod:`jamflow.analysis.forces`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..io import new_dataset_attrs
from ..packing import Packing, near_pairs
from ..tolerances import CONTACT_GAP_TOL

__all__ = [
    "MEAN_FIELD_GAP_EXPONENT",
    "PowerLawFit",
    "log_bin_edges",
    "fit_power_law",
    "sample_average",
    "non_contact_gaps",
    "gap_histogram",
    "gap_distribution",
]

#: Mean-field exponent of the gap distribution, p(h) ~ h^(-gamma) (Charbonneau et al. 2014).
MEAN_FIELD_GAP_EXPONENT: float = 0.41269


@dataclass(frozen=True)
class PowerLawFit:
    """Result of :func:`fit_power_law`: ``y = prefactor * x**slope`` on ``[x_min, x_max]``."""

    slope: float
    slope_err: float
    prefactor: float
    x_min: float
    x_max: float
    n_points: int
    chi2_reduced: float


def log_bin_edges(x_min: float, x_max: float, bins_per_decade: int) -> NDArray[np.float64]:
    """Logarithmically spaced bin edges from ``x_min`` to ``x_max``, both > 0.

    The number of bins is ``ceil(bins_per_decade * log10(x_max / x_min))``, so the
    edges hit both ends exactly.
    """
    if not (0.0 < x_min < x_max) or not np.isfinite(x_max):
        raise ValueError(f"need 0 < x_min < x_max, got x_min={x_min}, x_max={x_max}")
    if bins_per_decade < 1:
        raise ValueError(f"bins_per_decade must be >= 1, got {bins_per_decade}")
    n = int(np.ceil(bins_per_decade * np.log10(x_max / x_min) - 1e-9))
    return np.logspace(np.log10(x_min), np.log10(x_max), max(n, 1) + 1)


def fit_power_law(
    x: ArrayLike,
    y: ArrayLike,
    y_err: ArrayLike,
    x_min: float,
    x_max: float,
) -> PowerLawFit:
    """Weighted least-squares fit of ``log y = log A + slope * log x``.

    Points with ``x_min <= x <= x_max``, ``y > 0`` and ``y_err > 0`` enter with
    weight ``1 / sigma_log^2``, ``sigma_log = y_err / y`` (error propagation to
    ``log y``). The slope error is the covariance estimate, multiplied by
    ``sqrt(chi2_reduced)`` when that exceeds one (the data scatter more than their
    error bars say).

    Parameters
    ----------
    x, y, y_err : array_like, shape (B,)
        Bin centres, densities and their standard errors.
    x_min, x_max : float
        Fit window.

    Raises
    ------
    ValueError
        Fewer than three usable points in the window.
    """
    x, y, y_err = (np.asarray(a, dtype=np.float64) for a in (x, y, y_err))
    use = (x >= x_min) & (x <= x_max) & (y > 0) & (y_err > 0) & np.isfinite(y) & np.isfinite(y_err)
    n = int(use.sum())
    if n < 3:
        raise ValueError(
            f"power-law fit on [{x_min:g}, {x_max:g}] has {n} usable bin(s); widen the window or add samples"
        )
    lx, ly = np.log(x[use]), np.log(y[use])
    w = (y[use] / y_err[use]) ** 2
    design = np.stack([np.ones(n), lx], axis=1)
    normal = design.T @ (w[:, None] * design)
    coef = np.linalg.solve(normal, design.T @ (w * ly))
    cov = np.linalg.inv(normal)
    resid = ly - design @ coef
    chi2_red = float(np.sum(w * resid**2) / (n - 2)) if n > 2 else np.nan
    scale = np.sqrt(max(1.0, chi2_red)) if np.isfinite(chi2_red) else 1.0
    return PowerLawFit(
        slope=float(coef[1]),
        slope_err=float(np.sqrt(cov[1, 1]) * scale),
        prefactor=float(np.exp(coef[0])),
        x_min=float(x_min),
        x_max=float(x_max),
        n_points=n,
        chi2_reduced=chi2_red,
    )


def sample_average(
    densities: NDArray[np.float64], counts: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
    """Mean over samples and its standard error.

    Parameters
    ----------
    densities : ndarray, shape (M, B)
        Per-sample histogram densities.
    counts : ndarray, shape (M, B)
        Raw counts behind them (for the single-sample error).

    Returns
    -------
    mean, stderr : ndarray, shape (B,)
    method : str
        ``"sample standard error"`` for M >= 2 (std with ddof=1 over sqrt(M)); for a
        single sample the Poisson error ``density / sqrt(count)``.
    """
    m = densities.shape[0]
    mean = densities.mean(axis=0)
    if m >= 2:
        return mean, densities.std(axis=0, ddof=1) / np.sqrt(m), "sample standard error (ddof=1) over samples"
    total = counts.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.where(total > 0, mean / np.sqrt(total), 0.0)
    return mean, err, "Poisson counting error (single sample)"


def non_contact_gaps(packing: Packing, max_gap: float, gap_tol: float | None = None) -> NDArray[np.float64]:
    """Relative gaps ``0 < h <= max_gap`` of near pairs that are not contacts, shape (P,).

    Parameters
    ----------
    packing : Packing
    max_gap : float
        Largest gap kept (dimensionless); the neighbour search radius is
        ``max(D) (1 + max_gap)``, which must stay below half the box width.
    gap_tol : float or None
        ``None``: exclude the packing's explicit contacts if it has them, else pairs
        with ``h <= CONTACT_GAP_TOL``. A number: exclude pairs with ``h <= gap_tol``
        (recomputed from geometry even when contacts are stored).
    """
    pairs, h = near_pairs(packing, max_gap)
    if gap_tol is None and packing.contacts is not None:
        n = packing.n
        key = pairs.i * n + pairs.j
        contact_key = packing.contacts[:, 0] * n + packing.contacts[:, 1]
        keep = ~np.isin(key, contact_key)
    else:
        keep = h > (CONTACT_GAP_TOL if gap_tol is None else gap_tol)
    h = h[keep]
    # a non-contact pair at h <= 0 (touching within round-off) has no place on a log axis
    return h[h > 0.0]


def gap_histogram(
    gaps: Sequence[ArrayLike],
    n_particles: Sequence[int],
    max_gap: float = 0.1,
    min_gap: float = 1e-13,
    bins_per_decade: int = 5,
    fit_min: float = 1e-5,
    fit_max: float = 1e-2,
) -> tuple[xr.Dataset, dict]:
    """Logarithmic histogram of gap samples, sample average and power-law fit.

    Parameters
    ----------
    gaps : sequence of array_like, each shape (P_s,)
        Non-contact relative gaps of each sample (dimensionless).
    n_particles : sequence of int
        N of each sample (for the per-particle normalisation).
    max_gap, min_gap, bins_per_decade, fit_min, fit_max
        As in :func:`gap_distribution`.

    Returns
    -------
    dataset : xarray.Dataset
        Variables of :func:`gap_distribution` (no global attributes).
    summary : dict
        Fit results and counts (``fit_exponent``, ``fit_exponent_err``, ...).
    """
    if len(gaps) == 0 or len(gaps) != len(n_particles):
        raise ValueError("need one particle count per gap sample, and at least one sample")
    edges = log_bin_edges(min_gap, max_gap, bins_per_decade)
    width = np.diff(edges)
    counts = np.zeros((len(gaps), len(width)))
    density = np.zeros_like(counts)
    pdf = np.zeros_like(counts)
    n_below = 0
    for s, (h, n) in enumerate(zip(gaps, n_particles)):
        h = np.asarray(h, dtype=np.float64)
        n_below += int(np.sum((h > 0) & (h < min_gap)))
        counts[s], _ = np.histogram(h, bins=edges)
        density[s] = 2.0 * counts[s] / (n * width)
        total = counts[s].sum()
        pdf[s] = counts[s] / (total * width) if total > 0 else 0.0
    dens_mean, dens_err, method = sample_average(density, counts)
    pdf_mean, pdf_err, _ = sample_average(pdf, counts)
    centre = np.sqrt(edges[:-1] * edges[1:])
    summary: dict = {"error_method": method, "n_below_range": n_below, "n_samples": len(gaps),
                     "fit_min": float(fit_min), "fit_max": float(fit_max)}
    try:
        fit = fit_power_law(centre, dens_mean, dens_err, fit_min, fit_max)
        summary.update(fit_exponent=-fit.slope, fit_exponent_err=fit.slope_err, fit_prefactor=fit.prefactor,
                       fit_chi2_reduced=fit.chi2_reduced, fit_n_bins=fit.n_points)
    except ValueError:
        summary.update(fit_exponent=np.nan, fit_exponent_err=np.nan, fit_prefactor=np.nan,
                       fit_chi2_reduced=np.nan, fit_n_bins=0)
    one = {"units": "1"}
    ds = xr.Dataset(
        data_vars={
            "h_lower": ("bin", edges[:-1], {**one, "long_name": "lower bin edge of the relative gap h"}),
            "h_upper": ("bin", edges[1:], {**one, "long_name": "upper bin edge of the relative gap h"}),
            "gap_density": ("bin", dens_mean, {**one, "long_name": "non-contact neighbours per particle per unit h, sample mean"}),
            "gap_density_err": ("bin", dens_err, {**one, "long_name": "standard error of gap_density"}),
            "gap_pdf": ("bin", pdf_mean, {**one, "long_name": "gap probability density normalised on the binned range, sample mean"}),
            "gap_pdf_err": ("bin", pdf_err, {**one, "long_name": "standard error of gap_pdf"}),
            "count": (("sample", "bin"), counts.astype(np.int64), {**one, "long_name": "number of non-contact pairs per bin"}),
        },
        coords={"h": ("bin", centre, {**one, "long_name": "relative gap h = r/sigma_ij - 1 (geometric bin centre)"})},
    )
    return ds, summary


def gap_distribution(
    packings: Sequence[Packing],
    max_gap: float = 0.1,
    min_gap: float = 1e-13,
    bins_per_decade: int = 5,
    fit_min: float = 1e-5,
    fit_max: float = 1e-2,
    gap_tol: float | None = None,
    parameters: dict | None = None,
) -> xr.Dataset:
    """Sample-averaged gap distribution on logarithmic bins with a power-law fit.

    Parameters
    ----------
    packings : sequence of Packing
        One packing per sample.
    max_gap, min_gap : float
        Binned range of h (dimensionless); positive gaps below ``min_gap`` are
        counted in the attribute ``n_below_range``.
    bins_per_decade : int
    fit_min, fit_max : float
        Window of the fit ``p(h) ~ h^(-gamma)``.
    gap_tol : float or None
        Contact definition, see :func:`non_contact_gaps`.
    parameters : dict or None
        Stage parameters recorded in the provenance attributes.

    Returns
    -------
    xarray.Dataset
        dims ``bin`` (and ``sample``): ``h`` (geometric bin centre), ``h_lower``,
        ``h_upper``, ``gap_density`` and ``gap_density_err``, ``gap_pdf`` and
        ``gap_pdf_err``, ``count(sample, bin)``; attributes ``fit_exponent``
        (gamma), ``fit_exponent_err``, ``fit_min``, ``fit_max``, ``fit_prefactor``,
        ``fit_chi2_reduced`` (NaN when the window has too few populated bins),
        ``mean_field_exponent``, ``n_samples``.
    """
    if len(packings) == 0:
        raise ValueError("gap_distribution needs at least one packing")
    gaps = [non_contact_gaps(p, max_gap, gap_tol) for p in packings]
    ds, summary = gap_histogram(gaps, [p.n for p in packings], max_gap, min_gap, bins_per_decade, fit_min, fit_max)
    contact_def = ("explicit contacts of each packing (else h <= CONTACT_GAP_TOL)" if gap_tol is None
                   else f"pairs with h <= {gap_tol:g}")
    ds.attrs = new_dataset_attrs(
        "jamflow gap distribution",
        parameters or {},
        d=int(packings[0].d),
        N=int(packings[0].n),
        contacts_excluded=contact_def,
        fit_method="weighted least squares of log p against log h, weights (p/err)^2; "
                   "error scaled by sqrt(chi2_reduced) when > 1",
        mean_field_exponent=MEAN_FIELD_GAP_EXPONENT,
        **summary,
    )
    return ds
