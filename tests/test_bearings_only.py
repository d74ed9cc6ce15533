"""The bearings-only specialists: the range-parameterised EKF and the
modified-polar EKF, their kernels, Jacobians, batching and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import trackkit as tk
from trackkit.filters.bearings_only import (
    MPEKF,
    RPEKF,
    MPBelief,
    PendingParticles,
    RangeBankBelief,
    RangePF,
    cartesian_to_mpc,
    mpc_from_bearing,
    mpc_from_relative,
    mpc_to_cartesian,
    mpc_transition,
    range_split,
)

SIGMA = np.deg2rad(1.0)
CV = tk.models.ConstantVelocity(dim=2, q=1e-4)
P0 = np.diag([2000.0**2, 2000.0**2, 16.0, 16.0])


def _mpc_state(draw_or_rng) -> np.ndarray:
    """A plausible MPC state: any bearing, rates of a target 2-30 km away at < 20 m/s."""
    rng = draw_or_rng
    r = rng.uniform(2e3, 3e4)
    vrel = rng.uniform(-20, 20, 2)
    b = rng.uniform(-np.pi, np.pi)
    rel = np.concatenate([r * np.array([np.sin(b), np.cos(b)]), vrel])
    return mpc_from_relative(rel)[0]


def _observer(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An observer that manoeuvres: position and velocity at times t (a weave)."""
    pos = np.stack([4.0 * t + 300.0 * np.sin(t / 200.0), 2.0 * t + 150.0 * np.cos(t / 90.0)], -1)
    vel = np.stack([4.0 + 1.5 * np.cos(t / 200.0), 2.0 - 150.0 / 90.0 * np.sin(t / 90.0)], -1)
    return pos, vel


def _close_columns(a: np.ndarray, b: np.ndarray, rtol: float) -> None:
    """``|a - b| <= rtol * max|b|`` column by column (each MPC component has its own
    scale: 1/r is 1e-4, a rate 1e-3)."""
    scale = np.abs(b).max(0)
    assert np.all(np.abs(a - b) <= rtol * scale), np.abs(a - b).max(0) / scale


# --------------------------------------------------------------------------------------------
# Modified polar coordinates: kernels
# --------------------------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), dt=st.floats(0.0, 60.0),
       dp=st.tuples(st.floats(-500, 500), st.floats(-500, 500)),
       dv=st.tuples(st.floats(-5, 5), st.floats(-5, 5)))
def test_mpc_transition_jacobian_matches_finite_differences(num, seed, dt, dp, dv):
    y = _mpc_state(np.random.default_rng(seed))

    def f(Y):
        return mpc_transition(Y, dt, np.array(dp), np.array(dv))[0]

    def diff(a, b):
        d = a - b
        d[..., 0] = tk.angles.wrap(d[..., 0])
        return d

    # steps relative to each component's own size (1/r is 1e-4, a rate 1e-3): 1e-4 of it
    # keeps rounding (eps |y'| / step) and truncation (step^2) both below 1e-7
    J = mpc_transition(y, dt, np.array(dp), np.array(dv))[1]
    Jfd = num.jac(f, y, h=1e-4, diff=diff, floor=1e-12)
    num.close(J, Jfd, rtol=1e-6, what="d y'/d y", per_row=True)


@pytest.mark.parametrize("seed", range(5))
def test_polar_conversions_jacobians_match_finite_differences_and_round_trip(num, seed):
    rng = np.random.default_rng(seed)
    y = _mpc_state(rng)
    o, vo = rng.normal(0, 1e3, 2), rng.normal(0, 5, 2)
    x, Jx = mpc_to_cartesian(y, o, vo)
    num.close(Jx, num.jac(lambda Y: mpc_to_cartesian(Y, o, vo)[0], y, h=1e-4, floor=1e-12),
              rtol=1e-6, what="d x / d y", per_row=True)
    y2, Jy = cartesian_to_mpc(x, o, vo)

    def diff(a, b):
        d = a - b
        d[..., 0] = tk.angles.wrap(d[..., 0])
        return d

    num.close(Jy, num.jac(lambda X: cartesian_to_mpc(X, o, vo)[0], x, diff=diff), rtol=1e-6,
              what="d y / d x", per_row=True)
    # round trip, and the two Jacobians are inverses
    np.testing.assert_allclose(tk.angles.wrap(y2 - y), 0.0, atol=1e-12 * np.abs(y).max())
    np.testing.assert_allclose(Jy @ Jx, np.eye(4), atol=1e-9)


def test_mpc_transition_is_exact_for_a_cv_target_and_a_manoeuvring_observer():
    """The MPC of the true relative state at t + dt equals the transition of the MPC at t,
    whatever the observer does in between (it enters only through dp, dv)."""
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0, 2000, 40))
    target = np.array([3e3, 1.5e4, -4.0, -2.5])
    p_t = target[:2] + t[:, None] * target[2:]
    o, vo = _observer(t)
    rel = np.concatenate([p_t - o, target[2:] - vo], -1)
    y = mpc_from_relative(rel)[0]
    dt = np.diff(t)
    dp = o[1:] - o[:-1] - vo[:-1] * dt[:, None]
    dv = vo[1:] - vo[:-1]
    y_next, _ = mpc_transition(y[:-1], dt, dp, dv)
    np.testing.assert_allclose(tk.angles.wrap(y_next[:, 0] - y[1:, 0]), 0.0, atol=1e-12)
    _close_columns(y_next[:, 1:], y[1:, 1:], 1e-12)
    # predicting with the observer at constant velocity, then moving the frame to its true
    # pose, is the same map
    y_pred, _ = mpc_transition(y[:-1], dt)
    y_shift, _ = mpc_transition(y_pred, 0.0, dp, dv)
    np.testing.assert_allclose(tk.angles.wrap(y_shift[:, 0] - y[1:, 0]), 0.0, atol=1e-12)
    _close_columns(y_shift[:, 1:], y[1:, 1:], 1e-12)


# --------------------------------------------------------------------------------------------
# MPEKF
# --------------------------------------------------------------------------------------------


def _bearings(truth: np.ndarray, o: np.ndarray) -> np.ndarray:
    d = truth[..., :2] - o
    return np.arctan2(d[..., 0], d[..., 1])[..., None]


def test_mpekf_tracks_a_noise_free_target_exactly_through_observer_manoeuvres():
    """With an almost-certain prior and no noise, every step of the filter (the first
    conversion, the exact prediction, the frame shift at each update, the bearing update)
    keeps the estimate on the truth."""
    motion = tk.models.ConstantVelocity(dim=2, q=0.0)
    dt = 7.0
    t = np.arange(1, 120) * dt
    o, vo = _observer(t)
    x0 = np.array([3e3, 1.5e4, -4.0, -2.5])
    truth = np.concatenate([x0[:2] + t[:, None] * x0[2:], np.tile(x0[2:], (t.size, 1))], -1)
    f = MPEKF()
    b = f.init(tk.Gaussian(x0, np.diag([1e-2, 1e-2, 1e-8, 1e-8])))  # at t = 0
    for k in range(t.size):
        b = f.predict(b, motion, dt)
        sensor = tk.models.Bearing(o[k], SIGMA, velocity=vo[k])
        b, innov = f.update(b, _bearings(truth[k], o[k]), sensor)
        g = f.estimate(b)
        np.testing.assert_allclose(g.mean, truth[k], rtol=1e-9, atol=1e-6)
    assert isinstance(b, MPBelief) and b.polar.all()
    np.testing.assert_allclose(b.origin, o[-1]), np.testing.assert_allclose(b.velocity, vo[-1])


def test_mpekf_update_is_linear_in_the_bearing_and_estimate_is_the_jacobian_transform(num):
    rng = np.random.default_rng(2)
    y = _mpc_state(rng)
    P = num.spd(rng, (), 4) * np.outer(np.abs(y) + 1e-5, np.abs(y) + 1e-5) * 1e-4
    o, vo = np.array([100.0, -50.0]), np.array([3.0, 1.0])
    b = MPBelief(y, P, o, vo, np.array(True))
    z = np.array([y[0] + 0.01])
    sensor = tk.models.Bearing(o, SIGMA, velocity=vo)
    post, innov = MPEKF().update(b, z, sensor)
    # the Kalman update with H = [1, 0, 0, 0] (no frame shift: the sensor is at the pose)
    H = np.array([[1.0, 0, 0, 0]])
    S = H @ P @ H.T + SIGMA**2
    K = P @ H.T / S
    np.testing.assert_allclose(post.mean, y + (K * 0.01)[:, 0], rtol=1e-12)
    Pj = (np.eye(4) - K @ H) @ P @ (np.eye(4) - K @ H).T + K @ K.T * SIGMA**2
    np.testing.assert_allclose(post.cov, Pj, rtol=1e-9, atol=1e-12 * np.abs(Pj).max())
    np.testing.assert_allclose(innov.nu, [0.01], rtol=1e-12)
    np.testing.assert_allclose(innov.cov, S, rtol=1e-12)
    g = MPEKF().estimate(post)
    x, J = mpc_to_cartesian(post.mean, o, vo)
    np.testing.assert_allclose(g.mean, x, rtol=1e-12)
    np.testing.assert_allclose(g.cov, J @ post.cov @ J.T, rtol=1e-9,
                               atol=1e-12 * np.abs(g.cov).max())
    # a "math" sensor measures pi/2 - beta: the same information
    zm = tk.angles.wrap(np.pi / 2 - z)
    mpost, minnov = MPEKF().update(b, zm, tk.models.Bearing(o, SIGMA, convention="math",
                                                            velocity=vo))
    np.testing.assert_allclose(mpost.mean, post.mean, rtol=1e-12)
    np.testing.assert_allclose(minnov.nu, -innov.nu, rtol=1e-12)


def test_mpekf_first_update_carries_the_prior_into_polar_coordinates():
    """At the first bearing the Cartesian prior is converted at the sensor's pose; for a
    tight prior the start from the bearing equals the Jacobian conversion."""
    x = np.array([2e3, 1.2e4, -3.0, 1.0])
    P = np.diag([1.0, 1.0, 1e-4, 1e-4])
    o, vo = np.array([50.0, 10.0]), np.array([2.0, 3.0])
    b = MPEKF().init(tk.Gaussian(x, P))
    assert not b.polar
    z = np.array([np.nan])
    same, innov = MPEKF().update(b, z, tk.models.Bearing(o, SIGMA, velocity=vo))
    assert not same.polar and np.array_equal(same.mean, x) and np.isnan(innov.nu).all()
    z = _bearings(x, o)
    post, _ = MPEKF().update(b, z, tk.models.Bearing(o, SIGMA, velocity=vo))
    assert post.polar
    y, J = cartesian_to_mpc(x, o, vo)
    # z is the prior's own bearing: the update leaves the mean where the conversion put it
    # (up to the cubature's second-order terms, relative (sigma / r)^2 ~ 1e-8)
    np.testing.assert_allclose(post.mean, y, rtol=1e-6)
    g = MPEKF().estimate(post)
    np.testing.assert_allclose(g.mean, x, rtol=1e-6)


def _posterior_range_by_grid(x, P, o, z, var_z):
    """Mean and deviation of the range, and mean bearing, of ``N(x_p, P_pp)`` times the
    bearing's likelihood, on a fine polar grid (area ``r dr db``, exact geometry)."""
    r = np.linspace(1e-3, 2.5e4, 5001)
    b = z + np.sqrt(var_z) * np.linspace(-9.0, 9.0, 721)
    R, B = np.meshgrid(r, b, indexing="ij")
    d = np.stack([o[0] + R * np.sin(B), o[1] + R * np.cos(B)], -1) - x[:2]
    q = np.einsum("...i,ij,...j->...", d, np.linalg.inv(P[:2, :2]), d)
    w = R * np.exp(-0.5 * (q - q.min())) * np.exp(-0.5 * (B - z) ** 2 / var_z)
    w /= w.sum()
    rbar = (w * R).sum()
    return rbar, np.sqrt((w * (R - rbar) ** 2).sum()), (w * B).sum()


@pytest.mark.parametrize("ahead", [5e3, 1.5e3, -1e3])
def test_mpc_from_bearing_takes_the_range_given_the_bearing(ahead):
    """A prior 2 km along the line of sight, 150 m across, its mean 5 km, 1.5 km or -1 km
    (behind the observer) along it: the start's range ``1 / w`` and its spread ``sqrt(P_ww)
    / w^2`` are the posterior range's mean and deviation given the first bearing (a fine
    polar grid of the prior times the likelihood), w > 0 every time, and 1 / r starts
    uncorrelated with the rest."""
    o, vo = np.array([100.0, -200.0]), np.array([2.0, -1.0])
    los = np.deg2rad(35.0)
    u, up = np.array([np.sin(los), np.cos(los)]), np.array([np.cos(los), -np.sin(los)])
    P = np.zeros((4, 4))
    P[:2, :2] = 2000.0**2 * np.outer(u, u) + 150.0**2 * np.outer(up, up)
    P[2:, 2:] = 4.0 * np.eye(2)
    P[:2, 2:] = P[2:, :2] = 0.3 * 2000.0 * 2.0 * np.outer(u, u)  # range and velocity
    x = np.concatenate([o + ahead * u + 80.0 * up, [1.0, -3.0]])
    z, var_z = los + 0.01, np.deg2rad(1.5) ** 2
    y, Py = mpc_from_bearing(x, P, z, var_z, o, vo)
    rbar, sigma_r, bbar = _posterior_range_by_grid(x, P, o, z, var_z)
    assert y[3] > 0
    assert 1.0 / y[3] == pytest.approx(rbar, rel=5e-4)
    assert np.sqrt(Py[3, 3]) / y[3] ** 2 == pytest.approx(sigma_r, rel=5e-4)
    assert abs(y[0] - bbar) < 0.03 * np.sqrt(var_z)
    assert np.all(Py[3, :3] == 0) and np.all(Py[:3, 3] == 0)
    assert np.all(np.linalg.eigvalsh(Py) > 0)


def test_mpekf_first_update_reports_the_cartesian_priors_innovation():
    """The first bearing starts the MPC state (it is in the start, not applied twice); the
    step's innovation is the one an EKF on the Cartesian prior reports."""
    x = np.array([-1e3, 6e3, 1.0, -2.0])
    P = np.diag([1500.0**2, 2500.0**2, 4.0, 4.0])
    o, vo = np.array([50.0, 10.0]), np.array([2.0, 3.0])
    sensor = tk.models.Bearing(o, SIGMA, velocity=vo)
    z = _bearings(x, o) + 0.02
    post, innov = MPEKF().update(MPEKF().init(tk.Gaussian(x, P)), z, sensor)
    _, ekf = tk.filters.EKF().update(tk.Gaussian(x, P), z, sensor)
    np.testing.assert_allclose(innov.nu, ekf.nu, rtol=1e-12)
    np.testing.assert_allclose(innov.cov, ekf.cov, rtol=1e-12)
    y, Py = mpc_from_bearing(x, P, z[0], SIGMA**2, o, vo)
    np.testing.assert_array_equal(post.mean, y)
    np.testing.assert_array_equal(post.cov, Py)


def test_mpekf_batched_rows_equal_single_rows_with_missing_and_per_run_observers():
    rng = np.random.default_rng(5)
    runs = 3
    x0 = np.array([[0.0, 1.2e4, 5.0, -1.0], [2e3, 9e3, -2.0, 0.5], [-3e3, 1.5e4, 1.0, 1.0]])
    P = np.tile(P0, (runs, 1, 1))
    f = MPEKF()
    b = f.init(tk.Gaussian(x0, P))
    singles = [f.init(tk.Gaussian(x0[i], P0)) for i in range(runs)]
    t = np.arange(1, 41) * 10.0
    o, vo = _observer(t)
    offsets = np.array([[0.0, 0.0], [100.0, -300.0], [-50.0, 20.0]])
    for k in range(t.size):
        z = rng.normal(0.3, 0.2, (runs, 1))
        if k in (0, 5):
            z[1] = np.nan  # row 1 starts late and misses another bearing
        sensor = tk.models.Bearing(o[k] + offsets, SIGMA, velocity=np.tile(vo[k], (runs, 1)))
        b = f.predict(b, CV, 10.0)
        b, innov = f.update(b, z, sensor)
        for i in range(runs):
            singles[i] = f.predict(singles[i], CV, 10.0)
            singles[i], inn_i = f.update(singles[i], z[i], tk.models.Bearing(
                o[k] + offsets[i], SIGMA, velocity=vo[k]))
            np.testing.assert_allclose(b.mean[i], singles[i].mean, rtol=1e-12, atol=1e-300)
            np.testing.assert_allclose(b.cov[i], singles[i].cov, rtol=1e-9,
                                       atol=1e-12 * np.abs(singles[i].cov).max())
            np.testing.assert_array_equal(np.isnan(innov.nu[i]),
                                          np.isnan(inn_i.nu))
        if k == 0:
            assert b.polar.tolist() == [True, False, True]
    g = f.estimate(b)
    for i in range(runs):
        gi = f.estimate(singles[i])
        np.testing.assert_allclose(g.mean[i], gi.mean, rtol=1e-12)


# --------------------------------------------------------------------------------------------
# Range-parameterised EKF
# --------------------------------------------------------------------------------------------


def _mixture_moments(X, P, logw):
    w = np.exp(logw)
    m = np.einsum("...c,...cn->...n", w, X)
    d = X - m[..., None, :]
    C = np.einsum("...c,...cab->...ab", w, P + d[..., :, None] * d[..., None, :])
    return m, C


@pytest.mark.parametrize("components", [1, 4, 16, 40])
def test_range_split_keeps_the_priors_mean_and_covariance(components):
    rng = np.random.default_rng(components)
    o = np.array([100.0, -200.0])
    mean = np.array([3e3, 3e4, -2.0, 4.0])  # 6 sigma of range inside (0, 2 rbar)
    A = rng.normal(size=(4, 4)) * [1e3, 1e3, 2.0, 2.0]
    cov = A @ A.T + P0
    X, P, logw = range_split(mean, cov, o, components, n_sigma=6.0)
    assert X.shape == (components, 4) and P.shape == (components, 4, 4)
    np.testing.assert_allclose(np.exp(logw).sum(), 1.0, rtol=1e-12)
    m, C = _mixture_moments(X, P, logw)
    # everything beyond 6 sigma (2e-9 of the mass) is dropped
    assert np.all(np.abs(m - mean) <= 1e-6 * np.sqrt(np.diag(cov)))
    np.testing.assert_allclose(C, cov, rtol=1e-6, atol=1e-6 * np.abs(cov).max())
    for Pi in P:
        assert np.linalg.eigvalsh(Pi)[0] > 0


def test_range_split_lies_on_a_geometric_grid_with_constant_coefficient_of_variation():
    """A prior far wider than the interval (the classic RPEKF's uninformative range): the
    components sit on the line of sight with ranges in a constant ratio and range spreads a
    constant fraction (rho - 1) / ((rho + 1) sqrt 3) of their ranges; the weights follow the
    cells' widths."""
    o = np.array([0.0, 0.0])
    mean = np.array([0.0, 1e4, 0.0, 0.0])
    cov = np.diag([1e14, 1e14, 1.0, 1.0])  # flat to 1e-5 over the interval
    C, lo, hi = 12, 2e3, 4e4
    X, P, logw = range_split(mean, cov, o, C, r_min=lo, r_max=hi)
    r = X[:, 1]
    np.testing.assert_allclose(X[:, 0], 0.0, atol=1e-9)
    rho = (hi / lo) ** (1 / C)
    edges = lo * rho ** np.arange(C + 1)
    np.testing.assert_allclose(r, 0.5 * (edges[1:] + edges[:-1]), rtol=1e-6)
    cv = np.sqrt(P[:, 1, 1]) / r
    np.testing.assert_allclose(cv, (rho - 1) / ((rho + 1) * np.sqrt(3)), rtol=1e-5)
    np.testing.assert_allclose(np.exp(logw), np.diff(edges) / (hi - lo), rtol=1e-5)
    with pytest.raises(ValueError, match="range interval is empty"):
        range_split(np.array([0.0, 1e4, 0, 0]), np.diag([1e4, 1e4, 1, 1]), o, 4, r_min=2e4)


def test_one_component_rpekf_is_the_ekf():
    """A one-cell bank of a prior much narrower than its range is the prior itself (to the
    1e-15 of mass beyond 8 sigma), and then the RPEKF is the EKF."""
    x0 = np.array([1e3, 1.2e4, -3.0, 1.0])
    Pn = np.diag([100.0**2, 100.0**2, 0.5, 0.5])
    sensor_at = [tk.models.Bearing([2.0 * k, 4.0 * k], SIGMA) for k in range(30)]
    z = np.array([s.h(x0 + (k + 1) * 5.0 * np.r_[x0[2:], 0, 0]) for k, s in
                  enumerate(sensor_at)]) + 0.003
    rp, ekf = RPEKF(components=1, n_sigma=8.0), tk.filters.EKF()
    b, g = rp.init(tk.Gaussian(x0, Pn)), tk.Gaussian(x0, Pn)
    for k, s in enumerate(sensor_at):
        b, g = rp.predict(b, CV, 5.0), ekf.predict(g, CV, 5.0)
        b, ib = rp.update(b, z[k], s)
        g, ig = ekf.update(g, z[k], s)
        e = rp.estimate(b)
        np.testing.assert_allclose(e.mean, g.mean, rtol=1e-12)
        np.testing.assert_allclose(e.cov, g.cov, rtol=1e-9, atol=1e-12 * np.abs(g.cov).max())
        np.testing.assert_allclose(ib.nu, ig.nu, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(ib.cov, ig.cov, rtol=1e-12)


def test_rpekf_update_is_a_bank_of_ekf_updates_reweighted_by_their_likelihoods():
    x0 = np.array([0.0, 1.2e4, 2.0, -1.0])
    rp = RPEKF(components=5)
    s1 = tk.models.Bearing([0.0, 0.0], SIGMA)
    b = rp.predict(rp.init(tk.Gaussian(x0, P0)), CV, 5.0)
    b, _ = rp.update(b, np.array([0.02]), s1)
    assert b.split
    b = rp.predict(b, CV, 5.0)
    s2 = tk.models.Bearing([20.0, 30.0], SIGMA)
    z = np.array([0.031])
    post, innov = rp.update(b, z, s2)
    ekf = tk.filters.EKF()
    logw = b.log_weights.copy()
    S, nu = [], []
    for i in range(5):
        gi, ii = ekf.update(tk.Gaussian(b.mean[i], b.cov[i]), z, s2)
        np.testing.assert_allclose(post.mean[i], gi.mean, rtol=1e-12)
        np.testing.assert_allclose(post.cov[i], gi.cov, rtol=1e-12)
        r, Si = ii.nu[0], ii.cov[0, 0]
        logw[i] += -0.5 * (r * r / Si + np.log(2 * np.pi * Si))
        nu.append(r), S.append(Si)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    np.testing.assert_allclose(np.exp(post.log_weights), w, rtol=1e-9, atol=1e-300)
    c = np.exp(b.log_weights)
    nbar = c @ np.array(nu)
    np.testing.assert_allclose(innov.nu, [nbar], rtol=1e-12)
    Sbar = c @ (np.array(S) + (np.array(nu) - nbar) ** 2)
    np.testing.assert_allclose(innov.cov, [[Sbar]], rtol=1e-12)
    m, C = _mixture_moments(post.mean, post.cov, post.log_weights)
    e = rp.estimate(post)
    np.testing.assert_allclose(e.mean, m, rtol=1e-12)
    np.testing.assert_allclose(e.cov, C, rtol=1e-9)


def test_rpekf_pruning_drops_light_components_for_good():
    x0 = np.array([0.0, 1.2e4, 2.0, -1.0])
    rp = RPEKF(components=8, prune=0.05)
    b = rp.init(tk.Gaussian(x0, P0))
    b, _ = rp.update(rp.predict(b, CV, 5.0), np.array([0.0]), tk.models.Bearing([0, 0], SIGMA))
    w = np.exp(b.log_weights)
    assert np.all((w == 0) | (w >= 0.05)) and (w == 0).any()
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-12)
    dead = w == 0
    b, _ = rp.update(rp.predict(b, CV, 5.0), np.array([0.001]),
                     tk.models.Bearing([10, 0], SIGMA))
    assert np.all(np.exp(b.log_weights)[dead] == 0)
    assert np.isfinite(rp.estimate(b).mean).all()


def test_rpekf_batched_rows_equal_single_rows_with_missing_and_per_run_observers():
    rng = np.random.default_rng(11)
    runs = 3
    x0 = np.array([[0.0, 1.2e4, 5.0, -1.0], [2e3, 9e3, -2.0, 0.5], [-3e3, 1.5e4, 1.0, 1.0]])
    rp = RPEKF(components=6)
    b = rp.init(tk.Gaussian(x0, np.tile(P0, (runs, 1, 1))))
    singles = [rp.init(tk.Gaussian(x0[i], P0)) for i in range(runs)]
    offsets = np.array([[0.0, 0.0], [100.0, -300.0], [-50.0, 20.0]])
    for k in range(25):
        z = rng.normal(0.2, 0.1, (runs, 1))
        if k in (0, 3):
            z[2] = np.nan
        origin = np.array([3.0 * k, 2.0 * k]) + offsets
        b, innov = rp.update(rp.predict(b, CV, 10.0), z, tk.models.Bearing(origin, SIGMA))
        for i in range(runs):
            singles[i], inn_i = rp.update(rp.predict(singles[i], CV, 10.0), z[i],
                                          tk.models.Bearing(origin[i], SIGMA))
            np.testing.assert_allclose(b.mean[i], singles[i].mean, rtol=1e-12)
            np.testing.assert_allclose(b.log_weights[i], singles[i].log_weights, rtol=1e-9,
                                       atol=1e-12)
            np.testing.assert_array_equal(np.isnan(innov.nu[i]),
                                          np.isnan(inn_i.nu))
        if k == 0:
            assert b.split.tolist() == [True, True, False]
    assert isinstance(b, RangeBankBelief) and b.split.all()


# --------------------------------------------------------------------------------------------
# Bad input and the scenario engine
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, words", [
    ({"components": 0}, "components = 0"),
    ({"components": 2.0}, "components = 2.0"),
    ({"n_sigma": 0.0}, "n_sigma = 0.0"),
    ({"r_min": -1.0}, "r_min = -1.0"),
    ({"r_min": 5e3, "r_max": 4e3}, "r_max = 4000.0"),
    ({"prune": 0.2, "components": 8}, "prune = 0.2"),
])
def test_rpekf_refuses_bad_options(kwargs, words):
    with pytest.raises(ValueError, match=words):
        RPEKF(**kwargs)


def test_specialists_refuse_sensors_and_motions_they_cannot_use():
    g = tk.Gaussian(np.array([0.0, 1e4, 1.0, 1.0]), P0)
    rb = tk.models.RangeBearing([0.0, 0.0], 10.0, SIGMA)
    with pytest.raises(ValueError, match="RangeBearing measures 2 components; expected one "
                                         "bearing"):
        MPEKF().update(g, np.array([0.1, 1e4]), rb)
    with pytest.raises(ValueError, match="MPEKF.predict: motion is CoordinatedTurn"):
        b = MPEKF().update(g, np.array([0.1]), tk.models.Bearing([0, 0], SIGMA))[0]
        MPEKF().predict(b, tk.models.CoordinatedTurn(q=1.0, q_omega=0.01), 1.0)
    with pytest.raises(ValueError, match="Position has no 2-D origin"):
        RPEKF().update(g, np.array([0.1, 1e4]), tk.models.Position(dim=2, sigma=1.0))
    with pytest.raises(ValueError, match="MPEKF.init prior.mean has shape"):
        MPEKF().init(tk.Gaussian(np.zeros(5), np.eye(5)))
    with pytest.raises(ValueError, match="velocity has shape"):
        tk.models.Bearing([0, 0], SIGMA, velocity=[1.0, 2.0, 3.0])


def test_bearing_velocity_is_a_pose_field_that_h_ignores():
    x = np.array([1e3, 5e3, 1.0, 2.0])
    a = tk.models.Bearing([10.0, 20.0], SIGMA)
    b = tk.models.Bearing([10.0, 20.0], SIGMA, velocity=[3.0, -4.0])
    np.testing.assert_array_equal(a.velocity, [0.0, 0.0])
    np.testing.assert_array_equal(a.h(x), b.h(x))
    np.testing.assert_array_equal(a.jacobian(x), b.jacobian(x))


def test_scenario_engine_gives_the_sensor_the_observers_velocity():
    import trackkit.scenario as S
    from trackkit.experiments.montecarlo import plan_of

    plan = plan_of(S.load("bo-cv"))
    for k in (0, 130, 300):
        np.testing.assert_array_equal(plan.sensors[k].velocity,
                                      plan.observer_states[0, k + 1, 2:4])


# --------------------------------------------------------------------------------------------
# The PF's priors
# --------------------------------------------------------------------------------------------


def test_range_pf_with_the_gaussian_prior_is_the_pf():
    from trackkit.filters.particle import PF

    x0 = np.array([[0.0, 1.2e4, 2.0, -1.0], [1e3, 9e3, 0.0, 1.0]])
    prior = tk.Gaussian(x0, np.tile(P0, (2, 1, 1)))
    sensor = tk.models.Bearing([10.0, 0.0], SIGMA)
    a, b = RangePF(500, regularise=True), PF(500, regularise=True)
    assert RangePF.stochastic and a.name == "PF"
    pa, pb = a.init(prior, np.random.default_rng(4)), b.init(prior, np.random.default_rng(4))
    for k in range(5):
        z = np.array([[0.01 * k], [0.1]])
        pa, ia = a.update(a.predict(pa, CV, 5.0), z, sensor)
        pb, ib = b.update(b.predict(pb, CV, 5.0), z, sensor)
    np.testing.assert_array_equal(pa.states, pb.states)
    np.testing.assert_array_equal(a.estimate(pa).cov, b.estimate(pb).cov)


def test_range_pf_spreads_its_particles_along_the_first_bearing():
    """prior = "range": at the first bearing, positions on the line of sight with bearings
    N(z, sigma^2) and log-range uniform over [r_min, r_max]; velocities from the prior; a row
    without that bearing waits, and draws from its Gaussian when it is updated without one
    while others draw (checked through the moments, 20 000 particles: standard errors below
    1 % of each spread)."""
    N, lo, hi = 20000, 3e3, 3e4
    f = RangePF(N, prior="range", r_min=lo, r_max=hi)
    x0 = np.array([[0.0, 1.2e4, 2.0, -1.0], [1e3, 9e3, 0.0, 1.0]])
    b = f.init(tk.Gaussian(x0, np.tile(P0, (2, 1, 1))), np.random.default_rng(8))
    assert isinstance(b, PendingParticles)
    b = f.predict(b, CV, 5.0)
    o = np.array([100.0, -200.0])
    wait, innov = f.update(b, np.full((2, 1), np.nan), tk.models.Bearing(o, SIGMA))
    assert isinstance(wait, PendingParticles) and np.isnan(innov.nu).all()
    z = np.array([[0.3], [np.nan]])
    p, innov = f.update(b, z, tk.models.Bearing(o, SIGMA))
    X = p.states
    np.testing.assert_allclose(np.exp(p.log_weights).sum(-1), 1.0, rtol=1e-12)
    d = X[0, :, :2] - o
    r, beta = np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 0], d[:, 1])
    assert r.min() >= lo and r.max() <= hi
    u = np.log(r / lo) / np.log(hi / lo)  # uniform on [0, 1]
    assert abs(u.mean() - 0.5) < 0.01 and abs(u.var() - 1 / 12) < 2e-3  # 5 and 4 SE
    assert abs(beta.mean() - 0.3) < 0.01 * SIGMA * 3 and abs(beta.std() / SIGMA - 1) < 0.03
    pred = f.predict(f.init(tk.Gaussian(x0, np.tile(P0, (2, 1, 1)))), CV, 5.0)
    for row in (0, 1):  # velocities (and row 1's whole state) from the predicted Gaussian
        sl = slice(2, 4) if row == 0 else slice(0, 4)
        m, sd = pred.mean[row, sl], np.sqrt(np.diag(pred.cov[row])[sl])
        assert np.all(np.abs(X[row, :, sl].mean(0) - m) < 0.03 * sd)
        assert np.all(np.abs(X[row, :, sl].std(0) / sd - 1) < 0.03)
    with pytest.raises(ValueError, match="only for prior = 'range'"):
        RangePF(r_min=1e3)
    with pytest.raises(ValueError, match="prior = 'uniform'"):
        RangePF(prior="uniform")
    with pytest.raises(ValueError, match="r_max = 1000.0"):
        RangePF(prior="range", r_min=2e3, r_max=1e3)


def test_the_prior_conditioned_on_a_bearing_is_the_bayes_posterior():
    """prior = "bearing" (conditioned_on_bearing): the weighted particles' moments equal
    those of the exact posterior after one bearing, here computed by brute-force importance
    sampling of 4 million prior draws weighted by the bearing's likelihood, for a prior with
    position-velocity correlation and a bearing 2.5 prior sigmas off its mean. Tolerance: 5
    combined standard errors of the two estimates' means (ESS 365 000 and 49 000); the spreads
    to 2 %. Its effective sample size is 91 % of its 400 000 draws, where drawing from the
    prior keeps 1.2 %."""
    import math

    from trackkit.filters import resample as rs
    from trackkit.filters.bearings_only import conditioned_on_bearing

    rng = np.random.default_rng(1)
    x = np.array([1000.0, 12000.0, -3.0, 2.0])
    P = np.diag([2000.0, 2500.0, 4.0, 4.0]) ** 2
    P[0, 2] = P[2, 0] = 0.3 * 2000.0 * 4.0
    beta = math.atan2(5000.0, 10000.0) + 0.005
    N = 400_000
    X, lw = conditioned_on_bearing(x[None], P[None], np.zeros((1, 2)), np.array([beta]),
                                   np.array([SIGMA]), N, rng)
    w = np.exp(lw)
    np.testing.assert_allclose(w.sum(), 1.0, rtol=1e-12)
    ess = float(rs.effective_sample_size(lw)[0])
    assert ess > 0.9 * N
    m, C = rs.weighted_mean_cov(X, w)
    Y = rng.multivariate_normal(x, P, size=4_000_000)
    ll = -0.5 * (tk.angles.wrap(np.arctan2(Y[:, 0], Y[:, 1]) - beta) / SIGMA) ** 2
    v = np.exp(ll - ll.max())
    v /= v.sum()
    ess_brute = 1.0 / np.sum(v * v)
    assert ess_brute < 0.02 * len(Y)  # the prior's draws: about 1 in 80 kept
    m2, C2 = rs.weighted_mean_cov(Y[None], v[None])
    sd = np.sqrt(np.diag(C2[0]))
    se = sd * np.sqrt(1 / ess + 1 / ess_brute)
    assert np.all(np.abs(m[0] - m2[0]) < 5 * se), (m[0] - m2[0]) / se
    np.testing.assert_allclose(np.sqrt(np.diag(C[0])), sd, rtol=0.02)
    # every particle lies on the bearing's rays: its bearing ~ N(beta, sigma^2)
    b = np.arctan2(X[0, :, 0], X[0, :, 1])
    assert abs(b.mean() - beta) < 5 * SIGMA / math.sqrt(N) and abs(b.std() / SIGMA - 1) < 0.01


def test_range_pf_conditioned_on_the_first_bearing():
    """prior = "bearing" waits for the first bearing as "range" does, then draws there (rows
    without it draw from their Gaussian), resamples a row whose ESS is low and keeps the
    filter's options; r_min and r_max are refused with it."""
    f = RangePF(2000, prior="bearing", ess_threshold=1.0, regularise=True, shrink=True)
    x0 = np.array([[0.0, 1.2e4, 2.0, -1.0], [1e3, 9e3, 0.0, 1.0]])
    b = f.init(tk.Gaussian(x0, np.tile(P0, (2, 1, 1))), np.random.default_rng(8))
    assert isinstance(b, PendingParticles)
    b = f.predict(b, CV, 5.0)
    sensor = tk.models.Bearing([100.0, -200.0], SIGMA)
    p, innov = f.update(b, np.array([[0.05], [np.nan]]), sensor)
    assert isinstance(p, tk.Particles) and np.isnan(innov.nu[1]).all()
    np.testing.assert_allclose(np.exp(p.log_weights).sum(-1), 1.0, rtol=1e-12)
    d = p.states[0, :, :2] - [100.0, -200.0]
    assert np.abs(tk.angles.wrap(np.arctan2(d[:, 0], d[:, 1]) - 0.05)).max() < 8 * SIGMA
    assert np.ptp(p.states[1, :, 0]) > 5000  # row 1: the Gaussian draw, km wide
    g = f.estimate(f.predict(p, CV, 5.0))
    assert np.isfinite(g.cov).all()
    with pytest.raises(ValueError, match="only for prior = 'range'"):
        RangePF(prior="bearing", r_max=1e4)
    with pytest.raises(ValueError, match="'gaussian', 'bearing' or 'range'"):
        RangePF(prior="uniform")


def test_mpekf_refuses_a_prior_without_a_position_spread():
    b = MPEKF().init(tk.Gaussian(np.array([0.0, 5e3, 0.0, 0.0]), np.diag([0.0, 0.0, 1.0, 1.0])))
    with pytest.raises(ValueError, match=r"MPEKF.update prior cov \(its position block\) is "
                       "not positive definite"):
        MPEKF().update(b, np.array([0.01]), tk.models.Bearing([0, 0], SIGMA))
