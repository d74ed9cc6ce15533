"""Scans: the detections a sensor delivers in one sweep, stored flat for a whole sequence.

A scan is a set of k detections ``(k, m)`` taken at one time by one sensor. A sequence of S
scans with N detections in all is stored as four arrays (CSR layout):

* ``z (N, m)``: every detection, scan after scan;
* ``offsets (S + 1,)``: scan s holds ``z[offsets[s]:offsets[s + 1]]`` (an empty scan, a sweep
  in which nothing was detected, is ``offsets[s] == offsets[s + 1]``; it still matters, as it
  is a missed detection for every live track);
* ``times (S,)``: non-decreasing (two sensors may sweep at the same time);
* ``sensor (S,)``: the sensor id (a non-negative integer) of each scan.

Time and sensor are per scan, not per detection: a scan is one sensor's sweep by definition,
so a per-detection sensor column could only repeat the scan's value (or describe a mixed set
that the tracker would have to split again). ``scan_index`` gives the per-detection view
when a flat table is wanted.

On disk: Parquet holds one row per scan (``time``, ``sensor``, ``z`` as a list of
fixed-size lists), so empty scans survive and floats are binary-exact; CSV holds one row per
detection (``scan,time,sensor,z0..z{m-1}``), an empty scan as one row with the z fields
blank, floats written with ``repr`` (shortest round-tripping decimal), so both round-trip
exactly.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Scan", "Scans"]

Array = NDArray[np.float64]


class Scan(NamedTuple):
    """One scan: its ``time``, ``sensor`` id and detections ``z (k, m)`` (a view)."""

    time: float
    sensor: int
    z: Array


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Scans:
    """A sequence of scans in CSR layout (see the module docstring); validated on creation.

    Iterating gives one :class:`Scan` at a time, its ``z`` a read-only view into the flat
    array; ``scans[s]`` is scan s.
    """

    z: Array
    offsets: NDArray[np.int64]
    times: Array
    sensor: NDArray[np.int64]

    def __post_init__(self) -> None:
        z = np.array(self.z, dtype=float, copy=True)
        if z.ndim != 2 or z.shape[1] < 1:
            raise ValueError(f"Scans.z has shape {z.shape}; expected (N, m) with m >= 1")
        if not np.all(np.isfinite(z)):
            bad = np.argwhere(~np.isfinite(z))[0]
            raise ValueError(
                f"Scans.z has non-finite entries (first at row {bad[0]}, column {bad[1]}); "
                "expected finite detections (a missed scan is an empty scan, not nan)"
            )
        times = np.array(self.times, dtype=float, copy=True)
        if times.ndim != 1:
            raise ValueError(f"Scans.times has shape {times.shape}; expected (S,)")
        S = times.shape[0]
        if not np.all(np.isfinite(times)):
            raise ValueError("Scans.times has non-finite entries; expected finite seconds")
        if S > 1 and not np.all(np.diff(times) >= 0):
            i = int(np.argmax(~(np.diff(times) >= 0)))
            raise ValueError(
                f"Scans.times is not sorted: times[{i + 1}] = {times[i + 1]!r} < "
                f"times[{i}] = {times[i]!r}; expected non-decreasing times"
            )
        offsets = _integers(self.offsets, "offsets", (S + 1,))
        if offsets[0] != 0 or offsets[-1] != z.shape[0] or np.any(np.diff(offsets) < 0):
            raise ValueError(
                f"Scans.offsets = {offsets.tolist() if S < 20 else '...'} is not a valid "
                f"partition of the {z.shape[0]} detections; expected 0 = offsets[0] <= ... "
                f"<= offsets[S] = N"
            )
        sensor = _integers(self.sensor, "sensor", (S,))
        if np.any(sensor < 0):
            raise ValueError("Scans.sensor has negative ids; expected integers >= 0")
        for name, a in (("z", z), ("offsets", offsets), ("times", times), ("sensor", sensor)):
            object.__setattr__(self, name, _readonly(a))

    # -- construction ------------------------------------------------------------------------

    @classmethod
    def from_scans(cls, scans: Iterable[tuple[float, int, ArrayLike]], dim_z: int | None = None
                   ) -> Scans:
        """Build from ``(time, sensor, z_k)`` triples, ``z_k`` of shape ``(k, m)``
        (``dim_z`` is needed only when every scan is empty)."""
        scans = list(scans)
        zs = [np.asarray(s[2], dtype=float) for s in scans]
        if dim_z is None:
            shapes = [z.shape[-1] for z in zs if z.ndim == 2 and z.shape[0] > 0]
            if not shapes:
                raise ValueError("Scans.z: every scan is empty; pass dim_z")
            dim_z = shapes[0]
        for i, z in enumerate(zs):
            if z.size == 0:
                zs[i] = np.empty((0, dim_z))
            elif z.ndim != 2 or z.shape[1] != dim_z:
                raise ValueError(f"Scans.z: scan {i} has shape {z.shape}; expected (k, {dim_z})")
        counts = np.array([z.shape[0] for z in zs], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        z = np.concatenate(zs) if zs else np.empty((0, dim_z))
        return cls(z, offsets, [float(s[0]) for s in scans], [int(s[1]) for s in scans])

    # -- access ------------------------------------------------------------------------------

    @property
    def dim_z(self) -> int:
        return int(self.z.shape[1])

    @property
    def counts(self) -> NDArray[np.int64]:
        """Detections per scan, ``(S,)``."""
        return np.diff(self.offsets)

    @property
    def scan_index(self) -> NDArray[np.int64]:
        """The scan of every detection, ``(N,)``."""
        return np.repeat(np.arange(len(self), dtype=np.int64), self.counts)

    def __len__(self) -> int:
        return int(self.times.shape[0])

    def __getitem__(self, s: int) -> Scan:
        S = len(self)
        s = int(s)
        if not -S <= s < S:
            raise IndexError(f"scan {s} out of range for {S} scans")
        s %= S
        return Scan(float(self.times[s]), int(self.sensor[s]),
                    self.z[self.offsets[s]:self.offsets[s + 1]])

    def __iter__(self) -> Iterator[Scan]:
        z, o, t, c = self.z, self.offsets.tolist(), self.times.tolist(), self.sensor.tolist()
        for s in range(len(t)):
            yield Scan(t[s], c[s], z[o[s]:o[s + 1]])

    def __repr__(self) -> str:
        return f"Scans({len(self)} scans, {self.z.shape[0]} detections, dim_z={self.dim_z})"

    def equals(self, other: Scans) -> bool:
        """Exact (bitwise on floats) equality of the four arrays."""
        return all(
            a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
            for a, b in zip((self.z, self.offsets, self.times, self.sensor),
                            (other.z, other.offsets, other.times, other.sensor), strict=True)
        )

    # -- Parquet -----------------------------------------------------------------------------

    def to_parquet(self, path: str | os.PathLike) -> None:
        """One row per scan: ``time`` (float64), ``sensor`` (int64), ``z`` (list of
        fixed-size lists of m float64); m is also in the schema metadata (for all-empty
        sequences)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        m = self.dim_z
        inner = pa.FixedSizeListArray.from_arrays(pa.array(self.z.ravel()), m)
        z = pa.ListArray.from_arrays(pa.array(self.offsets.astype(np.int32)), inner)
        table = pa.table({"time": pa.array(self.times), "sensor": pa.array(self.sensor), "z": z})
        table = table.replace_schema_metadata({b"trackkit.scans.dim_z": str(m).encode()})
        pq.write_table(table, path)

    @classmethod
    def read_parquet(cls, path: str | os.PathLike) -> Scans:
        """Read a file written by :meth:`to_parquet` (validated like any Scans)."""
        import pyarrow as pa
        import pyarrow.compute as pc
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        for name in ("time", "sensor", "z"):
            if name not in table.column_names:
                raise ValueError(f"{path}: no column {name!r}; expected time, sensor, z")
        meta = table.schema.metadata or {}
        z_col = table.column("z").combine_chunks()
        if b"trackkit.scans.dim_z" in meta:
            m = int(meta[b"trackkit.scans.dim_z"])
        elif isinstance(z_col.type.value_type, pa.FixedSizeListType):
            m = z_col.type.value_type.list_size
        else:
            raise ValueError(f"{path}: column 'z' is not a list of fixed-size lists")
        counts = pc.list_value_length(z_col).fill_null(0).to_numpy(zero_copy_only=False)
        flat = z_col.flatten().flatten().to_numpy(zero_copy_only=False)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return cls(np.asarray(flat, dtype=float).reshape(-1, m), offsets,
                   table.column("time").to_numpy(), table.column("sensor").to_numpy())

    # -- CSV ---------------------------------------------------------------------------------

    def to_csv(self, path: str | os.PathLike) -> None:
        """One row per detection, ``scan,time,sensor,z0,...``; an empty scan is one row with
        the z fields blank. Floats are written with ``repr`` so that they read back exactly."""
        m = self.dim_z
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(["scan", "time", "sensor"] + [f"z{i}" for i in range(m)])
            zl = self.z.tolist()
            o = self.offsets.tolist()
            for s, (t, c) in enumerate(zip(self.times.tolist(), self.sensor.tolist(),
                                           strict=True)):
                head = [s, repr(t), c]
                if o[s] == o[s + 1]:
                    w.writerow(head + [""] * m)
                for row in zl[o[s]:o[s + 1]]:
                    w.writerow(head + [repr(v) for v in row])

    @classmethod
    def read_csv(cls, path: str | os.PathLike) -> Scans:
        """Read a file written by :meth:`to_csv`. A bad record stops the read with the file,
        line and column; scans must appear in order 0, 1, 2, ... with one time and sensor
        each."""
        with open(path, newline="") as fh:
            rows = csv.reader(fh)
            header = next(rows, None)
            if header is None or header[:3] != ["scan", "time", "sensor"] or len(header) < 4:
                raise ValueError(f"{path}, line 1: header {header!r}; expected "
                                 "scan,time,sensor,z0,...")
            m = len(header) - 3
            times: list[float] = []
            sensors: list[int] = []
            counts: list[int] = []
            z: list[list[float]] = []
            for line, row in enumerate(rows, start=2):
                if len(row) != m + 3:
                    raise ValueError(f"{path}, line {line}: {len(row)} fields; expected {m + 3}")
                try:
                    s, t, c = int(row[0]), float(row[1]), int(row[2])
                except ValueError as e:
                    raise ValueError(f"{path}, line {line}: {e}") from None
                if s == len(times):  # a new scan
                    times.append(t)
                    sensors.append(c)
                    counts.append(0)
                elif s != len(times) - 1 or t != times[-1] or c != sensors[-1]:
                    raise ValueError(
                        f"{path}, line {line}, column scan: scan {s} at time {t!r} sensor {c} "
                        f"does not continue scan {len(times) - 1} or start scan {len(times)}")
                if all(f == "" for f in row[3:]):
                    if counts[-1]:
                        raise ValueError(f"{path}, line {line}: blank detection in a "
                                         "non-empty scan")
                    counts[-1] = -1  # marks an empty scan; a detection may not follow
                    continue
                if counts[-1] < 0:
                    raise ValueError(f"{path}, line {line}: detection after an empty-scan row")
                vals = []
                for k, f in enumerate(row[3:]):
                    try:
                        vals.append(float(f))
                    except ValueError:
                        raise ValueError(f"{path}, line {line}, column {header[3 + k]}: "
                                         f"{f!r} is not a number") from None
                z.append(vals)
                counts[-1] += 1
        c = np.maximum(np.asarray(counts, dtype=np.int64), 0)
        offsets = np.concatenate([[0], np.cumsum(c)]).astype(np.int64)
        return cls(np.asarray(z, dtype=float).reshape(-1, m), offsets, times, sensors)


def _integers(a: ArrayLike, name: str, shape: tuple[int, ...]) -> NDArray[np.int64]:
    arr = np.asarray(a)
    if arr.shape != shape:
        raise ValueError(f"Scans.{name} has shape {arr.shape}; expected {shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        if not (np.all(np.isfinite(arr)) and np.array_equal(arr, np.round(arr))):
            raise ValueError(f"Scans.{name} has non-integer entries; expected integers")
    return np.array(arr, dtype=np.int64, copy=True)
