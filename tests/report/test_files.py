"""Report files: results.json schema, metrics.parquet layout, self-contained HTML, atomicity."""

from __future__ import annotations

import base64
import json
import math
import re

import numpy as np
import pyarrow.parquet as pq
import pytest

from trackkit.report import files, plots

from . import FILTERS, GROUPS, fake_result
from .test_plots import png_size

ALL_FILES = {"results.json", "timings.json", "metrics.parquet", "geometry.png", "rmse.png",
             "nees.png", "report.html"}
FILTER_KEYS = {"rmse", "anees", "anis", "nees_in_bounds", "diverged"}


def check_results_json(doc: dict) -> None:
    """The results.json schema (shared with the CLI tests): SI values whose
    units are named, the averaging window in seconds, no wall-clock timings."""
    assert set(doc) == {"scenario", "runs", "seed", "steps", "dt", "window", "units", "filters",
                        "pcrlb"}
    assert isinstance(doc["scenario"], str)
    for key in ("runs", "seed", "steps"):
        assert isinstance(doc[key], int) and not isinstance(doc[key], bool)
    assert isinstance(doc["dt"], float)
    window = doc["window"]
    assert set(window) == {"from_s", "to_s", "first_step", "steps"}
    assert 0.0 <= window["from_s"] <= window["to_s"]
    assert 1 <= window["steps"] == doc["steps"] - window["first_step"]
    assert doc["filters"]
    units = doc["units"]
    for entry in doc["filters"].values():
        assert set(entry) == FILTER_KEYS
        assert {"position", "velocity"} <= set(entry["rmse"])
        assert all(isinstance(v, float) for v in entry["rmse"].values())
        assert set(entry["rmse"]) <= set(units["rmse"])
        for key in ("anees", "anis", "nees_in_bounds"):
            assert entry[key] is None or isinstance(entry[key], float)
        assert isinstance(entry["diverged"], int)
    assert {"position", "velocity"} <= set(doc["pcrlb"])
    assert all(v is None or isinstance(v, float) for v in doc["pcrlb"].values())
    assert set(doc["pcrlb"]) == set(units["pcrlb"])
    assert units["rmse"]["position"] == "m" and units["rmse"]["velocity"] == "m/s"
    for key in ("dt", "window", "anees", "anis", "nees_in_bounds", "diverged"):
        assert units[key], key
    assert "seconds" not in json.dumps(doc)  # wall-clock times live in timings.json


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """One report written into a new nested directory: (result, out dir, returned paths)."""
    r = fake_result()
    out = tmp_path_factory.mktemp("report") / "a" / "b"
    return r, out, files.write_report(r, out)


def test_write_report_all_files(written):
    _, out, paths = written
    assert {p.name for p in paths.values()} == ALL_FILES
    assert all(p.parent == out for p in paths.values())
    assert {p.name for p in out.iterdir()} == ALL_FILES  # nothing else (no marker, no temp)
    assert [p.name for p in out.parent.iterdir()] == ["b"]
    for name in ("geometry.png", "rmse.png", "nees.png"):
        assert (out / name).stat().st_size > 5_000
        png_size(out / name)


def test_results_json_schema_and_values(written):
    r, out, _ = written
    doc = json.loads((out / "results.json").read_text())
    check_results_json(doc)
    expected = r.to_json_dict()
    for entry in expected["filters"].values():
        entry.pop("seconds_per_step")
    assert {k: doc[k] for k in expected} == expected
    assert set(doc["filters"]) == set(FILTERS)
    assert doc["filters"]["UKF"]["diverged"] == 1
    # course is SI (radians), and says so
    assert doc["filters"]["EKF"]["rmse"]["course"] == r.filters["EKF"].rmse_mean["course"]
    assert doc["units"]["rmse"]["course"] == doc["units"]["pcrlb"]["course"] == "rad"
    assert doc["pcrlb"]["position"] == pytest.approx(r.pcrlb_mean["position"])
    # the averaging window: from the time of step `start` to the last step
    assert doc["window"] == {"from_s": float(r.times[r.start]), "to_s": float(r.times[-1]),
                             "first_step": r.start, "steps": r.steps - r.start}


def test_timings_json(written):
    r, out, _ = written
    doc = json.loads((out / "timings.json").read_text())
    assert doc["seconds_per_step"] == {n: f.seconds_per_step for n, f in r.filters.items()}
    assert doc["units"]["seconds_per_step"].startswith("s ")
    assert "tuning_seconds" not in doc  # nothing was tuned


def test_results_json_does_not_depend_on_timings(tmp_path):
    a, b = fake_result(), fake_result()
    b.filters["EKF"].seconds_per_step *= 7
    for r, name in ((a, "a"), (b, "b")):
        files.write_results_json(r, tmp_path / f"{name}.json")
        files.write_timings_json(r, tmp_path / f"t{name}.json")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    assert (tmp_path / "ta.json").read_bytes() != (tmp_path / "tb.json").read_bytes()


def test_results_json_is_strict_json(tmp_path):
    r = fake_result()
    r.filters["EKF"].anis = float("nan")
    r.pcrlb_mean["course"] = float("inf")
    text = files.write_results_json(r, tmp_path / "results.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    doc = json.loads(text)
    assert doc["filters"]["EKF"]["anis"] is None and doc["pcrlb"]["course"] is None


def test_metrics_parquet(written):
    r, out, _ = written
    table = pq.read_table(out / "metrics.parquet")
    groups = list(GROUPS)
    assert table.column_names == [
        "filter", "step", "time", *(f"rmse_{g}" for g in groups), "nees", "nis", "nees_lo",
        "nees_hi", "nis_lo", "nis_hi", *(f"pcrlb_{g}" for g in groups)]
    assert table.num_rows == len(FILTERS) * r.steps
    df = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    assert list(dict.fromkeys(df["filter"])) == list(FILTERS)
    ukf = df["filter"] == "UKF"
    np.testing.assert_array_equal(df["step"][ukf], np.arange(r.steps))
    np.testing.assert_array_equal(df["time"][ukf], r.times)
    np.testing.assert_array_equal(df["rmse_course"][ukf], r.filters["UKF"].rmse["course"])
    np.testing.assert_array_equal(df["nees"][ukf], r.filters["UKF"].nees)
    np.testing.assert_array_equal(df["nis"][ukf], r.filters["UKF"].nis)  # nan kept
    np.testing.assert_array_equal(df["nees_hi"][ukf], r.filters["UKF"].nees_bounds[1])
    np.testing.assert_array_equal(df["pcrlb_position"][ukf], r.pcrlb["position"])
    assert table.schema.field("rmse_course").metadata[b"unit"] == b"rad"
    assert table.schema.field("pcrlb_velocity").metadata[b"unit"] == b"m/s"
    meta = json.loads(table.schema.metadata[b"trackkit"])
    assert meta["runs"] == r.runs and meta["start"] == r.start and meta["groups"] == GROUPS


def test_metrics_rejects_wrong_lengths():
    r = fake_result()
    r.filters["EKF"].nees = r.filters["EKF"].nees[:-1]
    with pytest.raises(ValueError, match="EKF nees: 49 values for 50 steps"):
        files.metrics_table(r)


def test_html_is_self_contained(written):
    r, out, _ = written
    page = (out / "report.html").read_text(encoding="utf-8")
    uris = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(uris) == 3
    for name, uri in zip(("geometry", "rmse", "nees"), uris, strict=True):
        assert base64.b64decode(uri) == (out / f"{name}.png").read_bytes()
    assert not re.search(r"https?:", page)
    assert not re.search(r"<(script|link|iframe)\b", page, re.IGNORECASE)
    assert not re.search(r'(src|href)="(?!data:)', page)  # nothing fetched from anywhere
    assert r.description in page and "<h1>fake_bot</h1>" in page
    assert "20 Monte Carlo runs, seed 7" in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt; notes are escaped" in page
    assert "PCRLB assumes the prior covariance" in page
    assert '<table class="summary">' in page and "RMSE course<br>[deg]" in page
    assert "<h2>Glossary</h2>" in page
    for term in ("ANEES", "ANIS", "NEES in 95% bounds", "Diverged", "Time per run-step"):
        assert f"<dt>{term}</dt>" in page


def test_failure_mid_write_leaves_no_partial_results(tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(plots, "plot_nees", broken)
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="disk on fire"):
        files.write_report(fake_result(), out)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # the temporary directory is gone too


def test_failure_keeps_the_previous_complete_report(tmp_path, monkeypatch):
    out = tmp_path / "out"
    files.write_report(fake_result(runs=20), out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    monkeypatch.setattr(plots, "plot_rmse", lambda *a, **k: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        files.write_report(fake_result(runs=99), out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert json.loads((out / "results.json").read_text())["runs"] == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_existing_directory_replaces_only_trackkit_files(tmp_path):
    out = tmp_path / "out"
    files.write_report(fake_result(runs=20), out)
    (out / "mine.txt").write_text("keep me")
    files.write_report(fake_result(runs=5, example=False), out)
    names = {p.name for p in out.iterdir()}
    assert names == (ALL_FILES - {"geometry.png"}) | {"mine.txt"}  # stale geometry removed
    assert (out / "mine.txt").read_text() == "keep me"
    assert json.loads((out / "results.json").read_text())["runs"] == 5
    assert files.INCOMPLETE not in names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_out_path_that_is_a_file(tmp_path):
    target = tmp_path / "results"
    target.write_text("not a directory")
    with pytest.raises(ValueError, match="is not a directory"):
        files.write_report(fake_result(), target)
    assert target.read_text() == "not a directory"


def test_efficiency_consistent_with_json():
    r = fake_result()
    doc = files.results_document(r)
    for name in FILTERS:
        for g in GROUPS:
            eff = doc["filters"][name]["rmse"][g] / doc["pcrlb"][g]
            assert math.isclose(eff, r.efficiency(name, g))


def test_nothing_is_written_beside_the_output_directory(tmp_path, monkeypatch):
    """The temporary files live inside the output directory, never next to it."""
    out = tmp_path / "out"
    out.mkdir()
    seen = []
    make_plots = plots.make_plots

    def watching(*args, **kwargs):
        seen.append(sorted(p.name for p in tmp_path.iterdir()))
        return make_plots(*args, **kwargs)

    monkeypatch.setattr(plots, "make_plots", watching)
    files.write_report(fake_result(), out)
    assert seen == [["out"]]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert {p.name for p in out.iterdir()} == ALL_FILES
