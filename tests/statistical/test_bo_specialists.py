"""The bearings-only specialists on the bundled ``bo-cv`` (500 runs, its
seed 2026), beside the EKF, IEKF, UKF and CKF.

The claims: today's best filter, the CKF, has a position RMSE of 1.39 times the PCRLB (the
report's average over t >= 900 s; 3 000 runs); the range-parameterised EKF, the modified-polar
EKF and the particle filter each do better, the best of them within 1.15 times the PCRLB; none
diverges; the report ranks them and gives their NEES.

The runs are cut into 10 blocks of 50 (``run.block``), each filtered and scored by the Monte
Carlo engine (``run_block``) and combined as the engine combines them, so every number is the
engine's for that block size (the Gaussian filters' are the same for any block size; the
PF's draws are not). Confidence: a filter beats another when its position MSE over the
window is lower and the paired difference over the 10 blocks (same truths and bearings for
every filter) is more than 3 standard errors from zero (one-sided, t with 9 degrees of
freedom: 99.2 %).

The PF is the bootstrap PF of bo-cv.toml: 2 000 particles from the Gaussian prior
conditioned on the first bearing (prior = "bearing"), regularised with Liu and West's
shrinkage. Without the shrinkage the kernel widens its cloud by (1 + h^2) at every
resampling (1.53, ANEES 2.5, behind the CKF); with it but drawn from the prior itself, a run
whose prior lies three sigmas off collapses onto the few draws near the first bearing (2 of
500 runs diverge at 5 000 particles). As configured: 1.29 here, 1.24 against the CKF's 1.34
on 1 000 runs of seed 2027, no run diverged in either.

What does not hold is a strict xfail with the numbers (500 runs, seed 2026, block 50): the
best, the MPEKF, is at 1.23, not 1.15. Within the window it reaches 1.10-1.12 over 900-1 000 s,
just after the manoeuvre, and then every filter drifts away from the bound along the
observer's second straight leg (the MPEKF to 1.47 at 1 795 s, the PF and the CKF alike, and a
20 000-particle PF too), while the bound settles at 317 m: the PCRLB, which takes every
bearing's information at the true state, is not tight once the target's process noise
erodes the range that the manoeuvre made observable (test_every_filter_drifts_from_the_bound).

Divergence is the engine's rule (``trackkit.eval.metrics``): a run whose estimate is not
finite, or whose NEES exceeds 100 chi2.ppf(1 - 1e-6, 4) = 3 400, at its last step or on more
than a quarter of its steps.

Slow: about 80 s of CPU, most of it the PF (500 runs x 2 000 particles x 360 steps); the
six Gaussian filters take about 15 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import combine, run_block
from trackkit.report.tables import summary

pytestmark = pytest.mark.slow

RUNS, BLOCK = 500, 50
SPECIALISTS = ("RPEKF", "MPEKF", "PF")
#: the CKF efficiency of an earlier measurement (3 000 runs) and our target for the best
#: specialist
CKF_EARLIER, TARGET = 1.39, 1.15


@pytest.fixture(scope="module")
def bo_cv():
    """The engine's result on 500 runs of bo-cv, and each filter's position MSE over the
    averaging window per block ``(20,)``."""
    d = S.load("bo-cv").model_dump()
    d["run"].update(runs=RUNS, block=BLOCK)
    s = S.parse(d, "bo-cv")
    assert s.run.seed == 2026
    parts = [run_block(s, b) for b in range(RUNS // BLOCK)]
    result = combine(s, parts)
    block_mse = {name: np.array([p.metrics[name].mse("position")[result.start:].mean()
                                 for p in parts]) for name in result.filters}
    print(f"\nbo-cv, {RUNS} runs, block {BLOCK}: position RMSE / PCRLB over t >= "
          f"{s.report.average_from_s:g} s, ANEES, diverged runs, paired t against the CKF")
    for name, f in result.filters.items():
        t = paired_t(block_mse, name, "CKF") if name != "CKF" else math.nan
        print(f"  {name:6s} {result.efficiency(name, 'position'):6.3f} {f.anees:9.3f} "
              f"{f.diverged:4d} {t:7.2f}")
    return result, block_mse


def efficiency(result, name: str) -> float:
    return result.efficiency(name, "position")


def paired_t(block_mse: dict, better: str, worse: str) -> float:
    """Mean over blocks of ``MSE(worse) - MSE(better)`` over its standard error."""
    d = block_mse[worse] - block_mse[better]
    return float(d.mean() / (d.std(ddof=1) / math.sqrt(d.size)))


def test_the_ckf_is_where_an_earlier_measurement_put_it(bo_cv):
    """1.39 at 3 000 runs; these 500 runs give 1.398."""
    result, _ = bo_cv
    assert result.runs == RUNS
    assert abs(efficiency(result, "CKF") - CKF_EARLIER) < 0.03


@pytest.mark.parametrize("name", ["RPEKF", "MPEKF"])
def test_rpekf_and_mpekf_beat_the_ckf(bo_cv, name):
    """RPEKF 1.30 and MPEKF 1.23 against the CKF's 1.40 (paired t 5.2 and 5.1)."""
    result, block_mse = bo_cv
    assert efficiency(result, name) < efficiency(result, "CKF")
    assert paired_t(block_mse, name, "CKF") > 3.0


def test_the_pf_beats_the_ckf(bo_cv):
    """1.29 against 1.40 (paired t = 4.8); 1.24 against 1.34 on 1 000 runs of seed 2027."""
    result, block_mse = bo_cv
    assert efficiency(result, "PF") < efficiency(result, "CKF")
    assert paired_t(block_mse, "PF", "CKF") > 3.0


def test_what_holds_of_the_pf(bo_cv):
    """It loses no run and its covariance is consistent with its error: ANEES 4.38 for a
    4-state (3.0-6.0 allowed: the plain regularised PF, whose kernel widens the cloud at every
    resampling, is at 2.5 and fails this)."""
    result, _ = bo_cv
    f = result.filters["PF"]
    assert f.diverged == 0
    assert 3.0 < f.anees < 6.0
    assert efficiency(result, "PF") < 1.35


@pytest.mark.xfail(strict=True, reason="the best specialist, the MPEKF, is at 1.23 x the "
                   "PCRLB (PF 1.29, RPEKF 1.30; 500 runs, seed 2026), not within 1.15: it is at "
                   "1.10-1.12 over 900-1 000 s, then every filter (a 20 000-particle PF too) "
                   "drifts from the bound along the second leg, the MPEKF to 1.47 at 1 795 s, "
                   "while the bound settles at 317 m: the bound is not tight there")
def test_the_best_specialist_is_within_1_15_of_the_pcrlb(bo_cv):
    result, _ = bo_cv
    assert min(efficiency(result, n) for n in SPECIALISTS) <= TARGET


def test_every_filter_drifts_from_the_bound(bo_cv):
    """Why the window's average misses 1.15: each filter's RMSE over the PCRLB is lowest
    just after the manoeuvre and grows along the second leg. Measured (t = 900, 1 795 s):
    MPEKF 1.10, 1.47; PF 1.17, 1.53; RPEKF 1.18, 1.51; CKF 1.27, 1.64. The best is within
    1.15 at 900 s, and every ratio at the end exceeds its value there by over 20 %."""
    result, _ = bo_cv
    t = np.asarray(result.times)
    bound = np.asarray(result.pcrlb["position"])
    at = {s_: int(np.searchsorted(t, s_)) for s_ in (900.0, 1795.0)}
    ratio = {n: np.asarray(result.filters[n].rmse["position"]) / bound
             for n in ("CKF", *SPECIALISTS)}
    assert min(r[at[900.0]] for r in ratio.values()) < TARGET
    for name, r in ratio.items():
        assert r[at[1795.0]] > 1.2 * r[at[900.0]], name


def test_what_holds_of_the_best_specialist(bo_cv):
    """The MPEKF is the best filter of bo-cv, within 1.25 x the PCRLB (1.23), and better
    than the RPEKF (paired)."""
    result, block_mse = bo_cv
    eff = {n: efficiency(result, n) for n in result.filters}
    assert min(eff, key=eff.get) == "MPEKF"
    assert eff["MPEKF"] < 1.25
    assert paired_t(block_mse, "MPEKF", "RPEKF") > 3.0


def test_no_specialist_diverges(bo_cv):
    result, _ = bo_cv
    for name in SPECIALISTS:
        f = result.filters[name]
        assert f.diverged == 0, name
        assert np.isfinite(f.rmse["position"]).all(), name


def test_the_report_ranks_them_and_gives_their_nees(bo_cv):
    """The summary table has a row per filter with its RMSE/PCRLB and ANEES as the result
    holds them; the Gaussian specialists' ANEES is near the state's 4 (RPEKF 4.1, MPEKF
    4.4; the CKF's 5.1)."""
    result, _ = bo_cv
    table = summary(result)
    col = {h: i for i, h in enumerate(table.headers)}
    rows = {r[0]: r for r in table.rows}
    for name in ("EKF", "IEKF", "UKF", "CKF", *SPECIALISTS):
        row = rows[name]
        assert float(row[col["RMSE/PCRLB\nposition"]]) == pytest.approx(
            efficiency(result, name), abs=0.006)
        assert float(row[col["ANEES"]]) == pytest.approx(result.filters[name].anees, rel=1e-2)
    for name in ("RPEKF", "MPEKF"):
        assert 3.0 < result.filters[name].anees < 5.0
    place = {n: int(rows[n][col["rank"]]) for n in result.filters if rows[n][col["rank"]] != "-"}
    assert sorted(place, key=place.get) == sorted(place, key=lambda n: efficiency(result, n))
    assert place["MPEKF"] == 1
