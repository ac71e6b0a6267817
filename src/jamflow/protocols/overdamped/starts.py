"""Dense starts for event-driven flow: a jammed packing decompressed to a target density.

Preparing a dense start by event-driven compression slows down as the packing fraction
approaches jamming (the event rate and the conditioning of N = S S^T both diverge). A
hard-sphere packing jammed by LS + CALiPPSO (or a soft packing at the jamming onset)
at phi_J is brought to any phi < phi_J in one step by shrinking every diameter by the
same factor ``(phi / phi_J)^(1/d)`` about fixed centres: no pair overlaps afterwards,
since every centre distance is at least the old contact distance up to the input's
overlap tolerance and every contact distance shrinks by the factor.

Physically the two starts differ: a decompressed jammed packing is a mechanically
special state (isostatic network, marginally stable gaps) with every gap opened by the
same relative amount, whereas a compression stopped at phi is a liquid-like state of
that density. Neither is the steady flowing state; a flow run must discard its initial
transient (of order 0.1-1 strain at phi close to phi_J) before averaging.
"""

from __future__ import annotations

import numpy as np

from ...network.spheres import force_balance_residual
from ...stages import require
from ...state.packing import Packing
from ...tolerances import FORCE_BALANCE_TOL, REWIRE_REL_TOL
from .driving import Drive

__all__ = ["decompressed", "jammed_start"]


def jammed_start(packing: Packing, drive: Drive) -> str | None:
    """Why a start cannot move under a fixed-volume shear, or None when it may.

    A start whose stored contact forces ``f >= 0`` balance every sphere (a positive
    self-stress: the forces of a CALiPPSO packing, or of a compression that ended
    jammed) resists any motion that closes its contacts on average. For velocities
    ``V`` of the spheres the contact rates are ``dr_c/dt = (S V)_c + n_c . E r_c`` and
    ``sum_c f_c (S V)_c = 0`` for a self-stress, so ``sum_c f_c dr_c/dt = sum_c f_c
    n_c . E r_c`` whatever the spheres do. When the imposed gradient ``E`` makes that
    negative some contact would have to close, which hard spheres cannot: the network
    is jammed against this drive (Lerner et al. Sec. IV D) and the dynamics cannot
    advance the strain. A drive that unloads the forces (the sum positive) may run.

    Returns
    -------
    str or None
        One line naming the reason and what to run instead.
    """
    if drive.mode != "shear" or packing.contacts is None or packing.force is None or not len(packing.force):
        return None
    f = np.asarray(packing.force, dtype=np.float64)
    if np.any(f < 0.0) or not np.any(f > 0.0) or force_balance_residual(packing).max() > FORCE_BALANCE_TOL:
        return None
    r = packing.contact_vectors()
    n = r / np.linalg.norm(r, axis=1)[:, None]
    rate = np.einsum("ca,ab,cb->c", n, drive.gradient(packing.d), r)
    if f @ rate >= -REWIRE_REL_TOL * float(np.abs(f) @ np.abs(rate)):
        return None
    return ("the start is jammed against this shear: its contact forces (a positive self-stress) resist the imposed "
            "strain, so hard spheres at fixed volume cannot move; shear at fixed pressure (--pressure P) or from a "
            "decompressed start (jamflow decompress IN OUT --phi PHI)")


def decompressed(packing: Packing, phi: float) -> Packing:
    """Shrink all diameters uniformly to packing fraction ``phi`` (centres and box unchanged).

    Parameters
    ----------
    packing : Packing
        A (typically jammed) packing at packing fraction ``phi_0``.
    phi : float
        Target packing fraction, ``0 < phi < phi_0``.

    Returns
    -------
    Packing
        Same centres and box, diameters scaled by ``(phi / phi_0)^(1/d)``; no contacts,
        forces, rattlers or pressure (none of them hold after the decompression).
        ``parameters`` records ``decompressed_from`` (phi_0) and ``decompressed_to``.

    Raises
    ------
    ValueError
        If ``phi`` is not in ``(0, phi_0)``.
    """
    require("decompress", packing.body_kind)
    phi0 = packing.packing_fraction
    if not (0.0 < phi < phi0):
        raise ValueError(f"decompression target phi = {phi} must lie in (0, {phi0:.6g}) (the packing's own phi)")
    scale = (phi / phi0) ** (1.0 / packing.d)
    return Packing(
        position=packing.position, diameter=packing.diameter * scale, box=packing.box,
        protocol=f"{packing.protocol}+decompressed", seed=packing.seed,
        parameters={**packing.parameters, "decompressed_from": phi0, "decompressed_to": phi},
        attrs=dict(packing.attrs),
    )
