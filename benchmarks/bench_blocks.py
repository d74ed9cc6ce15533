"""One block of the default scenario costs the same whatever the total number of runs.

    python benchmarks/bench_blocks.py [--block 250] [--repeat 3]

Times ``run_block(scenario, 0)`` (simulate, filter, evaluate 250 runs) with the scenario's
total at 1 000 and at 1 000 000 runs, in one process, best of ``repeat``, interleaved, and, for the
record, what spawning every run's seed sequence up front (as the engine did before) costs at
each total. Prints a markdown table for benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import trackkit.scenario as S
from trackkit.experiments.montecarlo import plan_of, run_block, with_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--block", type=int, default=250)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    base = S.load(S.DEFAULT)
    totals = (1_000, 1_000_000)
    scenarios = {}
    for total in totals:
        d = with_run(base, total, None).model_dump()
        d["run"]["block"] = a.block
        scenarios[total] = S.parse(d)
        plan_of(scenarios[total])  # compiled once, outside the timing, as after block 0
    block = {t: np.inf for t in totals}
    spawn = {t: np.inf for t in totals}
    for _ in range(a.repeat):  # interleaved, so that a change of load hits both totals
        for t in totals:
            t0 = time.perf_counter()
            run_block(scenarios[t], 0)
            block[t] = min(block[t], time.perf_counter() - t0)
            t0 = time.perf_counter()
            np.random.SeedSequence(0).spawn(t)
            spawn[t] = min(spawn[t], time.perf_counter() - t0)
    rows = [(t, block[t], spawn[t]) for t in totals]
    print(f"| total runs | one block of {a.block} runs (s) | spawning every run's seed "
          "up front, as before (s) |")
    print("|---|---|---|")
    for total, block, spawn in rows:
        print(f"| {total:,} | {block:.3f} | {spawn:.3f} |")
    print(f"\nratio of the block times (1 000 000 / 1 000): {rows[1][1] / rows[0][1]:.3f}")


if __name__ == "__main__":
    main()
