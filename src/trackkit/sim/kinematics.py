"""Platform kinematics: initial state plus manoeuvre legs, batched over runs.

A platform state is ``[p..., v...]`` (dim 2 or 3). Between steps it moves in a straight line,
or on a circular arc while a turn leg is active (the exact constant-turn transition), or with
a tangential acceleration; a course/speed leg sets the horizontal velocity, and a velocity
leg the whole velocity, at the start of the step interval that contains its start time.
Process noise, when given, is added after each step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackkit.models.motion import turn_transition

Array = NDArray[np.float64]

__all__ = ["LegPlan", "propagate"]


@dataclass(frozen=True)
class LegPlan:
    """A leg in SI: ``kind`` is "set", "velocity", "turn" or "accel". Turn rate is nautical
    (clockwise positive, rad/s); a "set" leg carries the new course (rad) and/or speed (m/s),
    a "velocity" leg the new velocity components (m/s, all ``dim`` of them)."""

    kind: str
    start: float
    end: float = np.inf
    course: float | None = None
    speed: float | None = None
    rate: float = 0.0
    accel: float = 0.0
    velocity: tuple[float, ...] | None = None


def _set_velocity(v: Array, course: float | None, speed: float | None) -> Array:
    vh = v[..., :2]
    cur_speed = np.hypot(vh[..., 0], vh[..., 1])
    cur_course = np.arctan2(vh[..., 0], vh[..., 1])
    c = cur_course if course is None else np.full_like(cur_speed, course)
    s = cur_speed if speed is None else np.full_like(cur_speed, speed)
    out = v.copy()
    out[..., 0], out[..., 1] = s * np.sin(c), s * np.cos(c)
    return out


def step(x: Array, t: float, dt: float, legs: Sequence[LegPlan], dim: int) -> Array:
    """Move platform states ``x`` ``(..., 2 dim)`` from time t to t + dt along the legs."""
    p, v = x[..., :dim], x[..., dim:2 * dim]
    for leg in legs:
        if leg.kind == "set" and t <= leg.start < t + dt:
            v = _set_velocity(v, leg.course, leg.speed)
        elif leg.kind == "velocity" and t <= leg.start < t + dt:
            v = np.broadcast_to(np.asarray(leg.velocity, dtype=float), v.shape)
    rate = sum(leg.rate for leg in legs if leg.kind == "turn" and leg.start <= t < leg.end)
    accel = sum(leg.accel for leg in legs if leg.kind == "accel" and leg.start <= t < leg.end)
    out = np.empty_like(x)
    if rate != 0.0:
        # trackkit's turn transition is counter-clockwise positive; a starboard turn is -rate
        F = turn_transition(np.asarray(-rate), np.asarray(dt))
        ph = np.concatenate([p[..., :2], v[..., :2]], -1) @ F.T
        out[..., :2], out[..., dim:dim + 2] = ph[..., :2], ph[..., 2:]
    else:
        out[..., :2] = p[..., :2] + dt * v[..., :2]
        out[..., dim:dim + 2] = v[..., :2]
    if accel != 0.0:
        speed = np.hypot(v[..., 0], v[..., 1])
        u = v[..., :2] / np.where(speed > 0, speed, 1.0)[..., None]
        out[..., :2] += 0.5 * accel * dt**2 * u
        out[..., dim:dim + 2] += accel * dt * u
    if dim == 3:
        out[..., 2] = p[..., 2] + dt * v[..., 2]
        out[..., 5] = v[..., 2]
    return out


def propagate(
    x0: Array,
    times: Array,
    legs: Sequence[LegPlan],
    dim: int,
    noise: Array | None = None,
) -> Array:
    """Platform states at ``times`` (``times[0]`` is the initial time), ``(T, ..., 2 dim)``.

    ``noise`` ``(T - 1, ..., 2 dim)``, if given, is added after each step (process noise).
    """
    out = np.empty((len(times),) + np.shape(x0))
    out[0] = x0
    for k in range(len(times) - 1):
        out[k + 1] = step(out[k], times[k], times[k + 1] - times[k], legs, dim)
        if noise is not None:
            out[k + 1] += noise[k]
    return out
