"""Batch least squares for the coefficients of Zolfagharnasab and Seif (2025): the equation-error
baseline.

The model is linear in theta, so the forward-Euler step with the mean input (paper eq. 4)
gives one linear regression per sample pair::

    y_k = (x_{k+1} - x_k) / dt = Phi(x_k, s_m(k)) theta + eps_k,   s_m(k) = (s_k + s_{k+1}) / 2

with ``Phi`` the 3 x 16 regressor matrix of ``trackkit.models.manoeuvring.regressors`` (SI rates
per unit prime coefficient). The surge, sway and yaw rows share no coefficients (a1..a9,
b1..b4, c1..c3), so each is its own problem ``y_i = X_i theta_i + eps_i`` with
``theta_i = (X_i^T X_i)^-1 X_i^T y_i``, solved for every run at once: the columns are scaled
to unit norm and the batched QR ``X_i D^-1 = Q R`` gives ``theta_i = D^-1 R^-1 Q^T y_i`` (the
normal equations would square the condition number: about 370 for the scaled surge columns
of the default programme, whose u^2, u n and n^2 move together, against 15-20 for sway and
yaw). The covariance is ``sigma_i^2 (X_i^T X_i)^-1`` with the residual
variance ``sigma_i^2 = |y_i - X_i theta_i|^2 / (N - p_i)``.

Pairs across a trial join (``starts[k + 1]``) and pairs with a missing sample are left out.

Errors in variables. With measured states ``z = x + e`` as regressors the estimate is biased:
the regressors carry the noise ``e_k``, and ``y_k`` carries ``-e_k / dt``, which is correlated
with them (for a damping term ``b x`` the bias is about ``-sigma^2 / (dt var x)`` in b). The
residual variance then also holds ``2 sigma^2 / dt^2`` of differenced measurement noise, so the
stated covariance is that of a white equation error, not of the measurement noise. With
noise-free states of the identifier's own discrete model (``substeps=1`` truth) the solution
is exact.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.manoeuvring import (
    EQUATION,
    N_THETA,
    Normalisation,
    reference_vessel,
    regressors,
)
from trackkit.renamed import renamed_keywords

__all__ = ["LeastSquaresFit", "EQUATIONS", "least_squares"]

Array = NDArray[np.float64]

#: the coefficients of the surge, sway and yaw equations (indices into theta)
EQUATIONS: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(i) for i in np.flatnonzero(EQUATION == e)) for e in range(3))


class LeastSquaresFit(NamedTuple):
    """``theta (..., 16)`` and its covariance ``cov (..., 16, 16)`` (block diagonal: the
    three equations are separate problems); ``residual_std (..., 3)`` the equation errors'
    standard deviations (SI: m/s^2, m/s^2, rad/s^2); ``rows (..., )`` the sample pairs used;
    ``condition (..., 3)`` the condition numbers of the column-scaled regressor matrices."""

    theta: Array
    cov: Array
    residual_std: Array
    rows: Array
    condition: Array


@renamed_keywords(T="dt")
def least_squares(x: ArrayLike, s: ArrayLike, dt: float, *, norm: Normalisation | None = None,
                  starts: ArrayLike | None = None) -> LeastSquaresFit:
    """Fit theta (prime units of ``norm``, default the reference vessel's) to body states
    ``x (..., K, 3)`` (SI, measured or true; nan where missing) and inputs
    ``s (..., K, 2)`` (rad, rpm) sampled every ``dt`` seconds; ``starts (K,)`` marks trial
    joins."""
    norm = reference_vessel().norm if norm is None else norm
    if not isinstance(norm, Normalisation):
        raise ValueError(f"norm = {norm!r}; expected a trackkit.models.manoeuvring.Normalisation")
    x, s = np.asarray(x, dtype=float), np.asarray(s, dtype=float)
    if x.ndim < 2 or x.shape[-1] != 3 or x.shape[-2] < 2:
        raise ValueError(f"x has shape {x.shape}; expected (..., K, 3) with K >= 2 samples")
    K = x.shape[-2]
    if s.ndim < 2 or s.shape[-2:] != (K, 2) or not np.all(np.isfinite(s)):
        raise ValueError(f"s has shape {s.shape}; expected finite (..., {K}, 2) inputs")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}; expected a sample period > 0 s")
    starts = np.zeros(K, bool) if starts is None else np.asarray(starts)
    if starts.shape != (K,) or starts.dtype != bool:
        raise ValueError(f"starts has shape {starts.shape} and dtype {starts.dtype}; expected "
                         f"({K},) booleans")
    batch = np.broadcast_shapes(x.shape[:-2], s.shape[:-2])
    x = np.broadcast_to(x, batch + (K, 3))
    s = np.broadcast_to(s, batch + (K, 2))

    x0, x1 = x[..., :-1, :], x[..., 1:, :]
    ok = ~starts[1:] & np.isfinite(x0).all(-1) & np.isfinite(x1).all(-1)  # (..., K - 1)
    x0 = np.where(ok[..., None], x0, 0.0)  # left-out rows become zero rows: no influence
    Phi = regressors(x0, 0.5 * (s[..., :-1, :] + s[..., 1:, :]), norm)  # (..., K-1, 3, 16)
    y = np.where(ok[..., None], (x1 - x0) / dt, 0.0)
    Phi = np.where(ok[..., None, None], Phi, 0.0)
    rows = ok.sum(-1)

    theta = np.zeros(batch + (N_THETA,))
    cov = np.zeros(batch + (N_THETA, N_THETA))
    resid = np.empty(batch + (3,))
    cond = np.empty(batch + (3,))
    for i, cols in enumerate(EQUATIONS):  # three independent problems, batched over runs
        c = np.array(cols)
        X, yi = Phi[..., :, i, c], y[..., :, i]  # (..., N, p), (..., N)
        p = c.size
        if np.any(rows < p + 1):
            raise ValueError(f"{int(rows.min())} usable sample pairs; expected more than {p} "
                             f"for the {('surge', 'sway', 'yaw')[i]} equation")
        d = np.sqrt((X * X).sum(-2))  # column norms
        if np.any(d == 0):
            raise ValueError(f"a regressor of the {('surge', 'sway', 'yaw')[i]} equation is "
                             "identically zero in these data; its coefficient is not "
                             "identifiable")
        Qm, Rm = np.linalg.qr(X / d[..., None, :])
        th = np.linalg.solve(Rm, (Qm.mT @ yi[..., None]))[..., 0] / d
        e = yi - (X @ th[..., None])[..., 0]
        var = (e * e).sum(-1) / (rows - p)
        Ri = np.linalg.solve(Rm, np.broadcast_to(np.eye(p), Rm.shape))  # R^-1
        C = (Ri @ Ri.mT) / (d[..., :, None] * d[..., None, :])  # (X^T X)^-1
        theta[..., c] = th
        cov[..., c[:, None], c[None, :]] = var[..., None, None] * C
        resid[..., i] = np.sqrt(var)
        sv = np.linalg.svd(Rm, compute_uv=False)
        cond[..., i] = sv[..., 0] / sv[..., -1]
    return LeastSquaresFit(theta, cov, resid, rows, cond)
