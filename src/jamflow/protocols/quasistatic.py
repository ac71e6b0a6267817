"""Quasistatic shear of soft spheres, and Lerner et al.'s steepest-descent shear protocol.

Both apply Lees–Edwards simple shear (flow axis 0, gradient axis 1,
``Box.with_shear``) in strain steps ``delta_gamma``: centres move affinely with the box
(``x -> A x``, ``A = h_new h_old^-1``), then the energy is minimised.

* :func:`aqs_shear` — athermal quasistatic shear: FIRE (or enthalpy minimisation at
  fixed pressure) after every step; stress from the soft pair forces
  (:mod:`jamflow.models.spheres.potential` conventions).
* :func:`lerner_sd_shear` — Lerner, During & Wyart Sec. V A 1: overdamped steepest
  descent ``dR/dt = -xi_0 grad U`` (Eq. 31) with the potential of Eq. 32
  ``epsilon_L (1 - r / sigma_ij)^2`` (``sigma_ij`` = sum of radii), step ``dt``, stopped
  at ``max_i |grad_i U| < tol``; the stress is *not* the soft stress but that of the
  hard-sphere contact forces (Eq. 18 with ``xi_0 = gamma_dot = 1``,
  ``|f> = -N^-1 S |V_aff>``, ``S|V_aff>_ij = R_x R_y / r``) on the tentative contact
  network ``r_ij < sigma_ij + delta_r``; shear stress Eq. 30 and pressure Eq. 24,
  in units of ``lambda gamma_dot / xi_0`` per ``lambda^(d-1)`` with ``lambda`` the
  packing's length unit. Its time series follows the flow schema of the
  event-driven code so the two can be compared step by step.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse.linalg as spla
import xarray as xr
from numpy.typing import NDArray

from ..box import Box
from ..io import new_dataset_attrs
from ..minimize.fire import DEFAULT_FIRE, FireParameters
from ..models.spheres.fast import steepest_descent
from ..models.spheres.model import fire, minimize_enthalpy
from ..models.spheres.potential import HARMONIC, PowerLawPotential, evaluate
from ..neighbors.pairs import pairs_within
from ..neighbors.verlet import NeighborList
from ..network import pair_rows
from ..stages import require
from ..state.packing import Packing
from ..tolerances import MINIMIZE_FORCE_TOL
from .overdamped.jamming import constrained_subset
from .soft_jam import soft_packing

__all__ = [
    "LERNER_DELTA_R",
    "affine_shear",
    "aqs_shear",
    "lerner_sd_shear",
    "tentative_network_stress",
]

#: Lerner et al.'s tentative-contact distance ``delta_r`` [lambda].
LERNER_DELTA_R: float = 1e-5


def affine_shear(x: NDArray[np.float64], box: Box, gamma: float) -> tuple[NDArray[np.float64], Box]:
    """Set the Lees–Edwards strain to ``gamma``, moving centres affinely with the box."""
    new = box.with_shear(gamma)
    A = new.matrix @ box.inverse
    return x @ A.T, new


def _reduce(x: NDArray[np.float64], box: Box, gamma0: float) -> tuple[NDArray[np.float64], Box, float]:
    """Keep the Lees–Edwards tilt within half a box side over long runs.

    Once the tilt exceeds ``h[0, 0] / 2`` the box is replaced by the same lattice with
    the tilt reduced (:attr:`Box.reduced`) and the centres are wrapped into it; the
    strain origin ``gamma0`` moves by the lattice shift, so ``gamma0 + total`` keeps
    giving the current tilt. Without it, pair vectors in a box sheared by strain
    ``gamma`` lose ``~log10(gamma)`` digits and minimisations stall (strain 1e4).
    """
    red = box.reduced
    if red == box:
        return x, box, gamma0
    return red.wrap(x), red, gamma0 + red.shear_strain - box.shear_strain


def _var(values: Any, units: str, long_name: str, **extra: Any) -> tuple:
    return ("step", np.asarray(values), {"units": units, "long_name": long_name, **extra})


def aqs_shear(
    packing: Packing,
    strain: float,
    step: float,
    potential: PowerLawPotential = HARMONIC,
    force_tol: float = MINIMIZE_FORCE_TOL,
    pressure: float | None = None,
    pressure_rtol: float = 1e-6,
    max_steps: int = 10_000_000,
    fire_params: FireParameters = DEFAULT_FIRE,
    progress: Callable[[float], None] | None = None,
) -> tuple[xr.Dataset, Packing]:
    """Athermal quasistatic shear to accumulated strain ``strain`` in steps ``step``.

    Parameters
    ----------
    packing : Packing
        Starting state (e.g. from :func:`jamflow.protocols.soft_jam.jam_to_pressure`); its
        current Lees–Edwards strain is the origin.
    strain, step : float
        Total strain added and strain step ``delta_gamma`` (dimensionless, > 0).
    potential : PowerLawPotential
    force_tol : float
        FIRE tolerance on ``max_i |F_i|`` after every step [epsilon / length].
    pressure : float, optional
        Fixed pressure ``P0`` [epsilon / length^d]: minimise the enthalpy with an
        isotropic box scale at every step instead of the energy at fixed volume.
    pressure_rtol : float
        Relative pressure tolerance of the fixed-pressure minimisation.
    max_steps : int
        FIRE step budget per strain step; a step that runs out raises RuntimeError.
    progress : callable, optional
        Called with the accumulated strain after every step.

    Returns
    -------
    series : xarray.Dataset
        Dim ``step``; coordinate ``strain``; ``shear_stress``, ``pressure``, ``energy``,
        ``n_contacts``, ``packing_fraction``, ``volume``, ``max_force``, ``fire_steps``.
    final : Packing
        Last state (contacts = overlapping pairs with forces), protocol ``+ ">aqs"``.
    """
    require("aqs", packing.body_kind)
    if not (step > 0.0 and strain > 0.0):
        raise ValueError(f"strain and step must be positive, got {strain}, {step}")
    n_steps = int(np.ceil(strain / step - 1e-9))
    x = np.array(packing.position)
    box = packing.box
    D = packing.diameter
    nlist = NeighborList(D)
    x, box, gamma0 = _reduce(x, box, box.shear_strain)
    rows: dict[str, list] = {k: [] for k in ("strain", "shear_stress", "pressure", "energy",
                                              "n_contacts", "volume", "max_force", "fire_steps")}

    def record(total: float, n: int) -> None:
        ev = evaluate(x, box, D, potential, nlist)
        for key, val in (("strain", total), ("shear_stress", ev.shear_stress),
                         ("pressure", ev.pressure), ("energy", ev.energy),
                         ("n_contacts", ev.n_contacts), ("volume", ev.volume),
                         ("max_force", ev.max_force), ("fire_steps", n)):
            rows[key].append(val)

    record(0.0, 0)
    for k in range(1, n_steps + 1):
        total = min(k * step, strain)
        x, box = affine_shear(x, box, gamma0 + total)
        x, box, gamma0 = _reduce(x, box, gamma0)
        if pressure is None:
            res = fire(x, box, D, potential, force_tol, max_steps, fire_params, nlist)
        else:
            res = minimize_enthalpy(x, box, D, pressure, potential, force_tol, pressure_rtol,
                                    max_steps, fire_params, nlist)
        if not res.converged:
            raise RuntimeError(f"minimisation did not converge at strain {total:.6g}")
        x, box = res.position, res.box
        record(total, res.steps)
        if progress is not None:
            progress(total)
    phi = packing.packing_fraction * packing.box.volume / np.asarray(rows["volume"])
    length = packing.attrs.get("length_unit", "packing length unit")
    # energies in epsilon of the pair potential, lengths in the packing's unit (mean diameter)
    stress_units = f"epsilon / length^{packing.d}"
    ds = xr.Dataset(
        data_vars={
            "shear_stress": _var(rows["shear_stress"], stress_units, "shear stress sigma_xy = (1/V) dU/dgamma",
                                 comment=f"length unit: {length}"),
            "pressure": _var(rows["pressure"], stress_units, "virial pressure", comment=f"length unit: {length}"),
            "energy": _var(rows["energy"], "1", "potential energy U", comment="epsilon"),
            "n_contacts": _var(np.asarray(rows["n_contacts"], np.int64), "1", "overlapping pairs"),
            "packing_fraction": _var(phi, "1", "packing fraction"),
            "volume": _var(rows["volume"], "1", "box volume", comment=f"{length}^d"),
            "max_force": _var(rows["max_force"], "1", "largest per-particle force norm after minimisation",
                              comment="epsilon / length"),
            "fire_steps": _var(np.asarray(rows["fire_steps"], np.int64), "1", "FIRE steps of the minimisation"),
        },
        coords={"strain": _var(rows["strain"], "1", "accumulated Lees-Edwards shear strain gamma")},
        attrs=new_dataset_attrs(
            "jamflow athermal quasistatic shear (soft spheres)",
            {"strain": strain, "step": step, "force_tol": force_tol, "pressure": pressure,
             "potential_exponent": potential.exponent, "epsilon": potential.epsilon,
             "fire": fire_params.as_dict()},
            mode="shear" if pressure is None else "shear_fixed_pressure",
            d=packing.d, N=packing.n, protocol=packing.protocol + ">aqs",
        ),
    )
    final = soft_packing(x, box, D, potential, packing, ">aqs", dict(packing.parameters),
                         dict(packing.attrs))
    return ds, final


def tentative_network_stress(
    x: NDArray[np.float64], box: Box, diameter: NDArray[np.float64], delta_r: float = LERNER_DELTA_R
) -> dict[str, Any]:
    """Hard-sphere contact forces and stress on the tentative network ``r < sigma + delta_r``.

    Lerner et al. Eq. 18 under unit simple-shear rate (``xi_0 = gamma_dot = 1``):
    ``S S^T |f> = -S |V_aff>`` with ``(S V_aff)_ij = R_x R_y / r`` (Lees–Edwards);
    solved by sparse LU, or by LSQR (minimum norm) when ``N = S S^T`` is singular.

    Returns
    -------
    dict with ``pairs`` (i, j arrays), ``force`` (Nc,), ``shear_stress`` (Eq. 30),
    ``pressure`` (Eq. 24), ``constraint_error`` (max |r - sigma| / sigma), ``z_bar``
    (Eq. 29), ``n_contacts``.
    """
    n, d = x.shape
    pairs = pairs_within(x, box, float(diameter.max()) + delta_r)
    sigma = 0.5 * (diameter[pairs.i] + diameter[pairs.j])
    r = pairs.distance
    keep = r < sigma + delta_r
    pairs, sigma, r = pairs.select(keep), sigma[keep], r[keep]
    nc = len(r)
    volume = box.volume
    out: dict[str, Any] = {"pairs": (pairs.i, pairs.j), "n_contacts": nc}
    if nc == 0:
        out.update(force=np.zeros(0), shear_stress=0.0, pressure=0.0, constraint_error=np.nan,
                   z_bar=0.0)
        return out
    R = pairs.dx
    contacts = np.stack([pairs.i, pairs.j], axis=1)
    # S = d r / d x, the contact Jacobian (Eq. 2)
    S = pair_rows(contacts, R / r[:, None], n)
    b = R[:, 0] * R[:, 1] / r
    Nmat = (S @ S.T).tocsc()
    f = None
    try:
        with warnings.catch_warnings():
            # a singular N (a floppy tentative network) is answered by least squares below
            warnings.simplefilter("error", spla.MatrixRankWarning)
            f = spla.spsolve(Nmat, -b)
        if not np.all(np.isfinite(f)) or np.linalg.norm(Nmat @ f + b) > 1e-8 * (np.linalg.norm(b) + 1e-300):
            f = None
    except (RuntimeError, spla.MatrixRankWarning):
        f = None
    if f is None:
        f = spla.lsqr(Nmat, -b, atol=1e-14, btol=1e-14, iter_lim=100 * nc)[0]
    out.update(
        force=f,
        shear_stress=float(-np.sum(f * b) / volume),
        pressure=float(np.sum(f * r) / (d * volume)),
        constraint_error=float(np.max(np.abs(r - sigma) / sigma)),
        z_bar=constrained_subset(n, d, contacts).z_bar,
    )
    return out


def lerner_sd_shear(
    packing: Packing,
    strain: float,
    step: float = 1e-6,
    dt: float = 0.1,
    grad_tol: float = 1e-9,
    delta_r: float = LERNER_DELTA_R,
    epsilon: float = 1.0,
    max_steps: int = 10_000_000,
    progress: Callable[[float], None] | None = None,
) -> xr.Dataset:
    """Lerner et al.'s steepest-descent shear protocol (Sec. V A 1) as a flow time series.

    Parameters
    ----------
    packing : Packing
        Starting configuration, lengths in units of ``lambda`` (Lerner: mean small
        diameter); hard-sphere-like (overlaps are relaxed by the first descent).
    strain : float
        Total strain added.
    step : float
        Strain step ``delta_gamma`` (paper: 1e-6).
    dt : float
        Steepest-descent step (paper: 0.1) [lambda^2 / (xi_0 epsilon_L)].
    grad_tol : float
        Stop each descent at ``max_i |grad_i U| < grad_tol`` (paper: 1e-9) [epsilon_L / lambda].
    delta_r : float
        Tentative-network distance (paper: 1e-5) [lambda].
    epsilon : float
        ``epsilon_L`` of Eq. 32 (energy scale; the soft potential is
        ``PowerLawPotential(epsilon=2 epsilon_L, exponent=2)``).
    max_steps : int
        Descent steps allowed per strain step (RuntimeError beyond).

    Returns
    -------
    xarray.Dataset
        The flow-run schema (docs/schema.md, "Flow runs"): dim ``step`` with coordinates ``strain`` and
        ``time`` (= strain, unit 1/gamma_dot); ``shear_stress``, ``pressure``,
        ``packing_fraction``, ``kappa`` (NaN: fixed volume), ``n_contacts``, ``z_bar``,
        ``volume``, ``constraint_error``, plus ``energy`` and ``sd_steps``; events
        (``event_*``) are pairs entering (1) or leaving (-1) the tentative network
        between strain steps.
    """
    require("sd-shear", packing.body_kind)
    if not (step > 0.0 and strain > 0.0):
        raise ValueError(f"strain and step must be positive, got {strain}, {step}")
    potential = PowerLawPotential(epsilon=2.0 * epsilon, exponent=2.0)
    n_steps = int(np.ceil(strain / step - 1e-9))
    x = np.array(packing.position)
    box = packing.box
    D = packing.diameter
    n = packing.n
    nlist = NeighborList(D)
    x, box, gamma0 = _reduce(x, box, box.shear_strain)
    keys = ("strain", "shear_stress", "pressure", "n_contacts", "z_bar", "constraint_error",
            "energy", "sd_steps", "volume")
    rows: dict[str, list] = {k: [] for k in keys}
    events: dict[str, list] = {"strain": [], "i": [], "j": [], "kind": []}
    previous = np.empty(0, np.int64)
    for k in range(n_steps + 1):
        total = min(k * step, strain)
        if k > 0:
            x, box = affine_shear(x, box, gamma0 + total)
            x, box, gamma0 = _reduce(x, box, gamma0)
        sd = steepest_descent(x, box, D, potential, dt, grad_tol * epsilon,
                              max_steps, nlist).result
        if not sd.converged:
            raise RuntimeError(f"steepest descent did not converge at strain {total:.6g}")
        x = sd.position
        net = tentative_network_stress(x, box, D, delta_r)
        key = net["pairs"][0] * n + net["pairs"][1]
        if k > 0:
            for kind, changed in ((1, np.setdiff1d(key, previous)), (-1, np.setdiff1d(previous, key))):
                events["strain"].extend([total] * len(changed))
                events["i"].extend((changed // n).tolist())
                events["j"].extend((changed % n).tolist())
                events["kind"].extend([kind] * len(changed))
        previous = key
        for name, val in (("strain", total), ("shear_stress", net["shear_stress"]),
                          ("pressure", net["pressure"]), ("n_contacts", net["n_contacts"]),
                          ("z_bar", net["z_bar"]), ("constraint_error", net["constraint_error"]),
                          ("energy", sd.energy), ("sd_steps", sd.steps), ("volume", box.volume)):
            rows[name].append(val)
        if progress is not None:
            progress(total)
    strain_arr = np.asarray(rows["strain"])
    phi = packing.packing_fraction * packing.box.volume / np.asarray(rows["volume"])
    stress_comment = "units lambda gamma_dot / xi_0 per lambda^(d-1), xi_0 = gamma_dot = 1"
    # Lerner et al. Sec. II D: forces in lambda gamma_dot / xi_0, stress per lambda^(d-1)
    sd_units = "gamma_dot / xi0" if packing.d == 2 else f"gamma_dot / (xi0 lambda^{packing.d - 2})"
    ev_strain = np.asarray(events["strain"], dtype=np.float64)
    ds = xr.Dataset(
        data_vars={
            "shear_stress": _var(rows["shear_stress"], sd_units,
                                 "shear stress of hard-sphere forces on the tentative network (Lerner Eq. 30)",
                                 comment=stress_comment),
            "pressure": _var(rows["pressure"], sd_units, "pressure of hard-sphere forces on the tentative network (Eq. 24)",
                             comment=stress_comment),
            "packing_fraction": _var(phi, "1", "packing fraction"),
            "kappa": _var(np.full(len(strain_arr), np.nan), "1", "compression to shear rate ratio (NaN: fixed volume)"),
            "n_contacts": _var(np.asarray(rows["n_contacts"], np.int64), "1",
                               "pairs in the tentative network r < sigma + delta_r"),
            "z_bar": _var(rows["z_bar"], "1", "constrained coordination (Lerner Eq. 29) of the tentative network"),
            "volume": _var(rows["volume"], "1", "box volume", comment="lambda^d"),
            "constraint_error": _var(rows["constraint_error"], "1",
                                     "max |r - sigma| / sigma over the tentative network"),
            "energy": _var(rows["energy"], "1", "soft energy after descent", comment="epsilon_L"),
            "sd_steps": _var(np.asarray(rows["sd_steps"], np.int64), "1", "steepest-descent steps"),
            "event_strain": ("event", ev_strain, {"units": "1", "long_name": "strain of the step at which the tentative network changed"}),
            "event_time": ("event", ev_strain, {"units": "1", "long_name": "time of the event", "comment": "1 / gamma_dot"}),
            "event_i": ("event", np.asarray(events["i"], np.int64), {"units": "1", "long_name": "first particle (i < j)"}),
            "event_j": ("event", np.asarray(events["j"], np.int64), {"units": "1", "long_name": "second particle"}),
            "event_kind": ("event", np.asarray(events["kind"], np.int8),
                           {"units": "1", "long_name": "tentative network change",
                            "flag_values": np.array([1, -1], np.int8),
                            "flag_meanings": "contact_made contact_broken"}),
        },
        coords={
            "strain": _var(strain_arr, "1", "accumulated Lees-Edwards shear strain gamma"),
            "time": _var(strain_arr, "1", "time", comment="1 / gamma_dot (gamma_dot = 1)"),
        },
        attrs=new_dataset_attrs(
            "jamflow steepest-descent shear (Lerner, During & Wyart Sec. V A 1)",
            {"strain": strain, "step": step, "dt": dt, "grad_tol": grad_tol, "delta_r": delta_r,
             "epsilon": epsilon},
            mode="shear", d=packing.d, N=packing.n, protocol=packing.protocol + ">sd",
            time_unit="1 / gamma_dot", stress_unit=stress_comment,
        ),
    )
    return ds
