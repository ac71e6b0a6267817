"""Moduli of cemented packings against the fraction of added links (chains paper Fig. 5).

Each packing's modulus lies between its Reuss (lower) and Voigt (upper) bound
(Sec. VI). Following the paper's caption ("a weighted average where the Reuss and
Voigt averages were used as a minimum and maximum"), a packing contributes its Hill
value ``x_i = (V_i + R_i) / 2`` with the standard deviation of a value uniform
between the bounds, ``s_i = (V_i - R_i) / sqrt(12)``, and weight ``w_i = 1 / s_i^2``;
the group value is ``sum w_i x_i / sum w_i``. Its standard error is the scatter of
the packings about it, ``sqrt(sum w_i^2 (x_i - x)^2) / sum w_i`` (exact for
independent packings whatever the weights; NaN for a single packing). Bounds that
coincide (an isotropic compliance) are widened to ``s_i = MIN_RELATIVE_SPREAD x_i``
so one packing cannot take all the weight. Packings with an infinite modulus (a
zero-compliance direction: links forbid that strain) are counted, not averaged.
Packings unstable to some strain (a negative eigenvalue of the compliance, e.g. a
fixed-box packing) have no Reuss-Voigt bracket: they are counted and left out of
every average.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import NDArray

__all__ = ["MIN_RELATIVE_SPREAD", "moduli_against_links", "weighted_modulus"]

#: Smallest Reuss-Voigt spread per packing, relative to its Hill value (module doc).
MIN_RELATIVE_SPREAD: float = 1e-6


def weighted_modulus(voigt: NDArray[np.float64], reuss: NDArray[np.float64]) -> tuple[float, float, int]:
    """``(value, standard error, number of infinite)`` of one group (module doc)."""
    voigt, reuss = np.asarray(voigt, float), np.asarray(reuss, float)
    finite = np.isfinite(voigt) & np.isfinite(reuss)
    n_inf = int((~finite).sum())
    if not finite.any():
        return float("inf"), float("nan"), n_inf
    v, r = voigt[finite], reuss[finite]
    x = 0.5 * (v + r)
    s = np.maximum((v - r) / np.sqrt(12.0), MIN_RELATIVE_SPREAD * np.abs(x))
    w = 1.0 / s**2
    mean = float(np.sum(w * x) / np.sum(w))
    se = float(np.sqrt(np.sum(w**2 * (x - mean) ** 2)) / np.sum(w)) if len(x) > 1 else float("nan")
    return mean, se, n_inf


def moduli_against_links(datasets: Sequence[xr.Dataset]) -> xr.Dataset:
    """Group ``chain-moduli`` datasets by the number of cemented links per sphere and average.

    Parameters
    ----------
    datasets : sequence of xr.Dataset
        ``jamflow moduli`` outputs of linked packings, with attributes ``N``,
        ``n_cemented`` (contacts turned into links, angle links not counted) and
        ``n_unstable`` (negative compliance eigenvalues).

    Returns
    -------
    xr.Dataset
        Dimension ``links_per_sphere`` (``n_l / N``): weighted bulk and shear moduli,
        standard errors, the mean Voigt and Reuss bounds of the finite packings, and
        the counts of packings, of unstable packings (not averaged) and of infinite moduli.
    """
    if not datasets:
        raise ValueError("no moduli datasets given")
    key = np.array([ds.attrs["n_cemented"] / ds.attrs["N"] for ds in datasets], float)
    groups = np.unique(key)
    out: dict[str, list[float]] = {}
    for g in groups:
        group = [ds for ds, k in zip(datasets, key) if k == g]
        members = [ds for ds in group if ds.attrs["n_unstable"] == 0]
        out.setdefault("n_packings", []).append(len(group))
        out.setdefault("n_unstable", []).append(len(group) - len(members))
        for name in ("bulk", "shear"):
            v = np.array([float(ds[f"{name}_voigt"]) for ds in members])
            r = np.array([float(ds[f"{name}_reuss"]) for ds in members])
            mean, se, n_inf = weighted_modulus(v, r)
            ok = np.isfinite(v) & np.isfinite(r)
            out.setdefault(f"{name}_weighted", []).append(mean)
            out.setdefault(f"{name}_se", []).append(se)
            out.setdefault(f"{name}_voigt_mean", []).append(float(v[ok].mean()) if ok.any() else float("inf"))
            out.setdefault(f"{name}_reuss_mean", []).append(float(r[ok].mean()) if ok.any() else float("inf"))
            out.setdefault(f"{name}_infinite", []).append(n_inf)
    unit = "epsilon / <D>^d"
    meaning = {
        "weighted": "Reuss-Voigt weighted modulus (chains paper Fig. 5)", "se": "weighted standard error",
        "voigt_mean": "mean Voigt bound of the finite packings", "reuss_mean": "mean Reuss bound of the finite packings",
        "infinite": "packings with an infinite modulus",
    }
    data = {"n_packings": (("links_per_sphere",), np.array(out["n_packings"]),
                           {"units": "1", "long_name": "packings in the group"}),
            "n_unstable": (("links_per_sphere",), np.array(out["n_unstable"]),
                           {"units": "1", "long_name": "packings unstable to some strain, not averaged"})}
    for name in ("bulk", "shear"):
        for part, text in meaning.items():
            data[f"{name}_{part}"] = (("links_per_sphere",), np.array(out[f"{name}_{part}"]),
                                      {"units": "1", "long_name": f"{name} modulus: {text}",
                                       "comment": "count" if part == "infinite" else unit})
    return xr.Dataset(data, coords={"links_per_sphere": ("links_per_sphere", groups,
                                                         {"units": "1", "long_name": "added links per sphere n_l / N"})})
