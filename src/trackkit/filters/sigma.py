r"""Sigma-point filters: the unscented (UKF) and cubature (CKF) Kalman filters.

Sigma points, with :math:`L L^\top = P` (lower Cholesky) and :math:`(L)_i` its i-th column,
:math:`i = 1, \dots, n`; the UKF adds the centre point :math:`\mathcal{X}_0 = \mathbf{x}`:

.. math::

    \mathcal{X}_i = \mathbf{x} + c\,(L)_i, \qquad \mathcal{X}_{i+n} = \mathbf{x} - c\,(L)_i

Moments of :math:`\mathcal{Y}_i = g(\mathcal{X}_i)`, the mean circular for angle components
and the differences wrapped:

.. math::

    \bar{\mathbf{y}} = \sum_i W^m_i \mathcal{Y}_i, \qquad
    P_y = \sum_i W^c_i (\mathcal{Y}_i - \bar{\mathbf{y}})(\mathcal{Y}_i - \bar{\mathbf{y}})^\top

The update regenerates the points from the prediction and, with
:math:`\mathcal{Z}_i = h(\mathcal{X}_i)`:

.. math::

    S &= \sum_i W^c_i (\mathcal{Z}_i - \hat{\mathbf{z}})(\mathcal{Z}_i - \hat{\mathbf{z}})^\top
        + R, \qquad
    C = \sum_i W^c_i (\mathcal{X}_i - \mathbf{x}^-)(\mathcal{Z}_i - \hat{\mathbf{z}})^\top, \\
    K &= C S^{-1}, \qquad \mathbf{x}^+ = \mathbf{x}^- + K \mathbf{r}, \qquad
    P^+ = P^- - K S K^\top

Internally the sigma-point axis leads, ``(k, ..., n)``, so that models whose pose carries the
batch axes (a moving observer per Monte Carlo run) broadcast against the points unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    keep_prior_where_missing,
    missing_rows,
    output,
)
from trackkit.linalg import (
    CHOL_MAX_N,
    CHOL_MIN_BATCH,
    cholesky,
    cholesky_t,
    mirror,
    solve_psd,
    symmetrize,
    triu,
)
from trackkit.models.protocols import MotionModel, SensorModel
from trackkit.models.sensors import wrap_small

__all__ = ["UKF", "CKF", "SRCKF", "SigmaPoints"]

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
        x, P = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
        X, batch, _ = _points(self, x, P, name)
        return X.reshape(X.shape[:1] + batch + x.shape[-1:])


def _factor_columns(P: Array, batch: tuple[int, ...], name: str) -> Array:
    """Cholesky columns of every covariance, batch flattened and last: ``C (n, n, N)`` with
    ``C[j, i] = L[:, i, j]`` for the N = prod(batch) rows (a covariance shared by several
    means is factored once and broadcast)."""
    n = P.shape[-1]
    Pb = P.reshape((-1, n, n))
    C = None
    if Pb.shape[0] >= CHOL_MIN_BATCH and n <= CHOL_MAX_N:
        C = cholesky_t(Pb)
    if C is None:  # small stacks: LAPACK; and the diagnosis when a factor does not exist
        C = cholesky(P, name).reshape(Pb.shape).transpose(2, 1, 0)
    if P.shape[:-2] != batch:
        pad = (1,) * (len(batch) - (P.ndim - 2))
        C = np.broadcast_to(C.reshape((n, n) + pad + P.shape[:-2]), (n, n) + batch)
        C = C.reshape(n, n, -1)
    return C


def _points(rule: SigmaPoints, x: Array, P: Array, name: str):
    """Sigma points with the batch flattened: ``(X (k, N, n), batch, x (N, n))``."""
    n = x.shape[-1]
    batch = x.shape[:-1]
    if P.shape[:-2] != batch:
        batch = np.broadcast_shapes(batch, P.shape[:-2])
    N = math.prod(batch)
    x2 = np.broadcast_to(x, batch + (n,)).reshape(N, n)
    cols = _factor_columns(P, batch, name).transpose(0, 2, 1)  # (n, N, n): column j of L
    X = np.empty((rule.wm.shape[0], N, n))
    o = 1 if rule.centre else 0
    Xp, Xm = X[o:o + n], X[o + n:]
    np.multiply(cols, rule.c, out=Xp)
    np.subtract(x2, Xp, out=Xm)  # x - c L_j
    Xp += x2  # x + c L_j
    if rule.centre:
        X[0] = x2
    return X, batch, x2


def _through(g, X: Array, batch: tuple[int, ...], *args) -> Array:
    """``g`` applied to sigma points ``X (k, N, n)`` given to it with the batch axes
    restored (models whose parameters carry batch axes broadcast against them);
    the result with the batch flattened again, ``(k, N, d)``."""
    k, N = X.shape[:2]
    Y = np.asarray(g(X.reshape((k,) + batch + X.shape[-1:]), *args), dtype=float)
    if Y.shape[1:-1] != batch:  # a model output constant over some batch axes
        Y = np.broadcast_to(Y, (k,) + batch + Y.shape[-1:])
    return Y.reshape(k, N, Y.shape[-1])


def _mean(Y: Array, wm: Array, angular: tuple[bool, ...] | None) -> Array:
    """Weighted mean over the leading point axis; circular on the angle components."""
    k = Y.shape[0]
    flat = Y.reshape(k, -1)
    if angular is not None and any(angular):
        if all(angular):
            s, c = wm.dot(np.sin(flat)), wm.dot(np.cos(flat))
            return np.arctan2(s, c).reshape(Y.shape[1:])
        y = wm.dot(flat).reshape(Y.shape[1:])
        mask = np.asarray(angular)
        s = np.tensordot(wm, np.sin(Y[..., mask]), axes=(0, 0))
        c = np.tensordot(wm, np.cos(Y[..., mask]), axes=(0, 0))
        y[..., mask] = np.arctan2(s, c)
        return y
    return wm.dot(flat).reshape(Y.shape[1:])


def _deviation(Y: Array, y: Array, angular: tuple[bool, ...] | None) -> Array:
    d = Y - y
    if angular is not None and any(angular):
        if all(angular):
            return wrap_small(d)
        mask = np.asarray(angular)
        d[..., mask] = wrap(d[..., mask])
    return d


def _cross(wc: Array, dA: Array, dB: Array) -> Array:
    """``sum_i wc_i dA_i dB_i^T`` over the leading point axis -> ``(..., a, b)``."""
    k = dA.shape[0]
    A = np.moveaxis(dA * wc.reshape((k,) + (1,) * (dA.ndim - 1)), 0, -1)  # (..., a, k)
    return A @ np.moveaxis(dB, 0, -2)  # (..., a, k) @ (..., k, b)


def _upper_of(M: Array) -> Array:
    """Upper triangles ``(N, T)`` of square matrices ``M (N, n, n)``."""
    n = M.shape[-1]
    return M.reshape(M.shape[0], n * n)[:, triu(n).flat]


def _noise_upper(Q: Array, batch: tuple[int, ...], n: int) -> Array:
    """Upper triangle of Q (``(T,)`` or ``(N, T)``), averaged with the lower one when Q is
    not exactly symmetric (as symmetrising the sum would)."""
    flat = triu(n).flat
    if Q.ndim == 2:
        if not (Q == Q.T).all():
            Q = symmetrize(Q)
        return Q.ravel()[flat]
    Q = np.broadcast_to(Q, batch + (n, n)).reshape(-1, n, n)
    if not (Q == Q.mT).all():
        Q = symmetrize(Q)
    return Q.reshape(-1, n * n)[:, flat]


class _SigmaPointFilter(Filter):
    rule: SigmaPoints

    def _rule(self, n: int) -> SigmaPoints:  # pragma: no cover - interface
        raise NotImplementedError

    def predict(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike) -> Gaussian:
        """Unscented transform through f: ``x- = sum Wm f(X)``, ``P- = sum Wc dY dY^T + Q``."""
        return self._predict(belief, motion, dt, False)[0]

    def predict_with_cross(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike):
        """Prediction and the cross-covariance ``C = sum Wc (X - x)(Y - x-)^T`` (for RTS)."""
        return self._predict(belief, motion, dt, True)

    def _predict(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike, with_cross: bool):
        n = getattr(motion, "dim_x", None)
        x, P = check_belief(belief, n, f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        n = x.shape[-1]
        rule = self._rule(n)
        X, batch, x2 = _points(rule, x, P, f"{self.name}.predict belief.cov")
        Y = _through(motion.f, X, batch, dt)
        ang = getattr(motion, "angular", None)
        y = _mean(Y, rule.wm, ang)
        dY = _deviation(Y, y, ang)
        cov = self._spread(rule, dY, np.asarray(motion.noise(x, dt), dtype=float), batch)
        pred = output(y.reshape(batch + (n,)), cov.reshape(batch + (n, n)), symmetric=True)
        if not with_cross:
            return pred, None
        C = _cross(rule.wc, _deviation(X, x2, ang), dY)
        return pred, C.reshape(batch + (n, n))

    def _spread(self, rule: SigmaPoints, dY: Array, Q: Array, batch: tuple[int, ...]) -> Array:
        """``sum Wc dY dY^T + Q`` ``(N, n, n)``, exactly symmetric: its upper triangle,
        mirrored."""
        n = dY.shape[-1]
        upper = _upper_of(_cross(rule.wc, dY, dY))
        upper += _noise_upper(Q, batch, n)
        return mirror(upper, n)

    def update(self, belief: Gaussian, z: ArrayLike,
               sensor: SensorModel) -> tuple[Gaussian, Innovation]:
        """Sigma points regenerated from the prediction; ``S = sum Wc dZ dZ^T + R``,
        ``C = sum Wc dX dZ^T``, ``K = C S^{-1}``, ``x+ = x- + K r``, ``P+ = P- - K S K^T``."""
        x, P = check_belief(belief, None, f"{self.name}.update belief")
        z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        n = x.shape[-1]
        rule = self._rule(n)
        X, batch, x2 = _points(rule, x, P, f"{self.name}.update belief.cov")
        Z = _through(sensor.h, X, batch)
        k, N, m = Z.shape
        zhat = _mean(Z, rule.wm, sensor.angular)  # (N, m)
        R = np.asarray(sensor.noise, dtype=float)
        if R.ndim > 2:  # one R per batch row
            R = np.broadcast_to(R, batch + (m, m)).reshape(N, m, m)
        P2 = np.broadcast_to(P, batch + (n, n)).reshape(N, n, n)
        K, S, cov = self._condition(rule, X - x2, _deviation(Z, zhat, sensor.angular), R, P2)
        miss = missing_rows(z)
        r = sensor.residual(z, zhat.reshape(batch + (m,)))
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        r2 = np.broadcast_to(r, batch + (m,)).reshape(N, m)
        xn = x2 + K[..., 0] * r2 if m == 1 else x2 + (K @ r2[..., None])[..., 0]
        post = output(xn.reshape(batch + (n,)), cov.reshape(batch + (n, n)), symmetric=True)
        innov = Innovation(r, S.reshape(batch + (m, m)))
        return keep_prior_where_missing(miss, (x, P), post, innov)

    def _condition(self, rule: SigmaPoints, dX: Array, dZ: Array, R: Array,
                   P: Array) -> tuple[Array, Array, Array]:
        """The gain ``K (N, n, m)``, ``S (N, m, m)`` and ``P+ (N, n, n)``, exactly symmetric
        (its upper triangle, mirrored), from the deviations ``dX (k, N, n)``, ``dZ (k, N, m)``
        of the points from their means."""
        N, n, m = P.shape[0], P.shape[-1], dZ.shape[-1]
        if m == 1:
            wdz = dZ[..., 0] * rule.wc[:, None]  # (k, N)
            S = np.einsum("kn,kn->n", wdz, dZ[..., 0]).reshape(N, 1, 1) + R
            C = np.einsum("kni,kn->ni", dX, wdz)[..., None]  # (N, n, 1)
        else:
            S = symmetrize(_cross(rule.wc, dZ, dZ) + R)
            C = _cross(rule.wc, dX, dZ)
        K = solve_psd(S, C.mT).mT  # (N, n, m)
        if m == 1:
            i, j = triu(n)[:2]
            k0 = K[..., 0]
            upper = _upper_of(P) - S[:, 0] * (k0[:, i] * k0[:, j])
        else:  # whole batched products, then the triangle (gathering it first is slower)
            upper = _upper_of(P) - _upper_of(np.matmul(K @ S, K.mT))
        return K, S, mirror(upper, n)


_RULES: dict[tuple, SigmaPoints] = {}


def _cached_rule(key: tuple, build) -> SigmaPoints:
    """A rule built once per (filter type, parameters, n); its weights are read-only."""
    rule = _RULES.get(key)
    if rule is None:
        rule = build()
        rule.wm.flags.writeable = rule.wc.flags.writeable = False
        if len(_RULES) > 256:
            _RULES.clear()
        _RULES[key] = rule
    return rule


class UKF(_SigmaPointFilter):
    r"""Unscented Kalman filter with scaled sigma points (Julier; Van der Merwe).

    The :math:`2n + 1` points (module docstring) have the scale and weights

    .. math::

        \lambda &= \alpha^2 (n + \kappa) - n, \qquad c = \sqrt{n + \lambda}, \\
        W^m_0 &= \frac{\lambda}{n + \lambda}, \qquad
        W^c_0 = W^m_0 + 1 - \alpha^2 + \beta, \qquad
        W^m_i = W^c_i = \frac{1}{2 (n + \lambda)} \quad (i = 1, \dots, 2n)

    Defaults are Stone Soup's: alpha = 0.5, beta = 2 and kappa = 3 - n (``kappa=None``).
    """

    name = "UKF"

    def __init__(self, alpha: float = 0.5, beta: float = 2.0, kappa: float | None = None):
        if not (np.isfinite(alpha) and alpha > 0):
            raise ValueError(f"UKF alpha = {alpha!r}; expected a positive number")
        if not np.isfinite(beta):
            raise ValueError(f"UKF beta = {beta!r}; expected a finite number")
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), kappa

    def _rule(self, n: int) -> SigmaPoints:
        key = (type(self), self.alpha, self.beta, self.kappa, n)
        return _cached_rule(key, lambda: self._build_rule(n))

    def _build_rule(self, n: int) -> SigmaPoints:
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
    r"""Cubature Kalman filter (Arasaratnam and Haykin, 2009): the third-degree spherical-
    radial rule, 2n points with equal weights,

    .. math::

        \mathcal{X}_{i} = \mathbf{x} \pm \sqrt{n}\,(L)_i, \qquad W^m_i = W^c_i = \frac{1}{2n}

    It equals the UKF with alpha = 1, beta = 0, kappa = 0."""

    name = "CKF"

    def _rule(self, n: int) -> SigmaPoints:
        return _cached_rule((type(self), n), lambda: SigmaPoints(
            np.sqrt(n), np.full(2 * n, 0.5 / n), np.full(2 * n, 0.5 / n), centre=False))


def _tria(A: Array) -> Array:
    """A lower-triangular ``L (N, p, p)`` with ``L L^T = A A^T`` for ``A (N, p, q)``, q >= p:
    the transposed R of the QR decomposition of ``A^T``, columns signed for a positive
    diagonal (a Cholesky factor where ``A A^T`` is definite)."""
    R = np.linalg.qr(A.mT, mode="r")
    L = R.mT
    d = np.diagonal(L, axis1=-2, axis2=-1)
    return L * np.where(d < 0, -1.0, 1.0)[:, None, :]


def _psd_sqrt(Q: Array, batch: tuple[int, ...], n: int) -> Array:
    """A factor ``F (N, n, n)`` with ``F F^T = Q`` for a positive semi-definite Q, shared
    ``(n, n)`` or per row: a process noise that is singular (constant parameters in the
    state) has no Cholesky factor, so the symmetric square root from its eigenvectors."""
    Q = symmetrize(np.asarray(Q, dtype=float))
    lam, V = np.linalg.eigh(Q)
    F = V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]
    return np.broadcast_to(F, batch + (n, n)).reshape(-1, n, n)


class SRCKF(CKF):
    r"""Square-root cubature Kalman filter (Arasaratnam and Haykin, 2009, section VI): the
    CKF's points and moments, with every covariance formed as the product of a triangular
    factor from a QR decomposition (:math:`\operatorname{Tria}`) instead of by sums and a
    subtraction, :math:`w = 1 / (2n)` the weight of every point:

    .. math::

        S^- &= \operatorname{Tria}\bigl[\sqrt{w}\,(\mathcal{Y} - \bar{\mathbf{y}}),\;
            \sqrt{Q}\bigr], \\
        \begin{bmatrix} S_{zz} & 0 \\ K S_{zz} & S^+ \end{bmatrix}
            &= \operatorname{Tria} \begin{bmatrix}
                \sqrt{w}\,(\mathcal{Z} - \hat{\mathbf{z}}) & \sqrt{R} \\
                \sqrt{w}\,(\mathcal{X} - \mathbf{x}^-) & 0 \end{bmatrix}, \\
        K &= (K S_{zz})\, S_{zz}^{-1}, \qquad \mathbf{x}^+ = \mathbf{x}^- + K \mathbf{r},
            \qquad P^+ = S^+ (S^+)^\top

    The same filter as the CKF in exact arithmetic; in floating point the covariances stay
    positive semi-definite where the CKF's ``P- - K S K^T`` can cancel into an indefinite
    matrix (a measurement far more precise than the prediction, as when a ship's measured
    u, v, r meet coefficients known only to their order of magnitude). The belief carried is
    still ``Gaussian(x, S S^T)``."""

    name = "SRCKF"

    def _spread(self, rule: SigmaPoints, dY: Array, Q: Array, batch: tuple[int, ...]) -> Array:
        """``S S^T`` with ``S = Tria([sqrt(w) dY, sqrt(Q)])``, symmetrised."""
        n = dY.shape[-1]
        w = np.sqrt(rule.wc)[:, None, None]
        S = _tria(np.concatenate([np.moveaxis(w * dY, 0, -1), _psd_sqrt(Q, batch, n)], -1))
        return symmetrize(S @ S.mT)

    def _condition(self, rule: SigmaPoints, dX: Array, dZ: Array, R: Array,
                   P: Array) -> tuple[Array, Array, Array]:
        """The joint factor of ``[z; x]`` triangularised (see the class docstring)."""
        N, n, m = P.shape[0], P.shape[-1], dZ.shape[-1]
        w = np.sqrt(rule.wc)[:, None, None]
        dZ = np.moveaxis(w * dZ, 0, -1)  # (N, m, k)
        dX = np.moveaxis(w * dX, 0, -1)  # (N, n, k)
        SR = _psd_sqrt(R, (N,), m)
        T = _tria(np.concatenate([np.concatenate([dZ, SR], -1),
                                  np.concatenate([dX, np.zeros((N, n, m))], -1)], -2))
        Szz, KSzz, Sp = T[:, :m, :m], T[:, m:, :m], T[:, m:, m:]
        K = np.linalg.solve(Szz.mT, KSzz.mT).mT  # K Szz = KSzz
        return K, symmetrize(Szz @ Szz.mT), symmetrize(Sp @ Sp.mT)
