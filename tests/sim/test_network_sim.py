"""Asynchronous bearings of a network of agents (trackkit.sim.sensor_network;
Jalalipoor and Kardehi Moghaddam 2021, eqs. 1-4, 9-12 and 17-18).

Statistical tests use fixed seeds (so they are deterministic) and each accepts at the 99%
level: a two-sided p-value above 0.01.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.distance import cdist

from trackkit.angles import wrap
from trackkit.models.motion import ConstantVelocity
from trackkit.sim.sensor_network import (
    bearings_at,
    cv_noise_factor,
    disk_graph,
    process_noise,
    schedule,
    simulate_network,
    straight_paths,
    target_truth,
)

DEG = math.pi / 180
ALPHA = 0.01
SIGMA = 2 * DEG

# three targets and three agents, all at speeds up to 30 m/s (invented: the paper's Table 1 is lost)
TARGETS = np.array([[0.0, 20e3, 10.0, -5.0], [5e3, 15e3, -20.0, 0.0], [-8e3, 18e3, 15.0, 10.0]])
AGENTS = np.array([[-10e3, 0.0, 20.0, 0.0], [0.0, 0.0, 0.0, 25.0], [10e3, 0.0, -20.0, 0.0]])


def run(seed: int = 7, runs: int = 20, **kw):
    args = dict(duration=600.0, period=2.0, sigma=SIGMA, mr=25e3)
    args.update(kw)
    return simulate_network(seed, runs, TARGETS, AGENTS, **args)


def test_noise_free_bearings_equal_the_geometry_exactly() -> None:
    rng = np.random.default_rng(1)
    S = rng.uniform(-5e3, 5e3, (4, 3, 2))
    X = np.concatenate([rng.uniform(-30e3, 30e3, (4, 3, 5, 2)), rng.normal(0, 10, (4, 3, 5, 2))],
                       -1)
    z, ok = bearings_at(S, X, None, SIGMA)
    dx, dy = X[..., 0] - S[..., None, 0], X[..., 1] - S[..., None, 1]
    assert ok.all()
    np.testing.assert_array_equal(z, np.arctan2(dx, dy))  # nautical, already in (-pi, pi]
    zm, _ = bearings_at(S, X, None, SIGMA, convention="math")
    np.testing.assert_array_equal(zm, np.arctan2(dy, dx))
    # due north, east, south and west of the sensor
    cross = np.array([[[0, 1e3, 0, 0], [1e3, 0, 0, 0], [0, -1e3, 0, 0], [-1e3, 0, 0, 0.0]]])
    z, _ = bearings_at(np.zeros((1, 2)), cross, None, SIGMA)
    np.testing.assert_allclose(z[0], [0.0, np.pi / 2, np.pi, -np.pi / 2], atol=1e-15)


def test_a_runs_bearings_are_the_geometry_plus_its_noise() -> None:
    """Every present bearing of a run is wrap(atan2(dx, dy) + sigma e), with e the schedule's
    noise, S on the straight line and T = x0 + t v (q = 0), to rounding."""
    seed, sig = 3, np.array([1.0, 2.0, 3.0]) * DEG
    out = run(seed, runs=4, sigma=sig, mr=np.inf)
    b = out.bearings
    sch = schedule(seed, 4, 3, 3, 600.0, 2.0)
    np.testing.assert_array_equal(b.time, sch.time)
    S = AGENTS[:, None, :2] + sch.time[..., None] * AGENTS[:, None, 2:]
    np.testing.assert_allclose(b.sensor, S, rtol=0, atol=1e-9)
    T = TARGETS[:, :2] + sch.time[..., None, None] * TARGETS[:, 2:]  # (R, A, E, Nt, 2)
    np.testing.assert_allclose(out.target_at_bearing[..., :2], T, rtol=0, atol=1e-8)
    h = np.arctan2(T[..., 0] - S[..., None, 0], T[..., 1] - S[..., None, 1])
    want = wrap(h + sig[:, None, None] * sch.noise)
    assert b.in_range.all() and b.n_out.sum() == 0
    err = np.abs(wrap(b.z - want))
    assert err.max() < 1e-12, err.max()
    np.testing.assert_array_equal(b.sigma, sig)


def test_bearing_noise_has_the_stated_sigma() -> None:
    """wrap(z - h(truth)) / sigma over 100 runs x 3 agents x 300 slots x 3 targets (270 000
    draws, none out of range): chi-square test of the variance, t-test of the mean and a KS
    test against N(0, 1), each at p > 0.01."""
    out = run(11, runs=100, mr=np.inf)
    b = out.bearings
    clean, _ = bearings_at(b.sensor, out.target_at_bearing, None, SIGMA)
    r = (wrap(b.z - clean) / SIGMA).ravel()
    n = r.size
    assert n == 100 * 3 * 300 * 3
    chi2 = float(np.sum(r**2))
    p_var = 2 * min(stats.chi2.cdf(chi2, n), stats.chi2.sf(chi2, n))
    assert p_var > ALPHA, (chi2 / n, p_var)
    assert abs(np.sqrt(chi2 / n) - 1) < 0.01  # measured: sigma_hat / sigma = 1.0014
    assert stats.ttest_1samp(r, 0.0).pvalue > ALPHA
    assert stats.kstest(r, "norm").pvalue > ALPHA


def test_out_of_range_bearings_are_absent_and_counted() -> None:
    mr = np.array([22e3, 18e3, 20e3])
    out = run(5, runs=10, duration=1000.0, mr=mr)
    b = out.bearings
    d = np.hypot(out.target_at_bearing[..., 0] - b.sensor[..., None, 0],
                 out.target_at_bearing[..., 1] - b.sensor[..., None, 1])
    beyond = d > mr[:, None, None]
    np.testing.assert_array_equal(b.in_range, ~beyond)
    np.testing.assert_array_equal(np.isnan(b.z), beyond)
    np.testing.assert_array_equal(b.n_out, beyond.sum(axis=2))
    E = b.time.shape[2]
    np.testing.assert_array_equal(b.in_range.sum(axis=2) + b.n_out, E)
    # the geometry really has both cases, for every agent
    assert 0 < b.n_out.sum() < b.z.size
    assert np.all(b.n_out.sum(axis=(0, 2)) > 0) and np.all(b.in_range.sum(axis=(0, 2, 3)) > 0)


def test_execution_times_are_sorted_with_the_documented_jitter() -> None:
    P, d_max = 2.0, 1.5
    sch = schedule(21, 50, 4, 2, 1000.0, P, max_delay=d_max)
    t = sch.time
    assert t.shape == (50, 4, 500) and sch.noise.shape == (50, 4, 500, 2)
    assert np.all(np.diff(t, axis=-1) > 0)
    d = t - P * np.arange(500)
    assert d.min() >= 0 and d.max() < d_max
    assert stats.kstest(d.ravel() / d_max, "uniform").pvalue > ALPHA  # d ~ U[0, d_max)
    gaps = np.diff(t, axis=-1)
    assert gaps.min() > P - d_max and gaps.max() < P + d_max
    # gap = P + d_{e+1} - d_e: mean P, variance 2 d_max^2 / 12 (100 000 gaps, 4.5 sigma)
    assert abs(gaps.mean() - P) < 4.5 * math.sqrt(d_max**2 / 6 / gaps.size)
    assert abs(gaps.var() / (d_max**2 / 6) - 1) < 0.03
    # agents are not synchronised, but d_max = 0 makes the network synchronous
    assert np.all(t[:, 0] != t[:, 1])
    sync = schedule(21, 2, 3, 1, 10.0, P, max_delay=0.0)
    np.testing.assert_array_equal(sync.time, np.broadcast_to(P * np.arange(5), (2, 3, 5)))


def test_disk_graph_is_symmetric_and_matches_pairwise_distances() -> None:
    rng = np.random.default_rng(2)
    pos = rng.uniform(-30e3, 30e3, (200, 6, 2))
    cr = np.array([25e3, 20e3, 30e3, 25e3, 10e3, np.inf])
    G = disk_graph(pos, cr)
    assert G.shape == (200, 6, 6) and G.dtype == bool
    np.testing.assert_array_equal(G, G.swapaxes(-1, -2))
    assert not G[:, np.arange(6), np.arange(6)].any()
    limit = np.minimum(cr[:, None], cr[None, :])
    for r in (0, 57, 199):
        d = cdist(pos[r], pos[r])
        np.testing.assert_array_equal(G[r], (d <= limit) & ~np.eye(6, dtype=bool))
    assert 0.2 < G.mean() < 0.8  # both links and gaps
    assert disk_graph(pos, np.inf)[:, ~np.eye(6, dtype=bool)].all()
    # a link at exactly CR is kept
    assert disk_graph(np.array([[0.0, 0.0], [3e3, 4e3]]), 5e3)[0, 1]


def test_same_seed_gives_the_same_bits() -> None:
    a, b = run(9, runs=6, q=0.05), run(9, runs=6, q=0.05)
    for x, y in zip(a, b, strict=True):
        if isinstance(x, tuple):
            for u, v in zip(x, y, strict=True):
                np.testing.assert_array_equal(u, v)
        else:
            np.testing.assert_array_equal(x, y)
    c = run(10, runs=6, q=0.05)
    assert not np.array_equal(a.bearings.time, c.bearings.time)


def test_a_runs_draws_depend_on_its_seed_alone() -> None:
    """A batch of 5 runs equals the 5 runs made one by one (first_run = r): the draws bit for
    bit, the arithmetic on them to rounding (DESIGN 5: a vectorised loop may round its body
    and its tail differently)."""
    seed, kw = 13, dict(q=0.05, duration=300.0)
    batch = run(seed, runs=5, **kw)
    sch = schedule(seed, 5, 3, 3, 300.0, 2.0)
    for r in range(5):
        one = simulate_network(seed, 1, TARGETS, AGENTS, duration=300.0, period=2.0,
                               sigma=SIGMA, mr=25e3, q=0.05, first_run=r)
        s1 = schedule(seed, 1, 3, 3, 300.0, 2.0, first_run=r)
        np.testing.assert_array_equal(s1.time[0], sch.time[r])
        np.testing.assert_array_equal(s1.noise[0], sch.noise[r])
        np.testing.assert_array_equal(one.bearings.time[0], batch.bearings.time[r])
        np.testing.assert_array_equal(one.bearings.in_range[0], batch.bearings.in_range[r])
        np.testing.assert_allclose(one.truth[0], batch.truth[r], rtol=1e-13, atol=1e-9)
        np.testing.assert_allclose(one.bearings.z[0], batch.bearings.z[r], rtol=0, atol=1e-13)
    w = process_noise(seed, 5, 40, 3)
    np.testing.assert_array_equal(process_noise(seed, 1, 40, 3, first_run=3)[0], w[3])
    # the purposes draw from separate streams: the delays do not move with the target count
    np.testing.assert_array_equal(schedule(seed, 5, 3, 1, 300.0, 2.0).time, sch.time)


def test_cv_noise_factor_is_a_factor_of_constant_velocitys_q() -> None:
    q = 0.3
    dt = np.array([0.0, 1e-6, 0.37, 2.0, 60.0])
    L = cv_noise_factor(q, dt)
    Q = ConstantVelocity(dim=2, q=q).noise(None, dt)
    np.testing.assert_allclose(L @ L.mT, Q, rtol=1e-12, atol=1e-300)
    assert np.all(np.triu(L, 1) == 0)


def test_process_noise_truth_has_constant_velocitys_covariance() -> None:
    """On an irregular grid (with a repeated time) the final state's deviation from the
    straight line has covariance Q(t_K - t_0): mean Mahalanobis square 4 within 3 sigma
    (4 000 runs, chi-square with 16 000 degrees of freedom). Measured: 4.007."""
    q, R = 0.5, 4000
    times = np.array([0.0, 0.3, 0.3, 1.1, 4.0, 4.5, 9.0])
    x0 = np.array([[100.0, -50.0, 3.0, -1.0]])
    w = process_noise(4, R, times.size - 1, 1)
    x = target_truth(x0, times, q, w)
    assert x.shape == (R, 7, 1, 4)
    np.testing.assert_array_equal(x[:, 1], x[:, 2])  # dt = 0 moves nothing
    cv = ConstantVelocity(dim=2, q=q)
    dev = x[:, -1, 0] - cv.f(x0[0], 9.0)
    m2 = np.einsum("ri,ij,rj->r", dev, np.linalg.inv(cv.noise(None, 9.0)), dev)
    assert abs(m2.mean() - 4) < 3 * math.sqrt(8 / R), m2.mean()
    # q = 0: the straight line itself
    x = target_truth(x0, times)
    want = np.concatenate([x0[0, :2] + times[:, None] * x0[0, 2:], np.tile(x0[0, 2:], (7, 1))],
                          -1)
    np.testing.assert_allclose(x[0, :, 0], want, rtol=1e-14, atol=1e-12)


def test_straight_paths() -> None:
    t = np.array([[0.0, 10.0], [5.0, 7.5]])
    S = straight_paths(AGENTS[:2], t)
    np.testing.assert_allclose(S, [[[-10e3, 0.0], [-9800.0, 0.0]], [[0.0, 125.0], [0.0, 187.5]]])


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(period=0.0), "period = 0.0"),
        (dict(max_delay=3.0), "max_delay = 3.0"),
        (dict(sigma=[1e-2, 1e-2]), r"sigma has shape \(2,\)"),
        (dict(sigma=-1.0), "sigma = "),
        (dict(mr=0.0), "mr = "),
        (dict(duration=1.0), "duration = 1.0 is shorter than period"),
        (dict(truth_dt=-1.0), "truth_dt = -1.0"),
    ],
)
def test_bad_input_names_the_field(kw, match) -> None:
    with pytest.raises(ValueError, match=match):
        run(1, runs=2, **kw)


def test_bad_shapes_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"targets has shape \(3, 5\)"):
        simulate_network(1, 2, np.zeros((3, 5)), AGENTS, duration=10.0, period=1.0, sigma=0.1)
    with pytest.raises(ValueError, match=r"agents has shape \(4, 3, 4\)"):
        simulate_network(1, 2, TARGETS, np.zeros((4, 3, 4)), duration=10.0, period=1.0,
                         sigma=0.1)
    with pytest.raises(ValueError, match="runs = 0"):
        schedule(1, 0, 3, 3, 10.0, 1.0)
    with pytest.raises(ValueError, match="times decrease"):
        target_truth(TARGETS, [0.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="noise is None but q > 0"):
        target_truth(TARGETS, [0.0, 1.0], q=0.1)
    with pytest.raises(ValueError, match=r"noise has shape \(2,\)"):
        bearings_at(np.zeros(2), TARGETS, np.zeros(2), SIGMA)
    with pytest.raises(ValueError, match=r"positions has shape \(3,\)"):
        disk_graph(np.zeros(3), 1.0)
