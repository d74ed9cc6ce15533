"""``trackkit track``: the track writers (Parquet, CSV, GeoJSON, PNGs, HTML, results.json) on a
small synthetic run, and the command end to end through the real CLI in a subprocess, on the
Solent AIS and OpenSky recordings (skipped when shared/data is absent) and on malformed
detection files."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

import trackkit as tk
from trackkit import cli
from trackkit.eval.clear_mot import score_run
from trackkit.io import BadRecord, EnuFrame, ReadReport, read_ais_csv
from trackkit.report.track_pages import (
    TRACK_FILES,
    TrackReport,
    ground_geodetic,
    history_table,
    track_metrics,
    tracks_geojson,
    write_track_report,
)
from trackkit.sim.virtual_radar import VirtualRadar, virtual_radar
from trackkit.tracking import ScoreLogic, SinglePoint, Tracker, TrackStatus
from trackkit.tracking.history import run_tracker

from ..cli_helpers import assert_user_error, trackkit
from ..io import layout_files
from ..sim.test_virtual_radar import fleet

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
SOLENT = DATA / "SolentAIS_20160112_130211.csv"
OPENSKY = DATA / "OpenSky_Plane_States.csv"
needs_data = pytest.mark.skipif(not SOLENT.exists() or not OPENSKY.exists(),
                                reason="shared/data not beside the repository")
PNG = b"\x89PNG\r\n\x1a\n"
FRAME = EnuFrame(50.8, -1.1)
EPOCH = np.datetime64("2016-01-12T13:02:11", "ns")


# --- the writers on a small synthetic run ------------------------------------------------------


@pytest.fixture(scope="module")
def small():
    """Ten vessels for 5 minutes through a 3 s radar; tracked with the command's tracker."""
    return tracked_fleet(radar_seed=2)


def tracked_fleet(radar_seed: int):
    """Ten vessels for 5 minutes through a 3 s radar (its draws from ``radar_seed``), tracked
    by a constant-velocity EKF with single-point initiation and the SPRT score."""
    reports = fleet(10, 300.0, seed=3)
    vr = VirtualRadar(period=3.0, clutter=5.0, max_range=20e3)
    run = virtual_radar(reports, vr, seed=radar_seed)
    lam = vr.clutter_density
    trk = Tracker(tk.filters.EKF(), tk.models.ConstantVelocity(dim=2, q=0.05), run.sensor,
                  pd=vr.pd, clutter_density=lam,
                  logic=ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=vr.pd,
                                             clutter_density=lam, new_target_density=lam / 100),
                  initiator=SinglePoint(v_std=10.0))
    history, _ = run_tracker(trk, run.scans)
    return reports, run, history


def read_report(kept: int) -> ReadReport:
    bad = (BadRecord("synthetic.csv", 7, "x", "not a number", "abc", "a decimal x"),
           BadRecord("synthetic.csv", 9, "y", "missing value", "", "a decimal y"))
    return ReadReport("synthetic.csv", rows_read=kept + 3, rows_kept=kept,
                      skipped={"not a number": 1, "missing value": 1}, bad=bad,
                      skipped_lines=np.array([7, 9]), out_of_order=4, duplicates=1,
                      epoch=EPOCH)


def report_of(small, **kw) -> TrackReport:
    reports, run, history = small
    base = dict(title="synthetic", source="synthetic.csv", fmt="ais", epoch=EPOCH, frame=FRAME,
                read=read_report(len(reports)),
                truth=run.truth, gospa_c=500.0,
                config={"virtual radar": {"period_s": 3.0}, "tracker": {"q_m2_s3": 0.05}},
                background=reports.position, site=(0.0, 0.0), max_range=20e3,
                notes=["a note"])
    return TrackReport(history, **{**base, **kw})


def test_parquet_and_csv_round_trip_the_history(small, tmp_path):
    _, _, h = small
    paths = write_track_report(report_of(small), tmp_path / "out")
    n = h.ids.size
    scan = np.repeat(np.arange(h.times.size), np.diff(h.offsets))
    for table in (pq.read_table(paths["parquet"]), pacsv.read_csv(paths["csv"])):
        assert table.num_rows == n
        assert np.array_equal(table["id"].to_numpy(), h.ids)
        assert np.array_equal(table["scan"].to_numpy(), scan)
        assert np.array_equal(table["time"].to_numpy(), h.times[scan])  # floats exact
        for k, name in enumerate(("x", "y", "vx", "vy")):
            assert np.array_equal(table[name].to_numpy(), h.mean[:, k])
            assert np.array_equal(table[f"var_{name}"].to_numpy(), h.var[:, k])
        status = np.where(h.status == TrackStatus.CONFIRMED, "confirmed", "tentative")
        assert table["status"].to_pylist() == status.tolist()
        lat, lon = table["lat"].to_numpy(), table["lon"].to_numpy()
        assert np.all(np.abs(lat - 50.8) < 0.3) and np.all(np.abs(lon + 1.1) < 0.4)
    # absolute times: a UTC timestamp in Parquet, ISO text in CSV, both epoch + time
    pt = pq.read_table(paths["parquet"])["time_utc"]
    assert str(pt.type) == "timestamp[ns, tz=UTC]"
    expected = EPOCH + np.round(h.times[scan] * 1e9).astype("timedelta64[ns]")
    assert np.array_equal(pt.cast("int64").to_numpy(), expected.astype(np.int64))
    with open(paths["csv"], encoding="utf-8") as fh:
        header, first = fh.readline(), fh.readline()
    assert header.startswith("id,scan,time,time_utc,x,y,vx,vy,var_x")
    assert re.search(r',"2016-01-12T13:0\d:\d\d\.\d{3}Z",', first)
    meta = json.loads(pq.read_schema(paths["parquet"]).metadata[b"trackkit"])
    assert meta["frame"] == [50.8, -1.1, 0.0] and meta["epoch"].startswith("2016-01-12")


def test_geojson_is_valid_with_lon_lat(small, tmp_path):
    _, _, h = small
    paths = write_track_report(report_of(small), tmp_path / "out")
    doc = json.loads(paths["geojson"].read_text(encoding="utf-8"))
    assert doc["type"] == "FeatureCollection"
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds[0] == "radar site" and doc["features"][0]["geometry"]["coordinates"] == [
        -1.1, 50.8]
    tracks = [f for f in doc["features"] if f["properties"]["kind"] == "track"]
    confirmed = np.unique(h.ids[h.status == TrackStatus.CONFIRMED])
    assert sorted(f["properties"]["id"] for f in tracks) == confirmed.tolist()
    for f in tracks:
        g, p = f["geometry"], f["properties"]
        coords = np.array(g["coordinates"], dtype=float).reshape(-1, 2)
        assert g["type"] == ("LineString" if len(coords) > 1 else "Point")
        assert np.all((-180 <= coords[:, 0]) & (coords[:, 0] <= 180))
        assert np.all((-90 <= coords[:, 1]) & (coords[:, 1] <= 90))
        assert p["points"] == len(coords) == len(p["times_s"])
        assert p["start_s"] == p["times_s"][0] and np.all(np.diff(p["times_s"]) > 0)
        assert p["start_utc"].startswith("2016-01-12T13:0") and p["end_utc"].endswith("Z")
        # the coordinates are the confirmed positions' ground points
        keep = (h.ids == p["id"]) & (h.status == TrackStatus.CONFIRMED)
        lat, lon = ground_geodetic(FRAME, h.mean[keep, 0], h.mean[keep, 1])
        np.testing.assert_allclose(coords, np.stack([lon, lat], 1), atol=6e-8)


def test_ground_geodetic_is_the_point_at_sea_level():
    frame = EnuFrame(51.8, -1.3)
    lat0 = np.array([51.8, 53.5, 49.9, 51.0])
    lon0 = np.array([-1.3, 2.0, -5.0, -1.29])
    x, y, _ = frame.to_enu(lat0, lon0, 0.0)
    lat, lon = ground_geodetic(frame, x, y)
    np.testing.assert_allclose(lat, lat0, atol=1e-9)
    np.testing.assert_allclose(lon, lon0, atol=1e-9)
    doc = tracks_geojson(small_history(), frame)
    assert doc == {"type": "FeatureCollection", "features": []}


def small_history():
    from trackkit.tracking.history import TrackHistory

    z = np.zeros(0, np.int64)
    return TrackHistory(np.array([0.0]), np.array([0, 0]), z, np.zeros(0, np.int8),
                        np.zeros((0, 4)), np.zeros((0, 4)), np.array([0]), np.array([0]),
                        np.array([0]), np.array([0]))


def test_pngs_html_and_results(small, tmp_path):
    paths = write_track_report(report_of(small), tmp_path / "out")
    for key in ("tracks_png", "gospa_png"):
        assert paths[key].read_bytes().startswith(PNG)
    page = paths["html"].read_text(encoding="utf-8")
    # self-contained: scripts inline, every image inline, no link to anything outside
    assert re.findall(r"<script[^>]*>", page) == [
        '<script type="application/json" id="tk-map-data">', "<script>"]
    assert not re.findall(r'(?:src|href)="(?!data:)', page)
    assert not re.findall(r"(?:https?:)?//[a-z0-9.-]+\.[a-z]{2,}/", page, re.I)
    assert page.count('src="data:image/png;base64,') == 2
    for text in ("mean GOSPA (m)", "Virtual radar", "Tracker", "track breaks", "a note",
                 "records read", "synthetic.csv:7:x: not a number", "sorted by time",
                 "exact duplicates dropped", "period 3 s", "q 0.05 m^2/s^3"):
        assert text in page
    # what a person looks for first: the headline figures, then the map, then the tracks,
    # the settings in words; the raw keys last
    order = [page.index(t) for t in ('class="headline"', 'id="tk-map"', "<h2>Tracks</h2>",
                                     "<h2>Settings</h2>", "<h2>Results in full</h2>",
                                     "<h2>Figures</h2>", "period_s")]
    assert order == sorted(order)
    head = page[page.index('class="headline"'):page.index('id="tk-map"')]
    tr = json.loads(paths["results"].read_text(encoding="utf-8"))["results"]
    doc_tracks = tr["tracks"]
    for text in ("vessels held", f"{doc_tracks['truths_confirmed']} of {doc_tracks['truths']}",
                 "tracks per vessel", "ID switches per vessel-hour",
                 f"mean GOSPA</div><div class=\"value\">{tr['gospa']['mean']:.3g} m",
                 f"{doc_tracks['rmse']:.3g} m"):
        assert text in head, text
    summary = pacsv.read_csv(paths["summary"])
    n_conf = np.unique(small[2].ids[small[2].status == TrackStatus.CONFIRMED]).size
    assert summary.num_rows == n_conf and page.count("<tr><td>") >= n_conf
    assert paths["skipped"].read_text().splitlines() == [
        "line,column,reason,value,expected", '7,"x","not a number","abc","a decimal x"',
        '9,"y","missing value","","a decimal y"']
    doc = json.loads(paths["results"].read_text(encoding="utf-8"))
    g = doc["results"]["gospa"]
    assert g["c"] == 500.0 and g["mean"] > 0
    assert g["rms"] == pytest.approx(math.sqrt(g["localisation"] + g["missed"] + g["false"]))
    assert doc["results"]["tracks"]["truths"] == 10
    # no leftovers: only the report files
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        {"tracks.parquet", "tracks.csv", "tracks.geojson", "tracks.png", "gospa.png",
         "report.html", "results.json", "skipped.csv", "tracks_summary.csv"})
    assert doc["input"]["records_skipped"] == 2 and doc["input"]["out_of_order_sorted"] == 4


def test_report_solves_the_gospa_assignment_once(small, tmp_path, monkeypatch):
    """GOSPA, the track counts, GOSPA with switching and the track table's identities all
    come from one solve of the assignment (each costs a few tenths of a second on a whole
    recording); the table from it equals the table that solves its own."""
    import trackkit.eval.track_metrics as mt
    from trackkit.report.track_table import track_table

    solves = []
    kernel = mt._assign

    def counted(*args, **kw):
        solves.append(args[0].x.shape[0])
        return kernel(*args, **kw)

    monkeypatch.setattr(mt, "_assign", counted)
    rep = report_of(small)
    paths = write_track_report(rep, tmp_path / "out")
    assert len(solves) == 1 and solves[0] == rep.truth.x.shape[0]
    assert paths["summary"].exists()
    names = [f"vessel {k}" for k in range(int(rep.truth.ids.max()) + 1)]
    kw = dict(truth=rep.truth, c=rep.gospa_c, object_ids=names, epoch=rep.epoch)
    given = track_table(rep.history, **kw, assignment=track_metrics(
        rep.history, rep.truth, rep.gospa_c)["_assignment"])
    assert len(solves) == 2
    alone = track_table(rep.history, **kw)
    assert len(solves) == 3  # the table alone solves it itself
    assert given.equals(alone) and any(alone["identity"].to_pylist())


def test_metrics_parts_add_up(small):
    _, run, h = small
    m = track_metrics(h, run.truth, 500.0)
    g = m["gospa"]
    assert g["missed_per_scan"] * 500.0**2 / 2 == pytest.approx(g["missed"])
    assert m["tracks_confirmed"] == np.unique(h.ids[h.status == TrackStatus.CONFIRMED]).size
    assert track_metrics(h, None, 500.0).get("gospa") is None


def test_metrics_hold_the_identity_scores_of_score_run():
    """The report's identity figures are eval.clear_mot's, threshold and penalty c (on radar
    draws where the tracker switches: 5 ID switches)."""
    _, run, h = tracked_fleet(radar_seed=3)
    m = track_metrics(h, run.truth, 500.0, site=(0.0, 0.0), sigma_bearing=math.radians(0.5))
    i = m["identity"]
    want = score_run(h.confirmed(), run.truth, (0.0, 0.0), math.radians(0.5), 500.0)
    for key, ref in [("mota", "mota"), ("motp_m", "motp"), ("idf1", "idf1"),
                     ("id_switches", "id_switches"), ("fragmentations", "fragmentations"),
                     ("id_switches_resolvable", "id_switches_resolvable"),
                     ("gospa_switching_mean", "gospa_switching")]:
        assert i[key] == want[ref], key
    steps = m["_identity_steps"]
    assert steps["id_switches"].sum() == i["id_switches"] > 0
    assert steps["id_switches_resolvable"].sum() == i["id_switches_resolvable"]
    assert len(steps["mota"]) == h.times.size
    assert track_metrics(h, run.truth, 500.0)["identity"]["id_switches_resolvable"] is None


def test_rewrite_removes_stale_files_and_failure_leaves_nothing(small, tmp_path, monkeypatch):
    out = tmp_path / "out"
    write_track_report(report_of(small), out)
    (out / "mine.txt").write_text("not ours")
    # no truth, no frame: no gospa.png, no GeoJSON; the old ones go
    paths = write_track_report(report_of(small, truth=None, frame=None, epoch=None,
                                         read=None), out)
    names = {p.name for p in out.iterdir()}
    assert "gospa.png" not in names and "tracks.geojson" not in names and "mine.txt" in names
    assert "skipped.csv" not in names
    assert set(paths) == {"parquet", "csv", "summary", "tracks_png", "html", "results"}
    assert "time_utc" not in pq.read_schema(paths["parquet"]).names
    assert set(TRACK_FILES) >= names - {"mine.txt"}
    before = sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir())

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    import trackkit.report.track_pages as tr

    monkeypatch.setattr(tr, "render_track_html", boom)
    with pytest.raises(OSError):
        write_track_report(report_of(small), out)
    assert sorted((p.name, p.stat().st_mtime_ns) for p in out.iterdir()) == before
    fresh = tmp_path / "a" / "b"
    with pytest.raises(OSError):
        write_track_report(report_of(small), fresh)
    assert not (tmp_path / "a").exists()


# --- the command: errors in words (in-process, fast) ------------------------------------------

runner = CliRunner()


def _invoke(*args):
    return runner.invoke(cli.app, ["track", *args], env={"COLUMNS": "200", "NO_COLOR": "1"})


def test_option_values_are_checked(tmp_path):
    f = tmp_path / "d.csv"
    f.write_text("time,x,y\n0,1,2\n")
    for args, names in ((["--pd", "1.5"], ["--pd", "1.5"]),
                        (["--period", "-1"], ["--period", "-1"]),
                        (["--clutter", "nan"], ["--clutter", "nan"])):
        res = _invoke(str(f), *args)
        assert res.exit_code == 2, res.output
        for name in names:
            assert name in res.output


def test_input_errors_name_the_file_and_what_to_do(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    ais = tmp_path / "ais.csv"
    ais.write_text("Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots\n"
                   "2016-01-12 13:02:11,1,50.8,-1.1,10,5\n")
    det = tmp_path / "det.csv"
    det.write_text("time,x,y\n0,1,2\n")
    odd = tmp_path / "odd.csv"
    odd.write_text("a,b\n1,2\n")
    cases = [
        ([str(ais)], [str(ais), "--as-radar"]),
        ([str(det), "--as-radar"], [str(det), "drop --as-radar"]),
        ([str(odd)], [str(odd), "'a', 'b'", "--format"]),
        ([str(tmp_path / "missing.csv")], ["missing.csv", "no such file"]),
        ([str(ais), "--as-radar", "--site-lat", "50"], ["--site-lon"]),
        ([str(ais), "--as-radar", "--columns", "lat=Lat,bogus=x"], ["--columns", "'bogus'"]),
        ([str(det), "--units", "distance=parsec"], ["distance", "'parsec'"]),
    ]
    for args, names in cases:
        res = _invoke(*args)
        assert res.exit_code == 2, (args, res.output)
        for name in names:
            assert name in res.output, (args, name, res.output)
    assert not (tmp_path / "trackkit-out").exists() or not any(
        (tmp_path / "trackkit-out").rglob("*.csv"))


# --- the command end to end (subprocess) ------------------------------------------------------


def test_no_file_tracks_the_bundled_sample_and_says_so(tmp_path):
    ran = trackkit("track", "--max-scans", "8", cwd=tmp_path)
    assert ran.code == 0, ran.text
    first = ran.out.splitlines()[0]
    assert first.startswith("No file given: tracking the sample shipped with trackkit, "
                            "solent-ais: AIS: 77 vessels"), first
    assert "trackkit track solent-ais --as-radar" in first
    out = tmp_path / "trackkit-out" / "track-solent-ais"
    doc = json.loads((out / "results.json").read_text())
    assert doc["input"]["file"].endswith("solent-ais.csv") and doc["input"]["format"] == "ais"
    assert doc["config"]["virtual radar"]["scans"] == 8
    summary = pacsv.read_csv(out / "tracks_summary.csv").to_pydict()
    mmsi = [str(s) for s in summary["identity"] if s is not None]
    assert len(mmsi) > 20 and all(s.isdigit() and len(s) == 9 for s in mmsi)


def test_the_tracker_options_reach_the_tracker(tmp_path):
    out = tmp_path / "o"
    ran = _invoke("solent-ais", "--as-radar", "--max-scans", "6", "--misses", "5", "--v-max",
                  "12", "--turn-q", "2e-5", "--turn-std-deg", "4", "--manoeuvre-q", "0.3",
                  "--hold", "60",
                  "--rejoin", "250", "--regain", "80", "--out", str(out))
    assert ran.exit_code == 0, ran.output
    tracker = json.loads((out / "results.json").read_text())["config"]["tracker"]
    assert tracker["v_max_m_s"] == 12.0 and "two-point" in tracker["initiator"]
    assert tracker["turn_rate_noise_rad2_s3"] == 2e-5 and tracker["turn_model_q_m2_s3"] == 0.3
    assert tracker["initial_turn_rate_std_deg_s"] == pytest.approx(4.0, rel=1e-12)
    assert "deleted after 6 consecutive missed scans" in tracker["logic"]
    assert "held, unseen, for 20 more missed scans (60 s)" in tracker["logic"]
    assert "confirmed within 250 m of it" in tracker["logic"]
    assert "position std is within 80 m" in tracker["logic"]
    ran = _invoke("solent-ais", "--as-radar", "--max-scans", "6", "--hold", "0", "--out",
                  str(tmp_path / "h0"))
    assert ran.exit_code == 0, ran.output
    logic = json.loads((tmp_path / "h0" / "results.json").read_text())["config"]["tracker"]
    assert "held" not in logic["logic"]
    # a detections file gets two-point initiation and the IMM when asked for them
    f = tmp_path / "plots.csv"
    _detections(f, bad=False)
    ran = _invoke(str(f), "--v-max", "30", "--turn-q", "1e-4", "--misses", "2", "--out",
                  str(tmp_path / "d"))
    assert ran.exit_code == 0, ran.output
    tracker = json.loads((tmp_path / "d" / "results.json").read_text())["config"]["tracker"]
    assert "coordinated turn" in tracker["motion"] and tracker["v_max_m_s"] == 30.0
    assert "deleted after 3 consecutive missed scans" in tracker["logic"]


def test_a_tracker_option_the_tracker_would_not_use_is_refused(tmp_path):
    f = tmp_path / "d.csv"
    f.write_text("time,x,y\n0,1,2\n")
    for args, names in (
            (["solent-ais", "--as-radar", "--v-std", "5"],
             ["--v-std 5", "two-point initiation", "--v-max (20 m/s)"]),
            ([str(f), "--v-max", "30", "--v-std", "5"], ["--v-std 5", "--v-max (30 m/s)"]),
            ([str(f), "--turn-std-deg", "3"], ["--turn-std-deg 3", "--turn-q"]),
            ([str(f), "--manoeuvre-q", "0.5"], ["--manoeuvre-q 0.5", "--turn-q"]),
            ([str(f), "--hold", "60"], ["--hold 60", "--misses"]),
            ([str(f), "--misses", "-1"], ["--misses", "-1"])):
        res = _invoke(*args, "--out", str(tmp_path / "never"))
        assert res.exit_code == 2, res.output
        for name in names:
            assert name in " ".join(res.output.split()), (name, res.output)
        assert not (tmp_path / "never").exists()
    res = _invoke(str(f), "--v-std", "5", "--out", str(tmp_path / "single"))
    assert res.exit_code == 0, res.output  # single-point initiation uses it


def test_the_report_shows_the_layout_and_what_was_set_missing(tmp_path):
    """A NOAA MarineCadastre file with courses out of range and a "not available" code: the
    page's input section names the layout and counts the courses set missing by reason."""
    f = layout_files.write_noaa(tmp_path / "AIS <harbour>.csv", layout_files.fleet(), special={
        3: {"COG": "-120.3"}, 5: {"COG": "-120.3"}, 7: {"COG": "-120.3"},
        9: {"COG": "-49.6"}, 11: {"Heading": "511"}})
    out = tmp_path / "o"
    ran = _invoke(str(f), "--as-radar", "--out", str(out))
    assert ran.exit_code == 0, ran.output
    page = (out / "report.html").read_text(encoding="utf-8")
    section = page[page.index("<h2>Input</h2>"):]
    assert "<th>layout recognised</th><td>AIS CSV, NOAA MarineCadastre layout (noaa)</td>" \
        in section
    for field_reason, n in (("course: outside [0, 360]", 3),
                            ("course: not available (-49.6)", 1),
                            ("heading: not available (511)", 1)):
        assert f"<th>{field_reason}</th><td>{n}</td>" in section, field_reason
    assert "AIS &lt;harbour&gt;.csv" in section and "AIS <harbour>" not in section
    doc = json.loads((out / "results.json").read_text())["input"]
    assert doc["layout"] == "noaa" and doc["set_missing"]["course"] == {
        "outside [0, 360]": 3, "not available (-49.6)": 1}


def _detections(path: Path, bad: bool = True) -> None:
    """Three targets in a straight line for 40 scans of 2 s, some clutter; with ``bad``, line
    11 has x = 'abc', line 21 repeats line 20 and two scans are out of time order."""
    rng = np.random.default_rng(1)
    lines = ["time,sensor,x,y"]
    for k in range(40):
        t = 2.0 * k
        for i in range(3):
            lines.append(f"{t},0,{1000 * i + 10 * t + rng.normal(0, 20):.2f},"
                         f"{500 * i + 5 * t + rng.normal(0, 20):.2f}")
        for _ in range(rng.poisson(2)):
            lines.append(f"{t},0,{rng.uniform(-2e3, 4e3):.2f},{rng.uniform(-2e3, 3e3):.2f}")
    if bad:
        lines[10] = "4.0,0,abc,12.0"
        lines[21] = lines[20]
        lines[30], lines[60] = lines[60], lines[30]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def test_malformed_detections_stop_and_skip(tmp_path):
    f = tmp_path / "plots.csv"
    _detections(f)
    ran = trackkit("track", str(f), "--on-bad", "stop", "--out", str(tmp_path / "o1"),
                   cwd=tmp_path)
    assert_user_error(ran, 2, f"{f}:11:x", "not a number", "'abc'", "--on-bad skip")
    assert not (tmp_path / "o1").exists()  # the directory it created is removed again

    ran = trackkit("track", str(f), "--site-lat", "50.8", "--site-lon", "-1.1", "--out",
                   str(tmp_path / "o2"), cwd=tmp_path)
    assert ran.code == 0, ran.text
    assert "skipped 1: 1 not a number" in ran.out
    assert f"{f}:11:x: not a number" in ran.out
    assert "dropped 1 exact duplicates" in ran.out
    assert "out of time order and were sorted" in ran.out
    assert f"listed in {tmp_path / 'o2' / 'skipped.csv'}" in ran.out
    skipped = (tmp_path / "o2" / "skipped.csv").read_text().splitlines()
    assert skipped == ["line,column,reason,value,expected",
                       '11,"x","not a number","abc","a decimal x"']
    doc = json.loads((tmp_path / "o2" / "results.json").read_text())
    assert doc["input"]["records_skipped"] == 1 and doc["input"]["duplicates_dropped"] == 1
    assert doc["input"]["skipped_by_reason"] == {"not a number": 1}
    assert doc["results"]["tracks_confirmed"] >= 3
    assert "gospa" not in doc["results"]  # no truth in a detections file
    page = (tmp_path / "o2" / "report.html").read_text()
    assert "sorted by time" in page and "No truth" in page
    assert (tmp_path / "o2" / "tracks.geojson").exists()  # the site gives lat/lon


def _check_outputs(out: Path, ran) -> dict:
    assert ran.code == 0, ran.text
    for name in ("tracks.parquet", "tracks.csv", "tracks.geojson", "tracks.png", "gospa.png",
                 "report.html", "results.json"):
        assert (out / name).is_file(), name
    assert not (out / ".trackkit.lock").exists()
    doc = json.loads((out / "results.json").read_text())
    g = doc["results"]["gospa"]
    assert g["mean"] > 0 and math.isfinite(g["mean"])
    assert f"mean GOSPA {g['mean']:.4g} m" in ran.out
    page = (out / "report.html").read_text()
    assert "mean GOSPA (m)" in page and f"{g['mean']:.6g}" in page
    geo = json.loads((out / "tracks.geojson").read_text())
    kinds = [f["properties"]["kind"] for f in geo["features"]]
    n = doc["results"]["tracks_confirmed"]
    assert (kinds.count("track"), kinds.count("smoothed track"), len(kinds)) == (n, n, 2 * n + 1)
    return doc


@needs_data
def test_solent_ais_as_radar_first_ten_minutes(tmp_path):
    """The Solent file through a virtual radar, the first 10 minutes (--until 600: 201 scans)
    to keep the test short; the whole file is the slow test below."""
    out = tmp_path / "solent"
    ran = trackkit("track", str(SOLENT), "--as-radar", "--until", "600", "--out", str(out),
                   cwd=tmp_path)
    doc = _check_outputs(out, ran)
    assert "18623 records read, 18620 kept" in ran.out
    assert "dropped 3 exact duplicates" in ran.out and "no records skipped" in ran.out
    assert doc["config"]["virtual radar"]["scans"] == 201
    assert doc["input"]["duplicates_dropped"] == 3 and doc["input"]["records_skipped"] == 0
    res = doc["results"]
    # a marine radar at the data's median: most vessels tracked, few false tracks
    assert res["tracks"]["confirmed_fraction"] > 0.9
    assert res["gospa"]["false_per_scan"] < 2 and res["tracks"]["rmse"] < 60


@needs_data
def test_opensky_as_radar(tmp_path):
    out = tmp_path / "opensky"
    ran = trackkit("track", str(OPENSKY), "--as-radar", "--out", str(out), cwd=tmp_path)
    doc = _check_outputs(out, ran)
    assert "6052 records read, 5410 kept" in ran.out
    assert "dropped 642 exact duplicates" in ran.out
    assert "records were out of time order and were sorted" in ran.out
    assert "sorted by time before tracking" in (out / "report.html").read_text()
    res = doc["results"]
    assert res["tracks"]["confirmed_fraction"] > 0.9 and res["tracks"]["rmse"] < 600


@needs_data
@pytest.mark.slow
def test_solent_whole_file(tmp_path):
    """The whole Solent recording (1691 scans of 3 s; about 25 s)."""
    out = tmp_path / "solent"
    ran = trackkit("track", str(SOLENT), "--as-radar", "--out", str(out), cwd=tmp_path)
    doc = _check_outputs(out, ran)
    res = doc["results"]
    assert doc["config"]["virtual radar"]["scans"] == 1691
    reports, _ = read_ais_csv(SOLENT)
    assert doc["config"]["virtual radar"]["objects_in_file"] == len(reports.ids) == 91
    assert res["tracks"]["completeness"] > 0.95 and res["gospa"]["mean"] < 500
    # the smoother stays near the filter over thousands of scans of a moored vessel (the
    # fixed-interval pass drifted by hundreds of kilometres there: 46 km RMSE)
    t = pq.read_table(out / "tracks.parquet").to_pydict()
    shown = np.array(t["status"]) == "confirmed"
    dev = np.hypot(np.subtract(t["x_smooth"], t["x"]), np.subtract(t["y_smooth"], t["y"]))[shown]
    assert np.median(dev) < 20.0 and dev.max() < 2000.0, (np.median(dev), dev.max())


def test_history_table_columns_follow_what_is_known(small):
    _, _, h = small
    plain = history_table(h)
    assert plain.column_names == ["id", "scan", "time", "x", "y", "vx", "vy", "var_x", "var_y",
                                  "var_vx", "var_vy", "status"]
    full = history_table(h, epoch=EPOCH, frame=FRAME)
    assert {"time_utc", "lat", "lon"} <= set(full.column_names)
