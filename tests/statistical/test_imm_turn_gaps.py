"""S7 of the missing-measurements thesis with missing plots (section 4-5): the IMM (CV KF + CT EKF)
on eimm_demo1's coordinated-turn target, 10 consecutive plots missing on a straight leg
(Fig. 4-13) and at the turn onset (Figs. 4-14, 4-15), filled by B0 (coast), P (a line
fitted to the last plots) or P' (the same fit over fewer plots while a manoeuvre detector
is on).

Set-up (``tests/test_imm.py``'s S7, imported): dt = 0.1 s, x0 = (0, 0, 1, 0, 0), straight on
steps 1-40, omega = +1 rad/s on 41-90 (step 41 is the first step moved by the turn), R =
0.05 I, IMM of CV (q = 0.01) with a KF and CT (turn-rate density 0.15) with an EKF, p_ij =
[[0.9, 0.1], [0.1, 0.9]], mu0 = (0.95, 0.05), each run's prior mean truth + N(0, P0). The
IMM is updated with the plot of step 1, then ``run_with_gaps`` runs it over steps 2..; steps
are counted from 1 as in the thesis. A gap is 10 plots (1 s); the error window is the gap and
the 10 steps (1 s) after it. 1000 runs, seed 12012 (the choices below were made on a
separate exploration seed, 12001, 400 runs).

Ours, fixed before the claim was measured:
- P = ``PolynomialFit(degree=1, window=15)``: a CV target's plots lie on a line; 15 plots
  (1.4 s) average the noise (sigma 0.22 m per axis, speed 1 m/s) down to a usable slope.
- P' = the same with ``short_window=5`` (the thesis's "five") while the detector is on.
- Detector: ``WindowDetector(L=5, pfa=1e-2, dim_z=2)`` on the IMM's mixture innovation. At
  pfa = 1e-2, on the exploration seed, it was the detector that saw the turn most often:
  the largest fraction of runs with the detector on at any step of the first turn was 0.44
  for it (step 58), 0.22 for the fading memory (alpha = 0.8) and 0.13 for NIS. The IMM's
  CT model absorbs much of the turn, so the mixture innovation stays small.
- Placements (first missing step): 20 (straight leg; the gap and the second after it,
  steps 20-39, are all straight, and the 15 plots before it too, unlike 95-104 whose
  window would reach back into the first turn); 41 (the turn's first step, Fig. 4-14);
  45 (4 steps into the turn, the earliest a detector might be expected to see it); 58
  (17 steps in, where the detector's on fraction peaked on the exploration seed: the
  earliest placement where P' acts in a sizeable share of runs; the gap and the second after
  it, steps 58-77, stay inside the turn).

What we found (seed 12012; position RMSE over the gap and the 1 s after, in m; ANEES:
position NEES, 2 degrees of freedom, averaged over the runs and the gap's steps; "on": the
fraction of runs whose detector was on when the gap began)::

    first step  handler  mean   median  ANEES   on     wins
    20          B0       0.238  0.220    1.63   0.011  B0 beats P in 35.1%
                P        0.207  0.192    5.76          P' beats P in 0.2%, ties 98.9%
                P'       0.211  0.192    6.25
    41          B0       0.299  0.285    2.33   0.020  B0 beats P in 74.3%
                P        0.342  0.330   11.01          P' beats P in 0.4%, ties 98.0%
                P'       0.346  0.333   11.58
    45          B0       0.419  0.413    5.44   0.017  B0 beats P in 84.7%
                P        0.500  0.494   26.99          P' beats P in 0.5%, ties 98.3%
                P'       0.504  0.498   27.57
    58          B0       0.387  0.375    4.79   0.417  B0 beats P in 96.9%
                P        0.591  0.596   38.45          P' beats P in 16.2%, ties 58.3%
                P'       0.636  0.631   48.54

(A tie: the detector was off at the gap's start, so P' was P.) The median over runs of
RMSE(P')/RMSE(P) is exactly 1.000 at every placement.

- On the straight leg P does what the thesis says: its RMSE (0.207 m) is below the raw
  plots' (sqrt(2 R) = 0.316 m) and below coasting's (0.238 m); it beats B0 in 64.9% of runs.
- The claim "P' beats P on the median" does not hold, for two reasons: (1) the detector
  is off at the gap's start in most runs at every placement (at the onset, 41, it cannot be
  on: the first turning step moves the target 5 mm off its line, against 0.22 m of noise;
  four steps in it is on in 1.7% of runs, the false-alarm level), and where it is off P'
  is P, so the median ratio is exactly 1; (2) where it is on, the 5-plot line is worse than
  the 15-plot one: the slope of a line through 5 plots 0.1 s apart has a standard deviation
  of 0.22 / sqrt(0.1) = 0.71 m/s against the target's 1 m/s. Neither P nor P' beats
  coasting in the turn: the IMM's CT model predicts the turn, a fitted line does not, and
  feeding pseudo-plots with the sensor's R makes the IMM confident in them (ANEES 11-49).
  The claim is kept below as a strict xfail with these numbers.
- Not tuned to pass. For the record, a scan on the exploration seed (median RMSE of a
  fit used in every run, no detector) found no line or parabola over 3-20 plots that beats
  coasting in the turn; 17 steps in, a 10-plot line (0.47 m) did beat the 15-plot one
  (0.59 m), but 5 plots (0.55 m) and 3 plots (0.95 m) did not, and at the onset longer was
  always better (5: 0.53, 10: 0.35, 15: 0.33, 20: 0.32 m).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy.stats import binomtest

import trackkit as tk
from tests.test_imm import DT, P0, POS, cv_ct, s7_data
from trackkit.filters.gaps import (
    Coast,
    PolynomialFit,
    gap_and_after,
    mask_by_count,
    run_with_gaps,
)
from trackkit.filters.maneuver import WindowDetector
from trackkit.linalg import quadratic_form

pytestmark = pytest.mark.slow

RUNS, SEED = 1000, 12012
GAP, AFTER = 10, 10  # plots missing; steps after the gap in the error window (1 s)
DETECTOR = WindowDetector(L=5, pfa=1e-2, dim_z=2)
HANDLERS = {"B0": Coast(), "P": PolynomialFit(1, 15), "P'": PolynomialFit(1, 15, short_window=5)}
STRAIGHT, ONSET, ONSET_4, TURN_17 = 20, 41, 45, 58
RAW_RMSE = np.sqrt(2 * 0.05)  # position RMSE of the plots themselves


@cache
def data():
    """Truth (steps 1..200 as rows), plots and the IMM's belief after step 1's plot."""
    X, Z, x0 = s7_data(RUNS, SEED)
    f = cv_ct()
    b, _ = f.update(f.init(tk.Gaussian(x0, P0)), Z[:, 0], POS)
    return f, b, X, Z


@cache
def gap_at(first: int) -> dict:
    """Each handler's run with the plots of steps ``first .. first + 9`` missing: per-run
    position RMSE over the gap and the 10 steps after, ANEES (position, 2 dof) over the gap,
    and whether the detector was on when the gap began."""
    f, b, X, Z = data()
    K = first - 2 + GAP + AFTER  # run_with_gaps's step k is step k + 2
    z = np.swapaxes(Z[:, 1:K + 1], 0, 1)
    mask = mask_by_count(K, first - 2, GAP)
    window = gap_and_after(mask, AFTER)
    out = {}
    for name, handler in HANDLERS.items():
        r = run_with_gaps(f, b, None, POS, z, DT, mask, handler, DETECTOR)
        e = r.estimate.mean[..., :2] - X[1:K + 1, None, :2]
        nees = quadratic_form(r.estimate.cov[..., :2, :2], e, "position covariance")
        out[name] = {"rmse": np.sqrt(np.mean(np.sum(e[window] ** 2, -1), 0)),
                     "anees": float(nees[mask].mean())}
        # P' reads the flag left by the step before the gap's first one
        out["on"] = r.maneuver[first - 3]
    return out


def summary(first: int) -> str:
    """One placement's rows of the module docstring's table (for the report)."""
    g = gap_at(first)
    b0, p, pp = (g[h]["rmse"] for h in HANDLERS)
    rows = [f"{first:<11} {h:<8} {g[h]['rmse'].mean():.3f}  {np.median(g[h]['rmse']):.3f}"
            f"   {g[h]['anees']:6.2f}" for h in HANDLERS]
    rows[0] += f"   {g['on'].mean():.3f}  B0 beats P in {np.mean(b0 < p):.1%}"
    rows[1] += (f"          P' beats P in {np.mean(pp < p):.1%}, "
                f"ties {np.mean(pp == p):.1%}")
    return "\n".join(rows)


def bootstrap_median_upper(x: np.ndarray, confidence: float = 0.99) -> float:
    """One-sided upper confidence bound of the median of x: the ``confidence`` quantile of
    the medians of 2000 bootstrap resamples (fixed seed)."""
    rng = np.random.default_rng(7)
    idx = rng.integers(0, x.size, (2000, x.size))
    return float(np.quantile(np.median(x[idx], axis=1), confidence))


def wins_lower(k: int, n: int, confidence: float = 0.99) -> float:
    """One-sided Clopper-Pearson lower bound of a win rate from k wins in n runs."""
    return binomtest(k, n).proportion_ci(2 * confidence - 1, "exact").low


# --- the straight leg (Fig. 4-13) ----------------------------------------------------------


def test_p_keeps_the_straight_leg_gap_small():
    """Gap at steps 20-29. "Estimated well" made testable: P's mean position RMSE over the
    gap and the second after it is below the raw plots' RMSE sqrt(2 R) = 0.316 m with
    margin (measured 0.207 m; asserted below 0.8 of it, 0.253 m; the Monte Carlo standard
    error of a mean over 1000 runs is about 0.002 m) and below coasting's (B0, 0.238 m). P
    beats B0 in 64.9% of runs; asserted: the one-sided 99% Clopper-Pearson lower bound of
    that rate (0.613) is above 0.5, i.e. P is better more often than not."""
    g = gap_at(STRAIGHT)
    p, b0 = g["P"]["rmse"], g["B0"]["rmse"]
    assert p.mean() < 0.8 * RAW_RMSE
    assert p.mean() < b0.mean()
    assert wins_lower(int(np.sum(p < b0)), RUNS) > 0.5


def test_pseudo_plots_make_the_imm_overconfident_over_the_gap():
    """Fed as plots with the sensor's R, the fitted values (whose errors are correlated and,
    far from the window, larger than R) shrink the IMM's covariance below its error: its
    position ANEES over the gap (2 for a consistent filter) is 5.8 with P on the straight
    leg and 11-38 in the turn, against 1.6-5.4 when it coasts (B0). Asserted: P's ANEES
    above twice B0's at every placement (measured 3.5 to 8 times). Were the NEES
    chi-square(2), the mean over 1000 independent runs would have a standard error near 3%
    of it even counting each run's 10 correlated steps as one sample."""
    for first in (STRAIGHT, ONSET, ONSET_4, TURN_17):
        g = gap_at(first)
        assert g["P"]["anees"] > 2 * g["B0"]["anees"], first


# --- the turn onset (Figs. 4-14, 4-15) -----------------------------------------------------


def test_the_detector_cannot_see_the_turn_at_its_onset():
    """When the gap begins the detector is on in 2.0% (gap from step 41) and 1.7% (from 45)
    of runs, the false-alarm level (1.1% on the straight leg, from step 20): the first
    turning steps move the target millimetres off its line. 17 steps in (from 58) it is on in
    41.7%. Asserted: below 5% at 41 and 45 (more than 6 standard errors of a 2% fraction
    over 1000 runs above it) and between 30% and 50% at 58 (5 standard errors either side):
    at no placement does P' act in more than half the runs."""
    assert gap_at(ONSET)["on"].mean() < 0.05
    assert gap_at(ONSET_4)["on"].mean() < 0.05
    assert 0.3 < gap_at(TURN_17)["on"].mean() < 0.5


def test_coasting_beats_a_fitted_line_in_the_turn():
    """In the turn the IMM's own prediction (its CT model) beats a straight line through the
    last plots: B0 beats P in 74.3% (gap from 41), 84.7% (45) and 96.9% (58) of runs, mean
    RMSE 0.299 against 0.342 m, 0.419 against 0.500, 0.387 against 0.591. Asserted: B0's
    mean RMSE below P's, and the one-sided 99% Clopper-Pearson lower bound of B0's win rate
    (measured 0.709, 0.819, 0.954) above 0.5 at each placement."""
    for first in (ONSET, ONSET_4, TURN_17):
        g = gap_at(first)
        p, b0 = g["P"]["rmse"], g["B0"]["rmse"]
        assert b0.mean() < p.mean(), first
        assert wins_lower(int(np.sum(b0 < p)), RUNS) > 0.5, first


def test_where_p_prime_acts_the_short_window_is_worse():
    """In the runs whose detector was on when the gap began (gap from step 58: 417 of 1000),
    P' (5 plots) against P (15 plots): P' wins in 38.8% of them, median RMSE ratio 1.163,
    mean RMSE 0.623 against 0.516 m. A 5-plot slope has a standard deviation of about
    0.71 m/s (sigma 0.22 m over a 0.4 s span) against the target's 1 m/s; the 15-plot line,
    though it misses the turn, is steadier. Asserted: P''s mean RMSE over those runs above
    P's, and the bootstrap 99% lower bound of the median ratio (1.085) above 1."""
    g = gap_at(TURN_17)
    on = g["on"]
    ratio = g["P'"]["rmse"][on] / g["P"]["rmse"][on]
    assert g["P'"]["rmse"][on].mean() > g["P"]["rmse"][on].mean()
    assert -bootstrap_median_upper(-ratio) > 1.0


@pytest.mark.xfail(strict=True, reason="the thesis's claim: median RMSE(P')/RMSE(P) < 1 at "
                   "the turn onset. Measured (seed 12012, 1000 runs, gap + 1 s): gap from "
                   "step 41: median 1.000, P' beats P in 0.4% of runs, detector on at the gap "
                   "start in 2.0%; from 45: median 1.000, 0.5%, on 1.7%; from 58: median "
                   "1.000, 16.2%, on 41.7%, and where on, median ratio 1.163 (P' wins 38.8%)")
@pytest.mark.parametrize("first", [ONSET, ONSET_4, TURN_17])
def test_thesis_claim_p_prime_beats_p_on_the_median(first):
    """The claim at each placement: the bootstrap 99% upper bound of the median over runs
    of RMSE(P')/RMSE(P) below 1, and P' winning more than half of the runs where the two
    differ (one-sided sign test at 1%)."""
    g = gap_at(first)
    ratio = g["P'"]["rmse"] / g["P"]["rmse"]
    assert bootstrap_median_upper(ratio) < 1.0
    wins, differ = int(np.sum(ratio < 1)), int(np.sum(ratio != 1))
    assert differ > 0 and binomtest(wins, differ, alternative="greater").pvalue < 0.01
