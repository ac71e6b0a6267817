"""Equations of state of hard spheres and the LS extrapolation of the jamming density.

The reduced pressure is ``p = beta P V / N`` (CALiPPSO paper, Sec. III). Two laws:

* the liquid, Carnahan–Starling (d = 3): ``p = (1 + phi + phi^2 - phi^3) / (1 - phi)^3``;
* the glass near jamming, the free-volume law (paper Eq. 15): ``p = d / (1 - phi/phi_J)``.

Eq. 15 is linear in ``1/p``: ``d/p = c0 + c1 phi`` with ``c0 = 1`` and
``c1 = -1/phi_J``. :func:`fit_jamming_density` fits this line on a window of pressures,
which stays well conditioned as ``p -> infinity`` where fitting ``p`` itself would
weight the most divergent points most; :func:`jamming_table` compares the
extrapolated ``phi_J^(LS)`` with the ``phi_J`` of LS+CALiPPSO per growth rate
(paper Table I).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from ..io import new_dataset_attrs

__all__ = ["EosFit", "carnahan_starling", "fit_jamming_density", "glass_pressure", "jamming_table", "table_markdown"]


def carnahan_starling(phi: ArrayLike) -> NDArray[np.float64]:
    """Reduced pressure ``beta P V / N`` of the 3D hard-sphere liquid (Carnahan–Starling)."""
    phi = np.asarray(phi, dtype=np.float64)
    return (1.0 + phi + phi**2 - phi**3) / (1.0 - phi) ** 3


def glass_pressure(phi: ArrayLike, d: int, phi_j: float) -> NDArray[np.float64]:
    """Free-volume glass law ``p = d / (1 - phi/phi_J)`` (paper Eq. 15), for ``phi < phi_J``."""
    return d / (1.0 - np.asarray(phi, dtype=np.float64) / phi_j)


@dataclass(frozen=True)
class EosFit:
    """Result of :func:`fit_jamming_density`.

    Attributes
    ----------
    phi_j : float
        Extrapolated jamming packing fraction (``1/p = 0``).
    phi_j_err : float
        Standard error of ``phi_j`` propagated from the fit covariance (scaled by the
        residuals). Points along one compression are correlated, so this is a lower
        bound; the spread over samples is the honest error (:func:`jamming_table`).
    prefactor : float
        Fitted prefactor ``A`` of ``p = A / (1 - phi/phi_J)``; Eq. 15 says ``A = d``.
    n_points : int
        Points in the pressure window.
    """

    phi_j: float
    phi_j_err: float
    prefactor: float
    n_points: int


def fit_jamming_density(
    phi: ArrayLike, p: ArrayLike, d: int, p_min: float = 1e5, p_max: float = np.inf
) -> EosFit:
    """Fit the glass equation of state ``p = d / (1 - phi/phi_J)`` (paper Eq. 15).

    The line ``d/p = c0 + c1 phi`` is fitted to the points with ``p_min <= p <= p_max``
    by weighted least squares with weights ``p``: each pressure window of an LS run
    measures ``p`` with a similar *relative* error, so the error of ``d/p`` scales as
    ``1/p``. The intercept is left free, so a prefactor other than ``d`` does not bias
    ``phi_J = -c0/c1``, the zero of ``1/p``; it is reported as ``prefactor = d/c0``.
    Weights are taken relative to the largest pressure and ``phi`` is centred and
    scaled, which keeps the normal equations well conditioned for windows spanning
    ``p = 1e3 ... 1e12``.

    Parameters
    ----------
    phi, p : array_like, shape (M,)
        Packing fraction and reduced pressure along a compression.
    d : int
        Spatial dimension.
    p_min, p_max : float
        Pressure window (paper Table I: 1e5 .. 1e11).

    Returns
    -------
    EosFit
    """
    phi = np.asarray(phi, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    if phi.shape != p.shape or phi.ndim != 1:
        raise ValueError(f"phi and p must be 1-d arrays of equal length, got {phi.shape} and {p.shape}")
    if not p_min < p_max:
        raise ValueError(f"empty pressure window [{p_min:g}, {p_max:g}]")
    keep = np.isfinite(phi) & np.isfinite(p) & (p >= p_min) & (p <= p_max)
    n = int(keep.sum())
    if n < 3:
        raise ValueError(f"{n} point(s) with {p_min:g} <= p <= {p_max:g}, need at least 3: the compression "
                         "did not reach the fit window (raise the LS target pressure or lower fit_min)")
    w = p[keep] / p[keep].max()
    centre = float(phi[keep].mean())
    scale = float(phi[keep].std()) or 1.0
    z = (phi[keep] - centre) / scale
    X = np.stack([w, w * z], axis=1)
    y = w * d / p[keep]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    cov = np.linalg.pinv(X.T @ X) * float(resid @ resid) / max(1, n - 2)
    b0, b1 = coef
    if b1 >= 0.0:
        raise ValueError("1/p does not decrease with phi in the fit window: not a glass branch")
    phi_j = centre - scale * b0 / b1
    grad = np.array([-scale / b1, scale * b0 / b1**2])
    c0 = b0 - b1 * centre / scale
    return EosFit(float(phi_j), float(np.sqrt(grad @ cov @ grad)), float(d / c0), n)


def _sem(x: NDArray[np.float64]) -> float:
    return float(np.std(x, ddof=1) / np.sqrt(len(x))) if len(x) > 1 else float("nan")


def jamming_table(
    series: Sequence[xr.Dataset],
    eos: Sequence[xr.Dataset],
    p_min: float = 1e5,
    p_max: float = 1e11,
    parameters: dict | None = None,
) -> xr.Dataset:
    """``<phi_J^(LS)>`` against ``<phi_J(p_tar)>`` of LS+CALiPPSO per growth rate (Table I).

    Parameters
    ----------
    series : sequence of xarray.Dataset
        ``jamflow overlap-series`` outputs, one per (sample, kappa), with attribute
        ``kappa`` and ``phi_J`` on dim ``p_target``; all with the same targets.
    eos : sequence of xarray.Dataset
        The equation of state of the same LS runs (``jamflow ls --eos``), same order:
        ``packing_fraction`` and ``pressure`` on dim ``record``, attribute ``d``.
    p_min, p_max : float
        Pressure window of the Eq. 15 fit.

    Returns
    -------
    xarray.Dataset
        dims ``kappa`` and ``p_target`` (and ``run``): ``phi_J_LS`` and ``phi_J_LS_err``
        (mean and standard error over samples), ``phi_J`` and ``phi_J_err`` (kappa,
        p_target), ``difference`` = mean over samples of ``phi_J(p_tar) - phi_J^(LS)``
        with ``difference_err``, ``n_samples``; per run ``run_kappa``, ``run_phi_J_LS``,
        ``run_fit_err``.
    """
    if len(series) == 0 or len(series) != len(eos):
        raise ValueError(f"need one equation of state per overlap series, got {len(eos)} for {len(series)}")
    targets = series[0]["p_target"].values
    run_kappa, run_fit, run_err, run_phi = [], [], [], []
    for s, e in zip(series, eos):
        if "kappa" not in s.attrs:
            raise ValueError("an overlap series has no growth rate: run overlap-series with --growth-rate")
        if not np.array_equal(s["p_target"].values, targets):
            raise ValueError("overlap series with different p_target values cannot share a table")
        kappa = float(s.attrs["kappa"])
        kappa_eos = e.attrs.get("kappa", kappa)
        if not np.isclose(float(kappa_eos), kappa, rtol=1e-12, atol=0.0):
            raise ValueError(f"series at kappa = {kappa:g} paired with an LS run at kappa = {float(kappa_eos):g}")
        if "d" not in e.attrs:
            raise ValueError("equation-of-state dataset lacks the attribute 'd'")
        fit = fit_jamming_density(e["packing_fraction"].values, e["pressure"].values, int(e.attrs["d"]), p_min, p_max)
        run_kappa.append(kappa)
        run_fit.append(fit.phi_j)
        run_err.append(fit.phi_j_err)
        run_phi.append(s["phi_J"].values)
    run_kappa = np.array(run_kappa)
    run_fit = np.array(run_fit)
    run_phi = np.array(run_phi)
    kappas = np.unique(run_kappa)
    shape = (len(kappas), len(targets))
    phi_mean, phi_err = np.empty(shape), np.empty(shape)
    diff, diff_err = np.empty(shape), np.empty(shape)
    ls_mean, ls_err, counts = np.empty(len(kappas)), np.empty(len(kappas)), np.empty(len(kappas), dtype=np.int64)
    for a, k in enumerate(kappas):
        sel = run_kappa == k
        counts[a] = int(sel.sum())
        ls_mean[a], ls_err[a] = run_fit[sel].mean(), _sem(run_fit[sel])
        for b in range(len(targets)):
            phi_mean[a, b], phi_err[a, b] = run_phi[sel, b].mean(), _sem(run_phi[sel, b])
            delta = run_phi[sel, b] - run_fit[sel]
            diff[a, b], diff_err[a, b] = delta.mean(), _sem(delta)
    one = {"units": "1"}
    sem = "standard error over samples (NaN for one sample)"
    return xr.Dataset(
        data_vars={
            "phi_J_LS": ("kappa", ls_mean, {**one, "long_name": "sample mean of phi_J^(LS), Eq. 15 fitted to the LS compression"}),
            "phi_J_LS_err": ("kappa", ls_err, {**one, "long_name": f"phi_J^(LS): {sem}"}),
            "phi_J": (("kappa", "p_target"), phi_mean, {**one, "long_name": "sample mean of phi_J of LS+CALiPPSO"}),
            "phi_J_err": (("kappa", "p_target"), phi_err, {**one, "long_name": f"phi_J: {sem}"}),
            "difference": (("kappa", "p_target"), diff,
                           {**one, "long_name": "sample mean of phi_J(p_tar) - phi_J^(LS) within each sample"}),
            "difference_err": (("kappa", "p_target"), diff_err, {**one, "long_name": f"difference: {sem}"}),
            "n_samples": ("kappa", counts, {**one, "long_name": "samples per growth rate"}),
            "run_kappa": ("run", run_kappa, {**one, "long_name": "growth rate of each LS run"}),
            "run_phi_J_LS": ("run", run_fit, {**one, "long_name": "phi_J^(LS) of each LS run"}),
            "run_fit_err": ("run", np.array(run_err),
                            {**one, "long_name": "least-squares error of each fit (correlated points: a lower bound)"}),
        },
        coords={
            "kappa": ("kappa", kappas, {"units": "1", "long_name": "LS growth rate of the diameters"}),
            "p_target": ("p_target", targets, {"units": "1", "long_name": "LS target reduced pressure"}),
        },
        attrs=new_dataset_attrs("jamflow LS extrapolation against LS+CALiPPSO (Table I)", parameters or {},
                                fit_min=float(p_min), fit_max=float(p_max),
                                fit_law="phi = phi_J (1 - d/p), CALiPPSO paper Eq. 15, least squares"),
    )


def table_markdown(ds: xr.Dataset) -> str:
    """The table of :func:`jamming_table` as markdown (rows: kappa)."""
    heads = ["kappa", "<phi_J^(LS)>"] + [f"<phi_J(p_tar={p:g})>" for p in ds["p_target"].values]
    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for a, k in enumerate(ds["kappa"].values):
        cells = [f"{k:g}", f"{ds['phi_J_LS'].values[a]:.6f} ± {ds['phi_J_LS_err'].values[a]:.1e}"]
        cells += [f"{m:.6f} ± {e:.1e}" for m, e in zip(ds["phi_J"].values[a], ds["phi_J_err"].values[a])]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
