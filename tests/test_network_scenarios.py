"""Network scenarios (Jalalipoor and Kardehi Moghaddam 2021): the schema and its messages, the
bundled files and their geometry, the Monte Carlo and its report, and the ``trackkit network``
command."""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import replace

import numpy as np
import pytest

from tests.cli_helpers import assert_user_error, trackkit
from trackkit.experiments.network_compare import compare_networks, run_mse
from trackkit.experiments.network_mc import run_network_mc
from trackkit.report.network_report import AGENT_UNITS, write_network_report
from trackkit.scenario import ScenarioError
from trackkit.scenario.network import (
    bundled_network,
    is_network,
    load_network,
    parse_network,
)
from trackkit.sim.sensor_network import simulate_network

BUNDLED = ("net-baseline", "net-limited", "net-random")

# a tiny scenario for the command and the report: 2 agents, 2 targets, 60 s
TINY = """
name = "net-tiny"
description = "two agents, two targets, one minute"

[network]
duration_s = 60.0
period_s = 5.0

[[agents]]
x_m = 0.0
y_m = 0.0
course_deg = 90.0
speed_mps = 10.0

[[agents]]
x_m = 20000.0
y_m = 0.0
course_deg = 0.0
speed_mps = 10.0

[[targets]]
x_m = 5000.0
y_m = 20000.0
course_deg = 150.0
speed_mps = 9.0

[[targets]]
x_m = 15000.0
y_m = 18000.0
course_deg = 230.0
speed_mps = 8.0

[settings]
steering = false

[run]
runs = 2
seed = 7
"""


def _tiny(**changes) -> dict:
    data = tomllib.loads(TINY)
    for path, value in changes.items():
        *head, last = path.split(".")
        d = data
        for k in head:
            d = d[int(k)] if isinstance(d, list) else d.setdefault(k, {})
        d[last] = value
    return data


def _short(sc, duration: float):
    return sc.model_copy(update={"network": sc.network.model_copy(
        update={"duration_s": duration})})


# --- schema ---------------------------------------------------------------------------------


@pytest.mark.parametrize("path,value,names", [
    ("agents.0.speed_mps", 45.0, ["agents.0.speed_mps", "45.0", "30"]),
    ("agents.1.meas_range_m", -5.0, ["agents.1.meas_range_m", "-5.0", "inf for unlimited"]),
    ("agents.0.sigma_deg", 0.0, ["agents.0.sigma_deg", "0.0", "greater than 0"]),
    ("targets.1.speed_mps", 40.0, ["targets.1.speed_mps", "40.0", "v_max"]),
    ("network.jitter_s", 9.0, ["network.jitter_s", "9.0", "period_s"]),
    ("network.loss", 1.0, ["network.loss", "1.0", "less than 1"]),
    ("settings.combination", "mean", ["settings.combination", "'mean'", "information"]),
    ("report.example_agent", 3, ["report.example_agent", "3", "from 1 to 2"]),
    ("name", "../x", ["name", "../x", "plain file name"]),
])
def test_schema_errors_name_the_field_value_and_expectation(path, value, names):
    with pytest.raises(ScenarioError) as err:
        parse_network(_tiny(**{path: value}), "tiny.toml")
    text = str(err.value)
    for n in ["tiny.toml", *names]:
        assert n in text, f"{n!r} not in {text}"


def test_schema_unknown_field_and_missing_targets():
    data = _tiny()
    data["agents"][0]["colour"] = "red"
    with pytest.raises(ScenarioError, match=r"agents\.0\.colour.*unknown field"):
        parse_network(data)
    data = _tiny()
    del data["targets"]
    with pytest.raises(ScenarioError, match=r"targets = \(missing\).*random_targets"):
        parse_network(data)
    data = _tiny()
    data["random_targets"] = {"count": 2, "x_m": [0.0, 1.0], "y_m": [5.0, 1.0],
                              "speed_mps": [1.0, 2.0]}
    with pytest.raises(ScenarioError, match=r"random_targets\.y_m.*lo <= hi"):
        parse_network(data)


def test_random_targets_depend_on_seed_and_run_alone():
    sc = load_network("net-random")
    a = sc.target_states(5, 3)
    assert a.shape == (4, 4)
    np.testing.assert_array_equal(a, sc.target_states(5, 3))
    assert not np.array_equal(a, sc.target_states(5, 4))
    r = sc.random_targets
    assert np.all((a[:, 0] >= r.x_m[0]) & (a[:, 0] <= r.x_m[1]))
    speed = np.hypot(a[:, 2], a[:, 3])
    assert np.all((speed >= r.speed_mps[0]) & (speed <= r.speed_mps[1]))


# --- the bundled files ------------------------------------------------------------------------


def test_bundled_names_load_with_notes():
    assert set(BUNDLED) <= set(bundled_network())
    for name in BUNDLED:
        sc = load_network(name)
        assert sc.name == name and sc.notes and is_network(name)
        assert len(sc.agents) == 3 and sc.network.duration_s == 1000.0
        assert all(a.sigma_deg == 2.0 for a in sc.agents)
    assert load_network("net-baseline").n_targets == 3
    assert load_network("net-random").n_targets == 4
    lim = load_network("net-limited")
    assert np.all(lim.meas_range() == 25000.0) and np.all(lim.comm_range() == 25000.0)
    assert np.all(np.isinf(load_network("net-baseline").meas_range()))
    assert not is_network("bo-cv") and not is_network("radar-crossing")


@pytest.mark.parametrize("name", BUNDLED)
def test_show_round_trips(name, tmp_path):
    ran = trackkit("show", name)
    assert ran.code == 0, ran.text
    f = tmp_path / f"{name}.toml"
    f.write_text(ran.out, encoding="utf-8")
    assert load_network(f) == load_network(name)


def test_net_limited_agent_2_never_measures_target_3():
    """Over every bundled run with straight courses (the simulator: all runs, cheap):
    agent 2 never has target 3 in range while agents 1 and 3 always do; with steering
    (closed loop, one full run without the reference): agent 2 never comes within its
    measurement range of target 3."""
    sc = load_network("net-limited")
    n = sc.network
    sim = simulate_network(sc.run.seed, sc.run.runs, sc.target_states(sc.run.seed, 0),
                           sc.agent_states(), duration=n.duration_s, period=n.period_s,
                           sigma=sc.sigma_rad(), mr=sc.meas_range(), max_delay=n.max_delay_s)
    seen = sim.bearings.in_range  # (R, A, E, Nt)
    assert not seen[:, 1, :, 2].any()
    assert seen[:, 0, :, 2].all() and seen[:, 2, :, 2].all()
    from trackkit.network.inprocess import run_network

    for run in range(1):
        r = run_network(sc.run.seed, run, sc.target_states(sc.run.seed, run), sc.agent_states(),
                        duration=n.duration_s, period=n.period_s, sigma=sc.sigma_rad(),
                        mr=sc.meas_range(), cr=sc.comm_range(), max_delay=n.max_delay_s,
                        steering=True)
        a2 = r.agents[1]
        d = np.hypot(*(a2.position - a2.truth[:, 2, :2]).T)
        assert d.min() > 25000.0


def test_net_baseline_close_pass_near_600_s():
    sc = load_network("net-baseline")
    sim = simulate_network(0, 1, sc.target_states(0, 0), sc.agent_states(), duration=1000.0,
                           period=5.0, sigma=sc.sigma_rad())
    tr = sim.truth[0]
    d = np.hypot(*(tr[:, 0, :2] - tr[:, 1, :2]).T)
    assert d.min() < 400.0 and abs(sim.truth_time[d.argmin()] - 600.0) <= 10.0
    assert sim.bearings.in_range.all()


def test_net_limited_agents_start_in_the_steering_safe_set():
    """The steering module's condition (its docstring, 'circle' safety): every pair's
    turning-circle centres c = p + R (cos C, -sin C), R = v / w, satisfy
    R_a + R_i + 0.05 CR + margin <= |c_a - c_i| <= 0.95 CR - R_a - R_i - margin."""
    from trackkit.network.steering import Steering

    sc = load_network("net-limited")
    st = Steering()
    p = sc.agent_states()
    v = np.hypot(p[:, 2], p[:, 3])
    C = np.arctan2(p[:, 2], p[:, 3])
    R = v / st.turn_rate
    c = p[:, :2] + R[:, None] * np.stack([np.cos(C), -np.sin(C)], axis=1)
    cr = sc.comm_range()
    for a in range(3):
        for i in range(a + 1, 3):
            d = np.hypot(*(c[a] - c[i]))
            lo = R[a] + R[i] + st.r_min * min(cr[a], cr[i]) + st.margin
            hi = st.r_max * min(cr[a], cr[i]) - R[a] - R[i] - st.margin
            assert lo <= d <= hi


# --- Monte Carlo and report -------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_mc():
    sc = parse_network(_tiny())
    return sc, run_network_mc(sc)


def test_monte_carlo_shapes_and_reference(tiny_mc):
    sc, mc = tiny_mc
    assert mc.runs == 2 and mc.n_agents == 2 and mc.n_targets == 2
    E = mc.time.size
    assert E == 12 and mc.err["pos"].shape == (2, 2, E, 2)
    assert mc.central_err is not None and mc.bound_pos.shape == (2, 2, E, 2)
    assert np.all(mc.sent == 2 * E) and np.all(mc.lost == 0)
    # the bound falls as bearings accumulate
    b = mc.bound_over_time("pos", pooled=True)
    assert np.all(b[:, -1] < b[:, 0])
    # the range bound is the position bound's projection on the line of sight: at most the
    # whole position bound
    assert np.all((mc.bound_rng > 0) & (mc.bound_rng <= mc.bound_pos * (1 + 1e-12)))


def test_report_keys_and_byte_identical_results(tiny_mc, tmp_path):
    sc, mc = tiny_mc
    p1 = write_network_report(mc, sc, tmp_path / "a")
    again = run_network_mc(sc)
    p2 = write_network_report(again, sc, tmp_path / "b")
    assert p1["results"].read_bytes() == p2["results"].read_bytes()
    doc = json.loads(p1["results"].read_text())
    for key in ("scenario", "runs", "seed", "steering", "agents", "targets", "duration_s",
                "windows", "metrics", "units", "per_agent", "central_reference", "messages",
                "series"):
        assert key in doc
    assert set(doc["per_agent"][0]) == set(AGENT_UNITS)
    assert set(doc["units"]["per_agent"]) == set(AGENT_UNITS)
    assert len(doc["per_agent"][1]["rmse_pos_last"]) == 2
    assert len(doc["series"]["time_s"]) == mc.time.size
    html = p1["html"].read_text()
    assert "data:image/png;base64," in html and "<script" not in html
    assert {"paths", "errors", "gospa", "html", "timings", "results"} == set(p1)


def test_paired_comparison_of_the_same_runs(tiny_mc):
    """A Monte Carlo against itself: ratio 1, no difference; against a copy with one
    agent's errors doubled: that agent's error is "higher" (t > 0, p tiny), the other's
    unchanged; runs of another seed are refused."""
    sc, mc = tiny_mc
    same = compare_networks(mc, mc, label_a="a", label_b="b")
    np.testing.assert_array_equal(same.ratio, 1.0)
    assert same.verdict == ["no difference"] * 2 and same.verdict_all == "no difference"
    err = {k: v.copy() for k, v in mc.err.items()}
    err["pos"][:, 0] *= 2.0
    worse = replace(mc, err=err)
    c = compare_networks(worse, mc, label_a="worse", label_b="mc", confidence=0.9)
    np.testing.assert_allclose(c.ratio, [2.0, 1.0], rtol=1e-12)
    assert c.verdict[1] == "no difference"
    mse = run_mse(mc)
    assert mse.shape == (2, 2)
    d = 3.0 * mse[:, 0]  # (2e)^2 - e^2 per run
    t = d.mean() / (d.std(ddof=1) / np.sqrt(2))
    assert c.t[0] == pytest.approx(t, rel=1e-12)
    assert c.lower_share[0] == 0.0
    with pytest.raises(ValueError, match="seed differs"):
        compare_networks(mc, replace(mc, seed=mc.seed + 1), label_a="a", label_b="b")


def test_report_with_straight_courses(tiny_mc, tmp_path):
    """The steering comparison in results.json, the page and courses.png; a report without
    it drops an earlier courses.png; a straight Monte Carlo as the steered one is refused."""
    sc, _ = tiny_mc
    steered = run_network_mc(sc, steering=True)
    flat = run_network_mc(sc, steering=False, keep_example=False)
    p = write_network_report(steered, sc, tmp_path / "r", straight=flat)
    doc = json.loads(p["results"].read_text())
    c = doc["courses"]
    assert c["steering_pays"] in {"yes", "no", "not measurably"}
    assert {"yes": "lower", "no": "higher"}.get(c["steering_pays"], "no difference") == \
        c["verdict"]
    assert len(c["per_agent"]) == 2 and c["per_agent"][0]["paired_runs"] == 2
    assert c["rmse_steered_m"] == pytest.approx(np.sqrt(np.nanmean(
        np.square(steered.err["pos"][:, :, steered.window("last")]))), rel=1e-12)
    assert "Steering against straight courses" in p["html"].read_text()
    assert p["courses"].is_file()
    q = write_network_report(steered, sc, tmp_path / "r")
    assert "courses" not in q and not (tmp_path / "r" / "courses.png").exists()
    with pytest.raises(ValueError, match="steered Monte Carlo"):
        write_network_report(flat, sc, tmp_path / "x", straight=steered)


# --- the command ------------------------------------------------------------------------------


def test_cli_network_processes_with_loss_delay_and_a_kill(tmp_path):
    """--loss, --delay and --kill reach the agent processes; the report counts lost and
    late messages and the outage's recovery; the options are refused in process and with a
    bad agent or time, naming them."""
    f = tmp_path / "tiny.toml"
    f.write_text(TINY, encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "1", "--agents", "processes", "--loss",
                   "0.2", "--delay", "7", "--kill", "2@20:30", "--out", str(tmp_path / "o"))
    assert ran.code == 0, ran.text
    doc = json.loads((tmp_path / "o" / "results.json").read_text())
    m, ch = doc["messages"], doc["channel"]
    assert m["sent"] == m["delivered"] + m["lost"] and m["lost"] > 0 and m["late"] > 0
    assert ch["loss"] == 0.2 and ch["delay_s"] == 7.0
    assert ch["outages"][0]["agent"] == 2 and ch["outages"][0]["restart_at_s"] == 30.0
    assert len(ch["outages"][0]["recovered_after_s"]) == 1
    assert "agent 2 killed at 20 s" in ran.out
    for args, names in ((["--delay", "1"], ["--delay", "--agents processes"]),
                        (["--agents", "processes", "--kill", "3@10"], ["--kill", "3@10",
                                                                        "1 to 2"]),
                        (["--agents", "processes", "--kill", "1@30:20"], ["1@30:20",
                                                                           "RESTART > T"]),
                        (["--agents", "processes", "--kill", "x"], ["--kill", "'x'",
                                                                     "AGENT@T"]),
                        (["--loss", "1.5"], ["--loss", "1.5", "[0, 1)"]),
                        (["--agents", "processes", "--launch", "9=ssh x"], ["--launch",
                                                                            "9=ssh x"]),
                        (["--launch", "1=env"], ["--launch", "--agents processes"])):
        assert_user_error(trackkit("network", str(f), *args), 2, *names)


def test_cli_network_compare_straight(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY.replace("steering = false", "steering = true"), encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "2", "--compare-straight", "--out",
                   str(tmp_path / "out"))
    assert ran.code == 0, ran.text
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    assert doc["steering"] is True and "courses" in doc
    assert "steering pays:" in ran.out
    assert (tmp_path / "out" / "courses.png").is_file()
    assert_user_error(trackkit("network", str(f), "--straight", "--compare-straight"), 2,
                      "--compare-straight", "steering")



def test_cli_network_writes_its_files(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY, encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "1", "--seed", "3", "--out",
                   str(tmp_path / "out"))
    assert ran.code == 0, ran.text
    for name in ("results.json", "timings.json", "report.html", "paths.png", "errors.png",
                 "gospa.png"):
        assert (tmp_path / "out" / name).is_file()
    assert not (tmp_path / "out" / ".trackkit.lock").exists()
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    assert doc["runs"] == 1 and doc["seed"] == 3 and doc["steering"] is False
    assert "net-tiny" in ran.out and "report:" in ran.out


def test_cli_network_straight_default_directory(tmp_path):
    f = tmp_path / "tiny.toml"
    f.write_text(TINY.replace("steering = false", "steering = true"), encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "1", "--straight", cwd=tmp_path)
    assert ran.code == 0, ran.text
    doc = json.loads((tmp_path / "trackkit-out" / "tiny-straight" / "results.json")
                     .read_text())
    assert doc["steering"] is False


def test_cli_network_bad_file_and_wrong_kind(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(TINY.replace("speed_mps = 10.0", "speed_mps = 99.0", 1), encoding="utf-8")
    assert_user_error(trackkit("network", str(f), "--out", str(tmp_path / "o")), 2,
                      "bad.toml", "agents.0.speed_mps", "99.0")
    assert not (tmp_path / "o").exists()
    assert_user_error(trackkit("network", "bo-cv"), 2, "bo-cv", "trackkit run")
    assert_user_error(trackkit("network", "no-such"), 2, "no-such", "net-baseline")
    assert_user_error(trackkit("run", "net-baseline"), 2, "trackkit network net-baseline")


def test_cli_list_shows_network_scenarios():
    ran = trackkit("list")
    assert ran.code == 0
    for name in (*BUNDLED, "bo-cv", "radar-crossing"):
        assert name in ran.out


def test_inf_ranges_write_and_read_back():
    assert math.isinf(load_network("net-baseline").agents[0].comm_range_m)


def test_a_loss_outside_0_1_is_refused_naming_it(tmp_path):
    from trackkit.network.inprocess import check_loss

    assert check_loss(0.0) == 0.0 and check_loss(0.999) == 0.999
    for bad in (1.0, -0.1, math.nan):
        with pytest.raises(ValueError, match=r"loss = .*expected a probability in \[0, 1\)"):
            check_loss(bad)
    f = tmp_path / "tiny.toml"
    f.write_text(TINY, encoding="utf-8")
    ran = trackkit("network", str(f), "--runs", "1", "--loss", "1.5", "--out",
                   str(tmp_path / "out"))
    assert_user_error(ran, 2, "--loss 1.5", "[0, 1)")
