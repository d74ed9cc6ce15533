r"""The bootstrap particle filter (Gordon, Salmond and Smith 1993), batched.

The belief is :class:`~trackkit.belief.Particles`: states ``x_i (..., N, n)`` and normalised
log-weights ``log w_i (..., N)`` per batch row (run or track), plus the generator the filter
draws from. With the motion model as the proposal, one step is

* predict, the noise drawn through a PSD square root of Q (so a Q with noiseless components
  is fine); the weights are unchanged:

  .. math::

      \mathbf{x}_i \leftarrow f(\mathbf{x}_i, \Delta t) + \mathbf{v}_i, \qquad
      \mathbf{v}_i \sim \mathcal{N}\bigl(0, Q(\mathbf{x}_i, \Delta t)\bigr)

* update, with :math:`\mathbf{r}_i = \mathbf{z} - h(\mathbf{x}_i)` (the sensor's own
  ``residual``, so angle components are wrapped), then normalised:

  .. math::

      \log w_i \leftarrow \log w_i + \log \mathcal{N}(\mathbf{r}_i; 0, R), \qquad
      \log w_i \leftarrow \log w_i - L, \quad L = \log \sum_j \exp(\log w_j)

* resample the rows whose effective sample size

  .. math::

      \mathrm{ESS} = \frac{1}{\sum_i w_i^2}

  is below ``ess_threshold * N`` (only those rows), with uniform weights afterwards, then
  optionally regularise (a Gaussian-kernel jitter, Musso et al., with or without Liu and
  West's shrinkage towards the mean) or roughen them (see :mod:`trackkit.filters.resample`).

Weights stay in log space throughout, so a measurement that every particle finds very
unlikely still gives finite, normalised weights. If no particle can explain a measurement at
all (every likelihood exactly zero: the residual or ``h`` is not finite for every particle of
that row), the update is rejected for that row: its particles and weights stay as predicted,
``belief.lost`` counts it, and the innovation is still reported (so its NIS shows the
mismatch). A particle whose own likelihood is not finite gets weight zero.

The innovation returned for NIS, gating and the Monte Carlo metrics is moment-matched from
the particles' residuals ``r_i = residual(z, h(x_i))`` and the predicted weights:

.. math::

    \bar{\mathbf{r}} = \sum_i w_i \mathbf{r}_i \;(= \mathbf{z} - \bar{\mathbf{z}}), \qquad
    S = \sum_i w_i (\mathbf{r}_i - \bar{\mathbf{r}})(\mathbf{r}_i - \bar{\mathbf{r}})^\top + R

On angle components the residuals are
wrapped and averaged about the heaviest particle's residual, so a cloud of bearings that
straddles +-pi, or lies across the cut from z, has its mean on the circle.
``estimate`` gives the weighted mean and covariance of the particles, circular on the
components listed in ``angles``. Rows whose ``z`` holds a nan keep the prediction (weights
unchanged, no resampling) and get a nan residual, as the Gaussian filters do.

Sensors and noise covariances may carry batch axes (a moving observer per run, one R per run):
their parameters broadcast against the batch axes of the particles, not the particle axis.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence

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
    missing_rows,
    output,
    produced,
    register,
)
from trackkit.filters.particle_fast import standard_normals
from trackkit.linalg import cholesky, psd_factor
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = ["PF", "sample_gaussian", "propagate", "log_likelihood", "predicted_measurement",
           "resample_rows"]

Array = NDArray[np.float64]
_F64 = np.dtype(np.float64)
_LOG_2PI = math.log(2.0 * math.pi)

# factors of read-only noise matrices (a model's cached Q, a sensor's R), by identity
_factors: dict[tuple[int, str], tuple[weakref.ref, Array]] = {}


def _cached(M: Array, kind: str, build) -> Array:
    """``build(M)``, remembered for a read-only M (the models' cached Q and R never change)."""
    if M.flags.writeable:
        return build(M)
    key = (id(M), kind)
    hit = _factors.get(key)
    if hit is not None and hit[0]() is M:
        return hit[1]
    value = build(M)
    if len(_factors) > 1024:
        _factors.clear()
    _factors[key] = (weakref.ref(M), value)
    return value


# log-weight arrays known to be uniform (made by init or by resampling every row), by
# identity: their weights need no exp
_uniform: dict[int, weakref.ref] = {}


def _mark_uniform(lw: Array) -> Array:
    if len(_uniform) > 4096:
        _uniform.clear()
    _uniform[id(lw)] = weakref.ref(lw)
    return lw


def _weights(lw: Array) -> Array | None:
    """``exp(log_weights)``, or None for an array known to be uniform (weights 1/N, which
    :func:`~trackkit.filters.resample.weighted_mean_cov` takes without multiplying)."""
    ref = _uniform.get(id(lw))
    if ref is not None and ref() is lw:
        return None
    return np.exp(lw)


def _per_row(M: Array, batch: tuple[int, ...]) -> Array:
    """A matrix-valued model output ``(..., k, k)`` aligned with particles ``batch + (N,)``:
    one matrix per batch row (``ndim - 2 <= len(batch)``) gets a particle axis; one per
    particle (``batch + (N,)``) is left as it is."""
    if 0 < M.ndim - 2 <= len(batch):
        return M[..., None, :, :]
    return M


def _angles_of(angular) -> tuple[int, ...]:
    return tuple(i for i, a in enumerate(angular or ()) if a)


# --------------------------------------------------------------------------------------------
# Kernels (pure functions over arrays; the PF class is a thin handle on them)
# --------------------------------------------------------------------------------------------


def sample_gaussian(mean: Array, cov: Array, n_particles: int,
                    rng: np.random.Generator) -> Array:
    """``N`` draws per batch row from ``N(mean, cov)``: ``x_i = m + L e_i``, ``L L^T = cov``
    (a PSD square root, so a singular prior is fine), shape ``batch + (N, n)``."""
    m = np.asarray(mean, dtype=float)
    P = np.asarray(cov, dtype=float)
    batch = np.broadcast_shapes(m.shape[:-1], P.shape[:-2])
    L = psd_factor(P, "prior covariance")
    e = standard_normals(rng, batch + (n_particles, m.shape[-1]))
    return m[..., None, :] + (e @ L.T if L.ndim == 2 else e @ L.mT)


def propagate(states: Array, motion: MotionModel, dt: ArrayLike, rng: np.random.Generator,
              angles: Sequence[int] = ()) -> Array:
    """``x_i <- f(x_i, dt) + L e_i`` with ``L L^T = Q(x_i, dt)``, ``e_i ~ N(0, I)``.

    ``states (..., N, n)``; ``dt`` a float or one step per batch row (``(...)``). Angle
    components (``angles``) are wrapped afterwards.
    """
    X = states
    batch = X.shape[:-2]
    d = dt
    if not isinstance(dt, float | int) and np.ndim(dt) > 0:
        d = np.asarray(dt, dtype=float)
        try:
            np.broadcast_shapes(d.shape, batch)
        except ValueError:
            raise ValueError(f"PF.predict: dt has shape {d.shape}; expected a float or one "
                             f"step per batch row, shape {batch}") from None
        d = d[..., None]  # the particles of a row share its step
    x = np.asarray(motion.f(X, d), dtype=float)
    if not x.flags.writeable or np.may_share_memory(x, X):
        x = x.copy()  # the noise is added in place: never into the caller's states
    Q = np.asarray(motion.noise(X, d), dtype=float)
    e = standard_normals(rng, X.shape)
    if Q.ndim == 2:
        # L^T stored contiguous: numpy's GEMM then takes it as it is (twice as fast)
        LT = _cached(Q, "sqrt-T", lambda M: np.ascontiguousarray(psd_factor(M, "process "
                                                                            "noise Q").T))
        x += e @ LT
    else:
        L = psd_factor(_per_row(Q, batch), "process noise Q")
        if L.shape[-3] == 1:  # one factor per batch row: a batched GEMM
            x += e @ L[..., 0, :, :].mT
        else:
            x += np.einsum("...ij,...j->...i", L, e)
    if angles:
        a = list(angles)
        x[..., a] = wrap(x[..., a])
    return x


def _measure(sensor: SensorModel, X: Array) -> Array:
    """``h`` of every particle, ``(..., N, m)``. A sensor whose pose carries batch axes must
    see the particle axis in front of them (its parameters broadcast against the trailing
    axes), so a one-particle probe decides how to call it."""
    batch = X.shape[:-2]
    if math.prod(batch) > 1:
        try:
            probe = np.shape(sensor.h(X[..., :1, :]))
            aligned = probe[:-1] == batch + (1,)
        except ValueError:
            aligned = False
        if not aligned:
            return np.moveaxis(np.asarray(sensor.h(np.moveaxis(X, -2, 0)), dtype=float), 0, -2)
    return np.asarray(sensor.h(X), dtype=float)


def _noise_R(sensor: SensorModel, batch: tuple[int, ...]) -> Array:
    R = sensor.noise
    return R if type(R) is np.ndarray and R.dtype == _F64 else np.asarray(R, dtype=float)


def _inverse_factor(R: Array) -> tuple[Array, Array]:
    """``(L^{-1}, log det R / 2)`` with ``L L^T = R`` (lower triangular)."""
    L = cholesky(R, "sensor noise R")
    half_logdet = np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)
    return np.linalg.inv(L), half_logdet


def _quadratic(r: Array, R: Array, batch: tuple[int, ...]) -> tuple[Array, Array]:
    """``(r^T R^{-1} r, log det R / 2)`` per particle: ``|y|^2`` with ``y = L^{-1} r``,
    ``L L^T = R``, one measurement component at a time (``r[..., j]`` is a contiguous run
    over the particles when r is in column layout, see :func:`_columns`)."""
    if R.ndim == 2:
        Linv, half_logdet = _cached(R, "inv-chol", _inverse_factor)
        coef = Linv.tolist()
    else:
        Linv, half_logdet = _inverse_factor(R)
        if R.ndim - 2 <= len(batch):  # one R per batch row: broadcast over the particles
            Linv, half_logdet = Linv[..., None, :, :], half_logdet[..., None]
        coef = [[Linv[..., i, j] for j in range(R.shape[-1])] for i in range(R.shape[-1])]
    m = r.shape[-1]
    cols = [r[..., j] for j in range(m)]
    q = None
    for i in range(m):
        y = cols[0] * coef[i][0]
        for j in range(1, i + 1):  # L^{-1} is lower triangular
            y += cols[j] * coef[i][j]
        np.square(y, out=y)
        if q is None:
            q = y
        else:
            q += y
    return q, half_logdet


def _columns(A: Array) -> Array:
    """``A (..., N, m)`` with the same values, stored components-first (a view of a
    ``(..., m, N)`` array): numpy then runs every elementwise pass along the particles
    instead of over a short last axis, several times faster for m <= 4."""
    if A.ndim < 2 or A.mT.flags.c_contiguous:
        return A
    C = np.empty(A.shape[:-2] + (A.shape[-1], A.shape[-2]))
    np.copyto(C, A.mT)
    return C.mT


def log_likelihood(states: Array, z: Array, sensor: SensorModel, Z: Array | None = None) -> Array:
    """``log N(residual(z, h(x_i)); 0, R)`` for every particle, ``(..., N)``.

    ``z`` is ``(..., m)`` (batch axes broadcasting against the particles'); ``Z`` the
    particles' predicted measurements if already computed. A row of z holding a nan (a
    missing measurement) gets 0 for every particle (no information); a particle whose
    residual is not finite gets ``-inf`` (weight zero).
    """
    if Z is None:
        Z = _measure(sensor, states)
    z = np.asarray(z, dtype=float)
    r = sensor.residual(z[..., None, :], _columns(Z))
    return _log_likelihood(r, sensor, states.shape[:-2], missing_rows(z))


def _log_likelihood(r: Array, sensor: SensorModel, batch: tuple[int, ...],
                    miss: NDArray[np.bool_] | None) -> Array:
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is a likelihood of 0
        ll, half_logdet = _quadratic(r, _noise_R(sensor, batch), batch)
    ll *= -0.5
    ll -= half_logdet + 0.5 * r.shape[-1] * _LOG_2PI
    if not math.isfinite(np.add.reduce(ll, axis=None)):
        ll = np.where(np.isnan(ll), -np.inf, ll)
        if miss is not None:
            ll = np.where(miss[..., None], 0.0, ll)
    return ll


def predicted_measurement(r: Array, weights: Array | None,
                          sensor: SensorModel) -> tuple[Array, Array]:
    """``(rbar, S)`` from the particles' residuals ``r_i = residual(z, h(x_i))``
    ``(..., N, m)`` and their weights (None: equal): ``rbar = z - zbar = sum_i w_i r_i`` and
    ``S = sum_i w_i (r_i - rbar)(r_i - rbar)^T + R``.

    On angle components the residuals are wrapped deviations, and their mean is taken about
    the highest-weighted particle's residual (``rbar = c + sum_i w_i wrap(r_i - c)``): the
    mean of the cloud on the circle, whatever side of the cut z and the cloud lie on.
    """
    ang = _angles_of(sensor.angular)
    with np.errstate(invalid="ignore", over="ignore"):  # a row whose h is not finite: nan
        return _moments(r, weights, sensor, ang)


def _moments(r: Array, weights: Array | None, sensor: SensorModel,
             ang: tuple[int, ...]) -> tuple[Array, Array]:
    if ang:
        if weights is None:  # equal weights: any particle is the heaviest
            c = r[..., :1, :]
        else:
            best = np.argmax(weights, axis=-1)[..., None, None]
            c = np.take_along_axis(r, best, axis=-2)  # (..., 1, m)
        d = r - c
        a = list(ang)
        da = d[..., a]
        if not (-3.0 < da.min() and da.max() < 3.0):  # wrap is the identity inside (-3, 3)
            d[..., a] = wrap(da)
        rbar, P = rs.weighted_mean_cov(d, weights)
        rbar += c[..., 0, :]
        rbar[..., a] = wrap(rbar[..., a])
    else:
        rbar, P = rs.weighted_mean_cov(r, weights)
    return rbar, P + _noise_R(sensor, r.shape[:-2])


def resample_rows(states: Array, log_weights: Array, rng: np.random.Generator,
                  ess_threshold: float = 0.5, resampler: str = "systematic",
                  regularise: bool = False, roughening: float = 0.0,
                  angles: Sequence[int] = (), keep: NDArray[np.bool_] | None = None,
                  weights: Array | None = None,
                  shrink: bool = False) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Resample the rows whose ``ESS < ess_threshold * N`` (except rows marked in ``keep``);
    returns ``(states, log_weights, resampled)`` with ``resampled (...)`` the rows that were.
    Resampled rows get uniform weights and, with ``regularise``, the Gaussian-kernel jitter
    scaled by their weighted covariance before resampling (with ``shrink``, after a pull
    towards their weighted mean that keeps that covariance), or with ``roughening = K > 0``
    the Gordon-Salmond-Smith jitter. ``weights``: ``exp(log_weights)`` if already computed. The
    inputs are not modified."""
    N, n = states.shape[-2:]
    w = np.exp(log_weights) if weights is None else weights
    mask = 1.0 / np.square(w).sum(-1) < ess_threshold * N  # ESS = 1 / sum w^2
    if keep is not None:
        mask &= ~keep
    if not mask.any():
        return states, log_weights, mask
    X2 = states.reshape(-1, N, n)
    lw2 = log_weights.reshape(-1, N)
    rows = np.flatnonzero(mask.ravel())
    w = w.reshape(-1, N)
    if rows.size < w.shape[0]:
        w = w[rows]
    m, S = rs.weighted_mean_cov(X2[rows], w, angles) if regularise else (None, None)
    a = rs.KERNELS[resampler](w, rng, N)
    flat_rows = X2.reshape(-1, n)
    Xr = np.take(flat_rows, (a + (rows * N)[:, None]).ravel(), axis=0).reshape(rows.size, N, n)
    if regularise:
        Xr = rs.regularise(Xr, np.full((rows.size, N), 1.0 / N), rng, cov=S, angles=angles,
                           shrink=shrink, mean=m, cov_is_sample=True)
    elif roughening > 0:
        Xr = rs.roughen(Xr, rng, roughening, angles)
    flat = -math.log(N)
    if rows.size == X2.shape[0]:
        return (Xr.reshape(states.shape), _mark_uniform(np.full(log_weights.shape, flat)),
                mask)
    Xn, lwn = X2.copy(), lw2.copy()
    Xn[rows] = Xr
    lwn[rows] = flat
    return Xn.reshape(states.shape), lwn.reshape(log_weights.shape), mask


# --------------------------------------------------------------------------------------------
# Input checks
# --------------------------------------------------------------------------------------------


def _check_particles(b, n: int | None, where: str) -> tuple[Array, Array]:
    """``(states, log_weights)`` after the per-step checks (shapes, finite, no nan weight)."""
    if not isinstance(b, Particles):
        if isinstance(b, Gaussian):
            raise TypeError(f"{where} is a Gaussian; the particle filter carries Particles: "
                            "build them with PF.init(prior, rng)")
        raise TypeError(f"{where} is a {type(b).__name__}; expected trackkit.Particles")
    X, lw = b.states, b.log_weights
    if type(X) is not np.ndarray or X.dtype is not _F64:
        X = np.asarray(X, dtype=float)
    if type(lw) is not np.ndarray or lw.dtype is not _F64:
        lw = np.asarray(lw, dtype=float)
    if X.ndim < 2:
        raise ValueError(f"{where}.states has shape {X.shape}; expected (..., N, n)")
    if n is not None and X.shape[-1] != n:
        raise ValueError(f"{where}.states has shape {X.shape}; the model's state has {n} "
                         f"components, so expected (..., N, {n})")
    if lw.shape != X.shape[:-1]:
        raise ValueError(f"{where}.log_weights has shape {lw.shape}; expected {X.shape[:-1]} "
                         "(one per particle)")
    if not produced(X) and not math.isfinite(np.add.reduce(X, axis=None)):
        bad = ~np.isfinite(X)
        if bad.any():
            raise ValueError(f"{where}.states has {int(bad.sum())} non-finite entries; "
                             "expected finite values")
    s = np.add.reduce(lw, axis=None)
    if math.isnan(s) or s == math.inf:
        if np.isnan(lw).any() or (lw == np.inf).any():
            raise ValueError(f"{where}.log_weights has nan or +inf entries; expected "
                             "normalised log-weights (finite or -inf)")
    return X, lw


def _check_angles(angles, where: str) -> tuple[int, ...]:
    try:
        out = tuple(angles)
    except TypeError:
        raise ValueError(f"{where}: angles = {angles!r}; expected a tuple of state "
                         "component indices") from None
    for a in out:
        if isinstance(a, bool) or not isinstance(a, int | np.integer) or a < 0:
            raise ValueError(f"{where}: angles = {angles!r}; expected indices >= 0 of the "
                             "angle components of the state")
    return tuple(sorted({int(a) for a in out}))


# --------------------------------------------------------------------------------------------
# The filter
# --------------------------------------------------------------------------------------------


class PF(Filter):
    """Bootstrap particle filter with ``n_particles`` per batch row.

    ``resampler``: "systematic" (default), "stratified", "residual" or "multinomial";
    ``ess_threshold``: resample a row when its ESS is below ``ess_threshold * N`` (0 never,
    1 whenever the weights are not uniform); ``regularise``: Gaussian-kernel jitter after
    resampling (the regularised PF); ``shrink``: with ``regularise``, pull the resampled
    particles towards their mean by ``sqrt(1 - h^2)`` first (Liu and West), so the jitter
    keeps the cloud's covariance instead of widening it by ``1 + h^2`` at every resampling;
    ``roughening``: Gordon-Salmond-Smith's K (0 off; at most one of it and regularise);
    ``angles``: state components that are angles (wrapped after every move, averaged
    circularly by ``estimate``).

    ``init(prior, rng)`` draws the particles from a Gaussian prior (or takes a
    :class:`~trackkit.belief.Particles`); every later draw comes from the generator carried
    in the belief, so a run is reproducible from its generator's seed.
    """

    name = "PF"
    stochastic = True

    def __init__(self, n_particles: int = 1000, resampler: str = "systematic",
                 ess_threshold: float = 0.5, regularise: bool = False,
                 roughening: float = 0.0, angles: tuple[int, ...] = (),
                 shrink: bool = False) -> None:
        if (isinstance(n_particles, bool) or not isinstance(n_particles, int | np.integer)
                or n_particles < 1):
            raise ValueError(f"PF n_particles = {n_particles!r}; expected an integer >= 1")
        if resampler not in rs.RESAMPLERS:
            raise ValueError(f"PF resampler = {resampler!r}; expected one of "
                             f"{', '.join(map(repr, rs.RESAMPLERS))}")
        if not (isinstance(ess_threshold, int | float) and 0.0 <= ess_threshold <= 1.0):
            raise ValueError(f"PF ess_threshold = {ess_threshold!r}; expected a number in "
                             "[0, 1] (a fraction of the number of particles)")
        if not isinstance(regularise, bool | np.bool_):
            raise ValueError(f"PF regularise = {regularise!r}; expected True or False")
        if not (isinstance(roughening, int | float) and math.isfinite(roughening)
                and roughening >= 0):
            raise ValueError(f"PF roughening = {roughening!r}; expected a number >= 0 "
                             "(Gordon's K, 0 for none)")
        if not isinstance(shrink, bool | np.bool_):
            raise ValueError(f"PF shrink = {shrink!r}; expected True or False")
        if shrink and not regularise:
            raise ValueError("PF shrink = True without regularise; expected regularise = True "
                             "(shrinkage is part of the regularised PF's kernel move)")
        if shrink and rs.optimal_bandwidth(int(n_particles), 1) >= 1:
            raise ValueError(f"PF shrink = True with n_particles = {n_particles!r}; expected "
                             "at least 2 particles (the kernel's bandwidth must be below 1)")
        if regularise and roughening > 0:
            raise ValueError(f"PF regularise = True and roughening = {roughening!r}; expected "
                             "at most one of the two jitters after resampling")
        self.n_particles = int(n_particles)
        self.resampler = resampler
        self.ess_threshold = float(ess_threshold)
        self.regularise = bool(regularise)
        self.shrink = bool(shrink)
        self.roughening = float(roughening)
        self.angles = _check_angles(angles, "PF")

    def _angles_for(self, n: int, where: str) -> tuple[int, ...]:
        if self.angles and self.angles[-1] >= n:
            raise ValueError(f"{where}: PF angles = {self.angles}; the state has {n} "
                             "components")
        return self.angles

    def init(self, prior: Gaussian | Particles,
             rng: np.random.Generator | None = None) -> Particles:
        """Particles from a Gaussian prior (``n_particles`` draws per batch row, equal
        weights), or a given :class:`Particles` checked (with ``rng``, if given, as its
        generator). ``rng`` None: a fresh ``np.random.default_rng()``."""
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"PF.init: rng is a {type(rng).__name__}; expected a "
                             "numpy.random.Generator or None")
        if isinstance(prior, Particles):
            X, lw = _check_particles(prior, None, "PF.init prior")
            self._angles_for(X.shape[-1], "PF.init")
            gen = rng if rng is not None else prior.rng
            gen = np.random.default_rng() if gen is None else gen
            return Particles._make((X, lw, gen, prior.lost))
        m, P = check_belief(prior, None, "PF.init prior")
        ang = self._angles_for(m.shape[-1], "PF.init")
        gen = np.random.default_rng() if rng is None else rng
        X = sample_gaussian(m, P, self.n_particles, gen)
        if ang:
            X[..., list(ang)] = wrap(X[..., list(ang)])
        lw = _mark_uniform(np.full(X.shape[:-1], -math.log(self.n_particles)))
        return Particles._make((X, lw, gen, None))

    def predict(self, belief: Particles, motion: MotionModel, dt: ArrayLike) -> Particles:
        """``x_i <- f(x_i, dt) + v_i``, ``v_i ~ N(0, Q(x_i, dt))``; weights unchanged."""
        X, lw = _check_particles(belief, getattr(motion, "dim_x", None), "PF.predict belief")
        check_dt(dt, "PF.predict")
        gen = belief.rng if belief.rng is not None else np.random.default_rng()
        Xp = propagate(X, motion, dt, gen, self._angles_for(X.shape[-1], "PF.predict"))
        return Particles._make((register(Xp), lw, gen, belief.lost))

    def update(self, belief: Particles, z: ArrayLike,
               sensor: SensorModel) -> tuple[Particles, Innovation]:
        """``log w_i += log N(residual(z, h(x_i)); 0, R)``, normalise, resample rows whose
        ESS is below the threshold. Returns the posterior and the moment-matched
        innovation."""
        X, lw = _check_particles(belief, None, "PF.update belief")
        batch = X.shape[:-2]
        z = check_measurement(z, sensor.dim_z, "PF.update", batch)
        gen = belief.rng if belief.rng is not None else np.random.default_rng()
        Z = _measure(sensor, X)
        if Z.shape[-1] != sensor.dim_z:
            raise ValueError(f"PF.update: the sensor's h gives shape {Z.shape}; expected "
                             f"(..., N, {sensor.dim_z})")
        miss = missing_rows(z)
        if miss is not None:  # a reference z there (any particle's h) keeps S finite
            z = np.where(miss[..., None], Z[..., 0, :], z)
        r = sensor.residual(z[..., None, :], _columns(Z))
        w = _weights(lw)
        rbar, S = predicted_measurement(r, w, sensor)
        if miss is not None:
            rbar = np.where(miss[..., None], np.nan, rbar)
        a = _log_likelihood(r, sensor, batch, miss)
        a += lw
        # normalise: log w' = a - L, L = logsumexp(a); w' = exp(a - top) / sum (one exp)
        top = a.max(-1, keepdims=True)
        dead = ~np.isfinite(top[..., 0])  # every likelihood zero (top = -inf)
        if dead.any():
            top[dead] = 0.0
        v = np.exp(a - top)
        total = v.sum(-1, keepdims=True)
        a -= top
        with np.errstate(divide="ignore", invalid="ignore"):  # dead rows: replaced below
            v /= total
            a -= np.log(total)
        lost = belief.lost
        if dead.any():  # no particle explains z: keep the prediction for those rows
            lost = (np.zeros(batch, dtype=np.int64) if lost is None else lost) + dead
            keep = dead if miss is None else dead | miss
        else:
            keep = miss
        if keep is not None:  # rows without an update keep their weights exactly
            a = np.where(keep[..., None], lw, a)
            v = np.where(keep[..., None], 1.0 / X.shape[-2] if w is None else w, v)
        Xn, lwn, _ = resample_rows(X, a, gen, self.ess_threshold, self.resampler,
                                   self.regularise, self.roughening,
                                   self._angles_for(X.shape[-1], "PF.update"), keep, v,
                                   self.shrink)
        return Particles._make((register(Xn), lwn, gen, lost)), Innovation(rbar, S)

    def estimate(self, belief: Particles) -> Gaussian:
        """Weighted mean and covariance of the particles (circular for ``angles``)."""
        X, lw = _check_particles(belief, None, "PF.estimate belief")
        m, P = rs.weighted_mean_cov(X, _weights(lw), self._angles_for(X.shape[-1],
                                                                        "PF.estimate"))
        return output(m, P, symmetric=True)
