"""A ``net-baseline`` Monte Carlo in-process (Jalalipoor and Kardehi Moghaddam 2021): the time per
run and the share of it in each phase of the agents' program.

Runs ``--runs`` runs of the bundled ``net-baseline`` scenario through ``run_network_mc``
(steered agents, the centralised reference, scoring and the per-run PCRLB), as
``trackkit network net-baseline`` does, in one process. Each phase is timed by wrapping the
function that does it with a ``perf_counter`` pair (a few microseconds per call, against
milliseconds per call inside), so the shares add up to the agents' part of the run:

- association: ``agents.associate`` (CV prediction to the scan time, measurement prediction,
  gate, the saturating cost and Munkres), once per source per execution;
- course control: ``Agent.steer`` (the three sub-objectives, the distance constraints, the
  turn-rate limit and the blend);
- composite measurement: ``agents.composites`` (the batched Gauss-Newton fit);
- combination: ``agents.combine_with_neighbours`` (track-to-track matching and diffusion);
- initiation: ``Agent._initiate``;
- the rest of ``Agent.step`` (prediction, update, timers, pruning, the message);
- outside the agents: the simulation, message delivery, the centralised reference, scoring
  and the bound.

    python benchmarks/bench_network.py [--runs 100] [--seed 2026] [--straight]
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections import defaultdict

import numpy as np

from trackkit.experiments.network_mc import run_network_mc
from trackkit.network import agents
from trackkit.scenario.network import load_network

spent: dict[str, float] = defaultdict(float)
calls: dict[str, int] = defaultdict(int)


def timed(owner, name: str, label: str) -> None:
    """Replace ``owner.name`` by a wrapper that adds its time to ``spent[label]``."""
    real = getattr(owner, name)

    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return real(*args, **kwargs)
        finally:
            spent[label] += time.perf_counter() - t0
            calls[label] += 1

    setattr(owner, name, wrapper)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--straight", action="store_true")
    args = ap.parse_args()

    print(f"numpy {np.__version__}, python {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} CPUs")
    timed(agents, "associate", "association")
    timed(agents.Agent, "steer", "course control")
    timed(agents, "composites", "composite measurement")
    timed(agents, "combine_with_neighbours", "combination")
    timed(agents.Agent, "_initiate", "initiation")
    timed(agents.Agent, "step", "agent step (all)")

    sc = load_network("net-baseline")
    t0 = time.perf_counter()
    mc = run_network_mc(sc, runs=args.runs, seed=args.seed, steering=not args.straight,
                        keep_example=False)
    wall = time.perf_counter() - t0

    inside = spent["agent step (all)"]
    phases = ["association", "composite measurement", "combination", "initiation"]
    rest_step = inside - sum(spent[p] for p in phases)
    agent_total = inside + spent["course control"]
    outside = wall - agent_total
    print(f"\nnet-baseline, {args.runs} runs, seed {args.seed}, "
          f"{'straight' if args.straight else 'steered'}: {wall:.1f} s, "
          f"{wall / args.runs:.2f} s per run (network run alone "
          f"{mc.seconds.mean():.2f} s, scoring and bound {(mc.wall - mc.seconds).mean():.2f} s)"
          "\n")
    print("| phase | calls per run | ms per call | s per run | share of the run |")
    print("|---|---:|---:|---:|---:|")
    rows = [(p, spent[p], calls[p]) for p in phases + ["course control"]]
    rows += [("rest of the agent step", rest_step, calls["agent step (all)"]),
             ("outside the agents", outside, 0)]
    for label, s, n in rows:
        per_call = f"{1e3 * s / n:.2f}" if n else "—"
        print(f"| {label} | {n / args.runs:.0f} | {per_call} | {s / args.runs:.3f} | "
              f"{100 * s / wall:.1f}% |")
    print(f"\nassociation and course control together: "
          f"{100 * (spent['association'] + spent['course control']) / wall:.1f}% of the run")


if __name__ == "__main__":
    main()
