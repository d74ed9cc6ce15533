"""GPS/INS records to the manoeuvring-model identifier's inputs: local positions, heading and
the body-frame measurement ``y = [u, v, r]`` on a uniform time grid; and the measured inputs
(nozzle angle, engine speed).

    log, report = read_nmea("trial.nmea")
    m = preprocess(log, dt=1.0)             # m.t, m.east, m.north, m.psi, m.u, m.v, m.r
    inputs, _ = read_inputs_csv("inputs.csv", epoch=log.epoch)
    nozzle, n = inputs_on_grid(inputs, m.t)

The steps (Zolfagharnasab and Seif 2025 leave them open):

1. latitude and longitude to east, north (m) in an :class:`~trackkit.io.frames.EnuFrame`
   (default at the median position, as the other readers);
2. the GPS velocity over ground, SOG and COG, to east and north components
   (:func:`~trackkit.io.frames.velocity_from_course`; a zero speed with no course is at rest);
3. the INS heading (unwrapped) and the gyro's yaw rate, linearly interpolated to the GPS
   velocity times;
4. the velocity rotated into the body frame with that heading (:func:`to_body`):
   ``u = ve sin psi + vn cos psi``, ``v = ve cos psi - vn sin psi`` (the inverse of
   ``east' = u sin psi + v cos psi``, ``north' = u cos psi - v sin psi``; v positive to
   starboard);
5. resampling onto ``t_k = start + k dt`` by linear interpolation: positions from the fixes,
   psi, u, v, r from their values at the velocity times. Linear, not smoothed: a grid time
   that falls on a sample gets the sample itself, so the noise the identifier's R must
   describe is the sensors' own (the EKF does the filtering).

``start`` defaults to the first multiple of dt from the epoch at which every stream has begun,
the grid ends where the first stream ends. A grid time between two samples of a stream that
are more than ``max_gap`` apart (default 2.5 times the stream's median interval) is a gap:
the quantities from that stream are nan there, ``gap`` marks the grid point and ``gaps``
names every such interval of the input. Everything is batched over leading run axes
(:func:`preprocess_sim`, where the sensor times are shared by the runs).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.io import _reports
from trackkit.io._table import TIME_FORMATS, Field, csv_header, read_csv_table
from trackkit.io.frames import EnuFrame, velocity_from_course
from trackkit.io.nmea import NavLog, epoch_ns
from trackkit.io.records import ReadReport
from trackkit.renamed import renamed_keywords

if TYPE_CHECKING:
    from trackkit.io.records import GpsFixes, InsSamples

__all__ = [
    "INPUT_COLUMNS",
    "BodyMeasurements",
    "Gap",
    "MeasuredInputs",
    "inputs_on_grid",
    "interpolate",
    "preprocess",
    "preprocess_sim",
    "read_inputs_csv",
    "to_body",
]

Array = NDArray[np.float64]

#: The measured-inputs CSV columns: time, nozzle angle (deg), engine speed (rpm).
INPUT_COLUMNS = ("time", "nozzle_deg", "rpm")


class Gap(NamedTuple):
    """An interval of a stream (``"position"``, ``"velocity"``, ``"heading"``, ``"rate"``)
    with no sample for longer than the allowed gap, in s from the epoch."""

    stream: str
    start: float
    end: float


class BodyMeasurements(NamedTuple):
    """The identifier's measurements on a uniform grid: ``t`` ``(N,)`` s; ``east``,
    ``north`` ``(..., N)`` m in ``frame``; ``psi`` heading, rad clockwise from north,
    continuous (unwrapped, starting in [0, 2 pi)); ``u`` surge and ``v`` sway (positive to
    starboard) m/s; ``r`` yaw rate rad/s, positive clockwise. ``gap`` ``(N,)`` marks grid
    points where some quantity is nan (in some run); ``gaps`` lists the input's gaps; ``dt``
    is the grid period (s)."""

    t: Array
    east: Array
    north: Array
    psi: Array
    u: Array
    v: Array
    r: Array
    gap: NDArray[np.bool_]
    gaps: tuple[Gap, ...]
    frame: EnuFrame
    dt: float


def to_body(ve: ArrayLike, vn: ArrayLike, psi: ArrayLike) -> tuple[Array, Array]:
    """East and north velocity (m/s) to surge and sway ``(u, v)`` at heading ``psi`` (rad
    clockwise from north; v positive to starboard): a rotation, so the speed is kept."""
    ve, vn, psi = (np.asarray(x, dtype=float) for x in (ve, vn, psi))
    s, c = np.sin(psi), np.cos(psi)
    return ve * s + vn * c, ve * c - vn * s


def interpolate(tq: ArrayLike, t: ArrayLike, y: ArrayLike, max_gap: float = np.inf
                ) -> tuple[Array, NDArray[np.bool_]]:
    """Linear interpolation of ``y`` ``(..., n)`` at times ``t`` ``(n,)`` (increasing) to
    ``tq`` ``(m,)``, batched over the leading axes. Returns ``(values (..., m), missing
    (m,))``: nan and missing outside ``[t[0], t[-1]]`` and inside an interval longer than
    ``max_gap``; a query on a sample time takes the sample itself, whatever its neighbours."""
    tq = np.asarray(tq, dtype=float)
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    n = t.shape[0]
    out_shape = y.shape[:-1] + tq.shape
    if n == 0:
        return np.full(out_shape, np.nan), np.ones(tq.shape, dtype=bool)
    if n == 1:
        hit = tq == t[0]
        return np.where(hit, y[..., :1], np.nan), ~hit
    i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, n - 2)
    dt = t[i + 1] - t[i]
    w = (tq - t[i]) / dt
    y0, y1 = y[..., i], y[..., i + 1]
    # select, not blend, on a sample: 0 * nan would spoil a good sample beside a nan
    val = np.where(w == 0, y0, np.where(w == 1, y1, (1.0 - w) * y0 + w * y1))
    missing = (tq < t[0]) | (tq > t[-1]) | ((w > 0) & (w < 1) & (dt > max_gap))
    return np.where(missing, np.nan, val), missing


def _stream_gap(name: str, t: Array, max_gap: float | None) -> float:
    if max_gap is not None:
        return max_gap
    if t.shape[0] < 2:
        return np.inf
    return 2.5 * float(np.median(np.diff(t)))


def _check_stream(name: str, what: str, t: Array, *ys: Array) -> None:
    if t.ndim != 1:
        raise ValueError(f"{name} times have shape {t.shape}; expected (n,)")
    if t.shape[0] < 2:
        raise ValueError(f"the {name} stream has {t.shape[0]} samples; expected at least two "
                         f"({what})")
    if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
        raise ValueError(f"{name} times are not finite and strictly increasing")
    for y in ys:
        if y.shape[-1:] != t.shape:
            raise ValueError(f"{name} values have shape {y.shape}; expected (..., "
                             f"{t.shape[0]}), the length of its times")


def _preprocess(t_pos: Array, lat: Array, lon: Array, t_vel: Array, sog: Array, cog: Array,
                t_hdg: Array, heading: Array, t_rate: Array, rate: Array, *, frame: EnuFrame,
                dt: float, max_gap: float | None, rate_source: str, start: float | None,
                end: float | None) -> BodyMeasurements:
    dt = float(dt)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}; expected a positive grid period in seconds")
    if max_gap is not None and not (max_gap > 0):
        raise ValueError(f"max_gap = {max_gap!r}; expected a positive number of seconds or "
                         "None")
    if rate_source not in ("gyro", "heading"):
        raise ValueError(f"rate_source = {rate_source!r}; expected 'gyro' or 'heading'")
    _check_stream("position", "GGA or RMC fixes", t_pos, lat, lon)
    _check_stream("velocity", "RMC or VTG speed and course", t_vel, sog, cog)
    _check_stream("heading", "HDT or THS", t_hdg, heading)
    psi_src = np.unwrap(heading, axis=-1)
    if rate_source == "gyro":
        _check_stream("rate", "ROT; or pass rate_source='heading'", t_rate, rate)
    else:
        # the differenced heading (second-order central differences, one-sided at the ends)
        t_rate, rate = t_hdg, np.gradient(psi_src, t_hdg, axis=-1)
    streams = {"position": t_pos, "velocity": t_vel, "heading": t_hdg, "rate": t_rate}
    gaps_allowed = {k: _stream_gap(k, v, max_gap) for k, v in streams.items()}
    gaps = tuple(Gap(k, float(v[j]), float(v[j + 1])) for k, v in streams.items()
                 for j in np.flatnonzero(np.diff(v) > gaps_allowed[k]))

    cog = np.where((sog == 0) & np.isnan(cog), 0.0, cog)  # at rest, the course is moot
    ve, vn = velocity_from_course(sog, cog, "m/s", "rad")
    psi_v, _ = interpolate(t_vel, t_hdg, psi_src, gaps_allowed["heading"])
    r_v, _ = interpolate(t_vel, t_rate, rate, gaps_allowed["rate"])
    u_v, v_v = to_body(ve, vn, psi_v)
    east, north, _ = frame.to_enu(lat, lon, 0.0)

    first = max(float(v[0]) for v in streams.values())
    last = min(float(v[-1]) for v in streams.values())
    t0 = float(np.ceil(first / dt - 1e-9) * dt) if start is None else float(start)
    t1 = last if end is None else float(end)
    if not t1 >= t0:
        raise ValueError(f"the grid would start at {t0!r} s and end at {t1!r} s; expected the "
                         "position, velocity, heading and rate streams to overlap "
                         f"(they span {first!r} to {last!r} s together)")
    grid = t0 + dt * np.arange(int(np.floor((t1 - t0) / dt + 1e-9)) + 1)
    e_g, _ = interpolate(grid, t_pos, east, gaps_allowed["position"])
    n_g, _ = interpolate(grid, t_pos, north, gaps_allowed["position"])
    g = gaps_allowed["velocity"]
    psi_g, _ = interpolate(grid, t_vel, psi_v, g)
    u_g, _ = interpolate(grid, t_vel, u_v, g)
    v_g, _ = interpolate(grid, t_vel, v_v, g)
    r_g, _ = interpolate(grid, t_vel, r_v, g)
    stack = np.stack([e_g, n_g, psi_g, u_g, v_g, r_g])
    gap = np.isnan(stack).reshape(-1, grid.shape[0]).any(axis=0)
    return BodyMeasurements(grid, e_g, n_g, psi_g, u_g, v_g, r_g, gap, gaps, frame, dt)


@renamed_keywords(T="dt")
def preprocess(log: NavLog, *, dt: float = 1.0, reference: _reports.Reference = None,
               max_gap: float | None = None, rate_source: str = "gyro",
               start: float | None = None, end: float | None = None) -> BodyMeasurements:
    """A recorded log (:func:`~trackkit.io.nmea.read_nmea`,
    :func:`~trackkit.io.nmea.read_nav_csv`) to :class:`BodyMeasurements` (see the module).
    ``reference`` is the ENU origin (an EnuFrame or ``(lat, lon[, alt])``; default the median
    fix); ``rate_source="heading"`` differentiates the heading instead of using the gyro;
    ``start``/``end`` (s from the log's epoch) bound the grid."""
    frame = _reports.as_frame(reference, log.lat, log.lon)
    return _preprocess(log.t_pos, log.lat, log.lon, log.t_vel, log.sog, log.cog,
                       log.t_heading, log.heading, log.t_rate, log.rate, frame=frame, dt=dt,
                       max_gap=max_gap, rate_source=rate_source, start=start, end=end)


@renamed_keywords(T="dt")
def preprocess_sim(gps: GpsFixes, ins: InsSamples, *, dt: float = 1.0,
                   reference: _reports.Reference = None, max_gap: float | None = None,
                   rate_source: str = "gyro", start: float | None = None,
                   end: float | None = None) -> BodyMeasurements:
    """Simulated GPS and INS (:mod:`trackkit.sim.gnss`, batched over runs) to
    :class:`BodyMeasurements`, the same steps without an NMEA round trip. Pass the simulator's
    origin as ``reference`` (``(lat0, lon0)``) to get positions in the truth's frame."""
    if reference is None:
        lat = np.asarray(gps.lat, dtype=float)
        lon = np.asarray(gps.lon, dtype=float)
        frame = _reports.as_frame(None, lat.ravel(), lon.ravel())
    else:
        frame = _reports.as_frame(reference, np.zeros(0), np.zeros(0))
    arr = [np.asarray(x, dtype=float) for x in (gps.t, gps.lat, gps.lon, gps.t, gps.sog,
                                                gps.cog, ins.t, ins.heading, ins.t, ins.rate)]
    return _preprocess(*arr, frame=frame, dt=dt, max_gap=max_gap, rate_source=rate_source,
                       start=start, end=end)


# -- measured inputs ---------------------------------------------------------------------------


class MeasuredInputs(NamedTuple):
    """The model's measured inputs, sorted by time: ``t`` ``(n,)`` s from the epoch;
    ``nozzle`` the waterjet nozzle ("rudder") angle, rad, with the file's sign convention;
    ``engine_speed`` rev/s (Hz; rpm / 60); ``line`` each value's CSV line; ``epoch`` the
    absolute time of t = 0 (None for relative times)."""

    t: Array
    nozzle: Array
    engine_speed: Array
    line: NDArray[np.int64]
    epoch: np.datetime64 | None


def read_inputs_csv(path: str | os.PathLike, on_bad: str = "skip", *,
                    time_format: str = "iso", epoch=None, max_nozzle_deg: float = 45.0,
                    max_rpm: float = 10_000.0, max_listed: int = 100
                    ) -> tuple[MeasuredInputs, ReadReport]:
    """Read ``time, nozzle_deg, rpm`` (all required; other columns are an error). A nozzle
    angle outside ``[-max_nozzle_deg, max_nozzle_deg]`` or an engine speed outside
    ``[0, max_rpm]`` is a bad record (skipped and named, or fatal with ``on_bad="stop"``).
    Records out of time order are sorted (counted); a repeated time keeps its first record
    (the others counted as duplicates). Pass ``epoch=log.epoch`` to share a log's t = 0;
    ``time_format="seconds"`` takes relative times as given."""
    if on_bad not in ("skip", "stop"):
        raise ValueError(f"on_bad = {on_bad!r}; expected 'skip' or 'stop'")
    if time_format not in TIME_FORMATS and "%" not in time_format:
        raise ValueError(f"time_format = {time_format!r}; expected one of "
                         f"{', '.join(map(repr, TIME_FORMATS))} or a strptime pattern")
    for name, value in (("max_nozzle_deg", max_nozzle_deg), ("max_rpm", max_rpm)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} = {value!r}; expected a positive finite number")
    path = os.fspath(path)
    header = csv_header(path)
    unknown = [h for h in header if h not in INPUT_COLUMNS]
    if unknown:
        raise ValueError(f"{path}:1: column {', '.join(map(repr, unknown))} is not known; "
                         f"expected the columns {', '.join(INPUT_COLUMNS)}")
    fields = [Field("time", "time", "time", time_format=time_format),
              Field("nozzle", "nozzle_deg", lo=-max_nozzle_deg, hi=max_nozzle_deg,
                    what="nozzle angle"),
              Field("rpm", "rpm", lo=0.0, hi=max_rpm, what="engine speed")]
    table = read_csv_table(path, fields, on_bad, max_listed=max_listed)
    c = table.columns
    lines = table.lines
    ep_ns = epoch_ns(epoch)
    if time_format == "seconds":
        if ep_ns is not None:
            raise ValueError(f"{path}: epoch given but time_format 'seconds' is relative")
        t_ns = np.round(c["time"] * 1e9).astype(np.int64)
        ep_ns, ep = 0, None
    else:
        t_ns = np.asarray(c["time"], dtype=np.int64)
        if ep_ns is None:
            ep_ns = int(t_ns.min()) if t_ns.size else 0
        ep = np.datetime64(ep_ns, "ns")
    n = len(lines)
    out_of_order = int(np.sum(t_ns[1:] < np.maximum.accumulate(t_ns)[:-1])) if n > 1 else 0
    o = np.lexsort((lines, t_ns))
    first = np.ones(n, dtype=bool)
    first[1:] = t_ns[o][1:] != t_ns[o][:-1]
    o = o[first]
    inputs = MeasuredInputs((t_ns[o] - ep_ns) / 1e9, np.deg2rad(c["nozzle"][o]),
                            c["rpm"][o] / 60.0, lines[o], ep)
    report = ReadReport(path=path, rows_read=table.rows_read, rows_kept=len(o),
                        skipped=dict(table.skipped), bad=tuple(table.bad),
                        skipped_lines=table.skipped_lines, out_of_order=out_of_order,
                        duplicates=n - len(o), not_given=dict(table.not_given), epoch=ep)
    return inputs, report


def inputs_on_grid(inputs: MeasuredInputs, t: ArrayLike) -> tuple[Array, Array]:
    """``(nozzle (rad), engine_speed (rev/s))`` at times ``t`` by linear interpolation; nan
    outside the recorded span."""
    nozzle, _ = interpolate(t, inputs.t, inputs.nozzle)
    speed, _ = interpolate(t, inputs.t, inputs.engine_speed)
    return nozzle, speed
