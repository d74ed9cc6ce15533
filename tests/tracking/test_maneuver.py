"""Manoeuvre detectors and the responses to a detection (the missing-measurements
thesis, sections 3-3-4-1 and 3-3-4-2).

Thresholds against chi-square quantiles, closed forms and a large simulation of the
fading-memory statistic; the detectors' false-alarm rates and detection delays on simulated
radar tracks; the on/off rule; Q and P inflation; the variable-order filter against a
hand-run CV/CA Kalman filter and against the CV Kalman filter alone.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy import integrate, stats

import trackkit as tk
from trackkit.belief import Gaussian, Innovation
from trackkit.filters.maneuver import (
    DetectorState,
    FadingMemoryDetector,
    NISDetector,
    PInflation,
    QInflation,
    ScaledNoise,
    WindowDetector,
    WindowState,
    chi2_threshold,
    fading_memory,
    fading_threshold,
    inflate_p,
    inflate_q,
    run_variable_order,
    run_with_detector,
    weighted_chi2_sf,
)
from trackkit.filters.run import run_filter

G = 9.80665

# ------------------------------------------------------------------------------------------
# A radar-like scenario: 2-D CV target, position plots every second with 100 m noise.
# Truth is drawn from the filter's own prior and process noise, so the KF is correctly
# specified and its innovations are independent N(0, S(k)) from the first step.

DT, Q_CV, SIGMA = 1.0, 1.0, 100.0
M0 = np.array([0.0, 0.0, 250.0, 0.0])
P0_DIAG = np.array([200.0**2, 200.0**2, 30.0**2, 30.0**2])


def simulate(runs: int, K: int, seed: int, accel=None, leg=(0, 0)):
    """Truth (K, runs, 4) and plots (K, runs, 2); a constant acceleration ``accel`` (m/s^2,
    x and y) is added over the steps ``leg[0] <= k < leg[1]``."""
    rng = np.random.default_rng(seed)
    cv = tk.models.ConstantVelocity(dim=2, q=Q_CV)
    F, L = cv.jacobian(None, DT), np.linalg.cholesky(cv.noise(None, DT))
    x = M0 + rng.standard_normal((runs, 4)) * np.sqrt(P0_DIAG)
    X, Z = np.empty((K, runs, 4)), np.empty((K, runs, 2))
    for k in range(K):
        x = x @ F.T + rng.standard_normal((runs, 4)) @ L.T
        if accel is not None and leg[0] <= k < leg[1]:
            x[:, :2] += 0.5 * np.asarray(accel) * DT**2
            x[:, 2:] += np.asarray(accel) * DT
        X[k] = x
        Z[k] = x[:, :2] + SIGMA * rng.standard_normal((runs, 2))
    return X, Z


def prior_for(runs: int) -> Gaussian:
    return Gaussian(np.tile(M0, (runs, 1)), np.tile(np.diag(P0_DIAG), (runs, 1, 1)))


CV = tk.models.ConstantVelocity(dim=2, q=Q_CV)
RADAR = tk.models.Position(dim=2, sigma=SIGMA)


def detectors(pfa: float = 0.01):
    return [NISDetector(pfa=pfa), FadingMemoryDetector(alpha=0.8, pfa=pfa),
            WindowDetector(L=5, pfa=pfa)]


# ------------------------------------------------------------------------------------------
# Thresholds


@pytest.mark.parametrize("pfa", [0.05, 1e-2, 1e-3, 1e-6])
@pytest.mark.parametrize("m", [1, 2, 3])
def test_nis_and_window_thresholds_are_chi_square_quantiles(pfa, m):
    """Both statistics are chi-square(m) under H0: the threshold is its 1 - pfa quantile
    (checked against ``ppf(1 - pfa)`` and that the tail beyond it is pfa)."""
    for det in (NISDetector(pfa=pfa, dim_z=m), WindowDetector(L=4, pfa=pfa, dim_z=m)):
        assert det.threshold == pytest.approx(stats.chi2.ppf(1 - pfa, m), rel=1e-9)
        assert stats.chi2.sf(det.threshold, m) == pytest.approx(pfa, rel=1e-9)
        off = max(pfa, 0.1)  # the documented default off level
        assert det.threshold_off == pytest.approx(stats.chi2.ppf(1 - off, m), rel=1e-9)
    assert chi2_threshold(pfa, m) == NISDetector(pfa=pfa, dim_z=m).threshold


def hypoexponential_sf(x, lam):
    """P(sum lam_j chi2_2 > x): chi2_2 / 2 is Exp(1), so the sum is hypoexponential with
    rates 1 / (2 lam_j) (distinct): sf = sum_i prod_{j != i} r_j / (r_j - r_i) exp(-r_i x)."""
    r = 1.0 / (2.0 * np.asarray(lam))
    out = 0.0
    for i in range(r.size):
        c = np.prod([r[j] / (r[j] - r[i]) for j in range(r.size) if j != i])
        out = out + c * np.exp(-r[i] * x)
    return out


@pytest.mark.parametrize("alpha", [0.5, 0.8])
@pytest.mark.parametrize("n", [2, 3, 5])
def test_weighted_chi2_sf_equals_hypoexponential_closed_form(alpha, n):
    """Two degrees of freedom: the n-term fading sum has a closed-form tail. Imhof's formula
    is 1/2 plus an integral near -1/2, so its accuracy is absolute, 5e-14 (rounding), which
    is 5e-9 relative at a tail of 1e-5; thresholds at pfa >= 1e-4 are good to 1e-9."""
    lam = alpha ** np.arange(n)
    x = np.linspace(1.0, 30.0, 12)
    ref = hypoexponential_sf(x, lam)
    got = weighted_chi2_sf(x, lam, 2)
    np.testing.assert_allclose(got, ref, rtol=0, atol=5e-14)
    big = ref > 1e-5
    np.testing.assert_allclose(got[big], ref[big], rtol=5e-9)
    # and its thresholds: the closed form's tail at fading_threshold(pfa, n) is pfa
    for pfa in (1e-2, 1e-4):
        t = fading_threshold(pfa, 2, alpha, n=n)
        assert hypoexponential_sf(t, lam) == pytest.approx(pfa, rel=1e-9)


def test_weighted_chi2_sf_one_dof_against_a_convolution():
    """One degree of freedom, two terms (the slowest-converging inversion):
    P(Z0^2 + a Z1^2 > x) = P(chi2_1 > x) + int_0^x f_1(t) P(chi2_1 > (x - t) / a) dt,
    integrated by quadpack with the t^(-1/2) weight; agreement 1e-9 relative."""
    a = 0.8
    for x in (0.7, 3.0, 9.0, 20.0):
        body, _ = integrate.quad(
            lambda t, x=x: np.exp(-t / 2) / math.sqrt(2 * math.pi) * stats.chi2.sf((x - t) / a, 1),
            0.0, x, weight="alg", wvar=(-0.5, 0.0), epsabs=1e-15, epsrel=1e-13, limit=200)
        ref = stats.chi2.sf(x, 1) + body
        assert weighted_chi2_sf(x, [1.0, a], 1) == pytest.approx(ref, rel=1e-9)


def test_fading_threshold_false_alarm_probability_by_simulation():
    """rho_n = sum_{j<n} alpha^j eps_j simulated directly, 10^6 independent chains of 70
    steps (alpha = 0.8, m = 2; alpha^70 = 2e-7, so step 70 is the steady state): the
    fraction above the Imhof threshold is pfa within 4 binomial standard errors (1e-4 at
    pfa = 1e-2, 3.2e-5 at 1e-3; a false failure once in 16 000 runs of this test), at the
    steady state and at each start-up age 1..5 with that age's threshold.

    The Satterthwaite threshold's exceedance agrees, within the same error, with its exact
    probability from ``weighted_chi2_sf`` (1.25% for a design of 1%): the moment-matched
    scaled chi-square is 25% optimistic in this tail, which is why Imhof is the default.
    """
    rng = np.random.default_rng(20260)
    alpha, m, N, n_steps = 0.8, 2, 1_000_000, 70
    rho = np.zeros(N)
    at_age = {}
    for n in range(1, n_steps + 1):
        rho = alpha * rho + rng.chisquare(m, N)
        if n <= 5 or n == n_steps:
            at_age[n] = rho.copy()
    lam = alpha ** np.arange(200)
    for pfa in (1e-2, 1e-3):
        se = math.sqrt(pfa * (1 - pfa) / N)
        det = FadingMemoryDetector(alpha=alpha, pfa=pfa, dim_z=m)
        on, _ = det.thresholds(np.array([1, 2, 3, 4, 5, 10_000]))
        assert np.all(np.diff(on) > 0)  # the n-term quantiles rise towards the steady one
        assert on[0] == pytest.approx(stats.chi2.isf(pfa, m), rel=1e-12)
        for n, t in zip((1, 2, 3, 4, 5, n_steps), on, strict=True):
            assert abs(np.mean(at_age[n] > t) - pfa) < 4 * se, (pfa, n)
        t_s = fading_threshold(pfa, m, alpha, method="satterthwaite")
        exact = float(weighted_chi2_sf(t_s, lam, m))
        assert abs(np.mean(at_age[n_steps] > t_s) - exact) < 4 * math.sqrt(exact / N)
        if pfa == 1e-2:
            assert 1.2 * pfa < exact < 1.3 * pfa


def test_fading_memory_and_detector_memory():
    """s = 0 for NIS, L - 1 for the window, round(alpha / (1 - alpha)) for the fading memory
    (the window of equal mean, L = 1 / (1 - alpha))."""
    assert NISDetector().memory == 0
    assert WindowDetector(L=7).memory == 6
    assert WindowDetector(L=1).memory == 0
    assert [fading_memory(a) for a in (0.5, 0.8, 0.9, 0.95)] == [1, 4, 9, 19]
    assert FadingMemoryDetector(alpha=0.8, startup=False).memory == 4
    # steady mean of rho is m / (1 - alpha), the mean of a window of 1 / (1 - alpha) NIS
    lam = 0.8 ** np.arange(400)
    assert 2 * lam.sum() == pytest.approx(2 / (1 - 0.8), rel=1e-12)


# ------------------------------------------------------------------------------------------
# The state machine


def test_state_interface_for_any_batch_shape():
    """init(batch_shape) gives arrays of that shape (on: bool); step takes an Innovation of
    that batch; every field keeps the batch as its leading axes."""
    rng = np.random.default_rng(1)
    for det in detectors():
        s = det.init((2, 3))
        assert isinstance(s, DetectorState | WindowState)
        assert s.on.shape == (2, 3) and s.on.dtype == bool and not s.on.any()
        innov = Innovation(rng.standard_normal((2, 3, 2)), np.broadcast_to(np.eye(2), (2, 3, 2, 2)))
        s = det.step(s, innov)
        for f in s:
            assert f.shape[:2] == (2, 3)
        assert np.all(s.k == 1) and np.all(s.age == 1)
    s = NISDetector().init(4)
    assert s.on.shape == (4,)
    with pytest.raises(ValueError, match=r"residual has shape \(4, 3\).*expected \(4, 2\)"):
        NISDetector().step(s, Innovation(np.zeros((4, 3)), np.eye(3)))


def test_missing_measurement_rows_hold_statistic_and_decision():
    """A nan residual row (no measurement) keeps its statistic, decision, counters and
    window (``fired`` is the event of this step: false); the other rows move on."""
    big = Innovation(np.array([[30.0, 0.0], [30.0, 0.0]]), np.eye(2))
    for det in detectors():
        s = det.step(det.init(2), big)
        assert s.on.all()
        r = np.array([[0.1, 0.2], [np.nan, np.nan]])
        s2 = det.step(s, Innovation(r, np.eye(2)))
        assert s.fired.all() and not s2.fired[1]
        for name in s._fields:
            if name in ("k", "fired"):
                continue
            np.testing.assert_array_equal(getattr(s2, name)[1], getattr(s, name)[1],
                                          err_msg=f"{type(det).__name__}.{name}")
        assert s2.age[0] == 2 and s2.statistic[0] != s.statistic[0]
        assert np.all(s2.k == 2)


def test_on_off_hysteresis_rule():
    """NIS with m = 1 and S = 1 (statistic = r^2): on above the on threshold, off after
    n_off = 3 consecutive steps below the off threshold; a step between the thresholds, or
    above, restarts the count; ``fired`` and ``onset`` mark the step it turned on."""
    det = NISDetector(pfa=1e-3, dim_z=1, pfa_off=0.2, n_off=3)
    hi, mid, lo = (math.sqrt(det.threshold) * 1.01, math.sqrt(det.threshold_off) * 1.5,
                   math.sqrt(det.threshold_off) * 0.5)
    seq = [lo, hi, lo, mid, lo, lo, hi, lo, lo, lo, lo, hi]
    on = [0, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 1]
    fired = [0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1]
    s = det.init(())
    for k, (r, want_on, want_fired) in enumerate(zip(seq, on, fired, strict=True)):
        s = det.step(s, Innovation(np.array([r]), np.eye(1)))
        assert bool(s.on) == bool(want_on), k
        assert bool(s.fired) == bool(want_fired), k
    assert int(s.onset) == 11
    s = det.reset(s, True)
    assert not s.on and s.statistic == 0 and s.age == 0 and s.onset == 11


@pytest.mark.parametrize("make, value", [
    (lambda v: NISDetector(pfa=v), 0.0), (lambda v: NISDetector(pfa=v), 1.0),
    (lambda v: NISDetector(pfa=v), -0.1), (lambda v: NISDetector(pfa=v), 1.5),
    (lambda v: NISDetector(pfa=v), float("nan")),
    (lambda v: WindowDetector(pfa=v), 2.0), (lambda v: FadingMemoryDetector(pfa=v), 0.0),
    (lambda v: FadingMemoryDetector(alpha=v), 0.0), (lambda v: FadingMemoryDetector(alpha=v), 1.0),
    (lambda v: FadingMemoryDetector(alpha=v), 1.2), (lambda v: FadingMemoryDetector(alpha=v), -0.5),
    (lambda v: WindowDetector(L=v), 0), (lambda v: WindowDetector(L=v), -3),
    (lambda v: WindowDetector(L=v), 2.5), (lambda v: NISDetector(dim_z=v), 0),
    (lambda v: NISDetector(pfa=0.01, pfa_off=v), 0.001),
    (lambda v: NISDetector(pfa=0.01, pfa_off=v), 0.7),
    (lambda v: NISDetector(n_off=v), 0),
    (lambda v: QInflation(v), 0.5), (lambda v: PInflation(v), float("inf")),
    (lambda v: fading_threshold(0.01, 2, v), 1.0),
    (lambda v: fading_threshold(0.01, 2, 0.8, method=v), "exact"),
])
def test_bad_parameters_raise_naming_the_value(make, value):
    """Each bad parameter raises ValueError naming the parameter's value."""
    with pytest.raises(ValueError, match=r" = " + re.escape(repr(value))):
        make(value)


# ------------------------------------------------------------------------------------------
# Statistics on simulated tracks


def test_false_alarm_rate_on_a_cv_target_matches_the_design():
    """CV target, correctly specified KF, 1000 runs x 150 steps, pfa = 1%: the fraction of
    steps whose statistic exceeds the threshold that applies (the fading memory's start-up
    thresholds included) is within 4 standard errors of pfa, for each detector.

    Successive decisions of the fading and window statistics are correlated, so the standard
    error is that of the mean of the 1000 per-run rates (runs are independent: batch means),
    estimated from their spread: 2.6e-4 (NIS, as for independent decisions), 4.2e-4 (fading),
    3.7e-4 (window). Measured rates: 1.007%, 1.036%, 0.988%. 4 standard errors: 99.99%
    two-sided, so the three together fail by chance once in 5000 (the seed is fixed).
    """
    runs, K, pfa = 1000, 150, 0.01
    _, Z = simulate(runs, K, seed=11)
    for det in detectors(pfa):
        res = run_with_detector(tk.filters.KF(), prior_for(runs), CV, RADAR, Z, DT, det)
        t_on, _ = det.thresholds(np.arange(1, K + 1))
        exceed = res.statistic > np.broadcast_to(t_on, (runs, K)).T
        per_run = exceed.mean(0)
        se = per_run.std(ddof=1) / math.sqrt(runs)
        assert se < 0.05 * pfa  # the test can see a 20% error
        assert abs(per_run.mean() - pfa) < 4 * se, (type(det).__name__, per_run.mean(), se)


def test_each_detector_fires_soon_after_a_3g_acceleration():
    """At step 50 the target starts a constant 3 g acceleration across its track (29.4 m/s^2;
    a T^2 / 2 = 14.7 m, 0.15 of the 100 m plot noise, in the first second). Each detector's
    statistic exceeds its threshold within 7 steps of the onset (steps 50..56) in at least
    95% of 400 runs. Measured: 100% for all three, median at step 54 (the 5th manoeuvring
    plot); with 400 of 400 runs the one-sided 99.9% Clopper-Pearson lower bound on the true
    rate is 98.3%."""
    runs, K, k0 = 400, 60, 50
    _, Z = simulate(runs, K, seed=12, accel=(0.0, 3 * G), leg=(k0, K))
    for det in detectors(0.01):
        res = run_with_detector(tk.filters.KF(), prior_for(runs), CV, RADAR, Z, DT, det)
        exceed = res.statistic[k0:k0 + 7] > det.threshold
        assert exceed.any(0).mean() >= 0.95, type(det).__name__


# ------------------------------------------------------------------------------------------
# Q and P inflation


def random_beliefs(rng, rows: int, n: int = 4) -> Gaussian:
    A = rng.standard_normal((rows, n, n))
    P = A @ A.transpose(0, 2, 1) + n * np.eye(n)
    return Gaussian(rng.standard_normal((rows, n)) * 10, P)


def test_q_inflation_scales_q_only_in_rows_that_are_on():
    """Rows that are off predict bitwise as without the response; rows that are on get
    ``P- = F P F^T + c Q`` (textbook, 1e-12 relative); the mean is untouched everywhere."""
    rng = np.random.default_rng(3)
    b = random_beliefs(rng, 7)
    on = np.array([0, 1, 0, 0, 1, 1, 0], bool)
    c, dt = 25.0, 2.0
    kf = tk.filters.KF()
    plain = kf.predict(b, CV, dt)
    infl = kf.predict(b, inflate_q(CV, c, on), dt)
    np.testing.assert_array_equal(infl.cov[~on], plain.cov[~on])
    np.testing.assert_array_equal(infl.mean, plain.mean)
    F, Q = CV.jacobian(None, dt), CV.noise(None, dt)
    want = F @ b.cov[on] @ F.T + c * Q
    np.testing.assert_allclose(infl.cov[on], want, rtol=1e-12)
    assert inflate_q(CV, c, np.zeros(7, bool)) is CV
    m = ScaledNoise(CV, np.where(on, c, 1.0))
    assert m.dim_x == 4 and m.linear
    np.testing.assert_array_equal(m.noise(None, dt)[~on], np.broadcast_to(Q, (4, 4, 4)))


def test_p_inflation_scales_p_only_in_rows_that_fired():
    """Rows not selected keep their covariance bitwise; selected rows get factor * P (one
    rounding, so bitwise equal to ``factor * P``); means are untouched."""
    rng = np.random.default_rng(4)
    b = random_beliefs(rng, 6)
    w = np.array([1, 0, 0, 1, 0, 0], bool)
    out = inflate_p(b, 7.0, w)
    np.testing.assert_array_equal(out.cov[~w], b.cov[~w])
    np.testing.assert_array_equal(out.cov[w], 7.0 * b.cov[w])
    np.testing.assert_array_equal(out.mean, b.mean)
    assert isinstance(out, Gaussian)
    assert inflate_p(b, 7.0, np.zeros(6, bool)) is b


def test_run_with_detector_responses_touch_only_their_rows():
    """40 steps of the CV scenario with NIS at pfa = 1%: about a third of the runs raise a
    false alarm. Monitoring alone is bitwise ``run_filter``; with either response the runs
    whose detector was never on are bitwise ``run_filter``; with P inflation a run's
    covariance at the step its detector first fires is factor x that of the plain run
    (bitwise: the same history up to that step, then one multiplication)."""
    runs, K = 300, 40
    _, Z = simulate(runs, K, seed=13)
    kf = tk.filters.KF()
    _, hist = run_filter(kf, prior_for(runs), CV, RADAR, Z, DT, history=True)
    det = NISDetector(pfa=0.01)
    mon = run_with_detector(kf, prior_for(runs), CV, RADAR, Z, DT, det)
    np.testing.assert_array_equal(mon.estimate.mean, hist.mean)
    np.testing.assert_array_equal(mon.estimate.cov, hist.cov)
    quiet = ~mon.on.any(0)
    assert 0.2 * runs < (~quiet).sum() < 0.5 * runs
    for resp in (QInflation(10.0), PInflation(10.0)):
        res = run_with_detector(kf, prior_for(runs), CV, RADAR, Z, DT, det, resp)
        q = ~res.on.any(0)
        np.testing.assert_array_equal(res.estimate.mean[:, q], hist.mean[:, q])
        np.testing.assert_array_equal(res.estimate.cov[:, q], hist.cov[:, q])
        if isinstance(resp, PInflation):
            first = np.argmax(res.fired, 0)
            rows = np.flatnonzero(res.fired.any(0))
            np.testing.assert_array_equal(res.estimate.cov[first[rows], rows],
                                          10.0 * hist.cov[first[rows], rows])
            np.testing.assert_array_equal(res.estimate.mean[first[rows], rows],
                                          hist.mean[first[rows], rows])


# ------------------------------------------------------------------------------------------
# The variable-order filter


def test_variable_order_without_detections_is_the_cv_kalman_filter():
    """No detection (pfa = 1e-12, 200 runs x 60 steps): the estimates are bitwise the CV
    Kalman filter's, with zero acceleration and zero acceleration covariance (also with dt
    given per step). With pfa = 1% about half the runs switch on false alarms; the others
    are still bitwise the CV Kalman filter."""
    runs, K = 200, 60
    _, Z = simulate(runs, K, seed=14)
    _, hist = run_filter(tk.filters.KF(), prior_for(runs), CV, RADAR, Z, DT, history=True)
    r = run_variable_order(prior_for(runs), RADAR, Z, DT, NISDetector(pfa=1e-12), q_cv=Q_CV,
                           q_ca=10.0)
    assert not r.mode.any() and not r.switched_on.any()
    assert r.estimate.mean.shape == (K, runs, 6) and r.estimate.cov.shape == (K, runs, 6, 6)
    np.testing.assert_array_equal(r.estimate.mean[..., :4], hist.mean)
    np.testing.assert_array_equal(r.estimate.cov[..., :4, :4], hist.cov)
    assert not r.estimate.mean[..., 4:].any() and not r.estimate.cov[..., 4:, :].any()
    r_list = run_variable_order(prior_for(runs), RADAR, Z, [DT] * K, NISDetector(pfa=1e-12),
                                q_cv=Q_CV, q_ca=10.0)
    np.testing.assert_array_equal(r_list.estimate.mean, r.estimate.mean)

    r = run_variable_order(prior_for(runs), RADAR, Z, DT, NISDetector(pfa=0.01), q_cv=Q_CV,
                           q_ca=10.0)
    never = ~r.mode.any(0) & ~r.switched_on.any(0)
    assert 0.3 * runs < never.sum() < 0.7 * runs
    np.testing.assert_array_equal(r.estimate.mean[:, never, :4], hist.mean[:, never])
    np.testing.assert_array_equal(r.estimate.cov[:, never, :4, :4], hist.cov[:, never])


def cv_ca_matrices(dt, q, order):
    """Textbook F and Q per axis, interleaved for x and y in [p, v, (a)] order."""
    if order == 2:
        F1 = np.array([[1, dt], [0, 1]])
        Q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    else:
        F1 = np.array([[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
        Q1 = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                           [dt**3 / 6, dt**2 / 2, dt]])
    return np.kron(F1, np.eye(2)), np.kron(Q1, np.eye(2))


def hand_kf(x, P, zs, F, Q, R):
    """Predict-update over zs, Joseph form; the filtered (x, P) after each step."""
    n = x.size
    H = np.eye(2, n)
    out = []
    for z in zs:
        x, P = F @ x, F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (z - H @ x)
        A = np.eye(n) - K @ H
        P = A @ P @ A.T + K @ R @ K.T
        out.append((x, P))
    return out


def test_variable_order_reinitialises_at_k_minus_s_from_the_stored_measurements():
    """A small deterministic case: two tracks, dt = 0.5 s, R = I; track 1 accelerates at
    8 m/s^2 in x from t = 4 s to t = 8 s. With the window detector (L = 3, s = 2) track 1
    switches to CA at step k = 10 and back at step 21; track 0 never switches.

    Against a hand-run Kalman filter (1e-12 relative): before k the CV filter; at k the CA
    filter started from the CV estimate at k - s - 1 = 7 with acceleration N(0, 5^2 I) and
    run over z(8), z(9), z(10), exactly those stored plots; then the CA filter on until the
    switch down, where the estimate is the CA position and velocity. The switch down is the
    first step at which the last three acceleration tests a^T P_aa^-1 a (re-filtered steps
    included) sum below chi2(6) at 0.95.
    """
    dt, K, accel_std = 0.5, 24, 5.0
    t = dt * np.arange(1, K + 1)
    z = np.empty((K, 2, 2))
    z[:, 0] = np.stack([10 + 2 * t, 5 - t], -1)
    px = (10 + 2 * t + 0.5 * 8.0 * np.clip(t - 4, 0, None) ** 2
          - 0.5 * 8.0 * np.clip(t - 8, 0, None) ** 2)
    z[:, 1] = np.stack([px, 5 - t], -1)
    z += 0.3 * np.sin(np.arange(K * 4).reshape(K, 2, 2))  # deterministic "noise"
    prior = Gaussian(np.array([[10.0, 5, 2, -1], [10.0, 5, 2, -1]]), np.tile(np.eye(4), (2, 1, 1)))
    sensor = tk.models.Position(dim=2, sigma=1.0)
    det = WindowDetector(L=3, pfa=1e-3)
    s = det.memory
    r = run_variable_order(prior, sensor, z, dt, det, q_cv=0.1, q_ca=1.0, accel_std=accel_std)
    assert not r.mode[:, 0].any()
    k_up = int(np.flatnonzero(r.switched_on[:, 1])[0])
    k_down = int(np.flatnonzero(r.switched_off[:, 1])[0])
    assert (k_up, k_down, s) == (10, 21, 2)
    assert r.mode[k_up:k_down, 1].all() and not r.mode[:k_up, 1].any()

    Fv, Qv = cv_ca_matrices(dt, 0.1, 2)
    Fa, Qa = cv_ca_matrices(dt, 1.0, 3)
    R = np.eye(2)
    cv_steps = hand_kf(prior.mean[1], prior.cov[1], z[:k_up, 1], Fv, Qv, R)
    for k, (x, P) in enumerate(cv_steps):
        np.testing.assert_allclose(r.estimate.mean[k, 1, :4], x, rtol=1e-12, atol=1e-11)
        np.testing.assert_allclose(r.estimate.cov[k, 1, :4, :4], P, rtol=1e-12, atol=1e-13)
    x7, P7 = cv_steps[k_up - s - 1]
    xa = np.concatenate([x7, np.zeros(2)])
    Pa = np.zeros((6, 6))
    Pa[:4, :4], Pa[4:, 4:] = P7, accel_std**2 * np.eye(2)
    ca_steps = hand_kf(xa, Pa, z[k_up - s:k_down + 1, 1], Fa, Qa, R)
    for j, (x, P) in enumerate(ca_steps[s:-1]):
        k = k_up + j
        np.testing.assert_allclose(r.estimate.mean[k, 1], x, rtol=1e-12, atol=1e-11)
        np.testing.assert_allclose(r.estimate.cov[k, 1], P, rtol=1e-12, atol=1e-13)
    x, P = ca_steps[-1]
    np.testing.assert_allclose(r.estimate.mean[k_down, 1, :4], x[:4], rtol=1e-12, atol=1e-11)
    np.testing.assert_allclose(r.estimate.cov[k_down, 1, :4, :4], P[:4, :4], rtol=1e-12, atol=1e-13)
    # the end rule, from the hand-run acceleration tests
    delta = [x[4:] @ np.linalg.solve(P[4:, 4:], x[4:]) for x, P in ca_steps]
    sums = np.convolve(delta, np.ones(3), "valid")  # windows ending at steps k_up-s+2 ..
    thr = stats.chi2.isf(0.05, 6)
    ends = k_up - s + 2 + np.arange(sums.size)
    assert ends[np.flatnonzero((sums < thr) & (ends >= k_up))[0]] == k_down


def test_variable_order_beats_the_cv_filter_on_a_constant_acceleration_leg():
    """200 runs: CV until step 40, a 3 g acceleration across the track over steps 40..69,
    then CV again. Over the acceleration leg the variable-order filter's position RMSE is
    below the CV Kalman filter's in at least 95% of runs and below half of it overall
    (measured: 104 m against 1655 m with the fading-memory detector)."""
    runs, K, leg = 200, 90, (40, 70)
    X, Z = simulate(runs, K, seed=15, accel=(0.0, 3 * G), leg=leg)
    _, hist = run_filter(tk.filters.KF(), prior_for(runs), CV, RADAR, Z, DT, history=True)
    err_cv = np.linalg.norm(hist.mean[..., :2] - X[..., :2], axis=-1)[leg[0]:leg[1]]
    r = run_variable_order(prior_for(runs), RADAR, Z, DT, FadingMemoryDetector(alpha=0.8),
                           q_cv=Q_CV, q_ca=10.0)
    err = np.linalg.norm(r.estimate.mean[..., :2] - X[..., :2], axis=-1)[leg[0]:leg[1]]
    per_run = np.sqrt((err**2).mean(0)) < np.sqrt((err_cv**2).mean(0))
    assert per_run.mean() >= 0.95
    assert np.sqrt((err**2).mean()) < 0.5 * np.sqrt((err_cv**2).mean())
    assert r.mode[leg[0] + 10:leg[1]].mean() > 0.8  # CA in use over most of the leg


def test_variable_order_bad_inputs_name_the_quantity():
    """Shapes and parameters of the variable-order runner are checked before it runs."""
    Z = np.zeros((5, 3, 2))
    det = NISDetector()
    ok = dict(q_cv=1.0, q_ca=1.0)
    with pytest.raises(ValueError, match=r"z has shape \(5,\)"):
        run_variable_order(prior_for(3), RADAR, np.zeros(5), DT, det, **ok)
    with pytest.raises(ValueError, match=r"prior has 3 state components"):
        run_variable_order(Gaussian(np.zeros((3, 3)), np.eye(3)), RADAR, Z, DT, det, **ok)
    with pytest.raises(ValueError, match=r"prior mean has batch shape \(4,\)"):
        run_variable_order(prior_for(4), RADAR, Z, DT, det, **ok)
    with pytest.raises(ValueError, match=r"end_window = 0"):
        run_variable_order(prior_for(3), RADAR, Z, DT, det, end_window=0, **ok)
    with pytest.raises(ValueError, match=r"end_pfa = 1.0"):
        run_variable_order(prior_for(3), RADAR, Z, DT, det, end_pfa=1.0, **ok)
    with pytest.raises(ValueError, match=r"accel_std = -2.0"):
        run_variable_order(prior_for(3), RADAR, Z, DT, det, accel_std=-2.0, **ok)
    with pytest.raises(ValueError, match=r"s = -1"):
        run_variable_order(prior_for(3), RADAR, Z, DT, det, s=-1, **ok)
    with pytest.raises(ValueError, match=r"dt has 2 steps but there are 5 measurements"):
        run_variable_order(prior_for(3), RADAR, Z, [1.0, 1.0], det, **ok)
    with pytest.raises(TypeError, match=r"expected \(prior, sensor, z, dt, detector"):
        run_variable_order(Z, DT, prior_for(3), RADAR, det, **ok)  # the order before run_filter's
