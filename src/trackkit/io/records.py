"""What the readers return: a columnar table of position reports and an account of the read.

:class:`Reports` is the common output of the AIS and ADS-B readers: one row per report,
sorted by time, every column a numpy array (x east, y north, z up in metres of the frame
``frame``; time in seconds from ``epoch``). :class:`ReadReport` says what happened to every
data line of the file: ``rows_read == rows_kept + n_skipped + duplicates`` always holds, so
nothing is lost without a count, and the first skipped records are listed with their file,
line and column.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from trackkit.io.frames import EnuFrame

__all__ = ["BadRecord", "GpsFixes", "InsSamples", "ReadReport", "Reports", "one_run"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class BadRecord:
    """One skipped (or fatal) record: where it is, the offending value and what was expected.

    ``line`` is the 1-based line of a CSV file (the header is line 1) or the 1-based row of a
    Parquet file (``unit="row"``).
    """

    path: str
    line: int
    column: str
    reason: str
    value: str = ""
    expected: str = ""
    unit: str = "line"

    def __str__(self) -> str:
        where = f"{self.path}:{self.line}" if self.unit == "line" else \
            f"{self.path}:row {self.line}"
        s = f"{where}:{self.column}: {self.reason}"
        if self.value != "" or self.expected:
            s += f" (value {self.value!r}"
            s += f"; expected {self.expected})" if self.expected else ")"
        return s


@dataclass(frozen=True)
class ReadReport:
    """The account of one read.

    * ``rows_read``: data records in the file (CSV lines after the header, Parquet rows);
    * ``rows_kept``: records in the output;
    * ``skipped``: records skipped, by reason (each record counted once, under the first bad
      field in column order);
    * ``bad``: the first ``max_listed`` skipped records, with file, line, column and value;
    * ``skipped_lines``: the line (or row) of every skipped record, sorted;
    * ``out_of_order``: kept records whose time is earlier than a record above them in the
      file (the output is sorted by time, so these were moved);
    * ``duplicates``: exact repeats (same id, time and position) dropped, the first kept;
    * ``not_given``: optional fields left blank (or holding a "not available" code), by field:
      the record is kept with nan there;
    * ``set_missing``: the same values by field and reason (``{"course": {"not available
      (360)": 12, "outside [0, 360]": 3}}``; "blank" for an empty field);
    * ``epoch``: the absolute time of t = 0 (None when the file's times are already relative);
    * ``layout``: the name of the file's layout (``trackkit.io.LAYOUTS``), "" when not known.
    """

    path: str
    rows_read: int
    rows_kept: int
    skipped: Mapping[str, int] = field(default_factory=dict)
    bad: tuple[BadRecord, ...] = ()
    skipped_lines: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    out_of_order: int = 0
    duplicates: int = 0
    not_given: Mapping[str, int] = field(default_factory=dict)
    epoch: np.datetime64 | None = None
    set_missing: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    layout: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "skipped", MappingProxyType(dict(self.skipped)))
        object.__setattr__(self, "not_given", MappingProxyType(dict(self.not_given)))
        object.__setattr__(self, "set_missing", MappingProxyType(
            {k: MappingProxyType(dict(v)) for k, v in self.set_missing.items()}))
        if self.rows_read != self.rows_kept + self.n_skipped + self.duplicates:
            raise AssertionError(
                f"{self.path}: {self.rows_read} rows read but {self.rows_kept} kept + "
                f"{self.n_skipped} skipped + {self.duplicates} duplicates; a record went "
                "missing (a bug in the reader)")

    @property
    def n_skipped(self) -> int:
        return int(sum(self.skipped.values()))

    def _why(self, label: str) -> str:
        """`` (12 not available (360), 3 outside [0, 360])``: why a field was set missing."""
        why = self.set_missing.get(label)
        if not why:
            return ""
        return " (" + ", ".join(f"{n} {r}" for r, n in sorted(why.items(),
                                                               key=lambda kv: -kv[1])) + ")"

    def summary(self) -> str:
        """A few lines for a log or the CLI."""
        layout = f" ({self.layout} layout)" if self.layout else ""
        lines = [f"{self.path}: {self.rows_read} records read, {self.rows_kept} kept{layout}"]
        if self.skipped:
            lines.append(f"  skipped {self.n_skipped}: " + ", ".join(
                f"{n} {r}" for r, n in sorted(self.skipped.items(), key=lambda kv: -kv[1])))
            lines.extend(f"    {b}" for b in self.bad[:10])
            if self.n_skipped > min(len(self.bad), 10):
                lines.append(f"    ... ({self.n_skipped - min(len(self.bad), 10)} more)")
        if self.duplicates:
            lines.append(f"  dropped {self.duplicates} exact duplicates")
        if self.out_of_order:
            lines.append(f"  {self.out_of_order} records were out of time order and were sorted")
        if self.not_given:
            lines.append("  not given (kept as nan): " + ", ".join(
                f"{f} {n}" + self._why(f) for f, n in self.not_given.items()))
        if self.epoch is not None:
            lines.append(f"  t = 0 at {self.epoch} UTC")
        return "\n".join(lines)


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Reports:
    """Position reports of many objects, one row per report, sorted by time (ties keep the
    order of the file).

    ``ids`` are the objects' identifiers as text (MMSI, icao24), sorted; ``code`` is each
    report's index into ``ids`` (dense integers ``0..len(ids)-1``, usable as array indices).
    ``x, y, z`` are east, north, up in metres in ``frame``; for data without altitude (AIS),
    z is the up coordinate of the sea-level point (slightly negative away from the reference,
    the earth's curvature), kept so that :meth:`geodetic` inverts exactly. ``vx, vy, vz`` are
    m/s, nan where not given. ``line`` is each report's line in ``source``. ``extra`` holds
    per-report columns particular to a source (e.g. ADS-B ``onground``, ``callsign``).
    """

    time: Array
    code: NDArray[np.int64]
    ids: NDArray[np.str_]
    x: Array
    y: Array
    z: Array
    vx: Array
    vy: Array
    vz: Array
    line: NDArray[np.int64]
    frame: EnuFrame
    epoch: np.datetime64 | None
    source: str = ""
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = np.shape(self.time)[0]
        for name in ("time", "code", "x", "y", "z", "vx", "vy", "vz", "line"):
            a = np.asarray(getattr(self, name))
            if a.shape != (n,):
                raise ValueError(f"Reports.{name} has shape {a.shape}; expected ({n},)")
            object.__setattr__(self, name, _readonly(np.array(a, copy=True)))
        object.__setattr__(self, "ids", _readonly(np.array(self.ids, dtype=str, copy=True)))
        if n and (self.code.min() < 0 or self.code.max() >= len(self.ids)):
            raise ValueError(f"Reports.code outside [0, {len(self.ids)}); expected indices "
                             "into ids")
        if n > 1 and not np.all(np.diff(self.time) >= 0):
            raise ValueError("Reports.time is not sorted; expected non-decreasing times")
        extra = {}
        for k, v in dict(self.extra).items():
            v = np.array(v, copy=True)
            if v.shape[:1] != (n,):
                raise ValueError(f"Reports.extra[{k!r}] has shape {v.shape}; expected ({n}, ...)")
            extra[k] = _readonly(v)
        object.__setattr__(self, "extra", MappingProxyType(extra))

    def __len__(self) -> int:
        return int(self.time.shape[0])

    def __repr__(self) -> str:
        span = f", {self.time[-1] - self.time[0]:.1f} s" if len(self) else ""
        return (f"Reports({len(self)} reports of {len(self.ids)} objects{span}, "
                f"from {self.source!r})")

    @property
    def id(self) -> NDArray[np.str_]:
        """Each report's identifier as text, ``ids[code]``."""
        return self.ids[self.code]

    @property
    def position(self) -> Array:
        """``(n, 2)`` east, north (m)."""
        return np.stack([self.x, self.y], axis=-1)

    @property
    def velocity(self) -> Array:
        """``(n, 2)`` east, north (m/s), nan where not given."""
        return np.stack([self.vx, self.vy], axis=-1)

    def geodetic(self) -> tuple[Array, Array, Array]:
        """Latitude, longitude (deg) and altitude (m) of every report, from the frame."""
        return self.frame.to_geodetic(self.x, self.y, self.z)

    def absolute_time(self) -> NDArray[np.datetime64]:
        """Times as ``datetime64[ns]`` (UTC); needs an epoch."""
        if self.epoch is None:
            raise ValueError(f"{self.source}: the times are relative (no epoch)")
        return self.epoch.astype("datetime64[ns]") + np.round(self.time * 1e9).astype(
            "timedelta64[ns]")

    def select(self, mask: NDArray[np.bool_]) -> Reports:
        """The reports where ``mask`` is true (ids and frame unchanged)."""
        mask = np.asarray(mask, dtype=bool)
        cols = {k: getattr(self, k)[mask] for k in
                ("time", "code", "x", "y", "z", "vx", "vy", "vz", "line")}
        return Reports(**cols, ids=self.ids, frame=self.frame, epoch=self.epoch,
                       source=self.source, extra={k: v[mask] for k, v in self.extra.items()})

    def for_object(self, ident: str) -> Reports:
        """The reports of one object, by its identifier."""
        k = np.searchsorted(self.ids, ident)
        if k >= len(self.ids) or self.ids[k] != ident:
            raise KeyError(f"{self.source}: no object {ident!r}")
        return self.select(self.code == k)


class GpsFixes(NamedTuple):
    """GPS fixes: ``t`` ``(N,)`` s; ``lat``, ``lon`` ``(..., N)`` WGS-84 degrees (the unit
    :class:`~trackkit.io.frames.EnuFrame` takes); ``sog`` m/s; ``cog`` rad clockwise from
    north in [0, 2 pi)."""

    t: Array
    lat: Array
    lon: Array
    sog: Array
    cog: Array


class InsSamples(NamedTuple):
    """INS output: ``t`` ``(M,)`` s; ``heading`` ``(..., M)`` rad clockwise from north in
    [0, 2 pi); ``rate`` ``(..., M)`` yaw rate, rad/s, positive clockwise."""

    t: Array
    heading: Array
    rate: Array


def one_run(record: GpsFixes | InsSamples, index: int | tuple[int, ...]
            ) -> GpsFixes | InsSamples:
    """The record of one run: ``index`` applied to the leading axes of every field but ``t``
    (e.g. to write one run of a batch as an NMEA log)."""
    return type(record)(record[0], *(np.asarray(x)[index] for x in record[1:]))
