"""``trackkit.tracking.recorded``: tracking a recording from Python gives what ``trackkit
track`` writes, bit for bit."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from tests.cli_helpers import trackkit
from trackkit.io import samples
from trackkit.report.track_pages import TRACKS_PARQUET, history_table, write_tracks_parquet
from trackkit.tracking.recorded import (
    TRACK_PROFILES,
    TrackOptions,
    TrackProfile,
    open_recording,
    track_recording,
)


def test_track_recording_gives_the_tracks_trackkit_track_writes(tmp_path):
    out = tmp_path / "cli"
    ran = trackkit("track", "solent-ais", "--as-radar", "--max-scans", "20", "--out", str(out))
    assert ran.code == 0, ran.text
    stages = []
    result = track_recording(samples.path("solent-ais"),
                             TrackOptions(as_radar=True, max_scans=20),
                             progress=lambda stage, done, total: stages.append(stage))
    assert len(result.scans) == 20 and stages[0] == "reading" and stages[-1] == "tracking"
    h = result.history
    assert np.unique(h.ids).size > 0, "no track: the comparison would prove nothing"
    mine = write_tracks_parquet(history_table(h, epoch=result.read.epoch, frame=result.frame,
                                              smoothed=result.smoothed),
                                tmp_path / "mine.parquet")
    written, ours = pq.read_table(out / TRACKS_PARQUET), pq.read_table(mine)
    assert written.equals(ours, check_metadata=True)
    for k, name in enumerate(("x", "y", "vx", "vy")):  # bit for bit, not to rounding
        column = written.column(name).to_numpy()
        assert np.array_equal(column.view(np.int64), h.mean[:, k].view(np.int64))


def test_options_fill_in_the_input_kinds_profile():
    given = TrackOptions(profile=TrackProfile(pd=0.8, q=2))
    ais = given.settings("ais")
    assert (ais.pd, ais.q) == (0.8, 2.0)
    assert ais.period == TRACK_PROFILES["ais"].period
    assert given.settings("detections").period is None  # a detections file has no scans


def test_a_detections_file_is_not_made_into_radar_plots(tmp_path):
    f = tmp_path / "plots.csv"
    f.write_text("time,x,y\n0,1,2\n", encoding="utf-8")
    with pytest.raises(ValueError, match="drop --as-radar"):
        open_recording(f, TrackOptions(as_radar=True))
    assert open_recording(f, TrackOptions()).kind == "detections"
