"""Multi-target radar scenes: truth, detections, missed detections and Poisson clutter.

A :class:`Scene` is a set of :class:`Target` s (each present for ``birth <= t < death``) seen by
one or more :class:`Radar` s. :func:`simulate_scene` gives, per Monte Carlo run, the radar
plots as :class:`~trackkit.io.scans.Scans` (scans of all radars merged in time order,
``sensor`` = the radar's index), the origin of every plot (target id, or -1 for clutter) and
the truth as :class:`~trackkit.eval.track_metrics.Frames`, one frame per scan.

Truth. Every target has the state ``x = [x, y, vx, vy]`` (SI, x east, y north), given at its
birth time, and moves on the grid of distinct scan times t_0 < t_1 < ... . Over a step
[t, t + dt) (for a newborn target, from its birth to the first grid time at or after it)::

    x' = F(omega, dt) x  (+ tangential acceleration terms)  + w,   w ~ N(0, q Q_CV(dt))

with ``F(omega, dt)`` the exact constant-turn transition (omega counter-clockwise positive;
omega = 0 is constant velocity), ``Q_CV`` the continuous white-noise acceleration Q per axis
``[[dt^3/3, dt^2/2], [dt^2/2, dt]]`` and q the target's spectral density (m^2/s^3). The
manoeuvres are scripted legs (``sim.kinematics.LegPlan``, the same semantics as
``sim.kinematics.step``): a "turn" leg (nautical rate, clockwise positive) and an "accel" leg
act on every step whose start t has ``start <= t < end``, a "set" leg (course and/or speed)
or a "velocity" leg sets the velocity at the start of the step with ``t <= start < t + dt``.
So a leg acts exactly when its times lie on the scan grid (the scene builders' do).

Detections. At a scan at time t of radar j, target i is detected iff it is alive
(``birth_i <= t < death_i``), its noise-free measurement h(x_i) lies in the radar's field of
view, and ``u < pd`` (u uniform); a detection is ``z = h(x_i) + L e``, ``L L^T = R`` (the
sensor's noise), angles wrapped to (-pi, pi]. (So a plot of a target near the edge of the
field of view may fall just outside it.) Clutter: ``N ~ Poisson(lambda)`` false plots per
scan, uniform in the field of view in measurement space (uniform in range and in bearing for a
range-bearing radar), spatial density ``lambda / V`` with V the field-of-view volume. Within a
scan the plots are in random order.

Determinism. Run r draws from ``run_rng(seed, r)`` alone (``sim.streams``), in this order:

1. process noise, standard normal ``(K, n, 4)`` (K distinct scan times, n targets);
2. detection draws, uniform ``(S, n)`` (S scans);
3. measurement noise, standard normal ``(S, n, m)``;
4. clutter counts, Poisson ``(S,)`` with each scan's radar's mean;
5. clutter positions, uniform ``(C, m)``, C the sum of the counts, scan after scan;
6. order keys, uniform ``(S n + C,)``: the S n of the target plots (scan-major), then the C of
   the clutter; a scan's plots are sorted by key.

Every draw is made whether or not it is used (a target not alive, not in view, or missed still
has its noise drawn), so the sizes depend on the scene alone and a run's data depend on
(scene, seed, r) alone, never on the other runs in the batch. The arithmetic is batched over
runs and targets (leading axes; a loop over time steps only); runs are processed in chunks
of about ``_CHUNK_ELEMENTS`` state numbers, which bounds the memory for large scenes.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.eval.track_metrics import Frames
from trackkit.io.scans import Scans
from trackkit.models.motion import turn_coefficients
from trackkit.models.sensors import Position, RangeBearing
from trackkit.sim.kinematics import LegPlan
from trackkit.sim.streams import run_rng

__all__ = [
    "Radar",
    "Scene",
    "SceneRun",
    "Target",
    "propagate_targets",
    "radar_clutter",
    "radar_crossing",
    "radar_dense",
    "simulate_scene",
]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

_LEG_KINDS = ("set", "velocity", "turn", "accel")
_CHUNK_ELEMENTS = 1 << 23  # numbers per chunk of runs (about 64 MB of float64)


def _finite(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} = {value!r}; expected a finite number")
    return v


# ---------------------------------------------------------------------------------------------
# scene description
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Target:
    """One target: ``state`` [x, y, vx, vy] (m, m/s) at time ``birth``; present for
    ``birth <= t < death`` (``death`` may be inf); CV process noise of spectral density ``q``
    (m^2/s^3, 0 for a scripted path); manoeuvres ``legs`` (``LegPlan``, absolute times)."""

    state: tuple[float, float, float, float]
    birth: float = 0.0
    death: float = math.inf
    q: float = 0.0
    legs: tuple[LegPlan, ...] = ()

    def __post_init__(self) -> None:
        s = np.asarray(self.state, dtype=float)
        if s.shape != (4,) or not np.all(np.isfinite(s)):
            raise ValueError(f"Target.state = {self.state!r}; expected 4 finite numbers "
                             "[x, y, vx, vy] (m, m/s)")
        object.__setattr__(self, "state", tuple(s.tolist()))
        birth = _finite(self.birth, "Target.birth")
        death = float(self.death)
        if not (death > birth):  # also refuses nan
            raise ValueError(f"Target.birth = {birth!r} >= Target.death = {self.death!r}; "
                             "expected birth < death (present for birth <= t < death)")
        q = _finite(self.q, "Target.q")
        if q < 0:
            raise ValueError(f"Target.q = {q!r}; expected a spectral density >= 0 (m^2/s^3)")
        object.__setattr__(self, "birth", birth)
        object.__setattr__(self, "death", death)
        object.__setattr__(self, "q", q)
        legs = tuple(self.legs)
        for k, leg in enumerate(legs):
            if not isinstance(leg, LegPlan) or leg.kind not in _LEG_KINDS:
                raise ValueError(f"Target.legs[{k}] = {leg!r}; expected a LegPlan of kind "
                                 f"{', '.join(_LEG_KINDS)}")
            if leg.kind == "velocity" and (leg.velocity is None or len(leg.velocity) != 2):
                raise ValueError(f"Target.legs[{k}].velocity = {leg.velocity!r}; expected "
                                 "(vx, vy)")
            if not (math.isfinite(leg.start) and leg.end >= leg.start):
                raise ValueError(f"Target.legs[{k}]: start = {leg.start!r}, end = {leg.end!r};"
                                 " expected a finite start <= end")
        object.__setattr__(self, "legs", legs)

    @classmethod
    def moving(cls, x: float, y: float, course: float, speed: float, **kw) -> Target:
        """A target at (x, y) on ``course`` (rad, clockwise from north) at ``speed`` (m/s):
        ``v = speed [sin course, cos course]``; ``kw`` as the constructor."""
        return cls((x, y, speed * math.sin(course), speed * math.cos(course)), **kw)


@dataclass(frozen=True, eq=False)
class Radar:
    """A radar: ``sensor`` (``RangeBearing``, or 2-D ``Position``) gives h(x) and the noise R;
    ``fov`` ``((lo0, hi0), (lo1, hi1))`` the field of view in measurement space (range
    interval and bearing sector ``lo <= b <= hi`` on the circle, ``hi - lo <= 2 pi``, for a
    range-bearing radar; the rectangle x in [lo0, hi0], y in [lo1, hi1] for a position radar);
    ``pd`` in (0, 1]; ``clutter`` the mean number of false plots per scan (Poisson).
    Scans at ``start + k period`` up to the scene's end, or at the explicit ``times``
    (which then replace period and start)."""

    sensor: RangeBearing | Position
    fov: tuple[tuple[float, float], tuple[float, float]]
    pd: float = 0.9
    clutter: float = 0.0
    period: float = 3.0
    start: float = 0.0
    times: tuple[float, ...] | None = None
    _lo: Array = field(init=False, repr=False)
    _width: Array = field(init=False, repr=False)
    _angular: NDArray[np.bool_] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = self.sensor
        if not (isinstance(s, RangeBearing) or (isinstance(s, Position) and s.dim == 2)):
            raise ValueError(f"Radar.sensor = {s!r}; expected a RangeBearing or a 2-D Position")
        fov = np.asarray(self.fov, dtype=float)
        if fov.shape != (2, 2) or not np.all(np.isfinite(fov)):
            raise ValueError(f"Radar.fov = {self.fov!r}; expected finite ((lo0, hi0), (lo1, hi1))"
                             " in measurement space")
        lo, width = fov[:, 0], fov[:, 1] - fov[:, 0]
        if np.any(width <= 0):
            raise ValueError(f"Radar.fov = {self.fov!r} is empty; expected lo < hi in each "
                             "component")
        angular = np.asarray(s.angular, dtype=bool)
        if isinstance(s, RangeBearing):
            if lo[0] < 0:
                raise ValueError(f"Radar.fov range interval {tuple(fov[0])} starts below 0")
            if width[1] > 2 * np.pi:
                raise ValueError(f"Radar.fov bearing sector {tuple(fov[1])} is wider than "
                                 "2 pi; expected hi - lo <= 2 pi (rad)")
        pd = float(self.pd)
        if not 0 < pd <= 1:
            raise ValueError(f"Radar.pd = {self.pd!r}; expected a detection probability in "
                             "(0, 1]")
        clutter = float(self.clutter)
        if not (math.isfinite(clutter) and clutter >= 0):
            raise ValueError(f"Radar.clutter = {self.clutter!r}; expected a finite mean number "
                             "of false plots per scan >= 0")
        period = float(self.period)
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"Radar.period = {self.period!r}; expected a period > 0 (s)")
        start = _finite(self.start, "Radar.start")
        times = self.times
        if times is not None:
            t = np.asarray(times, dtype=float)
            if t.ndim != 1 or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
                raise ValueError(f"Radar.times = {times!r}; expected finite non-decreasing "
                                 "scan times (s)")
            times = tuple(t.tolist())
        for name, v in (("fov", tuple(map(tuple, fov.tolist()))), ("pd", pd),
                        ("clutter", clutter), ("period", period), ("start", start),
                        ("times", times), ("_lo", lo), ("_width", width),
                        ("_angular", angular)):
            object.__setattr__(self, name, v)

    @property
    def kind(self) -> str:
        """"range-bearing" or "position"."""
        return "range-bearing" if isinstance(self.sensor, RangeBearing) else "position"

    @property
    def volume(self) -> float:
        """Field-of-view volume in measurement space, ``V = prod(hi - lo)`` (m rad or m^2)."""
        return float(np.prod(self._width))

    @property
    def clutter_density(self) -> float:
        """Clutter spatial density in measurement space, ``lambda / V``."""
        return self.clutter / self.volume

    def scan_times(self, end: float) -> Array:
        """The scan times: ``times``, or ``start + k period`` for k = 0, 1, ... while
        ``<= end`` (to a relative 1e-9 of the period, so that 0, 3, ..., 300 includes 300)."""
        if self.times is not None:
            return np.asarray(self.times, dtype=float)
        if end < self.start:
            return np.empty(0)
        k = math.floor((end - self.start) / self.period + 1e-9)
        return self.start + self.period * np.arange(k + 1)

    def in_view(self, z: Array) -> NDArray[np.bool_]:
        """Whether measurements ``z`` ``(..., 2)`` lie in the field of view (an angle
        component lies in the sector iff ``(b - lo) mod 2 pi <= hi - lo``)."""
        d = np.asarray(z, dtype=float) - self._lo
        d = np.where(self._angular, np.mod(d, 2 * np.pi), d)
        return np.all((d >= 0) & (d <= self._width), axis=-1)

    def clutter_points(self, u: Array) -> Array:
        """Map uniforms ``u`` ``(..., 2)`` in [0, 1) to the field of view: ``lo + u (hi - lo)``,
        angles wrapped to (-pi, pi]."""
        z = self._lo + np.asarray(u, dtype=float) * self._width
        return np.where(self._angular, wrap(z), z)


@dataclass(frozen=True, eq=False)
class Scene:
    """Targets (their ids are their indices), radars (sensor ids are their indices) and the
    end time (s) of periodic scans; time 0 is the scene start."""

    targets: tuple[Target, ...]
    radars: tuple[Radar, ...]
    end: float

    def __post_init__(self) -> None:
        targets, radars = tuple(self.targets), tuple(self.radars)
        for k, t in enumerate(targets):
            if not isinstance(t, Target):
                raise ValueError(f"Scene.targets[{k}] = {t!r}; expected a Target")
        if not radars or not all(isinstance(r, Radar) for r in radars):
            raise ValueError(f"Scene.radars = {self.radars!r}; expected one or more Radars")
        end = _finite(self.end, "Scene.end")
        object.__setattr__(self, "targets", targets)
        object.__setattr__(self, "radars", radars)
        object.__setattr__(self, "end", end)

    @property
    def sensors(self) -> tuple[RangeBearing | Position, ...]:
        """The sensor model of each sensor id (``Scans.sensor``)."""
        return tuple(r.sensor for r in self.radars)

    @property
    def clutter_density(self) -> Array:
        """Clutter density ``lambda / V`` per sensor id, ``(n_radars,)``."""
        return np.array([r.clutter_density for r in self.radars])

    def scan_times(self) -> tuple[Array, IntArray]:
        """Times ``(S,)`` and radar ids ``(S,)`` of all scans, in time order (radar order at
        equal times)."""
        ts = [r.scan_times(self.end) for r in self.radars]
        t = np.concatenate(ts) if ts else np.empty(0)
        j = np.repeat(np.arange(len(ts), dtype=np.int64), [len(x) for x in ts])
        order = np.lexsort((j, t))
        return t[order], j[order]


@dataclass(frozen=True, eq=False)
class SceneRun:
    """One Monte Carlo run: ``scans`` (plots in random order within a scan), ``origin (N,)``
    the target id of each plot or -1 for clutter, and ``truth``, one frame per scan of the
    targets alive at the scan (``x`` the states [x, y, vx, vy], ``ids`` the target ids)."""

    run: int
    scans: Scans
    origin: IntArray
    truth: Frames

    @property
    def truth_positions(self) -> Frames:
        """``truth`` with positions only (for OSPA / GOSPA on positions)."""
        return Frames(self.truth.offsets, self.truth.x[:, :2], self.truth.ids)


# ---------------------------------------------------------------------------------------------
# truth
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Legs:
    """All targets' legs as flat arrays, leg order kept within each target."""

    target: IntArray
    kind: IntArray  # index into _LEG_KINDS
    start: Array
    end: Array
    rate: Array
    accel: Array
    course: Array  # nan: keep
    speed: Array  # nan: keep
    vel: Array  # (L, 2), for "velocity" legs

    @classmethod
    def of(cls, targets: Sequence[Target]) -> _Legs:
        rows = [(i, leg) for i, t in enumerate(targets) for leg in t.legs]

        def col(f, dtype=float):
            return np.array([f(i, leg) for i, leg in rows], dtype=dtype).reshape(len(rows))

        def opt(v):
            return np.nan if v is None else v

        return cls(
            col(lambda i, g: i, np.int64), col(lambda i, g: _LEG_KINDS.index(g.kind), np.int64),
            col(lambda i, g: g.start), col(lambda i, g: g.end), col(lambda i, g: g.rate),
            col(lambda i, g: g.accel), col(lambda i, g: opt(g.course)),
            col(lambda i, g: opt(g.speed)),
            np.array([g.velocity if g.kind == "velocity" else (np.nan, np.nan)
                      for _, g in rows], dtype=float).reshape(len(rows), 2),
        )


def _set_velocities(x: Array, legs: _Legs, tx: Array, dt: Array) -> None:
    """Apply the "set" and "velocity" legs with ``tx <= start < tx + dt`` to ``x`` (R, n, 4)
    in place, one leg per target at a time in leg order (as ``kinematics.step``)."""
    trig = legs.kind <= 1
    if not trig.any():
        return
    i = legs.target
    trig &= (tx[i] <= legs.start) & (legs.start < tx[i] + dt[i])
    idx = np.flatnonzero(trig)
    while idx.size:
        _, first = np.unique(i[idx], return_index=True)
        now, idx = idx[first], np.delete(idx, first)
        tgt = i[now]
        v = x[:, tgt, 2:4]
        speed = np.where(np.isnan(legs.speed[now]), np.hypot(v[..., 0], v[..., 1]),
                         legs.speed[now])
        course = np.where(np.isnan(legs.course[now]), np.arctan2(v[..., 0], v[..., 1]),
                          legs.course[now])
        new = np.stack([speed * np.sin(course), speed * np.cos(course)], -1)
        is_vel = legs.kind[now] == 1
        x[:, tgt, 2:4] = np.where(is_vel[:, None], legs.vel[now], new)


def propagate_targets(
    targets: Sequence[Target], times: ArrayLike, noise: Array | None = None
) -> Array:
    """States of the targets at the increasing ``times`` ``(K,)``, ``(R, K, n, 4)``.

    ``noise`` ``(R, K, n, 4)`` standard normals (None: no process noise, R = 1). Before its
    birth a target holds its initial state; from its birth it moves as the module docstring
    says (turn, acceleration and set legs, then ``w = sqrt(q) L(dt) e``, ``L`` the Cholesky
    factor of ``Q_CV(dt)``), also after its death (the caller masks it out).
    """
    times = np.asarray(times, dtype=float)
    n, K = len(targets), times.shape[0]
    if times.ndim != 1 or np.any(np.diff(times) <= 0):
        raise ValueError("times: expected strictly increasing times (K,)")
    R = 1 if noise is None else noise.shape[0]
    if noise is not None and noise.shape != (R, K, n, 4):
        raise ValueError(f"noise has shape {noise.shape}; expected (R, {K}, {n}, 4)")
    birth = np.array([t.birth for t in targets], dtype=float).reshape(n)
    sq = np.sqrt(np.array([t.q for t in targets], dtype=float).reshape(n))
    x = np.broadcast_to(np.array([t.state for t in targets], dtype=float).reshape(n, 4),
                        (R, n, 4)).copy()
    legs = _Legs.of(targets)
    has_turn, has_accel = np.any(legs.kind == 2), np.any(legs.kind == 3)
    tx = birth.copy()  # time of each target's current state
    out = np.empty((R, K, n, 4))
    for k, t in enumerate(times):
        born = birth <= t
        dt = np.where(born, t - tx, 0.0)
        _set_velocities(x, legs, tx, dt)
        px, py, vx, vy = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
        nx = np.empty_like(x)
        if has_turn:
            act = (legs.kind == 2) & (legs.start <= tx[legs.target]) & (tx[legs.target] < legs.end)
            rate = np.bincount(legs.target, np.where(act, legs.rate, 0.0), minlength=n)
            # the transition is counter-clockwise positive; a nautical (starboard) rate is -w
            s, c, _, _, cos, sin = turn_coefficients(-rate, dt)
            nx[..., 0] = px + s * vx - c * vy
            nx[..., 1] = py + c * vx + s * vy
            nx[..., 2] = cos * vx - sin * vy
            nx[..., 3] = sin * vx + cos * vy
        else:
            nx[..., 0] = px + dt * vx
            nx[..., 1] = py + dt * vy
            nx[..., 2:] = x[..., 2:]
        if has_accel:
            act = (legs.kind == 3) & (legs.start <= tx[legs.target]) & (tx[legs.target] < legs.end)
            acc = np.bincount(legs.target, np.where(act, legs.accel, 0.0), minlength=n)
            speed = np.hypot(vx, vy)
            u = x[..., 2:] / np.where(speed > 0, speed, 1.0)[..., None]
            nx[..., :2] += (0.5 * acc * dt**2)[:, None] * u
            nx[..., 2:] += (acc * dt)[:, None] * u
        if noise is not None:
            # Cholesky factor of Q_CV(dt) per axis: [[sqrt(dt^3/3), 0], [sqrt(3 dt)/2, sqrt(dt)/2]]
            e = noise[:, k]
            rdt = np.sqrt(dt)
            l11, l21, l22 = sq * dt * rdt / math.sqrt(3), sq * math.sqrt(3) / 2 * rdt, sq * rdt / 2
            nx[..., :2] += l11[:, None] * e[..., :2]
            nx[..., 2:] += l21[:, None] * e[..., :2] + l22[:, None] * e[..., 2:]
        x = nx
        tx = np.where(born, t, tx)
        out[:, k] = x
    return out


# ---------------------------------------------------------------------------------------------
# simulation
# ---------------------------------------------------------------------------------------------


def simulate_scene(scene: Scene, runs: Iterable[int] | int, seed: int) -> list[SceneRun]:
    """Simulate the runs ``runs`` (run indices >= 0, or a count: ``range(runs)``) of
    ``scene``, run r from ``run_rng(seed, r)`` alone (see the module docstring).

    Returns one :class:`SceneRun` per run, in the order given: its ``scans`` (``S`` scans of
    every radar in time order, ``sensor`` the radar index), ``origin`` (target id of each plot,
    -1 for clutter) and ``truth`` (one frame per scan). The clutter density the association
    needs is ``scene.clutter_density[sensor]`` (``lambda / V``).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"scene = {scene!r}; expected a Scene")
    runs = list(range(int(runs)) if isinstance(runs, int | np.integer) else runs)
    if not all(isinstance(r, int | np.integer) and r >= 0 for r in runs):
        raise ValueError(f"runs = {runs!r}; expected run indices >= 0")
    runs = [int(r) for r in runs]
    times, radar = scene.scan_times()
    grid, kscan = np.unique(times, return_inverse=True)
    S, K, n = len(times), len(grid), len(scene.targets)
    per_run = max(1, 8 * (K + S) * n)  # the noise, truth and plot arrays of one run
    chunk = max(1, _CHUNK_ELEMENTS // per_run)
    out: list[SceneRun] = []
    for c in range(0, len(runs), chunk):
        out += _simulate_chunk(scene, runs[c:c + chunk], seed, times, radar, grid, kscan)
    return out


def _simulate_chunk(scene: Scene, runs: list[int], seed: int, times: Array, radar: IntArray,
                    grid: Array, kscan: IntArray) -> list[SceneRun]:
    targets, radars = scene.targets, scene.radars
    R, S, K, n, m = len(runs), len(times), len(grid), len(targets), 2
    lam = np.array([r.clutter for r in radars])[radar]
    # draws, per run in the documented order (sizes fixed by the scene)
    w = np.empty((R, K, n, 4))
    u = np.empty((R, S, n))
    e = np.empty((R, S, n, m))
    counts = np.empty((R, S), dtype=np.int64)
    uc: list[Array] = []
    keys_t = np.empty((R, S, n))
    keys_c: list[Array] = []
    for b, r in enumerate(runs):
        g = run_rng(seed, r)
        w[b] = g.standard_normal((K, n, 4))
        u[b] = g.random((S, n))
        e[b] = g.standard_normal((S, n, m))
        counts[b] = g.poisson(lam)
        C = int(counts[b].sum())
        uc.append(g.random((C, m)))
        keys = g.random(S * n + C)
        keys_t[b] = keys[:S * n].reshape(S, n)
        keys_c.append(keys[S * n:])
    truth = propagate_targets(targets, grid, w) if K else np.empty((R, 0, n, 4))
    birth = np.array([t.birth for t in targets]).reshape(n)
    death = np.array([t.death for t in targets]).reshape(n)
    alive = (birth <= times[:, None]) & (times[:, None] < death)  # (S, n)
    # target plots, radar by radar (batched over runs, its scans and targets)
    z = np.empty((R, S, n, m))
    det = np.zeros((R, S, n), dtype=bool)
    for j, rad in enumerate(radars):
        sj = np.flatnonzero(radar == j)
        if not sj.size:
            continue
        zt = rad.sensor.h(truth[:, kscan[sj]])  # (R, Sj, n, m)
        det[:, sj] = alive[sj] & rad.in_view(zt) & (u[:, sj] < rad.pd)
        L = np.linalg.cholesky(rad.sensor.noise)
        ej = e[:, sj]
        # z = h(x) + L e written out (m = 2), so each number's rounding is independent of
        # the batch shape (a matmul may pick another kernel for another batch size)
        zj = zt + ej[..., :1] * L[:, 0] + ej[..., 1:] * L[:, 1]
        z[:, sj] = np.where(rad._angular, wrap(zj), zj)
    rt, st, it = np.nonzero(det)
    # clutter plots
    cflat = counts.ravel()
    rc = np.repeat(np.repeat(np.arange(R), S), cflat)
    sc = np.repeat(np.tile(np.arange(S), R), cflat)
    uc_all = np.concatenate(uc) if uc else np.empty((0, m))
    lo = np.array([r._lo for r in radars])
    width = np.array([r._width for r in radars])
    ang = np.array([r._angular for r in radars])
    zc = lo[radar[sc]] + uc_all * width[radar[sc]]
    zc = np.where(ang[radar[sc]], wrap(zc), zc)
    # merge and shuffle within each scan by the order keys
    run_of = np.concatenate([rt, rc])
    scan_of = np.concatenate([st, sc])
    zz = np.concatenate([z[rt, st, it], zc])
    origin = np.concatenate([it, np.full(len(rc), -1)]).astype(np.int64)
    key = np.concatenate([keys_t[rt, st, it], np.concatenate(keys_c) if keys_c else []])
    order = np.lexsort((key, scan_of, run_of))
    zz, origin = zz[order], origin[order]
    per_scan = np.bincount(run_of * S + scan_of, minlength=R * S).reshape(R, S)
    bounds = np.concatenate([[0], np.cumsum(per_scan.sum(1))])
    # truth frames: the alive targets of each scan (the same ids in every run)
    sa, ia = np.nonzero(alive)
    f_off = np.concatenate([[0], np.cumsum(alive.sum(1))]).astype(np.int64)
    xa = truth[:, kscan[sa], ia]  # (R, M, 4)
    result = []
    for b, r in enumerate(runs):
        a, z1 = bounds[b], bounds[b + 1]
        offsets = np.concatenate([[0], np.cumsum(per_scan[b])]).astype(np.int64)
        scans = Scans(zz[a:z1], offsets, times, radar)
        result.append(SceneRun(r, scans, origin[a:z1].copy(),
                               Frames(f_off, xa[b].copy(), ia.astype(np.int64))))
    return result


# ---------------------------------------------------------------------------------------------
# scene builders
# ---------------------------------------------------------------------------------------------

_DEG = math.pi / 180


def radar_crossing(*, pd: float = 0.9, clutter: float = 20.0, q: float = 1e-4) -> Scene:
    """Three fast craft (40 and 35 m/s, boats or helicopters) whose paths cross and run close,
    seen by a coastal surveillance radar: the case where GNN and JPDA differ.

    Radar at the origin: range-bearing, sigma 25 m and 0.3 deg (a 3 s rotation X-band
    surveillance radar; at the targets' 12-19 km the bearing error is 65-100 m across range,
    comparable with the targets' separation), field of view 2-30 km and bearings 0-90 deg
    (the sector watched), ``pd`` and ``clutter`` false plots per scan (20: a density of
    4.5e-4 per m rad). Scans at 0, 3, ..., 300 s (101 scans). Targets (ids), all present
    throughout, q = 1e-4 m^2/s^3 (nearly the scripted paths: after 300 s, 0.17 m/s and 30 m
    off them, one sigma):

    * 0, "A": from (3, 12) km east (090 deg) at 40 m/s, straight, to (15, 12) km.
    * 1, "B": from (3.2, 12.7) km, course 100 deg at 40 m/s, converging on A at 10 deg (700 m
      apart at t = 0); crosses A's track at t = 99 s, 100 m ahead of A; turns to port onto
      090 deg over 117-126 s; runs parallel to A 156 m to its south and 87 m ahead (179 m
      apart) from 126 to 210 s; then turns 30 deg to starboard over 210-225 s and opens on
      120 deg (1.8 km from A at 300 s).
    * 2, "C": from (11.6, 6.5) km, course 340 deg at 35 m/s, crossing B's track then A's
      (150 m behind A) at t = 160-170 s, while they run parallel.

    Without process noise the closest approaches are A-B 100 m (t = 99 s), A-C 99 m
    (t = 165 s) and B-C 85 m (t = 162 s); the targets are 12-19 km from the radar, at
    bearings 14-61 deg (the tests check these claims).
    """
    v = 40.0
    ax0, y_a = 3000.0, 12000.0
    tc = 99.0  # B crosses A's track here, 100 m ahead of A
    vb = (v * math.sin(100 * _DEG), v * math.cos(100 * _DEG))
    xc = ax0 + v * tc + 100.0
    b0 = (xc - vb[0] * tc, y_a - vb[1] * tc)
    vc = 35.0
    t3, x3 = 168.0, ax0 + v * 168.0 - 150.0  # C crosses A's track 150 m behind A
    c_vel = (vc * math.sin(340 * _DEG), vc * math.cos(340 * _DEG))
    c0 = (x3 - c_vel[0] * t3, y_a - c_vel[1] * t3)
    targets = (
        Target((ax0, y_a, v, 0.0), q=q),
        Target((*b0, *vb), q=q, legs=(
            LegPlan("turn", 117.0, 126.0, rate=-10 * _DEG / 9.0),
            LegPlan("turn", 210.0, 225.0, rate=2 * _DEG),
        )),
        Target((*c0, *c_vel), q=q),
    )
    radar = Radar(RangeBearing((0.0, 0.0), 25.0, 0.3 * _DEG),
                  fov=((2000.0, 30000.0), (0.0, 90 * _DEG)), pd=pd, clutter=clutter, period=3.0)
    return Scene(targets, (radar,), end=300.0)


def _air_radar(pd: float, clutter: float) -> Radar:
    """A long-range air surveillance radar at the origin: 4 s rotation, all round, instrumented
    1-40 km, sigma 40 m in range and 0.5 deg in bearing (about 170 m across range at 20 km)."""
    return Radar(RangeBearing((0.0, 0.0), 40.0, 0.5 * _DEG),
                 fov=((1000.0, 40000.0), (-math.pi, math.pi)), pd=pd, clutter=clutter,
                 period=4.0)


def radar_clutter(*, pd: float = 0.9, clutter: float = 20.0, q: float = 0.1) -> Scene:
    """Ten aircraft through an air surveillance radar's coverage with 20 false plots per scan.

    Radar: ``_air_radar`` (4 s scans, 1-40 km, all round, 40 m and 0.5 deg), ``pd``,
    ``clutter`` false plots per scan (20: a density of 8.2e-5 per m rad). Scans at 0, 4, ...,
    400 s (101 scans). Target i = 0..9 is born at 20 i s on the 30 km circle at bearing
    36 i + 10 deg, flying at 60 + 10 i m/s across the coverage on the reciprocal bearing
    turned by 20 deg (alternately to port and starboard, so the tracks miss the radar by about
    10 km and cross each other); targets 3 and 6 make a 90 deg starboard turn over 32 s at
    t = 200 s; targets 2, 5 and 8 die 180 s after their birth (220, 280 and 340 s), the others
    live to the end. q = 0.1 m^2/s^3 (gentle wander: 6 m/s of velocity random walk in 400 s).
    Without process noise every target stays 10-31 km from the radar (in view) while alive.
    """
    targets = []
    for i in range(10):
        brg = (36 * i + 10) * _DEG
        course = brg + math.pi + (20 if i % 2 else -20) * _DEG
        birth = 20.0 * i
        legs = (LegPlan("turn", 200.0, 232.0, rate=90 * _DEG / 32),) if i in (3, 6) else ()
        targets.append(Target.moving(30e3 * math.sin(brg), 30e3 * math.cos(brg), course,
                                     60.0 + 10 * i, birth=birth, q=q, legs=legs,
                                     death=birth + 180.0 if i in (2, 5, 8) else math.inf))
    return Scene(tuple(targets), (_air_radar(pd, clutter),), end=400.0)


def radar_dense(n: int = 200, *, pd: float = 0.9, clutter: float = 50.0, q: float = 0.1,
                end: float = 1200.0, seed: int = 0) -> Scene:
    """``n`` targets spread over an air surveillance radar's coverage, for scale.

    Radar: ``_air_radar`` (4 s scans, 1-40 km all round, 40 m and 0.5 deg), ``pd``,
    ``clutter`` false plots per scan (50: 2e-4 per m rad). Scans at 0, 4, ..., ``end``
    (301 scans for 1200 s). The targets are drawn once from ``default_rng(seed)`` (the scene
    is fixed; runs differ only in their noise): born uniformly in [0, end / 2], at a point
    uniform in area in the 3-35 km annulus, on a uniform course, at a speed log-uniform in
    5-300 m/s (ships to jets), straight (q = 0.1 m^2/s^3); a target dies when its straight
    path leaves the 38 km circle (still in view), or lives to the end. The mean spacing of
    200 targets is about 4 km (3800 km^2 / 200 = 19 km^2 each), so most targets are well
    apart, while some pairs pass close by chance.
    """
    if int(n) != n or n < 0:
        raise ValueError(f"n = {n!r}; expected a number of targets >= 0")
    rng = np.random.default_rng(seed)
    n = int(n)
    birth = rng.uniform(0.0, end / 2, n)
    r = np.sqrt(rng.uniform(3e3**2, 35e3**2, n))
    brg = rng.uniform(-np.pi, np.pi, n)
    course = rng.uniform(-np.pi, np.pi, n)
    speed = np.exp(rng.uniform(np.log(5.0), np.log(300.0), n))
    p = np.stack([r * np.sin(brg), r * np.cos(brg)], -1)
    v = np.stack([speed * np.sin(course), speed * np.cos(course)], -1)
    # exit time from the 38 km circle: the positive root of |p + v t|^2 = 38 km^2
    pv, vv = np.sum(p * v, -1), speed**2
    t_exit = (-pv + np.sqrt(pv**2 - vv * (np.sum(p * p, -1) - 38e3**2))) / vv
    death = np.where(birth + t_exit < end, birth + t_exit, np.inf)
    targets = tuple(Target((*p[i], *v[i]), birth=float(birth[i]), death=float(death[i]), q=q)
                    for i in range(n))
    return Scene(targets, (_air_radar(pd, clutter),), end=end)
