"""The instantaneous contact network: the operator S, N = S S^T, forces and velocities.

Lerner, Düring & Wyart, Sec. II. For contacts ``c = (i, j)`` with separation
``R_c = x_j - x_i`` (the periodic image fixed by an integer lattice vector ``m_c``,
``R_c = x_j - x_i + h m_c``) and unit vector ``n_c``, ``S`` maps particle velocities
(length ``N d``) to the rates of change of contact distances (Eq. 1–3):
``(S V)_c = n_c . (V_j - V_i)``. Contact forces act on particles through ``S^T``
(Eq. 8).

With an imposed velocity-gradient tensor ``E`` (affine field ``V_aff = E x``) and
external forces ``F_ext``, overdamped force balance with drag ``-(V - V_aff)/xi0``
(Eqs. 5, 14) and rigid contacts ``S V = 0`` (Eq. 4) give

    N f = -(S V_aff / xi0 + S F_ext)              (Eqs. 11, 18)
    V   = V_aff + xi0 (F_ext + S^T f)             (Eqs. 9, 16)

which reduce to Eqs. 11–12 (forces only) and 18–19 (deformation only). Units: xi0 = 1
and rate 1 unless given; lengths in units of lambda.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from ..network import ContactSet, contact_jacobian

__all__ = [
    "FactorCache",
    "SingularNetworkError",
    "Solution",
    "TriangularFactor",
    "affine_rates",
    "pair_vectors",
    "pair_velocities",
    "s_matrix",
    "solve_network",
    "spectral_norm",
    "stress_tensor",
]


class SingularNetworkError(RuntimeError):
    """``N = S S^T`` is singular: the network carries a self-stress (potentially jammed)."""


def pair_vectors(
    x: NDArray[np.float64], h: NDArray[np.float64], pairs: NDArray[np.int64], images: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Separations ``x_j - x_i + h m`` of pairs with fixed periodic images.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Particle centres [lambda] (not necessarily wrapped).
    h : ndarray, shape (d, d)
        Box lattice matrix (columns = lattice vectors) [lambda].
    pairs : ndarray of int64, shape (P, 2)
        Pairs ``(i, j)``.
    images : ndarray of int64, shape (P, d)
        Lattice vector ``m`` of the image of j seen from i.

    Returns
    -------
    ndarray, shape (P, d)
    """
    return x[pairs[:, 1]] - x[pairs[:, 0]] + images @ h.T


def s_matrix(pairs: NDArray[np.int64], unit: NDArray[np.float64], n: int) -> sp.csr_matrix:
    """The operator ``S = d r_ij / d R_k`` (Eq. 2), sparse, shape (Nc, N d).

    Parameters
    ----------
    pairs : ndarray of int64, shape (Nc, 2)
    unit : ndarray, shape (Nc, d)
        Unit vectors ``n_ij`` from i to j.
    n : int
        Number of particles.
    """
    # the separations enter only strain columns, which S does not have
    return contact_jacobian(ContactSet(pairs[:, 0], pairs[:, 1], unit, unit), n, unit.shape[1])


@functools.lru_cache(maxsize=64)
def _spectral_norm(data: bytes, d: int) -> float:
    return float(np.linalg.norm(np.frombuffer(data).reshape(d, d), 2))


def spectral_norm(E: NDArray[np.float64]) -> float:
    """Largest singular value ``|E|_2`` of a (d, d) velocity gradient [1/time].

    Memoised on the matrix: the integrator asks several times per step for the same
    (or one of a few) gradients, and an SVD costs more than the rest of the query.
    """
    E = np.ascontiguousarray(E, dtype=np.float64)
    return _spectral_norm(E.tobytes(), E.shape[0])


def affine_rates(R: NDArray[np.float64], gradient: NDArray[np.float64]) -> NDArray[np.float64]:
    """``S V_aff`` for contacts with separations R: ``n . E R`` (Eq. 13), shape (Nc,)."""
    r = np.linalg.norm(R, axis=1)
    return np.einsum("ck,kl,cl->c", R, gradient, R) / r


@dataclass(frozen=True)
class Solution:
    """Contact forces and particle velocities on one contact network.

    Attributes
    ----------
    force : ndarray, shape (Nc,)
        Contact forces [lambda gamma_dot / xi0]; positive = repulsive.
    velocity : ndarray, shape (N, d)
        Non-affine velocity ``V - E x`` [lambda gamma_dot]; the full velocity of
        particle i is ``gradient @ x_i + velocity[i]``.
    gradient : ndarray, shape (d, d)
        Velocity-gradient tensor E of the affine flow (box: ``dh/dt = E h``).
    kappa : float
        Compression-to-shear rate ratio of fixed-pressure shear (Eq. 25); NaN otherwise.
    """

    force: NDArray[np.float64]
    velocity: NDArray[np.float64]
    gradient: NDArray[np.float64]
    kappa: float


@numba.njit(cache=True)
def _s_apply(pairs, unit, v):  # pragma: no cover - numba
    """``S v`` for a flat velocity ``v`` (length N d), shape (Nc,)."""
    nc, d = unit.shape
    out = np.empty(nc)
    for c in range(nc):
        i = pairs[c, 0] * d
        j = pairs[c, 1] * d
        s = 0.0
        for a in range(d):
            s += unit[c, a] * (v[j + a] - v[i + a])
        out[c] = s
    return out


@numba.njit(cache=True)
def _st_apply(pairs, unit, f, n):  # pragma: no cover - numba
    """``S^T f`` for contact forces ``f`` (Nc,), flat shape (N d,)."""
    nc, d = unit.shape
    out = np.zeros(n * d)
    for c in range(nc):
        i = pairs[c, 0] * d
        j = pairs[c, 1] * d
        for a in range(d):
            out[i + a] -= unit[c, a] * f[c]
            out[j + a] += unit[c, a] * f[c]
    return out


@dataclass
class FactorCache:
    """A factorisation of ``N = S S^T`` kept for later solves on the same contact network.

    Between events the network is fixed and its geometry drifts slowly, so the LU of
    N at an earlier geometry is an excellent preconditioner: conjugate gradients on
    the current N (the paper solves Eq. 11 by CG), warm-started from the last
    solution, converge in a few iterations. A cache only ever changes *how* a
    solution is computed, not which network is solved; callers reset it at points
    from which a run can be resumed, so a resumed run repeats the same solves.

    Attributes
    ----------
    rtol : float
        CG stops when the preconditioned residual ``|M^-1 r|_inf`` (≈ the error of
        the solution when M ≈ N) is below ``rtol |f|_inf``.
    max_iter : int
        Iterations after which CG gives up and N is refactorised directly.
    max_changes : int
        A network that differs from the factorised one by at most this many added plus
        removed pairs (the candidates of the rewiring after a collision) is solved by CG
        with a bordered preconditioner built from the cached LU (:func:`_bordered`).
    key : bytes or None
        Identity of the factorised network (its pairs).
    codes : ndarray of int64 or None
        Pair codes ``i N + j`` of the factorised network, in its order.
    lu : TriangularFactor or None
    guesses : list of ndarray
        Last solutions per right-hand side (warm starts), on the pairs ``guess_codes``.
    guess_codes : ndarray of int64 or None
    guess_time : float or None
        Time of the state ``guesses`` were solved at (None when the caller gave none).
    history : tuple or None
        The solutions before ``guesses`` as ``(codes, time, solutions)``: on an unchanged
        network the warm start is the linear extrapolation in time of the last two
        solutions (the forces vary smoothly between events), which saves CG iterations.
    bordered : dict
        Bordered preconditioners built on the current factorisation, by network (pair
        codes as bytes): the network after an event is solved at every step until the
        next factorisation, and its set-up (|P| + |Q| solves) is done once. A
        preconditioner built at an earlier geometry of the same network is still an
        approximate inverse; CG converges to the same tolerance on the current one.
    iterations : int
        CG iterations of the last cached solve (diagnostic).
    n_factor, n_cg, n_bordered : int
        Counts of direct factorisations, of CG solves, and of those CG solves on a
        changed network (diagnostic).
    """

    rtol: float = 1e-13
    max_iter: int = 8
    max_changes: int = 4
    key: bytes | None = None
    codes: NDArray[np.int64] | None = None
    lu: Any = None
    guesses: list = field(default_factory=list)
    guess_codes: NDArray[np.int64] | None = None
    guess_time: float | None = None
    history: tuple | None = None
    bordered: dict = field(default_factory=dict)
    iterations: int = 0
    n_factor: int = 0
    n_cg: int = 0
    n_bordered: int = 0

    def reset(self) -> None:
        """Forget the factorisation (the next solve factorises from scratch)."""
        self.key, self.codes, self.lu, self.guesses, self.guess_codes = None, None, None, [], None
        self.guess_time, self.history, self.bordered = None, None, {}

    def remember(self, codes: NDArray[np.int64], solutions: list[NDArray[np.float64]], time: float | None) -> None:
        """Keep the solutions of a solve as the next warm start (and the last ones as history)."""
        if self.guess_codes is not None and len(self.guesses) == len(solutions):
            self.history = (self.guess_codes, self.guess_time, self.guesses)
        self.guesses, self.guess_codes, self.guess_time = solutions, codes, time

    def warm_starts(self, codes: NDArray[np.int64], count: int, time: float | None = None) -> list[NDArray[np.float64]]:
        """Initial guesses for a solve on the pairs ``codes`` at ``time``.

        The last solutions, linearly extrapolated in time from the two before when
        both were on the same network at known distinct times, else carried over as
        they are to the pairs ``codes`` (zero on new pairs).
        """
        m = len(codes)
        if self.guess_codes is None or len(self.guesses) < count:
            return [np.zeros(m) for _ in range(count)]
        if np.array_equal(self.guess_codes, codes):
            h = self.history
            if (time is not None and self.guess_time is not None and h is not None and h[1] is not None
                    and h[1] != self.guess_time and len(h[2]) >= count and np.array_equal(h[0], codes)):
                w = (time - self.guess_time) / (self.guess_time - h[1])
                return [g1 + w * (g1 - g0) for g0, g1 in zip(h[2][:count], self.guesses[:count])]
            return self.guesses[:count]
        pos = _locate(self.guess_codes, codes)
        out = []
        for g in self.guesses[:count]:
            x0 = np.zeros(m)
            x0[pos >= 0] = g[pos[pos >= 0]]
            out.append(x0)
        return out


def _network_key(pairs: NDArray[np.int64], n: int) -> bytes:
    return np.int64(n).tobytes() + np.ascontiguousarray(pairs, dtype=np.int64).tobytes()


def _locate(codes_from: NDArray[np.int64], codes_to: NDArray[np.int64]) -> NDArray[np.int64]:
    """Position in ``codes_from`` of every entry of ``codes_to`` (-1 where absent)."""
    if len(codes_from) == 0:
        return np.full(len(codes_to), -1, dtype=np.int64)
    order = np.argsort(codes_from, kind="stable")
    srt = codes_from[order]
    loc = np.minimum(np.searchsorted(srt, codes_to), len(srt) - 1)
    return np.where(srt[loc] == codes_to, order[loc], -1)


def _bordered(lu, old_codes, codes, pairs, unit, n, cond_limit, max_changes):
    """Preconditioner for N on a network a few pairs away from the factorised one, or None.

    With C the kept pairs, Q the removed and P the added ones, it applies the exact
    inverse of ``[[M_CC, N_CP], [N_PC, N_PP]]``: ``M_CC^-1`` from the cached LU of M by
    the capacitance trick (solve with M, then cancel the Q components with
    ``(M^-1)_QQ``, |Q| extra solves once), the added pairs by their Schur complement
    ``T = N_PP - N_PC M_CC^-1 N_CP`` (current geometry, |P| solves once). A Schur
    complement below ``diag(N_PP) / cond_limit`` means an added pair is (nearly)
    dependent on the others — a possible self-stress — and returns None so that the
    caller factorises directly with its singularity checks.
    """
    pos = _locate(old_codes, codes)
    C = np.flatnonzero(pos >= 0)
    P = np.flatnonzero(pos < 0)
    kept = np.zeros(len(old_codes), dtype=bool)
    kept[pos[C]] = True
    Q = np.flatnonzero(~kept)
    if len(P) + len(Q) > max_changes or len(C) == 0:
        return None
    pos_c = pos[C]
    if len(Q):
        E = np.zeros((len(old_codes), len(Q)))
        E[Q, np.arange(len(Q))] = 1.0
        W = lu.solve(E)
        # small dense |Q| x |Q| (and below |P| x |P|) inverses, applied at every CG iteration
        WQQ_inv = np.linalg.inv(W[Q])

    def solve_cc(g):
        G = np.zeros((len(old_codes),) + g.shape[1:])
        G[pos_c] = g
        y = lu.solve(G)
        if len(Q):
            y = y - W @ (WQQ_inv @ y[Q])
        return y[pos_c]

    if len(P):
        cols = np.empty((len(codes), len(P)))
        for a, k in enumerate(P):
            e = np.zeros(len(codes))
            e[k] = 1.0
            cols[:, a] = _s_apply(pairs, unit, _st_apply(pairs, unit, e, n))
        NCP, NPP = cols[C], cols[P]
        B = solve_cc(NCP)
        T = NPP - NCP.T @ B
        if np.any(np.diag(T) <= np.diag(NPP) / cond_limit):
            return None
        T_inv = np.linalg.inv(T)

    def apply(g):
        out = np.empty(len(codes))
        a = solve_cc(g[C])
        if len(P):
            xp = T_inv @ (g[P] - NCP.T @ a)
            out[P] = xp
            out[C] = a - B @ xp
        else:
            out[C] = a
        return out

    return apply


def _pcg(pairs, unit, n, precond, b, x0, rtol, max_iter):
    """Conjugate gradients on ``N x = b`` with preconditioner ``precond(r) ≈ N^-1 r``.

    Returns (x, iterations), or (None, max_iter) without convergence. Converged when
    ``|M^-1 r|_inf <= rtol |x|_inf``: with M close to N the preconditioned residual
    estimates the error ``N^-1 r`` of x itself.
    """
    x = x0.copy()
    r = b - _s_apply(pairs, unit, _st_apply(pairs, unit, x, n))
    z = precond(r)
    p = z.copy()
    rz = float(r @ z)
    for it in range(max_iter + 1):
        if np.max(np.abs(z), initial=0.0) <= rtol * np.max(np.abs(x), initial=0.0):
            return x, it
        if it == max_iter or not rz > 0.0:
            break
        q = _s_apply(pairs, unit, _st_apply(pairs, unit, p, n))
        pq = float(p @ q)
        if not pq > 0.0:
            break
        alpha = rz / pq
        x += alpha * p
        r -= alpha * q
        z = precond(r)
        rz_new = float(r @ z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return None, max_iter


@numba.njit(cache=True)
def _triangular_solve(Lp, Li, Lx, Up, Ui, Ux, udiag, perm_r, perm_c, b):  # pragma: no cover - numba
    """``x`` with ``A x = b`` from ``Pr A Pc = L U`` (L unit lower, U upper; CSC, off-diagonal parts)."""
    n = b.shape[0]
    y = np.empty(n)
    for k in range(n):
        y[perm_r[k]] = b[k]
    for j in range(n):
        yj = y[j]
        for p in range(Lp[j], Lp[j + 1]):
            y[Li[p]] -= Lx[p] * yj
    for j in range(n - 1, -1, -1):
        yj = y[j] / udiag[j]
        y[j] = yj
        for p in range(Up[j], Up[j + 1]):
            y[Ui[p]] -= Ux[p] * yj
    x = np.empty(n)
    for k in range(n):
        x[k] = y[perm_c[k]]
    return x


class TriangularFactor:
    """The triangular factors of a SuperLU factorisation, solved by compiled substitution.

    SuperLU's own ``solve`` costs several times a plain forward and backward
    substitution for the small, very sparse N of a contact network (per-call and
    per-supernode overhead), and the cached factor is applied a few times per step.
    Same factors, so the same solution to round-off.

    Parameters
    ----------
    lu : scipy.sparse.linalg.SuperLU
        ``Pr A Pc = L U`` with unit-diagonal L.
    """

    def __init__(self, lu) -> None:
        L = sp.tril(lu.L, -1, format="csc")
        U = lu.U.tocsc()
        udiag = U.diagonal()
        U = sp.triu(U, 1, format="csc")
        self._args = (
            L.indptr.astype(np.int64), L.indices.astype(np.int64), L.data,
            U.indptr.astype(np.int64), U.indices.astype(np.int64), U.data, udiag,
            lu.perm_r.astype(np.int64), lu.perm_c.astype(np.int64),
        )
        self.shape = lu.shape

    def solve(self, b: NDArray[np.float64]) -> NDArray[np.float64]:
        """``N^-1 b`` for b of shape (n,) or (n, k)."""
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 1:
            return _triangular_solve(*self._args, np.ascontiguousarray(b))
        out = np.empty(b.shape)
        for k in range(b.shape[1]):
            out[:, k] = _triangular_solve(*self._args, np.ascontiguousarray(b[:, k]))
        return out


def _factorize(S: sp.csr_matrix, cond_limit: float, check_pivots: bool = True):
    """Sparse LU of N = S S^T with an explicit singularity check.

    A self-stress makes N exactly singular in exact arithmetic; in floating point its
    smallest pivot is round-off. With ``check_pivots``, a ratio of the smallest to the
    largest |U_kk| below ``1 / cond_limit`` is treated as singular (extracting U costs
    about as much as the factorisation, so callers skip it far from jamming).
    """
    Nmat = (S @ S.T).tocsc()
    try:
        # N is symmetric positive (semi)definite: diagonal pivots, and SymmetricMode keeps
        # the row order equal to the column order (same fill, several times faster)
        lu = spla.splu(Nmat, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularNetworkError(str(exc)) from exc
    if check_pivots:
        piv = np.abs(lu.U.diagonal())
        if piv.size and piv.min() < piv.max() / cond_limit:
            raise SingularNetworkError(f"N = S S^T nearly singular (pivot ratio {piv.min() / piv.max():.3g})")
    return lu


def solve_network(
    x: NDArray[np.float64],
    h: NDArray[np.float64],
    pairs: NDArray[np.int64],
    images: NDArray[np.int64],
    gradient: NDArray[np.float64],
    external: NDArray[np.float64] | None = None,
    xi0: float = 1.0,
    pressure: float | None = None,
    rate: float = 1.0,
    cond_limit: float = 1e13,
    check_pivots: bool = True,
    cache: FactorCache | None = None,
    time: float | None = None,
    separations: NDArray[np.float64] | None = None,
) -> Solution:
    """Forces and velocities of a contact network (Eqs. 11–12, 18–19, 23–25).

    Parameters
    ----------
    x, h, pairs, images
        See :func:`pair_vectors`; ``pairs`` is the contact network (Nc, 2).
    gradient : ndarray, shape (d, d)
        Imposed velocity gradient E [1/time]; for fixed pressure, the shear part
        ``rate * e_0 e_1^T`` only (the compression ``-kappa * rate * I`` is solved for).
    external : ndarray, shape (N, d), optional
        External forces [lambda gamma_dot / xi0].
    xi0 : float
        Mobility (velocity per force).
    pressure : float, optional
        Imposed pressure p (Eq. 24) [force / lambda^(d-1)]: fixed-pressure shear.
    rate : float
        Shear rate gamma_dot (fixed-pressure mode only).
    cond_limit : float
        Pivot ratio of N beyond which the network counts as singular.
    check_pivots : bool
        Check the pivots (else only an exactly singular factor or a solution whose
        residual exceeds ``1e-8`` relative is reported singular).
    cache : FactorCache, optional
        Reuse of an earlier factorisation as a CG preconditioner, on the same network
        or on one at most ``cache.max_changes`` pairs away (bordered preconditioner);
        only when ``check_pivots`` is False: near potential jamming every solve is a
        fresh factorisation with its pivot check. CG that does not converge within
        ``cache.max_iter`` iterations falls back to the direct solve, which refreshes
        the cache.
    time : float, optional
        Time of the state (any monotonic clock of the caller): lets the cache
        extrapolate its warm starts in time. Never changes which network is solved.
    separations : ndarray, shape (Nc, d), optional
        ``pair_vectors(x, h, pairs, images)`` if the caller has them already.

    Raises
    ------
    SingularNetworkError
        When N is singular (a self-stress exists); see :mod:`.jamming`.
    """
    n, d = x.shape
    nc = len(pairs)
    ext = np.zeros((n, d)) if external is None else external
    if nc == 0:
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
        if pressure is not None:
            # without contacts no pressure can be carried and Eq. 25 is undefined: the
            # gas is sheared at fixed volume (kappa = 0) until the first collision
            kappa = 0.0
        return Solution(np.zeros(0), xi0 * ext.copy(), E, kappa)
    R = pair_vectors(x, h, pairs, images) if separations is None else separations
    r = np.linalg.norm(R, axis=1)
    unit = R / r[:, None]
    pairs = np.ascontiguousarray(pairs, dtype=np.int64)
    rhs = -(affine_rates(R, gradient) / xi0 + _s_apply(pairs, unit, np.ascontiguousarray(ext, dtype=np.float64).ravel()))
    rhs_list = [rhs] if pressure is None else [rhs, rate * r / xi0]
    sols = None
    key = _network_key(pairs, n) if cache is not None else None
    codes = pairs[:, 0] * n + pairs[:, 1]
    if cache is not None and not check_pivots and cache.lu is not None:
        same = cache.key == key
        if same:
            precond = cache.lu.solve
        elif key in cache.bordered:
            precond = cache.bordered[key]
        else:
            precond = cache.bordered[key] = _bordered(
                cache.lu, cache.codes, codes, pairs, unit, n, cond_limit, cache.max_changes)
        if precond is not None:
            sols = []
            for b, x0 in zip(rhs_list, cache.warm_starts(codes, len(rhs_list), time)):
                xk, it = _pcg(pairs, unit, n, precond, b, x0, cache.rtol, cache.max_iter)
                if xk is None:
                    sols = None
                    break
                cache.iterations = it
                sols.append(xk)
            if sols is not None:
                cache.n_cg += 1
                cache.n_bordered += not same
    if sols is None:
        S = s_matrix(pairs, unit, n)
        lu = _factorize(S, cond_limit, check_pivots)
        sols = [lu.solve(b) for b in rhs_list]
        if not check_pivots:
            f = sols[0]
            res = np.linalg.norm(S @ (S.T @ f) - rhs)
            if not np.all(np.isfinite(f)) or res > 1e-8 * max(np.linalg.norm(rhs), 1e-300):
                raise SingularNetworkError(f"N = S S^T solve inaccurate (relative residual {res / max(np.linalg.norm(rhs), 1e-300):.3g})")
        if cache is not None:
            cache.key, cache.codes, cache.lu, cache.iterations = key, codes, TriangularFactor(lu), 0
            cache.bordered = {}
            cache.n_factor += 1
    if cache is not None:
        cache.remember(codes, sols, time)
    if pressure is None:
        f = sols[0]
        E = np.array(gradient, dtype=np.float64)
        kappa = np.nan
    else:
        # E = gradient - kappa * rate * I:  f = a + kappa * b with N b = rate r / xi0
        a, b = sols
        omega = abs(np.linalg.det(h))
        kappa = float((pressure * omega * d - a @ r) / (b @ r))
        f = a + kappa * b
        E = np.array(gradient, dtype=np.float64) - kappa * rate * np.eye(d)
    U = xi0 * (ext.ravel() + _st_apply(pairs, unit, f, n))
    return Solution(f, U.reshape(n, d), E, kappa)


def pair_velocities(
    R: NDArray[np.float64], pairs: NDArray[np.int64], sol: Solution
) -> NDArray[np.float64]:
    """Rates ``dr_ij/dt = n_ij . (V_j - V_i)`` (Eq. 26) of pairs with separations R, shape (P,)."""
    r = np.linalg.norm(R, axis=1)
    dU = sol.velocity[pairs[:, 1]] - sol.velocity[pairs[:, 0]]
    return (np.einsum("pk,pk->p", R, dU) + np.einsum("pk,kl,pl->p", R, sol.gradient, R)) / r


def stress_tensor(R: NDArray[np.float64], force: NDArray[np.float64], volume: float) -> NDArray[np.float64]:
    """Contact stress ``Sigma_ab = (1/Omega) sum_c f_c R_a R_b / r`` (positive = compressive), shape (d, d).

    Pressure (Eq. 24) is ``trace / d``; the shear stress of Eq. 30 is ``-Sigma_01``.
    """
    r = np.linalg.norm(R, axis=1)
    return np.einsum("c,ca,cb->ab", force / r, R, R) / volume
