"""Adaptive filters of Hashemi and Alfi (2019) (trackkit.filters.adaptive): MC-EKF, the
second-order Jacobian term, the innovation-window R adaptation, the lambda Q adaptation, the
Sage-Husa AEKF baseline; batch invariance, missing measurements, and a DBT sanity run.

Hand computations use plain numpy (``np.linalg.inv``, explicit loops), never the library's
kernels, so that each test could fail.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.angles import wrap
from trackkit.filters import EKF, UKF, run_filter
from trackkit.filters.adaptive import (
    AEKF,
    AMCEKF,
    MCEKF,
    Q_FORMS,
    AdaptiveBelief,
    SageHusaBelief,
    q_factor,
    r_factor,
    sage_husa_weight,
    second_order_jacobian,
    window_covariance,
)
from trackkit.models import (
    Augmented,
    BearingFrequency,
    ConstantVelocity,
    CoordinatedTurn,
    Position,
    RangeBearing,
)

KNOT = 1852.0 / 3600.0
SIGMA_B, SIGMA_F = np.deg2rad(2.0), 0.3


# --------------------------------------------------------------------------------------------
# Problems
# --------------------------------------------------------------------------------------------


def dbt_problem(B: int = 5, T: int = 10, seed: int = 0, q: float = 1e-4):
    """Hashemi and Alfi's scenario 1 geometry (courses CCW from east): observer from the origin at
    5 kn, course 20 deg; target from (6000, 6000) m at 15 kn, course 260 deg, 500 Hz; sigma 2 deg,
    0.3 Hz, c = 1500 m/s; T = 1 s. The prior is drawn around the truth from P0."""
    rng = np.random.default_rng(seed)
    vo = 5 * KNOT * np.array([np.cos(np.deg2rad(20)), np.sin(np.deg2rad(20))])
    vt = 15 * KNOT * np.array([np.cos(np.deg2rad(260)), np.sin(np.deg2rad(260))])
    x0 = np.array([6000.0, 6000.0, vt[0], vt[1], 500.0])
    t = np.arange(1, T + 1, dtype=float)
    truth = x0 + t[:, None] * np.array([vt[0], vt[1], 0.0, 0.0, 0.0])
    sensors = [BearingFrequency(origin=vo * tk_, velocity=vo, sigma_bearing=SIGMA_B,
                                sigma_freq=SIGMA_F, c=1500.0) for tk_ in t]
    zs = np.stack([s.h(truth[k]) for k, s in enumerate(sensors)])[:, None, :]
    zs = zs + rng.standard_normal((T, B, 2)) * [SIGMA_B, SIGMA_F]
    P0 = np.diag([1000.0**2, 1000.0**2, 4.0**2, 4.0**2, 1.0**2])
    m0 = x0 + rng.standard_normal((B, 5)) @ np.linalg.cholesky(P0).T
    motion = Augmented(ConstantVelocity(2, q), 1)
    return motion, sensors, truth, zs, m0, P0


def linear_problem(B: int = 2):
    motion = ConstantVelocity(dim=2, q=0.5)
    sensor = Position(dim=2, sigma=[2.0, 3.0])
    rng = np.random.default_rng(3)
    m0 = rng.uniform(-5, 5, (B, 4))
    P0 = np.broadcast_to(np.diag([25.0, 16.0, 4.0, 1.0]), (B, 4, 4)).copy()
    P0[:, 0, 2] = P0[:, 2, 0] = 3.0
    return motion, sensor, m0, P0


def _close(a, b, tol: float = 1e-12, scale: float | None = None) -> None:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape, (a.shape, b.shape)
    if scale is None:
        scale = float(np.nanmax(np.abs(b))) if np.any(np.isfinite(b)) else 1.0
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol * max(scale, 1e-300), equal_nan=True)


def _joseph(P, H, R):
    """Independent numpy Kalman pieces: S, K and the Joseph covariance."""
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    A = np.eye(P.shape[0]) - K @ H
    return S, K, A @ P @ A.T + K @ R @ K.T


def _fd_first_and_diag_second(sensor, x, steps):
    """Central differences of h: first derivatives (m, n) (steps / 10, against truncation) and
    the pure second derivatives d2h_i/dx_j^2 (m, n) (steps, against rounding), angles
    differenced on the circle."""
    h0 = sensor.h(x)
    n = x.shape[0]
    J = np.empty((sensor.dim_z, n))
    D2 = np.empty((sensor.dim_z, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = steps[j] / 10
        J[:, j] = sensor.residual(sensor.h(x + e), sensor.h(x - e)) / (2 * e[j])
        e[j] = steps[j]
        hp, hm = sensor.h(x + e), sensor.h(x - e)
        D2[:, j] = (sensor.residual(hp, h0) - sensor.residual(h0, hm)) / steps[j] ** 2
    return J, D2


# --------------------------------------------------------------------------------------------
# MC-EKF
# --------------------------------------------------------------------------------------------


def test_mcekf_covariance_is_joseph_at_the_updated_state():
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=1)
    pred = MCEKF().predict(tk.Gaussian(m0[0], P0), motion, 1.0)
    x, P = pred.mean, pred.cov
    post, innov = MCEKF().update(pred, zs[0, 0], sensors[0])
    ekf, ekf_innov = EKF().update(pred, zs[0, 0], sensors[0])

    s, R = sensors[0], sensors[0].noise
    r = zs[0, 0] - s.h(x)
    r[0] = wrap(r[0])
    H = s.jacobian(x)
    S, K, _ = _joseph(P, H, R)
    x_plus = x + K @ r
    Hp = s.jacobian(x_plus)
    _, Kp, P_plus = _joseph(P, Hp, R)

    _close(post.mean, x_plus, 1e-10)
    _close(post.mean, ekf.mean, 1e-12)  # the state update is the EKF's
    _close(post.cov, P_plus, 1e-9)
    _close(post.cov, P - Kp @ Hp @ P, 1e-7)  # the paper's form, equal for the optimal K+
    _close(innov.nu, r, 1e-12, scale=1.0)
    _close(innov.cov, S, 1e-12)
    _close(innov.cov, ekf_innov.cov, 1e-12)
    # the re-linearisation matters here (x+ moves hundreds of metres), so it is tested
    assert np.linalg.norm(x_plus[:2] - x[:2]) > 50.0
    assert not np.allclose(post.cov, ekf.cov, rtol=1e-4, atol=0)


def test_mcekf_batched_joseph_at_updated_state():
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=4)
    f = MCEKF()
    pred = f.predict(tk.Gaussian(m0, np.broadcast_to(P0, (4, 5, 5)).copy()), motion, 1.0)
    post, _ = f.update(pred, zs[0], sensors[0])
    s, R = sensors[0], sensors[0].noise
    for i in range(4):
        x, P = pred.mean[i], pred.cov[i]
        r = zs[0, i] - s.h(x)
        r[0] = wrap(r[0])
        _, K, _ = _joseph(P, s.jacobian(x), R)
        x_plus = x + K @ r
        _close(post.mean[i], x_plus, 1e-10)
        _close(post.cov[i], _joseph(P, s.jacobian(x_plus), R)[2], 1e-9)


def test_mcekf_equals_ekf_on_a_linear_sensor():
    motion, sensor, m0, P0 = linear_problem(B=7)
    rng = np.random.default_rng(0)
    b_mc = b_ekf = tk.Gaussian(m0, P0)
    for _ in range(5):
        z = rng.normal(0, 10, (7, 2))
        b_mc, i_mc = MCEKF().update(MCEKF().predict(b_mc, motion, 1.0), z, sensor)
        b_ekf, i_ekf = EKF().update(EKF().predict(b_ekf, motion, 1.0), z, sensor)
        _close(b_mc.mean, b_ekf.mean)
        _close(b_mc.cov, b_ekf.cov)
        _close(i_mc.nu, i_ekf.nu)
        _close(i_mc.cov, i_ekf.cov)


def test_amcekf_without_adaptation_is_the_mcekf():
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=3, T=20)
    for so in (False, True):
        a = AMCEKF(second_order=so, adapt_r=False, adapt_q=False)
        m = MCEKF(second_order=so)
        ba, bm = a.init(tk.Gaussian(m0, P0)), tk.Gaussian(m0, P0)
        for k, s in enumerate(sensors):
            ba, ia = a.update(a.predict(ba, motion, 1.0), zs[k], s)
            bm, im = m.update(m.predict(bm, motion, 1.0), zs[k], s)
        _close(ba.mean, bm.mean)
        _close(ba.cov, bm.cov)
        _close(ia.cov, im.cov)
        np.testing.assert_array_equal(ba.r_scale, 1.0)
        np.testing.assert_array_equal(ba.q_scale, 1.0)


# --------------------------------------------------------------------------------------------
# Second-order term (eqs. 12-13)
# --------------------------------------------------------------------------------------------


def test_second_order_jacobian_against_finite_differences(num):
    _, sensors, truth, _, _, _ = dbt_problem(B=1, T=3)
    s = sensors[2]
    x = truth[2] + np.array([-800.0, 500.0, 2.0, -1.0, 0.7])
    steps = np.array([10.0, 10.0, 1.0, 1.0, 1.0])
    J_fd, D2_fd = _fd_first_and_diag_second(s, x, steps)
    H2 = second_order_jacobian(s, x)
    num.close(H2, J_fd + 0.5 * D2_fd, rtol=1e-7, per_row=True, what="H = J + D2/2")
    # the added term itself, held to its own (much smaller) magnitude
    num.close(H2 - s.jacobian(x), 0.5 * D2_fd, rtol=1e-5, per_row=True, what="D2/2")
    assert np.abs(D2_fd).max() > 0
    # batched evaluation equals the per-row one
    xs = np.stack([x, x + 100.0, x - 50.0])
    Hb = second_order_jacobian(s, xs)
    for i in range(3):
        _close(Hb[i], second_order_jacobian(s, xs[i]))


def test_mcekf_second_order_uses_the_elementwise_term_at_both_points():
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=1)
    f = MCEKF(second_order=True)
    pred = f.predict(tk.Gaussian(m0[0], P0), motion, 1.0)
    x, P = pred.mean, pred.cov
    s, R = sensors[0], sensors[0].noise
    post, innov = f.update(pred, zs[0, 0], s)
    steps = np.array([10.0, 10.0, 1.0, 1.0, 1.0])
    J, D2 = _fd_first_and_diag_second(s, x, steps)
    H = J + 0.5 * D2
    S, K, _ = _joseph(P, H, R)
    r = s.residual(zs[0, 0], s.h(x))
    x_plus = x + K @ r
    Jp, D2p = _fd_first_and_diag_second(s, x_plus, steps)
    _, _, P_plus = _joseph(P, Jp + 0.5 * D2p, R)
    _close(innov.cov, S, 1e-6)
    _close(post.mean, x_plus, 1e-6)
    _close(post.cov, P_plus, 1e-5)


# --------------------------------------------------------------------------------------------
# R adaptation: window statistics (eqs. 14-19)
# --------------------------------------------------------------------------------------------


def test_window_covariance_and_alpha_kernels_by_hand():
    buf = np.zeros((3, 2))
    np.testing.assert_array_equal(window_covariance(buf, 0), np.zeros((2, 2)))
    buf[0], buf[1] = [1.0, 2.0], [-3.0, 0.5]
    C = window_covariance(buf, 2)  # two seen: (1/2) sum
    np.testing.assert_allclose(C, [[5.0, 0.25], [0.25, 2.125]], rtol=1e-15)
    buf[2] = [0.0, 4.0]
    C = window_covariance(buf, 7)  # full window: (1/3) sum
    np.testing.assert_allclose(C, np.array([[10.0, 0.5], [0.5, 20.25]]) / 3, rtol=1e-15)
    S = np.array([[2.0, 0.3], [0.3, 1.0]])
    assert r_factor(buf, 7, S) == pytest.approx((10.0 + 20.25) / 3 / 3.0, rel=1e-15)


def _feed(f, motion, sensor, b, r_k):
    """One step whose innovation is (up to rounding) the given r_k: z = h(x-) + r_k."""
    pred = f.predict(b, motion, 1.0)
    z = sensor.h(pred.mean) + r_k
    post, innov = f.update(pred, z, sensor)
    return pred, post, innov


def test_r_adaptation_window_alpha_and_ring_buffer_by_hand():
    motion, sensor, m0, P0 = linear_problem(B=2)
    N = 3
    f = AMCEKF(window=N, second_order=False, adapt_q=False, r_bounds=None)
    rng = np.random.default_rng(5)
    seq = rng.normal(0.0, 4.0, (6, 2, 2))  # 6 steps, 2 rows, 2 components
    b = f.init(tk.Gaussian(m0, P0))
    assert b.residuals.shape == (2, N, 0) and np.all(b.count == 0)
    H, R0 = np.eye(2, 4), sensor.noise
    seen = []
    r_scale = np.ones(2)
    for k in range(6):
        pred, b, innov = _feed(f, motion, sensor, b, seq[k])
        r = innov.nu
        _close(r, seq[k], 1e-12, scale=10.0)
        seen.append(r)
        for i in range(2):
            S_hand = H @ pred.cov[i] @ H.T + r_scale[i] * R0  # (16) with R(t)
            _close(innov.cov[i], S_hand)
            last = [s[i] for s in seen[-N:]]
            C_hand = sum(np.outer(v, v) for v in last) / len(last)  # (15), 1/k before full
            _close(window_covariance(b.residuals[i], b.count[i]), C_hand)
            alpha = np.trace(C_hand) / np.trace(S_hand)  # (18)
            _close(b.r_scale[i], r_scale[i] * alpha)  # (19), compounding
        r_scale = b.r_scale.copy()
        np.testing.assert_array_equal(b.count, k + 1)
    # ring buffer after 6 innovations (indices 0..5): slot j holds the latest i with i % 3 = j
    for j in range(N):
        np.testing.assert_array_equal(b.residuals[:, j], seen[3 + j])


def test_r_adaptation_wait_for_full_window_and_bounds():
    motion, sensor, m0, P0 = linear_problem(B=2)
    rng = np.random.default_rng(6)
    seq = rng.normal(0.0, 4.0, (5, 2, 2))
    f = AMCEKF(window=3, second_order=False, adapt_q=False, warmup="wait", r_bounds=None)
    b = f.init(tk.Gaussian(m0, P0))
    for k in range(5):
        _, b, innov = _feed(f, motion, sensor, b, seq[k])
        if k < 2:
            np.testing.assert_array_equal(b.r_scale, 1.0)
        elif k == 2:  # window full for the first time: alpha over the 3 innovations
            C = window_covariance(b.residuals, b.count)
            alpha = np.trace(C, axis1=-2, axis2=-1) / np.trace(innov.cov, axis1=-2, axis2=-1)
            _close(b.r_scale, alpha)
    # bounds clamp r_scale: huge innovations push it to the upper bound, tiny ones to the lower
    for scale, bound in ((1e3, 1.1), (1e-6, 0.9)):
        g = AMCEKF(window=3, second_order=False, adapt_q=False, r_bounds=(0.9, 1.1))
        b = g.init(tk.Gaussian(m0, P0))
        _, b, _ = _feed(g, motion, sensor, b, np.full((2, 2), scale))
        np.testing.assert_array_equal(b.r_scale, bound)


# --------------------------------------------------------------------------------------------
# Q adaptation: lambda (eqs. 20-21)
# --------------------------------------------------------------------------------------------


def test_q_factor_forms_by_hand():
    delta = np.array([1.0, -2.0, 0.5, 3.0])
    A = np.array([[2.0, 0.3, 0, 0], [0.3, 1.0, 0.2, 0], [0, 0.2, 0.5, 0.1], [0, 0, 0.1, 4.0]])
    P = A @ A.T
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    R = np.diag([0.5, 2.0])
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    ms = (1 + 4 + 0.25 + 9) / 4
    nees = delta @ np.linalg.inv(P) @ delta
    assert q_factor(delta, P, "mean-square") == pytest.approx(ms, rel=1e-15)
    assert q_factor(delta, P, "inverse-mean-square") == pytest.approx(1 / ms, rel=1e-15)
    assert q_factor(delta, P, "normalised-n") == pytest.approx(nees / 4, rel=1e-12)
    assert q_factor(delta, P, "normalised", K, H) == pytest.approx(
        nees / np.trace(K @ H), rel=1e-12)
    with pytest.raises(ValueError, match="q_form"):
        q_factor(delta, P, "cubic")
    # the normalised forms are dimensionless: a change of units (km for the first two
    # components) leaves them unchanged, the literal one changes
    D = np.diag([1e-3, 1e-3, 1.0, 1.0])
    Kd, Hd = D @ K, H @ np.linalg.inv(D)
    assert q_factor(D @ delta, D @ P @ D, "normalised", Kd, Hd) == pytest.approx(
        q_factor(delta, P, "normalised", K, H), rel=1e-10)
    assert q_factor(D @ delta, D @ P @ D, "mean-square") != pytest.approx(ms, rel=0.1)


@pytest.mark.parametrize("form", Q_FORMS)
def test_q_adaptation_in_the_filter_by_hand(form):
    motion, sensor, m0, P0 = linear_problem(B=2)
    f = AMCEKF(second_order=False, adapt_r=False, q_form=form, q_bounds=None)
    b = f.init(tk.Gaussian(m0, P0))
    H, R = np.eye(2, 4), sensor.noise
    F = motion.jacobian(None, 1.0)
    q, P_prev = np.ones(2), P0
    for r_k in ([3.0, -1.0], [0.5, 0.2], [-8.0, 6.0]):
        pred, b, _ = _feed(f, motion, sensor, b, np.array([r_k, r_k]) * [[1.0], [0.3]])
        for i in range(2):
            # P- with Q(t) = q_scale Q0
            _close(pred.cov[i], F @ P_prev[i] @ F.T + q[i] * motion.noise(None, 1.0))
            delta = b.mean[i] - pred.mean[i]  # (20)
            Pm = pred.cov[i]
            K = Pm @ H.T @ np.linalg.inv(H @ Pm @ H.T + R)
            ms = np.mean(delta**2)
            nees = delta @ np.linalg.inv(Pm) @ delta
            lam = {"mean-square": ms, "inverse-mean-square": 1 / ms,
                   "normalised": nees / np.trace(K @ H), "normalised-n": nees / 4}[form]
            _close(b.q_scale[i], q[i] * lam, 1e-10)  # (21) Q(t+1) = lambda Q(t)
        q, P_prev = b.q_scale.copy(), b.cov.copy()


def test_q_scale_and_lambda_clamping():
    motion, sensor, m0, P0 = linear_problem(B=2)
    big, small = np.full((2, 2), 50.0), np.full((2, 2), 1e-3)
    # mean-square with large moves -> lambda >> 1, clamped at the upper q bound; inverse -> low
    for form, r_k, bound in (("mean-square", big, 2.0), ("inverse-mean-square", big, 0.5),
                             ("mean-square", small, 0.5), ("normalised", big, 2.0)):
        f = AMCEKF(second_order=False, adapt_r=False, q_form=form, q_bounds=(0.5, 2.0))
        b = f.init(tk.Gaussian(m0, P0))
        _, b, _ = _feed(f, motion, sensor, b, r_k)
        np.testing.assert_array_equal(b.q_scale, bound)
    # lam_bounds clamp each lambda before it compounds: two steps of a clamped 1.5 -> 2.25
    f = AMCEKF(second_order=False, adapt_r=False, q_form="mean-square", q_bounds=None,
               lam_bounds=(0.8, 1.5))
    b = f.init(tk.Gaussian(m0, P0))
    for _ in range(2):
        _, b, _ = _feed(f, motion, sensor, b, big)
    _close(b.q_scale, np.full(2, 2.25), 1e-15)


def test_normalised_lambda_averages_one_for_a_consistent_filter():
    """E[delta^T P-^{-1} delta] = tr(K H): the default form is 1 on average when the filter's
    model is right, while (1/n) delta^T P-^{-1} delta averages tr(K H)/n (here < 1/2)."""
    rng = np.random.default_rng(11)
    B = 4000
    motion, sensor, _, _ = linear_problem(B=1)
    P0 = np.diag([25.0, 16.0, 4.0, 1.0])
    x0 = rng.standard_normal((B, 4)) @ np.linalg.cholesky(P0).T  # truth ~ N(0, P0)
    Q = motion.noise(None, 1.0)
    xt = motion.f(x0, 1.0) + rng.standard_normal((B, 4)) @ np.linalg.cholesky(Q).T
    z = xt[:, :2] + rng.standard_normal((B, 2)) * [2.0, 3.0]
    lam = {}
    for form in ("normalised", "normalised-n"):
        f = AMCEKF(second_order=False, adapt_r=False, q_form=form, q_bounds=None)
        b = f.init(tk.Gaussian(np.zeros((B, 4)), np.broadcast_to(P0, (B, 4, 4)).copy()))
        pred = f.predict(b, motion, 1.0)
        post, _ = f.update(pred, z, sensor)
        lam[form] = post.q_scale
    Pm = motion.jacobian(None, 1.0) @ P0 @ motion.jacobian(None, 1.0).T + Q
    H = np.eye(2, 4)
    trKH = np.trace(Pm @ H.T @ np.linalg.inv(H @ Pm @ H.T + sensor.noise) @ H)
    se = lam["normalised"].std() / np.sqrt(B)
    assert abs(lam["normalised"].mean() - 1.0) < 4 * se
    assert abs(lam["normalised-n"].mean() - trKH / 4) < 4 * se * trKH / 4
    assert trKH / 4 < 0.5


# --------------------------------------------------------------------------------------------
# Sage-Husa AEKF
# --------------------------------------------------------------------------------------------


def _sage_husa_loop(b_, motion, sensor, m0, P0, zs, adapt_q):
    """Direct per-row loop of the Sage-Husa recursion (documented in AEKF)."""
    x, P = m0.copy(), P0.copy()
    R, Q = sensor.noise.copy(), None
    out, accepted, rejected = [], 0, 0
    for k, z in enumerate(zs):
        F, Qm = motion.jacobian(x, 1.0), motion.noise(x, 1.0)
        if adapt_q and Q is None:
            Q = Qm.copy()
        x = motion.f(x, 1.0)
        P = F @ P @ F.T + (Q if adapt_q else Qm)
        H = sensor.jacobian(x)
        r = sensor.residual(z, sensor.h(x))
        d = (1 - b_) / (1 - b_ ** (k + 1))
        Rc = (1 - d) * R + d * (np.outer(r, r) - H @ P @ H.T)
        Rc = 0.5 * (Rc + Rc.T)
        if np.linalg.eigvalsh(Rc)[0] > 0:
            R, accepted = Rc, accepted + 1
        else:
            rejected += 1
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        xn = x + K @ r
        A = np.eye(len(x)) - K @ H
        Pn = A @ P @ A.T + K @ R @ K.T
        if adapt_q:
            dl = xn - x
            Qc = Q + d * (np.outer(dl, dl) + Pn - P)
            Qc = 0.5 * (Qc + Qc.T)
            if np.linalg.eigvalsh(Qc)[0] >= -1e-12 * np.abs(Qc).max():
                Q = Qc
        x, P = xn, Pn
        out.append((x.copy(), P.copy(), R.copy(), None if Q is None else Q.copy()))
    return out, accepted, rejected


@pytest.mark.parametrize("adapt_q", [False, True])
def test_sage_husa_against_a_direct_loop(adapt_q):
    rng = np.random.default_rng(8)
    B, T = 3, 15
    motion = ConstantVelocity(2, 0.5)
    sensor = RangeBearing(origin=(0.0, 0.0), sigma_range=5.0, sigma_bearing=0.01)
    m0 = np.column_stack([rng.uniform(800, 1500, (B, 2)), rng.uniform(-5, 5, (B, 2))])
    P0 = np.broadcast_to(np.diag([100.0, 100.0, 4.0, 4.0]), (B, 4, 4)).copy()
    # measurements noisier than the filter's R, so that the estimated R grows (is accepted)
    zs = np.stack([sensor.h(m0 + t * np.column_stack([m0[:, 2:], 0 * m0[:, 2:]]))
                   for t in range(1, T + 1)]) + rng.standard_normal((T, B, 2)) * [15.0, 0.03]
    f = AEKF(forgetting=0.9, adapt_q=adapt_q)
    b = f.init(tk.Gaussian(m0, P0))
    hist = []
    for k in range(T):
        b, _ = f.update(f.predict(b, motion, 1.0), zs[k], sensor)
        hist.append(b)
    n_acc = n_rej = 0
    for i in range(B):
        ref, acc, rej = _sage_husa_loop(0.9, motion, sensor, m0[i], P0[i], zs[:, i], adapt_q)
        n_acc, n_rej = n_acc + acc, n_rej + rej
        for bk, (x, P, R, Q) in zip(hist, ref, strict=True):
            _close(bk.mean[i], x, 1e-9)
            _close(bk.cov[i], P, 1e-9)
            _close(bk.R[i], R, 1e-9)
            if adapt_q:
                _close(bk.Q[i], Q, 1e-9)
    assert n_acc > 0 and n_rej > 0  # both branches of the safeguard ran
    np.testing.assert_array_equal(hist[-1].count, T)


def test_sage_husa_weight():
    assert sage_husa_weight(0.97, 0) == 1.0
    assert sage_husa_weight(0.97, 1) == pytest.approx(1 / 1.97, rel=1e-14)
    assert sage_husa_weight(0.97, 10_000) == pytest.approx(0.03, rel=1e-12)


# --------------------------------------------------------------------------------------------
# Batch invariance and missing measurements
# --------------------------------------------------------------------------------------------

FILTERS = {
    "MCEKF": MCEKF,
    "MCEKF2": lambda: MCEKF(second_order=True),
    "AMCEKF": AMCEKF,
    "AMCEKF-w4-wait": lambda: AMCEKF(window=4, warmup="wait"),
    "AMCEKF-ms": lambda: AMCEKF(window=4, q_form="mean-square"),
    "AEKF": AEKF,
    "AEKF-q": lambda: AEKF(adapt_q=True),
}


def _init(f, m, P):
    g = tk.Gaussian(m, P)
    return f.init(g)


def _run(f, motion, sensors, zs, m0, P0):
    b = _init(f, m0, P0)
    out = []
    for k, s in enumerate(sensors):
        b = f.predict(b, motion, 1.0)
        b, innov = f.update(b, zs[k], s)
        out.append((b, innov))
    return out


def _missing(zs):
    zs = zs.copy()
    zs[3, 1] = np.nan  # whole row
    zs[7, 4, 1] = np.nan  # one component: the row counts as missing
    zs[8, :, :] = np.nan  # every row
    return zs


@pytest.mark.parametrize("name", list(FILTERS))
def test_batch_equals_separate_runs(name):
    f = FILTERS[name]()
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=5, T=30)
    zs = _missing(zs)
    P0b = np.broadcast_to(P0, (5, 5, 5)).copy()
    batched = _run(f, motion, sensors, zs, m0, P0b)
    for i in range(5):
        single = _run(f, motion, sensors, zs[:, i], m0[i], P0)
        for (bb, ib), (bs, is_) in zip(batched, single, strict=True):
            for field, a in zip(bb._fields, bb, strict=True):
                s_ = getattr(bs, field)
                if field == "count":
                    np.testing.assert_array_equal(a[i], s_)
                elif field == "residuals":
                    _close(a[i], s_, 1e-12, scale=600.0)
                elif field in ("mean", "cov"):
                    _close(a[i], s_, 1e-12)
                else:
                    # r_scale, q_scale, R, Q are built from innovations z - h(x), which
                    # carry rounding of eps |z| (|z| ~ 500 Hz for r ~ 0.3 Hz) and compound
                    # over the steps; equal to rounding at that scale
                    _close(a[i], s_, 1e-10)
            _close(ib.nu[i], is_.nu, 1e-12, scale=600.0)
            _close(ib.cov[i], is_.cov, 1e-12)


@pytest.mark.parametrize("name", list(FILTERS))
def test_batch_shape_2x3(name):
    f = FILTERS[name]()
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=6, T=12)
    P0b = np.broadcast_to(P0, (6, 5, 5)).copy()
    flat = _run(f, motion, sensors, zs, m0, P0b)
    grid = _run(f, motion, sensors, zs.reshape(12, 2, 3, 2), m0.reshape(2, 3, 5),
                P0b.reshape(2, 3, 5, 5))
    bf, bg = flat[-1][0], grid[-1][0]
    assert bg.mean.shape == (2, 3, 5) and bg.cov.shape == (2, 3, 5, 5)
    for a, g in zip(bf, bg, strict=True):
        assert g.shape[:2] == (2, 3)
        _close(g.reshape(a.shape), a, 1e-12)
    assert grid[-1][1].nu.shape == (2, 3, 2)


@pytest.mark.parametrize("name", ["AMCEKF", "AMCEKF-ms", "AEKF", "AEKF-q", "MCEKF2"])
def test_missing_rows_return_prediction_and_keep_memory(name):
    f = FILTERS[name]()
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=5, T=12)
    b = _init(f, m0, np.broadcast_to(P0, (5, 5, 5)).copy())
    for k in range(11):
        b, _ = f.update(f.predict(b, motion, 1.0), zs[k], sensors[k])
    pred = f.predict(b, motion, 1.0)
    z = zs[11].copy()
    z[1] = np.nan
    z[3, 0] = np.nan
    post, innov = f.update(pred, z, sensors[11])
    for i in range(5):
        if i in (1, 3):
            for a, p in zip(post, pred, strict=True):
                np.testing.assert_array_equal(a[i], p[i])
            assert np.all(np.isnan(innov.nu[i]))
        else:
            assert not np.array_equal(post.mean[i], pred.mean[i])
            if isinstance(post, AdaptiveBelief | SageHusaBelief):
                assert post.count[i] == pred.count[i] + 1


@pytest.mark.parametrize("name", list(FILTERS))
def test_other_models_and_unbatched(name):
    """Any motion model and sensor: coordinated turn with range-bearing, unbatched state."""
    f = FILTERS[name]()
    motion = CoordinatedTurn(q=0.1, q_omega=1e-4)
    sensor = RangeBearing(origin=(0.0, 0.0), sigma_range=5.0, sigma_bearing=0.01)
    rng = np.random.default_rng(4)
    x = np.array([1000.0, -500.0, 5.0, 8.0, 0.01])
    P = np.diag([400.0, 400.0, 4.0, 4.0, 1e-4])
    b = _init(f, x, P)
    for _ in range(30):
        x = motion.f(x, 1.0)
        z = sensor.h(x) + rng.standard_normal(2) * [5.0, 0.01]
        b, innov = f.update(f.predict(b, motion, 1.0), z, sensor)
    assert b.mean.shape == (5,) and innov.nu.shape == (2,)
    assert np.all(np.isfinite(b.mean)) and np.linalg.norm(b.mean[:2] - x[:2]) < 100.0
    np.testing.assert_array_equal(b.cov, b.cov.T)


def test_init_run_filter_and_plain_gaussian():
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=3, T=20)
    f = AMCEKF()
    prior = tk.Gaussian(m0, P0)
    b, hist = run_filter(f, f.init(prior), motion, sensors, zs, 1.0, history=True)
    assert isinstance(b, AdaptiveBelief) and hist.mean.shape == (20, 3, 5)
    np.testing.assert_array_equal(b.count, 20)
    # a plain Gaussian given to predict is initialised on the spot: same result
    b2, _ = run_filter(f, prior, motion, sensors, zs, 1.0)
    _close(b2.mean, b.mean)
    assert isinstance(AEKF().init(prior), SageHusaBelief)
    g = f.estimate(b)
    assert type(g) is tk.Gaussian and g.mean is b.mean


def test_bad_options_and_mismatched_memory():
    for kw in ({"window": 0}, {"q_form": "cubic"}, {"warmup": "never"},
               {"r_bounds": (2.0, 1.0)}, {"q_bounds": (0.0, 1.0)}):
        with pytest.raises(ValueError):
            AMCEKF(**kw)
    with pytest.raises(ValueError, match="forgetting"):
        AEKF(forgetting=1.0)
    motion, sensors, _, zs, m0, P0 = dbt_problem(B=2, T=2)
    f = AMCEKF()
    b, _ = f.update(f.predict(f.init(tk.Gaussian(m0, P0)), motion, 1.0), zs[0], sensors[0])
    with pytest.raises(ValueError, match="window"):
        f.update(b, np.zeros((2, 1)), tk.models.Bearing(origin=(0.0, 0.0), sigma=0.01))


# --------------------------------------------------------------------------------------------
# DBT Monte Carlo sanity run
# --------------------------------------------------------------------------------------------


def test_dbt_monte_carlo_sanity():
    runs, T = 50, 300
    motion, sensors, truth, zs, m0, P0 = dbt_problem(B=runs, T=T, seed=2002)
    filters = {"EKF": EKF(), "UKF": UKF(), "MCEKF": MCEKF(),
               "MCEKF(2nd)": MCEKF(second_order=True), "AMCEKF": AMCEKF(), "AEKF": AEKF()}
    report = []
    for name, f in filters.items():
        b = tk.Gaussian(m0, np.broadcast_to(P0, (runs, 5, 5)).copy())
        if hasattr(f, "init"):
            b = f.init(b)
        se = np.zeros(T)
        for k, s in enumerate(sensors):
            b = f.predict(b, motion, 1.0)
            b, innov = f.update(b, zs[k], s)
            se[k] = ((b.mean[:, :2] - truth[k, :2]) ** 2).sum(-1).mean()
        g = f.estimate(b)
        assert np.all(np.isfinite(g.mean)) and np.all(np.isfinite(g.cov)), name
        assert np.all(np.isfinite(innov.nu)) and np.all(np.isfinite(innov.cov)), name
        np.testing.assert_array_equal(g.cov, np.swapaxes(g.cov, -1, -2))
        assert np.all(np.linalg.eigvalsh(g.cov)[..., 0] > 0), name
        if isinstance(b, AdaptiveBelief):
            assert np.all((b.r_scale >= 1e-3) & (b.r_scale <= 1e3))
            assert np.all((b.q_scale >= 1e-2) & (b.q_scale <= 1e2))
        report.append(f"{name:11s} position RMSE all {np.sqrt(se.mean()):7.1f} m, "
                      f"last 100 s {np.sqrt(se[-100:].mean()):7.1f} m")
    print("\nDBT scenario 1 geometry, 50 runs x 300 s:\n" + "\n".join(report))
