"""GA-based initialisation of Doppler-bearing tracking (Hashemi and Alfi 2019, section 4-2).

Geometry of Hashemi and Alfi's scenario 1 (courses counter-clockwise from east, as the paper's
direction words imply): observer from the origin at 5 kn on course 20 deg; target from
(6000, 6000) m at 15 kn on course 260 deg radiating 500 Hz; bearing sigma 2 deg, frequency sigma
0.3 Hz, c = 1500 m/s, dt = 1 s. The paper claims the GA finds the initial position to < 1000 m.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters.initialise import (
    aux_cost,
    compress,
    dbt_prior_cov,
    ga_initial_position,
    ga_prior,
)
from trackkit.optimize import GA, OptimizeResult

KN = 1852.0 / 3600.0
DT = 1.0


def _course(speed_kn: float, deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return speed_kn * KN * np.array([np.cos(a), np.sin(a)])


V_OBS = _course(5.0, 20.0)
X0 = np.array([6000.0, 6000.0, *_course(15.0, 260.0), 500.0])  # target at the prior time
# the filters' motion: the bundled dbt scenarios' CV with q = 1e-4 and a constant tone
MOTION = tk.models.Augmented(tk.models.ConstantVelocity(dim=2, q=1e-4))


def simulate(K: int, runs: int, seed: int, x0: np.ndarray = X0):
    """Measurements (K, runs, 2) at t = dt, ..., K dt of a target starting at x0 at t = 0,
    the K sensors (observer pose at each step) and the truth (K, 5)."""
    truth_motion = tk.models.Augmented(tk.models.ConstantVelocity(dim=2, q=0.0))
    x, truth, sensors = x0, [], []
    for k in range(1, K + 1):
        x = truth_motion.f(x, DT)
        truth.append(x)
        sensors.append(tk.models.BearingFrequency(
            origin=V_OBS * k * DT, velocity=V_OBS, sigma_bearing=np.deg2rad(2.0),
            sigma_freq=0.3, c=1500.0))
    truth = np.array(truth)
    zhat = np.stack([s.h(xk) for s, xk in zip(sensors, truth, strict=True)])  # (K, 2)
    noise_rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]
    v = np.stack([r.standard_normal((K, 2)) for r in noise_rngs], 1)  # (K, runs, 2)
    z = zhat[:, None, :] + v * np.array([np.deg2rad(2.0), 0.3])
    z[..., 0] = tk.angles.wrap(z[..., 0])
    return z, sensors, truth


def ga_rngs(seed: int, runs: int) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]


def error_stats(res: OptimizeResult, truth_xy: np.ndarray) -> dict[str, float]:
    err = np.linalg.norm(res.best_x - truth_xy, axis=-1)
    return {"median": float(np.median(err)), "p95": float(np.percentile(err, 95)),
            "max": float(err.max()), "frac_below_1000": float(np.mean(err < 1000.0))}


# --- the paper's claim -------------------------------------------------------------------


def test_ga_initial_position_within_1000_m_scenario_1() -> None:
    """GA(50, 200, 0.8, 0.05) over the first K = 800 measurements (block means of 25, so 32
    EKF steps per candidate), 20 runs: >= 95% of runs within 1000 m (the paper's claim).

    K = 800 because range is unobservable over short windows when velocity and tone are
    unknown (see test_range_needs_hundreds_of_measurements). Measured with these seeds:
    median ~150 m, 95th percentile ~550 m, max ~560 m; about 10 s.
    """
    runs, K = 20, 800
    z, sensors, _ = simulate(K, runs, seed=2002)
    res = ga_initial_position(z, sensors, MOTION, DT, rngs=ga_rngs(7, runs), block=25,
                              ga=GA(50, 200, 0.8, 0.05))
    stats = error_stats(res, X0[:2])
    print("GA initial position error (m), K = 800:", stats)
    assert res.best_x.shape == (runs, 2) and res.history.shape == (201, runs)
    assert stats["frac_below_1000"] >= 0.95, stats
    assert stats["median"] < 500.0, stats
    assert np.all(np.diff(res.history, axis=0) <= 0)


def test_twenty_measurements_do_not_fix_range() -> None:
    """K = 20 (20 s): the cost is flat along the bearing line (range CRLB ~240 km), and the
    NIS prefers short ranges (where the bearing's predicted variance is largest), so the
    GA's position is mostly far from the truth. Measured: median error ~6.5 km, no run
    within 1000 m. The paper's claim cannot hold with so few measurements."""
    runs, K = 20, 20
    z, sensors, _ = simulate(K, runs, seed=2002)
    res = ga_initial_position(z, sensors, MOTION, DT, rngs=ga_rngs(7, runs), block=5)
    stats = error_stats(res, X0[:2])
    print("GA initial position error (m), K = 20:", stats)
    assert stats["frac_below_1000"] <= 0.25, stats
    assert stats["median"] > 3000.0, stats


def test_range_needs_hundreds_of_measurements() -> None:
    """Cramer-Rao bound of the initial state [x, y, vx, vy, f0] from K measurements without
    prior information (Fisher information sum_k (H_k F^k)^T R^-1 H_k F^k): the along-range
    position std is ~243 km at K = 20, ~2.5 km at 300, ~420 m at 600 and ~160 m at 800.
    This is why the GA's window is K = 800, not 20."""
    _, sensors, truth = simulate(800, 1, seed=0)
    F = np.asarray(MOTION.jacobian(X0, DT))
    J, Fk, major = np.zeros((5, 5)), np.eye(5), {}
    for k, (s, x) in enumerate(zip(sensors, truth, strict=True), start=1):
        Fk = F @ Fk
        H = s.jacobian(x) @ Fk
        J += H.T @ np.linalg.solve(s.noise, H)
        if k in (20, 300, 600, 800):
            major[k] = np.sqrt(np.linalg.eigvalsh(np.linalg.inv(J)[:2, :2])[-1])
    assert major[20] > 1e5
    assert 1500 < major[300] < 4000
    assert 300 < major[600] < 550
    assert major[800] < 250


# --- the pieces ---------------------------------------------------------------------------


def test_cost_is_lowest_near_the_true_position_on_the_bearing_line() -> None:
    """J(p) along the true bearing line (K = 800 in blocks of 25): its minimum is within
    1 km of the true range for each of 4 runs, and the cost grows away from it."""
    z, sensors, _ = simulate(800, 4, seed=11)
    zc, sc, dts = compress(z, sensors, DT, 25)
    r = np.arange(2000.0, 20001.0, 250.0)
    p = np.stack([r * np.sin(np.pi / 4), r * np.cos(np.pi / 4)], -1)
    p = np.broadcast_to(p, (4,) + p.shape)
    J = aux_cost(p, zc, sc, MOTION, dts, np.zeros((4, 2)), z[0, :, 1], dbt_prior_cov())
    r_best = r[np.argmin(J, 1)]
    assert np.all(np.abs(r_best - np.hypot(6000, 6000)) < 1000), r_best
    assert np.all(J[:, 0] > J.min(1) + 50) and np.all(J[:, -1] > J.min(1) + 50)


def test_nll_cost_adds_the_log_determinants() -> None:
    z, sensors, _ = simulate(10, 3, seed=1)
    p = np.random.default_rng(0).uniform(3000, 9000, (3, 7, 2))
    args = (z, sensors, MOTION, DT, np.zeros((3, 2)), z[0, :, 1], dbt_prior_cov())
    nis = aux_cost(p, *args, cost="nis")
    nll = aux_cost(p, *args, cost="nll")
    b = tk.Gaussian(np.concatenate([p, np.zeros((3, 7, 2)),
                                    np.broadcast_to(z[0, :, 1, None, None], (3, 7, 1))], -1),
                    np.broadcast_to(dbt_prior_cov(), (3, 7, 5, 5)).copy())
    f, logdet, nis2 = tk.filters.EKF(), 0.0, 0.0
    for k, s in enumerate(sensors):
        b, innov = f.update(f.predict(b, MOTION, DT), z[k][:, None, :], s)
        logdet = logdet + np.linalg.slogdet(innov.cov)[1]
        nis2 = nis2 + innov.nis
    np.testing.assert_allclose(nis, nis2, rtol=1e-12)
    np.testing.assert_allclose(nll, nis + logdet, rtol=1e-12)


def test_missing_measurements_add_nothing() -> None:
    z, sensors, _ = simulate(6, 2, seed=3)
    p = np.full((2, 3, 2), 5000.0)
    args = (sensors, MOTION, DT, np.zeros((2, 2)), z[0, :, 1], dbt_prior_cov())
    z_missing = z.copy()
    z_missing[:, 1] = np.nan  # run 1 sees nothing
    J = aux_cost(p, z_missing, *args)
    np.testing.assert_array_equal(J[1], 0.0)
    np.testing.assert_array_equal(J[0], aux_cost(p, z, *args)[0])


def test_compress_block_means() -> None:
    """Noise-free measurements: each block mean equals h at the block's centre step (to the
    curvature term), the centre sensor carries sigma / sqrt(L), and the steps are L dt (the
    first from the prior time to the first centre)."""
    _, sensors, truth = simulate(75, 1, seed=0)
    zhat = np.stack([s.h(x) for s, x in zip(sensors, truth, strict=True)])[:, None, :]
    zc, sc, dts = compress(zhat, sensors, DT, 15)
    assert zc.shape == (5, 1, 2) and len(sc) == 5
    np.testing.assert_allclose(dts, [8.0, 15.0, 15.0, 15.0, 15.0])
    centre = [7, 22, 37, 52, 67]
    np.testing.assert_allclose(zc[:, 0], zhat[centre, 0], atol=1e-5)
    assert sc[0].origin.tolist() == sensors[7].origin.tolist()
    assert sc[0].sigma_bearing == pytest.approx(np.deg2rad(2.0) / np.sqrt(15))
    assert sc[0].sigma_freq == pytest.approx(0.3 / np.sqrt(15))


def test_compress_averages_bearings_across_the_cut() -> None:
    """Bearings around +-pi average on the circle, not to ~0."""
    s = [tk.models.BearingFrequency() for _ in range(3)]
    z = np.array([[[np.pi - 0.01, 500.0]], [[-np.pi + 0.01, 501.0]], [[np.pi - 0.02, 502.0]]])
    zc, _, _ = compress(z, s, DT, 3)
    assert abs(tk.angles.wrap(zc[0, 0, 0] - (np.pi - 0.02 / 3))) < 1e-12
    assert zc[0, 0, 1] == pytest.approx(501.0)


def test_ga_prior_feeds_the_main_filter() -> None:
    z, sensors, _ = simulate(30, 4, seed=5)
    res = ga_initial_position(z, sensors, MOTION, DT, rngs=ga_rngs(1, 4),
                              ga=GA(population=10, generations=3))
    prior = ga_prior(res, z[0, :, 1])
    assert prior.mean.shape == (4, 5) and prior.cov.shape == (4, 5, 5)
    np.testing.assert_array_equal(prior.mean[:, :2], res.best_x)
    np.testing.assert_array_equal(prior.mean[:, 2:4], 0.0)
    np.testing.assert_array_equal(prior.mean[:, 4], z[0, :, 1])
    np.testing.assert_allclose(prior.cov[0], dbt_prior_cov(1000.0))
    b, _ = tk.filters.run_filter(tk.filters.EKF(), prior, MOTION, sensors, z, DT)
    assert np.all(np.isfinite(b.mean))
    # positions may be passed directly
    p2 = ga_prior(res.best_x, 500.0, velocity_guess=(1.0, 2.0), cov=np.eye(5))
    np.testing.assert_array_equal(p2.mean[:, 2:], np.broadcast_to([1.0, 2.0, 500.0], (4, 3)))


def test_default_bounds_are_a_box_around_the_first_observer() -> None:
    z, sensors, _ = simulate(5, 2, seed=5)
    seen = []

    class Spy(GA):
        def minimize(self, cost, bounds, rngs):
            seen.append(np.asarray(bounds))
            return super().minimize(cost, bounds, rngs)

    ga_initial_position(z, sensors, MOTION, DT, rngs=ga_rngs(1, 2), max_range=3000.0,
                        ga=Spy(population=4, generations=1))
    o = sensors[0].origin
    np.testing.assert_allclose(seen[0], [[o[0] - 3000, o[0] + 3000], [o[1] - 3000, o[1] + 3000]])


def test_bad_input_is_named() -> None:
    z, sensors, _ = simulate(6, 2, seed=5)
    kw = {"rngs": ga_rngs(1, 2), "ga": GA(population=4, generations=1)}
    with pytest.raises(ValueError, match="measurements has shape"):
        ga_initial_position(z[:5], sensors, MOTION, DT, **kw)
    with pytest.raises(ValueError, match="block"):
        ga_initial_position(z, sensors, MOTION, DT, block=2, **kw)
    with pytest.raises(ValueError, match="not a multiple"):
        ga_initial_position(z, sensors, MOTION, DT, block=5, **kw)
    with pytest.raises(ValueError, match="cost"):
        ga_initial_position(z, sensors, MOTION, DT, cost="mse", **kw)
    with pytest.raises(ValueError, match="dt has shape"):
        ga_initial_position(z, sensors, MOTION, [1.0, 1.0], **kw)
    with pytest.raises(ValueError, match="one per run"):
        ga_initial_position(z, sensors, MOTION, DT, rngs=ga_rngs(1, 3))
    with pytest.raises(ValueError, match="positions have shape"):
        ga_prior(np.zeros((3, 3)), 500.0)


def test_other_filters_can_be_the_auxiliary_filter() -> None:
    """The auxiliary filter is swappable; a UKF's cost is close to the EKF's."""
    z, sensors, _ = simulate(20, 2, seed=4)
    p = np.full((2, 3, 2), 5000.0)
    args = (z, sensors, MOTION, DT, np.zeros((2, 2)), z[0, :, 1], dbt_prior_cov())
    J_ekf = aux_cost(p, *args)
    J_ukf = aux_cost(p, *args, aux_filter=tk.filters.UKF())
    assert np.all(np.isfinite(J_ukf))
    np.testing.assert_allclose(J_ukf, J_ekf, rtol=0.2)
