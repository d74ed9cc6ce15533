"""Simulated GPS and INS of a surface vessel, from a truth trajectory, batched over runs.

The truth is plain arrays (SI, nautical angles), the convention of the sea-trial simulator:

* ``t`` ``(K,)`` s, strictly increasing;
* ``east``, ``north`` ``(..., K)`` m in the local ENU frame at ``(lat0, lon0)``;
* ``psi`` ``(..., K)`` heading, rad clockwise from north (wrapped or continuous);
* ``u`` (surge, forward), ``v`` (sway, positive to starboard) ``(..., K)`` m/s, and ``r``
  ``(..., K)`` yaw rate, rad/s, positive clockwise (to starboard);

with ``east' = u sin psi + v cos psi``, ``north' = u cos psi - v sin psi``, ``psi' = r``.
Leading axes are Monte Carlo runs; the sensor times are shared by all runs.

Sensors (:class:`GpsModel`, :class:`InsModel`) sample the truth at their own rates, from
``t[0] + offset`` to ``t[-1]``. Between truth samples the truth is interpolated: east and
north by cubic Hermite interpolation with the kinematic velocities above as end-point
derivatives, psi (unwrapped) by cubic Hermite with ``r`` as derivative, and u, v, r linearly.
Hermite keeps the interpolated track consistent with the kinematics to O(dt^4) (a linear chord
would cut inside a turn); at truth sample times every value is the truth itself.

Noise (defaults, and why):

* GPS position: 1.5 m per horizontal axis (CEP 1.18 sigma = 1.8 m, 95% radius 2.45 sigma
  = 3.7 m), the usual 2-3 m CEP of a single-frequency marine receiver without SBAS; white by
  default, or first-order Gauss-Markov (``position_corr_time``; real errors wander over
  minutes) with the same stationary std. The identifier takes velocity from SOG/COG, not from
  differenced positions, so white position noise does not flatter it.
* GPS velocity: 0.05 m/s (~0.1 kn) per horizontal axis on the velocity vector, the Doppler
  velocity accuracy quoted for current receivers (u-blox M8/M9: 0.05 m/s). SOG and COG are
  computed from the noisy vector, as a receiver does, so the COG noise is about
  ``sigma / speed`` and grows at low speed (0.3 deg at 18 kn, 6 deg at 1 kn) and COG is
  meaningless at rest.
* GPS rate: 2 Hz. IMO MSC.112(73) asks shipborne GPS to update at least once per second,
  twice for high-speed craft; Naji 7 (44 kn) is one.
* INS heading: 0.2 deg (dual-antenna GNSS/INS or fibre-optic gyrocompass class, 0.1-0.5 deg;
  IMO's gyrocompass standard A.424(XI) allows far more), white.
* INS yaw rate: 0.05 deg/s (3 deg/min), a MEMS/FOG rate gyro after the INS's own filtering;
  white.
* INS rate: 10 Hz, a common NMEA output rate of heading sensors.

Noise is white unless stated, independent between quantities and runs. Draws come from the
given ``numpy.random.Generator`` in a fixed order: GPS position ``(..., N, 2)``, GPS velocity
``(..., N, 2)``, then INS heading ``(..., M)``, INS rate ``(..., M)``. Every draw is made
whatever its sigma (a zero sigma multiplies it by zero), so that silencing one noise leaves
the others' draws unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.io.frames import EnuFrame, course_from_velocity
from trackkit.io.records import GpsFixes, InsSamples

Array = NDArray[np.float64]

__all__ = [
    "KHOR_MUSA",
    "GpsModel",
    "InsModel",
    "sample_truth",
    "sensor_times",
    "simulate_gnss",
    "simulate_gps",
    "simulate_ins",
    "Truth",
]

#: A default local origin: the Khor Musa channel off Bandar Imam Khomeini, where the SAR boat
#: Naji 7 of Zolfagharnasab and Seif (2025) operates (latitude, longitude in degrees).
KHOR_MUSA = (30.43, 49.07)


class Truth(NamedTuple):
    """The truth at sensor times (see :func:`sample_truth`)."""

    t: Array
    east: Array
    north: Array
    psi: Array
    u: Array
    v: Array
    r: Array


def _check_number(owner: str, name: str, value: float, lo: float, *, strict: bool) -> float:
    v = float(value)
    ok = np.isfinite(v) and (v > lo if strict else v >= lo)
    if not ok:
        rel = ">" if strict else ">="
        raise ValueError(f"{owner}.{name} = {value!r}; expected a finite number {rel} {lo:g}")
    return v


@dataclass(frozen=True)
class GpsModel:
    """GPS noise and rate, SI: ``rate`` Hz, ``sigma_position`` m per horizontal axis,
    ``sigma_velocity`` m/s per horizontal axis, ``position_corr_time`` s (0: white),
    ``offset`` s from the truth's first time to the first fix. Defaults: see the module."""

    rate: float = 2.0
    sigma_position: float = 1.5
    sigma_velocity: float = 0.05
    position_corr_time: float = 0.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        _check_number("GpsModel", "rate", self.rate, 0.0, strict=True)
        _check_number("GpsModel", "sigma_position", self.sigma_position, 0.0, strict=False)
        _check_number("GpsModel", "sigma_velocity", self.sigma_velocity, 0.0, strict=False)
        _check_number("GpsModel", "position_corr_time", self.position_corr_time, 0.0,
                      strict=False)
        _check_number("GpsModel", "offset", self.offset, 0.0, strict=False)


@dataclass(frozen=True)
class InsModel:
    """INS noise and rate, SI: ``rate`` Hz, ``sigma_heading`` rad, ``sigma_rate`` rad/s,
    ``offset`` s. Defaults 10 Hz, 0.2 deg, 0.05 deg/s: see the module."""

    rate: float = 10.0
    sigma_heading: float = float(np.deg2rad(0.2))
    sigma_rate: float = float(np.deg2rad(0.05))
    offset: float = 0.0

    def __post_init__(self) -> None:
        _check_number("InsModel", "rate", self.rate, 0.0, strict=True)
        _check_number("InsModel", "sigma_heading", self.sigma_heading, 0.0, strict=False)
        _check_number("InsModel", "sigma_rate", self.sigma_rate, 0.0, strict=False)
        _check_number("InsModel", "offset", self.offset, 0.0, strict=False)


# -- truth ---------------------------------------------------------------------------------------


def _check_times(t: ArrayLike) -> Array:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t has shape {t.shape}; expected (K,) truth times with K >= 2")
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise ValueError(f"t[{k}] = {t[k]!r}; expected finite truth times")
    d = np.diff(t)
    if not np.all(d > 0):
        k = int(np.flatnonzero(~(d > 0))[0])
        raise ValueError(f"t is not strictly increasing: t[{k + 1}] = {t[k + 1]!r} after "
                         f"t[{k}] = {t[k]!r}; expected strictly increasing truth times")
    return t


def _check_series(name: str, x: ArrayLike, k: int) -> Array:
    x = np.asarray(x, dtype=float)
    if x.ndim < 1 or x.shape[-1] != k:
        raise ValueError(f"{name} has shape {x.shape}; expected (..., {k}), the length of t "
                         "last")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} holds non-finite values; expected finite truth")
    return x


def sensor_times(t: ArrayLike, rate: float, offset: float = 0.0) -> Array:
    """Times ``t[0] + offset + k / rate`` for k = 0, 1, ... up to ``t[-1]`` (a sample within
    1e-9 s of the end is kept, so a 2 Hz sensor on a 0..180 s truth ends at 180 s)."""
    t = _check_times(t)
    rate = _check_number("sensor_times", "rate", rate, 0.0, strict=True)
    offset = _check_number("sensor_times", "offset", offset, 0.0, strict=False)
    span = t[-1] - t[0] - offset
    if span < -1e-9:
        raise ValueError(f"offset = {offset!r} s is past the truth's end ({t[-1] - t[0]!r} s "
                         "after its start); expected an offset within the truth")
    n = int(np.floor(span * rate + 1e-9)) + 1
    ts = t[0] + offset + np.arange(n) / rate
    return np.minimum(ts, t[-1])  # the last sample may round a hair past the end


def sample_truth(t: ArrayLike, east: ArrayLike, north: ArrayLike, psi: ArrayLike,
                 u: ArrayLike, v: ArrayLike, r: ArrayLike, times: ArrayLike) -> Truth:
    """The truth at ``times`` (within ``[t[0], t[-1]]``): east, north and psi by cubic
    Hermite interpolation with the kinematic derivatives, u, v, r linearly (see the module).
    psi comes back continuous (unwrapped)."""
    t = _check_times(t)
    k = t.shape[0]
    east, north, psi, u, v, r = (_check_series(n, x, k) for n, x in (
        ("east", east), ("north", north), ("psi", psi), ("u", u), ("v", v), ("r", r)))
    try:
        shape = np.broadcast_shapes(east.shape, north.shape, psi.shape, u.shape, v.shape,
                                    r.shape)
    except ValueError:
        raise ValueError(f"east, north, psi, u, v, r have shapes {east.shape}, {north.shape}, "
                         f"{psi.shape}, {u.shape}, {v.shape}, {r.shape}; expected shapes that "
                         "broadcast, with K last") from None
    tq = np.asarray(times, dtype=float)
    if tq.ndim != 1 or not np.all(np.isfinite(tq)):
        raise ValueError("times: expected a 1-D array of finite sensor times")
    if tq.size and (tq.min() < t[0] - 1e-9 or tq.max() > t[-1] + 1e-9):
        raise ValueError(f"times span [{tq.min()!r}, {tq.max()!r}] s; expected times within "
                         f"the truth [{t[0]!r}, {t[-1]!r}] s")
    east, north, psi, u, v, r = (np.broadcast_to(x, shape) for x in
                                 (east, north, psi, u, v, r))
    psi = np.unwrap(psi, axis=-1)
    ve = u * np.sin(psi) + v * np.cos(psi)
    vn = u * np.cos(psi) - v * np.sin(psi)
    i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, k - 2)
    h = t[i + 1] - t[i]
    s = np.clip((tq - t[i]) / h, 0.0, 1.0)
    s2, s3 = s * s, s * s * s
    h00, h10, h01, h11 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2

    def hermite(p: Array, dp: Array) -> Array:
        return (h00 * p[..., i] + h10 * h * dp[..., i] + h01 * p[..., i + 1]
                + h11 * h * dp[..., i + 1])

    def linear(x: Array) -> Array:
        return (1.0 - s) * x[..., i] + s * x[..., i + 1]

    return Truth(tq, hermite(east, ve), hermite(north, vn), hermite(psi, r), linear(u),
                 linear(v), linear(r))


# -- sensors -------------------------------------------------------------------------------------


def _gauss_markov(w: Array, sigma: float, dt: float, tau: float) -> Array:
    """First-order Gauss-Markov along axis -2 from standard normals ``w`` ``(..., N, 2)``:
    ``e_0 = sigma w_0``, ``e_k = a e_{k-1} + sigma sqrt(1 - a^2) w_k``, ``a = exp(-dt/tau)``,
    the exact discretisation, stationary with std sigma."""
    if tau == 0.0:
        return sigma * w
    a = np.exp(-dt / tau)
    b = sigma * np.sqrt(1.0 - a * a)
    e = np.empty_like(w)
    e[..., 0, :] = sigma * w[..., 0, :]
    for k in range(1, w.shape[-2]):  # over time, never over runs
        e[..., k, :] = a * e[..., k - 1, :] + b * w[..., k, :]
    return e


Rng = np.random.Generator | Sequence[np.random.Generator]


def _check_rng(rng: Rng) -> None:
    ok = isinstance(rng, np.random.Generator) or (
        isinstance(rng, Sequence) and len(rng) > 0
        and all(isinstance(g, np.random.Generator) for g in rng))
    if not ok:
        raise ValueError(f"rng = {rng!r}; expected a numpy.random.Generator "
                         "(np.random.default_rng(seed)) or one per run")


def _normals(rng: Rng, shape: tuple[int, ...]) -> Array:
    """Standard normals of ``shape``; with one generator per run (a sequence), run i's from
    its own, so that a run's noise depends on its generator alone, not on the batch."""
    if isinstance(rng, np.random.Generator):
        return rng.standard_normal(shape)
    if not shape or shape[0] != len(rng):
        raise ValueError(f"{len(rng)} generators for a truth of shape {shape[:-1]}; expected "
                         "one per run, the truth's leading axis")
    return np.stack([g.standard_normal(shape[1:]) for g in rng])


def simulate_gps(t: ArrayLike, east: ArrayLike, north: ArrayLike, psi: ArrayLike,
                 u: ArrayLike, v: ArrayLike, r: ArrayLike, *, rng: Rng,
                 model: GpsModel | None = None, lat0: float = KHOR_MUSA[0],
                 lon0: float = KHOR_MUSA[1]) -> GpsFixes:
    """GPS fixes of the truth (see the module): positions with noise converted to latitude
    and longitude in the ENU frame at ``(lat0, lon0)`` (sea level), SOG and COG from the noisy
    velocity vector. ``rng``: one generator, or one per run (the truth's leading axis)."""
    model = GpsModel() if model is None else model
    _check_rng(rng)
    frame = EnuFrame(lat0, lon0)
    ts = sensor_times(t, model.rate, model.offset)
    tr = sample_truth(t, east, north, psi, u, v, r, ts)
    ve = tr.u * np.sin(tr.psi) + tr.v * np.cos(tr.psi)
    vn = tr.u * np.cos(tr.psi) - tr.v * np.sin(tr.psi)
    shape = tr.east.shape + (2,)
    ep = _gauss_markov(_normals(rng, shape), model.sigma_position, 1.0 / model.rate,
                       model.position_corr_time)
    ev = model.sigma_velocity * _normals(rng, shape)
    lat, lon, _ = frame.to_geodetic(tr.east + ep[..., 0], tr.north + ep[..., 1], 0.0)
    sog, cog = course_from_velocity(ve + ev[..., 0], vn + ev[..., 1], "m/s", "rad")
    return GpsFixes(ts, lat, lon, sog, cog)


def simulate_ins(t: ArrayLike, east: ArrayLike, north: ArrayLike, psi: ArrayLike,
                 u: ArrayLike, v: ArrayLike, r: ArrayLike, *, rng: Rng,
                 model: InsModel | None = None) -> InsSamples:
    """INS heading and yaw rate of the truth (see the module); heading in [0, 2 pi).
    ``rng``: one generator, or one per run (the truth's leading axis)."""
    model = InsModel() if model is None else model
    _check_rng(rng)
    ts = sensor_times(t, model.rate, model.offset)
    tr = sample_truth(t, east, north, psi, u, v, r, ts)
    heading = tr.psi + model.sigma_heading * _normals(rng, tr.psi.shape)
    rate = tr.r + model.sigma_rate * _normals(rng, tr.r.shape)
    return InsSamples(ts, np.mod(heading, 2.0 * np.pi), rate)


def simulate_gnss(t: ArrayLike, east: ArrayLike, north: ArrayLike, psi: ArrayLike,
                  u: ArrayLike, v: ArrayLike, r: ArrayLike, *, rng: Rng,
                  gps: GpsModel | None = None, ins: InsModel | None = None,
                  lat0: float = KHOR_MUSA[0], lon0: float = KHOR_MUSA[1]
                  ) -> tuple[GpsFixes, InsSamples]:
    """GPS then INS of a truth, from one generator or one per run (GPS draws first)."""
    fixes = simulate_gps(t, east, north, psi, u, v, r, rng=rng, model=gps, lat0=lat0,
                         lon0=lon0)
    return fixes, simulate_ins(t, east, north, psi, u, v, r, rng=rng, model=ins)
