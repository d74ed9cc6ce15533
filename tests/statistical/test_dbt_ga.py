"""The GA initialiser on the three bundled Doppler-bearing scenarios (Hashemi and Alfi
2019, section 4-2, Fig. 17).

Each scenario's own truth and measurements (its plan and seeded simulation, 20 runs) feed the
GA (population 50, 200 generations, crossover 0.8, mutation 0.05) over the first 800 s,
averaged in blocks of 25 (`trackkit.filters.initialise`: range is not observable from a few
tens of measurements, so the paper's "first measurements" must be hundreds here).
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import plan_of
from trackkit.filters.initialise import ga_initial_position
from trackkit.scenario.simulate import simulate_block

K, RUNS = 800, 20
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", ["dbt-approaching", "dbt-receding", "dbt-observer-manoeuvre"])
def test_ga_initial_position_error_below_1000_m(name):
    plan = plan_of(S.load(name))
    data = simulate_block(plan, 0, RUNS)
    rngs = [np.random.default_rng([plan.scenario.run.seed, r, 1]) for r in range(RUNS)]
    result = ga_initial_position(data.z[:K], plan.sensors[:K], plan.filter_motions[0],
                                 plan.dt, rngs=rngs, block=25)
    error = np.linalg.norm(result.best_x - data.truth[0][:, :2], axis=-1)
    print(name, "GA initial position error [m]: median", np.median(error).round(),
          "95th", np.percentile(error, 95).round(), "max", error.max().round())
    # the paper's claim, at the 95% level we set
    assert np.mean(error < 1000.0) >= 0.95
