"""Hashemi and Alfi (2019) on its premise: every filter starts from poor Q0 and R0.

The three bundled mis-specified DBT variants (`dbt-*-misspecified`: each filter's q ten
times the well-tuned 1e-4, and its R at half the true variances; the same geometries, seeds,
truths and measurements as the well-specified scenarios) are run once per module, 100 runs
of 2000 s each, in ten blocks of ten runs. The blocks give the confidence: the AMCEKF/EKF
position RMSE ratio is a ratio of mean squared errors summed over blocks, and its standard
error is the jackknife over the ten blocks (delete one block at a time); a claim holds at
99% (one-sided) when the ratio plus t(0.99, 9) = 2.82 standard errors is below the target.

Errors are reported over two windows, transient (600-1000 s) and steady (1000-2000 s),
from each result's per-step mean squared error, beside the scenario's own average from
600 s. The well-specified side (RMSE/PCRLB, ANEES, what adaptation gains there) is checked
in ``test_dbt.py``, which already runs those scenarios; docs/dbt-comparison.md has both.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import combine, run_blocks, run_scenario

GEOMETRIES = ["dbt-approaching", "dbt-receding", "dbt-observer-manoeuvre"]
SCENARIOS = [f"{g}-misspecified" for g in GEOMETRIES]
FILTERS = ["EKF", "UKF", "AEKF", "MCEKF", "AMCEKF"]
BLOCK = 10
T_99_9 = 2.821  # one-sided 99% quantile of Student's t with 9 degrees of freedom
WINDOWS = {"transient": (600.0, 1000.0), "steady": (1000.0, np.inf),
           "from 600 s": (600.0, np.inf)}
PAPER_RATIO = {"dbt-approaching": 0.58, "dbt-receding": 0.47, "dbt-observer-manoeuvre": 0.66}

pytestmark = pytest.mark.slow


def _run(name):
    s = S.load(name)
    d = s.model_dump()
    d["run"]["block"] = BLOCK  # ten blocks of ten runs: the jackknife's batches
    s = S.parse(d, name)
    parts = run_blocks(s, list(range(s.run.runs // BLOCK)), together=True)  # one pass
    return combine(s, parts), parts


@pytest.fixture(scope="module")
def results():
    out = {name: _run(name) for name in SCENARIOS}
    print()
    for name, (r, parts) in out.items():
        b = r.pcrlb["position"]
        print(f"{name}: position PCRLB " + ", ".join(
            f"{w} {np.sqrt(np.mean(b[_mask(r, w)] ** 2)):.1f} m" for w in WINDOWS))
        for f in FILTERS:
            cells = []
            for w in WINDOWS:
                ratio, se = _ratio(r, parts, f, w)
                cells.append(f"{w} {_rmse(r, f, w):6.1f} m ({ratio:.3f} +- {se:.3f})")
            fr = r.filters[f]
            print(f"  {f:7s} " + "  ".join(cells) + f"  RMSE/PCRLB "
                  f"{fr.rmse_mean['position'] / r.pcrlb_mean['position']:.2f}  ANEES "
                  f"{fr.anees:.2f}")
    return out


def _mask(r, window):
    lo, hi = WINDOWS[window]
    return (r.times >= lo - 1e-9) & (r.times < hi - 1e-9)


def _rmse(r, f, window="from 600 s"):
    """Position RMSE over the runs and the steps of ``window``, from the per-step RMSE."""
    return float(np.sqrt(np.mean(r.filters[f].rmse["position"][_mask(r, window)] ** 2)))


def _ratio(r, parts, f, window="from 600 s"):
    """RMSE_f / RMSE_EKF over ``window`` and its jackknife standard error over the blocks."""
    m = _mask(r, window)
    sse = np.array([[p.metrics[g].mse("position")[m].sum() for g in (f, "EKF")]
                    for p in parts])  # (blocks, 2): equal blocks, so sums of means suffice
    total = sse.sum(axis=0)
    ratio = np.sqrt(total[0] / total[1])
    loo = np.sqrt((total[0] - sse[:, 0]) / (total[1] - sse[:, 1]))
    n = len(parts)
    se = np.sqrt((n - 1) / n * np.sum((loo - loo.mean()) ** 2))
    return float(ratio), float(se)


def test_the_variants_are_the_well_specified_runs_with_poor_q0_and_r0():
    for g in GEOMETRIES:
        good, bad = S.load(g).model_dump(), S.load(f"{g}-misspecified").model_dump()
        for key in ("time", "target", "observers", "prior", "run"):
            assert bad[key] == good[key], (g, key)
        r_true = [np.deg2rad(2.0) ** 2, 0.3**2]
        for fg, fb in zip(good["filters"], bad["filters"], strict=True):
            assert fb["motion"]["q"] == pytest.approx(10 * fg["motion"]["q"])
            assert fb["r0_diag_si"] == pytest.approx([0.5 * v for v in r_true], rel=1e-7)
            assert (fb["name"], fb["type"], fb["options"]) == (fg["name"], fg["type"],
                                                              fg["options"])


def test_results_cover_the_papers_runs(results):
    for r, _ in results.values():
        assert r.runs == 100 and r.steps == 2000 and list(r.filters) == FILTERS


@pytest.mark.parametrize("window", list(WINDOWS))
@pytest.mark.parametrize("name", SCENARIOS)
def test_amcekf_over_ekf_below_0_8_with_poor_q0_and_r0(results, name, window):
    # our target, at 99% confidence (one-sided), in both windows and from 600 s.
    # Measured: from 600 s 0.45, 0.35, 0.55 (paper 0.58, 0.47, 0.66); transient 0.42, 0.40,
    # 0.49; steady 0.51, 0.31, 0.63, each with a jackknife standard error of 0.01-0.03
    r, parts = results[name]
    ratio, se = _ratio(r, parts, "AMCEKF", window)
    assert ratio + T_99_9 * se < 0.8, (name, window, ratio, se)


def test_receding_is_the_hardest_geometry_for_every_filter(results):
    # measured: receding 1.5-2.9 times the other two for every filter, far beyond the
    # Monte Carlo spread of a 100-run RMSE
    for f in FILTERS:
        rec = _rmse(results["dbt-receding-misspecified"][0], f)
        others = [_rmse(results[n][0], f) for n in SCENARIOS if n != "dbt-receding-misspecified"]
        assert rec > 1.2 * max(others), (f, rec, others)


def test_adaptation_recovers_what_poor_noise_costs_the_ekf(results):
    # Why the ratio falls: the EKF with poor Q0 and R0 sits at 3-5 times the PCRLB (measured
    # 3.6, 5.1, 3.1, against 1.3-1.4 well specified); the AMCEKF ends at 1.6-1.7 times the
    # bound whatever R0 it started from. The non-adaptive filters (UKF, MCEKF) stay within
    # 5% of the EKF: re-linearising does not repair a wrong Q or R.
    for name in SCENARIOS:
        r, parts = results[name]
        bound = r.pcrlb_mean["position"]
        assert _rmse(r, "EKF") > 2.5 * bound, name
        assert _rmse(r, "AMCEKF") < 2.0 * bound, name
        for f in ("UKF", "MCEKF"):
            assert abs(_ratio(r, parts, f)[0] - 1.0) < 0.05, (name, f)
        assert all(r.filters[f].diverged == 0 for f in FILTERS), name
        assert all(_rmse(r, f) > bound for f in FILTERS), name


@pytest.mark.parametrize("name", SCENARIOS)
def test_our_ratios_are_within_35_percent_below_the_papers(results, name):
    # with this mis-specification our gains are somewhat larger than the paper's, in the
    # same order (receding largest); the paper gives no Q0 or R0 to match exactly
    r, _ = results[name]
    ours = _rmse(r, "AMCEKF") / _rmse(r, "EKF")
    paper = PAPER_RATIO[name.removesuffix("-misspecified")]
    # measured 22%, 26% and 17% below
    assert paper * 0.65 < ours < paper, (ours, paper)


def test_amcekf_cannot_correct_channels_mis_scaled_differently():
    # A limitation, not a claim of the paper: the AMCEKF scales R with one factor for both
    # channels (alpha = tr(C_r) / tr(S), eqs. 14-19, traces that mix rad^2 and Hz^2). With
    # the bearing variance believed at half and the frequency variance at twice the truth
    # (q ten times too large, as in the variants) it fails: measured position RMSE 3467 m
    # against the EKF's 211 m on the approaching geometry (ratio 16.5; 17.7 and 19.4 on the
    # other two), ANEES 55. The Sage-Husa AEKF, with a full adaptive R, gains 25% there.
    d = S.load("dbt-approaching-misspecified").model_dump()
    for f in d["filters"]:
        f["r0_diag_si"] = [0.5 * np.deg2rad(2.0) ** 2, 2.0 * 0.3**2]
    r = run_scenario(S.parse(d, "dbt-approaching-misspecified"))
    ekf = r.filters["EKF"].rmse_mean["position"]
    print("\nbearing R x0.5, frequency R x2: RMSE / EKF " + ", ".join(
        f"{f} {fr.rmse_mean['position'] / ekf:.2f}" for f, fr in r.filters.items()))
    assert r.filters["AMCEKF"].rmse_mean["position"] > 5 * ekf
    assert r.filters["AEKF"].rmse_mean["position"] < 0.9 * ekf
