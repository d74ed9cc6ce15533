"""The IMM's measurement prediction without an update (``IMM.measurement_prediction``): the
same zhat and S as the update at ``z0 = h(x-)`` (the mixture's innovation and its
covariance), which the multi-target tracker used before, on random predicted beliefs for a
range-bearing radar (bearings near +-pi, where the models' predicted bearings straddle the
cut) and a position sensor; the cases it declines (None), where the tracker takes the update
instead."""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.angles import wrap
from trackkit.filters.imm import IMM
from trackkit.tracking.tracker import Tracker

CV = tk.models.ConstantVelocity(dim=2, q=0.5)
CT = tk.models.CoordinatedTurn(q=0.5, q_omega=1e-3)
RADAR = tk.models.RangeBearing(origin=[100.0, -50.0], sigma_range=20.0,
                               sigma_bearing=np.deg2rad(0.5))
POS = tk.models.Position(dim=2, sigma=25.0)


def cv_ct(inner=None) -> IMM:
    return IMM([CV, CT], inner or tk.filters.EKF(), [[0.95, 0.05], [0.05, 0.95]],
               mu0=(0.9, 0.1))


def by_update(f, belief, sensor):
    """The update-based prediction: ``zhat = z0 - nu`` and S of the update at z0 = h(x-)."""
    z0 = np.asarray(sensor.h(f.estimate(belief).mean), dtype=float)
    _, innov = f.update(belief, z0, sensor)
    zhat = z0 - innov.nu
    ang = np.asarray(sensor.angular)
    zhat[..., ang] = wrap(zhat[..., ang])
    return zhat, innov.cov


def predicted(f: IMM, seed: int, T: int, behind: bool = False):
    """A predicted belief of T tracks with random means, covariances and mode probabilities
    (``behind``: every track just south of the radar, its bearing within 0.01 rad of pi,
    the models' east offsets of opposite signs)."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-8e3, 8e3, (T, 2)), rng.normal(0, 8, (T, 2)),
                         rng.normal(0, 0.02, T)])
    if behind:
        x[:, 0] = RADAR.origin[0] + rng.uniform(-20, 20, T)
        x[:, 1] = RADAR.origin[1] - rng.uniform(3e3, 6e3, T)
        x[:, 2] = 0.0
    L = rng.normal(0, 1, (T, 5, 5)) * np.array([30.0, 30.0, 3.0, 3.0, 0.01])[:, None]
    P = L @ L.mT + np.diag([100.0, 100.0, 1.0, 1.0, 1e-4])
    b = f.init(tk.Gaussian(x, P))
    mu = rng.dirichlet([1.0, 1.0], T)
    b = f.predict(b._replace(mu=mu), None, 3.0)
    if behind:  # the predicted CV a little east of the radar's meridian, CT a little west
        X = b.mean.copy()
        X[:, 0, 0] = RADAR.origin[0] + np.abs(X[:, 0, 0] - RADAR.origin[0]) + 1.0
        X[:, 1, 0] = RADAR.origin[0] - np.abs(X[:, 1, 0] - RADAR.origin[0]) - 1.0
        b = b._replace(mean=X)
    return b


def assert_same(fast, ref, ang):
    zf, Sf = fast
    zr, Sr = ref
    d = zf - zr
    d[..., ang] = wrap(d[..., ang])
    scale = np.where(ang, 1.0, np.abs(zr))
    assert (np.abs(d) <= 1e-12 * np.maximum(scale, 1.0)).all()
    np.testing.assert_allclose(Sf, Sr, rtol=1e-12, atol=0)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("sensor", [RADAR, POS], ids=["range-bearing", "position"])
def test_fast_prediction_equals_the_update_at_h_of_the_prediction(seed, sensor):
    f = cv_ct()
    b = predicted(f, seed, 60)
    fast = f.measurement_prediction(b, sensor)
    assert fast is not None
    assert_same(fast, by_update(f, b, sensor), np.asarray(sensor.angular))
    # (the same arithmetic: equal to the last bit)
    assert np.array_equal(fast[1], by_update(f, b, sensor)[1])


@pytest.mark.parametrize("seed", range(3))
def test_bearings_that_straddle_pi_are_wrapped_like_the_update(seed):
    f = cv_ct()
    b = predicted(f, seed, 40, behind=True)
    zj = [RADAR.h(g.mean)[:, 1] for g in f.model_estimates(b)]
    assert ((zj[0] > 3.1) & (zj[1] < -3.1)).all()  # the two models either side of the cut
    fast = f.measurement_prediction(b, RADAR)
    ref = by_update(f, b, RADAR)
    assert_same(fast, ref, np.array([False, True]))
    assert (np.abs(fast[0][:, 1]) > 3.1).all() and (np.abs(fast[0][:, 1]) <= np.pi).all()


def test_one_track_and_the_tracker_takes_it():
    f = cv_ct()
    b = predicted(f, 7, 1)
    trk = Tracker(f, None, RADAR, extra_mean=(0.0,), extra_std=(0.01,))
    assert_same(trk.measurement_prediction(b, RADAR), by_update(f, b, RADAR),
                np.array([False, True]))


@pytest.mark.parametrize("case", ["ukf", "ekf2", "kf-fast", "columns"])
def test_declined_cases_fall_back_to_the_update(case):
    """Filters whose zhat and S are not h(x-) and H P H^T + R (UKF, second-order EKF), the
    IMM's own KF fast path and the Kalman kernel for 1024 rows and more: None, and the
    tracker's prediction is the update's."""
    sensor, T = RADAR, 30
    if case == "ukf":
        f = cv_ct(tk.filters.UKF())
    elif case == "ekf2":
        f = cv_ct(tk.filters.EKF(order=2))
    elif case == "kf-fast":
        f = IMM([CV, tk.models.ConstantVelocity(dim=2, q=50.0)], tk.filters.KF(),
                [[0.9, 0.1], [0.1, 0.9]])
        sensor = POS
    else:
        f, sensor, T = cv_ct(), POS, 1100
    if case == "kf-fast":
        rng = np.random.default_rng(3)
        b = f.predict(f.init(tk.Gaussian(rng.normal(0, 1e3, (T, 4)),
                                         np.diag([400.0, 400.0, 25.0, 25.0]))), None, 3.0)
    else:
        b = predicted(f, 3, T)
    assert f.measurement_prediction(b, sensor) is None
    trk = Tracker(f, None, sensor)
    zhat, S = trk.measurement_prediction(b, sensor)
    zr, Sr = by_update(f, b, sensor)
    assert np.array_equal(zhat, zr) and np.array_equal(S, Sr)


@pytest.mark.parametrize("mu_ct", [0.3, 0.0])
def test_combined_mean_is_the_estimates_mean(mu_ct):
    """The combination's mean alone (for z0) equals ``estimate().mean`` bit for bit, also
    when the turn model's weight is exactly 0 (combine's limit)."""
    f = cv_ct()
    b = predicted(f, 11, 20)
    b = b._replace(mu=np.tile([1.0 - mu_ct, mu_ct], (20, 1)))
    assert np.array_equal(f._combined_mean(b), f.estimate(b).mean)
