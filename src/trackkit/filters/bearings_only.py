"""Bearings-only specialists: the range-parameterised EKF and the modified-polar EKF.

Bearings-only tracking from one observer leaves range unobservable until the observer
manoeuvres, and a Cartesian EKF linearised at a wrong range drifts and becomes overconfident.
The two filters here are the classic cures (Arulampalam and Ristic 2000 compare them with a
particle filter):

* :class:`RPEKF`, the range-parameterised EKF (Peach 1995): a bank of EKFs whose initial
  ranges lie on a geometric grid, each with a range spread proportional to its range, so that
  each one is linearised well; the bank's weights follow each filter's measurement
  likelihood, and the estimate is the Gaussian of the mixture.
* :class:`MPEKF`, the modified-polar-coordinates EKF (Aidala and Hammel 1983): the state
  ``y = [beta, beta_dot, r_dot / r, 1 / r]`` relative to the observer, in which the bearing
  update is linear and the (unobservable) inverse range stays apart from what is observed.
* :class:`RangePF`, the bootstrap particle filter (:class:`~trackkit.filters.particle.PF`)
  with its particles drawn from the Gaussian prior, or spread over a range interval along the
  first bearing (for a user whose prior says little about range).

Both receive a Cartesian prior ``N(x0, P0)`` over ``[x, y, vx, vy]`` (what a scenario gives
every filter) and learn the observer's pose only from the sensor of the first update, so both
build their own representation there, lazily, row by row. Their ``estimate`` is a Cartesian
Gaussian, so the metrics and the PCRLB treat them like every other filter.

Bearings are nautical (clockwise from north) inside the MPEKF's state; a sensor with
``convention="math"`` is measured as ``pi/2 - beta``. Every kernel is batched over leading
axes; the RPEKF's components sit on the axis after the batch axes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation, Particles
from trackkit.filters import resample as rs
from trackkit.filters.base import (
    Filter,
    check_belief,
    check_dt,
    check_measurement,
    keep_prior_where_missing,
    missing_rows,
    output,
    register,
)
from trackkit.filters.imm import combine, mixture_innovation
from trackkit.filters.kalman import EKF, condition, jacobian_predict
from trackkit.filters.particle import PF, resample_rows
from trackkit.filters.particle_fast import standard_normals
from trackkit.linalg import gaussian_loglik, mm, mmT, psd_factor, solve_psd, symmetrize
from trackkit.models.motion import ConstantVelocity
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = [
    "RangePF",
    "PendingParticles",
    "RPEKF",
    "RangeBankBelief",
    "range_split",
    "MPEKF",
    "MPBelief",
    "mpc_transition",
    "mpc_from_relative",
    "mpc_from_bearing",
    "mpc_to_cartesian",
    "cartesian_to_mpc",
    "conditioned_on_bearing",
]

Array = NDArray[np.float64]

#: without ``r_min``, the bank's lowest range is at least this fraction of the prior's range
MIN_RANGE_FRACTION = 0.05

_EKF = EKF()  # the RPEKF's components (a stateless strategy: one serves every bank)


# --------------------------------------------------------------------------------------------
# Shared checks
# --------------------------------------------------------------------------------------------


def _origin(sensor: SensorModel, where: str) -> Array:
    """The sensor's 2-D origin (..., 2); a sensor without one cannot anchor a line of sight."""
    o = getattr(sensor, "origin", None)
    if o is None or np.shape(o)[-1:] != (2,):
        raise ValueError(f"{where}: sensor {type(sensor).__name__} has no 2-D origin; expected "
                         "a bearing sensor from one observer (trackkit.models.Bearing)")
    return np.asarray(o, dtype=float)


def _bearing_sensor(sensor: SensorModel, where: str) -> tuple[Array, Array, float]:
    """``(origin, velocity, sign)`` of a single-bearing sensor: the measured bearing is
    ``sign * beta + offset`` with beta nautical (sign -1 and offset pi/2 for "math")."""
    if getattr(sensor, "dim_z", None) != 1 or tuple(getattr(sensor, "angular", ())) != (True,):
        raise ValueError(f"{where}: sensor {type(sensor).__name__} measures "
                         f"{getattr(sensor, 'dim_z', '?')} components; expected one bearing "
                         "(trackkit.models.Bearing)")
    o = _origin(sensor, where)
    v = np.asarray(getattr(sensor, "velocity", np.zeros(2)), dtype=float)
    if v.shape[-1:] != (2,):
        raise ValueError(f"{where}: sensor velocity has shape {v.shape}; expected (..., 2)")
    convention = getattr(sensor, "convention", "nautical")
    return o, v, (1.0 if convention == "nautical" else -1.0)


def _constant_velocity(motion: MotionModel, where: str) -> None:
    if not (isinstance(getattr(motion, "motion", motion), ConstantVelocity)
            and motion.dim_x == 4):
        raise ValueError(f"{where}: motion is {type(motion).__name__}; expected a 2-D "
                         "ConstantVelocity (the exact polar prediction assumes it)")


# --------------------------------------------------------------------------------------------
# Range-parameterised EKF
# --------------------------------------------------------------------------------------------


class RangeBankBelief(NamedTuple):
    """Belief of the RPEKF: ``mean (..., C, n)`` and ``cov (..., C, n, n)`` of the C
    component EKFs, ``log_weights (..., C)`` (normalised; ``-inf`` for a pruned component)
    and ``split (...)``, whether the row's bank is built. Until its first bearing a row holds
    its Gaussian in component 0 (the others are copies with weight 0)."""

    mean: Array
    cov: Array
    log_weights: Array
    split: Array

    def at(self, index) -> RangeBankBelief:
        """The belief at a batch index (every field indexed alike)."""
        return RangeBankBelief(*(np.asarray(a)[index] for a in self))


#: Gauss-Legendre rule for the moments of a normal density over a range cell
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)


def _cell_moments(a_lo: Array, a_hi: Array) -> tuple[Array, Array, Array]:
    """``log Z``, mean and variance of a standard normal restricted to ``[a_lo, a_hi]``
    (``Z = Phi(a_hi) - Phi(a_lo)``).

    With the cell's centre c and half-width h, ``s = c + t`` and the density over the cell
    is ``phi(c) exp(-c t - t^2 / 2)``: its moments about c by 64-point Gauss-Legendre, in
    log space. The closed forms (``mu = (phi(a) - phi(b)) / Z``, ...) cancel catastrophically
    for a cell narrow against the prior's spread, where the variance is ``h^2 / 3`` beside
    terms of order 1; the rule is exact to rounding for any cell of up to tens of sigma.
    """
    c = 0.5 * (a_lo + a_hi)
    h = 0.5 * (a_hi - a_lo)
    t = h[..., None] * _GL_NODES
    ell = -c[..., None] * t - 0.5 * t * t
    top = ell.max(-1, keepdims=True)
    g = _GL_WEIGHTS * np.exp(ell - top)
    S0 = g.sum(-1)
    mean_t = (g * t).sum(-1) / S0
    v = (g * (t - mean_t[..., None]) ** 2).sum(-1) / S0
    logZ = -0.5 * c * c - 0.5 * math.log(2 * math.pi) + top[..., 0] + np.log(h * S0)
    return logZ, c + mean_t, v


def range_split(mean: ArrayLike, cov: ArrayLike, origin: ArrayLike, components: int = 16,
                n_sigma: float = 4.0, r_min: float | None = None,
                r_max: float | None = None) -> tuple[Array, Array, Array]:
    """Split ``N(mean, cov)`` into a Gaussian sum along its line of sight from ``origin``.

    With ``e`` the unit vector from ``origin`` through the prior's position (padded with
    zeros to the state), ``s = e^T (x - mean)`` has variance ``sigma^2 = e^T P e`` and
    ``x | s ~ N(mean + k s, P - sigma^2 k k^T)``, ``k = P e / sigma^2``. The range
    ``r = rbar + s`` (``rbar = e^T (mean - origin)``) is cut into C cells whose edges are the
    geometric grid ``r_j = r_lo (r_hi / r_lo)^(j / C)`` over ``[r_lo, r_hi]`` =
    ``[rbar - n_sigma sigma, rbar + n_sigma sigma]`` (at least ``MIN_RANGE_FRACTION rbar``,
    or clipped to ``[r_min, r_max]``); component i takes the prior's mass in its cell as its
    weight and the prior's mean ``mu_i`` and variance ``v_i`` of s within it:
    ``x_i = mean + k mu_i``, ``P_i = P - (sigma^2 - v_i) k k^T``.

    So the mixture keeps the prior's mean and covariance (up to the mass outside the
    interval, 6e-5 at 4 sigma), and each component's range spread is about its cell's,
    ``(rho - 1) / ((rho + 1) sqrt 3)`` of its range with ``rho = (r_hi / r_lo)^(1 / C)``:
    the constant coefficient of variation of the range-parameterised EKF.
    Returns ``(means (..., C, n), covs (..., C, n, n), log_weights (..., C))``.
    """
    x = np.asarray(mean, dtype=float)
    P = np.asarray(cov, dtype=float)
    o = np.asarray(origin, dtype=float)
    n = x.shape[-1]
    d = x[..., :2] - o
    rbar = np.hypot(d[..., 0], d[..., 1])
    if not np.all(rbar > 0):
        raise ValueError("range_split: the prior's mean position is on the observer "
                         "(range 0); expected a target away from the origin")
    e = np.zeros(np.broadcast_shapes(x.shape, d.shape[:-1] + (n,)))
    e[..., :2] = d / rbar[..., None]
    Pe = mm(P, e[..., None])[..., 0]
    var = (e * Pe).sum(-1)
    sigma = np.sqrt(var)
    k = Pe / var[..., None]
    lo = rbar - n_sigma * sigma
    lo = np.maximum(lo, MIN_RANGE_FRACTION * rbar if r_min is None else r_min)
    hi = rbar + n_sigma * sigma
    if r_max is not None:
        hi = np.minimum(hi, r_max)
    if not np.all(hi > lo):
        i = np.argwhere(~(hi > lo))[0] if np.ndim(hi) else ()
        raise ValueError(
            f"range_split: the range interval is empty at batch index {tuple(i)} "
            f"([{float(lo[tuple(i)]):.6g}, {float(hi[tuple(i)]):.6g}] m): the prior's "
            f"range {float(rbar[tuple(i)]):.6g} +- {n_sigma} x {float(sigma[tuple(i)]):.6g} m "
            f"does not meet [r_min, r_max] = [{r_min}, {r_max}]")
    edges = lo[..., None] * (hi / lo)[..., None] ** (np.arange(components + 1) / components)
    a = (edges - rbar[..., None]) / sigma[..., None]
    logZ, mu, v = _cell_moments(a[..., :-1], a[..., 1:])
    logw = _normalise(logZ)
    means = x[..., None, :] + (sigma[..., None] * mu)[..., None] * k[..., None, :]
    kk = k[..., :, None] * k[..., None, :]
    shrink = (var[..., None] * (1.0 - v))[..., None, None]  # sigma^2 - v_i, v_i in sigma^2
    covs = P[..., None, :, :] - shrink * kk[..., None, :, :]
    return means, symmetrize(covs), logw


def _normalise(logw: Array) -> Array:
    """Log weights shifted so that they sum to one (rows of -inf stay -inf)."""
    top = logw.max(-1, keepdims=True)
    with np.errstate(invalid="ignore"):
        return logw - (top + np.log(np.exp(logw - top).sum(-1, keepdims=True)))


class RPEKF(Filter):
    """Range-parameterised EKF (Peach 1995; Arulampalam and Ristic 2000).

    A bank of ``components`` EKFs. At a row's first bearing the Gaussian prior is split
    along its line of sight from the sensor (:func:`range_split`): geometric range cells
    over ``rbar -+ n_sigma sigma`` (clipped to ``[r_min, r_max]``), each component holding
    the prior's mass, mean and spread within its cell, so the prior's information is kept
    (its mean and covariance, up to the mass beyond ``n_sigma``) while each component's
    range spread is a fixed fraction of its range. Then every component is an EKF and

        w_i <- w_i N(z; h(x_i-), S_i) / sum_j w_j N(z; h(x_j-), S_j)

    Components whose weight falls below ``prune`` get weight 0 for good (they are still
    carried, so the arrays keep their shape). ``estimate`` is the moment-matched Gaussian
    ``x = sum_i w_i x_i``, ``P = sum_i w_i (P_i + (x_i - x)(x_i - x)^T)``; the innovation is
    the moment-matched one of the predicted measurement mixture.
    """

    name = "RPEKF"

    def __init__(self, components: int = 16, n_sigma: float = 4.0, r_min: float | None = None,
                 r_max: float | None = None, prune: float = 0.0) -> None:
        if not (isinstance(components, int | np.integer) and components >= 1):
            raise ValueError(f"RPEKF components = {components!r}; expected an integer >= 1")
        if not (np.isfinite(n_sigma) and n_sigma > 0):
            raise ValueError(f"RPEKF n_sigma = {n_sigma!r}; expected a number > 0 (prior "
                             "standard deviations each side of its range)")
        for name, value in (("r_min", r_min), ("r_max", r_max)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"RPEKF {name} = {value!r}; expected a range > 0 m or None")
        if r_min is not None and r_max is not None and not r_max > r_min:
            raise ValueError(f"RPEKF r_max = {r_max!r}; expected a range > r_min = {r_min!r}")
        if not (np.isfinite(prune) and 0 <= prune < 1.0 / components):
            raise ValueError(f"RPEKF prune = {prune!r}; expected a weight in [0, "
                             f"1 / components) = [0, {1.0 / components:.6g})")
        self.components = int(components)
        self.n_sigma = float(n_sigma)
        self.r_min = None if r_min is None else float(r_min)
        self.r_max = None if r_max is None else float(r_max)
        self.prune = float(prune)

    def init(self, prior: Gaussian) -> RangeBankBelief:
        """Component 0 holds the prior until the row's first bearing (weight 1)."""
        x, P = check_belief(prior, None, f"{self.name}.init prior")
        C = self.components
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
        n = x.shape[-1]
        X = np.broadcast_to(x[..., None, :], batch + (C, n)).copy()
        PX = np.broadcast_to(P[..., None, :, :], batch + (C, n, n)).copy()
        logw = np.full(batch + (C,), -np.inf)
        logw[..., 0] = 0.0
        return RangeBankBelief(X, register(PX), logw, np.zeros(batch, bool))

    def _belief(self, belief, where: str) -> RangeBankBelief:
        if isinstance(belief, RangeBankBelief):
            return belief
        if isinstance(belief, Gaussian):
            return self.init(belief)
        raise ValueError(f"{where}: belief is {type(belief).__name__}; expected a "
                         "RangeBankBelief (RPEKF.init) or a Gaussian")

    def estimate(self, belief: RangeBankBelief) -> Gaussian:
        b = self._belief(belief, f"{self.name}.estimate")
        w = np.exp(b.log_weights)
        live = (w > 0)[..., None]
        X = np.where(live, b.mean, 0.0)  # a pruned component may hold anything
        P = np.where(live[..., None], b.cov, 0.0)
        return Gaussian._make(combine(w, X, P))

    def predict(self, belief: RangeBankBelief, motion: MotionModel,
                dt: ArrayLike) -> RangeBankBelief:
        """Every component's EKF prediction; the weights do not change."""
        b = self._belief(belief, f"{self.name}.predict belief")
        g = _EKF.predict(Gaussian._make((b.mean, b.cov)), motion, dt)
        return RangeBankBelief(g.mean, g.cov, b.log_weights, b.split)

    def update(self, belief: RangeBankBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[RangeBankBelief, Innovation]:
        """Build the bank where this is the row's first bearing, then update every component
        and reweight by its likelihood."""
        b = self._belief(belief, f"{self.name}.update belief")
        where = f"{self.name}.update"
        z = check_measurement(z, sensor.dim_z, where, b.mean.shape[:-2])
        miss = missing_rows(z)
        X, PX, logw, split = b
        build = ~split if miss is None else ~split & ~miss
        if build.any():
            o = np.broadcast_to(_origin(sensor, where), build.shape + (2,))
            if build.all():
                X, PX, logw = range_split(X[..., 0, :], PX[..., 0, :, :], o, self.components,
                                          self.n_sigma, self.r_min, self.r_max)
            else:  # only those rows: the others' component 0 is no prior any more
                X, PX, logw = X.copy(), PX.copy(), logw.copy()
                X[build], PX[build], logw[build] = range_split(
                    X[build][:, 0], PX[build][:, 0], o[build], self.components, self.n_sigma,
                    self.r_min, self.r_max)
            split = split | build
        # components lead while the sensor sees them: its pose broadcasts over the batch axes
        g = Gaussian._make((np.moveaxis(X, -2, 0), register(np.moveaxis(PX, -3, 0))))
        post, innov = _EKF.update(g, z, sensor)
        nu, S = np.moveaxis(innov.nu, 0, -2), np.moveaxis(innov.cov, 0, -3)
        c = np.exp(logw)
        if miss is None:
            loglik = gaussian_loglik(nu, S)
        else:
            loglik = gaussian_loglik(np.where(np.isnan(nu), 0.0, nu), S)
            loglik = np.where(miss[..., None], 0.0, loglik)
        new = _normalise(logw + loglik)
        if self.prune > 0:
            new = _normalise(np.where(np.exp(new) < self.prune, -np.inf, new))
        v, Sm = mixture_innovation(c, np.where(c[..., None] > 0, nu, 0.0),
                                   np.where(c[..., None, None] > 0, S, 0.0))
        if miss is not None:
            v = np.where(miss[..., None], np.nan, v)
        out = RangeBankBelief(np.moveaxis(post.mean, 0, -2),
                              register(np.moveaxis(post.cov, 0, -3)), new, split)
        return out, Innovation(v, Sm)


# --------------------------------------------------------------------------------------------
# Modified polar coordinates: kernels
# --------------------------------------------------------------------------------------------


def _unit(beta: Array) -> tuple[Array, Array]:
    """Line-of-sight unit vector ``u = (sin b, cos b)`` (nautical) and ``u' = du/db``."""
    s, c = np.sin(beta), np.cos(beta)
    return np.stack([s, c], -1), np.stack([c, -s], -1)


def _polar(s1: Array, s2: Array, w: Array) -> tuple[Array, Array, Array, Array]:
    """MPC of a relative position ``s1`` and velocity ``s2`` both divided by a range r0,
    with ``w = 1 / r0``: ``beta = atan2(s1x, s1y)``, ``beta_dot = (s1y s2x - s1x s2y) /
    |s1|^2``, ``r_dot / r = s1 . s2 / |s1|^2``, ``1 / r = w / |s1|``; and the derivatives
    ``dy/ds1 (..., 4, 2)``, ``dy/ds2 (..., 4, 2)``, ``dy/dw (..., 4)``."""
    x1, y1, x2, y2 = s1[..., 0], s1[..., 1], s2[..., 0], s2[..., 1]
    rho2 = x1 * x1 + y1 * y1
    rho = np.sqrt(rho2)
    c = y1 * x2 - x1 * y2
    d = x1 * x2 + y1 * y2
    y = np.stack([np.arctan2(x1, y1), c / rho2, d / rho2, w / rho], -1)
    r4 = rho2 * rho2
    zero = np.zeros_like(rho)
    d1 = np.stack([
        np.stack([y1 / rho2, -x1 / rho2], -1),
        np.stack([-y2 / rho2 - 2 * c * x1 / r4, x2 / rho2 - 2 * c * y1 / r4], -1),
        np.stack([x2 / rho2 - 2 * d * x1 / r4, y2 / rho2 - 2 * d * y1 / r4], -1),
        np.stack([-w * x1 / (rho2 * rho), -w * y1 / (rho2 * rho)], -1),
    ], -2)
    d2 = np.stack([
        np.stack([zero, zero], -1),
        np.stack([y1 / rho2, -x1 / rho2], -1),
        np.stack([x1 / rho2, y1 / rho2], -1),
        np.stack([zero, zero], -1),
    ], -2)
    dw = np.stack([zero, zero, zero, 1.0 / rho], -1)
    return y, d1, d2, dw


def mpc_from_relative(rel: ArrayLike) -> tuple[Array, Array]:
    """MPC ``[beta, beta_dot, r_dot / r, 1 / r]`` of a relative state ``[x, y, vx, vy]``
    (target minus observer) and its Jacobian ``(..., 4, 4)``:
    ``beta = atan2(x, y)``, ``beta_dot = (y vx - x vy) / r^2``, ``r_dot / r = (x vx + y vy)
    / r^2``."""
    rel = np.asarray(rel, dtype=float)
    y, d1, d2, _ = _polar(rel[..., :2], rel[..., 2:4], np.ones(rel.shape[:-1]))
    return y, np.concatenate([d1, d2], -1)


def mpc_to_cartesian(y: ArrayLike, origin: ArrayLike = (0.0, 0.0),
                     velocity: ArrayLike = (0.0, 0.0)) -> tuple[Array, Array]:
    """The target's ``[x, y, vx, vy]`` from MPC ``y`` relative to an observer at ``origin``
    moving at ``velocity``, and the Jacobian ``d x / d y`` ``(..., 4, 4)``:
    ``p = o + u / w``, ``v = v_o + (r_dot/r u + beta_dot u') / w`` with ``u = (sin b, cos b)``,
    ``u' = (cos b, -sin b)`` and ``w = 1 / r``."""
    y = np.asarray(y, dtype=float)
    b, bd, rd, w = y[..., 0], y[..., 1], y[..., 2], y[..., 3]
    u, up = _unit(b)
    vr = rd[..., None] * u + bd[..., None] * up
    inv = (1.0 / w)[..., None]
    x = np.concatenate([np.asarray(origin, dtype=float) + u * inv,
                        np.asarray(velocity, dtype=float) + vr * inv], -1)
    zero = np.zeros(u.shape)
    dpos = np.stack([up * inv, zero, zero, -u * inv**2], -1)  # (..., 2, 4)
    dvel = np.stack([(rd[..., None] * up - bd[..., None] * u) * inv, up * inv, u * inv,
                     -vr * inv**2], -1)
    return x, np.concatenate([dpos, dvel], -2)


def cartesian_to_mpc(x: ArrayLike, origin: ArrayLike = (0.0, 0.0),
                     velocity: ArrayLike = (0.0, 0.0)) -> tuple[Array, Array]:
    """MPC of the target state ``x = [x, y, vx, vy]`` relative to the observer (``origin``,
    ``velocity``), and its Jacobian ``d y / d x``: :func:`mpc_from_relative` of
    ``x - [origin, velocity]``."""
    x = np.asarray(x, dtype=float)
    ov = np.concatenate([np.broadcast_to(np.asarray(origin, dtype=float), x.shape[:-1] + (2,)),
                         np.broadcast_to(np.asarray(velocity, dtype=float),
                                         x.shape[:-1] + (2,))], -1)
    return mpc_from_relative(x - ov)


def mpc_transition(y: ArrayLike, dt: ArrayLike, dp: ArrayLike = (0.0, 0.0),
                   dv: ArrayLike = (0.0, 0.0)) -> tuple[Array, Array]:
    """The exact MPC prediction of a constant-velocity target over ``dt`` (Aidala and Hammel
    1983), and its Jacobian ``d y' / d y`` ``(..., 4, 4)``.

    ``dp`` and ``dv`` are the observer's deviation from constant velocity over the step
    (its displacement minus ``v_o dt``, and its velocity change). With ``w = 1 / r``,
    ``u = (sin b, cos b)`` and ``u' = du/db``, the relative position and velocity at the end
    of the step, divided by the range at its start, are

        s1 = u + dt (r_dot/r u + beta_dot u') - w dp
        s2 = r_dot/r u + beta_dot u' - w dv

    and ``y' = [atan2(s1x, s1y), (s1y s2x - s1x s2y) / |s1|^2, s1 . s2 / |s1|^2,
    w / |s1|]``: no range is needed except where the observer manoeuvres (the ``w dp``,
    ``w dv`` terms, through which range becomes observable).
    """
    y = np.asarray(y, dtype=float)
    dp, dv = np.asarray(dp, dtype=float), np.asarray(dv, dtype=float)
    dt = np.asarray(dt, dtype=float)[..., None]
    b, bd, rd, w = y[..., 0], y[..., 1], y[..., 2], y[..., 3]
    u, up = _unit(b)
    vr = rd[..., None] * u + bd[..., None] * up
    s1 = u + dt * vr - w[..., None] * dp
    s2 = vr - w[..., None] * dv
    yn, d1, d2, dw = _polar(s1, s2, w)
    dvr_db = rd[..., None] * up - bd[..., None] * u  # du'/db = -u
    shape = np.broadcast_shapes(s1.shape, dp.shape)
    ds1 = np.stack([up + dt * dvr_db, dt * up, dt * u,
                    np.broadcast_to(-dp, shape)], -1)  # (..., 2, 4)
    ds2 = np.stack([dvr_db, up, u, np.broadcast_to(-dv, shape)], -1)
    J = mm(d1, ds1) + mm(d2, ds2)
    J[..., :, 3] += dw
    return yn, J


def _range_given_bearing(d_u: Array, d_c: Array, l_uu: Array, l_uc: Array, l_cc: Array,
                         var_beta: Array) -> tuple[Array, Array]:
    """Mean and standard deviation of the range ``r > 0`` given a Gaussian position prior
    and one bearing, by 64-point Gauss-Legendre quadrature of its density (below).

    In the frame of the bearing's ray (unit vectors u along it, u' across), the prior's
    mean is ``(d_u, d_c)`` from the observer and its information matrix ``[[l_uu, l_uc],
    [l_uc, l_cc]]``. A target at range r and bearing ``beta + delta`` is at ``(r, r delta)``
    (the arc taken straight over the bearing's spread) in an area ``r dr ddelta``, and the
    bearing's likelihood is ``N(delta; 0, var_beta)``. With ``e = r - d_u``, ``g = l_cc d_c
    - l_uc e`` and ``k = l_cc r^2 + 1 / var_beta``, the integral over delta leaves

        p(r | beta) ~ r / sqrt(k) exp(-(l_uu e^2 - 2 l_uc e d_c + l_cc d_c^2 - r^2 g^2 / k) / 2)

    which grows like r where the prior is wider across the ray than the bearing (the polar
    area element) and is the prior's Gaussian along the ray where it is narrower; it is
    finite and positive for a prior whose mean is near or behind the observer. The rule
    covers ``[max(0, mu - 10 s), max(mu, 0) + 10 s]`` with ``mu``, ``s`` the prior's range
    along the ray and its spread there (``mu = d_u + l_uc d_c / l_uu``, ``s^2 = 1 / l_uu``).
    """
    mu = d_u + l_uc * d_c / l_uu
    s = 1.0 / np.sqrt(l_uu)
    lo = np.maximum(mu - 10.0 * s, 0.0)
    hi = np.maximum(mu, 0.0) + 10.0 * s
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    r = c[..., None] + h[..., None] * _GL_NODES
    e = r - d_u[..., None]
    g = l_cc[..., None] * d_c[..., None] - l_uc[..., None] * e
    k = l_cc[..., None] * r * r + 1.0 / var_beta[..., None]
    q = (l_uu[..., None] * e * e - 2.0 * l_uc[..., None] * e * d_c[..., None]
         + l_cc[..., None] * d_c[..., None] ** 2 - r * r * g * g / k)
    ell = np.log(r) - 0.5 * np.log(k) - 0.5 * q
    wts = _GL_WEIGHTS * np.exp(ell - ell.max(-1, keepdims=True))
    wts = wts / wts.sum(-1, keepdims=True)
    rbar = (wts * r).sum(-1)
    return rbar, np.sqrt((wts * (r - rbar[..., None]) ** 2).sum(-1))


def mpc_from_bearing(x: ArrayLike, P: ArrayLike, beta: ArrayLike, var_beta: ArrayLike,
                     origin: ArrayLike = (0.0, 0.0), velocity: ArrayLike = (0.0, 0.0),
                     name: str = "mpc_from_bearing prior cov") -> tuple[Array, Array]:
    """The MPC prior ``(y, P_y)`` of a Cartesian prior ``N(x, P)`` given a first bearing
    ``beta`` (nautical, variance ``var_beta``) from an observer at ``origin`` moving at
    ``velocity``, the bearing's information included: Aidala and Hammel (1983) start the
    filter from the first bearing and a range guess, ``1 / r`` with deviation ``sigma_r /
    r^2``; here the guess and its spread are the prior's given that bearing.

    In the frame of the bearing's ray (``u = (sin beta, cos beta)``, ``u' = du/dbeta``),
    ``d = x_p - origin`` has coordinates ``(d_u, d_c)`` and ``P_pp^-1`` entries ``l_uu,
    l_uc, l_cc``. The range given the bearing has mean ``rbar`` and deviation ``sigma_r``
    (``_range_given_bearing``); the bearing given that range is

        var_b = 1 / (1 / var_beta + rbar^2 l_cc),  b = beta + var_b rbar (l_cc d_c - l_uc
        (rbar - d_u))

    (the prior's cross-range at ``rbar`` fused with the measured bearing). The target is then
    at ``p = origin + rbar u(b)`` with covariance ``C_p = sigma_r^2 u u^T + rbar^2 var_b u'
    u'^T`` (at b), its velocity the prior's given the position, ``v = x_v + G (p - x_p)``,
    ``G = P_vp P_pp^-1``, with covariance ``P_vv - G P_pv + G C_p G^T`` and ``Cov(v, p) =
    G C_p``; ``y`` and ``P_y`` are :func:`cartesian_to_mpc` of that Gaussian, linearised at
    its mean, except that ``1 / r`` is left uncorrelated with the rest. The linearisation's
    ``Cov(beta_dot, 1 / r) = (v_c / r) sigma_w^2`` (``v_c`` the relative velocity across the
    line of sight) is the first-order term of a product of two factors each uncertain by
    tens of percent: with it every bearing-rate
    update moves ``1 / r``, and a run whose prior range is short sweeps it through zero on
    the first leg; without it ``1 / r`` stays where the prior put it until the observer
    manoeuvres and the bearings see the range.

    The prior itself converted (by a linearisation at its mean, or the cubature rule's
    points 2 sigma either side of it) puts ``1 / r`` of a range near zero, or behind the
    observer, into the inverse range's mean and spread when the prior is wide in range.
    """
    x, P = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
    beta, var_beta = np.asarray(beta, dtype=float), np.asarray(var_beta, dtype=float)
    o = np.asarray(origin, dtype=float)
    u, up = _unit(beta)
    Lam = solve_psd(P[..., :2, :2], np.broadcast_to(np.eye(2), P[..., :2, :2].shape),
                    f"{name} (its position block)")
    d = x[..., :2] - o
    Lu, Lup = (Lam @ u[..., None])[..., 0], (Lam @ up[..., None])[..., 0]
    l_uu, l_uc, l_cc = (u * Lu).sum(-1), (u * Lup).sum(-1), (up * Lup).sum(-1)
    d_u, d_c = (d * u).sum(-1), (d * up).sum(-1)
    rbar, sigma_r = _range_given_bearing(d_u, d_c, l_uu, l_uc, l_cc, var_beta)
    var_b = 1.0 / (1.0 / var_beta + rbar * rbar * l_cc)
    u, up = _unit(beta + var_b * rbar * (l_cc * d_c - l_uc * (rbar - d_u)))
    Cp = (sigma_r**2)[..., None, None] * u[..., :, None] * u[..., None, :] + (
        (rbar * rbar * var_b)[..., None, None] * up[..., :, None] * up[..., None, :])
    G = P[..., 2:, :2] @ Lam
    p = o + rbar[..., None] * u
    GC = G @ Cp
    Xs = np.concatenate([p, x[..., 2:] + ((p - x[..., :2])[..., None, :] @ G.mT)[..., 0, :]],
                        -1)
    Ps = np.concatenate([np.concatenate([Cp, GC.mT], -1), np.concatenate(
        [GC, P[..., 2:, 2:] - G @ P[..., :2, 2:] + GC @ G.mT], -1)], -2)
    y, J = cartesian_to_mpc(Xs, o, velocity)
    Py = symmetrize(mm(mm(J, Ps), J.mT))
    # 1 / r apart from the rest (a block-diagonal part of a covariance is one)
    Py[..., 3, :3] = Py[..., :3, 3] = 0.0
    return y, Py


# --------------------------------------------------------------------------------------------
# Modified polar coordinates: the filter
# --------------------------------------------------------------------------------------------


class MPBelief(NamedTuple):
    """Belief of the MPEKF. Where ``polar`` (a row has seen its first bearing), ``mean
    (..., 4)`` and ``cov`` are the MPC state ``[beta, beta_dot, r_dot / r, 1 / r]`` relative
    to an observer at ``origin (..., 2)`` moving at ``velocity (..., 2)``: the observer's
    pose at the last update, carried forward at constant velocity by ``predict`` (the next
    update shifts the frame to the observer's true pose, which is where its manoeuvre
    enters). Elsewhere ``mean`` and ``cov`` are the Cartesian prior ``[x, y, vx, vy]``."""

    mean: Array
    cov: Array
    origin: Array
    velocity: Array
    polar: Array

    def at(self, index) -> MPBelief:
        """The belief at a batch index (every field indexed alike)."""
        return MPBelief(*(np.asarray(a)[index] for a in self))


def _shifted(y: Array, P: Array, dt: ArrayLike, dp: Array, dv: Array) -> tuple[Array, Array]:
    """``y' = f(y)`` and ``P' = J P J^T`` through :func:`mpc_transition`."""
    yn, J = mpc_transition(y, dt, dp, dv)
    return yn, symmetrize(mm(mm(J, P), J.mT))


def _rows(mask: Array, *arrays: Array) -> list[Array]:
    return [np.broadcast_to(a, mask.shape + a.shape[mask.ndim:])[mask] for a in arrays]


def _first_innovation(x: Array, P: Array, o: Array, z: Array, R: Array, sign: float,
                      offset: float, sensor: SensorModel) -> tuple[Array, Array]:
    """Residual and covariance of a bearing against a Cartesian prior, linearised at its
    mean: ``beta = atan2(dx, dy)``, ``H = sign [dy, -dx, 0, 0] / rho^2``."""
    dx, dy = x[..., 0] - o[..., 0], x[..., 1] - o[..., 1]
    rho2 = dx * dx + dy * dy
    zero = np.zeros_like(dx)
    H = sign * np.stack([dy / rho2, -dx / rho2, zero, zero], -1)[..., None, :]
    r = sensor.residual(z, (sign * np.arctan2(dx, dy) + offset)[..., None])
    return r, symmetrize(mm(mm(H, P), H.mT) + R)


class MPEKF(Filter):
    """Modified-polar-coordinates EKF (Aidala and Hammel 1983) for a constant-velocity
    target seen by one bearing sensor.

    State ``y = [beta, beta_dot, r_dot / r, 1 / r]`` relative to the observer (beta
    nautical). Prediction is exact for the target (:func:`mpc_transition`, with ``dp = dv =
    0``: the observer assumed to keep its velocity), ``P- = F P F^T + G Q G^T`` with F its
    Jacobian and G the Jacobian of the MPC of the relative Cartesian state at the predicted
    point (Q the motion model's, Cartesian). At an update the frame moves to the sensor's
    pose (``origin``, ``velocity``: the observer's manoeuvre since the last update, exact in
    the mean, linearised in the covariance), then the bearing update is linear, ``H = [1, 0,
    0, 0]`` (``-1`` for a "math" sensor), with the Joseph form.

    Before a row's first bearing it carries the Cartesian prior (a KF prediction). The
    first bearing starts the MPC state (:func:`mpc_from_bearing`): the bearing from it and
    the prior's cross-range, the inverse range ``1 / rbar`` with deviation ``sigma_r /
    rbar^2`` from the prior's range given that bearing (positive even for a prior whose
    mean is near or behind the observer), uncorrelated with the rest until a manoeuvre
    makes it observable; the rates from the prior's velocity there. That step's innovation
    is the Cartesian prior's, as an EKF reports it. ``estimate`` converts back: ``p = o + u
    / w``, ``v = v_o + (r_dot/r u + beta_dot u') / w`` with its Jacobian for the covariance.

    The sensor must carry the observer's ``velocity`` (``trackkit.models.Bearing(...,
    velocity=...)``; the scenario engine sets it): a sensor without one says the observer is
    at rest.
    """

    name = "MPEKF"

    def init(self, prior: Gaussian) -> MPBelief:
        x, P = check_belief(prior, 4, f"{self.name}.init prior")
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
        return MPBelief(np.broadcast_to(x, batch + (4,)).copy(),
                        register(np.broadcast_to(P, batch + (4, 4)).copy()),
                        np.zeros(batch + (2,)), np.zeros(batch + (2,)), np.zeros(batch, bool))

    def _belief(self, belief, where: str) -> MPBelief:
        if isinstance(belief, MPBelief):
            return belief
        if isinstance(belief, Gaussian):
            return self.init(belief)
        raise ValueError(f"{where}: belief is {type(belief).__name__}; expected an MPBelief "
                         "(MPEKF.init) or a Gaussian")

    def estimate(self, belief: MPBelief) -> Gaussian:
        b = self._belief(belief, f"{self.name}.estimate")
        if not b.polar.any():
            return Gaussian._make((b.mean, b.cov))
        if b.polar.all():
            x, J = mpc_to_cartesian(b.mean, b.origin, b.velocity)
            return Gaussian._make((x, symmetrize(mm(mm(J, b.cov), J.mT))))
        x, P = b.mean.copy(), b.cov.copy()
        y, Py, o, v = _rows(b.polar, b.mean, b.cov, b.origin, b.velocity)
        xp, J = mpc_to_cartesian(y, o, v)
        x[b.polar], P[b.polar] = xp, symmetrize(mm(mm(J, Py), J.mT))
        return Gaussian._make((x, P))

    def predict(self, belief: MPBelief, motion: MotionModel, dt: ArrayLike) -> MPBelief:
        b = self._belief(belief, f"{self.name}.predict belief")
        where = f"{self.name}.predict"
        _constant_velocity(motion, where)
        check_dt(dt, where)
        y, P = check_belief(Gaussian._make((b.mean, b.cov)), 4, f"{where} belief")
        polar = b.polar
        origin = b.origin + np.asarray(dt, dtype=float)[..., None] * b.velocity
        mean, cov = y.copy(), P.copy()
        if polar.any():
            if np.ndim(dt) == 0:
                step = float(dt)
            else:
                step = np.broadcast_to(dt, polar.shape)[polar]
            yp, Pp = _rows(polar, y, P)
            yn, Pn = _shifted(yp, Pp, step, np.zeros(2), np.zeros(2))
            yn[..., 0] = wrap(yn[..., 0])
            # the target's process noise, Cartesian, carried into MPC at the predicted point
            rel, _ = mpc_to_cartesian(yn)
            _, G = mpc_from_relative(rel)
            Q = np.asarray(motion.noise(rel, step), dtype=float)
            mean[polar], cov[polar] = yn, symmetrize(Pn + mmT(mm(G, Q), G))
        if not polar.all():
            cart = ~polar
            xc, Pc = _rows(cart, y, P)
            step = dt if np.ndim(dt) == 0 else np.broadcast_to(dt, cart.shape)[cart]
            g = jacobian_predict(xc, Pc, motion, step)
            mean[cart], cov[cart] = g.mean, g.cov
        return MPBelief(mean, register(symmetrize(cov)), origin, b.velocity, polar)

    def update(self, belief: MPBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[MPBelief, Innovation]:
        b = self._belief(belief, f"{self.name}.update belief")
        where = f"{self.name}.update"
        o, vo, sign = _bearing_sensor(sensor, where)
        y, P = check_belief(Gaussian._make((b.mean, b.cov)), 4, f"{where} belief")
        batch = y.shape[:-1]
        z = check_measurement(z, 1, where, batch)
        miss = missing_rows(z)
        o = np.broadcast_to(o, batch + (2,))
        vo = np.broadcast_to(vo, batch + (2,))
        polar = b.polar
        y, P = y.copy(), P.copy()
        if polar.any():
            # the frame moves to the observer's true pose: its manoeuvre since the last update
            yp, Pp, dp, dv = _rows(polar, y, P, o - b.origin, vo - b.velocity)
            yn, Pn = _shifted(yp, Pp, 0.0, dp, dv)
            yn[..., 0] = wrap(yn[..., 0])
            y[polar], P[polar] = yn, Pn
        first = ~polar if miss is None else ~polar & ~np.broadcast_to(miss, batch)
        offset = 0.0 if sign > 0 else 0.5 * np.pi
        R = np.broadcast_to(np.asarray(sensor.noise, dtype=float), batch + (1, 1))
        if first.any():  # the Cartesian prior's bearing innovation, as an EKF reports it
            xc, Pc, of, vf, zf, Rf = _rows(first, y, P, o, vo, z, R)
            cart = _first_innovation(xc, Pc, of, zf, Rf, sign, offset, sensor)
            start = mpc_from_bearing(xc, Pc, sign * (zf[..., 0] - offset), Rf[..., 0, 0],
                                     of, vf, f"{where} prior cov")
        now_polar = polar | first
        origin = np.where(now_polar[..., None], o, b.origin)
        velocity = np.where(now_polar[..., None], vo, b.velocity)
        H = np.array([[sign, 0.0, 0.0, 0.0]])
        zhat = sign * y[..., :1] + offset
        r = sensor.residual(z, zhat)
        if miss is not None:
            r = np.where(np.isnan(r), 0.0, r)
        yn, Pn, S = condition(y, P, r, H, R)
        if first.any():  # those rows start from their first bearing, which is in them
            r, S = r.copy(), S.copy()
            (yn[first], Pn[first]), (r[first], S[first]) = start, cart
        yn[..., 0] = wrap(yn[..., 0])
        post, innov = keep_prior_where_missing(miss, (y, P), output(yn, Pn, symmetric=True),
                                               Innovation(r, S))
        if not now_polar.all():  # rows still Cartesian have seen nothing
            keep = ~now_polar
            post = Gaussian._make((np.where(keep[..., None], y, post.mean),
                                   register(np.where(keep[..., None, None], P, post.cov))))
        return MPBelief(post.mean, post.cov, origin, velocity, now_polar), innov


# --------------------------------------------------------------------------------------------
# Particle filter with a range-interval prior
# --------------------------------------------------------------------------------------------


class PendingParticles(NamedTuple):
    """Belief of a :class:`RangePF` drawing at its first bearing, until then: the Gaussian
    prior (``mean (..., n)``, ``cov (..., n, n)``, predicted by an EKF step) and the
    generator the particles will be drawn from."""

    mean: Array
    cov: Array
    rng: np.random.Generator


def _log_uniform_ranges(lo: Array, hi: Array, shape: tuple[int, ...],
                        rng: np.random.Generator) -> Array:
    """Ranges with ``log r ~ U(log lo, log hi)``, ``(..., N)``."""
    u = rng.random(shape)
    return lo[..., None] * (hi / lo)[..., None] ** u


def conditioned_on_bearing(x: Array, P: Array, origin: Array, beta: Array, sigma: Array,
                           n_particles: int, rng: np.random.Generator) -> tuple[Array, Array]:
    """Particles and log-weights of the Gaussian prior ``N(x, P)`` conditioned on one
    bearing, by importance sampling along the bearing's rays (exact for any Gaussian prior).

    With ``u(b) = (sin b, cos b)`` (nautical), a position on the ray of bearing b from the
    sensor o is ``p = o + r u``, and along that ray the prior's position density is Gaussian
    in r: with ``Lambda = P_pp^-1``, ``d = x_p - o``, ``a = u^T Lambda u`` and
    ``mu = u^T Lambda d / a``, ``N(p; x_p, P_pp) = K(b) N(r; mu, 1/a) / Phi(mu sqrt(a))``,
    ``K(b) = exp(-(d^T Lambda d - a mu^2) / 2) Phi(mu sqrt(a)) / (2 pi sqrt(a |P_pp|))``.
    The proposal draws ``b ~ N(beta, sigma^2)`` (beta the measured bearing), then
    ``r ~ N(mu, 1/a)`` truncated to ``r > 0``, then the other components from the prior
    conditioned on the position, ``N(x_v + P_vp Lambda (p - x_p), P_vv - P_vp Lambda P_pv)``.
    Its density in Cartesian coordinates carries the polar Jacobian ``1 / r``, and the
    bearing's likelihood ``N(beta; b, sigma^2)`` equals the proposal's ``N(b; beta,
    sigma^2)``, so the weight ``prior x likelihood / proposal`` is ``K(b) r``.

    ``x (..., n)``, ``P (..., n, n)`` (positions first), ``origin (..., 2)``, ``beta (...)``
    nautical, ``sigma (...)``; returns ``(states (..., N, n), log_weights (..., N))``,
    normalised.
    """
    from scipy.special import log_ndtr, ndtr, ndtri

    batch, n, N = x.shape[:-1], x.shape[-1], n_particles
    b = beta[..., None] + sigma[..., None] * standard_normals(rng, batch + (N,))
    u = np.stack([np.sin(b), np.cos(b)], -1)  # (..., N, 2)
    Lam = np.linalg.inv(P[..., :2, :2])
    d = x[..., :2] - origin
    Lu = u @ Lam  # Lambda is symmetric: rows u^T Lambda
    a = (Lu * u).sum(-1)
    mu = (Lu * d[..., None, :]).sum(-1) / a
    s = 1.0 / np.sqrt(a)
    # r = mu + s Y, Y > -mu / s: Y = -ndtri(V Phi(mu / s)), V ~ U(0, 1] (the upper tail's
    # form stays accurate when the ray points away from the prior and Phi(mu / s) is tiny)
    v = 1.0 - rng.random(batch + (N,))
    r = np.maximum(mu - s * ndtri(v * ndtr(mu / s)), 1e-9 * np.abs(mu) + 1e-300)
    X = np.empty(batch + (N, n))
    X[..., :2] = origin[..., None, :] + r[..., None] * u
    if n > 2:
        G = P[..., 2:, :2] @ Lam  # P_vp Lambda
        Xv = x[..., None, 2:] + (X[..., :2] - x[..., None, :2]) @ G.mT
        L = psd_factor(P[..., 2:, 2:] - G @ P[..., :2, 2:], "PF.update: prior velocity")
        X[..., 2:] = Xv + standard_normals(rng, batch + (N, n - 2)) @ L.mT
    dLd = (d * (Lam @ d[..., None])[..., 0]).sum(-1)
    lw = -0.5 * (dLd[..., None] - a * mu * mu) + log_ndtr(mu / s) - 0.5 * np.log(a) + np.log(r)
    lw, _ = rs.normalise_log_weights(lw)
    return X, lw


class RangePF(Filter):
    """The bootstrap particle filter (:class:`~trackkit.filters.particle.PF`, whose options
    the first five and ``shrink`` are) with a choice of prior.

    ``prior="gaussian"``: the particles are drawn from the Gaussian prior at ``init``, as
    ``PF.init`` does: the same information as every other filter and the PCRLB.
    ``prior="bearing"``: the same Gaussian prior, but drawn at the row's first bearing and
    conditioned on it (:func:`conditioned_on_bearing`: along the bearing's rays, ranges from
    the prior's density on each ray, the rest from the prior given the position, weighted
    exactly). A prior that is wide across the line of sight (km, against a bearing's tens of
    metres) leaves only a few of its draws near the bearing, and fewer still when the target
    lies in the prior's tail; this puts every particle where the bearing allows, with the
    same information as ``"gaussian"``.
    ``prior="range"``: at the row's first bearing z (sensor at o, noise sigma), particle
    i is ``o + r_i (sin b_i, cos b_i)`` with ``b_i ~ N(z, sigma^2)`` (nautical) and
    ``log r_i`` uniform over ``[r_min, r_max]`` (default: the prior's range along that line
    of sight +- 4 of its standard deviations, at least 0.05 of the range, as the RPEKF), and
    velocity drawn from the prior's velocity marginal; the weights are uniform, since the
    bearing was used in the draw (the update at that step changes nothing else). This is the
    prior of Arulampalam and Ristic (2000): it ignores what the Gaussian prior says about
    range and cross-range, so against a PCRLB that includes that prior it gives information
    away; it is for a user whose prior is only a range interval.
    """

    name = "PF"
    stochastic = True

    def __init__(self, n_particles: int = 1000, resampler: str = "systematic",
                 ess_threshold: float = 0.5, regularise: bool = False,
                 roughening: float = 0.0, prior: str = "gaussian", r_min: float | None = None,
                 r_max: float | None = None, shrink: bool = False) -> None:
        self.pf = PF(n_particles, resampler, ess_threshold, regularise, roughening,
                     shrink=shrink)
        if prior not in ("gaussian", "bearing", "range"):
            raise ValueError(f"PF prior = {prior!r}; expected 'gaussian', 'bearing' or 'range'")
        for name, value in (("r_min", r_min), ("r_max", r_max)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"PF {name} = {value!r}; expected a range > 0 m or None")
        if r_min is not None and r_max is not None and not r_max > r_min:
            raise ValueError(f"PF r_max = {r_max!r}; expected a range > r_min = {r_min!r}")
        if prior != "range" and (r_min is not None or r_max is not None):
            raise ValueError(f"PF r_min = {r_min!r}, r_max = {r_max!r}: the range interval is "
                             "only for prior = 'range'")
        self.prior = prior
        self.r_min = None if r_min is None else float(r_min)
        self.r_max = None if r_max is None else float(r_max)

    def __repr__(self) -> str:
        return (f"RangePF(pf={self.pf!r}, prior={self.prior!r}, r_min={self.r_min!r}, "
                f"r_max={self.r_max!r})")

    def init(self, prior: Gaussian, rng: np.random.Generator | None = None
             ) -> Particles | PendingParticles:
        if self.prior == "gaussian" or isinstance(prior, Particles):
            return self.pf.init(prior, rng)
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"PF.init: rng is a {type(rng).__name__}; expected a "
                             "numpy.random.Generator or None")
        x, P = check_belief(prior, None, "PF.init prior")
        batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2])
        return PendingParticles(np.broadcast_to(x, batch + x.shape[-1:]).copy(),
                                register(np.broadcast_to(P, batch + P.shape[-2:]).copy()),
                                np.random.default_rng() if rng is None else rng)

    def estimate(self, belief: Particles | PendingParticles) -> Gaussian:
        if isinstance(belief, PendingParticles):
            return Gaussian._make((belief.mean, belief.cov))
        return self.pf.estimate(belief)

    def predict(self, belief: Particles | PendingParticles, motion: MotionModel, dt: ArrayLike
                ) -> Particles | PendingParticles:
        if isinstance(belief, PendingParticles):
            g = _EKF.predict(Gaussian._make((belief.mean, belief.cov)), motion, dt)
            return PendingParticles(g.mean, g.cov, belief.rng)
        return self.pf.predict(belief, motion, dt)

    def update(self, belief: Particles | PendingParticles, z: ArrayLike,
               sensor: SensorModel) -> tuple[Particles | PendingParticles, Innovation]:
        if not isinstance(belief, PendingParticles):
            return self.pf.update(belief, z, sensor)
        where = "PF.update"
        x, P = check_belief(Gaussian._make((belief.mean, belief.cov)), None, f"{where} belief")
        o, _, sign = _bearing_sensor(sensor, where)
        batch = x.shape[:-1]
        z = check_measurement(z, 1, where, batch)
        miss = missing_rows(z)
        # the innovation of this step: the Gaussian prior's, as an EKF would report it
        _, innov = _EKF.update(Gaussian._make((x, P)), z, sensor)
        if miss is not None and miss.all():
            return PendingParticles(x, P, belief.rng), innov
        rng, N, n = belief.rng, self.pf.n_particles, x.shape[-1]
        Xg = self.pf.init(Gaussian._make((x, P)), rng).states  # rows without a bearing
        zb = np.broadcast_to(z[..., 0] if miss is None else np.where(miss, 0.0, z[..., 0]),
                             batch)
        beta = sign * (zb - (0.0 if sign > 0 else 0.5 * np.pi))  # nautical bearing of z
        o = np.broadcast_to(o, batch + (2,))
        sigma_b = np.broadcast_to(np.sqrt(sensor.noise[..., 0, 0]), batch)
        if self.prior == "bearing":
            X, lw = conditioned_on_bearing(x, P, o, beta, sigma_b, N, rng)
            if miss is not None:  # those rows keep the Gaussian draw, as the PF would make it
                X = np.where(miss[..., None, None], Xg, X)
                lw = np.where(miss[..., None], -math.log(N), lw)
            pf = self.pf
            X, lw, _ = resample_rows(X, lw, rng, pf.ess_threshold, pf.resampler, pf.regularise,
                                     pf.roughening, (), miss, None, pf.shrink)
            return Particles._make((register(X), lw, rng, None)), innov
        u = np.stack([np.sin(beta), np.cos(beta)], -1)
        rbar = ((x[..., :2] - o) * u).sum(-1)
        sigma = np.sqrt(np.einsum("...i,...ij,...j->...", u, P[..., :2, :2], u))
        lo = np.maximum(rbar - 4.0 * sigma, MIN_RANGE_FRACTION * np.abs(rbar))
        lo = lo if self.r_min is None else np.full(batch, self.r_min)
        hi = rbar + 4.0 * sigma if self.r_max is None else np.full(batch, self.r_max)
        if not np.all(hi > lo):
            raise ValueError(f"{where}: the range interval [r_min, r_max] = [{self.r_min}, "
                             f"{self.r_max}] is empty for the prior's line of sight; "
                             "expected r_max > r_min > 0")
        r = _log_uniform_ranges(lo, hi, batch + (N,), rng)
        b = beta[..., None] + sign * sigma_b[..., None] * standard_normals(rng, batch + (N,))
        X = np.empty(batch + (N, n))
        X[..., 0] = o[..., None, 0] + r * np.sin(b)
        X[..., 1] = o[..., None, 1] + r * np.cos(b)
        X[..., 2:] = Xg[..., 2:]  # velocity (and any extras) from the Gaussian prior
        lw = np.full(batch + (N,), -math.log(N))
        if miss is not None:  # those rows keep the Gaussian draw, as the PF would make it
            X = np.where(miss[..., None, None], Xg, X)
        return Particles._make((register(X), lw, rng, None)), innov
