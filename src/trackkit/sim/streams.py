"""One random stream per Monte Carlo run, built from the scenario's seed and the run's index.

Run r of a scenario with seed s draws from ``run_rng(s, r)``: the generator of child r of
``SeedSequence(s)``, built from (s, r) alone, so simulating a block of runs costs the same
whatever the total number of runs, and a run's data do not depend on which block or worker
draws them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["run_rng"]


def run_rng(seed: int, run: int) -> np.random.Generator:
    """The generator of run ``run``: child ``run`` of ``SeedSequence(seed)``, the same stream
    as ``SeedSequence(seed).spawn(run + 1)[run]`` without spawning the ones before it."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run,)))
