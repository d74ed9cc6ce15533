"""A multi-target scenario's comparison from start to end: build the scene and the trackers,
run the Monte Carlo, and track run 0 once more for the report's example picture.

    scenario = load_multitarget("radar-crossing")
    result, example = run_multitarget(scenario, runs=20, workers=2)
    write_tracking_report(result, scenario, example, "trackkit-out/radar-crossing")

The Monte Carlo is ``trackkit.experiments.tracking_mc.run_tracking`` (per-run simulation, fixed
blocks of runs on an executor, per-run numbers reduced in run order, so a result is
bit-identical whatever the block size and the executor on one machine).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from trackkit.experiments.tracking_mc import TrackingResult, run_tracking
from trackkit.scenario.multitarget import MultiTargetScenario, build, scan_period
from trackkit.sim.scene import SceneRun, simulate_scene
from trackkit.tracking.history import TrackHistory, run_tracker

__all__ = ["TrackingExample", "run_multitarget"]


class TrackingExample(NamedTuple):
    """One Monte Carlo run for the pictures: the simulated ``run`` (plots, their origins and
    the truth) and each tracker's ``histories[name]`` on it."""

    run: SceneRun
    histories: dict[str, TrackHistory]


def run_multitarget(scenario: MultiTargetScenario, runs: int | None = None,
                    seed: int | None = None, workers: int | None = None,
                    scheduler: str | None = None,
                    progress: Callable[[float, int], None] | None = None,
                    block: int | None = None) -> tuple[TrackingResult, TrackingExample]:
    """Build ``scenario`` (``scenario.multitarget.build``), run its Monte Carlo
    (``run_tracking`` with ``run.runs``, ``run.seed``, ``run.block`` unless given here,
    ``report.c_m``, ``report.ospa_p`` and ``report.confirm_within_scans`` scan periods), and
    track run 0 once more with every tracker for the example picture.
    ``progress(runs_done, runs)`` as ``run_tracking``'s."""
    runs = scenario.run.runs if runs is None else int(runs)
    seed = scenario.run.seed if seed is None else int(seed)
    block = scenario.run.block if block is None else int(block)
    scene, trackers = build(scenario)
    n, period = scenario.report.confirm_within_scans, scan_period(scene)
    within = n * period if math.isfinite(period) else math.inf  # one scan: no period
    result = run_tracking(scene, trackers, runs, seed, c=scenario.report.c_m, within=within,
                          block=block, workers=workers, scheduler=scheduler,
                          progress=progress, ospa_p=scenario.report.ospa_p)
    (run0,) = simulate_scene(scene, [0], seed)
    histories = {name: run_tracker(t, run0.scans)[0] for name, t in trackers.items()}
    return result, TrackingExample(run0, histories)
