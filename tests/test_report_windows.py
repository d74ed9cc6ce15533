"""Named error windows (``[report] windows``): validated with messages that name the
field, the value and the expectation; carried into the Monte Carlo result from the per-step
sums (no accumulation of their own, the same bits for any chunking); shown in results.json,
the HTML report and the ``trackkit run`` tables."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rich.console import Console

import trackkit.scenario as S
from tests.cli_helpers import trackkit
from trackkit.experiments.montecarlo import run_scenario
from trackkit.report.html import render_html
from trackkit.report.tables import matching_rich_tables, window_summaries
from trackkit.scenario.schema import window_steps
from trackkit.scenario.toml_writer import dumps as to_toml

WINDOWS = {"transient": [50.0, 100.0], "steady": [100.0, 200.0]}


def _small(windows: dict | None = WINDOWS, runs: int = 6, block: int = 3) -> S.Scenario:
    """dbt-receding cut to 200 s and a few runs: every filter, every group, in seconds."""
    d = S.load("dbt-receding").model_dump()
    d["time"]["duration_s"] = 200.0
    d["report"]["average_from_s"] = 50.0
    d["report"]["windows"] = windows or {}
    d["run"].update(runs=runs, block=block)
    return S.parse(d, "dbt-small")


@pytest.fixture(scope="module")
def result():
    return run_scenario(_small())


def _error(windows: dict) -> str:
    d = _small().model_dump()
    d["report"]["windows"] = windows
    with pytest.raises(S.ScenarioError) as info:
        S.parse(d, "bad")
    return str(info.value)


# --- the schema -------------------------------------------------------------------------------


def test_the_bundled_dbt_scenarios_set_the_papers_two_windows():
    names = [n for n in S.bundled() if n.startswith("dbt-")]
    assert len(names) == 6
    for n in names:
        assert S.load(n).report.windows == {"transient": [600.0, 1000.0],
                                            "steady": [1000.0, 2000.0]}, n


def test_windows_default_to_none_and_keep_their_order():
    assert S.load("bo-cv").report.windows == {}
    s = _small({"b": [100.0, 200.0], "a": [50.0, 100.0]})
    assert list(s.report.windows) == ["b", "a"]


@pytest.mark.parametrize("windows, words", [
    ({"t": [100.0, 50.0]}, ["report.windows.t", "[100, 50]", "start_s < end_s"]),
    ({"t": [50.0, 50.0]}, ["report.windows.t", "[50, 50]", "start_s < end_s"]),
    ({"late": [100.0, 250.0]}, ["report.windows.late", "[100, 250]", "duration_s = 200",
                                "end_s <= 200"]),
    ({"tiny": [10.2, 10.8]}, ["report.windows.tiny", "[10.2, 10.8]", "holds no measurement",
                              "at least one"]),
    ({"1st": [50.0, 100.0]}, ["report.windows.1st", "'1st'", "starting with a letter"]),
    ({"a b": [50.0, 100.0]}, ["'a b'", "letters, digits"]),
    ({"t": [-5.0, 100.0]}, ["report.windows.t", "-5", "greater than or equal to 0"]),
    ({"t": [50.0, 100.0, 150.0]}, ["report.windows.t", "[50.0, 100.0, 150.0]", "3 values",
                                   "expected 2, [start_s, end_s]"]),
    ({"t": [50.0]}, ["report.windows.t", "[50.0]", "expected 2, [start_s, end_s]"]),
    ({"t": ["soon", 100.0]}, ["report.windows.t", "soon", "number"]),
])
def test_bad_windows_are_named_with_their_value_and_expectation(windows, words):
    message = _error(windows)
    for w in words:
        assert w in message, (w, message)


def test_window_steps_are_half_open_but_keep_the_last_measurement():
    # measurement k is at t = (k + 1) step_s
    assert window_steps(600.0, 1000.0, 2000, 1.0) == (599, 999)  # t = 600 .. 999
    assert window_steps(1000.0, 2000.0, 2000, 1.0) == (999, 2000)  # t = 1000 .. 2000
    assert window_steps(0.0, 2.0, 2000, 1.0) == (0, 1)  # t = 1
    assert window_steps(0.25, 0.55, 10, 0.1) == (2, 5)  # t = 0.3, 0.4, 0.5 (rounding-safe)
    assert window_steps(0.5, 0.6, 10, 0.1)[1] - window_steps(0.5, 0.6, 10, 0.1)[0] == 1


def test_windows_survive_the_toml_round_trip():
    s = _small()
    import tomllib

    again = S.parse(tomllib.loads(to_toml(s)), "again")
    assert again.report.windows == s.report.windows


# --- the result ---------------------------------------------------------------------------------


def test_window_numbers_are_the_per_step_ones_averaged(result):
    r = result
    for w, (a, b) in WINDOWS.items():
        k0, k1 = r.window_steps[w]
        assert r.windows[w] == (a, b)  # a tuple in the result
        assert r.times[k0] == a and r.times[k1 - 1] == (b - 1 if b < 200 else 200.0)
        for g, bound in r.pcrlb.items():
            assert r.pcrlb_windows[w][g] == pytest.approx(
                np.sqrt(np.mean(bound[k0:k1] ** 2)), rel=1e-14)
        for name, f in r.filters.items():
            fw = f.windows[w]
            for g in r.groups:
                assert fw["rmse"][g] == pytest.approx(
                    np.sqrt(np.mean(f.rmse[g][k0:k1] ** 2)), rel=1e-12), (w, name, g)
                assert r.efficiency(name, g, w) == pytest.approx(
                    fw["rmse"][g] / r.pcrlb_windows[w][g], rel=1e-15)
            assert fw["anees"] == pytest.approx(np.mean(f.nees[k0:k1]), rel=1e-13)
            assert fw["anis"] == pytest.approx(np.nanmean(f.nis[k0:k1]), rel=1e-13)
            assert 0.0 <= fw["nees_in_bounds"] <= 1.0


def test_a_window_from_average_from_s_to_the_end_is_the_summary_bit_for_bit():
    r = run_scenario(_small({"all": [50.0, 200.0]}, runs=3, block=3))
    for f in r.filters.values():
        fw = f.windows["all"]
        assert fw["rmse"] == f.rmse_mean
        assert fw["anees"] == f.anees and fw["anis"] == f.anis
        assert fw["nees_in_bounds"] == f.nees_in_bounds
    assert r.pcrlb_windows["all"] == r.pcrlb_mean


def test_windows_change_no_other_number(result):
    plain = run_scenario(_small(None)).to_json_dict()
    doc = result.to_json_dict()
    windows = doc.pop("windows")
    assert "windows" not in plain
    for d in (doc, plain):
        for f in d["filters"].values():
            f.pop("seconds_per_step")
    assert doc == plain
    assert set(windows) == set(WINDOWS)
    assert windows["steady"]["steps"] == 101 and windows["transient"]["steps"] == 50
    json.dumps(windows, allow_nan=False)


def test_window_numbers_are_the_same_bits_for_any_chunking(result):
    # the windows are read from the exact per-step sums: chunks of one block or of two
    # (and any executor, which sees the same blocks) give the same bits
    for chunk in (3, 6):
        again = run_scenario(_small(), chunk=chunk)
        assert again.to_json_dict()["windows"] == result.to_json_dict()["windows"], chunk


# --- the report ---------------------------------------------------------------------------------


def test_window_tables_one_per_window_with_the_bound_row(result):
    tables = window_summaries(result)
    assert [t.title for t in tables] == ["Error window transient: 50-100 s",
                                         "Error window steady: 100-200 s"]
    for t in tables:
        assert [row[0] for row in t.rows] == [*result.filters, "PCRLB"]
        assert "RMSE/PCRLB\nposition" in t.headers and "ANEES" in t.headers
        assert t.sections == [len(result.filters) - 1]
    assert "t = 100 to 200 s (101 steps)" in tables[1].caption
    assert window_summaries(run_scenario(_small(None, runs=2, block=2))) == []


def test_window_tables_fit_a_narrow_console_by_transposing(result):
    wide, narrow = Console(width=250, record=True), Console(width=90, record=True)
    for console in (wide, narrow):
        for table in matching_rich_tables(result, width=console.width):
            console.print(table)
    text = narrow.export_text()
    assert "Error window steady: 100-200 s" in text
    assert "RMSE/PCRLB position" in text  # a row label when transposed
    assert max(len(line) for line in text.splitlines()) <= 90
    assert "RMSE/PCRLB position" not in wide.export_text()  # headers on two lines when wide


def test_html_report_has_the_window_tables(result):
    page = render_html(result, {})
    assert "<h2>Error windows</h2>" in page
    assert "<h3>Error window transient: 50-100 s</h3>" in page
    assert page.count('<tr class="bound"><th>PCRLB</th>') == 3  # summary and two windows


def test_trackkit_run_prints_the_window_tables(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(to_toml(_small(runs=2, block=2)), encoding="utf-8")
    ran = trackkit("run", str(path), "--out", str(tmp_path / "out"))
    assert ran.code == 0, ran.text
    assert "Error window transient: 50-100 s" in ran.out
    assert "Error window steady: 100-200 s" in ran.out
    doc = json.loads((tmp_path / "out" / "results.json").read_text())
    assert set(doc["windows"]) == {"transient", "steady"}
