"""Contact-force distribution P(f), its small-force tail, and bucklers.

Forces are normalised by their mean in each sample, ``f / <f>``, over the contacts
of the rigid backbone (both particles non-rattlers). Near jamming the weak forces
follow ``P(f) ~ f^theta``. Charbonneau, Corwin, Parisi and Zamponi (PRL 114,
125504, 2015) showed that two populations hide in that tail:

* **bucklers**: non-rattler particles with exactly ``d + 1`` backbone contacts. A
  buckler's weakest contact belongs to a *localised* excitation with exponent
  ``theta_l = 0.17462``.
* the remaining, *extended* contacts follow the mean-field ``theta_e = 0.42311``.

Definition used here: a contact is a **buckler contact** when at least one of its
two particles is a buckler; all other backbone contacts are **extended**. The
distribution of each population is normalised by its own number of contacts (so
each integrates to one) and by the mean force of *all* backbone contacts of the
sample (one force scale per packing).

The exponents are maximum-likelihood fits to the pooled forces of all packings
(:mod:`jamflow.analysis.fitting`, no binning), with a bootstrap statistical error
over packings and contacts and a systematic error from a scan of fit windows. The
window is chosen on all backbone contacts and used for both populations. With fewer
than :data:`~jamflow.analysis.fitting.MIN_IN_WINDOW` forces in the window an
exponent is NaN and ``fit_exponent*_reason`` says why (a few hundred contacts hold
only a handful of forces below 0.1 <f>).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..io import new_dataset_attrs
from ..network.spheres import rattler_mask
from ..stages import require
from ..state.packing import Packing
from .fitting import analyse_exponent, check_window, density_prefactor
from .gaps import log_bin_edges, sample_average

__all__ = [
    "THETA_EXTENDED",
    "THETA_LOCALISED",
    "bucklers",
    "normalised_forces",
    "force_distribution",
]

#: Mean-field small-force exponent of extended contacts (Charbonneau et al. 2014/2015).
THETA_EXTENDED: float = 0.42311
#: Small-force exponent of forces localised on bucklers (Charbonneau et al. PRL 2015).
THETA_LOCALISED: float = 0.17462


def _backbone(packing: Packing, backbone_only: bool = True) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]:
    if packing.contacts is None or packing.force is None:
        raise ValueError("the force distribution needs a packing with contacts and forces")
    if not backbone_only:
        return packing.contacts, packing.force, np.zeros(packing.n, dtype=bool)
    rattler = rattler_mask(packing)
    c = packing.contacts
    keep = ~(rattler[c[:, 0]] | rattler[c[:, 1]])
    return c[keep], packing.force[keep], rattler


def bucklers(packing: Packing, backbone_only: bool = True) -> NDArray[np.bool_]:
    """Non-rattler particles with exactly ``d + 1`` backbone contacts, shape (N,).

    With ``backbone_only=False`` every contact counts and no particle is a rattler.
    """
    c, _, rattler = _backbone(packing, backbone_only)
    z = np.bincount(c.ravel(), minlength=packing.n)
    return (~rattler) & (z == packing.d + 1)


def normalised_forces(packing: Packing, backbone_only: bool = True) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Backbone forces divided by their mean, and the buckler-contact mask.

    ``backbone_only=False`` uses every contact (see :func:`force_distribution`).

    Returns
    -------
    f : ndarray, shape (Nc_backbone,)
        ``f / <f>`` (dimensionless).
    buckler_contact : ndarray of bool, shape (Nc_backbone,)
        True where at least one particle of the contact is a buckler.
    """
    c, f, _ = _backbone(packing, backbone_only)
    if len(f) == 0:
        raise ValueError("packing has no backbone contacts (a flowing, hypostatic network loses every "
                         "particle to rattler removal: use all contacts instead)")
    mean = float(np.mean(f))
    if not mean > 0.0:
        raise ValueError(f"mean contact force must be positive, got {mean:g}")
    b = bucklers(packing, backbone_only)
    return f / mean, b[c[:, 0]] | b[c[:, 1]]


def _densities(values: Sequence[NDArray[np.float64]], edges: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    counts = np.array([np.histogram(v, bins=edges)[0] for v in values], dtype=np.float64)
    totals = np.array([len(v) for v in values], dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        dens = np.where(totals[:, None] > 0, counts / (totals[:, None] * np.diff(edges)), 0.0)
    return dens, counts


def force_distribution(
    packings: Sequence[Packing],
    f_max: float = 6.0,
    linear_bins: int = 60,
    log_min: float = 1e-6,
    bins_per_decade: int = 5,
    fit_min: float = 1e-3,
    fit_max: float = 1e-1,
    backbone_only: bool = True,
    parameters: dict | None = None,
    n_boot: int = 200,
    seed: int = 0,
) -> xr.Dataset:
    """Sample-averaged P(f / <f>) on linear and logarithmic bins, with tail fits.

    Parameters
    ----------
    packings : sequence of Packing
        Packings with contacts and forces, one per sample.
    f_max : float
        Upper end of both binnings (in units of the mean force).
    linear_bins : int
        Number of linear bins on ``[0, f_max]``.
    log_min, bins_per_decade : float, int
        Logarithmic bins on ``[log_min, f_max]``.
    fit_min, fit_max : float
        Scaling range searched for ``P(f) ~ f^theta`` (:mod:`jamflow.analysis.fitting`).
    backbone_only : bool
        True (jammed packings): contacts between non-rattlers only, rattlers from
        the packing or from iterative removal. False: every contact, no rattlers —
        for flowing, hypostatic networks, which iterative removal empties.
    parameters : dict or None
        Stage parameters recorded in the provenance attributes.
    n_boot, seed : int
        Bootstrap resamples of the statistical error and their seed.

    Returns
    -------
    xarray.Dataset
        dims ``fbin`` (linear), ``logbin`` (logarithmic): ``P_linear``, ``P_log`` and
        their errors for all backbone contacts, ``P_log_buckler`` /
        ``P_log_extended`` for the two populations (see module docstring); dim
        ``window``: the scanned fit windows of all contacts. Each distribution is
        normalised by the number of its forces, so its integral over all f is 1 (the
        fraction beyond ``f_max`` is the attribute ``fraction_above_f_max``).
        Attributes ``fit_exponent`` (theta, all; NaN and ``fit_exponent_reason``
        when refused), ``_stat``, ``_sys``, ``_err``, ``_n_in_window``, the same for
        ``fit_exponent_buckler`` and ``fit_exponent_extended``, ``fit_min``,
        ``fit_max`` (chosen window), ``fit_method``, ``buckler_fraction`` (bucklers
        over non-rattlers), ``buckler_contact_fraction``.
    """
    for packing in packings:
        require("forces", packing.body_kind)
    if len(packings) == 0:
        raise ValueError("force_distribution needs at least one packing")
    check_window(fit_min, fit_max)
    per_sample = [normalised_forces(p, backbone_only) for p in packings]
    allf = [f for f, _ in per_sample]
    buck = [f[b] for f, b in per_sample]
    ext = [f[~b] for f, b in per_sample]

    lin_edges = np.linspace(0.0, f_max, linear_bins + 1)
    log_edges = log_bin_edges(log_min, f_max, bins_per_decade)
    lin_d, lin_c = _densities(allf, lin_edges)
    lin_mean, lin_err, method = sample_average(lin_d, lin_c)
    out_vars: dict = {}
    fits: dict = {}
    log_centre = np.sqrt(log_edges[:-1] * log_edges[1:])
    main = analyse_exponent(allf, fit_min, fit_max, n_boot=n_boot, seed=seed)
    for name, values in (("", allf), ("_buckler", buck), ("_extended", ext)):
        dens, cnt = _densities(values, log_edges)
        mean, err, _ = sample_average(dens, cnt)
        label = {"": "all backbone contacts", "_buckler": "contacts involving a buckler",
                 "_extended": "contacts not involving a buckler"}[name]
        out_vars[f"P_log{name}"] = ("logbin", mean, {"units": "1", "long_name": f"P(f/<f>) on log bins, {label}"})
        out_vars[f"P_log{name}_err"] = ("logbin", err, {"units": "1", "long_name": f"standard error of P_log{name}"})
        fit = main if name == "" else analyse_exponent(values, main.x_min, main.x_max, choose_window=False,
                                                       n_boot=n_boot, seed=seed)
        fits.update(fit.exponent_attrs(f"fit_exponent{name}"))
        n_pop = sum(len(v) for v in values)
        fits[f"fit_prefactor{name}"] = (density_prefactor(fit.alpha, fit.x_min, fit.x_max, fit.n_in_window / n_pop)
                                        if np.isfinite(fit.alpha) and n_pop else np.nan)
    n_nonrattler = n_buckler = 0
    for p in packings:
        b = bucklers(p, backbone_only)
        _, _, rattler = _backbone(p, backbone_only)
        n_nonrattler += int((~rattler).sum())
        n_buckler += int(b.sum())
    n_all = sum(len(f) for f in allf)
    attrs = new_dataset_attrs(
        "jamflow contact-force distribution",
        parameters or {},
        n_samples=len(packings),
        d=int(packings[0].d),
        N=int(packings[0].n),
        force_normalisation="each force divided by the mean backbone force of its packing",
        contacts_used="backbone (non-rattler) contacts" if backbone_only else "all contacts, no rattler removal",
        buckler_definition="non-rattler particle with exactly d+1 backbone contacts; a buckler contact "
                           "has at least one buckler among its two particles (Charbonneau et al. PRL 2015)",
        error_method=method,
        **main.window_attrs("fit"),
        theta_extended_mean_field=THETA_EXTENDED,
        theta_localised_mean_field=THETA_LOCALISED,
        buckler_fraction=n_buckler / n_nonrattler if n_nonrattler else np.nan,
        buckler_contact_fraction=sum(len(f) for f in buck) / n_all,
        fraction_above_f_max=sum(int(np.sum(f > f_max)) for f in allf) / n_all,
        n_forces=n_all,
        **fits,
    )
    one = {"units": "1"}
    return xr.Dataset(
        data_vars={
            "P_linear": ("fbin", lin_mean, {**one, "long_name": "P(f/<f>) on linear bins, all backbone contacts"}),
            "P_linear_err": ("fbin", lin_err, {**one, "long_name": "standard error of P_linear"}),
            **out_vars,
            **main.scan_variables(1.0, "theta", "1"),
        },
        coords={
            "f": ("fbin", 0.5 * (lin_edges[:-1] + lin_edges[1:]), {**one, "long_name": "f/<f>, linear bin centre"}),
            "f_log": ("logbin", log_centre, {**one, "long_name": "f/<f>, geometric centre of log bin"}),
            "f_lower": ("fbin", lin_edges[:-1], {**one, "long_name": "lower edge of linear bin"}),
            "f_log_lower": ("logbin", log_edges[:-1], {**one, "long_name": "lower edge of log bin"}),
        },
        attrs=attrs,
    )
