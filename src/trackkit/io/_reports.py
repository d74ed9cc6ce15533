"""From validated columns to :class:`Reports`: times from an epoch, ids coded, exact
duplicates dropped, the local frame, sorting by time; shared by the AIS and ADS-B readers."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from trackkit.io._table import Table, relative_times
from trackkit.io.frames import EnuFrame
from trackkit.io.records import ReadReport, Reports

Reference = EnuFrame | tuple[float, float] | tuple[float, float, float] | None


def as_frame(reference: Reference, lat: np.ndarray, lon: np.ndarray) -> EnuFrame:
    if reference is None:
        return EnuFrame.at_median(lat, lon) if len(lat) else EnuFrame(0.0, 0.0)
    if isinstance(reference, EnuFrame):
        return reference
    ref = tuple(float(v) for v in reference)
    if len(ref) not in (2, 3):
        raise ValueError(f"reference = {reference!r}; expected an EnuFrame or (lat, lon[, alt])")
    return EnuFrame(*ref)


def bounds_check(bounds) -> tuple[float, float, float, float] | None:
    if bounds is None:
        return None
    b = tuple(float(v) for v in bounds)
    if len(b) != 4 or not (b[0] <= b[1] and b[2] <= b[3]):
        raise ValueError(f"bounds = {bounds!r}; expected (lat_min, lat_max, lon_min, lon_max) "
                         "with min <= max")
    return b  # type: ignore[return-value]


def outside_bounds(bounds):
    """A row check that skips (softly) positions outside a latitude/longitude box."""
    def check(v: dict) -> list:
        lat, lon = v["lat"], v["lon"]
        out = (lat < bounds[0]) | (lat > bounds[1]) | (lon < bounds[2]) | (lon > bounds[3])
        return [(out, "lat", "outside bounds",
                 f"a position in lat [{bounds[0]:g}, {bounds[1]:g}], "
                 f"lon [{bounds[2]:g}, {bounds[3]:g}]")]
    return check


def _codes(ids: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique identifiers and each row's index into them (hashing in pyarrow, so a
    million rows cost milliseconds, not a Python sort of strings)."""
    if len(ids) == 0:
        return np.zeros(0, dtype=str), np.zeros(0, dtype=np.int64)
    d = pc.dictionary_encode(ids)
    uniq = np.asarray(d.dictionary.to_pylist(), dtype=str)
    order = np.argsort(uniq, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    idx = np.asarray(d.indices.to_numpy(zero_copy_only=False), dtype=np.int64)
    return uniq[order], rank[idx].astype(np.int64)


def _same(a: np.ndarray) -> np.ndarray:
    """Adjacent equality with nan equal to nan."""
    return (a[1:] == a[:-1]) | (np.isnan(a[1:]) & np.isnan(a[:-1]))


def finish(table: Table, *, time_format: str, epoch, reference: Reference,
           alt: np.ndarray | None, vel: tuple[np.ndarray, np.ndarray, np.ndarray],
           extra: dict[str, np.ndarray], layout: str = "") -> tuple[Reports, ReadReport]:
    c = table.columns
    t, ep = relative_times(c["time"], time_format, epoch)
    lat, lon = c["lat"], c["lon"]
    lines = table.lines
    n = len(t)
    if alt is None:
        alt = np.zeros(n)
    # rows are in file order here: count those earlier than something above them
    out_of_order = int(np.sum(t[1:] < np.maximum.accumulate(t)[:-1])) if n > 1 else 0
    ids, code = _codes(c["id"])
    # exact duplicates: same object, time and position; the first in the file is kept
    o = np.lexsort((lines, alt, lon, lat, code, t))
    dup_sorted = np.zeros(n, dtype=bool)
    if n > 1:
        dup_sorted[1:] = ((code[o][1:] == code[o][:-1]) & _same(t[o]) & _same(lat[o])
                          & _same(lon[o]) & _same(alt[o]))
    keep = np.ones(n, dtype=bool)
    keep[o[dup_sorted]] = False
    duplicates = int(n - keep.sum())
    frame = as_frame(reference, lat[keep], lon[keep])
    order = np.flatnonzero(keep)
    order = order[np.lexsort((lines[order], t[order]))]
    x, y, z = frame.to_enu(lat[order], lon[order], np.nan_to_num(alt[order], nan=0.0))
    used = np.unique(code[order])
    remap = np.full(len(ids), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    reports = Reports(
        time=t[order], code=remap[code[order]], ids=ids[used], x=x, y=y, z=z,
        vx=vel[0][order], vy=vel[1][order], vz=vel[2][order], line=lines[order], frame=frame,
        epoch=ep, source=table.path, extra={k: v[order] for k, v in extra.items()})
    report = ReadReport(
        path=table.path, rows_read=table.rows_read, rows_kept=len(order),
        skipped=dict(table.skipped), bad=tuple(table.bad), skipped_lines=table.skipped_lines,
        out_of_order=out_of_order, duplicates=duplicates, not_given=dict(table.not_given),
        epoch=ep, set_missing=table.set_missing, layout=layout)
    return reports, report
