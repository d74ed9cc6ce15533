"""Manoeuvring-trial metrics and the IMO standards for ship manoeuvrability, batched.

Inputs are trial records sampled at times ``t (K,)``: positions ``east, north`` (m) and
heading ``psi`` (rad, clockwise from north; unwrapped here) of shape ``(..., K)``, the leading
axes being runs. The command is executed at ``t[0]``. Events between samples are found by
linear interpolation, heading extremes by a parabola through the three samples around them.

Turning circle (heading change ``e = side (psi - psi[0])``, side +1 starboard, -1 port):

* advance: distance along the original course from the execute point when e = 90 deg;
* transfer: distance toward the turn, normal to the original course, when e = 90 deg;
* tactical diameter: the same normal distance when e = 180 deg;
* steady diameter: the chord between the positions at e = 360 and 540 deg (opposite points of
  the steady circle), and D/L = steady diameter / L.

Zig-zag delta/alpha (``e = side (psi - psi[0])``, the first command to ``side``):

* initial turning time: from t[0] to e = +alpha (the second command); the distance sailed
  by then is the initial turning distance;
* time to check yaw: from the second command to the first heading extreme;
* first overshoot: that extreme beyond +alpha; second overshoot: the next extreme beyond
  -alpha (after the third command, at e = -alpha);
* period: from the second command to the fourth (e = +alpha again), one full cycle.

IMO resolution MSC.137(76), section 5.3 (L the ship length in m, V the test speed in m/s):
advance <= 4.5 L and tactical diameter <= 5 L; with 10 deg rudder, at most 2.5 L sailed
before a 10 deg heading change; 10/10 first overshoot <= 10 deg if L/V < 10 s, <= 20 deg if
L/V >= 30 s, else (5 + L/V / 2) deg; 10/10 second overshoot <= 25 deg if L/V < 10 s,
<= 40 deg if L/V >= 30 s, else (17.5 + 0.75 L/V) deg; 20/20 first overshoot <= 25 deg.
The standards formally apply to ships of 100 m in length and over (and to chemical and gas
carriers regardless of length); for Zolfagharnasab and Seif's 19.6 m craft they are shown for
reference only.
Beside them, the paper's acceptance band 2 <= D/L <= 7.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "TurningMetrics",
    "ZigZagMetrics",
    "Criterion",
    "turning_metrics",
    "zigzag_metrics",
    "imo_criteria",
    "IMO_NOTE",
]

Array = NDArray[np.float64]

#: The caveat shown with the IMO manoeuvring criteria: they apply to ships of 100 m and over.
IMO_NOTE = ("IMO MSC.137(76) applies to ships of 100 m and over; for a craft this small it is "
            "shown for reference only")


class TurningMetrics(NamedTuple):
    """Turning-circle metrics (m), each of the run shape."""

    advance: Array
    transfer: Array
    tactical_diameter: Array
    steady_diameter: Array
    diameter_to_length: Array  # steady diameter / L


class ZigZagMetrics(NamedTuple):
    """Zig-zag metrics: times in s, angles in rad, distance in m (nan when not reached)."""

    initial_turning_time: Array
    initial_turning_distance: Array
    time_to_check_yaw: Array
    first_overshoot: Array
    second_overshoot: Array
    period: Array


class Criterion(NamedTuple):
    """One check ``lower <= value <= upper`` (SI: m or rad; D/L dimensionless)."""

    name: str
    value: Array
    lower: Array
    upper: Array
    passed: Array
    source: str


def _series(name: str, a: ArrayLike, K: int | None = None) -> Array:
    a = np.asarray(a, dtype=float)
    if a.ndim < 1 or (K is not None and a.shape[-1] != K):
        want = "(..., K)" if K is None else f"(..., {K}) like t"
        raise ValueError(f"{name} has shape {a.shape}; expected {want}")
    return a


def _times(t: ArrayLike) -> Array:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError(f"t has shape {t.shape}; expected at least 3 finite, increasing times")
    return t


def _first(y: Array, level: Array, after: Array | None = None) -> tuple[Array, Array, Array]:
    """First sample ``i`` with ``y[i] >= level`` (only ``i > after``), the fraction ``w`` of
    the way from ``i - 1`` at which y crosses the level, and whether it exists."""
    K = y.shape[-1]
    ok = y >= level[..., None]
    if after is not None:
        ok &= np.arange(K) > after[..., None]
    found = ok.any(-1)
    i = np.maximum(ok.argmax(-1), 1)
    y0 = np.take_along_axis(y, (i - 1)[..., None], -1)[..., 0]
    y1 = np.take_along_axis(y, i[..., None], -1)[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.clip(np.where(y1 > y0, (level - y0) / (y1 - y0), 1.0), 0.0, 1.0)
    return i, w, found


def _at(q: Array, i: Array, w: Array, found: Array) -> Array:
    """``q`` linearly interpolated at sample ``i - 1 + w`` (nan where not found)."""
    q0 = np.take_along_axis(q, (i - 1)[..., None], -1)[..., 0]
    q1 = np.take_along_axis(q, i[..., None], -1)[..., 0]
    return np.where(found, q0 + w * (q1 - q0), np.nan)


def _peak(y: Array, t: Array, lo: Array, hi: Array) -> tuple[Array, Array]:
    """Maximum of ``y`` over samples ``lo <= k < hi`` refined by the parabola through the
    samples around it: ``p = (y0 - y2) / (2 (y0 - 2 y1 + y2))``, ``y1 - (y0 - y2) p / 4``."""
    K = y.shape[-1]
    k = np.arange(K)
    m = np.where((k >= lo[..., None]) & (k < hi[..., None]), y, -np.inf).argmax(-1)
    mm = np.clip(m, 1, K - 2)
    y0, y1, y2 = (np.take_along_axis(y, (mm + j)[..., None], -1)[..., 0] for j in (-1, 0, 1))
    den = y0 - 2 * y1 + y2
    interior = (m == mm) & (den < 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.where(interior, 0.5 * (y0 - y2) / den, 0.0)
    p = np.clip(p, -0.5, 0.5)
    ym = np.take_along_axis(y, m[..., None], -1)[..., 0]
    peak = np.where(interior, y1 - 0.25 * (y0 - y2) * p, ym)
    tp = np.where(interior, t[mm] + p * 0.5 * (t[mm + 1] - t[mm - 1]), t[m])
    return peak, tp


def _heading(psi: Array, side: ArrayLike | None) -> tuple[Array, Array]:
    psi = np.unwrap(psi, axis=-1)
    e = psi - psi[..., :1]
    if side is None:
        side = np.where(e[..., -1] >= 0, 1.0, -1.0)
    side = np.asarray(side, dtype=float)
    if not np.all(np.isin(side, (-1.0, 1.0))):
        raise ValueError(f"side = {side.tolist()!r}; expected +1 (starboard) or -1 (port)")
    return side[..., None] * e, side


def turning_metrics(t: ArrayLike, east: ArrayLike, north: ArrayLike, psi: ArrayLike,
                    length: float, side: ArrayLike | None = None) -> TurningMetrics:
    """Advance, transfer, tactical and steady diameter, D/L of turning-circle records (the
    turn's side from the final heading change unless given)."""
    t = _times(t)
    K = t.size
    east, north = _series("east", east, K), _series("north", north, K)
    psi = _series("psi", psi, K)
    if not (math.isfinite(length) and length > 0):
        raise ValueError(f"length = {length!r}; expected a finite ship length > 0 m")
    e, side = _heading(psi, side)
    shape = np.broadcast_shapes(e.shape, east.shape, north.shape)
    e, east, north = (np.broadcast_to(a, shape) for a in (e, east, north))
    dx, dy = east - east[..., :1], north - north[..., :1]
    p0 = np.broadcast_to(psi[..., :1], shape[:-1] + (1,))
    along = dx * np.sin(p0) + dy * np.cos(p0)
    normal = side[..., None] * (dx * np.cos(p0) - dy * np.sin(p0))

    def when(deg: float, q: Array) -> Array:
        return _at(q, *_first(e, np.full(shape[:-1], math.radians(deg))))

    a90, t90, t180 = when(90, along), when(90, normal), when(180, normal)
    x360, y360 = when(360, dx), when(360, dy)
    x540, y540 = when(540, dx), when(540, dy)
    D = np.hypot(x540 - x360, y540 - y360)
    return TurningMetrics(a90, t90, t180, D, D / length)


def zigzag_metrics(t: ArrayLike, psi: ArrayLike, alpha: ArrayLike,
                   east: ArrayLike | None = None, north: ArrayLike | None = None,
                   side: ArrayLike = 1.0) -> ZigZagMetrics:
    """Initial turning time (and distance, given positions), time to check yaw, first and
    second overshoot and period of zig-zag records; ``alpha`` is the switching heading
    deviation (rad), ``side`` the first command's side."""
    t = _times(t)
    K = t.size
    psi = _series("psi", psi, K)
    alpha = np.asarray(alpha, dtype=float)
    if not np.all(np.isfinite(alpha) & (alpha > 0)):
        raise ValueError(f"alpha = {alpha.tolist()!r}; expected heading angles > 0 rad")
    e, _ = _heading(psi, side)
    batch = np.broadcast_shapes(e.shape[:-1], alpha.shape)
    e = np.broadcast_to(e, batch + (K,))
    alpha = np.broadcast_to(alpha, batch)
    tt = np.broadcast_to(t, batch + (K,))
    i1, w1, f1 = _first(e, alpha)
    i2, _, f2 = _first(-e, alpha, after=np.where(f1, i1, K))
    i3, w3, f3 = _first(e, alpha, after=np.where(f2, i2, K))
    t1, t3 = _at(tt, i1, w1, f1), _at(tt, i3, w3, f3)
    peak1, tp1 = _peak(e, t, i1 - 1, np.where(f2, i2, K))
    peak2, _ = _peak(-e, t, i2 - 1, np.where(f3, i3, K))
    if east is not None and north is not None:
        east, north = _series("east", east, K), _series("north", north, K)
        seg = np.hypot(np.diff(east, axis=-1), np.diff(north, axis=-1))
        s = np.concatenate([np.zeros(seg.shape[:-1] + (1,)), np.cumsum(seg, -1)], -1)
        dist = _at(np.broadcast_to(s, batch + (K,)), i1, w1, f1)
    else:
        dist = np.full(batch, np.nan)
    nan = np.nan
    return ZigZagMetrics(
        initial_turning_time=np.asarray(t1 - t[0]), initial_turning_distance=np.asarray(dist),
        time_to_check_yaw=np.where(f1 & f2, tp1 - t1, nan),
        first_overshoot=np.where(f1 & f2, peak1 - alpha, nan),
        second_overshoot=np.where(f2 & f3, peak2 - alpha, nan), period=np.asarray(t3 - t1))


def _check(name: str, value: Array, lower: ArrayLike, upper: ArrayLike,
           source: str) -> Criterion:
    value = np.asarray(value, dtype=float)
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    return Criterion(name, value, lower, upper, (value >= lower) & (value <= upper), source)


def imo_criteria(length: float, speed: ArrayLike, *, turning: TurningMetrics | None = None,
                 zigzag10: ZigZagMetrics | None = None,
                 zigzag20: ZigZagMetrics | None = None) -> dict[str, Criterion]:
    """The MSC.137(76) 5.3 checks that the given metrics allow, plus the paper's
    2 <= D/L <= 7 band (on the steady diameter). ``turning`` should come from a turning
    circle at the maximum nozzle angle, as the standard prescribes, and ``zigzag10`` carry the
    initial turning distance (positions given to ``zigzag_metrics``; nan fails). ``speed`` is
    the test speed V (m/s); limits use L/V in s. A criterion passes when
    ``lower <= value <= upper``. See ``IMO_NOTE``: for reference only below 100 m."""
    if not (math.isfinite(length) and length > 0):
        raise ValueError(f"length = {length!r}; expected a finite ship length > 0 m")
    V = np.asarray(speed, dtype=float)
    if not np.all(np.isfinite(V) & (V > 0)):
        raise ValueError(f"speed = {V.tolist()!r}; expected test speeds > 0 m/s")
    LV = length / V
    deg = math.radians
    out: dict[str, Criterion] = {}
    if turning is not None:
        out["advance"] = _check("advance", turning.advance, -np.inf, 4.5 * length,
                                "MSC.137(76) 5.3.1: advance <= 4.5 L")
        out["tactical_diameter"] = _check(
            "tactical_diameter", turning.tactical_diameter, -np.inf, 5 * length,
            "MSC.137(76) 5.3.1: tactical diameter <= 5 L")
        out["paper_band"] = _check("paper_band", turning.diameter_to_length, 2.0, 7.0,
                                   "Zolfagharnasab and Seif 2025: 2 <= D/L <= 7, steady diameter")
    if zigzag10 is not None:
        out["initial_turning"] = _check(
            "initial_turning", zigzag10.initial_turning_distance, -np.inf, 2.5 * length,
            "MSC.137(76) 5.3.2: <= 2.5 L sailed before 10 deg heading change (10 deg rudder)")
        first = np.where(LV < 10, 10.0, np.where(LV >= 30, 20.0, 5 + 0.5 * LV))
        second = np.where(LV < 10, 25.0, np.where(LV >= 30, 40.0, 17.5 + 0.75 * LV))
        out["first_overshoot_10"] = _check(
            "first_overshoot_10", zigzag10.first_overshoot, -np.inf, np.radians(first),
            "MSC.137(76) 5.3.3.1: 10/10 first overshoot")
        out["second_overshoot_10"] = _check(
            "second_overshoot_10", zigzag10.second_overshoot, -np.inf, np.radians(second),
            "MSC.137(76) 5.3.3.2: 10/10 second overshoot")
    if zigzag20 is not None:
        out["first_overshoot_20"] = _check(
            "first_overshoot_20", zigzag20.first_overshoot, -np.inf, deg(25.0),
            "MSC.137(76) 5.3.3.3: 20/20 first overshoot <= 25 deg")
    return out
