"""``trackkit track FILE --as-radar`` on a NOAA, a DMA, an NMEA and an SBS-1 file with no
--columns, through the real CLI in a subprocess; and a user's bad value as a one-line error."""

from __future__ import annotations

import json

import pytest

from ..cli_helpers import assert_user_error, trackkit
from .layout_files import (
    fleet,
    position,
    sbs_line,
    sentences,
    tag_block,
    unix,
    write_dma,
    write_noaa,
)


def _nmea(path):
    lines = [tag_block(int(unix(r.t))) + sentences(position(r))[0] for r in fleet()]
    path.write_text("\n".join(lines) + "\n")
    return path


def _sbs(path):
    lines = []
    for r in fleet(3, 40, dt=5.0):  # aircraft: the same legs, a hundred times as fast
        lat = 51.0 + (r.lat - 50.8) * 100
        lon = -1.0 + (r.lon + 1.1) * 100
        lines.append(sbs_line(3, f"4CA{r.ident % 1000:03d}", r.t, alt="30000",
                              lat=f"{lat:.5f}", lon=f"{lon:.5f}"))
    path.write_text("\n".join(lines) + "\n")
    return path


FILES = {"noaa": lambda d: write_noaa(d / "AIS_2024_01_05.csv", fleet(),
                                      special={3: {"COG": "-49.6"}}),
         "dma": lambda d: write_dma(d / "aisdk-2024-01-05.csv", fleet()),
         "nmea-ais": lambda d: _nmea(d / "harbour.nmea"),
         "sbs1": lambda d: _sbs(d / "adsb.sbs")}


@pytest.mark.parametrize("layout", list(FILES))
def test_track_recognises_the_layout_without_columns(tmp_path, layout):
    path = FILES[layout](tmp_path)
    out = tmp_path / "out"
    ran = trackkit("track", str(path), "--as-radar", "--max-scans", "8", "--out", str(out))
    assert ran.code == 0, ran.text
    assert f"({layout} layout)" in ran.out
    doc = json.loads((out / "results.json").read_text())
    assert doc["config"]["virtual radar"]["objects_in_file"] == (3 if layout == "sbs1" else 4)
    if layout == "noaa":
        assert "course 1 (1 not available (-49.6))" in ran.out


def test_a_bad_value_with_on_bad_stop_is_one_line(tmp_path):
    path = write_noaa(tmp_path / "noaa.csv", fleet(2, 5), special={4: {"LAT": "5O.8"}})
    ran = trackkit("track", str(path), "--as-radar", "--on-bad", "stop",
                   "--out", str(tmp_path / "out"))
    assert_user_error(ran, 2, f"{path}:6:LAT", "'5O.8'", "expected a decimal latitude")
