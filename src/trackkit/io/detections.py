"""Detection files (radar plots, sonar contacts) in, :class:`~trackkit.io.scans.Scans`
out.

One row per detection: a time, a sensor id, and either Cartesian ``x, y`` (``z``) or polar
``range, bearing`` coordinates; column names are given by :class:`DetectionColumns`, units by
:class:`DetectionUnits`. Detections with the same (time, sensor) form one scan. A row whose
coordinates are all blank marks a scan with no detections (a sweep that saw nothing, which a
tracker must know about), as :meth:`Scans.to_csv` writes it.

    scans, report = read_detections("plots.csv",
                                    DetectionColumns(range="rng_nm", bearing="brg_deg"),
                                    DetectionUnits(distance="nmi", angle="deg", time="iso"))

Polar detections come out as ``[range (m), bearing (rad)]``, bearing nautical (clockwise from
north, wrapped to (-pi, pi]), the measurement of ``tk.models.RangeBearing``; Cartesian as
``[x, y(, z)]`` in metres.

Finite but absurd values are bad records (named and skipped, or fatal with ``on_bad="stop"``):
``|x|, |y|, |z|`` and range above 1e8 m (100 000 km, beyond geostationary orbit), a bearing
outside [-360, 360] deg, a relative time beyond 1e10 s (317 years) or an absolute one outside
1900 to 2200 UTC.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from trackkit.angles import wrap
from trackkit.io._table import (
    MAX_DISTANCE,
    TIME_FORMATS,
    Field,
    Progress,
    read_csv_table,
    read_parquet_table,
    relative_times,
)
from trackkit.io.frames import ANGLE_UNITS, DISTANCE_UNITS, unit_factor
from trackkit.io.records import ReadReport
from trackkit.io.scans import Scans

__all__ = ["DetectionColumns", "DetectionUnits", "read_detections"]

_TIME_UNITS = {"s": "seconds", "iso": "iso", "unix": "unix", "unix_ms": "unix_ms"}


@dataclass(frozen=True)
class DetectionColumns:
    """Column names. Give ``x`` and ``y`` (and optionally ``z``) or ``range`` and
    ``bearing``; ``sensor=None`` puts every detection on sensor 0."""

    time: str = "time"
    sensor: str | None = "sensor"
    x: str | None = "x"
    y: str | None = "y"
    z: str | None = None
    range: str | None = None
    bearing: str | None = None

    def __post_init__(self) -> None:
        polar = self.range is not None or self.bearing is not None
        if polar:
            if self.range is None or self.bearing is None:
                raise ValueError("DetectionColumns: give both range and bearing")
            # polar columns replace the default Cartesian names
            object.__setattr__(self, "x", None)
            object.__setattr__(self, "y", None)
            if self.z is not None:
                raise ValueError("DetectionColumns: z with range and bearing is not supported")
        elif self.x is None or self.y is None:
            raise ValueError("DetectionColumns: give x and y, or range and bearing")

    @property
    def polar(self) -> bool:
        return self.range is not None

    @property
    def coordinates(self) -> tuple[str, ...]:
        if self.polar:
            return (self.range, self.bearing)  # type: ignore[return-value]
        return tuple(c for c in (self.x, self.y, self.z) if c is not None)


@dataclass(frozen=True)
class DetectionUnits:
    """Units of the file: ``distance`` ``"m"``, ``"km"`` or ``"nmi"`` (x, y, z, range);
    ``angle`` ``"deg"`` or ``"rad"``; ``bearing`` ``"nautical"`` (clockwise from north) or
    ``"math"`` (counter-clockwise from east); ``time`` ``"s"`` (relative seconds), ``"iso"``,
    ``"unix"``, ``"unix_ms"`` or a strptime pattern."""

    distance: str = "m"
    angle: str = "deg"
    bearing: str = "nautical"
    time: str = "s"

    def __post_init__(self) -> None:
        unit_factor(DISTANCE_UNITS, self.distance, "distance")
        unit_factor(ANGLE_UNITS, self.angle, "angle")
        if self.bearing not in ("nautical", "math"):
            raise ValueError(f"DetectionUnits.bearing = {self.bearing!r}; expected 'nautical' "
                             "or 'math'")
        if self.time not in _TIME_UNITS and "%" not in self.time:
            raise ValueError(f"DetectionUnits.time = {self.time!r}; expected 's', 'iso', "
                             "'unix', 'unix_ms' or a strptime pattern")

    @property
    def time_format(self) -> str:
        return _TIME_UNITS.get(self.time, self.time)


def read_detections(path: str | os.PathLike, columns: DetectionColumns | None = None,
                    units: DetectionUnits | None = None, on_bad: str = "skip", *,
                    format: str | None = None, epoch=None, progress: Progress | None = None,
                    max_listed: int = 100) -> tuple[Scans, ReadReport]:
    """Read a detections file (CSV or Parquet, by ``format`` or the file's suffix) into
    scans grouped by (time, sensor), sorted by time then sensor.

    Bad records are skipped and counted (``on_bad="skip"``) or stop the read; exact
    duplicates (same time, sensor and coordinates) are dropped and counted. With absolute
    times (``units.time`` not ``"s"``) the scans' times are seconds from ``report.epoch``.
    """
    col = DetectionColumns() if columns is None else columns
    un = DetectionUnits() if units is None else units
    path = os.fspath(path)
    if format is None:
        format = "parquet" if path.lower().endswith((".parquet", ".pq")) else "csv"
    if format not in ("csv", "parquet"):
        raise ValueError(f"format = {format!r}; expected 'csv' or 'parquet'")
    fmt = un.time_format
    if fmt not in TIME_FORMATS and "%" not in fmt:
        raise ValueError(f"DetectionUnits.time = {un.time!r} is not a known time format")
    fields = [Field("time", col.time, "time", time_format=fmt)]
    if col.sensor is not None:
        fields.append(Field("sensor", col.sensor, "int", what="sensor id"))
    roles = []
    # physical limits in the file's units (see the module docstring)
    far = dict(limit=MAX_DISTANCE / unit_factor(DISTANCE_UNITS, un.distance, "distance"),
               limit_why=f"in {un.distance}; {MAX_DISTANCE:g} m, beyond geostationary orbit")
    turn = 2 * np.pi / unit_factor(ANGLE_UNITS, un.angle, "angle")
    if col.polar:
        fields.append(Field("c0", col.range, required=False, lo=0.0, what="range", **far))
        fields.append(Field("c1", col.bearing, required=False, lo=-turn, hi=turn,
                            what="bearing"))
        roles = ["c0", "c1"]
    else:
        for k, name in enumerate(col.coordinates):
            fields.append(Field(f"c{k}", name, required=False, what="xyz"[k], **far))
            roles.append(f"c{k}")

    def partial(v: dict) -> list:
        # all coordinates blank is an empty scan; some blank is a record with a missing value
        blank = np.stack([np.isnan(v[r]) for r in roles])
        some = blank.any(axis=0) & ~blank.all(axis=0)
        first = np.argmax(blank, axis=0)
        return [(some & (first == k), r, "missing value",
                 "all coordinates, or none (an empty scan)") for k, r in enumerate(roles)]

    reader = read_parquet_table if format == "parquet" else read_csv_table
    table = reader(path, fields, on_bad, progress, max_listed=max_listed, row_check=partial)
    c = table.columns
    n = len(table.lines)
    for r in roles:  # blank coordinates are the empty-scan markers, not "not given"
        table.not_given.pop(next(f.label for f in fields if f.role == r), None)
    t, ep = relative_times(c["time"], fmt, epoch)
    sensor = c["sensor"] if col.sensor is not None else np.zeros(n, dtype=np.int64)
    d = unit_factor(DISTANCE_UNITS, un.distance, "distance")
    if col.polar:
        b = c["c1"] * unit_factor(ANGLE_UNITS, un.angle, "angle")
        if un.bearing == "math":
            b = np.pi / 2 - b
        z = np.stack([c["c0"] * d, wrap(b)], axis=-1)
    else:
        z = np.stack([c[r] * d for r in roles], axis=-1)
    marker = np.isnan(z).all(axis=1)
    lines = table.lines
    out_of_order = int(np.sum(t[1:] < np.maximum.accumulate(t)[:-1])) if n > 1 else 0
    # exact duplicates: same time, sensor and coordinates (markers included); first kept
    keys = [lines] + [z[:, k] for k in range(z.shape[1])][::-1] + [sensor, t]
    o = np.lexsort(keys)
    dup = np.zeros(n, dtype=bool)
    if n > 1:
        zs = z[o]
        same = (t[o][1:] == t[o][:-1]) & (sensor[o][1:] == sensor[o][:-1])
        same &= np.all((zs[1:] == zs[:-1]) | (np.isnan(zs[1:]) & np.isnan(zs[:-1])), axis=1)
        dup[o[1:][same]] = True
    keep = ~dup
    o = np.flatnonzero(keep)
    o = o[np.lexsort((lines[o], sensor[o], t[o]))]
    ts, ss, zz, mk = t[o], sensor[o], z[o], marker[o]
    new = np.ones(len(o), dtype=bool)
    new[1:] = (ts[1:] != ts[:-1]) | (ss[1:] != ss[:-1])
    start = np.flatnonzero(new)
    scan_of = np.cumsum(new) - 1
    counts = np.bincount(scan_of[~mk], minlength=len(start)).astype(np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    scans = Scans(zz[~mk].reshape(-1, z.shape[1]), offsets, ts[start], ss[start])
    report = ReadReport(
        path=path, rows_read=table.rows_read, rows_kept=len(o), skipped=dict(table.skipped),
        bad=tuple(table.bad), skipped_lines=table.skipped_lines, out_of_order=out_of_order,
        duplicates=int(dup.sum()), not_given=dict(table.not_given), epoch=ep)
    return scans, report
