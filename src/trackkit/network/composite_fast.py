"""Compiled composite measurement (``trackkit.network.composite``): the damped Gauss-Newton fit
of every row, its Cramer-Rao bound and its status in one compiled loop over the rows.

The numpy form (``composite._fit_numpy``) iterates all rows together: each step is some 60
array operations on rows of 4 to 20 numbers, and a network agent's fits are a few rows at a
time (three on average in a ``net-baseline`` block), so its cost is the calls, about a
millisecond a fit. Here each row runs the same iteration on its own, with the same equations
in the same order:

    r_k = wrap(z_k - h(F(t_k, t_f) X, S(t_k))) / sigma_k,   A_k = H_k / sigma_k
    lambda = 1/2 sum_k r_k^2,   J = sum_k A_k A_k^T,   g = sum_k A_k r_k
    (J + mu diag(J)) delta = g  by Cholesky; keep X + delta if lambda falls
    stop when mu = mu_min and g^T delta <= max(tol^2, the rounding floor of lambda)
    R_c = D^-1/2 J_s^-1 D^-1/2,  J_s = D^-1/2 J D^-1/2,  D = diag(J)

A missing bearing is skipped (the numpy form adds its exact zeros), so a row's numbers do
not depend on how many slots it has or which rows share its call. The sums run over the
bearings in order; numpy's ``einsum`` may fuse their multiply-adds, so the two forms agree to
rounding, not bit for bit (``tests/network/test_composite_fast.py``: 1e-12 relative on
observable geometry). No fastmath, so no FMA contraction and no reordered sum: the bits do
not depend on the CPU the kernel is compiled for (the same test compiles it for plain x86-64
and for AVX2). The kernel is used for every call, one row or thousands: its cost per row
does not depend on the batch, and one path keeps a run's fits the same whatever runs it is
stepped with. numba compiles it on first use and caches the machine code beside this module
(``cache=True``).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from trackkit.filters.imm_fast import wrap_angle

__all__ = ["CONVERGED", "MU_MAX", "MU_MIN", "MU_REFUSED", "NOT_CONVERGED", "ROUND", "SINGULAR",
           "fit"]

Array = NDArray[np.float64]

#: least damping, relative to J_s's unit diagonal: keeps J_s + mu I positive definite when
#: J_s is singular to rounding, and changes a Gauss-Newton step by about 1e-12 relative
MU_MIN = 1e-12
#: damping after the first refused step (then ten times more per refusal)
MU_REFUSED = 1e-3
#: a row whose damping passes this has no downhill step left: it stops
MU_MAX = 1e10
#: rounding error of one residual z_k - h_k (rad): atan2's last place near pi, and the
#: subtraction's
ROUND = 4.0 * float(np.spacing(np.pi))

#: The Gauss-Newton decrement ``g^T J^{-1} g`` fell to ``tol**2`` or below (or to the rounding
#: floor of lambda): the estimate is at the maximum of the likelihood to a small fraction of
#: its own standard deviation.
CONVERGED = 0
#: ``max_iter`` steps were spent, or no step could lower lambda any more (mu above 1e10),
#: before the decrement test passed; ``mean`` is the last iterate.
NOT_CONVERGED = 1
#: J at the last iterate is rank-deficient or ill-conditioned (the reciprocal condition number
#: of the unit-diagonal J_s below ``rcond``, or J not finite), or the row has fewer than 4
#: bearings: the geometry does not observe the state (e.g. one sensor that does not manoeuvre).
#: ``cov`` is nan; ``mean`` is the last iterate (x0 for fewer than 4 bearings).
SINGULAR = 2


@numba.njit(cache=True, error_model="numpy")
def _normal(X: Array, z: Array, dt: Array, xs: Array, ys: Array, w: Array,
            present: NDArray[np.bool_], n: int, sign: float, J: Array, g: Array) -> float:
    """lambda of row n at X (4,), with J (4, 4) and g (4,) written in place."""
    J[:] = 0.0
    g[:] = 0.0
    cost = 0.0
    A = np.empty(4)
    for k in range(z.shape[0]):
        if not present[k, n]:
            continue
        d = dt[k, n]
        u = d * X[2] + X[0] - xs[k, n]
        v = d * X[3] + X[1] - ys[k, n]
        h = math.atan2(u, v) if sign > 0 else math.atan2(v, u)
        r = wrap_angle(z[k, n] - h) * w[k, n]
        q = w[k, n] / (u * u + v * v)  # 1 / (sigma_k r^2); inf for a target on a sensor
        if sign > 0:
            A[0], A[1] = v * q, u * -q  # eqs. 30-31, whitened
        else:
            A[1], A[0] = u * q, v * -q
        A[2], A[3] = A[0] * d, A[1] * d  # eqs. 32-33
        cost += r * r
        for i in range(4):
            g[i] += A[i] * r
            for j in range(4):
                J[i, j] += A[i] * A[j]
    return 0.5 * cost


@numba.njit(cache=True, error_model="numpy")
def _cholesky(P: Array, L: Array) -> bool:
    """L L^T = P (4 x 4), the lower triangle of L; whether every pivot is > 0."""
    good = True
    for i in range(4):
        for j in range(i + 1):
            acc = P[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = math.sqrt(acc) if i == j else acc / L[j, j]
        good = good and L[i, i] > 0  # false for nan
    return good


@numba.njit(cache=True, error_model="numpy")
def _substitute(L: Array, b: Array, x: Array) -> None:
    """x = (L L^T)^-1 b by forward and back substitution."""
    for i in range(4):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * x[k]
        x[i] = acc / L[i, i]
    for i in range(3, -1, -1):
        acc = x[i]
        for k in range(i + 1, 4):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]


@numba.njit(cache=True, error_model="numpy")
def _trace(J: Array) -> float:
    return J[0, 0] + J[1, 1] + J[2, 2] + J[3, 3]


@numba.njit(cache=True, error_model="numpy")
def _iterate(X: Array, z: Array, dt: Array, xs: Array, ys: Array, w: Array,
             present: NDArray[np.bool_], n: int, sign: float, max_iter: int, tol: float,
             J: Array) -> tuple[float, int, int]:
    """The damped Gauss-Newton iteration of row n from X (in place); J (4, 4) is left at
    the last linearisation point. Returns lambda there, the status and the steps."""
    g, delta, Xt, gt = np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    Jd, Jt, L = np.empty((4, 4)), np.empty((4, 4)), np.zeros((4, 4))
    cost = _normal(X, z, dt, xs, ys, w, present, n, sign, J, g)
    count = 0
    w2 = 0.0
    for k in range(z.shape[0]):
        if present[k, n]:
            count += 1
            w2 += w[k, n] * w[k, n]
    if count < 4 or not (np.isfinite(cost) and np.isfinite(_trace(J))):
        return cost, NOT_CONVERGED, 0
    mu, it = MU_MIN, 0
    for _ in range(max_iter):
        Jd[:] = J
        for i in range(4):
            Jd[i, i] *= 1.0 + mu
        if _cholesky(Jd, L):
            _substitute(L, g, delta)
        else:
            delta[:] = np.nan
        decrement = ((g[0] * delta[0] + g[1] * delta[1]) + g[2] * delta[2]) + g[3] * delta[3]
        floor = max(tol * tol, 2.0 * ROUND * math.sqrt(2.0 * cost * w2))
        if mu <= MU_MIN and decrement <= floor:
            for i in range(4):
                X[i] += delta[i]
            return cost, CONVERGED, it + 1
        for i in range(4):
            Xt[i] = X[i] + delta[i]
        ct = _normal(Xt, z, dt, xs, ys, w, present, n, sign, Jt, gt)
        it += 1
        if np.isfinite(_trace(Jt)) and np.isfinite(ct) and ct < cost:
            X[:] = Xt
            J[:] = Jt
            g[:] = gt
            cost, mu = ct, MU_MIN
        else:
            mu = max(10.0 * mu, MU_REFUSED)
            if mu > MU_MAX:
                break
    return cost, NOT_CONVERGED, it


@numba.njit(cache=True, error_model="numpy")
def _bound(J: Array, rcond: float, cov: Array) -> bool:
    """cov = J^-1 through the unit-diagonal J_s; whether J_s's reciprocal condition
    estimate 1 / (tr J_s max_i (J_s^-1)_ii) is at least rcond (false for nan)."""
    s = np.empty(4)
    for i in range(4):
        s[i] = 1.0 / math.sqrt(J[i, i] if J[i, i] > 0 else 1.0)
    Js, L, inv, e, col = (np.empty((4, 4)), np.zeros((4, 4)), np.empty((4, 4)), np.zeros(4),
                          np.empty(4))
    for i in range(4):
        for j in range(4):
            Js[i, j] = J[i, j] * s[i] * s[j]
    if _cholesky(Js, L):
        for j in range(4):
            e[:] = 0.0
            e[j] = 1.0
            _substitute(L, e, col)
            inv[:, j] = col
    else:
        inv[:] = np.nan
    biggest = -math.inf
    for i in range(4):
        if math.isnan(inv[i, i]):  # nan propagates, as in numpy's max
            biggest = math.nan
            break
        biggest = max(biggest, inv[i, i])
    rc = 1.0 / (_trace(Js) * biggest)
    for i in range(4):
        for j in range(4):
            cov[i, j] = inv[i, j] * s[i] * s[j]
    for i in range(4):
        for j in range(i):
            cov[i, j] = cov[j, i] = (cov[i, j] + cov[j, i]) * 0.5
    return rc >= rcond


@numba.njit(cache=True, error_model="numpy")
def _fit(z: Array, dt: Array, xs: Array, ys: Array, w: Array, present: NDArray[np.bool_],
         sign: float, X0: Array, max_iter: int, tol: float, rcond: float,
         mean: Array, cov: Array, J: Array, status: NDArray[np.int8],
         iterations: NDArray[np.int64], cost: Array) -> None:
    X = np.empty(4)
    for n in range(X0.shape[1]):
        X[:] = X0[:, n]
        c, st, it = _iterate(X, z, dt, xs, ys, w, present, n, sign, max_iter, tol, J[n])
        mean[n] = X
        cost[n], iterations[n] = c, it
        count = 0
        for k in range(z.shape[0]):
            if present[k, n]:
                count += 1
        well = _bound(J[n], rcond, cov[n]) and count >= 4
        status[n] = st if well else SINGULAR
        if not well:
            cov[n] = np.nan


def fit(z: Array, dt: Array, xs: Array, ys: Array, w: Array, pad: Array | None, sign: float,
        X: Array, max_iter: int, tol: float, rcond: float
        ) -> tuple[Array, Array, Array, NDArray[np.int8], NDArray[np.int64], Array]:
    """The composite of each of N rows from the bearings ``(M, N)`` of ``composite._prepare``
    (``pad`` 1.0 where a bearing is missing, None when none is) and the start ``X (4, N)``:
    ``mean (N, 4)``, ``cov (N, 4, 4)`` (nan where singular), ``information (N, 4, 4)``,
    ``status (N,)`` int8, ``iterations (N,)`` and ``cost (N,)``, as ``Composite``."""
    N = X.shape[1]
    present = np.ones(z.shape, dtype=bool) if pad is None else pad == 0.0
    mean, cov, J = np.empty((N, 4)), np.empty((N, 4, 4)), np.empty((N, 4, 4))
    status, iterations, cost = (np.empty(N, np.int8), np.empty(N, np.int64), np.empty(N))
    _fit(z, dt, xs, ys, w, present, float(sign), X, int(max_iter), float(tol), float(rcond),
         mean, cov, J, status, iterations, cost)
    return mean, cov, J, status, iterations, cost
