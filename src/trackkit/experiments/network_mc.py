"""Monte Carlo of a network scenario (Jalalipoor and Kardehi Moghaddam 2021): runs of
``network.inprocess.run_network``, each agent scored against the true targets beside the
centralised reference and the centralised PCRLB of that run.

    sc = load_network("net-baseline")
    mc = run_network_mc(sc, runs=20)           # NetworkMonteCarlo
    mc.window_rmse("pos", "last")              # (A, Nt) per agent and target

**Runs.** Run r is ``run_network(seed, r, ...)`` with the scenario's agents, targets (drawn
for run r when random: ``NetworkScenario.target_states``), schedule and settings; it depends
on (seed, r) alone, so a result is the same whatever else runs. Runs are stepped together
in blocks of ``NETWORK_BLOCK`` (``network.inprocess.run_network_block``, bit for bit the runs
one at a time); a block is one task of ``experiments.executors.execute``, in this process or
on Dask workers (``workers``, ``scheduler``), and the blocks come back in run order. With
``agents="processes"`` a run is ``network.processes.run_network_processes`` instead (every
agent its own OS process over ZeroMQ; the same numbers when the scenario has no loss).

**Time axis.** Every agent executes exactly once per period (``sim.sensor_network.schedule``), so
execution e of every agent lies in slot e, ``[e P, (e + 1) P)``; series are indexed by e and
plotted at the slot's expected time ``e P + jitter / 2``.

**Scores** of one tracker's confirmed tracks at one execution (``eval.network_score``, cut-off
``report.c_m``, GOSPA p = 2, alpha = 2): the number of confirmed tracks, GOSPA, and for every
target assigned a track (the optimal assignment of ``eval.track_metrics.assign``, pairs closer
than c), the position error ``|p_hat - p|``, the velocity error ``|v_hat - v|`` and the range
error ``| |p_hat - s| - |p - s| |`` (s: the agent's position); nan where the target has no
track.

**The centralised reference beside agent a.** ``run_network(central=True)`` runs one more
tracker after every agent execution with every agent's bearings so far. Agent a's execution
at time t is compared with the last central execution at that time (``searchsorted``: with
jitter 0 several agents share a time, and the reference then holds all their bearings), and
its range error is taken from agent a's position.

**The bound.** The centralised bearings-only PCRLB of the run (``network.bound
.network_pcrlb``) on the agents' *actual* paths (steered, not the straight lines of
``sim.sensor_network``): one event per agent execution with that agent's position, bearing std and
the targets in its measurement range, the prior ``diag(sp^2, sp^2, sv^2, sv^2)`` at t = 0
(``report.prior_pos_std_m``, ``prior_vel_std_mps``) and the scenario's q. Agent a's entry at
execution e is the bound after that event, per target (position and velocity).

**Reductions.** Over time, per agent and target: ``sqrt(mean over runs of e^2)`` over the
runs where the target is held (RMSE), and the fraction of runs where it is held; the bound
``sqrt(mean over runs of bound^2)`` (the mean of the per-run bounds, which
docs/network-comparison.md explains is the one to report). Windows: the executions whose
slot time lies in the first ``report.first_fraction`` or the last ``report.last_fraction``
of the run, pooled over runs (and over targets for the per-agent numbers).
"""

from __future__ import annotations

import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from trackkit.eval.network_score import score_trace
from trackkit.eval.track_metrics import Frames, assign
from trackkit.network.bound import NetworkBound, network_pcrlb
from trackkit.network.inprocess import (
    NetworkResult,
    Trace,
    run_network,
    run_network_block,
)

if TYPE_CHECKING:
    from trackkit.network.agents import AgentSettings
    from trackkit.network.processes import Deployment
    from trackkit.scenario.network import NetworkScenario

__all__ = ["NETWORK_BLOCK", "NetworkMonteCarlo", "RunScores", "run_bound", "run_network_mc",
           "score_run"]

#: runs stepped together in process (``run_network_mc``'s ``block``): past about 25 the
#: per-run work outside the batched kernels dominates (benchmarks/RESULTS.md)
NETWORK_BLOCK = 25

Array = NDArray[np.float64]
Kind = Literal["pos", "vel", "rng"]


@dataclass
class RunScores:
    """One run's scores, A agents, E executions, Nt targets (module docstring).

    ``count (A, E)``, ``gospa (A, E)``, ``err[kind] (A, E, Nt)`` for kind in pos, vel, rng;
    ``central_*`` the same for the centralised reference beside each agent (None without
    it); ``bound_pos``, ``bound_vel``, ``bound_rng`` ``(A, E, Nt)`` the centralised PCRLB
    (``bound_rng``: on the range from the agent, ``sqrt(e^T J^-1 e)``, e the unit line of
    sight in the position block);
    ``held_final (A,)`` whether the agent ends with exactly one confirmed track per target,
    each assigned; ``final_range (A, Nt)`` the true agent-target distance at the agent's
    last execution; ``spacing (2,)`` the run's least and greatest agent-pair distance as a
    fraction of the communication range (``NetworkResult.spacing``); ``sent``,
    ``delivered``, ``lost``, ``late`` messages; ``seconds`` the network run's
    wall-clock time (``NetworkResult.seconds``).
    """

    count: NDArray[np.int64]
    gospa: Array
    err: dict[str, Array]
    central_count: NDArray[np.int64] | None
    central_gospa: Array | None
    central_err: dict[str, Array] | None
    central_held_final: bool | None
    bound_pos: Array
    bound_vel: Array
    bound_rng: Array
    held_final: NDArray[np.bool_]
    final_range: Array
    spacing: Array
    sent: int
    delivered: int
    lost: int
    late: int
    seconds: float


def _scores(time: Array, offsets: NDArray[np.int64], mean: Array, truth: Array,
            where: Array, c: float) -> tuple[NDArray[np.int64], Array, dict[str, Array]]:
    """count (E,), GOSPA (E,) and the errors (E, Nt) of one tracker's executions;
    ``where (E, 2)`` the agent's positions for the range error."""
    s = score_trace(time, offsets, mean, truth, c=c)
    E, Nt = truth.shape[:2]
    tru = Frames(np.arange(E + 1, dtype=np.int64) * Nt, truth[:, :, :2].reshape(E * Nt, 2))
    est = Frames(offsets, np.ascontiguousarray(mean[:, :2]))
    I, J = assign(tru, est, c)  # score_trace's assignment (same arguments, p = 2)
    X, Y = truth.reshape(E * Nt, 4), mean
    vel = np.full(E * Nt, np.nan)
    vel[I] = np.hypot(*(Y[J, 2:4] - X[I, 2:4]).T)
    s_of = np.repeat(where, Nt, axis=0)
    rng = np.full(E * Nt, np.nan)
    rng[I] = np.abs(np.hypot(*(Y[J, :2] - s_of[I]).T) - np.hypot(*(X[I, :2] - s_of[I]).T))
    return s.count, s.gospa, {"pos": s.error, "vel": vel.reshape(E, Nt),
                              "rng": rng.reshape(E, Nt)}


def _held(count: NDArray[np.int64], pos: Array, n_targets: int) -> bool:
    """Exactly one confirmed track per target at the last execution, each assigned."""
    return bool(count[-1] == n_targets and not np.isnan(pos[-1]).any())


def _at_times(trace: Trace, times: Array) -> tuple[Array, NDArray[np.int64], Array, Array]:
    """The central trace at the last of its executions at each of ``times`` (module
    docstring): (time, offsets, mean, truth)."""
    idx = np.searchsorted(trace.time, times, side="right") - 1
    if np.any(idx < 0) or not np.array_equal(trace.time[idx], times):
        raise ValueError("the centralised trace has no execution at some agent's execution "
                         "time; expected one after every agent execution")
    lo, hi = trace.offsets[idx], trace.offsets[idx + 1]
    rows = np.concatenate([np.arange(a, b) for a, b in zip(lo, hi, strict=True)]).astype(
        np.int64) if idx.size else np.zeros(0, np.int64)
    off = np.concatenate([[0], np.cumsum(hi - lo)]).astype(np.int64)
    return trace.time[idx], off, trace.mean[rows].reshape(-1, 4), trace.truth[idx]


def run_bound(results: Sequence[NetworkResult], sigma: Array, meas_range: Array,
              prior_cov: Array, q: float) -> list[NetworkBound]:
    """The centralised PCRLB on each run's actual paths (one event per agent execution),
    every run in one batched ``network_pcrlb``; one ``NetworkBound`` per run."""
    def events(result: NetworkResult) -> tuple[Array, ...]:
        t = np.stack([tr.time for tr in result.agents])  # (A, E)
        pos = np.stack([tr.position for tr in result.agents])  # (A, E, 2)
        truth = np.stack([tr.truth for tr in result.agents])  # (A, E, Nt, 4)
        A, E, Nt = truth.shape[:3]
        valid = np.hypot(truth[..., 0] - pos[..., None, 0],
                         truth[..., 1] - pos[..., None, 1]) <= meas_range[:, None, None]
        sig = np.broadcast_to(sigma[:, None], (A, E))
        return (t.reshape(A * E), pos.reshape(A * E, 2), truth.reshape(A * E, Nt, 4),
                sig.reshape(A * E), valid.reshape(A * E, Nt))
    t, pos, truth, sig, valid = (np.stack(a) for a in zip(*map(events, results),
                                                          strict=True))
    b = network_pcrlb(prior_cov, t, pos, truth, sig, valid, q=q, history=True)
    return [NetworkBound(*(None if a is None else a[i] for a in b))
            for i in range(len(results))]


def score_run(result: NetworkResult, sigma: Array, meas_range: Array, prior_cov: Array,
              q: float, c: float, bound: NetworkBound | None = None) -> RunScores:
    """Score one ``run_network`` result (module docstring); ``bound``: its ``run_bound``,
    when computed already (with the other runs of its block)."""
    A = len(result.agents)
    E = result.agents[0].time.shape[0]
    if any(tr.time.shape[0] != E for tr in result.agents):
        raise ValueError("the agents' traces have different numbers of executions; expected "
                         "one execution per agent and period")
    Nt = result.agents[0].truth.shape[1]
    count = np.zeros((A, E), np.int64)
    gospa = np.zeros((A, E))
    err = {k: np.zeros((A, E, Nt)) for k in ("pos", "vel", "rng")}
    have_c = result.central is not None
    c_count = np.zeros((A, E), np.int64) if have_c else None
    c_gospa = np.zeros((A, E)) if have_c else None
    c_err = {k: np.zeros((A, E, Nt)) for k in ("pos", "vel", "rng")} if have_c else None
    held = np.zeros(A, bool)
    for a, tr in enumerate(result.agents):
        n, g, e = _scores(tr.time, tr.offsets, tr.mean, tr.truth, tr.position, c)
        count[a], gospa[a] = n, g
        for k in err:
            err[k][a] = e[k]
        held[a] = _held(n, e["pos"], Nt)
        if have_c:
            t, off, mean, truth = _at_times(result.central, tr.time)
            n, g, e = _scores(t, off, mean, truth, tr.position, c)
            c_count[a], c_gospa[a] = n, g
            for k in c_err:
                c_err[k][a] = e[k]
    c_held = None
    if have_c:
        ct = result.central
        n, _, e = _scores(ct.time, ct.offsets, ct.mean, ct.truth,
                          np.zeros((ct.time.shape[0], 2)), c)
        c_held = _held(n, e["pos"], Nt)

    # the centralised PCRLB on the actual paths: one event per agent execution
    b = run_bound([result], sigma, meas_range, prior_cov, q)[0] if bound is None else bound
    pos = np.stack([tr.position for tr in result.agents])  # (A, E, 2)
    truth = np.stack([tr.truth for tr in result.agents])  # (A, E, Nt, 4)
    back = np.empty(A * E, np.intp)
    back[b.order] = np.arange(A * E)  # sorted position of every input event
    bound_pos = b.position_rmse[back].reshape(A, E, Nt)
    bound_vel = b.velocity_rmse[back].reshape(A, E, Nt)
    # the range from the agent: |p_hat - s| - |p - s| ~ u^T (p_hat - p), u the unit line of
    # sight, so its bound is sqrt(e^T J^-1 e) with e = [u, 0, 0]
    u = truth[..., :2] - pos[..., None, :]
    u /= np.hypot(u[..., 0], u[..., 1])[..., None]
    e = np.concatenate([u, np.zeros_like(u)], -1).reshape(A * E, Nt, 4, 1)
    J = b.history[back]
    bound_rng = np.sqrt((e * np.linalg.solve(J, e)).sum((-2, -1))).reshape(A, E, Nt)
    final_range = np.hypot(truth[:, -1, :, 0] - pos[:, -1, None, 0],
                           truth[:, -1, :, 1] - pos[:, -1, None, 1])
    return RunScores(count, gospa, err, c_count, c_gospa, c_err, c_held, bound_pos, bound_vel,
                     bound_rng, held, final_range, np.asarray(result.spacing, float),
                     int(result.sent), int(result.delivered), int(result.lost),
                     int(result.late), float(result.seconds))


def _rms(x: Array, axis) -> Array:
    """sqrt(mean x^2) over ``axis`` ignoring nan (nan where nothing is there)."""
    have = ~np.isnan(x)
    n = have.sum(axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(np.nansum(x * x, axis) / np.maximum(n, 1)), np.nan)


@dataclass
class NetworkMonteCarlo:
    """A network Monte Carlo: the per-run scores stacked over runs R (run order), and the
    example run (run 0) for the pictures.

    ``time (E,)``: the slot times ``e P + jitter / 2`` (s). Arrays of :class:`RunScores`
    with a leading runs axis: ``count``, ``gospa`` ``(R, A, E)``; ``err[kind]``
    ``(R, A, E, Nt)``; ``central_*`` likewise (None without the reference);
    ``bound_pos``, ``bound_vel``, ``bound_rng``; ``held_final (R, A)``, ``central_held_final (R,)``;
    ``final_range (R, A, Nt)`` the true agent-target distance at the end; ``spacing (R, 2)``
    each run's least and greatest agent-pair distance over the communication range;
    ``sent``, ``delivered``, ``lost``, ``late`` ``(R,)``; ``recovered (R, K)`` per outage
    the time from the restart until the agent held its tracks again (``--agents
    processes`` with outages; nan if never; K = 0 otherwise); ``seconds (R,)`` (network run) and
    ``wall (R,)`` (run, scores and bound); the channel: ``loss`` (probability), ``delay``
    (s) and ``outages``; ``curve`` (agents authenticated and encrypted with CURVE) and
    ``refused (R,)`` (peers CURVE refused per run; zeros without CURVE).
    """

    name: str
    runs: int
    seed: int
    steering: bool
    duration: float
    period: float
    jitter: float
    first_fraction: float
    last_fraction: float
    c: float
    time: Array
    count: NDArray[np.int64]
    gospa: Array
    err: dict[str, Array]
    central_count: NDArray[np.int64] | None
    central_gospa: Array | None
    central_err: dict[str, Array] | None
    central_held_final: NDArray[np.bool_] | None
    bound_pos: Array
    bound_vel: Array
    bound_rng: Array
    held_final: NDArray[np.bool_]
    final_range: Array
    spacing: Array
    sent: NDArray[np.int64]
    delivered: NDArray[np.int64]
    lost: NDArray[np.int64]
    late: NDArray[np.int64]
    recovered: Array
    seconds: Array
    wall: Array
    loss: float = 0.0
    delay: float = 0.0
    outages: tuple[tuple[int, float, float | None], ...] = ()
    curve: bool = False
    refused: NDArray[np.int64] | None = None
    example: NetworkResult | None = field(default=None, repr=False)
    example_targets: Array | None = field(default=None, repr=False)

    @property
    def n_agents(self) -> int:
        return int(self.count.shape[1])

    @property
    def n_targets(self) -> int:
        return int(self.err["pos"].shape[-1])

    @property
    def has_central(self) -> bool:
        return self.central_err is not None

    def window(self, which: Literal["first", "last", "all"]) -> NDArray[np.bool_]:
        """``(E,)``: the executions whose slot time lies in the window."""
        if which == "all":
            return np.ones(self.time.shape, bool)
        if which == "first":
            return self.time <= self.first_fraction * self.duration
        return self.time >= (1.0 - self.last_fraction) * self.duration

    def window_s(self, which: Literal["first", "last"]) -> tuple[float, float]:
        """The window's [from, to] in seconds."""
        if which == "first":
            return 0.0, self.first_fraction * self.duration
        return (1.0 - self.last_fraction) * self.duration, self.duration

    # -- over time ------------------------------------------------------------------------

    def rmse_over_time(self, kind: Kind, central: bool = False,
                       pooled: bool = False) -> Array:
        """RMSE over runs ``(A, E, Nt)`` (``pooled``: over runs and targets, ``(A, E)``)."""
        e = self.central_err[kind] if central else self.err[kind]
        return _rms(e, (0, 3) if pooled else 0)

    def bound_over_time(self, kind: Kind, pooled: bool = False) -> Array:
        """The PCRLB, ``sqrt(mean over runs of bound^2)``, ``(A, E, Nt)`` or pooled over
        targets ``(A, E)``."""
        return _rms(self._bound(kind), (0, 3) if pooled else 0)

    def held_over_time(self, central: bool = False) -> Array:
        """Fraction of runs where each target has a track, ``(A, E, Nt)``."""
        e = self.central_err["pos"] if central else self.err["pos"]
        return (~np.isnan(e)).mean(0)

    def _bound(self, kind: Kind) -> Array:
        return {"pos": self.bound_pos, "vel": self.bound_vel, "rng": self.bound_rng}[kind]

    # -- windows ----------------------------------------------------------------------------

    def window_rmse(self, kind: Kind, which: Literal["first", "last", "all"],
                    central: bool = False, pooled: bool = False) -> Array:
        """RMSE over the runs and the window's executions, per agent and target ``(A, Nt)``
        (``pooled``: over targets too, ``(A,)``)."""
        e = (self.central_err[kind] if central else self.err[kind])[:, :, self.window(which)]
        return _rms(e, (0, 2, 3) if pooled else (0, 2))

    def window_bound(self, kind: Kind, which: Literal["first", "last", "all"],
                     pooled: bool = False) -> Array:
        """The PCRLB's RMS over the runs and the window's executions, ``(A, Nt)`` or
        ``(A,)``."""
        b = self._bound(kind)[:, :, self.window(which)]
        return _rms(b, (0, 2, 3) if pooled else (0, 2))


def run_network_mc(scenario, runs: int | None = None, seed: int | None = None,
                   steering: bool | None = None,
                   progress: Callable[[float, int], None] | None = None,
                   keep_example: bool = True,
                   agents: Literal["inprocess", "processes"] = "inprocess",
                   loss: float | None = None,
                   delay: float = 0.0,
                   outages: Sequence[tuple[int, float, float | None]] = (),
                   deployment: Deployment | None = None,
                   block: int = NETWORK_BLOCK,
                   workers: int | None = None,
                   scheduler: str | None = None,
                   ) -> NetworkMonteCarlo:
    """Runs 0 .. runs-1 of a ``scenario.network.NetworkScenario`` (module docstring);
    ``runs``, ``seed``, ``steering`` and ``loss`` override the file's; ``progress(done,
    runs)`` after every block; ``keep_example`` keeps run 0's ``NetworkResult`` for the
    pictures. ``agents``: "inprocess" (``run_network``, the default) or "processes"
    (``network.processes.run_network_processes``: every agent its own OS process, talking
    over ZeroMQ; without loss, delay and outages the same results bit for bit, only slower),
    which also takes ``delay`` (the channel's delivery delay, simulated s), ``outages``
    (``(agent, kill_at, restart_at or None)``, 0-based agent) and ``deployment`` (a
    ``network.processes.Deployment``: the address the environment binds, agents on other
    machines, CURVE: on by default off loopback). In process, ``block`` runs at a time step
    together (``network.inprocess.run_network_block``: the same results bit for bit as one
    at a time, about half the time per run at 25), and each run's wall time is its share of
    its block's. ``workers`` (a local Dask cluster of that many processes) or ``scheduler``
    (a running one's address) send every block to Dask as one task
    (``experiments.executors.execute``); the blocks come back in run order, so the results
    are the same bits whatever the executor and the number of workers."""
    if not (isinstance(block, int) and block >= 1):
        raise ValueError(f"block = {block!r}; expected an integer >= 1 (runs stepped together)")
    if agents == "processes" and (workers or scheduler):
        raise ValueError(f"agents = 'processes' with workers = {workers!r}, scheduler = "
                         f"{scheduler!r}: Dask runs blocks of runs with every agent in the "
                         "worker's process; expected agents='inprocess' with Dask")
    job = _job(scenario, runs, seed, steering, keep_example, agents, loss, delay, outages,
               deployment, block)
    from trackkit.experiments.executors import execute

    nblocks = -(-job.runs // job.size)
    blocks = [b for chunk in execute(_run_block, job, [[b] for b in range(nblocks)],
                                     lambda t: len(job.block_runs(t[0])), job.runs,
                                     workers=workers, scheduler=scheduler, progress=progress)
              for b in chunk]
    example = next((b.example for b in blocks if b.example is not None), (None, None))
    return _stacked(scenario, [s for b in blocks for s in b.scores], seed=job.seed,
                    steering=job.options["steering"],
                    recovered=np.array([r for b in blocks for r in b.recovered], float)
                    .reshape(job.runs, len(outages)),
                    wall=np.concatenate([b.wall for b in blocks]), loss=job.options["loss"],
                    delay=float(delay), outages=tuple(outages), curve=blocks[-1].curve,
                    refused=np.array([n for b in blocks for n in b.refused], np.int64),
                    example=example[0], example_targets=example[1])


@dataclass(frozen=True)
class _Job:
    """What every block of one network Monte Carlo needs (sent once to each Dask worker):
    the scenario, the run count, the seed, the block size, the agents' initial states,
    ``runner``'s keywords and the prior of the bound."""

    scenario: NetworkScenario
    runs: int
    seed: int
    size: int
    states: Array
    runner: Callable[..., NetworkResult]
    options: dict
    prior: Array
    keep_example: bool

    def block_runs(self, b: int) -> list[int]:
        """The runs of block ``b``: fixed by the block size alone."""
        return list(range(b * self.size, min(self.runs, (b + 1) * self.size)))


@dataclass
class _Block:
    """One block's per-run scores, outage recoveries, refused peers and wall times; whether
    CURVE secured it; run 0's result and targets when it holds run 0 and they are kept."""

    scores: list[RunScores]
    recovered: list[list[float]]
    refused: list[int]
    wall: Array
    curve: bool
    example: tuple[NetworkResult, Array] | None


def _job(scenario, runs: int | None, seed: int | None, steering: bool | None,
         keep_example: bool, agents: str, loss: float | None, delay: float,
         outages: Sequence[tuple[int, float, float | None]], deployment: Deployment | None,
         block: int) -> _Job:
    """The checked run count, seed and options of ``run_network_mc``."""
    runner, extra = _runner(agents, delay, outages, deployment)
    runs = scenario.run.runs if runs is None else int(runs)
    seed = scenario.run.seed if seed is None else int(seed)
    if runs < 1:
        raise ValueError(f"runs = {runs}; expected at least 1")
    if seed < 0:
        raise ValueError(f"seed = {seed}; expected an integer >= 0")
    net, rep = scenario.network, scenario.report
    options = dict(duration=net.duration_s, period=net.period_s, sigma=scenario.sigma_rad(),
                   mr=scenario.meas_range(), cr=scenario.comm_range(),
                   max_delay=net.max_delay_s, q=net.q, settings=_agent_settings(scenario),
                   steering=scenario.settings.steering if steering is None else bool(steering),
                   central=scenario.run.central,
                   loss=net.loss if loss is None else float(loss), **extra)
    prior = np.diag([rep.prior_pos_std_m**2] * 2 + [rep.prior_vel_std_mps**2] * 2)
    return _Job(scenario, runs, seed, block if runner is run_network else 1,
                scenario.agent_states(), runner, options, prior, keep_example)


def _run_block(job: _Job, task: list[int], report: Callable[[float], None] | None
               ) -> list[_Block]:
    """Block ``task[0]`` of ``job``: its runs (stepped together in process), their bounds
    and their scores (one executor task; ``report`` unused: a block reports when done)."""
    t0 = _time.perf_counter()
    runs = job.block_runs(task[0])
    sc, o = job.scenario, job.options
    targets = [sc.target_states(job.seed, r) for r in runs]
    if job.runner is run_network:
        results = run_network_block(job.seed, runs, targets, job.states, **o)
    else:
        results = [job.runner(job.seed, runs[0], targets[0], job.states, **o)]
    bounds = run_bound(results, o["sigma"], o["mr"], job.prior, o["q"])
    scores = [score_run(res, o["sigma"], o["mr"], job.prior, o["q"], sc.report.c_m, b)
              for res, b in zip(results, bounds, strict=True)]
    keep = runs[0] == 0 and job.keep_example
    share = (_time.perf_counter() - t0) / len(runs)
    return [_Block(scores, [list(getattr(res, "recovered", [])) for res in results],
                   [getattr(res, "refused", 0) for res in results],
                   np.full(len(runs), share), getattr(results[-1], "curve", False),
                   (results[0], targets[0]) if keep else None)]


def _runner(agents: str, delay: float, outages: Sequence[tuple[int, float, float | None]],
            deployment: Deployment | None) -> tuple[Callable[..., NetworkResult], dict]:
    """``run_network``, or ``run_network_processes`` with its extra keywords; the options
    that need agents in their own processes are refused in process."""
    d = deployment
    if agents == "inprocess":
        remote = d is not None and (d.host != "127.0.0.1" or d.advertise or d.launch
                                    or d.curve or d.keys is not None)
        if delay != 0.0 or outages or remote:
            host, advertise, launch = ((d.host, d.advertise, d.launch) if d is not None
                                       else ("127.0.0.1", None, None))
            raise ValueError(f"delay = {delay!r}, outages = {list(outages)!r}, host = "
                             f"{host!r}, advertise = {advertise!r}, launch = {launch!r}: a "
                             "channel delay, killing agents, addresses and launchers need "
                             "agents='processes'")
        return run_network, {}
    if agents == "processes":
        from trackkit.network.processes import Deployment, run_network_processes

        return run_network_processes, {"delay": delay, "outages": tuple(outages),
                                       "deployment": Deployment() if d is None else d}
    raise ValueError(f"agents = {agents!r}; expected 'inprocess' or 'processes'")


def _agent_settings(scenario) -> AgentSettings:
    """The agents' settings of a network scenario."""
    from dataclasses import replace

    from trackkit.network.agents import AgentSettings

    settings = AgentSettings(combination=scenario.settings.combination)
    if scenario.settings.q is not None:
        settings = replace(settings, q=scenario.settings.q)
    return settings


def _stacked(scenario, per_run: list[RunScores], **more) -> NetworkMonteCarlo:
    """The per-run scores stacked over the runs, with the scenario's constants and
    ``more`` (the run's other fields)."""
    net, rep = scenario.network, scenario.report
    E = per_run[0].count.shape[1]
    have_c = per_run[0].central_err is not None

    def stack(get) -> np.ndarray:
        return np.stack([get(s) for s in per_run])

    return NetworkMonteCarlo(
        name=scenario.name, runs=len(per_run), duration=net.duration_s,
        period=net.period_s, jitter=net.max_delay_s, first_fraction=rep.first_fraction,
        last_fraction=rep.last_fraction, c=rep.c_m,
        time=net.period_s * np.arange(E) + 0.5 * net.max_delay_s,
        count=stack(lambda s: s.count), gospa=stack(lambda s: s.gospa),
        err={k: stack(lambda s, k=k: s.err[k]) for k in ("pos", "vel", "rng")},
        central_count=stack(lambda s: s.central_count) if have_c else None,
        central_gospa=stack(lambda s: s.central_gospa) if have_c else None,
        central_err=({k: stack(lambda s, k=k: s.central_err[k]) for k in ("pos", "vel", "rng")}
                     if have_c else None),
        central_held_final=(np.array([s.central_held_final for s in per_run])
                            if have_c else None),
        bound_pos=stack(lambda s: s.bound_pos), bound_vel=stack(lambda s: s.bound_vel),
        bound_rng=stack(lambda s: s.bound_rng),
        held_final=stack(lambda s: s.held_final),
        final_range=stack(lambda s: s.final_range), spacing=stack(lambda s: s.spacing),
        sent=np.array([s.sent for s in per_run], np.int64),
        delivered=np.array([s.delivered for s in per_run], np.int64),
        lost=np.array([s.lost for s in per_run], np.int64),
        late=np.array([s.late for s in per_run], np.int64),
        seconds=np.array([s.seconds for s in per_run]), **more,
    )
