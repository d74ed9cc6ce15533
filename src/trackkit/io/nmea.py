"""GPS/INS logs as NMEA 0183 (writer, and reader with ``pynmea2``) and as one CSV layout.

    log, report = read_nmea("trial.nmea")        # GGA RMC VTG HDT THS ROT
    log.t_pos, log.lat, log.lon                  # s from report.epoch; degrees
    log.t_vel, log.sog, log.cog                  # m/s; rad clockwise from north
    log.t_heading, log.heading                   # rad clockwise from north
    log.t_rate, log.rate                         # rad/s, positive to starboard
    print(report.summary())

Each quantity keeps its own times: sentences come at different rates (GPS 1-2 Hz, INS
10 Hz). Units are converted once, here: knots to m/s, degrees to radians, ROT degrees per
minute to rad/s; latitude and longitude stay in degrees, the unit of
:class:`~trackkit.io.frames.EnuFrame`.

**Time.** GGA and RMC carry a UTC time of day (RMC also the date). HDT, THS, ROT and VTG carry
none: a line may start with an NMEA 0183 v4 TAG block ``\\c:<UNIX time>*hh\\`` (the time the
logger received it; ten or fewer integer digits are seconds, more are milliseconds, as AIS
loggers write it), else the sentence takes the time of the last GGA/RMC fix above it (exact
when the INS is sampled with the GPS, as :func:`write_nmea` does without TAG blocks; with a
faster INS, the later sentences of a fix interval repeat its time and are dropped as
duplicates, counted). A GGA time of day is put on the day that brings it nearest to a
reference: the line's TAG time, else the time of the line above, which handles the midnight
rollover; the first reference is the first date the file gives (RMC date or TAG time), else
``date=``, else the times are relative (``report.epoch`` is None). t = 0 is ``epoch`` if given,
else the first record (the first fix, in a log that starts with one).

**Every line is accounted for** (``report.rows_read == rows_kept + n_skipped +
duplicates``). Skipped, by reason: ``checksum failure`` (sentence or TAG block), ``truncated``
(a ``$`` line with no ``*hh`` at its end), ``malformed`` (not an NMEA line, or a field that is
not what the sentence type allows), ``invalid fix`` (GGA quality 0, 6 or 7; RMC status V or
mode N, E, M; VTG mode N, E, M or no speed; THS mode V or M; ROT status V; a blank heading or
rate), ``no time`` (an untimed sentence before any fix and without a TAG block),
``blank line``, and ``unsupported sentence`` (well-formed, checksum good, a type other than the
six: not an error, counted by type in ``log.unsupported`` and named in
``log.unsupported_lines``, not listed in ``report.bad``). With ``on_bad="stop"`` the first
checksum failure, truncated or malformed line raises a ValueError naming file, line and
reason; the others are never fatal. Kept lines whose time is earlier than an earlier line of
the same quantity are kept and sorted (``report.out_of_order``, lines in
``log.out_of_order_lines``). A quantity given twice at one time (GGA and RMC of one fix both
give the position) is taken from the first line; a line that adds nothing new is a duplicate.

Values are parsed strictly by this module (``pynmea2`` checks the checksum, splits the
sentence and names its fields; its own conversions return the raw text on error and read a
coordinate "0" as 0 deg, which is no validation). Coordinates must be ``ddmm.m...`` /
``dddmm.m...`` with a hemisphere letter; numbers are plain decimals (no exponent, nan or inf);
course and heading are in [0, 360] deg.

**Printed precision** of :func:`write_nmea`: time of day 0.01 s, TAG time 1 ms, latitude
and longitude 1e-5 minute (0.019 m, so within 9.3 mm), SOG 0.001 kn (within 0.26 mm/s),
COG and heading 0.01 deg (within 0.005 deg), ROT 0.01 deg/min (within 1.5e-6 rad/s).

**CSV form** (:func:`write_nav_csv`, :func:`read_nav_csv`): columns ``time, lat, lon,
sog_kn, cog_deg, heading_deg, rot_deg_min`` (``time`` required, the others optional; any
other column is an error, since a look-alike such as ``heading_rad`` would be read in the
wrong unit). One row per time; blank cells are quantities not sampled then. ``lat`` and
``lon`` go together, ``cog_deg`` needs ``sog_kn``; a row with nothing but a time is skipped as
``no values``. It reads into the same :class:`NavLog`.
"""

from __future__ import annotations

import datetime as _dt
import os
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
import pynmea2
from numpy.typing import NDArray

from trackkit.io._table import BLANK, TIME_FORMATS, Field, csv_header, parse_epoch, read_csv_table
from trackkit.io.frames import KNOT
from trackkit.io.records import BadRecord, ReadReport

if TYPE_CHECKING:
    from trackkit.io.records import GpsFixes, InsSamples

__all__ = [
    "NAV_CSV_COLUMNS",
    "SUPPORTED",
    "NavLog",
    "format_sentence",
    "nmea_lines",
    "read_nav_csv",
    "read_nmea",
    "write_nav_csv",
    "write_nmea",
]

Array = NDArray[np.float64]
Lines = NDArray[np.int64]

#: The sentence types read (others are counted as unsupported).
SUPPORTED = ("GGA", "RMC", "VTG", "HDT", "THS", "ROT")
GPS_SENTENCES = ("GGA", "RMC", "VTG")
INS_SENTENCES = ("HDT", "THS", "ROT")
#: The CSV form's columns, in order.
NAV_CSV_COLUMNS = ("time", "lat", "lon", "sog_kn", "cog_deg", "heading_deg", "rot_deg_min")

CHECKSUM = "checksum failure"
TRUNCATED = "truncated"
MALFORMED = "malformed"
UNSUPPORTED = "unsupported sentence"
INVALID = "invalid fix"
NO_TIME = "no time"
NO_VALUES = "no values"
#: Reasons that never stop a read, even with ``on_bad="stop"``: the line is well formed.
SOFT = frozenset({BLANK, UNSUPPORTED, INVALID, NO_TIME, NO_VALUES})

DAY_NS = 86_400 * 1_000_000_000
DEG = np.pi / 180.0
ROT_UNIT = DEG / 60.0  # deg/min to rad/s

if "THS" not in pynmea2.TalkerSentence.sentence_types:
    class THS(pynmea2.TalkerSentence):
        """True heading and status (IEC 61162-1 ed. 4); pynmea2 1.19 does not know it, and
        defining it registers it with pynmea2's parser."""

        fields = (("True heading", "headt", float), ("Mode indicator", "mi"))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class NavLog:
    """GPS/INS records of one log, each quantity with its own times (float s from
    ``epoch``, strictly increasing) and source lines (or CSV lines).

    * position: ``t_pos``, ``lat``, ``lon`` (WGS-84 degrees), ``line_pos``;
    * velocity over ground: ``t_vel``, ``sog`` (m/s), ``cog`` (rad clockwise from north in
      [0, 2 pi), nan where the sentence gave a speed but no course), ``line_vel``;
    * heading: ``t_heading``, ``heading`` (rad clockwise from north in [0, 2 pi)),
      ``line_heading``;
    * yaw rate: ``t_rate``, ``rate`` (rad/s, positive clockwise), ``line_rate``;
    * ``epoch``: the absolute time of t = 0 (None: relative times); ``source``: the file;
      ``out_of_order_lines``: kept lines that were earlier than a line above them;
      ``unsupported``: unsupported sentences by address (``GPGSV``), at
      ``unsupported_lines``.
    """

    t_pos: Array
    lat: Array
    lon: Array
    line_pos: Lines
    t_vel: Array
    sog: Array
    cog: Array
    line_vel: Lines
    t_heading: Array
    heading: Array
    line_heading: Lines
    t_rate: Array
    rate: Array
    line_rate: Lines
    epoch: np.datetime64 | None = None
    source: str = ""
    out_of_order_lines: Lines = field(default_factory=lambda: np.zeros(0, np.int64))
    unsupported: Mapping[str, int] = field(default_factory=dict)
    unsupported_lines: Lines = field(default_factory=lambda: np.zeros(0, np.int64))

    def __post_init__(self) -> None:
        groups = (("t_pos", "lat", "lon", "line_pos"), ("t_vel", "sog", "cog", "line_vel"),
                  ("t_heading", "heading", "line_heading"), ("t_rate", "rate", "line_rate"))
        for names in groups:
            n = np.shape(getattr(self, names[0]))
            for name in names:
                kind = np.int64 if name.startswith("line") else float
                a = np.asarray(getattr(self, name), dtype=kind)
                if a.shape != n or a.ndim != 1:
                    raise ValueError(f"NavLog.{name} has shape {a.shape}; expected {n}, the "
                                     f"shape of {names[0]}")
                object.__setattr__(self, name, _readonly(a))
            t = getattr(self, names[0])
            if t.size > 1 and not np.all(np.diff(t) > 0):
                raise ValueError(f"NavLog.{names[0]} is not strictly increasing; expected one "
                                 "sample per time, sorted")
        for name in ("out_of_order_lines", "unsupported_lines"):
            object.__setattr__(self, name, _readonly(np.asarray(getattr(self, name),
                                                                dtype=np.int64)))
        object.__setattr__(self, "unsupported", MappingProxyType(dict(self.unsupported)))

    def __repr__(self) -> str:
        return (f"NavLog({len(self.t_pos)} positions, {len(self.t_vel)} velocities, "
                f"{len(self.t_heading)} headings, {len(self.t_rate)} rates from "
                f"{self.source!r})")

    def absolute_time(self, t: Array) -> NDArray[np.datetime64]:
        """Times ``t`` (s from the epoch) as ``datetime64[ns]`` UTC; needs an epoch."""
        if self.epoch is None:
            raise ValueError(f"{self.source}: the times are relative (no epoch)")
        return self.epoch.astype("datetime64[ns]") + np.round(
            np.asarray(t, dtype=float) * 1e9).astype("timedelta64[ns]")


# -- writing ---------------------------------------------------------------------------------------

_ADDRESS = re.compile(r"^[A-Z]{2}[A-Z]{3}$")


def _checksum(body: str) -> int:
    return int(pynmea2.NMEASentence.checksum(body))


def format_sentence(address: str, fields: Sequence[str], tag_time_ms: int | None = None) -> str:
    """``$<address>,<fields>*hh`` with its checksum (XOR of the characters between ``$`` and
    ``*``), optionally after a TAG block ``\\c:<tag_time_ms>*hh\\``. No line ending."""
    if not _ADDRESS.match(address):
        raise ValueError(f"address = {address!r}; expected a talker and a sentence type such "
                         "as 'GPGGA'")
    for f in fields:
        if any(c in f for c in ",*$!\\\r\n"):
            raise ValueError(f"field {f!r} holds a reserved character; expected plain text")
    body = address + "," + ",".join(fields)
    out = f"${body}*{_checksum(body):02X}"
    if tag_time_ms is not None:
        tag = f"c:{int(tag_time_ms)}"
        out = f"\\{tag}*{_checksum(tag):02X}\\" + out
    return out


def epoch_ns(epoch) -> int | None:
    if epoch is None:
        return None
    if isinstance(epoch, _dt.datetime) and epoch.tzinfo is not None:
        epoch = epoch.astimezone(_dt.UTC).replace(tzinfo=None)
    ep = parse_epoch(epoch)
    return None if ep is None else int(ep.astype("datetime64[ns]").astype(np.int64))


def _start_ns(start) -> int:
    """A start time (ISO text, datetime, datetime64, unix seconds) as int ns since 1970 UTC."""
    ns = epoch_ns(start)
    if ns is None:
        raise ValueError("start = None; expected the absolute UTC time of t = 0")
    return ns


def _dm(value: float, deg_digits: int, hemispheres: str) -> tuple[str, str]:
    """Degrees to ``(d)ddmm.mmmmm`` (1e-5 minute, rounded in integers so 59.999995 minutes
    carries into the degrees) and the hemisphere letter."""
    units = int(round(abs(value) * 6_000_000))
    d, m = divmod(units, 6_000_000)
    hemi = hemispheres[1] if value < 0 and units else hemispheres[0]
    return f"{d:0{deg_digits}d}{m // 100_000:02d}.{m % 100_000:05d}", hemi


def _angle(deg: float) -> str:
    """An angle in [0, 360) to 0.01 deg, ``ddd.dd``."""
    q = int(round(deg * 100)) % 36_000
    return f"{q // 100:03d}.{q % 100:02d}"


def _signed(x: float, digits: int) -> str:
    q = int(round(x * 10**digits))
    return f"{'-' if q < 0 else ''}{abs(q) // 10**digits}.{abs(q) % 10**digits:0{digits}d}"


def _tod_date(ns: int) -> tuple[str, str]:
    cs = (ns + 5_000_000) // 10_000_000  # rounded to 0.01 s; the date follows the rounding
    day, c = divmod(cs, 8_640_000)
    hh, c = divmod(c, 360_000)
    mm, c = divmod(c, 6_000)
    ss, c = divmod(c, 100)
    date = np.datetime64(int(day), "D").astype(object)
    return f"{hh:02d}{mm:02d}{ss:02d}.{c:02d}", date.strftime("%d%m%y")


def _check_record(name: str, rec, fields: Sequence[str]) -> int:
    t = np.asarray(rec.t, dtype=float)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"{name}.t: expected a 1-D array of finite times")
    for f in fields:
        a = np.asarray(getattr(rec, f), dtype=float)
        if a.shape != t.shape:
            raise ValueError(f"{name}.{f} has shape {a.shape}; expected {t.shape} (one run: "
                             "select it with trackkit.io.records.one_run)")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}.{f} holds non-finite values; expected finite values")
    return t.shape[0]


def nmea_lines(gps: GpsFixes | None, ins: InsSamples | None, start, *,
               sentences: Sequence[str] = ("GGA", "RMC", "HDT", "ROT"),
               gps_talker: str = "GP", ins_talker: str = "HE", tag_blocks: bool = True
               ) -> list[str]:
    """The NMEA lines (no line endings) of one run's GPS fixes and INS samples, in time order
    (GPS first at equal times). ``start`` is the UTC time of t = 0. Each fix gives the GPS
    sentences among ``sentences`` (GGA: quality 1, 8 satellites, HDOP 1.0, altitude 0 m,
    which are not simulated; RMC: status A, mode A; VTG), each INS sample the INS ones (HDT
    or THS, mode A; ROT, status A). ``tag_blocks`` puts the time on every line (see the
    module)."""
    bad = [s for s in sentences if s not in SUPPORTED]
    if bad or not sentences:
        raise ValueError(f"sentences = {tuple(sentences)!r}; expected some of {SUPPORTED}")
    for name, talker in (("gps_talker", gps_talker), ("ins_talker", ins_talker)):
        if not re.match(r"^[A-Z]{2}$", talker):
            raise ValueError(f"{name} = {talker!r}; expected two capital letters ('GP', 'HE')")
    t0 = _start_ns(start)
    events: list[tuple[int, int, int]] = []
    gs = [s for s in sentences if s in GPS_SENTENCES]
    ins_s = [s for s in sentences if s in INS_SENTENCES]
    if gps is not None and gs:
        n = _check_record("gps", gps, ("lat", "lon", "sog", "cog"))
        if np.any(np.abs(gps.lat) > 90) or np.any(np.abs(gps.lon) > 180):
            raise ValueError("gps.lat/lon outside [-90, 90] / [-180, 180] deg")
        events += [(t0 + int(round(float(gps.t[k]) * 1e9)), 0, k) for k in range(n)]
    if ins is not None and ins_s:
        n = _check_record("ins", ins, ("heading", "rate"))
        events += [(t0 + int(round(float(ins.t[k]) * 1e9)), 1, k) for k in range(n)]
    if any(ns < 0 for ns, _, _ in events):
        raise ValueError("start + t is before 1970; expected UTC times after 1970-01-01")
    events.sort()
    out = []
    for ns, src, k in events:
        tag = (ns + 500_000) // 1_000_000 if tag_blocks else None
        if src == 0:
            assert gps is not None
            tod, date = _tod_date(ns)
            lat, ns_ = _dm(float(gps.lat[k]), 2, "NS")
            lon, ew = _dm(float(gps.lon[k]), 3, "EW")
            kn = float(gps.sog[k]) / KNOT
            cog = _angle(np.rad2deg(float(gps.cog[k])))
            for s in gs:
                if s == "GGA":
                    f = [tod, lat, ns_, lon, ew, "1", "08", "1.0", "0.0", "M", "0.0", "M", "",
                         ""]
                elif s == "RMC":
                    f = [tod, "A", lat, ns_, lon, ew, f"{kn:.3f}", cog, date, "", "", "A"]
                else:
                    f = [cog, "T", "", "M", f"{kn:.3f}", "N", f"{kn * 1.852:.3f}", "K", "A"]
                out.append(format_sentence(gps_talker + s, f, tag))
        else:
            assert ins is not None
            for s in ins_s:
                if s == "HDT":
                    f = [_angle(np.rad2deg(float(ins.heading[k]))), "T"]
                elif s == "THS":
                    f = [_angle(np.rad2deg(float(ins.heading[k]))), "A"]
                else:
                    f = [_signed(float(ins.rate[k]) / ROT_UNIT, 2), "A"]
                out.append(format_sentence(ins_talker + s, f, tag))
    return out


def write_nmea(path: str | os.PathLike, gps: GpsFixes | None, ins: InsSamples | None, start,
               **options) -> int:
    """Write :func:`nmea_lines` to ``path`` (ASCII, CR LF line ends, as NMEA 0183 ends
    sentences); returns the number of lines."""
    lines = nmea_lines(gps, ins, start, **options)
    with open(path, "w", encoding="ascii", newline="") as fh:
        fh.writelines(s + "\r\n" for s in lines)
    return len(lines)


# -- reading: one line -------------------------------------------------------------------------


class _Bad(Exception):
    def __init__(self, reason: str, column: str, value: str, expected: str):
        super().__init__(reason)
        self.reason, self.column, self.value, self.expected = reason, column, value, expected


class _Unsupported(Exception):
    def __init__(self, address: str):
        super().__init__(address)
        self.address = address


@dataclass
class _Rec:
    line: int
    kind: str
    tod: int | None = None  # ns since midnight
    day: int | None = None  # days since 1970-01-01
    tag: int | None = None  # ns since 1970
    pos: tuple[float, float] | None = None
    vel: tuple[float, float] | None = None
    heading: float | None = None
    rate: float | None = None
    not_given: tuple[str, ...] = ()


_TAG = re.compile(r"^\\(?P<body>[^\\*]*)\*(?P<cs>[0-9A-Fa-f]{2})\\(?P<rest>.*)$")
_SENTENCE = re.compile(r"^(?P<start>[$!])(?P<body>[^*$!\\]*)\*(?P<cs>[0-9A-Fa-f]{2})$")
_ENDS_WITH_CS = re.compile(r"\*[0-9A-Fa-f]{2}$")
_TIME = re.compile(r"^(\d{2})(\d{2})(\d{2})(?:\.(\d{1,9}))?$")
_LAT = re.compile(r"^(\d{2})(\d{2}(?:\.\d+)?)$")
_LON = re.compile(r"^(\d{3})(\d{2}(?:\.\d+)?)$")
_UNSIGNED = re.compile(r"^(\d+(\.\d*)?|\.\d+)$")
_SIGNED = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)$")
_TAG_TIME = re.compile(r"^(\d{1,16})(?:\.(\d{1,9}))?$")


def _field(data: list[str], i: int) -> str:
    return data[i].strip() if i < len(data) else ""


def _need(kind: str, data: list[str], n: int) -> None:
    if len(data) < n:
        raise _Bad(MALFORMED, f"{kind} fields", str(len(data)), f"at least {n} fields")


def _time(kind: str, s: str) -> int:
    m = _TIME.match(s)
    if not m or int(m[1]) > 23 or int(m[2]) > 59 or int(m[3]) > 59:
        raise _Bad(MALFORMED, f"{kind} time", s, "a UTC time hhmmss.ss")
    frac = int((m[4] or "0").ljust(9, "0"))  # digits, not a float: no rounding
    return ((int(m[1]) * 60 + int(m[2])) * 60 + int(m[3])) * 1_000_000_000 + frac


def _date(kind: str, s: str) -> int:
    try:
        d = _dt.datetime.strptime(s, "%d%m%y").date() if re.match(r"^\d{6}$", s) else None
    except ValueError:
        d = None
    if d is None:
        raise _Bad(MALFORMED, f"{kind} date", s, "a date ddmmyy")
    return (d - _dt.date(1970, 1, 1)).days


def _coord(kind: str, what: str, s: str, hemi: str, pattern: re.Pattern, letters: str,
           limit: float) -> float:
    m = pattern.match(s)
    if not m or float(m[2]) >= 60.0:
        form = "ddmm.mmmm" if letters == "NS" else "dddmm.mmmm"
        raise _Bad(MALFORMED, f"{kind} {what}", s, f"{form} with minutes below 60")
    if hemi not in letters:
        raise _Bad(MALFORMED, f"{kind} {what} hemisphere", hemi, f"{letters[0]} or {letters[1]}")
    v = int(m[1]) + float(m[2]) / 60.0
    if v > limit:
        raise _Bad(MALFORMED, f"{kind} {what}", s, f"at most {limit:g} deg")
    return -v if hemi == letters[1] else v


def _number(kind: str, what: str, s: str, signed: bool = False, hi: float | None = None
            ) -> float:
    if not (_SIGNED if signed else _UNSIGNED).match(s):
        raise _Bad(MALFORMED, f"{kind} {what}", s,
                   "a signed decimal" if signed else "a non-negative decimal")
    v = float(s)
    if hi is not None and v > hi:
        raise _Bad(MALFORMED, f"{kind} {what}", s, f"a value in [0, {hi:g}]")
    return v


def _position(kind: str, data: list[str], i: int) -> tuple[float, float]:
    return (_coord(kind, "latitude", _field(data, i), _field(data, i + 1), _LAT, "NS", 90.0),
            _coord(kind, "longitude", _field(data, i + 2), _field(data, i + 3), _LON, "EW",
                   180.0))


def _tag_time(body: str) -> int | None:
    t = None
    for p in body.split(","):
        key, _, val = p.partition(":")
        if key == "c":
            m = _TAG_TIME.match(val)
            if not m:
                raise _Bad(MALFORMED, "TAG block c", val, "UNIX time in s or ms")
            # more than ten integer digits is milliseconds (ten cover seconds to 2286)
            unit = 1_000_000 if len(m[1]) > 10 else 1_000_000_000
            frac = m[2] or ""
            t = int(m[1]) * unit + int(frac.ljust(9, "0")) * unit // 1_000_000_000
    return t


def _parse(text: str, number: int) -> _Rec:
    """One line to a record, or :class:`_Bad` / :class:`_Unsupported`."""
    tag = None
    whole = text[:80]
    if text.startswith("\\"):
        m = _TAG.match(text)
        if not m:
            raise _Bad(MALFORMED, "TAG block", whole, "\\<key>:<value>,...*hh\\ before the $")
        if int(m["cs"], 16) != _checksum(m["body"]):
            raise _Bad(CHECKSUM, "TAG block checksum", m["cs"].upper(),
                       f"{_checksum(m['body']):02X}")
        tag = _tag_time(m["body"])
        text = m["rest"]
    if not text.startswith(("$", "!")):
        raise _Bad(MALFORMED, "*", whole, "an NMEA sentence $ttsss,...*hh")
    m = _SENTENCE.match(text)
    if not m:
        if _ENDS_WITH_CS.search(text):
            raise _Bad(MALFORMED, "*", whole, "one sentence, $ttsss,...*hh")
        raise _Bad(TRUNCATED, "*", whole, "a sentence ending in *hh")
    if int(m["cs"], 16) != _checksum(m["body"]):
        raise _Bad(CHECKSUM, "checksum", m["cs"].upper(), f"{_checksum(m['body']):02X}")
    address = m["body"].partition(",")[0]
    if m["start"] == "!":  # encapsulated (AIS VDM/VDO): not navigation data
        raise _Unsupported(address)
    try:
        msg = pynmea2.parse(text, check=True)
    except pynmea2.SentenceTypeError:
        raise _Unsupported(address) from None
    except (pynmea2.ParseError, ValueError):
        raise _Bad(MALFORMED, "*", whole, "an NMEA sentence $ttsss,...*hh") from None
    kind = getattr(msg, "sentence_type", "")
    if not isinstance(msg, pynmea2.TalkerSentence) or kind not in SUPPORTED:
        raise _Unsupported(address)
    d = [x.strip() for x in msg.data]
    rec = _Rec(number, kind, tag=tag)
    if kind == "GGA":
        _need(kind, d, 6)
        q = _field(d, 5)
        if not q.isdigit():
            raise _Bad(MALFORMED, "GGA quality", q, "a fix quality 0-8")
        if int(q) in (0, 6, 7):
            raise _Bad(INVALID, "GGA quality", q, "a measured fix (quality 1-5 or 8)")
        rec.tod = _time(kind, d[0])
        rec.pos = _position(kind, d, 1)
    elif kind == "RMC":
        _need(kind, d, 9)
        if d[1] not in ("A", "V"):
            raise _Bad(MALFORMED, "RMC status", d[1], "A or V")
        mode = _field(d, 11)
        if d[1] == "V" or mode in ("N", "E", "M"):
            raise _Bad(INVALID, "RMC status" if d[1] == "V" else "RMC mode",
                       d[1] if d[1] == "V" else mode, "a valid fix (status A, mode not N/E/M)")
        rec.tod = _time(kind, d[0])
        rec.day = _date(kind, d[8])
        rec.pos = _position(kind, d, 2)
        if d[6]:
            cog = _number(kind, "course", d[7], hi=360.0) if d[7] else np.nan
            rec.vel = (_number(kind, "speed", d[6]) * KNOT, np.mod(cog * DEG, 2 * np.pi))
            rec.not_given = () if d[7] else ("course",)
        else:
            rec.not_given = ("speed",)
    elif kind == "VTG":
        _need(kind, d, 8)
        if _field(d, 8) in ("N", "E", "M"):
            raise _Bad(INVALID, "VTG mode", d[8], "a valid fix (mode not N/E/M)")
        if d[4]:
            sog = _number(kind, "speed", d[4]) * KNOT
        elif d[6]:
            sog = _number(kind, "speed km/h", d[6]) * (1000.0 / 3600.0)
        else:
            raise _Bad(INVALID, "VTG speed", "", "a speed over ground")
        cog = _number(kind, "course", d[0], hi=360.0) if d[0] else np.nan
        rec.vel = (sog, np.mod(cog * DEG, 2 * np.pi))
        rec.not_given = () if d[0] else ("course",)
    elif kind in ("HDT", "THS"):
        _need(kind, d, 2)
        if kind == "THS" and d[1] not in ("A", "E", "M", "S", "V"):
            raise _Bad(MALFORMED, "THS mode", d[1], "A, E, M, S or V")
        if (kind == "THS" and d[1] in ("V", "M")) or not d[0]:
            raise _Bad(INVALID, f"{kind} heading" if not d[0] else "THS mode",
                       d[0] if not d[0] else d[1], "a valid heading (THS mode A, E or S)")
        rec.heading = float(np.mod(_number(kind, "heading", d[0], hi=360.0) * DEG, 2 * np.pi))
    else:  # ROT
        _need(kind, d, 2)
        if d[1] not in ("A", "V"):
            raise _Bad(MALFORMED, "ROT status", d[1], "A or V")
        if d[1] == "V" or not d[0]:
            raise _Bad(INVALID, "ROT status" if d[1] == "V" else "ROT rate",
                       d[1] if d[1] == "V" else "", "a valid rate (status A)")
        rec.rate = _number(kind, "rate", d[0], signed=True) * ROT_UNIT
    return rec


# -- reading: the log --------------------------------------------------------------------------


def _check_on_bad(on_bad: str) -> None:
    if on_bad not in ("skip", "stop"):
        raise ValueError(f"on_bad = {on_bad!r}; expected 'skip' or 'stop'")


def _nearest_day(tod: int, ref: int) -> int:
    """The time ``tod`` (ns of day) on the day that brings it nearest to ``ref``."""
    base = (ref // DAY_NS) * DAY_NS + tod
    return min((base - DAY_NS, base, base + DAY_NS), key=lambda x: abs(x - ref))


class _Log:
    """What a read collects before assembly: per good line its time (int ns) and values."""

    def __init__(self, path: str, on_bad: str, max_listed: int, soft: frozenset[str]):
        self.path, self.on_bad, self.max_listed, self.soft = path, on_bad, max_listed, soft
        self.rows = 0
        self.skipped: Counter = Counter()
        self.skipped_lines: list[int] = []
        self.bad: list[BadRecord] = []
        self.not_given: Counter = Counter()
        self.unsupported: Counter = Counter()
        self.unsupported_lines: list[int] = []

    def skip(self, line: int, reason: str, column: str, value: str, expected: str,
             listed: bool = True) -> None:
        self.skipped[reason] += 1
        self.skipped_lines.append(line)
        rec = BadRecord(self.path, line, column, reason, value, expected)
        if self.on_bad == "stop" and reason not in self.soft:
            raise ValueError(f"{rec} [on_bad='stop'; pass on_bad='skip' to skip bad records]")
        if listed and len(self.bad) < self.max_listed:
            self.bad.append(rec)


def _assemble(acc: _Log, lines: Lines, times: NDArray[np.int64], pos: Array, vel: Array,
              heading: Array, rate: Array, not_given: list[tuple[str, ...]],
              epoch_ns: int | None, absolute: bool) -> tuple[NavLog, ReadReport]:
    """Sort, de-duplicate and account for the good lines (file order): ``times`` int ns,
    ``pos`` (n, 2), ``vel`` (n, 2), ``heading`` (n,), ``rate`` (n,) with nan where a line does
    not give the quantity (a velocity's course may be nan: its speed decides). t = 0 at
    ``epoch_ns``, else at the earliest kept record; ``absolute`` says whether that is a UTC
    time (else the epoch is None)."""
    n = len(lines)
    streams = {"pos": ~np.isnan(pos[:, 0]), "vel": ~np.isnan(vel[:, 0]),
               "heading": ~np.isnan(heading), "rate": ~np.isnan(rate)}
    low = np.iinfo(np.int64).min
    ooo = np.zeros(n, dtype=bool)
    used = np.zeros(n, dtype=bool)
    sel = {}
    for name, m in streams.items():
        if n == 0:
            sel[name] = np.zeros(0, np.int64)
            continue
        # the latest time of this quantity on the lines above each line
        above = np.concatenate([[low], np.maximum.accumulate(np.where(m, times, low))[:-1]])
        ooo |= m & (times < above)
        idx = np.flatnonzero(m)
        o = idx[np.lexsort((lines[idx], times[idx]))]
        first = np.ones(len(o), dtype=bool)
        first[1:] = times[o][1:] != times[o][:-1]  # one value per time: the first line's
        sel[name] = o[first]
        used[o[first]] = True
    if epoch_ns is None:
        epoch_ns = int(times[used].min()) if used.any() else 0
    epoch = np.datetime64(epoch_ns, "ns") if absolute else None
    for k in np.flatnonzero(used):
        for what in not_given[k]:
            acc.not_given[what] += 1

    def secs(i: Lines) -> Array:
        return (times[i] - epoch_ns) / 1e9

    p, v, h, r = sel["pos"], sel["vel"], sel["heading"], sel["rate"]
    log = NavLog(
        t_pos=secs(p), lat=pos[p, 0], lon=pos[p, 1], line_pos=lines[p],
        t_vel=secs(v), sog=vel[v, 0], cog=vel[v, 1], line_vel=lines[v],
        t_heading=secs(h), heading=heading[h], line_heading=lines[h],
        t_rate=secs(r), rate=rate[r], line_rate=lines[r], epoch=epoch, source=acc.path,
        out_of_order_lines=lines[ooo & used], unsupported=dict(acc.unsupported),
        unsupported_lines=np.asarray(acc.unsupported_lines, dtype=np.int64))
    acc.bad.sort(key=lambda b: b.line)
    report = ReadReport(
        path=acc.path, rows_read=acc.rows, rows_kept=int(used.sum()), skipped=dict(acc.skipped),
        bad=tuple(acc.bad), skipped_lines=np.sort(np.asarray(acc.skipped_lines, dtype=np.int64)),
        out_of_order=int((ooo & used).sum()), duplicates=int(n - used.sum()),
        not_given=dict(acc.not_given), epoch=epoch)
    return log, report


def read_nmea(path: str | os.PathLike, on_bad: str = "skip", *, date=None, epoch=None,
              max_listed: int = 100) -> tuple[NavLog, ReadReport]:
    """Read GGA, RMC, VTG, HDT, THS and ROT sentences from an NMEA 0183 log (see the module
    for times, validation and accounting). ``date`` (a ``datetime.date`` or ISO text) dates a
    log that gives none (GGA only, no TAG blocks); ``epoch`` is the absolute time of t = 0
    (default the first record). ``on_bad`` is ``"skip"`` or ``"stop"``."""
    _check_on_bad(on_bad)
    path = os.fspath(path)
    acc = _Log(path, on_bad, max_listed, SOFT)
    recs: list[_Rec] = []
    with open(path, "rb") as fh:
        for number, raw in enumerate(fh, start=1):
            acc.rows += 1
            text = raw.decode("ascii", errors="replace").strip()
            if not text:
                acc.skip(number, BLANK, "*", "", "a sentence")
                continue
            try:
                recs.append(_parse(text, number))
            except _Bad as b:
                acc.skip(number, b.reason, b.column, b.value, b.expected)
            except _Unsupported as u:
                acc.skip(number, UNSUPPORTED, "address", u.address, "", listed=False)
                acc.unsupported[u.address] += 1
                acc.unsupported_lines.append(number)

    # the first reference for a time of day: the file's first absolute time, else the date
    ref0 = next(((r.day * DAY_NS + r.tod) if r.day is not None and r.tod is not None else r.tag
                 for r in recs if r.day is not None or r.tag is not None), None)
    relative = False
    if ref0 is None:
        if date is not None:
            d = date if isinstance(date, _dt.date) else _dt.date.fromisoformat(str(date))
            ref0 = (d - _dt.date(1970, 1, 1)).days * DAY_NS + DAY_NS // 2
        else:
            relative, ref0 = True, DAY_NS // 2
    ep_ns = epoch_ns(epoch)
    if relative and ep_ns is not None:
        raise ValueError(f"{path}: epoch given but the log has no date (no RMC, no TAG "
                         "block time); pass date= to date it")
    good: list[_Rec] = []
    times: list[int] = []
    last = last_fix = None
    for r in recs:
        if r.day is not None and r.tod is not None:
            t = r.day * DAY_NS + r.tod
        elif r.tod is not None:
            t = _nearest_day(r.tod, r.tag if r.tag is not None else
                             (last if last is not None else ref0))
        elif r.tag is not None:
            t = r.tag
        elif last_fix is not None:
            t = last_fix
        else:
            acc.skip(r.line, NO_TIME, f"{r.kind} time", "",
                     "a GGA/RMC fix above it or a TAG block time")
            continue
        if r.kind in ("GGA", "RMC"):
            last_fix = t
        last = t
        good.append(r)
        times.append(t)
    n = len(good)
    nan2 = (np.nan, np.nan)
    pos = np.array([r.pos or nan2 for r in good], dtype=float).reshape(n, 2)
    vel = np.array([r.vel or nan2 for r in good], dtype=float).reshape(n, 2)
    hdg = np.array([np.nan if r.heading is None else r.heading for r in good], dtype=float)
    rot = np.array([np.nan if r.rate is None else r.rate for r in good], dtype=float)
    lines = np.array([r.line for r in good], dtype=np.int64)
    t_ns = np.array(times, dtype=np.int64)
    return _assemble(acc, lines, t_ns, pos, vel, hdg, rot, [r.not_given for r in good], ep_ns,
                     not relative)


# -- the CSV form ------------------------------------------------------------------------------


def write_nav_csv(path: str | os.PathLike, gps: GpsFixes | None, ins: InsSamples | None,
                  start) -> int:
    """One run's GPS and INS as the CSV form: one row per time (the union of the fix and INS
    times, ISO 8601 UTC to 1 ms), blanks where a quantity is not sampled; latitude and
    longitude to 1e-8 deg, the rest as printed in NMEA. Returns the number of data rows."""
    t0 = _start_ns(start)
    rows: dict[int, list[str]] = {}

    def row(t: float) -> list[str]:
        ms = (t0 + int(round(t * 1e9)) + 500_000) // 1_000_000
        return rows.setdefault(ms, [""] * len(NAV_CSV_COLUMNS))

    if gps is not None:
        n = _check_record("gps", gps, ("lat", "lon", "sog", "cog"))
        for k in range(n):
            r = row(float(gps.t[k]))
            r[1], r[2] = f"{float(gps.lat[k]):.8f}", f"{float(gps.lon[k]):.8f}"
            r[3] = f"{float(gps.sog[k]) / KNOT:.3f}"
            r[4] = _angle(np.rad2deg(float(gps.cog[k])))
    if ins is not None:
        n = _check_record("ins", ins, ("heading", "rate"))
        for k in range(n):
            r = row(float(ins.t[k]))
            r[5] = _angle(np.rad2deg(float(ins.heading[k])))
            r[6] = _signed(float(ins.rate[k]) / ROT_UNIT, 2)
    with open(path, "w", encoding="ascii", newline="") as fh:
        fh.write(",".join(NAV_CSV_COLUMNS) + "\n")
        for ms in sorted(rows):
            r = rows[ms]
            r[0] = str(np.datetime64(ms, "ms")) + "Z"
            fh.write(",".join(r) + "\n")
    return len(rows)


def read_nav_csv(path: str | os.PathLike, on_bad: str = "skip", *, time_format: str = "iso",
                 epoch=None, max_listed: int = 100) -> tuple[NavLog, ReadReport]:
    """Read the CSV form (see the module) into a :class:`NavLog`. ``time_format`` is one of
    ``"iso"``, ``"unix"``, ``"unix_ms"``, ``"seconds"`` (relative: kept as given) or a
    strptime pattern; ``epoch`` as in :func:`read_nmea`; bad rows as in the other readers."""
    _check_on_bad(on_bad)
    if time_format not in TIME_FORMATS and "%" not in time_format:
        raise ValueError(f"time_format = {time_format!r}; expected one of "
                         f"{', '.join(map(repr, TIME_FORMATS))} or a strptime pattern")
    path = os.fspath(path)
    header = csv_header(path)
    unknown = [h for h in header if h not in NAV_CSV_COLUMNS]
    if unknown:
        raise ValueError(f"{path}:1: column {', '.join(map(repr, unknown))} is not known; "
                         f"expected columns among {', '.join(NAV_CSV_COLUMNS)}")
    spec = {
        "time": Field("time", "time", "time", time_format=time_format),
        "lat": Field("lat", "lat", required=False, lo=-90.0, hi=90.0, what="latitude"),
        "lon": Field("lon", "lon", required=False, lo=-180.0, hi=180.0, what="longitude"),
        "sog_kn": Field("sog", "sog_kn", required=False, lo=0.0, what="speed"),
        "cog_deg": Field("cog", "cog_deg", required=False, lo=0.0, hi=360.0, what="course"),
        "heading_deg": Field("heading", "heading_deg", required=False, lo=0.0, hi=360.0,
                             what="heading"),
        "rot_deg_min": Field("rot", "rot_deg_min", required=False, what="rate of turn"),
    }
    fields = [spec["time"]] + [spec[c] for c in header if c != "time"]

    def pairs(v: dict) -> list:
        nan = np.full(len(v["time"]), np.nan)
        lat, lon = v.get("lat", nan), v.get("lon", nan)
        sog, cog = v.get("sog", nan), v.get("cog", nan)
        given = [~np.isnan(v.get(k, nan)) for k in ("lat", "lon", "sog", "cog", "heading",
                                                     "rot")]
        role = "lat" if "lat" in v else ("lon" if "lon" in v else "time")
        return [
            (np.isnan(lon) & ~np.isnan(lat), "lat", "latitude without longitude",
             "lat and lon together"),
            (np.isnan(lat) & ~np.isnan(lon), "lon", "longitude without latitude",
             "lat and lon together"),
            (np.isnan(sog) & ~np.isnan(cog), "cog" if "cog" in v else "time",
             "course without speed", "cog_deg with sog_kn"),
            (~np.any(given, axis=0), role, NO_VALUES, "a value besides the time"),
        ]

    table = read_csv_table(path, fields, "stop" if on_bad == "stop" else "skip",
                           soft=frozenset({NO_VALUES}), max_listed=max_listed, row_check=pairs)
    c = table.columns
    n = len(table.lines)
    nan = np.full(n, np.nan)
    if time_format == "seconds":
        t_ns = np.round(c["time"] * 1e9).astype(np.int64)
    else:
        t_ns = np.asarray(c["time"], dtype=np.int64)
    lat, lon = c.get("lat", nan), c.get("lon", nan)
    sog = c.get("sog", nan) * KNOT
    cog = np.mod(c.get("cog", nan) * DEG, 2 * np.pi)
    acc = _Log(path, on_bad, max_listed, SOFT)
    acc.rows = table.rows_read
    acc.skipped = Counter(table.skipped)
    acc.skipped_lines = list(table.skipped_lines)
    acc.bad = list(table.bad)
    ep_ns = epoch_ns(epoch)
    if time_format == "seconds":
        if ep_ns is not None:
            raise ValueError(f"{path}: epoch given but time_format 'seconds' is relative")
        ep_ns = 0  # relative seconds are kept as given
    # blank cells are the layout (quantities not sampled then), not missing data; only a speed
    # without its course is counted as "not given", as in the NMEA reader
    ng = [("course",) if s_ == s_ and c_ != c_ else () for s_, c_ in zip(sog, cog, strict=True)]
    return _assemble(acc, table.lines, t_ns, np.stack([lat, lon], -1), np.stack([sog, cog], -1),
                     np.mod(c.get("heading", nan) * DEG, 2 * np.pi),
                     c.get("rot", nan) * ROT_UNIT, ng, ep_ns, time_format != "seconds")
