"""Monte Carlo comparison of filters on a scenario: simulate, estimate, evaluate, streamed.

The runs are cut into fixed blocks (``scenario.run.block`` runs each). A block is simulated
(``trackkit.scenario.simulate``) and filtered as one batch. Its statistics are accumulated as it
streams (``MonteCarloMetrics``, fed a window of steps at a time): each step's terms are summed
in float64 over the block, and only these block totals enter an exact accumulator, so the
blocks merge exactly and in any order. Its PCRLB information sums are added in block order.

What is bit-identical: with the same scenario, seed and block size, every number (timings
aside) on one machine, whatever the executor, the chunking or the number of Dask workers. Run
r always draws from its own generator (``run_rng(seed, r)``) and always sits at the same place
in the same block, a block's float64 totals depend on that block alone (and its windows of
steps on the block size alone), and the exact accumulator's sums do not depend on the order
they are merged in. What agrees only to a tolerance: the same computation on another CPU
(numpy's SIMD loops and the BLAS kernels round differently with AVX2 and AVX-512), and a run
placed in another block or at another position in its block (a vectorised transcendental
function may round an element differently in a loop's body and its tail, and the block totals
are float64 sums). Both are checked to 1e-12 relative on the goldens (tests/goldens), which CI
also runs with numpy's AVX-512 paths and OpenBLAS's AVX-512 kernels disabled.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian, Innovation
from trackkit.eval import metrics as _metrics
from trackkit.eval.covariance_matching import MatchingMetrics, measurement_noise_rms, noise_in_use
from trackkit.eval.crlb import PCRLB, rmse_bound
from trackkit.eval.metrics import MonteCarloMetrics
from trackkit.experiments.results import Example, FilterResult, MonteCarloResult
from trackkit.scenario.build import Plan, compile_scenario
from trackkit.scenario.schema import Scenario, window_steps
from trackkit.scenario.simulate import BlockData, simulate_block

Array = NDArray[np.float64]

#: steps of one filter between progress reports inside a block (a report costs a callback)
PROGRESS_STEPS = 50

__all__ = ["run_scenario", "run_block", "combine", "BlockResult", "plan_of", "with_run",
           "filter_rng", "ga_rng"]

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


class SpeedError:
    """Error of the speed ``|v_true| - |v_est|`` (m/s), the velocity at state ``dim``,
    ``dim + 1``. A class, not a closure, so that a stored block holds data only."""

    def __init__(self, dim: int) -> None:
        self.dim = dim

    def __call__(self, truth: Array, mean: Array) -> Array:
        dim = self.dim
        # |v| as np.linalg.norm computes it (sqrt of the sum of squares), without its
        # reduction over a length-2 axis
        vt = np.sqrt(truth[..., dim] * truth[..., dim] + truth[..., dim + 1] * truth[..., dim + 1])
        ve = np.sqrt(mean[..., dim] * mean[..., dim] + mean[..., dim + 1] * mean[..., dim + 1])
        return (vt - ve)[..., None]


class CourseError:
    """Error of the course ``atan2(vx, vy)`` (rad, wrapped), the velocity at state ``dim``."""

    def __init__(self, dim: int) -> None:
        self.dim = dim

    def __call__(self, truth: Array, mean: Array) -> Array:
        dim = self.dim
        ct = np.arctan2(truth[..., dim], truth[..., dim + 1])
        ce = np.arctan2(mean[..., dim], mean[..., dim + 1])
        return wrap(ct - ce)[..., None]


class BearingError:
    """Error of the bearing from the first observer to the target, wrapped (rad). The
    observer's position is set by the engine before each use: ``(2,)`` for one step, or
    ``(steps, 1, 2)`` for a window of steps (``MonteCarloMetrics.add_steps``)."""

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
        "speed": SpeedError(d), "course": CourseError(d), "bearing": BearingError(),
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
    """Gradient of speed, course or bearing (from ``origin``, ``(..., 2)`` broadcast against
    the batch axes) at true states ``x`` (..., n)."""
    g = np.zeros(x.shape)
    if group == "bearing":
        u, v = x[..., 0] - origin[..., 0], x[..., 1] - origin[..., 1]
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


# --- estimation and evaluation of one block -----------------------------------------------


@dataclass
class BlockResult:
    """Everything a block contributes; combined in block order."""

    block: int
    runs: int
    metrics: dict[str, MonteCarloMetrics]
    seconds: dict[str, float]
    info: Array  # (T, n, n) sum over runs of pd H^T R^-1 H at the truths
    grads: dict[str, Array]  # derived group -> (T, n) sum over runs of the gradient
    example: Example | None = None
    matching: dict[str, dict[str, Array]] | None = None  # filter -> per-run J2, J3, J4
    j1: Array | None = None  # (runs, m) per-run raw noise RMS
    gaps: dict[str, dict] | None = None  # filter -> _GapAccumulator.result
    classes: dict[str, dict] | None = None  # filter -> _ClassAccumulator.result (classifiers)


class _StepWindow:
    """A filter's estimates and innovations over a window of consecutive steps of a batch,
    handed to ``MonteCarloMetrics.add_steps`` at once (``metrics.WINDOW_ROWS`` run-steps: one
    numpy pass per quantity over the window instead of one per step), each block's runs
    (``parts``: accumulator and rows) to its own accumulator. A window holds as many steps as
    ``WINDOW_ROWS`` run-steps of the largest block, whatever the batch: the windows depend on
    the block size and the steps alone, so the sums are the same bits on any executor."""

    def __init__(self, parts: list[tuple[MonteCarloMetrics, slice]], plan: Plan, truth: Array,
                 groups: dict) -> None:
        self.parts, self.plan, self.truth, self.groups = parts, plan, truth, groups
        runs = max(len(range(truth.shape[1])[rows]) for _, rows in parts)
        self.size = max(1, _metrics.WINDOW_ROWS // max(runs, 1))
        self.k0, self.used = 0, 0
        self.buffers: list[Array] | None = None

    def add(self, k: int, g: Gaussian, innov) -> None:
        if self.used and k != self.k0 + self.used:
            self.flush()
        if not self.used:
            self.k0 = k
        parts = (g.mean, g.cov) if innov is None else (g.mean, g.cov, innov.nu,
                                                       innov.cov)
        bufs = self.buffers
        try:
            if bufs is None or len(bufs) != len(parts):
                raise ValueError("new buffers")
            j = self.used
            for b, p in zip(bufs, parts):  # noqa: B905 (lengths checked above)
                b[j] = p  # a shared covariance is broadcast over the runs
        except ValueError:  # the first step, or shapes that changed: start a new window
            self.flush()
            self.k0 = k
            self.buffers = [np.empty((self.size, *np.shape(p))) for p in parts]
            for b, p in zip(self.buffers, parts, strict=True):
                b[0] = p
        self.used += 1
        if self.used == self.size:
            self.flush()

    def flush(self) -> None:
        u, k0 = self.used, self.k0
        if not u:
            return
        self.used = 0
        b = [x[:u] for x in self.buffers]
        bearing = self.groups.get("bearing")
        if bearing is not None:
            saved = bearing.origin
            bearing.origin = self.plan.observer_states[0, k0 + 1:k0 + u + 1, None, :2]
        try:
            truth = self.truth[k0 + 1:k0 + u + 1]
            # the means and innovations have a run axis; a covariance shared by the runs not
            per_run = [True, b[1].ndim == 4, True, len(b) == 4 and b[3].ndim == 4]
            for acc, rows in self.parts:
                x = [a[:, rows] if r else a for a, r in zip(b, per_run)]  # noqa: B905
                acc.add_steps(k0, truth[:, rows], Gaussian._make(x[:2]),
                              Innovation(*x[2:]) if len(x) == 4 else None)
        finally:
            if bearing is not None:
                bearing.origin = saved


def _pcrlb_ingredients(plan: Plan, truth: Array, groups: dict) -> tuple[Array, dict]:
    """Per step, summed over the block's runs: the measurement information
    ``pd H^T R^-1 H`` at the true states ``truth (T + 1, B, n)`` ``(T, n, n)``, and the
    gradient of each derived group (speed, course, bearing) ``(T, n)``. The Jacobians come
    from each step's sensor; the rest is done a window of steps at a time."""
    T, n, d = plan.steps, plan.n, plan.dim
    B = truth.shape[1]
    info = np.empty((T, n, n))
    size = max(1, _metrics.WINDOW_ROWS // max(B, 1))
    for k0 in range(0, T, size):
        k1 = min(T, k0 + size)
        sensors = plan.sensors[k0:k1]
        m = sensors[0].dim_z
        if any(s.dim_z != m for s in sensors):  # sensors of several sizes: step by step
            for k in range(k0, k1):
                info[k:k + 1] = _information(plan, sensors[k - k0:k - k0 + 1],
                                             truth[k + 1:k + 2])
        else:
            info[k0:k1] = _information(plan, sensors, truth[k0 + 1:k1 + 1])
    grads = {g: _derived_gradient(g, d, n, truth[1:], plan.observer_states[0, 1:, None, :2])
             .sum(1) for g in groups if g in ("speed", "course", "bearing")}
    return info, grads


def _information(plan: Plan, sensors: list, truth: Array) -> Array:
    """``pd sum_runs H^T R^-1 H`` for steps of equal measurement size: ``truth (w, B, n)``,
    one sensor per step."""
    w, B, n = truth.shape
    m = sensors[0].dim_z
    H = np.stack([np.broadcast_to(s.jacobian(x), (B, m, n)) for s, x in
                  zip(sensors, truth, strict=True)])  # (w, B, m, n)
    Rinv = np.linalg.inv(np.stack([np.asarray(s.noise, dtype=float) for s in sensors]))
    RinvH = Rinv[:, None] @ H if m > 1 else H * Rinv[:, None]
    return plan.p_detect * np.einsum("wbmi,wbmj->wij", H, RinvH)


def run_block(scenario: Scenario, block: int,
              progress: Callable[[float], None] | None = None) -> BlockResult:
    """Simulate, filter and evaluate block ``block`` of the scenario's runs; ``progress`` is
    told the fraction of the block done, after every ``PROGRESS_STEPS`` steps of a filter."""
    return _run_batch(scenario, [block], progress)[0]


def _span(s: Scenario, block: int) -> tuple[int, int]:
    r0 = block * s.run.block
    r1 = min(s.run.runs, r0 + s.run.block)
    if not 0 <= r0 < r1:
        raise ValueError(f"block {block} is outside the {s.run.runs} runs")
    return r0, r1


def _check_together(plan: Plan) -> None:
    """Blocks filtered as one batch must give each block's own runs: refused where a block's
    result depends on more than its runs' truths and measurements (``report.matching`` is
    refused before the plan is compiled)."""
    for name, f in zip(plan.filter_names, plan.filters, strict=True):
        if getattr(f, "stochastic", False):
            raise ValueError(f"filter {name!r} draws from its block's own generator "
                             "(filter_rng): its blocks cannot be filtered together")


def _joined(datas: list[BlockData]) -> BlockData:
    if len(datas) == 1:
        return datas[0]
    return BlockData(np.concatenate([d.truth for d in datas], axis=1),
                     np.concatenate([d.z for d in datas], axis=1),
                     np.concatenate([d.prior_offset for d in datas], axis=0))


def _run_batch(scenario: Scenario, blocks: list[int],
               progress: Callable[[float], None] | None = None) -> list[BlockResult]:
    """Blocks ``blocks``, each simulated on its own (its runs' data are the bits of
    ``run_block``), filtered as one batch of their runs, each evaluated on its own runs."""
    if len(blocks) > 1 and scenario.report.matching:
        raise ValueError("report.matching scores each block's runs on their own: its blocks "
                         "cannot be filtered together")
    plan = plan_of(scenario)
    s = plan.scenario
    spans = [_span(s, b) for b in blocks]
    if len(blocks) > 1:
        _check_together(plan)
    datas = [simulate_block(plan, r0, r1) for r0, r1 in spans]
    data = _joined(datas)
    edges = np.cumsum([0] + [r1 - r0 for r0, r1 in spans])
    rows = [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)] \
        if len(blocks) > 1 else [slice(None)]
    B = int(edges[-1])
    T, n, d = plan.steps, plan.n, plan.dim
    if plan.gap_mask is not None:
        data.z[plan.gap_mask] = np.nan  # the radar saw nothing: every filter's data alike
    gap_windows = _gap_windows(plan)
    groups = groups_for(plan)
    angular = None
    if s.report.angle_states:
        angular = tuple(j in s.report.angle_states for j in range(n))
    P = len(blocks)
    metrics: list[dict] = [{} for _ in blocks]
    seconds: list[dict] = [{} for _ in blocks]
    gaps: list[dict] = [{} for _ in blocks]
    classes: list[dict] = [{} for _ in blocks]
    keep = spans[0][0] == 0  # run 0's example, the first row of the batch
    ga_start = None
    if s.prior.initialiser == "ga":  # each run's GA with the run's own generator
        ga_start = _ga_start(plan, data, [r for r0, r1 in spans for r in range(r0, r1)])
    est_hist: dict[str, tuple[Array, Array]] = {}
    matching = {} if s.report.matching else None
    logs = {}
    pseudo_hist: dict[str, Array] = {}
    m = plan.sensors[0].dim_z
    for i, (name, f, motion, (mean0, P0)) in enumerate(zip(
            plan.filter_names, plan.filters, plan.filter_motions, plan.priors, strict=True)):
        accs = [MonteCarloMetrics(groups=groups, angular=angular) for _ in blocks]
        window = _StepWindow(list(zip(accs, rows, strict=True)), plan, data.truth, groups)
        match = None if matching is None else MatchingMetrics(B, n, m, T, log=keep)
        if ga_start is not None:  # every filter from the same GA estimate (the paper's)
            prior = Gaussian(ga_start.mean.copy(), ga_start.cov.copy())
        else:
            prior = data.prior(P0, mean0)
        b = f.init(prior, rng=filter_rng(s.run.seed, blocks[0], i)) if getattr(
            f, "stochastic", False) else f.init(prior)
        elapsed = 0.0
        handler = plan.gap_handlers[i] if plan.gap_handlers else None
        sizes = [(r1 - r0, r) for (r0, r1), r in zip(spans, rows, strict=True)]
        gap = [_GapAccumulator(groups, gap_windows, runs, T, handler is not None, angular, r)
               for runs, r in sizes]
        names = getattr(f, "class_names", None)
        cls = None if names is None else [
            _ClassAccumulator(names, s.report.true_class, runs, T, r) for runs, r in sizes]
        if keep:
            hm, hP = np.empty((T, n)), np.empty((T, n, n))
            hz = np.full((T, m), np.nan)
        for k in range(T):
            sensor = plan.filter_sensor(i, k)
            t0 = time.perf_counter()
            b = f.predict(b, motion, plan.times[k + 1] - plan.times[k])
            R_used = None if match is None else noise_in_use(b, sensor.noise)
            b, innov = f.update(b, data.z[k], sensor)
            elapsed += time.perf_counter() - t0
            g = f.estimate(b)
            window.add(k, g, innov)
            if "bearing" in groups:
                groups["bearing"].origin = plan.observer_states[0, k + 1, :2]
            for part in gap:
                part.add(k, data.truth[k + 1], g.mean, b)
            if cls is not None:
                for part in cls:
                    part.add(k, b.class_prob)  # the classifier's own belief (class_names)
            if keep and handler is not None:
                hz[k] = b.z_pseudo[0]
            if match is not None:
                match.add(k, data.truth[k + 1], g.mean, innov, R_used, plan.sensors[k])
            if keep:
                hm[k], hP[k] = g.mean[0], g.cov[0]
            if progress is not None and (k + 1) % PROGRESS_STEPS == 0:
                progress((i + (k + 1) / T) / len(plan.filters))
        window.flush()  # the last steps
        for j in range(P):
            accs[j].flush()  # the batch totals into the exact sums, before a block is sent
            metrics[j][name] = accs[j]
            seconds[j][name] = elapsed * (spans[j][1] - spans[j][0]) / B  # its runs' share
            gaps[j][name] = gap[j].result(handler)
            if cls is not None:
                classes[j][name] = cls[j].result()
        if keep and handler is not None:
            pseudo_hist[name] = hz
        if match is not None:
            matching[name] = match.per_run(s.report.dom_alpha)
            if keep:
                logs[name] = match.logs
        if keep:
            est_hist[name] = (hm, hP)
        if progress is not None:
            progress((i + 1) / len(plan.filters))
    example = None
    if keep:
        example = Example(times=plan.times[1:], truth=data.truth[1:, 0],
                          observer=plan.observer_states[0, 1:, :d], estimates=est_hist,
                          measurements=data.z[:, 0], logs=logs, pseudo=pseudo_hist)
    j1 = None
    if matching is not None:
        z_true = np.stack([plan.sensors[k].h(data.truth[k + 1]) for k in range(T)])
        j1 = measurement_noise_rms(data.z, z_true, plan.sensors[0])
    out = []
    for j, (block, r) in enumerate(zip(blocks, rows, strict=True)):
        info, grads = _pcrlb_ingredients(plan, data.truth[:, r], groups)
        out.append(BlockResult(block, spans[j][1] - spans[j][0], metrics[j], seconds[j], info,
                               grads, example if j == 0 else None, matching, j1, gaps[j],
                               classes[j]))
    return out


def ga_rng(seed: int, run: int) -> np.random.Generator:
    """The generator of run ``run``'s GA initialiser: keyed by the seed, a distinct word and
    the run alone (not its block), so a run's GA start is the same whatever the block size,
    and it never shares a stream with the simulation or a filter."""
    return np.random.default_rng(np.random.SeedSequence([seed, 0x67615F69, run]))


def _ga_start(plan: Plan, data: BlockData, runs: list[int]) -> Gaussian:
    """Every run's GA start (``prior.initialiser = "ga"``; ``runs``: the runs of ``data``,
    whose generators it draws from): the position the GA finds from
    the first K measurements (``trackkit.filters.initialise.ga_initial_position``, the
    auxiliary filter predicting with the first filter's motion), the velocity guess and the
    run's first measured frequency, with ``P0 = diag(prior.ga.std^2)``; at the prior time.

    The main filters then process all the measurements from the first, including the K the
    GA has seen (the paper's Fig. 2: the GA's position initialises the main filter). That
    uses those K twice; the stated P0 (1000 m by default, against a GA error of a few hundred
    metres, see docs/dbt-truth-and-initialisation.md) is what keeps the NEES honest.
    """
    from trackkit.filters.initialise import ga_initial_position, ga_prior
    from trackkit.optimize.ga import GA

    s = plan.scenario
    ga = s.prior.ga_settings
    K = ga.measurements
    z = data.z[:K]
    freq = z[..., 1]
    seen = ~np.isnan(freq)
    if not seen.any(0).all():
        lost = runs[int(np.flatnonzero(~seen.any(0))[0])]
        raise ValueError(f"run {lost} has no frequency measurement among the first "
                         f"prior.ga.measurements = {K}; the GA initialiser needs one (its f0 "
                         "guess): expected more measurements or a higher p_detect")
    f0 = freq[np.argmax(seen, axis=0), np.arange(len(runs))]
    v0 = np.asarray(ga.velocity_guess_mps, dtype=float)
    result = ga_initial_position(
        z, plan.sensors[:K], plan.filter_motions[0], plan.dt,
        rngs=[ga_rng(s.run.seed, r) for r in runs], velocity_guess=v0,
        f0_guess=f0, cov=np.diag(np.square(ga.aux_std)), max_range=ga.max_range_m,
        ga=GA(ga.population, ga.generations, ga.crossover, ga.mutation), cost=ga.cost,
        block=ga.block)
    return ga_prior(result, f0, velocity_guess=v0, cov=np.diag(np.square(ga.std)))


def filter_rng(seed: int, block: int, index: int) -> np.random.Generator:
    """The generator of filter ``index`` (its place in ``[[filters]]``) in block ``block``:
    a stochastic filter (a particle filter, ``f.stochastic``) draws from it, so its result
    depends on the seed and the block alone, whatever the executor, and never shares a
    stream with the simulation (``run_rng`` spawns children of ``SeedSequence(seed)``;
    these are keyed by a distinct word)."""
    return np.random.default_rng(np.random.SeedSequence([seed, 0x7466696C, block, index]))


def _gap_windows(plan: Plan) -> tuple[Array, Array] | None:
    """The steps [gaps] hides and the ``round(after_gap_s / dt)`` steps after each gap that
    are not themselves missing (where the recovery is scored), as step indices; None
    without [gaps]."""
    if plan.gap_mask is None:
        return None
    from trackkit.filters.gaps import gap_and_after

    after = int(round(plan.scenario.report.after_gap_s / plan.dt))
    mask = plan.gap_mask
    return np.flatnonzero(mask), np.flatnonzero(gap_and_after(mask, after) & ~mask)


class _GapAccumulator:
    """Per-run sums of squared errors per group over the gap steps and the steps after
    them, and the runs fed a pseudo-measurement at each step. Each run's sums add its own
    steps in time order, so they do not depend on how runs are split into blocks. ``rows``:
    the block's runs in the batch it was filtered in."""

    def __init__(self, groups: dict, windows: tuple[Array, Array] | None, runs: int,
                 steps: int, handler: bool, angular: tuple[bool, ...] | None,
                 rows: slice = slice(None)) -> None:
        self.groups, self.handler, self.rows = groups, handler, rows
        self.angular = None if angular is None else np.asarray(angular)
        self.where = np.zeros(steps, np.int8)  # 1: gap, 2: after
        if windows is not None:
            self.where[windows[0]], self.where[windows[1]] = 1, 2
        self.sse = ({g: np.zeros(runs) for g in groups} if windows is not None else None,
                    {g: np.zeros(runs) for g in groups} if windows is not None else None)
        self.pseudo = np.zeros(steps, np.int64)

    def add(self, k: int, truth: Array, mean: Array, belief) -> None:
        if self.handler:
            self.pseudo[k] = int(np.count_nonzero(np.asarray(belief.pseudo)[self.rows]))
        w = self.where[k]
        if not w:
            return
        sse = self.sse[w - 1]
        truth, mean = truth[self.rows], mean[self.rows]
        e_all = truth - mean
        if self.angular is not None:  # as MonteCarloMetrics wraps them
            e_all = np.where(self.angular, wrap(e_all), e_all)
        for g, spec in self.groups.items():
            e = spec(truth, mean) if callable(spec) else e_all[..., spec]
            sse[g] += np.sum(e * e, -1)

    def result(self, handler: str | None) -> dict:
        out: dict = {"handler": handler}
        if self.sse[0] is not None:
            out["gap_sse"], out["after_sse"] = self.sse
        if self.handler:
            out["pseudo_steps"] = self.pseudo
        return out


class _ClassAccumulator:
    """The class probabilities of a filter that classifies (its belief's ``class_prob``,
    ``(runs, C)`` per step): their sum over runs per step, each run's last ones and, when the
    scenario names the true class, each run's probability of it at every step (for its
    percentiles over runs). ``rows``: the block's runs in the batch it was filtered in."""

    def __init__(self, names: tuple[str, ...], true_class: str | None, runs: int,
                 steps: int, rows: slice = slice(None)) -> None:
        self.names, self.rows = tuple(names), rows
        self.true = self.names.index(true_class) if true_class in self.names else None
        self.sum = np.zeros((steps, len(self.names)))
        self.history = None if self.true is None else np.empty((runs, steps))
        self.final = np.full((runs, len(self.names)), np.nan)

    def add(self, k: int, prob: Array) -> None:
        p = np.asarray(prob, dtype=float).reshape(-1, len(self.names))[self.rows]
        self.sum[k] = p.sum(0)
        self.final = p
        if self.history is not None:
            self.history[:, k] = p[:, self.true]

    def result(self) -> dict:
        return {"names": self.names, "sum": self.sum, "final": self.final.copy(),
                "true": self.history}


def run_blocks(scenario: Scenario, blocks: list[int],
               progress: Callable[[float], None] | None = None, *,
               together: bool = False) -> list[BlockResult]:
    """A chunk of blocks (one executor task); ``progress`` is told the runs done in it.

    ``together``: the blocks' runs filtered as one batch, one pass over the steps instead of
    one per block (small blocks, the batches of a batch-means or jackknife error, cost what
    one large block costs), each block still simulated and evaluated on its own runs. Every
    block's truths, measurements and priors are the bits of ``run_block``; its estimates and
    statistics agree with ``run_block``'s to the rounding a run's place in a batch changes
    (numpy's SIMD loops round a loop's body and its tail apart, and a filter's recursion
    carries that on: within 1e-8 relative, tests/experiments/test_blocks_together.py), and
    its ``seconds`` are the batch's time shared by runs. Refused for a stochastic filter (it draws
    from its block's generator) and for ``report.matching``.
    """
    if together:
        runs = sum(_span(scenario, b)[1] - _span(scenario, b)[0] for b in blocks)
        tell = None if progress is None else (lambda f: progress(f * runs))
        return _run_batch(scenario, list(blocks), tell)
    size = scenario.run.block
    out = []
    for b in blocks:
        runs = min(scenario.run.runs, (b + 1) * size) - b * size
        done = sum(p.runs for p in out)
        tell = None if progress is None else (lambda f, d=done, n=runs: progress(d + f * n))
        out.append(run_block(scenario, b, tell))
    return out


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
    spans = {w: window_steps(a, b, T, plan.dt) for w, (a, b) in s.report.windows.items()}
    pcrlb_windows = {w: {g: float(np.sqrt(np.mean(v[k0:k1] ** 2))) for g, v in pcrlb.items()}
                     for w, (k0, k1) in spans.items()}
    filters = {}
    windows = _gap_windows(plan)
    for name in plan.filter_names:
        acc = parts[0].metrics[name]
        for p in parts[1:]:
            acc = acc.merge(p.metrics[name])
        summ = acc.summary(start)
        in_windows = {}
        for w, (k0, k1) in spans.items():  # from the per-step sums: no accumulation of its own
            ws = acc.summary(k0, stop=k1)
            in_windows[w] = {"rmse": {g: ws[f"rmse_{g}"] for g in groups},
                             "anees": ws["nees_mean"], "anis": ws["nis_mean"],
                             "nees_in_bounds": ws["nees_inside"]}
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
            gaps=_combine_gaps([p.gaps[name] for p in parts]),
            classes=_combine_classes([(p.classes or {}).get(name) for p in parts], runs,
                                     s.report.true_class),
            windows=in_windows,
        )
    notes = list(s.notes)
    if {"speed", "course", "bearing"} & set(groups):
        notes.append("The speed, course and bearing bounds propagate the state bound to first "
                     "order (G B G^T with G the mean gradient over runs). While the uncertainty "
                     "is large compared with the speed or range this is not a true lower "
                     "bound, and filters can fall below it early in a track.")
    if s.prior.initialiser == "ga":
        ga = s.prior.ga_settings
        notes.append(f"Every filter starts from the GA initialiser's position (population "
                     f"{ga.population}, {ga.generations} generations, from the first "
                     f"{ga.measurements} measurements in blocks of {ga.block}) with P0 = "
                     f"diag({', '.join(f'{v:g}' for v in ga.std)})^2, and then processes "
                     "every measurement, those the GA saw included. The PCRLB keeps the "
                     "scenario's prior (J0 = P0^-1 of prior.std), which a GA-started filter "
                     "does not use.")
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
        gap_steps=None if windows is None else windows[0],
        after_steps=None if windows is None else windows[1],
        after_gap_s=s.report.after_gap_s, kinematic=not s.linear_system or plan.n >= 2 * plan.dim,
        windows={w: (a, b) for w, (a, b) in s.report.windows.items()}, window_steps=spans,
        pcrlb_windows=pcrlb_windows,
    )


def _combine_classes(parts: list[dict | None], runs: int, true_class: str | None) -> dict:
    """Block results of one filter's class accumulator, in block order: ``names``, the mean
    probability of each class per step ``mean (steps, C)``, each run's last probabilities
    ``final (runs, C)``, ``true_class`` and (when it is one of the filter's classes) each
    run's probability of it per step ``true (runs, steps)``; empty for a filter that does
    not classify."""
    if not parts or parts[0] is None:
        return {}
    total = parts[0]["sum"].copy()
    for p in parts[1:]:
        total += p["sum"]
    true = None if parts[0]["true"] is None else np.concatenate([p["true"] for p in parts])
    return {"names": parts[0]["names"], "mean": total / runs,
            "final": np.concatenate([p["final"] for p in parts]),
            "true_class": true_class if true is not None else None, "true": true}


def _combine_gaps(parts: list[dict]) -> dict:
    """Block results of one filter's gap accumulator, in block order."""
    out = {"handler": parts[0]["handler"]}
    for key in ("gap_sse", "after_sse"):
        if key in parts[0]:
            out[key] = {g: np.concatenate([p[key][g] for p in parts]) for g in parts[0][key]}
    if "pseudo_steps" in parts[0]:
        total = parts[0]["pseudo_steps"].copy()
        for p in parts[1:]:
            total += p["pseudo_steps"]
        out["pseudo_steps"] = total
    return out


# --- the public entry point ---------------------------------------------------------------


def with_run(scenario: Scenario, runs: int | None, seed: int | None) -> Scenario:
    """The scenario with ``run.runs`` / ``run.seed`` replaced (validated again)."""
    run = scenario.run.model_copy(update={k: v for k, v in
                                          (("runs", runs), ("seed", seed)) if v is not None})
    data = scenario.model_dump()
    data["run"] = run.model_dump()
    return Scenario.model_validate(data)


#: bytes each run keeps until the end, per filter: the exact accumulator's per-run divergence
#: counters (``MonteCarloMetrics.run_*``), with room for the bookkeeping around them
BYTES_PER_RUN_PER_FILTER = 64


class RunBudgetError(ValueError):
    """A run count that cannot finish on this machine (memory) or within the time allowed."""


def _memory_bytes() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 8 << 30


def check_memory(scenario: Scenario) -> None:
    """Refuse a run count whose per-run results alone would take half of this machine's
    memory, before anything runs."""
    runs, filters = scenario.run.runs, len(scenario.filters)
    per_run = BYTES_PER_RUN_PER_FILTER * filters
    if scenario.report.matching:
        per_run += 8 * filters * (scenario.state_dim + 4)  # per-run J2-J4 and J1
    from trackkit.scenario.options import CLASS_TYPES

    classifiers = sum(f.type in CLASS_TYPES for f in scenario.filters)
    if classifiers:  # each run's last class probabilities and P(true class) per step
        steps = scenario.time.steps if scenario.report.true_class else 0
        per_run += 8 * classifiers * (2 + steps)
    budget = _memory_bytes() // 2
    if runs * per_run > budget:
        raise RunBudgetError(
            f"runs = {runs} would keep about {runs * per_run / 2**30:.1f} GiB of per-run "
            f"results ({per_run} bytes per run for {filters} filters); this machine has "
            f"{_memory_bytes() / 2**30:.1f} GiB, so at most {budget // per_run} runs fit")


def check_time(runs: int, done: int, seconds: float, max_seconds: float | None,
               parallel: int = 1) -> None:
    """Refuse to go on when the runs would take longer than ``max_seconds``, estimated from
    the ``done`` runs that took ``seconds`` here, shared by ``parallel`` workers."""
    if max_seconds is None or done >= runs:
        return
    estimate = seconds / done * runs / parallel
    if estimate > max_seconds:
        raise RunBudgetError(
            f"runs = {runs} would take about {_duration(estimate)} here ({seconds / done * 1e3:.3g}"
            f" ms per run, measured on the first {done}), more than the {_duration(max_seconds)}"
            " allowed; run fewer runs, more workers, or allow more time (--max-hours)")


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.0f} days"


def _tasks(runs: int, block: int, per_task: int, first: int = 0) -> Iterator[list[int]]:
    """Tasks of ``per_task`` consecutive blocks from block ``first``, made as they are needed
    (a billion runs must not build four million lists before the first block runs)."""
    nblocks = -(-runs // block)
    for i in range(first, nblocks, per_task):
        yield list(range(i, min(nblocks, i + per_task)))


def _task_runs(runs: int, block: int, task: list[int]) -> int:
    return min(runs, (task[-1] + 1) * block) - task[0] * block


def run_scenario(
    scenario: Scenario,
    runs: int | None = None,
    seed: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress: Callable[[float, int], None] | None = None,
    max_seconds: float | None = None,
) -> MonteCarloResult:
    """Run the scenario's Monte Carlo comparison and return its result.

    ``workers`` > 0 or a ``scheduler`` address sends chunks of blocks to Dask; ``chunk`` is
    the runs per task (rounded up to whole blocks). ``progress(done, total)`` is told the runs
    done (fractional within a block) every few seconds. A run count whose per-run results do
    not fit in memory is refused at once; with ``max_seconds``, the first block is timed and a
    run count whose estimate exceeds it is refused (``RunBudgetError``). Fuzzy filters with a
    ``tune`` block must be tuned first: ``trackkit.experiments.compare`` does both.
    """
    from trackkit.experiments.executors import execute

    if runs is not None and runs < 1:
        raise ValueError(f"runs = {runs}; expected at least 1")
    if seed is not None and seed < 0:
        raise ValueError(f"seed = {seed}; expected a non-negative integer")
    s = with_run(scenario, runs, seed)
    untuned = [f.name for f in s.filters if f.tune is not None]
    if untuned:
        raise ValueError(f"filters {untuned} have a tune block and are not tuned yet; run the "
                         "scenario with trackkit.experiments.compare, which tunes them first")
    check_memory(s)
    plan_of(s)  # compile (and so validate models) before any work is sent out
    total, size = s.run.runs, s.run.block
    nblocks = -(-total // size)
    per_task = max(1, -(-(chunk or size) // size))
    if chunk is None and (workers or scheduler):
        per_task = max(1, nblocks // (4 * max(workers or 1, 1)))
    parts: list[BlockResult] = []
    first = 0
    if max_seconds is not None and nblocks > 1:
        # time one block here before committing to the rest
        t0 = time.perf_counter()
        parts += run_blocks(s, [0], None if progress is None else
                            (lambda d: progress(d, total)))
        check_time(total, parts[0].runs, time.perf_counter() - t0, max_seconds, workers or 1)
        first = 1
    done = sum(p.runs for p in parts)
    tasks = _tasks(total, size, per_task, first)
    chunks = execute(run_blocks, s, tasks, lambda t: _task_runs(total, size, t),
                     total - done, workers=workers, scheduler=scheduler,
                     progress=None if progress is None else (lambda d, _: progress(done + d,
                                                                                   total)))
    return combine(s, parts + [p for chunk_parts in chunks for p in chunk_parts])
