"""Innovation covariance matching and the thesis metrics J1-J4 of Naseri Solhdar (eqs 3-15 to
3-18), accumulated per run as the filter streams.

For every filter, whatever its kind, the innovations ``r_k`` and their covariance ``S_k`` give
the windowed covariance ``C_k`` (N = 25, zero until full) and ``DOM_k = S_k - C_k``
(:mod:`trackkit.filters.fuzzy`). Per run, over the K steps with a measurement:

- ``J1(i) = sqrt((1/K) sum_k (z_a - z_m)_i^2)``: the raw measurement noise (noise-free minus
  measured; filter-independent);
- ``J2(i) = sqrt((1/K) sum_k (z_a - h(x_e))_i^2)``: noise-free minus estimated measurement;
- ``J3(j) = sqrt((1/K) sum_k (x_a - x_e)_j^2)``: the state RMSE of one run (the thesis calls
  it J1 in chapters 4 and 5);
- ``J4 = alpha sum_i sqrt((1/K) sum_k DOM_k(i,i)^2)``: the tuning cost of the fuzzy system
  (alpha 1000 in chapter 3, 5000 after). The thesis does not say which DOM entries enter J4
  for a matrix DOM; the sum over the diagonal is the printed cost's form, and the thesis's
  J4 and cost values are of the same size (1246 and 983 for its tuned filter).

Angle channels are wrapped. Monte Carlo reports the mean of these per-run values (and run 0,
the "one fixed-seed run" of the thesis's tables).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from trackkit.filters.adaptive import AdaptiveBelief, push_innovation
from trackkit.filters.fuzzy import dom_cost, matching_covariance
from trackkit.models.protocols import SensorModel

Array = NDArray[np.float64]

__all__ = ["MatchingMetrics", "noise_in_use", "measurement_noise_rms"]


def noise_in_use(belief: Any, R0: Array) -> Array:
    """The R the filter uses at its next update: an adaptive belief's own estimate (fuzzy,
    Sage-Husa, AMCEKF scale) or else R0, the R the filter was given."""
    if isinstance(belief, AdaptiveBelief):
        return belief.r_scale[..., None, None] * R0
    R = getattr(belief, "R", None)
    return R if R is not None and R.shape[-1] else R0


def measurement_noise_rms(z: Array, z_true: Array, sensor: SensorModel) -> Array:
    """J1 of each run ``(B, m)`` from measurements ``z (T, B, m)`` and their noise-free
    values ``z_true (T, B, m)``; steps without a measurement are left out."""
    e = sensor.residual(z_true, z)
    return np.sqrt(np.nanmean(e * e, axis=0))


class MatchingMetrics:
    """Per-run running sums for J2, J3 and J4 of one filter over a block of B runs, and the
    run-0 logs of diag R, S, C and DOM (``log=True``)."""

    def __init__(self, runs: int, n: int, m: int, steps: int, window: int = 25,
                 log: bool = False) -> None:
        self.window = window
        self.residuals = np.zeros((runs, window, 0))
        self.count = np.zeros(runs, np.int64)
        self.steps = np.zeros((runs, 1))
        self.j2 = np.zeros((runs, m))
        self.j3 = np.zeros((runs, n))
        self.dom = np.zeros((runs, m))
        self.logs = {k: np.full((steps, m), np.nan) for k in ("R", "S", "C", "DOM")} if log \
            else None

    def add(self, k: int, truth: Array, mean: Array, innovation, R: Array,
            sensor: SensorModel) -> None:
        """Step k: true states ``truth (B, n)``, estimates ``mean (B, n)``, the update's
        innovation, the R it used ``(..., m, m)`` and the (true) sensor of the step."""
        r, S = innovation.nu, innovation.cov
        keep = ~np.isnan(r).any(-1)
        B = truth.shape[0]
        self.residuals, self.count = push_innovation(
            self.residuals, self.count, r, keep, self.window, (B,), "MatchingMetrics")
        C = matching_covariance(self.residuals, self.count)
        dom = np.diagonal(np.broadcast_to(S, C.shape) - C, axis1=-2, axis2=-1)
        e_z = sensor.residual(sensor.h(truth), sensor.h(mean))
        w = keep[:, None]
        self.steps += w
        self.j2 += np.where(w, e_z * e_z, 0.0)
        self.dom += np.where(w, dom * dom, 0.0)
        e_x = truth - mean
        self.j3 += np.where(w, e_x * e_x, 0.0)
        if self.logs is not None:
            diag = np.diagonal  # run 0 only
            self.logs["R"][k] = diag(np.broadcast_to(R, C.shape)[0])
            self.logs["S"][k] = diag(np.broadcast_to(S, C.shape)[0])
            self.logs["C"][k] = diag(C[0])
            self.logs["DOM"][k] = dom[0]

    def per_run(self, alpha: float) -> dict[str, Array]:
        """``J2 (B, m)``, ``J3 (B, n)`` and ``J4 (B,)`` of each run."""
        K = np.maximum(self.steps, 1)
        return {"J2": np.sqrt(self.j2 / K), "J3": np.sqrt(self.j3 / K),
                "J4": dom_cost(self.dom / K, 1, alpha)}
