"""Missing measurements in the scenario engine: the [gaps] table and the filters'
gaps handlers, the WithGaps wrapper against run_with_gaps, pseudo flags, the results' gap
fields, the report's table and time plot, and determinism over block chunkings."""

from __future__ import annotations

import json

import numpy as np
import pytest

import trackkit as tk
import trackkit.scenario as S
from trackkit.experiments.montecarlo import run_scenario
from trackkit.filters.gaps import (
    PolynomialFit,
    SineFit,
    WithGaps,
    mask_by_time,
    measurement_times,
    run_with_gaps,
)
from trackkit.filters.maneuver import NISDetector
from trackkit.report import write_report

GAP_SCENARIOS = ["gaps-cv", "gaps-ca", "gaps-sine"]


def problems(d: dict) -> str:
    with pytest.raises(ValueError) as err:
        S.parse(d, "x")
    return str(err.value)


def cwpa(**changes) -> dict:
    d = S.load("kf-cwpa").model_dump()
    d.update(changes)
    return d


# --- schema ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("gaps", "field", "words"), [
    ({"samples": [[10, 60]]}, "gaps.samples.0", "expected 0 <= first <= last <= 49"),
    ({"samples": [[20, 10]]}, "gaps.samples.0", "expected first <= last"),
    ({"counts": [[45, 10]]}, "gaps.counts.0", "reaches index 54"),
    ({"time_s": [[30.0, 40.0]]}, "gaps.time_s.0", "holds no measurement time"),
    ({"time_s": [[5.0, 5.0]]}, "gaps.time_s.0", "expected start_s < stop_s"),
    ({}, "gaps", "expected at least one of time_s, samples or counts"),
])
def test_gaps_table_errors_name_field_and_value(gaps, field, words):
    msg = problems(cwpa(gaps=gaps))
    assert field in msg and words in msg


@pytest.mark.parametrize(("spec", "field", "words"), [
    ({"handler": "B3"}, "filters.0.gaps.handler", "'B0', 'B1', 'B2', 'P' or \"P'\""),
    ({"handler": "B2", "degree": 2}, "filters.0.gaps.degree", "it takes n"),
    ({"handler": "B1", "n": 3}, "filters.0.gaps.n", "it takes no options"),
    ({"handler": "P'", "window": 5}, "filters.0.gaps.short_window", "needs short_window"),
    ({"handler": "P", "degree": 3, "window": 3}, "filters.0.gaps.window",
     "expected an integer >= 4"),
    ({"handler": "P", "function": "sine"}, "filters.0.gaps.function",
     "needs a sensor of one channel; the scenario measures 2"),
    ({"handler": "P'", "short_window": 3, "detector": {"type": "NIS", "L": 4}},
     "filters.0.gaps.detector.L", 'L is for detector type "window"'),
    ({"handler": "P'", "short_window": 3, "detector": {"type": "fading", "pfa": 1.5}},
     "filters.0.gaps.detector.pfa", "less than 1"),
    ({"handler": "P'", "short_window": 12, "detector": {"type": "NIS"}},
     "filters.0.gaps.short_window", "expected fewer than window = 10"),
])
def test_handler_errors_name_field_and_value(spec, field, words):
    d = cwpa()
    d["filters"][0]["gaps"] = spec
    msg = problems(d)
    assert field in msg and words in msg


def test_sine_amplitude_switch():
    d = S.load("gaps-sine").model_dump()
    d["observers"][0]["sensor"]["amplitude"] = True
    assert "3-component target.state" in problems(d)
    d = cwpa()
    d["observers"][0]["sensor"]["amplitude"] = False
    assert "amplitude = false is for sensor Sine, not Position" in problems(d)


def test_gap_mask_matches_gaps_module():
    s = S.load("gaps-ca")
    t = measurement_times(s.time.steps, s.time.step_s)
    assert np.array_equal(s.gaps.mask(s.time.steps, s.time.step_s), mask_by_time(t, 2.0, 5.0))
    assert s.gaps.mask(80, 0.1).sum() == 30  # 2.0 .. 4.9 s: half-open
    both = s.gaps.model_copy(update={"samples": [(70, 72)], "counts": [(0, 2)]})
    m = both.mask(80, 0.1)
    assert m.sum() == 35 and m[[0, 1, 70, 71, 72]].all() and not m[[2, 69, 73]].any()


# --- the wrapper ----------------------------------------------------------------------------


def _data(K=80, R=6, seed=3):
    rng = np.random.default_rng(seed)
    z = np.cumsum(rng.standard_normal((K, R, 1)), 0) + 0.05 * np.arange(K)[:, None, None] ** 2
    prior = tk.Gaussian(np.zeros((R, 3)), np.tile(np.eye(3), (R, 1, 1)))
    return z, prior


@pytest.mark.parametrize("case", ["B2", "P", "P'"])
def test_wrapper_equals_run_with_gaps_bitwise(case):
    """Step by step through WithGaps gives run_with_gaps' numbers bit for bit, when the
    steps given to run_with_gaps are the wrapper's (its times the steps' cumulative sum)."""
    motion = tk.models.ConstantAcceleration(dim=1, q=0.1)
    sensor = tk.models.Position(dim=1, sigma=0.5)
    z, prior = _data()
    K = len(z)
    times = measurement_times(K, np.full(K, 0.1))
    mask = mask_by_time(times, 2.0, 5.0)
    handler, det = {"B2": ("B2", None), "P": (PolynomialFit(2, 20), None),
                    "P'": (PolynomialFit(2, 20, short_window=5), NISDetector(dim_z=1))}[case]
    ref = run_with_gaps(tk.filters.KF(), prior, motion, sensor, z, np.full(K, 0.1), mask,
                        handler, det)
    dts = np.diff(np.concatenate([[0.0], times]))
    w = WithGaps(tk.filters.KF(), handler, det)
    b = w.init(prior)
    for k in range(K):
        b = w.predict(b, motion, dts[k])
        assert b.t[0] == times[k]
        b, innov = w.update(b, np.where(mask[k], np.nan, z[k]), sensor)
        assert np.array_equal(w.estimate(b).mean, ref.estimate.mean[k])
        assert np.array_equal(w.estimate(b).cov, ref.estimate.cov[k])
        assert np.array_equal(b.pseudo, ref.is_pseudo[k])
        assert np.array_equal(b.z_pseudo, ref.pseudo[k], equal_nan=True)
        assert np.isnan(innov.nu).all() == bool(mask[k])  # NIS: real ones only
        if det is not None:
            assert np.array_equal(b.detector.on, ref.maneuver[k])
    assert ref.is_pseudo.sum() == 30 * z.shape[1]


def test_wrapper_sine_fit_bitwise():
    motion = tk.models.ConstantVelocity(dim=1, q=0.01)
    sensor = tk.models.Sine(sigma=1.0, amplitude=False)
    rng = np.random.default_rng(1)
    K, R = 60, 5
    theta = 1.0 * 0.1 * np.arange(1, K + 1)[:, None] + 0.1 * rng.standard_normal((1, R))
    z = np.sin(theta)[..., None] + 0.3 * rng.standard_normal((K, R, 1))
    prior = tk.Gaussian(np.tile([0.0, 1.0], (R, 1)), np.tile(np.eye(2) * 0.1, (R, 1, 1)))
    times = measurement_times(K, np.full(K, 0.1))
    mask = np.zeros(K, bool)
    mask[35:50] = True
    ref = run_with_gaps(tk.filters.EKF(), prior, motion, sensor, z, np.full(K, 0.1), mask,
                        SineFit(window=30))
    w = WithGaps(tk.filters.EKF(), SineFit(window=30))
    b = w.init(prior)
    for k, dt in enumerate(np.diff(np.concatenate([[0.0], times]))):
        b = w.predict(b, motion, dt)
        b, _ = w.update(b, np.where(mask[k], np.nan, z[k]), sensor)
        assert np.array_equal(w.estimate(b).mean, ref.estimate.mean[k])


def test_wrapper_bad_input():
    with pytest.raises(ValueError, match="needs a manoeuvre detector"):
        WithGaps(tk.filters.KF(), PolynomialFit(1, 10, short_window=3))
    with pytest.raises(ValueError, match="handler name = 'B7'"):
        WithGaps(tk.filters.KF(), "B7")


# --- the engine and the report --------------------------------------------------------------


def _small(name: str, runs: int = 12, block: int = 5) -> S.Scenario:
    d = S.load(name).model_dump()
    d["run"].update(runs=runs, block=block)
    return S.parse(d, name)


def test_engine_gap_fields_and_pseudo_flags():
    s = _small("gaps-ca")
    r = run_scenario(s)
    gap = np.flatnonzero(s.gaps.mask(s.time.steps, s.time.step_s))
    assert r.gap_steps.tolist() == gap.tolist() == list(range(19, 49))
    assert r.after_steps.tolist() == list(range(49, 59))  # after_gap_s = 1 s: 10 steps
    for name, f in r.filters.items():
        handler = f.gaps["handler"]
        fed = f.gaps["pseudo_steps"]
        # B0 feeds nothing; B2 and P feed every run at every gap step and nowhere else
        expected = np.zeros(s.time.steps, int)
        if handler != "B0":
            expected[gap] = s.run.runs
        assert np.array_equal(fed, expected), name
        assert r.pseudo_fraction(name) == pytest.approx(expected.sum() / (12 * 80), rel=1e-15)
        ex = r.example.pseudo[name]
        assert np.isfinite(ex[gap]).all() == (handler != "B0")
        assert np.isnan(np.delete(ex, gap, axis=0)).all()
    assert np.isnan(r.example.measurements[gap]).all()
    # the gap RMSE is the per-step RMSE over those steps (the same squared errors)
    for name, f in r.filters.items():
        mse = f.rmse["x1"][gap] ** 2
        assert r.gap_rmse(name, "x1") == pytest.approx(np.sqrt(mse.mean()), rel=1e-12)
        per_run = r.gap_rmse_per_run(name, "x1", "gap")
        assert np.sqrt(np.mean(per_run**2)) == pytest.approx(r.gap_rmse(name, "x1"),
                                                             rel=1e-12)
    doc = r.to_json_dict()["gaps"]
    assert doc["steps"] == gap.tolist() and doc["after_gap_s"] == 1.0
    assert set(doc["filters"]["CA-P"]) == {"handler", "pseudo_fraction", "rmse_gap",
                                           "rmse_after", "rmse_both"}
    assert doc["filters"]["CA-P"]["handler"] == "P"


def test_engine_matches_run_with_gaps():
    """One filter of a bundled scenario through the engine equals run_with_gaps on the same
    simulated data (the engine's run 0 estimate, 1e-12: the engine's KF runs the same
    kernels on a block of runs)."""
    from trackkit.experiments.montecarlo import plan_of
    from trackkit.scenario.simulate import simulate_block

    s = _small("gaps-ca", runs=4, block=4)
    plan = plan_of(s)
    data = simulate_block(plan, 0, 4)
    i = plan.filter_names.index("CA-P")
    mean0, P0 = plan.priors[i]
    m0 = data.truth[0] + data.prior_offset @ np.linalg.cholesky(P0).T
    prior = tk.Gaussian(m0, np.broadcast_to(P0, (4, 3, 3)).copy())
    ref = run_with_gaps(tk.filters.KF(), prior, plan.filter_motions[i], plan.sensors[0],
                        data.z, np.diff(plan.times), plan.gap_mask,
                        PolynomialFit(2, 20))
    r = run_scenario(s)
    est = r.example.estimates["CA-P"][0]
    np.testing.assert_allclose(est, ref.estimate.mean[:, 0], rtol=1e-12, atol=1e-12)
    assert np.array_equal(np.isfinite(r.example.pseudo["CA-P"][:, 0]), ref.is_pseudo[:, 0])


def test_gap_results_identical_over_chunkings():
    s = _small("gaps-sine", runs=10, block=5)
    a = run_scenario(s).to_json_dict()
    b = run_scenario(s, chunk=10).to_json_dict()
    for doc in (a, b):
        for f in doc["filters"].values():
            f.pop("seconds_per_step")
    assert a["gaps"] == b["gaps"]
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def test_report_has_gap_table_and_time_plot(tmp_path):
    r = run_scenario(_small("gaps-sine", runs=6, block=6))
    written = write_report(r, tmp_path)
    assert "time" in written and "geometry" not in written  # a given (theta, omega) state
    page = (tmp_path / "report.html").read_text()
    assert "Error over the gap and after, per handler" in page
    assert 'alt="time"' in page
    doc = json.loads((tmp_path / "results.json").read_text())
    assert doc["gaps"]["filters"]["B1"]["pseudo_fraction"] == pytest.approx(41 / 100)
    assert doc["gaps"]["filters"]["B0"]["pseudo_fraction"] == 0.0


def test_no_gaps_no_gap_fields():
    r = run_scenario(_small("kf-cwpa", runs=3, block=3))
    assert "gaps" not in r.to_json_dict() and r.gap_steps is None
