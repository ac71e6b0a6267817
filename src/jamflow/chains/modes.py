"""Normal modes of linked packings with their zero modes named (chains paper Sec. IV A).

The eigenvectors ``v`` of the constrained Hessian ``H_E`` (:func:`~jamflow.chains.hessian.constrained_hessian`)
are mapped back to centres and strain by ``B^T v`` (the paper: "multiplying them by
``B^T`` giving a set of ``N_dof`` eigenmodes in the familiar basis of positions of
particles and strains"). Every mode is a unit vector in the coordinates of the
models: centres [length] and, with strain, the scaled strain ``e`` of
:mod:`jamflow.models.strain` (``e_aa = q_s eps_aa``, ``e_ab = sqrt(2) q_s eps_ab``).

The zero eigenspace (eigenvalues below
:data:`~jamflow.chains.hessian.ZERO_MODE_RTOL` of the largest) is given a basis
of named motions, in this order, each orthogonalised against the ones before: the
**free motions** of held clusters (a trimer swinging about its only touching sphere,
a dangling chain end, a rotator; :attr:`jamflow.network.BodyCount.free_motions`),
the motions of the **rattling clusters** that the counting removes whole (both
local: they stay on their clusters' spheres), then the ``d`` **translations**
(what of the uniform translations is orthogonal to those). What of the zero eigenspace is
left is **floppy**: a zero mode no counting explains (an unjamming motion, or a
rattling cluster only the certificate's LPs find). Each named motion must lie in
the zero eigenspace; one that does not is reported (``unexplained``), never
silently dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from ..models.spheres.potential import HARMONIC, PowerLawPotential
from ..models.strain import strain_matrix
from ..network import BodyCount, count_bodies
from ..state.packing import Packing
from .hessian import ZERO_MODE_RTOL, _geometry, constrained_hessian, gamma_matrix

__all__ = ["MODE_LABELS", "LinkedModes", "linked_modes", "modes_dataset"]

#: Names of the mode labels (index = code stored in ``LinkedModes.label``).
MODE_LABELS: tuple[str, ...] = ("vibration", "translation", "rattling_cluster", "free_motion", "floppy")

#: A named zero motion lies in the zero eigenspace when its component outside it is
#: below this fraction of its norm: eigenvectors of a dense symmetric eigensolver are
#: accurate to ~1e-16 / gap, and the gap to the softest vibration of a jammed packing
#: at P0 >= 1e-7 is above ~1e-8 of the largest eigenvalue.
ZERO_SPACE_RTOL: float = 1e-6


@dataclass(frozen=True)
class LinkedModes:
    """Eigenvalues, modes in centre (and strain) coordinates and labels of a linked packing.

    Attributes
    ----------
    eigenvalues : ndarray, shape (n_t,)
        Ascending [epsilon / length^2 at unit mass].
    vectors : ndarray, shape (N d [+ m], n_t)
        Orthonormal modes ``B^T v`` (module doc); zero modes in the named basis.
    label : ndarray of int8, shape (n_t,)
        Index into :data:`MODE_LABELS`.
    basis : ndarray, shape (n_t, N d [+ m])
        ``B`` of the constrained Hessian.
    count : BodyCount
        The counting that names the zero modes (fixed box).
    strain : bool
        Whether the strain is among the degrees of freedom (at fixed volume).
    strain_scale : float
        ``q_s`` of the strain coordinates [length].
    unexplained : int
        Named motions (translations, rattling-cluster and free motions) that are not
        zero modes.
    """

    eigenvalues: NDArray[np.float64]
    vectors: NDArray[np.float64]
    label: NDArray[np.int8]
    basis: NDArray[np.float64]
    count: BodyCount
    strain: bool
    strain_scale: float
    unexplained: int

    @property
    def n_zero(self) -> int:
        """Zero modes (every label but ``vibration``)."""
        return int(np.sum(self.label > 0))

    def n_label(self, name: str) -> int:
        """Modes labelled ``name`` (one of :data:`MODE_LABELS`)."""
        return int(np.sum(self.label == MODE_LABELS.index(name)))

    def displacement(self, n: int, d: int) -> NDArray[np.float64]:
        """Centre displacements of every mode, shape (n_t, N, d) [length per unit mode amplitude]."""
        return self.vectors[: n * d].T.reshape(-1, n, d)

    def strain_tensor(self, d: int) -> NDArray[np.float64]:
        """Strain ``eps`` of every mode, shape (n_t, d, d) (zeros without strain)."""
        if not self.strain:
            return np.zeros((self.vectors.shape[1], d, d))
        e = self.vectors[-(d * (d + 1) // 2):].T
        return np.array([strain_matrix(row, d, self.strain_scale) for row in e])


def _named_motions(count: BodyCount, n: int, d: int, m: int) -> list[tuple[int, NDArray[np.float64]]]:
    """(label, columns (N d + m, k)) of the translations, rattling-cluster motions and free motions."""
    groups = [(MODE_LABELS.index("free_motion"), count.free_motions.toarray()),
              (MODE_LABELS.index("rattling_cluster"), count.rattling_motions.toarray()),
              (MODE_LABELS.index("translation"), np.tile(np.eye(d), (n, 1)))]
    return [(code, np.vstack([cols, np.zeros((m, cols.shape[1]))])) for code, cols in groups if cols.shape[1]]


def linked_modes(packing: Packing, potential: PowerLawPotential = HARMONIC, strain: bool | None = None
                 ) -> LinkedModes:
    """Normal modes of a force-balanced linked packing with named zero modes (module doc).

    Parameters
    ----------
    strain : bool, optional
        Include the strain at fixed volume; default: when the packing is shear-stabilised
        (a fixed-box packing is not in equilibrium in the strain).
    """
    if strain is None:
        strain = bool(packing.attrs.get("shear_stabilized", 0))
    ch = constrained_hessian(packing, potential, strain=strain)
    geo = _geometry(packing, potential)
    count = count_bodies(np.stack([geo.pairs.i, geo.pairs.j], axis=1), packing.n, packing.d, packing.links,
                         packing.position, packing.box)
    B, w = ch.basis, ch.eigenvalues
    v = B @ ch.modes  # eigenvectors in tangent coordinates
    zero = np.abs(w) <= ZERO_MODE_RTOL * np.abs(w).max(initial=0.0)
    Z = v[:, zero]
    named, labels, unexplained = [], [], 0
    for code, cols in _named_motions(count, packing.n, packing.d, ch.modes.shape[0] - packing.n * packing.d):
        t = B @ cols  # named motions lie in the tangent space: B^T B cols = cols
        inside = Z @ (Z.T @ t)
        off = np.linalg.norm(t - inside, axis=0) > ZERO_SPACE_RTOL * np.linalg.norm(t, axis=0)
        unexplained += int(off.sum())
        for col in inside[:, ~off].T:
            for prev in named:
                col = col - prev * (prev @ col)
            norm = np.linalg.norm(col)
            if norm > ZERO_SPACE_RTOL:
                named.append(col / norm)
                labels.append(code)
    named_block = np.array(named).T.reshape(Z.shape[0], -1)
    rest = Z - named_block @ (named_block.T @ Z)
    u, s, _ = np.linalg.svd(rest, full_matrices=False)
    floppy = u[:, : max(0, Z.shape[1] - named_block.shape[1])] if rest.size else np.zeros((Z.shape[0], 0))
    zero_basis = np.hstack([named_block, floppy])
    label = np.zeros(w.size, np.int8)
    vectors_t = v.copy()
    idx = np.flatnonzero(zero)
    vectors_t[:, idx] = zero_basis[:, : idx.size]
    label[idx] = np.r_[labels, np.full(floppy.shape[1], MODE_LABELS.index("floppy"))][: idx.size]
    return LinkedModes(w, B.T @ vectors_t, label, B, count, strain, geo.strain_scale, unexplained)


def modes_dataset(modes: LinkedModes, packing: Packing) -> xr.Dataset:
    """The ``linked-modes`` dataset of ``jamflow modes`` (provenance attributes added by the caller).

    Variables ``eigenvalue(mode)``, ``mode_label(mode)`` (CF flags of
    :data:`MODE_LABELS`), ``mode_displacement(mode, particle, spatial)`` and
    ``mode_strain(mode, strain_component)`` (``eps_ab``, zero without strain);
    attributes the label counts and ``max_constraint_violation = max |Gamma^T y|`` over
    the modes (every link and the volume kept to first order).
    """
    n, d = packing.n, packing.d
    violation = float(np.max(np.abs(gamma_matrix(_geometry(packing, HARMONIC), modes.strain).T @ modes.vectors),
                             initial=0.0))
    a, b = np.triu_indices(d)
    mode = ("mode",)
    counts = {f"n_{name}": modes.n_label(name) for name in MODE_LABELS}
    return xr.Dataset(
        data_vars={
            "eigenvalue": (mode, modes.eigenvalues, {"units": "1", "long_name": "constrained-Hessian eigenvalue "
                                                     "(ascending)", "comment": "epsilon / length^2 (unit mass)"}),
            "mode_label": (mode, modes.label, {"units": "1", "long_name": "what the mode is",
                                               "flag_values": np.arange(len(MODE_LABELS), dtype=np.int8),
                                               "flag_meanings": " ".join(MODE_LABELS)}),
            "mode_displacement": (mode + ("particle", "spatial"), modes.displacement(n, d),
                                  {"units": "1", "long_name": "centre displacement of the unit mode",
                                   "comment": "length unit of the packing; modes are unit vectors in centres and "
                                              "the scaled strain q_s eps"}),
            "mode_strain": (mode + ("strain_component",), modes.strain_tensor(d)[:, a, b],
                            {"units": "1", "long_name": "strain eps_ab of the unit mode (zero without strain)"}),
        },
        coords={"strain_component": [f"{'xyz'[i]}{'xyz'[j]}" for i, j in zip(a, b)]},
        attrs={"N": n, "d": d, "n_links": 0 if packing.links is None else len(packing.links),
               "hessian_strain": int(modes.strain), "strain_scale": modes.strain_scale, "n_zero": modes.n_zero,
               "unexplained": modes.unexplained, "max_constraint_violation": violation,
               "pressure": float(packing.pressure or np.nan), "length_unit": packing.attrs.get("length_unit", ""),
               **counts},
    )
