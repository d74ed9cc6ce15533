"""Exact discretisation of linear time-invariant continuous models (Van Loan, 1978)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

__all__ = ["discretize"]


def discretize(
    A: ArrayLike, L: ArrayLike, Qc: ArrayLike, dt: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Discretise ``dx/dt = A x + L w``, ``E[w w^T] = Qc delta(t - s)``, over a step ``dt``.

    Van Loan: with ``M = [[-A, L Qc L^T], [0, A^T]] dt`` and ``expm(M) = [[., G12], [0, G22]]``,
    ``F = G22^T`` and ``Q = F G12``. ``dt`` may be an array; F and Q then get its shape as
    leading axes.
    """
    A = np.asarray(A, dtype=float)
    L = np.asarray(L, dtype=float)
    Qc = np.atleast_2d(np.asarray(Qc, dtype=float))
    n = A.shape[-1]
    if A.shape != (n, n):
        raise ValueError(f"A has shape {A.shape}; expected a square matrix (n, n)")
    if L.ndim != 2 or L.shape[0] != n or Qc.shape != (L.shape[1], L.shape[1]):
        raise ValueError(
            f"L has shape {L.shape} and Qc {Qc.shape}; expected L ({n}, s) and Qc (s, s)"
        )
    dt = np.asarray(dt, dtype=float)
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = L @ Qc @ L.T
    M[n:, n:] = A.T
    G = expm(M * dt[..., None, None])
    F = np.swapaxes(G[..., n:, n:], -1, -2)
    Q = F @ G[..., :n, n:]
    return F, 0.5 * (Q + np.swapaxes(Q, -1, -2))
