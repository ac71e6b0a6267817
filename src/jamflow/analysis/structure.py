"""Structure of packings: radial distribution g(r) and crystallinity indicators.

* g(r) in any dimension. Distances are measured in units of the **mean diameter**;
  for polydisperse packings this is the total (all-species) g(r) of centre
  distances, not a per-species or gap-based one. Bins are ``[k w, (k + 1) w)``; a
  distance within :data:`~jamflow.tolerances.BIN_EDGE_RTOL` of an edge counts in the
  bin above it, so contacts (and lattice distances) that sit on an edge, as the
  small-large contacts of a 1:1.4 mixture sit on r = 1 mean diameter, fall in one bin
  whatever the round-off of a rigid shift or a relabelling.
* 2D: bond-orientational order ``psi6_i = (1/6) sum_j exp(6 i theta_ij)`` over the
  six nearest neighbours of ``i``; ``|psi6|`` is 1 on a triangular lattice and of
  order ``1/sqrt(N)`` for the global value of a random configuration.
* 3D: Steinhardt ``q6`` over the twelve nearest neighbours (Steinhardt, Nelson,
  Ronchetti 1983); the global ``Q6`` is 0.5745 for FCC, 0.4848 for HCP, ~0.29 for
  a random packing's local q6 and ~0 globally. Crystal-like particles follow ten
  Wolde, Ruiz-Montero and Frenkel: bond ``ij`` is *connected* when the normalised
  ``q6(i) · q6(j)* > 0.7``; a particle is crystal-like with at least 7 connected
  bonds among its 12 neighbours (thresholds are parameters).
* Other dimensions: g(r) only.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import NDArray
from scipy.special import sph_harm_y

from ..io import new_dataset_attrs
from ..neighbors.pairs import pairs_within
from ..stages import require
from ..state.packing import Packing, sphere_volume
from ..tolerances import BIN_EDGE_RTOL

__all__ = [
    "TWF_DOT_THRESHOLD",
    "TWF_MIN_CONNECTED",
    "radial_distribution",
    "largest_r_max",
    "binned_counts",
    "nearest_neighbours",
    "hexatic_order",
    "bond_order_vectors",
    "steinhardt_q",
    "crystal_like",
    "crystal_like_from",
    "crystal_fraction",
    "structure_dataset",
    "CRYSTAL_FRACTION_THRESHOLD",
    "PSI6_CRYSTAL_THRESHOLD",
]

#: ten Wolde–Frenkel threshold on the normalised q6(i)·q6(j)* for a connected bond.
TWF_DOT_THRESHOLD: float = 0.7
#: Connected bonds (out of 12 neighbours) that make a particle crystal-like.
TWF_MIN_CONNECTED: int = 7
#: Fraction of ten Wolde–Frenkel crystal-like particles above which a 3D packing counts
#: as crystallised. Random close packed and glassy monodisperse spheres have a few
#: per cent at most; a crystallised LS run has a large fraction.
CRYSTAL_FRACTION_THRESHOLD: float = 0.2
#: 2D: a particle is crystal-like (locally hexagonal) when its local ``|psi6|`` exceeds this.
PSI6_CRYSTAL_THRESHOLD: float = 0.7


def _half_width(packing: Packing) -> float:
    return 0.5 * float(np.min(packing.box.widths))


def largest_r_max(packing: Packing) -> float:
    """The largest ``r_max`` [mean diameters] of :func:`radial_distribution`: just below half the smallest box width."""
    return _half_width(packing) / float(np.mean(packing.diameter)) * (1.0 - 1e-12)


def binned_counts(values: NDArray[np.float64], width: float, bins: int) -> NDArray[np.int64]:
    """Counts of ``values`` in the bins ``[k width, (k + 1) width)``, ``k = 0 .. bins - 1``.

    A value within :data:`~jamflow.tolerances.BIN_EDGE_RTOL` (relative) of an edge counts
    in the bin above that edge, so round-off never decides the bin of a value that
    lies on an edge.
    """
    k = np.asarray(values, dtype=np.float64) / width
    edge = np.rint(k)
    on_edge = np.abs(k - edge) <= BIN_EDGE_RTOL * np.maximum(edge, 1.0)
    index = np.where(on_edge, edge, np.floor(k))
    index = index[(index >= 0) & (index < bins)].astype(np.int64)
    return np.bincount(index, minlength=bins)


def radial_distribution(packing: Packing, r_max: float = 3.0, bins: int = 150) -> tuple[NDArray, NDArray, NDArray]:
    """Radial distribution function g(r).

    Parameters
    ----------
    packing : Packing
    r_max : float
        Largest distance in units of the mean diameter; must stay below half the
        smallest box width (:func:`largest_r_max`).
    bins : int
        Bins of width ``r_max / bins`` (edges: :func:`binned_counts`).

    Returns
    -------
    r : ndarray, shape (bins,)
        Bin centres in units of the mean diameter.
    g : ndarray, shape (bins,)
        ``g(r) = 2 n(r) / (N rho V_shell(r))`` with ``rho = N / V``; 1 for an ideal gas.
    edges : ndarray, shape (bins + 1,)
    """
    unit = float(np.mean(packing.diameter))
    cutoff = r_max * unit
    if cutoff >= _half_width(packing):
        raise ValueError(
            f"r_max = {r_max:g} mean diameters exceeds half the smallest box width "
            f"({_half_width(packing) / unit:.4g} mean diameters)"
        )
    pairs = pairs_within(packing.position, packing.box, cutoff)
    width = r_max / bins
    edges = width * np.arange(bins + 1)
    counts = binned_counts(pairs.distance / unit, width, bins)
    shell = np.diff(sphere_volume(packing.d, 2.0 * edges * unit))
    rho = packing.n / packing.box.volume
    g = 2.0 * counts / (packing.n * rho * shell)
    return 0.5 * (edges[:-1] + edges[1:]), g, edges


def nearest_neighbours(packing: Packing, k: int) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The ``k`` nearest neighbours of every particle, sorted by distance.

    Returns
    -------
    j : ndarray of int64, shape (N, k)
        Neighbour indices.
    dx : ndarray, shape (N, k, d)
        Minimum-image ``x_j - x_i`` [length].

    Raises
    ------
    ValueError
        Some particle has fewer than ``k`` neighbours within half the box width.
    """
    n, d = packing.n, packing.d
    limit = 0.999 * _half_width(packing)
    # radius expected to hold ~3k neighbours in an ideal gas (a Poisson count below k is
    # then rare even among 1e5 particles); grow it only if some particle still lacks k
    cutoff = min(limit, float((3.0 * k * packing.box.volume / n / sphere_volume(d, 2.0)) ** (1.0 / d)))
    while True:
        pairs = pairs_within(packing.position, packing.box, cutoff)
        src = np.concatenate([pairs.i, pairs.j])
        dst = np.concatenate([pairs.j, pairs.i])
        dx = np.concatenate([pairs.dx, -pairs.dx])
        dist = np.linalg.norm(dx, axis=1)
        count = np.bincount(src, minlength=n)
        if count.min() >= k:
            break
        if cutoff >= limit:
            raise ValueError(f"particle {int(np.argmin(count))} has fewer than {k} neighbours within half the box")
        cutoff = min(limit, 1.5 * cutoff)
    order = np.lexsort((dist, src))
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    take = (start[:, None] + np.arange(k)[None, :]).ravel()
    return dst[order][take].reshape(n, k), dx[order][take].reshape(n, k, d)


def hexatic_order(packing: Packing) -> NDArray[np.complex128]:
    """Local 2D bond-orientational order ``psi6_i`` over the 6 nearest neighbours, shape (N,)."""
    if packing.d != 2:
        raise ValueError(f"psi6 is defined in 2D, got d={packing.d}")
    _, dx = nearest_neighbours(packing, 6)
    theta = np.arctan2(dx[..., 1], dx[..., 0])
    return np.exp(6j * theta).mean(axis=1)


def bond_order_vectors(packing: Packing, l: int = 6, k: int = 12) -> tuple[NDArray[np.complex128], NDArray[np.int64]]:
    """Steinhardt ``q_lm(i) = (1/k) sum_j Y_lm(r_ij)`` over the ``k`` nearest neighbours (3D).

    Returns
    -------
    qlm : ndarray of complex, shape (N, 2l+1)
        For ``m = -l .. l``.
    neighbours : ndarray of int64, shape (N, k)
    """
    if packing.d != 3:
        raise ValueError(f"Steinhardt q_l is computed in 3D, got d={packing.d}")
    j, dx = nearest_neighbours(packing, k)
    r = np.linalg.norm(dx, axis=2)
    polar = np.arccos(np.clip(dx[..., 2] / r, -1.0, 1.0))
    azimuth = np.arctan2(dx[..., 1], dx[..., 0])
    m = np.arange(-l, l + 1)
    y = sph_harm_y(l, m[None, None, :], polar[..., None], azimuth[..., None])
    return y.mean(axis=1), j


def steinhardt_q(packing: Packing, l: int = 6, k: int = 12) -> tuple[NDArray[np.float64], float, NDArray[np.complex128]]:
    """Steinhardt bond-orientational order over the ``k`` nearest neighbours (3D).

    Returns
    -------
    q_local : ndarray, shape (N,)
        ``q_l(i) = sqrt(4 pi / (2l+1) sum_m |q_lm(i)|^2)``.
    Q_global : float
        ``sqrt(4 pi / (2l+1) sum_m |<q_lm>|^2)`` with ``<.>`` over particles (equal
        neighbour counts, so this is the bond average).
    qlm : ndarray of complex, shape (N, 2l+1)
    """
    qlm, _ = bond_order_vectors(packing, l, k)
    norm = 4.0 * np.pi / (2 * l + 1)
    q_local = np.sqrt(norm * np.sum(np.abs(qlm) ** 2, axis=1))
    q_global = float(np.sqrt(norm * np.sum(np.abs(qlm.mean(axis=0)) ** 2)))
    return q_local, q_global, qlm


def crystal_like(
    packing: Packing,
    dot_threshold: float = TWF_DOT_THRESHOLD,
    min_connected: int = TWF_MIN_CONNECTED,
    k: int = 12,
) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
    """ten Wolde–Frenkel crystal-like particles from normalised q6 vectors (3D).

    Returns
    -------
    crystal : ndarray of bool, shape (N,)
    connected : ndarray of int, shape (N,)
        Number of neighbours ``j`` with ``Re(q6(i) · q6(j)*) / (|q6(i)| |q6(j)|) > dot_threshold``.
    """
    qlm, j = bond_order_vectors(packing, 6, k)
    return crystal_like_from(qlm, j, dot_threshold, min_connected)


def crystal_like_from(
    qlm: NDArray[np.complex128],
    neighbours: NDArray[np.int64],
    dot_threshold: float = TWF_DOT_THRESHOLD,
    min_connected: int = TWF_MIN_CONNECTED,
) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
    """:func:`crystal_like` from precomputed :func:`bond_order_vectors` (l = 6)."""
    unit = qlm / np.linalg.norm(qlm, axis=1)[:, None]
    dots = np.real(np.sum(unit[:, None, :] * np.conj(unit[neighbours]), axis=2))
    connected = np.sum(dots > dot_threshold, axis=1)
    return connected >= min_connected, connected


def crystal_fraction(packing: Packing) -> float:
    """Crystallisation indicator: fraction of crystal-like particles.

    3D: ten Wolde–Frenkel crystal-like particles from q6 over 12 neighbours
    (:func:`crystal_like`); 2D: fraction of particles with local
    ``|psi6| > PSI6_CRYSTAL_THRESHOLD`` (:func:`hexatic_order`; meaningful for
    monodisperse discs). A packing counts as crystallised above
    :data:`CRYSTAL_FRACTION_THRESHOLD`.
    """
    if packing.d == 3:
        return float(np.mean(crystal_like(packing)[0]))
    if packing.d == 2:
        return float(np.mean(np.abs(hexatic_order(packing)) > PSI6_CRYSTAL_THRESHOLD))
    raise ValueError(f"crystal fraction is defined for d = 2, 3, got d={packing.d}")


def structure_dataset(packing: Packing, r_max: float = 3.0, bins: int = 150, parameters: dict | None = None) -> xr.Dataset:
    """g(r) plus the crystallinity indicator of the packing's dimension, as a dataset.

    Variables: ``g(r)``; 2D ``psi6_abs(particle)`` (local |psi6|); 3D
    ``q6(particle)`` and ``crystal_like(particle)``. Attributes: ``psi6_global``,
    ``psi6_local_mean`` (2D); ``Q6_global``, ``q6_local_mean``,
    ``crystal_fraction`` (3D); ``crystallinity`` says which was computed;
    ``r_max`` and ``r_max_requested``.

    An ``r_max`` beyond half the smallest box width (where minimum-image distances end)
    is clipped there: the bins keep their width ``r_max / bins`` and the last ones are
    dropped, so g(r) of small and large packings share their bins; ``r_max_clipped``
    (0/1) says whether that happened.
    """
    require("rdf", packing.body_kind)
    width = r_max / bins
    kept = min(bins, int(np.floor(largest_r_max(packing) / width)))
    if kept < 1:
        raise ValueError(f"half the smallest box width ({largest_r_max(packing):.4g} mean diameters) is below one "
                         f"bin width ({width:.4g}): use more bins or a larger packing")
    r, g, edges = radial_distribution(packing, kept * width, kept)
    one = {"units": "1"}
    data_vars: dict = {
        "g": ("r", g, {**one, "long_name": "radial distribution function g(r)"}),
        "r_lower": ("r", edges[:-1], {**one, "long_name": "lower bin edge, in mean diameters"}),
    }
    extra: dict = {}
    if packing.d == 2:
        psi = hexatic_order(packing)
        data_vars["psi6_abs"] = ("particle", np.abs(psi), {**one, "long_name": "local hexatic order |psi6_i| (6 nearest neighbours)"})
        extra = {"crystallinity": "2D hexatic psi6 over 6 nearest neighbours",
                 "psi6_global": float(np.abs(psi.mean())), "psi6_local_mean": float(np.abs(psi).mean())}
    elif packing.d == 3:
        qlm, neighbours = bond_order_vectors(packing, 6, 12)
        norm = 4.0 * np.pi / 13.0
        q6 = np.sqrt(norm * np.sum(np.abs(qlm) ** 2, axis=1))
        q6g = float(np.sqrt(norm * np.sum(np.abs(qlm.mean(axis=0)) ** 2)))
        crys, connected = crystal_like_from(qlm, neighbours)
        data_vars["q6"] = ("particle", q6, {**one, "long_name": "local Steinhardt q6 (12 nearest neighbours)"})
        data_vars["crystal_like"] = ("particle", crys.astype(np.int8),
                                     {**one, "long_name": "ten Wolde-Frenkel crystal-like flag (1 = crystal-like)"})
        data_vars["n_connected"] = ("particle", connected, {**one, "long_name": "connected q6 bonds (of 12)"})
        extra = {"crystallinity": (f"3D Steinhardt Q6 over 12 nearest neighbours; crystal-like: at least "
                                   f"{TWF_MIN_CONNECTED} of 12 bonds with normalised q6.q6* > {TWF_DOT_THRESHOLD}"),
                 "Q6_global": q6g, "q6_local_mean": float(q6.mean()), "crystal_fraction": float(crys.mean())}
    else:
        extra = {"crystallinity": f"not computed in d={packing.d} (g(r) only)"}
    return xr.Dataset(
        data_vars=data_vars,
        coords={"r": ("r", r, {**one, "long_name": "centre distance in units of the mean diameter (bin centre)"})},
        attrs=new_dataset_attrs(
            "jamflow structure", parameters or {}, d=packing.d, N=packing.n,
            packing_fraction=packing.packing_fraction, r_max=float(edges[-1]), r_max_requested=float(r_max),
            r_max_clipped=int(kept < bins),
            length_unit_g="mean diameter; polydisperse packings: total g(r) of centre distances",
            **extra,
        ),
    )
