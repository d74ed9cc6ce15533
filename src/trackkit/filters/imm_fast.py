"""Compiled fast path of the IMM (``trackkit.filters.imm``) for the recorded-data tracker's
configuration: the same equations, one compiled loop over the batch rows instead of a few
dozen numpy calls on arrays of a few tens of tracks.

It takes over only for exactly this configuration (:func:`configuration`):

* two models, ``ConstantVelocity(dim=2)`` (state ``[x, y, vx, vy]``) and ``CoordinatedTurn``
  (``[x, y, vx, vy, omega]``), in that order, each with the default state map (CV nested in
  CT) and ``fill="others"``, each with a first-order ``EKF``; the prediction with the IMM's
  own models and one scalar time step;
* a ``RangeBearing`` sensor (bearing wrapped to (-pi, pi]). (A ``Position`` sensor stays on
  the numpy path, whose Kalman kernel changes from 1024 rows: the kernels' ``kind`` 1, the
  position itself, is there for it.)

For one row (mode probabilities mu_j, model means x_j and covariances P_j):

    mixing       c_j = sum_i p_ij mu_i,  mu_{i|j} = p_ij mu_i / c_j (0 where c_j = 0)
                 x0_j = sum_i mu_{i|j} x_i,  P0_j = sum_i mu_{i|j} (P_i + d_i d_i^T)
                 (into CT, the CV model's turn rate is CT's own: mean x_1[4], variance
                 P_1[4, 4], uncorrelated with the rest)
    prediction   x_j- = f_j(x0_j),  P_j- = F_j P0_j F_j^T + Q_j   (F_j the Jacobian at x0_j)
    measurement  zhat_j = h(x_j-), H_j its Jacobian, S_j = H_j P_j- H_j^T + R,
                 K_j = P_j- H_j^T S_j^-1, x_j = x_j- + K_j nu_j,
                 P_j = P_j- - K_j A_j^T - W_j K_j^T (A_j = P_j- H_j^T, W_j = A_j - K_j S_j)
                 mu_j ~ c_j N(nu_j; 0, S_j)   (in log space)
    combination  the carriers' moment match of ``imm.combine`` (the turn rate from CT alone)

Rows with nan in z keep the prediction and mu = c (as ``IMM.update``). Results equal the
numpy path's to rounding (``tests/test_imm_fast.py``: 1e-12 relative). numba compiles on
first use and caches the machine code beside this module (``cache=True``).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from trackkit.models import ConstantVelocity, CoordinatedTurn
from trackkit.models.sensors import RangeBearing

Array = NDArray[np.float64]
_TWO_PI = 2.0 * math.pi
_LOG_2PI = math.log(2.0 * math.pi)
#: below this CT weight the combination takes imm.combine's limit (imm._SMALL_WEIGHT)
_SMALL = float(np.finfo(float).tiny / np.finfo(float).eps ** 2)


class SensorParams(NamedTuple):
    """What the kernels need of a sensor: ``kind`` 0 range-bearing, 1 position; the
    origin; R (2 x 2); ``nautical`` bearings (clockwise from north)."""

    kind: int
    origin: Array
    R: Array
    nautical: bool


def configuration(imm: Any) -> bool:
    """Whether the IMM is the one configuration the kernels implement (module docstring)."""
    from trackkit.filters.kalman import EKF

    models, filters = imm.models, imm.filters
    return (len(models) == 2 and type(models[0]) is ConstantVelocity and models[0].dim == 2
            and type(models[1]) is CoordinatedTurn and imm.fill == "others"
            and all(type(f) is EKF and f.order == 1 for f in filters)
            and [a.tolist() for a in imm.state_maps] == [[0, 1, 2, 3], [0, 1, 2, 3, 4]])


def sensor_params(sensor: Any) -> SensorParams | None:
    """The kernels' view of a ``RangeBearing`` sensor, or None."""
    if type(sensor) is RangeBearing:
        return SensorParams(0, np.asarray(sensor.origin, dtype=float), sensor.noise,
                            sensor.convention == "nautical")
    return None


# -- the kernels -------------------------------------------------------------------------------


@numba.njit(cache=True, error_model="numpy")
def wrap_angle(a: float) -> float:  # pragma: no cover
    """``angles.wrap`` on one float, the same operations (compiled, for kernels)."""
    w = a - _TWO_PI * math.ceil((a - math.pi) / _TWO_PI)
    if w > math.pi:
        w -= _TWO_PI
    if w <= -math.pi:
        w += _TWO_PI
    return w


@numba.njit(cache=True, error_model="numpy")
def _turn(w, dt):  # pragma: no cover
    """``motion.turn_coefficients`` on one turn rate: s, c, ds, dc, cos, sin."""
    wt = w * dt
    small = abs(wt) < 1e-3
    ws = 1.0 if small else w
    sn, cs = math.sin(wt), math.cos(wt)
    if small:
        return (dt - w**2 * dt**3 / 6, w * dt**2 / 2 - w**3 * dt**4 / 24,
                -w * dt**3 / 3 + w**3 * dt**5 / 30, dt**2 / 2 - w**2 * dt**4 / 8, cs, sn)
    versin = 1 - cs
    return (sn / ws, versin / ws, (wt * cs - sn) / ws**2, (wt * sn - versin) / ws**2, cs, sn)


@numba.njit(cache=True, error_model="numpy")
def _sandwich(F, P, Q, n, out):  # pragma: no cover
    """``out[:n, :n] = F P F^T + Q`` (upper triangle mirrored)."""
    FP = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            s = 0.0
            for k in range(n):
                s += F[a, k] * P[k, b]
            FP[a, b] = s
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for k in range(n):
                s += FP[a, k] * F[b, k]
            out[a, b] = s + Q[a, b]
            out[b, a] = out[a, b]


@numba.njit(cache=True, error_model="numpy")
def predict_kernel(mu, X, P, p, dt, Fcv, Qcv, Qct):  # pragma: no cover
    """Mixing and both EKF predictions for every row: ``(c (N, 2), X- (N, 2, 5),
    P- (N, 2, 5, 5))``."""
    N = mu.shape[0]
    c = np.zeros((N, 2))
    Xp = np.zeros((N, 2, 5))
    Pp = np.zeros((N, 2, 5, 5))
    Xa = np.zeros((2, 5))
    Pa = np.zeros((2, 5, 5))
    x0 = np.zeros(5)
    P0 = np.zeros((5, 5))
    F = np.zeros((5, 5))
    for t in range(N):
        for i in range(2):  # (element loops: slice assignments cost seconds of compile)
            for a in range(5):
                Xa[i, a] = X[t, i, a]
                for b in range(5):
                    Pa[i, a, b] = P[t, i, a, b]
        for j in range(2):
            n = 4 + j
            cj = p[0, j] * mu[t, 0] + p[1, j] * mu[t, 1]
            c[t, j] = cj
            w0 = p[0, j] * mu[t, 0] / cj if cj > 0 else 0.0
            w1 = p[1, j] * mu[t, 1] / cj if cj > 0 else 0.0
            if j == 1:  # the CV model's turn rate is CT's own (fill "others")
                Xa[0, 4] = X[t, 1, 4]
                Pa[0, 4, 4] = P[t, 1, 4, 4]
            for a in range(n):
                x0[a] = w0 * Xa[0, a] + w1 * Xa[1, a]
            for a in range(n):
                d0a, d1a = Xa[0, a] - x0[a], Xa[1, a] - x0[a]
                for b in range(a, n):
                    v = (w0 * (Pa[0, a, b] + d0a * (Xa[0, b] - x0[b]))
                         + w1 * (Pa[1, a, b] + d1a * (Xa[1, b] - x0[b])))
                    P0[a, b] = v
                    P0[b, a] = v
            if j == 0:
                for a in range(4):
                    s = 0.0
                    for k in range(4):
                        s += Fcv[a, k] * x0[k]
                    Xp[t, 0, a] = s
                _sandwich(Fcv, P0, Qcv, 4, Pp[t, 0])
            else:
                s_, c_, ds, dc, cs, sn = _turn(x0[4], dt)
                vx, vy = x0[2], x0[3]
                Xp[t, 1, 0] = x0[0] + s_ * vx - c_ * vy
                Xp[t, 1, 1] = x0[1] + c_ * vx + s_ * vy
                Xp[t, 1, 2] = cs * vx - sn * vy
                Xp[t, 1, 3] = sn * vx + cs * vy
                Xp[t, 1, 4] = x0[4] + 0 * dt
                for a in range(5):
                    for b in range(5):
                        F[a, b] = 1.0 if a == b and (a < 2 or a == 4) else 0.0
                F[0, 2], F[0, 3], F[1, 2], F[1, 3] = s_, -c_, c_, s_
                F[2, 2], F[2, 3], F[3, 2], F[3, 3] = cs, -sn, sn, cs
                F[0, 4] = ds * vx - dc * vy
                F[1, 4] = dc * vx + ds * vy
                F[2, 4] = -dt * (sn * vx + cs * vy)
                F[3, 4] = dt * (cs * vx - sn * vy)
                _sandwich(F, P0, Qct, 5, Pp[t, 1])
    return c, Xp, Pp


@numba.njit(cache=True, error_model="numpy")
def _measure(x, kind, origin, nautical, zhat, H):  # pragma: no cover
    """``zhat = h(x)`` and the position columns of its Jacobian ``H (2, 2)``."""
    if kind == 1:
        zhat[0], zhat[1] = x[0], x[1]
        H[0, 0], H[0, 1], H[1, 0], H[1, 1] = 1.0, 0.0, 0.0, 1.0
        return
    u, v = x[0] - origin[0], x[1] - origin[1]
    zhat[0] = math.hypot(u, v)
    r2 = u * u + v * v
    r = math.sqrt(r2)
    H[0, 0], H[0, 1] = u / r, v / r
    if nautical:
        zhat[1] = math.atan2(u, v)
        H[1, 0], H[1, 1] = v / r2, -u / r2
    else:
        zhat[1] = math.atan2(v, u)
        H[1, 0], H[1, 1] = -v / r2, u / r2


@numba.njit(cache=True, error_model="numpy")
def _innovation_cov(Pj, H, R, A, S):  # pragma: no cover
    """``A = P H^T`` (n x 2, H on the position only) and ``S = H A + R`` symmetrised."""
    n = Pj.shape[0]
    for a in range(n):
        for m in range(2):
            A[a, m] = Pj[a, 0] * H[m, 0] + Pj[a, 1] * H[m, 1]
    s00 = H[0, 0] * A[0, 0] + H[0, 1] * A[1, 0] + R[0, 0]
    s01 = H[0, 0] * A[0, 1] + H[0, 1] * A[1, 1] + R[0, 1]
    s10 = H[1, 0] * A[0, 0] + H[1, 1] * A[1, 0] + R[1, 0]
    s11 = H[1, 0] * A[0, 1] + H[1, 1] * A[1, 1] + R[1, 1]
    S[0, 0], S[1, 1] = s00, s11
    S[0, 1] = S[1, 0] = (s01 + s10) * 0.5


@numba.njit(cache=True, error_model="numpy")
def _residual(z, zhat, kind, nu):  # pragma: no cover
    nu[0] = z[0] - zhat[0]
    nu[1] = z[1] - zhat[1] if kind == 1 else wrap_angle(z[1] - zhat[1])


@numba.njit(cache=True, error_model="numpy")
def _mixture(w, nus, Ss, v, Sm):  # pragma: no cover
    """``v = sum_j w_j nu_j``, ``Sm = sum_j w_j (S_j + (nu_j - v)(nu_j - v)^T)``."""
    for a in range(2):
        v[a] = w[0] * nus[0, a] + w[1] * nus[1, a]
    for a in range(2):
        for b in range(a, 2):
            s = 0.0
            for j in range(2):
                s += w[j] * (Ss[j, a, b] + (nus[j, a] - v[a]) * (nus[j, b] - v[b]))
            Sm[a, b] = s
            Sm[b, a] = s


@numba.njit(cache=True, error_model="numpy")
def prediction_kernel(mu, X, P, R, kind, origin, nautical):  # pragma: no cover
    """The mixture's predicted measurement ``zhat (N, 2)`` and covariance ``S (N, 2, 2)``
    (``IMM.measurement_prediction``): per model at ``z0 = h(x-)``, x- the combined mean."""
    N = mu.shape[0]
    zh = np.zeros((N, 2))
    Sm = np.zeros((N, 2, 2))
    xc = np.zeros(2)
    z0 = np.zeros(2)
    zj = np.zeros(2)
    H = np.zeros((2, 2))
    nus = np.zeros((2, 2))
    Ss = np.zeros((2, 2, 2))
    A = np.zeros((5, 2))
    v = np.zeros(2)
    for t in range(N):
        m0, m1 = mu[t, 0], mu[t, 1]
        if m1 < _SMALL:  # imm.combine's limit: weights over the largest
            top = max(m0, m1)
            m0, m1 = m0 / top, m1 / top
        for a in range(2):
            xc[a] = (m0 * X[t, 0, a] + m1 * X[t, 1, a]) / (m0 + m1)
        _measure(xc, kind, origin, nautical, z0, H)
        for j in range(2):
            _measure(X[t, j], kind, origin, nautical, zj, H)
            _innovation_cov(P[t, j, :4 + j, :4 + j], H, R, A, Ss[j])
            _residual(z0, zj, kind, nus[j])
        _mixture(mu[t], nus, Ss, v, Sm[t])
        zh[t, 0] = z0[0] - v[0]
        zh[t, 1] = z0[1] - v[1] if kind == 1 else wrap_angle(z0[1] - v[1])
    return zh, Sm


@numba.njit(cache=True, error_model="numpy")
def _condition(x, Pj, nu, A, S, n, xo, Po):  # pragma: no cover
    """The Kalman update of one model: K = A S^-1, W = A - K S,
    ``P+ = P - K A^T - W K^T`` (upper triangle mirrored); the log-likelihood of nu."""
    a, b, d = S[0, 0], S[0, 1], S[1, 1]
    det = a * d - b * S[1, 0]
    K = np.empty((n, 2))
    W = np.empty((n, 2))
    for r in range(n):
        K[r, 0] = (A[r, 0] * d - A[r, 1] * b) / det
        K[r, 1] = (A[r, 1] * a - A[r, 0] * b) / det
        for m in range(2):
            W[r, m] = A[r, m] - (K[r, 0] * S[0, m] + K[r, 1] * S[1, m])
        xo[r] = x[r] + (K[r, 0] * nu[0] + K[r, 1] * nu[1])
    for r in range(n):
        for s in range(r, n):
            e = (K[r, 0] * A[s, 0] + K[r, 1] * A[s, 1]) + (W[r, 0] * K[s, 0] + W[r, 1] * K[s, 1])
            Po[r, s] = Pj[r, s] - e
            Po[s, r] = Po[r, s]
    q = (nu[0] * (d * nu[0] - b * nu[1]) + nu[1] * (a * nu[1] - b * nu[0])) / det
    return -0.5 * (q + math.log(det) + 2 * _LOG_2PI)


@numba.njit(cache=True, error_model="numpy")
def update_kernel(mu, X, P, z, R, kind, origin, nautical):  # pragma: no cover
    """Both models' EKF updates, the mode probabilities and the mixture innovation
    ``(mu, X, P, v (N, 2), Sm (N, 2, 2), bad)`` (``IMM.update``); ``bad`` the first row
    whose innovation covariance is not positive definite, or -1."""
    N = mu.shape[0]
    mu_o, X_o, P_o = mu.copy(), X.copy(), P.copy()
    v = np.zeros((N, 2))
    Sm = np.zeros((N, 2, 2))
    zt = np.zeros(2)
    zj = np.zeros(2)
    H = np.zeros((2, 2))
    nus = np.zeros((2, 2))
    Ss = np.zeros((2, 2, 2))
    A = np.zeros((5, 2))
    ll = np.zeros(2)
    xs = np.zeros((2, 5))
    Ps = np.zeros((2, 5, 5))
    bad = -1
    for t in range(N):
        miss = math.isnan(z[t, 0]) or math.isnan(z[t, 1])
        if miss:  # a stand-in measurement, model 0's predicted one, for S and nu - v
            _measure(X[t, 0], kind, origin, nautical, zt, H)
        else:
            zt[0], zt[1] = z[t, 0], z[t, 1]
        for j in range(2):
            n = 4 + j
            _measure(X[t, j], kind, origin, nautical, zj, H)
            _innovation_cov(P[t, j, :n, :n], H, R, A, Ss[j])
            _residual(zt, zj, kind, nus[j])
            S = Ss[j]
            if not (S[0, 0] > 0 and S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0] > 0):
                if bad < 0:
                    bad = t
                continue
            ll[j] = _condition(X[t, j, :n], P[t, j, :n, :n], nus[j], A, S, n, xs[j, :n],
                               Ps[j, :n, :n])
        _mixture(mu[t], nus, Ss, v[t], Sm[t])
        if miss:
            v[t, 0] = v[t, 1] = np.nan
            continue
        a0 = math.log(mu[t, 0]) + ll[0] if mu[t, 0] > 0 else -np.inf
        a1 = math.log(mu[t, 1]) + ll[1] if mu[t, 1] > 0 else -np.inf
        top = max(a0, a1)
        e0, e1 = math.exp(a0 - top), math.exp(a1 - top)
        mu_o[t, 0], mu_o[t, 1] = e0 / (e0 + e1), e1 / (e0 + e1)
        for j in range(2):  # (element loops: slice assignments cost seconds of compile)
            for a in range(4 + j):
                X_o[t, j, a] = xs[j, a]
                for b in range(4 + j):
                    P_o[t, j, a, b] = Ps[j, a, b]
    return mu_o, X_o, P_o, v, Sm, bad


@numba.njit(cache=True, error_model="numpy")
def estimate_kernel(mu, X, P):  # pragma: no cover
    """``imm.combine`` with ``fill="others"`` for CV nested in CT: ``(x (N, 5), P (N, 5,
    5))``; the turn rate's moments from CT alone, and the limit (weights over the largest,
    CT's turn rate its own) where CT's weight is below ``_SMALL``."""
    N = mu.shape[0]
    x = np.zeros((N, 5))
    Pm = np.zeros((N, 5, 5))
    d = np.zeros((2, 5))
    for t in range(N):
        a0, a1, b1 = mu[t, 0], mu[t, 1], mu[t, 1]
        if b1 < _SMALL:
            top = max(a0, a1)
            a0, a1, b1 = a0 / top, a1 / top, 1.0
        for k in range(4):
            x[t, k] = (a0 * X[t, 0, k] + a1 * X[t, 1, k]) / (a0 + a1)
            d[0, k], d[1, k] = X[t, 0, k] - x[t, k], X[t, 1, k] - x[t, k]
        x[t, 4] = b1 * X[t, 1, 4] / b1
        d[0, 4], d[1, 4] = 0.0, X[t, 1, 4] - x[t, 4]
        for a in range(5):
            for b in range(a, 5):
                if b < 4 or a < 4:
                    s = (a0 * (P[t, 0, a, b] + d[0, a] * d[0, b])
                         + a1 * (P[t, 1, a, b] + d[1, a] * d[1, b])) / (a0 + a1)
                else:
                    s = b1 * (P[t, 1, 4, 4] + d[1, 4] * d[1, 4]) / b1
                Pm[t, a, b] = s
                Pm[t, b, a] = s
    return x, Pm
