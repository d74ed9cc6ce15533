"""The Doppler-bearing studies' jackknife blocks: ten blocks of ten runs, one by one and
filtered together.

    python benchmarks/bench_dbt_blocks.py [--scenario dbt-approaching-misspecified]
                                          [--repeat 3] [--one-by-one-only]

Times ``run_blocks(scenario, blocks 0-9)`` of 100 runs in blocks of 10 (five filters, 2000
steps: what ``tests/statistical/test_dbt_premise.py`` runs per geometry), one block at a time
and with ``together=True``, and one block of 100 runs for reference, in one process, best of
``repeat``, interleaved; and each filter's seconds of one block of ten. ``--one-by-one-only``
times what an earlier revision has (no ``together``), for a before/after of the same code
path from two checkouts. Prints markdown rows for benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import trackkit.scenario as S
from trackkit.experiments.montecarlo import plan_of, run_block, run_blocks


def _scenario(name: str, block: int) -> S.Scenario:
    d = S.load(name).model_dump()
    d["run"]["block"] = block
    return S.parse(d, name)


def _seconds(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="dbt-approaching-misspecified")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--one-by-one-only", action="store_true")
    a = ap.parse_args()
    tens, hundred = _scenario(a.scenario, 10), _scenario(a.scenario, 100)
    for s in (tens, hundred):
        plan_of(s)  # compiled once, outside the timing
    blocks = list(range(10))
    cases = {"ten blocks of 10, one by one": lambda: run_blocks(tens, blocks)}
    if not a.one_by_one_only:
        cases["ten blocks of 10, together"] = lambda: run_blocks(tens, blocks, together=True)
        cases["one block of 100"] = lambda: run_block(hundred, 0)
    best = {k: np.inf for k in cases}
    for _ in range(a.repeat):  # interleaved, so that a change of load hits every case
        for k, fn in cases.items():
            best[k] = min(best[k], _seconds(fn))
    print(f"| {a.scenario}, 100 runs | seconds (best of {a.repeat}) |\n|---|---:|")
    for k, v in best.items():
        print(f"| {k} | {v:.2f} |")
    seconds = run_block(tens, 0).seconds
    print("\nfilter seconds in one block of ten: " + ", ".join(
        f"{f} {v:.3f}" for f, v in seconds.items()))


if __name__ == "__main__":
    main()
