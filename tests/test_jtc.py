"""Joint tracking and classification (Hosseini, Haeri and Khaloozadeh 2019): the class models, the
mode chain, the single-filter JTC and the multi-filter baseline, against references written from the
formulas (loops over runs, classes and particles) and against what the paper states."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

import trackkit as tk
import trackkit.scenario as S
from trackkit.angles import wrap
from trackkit.experiments.montecarlo import run_scenario
from trackkit.filters.jtc import JTC, JTCBelief, MultiFilterBelief, MultiFilterJTC, next_modes
from trackkit.models import classes as cl
from trackkit.models.classes import (
    AIRLINER,
    FIGHTER,
    Mode,
    SpeedLikelihood,
    TargetClass,
    mode_step,
    paper_modes,
    transition_matrix,
)
from trackkit.report import write_report

RADAR = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=20.0,
                               sigma_bearing=math.radians(0.2))


# --------------------------------------------------------------------------------------------
# 1. The classes: speed likelihoods, modes, transition matrix
# --------------------------------------------------------------------------------------------


def test_speed_likelihoods_have_the_papers_values_at_200_mps():
    # the paper's speed likelihoods: g(c1)(200) = 0.8 - (0.7/200)(200 - 100) = 0.45 and, with the
    # sign fixed, g(c2)(200) = 0.1 + (0.85/500)(200 - 150) = 0.185
    assert AIRLINER.speed_likelihood(200.0) == pytest.approx(0.45, rel=1e-15, abs=0)
    assert FIGHTER.speed_likelihood(200.0) == pytest.approx(0.185, rel=1e-15, abs=0)


@pytest.mark.parametrize("v, g1, g2", [
    (0.0, 0.8, 0.1), (100.0, 0.8, 0.1), (150.0, 0.625, 0.1), (300.0, 0.1, 0.355),
    (400.0, 0.1, 0.525), (650.0, 0.1, 0.95), (1000.0, 0.1, 0.95),
])
def test_speed_likelihoods_follow_the_printed_branches(v, g1, g2):
    # the printed formulas at each branch (c2's middle branch with "+": continuous from 0.1
    # at 150 m/s to 0.95 at 650 m/s)
    assert AIRLINER.speed_likelihood(v) == pytest.approx(g1, rel=1e-14)
    assert FIGHTER.speed_likelihood(v) == pytest.approx(g2, rel=1e-14)


def test_speed_likelihood_is_continuous_at_its_knots():
    for k in (AIRLINER, FIGHTER):
        g = k.speed_likelihood
        for v in (g.v_low, g.v_high):
            assert abs(float(g(v + 1e-9)) - float(g(v - 1e-9))) < 1e-10


def test_transition_rows_sum_to_one_and_hold_the_papers_entries():
    P = transition_matrix()
    np.testing.assert_array_equal(np.diag(P), 0.6)
    assert np.all(P[~np.eye(5, dtype=bool)] == pytest.approx(0.1, rel=1e-15))
    np.testing.assert_allclose(P.sum(1), 1.0, rtol=0, atol=1e-15)
    for k in cl.PAPER_CLASSES:
        np.testing.assert_allclose(k.transition.sum(1), 1.0, rtol=0, atol=1e-15)
    Q = transition_matrix(4, 0.85)
    np.testing.assert_allclose(Q.sum(1), 1.0, rtol=0, atol=1e-15)
    assert Q[0, 1] == pytest.approx(0.05, rel=1e-14)


def test_the_paper_classes_have_five_modes_with_the_papers_numbers():
    assert [m.name for m in FIGHTER.modes] == ["CV", "CA+", "CA-", "CT+", "CT-"]
    np.testing.assert_array_equal(FIGHTER.accelerations, [0, 20, -20, 0, 0])
    np.testing.assert_array_equal(AIRLINER.accelerations, [0, 5, -5, 0, 0])
    np.testing.assert_allclose(FIGHTER.turn_rates, np.radians([0, 0, 0, 1, -1]), rtol=1e-15)
    np.testing.assert_allclose(AIRLINER.turn_rates, np.radians([0, 0, 0, 0.5, -0.5]),
                               rtol=1e-15)


@pytest.mark.parametrize("kwargs, words", [
    ({"transition": [[0.5, 0.4], [0.5, 0.5]]}, ["row 0 sums to", "expected rows summing to 1"]),
    ({"transition": np.eye(3)}, ["shape (3, 3)", "expected (2, 2)"]),
    ({"transition": [[1.5, -0.5], [0.5, 0.5]]}, ["outside [0, 1]"]),
    ({"modes": ()}, ["expected one or more Mode"]),
])
def test_a_bad_class_is_refused_with_the_field_named(kwargs, words):
    args = {"name": "c", "speed_likelihood": SpeedLikelihood(100, 0.5, 200, 0.5),
            "modes": (Mode("CV"), Mode("CT", turn_rate=0.1))} | kwargs
    with pytest.raises(ValueError) as err:
        TargetClass(**args)
    for w in words:
        assert w in str(err.value)


@pytest.mark.parametrize("kwargs, word", [
    ({"v_low": 300.0, "v_high": 100.0}, "v_low < v_high"),
    ({"g_low": 0.0}, "g_low = 0.0"),
    ({"g_high": math.nan}, "g_high = nan"),
])
def test_a_bad_speed_likelihood_is_refused(kwargs, word):
    args = {"v_low": 100.0, "g_low": 0.8, "v_high": 300.0, "g_high": 0.1} | kwargs
    with pytest.raises(ValueError, match=word):
        SpeedLikelihood(**args)


def test_a_turn_mode_is_the_standard_coordinated_turn():
    # our F(omega) is trackkit's KnownTurnRate transition (the standard CT matrix for
    # [x, y, vx, vy], counter-clockwise positive), which the paper prints with a sign lost
    rng = np.random.default_rng(4)
    x = rng.normal([1e4, -2e4, 250.0, -120.0], [1e3, 1e3, 50.0, 50.0], (50, 4))
    for omega in (math.radians(1.0), -math.radians(0.5), 0.3, 1e-7):
        want = tk.models.KnownTurnRate(omega=omega, q=0.0).f(x, 2.0)
        np.testing.assert_allclose(mode_step(x, omega, 0.0, 2.0), want, rtol=1e-12, atol=0)
    # a turn keeps the speed; the printed matrix (velocity block [[c, s], [s, c]]) does not
    wT = 0.3 * 2.0
    v = x[:, 2:]
    printed = v @ np.array([[math.cos(wT), math.sin(wT)], [math.sin(wT), math.cos(wT)]]).T
    ours = mode_step(x, 0.3, 0.0, 2.0)[:, 2:]
    np.testing.assert_allclose(np.hypot(*ours.T), np.hypot(*v.T), rtol=1e-13)
    assert np.max(np.abs(np.hypot(*printed.T) / np.hypot(*v.T) - 1)) > 0.1


def test_an_acceleration_mode_changes_the_speed_along_the_velocity():
    x = np.array([[0.0, 0.0, 300.0, 400.0], [10.0, 5.0, -30.0, 0.0]])
    out = mode_step(x, 0.0, 20.0, 2.0)
    speed0, speed1 = np.hypot(x[:, 2], x[:, 3]), np.hypot(out[:, 2], out[:, 3])
    np.testing.assert_allclose(speed1, speed0 + 40.0, rtol=1e-14)
    np.testing.assert_allclose(out[:, 2:] / speed1[:, None], x[:, 2:] / speed0[:, None],
                               rtol=1e-14)
    # x_{k+1} = F x + G a: position moves by v T + a T^2 / 2 along the velocity
    np.testing.assert_allclose(out[:, :2], x[:, :2] + 2.0 * x[:, 2:]
                               + 2.0 * 20.0 * x[:, 2:] / speed0[:, None], rtol=1e-14)
    # the paper's literal G u puts u on both axes
    axes = mode_step(x, 0.0, 20.0, 2.0, along="axes")
    np.testing.assert_allclose(axes[:, 2:], x[:, 2:] + 40.0, rtol=1e-14)
    with pytest.raises(ValueError, match="along = 'north'"):
        mode_step(x, 0.0, 20.0, 2.0, along="north")


# --------------------------------------------------------------------------------------------
# 2. The mode chain
# --------------------------------------------------------------------------------------------


def test_inverse_cdf_sampling_picks_the_interval_holding_u():
    cdf = np.cumsum(transition_matrix(), axis=1)  # row 0: 0.6, 0.7, 0.8, 0.9, 1.0
    u = np.array([0.0, 0.59, 0.61, 0.69, 0.71, 0.85, 0.95, 0.999])
    np.testing.assert_array_equal(next_modes(np.zeros(8, np.intp), cdf, u),
                                  [0, 0, 1, 1, 2, 3, 4, 4])
    # row 3: 0.1, 0.2, 0.3, 0.9, 1.0
    np.testing.assert_array_equal(next_modes(np.full(8, 3, np.intp), cdf, u),
                                  [0, 3, 3, 3, 3, 3, 4, 4])


def test_the_mode_switch_rate_is_0_4_per_step():
    """The particles of JTC.predict change mode at the rate 1 - 0.6 = 0.4 per step: 5 steps of
    100 x 10 000 particles, so the rate's standard error is sqrt(0.24 / 5e6) = 2.2e-4; the
    bound is 5 of them (two-sided confidence 1 - 6e-7). Each row's empirical transition
    frequencies match p_ij within 5 standard errors (25 cells: family confidence 1 - 1.5e-5).
    """
    f = JTC(particles_per_class=5000, sigma=0.0)
    b = f.init(tk.Gaussian(np.tile([1e4, 2e4, 200.0, 0.0], (100, 1)), np.eye(4)),
               rng=np.random.default_rng(13))
    counts = np.zeros((5, 5))
    for _ in range(5):
        before = b.modes
        b = f.predict(b, None, 1.0)
        np.add.at(counts, (before.ravel(), b.modes.ravel()), 1)
    n = counts.sum()
    rate = 1.0 - np.trace(counts) / n
    assert abs(rate - 0.4) < 5 * math.sqrt(0.24 / n)
    rows = counts.sum(1, keepdims=True)
    P = transition_matrix()
    assert np.all(np.abs(counts / rows - P) < 5 * np.sqrt(P * (1 - P) / rows))


# --------------------------------------------------------------------------------------------
# 3. The single filter against the formulas
# --------------------------------------------------------------------------------------------


def _prior(runs: int, x0=(2.0e4, 2.5e4, 300.0, 40.0), std=(100.0, 100.0, 30.0, 30.0)):
    return tk.Gaussian(np.tile(x0, (runs, 1)), np.tile(np.diag(np.square(std)), (runs, 1, 1)))


def _z(x, rng, sensor=RADAR):
    return sensor.h(np.asarray(x)) + rng.standard_normal(
        np.shape(x)[:-1] + (2,)) * [sensor.sigma_range, sensor.sigma_bearing]


def _reference(classes, states, labels, lp_prev, z, speed, recursion="bayes", speed_from=None):
    """One JTC update by the formulas, one run and one class at a time: the class posterior,
    the class means, the overall mean and covariance, the innovation mean and covariance."""
    Rinv = np.linalg.inv(RADAR.noise)
    B, C = len(states), len(classes)
    out = {k: [] for k in ("p", "class_mean", "mean", "cov", "nu", "S")}
    for b in range(B):
        X, lab = states[b], labels[b]
        N = len(X)
        d = X[:, :2]
        r = np.stack([z[b, 0] - np.hypot(d[:, 0], d[:, 1]),
                      wrap(z[b, 1] - np.arctan2(d[:, 0], d[:, 1]))], -1)
        lik = np.exp(-0.5 * np.einsum("ji,ik,jk->j", r, Rinv, r))
        v = np.hypot(X[:, 2], X[:, 3])
        p_prev = np.exp(lp_prev[b])
        L, means, ws = np.empty(C), np.empty((C, 4)), []
        nu = np.zeros(2)
        for c, k in enumerate(classes):
            j = lab == c
            g = (k.speed_likelihood(v[j]) if speed_from is None
                 else np.full(j.sum(), k.speed_likelihood(speed_from[b])))
            e = lik[j] * g
            L[c] = e.mean() * (j.sum() / N if recursion == "paper" else 1.0)
            w = e / e.sum()
            ws.append((j, w))
            means[c] = w @ X[j]
            nu += p_prev[c] * r[j].mean(0)
        p = p_prev * L / np.sum(p_prev * L)
        mean = p @ means
        cov = sum(p[c] * (w[:, None] * (X[j] - mean)).T @ (X[j] - mean)
                  for c, (j, w) in enumerate(ws))
        S = sum(p_prev[c] * ((r[lab == c] - nu).T @ (r[lab == c] - nu)) / (lab == c).sum()
                for c in range(C)) + RADAR.noise
        for key, val in zip(out, (p, means, mean, cov, nu, S), strict=True):
            out[key].append(val)
    return {k: np.array(v) for k, v in out.items()}


def _close_moments(post, innov, want):
    """Covariances to 1e-12 of their largest entry; the innovation's mean, a mean of residuals
    that cancel, to 1e-12 of the residuals' spread (sqrt(S_ii))."""
    np.testing.assert_allclose(post.cov, want["cov"], rtol=0,
                               atol=1e-12 * np.abs(want["cov"]).max())
    np.testing.assert_allclose(innov.cov, want["S"], rtol=1e-12)
    spread = np.sqrt(np.diagonal(want["S"], axis1=-2, axis2=-1))
    assert np.all(np.abs(innov.nu - want["nu"]) <= 1e-12 * spread)


@pytest.mark.parametrize("recursion", ["bayes", "paper"])
def test_an_update_matches_the_formulas(recursion):
    rng = np.random.default_rng(5)
    f = JTC(particles_per_class=300, floor=0.2, recursion=recursion, speed="particle")
    truth = np.array([2.0e4, 2.5e4, 300.0, 40.0])
    b = f.init(_prior(6), rng=np.random.default_rng(6))
    b = f.predict(b, None, 1.0)
    # uneven classes, as after a few allocations
    b, _ = f.update(b, _z(truth + [300, 40, 0, 0], rng)[None].repeat(6, 0), RADAR)
    b = f.predict(b, None, 1.0)
    z = _z(np.tile(truth + [600, 80, 0, 0], (6, 1)), rng)
    want = _reference(f.classes, b.states, b.labels, b.log_class_prob, z, None, recursion)
    post, innov = f.update(b, z, RADAR)
    assert not np.all(b.counts == 300)
    np.testing.assert_allclose(post.class_prob, want["p"], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(post.class_mean, want["class_mean"], rtol=1e-12)
    np.testing.assert_allclose(post.mean, want["mean"], rtol=1e-12)
    _close_moments(post, innov, want)
    np.testing.assert_allclose(f.estimate(post).mean, want["mean"], rtol=1e-12)


def test_an_update_with_the_estimates_speed_matches_the_formulas():
    rng = np.random.default_rng(7)
    f = JTC(particles_per_class=200, speed="estimate")
    b = f.predict(f.init(_prior(4), rng=np.random.default_rng(8)), None, 1.0)
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (4, 1)), rng)
    want = _reference(f.classes, b.states, b.labels, b.log_class_prob, z, None,
                      speed_from=b.speed)
    post, _ = f.update(b, z, RADAR)
    np.testing.assert_allclose(b.speed, math.hypot(300.0, 40.0), rtol=1e-15)
    np.testing.assert_allclose(post.class_prob, want["p"], rtol=1e-12)
    np.testing.assert_allclose(post.mean, want["mean"], rtol=1e-12)
    np.testing.assert_allclose(post.speed, np.hypot(post.mean[:, 2], post.mean[:, 3]),
                               rtol=1e-15)


def _twin_classes():
    """Two classes that differ in nothing but their names: no step tells them apart."""
    g = SpeedLikelihood(100.0, 0.5, 300.0, 0.5)
    modes = paper_modes(10.0, math.radians(1.0))
    return TargetClass("a", g, modes), TargetClass("b", g, modes)


def _belief_with(p, counts, rng, rows=1):
    """A JTC belief whose class 0 holds counts[0] particles, copies of class 1's set (counts
    = (k n, n)), so that both classes' mean likelihoods are equal exactly."""
    n = counts[1]
    base = rng.normal([2e4, 2.5e4, 200.0, 0.0], [50.0, 50.0, 10.0, 10.0], (n, 4))
    X = np.concatenate([np.tile(base, (counts[0] // n, 1)), base])[None].repeat(rows, 0)
    labels = np.repeat(np.arange(2, dtype=np.int8), counts)[None].repeat(rows, 0)
    return JTCBelief(*(X[..., i] for i in range(4)), labels, np.zeros_like(labels),
                     np.tile(counts, (rows, 1)), np.log(np.tile(p, (rows, 1))), rng,
                     np.full(rows, 200.0))


def test_the_papers_recursion_counts_the_prior_twice():
    """A step that cannot tell the classes apart (equal likelihoods) must leave p(c) alone.
    With 8 000 and 2 000 particles for p = (0.8, 0.2), Bayes' recursion does; Table 1's, whose
    summed weights already carry N_c / N = p(c), multiplies p in again:
    (0.8^2, 0.2^2) / (0.64 + 0.04) = (0.9412, 0.0588) (docs/jtc-comparison.md)."""
    rng = np.random.default_rng(9)
    z = _z(np.array([[2e4, 2.5e4, 200.0, 0.0]]), rng)
    for recursion, want in (("bayes", [0.8, 0.2]), ("paper", [0.64 / 0.68, 0.04 / 0.68])):
        f = JTC(_twin_classes(), particles_per_class=5000, recursion=recursion)
        b = _belief_with([0.8, 0.2], [8000, 2000], np.random.default_rng(10))
        post, _ = f.update(b, z, RADAR)
        np.testing.assert_allclose(post.class_prob[0], want, rtol=1e-12)


def test_allocation_keeps_the_floor_and_follows_the_posterior():
    """N_c = n_floor + Mult(N - s n_floor, p): with p = (0.3, 0.7) held by twin classes, 2 000
    rows of N = 200 (n_floor = 10): every count >= 10, the counts sum to 200, and the mean of
    N_1 is 10 + 180 x 0.3 = 64 within 5 standard errors (sqrt(180 x 0.21 / 2000) = 0.14;
    confidence 1 - 6e-7)."""
    rng = np.random.default_rng(11)
    f = JTC(_twin_classes(), particles_per_class=100, floor=0.1)
    b = _belief_with([0.3, 0.7], [100, 100], rng, rows=2000)
    z = _z(np.tile([2e4, 2.5e4, 200.0, 0.0], (2000, 1)), rng)
    post, _ = f.update(b, z, RADAR)
    np.testing.assert_allclose(post.class_prob, np.tile([0.3, 0.7], (2000, 1)), rtol=1e-12)
    counts = post.counts
    assert counts.min() >= 10 and np.all(counts.sum(1) == 200)
    assert abs(counts[:, 0].mean() - 64.0) < 5 * math.sqrt(180 * 0.21 / 2000)
    np.testing.assert_array_equal(np.sum(post.labels == 0, 1), counts[:, 0])
    assert np.all(np.diff(post.labels, axis=1) >= 0)  # still sorted by class


def test_resampling_keeps_each_particle_in_its_class_and_a_lost_class_at_its_floor():
    rng = np.random.default_rng(12)
    f = JTC(particles_per_class=500, floor=0.1)
    truth = np.array([2e4, 2.5e4, 340.0, 0.0])  # a fighter: P(airliner) collapses
    b = f.init(_prior(5, truth), rng=np.random.default_rng(1))
    for _ in range(15):
        b = f.predict(b, None, 1.0)
        truth = mode_step(truth, 0.0, 0.0, 1.0)
        before = b
        b, _ = f.update(b, _z(np.tile(truth, (5, 1)), rng), RADAR)
        for r in range(5):
            for c in range(2):
                old = before.x[r][before.labels[r] == c]
                assert np.all(np.isin(b.x[r][b.labels[r] == c], old))
    assert np.all(b.class_prob[:, 1] > 1 - 1e-6)
    np.testing.assert_array_equal(b.counts, np.tile([50, 950], (5, 1)))


def test_predict_moves_each_particle_by_its_new_mode():
    f = JTC(particles_per_class=400, sigma=0.0)
    b = f.init(_prior(3), rng=np.random.default_rng(3))
    p = f.predict(b, None, 2.0)
    omega = np.stack([k.turn_rates for k in f.classes])[p.labels, p.modes]
    u = np.stack([k.accelerations for k in f.classes])[p.labels, p.modes]
    want = mode_step(b.states, omega, u, 2.0)
    np.testing.assert_allclose(p.states, want, rtol=1e-12)
    np.testing.assert_array_equal(p.labels, b.labels)
    assert p.mean is None


def test_estimate_after_a_prediction_weighs_classes_by_their_probability():
    f = JTC(particles_per_class=300)
    b = f.init(_prior(2), rng=np.random.default_rng(2))
    b = b._replace(log_class_prob=np.log(np.array([[0.25, 0.75], [0.9, 0.1]])))
    g = f.estimate(b)
    X, lab, p = b.states, b.labels, b.class_prob
    for r in range(2):
        W = np.where(lab[r] == 0, p[r, 0], p[r, 1]) / 300
        m = W @ X[r]
        np.testing.assert_allclose(g.mean[r], m, rtol=1e-12)
        P = (W[:, None] * (X[r] - m)).T @ (X[r] - m)
        np.testing.assert_allclose(g.cov[r], P, rtol=0, atol=1e-12 * np.abs(P).max())
    np.testing.assert_allclose(f.class_estimates(b)[:, 1], X[:, 300:].mean(1), rtol=1e-12)


def test_a_missing_plot_keeps_the_prediction_of_its_row_only():
    rng = np.random.default_rng(14)
    f = JTC(particles_per_class=300)
    b = f.predict(f.init(_prior(3), rng=np.random.default_rng(15)), None, 1.0)
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (3, 1)), rng)
    z[1] = np.nan
    post, innov = f.update(b, z, RADAR)
    np.testing.assert_array_equal(post.x[1], b.x[1])
    np.testing.assert_array_equal(post.counts[1], b.counts[1])
    np.testing.assert_array_equal(post.log_class_prob[1], b.log_class_prob[1])
    assert np.isnan(innov.nu[1]).all() and np.isfinite(innov.nu[[0, 2]]).all()
    assert not np.array_equal(post.x[0], b.x[0])
    np.testing.assert_allclose(post.mean[1], f.estimate(b).mean[1], rtol=1e-12)


def test_the_same_generator_gives_the_same_run_bit_for_bit():
    def run(seed):
        f = JTC(particles_per_class=200)
        rng = np.random.default_rng(0)
        b = f.init(_prior(3), rng=np.random.default_rng(seed))
        for _ in range(3):
            b, _ = f.update(f.predict(b, None, 1.0),
                            _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (3, 1)), rng), RADAR)
        return b
    a, b, c = run(1), run(1), run(2)
    for x, y in zip(a[:5], b[:5], strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.x, c.x)


def test_batch_axes_lead_and_any_batch_shape_works():
    f = JTC(particles_per_class=50)
    prior = tk.Gaussian(np.tile([2e4, 2.5e4, 300.0, 40.0], (2, 3, 1)),
                        np.tile(np.diag([1e4, 1e4, 900.0, 900.0]), (2, 3, 1, 1)))
    b = f.predict(f.init(prior, rng=np.random.default_rng(0)), None, 1.0)
    assert b.x.shape == (2, 3, 100) and b.states.shape == (2, 3, 100, 4)
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (2, 3, 1)), np.random.default_rng(1))
    post, innov = f.update(b, z, RADAR)
    assert post.class_prob.shape == (2, 3, 2) and f.estimate(post).cov.shape == (2, 3, 4, 4)
    assert innov.nu.shape == (2, 3, 2) and innov.cov.shape == (2, 3, 2, 2)


def test_a_generic_sensor_gives_the_range_bearing_fast_paths_numbers():
    class Generic(tk.models.RangeBearing):  # the same model through h and residual
        pass

    rng = np.random.default_rng(16)
    f = JTC(particles_per_class=200)
    b = f.predict(f.init(_prior(3), rng=np.random.default_rng(17)), None, 1.0)
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (3, 1)), rng)
    slow = Generic(origin=[0.0, 0.0], sigma_range=20.0, sigma_bearing=math.radians(0.2))
    a, _ = f.update(b._replace(rng=np.random.default_rng(1)), z, RADAR)
    c, _ = f.update(b._replace(rng=np.random.default_rng(1)), z, slow)
    np.testing.assert_allclose(a.class_prob, c.class_prob, rtol=1e-12)
    np.testing.assert_allclose(a.mean, c.mean, rtol=1e-12)


# --------------------------------------------------------------------------------------------
# 4. The multi-filter baseline
# --------------------------------------------------------------------------------------------


def test_the_multi_filter_update_matches_the_formulas():
    rng = np.random.default_rng(18)
    f = MultiFilterJTC(particles_per_class=300, speed="particle")
    b = f.predict(f.init(_prior(4), rng=np.random.default_rng(19)), None, 1.0)
    b = b._replace(log_class_prob=np.log(np.tile([0.3, 0.7], (4, 1))))
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (4, 1)), rng)
    states = b.states.reshape(4, 600, 4)
    labels = np.repeat([0, 1], 300)[None].repeat(4, 0)
    want = _reference(f.classes, states, labels, b.log_class_prob, z, None)
    post, innov = f.update(b, z, RADAR)
    np.testing.assert_allclose(post.class_prob, want["p"], rtol=1e-12)
    np.testing.assert_allclose(post.class_mean, want["class_mean"], rtol=1e-12)
    np.testing.assert_allclose(post.mean, want["mean"], rtol=1e-12)
    _close_moments(post, innov, want)
    assert post.x.shape == (4, 2, 300)
    for c in range(2):  # each class filter resamples its own particles
        assert np.all(np.isin(post.x[:, c], b.x[:, c]))


def test_the_multi_filter_with_the_estimates_speed_matches_the_formulas():
    rng = np.random.default_rng(20)
    f = MultiFilterJTC(particles_per_class=200)
    assert f.speed == "estimate"
    b = f.predict(f.init(_prior(3), rng=np.random.default_rng(21)), None, 1.0)
    z = _z(np.tile([2.03e4, 2.504e4, 300.0, 40.0], (3, 1)), rng)
    labels = np.repeat([0, 1], 200)[None].repeat(3, 0)
    want = _reference(f.classes, b.states.reshape(3, 400, 4), labels, b.log_class_prob, z,
                      None, speed_from=b.speed)
    post, _ = f.update(b, z, RADAR)
    np.testing.assert_allclose(post.class_prob, want["p"], rtol=1e-12)
    np.testing.assert_allclose(post.mean, want["mean"], rtol=1e-12)


def test_the_multi_filter_belief_has_the_classes_on_their_own_axis():
    f = MultiFilterJTC(particles_per_class=100)
    b = f.init(_prior(3), rng=np.random.default_rng(0))
    assert isinstance(b, MultiFilterBelief)
    assert b.states.shape == (3, 2, 100, 4) and b.class_prob.shape == (3, 2)
    g = f.estimate(f.predict(b, None, 1.0))
    assert g.mean.shape == (3, 4)
    np.testing.assert_allclose(b.class_prob, 0.5, rtol=1e-15)


# --------------------------------------------------------------------------------------------
# 5. Bad input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, words", [
    ({"particles_per_class": 0}, ["particles_per_class = 0", "integer >= 1"]),
    ({"particles_per_class": 2.5}, ["particles_per_class = 2.5"]),
    ({"floor": 0.0}, ["floor = 0.0", "(0, 1]"]),
    ({"floor": 1e-5}, ["floor = 1e-05", "at least 1 particle"]),
    ({"sigma": -1.0}, ["sigma = -1.0", ">= 0 (m/s^2)"]),
    ({"diagonal": 1.5}, ["diagonal = 1.5", "probability"]),
    ({"recursion": "naive"}, ["recursion = 'naive'", "'bayes'"]),
    ({"speed": "mean"}, ["speed = 'mean'", "'particle'"]),
    ({"acceleration": "north"}, ["acceleration = 'north'", "'velocity'"]),
    ({"class_prior": [0.6, 0.6]}, ["class_prior = [0.6, 0.6]", "summing to 1"]),
    ({"classes": (AIRLINER, AIRLINER)}, ["repeat"]),
    ({"classes": (AIRLINER, TargetClass("x", FIGHTER.speed_likelihood, (Mode("CV"),)))},
     ["[1, 5] modes"]),
])
def test_bad_options_are_refused_naming_the_option(kwargs, words):
    with pytest.raises(ValueError) as err:
        JTC(**kwargs)
    for w in words:
        assert w in str(err.value)


def test_a_bad_prior_or_measurement_is_refused():
    f = JTC(particles_per_class=10)
    with pytest.raises(ValueError, match=r"prior.mean has shape \(2, 5\); expected \(..., 4\)"):
        f.init(tk.Gaussian(np.zeros((2, 5)), np.tile(np.eye(5), (2, 1, 1))))
    b = f.init(_prior(2), rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"JTC.update: z has shape \(2, 3\)"):
        f.update(b, np.zeros((2, 3)), RADAR)
    with pytest.raises(ValueError, match="dt"):
        f.predict(b, None, -1.0)
    with pytest.raises(ValueError, match="not positive semi-definite|cov"):
        f.init(tk.Gaussian(np.zeros(4), -np.eye(4)))


# --------------------------------------------------------------------------------------------
# 6. The scenario engine and the report
# --------------------------------------------------------------------------------------------


def _small(name: str, runs: int = 4, steps: int = 12, particles: int = 200):
    d = S.load(name).model_dump()
    d["run"].update(runs=runs, block=3)
    d["time"]["duration_s"] = float(steps)
    d["target"]["legs"] = []
    for f in d["filters"]:
        f["options"]["particles_per_class"] = particles
    return S.parse(d, name)


def test_the_engine_records_class_probabilities_and_the_report_shows_them(tmp_path):
    s = _small("jtc-fighter")
    r = run_scenario(s)
    assert r.classifiers() == ["JTC", "MultiFilter"]
    for name in r.classifiers():
        c = r.filters[name].classes
        assert c["names"] == ("airliner", "fighter") and c["true_class"] == "fighter"
        assert c["true"].shape == (4, 12) and c["final"].shape == (4, 2)
        np.testing.assert_allclose(c["mean"].sum(1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(c["mean"][:, 1], c["true"].mean(0), rtol=1e-12)
        np.testing.assert_allclose(c["final"][:, 1], c["true"][:, -1], rtol=0)
        summ = r.classification(name)
        assert summ["above"] == np.mean(c["final"][:, 1] > 0.9)
    paths = write_report(r, tmp_path)
    doc = json.loads((tmp_path / "results.json").read_text())
    block = doc["classification"]["filters"]["JTC"]
    assert block["true_class"] == "fighter" and block["classes"] == ["airliner", "fighter"]
    assert "classification" in doc["units"]
    assert "classes" in paths and (tmp_path / "classes.png").stat().st_size > 10_000
    table = pq.read_table(tmp_path / "metrics.parquet").to_pydict()
    rows = np.array(table["filter"]) == "JTC"
    np.testing.assert_allclose(np.array(table["class_prob_fighter"])[rows],
                               r.filters["JTC"].classes["mean"][:, 1], rtol=0)
    np.testing.assert_allclose(np.array(table["p_true_p10"])[rows],
                               r.true_class_percentiles("JTC")[0], rtol=0)
    html = (tmp_path / "report.html").read_text()
    assert "<h2>Classification</h2>" in html and "runs ending" in html


def test_the_engine_gives_the_same_numbers_for_the_same_seed():
    a, b = run_scenario(_small("jtc-airliner", runs=3, steps=5)), run_scenario(
        _small("jtc-airliner", runs=3, steps=5))
    assert a.to_json_dict()["classification"] == b.to_json_dict()["classification"]
    for n in a.filters:
        np.testing.assert_array_equal(a.filters[n].rmse["position"],
                                      b.filters[n].rmse["position"])


def test_a_scenario_without_classifiers_has_no_classification_block():
    d = S.load("cv-position").model_dump()
    d["run"].update(runs=3)
    r = run_scenario(S.parse(d, "cv-position"))
    assert r.classifiers() == [] and "classification" not in r.to_json_dict()


@pytest.mark.parametrize("change, words", [
    (lambda d: d["report"].update(true_class="bomber"), ["report.true_class", "bomber"]),
    (lambda d: (d["target"].update(extras=[1.0]), d["prior"].update(std=[1.0] * 5)),
     ["'JTC' (JTC)", "has 5 components", "expected dim = 2"]),
    (lambda d: d["filters"][0]["options"].update(floor=1e-9),
     ["filters.0.options", "floor = 1e-09"]),
    (lambda d: d["filters"][1]["options"].update(recursion="paper"),
     ["filters.1.options.recursion", "has no option recursion"]),
])
def test_a_bad_classification_scenario_is_refused_naming_the_field(change, words):
    d = S.load("jtc-fighter").model_dump()
    change(d)
    with pytest.raises(S.ScenarioError) as err:
        S.parse(d, "bad.toml")
    for w in words:
        assert w in str(err.value)
