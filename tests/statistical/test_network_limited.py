"""The network's statistics on the bundled ``net-limited`` at 100 runs (seed 2026, steered):
agent 2 tracks target 3 from its neighbours' data alone, the agents keep their neighbour
distances in the band, and 10% message loss against the lossless network (the same runs:
targets and bearing noise equal; the loss stream is the run's own).

Confidence: the observed fractions are asserted against our thresholds with the
Clopper-Pearson 95% interval printed beside them; the loss comparison is paired over runs
(``experiments.network_compare``, 95%).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import beta, binomtest

from trackkit.experiments.network_compare import compare_networks
from trackkit.experiments.network_mc import run_network_mc
from trackkit.scenario.network import load_network

pytestmark = pytest.mark.slow

RUNS, SEED, LOSS = 100, 2026, 0.1
_MC: dict[float, object] = {}


def _mc(loss: float):
    if loss not in _MC:
        sc = load_network("net-limited")
        sc = sc.model_copy(update={"network": sc.network.model_copy(update={"loss": loss})})
        # one block of all the runs: the same bits as any block size, a fifth less time
        _MC[loss] = run_network_mc(sc, runs=RUNS, seed=SEED, keep_example=False, block=RUNS)
    return _MC[loss]


def _interval(k: int, n: int) -> tuple[float, float]:
    lo = beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def test_agent_2_tracks_target_3_from_neighbours_alone():
    """Agent 2 never measures target 3 (beyond its 25 km range at every execution), yet its
    final position error on it is below 5% of the agent-target distance in at least 90% of
    the runs (a run without a track of target 3 at the end counts as a failure)."""
    mc = _mc(0.0)
    assert np.all(mc.final_range[:, 1, 2] > 25_000.0)
    final = mc.err["pos"][:, 1, -1, 2]
    rel = final / mc.final_range[:, 1, 2]
    ok = int(np.sum(np.nan_to_num(rel, nan=np.inf) < 0.05))
    print(f"agent 2, target 3: final error below 5% of the distance in {ok}/{RUNS} runs "
          f"(95% CI {_interval(ok, RUNS)}); median {np.nanmedian(rel):.4f}, 90th percentile "
          f"{np.nanpercentile(rel, 90):.4f}; distance {mc.final_range[:, 1, 2].min():.0f}-"
          f"{mc.final_range[:, 1, 2].max():.0f} m")
    assert ok >= 0.9 * RUNS


def test_neighbour_distances_stay_in_the_band():
    """Every pair of agents stays within [0.05, 0.95] of the communication range at every
    execution instant of every run."""
    mc = _mc(0.0)
    low, high = mc.spacing[:, 0].min(), mc.spacing[:, 1].max()
    print(f"agent-pair distance over the communication range: {low:.4f} to {high:.4f}")
    assert 0.05 <= low and high <= 0.95


def test_ten_percent_message_loss_within_1_5x_of_lossless():
    """With 10% of the deliveries lost, each agent's position RMSE over the last 20% stays
    within 1.5x of the lossless run's; the losses are counted (sent = delivered + lost, and
    the lost share is consistent with 10% at 99%)."""
    clean, lossy = _mc(0.0), _mc(LOSS)
    c = compare_networks(lossy, clean, label_a="10% loss", label_b="lossless")
    print(f"\nlossy {np.round(c.rmse_a)} m, lossless {np.round(c.rmse_b)} m, ratio "
          f"{np.round(c.ratio, 3)}; lossy lower in {c.lower_share} of runs, t "
          f"{np.round(c.t, 2)}, p {np.round(c.p, 3)}: {c.verdict}; held at the end lossy "
          f"{c.held_a}, lossless {c.held_b}")
    assert np.all(c.ratio < 1.5)
    assert np.all(lossy.sent == lossy.delivered + lossy.lost) and np.all(clean.lost == 0)
    sent, lost = int(lossy.sent.sum()), int(lossy.lost.sum())
    assert binomtest(lost, sent, LOSS).pvalue > 0.01
