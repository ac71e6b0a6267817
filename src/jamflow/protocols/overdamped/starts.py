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

from ...stages import require
from ...state.packing import Packing

__all__ = ["decompressed"]


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
