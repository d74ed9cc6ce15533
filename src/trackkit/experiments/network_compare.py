"""Two network Monte Carlos of the same runs side by side (Jalalipoor and Kardehi Moghaddam 2021):
steered against straight courses, or a lossy network against a lossless one.

Both must be the same scenario's runs 0 .. R-1 from the same seed, so that run r has the
same targets and bearing noise in both (``experiments.network_mc``): the comparison is paired. Per
agent and run, the position MSE over the window (executions where a target is held, pooled
over the targets) gives ``d_r = MSE_a,r - MSE_b,r``; the paired t statistic

    t = mean(d) / (std(d) / sqrt(R')),    R' runs where both agents hold something,

with a two-sided p-value from Student's t with R' - 1 degrees of freedom, says whether a's
error differs from b's at the stated confidence. The t test is on the per-run MSE, so one
run with a lost track weighs heavily; the share of runs where a is lower is reported beside
it as the robust view. ``ratio`` is the pooled RMSE ratio a / b over runs, executions and
targets (``NetworkMonteCarlo.window_rmse``).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from trackkit.experiments.network_mc import NetworkMonteCarlo

__all__ = ["PairedComparison", "compare_networks", "run_mse"]

Array = NDArray[np.float64]


class PairedComparison(NamedTuple):
    """``a`` against ``b`` per agent (arrays ``(A,)``) and pooled over the agents
    (``*_all``: the per-run MSE averaged over the agents).

    ``rmse_a``, ``rmse_b``: pooled position RMSE over the window (m); ``ratio`` = a / b;
    ``lower_share``: fraction of the paired runs where a's MSE is below b's; ``t``, ``p``:
    the paired t statistic and its two-sided p-value; ``runs``: the paired runs;
    ``verdict``: "lower", "higher" or "no difference" (a against b at ``confidence``);
    ``held_a``, ``held_b``: fraction of runs ending with every target held."""

    label_a: str
    label_b: str
    window: tuple[float, float]
    confidence: float
    rmse_a: Array
    rmse_b: Array
    ratio: Array
    lower_share: Array
    t: Array
    p: Array
    runs: NDArray[np.int64]
    verdict: list[str]
    held_a: Array
    held_b: Array
    rmse_a_all: float
    rmse_b_all: float
    ratio_all: float
    lower_share_all: float
    t_all: float
    p_all: float
    verdict_all: str


def run_mse(mc: NetworkMonteCarlo, which: Literal["first", "last", "all"] = "last") -> Array:
    """``(R, A)``: each run's position MSE over the window, pooled over the executions and
    targets where a target is held (nan where nothing is held)."""
    e = mc.err["pos"][:, :, mc.window(which)]
    sq = np.square(e)
    n = np.sum(~np.isnan(sq), axis=(2, 3))
    total = np.nansum(sq, axis=(2, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def _paired(d: Array, confidence: float) -> tuple[float, float, float, int, str]:
    """Lower share, t, p, paired runs and verdict for the differences d (nan dropped)."""
    d = d[~np.isnan(d)]
    n = d.size
    if n < 2:
        return np.nan, np.nan, np.nan, n, "no difference"
    share = float(np.mean(d < 0))
    sd = float(np.std(d, ddof=1))
    if sd == 0.0:
        t = 0.0 if np.all(d == 0) else np.copysign(np.inf, float(np.mean(d)))
        p = 1.0 if t == 0.0 else 0.0
    else:
        t = float(np.mean(d) / (sd / np.sqrt(n)))
        p = float(2.0 * stats.t.sf(abs(t), n - 1))
    verdict = ("no difference" if p >= 1.0 - confidence else ("lower" if t < 0 else "higher"))
    return share, t, p, n, verdict


def compare_networks(a: NetworkMonteCarlo, b: NetworkMonteCarlo, *, label_a: str,
                     label_b: str, which: Literal["first", "last", "all"] = "last",
                     confidence: float = 0.95) -> PairedComparison:
    """Paired comparison of two Monte Carlos of the same runs (module docstring)."""
    if not 0.5 <= confidence < 1.0:
        raise ValueError(f"confidence = {confidence!r}; expected a value in [0.5, 1)")
    for what, u, v in (("scenario", a.name, b.name), ("runs", a.runs, b.runs),
                       ("seed", a.seed, b.seed), ("duration", a.duration, b.duration),
                       ("agents", a.n_agents, b.n_agents), ("targets", a.n_targets,
                                                            b.n_targets)):
        if u != v:
            raise ValueError(f"compare_networks: {what} differs ({u!r} against {v!r}); "
                             "expected two Monte Carlos of the same runs")
    ma, mb = run_mse(a, which), run_mse(b, which)
    A = a.n_agents
    per = [_paired(ma[:, i] - mb[:, i], confidence) for i in range(A)]
    pooled = _paired(np.mean(ma, 1) - np.mean(mb, 1), confidence)
    ra, rb = a.window_rmse("pos", which, pooled=True), b.window_rmse("pos", which, pooled=True)
    all_a = float(np.sqrt(np.nanmean(np.square(a.err["pos"][:, :, a.window(which)]))))
    all_b = float(np.sqrt(np.nanmean(np.square(b.err["pos"][:, :, b.window(which)]))))
    window = (0.0, a.duration) if which == "all" else a.window_s(which)
    return PairedComparison(
        label_a=label_a, label_b=label_b, window=window, confidence=confidence,
        rmse_a=ra, rmse_b=rb, ratio=ra / rb,
        lower_share=np.array([p[0] for p in per]), t=np.array([p[1] for p in per]),
        p=np.array([p[2] for p in per]), runs=np.array([p[3] for p in per], np.int64),
        verdict=[p[4] for p in per],
        held_a=a.held_final.mean(0), held_b=b.held_final.mean(0),
        rmse_a_all=all_a, rmse_b_all=all_b, ratio_all=all_a / all_b,
        lower_share_all=pooled[0], t_all=pooled[1], p_all=pooled[2],
        verdict_all=pooled[4],
    )
