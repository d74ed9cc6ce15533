"""Streamed Monte Carlo metrics: chunk merging (batch totals combined exactly), the window of
steps, RMSE, NEES/NIS consistency, missing measurements and the divergence rule."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

import trackkit as tk
import trackkit.eval.metrics as metrics_module
from trackkit.angles import wrap
from trackkit.eval import MonteCarloMetrics, chi2_bounds, merge_all
from trackkit.eval.metrics import _LIMBS, _exact_add, _exact_value, _quadratic

GROUPS = {"position": [0, 1], "velocity": [2, 3]}


def course_error(truth: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """A derived angle group: wrapped course error (nautical course atan2(vx, vy))."""
    c_true = np.arctan2(truth[:, 2], truth[:, 3])
    c_hat = np.arctan2(mean[:, 2], mean[:, 3])
    return wrap(c_true - c_hat)[:, None]


def run_kf(runs: int, steps: int, seed: int, q_filter_factor: float = 1.0,
           p_missing: float = 0.0):
    """A CV target with position measurements filtered by a KF, batched over runs.

    Returns per step the truths, the filtered Gaussians and the innovations (lists)."""
    rng = np.random.default_rng(seed)
    dt, q = 1.0, 0.2
    motion = tk.models.ConstantVelocity(dim=2, q=q)
    model = tk.models.ConstantVelocity(dim=2, q=q * q_filter_factor)
    sensor = tk.models.Position(dim=2, sigma=3.0)
    m0, P0 = np.array([0.0, 0.0, 2.0, 1.0]), np.diag([50.0, 50.0, 4.0, 4.0])
    x = m0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    LQ = np.linalg.cholesky(motion.noise(x, dt))
    b = tk.Gaussian(np.tile(m0, (runs, 1)), np.tile(P0, (runs, 1, 1)))
    f = tk.filters.KF()
    truths, ests, innovs = [], [], []
    for _ in range(steps):
        x = motion.f(x, dt) + rng.standard_normal((runs, 4)) @ LQ.T
        z = x[:, :2] + 3.0 * rng.standard_normal((runs, 2))
        if p_missing:
            z[rng.random(runs) < p_missing] = np.nan
        b = f.predict(b, model, dt)
        b, innov = f.update(b, z, sensor)
        truths.append(x)
        ests.append(b)
        innovs.append(innov)
    return truths, ests, innovs


def accumulate(truths, ests, innovs, rows=slice(None), **kwargs) -> MonteCarloMetrics:
    acc = MonteCarloMetrics(groups=kwargs.pop("groups", GROUPS), **kwargs)
    for k, (x, b, i) in enumerate(zip(truths, ests, innovs, strict=True)):
        acc.add(k, x[rows], b.at(rows), tk.Innovation(i.nu[rows], i.cov[rows]))
    return acc


# -- (a) exact merging -------------------------------------------------------------------------


def _position_independent(truths, ests, innovs):
    """The same data with every per-run term computed once for the whole batch.

    Vectorised kernels may round one run's terms differently in another batch (a batched
    Cholesky that takes over above a batch-size threshold, SIMD arctan2 bodies and tails);
    keeping runs in fixed blocks is the engine's answer. Here the accumulator alone is under
    test, so its inputs are made such that each run's terms are the same bits in any batch:
    diagonal covariances (their Cholesky factor and solve are exact elementwise operations)
    and the course error precomputed as a fifth state component with a zero estimate.
    """
    out_t, out_e, out_i = [], [], []
    for x, b, i in zip(truths, ests, innovs, strict=True):
        R = x.shape[0]
        course = course_error(x, b.mean)  # once, for the whole batch
        out_t.append(np.concatenate([x, course], axis=1))
        cov = np.zeros((R, 5, 5))
        cov[:, np.arange(4), np.arange(4)] = np.diagonal(b.cov, axis1=1, axis2=2)
        cov[:, 4, 4] = 1.0
        out_e.append(tk.Gaussian(np.concatenate([b.mean, np.zeros((R, 1))], axis=1), cov))
        S = np.zeros_like(i.cov)
        S[:, [0, 1], [0, 1]] = np.diagonal(i.cov, axis1=1, axis2=2)
        out_i.append(tk.Innovation(i.nu, S))
    return out_t, out_e, out_i


@pytest.mark.portability
def test_merged_chunks_are_the_same_bits_in_any_order_and_combine_batch_totals_exactly():
    # the accumulator alone: the same per-run terms, in the same chunks, give the same bits in
    # any merge order and grouping (on any CPU: the terms are position-independent); each
    # chunk contributes its float64 batch total per step, combined exactly
    data = _position_independent(*run_kf(runs=300, steps=40, seed=11, p_missing=0.2))
    kw = {"groups": {**GROUPS, "course": [4]}, "nees_indices": (0, 1, 2, 3)}
    whole = accumulate(*data, **kw)
    cuts = [(0, 97), (97, 130), (130, 300)]
    chunks = [accumulate(*data, rows=slice(a, b), **kw) for a, b in cuts]
    merged_orders = [
        merge_all(chunks),
        chunks[2].merge(chunks[0]).merge(chunks[1]),
        chunks[0].merge(chunks[1].merge(chunks[2])),
    ]
    first = merged_orders[0]
    for merged in merged_orders:
        assert merged.runs == whole.runs == 300
        assert merged.n_steps == whole.n_steps == 40
        for name in whole.names:
            np.testing.assert_array_equal(merged.total(name), first.total(name))  # bitwise
            np.testing.assert_array_equal(merged.count(name), whole.count(name))
            # other batches, other float64 batch totals: equal to rounding
            np.testing.assert_allclose(merged.total(name), whole.total(name), rtol=1e-14)
        assert merged.summary(start=5) == first.summary(start=5)
    # chunks in the natural order also keep the per-run divergence counters in run order
    np.testing.assert_array_equal(first.diverged(), whole.diverged())
    np.testing.assert_array_equal(first.run_bad, whole.run_bad)

    # each step's sum is the correctly rounded exact sum (math.fsum) of the chunks' float64
    # totals, each np.sum of that chunk's vector of per-run terms
    truths, ests, _ = data
    for k in (0, 17, 39):
        e = truths[k] - ests[k].mean
        pos, course = (e[:, :2] ** 2).sum(-1), e[:, 4] ** 2
        assert whole.total("position")[k] == np.sum(pos)
        assert first.total("position")[k] == math.fsum(np.sum(pos[a:b]) for a, b in cuts)
        assert first.total("course")[k] == math.fsum(np.sum(course[a:b]) for a, b in cuts)


@pytest.mark.parametrize("window", [1, 7, 300, 10**5])
def test_the_window_of_steps_does_not_change_a_bit(monkeypatch, window):
    # add() evaluates a window of steps at a time; every per-run term is elementwise, so
    # the window (one step, a few, every step at once) changes no bit of any result
    data = run_kf(runs=60, steps=30, seed=17, p_missing=0.2)
    groups = {**GROUPS, "course": course_error}
    ref = accumulate(*data, groups=groups)
    monkeypatch.setattr(metrics_module, "WINDOW_ROWS", window)
    acc = accumulate(*data, groups=groups)
    for name in ref.names:
        np.testing.assert_array_equal(acc.total(name), ref.total(name))
        np.testing.assert_array_equal(acc.count(name), ref.count(name))
    assert acc.summary(start=3) == ref.summary(start=3)
    np.testing.assert_array_equal(acc.diverged(), ref.diverged())


@pytest.mark.parametrize("m", [1, 2, 3, 4, 6])
def test_quadratic_forms_are_position_independent_and_correct(m):
    # each row's r^T S^-1 r is the same bits alone or in any batch, and agrees with a solve
    rng = np.random.default_rng(m)
    A = rng.standard_normal((50, m, m))
    S = A @ A.mT + 0.1 * np.eye(m)
    r = rng.standard_normal((50, m))
    q, ok = _quadratic(S, r)
    assert ok.all()
    for i in (0, 13, 49):
        qi, _ = _quadratic(S[i : i + 1], r[i : i + 1])
        assert qi[0] == q[i]
    np.testing.assert_allclose(q, np.einsum("ri,ri->r", r, np.linalg.solve(S, r[..., None])[
        ..., 0]), rtol=1e-10)
    S[7] = -np.eye(m)  # not positive definite: flagged, the others unchanged
    q2, ok2 = _quadratic(S, r)
    assert not ok2[7] and ok2.sum() == 49
    np.testing.assert_array_equal(q2[ok2], q[ok2])


def test_merge_of_different_lengths_and_configurations():
    data = run_kf(runs=20, steps=10, seed=12)
    short = accumulate(*(d[:6] for d in data), rows=slice(0, 10))
    long = accumulate(*data, rows=slice(10, 20))
    m = short.merge(long)
    assert m.n_steps == 10 and m.runs == 20
    np.testing.assert_array_equal(m.count("position"), [20] * 6 + [10] * 4)
    with pytest.raises(ValueError, match="configurations"):
        short.merge(MonteCarloMetrics(groups={"position": [0, 1]}))
    with pytest.raises(ValueError, match="runs"):
        x, b, _ = (d[0] for d in data)
        short.add(0, x, b)  # 20 runs into an accumulator of 10


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(min_value=0.0, max_value=1e300, allow_subnormal=True), min_size=1,
             max_size=60),
    st.lists(st.integers(0, 60), max_size=4),
)
def test_exact_sum_is_chunk_invariant_and_correctly_rounded(values, cuts):
    v = np.array(values)
    one = np.zeros((1, _LIMBS), np.int64)
    _exact_add(one, np.zeros(v.size, np.intp), v)
    parts = np.zeros((1, _LIMBS), np.int64)
    for chunk in np.split(v, sorted(c for c in cuts if c <= v.size)):
        part = np.zeros((1, _LIMBS), np.int64)
        _exact_add(part, np.zeros(chunk.size, np.intp), chunk)
        parts += part
    assert _exact_value(one)[0] == _exact_value(parts)[0] == math.fsum(values)


# -- (b) RMSE ----------------------------------------------------------------------------------


def test_rmse_per_step_and_time_average_match_direct_computation():
    truths, ests, innovs = run_kf(runs=200, steps=30, seed=13)
    acc = accumulate(truths, ests, innovs, groups={**GROUPS, "course": course_error})
    err = np.stack(truths) - np.stack([b.mean for b in ests])  # (T, R, n), test only
    for name, idx in GROUPS.items():
        mse = (err[..., idx] ** 2).sum(-1).mean(-1)
        np.testing.assert_allclose(acc.rmse(name), np.sqrt(mse), rtol=1e-14)
        np.testing.assert_allclose(acc.rmse_time_average(name, start=10),
                                   np.sqrt(mse[10:].mean()), rtol=1e-14)
        assert acc.summary(start=10)[f"rmse_{name}"] == acc.rmse_time_average(name, 10)
    course = np.stack([course_error(x, b.mean)[:, 0] for x, b in zip(truths, ests,
                                                                      strict=True)])
    np.testing.assert_allclose(acc.rmse("course"), np.sqrt((course**2).mean(-1)), rtol=1e-14)
    nees = np.einsum("tri,trij,trj->tr", err, np.linalg.inv(np.stack([b.cov for b in ests])),
                     err)
    np.testing.assert_allclose(acc.nees(), nees.mean(-1), rtol=1e-10)


def test_angular_state_components_are_wrapped():
    acc = MonteCarloMetrics(groups={"phase": [0]}, angular=[True, False])
    truth = np.array([[np.pi - 0.1, 0.0]])
    est = tk.Gaussian(np.array([[-np.pi + 0.1, 0.0]]), np.eye(2)[None])
    acc.add(0, truth, est)
    np.testing.assert_allclose(acc.rmse("phase"), [0.2])  # not 2 pi - 0.2


# -- (c) NEES / NIS consistency ----------------------------------------------------------------


def test_kf_nees_and_nis_are_consistent_about_95_percent_inside():
    """A KF on its own linear-Gaussian model is consistent: at each step N times the average
    NEES of N = 500 independent runs is chi2(4 N), so the average lies inside its two-sided
    95 % bounds with probability 0.95 per step. The 200 steps are not independent (the same
    runs carry over), so the fraction inside varies more than a binomial(200, 0.95) would
    (sd 0.015); 0.85 leaves a wide margin against chance while a clearly inconsistent
    filter (below) fails it."""
    acc = accumulate(*run_kf(runs=500, steps=200, seed=14))
    s = acc.summary()
    assert 0.85 <= s["nees_inside"] <= 1.0
    assert 0.85 <= s["nis_inside"] <= 1.0
    assert abs(s["nees_mean"] - 4.0) < 0.2 and abs(s["nis_mean"] - 2.0) < 0.1
    assert s["diverged"] == 0.0 and s["runs"] == 500.0 and s["steps"] == 200.0
    assert all(isinstance(v, float) for v in s.values())
    lo, hi = acc.bounds("nees")
    np.testing.assert_allclose([lo[0], hi[0]], [chi2.ppf(0.025, 2000) / 500,
                                                chi2.ppf(0.975, 2000) / 500], rtol=1e-12)

    # power: a filter whose Q is 20 times too small is overconfident and fails the check
    bad = accumulate(*run_kf(runs=500, steps=200, seed=14, q_filter_factor=0.05))
    assert bad.summary()["nees_inside"] < 0.2


def test_chi2_bounds():
    lo, hi = chi2_bounds([1, 10, 0], [3, 30, 0])
    np.testing.assert_allclose([lo[0], hi[1]], [chi2.ppf(0.025, 3), chi2.ppf(0.975, 30) / 10],
                               rtol=1e-12)
    assert np.isnan(lo[2]) and np.isnan(hi[2])
    with pytest.raises(ValueError, match="confidence"):
        chi2_bounds(1, 2, confidence=1.5)


# -- (d) NIS with missing measurements ---------------------------------------------------------


def test_nis_skips_missing_measurements():
    truths, ests, innovs = run_kf(runs=400, steps=25, seed=15, p_missing=0.3)
    acc = accumulate(truths, ests, innovs)
    counts = acc.count("nis")
    for k, i in enumerate(innovs):
        present = ~np.isnan(i.nu).any(-1)
        assert 0 < present.sum() < 400  # the scenario really has missing rows
        assert counts[k] == present.sum()
        r, S = i.nu[present], i.cov[present]
        nis = np.einsum("ri,rij,rj->r", r, np.linalg.inv(S), r)
        np.testing.assert_allclose(acc.nis()[k], nis.mean(), rtol=1e-12)
        lo, hi = acc.bounds("nis")
        n_k = present.sum()
        np.testing.assert_allclose([lo[k], hi[k]],
                                   [chi2.ppf(0.025, 2 * n_k) / n_k,
                                    chi2.ppf(0.975, 2 * n_k) / n_k])
    # NEES still counts every run (the estimate exists even without a measurement)
    np.testing.assert_array_equal(acc.count("nees"), 400)
    # a step where every measurement is missing has no NIS (nan), and is not "inside"
    only = MonteCarloMetrics(groups=GROUPS)
    only.add_innovation(0, tk.Innovation(np.full((3, 2), np.nan), np.tile(np.eye(2), (3, 1, 1))))
    assert np.isnan(only.nis()[0]) and np.isnan(only.summary()["nis_inside"])


# -- (e) divergence ----------------------------------------------------------------------------


def test_divergence_rule_flags_diverged_runs_only():
    """Runs: 0 good; 1 lost at the end; 2 lost for 40 % of the steps, then recovered; 3 one
    bad step in the middle; 4 non-finite estimate at one step; 5 far off in position but with
    a covariance that admits it (flagged only by the distance rule)."""
    rng = np.random.default_rng(16)
    T, R = 50, 6
    P = np.tile(np.diag([4.0, 4.0, 1.0, 1.0]), (R, 1, 1))
    P[5] *= 1e6
    acc = MonteCarloMetrics(groups=GROUPS)
    acc_dist = MonteCarloMetrics(groups=GROUPS, distance=500.0)
    for k in range(T):
        truth = rng.normal(0.0, 100.0, (R, 4))
        e = rng.standard_normal((R, 4)) * np.sqrt(np.diagonal(P, axis1=1, axis2=2))
        if k >= T - 5:
            e[1, :2] += 1e4
        if 10 <= k < 30:
            e[2, :2] += 1e4
        if k == 25:
            e[3, :2] += 1e4
        e[5, :2] = 1000.0
        mean = truth - e
        if k == 20:
            mean[4, 0] = np.nan
        for a in (acc, acc_dist):
            a.add(k, truth, tk.Gaussian._make((mean, P)))  # a filter's own nan
    np.testing.assert_array_equal(acc.diverged(), [False, True, True, False, False, False])
    np.testing.assert_array_equal(acc_dist.diverged(), [False, True, True, False, False, True])
    assert acc.summary()["diverged"] == 2.0 and acc_dist.summary()["diverged"] == 3.0
    # the non-finite run is counted as invalid at that step and left out of the sums
    assert acc.invalid[20] == 1 and acc.count("position")[20] == R - 1
    assert acc.run_bad[4] == 1  # one bad step: not diverged
    # the default threshold is 100 x the chi2(4) 1 - 1e-6 quantile
    thr = 100 * chi2.ppf(1 - 1e-6, 4)
    assert 3000 < thr < 3500


def test_input_checks():
    with pytest.raises(ValueError, match="distance_group"):
        MonteCarloMetrics(groups=GROUPS, distance=10.0, distance_group="pos")
    with pytest.raises(ValueError, match="'nees'"):
        MonteCarloMetrics(groups={"nees": [0]})
    acc = MonteCarloMetrics(groups=GROUPS)
    with pytest.raises(ValueError, match="shape"):
        acc.add(0, np.zeros((3, 4)), tk.Gaussian(np.zeros((3, 2)), np.eye(2)))
    with pytest.raises(ValueError, match="k = -1"):
        acc.add(-1, np.zeros((3, 4)), tk.Gaussian(np.zeros((3, 4)), np.eye(4)))
    with pytest.raises(KeyError, match="speed"):
        acc.rmse("speed")


def test_chi2_ppf_is_scipy_stats_chi2_ppf_bit_for_bit():
    # the goodness-of-fit and gate thresholds use it in place of scipy.stats (whose call
    # costs about 100 us): the same quantiles, not merely close ones
    q = np.array([1e-6, 0.01, 0.05, 0.5, 0.95, 0.99, 0.999, 1 - 1e-6])[:, None]
    dof = np.arange(1, 41)[None, :]
    np.testing.assert_array_equal(metrics_module.chi2_ppf(q, dof), chi2.ppf(q, dof))
    assert metrics_module.chi2_ppf(0.999, 9) == chi2.ppf(0.999, 9)
