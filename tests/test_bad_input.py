"""Bad input: filters reject wrong shapes, non-finite priors and
covariances that are not symmetric positive semi-definite with a ValueError that names the
quantity and the shapes; models reject invalid parameters at construction. Nothing is
silently repaired.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import trackkit as tk
from tests.test_filters import FILTERS
from trackkit.filters import EKF, IEKF, KF, UKF
from trackkit.models import (
    AzimuthElevation,
    Bearing,
    BearingFrequency,
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    KnownTurnRate,
    LinearMotion,
    MultipathDelay,
    Position,
    RandomSine,
    RangeBearing,
    Sine,
    Singer,
    Stack,
)

NAMES = list(FILTERS)

CV = ConstantVelocity(dim=2, q=0.1)
POS = Position(dim=2, sigma=1.0)


def _good(batch=()):
    mean = np.zeros(batch + (4,))
    cov = np.broadcast_to(np.diag([4.0, 4.0, 1.0, 1.0]), batch + (4, 4)).copy()
    return mean, cov


def _call(name, op, mean, cov, z=None):
    f = FILTERS[name]()
    b = tk.Gaussian(mean, cov)
    if op == "predict":
        return f.predict(b, CV, 1.0)
    return f.update(b, np.zeros(np.shape(mean)[:-1] + (2,)) if z is None else z, POS)


def _message(excinfo) -> str:
    return str(excinfo.value)


def _mentions_shape(msg: str, shape: tuple) -> bool:
    return str(tuple(shape)) in msg


OPS = ["predict", "update"]


# --------------------------------------------------------------------------------------------
# Shapes
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("batch", [(), (5,)])
def test_wrong_state_length_for_motion_model(name, batch):
    mean = np.zeros(batch + (3,))
    cov = np.broadcast_to(np.eye(3), batch + (3, 3)).copy()
    with pytest.raises(ValueError) as ei:
        _call(name, "predict", mean, cov)
    msg = _message(ei)
    assert "mean" in msg
    assert _mentions_shape(msg, mean.shape)
    assert "4" in msg  # the model's state length


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("zshape", [(3,), (1,), (5, 3), (5, 1)])
def test_measurement_with_wrong_number_of_components(name, zshape):
    mean, cov = _good((5,) if len(zshape) == 2 else ())
    with pytest.raises(ValueError) as ei:
        _call(name, "update", mean, cov, z=np.zeros(zshape))
    msg = _message(ei)
    assert re.search(r"\bz\b", msg)
    assert _mentions_shape(msg, zshape)
    assert "2" in msg  # the sensor's measurement length


@pytest.mark.parametrize("name", NAMES)
def test_measurement_batch_shape_not_matching_belief(name):
    mean, cov = _good((5,))
    with pytest.raises(ValueError) as ei:
        _call(name, "update", mean, cov, z=np.zeros((3, 2)))
    msg = _message(ei)
    assert re.search(r"\bz\b", msg), msg
    assert _mentions_shape(msg, (3, 2)), msg


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
def test_mean_cov_trailing_shape_mismatch(name, op):
    mean = np.zeros(4)
    cov = np.eye(3)
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "cov" in msg
    assert _mentions_shape(msg, cov.shape)
    assert "4" in msg


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
def test_mean_cov_batch_shape_mismatch(name, op):
    # 5 means and 3 covariances do not describe one batch of beliefs: rejected, naming both
    mean, _ = _good((5,))
    _, cov = _good((3,))
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "mean" in msg and "cov" in msg, msg
    assert ("(5,)" in msg or "(5, 4)" in msg) and ("(3,)" in msg or "(3, 4, 4)" in msg), msg


@pytest.mark.parametrize("name", NAMES)
def test_shared_covariance_broadcasts(name):
    # one covariance shared by a batch of means is a valid belief (tk.check_gaussian accepts
    # batch shapes that broadcast), so every filter must handle it like per-row copies
    mean, _ = _good((5,))
    mean[:, 0] = np.arange(5.0)
    _, cov = _good(())
    tk.check_gaussian(mean, cov)
    b = _call(name, "predict", mean, cov)
    ref = _call(name, "predict", mean, np.broadcast_to(cov, (5, 4, 4)).copy())
    np.testing.assert_allclose(b.mean, ref.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.broadcast_to(b.cov, (5, 4, 4)), ref.cov, rtol=1e-12,
                               atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_scalar_mean_rejected(name):
    with pytest.raises(ValueError, match="mean"):
        _call(name, "predict", np.float64(1.0), np.eye(1))


# --------------------------------------------------------------------------------------------
# Non-finite, asymmetric, non-PSD priors
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_prior_mean(name, op, bad):
    mean, cov = _good((3,))
    mean[1, 2] = bad
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "mean" in msg and "non-finite" in msg


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_prior_cov(name, op, bad):
    mean, cov = _good((3,))
    cov[2, 1, 1] = bad
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "cov" in msg and "non-finite" in msg


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
def test_non_symmetric_prior_cov_is_rejected_not_symmetrised(name, op):
    mean, cov = _good((3,))
    cov[1, 0, 2] += 0.5  # cov[1] is no longer symmetric
    before = cov.copy()
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "cov" in msg and "not symmetric" in msg
    assert "(1,)" in msg  # the offending batch row
    np.testing.assert_array_equal(cov, before)  # and the input was not modified


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("op", OPS)
def test_non_psd_prior_cov(name, op):
    mean, cov = _good((3,))
    cov[0, 0, 1] = cov[0, 1, 0] = 10.0  # |rho| > 1
    with pytest.raises(ValueError) as ei:
        _call(name, op, mean, cov)
    msg = _message(ei)
    assert "cov" in msg and "positive semi-definite" in msg


@pytest.mark.parametrize("name", NAMES)
def test_unbatched_bad_cov_names_the_filter_and_step(name):
    mean, cov = _good(())
    cov[0, 0] = -1.0
    with pytest.raises(ValueError) as ei:
        _call(name, "predict", mean, cov)
    msg = _message(ei)
    assert FILTERS[name]().name in msg and "predict" in msg


def test_check_gaussian_rejects_and_reports():
    with pytest.raises(ValueError, match="prior.mean has non-finite"):
        tk.check_gaussian([0.0, np.nan], np.eye(2), "prior")
    with pytest.raises(ValueError, match=r"prior.cov has shape \(3, 3\)"):
        tk.check_gaussian([0.0, 0.0], np.eye(3), "prior")
    with pytest.raises(ValueError, match="do not broadcast"):
        tk.check_gaussian(np.zeros((5, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)), "prior")
    with pytest.raises(ValueError, match="not symmetric"):
        tk.check_gaussian([0.0, 0.0], [[1.0, 0.1], [0.0, 1.0]], "prior")
    g = tk.check_gaussian([0.0, 0.0], np.eye(2), "prior")
    assert g.mean.dtype == np.float64


# --------------------------------------------------------------------------------------------
# KF with nonlinear models
# --------------------------------------------------------------------------------------------


def test_kf_rejects_nonlinear_motion_with_type_error():
    mean = np.zeros(5)
    cov = np.eye(5)
    with pytest.raises(TypeError, match="CoordinatedTurn"):
        KF().predict(tk.Gaussian(mean, cov), CoordinatedTurn(), 1.0)


@pytest.mark.parametrize("sensor", [Bearing(), RangeBearing(), Stack((POS, Bearing()))])
def test_kf_rejects_nonlinear_sensor_with_type_error(sensor):
    mean, cov = _good(())
    mean[:2] = [10.0, 20.0]
    with pytest.raises(TypeError, match="nonlinear"):
        KF().update(tk.Gaussian(mean, cov), np.zeros(sensor.dim_z), sensor)


def test_kf_accepts_linear_models():
    mean, cov = _good(())
    b = KF().predict(tk.Gaussian(mean, cov), LinearMotion(np.eye(4), 0.1 * np.eye(4)), 1.0)
    KF().update(b, np.zeros(4), Stack((POS, Position(dim=2, sigma=2.0))))


# --------------------------------------------------------------------------------------------
# Model and filter constructors
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: Position(dim=2, sigma=0.0), "sigma"),
        (lambda: Position(dim=2, sigma=-1.0), "sigma"),
        (lambda: Position(dim=2, sigma=[1.0, 0.0]), "sigma"),
        (lambda: Position(dim=2, sigma=[1.0, 2.0, 3.0]), "sigma"),
        (lambda: Position(dim=2, sigma=np.nan), "sigma"),
        (lambda: Bearing(sigma=0.0), "sigma"),
        (lambda: Bearing(sigma=-0.01), "sigma"),
        (lambda: RangeBearing(sigma_range=-1.0), "sigma_range"),
        (lambda: RangeBearing(sigma_bearing=0.0), "sigma_bearing"),
        (lambda: AzimuthElevation(sigma_az=0.0), "sigma_az"),
        (lambda: AzimuthElevation(sigma_el=-1.0), "sigma_el"),
        (lambda: BearingFrequency(sigma_freq=0.0), "sigma_freq"),
        (lambda: BearingFrequency(sigma_bearing=-0.1), "sigma_bearing"),
        (lambda: BearingFrequency(c=0.0), "c"),
        (lambda: MultipathDelay(sigma=-1e-4), "sigma"),
        (lambda: MultipathDelay(h_surface=0.0), "h_surface"),
        (lambda: MultipathDelay(h_bottom=-5.0), "h_bottom"),
        (lambda: MultipathDelay(c=np.inf), "c"),
        (lambda: Sine(sigma=0.0), "sigma"),
    ],
)
def test_sensor_constructors_reject_non_positive_noise(make, field):
    with pytest.raises(ValueError) as ei:
        make()
    assert re.search(rf"\b{field}\b", str(ei.value)), str(ei.value)


@pytest.mark.parametrize(
    "make, fragment",
    [
        (lambda: Bearing(convention="compass"), "convention"),
        (lambda: RangeBearing(convention="degrees"), "convention"),
        (lambda: AzimuthElevation(convention="NAUTICAL"), "convention"),
        (lambda: Bearing(origin=(0.0, 0.0, 0.0)), "origin"),
        (lambda: AzimuthElevation(origin=(0.0, 0.0)), "origin"),
        (lambda: BearingFrequency(velocity=(1.0,)), "velocity"),
        (lambda: Bearing(origin=(np.nan, 0.0)), "origin"),
        (lambda: Position(dim=4), "dim"),
        (lambda: Position(dim=0), "dim"),
        (lambda: Stack(()), "empty"),
    ],
)
def test_sensor_constructors_reject_bad_options(make, fragment):
    with pytest.raises(ValueError, match=fragment):
        make()


@pytest.mark.parametrize(
    "make, fragment",
    [
        (lambda: ConstantVelocity(dim=4), "dim"),
        (lambda: ConstantVelocity(dim=0), "dim"),
        (lambda: ConstantAcceleration(dim=5), "dim"),
        (lambda: Singer(dim=0), "dim"),
        (lambda: ConstantVelocity(dim=2, q=-1.0), "q"),
        (lambda: ConstantVelocity(dim=2, q=[1.0, -1.0]), "q"),
        (lambda: ConstantVelocity(dim=2, q=[1.0, 1.0, 1.0]), "q"),
        (lambda: ConstantVelocity(dim=2, q=np.nan), "q"),
        (lambda: ConstantAcceleration(dim=2, q=-0.5), "q"),
        (lambda: Singer(tau=0.0), "tau"),
        (lambda: Singer(tau=-5.0), "tau"),
        (lambda: Singer(tau=np.inf), "tau"),
        (lambda: Singer(sigma=-1.0), "sigma"),
        (lambda: LinearMotion(np.eye(3), np.eye(2)), "F"),
    ],
)
def test_motion_constructors_reject_bad_parameters(make, fragment):
    with pytest.raises(ValueError, match=fragment):
        make()


@pytest.mark.parametrize(
    "make, fragment",
    [
        (lambda: CoordinatedTurn(q=-1.0), "q"),
        (lambda: CoordinatedTurn(q_omega=-1e-4), "q_omega"),
        (lambda: CoordinatedTurn(q_omega=np.nan), "q_omega"),
        (lambda: KnownTurnRate(omega=0.1, q=-1.0), "q"),
        (lambda: KnownTurnRate(omega=np.nan), "omega"),
        (lambda: RandomSine(q1=-0.2), "q1"),
        (lambda: RandomSine(q2=-0.1), "q2"),
    ],
)
def test_turn_and_sine_models_reject_invalid_noise_at_construction(make, fragment):
    # like ConstantVelocity(q=-1): a negative noise density is an invalid model, and must not
    # wait to surface (or not) as a non-PSD Q in some later filter step
    with pytest.raises(ValueError, match=fragment):
        make()


@pytest.mark.parametrize(
    "make, fragment",
    [
        (lambda: EKF(order=3), "order"),
        (lambda: EKF(order=0), "order"),
        (lambda: IEKF(iterations=0), "iterations"),
        (lambda: IEKF(iterations=2.5), "iterations"),
        (lambda: UKF(alpha=0.0), "alpha"),
        (lambda: UKF(alpha=np.nan), "alpha"),
        (lambda: UKF(beta=np.inf), "beta"),
    ],
)
def test_filter_constructors_reject_bad_options(make, fragment):
    with pytest.raises(ValueError, match=fragment):
        make()


def test_ukf_rejects_non_positive_spread():
    # n + lambda <= 0 makes the sigma-point spread imaginary: reported, not repaired
    f = UKF(alpha=0.5, kappa=-4.0)
    mean, cov = _good(())
    with pytest.raises(ValueError, match="lambda"):
        f.predict(tk.Gaussian(mean, cov), CV, 1.0)


def test_sensor_state_length_check():
    with pytest.raises(ValueError, match="f0"):
        EKF().update(tk.Gaussian(*_good(())), np.zeros(2), BearingFrequency())


# -- the Python API: cheap checks at construction, bad dt and inf in z ---------------


@pytest.mark.parametrize(
    "mean, cov, words",
    [
        ([np.nan, 0.0], np.eye(2), ["Gaussian.mean", "nan", "(0,)", "finite"]),
        ([0.0, 0.0], [[1.0, 0.0], [0.0, np.inf]], ["Gaussian.cov", "inf", "(1, 1)"]),
        ([0.0, 0.0], np.eye(3), ["Gaussian.cov", "(3, 3)", "(..., 2, 2)"]),
        (0.0, np.eye(1), ["Gaussian.mean", "scalar"]),
        (np.zeros((3, 2)), np.zeros((4, 2, 2)), ["(3,)", "(4,)", "broadcast"]),
        (np.zeros(2), np.tile(np.eye(2), (3, 1, 1)), ["one mean per covariance"]),
        ([0.0, 0.0], [1.0, 1.0], ["Gaussian.cov", "(2,)"]),
    ],
)
def test_gaussian_checks_shapes_and_finiteness_at_construction(mean, cov, words):
    with pytest.raises(ValueError) as err:
        tk.Gaussian(mean, cov)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_gaussian_leaves_the_costly_checks_to_the_filters():
    # an asymmetric or indefinite covariance is accepted at construction (an eigen-
    # decomposition per belief would cost more than a filter step) and refused where a filter
    # takes it in, naming the quantity
    for cov in ([[1.0, 0.5], [0.0, 1.0]], [[1.0, 0.0], [0.0, -1.0]]):
        b = tk.Gaussian(np.zeros(2), cov)
        with pytest.raises(ValueError, match="cov"):
            EKF().update(b, np.zeros(2), Position(dim=2, sigma=1.0))
    # lists become float arrays; an integer mean too
    b = tk.Gaussian([1, 2], [[1, 0], [0, 1]])
    assert b.mean.dtype == b.cov.dtype == np.float64


def test_gaussian_unchecked_constructor_keeps_what_a_filter_produced():
    # a diverging filter's nan must reach the metrics, not stop a Monte Carlo study
    b = tk.Gaussian._make((np.array([np.nan, 0.0]), np.eye(2)))
    assert np.isnan(b.mean[0]) and type(b) is tk.Gaussian
    assert type(tk.Gaussian(np.zeros((3, 2)), np.tile(np.eye(2), (3, 1, 1))).at(1)) is tk.Gaussian


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("dt", [np.nan, np.inf, -1.0, np.array([1.0, np.nan, 1.0])])
def test_predict_refuses_a_bad_time_step(name, dt):
    f = FILTERS[name]()
    b = tk.Gaussian(*_good((3,)))
    with pytest.raises(ValueError, match=r"predict.*dt"):
        f.predict(f.init(b) if hasattr(f, "init") else b, CV, dt)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("batch", [(), (3,)])
def test_update_refuses_inf_in_z_and_keeps_nan_as_missing(name, batch):
    f = FILTERS[name]()
    b = tk.Gaussian(*_good(batch))
    b = f.init(b) if hasattr(f, "init") else b
    z = np.zeros(batch + (2,))
    z[..., 1] = np.inf
    with pytest.raises(ValueError, match="z has an infinite entry"):
        f.update(b, z, POS)
    z[..., 1] = np.nan  # missing: the prediction comes back
    post, innov = f.update(b, z, POS)
    est = f.estimate(post) if hasattr(f, "estimate") else post
    np.testing.assert_array_equal(est.mean, _good(batch)[0])
