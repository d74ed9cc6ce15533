"""``trackkit track`` on awkward input, through the real command in a subprocess: a run that
confirms no track, a byte that is not UTF-8, a corrupt Parquet file, and finite but absurd
values. Each checks the exit code, the words of the message (file, line, field, value), that no
traceback or numpy warning leaks, and which files exist afterwards."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from ..cli_helpers import assert_user_error, trackkit

AIS_HEADER = "Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots"
# the AIS tracker's IMM carries the turn rate (rad/s) as a fifth state component
TRACK_COLUMNS = ["id", "scan", "time", "time_utc", "x", "y", "vx", "vy", "turn_rate", "var_x",
                 "var_y", "var_vx", "var_vy", "var_turn_rate", "status", "lat", "lon",
                 "x_smooth", "y_smooth", "vx_smooth", "vy_smooth", "turn_rate_smooth",
                 "var_x_smooth", "var_y_smooth", "var_vx_smooth", "var_vy_smooth",
                 "var_turn_rate_smooth", "lat_smooth", "lon_smooth"]
RADAR_FILES = {"tracks.parquet", "tracks.csv", "tracks.geojson", "tracks.png", "gospa.png",
               "tracks_summary.csv", "report.html", "results.json", "manifest.json"}


def _ais_lines(n_vessels: int = 4, minutes: float = 3.0) -> list[str]:
    """Vessels sailing straight near 50.8 N 1.1 W, a report from each every 3 s."""
    rng = np.random.default_rng(7)
    lines = [AIS_HEADER]
    start = np.datetime64("2016-01-12T13:02:11", "ms")
    for k in range(int(minutes * 20)):
        for v in range(n_vessels):
            t = start + np.timedelta64(3000 * k + 100 * v, "ms")
            lat = 50.80 + 0.01 * v + 2e-5 * k
            lon = -1.10 + 0.015 * v + 3e-5 * k
            lines.append(f"{str(t).replace('T', ' ')},{235000000 + v},{lat:.6f},{lon:.6f},"
                         f"{45 + rng.normal(0, 1):.1f},{8 + rng.normal(0, 0.1):.1f}")
    return lines


def _names(out: Path) -> set[str]:
    return {p.name for p in out.iterdir()}


# --- a run that confirms no track ----------------------------------------------------------


def test_no_confirmed_track_is_a_result_not_a_bug(tmp_path):
    f = tmp_path / "ais.csv"
    f.write_text("\n".join(_ais_lines()) + "\n", encoding="utf-8")
    out = tmp_path / "two"
    ran = trackkit("track", str(f), "--as-radar", "--max-scans", "2", "--out", str(out),
                   cwd=tmp_path)
    assert_user_error(ran, 0, "0 confirmed of", "No track was confirmed", "position RMSE n/a")
    assert "trackkit bug" not in ran.text and "error" not in ran.text
    assert _names(out) == RADAR_FILES  # no lock, no skipped.csv, nothing half-written
    # the tentative states of the tracks started, as in any run; none confirmed
    for table in (pacsv.read_csv(out / "tracks.csv"), pq.read_table(out / "tracks.parquet")):
        assert table.column_names == TRACK_COLUMNS and table.num_rows > 0
        assert set(table["status"].to_pylist()) == {"tentative"}
    geo = json.loads((out / "tracks.geojson").read_text())
    assert [f["properties"]["kind"] for f in geo["features"]] == ["radar site"]
    doc = json.loads((out / "results.json").read_text())
    res = doc["results"]
    assert res["scans"] == 2 and res["tracks_confirmed"] == 0 and res["tracks_started"] > 0
    assert res["tracks"]["rmse"] is None and res["tracks"]["truths_confirmed"] == 0
    page = (out / "report.html").read_text()
    assert "No track was confirmed" in page and "None" not in page

    # no plot at all (nothing in range, no clutter): track files with their columns, no rows
    out = tmp_path / "none"
    ran = trackkit("track", str(f), "--as-radar", "--clutter", "0", "--min-range", "1",
                   "--max-range", "2", "--out", str(out), cwd=tmp_path)
    assert_user_error(ran, 0, "0 confirmed of 0 started", "No track was confirmed")
    assert _names(out) == RADAR_FILES
    assert (out / "tracks.csv").read_text().splitlines() == [",".join(TRACK_COLUMNS)]
    table = pq.read_table(out / "tracks.parquet")
    assert table.column_names == TRACK_COLUMNS and table.num_rows == 0


# --- a corrupt Parquet file ------------------------------------------------------------------


def test_corrupt_parquet_is_named(tmp_path):
    rng = np.random.default_rng(0)
    n = 3000
    table = pa.table({"time": np.repeat(np.arange(n // 3, dtype=float), 3),
                      "x": rng.normal(0, 1e3, n), "y": rng.normal(0, 1e3, n)})
    good = tmp_path / "good.parquet"
    pq.write_table(table, good, row_group_size=1000, compression="snappy")
    raw = bytearray(good.read_bytes())
    cases = {"noise.parquet": bytes(rng.integers(0, 256, 400, dtype=np.uint8)),
             "cut.parquet": bytes(raw[: len(raw) // 2]),
             # the footer intact, the second row group's pages overwritten
             "pages.parquet": bytes(raw[: len(raw) // 2] + b"\x55" * (len(raw) // 4)
                                    + raw[len(raw) // 2 + len(raw) // 4:])}
    for name, data in cases.items():
        f = tmp_path / name
        f.write_bytes(data)
        out = tmp_path / f"out-{name}"
        ran = trackkit("track", str(f), "--out", str(out), cwd=tmp_path)
        assert_user_error(ran, 2, f"{f}: not a readable Parquet file")
        if name == "pages.parquet":
            assert " from row " in ran.text  # the footer was read; the pages were not
        assert not out.exists()  # the directory the run created is removed again


# --- a byte that is not UTF-8 ----------------------------------------------------------------


def test_a_byte_that_is_not_utf8_is_one_bad_record(tmp_path):
    lines = [line.encode() for line in _ais_lines()]
    lines[10] = lines[10].replace(b",50.", b",5\xea0.", 1)    # line 11: a Latin-1 byte
    lines[13] = lines[13] + b",\xff"                           # line 14: and a field too many
    f = tmp_path / "ais.csv"
    f.write_bytes(b"\n".join(lines) + b"\n")
    out = tmp_path / "skip"
    ran = trackkit("track", str(f), "--as-radar", "--out", str(out), cwd=tmp_path)
    assert_user_error(ran, 0, f"{f}:11:Latitude_degrees: not UTF-8 text", "byte 0xea",
                      f"{f}:14:*: wrong number of fields", "skipped 2: ",
                      "1 not UTF-8 text", f"listed in {out / 'skipped.csv'}")
    assert "codec" not in ran.text
    assert _names(out) == RADAR_FILES | {"skipped.csv"}
    first, second = (out / "skipped.csv").read_text().splitlines()[1:]
    assert first.startswith('11,"Latitude_degrees","not UTF-8 text","5\\xea0.')
    assert first.endswith('","UTF-8 text, not byte 0xea"')
    assert second.startswith('14,"*","wrong number of fields","2016-01-12 13:02:')
    assert second.endswith(',\\xff","6 fields, got 7"')
    doc = json.loads((out / "results.json").read_text())
    assert doc["input"]["records_skipped"] == 2 and doc["input"]["skipped_by_reason"] == {
        "not UTF-8 text": 1, "wrong number of fields": 1}
    assert doc["input"]["records_kept"] == len(lines) - 3

    ran = trackkit("track", str(f), "--as-radar", "--on-bad", "stop", "--out",
                   str(tmp_path / "stop"), cwd=tmp_path)
    assert_user_error(ran, 2, f"{f}:11:Latitude_degrees: not UTF-8 text", "0xea",
                      "--on-bad skip")
    assert not (tmp_path / "stop").exists()

    f.write_bytes(b"\n".join([lines[0].replace(b"Time", b"T\xefme")] + lines[1:]) + b"\n")
    ran = trackkit("track", str(f), "--as-radar", "--out", str(tmp_path / "header"),
                   cwd=tmp_path)
    assert_user_error(ran, 2, f"{f}:1: the header is not UTF-8 text", "byte 0xef")
    assert not (tmp_path / "header").exists()


# --- finite but absurd values ----------------------------------------------------------------


def _plots() -> list[str]:
    """Three targets moving straight for 30 scans of 2 s (x, y in m)."""
    lines = ["time,x,y"]
    for k in range(30):
        lines += [f"{2.0 * k},{1000 * i + 10 * k:.1f},{500 * i + 5 * k:.1f}" for i in range(3)]
    return lines


def test_absurd_detections_are_bad_records(tmp_path):
    lines = _plots()
    lines[10] = "6.0,1e300,12.0"     # 1e300 m: finite, absurd
    lines[20] = "12.0,1000,-2e8"     # 200 000 km
    lines[30] = "1e300,2000,500"     # a time of 1e300 s
    f = tmp_path / "plots.csv"
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "skip"
    ran = trackkit("track", str(f), "--out", str(out), cwd=tmp_path)
    assert_user_error(ran, 0, f"{f}:11:x: |x| above 1e+08", "'1e300'",
                      f"{f}:21:y: |y| above 1e+08", "'-2e8'",
                      f"{f}:31:time: time out of range", "skipped 3")
    assert "overflow" not in ran.text and "warning" not in ran.text.lower()
    assert _names(out) == {"tracks.parquet", "tracks.csv", "tracks.png", "report.html",
                           "results.json", "skipped.csv", "manifest.json",
                           "tracks_summary.csv"}
    assert [row.split(",")[:2] for row in (out / "skipped.csv").read_text().splitlines()[1:]] \
        == [["11", '"x"'], ["21", '"y"'], ["31", '"time"']]
    doc = json.loads((out / "results.json").read_text())
    assert doc["input"]["skipped_by_reason"] == {"|x| above 1e+08": 1, "|y| above 1e+08": 1,
                                                 "time out of range": 1}
    assert doc["results"]["tracks_confirmed"] >= 3
    tracks = pacsv.read_csv(out / "tracks.csv")
    assert np.max(np.abs(tracks["x"].to_numpy())) < 1e4
    assert np.max(np.abs(tracks["time"].to_numpy())) <= 58.0

    ran = trackkit("track", str(f), "--on-bad", "stop", "--out", str(tmp_path / "stop"),
                   cwd=tmp_path)
    assert_user_error(ran, 2, f"{f}:11:x: |x| above 1e+08", "'1e300'", "geostationary",
                      "--on-bad skip")
    assert not (tmp_path / "stop").exists()


def test_absurd_ais_reports_are_bad_records(tmp_path):
    lines = _ais_lines()
    cut = [line.split(",") for line in lines]
    cut[4][2] = "91"                            # latitude
    cut[5][3] = "1e300"                         # longitude
    cut[6][5] = "1e300"                         # speed (knots)
    cut[7][0] = "2250-01-12 13:02:20.000"       # time
    f = tmp_path / "ais.csv"
    f.write_text("\n".join(",".join(c) for c in cut) + "\n")
    out = tmp_path / "skip"
    ran = trackkit("track", str(f), "--as-radar", "--out", str(out), cwd=tmp_path)
    # latitude 91 is AIS's "not available": skipped as such; an absurd speed is an optional
    # field's bad value, set missing with the record kept
    assert_user_error(ran, 0, f"{f}:5:Latitude_degrees: position not available (latitude 91)",
                      "'91'", f"{f}:6:Longitude_degrees: longitude outside [-180, 180]",
                      "'1e300'", "speed 1 (1 magnitude above 1943.84)",
                      f"{f}:8:Time: time out of range", "'2250-01-12 13:02:20.000'",
                      "skipped 3")
    assert "overflow" not in ran.text and "warning" not in ran.text.lower()
    assert _names(out) == RADAR_FILES | {"skipped.csv"}
    doc = json.loads((out / "results.json").read_text())
    assert doc["input"]["records_skipped"] == 3
    assert doc["input"]["records_kept"] == len(lines) - 4
    assert doc["results"]["tracks"]["truths"] == 4 and doc["results"]["tracks_confirmed"] >= 4


# --- the bundled samples, by name ------------------------------------------------------------


def test_solent_sample_by_name(tmp_path):
    """`trackkit track solent-ais --as-radar`: the default output directory is named after
    the sample; a marine radar at the data's median tracks nearly every vessel."""
    ran = trackkit("track", "solent-ais", "--as-radar", cwd=tmp_path)
    out = tmp_path / "trackkit-out" / "track-solent-ais"
    assert_user_error(ran, 0, "solent-ais.csv: 2159 records read, 2158 kept",
                      "no records skipped", f"report: {out / 'report.html'}")
    assert _names(out) == RADAR_FILES
    doc = json.loads((out / "results.json").read_text())
    radar, res = doc["config"]["virtual radar"], doc["results"]
    assert radar["scans"] == 200 and radar["objects_in_file"] == 77
    assert res["tracks"]["confirmed_fraction"] > 0.9 and res["tracks"]["rmse"] < 60
    assert res["gospa"]["false_per_scan"] < 2 and res["gospa"]["missed_per_scan"] < 2


def test_opensky_sample_by_name_and_a_file_of_that_name_first(tmp_path):
    ran = trackkit("track", "opensky-adsb", "--as-radar", "--out", "o", cwd=tmp_path)
    assert_user_error(ran, 0, "opensky-adsb.csv: 1556 records read, 1452 kept",
                      "dropped 104 exact duplicates")
    assert _names(tmp_path / "o") == RADAR_FILES
    doc = json.loads((tmp_path / "o" / "results.json").read_text())
    res = doc["results"]
    assert doc["config"]["virtual radar"]["scans"] == 30
    assert res["tracks"]["confirmed_fraction"] > 0.9 and res["tracks"]["rmse"] < 600
    # a real file of a sample's name is read instead of the sample
    (tmp_path / "opensky-adsb").write_text("\n".join(_ais_lines()) + "\n")
    ran = trackkit("track", "opensky-adsb", "--as-radar", "--out", "mine", cwd=tmp_path)
    assert_user_error(ran, 0, f"opensky-adsb: {len(_ais_lines()) - 1} records read")
    assert json.loads((tmp_path / "mine" / "results.json").read_text())["input"][
        "format"] == "ais"
    ran = trackkit("track", "opensky", "--as-radar", cwd=tmp_path)
    assert_user_error(ran, 2, "opensky: no such file", "bundled sample",
                      "solent-ais, opensky-adsb")
