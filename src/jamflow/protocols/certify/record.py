"""What a jamming certificate says: the categories, the LP records, the certificate and its dataset."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ...io import new_dataset_attrs
from ...network import isostatic_count
from ...state.packing import Packing

#: Jamming categories, weakest first.
CLASSIFICATIONS: tuple[str, ...] = ("not_jammed", "locally_jammed", "collectively_jammed", "strictly_jammed")

#: Why a particle left the backbone (index = code stored in ``rattler_stage``).
RATTLER_STAGES: tuple[str, ...] = ("backbone", "coordination", "local_lp", "rattling_cluster")

#: LP kinds (index = code stored in ``lp_stage``).
LP_STAGES: tuple[str, ...] = ("local", "collective", "strict")


@dataclass(frozen=True)
class LPRecord:
    """One solved LP: kind, load index and sign, HiGHS status, optimum, cost."""

    stage: str
    rhs: str  # "gaps" (screening) or "zero" (exact contacts)
    load: int
    sign: int
    status: str
    objective: float
    time: float  # wall time [s]
    iterations: int
    max_displacement: float  # largest displacement (or strain coordinate) [mean diameters]


@dataclass(frozen=True)
class JammingCertificate:
    """Outcome of :func:`certify`.

    Attributes
    ----------
    classification : str
        Strongest category that holds, one of :data:`CLASSIFICATIONS`.
    contacts : ndarray of int64, shape (Nc, 2)
        Contact network tested (all particles).
    gap : ndarray, shape (Nc,)
        Relative gaps ``r / sigma_ij - 1`` of those contacts.
    rhs : str
        ``"zero"`` (exact contacts) or ``"gaps"`` (gap-aware constraints).
    rattler_stage : ndarray of int8, shape (N,)
        Index into :data:`RATTLER_STAGES` (0 = backbone).
    motion : ndarray, shape (N, d) or None
        Unjamming displacement [mean diameters, every coordinate at most 1]; zero on
        rattlers. None when no unjamming motion of the backbone was found.
    motion_strain : ndarray, shape (d, d) or None
        Box strain of the unjamming motion (strict test only).
    motion_stage : str
        ``"collective"``, ``"strict"`` or ``""``.
    strict_tested : bool
        Whether the strain LP ran.
    cage : float
        Gap-aware only: largest coordinate of the gap-aware LP solutions that found
        no unjamming motion [mean diameters], i.e. the first-order cage; 1 when a
        cage reaches the displacement bound.
    cage_at_bound : int
        Gap-aware loads whose cage reached the bound although the exact-contact
        cone is trivial (the cage is then at least one mean diameter).
    lp : list of LPRecord
    parameters : dict
    self_stress_decisions : int
        Backbones decided without LPs by the Roth-Whiteley test (see :func:`certify`).
    """

    classification: str
    contacts: NDArray[np.int64]
    gap: NDArray[np.float64]
    rhs: str
    rattler_stage: NDArray[np.int8]
    motion: NDArray[np.float64] | None
    motion_strain: NDArray[np.float64] | None
    motion_stage: str
    strict_tested: bool
    cage: float
    cage_at_bound: int
    lp: list[LPRecord] = field(default_factory=list)
    parameters: dict[str, Any] = field(default_factory=dict)
    self_stress_decisions: int = 0

    @property
    def rattler(self) -> NDArray[np.bool_]:
        """Particles outside the certified backbone, shape (N,)."""
        return self.rattler_stage > 0

    @property
    def backbone_contacts(self) -> NDArray[np.int64]:
        """Contacts between backbone particles, shape (Nb, 2)."""
        r = self.rattler
        keep = ~(r[self.contacts[:, 0]] | r[self.contacts[:, 1]])
        return self.contacts[keep]


def certificate_to_dataset(cert: JammingCertificate, packing: Packing, parameters: dict[str, Any] | None = None) -> xr.Dataset:
    """The certificate as a dataset (variables with units and long names, provenance)."""
    n, d = packing.n, packing.d
    c = cert.contacts
    rattler = cert.rattler
    n_backbone = int((~rattler).sum())
    n_bc = len(cert.backbone_contacts)
    flag = {"units": "1"}
    motion = np.zeros((n, d)) if cert.motion is None else cert.motion
    strain = np.zeros((d, d)) if cert.motion_strain is None else cert.motion_strain
    recs = cert.lp
    data_vars = {
        "contact_i": (("contact",), c[:, 0], {**flag, "long_name": "first particle of a tested contact (i < j)"}),
        "contact_j": (("contact",), c[:, 1], {**flag, "long_name": "second particle of a tested contact (i < j)"}),
        "contact_gap": (("contact",), cert.gap, {**flag, "long_name": "relative gap r / sigma_ij - 1 of a tested contact"}),
        "rattler": (("particle",), rattler.astype(np.int8), {
            **flag, "long_name": "rattler flag (1 = outside the certified backbone)",
            "flag_values": np.array([0, 1], dtype=np.int8), "flag_meanings": "backbone rattler"}),
        "rattler_stage": (("particle",), cert.rattler_stage, {
            **flag, "long_name": "stage at which a particle was removed as a rattler",
            "flag_values": np.arange(len(RATTLER_STAGES), dtype=np.int8),
            "flag_meanings": " ".join(RATTLER_STAGES)}),
        "unjamming_motion": (("particle", "spatial"), motion, {
            **flag, "long_name": "unjamming displacement found by the LP (zero if none)",
            "comment": "in mean diameters, every coordinate bounded by 1; only the direction is "
                       "meaningful for exact contacts; zero on rattlers"}),
        "unjamming_strain": (("spatial", "spatial_2"), strain, {
            **flag, "long_name": "symmetric box strain of the unjamming motion (strict test; zero if none)"}),
        "lp_stage": (("lp",), np.array([LP_STAGES.index(r.stage) for r in recs], dtype=np.int8), {
            **flag, "long_name": "kind of LP", "flag_values": np.arange(len(LP_STAGES), dtype=np.int8),
            "flag_meanings": " ".join(LP_STAGES)}),
        "lp_rhs": (("lp",), np.array([r.rhs == "gaps" for r in recs], dtype=np.int8), {
            **flag, "long_name": "right-hand side of the LP", "flag_values": np.array([0, 1], dtype=np.int8),
            "flag_meanings": "zero_exact_contacts gaps"}),
        "lp_load": (("lp",), np.array([r.load for r in recs], dtype=np.int32), {**flag, "long_name": "random load index"}),
        "lp_sign": (("lp",), np.array([r.sign for r in recs], dtype=np.int8), {**flag, "long_name": "sign of the load"}),
        "lp_optimal": (("lp",), np.array([r.status == "Optimal" for r in recs], dtype=np.int8), {
            **flag, "long_name": "HiGHS model status is Optimal (1) or not (0)"}),
        "lp_objective": (("lp",), np.array([r.objective for r in recs]), {
            **flag, "long_name": "optimum of the load times the displacement (mean diameters)"}),
        "lp_time": (("lp",), np.array([r.time for r in recs]), {"units": "s", "long_name": "wall time of the LP solve"}),
        "lp_iterations": (("lp",), np.array([r.iterations for r in recs], dtype=np.int64), {
            **flag, "long_name": "simplex plus interior-point iterations"}),
        "lp_max_displacement": (("lp",), np.array([r.max_displacement for r in recs]), {
            **flag, "long_name": "largest particle displacement (or strain) of the LP solution, in mean diameters"}),
    }
    attrs = new_dataset_attrs(
        f"jamflow jamming certificate: {cert.classification}",
        parameters if parameters is not None else cert.parameters,
        classification=cert.classification,
        rhs=cert.rhs,
        strict_tested=cert.strict_tested,
        motion_stage=cert.motion_stage,
        has_unjamming_motion=cert.motion is not None,
        d=d,
        N=n,
        n_rattlers=int(rattler.sum()),
        n_backbone=n_backbone,
        n_contacts=len(c),
        n_backbone_contacts=n_bc,
        isostatic_count=isostatic_count(n_backbone, d, global_dofs=d),
        n_lp=len(recs),
        lp_time_total=float(sum(r.time for r in recs)),
        cage=cert.cage,
        cage_at_bound=cert.cage_at_bound,
        n_self_stress_decisions=cert.self_stress_decisions,
        packing_protocol=packing.protocol,
    )
    return xr.Dataset(data_vars=data_vars, attrs=attrs)
