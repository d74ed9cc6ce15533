"""AIS position reports from CSV: the Solent layout by default, any other through a mapping.

    reports, report = read_ais_csv("SolentAIS_20160112_130211.csv")
    reports.x, reports.y          # east, north (m) from the median position
    reports.vx, reports.vy        # m/s from SOG (knots) and COG (deg); nan where not available
    print(report.summary())       # what was skipped, sorted, dropped

AIS codes "not available" as COG 360 and SOG 102.3: such values are read as not given (the
report is kept, its velocity nan; a vessel with SOG 0 and no course has velocity 0).
Latitude must lie in [-90, 90], longitude in [-180, 180], course in [0, 360] deg, speed in
[0, 1000] m/s (Mach 3) and the time from 1900 to 2200 UTC: a record beyond is bad.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from trackkit.io import _reports
from trackkit.io._table import MAX_SPEED, TIME_FORMATS, Field, Progress, read_csv_table
from trackkit.io.frames import ANGLE_UNITS, SPEED_UNITS, unit_factor
from trackkit.io.records import ReadReport, Reports

__all__ = ["AisColumns", "SOLENT", "read_ais_csv"]


@dataclass(frozen=True)
class AisColumns:
    """Which column holds what in an AIS CSV file, and in which units.

    ``time_format`` is ``"iso"`` (``2016-01-12 13:02:11.218``, ``T`` or space, optional
    fraction and ``Z``/``+hh:mm``), ``"unix"`` (seconds since 1970 UTC), ``"unix_ms"``,
    ``"seconds"`` (already relative: no epoch) or a strptime pattern such as
    ``"%d/%m/%Y %H:%M:%S"``. ``course`` and ``speed`` may be None (no velocity). The
    "not available" codes are read as not given; set them to None for data that mean 360 and
    102.3 literally.
    """

    time: str = "Time"
    id: str = "MMSI"
    lat: str = "Latitude_degrees"
    lon: str = "Longitude_degrees"
    course: str | None = "COG_degrees"
    speed: str | None = "SOG_knots"
    time_format: str = "iso"
    course_unit: str = "deg"
    speed_unit: str = "kn"
    course_unavailable: float | None = 360.0
    speed_unavailable: float | None = 102.3

    def __post_init__(self) -> None:
        unit_factor(ANGLE_UNITS, self.course_unit, "course")
        unit_factor(SPEED_UNITS, self.speed_unit, "speed")
        if self.time_format not in TIME_FORMATS and "%" not in self.time_format:
            raise ValueError(f"AisColumns.time_format = {self.time_format!r}; expected one of "
                             f"{', '.join(map(repr, TIME_FORMATS))} or a strptime pattern")


#: The layout of the Solent AIS recording (Stone Soup's demo data).
SOLENT = AisColumns()


def read_ais_csv(path: str | os.PathLike, columns: AisColumns | None = None,
                 on_bad: str = "skip", *, reference: _reports.Reference = None,
                 epoch=None, bounds: tuple[float, float, float, float] | None = None,
                 progress: Progress | None = None, max_listed: int = 100
                 ) -> tuple[Reports, ReadReport]:
    """Read AIS position reports from a CSV file.

    ``on_bad="skip"`` skips bad records (counted by reason in the report, the first
    ``max_listed`` listed with file, line and column); ``"stop"`` raises ValueError at the
    first. ``reference`` is the ENU origin (an :class:`EnuFrame` or ``(lat, lon[, alt])``;
    default the median position); ``epoch`` the absolute time of t = 0 (default the first
    report's time floored to the second). ``bounds = (lat_min, lat_max, lon_min, lon_max)``
    skips positions outside a box (counted as "outside bounds"; never stops the read).
    ``progress(bytes_done, bytes_total)`` is called after every block.
    """
    col = SOLENT if columns is None else columns
    deg = col.course_unit == "deg"
    fields = [
        Field("time", col.time, "time", time_format=col.time_format),
        Field("id", col.id, "text", what="id"),
        Field("lat", col.lat, lo=-90.0, hi=90.0, what="latitude"),
        Field("lon", col.lon, lo=-180.0, hi=180.0, what="longitude"),
    ]
    if col.course is not None:
        fields.append(Field("course", col.course, required=False, lo=0.0,
                            hi=360.0 if deg else 2 * np.pi, what="course",
                            unavailable=col.course_unavailable))
    if col.speed is not None:
        fields.append(Field("speed", col.speed, required=False, lo=0.0, what="speed",
                            unavailable=col.speed_unavailable,
                            limit=MAX_SPEED / unit_factor(SPEED_UNITS, col.speed_unit, "speed"),
                            limit_why=f"in {col.speed_unit}; {MAX_SPEED:g} m/s, Mach 3"))
    b = _reports.bounds_check(bounds)
    table = read_csv_table(path, fields, on_bad, progress, soft=frozenset({"outside bounds"}),
                           max_listed=max_listed,
                           row_check=None if b is None else _reports.outside_bounds(b))
    n = len(table.lines)
    vx = vy = np.full(n, np.nan)
    if col.speed is not None:
        s = table.columns["speed"] * unit_factor(SPEED_UNITS, col.speed_unit, "speed")
        c = (table.columns["course"] * unit_factor(ANGLE_UNITS, col.course_unit, "course")
             if col.course is not None else np.full(n, np.nan))
        # a vessel at rest has a known velocity even when its course is not available
        c = np.where((s == 0) & np.isnan(c), 0.0, c)
        vx, vy = s * np.sin(c), s * np.cos(c)
    return _reports.finish(table, time_format=col.time_format, epoch=epoch,
                           reference=reference, alt=None, vel=(vx, vy, np.full(n, np.nan)),
                           extra={})
