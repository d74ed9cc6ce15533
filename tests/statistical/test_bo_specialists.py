"""Issue 13, item 4: the bearings-only specialists on the bundled ``bo-cv`` (500 runs, its
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

What does not hold is a strict xfail with the numbers (500 runs, seed 2026, block 50): the PF
(2 000 particles, regularised) is at 1.53 against the CKF's 1.40, and the best, the MPEKF, at
1.22, not 1.15. Why (bo-cv.toml's notes): trackkit's bootstrap PF does not pass the CKF even
with 10 000 particles (1.46 on 100 runs where the CKF has 1.40); a kernel shrunk towards the
mean (Liu-West) brings 10 000 particles to 1.27 (500 runs), and that PF, close to the optimal
estimator, is itself above 1.15: the bound is not tight on this geometry.

Divergence is the engine's rule (``trackkit.eval.metrics``): a run whose estimate is not
finite, or whose NEES exceeds 100 chi2.ppf(1 - 1e-6, 4) = 3 400, at its last step or on more
than a quarter of its steps.

Slow: about 120 s of CPU, nearly all of it the PF (500 runs x 2 000 particles x 360 steps);
the six Gaussian filters take about 15 s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.eval.montecarlo import combine, run_block
from trackkit.report.tables import summary

pytestmark = pytest.mark.slow

RUNS, BLOCK = 500, 50
SPECIALISTS = ("RPEKF", "MPEKF", "PF")
#: the issue's CKF efficiency (3 000 runs) and its target for the best specialist
CKF_ISSUE, TARGET = 1.39, 1.15


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


def test_the_ckf_is_where_the_issue_measured_it(bo_cv):
    """1.39 at 3 000 runs; these 500 runs give 1.398."""
    result, _ = bo_cv
    assert result.runs == RUNS
    assert abs(efficiency(result, "CKF") - CKF_ISSUE) < 0.03


@pytest.mark.parametrize("name", ["RPEKF", "MPEKF"])
def test_rpekf_and_mpekf_beat_the_ckf(bo_cv, name):
    """RPEKF 1.30 and MPEKF 1.22 against the CKF's 1.40 (paired t 5.2 and 5.5)."""
    result, block_mse = bo_cv
    assert efficiency(result, name) < efficiency(result, "CKF")
    assert paired_t(block_mse, name, "CKF") > 3.0


@pytest.mark.xfail(strict=True, reason="the PF (2 000 particles, regularised) is at 1.53 x "
                   "the PCRLB against the CKF's 1.40 (500 runs, seed 2026, block 50; paired "
                   "t = -4.9): its kernel jitter widens the cloud at every resampling and "
                   "2 000 particles cover the collapse at the manoeuvre poorly; 10 000 give "
                   "1.46 (100 runs, CKF 1.40), with Liu-West shrinkage 1.27 (500 runs)")
def test_the_pf_beats_the_ckf(bo_cv):
    result, block_mse = bo_cv
    assert efficiency(result, "PF") < efficiency(result, "CKF")
    assert paired_t(block_mse, "PF", "CKF") > 3.0


def test_what_holds_of_the_pf(bo_cv):
    """It loses no run, is not overconfident and stays within 1.75 x the PCRLB: 1.53 and
    ANEES 2.5 here (its covariance, widened by the jitter, overstates the error); other
    draws give 1.51 and 2.6 (block 250) or 1.64 and 4.9 (block 25): 2 000 particles leave a
    few runs far off, and they move these numbers."""
    result, _ = bo_cv
    f = result.filters["PF"]
    assert f.diverged == 0
    assert 1.0 < f.anees < 6.0
    assert efficiency(result, "PF") < 1.75


@pytest.mark.xfail(strict=True, reason="the best specialist, the MPEKF, is at 1.22 x the "
                   "PCRLB (RPEKF 1.30, PF 1.53; 500 runs, seed 2026), not within 1.15: a "
                   "10 000-particle PF with shrinkage, near the optimal estimator, is at 1.27, "
                   "so the bound is not tight on bo-cv")
def test_the_best_specialist_is_within_1_15_of_the_pcrlb(bo_cv):
    result, _ = bo_cv
    assert min(efficiency(result, n) for n in SPECIALISTS) <= TARGET


def test_what_holds_of_the_best_specialist(bo_cv):
    """The MPEKF is the best filter of bo-cv, within 1.25 x the PCRLB (1.22), and better
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
    4.3; the CKF's 5.1)."""
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
