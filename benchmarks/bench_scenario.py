"""The default scenario at 1 000 Monte Carlo runs: time per run-step per filter.

    python benchmarks/bench_scenario.py [--runs 1000] [--workers 0]

Prints each filter's time per run-step (filter predict + update only) and the wall time of
the whole comparison (simulation, filtering, metrics and bound).
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

import trackkit.scenario as S
from trackkit.experiments.montecarlo import run_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=S.DEFAULT)
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=0)
    a = ap.parse_args()
    scenario = S.load(a.scenario)
    t0 = time.perf_counter()
    result = run_scenario(scenario, runs=a.runs, workers=a.workers or None)
    wall = time.perf_counter() - t0
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, numpy {np.__version__}")
    print(f"{result.scenario}: {result.runs} runs x {result.steps} steps, "
          f"workers={a.workers or 'in-process'}, wall {wall:.1f} s "
          f"({wall / (result.runs * result.steps) * 1e6:.2f} us per run-step, all filters, "
          "simulation and metrics included)")
    print(f"{'filter':8s} {'us/run-step':>12s} {'RMSE pos [m]':>13s} {'PCRLB [m]':>10s}")
    for name, f in result.filters.items():
        print(f"{name:8s} {f.seconds_per_step * 1e6:12.3f} {f.rmse_mean['position']:13.1f} "
              f"{result.pcrlb_mean['position']:10.1f}")


if __name__ == "__main__":
    main()
