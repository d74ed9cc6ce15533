"""Sigma-point filters: the unscented (UKF) and cubature (CKF) Kalman filters.

Sigma points ``X_i = x + c (L)_i`` and ``X_{i+n} = x - c (L)_i`` with ``L L^T = P`` (lower
Cholesky) and ``(L)_i`` its i-th column; the UKF adds the centre point ``X_0 = x``. Moments of
``Y_i = g(X_i)``: ``y = sum Wm_i Y_i`` (circular for angle components),
``P_y = sum Wc_i (Y_i - y)(Y_i - y)^T`` with wrapped differences.

Internally the sigma-point axis leads, ``(k, ..., n)``, so that models whose pose carries the
batch axes (a moving observer per Monte Carlo run) broadcast against the points unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_measurement,
    keep_prior_where_missing,
    missing_rows,
    output,
)
from trackkit.linalg import cholesky, solve_psd

__all__ = ["UKF", "CKF", "SigmaPoints"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SigmaPoints:
    """A sigma-point rule: scale ``c``, mean weights ``wm`` and covariance weights ``wc``
    over the points [centre?, +columns, -columns]."""

    c: float
    wm: Array
    wc: Array
    centre: bool

    def points(self, x: Array, P: Array, name: str) -> Array:
        """Sigma points of N(x, P) with the point axis first: ``(k, ..., n)``."""
        L = cholesky(P, name)
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
        n = x.shape[-1]
        cols = self.c * np.moveaxis(L, -1, 0)  # (n, ..., n): column i of L as row i
        pad = (1,) * (len(batch) - (P.ndim - 2))  # a covariance shared by a batch of means
        cols = np.broadcast_to(cols.reshape((n,) + pad + P.shape[:-2] + (n,)),
                               (n,) + batch + (n,))
        xs = np.broadcast_to(x, batch + (n,))
        parts = [xs[None]] if self.centre else []
        return np.concatenate(parts + [xs + cols, xs - cols], axis=0)


def _mean(Y: Array, wm: Array, angular: tuple[bool, ...] | None) -> Array:
    """Weighted mean over the leading point axis; circular on the angle components."""
    y = np.tensordot(wm, Y, axes=(0, 0))
    if angular is not None and any(angular):
        mask = np.asarray(angular)
        s = np.tensordot(wm, np.sin(Y[..., mask]), axes=(0, 0))
        c = np.tensordot(wm, np.cos(Y[..., mask]), axes=(0, 0))
        y[..., mask] = np.arctan2(s, c)
    return y


def _deviation(Y: Array, y: Array, angular: tuple[bool, ...] | None) -> Array:
    d = Y - y
    if angular is not None and any(angular):
        mask = np.asarray(angular)
        d[..., mask] = wrap(d[..., mask])
    return d


def _cross(wc: Array, dA: Array, dB: Array) -> Array:
    """``sum_i wc_i dA_i dB_i^T`` over the leading point axis -> ``(..., a, b)``."""
    k = dA.shape[0]
    A = np.moveaxis(dA * wc.reshape((k,) + (1,) * (dA.ndim - 1)), 0, -1)  # (..., a, k)
    return A @ np.moveaxis(dB, 0, -2)  # (..., a, k) @ (..., k, b)


class _SigmaPointFilter(Filter):
    rule: SigmaPoints

    def _rule(self, n: int) -> SigmaPoints:  # pragma: no cover - interface
        raise NotImplementedError

    def predict(self, belief: Gaussian, motion, dt: ArrayLike) -> Gaussian:
        """Unscented transform through f: ``x- = sum Wm f(X)``, ``P- = sum Wc dY dY^T + Q``."""
        pred, _ = self.predict_with_cross(belief, motion, dt)
        return pred

    def predict_with_cross(self, belief: Gaussian, motion, dt: ArrayLike):
        """Prediction and the cross-covariance ``C = sum Wc (X - x)(Y - x-)^T`` (for RTS)."""
        n = getattr(motion, "dim_x", None)
        x, P = check_belief(belief, n, f"{self.name}.predict belief")
        rule = self._rule(x.shape[-1])
        X = rule.points(x, P, f"{self.name}.predict belief.cov")
        Y = motion.f(X, dt)
        ang = getattr(motion, "angular", None)
        y = _mean(Y, rule.wm, ang)
        dY = _deviation(Y, y, ang)
        Pp = _cross(rule.wc, dY, dY) + motion.noise(x, dt)
        C = _cross(rule.wc, _deviation(X, x, ang), dY)
        return output(y, Pp), C

    def update(self, belief: Gaussian, z: ArrayLike, sensor) -> tuple[Gaussian, Innovation]:
        """Sigma points regenerated from the prediction; ``S = sum Wc dZ dZ^T + R``,
        ``C = sum Wc dX dZ^T``, ``K = C S^{-1}``, ``x+ = x- + K r``, ``P+ = P- - K S K^T``."""
        x, P = check_belief(belief, None, f"{self.name}.update belief")
        z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        rule = self._rule(x.shape[-1])
        X = rule.points(x, P, f"{self.name}.update belief.cov")
        Z = sensor.h(X)
        zhat = _mean(Z, rule.wm, sensor.angular)
        dZ = _deviation(Z, zhat, sensor.angular)
        S = _cross(rule.wc, dZ, dZ) + sensor.noise
        S = 0.5 * (S + np.swapaxes(S, -1, -2))
        C = _cross(rule.wc, X - x, dZ)
        K = np.swapaxes(solve_psd(S, np.swapaxes(C, -1, -2)), -1, -2)
        miss = missing_rows(z)
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        xn = x + (K @ r[..., None])[..., 0]
        Pn = P - K @ S @ np.swapaxes(K, -1, -2)
        return keep_prior_where_missing(miss, (x, P), output(xn, Pn), Innovation(r, S))


class UKF(_SigmaPointFilter):
    """Unscented Kalman filter with scaled sigma points (Julier; Van der Merwe).

    ``lambda = alpha^2 (n + kappa) - n``, ``c = sqrt(n + lambda)``,
    ``Wm_0 = lambda / (n + lambda)``, ``Wc_0 = Wm_0 + 1 - alpha^2 + beta``,
    ``Wm_i = Wc_i = 1 / (2 (n + lambda))``. Defaults are Stone Soup's: alpha = 0.5, beta = 2
    and kappa = 3 - n (``kappa=None``).
    """

    name = "UKF"

    def __init__(self, alpha: float = 0.5, beta: float = 2.0, kappa: float | None = None):
        if not (np.isfinite(alpha) and alpha > 0):
            raise ValueError(f"UKF alpha = {alpha!r}; expected a positive number")
        if not np.isfinite(beta):
            raise ValueError(f"UKF beta = {beta!r}; expected a finite number")
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), kappa

    def _rule(self, n: int) -> SigmaPoints:
        kappa = 3.0 - n if self.kappa is None else float(self.kappa)
        lam = self.alpha**2 * (n + kappa) - n
        if not n + lam > 0:
            raise ValueError(
                f"UKF: n + lambda = {n + lam:.3g} for n = {n}, alpha = {self.alpha}, "
                f"kappa = {kappa}; expected > 0 (raise alpha or kappa)"
            )
        wm = np.full(2 * n + 1, 0.5 / (n + lam))
        wc = wm.copy()
        wm[0] = lam / (n + lam)
        wc[0] = wm[0] + 1.0 - self.alpha**2 + self.beta
        return SigmaPoints(np.sqrt(n + lam), wm, wc, centre=True)


class CKF(_SigmaPointFilter):
    """Cubature Kalman filter (Arasaratnam and Haykin, 2009): the third-degree spherical-
    radial rule, 2n points ``x +- sqrt(n) (L)_i`` with equal weights ``1 / (2n)``. It equals
    the UKF with alpha = 1, beta = 0, kappa = 0."""

    name = "CKF"

    def _rule(self, n: int) -> SigmaPoints:
        w = np.full(2 * n, 0.5 / n)
        return SigmaPoints(np.sqrt(n), w, w, centre=False)
