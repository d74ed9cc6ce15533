"""Every bundled motion and sensor model reads its noise the same way (``noise_cov``) and
satisfies the Protocol the filters rely on (MotionModel, SensorModel); every filter is a
Filter."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters.base import Filter
from trackkit.identify.augmented import SampledVessel
from trackkit.models import motion as motion_module
from trackkit.models import sensors as sensor_module
from trackkit.models.manoeuvring import AugmentedVessel, reference_vessel

NORM = reference_vessel().norm
M = tk.models

MOTIONS = [
    M.LinearMotion(np.eye(2), 0.5 * np.eye(2)),
    M.ContinuousLinear(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]),
                       np.array([[2.0]])),
    M.ConstantVelocity(dim=2, q=1.5),
    M.ConstantAcceleration(dim=2, q=0.3),
    M.Singer(dim=2, tau=10.0, sigma=2.0),
    M.KnownTurnRate(omega=0.05, q=0.7),
    M.CoordinatedTurn(q=0.7, q_omega=1e-3),
    M.RandomSine(),
    M.Augmented(M.ConstantVelocity(dim=2, q=1.0), extras=1, q_extra=0.1),
    AugmentedVessel([0.1, 1500.0], NORM, q_body=1e-3, q_theta=1e-4),
    SampledVessel([0.1, 1500.0], [0.12, 1500.0], NORM, q_body=1e-3, q_theta=1e-4),
    M.with_noise(M.ConstantVelocity(dim=2, q=1.0), 2.0 * np.eye(4)),
]

SENSORS = [
    M.Position(dim=2, sigma=3.0),
    M.Bearing(origin=(10.0, -5.0), sigma=0.02),
    M.RangeBearing(sigma_range=5.0, sigma_bearing=0.01),
    M.AzimuthElevation(sigma_az=0.01, sigma_el=0.02),
    M.BearingFrequency(sigma_bearing=0.01, sigma_freq=0.2),
    M.MultipathDelay(origin=(0.0, 0.0, -10.0), sigma=1e-4),
    M.Sine(sigma=0.3),
    M.Stack((M.Position(dim=2, sigma=3.0), M.Bearing(sigma=0.02))),
    M.with_noise(M.Position(dim=2, sigma=1.0), np.diag([4.0, 9.0])),
]


def _state(model, seed=0):
    return np.random.default_rng(seed).normal(size=(3, model.dim_x)) + 50.0


def _classes(module, base):
    return {c for c in vars(module).values()
            if inspect.isclass(c) and issubclass(c, base) and c is not base
            and not c.__name__.startswith("_")}


def test_every_bundled_model_is_listed():
    """A new model must join the lists above, so the checks below cover it."""
    assert _classes(motion_module, M.MotionBase) <= {type(m) for m in MOTIONS}
    assert _classes(sensor_module, M.SensorBase) <= {type(s) for s in SENSORS}


@pytest.mark.parametrize("motion", MOTIONS, ids=lambda m: type(m).__name__)
def test_motion_noise_cov_is_q(motion):
    x = _state(motion)
    for dt in (0.5, np.array([0.1, 1.0, 2.0])):
        np.testing.assert_array_equal(motion.noise_cov(x, dt), motion.noise(x, dt))


@pytest.mark.parametrize("sensor", SENSORS, ids=lambda s: type(s).__name__)
def test_sensor_noise_cov_is_r(sensor):
    x = np.zeros((3, 6))
    assert sensor.noise_cov(x) is sensor.noise
    assert sensor.noise_cov() is sensor.noise


def test_noise_cov_sees_a_replaced_noise():
    cv = M.ConstantVelocity(dim=2, q=1.0)
    np.testing.assert_array_equal(M.with_noise(cv, 2.0 * np.eye(4)).noise_cov(None, 1.0),
                                  2.0 * np.eye(4))
    np.testing.assert_array_equal(M.with_noise(M.Position(dim=2), np.diag([4.0, 9.0]))
                                  .noise_cov(), np.diag([4.0, 9.0]))


@pytest.mark.parametrize("motion", MOTIONS, ids=lambda m: type(m).__name__)
def test_motion_models_satisfy_the_protocol(motion):
    assert isinstance(motion, M.MotionModel)
    assert not isinstance(motion, M.SensorModel)
    x = _state(motion)
    assert np.shape(motion.f(x, 0.5)) == x.shape
    n = motion.dim_x
    assert np.broadcast_shapes(np.shape(motion.jacobian(x, 0.5)), (3, n, n)) == (3, n, n)
    assert np.broadcast_shapes(np.shape(motion.noise(x, 0.5)), (3, n, n)) == (3, n, n)


@pytest.mark.parametrize("sensor", SENSORS, ids=lambda s: type(s).__name__)
def test_sensor_models_satisfy_the_protocol(sensor):
    assert isinstance(sensor, M.SensorModel)
    assert not isinstance(sensor, M.MotionModel)
    m = sensor.dim_z
    assert len(sensor.angular) == m and np.shape(sensor.noise)[-2:] == (m, m)


def test_a_duck_typed_model_satisfies_the_protocol_and_a_partial_one_does_not():
    class Duck:
        dim_x = 1

        def f(self, x, dt):
            return x

        def jacobian(self, x, dt):
            return np.eye(1)

        def noise(self, x, dt):
            return np.zeros((1, 1))

    class Lame:
        dim_x = 1

        def f(self, x, dt):
            return x

    assert isinstance(Duck(), M.MotionModel)
    assert not isinstance(Lame(), M.MotionModel)


def _filters():
    cv = M.ConstantVelocity(dim=2, q=1.0)
    F = tk.filters
    out = [F.KF(), F.EKF(), F.IEKF(), F.UKF(), F.CKF(), F.SRCKF(), F.PF(100),
           F.AlphaBeta(*tk.filters.alphabeta.kohn()), F.AlphaBetaGamma(0.5, 0.4, 0.1),
           F.IMM([cv, cv], F.KF(), np.array([[0.9, 0.1], [0.1, 0.9]])),
           F.MCEKF(), F.AMCEKF(), F.AEKF(), F.FuzzyAdaptive(),
           F.RPEKF(), F.MPEKF(), F.RangePF(), F.JTC(), F.MultiFilterJTC()]
    return out


def test_every_filter_satisfies_filter():
    filters = _filters()
    exported = {getattr(tk.filters, n) for n in tk.filters.__all__}
    classes = {c for c in exported if inspect.isclass(c) and hasattr(c, "predict")
               and hasattr(c, "update")}
    assert classes <= {type(f) for f in filters}
    for f in filters:
        assert isinstance(f, Filter), type(f).__name__
