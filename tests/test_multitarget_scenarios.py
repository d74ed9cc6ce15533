"""Multi-target scenarios: the schema and its messages, the bundled files, the
driver and the report files."""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest

from trackkit.experiments.tracking_mc import run_tracking
from trackkit.experiments.tracking_run import run_multitarget
from trackkit.report.tracking_report import write_tracking_report
from trackkit.scenario import ScenarioError
from trackkit.scenario.multitarget import (
    MultiTargetScenario,
    build,
    bundled_multitarget,
    is_multitarget,
    load_multitarget,
    parse_multitarget,
    scan_period,
)
from trackkit.sim.scene import Scene
from trackkit.tracking import GNN, JPDA, ScoreLogic, SinglePoint, Tracker

BUNDLED = ("radar-crossing", "radar-clutter", "radar-dense")
PNG = b"\x89PNG\r\n\x1a\n"


def _crossing(**run) -> MultiTargetScenario:
    sc = load_multitarget("radar-crossing")
    return sc.model_copy(update={"run": sc.run.model_copy(update=run)}) if run else sc


# --- the bundled files ---------------------------------------------------------------------


def test_bundled_names_and_descriptions():
    names = bundled_multitarget()
    assert set(BUNDLED) <= set(names)
    assert all(names[n] for n in BUNDLED)


@pytest.mark.parametrize("name", BUNDLED)
def test_every_bundled_file_loads_and_builds(name):
    sc = load_multitarget(name)
    assert sc.name == name and sc.notes
    assert {t.associator for t in sc.trackers} == {"GNN", "JPDA"}
    scene, trackers = build(sc)
    assert isinstance(scene, Scene)
    assert list(trackers) == [t.name for t in sc.trackers]
    assert all(isinstance(t, Tracker) for t in trackers.values())
    assert len(scene.targets) == {"radar-crossing": 3, "radar-clutter": 10,
                                  "radar-dense": 200}[name]
    if name == "radar-dense":
        assert sc.run.runs <= 10  # for scale: few runs


def test_build_matches_the_statistical_tests_configuration():
    sc = load_multitarget("radar-clutter")
    scene, trackers = build(sc)
    lam = scene.clutter_density[0]
    t = trackers["JPDA"]
    assert np.all(t.motion.q == 10.0) and t.pd == 0.9 and t.clutter_density == lam
    assert isinstance(t.associator, JPDA) and isinstance(trackers["GNN"].associator, GNN)
    assert t.logic == ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=0.9, clutter_density=lam,
                                           new_target_density=4e-7)
    assert t.initiator == SinglePoint(v_std=100.0)
    assert scan_period(scene) == 4.0


def test_is_multitarget(tmp_path):
    assert all(is_multitarget(n) for n in BUNDLED)
    assert not is_multitarget("bo-cv")  # a single-target scenario
    assert not is_multitarget("no-such-scenario")
    f = tmp_path / "mine.toml"
    f.write_text('name = "mine"\n[scene]\nbuilder = "radar_crossing"\nq = 0.0\n')
    assert is_multitarget(f)
    (tmp_path / "bad.toml").write_text("not = [toml")
    assert not is_multitarget(tmp_path / "bad.toml")


def test_unknown_bundled_name_lists_the_bundled_ones():
    with pytest.raises(ScenarioError, match="radar-crossing"):
        load_multitarget("radar-crosing")


# --- validation messages -------------------------------------------------------------------


def _bad(change) -> str:
    data = copy.deepcopy(load_multitarget("radar-crossing").model_dump(exclude_none=True))
    change(data)
    with pytest.raises(ScenarioError) as err:
        parse_multitarget(data, "mine.toml")
    return str(err.value)


def _history(t: dict, **kw) -> None:
    for k in ("alpha", "beta", "new_target_density"):
        t.pop(k)
    t.update(logic="history", **kw)


@pytest.mark.parametrize("change, field, value", [
    (lambda d: d["scene"].update(builder="radar_swarm"), "scene.builder", "'radar_swarm'"),
    (lambda d: d["scene"].update(pd=0), "scene.pd", "0"),
    (lambda d: d["trackers"][1].update(associator="MHT"), "trackers.1.associator", "'MHT'"),
    (lambda d: _history(d["trackers"][0], confirm=[4, 3]), "trackers.0.confirm", "[4, 3]"),
    (lambda d: d["trackers"][1].update(cost="distance"), "trackers.1.cost", "'distance'"),
    (lambda d: d["trackers"][0].update(missed_distance=10.0), "trackers.0.missed_distance",
     "10.0"),
    (lambda d: d["trackers"][0].update(cost="distance", missed_distance=0.0),
     "trackers.0.missed_distance", "0.0"),
    (lambda d: d["scene"].update(n=50), "scene.n", "50"),
    (lambda d: d["trackers"][0].update(filter="KF"), "trackers.0.filter", "'KF'"),
    (lambda d: d["trackers"][1].update(name="GNN"), "trackers.1.name", "'GNN'"),
    (lambda d: d["trackers"][0].update(v_max_mps=300.0), "trackers.0.v_max_mps", "300.0"),
    (lambda d: d["report"].update(ospa_p=0.5), "report.ospa_p", "0.5"),
    (lambda d: d["run"].update(runs=0), "run.runs", "0"),
    (lambda d: d.update(colour="red"), "colour", "'red'"),
    (lambda d: d.update(name="../x"), "name", "'../x'"),
])
def test_bad_fields_are_named_with_their_values(change, field, value):
    msg = _bad(change)
    assert msg.startswith("mine.toml: 1 problem(s)"), msg
    assert f"  {field} = {value}: " in msg, msg


def test_the_old_cost_name_is_refused_naming_the_new_one():
    msg = _bad(lambda d: d["trackers"][0].update(cost="seed004"))
    assert "  trackers.0.cost = 'seed004': cost 'seed004' is now spelled 'saturating'" in msg, msg


def test_no_clutter_needs_the_trackers_clutter_density():
    msg = _bad(lambda d: d["scene"].update(clutter_per_scan=0.0))
    assert "trackers.0.clutter_density = (missing)" in msg and "no clutter" in msg
    data = load_multitarget("radar-crossing").model_dump(exclude_none=True)
    data["scene"]["clutter_per_scan"] = 0.0
    for t in data["trackers"]:
        t["clutter_density"] = 1e-6
    _, trackers = build(parse_multitarget(data))
    assert trackers["GNN"].clutter_density == 1e-6


def test_other_filters_logics_and_initiators_build_and_track():
    data = load_multitarget("radar-crossing").model_dump(exclude_none=True)
    data["trackers"] = [
        {"name": "UKF", "filter": "UKF", "q": 1.0, "associator": "GNN", "cost": "distance",
         "missed_distance": 10.0, "logic": "history", "confirm": [2, 3], "delete": [3, 3],
         "initiator": "two-point",
         "v_max_mps": 60.0, "margin_m": 100.0, "p_gate": 0.995},
        {"name": "CKF", "filter": "CKF", "q": 1.0, "associator": "JPDA"},
    ]
    sc = parse_multitarget(data)
    scene, trackers = build(sc)
    assert trackers["UKF"].initiator.v_max == 60.0 and trackers["UKF"].p_gate == 0.995
    assert trackers["UKF"].logic.confirm == (2, 3)
    assert trackers["UKF"].associator == GNN(cost="distance", missed_distance=10.0)
    assert trackers["CKF"].initiator == SinglePoint(v_std=100.0)  # the defaults
    result = run_tracking(scene, trackers, runs=1, seed=1, c=500.0, within=15.0)
    for tr in result.trackers.values():
        assert tr.summary["truths"] == 3 and np.all(np.isfinite(tr.gospa))


# --- the driver ----------------------------------------------------------------------------


def _same(a, b) -> None:
    assert a.trackers.keys() == b.trackers.keys()
    for name in a.trackers:
        x, y = a.trackers[name], b.trackers[name]
        for f in ("gospa", "ospa", "confirmed"):
            np.testing.assert_array_equal(getattr(x, f), getattr(y, f))
        for k in x.gospa_parts:
            np.testing.assert_array_equal(x.gospa_parts[k], y.gospa_parts[k])
        assert x.summary == pytest.approx(y.summary, rel=0, abs=0, nan_ok=True)
        assert x.approximated == y.approximated


def test_same_result_for_block_1_and_block_4():
    sc = _crossing()
    one, ex = run_multitarget(sc, runs=4, seed=5, block=1)
    four, _ = run_multitarget(sc, runs=4, seed=5, block=4)
    _same(one, four)
    assert one.runs == 4 and one.within == 15.0 and one.c == 500.0
    assert ex.run.run == 0 and set(ex.histories) == {"GNN", "JPDA", "JPDA*"}


def test_the_driver_is_run_tracking_with_the_files_settings_and_ospa_p_counts():
    sc = _crossing()
    scene, trackers = build(sc)
    ours, _ = run_multitarget(sc, runs=2, seed=9)
    _same(ours, run_tracking(scene, trackers, runs=2, seed=9, c=500.0, within=15.0))
    sc2 = sc.model_copy(update={"report": sc.report.model_copy(update={"ospa_p": 2.0})})
    p2, _ = run_multitarget(sc2, runs=2, seed=9)
    for name in trackers:  # a power mean grows with its order
        assert np.all(p2.trackers[name].ospa >= ours.trackers[name].ospa - 1e-9)
        assert np.mean(p2.trackers[name].ospa) > np.mean(ours.trackers[name].ospa)
        np.testing.assert_array_equal(p2.trackers[name].gospa, ours.trackers[name].gospa)


# --- the report ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    sc = _crossing(runs=2)
    result, example = run_multitarget(sc)
    out = tmp_path_factory.mktemp("mt") / "radar-crossing"
    return sc, result, example, out, write_tracking_report(result, sc, example, out)


def test_report_writes_every_file(report):
    _, _, _, out, paths = report
    names = {"results.json", "timings.json", "metrics.parquet", "xy.png", "gospa.png",
             "report.html"}
    assert {p.name for p in paths.values()} == names
    assert {p.name for p in out.iterdir()} == names  # no temporary or marker left


def test_results_json_schema_and_units(report):
    sc, result, _, out, _ = report
    doc = json.loads((out / "results.json").read_text())
    assert doc["scenario"] == "radar-crossing" and doc["kind"] == "multi-target"
    assert doc["runs"] == 2 and doc["seed"] == sc.run.seed and doc["scans"] == 101
    assert doc["metrics"] == {"c_m": 500.0, "ospa_p": 1.0, "gospa_p": 2.0,
                              "gospa_alpha": 2.0, "confirm_within_scans": 5.0,
                              "confirm_within_s": 15.0}
    assert doc["scene"]["targets"] == 3
    units = doc["units"]["trackers"]
    assert set(doc["trackers"]) == {"GNN", "JPDA", "JPDA*"}
    for name, entry in doc["trackers"].items():
        assert list(entry) == list(units)  # every number has its unit
        assert all(isinstance(v, int | float) or v is None for v in entry.values())
        tr = result.trackers[name]
        assert entry["gospa"] == pytest.approx(np.mean(tr.gospa), rel=1e-15)
        assert entry["gospa_rms"] ** 2 == pytest.approx(
            entry["gospa_localisation"] + entry["gospa_missed"] + entry["gospa_false"])
        assert entry["truths"] == 6 and 0 <= entry["completeness"] <= 1
        assert entry["false_tracks_per_100_scans"] == pytest.approx(
            100 * entry["false_tracks"] / 202)
    assert doc["trackers"]["GNN"]["jpda_clusters_approximated"] == 0
    for key in ("gospa", "rmse", "mean_confirm_delay", "mean_purity", "id_switches"):
        assert key in units
    timings = json.loads((out / "timings.json").read_text())
    assert set(timings["seconds_per_scan"]) == {"GNN", "JPDA", "JPDA*"}
    assert "seconds" not in (out / "results.json").read_text()


def test_metrics_parquet_columns(report):
    _, result, example, out, _ = report
    t = pq.read_table(out / "metrics.parquet")
    assert t.column_names == ["tracker", "scan", "time", "truths", "gospa",
                              "gospa_localisation", "gospa_missed", "gospa_false", "ospa",
                              "confirmed"]
    assert t.num_rows == 3 * 101  # three trackers x 101 scans
    assert t.schema.field("gospa").metadata[b"unit"] == b"m"
    assert t.schema.field("gospa_missed").metadata[b"unit"] == b"m^2"
    meta = json.loads(t.schema.metadata[b"trackkit"])
    assert meta["runs"] == 2 and meta["c_m"] == 500.0
    d = t.to_pydict()
    np.testing.assert_array_equal(d["gospa"][:101], result.trackers["GNN"].gospa)
    np.testing.assert_array_equal(d["truths"][:101], example.run.truth.sizes)


def test_pngs_are_valid(report):
    _, _, _, out, _ = report
    for name in ("xy.png", "gospa.png"):
        raw = (out / name).read_bytes()
        assert raw.startswith(PNG) and raw.rstrip().endswith(b"IEND\xaeB`\x82")
        width, height = int.from_bytes(raw[16:20], "big"), int.from_bytes(raw[20:24], "big")
        assert width > 300 and height > 300


def test_html_is_self_contained(report):
    sc, _, _, out, _ = report
    page = (out / "report.html").read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert "<script" not in page and "<link" not in page and "href=" not in page
    assert "url(" not in page
    srcs = re.findall(r'src="([^"]*)"', page)
    assert len(srcs) == 2 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r"(?:https?|ftp)://", re.sub(r'src="data:[^"]*"', "", page))
    for text in ("GOSPA", "OSPA", "ID switches", "track purity", "Glossary", sc.notes[0][:40]):
        assert text.lower() in page.lower(), text


def test_equal_seeds_give_byte_identical_results_json(report, tmp_path):
    sc, _, _, out, _ = report
    result, example = run_multitarget(sc)
    again = write_tracking_report(result, sc, example, tmp_path / "again")
    assert again["results"].read_bytes() == (out / "results.json").read_bytes()


def test_report_without_example_has_no_xy(report, tmp_path):
    sc, result, _, _, _ = report
    paths = write_tracking_report(result, sc, None, tmp_path / "noex")
    assert "xy" not in paths and not (tmp_path / "noex" / "xy.png").exists()
    assert (tmp_path / "noex" / "results.json").is_file()


@pytest.mark.slow
def test_radar_dense_runs_one_run(tmp_path):
    sc = load_multitarget("radar-dense")
    result, example = run_multitarget(sc, runs=1)
    paths = write_tracking_report(result, sc, example, tmp_path / "dense")
    doc = json.loads(paths["results"].read_text())
    assert doc["scene"]["targets"] == 200 and doc["trackers"]["GNN"]["truths"] == 200


def test_trackkit_run_runs_a_multitarget_scenario_and_show_round_trips(tmp_path):
    # the real command: `trackkit list` shows the scenes, `show` prints TOML that `run` reads
    from tests.cli_helpers import trackkit

    listed = trackkit("list", cwd=tmp_path)
    assert listed.code == 0 and all(n in listed.out for n in bundled_multitarget())
    shown = trackkit("show", "radar-crossing", cwd=tmp_path)
    assert shown.code == 0
    (tmp_path / "mine.toml").write_text(shown.out)
    assert load_multitarget(tmp_path / "mine.toml") == load_multitarget("radar-crossing")
    ran = trackkit("run", str(tmp_path / "mine.toml"), "--runs", "2", "--out", "o",
                   cwd=tmp_path)
    assert ran.code == 0, ran.text
    assert "GOSPA [m]" in ran.out and "JPDA" in ran.out
    doc = json.loads((tmp_path / "o" / "results.json").read_text())
    assert set(doc["trackers"]) == {"GNN", "JPDA", "JPDA*"} and doc["runs"] == 2
