"""Readers fed malformed input: every bad record is counted and named with its line and
column, and no good record is lost or altered."""

import os
import tempfile

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackkit.io import KNOT, _table, read_ais_csv, read_opensky_csv
from trackkit.io._table import _NUMBER

HEADER = "Time,MMSI,Latitude_degrees,Longitude_degrees,COG_degrees,SOG_knots"
COLS = HEADER.split(",")
BASE_NS = int(np.datetime64("2016-01-12T13:02:11", "ns").astype(np.int64))
IDS = ("235070762", "232002939", "244660000")

GARBAGE = ("abc", "1.2.3", "--5", "0x10", "5e", "1_0", ".", "e5", "12a")
BAD_TIMES = ("2016-13-01 00:00:00", "yesterday", "2016-01-12 25:00:00", "12/01/2016 13:00:00",
             "2016-01-12 13:02", "2016-01-12T13:02:11.1234567891", "1452603731")

# one corruption of one field of a good row: (kind, column index, reason); a bad course or
# speed (columns 4, 5: optional) is set missing, the record kept, counted under the reason
BAD_KINDS = [
    ("garbage", 2, "not a number"), ("garbage", 3, "not a number"),
    ("garbage", 4, "not a number"), ("garbage", 5, "not a number"),
    ("empty", 0, "missing value"), ("empty", 1, "missing value"),
    ("empty", 2, "missing value"), ("empty", 3, "missing value"),
    ("lat_range", 2, "latitude outside [-90, 90]"),
    ("lon_range", 3, "longitude outside [-180, 180]"),
    ("nonfinite", 2, "not finite"), ("nonfinite", 3, "not finite"),
    ("nonfinite", 4, "not finite"), ("nonfinite", 5, "not finite"),
    ("neg_speed", 5, "negative"), ("course_range", 4, "outside [0, 360]"),
    ("bad_time", 0, "bad time"), ("extra", None, "wrong number of fields"),
    ("missing", None, "wrong number of fields"), ("blank", None, "blank line"),
]
OPTIONAL = {4: "course", 5: "speed"}


def _value(text: str, lo: float, hi: float, code: str) -> float:
    """A course or speed as the reader keeps it: nan when blank, the code, or bad."""
    try:
        v = float(text)
    except ValueError:
        return np.nan
    if "_" in text:  # Python's float reads 1_0 as 10; a file's number has no underscores
        return np.nan
    return v if text != code and lo <= v <= hi else np.nan


@st.composite
def good_rows(draw, k):
    """A valid report; its time is unique by construction (k is the row's index)."""
    ms = draw(st.integers(0, 999)) * 1000 + k
    course = draw(st.one_of(st.floats(0, 359.9), st.sampled_from(["", "360"])))
    speed = draw(st.one_of(st.floats(0, 60), st.just("")))
    sep = draw(st.sampled_from([" ", "T"]))
    t = str(np.datetime64(BASE_NS + ms * 1_000_000, "ns").astype("datetime64[ms]"))
    return {
        "ms": ms, "fields": [
            t.replace("T", sep), draw(st.sampled_from(IDS)), repr(draw(st.floats(-90, 90))),
            repr(draw(st.floats(-180, 180))),
            course if isinstance(course, str) else repr(course),
            speed if isinstance(speed, str) else repr(speed)]}


@st.composite
def files(draw):
    n = draw(st.integers(1, 40))
    rows = []
    goods = []
    for k in range(n):
        what = draw(st.sampled_from(["good", "good", "bad", "dup"]))
        if what == "dup" and goods:
            rows.append({**draw(st.sampled_from(goods)), "dup": True})
            continue
        row = draw(good_rows(k))
        if what != "bad":
            rows.append(row)
            goods.append(row)
            continue
        kind, c, reason = draw(st.sampled_from(BAD_KINDS))
        f = list(row["fields"])
        if kind == "garbage":
            f[c] = draw(st.sampled_from(GARBAGE))
        elif kind == "empty":
            f[c] = draw(st.sampled_from(["", "  "]))
        elif kind == "lat_range":  # 91 is "not available", counted apart
            f[c] = repr(draw(st.floats(90.001, 1e4).filter(lambda v: v != 91.0))
                        * draw(st.sampled_from([-1, 1])))
        elif kind == "lon_range":
            f[c] = repr(draw(st.floats(180.001, 1e4).filter(lambda v: v != 181.0))
                        * draw(st.sampled_from([-1, 1])))
        elif kind == "nonfinite":
            f[c] = draw(st.sampled_from(["nan", "inf", "-inf", "NaN", "1e999"]))
        elif kind == "neg_speed":
            f[c] = repr(-draw(st.floats(1e-3, 100)))
        elif kind == "course_range":
            f[c] = repr(draw(st.one_of(st.floats(360.01, 1e4), st.floats(-1e4, -0.01))))
        elif kind == "bad_time":
            f[c] = draw(st.sampled_from(BAD_TIMES))
        elif kind == "extra":
            f = f + ["junk"]
        elif kind == "missing":
            f = f[:draw(st.integers(1, 5))]
        if c in OPTIONAL:  # kept, the value set missing
            row = {**row, "fields": f, "set_missing": (OPTIONAL[c], reason)}
            rows.append(row)
            goods.append(row)
            continue
        rows.append({"fields": f, "bad": (None if c is None else COLS[c], reason),
                     "blank": kind == "blank"})
    return rows


def _write(rows) -> str:
    fd, path = tempfile.mkstemp(suffix=".csv")
    with os.fdopen(fd, "w") as fh:
        fh.write(HEADER + "\n")
        for r in rows:
            fh.write(("" if r.get("blank") else ",".join(r["fields"])) + "\n")
    return path


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(files(), st.sampled_from([None, 300]))
def test_every_bad_record_is_named_and_no_good_record_lost(rows, block_size):
    path = _write(rows)
    # 300-byte blocks: a few records each, so line numbers must carry across blocks
    old = _table.BLOCK_SIZE
    _table.BLOCK_SIZE = block_size or old
    try:
        r, rep = read_ais_csv(path, max_listed=1000)
        lines = {i + 2: row for i, row in enumerate(rows)}
        bad = {ln: row["bad"] for ln, row in lines.items() if "bad" in row}
        good = {ln: row for ln, row in lines.items() if "bad" not in row and "dup" not in row}
        dups = [ln for ln, row in lines.items() if row.get("dup")]

        assert rep.rows_read == len(rows)
        assert rep.rows_read == rep.rows_kept + rep.n_skipped + rep.duplicates
        assert rep.n_skipped == len(bad) and rep.duplicates == len(dups)
        assert rep.skipped_lines.tolist() == sorted(bad)
        # every bad record listed once, at its line, under the corrupted column
        listed = {b.line: (b.column, b.reason) for b in rep.bad}
        assert len(listed) == len(rep.bad) == len(bad)
        for ln, (column, reason) in bad.items():
            assert listed[ln] == (column or "*", reason), (ln, lines[ln]["fields"])
            assert str(next(b for b in rep.bad if b.line == ln)).startswith(f"{path}:{ln}:")
        counts = {}
        for _, reason in bad.values():
            counts[reason] = counts.get(reason, 0) + 1
        assert dict(rep.skipped) == counts
        # a bad course or speed is counted by field and reason, its record kept (an exact
        # duplicate's too: the values are counted before duplicates are dropped)
        soft = {}
        for ln in list(good) + dups:
            if "set_missing" in lines[ln]:
                soft[lines[ln]["set_missing"]] = soft.get(lines[ln]["set_missing"], 0) + 1
        for (label, reason), k in soft.items():
            assert rep.set_missing[label][reason] == k

        # the kept records are exactly the good ones (duplicates: the first copy kept)
        assert sorted(r.line.tolist()) == sorted(good)
        assert len(r) == len(good)
        if not good:
            return
        g = [good[ln] for ln in r.line.tolist()]
        assert r.id.tolist() == [row["fields"][1] for row in g]
        ms = np.array([row["ms"] for row in g])
        epoch_ms = (ms.min() + 11_000) // 1000 * 1000 - 11_000   # first time, floored to 1 s
        np.testing.assert_array_equal(r.time, (ms - epoch_ms) * 1_000_000 / 1e9)
        assert np.all(np.diff(r.time) >= 0)
        lat, lon, _ = r.geodetic()
        f = np.array([row["fields"] for row in g], dtype=object)
        np.testing.assert_allclose(lat, f[:, 2].astype(float), rtol=0, atol=1e-9)
        dlon = (lon - f[:, 3].astype(float) + 180) % 360 - 180  # +-180 are one meridian
        assert np.max(np.abs(dlon)) < 1e-9 * max(1.0, 1 / max(np.cos(np.deg2rad(
            np.abs(lat).max())), 1e-12))
        sog = np.array([_value(s, 0, 1000 / KNOT, "102.3") for s in f[:, 5]])
        cog = np.array([_value(c, 0, 360, "360") for c in f[:, 4]])
        cog = np.where((sog == 0) & np.isnan(cog), 0.0, cog)
        np.testing.assert_allclose(r.vx, sog * KNOT * np.sin(np.deg2rad(cog)), atol=1e-12)
        np.testing.assert_allclose(r.vy, sog * KNOT * np.cos(np.deg2rad(cog)), atol=1e-12)
        # times out of order: kept-or-duplicate records earlier than one above them
        valid = sorted(good) + dups
        t = np.array([lines[ln]["ms"] for ln in sorted(valid)])
        expect = int(np.sum(t[1:] < np.maximum.accumulate(t)[:-1])) if len(t) > 1 else 0
        assert rep.out_of_order == expect

        # on_bad="stop" names the first bad record (blank lines are skipped, never fatal)
        fatal = [ln for ln, (_, reason) in sorted(bad.items()) if reason != "blank line"]
        if fatal:
            column, reason = bad[fatal[0]]
            with pytest.raises(ValueError) as e:
                read_ais_csv(path, on_bad="stop")
            assert str(e.value).startswith(f"{path}:{fatal[0]}:{column or '*'}: {reason}")
        else:
            assert len(read_ais_csv(path, on_bad="stop")[0]) == len(good)
    finally:
        _table.BLOCK_SIZE = old
        os.unlink(path)


def test_stop_names_file_line_column_value_and_expectation(tmp_path):
    p = tmp_path / "ais.csv"
    p.write_text(HEADER + "\n2016-01-12 13:02:11.218,235070762,50.77,-1.09,157.8,5.9\n"
                 "2016-01-12 13:02:12.000,235070762,50.78,-1.09,157.8,5.9\n"
                 "2016-01-12 13:02:13.000,235070762,95.5,-1.09,157.8,5.9\n"
                 "2016-01-12 13:02:14.000,235070762,50.79,west,157.8,5.9\n")
    with pytest.raises(ValueError) as e:
        read_ais_csv(p, on_bad="stop")
    msg = str(e.value)
    assert msg.startswith(f"{p}:4:Latitude_degrees: latitude outside [-90, 90]")
    assert "'95.5'" in msg and "expected a latitude in [-90, 90]" in msg
    r, rep = read_ais_csv(p)
    assert len(r) == 2 and rep.skipped_lines.tolist() == [4, 5]
    assert [str(b) for b in rep.bad][1] == (f"{p}:5:Longitude_degrees: not a number (value "
                                            "'west'; expected a decimal longitude)")
    assert "skipped 2" in rep.summary()


def test_wrong_fields_and_missing_columns(tmp_path):
    p = tmp_path / "ais.csv"
    p.write_text("Time,MMSI,Lat\n2016-01-12 13:02:11,1,50\n")
    with pytest.raises(ValueError, match=r"ais.csv:1: no column 'Latitude_degrees', "
                                         r"'Longitude_degrees'.*the file has 'Time', 'MMSI'"):
        read_ais_csv(p)


def test_other_layout_by_mapping(tmp_path):
    from trackkit.io import AisColumns

    p = tmp_path / "ais.csv"
    p.write_text("mmsi,ts,lon,lat,spd_ms\n"
                 "7,1452603731.5,-1.0,50.0,2.0\n7,1452603730.25,-1.001,50.0,0\n"
                 "8,bad,-1.0,50.0,1\n")
    cols = AisColumns(time="ts", id="mmsi", lat="lat", lon="lon", course=None, speed="spd_ms",
                      time_format="unix", speed_unit="m/s", speed_unavailable=None)
    r, rep = read_ais_csv(p, cols)
    assert r.time.tolist() == [0.25, 1.5] and r.line.tolist() == [3, 2]
    assert rep.out_of_order == 1 and dict(rep.skipped) == {"bad time": 1}
    assert r.vx[0] == 0.0 and np.isnan(r.vx[1])            # at rest; moving, no course
    assert str(rep.epoch) == "2016-01-12T13:02:10.000000000"
    with pytest.raises(ValueError, match="time_format = 'julian'"):
        AisColumns(time_format="julian")
    p.write_text("mmsi,ts,lon,lat\n7,12/01/2016 13:02:11,-1.0,50.0\n")
    r, _ = read_ais_csv(p, AisColumns(time="ts", id="mmsi", lat="lat", lon="lon", course=None,
                                      speed=None, time_format="%d/%m/%Y %H:%M:%S"))
    assert str(r.absolute_time()[0]) == "2016-01-12T13:02:11.000000000"


def test_opensky_no_position_is_skipped_never_fatal(tmp_path):
    p = tmp_path / "os.csv"
    head = ("time,icao24,lat,lon,velocity,heading,vertrate,callsign,onground,baroaltitude,"
            "geoaltitude,lastposupdate\n")
    p.write_text(head +
                 "1626098400,3c4591,51.4,-0.44,254.6,99.6,0.0,BOX413  ,False,10668.0,10843.2,"
                 "1626098398.996\n"
                 "1626098400,3c4592,,,254.6,99.6,0.0,ABC,False,10668.0,10843.2,\n"
                 "1626098410,3c4591,51.4,-0.44,254.6,99.6,0.0,BOX413  ,False,10668.0,10843.2,"
                 "1626098398.996\n"
                 "1626098410,3c4593,51.5,-0.45,,,,,True,,900.0,\n")
    r, rep = read_opensky_csv(p, on_bad="stop")
    assert dict(rep.skipped) == {"no position": 1} and rep.duplicates == 1
    assert r.ids.tolist() == ["3c4591", "3c4593"] and r.line.tolist() == [2, 5]
    assert r.time.tolist() == pytest.approx([0.996, 12.0])       # lastposupdate, else time
    assert r.extra["onground"].tolist() == [False, True]
    assert r.extra["callsign"].tolist() == ["BOX413", ""]
    assert np.isnan(r.vx[1]) and np.isnan(r.vz[1])
    _, _, alt = r.geodetic()
    assert alt == pytest.approx([10843.2, 900.0])
    r, _ = read_opensky_csv(p, altitude="baro")
    assert r.geodetic()[2] == pytest.approx([10668.0, 900.0])      # geo fills a blank baro


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="0123456789+-.eEinfatyINFAY ", max_size=8))
def test_number_pattern_agrees_with_the_cast(s):
    # what the pattern accepts the cast parses, to the same value as Python's float
    s = s.strip()
    arr = pa.array([s])
    if pc.match_substring_regex(arr, _NUMBER)[0].as_py():
        v = pc.cast(arr, pa.float64())[0].as_py()
        assert v == float(s) or (np.isnan(v) and np.isnan(float(s)))


@pytest.mark.parametrize("read_size", [1, 7, 1 << 20])
def test_a_byte_that_is_not_utf8_is_one_bad_record(tmp_path, monkeypatch, read_size):
    # multi-byte characters (ids) and bad bytes cut anywhere by the reads of the file
    monkeypatch.setattr(_table, "READ_SIZE", read_size)
    rows = [f"2016-01-12 13:02:{10 + k:02d}.000,Ålesund-{k}é,50.{k},-1.1,10,5".encode()
            for k in range(12)]
    rows[3] = rows[3].replace(b"50.3", b"5\xea0.3")                   # Latin-1 e-circumflex
    rows[6] = rows[6].replace("Ålesund".encode(), b"\xc5lesund")      # Latin-1 A-ring
    rows[9] = rows[9] + b",\xff\xfe"                                  # and a field too many
    rows[11] = rows[11].replace(b"-1.1", b"-1.1\xe2\x82")             # a cut-off character
    p = tmp_path / "ais.csv"
    p.write_bytes(HEADER.encode() + b"\n" + b"\n".join(rows) + b"\n")
    r, rep = read_ais_csv(p)
    assert [(b.line, b.column, b.reason, b.value, b.expected) for b in rep.bad] == [
        (5, "Latitude_degrees", "not UTF-8 text", "5\\xea0.3", "UTF-8 text, not byte 0xea"),
        (8, "MMSI", "not UTF-8 text", "\\xc5lesund-6é", "UTF-8 text, not byte 0xc5"),
        (11, "*", "wrong number of fields",
         "2016-01-12 13:02:19.000,Ålesund-9é,50.9,-1.1,10,5,\\xff\\xfe", "6 fields, got 7"),
        (13, "Longitude_degrees", "not UTF-8 text", "-1.1\\xe2\\x82",
         "UTF-8 text, not byte 0xe2")]
    assert dict(rep.skipped) == {"not UTF-8 text": 3, "wrong number of fields": 1}
    assert rep.rows_read == 12 and rep.rows_kept == len(r) == 8
    assert sorted(r.ids.tolist()) == sorted(f"Ålesund-{k}é" for k in (0, 1, 2, 4, 5, 7, 8, 10))
    with pytest.raises(ValueError) as e:
        read_ais_csv(p, on_bad="stop")
    assert str(e.value).startswith(f"{p}:5:Latitude_degrees: not UTF-8 text (value "
                                   "'5\\\\xea0.3'; expected UTF-8 text, not byte 0xea)")
    p.write_bytes(b"T\xefme" + HEADER.encode()[4:] + b"\n" + rows[0] + b"\n")
    with pytest.raises(ValueError, match=r"ais.csv:1: the header is not UTF-8 text \(byte 0xef"):
        read_ais_csv(p)


def test_finite_but_absurd_values_are_bad_records(tmp_path):
    import warnings

    from trackkit.io import DetectionColumns, DetectionUnits, read_detections

    p = tmp_path / "os.csv"
    p.write_text("time,icao24,lat,lon,velocity,heading,vertrate,geoaltitude\n"
                 "1626098400,a,51,0,250,10,5,10000\n"
                 "1626098400,b,51,0,1e300,10,5,10000\n"       # speed
                 "1626098400,c,51,0,250,10,-1500,10000\n"     # vertical rate
                 "1626098400,d,51,0,250,10,5,2e5\n"           # altitude, 200 km
                 "1626098400,e,91,0,250,10,5,10000\n"         # latitude
                 "1626098400,f,51,-1e300,250,10,5,10000\n"    # longitude
                 "1626098410,a,51,0.01,999.9,10,-999,-999\n")  # just inside every limit
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r, rep = read_opensky_csv(p)
    assert [(b.line, b.column, b.reason, b.value) for b in rep.bad] == [
        (6, "lat", "latitude outside [-90, 90]", "91"),
        (7, "lon", "longitude outside [-180, 180]", "-1e300")]
    # an absurd optional value is set missing, its record kept
    assert r.line.tolist() == [2, 3, 4, 5, 8]
    assert {k: dict(v) for k, v in rep.set_missing.items()} == {
        "speed": {"magnitude above 1000": 1},
        "vertrate": {"magnitude above 1000": 1},
        "geoaltitude": {"outside [-1000, 100000]": 1}}
    assert np.isnan(r.vx[r.line == 3]).all() and np.isnan(r.vz[r.line == 4]).all()
    assert not r.extra["has_altitude"][r.line == 5].any()
    # detections: the limit of 1e8 m in the file's units, bearings within a turn either way
    p = tmp_path / "d.csv"
    p.write_text("time,r,b\n0,99999,-359\n1,100001,2\n2,5,361\n3,5,-360\n1e11,5,5\n")
    s, rep = read_detections(p, DetectionColumns(sensor=None, range="r", bearing="b"),
                             DetectionUnits(distance="km"))
    assert [(b.line, b.reason) for b in rep.bad] == [
        (3, "|range| above 100000"), (4, "bearing outside [-360, 360]"),
        (6, "time out of range")]
    assert "in km; 1e+08 m" in rep.bad[0].expected
    assert s.times.tolist() == [0.0, 3.0]
    p.write_text("time,r,b\n0,5,6.2\n1,5,6.3\n")
    _, rep = read_detections(p, DetectionColumns(sensor=None, range="r", bearing="b"),
                             DetectionUnits(angle="rad"))
    assert [(b.line, b.reason) for b in rep.bad] == [(3, "bearing outside [-6.28319, 6.28319]")]
