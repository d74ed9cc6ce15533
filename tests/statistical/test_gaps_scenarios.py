"""The missing-measurements thesis's claims about gaps (chapter 4) through the bundled scenarios, as
``trackkit run`` runs them: gaps-ca (S5), gaps-sine (S6) and gaps-cv (S4), each at its own
1 000 runs and seed.

"P beats X" is per run: P's RMSE of the first state component (position; the wrapped phase
in S6) over the gap and the ``report.after_gap_s`` after it is below X's. Where a claim of
the thesis does not hold, a strict xfail carries the measured numbers, and beside it a
passing test asserts what does hold. Confidence: a fraction p over N = 1 000 runs has a
standard error sqrt(p (1 - p) / N) (1.3 points at p = 0.8); each asserted threshold is at
least 3 standard errors from the measured value (99.7% two-sided), unless said.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.scenario as S
from trackkit.experiments.montecarlo import run_scenario

pytestmark = pytest.mark.slow


def _run(name):
    r = run_scenario(S.load(name))
    assert r.runs >= 1000
    return r


@pytest.fixture(scope="module")
def ca():
    return _run("gaps-ca")


@pytest.fixture(scope="module")
def sine():
    return _run("gaps-sine")


@pytest.fixture(scope="module")
def cv():
    return _run("gaps-cv")


def beats(r, a, b, group="x1"):
    """Fraction of runs where a's RMSE over the gap and after is below b's, and the median
    ratio RMSE(a) / RMSE(b)."""
    ea, eb = r.gap_rmse_per_run(a, group), r.gap_rmse_per_run(b, group)
    return float(np.mean(ea < eb)), float(np.median(ea / eb))


# --- S5 -------------------------------------------------------------------------------------


def test_s5_p_beats_b2(ca):
    """P beats B2 in both filter sets: measured 100.0% of runs (matched CA KF, median ratio
    0.083) and 100.0% (CV KF, median 0.083). Asserted: at least 95%."""
    for f in ("CA", "CV"):
        frac, ratio = beats(ca, f"{f}-P", f"{f}-B2")
        assert frac >= 0.95 and ratio < 0.5


def test_s5_matched_kf_coasting_beats_the_fit(ca):
    """With the CA KF on the true model, coasting is the MMSE predictor: P beats B0 in
    29.8% of runs (median RMSE(P)/RMSE(B0) 1.56) and B0's mean squared error over the
    window is below P's. Asserted: P beats B0 in under 40% of runs (7 s.e. above)."""
    frac, ratio = beats(ca, "CA-P", "CA-B0")
    assert frac < 0.4 and ratio > 1.0
    assert ca.gap_rmse("CA-B0", "x1", "both") < ca.gap_rmse("CA-P", "x1", "both")


@pytest.mark.xfail(strict=True, reason="thesis claim (chapter 4) with a filter whose model "
                   "matches the target: P beats B0 in >= 80% of runs; measured 29.8% (median "
                   "RMSE ratio 1.56) on gaps-ca's CA KF")
def test_s5_thesis_claim_matched(ca):
    assert beats(ca, "CA-P", "CA-B0")[0] >= 0.8


def test_s5_thesis_claim_holds_with_a_mismatched_model(ca):
    """P's premise: the filter's model does not match the target (a CV KF on the
    accelerating target). P beats B0 in 98.4% of runs (median ratio 0.25) and B2 in 100%:
    the thesis's 80% holds (asserted, 14 s.e. below)."""
    for other in ("CV-B0", "CV-B2"):
        frac, ratio = beats(ca, "CV-P", other)
        assert frac >= 0.8 and ratio < 0.5


# --- S6 -------------------------------------------------------------------------------------


def test_s6_p_beats_b1(sine):
    """P (the sine fit) beats B1 (hold the last measurement): measured 79.7% of runs,
    median RMSE(P)/RMSE(B1) 0.49. Asserted 3 s.e. below: at least 75%, median below 0.6."""
    frac, ratio = beats(sine, "P", "B1")
    assert frac >= 0.75 and ratio < 0.6


def test_s6_thesis_thresholds_within_monte_carlo_error(sine):
    """The thesis's thresholds (chapter 4): P beats B1 in >= 80% of runs and the median
    RMSE(P)/RMSE(B1) is below 0.5. Measured on gaps-sine's 1 000 runs: 79.7% and 0.49. The
    fraction is 0.2 standard errors short of 80%: our runs cannot tell it from the thesis's
    threshold, so the claim is tested as "not contradicted": the one-sided 99% upper
    Clopper-Pearson bound of P's win rate reaches 80% (it would not if the true rate were
    below about 76%), and the median ratio is below 0.5."""
    from scipy.stats import beta

    frac, ratio = beats(sine, "P", "B1")
    runs = sine.runs
    wins = round(frac * runs)
    upper = beta.ppf(0.99, wins + 1, runs - wins)
    assert upper >= 0.8 and ratio < 0.5, (frac, upper, ratio)


# --- S4 -------------------------------------------------------------------------------------


def test_s4_b2_recovers(cv):
    """B2 keeps the track: finite errors, and the per-step position RMSE 30 steps after the
    gap is within 10% of coasting's (B0 gets every real measurement the same way; measured
    ratio at step 54: about 1.0), while over the gap B2 is worse (measured 29.9 m against
    7.2 m for B0)."""
    b2, b0 = cv.filters["B2"].rmse["x1"], cv.filters["B0"].rmse["x1"]
    assert np.isfinite(b2).all()
    end = int(cv.gap_steps[-1])
    assert np.all(b2[end + 30:] / b0[end + 30:] < 1.1)
    assert cv.gap_rmse("B2", "x1") > 2 * cv.gap_rmse("B0", "x1")
