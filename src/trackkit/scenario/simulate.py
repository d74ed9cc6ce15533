"""Truth and measurements of a compiled scenario, batched over runs, seeded per run.

Run r of a scenario with seed s draws from ``run_rng(s, r)``: the generator of child r of
``SeedSequence(s)``, built from (s, r) alone, so simulating a block costs the same whatever
the total number of runs. Per run, the draws come in a fixed order: the prior offset (n), the
process noise (T x n), the measurement noise (T x m) and the detection draws (T), so every
filter sees the same truth, measurements and prior offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.linalg import psd_factor
from trackkit.scenario.build import Plan
from trackkit.sim.kinematics import step as platform_step
from trackkit.sim.streams import run_rng

Array = NDArray[np.float64]

__all__ = ["BlockData", "simulate_block"]


@dataclass
class BlockData:
    """A block's truths ``(T + 1, B, n)``, measurements ``(T, B, m)`` (nan where missed) and
    prior offsets ``(B, n)``, standard-normal draws."""

    truth: Array
    z: Array
    prior_offset: Array

    def prior(self, P0: Array, mean0: Array | None = None) -> Gaussian:
        """The filters' prior of each run, ``N(m0, P0)``: ``m0 = x0 + L u`` with ``x0`` the
        run's true initial state, ``L L^T = P0`` and ``u`` its prior offset, so the prior is
        consistent with the truth; or the scenario's fixed ``mean0`` for every run."""
        B, n = self.prior_offset.shape
        m0 = (self.truth[0] + self.prior_offset @ np.linalg.cholesky(P0).T) if mean0 is None \
            else np.broadcast_to(mean0, (B, n)).copy()
        return Gaussian(m0, np.broadcast_to(P0, (B, n, n)).copy())


def simulate_block(plan: Plan, r0: int, r1: int, seed: int | None = None) -> BlockData:
    """Truth and measurements for runs r0..r1-1 (default seed: the scenario's ``run.seed``)."""
    s = plan.scenario
    seed = s.run.seed if seed is None else seed
    T, n, d = plan.steps, plan.n, plan.dim
    B = r1 - r0
    m = plan.sensors[0].dim_z
    u0 = np.empty((B, n))
    w = np.empty((T, B, n))
    e = np.empty((T, B, m))
    det = np.empty((T, B))
    for i in range(B):
        g = run_rng(seed, r0 + i)
        u0[i] = g.standard_normal(n)
        w[:, i] = g.standard_normal((T, n))
        e[:, i] = g.standard_normal((T, m))
        det[:, i] = g.random(T)
    truth = np.empty((T + 1, B, n))
    truth[0] = plan.x0
    kin = 2 * d
    for k in range(T):
        dt = plan.times[k + 1] - plan.times[k]
        L = psd_factor(np.asarray(plan.truth_motion.noise(truth[k], dt)), "truth process noise Q")
        if s.linear_system:
            nxt = plan.truth_motion.f(truth[k], dt)
        else:
            nxt = truth[k].copy()
            nxt[:, :kin] = platform_step(truth[k][:, :kin], plan.times[k], dt,
                                         plan.target_legs, d)
        truth[k + 1] = nxt + w[k] @ L.T
    z = np.empty((T, B, m))
    for k in range(T):
        sensor = plan.sensors[k]
        z[k] = sensor.h(truth[k + 1]) + e[k] @ np.linalg.cholesky(sensor.noise).T
        ang = np.asarray(sensor.angular)
        z[k][:, ang] = wrap(z[k][:, ang])
    if plan.p_detect < 1.0:
        z[det >= plan.p_detect] = np.nan
    return BlockData(truth, z, u0)
