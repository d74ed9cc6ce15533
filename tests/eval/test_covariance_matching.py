"""Naseri Solhdar's matching metrics (trackkit.eval.covariance_matching): J1-J4 per run,
the run-0 logs of R, S, C and DOM, and the R a filter uses (``noise_in_use``).

Expectations are running sums written out in Python loops over hand-fed sequences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.belief import Gaussian, Innovation
from trackkit.eval.covariance_matching import MatchingMetrics, measurement_noise_rms, noise_in_use
from trackkit.experiments.compare import compare
from trackkit.filters import KF, FuzzyAdaptive
from trackkit.filters.adaptive import AdaptiveBelief, SageHusaBelief
from trackkit.filters.fuzzy import DEFAULT_PARAMS
from trackkit.models import Bearing, LinearMotion, Position

# --------------------------------------------------------------------------------------------
# MatchingMetrics on a hand-fed sequence
# --------------------------------------------------------------------------------------------


def _sequence(K: int, B: int, n: int, m: int, seed: int):
    rng = np.random.default_rng(seed)
    truth = rng.normal(0, 5, (K, B, n))
    mean = truth + rng.normal(0, [1.0, 2.0, 0.5][:n], (K, B, n))
    resid = rng.normal(0, [1.0, 3.0][:m], (K, B, m))
    A = rng.normal(size=(K, B, m, m))
    Scov = A @ np.swapaxes(A, -1, -2) + np.eye(m)
    R = np.abs(rng.normal(1.0, 0.3, (K, B, m)))
    return truth, mean, resid, Scov, R


def test_matching_metrics_equal_manual_running_sums_and_logs():
    K, B, n, m, N, alpha = 9, 2, 3, 2, 3, 1000.0
    truth, mean, resid, Scov, Rd = _sequence(K, B, n, m, seed=1)
    resid[[3, 6], 1] = np.nan  # run 1 misses two measurements
    sensor = Position(dim=2, sigma=1.0)
    mm = MatchingMetrics(B, n, m, K, window=N, log=True)
    for k in range(K):
        R = np.stack([np.diag(Rd[k, i]) for i in range(B)])
        mm.add(k, truth[k], mean[k], Innovation(resid[k], Scov[k]), R, sensor)
    out = mm.per_run(alpha)
    assert out["J2"].shape == (B, m) and out["J3"].shape == (B, n) and out["J4"].shape == (B,)

    for i in range(B):
        kept, j2, j3, d2, steps = [], [0.0] * m, [0.0] * n, [0.0] * m, 0
        for k in range(K):
            r = resid[k, i]
            if np.isnan(r).any():
                continue
            kept.append(r)
            steps += 1
            if len(kept) >= N:
                C = sum(np.outer(v, v) for v in kept[-N:]) / N
            else:
                C = np.zeros((m, m))
            for a in range(m):
                dom = Scov[k, i, a, a] - C[a, a]
                d2[a] += dom * dom
                e = truth[k, i, a] - mean[k, i, a]  # h = first two components
                j2[a] += e * e
            for a in range(n):
                j3[a] += (truth[k, i, a] - mean[k, i, a]) ** 2
            if i == 0:  # run 0 log
                np.testing.assert_allclose(mm.logs["C"][k], np.diag(C), rtol=1e-13, atol=1e-15)
                np.testing.assert_allclose(mm.logs["DOM"][k], np.diag(Scov[k, 0]) - np.diag(C),
                                           rtol=1e-13, atol=1e-13)
                np.testing.assert_array_equal(mm.logs["S"][k], np.diag(Scov[k, 0]))
                np.testing.assert_array_equal(mm.logs["R"][k], Rd[k, 0])
        assert steps == (K if i == 0 else K - 2)
        np.testing.assert_allclose(out["J2"][i], [math.sqrt(v / steps) for v in j2], rtol=1e-13)
        np.testing.assert_allclose(out["J3"][i], [math.sqrt(v / steps) for v in j3], rtol=1e-13)
        J4 = alpha * sum(math.sqrt(v / steps) for v in d2)
        assert out["J4"][i] == pytest.approx(J4, rel=1e-13)
    # the logs start full of nan and hold run 0 only
    assert set(mm.logs) == {"R", "S", "C", "DOM"}
    assert all(v.shape == (K, m) for v in mm.logs.values())
    np.testing.assert_array_equal(mm.logs["C"][:N - 1], 0.0)
    assert np.all(mm.logs["C"][N - 1:] > 0)


def test_matching_metrics_shared_s_and_r_broadcast_and_no_logs_by_default():
    K, B, n, m = 4, 3, 3, 2
    truth, mean, resid, Scov, _ = _sequence(K, B, n, m, seed=2)
    sensor = Position(dim=2, sigma=1.0)
    shared = MatchingMetrics(B, n, m, K, window=2)
    per_row = MatchingMetrics(B, n, m, K, window=2)
    for k in range(K):
        R = np.diag([1.0, 2.0])
        shared.add(k, truth[k], mean[k], Innovation(resid[k], Scov[k, 0]), R, sensor)
        per_row.add(k, truth[k], mean[k],
                    Innovation(resid[k], np.broadcast_to(Scov[k, 0], (B, m, m))),
                    np.broadcast_to(R, (B, m, m)), sensor)
    assert shared.logs is None
    a, b = shared.per_run(5000.0), per_row.per_run(5000.0)
    for key in ("J2", "J3", "J4"):
        np.testing.assert_array_equal(a[key], b[key])


def test_j2_wraps_angle_channels():
    # a bearing estimate on the other side of the +-pi cut is 0.1 rad off, not 2 pi - 0.1
    sensor = Bearing((0.0, 0.0), sigma=0.01, convention="math")
    th_t, th_e = math.pi - 0.05, -math.pi + 0.05
    truth = np.array([[100 * math.cos(th_t), 100 * math.sin(th_t), 0.0, 0.0]])
    mean = np.array([[100 * math.cos(th_e), 100 * math.sin(th_e), 0.0, 0.0]])
    mm = MatchingMetrics(1, 4, 1, 1, window=1)
    mm.add(0, truth, mean, Innovation(np.array([[0.0]]), np.array([[1.0]])), np.eye(1), sensor)
    assert mm.per_run(1.0)["J2"][0, 0] == pytest.approx(0.1, rel=1e-9)


# --------------------------------------------------------------------------------------------
# J1
# --------------------------------------------------------------------------------------------


def test_j1_of_simulated_noise_is_sigma_within_sampling_error():
    # T x B x m Gaussian draws with sd sigma: J1^2 T / sigma^2 is chi-square(T), so J1 / sigma
    # has sd ~ 1 / sqrt(2 T) = 0.0112 for T = 4000; accept 4.5 sd (5 %).
    T, B = 4000, 3
    sigma = np.array([0.5, 3.0])
    rng = np.random.default_rng(17)
    z_true = rng.uniform(-100, 100, (T, B, 2))
    z = z_true + rng.standard_normal((T, B, 2)) * sigma
    J1 = measurement_noise_rms(z, z_true, Position(dim=2, sigma=sigma))
    assert J1.shape == (B, 2)
    assert np.all(np.abs(J1 / sigma - 1) < 4.5 / math.sqrt(2 * T)), J1 / sigma


def test_j1_leaves_out_missing_steps_and_wraps_angles():
    z_true = np.array([[[1.0]], [[2.0]], [[3.0]], [[3.1]]])  # (T, B = 1, m = 1)
    z = np.array([[[1.5]], [[np.nan]], [[2.0]], [[-3.1]]])
    # errors 0.5, (missing), -1.0 and wrap(3.1 - (-3.1)) = 6.2 - 2 pi
    e = [0.5, 1.0, 6.2 - 2 * math.pi]
    expected = math.sqrt(sum(v * v for v in e) / 3)
    J1 = measurement_noise_rms(z, z_true, Bearing((0.0, 0.0), sigma=0.1))
    assert J1.shape == (1, 1)
    assert J1[0, 0] == pytest.approx(expected, rel=1e-12)


# --------------------------------------------------------------------------------------------
# noise_in_use
# --------------------------------------------------------------------------------------------


def test_noise_in_use_for_each_kind_of_belief():
    R0 = np.diag([4.0, 0.25])
    # a plain Gaussian: the R the filter was given
    g = Gaussian(np.zeros((2, 3)), np.broadcast_to(np.eye(3), (2, 3, 3)))
    assert noise_in_use(g, R0) is R0
    # a fuzzy belief before its first update: R0; after: its own R
    F = np.eye(3)
    f = FuzzyAdaptive(KF(), warmup="adapt")
    b = f.init(g)
    np.testing.assert_array_equal(noise_in_use(b, R0), R0)
    b, _ = f.update(f.predict(b, LinearMotion(F, 0.1 * np.eye(3)), 1.0),
                    np.array([[1.0, 2.0], [0.0, -1.0]]), Position(dim=2, sigma=[2.0, 0.5]))
    assert not np.allclose(b.R, R0)
    np.testing.assert_array_equal(noise_in_use(b, R0), b.R)
    # an AMCEKF belief: r_scale R0 per row
    ab = AdaptiveBelief(g.mean, g.cov, np.array([0.5, 3.0]), np.ones(2), np.zeros((2, 5, 2)),
                        np.zeros(2, np.int64))
    np.testing.assert_array_equal(noise_in_use(ab, R0), np.stack([0.5 * R0, 3.0 * R0]))
    # a Sage-Husa belief: its R once started, R0 before
    Rsh = np.stack([np.diag([1.0, 2.0]), np.diag([3.0, 4.0])])
    sh = SageHusaBelief(g.mean, g.cov, Rsh, np.zeros((2, 0, 0)), np.zeros(2, np.int64))
    np.testing.assert_array_equal(noise_in_use(sh, R0), Rsh)
    sh0 = sh._replace(R=np.zeros((2, 0, 0)))
    np.testing.assert_array_equal(noise_in_use(sh0, R0), R0)


# --------------------------------------------------------------------------------------------
# Through the Monte Carlo engine: run 0's numbers from its example track
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_ch3():
    d = S.load("uw-ch3-r").model_dump()
    d["time"]["duration_s"] = 60.0
    by_name = {f["name"]: f for f in d["filters"]}
    d["filters"] = [by_name["KF"], dict(by_name["OFKF"], tune=None,
                                        options={"params": list(DEFAULT_PARAMS)})]
    d["run"].update(runs=3, block=2)
    return compare(S.parse(d))


def test_engine_matching_numbers_of_run_0_from_its_example(small_ch3):
    res = small_ch3
    ex = res.example
    T = res.steps
    H = np.eye(2, 3)
    z_true = ex.truth @ H.T
    # J1: raw noise of run 0
    np.testing.assert_allclose(res.j1[0], np.sqrt(np.mean((ex.measurements - z_true) ** 2, 0)),
                               rtol=1e-12)
    assert res.j1.shape == (3, 2)
    for name in ("KF", "OFKF"):
        mean = ex.estimates[name][0]
        mt = res.filters[name].matching
        assert mt["J2"].shape == (3, 2) and mt["J3"].shape == (3, 3) and mt["J4"].shape == (3,)
        np.testing.assert_allclose(mt["J3"][0], np.sqrt(np.mean((ex.truth - mean) ** 2, 0)),
                                   rtol=1e-12)
        np.testing.assert_allclose(mt["J2"][0],
                                   np.sqrt(np.mean((z_true - mean @ H.T) ** 2, 0)), rtol=1e-12)
        logs = ex.logs[name]
        J4 = res.dom_alpha * np.sqrt(np.mean(logs["DOM"] ** 2, 0)).sum()
        assert mt["J4"][0] == pytest.approx(J4, rel=1e-12)
        np.testing.assert_allclose(logs["DOM"], logs["S"] - logs["C"], rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(logs["C"][:24], 0.0)
        assert np.all(logs["C"][24:] > 0)
        assert all(v.shape == (T, 2) for v in logs.values())
    # the plain KF keeps its R0 = diag(8, 1); the fuzzy one too until its window is full,
    # then moves (R0 = diag(8, 1) against the true diag(0.8, 9))
    np.testing.assert_array_equal(ex.logs["KF"]["R"], np.broadcast_to([8.0, 1.0], (T, 2)))
    R = ex.logs["OFKF"]["R"]
    np.testing.assert_array_equal(R[:25], np.broadcast_to([8.0, 1.0], (25, 2)))
    assert np.all(R[25] != [8.0, 1.0])  # adapted at the 25th update, used from the 26th
    assert R[-1, 0] < 8.0 and R[-1, 1] > 1.0
    assert res.dom_alpha == 1000.0
