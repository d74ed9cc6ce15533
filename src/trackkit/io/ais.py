"""AIS position reports from CSV: the Solent layout by default, any other through a mapping.

    reports, report = read_ais_csv("SolentAIS_20160112_130211.csv")
    reports.x, reports.y          # east, north (m) from the median position
    reports.vx, reports.vy        # m/s from SOG (knots) and COG (deg); nan where not available
    print(report.summary())       # what was skipped, sorted, dropped

AIS (ITU-R M.1371) codes "not available" as COG 360, SOG 102.3, heading 511, latitude 91
and longitude 181. An optional field (course, speed, heading) that holds its code, is not a
number, or is out of range (course outside [0, 360] deg, speed negative or above 1000 m/s,
Mach 3, heading outside [0, 359] deg) is set missing, the report kept, counted by field and
reason (``report.set_missing``); its velocity is then nan (a vessel with SOG 0 and no course
has velocity 0). Only the time, the id and the position are required: latitude 91 or
longitude 181 skips the record as "position not available" (never fatal); otherwise
latitude must lie in [-90, 90], longitude in [-180, 180] and the time from 1900 to 2200 UTC,
or the record is bad.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from trackkit.io import _reports
from trackkit.io._table import MAX_SPEED, TIME_FORMATS, Field, Progress, read_csv_table
from trackkit.io.frames import ANGLE_UNITS, SPEED_UNITS, unit_factor
from trackkit.io.records import ReadReport, Reports

__all__ = ["AisColumns", "SOLENT", "fields_of", "read_ais_csv", "velocity"]


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
    course_unavailable: float | tuple[float, ...] | None = 360.0
    speed_unavailable: float | tuple[float, ...] | None = 102.3
    heading: str | None = None  # true heading (deg), kept in ``reports.extra["heading_deg"]``
    heading_unavailable: float | None = 511.0
    lat_unavailable: float | None = 91.0
    lon_unavailable: float | None = 181.0

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
                 progress: Progress | None = None, max_listed: int = 100,
                 layout: str = "") -> tuple[Reports, ReadReport]:
    """Read AIS position reports from a CSV file (``layout`` names it in the report).

    ``on_bad="skip"`` skips bad records (counted by reason in the report, the first
    ``max_listed`` listed with file, line and column); ``"stop"`` raises ValueError at the
    first. ``reference`` is the ENU origin (an :class:`EnuFrame` or ``(lat, lon[, alt])``;
    default the median position); ``epoch`` the absolute time of t = 0 (default the first
    report's time floored to the second). ``bounds = (lat_min, lat_max, lon_min, lon_max)``
    skips positions outside a box (counted as "outside bounds"; never stops the read).
    ``progress(bytes_done, bytes_total)`` is called after every block.
    """
    col = SOLENT if columns is None else columns
    fields = fields_of(col)
    b = _reports.bounds_check(bounds)
    table = read_csv_table(path, fields, on_bad, progress, soft=frozenset({"outside bounds"}),
                           max_listed=max_listed,
                           row_check=None if b is None else _reports.outside_bounds(b))
    n = len(table.lines)
    nan = np.full(n, np.nan)
    c = table.columns
    speed = c["speed"] * unit_factor(SPEED_UNITS, col.speed_unit, "speed") if col.speed \
        else nan
    course = c["course"] * unit_factor(ANGLE_UNITS, col.course_unit, "course") if col.course \
        else nan
    vx, vy = velocity(speed, course)
    extra = {"heading_deg": c["heading"]} if col.heading is not None else {}
    return _reports.finish(table, time_format=col.time_format, epoch=epoch,
                           reference=reference, alt=None, vel=(vx, vy, nan), extra=extra,
                           layout=layout)


def velocity(speed: np.ndarray, course: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """East and north velocity (m/s) from speed over ground (m/s) and course (rad clockwise
    from north); a vessel at rest has a known velocity even when its course is not given."""
    course = np.where((speed == 0) & np.isnan(course), 0.0, course)
    return speed * np.sin(course), speed * np.cos(course)


def fields_of(col: AisColumns) -> list[Field]:
    """The fields of a layout: time, id and position required, the rest set missing when
    bad."""
    deg = col.course_unit == "deg"
    fields = [
        Field("time", col.time, "time", time_format=col.time_format),
        Field("id", col.id, "text", what="id"),
        Field("lat", col.lat, lo=-90.0, hi=90.0, what="latitude",
              unavailable=col.lat_unavailable, unavailable_reason="position not available"),
        Field("lon", col.lon, lo=-180.0, hi=180.0, what="longitude",
              unavailable=col.lon_unavailable, unavailable_reason="position not available"),
    ]
    if col.course is not None:
        fields.append(Field("course", col.course, required=False, lo=0.0,
                            hi=360.0 if deg else 2 * np.pi, what="course",
                            unavailable=col.course_unavailable, bad_is_missing=True))
    if col.speed is not None:
        fields.append(Field("speed", col.speed, required=False, lo=0.0, what="speed",
                            unavailable=col.speed_unavailable, bad_is_missing=True,
                            limit=MAX_SPEED / unit_factor(SPEED_UNITS, col.speed_unit, "speed"),
                            limit_why=f"in {col.speed_unit}; {MAX_SPEED:g} m/s, Mach 3"))
    if col.heading is not None:
        fields.append(Field("heading", col.heading, required=False, lo=0.0, hi=359.0,
                            what="heading", unavailable=col.heading_unavailable,
                            bad_is_missing=True))
    return fields
