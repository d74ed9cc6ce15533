"""A virtual radar over recorded traffic: the plots a radar at a given site would have made of
the objects in an AIS or ADS-B recording, and the truth to score a tracker against.

    vr = VirtualRadar(site=(0.0, 0.0), period=3.0, sigma_range=20.0,
                      sigma_bearing=np.deg2rad(0.5), pd=0.9, clutter=10.0, max_range=40e3)
    run = virtual_radar(reports, vr, seed=1)
    run.scans        # Scans of [range (m), bearing (rad, nautical)] plots, sensor 0
    run.origin       # the object code (index into reports.ids) of each plot, -1 for clutter
    run.truth        # Frames: per scan, the interpolated reported positions of the objects
                     # the radar could see (in range), ids = object codes
    run.sensor       # the RangeBearing model of the plots (site and sigmas), for a tracker

The truth is the reported positions, not the objects' true positions: AIS and ADS-B positions
carry their own errors (GNSS, a few metres to tens of metres; AIS positions can also be late
or from a misplaced antenna, tens of metres on a large ship), so a GOSPA against them has a
floor of that size, and the radar plots are made from them too (a real radar would see the
hull, not the GNSS antenna). The radar is 2-D: range is the horizontal distance in the local
frame (an aircraft's altitude and the radar horizon are ignored), and every plot of a scan
carries the scan's time (a rotating radar would see each bearing a little later).

Scans. At ``start + k period`` for k = 0, 1, ... while the time is at most the last report
(``start`` defaults to the first report's time; ``until`` and ``max_scans`` cut it short).

Where an object is. At a scan time t, an object's position is interpolated linearly between
its two reports around t, ``p = p_j + (t - t_j) / (t_{j+1} - t_j) (p_{j+1} - p_j)`` with
``t_j <= t < t_{j+1}`` (exactly ``p_j`` at a report's time). Only within its reporting
interval ``[first report, last report]`` (an object with a single report is seen only by a
scan at exactly its time), and
not across a gap between consecutive reports longer than ``max_gap`` (default three scan
periods or 120 s, whichever is longer: AIS class A reports every 2-10 s under way and class
B every 30 s, but messages are lost, and the Solent recording has many 40-120 s gaps of
vessels under way whose reports either side lie on a straight line to tens of metres; a
radar would have seen them throughout), unless the object moved less than
``still_distance`` over a gap of at most ``still_gap``: a vessel at anchor reports every
three minutes (ITU-R M.1371), and staying put it is interpolated exactly. The object is
*in range* if ``min_range <= |p - site| <= max_range``; the truth of a scan is every object
in range there, detected or not.

Plots. An object in range is detected with probability ``pd``; its plot is
``[r + sigma_range e0, wrap(b + sigma_bearing e1)]`` (r, b the range and nautical bearing of
p from the site, e standard normal). Clutter: ``N ~ Poisson(clutter)`` false plots per
scan, uniform in range on ``[min_range, max_range]`` and in bearing on ``[-pi, pi)`` (the
spatial density the tracker needs is ``clutter_density = clutter / ((max_range - min_range)
2 pi)`` per metre radian, as ``sim.scene.Radar.clutter_density``). Within a scan the
plots are in bearing order, as a rotating radar delivers them.

Determinism. Scan k draws from its own stream, ``run_rng(seed, k)`` (``sim.streams``), in
this order: its clutter count, the detection uniforms ``(P_k,)`` of its P_k objects in range
(by object code) with its clutter uniforms ``(C_k, 2)`` in one block, and the measurement noise
``(P_k, 2)``. So scan k's plots depend on the seed, k and the reports alone: the first N scans
are the same plots whatever ``until`` or ``max_scans`` (a short trial is the start of the full
run), and the same reports, radar and seed give the same plots, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.eval.track_metrics import Frames
from trackkit.io.records import Reports
from trackkit.io.scans import Scans
from trackkit.models.sensors import RangeBearing
from trackkit.sim.streams import run_rng

__all__ = ["VirtualRadar", "VirtualRadarRun", "interpolate_positions", "scan_times",
           "virtual_radar"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: the shortest default ``max_gap`` (s): lost AIS messages leave gaps of a minute or two in
#: the track of a vessel under way (module doc)
DEFAULT_MIN_GAP = 120.0


def _positive(value: float, name: str, allow_zero: bool = False) -> float:
    v = float(value)
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        want = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"VirtualRadar.{name} = {value!r}; expected a finite number {want}")
    return v


@dataclass(frozen=True)
class VirtualRadar:
    """A 2-D rotating radar: ``site`` (x east, y north in the reports' frame, m), scan
    ``period`` (s), noise ``sigma_range`` (m) and ``sigma_bearing`` (rad), detection
    probability ``pd``, ``clutter`` false plots per scan (Poisson mean), instrumented range
    ``[min_range, max_range]`` (m); ``max_gap`` (s, default the longer of 3 periods and
    120 s), ``still_distance``
    (m) and ``still_gap`` (s) decide which gaps between reports are bridged (module doc)."""

    site: tuple[float, float] = (0.0, 0.0)
    period: float = 3.0
    sigma_range: float = 20.0
    sigma_bearing: float = math.radians(0.5)
    pd: float = 0.9
    clutter: float = 10.0
    max_range: float = 40e3
    min_range: float = 50.0
    max_gap: float | None = None
    still_distance: float = 50.0
    still_gap: float = 600.0

    def __post_init__(self) -> None:
        site = np.asarray(self.site, dtype=float)
        if site.shape != (2,) or not np.all(np.isfinite(site)):
            raise ValueError(f"VirtualRadar.site = {self.site!r}; expected finite (x, y) in "
                             "metres of the reports' frame")
        object.__setattr__(self, "site", (float(site[0]), float(site[1])))
        for name in ("period", "sigma_range", "sigma_bearing", "max_range"):
            object.__setattr__(self, name, _positive(getattr(self, name), name))
        for name in ("clutter", "min_range", "still_distance", "still_gap"):
            object.__setattr__(self, name, _positive(getattr(self, name), name, True))
        pd = float(self.pd)
        if not 0.0 < pd <= 1.0:
            raise ValueError(f"VirtualRadar.pd = {self.pd!r}; expected a detection probability "
                             "in (0, 1]")
        object.__setattr__(self, "pd", pd)
        if self.min_range >= self.max_range:
            raise ValueError(f"VirtualRadar.min_range = {self.min_range!r} >= max_range = "
                             f"{self.max_range!r}; expected min_range < max_range (m)")
        if self.max_gap is not None:
            object.__setattr__(self, "max_gap", _positive(self.max_gap, "max_gap"))

    @property
    def gap(self) -> float:
        """The longest gap between reports bridged for a moving object (s)."""
        if self.max_gap is None:
            return max(3.0 * self.period, DEFAULT_MIN_GAP)
        return float(self.max_gap)

    @property
    def sensor(self) -> RangeBearing:
        """The measurement model of the plots (nautical bearings from the site)."""
        return RangeBearing(origin=self.site, sigma_range=self.sigma_range,
                            sigma_bearing=self.sigma_bearing)

    @property
    def volume(self) -> float:
        """The measurement space the clutter fills: ``(max_range - min_range) 2 pi`` (m rad)."""
        return (self.max_range - self.min_range) * 2.0 * math.pi

    @property
    def clutter_density(self) -> float:
        """False plots per metre radian per scan, ``clutter / volume``."""
        return self.clutter / self.volume


@dataclass(frozen=True, eq=False)
class VirtualRadarRun:
    """What :func:`virtual_radar` made: ``scans`` (range-bearing plots, sensor 0), ``origin
    (N,)`` each plot's object code or -1 for clutter, ``truth`` (per scan the objects in
    range: positions ``(M, 2)``, ids the object codes), ``truth_velocity (M, 2)`` (the
    velocity of the interpolation segment, m/s), the ``radar`` and the ``ids`` of the
    objects (``reports.ids``: ``ids[code]`` is an MMSI or icao24)."""

    scans: Scans
    origin: IntArray
    truth: Frames
    truth_velocity: Array
    radar: VirtualRadar
    ids: NDArray[np.str_]

    @property
    def sensor(self) -> RangeBearing:
        return self.radar.sensor

    @property
    def clutter_density(self) -> float:
        return self.radar.clutter_density

    @property
    def objects_seen(self) -> int:
        """Distinct objects in range at some scan."""
        return int(np.unique(self.truth.ids).size) if self.truth.ids is not None else 0


def scan_times(first: float, last: float, period: float, *, start: float | None = None,
               until: float | None = None, max_scans: int | None = None) -> Array:
    """``start + k period`` (start default ``first``) while ``<= min(last, until)``, at most
    ``max_scans`` of them (to a relative 1e-9 of the period, so an end on the grid is
    included)."""
    t0 = float(first if start is None else start)
    end = float(last if until is None else min(last, until))
    if end < t0:
        return np.empty(0)
    k = math.floor((end - t0) / period + 1e-9) + 1
    if max_scans is not None:
        k = min(k, int(max_scans))
    return t0 + period * np.arange(k, dtype=float)


def interpolate_positions(time: ArrayLike, code: ArrayLike, x: ArrayLike, y: ArrayLike,
                          times: ArrayLike, n_objects: int, *, max_gap: float,
                          still_distance: float = 0.0, still_gap: float = 0.0
                          ) -> tuple[IntArray, IntArray, Array, Array]:
    """Every object's position at every query time inside its reporting interval.

    ``time, code, x, y (R,)`` are reports (any order; ``code`` in ``[0, n_objects)``),
    ``times (S,)`` non-decreasing query times. Returns ``(scan, obj, p, v)``: the pairs
    (query index, object code) where the object's position is known, sorted by scan then
    object, its interpolated position ``p (P, 2)`` and the segment's velocity ``v (P, 2)``
    (0 at an object's last report). A pair inside a gap longer than ``max_gap`` is left out,
    unless the object moved at most ``still_distance`` over a gap of at most ``still_gap``.
    All array operations: the segment of every pair is found by one merge sort of the
    reports and the queries.
    """
    t = np.asarray(time, dtype=float)
    c = np.asarray(code, dtype=np.int64)
    px, py = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    T = np.asarray(times, dtype=float)
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2)))
    if t.size == 0 or T.size == 0:
        return empty
    o = np.lexsort((t, c))  # reports by object, then time
    t, c, px, py = t[o], c[o], px[o], py[o]
    count = np.bincount(c, minlength=n_objects)
    start = np.concatenate([[0], np.cumsum(count)])[:-1]
    first = np.full(n_objects, np.inf)
    last = np.full(n_objects, -np.inf)
    has = count > 0
    first[has] = t[start[has]]
    last[has] = t[start[has] + count[has] - 1]
    # the scans inside each object's interval: a contiguous run [a_k, b_k) of the queries
    a = np.searchsorted(T, first, side="left")
    b = np.searchsorted(T, last, side="right")
    n_q = np.where(has, np.maximum(b - a, 0), 0)
    obj = np.repeat(np.arange(n_objects), n_q)
    if obj.size == 0:
        return empty
    scan = a[obj] + np.arange(obj.size) - np.repeat(np.cumsum(n_q) - n_q, n_q)
    tq = T[scan]
    # merge: reports before queries at equal (object, time), so counting the reports before a
    # query gives j with t_j <= t < t_{j+1} (searchsorted side="right" within the object)
    key_c = np.concatenate([c, obj])
    key_t = np.concatenate([t, tq])
    is_q = np.concatenate([np.zeros(t.size, bool), np.ones(obj.size, bool)])
    m = np.lexsort((is_q, key_t, key_c))
    reports_before = np.cumsum(~is_q[m]) - 1  # global index of the last report at or before
    j = np.zeros(obj.size, np.int64)
    qpos = np.flatnonzero(is_q[m])
    j[m[qpos] - t.size] = reports_before[qpos]
    end_of = start + count - 1
    nxt = np.minimum(j + 1, end_of[obj])
    dt = t[nxt] - t[j]
    at_report = (tq == t[j]) | (nxt == j)
    w = np.where(dt > 0, (tq - t[j]) / np.where(dt > 0, dt, 1.0), 0.0)
    dx, dy = px[nxt] - px[j], py[nxt] - py[j]
    p = np.stack([px[j] + w * dx, py[j] + w * dy], axis=-1)
    v = np.where(dt[:, None] > 0, np.stack([dx, dy], -1) / np.where(dt > 0, dt, 1.0)[:, None],
                 0.0)
    bridged = (dt <= max_gap) | ((np.hypot(dx, dy) <= still_distance) & (dt <= still_gap))
    keep = at_report | bridged
    # sorted by scan then object (obj is already in object order, scans ascending within it)
    order = np.lexsort((obj[keep], scan[keep]))
    return (scan[keep][order].astype(np.int64), obj[keep][order].astype(np.int64),
            p[keep][order], v[keep][order])


def _draws(seed: int, offsets: IntArray, clutter: float
           ) -> tuple[Array, Array, IntArray, Array]:
    """The random numbers of every scan, scan k from ``run_rng(seed, k)`` alone (module doc):
    detection uniforms ``(P,)`` and noise ``(P, 2)`` of the pairs in range (scan k's are rows
    ``offsets[k]:offsets[k+1]``), clutter counts ``(S,)`` and clutter uniforms ``(C, 2)``."""
    S = offsets.size - 1
    P = int(offsets[-1])
    u = np.empty(P)
    e = np.empty((P, 2))
    counts = np.empty(S, np.int64)
    uc = []
    for k in range(S):
        a, b = int(offsets[k]), int(offsets[k + 1])
        g = run_rng(seed, k)
        n = int(g.poisson(clutter))
        block = g.random(b - a + 2 * n)
        u[a:b] = block[:b - a]
        uc.append(block[b - a:])
        e[a:b] = g.standard_normal((b - a, 2))
        counts[k] = n
    return u, e, counts, np.concatenate(uc).reshape(-1, 2)


def virtual_radar(reports: Reports, radar: VirtualRadar, seed: int = 0, *,
                  start: float | None = None, until: float | None = None,
                  max_scans: int | None = None) -> VirtualRadarRun:
    """The plots ``radar`` would make of the objects in ``reports``, and the truth (see the
    module docstring). ``start``, ``until`` (s, in the reports' time) and ``max_scans`` limit
    the scans."""
    if not isinstance(reports, Reports):
        raise ValueError(f"reports is a {type(reports).__name__}; expected trackkit.io.Reports")
    if not isinstance(radar, VirtualRadar):
        raise ValueError(f"radar is a {type(radar).__name__}; expected a VirtualRadar")
    if max_scans is not None and int(max_scans) < 1:
        raise ValueError(f"max_scans = {max_scans!r}; expected at least 1")
    if len(reports) == 0:
        raise ValueError(f"{reports.source or 'reports'}: no reports to make radar plots of")
    times = scan_times(float(reports.time[0]), float(reports.time[-1]), radar.period,
                       start=start, until=until, max_scans=max_scans)
    if times.size == 0:
        raise ValueError(f"{reports.source or 'reports'}: no scan between start = {start!r} "
                         f"and until = {until!r} (the reports span {reports.time[0]:g} to "
                         f"{reports.time[-1]:g} s)")
    S = times.size
    scan, obj, p, v = interpolate_positions(
        reports.time, reports.code, reports.x, reports.y, times, len(reports.ids),
        max_gap=radar.gap, still_distance=radar.still_distance, still_gap=radar.still_gap)
    site = np.asarray(radar.site)
    d = p - site
    rng_true = np.hypot(d[:, 0], d[:, 1])
    inside = (rng_true >= radar.min_range) & (rng_true <= radar.max_range)
    scan, obj, p, v, d, rng_true = (a[inside] for a in (scan, obj, p, v, d, rng_true))
    brg_true = np.arctan2(d[:, 0], d[:, 1])  # nautical: clockwise from north

    t_off = np.concatenate([[0], np.cumsum(np.bincount(scan, minlength=S))]).astype(np.int64)
    u, e, counts, uc = _draws(seed, t_off, radar.clutter)
    det = u < radar.pd
    zt = np.stack([rng_true + radar.sigma_range * e[:, 0],
                   wrap(brg_true + radar.sigma_bearing * e[:, 1])], axis=-1)[det]
    zc = np.stack([radar.min_range + uc[:, 0] * (radar.max_range - radar.min_range),
                   wrap(-np.pi + uc[:, 1] * 2.0 * np.pi)], axis=-1)
    scan_of = np.concatenate([scan[det], np.repeat(np.arange(S), counts)])
    z = np.concatenate([zt, zc]).reshape(-1, 2)
    origin = np.concatenate([obj[det], np.full(zc.shape[0], -1, np.int64)])
    order = np.lexsort((origin, z[:, 1], scan_of))  # bearing order within a scan
    z, origin, scan_of = z[order], origin[order], scan_of[order]
    offsets = np.concatenate([[0], np.cumsum(np.bincount(scan_of, minlength=S))])
    scans = Scans(z, offsets.astype(np.int64), times, np.zeros(S, np.int64))

    truth = Frames(t_off, p, obj)
    return VirtualRadarRun(scans, origin.astype(np.int64), truth, v, radar, reports.ids)
