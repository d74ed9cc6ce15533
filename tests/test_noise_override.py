"""``trackkit.models.with_noise``: a sensor or motion model with its R or Q replaced.

The wrapped model must behave exactly like the model built with that noise: everything but
the noise is forwarded, and every filter reads the new R (Q), batched or not.
"""

from __future__ import annotations

import numpy as np
import pytest

from trackkit.belief import Gaussian
from trackkit.filters import CKF, EKF, IEKF, KF, UKF
from trackkit.models import (
    AzimuthElevation,
    ConstantVelocity,
    LinearMotion,
    Position,
    RangeBearing,
    with_noise,
)
from trackkit.models.noise import MotionWithNoise, SensorWithNoise


def _prior(B: int | None = None, n: int = 4) -> Gaussian:
    P = np.diag([25.0, 16.0, 4.0, 1.0, 9.0, 2.0][:n])
    P[0, 2] = P[2, 0] = 3.0
    m = np.array([1000.0, 2000.0, -3.0, 4.0, -50.0, 0.5][:n])
    if B is None:
        return Gaussian(m, P)
    rng = np.random.default_rng(B)
    return Gaussian(m + rng.normal(0, 3, (B, n)), np.broadcast_to(P, (B, n, n)).copy())


# --------------------------------------------------------------------------------------------
# Forwarding
# --------------------------------------------------------------------------------------------


def test_sensor_with_noise_forwards_everything_but_the_noise():
    base = RangeBearing(origin=(10.0, -20.0), sigma_range=5.0, sigma_bearing=0.01)
    R = np.array([[4.0, 0.01], [0.01, 1e-4]])
    s = with_noise(base, R)
    assert isinstance(s, SensorWithNoise)
    np.testing.assert_array_equal(s.noise, R)
    assert not np.array_equal(base.noise, R)  # the original is untouched
    np.testing.assert_array_equal(base.noise, np.diag([25.0, 1e-4]))
    assert s.dim_z == 2 and s.linear is False and s.angular == (False, True)
    x = np.array([[300.0, 400.0, 1.0, -2.0], [-500.0, 50.0, 0.0, 3.0]])
    np.testing.assert_array_equal(s.h(x), base.h(x))
    np.testing.assert_array_equal(s.jacobian(x), base.jacobian(x))
    np.testing.assert_array_equal(s.hessian(x), base.hessian(x))
    # residual wraps the bearing exactly as the sensor does
    z, zhat = np.array([10.0, 3.1]), np.array([9.0, -3.1])
    np.testing.assert_array_equal(s.residual(z, zhat), base.residual(z, zhat))
    assert abs(s.residual(z, zhat)[1] - (6.2 - 2 * np.pi)) < 1e-12
    assert s.origin is base.origin and s.sensor is base
    lin = with_noise(Position(dim=2, sigma=1.0), np.eye(2))
    assert lin.linear is True and lin.dim_z == 2


def test_motion_with_noise_forwards_everything_but_the_noise():
    base = ConstantVelocity(dim=2, q=0.5)
    Q = np.diag([1.0, 2.0, 3.0, 4.0])
    m = with_noise(base, Q)
    assert isinstance(m, MotionWithNoise)
    assert m.dim_x == 4 and m.linear == base.linear
    x = np.array([[1.0, 2.0, 3.0, 4.0], [0.0, -1.0, 0.5, 2.0]])
    for dt in (0.5, 2.0):
        np.testing.assert_array_equal(m.f(x, dt), base.f(x, dt))
        np.testing.assert_array_equal(m.jacobian(x, dt), base.jacobian(x, dt))
        np.testing.assert_array_equal(m.noise(x, dt), Q)  # the same Q for every x and dt
    assert not np.array_equal(base.noise(x[0], 1.0), Q)
    np.testing.assert_array_equal(m.noise(x[0]), Q)


# --------------------------------------------------------------------------------------------
# Filters read the replaced noise
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("filt", [KF(), EKF(), EKF(order=2), IEKF(), UKF(), CKF()],
                         ids=["KF", "EKF", "EKF2", "IEKF", "UKF", "CKF"])
def test_update_with_replaced_r_equals_a_sensor_built_with_that_r_linear(filt):
    built = Position(dim=2, sigma=[3.0, 0.5])
    wrapped = with_noise(Position(dim=2, sigma=1.0), np.diag([9.0, 0.25]))
    b = _prior(5)
    z = np.array([[1003.0, 1995.0]] * 5)
    pb, ib = filt.update(b, z, built)
    pw, iw = filt.update(b, z, wrapped)
    np.testing.assert_allclose(pw.mean, pb.mean, rtol=1e-14)
    np.testing.assert_allclose(pw.cov, pb.cov, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(iw.cov, ib.cov, rtol=1e-14)
    # and differs from the unreplaced sensor (the test can fail)
    po, _ = filt.update(b, z, Position(dim=2, sigma=1.0))
    assert not np.allclose(po.cov, pb.cov, rtol=1e-3)


@pytest.mark.parametrize("filt", [EKF(), EKF(order=2), UKF(), CKF()],
                         ids=["EKF", "EKF2", "UKF", "CKF"])
def test_update_with_replaced_r_equals_a_sensor_built_with_that_r_nonlinear(filt):
    built = AzimuthElevation((100.0, -50.0, -20.0), sigma_az=0.03, sigma_el=0.02)
    wrapped = with_noise(AzimuthElevation((100.0, -50.0, -20.0), sigma_az=0.01, sigma_el=0.01),
                         np.diag([0.03**2, 0.02**2]))
    b = _prior(4, n=6)
    z = built.h(b.mean) + np.array([0.01, -0.005])
    pb, ib = filt.update(b, z, built)
    pw, iw = filt.update(b, z, wrapped)
    np.testing.assert_allclose(pw.mean, pb.mean, rtol=1e-13)
    np.testing.assert_allclose(pw.cov, pb.cov, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(iw.nu, ib.nu, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(iw.cov, ib.cov, rtol=1e-13)


@pytest.mark.parametrize("filt", [KF(), EKF(), UKF()], ids=["KF", "EKF", "UKF"])
def test_predict_with_replaced_q_equals_a_model_built_with_that_q(filt):
    F = np.array([[1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 1.0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    Q = np.diag([0.3, 0.2, 0.1, 0.05])
    Q[0, 2] = Q[2, 0] = 0.02
    b = _prior(3)
    pb = filt.predict(b, LinearMotion(F, Q), 1.0)
    pw = filt.predict(b, with_noise(LinearMotion(F, np.eye(4)), Q), 1.0)
    np.testing.assert_allclose(pw.mean, pb.mean, rtol=1e-14)
    np.testing.assert_allclose(pw.cov, pb.cov, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(pb.cov[0], F @ b.cov[0] @ F.T + Q, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("filt", [KF(), EKF(), UKF()], ids=["KF", "EKF", "UKF"])
def test_batched_r_equals_row_by_row(filt):
    B = 4
    rng = np.random.default_rng(3)
    A = rng.normal(size=(B, 2, 2))
    R = A @ A.transpose(0, 2, 1) + np.eye(2)  # (B, 2, 2) SPD, one per row
    sensor = Position(dim=2, sigma=1.0)
    b = _prior(B)
    z = b.mean[:, :2] + rng.normal(0, 2, (B, 2))
    post, innov = filt.update(b, z, with_noise(sensor, R))
    for i in range(B):
        pi, ii = filt.update(b.at(i), z[i], with_noise(sensor, R[i]))
        np.testing.assert_allclose(post.mean[i], pi.mean, rtol=1e-13)
        np.testing.assert_allclose(post.cov[i], pi.cov, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(innov.cov[i], ii.cov, rtol=1e-13)
        # hand check: S = H P H^T + R_i
        H = np.eye(2, 4)
        np.testing.assert_allclose(ii.cov, H @ b.cov[i] @ H.T + R[i], rtol=1e-13)


@pytest.mark.parametrize("filt", [KF(), EKF(), UKF()], ids=["KF", "EKF", "UKF"])
def test_batched_q_equals_row_by_row(filt):
    B = 3
    F = np.eye(4) + np.eye(4, k=2)
    Qs = np.stack([np.diag([0.1, 0.2, 0.3, 0.4]) * (i + 1) for i in range(B)])
    b = _prior(B)
    pred = filt.predict(b, with_noise(LinearMotion(F, np.eye(4)), Qs), 1.0)
    for i in range(B):
        pi = filt.predict(b.at(i), LinearMotion(F, Qs[i]), 1.0)
        np.testing.assert_allclose(pred.mean[i], pi.mean, rtol=1e-14)
        np.testing.assert_allclose(pred.cov[i], pi.cov, rtol=1e-12, atol=1e-13)


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("R, match", [
    (np.eye(3), r"R has shape \(3, 3\)"),
    (np.ones(2), r"R has shape \(2,\)"),
    (np.ones((2, 3)), r"R has shape"),
    (np.ones((4, 2, 3)), r"R has shape"),
    (np.array([[1.0, 0.0], [0.0, np.nan]]), "R has non-finite"),
    (np.array([[np.inf, 0.0], [0.0, 1.0]]), "R has non-finite"),
])
def test_bad_r_raises(R, match):
    with pytest.raises(ValueError, match=match):
        with_noise(Position(dim=2, sigma=1.0), R)


@pytest.mark.parametrize("Q, match", [
    (np.eye(3), r"Q has shape \(3, 3\)"),
    (np.ones(4), r"Q has shape"),
    (np.full((4, 4), np.inf), "Q has non-finite"),
])
def test_bad_q_raises(Q, match):
    with pytest.raises(ValueError, match=match):
        with_noise(ConstantVelocity(dim=2, q=1.0), Q)


def test_neither_sensor_nor_motion_raises_type_error():
    with pytest.raises(TypeError, match="neither a sensor"):
        with_noise(object(), np.eye(2))
