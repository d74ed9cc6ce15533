"""PCRLB: against the Kalman filter (linear-Gaussian), a brute-force Fisher information, Stone
Soup's PCRBMetric, a direct evaluation of the Tichavsky-Muravchik-Nehorai formulas, and the
Monte Carlo RMSE of a Kalman filter."""

from __future__ import annotations

import datetime

import numpy as np
import pytest

import trackkit as tk
from trackkit.eval import PCRLB, pcrlb, rmse_bound

CV_ORDER_SS = [0, 2, 1, 3]  # Stone Soup orders [x, vx, y, vy]; trackkit [x, y, vx, vy]


def rel_err(A: np.ndarray, B: np.ndarray) -> float:
    """Matrix relative error ``max|A - B| / max|B|`` (element-wise relative error is
    meaningless for near-zero off-diagonal entries)."""
    return float(np.max(np.abs(A - B)) / np.max(np.abs(B)))


def draw(rng: np.random.Generator, mean: np.ndarray, cov: np.ndarray, runs: int) -> np.ndarray:
    L = np.linalg.cholesky(cov) if np.any(cov) else np.zeros_like(cov)
    return mean + rng.standard_normal((runs, len(mean))) @ L.T


def simulate_linear(rng, motion, sensor, m0, P0, runs, dts):
    """Truths ``(T + 1, runs, n)`` and measurements ``(T, runs, m)`` of a linear model."""
    x = draw(rng, m0, P0, runs)
    truths, zs = [x], []
    for dt in dts:
        Q = motion.noise(x, dt)
        x = motion.f(x, dt) + draw(rng, np.zeros(len(m0)), Q, runs)
        zs.append(sensor.h(x) + draw(rng, np.zeros(sensor.dim_z), sensor.noise, runs))
        truths.append(x)
    return np.stack(truths), np.stack(zs)


def kf_covariances(motion, sensor, m0, P0, zs, dts):
    """KF covariances after each update (batched covariance, one per run)."""
    runs = zs.shape[1]
    b = tk.Gaussian(np.tile(m0, (runs, 1)), np.tile(P0, (runs, 1, 1)))
    f = tk.filters.KF()
    means, covs = [], []
    for z, dt in zip(zs, dts, strict=True):
        b = f.predict(b, motion, dt)
        b, _ = f.update(b, z, sensor)
        means.append(b.mean)
        covs.append(b.cov)
    return np.stack(means), np.stack(covs)


# -- (a), (b): linear-Gaussian problems, where the bound is the KF covariance -----------------


def test_linear_gaussian_bound_equals_kf_covariance_step_by_step():
    rng = np.random.default_rng(1)
    motion = tk.models.ConstantVelocity(dim=2, q=[0.3, 0.05])
    sensor = tk.models.Position(dim=2, sigma=[3.0, 5.0])
    m0, P0 = np.array([0.0, 0.0, 5.0, 3.0]), np.diag([100.0, 150.0, 10.0, 4.0])
    dts = 0.5 + 0.1 * (np.arange(80) % 7)  # irregular sampling
    truths, zs = simulate_linear(rng, motion, sensor, m0, P0, 20, dts)
    _, covs = kf_covariances(motion, sensor, m0, P0, zs, dts)

    bound = PCRLB(P0)
    assert rel_err(bound.bound, P0) < 1e-14  # starts at the prior: J_0 = P0^{-1}
    for k, dt in enumerate(dts):
        bound.predict(motion, truths[k], dt).update(sensor, truths[k + 1])
        assert bound.last_form == "covariance"
        assert rel_err(bound.bound, covs[k, 0]) < 1e-9, k


def test_information_form_agrees_with_kf_when_q_positive_definite():
    rng = np.random.default_rng(2)
    motion = tk.models.ConstantVelocity(dim=2, q=0.5)
    sensor = tk.models.Position(dim=2, sigma=2.0)
    m0, P0 = np.zeros(4), np.diag([50.0, 50.0, 5.0, 5.0])
    dts = np.ones(60)
    truths, zs = simulate_linear(rng, motion, sensor, m0, P0, 10, dts)
    _, covs = kf_covariances(motion, sensor, m0, P0, zs, dts)
    bound = PCRLB(P0, form="information")
    for k, dt in enumerate(dts):
        bound.predict(motion, truths[k], dt).update(sensor, truths[k + 1])
        assert bound.last_form == "information"
        assert rel_err(bound.bound, covs[k, 0]) < 1e-9, k


def test_zero_process_noise_bound_equals_kf_covariance():
    dt = 2.0
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    motion = tk.models.LinearMotion(F, np.zeros((4, 4)))
    sensor = tk.models.Position(dim=2, sigma=10.0)
    m0, P0 = np.array([100.0, -50.0, 3.0, 1.0]), np.diag([400.0, 400.0, 9.0, 9.0])
    dts = np.full(50, dt)
    truths, zs = simulate_linear(np.random.default_rng(3), motion, sensor, m0, P0, 8, dts)
    _, covs = kf_covariances(motion, sensor, m0, P0, zs, dts)

    bound = PCRLB(P0)
    Finv = np.linalg.inv(F)
    J = np.linalg.inv(P0)
    HtRH = sensor.jacobian(m0).T @ np.linalg.inv(sensor.noise) @ sensor.jacobian(m0)
    for k in range(len(dts)):
        bound.predict(motion, truths[k], dt).update(sensor, truths[k + 1])
        assert bound.last_form == "covariance"
        assert rel_err(bound.bound, covs[k, 0]) < 1e-9, k
        J = Finv.T @ J @ Finv + HtRH  # the documented Q = 0 rule
        assert rel_err(bound.information, J) < 1e-9, k

    with pytest.raises(ValueError, match="process noise Q"):
        PCRLB(P0, form="information").predict(motion, truths[0], dt)


# -- (c) bearings-only: brute-force Fisher information and Stone Soup --------------------------


def observer_track(T: int, dt: float) -> np.ndarray:
    """Observer positions at steps 0..T: east at 5 m/s, then north-east (a leg change makes
    range observable from bearings)."""
    v = np.where(np.arange(T + 1)[:, None] < T // 2, [5.0, 0.0], [3.5, 3.5])
    return np.concatenate([[[0.0, 0.0]], np.cumsum(v[1:] * dt, axis=0)])


def bearing_jacobian(p: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """d/dx of the nautical bearing atan2(dx, dy), written out here independently of
    trackkit: [dy, -dx, 0, 0] / r^2, shape (..., 1, 4)."""
    d = p[..., :2] - origin
    r2 = (d * d).sum(-1)
    H = np.zeros(p.shape[:-1] + (1, 4))
    H[..., 0, 0], H[..., 0, 1] = d[..., 1] / r2, -d[..., 0] / r2
    return H


def test_bearings_only_matches_brute_force_fisher_information():
    """Q = 0: x_k = F^k x_0, so the information about x_0 from z_1..z_k is
    ``J0_k = P0^{-1} + sum_i (F^i)^T E[H_i^T R^{-1} H_i] F^i`` and the bound on x_k is
    ``F^k J0_k^{-1} (F^k)^T``; expectations over 300 truths with per-run observer offsets."""
    T, dt, runs, sigma = 60, 10.0, 300, np.deg2rad(1.0)
    motion = tk.models.ConstantVelocity(dim=2, q=0.0)
    m0 = np.array([4000.0, 6000.0, -4.0, -2.0])
    P0 = np.diag([500.0, 500.0, 2.0, 2.0]) ** 2
    rng = np.random.default_rng(4)
    x0 = draw(rng, m0, P0, runs)
    offsets = rng.normal(0.0, 200.0, (runs, 2))  # each run's observer is shifted
    obs = observer_track(T, dt)[:, None, :] + offsets  # (T + 1, runs, 2)
    F = motion.jacobian(m0, dt)
    truths = np.stack([x0 @ np.linalg.matrix_power(F, k).T for k in range(T + 1)])

    sensors = [tk.models.Bearing(origin=obs[k + 1], sigma=sigma) for k in range(T)]
    bounds = pcrlb(P0, motion, sensors, truths, dt)

    J0 = np.linalg.inv(P0)
    for k in range(1, T + 1):
        Fk = np.linalg.matrix_power(F, k)
        H = bearing_jacobian(truths[k], obs[k])
        info = (np.swapaxes(H, -1, -2) @ H).mean(0) / sigma**2
        J0 = J0 + Fk.T @ info @ Fk
        brute = Fk @ np.linalg.inv(J0) @ Fk.T
        assert rel_err(bounds[k - 1], brute) < 1e-9, k
    # the bound is informative: position RMSE bound far below the prior's 707 m
    assert rmse_bound(bounds[-1], [0, 1]) < 200.0


@pytest.mark.parametrize("jacobian, tol", [("analytic", 1e-9), ("stonesoup", 2e-4)])
def test_bearings_only_matches_stonesoup_pcrb_metric(jacobian: str, tol: float):
    """Stone Soup's PCRBMetric (Riccati recursion ``J = (F J^-1 F^T + Q)^-1 + H^T R^-1 H`` on
    one ground-truth path, static sensors, Jacobians at the truth) against ours on the same
    single truth path, with small process noise.

    Its assumptions hold: linear-Gaussian transition, additive Gaussian bearing noise, one
    truth path (one run, so our average over runs is that path). Two adaptations: (1) Stone
    Soup's sensors are static, so the path is given to it in observer-relative coordinates
    (the bearing Jacobian depends only on the relative position and F is linear, so the bound
    is unchanged); (2) PCRBMetric sets ``translation_offset = sensor_locations[:, i]``, a 1-D
    slice that Cartesian2DToBearing cannot index (Stone Soup 1.9.1 bug), so the locations are
    passed with an extra axis, shape (2, 1, 1).

    Stone Soup's bearing Jacobian is a forward finite difference (relative error ~1e-8), which
    the ill-conditioned bearings-only information amplifies to ~3e-5 in the bound: with it the
    tolerance is 2e-4. With the analytic Jacobian (``-y/r^2, x/r^2`` for its atan2(y, x)
    bearing) supplied to Stone Soup's model, its recursion and ours agree to 1e-9 (observed
    ~4e-14).
    """
    from stonesoup.metricgenerator.manager import MultiManager
    from stonesoup.metricgenerator.pcrbmetric import PCRBMetric
    from stonesoup.models.measurement.nonlinear import Cartesian2DToBearing
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
    )
    from stonesoup.models.transition.linear import (
        ConstantVelocity as SSConstantVelocity,
    )
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    from stonesoup.types.state import GaussianState

    T, dt, q, sigma = 40, 10.0, 1e-4, np.deg2rad(1.5)
    motion = tk.models.ConstantVelocity(dim=2, q=q)
    m0 = np.array([3000.0, 5000.0, -3.0, -4.0])
    P0 = np.diag([400.0, 400.0, 2.0, 2.0]) ** 2
    rng = np.random.default_rng(5)
    x = draw(rng, m0, P0, 1)
    truths = [x]
    for _ in range(T):
        x = motion.f(x, dt) + draw(rng, np.zeros(4), motion.noise(x, dt), 1)
        truths.append(x)
    truths = np.stack(truths)  # (T + 1, 1, 4)
    obs = observer_track(T, dt)
    sensors = [tk.models.Bearing(origin=obs[k + 1], sigma=sigma) for k in range(T)]
    ours = pcrlb(P0, motion, sensors, truths, dt)

    class AnalyticBearing(Cartesian2DToBearing):
        def jacobian(self, state, **kwargs):
            x = state.state_vector[0, 0] - self.translation_offset[0, 0]
            y = state.state_vector[2, 0] - self.translation_offset[1, 0]
            r2 = x * x + y * y
            return np.array([[-y / r2, 0.0, x / r2, 0.0]])

    model = AnalyticBearing if jacobian == "analytic" else Cartesian2DToBearing
    t0 = datetime.datetime(2024, 1, 1)
    rel = truths[:, 0, :].copy()
    rel[:, :2] -= obs
    path = GroundTruthPath([
        GroundTruthState(rel[k, CV_ORDER_SS].astype(float),
                         timestamp=t0 + datetime.timedelta(seconds=k * dt))
        for k in range(T + 1)
    ])
    generator = PCRBMetric(
        prior=GaussianState(m0[CV_ORDER_SS], P0[np.ix_(CV_ORDER_SS, CV_ORDER_SS)],
                            timestamp=t0),
        transition_model=CombinedLinearGaussianTransitionModel(
            [SSConstantVelocity(q), SSConstantVelocity(q)]),
        measurement_model=model(
            ndim_state=4, mapping=(0, 2), noise_covar=np.array([[sigma**2]])),
        sensor_locations=np.zeros((2, 1, 1)),
        position_mapping=(0, 2),
        velocity_mapping=(1, 3),
    )
    manager = MultiManager(generators=[generator])
    manager.add_data({"groundtruth_paths": [path]})
    value = manager.generate_metrics()["pcrb_generator"]["PCRB Metrics"].value
    theirs = np.asarray(value["inverse_j"])[1:][:, CV_ORDER_SS][:, :, CV_ORDER_SS]
    for k in range(T):
        assert rel_err(ours[k], theirs[k]) < tol, k
    np.testing.assert_allclose(rmse_bound(ours, [0, 1]), value["position_RMSE"][1:], rtol=tol)
    np.testing.assert_allclose(rmse_bound(ours, [2, 3]), value["velocity_RMSE"][1:], rtol=tol)


# -- the information form with a state-dependent Jacobian --------------------------------------


def test_information_form_equals_direct_tmn_formulas_for_coordinated_turn():
    """F varies over the truths (coordinated turn), so "auto" takes the information form;
    compare with the TMN recursion evaluated term by term with a Python loop over runs."""
    motion = tk.models.CoordinatedTurn(q=0.2, q_omega=1e-4)
    sensor = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=10.0, sigma_bearing=0.01)
    rng = np.random.default_rng(6)
    runs, T, dt = 40, 15, 2.0
    m0 = np.array([2000.0, 1000.0, 10.0, -5.0, 0.02])
    P0 = np.diag([100.0, 100.0, 4.0, 4.0, 1e-4])
    x = draw(rng, m0, P0, runs)
    bound = PCRLB(P0)
    J = np.linalg.inv(P0)
    for _ in range(T):
        x_next = motion.f(x, dt) + draw(rng, np.zeros(5), motion.noise(x, dt), runs)
        bound.predict(motion, x, dt).update(sensor, x_next)
        assert bound.last_form == "information"
        D11 = np.zeros((5, 5))
        D12 = np.zeros((5, 5))
        D22 = np.zeros((5, 5))
        for r in range(runs):  # the reference: a plain loop over the runs
            Fr = motion.jacobian(x[r], dt)
            Qi = np.linalg.inv(motion.noise(x[r], dt))
            Hr = sensor.jacobian(x_next[r])
            D11 += Fr.T @ Qi @ Fr / runs
            D12 += -Fr.T @ Qi / runs
            D22 += (Qi + Hr.T @ np.linalg.inv(sensor.noise) @ Hr) / runs
        J = D22 - D12.T @ np.linalg.inv(J + D11) @ D12
        assert rel_err(bound.information, J) < 1e-9
        x = x_next


def test_singular_q_with_varying_jacobian_warns_and_uses_covariance_form():
    motion = tk.models.CoordinatedTurn(q=0.0, q_omega=0.0)
    rng = np.random.default_rng(7)
    m0 = np.array([2000.0, 1000.0, 10.0, -5.0, 0.02])
    P0 = np.diag([100.0, 100.0, 4.0, 4.0, 1e-4])
    x = draw(rng, m0, P0, 30)
    bound = PCRLB(P0)
    with pytest.warns(UserWarning, match="approximation"):
        bound.predict(motion, x, 1.0)
    assert bound.last_form == "covariance"
    F = motion.jacobian(x, 1.0)
    expected = (F @ P0 @ np.swapaxes(F, -1, -2)).mean(0)  # the documented rule
    assert rel_err(bound.bound, expected) < 1e-10


# -- (d) Monte Carlo: the KF's RMSE attains the bound ------------------------------------------


def test_kf_monte_carlo_rmse_matches_bound():
    """For a linear-Gaussian problem the KF is efficient: its error at step k is N(0, P_k)
    with P_k the bound. With R runs the Monte Carlo MSE of a group has mean tr(P_g) and
    standard deviation sqrt(2 tr(P_g^2) / R) (Gaussian errors), so the z-score of each step
    is about N(0, 1). We require |z| < 4 at every step: per step a false alarm has
    probability 6e-5, so over 2 groups x 50 steps the test holds with >= 99.3 % confidence
    (Bonferroni); the seed is fixed, so the outcome is deterministic."""
    runs, T, dt = 2000, 50, 1.0
    motion = tk.models.ConstantVelocity(dim=2, q=0.1)
    sensor = tk.models.Position(dim=2, sigma=2.0)
    m0, P0 = np.array([0.0, 0.0, 1.0, 1.0]), np.diag([25.0, 25.0, 4.0, 4.0])
    dts = np.full(T, dt)
    truths, zs = simulate_linear(np.random.default_rng(8), motion, sensor, m0, P0, runs, dts)
    means, _ = kf_covariances(motion, sensor, m0, P0, zs, dts)
    bounds = pcrlb(P0, motion, sensor, truths, dt)
    err = means - truths[1:]
    for idx in ([0, 1], [2, 3]):
        mse = (err[..., idx] ** 2).sum(-1).mean(-1)  # (T,)
        Pg = bounds[:, idx][:, :, idx]
        tr = np.trace(Pg, axis1=-2, axis2=-1)
        sd = np.sqrt(2 * np.trace(Pg @ Pg, axis1=-2, axis2=-1) / runs)
        z = (mse - tr) / sd
        assert np.all(np.abs(z) < 4.0), z
        # in RMSE terms: relative sd of the MSE is ~ 1/sqrt(R) = 0.022 here, of the RMSE half
        # that, so 4 sd is ~ 0.045
        np.testing.assert_allclose(np.sqrt(mse), rmse_bound(bounds, idx), rtol=0.05)


# -- API details -------------------------------------------------------------------------------


def test_weights_extra_batch_axes_and_input_checks():
    motion = tk.models.ConstantVelocity(dim=1, q=1.0)
    sensor = tk.models.Position(dim=1, sigma=1.0)
    P0 = np.diag([4.0, 1.0])
    x = np.zeros((5, 3, 2))  # 5 runs x 3 targets
    b = PCRLB(P0).predict(motion, x, 1.0).update(sensor, x)
    assert b.bound.shape == (3, 2, 2)
    single = PCRLB(P0).predict(motion, x[:, 0], 1.0).update(sensor, x[:, 0])
    assert rel_err(b.bound[1], single.bound) < 1e-15

    # weight 0 adds nothing; weight 0.5 on all runs halves the information
    none = PCRLB(P0).predict(motion, x[:, 0], 1.0)
    J_pred = none.information.copy()
    none.update(sensor, x[:, 0], weight=0.0)
    np.testing.assert_array_equal(none.information, J_pred)
    half = PCRLB(P0).predict(motion, x[:, 0], 1.0).update(sensor, x[:, 0], weight=0.5)
    np.testing.assert_allclose(half.information - J_pred, 0.5 * (single.information - J_pred))

    with pytest.raises(ValueError, match="truths"):
        PCRLB(P0).predict(motion, np.zeros((5, 3)), 1.0)
    with pytest.raises(ValueError, match="prior_cov"):
        PCRLB(np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(ValueError, match="form"):
        PCRLB(P0, form="fast")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="weight"):
        PCRLB(P0).update(sensor, x[:, 0], weight=-1.0)
