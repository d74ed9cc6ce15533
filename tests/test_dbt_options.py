"""The Doppler-bearing comparison's two other options: the GA initialiser of Hashemi and Alfi
(2019) as ``[prior] initialiser = "ga"`` (validated, every filter started from the same
GA estimate, a run's start independent of its block), and a truth with process noise
(``target.motion.q > 0``), whose PCRLB carries the truth's Q."""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.experiments.montecarlo as mc
import trackkit.scenario as S
from trackkit.eval.crlb import pcrlb, rmse_bound
from trackkit.scenario.simulate import simulate_block

#: a GA small enough for a unit test: 100 measurements in 4 blocks, 10 x 5 generations
SMALL_GA = {"measurements": 100, "block": 25, "population": 10, "generations": 5}


def _dbt(duration: float = 200.0, runs: int = 4, block: int = 2, ga: dict | None = None,
         q_true: float = 0.0, name: str = "dbt-approaching") -> S.Scenario:
    d = S.load(name).model_dump()
    d["time"]["duration_s"] = duration
    d["report"]["average_from_s"] = 50.0
    d["report"]["windows"] = {}
    d["run"].update(runs=runs, block=block)
    d["target"]["motion"]["q"] = q_true
    if ga is not None:
        d["prior"]["initialiser"] = "ga"
        d["prior"]["ga"] = ga
    return S.parse(d, "dbt-small")


def _error(edit, base: str = "dbt-approaching") -> str:
    d = S.load(base).model_dump()
    edit(d)
    with pytest.raises(S.ScenarioError) as info:
        S.parse(d, "bad")
    return str(info.value)


# --- the GA initialiser: the schema ----------------------------------------------------------


def test_draw_is_the_default_and_ga_takes_the_papers_settings():
    assert S.load("dbt-approaching").prior.initialiser == "draw"
    s = _dbt(duration=2000.0, ga={})
    ga = s.prior.ga_settings
    assert s.prior.initialiser == "ga"
    assert (ga.population, ga.generations, ga.crossover, ga.mutation) == (50, 200, 0.8, 0.05)
    assert (ga.measurements, ga.block, ga.cost) == (800, 25, "nis")
    assert ga.std == [1000.0, 1000.0, 10.0, 10.0, 5.0]


def _set(path: str, value):
    def edit(d: dict) -> None:
        *head, last = path.split(".")
        node = d
        for key in head:
            if key.isdigit():
                node = node[int(key)]
            else:
                if node.get(key) is None:
                    node[key] = {}
                node = node[key]
        node[last] = value
    return edit


def _both(*edits):
    def edit(d: dict) -> None:
        for e in edits:
            e(d)
    return edit


GA_ON = _set("prior.initialiser", "ga")


@pytest.mark.parametrize("edit, words", [
    (_both(GA_ON, _set("prior.ga.block", 24)), ["prior.ga.block", "24", "odd"]),
    (_both(GA_ON, _set("prior.ga.measurements", 810)),
     ["prior.ga.measurements", "810", "multiple of block = 25"]),
    (_both(GA_ON, _set("prior.ga.measurements", 2025)),
     ["prior.ga.measurements", "2025", "at most 2000"]),
    (_both(GA_ON, _set("prior.ga.std", [1000.0, 1000.0, 10.0])),
     ["prior.ga.std", "3 values", "expected 5", "[x, y, vx, vy, f0]"]),
    (_both(GA_ON, _set("prior.ga.velocity_guess_mps", [1.0])),
     ["prior.ga.velocity_guess_mps", "[1.0]", "expected 2"]),
    (_both(GA_ON, _set("prior.ga.crossover", 1.5)), ["prior.ga.crossover", "1.5"]),
    (_both(GA_ON, _set("prior.ga.cost", "mse")), ["prior.ga.cost", "mse", "'nis'"]),
    (_both(GA_ON, _set("prior.ga.population", 1)), ["prior.ga.population", "1", "2"]),
    (_set("prior.ga", {"generations": 10}),
     ["prior.ga", "initialiser = 'draw'", "expected initialiser = \"ga\""]),
    (_both(GA_ON, _set("prior.mean", [0.0, 0.0, 0.0, 0.0, 500.0])),
     ["prior.mean", "initialiser = \"ga\"", "expected no mean"]),
    (_both(GA_ON, _set("filters.1.prior", {"std": [1.0, 1.0, 1.0, 1.0, 1.0]})),
     ["filters.1.prior", "'UKF'", "expected no filters[].prior"]),
    (_set("prior.initialiser", "guess"), ["prior.initialiser", "guess", "'draw' or 'ga'"]),
])
def test_bad_ga_settings_are_named_with_their_value_and_expectation(edit, words):
    message = _error(edit)
    for w in words:
        assert w in message, (w, message)


def test_ga_needs_a_doppler_bearing_scenario():
    message = _error(GA_ON, "bo-cv")
    for w in ("prior.initialiser", "'ga'", "BearingFrequency", "[x, y, vx, vy, f0]",
              "sensors ['Bearing']"):
        assert w in message, (w, message)


# --- the GA initialiser: the engine ---------------------------------------------------------


def test_ga_start_is_the_ga_position_the_velocity_guess_and_the_first_frequency():
    s = _dbt(ga={**SMALL_GA, "velocity_guess_mps": [1.0, -2.0], "std": [900.0, 800.0, 7.0,
                                                                       6.0, 4.0]})
    plan = mc.plan_of(s)
    data = simulate_block(plan, 0, 4)
    g = mc._ga_start(plan, data, [0, 1, 2, 3])
    assert g.mean.shape == (4, 5) and g.cov.shape == (4, 5, 5)
    np.testing.assert_array_equal(g.mean[:, 2:4], np.broadcast_to([1.0, -2.0], (4, 2)))
    np.testing.assert_array_equal(g.mean[:, 4], data.z[0, :, 1])  # the first measured tone
    np.testing.assert_array_equal(g.cov, np.broadcast_to(
        np.diag([900.0**2, 800.0**2, 49.0, 36.0, 16.0]), (4, 5, 5)))
    box = plan.observer_states[0, 0, :2]
    assert np.all(np.abs(g.mean[:, :2] - box) <= 20_000.0)  # inside the searched square


def test_a_runs_ga_start_does_not_depend_on_its_block():
    s = _dbt(ga=SMALL_GA)
    plan = mc.plan_of(s)
    whole = mc._ga_start(plan, simulate_block(plan, 0, 4), [0, 1, 2, 3])
    halves = [mc._ga_start(plan, simulate_block(plan, r, r + 2), [r, r + 1]) for r in (0, 2)]
    # each run's GA draws from its own generator (seed, run): only the batch's rounding
    # could differ, and it does not here
    np.testing.assert_allclose(np.concatenate([h.mean for h in halves]), whole.mean,
                               rtol=1e-12, atol=0)


def test_every_filter_starts_from_the_same_ga_estimate(monkeypatch):
    s = _dbt(ga=SMALL_GA, runs=2, block=2)
    first: dict[int, np.ndarray] = {}
    for i, f in enumerate(mc.plan_of(s).filters):
        def init(prior, i=i, rng=None, _init=f.init):
            # the first call is the engine's start (adaptive filters call init again inside)
            first.setdefault(i, np.array(prior.mean))
            return _init(prior)
        monkeypatch.setattr(f, "init", init, raising=False)
    result = mc.run_scenario(s)
    assert sorted(first) == list(range(len(s.filters)))
    starts = [first[i] for i in sorted(first)]
    for m in starts[1:]:
        np.testing.assert_array_equal(m, starts[0])
    data = simulate_block(mc.plan_of(s), 0, 2)
    assert not np.allclose(starts[0][:, :2], data.truth[0][:, :2] + 0.0)  # not the truth
    assert any("GA initialiser" in n and "PCRLB keeps the scenario's prior" in n
               for n in result.notes)


def test_ga_start_keeps_the_pcrlb_of_the_scenario_prior():
    draw, ga = (mc.run_scenario(_dbt(ga=g, runs=2, block=2)) for g in (None, SMALL_GA))
    for g in draw.pcrlb:
        np.testing.assert_array_equal(draw.pcrlb[g], ga.pcrlb[g])
    assert ga.filters["EKF"].rmse_mean != draw.filters["EKF"].rmse_mean


# --- a truth with process noise ---------------------------------------------------------------


def test_the_truth_moves_with_the_stated_process_noise():
    # CV with acceleration density q: each step adds a velocity increment of variance q dt
    # (dt = 1 s); 400 runs x 100 steps = 40 000 draws per axis, so the sample variance is
    # within 3.5% of q at about 5 sigma (its relative sd is sqrt(2 / 40 000) = 0.7%)
    q = 1e-4
    plan = mc.plan_of(_dbt(duration=100.0, q_true=q))
    truth = simulate_block(plan, 0, 400).truth
    dv = np.diff(truth[:, :, 2:4], axis=0)
    assert np.var(dv) == pytest.approx(q, rel=0.035)
    assert np.all(truth[:, :, 4] == 500.0)  # the tone stays constant (q_extra = 0)
    still = simulate_block(mc.plan_of(_dbt(duration=100.0)), 0, 4).truth
    assert np.all(np.diff(still[:, :, 2:4], axis=0) == 0.0)  # q = 0: exactly straight


def test_the_pcrlb_carries_the_truths_process_noise():
    # the engine's bound (block information sums, covariance form) against trackkit.eval.crlb's
    # pcrlb on the same truths, with the truth's own motion model (its Q included)
    s = _dbt(duration=300.0, runs=4, block=4, q_true=1e-4)
    plan = mc.plan_of(s)
    result = mc.run_scenario(s)
    truths = simulate_block(plan, 0, 4).truth
    direct = pcrlb(plan.prior_cov, plan.truth_motion, plan.sensors, truths, plan.dt)
    np.testing.assert_allclose(result.pcrlb["position"], rmse_bound(direct, [0, 1]),
                               rtol=1e-9)
    still = mc.run_scenario(_dbt(duration=300.0, runs=4, block=4))
    # with process noise the bound is higher once the measurements dominate the prior
    assert np.all(result.pcrlb["position"][100:] > still.pcrlb["position"][100:])
    assert np.all(result.pcrlb["velocity"][100:] > still.pcrlb["velocity"][100:])
