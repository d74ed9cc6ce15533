"""The engine under the readers: stream a table in blocks, validate each column with array
operations, and account for every record.

A reader describes what it wants as a list of :class:`Field` (which column, what kind of value,
whether it may be blank, its valid range). :func:`read_csv_table` and
:func:`read_parquet_table` stream the file (pyarrow, a few MB at a time, every column read as
text from CSV so that one bad value cannot fail the whole parse), convert every field of a
block at once, and build per-record messages only for the bad records. A record with several
bad fields is counted once, under its first bad field in the file's column order.

CSV files are UTF-8: a byte that is not UTF-8 makes its record bad (reason "not UTF-8 text",
the byte named), like any other bad value; only a header that is not UTF-8 rejects the file.
Finite values beyond physical limits (:data:`MAX_DISTANCE`, :data:`MAX_SPEED`,
:data:`ALTITUDE`, :data:`MAX_SECONDS`, :data:`TIME_SPAN`) are bad records too.

CSV line numbers are physical lines (the header is line 1) as long as no quoted value holds a
line break; Parquet records are numbered by row from 1.
"""

from __future__ import annotations

import codecs
import csv
import dataclasses
import os
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from trackkit.io.records import BadRecord

__all__ = ["Field", "Table", "read_csv_table", "read_parquet_table", "parse_epoch"]

Progress = Callable[[int, int], None]
RowCheck = Callable[[dict], list]
Prepare = Callable[[dict], dict]

# What pyarrow's string-to-double cast accepts (checked against it in the tests), so that the
# cast of the matching strings cannot fail; everything else is "not a number".
_NUMBER = r"^[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?$|^[+-]?(?i:nan|inf|infinity)$"
_INTEGER = r"^\+?[0-9]+$"
_ISO = (r"^(?P<dt>[0-9]{4}-[0-9]{2}-[0-9]{2}[T ][0-9]{2}:[0-9]{2}:[0-9]{2})"
        r"(?P<frac>\.[0-9]{1,9})?(?P<tz>Z|[+-][0-9]{2}:?[0-9]{2})?$")
_TRUE = ("true", "t", "1", "yes")
_FALSE = ("false", "f", "0", "no")

#: Time formats besides strptime patterns (any format holding ``%``).
TIME_FORMATS = {
    "iso": "an ISO 8601 time such as 2016-01-12 13:02:11.218 (UTC unless an offset is given)",
    "unix": "seconds since 1970-01-01 UTC",
    "unix_ms": "milliseconds since 1970-01-01 UTC",
    "seconds": "seconds (relative)",
}
BAD_FIELDS = "wrong number of fields"
BLANK = "blank line"  # skipped and counted, but never fatal
NOT_UTF8 = "not UTF-8 text"
NAT = np.iinfo(np.int64).min  # numpy's NaT: a time not given
BLOCK_SIZE = 1 << 22  # bytes of CSV parsed at a time: memory is a few blocks, not the file

# Physical limits: a finite value beyond them is a corrupt record, not a measurement (and
# would overflow the tracker's squares into inf).
#: m: the largest |x|, |y|, |z| or range of a detection, 100 000 km (beyond geostationary
#: orbit, 42 164 km from the earth's centre; a quarter of the way to the moon)
MAX_DISTANCE = 1e8
#: m/s: the largest speed or vertical rate, Mach 3 (faster than any vessel or aircraft that
#: reports AIS or ADS-B)
MAX_SPEED = 1000.0
#: m: altitudes from below the lowest shore (the Dead Sea, -430 m) to the edge of space
ALTITUDE = (-1e3, 1e5)
#: s: the largest |time| relative to an epoch (about 317 years)
MAX_SECONDS = 1e10
#: absolute times: from 1900 to 2200 UTC; outside, a clock error, not a recording
TIME_SPAN = (np.datetime64("1900-01-01", "ns").astype(np.int64),
             np.datetime64("2200-01-01", "ns").astype(np.int64))


@dataclass(frozen=True)
class Field:
    """One column to read: ``role`` names it in the output, ``column`` in the file.

    ``kind`` is ``"number"``, ``"time"``, ``"text"``, ``"int"`` or ``"bool"``. A blank value
    of a ``required`` field makes the record bad (reason ``missing``, which is soft, i.e.
    skipped even with ``on_bad="stop"``, when ``missing_soft``); of an optional field it is
    "not given": nan (numbers), False (bool), counted in ``not_given``. ``unavailable`` is a
    code, or a tuple of codes, that the source uses for "not available" (AIS COG 360): an
    optional field's is read as not given; a required field's makes the record skipped, softly
    (reason ``"<unavailable_reason> (<what> <code>)"``). ``lo, hi`` bound valid numbers
    (inclusive); ``limit`` bounds their magnitude (in the file's units; ``limit_why`` says what
    it is in words), a physical limit such as :data:`MAX_DISTANCE`. With ``bad_is_missing`` an
    optional number that is not a number, not finite, out of range or beyond the limit is set
    missing (the record kept), counted by field and reason, instead of making the record bad.
    """

    role: str
    column: str
    kind: str = "number"
    required: bool = True
    lo: float | None = None
    hi: float | None = None
    what: str = ""
    unavailable: float | None = None
    time_format: str = "iso"
    missing: str = "missing value"
    missing_soft: bool = False
    limit: float | None = None
    limit_why: str = ""
    bad_is_missing: bool = False
    unavailable_reason: str = "not available"

    @property
    def label(self) -> str:
        return self.what or self.role

    @property
    def codes(self) -> tuple[float, ...]:
        """The "not available" codes."""
        u = self.unavailable
        return () if u is None else tuple(u) if isinstance(u, tuple) else (u,)

    def unavailable_text(self, code: float) -> str:
        return f"{self.unavailable_reason} ({self.label} {code:g})"

    def range_text(self) -> str:
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        return f"[{lo}, {hi}]"


@dataclass
class Table:
    """What a read produced: the kept records' values by role (numpy arrays; text fields as
    pyarrow string arrays) and lines, and the account of the rest."""

    path: str
    columns: dict
    lines: np.ndarray
    rows_read: int
    skipped: Counter
    bad: list
    skipped_lines: np.ndarray
    not_given: Counter
    set_missing: dict = dataclasses.field(default_factory=dict)  # {label: Counter(reason)}


# -- value conversion -------------------------------------------------------------------------


def _blank(arr: pa.Array) -> np.ndarray:
    if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        m = pc.or_kleene(pc.is_null(arr), pc.equal(arr, ""))
    else:
        m = pc.is_null(arr)
    return np.asarray(m.fill_null(True).to_numpy(zero_copy_only=False), dtype=bool)


def _is_text(arr: pa.Array) -> bool:
    return pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type)


def _numbers(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """(values as float64 with nan where not a number, mask of non-numbers among non-blank)."""
    if _is_text(arr):
        ok = np.asarray(pc.match_substring_regex(arr, _NUMBER).fill_null(False)
                        .to_numpy(zero_copy_only=False), dtype=bool)
        masked = pc.if_else(pa.array(ok), arr, pa.scalar(None, arr.type))
        vals = pc.cast(masked, pa.float64())
    elif pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type) or \
            pa.types.is_decimal(arr.type):
        ok = ~_blank(arr)
        vals = pc.cast(arr, pa.float64())
    else:
        return np.full(len(arr), np.nan), np.ones(len(arr), dtype=bool)
    v = np.asarray(vals.fill_null(np.nan).to_numpy(zero_copy_only=False), dtype=float)
    return v, ~ok


def _times(arr: pa.Array, fmt: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, mask of bad values among non-blank). Absolute formats give int64 ns since
    1970 UTC, numeric ones float64 seconds (since 1970 for unix, relative for seconds)."""
    if fmt == "seconds":
        v, bad = _numbers(arr)
        return v, bad | ~np.isfinite(v)
    if fmt in ("unix", "unix_ms"):
        v, bad = _numbers(arr)
        digits = 9 if fmt == "unix" else 6
        bad = bad | ~(np.abs(v) < 9e18 / 10**digits)  # int64 ns holds years 1678 to 2262
        ns = np.round(np.where(bad, 0.0, v) * 10**digits).astype(np.int64)
        if _is_text(arr):
            # plain decimals exactly, digit by digit: a float64 of unix seconds keeps only
            # about 0.2 microseconds
            parts = pc.extract_regex(arr, r"^(?P<i>[+-]?[0-9]{1,13})(?:\.(?P<f>[0-9]*))?$")
            ok = np.asarray(pc.is_valid(parts).to_numpy(zero_copy_only=False), dtype=bool)
            ok &= ~bad
            if ok.any():
                i = pc.cast(pc.if_else(pa.array(ok), parts.field("i"), "0"), pa.int64())
                f = pc.utf8_slice_codeunits(parts.field("f").fill_null(""), 0, digits)
                f = pc.utf8_rpad(pc.if_else(pa.array(ok), f, ""), digits, "0")
                i = np.asarray(i.to_numpy(zero_copy_only=False), dtype=np.int64)
                f = np.asarray(pc.cast(f, pa.int64()).to_numpy(zero_copy_only=False),
                               dtype=np.int64)
                neg = np.asarray(pc.starts_with(parts.field("i").fill_null(""), "-")
                                 .to_numpy(zero_copy_only=False), dtype=bool)
                exact = np.where(neg, i * 10**digits - f, i * 10**digits + f)
                ns = np.where(ok, exact, ns)
        return ns, bad
    if pa.types.is_timestamp(arr.type) or pa.types.is_date(arr.type):
        ts = pc.cast(arr, pa.timestamp("ns", tz=getattr(arr.type, "tz", None)))
        v = ts.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False)
        return np.asarray(v, dtype=np.int64), np.zeros(len(arr), dtype=bool)
    if not _is_text(arr):
        return np.zeros(len(arr), dtype=np.int64), np.ones(len(arr), dtype=bool)
    if fmt == "iso":
        parts = pc.extract_regex(arr, _ISO)
        dt = pc.replace_substring(parts.field("dt"), " ", "T")
        ts = pc.strptime(dt, "%Y-%m-%dT%H:%M:%S", "ns", error_is_null=True)
        ns = np.asarray(ts.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False),
                        dtype=np.int64)
        bad = np.asarray(pc.is_null(ts).to_numpy(zero_copy_only=False), dtype=bool)
        frac = parts.field("frac").fill_null("")
        if pc.any(pc.not_equal(frac, "")).as_py():
            # ".218" -> 218000000 ns, padded to nine digits so no float rounding enters
            digits = pc.utf8_rpad(pc.utf8_slice_codeunits(frac, 1), 9, "0")
            digits = pc.if_else(pc.equal(digits, "000000000"), "0", digits)
            ns = ns + np.asarray(pc.cast(pc.if_else(pc.equal(frac, ""), "0", digits),
                                         pa.int64()).to_numpy(zero_copy_only=False))
        tz = parts.field("tz").fill_null("")
        if pc.any(pc.and_(pc.not_equal(tz, ""), pc.not_equal(tz, "Z"))).as_py():
            t = np.asarray(tz.to_numpy(zero_copy_only=False), dtype=object)
            off = np.array([_offset_ns(s) for s in t], dtype=np.int64)
            ns = ns - off
        return ns, bad
    ts = pc.strptime(arr, fmt, "ns", error_is_null=True)
    ns = np.asarray(ts.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False),
                    dtype=np.int64)
    return ns, np.asarray(pc.is_null(ts).to_numpy(zero_copy_only=False), dtype=bool)


def _far_time(v: np.ndarray, fmt: str) -> np.ndarray:
    """Times beyond :data:`MAX_SECONDS` (relative) or outside :data:`TIME_SPAN`."""
    if fmt == "seconds":
        return np.abs(v) > MAX_SECONDS
    return (v < TIME_SPAN[0]) | (v >= TIME_SPAN[1])


def _offset_ns(tz: str) -> int:
    if tz in ("", "Z"):
        return 0
    sign = -1 if tz[0] == "-" else 1
    hh, mm = int(tz[1:3]), int(tz[-2:])
    return sign * (hh * 3600 + mm * 60) * 1_000_000_000


def _ints(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    if _is_text(arr):
        ok = np.asarray(pc.match_substring_regex(arr, _INTEGER).fill_null(False)
                        .to_numpy(zero_copy_only=False), dtype=bool)
        # digits beyond int64 would overflow the cast: treat as bad
        ok &= np.asarray(pc.less_equal(pc.utf8_length(arr), 18).fill_null(False)
                         .to_numpy(zero_copy_only=False), dtype=bool)
        masked = pc.if_else(pa.array(ok), arr, pa.scalar(None, arr.type))
        v = np.asarray(pc.cast(masked, pa.int64()).fill_null(0).to_numpy(zero_copy_only=False),
                       dtype=np.int64)
        return v, ~ok
    f, bad = _numbers(arr)
    bad = bad | ~np.isfinite(f) | (np.round(f) != f) | (f < 0) | (np.abs(f) > 2.0**62)
    return np.where(bad, 0, f).astype(np.int64), bad


def _bools(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    if pa.types.is_boolean(arr.type):
        return np.asarray(arr.fill_null(False).to_numpy(zero_copy_only=False), dtype=bool), \
            np.zeros(len(arr), dtype=bool)
    if not _is_text(arr):
        f, bad = _numbers(arr)
        return f == 1, bad | ~np.isin(f, (0.0, 1.0))
    low = pc.utf8_lower(arr)
    t = np.asarray(pc.is_in(low, pa.array(_TRUE)).to_numpy(zero_copy_only=False), dtype=bool)
    f = np.asarray(pc.is_in(low, pa.array(_FALSE)).to_numpy(zero_copy_only=False), dtype=bool)
    return t, ~(t | f)


# A byte that is not UTF-8 becomes the code point _MARK + byte (the last private-use code
# points of plane 16, never in real data) as the file is read: the parser then sees valid
# text, and the bad byte is one bad value of one record, found and shown as \xNN.
_MARK = 0x10FF00
_MARKED = r"[\x{10FF80}-\x{10FFFF}]"
_SHOW = {_MARK + b: f"\\x{b:02x}" for b in range(0x80, 0x100)}
READ_SIZE = 1 << 20  # bytes of the file decoded at a time


def _mark(err: UnicodeDecodeError) -> tuple[str, int]:
    return "".join(chr(_MARK + b) for b in err.object[err.start:err.end]), err.end


codecs.register_error("trackkit-mark-bytes", _mark)


def shown(text: str) -> str:
    """A value as read, its marked bad bytes written back as ``\\xNN``."""
    return text.translate(_SHOW)


class _MarkedUtf8:
    """A CSV file as UTF-8 bytes for the parser, every byte that is not UTF-8 marked;
    ``tell()`` is the position in the file (for the progress), ``marked`` whether any byte
    so far was bad."""

    def __init__(self, raw) -> None:
        self.raw, self.buf, self.marked, self.closed = raw, b"", False, False
        self.decoder = codecs.getincrementaldecoder("utf-8")("trackkit-mark-bytes")

    def read(self, n: int = -1) -> bytes:
        while n < 0 or len(self.buf) < n:
            chunk = self.raw.read(READ_SIZE)
            text = self.decoder.decode(chunk, final=not chunk)
            if text and not self.marked and max(text) >= chr(_MARK + 0x80):
                self.marked = True
            self.buf += text.encode("utf-8")
            if not chunk:
                break
        out, self.buf = (self.buf, b"") if n < 0 else (self.buf[:n], self.buf[n:])
        return out

    def tell(self) -> int:
        return self.raw.tell()

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False

    def close(self) -> None:
        self.closed = True


def _undecodable(arr: pa.Array) -> list:
    """``(rows, reason, expected)`` entries for the values of a text column holding marked
    bytes, one per first bad byte."""
    m = np.asarray(pc.match_substring_regex(arr, _MARKED).fill_null(False)
                   .to_numpy(zero_copy_only=False), dtype=bool)
    if not m.any():
        return []
    rows = np.flatnonzero(m)
    by_byte: dict[int, list[int]] = {}
    for i, v in zip(rows, arr.take(pa.array(rows)).to_pylist(), strict=True):
        first = next(ord(c) - _MARK for c in v if ord(c) >= _MARK + 0x80)
        by_byte.setdefault(first, []).append(int(i))
    return [(np.asarray(r), NOT_UTF8, f"UTF-8 text, not byte 0x{b:02x}")
            for b, r in sorted(by_byte.items())]


def convert(field: Field, raw: pa.Array):
    """Convert one column of a block. Returns ``(values, entries, missing)`` where
    entries is a list of ``(row indices, reason, expected)`` for the bad values and
    missing a list of ``(mask, reason)`` for the optional values set missing (blank, "not
    available", or bad with ``bad_is_missing``)."""
    arr = pc.utf8_trim_whitespace(raw) if _is_text(raw) else raw
    blank = _blank(arr)
    entries = []
    if field.required and blank.any():
        entries.append((np.flatnonzero(blank), field.missing, f"a {field.label}"))
    kind = field.kind
    missing = [] if field.required else [(blank, "blank")]
    if kind == "text":
        return arr, entries, missing
    if kind == "number":
        return _convert_number(field, arr, blank, entries, missing)
    if kind == "time":
        v, bad = _times(arr, field.time_format)
        bad &= ~blank
        far = _far_time(v, field.time_format) & ~blank & ~bad
        # blank (or bad) times are NaT for absolute times, nan for relative ones
        v = np.where(blank | bad | far, NAT if v.dtype == np.int64 else np.nan, v)
        expected = TIME_FORMATS.get(field.time_format, f"a time like {field.time_format!r}")
        entries.append((np.flatnonzero(bad), "bad time", expected))
        entries.append((np.flatnonzero(far), "time out of range", (
            f"|time| at most {MAX_SECONDS:g} s" if field.time_format == "seconds" else
            "a time from 1900 to 2200 UTC")))
        return v, entries, missing
    if kind == "int":
        v, bad = _ints(arr)
        bad &= ~blank
        entries.append((np.flatnonzero(bad), f"bad {field.label}",
                        f"a non-negative integer {field.label}"))
        return v, entries, missing
    if kind == "bool":
        v, bad = _bools(arr)
        bad &= ~blank
        entries.append((np.flatnonzero(bad), "not a boolean", "True or False"))
        return v & ~blank, entries, missing
    raise ValueError(f"Field {field.role!r}: kind {kind!r} is not known")


def _convert_number(field: Field, arr: pa.Array, blank: np.ndarray, entries: list,
                    missing: list):
    """The number branch of :func:`convert`: each check gives a mask of the values it
    rejects, which makes the record bad, or (optional, ``bad_is_missing``) the value missing."""
    v, nan_ = _numbers(arr)
    soft = field.bad_is_missing and not field.required

    def reject(mask: np.ndarray, reason: str, expected: str) -> None:
        if soft:
            missing.append((mask, reason))
        else:
            entries.append((np.flatnonzero(mask), reason, expected))

    notnum = nan_ & ~blank
    reject(notnum, "not a number", f"a decimal {field.label}")
    nonfin = ~blank & ~notnum & ~np.isfinite(v)
    reject(nonfin, "not finite", f"a finite {field.label}")
    given = ~blank & ~notnum & ~nonfin
    for code in field.codes:
        # codes are written with at most a few decimals, so compare as written
        unavail = given & (np.abs(v - code) <= 1e-9 * max(1.0, abs(code)))
        given &= ~unavail
        if field.required:
            entries.append((np.flatnonzero(unavail), field.unavailable_text(code),
                            f"a {field.label} ({code:g} means not available)"))
        else:
            missing.append((unavail, f"not available ({code:g})"))
    if field.lo is not None or field.hi is not None:
        lo = -np.inf if field.lo is None else field.lo
        hi = np.inf if field.hi is None else field.hi
        out = given & ((v < lo) | (v > hi))
        if soft:  # else the record is bad and its value stays, for the row checks
            given &= ~out
        negative = lo == 0 and hi == np.inf
        if soft:
            reject(out, "negative" if negative else f"outside {field.range_text()}", "")
        else:
            reject(out, f"negative {field.label}" if negative
                   else f"{field.label} outside {field.range_text()}",
                   f"a {field.label} in {field.range_text()}")
    if field.limit is not None:
        big = given & (np.abs(v) > field.limit)
        if soft:
            given &= ~big
        reject(big, f"magnitude above {field.limit:g}" if soft else
               f"|{field.label}| above {field.limit:g}",
               f"|{field.label}| at most {field.limit:g} ({field.limit_why})")
    return np.where(given, v, np.nan), entries, missing


# -- the accumulator --------------------------------------------------------------------------


class Accumulator:
    def __init__(self, path: str, fields: Sequence[Field], order: dict[str, int], on_bad: str,
                 soft: frozenset[str], max_listed: int, row_check: RowCheck | None,
                 unit: str):
        if on_bad not in ("skip", "stop"):
            raise ValueError(f"on_bad = {on_bad!r}; expected 'skip' or 'stop'")
        self.path, self.fields, self.order, self.on_bad = path, fields, order, on_bad
        # a required field's "not available" code is the source saying so, not an error
        soft = soft | {f.unavailable_text(c) for f in fields if f.required for c in f.codes}
        self.soft, self.max_listed, self.row_check, self.unit = soft, max_listed, row_check, unit
        self.values: dict[str, list] = {f.role: [] for f in fields}
        self.lines: list[np.ndarray] = []
        self.rows = 0
        self.skipped: Counter = Counter()
        self.not_given: Counter = Counter()
        self.set_missing: dict[str, Counter] = {}
        self.bad: list[BadRecord] = []
        self.bad_lines: list[np.ndarray] = []
        self.whole_rows: list[BadRecord] = []  # wrong field counts, from the CSV parser

    def _record(self, rec: BadRecord) -> None:
        if self.on_bad == "stop" and rec.reason not in self.soft | {BLANK}:
            raise ValueError(f"{rec} [on_bad='stop'; pass on_bad='skip' to skip bad records]")
        if len(self.bad) < self.max_listed:
            self.bad.append(rec)

    def add(self, cols: dict[str, pa.Array], lines: np.ndarray,
            undecodable: dict[str, list] | None = None) -> None:
        """One block: ``cols`` by role, each record's line, and per role the entries of
        values that were not UTF-8 (:func:`_undecodable`)."""
        n = len(lines)
        self.rows += n
        values, idx, col, reason, expected, ngs = {}, [], [], [], [], {}
        all_blank = np.ones(n, dtype=bool)
        for f in self.fields:
            raw = cols[f.role]
            all_blank &= _blank(pc.utf8_trim_whitespace(raw) if _is_text(raw) else raw)
        if all_blank.any():  # a blank line: not data, but counted like any skipped record
            idx.append(np.flatnonzero(all_blank))
            col.append(np.full(int(all_blank.sum()), -1))
            reason.extend([BLANK] * int(all_blank.sum()))
            expected.extend(["a record"] * int(all_blank.sum()))
        for f in self.fields:
            v, entries, ngs[f.label] = convert(f, cols[f.role])
            # first, so that a value with a bad byte is named for that, not as a bad number
            entries = (undecodable or {}).get(f.role, []) + entries
            values[f.role] = v
            for i, r, e in entries:
                if len(i):
                    idx.append(i)
                    col.append(np.full(len(i), self.order[f.role]))
                    reason.extend([r] * len(i))
                    expected.extend([e] * len(i))
        if self.row_check is not None:
            for mask, role, r, e in self.row_check(values):
                i = np.flatnonzero(mask)
                if len(i):
                    idx.append(i)
                    col.append(np.full(len(i), self.order[role] + 0.5))
                    reason.extend([r] * len(i))
                    expected.extend([e] * len(i))
        # parser-level bad rows at or before this block's last line go first, in line order
        last = int(lines[-1]) if n else -1
        pending = [r for r in self.whole_rows if r.line <= last] if n else []
        self.whole_rows = [r for r in self.whole_rows if r.line > last] if n else \
            self.whole_rows
        keep = np.ones(n, dtype=bool)
        recs: list[BadRecord] = list(pending)
        if idx:
            idx_a = np.concatenate(idx)
            col_a = np.concatenate(col)
            o = np.lexsort((col_a, idx_a))
            first = np.ones(len(o), dtype=bool)
            first[1:] = idx_a[o][1:] != idx_a[o][:-1]
            sel = o[first]  # one entry per bad row, its first bad column
            rows = idx_a[sel]
            keep[rows] = False
            reasons = np.asarray(reason, dtype=object)[sel]
            self.skipped.update(reasons.tolist())
            self.bad_lines.append(lines[rows])
            # messages only for the rows that may be listed, and the first fatal one
            need = self.max_listed - len(self.bad)
            names = {self.order[f.role]: f for f in self.fields}
            exp = np.asarray(expected, dtype=object)
            for k in range(len(rows)):
                fatal = self.on_bad == "stop" and reasons[k] not in self.soft | {BLANK}
                if k >= need and not fatal:
                    if self.on_bad == "skip":
                        break
                    continue
                f = names.get(int(col_a[sel[k]]))
                v = "" if f is None else cols[f.role][int(rows[k])].as_py()
                recs.append(BadRecord(self.path, int(lines[rows[k]]),
                                      "*" if f is None else f.column, reasons[k],
                                      "" if v is None else shown(str(v)), exp[sel[k]],
                                      self.unit))
                if fatal:
                    break
        for r in sorted(recs, key=lambda r: r.line):
            self._record(r)
        for label, missing in ngs.items():
            self._count_missing(label, missing, keep)
        for f in self.fields:
            v = values[f.role]
            self.values[f.role].append(v.filter(pa.array(keep)) if isinstance(v, pa.Array)
                                       else v[keep])
        self.lines.append(lines[keep])

    def _count_missing(self, label: str, missing: list, keep: np.ndarray) -> None:
        """Count the kept records' values set missing, by field (``not_given``) and by field
        and reason (``set_missing``)."""
        if not missing:
            return
        any_ = np.zeros(len(keep), dtype=bool)
        for mask, reason in missing:
            if (k := int((mask & keep).sum())):
                self.set_missing.setdefault(label, Counter())[reason] += k
            any_ |= mask
        if (k := int((any_ & keep).sum())):
            self.not_given[label] += k

    def bad_row(self, line: int, column: str, reason: str, value: str, expected: str) -> None:
        """A record skipped before its fields were read (a line that is not a sentence, a
        message with no position): counted and listed in line order with the others."""
        self.rows += 1
        self.skipped[reason] += 1
        self.bad_lines.append(np.array([line], dtype=np.int64))
        self.whole_rows.append(BadRecord(self.path, line, column, reason, shown(value[:200]),
                                         expected, self.unit))

    def flush(self, last: int) -> None:
        """Record the queued rows up to line ``last`` (a reader that calls :meth:`bad_row`
        for lines with no record in :meth:`add` after them)."""
        for r in [r for r in self.whole_rows if r.line <= last]:
            self._record(r)
        self.whole_rows = [r for r in self.whole_rows if r.line > last]

    def whole_row(self, line: int, expected: int, actual: int, text: str) -> None:
        """A record the CSV parser could not split into the header's fields."""
        self.rows += 1
        self.skipped[BAD_FIELDS] += 1
        self.bad_lines.append(np.array([line], dtype=np.int64))
        self.whole_rows.append(BadRecord(self.path, line, "*", BAD_FIELDS, shown(text[:200]),
                                         f"{expected} fields, got {actual}", self.unit))

    def finish(self) -> Table:
        for r in self.whole_rows:
            self._record(r)
        self.whole_rows = []
        cols = {}
        for f in self.fields:
            # each column's blocks are let go as it is joined: the peak is one column twice
            parts = self.values.pop(f.role)
            if f.kind == "text":
                cols[f.role] = pa.concat_arrays([p.cast(pa.string()) for p in parts]) if parts \
                    else pa.array([], pa.string())
            else:
                cols[f.role] = np.concatenate(parts) if parts else np.zeros(0)
        lines = np.concatenate(self.lines) if self.lines else np.zeros(0, np.int64)
        self.lines = []
        bl = np.sort(np.concatenate(self.bad_lines)) if self.bad_lines else np.zeros(0, np.int64)
        self.bad.sort(key=lambda r: r.line)
        return Table(self.path, cols, lines.astype(np.int64), self.rows, self.skipped,
                     self.bad[: self.max_listed], bl.astype(np.int64), self.not_given,
                     self.set_missing)


# -- readers ----------------------------------------------------------------------------------


def csv_header(path: str) -> list[str]:
    # the first line only: a bad byte further down is a bad record, not a bad header
    with open(path, "rb") as fh:
        first = fh.readline()
    try:
        text = first.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ValueError(f"{path}:1: the header is not UTF-8 text (byte "
                         f"0x{first[err.start]:02x} at byte {err.start + 1} of the line); "
                         "expected the column names, saved as UTF-8") from None
    header = next(csv.reader([text]), None)
    if not header:
        raise ValueError(f"{path}:1: no header line; expected the column names")
    return [h.strip() for h in header]


def _check_columns(path: str, have: Sequence[str], fields: Sequence[Field], where: str) -> None:
    missing = [f.column for f in fields if f.column not in have]
    if missing:
        raise ValueError(f"{path}{where}: no column {', '.join(map(repr, missing))}; the "
                         f"file has {', '.join(map(repr, have))} (pass a column mapping)")


def read_csv_table(path: str | os.PathLike, fields: Sequence[Field], on_bad: str = "skip",
                   progress: Progress | None = None, soft: frozenset[str] = frozenset(),
                   max_listed: int = 100, row_check: RowCheck | None = None,
                   block_size: int | None = None, *, names: Sequence[str] | None = None,
                   prepare: Prepare | None = None,
                   row_reason: Callable[[str], tuple[str, str] | None] | None = None
                   ) -> Table:
    """Stream a CSV file through the fields, ``block_size`` bytes at a time (default
    :data:`BLOCK_SIZE`); see the module docstring. A file with no header gives its column
    ``names`` (line 1 is then the first record). ``prepare(columns)`` may derive the fields'
    columns of each block from the file's (by role; e.g. a time from a date and a time
    column). ``row_reason(text)`` may name a record that has the wrong number of fields
    ``(reason, expected)`` (a line of another kind, skipped under that reason)."""
    import pyarrow.csv as pacsv

    path = os.fspath(path)
    header = list(names) if names is not None else csv_header(path)
    _check_columns(path, header, fields, ":1" if names is None else "")
    order = {f.role: header.index(f.column) for f in fields}
    acc = Accumulator(path, fields, order, on_bad, soft, max_listed, row_check, "line")

    rejected: list[int] = []  # lines the parser rejected (it may do so before a block is read)
    first = 1 if names is not None else 2

    def invalid(row) -> str:
        # row.number is the physical line (the header, if any, is line 1), blank lines included
        line = int(row.number)
        rejected.append(line)
        other = row_reason(row.text) if row_reason is not None else None
        if other is not None:
            acc.bad_row(line, "*", other[0], row.text, other[1])
        else:
            acc.whole_row(line, row.expected_columns, row.actual_columns, row.text)
        return "skip"

    wanted = sorted({f.column for f in fields}, key=header.index)
    size = os.path.getsize(path)
    next_line = first
    with open(path, "rb") as fh:
        text = _MarkedUtf8(fh)
        reader = pacsv.open_csv(
            text,
            # single-threaded: the parser then knows the line of a bad row, and memory stays
            # one block
            read_options=pacsv.ReadOptions(use_threads=False,
                                           block_size=block_size or BLOCK_SIZE,
                                           column_names=None if names is None else header),
            parse_options=pacsv.ParseOptions(invalid_row_handler=invalid,
                                             ignore_empty_lines=False),
            convert_options=pacsv.ConvertOptions(
                column_types={c: pa.string() for c in header}, include_columns=wanted,
                strings_can_be_null=False, quoted_strings_can_be_null=False))
        while True:
            try:
                batch = reader.read_next_batch()
            except StopIteration:
                break
            rejected[:] = [x for x in rejected if x >= next_line]
            n = batch.num_rows
            lines = _lines(next_line, n, rejected)
            if n:
                next_line = int(lines[-1]) + 1
            cols = {f.role: batch.column(f.column) for f in fields}
            if prepare is not None:
                cols = prepare(cols)
            bad_bytes = {r: e for r, c in cols.items() if (e := _undecodable(c))} \
                if text.marked else None
            acc.add(cols, lines, bad_bytes)
            if progress is not None:
                progress(min(fh.tell(), size), size)
    if progress is not None:
        progress(size, size)
    return acc.finish()


def _lines(start: int, n: int, skipped: list[int]) -> np.ndarray:
    """The first n line numbers >= start that the parser did not reject."""
    s = np.asarray([x for x in skipped if x >= start], dtype=np.int64)
    k = 0
    while True:
        cand = np.arange(start, start + n + k, dtype=np.int64)
        hit = np.isin(cand, s)
        if int(hit.sum()) == k:
            return cand[~hit]
        k = int(hit.sum())


def _corrupt(err: Exception) -> bool:
    """pyarrow reports corrupt data as ArrowInvalid or as an OSError without an errno (a
    real I/O failure, such as permission denied, has one)."""
    return isinstance(err, pa.ArrowException) or (isinstance(err, OSError) and
                                                   err.errno is None)


def _not_parquet(path: str, err: Exception, where: str = "") -> ValueError:
    return ValueError(f"{path}: not a readable Parquet file{where} ({str(err).strip()}); "
                      "expected a Parquet file as pyarrow or pandas write it, or a CSV file "
                      "named .csv")


def read_header(path: str | os.PathLike) -> list[str]:
    """The column names of a CSV file (its first line) or of a Parquet file (its schema)."""
    if os.fspath(path).lower().endswith((".parquet", ".pq")):
        return list(open_parquet(path).schema_arrow.names)
    return csv_header(os.fspath(path))


def open_parquet(path: str | os.PathLike):
    """``pyarrow.parquet.ParquetFile`` of ``path``; a corrupt or truncated file is a
    ValueError naming it (pyarrow's own message names no file)."""
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(path)
    except (pa.ArrowException, OSError) as err:
        if not _corrupt(err):
            raise
        raise _not_parquet(os.fspath(path), err) from None


def read_parquet_table(path: str | os.PathLike, fields: Sequence[Field], on_bad: str = "skip",
                       progress: Progress | None = None, soft: frozenset[str] = frozenset(),
                       max_listed: int = 100, row_check: RowCheck | None = None,
                       batch_size: int = 1 << 16) -> Table:
    """Stream a Parquet file through the fields; records are numbered by row from 1."""
    path = os.fspath(path)
    pf = open_parquet(path)
    names = pf.schema_arrow.names
    _check_columns(path, names, fields, "")
    order = {f.role: names.index(f.column) for f in fields}
    acc = Accumulator(path, fields, order, on_bad, soft, max_listed, row_check, "row")
    total = pf.metadata.num_rows
    size = os.path.getsize(path)
    done = 0
    wanted = sorted({f.column for f in fields}, key=names.index)
    batches = pf.iter_batches(batch_size=batch_size, columns=wanted)
    while True:
        try:
            batch = next(batches)
        except StopIteration:
            break
        except (pa.ArrowException, OSError) as err:  # a corrupt page further in
            if not _corrupt(err):
                raise
            raise _not_parquet(path, err, f" from row {done + 1} on") from None
        n = batch.num_rows
        cols = {f.role: batch.column(f.column) for f in fields}
        acc.add(cols, np.arange(done + 1, done + n + 1, dtype=np.int64))
        done += n
        if progress is not None:
            progress(int(size * done / max(total, 1)), size)
    if progress is not None:
        progress(size, size)
    return acc.finish()


# -- time ---------------------------------------------------------------------------------------


def parse_epoch(epoch) -> np.datetime64 | None:
    """A user's epoch (ISO text, datetime, datetime64, or unix seconds) as datetime64[ns]."""
    if epoch is None:
        return None
    if isinstance(epoch, (int, float, np.integer, np.floating)):
        return np.datetime64(int(round(float(epoch) * 1e9)), "ns")
    try:
        s = epoch.rstrip("Z") if isinstance(epoch, str) else epoch
        return np.datetime64(s, "ns")
    except (ValueError, TypeError):
        raise ValueError(f"epoch = {epoch!r}; expected an ISO 8601 UTC time, a datetime or "
                         "unix seconds") from None


def relative_times(t: np.ndarray, fmt: str, epoch=None
                   ) -> tuple[np.ndarray, np.datetime64 | None]:
    """Absolute times (int64 ns or float unix seconds, as :func:`convert` gives them) to float
    seconds from an epoch: the given one, else the earliest time floored to the second (so
    that the fractions of the file's times survive)."""
    ep = parse_epoch(epoch)
    if fmt == "seconds":
        if ep is not None:
            raise ValueError("epoch given but the time format 'seconds' is relative")
        return np.asarray(t, dtype=float), None
    if t.dtype == np.int64:  # ns since 1970
        e_ns = (int(ep.astype("datetime64[ns]").astype(np.int64)) if ep is not None else
                (int(t.min()) // 1_000_000_000 * 1_000_000_000 if len(t) else 0))
        return (t - e_ns) / 1e9, np.datetime64(e_ns, "ns")
    if ep is not None:
        e_ns = int(ep.astype("datetime64[ns]").astype(np.int64))
        return t - e_ns / 1e9, np.datetime64(e_ns, "ns")
    e_s = float(np.floor(t.min())) if len(t) else 0.0
    return t - e_s, np.datetime64(int(e_s), "s").astype("datetime64[ns]")
