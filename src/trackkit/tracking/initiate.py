"""Track initiation from unassigned plots: one-point, two-point and converted measurements.

All kernels are batched over plots (and over pairs of plots); states are ordered positions
then velocities, ``[x, y, vx, vy]`` (or ``[x, y, z, vx, vy, vz]``), x east, y north.

- ``single_point(z, R, v_max=...)``: position from the plot, velocity from a zero-mean prior.
- ``two_point(z1, R1, t1, z2, R2, t2, v_max=...)``: every pair of plots of two scans closer
  than ``v_max * dt`` (KD-tree), state by differencing.
- ``convert_range_bearing(z, sensor)``: range-bearing plots to Cartesian positions with the
  unbiased converted-measurement covariance, to feed either initiator (or a linear KF).
- ``initiate_from_bearing(i, bearings, r_min, r_max, v_max, rng)``: randomised initiation from
  one bearing (Jalalipoor and Kardehi Moghaddam 2021, eqs. 7-8), below.

Randomised initiation from one bearing. A bearing that no track claims may be a new target.
Candidate targets are drawn around it: from the measuring sensor at ``o`` with bearing ``z``
and noise ``sigma``,

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
whose summed cost is least, and :func:`initiate_from_bearing` returns it with a starting
covariance.

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
from scipy.spatial import cKDTree

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.models.sensors import RangeBearing
from trackkit.tracking.bearings import BearingSet

__all__ = [
    "single_point",
    "two_point",
    "pair_plots",
    "convert_range_bearing",
    "converted_cov_given_truth",
    "Initiation",
    "candidates",
    "congruity",
    "initiate_from_bearing",
]

Array = NDArray[np.float64]


def _plots(z: ArrayLike, name: str) -> Array:
    z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.shape[-1] not in (1, 2, 3) or not np.all(np.isfinite(z)):
        raise ValueError(
            f"{name} has shape {z.shape}; expected finite plots of shape (K, d), d in 1..3"
        )
    return z


def _plot_cov(R: ArrayLike, k: int, d: int, name: str) -> Array:
    """R as ``(k, d, d)``: one covariance shared by all plots, or one per plot."""
    R = np.asarray(R, dtype=float)
    if R.shape not in ((d, d), (k, d, d)) or not np.all(np.isfinite(R)):
        raise ValueError(
            f"{name} has shape {R.shape}; expected finite ({d}, {d}) or ({k}, {d}, {d})"
        )
    return np.broadcast_to(R, (k, d, d))


def _times(t: ArrayLike, k: int, name: str) -> Array:
    t = np.asarray(t, dtype=float)
    if t.shape not in ((), (k,)) or not np.all(np.isfinite(t)):
        raise ValueError(f"{name} has shape {t.shape}; expected a finite scalar or ({k},)")
    return np.broadcast_to(t, (k,))


def _positive(v: float, name: str) -> float:
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name} = {v!r}; expected a positive number")
    return float(v)


# ------------------------------------------------------------------------------------------
# One-point initiation


def single_point(z: ArrayLike, R: ArrayLike, *, v_max: float | None = None,
                 v_std: float | ArrayLike | None = None) -> Gaussian:
    """One-point initiation (Bar-Shalom, Willett & Tian 2011; Blackman & Popoli 1999): for
    each plot ``z_k`` with covariance ``R_k``

        x_k = [z_k, 0],    P_k = [[R_k, 0], [0, sigma_v^2 I]],

    ``sigma_v = v_max / sqrt(3)`` (the standard deviation of a velocity component uniform on
    [-v_max, v_max]) or the given ``v_std`` (a scalar or one per axis).

    ``z`` is ``(K, d)`` Cartesian plots (convert range-bearing plots first), ``R`` is
    ``(d, d)`` or ``(K, d, d)``. Returns a Gaussian with mean ``(K, 2d)``, cov
    ``(K, 2d, 2d)``.
    """
    z = _plots(z, "z")
    k, d = z.shape
    Rk = _plot_cov(R, k, d, "R")
    if (v_max is None) == (v_std is None):
        raise ValueError(
            f"v_max = {v_max!r}, v_std = {v_std!r}; expected exactly one of the two"
        )
    if v_max is not None:
        sigma_v = np.full(d, _positive(v_max, "v_max") / np.sqrt(3.0))
    else:
        sigma_v = np.broadcast_to(np.asarray(v_std, dtype=float), np.shape(v_std))
        if sigma_v.shape not in ((), (d,)) or not np.all(np.isfinite(sigma_v) & (sigma_v > 0)):
            raise ValueError(
                f"v_std = {np.asarray(v_std).tolist()!r}; expected a positive number or {d} of them"
            )
        sigma_v = np.broadcast_to(sigma_v, (d,))
    mean = np.zeros((k, 2 * d))
    mean[:, :d] = z
    P = np.zeros((k, 2 * d, 2 * d))
    P[:, :d, :d] = Rk
    P[:, d:, d:] = np.diag(sigma_v**2)
    return Gaussian(mean, P)


# ------------------------------------------------------------------------------------------
# Two-point differencing


def pair_plots(z1: ArrayLike, z2: ArrayLike, max_distance: float) -> NDArray[np.int64]:
    """All pairs ``(i, j)`` with ``|z2_j - z1_i| <= max_distance``, as ``(P, 2)`` int64
    sorted by i then j (a KD-tree range search, O((K1 + K2) log K + P))."""
    z1 = _plots(z1, "z1")
    z2 = _plots(z2, "z2")
    if z1.shape[1] != z2.shape[1]:
        raise ValueError(f"z1 has shape {z1.shape} and z2 {z2.shape}; expected the same d")
    if not (np.isfinite(max_distance) and max_distance >= 0):
        raise ValueError(f"max_distance = {max_distance!r}; expected a number >= 0")
    if len(z1) == 0 or len(z2) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    # sparse_distance_matrix with ndarray output keeps zero distances (a stationary target
    # seen at the same place twice) and the boundary distance == max_distance.
    m = cKDTree(z1).sparse_distance_matrix(cKDTree(z2), max_distance, output_type="ndarray")
    pairs = np.stack([m["i"], m["j"]], axis=1).astype(np.int64)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def two_point(z1: ArrayLike, R1: ArrayLike, t1: ArrayLike, z2: ArrayLike, R2: ArrayLike,
              t2: ArrayLike, *, v_max: float,
              margin: float = 0.0) -> tuple[NDArray[np.int64], Gaussian]:
    """Two-point differencing (Bar-Shalom, Li & Kirubarajan 2001, "two-point differencing"
    initialisation) for every pair of plots ``z1_i`` (scan 1, time ``t1``) and ``z2_j``
    (scan 2, time ``t2``) with

        |z2_j - z1_i| <= v_max * dt_ij + margin,     dt_ij = t2_j - t1_i > 0.

    The state at ``t2_j`` and its covariance, from independent plot errors:

        x = [z2, (z2 - z1) / dt],
        P = [[R2, R2 / dt], [R2 / dt, (R1 + R2) / dt^2]].

    ``z1`` ``(K1, d)``, ``z2`` ``(K2, d)`` Cartesian; ``R1``, ``R2`` shared ``(d, d)`` or per
    plot; ``t1``, ``t2`` scalars or per plot. ``margin`` widens the gate for plot errors
    (e.g. a few position standard deviations). Returns ``pairs`` ``(P, 2)`` (indices into
    z1, z2, sorted) and the Gaussian of the pairs, mean ``(P, 2d)``, cov ``(P, 2d, 2d)``.
    """
    z1 = _plots(z1, "z1")
    z2 = _plots(z2, "z2")
    (k1, d), k2 = z1.shape, len(z2)
    if z2.shape[1] != d:
        raise ValueError(f"z1 has shape {z1.shape} and z2 {z2.shape}; expected the same d")
    R1 = _plot_cov(R1, k1, d, "R1")
    R2 = _plot_cov(R2, k2, d, "R2")
    t1 = _times(t1, k1, "t1")
    t2 = _times(t2, k2, "t2")
    v_max = _positive(v_max, "v_max")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin = {margin!r}; expected a number >= 0")
    empty = (np.zeros((0, 2), dtype=np.int64),
             Gaussian(np.zeros((0, 2 * d)), np.zeros((0, 2 * d, 2 * d))))
    if k1 == 0 or k2 == 0:
        return empty
    if t2.min() <= t1.max():
        raise ValueError(
            f"t2 (min {t2.min()!r}) is not after t1 (max {t1.max()!r}); expected every plot "
            "of the second scan later than every plot of the first"
        )
    # The KD-tree searches the widest gate; per-plot times then tighten it pair by pair.
    pairs = pair_plots(z1, z2, v_max * (t2.max() - t1.min()) + margin)
    i, j = pairs[:, 0], pairs[:, 1]
    dt = t2[j] - t1[i]
    dist = np.linalg.norm(z2[j] - z1[i], axis=-1)
    keep = dist <= v_max * dt + margin
    pairs, i, j, dt = pairs[keep], i[keep], j[keep], dt[keep]
    if len(pairs) == 0:
        return empty
    mean = np.concatenate([z2[j], (z2[j] - z1[i]) / dt[:, None]], axis=-1)
    Ra, Rb = R1[i], R2[j]
    dt_ = dt[:, None, None]
    P = np.empty((len(pairs), 2 * d, 2 * d))
    P[:, :d, :d] = Rb
    P[:, :d, d:] = Rb / dt_
    P[:, d:, :d] = np.swapaxes(Rb, -1, -2) / dt_
    P[:, d:, d:] = (Ra + Rb) / dt_**2
    return pairs, Gaussian(mean, P)


# ------------------------------------------------------------------------------------------
# Converted measurements


def _trig(theta: Array, convention: str) -> tuple[Array, Array]:
    """(a, b) with the position ``r * [a, b]``: nautical ``[sin, cos]`` (clockwise from
    north), math ``[cos, sin]`` (counter-clockwise from east)."""
    if convention == "nautical":
        return np.sin(theta), np.cos(theta)
    return np.cos(theta), np.sin(theta)


def _lambdas(sigma_theta: float) -> tuple[float, float]:
    """``lambda = E[cos w] = exp(-s^2/2)`` and ``lambda' = E[cos 2w] = exp(-2 s^2)`` for
    ``w ~ N(0, s^2)``."""
    s2 = sigma_theta**2
    return float(np.exp(-s2 / 2)), float(np.exp(-2 * s2))


def convert_range_bearing(z: ArrayLike, sensor: RangeBearing,
                          method: str = "unbiased") -> tuple[Array, Array]:
    """Range-bearing plots ``z = [r_m, theta_m]`` ``(..., 2)`` to Cartesian positions and
    covariances ``(..., 2)``, ``(..., 2, 2)``, using ``sensor``'s origin, sigmas and bearing
    convention (nautical: ``x = r sin theta``, ``y = r cos theta``).

    ``method="unbiased"``: the modified unbiased converted measurement (Mo, Song, Zhou, Sun &
    Bar-Shalom 1998, IEEE T-AES 34(3); the multiplicative form of the unbiased conversion of
    Lerro & Bar-Shalom 1993, IEEE T-AES 29(4)). With ``lambda = exp(-s_t^2 / 2)``,
    ``lambda' = exp(-2 s_t^2)`` and, in the nautical convention, ``u = [sin, cos](theta_m)``:

        p_u = origin + r_m u / lambda                         (E[p_u | truth] = truth)
        R_u = (lambda^-2 - 2) r_m^2 u u^T
              + (r_m^2 + s_r^2)/2 [[1 - l' cos 2t, l' sin 2t], [l' sin 2t, 1 + l' cos 2t]]

    (math convention: ``u = [cos, sin]`` and the signs of the ``cos 2t`` terms swap).
    ``R_u = E[(p_u - p)(p_u - p)^T | z]``, the error covariance given the measurement (what a
    filter can use); ``converted_cov_given_truth`` is the one given the true position.

    ``method="linearized"``: ``p = origin + r_m u`` and ``R = J diag(s_r^2, s_t^2) J^T``,
    J the Jacobian of the conversion at the measurement. Biased when ``r s_t^2 / s_r`` is
    not small (Lerro & Bar-Shalom's criterion: above about 0.4).
    """
    if not isinstance(sensor, RangeBearing):
        raise ValueError(f"sensor is a {type(sensor).__name__}; expected a RangeBearing")
    if method not in ("unbiased", "linearized"):
        raise ValueError(f"method = {method!r}; expected 'unbiased' or 'linearized'")
    z = np.asarray(z, dtype=float)
    if z.ndim < 1 or z.shape[-1] != 2 or not np.all(np.isfinite(z)):
        raise ValueError(f"z has shape {z.shape}; expected finite [range, bearing] (..., 2)")
    r, theta = z[..., 0], z[..., 1]
    a, b = _trig(theta, sensor.convention)
    sr2, st2 = sensor.sigma_range**2, sensor.sigma_bearing**2
    u = np.stack([a, b], axis=-1)
    uuT = u[..., :, None] * u[..., None, :]
    if method == "linearized":
        # d(r u)/d theta = r u_perp, u_perp = [b, -a] (nautical) or [-b, a] (math)
        up = np.stack([b, -a] if sensor.convention == "nautical" else [-b, a], axis=-1)
        R = sr2 * uuT + (r**2 * st2)[..., None, None] * (up[..., :, None] * up[..., None, :])
        return sensor.origin + r[..., None] * u, R
    lam, lam2 = _lambdas(sensor.sigma_bearing)
    R = ((lam**-2 - 2.0) * r**2)[..., None, None] * uuT + _spread(r**2 + sr2, a, b, lam2)
    return sensor.origin + (r / lam)[..., None] * u, R


def _spread(rho2: Array, a: Array, b: Array, lam2: float) -> Array:
    """``E[p p^T]`` of ``p = r [a, b](theta + w)`` over ``w`` with ``E[r^2] = rho2``:

        rho2 / 2 [[1 + l' (a^2 - b^2), 2 l' a b], [2 l' a b, 1 - l' (a^2 - b^2)]]

    (``a^2 - b^2`` is ``cos 2 theta`` in the math frame, ``-cos 2 theta`` in the nautical,
    ``2 a b = sin 2 theta`` in both)."""
    c2, s2 = a * a - b * b, 2.0 * a * b
    out = np.empty(np.shape(rho2) + (2, 2))
    out[..., 0, 0] = 1.0 + lam2 * c2
    out[..., 1, 1] = 1.0 - lam2 * c2
    out[..., 0, 1] = out[..., 1, 0] = lam2 * s2
    return 0.5 * rho2[..., None, None] * out


def converted_cov_given_truth(r: ArrayLike, theta: ArrayLike, sensor: RangeBearing) -> Array:
    """Covariance of the unbiased converted measurement about the true position ``r [a, b]``
    (``a, b`` from the true bearing; Mo et al. 1998, the "true" covariance):

        R_t = E[p_u p_u^T] - p p^T
            = lambda^-2 (r^2 + s_r^2)/2 [[1 + l' c2, l' s2], [l' s2, 1 - l' c2]] - r^2 u u^T

    ``(..., 2, 2)``. Unknowable in a tracker (it needs the truth); it is the exact sample
    covariance of ``convert_range_bearing`` over measurement noise, for simulations and tests.
    """
    if not isinstance(sensor, RangeBearing):
        raise ValueError(f"sensor is a {type(sensor).__name__}; expected a RangeBearing")
    r = np.asarray(r, dtype=float)
    theta = np.asarray(theta, dtype=float)
    a, b = _trig(theta, sensor.convention)
    lam, lam2 = _lambdas(sensor.sigma_bearing)
    u = np.stack([a, b], axis=-1)
    uuT = u[..., :, None] * u[..., None, :]
    spread = _spread(r**2 + sensor.sigma_range**2, a, b, lam2)
    return lam**-2 * spread - (r**2)[..., None, None] * uuT


# --- randomised initiation from one bearing -----------------------------------------------------


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


def initiate_from_bearing(bearing: int, bearings: BearingSet, r_min: float, r_max: float,
                          v_max: float, rng: np.random.Generator, n_candidates: int = 2000,
                          k1: float = 1.0, k2: float = 0.5) -> Initiation:
    """The best of ``n_candidates`` drawn around ``bearings[bearing]`` by their congruity
    with all of ``bearings`` (that one included), at its time. The covariance is the
    candidates' spread along the line of sight (range: ``(r_max - r_min)^2 / 12``), the
    bearing's across it, and ``v_max^2 / 3`` per velocity component: wide enough for the
    filter that takes over, as a track started from one line of bearings must be."""
    b = _bearings(bearings, "initiate_from_bearing")
    if not (isinstance(bearing, int | np.integer) and 0 <= bearing < b.z.size):
        raise ValueError(f"initiate_from_bearing: bearing = {bearing!r}; expected an index "
                         f"into the {b.z.size} bearings")
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
