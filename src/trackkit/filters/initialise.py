"""GA-based track initialisation for Doppler-bearing tracking (Hashemi and Alfi 2019, section 4-2).

The paper's Fig. 2: a genetic algorithm searches the initial target position; each candidate
initialises an auxiliary Kalman filter, the filter's residuals over the first measurements
are the candidate's cost, and the best candidate initialises the main filter.

Here, for run r and candidate position p, the auxiliary prior is ``N([p, v0, f0], P0)`` at
the prior time (one step before the first measurement: the convention of ``run_filter`` and
the Monte Carlo engine), with v0 a velocity guess (default 0) and f0 a tone guess (default
the run's first measured frequency). An EKF runs over the first K measurements (predict by
dt, update) and the cost is

- ``"nis"`` (default): ``J(p) = sum_k r_k^T S_k^{-1} r_k``, the paper's residual, normalised;
- ``"nll"``: ``J(p) = sum_k r_k^T S_k^{-1} r_k + log det S_k``, twice the negative log
  likelihood of the K measurements (prediction-error decomposition).

Missing measurements (nan) add nothing. All candidates of all runs are filtered together as
one batch of shape (runs, population) per generation.

**Choices the paper leaves open (documented defaults):**

- *K, the number of measurements.* One measurement cannot fix range, and with the velocity
  and tone unknown a few tens cannot either: for Hashemi and Alfi's scenario 1 (2 deg, 0.3 Hz, 1 s)
  the Cramer-Rao bound on the initial position along the line of sight, from K measurements
  with no prior on velocity and tone, is about 243 km at K = 20, 18 km at 100, 2.5 km at
  300, 420 m at 600 and 160 m at 800 (scenario 2: 300 m at 600). The paper's "< 1000 m" then
  needs K of about 600 to 800 (a batch initialiser over the first 10 to 13 minutes). K is the
  length of the measurements passed in; ``block`` (e.g. 25) averages blocks of measurements
  first (``compress``) so that long windows stay cheap. Measured (GA 50 x 200, block 25,
  100 runs): scenario 1 with K = 800 gives a median error of 154 m, 95th percentile 382 m,
  max 477 m; with K = 600, 94% of runs within 1000 m; scenario 2 with K = 800, max 567 m.
  With K = 20 no run is within 1000 m (the NIS then also favours short ranges, where the
  predicted bearing variance is largest).
- *P0 of the auxiliary filter* (``dbt_prior_cov()``): 200 m in position, 10 m/s in velocity,
  5 Hz in the tone. The position spread is small against the km-scale range ambiguity so
  that J(p) scores the candidate p itself (with 1000 m the filter moves away from p and
  J flattens); velocity and tone spreads cover ship speeds and the Doppler shift
  ``f0 v / c`` (5 Hz at 15 kn, 500 Hz).
- *Search bounds* (the paper gives none): the square of half-width ``max_range`` = 20 km
  around the first observer position, a generous passive-sonar detection range for a tonal
  (the scenarios start at 8.5 km). A wider box costs a few generations, not accuracy; the
  global optimum lies on the narrow valley along the bearing line, which the GA finds within
  about 25 generations.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.filters.kalman import EKF
from trackkit.models.protocols import MotionModel
from trackkit.optimize.base import Optimizer, OptimizeResult
from trackkit.optimize.ga import GA

__all__ = ["ga_initial_position", "ga_prior", "dbt_prior_cov", "aux_cost", "compress"]

Array = NDArray[np.float64]

_COSTS = ("nis", "nll")


def dbt_prior_cov(sigma_pos: float = 200.0, sigma_vel: float = 10.0,
                  sigma_f0: float = 5.0) -> Array:
    """``diag(sp^2, sp^2, sv^2, sv^2, sf^2)`` for the DBT state [x, y, vx, vy, f0]."""
    return np.diag([sigma_pos**2, sigma_pos**2, sigma_vel**2, sigma_vel**2, sigma_f0**2])


def _prior_mean(p: Array, v0: Array, f0: Array) -> Array:
    """[p, v0, f0] for candidates p (runs, n, 2), v0 (runs, 2), f0 (runs,)."""
    shape = p.shape[:-1]
    return np.concatenate([p, np.broadcast_to(v0[:, None, :], shape + (2,)),
                           np.broadcast_to(f0[:, None, None], shape + (1,))], -1)


def aux_cost(p: Array, measurements: Array, sensors: Sequence[Any], motion: MotionModel, dt: Any,
             v0: Array, f0: Array, cov: Array, cost: str = "nis",
             aux_filter: Any = None) -> Array:
    """Auxiliary-filter cost ``J(p)`` ``(runs, n)`` of candidates p ``(runs, n, 2)``.

    ``measurements`` is ``(K, runs, m)``; ``sensors`` holds the K per-step sensor models;
    ``dt`` a float or K steps; v0 ``(runs, 2)``, f0 ``(runs,)``, cov ``(5, 5)``. One pass of
    ``aux_filter`` (default ``EKF()``) over the batch (runs, n).
    """
    f = EKF() if aux_filter is None else aux_filter
    runs, n = p.shape[:2]
    x = _prior_mean(p, v0, f0)
    P = np.broadcast_to(cov, (runs, n) + cov.shape).copy()
    b = Gaussian(x, P)
    if hasattr(f, "init"):  # filters with memory start their own belief type
        b = f.init(b)
    steps = np.broadcast_to(np.asarray(dt, dtype=float), (len(sensors),))
    J = np.zeros((runs, n))
    for k, sensor in enumerate(sensors):
        b = f.predict(b, motion, float(steps[k]))
        z = measurements[k][:, None, :]
        b, innov = f.update(b, z, sensor)
        nis = innov.nis
        if cost == "nll":
            nis = nis + np.linalg.slogdet(innov.cov)[1]
        J += np.where(np.isnan(nis), 0.0, nis)
    return J


def compress(measurements: Array, sensors: Sequence[Any], dt: Any,
             block: int) -> tuple[Array, list[Any], Array]:
    """Average consecutive blocks of ``block`` (odd) measurements into one each.

    Block j covers steps ``jL .. jL + L - 1`` and stands for its centre step
    ``c = jL + (L - 1)/2``: ``zbar = z_c + mean_i res(z_i, z_c)`` (angles averaged through
    wrapped residuals), taken with the centre step's sensor whose ``sigma*`` fields are
    divided by ``sqrt(L)`` (R / L). The mean of a slowly varying h over the block differs from
    h at the centre by ``h'' L^2 dt^2 / 24``, negligible against ``sigma / sqrt(L)`` for
    Doppler-bearing geometry at sonar ranges and blocks of tens of seconds. Missing values are
    left out of a mean (a block with none is missing). Returns the block measurements
    ``(K / L, runs, m)``, sensors and steps (the first from the prior time to ``c_0``).
    """
    K = len(sensors)
    if K % block:
        raise ValueError(f"K = {K} measurements is not a multiple of block = {block}")
    steps = np.broadcast_to(np.asarray(dt, dtype=float), (K,))
    t = np.cumsum(steps)
    centre = np.arange(K // block) * block + (block - 1) // 2
    zc = measurements[centre]
    z = measurements.reshape((K // block, block) + measurements.shape[1:])
    res = sensors[0].residual(z, zc[:, None])
    ok = ~np.isnan(res)
    n = ok.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, res, 0.0).sum(1) / n
    zbar = np.where(n > 0, zc + mean, np.nan)
    ang = np.asarray(getattr(sensors[0], "angular", ()), dtype=bool)
    if ang.any():
        zbar[..., ang] = wrap(zbar[..., ang])
    out = []
    for c in centre:
        sigmas = {f.name: getattr(sensors[c], f.name) / np.sqrt(block)
                  for f in dataclasses.fields(sensors[c])
                  if f.name.startswith("sigma") and f.init}
        if not sigmas:
            raise ValueError(f"block > 1 needs sensors with sigma* fields; "
                             f"{type(sensors[c]).__name__} has none")
        out.append(dataclasses.replace(sensors[c], **sigmas))
    return zbar, out, np.diff(t[centre], prepend=0.0)


def _box(sensors: Sequence[Any], max_range: float) -> Array:
    o = np.asarray(sensors[0].origin, dtype=float)
    if o.shape != (2,):
        raise ValueError(f"sensors[0].origin has shape {o.shape}; expected (2,) (one observer "
                         "pose shared by all runs) when bounds are not given")
    return np.stack([o - max_range, o + max_range], -1)


def ga_initial_position(
    measurements: ArrayLike,
    sensors: Sequence[Any],
    motion: MotionModel,
    dt: float | Sequence[float],
    *,
    rngs: Sequence[Any],
    velocity_guess: ArrayLike = (0.0, 0.0),
    f0_guess: ArrayLike | None = None,
    cov: ArrayLike | None = None,
    bounds: ArrayLike | None = None,
    max_range: float = 20_000.0,
    ga: Optimizer | None = None,
    cost: str = "nis",
    block: int = 1,
    aux_filter: Any = None,
) -> OptimizeResult:
    """Search each run's initial target position by GA on the auxiliary-filter cost.

    ``measurements`` ``(K, runs, 2)`` [bearing, frequency] and ``sensors`` the K
    ``BearingFrequency`` models (observer pose per step, shared by the runs); the prior time
    is one ``dt`` before the first measurement. ``velocity_guess`` ``(2,)`` or ``(runs, 2)``;
    ``f0_guess`` scalar or ``(runs,)``, default each run's first measured frequency. ``cov``
    the auxiliary prior covariance (default ``dbt_prior_cov()``). ``bounds`` ``(2, 2)`` or
    ``(runs, 2, 2)`` on (x, y); default the square of half-width ``max_range`` around the
    first observer position. ``ga`` defaults to ``GA(50, 200, 0.8, 0.05)`` (the paper's).
    ``cost`` is ``"nis"`` or ``"nll"``; ``block`` (odd, dividing K) averages blocks of
    measurements first (``compress``); ``aux_filter`` defaults to ``EKF()``. ``rngs``: one
    Generator per run (see ``trackkit.optimize``).

    Returns the optimiser's result: ``best_x`` ``(runs, 2)`` the positions at the prior time,
    ``best_f`` their costs.
    """
    z = np.asarray(measurements, dtype=float)
    if z.ndim != 3 or z.shape[0] != len(sensors):
        raise ValueError(
            f"measurements has shape {z.shape}; expected (K, runs, m) with K = "
            f"len(sensors) = {len(sensors)}"
        )
    if cost not in _COSTS:
        raise ValueError(f"cost = {cost!r}; expected one of {_COSTS}")
    K, runs, _ = z.shape
    if np.ndim(dt) and np.shape(dt) != (K,):
        raise ValueError(f"dt has shape {np.shape(dt)}; expected a float or ({K},)")
    if len(rngs) != runs:
        raise ValueError(f"rngs has {len(rngs)} generators; expected one per run ({runs})")
    v0 = np.broadcast_to(np.asarray(velocity_guess, dtype=float), (runs, 2))
    if f0_guess is None:
        freq = z[..., 1]
        first = np.argmax(~np.isnan(freq), axis=0)
        f0 = freq[first, np.arange(runs)]
        if np.isnan(f0).any():
            raise ValueError("f0_guess not given and some runs have no frequency measurement")
    else:
        f0 = np.broadcast_to(np.asarray(f0_guess, dtype=float), (runs,))
    P0 = dbt_prior_cov() if cov is None else np.asarray(cov, dtype=float)
    box = _box(sensors, max_range) if bounds is None else np.asarray(bounds, dtype=float)
    ga = GA(50, 200, 0.8, 0.05) if ga is None else ga
    if not (isinstance(block, int) and block >= 1 and block % 2 == 1):
        raise ValueError(f"block = {block!r}; expected an odd integer >= 1")
    if block > 1:
        z, sensors, dt = compress(z, sensors, dt, block)

    def J(p: Array) -> Array:
        return aux_cost(p, z, sensors, motion, dt, v0, f0, P0, cost, aux_filter)

    return ga.minimize(J, box, rngs)


def ga_prior(result: OptimizeResult | ArrayLike, f0_guess: ArrayLike, *,
             velocity_guess: ArrayLike = (0.0, 0.0), cov: ArrayLike | None = None) -> Gaussian:
    """The main filter's prior ``N([p, v0, f0], P0)``, batch ``(runs,)``, from the GA.

    ``result`` is an ``OptimizeResult`` (its ``best_x``) or positions ``(runs, 2)``; the
    prior is at the GA's prior time (one step before the first measurement), ready for
    ``run_filter`` or the Monte Carlo engine. ``f0_guess`` scalar or ``(runs,)`` (e.g. the
    first measured frequencies ``z[0, :, 1]``). ``cov`` defaults to
    ``dbt_prior_cov(1000, 10, 5)``: 1000 m in position, the accuracy the paper claims.
    """
    p = np.asarray(result.best_x if isinstance(result, OptimizeResult) else result, float)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"positions have shape {p.shape}; expected (runs, 2)")
    runs = p.shape[0]
    v0 = np.broadcast_to(np.asarray(velocity_guess, dtype=float), (runs, 2))
    f0 = np.broadcast_to(np.asarray(f0_guess, dtype=float), (runs,))
    mean = _prior_mean(p[:, None, :], v0, f0)[:, 0]
    P0 = dbt_prior_cov(1000.0) if cov is None else np.asarray(cov, dtype=float)
    return Gaussian(mean, np.broadcast_to(P0, (runs, 5, 5)).copy())
