"""NMEA 0183 and CSV GPS/INS logs (trackkit.io.nmea): simulator -> log -> reader round trips
to the printed precision, the checked-in fixture, and fuzzed logs in which every bad line is
counted and named by its line and no good line is lost.

The fixture ``tests/fixtures/sar_trial.nmea`` (and ``sar_trial_inputs.csv``) is regenerated
with ``python tests/fixtures/make_sar_fixture.py`` (see its docstring).

Tolerances come from the printed digits (half a unit of the last one): latitude and longitude
1e-5 minute -> 0.5e-5 / 60 deg; SOG 0.001 kn -> 0.0005 kn; COG and heading 0.01 deg ->
0.005 deg; ROT 0.01 deg/min -> 0.005 deg/min; GGA/RMC time 0.01 s -> 0.005 s; TAG time 1 ms
-> 0.5 ms. The CSV form prints latitude and longitude to 1e-8 deg.
"""

import dataclasses
import datetime as dt
import functools
import importlib.util
import operator
from pathlib import Path

import numpy as np
import pynmea2
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trackkit.angles import wrap
from trackkit.io.frames import KNOT
from trackkit.io.nmea import (
    NavLog,
    format_sentence,
    nmea_lines,
    read_nav_csv,
    read_nmea,
    write_nav_csv,
    write_nmea,
)
from trackkit.io.records import one_run
from trackkit.sim.gnss import GpsModel, InsModel, simulate_gnss

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
DEG = np.pi / 180
TOL_LATLON = 0.5e-5 / 60 + 1e-12  # deg
TOL_SOG = 0.0005 * KNOT + 1e-12  # m/s
TOL_ANGLE = 0.005 * DEG + 1e-12  # rad
TOL_ROT = 0.005 * DEG / 60 + 1e-15  # rad/s


def _fixture_module():
    spec = importlib.util.spec_from_file_location("make_sar_fixture",
                                                  FIXTURES / "make_sar_fixture.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def xor(body: str) -> str:
    """The NMEA checksum, computed here independently of the module."""
    return f"{functools.reduce(operator.xor, map(ord, body), 0):02X}"


def turn_truth(duration=120.0, rate=10.0, speed=9.0, v=-0.8, r=6.0 * DEG, psi0=5.9):
    t = np.arange(int(duration * rate) + 1) / rate
    psi = psi0 + r * t
    e = (speed * (np.cos(psi0) - np.cos(psi)) + v * (np.sin(psi) - np.sin(psi0))) / r
    n = (speed * (np.sin(psi) - np.sin(psi0)) - v * (np.cos(psi0) - np.cos(psi))) / r
    return t, e, n, psi, np.full_like(t, speed), np.full_like(t, v), np.full_like(t, r)


def check_close(log: NavLog, gps, ins, gps_tol=0.005, ins_tol=0.0005, velocity=True,
                heading=True):
    assert np.allclose(log.t_pos, gps.t, atol=gps_tol, rtol=0)
    assert np.max(np.abs(log.lat - gps.lat)) <= TOL_LATLON
    assert np.max(np.abs(log.lon - gps.lon)) <= TOL_LATLON
    if velocity:
        assert np.allclose(log.t_vel, gps.t, atol=gps_tol, rtol=0)
        assert np.max(np.abs(log.sog - gps.sog)) <= TOL_SOG
        assert np.max(np.abs(wrap(log.cog - gps.cog))) <= TOL_ANGLE
    if heading:
        assert np.allclose(log.t_heading, ins.t, atol=ins_tol, rtol=0)
        assert np.max(np.abs(wrap(log.heading - ins.heading))) <= TOL_ANGLE
        assert np.allclose(log.t_rate, ins.t, atol=ins_tol, rtol=0)
        assert np.max(np.abs(log.rate - ins.rate)) <= TOL_ROT


# -- round trips -------------------------------------------------------------------------------


@pytest.mark.parametrize("sentences, start", [
    (("GGA", "RMC", "HDT", "ROT"), "2024-06-01T23:59:00"),       # crosses midnight
    (("GGA", "VTG", "THS", "ROT"), "2023-12-31T23:58:30.25"),     # and the year
    (("RMC", "HDT", "ROT"), dt.datetime(2024, 3, 1, 8, 0, tzinfo=dt.UTC)),
])
def test_simulator_log_reader_round_trip(tmp_path, sentences, start):
    gps, ins = simulate_gnss(*turn_truth(), rng=np.random.default_rng(1))
    path = tmp_path / "trial.nmea"
    n = write_nmea(path, gps, ins, start, sentences=sentences)
    assert n == len(gps.t) * sum(s in ("GGA", "RMC", "VTG") for s in sentences) + \
        len(ins.t) * sum(s in ("HDT", "THS", "ROT") for s in sentences)
    log, rep = read_nmea(path)
    assert rep.rows_read == rep.rows_kept + rep.duplicates == n and rep.n_skipped == 0
    # GGA and RMC of one fix both give the position: the RMC (or GGA) adds the velocity, so
    # nothing is a duplicate; the epoch is the first fix
    assert rep.duplicates == 0 and rep.out_of_order == 0
    start64 = np.datetime64(start.replace(tzinfo=None) if isinstance(start, dt.datetime)
                            else start, "ns")
    assert log.epoch == rep.epoch == start64
    check_close(log, gps, ins)
    assert np.all(np.diff(log.t_pos) > 0)


def test_without_tag_blocks_an_ins_sampled_with_the_gps_is_exact(tmp_path):
    truth = turn_truth()
    gps, ins = simulate_gnss(*truth, rng=np.random.default_rng(2), ins=InsModel(rate=2.0))
    path = tmp_path / "notag.nmea"
    write_nmea(path, gps, ins, "2024-06-01T10:00:00", tag_blocks=False)
    assert not path.read_text().startswith("\\")
    log, rep = read_nmea(path)
    assert rep.n_skipped == 0 and rep.duplicates == 0
    check_close(log, gps, ins)


def test_without_tag_blocks_a_faster_ins_is_decimated_and_counted(tmp_path):
    gps, ins = simulate_gnss(*turn_truth(duration=10), rng=np.random.default_rng(2))
    path = tmp_path / "notag10.nmea"
    write_nmea(path, gps, ins, "2024-06-01T10:00:00", tag_blocks=False)
    log, rep = read_nmea(path)
    # INS at 10 Hz, GPS at 2 Hz: the 4 INS samples after each fix repeat its time
    assert rep.duplicates == 2 * 4 * 20 and rep.n_skipped == 0
    assert np.array_equal(log.t_heading, gps.t)
    assert rep.rows_read == rep.rows_kept + rep.duplicates


def test_written_sentences_have_valid_checksums():
    gps, ins = simulate_gnss(*turn_truth(duration=5), rng=np.random.default_rng(3))
    lines = nmea_lines(gps, ins, "2024-06-01T00:00:00",
                       sentences=("GGA", "RMC", "VTG", "HDT", "THS", "ROT"))
    kinds = set()
    for s in lines:
        tag, sentence = s[1:].split("\\", 1)
        body, cs = tag.split("*")
        assert xor(body) == cs and body.startswith("c:")
        assert xor(sentence[1:sentence.index("*")]) == sentence[-2:]
        kinds.add(pynmea2.parse(sentence, check=True).sentence_type)  # pynmea2 agrees
    assert kinds == {"GGA", "RMC", "VTG", "HDT", "THS", "ROT"}
    assert format_sentence("GPGGA", ["1", "2"]) == "$GPGGA,1,2*" + xor("GPGGA,1,2")


def test_printed_fields():
    s = format_sentence("HEROT", ["-3.25", "A"], tag_time_ms=1717243200123)
    assert s == "\\c:1717243200123*" + xor("c:1717243200123") + "\\$HEROT,-3.25,A*" + \
        xor("HEROT,-3.25,A")
    gps, ins = simulate_gnss(*turn_truth(duration=1), rng=np.random.default_rng(3),
                             gps=GpsModel(sigma_position=0, sigma_velocity=0))
    gga = nmea_lines(gps, None, "2024-06-01T12:34:56.789", sentences=("GGA",),
                     tag_blocks=False)[0]
    f = gga.split(",")
    assert f[1] == "123456.79" and f[2] == "3025.80000" and f[3] == "N"
    assert f[4] == "04904.20000" and f[5] == "E" and f[6] == "1"
    # 59.999996 minutes round up into the next degree
    g = gps._replace(lat=np.full_like(gps.lat, 30 + 59.999996 / 60))
    assert nmea_lines(g, None, "2024-06-01", sentences=("GGA",))[0].split(",")[2] == \
        "3100.00000"


def test_write_errors_name_the_problem(tmp_path):
    gps, ins = simulate_gnss(*[np.broadcast_to(x, (2,) + np.shape(x)) if i else x
                               for i, x in enumerate(turn_truth(duration=2))],
                             rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"gps.lat has shape \(2, 5\).*one_run"):
        nmea_lines(gps, ins, "2024-06-01")
    g1, i1 = one_run(gps, 0), one_run(ins, 0)
    assert len(nmea_lines(g1, i1, "2024-06-01")) == 2 * 5 + 2 * 21
    with pytest.raises(ValueError, match=r"sentences = \('GGA', 'GSV'\)"):
        nmea_lines(g1, i1, "2024-06-01", sentences=("GGA", "GSV"))
    with pytest.raises(ValueError, match="start = None"):
        nmea_lines(g1, i1, None)
    with pytest.raises(ValueError, match=r"gps_talker = 'G'"):
        nmea_lines(g1, i1, "2024-06-01", gps_talker="G")


# -- the fixture ---------------------------------------------------------------------------------


def test_fixture_reads_clean_and_matches_its_generator():
    mod = _fixture_module()
    log, rep = read_nmea(FIXTURES / "sar_trial.nmea")
    assert (FIXTURES / "sar_trial.nmea").stat().st_size < 200_000
    assert rep.rows_read == rep.rows_kept == 1996 and rep.n_skipped == rep.duplicates == 0
    assert str(rep.epoch) == "2024-06-01T23:58:30.000000000"
    # the log crosses midnight: 90 s in, the time of day rolls over to 00:00:00
    assert log.t_pos[0] == 0 and log.t_pos[-1] == 166.0 and np.all(np.diff(log.t_pos) == 1.0)
    assert str(log.absolute_time(log.t_pos[-1:])[0]) == "2024-06-02T00:01:16.000000000"
    assert len(log.t_heading) == len(log.t_rate) == 5 * 166 + 1
    # regenerated here: equal to one unit of the last printed digit (a CPU that rounds a
    # sine differently in the last bit may flip a printed digit; on one machine it is equal)
    gps, ins = mod.sensors()
    assert np.max(np.abs(log.lat - gps.lat)) <= 2 * TOL_LATLON
    assert np.max(np.abs(log.lon - gps.lon)) <= 2 * TOL_LATLON
    assert np.max(np.abs(log.sog - gps.sog)) <= 2 * TOL_SOG
    assert np.max(np.abs(wrap(log.cog - gps.cog))) <= 2 * TOL_ANGLE
    assert np.max(np.abs(wrap(log.heading - ins.heading))) <= 2 * TOL_ANGLE
    assert np.max(np.abs(log.rate - ins.rate)) <= 2 * TOL_ROT


def test_fixture_regenerates(tmp_path):
    mod = _fixture_module()
    nmea, csv = mod.write(tmp_path)
    new = nmea.read_text().splitlines()
    old = (FIXTURES / "sar_trial.nmea").read_text().splitlines()
    assert len(new) == len(old)
    # the same sentences in the same order; the same values to one unit in the last digit
    assert [s.split(",")[0] for s in new] == [s.split(",")[0] for s in old]
    a, _ = read_nmea(nmea)
    b, _ = read_nmea(FIXTURES / "sar_trial.nmea")
    for name in ("t_pos", "t_heading", "line_pos", "line_heading", "line_rate"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert np.max(np.abs(a.lat - b.lat)) <= 2.1e-7 and np.max(np.abs(a.rate - b.rate)) < 3e-6
    assert csv.read_text().splitlines()[0] == "time,nozzle_deg,rpm"
    assert len(csv.read_text().splitlines()) == len(
        (FIXTURES / "sar_trial_inputs.csv").read_text().splitlines()) == 168


# -- times -------------------------------------------------------------------------------------


def _write_lines(tmp_path, lines, name="log.nmea"):
    p = tmp_path / name
    p.write_bytes(b"".join((s if isinstance(s, bytes) else s.encode()) + b"\r\n"
                           for s in lines))
    return p


def _gga(tod, lat="3025.80000", q="1"):
    return format_sentence("GPGGA", [tod, lat, "N", "04904.20000", "E", q, "08", "1.0", "0.0",
                                     "M", "0.0", "M", "", ""])


def test_midnight_rollover_of_the_time_of_day(tmp_path):
    lines = [_gga("235959.00"), _gga("235959.50"), _gga("000000.00"), _gga("000000.50"),
             _gga("000000.20"), _gga("000001.00")]
    p = _write_lines(tmp_path, lines)
    log, rep = read_nmea(p, date="2024-06-01")
    assert log.epoch == np.datetime64("2024-06-01T23:59:59", "ns")
    assert log.t_pos.tolist() == [0.0, 0.5, 1.0, 1.2, 1.5, 2.0]
    # the small step back is out of order (kept, sorted, named), not a day forward
    assert rep.out_of_order == 1 and log.out_of_order_lines.tolist() == [5]
    assert log.line_pos.tolist() == [1, 2, 3, 5, 4, 6]
    # no date anywhere: relative times, no epoch
    log2, rep2 = read_nmea(p)
    assert log2.epoch is None and rep2.epoch is None
    assert np.array_equal(log2.t_pos, log.t_pos)
    with pytest.raises(ValueError, match="epoch given but the log has no date"):
        read_nmea(p, epoch="2024-06-01T00:00:00")
    # an RMC date later in the file dates the GGA lines before it
    rmc = format_sentence("GPRMC", ["000001.50", "A", "3025.80000", "N", "04904.20000", "E",
                                    "10.0", "90.0", "020624", "", "", "A"])
    log3, _ = read_nmea(_write_lines(tmp_path, lines + [rmc], "dated.nmea"))
    assert log3.epoch == np.datetime64("2024-06-01T23:59:59", "ns")
    assert log3.t_pos[-1] == 2.5 and log3.t_vel.tolist() == [2.5]


def test_tag_block_times_in_seconds_and_milliseconds(tmp_path):
    hdt = format_sentence("HEHDT", ["123.40", "T"])
    lines = [format_sentence("HEHDT", ["123.40", "T"], 1717243200250),
             "\\c:1717243201*" + xor("c:1717243201") + "\\" + hdt,
             "\\s:GP01,c:1717243201.75*" + xor("s:GP01,c:1717243201.75") + "\\" + hdt]
    log, rep = read_nmea(_write_lines(tmp_path, lines))
    assert rep.n_skipped == 0
    assert log.epoch == np.datetime64("2024-06-01T12:00:00.250", "ns")
    assert log.t_heading.tolist() == [0.0, 0.75, 1.5]
    assert np.allclose(log.heading, 123.4 * DEG)


def test_untimed_sentences_before_any_time_are_skipped(tmp_path):
    lines = [format_sentence("HEHDT", ["10.00", "T"]), _gga("120000.00"),
             format_sentence("HEHDT", ["11.00", "T"]), format_sentence("HEROT", ["6.00", "A"])]
    log, rep = read_nmea(_write_lines(tmp_path, lines), date=dt.date(2024, 6, 1))
    assert dict(rep.skipped) == {"no time": 1} and rep.skipped_lines.tolist() == [1]
    assert rep.bad[0].line == 1 and rep.bad[0].reason == "no time"
    assert log.t_heading.tolist() == [0.0] and log.line_heading.tolist() == [3]
    assert np.isclose(log.rate[0], 0.1 * DEG)


# -- bad lines ---------------------------------------------------------------------------------


def test_bad_fields_are_named(tmp_path):
    lines = [
        _gga("120000.00", lat="48x7.038"),                                        # 1
        _gga("126000.00"),                                                        # 2
        format_sentence("GPRMC", ["120001.00", "A", "3025.8", "N", "04904.2", "E", "10.0",
                                  "400.0", "010624", "", "", "A"]),               # 3
        format_sentence("GPRMC", ["120001.00", "A", "3025.8", "N", "04904.2", "E", "1e1",
                                  "40.0", "010624", "", "", "A"]),                # 4
        format_sentence("GPRMC", ["120001.00", "A", "3025.8", "N", "04904.2", "E", "10",
                                  "40.0", "310224", "", "", "A"]),                # 5
        format_sentence("HEHDT", ["nan", "T"], 1717243200000),                    # 6
        format_sentence("HEROT", ["3.0", "X"], 1717243200000),                    # 7
        _gga("120000.00", q="0"),                                                 # 8
        format_sentence("GPRMC", ["120001.00", "V", "", "", "", "", "", "", "010624", "", "",
                                  "N"]),                                          # 9
        format_sentence("HETHS", ["", "V"], 1717243200000),                       # 10
        format_sentence("HEROT", ["", "V"], 1717243200000),                       # 11
        "$GPGGA,120000.00,3025.8,N,04904.2,E,1,08,1.0,0.0,M",                     # 12
        "\\c:1717243200000*00\\$HEHDT,10.00,T*" + xor("HEHDT,10.00,T"),           # 13
        "hello, world",                                                           # 14
        "",                                                                       # 15
        format_sentence("GPGSV", ["3", "1", "11"]),                               # 16
        "!AIVDM,1,1,,A,13aG?P0P00PD;88MD5MTDww@2<0L,0*" + xor(
            "AIVDM,1,1,,A,13aG?P0P00PD;88MD5MTDww@2<0L,0"),                       # 17
        format_sentence("GPGGA", ["120000.00", "3025.8", "N"]),                   # 18
    ]
    log, rep = read_nmea(_write_lines(tmp_path, lines))
    got = {b.line: (b.reason, b.column, b.value) for b in rep.bad}
    assert got == {
        1: ("malformed", "GGA latitude", "48x7.038"),
        2: ("malformed", "GGA time", "126000.00"),
        3: ("malformed", "RMC course", "400.0"),
        4: ("malformed", "RMC speed", "1e1"),
        5: ("malformed", "RMC date", "310224"),
        6: ("malformed", "HDT heading", "nan"),
        7: ("malformed", "ROT status", "X"),
        8: ("invalid fix", "GGA quality", "0"),
        9: ("invalid fix", "RMC status", "V"),
        10: ("invalid fix", "THS heading", ""),
        11: ("invalid fix", "ROT status", "V"),
        12: ("truncated", "*", lines[11]),
        13: ("checksum failure", "TAG block checksum", "00"),
        14: ("malformed", "*", "hello, world"),
        15: ("blank line", "*", ""),
        18: ("malformed", "GGA fields", "3"),
    }
    assert dict(log.unsupported) == {"GPGSV": 1, "AIVDM": 1}
    assert log.unsupported_lines.tolist() == [16, 17]
    assert rep.skipped_lines.tolist() == list(range(1, 19))
    assert rep.rows_read == 18 and rep.rows_kept == 0
    s = str(rep.bad[0])
    assert s.startswith(f"{tmp_path / 'log.nmea'}:1:GGA latitude: malformed (value '48x7.038'")
    assert "unsupported sentence" in rep.summary()


def test_on_bad_stop_raises_at_the_first_real_error(tmp_path):
    good = _gga("120000.00")
    bad_cs = good[:-2] + ("00" if good[-2:] != "00" else "01")
    p = _write_lines(tmp_path, [good, format_sentence("GPGSV", ["1"]), _gga("120001.00", q="0"),
                                "", bad_cs, good])
    with pytest.raises(ValueError, match=rf"{p}:5:checksum: checksum failure .*on_bad='stop'"):
        read_nmea(p, on_bad="stop")
    with pytest.raises(ValueError, match="on_bad = 'raise'; expected 'skip' or 'stop'"):
        read_nmea(p, on_bad="raise")
    log, rep = read_nmea(p)
    assert rep.duplicates == 1 and rep.rows_kept == 1  # the same fix twice: the first kept


# -- fuzzing -----------------------------------------------------------------------------------

BASE = np.datetime64("2024-06-01T12:00:00", "ns")
BASE_MS = int(BASE.astype("datetime64[ms]").astype(np.int64))


def _tod(ms: int) -> str:
    t = np.datetime64(BASE_MS + ms, "ms").astype(object)
    return t.strftime("%H%M%S.") + f"{t.microsecond // 10_000:02d}"


def _dm(value: float, minutes_digits: int, width: int) -> tuple[str, float]:
    """Printed ddmm.mmm and the value it means (deg, unsigned)."""
    units = round(abs(value) * 60 * 10**minutes_digits)
    d, m = divmod(units, 60 * 10**minutes_digits)
    text = f"{d:0{width}d}{m // 10**minutes_digits:02d}.{m % 10**minutes_digits:0{minutes_digits}d}"
    return text, d + float(text[width:]) / 60


@st.composite
def good_line(draw, kind, ms, tag):
    """A good sentence at time ``ms`` (ms after BASE) and what the reader must return."""
    lat = draw(st.floats(-89.9, 89.9))
    lon = draw(st.floats(-179.9, 179.9))
    lat_s, lat_v = _dm(lat, draw(st.integers(1, 6)), 2)
    lon_s, lon_v = _dm(lon, draw(st.integers(1, 6)), 3)
    ns, ew = ("S" if lat < 0 else "N"), ("W" if lon < 0 else "E")
    lat_v, lon_v = (-lat_v if lat < 0 else lat_v), (-lon_v if lon < 0 else lon_v)
    sog = f"{draw(st.floats(0, 40)):.{draw(st.integers(0, 3))}f}"
    cog = f"{draw(st.floats(0, 359.99)):.2f}"
    hdg = f"{draw(st.floats(0, 359.99)):.2f}"
    rot = f"{draw(st.floats(-300, 300)):.2f}"
    t = ms / 1000
    vel = ("vel", t, (float(sog) * KNOT, float(cog) * DEG))
    if kind == "GGA":
        s = format_sentence("GPGGA", [_tod(ms), lat_s, ns, lon_s, ew, "1", "08", "1.0", "0.0",
                                      "M", "0.0", "M", "", ""], tag)
        exp = [("pos", t, (lat_v, lon_v))]
    elif kind == "RMC":
        s = format_sentence("GPRMC", [_tod(ms), "A", lat_s, ns, lon_s, ew, sog, cog, "010624",
                                      "", "", "A"], tag)
        exp = [("pos", t, (lat_v, lon_v)), vel]
    elif kind == "VTG":
        s = format_sentence("GPVTG", [cog, "T", "", "M", sog, "N", "", "K", "A"], tag)
        exp = [vel]
    elif kind in ("HDT", "THS"):
        s = format_sentence("HE" + kind, [hdg, "T" if kind == "HDT" else "A"], tag)
        exp = [("heading", t, (float(hdg) * DEG,))]
    else:
        s = format_sentence("HEROT", [rot, "A"], tag)
        exp = [("rate", t, (float(rot) * DEG / 60,))]
    return s, exp


TIMED = ("GGA", "RMC")
KINDS = ("GGA", "RMC", "VTG", "HDT", "THS", "ROT")
UNSUPPORTED = [("GPGSV", "$GPGSV,3,1,11,03,03,111,00"),
               ("GPZDA", "$GPZDA,120000.00,01,06,2024,00,00"),
               ("PSRF103", "$PSRF103,00,01,00,01"), ("XXABC", "$XXABC,1,2"),
               ("AIVDM", "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0")]
INVALID = ["GPGGA,{tod},,,,,0,00,99.9,,,,,,", "GPRMC,{tod},V,,,,,,,010624,,,N", "HEROT,,V",
           "HETHS,,V", "GPVTG,,T,,M,,N,,K,N"]


@st.composite
def fuzzed_log(draw):
    """Lines (str or bytes) and, per line, what it is: ("good", expectations, out_of_order),
    ("bad", reason), ("unsupported", address)."""
    n = draw(st.integers(1, 30))
    lines, what = [], []
    latest: dict[str, int] = {}
    used: set[tuple[str, int]] = set()
    for k in range(n):
        ms = 200 * k + 20 * draw(st.integers(0, 9))  # good times: increasing, even 10 ms
        kind = draw(st.sampled_from(KINDS))
        tag = BASE_MS + ms if (kind not in TIMED or draw(st.booleans())) else None
        s, exp = draw(good_line(kind, ms, tag))
        op = draw(st.sampled_from(["good"] * 4 + ["checksum", "tag_checksum", "truncated",
                                                  "garbage", "binary", "unsupported",
                                                  "invalid", "out_of_order", "blank"]))
        streams = {e[0] for e in exp}
        if op == "out_of_order" and all(st_ in latest for st_ in streams):
            # an odd multiple of 10 ms before the latest of its quantities: never a good time
            back = min(latest[x] for x in streams)
            ms2 = back - 10 * (2 * draw(st.integers(0, 20)) + 1)
            if ms2 >= 0 and not any((x, ms2) in used for x in streams):
                tag2 = BASE_MS + ms2 if (kind not in TIMED or tag is not None) else None
                s, exp = draw(good_line(kind, ms2, tag2))
                used.update((x, ms2) for x in streams)
                lines.append(s)
                what.append(("good", exp, True))
                continue
            op = "good"
        elif op == "out_of_order":
            op = "good"
        if op == "good":
            for x in streams:
                latest[x] = max(latest.get(x, -1), ms)
            used.update((x, ms) for x in streams)
            lines.append(s)
            what.append(("good", exp, False))
        elif op == "checksum":
            cs = s[-2:]
            lines.append(s[:-2] + draw(st.sampled_from([f"{i:02X}" for i in range(256)
                                                        if f"{i:02X}" != cs])))
            what.append(("bad", "checksum failure"))
        elif op == "tag_checksum":
            body = f"c:{BASE_MS + ms}"
            bad = draw(st.sampled_from([f"{i:02X}" for i in range(256) if f"{i:02X}" != xor(body)]))
            sentence = s[s.index("$"):]
            lines.append(f"\\{body}*{bad}\\{sentence}")
            what.append(("bad", "checksum failure"))
        elif op == "truncated":
            start = s.index("$") + 2
            lines.append(s[:draw(st.integers(start, len(s) - 1))])
            what.append(("bad", "truncated"))
        elif op == "garbage":
            g = draw(st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1,
                             max_size=60).filter(lambda x: x[0] not in "$!\\"))
            lines.append(g)
            what.append(("bad", "malformed"))
        elif op == "binary":
            lines.append(bytes(draw(st.lists(st.integers(128, 255), min_size=1, max_size=40))))
            what.append(("bad", "malformed"))
        elif op == "unsupported":
            address, text = draw(st.sampled_from(UNSUPPORTED))
            line = f"{text}*{xor(text[1:])}"
            if draw(st.booleans()):
                line = f"\\c:{BASE_MS + ms}*{xor(f'c:{BASE_MS + ms}')}\\" + line
            lines.append(line)
            what.append(("unsupported", address))
        elif op == "invalid":
            body = draw(st.sampled_from(INVALID)).format(tod=_tod(ms))
            lines.append(f"\\c:{BASE_MS + ms}*{xor(f'c:{BASE_MS + ms}')}\\${body}*{xor(body)}")
            what.append(("bad", "invalid fix"))
        else:
            lines.append("")
            what.append(("bad", "blank line"))
    return lines, what


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                   HealthCheck.function_scoped_fixture])
@given(fuzzed_log())
def test_fuzzed_logs_every_bad_line_named_no_good_line_lost(tmp_path, case):
    lines, what = case
    p = _write_lines(tmp_path, lines, "fuzz.nmea")
    log, rep = read_nmea(p, date="2024-06-01", epoch=BASE, max_listed=10_000)
    number = {i + 1: w for i, w in enumerate(what)}
    bad = {ln: w[1] for ln, w in number.items() if w[0] == "bad"}
    unsupported = {ln: w[1] for ln, w in number.items() if w[0] == "unsupported"}
    good = {ln: w for ln, w in number.items() if w[0] == "good"}

    assert rep.rows_read == len(lines)
    assert rep.rows_read == rep.rows_kept + rep.n_skipped + rep.duplicates
    assert rep.duplicates == 0 and rep.rows_kept == len(good)
    assert {b.line: b.reason for b in rep.bad} == bad
    assert len(rep.bad) == len(bad)
    assert rep.skipped_lines.tolist() == sorted(bad | unsupported)
    counts: dict[str, int] = {}
    for reason in bad.values():
        counts[reason] = counts.get(reason, 0) + 1
    if unsupported:
        counts["unsupported sentence"] = len(unsupported)
    assert dict(rep.skipped) == counts
    assert log.unsupported_lines.tolist() == sorted(unsupported)
    assert sum(log.unsupported.values()) == len(unsupported)
    assert log.out_of_order_lines.tolist() == sorted(ln for ln, w in good.items() if w[2])
    assert rep.out_of_order == len(log.out_of_order_lines)

    # every good line's values come back unchanged, at its time
    got = {}
    for name, t, vals, line in (
            ("pos", log.t_pos, (log.lat, log.lon), log.line_pos),
            ("vel", log.t_vel, (log.sog, log.cog), log.line_vel),
            ("heading", log.t_heading, (log.heading,), log.line_heading),
            ("rate", log.t_rate, (log.rate,), log.line_rate)):
        for k, ln in enumerate(line.tolist()):
            got[(name, ln)] = (t[k], tuple(v[k] for v in vals))
    expected = {(name, ln): (t, vals) for ln, w in good.items() for name, t, vals in w[1]}
    assert set(got) == set(expected)
    for key, (t, vals) in expected.items():
        gt, gv = got[key]
        assert abs(gt - t) < 1e-9, key
        assert np.allclose(gv, vals, rtol=1e-12, atol=1e-12), (key, gv, vals)


# -- the CSV form ------------------------------------------------------------------------------


def test_csv_form_round_trip(tmp_path):
    gps, ins = simulate_gnss(*turn_truth(duration=30), rng=np.random.default_rng(4),
                             gps=GpsModel(rate=1.0, offset=0.25))
    p = tmp_path / "nav.csv"
    rows = write_nav_csv(p, gps, ins, "2024-06-01T23:59:50")
    assert rows == len(np.union1d(np.round(gps.t, 3), np.round(ins.t, 3)))
    assert p.read_text().splitlines()[0] == "time,lat,lon,sog_kn,cog_deg,heading_deg,rot_deg_min"
    log, rep = read_nav_csv(p)
    assert rep.rows_read == rep.rows_kept == rows and rep.n_skipped == 0
    assert log.epoch == np.datetime64("2024-06-01T23:59:50", "ns")
    assert np.max(np.abs(log.lat - gps.lat)) <= 0.5e-8 + 1e-12
    assert np.max(np.abs(log.lon - gps.lon)) <= 0.5e-8 + 1e-12
    # the rest as printed in NMEA; times to 1 ms
    check_close(dataclasses.replace(log, lat=gps.lat, lon=gps.lon), gps, ins, gps_tol=0.0005)


def test_csv_form_bad_rows_are_named(tmp_path):
    p = tmp_path / "nav.csv"
    p.write_text("time,lat,lon,sog_kn,cog_deg,heading_deg,rot_deg_min\n"
                 "2024-06-01T12:00:00Z,30.4,49.1,10,90,91,2\n"       # 2 good
                 "2024-06-01T12:00:01Z,30.4,,10,90,,\n"              # 3 lat without lon
                 "2024-06-01T12:00:02Z,,,-1,90,,\n"                  # 4 negative speed
                 "2024-06-01T12:00:03Z,,,,90,,\n"                    # 5 course without speed
                 "2024-06-01T12:00:04Z,,,,,400,\n"                   # 6 heading range
                 "2024-06-01T12:00:05Z,,,,,,\n"                      # 7 no values (soft)
                 "yesterday,,,,,10,\n"                               # 8 bad time
                 "2024-06-01T11:59:59.5Z,,,,,12.5,\n"                # 9 out of order, kept
                 "2024-06-01T12:00:06Z,,,3,,,-4\n")                  # 10 speed, no course
    log, rep = read_nav_csv(p)
    got = {b.line: (b.column, b.reason) for b in rep.bad}
    assert got == {3: ("lat", "latitude without longitude"), 4: ("sog_kn", "negative speed"),
                   5: ("cog_deg", "course without speed"),
                   6: ("heading_deg", "heading outside [0, 360]"), 7: ("lat", "no values"),
                   8: ("time", "bad time")}
    assert rep.rows_kept == 3 and rep.out_of_order == 1 and log.out_of_order_lines.tolist() == [9]
    assert log.epoch == np.datetime64("2024-06-01T11:59:59.5", "ns")
    assert log.t_heading.tolist() == [0.0, 0.5] and log.line_heading.tolist() == [9, 2]
    assert np.isnan(log.cog[-1]) and dict(rep.not_given) == {"course": 1}
    with pytest.raises(ValueError, match=rf"{p}:3:lat: latitude without longitude"):
        read_nav_csv(p, on_bad="stop")


def test_csv_form_unknown_or_missing_columns(tmp_path):
    p = tmp_path / "nav.csv"
    p.write_text("time,lat,lon,heading_rad\n2024-06-01T12:00:00Z,30,49,1.0\n")
    with pytest.raises(ValueError, match=r"column 'heading_rad' is not known"):
        read_nav_csv(p)
    p.write_text("lat,lon\n30,49\n")
    with pytest.raises(ValueError, match=r"no column 'time'"):
        read_nav_csv(p)
    p.write_text("time,heading_deg\n0.5,10\n1.5,20\n")
    log, rep = read_nav_csv(p, time_format="seconds")
    assert log.epoch is None and log.t_heading.tolist() == [0.5, 1.5] and log.t_pos.size == 0
    with pytest.raises(ValueError, match="time_format = 'secs'"):
        read_nav_csv(p, time_format="secs")
