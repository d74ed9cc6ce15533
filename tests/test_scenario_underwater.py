"""The scenario fields and bundled scenarios of Naseri Solhdar's thesis: validation errors that name
the field, the six ``uw-*`` scenarios with the thesis's numbers, the linear-system truth and
velocity legs.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.linalg import block_diag

import trackkit.scenario as S
from trackkit.experiments.montecarlo import groups_for, plan_of
from trackkit.filters import EKF, KF, UKF, FuzzyAdaptive
from trackkit.models import AzimuthElevation, MultipathDelay
from trackkit.scenario.build import compile_scenario
from trackkit.scenario.simulate import simulate_block

F3 = [[0.77, 0.20, 0.0], [0.22, 0.72, 0.22], [0.02, 0.0, 0.72]]
KMH = 1 / 3.6
DEG2 = (math.pi / 180) ** 2
UNDERWATER = ["uw-ch3-r", "uw-ch3-q", "uw-ch4-delays", "uw-ch5-fixed", "uw-ch5-cv",
              "uw-ch5-manoeuvre"]


def base(name: str = "uw-ch3-r") -> dict:
    """The bundled scenario as a dict, without the ch3 UKF (filters KF, GAFKF, PSOFKF, OFKF)."""
    d = copy.deepcopy(S.load(name).model_dump())
    d["filters"] = [f for f in d["filters"] if f["name"] != "UKF" or "ch3" not in name]
    return d


def rejects(d: dict, *patterns: str) -> str:
    with pytest.raises(S.ScenarioError) as err:
        S.parse(d)
    msg = str(err.value)
    for p in patterns:
        assert p in msg, (p, msg)
    return msg


# --------------------------------------------------------------------------------------------
# Validation: every error names the field
# --------------------------------------------------------------------------------------------


def test_linear_motion_needs_f_and_q_diag():
    d = base()
    d["target"]["motion"] = {"model": "Linear", "q_diag": [1.0, 1.0, 1.0]}
    rejects(d, "target.motion", "needs F", "q_diag")
    d["target"]["motion"] = {"model": "Linear", "F": F3}
    rejects(d, "target.motion", "needs F", "q_diag")


def test_linear_f_must_be_square_and_q_diag_match_it():
    d = base()
    d["target"]["motion"]["F"] = [[1.0, 0.0, 0.0], [0.0, 1.0], [0.0, 0.0, 1.0]]
    rejects(d, "target.motion", "F has rows of lengths [3, 2, 3]", "square")
    d = base()
    d["target"]["motion"]["q_diag"] = [1.0, 1.0]
    rejects(d, "target.motion", "q_diag has 2 values; expected 3")
    d = base()
    d["filters"][0]["motion"] = {"model": "Linear", "F": [[1.0, 0.0], [0.0, 1.0]],
                                 "q_diag": [1.0, 1.0]}
    rejects(d, "filters[0].motion.F is 2 x 2; expected 3 x 3")
    d = base()
    d["target"]["motion"]["q_diag"] = [1.0, -1.0, 1.0]
    rejects(d, "target.motion.q_diag.1", "greater than or equal to 0")


def test_linear_target_needs_a_state_of_its_size_and_no_legs():
    d = base()
    d["target"]["state"] = None
    rejects(d, "needs target.state")
    d = base()
    d["target"]["legs"] = [{"start_s": 10.0, "course_deg": 10.0}]
    rejects(d, "takes no legs")
    d = base()
    d["target"]["state"] = [0.0, 0.0]
    rejects(d, "target.state has 2 values")
    d = base()
    d["prior"]["std"] = [0.1, 0.1]
    rejects(d, "prior.std has 2 rows; expected 3")


def test_q_diag_and_f_only_on_their_models():
    d = base("bo-cv")
    d["target"]["motion"] = {"model": "Singer", "q_diag": [1.0] * 4}
    rejects(d, "target.motion", "q_diag is for ConstantVelocity and Linear, not Singer")
    d["target"]["motion"] = {"model": "ConstantVelocity", "F": F3}
    rejects(d, "target.motion", "F is only for motion model Linear")
    # on a constant velocity model the length is the state's, checked when compiled
    d["target"]["motion"] = {"model": "ConstantVelocity", "q_diag": [1.0] * 3}
    with pytest.raises(ValueError, match="q_diag has 3 values; expected 4"):
        compile_scenario(S.parse(d))


def test_velocity_legs_are_checked_against_the_dimension():
    d = base("bo-cv")
    d["observers"][0]["legs"] = [{"start_s": 100.0, "velocity_mps": [1.0, 2.0, 3.0]}]
    rejects(d, "observers[0].legs[0].velocity_mps has 3 components; expected 2 (dim)")
    d["observers"][0]["legs"] = [{"start_s": 100.0, "velocity_mps": [1.0, 2.0, 3.0, 4.0]}]
    rejects(d, "observers.0.legs.0", "velocity_mps has 4 components; expected 2 or 3")
    d["observers"][0]["legs"] = [{"start_s": 100.0, "velocity_mps": [1.0, 2.0],
                                  "course_deg": 10.0}]
    rejects(d, "observers.0.legs.0", "exactly one of", "velocity_mps")


def test_target_velocity_leg_with_wrong_component_count_names_the_field():
    d = base("bo-cv")
    d["target"]["legs"] = [{"start_s": 100.0, "velocity_mps": [1.0, 2.0, 3.0]}]
    with pytest.raises(ValueError, match=r"target\.legs\[0\]\.velocity_mps"):
        compile_scenario(S.parse(d))


def test_fuzzy_filters_need_exactly_one_of_tune_or_params():
    d = base()
    d["filters"][3]["tune"] = None
    rejects(d, "filters.3", "'OFKF' (OFKF) needs exactly one of tune", "options.params")
    d = base()
    d["filters"][3]["options"] = {"params": [0.0] * 15}
    rejects(d, "filters.3", "needs exactly one of tune")
    d = base()
    d["filters"][0]["tune"] = {"optimizer": "GA"}
    rejects(d, "filters.0", "'KF' (KF): tune is only for the fuzzy-adaptive filters")
    d = base()
    d["filters"][3]["options"] = {"alpha": 0.5}
    rejects(d, "filters.3", "has no option alpha")
    d = base()
    d["filters"][3]["tune"]["population"] = 1
    rejects(d, "filters.3.tune.population")
    d = base()
    d["filters"][3]["tune"]["optimizer"] = "SA"
    rejects(d, "filters.3.tune.optimizer")


def test_r0_and_r_diagonals_of_the_wrong_length_name_the_field():
    d = base()
    d["filters"][0]["r0_diag_si"] = [8.0, 1.0, 1.0]
    with pytest.raises(ValueError, match=r"'KF': r0_diag_si has 3 values; expected 2"):
        compile_scenario(S.parse(d))
    d = base()
    d["filters"][0]["r0_diag_si"] = [8.0, 0.0]
    rejects(d, "filters.0.r0_diag_si.1", "greater than 0")
    d = base("uw-ch5-fixed")
    d["observers"][1]["sensor"]["r_diag_si"] = [1e-4, 1e-4, 1e-4]
    with pytest.raises(ValueError, match="AzimuthElevation: r_diag_si has 3 values; expected 2"):
        compile_scenario(S.parse(d))
    d = base()
    d["observers"][0]["sensor"]["r_diag_si"] = [0.8, -9.0]
    rejects(d, "observers.0.sensor.r_diag_si.1", "greater than 0")


def test_position_r_diag_si_longer_than_the_position_is_rejected():
    d = base("cv-position")
    d["observers"][0]["sensor"]["r_diag_si"] = [1.0, 1.0, 1.0]
    with pytest.raises(ValueError, match="r_diag_si"):
        compile_scenario(S.parse(d))


def _two_state(groups):
    d = base()
    d["target"].update(state=[0.0, 0.0],
                       motion={"model": "Linear", "F": [[0.9, 0.1], [0.0, 0.8]],
                               "q_diag": [0.1, 0.1]})
    d["observers"][0]["sensor"]["r_diag_si"] = [1.0]
    d["prior"] = {"std": [0.1, 0.1], "mean": [0.0, 0.0]}
    d["filters"] = [{"name": "KF", "type": "KF"}]
    d["report"]["groups"] = groups
    d["time"]["duration_s"] = 5.0
    return S.parse(d)


def test_group_x3_on_a_two_state_scenario_names_the_group():
    s = _two_state(["x1", "x2"])
    assert list(groups_for(plan_of(s))) == ["x1", "x2"]
    with pytest.raises(ValueError, match=r"report.groups has \['x3'\]"):
        _two_state(["x1", "x3"])  # refused when the scenario is read, before any tuning


def test_kinematic_groups_on_a_linear_system_name_the_group():
    d = base()
    d["report"]["groups"] = ["position", "velocity"]
    with pytest.raises(ValueError, match="groups"):
        groups_for(plan_of(S.parse(d)))


def test_report_fields_of_the_underwater_scenarios():
    d = base()
    d["report"]["dom_alpha"] = 0.0
    rejects(d, "report.dom_alpha")
    d = base()
    d["report"]["groups"] = ["x4"]
    rejects(d, "report.groups.0")
    d = base()
    d["filters"][3]["options"] = {"q_inputs": [0.0, 0.0, 1.0]}
    d["filters"][3]["tune"] = None
    d["filters"][3]["options"]["params"] = [0.0] * 5 + [1.0] * 5 + [0.0] * 5
    with pytest.raises(ValueError, match="q_inputs has 3 values"):
        compile_scenario(S.parse(d))


# --------------------------------------------------------------------------------------------
# The bundled scenarios
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def plans():
    return {name: compile_scenario(S.load(name)) for name in UNDERWATER}


def test_all_six_load_compile_and_share_the_thesis_settings(plans):
    for name, plan in plans.items():
        s = plan.scenario
        assert s.name == name
        assert plan.steps == 500 and plan.dt == 1.0
        assert s.report.matching is True
        assert s.report.dom_alpha == (1000.0 if "ch3" in name else 5000.0)
        groups_for(plan)  # the report groups fit the state
        for spec, f in zip(s.filters, plan.filters, strict=True):
            if spec.type.startswith("OF"):
                assert isinstance(f, FuzzyAdaptive) and f.name == spec.type
                assert f.window == 25 and f.warmup == "wait"
                assert spec.tune is not None


def test_ch3_r_numbers(plans):
    p = plans["uw-ch3-r"]
    np.testing.assert_array_equal(p.truth_motion.F, F3)
    np.testing.assert_array_equal(p.truth_motion.Q, 0.02 * np.eye(3))
    np.testing.assert_allclose(p.sensors[0].noise, np.diag([0.8, 9.0]), rtol=1e-15)
    np.testing.assert_array_equal(p.sensors[0].jacobian(np.zeros(3)), np.eye(2, 3))  # H=[I 0]
    np.testing.assert_array_equal(p.x0, 0.0)
    np.testing.assert_array_equal(p.nominal, 0.0)
    assert [f.name for f in p.filters] == ["KF", "UKF", "OFKF", "OFKF", "OFKF"]
    assert isinstance(p.filters[0], KF) and isinstance(p.filters[4].base, KF)
    for i in range(5):
        np.testing.assert_array_equal(p.filter_r0[i], np.diag([8.0, 1.0]))
        np.testing.assert_array_equal(p.filter_sensor(i, 7).noise, np.diag([8.0, 1.0]))
        mean, P0 = p.priors[i]
        np.testing.assert_array_equal(mean, 0.0)
        np.testing.assert_allclose(P0, 0.01 * np.eye(3), rtol=1e-15)
        np.testing.assert_array_equal(p.filter_motions[i].Q, 0.02 * np.eye(3))
    assert p.filters[4].adapt == "R"
    tunes = [f.tune for f in p.scenario.filters[2:]]
    assert [t.optimizer for t in tunes] == ["GA", "PSO", "ICA"]
    # the thesis's 15 runs, population 50, 30 iterations; tuning data apart from the runs
    assert all((t.population, t.iterations, t.runs) == (50, 30, 15) for t in tunes)
    assert all(t.seed != p.scenario.run.seed for t in tunes)


def test_ch3_q_numbers(plans):
    p = plans["uw-ch3-q"]
    np.testing.assert_array_equal(p.truth_motion.Q, np.diag([1.0, 10.0, 2.0]))
    np.testing.assert_allclose(p.sensors[0].noise, np.diag([0.8, 9.0]), rtol=1e-15)
    for i in range(5):
        assert p.filter_r0[i] is None  # R known
        np.testing.assert_array_equal(p.filter_motions[i].Q, np.diag([10.0, 0.2, 12.0]))
        np.testing.assert_array_equal(p.filter_motions[i].F, F3)
    for f in p.filters[2:]:
        assert f.adapt == "Q" and f.q_inputs == ((0, 0), (1, 1), (0, 1))


def test_ch4_delays_numbers(plans):
    p = plans["uw-ch4-delays"]
    s = p.scenario
    # both sensors fixed at depth 160 m: z = -160 at every step, zero velocity
    np.testing.assert_array_equal(p.observer_states[:, :, 2], -160.0)
    np.testing.assert_array_equal(p.observer_states[:, :, 3:], 0.0)
    np.testing.assert_array_equal(p.observer_states[:, 0, :3],
                                  [[-200.0, -600.0, -160.0], [-220.0, -200.0, -160.0]])
    stack = p.sensors[0]
    assert stack.dim_z == 4
    for sens in stack.sensors:
        assert (sens.h_surface, sens.h_bottom, sens.c) == (160.0, 52.0, 1500.0)
    # x0 = [0, -5, -98] m, [-5, -1, -0.1] km/h; filters' x0_hat and P0 = I
    np.testing.assert_allclose(p.x0, [0, -5, -98, -5 * KMH, -1 * KMH, -0.1 * KMH],
                               rtol=0, atol=1e-6)
    for i in range(3):
        mean, P0 = p.priors[i]
        np.testing.assert_allclose(mean, [0, 2, -88, -4 * KMH, 0, -0.2 * KMH], atol=1e-6)
        np.testing.assert_array_equal(P0, np.eye(6))
        np.testing.assert_array_equal(p.filter_r0[i], 1e-3 * np.eye(4))  # R0 = 1e-3 I
    np.testing.assert_array_equal(p.truth_motion.Q, 1e-4 * np.eye(6))
    np.testing.assert_array_equal(p.truth_motion.F, np.eye(6) + np.eye(6, k=3))
    assert isinstance(p.filters[0], EKF) and isinstance(p.filters[1], UKF)
    assert isinstance(p.filters[2].base, EKF)
    # SNR 20 dB: variance = mean square of the noise-free delay over the nominal track / 100,
    # with the sensor rebuilt here
    truth = np.empty((501, 6))  # the noise-free constant-velocity track
    truth[:, :3] = p.x0[:3] + np.arange(501)[:, None] * p.x0[3:]
    truth[:, 3:] = p.x0[3:]
    np.testing.assert_allclose(p.nominal, truth, rtol=1e-12, atol=1e-9)
    var = []
    for o in ((-200.0, -600.0, -160.0), (-220.0, -200.0, -160.0)):
        z = MultipathDelay(o, 160.0, 52.0, sigma=1.0, c=1500.0).h(truth[1:])
        var += list(np.mean(z**2, 0) / 10 ** (20 / 10))
    np.testing.assert_allclose(np.concatenate([np.square(v) for v in p.sigmas]), var,
                               rtol=1e-12)
    np.testing.assert_allclose(stack.noise, np.diag(var), rtol=1e-12)
    # the sizes the notes quote (sensor 1): about 1e-5 s^2 for tau1 and 1.5e-6 s^2 for tau2
    assert 0.7e-5 < var[0] < 1.5e-5 and 1e-6 < var[1] < 2e-6
    # ICA-tuned (thesis), on data apart from the Monte Carlo runs
    assert s.filters[2].tune.optimizer == "ICA" and s.filters[2].tune.seed != s.run.seed


@pytest.mark.parametrize("name", ["uw-ch5-fixed", "uw-ch5-cv", "uw-ch5-manoeuvre"])
def test_ch5_numbers(plans, name):
    p = plans[name]
    # true R = diag(3, 0.4) deg^2 per sensor, R0 = diag(0.3, 0.03) deg^2 (7 digits in the file)
    R = np.diag([3.0, 0.4]) * DEG2
    np.testing.assert_allclose(p.sensors[0].noise, block_diag(R, R), rtol=1e-6)
    for i in range(3):
        np.testing.assert_allclose(p.filter_r0[i], np.diag([0.3, 0.03, 0.3, 0.03]) * DEG2,
                                   rtol=1e-6)
        mean, P0 = p.priors[i]
        np.testing.assert_allclose(mean, [-500, -40, -40, 17 * KMH, KMH, KMH], atol=1e-6)
        np.testing.assert_allclose(np.sqrt(np.diag(P0)),
                                   [50, 15, 15, 5 * KMH, 0.4 * KMH, 0.4 * KMH], atol=1e-6)
    np.testing.assert_allclose(p.x0, [-530, -50, -50, 14 * KMH, 0.3 * KMH, 0.1 * KMH],
                               atol=1e-6)
    np.testing.assert_array_equal(p.observer_states[:, 0, :3],
                                  [[-900.0, -200.0, -100.0], [-910.0, -180.0, -100.0]])
    # azimuth from the x axis, counter-clockwise ("math"): a target straight along +y of
    # sensor 1 is at +90 degrees, one along +x at 0
    s1 = p.sensors[0].sensors[0]
    assert s1.convention == "math"
    o = s1.origin  # sensor 1 at step 1 (it has moved there in the moving cases)
    np.testing.assert_array_equal(o, p.observer_states[0, 1, :3])
    x = np.array([[o[0], o[1] + 300.0, o[2], 0, 0, 0], [o[0] + 300.0, o[1], o[2], 0, 0, 0]])
    np.testing.assert_allclose(s1.h(x), [[math.pi / 2, 0.0], [0.0, 0.0]], atol=1e-12)
    ref = AzimuthElevation(p.observer_states[0, 1, :3], convention="math")
    np.testing.assert_allclose(s1.h(p.nominal[1]), ref.h(p.nominal[1]), rtol=1e-14)
    v = p.observer_states[:, :, 3:]
    if name == "uw-ch5-fixed":
        np.testing.assert_array_equal(v, 0.0)
    elif name == "uw-ch5-cv":
        np.testing.assert_allclose(v, np.broadcast_to([12 * KMH, 0, -KMH], v.shape), atol=1e-6)
        t = p.times[:, None]
        np.testing.assert_allclose(p.observer_states[0, :, :3],
                                   [-900.0, -200.0, -100.0] + t * v[0, 0], rtol=0, atol=1e-9)
    tune = {f.name: f.tune for f in p.scenario.filters}["OFEKF"]
    assert (tune.on is None) == (name == "uw-ch5-fixed")


def test_ch5_manoeuvre_velocity_schedule(plans):
    p = plans["uw-ch5-manoeuvre"]
    obs = p.observer_states  # (2, 501, 6), index = time in s
    sched = {0: ([12, 0, -1], [12, 0, -1]), 125: ([12, -6, -1], [12, 6, -1]),
             250: ([6, 12, 0], [6, -12, 0]), 375: ([12, -6, 1], [12, 6, 1])}
    starts = sorted(sched)
    for j in range(2):
        for a, start in enumerate(starts):
            end = starts[a + 1] if a + 1 < len(starts) else 500
            # the new velocity holds from the step after `start` (state at t = start still
            # has the old one: the leg acts on the interval [start, start + 1)); the file
            # gives it in m/s to 6 decimals
            lo = start + 1 if start else 0
            vel = obs[j, lo, 3:]
            np.testing.assert_allclose(vel, np.array(sched[start][j]) * KMH, rtol=0, atol=1e-6)
            np.testing.assert_array_equal(obs[j, lo:end + 1, 3:],
                                          np.broadcast_to(vel, (end + 1 - lo, 3)))
            # positions integrate it from the leg's start
            t = np.arange(start, end + 1)[:, None] - start
            np.testing.assert_allclose(obs[j, start:end + 1, :3], obs[j, start, :3] + t * vel,
                                       rtol=0, atol=1e-9)
        assert not np.allclose(obs[j, 125, 3:], obs[j, 126, 3:])


def test_a_velocity_leg_changes_the_observer_velocity_at_its_time():
    d = base("bo-cv")
    d["observers"][0]["legs"] = [{"start_s": 50.0, "velocity_mps": [3.0, -4.0]}]
    d["observers"][0]["initial"] = {"x_m": 10.0, "y_m": 20.0, "vx_mps": 1.0, "vy_mps": 2.0}
    p = compile_scenario(S.parse(d))
    obs, t = p.observer_states[0], p.times  # step 5 s
    k = int(np.searchsorted(t, 50.0))
    assert t[k] == 50.0
    np.testing.assert_array_equal(obs[: k + 1, 2:], np.broadcast_to([1.0, 2.0], (k + 1, 2)))
    np.testing.assert_array_equal(obs[k + 1:, 2:], np.broadcast_to([3.0, -4.0],
                                                                   (len(t) - k - 1, 2)))
    np.testing.assert_allclose(obs[: k + 1, :2], [10.0, 20.0] + t[: k + 1, None] * [1.0, 2.0],
                               rtol=1e-13)
    np.testing.assert_allclose(obs[k:, :2], [60.0, 120.0] + (t[k:, None] - 50.0) * [3.0, -4.0],
                               rtol=1e-13)


# --------------------------------------------------------------------------------------------
# The linear-system truth: x' = F x + w
# --------------------------------------------------------------------------------------------


def test_linear_truth_and_measurements_follow_the_documented_draws():
    d = base()
    d["time"]["duration_s"] = 40.0
    d["run"].update(runs=3, seed=123)
    s = S.parse(d)
    data = simulate_block(plan_of(s), 0, 3)
    F = np.array(F3)
    T = 40
    for r, child in enumerate(np.random.SeedSequence(123).spawn(3)):
        g = np.random.default_rng(child)
        u0 = g.standard_normal(3)  # prior offset, then process noise, measurement noise
        w = g.standard_normal((T, 3))
        e = g.standard_normal((T, 2))
        x = np.zeros(3)
        for k in range(T):
            x = F @ x + math.sqrt(0.02) * w[k]
            np.testing.assert_allclose(data.truth[k + 1, r], x, rtol=1e-12, atol=1e-15)
            z = x[:2] + np.array([math.sqrt(0.8), 3.0]) * e[k]
            np.testing.assert_allclose(data.z[k, r], z, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(data.prior_offset[r], u0)
        np.testing.assert_array_equal(data.truth[0, r], 0.0)


def test_linear_truth_residual_has_the_stated_covariance():
    # 20 runs x 500 steps of the Q-tuning benchmark (true Q = diag(1, 10, 2)): the sample
    # variance of x' - F x over N = 10000 draws has relative sd sqrt(2 / N) = 1.4 %; accept
    # 4.5 sd. Off-diagonal sample covariances have sd sqrt(Q_ii Q_jj / N).
    d = base("uw-ch3-q")
    d["run"].update(runs=20, seed=7, block=20)
    s = S.parse(d)
    plan = plan_of(s)
    data = simulate_block(plan, 0, 20)
    F = np.array(F3)
    w = data.truth[1:] - data.truth[:-1] @ F.T  # (T, B, 3)
    w = w.reshape(-1, 3)
    N = len(w)
    C = w.T @ w / N
    Q = np.diag([1.0, 10.0, 2.0])
    assert np.all(np.abs(np.diag(C) / np.diag(Q) - 1) < 4.5 * math.sqrt(2 / N)), np.diag(C)
    for i in range(3):
        for j in range(i + 1, 3):
            assert abs(C[i, j]) < 4.5 * math.sqrt(Q[i, i] * Q[j, j] / N), (i, j, C[i, j])
    # and the measurements carry R = diag(0.8, 9)
    v = (data.z - data.truth[1:, :, :2]).reshape(-1, 2)
    assert np.all(np.abs(np.mean(v**2, 0) / [0.8, 9.0] - 1) < 4.5 * math.sqrt(2 / N))
