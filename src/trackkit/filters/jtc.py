r"""Joint tracking and classification with multiple-model particle filters (Hosseini, Haeri and
Khaloozadeh 2019).

Two filters estimate the state ``x = [x, y, vx, vy]`` and the class ``c`` of a target (an
airliner or a fighter, :mod:`trackkit.models.classes`) from radar plots:

* :class:`JTC`, the paper's single filter (Table 1): each particle carries a
  state, a class label and a manoeuvre mode; particles are allocated to the classes at every
  step by :math:`N_c \sim \operatorname{Mult}(N, p(c \mid Z^k))` with a floor, and resampled
  within their class.
* :class:`MultiFilterJTC`, the paper's baseline (Fig. 1): one multiple-model particle filter
  per class, each with its class's modes and a fixed number of particles, combined by
  Bayes' rule.

Both run the same step for each particle j of class :math:`c = c^j`: the class's mode chain
(drawn by inverse CDF), the mode's motion with :math:`\mathbf{w} \sim \mathcal{N}(0,
\sigma^2 I)`, and the weight, the kinematic likelihood times the speed likelihood:

.. math::

    m_k^j &\sim p(m_k \mid m_{k-1}^j) \\
    \mathbf{x}_k^j &= F(\omega_m)\, \mathbf{x}_{k-1}^j + G (\mathbf{a}_m + \mathbf{w}) \\
    w_k^j &= p(\mathbf{z}_k \mid \mathbf{x}_k^j)\, g(v^j \mid c)

and the same class posterior. With the weights normalised within each class (each class's
particles represent :math:`p(\mathbf{x}_k \mid c, Z^{k-1})` whatever their number), the class
likelihood is the mean of the class's unnormalised weights and Bayes' rule is

.. math::

    L(c) &= p(\mathbf{z}_k, y_k \mid c, Z^{k-1})
        = \frac{1}{N_c} \sum_{j \in c} p(\mathbf{z}_k \mid \mathbf{x}_k^j)\, g(v^j \mid c) \\
    p(c \mid Z^k) &= \frac{L(c)\, p(c \mid Z^{k-1})}{\sum_{c'} L(c')\, p(c' \mid Z^{k-1})}

Table 1 of the paper instead normalises the weights over all N particles (each 1/N after
resampling) and takes ``L(c) = sum_{j in c} w_k^j``: that sum is proportional to
``(N_c / N) L(c)``, and since ``N_c`` was drawn from ``Mult(N, p(c | Z^{k-1}))`` it already
carries the prior ``p(c | Z^{k-1})``, which the recursion then multiplies in a second time.
While both classes are above the floor the log-odds double at every step
(``lambda_k ~ 2 lambda_{k-1} + l_k``); once the trailing class is held at its floor, the extra
factor is a push of ``log((N - n_floor) / n_floor) = log 19 = 2.9`` per step toward the
leader, more than the largest evidence the speed likelihoods can give (``log(0.95 / 0.1) =
2.25``), so an early lead is never undone. ``recursion="bayes"`` (default) is the correct
recursion; ``recursion="paper"`` keeps the printed one (``L(c) N_c / N``) for comparison
(docs/jtc-comparison.md gives the numbers).

The speed ``v`` in ``g(v | c)`` (A.6's question): ``speed="estimate"`` (default) evaluates
it once per class on the speed of the previous step's overall estimate, the paper's words
("the speed estimated at the previous step", standing in for a class measurement ``y_k``),
so g weighs the classes and leaves the particles' weights within a class alone;
``speed="particle"`` evaluates it on each particle's own speed, so that g also acts on the
state, as a prior on the class's speeds applied again at every step: it pulls the fighter
class's speeds up and the airliner's down (g rises with speed for c2 and falls for c1). On
the bundled scenarios that costs 4-6% of position RMSE for the same classification
(docs/jtc-comparison.md).

The floor (A.6: how ``N_Thr = 0.1 N_c`` is enforced): ``n_floor = floor x particles_per_class``
particles are reserved for every class first, and the other ``N - s n_floor`` are allocated by
``Mult(N - s n_floor, p(c | Z^k))``; every class keeps at least ``n_floor`` particles, the
expected count of a likely class is ``n_floor + (N - s n_floor) p(c)``, and a class whose
probability has collapsed still has particles to measure its likelihood with, so a wrong
decision can be undone. Resampling within classes is one systematic pass over the weights
rescaled to ``N_c / N`` per class, which gives each class exactly its ``N_c`` offspring.

Estimates (computed before resampling, from the weighted particles): the class-conditional
means and the overall mixture,

.. math::

    \mathbf{x}^c = \sum_{j \in c} w^j \mathbf{x}^j, \qquad
    \mathbf{x} = \sum_c p(c \mid Z^k)\, \mathbf{x}^c

with its covariance (the particles' covariance under the weights ``p(c^j) w^j``).

Both filters are stateless strategies, batched over runs: their beliefs carry the particles
as one ``(..., N)`` array per state component (``belief.states`` stacks them, ``(..., N, 4)``)
and the generator they draw from; every step resamples (the allocation is part of it).
``predict`` ignores the motion model it is given (each class has its own modes). Particles
are kept sorted by class within each batch row (class 0's first), which resampling
preserves, so per-class sums are segment sums.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import check_dt, check_measurement, register
from trackkit.filters.particle_fast import standard_normals
from trackkit.filters.resample import logsumexp, systematic
from trackkit.linalg import check_covariance, psd_factor
from trackkit.models.classes import (
    ALONG,
    PAPER_CLASSES,
    TargetClass,
    mode_step_components,
    turn_terms,
)
from trackkit.models.protocols import MotionModel, SensorModel
from trackkit.models.sensors import RangeBearing

__all__ = ["JTC", "JTCBelief", "MultiFilterJTC", "MultiFilterBelief", "next_modes",
           "RECURSIONS", "SPEEDS"]

Array = NDArray[np.float64]
Ints = NDArray[np.integer]

#: The class recursions of ``JTC(recursion=...)``: Bayes' rule or the paper's printed one.
RECURSIONS = ("bayes", "paper")
#: Where ``JTC(speed=...)`` evaluates the speed likelihood: the previous overall estimate's
#: speed, or each particle's own.
SPEEDS = ("estimate", "particle")


# --------------------------------------------------------------------------------------------
# Kernels (particles as components: one contiguous (B, N) array per state component, where
# numpy's loops run several times faster than on the strided columns of a (B, N, 4) array)
# --------------------------------------------------------------------------------------------


def next_modes(rows: Ints, cdf: Array, u: Array) -> NDArray[np.int8]:
    """Each particle's next mode by inverse-CDF sampling (step 1 of the MMPF).

    ``cdf[r]`` is row r of a transition matrix, cumulated: ``b_j = p_r1 + ... + p_rj``;
    particle i in row ``rows[i]`` (its class's table row for its current mode) with the
    uniform ``u[i]`` in [0, 1) moves to the mode j with ``b_{j-1} <= u < b_j`` (``b_0 = 0``),
    i.e. ``j = #{l < M : b_l <= u}`` (0-based). The comparisons run in the precision of u
    (a filter draws it in single precision: half the memory traffic, and a resolution of
    2^-24 in the probabilities, far below any transition's).
    """
    out = np.zeros(np.shape(u), dtype=np.int8)
    b = cdf.astype(u.dtype)
    for j in range(cdf.shape[1] - 1):
        out += np.take(b[:, j], rows) <= u
    return out


class _Tables(NamedTuple):
    """Per (class, mode) row ``r = c M + m``: the cumulated transition row and the motion's
    terms for one step (``sin(wT)/w``, ``(1 - cos(wT))/w``, ``cos``, ``sin``, ``u``)."""

    cdf: Array  # (C M, M)
    s: Array
    c: Array
    cos: Array
    sin: Array
    u: Array


def _tables(classes: tuple[TargetClass, ...], dt: float) -> _Tables:
    cdf = np.concatenate([np.cumsum(k.transition, axis=1) for k in classes])
    omega = np.concatenate([k.turn_rates for k in classes])
    s, c, cos, sin = turn_terms(omega, dt)
    u = np.concatenate([k.accelerations for k in classes])
    return _Tables(cdf, s, c, cos, sin, u)


Parts = tuple[Array, Array, Array, Array]


def _propagate(X: Parts, rows: Ints, tab: _Tables, wx: Array, wy: Array, dt: float,
               along: str) -> Parts:
    """``x_k = F(omega_r) x_{k-1} + G (a_r + w)`` per particle, r its (class, mode) row."""
    return mode_step_components(*X, np.take(tab.s, rows), np.take(tab.c, rows),
                                np.take(tab.cos, rows), np.take(tab.sin, rows),
                                np.take(tab.u, rows), dt, wx, wy, along)


def _residuals(X: Parts, z: Array, sensor: SensorModel) -> tuple[Array, ...]:
    """``z - h(x^j)`` per particle, one ``(B, N)`` array per measurement component, angles
    wrapped to (-pi, pi].

    For a 2-D ``RangeBearing`` at a fixed origin the bearing residual is formed without the
    bearing: ``z_b - b = atan2(sin(z_b - b), cos(z_b - b))``, the sine and cosine of the
    difference taken from the measured direction ``(sin z_b, cos z_b)`` and the particle's
    offset ``(dx, dy)`` (nautical: ``r sin = dy sin z_b - dx cos z_b``,
    ``r cos = dy cos z_b + dx sin z_b``; r cancels): the wrapped residual exactly, with one
    arctan2 per particle and no wrap. Any other sensor goes through its ``h`` and
    ``residual``.
    """
    if type(sensor) is RangeBearing and np.shape(sensor.origin) == (2,):
        # in place throughout (see classes.mode_step_components: fresh temporaries cost page faults)
        dx = np.subtract(X[0], sensor.origin[0])
        dy = np.subtract(X[1], sensor.origin[1])
        if sensor.convention != "nautical":  # math: the roles of x and y swap
            dx, dy = dy, dx
        rr = np.multiply(dx, dx)
        tmp = np.multiply(dy, dy)
        rr += tmp
        np.sqrt(rr, out=rr)
        np.subtract(z[:, 0:1], rr, out=rr)  # z_r - r
        sz, cz = np.sin(z[:, 1:2]), np.cos(z[:, 1:2])
        num = np.multiply(dy, sz)
        np.multiply(dx, cz, out=tmp)
        num -= tmp  # r sin(z_b - b)
        np.multiply(dx, sz, out=tmp)
        np.multiply(dy, cz, out=dy)
        dy += tmp  # r cos(z_b - b)
        return rr, np.arctan2(num, dy, out=num)
    r = np.asarray(sensor.residual(z[:, None, :], sensor.h(np.stack(X, -1))), dtype=float)
    return tuple(r[..., i] for i in range(r.shape[-1]))


def _log_likelihood(r: tuple[Array, ...], R: Array) -> Array:
    """``log p(z | x^j) = -r^T R^{-1} r / 2`` per particle, up to a constant shared by all
    particles and classes (it cancels in every ratio the filters take)."""
    Rinv = np.linalg.inv(R)
    q = np.zeros(np.shape(r[0]))
    tmp = np.empty_like(q)
    for i in range(len(r)):
        for j in range(i, len(r)):
            if Rinv[i, j] != 0:
                np.multiply(r[i], r[j], out=tmp)
                tmp *= -0.5 * Rinv[i, j] * (1 if i == j else 2)
                q += tmp
    return q


def _moments(parts: Sequence[Array], w: Array) -> tuple[Array, Array]:
    """Weighted mean ``(B, n)`` and covariance ``(B, n, n)`` of particles given as n
    component arrays ``(B, N)``, weights ``w (B, N)`` summing to 1 per row:
    ``m = sum_j w_j x_j``, ``P = sum_j w_j (x_j - m)(x_j - m)^T`` (exactly symmetric).
    (trackkit.filters.resample.weighted_mean_cov for this layout.)"""
    D = np.stack(parts, axis=1)  # (B, n, N)
    m = (D @ w[..., None])[..., 0]
    D -= m[..., None]
    P = (D * w[:, None, :]) @ D.mT
    return m, 0.5 * (P + P.mT)


def _segments(counts: Ints) -> NDArray[np.intp]:
    """Start of each (row, class) segment in the flattened particle axis: particles of one
    row are sorted by class, so class c of row b starts at ``b N + sum_{c' < c} N_c'``."""
    B, C = counts.shape
    N = int(counts[0].sum())
    starts = np.zeros((B, C), dtype=np.intp)
    np.cumsum(counts[:, :-1], axis=1, out=starts[:, 1:])
    starts += (np.arange(B, dtype=np.intp) * N)[:, None]
    return starts.ravel()


def _per_particle(values: Array, counts: Ints) -> Array:
    """A per-(row, class) value ``(B, C)`` repeated over the class's particles, ``(B, N)``."""
    B = counts.shape[0]
    return np.repeat(values.ravel(), counts.ravel()).reshape(B, -1)


def _speed_likelihood(classes: tuple[TargetClass, ...], labels: Ints, speed: Array) -> Array:
    """``g(v^j | c^j)`` per particle."""
    g = classes[0].speed_likelihood(speed)
    for i, k in enumerate(classes[1:], start=1):
        g = np.where(labels == i, k.speed_likelihood(speed), g)
    return g


def _resample_rows(parts: Sequence[Array], idx: NDArray[np.intp]) -> list[Array]:
    """``a[b, idx[b, j]]`` for each ``(B, N)`` array a (one flat take each)."""
    B, N = idx.shape
    flat = (idx + (np.arange(B, dtype=np.intp) * N)[:, None]).ravel()
    return [np.take(a.reshape(-1), flat).reshape(B, N) for a in parts]


def _check_prior(prior: Gaussian, where: str) -> tuple[Array, Array]:
    x = np.asarray(prior.mean, dtype=float)
    if x.ndim < 1 or x.shape[-1] != 4:
        raise ValueError(f"{where}: prior.mean has shape {x.shape}; expected (..., 4), the "
                         "state [x, y, vx, vy]")
    if not np.isfinite(x).all():
        raise ValueError(f"{where}: prior.mean has non-finite entries; expected finite values")
    P = check_covariance(prior.cov, f"{where} prior.cov", n=4)
    return x, np.broadcast_to(P, x.shape[:-1] + (4, 4))


def _check_classes(classes: Sequence[TargetClass], where: str) -> tuple[TargetClass, ...]:
    classes = tuple(classes)
    if not classes or not all(isinstance(k, TargetClass) for k in classes):
        raise ValueError(f"{where}: classes = {classes!r}; expected one or more TargetClass")
    names = [k.name for k in classes]
    if len(set(names)) != len(names):
        raise ValueError(f"{where}: class names {names} repeat; expected distinct names")
    M = {k.n_modes for k in classes}
    if len(M) != 1:
        raise ValueError(f"{where}: the classes have {sorted(M)} modes; expected the same "
                         "number of modes in every class (one mode chain per particle)")
    return classes


def _check_int(value: object, name: str, where: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        raise ValueError(f"{where}: {name} = {value!r}; expected an integer >= {low}")
    return int(value)


def _check_choice(value: object, name: str, allowed: tuple[str, ...], where: str) -> str:
    if value not in allowed:
        raise ValueError(f"{where}: {name} = {value!r}; expected one of {allowed}")
    return str(value)


def _check_sigma(sigma: object, where: str) -> float:
    if isinstance(sigma, bool) or not isinstance(sigma, int | float) or not (
            math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"{where}: sigma = {sigma!r}; expected a finite acceleration noise "
                         "standard deviation >= 0 (m/s^2)")
    return float(sigma)


def _with_diagonal(classes: tuple[TargetClass, ...], diagonal: float | None,
                   where: str) -> tuple[TargetClass, ...]:
    if diagonal is None:
        return classes
    if isinstance(diagonal, bool) or not isinstance(diagonal, int | float) or not (
            0 <= diagonal <= 1):
        raise ValueError(f"{where}: diagonal = {diagonal!r}; expected a probability in "
                         "[0, 1] (or None: each class's own transition)")
    return tuple(k.with_transition(float(diagonal)) for k in classes)


def _class_prior(class_prior: ArrayLike | None, C: int, where: str) -> Array:
    if class_prior is None:
        return np.full(C, 1.0 / C)
    p = np.asarray(class_prior, dtype=float)
    if p.shape != (C,) or not np.isfinite(p).all() or (p <= 0).any() or abs(
            math.fsum(p.tolist()) - 1.0) > 1e-9:
        raise ValueError(f"{where}: class_prior = {np.asarray(class_prior).tolist()!r}; "
                         f"expected {C} probabilities > 0 summing to 1")
    return p


def _mixture(means: Array, covs: Array, p: Array) -> tuple[Array, Array]:
    """Mean and covariance of ``sum_c p_c N(means_c, covs_c)`` (``(..., C, n)``, ``(..., C,
    n, n)``, ``(..., C)``)."""
    m = (p[..., None] * means).sum(-2)
    d = means - m[..., None, :]
    P = (p[..., None, None] * (covs + d[..., :, None] * d[..., None, :])).sum(-3)
    return m, 0.5 * (P + P.mT)


# --------------------------------------------------------------------------------------------
# The single filter
# --------------------------------------------------------------------------------------------


class JTCBelief(NamedTuple):
    """What :class:`JTC` carries between steps; batch axes ``...`` first.

    The particles, equally weighted within their class: their components ``x``, ``y`` (m),
    ``vx``, ``vy`` (m/s), class ``labels`` (sorted within each row) and ``modes``, each
    ``(..., N)`` (``states`` stacks the components, ``(..., N, 4)``); ``counts (..., C)``
    particles per class; ``log_class_prob (..., C)`` the class posterior (log); ``rng`` the
    generator the filter draws from; ``speed (...,)`` the speed of the last estimate (for
    ``speed="estimate"``); ``mean``, ``cov`` and ``class_mean (..., C, 4)``: the estimates of
    the last update (None after a prediction)."""

    x: Array
    y: Array
    vx: Array
    vy: Array
    labels: NDArray[np.int8]
    modes: NDArray[np.int8]
    counts: NDArray[np.int64]
    log_class_prob: Array
    rng: np.random.Generator
    speed: Array
    mean: Array | None = None
    cov: Array | None = None
    class_mean: Array | None = None

    @property
    def states(self) -> Array:
        """The particles' states ``(..., N, 4)``."""
        return np.stack((self.x, self.y, self.vx, self.vy), -1)

    @property
    def class_prob(self) -> Array:
        """``p(c | Z^k)``, ``(..., C)``."""
        return np.exp(self.log_class_prob)


def _draw_prior(prior: Gaussian, shape: tuple[int, ...], rng: np.random.Generator,
                where: str) -> tuple[tuple[int, ...], Parts]:
    """Particles from the prior: components of shape ``batch + shape``."""
    x, P = _check_prior(prior, where)
    batch = x.shape[:-1]
    L = psd_factor(P, f"{where} prior.cov")
    e = standard_normals(rng, batch + (4,) + shape)
    k = len(shape)
    parts = tuple(x[(..., i) + (None,) * k]
                  + sum(L[(..., i, j) + (None,) * k] * e[(..., j) + (slice(None),) * k]
                        for j in range(4))
                  for i in range(4))
    return batch, parts


class JTC:
    """Joint tracking and classification by one multiple-model particle filter whose particles
    carry a class label (Hosseini, Haeri and Khaloozadeh 2019, Table 1; module docstring).

    ``classes``: the target classes (default the paper's airliner and fighter);
    ``particles_per_class`` N_c (N = s N_c in all); ``floor``: the fraction of N_c every class
    keeps (the paper's ``N_Thr = 0.1 N_c``); ``sigma``: the acceleration noise standard
    deviation (m/s^2) of every mode; ``diagonal``: the mode transition's diagonal for every
    class (None: each class's own); ``recursion``: "bayes" or the paper's printed "paper";
    ``speed``: g on the previous "estimate"'s speed or on each "particle"'s;
    ``acceleration``: a CA mode's u along the "velocity" or on both "axes";
    ``class_prior``: ``p(c)`` at the start (default uniform).
    """

    name = "JTC"
    stochastic = True

    def __init__(self, classes: Sequence[TargetClass] = PAPER_CLASSES,
                 particles_per_class: int = 5000, floor: float = 0.1, sigma: float = 10.0,
                 diagonal: float | None = None, recursion: str = "bayes",
                 speed: str = "estimate", acceleration: str = "velocity",
                 class_prior: ArrayLike | None = None) -> None:
        where = "JTC"
        self.classes = _with_diagonal(_check_classes(classes, where), diagonal, where)
        self.particles_per_class = _check_int(particles_per_class, "particles_per_class",
                                              where)
        if isinstance(floor, bool) or not isinstance(floor, int | float) or not (
                0 < floor <= 1):
            raise ValueError(f"{where}: floor = {floor!r}; expected a fraction in (0, 1] of "
                             "particles_per_class that every class keeps")
        self.floor = float(floor)
        self.n_floor = math.floor(self.floor * self.particles_per_class + 1e-9)
        if self.n_floor < 1:
            raise ValueError(f"{where}: floor = {floor!r} keeps "
                             f"{self.floor * self.particles_per_class:g} of particles_per_class"
                             f" = {particles_per_class}; expected at least 1 particle per "
                             "class (floor >= 1 / particles_per_class)")
        self.sigma = _check_sigma(sigma, where)
        self.diagonal = diagonal
        self.recursion = _check_choice(recursion, "recursion", RECURSIONS, where)
        self.speed = _check_choice(speed, "speed", SPEEDS, where)
        self.acceleration = _check_choice(acceleration, "acceleration", ALONG, where)
        self.class_prior = _class_prior(class_prior, len(self.classes), where)
        self._cache: dict[float, _Tables] = {}

    @property
    def class_names(self) -> tuple[str, ...]:
        return tuple(k.name for k in self.classes)

    @property
    def n_particles(self) -> int:
        return len(self.classes) * self.particles_per_class

    def _tables(self, dt: float) -> _Tables:
        tab = self._cache.get(dt)
        if tab is None:
            if len(self._cache) > 64:
                self._cache.clear()
            tab = self._cache[dt] = _tables(self.classes, dt)
        return tab

    def __repr__(self) -> str:
        return (f"JTC(classes={self.class_names}, particles_per_class="
                f"{self.particles_per_class}, floor={self.floor}, sigma={self.sigma}, "
                f"diagonal={self.diagonal}, recursion={self.recursion!r}, "
                f"speed={self.speed!r}, acceleration={self.acceleration!r})")

    # -- init, predict -----------------------------------------------------------------------

    def init(self, prior: Gaussian, rng: np.random.Generator | None = None) -> JTCBelief:
        """N = s N_c particles per batch row drawn from the prior, N_c of each class, modes
        uniform over the class's modes, ``p(c)`` the class prior."""
        rng = np.random.default_rng() if rng is None else rng
        C, Nc = len(self.classes), self.particles_per_class
        N = C * Nc
        batch, parts = _draw_prior(prior, (N,), rng, "JTC.init")
        labels = np.broadcast_to(np.repeat(np.arange(C, dtype=np.int8), Nc), batch + (N,))
        modes = rng.integers(0, self.classes[0].n_modes, size=batch + (N,), dtype=np.int8)
        mean = np.asarray(prior.mean, dtype=float)
        return JTCBelief(*parts, labels.copy(), modes, np.full(batch + (C,), Nc, np.int64),
                         np.broadcast_to(np.log(self.class_prior), batch + (C,)).copy(), rng,
                         np.hypot(mean[..., 2], mean[..., 3]))

    def predict(self, belief: JTCBelief, motion: MotionModel | None = None,
                dt: float = 1.0) -> JTCBelief:
        """Each particle's next mode from its class's chain, then its state by the mode's
        motion with acceleration noise ``sigma`` (``motion`` is not used)."""
        check_dt(dt, "JTC.predict")
        dt = float(dt)
        tab = self._tables(dt)
        M = self.classes[0].n_modes
        rng = belief.rng
        shape = belief.modes.shape
        base = belief.labels.astype(np.intp) * M
        m = next_modes(base + belief.modes, tab.cdf, rng.random(shape, dtype=np.float32))
        w = standard_normals(rng, (2,) + shape)
        w *= self.sigma
        X = _propagate((belief.x, belief.y, belief.vx, belief.vy), base + m, tab, w[0], w[1],
                       dt, self.acceleration)
        return belief._replace(x=X[0], y=X[1], vx=X[2], vy=X[3], modes=m, mean=None,
                               cov=None, class_mean=None)

    # -- update ------------------------------------------------------------------------------

    def update(self, belief: JTCBelief, z: ArrayLike,
               sensor: SensorModel) -> tuple[JTCBelief, Innovation]:
        """Weights ``p(z | x) g(v | c)``, the class posterior, the estimates, then the
        allocation ``N_c`` and resampling within each class (module docstring). A row whose
        z is missing (nan) keeps its prediction and its class posterior."""
        batch, N = belief.x.shape[:-1], belief.x.shape[-1]
        C = len(self.classes)
        z = check_measurement(z, sensor.dim_z, "JTC.update", batch)
        B = math.prod(batch)
        X = tuple(a.reshape(B, N) for a in (belief.x, belief.y, belief.vx, belief.vy))
        labels = belief.labels.reshape(B, N)
        modes = belief.modes.reshape(B, N)
        counts = belief.counts.reshape(B, C)
        lp_prev = belief.log_class_prob.reshape(B, C)
        zf = np.broadcast_to(z, batch + (sensor.dim_z,)).reshape(B, -1)
        miss = np.isnan(zf).any(-1)
        some_missing = bool(miss.any())
        if some_missing:
            zf = np.where(miss[:, None], 0.0, zf)
        starts = _segments(counts)

        # weights p(z | x^j) g(v^j | c^j), normalised within each class
        R = np.asarray(sensor.noise, dtype=float)
        r = _residuals(X, zf, sensor)
        ll = _log_likelihood(r, R)
        g = None
        if self.speed == "particle":
            g = _speed_likelihood(self.classes, labels, np.sqrt(X[2] * X[2] + X[3] * X[3]))
        if some_missing:
            ll[miss] = 0.0
            if g is not None:
                g[miss] = 1.0
        top = np.maximum.reduceat(ll.ravel(), starts).reshape(B, C)  # m_c, for exp
        e = np.exp(np.subtract(ll, _per_particle(top, counts), out=ll), out=ll)
        if g is not None:
            e *= g
        S = np.add.reduceat(e.ravel(), starts).reshape(B, C)
        w = np.divide(e, _per_particle(S, counts), out=e)

        # the class posterior: L(c) = S_c exp(m_c) / N_c (times N_c / N: the paper's form)
        logL = top + np.log(S) - np.log(counts)
        if self.speed == "estimate":
            v = belief.speed.reshape(B)
            gc = np.stack([k.speed_likelihood(v) for k in self.classes], -1)
            logL = logL + np.where(miss[:, None], 0.0, np.log(gc))
        if self.recursion == "paper":
            logL = logL + np.log(counts / N)
        lp = lp_prev + logL
        lp -= logsumexp(lp)[:, None]
        if some_missing:
            lp = np.where(miss[:, None], lp_prev, lp)
        p = np.exp(lp)

        # the innovation under the predicted weights p(c | Z^{k-1}) / N_c
        nu, Sr = _moments(r, _per_particle(np.exp(lp_prev) / counts, counts))
        # estimates: the mixture is the particles under the weights p(c^j) w^j
        mean, cov = _moments(X, _per_particle(p, counts) * w)
        class_mean = np.stack([np.add.reduceat((w * a).ravel(), starts).reshape(B, C)
                               for a in X], -1)

        # allocation with the floor, then resampling within classes
        rng = belief.rng
        rest = N - C * self.n_floor
        new_counts = self.n_floor + (rng.multinomial(rest, p) if rest else 0)
        idx = systematic(w * _per_particle(new_counts / N, counts), rng)
        parts = _resample_rows((*X, labels, modes), idx)
        if some_missing:
            keep = miss[:, None]
            parts = [np.where(keep, old, new) for old, new in zip((*X, labels, modes), parts,
                                                                  strict=True)]
            new_counts = np.where(keep, counts, new_counts)
        out = JTCBelief(
            *(a.reshape(batch + (N,)) for a in parts), new_counts.reshape(batch + (C,)),
            lp.reshape(batch + (C,)), rng, np.hypot(mean[:, 2], mean[:, 3]).reshape(batch),
            mean.reshape(batch + (4,)), register(cov.reshape(batch + (4, 4))),
            class_mean.reshape(batch + (C, 4)))
        nu = np.where(miss[:, None], np.nan, nu) if some_missing else nu
        return out, Innovation(nu.reshape(batch + (-1,)), (Sr + R).reshape(batch + R.shape))

    # -- estimates ---------------------------------------------------------------------------

    def estimate(self, belief: JTCBelief) -> Gaussian:
        """The overall estimate: the last update's, or (after a prediction) the particles'
        mean and covariance under the weights ``p(c^j) / N_c``."""
        if belief.mean is not None:
            return Gaussian._make((belief.mean, belief.cov))
        batch, N = belief.x.shape[:-1], belief.x.shape[-1]
        C = len(self.classes)
        B = math.prod(batch)
        counts = belief.counts.reshape(B, C)
        W = _per_particle(belief.class_prob.reshape(B, C) / counts, counts)
        m, P = _moments([a.reshape(B, N) for a in (belief.x, belief.y, belief.vx, belief.vy)],
                        W)
        return Gaussian._make((m.reshape(batch + (4,)), register(P.reshape(batch + (4, 4)))))

    def class_estimates(self, belief: JTCBelief) -> Array:
        """The class-conditional means ``x^c``, ``(..., C, 4)``: the last update's, or the
        particles' means per class after a prediction."""
        if belief.class_mean is not None:
            return belief.class_mean
        batch = belief.x.shape[:-1]
        C = len(self.classes)
        B = math.prod(batch)
        counts = belief.counts.reshape(B, C)
        starts = _segments(counts)
        sums = np.stack([np.add.reduceat(a.reshape(-1), starts).reshape(B, C)
                         for a in (belief.x, belief.y, belief.vx, belief.vy)], -1)
        return (sums / counts[..., None]).reshape(batch + (C, 4))


# --------------------------------------------------------------------------------------------
# The multi-filter baseline
# --------------------------------------------------------------------------------------------


class MultiFilterBelief(NamedTuple):
    """What :class:`MultiFilterJTC` carries: class c's particles, equally weighted, are
    ``x[..., c, :]``, ``y``, ``vx``, ``vy`` and ``modes``, each ``(..., C, N_c)``
    (``states`` stacks them, ``(..., C, N_c, 4)``); ``log_class_prob (..., C)``; ``rng``;
    ``speed (...,)``; the last update's ``mean``, ``cov``, ``class_mean (..., C, 4)`` and
    ``class_cov (..., C, 4, 4)`` (None after a prediction)."""

    x: Array
    y: Array
    vx: Array
    vy: Array
    modes: NDArray[np.int8]
    log_class_prob: Array
    rng: np.random.Generator
    speed: Array
    mean: Array | None = None
    cov: Array | None = None
    class_mean: Array | None = None
    class_cov: Array | None = None

    @property
    def states(self) -> Array:
        """The particles' states ``(..., C, N_c, 4)``."""
        return np.stack((self.x, self.y, self.vx, self.vy), -1)

    @property
    def class_prob(self) -> Array:
        """``p(c | Z^k)``, ``(..., C)``."""
        return np.exp(self.log_class_prob)


class MultiFilterJTC:
    """The multiple-model JTC baseline (Hosseini, Haeri and Khaloozadeh 2019, Fig. 1): one
    multiple-model particle filter per class, each with its class's modes and
    ``particles_per_class`` particles, resampled (systematic) at every step; the class posterior
    ``p(c | Z^k) = p(z_k, y_k | c, Z^{k-1}) p(c | Z^{k-1}) / sum_c' (...)`` from each filter's
    likelihood (the mean of its unnormalised weights ``p(z | x) g(v | c)``, as in
    :class:`JTC`), and the overall estimate the posterior-weighted mixture of the class
    filters' estimates. Options as :class:`JTC`'s (no floor and no recursion: each class
    always has its N_c particles, and the recursion is Bayes')."""

    name = "MultiFilterJTC"
    stochastic = True

    def __init__(self, classes: Sequence[TargetClass] = PAPER_CLASSES,
                 particles_per_class: int = 5000, sigma: float = 10.0,
                 diagonal: float | None = None, speed: str = "estimate",
                 acceleration: str = "velocity", class_prior: ArrayLike | None = None) -> None:
        where = "MultiFilterJTC"
        self.classes = _with_diagonal(_check_classes(classes, where), diagonal, where)
        self.particles_per_class = _check_int(particles_per_class, "particles_per_class",
                                              where)
        self.sigma = _check_sigma(sigma, where)
        self.diagonal = diagonal
        self.speed = _check_choice(speed, "speed", SPEEDS, where)
        self.acceleration = _check_choice(acceleration, "acceleration", ALONG, where)
        self.class_prior = _class_prior(class_prior, len(self.classes), where)
        self._cache: dict[float, list[_Tables]] = {}

    @property
    def class_names(self) -> tuple[str, ...]:
        return tuple(k.name for k in self.classes)

    def _tables(self, dt: float) -> list[_Tables]:
        tabs = self._cache.get(dt)
        if tabs is None:
            if len(self._cache) > 64:
                self._cache.clear()
            tabs = self._cache[dt] = [_tables((k,), dt) for k in self.classes]
        return tabs

    def __repr__(self) -> str:
        return (f"MultiFilterJTC(classes={self.class_names}, particles_per_class="
                f"{self.particles_per_class}, sigma={self.sigma}, diagonal={self.diagonal}, "
                f"speed={self.speed!r}, acceleration={self.acceleration!r})")

    def init(self, prior: Gaussian, rng: np.random.Generator | None = None
             ) -> MultiFilterBelief:
        """N_c particles per class and batch row drawn from the prior, modes uniform."""
        rng = np.random.default_rng() if rng is None else rng
        C, Nc = len(self.classes), self.particles_per_class
        batch, parts = _draw_prior(prior, (C, Nc), rng, "MultiFilterJTC.init")
        modes = rng.integers(0, self.classes[0].n_modes, size=batch + (C, Nc), dtype=np.int8)
        mean = np.asarray(prior.mean, dtype=float)
        return MultiFilterBelief(
            *parts, modes, np.broadcast_to(np.log(self.class_prior), batch + (C,)).copy(), rng,
            np.hypot(mean[..., 2], mean[..., 3]))

    def predict(self, belief: MultiFilterBelief, motion: MotionModel | None = None, dt: float = 1.0
                ) -> MultiFilterBelief:
        """Each class filter's prediction: modes from its chain, states by its modes."""
        check_dt(dt, "MultiFilterJTC.predict")
        dt = float(dt)
        rng = belief.rng
        comps = (belief.x, belief.y, belief.vx, belief.vy)
        out = [np.empty_like(a) for a in comps]
        mp = np.empty_like(belief.modes)
        for c, tab in enumerate(self._tables(dt)):
            mode = belief.modes[..., c, :]
            m = next_modes(mode, tab.cdf, rng.random(mode.shape, dtype=np.float32))
            w = standard_normals(rng, (2,) + mode.shape)
            w *= self.sigma
            X = _propagate(tuple(a[..., c, :] for a in comps), m, tab, w[0], w[1], dt,
                           self.acceleration)
            for o, a in zip(out, X, strict=True):
                o[..., c, :] = a
            mp[..., c, :] = m
        return belief._replace(x=out[0], y=out[1], vx=out[2], vy=out[3], modes=mp, mean=None,
                               cov=None, class_mean=None, class_cov=None)

    def update(self, belief: MultiFilterBelief, z: ArrayLike, sensor: SensorModel
               ) -> tuple[MultiFilterBelief, Innovation]:
        """Each class filter's update and resampling; the class posterior from their
        likelihoods; the mixture estimate. A row whose z is missing keeps its prediction."""
        batch, (C, Nc) = belief.x.shape[:-2], belief.x.shape[-2:]
        z = check_measurement(z, sensor.dim_z, "MultiFilterJTC.update", batch)
        B = math.prod(batch)
        comps = [a.reshape(B, C, Nc) for a in (belief.x, belief.y, belief.vx, belief.vy,
                                                belief.modes)]
        zf = np.broadcast_to(z, batch + (sensor.dim_z,)).reshape(B, -1)
        miss = np.isnan(zf).any(-1)
        some_missing = bool(miss.any())
        if some_missing:
            zf = np.where(miss[:, None], 0.0, zf)
        lp_prev = belief.log_class_prob.reshape(B, C)
        R = np.asarray(sensor.noise, dtype=float)
        m = R.shape[-1]
        rng = belief.rng
        v_prev = belief.speed.reshape(B)
        logL = np.empty((B, C))
        means, covs = np.empty((B, C, 4)), np.empty((B, C, 4, 4))
        nus, Ss = np.empty((B, C, m)), np.empty((B, C, m, m))
        new = [np.empty_like(a) for a in comps]
        for c, k in enumerate(self.classes):
            X = tuple(np.ascontiguousarray(a[:, c]) for a in comps[:4])
            r = _residuals(X, zf, sensor)
            ll = _log_likelihood(r, R)
            if some_missing:
                ll[miss] = 0.0
            top = ll.max(-1)
            e = np.exp(ll - top[:, None])
            if self.speed == "particle":
                g = k.speed_likelihood(np.sqrt(X[2] * X[2] + X[3] * X[3]))
                if some_missing:
                    g[miss] = 1.0
                e *= g
            S = e.sum(-1)
            w = e / S[:, None]
            logL[:, c] = top + np.log(S) - math.log(Nc)
            if self.speed == "estimate":
                logL[:, c] += np.where(miss, 0.0, np.log(k.speed_likelihood(v_prev)))
            means[:, c], covs[:, c] = _moments(X, w)
            nus[:, c], Ss[:, c] = _moments(r, np.full((B, Nc), 1.0 / Nc))
            idx = systematic(w, rng)
            for o, a in zip(new, _resample_rows((*X, comps[4][:, c]), idx), strict=True):
                o[:, c] = a
        lp = lp_prev + logL
        lp -= logsumexp(lp)[:, None]
        if some_missing:
            lp = np.where(miss[:, None], lp_prev, lp)
        mean, cov = _mixture(means, covs, np.exp(lp))
        # the innovation: the mixture of the class filters' predictions, p(c | Z^{k-1})
        nu, S = _mixture(nus, Ss, np.exp(lp_prev))
        if some_missing:
            keep = miss[:, None, None]
            new = [np.where(keep, old, a) for old, a in zip(comps, new, strict=True)]
            nu = np.where(miss[:, None], np.nan, nu)
        out = MultiFilterBelief(
            *(a.reshape(batch + (C, Nc)) for a in new), lp.reshape(batch + (C,)), rng,
            np.hypot(mean[:, 2], mean[:, 3]).reshape(batch), mean.reshape(batch + (4,)),
            register(cov.reshape(batch + (4, 4))), means.reshape(batch + (C, 4)),
            covs.reshape(batch + (C, 4, 4)))
        return out, Innovation(nu.reshape(batch + (m,)), (S + R).reshape(batch + (m, m)))

    def estimate(self, belief: MultiFilterBelief) -> Gaussian:
        """The posterior-weighted mixture of the class filters' estimates (the last update's,
        or the particles' after a prediction)."""
        if belief.mean is not None:
            return Gaussian._make((belief.mean, belief.cov))
        batch, (C, Nc) = belief.x.shape[:-2], belief.x.shape[-2:]
        B = math.prod(batch)
        parts = [a.reshape(B * C, Nc) for a in (belief.x, belief.y, belief.vx, belief.vy)]
        mc, Pc = _moments(parts, np.full((B * C, Nc), 1.0 / Nc))
        mean, cov = _mixture(mc.reshape(B, C, 4), Pc.reshape(B, C, 4, 4),
                             belief.class_prob.reshape(B, C))
        return Gaussian._make((mean.reshape(batch + (4,)),
                               register(cov.reshape(batch + (4, 4)))))

    def class_estimates(self, belief: MultiFilterBelief) -> Array:
        """The class filters' means ``(..., C, 4)``."""
        if belief.class_mean is not None:
            return belief.class_mean
        return np.stack([a.mean(-1) for a in (belief.x, belief.y, belief.vx, belief.vy)], -1)
