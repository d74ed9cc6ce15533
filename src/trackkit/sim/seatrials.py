"""Sea-trial manoeuvres of the vessel model of Zolfagharnasab and Seif (2025), batched over leading
run axes.

Every trial starts at t = 0 on a straight course (heading ``psi0``, body state
``[speed, 0, 0]``, nozzle amidships) and executes its first command at t = 0. Between output
samples ``t_k = k dt`` it takes ``substeps`` forward-Euler steps of ``h = dt / substeps``::

    x <- x + h f(x, s_m, theta) + w,   s_m = (s(t) + s(t + h)) / 2,   w ~ N(0, q h)

so ``substeps=1`` is exactly the paper's discrete model (eq. 4) on the recorded samples, and
more substeps approach the continuous model. The pose follows the exact arc with the body
velocity held at the mean of each sub-step's ends (``models.manoeuvring.integrate_pose``).

The applied nozzle angle follows its command at a limited rate: ``rate_limit`` defaults to
15 deg/s, our choice for a hydraulic waterjet nozzle (hard over to hard over, 2 x 30 deg, in
4 s; a conventional rudder needs 28 s from 35 deg one side to 30 deg the other under SOLAS,
about 2.3 deg/s). Engine speed follows its command at ``rpm_rate`` (200 rpm/s by default:
1000 to 2000 rpm in 5 s, our choice for a high-speed diesel).

Each run switches on its own heading (masks over the batch); only time is looped over.
Process noise uses ``rng``: one ``numpy.random.Generator`` for the whole batch, or one per run
(a sequence over the flattened batch), in which case a run's noise does not depend on the
other runs in the batch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.models.manoeuvring import (
    N_THETA,
    Normalisation,
    advance_pose_unchecked,
    rhs_unchecked,
    straight_line_speed,
)
from trackkit.renamed import renamed_keywords

__all__ = ["Trial", "turning_circle", "zigzag", "acceleration_run"]

Array = NDArray[np.float64]
Rng = np.random.Generator | Sequence[np.random.Generator] | None

_NOZZLE_RATE = math.radians(15.0)  # rad/s
_RPM_RATE = 200.0  # rpm/s


class Trial(NamedTuple):
    """A simulated trial: ``t (K,)`` s and, per run ``(..., K)``, the applied nozzle angle
    ``delta`` (rad) and engine speed ``n`` (rpm), the body states ``u, v`` (m/s), ``r``
    (rad/s) and the pose ``east, north`` (m), ``psi`` (rad, clockwise from north, unwrapped)."""

    t: Array
    delta: Array
    n: Array
    u: Array
    v: Array
    r: Array
    east: Array
    north: Array
    psi: Array


def _positive(value: float, name: str, allow_inf: bool = False) -> float:
    v = float(value)
    if not (v > 0 and (math.isfinite(v) or (allow_inf and v == math.inf))):
        want = "a number > 0 (inf allowed)" if allow_inf else "a finite number > 0"
        raise ValueError(f"{name} = {value!r}; expected {want}")
    return v


def _finite(value: ArrayLike, name: str) -> Array:
    a = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} = {a.tolist()!r}; expected finite values")
    return a


class _Noise:
    """``sqrt(q h) N(0, I)`` per sub-step; per-run generators draw blocks of steps."""

    _BLOCK = 256

    def __init__(self, q: ArrayLike | None, rng: Rng, batch: tuple[int, ...], h: float):
        self.sd = None
        if q is None:
            return
        q = np.broadcast_to(_finite(q, "q"), (3,)) if np.ndim(q) == 0 else _finite(q, "q")
        if q.shape != (3,) or np.any(q < 0):
            raise ValueError(f"q = {q.tolist()!r}; expected 3 spectral densities >= 0 "
                             "(m^2/s^3, m^2/s^3, rad^2/s^3)")
        if rng is None:
            raise ValueError("rng = None; process noise q needs a numpy.random.Generator")
        self.sd, self.batch, self.rng = np.sqrt(q * h), batch, rng
        if not isinstance(rng, np.random.Generator):
            self.rng = list(rng)
            if len(self.rng) != math.prod(batch):
                raise ValueError(f"rng has {len(self.rng)} generators; expected one per run "
                                 f"({math.prod(batch)} for batch shape {batch})")
            self.buf, self.i = None, self._BLOCK

    def draw(self) -> Array | float:
        if self.sd is None:
            return 0.0
        if isinstance(self.rng, np.random.Generator):
            return self.sd * self.rng.standard_normal(self.batch + (3,))
        if self.i == self._BLOCK:
            blocks = [g.standard_normal((self._BLOCK, 3)) for g in self.rng]
            self.buf = np.stack(blocks, 1).reshape((self._BLOCK,) + self.batch + (3,))
            self.i = 0
        self.i += 1
        return self.sd * self.buf[self.i - 1]


Command = Callable[[float, Array], tuple[Array, Array]]


def _run(theta: Array, norm: Normalisation, batch: tuple[int, ...], speed: Array,
         psi0: Array, delta0: Array, n0: Array, command: Command,
         done: Callable[[Array], Array] | None, *, dt: float, substeps: int,
         duration: float | None, max_duration: float, rate_limit: float, rpm_rate: float,
         q: ArrayLike | None, rng: Rng) -> Trial:
    """The shared time loop; ``command(t, pose)`` gives the commanded ``(delta, n)``."""
    dt = _positive(dt, "dt")
    if not (isinstance(substeps, int | np.integer) and substeps >= 1):
        raise ValueError(f"substeps = {substeps!r}; expected an integer >= 1")
    rate_limit = _positive(rate_limit, "rate_limit", allow_inf=True)
    rpm_rate = _positive(rpm_rate, "rpm_rate", allow_inf=True)
    max_duration = _positive(max_duration, "max_duration")
    if duration is not None:
        duration = _positive(duration, "duration")
    h = dt / substeps
    K = int(math.floor((duration if duration is not None else max_duration) / dt + 1e-9))
    noise = _Noise(q, rng, batch, h)
    zero = np.zeros(batch)
    x = np.stack([speed + zero, zero, zero], -1)
    pose = np.stack([zero, zero, psi0 + zero], -1)
    d, n = delta0 + zero, n0 + zero
    rec = [(d, n, x, pose)]
    for k in range(K):
        if duration is None and done is not None and done(pose).all():
            break
        for j in range(substeps):
            dc, nc = command(k * dt + j * h, pose)
            d1 = d + np.clip(dc - d, -rate_limit * h, rate_limit * h)
            n1 = n + np.clip(nc - n, -rpm_rate * h, rpm_rate * h)
            s_m = np.stack([0.5 * (d + d1), 0.5 * (n + n1)], -1)
            x1 = x + h * rhs_unchecked(x, s_m, theta, norm) + noise.draw()
            pose = advance_pose_unchecked(pose, 0.5 * (x + x1), h)
            x, d, n = x1, d1, n1
        rec.append((d, n, x, pose))
    D, N, X, P = (np.stack(a, -1) for a in zip(*rec, strict=True))
    t = dt * np.arange(D.shape[-1])
    return Trial(t, D, N, X[..., 0, :], X[..., 1, :], X[..., 2, :], P[..., 0, :],
                 P[..., 1, :], P[..., 2, :])


def _setup(theta: ArrayLike, norm: Normalisation, rpm: ArrayLike, speed: ArrayLike | None,
           rpm_name: str = "rpm", **extra: ArrayLike
           ) -> tuple[Array, tuple[int, ...], Array, Array, dict]:
    """Check and broadcast: ``(theta, batch, rpm, speed, extras)``; speed defaults to the
    straight-line equilibrium at ``rpm``."""
    theta = np.asarray(theta, dtype=float)
    if theta.ndim < 1 or theta.shape[-1] != N_THETA or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta has shape {theta.shape}; expected finite (..., {N_THETA})")
    if not isinstance(norm, Normalisation):
        raise ValueError(f"norm = {norm!r}; expected a trackkit.models.manoeuvring.Normalisation")
    rpm = _finite(rpm, rpm_name)
    if np.any(rpm < 0):
        raise ValueError(f"{rpm_name} = {rpm.tolist()!r}; expected engine speeds >= 0")
    if speed is None:
        speed = straight_line_speed(theta, rpm, norm)
        if not np.all(np.isfinite(speed)):
            raise ValueError("speed = None but these coefficients have no stable straight-line "
                             f"speed at {rpm_name} = {rpm.tolist()!r}; give the approach "
                             "speed (m/s)")
    speed = _finite(speed, "speed")
    extra = {k: _finite(v, k) for k, v in extra.items()}
    shapes = [theta.shape[:-1], rpm.shape, speed.shape] + [v.shape for v in extra.values()]
    try:
        batch = np.broadcast_shapes(*shapes)
    except ValueError:
        raise ValueError(f"run axes do not broadcast: theta {theta.shape[:-1]}, {rpm_name} "
                         f"{rpm.shape}, speed {speed.shape}, "
                         + ", ".join(f"{k} {v.shape}" for k, v in extra.items())) from None
    return theta, batch, rpm, speed, extra


def _side(side: ArrayLike) -> Array:
    s = np.asarray(side, dtype=float)
    if not np.all(np.isin(s, (-1.0, 1.0))):
        raise ValueError(f"side = {s.tolist()!r}; expected +1 (starboard) or -1 (port)")
    return s


@renamed_keywords(T="dt")
def turning_circle(theta: ArrayLike, norm: Normalisation, *, delta: ArrayLike,
                   rpm: ArrayLike, speed: ArrayLike | None = None, side: ArrayLike = 1.0,
                   psi0: ArrayLike = 0.0, dt: float = 1.0, substeps: int = 10,
                   duration: float | None = None, max_duration: float = 1800.0,
                   rate_limit: float = _NOZZLE_RATE, rpm_rate: float = _RPM_RATE,
                   q: ArrayLike | None = None, rng: Rng = None) -> Trial:
    """Turning circle: nozzle put to ``side * delta`` (rad; side +1 starboard, -1 port) at
    t = 0 and held. With ``duration=None`` it runs until every run's heading has changed by
    at least 540 deg (checked at the samples; at most ``max_duration``)."""
    theta, batch, rpm, speed, ex = _setup(theta, norm, rpm, speed, delta=delta,
                                          side=_side(side), psi0=psi0)
    target = ex["side"] * np.abs(ex["delta"]) + np.zeros(batch)

    def command(t: float, pose: Array) -> tuple[Array, Array]:
        return target, rpm

    def done(pose: Array) -> Array:
        return np.abs(pose[..., 2] - ex["psi0"]) >= 3 * np.pi

    return _run(theta, norm, batch, speed, ex["psi0"], 0.0, rpm, command, done, dt=dt,
                substeps=substeps, duration=duration, max_duration=max_duration,
                rate_limit=rate_limit, rpm_rate=rpm_rate, q=q, rng=rng)


@renamed_keywords(T="dt")
def zigzag(theta: ArrayLike, norm: Normalisation, *, delta: ArrayLike, alpha: ArrayLike,
           rpm: ArrayLike, speed: ArrayLike | None = None, side: ArrayLike = 1.0,
           psi0: ArrayLike = 0.0, commands: int = 5, dt: float = 1.0, substeps: int = 10,
           duration: float | None = None, max_duration: float = 1800.0,
           rate_limit: float = _NOZZLE_RATE, rpm_rate: float = _RPM_RATE,
           q: ArrayLike | None = None, rng: Rng = None) -> Trial:
    """A ``delta/alpha`` zig-zag (10/10: both 10 deg, in rad here). Command 1 at t = 0 puts
    the nozzle to ``side * delta``; each run reverses it when its own heading deviation
    ``e = side (psi - psi0)`` reaches ``+alpha`` (nozzle then to the other side) or
    ``-alpha``, until ``commands`` commands are given. With ``duration=None`` it runs until
    every run's heading, after the last command, reaches the angle at which the next command
    would be due (at most ``max_duration``)."""
    theta, batch, rpm, speed, ex = _setup(theta, norm, rpm, speed, delta=delta, alpha=alpha,
                                          side=_side(side), psi0=psi0)
    if not (isinstance(commands, int | np.integer) and commands >= 1):
        raise ValueError(f"commands = {commands!r}; expected an integer >= 1")
    if np.any(ex["alpha"] <= 0):
        raise ValueError(f"alpha = {ex['alpha'].tolist()!r}; expected heading angles > 0 rad")
    side_, amp, alpha_ = ex["side"], np.abs(ex["delta"]), ex["alpha"]
    sign = np.ones(batch)  # +1: nozzle to side, -1: to the other side
    given = np.ones(batch, dtype=int)
    finished = np.zeros(batch, bool)

    def reached(pose: Array) -> Array:
        return sign * side_ * (pose[..., 2] - ex["psi0"]) >= alpha_

    def command(t: float, pose: Array) -> tuple[Array, Array]:
        nonlocal sign, given, finished
        hit, last = reached(pose), given >= commands
        finished = finished | (last & hit)
        switch = ~last & hit
        sign = np.where(switch, -sign, sign)
        given = given + switch
        return side_ * sign * amp, rpm

    def done(pose: Array) -> Array:
        return finished | ((given >= commands) & reached(pose))

    return _run(theta, norm, batch, speed, ex["psi0"], 0.0, rpm, command, done,
                dt=dt, substeps=substeps, duration=duration, max_duration=max_duration,
                rate_limit=rate_limit, rpm_rate=rpm_rate, q=q, rng=rng)


@renamed_keywords(T="dt")
def acceleration_run(theta: ArrayLike, norm: Normalisation, *, rpm_start: ArrayLike,
                     rpm_end: ArrayLike, t_step: float = 10.0, speed: ArrayLike | None = None,
                     psi0: ArrayLike = 0.0, dt: float = 1.0, substeps: int = 10,
                     duration: float = 120.0, rate_limit: float = _NOZZLE_RATE,
                     rpm_rate: float = _RPM_RATE, q: ArrayLike | None = None,
                     rng: Rng = None) -> Trial:
    """Acceleration run at zero nozzle: engine speed commanded from ``rpm_start`` to
    ``rpm_end`` at ``t_step`` (s), from the straight-line speed at ``rpm_start`` unless
    ``speed`` is given."""
    theta, batch, rpm0, speed, ex = _setup(theta, norm, rpm_start, speed, "rpm_start",
                                           rpm_end=rpm_end, psi0=psi0)
    if np.any(ex["rpm_end"] < 0):
        raise ValueError(f"rpm_end = {ex['rpm_end'].tolist()!r}; expected engine speeds >= 0")
    t_step = float(_finite(t_step, "t_step"))
    zero = np.zeros(batch)

    def command(t: float, pose: Array) -> tuple[Array, Array]:
        return zero, (ex["rpm_end"] if t >= t_step - 1e-12 else rpm0) + zero

    return _run(theta, norm, batch, speed, ex["psi0"], 0.0, rpm0, command, None, dt=dt,
                substeps=substeps, duration=duration, max_duration=duration,
                rate_limit=rate_limit, rpm_rate=rpm_rate, q=q, rng=rng)
