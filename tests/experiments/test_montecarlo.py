"""The Monte Carlo engine: bound, consistency, determinism across executors, bad input."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import trackkit.eval.metrics as metrics_module
import trackkit.scenario as S
from trackkit.eval.crlb import pcrlb, rmse_bound
from trackkit.experiments.montecarlo import PROGRESS_STEPS, RunBudgetError, plan_of, run_scenario
from trackkit.scenario.simulate import simulate_block
from trackkit.sim.streams import run_rng


@pytest.fixture(scope="module")
def linear():
    return run_scenario(S.load("cv-position"))


def test_linear_pcrlb_equals_kf_covariance(linear):
    # The KF covariance does not depend on the data, so run 0's covariance is the KF's.
    P = linear.example.estimates["KF"][1]
    kf_pos = np.sqrt(P[:, 0, 0] + P[:, 1, 1])
    kf_vel = np.sqrt(P[:, 2, 2] + P[:, 3, 3])
    np.testing.assert_allclose(linear.pcrlb["position"], kf_pos, rtol=1e-9)
    np.testing.assert_allclose(linear.pcrlb["velocity"], kf_vel, rtol=1e-9)


def test_linear_kf_rmse_matches_bound_within_monte_carlo_error(linear):
    # Per step, runs * MSE / bound^2 is chi-square with runs * d degrees of freedom for an
    # efficient filter: relative sd of MSE/bound^2 is sqrt(2 / (runs d)). 4.5 sd per step over
    # 200 steps keeps the family-wise false alarm below 0.2% (Bonferroni).
    kf = linear.filters["KF"]
    for g, d in (("position", 2), ("velocity", 2)):
        ratio = kf.rmse[g] ** 2 / linear.pcrlb[g] ** 2
        sd = np.sqrt(2 / (linear.runs * d))
        assert np.all(np.abs(ratio - 1) < 4.5 * sd), (g, np.abs(ratio - 1).max() / sd)
    # the other filters are the same estimator on a linear problem
    for name in ("EKF", "UKF"):
        np.testing.assert_allclose(linear.filters[name].rmse["position"], kf.rmse["position"],
                                   rtol=1e-6)


def test_linear_kf_nees_inside_bounds_about_95_percent(linear):
    # 95% two-sided chi-square bounds per step; steps share runs, so the fraction is
    # correlated over time: accept 0.85-1.0 (a filter with Q 20x too small scores ~0.01).
    kf = linear.filters["KF"]
    assert 0.85 <= kf.nees_in_bounds <= 1.0
    assert abs(kf.anees - 4.0) < 0.2
    assert abs(kf.anis - 2.0) < 0.1
    assert kf.diverged == 0


def _small(name: str, runs: int, block: int):
    d = S.load(name).model_dump()
    d["run"].update(runs=runs, block=block)
    for f in d["filters"]:
        if f["type"] == "PF":  # the engine's checks, the PF's draws included, not its accuracy
            f.setdefault("options", {})["n_particles"] = 100
    return S.parse(d)


def _numbers(result):
    doc = result.to_json_dict()
    for f in doc["filters"].values():
        f.pop("seconds_per_step")  # wall time: the one number that may differ
    per_step = {name: (f.nees, f.nis, *f.rmse.values()) for name, f in result.filters.items()}
    return doc, per_step, result.pcrlb


def _same(a, b):
    assert a[0] == b[0]
    for name in a[1]:
        for x, y in zip(a[1][name], b[1][name], strict=True):
            np.testing.assert_array_equal(x, y)
    for g in a[2]:
        np.testing.assert_array_equal(a[2][g], b[2][g])


@pytest.mark.portability
def test_same_numbers_for_any_chunking():
    s = _small("bo-cv", runs=30, block=10)
    one = _numbers(run_scenario(s))
    _same(one, _numbers(run_scenario(s, chunk=30)))
    _same(one, _numbers(run_scenario(s, chunk=20)))


@pytest.mark.portability
def test_same_numbers_for_any_chunking_with_many_windows_of_steps(monkeypatch):
    # each filter's estimates reach the metrics a window of steps at a time; with windows of
    # 2 steps (a block of 10 runs, 25 run-steps) a block spans 180 windows, whose bounds
    # depend on the block alone: the chunking still changes no bit, and the windows only
    # move where a vectorised function rounds an element (the course's arctan2)
    s = _small("bo-cv", runs=20, block=10)
    default = _numbers(run_scenario(s))
    monkeypatch.setattr(metrics_module, "WINDOW_ROWS", 25)
    one = _numbers(run_scenario(s))
    _same(one, _numbers(run_scenario(s, chunk=20)))
    for name, f in one[0]["filters"].items():
        for key in ("anees", "anis"):
            assert f[key] == pytest.approx(default[0]["filters"][name][key], rel=1e-12)
        for g, v in f["rmse"].items():
            assert v == pytest.approx(default[0]["filters"][name]["rmse"][g], rel=1e-12)
        assert f["diverged"] == default[0]["filters"][name]["diverged"]


@pytest.mark.slow
@pytest.mark.portability
def test_same_numbers_on_a_local_dask_cluster():
    s = _small("bo-cv", runs=30, block=10)
    seen = []
    dask = run_scenario(s, workers=2, chunk=10, progress=lambda d, t: seen.append((d, t)))
    _same(_numbers(run_scenario(s)), _numbers(dask))
    assert seen[-1] == (30, 30)
    # the workers report inside their tasks too (events), and the count never goes back
    done = [d for d, _ in seen]
    assert done == sorted(done) and len(set(done)) > 3


@pytest.mark.portability
def test_runs_are_independent_of_their_block_neighbours():
    # run r draws from its own generator: its random draws do not depend on the block, bit
    # for bit. What is computed from them agrees to rounding: a vectorised transcendental
    # function (arctan2 for a bearing) may round an element differently in a SIMD loop's
    # body and its tail, so the bitwise guarantee is scoped to a fixed block (run.block).
    s = _small("bo-cv", runs=20, block=10)
    plan = plan_of(s)
    a = simulate_block(plan, 10, 20)
    b = simulate_block(plan, 5, 20)
    np.testing.assert_array_equal(a.prior_offset, b.prior_offset[5:])
    np.testing.assert_allclose(a.truth, b.truth[:, 5:], rtol=1e-12, atol=0)
    np.testing.assert_allclose(a.z, b.z[:, 5:], rtol=1e-12, atol=1e-15)


def test_run_generators_are_the_spawned_children_without_spawning_the_others():
    # run r's stream is child r of SeedSequence(seed), built from (seed, r) alone: a block of
    # a billion-run study costs what it costs in a ten-run one
    seed = 2026
    children = np.random.SeedSequence(seed).spawn(7)
    for r in (0, 3, 6):
        np.testing.assert_array_equal(run_rng(seed, r).standard_normal(5),
                                      np.random.default_rng(children[r]).standard_normal(5))
    big = run_rng(seed, 10**12).standard_normal(3)
    assert np.isfinite(big).all()
    assert not np.array_equal(run_rng(seed, 1).standard_normal(3),
                              run_rng(seed + 1, 1).standard_normal(3))


def test_engine_bound_matches_direct_pcrlb_on_the_same_truths():
    # bearings-only with no process noise: every run has the same truth, and the engine's
    # block-summed information must reproduce the direct recursion
    d = S.load("bo-cv").model_dump()
    d["run"].update(runs=12, block=5)
    d["target"]["motion"]["q"] = 0.0
    s = S.parse(d)
    result = run_scenario(s)
    plan = plan_of(s)
    truths = np.concatenate([simulate_block(plan, r, min(r + 5, 12)).truth
                             for r in range(0, 12, 5)], axis=1)
    B = pcrlb(plan.prior_cov, plan.truth_motion, plan.sensors, truths, plan.dt)
    np.testing.assert_allclose(result.pcrlb["position"], rmse_bound(B, [0, 1]), rtol=1e-9)
    np.testing.assert_allclose(result.pcrlb["velocity"], rmse_bound(B, [2, 3]), rtol=1e-9)


@pytest.mark.parametrize(
    "change, words",
    [
        (lambda d: d["target"]["motion"].update(model="Foo"), ["target.motion.model", "Foo"]),
        (lambda d: d["prior"].update(std=[1.0, 2.0, 3.0]), ["prior.std", "3", "4"]),
        (lambda d: d["observers"][0]["sensor"].update(sigma_deg=-1.0),
         ["observers.0.sensor.sigma_deg", "-1", "greater than 0"]),
        (lambda d: d["prior"].update(std=None, cov=np.diag([1.0, 1, -1, 1]).tolist()),
         ["prior", "positive definite"]),
        (lambda d: d["filters"][0].update(options={"alpha": 1.0}),
         ["filters.0", "alpha", "allowed"]),
        (lambda d: d["target"].update(speed=3), ["target.speed", "unknown field"]),
        (lambda d: d["time"].update(step_s=7.0), ["duration_s", "whole number"]),
    ],
)
def test_bad_scenarios_name_the_field(change, words):
    d = copy.deepcopy(S.load("bo-cv").model_dump())
    change(d)
    with pytest.raises(S.ScenarioError) as err:
        S.parse(d, "bad.toml")
    msg = str(err.value)
    assert msg.startswith("bad.toml")
    for w in words:
        assert w in msg, (w, msg)


def test_unknown_scenario_and_bad_runs():
    with pytest.raises(S.ScenarioError, match="no bundled scenario named 'nope'"):
        S.load("nope")
    with pytest.raises(ValueError, match="runs = 0"):
        run_scenario(S.load("cv-position"), runs=0)


def test_progress_moves_inside_a_block():
    # one block of 30 runs: the bar is told about every filter pass (and every
    # PROGRESS_STEPS steps of one), not only when the block is done
    s = _small("bo-cv", runs=30, block=30)
    seen = []
    run_scenario(s, progress=lambda done, total: seen.append((done, total)))
    done = [d for d, _ in seen]
    assert all(t == 30 for _, t in seen)
    assert done == sorted(done) and done[-1] == 30
    steps = plan_of(s).steps
    filters = len(s.filters)
    assert len(done) >= filters * (steps // PROGRESS_STEPS)
    assert 0 < done[0] < 30 / filters + 1e-9


def test_a_run_count_that_cannot_fit_is_refused_before_anything_runs():
    s = S.load("bo-cv")
    with pytest.raises(RunBudgetError) as err:
        run_scenario(s, runs=10**12)
    msg = str(err.value)
    assert "runs = 1000000000000" in msg and "GiB" in msg and "at most" in msg


def test_a_run_count_that_cannot_finish_in_time_is_refused_after_one_block():
    s = _small("bo-cv", runs=40, block=10)
    with pytest.raises(RunBudgetError, match=r"runs = 40 would take about .* allowed"):
        run_scenario(s, max_seconds=1e-6)
    # within the allowance the first block timed is part of the result, which is unchanged
    _same(_numbers(run_scenario(s)), _numbers(run_scenario(s, max_seconds=1e6)))
