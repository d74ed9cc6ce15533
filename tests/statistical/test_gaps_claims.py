"""The missing-measurements thesis's claims about gaps (chapter 4; docs/radar-comparison.md) on
our Monte Carlo runs.

The scenarios are built directly with trackkit's models. The thesis gives the time step,
the gap and (S6) R; every other number is ours, marked "(ours)" in each docstring. Runs are
batch rows; run r draws from ``run_rng(seed, r)`` in a fixed order (the initial-state offset,
then the process noise, then the measurement noise), so every handler sees the same truth
and measurements. The window of a fit P is, in both S5 and S6, the whole record before the
gap (the thesis fits "the measurements from the preceding interval"), chosen before any run.

Where a claim of the thesis does not hold on these runs, the test asserts what does, with the
reason, and the claim itself stays as a strict xfail with the numbers we measured: it fails
loudly if a change ever makes it hold, so that the comparison document is updated.
Confidence: a fraction p over N runs has standard error sqrt(p (1 - p) / N); the thresholds
asserted are at least 3 standard errors from what we measured (99.7% two-sided), unless said.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.angles import wrap
from trackkit.filters.gaps import (
    Coast,
    HoldLast,
    MeanOfLast,
    PolynomialFit,
    SineFit,
    gap_and_after,
    mask_by_samples,
    mask_by_time,
    measurement_times,
    run_with_gaps,
)
from trackkit.linalg import psd_factor
from trackkit.sim.streams import run_rng

RUNS = 1000


def simulate(motion, sensor, x0, P0, steps, dt, runs, seed):
    """Truth ``(steps + 1, runs, n)`` from ``x0 + chol(P0) u`` and measurements
    ``(steps, runs, m)``; the filters start from ``N(x0, P0)``."""
    n, m = x0.size, sensor.dim_z
    u0, w, e = np.empty((runs, n)), np.empty((steps, runs, n)), np.empty((steps, runs, m))
    for r in range(runs):
        g = run_rng(seed, r)
        u0[r] = g.standard_normal(n)
        w[:, r] = g.standard_normal((steps, n))
        e[:, r] = g.standard_normal((steps, m))
    LQ = psd_factor(np.asarray(motion.noise(None, dt)))
    LR = np.linalg.cholesky(sensor.noise)
    x = np.empty((steps + 1, runs, n))
    x[0] = x0 + u0 @ psd_factor(P0).T
    z = np.empty((steps, runs, m))
    for k in range(steps):
        x[k + 1] = motion.f(x[k], dt) + w[k] @ LQ.T
        z[k] = sensor.h(x[k + 1]) + e[k] @ LR.T
    prior = tk.Gaussian(np.tile(x0, (runs, 1)), np.tile(P0, (runs, 1, 1)))
    return x, z, prior


def per_run_rmse(err, window):
    """RMSE over the steps of ``window`` (K,), one per run."""
    return np.sqrt(np.mean(err[window] ** 2, axis=0))


def summary(a, b):
    """Fraction of runs where ``a < b`` and the median of ``a / b``."""
    return float(np.mean(a < b)), float(np.median(a / b))


# ------------------------------------------------------------------------------------------
# S5: 1-D nearly-constant-acceleration target, KF, T = 0.1 s, no measurements 2-5 s


S5_DT, S5_STEPS = 0.1, 80


@pytest.fixture(scope="module")
def s5():
    """S5 (the thesis's section 4-3): T = 0.1 s and the gap 2-5 s (30 samples, t = 2.0 .. 4.9 s) are
    the thesis's. Ours: 8 s of track; white-jerk density q = 0.1 m^2/s^5; position noise
    sigma = 0.5 m; x0 = (0 m, 5 m/s, 1 m/s^2) with P0 = diag(0.25, 1, 1); B2 averages the
    last 5; P is a degree-2 polynomial (the thesis's choice for CA) over the last 20 (all
    19 measurements before the gap). The KF uses the true model. Error window: the gap and
    the 1 s after it (40 steps). Seed 5001, 1000 runs."""
    motion = tk.models.ConstantAcceleration(dim=1, q=0.1)
    sensor = tk.models.Position(dim=1, sigma=0.5)
    x, z, prior = simulate(motion, sensor, np.array([0.0, 5.0, 1.0]),
                           np.diag([0.25, 1.0, 1.0]), S5_STEPS, S5_DT, RUNS, 5001)
    mask = mask_by_time(measurement_times(S5_STEPS, S5_DT), 2.0, 5.0)
    window = gap_and_after(mask, 10)
    out = {}
    for name, h in (("B0", Coast()), ("B2", MeanOfLast(5)), ("P", PolynomialFit(2, 20))):
        run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, S5_DT, mask, h,
                            keep_cov=False)
        out[name] = per_run_rmse(run.estimate.mean[..., 0] - x[1:, :, 0], window)
    return out


def test_s5_p_beats_b2(s5):
    """P beats B2 on position RMSE over the gap and the second after it in at least 80% of
    runs (the thesis's claim; measured 97.4%, 95% interval 96.4-98.4%; median ratio
    RMSE(P)/RMSE(B2) = 0.15). B2 feeds a stale position to an accelerating target."""
    frac, ratio = summary(s5["P"], s5["B2"])
    assert frac >= 0.8
    assert ratio < 0.5


def test_s5_coasting_on_the_true_model_beats_the_fit(s5):
    """B0 beats P: with the KF on the true linear-Gaussian model, its prediction through
    the gap is the minimum-mean-square-error estimate given the real measurements, and
    after the gap it re-converges with the right covariance; the fit uses less data, and
    feeding its values as measurements with the sensor's R makes the filter overconfident.
    Measured: P beats B0 in 33.3% of runs (95% interval 30.4-36.2%), median
    RMSE(P)/RMSE(B0) = 1.50, mean MSE ratio 2.30; the mean MSE ratio is asserted above 1
    (theory guarantees it in expectation)."""
    frac, ratio = summary(s5["P"], s5["B0"])
    assert np.mean(s5["B0"] ** 2) < np.mean(s5["P"] ** 2)
    assert frac < 0.5 and ratio > 1.0


@pytest.mark.xfail(strict=True, reason="thesis claim (chapter 4): P beats B0 in >= 80% of "
                   "runs; measured 33.3% (median RMSE ratio 1.50): coasting a matched KF is "
                   "the MMSE predictor (see the test above)")
def test_s5_thesis_claim_p_beats_b0_and_b2(s5):
    assert summary(s5["P"], s5["B0"])[0] >= 0.8
    assert summary(s5["P"], s5["B2"])[0] >= 0.8


# ------------------------------------------------------------------------------------------
# S6: the sine, state (theta, omega), y = sin(theta) + r, EKF, gap at samples 50-90


S6_DT, S6_STEPS = 0.1, 100


@pytest.fixture(scope="module")
def s6():
    """S6 (the thesis's section 4-4): dt = 0.1 s, R = 1, Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]],
    H = (cos theta, 0) (``Sine(amplitude=False)``), EKF, and the gap from sample 50 to 90
    (counted from 1: indices 49 .. 89, t = 5.0 .. 9.0 s) are the thesis's. Ours: q = 0.01
    rad^2/s^3 (the thesis prints Q without a factor; q = 1 literally, see the report);
    x0 = (0 rad, 1 rad/s), P0 = diag(0.1, 0.1); 10 s of samples; P is ``SineFit`` over
    the last 49 (all before the gap), amplitude 1, Gauss-Newton from the EKF's predicted
    estimate. Error: the phase error wrapped to (-pi, pi] (y cannot tell theta from
    theta + 2 pi), over the gap and the second after it (51 steps). Seed 6001, 1000 runs."""
    motion = tk.models.ConstantVelocity(dim=1, q=0.01)
    sensor = tk.models.Sine(sigma=1.0, amplitude=False)
    x, z, prior = simulate(motion, sensor, np.array([0.0, 1.0]), np.diag([0.1, 0.1]),
                           S6_STEPS, S6_DT, RUNS, 6001)
    mask = mask_by_samples(S6_STEPS, 49, 89)
    window = gap_and_after(mask, 10)
    out = {}
    for name, h in (("B0", Coast()), ("B1", HoldLast()), ("P", SineFit(window=49))):
        run = run_with_gaps(tk.filters.EKF(), prior, motion, sensor, z, S6_DT, mask, h,
                            keep_cov=False)
        out[name] = per_run_rmse(wrap(run.estimate.mean[..., 0] - x[1:, :, 0]), window)
    return out


def test_s6_p_beats_b1(s6):
    """P beats B1 (hold the last measurement) over the gap and the second after it.
    Measured: in 79.2% of runs (95% interval 76.7-81.7%), median RMSE(P)/RMSE(B1) = 0.51
    (bootstrap 95% interval 0.46-0.54). Asserted 3 standard errors below: at least 75% of
    runs, median ratio below 0.6. (B0, coasting, beats B1 in 83.2% with median 0.46, and
    P against B0 is a coin toss: 47.7%, median 1.02.)
    With R = 1 on a unit sine the EKF's phase error is already 0.3-0.5 rad before the gap,
    and the runs that P loses are mostly those where it was worse before the gap."""
    frac, ratio = summary(s6["P"], s6["B1"])
    assert frac >= 0.75
    assert ratio < 0.6


@pytest.mark.xfail(strict=True, reason="thesis thresholds (chapter 4): P beats B1 in >= 80% "
                   "of runs and median RMSE(P)/RMSE(B1) < 0.5; measured 79.2% and 0.51")
def test_s6_thesis_thresholds(s6):
    frac, ratio = summary(s6["P"], s6["B1"])
    assert frac >= 0.8 and ratio < 0.5


# ------------------------------------------------------------------------------------------
# S4: 1-D nearly-constant-velocity target, KF, T = 1 s, gap 20-25 s, B2


S4_DT, S4_STEPS = 1.0, 90


@pytest.fixture(scope="module")
def s4():
    """S4 (the thesis's section 4-2): T = 1 s and the gap 20-25 s (t = 20 .. 24 s, 5 samples) are
    the thesis's. Ours: 90 s of track; white-acceleration density q = 0.1 m^2/s^3; position
    noise sigma = 10 m; x0 = (0 m, 10 m/s), P0 = diag(100, 4); B2 averages the last 5; gaps
    of 10, 15 and 20 s from t = 20 s for the growth. Seed 4001, 1000 runs."""
    motion = tk.models.ConstantVelocity(dim=1, q=0.1)
    sensor = tk.models.Position(dim=1, sigma=10.0)
    x, z, prior = simulate(motion, sensor, np.array([0.0, 10.0]), np.diag([100.0, 4.0]),
                           S4_STEPS, S4_DT, RUNS, 4001)
    t = measurement_times(S4_STEPS, S4_DT)

    def run(mask, h):
        r = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, S4_DT, mask, h)
        return r, r.estimate.mean[..., 0] - x[1:, :, 0]

    _, e_ref = run(np.zeros(S4_STEPS, bool), Coast())
    out = {"ref": np.sqrt(np.mean(e_ref**2, axis=1)), "gaps": {}}
    for length in (5, 10, 15, 20):
        mask = mask_by_time(t, 20.0, 20.0 + length)
        r, e = run(mask, MeanOfLast(5))
        end = int(np.nonzero(mask)[0][-1])
        # the first real measurement after the gap against the prediction from the gap's end
        F, Q = motion.jacobian(None, S4_DT), motion.noise(None, S4_DT)
        x_pred = r.estimate.mean[end] @ F.T
        S = (F @ r.estimate.cov[end] @ F.T + Q)[:, 0, 0] + sensor.noise[0, 0]
        nis = (z[end + 1, :, 0] - x_pred[:, 0]) ** 2 / S
        out["gaps"][length] = dict(mask=mask, end=end, rmse=np.sqrt(np.mean(e**2, axis=1)),
                                   gap_rmse=float(np.sqrt(np.mean(e[mask] ** 2))), nis=nis)
    return out


def _settling(ratio):
    """Steps after which ``ratio`` stays within 10% of 1 to the end of the run."""
    above = np.nonzero(ratio > 1.1)[0]
    return int(above[-1] + 1) if above.size else 0


def test_s4_b2_keeps_the_track(s4):
    """After the thesis's 5-s gap, B2's per-step RMSE (over 1000 runs) comes back within 10%
    of the no-gap run's and stays there within 30 steps of the gap's end (measured 24; each
    step's RMSE ratio has about 2% Monte Carlo noise, which moves that crossing by a few
    steps), within 50% after 10 (measured 8), and is finite throughout: the filter, fed
    every measurement, recovers. The step counts are set by the KF's steady-state velocity
    gain at q = 0.1, sigma = 10 m."""
    g = s4["gaps"][5]
    ratio = g["rmse"][g["end"] + 1:] / s4["ref"][g["end"] + 1:]
    assert np.isfinite(g["rmse"]).all()
    assert _settling(ratio) <= 30
    assert np.all(ratio[10:] <= 1.5)


def test_s4_b2_error_grows_with_the_gap(s4):
    """Longer gaps (5, 10, 15, 20 s) give a larger RMSE over the gap (measured 30, 64, 99,
    134 m), a larger peak (48, 109, 170, 228 m) and no faster recovery (24, 28, 30, 30
    steps to within 10%)."""
    gaps = [s4["gaps"][n] for n in (5, 10, 15, 20)]
    rmse = [g["gap_rmse"] for g in gaps]
    peak = [g["rmse"][g["mask"]].max() for g in gaps]
    settle = [_settling(g["rmse"][g["end"] + 1:] / s4["ref"][g["end"] + 1:]) for g in gaps]
    assert all(a < b for a, b in zip(rmse, rmse[1:], strict=False))
    assert all(a < b for a, b in zip(peak, peak[1:], strict=False))
    assert all(a <= b for a, b in zip(settle, settle[1:], strict=False))


def test_s4_b2_would_not_pass_a_gate(s4):
    """What "keeps the track" needs: in a tracker that gates, the first measurement after
    the 5-s gap must fall in the 99% gate of the B2-fed prediction. It does in 10% of runs
    (asserted below 25%): B2 makes the filter confident in a stale position, so a gated
    tracker would drop the target, as the thesis fears for S5 (Fig. 4-6)."""
    g = s4["gaps"][5]
    assert np.mean(g["nis"] < 6.635) < 0.25
