"""The track table, the headline figures, the settings in words and the map's data of
``trackkit track``'s report, on hand-made histories whose answers are known, and the hits that
``run_tracker`` records, checked against the filter's covariance."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from trackkit.eval.track_metrics import frames
from trackkit.report.track_map import map_data, map_html, simplify
from trackkit.report.track_table import track_table
from trackkit.report.track_words import headline_figures, settings_in_words
from trackkit.tracking.history import TrackHistory
from trackkit.tracking.logic import TrackStatus

from .test_track_command import small  # noqa: F401  (the fixture)

C, T = int(TrackStatus.CONFIRMED), int(TrackStatus.TENTATIVE)
EPOCH = np.datetime64("2016-01-12T13:02:11", "ns")


def history_of(rows: list[list[tuple]], hit: bool = True) -> TrackHistory:
    """Per scan (times 0, 1, 2, ...) rows ``(id, status, x, y, vx, vy, hit)``."""
    flat = [r for scan in rows for r in scan]
    sizes = [len(scan) for scan in rows]
    s = len(rows)
    return TrackHistory(
        times=np.arange(s, dtype=float), offsets=np.r_[0, np.cumsum(sizes)].astype(np.int64),
        ids=np.array([r[0] for r in flat], np.int64),
        status=np.array([r[1] for r in flat], np.int8),
        mean=np.array([r[2:6] for r in flat], float).reshape(-1, 4),
        var=np.ones((len(flat), 4)), pairs=np.zeros(s, np.int64),
        started=np.zeros(s, np.int64), deleted=np.zeros(s, np.int64),
        approximated=np.zeros(s, np.int64),
        hit=np.array([r[6] for r in flat], bool) if hit else None)


def three_tracks() -> tuple[TrackHistory, object]:
    """Track 1 along x at 2 m/s, scans 0-4, missed at scans 2 and 3; track 2 tentative at
    scan 0, confirmed at 1-2 at 5 m/s, then deleted; track 3 confirmed at 3-4, missed at 4.
    Object 0 sits on track 1 at scans 0-2, object 1 at scans 3-4; nothing near 2 and 3."""
    rows = [[(1, C, 0, 0, 2, 0, True), (2, T, 5e3, 0, 3, 4, True)],
            [(1, C, 2, 0, 2, 0, True), (2, C, 5e3 + 3, 4, 3, 4, True)],
            [(1, C, 4, 0, 2, 0, False), (2, C, 5e3 + 6, 8, 3, 4, False)],
            [(1, C, 6, 0, 2, 0, False), (3, C, 0, 9e3, 0, 1, True)],
            [(1, C, 8, 0, 2, 0, True), (3, C, 0, 9e3 + 1, 0, 1, False)]]
    truth = frames([[[0, 1]], [[2, 1]], [[4, 1]], [[6, 1]], [[8, 1]]],
                   ids=[[0], [0], [0], [1], [1]])
    return history_of(rows), truth


def test_track_table_of_known_tracks():
    h, truth = three_tracks()
    t = track_table(h, truth=truth, c=100.0, object_ids=["235000001", "235000002"],
                    epoch=EPOCH).to_pydict()
    assert t["id"] == [1, 2, 3]
    assert t["identity"] == ["235000001", "", ""]
    assert t["identity_share"][0] == pytest.approx(3 / 5)
    assert all(math.isnan(v) for v in t["identity_share"][1:])
    assert t["start_s"] == [0.0, 1.0, 3.0] and t["end_s"] == [4.0, 2.0, 4.0]
    assert t["start_utc"] == ["2016-01-12T13:02:11Z", "2016-01-12T13:02:12Z",
                              "2016-01-12T13:02:14Z"]
    assert t["duration_s"] == [4.0, 1.0, 1.0] and t["scans"] == [5, 2, 2]
    assert t["distance_m"] == pytest.approx([8.0, 5.0, 1.0])
    assert t["mean_speed_m_s"] == pytest.approx([2.0, 5.0, 1.0])
    assert t["max_speed_m_s"] == pytest.approx([2.0, 5.0, 1.0])
    # track 1: last hit at 1 s, missed at 2 and 3 s: 2 s on prediction alone
    assert t["longest_coast_s"] == [2.0, 1.0, 1.0]
    assert t["status"] == ["tracking", "deleted", "coasting"]


def test_track_table_without_truth_or_hits():
    h, _ = three_tracks()
    t = track_table(h._replace(hit=None)).to_pydict()
    assert t["identity"] == ["", "", ""] and "start_utc" not in t
    assert all(math.isnan(v) for v in t["longest_coast_s"])
    assert t["status"] == ["alive", "deleted", "alive"]
    empty = track_table(history_of([[(1, T, 0, 0, 0, 0, True)]]))
    assert empty.num_rows == 0 and "status" in empty.column_names


def test_identity_is_the_object_most_often_assigned(small):  # noqa: F811
    """On a tracker run: each track's identity and share agree with a direct count of the
    GOSPA assignment's pairs (c = 500 m), and the purest tracks follow one object."""
    from trackkit.eval.track_metrics import assign

    _, run, h = small
    t = track_table(h, truth=run.truth, c=500.0, object_ids=list(run.ids)).to_pydict()
    conf = h.confirmed()
    i, j = assign(run.truth, conf, 500.0)
    for k, tid in enumerate(t["id"]):
        objs = run.truth.ids[i[conf.ids[j] == tid]]
        if objs.size == 0:
            assert t["identity"][k] == ""
            continue
        codes, counts = np.unique(objs, return_counts=True)
        assert t["identity"][k] == run.ids[codes[np.argmax(counts)]]
        assert t["identity_share"][k] == pytest.approx(counts.max() / t["scans"][k])
    assert np.nanmedian(t["identity_share"]) > 0.9


def test_run_tracker_records_hits(small):  # noqa: F811
    """A row not hit was only predicted, so its position variance grew from the scan before;
    a new track is hit (by its plot); no scan has more hits than plots."""
    _, run, h = small
    scan = np.repeat(np.arange(h.times.size), np.diff(h.offsets))
    assert h.hit is not None and h.hit.shape == h.ids.shape
    prev = {}
    grew, n_miss = 0, 0
    for s in range(h.times.size):
        rows = range(h.offsets[s], h.offsets[s + 1])
        for r in rows:
            tid = int(h.ids[r])
            if tid not in prev:
                assert h.hit[r], f"track {tid} started without a plot"
            elif not h.hit[r]:
                n_miss += 1
                grew += h.var[r, 0] > h.var[prev[tid], 0]
            prev[tid] = r
        assert h.hit[scan == s].sum() <= run.scans.offsets[s + 1] - run.scans.offsets[s]
    assert n_miss > 50 and grew == n_miss


def test_headline_figures_from_the_metrics():
    metrics = {"tracks_confirmed": 12, "tracks_started": 40, "scans": 1200,
               "mean_confirmed_per_scan": 9.5,
               "gospa": {"mean": 310.25, "c": 500.0},
               "tracks": {"truths": 11, "truths_confirmed": 10, "tracks": 12,
                          "id_switches": 30, "truth_steps": 12_000, "rmse": 23.4}}
    figs = headline_figures(metrics, np.arange(1200) * 3.0, "ais")
    assert [f[0] for f in figs] == ["vessels held", "tracks per vessel",
                                    "ID switches per vessel-hour", "mean GOSPA",
                                    "position RMSE"]
    # 12 000 vessel-scans of 3 s are 10 vessel-hours: 30 switches, 3 per vessel-hour
    assert [f[1] for f in figs] == ["10 of 11", "1.2", "3", "310 m", "23.4 m"]
    assert "10 vessel-hours" in figs[2][2]
    # with the CLEAR-MOT scores the headline counts their ID switches instead
    clear = headline_figures({**metrics, "identity": {"id_switches": 5}},
                             np.arange(1200) * 3.0, "ais")
    assert clear[2][1] == "0.5" and "(CLEAR-MOT)" in clear[2][2]
    plain = headline_figures({k: metrics[k] for k in ("tracks_confirmed", "tracks_started",
                                                     "scans", "mean_confirmed_per_scan")},
                             [0.0, 1.0])
    assert plain[0][:2] == ("confirmed tracks", "12")


def test_settings_in_words_with_units():
    radar = {"site_lat_deg": 50.79476, "site_lon_deg": -1.11141, "site_x_m": 0.0,
             "site_y_m": 0.0, "period_s": 3.0, "sigma_range_m": 20.0, "sigma_bearing_deg": 0.5,
             "pd": 0.9, "clutter_per_scan": 10.0, "min_range_m": 50.0, "max_range_m": 40e3,
             "max_gap_s": 120.0, "still_distance_m": 50.0, "still_gap_s": 600.0, "seed": 0,
             "scans": 1691, "plots": 103_000, "plots_of_objects": 86_000,
             "objects_in_file": 91, "objects_in_range": 88}
    tracker = {"filter": "EKF", "motion": "constant velocity", "q_m2_s3": 0.05,
               "associator": "GNN", "initiator": "single point, velocity 0",
               "initial_velocity_std_m_s": 10.0, "pd_assumed": 0.9, "gospa_c_m": 500.0,
               "new_thing_m_s": 2.5}
    (t1, radar_text), (t2, tracker_text) = settings_in_words(
        {"virtual radar": radar, "tracker": tracker})
    assert (t1, t2) == ("Virtual radar", "Tracker")
    for part in ("Virtual radar at 50.79476 N, 1.11141 W", "a scan every 3 s",
                 "range noise 20 m", "bearing noise 0.5 deg", "from 50 m to 40 km",
                 "1,691 scans", "88 of the 91 objects"):
        assert part in radar_text, part
    for part in ("EKF on a constant velocity model (process noise q 0.05 m^2/s^3)",
                 "initial velocity std 10 m/s", "cut-off 500 m", "new thing 2.5 m/s"):
        assert part in tracker_text, part
    assert "site_lat_deg" not in radar_text and "_" not in tracker_text


def test_simplify_keeps_the_path_within_the_tolerance():
    rng = np.random.default_rng(5)
    p = np.cumsum(rng.normal(0, 5, (400, 2)), axis=0)
    keep = simplify(p, 10.0)
    assert keep[0] == 0 and keep[-1] == 399 and 10 < keep.size < 400
    for a, b in zip(keep[:-1], keep[1:], strict=True):
        seg, rel = p[b] - p[a], p[a + 1:b] - p[a]
        d = np.abs(seg[0] * rel[:, 1] - seg[1] * rel[:, 0]) / np.hypot(*seg)
        assert np.all(d <= 10.0)
    assert simplify(np.zeros((5, 2)), 1.0).tolist() == [0, 4]


def test_map_data_decodes_and_escapes(small):  # noqa: F811
    """The steps add up to the confirmed positions (within half the grid and the
    tolerance); what the page shows cannot end its script."""
    import pyarrow as pa

    reports, _, h = small
    ids = np.unique(h.ids[h.status == TrackStatus.CONFIRMED])
    table = pa.table({"id": ids, "identity": ["</script><b>x</b>&"] * ids.size})
    d = map_data(h, table=table, background=reports.position, site=(0.0, 0.0),
                 max_range=20e3, epoch=EPOCH, background_label="<reported>")
    assert [r[0] for r in d["tracks"]] == ids.tolist()
    q, tol = d["quantum"], d["tolerance"]
    for tid, _, first, dscan, dx, dy in d["tracks"]:
        x, y = np.cumsum(dx) * q, np.cumsum(dy) * q
        scans = np.cumsum([first, *dscan])
        rows = np.flatnonzero((h.ids == tid) & (h.status == TrackStatus.CONFIRMED))
        row_scan = np.searchsorted(h.offsets, rows, side="right") - 1
        at = rows[np.searchsorted(row_scan, scans)]
        np.testing.assert_array_less(np.abs(h.mean[at, 0] - x), q / 2 + 1e-9)
        np.testing.assert_array_less(np.abs(h.mean[at, 1] - y), q / 2 + 1e-9)
        assert scans[0] == row_scan[0] and scans[-1] == row_scan[-1]
    assert tol <= 20.0 and len(d["background"][0]) > 100
    page = map_html(d)
    script = re.search(r'<script type="application/json" id="tk-map-data">(.*?)</script>',
                       page, re.S).group(1)
    assert "<" not in script and "&" not in script
    back = json.loads(script)
    assert back["tracks"][0][1] == "</script><b>x</b>&"
    assert back["background_label"] == "<reported>"


def test_page_shows_further_metrics(small):  # noqa: F811
    """Figures that track_metrics may add (CLEAR-MOT, IDF1) appear on the page without a
    change to it; series stay in results.json."""
    from trackkit.report.track_pages import render_track_html, track_metrics

    from .test_track_command import report_of

    _, run, h = small
    m = track_metrics(h, run.truth, 500.0)
    m["clear_mot"] = {"mota": 0.8125, "motp_m": 21.5, "per_scan": [0.1, 0.2]}
    m["idf1"] = 0.9375
    page = render_track_html(report_of(small), m, {})
    assert "<th>mota</th><td>0.8125</td>" in page and "<th>motp m</th><td>21.5</td>" in page
    assert "<th>idf1</th><td>0.9375</td>" in page and "<th>per scan</th>" not in page


def test_a_track_held_at_the_end_is_held():
    """Track 5 confirmed at scans 0-1, then lost and held (not shown) to the end: "held",
    not "deleted"; track 6, deleted after scan 1, stays "deleted"."""
    L = TrackStatus.LOST
    rows = [[(5, C, 0, 0, 1, 0, True), (6, C, 500, 0, 1, 0, True)],
            [(5, C, 1, 0, 1, 0, True), (6, C, 501, 0, 1, 0, True)],
            [(5, L, 2, 0, 1, 0, False)],
            [(5, L, 3, 0, 1, 0, False)]]
    t = track_table(history_of(rows)).to_pydict()
    assert t["id"] == [5, 6] and t["status"] == ["held", "deleted"]
    assert t["end_s"] == [1.0, 1.0]  # the table describes the track as shown
