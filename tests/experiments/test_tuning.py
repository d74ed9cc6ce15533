"""Off-line tuning of the fuzzy-adaptive filters (trackkit.experiments.tuning): the batched DOM cost
against one candidate at a time, the optimiser statistics, writing the tuned system into the
scenario, the per-process cache and ``tune.on``.

Cheap settings throughout: Naseri Solhdar's chapter-3 benchmark cut to 100 steps, 2 optimiser runs
of 3 iterations with populations of 10.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.belief import Gaussian
from trackkit.experiments.compare import compare
from trackkit.experiments.montecarlo import plan_of, run_scenario, with_run
from trackkit.experiments.tuning import TuningResult, dom_costs, tune_filter, tune_scenario
from trackkit.filters import KF, FuzzyAdaptive
from trackkit.filters.fuzzy import DEFAULT_PARAMS, N_PARAMS, PARAM_BOUNDS
from trackkit.models import LinearMotion, Position
from trackkit.scenario.simulate import simulate_block

F3 = np.array([[0.77, 0.20, 0.0], [0.22, 0.72, 0.22], [0.02, 0.0, 0.72]])
OFKF = 3  # index of the ICA-tuned filter in uw-ch3-r and uw-ch3-q


def cheap(name: str = "uw-ch3-r", duration: float = 100.0, **tune) -> dict:
    """The scenario shortened, with brief tuning and its filters KF, GAFKF, PSOFKF, OFKF
    (the UKF, equal to the KF there, is left out so the indices above hold)."""
    d = S.load(name).model_dump()
    d["filters"] = [f for f in d["filters"] if f["name"] != "UKF"]
    d["time"]["duration_s"] = duration
    for f in d["filters"]:
        if f["tune"]:
            f["tune"].update(runs=2, iterations=3, population=10, **tune)
    return d


@pytest.fixture(scope="module")
def ch3r():
    return S.parse(cheap())


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are TOML basic-string escapes
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()
                               if x is not None) + "}"
    raise TypeError(type(v))


def write_toml(path, data: dict):
    """A scenario dict as TOML (inline tables only; None fields left out)."""
    path.write_text("\n".join(f"{k} = {_toml_value(v)}" for k, v in data.items()
                              if v is not None) + "\n")
    return path


def _cost_alone(params, z, x0, P0, motion, sensor, alpha, **kw) -> float:
    """One candidate on one realisation, written out: alpha sum_i RMS_k DOM_k(i,i)."""
    f = FuzzyAdaptive(KF(), params, **kw)
    b = f.init(Gaussian(x0, P0))
    sq = np.zeros(z.shape[-1])
    for k in range(len(z)):
        b = f.predict(b, motion, 1.0)
        b, _ = f.update(b, z[k], sensor)
        sq += np.diagonal(b.S - b.C) ** 2
    return alpha * sum(math.sqrt(v / len(z)) for v in sq)


# --------------------------------------------------------------------------------------------
# The batched cost
# --------------------------------------------------------------------------------------------


def test_dom_costs_of_a_population_equal_each_candidate_alone_r(ch3r):
    plan = plan_of(ch3r)
    K, P = 2, 4
    data = simulate_block(plan_of(with_run(ch3r, K, 77)), 0, K)
    x0 = np.zeros((K, 3))
    rng = np.random.default_rng(0)
    params = rng.uniform(PARAM_BOUNDS[:, 0], PARAM_BOUNDS[:, 1], (P, N_PARAMS))
    costs = dom_costs(plan.filters[OFKF], params, plan, OFKF, data.z, x0, 1000.0)
    assert costs.shape == (P, K)
    # the scenario's filter built by hand: F, Q = 0.02 I, R0 = diag(8, 1), P0 = 0.01 I
    motion = LinearMotion(F3, 0.02 * np.eye(3))
    sensor = Position(dim=2, sigma=[math.sqrt(8.0), 1.0])
    for p in range(P):
        for k in range(K):
            c = _cost_alone(params[p], data.z[:, k], x0[k], 0.01 * np.eye(3), motion, sensor,
                            1000.0)
            assert costs[p, k] == pytest.approx(c, rel=1e-10)
    assert len(np.unique(costs.round(6))) == P * K  # distinct candidates, distinct costs


def test_dom_costs_of_a_population_equal_each_candidate_alone_q():
    s = S.parse(cheap("uw-ch3-q", duration=60.0))
    plan = plan_of(s)
    K, P = 2, 3
    data = simulate_block(plan_of(with_run(s, K, 5)), 0, K)
    x0 = np.zeros((K, 3))
    params = np.random.default_rng(1).uniform(PARAM_BOUNDS[:, 0], PARAM_BOUNDS[:, 1],
                                              (P, N_PARAMS))
    costs = dom_costs(plan.filters[OFKF], params, plan, OFKF, data.z, x0, 1000.0)
    motion = LinearMotion(F3, np.diag([10.0, 0.2, 12.0]))  # the filters' Q0
    sensor = Position(dim=2, sigma=[math.sqrt(0.8), 3.0])  # R known
    for p in range(P):
        for k in range(K):
            c = _cost_alone(params[p], data.z[:, k], x0[k], 0.01 * np.eye(3), motion, sensor,
                            1000.0, adapt="Q", q_inputs=((0, 0), (1, 1), (0, 1)))
            assert costs[p, k] == pytest.approx(c, rel=1e-10)


def test_dom_costs_with_missed_detections_use_the_steps_with_a_measurement(ch3r):
    plan = plan_of(ch3r)
    data = simulate_block(plan_of(with_run(ch3r, 1, 5)), 0, 1)
    z = data.z.copy()
    z[40:60] = np.nan  # 20 of the 100 scans missing
    cost = dom_costs(plan.filters[OFKF], np.array(DEFAULT_PARAMS)[None], plan, OFKF, z,
                     np.zeros((1, 3)), 1000.0)[0, 0]
    f = FuzzyAdaptive(KF(), DEFAULT_PARAMS)
    b = f.init(Gaussian(np.zeros(3), 0.01 * np.eye(3)))
    motion = LinearMotion(F3, 0.02 * np.eye(3))
    sensor = Position(dim=2, sigma=[math.sqrt(8.0), 1.0])
    sq, kept = np.zeros(2), 0
    for k in range(len(z)):
        b, _ = f.update(f.predict(b, motion, 1.0), z[k, 0], sensor)
        if not np.isnan(z[k, 0]).any():
            sq += np.diagonal(b.S - b.C) ** 2
            kept += 1
    assert kept == 80
    assert cost == pytest.approx(1000.0 * sum(math.sqrt(v / kept) for v in sq), rel=1e-10)


# --------------------------------------------------------------------------------------------
# The tuning result
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("index, optimizer", [(1, "GA"), (2, "PSO"), (3, "ICA")])
def test_tuning_result_statistics_history_and_bounds(ch3r, index, optimizer):
    res = tune_filter(ch3r, index)
    assert isinstance(res, TuningResult)
    t = ch3r.filters[index].tune
    assert (res.optimizer, res.runs, res.population, res.iterations) == (optimizer, 2, 10, 3)
    assert res.costs.shape == (2,)
    assert res.best == np.min(res.costs) and res.worst == np.max(res.costs)
    assert res.mean == pytest.approx(np.mean(res.costs), rel=1e-15)
    assert res.best <= res.mean <= res.worst
    assert res.history.shape == (t.iterations + 1, t.runs)
    assert np.all(np.diff(res.history, axis=0) <= 0)
    np.testing.assert_array_equal(res.history[-1], res.costs)
    assert res.params.shape == (N_PARAMS,)
    assert np.all((PARAM_BOUNDS[:, 0] <= res.params) & (res.params <= PARAM_BOUNDS[:, 1]))
    # the chosen params really score `best` on the tuning data (one realisation from
    # tune.seed, prior mean 0), filtered by hand
    data = simulate_block(plan_of(with_run(ch3r, t.realisations, t.seed)), 0, t.realisations)
    c = _cost_alone(res.params, data.z[:, 0], np.zeros(3), 0.01 * np.eye(3),
                    LinearMotion(F3, 0.02 * np.eye(3)),
                    Position(dim=2, sigma=[math.sqrt(8.0), 1.0]), 1000.0)
    assert c == pytest.approx(res.best, rel=1e-10)
    summary = res.summary()
    assert summary["best"] == res.best and summary["params"] == res.params.tolist()


def test_tune_scenario_writes_the_params_and_removes_tune(ch3r):
    s2, results = tune_scenario(ch3r)
    assert set(results) == {"GAFKF", "PSOFKF", "OFKF"}
    assert s2.filters[0] == ch3r.filters[0]  # the plain KF is untouched
    for i, spec in enumerate(s2.filters[1:], start=1):
        assert spec.tune is None
        assert spec.options["params"] == [float(v) for v in results[spec.name].params]
        assert results[spec.name] is tune_filter(ch3r, i)
        assert spec.r0_diag_si == [8.0, 1.0]
    # the tuned scenario compiles with those systems
    plan = plan_of(s2)
    np.testing.assert_array_equal(plan.filters[3].params, results["OFKF"].params)
    # nothing to tune: the same scenario back
    s3, none = tune_scenario(s2)
    assert s3 is s2 and none == {}
    with pytest.raises(ValueError, match="no tune block"):
        tune_filter(s2, 3)


def test_tuning_is_cached_whatever_the_run_section(ch3r):
    a = tune_filter(ch3r, OFKF)
    assert tune_filter(ch3r, OFKF) is a
    d = ch3r.model_dump()
    d["run"].update(runs=7, seed=99, block=3)
    assert tune_filter(S.parse(d), OFKF) is a
    # the tuning data's seed is part of the key
    other = tune_filter(S.parse(cheap(seed=3099)), OFKF)
    assert other is not a and not np.array_equal(other.params, a.params)


def test_compare_tunes_first_and_reports_the_tuning(ch3r):
    d = ch3r.model_dump()
    d["run"].update(runs=2, block=2)
    with pytest.raises(ValueError, match="not tuned yet"):
        run_scenario(S.parse(d))
    seen = []
    res = compare(S.parse(d), tuning_progress=lambda done, total: seen.append((done, total)))
    # cached tunings report their generations at once; the count still adds up
    assert seen[-1][0] == seen[-1][1] > 0 and all(a <= b for a, b in seen)
    assert set(res.tuning) == {"GAFKF", "PSOFKF", "OFKF"}
    assert res.tuning["OFKF"] is tune_filter(ch3r, OFKF)
    assert set(res.filters) == {"KF", "GAFKF", "PSOFKF", "OFKF"}
    assert res.filters["OFKF"].matching["J4"].shape == (2,)


# --------------------------------------------------------------------------------------------
# tune.on
# --------------------------------------------------------------------------------------------


def test_tune_on_reuses_the_named_scenarios_tuning(ch3r, tmp_path):
    source = write_toml(tmp_path / "source.toml", ch3r.model_dump())
    assert S.load(source) == ch3r  # the TOML round trip is exact
    d = cheap(duration=50.0)  # a different scenario that borrows the tuning
    d["filters"] = [d["filters"][0], dict(d["filters"][3], tune={"on": str(source)})]
    target = S.parse(d)
    res = tune_filter(target, 1)  # index 1 here, index 3 in the source
    assert res is tune_filter(S.load(source), OFKF)
    np.testing.assert_array_equal(res.params, tune_filter(ch3r, OFKF).params)
    s2, results = tune_scenario(target)
    assert s2.filters[1].options["params"] == [float(v) for v in res.params]
    assert s2.time.duration_s == 50.0


def test_tune_on_errors(ch3r, tmp_path):
    def borrowing(on: str):
        d = cheap()
        d["filters"] = [dict(d["filters"][3], tune={"on": on})]
        return S.parse(d)

    # a scenario without a filter of that name
    with pytest.raises(ValueError, match=r"tune.on = 'cv-position' has no filter of that name"):
        tune_filter(borrowing("cv-position"), 0)
    # a same-named filter that is not tuned there
    d = ch3r.model_dump()
    d["filters"][3].update(tune=None, options={"params": [0.0] * 5 + [1.0] * 5 + [0.0] * 5})
    fixed = write_toml(tmp_path / "fixed.toml", d)
    with pytest.raises(ValueError, match="has no filter of that name with a tune block"):
        tune_filter(borrowing(str(fixed)), 0)
    # a source that borrows again
    d = ch3r.model_dump()
    d["filters"][3]["tune"] = {"on": "uw-ch3-r"}
    chained = write_toml(tmp_path / "chained.toml", d)
    with pytest.raises(ValueError, match="refers on again"):
        tune_filter(borrowing(str(chained)), 0)
    # no such scenario
    with pytest.raises(S.ScenarioError, match="no bundled scenario"):
        tune_filter(borrowing("no-such-scenario"), 0)


def test_bundled_tune_on_points_at_a_tuned_filter_of_the_same_name():
    src = S.load("uw-ch5-fixed")
    names = [f.name for f in src.filters]
    tuned = src.filters[names.index("OFEKF")].tune
    assert tuned is not None and tuned.on is None and tuned.optimizer == "ICA"
    for name in ("uw-ch5-cv", "uw-ch5-manoeuvre"):
        spec = {f.name: f for f in S.load(name).filters}["OFEKF"]
        assert spec.tune.on == "uw-ch5-fixed"
