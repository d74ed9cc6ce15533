r"""Kalman filters linearised by Jacobians: KF, EKF (first and second order) and IEKF.

Notation follows the textbook. Prediction, with :math:`F` the Jacobian of :math:`f` at
:math:`\mathbf{x}` (the matrix itself for a linear model):

.. math::

    \mathbf{x}^- = f(\mathbf{x}), \qquad P^- = F P F^\top + Q

Update with the innovation :math:`\mathbf{r} = \mathbf{z} - h(\mathbf{x}^-)` and the Joseph
form of the covariance:

.. math::

    S &= H P^- H^\top + R, \qquad K = P^- H^\top S^{-1}, \\
    \mathbf{x}^+ &= \mathbf{x}^- + K \mathbf{r}, \qquad
    P^+ = (I - K H) P^- (I - K H)^\top + K R K^\top

Every kernel works on any leading batch shape.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    keep_prior_where_missing,
    missing_rows,
    output,
    register,
)
from trackkit.filters.kalman_fast import (
    FAST_MAX_M,
    predict_cov,
    sandwich,
    update_batch,
    update_one,
)
from trackkit.linalg import mm, mmT, quadratic_form, solve_psd, symmetrize
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = ["Linearised", "KF", "EKF", "IEKF", "joseph_update", "condition"]

Array = NDArray[np.float64]
_F64 = np.dtype(np.float64)


def jacobian_predict(x: Array, P: Array, motion: MotionModel, dt: ArrayLike) -> Gaussian:
    """``x- = f(x, dt)``, ``P- = F P F^T + Q`` with F the Jacobian of f at x.

    P- is exactly symmetric. A model whose F or Q is not n x n gets the formula as written.
    """
    both = getattr(motion, "f_and_jacobian", None)  # a model that shares the work
    fx, F = both(x, dt) if both is not None else (None, motion.jacobian(x, dt))
    Q = motion.noise(x, dt)
    # the fast path (kalman_fast): the Kronecker GEMM up to _KRON_MAX_N states, else sandwich
    Pp = predict_cov(F, P, Q)
    if fx is None:
        fx = motion.f(x, dt)
    if Pp is not None:
        return Gaussian._make((fx, register(Pp)))  # Pp exactly symmetric
    F, Q = np.asarray(F, dtype=float), np.asarray(Q, dtype=float)
    return output(fx, sandwich(F, P) + Q)


def kalman_gain(P: Array, H: Array, R: Array) -> tuple[Array, Array, Array]:
    """``A = P H^T``, ``S = H P H^T + R`` (symmetrised) and ``K = A S^{-1}``."""
    A = mmT(P, H)
    S = mm(H, A) + R
    if S.shape[-1] > 1:
        S = symmetrize(S)
    return A, S, solve_psd(S, A.mT).mT


def joseph_update(x: Array, P: Array, nu: Array, H: Array, R: Array
                  ) -> tuple[Array, Array, Array]:
    r"""The Kalman update for the innovation :math:`\nu` as the textbook writes it (Bar-Shalom,
    Li and Kirubarajan 2001, section 5.2.3; the covariance in Joseph form, Bucy and Joseph
    1968):

    .. math::

        S &= H P H^\top + R \\
        K &= P H^\top S^{-1} \\
        \mathbf{x}^+ &= \mathbf{x} + K \nu \\
        P^+ &= (I - K H) P (I - K H)^\top + K R K^\top

    on any batch shapes; returns ``(x+, P+, S)``, S and P+ symmetrised (exactly symmetric).
    The reference of the fast kernels in :mod:`trackkit.filters.kalman_fast`, and what
    :func:`condition` runs for measurements of more than ``FAST_MAX_M`` components.
    """
    n = P.shape[-1]
    S = symmetrize(H @ P @ H.mT + R)
    K = solve_psd(S, (P @ H.mT).mT).mT  # P H^T S^{-1}, as (S^{-1} (P H^T)^T)^T: S symmetric
    I_KH = np.eye(n) - K @ H
    x_new = x + (K @ nu[..., None])[..., 0]
    P_new = symmetrize(I_KH @ P @ I_KH.mT + K @ R @ K.mT)
    return x_new, P_new, S


def condition(
    x: Array, P: Array, nu: Array, H: Array, R: Array
) -> tuple[Array, Array, Array]:
    """The Kalman update for the innovation nu, :func:`joseph_update`: returns ``(x+, P+, S)``,
    P+ exactly symmetric.

    Measurements of up to ``FAST_MAX_M`` components (every sensor model but a stack of
    them) take the fast kernels, the same equations ordered for speed
    (:func:`~trackkit.filters.kalman_fast.update_one` for one problem,
    :func:`~trackkit.filters.kalman_fast.update_batch` for a batch); larger ones the
    textbook form as written.
    """
    if type(H) is not np.ndarray or H.dtype is not _F64:
        H = np.asarray(H, dtype=float)
    if type(R) is not np.ndarray or R.dtype is not _F64:
        R = np.asarray(R, dtype=float)
    if H.shape[-2] > FAST_MAX_M:
        return joseph_update(x, P, nu, H, R)
    if x.ndim == 1 and P.ndim == 2 and H.ndim == 2 and R.ndim == 2 and nu.ndim == 1:
        return update_one(x, P, nu, H, R)
    return update_batch(x, P, nu, H, R)


def _second_order_terms(Hs: Array, P: Array) -> tuple[Array, Array]:
    """Second-order EKF corrections from the measurement Hessians ``Hs`` (..., m, n, n).

    ``dz_i = 1/2 tr(Hs_i P)`` added to the predicted measurement and
    ``B_ij = 1/2 tr(Hs_i P Hs_j P)`` added to the innovation covariance.
    """
    HP = mm(Hs, P[..., None, :, :])
    dz = 0.5 * np.trace(HP, axis1=-2, axis2=-1)
    B = 0.5 * np.einsum("...iab,...jba->...ij", HP, HP)
    return dz, B


def linearize(sensor: SensorModel, x: Array) -> tuple[Array, Array]:
    """``(h(x), H(x))``: the sensor's fused ``linearize`` when it has one."""
    lin = getattr(sensor, "linearize", None)
    zhat, H = (sensor.h(x), sensor.jacobian(x)) if lin is None else lin(x)
    return zhat, H if type(H) is np.ndarray else np.asarray(H)


def dim_x_of(motion_or_sensor) -> int | None:
    return getattr(motion_or_sensor, "dim_x", None)


class Linearised(Filter):
    """Shared prediction of the Jacobian-based filters."""

    def predict(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike) -> Gaussian:
        """``x- = f(x, dt)``; ``P- = F P F^T + Q``."""
        x, P = check_belief(belief, getattr(motion, "dim_x", None),
                            f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        return jacobian_predict(x, P, motion, dt)

    def predict_with_cross(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike):
        """Prediction and the cross-covariance ``Cov(x_k, x_{k+1}) = P F^T`` (for RTS)."""
        x, P = check_belief(belief, dim_x_of(motion), f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        F = np.asarray(motion.jacobian(x, dt))
        return jacobian_predict(x, P, motion, dt), mmT(P, F)

    def _inputs(self, belief, z, sensor: SensorModel):
        x, P = check_belief(belief, None, f"{self.name}.update belief")
        z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        return x, P, z


class KF(Linearised):
    """Linear Kalman filter: motion and sensor must be linear (``model.linear``)."""

    name = "KF"

    def predict(self, belief: Gaussian, motion: MotionModel, dt: ArrayLike) -> Gaussian:
        if not getattr(motion, "linear", False):
            raise TypeError(f"KF needs a linear motion model; {type(motion).__name__} is "
                            "nonlinear (use EKF, IEKF, UKF or CKF)")
        x, P = check_belief(belief, getattr(motion, "dim_x", None),
                            f"{self.name}.predict belief")
        check_dt(dt, f"{self.name}.predict")
        return jacobian_predict(x, P, motion, dt)

    def update(self, belief: Gaussian, z: ArrayLike,
               sensor: SensorModel) -> tuple[Gaussian, Innovation]:
        """``nu = z - H x-``; ``K = P- H^T S^{-1}``; Joseph-form covariance."""
        if not getattr(sensor, "linear", False):
            raise TypeError(f"KF needs a linear sensor model; {type(sensor).__name__} is "
                            "nonlinear (use EKF, IEKF, UKF or CKF)")
        x, P = check_belief(belief, None, f"{self.name}.update belief")
        if not (type(z) is np.ndarray and z.dtype is _F64 and z.shape == (sensor.dim_z,)
                and x.ndim == 1 and math.isfinite(sum(z.tolist()))):
            # (the lean path: one problem, one finite float z, nothing to convert or check)
            z = check_measurement(z, sensor.dim_z, f"{self.name}.update", x.shape[:-1])
        zhat, H = linearize(sensor, x)
        miss = missing_rows(z)
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        R = sensor.noise
        if (x.ndim == 1 and r.ndim == 1 and H.ndim == 2 and type(R) is np.ndarray
                and R.ndim == 2 and R.dtype is _F64 and H.dtype is _F64
                and H.shape[0] <= FAST_MAX_M):
            xn, Pn, S = update_one(x, P, r, H, R)
        else:
            xn, Pn, S = condition(x, P, r, H, R)
        post, innov = Gaussian._make((xn, register(Pn))), Innovation(r, S)  # Pn exactly symmetric
        if miss is None:
            return post, innov
        return keep_prior_where_missing(miss, (x, P), post, innov)


class EKF(Linearised):
    r"""Extended Kalman filter, first order (``order=1``) or second order (``order=2``).

    The first-order filter linearises :math:`h` at the prediction, the Jacobian
    :math:`H = \partial h / \partial \mathbf{x}` at :math:`\mathbf{x}^-`, and applies the
    Kalman update. The
    second-order filter adds the measurement-Hessian terms of Athans, Wishner and Bertolini,
    with :math:`\mathcal{H}_i` the Hessian of the i-th component of :math:`h`:

    .. math::

        \hat z_i = h_i(\mathbf{x}^-) + \tfrac12 \operatorname{tr}(\mathcal{H}_i P^-), \qquad
        S = H P^- H^\top + R + B, \qquad
        B_{ij} = \tfrac12 \operatorname{tr}(\mathcal{H}_i P^- \mathcal{H}_j P^-)

    The prediction stays first order (the motion models here are linear or mildly nonlinear
    over one step).
    """

    name = "EKF"

    def __init__(self, order: int = 1) -> None:
        if order not in (1, 2):
            raise ValueError(f"EKF order = {order!r}; expected 1 or 2")
        self.order = order

    def update(self, belief: Gaussian, z: ArrayLike,
               sensor: SensorModel) -> tuple[Gaussian, Innovation]:
        x, P, z = self._inputs(belief, z, sensor)
        miss = missing_rows(z)
        zhat, H = linearize(sensor, x)
        R = sensor.noise
        if self.order == 2:
            dz, B = _second_order_terms(sensor.hessian(x), P)
            zhat, R = zhat + dz, R + B
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        xn, Pn, S = condition(x, P, r, H, R)
        return keep_prior_where_missing(miss, (x, P), output(xn, Pn, symmetric=True),
                                        Innovation(r, S))


class IEKF(Linearised):
    r"""Iterated EKF: Gauss-Newton on the MAP cost of the update (Bell and Cathey 1993).

    From :math:`\mathbf{x}_0 = \mathbf{x}^-`, for ``iterations`` steps (1 is the EKF):

    .. math::

        H_i &= \left.\frac{\partial h}{\partial \mathbf{x}}\right|_{\mathbf{x}_i}, \qquad
        K_i = P^- H_i^\top (H_i P^- H_i^\top + R)^{-1}, \\
        \mathbf{x}_{gn} &= \mathbf{x}^- + K_i \bigl(\mathbf{z} - h(\mathbf{x}_i)
            - H_i (\mathbf{x}^- - \mathbf{x}_i)\bigr)

    The covariance is the Joseph form with the last :math:`K_i, H_i`.

    With ``line_search=True`` each step is
    :math:`\mathbf{x}_{i+1} = \mathbf{x}_i + a (\mathbf{x}_{gn} - \mathbf{x}_i)` with
    :math:`a` halved (up to ``max_halvings`` times) until the MAP cost

    .. math::

        c(\mathbf{x}) = (\mathbf{x} - \mathbf{x}^-)^\top (P^-)^{-1} (\mathbf{x} - \mathbf{x}^-)
            + (\mathbf{z} - h(\mathbf{x}))^\top R^{-1} (\mathbf{z} - h(\mathbf{x}))

    does not increase; a row whose cost never decreases stays where it is. Plain Gauss-Newton
    (``line_search=False``) can overshoot when h is strongly nonlinear over the prior's spread
    (Havlik and Straka 2015). Either way the iteration converges to the MAP point of the update,
    and the covariance linearised there can be overconfident when the measurement is weakly
    informative in some direction (bearings-only range early in a track): the IEKF is not always
    better.

    The returned innovation is the one at the prediction, ``z - h(x-)`` with its S, as used
    for gating and NIS.
    """

    name = "IEKF"

    def __init__(self, iterations: int = 5, line_search: bool = False,
                 max_halvings: int = 4) -> None:
        if not (isinstance(iterations, int | np.integer) and iterations >= 1):
            raise ValueError(f"IEKF iterations = {iterations!r}; expected an integer >= 1")
        if not (isinstance(max_halvings, int | np.integer) and max_halvings >= 0):
            raise ValueError(f"IEKF max_halvings = {max_halvings!r}; expected an integer >= 0")
        self.iterations = int(iterations)
        self.line_search = bool(line_search)
        self.max_halvings = int(max_halvings)

    def update(self, belief: Gaussian, z: ArrayLike,
               sensor: SensorModel) -> tuple[Gaussian, Innovation]:
        x0, P, z = self._inputs(belief, z, sensor)
        miss = missing_rows(z)
        R = sensor.noise
        if miss is not None:
            z = np.where(miss[..., None], sensor.h(x0), z)

        def cost(x: Array) -> Array:
            return (quadratic_form(P, x - x0, "IEKF predicted covariance")
                    + quadratic_form(R, sensor.residual(z, sensor.h(x)), "R"))

        xi = x0
        c_i = cost(x0) if self.line_search else None
        for i in range(self.iterations):
            H = np.asarray(sensor.jacobian(xi))
            r = sensor.residual(z, sensor.h(xi)) - mm(H, (x0 - xi)[..., None])[..., 0]
            x_gn, Pn, S = condition(x0, P, r, H, R)
            if i == 0:
                innov = Innovation(r, S)
            if not self.line_search:
                xi = x_gn
                continue
            step, accepted = x_gn - xi, np.zeros(np.shape(c_i), bool)
            x_new, c_new = xi, c_i
            a = 1.0
            for _ in range(self.max_halvings + 1):
                x_try = xi + a * step
                c_try = cost(x_try)
                take = ~accepted & (c_try <= c_i)
                x_new = np.where(take[..., None], x_try, x_new)
                c_new = np.where(take, c_try, c_new)
                accepted |= take
                if accepted.all():
                    break
                a *= 0.5
            xi, c_i = x_new, c_new
        return keep_prior_where_missing(miss, (x0, P), output(xi, Pn, symmetric=True), innov)
