"""Compiled fast path of the fixed-lag RTS smoother's backward sweeps
(:func:`trackkit.filters.smoothers.fixed_lag_sweeps`): the same equations, one compiled walk
per row instead of ``lag`` numpy passes over every row.

Rows are linked by ``nxt`` (the row that follows each one, -1 at the end of a chain). For
each row k the walk follows the links up to ``lag`` rows, to row ``k + m``, and runs the RTS
recursion back from the filtered estimate there,

    xs_{k+m} = x_{k+m},  Ps_{k+m} = P_{k+m}
    xs_i = x_i + G_i (xs_{i+1} - x-_{i+1})
    Ps_i = sym(P_i + (G_i (Ps_{i+1} - P-_{i+1})) G_i^T)      (sym(A) = (A + A^T) / 2)

in the order of :func:`trackkit.filters.smoothers.rts_update`, so that its results equal the
numpy sweeps' to rounding (``tests/test_fast_paths.py``). The work is the same, ``lag`` steps
a row; what goes is the numpy temporaries of ``lag`` passes over arrays of every row (on the
whole Solent recording, 150 000 rows of the five-state turn model, 20 steps: 1.7 s in numpy,
see ``benchmarks/RESULTS.md`` for the compiled figure). The state size n is compiled in, one
kernel per n (numba specialises on a tuple's length), so that the n x n loops unroll: 2.4
times faster than one kernel taking n from the arrays. numba compiles on first use and caches
the machine code beside this module (``cache=True``).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

__all__ = ["fixed_lag_kernel"]


def fixed_lag_kernel(x: Array, P: Array, pm: Array, pc: Array, G: Array,
                     nxt: NDArray[np.int64], lag: int) -> tuple[Array, Array]:
    """Each row smoothed back from the filtered estimate ``lag`` links later (or its chain's
    end): ``x (N, n)``, ``P (N, n, n)`` filtered; ``pm``, ``pc`` the one-step predictions
    and ``G`` the gains of each row with a successor (anything where ``nxt < 0``)."""
    c = np.ascontiguousarray  # one compiled layout
    return _walk(c(x), c(P), c(pm), c(pc), c(G), c(nxt), lag, (0,) * x.shape[1])


@numba.njit(cache=True, error_model="numpy")
def _walk(x, P, pm, pc, G, nxt, lag, size):  # noqa: ANN001, ANN202 - numba's types
    """:func:`fixed_lag_kernel`; ``size``, a tuple of n zeros, carries the state size n in
    its type, so that numba compiles one kernel per n with the n x n loops unrolled."""
    n = len(size)
    N = x.shape[0]
    xs, Ps = x.copy(), P.copy()
    chain = np.empty(lag + 1, np.int64)
    a, b = np.empty(n), np.empty(n)
    A, D, T, g = np.empty((n, n)), np.empty((n, n)), np.empty((n, n)), np.empty((n, n))
    for k in range(N):
        m, j = 0, k
        chain[0] = k
        while m < lag and nxt[j] >= 0:
            j = nxt[j]
            m += 1
            chain[m] = j
        if m == 0:
            continue
        a[:], A[:, :] = x[j], P[j]
        for i in range(m - 1, -1, -1):
            r = chain[i]
            g[:, :] = G[r]
            for p in range(n):
                b[p] = a[p] - pm[r, p]
                for q in range(n):
                    D[p, q] = A[p, q] - pc[r, p, q]
            for p in range(n):
                s = 0.0
                for q in range(n):
                    s += g[p, q] * b[q]
                a[p] = x[r, p] + s
                for q in range(n):
                    s = 0.0
                    for t in range(n):
                        s += g[p, t] * D[t, q]
                    T[p, q] = s
            # (T G^T)[p, q] and [q, p] summed in the same order: sym() of the product is
            # their mean, of which one triangle is computed and mirrored
            for p in range(n):
                for q in range(p, n):
                    s = 0.0
                    u = 0.0
                    for t in range(n):
                        s += T[p, t] * g[q, t]
                        u += T[q, t] * g[p, t]
                    A[p, q] = ((P[r, p, q] + s) + (P[r, q, p] + u)) * 0.5
                    A[q, p] = A[p, q]
        xs[k], Ps[k] = a, A
    return xs, Ps

