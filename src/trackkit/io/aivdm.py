"""AIS position reports from raw NMEA 0183 sentences (``!AIVDM``, ``!AIVDO``), decoded with
``pyais``.

    reports, report = read_aivdm("harbour.nmea")

A line holds one sentence, optionally with the time the receiver logged it: an NMEA 4.10 tag
block before it (``\\s:rx1,c:1704456000*hh\\!AIVDM,...``; ``c`` is unix seconds, or
milliseconds when it has more than ten digits), or a unix time or an ISO 8601 time before the
sentence or after its checksum (``1704456000.25 !AIVDM,...``, ``2024-01-05T12:00:00Z;!AIVDM,...``,
``!AIVDM,...*hh,1704456000``). A line with no time takes the time of the last timed line above
it in the file (receivers that time only some lines). A file with no receiver times is timed
by its base stations: the UTC date and time of the last type 4 (or 11) report above, put at
the message's own UTC second (the one nearest that time, within half a minute either way;
at the base station's time when the message gives no second). A message before any of these
has no time and is skipped ("no time").

Multi-part messages (types 5, 19, 24 in two sentences) are reassembled by their sequential
message id and channel; a part missing (a broken pair) makes the message skipped as
"incomplete multi-part message", counted once at its first line. Records are messages: a
multi-part message is one record, at the line of its first part, so ``report.rows_read`` counts
messages and bad lines, not lines.

Position reports are message types 1, 2, 3 (class A), 18, 19 (class B), 9 (SAR aircraft) and
27 (long range); their time, MMSI and position are required, course, speed and heading
optional, with the ITU-R M.1371 codes read as "not available" (as in
:func:`~trackkit.io.read_ais_csv`; type 27's speed 63 kn and course 511 deg, and type 9's speed
1023 kn, are its own codes for it). Other message types (static data, base stations, ...) are
skipped as "not a position report (type N)", never fatal. A sentence whose checksum fails, or
that cannot be split or decoded, is skipped as "checksum failure" or "malformed" (fatal with
``on_bad="stop"``).

The file is read line by line and decoded in chunks of :data:`CHUNK` messages, so memory holds
one chunk besides the output.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from trackkit.io import _reports
from trackkit.io._table import Accumulator, Progress
from trackkit.io.ais import AisColumns, fields_of, velocity
from trackkit.io.frames import KNOT
from trackkit.io.records import ReadReport, Reports

__all__ = ["CHUNK", "looks_like_aivdm", "read_aivdm"]

#: Messages decoded at a time (memory holds one chunk of messages).
CHUNK = 50_000  # messages decoded at a time
POSITION_TYPES = (1, 2, 3, 9, 18, 19, 27)
#: per message type, its own "not available" codes mapped to the class A ones
_OWN_CODES = {27: {"speed": (63.0, 102.3), "course": (511.0, 360.0)},
              9: {"speed": (1023.0, 102.3)}}
_SENTENCE = re.compile(r"[!$][A-Z]{2}VD[MO],")
_TAG = re.compile(r"\\([^\\]*)\\")
_UNIX = re.compile(r"^[0-9]{9,13}(\.[0-9]*)?$")
_ISO = re.compile(r"^[0-9]{4}-[0-9]{2}-[0-9]{2}[T ][0-9]{2}:[0-9]{2}:[0-9]{2}(\.[0-9]+)?Z?$")
_SEPARATORS = " \t,;|"
#: the fields as the validation sees them (role names are the "columns" named in messages)
_COLUMNS = AisColumns(time="time", id="mmsi", lat="lat", lon="lon", course="course",
                      speed="speed", heading="heading")
_SOFT = frozenset({"not a position report", "no time", "incomplete multi-part message",
                   "outside bounds"})


def looks_like_aivdm(lines: Sequence[str]) -> bool:
    """Whether the first lines of a file are AIS sentences (some of the first five)."""
    return any(_SENTENCE.search(ln) for ln in lines[:5])


def _checksum_ok(body: str, given: str) -> bool:
    x = 0
    for ch in body:
        x ^= ord(ch)
    return f"{x:02X}" == given.upper()


def _time_text(text: str) -> int | None:
    """A receiver time (unix seconds or milliseconds, or ISO 8601 UTC) as ns, else None."""
    text = text.strip(_SEPARATORS)
    if _UNIX.match(text):
        whole, _, frac = text.partition(".")
        if len(whole) > 10:  # milliseconds
            return int(whole) * 1_000_000 + int((frac + "000000")[:6] or 0)
        return int(whole) * 1_000_000_000 + int((frac + "000000000")[:9] or 0)
    if _ISO.match(text):
        return int(np.datetime64(text.rstrip("Z").replace(" ", "T"), "ns").astype(np.int64))
    return None


class _Line:
    """One line split: its sentence, its time (ns or None) and why it is bad (or "")."""

    __slots__ = ("sentence", "time", "error", "fields")

    def __init__(self, text: str):
        self.sentence, self.time, self.error, self.fields = "", None, "", []
        m = _SENTENCE.search(text)
        if m is None:
            self.error = "malformed"
            return
        prefix, rest = text[:m.start()], text[m.start():]
        tag = _TAG.search(prefix)
        if tag is not None:
            body, star, check = tag.group(1).rpartition("*")
            if star and not _checksum_ok(body, check):
                self.error = "checksum failure (tag block)"
                return
            for item in (body if star else tag.group(1)).split(","):
                key, _, value = item.partition(":")
                if key == "c" and value.isdigit():
                    self.time = int(value) * (1_000_000 if len(value) > 10 else 1_000_000_000)
            prefix = prefix[:tag.start()] + prefix[tag.end():]
        star = rest.find("*")
        if star < 0 or len(rest) < star + 3:
            self.error = "malformed"
            return
        self.sentence, suffix = rest[:star + 3], rest[star + 3:]
        if not _checksum_ok(rest[1:star], rest[star + 1:star + 3]):
            self.error = "checksum failure"
            return
        self.fields = rest[1:star].split(",")
        if len(self.fields) != 7 or not (self.fields[1].isdigit() and self.fields[2].isdigit()):
            self.error = "malformed"
            return
        for extra in (prefix, suffix):
            if self.time is None and extra.strip(_SEPARATORS):
                self.time = _time_text(extra)


class _Chunk:
    """The position reports of one chunk, as lists until :meth:`columns`."""

    def __init__(self) -> None:
        self.lines: list[int] = []
        self.values: dict[str, list] = {r: [] for r in ("time", "id", "lat", "lon", "course",
                                                        "speed", "heading")}

    def __len__(self) -> int:
        return len(self.lines)

    def add(self, line: int, time: int, msg) -> None:
        v = self.values
        own = _OWN_CODES.get(msg.msg_type, {})
        speed, course = getattr(msg, "speed", None), getattr(msg, "course", None)
        if "speed" in own and speed == own["speed"][0]:
            speed = own["speed"][1]
        if "course" in own and course == own["course"][0]:
            course = own["course"][1]
        self.lines.append(line)
        v["time"].append(time)
        v["id"].append(str(msg.mmsi))
        v["lat"].append(msg.lat)
        v["lon"].append(msg.lon)
        v["speed"].append(speed)
        v["course"].append(course)
        v["heading"].append(getattr(msg, "heading", None))

    def columns(self) -> dict[str, pa.Array]:
        v = self.values
        cols = {r: pa.array(v[r], pa.float64()) for r in ("lat", "lon", "course", "speed",
                                                           "heading")}
        cols["time"] = pa.array(v["time"], pa.timestamp("ns"))
        cols["id"] = pa.array(v["id"], pa.string())
        return cols


def _utc(msg) -> int | None:
    """A base station report's UTC time (ns), None when it gives none."""
    try:
        when = np.datetime64(f"{msg.year:04d}-{msg.month:02d}-{msg.day:02d}T{msg.hour:02d}:"
                             f"{msg.minute:02d}:{msg.second:02d}", "ns")
    except ValueError:
        return None
    ns = int(when.astype(np.int64))
    return ns if msg.year >= 1900 and msg.second < 60 else None


def _at_second(clock: int, second: int) -> int:
    """The time at UTC second ``second`` nearest ``clock`` (ns); ``clock`` for 60 and above
    (not available)."""
    if not 0 <= second < 60:
        return clock
    minute = 60_000_000_000
    t = clock - clock % minute + second * 1_000_000_000
    if t - clock > minute // 2:
        t -= minute
    elif clock - t > minute // 2:
        t += minute
    return t


def _decode(sentences: list[str]):
    """The message of a sentence or of the parts of a multi-part one, else the error."""
    import pyais
    from pyais.exceptions import AISBaseException

    try:
        return pyais.decode(*sentences), ""
    except (AISBaseException, ValueError, IndexError, KeyError, TypeError) as err:
        return None, str(err) or type(err).__name__


class _Reader:
    """The state of one read: the accumulator, the chunk, the parts awaiting the rest of
    their message and the last receiver time."""

    def __init__(self, acc: Accumulator):
        self.acc, self.chunk = acc, _Chunk()
        self.pending: dict[tuple[str, str], tuple[int, int | None, list[str], int]] = {}
        self.last_time: int | None = None
        self.clock: int | None = None  # the last base station's UTC time (ns)

    def incomplete(self, line: int, sentences: list[str], count: int) -> None:
        self.acc.bad_row(line, "*", "incomplete multi-part message", sentences[0],
                         f"{count} parts of one message, in order")

    def line(self, number: int, text: str) -> None:
        if not text.strip():
            self.acc.bad_row(number, "*", "blank line", "", "a record")
            return
        ln = _Line(text)
        if ln.error:
            self.acc.bad_row(number, "*", ln.error, text,
                             "an AIS sentence !AIVDM,n,k,id,channel,payload,fill*hh")
            return
        if ln.time is not None:
            self.last_time = ln.time
        f = ln.fields
        count, num, key = int(f[1]), int(f[2]), (f[3], f[4])
        t = ln.time if ln.time is not None else self.last_time
        if count == 1:
            self.message(number, t, [ln.sentence])
            return
        if num == 1:
            if key in self.pending:
                first, _, parts, n = self.pending.pop(key)
                self.incomplete(first, parts, n)
            self.pending[key] = (number, t, [ln.sentence], count)
            return
        p = self.pending.get(key)
        if p is None or p[3] != count or len(p[2]) + 1 != num:
            if p is not None:
                self.incomplete(p[0], p[2], p[3])
                del self.pending[key]
            self.incomplete(number, [ln.sentence], count)
            return
        p[2].append(ln.sentence)
        if len(p[2]) == count:
            del self.pending[key]
            self.message(p[0], p[1] if p[1] is not None else t, p[2])

    def message(self, number: int, t: int | None, sentences: list[str]) -> None:
        msg, error = _decode(sentences)
        if msg is not None and msg.msg_type in (4, 11):
            self.clock = _utc(msg) or self.clock
        if msg is not None and t is None and self.clock is not None:
            t = _at_second(self.clock, getattr(msg, "second", 60))
        if msg is None:
            self.acc.bad_row(number, "*", "malformed", " ".join(sentences),
                             f"a payload pyais decodes ({error})")
        elif msg.msg_type not in POSITION_TYPES:
            self.acc.bad_row(number, "*", f"not a position report (type {msg.msg_type})",
                             sentences[0], "message types " + ", ".join(map(str, POSITION_TYPES)))
        elif t is None:
            self.acc.bad_row(number, "*", "no time", sentences[0],
                             "a tag block c:, or a receiver time, on this line or above")
        else:
            self.chunk.add(number, t, msg)

    def flush(self, number: int) -> None:
        if len(self.chunk):
            self.acc.add(self.chunk.columns(), np.asarray(self.chunk.lines, dtype=np.int64))
            self.chunk = _Chunk()
        self.acc.flush(number)


def read_aivdm(path: str | os.PathLike, on_bad: str = "skip", *,
               reference: _reports.Reference = None, epoch=None,
               bounds: tuple[float, float, float, float] | None = None,
               progress: Progress | None = None, max_listed: int = 100
               ) -> tuple[Reports, ReadReport]:
    """Read AIS position reports from NMEA sentences (see the module docstring); the
    arguments are those of :func:`~trackkit.io.read_ais_csv`."""
    path = os.fspath(path)
    fields = fields_of(_COLUMNS)
    b = _reports.bounds_check(bounds)
    soft = _SOFT | {f"not a position report (type {t})" for t in range(64)}
    acc = Accumulator(path, fields, {f.role: k for k, f in enumerate(fields)}, on_bad,
                      frozenset(soft), max_listed,
                      None if b is None else _reports.outside_bounds(b), "line")
    reader = _Reader(acc)
    size, done, number = os.path.getsize(path), 0, 0
    with open(path, "rb") as fh:
        for number, raw in enumerate(fh, start=1):
            done += len(raw)
            try:
                text = raw.decode("utf-8").strip()
            except UnicodeDecodeError as err:
                acc.bad_row(number, "*", "not UTF-8 text", raw[:80].decode("latin-1"),
                            f"UTF-8 text, not byte 0x{raw[err.start]:02x}")
                continue
            reader.line(number, text)
            if len(reader.chunk) >= CHUNK:
                reader.flush(number)
                if progress is not None:
                    progress(done, size)
    for first, _, parts, n in sorted(reader.pending.values()):
        reader.incomplete(first, parts, n)
    reader.flush(number)
    if progress is not None:
        progress(size, size)
    table = acc.finish()
    c = table.columns
    vx, vy = velocity(c["speed"] * KNOT, np.deg2rad(c["course"]))
    return _reports.finish(table, time_format="iso", epoch=epoch, reference=reference,
                           alt=None, vel=(vx, vy, np.full(len(vx), np.nan)),
                           extra={"heading_deg": c["heading"]}, layout="nmea-ais")
