"""Dynamical-matrix spectrum of shape packings: regions 0-3 and quartic modes (Sec. III B).

The dynamical matrix is ``M = d^2 U / d xi d xi`` over ``xi = (x_i, y_i, theta_i)``
(Eq. 2; not mass-weighted, as in the paper), the complex-step Hessian of
:meth:`~jamflow.models.shapes.ShapeModel.hessian` (round-off accurate: no truncation
error, which finite differences could not avoid for eigenvalues of 1e-14 ... 1e-8).
All ``3N`` eigenvalues come from a dense symmetric eigensolver (LAPACK ``syevd``).

Regions (Fig. 7):

- 0: ``|lambda| <= lambda_0``, zero modes (global translations, rattlers, sliders);
  ``lambda_0 = ZERO_EIGENVALUE_RTOL * lambda_max`` is the floor of a backward-stable
  eigensolver (a few ``eps * ||M||``) with a safety factor;
- 1: ``lambda_0 < lambda < lambda_c``, quartic modes, ``N_1`` of them;
- 2 and 3: ``lambda >= lambda_c``, predominantly rotational (2: more than half of the
  eigenvector's weight on orientations) or translational (3).

``lambda_c`` is given, or placed at the geometric middle of the widest gap of
``log lambda`` among the nonzero eigenvalues in the lower half of the spectrum (the
paper separates regions 1 and 2 by such a gap, ``lambda_c ~ 4e-8`` at ``P0 = 1e-9``;
region 1 scales with ``P0``, region 2 does not). Only a gap that can separate a
quartic band counts: its lower edge is a stress-scale eigenvalue,
``lambda <= QUARTIC_PRESSURE_RATIO * P`` (``P`` the packing's virial pressure), and it
spans at least ``REGION_GAP_MIN_RATIO``. Without such a gap region 1 is empty
(``lambda_c = lambda_0``): the widest gap alone put a lone ordinary mode
(``lambda = 2e-3`` at ``P = 1e-9``, negative fourth derivative) of a dumbbell packing
into region 1. The fourth derivative of ``U`` along
each region-1 mode ``v`` (Fig. 11) is the second difference of ``v^T M(q + s v) v``: the
first step opens no contact (:func:`fourth_derivative_step`); it grows while the
contact network stays the same (:func:`contact_signature`) until two steps agree, central
where the network is unchanged on both sides, else one-sided on the side where it is
(:func:`fourth_derivative_along`): a contact at the verge of opening, or of changing type,
makes ``M`` jump between two samples. The samples lie exactly on the line
(:func:`exact_line`), and a step counts only where the measured round-off of
``v^T M v`` (:func:`roundoff_of_form`) cannot pass for its curvature.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..minimize.model import pressure_of
from ..models.shapes import POINT_TERM_FAMILIES
from ..state.packing import Packing
from .counting import count_constraints, dofs_per_body, shape_model_of

__all__ = ["ZERO_EIGENVALUE_RTOL", "QUARTIC_PRESSURE_RATIO", "REGION_GAP_MIN_RATIO", "SPECTRUM_FORCE_RATIO",
           "FOURTH_DERIVATIVE_STEP", "FOURTH_AGREEMENT_RTOL", "FOURTH_TARGET_RTOL", "FOURTH_ROUNDOFF_RTOL",
           "FOURTH_STEP_STABILITY_RTOL", "contact_signature", "exact_line", "roundoff_of_form", "energy_quartic_fit",
           "fourth_derivative_step", "fourth_derivative_along", "Spectrum", "quartic_check", "spectrum"]

#: Eigenvalues with ``|lambda| <= ZERO_EIGENVALUE_RTOL * lambda_max`` are zero modes:
#: LAPACK's eigenvalues err by ``O(eps ||M||) ~ 1e-16 lambda_max``; 1e-13 leaves a
#: factor of ~500 for the round-off of M itself (complex-step entries to ~eps).
ZERO_EIGENVALUE_RTOL: float = 1e-13

#: Region-1 (quartic) eigenvalues are stress terms and vanish with the pressure: a gap
#: opens region 1 only when its lower edge is at most this many times the pressure
#: [k units]; region 2 does not scale with P
#: (measured: docs/notes/shapes.md#constants-of-the-spectrum-jamflowshapesspectrum).
QUARTIC_PRESSURE_RATIO: float = 1e3

#: A gap that separates regions 1 and 2 spans at least this factor in ``lambda``
#: (measured: docs/notes/shapes.md#constants-of-the-spectrum-jamflowshapesspectrum).
REGION_GAP_MIN_RATIO: float = 10.0

#: The spectrum's region 1 is trusted only when the largest generalised force of the
#: packing is at most this fraction of its pressure: quartic eigenvalues are ~P, and
#: residual forces shift them
#: (measured: docs/notes/shapes.md#constants-of-the-spectrum-jamflowshapesspectrum).
SPECTRUM_FORCE_RATIO: float = 1e-3

#: Largest step [length, or rad] of the second difference of ``v^T M v`` along a quartic
#: mode. Truncation is ``~ h^2 U^(6) / U^(4)``: measured 1e-4 relative at ``h = 1e-2`` on
#: the near-disk ellipse packings (``alpha - 1 = 1e-3``), whose fourth derivatives
#: (~1e-6 ... 1e-8 k, ``~ k (alpha - 1)^2``) need steps of 1e-4 ... 1e-2 above round-off.
FOURTH_DERIVATIVE_STEP: float = 1e-2

#: First step: at most this fraction of ``sqrt(delta_min)``, ``delta_min`` the smallest
#: pair overlap: along a quartic mode contact distances change at second order,
#: ``~ h^2``, so a step ``h^2 << delta_min`` opens no contact. With a fixed 1e-3 the
#: steps at P0 = 1e-7 (overlaps ~1e-7) broke contacts and gave fourth derivatives 1e3-1e5
#: times those of the same packing at P0 = 1e-6. Larger steps are taken only while the
#: contact network stays the same (:func:`contact_signature`).
FOURTH_STEP_OVERLAP_FRACTION: float = 0.1

#: Smallest first step: round-off ``~ eps ||M|| / h^2`` stays below ~1e-3 of ``||M||``.
FOURTH_DERIVATIVE_MIN_STEP: float = 1e-6

#: Two second differences of ``v^T M v`` (steps ``h`` and ``h / 2``) agree when they
#: differ by at most this fraction of the larger magnitude; the step grows (x4) until they
#: do. Smooth data at a step well above round-off agree to 1e-4 ... 1e-6 (measured on the
#: near-disk ellipses); a jump of ``M`` between samples changes the estimate by orders of
#: magnitude (8e5 against 9.7 on the vendored A = 1.3 packing).
FOURTH_TARGET_RTOL: float = 1e-3

#: Largest disagreement of the two steps accepted when no step reaches
#: :data:`FOURTH_TARGET_RTOL` inside the smooth window (else NaN).
FOURTH_AGREEMENT_RTOL: float = 0.05

#: A pair of second differences counts only when the round-off bound of the finer one,
#: ``4 eps_f / (h / 2)^2`` (``eps_f`` the measured round-off of ``v^T M v``,
#: :func:`roundoff_of_form`), is at most this fraction of it: near disks ``eps_f`` is 1e-9
#: ... 4e-8 of ``v^T M v`` and two round-off-dominated differences agreed to 1e-3 by
#: chance, 1 % off the converged value
#: (measured: docs/notes/shapes.md#fourth-derivatives-near-the-disk-limit).
FOURTH_ROUNDOFF_RTOL: float = 1e-3

#: Largest relative difference of two accepted estimates (e.g. from first steps ``h`` and
#: ``4 h``): each returns the coarser difference of a pair that agrees to
#: :data:`FOURTH_TARGET_RTOL`, so its truncation (``~ h^2``, 4/3 of the gap) is at most
#: ``4/3 FOURTH_TARGET_RTOL`` and its round-off at most ``FOURTH_ROUNDOFF_RTOL / 4``.
FOURTH_STEP_STABILITY_RTOL: float = 2.0 * (4.0 / 3.0 * FOURTH_TARGET_RTOL + FOURTH_ROUNDOFF_RTOL / 4.0)

#: Configurations one unit in the last place away from the base point (random signs,
#: this seed) whose spread of ``v^T M v`` is its round-off (:func:`roundoff_of_form`).
FOURTH_ROUNDOFF_SAMPLES: int = 8
FOURTH_ROUNDOFF_SEED: int = 0

#: Windows (dyadic, widest first) and odd number of points of :func:`energy_quartic_fit`:
#: the energy's round-off (~1e-22 k on the near-disk ellipses) enters the fitted ``U^(4)``
#: as ``~ 24 eps_U / w^4``: 1e-5 of it at ``w = 2^-6`` for ``alpha - 1 = 1e-4``, 1e-3 ... 3e-3 at
#: ``2^-8``; some modes open a contact within ``2^-6``
#: (measured: docs/notes/shapes.md#fourth-derivatives-near-the-disk-limit).
ENERGY_FIT_WIDTHS: tuple[float, ...] = (2.0**-6, 2.0**-7, 2.0**-8, 2.0**-9)
ENERGY_FIT_POINTS: int = 33


def fourth_derivative_step(min_overlap: float) -> float:
    """First step [length or rad] of the fourth derivative for a packing whose smallest overlap is ``min_overlap``."""
    return float(np.clip(FOURTH_STEP_OVERLAP_FRACTION * np.sqrt(max(min_overlap, 0.0)), FOURTH_DERIVATIVE_MIN_STEP,
                         1e-3))


def exact_line(q: NDArray[np.float64], v: NDArray[np.float64], h: float,
               max_step: float = FOURTH_DERIVATIVE_STEP) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``q``, ``v`` and ``h`` moved onto a dyadic grid on which every ``q + s v`` is exact.

    ``h`` becomes the power of two at or below it; ``q`` a multiple of ``g``, the unit in
    the last place of the largest coordinate any sample reaches (``|q| + 4 max_step |v|``);
    ``v`` a multiple of ``g / (h / 2)``. Then ``s v`` for ``s`` a multiple of ``h / 2`` and
    ``q + s v`` are exact: the samples of a second difference lie on one straight line.
    Rounded in floating point they stray from it by ~1 ulp of the coordinates, and
    ``v^T M v`` changes across the line (~1e-5 k per unit length on the near-disk
    ellipses) a million times faster than along a quartic mode, which made half of its
    round-off there. ``q`` moves by at most ``g / 2``, ``v`` by ``g / h`` (~2e-10 at
    ``h = 8e-6`` and coordinates below 8).

    Returns
    -------
    q, v : ndarray, shape (n_dof,)
    h : float
    """
    h = float(2.0 ** np.floor(np.log2(h)))
    reach = float(np.max(np.abs(q)) + 4.0 * max_step * np.max(np.abs(v)))
    grid = float(2.0 ** (np.ceil(np.log2(reach)) - 52))
    return np.round(q / grid) * grid, np.round(v * (0.5 * h) / grid) * (grid / (0.5 * h)), h


def roundoff_of_form(form: Callable[[NDArray[np.float64]], float], q: NDArray[np.float64]) -> float:
    """Round-off of ``form(q)`` [its units]: the largest change when every coordinate moves by one ulp.

    :data:`FOURTH_ROUNDOFF_SAMPLES` configurations with random signs
    (:data:`FOURTH_ROUNDOFF_SEED`): they hold the evaluation's round-off and the form's
    change under the rounding of a configuration. On the near-disk ellipses it is 3 to 7
    times the rms scatter of ``v^T M v`` on an :func:`exact_line` (1.3e-19 against
    2e-20 for one mode), so it errs on the side of larger steps.
    """
    rng = np.random.default_rng(FOURTH_ROUNDOFF_SEED)
    base = form(q)
    return max(abs(form(np.nextafter(q, np.where(rng.random(q.size) < 0.5, -np.inf, np.inf))) - base)
               for _ in range(FOURTH_ROUNDOFF_SAMPLES))


def contact_signature(model, q: NDArray[np.float64]) -> frozenset:
    """The contact network of a shape configuration as a set: its second derivatives are
    smooth while it does not change.

    One entry per energy term: circulo vertex-edge terms with whether the foot is clamped
    to an edge end (the kink of App. A's distance), Reuleaux and dumbbell point terms
    with their kind, ellipse pairs.
    """
    if model.family == "circulo":
        t = model.contact_terms(q)
        return frozenset(zip(t["i"], t["j"], t["vertex_body"], t["vertex"], t["edge"], t["t"] <= 0.0, t["t"] >= 1.0,
                             strict=True))
    if model.family in POINT_TERM_FAMILIES:
        t = model.point_terms(q)
        return frozenset(zip(t["i"], t["j"], t["type"], t["a"], t["b"], strict=True))
    t = model.pair_table(q)
    return frozenset(zip(t["i"], t["j"], strict=True))


@dataclass(frozen=True)
class Spectrum:
    """Eigenvalues and regions of a shape packing's dynamical matrix.

    Attributes
    ----------
    eigenvalue : ndarray, shape (3N,)
        Ascending [k] (energy / length^2 for translations).
    region : ndarray of int, shape (3N,)
        0, 1, 2 or 3 (module doc).
    rotational_weight : ndarray, shape (3N,)
        Weight of each unit eigenvector on the orientations.
    fourth_derivative : ndarray, shape (3N,)
        ``d^4 U / d s^4`` along region-1 modes (NaN elsewhere) [k].
    lambda_0, lambda_c : float
        Zero-mode floor and the region-1/2 cutoff.
    n_quartic : int
        ``N_1``, the number of region-1 eigenvalues.
    n_zero : int
        Number of region-0 eigenvalues.
    pressure : float
        Virial pressure of the packing [k].
    max_force : float
        Largest generalised force ``sqrt(F^2 + (tau / l)^2)`` of the packing [k length].
    """

    eigenvalue: NDArray[np.float64]
    region: NDArray[np.int64]
    rotational_weight: NDArray[np.float64]
    fourth_derivative: NDArray[np.float64]
    lambda_0: float
    lambda_c: float
    n_quartic: int
    n_zero: int
    pressure: float
    max_force: float

    @property
    def balanced(self) -> bool:
        """Whether the packing is force balanced well enough for region 1 (:data:`SPECTRUM_FORCE_RATIO`)."""
        return self.max_force <= SPECTRUM_FORCE_RATIO * self.pressure


def fourth_derivative_along(model, q: NDArray[np.float64], v: NDArray[np.float64], h: float,
                            signature: Callable[[NDArray[np.float64]], frozenset] | None = None,
                            max_step: float = FOURTH_DERIVATIVE_STEP) -> float:
    """``d^4 U / ds^4`` along the unit mode ``v`` at ``q``, or NaN [k].

    The second derivative of ``f(s) = v^T M(q + s v) v`` (``f(0)`` evaluated the same
    way, not the eigensolver's eigenvalue, whose error ~``eps ||M||`` would swamp a
    small fourth derivative) from samples at ``s = 0, +-h/2, +-h, +-2h``: central,
    right and left second differences at steps ``h`` and ``h / 2``; of those whose
    stencil keeps the contact network (``signature``, when given) the one where the two
    steps agree best. While they disagree by more than :data:`FOURTH_TARGET_RTOL` the
    step grows by 4 (a small fourth derivative, ``~ k (alpha - 1)^2`` near disks, needs
    a step far above the one that merely opens no contact), up to ``max_step`` or the
    step at which no stencil keeps the network. A jump of ``M`` (a contact opening or
    changing type between samples) spoils the stencils that straddle it, not the
    others. The samples lie exactly on the line (:func:`exact_line`, ``h`` rounded
    down to a power of two); a pair counts only where the round-off of ``f``
    (:func:`roundoff_of_form`) moves the finer difference by at most
    :data:`FOURTH_ROUNDOFF_RTOL` of it, so that two differences dominated by round-off
    cannot agree by chance.

    Parameters
    ----------
    model
        Anything with ``hessian(q)`` returning a sparse matrix.
    q : ndarray, shape (n_dof,)
    v : ndarray, shape (n_dof,)
        Unit mode.
    h : float
        First step [length or rad], from :func:`fourth_derivative_step`.
    signature : callable, optional
        ``q -> frozenset`` of the contact network (:func:`contact_signature`).
    max_step : float

    Returns
    -------
    float
        The estimate at the accepted step, or NaN when no smooth stencil above round-off agrees to
        :data:`FOURTH_AGREEMENT_RTOL`.
    """
    q, v, h = exact_line(q, v, h, max_step)
    reference = None if signature is None else signature(q)
    f: dict[float, float] = {}
    same: dict[float, bool] = {}

    def form(x: NDArray[np.float64]) -> float:
        return float(v @ (model.hessian(x) @ v))

    def sample(s: float) -> float:
        if s not in f:
            f[s] = form(q + s * v)
        return f[s]

    noise = roundoff_of_form(form, q)

    def smooth(*points: float) -> bool:
        for s in points:
            if s not in same:
                same[s] = reference is None or s == 0.0 or signature(q + s * v) == reference
        return all(same[s] for s in points)

    best, best_gap = np.nan, np.inf
    step = h
    while step <= max_step * (1.0 + 1e-12):
        found = False
        for sign, (a, b, c) in ((0, (-1.0, 0.0, 1.0)), (1, (0.0, 1.0, 2.0)), (-1, (0.0, -1.0, -2.0))):
            nodes = [x * step for x in (a, b, c)] + [0.5 * x * step for x in (a, b, c)]
            if not smooth(*nodes):
                continue
            found = True
            coarse = (sample(a * step) - 2.0 * sample(b * step) + sample(c * step)) / step**2
            fine = (sample(0.5 * a * step) - 2.0 * sample(0.5 * b * step) + sample(0.5 * c * step)) / (0.5 * step) ** 2
            if 4.0 * noise / (0.5 * step) ** 2 > FOURTH_ROUNDOFF_RTOL * abs(fine):
                continue
            gap = abs(coarse - fine) / max(abs(coarse), abs(fine), np.finfo(float).tiny)
            if gap < best_gap:
                best, best_gap = coarse, gap
            if sign == 0 and gap <= FOURTH_TARGET_RTOL:
                break
        if not found or best_gap <= FOURTH_TARGET_RTOL:
            break
        step *= 4.0
    return float(best) if best_gap <= FOURTH_AGREEMENT_RTOL else float("nan")


def energy_quartic_fit(model, q: NDArray[np.float64], v: NDArray[np.float64],
                       signature: Callable[[NDArray[np.float64]], frozenset],
                       widths: tuple[float, ...] = ENERGY_FIT_WIDTHS) -> tuple[float, float, float, float]:
    """``d^4 U / ds^4`` along ``v`` from the energy alone: a check independent of ``v^T M v``.

    A least-squares polynomial of degrees 1 ... 6 through ``U(q + s v) - U(q)`` at
    :data:`ENERGY_FIT_POINTS` points ``|s| <= w`` on an :func:`exact_line`, ``w`` the
    first of ``widths`` whose points all keep the contact network (``signature``);
    ``24`` times its ``s^4`` coefficient, with the standard error from the residual.

    Returns
    -------
    d4, d4_error : float
        [k]; NaN when every window changes the network.
    eigenvalue : float
        Twice the ``s^2`` coefficient [k].
    w : float
        The window [length or rad].
    """
    half = ENERGY_FIT_POINTS // 2
    design = np.vander(np.arange(-half, half + 1) / half, 7, increasing=True)[:, 1:]
    reference = signature(q)
    for w in widths:
        x, u, _ = exact_line(q, v, 2.0 * w / half, w)
        s = np.arange(-half, half + 1) * (w / half)
        if all(signature(x + t * u) == reference for t in s):
            energy = np.array([model.evaluate(x + t * u).energy for t in s]) - model.evaluate(x).energy
            coef, residual, *_ = np.linalg.lstsq(design, energy, rcond=None)
            sigma = np.sqrt(residual[0] / (s.size - design.shape[1]) * np.linalg.inv(design.T @ design)[3, 3])
            return 24.0 * coef[3] / w**4, 24.0 * sigma / w**4, 2.0 * coef[1] / w**2, w
    return float("nan"), float("nan"), float("nan"), float("nan")


def _auto_cutoff(lam: NDArray[np.float64], lambda_0: float, pressure: float) -> float:
    """``lambda_c`` from the widest admissible gap (module doc); ``lambda_0`` when there is none."""
    nonzero = lam[lam > lambda_0]
    low = nonzero[: max(2, nonzero.size // 2)]
    if low.size < 2:
        return float(lambda_0)
    gaps = np.diff(np.log(low))
    admissible = (low[:-1] <= QUARTIC_PRESSURE_RATIO * pressure) & (gaps >= np.log(REGION_GAP_MIN_RATIO))
    if not np.any(admissible):
        return float(lambda_0)
    k = int(np.argmax(np.where(admissible, gaps, -np.inf)))
    return float(np.sqrt(low[k] * low[k + 1]))


def spectrum(packing: Packing, lambda_c: float | None = None, fourth: bool = True) -> Spectrum:
    """Full spectrum of the dynamical matrix with regions and quartic modes (module doc).

    Bodies jammed with frozen orientations (Fig. 3a, :func:`~jamflow.shapes.counting.dofs_per_body`)
    have the ``2N x 2N`` translational block as their dynamical matrix.
    """
    model, q = shape_model_of(packing)
    n = model.n
    dofs = 2 * n if dofs_per_body(packing) == 2 else 3 * n
    hess = model.hessian(q).toarray()[:dofs, :dofs]
    lam, vec = np.linalg.eigh(hess)
    # dofs are centres first, then orientations
    rot = np.sum(vec[2 * n:] ** 2, axis=0)
    lambda_0 = ZERO_EIGENVALUE_RTOL * float(max(abs(lam[-1]), abs(lam[0])))
    ev = model.evaluate(q)
    pressure = pressure_of(ev, packing.box)
    if lambda_c is not None and not (np.isfinite(lambda_c) and lambda_c > 0.0):
        raise ValueError(f"--lambda-c must be positive and finite, got {lambda_c}")
    if lambda_c is None:
        if not lambda_0 > 0.0:
            raise ValueError("the dynamical matrix is zero: no body touches another (not a jammed packing)")
        lambda_c = _auto_cutoff(lam, lambda_0, pressure)
    region = np.where(np.abs(lam) <= lambda_0, 0, np.where(lam < lambda_c, 1, np.where(rot > 0.5, 2, 3)))
    d4 = np.full(lam.size, np.nan)
    if fourth:
        energy = model.pair_table(q)["energy"]
        # one harmonic term per pair: U = (k/2) delta^2 (the shallowest term of a pair bounds this from above)
        h = fourth_derivative_step(float(np.sqrt(2.0 * energy.min() / model.k)) if energy.size else 0.0)
        for k in np.flatnonzero(region == 1):
            v = np.zeros(q.size)
            v[:dofs] = vec[:, k]
            d4[k] = fourth_derivative_along(model, q, v, h, lambda x: contact_signature(model, x))
    return Spectrum(lam, region.astype(np.int64), rot, d4, lambda_0, float(lambda_c),
                    int(np.count_nonzero(region == 1)), int(np.count_nonzero(region == 0)), pressure,
                    # frozen orientations carry unbalanced torques by design: only the forces count
                    float(model.max_force(model.project(ev.gradient, q))))


def quartic_check(packing: Packing, spec: Spectrum) -> dict:
    """``N_c = N_c^0 - N_1`` (Sec. III B) with contacts counted once and twice.

    ``isostatic_count``, ``n_rattlers`` and ``n_sliders`` are those of the ``twice``
    count (every contact point, as the dynamical matrix sees them).
    """
    out = {}
    for mode in ("once", "twice"):
        c, *_ = count_constraints(packing, mode)
        out[f"n_contacts_{mode}"] = c.n_contacts
    out.update(isostatic_count=c.isostatic_count, n_rattlers=c.n_rattlers, n_sliders=c.n_sliders,
               isostatic_minus_quartic=c.isostatic_count - spec.n_quartic)
    return out
