r"""Fixed-interval smoothing: Rauch-Tung-Striebel for every filter in trackkit.

With the filter's one-step prediction :math:`\mathbf{x}^-_{k+1}, P^-_{k+1}` from
:math:`(\mathbf{x}_k, P_k)` and the cross-covariance
:math:`C_k = \operatorname{Cov}(\mathbf{x}_k, \mathbf{x}_{k+1})` (:math:`P_k F^\top` for
KF/EKF, the sigma-point sum for UKF/CKF, which makes this the unscented RTS smoother of
Sarkka 2008), the smoothed :math:`\mathbf{x}^s_k, P^s_k` are, backwards from the last step:

.. math::

    G_k &= C_k \bigl(P^-_{k+1}\bigr)^{-1} \\
    \mathbf{x}^s_k &= \mathbf{x}_k + G_k \bigl(\mathbf{x}^s_{k+1} - \mathbf{x}^-_{k+1}\bigr) \\
    P^s_k &= P_k + G_k \bigl(P^s_{k+1} - P^-_{k+1}\bigr) G_k^\top
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from trackkit.belief import Gaussian
from trackkit.filters.base import Filter, check_belief, register
from trackkit.linalg import solve_psd, symmetrize
from trackkit.models.protocols import MotionModel

__all__ = ["SWEEP_KERNEL_MIN_ROWS", "fixed_lag_sweeps", "rts_gain", "rts_step", "rts_update",
           "smooth"]

#: from this many rows the fixed-lag sweeps run compiled (``smoothers_fast``). Warm, the
#: compiled walk is faster at every size measured (lag 20, five states: 16x at 30 rows, 4x at
#: 10 000, 2.7x at 150 000), so it takes every batch; the numpy passes of :func:`rts_update`
#: below it are the textbook form that ``tests/test_fast_paths.py`` pins it to
SWEEP_KERNEL_MIN_ROWS = 0


def smooth(f: Filter, filtered: Gaussian, motion: MotionModel | Sequence[MotionModel],
           dt: ArrayLike | Sequence[float]) -> Gaussian:
    """RTS-smooth a filtered sequence whose mean is ``(T, ..., n)`` and cov ``(T, ..., n, n)``.

    ``dt`` is one step length, or ``T - 1`` of them (``dt[k]`` from step k to k + 1).
    ``motion`` may also be a sequence of ``T - 1`` models. Returns the smoothed sequence.
    """
    x, P = check_belief(filtered, getattr(motion, "dim_x", None), "smooth filtered")
    T = x.shape[0]
    if x.ndim < 2:
        raise ValueError(f"smooth filtered.mean has shape {x.shape}; expected (T, ..., n)")
    dts = np.broadcast_to(np.asarray(dt, dtype=float), (T - 1,) + np.shape(dt)[1:]) if (
        np.ndim(dt) == 0) else np.asarray(dt, dtype=float)
    if dts.shape[0] != T - 1:
        raise ValueError(f"smooth dt has {dts.shape[0]} steps; expected T - 1 = {T - 1}")
    motions = list(motion) if isinstance(motion, Sequence) else [motion] * (T - 1)
    if len(motions) != T - 1:
        raise ValueError(f"smooth motion has {len(motions)} models; expected T - 1 = {T - 1}")
    xs, Ps = np.empty_like(x), np.empty_like(P)
    xs[-1], Ps[-1] = x[-1], P[-1]
    for k in range(T - 2, -1, -1):
        xs[k], Ps[k] = rts_step(f, x[k], P[k], xs[k + 1], Ps[k + 1], motions[k], dts[k])
    return Gaussian._make((xs, register(Ps)))


def rts_gain(f: Filter, x: np.ndarray, P: np.ndarray, motion: MotionModel, dt: ArrayLike
             ) -> tuple[Gaussian, np.ndarray]:
    """The one-step prediction ``x-_{k+1}, P-_{k+1}`` of the filtered ``(x_k, P_k)`` and the
    smoother gain ``G_k = C_k (P-_{k+1})^{-1}`` (module docstring), batched."""
    pred, C = f.predict_with_cross(Gaussian._make((x, register(P))), motion, dt)
    G = np.swapaxes(solve_psd(pred.cov, np.swapaxes(C, -1, -2), "predicted covariance"),
                    -1, -2)
    return pred, G


def rts_update(x: np.ndarray, P: np.ndarray, pred: Gaussian, G: np.ndarray,
               xs_next: np.ndarray, Ps_next: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``xs_k = x_k + G_k (xs_{k+1} - x-_{k+1})``, ``Ps_k = P_k + G_k (Ps_{k+1} - P-_{k+1})
    G_k^T``, batched."""
    xs = x + (G @ (xs_next - pred.mean)[..., None])[..., 0]
    Ps = symmetrize(P + G @ (Ps_next - pred.cov) @ np.swapaxes(G, -1, -2))
    return xs, Ps


def rts_step(f: Filter, x: np.ndarray, P: np.ndarray, xs_next: np.ndarray,
             Ps_next: np.ndarray, motion: MotionModel, dt: ArrayLike
             ) -> tuple[np.ndarray, np.ndarray]:
    """One backward step (module docstring), batched: the filtered ``x_k (..., n)``,
    ``P_k (..., n, n)`` and the smoothed ``xs_{k+1}``, ``Ps_{k+1}`` give ``(xs_k, Ps_k)``."""
    pred, G = rts_gain(f, x, P, motion, dt)
    return rts_update(x, P, pred, G, xs_next, Ps_next)


def fixed_lag_sweeps(x: np.ndarray, P: np.ndarray, pred: Gaussian, G: np.ndarray,
                     nxt: np.ndarray, lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-lag RTS over rows linked by ``nxt`` (the next row of each, -1 at a chain's
    end): each row smoothed back from the filtered estimate ``lag`` links later (or its
    chain's end). ``pred`` and ``G`` are :func:`rts_gain`'s for every row (read only where
    ``nxt >= 0``). With the gains of one pass, ``lag`` sweeps of

        xs_k <- x_k + G_k (xs_{k+1} - x-_{k+1})      (xs = x at first)

    over every row at once leave in row k the recursion unrolled over k+1 .. k+lag. From
    ``SWEEP_KERNEL_MIN_ROWS`` rows the compiled walk of ``smoothers_fast`` does the same."""
    if lag < 1:
        raise ValueError(f"lag = {lag!r}; expected a number of scans >= 1")
    nxt = np.asarray(nxt, np.int64)
    if x.shape[0] >= SWEEP_KERNEL_MIN_ROWS:
        from trackkit.filters.smoothers_fast import fixed_lag_kernel
        return fixed_lag_kernel(x, P, pred.mean, pred.cov, G, nxt, int(lag))
    rows = np.flatnonzero(nxt >= 0)
    after = nxt[rows]
    step = Gaussian._make((pred.mean[rows], pred.cov[rows]))
    xs, Ps = x.copy(), P.copy()
    for _ in range(lag):
        xs_r, Ps_r = rts_update(x[rows], P[rows], step, G[rows], xs[after], Ps[after])
        xs, Ps = x.copy(), P.copy()
        xs[rows], Ps[rows] = xs_r, Ps_r
    return xs, Ps
