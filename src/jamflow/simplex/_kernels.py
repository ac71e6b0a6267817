"""Compiled loops of the warm simplex: triangular solves on SuperLU's factors, the
product-form (row eta) updates, the matrix-vector product of the ratio test, the
Harris ratio tests and Devex pricing.

Conventions (see :mod:`jamflow.simplex.factor`): SuperLU factorises ``Pr W Pc = L U``
with ``L`` unit lower triangular (CSC, diagonal first in each column) and ``U`` upper
triangular (CSC, diagonal last in each column; also kept as CSR, diagonal first in
each row, for the scatter form of ``U^T``). Every loop that scatters a column skips
zero entries, so a sparse right-hand side costs only its reach.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit


@njit(cache=True)
def lu_solve(Lp, Li, Lx, Up, Ui, Ux, perm_r, perm_c, b, x):
    """``x = W^-1 b`` with ``Pr W Pc = L U`` (``x`` may not alias ``b``)."""
    n = len(b)
    v = np.zeros(n)
    for i in range(n):
        v[perm_r[i]] = b[i]
    for j in range(n):  # L v = v, column scatter, diagonal (first entry) is one
        vj = v[j]
        if vj != 0.0:
            for k in range(Lp[j] + 1, Lp[j + 1]):
                v[Li[k]] -= Lx[k] * vj
    for j in range(n - 1, -1, -1):  # U v = v, column scatter backwards, diagonal last
        vj = v[j]
        if vj != 0.0:
            last = Up[j + 1] - 1
            vj /= Ux[last]
            v[j] = vj
            for k in range(Up[j], last):
                v[Ui[k]] -= Ux[k] * vj
    for i in range(n):
        x[i] = v[perm_c[i]]


@njit(cache=True)
def lu_solve_transposed(Lp, Li, Lx, Urp, Urj, Urx, perm_r, perm_c, c, y):
    """``y = W^-T c`` with ``Pr W Pc = L U``: ``U^T`` by rows of ``U`` (scatter,
    diagonal first in each row), then ``L^T`` by columns of ``L`` (gather)."""
    n = len(c)
    u = np.zeros(n)
    for i in range(n):
        u[perm_c[i]] = c[i]
    for i in range(n):
        ui = u[i]
        if ui != 0.0:
            first = Urp[i]
            ui /= Urx[first]
            u[i] = ui
            for k in range(first + 1, Urp[i + 1]):
                u[Urj[k]] -= Urx[k] * ui
    for j in range(n - 1, -1, -1):
        s = u[j]
        for k in range(Lp[j] + 1, Lp[j + 1]):
            s -= Lx[k] * u[Li[k]]
        u[j] = s
    for i in range(n):
        y[i] = u[perm_r[i]]


@njit(cache=True)
def eta_forward(eta_slot, eta_beta, count, x):
    """``x <- E_1^-1 ... E_count^-1 x`` (in place): the row etas of the product form,
    newest first. ``E`` is the identity with row ``p`` replaced by ``beta``; its inverse
    changes only ``x_p = (x_p - sum_{j != p} beta_j x_j) / beta_p``. A sparse ``x`` (the
    ``e_p`` of a pivot) keeps a list of its nonzeros, so each eta costs its length, not n."""
    n = len(x)
    nz = np.empty(n, dtype=np.int64)
    is_nz = np.zeros(n, dtype=np.bool_)
    m = 0
    for j in range(n):
        if x[j] != 0.0:
            nz[m] = j
            is_nz[j] = True
            m += 1
    sparse = m + count < n // 8
    for e in range(count - 1, -1, -1):
        p = eta_slot[e]
        beta = eta_beta[e]
        s = x[p]
        if sparse:
            for t in range(m):
                j = nz[t]
                if j != p:
                    s -= beta[j] * x[j]
        else:
            for j in range(n):
                if j != p:
                    s -= beta[j] * x[j]
        x[p] = s / beta[p]
        if sparse and not is_nz[p] and x[p] != 0.0:
            is_nz[p] = True
            nz[m] = p
            m += 1


@njit(cache=True)
def eta_backward(eta_slot, eta_beta, count, y):
    """``y <- E_count^-T ... E_1^-T y`` (in place), oldest first."""
    n = len(y)
    for e in range(count):
        p = eta_slot[e]
        beta = eta_beta[e]
        yp = y[p] / beta[p]
        if yp != 0.0:
            for j in range(n):
                y[j] -= beta[j] * yp
        y[p] = yp


@njit(cache=True)
def csr_matvec(indptr, indices, data, x, out):
    """``out = A x`` for ``A`` in CSR."""
    for i in range(len(indptr) - 1):
        s = 0.0
        for k in range(indptr[i], indptr[i + 1]):
            s += data[k] * x[indices[k]]
        out[i] = s


@njit(cache=True)
def primal_ratio(alpha, slack, row_slot, d, z, lower, upper, col_slot, tol, pivot_tol):
    """Harris's two-pass ratio test of the primal step ``z + t d``.

    Rows outside the working set (``row_slot < 0``) with ``alpha = a_i . d > pivot_tol``
    block at ``slack / alpha``; columns outside it (``col_slot < 0``) at the bound they
    move towards. Pass one finds the largest step that keeps every blocking constraint
    within ``tol`` of feasibility; pass two takes, among those reaching their bound by
    then, the one with the largest ``|alpha|`` (the most stable pivot).

    Returns ``(kind, index, step)``: kind 0 a row, 1 a column's lower bound, 2 its upper
    bound, -1 nothing blocks (``step = inf``).
    """
    t_max = np.inf
    for i in range(len(alpha)):
        a = alpha[i]
        if a > pivot_tol and row_slot[i] < 0:
            t_max = min(t_max, (slack[i] + tol) / a)
    for j in range(len(d)):
        dj = d[j]
        if col_slot[j] >= 0:
            continue
        if dj > pivot_tol and upper[j] < np.inf:
            t_max = min(t_max, (upper[j] - z[j] + tol) / dj)
        elif dj < -pivot_tol and lower[j] > -np.inf:
            t_max = min(t_max, (z[j] - lower[j] + tol) / -dj)
    if t_max == np.inf:
        return -1, -1, np.inf
    kind, index, best, step = -1, -1, 0.0, 0.0
    for i in range(len(alpha)):
        a = alpha[i]
        if a > pivot_tol and row_slot[i] < 0:
            t = slack[i] / a
            if t <= t_max and a > best:
                kind, index, best, step = 0, i, a, t
    for j in range(len(d)):
        dj = d[j]
        if col_slot[j] >= 0:
            continue
        if dj > pivot_tol and upper[j] < np.inf:
            t = (upper[j] - z[j]) / dj
            if t <= t_max and dj > best:
                kind, index, best, step = 2, j, dj, t
        elif dj < -pivot_tol and lower[j] > -np.inf:
            t = (z[j] - lower[j]) / -dj
            if t <= t_max and -dj > best:
                kind, index, best, step = 1, j, -dj, t
    return kind, index, max(step, 0.0)


@njit(cache=True)
def dual_infeasibility(y, side, out):
    """Each working-set member's dual infeasibility: a row or an upper bound needs
    ``y >= 0``, a lower bound ``y <= 0``, a free column held at a value ``y = 0``; a
    fixed column is never infeasible. ``side``: 1 upper (rows), -1 lower, 0 free, 2 fixed."""
    for k in range(len(y)):
        s = side[k]
        if s == 1:
            out[k] = max(-y[k], 0.0)
        elif s == -1:
            out[k] = max(y[k], 0.0)
        elif s == 0:
            out[k] = abs(y[k])
        else:
            out[k] = 0.0


@njit(cache=True)
def devex_price(infeas, weight, tol):
    """The member with the largest ``infeas^2 / weight`` above ``tol``, or -1."""
    best, pick = 0.0, -1
    for k in range(len(infeas)):
        f = infeas[k]
        if f > tol:
            score = f * f / weight[k]
            if score > best:
                best, pick = score, k
    return pick


@njit(cache=True)
def devex_update(weight, beta, p):
    """Devex reference weights after slot ``p`` pivoted with row ``beta = W^-T w_q``:
    ``w_k <- max(w_k, (beta_k / beta_p)^2 w_p)``, ``w_p <- max(w_p / beta_p^2, 1)``."""
    bp = beta[p]
    wp = weight[p]
    for k in range(len(weight)):
        if k != p:
            r = beta[k] / bp
            weight[k] = max(weight[k], r * r * wp)
    weight[p] = max(wp / (bp * bp), 1.0)


@njit(cache=True)
def dual_ratio(y, beta, rho, side, tol, pivot_tol):
    """Harris's two-pass ratio test of the dual step ``y - lam rho beta`` (``lam >= 0``):
    a row or upper-bound member blocks where ``rho beta_k > 0`` at ``y_k / (rho beta_k)``,
    a lower-bound member where ``rho beta_k < 0``, a free member at once; fixed members
    never. Returns the leaving slot (-1: none blocks) and ``lam``."""
    t_max = np.inf
    for k in range(len(y)):
        s = side[k]
        g = rho * beta[k]
        if s == 2 or abs(g) <= pivot_tol:
            continue
        if s == 0:
            t_max = min(t_max, tol / abs(g))
        elif s == 1 and g > 0.0:
            t_max = min(t_max, (y[k] + tol) / g)
        elif s == -1 and g < 0.0:
            t_max = min(t_max, (y[k] - tol) / g)
    if t_max == np.inf:
        return -1, np.inf
    pick, best, lam = -1, 0.0, 0.0
    for k in range(len(y)):
        s = side[k]
        g = rho * beta[k]
        if s == 2 or abs(g) <= pivot_tol:
            continue
        if s == 0:
            t = 0.0
        elif (s == 1 and g > 0.0) or (s == -1 and g < 0.0):
            t = y[k] / g
        else:
            continue
        if t <= t_max and abs(g) > best:
            pick, best, lam = k, abs(g), t
    return pick, max(lam, 0.0)


@njit(cache=True)
def most_violated(slack, row_slot, z, lower, upper, col_slot, tol):
    """The constraint outside the working set violated most, by more than ``tol``:
    ``(kind, index, violation)`` with kind 0 a row, 1 a column below its lower bound,
    2 above its upper bound, -1 none."""
    kind, index, worst = -1, -1, tol
    for i in range(len(slack)):
        if row_slot[i] < 0 and -slack[i] > worst:
            kind, index, worst = 0, i, -slack[i]
    for j in range(len(z)):
        if col_slot[j] >= 0:
            continue
        if lower[j] - z[j] > worst:
            kind, index, worst = 1, j, lower[j] - z[j]
        elif z[j] - upper[j] > worst:
            kind, index, worst = 2, j, z[j] - upper[j]
    return kind, index, worst


@njit(cache=True)
def sketch_update(p, beta, S, weight):
    """``S <- E^-T S`` for one row eta (slot ``p``, row ``beta``) applied to every column
    of the sketch ``S`` (n, m) (row ``p`` divided by ``beta_p``, then ``beta`` times it
    subtracted from every other row), and the weights ``|S_k|^2 / m`` of every row."""
    n, m = S.shape
    bp = beta[p]
    for c in range(m):
        S[p, c] /= bp
    for j in range(n):
        bj = beta[j]
        if j != p and bj != 0.0:
            for c in range(m):
                S[j, c] -= bj * S[p, c]
        w = 0.0
        for c in range(m):
            w += S[j, c] * S[j, c]
        weight[j] = max(w / m, 1e-300)
