"""Each layout of recorded AIS and ADS-B data recognised from its first lines with no options,
every usable position kept, and what was set missing counted by field and reason."""

from __future__ import annotations

import numpy as np
import pytest

from trackkit.io import KNOT, LAYOUTS, read_recording, recognise
from trackkit.io.layouts import SNIFF_BYTES

from .layout_files import (
    DMA_COLUMNS,
    NOAA_COLUMNS,
    fleet,
    position,
    sbs_line,
    sentences,
    tag_block,
    unix,
    write_dma,
    write_noaa,
)


def _progress_ends_at_size(path, layout):
    calls = []
    read_recording(path, layout, progress=lambda done, total: calls.append((done, total)))
    size = path.stat().st_size
    assert calls and calls[-1] == (size, size)
    assert all(a[0] <= b[0] for a, b in zip(calls, calls[1:], strict=False))


# --- CSV layouts -------------------------------------------------------------------------------


NOAA_SPECIAL = {3: {"COG": "-49.6"}, 5: {"COG": "360.0"}, 7: {"COG": "-120.3"},
                9: {"Heading": "511"}, 11: {"SOG": "102.3"}, 13: {"LAT": "91.0"},
                15: {"LON": "181.0"}, 17: {"SOG": "-0.1", "COG": "-49.6"}}


@pytest.mark.parametrize("variant", ["published", "reordered, TranscieverClass and ETA"])
def test_noaa_is_recognised_and_bad_optional_fields_are_set_missing(tmp_path, variant):
    cols = list(NOAA_COLUMNS)
    if variant != "published":  # another release: other order, the misspelling, more columns
        cols = cols[2:4] + cols[:2] + cols[4:-1] + ["TranscieverClass", "ETA"]
    reps = fleet()
    p = write_noaa(tmp_path / "AIS_2024_01_05.csv", reps, cols, NOAA_SPECIAL)
    assert recognise(p) is LAYOUTS["noaa"]
    r, rep = read_recording(p)
    assert rep.layout == "noaa" and "(noaa layout)" in rep.summary()
    # only the two records with no usable position are skipped; every other one is kept
    assert dict(rep.skipped) == {"position not available (latitude 91)": 1,
                                 "position not available (longitude 181)": 1}
    assert sorted(r.line.tolist()) == [i + 2 for i in range(len(reps)) if i not in (13, 15)]
    assert {k: dict(v) for k, v in rep.set_missing.items()} == {
        "course": {"not available (-49.6)": 2, "not available (360)": 1,
                   "outside [0, 360]": 1},
        "speed": {"not available (102.3)": 1, "negative": 1},
        "heading": {"not available (511)": 1}}
    assert "course 4 (2 not available (-49.6), 1 not available (360), 1 outside [0, 360])" \
        in rep.summary()
    # velocities where course and speed are good; nan where either was set missing
    good = np.array([i not in (3, 5, 7, 11, 17) for i in range(len(reps))])
    kept = r.line - 2
    sog = np.array([reps[i].sog for i in kept]) * KNOT
    cog = np.deg2rad([reps[i].cog for i in kept])
    ok = good[kept]
    np.testing.assert_allclose(r.vx[ok], sog[ok] * np.sin(cog[ok]), atol=0.05 * KNOT)
    assert np.isnan(r.vx[~ok]).all()
    hd = r.extra["heading_deg"]
    assert np.isnan(hd[kept == 9]).all() and np.isfinite(hd[kept != 9]).all()
    _progress_ends_at_size(p, None)


def test_dma_is_recognised_with_day_first_times(tmp_path):
    reps = fleet()
    p = write_dma(tmp_path / "aisdk-2024-01-05.csv", reps,
                  {2: {"Latitude": "91.000000", "Longitude": "181.000000"},
                   4: {"Heading": "", "COG": ""}, 6: {"Heading": "511"}})
    assert recognise(p) is LAYOUTS["dma"]
    r, rep = read_recording(p)
    assert rep.layout == "dma"
    assert dict(rep.skipped) == {"position not available (latitude 91)": 1}
    assert len(r) == len(reps) - 1
    assert {k: dict(v) for k, v in rep.set_missing.items()} == {
        "course": {"blank": 1}, "heading": {"blank": 1, "not available (511)": 1}}
    # 05/01/2024 is the 5th of January, not the 1st of May
    assert str(rep.epoch) == "2024-01-05T12:00:00.000000000"
    t = r.absolute_time()
    want = np.datetime64("2024-01-05T12:00:00") + np.array(
        [round(reps[i].t) for i in r.line - 2]).astype("timedelta64[s]")
    assert (t == want).all()
    _progress_ends_at_size(p, None)


def test_solent_and_opensky_headers_are_recognised(tmp_path):
    p = tmp_path / "solent.csv"
    p.write_text("Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots\n"
                 "2016-01-12 13:02:11.218,235070762,50.77,-1.09,157.8,5.9\n")
    assert recognise(p) is LAYOUTS["solent"]
    q = tmp_path / "states.csv"
    q.write_text("icao24,lat,lon,time,velocity\n3c4591,51.4,-0.44,1626098400,250\n")
    assert recognise(q) is LAYOUTS["opensky"]            # key columns in any order
    r, rep = read_recording(q)
    assert rep.layout == "opensky" and len(r) == 1


def test_an_unknown_layout_says_what_was_expected(tmp_path):
    p = tmp_path / "other.csv"
    p.write_text("when,ship,y,x\n2024-01-05 12:00:00,1,50,-1\n")
    assert recognise(p) is None
    with pytest.raises(ValueError) as e:
        read_recording(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}: not a known layout")
    for expected in ("BaseDateTime, MMSI, LAT, LON", "# Timestamp, MMSI, Latitude, Longitude",
                     "!AIVDM", "MSG,3", "time, icao24, lat, lon"):
        assert expected in msg


def test_a_bad_required_value_names_file_line_column_and_value(tmp_path):
    reps = fleet(2, 5)
    p = write_noaa(tmp_path / "noaa.csv", reps, special={3: {"LAT": "north"}})
    with pytest.raises(ValueError) as e:
        read_recording(p, on_bad="stop")
    assert str(e.value).startswith(f"{p}:5:LAT: not a number (value 'north'; expected a "
                                   "decimal latitude)")


def test_recognition_reads_only_the_first_lines(tmp_path, monkeypatch):
    reps = fleet(4, 3000)
    p = write_noaa(tmp_path / "big.csv", reps)
    assert p.stat().st_size > 4 * SNIFF_BYTES
    read = []
    real_open = open

    def counting_open(*a, **kw):
        fh = real_open(*a, **kw)
        orig = fh.read
        fh.read = lambda n=-1: (read.append(n), orig(n))[1]
        return fh

    monkeypatch.setattr("builtins.open", counting_open)
    assert recognise(p) is LAYOUTS["noaa"]
    assert read == [SNIFF_BYTES]


# --- NMEA AIS ----------------------------------------------------------------------------------


def _nmea_file(tmp_path):
    """Positions with tag blocks, receiver times before and after the sentence, a type 5
    in two parts, a broken pair, type 19 and 24 messages, a bad checksum."""
    reps = fleet(3, 4, dt=10.0)
    lines, expect = [], []
    t0 = int(unix(0))
    for k, r in enumerate(reps):
        msg_type = (1, 18, 19)[k % 3]
        s = sentences(position(r, msg_type))[0]
        style = k % 3
        if style == 0:
            lines.append(tag_block(t0 + int(r.t)) + s)
            t = float(int(r.t))
        elif style == 1:
            lines.append(f"{unix(r.t):.3f} {s}")
            t = r.t
        else:
            lines.append(f"{s},{int(unix(r.t))}")
            t = float(int(r.t))
        expect.append((len(lines), str(r.ident), t))
    five = sentences({"type": 5, "mmsi": reps[0].ident, "shipname": "TEST",
                      "destination": "SOUTHAMPTON"}, seq_id=3)
    lines += [tag_block(t0 + 100) + five[0], five[1]]          # reassembled: a type 5
    lines.append(five[0])                                       # the first part alone
    lines += sentences({"type": 24, "mmsi": reps[1].ident, "partno": 0, "shipname": "B"})
    bad = sentences(position(reps[0]))[0]
    lines.append(bad[:-2] + ("00" if bad[-2:] != "00" else "01"))
    return lines, expect


def test_nmea_sentences_are_recognised_reassembled_and_timed(tmp_path):
    lines, expect = _nmea_file(tmp_path)
    p = tmp_path / "harbour.nmea"
    p.write_text("\n".join(lines) + "\n")
    assert recognise(p) is LAYOUTS["nmea-ais"]
    r, rep = read_recording(p)
    assert rep.layout == "nmea-ais"
    assert dict(rep.skipped) == {"not a position report (type 5)": 1,
                                 "incomplete multi-part message": 1,
                                 "not a position report (type 24)": 1,
                                 "checksum failure": 1}
    # records are messages: the two-part type 5 is one, at its first line
    assert rep.rows_read == len(expect) + 4
    assert [b.line for b in rep.bad] == [len(expect) + 1, len(expect) + 3,
                                         len(expect) + 4, len(expect) + 5]
    got = sorted(zip(r.line.tolist(), r.id.tolist(), r.time.tolist(), strict=True))
    assert [(ln, i) for ln, i, _ in got] == [(ln, i) for ln, i, _ in expect]
    t_abs = r.epoch.astype("datetime64[ns]").astype(np.int64) / 1e9 + np.array(
        [t for *_, t in got])
    np.testing.assert_allclose(t_abs, [unix(t) for *_, t in expect], rtol=0, atol=1e-6)
    _progress_ends_at_size(p, None)


def test_nmea_not_available_codes_and_a_bad_sentence_with_stop(tmp_path):
    r0 = fleet(1, 1)[0]
    lines = [tag_block(int(unix(0))) + sentences(position(
        r0, speed=102.3, course=360.0, heading=511))[0],
        tag_block(int(unix(1))) + sentences(position(r0, lat=91.0, lon=181.0))[0],
        "this is not a sentence"]
    p = tmp_path / "codes.nmea"
    p.write_text("\n".join(lines) + "\n")
    r, rep = read_recording(p, "nmea-ais")
    assert len(r) == 1 and np.isnan(r.vx).all()
    assert {k: dict(v) for k, v in rep.set_missing.items()} == {
        "course": {"not available (360)": 1}, "speed": {"not available (102.3)": 1},
        "heading": {"not available (511)": 1}}
    assert dict(rep.skipped) == {"position not available (latitude 91)": 1, "malformed": 1}
    with pytest.raises(ValueError) as e:
        read_recording(p, "nmea-ais", on_bad="stop")
    assert str(e.value).startswith(f"{p}:3:*: malformed (value 'this is not a sentence'")


# --- SBS-1 -------------------------------------------------------------------------------------


def test_sbs1_positions_with_velocity_merged(tmp_path):
    lines = [sbs_line(1, "4CA2D6", 0.0, callsign="RYR123"),
             sbs_line(4, "4CA2D6", 0.5, speed="420", track="90.0", vrate="-640"),
             sbs_line(3, "4CA2D6", 1.0, alt="37000", lat="51.47", lon="-0.46"),
             "STA,,5,179,4CA2D6,10103,2024/01/05,12:00:01.100,2024/01/05,12:00:01.100,RM",
             sbs_line(3, "40621D", 1.5, alt="12000", lat="51.57", lon="-0.40"),
             sbs_line(3, "4CA2D6", 2.0, alt="37025", lat="51.47", lon="-0.455"),
             sbs_line(3, "40621D", 2.5, alt="12000", lat="", lon=""),
             sbs_line(2, "40621E", 3.0, alt="", speed="12", track="180", lat="51.47",
                      lon="-0.46")]
    p = tmp_path / "adsb.sbs"
    p.write_text("\n".join(lines) + "\n")
    assert recognise(p) is LAYOUTS["sbs1"]
    r, rep = read_recording(p)
    assert rep.layout == "sbs1"
    assert r.line.tolist() == [3, 5, 6, 8]
    assert dict(rep.skipped) == {"not a position (MSG 1)": 1, "not a position (MSG 4)": 1,
                                 "not a position (STA line)": 1, "missing value": 1}
    # the type 4 velocity of 4CA2D6 carried to its positions; 40621D has none
    v = np.hypot(r.vx, r.vy)
    np.testing.assert_allclose(v[[0, 2]], 420 * KNOT)
    np.testing.assert_allclose(r.vx[[0, 2]], 420 * KNOT * np.sin(np.deg2rad(90.0)))
    np.testing.assert_allclose(r.vz[[0, 2]], -640 * 0.3048 / 60)
    assert np.isnan(v[1]) and v[3] == pytest.approx(12 * KNOT)
    _, _, alt = r.geodetic()
    assert alt[:3] == pytest.approx([37000 * 0.3048, 12000 * 0.3048, 37025 * 0.3048])
    assert r.extra["has_altitude"].tolist() == [True, True, True, False]
    _progress_ends_at_size(p, None)


def test_layout_names_and_profiles():
    kinds = {name: lay.kind for name, lay in LAYOUTS.items()}
    assert kinds == {"solent": "ais", "noaa": "ais", "dma": "ais", "opensky": "opensky",
                     "nmea-ais": "ais", "sbs1": "opensky"}
    assert DMA_COLUMNS[0] == "# Timestamp"


def test_nmea_without_receiver_times_is_timed_by_base_stations(tmp_path):
    reps = fleet(2, 3, dt=10.0)  # UTC seconds 0 to 20 of the minute
    base = sentences({"type": 4, "mmsi": 2_190_000, "year": 2024, "month": 1, "day": 5,
                      "hour": 11, "minute": 59, "second": 58, "lat": 50.8, "lon": -1.1})[0]
    lines = [sentences(position(reps[0]))[0], base]        # before the clock: no time
    lines += [sentences(position(r))[0] for r in reps[1:]]
    p = tmp_path / "plain.nmea"
    p.write_text("\n".join(lines) + "\n")
    r, rep = read_recording(p)
    assert dict(rep.skipped) == {"no time": 1, "not a position report (type 4)": 1}
    # each message at its own UTC second, in the minute nearest the base station's time
    want = [np.datetime64("2024-01-05T12:00:00") + np.timedelta64(int(x.t) % 60, "s")
            for x in reps[1:]]
    got = sorted(zip(r.line.tolist(), r.absolute_time().astype("datetime64[s]").tolist(),
                     strict=True))
    assert [g[1] for g in got] == [w.astype(object) for w in want]
