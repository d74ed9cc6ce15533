"""Hashemi and Alfi (2019): the Doppler-bearing comparison at the paper's 100 runs.

The three bundled scenarios are run once (fixed seeds, 100 runs, 2000 steps each); the tests
check the paper's claims that our runs support, and record the one that does not.
"""

from __future__ import annotations

import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import run_scenario

SCENARIOS = ["dbt-approaching", "dbt-receding", "dbt-observer-manoeuvre"]
FILTERS = ["EKF", "UKF", "AEKF", "MCEKF", "AMCEKF"]


@pytest.fixture(scope="module")
def results():
    return {name: run_scenario(S.load(name)) for name in SCENARIOS}


pytestmark = pytest.mark.slow


def _pos(result, f):
    return result.filters[f].rmse_mean["position"]


def test_results_have_the_papers_filters_and_groups(results):
    for r in results.values():
        assert r.runs == 100 and r.steps == 2000
        assert list(r.filters) == FILTERS
        assert set(r.pcrlb) == {"position", "velocity", "speed", "course", "frequency",
                                "bearing"}


@pytest.mark.parametrize("name", SCENARIOS)
def test_proposed_filter_beats_the_ekf_on_position(results, name):
    # the paper's qualitative claim: the proposed filter has the lowest position error. All
    # filters see the same truths and measurements, so the comparison is paired; the margins
    # we see (5-12% below the EKF) are the ones recorded in docs/dbt-comparison.md
    r = results[name]
    assert all(_pos(r, "AMCEKF") < _pos(r, f) for f in FILTERS if f != "AMCEKF")


@pytest.mark.xfail(strict=True, reason="the paper's margins (AMCEKF/EKF = 0.58, 0.47, 0.66) "
                   "do not reproduce with well-specified noise: we get 0.88-0.95; with poor "
                   "Q0 and R0 they do (test_dbt_premise.py, docs/dbt-comparison.md)")
@pytest.mark.parametrize("name", SCENARIOS)
def test_proposed_filter_ratio_below_0_8(results, name):
    r = results[name]
    assert _pos(r, "AMCEKF") / _pos(r, "EKF") < 0.8


PAPER_RATIO = {"dbt-approaching": 0.58, "dbt-receding": 0.47, "dbt-observer-manoeuvre": 0.66}


@pytest.mark.parametrize("name", SCENARIOS)
def test_the_paper_ratio_is_below_what_the_bound_allows_against_our_ekf(results, name):
    # Why the 0.8 target cannot hold here: our EKF is close to the PCRLB, so even an
    # efficient filter would have RMSE / RMSE_EKF >= PCRLB / RMSE_EKF, which is above the
    # paper's ratio (and near 0.8) in every scenario.
    r = results[name]
    floor = r.pcrlb_mean["position"] / _pos(r, "EKF")
    assert floor > PAPER_RATIO[name]
    assert floor > 0.7


def test_receding_is_the_hardest_scenario_for_every_filter(results):
    for f in FILTERS:
        rec = _pos(results["dbt-receding"], f)
        others = [_pos(results[n], f) for n in SCENARIOS if n != "dbt-receding"]
        assert rec > max(others), (f, rec, others)


def test_no_filter_diverges_and_all_stay_above_the_bound(results):
    for r in results.values():
        for f in FILTERS:
            assert r.filters[f].diverged == 0
            # an estimator cannot beat the PCRLB (position is a linear group: a true bound)
            assert _pos(r, f) > r.pcrlb_mean["position"]


def _window_rmse(result, f, lo, hi=float("inf")):
    """Position RMSE over the runs and the steps lo <= t < hi, from the per-step RMSE."""
    m = (result.times >= lo - 1e-9) & (result.times < hi - 1e-9)
    return float((result.filters[f].rmse["position"][m] ** 2).mean() ** 0.5)


def test_with_well_specified_noise_adaptation_gains_little(results):
    # The other side of the premise (tests/statistical/test_dbt_premise.py has the
    # mis-specified variants): with a well-tuned q and the true R the EKF is at 1.3-1.4
    # times the PCRLB, and the AMCEKF gains 12%, 5% and 10% on it from 600 s (transient
    # 600-1000 s: 15%, 9%, 13%; steady 1000-2000 s: 5%, -1%, 7%). Asserted with a margin:
    # at most 15% from 600 s and at most 10% in the steady window, in every geometry.
    print()
    for name, r in results.items():
        bound = r.pcrlb_mean["position"]
        print(f"{name}: position PCRLB {bound:.1f} m (from 600 s)")
        for f in FILTERS:
            fr = r.filters[f]
            print(f"  {f:7s} RMSE {_pos(r, f):6.1f} m  RMSE/PCRLB {_pos(r, f) / bound:.2f}  "
                  f"ANEES {fr.anees:.2f}  transient {_window_rmse(r, f, 600, 1000):6.1f} m  "
                  f"steady {_window_rmse(r, f, 1000):6.1f} m  ratio to the EKF "
                  f"{_pos(r, f) / _pos(r, 'EKF'):.3f}")
        assert 1.2 < _pos(r, "EKF") / bound < 1.5, name
        assert _pos(r, "AMCEKF") / _pos(r, "EKF") > 0.85, name
        steady = _window_rmse(r, "AMCEKF", 1000) / _window_rmse(r, "EKF", 1000)
        assert steady > 0.9, (name, steady)
