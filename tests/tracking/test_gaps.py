"""Missing-measurement handling (the missing-measurements thesis, chapter 4): gap masks, the
handlers B0, B1, B2, P and P' on small deterministic sequences, and the runner with trackkit's
filters.

Deterministic maths is checked to 1e-12 relative unless a reason is given beside the check;
the handlers' batched rows must equal single rows bitwise (their reductions run slot by
slot), while the filters' own batched kernels round differently with the batch size, so a
whole run is compared row by row to 1e-12.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest

import trackkit as tk
from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.filters.gaps import (
    HANDLER_NAMES,
    Coast,
    GapHandler,
    HoldLast,
    MeanOfLast,
    PolynomialFit,
    SineFit,
    gap_and_after,
    make_handler,
    mask_by_count,
    mask_by_samples,
    mask_by_time,
    measurement_times,
    run_with_gaps,
    union,
)

REL = 1e-12


# ------------------------------------------------------------------------------------------
# A stand-in manoeuvre detector with the interface of trackkit.filters.maneuver's detectors


class _DetState(NamedTuple):
    stat: np.ndarray
    on: np.ndarray


class StandInDetector:
    """Fading-memory NIS ``rho = alpha rho + eps`` against a threshold; a nan residual
    holds the statistic and the on flag (the interface of maneuver.py's detectors)."""

    def __init__(self, threshold: float = 20.0, alpha: float = 0.8) -> None:
        self.threshold, self.alpha = threshold, alpha

    def init(self, batch_shape):
        return _DetState(np.zeros(batch_shape), np.zeros(batch_shape, bool))

    def step(self, s, innov):
        eps = innov.nis
        held = np.isnan(eps)
        stat = np.where(held, s.stat, self.alpha * s.stat + np.where(held, 0.0, eps))
        return _DetState(stat, np.where(held, s.on, stat > self.threshold))


def _feed(handler: GapHandler, sensor, times, z, batch=()):
    """A handler's memory after observing ``z (K, ..., m)`` at ``times`` (nan = not real)."""
    mem = handler.init(batch, sensor)
    for t, zk in zip(times, z, strict=True):
        mem = handler.observe(mem, t, zk)
    return mem


POS1 = tk.models.Position(dim=1, sigma=1.0)
POS2 = tk.models.Position(dim=2, sigma=1.0)
BEARING = tk.models.Bearing(origin=[0.0, 0.0], sigma=0.01)


# ------------------------------------------------------------------------------------------
# Masks


def test_measurement_times_follow_the_runner_convention():
    t = measurement_times(5, 0.1, t0=2.0)
    np.testing.assert_array_equal(t, 2.0 + np.array([1, 2, 3, 4, 5]) * 0.1)
    np.testing.assert_array_equal(measurement_times(3, [1.0, 2.0, 0.5]), [1.0, 3.0, 3.5])


def test_mask_by_time_is_half_open_and_counts_the_thesis_samples():
    """S5: 2-5 s at T = 0.1 s is the thesis's 30 samples, t = 2.0 .. 4.9 s; S4: 20-25 s at
    T = 1 s is t = 20 .. 24 s."""
    t = measurement_times(80, 0.1)
    m = mask_by_time(t, 2.0, 5.0)
    assert m.shape == (80,) and m.sum() == 30
    np.testing.assert_allclose(t[m][[0, -1]], [2.0, 4.9], rtol=REL)
    assert not m[np.argmin(np.abs(t - 5.0))]  # the first measurement after the gap
    t4 = measurement_times(40, 1.0)
    np.testing.assert_array_equal(t4[mask_by_time(t4, 20.0, 25.0)], [20, 21, 22, 23, 24])


def test_mask_by_time_lands_on_the_grid_whichever_way_k_dt_rounds():
    t = np.arange(1, 101) * 0.1  # 3 * 0.1 = 0.30000000000000004 and the like
    for a, b in [(0.3, 0.6), (0.7, 1.3), (2.9, 3.3)]:
        assert mask_by_time(t, a, b).sum() == round((b - a) / 0.1)


def test_mask_by_time_per_run():
    t = measurement_times(50, 1.0)
    starts = np.array([10.0, 20.0, 30.0])
    m = mask_by_time(t, starts, starts + 5.0)
    assert m.shape == (50, 3)
    for j, a in enumerate(starts):
        np.testing.assert_array_equal(m[:, j], mask_by_time(t, a, a + 5.0))


def test_mask_by_samples_includes_both_ends():
    """S6: the thesis's samples 50 to 90 (counted from 1) are indices 49 .. 89, 41 samples."""
    m = mask_by_samples(100, 49, 89)
    np.testing.assert_array_equal(np.nonzero(m)[0], np.arange(49, 90))
    per_run = mask_by_samples(100, np.array([10, 49]), np.array([19, 89]))
    np.testing.assert_array_equal(per_run[:, 1], m)
    np.testing.assert_array_equal(np.nonzero(per_run[:, 0])[0], np.arange(10, 20))


def test_mask_by_count():
    np.testing.assert_array_equal(np.nonzero(mask_by_count(200, 40, 10))[0], np.arange(40, 50))
    m = mask_by_count(30, np.array([0, 5]), np.array([3, 1]))
    np.testing.assert_array_equal(np.nonzero(m[:, 0])[0], [0, 1, 2])
    np.testing.assert_array_equal(np.nonzero(m[:, 1])[0], [5])


def test_union_of_gaps_and_of_shared_with_per_run_masks():
    a, b = mask_by_count(20, 2, 3), mask_by_samples(20, 10, 11)
    np.testing.assert_array_equal(np.nonzero(union(a, b))[0], [2, 3, 4, 10, 11])
    per_run = mask_by_count(20, np.array([0, 15]), 2)
    u = union(a, per_run)
    assert u.shape == (20, 2)
    np.testing.assert_array_equal(np.nonzero(u[:, 1])[0], [2, 3, 4, 15, 16])


def test_gap_and_after():
    m = mask_by_samples(12, 3, 4)
    np.testing.assert_array_equal(np.nonzero(gap_and_after(m, 2))[0], [3, 4, 5, 6])
    np.testing.assert_array_equal(gap_and_after(m, 0), m)
    np.testing.assert_array_equal(np.nonzero(gap_and_after(mask_by_samples(6, 4, 5), 3))[0],
                                  [4, 5])


@pytest.mark.parametrize("call, match", [
    (lambda: mask_by_time(measurement_times(10, 1.0), 5.0, 5.0), "start = 5.0 and stop = 5.0"),
    (lambda: mask_by_time(measurement_times(10, 1.0), 20.0, 25.0), r"\[20.0, 25.0\)"),
    (lambda: mask_by_time(measurement_times(10, 1.0), np.nan, 5.0), "start"),
    (lambda: mask_by_time([1.0, 3.0, 2.0], 1.0, 2.0), "not increasing"),
    (lambda: mask_by_samples(10, 5, 3), "from sample 5 to 3"),
    (lambda: mask_by_samples(10, 5, 10), "<= 9"),
    (lambda: mask_by_samples(10, -1, 3), "from sample -1"),
    (lambda: mask_by_samples(10, 2.5, 3), "first = 2.5"),
    (lambda: mask_by_count(10, 2, 0), "count = 0"),
    (lambda: mask_by_count(10, 8, 5), "from sample 8 to 12"),
    (lambda: mask_by_samples(0, 0, 0), "steps = 0"),
    (lambda: union(), "no masks"),
    (lambda: union(np.zeros(5, bool), np.zeros(6, bool)), r"\[5, 6\] time steps"),
    (lambda: union(np.zeros(5)), "dtype float64"),
    (lambda: gap_and_after(np.zeros(5, bool), -1), "after = -1"),
    (lambda: measurement_times(5, -0.1), "dt = -0.1"),
])
def test_bad_mask_input_names_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# ------------------------------------------------------------------------------------------
# Handlers on small deterministic sequences


def test_coast_feeds_nothing():
    h = Coast()
    mem = _feed(h, POS1, [0.1, 0.2], np.array([[1.0], [2.0]]))
    z, _ = h.pseudo(mem, 0.3, True, POS1)
    assert z.shape == (1,) and np.isnan(z).all()


def test_hold_last_holds_the_newest_real_measurement():
    h = HoldLast()
    mem = h.init((), POS2)
    z, _ = h.pseudo(mem, 0.1, True, POS2)
    assert np.isnan(z).all()  # nothing seen yet: coast
    for t, zk in [(0.1, [1.0, -1.0]), (0.2, [2.0, -2.0]), (0.3, [np.nan, np.nan]),
                  (0.4, [3.0, -3.0])]:
        mem = h.observe(mem, t, np.array(zk))
    z, _ = h.pseudo(mem, 0.5, True, POS2)
    np.testing.assert_array_equal(z, [3.0, -3.0])
    z, _ = h.pseudo(mem, 0.5, False, POS2)
    assert np.isnan(z).all()  # not missing: no pseudo-measurement


def test_mean_of_last_n():
    h = MeanOfLast(3)
    mem = _feed(h, POS1, [1, 2], np.array([[1.0], [2.0]]))
    z, _ = h.pseudo(mem, 3.0, True, POS1)
    assert z[0] == 1.5  # fewer than n seen: the mean of those
    mem = _feed(h, POS1, [1, 2, 3, 4, 5], np.array([[1.0], [2.0], [np.nan], [4.0], [8.0]]))
    z, _ = h.pseudo(mem, 6.0, True, POS1)
    assert z[0] == (2.0 + 4.0 + 8.0) / 3  # the last three real ones, skipping the nan


def test_mean_of_angles_across_the_cut():
    """Bearings pi - 0.1, -pi + 0.1, -pi + 0.2 are 0.1 rad apart on the circle: their mean
    is pi + 0.2/3 unwrapped, -pi + 0.2/3 wrapped (not the near-zero arithmetic mean)."""
    h = MeanOfLast(3)
    zs = np.array([[np.pi - 0.1], [-np.pi + 0.1], [-np.pi + 0.2]])
    z, _ = h.pseudo(_feed(h, BEARING, [1, 2, 3], zs), 4.0, True, BEARING)
    assert z[0] == pytest.approx(-np.pi + 0.2 / 3, rel=REL)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_polynomial_extrapolation_is_exact_on_polynomial_data(degree):
    """z = sum c_j t^j sampled at 0.1 .. 2.0 s; the fit of that degree over the last 12
    extrapolates to 2.1 .. 3.0 s exactly (to rounding; the fit is in scaled time, so V is
    well conditioned: 1e-12 relative)."""
    c = np.array([1.5, -2.0, 0.7, 0.3])[: degree + 1]
    t = measurement_times(30, 0.1)
    truth = np.polynomial.polynomial.polyval(t, c)
    z = np.stack([truth, -2 * truth + 1], -1)  # two components, fitted independently
    h = PolynomialFit(degree, window=12)
    mem = _feed(h, POS2, t[:20], z[:20])
    for k in range(20, 30):
        zk, mem = h.pseudo(mem, t[k], True, POS2)
        np.testing.assert_allclose(zk, z[k], rtol=REL, atol=REL * np.abs(z).max())


def test_polynomial_fit_uses_the_last_window_only():
    """A kink at t = 1: a degree-1 fit over the last 5 (all after the kink) extrapolates the
    new line exactly; over the last 15 it does not."""
    t = measurement_times(20, 0.1)
    z = np.where(t <= 1.0, t, 1.0 + 3.0 * (t - 1.0))[:, None]
    short, long = PolynomialFit(1, 5), PolynomialFit(1, 15)
    zs, _ = short.pseudo(_feed(short, POS1, t[:15], z[:15]), t[15], True, POS1)
    zl, _ = long.pseudo(_feed(long, POS1, t[:15], z[:15]), t[15], True, POS1)
    assert zs[0] == pytest.approx(z[15, 0], rel=REL)
    assert abs(zl[0] - z[15, 0]) > 0.1


def test_polynomial_fit_of_bearings_across_the_cut():
    """Bearing 3.0 + 0.05 k rad crosses pi at k = 3: unwrapped before the fit and wrapped
    after, the degree-1 fit reproduces it (1e-12 absolute: angles of order pi)."""
    t = measurement_times(20, 1.0)
    z = wrap(3.0 + 0.05 * np.arange(20))[:, None]
    h = PolynomialFit(1, 6)
    mem = _feed(h, BEARING, t[:8], z[:8])
    for k in range(8, 20):
        zk, mem = h.pseudo(mem, t[k], True, BEARING)
        assert abs(wrap(zk[0] - z[k, 0])) < 1e-12
        assert -np.pi < zk[0] <= np.pi


def test_fit_is_made_once_per_gap_and_dropped_by_a_real_measurement():
    h = PolynomialFit(1, 4)
    t = measurement_times(10, 1.0)
    mem = _feed(h, POS1, t[:4], (2.0 * t[:4])[:, None])
    _, mem = h.pseudo(mem, t[4], True, POS1)
    assert mem.fitted and mem.t_ref == t[3]
    coef = mem.coef.copy()
    _, mem = h.pseudo(mem, t[5], True, POS1)
    np.testing.assert_array_equal(mem.coef, coef)  # held through the gap
    mem = h.observe(mem, t[6], np.array([100.0]))
    assert not mem.fitted
    z, mem = h.pseudo(mem, t[7], True, POS1)  # a new gap: refitted through (t6, 100)
    assert mem.t_ref == t[6] and abs(z[0] - 2.0 * t[7]) > 10


def test_too_few_measurements_to_fit_coast():
    h = PolynomialFit(2, 10)
    mem = _feed(h, POS1, [1.0, 2.0], np.array([[1.0], [2.0]]))
    z, mem = h.pseudo(mem, 3.0, True, POS1)
    assert np.isnan(z).all() and not mem.fitted


def _sine_estimate(theta, omega, amplitude=None):
    x = [theta, omega] + ([] if amplitude is None else [amplitude])
    return Gaussian(np.array(x), np.eye(len(x)))


def test_sine_fit_recovers_a_noiseless_sine():
    """y = sin(0.3 + 1.7 t) at 0.1 .. 3.0 s; Gauss-Newton from a filter estimate off by
    0.3 rad in phase and 0.25 rad/s in rate recovers it (zero-residual Gauss-Newton
    converges quadratically, to rounding: 1e-10 absolute on values of order 1)."""
    sensor = tk.models.Sine(sigma=1.0, amplitude=False)
    t = measurement_times(60, 0.1)
    theta = 0.3 + 1.7 * t
    h = SineFit(window=30)
    mem = _feed(h, sensor, t[:30], np.sin(theta[:30])[:, None])
    est = _sine_estimate(theta[30] + 0.3, 1.7 - 0.25)  # predicted estimate at t[30]
    for k in range(30, 60):
        zk, mem = h.pseudo(mem, t[k], True, sensor, est)
        assert abs(zk[0] - np.sin(theta[k])) < 1e-10
    np.testing.assert_allclose(mem.coef[:2, 0], [theta[29], 1.7], rtol=1e-10)


def test_sine_fit_with_amplitude():
    """The S3 sine y = a sin(theta) on [theta, omega, a]: a = 2.5 fitted from a = 2 (1e-10
    absolute, as above)."""
    sensor = tk.models.Sine(sigma=1.0, amplitude=True)
    t = measurement_times(50, 0.1)
    theta = -1.0 + 2.2 * t
    h = SineFit(window=25, amplitude=2)
    mem = _feed(h, sensor, t[:25], (2.5 * np.sin(theta[:25]))[:, None])
    zk, mem = h.pseudo(mem, t[40], True, sensor, _sine_estimate(theta[25] - 0.2, 2.0, 2.0))
    assert abs(zk[0] - 2.5 * np.sin(theta[40])) < 1e-10
    assert mem.coef[2, 0] == pytest.approx(2.5, rel=1e-10)


def test_p_prime_fits_the_short_window_where_the_detector_is_on():
    """Two rows with the same kinked data (slope 1, then 3 after t = 1): the row whose
    detector is on fits the last 5 (after the kink) and extrapolates the new line."""
    h = PolynomialFit(1, window=15, short_window=5)
    assert h.label == "P'"
    t = measurement_times(20, 0.1)
    z = np.where(t <= 1.0, t, 1.0 + 3.0 * (t - 1.0))[:, None]
    zz = np.broadcast_to(z[:, None, :], (20, 2, 1))
    mem = _feed(h, POS1, t[:15], zz[:15], batch=(2,))
    zk, _ = h.pseudo(mem, t[15], np.array([True, True]), POS1,
                     maneuver=np.array([False, True]))
    assert zk[1, 0] == pytest.approx(z[15, 0], rel=REL)
    long, _ = PolynomialFit(1, 15).pseudo(_feed(PolynomialFit(1, 15), POS1, t[:15], z[:15]),
                                          t[15], True, POS1)
    assert zk[0, 0] == long[0]
    with pytest.raises(ValueError, match="maneuver=None"):
        h.pseudo(mem, t[15], True, POS1)


def _ragged_batch(rng, R, K, m, nan_rate=0.25):
    """R rows of measurements with nan at random steps (so every row's window differs)."""
    z = rng.standard_normal((K, R, m)).cumsum(0)
    z[rng.random((K, R)) < nan_rate] = np.nan
    return z


@pytest.mark.parametrize("make", [
    lambda: HoldLast(), lambda: MeanOfLast(4), lambda: PolynomialFit(2, 8),
    lambda: PolynomialFit(1, 8, short_window=3),
])
def test_handler_rows_batched_equal_single_rows_bitwise(make):
    rng = np.random.default_rng(11)
    R, K = 9, 25
    z = _ragged_batch(rng, R, K, 2)
    t = measurement_times(K, 0.5)
    missing = rng.random((3, R)) < 0.7
    on = rng.random(R) < 0.5
    h = make()
    mem = _feed(h, POS2, t[:-3], z[:-3], batch=(R,))
    outs = []
    for j in range(3):
        zk, mem = h.pseudo(mem, t[-3 + j], missing[j], POS2, maneuver=on)
        outs.append(zk)
    for r in range(R):
        m1 = _feed(h, POS2, t[:-3], z[:-3, r:r + 1], batch=(1,))
        for j in range(3):
            zk, m1 = h.pseudo(m1, t[-3 + j], missing[j, r:r + 1], POS2, maneuver=on[r:r + 1])
            np.testing.assert_array_equal(zk[0], outs[j][r])


def test_sine_fit_rows_batched_equal_single_rows_bitwise():
    rng = np.random.default_rng(5)
    R, K = 6, 40
    t = measurement_times(K, 0.1)
    theta = rng.uniform(-1, 1, R) + np.outer(t, rng.uniform(0.5, 3, R))
    z = (np.sin(theta) + 0.3 * rng.standard_normal((K, R)))[..., None]
    z[rng.random((K, R)) < 0.2] = np.nan
    sensor = tk.models.Sine(sigma=1.0, amplitude=False)
    h = SineFit(window=20)
    est = Gaussian(np.stack([theta[-5] + 0.1, np.full(R, 1.5)], -1), np.tile(np.eye(2), (R, 1, 1)))
    mem = _feed(h, sensor, t[:-5], z[:-5], batch=(R,))
    zb, _ = h.pseudo(mem, t[-5], True, sensor, est)
    for r in range(R):
        m1 = _feed(h, sensor, t[:-5], z[:-5, r:r + 1], batch=(1,))
        z1, _ = h.pseudo(m1, t[-5], True, sensor, est.at(slice(r, r + 1)))
        np.testing.assert_array_equal(z1[0], zb[r])


# ------------------------------------------------------------------------------------------
# Options and names


def test_make_handler_by_name():
    assert isinstance(make_handler("B0"), Coast)
    assert isinstance(make_handler("B1"), HoldLast)
    assert make_handler("B2", n=7).n == 7
    p = make_handler("P", degree=2, window=20)
    assert isinstance(p, PolynomialFit) and (p.degree, p.window, p.label) == (2, 20, "P")
    pp = make_handler("P'", degree=1, window=20, short_window=5)
    assert pp.short_window == 5 and pp.label == "P'"
    s = make_handler("P", function="sine", window=30)
    assert isinstance(s, SineFit) and s.window == 30
    assert set(HANDLER_NAMES) == {"B0", "B1", "B2", "P", "P'"}


@pytest.mark.parametrize("call, match", [
    (lambda: make_handler("B3"), "name = 'B3'"),
    (lambda: make_handler("B2", window=3), r"unknown option\(s\) \['window'\]"),
    (lambda: make_handler("P", function="spline"), "function = 'spline'"),
    (lambda: make_handler("P'", degree=1, window=10), "short_window is missing"),
    (lambda: make_handler("P", window=10, short_window=3), "short_window = 3"),
    (lambda: MeanOfLast(0), "MeanOfLast n = 0"),
    (lambda: MeanOfLast(2.5), "MeanOfLast n = 2.5"),
    (lambda: PolynomialFit(degree=-1), "degree = -1"),
    (lambda: PolynomialFit(degree=2, window=2), "window = 2"),
    (lambda: PolynomialFit(1, 10, short_window=10), "short_window = 10"),
    (lambda: PolynomialFit(2, 10, short_window=2), "short_window = 2"),
    (lambda: SineFit(phase=1, rate=1), r"\[1, 1\]"),
    (lambda: SineFit(window=1), "window = 1"),
    (lambda: SineFit(iterations=0), "iterations = 0"),
    (lambda: SineFit().init((), POS2), "measures 2 components"),
])
def test_bad_options_name_the_value(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# ------------------------------------------------------------------------------------------
# The runner


def _ca_problem(R=5, K=60, seed=3):
    """A 1-D nearly-constant-acceleration target, T = 0.1 s, position measured."""
    rng = np.random.default_rng(seed)
    motion = tk.models.ConstantAcceleration(dim=1, q=0.1)
    sensor = tk.models.Position(dim=1, sigma=0.5)
    x = np.tile([0.0, 5.0, 1.0], (R, 1))
    L = np.linalg.cholesky(motion.noise(None, 0.1))
    z = np.empty((K, R, 1))
    for k in range(K):
        x = motion.f(x, 0.1) + rng.standard_normal((R, 3)) @ L.T
        z[k] = x[:, :1] + 0.5 * rng.standard_normal((R, 1))
    prior = Gaussian(np.tile([0.0, 5.0, 1.0], (R, 1)), np.tile(np.diag([0.25, 1, 1]), (R, 1, 1)))
    return motion, sensor, prior, z


@pytest.mark.parametrize("handler", ["B0", "B1", "B2", "P"])
def test_runner_marks_the_pseudo_steps(handler):
    motion, sensor, prior, z = _ca_problem()
    K = z.shape[0]
    mask = mask_by_time(measurement_times(K, 0.1), 2.0, 3.0)
    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1, mask, handler)
    np.testing.assert_array_equal(run.missing, np.broadcast_to(mask[:, None], (K, 5)))
    if handler == "B0":
        assert not run.is_pseudo.any() and np.isnan(run.pseudo).all()
    else:
        np.testing.assert_array_equal(run.is_pseudo, run.missing)
        assert np.isfinite(run.pseudo[mask]).all() and np.isnan(run.pseudo[~mask]).all()
    assert run.estimate.mean.shape == (K, 5, 3) and run.estimate.cov.shape == (K, 5, 3, 3)
    assert run.maneuver is None


def test_runner_feeds_the_handlers_values_and_coasting_is_prediction():
    """B1's pseudo-measurements are the last real z; with B0 the gap is pure prediction."""
    motion, sensor, prior, z = _ca_problem()
    mask = mask_by_samples(z.shape[0], 20, 29)
    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1, mask, HoldLast())
    np.testing.assert_array_equal(run.pseudo[20:30], np.broadcast_to(z[19], (10, 5, 1)))
    f = tk.filters.KF()
    run0 = run_with_gaps(f, prior, motion, sensor, z, 0.1, mask, Coast())
    b = Gaussian(run0.estimate.mean[19], run0.estimate.cov[19])
    for k in range(20, 30):
        b = f.predict(b, motion, 0.1)
        np.testing.assert_array_equal(run0.estimate.mean[k], b.mean)
        np.testing.assert_array_equal(run0.estimate.cov[k], b.cov)


def test_runner_treats_nan_rows_as_missing_and_fills_them():
    motion, sensor, prior, z = _ca_problem()
    z = z.copy()
    z[10, 2] = np.nan  # a missed detection outside the mask
    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1,
                        np.zeros(z.shape[0], bool), "B1")
    assert run.missing.sum() == 1 and run.is_pseudo[10, 2]
    assert run.pseudo[10, 2, 0] == z[9, 2, 0]


def test_runner_fits_real_measurements_only():
    """A polynomial fit over the last 10 sees the real ones: at a second gap the fit
    spans the first gap, and its pseudo-measurements are not in the window."""
    motion, sensor, prior, z = _ca_problem(R=1, K=50)
    t = measurement_times(50, 0.1)
    truth = (1.0 + 2.0 * t - 0.4 * t**2)[:, None, None]
    mask = union(mask_by_samples(50, 20, 24), mask_by_samples(50, 28, 35))
    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, truth, 0.1,
                        mask, PolynomialFit(2, 10))
    np.testing.assert_allclose(run.pseudo[mask], truth[mask], rtol=REL)


@pytest.mark.parametrize("make", [tk.filters.EKF, tk.filters.UKF, tk.filters.CKF])
def test_runner_with_any_filter_on_a_linear_problem_equals_the_kf(make):
    """On linear models the EKF, UKF and CKF are the KF (1e-9 relative: the sigma-point
    filters reach the same numbers by another route)."""
    motion, sensor, prior, z = _ca_problem()
    mask = mask_by_samples(z.shape[0], 20, 34)
    ref = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1, mask, "P")
    run = run_with_gaps(make(), prior, motion, sensor, z, 0.1, mask, "P")
    np.testing.assert_allclose(run.estimate.mean, ref.estimate.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(run.pseudo, ref.pseudo, rtol=1e-9)


def test_runner_with_a_filter_that_keeps_its_own_belief():
    """AMCEKF's belief is its own NamedTuple; the runner gives f.estimate of it."""
    motion, sensor, prior, z = _ca_problem()
    mask = mask_by_samples(z.shape[0], 20, 34)
    f = tk.filters.AMCEKF()
    run = run_with_gaps(f, prior, motion, sensor, z, 0.1, mask, "B2")
    assert isinstance(run.belief, tk.filters.AdaptiveBelief)
    np.testing.assert_array_equal(run.estimate.mean[-1], f.estimate(run.belief).mean)
    assert np.isfinite(run.estimate.mean).all() and run.is_pseudo[20:35].all()


def test_runner_sine_fit_with_the_ekf():
    """S6's model: a noiseless sine fed to the EKF, SineFit over the gap reproduces it
    (1e-9 absolute: the fit is to the real, noiseless data)."""
    motion = tk.models.ConstantVelocity(dim=1, q=1e-4)
    sensor = tk.models.Sine(sigma=1.0, amplitude=False)
    t = measurement_times(80, 0.1)
    z = np.sin(0.2 + 1.3 * t)[:, None, None]
    prior = Gaussian(np.array([[0.2, 1.3]]), np.array([np.diag([0.01, 0.01])]))
    mask = mask_by_samples(80, 49, 69)
    run = run_with_gaps(tk.filters.EKF(), prior, motion, sensor, z, 0.1, mask, SineFit(40))
    assert run.is_pseudo.sum() == 21
    np.testing.assert_allclose(run.pseudo[mask], z[mask], atol=1e-9)


def test_runner_rows_equal_single_rows():
    """Each row of a batched run is the run of that row alone. The handlers' outputs are
    bitwise equal; the filter's batched kernels round differently with the batch size, so
    the estimates agree to 1e-12 relative."""
    motion, sensor, prior, z = _ca_problem(R=6, K=60)
    starts = np.array([10, 15, 20, 25, 12, 30])
    mask = union(mask_by_count(60, starts, 12), mask_by_count(60, 45, 3))
    for h in (HoldLast(), MeanOfLast(4), PolynomialFit(2, 15)):
        full = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1, mask, h)
        for r in range(6):
            one = run_with_gaps(tk.filters.KF(), prior.at(slice(r, r + 1)), motion,
                                sensor, z[:, r:r + 1], 0.1, mask[:, r:r + 1], h)
            np.testing.assert_array_equal(one.pseudo[:, 0], full.pseudo[:, r])
            np.testing.assert_array_equal(one.is_pseudo[:, 0], full.is_pseudo[:, r])
            np.testing.assert_allclose(one.estimate.mean[:, 0], full.estimate.mean[:, r],
                                       rtol=REL, atol=REL * np.abs(full.estimate.mean).max())


def test_runner_feeds_the_detector_real_innovations_only():
    """The detector's statistic is held through the gap (nan residuals), and P' with the
    detector on at the gap's start extrapolates from the short window.

    A CV target at 1 m/s turns to 6 m/s at t = 3 s (noiseless); the gap starts at 4 s.
    """
    motion = tk.models.ConstantVelocity(dim=1, q=0.01)
    sensor = tk.models.Position(dim=1, sigma=0.1)
    t = measurement_times(70, 0.1)
    pos = np.where(t <= 3.0, t, 3.0 + 6.0 * (t - 3.0))
    z = pos[:, None, None]
    prior = Gaussian(np.array([[0.0, 1.0]]), np.array([np.diag([0.01, 0.01])]))
    mask = mask_by_time(t, 4.0, 5.0)
    det = StandInDetector(threshold=20.0)
    seen = []

    class Spy(StandInDetector):
        def step(self, s, innov):
            seen.append(innov.nu.copy())
            return super().step(s, innov)

    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z,
                        0.1, mask, PolynomialFit(1, 30, short_window=5), Spy(threshold=20.0))
    res = np.array(seen)[:, 0, 0]
    assert np.isnan(res[mask]).all() and np.isfinite(res[~mask]).all()
    assert run.maneuver.shape == (70, 1) and run.maneuver[mask].all()  # on, and held
    np.testing.assert_allclose(run.pseudo[mask, 0, 0], pos[mask], rtol=REL)  # short window
    long = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, 0.1,
                         mask, PolynomialFit(1, 30), det)
    assert np.abs(long.pseudo[mask, 0, 0] - pos[mask]).max() > 1.0
    assert long.maneuver is not None


@pytest.mark.parametrize("call, match", [
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z[..., 0],
                                      0.1, np.zeros(60, bool), "B0"), r"z has shape \(60, 5\)"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.1, np.zeros(59, bool),
                                      "B0"), "mask has 59 time steps"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.1, np.zeros(60), "B0"),
     "dtype float64"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.1, np.zeros(60, bool),
                                      "B7"), "name = 'B7'"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.1, np.zeros(60, bool),
                                      3), "handler = 3"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.1, np.zeros(60, bool),
                                      PolynomialFit(1, 10, 3)), "detector=None"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z, 0.0, np.zeros(60, bool),
                                      "B0"), "dt = 0.0"),
    (lambda m, s, p, z: run_with_gaps(tk.filters.KF(), p, m, s, z,
                                      0.1, np.zeros((60, 4), bool), "B0"), "do not broadcast"),
])
def test_runner_bad_input_names_the_value(call, match):
    motion, sensor, prior, z = _ca_problem()
    with pytest.raises(ValueError, match=match):
        call(motion, sensor, prior, z)


def test_runner_refuses_the_old_argument_order():
    """(f, prior, z, mask, handler, motion, sensor, dt) is now run_filter's order."""
    motion, sensor, prior, z = _ca_problem()
    with pytest.raises(TypeError, match=r"expected \(f, prior, motion, sensor, z, dt, mask"):
        run_with_gaps(tk.filters.KF(), prior, z, np.zeros(60, bool), "B0", motion, sensor, 0.1)


@pytest.mark.parametrize("name", ["NISDetector", "FadingMemoryDetector", "WindowDetector"])
def test_runner_with_the_real_detectors(name):
    """trackkit.filters.maneuver's detectors drive P' as the stand-in does: on after the
    turn at 3 s, held through the gap, and the pseudo-measurements follow the new line."""
    maneuver = pytest.importorskip("trackkit.filters.maneuver")
    motion = tk.models.ConstantVelocity(dim=1, q=0.01)
    sensor = tk.models.Position(dim=1, sigma=0.1)
    t = measurement_times(70, 0.1)
    pos = np.where(t <= 3.0, t, 3.0 + 6.0 * (t - 3.0))
    prior = Gaussian(np.array([[0.0, 1.0]]), np.array([np.diag([0.01, 0.01])]))
    mask = mask_by_time(t, 4.0, 5.0)
    det = getattr(maneuver, name)(dim_z=1)
    run = run_with_gaps(tk.filters.KF(), prior, motion, sensor,
                        pos[:, None, None], 0.1, mask, PolynomialFit(1, 30, short_window=5), det)
    assert not run.maneuver[t < 3.0].any() and run.maneuver[mask].all()
    np.testing.assert_allclose(run.pseudo[mask, 0, 0], pos[mask], rtol=REL)
