"""ADS-B position reports from SBS-1 BaseStation lines, as dump1090-style receivers write them
(port 30003).

    reports, report = read_sbs("adsb.sbs")

A line is 22 comma-separated fields with no header::

    MSG,3,1,1,4CA2D6,1,2024/01/05,12:00:00.000,2024/01/05,12:00:00.000,,37000,,,51.47,-0.46,,,0,0,0,0

message type, transmission type, session, aircraft, ICAO 24-bit address (hex), flight, date
and time generated, date and time logged, callsign, altitude (ft), ground speed (kn), track
(deg), latitude, longitude, vertical rate (ft/min), squawk, alert, emergency, SPI, on ground.
Positions come from transmission types 2 (surface) and 3 (airborne); their time (the time
generated, UTC), address and position are required. Speed, track and vertical rate are
taken from the position line where it has them, else from the last type 4 (airborne
velocity) line of the same aircraft above it in the file: so a position carries the latest
velocity heard. Altitude (ft) becomes metres. The other lines (types 1, 5 to 8, and the
``SEL``, ``ID``, ``AIR``, ``STA``, ``CLK`` lines) are skipped and counted by kind, never fatal.

The file is streamed in blocks like a CSV file (``read_csv_table`` of ``trackkit.io._table``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from trackkit.io import _reports
from trackkit.io._table import ALTITUDE, MAX_SPEED, Field, Progress, read_csv_table
from trackkit.io.ais import velocity
from trackkit.io.frames import KNOT
from trackkit.io.records import ReadReport, Reports

__all__ = ["SBS_COLUMNS", "looks_like_sbs", "read_sbs"]

#: the 22 fields of a line, in order
SBS_COLUMNS = ("message_type", "transmission_type", "session_id", "aircraft_id", "hex_ident",
               "flight_id", "date_generated", "time_generated", "date_logged", "time_logged",
               "callsign", "altitude", "ground_speed", "track", "lat", "lon", "vertical_rate",
               "squawk", "alert", "emergency", "spi", "is_on_ground")
OTHER_LINES = ("SEL", "ID", "AIR", "STA", "CLK")
FOOT = 0.3048
VELOCITY_ROLES = ("speed", "track", "vertrate")


def looks_like_sbs(lines: Sequence[str]) -> bool:
    """Whether the first lines of a file are SBS-1 lines: a MSG line of 22 fields among the
    first five, and no line there of another kind."""
    head = [ln.split(",") for ln in lines[:5]]
    return any(f[0] == "MSG" and len(f) == 22 for f in head) and all(
        f[0] in ("MSG", *OTHER_LINES) for f in head)


def _other_line(text: str) -> tuple[str, str] | None:
    kind = text.split(",", 1)[0].strip()
    if kind in OTHER_LINES:
        return f"not a position ({kind} line)", "a MSG line"
    return None


class _Velocities:
    """Each aircraft's last velocity line (type 4) seen so far, carried from block to block;
    a position line without speed, track or vertical rate takes them from there."""

    def __init__(self) -> None:
        self.last: dict[str, tuple] = {}  # address -> (speed, track, vertical rate) as text

    def __call__(self, cols: dict) -> dict:
        n = len(cols["id"])
        if n == 0:
            return cols
        cols["time"] = pc.binary_join_element_wise(
            pc.replace_substring(cols["time"], "/", "-"), cols["time_of_day"], "T")
        is4 = np.asarray(pc.equal(pc.utf8_trim_whitespace(cols["msg"]), "4").fill_null(False)
                         .to_numpy(zero_copy_only=False), dtype=bool)
        enc = pc.dictionary_encode(cols["id"])
        code = np.asarray(enc.indices.to_numpy(zero_copy_only=False), dtype=np.int64)
        names = enc.dictionary.to_pylist()
        # in file order within each aircraft: the last type 4 line at or above each line
        order = np.lexsort((np.arange(n), code))
        c = code[order]
        start = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
        group_start = np.repeat(start, np.diff(np.r_[start, n]))
        seen = np.maximum.accumulate(np.where(is4[order], np.arange(n), -1))
        src = np.full(n, -1)
        src[order] = np.where(seen >= group_start, order[np.maximum(seen, 0)], -1)
        earlier = [self.last.get(a, (None, None, None)) for a in names]
        for k, role in enumerate(VELOCITY_ROLES):
            col = cols[role]
            blank = np.asarray(pc.equal(pc.utf8_trim_whitespace(col), "").fill_null(True)
                               .to_numpy(zero_copy_only=False), dtype=bool)
            carried = pa.array([e[k] for e in earlier], pa.string()).take(pa.array(code))
            here = col.take(pa.array(np.maximum(src, 0)))
            merged = pc.if_else(pa.array(src >= 0), here, carried)
            cols[role] = pc.if_else(pa.array(blank & ~is4), merged, col)
        for i in order[np.r_[c[1:] != c[:-1], True]]:
            j = src[i]
            if j >= 0:
                self.last[names[code[i]]] = tuple(cols[r][j].as_py() for r in VELOCITY_ROLES)
        return cols


def _positions_only(values: dict) -> list:
    """Row check: lines other than a position (type 2 or 3) are skipped, softly."""
    kind = values["msg"]
    out = []
    for t in (1, 4, 5, 6, 7, 8):
        out.append((kind == t, "msg", f"not a position (MSG {t})", "MSG 2 or 3"))
    out.append((~np.isin(kind, (1, 2, 3, 4, 5, 6, 7, 8)), "msg", "unknown transmission type",
                "MSG 1 to 8"))
    return out


def read_sbs(path: str | os.PathLike, on_bad: str = "skip", *,
             reference: _reports.Reference = None, epoch=None,
             bounds: tuple[float, float, float, float] | None = None,
             progress: Progress | None = None, max_listed: int = 100
             ) -> tuple[Reports, ReadReport]:
    """Read ADS-B positions from an SBS-1 file (see the module docstring); the arguments are
    those of :func:`~trackkit.io.read_ais_csv`."""
    path = os.fspath(path)
    fast = dict(required=False, bad_is_missing=True)
    fields = [
        Field("msg", "transmission_type", "int", what="transmission type"),
        Field("time", "date_generated", "time"),
        Field("time_of_day", "time_generated", "text", what="time generated"),
        Field("id", "hex_ident", "text", what="hex_ident"),
        Field("lat", "lat", lo=-90.0, hi=90.0, what="latitude"),
        Field("lon", "lon", lo=-180.0, hi=180.0, what="longitude"),
        Field("alt", "altitude", lo=ALTITUDE[0] / FOOT, hi=ALTITUDE[1] / FOOT,
              what="altitude", **fast),
        Field("speed", "ground_speed", lo=0.0, hi=MAX_SPEED / KNOT, what="ground speed", **fast),
        Field("track", "track", lo=0.0, hi=360.0, what="track", **fast),
        Field("vertrate", "vertical_rate", limit=MAX_SPEED / FOOT * 60, what="vertical rate",
              limit_why="in ft/min; 1000 m/s, Mach 3", **fast),
        Field("callsign", "callsign", "text", required=False, what="callsign"),
    ]
    soft = {f"not a position (MSG {t})" for t in (1, 4, 5, 6, 7, 8)}
    soft |= {f"not a position ({k} line)" for k in OTHER_LINES} | {"outside bounds"}
    b = _reports.bounds_check(bounds)

    def check(values: dict) -> list:
        out = _positions_only(values)
        return out + (_reports.outside_bounds(b)(values) if b is not None else [])

    table = read_csv_table(path, fields, on_bad, progress, soft=frozenset(soft),
                           max_listed=max_listed, row_check=check, names=SBS_COLUMNS,
                           prepare=_Velocities(), row_reason=_other_line)
    c = table.columns
    vx, vy = velocity(c["speed"] * KNOT, np.deg2rad(c["track"]))
    vz = c["vertrate"] * FOOT / 60
    alt = c["alt"] * FOOT
    extra = {"has_altitude": ~np.isnan(alt),
             "callsign": np.asarray(c["callsign"].to_pylist(), dtype=str)}
    return _reports.finish(table, time_format="iso", epoch=epoch, reference=reference,
                           alt=alt, vel=(vx, vy, vz), extra=extra, layout="sbs1")
