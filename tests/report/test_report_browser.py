"""``report.html`` of ``trackkit track`` in a real browser: Debian's headless Chromium opens
the page from disk with no network, and the page must load without a console message, draw
its tracks on the map (screenshot pixels in the tracks' colours, the map's own count of
tracks drawn) and offer the time slider. ``.ci/run`` installs ``chromium`` when missing."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.browser import CHROMIUM, HEIGHT, WIDTH, open_in_chromium
from trackkit.io import samples
from trackkit.report.track_map import PALETTE
from trackkit.report.track_pages import track_report, write_track_report
from trackkit.tracking.recorded import TrackOptions, track_recording

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine "
                                "(.ci/run installs it)")


def test_console_messages_are_seen(tmp_path):
    """The check below can fail: a page that logs an error and throws is caught."""
    page = tmp_path / "bad.html"
    page.write_text('<!DOCTYPE html><html><body><script>console.error("broken map");'
                    "null.f();</script></body></html>", encoding="utf-8")
    _, console, _ = open_in_chromium(page, tmp_path)
    assert any("broken map" in m for m in console)
    assert any("Uncaught TypeError" in m for m in console)


def test_report_map_draws_the_tracks_offline(tmp_path):
    result = track_recording(samples.path("solent-ais"), TrackOptions(as_radar=True,
                                                                      max_scans=60))
    paths = write_track_report(track_report(result), tmp_path / "out")
    n_tracks = int(np.unique(result.history.confirmed().ids).size)
    assert n_tracks > 20
    dom, console, shot = open_in_chromium(paths["html"], tmp_path)
    assert console == []
    # the map's script ran to the end and drew every track; the slider spans the scans
    root = re.search(r'<section id="tk-map"[^>]*>', dom).group(0)
    assert 'data-rendered="true"' in root
    assert f'data-tracks="{n_tracks}"' in root and f'data-tracks-drawn="{n_tracks}"' in root
    slider = re.search(r'<input type="range" id="tk-time"[^>]*>', dom).group(0)
    assert 'max="59"' in slider
    assert re.search(r'<span id="tk-time-label">2016-01-12 13:05:\d\d UTC</span>', dom)
    # the screenshot: the map (below the headline figures and the slider) holds the tracks'
    # colours, nine of tab10's ten (its grey is left out: it is also the background's hue)
    from matplotlib.image import imread

    img = imread(shot)[..., :3]
    assert img.shape[:2] == (HEIGHT, WIDTH)
    area = img[400:1000, 60:WIDTH - 60]
    rgb = np.array([[int(c[i:i + 2], 16) / 255 for i in (1, 3, 5)] for c in PALETTE
                    if c != "#7f7f7f"])
    near = np.abs(area[:, :, None, :] - rgb[None, None]).max(axis=-1) < 0.04
    per_colour = near.sum(axis=(0, 1))
    assert np.all(per_colour >= 40) and per_colour.sum() > 600, per_colour
    # and nothing in those colours above the map: the count is of the map's drawing
    assert not np.any(np.abs(img[:230, :, None, :] - rgb[None, None]).max(axis=-1) < 0.04)


PROBE = """<script>
(function () {  // what a user does: hover a track, move the slider, show whole tracks
  var root = document.getElementById("tk-map"), m = root.tkMap;
  var cv = document.getElementById("tk-canvas"), r = cv.getBoundingClientRect();
  var tr = m.tracks[m.tracks.length - 1], k = tr.x.length >> 1, p = m.toScreen(tr.x[k], tr.y[k]);
  cv.dispatchEvent(new PointerEvent("pointermove", {clientX: r.left + p[0],
                                                    clientY: r.top + p[1], bubbles: true}));
  var tip = document.getElementById("tk-tip");
  root.dataset.probeTip = tip.hidden ? "" : tip.textContent.split("\\n").join(" | ");
  var slider = document.getElementById("tk-time"), drawn = [];
  ["0", "30"].forEach(function (v) {
    slider.value = v; slider.dispatchEvent(new Event("input"));
    drawn.push(root.dataset.tracksDrawn);
  });
  var mode = document.getElementById("tk-mode");
  mode.value = "all"; mode.dispatchEvent(new Event("change")); drawn.push(root.dataset.tracksDrawn);
  root.dataset.probeDrawn = drawn.join(",");
  // zoom in at the canvas' centre by a wheel step, then drag 50 px right and 20 px down
  var cx = r.left + r.width / 2, cy = r.top + r.height / 2, a = m.toScreen(tr.x[k], tr.y[k]);
  cv.dispatchEvent(new WheelEvent("wheel", {clientX: cx, clientY: cy, deltaY: -200,
                                            bubbles: true, cancelable: true}));
  var b = m.toScreen(tr.x[k], tr.y[k]);
  var at = function (type, x, y) {
    cv.dispatchEvent(new PointerEvent(type, {clientX: x, clientY: y, bubbles: true}));
  };
  at("pointerdown", cx, cy); at("pointermove", cx + 50, cy + 20); at("pointerup", cx + 50, cy + 20);
  var c = m.toScreen(tr.x[k], tr.y[k]);
  root.dataset.probeZoom = ((b[0] - r.width / 2) / (a[0] - r.width / 2)).toFixed(4);
  root.dataset.probePan = (c[0] - b[0]).toFixed(2) + "," + (c[1] - b[1]).toFixed(2);
})();
</script>"""


def test_report_map_hover_and_slider(tmp_path):
    """A probe appended to the page hovers the middle of a track, moves the slider, zooms and
    drags: the tip names a track with its MMSI and start time as the track table has them,
    the map draws the tracks confirmed by the slider's time, and zoom and pan move it."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    result = track_recording(samples.path("solent-ais"), TrackOptions(as_radar=True,
                                                                      max_scans=40))
    paths = write_track_report(track_report(result), tmp_path / "out")
    page = paths["html"].read_text(encoding="utf-8").replace("</body>", PROBE + "</body>")
    probe = tmp_path / "probe.html"
    probe.write_text(page, encoding="utf-8")
    dom, console, _ = open_in_chromium(probe, tmp_path)
    assert console == []
    root = re.search(r'<section id="tk-map"[^>]*>', dom).group(0)
    tip = re.search(r'data-probe-tip="([^"]*)"', root).group(1)
    text = {c: pa.string() for c in ("identity", "start_utc")}
    table = pacsv.read_csv(paths["summary"], convert_options=pacsv.ConvertOptions(
        column_types=text)).to_pydict()
    tid = int(re.match(r"track (\d+) \| MMSI ", tip).group(1))
    k = table["id"].index(tid)
    assert f"MMSI {table['identity'][k]} |" in tip
    assert table["start_utc"][k].replace("T", " ").replace("Z", " UTC") in tip
    start = np.array(table["start_s"])
    t = result.history.times
    expected = [int(np.sum(start <= t[0])), int(np.sum(start <= t[30])), len(start)]
    assert expected[0] < expected[1] < expected[2]
    assert re.search(r'data-probe-drawn="([^"]*)"', root).group(1) == ",".join(
        map(str, expected))
    # a wheel step of 200 zooms by exp(200 x 0.0015) about the cursor; a drag moves the map
    zoom = float(re.search(r'data-probe-zoom="([^"]*)"', root).group(1))
    assert zoom == pytest.approx(np.exp(0.3), abs=2e-4)
    assert re.search(r'data-probe-pan="([^"]*)"', root).group(1) == "50.00,20.00"
