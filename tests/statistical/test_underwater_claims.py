"""The claims of Naseri Solhdar's thesis on our Monte Carlo runs, at the bundled scenarios'
fixed seeds and run counts (100 runs each; the thesis has one run).

Each ratio is of Monte Carlo RMSEs over 100 runs and 500 steps. The thresholds are those of
our reading of the thesis (docs/uw-comparison.md), which allow for the thesis's garbled inputs and
single run; they are not tuned to our numbers. What the margins are on our runs is recorded in
``docs/uw-comparison.md``. ICA is not asserted to beat GA and PSO: the thesis's margin
(under 1% on the mean cost) is within run-to-run noise.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.compare import compare

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def results():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = compare(S.load(name))
        return cache[name]

    return get


def _ratio(result, filt, ref, group):
    return result.filters[filt].rmse_mean[group] / result.filters[ref].rmse_mean[group]


def _j4(result, filt):
    return float(np.mean(result.filters[filt].matching["J4"]))


def test_ch3_r_tuning_beats_the_kf(results):
    r = results("uw-ch3-r")
    assert r.runs >= 50
    for filt in ("GAFKF", "PSOFKF", "OFKF"):
        assert _ratio(r, filt, "KF", "x1") <= 0.8
        assert _ratio(r, filt, "KF", "x2") <= 0.8
        assert _ratio(r, filt, "KF", "x3") < 1.0
        assert _j4(r, filt) <= 0.5 * _j4(r, "KF")


@pytest.mark.parametrize("name", ["uw-ch3-r", "uw-ch3-q"])
def test_the_ukf_is_the_kf_on_the_linear_benchmark(results, name):
    r = results(name)
    for g in ("x1", "x2", "x3"):
        assert r.filters["UKF"].rmse_mean[g] == pytest.approx(r.filters["KF"].rmse_mean[g],
                                                              rel=1e-9)


def test_ch3_q_tuning_beats_the_kf(results):
    r = results("uw-ch3-q")
    for filt in ("GAFKF", "PSOFKF", "OFKF"):
        for g in ("x1", "x2", "x3"):
            assert _ratio(r, filt, "KF", g) < 1.0
        assert _ratio(r, filt, "KF", "x3") <= 0.7
        assert _j4(r, filt) <= 0.5 * _j4(r, "KF")


def test_r_tuning_helps_x1_x2_more_and_q_tuning_helps_x3_more(results):
    rr, rq = results("uw-ch3-r"), results("uw-ch3-q")
    for g in ("x1", "x2"):
        assert _ratio(rr, "OFKF", "KF", g) < _ratio(rq, "OFKF", "KF", g)
    assert _ratio(rq, "OFKF", "KF", "x3") < _ratio(rr, "OFKF", "KF", "x3")


@pytest.mark.parametrize("name", ["uw-ch3-r", "uw-ch3-q"])
def test_each_optimiser_best_mean_worst(results, name):
    r = results(name)
    assert {t.optimizer for t in r.tuning.values()} == {"GA", "PSO", "ICA"}
    for t in r.tuning.values():
        assert t.runs == 15 and t.population == 50 and t.iterations == 30
        assert t.best == pytest.approx(t.costs.min()) and t.worst == pytest.approx(t.costs.max())
        assert t.mean == pytest.approx(t.costs.mean())
        assert t.best <= t.mean <= t.worst
        assert t.best < t.history[0].min()  # the optimiser improved on its initial population


def test_ch4_delays_fuzzy_ekf_beats_the_ekf(results):
    r = results("uw-ch4-delays")
    assert _ratio(r, "OFEKF", "EKF", "position") < 0.9
    assert _j4(r, "OFEKF") <= 0.5 * _j4(r, "EKF")
    assert r.filters["OFEKF"].diverged == 0


def test_ch5_fixed_fuzzy_ekf_beats_the_ekf(results):
    r = results("uw-ch5-fixed")
    assert _ratio(r, "OFEKF", "EKF", "position") < 1.0
    assert _j4(r, "OFEKF") <= 0.5 * _j4(r, "EKF")


@pytest.mark.parametrize("moving", ["uw-ch5-cv", "uw-ch5-manoeuvre"])
def test_moving_sensors_cut_the_x_error(results, moving):
    fixed, mov = results("uw-ch5-fixed"), results(moving)
    for filt in ("EKF", "UKF", "OFEKF"):
        assert mov.filters[filt].rmse_mean["x"] <= 0.7 * fixed.filters[filt].rmse_mean["x"]


def test_moving_sensors_reuse_the_fixed_sensor_tuning(results):
    fixed = results("uw-ch5-fixed").tuning["OFEKF"]
    for name in ("uw-ch5-cv", "uw-ch5-manoeuvre"):
        np.testing.assert_array_equal(results(name).tuning["OFEKF"].params, fixed.params)
