"""An in-process network run of the agents of Jalalipoor and Kardehi Moghaddam (2021)
(:mod:`trackkit.network.agents`).

One run, one multi-target problem:

* truth and execution schedule from ``sim.sensor_network.simulate_network`` (seed, run): the target
  states at every execution, the execution times and the standard-normal bearing noise
  (the same draws as ``sim.sensor_network.schedule``);
* the agents execute one at a time in time order (ties: lower agent index first). At its
  execution the agent is moved from its previous execution on its last commanded course
  (``steering.move``; without steering, the straight line ``p0 + t v`` exactly, so that the
  bearings equal ``simulate_network``'s bit for bit), takes its bearings with ``bearings_at``
  at that position, runs ``Agent.step``, and broadcasts;
* the message is delivered at once to every agent linked to the sender in the disk graph of
  the agents' positions at that time (the others extrapolated on their current commands),
  each delivery lost with probability ``loss`` (optional; default none). Delayed delivery is
  not implemented;
* optionally a centralised reference (``central``):

  - ``True`` or ``"filter"``: :func:`trackkit.network.central.central_fusion`, one EKF (or
    UKF, CKF, IEKF: ``central_settings``) per target fed every agent's bearings in time
    order, with *ideal association* (each bearing's true target label), started from a
    composite measurement of its first bearings. It measures fusion, not association, and
    sits at the centralised PCRLB on the baseline-like geometry (tests/network/
    test_central.py). It runs after the agents, on the bearings they actually took (the
    steered positions included), and its q is the truth's ``q`` unless
    ``central_settings.q`` says otherwise;
  - ``"agent"``: the earlier reference, one more agent program (same settings, no
    neighbours, no combination) that receives every agent's bearings at each execution and
    runs after it. It has to associate and batch like the agents, and with 6-bearing
    composites it came out *worse* than the agents: kept for comparison only.

Randomness: the simulation's draws are ``simulate_network``'s (children 0..2 of
``SeedSequence(seed, spawn_key=(run,))``); the agents' initiation streams are
``SeedSequence(seed, spawn_key=(run, 3, a))`` and message loss ``(run, 4)``, so a run
depends on (seed, run) alone.

Recorded per agent and execution: the confirmed tracks (ids, states, covariances), the
true target states at that time, and the agent's position (:class:`Trace`).
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.network.agents import (
    Agent,
    AgentSettings,
    Call,
    Payload,
    Program,
    StepReport,
    empty_bearings,
    own_bearings,
    run_inline,
)
from trackkit.network.central import CentralFusion, CentralSettings, central_fusion
from trackkit.network.lockstep import drive
from trackkit.network.steering import TURN_RATE, Steering, move
from trackkit.network.tracks import Message
from trackkit.sim.sensor_network import (
    NetworkRun,
    bearings_at,
    disk_graph,
    schedule,
    simulate_network,
)

__all__ = ["Trace", "NetworkResult", "NetworkRunState", "run_network", "run_network_block",
           "check_loss"]

Array = NDArray[np.float64]


class Trace(NamedTuple):
    """One tracker's output over its E executions.

    ``time (E,)``; the confirmed tracks of execution e are rows ``offsets[e]:offsets[e + 1]``
    of ``ids (N,)``, ``mean (N, 4)``, ``cov (N, 4, 4)``; ``truth (E, Nt, 4)`` the true
    target states at each execution; ``position (E, 2)`` the agent's position (nan for the
    centralised node); ``reports``: the :class:`StepReport` of each execution (for the
    centralised filter: ``associated`` = the bearings it took, ``started`` = the targets
    whose filter started there, the rest 0).
    """

    time: Array
    offsets: NDArray[np.int64]
    ids: NDArray[np.int64]
    mean: Array
    cov: Array
    truth: Array
    position: Array
    reports: list[StepReport]


class NetworkResult(NamedTuple):
    """``agents``: one :class:`Trace` per agent; ``central``: the centralised reference's
    (None when not asked); ``sim``: the ``NetworkRun`` (one run); ``sent``, ``delivered``,
    ``lost``: message counts; ``seconds``: wall-clock time of the run (agents and
    reference); ``fusion``: the centralised filter's full output (a one-run
    :class:`~trackkit.network.central.CentralFusion`, for its NEES) when ``central`` is the
    filter, else None; ``spacing``: the least and the greatest distance between two agents
    over all execution instants, each as a fraction of the pair's communication range
    (the smaller of the two; nan where every range is unlimited); ``late``: delivered
    messages that missed at least one of the receiver's executions they would have reached
    without the channel's delay (0 in process, where delivery is immediate)."""

    agents: list[Trace]
    central: Trace | None
    sim: NetworkRun
    sent: int
    delivered: int
    lost: int
    seconds: float
    fusion: CentralFusion | None = None
    spacing: tuple[float, float] = (math.nan, math.nan)
    late: int = 0


class Spacing:
    """The least and greatest agent-pair distance over the execution instants, as a
    fraction of the pair's communication range (``NetworkResult.spacing``)."""

    def __init__(self, cr: Array) -> None:
        i, j = np.triu_indices(cr.shape[0], 1)
        self.i, self.j = i, j
        self.range = np.minimum(cr[i], cr[j])
        self.finite = np.isfinite(self.range)
        self.low, self.high = math.inf, -math.inf

    def add(self, where: Array) -> None:
        if not self.finite.any():
            return
        d = np.hypot(*(where[self.i] - where[self.j]).T)[self.finite] / self.range[self.finite]
        self.low, self.high = min(self.low, float(d.min())), max(self.high, float(d.max()))

    @property
    def span(self) -> tuple[float, float]:
        return (self.low, self.high) if self.finite.any() else (math.nan, math.nan)


class Recorder:
    def __init__(self) -> None:
        self.time: list[float] = []
        self.sizes: list[int] = []
        self.ids: list[Array] = []
        self.mean: list[Array] = []
        self.cov: list[Array] = []
        self.truth: list[Array] = []
        self.position: list[Array] = []
        self.reports: list[StepReport] = []

    def add(self, agent: Agent, truth: Array, position: Array, report: StepReport) -> None:
        c = agent.confirmed()
        self.time.append(agent.time)
        self.sizes.append(c.size)
        self.ids.append(c.ids)
        self.mean.append(c.mean)
        self.cov.append(c.cov)
        self.truth.append(truth)
        self.position.append(position)
        self.reports.append(report)

    def trace(self) -> Trace:
        off = np.concatenate([[0], np.cumsum(self.sizes)]).astype(np.int64)
        return Trace(np.asarray(self.time), off,
                     np.concatenate(self.ids) if self.ids else np.zeros(0, np.int64),
                     np.concatenate(self.mean) if self.mean else np.zeros((0, 4)),
                     np.concatenate(self.cov) if self.cov else np.zeros((0, 4, 4)),
                     np.asarray(self.truth), np.asarray(self.position), self.reports)


def check_loss(loss: float, name: str = "loss =") -> float:
    """``loss``, a probability that one delivery is lost, in [0, 1); else a ValueError naming
    it as ``name`` (``--loss`` on the command line)."""
    if not 0.0 <= loss < 1.0:
        raise ValueError(f"{name} {loss!r}; expected a probability in [0, 1)")
    return loss


def run_network(
    seed: int,
    run: int,
    targets: ArrayLike,
    agents: ArrayLike,
    *,
    duration: float,
    period: float,
    sigma: ArrayLike,
    mr: ArrayLike = math.inf,
    cr: ArrayLike = math.inf,
    max_delay: float | None = None,
    q: float = 0.0,
    settings: AgentSettings | None = None,
    steering: bool = False,
    central: bool | str = False,
    loss: float = 0.0,
    central_settings: CentralSettings | None = None,
) -> NetworkResult:
    """Run ``run`` of a network of agents (module docstring).

    Args:

        seed, run: the run's randomness comes from (seed, run) alone.
        targets: ``(Nt, 4)`` target states at t = 0; agents: ``(A, 4)`` agent states at
            t = 0 (position, velocity: the initial course and the constant speed).
        duration, period, max_delay, q: the schedule and truth (``simulate_network``).
        sigma, mr, cr: bearing std (rad), measurement and communication ranges (m), scalar
            or per agent.
        settings: the agents' ``AgentSettings`` (their ``comm_range`` and ``meas_range`` are
            set per agent from cr and mr); with ``steering`` True, ``settings.steering``
            (default ``Steering()``) steers the agents, else they run straight.
        central: also run a centralised reference: False (none), True or "filter" (the
            centralised filter with ideal association), "agent" (the earlier agent-program
            reference); module docstring.
        loss: probability that one delivery is lost (0 <= loss < 1).
        central_settings: the centralised filter's ``CentralSettings``.
    """
    one = NetworkRunState(seed, run, targets, agents, duration=duration, period=period,
                          sigma=sigma, mr=mr, cr=cr, max_delay=max_delay, q=q,
                          settings=settings, steering=steering, central=central, loss=loss,
                          central_settings=central_settings)
    t0 = _time.perf_counter()
    for k in range(one.executions):
        run_inline(one.execution(k))
    return one.result(t0)


def run_network_block(seed: int, runs: Sequence[int], targets: Sequence[ArrayLike],
                      agents: ArrayLike, **options: Any) -> list[NetworkResult]:
    """Runs ``runs`` of a network (``targets[i]`` the targets of ``runs[i]``) stepped
    together, execution by execution: the agents' kernel calls of all runs at one execution
    run as one batched call (:func:`trackkit.network.lockstep.drive`). Each result equals
    ``run_network(seed, runs[i], targets[i], agents, **options)`` bit for bit; its
    ``seconds`` is the block's wall time shared equally among its runs."""
    if len(targets) != len(runs):
        raise ValueError(f"{len(targets)} target sets for {len(runs)} runs; expected one "
                         "per run")
    states = [NetworkRunState(seed, int(r), tg, agents, **options)
              for r, tg in zip(runs, targets, strict=True)]
    if not states:
        return []
    t0 = _time.perf_counter()
    for k in range(states[0].executions):
        drive([one.execution(k) for one in states])
    fusion: list[CentralFusion | None] = [None] * len(states)
    first = states[0]
    if first.w.central == "filter":  # the centralised filter of every run in one batch
        both = central_fusion(np.stack([one.Zc for one in states]),
                              np.stack([one.w.times for one in states]),
                              np.stack([one.Sc for one in states]), first.w.sig, q=first.q,
                              settings=first.central_settings)
        fusion = [CentralFusion(*(a[i:i + 1] for a in both)) for i in range(len(states))]
    share = (_time.perf_counter() - t0) / len(states)
    return [one.result(_time.perf_counter() - share, f) for one, f in zip(states, fusion,
                                                                         strict=True)]


class NetworkRunState:
    """One in-process network run between its executions (``run_network``'s arguments):
    the world, the agents, their motion and recorders, the message counts. ``execution(k)``
    is the k-th execution in time order as a program (its kernel calls yielded as
    :class:`~trackkit.network.agents.Call`); ``result`` the run's :class:`NetworkResult`
    after the last one."""

    def __init__(self, seed: int, run: int, targets: ArrayLike, agents: ArrayLike, *,
                 duration: float, period: float, sigma: ArrayLike, mr: ArrayLike = math.inf,
                 cr: ArrayLike = math.inf, max_delay: float | None = None, q: float = 0.0,
                 settings: AgentSettings | None = None, steering: bool = False,
                 central: bool | str = False, loss: float = 0.0,
                 central_settings: CentralSettings | None = None) -> None:
        check_loss(loss)
        w = build_world(seed, run, targets, agents, duration=duration, period=period,
                        sigma=sigma, mr=mr, cr=cr, max_delay=max_delay, q=q,
                        settings=settings, steering=steering, central=central)
        A, E = w.times.shape
        self.w, self.period, self.steering, self.loss = w, period, steering, loss
        self.q, self.central_settings = q, central_settings
        self.nodes = [Agent(a, w.settings[a], np.random.default_rng(np.random.SeedSequence(
            seed, spawn_key=(run, 3, a)))) for a in range(A)]
        self.motion = Motion(w.ag0, steering)
        self.rec = [Recorder() for _ in range(A)]
        self.rec_c = Recorder() if w.hub is not None else None
        # the bearings as taken, labelled by target, for the centralised filter
        self.Zc = np.full((A, E, w.Nt), np.nan)
        self.Sc = np.zeros((A, E, 2))
        self.sent = self.delivered = self.lost = 0
        self.spacing = Spacing(w.CR)

    @property
    def executions(self) -> int:
        """The run's number of executions (every agent's, in time order)."""
        return len(self.w.order)

    def execution(self, k: int) -> Program:
        """The k-th execution: move the agent, take its bearings, run its program, steer,
        deliver its message over the disk graph (and to the "agent" reference's hub)."""
        w, motion = self.w, self.motion
        a, e = w.order[k]
        t = float(w.times[a, e])
        here, vel = yield from motion.at(a, t)
        truth = w.sim.target_at_bearing[0, a, e]
        z, _ = yield Call(bearings_at, (here, truth, w.noise[a, e], w.sig[a], w.MR[a]))
        self.Zc[a, e], self.Sc[a, e] = z, here
        own = own_bearings(z, t, here, float(w.sig[a]), a)
        msg, rep = yield from self.nodes[a].program(t, own, here, vel)
        self.rec[a].add(self.nodes[a], truth, here, rep)
        if self.steering:
            E = w.times.shape[1]
            dt_next = float(w.times[a, e + 1] - t) if e + 1 < E else self.period
            motion.cmd[a] = yield from self.nodes[a].steering_program(
                here, float(motion.course[a]), float(motion.speed[a]), dt_next)

        # delivery over the disk graph at time t
        where = yield from motion.where(t)
        self.spacing.add(where)
        links = disk_graph(where, w.CR)[a]
        for b in np.flatnonzero(links).tolist():
            self.sent += 1
            if self.loss > 0 and w.lose.random() < self.loss:
                self.lost += 1
                continue
            self.nodes[b].receive(msg)
            self.delivered += 1
        if self.rec_c is not None:
            yield from relay_to_hub(w.hub, self.rec_c, msg.payload, t, truth)

    def result(self, t0: float, fusion: CentralFusion | None = None) -> NetworkResult:
        """The run's result after its last execution (``seconds`` counted from ``t0``;
        ``fusion``: the centralised filter's output for this run, when computed already)."""
        trace_c, fusion = central_trace(self.w, self.rec_c, self.Zc, self.Sc, self.q,
                                        self.central_settings, fusion)
        seconds = _time.perf_counter() - t0
        return NetworkResult([r.trace() for r in self.rec], trace_c, self.w.sim, self.sent,
                             self.delivered, self.lost, seconds, fusion, self.spacing.span)


# --------------------------------------------------------------------------------------------
# What the in-process run and the process run (trackkit.network.processes) share


class World(NamedTuple):
    """A network run's fixed parts, built from its arguments by :func:`build_world`: the
    simulation, the execution times ``(A, E)`` and bearing noise ``(A, E, Nt)``, each
    agent's bearing std, ranges and settings, the "agent" reference's hub (or None), the
    message-loss stream, and the executions ``(a, e)`` in time order."""

    central: bool | str
    ag0: Array
    sim: NetworkRun
    times: Array
    noise: Array
    sig: Array
    MR: Array
    CR: Array
    settings: list[AgentSettings]
    hub: Agent | None
    lose: np.random.Generator
    order: list[tuple[int, int]]

    @property
    def Nt(self) -> int:
        return self.sim.target_at_bearing.shape[-2]


def build_world(seed: int, run: int, targets: ArrayLike, agents: ArrayLike, *,
                duration: float, period: float, sigma: ArrayLike, mr: ArrayLike, cr: ArrayLike,
                max_delay: float | None, q: float, settings: AgentSettings | None,
                steering: bool, central: bool | str) -> World:
    """Check the shared arguments of a network run and build its :class:`World`."""
    if central is True:
        central = "filter"
    if central not in (False, "filter", "agent"):
        raise ValueError(f"central = {central!r}; expected False, True, 'filter' or 'agent'")
    base = AgentSettings() if settings is None else settings
    if steering and base.steering is None:
        base = replace(base, steering=Steering())
    if not steering and base.steering is not None:
        base = replace(base, steering=None)
    ag0 = np.asarray(agents, dtype=float)
    if ag0.ndim != 2 or ag0.shape[1] != 4:
        raise ValueError(f"agents has shape {ag0.shape}; expected (A, 4) states [x, y, vx, vy]")
    A = ag0.shape[0]
    sim = simulate_network(seed, 1, targets, ag0, duration=duration, period=period,
                           sigma=sigma, mr=mr, max_delay=max_delay, q=q, first_run=run)
    Nt = sim.target_at_bearing.shape[-2]
    sch = schedule(seed, 1, A, Nt, duration, period, max_delay, first_run=run)
    times, noise = sch.time[0], sch.noise[0]  # (A, E), (A, E, Nt)
    E = times.shape[1]
    sig = np.broadcast_to(np.asarray(sigma, dtype=float), (A,))
    MR = np.broadcast_to(np.asarray(mr, dtype=float), (A,))
    CR = np.broadcast_to(np.asarray(cr, dtype=float), (A,))
    per_agent = [replace(base, comm_range=float(CR[a]), meas_range=float(MR[a]),
                         r_max=min(base.r_max, float(MR[a]))) for a in range(A)]
    hub = None
    if central == "agent":
        s = replace(base, combine_neighbours=False, steering=None,
                    r_max=min(base.r_max, float(MR.max())))
        hub = Agent(A, s, np.random.default_rng(np.random.SeedSequence(seed,
                                                                       spawn_key=(run, 3, A))))
    lose = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, 4)))
    # time order, ties: lower agent index first
    order = np.lexsort((np.repeat(np.arange(A), E), times.ravel()))
    return World(central, ag0, sim, times, noise, sig, MR, CR, per_agent, hub, lose,
                  [divmod(int(f), E) for f in order])


class Motion:
    """The agents' kinematics between executions: with steering, each agent is moved from its
    previous execution on its last commanded course (``steering.move``); without, the
    straight line ``p0 + t v`` exactly (so the bearings equal ``simulate_network``'s)."""

    def __init__(self, ag0: Array, steering: bool) -> None:
        self.ag0, self.steering = ag0, steering
        self.pos = ag0[:, :2].copy()
        self.speed = np.hypot(ag0[:, 2], ag0[:, 3])
        self.course = np.arctan2(ag0[:, 2], ag0[:, 3])
        self.cmd = self.course.copy()
        self.last_t = np.zeros(len(ag0))

    def at(self, a: int, t: float) -> Program:
        """Agent a's position and velocity at its execution time t (moving it there), as a
        program (its move a :class:`~trackkit.network.agents.Call`)."""
        if self.steering:
            p, c = yield Call(move, (self.pos[a], self.course[a], self.speed[a], self.cmd[a],
                                     t - self.last_t[a], TURN_RATE, False))
            self.pos[a], self.course[a], self.last_t[a] = p, float(c), t
            here = self.pos[a].copy()
        else:
            here = self.ag0[a, :2] + t * self.ag0[a, 2:]
        course = self.course[a]
        return here, self.speed[a] * np.array([math.sin(course), math.cos(course)])

    def where(self, t: float) -> Program:
        """Every agent's position at t, the others extrapolated on their current commands
        (a program, as ``at``)."""
        if not self.steering:
            return self.ag0[:, :2] + t * self.ag0[:, 2:]
        p, _ = yield Call(move, (self.pos, self.course, self.speed, self.cmd, t - self.last_t,
                                 TURN_RATE, False))
        return p


def relay_to_hub(hub: Agent, rec: Recorder, payload: Payload, t: float,
                 truth: Array) -> Program:
    """The "agent" reference: the sender's bearings (not its tracks) to the hub, which then
    executes (a program: :class:`~trackkit.network.agents.Call`)."""
    bare = replace(payload, ids=payload.ids[:0], mean=payload.mean[:0],
                   cov=payload.cov[:0], status=payload.status[:0], lost=payload.lost[:0])
    hub.receive(Message(payload.sender, payload.time, bare))
    _, rep = yield from hub.program(t, empty_bearings())
    rec.add(hub, truth, np.full(2, np.nan), rep)


def central_trace(w: World, rec_c: Recorder | None, Zc: Array, Sc: Array, q: float,
                  central_settings: CentralSettings | None,
                  fusion: CentralFusion | None = None
                  ) -> tuple[Trace | None, CentralFusion | None]:
    """The centralised reference's trace (and the filter's output), after the run;
    ``fusion``: the filter's output when already computed (a block's, one run of it)."""
    if w.central == "filter":
        if fusion is None:
            fusion = central_fusion(Zc[None], w.times[None], Sc[None], w.sig, q=q,
                                    settings=central_settings)
        return _fusion_trace(fusion, w.sim.target_at_bearing[0], Zc), fusion
    return (rec_c.trace() if rec_c else None), None


def _fusion_trace(c: CentralFusion, truth: Array, z: Array) -> Trace:
    """A one-run :class:`CentralFusion` as a :class:`Trace`: one entry per execution (in
    time order), the started targets as confirmed tracks with ids j + 1 (ideal association),
    the truth ``(A, E, Nt, 4)`` at each execution, position nan (a fusion centre)."""
    A, E, Nt = z.shape
    M = A * E
    on = c.started[0]  # (M, Nt)
    order = c.order[0]
    sizes = on.sum(1)
    off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    ids = np.broadcast_to(np.arange(1, Nt + 1, dtype=np.int64), (M, Nt))[on]
    took = (~np.isnan(z.reshape(M, Nt)[order]) & on).sum(1)
    first = np.diff(np.concatenate([np.zeros((1, Nt), bool), on]), axis=0).sum(1)
    reports = [StepReport(int(n), 0, 0, int(f), 0, 0, 0)
               for n, f in zip(took.tolist(), first.tolist(), strict=True)]
    return Trace(c.time[0].copy(), off, ids, c.mean[0][on], c.cov[0][on],
                 truth.reshape(M, Nt, 4)[order], np.full((M, 2), np.nan), reports)
