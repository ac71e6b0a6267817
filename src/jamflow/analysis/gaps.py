"""Gap distribution p(h) of jammed and nearly jammed packings, with a power-law fit.

The relative gap of a pair is ``h_ij = r_ij / sigma_ij - 1`` (CALiPPSO paper, App. D).
Contacts are excluded: they are the packing's explicit contacts (the solver's
network) when it has them, otherwise pairs with ``h <= gap_tol``.

Rattlers
--------
By default only gaps between two *stable* particles are kept: rattlers are removed
iteratively from the contact network (:func:`jamflow.network.spheres.rattler_mask`,
the stored rattlers or :func:`~jamflow.analysis.contacts.find_rattlers`), as in
Charbonneau et al. (PRL 2012, Nat. Commun. 2014) and the CALiPPSO paper. A rattler
sits loose in its cage, so its gaps are not those of the rigid backbone; in a
CALiPPSO packing rattlers touching a neighbour give a spike of pairs at
``h ~ 1e-11``. ``include_rattlers=True`` keeps every pair, which is the only option
for an LS snapshot at finite pressure: it has no contact network.

Near jamming the gaps follow ``p(h) ~ h^(-gamma)`` over many decades with the
mean-field exponent ``gamma = 0.41269`` (Charbonneau, Kurchan, Parisi, Urbani,
Zamponi 2014); an LS snapshot at finite pressure ``p`` instead shows a plateau for
``h < 1/p``, so the fit range starts at ``1/p`` there. The exponent, its statistical
and systematic errors and the fit window come from :mod:`jamflow.analysis.fitting`
(maximum likelihood on the gaps themselves, no binning).

Normalisation
-------------
``gap_density`` counts *neighbours per particle per unit h*: a pair is a neighbour of
both its particles, so ``gap_density = 2 n_pairs(bin) / (N dh)`` with ``N`` the
number of particles whose pairs are counted (the stable ones, or all when rattlers
are included); its integral up to ``h`` is the mean number of non-contact neighbours
within gap ``h`` (the cumulative ``Z(h) - z`` of Charbonneau et al.). ``gap_pdf``
is the same histogram normalised to unit integral over the binned range.

The histogram and sample-average helpers here are shared by
:mod:`jamflow.analysis.forces`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..io import new_dataset_attrs
from ..network.spheres import contact_network, rattler_mask
from ..stages import require
from ..state.packing import Packing, near_pairs
from ..tolerances import CONTACT_GAP_TOL
from .fitting import analyse_exponent, check_window, density_prefactor

__all__ = [
    "MEAN_FIELD_GAP_EXPONENT",
    "log_bin_edges",
    "sample_average",
    "non_contact_gaps",
    "gap_histogram",
    "gap_distribution",
]

#: Mean-field exponent of the gap distribution, p(h) ~ h^(-gamma) (Charbonneau et al. 2014).
MEAN_FIELD_GAP_EXPONENT: float = 0.41269


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


def non_contact_gaps(packing: Packing, max_gap: float, gap_tol: float | None = None,
                     include_rattlers: bool = False) -> tuple[NDArray[np.float64], int]:
    """Relative gaps ``0 < h <= max_gap`` of near pairs that are not contacts.

    Parameters
    ----------
    packing : Packing
    max_gap : float
        Largest gap kept (dimensionless); the neighbour search radius is
        ``max(D) (1 + max_gap)``, which must stay below half the box width.
    gap_tol : float or None
        ``None``: the packing's explicit contacts if it has them, else pairs with
        ``h <= CONTACT_GAP_TOL``. A number: contacts are pairs with ``h <= gap_tol``
        (recomputed from geometry even when contacts are stored).
    include_rattlers : bool
        False: drop every pair with a rattler of that contact network.

    Returns
    -------
    gaps : ndarray, shape (P,)
    n_counted : int
        Particles whose pairs are counted (stable ones, or all), for normalisation.

    Raises
    ------
    ValueError
        Rattlers are to be excluded but the network leaves no stable particle (an LS
        snapshot has no contacts: use ``include_rattlers``).
    """
    pairs, h = near_pairs(packing, max_gap)
    contacts = contact_network(packing, gap_tol)
    n = packing.n
    keep = ~np.isin(pairs.i * n + pairs.j, contacts[:, 0] * n + contacts[:, 1])
    n_counted = n
    if not include_rattlers:
        rattler = rattler_mask(packing, contacts)
        n_counted = int(np.sum(~rattler))
        if n_counted == 0:
            source = "its stored contacts" if gap_tol is None and packing.contacts is not None else (
                f"contacts h <= {CONTACT_GAP_TOL if gap_tol is None else gap_tol:g}")
            raise ValueError(f"every particle is a rattler for {source} (an LS snapshot has no contact "
                             "network): include rattlers (--include-rattlers) or give a jammed packing")
        keep &= ~(rattler[pairs.i] | rattler[pairs.j])
    h = h[keep]
    # a non-contact pair at h <= 0 (touching within round-off) has no place on a log axis
    return h[h > 0.0], n_counted


def gap_histogram(
    gaps: Sequence[ArrayLike],
    n_particles: Sequence[int],
    max_gap: float = 0.1,
    min_gap: float = 1e-13,
    bins_per_decade: int = 5,
    fit_min: float = 1e-5,
    fit_max: float = 1e-2,
    choose_window: bool = True,
    n_boot: int = 200,
    seed: int = 0,
) -> tuple[xr.Dataset, dict]:
    """Logarithmic histogram of gap samples, sample average and power-law fit.

    Parameters
    ----------
    gaps : sequence of array_like, each shape (P_s,)
        Non-contact relative gaps of each sample (dimensionless).
    n_particles : sequence of int
        Particles counted in each sample (for the per-particle normalisation).
    max_gap, min_gap, bins_per_decade
        Binned range and resolution, as in :func:`gap_distribution`.
    fit_min, fit_max : float
        Scaling range searched for ``p(h) ~ h^-gamma``
        (:func:`jamflow.analysis.fitting.analyse_exponent`).
    choose_window, n_boot, seed
        Passed to :func:`~jamflow.analysis.fitting.analyse_exponent`.

    Returns
    -------
    dataset : xarray.Dataset
        Variables of :func:`gap_distribution` (no global attributes).
    summary : dict
        ``fit_exponent`` (gamma), ``fit_exponent_stat``, ``fit_exponent_sys``,
        ``fit_exponent_err`` (combined), ``fit_min``/``fit_max`` (chosen window),
        ``fit_prefactor`` (of ``gap_density``), counts and method.
    """
    if len(gaps) == 0 or len(gaps) != len(n_particles):
        raise ValueError("need one particle count per gap sample, and at least one sample")
    check_window(fit_min, fit_max)
    edges = log_bin_edges(min_gap, max_gap, bins_per_decade)
    width = np.diff(edges)
    samples = [np.asarray(h, dtype=np.float64) for h in gaps]
    counts = np.zeros((len(samples), len(width)))
    density = np.zeros_like(counts)
    pdf = np.zeros_like(counts)
    n_below = 0
    for s, (h, n) in enumerate(zip(samples, n_particles)):
        n_below += int(np.sum((h > 0) & (h < min_gap)))
        counts[s], _ = np.histogram(h, bins=edges)
        density[s] = 2.0 * counts[s] / (n * width)
        total = counts[s].sum()
        pdf[s] = counts[s] / (total * width) if total > 0 else 0.0
    dens_mean, dens_err, method = sample_average(density, counts)
    pdf_mean, pdf_err, _ = sample_average(pdf, counts)
    centre = np.sqrt(edges[:-1] * edges[1:])
    fit = analyse_exponent(samples, fit_min, fit_max, choose_window=choose_window, n_boot=n_boot, seed=seed)
    per_particle = 2.0 * fit.n_in_window / float(np.sum(n_particles))
    prefactor = (density_prefactor(fit.alpha, fit.x_min, fit.x_max, per_particle)
                 if np.isfinite(fit.alpha) else np.nan)
    summary: dict = {"error_method": method, "n_below_range": n_below, "n_samples": len(samples),
                     **fit.exponent_attrs("fit_exponent", sign=-1.0), **fit.window_attrs("fit"),
                     "fit_prefactor": prefactor}
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
            **fit.scan_variables(-1.0, "gamma", "1"),
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
    include_rattlers: bool = False,
    n_boot: int = 200,
    seed: int = 0,
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
        Scaling range searched for ``p(h) ~ h^(-gamma)``. When every packing has a
        finite reduced pressure (LS snapshots), ``fit_min`` is raised to ``1/p`` of
        the lowest pressure, where the plateau ends.
    gap_tol : float or None
        Contact definition, see :func:`non_contact_gaps`.
    parameters : dict or None
        Stage parameters recorded in the provenance attributes.
    include_rattlers : bool
        Keep pairs with rattlers (default: gaps between stable particles only).
    n_boot, seed : int
        Bootstrap resamples of the statistical error and their seed.

    Returns
    -------
    xarray.Dataset
        dims ``bin`` (and ``sample``): ``h`` (geometric bin centre), ``h_lower``,
        ``h_upper``, ``gap_density`` and ``gap_density_err``, ``gap_pdf`` and
        ``gap_pdf_err``, ``count(sample, bin)``; dim ``window``: the scanned fit
        windows (``window_lower``, ``window_upper``, ``window_exponent``, ...);
        attributes ``fit_exponent`` (gamma; NaN with ``fit_exponent_reason`` when
        refused), ``fit_exponent_stat``, ``fit_exponent_sys``, ``fit_exponent_err``,
        ``fit_min``, ``fit_max`` (chosen window), ``fit_method``,
        ``fit_exponent_n_in_window``, ``rattlers_included``, ``mean_field_exponent``.
    """
    for packing in packings:
        require("gaps", packing.body_kind)
    if len(packings) == 0:
        raise ValueError("gap_distribution needs at least one packing")
    check_window(fit_min, fit_max)
    # the plateau is of hard spheres at a finite reduced pressure (LS snapshots); a soft
    # packing's pressure P0 is an energy density, not that pressure
    pressures = [p.pressure if p.protocol.rsplit(">", 1)[-1] == "ls" else None for p in packings]
    lower = fit_min
    if all(p is not None and np.isfinite(p) and p > 0 for p in pressures):
        lower = max(fit_min, 1.0 / min(pressures))
        if lower >= fit_max:
            raise ValueError(f"the LS plateau ends at 1/p = {lower:g}, above --fit-max {fit_max:g}: raise --fit-max")
    per = [non_contact_gaps(p, max_gap, gap_tol, include_rattlers) for p in packings]
    ds, summary = gap_histogram([g for g, _ in per], [n for _, n in per], max_gap, min_gap, bins_per_decade,
                                lower, fit_max, n_boot=n_boot, seed=seed)
    contact_def = ("explicit contacts of each packing (else h <= CONTACT_GAP_TOL)" if gap_tol is None
                   else f"pairs with h <= {gap_tol:g}")
    ds.attrs = new_dataset_attrs(
        "jamflow gap distribution",
        parameters or {},
        d=int(packings[0].d),
        N=int(packings[0].n),
        contacts_excluded=contact_def,
        rattlers_included=int(include_rattlers),
        rattler_treatment=("all pairs kept, rattlers included" if include_rattlers else
                           "pairs with a rattler (iterative removal of particles with < d+1 contacts) excluded; "
                           "gap_density per stable particle"),
        n_particles_counted=int(sum(n for _, n in per)),
        fit_lower_edge_rule=("1/p of the lowest LS pressure (end of the plateau)" if lower > fit_min else
                             "fit_min as given"),
        mean_field_exponent=MEAN_FIELD_GAP_EXPONENT,
        **summary,
    )
    return ds
