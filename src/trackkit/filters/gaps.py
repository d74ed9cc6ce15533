"""Keeping a track through missing measurements: the missing-measurements thesis's chapter 4, its
own contribution.

When the radar sees nothing for a while (smoke, cloud, a beam problem), a handler decides
what the filter is fed at each missing step:

- ``Coast`` (B0): nothing; the update returns the prediction.
- ``HoldLast`` (B1): the last real measurement, again and again.
- ``MeanOfLast(n)`` (B2): the mean of the last n real measurements.
- ``PolynomialFit(degree, window)`` (P): a least-squares polynomial in time through the last
  ``window`` real measurements, extrapolated to the missing times (degree 1 for a CV target,
  2 for CA); with ``short_window`` it is P': the last ``short_window`` only, for the runs
  whose manoeuvre detector is on.
- ``SineFit(window)`` (P for the sine example): ``y = a sin(theta0 + omega tau)`` fitted by
  batched Gauss-Newton, started from the filter's own estimate.

Masks say which measurements are missing: bool arrays over time steps (True = missing),
``(K,)`` for every run alike or ``(K, ...)`` per run, built by time interval, sample interval
or count and combined with ``union``. ``run_with_gaps`` runs any trackkit filter over a
batch of runs with a handler, and records which steps were pseudo-measurements.

Handlers are stateless strategies; what they remember (the last real measurements and the
current gap's fit) is a ``GapMemory`` of arrays whose leading axes are the batch axes.
Measurement components that are angles (the sensor's ``angular`` flags) are unwrapped
before the mean or the fit and wrapped after.
"""

from __future__ import annotations

import inspect
import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import Filter
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = [
    "measurement_times",
    "mask_by_time",
    "mask_by_samples",
    "mask_by_count",
    "union",
    "gap_and_after",
    "GapMemory",
    "GapHandler",
    "Coast",
    "HoldLast",
    "MeanOfLast",
    "PolynomialFit",
    "SineFit",
    "HANDLER_NAMES",
    "make_handler",
    "GapRun",
    "run_with_gaps",
    "GapBelief",
    "WithGaps",
]

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


# --------------------------------------------------------------------------------------------
# Gap masks
# --------------------------------------------------------------------------------------------


def measurement_times(steps: int, dt: ArrayLike, t0: float = 0.0) -> Array:
    """Times of measurements ``0, ..., steps-1`` as ``run_with_gaps`` (and ``run_filter``) take
    them: the first one step after the prior, ``t_k = t0 + (k + 1) dt`` for a scalar dt, or
    ``t0 + cumsum(dt)`` for one step per measurement."""
    K = _count(steps, "steps", 1)
    if not math.isfinite(t0):
        raise ValueError(f"t0 = {t0!r}; expected a finite start time (s)")
    d = np.asarray(dt, dtype=float)
    if d.ndim == 0:
        if not (math.isfinite(float(d)) and d > 0):
            raise ValueError(f"dt = {dt!r}; expected a finite time step > 0 (s)")
        return t0 + np.arange(1, K + 1) * float(d)
    if d.shape != (K,) or not np.all(np.isfinite(d)) or not np.all(d > 0):
        raise ValueError(f"dt has shape {d.shape} (values {d.ravel()[:4].tolist()}...); "
                         f"expected a scalar or ({K},) finite steps > 0 (s)")
    return t0 + np.cumsum(d)


def mask_by_time(times: ArrayLike, start: ArrayLike, stop: ArrayLike) -> Mask:
    """Missing where ``start <= t < stop``: ``(K,)``, or ``(K, ...)`` when start or stop
    carry per-run batch axes.

    The interval is half-open so that a gap holds ``(stop - start) / T`` samples (30 for
    the missing-measurements thesis's 2-5 s at T = 0.1 s, as the thesis counts them, 5 for its 20-25
    s at T = 1 s) and back-to-back gaps tile without overlap; the first measurement after the gap is
    the one at ``stop``. Ends are compared within 1e-9 relative (of ``max(1, |start|, |stop|)``
    seconds), so times computed as ``k dt`` land on the grid whichever way they round.
    A gap that holds no sample is an error.
    """
    t = _times(times)
    a, b = np.asarray(start, dtype=float), np.asarray(stop, dtype=float)
    for name, v in (("start", a), ("stop", b)):
        if not np.all(np.isfinite(v)):
            raise ValueError(f"mask_by_time: {name} = {v.tolist()!r}; expected finite times (s)")
    a, b = np.broadcast_arrays(a, b)
    if not np.all(a < b):
        i = np.argwhere(~(a < b))[0] if a.ndim else ()
        raise ValueError(f"mask_by_time: start = {float(a[tuple(i)])!r} and stop = "
                         f"{float(b[tuple(i)])!r}; "
                         "expected start < stop")
    tol = 1e-9 * np.maximum(1.0, np.maximum(np.abs(a), np.abs(b)))
    tt = t.reshape(t.shape + (1,) * a.ndim)
    mask = (tt >= a - tol) & (tt < b - tol)
    empty = ~mask.any(0)
    if np.any(empty):
        i = tuple(np.argwhere(empty)[0]) if a.ndim else ()
        raise ValueError(f"mask_by_time: the gap [{float(a[i])!r}, {float(b[i])!r}) s holds "
                         f"no measurement time (times run from {float(t[0])!r} to "
                         f"{float(t[-1])!r} s); expected a gap "
                         "that covers at least one")
    return mask


def mask_by_samples(steps: int, first: ArrayLike, last: ArrayLike) -> Mask:
    """Missing at sample indices ``first`` to ``last``, both included (0-based indices into the
    measurement axis; the missing-measurements thesis's "from sample 50 to sample 90", counted from
    1, is
    ``first=49, last=89``). Per-run arrays give ``(K, ...)``."""
    K = _count(steps, "steps", 1)
    a = _indices(first, "first")
    b = _indices(last, "last")
    a, b = np.broadcast_arrays(a, b)
    _check_index_range(a, b, K)
    k = np.arange(K).reshape((K,) + (1,) * a.ndim)
    return (k >= a) & (k <= b)


def mask_by_count(steps: int, start: ArrayLike, count: ArrayLike) -> Mask:
    """``count`` consecutive missing samples from index ``start`` (0-based): indices
    ``start`` to ``start + count - 1``. Per-run arrays give ``(K, ...)``."""
    K = _count(steps, "steps", 1)
    a = _indices(start, "start")
    c = _indices(count, "count")
    if np.any(c < 1):
        raise ValueError(f"mask_by_count: count = {c.tolist()!r}; expected integers >= 1")
    a, c = np.broadcast_arrays(a, c)
    _check_index_range(a, a + c - 1, K)
    k = np.arange(K).reshape((K,) + (1,) * a.ndim)
    return (k >= a) & (k < a + c)


def union(*masks: ArrayLike) -> Mask:
    """Several gaps at once: the logical or of masks whose axis 0 is time (``(K,)`` masks
    apply to every run of the ``(K, ...)`` ones)."""
    if not masks:
        raise ValueError("union: no masks given; expected at least one")
    ms = [_mask(m, f"union mask {i}") for i, m in enumerate(masks)]
    K = ms[0].shape[0]
    if any(m.shape[0] != K for m in ms):
        raise ValueError(f"union: masks have {[m.shape[0] for m in ms]} time steps; expected "
                         "the same number")
    nd = max(m.ndim for m in ms)
    ms = [m.reshape(m.shape + (1,) * (nd - m.ndim)) for m in ms]
    out = ms[0]
    for m in ms[1:]:
        out = out | m
    return out


def gap_and_after(mask: ArrayLike, after: int) -> Mask:
    """The missing steps and the ``after`` steps that follow each gap (where the
    missing-measurements thesis looks for the error: over the gap and while the filter recovers)."""
    m = _mask(mask, "gap_and_after mask")
    n = _count(after, "after", 0)
    out = m.copy()
    for j in range(1, min(n, m.shape[0] - 1) + 1):
        out[j:] |= m[:-j]
    return out


def _count(v: Any, name: str, least: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < least:
        raise ValueError(f"{name} = {v!r}; expected an integer >= {least}")
    return int(v)


def _times(times: ArrayLike) -> Array:
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise ValueError(f"times has shape {t.shape}; expected a non-empty (K,) array of finite "
                         "times (s)")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise ValueError("times are not increasing; expected measurement times in order")
    return t


def _indices(v: ArrayLike, name: str) -> NDArray[np.int64]:
    a = np.asarray(v)
    if a.dtype == bool or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name} = {a.tolist()!r}; expected integer sample indices")
    return a.astype(np.int64)


def _check_index_range(a: NDArray[np.int64], b: NDArray[np.int64], K: int) -> None:
    bad = (a < 0) | (b < a) | (b >= K)
    if np.any(bad):
        i = tuple(np.argwhere(bad)[0]) if a.ndim else ()
        raise ValueError(f"gap from sample {int(a[i])} to {int(b[i])}; expected "
                         f"0 <= first <= last <= {K - 1} (the last sample index)")


def _mask(m: ArrayLike, name: str) -> Mask:
    a = np.asarray(m)
    if a.dtype != bool or a.ndim < 1:
        raise ValueError(f"{name} has dtype {a.dtype} and shape {a.shape}; expected a bool "
                         "array (K, ...) with time on axis 0")
    return a


# --------------------------------------------------------------------------------------------
# Handlers
# --------------------------------------------------------------------------------------------


class GapMemory(NamedTuple):
    """What a handler remembers, per batch row (leading axes ``...``).

    ``z (..., L, m)`` and ``t (..., L)``: the last L real measurements and their times,
    oldest first (nan before any arrived); ``count (...)``: real measurements seen;
    ``coef (..., p, m)``, ``t_ref (...)``, ``scale (...)``: the fit made when the current gap
    began, in ``s = (t - t_ref) / scale`` (nan when none); ``fitted (...)``: a fit is held.
    """

    z: Array
    t: Array
    count: NDArray[np.int64]
    coef: Array
    t_ref: Array
    scale: Array
    fitted: NDArray[np.bool_]


class GapHandler:
    """Interface of the missing-measurement handlers.

    ``init(batch_shape, sensor) -> GapMemory``;
    ``pseudo(memory, t, missing, sensor, estimate=None, maneuver=None) -> (z, memory)``:
    the pseudo-measurement for each row with ``missing`` at time t, nan where none is made
    (``estimate``: the filter's predicted Gaussian at t; ``maneuver``: the detector's on
    flags); ``observe(memory, t, z) -> memory`` remembers the real rows of z (nan rows are
    not real).
    """

    label: str = "?"
    #: the past real measurements kept
    memory: int = 0
    #: P' window while the manoeuvre detector is on (None: the handler ignores the detector)
    short_window: int | None = None
    #: whether ``pseudo`` needs the filter's estimate
    needs_estimate: bool = False

    def _coefficients(self) -> int:
        return 0

    def init(self, batch_shape: tuple[int, ...], sensor: SensorModel) -> GapMemory:
        batch, L, m, p = tuple(batch_shape), self.memory, sensor.dim_z, self._coefficients()
        return GapMemory(np.full(batch + (L, m), np.nan), np.full(batch + (L,), np.nan),
                         np.zeros(batch, np.int64), np.full(batch + (p, m), np.nan),
                         np.full(batch, np.nan), np.full(batch, np.nan), np.zeros(batch, bool))

    def observe(self, memory: GapMemory, t: ArrayLike, z: ArrayLike) -> GapMemory:
        """Push each real row of ``z (..., m)`` (taken at t) into the window; a real
        measurement ends that row's gap, so its fit is dropped."""
        z = np.asarray(z, dtype=float)
        batch = memory.count.shape
        real = np.broadcast_to(~np.isnan(z).any(-1), batch)
        count = np.asarray(memory.count + real)
        fitted = np.asarray(memory.fitted & ~real)
        if self.memory == 0:
            return memory._replace(count=count, fitted=fitted)
        zn = np.broadcast_to(z, batch + z.shape[-1:])[..., None, :]
        tn = np.broadcast_to(np.asarray(t, dtype=float), batch)[..., None]
        zb = np.where(real[..., None, None],
                      np.concatenate([memory.z[..., 1:, :], zn], -2), memory.z)
        tb = np.where(real[..., None], np.concatenate([memory.t[..., 1:], tn], -1), memory.t)
        return memory._replace(z=zb, t=tb, count=count, fitted=fitted)

    def pseudo(self, memory: GapMemory, t: ArrayLike, missing: ArrayLike, sensor: SensorModel,
               estimate: Gaussian | None = None,
               maneuver: ArrayLike | None = None) -> tuple[Array, GapMemory]:
        raise NotImplementedError  # pragma: no cover - interface

    def __repr__(self) -> str:
        fields = ", ".join(f"{k}={v!r}" for k, v in vars(self).items())
        return f"{type(self).__name__}({fields})"


class Coast(GapHandler):
    """B0: no pseudo-measurement; the filter coasts on its prediction (``x+ = x-``,
    ``P+ = P-``) through the gap."""

    label = "B0"

    def pseudo(self, memory, t, missing, sensor: SensorModel, estimate=None, maneuver=None):
        return np.full(memory.count.shape + (sensor.dim_z,), np.nan), memory


class HoldLast(GapHandler):
    """B1: the last real measurement, ``z~_k = z_j``, j the newest real step (the thesis's
    "current practice"). Rows that have seen none coast."""

    label = "B1"
    memory = 1

    def pseudo(self, memory, t, missing, sensor: SensorModel, estimate=None, maneuver=None):
        miss = np.broadcast_to(np.asarray(missing, bool), memory.count.shape)
        return np.where(miss[..., None], memory.z[..., -1, :], np.nan), memory


class MeanOfLast(GapHandler):
    """B2: the mean of the last n real measurements, ``z~_k = (1/n) sum_{i=1..n} z_{j_i}``
    (fewer while fewer have arrived; rows that have seen none coast). Angle components are
    averaged unwrapped, then wrapped."""

    label = "B2"

    def __init__(self, n: int = 5) -> None:
        self.n = _count(n, "MeanOfLast n", 1)

    @property
    def memory(self) -> int:  # type: ignore[override]
        return self.n

    def pseudo(self, memory, t, missing, sensor: SensorModel, estimate=None, maneuver=None):
        miss = np.broadcast_to(np.asarray(missing, bool), memory.count.shape)
        L = self.n
        valid = _recent(memory.count, L, L)
        u = np.where(valid[..., None], _unwrap(memory.z, _angular(sensor)), 0.0)
        total = _slot_sum(u)
        used = np.minimum(memory.count, L)
        with np.errstate(invalid="ignore", divide="ignore"):
            zbar = total / used[..., None]
        ok = miss & (used > 0)
        return np.where(ok[..., None], _wrap_angles(zbar, sensor), np.nan), memory


class _Fit(GapHandler):
    """What P and P' share: a fit through the last ``window`` real measurements, or the last
    ``short_window`` while the manoeuvre detector is on (P')."""

    window: int

    def _windows(self, window: int, short_window: int | None, least: int) -> None:
        name = type(self).__name__
        self.window = _count(window, f"{name} window", least)
        if short_window is not None:
            short_window = _count(short_window, f"{name} short_window", least)
            if short_window >= self.window:
                raise ValueError(f"{name} short_window = {short_window!r}; expected fewer "
                                 f"than window = {self.window}")
        self.short_window = short_window

    @property
    def label(self) -> str:  # type: ignore[override]
        return "P" if self.short_window is None else "P'"

    @property
    def memory(self) -> int:  # type: ignore[override]
        return self.window


class PolynomialFit(_Fit):
    """P (P' with ``short_window``): a least-squares polynomial through the last ``window``
    real measurements, extrapolated to the missing times.

    With ``s = (t - t_ref) / scale`` (t_ref the newest real time, scale the window's span)
    and the Vandermonde matrix ``V_ij = s_i^j`` (j = 0..degree) over the window,
    ``c = V^+ z`` and ``z~(t) = sum_j c_j s(t)^j``. The fit is made once, when the gap
    begins, and held until the next real measurement. When every run's window has the same
    times (the usual case) ``V^+`` is one pseudo-inverse applied to all runs at once;
    otherwise one per run, batched. Rows with fewer than ``degree + 1`` real measurements
    coast. P': rows whose manoeuvre detector is on at the gap's start fit only the last
    ``short_window`` (measurements from before a manoeuvre say little about it).
    """

    def __init__(self, degree: int = 1, window: int = 10,
                 short_window: int | None = None) -> None:
        self.degree = _count(degree, "PolynomialFit degree", 0)
        self._windows(window, short_window, self.degree + 1)

    def _coefficients(self) -> int:
        return self.degree + 1

    def pseudo(self, memory, t, missing, sensor: SensorModel, estimate=None, maneuver=None):
        batch = memory.count.shape
        miss = np.broadcast_to(np.asarray(missing, bool), batch)
        w = _windows(self, batch, maneuver)
        p = self.degree + 1
        need = miss & ~memory.fitted & (np.minimum(memory.count, w) >= p)
        if need.any():
            valid = _recent(memory.count[need], self.window, w[need])
            z = _unwrap(memory.z[need], _angular(sensor))
            c, t_ref, scale = _poly_fit(z, memory.t[need], valid, p)
            memory = _store(memory, need, c, t_ref, scale)
        s = (np.asarray(t, dtype=float) - memory.t_ref) / memory.scale
        y = memory.coef[..., p - 1, :]
        for j in range(p - 2, -1, -1):  # Horner
            y = y * s[..., None] + memory.coef[..., j, :]
        ok = miss & memory.fitted
        return np.where(ok[..., None], _wrap_angles(y, sensor), np.nan), memory


class SineFit(_Fit):
    """P for the missing-measurements thesis's sine (sections 2-5-5-2 and 4-4): ``y(t) = a
    sin(theta0 + omega (t - t_ref))`` fitted to the last ``window`` real measurements, extrapolated
    to the missing times.

    Nonlinear least squares, ``min sum_i (y_i - a sin(phi_i))^2``, ``phi_i = theta0 +
    omega tau_i``, by batched Gauss-Newton: ``J_i = [a cos phi_i, a tau_i cos phi_i,
    sin phi_i]``, step ``delta = J^+ r``, halved (up to 10 times) until the cost falls; a row
    whose cost no longer falls is done. It starts from the filter's own predicted estimate
    at the first missing step: ``omega = x[rate]``, ``theta0 = x[phase] - omega (t -
    t_ref)``, ``a = x[amplitude]`` (or 1). With ``amplitude=None`` the amplitude is held at
    1 (section 4-4's ``y = sin theta``); with an index it is fitted too (and reported with a >= 0,
    since ``a sin(phi) = -a sin(phi + pi)``). ``short_window`` as for
    ``PolynomialFit`` (P'). The sensor must measure one component.
    """

    needs_estimate = True

    def __init__(self, window: int = 30, phase: int = 0, rate: int = 1,
                 amplitude: int | None = None, iterations: int = 30,
                 short_window: int | None = None) -> None:
        self.phase = _count(phase, "SineFit phase", 0)
        self.rate = _count(rate, "SineFit rate", 0)
        self.amplitude = None if amplitude is None else _count(amplitude, "SineFit amplitude",
                                                               0)
        idx = [self.phase, self.rate] + ([] if self.amplitude is None else [self.amplitude])
        if len(set(idx)) != len(idx):
            raise ValueError(f"SineFit phase, rate, amplitude = {idx!r}; expected distinct "
                             "state indices")
        p = len(idx)
        self.iterations = _count(iterations, "SineFit iterations", 1)
        self._windows(window, short_window, p)

    def _coefficients(self) -> int:
        return 3

    def init(self, batch_shape: tuple[int, ...], sensor: SensorModel) -> GapMemory:
        if sensor.dim_z != 1:
            raise ValueError(f"SineFit: the sensor measures {sensor.dim_z} components; "
                             "expected 1 (y = a sin(theta))")
        return super().init(batch_shape, sensor)

    def pseudo(self, memory, t, missing, sensor: SensorModel, estimate=None, maneuver=None):
        batch = memory.count.shape
        miss = np.broadcast_to(np.asarray(missing, bool), batch)
        w = _windows(self, batch, maneuver)
        p = 2 if self.amplitude is None else 3
        need = miss & ~memory.fitted & (np.minimum(memory.count, w) >= p)
        if need.any():
            if estimate is None:
                raise ValueError("SineFit.pseudo: estimate is None; expected the filter's "
                                 "predicted Gaussian (the fit starts from it)")
            x = np.broadcast_to(np.asarray(estimate.mean, dtype=float),
                                batch + np.shape(estimate.mean)[-1:])[need]
            n = x.shape[-1]
            if max(self.phase, self.rate, self.amplitude or 0) >= n:
                raise ValueError(f"SineFit: state index out of range for a state of {n} "
                                 f"components (phase={self.phase}, rate={self.rate}, "
                                 f"amplitude={self.amplitude})")
            tt = memory.t[need]
            t_ref = tt[..., -1]
            omega = x[..., self.rate]
            theta0 = x[..., self.phase] - omega * (np.broadcast_to(t, batch)[need] - t_ref)
            a = np.ones_like(omega) if self.amplitude is None else x[..., self.amplitude]
            valid = _recent(memory.count[need], self.window, w[need])
            theta0, omega, a = _sine_fit(memory.z[need][..., 0], tt - t_ref[..., None], valid,
                                         theta0, omega, a, self.amplitude is not None,
                                         self.iterations)
            c = np.stack([theta0, omega, a], -1)[..., None]
            memory = _store(memory, need, c, t_ref, np.ones_like(t_ref))
        tau = np.asarray(t, dtype=float) - memory.t_ref
        c = memory.coef[..., 0]
        y = c[..., 2] * np.sin(c[..., 0] + c[..., 1] * tau)
        ok = miss & memory.fitted
        return np.where(ok, y, np.nan)[..., None], memory


def _windows(h: GapHandler, batch: tuple[int, ...], maneuver: ArrayLike | None
             ) -> NDArray[np.int64]:
    """Each row's window: the short one where P' sees the detector on."""
    w = np.full(batch, h.memory, np.int64)
    if h.short_window is None:
        return w
    if maneuver is None:
        raise ValueError(f"{type(h).__name__} with short_window (P') needs the manoeuvre "
                         "detector's on flags; got maneuver=None")
    on = np.broadcast_to(np.asarray(maneuver, bool), batch)
    return np.where(on, h.short_window, w)


def _store(memory: GapMemory, rows: Mask, coef: Array, t_ref: Array,
           scale: Array) -> GapMemory:
    c, r, s, f = (np.array(a) for a in (memory.coef, memory.t_ref, memory.scale,
                                        memory.fitted))
    c[rows], r[rows], s[rows], f[rows] = coef, t_ref, scale, True
    return memory._replace(coef=c, t_ref=r, scale=s, fitted=f)


def _recent(count: NDArray[np.int64], L: int, w: ArrayLike) -> Mask:
    """Slots of an L-slot window (oldest first) that hold one of the last ``w`` real
    measurements: slot i is in when ``i >= L - min(count, w)``."""
    used = np.minimum(count, w)
    return np.arange(L) >= (L - used)[..., None]


def _slot_sum(u: Array) -> Array:
    """Sum over the window axis (-2), slot by slot: the same additions in the same order
    whatever the batch, so a row's result never depends on the rows beside it."""
    total = u[..., 0, :].copy()
    for i in range(1, u.shape[-2]):
        total += u[..., i, :]
    return total


def _angular(sensor: SensorModel) -> NDArray[np.bool_]:
    return np.asarray(tuple(getattr(sensor, "angular", ())) or (False,) * sensor.dim_z, bool)


def _wrap_angles(z: Array, sensor: SensorModel) -> Array:
    ang = _angular(sensor)
    return np.where(ang, wrap(z), z) if ang.any() else z


def _unwrap(z: Array, angular: NDArray[np.bool_]) -> Array:
    """The window ``z (..., L, m)`` with its angle components made continuous, anchored at
    the newest sample: ``u_i = z_L - sum_{j >= i} wrap(z_{j+1} - z_j)``. Slots not yet
    filled (nan, always the oldest) stay nan."""
    if not angular.any() or z.shape[-2] < 2:
        return z
    d = wrap(np.diff(z, axis=-2))
    d = np.where(np.isnan(d), 0.0, d)
    tail = np.flip(np.cumsum(np.flip(d, -2), -2), -2)
    u = z[..., -1:, :] - np.concatenate([tail, np.zeros_like(z[..., -1:, :])], -2)
    return np.where(angular & ~np.isnan(z), u, z)


def _poly_fit(z: Array, t: Array, valid: Mask, p: int) -> tuple[Array, Array, Array]:
    """Least-squares polynomial coefficients ``c = V^+ z`` over the valid slots (rows of V
    and z outside the window are zero, so they do not count). Returns ``(c (N, p, m),
    t_ref (N,), scale (N,))``."""
    t_ref = t[..., -1]
    span = t_ref - np.where(valid, t, np.inf).min(-1)
    scale = np.where(span > 0, span, 1.0)
    s = np.where(valid, (t - t_ref[..., None]) / scale[..., None], 0.0)
    cols = [valid.astype(float)]
    for _ in range(1, p):
        cols.append(cols[-1] * s)
    V = np.stack(cols, -1)  # (N, L, p)
    y = np.where(valid[..., None], z, 0.0)
    if (V == V[0]).all():
        A = np.broadcast_to(np.linalg.pinv(V[:1])[0], V.shape[:1] + (p, V.shape[1]))
    else:
        A = np.linalg.pinv(V)  # (N, p, L), one SVD per row
    c = A[..., :, 0, None] * y[..., 0, None, :]
    for i in range(1, V.shape[1]):  # slot by slot: batch-independent rounding
        c = c + A[..., :, i, None] * y[..., i, None, :]
    return c, t_ref, scale


def _sine_fit(y: Array, tau: Array, valid: Mask, theta0: Array, omega: Array, a: Array,
              fit_amplitude: bool, iterations: int) -> tuple[Array, Array, Array]:
    """Batched Gauss-Newton for ``min sum_i (y_i - a sin(theta0 + omega tau_i))^2`` over the
    valid slots (see ``SineFit``). Each row stops on its own, so its result does not
    depend on the other rows."""
    vf = valid.astype(float)
    tau = np.where(valid, tau, 0.0)
    y = np.where(valid, y, 0.0)

    def residual(th, om, am):
        return vf * (y - am[..., None] * np.sin(th[..., None] + om[..., None] * tau))

    def cost(r):
        return _slot_sum(r[..., None] * r[..., None])[..., 0]

    params = np.stack([theta0, omega, a], -1)
    r = residual(theta0, omega, a)
    c = cost(r)
    done = np.zeros(c.shape, bool)
    for _ in range(iterations):
        th, om, am = params[..., 0], params[..., 1], params[..., 2]
        phi = th[..., None] + om[..., None] * tau
        cos = np.cos(phi)
        cols = [vf * am[..., None] * cos, vf * am[..., None] * tau * cos]
        if fit_amplitude:
            cols.append(vf * np.sin(phi))
        J = np.stack(cols, -1)  # (N, L, p)
        Jp = np.linalg.pinv(J)  # (N, p, L)
        step = Jp[..., :, 0] * r[..., None, 0]
        for i in range(1, J.shape[-2]):
            step = step + Jp[..., :, i] * r[..., None, i]
        if not fit_amplitude:
            step = np.concatenate([step, np.zeros_like(step[..., :1])], -1)
        taken = done.copy()
        frac = 1.0
        for _ in range(11):
            trial = params + frac * step
            r_try = residual(trial[..., 0], trial[..., 1], trial[..., 2])
            c_try = cost(r_try)
            take = ~taken & (c_try < c)
            params = np.where(take[..., None], trial, params)
            r = np.where(take[..., None], r_try, r)
            c = np.where(take, c_try, c)
            taken |= take
            if taken.all():
                break
            frac *= 0.5
        done |= ~taken  # no step lowered the cost: this row has converged
        if done.all():
            break
    th, om, am = params[..., 0], params[..., 1], params[..., 2]
    # a sin(phi) = -a sin(phi + pi): report the fit with a >= 0
    return np.where(am < 0, th + np.pi, th), om, np.abs(am)


#: The thesis's handler names that :func:`make_handler` accepts.
HANDLER_NAMES = ("B0", "B1", "B2", "P", "P'")


def make_handler(name: str, **options: Any) -> GapHandler:
    """A handler by the missing-measurements thesis's name and its options, as a scenario file
    selects it:

    ``"B0"`` (coast), ``"B1"`` (hold last), ``"B2"`` (``n``), ``"P"`` (``function=
    "polynomial"`` with ``degree``, ``window``; or ``function="sine"`` with ``window``,
    ``phase``, ``rate``, ``amplitude``, ``iterations``) and ``"P'"`` (the same and a
    ``short_window``, required).
    """
    classes: dict[str, type[GapHandler]] = {"B0": Coast, "B1": HoldLast, "B2": MeanOfLast}
    if name in classes:
        cls = classes[name]
    elif name in ("P", "P'"):
        function = options.pop("function", "polynomial")
        fits = {"polynomial": PolynomialFit, "sine": SineFit}
        if function not in fits:
            raise ValueError(f"handler {name!r}: function = {function!r}; expected one of "
                             f"{sorted(fits)}")
        if name == "P'" and options.get("short_window") is None:
            raise ValueError("handler \"P'\": short_window is missing; expected the window "
                             "used while the manoeuvre detector is on")
        if name == "P" and options.get("short_window") is not None:
            raise ValueError(f"handler 'P': short_window = {options['short_window']!r}; "
                             "a short window makes it P' (name it \"P'\")")
        cls = fits[function]
    else:
        raise ValueError(f"handler name = {name!r}; expected one of {list(HANDLER_NAMES)}")
    allowed = set(inspect.signature(cls.__init__).parameters) - {"self"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise ValueError(f"handler {name!r}: unknown option(s) {unknown}; expected some of "
                         f"{sorted(allowed)}")
    return cls(**options)


# --------------------------------------------------------------------------------------------
# The runner
# --------------------------------------------------------------------------------------------


class GapRun(NamedTuple):
    """A filter's run through gaps, time on axis 0.

    ``times (K,)``; ``estimate``: ``f.estimate`` of the filtered belief after each step,
    mean ``(K, ..., n)`` and cov ``(K, ..., n, n)`` (cov None unless kept); ``pseudo (K, ...,
    m)``: the pseudo-measurements fed (nan elsewhere); ``is_pseudo (K, ...)``: steps that
    were fed a pseudo-measurement; ``missing (K, ...)``: steps without a real measurement
    (the mask, and rows of z that are nan); ``maneuver (K, ...)``: the detector's on flag
    after each step (None without a detector); ``belief``: the last belief, to continue from.
    """

    times: Array
    estimate: Gaussian
    pseudo: Array
    is_pseudo: NDArray[np.bool_]
    missing: NDArray[np.bool_]
    maneuver: NDArray[np.bool_] | None
    belief: Any


def run_with_gaps(f: Filter, prior: Any, motion: MotionModel | None, sensor: SensorModel,
                  z: ArrayLike, dt: ArrayLike, mask: ArrayLike, handler: GapHandler | str,
                  detector=None, *, t0: float = 0.0, keep_cov: bool = True) -> GapRun:
    """Run filter ``f`` over ``z (K, ..., m)`` (step k measured at ``t0 + (k + 1) dt``, see
    ``measurement_times``), with the measurements that ``mask`` (``(K,)`` or ``(K, ...)``,
    True = missing) hides, and rows of z that are nan, replaced by ``handler``'s
    pseudo-measurements.

    Each step: predict; at missing rows, ``z~ = handler.pseudo(...)`` (nan: coast); update
    with the real or pseudo measurement; remember the real ones. The detector, if given
    (``det.init(batch_shape)``, ``det.step(state, innovation)``, ``state.on``), is fed the
    innovations of real measurements only (nan residuals at missing steps hold its
    statistic): pseudo-measurements agree with the fit by construction and say nothing of a
    manoeuvre. P' reads its on flags at the gap's start. ``prior`` is a Gaussian (passed
    through ``f.init``) or the filter's own belief. The arguments come in
    :func:`~trackkit.filters.run_filter`'s order.
    """
    if isinstance(motion, np.ndarray | list) or not hasattr(sensor, "dim_z"):
        raise TypeError("run_with_gaps: expected (f, prior, motion, sensor, z, dt, mask, "
                        f"handler); got a {type(motion).__name__} for motion and a "
                        f"{type(sensor).__name__} for sensor")
    if isinstance(handler, str):
        handler = make_handler(handler)
    if not isinstance(handler, GapHandler):
        raise ValueError(f"handler = {handler!r}; expected a GapHandler or one of "
                         f"{list(HANDLER_NAMES)}")
    zs = np.asarray(z, dtype=float)
    m = sensor.dim_z
    if zs.ndim < 2 or zs.shape[-1] != m:
        raise ValueError(f"run_with_gaps: z has shape {zs.shape}; expected (K, ..., {m}) with "
                         "time on axis 0 (the sensor measures "
                         f"{m} component{'s' if m > 1 else ''})")
    K = zs.shape[0]
    miss_all = _mask(mask, "run_with_gaps mask")
    if miss_all.shape[0] != K:
        raise ValueError(f"run_with_gaps: mask has {miss_all.shape[0]} time steps and z has "
                         f"{K}; expected the same")
    times = measurement_times(K, dt, t0)
    dts = np.diff(np.concatenate([[t0], times])) if np.ndim(dt) else [float(dt)] * K
    if handler.short_window is not None and detector is None:
        raise ValueError(f"run_with_gaps: handler {handler!r} is P' (short_window) and needs "
                         "a manoeuvre detector; got detector=None")
    if isinstance(prior, Gaussian):
        b = f.init(prior) if hasattr(f, "init") else prior
    else:
        b = prior
    estimate = getattr(f, "estimate", lambda belief: belief)
    n = np.shape(estimate(b).mean)[-1]
    try:
        batch = np.broadcast_shapes(zs.shape[1:-1], miss_all.shape[1:],
                                    np.shape(estimate(b).mean)[:-1])
    except ValueError:
        raise ValueError(f"run_with_gaps: z batch shape {zs.shape[1:-1]}, mask batch shape "
                         f"{miss_all.shape[1:]} and prior batch shape "
                         f"{np.shape(estimate(b).mean)[:-1]} do not broadcast") from None
    memory = handler.init(batch, sensor)
    dstate = detector.init(batch) if detector is not None else None

    means = np.empty((K,) + batch + (n,))
    covs = np.empty((K,) + batch + (n, n)) if keep_cov else None
    pseudo = np.full((K,) + batch + (m,), np.nan)
    is_pseudo = np.zeros((K,) + batch, bool)
    missing = np.zeros((K,) + batch, bool)
    maneuver = np.zeros((K,) + batch, bool) if detector is not None else None
    for k in range(K):
        t = float(times[k])
        b = f.predict(b, motion, dts[k])
        zk = np.broadcast_to(zs[k], batch + (m,))
        miss = np.broadcast_to(miss_all[k], batch) | np.isnan(zk).any(-1)
        on = dstate.on if dstate is not None else None
        zp, memory = handler.pseudo(memory, t, miss, sensor,
                                    estimate(b) if handler.needs_estimate else None, on)
        zp = np.where(miss[..., None], zp, np.nan)
        fed = np.where(miss[..., None], zp, zk)
        b, innov = f.update(b, fed, sensor)
        real = np.where(miss[..., None], np.nan, zk)
        memory = handler.observe(memory, t, real)
        if dstate is not None:
            r = np.where(miss[..., None], np.nan, innov.nu)
            dstate = detector.step(dstate, Innovation(r, innov.cov))
            maneuver[k] = np.broadcast_to(dstate.on, batch)
        g = estimate(b)
        means[k] = np.broadcast_to(g.mean, batch + (n,))
        if covs is not None:
            covs[k] = np.broadcast_to(g.cov, batch + (n, n))
        pseudo[k] = zp
        is_pseudo[k] = miss & ~np.isnan(zp).any(-1)
        missing[k] = miss
    return GapRun(times, Gaussian._make((means, covs)), pseudo, is_pseudo, missing, maneuver, b)


# --------------------------------------------------------------------------------------------
# The same, one step at a time: a filter wrapper
# --------------------------------------------------------------------------------------------


class GapBelief(NamedTuple):
    """A :class:`WithGaps` filter's belief, leading axes the batch axes.

    ``inner``: the wrapped filter's belief; ``memory``: the handler's ``GapMemory`` (None
    until the first update, which gives the sensor); ``detector``: the detector's state (None
    without one); ``t (...)``: the time of the last prediction, the sum of the steps;
    ``pseudo (...)``: the last update was fed a pseudo-measurement; ``z_pseudo (..., m)``:
    that pseudo-measurement (nan where none; None before the first update)."""

    inner: Any
    memory: GapMemory | None
    detector: Any
    t: Array
    pseudo: NDArray[np.bool_]
    z_pseudo: Array | None


class WithGaps:
    """Filter ``f`` with a missing-measurement handler and optionally a manoeuvre detector,
    as a filter: ``init``, ``predict``, ``update``, ``estimate`` (what a per-step loop like the
    scenario engine's calls). Missing rows are those of z that are nan.

    Each step does what :func:`run_with_gaps` does: ``predict`` advances the inner filter
    and the belief's time ``t <- t + dt``; ``update`` fills the missing rows with
    ``z~ = handler.pseudo(...)``, updates the inner filter with the real or pseudo
    measurement, remembers the real ones and steps the detector with the innovations of the
    real ones. The returned innovation's residual is nan where no real measurement came, so
    the NIS counts real measurements only. With the step sequence given to
    :func:`run_with_gaps` as an array (its times the cumulative sum of the steps, the sum
    this wrapper keeps), both give the same numbers bit for bit.
    """

    def __init__(self, f: Any, handler: GapHandler | str, detector: Any = None,
                 t0: float = 0.0) -> None:
        if isinstance(handler, str):
            handler = make_handler(handler)
        if not isinstance(handler, GapHandler):
            raise ValueError(f"handler = {handler!r}; expected a GapHandler or one of "
                             f"{list(HANDLER_NAMES)}")
        if handler.short_window is not None and detector is None:
            raise ValueError(f"WithGaps: handler {handler!r} is P' (short_window) and needs a "
                             "manoeuvre detector; got detector=None")
        if not math.isfinite(t0):
            raise ValueError(f"WithGaps: t0 = {t0!r}; expected a finite start time (s)")
        self.f, self.handler, self.detector, self.t0 = f, handler, detector, float(t0)

    def _estimate(self, inner: Any) -> Gaussian:
        return self.f.estimate(inner) if hasattr(self.f, "estimate") else inner

    @property
    def stochastic(self) -> bool:
        """Whether the inner filter draws random numbers (then ``init`` takes its ``rng``)."""
        return getattr(self.f, "stochastic", False)

    def init(self, prior: Any, rng: np.random.Generator | None = None) -> GapBelief:
        """The belief from a Gaussian prior (through the inner filter's ``init``, given
        ``rng`` when the inner filter is stochastic) or from the inner filter's own belief."""
        if not (isinstance(prior, Gaussian) and hasattr(self.f, "init")):
            inner = prior
        elif self.stochastic:
            inner = self.f.init(prior, rng=rng)
        else:
            inner = self.f.init(prior)
        batch = np.shape(self._estimate(inner).mean)[:-1]
        dstate = self.detector.init(batch) if self.detector is not None else None
        return GapBelief(inner, None, dstate, np.full(batch, self.t0), np.zeros(batch, bool),
                         None)

    def predict(self, belief: GapBelief, motion: MotionModel, dt: float) -> GapBelief:
        inner = self.f.predict(belief.inner, motion, dt)
        return belief._replace(inner=inner, t=belief.t + dt)

    def update(self, belief: GapBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[GapBelief, Innovation]:
        m = sensor.dim_z
        zk = np.asarray(z, dtype=float)
        batch = belief.t.shape
        zk = np.broadcast_to(zk, batch + (m,))
        memory = belief.memory
        if memory is None:
            memory = self.handler.init(batch, sensor)
        miss = np.isnan(zk).any(-1)
        on = belief.detector.on if belief.detector is not None else None
        # every row shares the step's time; run_with_gaps passes it as a float
        t = float(belief.t.flat[0]) if belief.t.size else self.t0
        est = self._estimate(belief.inner) if self.handler.needs_estimate else None
        zp, memory = self.handler.pseudo(memory, t, miss, sensor, est, on)
        zp = np.where(miss[..., None], zp, np.nan)
        fed = np.where(miss[..., None], zp, zk)
        inner, innov = self.f.update(belief.inner, fed, sensor)
        real = np.where(miss[..., None], np.nan, zk)
        memory = self.handler.observe(memory, t, real)
        r = np.where(miss[..., None], np.nan, innov.nu)
        dstate = belief.detector
        if dstate is not None:
            dstate = self.detector.step(dstate, Innovation(r, innov.cov))
        pseudo = miss & ~np.isnan(zp).any(-1)
        out = GapBelief(inner, memory, dstate, belief.t, pseudo, zp)
        return out, innov._replace(nu=r)

    def estimate(self, belief: GapBelief) -> Gaussian:
        return self._estimate(belief.inner)

    def __repr__(self) -> str:
        return f"WithGaps({self.f!r}, {self.handler!r}, detector={self.detector!r})"
