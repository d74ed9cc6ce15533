"""A ``net-baseline`` Monte Carlo in process (Jalalipoor and Kardehi Moghaddam 2021): the time
per run with the runs one at a time and stepped together in blocks, in one process.

Runs ``--runs`` runs of the bundled ``net-baseline`` scenario through ``run_network_mc``
(steered agents, the centralised reference, scoring and the per-run PCRLB), as
``trackkit network net-baseline`` does, once per block size of ``--blocks`` (1 is one run at
a time, the loop before blocks), the sizes in turn for ``--rounds`` rounds; the best round of
each. Every block size gives the same numbers bit for bit (checked here on the scores).

For the largest block it also reports the time inside the batched kernels
(``network.lockstep.BATCHED``, each wrapped with a ``perf_counter`` pair) against the rest:
the agents' per-run program between its kernel calls, the simulation, message delivery, the
centralised filter, scoring and the bound.

    python benchmarks/bench_network.py [--runs 100] [--blocks 1 25] [--rounds 2] [--seed 2026]
                                       [--before SRC]

``--before SRC`` also times an earlier revision's ``run_network_mc`` (its ``src`` directory,
for example of a ``git worktree``) in a child process, in turn with the block sizes in each
round, its import outside the timing, and says whether its scores are this revision's bits.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

import numpy as np

from trackkit.experiments.network_mc import run_network_mc
from trackkit.network import lockstep
from trackkit.scenario.network import load_network


def timed_kernels() -> dict[str, float]:
    """Wrap every batched kernel so that its time adds up in the returned dict."""
    spent: dict[str, float] = defaultdict(float)
    for fn, many in list(lockstep.BATCHED.items()):
        def wrapper(calls, many=many, name=fn.__name__):
            t0 = time.perf_counter()
            try:
                return many(calls)
            finally:
                spent[name] += time.perf_counter() - t0
        lockstep.BATCHED[fn] = wrapper
    return spent


_BEFORE = """
import sys, time, numpy as np
from trackkit.experiments.network_mc import run_network_mc
from trackkit.scenario.network import load_network
sc = load_network("net-baseline")
t0 = time.perf_counter()
mc = run_network_mc(sc, runs=int(sys.argv[1]), seed=int(sys.argv[2]), keep_example=False)
wall = time.perf_counter() - t0
np.savez(sys.argv[3], wall=wall, gospa=mc.gospa, pos=mc.err["pos"], count=mc.count)
"""


def run_before(src: str, runs: int, seed: int) -> tuple[float, tuple]:
    """An earlier revision's Monte Carlo in a child process: its seconds and scores."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "before.npz")
        subprocess.run([sys.executable, "-c", _BEFORE, str(runs), str(seed), out], check=True,
                       env={**os.environ, "PYTHONPATH": src})
        with np.load(out) as f:
            return float(f["wall"]), (f["gospa"], f["pos"], f["count"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--blocks", type=int, nargs="+", default=[1, 25])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--before", metavar="SRC", help="an earlier revision's src directory")
    args = ap.parse_args()
    print(f"numpy {np.__version__}, python {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    sc = load_network("net-baseline")
    best: dict[int, float] = {}
    scores = {}
    before = np.inf
    for rnd in range(args.rounds):
        if args.before:
            wall, before_scores = run_before(args.before, args.runs, args.seed)
            before = min(before, wall)
            print(f"round {rnd + 1}, before: {wall:.1f} s, {wall / args.runs:.3f} s per run",
                  flush=True)
        for b in args.blocks:
            t0 = time.perf_counter()
            mc = run_network_mc(sc, runs=args.runs, seed=args.seed, keep_example=False,
                                block=b)
            wall = time.perf_counter() - t0
            best[b] = min(best.get(b, np.inf), wall)
            scores[b] = (mc.gospa, mc.err["pos"], mc.count)
            print(f"round {rnd + 1}, block {b}: {wall:.1f} s, {wall / args.runs:.3f} s per run",
                  flush=True)
    first = scores[args.blocks[0]]
    same = all(all(np.array_equal(x, y, equal_nan=True) for x, y in zip(first, v, strict=True))
               for v in scores.values())
    print(f"\nnet-baseline, {args.runs} runs, seed {args.seed}, steered; scores bit for bit "
          f"equal across block sizes: {same}\n")
    print("| runs stepped together | s per run (best of rounds) | against one at a time |"
          + (" against before |" if args.before else ""))
    print("|---:|---:|---:|" + ("---:|" if args.before else ""))
    ref = best.get(1)
    if args.before:
        same_before = all(np.array_equal(x, y, equal_nan=True)
                          for x, y in zip(first, before_scores, strict=True))
        print(f"| before, one at a time | {before / args.runs:.3f} | - | 1.00x |")
    for b in args.blocks:
        ratio = f"{ref / best[b]:.2f}x" if ref else "-"
        vs = f" {before / best[b]:.2f}x |" if args.before else ""
        print(f"| {b} | {best[b] / args.runs:.3f} | {ratio} |{vs}")
    if args.before:
        print(f"\nthe earlier revision's scores bit for bit these: {same_before}")
        for name, x, y in zip(("GOSPA", "position error", "count"), first, before_scores,
                              strict=True):
            print(f"  {name}: mean {np.nanmean(x):.6g} against {np.nanmean(y):.6g}, largest "
                  f"difference of a run-step {np.nanmax(np.abs(x - y)):.3g}")

    b = max(args.blocks)
    spent = timed_kernels()
    t0 = time.perf_counter()
    run_network_mc(sc, runs=args.runs, seed=args.seed, keep_example=False, block=b)
    wall = time.perf_counter() - t0
    inside = sum(spent.values())
    print(f"\nblock {b}, kernels timed: {wall:.1f} s; inside the batched kernels "
          f"{inside:.1f} s ({100 * inside / wall:.0f}%), the rest {wall - inside:.1f} s\n")
    print("| batched kernel | s per run |")
    print("|---|---:|")
    for name, s in sorted(spent.items(), key=lambda kv: -kv[1]):
        print(f"| {name} | {s / args.runs:.3f} |")


if __name__ == "__main__":
    main()
