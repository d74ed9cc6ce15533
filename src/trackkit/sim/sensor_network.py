"""Asynchronous bearings of moving agents on constant-velocity targets (Jalalipoor and Kardehi
Moghaddam 2021, eqs. 1-4, 9-12 and 17-18), batched over Monte Carlo runs, seeded per run.

Geometry and measurement (2.1). Agent i at S_i(t) = [x_s, y_s] takes, at each of its
executions t, one bearing of every target j whose position T_j(t) = [x_t, y_t] lies within its
measurement range MR_i (360 degree field of view)::

    z_ij(t) = wrap(atan2(x_t - x_s, y_t - y_s) + sigma_i e),   e ~ N(0, 1)
    present  iff  |T_j(t) - S_i(t)| <= MR_i

(nautical: clockwise from north, wrapped to (-pi, pi]; ``convention="math"`` gives
atan2(dy, dx)). A target beyond MR_i gives no bearing: the slot holds nan, ``in_range`` is
False and ``Bearings.n_out`` counts it, so nothing disappears silently.

Targets (2.2). x = [x, y, vx, vy] moves between consecutive times t_k < t_{k+1}
(dt = t_{k+1} - t_k) as::

    x_{k+1} = F(dt) x_k + L(dt) w_k,   w_k ~ N(0, I_4),   L L^T = Q(dt)

with F and Q those of ``models.ConstantVelocity(dim=2, q=q)`` (per axis
F = [[1, dt], [0, 1]], Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]], q in m^2/s^3). This is the
exact sampling of continuous white-noise acceleration at arbitrary times, so the truth is
consistent on any grid, including the union of a fine grid and every execution time.

Asynchrony ("random delays" in the paper, which gives no distribution). Time is cut into
slots of the nominal period P; agent i's e-th execution (e = 0 .. E-1, E = floor(D / P) for a
duration D) is delayed from the slot's start by a uniform random delay::

    t_ie = e P + d_ie,   d_ie ~ U[0, d_max),   0 <= d_max <= P

so each agent runs exactly once per slot, its times are strictly increasing (the slots do not
overlap), the gaps t_i,e+1 - t_ie have mean P and lie in (P - d_max, P + d_max), and
different agents are never synchronised for d_max > 0 (d_max = 0 is the synchronous network).

Communication (2.10). The proximity (disk) graph links agents k != l with
``|S_k - S_l| <= min(CR_k, CR_l)``: a link is two-way, so both ends must reach.

Record layout. Bearings are padded arrays, one slot per (run, agent, execution, target):
``Bearings.z[r, i, e, j]`` is agent i's e-th bearing of target j in run r; the agent and
target indices are the axes 1 and 3 (the target index is for truth bookkeeping: an estimator
must not use it), the time and sensor position are ``time[r, i, e]`` and ``sensor[r, i, e]``.
A padded layout keeps every run the same shape (the array code needs no per-run lists) and a
window of an agent's bearings of one target is a slice that
``network.composite_measurement`` takes as it is (nan = absent).

Determinism. Run r draws from the children of ``SeedSequence(seed, spawn_key=(r,))`` (the
sequence behind ``sim.streams.run_rng(seed, r)``), one child per purpose, so each purpose's
draws depend on (seed, r) and the sizes alone, never on the other runs or on another purpose:

* child 0: the execution delays, uniform ``(A, E)``;
* child 1: the bearing noise, standard normal ``(A, E, Nt)`` (drawn for every slot, also for
  targets out of range);
* child 2: the target process noise, standard normal ``(K - 1, Nt, 4)``, only when q > 0.

The only Python loop over runs is the one that asks each run's generator for its block of
draws (a per-run seed needs a per-run generator); all arithmetic is batched, with loops over
time steps only.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.models.motion import ConstantVelocity, interleave_axes
from trackkit.models.sensors import Bearing, check_convention

__all__ = [
    "Bearings",
    "NetworkRun",
    "Schedule",
    "bearings_at",
    "cv_noise_factor",
    "disk_graph",
    "process_noise",
    "schedule",
    "simulate_network",
    "straight_paths",
    "target_truth",
]

Array = NDArray[np.float64]

#: which child of a run's SeedSequence serves which draws (see the module docstring)
_CHILD_DELAY, _CHILD_BEARING, _CHILD_PROCESS = 0, 1, 2


class Schedule(NamedTuple):
    """The random part of a network run that does not depend on where the agents go.

    ``time`` ``(R, A, E)``: execution times t_ie = e P + d_ie, increasing along E.
    ``noise`` ``(R, A, E, Nt)``: the standard-normal bearing noise e of every slot.
    """

    time: Array
    noise: Array


class Bearings(NamedTuple):
    """Every bearing slot of a run batch (module docstring: record layout).

    ``z`` ``(R, A, E, Nt)``: bearings (rad, wrapped), nan where the target is beyond MR.
    ``time`` ``(R, A, E)``: the execution time of each slot (s).
    ``sensor`` ``(R, A, E, 2)``: the agent's position S_i(t) (east, north; m).
    ``in_range`` ``(R, A, E, Nt)``: True where the bearing is present.
    ``n_out`` ``(R, A, Nt)``: bearings absent because the target was beyond MR.
    ``sigma`` ``(A,)``: each agent's bearing standard deviation (rad).
    """

    z: Array
    time: Array
    sensor: Array
    in_range: NDArray[np.bool_]
    n_out: NDArray[np.int64]
    sigma: Array


class NetworkRun(NamedTuple):
    """An open-loop network run: the truth and the bearings.

    ``truth_time`` ``(K,)``: the fine grid 0, dt, 2 dt, ... <= duration (s).
    ``truth`` ``(R, K, Nt, 4)``: target states on the fine grid.
    ``target_at_bearing`` ``(R, A, E, Nt, 4)``: target states at each execution time (for
    metrics and bounds; an estimator must not read it).
    ``bearings``: the ``Bearings`` record.
    """

    truth_time: Array
    truth: Array
    target_at_bearing: Array
    bearings: Bearings


# --- input checks ----------------------------------------------------------------------------


def _positive(name: str, value: float, allow_inf: bool = False) -> float:
    v = float(value)
    if not (v > 0 and (allow_inf or math.isfinite(v))):  # also refuses nan
        what = "a number > 0 (inf allowed)" if allow_inf else "a finite number > 0"
        raise ValueError(f"{name} = {value!r}; expected {what}")
    return v


def _per_agent(name: str, value: ArrayLike, n_agents: int, allow_inf: bool = False) -> Array:
    """A scalar or one value per agent, > 0, as an ``(A,)`` array."""
    v = np.asarray(value, dtype=float)
    if v.ndim == 0:
        v = np.full(n_agents, float(v))
    if v.shape != (n_agents,):
        raise ValueError(f"{name} has shape {v.shape}; expected a scalar or ({n_agents},), "
                         "one value per agent")
    ok = (v > 0) & (np.isfinite(v) | allow_inf)
    if not ok.all():
        what = "> 0 (inf allowed)" if allow_inf else "finite and > 0"
        raise ValueError(f"{name} = {v.tolist()}; expected values {what}")
    return v


def _states(name: str, value: ArrayLike, what: str) -> Array:
    x = np.asarray(value, dtype=float)
    if x.ndim not in (2, 3) or x.shape[-1] != 4 or x.shape[-2] < 1:
        raise ValueError(f"{name} has shape {x.shape}; expected ({what}, 4) or "
                         f"(runs, {what}, 4) states [x, y, vx, vy]")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} has non-finite entries; expected finite states (m, m/s)")
    return x


def _count(name: str, value: int, least: int) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < least:
        raise ValueError(f"{name} = {value!r}; expected an integer >= {least}")
    return int(value)


def _draw(seed: int, first_run: int, runs: int, child: int, draw) -> Array:
    """``draw(g)`` stacked over runs, g the generator of child ``child`` of run r's
    SeedSequence (the one behind ``sim.streams.run_rng(seed, r)``)."""
    out = [draw(np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(r, child))))
           for r in range(first_run, first_run + runs)]
    return np.stack(out)


def _slots(duration: float, period: float) -> int:
    """E = floor(D / P), forgiving the rounding of a D that is a whole number of periods
    (0.3 / 0.1 is 2.9999999999999996)."""
    return int(math.floor(duration / period * (1.0 + 1e-12)))


# --- draws ---------------------------------------------------------------------------------


def schedule(
    seed: int,
    runs: int,
    n_agents: int,
    n_targets: int,
    duration: float,
    period: float,
    max_delay: float | None = None,
    first_run: int = 0,
) -> Schedule:
    """Execution times and bearing noise of runs ``first_run .. first_run + runs - 1``.

    ``t_ie = e P + d_ie``, ``d_ie = d_max u_ie``, ``u_ie ~ U[0, 1)`` (child 0), e = 0 .. E-1
    with E = floor(duration / P); bearing noise ``e ~ N(0, 1)`` ``(A, E, Nt)`` (child 1).
    ``max_delay`` d_max defaults to P (each execution uniform in its slot); it must lie in
    [0, P] so that an agent's executions stay in order.
    """
    runs = _count("runs", runs, 1)
    n_agents = _count("n_agents", n_agents, 1)
    n_targets = _count("n_targets", n_targets, 1)
    first_run = _count("first_run", first_run, 0)
    duration = _positive("duration", duration)
    period = _positive("period", period)
    d_max = period if max_delay is None else float(max_delay)
    if not 0 <= d_max <= period:  # also refuses nan
        raise ValueError(f"max_delay = {max_delay!r}; expected 0 <= max_delay <= period "
                         f"= {period!r} s (a longer delay could reorder an agent's executions)")
    E = _slots(duration, period)
    if E < 1:
        raise ValueError(f"duration = {duration!r} is shorter than period = {period!r}; "
                         "expected at least one execution slot")
    u = _draw(seed, first_run, runs, _CHILD_DELAY, lambda g: g.random((n_agents, E)))
    e = _draw(seed, first_run, runs, _CHILD_BEARING,
              lambda g: g.standard_normal((n_agents, E, n_targets)))
    time = period * np.arange(E) + d_max * u
    return Schedule(time, e)


def process_noise(seed: int, runs: int, n_steps: int, n_targets: int,
                  first_run: int = 0) -> Array:
    """Standard-normal target process noise ``(R, n_steps, Nt, 4)`` (child 2 of each run)."""
    runs = _count("runs", runs, 1)
    n_steps = _count("n_steps", n_steps, 0)
    n_targets = _count("n_targets", n_targets, 1)
    first_run = _count("first_run", first_run, 0)
    return _draw(seed, first_run, runs, _CHILD_PROCESS,
                 lambda g: g.standard_normal((n_steps, n_targets, 4)))


# --- kinematics ----------------------------------------------------------------------------


def cv_noise_factor(q: float, dt: ArrayLike) -> Array:
    """The lower-triangular L ``(..., 4, 4)`` with L L^T = Q(dt) of
    ``ConstantVelocity(dim=2, q=q)``, in closed form so that dt = 0 (a grid time that is
    also an execution time) and tiny dt need no Cholesky (which would fail on Q = 0, and
    batched would fail every row for one bad row). Per axis::

        L = sqrt(q) [[sqrt(dt^3 / 3), 0], [sqrt(3 dt) / 2, sqrt(dt) / 2]]

    (L L^T: dt^3/3, dt^2/2 off the diagonal, 3 dt/4 + dt/4 = dt.)
    """
    dt = np.asarray(dt, dtype=float)
    B = np.zeros(dt.shape + (2, 2))
    B[..., 0, 0] = np.sqrt(dt**3 / 3.0)
    B[..., 1, 0] = np.sqrt(3.0 * dt) / 2.0
    B[..., 1, 1] = np.sqrt(dt) / 2.0
    return interleave_axes(B, np.full(2, math.sqrt(q)))


def target_truth(x0: ArrayLike, times: ArrayLike, q: float = 0.0,
                 noise: ArrayLike | None = None) -> Array:
    """CV target states at ``times``, ``(R, K, Nt, 4)``.

    ``x0`` ``(Nt, 4)`` or ``(R, Nt, 4)``: the states at ``times[..., 0]``. ``times`` ``(K,)``
    or ``(R, K)``: nondecreasing (equal times give equal states). R is the runs axis of
    whichever of x0, times and noise has one. ``x_{k+1} = F(dt) x_k +
    L(dt) w_k`` (module docstring) with ``w = noise`` ``(R, K - 1, Nt, 4)`` standard normals
    (``process_noise``); ``noise`` is required when q > 0 and ignored when q = 0.
    """
    x0 = _states("x0", x0, "Nt")
    t = np.asarray(times, dtype=float)
    if t.ndim not in (1, 2) or t.shape[-1] < 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"times has shape {t.shape}; expected finite (K,) or (R, K) times")
    if np.any(np.diff(t, axis=-1) < 0):
        raise ValueError("times decrease somewhere; expected nondecreasing times per run")
    q = float(q)
    if not (q >= 0 and math.isfinite(q)):
        raise ValueError(f"q = {q!r}; expected a finite spectral density >= 0 (m^2/s^3)")
    # the runs come from whichever of x0, times and noise has them
    w_runs = np.shape(noise)[0] if (q > 0 and noise is not None and np.ndim(noise)) else 1
    R = max(x0.shape[0] if x0.ndim == 3 else 1, t.shape[0] if t.ndim == 2 else 1, w_runs)
    if (x0.ndim == 3 and x0.shape[0] != R) or (t.ndim == 2 and t.shape[0] != R):
        raise ValueError(f"x0 has shape {x0.shape} and times {t.shape}; expected the same "
                         "number of runs on their leading axes")
    K, Nt = t.shape[-1], x0.shape[-2]
    t = np.broadcast_to(t, (R, K))
    if q > 0:
        if noise is None:
            raise ValueError("noise is None but q > 0; expected standard normals "
                             f"(R, K - 1, Nt, 4) = {(R, K - 1, Nt, 4)} (see process_noise)")
        w = np.asarray(noise, dtype=float)
        if w.shape != (R, K - 1, Nt, 4):
            raise ValueError(f"noise has shape {w.shape}; expected (R, K - 1, Nt, 4) = "
                             f"{(R, K - 1, Nt, 4)}")
    cv = ConstantVelocity(dim=2, q=q)
    out = np.empty((R, K, Nt, 4))
    out[:, 0] = x0
    dts = np.diff(t, axis=-1)
    # every step's F(dt) at once, (R, K - 1, 1, 4, 4): one step per run, shared by its targets
    F = cv.jacobian(x0, dts[:, :, None])
    for k in range(K - 1):
        out[:, k + 1] = np.einsum("...ij,...j->...i", F[:, k], out[:, k])
        if q > 0:
            out[:, k + 1] += np.einsum("rij,rtj->rti", cv_noise_factor(q, dts[:, k]), w[:, k])
    return out


def straight_paths(agents: ArrayLike, times: ArrayLike) -> Array:
    """Positions ``S(t) = p0 + t v`` of agents on straight lines, ``(..., A, E, 2)``.

    ``agents`` ``(..., A, 4)``: [x, y, vx, vy] at t = 0; ``times`` ``(..., A, E)``.
    """
    a = _states("agents", agents, "A")
    t = np.asarray(times, dtype=float)
    if t.ndim < 2 or t.shape[-2] != a.shape[-2]:
        raise ValueError(f"times has shape {t.shape}; expected (..., A, E) with A = "
                         f"{a.shape[-2]} agents")
    return a[..., None, :2] + t[..., None] * a[..., None, 2:4]


# --- measurement and graph -----------------------------------------------------------------


def bearings_at(
    sensor_pos: ArrayLike,
    targets: ArrayLike,
    noise: ArrayLike | None,
    sigma: ArrayLike,
    mr: ArrayLike = np.inf,
    convention: str = "nautical",
) -> tuple[Array, NDArray[np.bool_]]:
    """The bearings of one batched execution event (module docstring, 2.1).

    Args:

        sensor_pos: ``(..., 2)`` the executing agents' positions S (east, north; m).
        targets: ``(..., Nt, 4)`` the target states at the same times (only x, y are read).
        noise: ``(..., Nt)`` standard normals e, or None for noise-free bearings.
        sigma: bearing standard deviation (rad), broadcastable to the batch shape ``...``.
        mr: measurement range (m, inf for unlimited), broadcastable to ``...``.
        convention: "nautical" (atan2(dx, dy), default) or "math" (atan2(dy, dx)).

    Returns:

        ``z`` ``(..., Nt)``: wrap(h + sigma e), nan where ``|T - S| > MR``; ``in_range``
        ``(..., Nt)``.
    """
    check_convention(convention)
    S = np.asarray(sensor_pos, dtype=float)
    X = np.asarray(targets, dtype=float)
    if S.ndim < 1 or S.shape[-1] != 2:
        raise ValueError(f"sensor_pos has shape {S.shape}; expected (..., 2) positions")
    if X.ndim < 2 or X.shape[-1] < 2:
        raise ValueError(f"targets has shape {X.shape}; expected (..., Nt, 4) states")
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(X[..., :2]))):
        raise ValueError("sensor_pos or targets have non-finite positions; expected finite "
                         "metres")
    sig = np.asarray(sigma, dtype=float)
    rng = np.asarray(mr, dtype=float)
    if not np.all(sig > 0) or not np.all(np.isfinite(sig)):
        raise ValueError(f"sigma = {sig.tolist()}; expected finite values > 0 (rad)")
    if not np.all(rng > 0):
        raise ValueError(f"mr = {rng.tolist()}; expected values > 0 (m; inf for unlimited)")
    origin = S[..., None, :]
    dist = np.hypot(X[..., 0] - origin[..., 0], X[..., 1] - origin[..., 1])
    in_range = dist <= rng[..., None]
    h = Bearing(origin=origin, convention=convention).h(X)[..., 0]
    if noise is not None:
        e = np.asarray(noise, dtype=float)
        if e.shape != h.shape:
            raise ValueError(f"noise has shape {e.shape}; expected {h.shape} (..., Nt)")
        h = h + sig[..., None] * e
    z = np.where(in_range, wrap(h), np.nan)
    return z, in_range


def disk_graph(positions: ArrayLike, cr: ArrayLike) -> NDArray[np.bool_]:
    """The proximity graph ``(..., A, A)``: ``G[k, l]`` iff k != l and
    ``|S_k - S_l| <= min(CR_k, CR_l)``. Symmetric; no self-loops
    (``network.diffusion.neighbourhood`` adds them).

    ``positions`` ``(..., A, 2)``; ``cr`` a scalar or ``(A,)`` (m, inf for unlimited).
    """
    P = np.asarray(positions, dtype=float)
    if P.ndim < 2 or P.shape[-1] != 2 or not np.all(np.isfinite(P)):
        raise ValueError(f"positions has shape {P.shape}; expected finite (..., A, 2)")
    A = P.shape[-2]
    c = _per_agent("cr", cr, A, allow_inf=True)
    # a - b is exactly -(b - a) and hypot ignores signs, so the matrix is exactly symmetric
    d = np.hypot(P[..., :, None, 0] - P[..., None, :, 0], P[..., :, None, 1] - P[..., None, :, 1])
    G = d <= np.minimum(c[:, None], c[None, :])
    G[..., np.arange(A), np.arange(A)] = False
    return G


# --- an open-loop run ----------------------------------------------------------------------


def simulate_network(
    seed: int,
    runs: int,
    targets: ArrayLike,
    agents: ArrayLike,
    *,
    duration: float,
    period: float,
    sigma: ArrayLike,
    mr: ArrayLike = np.inf,
    max_delay: float | None = None,
    q: float = 0.0,
    truth_dt: float = 1.0,
    first_run: int = 0,
    convention: str = "nautical",
) -> NetworkRun:
    """Runs ``first_run ..`` of an open-loop network: straight-line agents, CV targets.

    Args:

        seed, runs, first_run: run r draws from ``SeedSequence(seed, spawn_key=(r,))``'s
            children (module docstring).
        targets: ``(Nt, 4)`` or ``(R, Nt, 4)`` target states at t = 0 (m, m/s).
        agents: ``(A, 4)`` or ``(R, A, 4)`` agent states at t = 0 (straight lines).
        duration, period, max_delay: the schedule (``schedule``).
        sigma, mr: per-agent bearing std (rad) and measurement range (m), scalar or ``(A,)``.
        q: target process-noise spectral density (m^2/s^3).
        truth_dt: the fine truth grid's step (s); the truth is propagated on the union of
            that grid and every execution time, so both are exact samples of one path.
        convention: the bearing convention.

    Returns:

        ``NetworkRun``.
    """
    x0 = _states("targets", targets, "Nt")
    ag = _states("agents", agents, "A")
    Nt, A = x0.shape[-2], ag.shape[-2]
    sig = _per_agent("sigma", sigma, A)
    rng = _per_agent("mr", mr, A, allow_inf=True)
    truth_dt = _positive("truth_dt", truth_dt)
    duration = _positive("duration", duration)
    sch = schedule(seed, runs, A, Nt, duration, period, max_delay, first_run)
    R, E = sch.time.shape[0], sch.time.shape[2]
    for name, a in (("targets", x0), ("agents", ag)):
        if a.ndim == 3 and a.shape[0] != R:
            raise ValueError(f"{name} has shape {a.shape}; expected {R} runs on the leading "
                             "axis, or no runs axis")

    grid = truth_dt * np.arange(_slots(duration, truth_dt) + 1)
    K0 = grid.size
    t_all = np.concatenate([np.broadcast_to(grid, (R, K0)), sch.time.reshape(R, A * E)], -1)
    order = np.argsort(t_all, axis=-1, kind="stable")
    where = np.argsort(order, axis=-1)  # where each input time sits on the sorted grid
    t_sorted = np.take_along_axis(t_all, order, -1)
    w = process_noise(seed, R, t_sorted.shape[-1] - 1, Nt, first_run) if q > 0 else None
    truth = target_truth(x0, t_sorted, q, w)

    def pick(idx: NDArray[np.intp]) -> Array:
        return np.take_along_axis(truth, idx[:, :, None, None], axis=1)

    on_grid = pick(where[:, :K0])
    at_bearing = pick(where[:, K0:]).reshape(R, A, E, Nt, 4)
    sensor = straight_paths(ag, sch.time)
    z, in_range = bearings_at(sensor, at_bearing, sch.noise, sig[:, None], rng[:, None],
                              convention)
    n_out = (~in_range).sum(axis=2)
    bearings = Bearings(z, sch.time, np.ascontiguousarray(np.broadcast_to(sensor, (R, A, E, 2))),
                        in_range, n_out, sig)
    return NetworkRun(grid, on_grid, at_bearing, bearings)
