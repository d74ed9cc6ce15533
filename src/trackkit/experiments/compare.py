"""A scenario's comparison from start to end: tune what must be tuned, then run the Monte
Carlo on the tuned scenario. The tuner drives the Monte Carlo, never the other way round."""

from __future__ import annotations

from collections.abc import Callable

from trackkit.experiments.montecarlo import run_scenario, with_run
from trackkit.experiments.results import MonteCarloResult
from trackkit.experiments.tuning import tune_scenario
from trackkit.scenario.schema import Scenario

__all__ = ["compare"]


def compare(
    scenario: Scenario,
    runs: int | None = None,
    seed: int | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress: Callable[[float, int], None] | None = None,
    tuning_progress: Callable[[int, int], None] | None = None,
    max_seconds: float | None = None,
) -> MonteCarloResult:
    """Tune the scenario's fuzzy filters (``tuning_progress(done, total)`` counts optimiser
    generations), then run its Monte Carlo (``run_scenario``, whose arguments the rest are)
    and attach the tuning results."""
    s = with_run(scenario, runs, seed)
    tuned, tuning = tune_scenario(s, progress=tuning_progress)
    result = run_scenario(tuned, workers=workers, scheduler=scheduler, chunk=chunk,
                          progress=progress, max_seconds=max_seconds)
    result.tuning = tuning
    return result
