"""The claims of Hosseini, Haeri and Khaloozadeh (2019) about joint tracking and classification, on
the bundled jtc-fighter and jtc-airliner scenarios at their 100 runs and fixed seeds.

The scenarios run the paper's 5 000 particles per class; these tests run 1 000 (the claims
hold there too, and the two tests stay under 90 s on two cores); docs/jtc-comparison.md has the
numbers at 5 000. Both filters see the same truth, plots and priors in every run.
"""

from __future__ import annotations

import math

import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import run_scenario

PARTICLES = 1000
FILTERS = ("JTC", "MultiFilter")


def _result(name: str):
    d = S.load(name).model_dump()
    for f in d["filters"]:
        f["options"]["particles_per_class"] = PARTICLES
    return run_scenario(S.parse(d, name))


@pytest.fixture(scope="module", params=["jtc-fighter", "jtc-airliner"])
def result(request):
    return _result(request.param)


@pytest.mark.slow
def test_the_true_class_ends_above_0_9_in_at_least_90_percent_of_runs(result):
    """Claim 1: a fighter above 300 m/s ends with P(fighter) > 0.9, and its airliner twin with
    P(airliner) > 0.9, in at least 90% of the 100 runs, for both filters. Measured at 1 000
    particles per class: 100 of 100 runs for each filter and scenario (the speed likelihood
    alone multiplies the odds by 2.4 (airliner) to 4.2 (fighter) per scan; over six seeds the
    baseline's particle-starved fighter filter ended above 0.9 in 98-100 runs); with 100 of
    100, the one-sided 99.9% lower confidence bound of the rate is 0.001^(1/100) = 0.933 >
    0.9 (Clopper-Pearson)."""
    assert result.runs == 100
    for name in FILTERS:
        c = result.classification(name)
        assert c["true_class"] == {"jtc-fighter": "fighter",
                                   "jtc-airliner": "airliner"}[result.scenario]
        assert c["above"] >= 0.9, (name, c)


@pytest.mark.slow
def test_the_single_filter_is_within_10_percent_of_the_baseline_on_position(result):
    """Claim 2: the single-filter JTC's position RMSE over the run (all 100 steps, 100 runs) is
    no worse than the multi-filter baseline's by more than 10%. Measured at 1 000 particles
    per class (JTC / baseline): fighter 85.8 / 104.1 m = 0.82, airliner 51.3 / 51.4 m = 1.00;
    at the scenarios' 5 000: 72.0 / 75.1 = 0.96 and 51.1 / 51.1 = 1.00. Over the six seeds
    2013-2018 (fighter) and 2014-2019 (airliner) at 1 000 the ratio stayed within 0.81-0.87
    and 0.99-1.00: at 1 000 the baseline's fighter filter has its fixed 1 000 particles where
    the JTC's fighter class has about 1 900, and the 3 deg/s turns starve it (its ANEES 49
    against the JTC's 15), so the claim holds with room to spare."""
    jtc = result.filters["JTC"].rmse_mean["position"]
    base = result.filters["MultiFilter"].rmse_mean["position"]
    assert math.isfinite(jtc) and math.isfinite(base)
    assert jtc <= 1.1 * base, (result.scenario, jtc, base, jtc / base)
    assert result.filters["JTC"].diverged == 0 and result.filters["MultiFilter"].diverged == 0
