"""Centralised fusion of every agent's bearings: the reference a decentralised network is
measured against (Jalalipoor and Kardehi Moghaddam 2021 give no such reference).

One filter per target receives every bearing of every agent, one at a time in time order,
as a fusion centre linked to every agent without loss or delay would. Batched over runs R
and targets Nt: the state is ``(R, Nt, 4)`` = [x, y, vx, vy], and no Python loop runs over
either (the loop is over the M = A E executions, sorted by time).

**Association is ideal.** The bearing of target j goes to filter j: the simulation's true
target label is used, which no real tracker has. The reference therefore measures *fusion*
(how well all the bearings together fix each target), not association or track management:
that is what "centralised fusion" means here, and it is the quantity the PCRLB bounds.
A decentralised agent that comes within a factor of this reference loses that factor to its
partial view, its composite batching, its association and its life cycle together.

The model (trackkit's conventions). Target j moves by ``models.ConstantVelocity(dim=2, q)``:

    x_k = F(dt) x_{k-1} + w,   F(dt) = [[I, dt I], [0, I]],
    Q(dt) = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]],   dt = t_k - t_{k-1}

and execution k of agent a(k) at S_k (its position at t_k) gives the nautical bearing

    z_kj = atan2(x_j - x_s, y_j - y_s) + v,   v ~ N(0, sigma_a(k)^2)

(``models.Bearing(origin=S_k, sigma=sigma_a(k))``; residuals wrapped to (-pi, pi]). The
filter (EKF by default; UKF, CKF or IEKF from ``tk.filters``) runs, per execution,

    predict:  x- = F x,  P- = F P F^T + Q
    update:   H = [(y - y_s), -(x - x_s), 0, 0] / r^2 at x-,  S = H P- H^T + sigma^2,
              K = P- H^T / S,  x+ = x- + K wrap(z - h(x-)),
              P+ = (I - K H) P- (I - K H)^T + K sigma^2 K^T       (Joseph form)

A target out of an agent's range gives no bearing (nan): the update returns the prediction.

**Start.** A Cartesian EKF started far from the truth with a huge covariance linearises at
the wrong place and collapses in range; so each filter starts from the composite measurement
(``network.composite_measurement``, the Gauss-Newton ML estimate of the state from a batch of
bearings, with covariance J^{-1}) of its target's first n bearings, at the time of the n-th:
the smallest n in ``init_min, init_min + init_step, .. <= init_max`` whose composite

* CONVERGED (and is not SINGULAR),
* passes the goodness of fit ``2 lambda <= chi2.ppf(fit_p, n - 4)``, and
* fixes the position: ``sqrt(tr P_xy) <= init_rel_std * range`` (range from the mean
  sensor position of the batch to the estimate), so that the EKF linearises where the
  likelihood is close to Gaussian, and the velocity: ``sqrt(tr P_v) <= init_vel_std``.
  (Measured on the baseline-like geometry: the first 6 bearings, two per agent over about
  10 s, fix the position to a few per cent of the range but the velocity only to hundreds
  of m/s in a few runs in fifty; an EKF started there drifts far off and its NEES runs
  into the hundreds.)

The Gauss-Newton iterations start from the least-squares intersection of the batch's lines
of sight (zero velocity). The bearings of that batch are used by the composite only; the
filter takes every later one, so each bearing enters once. A target whose first
``init_max`` bearings never qualify is not started (``started`` stays False).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.belief import Gaussian
from trackkit.eval.metrics import chi2_ppf
from trackkit.filters import CKF, EKF, IEKF, UKF
from trackkit.models import Bearing, ConstantVelocity
from trackkit.network.composite import CONVERGED, composite_measurement
from trackkit.sim.sensor_network import NetworkRun

__all__ = [
    "FILTERS",
    "CentralSettings",
    "CentralFusion",
    "central_fusion",
    "central_from_run",
    "nees",
]

Array = NDArray[np.float64]

#: the filters the centralised reference can run
FILTERS = ("ekf", "ukf", "ckf", "iekf")


@dataclass(frozen=True)
class CentralSettings:
    """The centralised filter's options.

    ``filter``: one of :data:`FILTERS` (default "ekf"). ``q``: the CV spectral density
    (m^2/s^3); None takes the value the caller passes (``run_network`` passes the truth's
    q). Start (module docstring): ``init_min`` = 6 bearings (two per agent of three),
    growing by ``init_step`` = 3 up to ``init_max`` = 90; ``init_rel_std`` = 0.1;
    ``init_vel_std`` = 10 m/s; ``fit_p`` = 0.999.
    """

    filter: str = "ekf"
    q: float | None = None
    init_min: int = 6
    init_step: int = 3
    init_max: int = 90
    init_rel_std: float = 0.1
    init_vel_std: float = 10.0
    fit_p: float = 0.999

    def __post_init__(self) -> None:
        if self.filter not in FILTERS:
            raise ValueError(f"CentralSettings.filter = {self.filter!r}; expected one of "
                             f"{FILTERS}")
        if self.q is not None and not (math.isfinite(self.q) and self.q >= 0):
            raise ValueError(f"CentralSettings.q = {self.q!r}; expected None or a finite "
                             "spectral density >= 0 (m^2/s^3)")
        for name, least in (("init_min", 4), ("init_step", 1), ("init_max", 4)):
            v = getattr(self, name)
            if not (isinstance(v, int | np.integer) and v >= least):
                raise ValueError(f"CentralSettings.{name} = {v!r}; expected an integer >= "
                                 f"{least}")
        if self.init_max < self.init_min:
            raise ValueError(f"CentralSettings.init_max = {self.init_max!r}; expected >= "
                             f"init_min = {self.init_min!r}")
        for name in ("init_rel_std", "init_vel_std"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and v > 0 and math.isfinite(v)):
                raise ValueError(f"CentralSettings.{name} = {v!r}; expected a finite number "
                                 "> 0")
        if not 0 < self.fit_p < 1:
            raise ValueError(f"CentralSettings.fit_p = {self.fit_p!r}; expected a "
                             "probability in (0, 1)")


class CentralFusion(NamedTuple):
    """The centralised filter's output on M executions sorted by time, batch R runs.

    ``time (R, M)``: the execution times, sorted (ties: lower agent first).
    ``order (R, M)``: each sorted execution's index into the input's flattened (A E) axis.
    ``agent (R, M)``: the executing agent. ``mean (R, M, Nt, 4)``, ``cov (R, M, Nt, 4, 4)``:
    each target's estimate after that execution's update (nan where not ``started``).
    ``started (R, M, Nt)``: the target's filter is running at that execution.
    ``start_time (R, Nt)``: the time of its start (nan: never started); ``start_bearings
    (R, Nt)``: the bearings in its start composite (0: never started).
    """

    time: Array
    order: NDArray[np.intp]
    agent: NDArray[np.intp]
    mean: Array
    cov: Array
    started: NDArray[np.bool_]
    start_time: Array
    start_bearings: NDArray[np.int64]


def _filter(name: str):
    return {"ekf": EKF, "ukf": UKF, "ckf": CKF, "iekf": IEKF}[name]()


def _intersection(z: Array, S: Array) -> Array:
    """The least-squares intersection of lines of sight, ``(..., 2)``, from bearings
    ``z (..., n)`` (nan: absent) at sensor positions ``S (..., n, 2)``.

    The line through S_k along (sin z_k, cos z_k) has normal n_k = (cos z_k, -sin z_k), and
    the point p minimising sum_k (n_k . (p - S_k))^2 solves
    ``(sum n_k n_k^T) p = sum n_k n_k^T S_k``. A ridge of 1e-9 of the trace keeps the system
    regular when the lines are parallel (then p sits near the sensors: a start, not an answer).
    """
    ok = ~np.isnan(z)
    zz = np.where(ok, z, 0.0)
    n = np.stack([np.cos(zz), -np.sin(zz)], -1) * ok[..., None]
    N = np.einsum("...ki,...kj->...ij", n, n)
    b = np.einsum("...ki,...kj,...kj->...i", n, n, np.where(ok[..., None], S, 0.0))
    N = N + 1e-9 * np.trace(N, axis1=-2, axis2=-1)[..., None, None] * np.eye(2) \
        + 1e-300 * np.eye(2)
    return np.linalg.solve(N, b[..., None])[..., 0]


def _starts(z: Array, t: Array, S: Array, sig: Array, s: CentralSettings
            ) -> tuple[Array, Array, NDArray[np.intp], NDArray[np.int64]]:
    """The start composite of every (run, target) (module docstring).

    Inputs sorted by time: ``z (R, M, Nt)``, ``t (R, M)``, ``S (R, M, 2)``, ``sig (R, M)``.
    Returns the mean ``(R, Nt, 4)`` and covariance ``(R, Nt, 4, 4)`` at the start, the
    sorted execution index of the start ``(R, Nt)`` (M: never) and the bearings used.
    """
    R, M, Nt = z.shape
    present = ~np.isnan(z)
    # per (run, target), the sorted executions holding a bearing of it, first n_max of them
    n_max = min(s.init_max, M)
    sizes = np.arange(s.init_min, n_max + 1, s.init_step)
    R_, Nt_ = np.arange(R)[:, None, None], np.arange(Nt)[None, :, None]
    mean = np.zeros((R, Nt, 4))
    cov = np.broadcast_to(np.eye(4), (R, Nt, 4, 4)).copy()
    k0 = np.full((R, Nt), M, np.intp)
    used = np.zeros((R, Nt), np.int64)
    if sizes.size == 0:
        return mean, cov, k0, used
    idx = np.argsort(~present, axis=1, kind="stable").transpose(0, 2, 1)[..., :n_max]
    count = present.sum(1)  # (R, Nt)
    zw = z.transpose(0, 2, 1)[R_, Nt_, idx]  # (R, Nt, n_max)
    tw, sw = t[R_, idx], sig[R_, idx]
    Sw = S[R_, idx]  # (R, Nt, n_max, 2)
    # candidate c uses the first sizes[c] bearings: (R, Nt, C, n_max), nan beyond
    C = sizes.size
    keep = np.arange(n_max)[None, :] < sizes[:, None]  # (C, n_max)
    keep = keep & (np.arange(n_max) < count[..., None, None])  # also where there are fewer
    zc = np.where(keep, zw[:, :, None, :], np.nan)
    last = np.minimum(sizes, count[..., None]) - 1  # (R, Nt, C), index of the last bearing
    t_f = np.take_along_axis(tw, np.maximum(last, 0), -1)
    x0 = np.zeros((R, Nt, C, 4))
    x0[..., :2] = _intersection(zc, np.broadcast_to(Sw[:, :, None], zc.shape + (2,)))
    tc = np.where(keep, tw[:, :, None, :], t_f[..., None])
    sc = np.where(keep, sw[:, :, None, :], 1.0)
    c = composite_measurement(zc, tc, np.broadcast_to(Sw[:, :, None], zc.shape + (2,)), sc,
                              t_f, x0)
    M_c = keep.sum(-1)
    fit = 2.0 * c.cost <= chi2_ppf(s.fit_p, np.maximum(M_c - 4, 1))
    centre = np.nanmean(np.where(keep[..., None], Sw[:, :, None], np.nan), -2)
    rng_ = np.hypot(*(c.mean[..., :2] - centre).transpose(3, 0, 1, 2))
    with np.errstate(invalid="ignore"):
        spread = np.sqrt(c.cov[..., 0, 0] + c.cov[..., 1, 1])
        vspread = np.sqrt(c.cov[..., 2, 2] + c.cov[..., 3, 3])
        good = ((c.status == CONVERGED) & fit & (M_c == sizes) & (M_c >= 4)
                & (spread <= s.init_rel_std * rng_) & (vspread <= s.init_vel_std))
    first = np.argmax(good, -1)  # (R, Nt): the smallest good candidate
    ok = good.any(-1)
    pick = first[..., None]
    mean = np.where(ok[..., None], np.take_along_axis(c.mean, pick[..., None], 2)[:, :, 0],
                    mean)
    P = np.take_along_axis(c.cov, pick[..., None, None], 2)[:, :, 0]
    cov = np.where(ok[..., None, None], P, cov)
    kl = np.take_along_axis(last, pick, -1)[..., 0]
    k0 = np.where(ok, np.take_along_axis(idx, np.maximum(kl, 0)[..., None], -1)[..., 0], M)
    used = np.where(ok, sizes[first], 0).astype(np.int64)
    return mean, cov, k0, used


def central_fusion(
    z: ArrayLike,
    time: ArrayLike,
    sensor: ArrayLike,
    sigma: ArrayLike,
    *,
    q: float = 0.0,
    settings: CentralSettings | None = None,
) -> CentralFusion:
    """Centralised fusion of labelled bearings (module docstring).

    Args:

        z: ``(R, A, E, Nt)`` agent a's bearing of target j at its e-th execution (rad,
            nautical; nan: none). The target axis is the true label (ideal association).
        time: ``(R, A, E)`` execution times (s). sensor: ``(R, A, E, 2)`` the agent's
            position at each execution (m). sigma: bearing std (rad), scalar, ``(A,)`` or
            ``(R, A)``.
        q: the CV spectral density used when ``settings.q`` is None (m^2/s^3).
        settings: ``CentralSettings``.

    Returns:

        ``CentralFusion``.
    """
    s = CentralSettings() if settings is None else settings
    Z = np.asarray(z, dtype=float)
    if Z.ndim != 4:
        raise ValueError(f"z has shape {Z.shape}; expected (R, A, E, Nt) bearings")
    R, A, E, Nt = Z.shape
    T = np.asarray(time, dtype=float)
    if T.shape != (R, A, E) or not np.all(np.isfinite(T)):
        raise ValueError(f"time has shape {T.shape}; expected finite (R, A, E) = "
                         f"{(R, A, E)} execution times")
    P_ = np.asarray(sensor, dtype=float)
    if P_.shape != (R, A, E, 2) or not np.all(np.isfinite(P_)):
        raise ValueError(f"sensor has shape {P_.shape}; expected finite (R, A, E, 2) = "
                         f"{(R, A, E, 2)} positions")
    try:
        sg = np.broadcast_to(np.asarray(sigma, dtype=float)[..., None], (R, A, E))
    except ValueError:
        raise ValueError(f"sigma has shape {np.shape(sigma)}; expected a scalar, (A,) or "
                         f"(R, A) with A = {A}") from None
    if not (np.all(sg > 0) and np.all(np.isfinite(sg))):
        raise ValueError("sigma has entries that are not finite and > 0; expected standard "
                         "deviations in radians")
    if np.isinf(Z).any():
        raise ValueError("z has infinite entries; expected bearings in radians, nan for none")
    qq = float(q) if s.q is None else s.q
    if not (math.isfinite(qq) and qq >= 0):
        raise ValueError(f"q = {q!r}; expected a finite spectral density >= 0 (m^2/s^3)")

    # the executions of all agents in time order (ties: lower agent first, as run_network)
    M = A * E
    flat_t = T.reshape(R, M)
    order = np.argsort(flat_t, axis=1, kind="stable")
    ts = np.take_along_axis(flat_t, order, 1)
    zs = np.take_along_axis(Z.reshape(R, M, Nt), order[..., None], 1)
    Ss = np.take_along_axis(P_.reshape(R, M, 2), order[..., None], 1)
    sgs = np.take_along_axis(sg.reshape(R, M), order, 1)
    agent = order // E

    x, P, k0, used = _starts(zs, ts, Ss, sgs, s)
    t_start = np.where(k0 < M, np.take_along_axis(ts, np.minimum(k0, M - 1), 1), np.nan)
    t_now = t_start.copy()
    f, cv = _filter(s.filter), ConstantVelocity(dim=2, q=qq)
    levels = np.unique(sgs)
    b = Gaussian(x, P)
    out_x = np.full((R, M, Nt, 4), np.nan)
    out_P = np.full((R, M, Nt, 4, 4), np.nan)
    started = np.arange(M)[None, :, None] >= k0[:, None, :]
    for k in range(M):
        run = k > k0  # (R, Nt): rows whose filter takes this execution
        if run.any():
            dt = np.where(run, ts[:, k, None] - t_now, 0.0)
            b = f.predict(b, cv, dt)
            origin = Ss[:, k, None, :]  # (R, 1, 2): one sensor per run, all targets
            zk = np.where(run, zs[:, k], np.nan)
            # one update per distinct sigma (a Bearing's sigma is a scalar); rows of the
            # other levels hold nan and keep their prediction
            for lev in levels:
                on = (sgs[:, k] == lev)[:, None]
                if not (on & run & ~np.isnan(zk)).any():
                    continue
                sen = Bearing(origin=origin, sigma=float(lev))
                b, _ = f.update(b, np.where(on, zk, np.nan)[..., None], sen)
            t_now = np.where(run, ts[:, k, None], t_now)
        here = started[:, k]
        out_x[:, k] = np.where(here[..., None], b.mean, np.nan)
        out_P[:, k] = np.where(here[..., None, None], b.cov, np.nan)
    return CentralFusion(ts, order, agent, out_x, out_P, started, t_start, used)


def central_from_run(run: NetworkRun, *, q: float = 0.0,
                     settings: CentralSettings | None = None) -> CentralFusion:
    """:func:`central_fusion` on the bearings of a ``sim.sensor_network`` run batch (straight
    agents: the bearings ``run_network`` gives them)."""
    b = run.bearings
    return central_fusion(b.z, b.time, b.sensor, b.sigma, q=q, settings=settings)


def nees(result: CentralFusion, truth: ArrayLike) -> Array:
    """``e^T P^{-1} e`` ``(R, M, Nt)`` of each estimate, e = mean - truth, with ``truth``
    ``(R, A, E, Nt, 4)`` (``NetworkRun.target_at_bearing``; taken in the result's order);
    nan where not started."""
    X = np.asarray(truth, dtype=float)
    R, M, Nt = result.started.shape
    if X.ndim != 5 or X.shape[0] != R or X.shape[1] * X.shape[2] != M:
        raise ValueError(f"truth has shape {X.shape}; expected (R, A, E, Nt, 4) with R = {R} "
                         f"and A E = {M}")
    Xs = np.take_along_axis(X.reshape(R, M, Nt, 4), result.order[..., None, None], 1)
    e = result.mean - Xs
    ok = result.started
    P = np.where(ok[..., None, None], result.cov, np.eye(4))
    e0 = np.where(ok[..., None], e, 0.0)
    d = np.einsum("...i,...i->...", e0, np.linalg.solve(P, e0[..., None])[..., 0])
    return np.where(ok, d, np.nan)
