"""The augmented EKF of ``trackkit.identify.augmented``, one compiled pass over the runs per
sample.

Why compiled: one sample of the EKF by blocks is about 1 100 multiply-adds per run, spread
over seven small batched matrix products (3 x 3, 3 x 16, 19 x 3, ...) and a dozen elementwise
passes. numpy pays 30-100 us per batched product of 1 000 small matrices whatever their size
(measured: ``(19 x 3)(3 x 19)`` 107 us, ``(3 x 3)(3 x 3)`` 33 us), which kept the numpy form
at 3-5 us per run-step, 10-16 times FilterPy's one run (``benchmarks/bench_vessel.py``). Here
the runs are the last, contiguous axis (``x (19, N)``, the covariance's lower triangle ``P
(190, N)``), each equation is a loop over the runs of a chunk that the compiler turns into
vector instructions, and a chunk's working set stays in cache.

The equations are ``trackkit.filters.EKF``'s on ``SampledVessel``, with ``F = [[A, B], [0,
I]]`` and ``H = [I3 0]`` written out (the generic filter is the textbook form this is pinned
to, ``tests/identify/test_fused.py``)::

    body', A, B  m Euler steps of h = dt / m from the model (eq. 2, ``prime_rates``,
                 ``prime_jacobian``, ``prime_terms``): A = A_(m-1) .. A_0,
                 B = sum_j A_(m-1) .. A_(j+1) B_j,  A_j = I + h D J' / scale,  B_j = h D Phi
    G    = [A B] P                                     (3 x 19, the top rows of F P)
    P-   = P with  P-_xt = G_t,  P-_xx = sym(G_x A^T + G_t B^T) + Q_x,  P-_tt = P_tt + Q_t
    x-   = [body', theta]
    S    = P-_xx + R = L L^T                          (Cholesky)
    W    = P-[:, :3] L^-T,   w = L^-1 (z - x-_body)    (forward substitution)
    x+   = x- + W w,   P+ = P- - W W^T,   NIS = w^T w

``P+ = P- - W W^T`` is ``P- - K S K^T`` with ``K = P- H^T S^-1``, the optimal-gain form: the
Joseph form of FilterPy and ``trackkit.filters.EKF`` in exact arithmetic, and symmetric by
construction, since only the lower triangle is kept. With one Euler step B keeps each body
equation to its own coefficients, and its structural zeros are skipped (``Plan.pairs``).

The model's equations are written once, in ``trackkit.models.manoeuvring``, and compiled here from
the same functions, so one step's prediction is the numpy model's bits. No sum is reordered
(no fastmath, so no FMA contraction) and each run is computed alone, so the bits do not depend
on the number of runs, the chunk or the CPU's vector width. The compiled code is cached beside
this file; numba keys that cache on this file only, so after editing the model's ``prime_*``
functions delete ``__pycache__/fused*.nbi`` (the tests that pin the kernel to the model fail
on a stale cache).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np

from trackkit.models.manoeuvring import (
    EQUATION,
    Normalisation,
    prime_jacobian,
    prime_rates,
    prime_terms,
)

Array = np.ndarray

#: Runs per chunk: the chunk's G, W and covariance rows stay in the 1 MB L2 of a core.
CHUNK = 256

N_STATE = 19
_I, _J = np.tril_indices(N_STATE)
#: ``TRI[i, j]``: the row of ``P (190, N)`` holding ``P_ij`` (either triangle).
TRI = np.zeros((N_STATE, N_STATE), np.int64)
TRI[_I, _J] = np.arange(_I.size)
TRI[_J, _I] = np.arange(_I.size)


def pack(P: Array) -> Array:
    """``(N, 19, 19)`` covariances to their lower triangles ``(190, N)``, runs last."""
    return np.ascontiguousarray(P[:, _I, _J].T)


def unpack(P2: Array) -> Array:
    """The inverse of ``pack``: ``(190, N)`` to ``(N, 19, 19)``."""
    return P2.T[:, TRI]


_rates = numba.njit(prime_rates)
_terms = numba.njit(prime_terms)
_jacobian = numba.njit(prime_jacobian)


# The kernel's pieces, each one equation. The per-run ones are inlined (``inline="always"``):
# called, the sub-step loop ran about 30% slower; inlining changes no operation, so no bit.
@numba.njit(nogil=True, error_model="numpy", inline="always")
def _model_at(b0, b1, b2, d, e, th, scale):  # pragma: no cover
    """The prime model at the body state ``b`` (SI) and the input ``(d, e)`` (rad, rpm): the
    Jacobian ``J'`` (9), the terms ``Phi`` (16) and the rates ``f`` (3)."""
    u, v, r, nn = b0 / scale[0], b1 / scale[0], b2 * scale[1], e / scale[2]
    return (_jacobian(u, v, r, d, nn, th), _terms(u, v, r, d, nn),
            _rates(u, v, r, d, nn, th))


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _transition(Aj, h, J, DS):  # pragma: no cover
    """``A_j = I + h D J' / scale`` into ``Aj (3, 3)``."""
    for i in range(3):
        for c in range(3):
            Aj[i, c] = (1.0 if i == c else 0.0) + h * (J[3 * i + c] * DS[i, c])


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _euler(b0, b1, b2, h, D, f):  # pragma: no cover
    """``body' = body + h D f``."""
    return b0 + h * (D[0] * f[0]), b1 + h * (D[1] * f[1]), b2 + h * (D[2] * f[2])


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _one_step(x, q, s0, s1, h, scale, DS, th, A, B, k):  # pragma: no cover
    """Run ``q``'s one Euler step of ``h`` with the mean input (eq. 4): returns ``body'``;
    ``A[:, :, k] = A_0`` and ``B[:, :, k] = B_0`` on its non-zero entries."""
    b0, b1, b2 = x[0, q], x[1, q], x[2, q]
    d, e = 0.5 * (s0[0, q] + s1[0, q]), 0.5 * (s0[1, q] + s1[1, q])
    J, t, f = _model_at(b0, b1, b2, d, e, th, scale)
    _transition(A[:, :, k], h, J, DS)
    D = scale[3:6]
    for c in range(th.size):
        B[EQUATION[c], c, k] = h * (t[c] * D[EQUATION[c]])
    return _euler(b0, b1, b2, h, D, f)


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _substep_input(s0, s1, sf, fine, q, j, m):  # pragma: no cover
    """Run ``q``'s input over sub-step ``j`` of ``m``: the mean of the measured inputs at its
    ends (``fine``), or the inputs interpolated to its middle."""
    if fine:
        return 0.5 * (sf[j, 0, q] + sf[j + 1, 0, q]), 0.5 * (sf[j, 1, q] + sf[j + 1, 1, q])
    f = (j + 0.5) / m
    return s0[0, q] + f * (s1[0, q] - s0[0, q]), s0[1, q] + f * (s1[1, q] - s0[1, q])


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _chain(Aj, Ak, Bk, T3, T16):  # pragma: no cover
    """``A <- A_j A``, ``B <- A_j B`` (``T3``, ``T16``: scratch)."""
    for i in range(3):
        for c in range(3):
            T3[i, c] = Aj[i, 0] * Ak[0, c] + Aj[i, 1] * Ak[1, c] + Aj[i, 2] * Ak[2, c]
        for c in range(Bk.shape[1]):
            T16[i, c] = Aj[i, 0] * Bk[0, c] + Aj[i, 1] * Bk[1, c] + Aj[i, 2] * Bk[2, c]
    Ak[:, :] = T3
    Bk[:, :] = T16


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _substeps(x, q, s0, s1, sf, fine, m, h, scale, DS, th, Ak, Bk, Aj, T3,
              T16):  # pragma: no cover
    """Run ``q``'s ``m`` Euler steps of ``h``: returns ``body'``; ``Ak = A_(m-1) .. A_0`` and
    ``Bk = sum_j A_(m-1) .. A_(j+1) B_j`` (``Aj``, ``T3``, ``T16``: scratch)."""
    b0, b1, b2 = x[0, q], x[1, q], x[2, q]
    D = scale[3:6]
    for j in range(m):
        d, e = _substep_input(s0, s1, sf, fine, q, j, m)
        J, t, f = _model_at(b0, b1, b2, d, e, th, scale)
        _transition(Aj, h, J, DS)
        if j == 0:
            Ak[:, :] = Aj
            Bk[:, :] = 0.0
        else:
            _chain(Aj, Ak, Bk, T3, T16)
        for c in range(th.size):
            Bk[EQUATION[c], c] += h * (t[c] * D[EQUATION[c]])
        b0, b1, b2 = _euler(b0, b1, b2, h, D, f)
    return b0, b1, b2


@numba.njit(nogil=True, error_model="numpy")
def _model(x, s0, s1, sf, fine, m, h, scale, DS, c0, c1, A, B, body):  # pragma: no cover
    """The model, run by run over ``c0:c1``: ``body'`` into ``body (3, chunk)`` and the
    Jacobian's blocks into ``A (3, 3, chunk)`` and ``B (3, 16, chunk)``."""
    n = x.shape[0]
    th = np.empty(n - 3)  # a run's coefficients, contiguous
    Ak = np.empty((3, 3))  # a run's A and B over its sub-steps
    Bk = np.empty((3, n - 3))
    Aj = np.empty((3, 3))
    T3 = np.empty((3, 3))
    T16 = np.empty((3, n - 3))
    for k in range(c1 - c0):
        q = c0 + k
        for c in range(n - 3):
            th[c] = x[3 + c, q]
        if m == 1:
            b0, b1, b2 = _one_step(x, q, s0, s1, h, scale, DS, th, A, B, k)
        else:
            b0, b1, b2 = _substeps(x, q, s0, s1, sf, fine, m, h, scale, DS, th, Ak, Bk, Aj,
                                   T3, T16)
            for i in range(3):
                for c in range(3):
                    A[i, c, k] = Ak[i, c]
                for c in range(n - 3):
                    B[i, c, k] = Bk[i, c]
        body[0, k], body[1, k], body[2, k] = b0, b1, b2


@numba.njit(nogil=True, error_model="numpy")
def _top_rows(G, A, B, P, pairs, c0, c1):  # pragma: no cover
    """``G = [A B] P``, the top rows of ``F P``, over the runs ``c0:c1``."""
    M = c1 - c0
    for i in range(3):
        for j in range(G.shape[1]):
            g = G[i, j, :M]
            g[:] = 0.0
            for c in range(3):
                a = A[i, c, :M]
                p = P[TRI[c, j], c0:c1]
                for k in range(M):
                    g[k] += a[k] * p[k]
            for q in range(pairs.shape[0]):
                if pairs[q, 0] == i:
                    c = pairs[q, 1]
                    b = B[i, c, :M]
                    p = P[TRI[3 + c, j], c0:c1]
                    for k in range(M):
                        g[k] += b[k] * p[k]


@numba.njit(nogil=True, error_model="numpy")
def _predict_covariance(P, G, A, B, X, pairs, Qd, c0, c1):  # pragma: no cover
    """``X = G_x A^T + G_t B^T``; ``P-_xx = (X + X^T) / 2 + Q_x``, ``P-_tx = G_t^T``,
    ``P-_tt = P_tt + Q_t``, in place over the runs ``c0:c1``."""
    M = c1 - c0
    n = G.shape[1]
    for i in range(3):
        for j in range(3):
            xx = X[i, j, :M]
            xx[:] = 0.0
            for c in range(3):
                g = G[i, c, :M]
                a = A[j, c, :M]
                for k in range(M):
                    xx[k] += g[k] * a[k]
            for q in range(pairs.shape[0]):
                if pairs[q, 0] == j:
                    c = pairs[q, 1]
                    g = G[i, 3 + c, :M]
                    b = B[j, c, :M]
                    for k in range(M):
                        xx[k] += g[k] * b[k]
    for i in range(3):
        for j in range(i + 1):
            p = P[TRI[i, j], c0:c1]
            xij = X[i, j, :M]
            xji = X[j, i, :M]
            for k in range(M):
                p[k] = 0.5 * (xij[k] + xji[k])
        p = P[TRI[i, i], c0:c1]
        for k in range(M):
            p[k] += Qd[i]
        for j in range(3, n):
            P[TRI[j, i], c0:c1] = G[i, j, :M]
    for j in range(3, n):
        p = P[TRI[j, j], c0:c1]
        for k in range(M):
            p[k] += Qd[j]


@numba.njit(nogil=True, error_model="numpy")
def _innovation(P, R, z, x, L, w, nis, c0, c1):  # pragma: no cover
    """``S = L L^T`` and ``w = L^-1 (z - x_body)``, run by run over ``c0:c1``, into ``L (6,
    chunk)`` (its diagonal inverted) and ``w (3, chunk)``; the NIS ``w^T w`` into ``nis``.
    A missing measurement (or an S that is not positive definite, counted and returned)
    gives ``W = 0`` and ``w = 0``: P and x stay predicted."""
    bad = 0
    for k in range(c1 - c0):
        r = c0 + k
        s00 = P[TRI[0, 0], r] + R[0, 0]
        d1 = P[TRI[1, 1], r] + R[1, 1]
        d2 = P[TRI[2, 2], r] + R[2, 2]
        l00 = math.sqrt(s00)
        l10 = (P[TRI[1, 0], r] + R[1, 0]) / l00
        l20 = (P[TRI[2, 0], r] + R[2, 0]) / l00
        d1 = d1 - l10 * l10
        l11 = math.sqrt(d1)
        l21 = (P[TRI[2, 1], r] + R[2, 1] - l20 * l10) / l11
        d2 = d2 - l20 * l20 - l21 * l21
        l22 = math.sqrt(d2)
        missing = math.isnan(z[0, r]) or math.isnan(z[1, r]) or math.isnan(z[2, r])
        if not missing and not (s00 > 0.0 and d1 > 0.0 and d2 > 0.0):
            bad += 1
            missing = True
        if missing:
            nis[r] = math.nan
            l00 = l11 = l22 = math.inf  # 1 / inf = 0: W's rows vanish below
            l10 = l20 = l21 = 0.0
            w[0, k] = w[1, k] = w[2, k] = 0.0
        else:
            w0 = (z[0, r] - x[0, r]) / l00
            w1 = (z[1, r] - x[1, r] - l10 * w0) / l11
            w2 = (z[2, r] - x[2, r] - l20 * w0 - l21 * w1) / l22
            w[0, k] = w0
            w[1, k] = w1
            w[2, k] = w2
            nis[r] = w0 * w0 + w1 * w1 + w2 * w2
        L[0, k] = 1.0 / l00
        L[1, k] = l10
        L[2, k] = l20
        L[3, k] = 1.0 / l11
        L[4, k] = l21
        L[5, k] = 1.0 / l22
    return bad


@numba.njit(nogil=True, error_model="numpy")
def _gain(P, x, W, L, w, c0, c1):  # pragma: no cover
    """``W = P-[:, :3] L^-T`` by forward substitution along each row (L's diagonal stored
    inverted: three divisions per run instead of 57); ``x+ = x- + W w``."""
    M = c1 - c0
    i00, l10, l20 = L[0, :M], L[1, :M], L[2, :M]
    i11, l21, i22 = L[3, :M], L[4, :M], L[5, :M]
    w0, w1, w2 = w[0, :M], w[1, :M], w[2, :M]
    for i in range(x.shape[0]):
        p0 = P[TRI[i, 0], c0:c1]
        p1 = P[TRI[i, 1], c0:c1]
        p2 = P[TRI[i, 2], c0:c1]
        W0 = W[0, i, :M]
        W1 = W[1, i, :M]
        W2 = W[2, i, :M]
        xi = x[i, c0:c1]
        for k in range(M):
            a = p0[k] * i00[k]
            b = (p1[k] - l10[k] * a) * i11[k]
            c = (p2[k] - l20[k] * a - l21[k] * b) * i22[k]
            W0[k] = a
            W1[k] = b
            W2[k] = c
            xi[k] += a * w0[k] + b * w1[k] + c * w2[k]


@numba.njit(nogil=True, error_model="numpy")
def _downdate(P, W, c0, c1):  # pragma: no cover
    """``P+ = P- - W W^T`` on the lower triangle, over the runs ``c0:c1``."""
    M = c1 - c0
    for i in range(W.shape[1]):
        a0 = W[0, i, :M]
        a1 = W[1, i, :M]
        a2 = W[2, i, :M]
        for j in range(i + 1):
            b0 = W[0, j, :M]
            b1 = W[1, j, :M]
            b2 = W[2, j, :M]
            p = P[TRI[i, j], c0:c1]
            for k in range(M):
                p[k] -= a0[k] * b0[k] + a1[k] * b1[k] + a2[k] * b2[k]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _step(x, P, s0, s1, sf, fine, m, h, scale, DS, pairs, Qd, z, R, nis,
          chunk):  # pragma: no cover
    """One predict-update of every run, chunk by chunk (the module docstring's equations);
    returns the number of runs whose S is not positive definite."""
    n, N = x.shape
    A = np.empty((3, 3, chunk))
    B = np.empty((3, n - 3, chunk))
    G = np.empty((3, n, chunk))
    W = np.empty((3, n, chunk))
    X = np.empty((3, 3, chunk))
    L = np.empty((6, chunk))
    w = np.empty((3, chunk))
    bad = 0
    for c0 in range(0, N, chunk):
        c1 = min(N, c0 + chunk)
        # the body states' prediction (in L) is written after G, which needs the prior P only
        _model(x, s0, s1, sf, fine, m, h, scale, DS, c0, c1, A, B, L)
        _top_rows(G, A, B, P, pairs, c0, c1)
        x[:3, c0:c1] = L[:3, :c1 - c0]
        _predict_covariance(P, G, A, B, X, pairs, Qd, c0, c1)
        bad += _innovation(P, R, z, x, L, w, nis, c0, c1)
        _gain(P, x, W, L, w, c0, c1)
        _downdate(P, W, c0, c1)
    return bad


_NO_SUB = np.zeros((1, 2, 1))  # the kernel's sf when the inputs are interpolated


class Plan(NamedTuple):
    """What the kernel needs of the model, computed once per identification: ``substeps``
    ``m``, ``h = dt / m``, ``scale = [U0, L / U0, n0, D1, D2, D3]``, ``DS = D_i / scale_j`` and
    the ``(row, coefficient)`` entries of B that can be non-zero."""

    m: int
    h: float
    scale: Array
    DS: Array
    pairs: Array


def plan(norm: Normalisation, substeps: int, dt: float) -> Plan:
    """The kernel's constants for prime system ``norm``, ``substeps`` Euler steps per sample
    period ``dt``."""
    m = int(substeps)
    # one step keeps each body equation to its own coefficients; more mix them through A
    pairs = (np.stack([EQUATION, np.arange(EQUATION.size)], -1) if m == 1 else
             np.argwhere(np.ones((3, EQUATION.size), bool)))
    return Plan(m, dt / m, np.array([norm.speed, norm.length / norm.speed, norm.rpm,
                                    *norm.rate_scale]),
                norm.rate_scale[:, None] / norm.state_scale[None, :], pairs.astype(np.int64))


def predict_update(x: Array, P: Array, s_prev: Array, s_next: Array, plan: Plan, Qd: Array,
                   z: Array, R: Array, s_sub: Array | None = None) -> Array:
    """One predict-update of the augmented EKF for ``N`` runs, in place, runs last: ``x (19,
    N)`` and the packed covariance ``P (190, N)`` (``pack``) become the posterior. The
    prediction takes ``plan.m`` Euler steps from the inputs ``s_prev`` to ``s_next`` (each
    ``(2, N)``; ``augmented.SampledVessel``; for one step the mean input of eq. 4), or, with
    ``s_sub (m + 1, 2, N)``, the inputs at the sub-steps' ends (each sub-step their mean); ``Qd
    (19,)`` are the per-sample noise variances, ``z (3, N)`` the measurements (nan where
    missing), ``R (3, 3)``. Returns the NIS ``(N,)`` (nan where missing); raises if an
    innovation covariance is not positive definite."""
    nis = np.empty(x.shape[1])
    fine = s_sub is not None and plan.m > 1
    if fine and s_sub.shape != (plan.m + 1,) + s_prev.shape:
        raise ValueError(f"s_sub has shape {s_sub.shape}; expected {(plan.m + 1,) + s_prev.shape}")
    sf = s_sub if fine else _NO_SUB
    bad = _step(x, P, s_prev, s_next, sf, fine, plan.m, plan.h, plan.scale, plan.DS,
                plan.pairs, Qd, z, R, nis, CHUNK)
    if bad:
        raise ValueError("innovation covariance S = P_xx + R is not positive definite in "
                         f"{bad} run(s); expected SPD 3 x 3 matrices")
    return nis


def step_is_compiled() -> bool:
    """Whether numba's on-disk cache beside this module holds the compiled filter step already
    (the first run compiles it, some seconds); True when this numba keeps its cache elsewhere,
    so that nobody is told to wait for nothing."""
    try:
        return Path(_step._cache._cache_file._index_path).is_file()
    except AttributeError:
        return True
