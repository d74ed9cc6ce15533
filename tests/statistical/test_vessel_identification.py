"""Zolfagharnasab and Seif (2025): identification of the 16-coefficient manoeuvring model of the
19.6 m waterjet SAR boat by a Kalman filter on the augmented state, Monte Carlo claims.

Data: ``trackkit.identify.programme`` (acceleration 1000 -> 2000 rpm, 20/20 zig-zag at
2000 rpm, 20/20 zig-zag at 1500 rpm, port turn, deceleration 2000 -> 1200 rpm, 10/10
zig-zag, starboard turn; 657 samples at T = 1 s) of the reference vessel, 100 runs, seed
2025, measurement noise 0.05 m/s on u and v, 0.1 deg/s on r, GPS 2.5 m per axis, heading
0.2 deg. Two truths:

* ``realistic``: the default near-continuous truth (10 Euler sub-steps per sample), which the
  asserted claims use. Identifier: ``identify`` defaults (EKF, 10 sub-steps per sample with
  the input interpolated, q_body = (3e-4, 3e-4, 3e-6), q_theta = 0, theta0 = 0 with sd 1).
* ``exact``: the identifier's own discrete model (``substeps=1``, paper eq. 4). Identifier:
  one Euler step per sample with the mean input (the paper's), q_body = (1e-5, 1e-5, 1e-8)
  (the model is exact; a small Q only keeps the filter from locking up).

The identifiable set is {a1, a9, b1..b4, c1..c3}: the sway and yaw coefficients, and the
surge terms that the rpm changes separate. a2, a3, a5, a6, a7 (v^2, r^2, v r, v d, r d in
surge) are weakly excited by the turns and zig-zags at this noise (median posterior sd
75-130% of the value on the realistic truth, 47-82% on the exact one), a4 (d^2) and a8 (u n)
moderately (17% and 29%; 11% and 16%).

Seeds are fixed, so every test is deterministic; the thresholds are the ones we set, and
the comments give the measured values and the confidence where a count of runs is tested.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import chi2

from trackkit.eval.manoeuvres import turning_metrics, zigzag_metrics
from trackkit.identify import (
    coefficient_nees,
    dead_reckon,
    identify,
    least_squares,
    position_error,
    predict,
    programme,
    relative_error,
    rmse,
    settling_step,
)
from trackkit.models.manoeuvring import COEFFICIENT_NAMES
from trackkit.sim import seatrials

RUNS, SEED = 100, 2025
SWAY_YAW = [9, 10, 11, 12, 13, 14, 15]  # b1..b4, c1..c3
CLAIM_A = [9, 10, 11, 13, 14, 15]  # b1..b3, c1..c3
IDENTIFIABLE = [0, 8] + SWAY_YAW  # a1, a9, b1..b4, c1..c3
Q_EXACT = [1e-5, 1e-5, 1e-8]
NEES_BAND = chi2.ppf([0.025, 0.975], 16)


def _names(idx) -> str:
    return ", ".join(COEFFICIENT_NAMES[i] for i in idx)


@pytest.fixture(scope="module", params=["realistic", "exact"])
def case(request):
    exact = request.param == "exact"
    rec = programme(RUNS, SEED, substeps=1 if exact else 10)
    kw = {"substeps": 1, "q_body": Q_EXACT} if exact else {}
    m = 1 if exact else 10
    ekf = identify(rec.z, rec.s, rec.dt, starts=rec.starts, filter="ekf", **kw)
    return SimpleNamespace(name=request.param, rec=rec, ekf=ekf, kw=kw, m=m,
                           theta=rec.truth.theta)


@pytest.fixture(scope="module")
def realistic():
    return programme(RUNS, SEED)


# --- a. sway and yaw coefficients -----------------------------------------------------------


def test_a_median_error_of_b1_b3_and_c1_c3_below_15_percent(case):
    # measured (median over 100 runs, b1 b2 b3 c1 c2 c3): realistic 0.9 2.0 1.4 3.3 1.7 1.7%,
    # exact 0.8 1.5 1.4 1.7 0.4 0.2%
    med = np.median(relative_error(case.ekf.theta, case.theta), 0)[CLAIM_A]
    assert np.all(med < 0.15), dict(zip(_names(CLAIM_A).split(", "), med.round(4), strict=True))


def test_a_the_papers_euler_step_biases_yaw_on_near_continuous_data(realistic):
    # One Euler step per second (paper eq. 4) against the near-continuous truth: the yaw
    # time constant is about 1.7 s, and the identified c1, c2, c3 are the Euler-equivalent
    # ones, 14-15% off (measured mean errors +14.2%, +14.5%, -14.3%, i.e. 53, 229 and 566
    # standard errors of the 100-run mean), against 1.7-3.3% with ten sub-steps.
    r = identify(realistic.z, realistic.s, realistic.dt, starts=realistic.starts, substeps=1)
    th = realistic.truth.theta
    bias = (r.theta.mean(0) - th) / np.abs(th)
    se = r.theta.std(0) / np.abs(th) / math.sqrt(RUNS)
    assert np.all(np.abs(bias[13:]) > 0.10) and np.all(np.abs(bias[13:]) > 20 * se[13:])


# --- b. filtered body states ----------------------------------------------------------------


def test_b_filtered_uvr_rmse_below_the_measurement_noise(case):
    # per run, over all 657 samples; measured worst run / noise sd (u, v, r): realistic 0.49,
    # 0.40, 0.67; exact 0.43, 0.31, 0.36. Asserted in every run.
    ratio = rmse(case.ekf.body - case.rec.x, -2) / case.rec.noise.body
    assert np.all(ratio < 1.0), ratio.max(0)


# --- c. convergence within 500 steps --------------------------------------------------------


def test_c_identifiable_coefficients_within_20_percent_by_step_500(case):
    # the step from which each coefficient stays within 20% of the truth to the end; measured:
    # all nine of a1, a9, b1..b4, c1..c3 by step 500 in 99% (realistic) and 100% (exact) of
    # runs; the slowest is a1 (median step 337 and 322: it needs the deceleration run, at
    # samples 394-454). A true rate of 95% would give >= 90 of 100 runs with 98.9% probability.
    k = settling_step(case.ekf.theta_history, case.theta, tol=0.2)[:, IDENTIFIABLE]
    frac = np.mean((k <= 500).all(-1))
    assert frac >= 0.90, frac


@pytest.mark.xfail(strict=True, reason=(
    "all 16 within 20% by step 500 in 0% of runs (both truths). Per coefficient, realistic "
    "(exact): a2 1% (3%), a3 1% (0%), a5 8% (8%), a6 10% (12%), a7 1% (15%), a4 62% (90%), "
    "a8 53% (70%), a1 99% (100%), the others 100%: the surge terms in v^2, r^2, v r, v d, r d "
    "are weakly excited at this noise (median posterior sd 75-130% of the value), d^2 and u n "
    "moderately (17% and 29%)"))
def test_c_all_16_coefficients_within_20_percent_by_step_500(case):
    k = settling_step(case.ekf.theta_history, case.theta, tol=0.2)
    assert np.mean((k <= 500).all(-1)) >= 0.90


# --- d. consistency of the coefficients' covariance -----------------------------------------


def _nees_inside(r, theta) -> float:
    nees = coefficient_nees(r.theta, r.cov, theta)
    return float(np.mean((nees >= NEES_BAND[0]) & (nees <= NEES_BAND[1])))


def test_d_coefficient_nees_inside_the_95_percent_band_in_90_percent_of_runs(case):
    # 16-dimensional NEES at the end against chi2(16) [6.91, 28.85]; measured: realistic 95%
    # inside (mean 20.8), exact 97% (mean 14.6). For a consistent filter 95 of 100 runs are
    # expected inside; >= 90 then has probability 0.989.
    assert _nees_inside(case.ekf, case.theta) >= 0.90


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "with Q matched to the rms of the model's own error per sample (q_body = 3e-5, 3e-5, "
    "1e-6: 0.004 m/s, 0.005 m/s, 0.05 deg/s), 6% of runs inside, NEES mean 42: that error is "
    "not white but comes in bursts where the rate-limited nozzle starts or stops between "
    "samples (the interpolated input misses them), so its effect on the coefficients is "
    "systematic: c3, the nozzle's yaw effectiveness, has an rms error of twice its stated sd. "
    "The default q_body, ten times larger, gives 95%; a coefficient random walk (1e-6/s with "
    "q_body = 1e-4, 1e-4, 1e-7) also gives 91% (NEES mean 10.8) but lets c1 wander (7.2% "
    "median error instead of 3.3%)"))
def test_d_nees_with_q_matched_to_the_model_error_rms(realistic):
    r = identify(realistic.z, realistic.s, realistic.dt, starts=realistic.starts,
                 q_body=[3e-5, 3e-5, 1e-6])
    assert _nees_inside(r, realistic.truth.theta) >= 0.90


# --- e. EKF, UKF, CKF and batch least squares -----------------------------------------------


@pytest.mark.slow
def test_e_the_three_filters_agree_and_are_consistent(case):
    # measured median errors of b1..b4, c1..c3 agree within 0.25 percentage points between
    # the filters (the model is mildly nonlinear over one sample); NEES inside: realistic
    # EKF 95%, UKF 95%, CKF 96%; exact EKF 97%, UKF 96%, CKF 96%
    rec = case.rec
    med = {"ekf": np.median(relative_error(case.ekf.theta, case.theta), 0)}
    for name in ("ukf", "ckf"):
        r = identify(rec.z, rec.s, rec.dt, starts=rec.starts, filter=name, **case.kw)
        med[name] = np.median(relative_error(r.theta, case.theta), 0)
        assert _nees_inside(r, case.theta) >= 0.90, name
        np.testing.assert_allclose(med[name][SWAY_YAW], med["ekf"][SWAY_YAW], atol=0.005)


def test_e_least_squares_is_worse_than_the_filter_on_near_continuous_data(realistic):
    # Equation error with the Euler difference on measured states: discretisation bias plus
    # errors in variables. Measured median errors (b1 b2 b3 b4 c1 c2 c3): LS 3.1 10.5 4.6 9.5
    # 8.1 12.9 13.6%, EKF 0.9 2.0 1.4 0.7 3.3 1.7 1.7%; LS NEES inside the band in 0% of runs
    # (mean 1128).
    th = realistic.truth.theta
    ls = least_squares(realistic.z, realistic.s, realistic.dt, starts=realistic.starts)
    ekf = identify(realistic.z, realistic.s, realistic.dt, starts=realistic.starts)
    e_ls = np.median(relative_error(ls.theta, th), 0)
    e_ekf = np.median(relative_error(ekf.theta, th), 0)
    assert np.all(e_ls[SWAY_YAW] > e_ekf[SWAY_YAW])
    assert _nees_inside(ls, th) < 0.5


def test_e_least_squares_errors_in_variables_bias():
    # On the identifier's own discrete model only the noisy regressors bias least squares:
    # measured mean errors b1 -6.1%, b2 -9.1%, b3 +7.3% (42, 31 and 29 standard errors of
    # the 100-run mean) against the EKF's -0.1%, -0.35%, +0.1%
    rec = programme(RUNS, SEED, substeps=1)
    th = rec.truth.theta
    ls = least_squares(rec.z, rec.s, rec.dt, starts=rec.starts)
    ekf = identify(rec.z, rec.s, rec.dt, starts=rec.starts, substeps=1, q_body=Q_EXACT)
    idx = [9, 10, 11]
    bias_ls = (ls.theta.mean(0) - th)[idx] / np.abs(th[idx])
    se_ls = ls.theta.std(0)[idx] / np.abs(th[idx]) / math.sqrt(RUNS)
    bias_ekf = (ekf.theta.mean(0) - th)[idx] / np.abs(th[idx])
    assert np.all(np.abs(bias_ls) > 0.03) and np.all(np.abs(bias_ls) > 10 * se_ls)
    assert np.all(np.abs(bias_ekf) < np.abs(bias_ls) / 3)


# --- f. prediction with the identified model ------------------------------------------------


def test_f_predicted_10_10_zigzag_within_a_ship_length(case):
    # A 10/10 zig-zag to port first (the programme's is to starboard), 60 s from the true
    # initial state, only its sampled inputs given. Measured max position error over the
    # 60 s: realistic median run 0.96 m (worst run 1.03 m), exact 0.16 m (worst 0.58 m).
    th, norm, d = case.theta, case.rec.truth.norm, math.radians(10)
    val = seatrials.zigzag(th, norm, delta=d, alpha=d, rpm=2000.0, side=-1.0,
                           substeps=case.rec.substeps, duration=60.0)
    s = np.stack([val.delta, val.n], -1)
    x0 = np.array([val.u[0], val.v[0], val.r[0]])
    p = predict(case.ekf.theta, s, case.rec.dt, x0, norm=norm, substeps=case.m)
    worst = position_error(p.pose, val.east, val.north).max(-1)
    assert np.median(worst) < 19.6


def test_f_overshoots_and_turning_diameter_within_10_percent(case):
    # The identified models (each run's) in the sea-trial simulator with their own
    # discretisation, against the reference vessel with the truth's: 10/10 zig-zag first and
    # second overshoot (reference 5.06 and 6.28 deg realistic) and D/L of a 20 deg turn
    # (4.92). Measured relative differences, median run / worst run: realistic 4.3/5.1%,
    # 5.0/5.6%, 0.4/0.7%; exact 0.2/0.7%, 0.2/1.9%, 0.07/0.3%. Asserted in the median run
    # (the claim) and in 90% of runs.
    th, norm, d = case.theta, case.rec.truth.norm, math.radians(10)
    speed = case.rec.truth.design["speed"]
    ref = seatrials.zigzag(th, norm, delta=d, alpha=d, rpm=2000.0, substeps=case.rec.substeps)
    hat = seatrials.zigzag(case.ekf.theta, norm, delta=d, alpha=d, rpm=2000.0, speed=speed,
                           substeps=case.m, duration=ref.t[-1] + 20.0)
    mr, mh = zigzag_metrics(ref.t, ref.psi, d), zigzag_metrics(hat.t, hat.psi, d)
    turn = dict(delta=math.radians(20), rpm=2000.0)
    tr = seatrials.turning_circle(th, norm, substeps=case.rec.substeps, **turn)
    th_ = seatrials.turning_circle(case.ekf.theta, norm, speed=speed, substeps=case.m, **turn)
    L = case.rec.truth.design["length"]
    dl_ref = turning_metrics(tr.t, tr.east, tr.north, tr.psi, L).diameter_to_length
    dl_hat = turning_metrics(th_.t, th_.east, th_.north, th_.psi, L).diameter_to_length
    for name, ref_v, hat_v in (("first overshoot", mr.first_overshoot, mh.first_overshoot),
                               ("second overshoot", mr.second_overshoot, mh.second_overshoot),
                               ("D/L", dl_ref, dl_hat)):
        rel = np.abs(hat_v - ref_v) / np.abs(ref_v)
        assert np.median(rel) < 0.10, name
        assert np.mean(rel < 0.10) >= 0.90, name


# --- g. filtering against raw GPS positions -------------------------------------------------


def test_g_filtered_track_beats_raw_gps(case):
    # The filtered u, v integrated with the measured heading (0.2 deg) from each trial's
    # known start pose (dead_reckon), against GPS positions with 2.5 m per axis (RMSE 3.55 m
    # horizontal). Measured track RMSE: realistic median 0.43 m (8.2 times better than GPS;
    # worst run 0.81 m, smallest factor 4.3), exact 0.41 m (8.5; 4.6). For reference, the raw
    # measured u, v integrated the same way give 0.52 m: most of the gain over GPS comes
    # from integrating velocities rather than from the filter. Asserted in every run, and a
    # median factor of at least 4.
    rec, body = case.rec, case.ekf.body
    err, gps = [], []
    for seg in rec.segments:
        sl = slice(seg.start, seg.stop)
        track = dead_reckon(body[:, sl], rec.heading[:, sl], rec.dt, rec.pose[:, seg.start])
        err.append(position_error(track, rec.pose[:, sl, 0], rec.pose[:, sl, 1]))
        gps.append(position_error(rec.gps[:, sl], rec.pose[:, sl, 0], rec.pose[:, sl, 1]))
    e, g = rmse(np.concatenate(err, -1)), rmse(np.concatenate(gps, -1))
    assert np.all(e < g)
    assert np.median(g / e) >= 4.0, np.median(g / e)
