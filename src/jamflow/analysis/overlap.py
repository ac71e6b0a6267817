"""Contact-network overlap Q between jammed packings of the same sample.

CALiPPSO paper, Sec. III A: ``Q(A, B) = |C_A ∩ C_B| / N_c(B)`` with ``C`` the set of
contacts identified by particle identity (pairs ``i < j``) and ``B`` the reference
(the packing jammed from the largest target pressure ``p_max``). ``Q = 1`` only
when the two networks coincide. ``|Delta phi_J| = |phi_J(p_max) - phi_J(p_tar)|``
accompanies it (Fig. 3 c–f).

Two packings are comparable when they have the same N and d and proportional
diameters: jamming the same sample from different pressures inflates all spheres by
a common factor, so only the ratios must agree (relative tolerance
``jamflow.tolerances.DIAMETER_RATIO_RTOL``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..io import new_dataset_attrs
from ..network.spheres import contact_network
from ..stages import require
from ..state.packing import Packing
from ..tolerances import DIAMETER_RATIO_RTOL

__all__ = ["check_same_sample", "contact_overlap", "overlap_dataset", "overlap_series"]


def check_same_sample(a: Packing, b: Packing) -> None:
    """Raise ``ValueError`` unless ``a`` and ``b`` have equal N, d and proportional diameters."""
    if a.n != b.n or a.d != b.d:
        raise ValueError(f"packings differ in size: N={a.n}, d={a.d} against N={b.n}, d={b.d}")
    ratio = a.diameter / b.diameter
    if not np.allclose(ratio, ratio[0], rtol=DIAMETER_RATIO_RTOL, atol=0.0):
        k = int(np.argmax(np.abs(ratio / ratio[0] - 1.0)))
        raise ValueError(
            f"packings do not hold the same particles: diameter ratio of particle {k} is {ratio[k]:.12g}, "
            f"of particle 0 {ratio[0]:.12g}"
        )


def _keys(contacts: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    return np.unique(contacts[:, 0] * n + contacts[:, 1])


def contact_overlap(a: Packing, b: Packing, gap_tol: float | None = None) -> tuple[float, int, int, int]:
    """``Q(A, B) = |C_A ∩ C_B| / N_c(B)``.

    Parameters
    ----------
    a, b : Packing
        ``b`` is the reference. Contacts are the packings' own (``gap_tol=None``) or
        pairs with ``h <= gap_tol``, as in :func:`~jamflow.analysis.contacts.contact_network`.

    Returns
    -------
    Q : float
    n_common, n_contacts_a, n_contacts_b : int
    """
    for packing in (a, b):
        require("overlap", packing.body_kind)
    check_same_sample(a, b)
    ka = _keys(contact_network(a, gap_tol), a.n)
    kb = _keys(contact_network(b, gap_tol), b.n)
    if len(kb) == 0:
        raise ValueError("the reference packing has no contacts; Q is undefined")
    common = int(np.intersect1d(ka, kb, assume_unique=True).size)
    return common / len(kb), common, len(ka), len(kb)


def overlap_dataset(a: Packing, b: Packing, gap_tol: float | None = None, parameters: dict | None = None) -> xr.Dataset:
    """:func:`contact_overlap` as a dataset with attributes ``Q``, counts and phi's."""
    q, common, na, nb = contact_overlap(a, b, gap_tol)
    one = {"units": "1"}
    return xr.Dataset(
        data_vars={
            "Q": ((), q, {**one, "long_name": "contact-network overlap |C_A ∩ C_B| / N_c(B)"}),
            "n_common": ((), common, {**one, "long_name": "number of contacts common to A and B"}),
            "n_contacts_a": ((), na, {**one, "long_name": "number of contacts of A"}),
            "n_contacts_b": ((), nb, {**one, "long_name": "number of contacts of the reference B"}),
        },
        attrs=new_dataset_attrs(
            "jamflow contact-network overlap",
            parameters or {},
            Q=q, n_common=common, n_contacts_a=na, n_contacts_b=nb,
            phi_a=a.packing_fraction, phi_b=b.packing_fraction,
            abs_delta_phi=abs(a.packing_fraction - b.packing_fraction),
            contacts="explicit contacts of each packing" if gap_tol is None else f"pairs with h <= {gap_tol:g}",
        ),
    )


def overlap_series(
    packings: Sequence[Packing],
    p_target: Sequence[float],
    gap_tol: float | None = None,
    parameters: dict | None = None,
    growth_rate: float | None = None,
) -> xr.Dataset:
    """Q(p_tar), |Delta phi_J(p_tar)| and n(p_tar) of one sample against its largest p_tar.

    Parameters
    ----------
    packings : sequence of Packing
        Jammed packings of one sample, each crunched from the target pressure in
        ``p_target`` (same order). When every packing carries the attribute
        ``iterations`` (written by ``jamflow calippso``), the number of linear
        optimisations ``n_lp`` is included (Fig. 3 g, h).
    p_target : sequence of float
        Target pressures; the packing at the largest one is the reference.
    growth_rate : float or None
        LS growth rate kappa of the sample, stored as attribute ``kappa`` so that
        samples can be grouped by it (Fig. 3, left column).

    Returns
    -------
    xarray.Dataset
        dim ``p_target`` (sorted ascending): ``Q``, ``one_minus_Q``, ``phi_J``,
        ``abs_delta_phi_J``, ``n_contacts``, ``n_common`` and possibly ``n_lp``.
    """
    p_target = np.asarray(p_target, dtype=np.float64)
    if len(packings) != len(p_target) or len(packings) == 0:
        raise ValueError(f"need one p_target per packing, got {len(p_target)} for {len(packings)} packings")
    if len(np.unique(p_target)) != len(p_target):
        raise ValueError("p_target values must be distinct")
    order = np.argsort(p_target)
    ref = packings[order[-1]]
    rows = [contact_overlap(packings[k], ref, gap_tol) for k in order]
    phi = np.array([packings[k].packing_fraction for k in order])
    q = np.array([r[0] for r in rows])
    one = {"units": "1"}
    data_vars = {
        "Q": ("p_target", q, {**one, "long_name": "contact overlap with the packing at the largest p_target"}),
        "one_minus_Q": ("p_target", 1.0 - q, {**one, "long_name": "1 - Q"}),
        "phi_J": ("p_target", phi, {**one, "long_name": "jamming packing fraction"}),
        "abs_delta_phi_J": ("p_target", np.abs(phi - phi[-1]),
                            {**one, "long_name": "|phi_J(p_max) - phi_J(p_target)|"}),
        "n_contacts": ("p_target", np.array([r[2] for r in rows]), {**one, "long_name": "number of contacts"}),
        "n_common": ("p_target", np.array([r[1] for r in rows]),
                     {**one, "long_name": "contacts shared with the reference"}),
    }
    if all("iterations" in packings[k].attrs for k in order):
        # LPs solved: a Newton finish (jamflow calippso --finish newton) is a history entry, not an LP
        data_vars["n_lp"] = ("p_target", np.array([int(packings[k].attrs.get("n_lps", packings[k].attrs["iterations"]))
                                                   for k in order]),
                             {**one, "long_name": "number of linear optimisations of CALiPPSO"})
    extra = {} if growth_rate is None else {"kappa": float(growth_rate)}
    return xr.Dataset(
        data_vars=data_vars,
        coords={"p_target": ("p_target", p_target[order],
                             {"units": "1", "long_name": "target reduced pressure of the LS compression"})},
        attrs=new_dataset_attrs("jamflow contact overlap series", parameters or {},
                                p_max=float(p_target[order[-1]]), **extra),
    )
