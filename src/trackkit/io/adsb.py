"""ADS-B position reports from OpenSky state-vector CSV files.

    reports, report = read_opensky_csv("OpenSky_Plane_States.csv")

One row of an OpenSky export is the state of one aircraft at a sampling ``time``; its position
may be older (``lastposupdate``). The position's own time is used when the file has it, so a
position repeated over several samples becomes exact duplicates (same aircraft, time and
position), which are dropped and counted. Rows with no position are skipped (reason
"no position", never fatal: OpenSky writes them for aircraft heard without a position).
Altitudes are metres (``geoaltitude``, GNSS height, by default, else ``baroaltitude``; the
other fills in where one is blank); velocity (m/s over ground) and heading (deg clockwise
from north, true track) give vx, vy, and vertrate vz. ``onground`` and ``callsign`` are kept
in ``reports.extra``. A record beyond physical limits is bad: latitude outside [-90, 90],
longitude outside [-180, 180], a time outside 1900 to 2200 UTC. An optional value beyond them
(speed or vertical rate above 1000 m/s, Mach 3, in magnitude, an altitude outside [-1 km,
100 km], a heading outside [0, 360]) or not a number is set missing, the record kept, and
counted by field and reason (``report.set_missing``).
"""

from __future__ import annotations

import os

import numpy as np

from trackkit.io import _reports
from trackkit.io._table import (
    ALTITUDE,
    MAX_SPEED,
    NAT,
    Field,
    Progress,
    csv_header,
    read_csv_table,
)
from trackkit.io.records import ReadReport, Reports

__all__ = ["read_opensky_csv"]


def read_opensky_csv(path: str | os.PathLike, on_bad: str = "skip", *,
                     altitude: str = "geo", reference: _reports.Reference = None, epoch=None,
                     bounds: tuple[float, float, float, float] | None = None,
                     progress: Progress | None = None, max_listed: int = 100
                     ) -> tuple[Reports, ReadReport]:
    """Read OpenSky state vectors (``time, icao24, lat, lon`` required; ``velocity,
    heading, vertrate, callsign, onground, baroaltitude, geoaltitude, lastposupdate`` used
    when present). ``altitude`` is ``"geo"`` or ``"baro"``; the other arguments are those of
    :func:`~trackkit.io.read_ais_csv`.
    """
    if altitude not in ("geo", "baro"):
        raise ValueError(f"altitude = {altitude!r}; expected 'geo' or 'baro'")
    path = os.fspath(path)
    have = set(csv_header(path))
    fields = [
        Field("time", "time", "time", time_format="unix"),
        Field("id", "icao24", "text", what="icao24"),
        Field("lat", "lat", lo=-90.0, hi=90.0, what="latitude", missing="no position",
              missing_soft=True),
        Field("lon", "lon", lo=-180.0, hi=180.0, what="longitude", missing="no position",
              missing_soft=True),
    ]
    fast = dict(limit=MAX_SPEED, limit_why=f"in m/s; {MAX_SPEED:g} m/s, Mach 3")
    opt = dict(required=False, bad_is_missing=True)  # a bad value is set missing, not the record
    optional = {
        "lastposupdate": Field("pos_time", "lastposupdate", "time", required=False,
                               time_format="unix", what="lastposupdate"),
        "velocity": Field("speed", "velocity", lo=0.0, what="speed", **fast, **opt),
        "heading": Field("heading", "heading", lo=0.0, hi=360.0, what="heading", **opt),
        "vertrate": Field("vertrate", "vertrate", what="vertrate", **fast, **opt),
        "geoaltitude": Field("geo", "geoaltitude", lo=ALTITUDE[0], hi=ALTITUDE[1],
                             what="geoaltitude", **opt),
        "baroaltitude": Field("baro", "baroaltitude", lo=ALTITUDE[0], hi=ALTITUDE[1],
                              what="baroaltitude", **opt),
        "onground": Field("onground", "onground", "bool", required=False, what="onground"),
        "callsign": Field("callsign", "callsign", "text", required=False, what="callsign"),
    }
    fields += [f for c, f in optional.items() if c in have]
    b = _reports.bounds_check(bounds)
    table = read_csv_table(path, fields, on_bad, progress,
                           soft=frozenset({"no position", "outside bounds"}),
                           max_listed=max_listed,
                           row_check=None if b is None else _reports.outside_bounds(b))
    c = table.columns
    n = len(table.lines)
    nan = np.full(n, np.nan)
    # the time of the position, not of the sample, where the file says
    if "pos_time" in c:
        c["time"] = np.where(c["pos_time"] == NAT, c["time"], c["pos_time"])
    first, second = ("geo", "baro") if altitude == "geo" else ("baro", "geo")
    alt = c.get(first, nan)
    alt = np.where(np.isnan(alt), c.get(second, nan), alt)
    if np.isnan(alt).any():
        table.not_given["altitude (x, y at the ellipsoid)"] += int(np.isnan(alt).sum())
    s = c.get("speed", nan)
    h = np.deg2rad(c.get("heading", nan))
    h = np.where((s == 0) & np.isnan(h), 0.0, h)  # at rest: velocity known, heading moot
    vel = (s * np.sin(h), s * np.cos(h), c.get("vertrate", nan))
    extra: dict[str, np.ndarray] = {"has_altitude": ~np.isnan(alt)}
    if "onground" in c:
        extra["onground"] = np.asarray(c["onground"], dtype=bool)
    if "callsign" in c:
        extra["callsign"] = np.asarray(c["callsign"].to_pylist(), dtype=str)
    return _reports.finish(table, time_format="unix", epoch=epoch, reference=reference,
                           alt=alt, vel=vel, extra=extra)
