"""Filters (trackkit.filters): KF, EKF (orders 1 and 2), IEKF, UKF, CKF, RTS smoothing and
run_filter. No external oracles here (those live in tests/oracles): batch invariance, missing
measurements, symmetry, equalities between filters that must hold exactly on linear models,
the random-sine problem of the missing-measurements thesis, statistical consistency (NEES/NIS) and
streaming memory.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy import stats

import trackkit as tk
from trackkit.filters import CKF, EKF, IEKF, KF, SRCKF, UKF, run_filter, smooth
from trackkit.models import (
    ConstantVelocity,
    CoordinatedTurn,
    Position,
    RandomSine,
    RangeBearing,
    Sine,
)

FILTERS = {
    "KF": KF,
    "EKF": EKF,
    "EKF2": lambda: EKF(order=2),
    "IEKF": IEKF,
    "UKF": UKF,
    "CKF": CKF,
    "SRCKF": SRCKF,
}
NONLINEAR = [k for k in FILTERS if k != "KF"]


# --------------------------------------------------------------------------------------------
# Problems
# --------------------------------------------------------------------------------------------


def _simulate(motion, sensor, x0, P0, dts, rng):
    """Truth and measurements with per-row initial draws: x0 (B, n), dts (T,) or (T, B)."""
    B, n = x0.shape
    x = x0 + np.einsum("bij,bj->bi", np.linalg.cholesky(P0), rng.standard_normal((B, n)))
    xs, zs = [], []
    Lr = np.linalg.cholesky(sensor.noise)
    for dt in dts:
        Q = np.broadcast_to(motion.noise(x, dt), (B, n, n))
        w = np.einsum("bij,bj->bi", np.linalg.cholesky(Q), rng.standard_normal((B, n)))
        x = motion.f(x, dt) + w
        z = sensor.h(x) + rng.standard_normal((B, sensor.dim_z)) @ Lr.T
        xs.append(x)
        zs.append(z)
    return np.stack(xs), np.stack(zs)


def linear_problem(B=7, T=6, seed=0, per_row_dt=False):
    rng = np.random.default_rng(seed)
    motion = ConstantVelocity(dim=2, q=0.5)
    sensor = Position(dim=2, sigma=[2.0, 3.0])
    m0 = np.column_stack([rng.uniform(-100, 100, (B, 2)), rng.uniform(-5, 5, (B, 2))])
    A = rng.standard_normal((B, 4, 4)) * 0.3
    P0 = np.einsum("bij,bkj->bik", A, A) + np.diag([25.0, 25.0, 4.0, 4.0])
    P0 = 0.5 * (P0 + np.swapaxes(P0, -1, -2))
    dts = rng.uniform(0.5, 1.5, (T, B)) if per_row_dt else np.full(T, 1.0)
    _, zs = _simulate(motion, sensor, m0, P0, dts, rng)
    return motion, sensor, m0, P0, dts, zs


def nonlinear_problem(B=7, T=6, seed=1, per_row_dt=False):
    rng = np.random.default_rng(seed)
    motion = CoordinatedTurn(q=0.1, q_omega=1e-4)
    sensor = RangeBearing(origin=(0.0, 0.0), sigma_range=5.0, sigma_bearing=0.01)
    m0 = np.column_stack([
        rng.uniform(500, 2000, (B, 2)) * rng.choice([-1, 1], (B, 2)),
        rng.uniform(-10, 10, (B, 2)),
        rng.uniform(-0.05, 0.05, B),
    ])
    P0 = np.broadcast_to(np.diag([400.0, 400.0, 4.0, 4.0, 1e-4]), (B, 5, 5)).copy()
    P0[:, 0, 1] = P0[:, 1, 0] = rng.uniform(-100, 100, B)
    dts = rng.uniform(0.5, 1.5, (T, B)) if per_row_dt else np.full(T, 1.0)
    _, zs = _simulate(motion, sensor, m0, P0, dts, rng)
    return motion, sensor, m0, P0, dts, zs


def _problem_for(name, **kw):
    return linear_problem(**kw) if name == "KF" else nonlinear_problem(**kw)


def _run(f, motion, sensor, x, P, dts, zs):
    """predict/update over the sequence; returns the list of (belief, innovation) per step."""
    b = tk.Gaussian(x, P)
    out = []
    for dt, z in zip(dts, zs, strict=True):
        b = f.predict(b, motion, dt)
        assert_symmetric(b.cov)
        b, innov = f.update(b, z, sensor)
        assert_symmetric(b.cov)
        out.append((b, innov))
    return out


def assert_symmetric(P):
    np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2))


def _close(a, b, tol=1e-12, scale=None):
    """Equal to ``tol`` relative to ``scale`` (default: the array's largest magnitude)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, (a.shape, b.shape)
    if scale is None:
        scale = float(np.nanmax(np.abs(b))) if np.any(np.isfinite(b)) else 1.0
    scale = max(1.0, float(scale))
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol * scale, equal_nan=True)


# --------------------------------------------------------------------------------------------
# Batch invariance
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("per_row_dt", [False, True], ids=["dt", "per-row-dt"])
@pytest.mark.parametrize("name", list(FILTERS))
def test_batch_equals_separate_unbatched_calls(name, per_row_dt):
    f = FILTERS[name]()
    motion, sensor, m0, P0, dts, zs = _problem_for(name, per_row_dt=per_row_dt)
    batched = _run(f, motion, sensor, m0, P0, dts, zs)
    for i in range(m0.shape[0]):
        dts_i = dts[:, i] if per_row_dt else dts
        single = _run(f, motion, sensor, m0[i], P0[i], dts_i, zs[:, i])
        for (bb, ib), (bs, is_) in zip(batched, single, strict=True):
            assert bs.mean.shape == (m0.shape[1],)
            _close(bb.mean[i], bs.mean)
            _close(bb.cov[i], bs.cov)
            # a residual z - zhat is a small difference of large numbers (a range of ~2 km):
            # compare it at the measurement's scale
            _close(ib.nu[i], is_.nu, scale=np.abs(zs).max())
            _close(ib.cov[i], is_.cov)


@pytest.mark.parametrize("name", list(FILTERS))
def test_batch_shape_2x3(name):
    f = FILTERS[name]()
    motion, sensor, m0, P0, dts, zs = _problem_for(name, B=6)
    flat = _run(f, motion, sensor, m0, P0, dts, zs)
    n, m = m0.shape[1], zs.shape[-1]
    grid = _run(f, motion, sensor, m0.reshape(2, 3, n), P0.reshape(2, 3, n, n), dts,
                zs.reshape(len(dts), 2, 3, m))
    for (bf, inf), (bg, ing) in zip(flat, grid, strict=True):
        assert bg.mean.shape == (2, 3, n) and bg.cov.shape == (2, 3, n, n)
        assert ing.nu.shape == (2, 3, m) and ing.cov.shape == (2, 3, m, m)
        _close(bg.mean.reshape(6, n), bf.mean)
        _close(bg.cov.reshape(6, n, n), bf.cov)
        _close(ing.nu.reshape(6, m), inf.nu, scale=np.abs(zs).max())
        # and a single (2, 3) element equals the unbatched call
    single = _run(f, motion, sensor, m0[4], P0[4], dts, zs[:, 4])
    _close(grid[-1][0].mean[1, 1], single[-1][0].mean)
    _close(grid[-1][0].cov[1, 1], single[-1][0].cov)


@pytest.mark.parametrize("name", NONLINEAR)
def test_moving_observer_origin_with_batch_axes(name):
    # one sensor object whose origin has the batch shape == per-row sensors
    f = FILTERS[name]()
    motion, _, m0, P0, dts, _ = nonlinear_problem(B=5)
    rng = np.random.default_rng(2)
    origins = rng.uniform(-300, 300, (5, 2))
    sensor = RangeBearing(origin=origins, sigma_range=5.0, sigma_bearing=0.01)
    z = sensor.h(motion.f(m0, 1.0)) + rng.standard_normal((5, 2)) * [5.0, 0.01]
    pb = f.predict(tk.Gaussian(m0, P0), motion, 1.0)
    bb, ib = f.update(pb, z, sensor)
    for i in range(5):
        si = RangeBearing(origin=origins[i], sigma_range=5.0, sigma_bearing=0.01)
        p = f.predict(tk.Gaussian(m0[i], P0[i]), motion, 1.0)
        b, inn = f.update(p, z[i], si)
        _close(bb.mean[i], b.mean)
        _close(bb.cov[i], b.cov)
        _close(ib.nu[i], inn.nu, scale=np.abs(z).max())


# --------------------------------------------------------------------------------------------
# Missing measurements
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(FILTERS))
def test_missing_measurement_rows_return_prediction(name):
    f = FILTERS[name]()
    motion, sensor, m0, P0, dts, zs = _problem_for(name)
    pred = f.predict(tk.Gaussian(m0, P0), motion, dts[0])
    z = zs[0].copy()
    z[2] = np.nan  # whole row missing
    z[5, 0] = np.nan  # one component missing: the row counts as missing
    post, innov = f.update(pred, z, sensor)
    for i in (2, 5):
        np.testing.assert_array_equal(post.mean[i], pred.mean[i])
        np.testing.assert_array_equal(post.cov[i], pred.cov[i])
        assert np.all(np.isnan(innov.nu[i]))
    assert np.all(np.isfinite(post.mean)) and np.all(np.isfinite(post.cov))
    # the other rows are updated as if no row were missing
    full, innov_full = f.update(pred, zs[0], sensor)
    keep = [0, 1, 3, 4, 6]
    _close(post.mean[keep], full.mean[keep])
    _close(post.cov[keep], full.cov[keep])
    _close(innov.nu[keep], innov_full.nu[keep], scale=np.abs(zs).max())
    assert not np.allclose(full.mean[keep], pred.mean[keep])  # an update happened
    assert_symmetric(post.cov)
    # NIS is nan exactly where the measurement is missing
    nis = innov.nis
    assert np.isnan(nis[[2, 5]]).all() and np.isfinite(nis[keep]).all()


@pytest.mark.parametrize("name", list(FILTERS))
def test_missing_measurement_unbatched(name):
    f = FILTERS[name]()
    motion, sensor, m0, P0, dts, _ = _problem_for(name)
    pred = f.predict(tk.Gaussian(m0[0], P0[0]), motion, 1.0)
    post, innov = f.update(pred, np.full(sensor.dim_z, np.nan), sensor)
    np.testing.assert_array_equal(post.mean, pred.mean)
    np.testing.assert_array_equal(post.cov, pred.cov)
    assert np.isnan(innov.nu).all()


# --------------------------------------------------------------------------------------------
# Equalities that hold on linear-Gaussian problems, and between filter variants
# --------------------------------------------------------------------------------------------


def test_linear_gaussian_all_filters_equal_kf():
    motion, sensor, m0, P0, dts, zs = linear_problem(B=4, T=20, seed=3)
    ref = _run(KF(), motion, sensor, m0, P0, dts, zs)
    for name in NONLINEAR + ["IEKF3"]:
        f = IEKF(iterations=3) if name == "IEKF3" else FILTERS[name]()
        out = _run(f, motion, sensor, m0, P0, dts, zs)
        for k, ((b, i), (br, ir)) in enumerate(zip(out, ref, strict=True)):
            try:
                _close(b.mean, br.mean, 1e-9)
                _close(b.cov, br.cov, 1e-9)
                _close(i.nu, ir.nu, 1e-9)
                _close(i.cov, ir.cov, 1e-9)
            except AssertionError as e:
                raise AssertionError(f"{name} differs from KF at step {k}: {e}") from None


def test_iekf_one_iteration_equals_ekf():
    motion, sensor, m0, P0, dts, zs = nonlinear_problem(T=8)
    a = _run(IEKF(iterations=1), motion, sensor, m0, P0, dts, zs)
    b = _run(EKF(), motion, sensor, m0, P0, dts, zs)
    for (ba, ia), (bb, ib) in zip(a, b, strict=True):
        _close(ba.mean, bb.mean)
        _close(ba.cov, bb.cov)
        _close(ia.nu, ib.nu)
        _close(ia.cov, ib.cov)


def test_iekf_iterations_change_the_nonlinear_update():
    # a sanity check that the iteration is not a no-op on a nonlinear sensor
    motion, sensor, m0, P0, dts, zs = nonlinear_problem(T=1)
    pred = EKF().predict(tk.Gaussian(m0, P0 * 100), motion, 1.0)
    b1, _ = IEKF(iterations=1).update(pred, zs[0], sensor)
    b5, _ = IEKF(iterations=5).update(pred, zs[0], sensor)
    assert np.max(np.abs(b1.mean - b5.mean)) > 1e-6


def test_second_order_ekf_equals_ekf_on_linear_sensor():
    motion, sensor, m0, P0, dts, zs = linear_problem(T=10)
    a = _run(EKF(order=2), motion, sensor, m0, P0, dts, zs)
    b = _run(EKF(), motion, sensor, m0, P0, dts, zs)
    for (ba, ia), (bb, ib) in zip(a, b, strict=True):
        _close(ba.mean, bb.mean)
        _close(ba.cov, bb.cov)
        _close(ia.cov, ib.cov)


def test_second_order_ekf_uses_hessian_terms():
    # zhat_i = h_i + 1/2 tr(Hs_i P), S = H P H^T + R + B with B_ij = 1/2 tr(Hs_i P Hs_j P)
    sensor = Sine()
    x = np.array([0.4, 10.0, 1.2])
    P = np.diag([0.5, 0.3, 0.2])
    P[0, 2] = P[2, 0] = 0.1
    b = tk.Gaussian(x, P)
    z = np.array([0.9])
    _, inn = EKF(order=2).update(b, z, sensor)
    Hs = sensor.hessian(x)[0]
    H = sensor.jacobian(x)
    zhat = sensor.h(x)[0] + 0.5 * np.trace(Hs @ P)
    S = (H @ P @ H.T)[0, 0] + 1.0 + 0.5 * np.trace(Hs @ P @ Hs @ P)
    assert inn.nu[0] == pytest.approx(z[0] - zhat, rel=1e-12)
    assert inn.cov[0, 0] == pytest.approx(S, rel=1e-12)


def test_ukf_and_ckf_weights_reproduce_mean_and_covariance():
    # the sigma points of N(x, P) have weighted mean x and covariance P (both rules)
    rng = np.random.default_rng(0)
    x = rng.standard_normal(5)
    A = rng.standard_normal((5, 5))
    P = A @ A.T + np.eye(5)
    for f in (UKF(), UKF(alpha=1.0, beta=0.0, kappa=0.0), CKF()):
        rule = f._rule(5)
        X = rule.points(x, P, "P")
        np.testing.assert_allclose(rule.wm @ X, x, atol=1e-12)
        d = X - x
        np.testing.assert_allclose((rule.wc[:, None] * d).T @ d, P, atol=1e-12)


def test_ckf_equals_ukf_alpha1_beta0_kappa0():
    motion, sensor, m0, P0, dts, zs = nonlinear_problem(T=5)
    a = _run(CKF(), motion, sensor, m0, P0, dts, zs)
    b = _run(UKF(alpha=1.0, beta=0.0, kappa=0.0), motion, sensor, m0, P0, dts, zs)
    for (ba, _), (bb, _) in zip(a, b, strict=True):
        _close(ba.mean, bb.mean, 1e-10)
        _close(ba.cov, bb.cov, 1e-10)


def test_square_root_ckf_equals_ckf():
    # the same filter in exact arithmetic: the QR factors' products are the CKF's sums
    motion, sensor, m0, P0, dts, zs = nonlinear_problem(T=5)
    a = _run(SRCKF(), motion, sensor, m0, P0, dts, zs)
    b = _run(CKF(), motion, sensor, m0, P0, dts, zs)
    for (ba, ia), (bb, ib) in zip(a, b, strict=True):
        _close(ba.mean, bb.mean, 1e-10)
        _close(ba.cov, bb.cov, 1e-10)
        _close(ia.cov, ib.cov, 1e-10)


def test_square_root_ckf_stays_definite_where_the_ckf_does_not():
    # a coordinate known to 1e3 measured to 1e-5, strongly correlated with an unmeasured one:
    # P- - K S K^T cancels eight orders of magnitude in the CKF; the square-root form's
    # covariance is a product of factors
    motion = tk.models.ConstantVelocity(dim=1, q=0.0)
    sensor = tk.models.Position(dim=1, sigma=1e-5)
    P0 = np.array([[1e6, 0.999999 * 1e6], [0.999999 * 1e6, 1e6]])
    b_sr = b_ckf = tk.Gaussian(np.zeros(2), P0)
    worst = {"CKF": np.inf, "SRCKF": np.inf}
    for z in (1.0, 1.1, 1.2, 1.3):
        b_sr = SRCKF().update(SRCKF().predict(b_sr, motion, 1.0), [z], sensor)[0]
        worst["SRCKF"] = min(worst["SRCKF"], np.linalg.eigvalsh(b_sr.cov)[0])
        try:
            b_ckf = CKF().update(CKF().predict(b_ckf, motion, 1.0), [z], sensor)[0]
            worst["CKF"] = min(worst["CKF"], np.linalg.eigvalsh(b_ckf.cov)[0])
        except ValueError:  # its covariance is no longer positive definite
            worst["CKF"] = -np.inf
    assert worst["SRCKF"] > 0
    assert worst["CKF"] < 0


# --------------------------------------------------------------------------------------------
# The missing-measurements thesis's random sine (S3)
# --------------------------------------------------------------------------------------------


def test_random_sine_s3_ekf_ekf2_ukf(record_property):
    """S3: RandomSine(q1=0.2, q2=0.1), y = a sin(theta) + r, R = 1, dt = 0.01, 500 steps,
    prior N((0, 10, 1), diag(3, 3, 3)); the truth starts from a draw of that prior."""
    dt, T = 0.01, 500
    motion, sensor = RandomSine(q1=0.2, q2=0.1), Sine(sigma=1.0)
    m0, P0 = np.array([0.0, 10.0, 1.0]), np.diag([3.0, 3.0, 3.0])
    rng = np.random.default_rng(2024)
    X, Z = _simulate(motion, sensor, m0[None], P0[None], np.full(T, dt), rng)
    X, Z = X[:, 0], Z[:, 0]
    raw = float(np.mean((Z[:, 0] - sensor.h(X)[:, 0]) ** 2))
    results = {}
    for name, f in [("EKF", EKF()), ("EKF2", EKF(order=2)), ("UKF", UKF())]:
        _, hist = run_filter(f, tk.Gaussian(m0, P0), motion, sensor, Z, dt, history=True)
        assert hist.mean.shape == (T, 3) and hist.cov.shape == (T, 3, 3)
        mse = np.mean((hist.mean - X) ** 2, axis=0)
        signal = float(np.mean((sensor.h(hist.mean)[:, 0] - sensor.h(X)[:, 0]) ** 2))
        results[name] = mse
        record_property(f"{name}_mse_theta_omega_a", [float(v) for v in mse])
        record_property(f"{name}_signal_mse", signal)
        print(f"S3 {name}: MSE theta {mse[0]:.3f}, omega {mse[1]:.3f}, a {mse[2]:.3f}; "
              f"signal MSE {signal:.3f} (raw measurement MSE {raw:.3f})")
        assert np.all(np.isfinite(mse)), name
        assert np.all(np.isfinite(hist.cov)), name
        # theta and a are identifiable only up to (theta + pi, -a); the signal a sin(theta)
        # is identifiable, and the filtered signal must beat the raw measurements clearly
        assert signal < 0.5 * raw, (name, signal, raw)
    assert not np.allclose(results["EKF"], results["EKF2"])  # order 2 does change the estimate


# --------------------------------------------------------------------------------------------
# Smoothing, consistency, streaming
# --------------------------------------------------------------------------------------------


def _mc_linear(runs, T, seed, dt=1.0):
    rng = np.random.default_rng(seed)
    motion = ConstantVelocity(dim=2, q=0.2)
    sensor = Position(dim=2, sigma=5.0)
    m0 = np.zeros((runs, 4))
    P0 = np.broadcast_to(np.diag([100.0, 100.0, 10.0, 10.0]), (runs, 4, 4)).copy()
    X, Z = _simulate(motion, sensor, m0, P0, np.full(T, dt), rng)
    return motion, sensor, m0, P0, X, Z


def test_rts_smoothing_reduces_error_monte_carlo():
    runs, T = 500, 40
    motion, sensor, m0, P0, X, Z = _mc_linear(runs, T, seed=11)
    f = KF()
    _, hist = run_filter(f, tk.Gaussian(m0, P0), motion, sensor, Z, 1.0, history=True)
    sm = smooth(f, hist, motion, 1.0)
    assert sm.mean.shape == (T, runs, 4) and sm.cov.shape == (T, runs, 4, 4)
    mse_f = np.mean((hist.mean - X) ** 2)
    mse_s = np.mean((sm.mean - X) ** 2)
    # RTS uses the future measurements: over 500 runs x 40 steps the smoothed MSE is clearly
    # smaller (the ratio with this seed is 0.31); stated margin: at least 50 % lower
    assert mse_s < 0.5 * mse_f, (mse_s, mse_f)
    # the last smoothed step is the last filtered step; smoothed covariances are no larger
    np.testing.assert_array_equal(sm.mean[-1], hist.mean[-1])
    np.testing.assert_array_equal(sm.cov[-1], hist.cov[-1])
    assert np.all(np.trace(sm.cov, axis1=-2, axis2=-1) <= np.trace(hist.cov, axis1=-2,
                                                                  axis2=-1) + 1e-9)
    assert_symmetric(sm.cov)
    # the smoothed covariance is honest too: mean NEES over all runs and steps near n = 4
    e = sm.mean - X
    nees = np.einsum("...i,...ij,...j->...", e, np.linalg.inv(sm.cov), e)
    assert 3.8 < nees.mean() < 4.2


@pytest.mark.parametrize("name", ["EKF", "UKF", "CKF"])
def test_smoother_of_other_filters_equals_kf_smoother_on_linear(name):
    motion, sensor, m0, P0, X, Z = _mc_linear(runs=5, T=15, seed=4)
    f_ref, f = KF(), FILTERS[name]()
    _, h_ref = run_filter(f_ref, tk.Gaussian(m0, P0), motion, sensor, Z, 1.0, history=True)
    _, h = run_filter(f, tk.Gaussian(m0, P0), motion, sensor, Z, 1.0, history=True)
    s_ref = smooth(f_ref, h_ref, motion, 1.0)
    s = smooth(f, h, motion, 1.0)
    _close(s.mean, s_ref.mean, 1e-9)
    _close(s.cov, s_ref.cov, 1e-9)


def test_kf_nees_nis_consistent_chi_square():
    runs, T, n, m = 2000, 30, 4, 2
    motion, sensor, m0, P0, X, Z = _mc_linear(runs, T, seed=5)
    f = KF()
    b = tk.Gaussian(m0, P0)
    for k in range(T):
        b = f.predict(b, motion, 1.0)
        b, innov = f.update(b, Z[k], sensor)
    e = b.mean - X[-1]
    nees = np.einsum("bi,bij,bj->b", e, np.linalg.inv(b.cov), e)
    # runs are independent: sum of NEES ~ chi2(runs * n); two-sided 99.9 % interval
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], runs * n) / runs
    assert lo < nees.mean() < hi, (lo, nees.mean(), hi)
    nis = innov.nis
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], runs * m) / runs
    assert lo < nis.mean() < hi, (lo, nis.mean(), hi)


def test_run_filter_matches_manual_loop_and_calls_on_step():
    motion, sensor, m0, P0, dts, zs = nonlinear_problem(T=6)
    f = UKF()
    seen = []
    b, hist = run_filter(f, tk.Gaussian(m0, P0), motion, sensor, list(zs), 1.0, history=True,
                         on_step=lambda k, bel, inn: seen.append((k, inn.nu.shape)))
    manual = _run(f, motion, sensor, m0, P0, dts, zs)
    _close(b.mean, manual[-1][0].mean)
    _close(hist.mean, np.stack([m[0].mean for m in manual]))
    _close(hist.cov, np.stack([m[0].cov for m in manual]))
    assert seen == [(k, (7, 2)) for k in range(6)]
    _, none = run_filter(f, tk.Gaussian(m0, P0), motion, sensor, list(zs), 1.0)
    assert none is None


def _peak_bytes(steps, runs=1000, n=4):
    motion = ConstantVelocity(dim=2, q=0.1)
    sensor = Position(dim=2, sigma=1.0)
    prior = tk.Gaussian(np.zeros((runs, n)), np.broadcast_to(np.eye(n), (runs, n, n)).copy())
    rng = np.random.default_rng(0)

    def measurements():
        for _ in range(steps):
            yield rng.standard_normal((runs, 2))

    f = KF()
    # warm up (first-call allocations, caches), then measure
    run_filter(f, prior, motion, sensor, (rng.standard_normal((runs, 2)) for _ in range(3)), 1.0)
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        b, hist = run_filter(f, prior, motion, sensor, measurements(), 1.0, history=False)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert hist is None and b.mean.shape == (runs, n)
    return peak


def test_run_filter_streaming_memory_does_not_grow_with_steps():
    runs, n = 1000, 4
    p100 = _peak_bytes(100, runs, n)
    p1000 = _peak_bytes(1000, runs, n)
    one_cov = runs * n * n * 8  # 128 kB
    # the working set is a few beliefs and temporaries (runs x n^2), independent of steps
    assert p1000 <= 1.1 * p100 + one_cov, (p100, p1000)
    assert p1000 < 40 * one_cov, (p1000, one_cov)
