"""Randomised track initiation from bearings (Jalalipoor and Kardehi Moghaddam 2021, eqs. 7-8).

A bearing that no track claims may be a new target. Candidate targets are drawn around it:
from the measuring sensor at ``o`` with bearing ``z`` and noise ``sigma``,

    beta_c ~ N(z, sigma^2),   r_c ~ U(r_min, r_max),   course_c ~ U[0, 2 pi),
    speed_c ~ U(0, v_max),    x_c = o + r_c (sin beta_c, cos beta_c),
    v_c = speed_c (sin course_c, cos course_c)

(the paper draws the range "uniform in the sensor's measurement range"; its speed is unstated,
uniform up to the targets' top speed is our reading). Each candidate's congruity with the M
unclaimed bearings (z_m at t_m from o_m, noise sigma_m; the agent's own and its neighbours')
is a robust sum over them,

    C_c = sum_m K1 (1 - exp(-K2 zeta_cm^2)),
    zeta_cm = wrap(h(x_c + (t_m - t_0) v_c; o_m) - z_m) / sigma_m

with h the nautical bearing. The paper's zeta is in radians with unstated K1, K2; here it is in
standard deviations of each bearing, so that K2 = 1/2 makes each term a Gaussian kernel of
the bearing's own noise, and bearings of unequal quality mix. A bearing of another target
costs at most K1: a candidate is not dragged towards it. The paper keeps the candidate of
"highest congruity" with a cost that is 0 for a perfect match; the best candidate is the one
whose summed cost is least, and :func:`initiate` returns it with a starting covariance.

Where another agent's bearings of a different target cross this bearing's line of sight, the
crossing (a ghost) can be supported by as many bearings as the target: bearings-only
initiation from several sensors is ambiguous there, and the paper's cost does not remove the
ambiguity; the track's later bearings and the duplicate pruning must.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.network.bearings import BearingSet

__all__ = ["candidates", "congruity", "Initiation", "initiate"]

Array = NDArray[np.float64]


def _bearings(b: BearingSet, where: str) -> BearingSet:
    z = np.asarray(b.z, dtype=float).reshape(-1)
    M = z.size
    t = np.broadcast_to(np.asarray(b.t, dtype=float), (M,))
    o = np.broadcast_to(np.asarray(b.sensor, dtype=float), (M, 2))
    s = np.broadcast_to(np.asarray(b.sigma, dtype=float), (M,))
    for name, v in (("z", z), ("t", t), ("sensor", o), ("sigma", s)):
        if not np.isfinite(v).all():
            raise ValueError(f"{where}: bearings.{name} has non-finite entries; expected "
                             "finite values")
    if not (s > 0).all():
        raise ValueError(f"{where}: bearings.sigma has entries <= 0; expected rad > 0")
    src = np.broadcast_to(np.asarray(b.source, dtype=np.int64), (M,))
    return BearingSet(z, t, o, s, src)


def candidates(z: float, sigma: float, origin: ArrayLike, r_min: float, r_max: float,
               v_max: float, n: int, rng: np.random.Generator) -> Array:
    """``n`` candidate states ``[x, y, vx, vy]`` ``(n, 4)`` around one bearing ``z`` taken
    from ``origin`` (see the module docstring), at that bearing's time."""
    if not (0 <= r_min < r_max and math.isfinite(r_max)):
        raise ValueError(f"candidates: r_min = {r_min!r}, r_max = {r_max!r}; expected "
                         "0 <= r_min < r_max < inf (m)")
    if not (math.isfinite(v_max) and v_max >= 0):
        raise ValueError(f"candidates: v_max = {v_max!r}; expected a speed >= 0 (m/s)")
    if not (isinstance(n, int | np.integer) and n >= 1):
        raise ValueError(f"candidates: n = {n!r}; expected an integer >= 1")
    if not (math.isfinite(sigma) and sigma > 0 and math.isfinite(z)):
        raise ValueError(f"candidates: z = {z!r}, sigma = {sigma!r}; expected a finite "
                         "bearing and sigma > 0 (rad)")
    o = np.asarray(origin, dtype=float)
    beta = z + sigma * rng.standard_normal(n)
    r = rng.uniform(r_min, r_max, n)
    course = rng.uniform(0.0, 2.0 * math.pi, n)
    speed = rng.uniform(0.0, v_max, n)
    return np.stack([o[0] + r * np.sin(beta), o[1] + r * np.cos(beta),
                     speed * np.sin(course), speed * np.cos(course)], -1)


def congruity(states: ArrayLike, t0: float, bearings: BearingSet, k1: float = 1.0,
              k2: float = 0.5) -> Array:
    """``C_c = sum_m K1 (1 - exp(-K2 zeta_cm^2))`` of candidates ``states (..., 4)`` at time
    ``t0`` against ``bearings``: ``(...)`` (lower is better)."""
    b = _bearings(bearings, "congruity")
    X = np.asarray(states, dtype=float)
    if X.shape[-1:] != (4,):
        raise ValueError(f"congruity: states have shape {X.shape}; expected (..., 4)")
    dt = b.t - t0
    px = X[..., 0, None] + dt * X[..., 2, None] - b.sensor[:, 0]
    py = X[..., 1, None] + dt * X[..., 3, None] - b.sensor[:, 1]
    zeta = wrap(np.arctan2(px, py) - b.z) / b.sigma
    return (k1 * -np.expm1(-k2 * zeta * zeta)).sum(-1)


class Initiation(NamedTuple):
    """The chosen candidate ``mean (4,)`` at ``t0``, a starting covariance ``cov (4, 4)``,
    its summed cost and the number of bearings within 2 sigma of it (``support``)."""

    mean: Array
    cov: Array
    cost: float
    support: int


def initiate(bearing: int, bearings: BearingSet, r_min: float, r_max: float, v_max: float,
             rng: np.random.Generator, n_candidates: int = 2000, k1: float = 1.0,
             k2: float = 0.5) -> Initiation:
    """The best of ``n_candidates`` drawn around ``bearings[bearing]`` by their congruity
    with all of ``bearings`` (that one included), at its time. The covariance is the
    candidates' spread along the line of sight (range: ``(r_max - r_min)^2 / 12``), the
    bearing's across it, and ``v_max^2 / 3`` per velocity component: wide enough for the
    filter that takes over, as a track started from one line of bearings must be."""
    b = _bearings(bearings, "initiate")
    if not (isinstance(bearing, int | np.integer) and 0 <= bearing < b.z.size):
        raise ValueError(f"initiate: bearing = {bearing!r}; expected an index into the "
                         f"{b.z.size} bearings")
    z, t0, o, s = b.z[bearing], b.t[bearing], b.sensor[bearing], b.sigma[bearing]
    X = candidates(z, s, o, r_min, r_max, v_max, n_candidates, rng)
    cost = congruity(X, t0, b, k1, k2)
    best = int(np.argmin(cost))
    x = X[best]
    dt = b.t - t0
    zeta = wrap(np.arctan2(x[0] + dt * x[2] - b.sensor[:, 0],
                           x[1] + dt * x[3] - b.sensor[:, 1]) - b.z) / b.sigma
    r = math.hypot(x[0] - o[0], x[1] - o[1])
    u = np.array([math.sin(z), math.cos(z)])  # along the line of sight
    w = np.array([u[1], -u[0]])
    pos = ((r_max - r_min) ** 2 / 12.0) * np.outer(u, u) + (r * s) ** 2 * np.outer(w, w)
    P = np.zeros((4, 4))
    P[:2, :2] = pos
    P[2:, 2:] = np.eye(2) * max(v_max, 1e-3) ** 2 / 3.0
    return Initiation(x, P, float(cost[best]), int(np.sum(np.abs(zeta) <= 2.0)))
