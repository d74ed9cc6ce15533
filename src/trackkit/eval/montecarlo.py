"""Monte Carlo comparison of filters on a scenario: simulate, estimate, evaluate, streamed.

The runs are cut into fixed blocks (``scenario.run.block`` runs each). A block is simulated
and filtered as one batch; its statistics are accumulated exactly (``MonteCarloMetrics``) and
its PCRLB information sums are added in block order. Run r always draws from child r of
``SeedSequence(seed)`` and always sits in the same block, so the numbers are identical whether
the blocks are computed in one process, in other chunkings, or on Dask workers.

Per block and run, the random draws come in a fixed order: the prior offset (n), the process
noise (T x n), the measurement noise (T x m) and the detection draws (T), so every filter sees
the same truth, measurements and prior offset.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.eval.crlb import PCRLB, rmse_bound
from trackkit.eval.matching import MatchingMetrics, measurement_noise_rms, noise_in_use
from trackkit.eval.metrics import MonteCarloMetrics
from trackkit.eval.results import Example, FilterResult, MonteCarloResult
from trackkit.scenario.build import Plan, compile_scenario
from trackkit.scenario.schema import Scenario
from trackkit.sim.kinematics import step as platform_step

Array = NDArray[np.float64]

__all__ = ["run_scenario", "run_block", "simulate_block", "combine", "BlockResult"]

UNITS = {"position": "m", "velocity": "m/s", "speed": "m/s", "course": "rad", "x": "m",
         "y": "m", "z": "m", "vx": "m/s", "vy": "m/s", "vz": "m/s", "x1": "-", "x2": "-",
         "x3": "-", "frequency": "Hz", "bearing": "rad"}


@lru_cache(maxsize=8)
def _plan_for(scenario_json: str) -> Plan:
    return compile_scenario(Scenario.model_validate_json(scenario_json))


def plan_of(scenario: Scenario) -> Plan:
    """The compiled plan, cached per process (Dask workers compile once per scenario)."""
    return _plan_for(scenario.model_dump_json())


# --- error groups -------------------------------------------------------------------------


def _speed_error(dim: int):
    def err(truth: Array, mean: Array) -> Array:
        vt = np.linalg.norm(truth[..., dim:dim + 2], axis=-1)
        ve = np.linalg.norm(mean[..., dim:dim + 2], axis=-1)
        return (vt - ve)[..., None]
    return err


def _course_error(dim: int):
    def err(truth: Array, mean: Array) -> Array:
        ct = np.arctan2(truth[..., dim], truth[..., dim + 1])
        ce = np.arctan2(mean[..., dim], mean[..., dim + 1])
        return wrap(ct - ce)[..., None]
    return err


class BearingError:
    """Error of the bearing from the first observer to the target, wrapped (rad). The
    observer's position at the current step is set by the engine before each use."""

    def __init__(self) -> None:
        self.origin = np.zeros(2)

    def __call__(self, truth: Array, mean: Array) -> Array:
        dt_, de = truth[..., :2] - self.origin, mean[..., :2] - self.origin
        bt = np.arctan2(dt_[..., 0], dt_[..., 1])
        be = np.arctan2(de[..., 0], de[..., 1])
        return wrap(bt - be)[..., None]


def groups_for(plan: Plan) -> dict:
    d = plan.dim
    table = {
        "position": list(range(d)), "velocity": list(range(d, 2 * d)),
        "x": [0], "y": [1], "z": [2], "vx": [d], "vy": [d + 1], "vz": [2 * d - 1],
        "x1": [0], "x2": [1], "x3": [2], "frequency": [2 * d],
        "speed": _speed_error(d), "course": _course_error(d), "bearing": BearingError(),
    }
    out = {}
    for g in plan.scenario.report.groups:
        lacks = (g in ("z", "vz") and d == 2 or g == "frequency" and plan.n <= 2 * d
                 or g.startswith("x") and g[1:].isdigit() and int(g[1:]) > plan.n)
        if lacks:
            raise ValueError(f"report.groups has {g!r}, which this scenario's state lacks")
        out[g] = table[g]
    return out


def _derived_gradient(group: str, dim: int, n: int, x: Array, origin: Array) -> Array:
    """Gradient of speed, course or bearing (from ``origin``) at true states ``x`` (runs, n)."""
    g = np.zeros(x.shape)
    if group == "bearing":
        u, v = x[..., 0] - origin[0], x[..., 1] - origin[1]
        r2 = u * u + v * v
        g[..., 0], g[..., 1] = v / r2, -u / r2
        return g
    vx, vy = x[..., dim], x[..., dim + 1]
    v2 = np.maximum(vx * vx + vy * vy, 1e-300)
    if group == "speed":
        g[..., dim], g[..., dim + 1] = vx / np.sqrt(v2), vy / np.sqrt(v2)
    else:  # course = atan2(vx, vy)
        g[..., dim], g[..., dim + 1] = vy / v2, -vx / v2
    return g


# --- simulation ---------------------------------------------------------------------------


@dataclass
class BlockData:
    truth: Array  # (T + 1, B, n)
    z: Array  # (T, B, m)
    prior_offset: Array  # (B, n) standard-normal draws


def simulate_block(plan: Plan, r0: int, r1: int) -> BlockData:
    """Truth and measurements for runs r0..r1-1, batched, from each run's own generator."""
    s = plan.scenario
    T, n, d = plan.steps, plan.n, plan.dim
    children = np.random.SeedSequence(s.run.seed).spawn(s.run.runs)[r0:r1]
    B = r1 - r0
    m = plan.sensors[0].dim_z
    u0 = np.empty((B, n))
    w = np.empty((T, B, n))
    e = np.empty((T, B, m))
    det = np.empty((T, B))
    for i, child in enumerate(children):
        g = np.random.default_rng(child)
        u0[i] = g.standard_normal(n)
        w[:, i] = g.standard_normal((T, n))
        e[:, i] = g.standard_normal((T, m))
        det[:, i] = g.random(T)
    truth = np.empty((T + 1, B, n))
    truth[0] = plan.x0
    kin = 2 * d
    for k in range(T):
        dt = plan.times[k + 1] - plan.times[k]
        L = _noise_factor(np.asarray(plan.truth_motion.noise(truth[k], dt)))
        if s.linear_system:
            nxt = plan.truth_motion.f(truth[k], dt)
        else:
            nxt = truth[k].copy()
            nxt[:, :kin] = platform_step(truth[k][:, :kin], plan.times[k], dt,
                                         plan.target_legs, d)
        truth[k + 1] = nxt + w[k] @ L.T
    z = np.empty((T, B, m))
    for k in range(T):
        sensor = plan.sensors[k]
        R = sensor.noise
        z[k] = sensor.h(truth[k + 1]) + e[k] @ np.linalg.cholesky(R).T
        ang = np.asarray(sensor.angular)
        z[k][:, ang] = wrap(z[k][:, ang])
    if plan.p_detect < 1.0:
        z[det >= plan.p_detect] = np.nan
    return BlockData(truth, z, u0)


def _noise_factor(Q: Array) -> Array:
    """A factor L with L L^T = Q: Cholesky, or for a singular Q (deterministic components,
    zero process noise) the scaled eigenvectors; no jitter is added to the noise."""
    try:
        return np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(Q)
        return vecs * np.sqrt(np.clip(vals, 0, None))


# --- estimation and evaluation of one block -----------------------------------------------


@dataclass
class BlockResult:
    """Everything a block contributes; combined in block order."""

    block: int
    runs: int
    metrics: dict[str, MonteCarloMetrics]
    seconds: dict[str, float]
    info: Array  # (T, n, n) sum over runs of p_d H^T R^-1 H at the truths
    grads: dict[str, Array]  # derived group -> (T, n) sum over runs of the gradient
    example: Example | None = None
    matching: dict[str, dict[str, Array]] | None = None  # filter -> per-run J2, J3, J4
    j1: Array | None = None  # (runs, m) per-run raw noise RMS


def run_block(scenario: Scenario, block: int) -> BlockResult:
    """Simulate, filter and evaluate block ``block`` of the scenario's runs."""
    plan = plan_of(scenario)
    s = plan.scenario
    r0 = block * s.run.block
    r1 = min(s.run.runs, r0 + s.run.block)
    if not 0 <= r0 < r1:
        raise ValueError(f"block {block} is outside the {s.run.runs} runs")
    data = simulate_block(plan, r0, r1)
    T, n, d = plan.steps, plan.n, plan.dim
    groups = groups_for(plan)
    metrics, seconds = {}, {}
    example = None
    keep = r0 == 0
    est_hist: dict[str, tuple[Array, Array]] = {}
    matching = {} if s.report.matching else None
    logs = {}
    m = plan.sensors[0].dim_z
    for i, (name, f, motion, (mean0, P0)) in enumerate(zip(
            plan.filter_names, plan.filters, plan.filter_motions, plan.priors, strict=True)):
        acc = MonteCarloMetrics(groups=groups)
        match = None if matching is None else MatchingMetrics(r1 - r0, n, m, T, log=keep)
        L0 = np.linalg.cholesky(P0)
        m0 = (data.truth[0] + data.prior_offset @ L0.T) if mean0 is None else (
            np.broadcast_to(mean0, (r1 - r0, n)).copy())
        b = f.init(Gaussian(m0, np.broadcast_to(P0, (r1 - r0, n, n)).copy()))
        elapsed = 0.0
        if keep:
            hm, hP = np.empty((T, n)), np.empty((T, n, n))
        for k in range(T):
            sensor = plan.filter_sensor(i, k)
            t0 = time.perf_counter()
            b = f.predict(b, motion, plan.times[k + 1] - plan.times[k])
            R_used = None if match is None else noise_in_use(b, sensor.noise)
            b, innov = f.update(b, data.z[k], sensor)
            elapsed += time.perf_counter() - t0
            g = f.estimate(b)
            if "bearing" in groups:
                groups["bearing"].origin = plan.observer_states[0, k + 1, :2]
            acc.add(k, data.truth[k + 1], g, innov)
            if match is not None:
                match.add(k, data.truth[k + 1], g.mean, innov, R_used, plan.sensors[k])
            if keep:
                hm[k], hP[k] = g.mean[0], g.cov[0]
        metrics[name], seconds[name] = acc, elapsed
        if match is not None:
            matching[name] = match.per_run(s.report.dom_alpha)
            if keep:
                logs[name] = match.logs
        if keep:
            est_hist[name] = (hm, hP)
    # PCRLB ingredients: measurement information and derived-group gradients, summed over runs
    info = np.empty((T, n, n))
    for k in range(T):
        sensor = plan.sensors[k]
        H = np.broadcast_to(sensor.jacobian(data.truth[k + 1]), (r1 - r0, sensor.dim_z, n))
        RinvH = np.linalg.solve(sensor.noise, H)
        info[k] = plan.p_detect * np.einsum("bmi,bmj->ij", H, RinvH)
    grads = {g: np.stack([_derived_gradient(g, d, n, data.truth[k + 1],
                                            plan.observer_states[0, k + 1, :2]).sum(0)
                          for k in range(T)])
             for g in groups if g in ("speed", "course", "bearing")}
    if keep:
        example = Example(times=plan.times[1:], truth=data.truth[1:, 0],
                          observer=plan.observer_states[0, 1:, :d], estimates=est_hist,
                          measurements=data.z[:, 0], logs=logs)
    j1 = None
    if matching is not None:
        z_true = np.stack([plan.sensors[k].h(data.truth[k + 1]) for k in range(T)])
        j1 = measurement_noise_rms(data.z, z_true, plan.sensors[0])
    return BlockResult(block, r1 - r0, metrics, seconds, info, grads, example, matching, j1)


def run_blocks(scenario: Scenario, blocks: list[int]) -> list[BlockResult]:
    """A chunk of blocks (one executor task)."""
    return [run_block(scenario, b) for b in blocks]


# --- combining blocks ---------------------------------------------------------------------


def _bound_series(plan: Plan, info: Array, runs: int) -> Array:
    """PCRLB per step from the run-averaged measurement information (covariance form)."""
    bound = PCRLB(plan.prior_cov)
    out = np.empty((plan.steps, plan.n, plan.n))
    for k in range(plan.steps):
        dt = plan.times[k + 1] - plan.times[k]
        bound.predict(plan.truth_motion, plan.x0[None], dt)
        bound.add_information(info[k] / runs)
        out[k] = bound.bound
    return out


def combine(scenario: Scenario, parts: list[BlockResult]) -> MonteCarloResult:
    """Fold block results in block order into the comparison's result."""
    plan = plan_of(scenario)
    s = plan.scenario
    parts = sorted(parts, key=lambda p: p.block)
    expected = list(range(len(parts)))
    if [p.block for p in parts] != expected or sum(p.runs for p in parts) != s.run.runs:
        raise RuntimeError(f"blocks {[p.block for p in parts]} do not cover the "
                           f"{s.run.runs} runs; refusing to report a partial result")
    runs, T = s.run.runs, plan.steps
    start = int(np.searchsorted(plan.times[1:], s.report.average_from_s - 1e-9))
    info = parts[0].info.copy()
    for p in parts[1:]:
        info += p.info
    bounds = _bound_series(plan, info, runs)
    groups = groups_for(plan)
    pcrlb = {}
    for g, spec in groups.items():
        if callable(spec):
            grad = sum(p.grads[g] for p in parts) / runs  # (T, n)
            pcrlb[g] = np.sqrt(np.einsum("ti,tij,tj->t", grad, bounds, grad))
        else:
            pcrlb[g] = rmse_bound(bounds, spec)
    pcrlb_mean = {g: float(np.sqrt(np.mean(v[start:] ** 2))) for g, v in pcrlb.items()}
    filters = {}
    for name in plan.filter_names:
        acc = parts[0].metrics[name]
        for p in parts[1:]:
            acc = acc.merge(p.metrics[name])
        summ = acc.summary(start)
        filters[name] = FilterResult(
            name=name,
            rmse={g: acc.rmse(g) for g in groups},
            rmse_mean={g: acc.rmse_time_average(g, start) for g in groups},
            nees=acc.nees(), nis=acc.nis(),
            nees_bounds=acc.bounds("nees"), nis_bounds=acc.bounds("nis"),
            anees=summ["nees_mean"], anis=summ["nis_mean"],
            nees_in_bounds=summ["nees_inside"], nis_in_bounds=summ["nis_inside"],
            diverged=int(summ["diverged"]),
            seconds_per_step=sum(p.seconds[name] for p in parts) / (runs * T),
            matching={} if parts[0].matching is None else {
                k: np.concatenate([p.matching[name][k] for p in parts])
                for k in parts[0].matching[name]},
        )
    notes = list(s.notes)
    if {"speed", "course", "bearing"} & set(groups):
        notes.append("The speed, course and bearing bounds propagate the state bound to first "
                     "order (G B G^T with G the mean gradient over runs). While the uncertainty "
                     "is large compared with the speed or range this is not a true lower "
                     "bound, and filters can fall below it early in a track.")
    if s.target.legs:
        notes.append("The PCRLB uses the target's stated motion model and process noise; the "
                     "scripted manoeuvres are not in that model, so during them the bound is "
                     "indicative only.")
    return MonteCarloResult(
        scenario=s.name, description=s.description, runs=runs, seed=s.run.seed, steps=T,
        dt=plan.dt, times=plan.times[1:], start=start,
        groups={g: UNITS[g] for g in groups}, filters=filters, pcrlb=pcrlb,
        pcrlb_mean=pcrlb_mean, example=parts[0].example, notes=notes,
        j1=None if parts[0].j1 is None else np.concatenate([p.j1 for p in parts]),
        dom_alpha=s.report.dom_alpha,
    )


# --- the public entry point ---------------------------------------------------------------


def with_run(scenario: Scenario, runs: int | None, seed: int | None) -> Scenario:
    """The scenario with ``run.runs`` / ``run.seed`` replaced (validated again)."""
    run = scenario.run.model_copy(update={k: v for k, v in
                                          (("runs", runs), ("seed", seed)) if v is not None})
    data = scenario.model_dump()
    data["run"] = run.model_dump()
    return Scenario.model_validate(data)


def run_scenario(
    scenario: Scenario,
    runs: int | None = None,
    seed: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> MonteCarloResult:
    """Run the scenario's comparison and return its result.

    ``workers`` > 0 or a ``scheduler`` address sends chunks of blocks to Dask; ``chunk`` is
    the runs per task (rounded up to whole blocks). The same seed gives the same numbers on
    every executor and chunking (timings aside).
    """
    from trackkit.eval.executors import execute
    from trackkit.eval.tuning import tune_scenario

    if runs is not None and runs < 1:
        raise ValueError(f"runs = {runs}; expected at least 1")
    if seed is not None and seed < 0:
        raise ValueError(f"seed = {seed}; expected a non-negative integer")
    s = with_run(scenario, runs, seed)
    plan_of(s)  # compile (and so validate models) before any work is sent out
    s, tuning = tune_scenario(s)  # fuzzy systems are tuned once, before the runs
    nblocks = -(-s.run.runs // s.run.block)
    per_task = max(1, -(-(chunk or s.run.block) // s.run.block))
    if chunk is None and (workers or scheduler):
        per_task = max(1, nblocks // (4 * max(workers or 1, 1)))
    tasks = [list(range(i, min(nblocks, i + per_task))) for i in range(0, nblocks, per_task)]
    sizes = [sum(min(s.run.runs, (b + 1) * s.run.block) - b * s.run.block for b in t)
             for t in tasks]
    parts = execute(run_blocks, s, tasks, sizes, workers=workers, scheduler=scheduler,
                    progress=progress)
    result = combine(s, [p for chunk_parts in parts for p in chunk_parts])
    result.tuning = tuning
    return result
