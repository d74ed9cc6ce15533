"""Off-line tuning of the fuzzy-adaptive filters' membership functions (Naseri Solhdar, sections 3-2
and 3-4-4).

The thesis's design procedure: simulate the problem, run the filter with a candidate fuzzy
system, score it by the degree of matching alone,

    cost = alpha sum_i sqrt((1/K) sum_k DOM_k(i,i)^2)        (alpha = ``report.dom_alpha``)

(no true state needed, so real data would do), minimise with GA, PSO or ICA, and freeze the
best system. Here a whole optimiser population (of all independent optimiser runs at once) is
one batch of the filter: the candidates are rows, each with its own parameter vector.

The tuning data are ``realisations`` runs of the scenario drawn from ``tune.seed``, apart
from the Monte Carlo runs that score the tuned filter. ``tune.on`` names a bundled scenario
whose same-named filter's tuning is reused (the thesis reuses its fixed-sensor system for
moving sensors).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from trackkit.belief import Gaussian
from trackkit.filters.fuzzy import PARAM_BOUNDS, FuzzyAdaptive, dom_cost
from trackkit.optimize import GA, ICA, PSO
from trackkit.optimize.base import Optimizer, repeat
from trackkit.scenario.build import Plan, compile_scenario
from trackkit.scenario.schema import FilterSpec, RunSpec, Scenario, TuneSpec
from trackkit.scenario.simulate import simulate_block

Array = NDArray[np.float64]

__all__ = ["TuningResult", "dom_costs", "tune_filter", "tune_scenario"]


@dataclass
class TuningResult:
    """One tuned filter: the optimiser's best, mean and worst final cost over its
    independent runs (the thesis's Table 3-2), each run's convergence ``history``
    ``(iterations + 1, runs)`` and the chosen ``params`` (the best run's)."""

    optimizer: str
    runs: int
    population: int
    iterations: int
    best: float
    mean: float
    worst: float
    history: Array
    params: Array
    costs: Array  # (runs,) final cost of each run
    seconds: float

    def summary(self) -> dict[str, Any]:
        return {"optimizer": self.optimizer, "runs": self.runs,
                "population": self.population, "iterations": self.iterations,
                "best": self.best, "mean": self.mean, "worst": self.worst,
                "params": self.params.tolist(), "seconds": self.seconds}


def _optimizer(spec: TuneSpec) -> Optimizer:
    if spec.optimizer == "GA":
        return GA(population=spec.population, generations=spec.iterations)
    cls = PSO if spec.optimizer == "PSO" else ICA
    return cls(population=spec.population, iterations=spec.iterations)


def dom_costs(template: FuzzyAdaptive, params: Array, plan: Plan, index: int, z: Array,
              x0: Array, alpha: float) -> Array:
    """The DOM cost of each candidate ``params (P, 15)`` on each realisation: ``(P, K)``.

    ``z (T, K, m)`` the realisations' measurements, ``x0 (K, n)`` their prior means; filter
    ``index`` of ``plan`` gives the motion model, R0 and P0. Rows are candidate-major
    (candidate p, realisation k at row ``p K + k``).
    """
    P, K = params.shape[0], z.shape[1]
    n = x0.shape[-1]
    f = template.with_params(np.repeat(params, K, axis=0))
    motion = plan.filter_motions[index]
    P0 = plan.priors[index][1]
    b = f.init(Gaussian(np.tile(x0, (P, 1)), np.broadcast_to(P0, (P * K, n, n)).copy()))
    dom_sq = np.zeros((P * K, z.shape[-1]))
    seen = np.zeros((P * K, 1))
    for k in range(plan.steps):
        zk = np.tile(z[k], (P, 1))
        b = f.predict(b, motion, plan.times[k + 1] - plan.times[k])
        b, _ = f.update(b, zk, plan.filter_sensor(index, k))
        d = np.diagonal(b.dom, axis1=-2, axis2=-1)
        has = ~np.isnan(zk).any(-1, keepdims=True)  # J4 counts the steps with a measurement
        dom_sq += np.where(has, d * d, 0.0)
        seen += has
    cost = dom_cost(dom_sq / np.maximum(seen, 1), 1, alpha)
    return np.where(np.isfinite(cost), cost, np.inf).reshape(P, K)


Progress = Callable[[int, int], None]


def tune_filter(scenario: Scenario, index: int, progress: Progress | None = None
                ) -> TuningResult:
    """Tune filter ``index`` of the scenario (an OF* filter with a ``tune`` block);
    ``progress(done, total)`` counts the optimiser's generations.

    With ``tune.on`` the result is that of the same-named filter of the bundled scenario
    ``on`` (tuned there, once per process): the thesis reuses the fuzzy system tuned with
    fixed sensors for its moving-sensor runs.
    """
    spec: FilterSpec = scenario.filters[index]
    if spec.tune is None:
        raise ValueError(f"filter {spec.name!r} has no tune block")
    if spec.tune.on is not None:
        from trackkit.scenario import load

        source = load(spec.tune.on)
        names = [f.name for f in source.filters]
        if spec.name not in names or source.filters[names.index(spec.name)].tune is None:
            raise ValueError(f"filter {spec.name!r}: tune.on = {spec.tune.on!r} has no filter "
                             f"of that name with a tune block (its filters: {names})")
        if source.filters[names.index(spec.name)].tune.on is not None:
            raise ValueError(f"filter {spec.name!r}: tune.on = {spec.tune.on!r} refers on "
                             "again; expected a scenario that tunes the filter itself")
        return _tuned(_key(source), names.index(spec.name), progress)
    return _tuned(_key(scenario), index, progress)


def _key(scenario: Scenario) -> str:
    """The scenario as the tuning sees it: the Monte Carlo run settings play no part, so a
    scenario tunes once per process whatever its runs and seed."""
    data = scenario.model_dump()
    data["run"] = RunSpec().model_dump()
    return Scenario.model_validate(data).model_dump_json()


_CACHE: dict[tuple[str, int], TuningResult] = {}
_CACHE_SIZE = 64  # a test session holds a few dozen tunings; each costs up to 90 s


def generations(spec: TuneSpec) -> int:
    """Cost evaluations of one tuning: the initial population and each iteration."""
    return spec.iterations + 1


def _tuned(scenario_json: str, index: int, progress: Progress | None = None) -> TuningResult:
    """The tuning of filter ``index``, computed once per process per scenario."""
    key = (scenario_json, index)
    if key in _CACHE:
        return _CACHE[key]
    scenario = Scenario.model_validate_json(scenario_json)
    t = scenario.filters[index].tune
    plan = compile_scenario(scenario)
    data = simulate_block(plan, 0, t.realisations, seed=t.seed)
    mean0, P0 = plan.priors[index]
    x0 = data.prior(P0, mean0).mean
    template = plan.filters[index]
    alpha = scenario.report.dom_alpha
    calls = 0

    def cost(X: Array) -> Array:
        nonlocal calls
        B, N, d = X.shape
        out = dom_costs(template, X.reshape(B * N, d), plan, index, data.z, x0,
                        alpha).mean(-1).reshape(B, N)
        calls += 1
        if progress is not None:
            progress(min(calls, generations(t)), generations(t))
        return out

    seeds = np.random.SeedSequence(t.seed).spawn(t.runs)
    t0 = time.perf_counter()
    stats = repeat(_optimizer(t), cost, PARAM_BOUNDS, seeds)
    res = stats["results"]
    result = TuningResult(optimizer=t.optimizer, runs=t.runs, population=t.population,
                          iterations=t.iterations, best=stats["best"], mean=stats["mean"],
                          worst=stats["worst"], history=res.history, params=stats["best_x"],
                          costs=res.best_f, seconds=time.perf_counter() - t0)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = result
    return result


def tune_scenario(scenario: Scenario, progress: Progress | None = None
                  ) -> tuple[Scenario, dict[str, TuningResult]]:
    """Tune every filter with a ``tune`` block; return the scenario with the tuned
    parameters written into those filters' ``options.params`` (and their ``tune`` blocks
    removed), and the tuning results by filter name. ``progress(done, total)`` counts
    optimiser generations over all the filters to tune."""
    results = {}
    data = scenario.model_dump()
    todo = [i for i, spec in enumerate(scenario.filters) if spec.tune is not None]
    total = sum(generations(scenario.filters[i].tune) for i in todo)
    done = 0
    for i in todo:
        spec = scenario.filters[i]
        tell = None if progress is None else (lambda d, _, base=done: progress(base + d, total))
        res = tune_filter(scenario, i, tell)
        done += generations(spec.tune)
        if progress is not None:
            progress(done, total)
        results[spec.name] = res
        data["filters"][i]["options"]["params"] = [float(v) for v in res.params]
        data["filters"][i]["tune"] = None
    if not results:
        return scenario, results
    return Scenario.model_validate(data), results
