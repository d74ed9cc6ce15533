"""Hashemi and Alfi (2019) beside two premises of its own: a truth with process noise,
and the GA initialiser offered beside the draw from the prior.

Truth with process noise: the three well-specified DBT geometries with the truth's q raised
from 0 to 1e-4 m^2/s^3, the q every filter assumes (100 runs each, the bundled seeds, ten
blocks of ten). GA start: the same geometries, 30 runs each, every filter started from the
GA estimate (the paper's GA, 800 measurements in blocks of 25) against the draw from the
prior, paired (the same truths and measurements). Confidence as in test_dbt_premise.py: a
ratio of mean squared errors summed over blocks, its standard error the jackknife over the
blocks, and a one-sided 99% claim at t(0.99, blocks - 1) standard errors. The numbers are
in docs/dbt-truth-and-initialisation.md. Each result's blocks are filtered together (one
pass over the steps, each block scored on its own runs: ``run_blocks(..., together=True)``).
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit.experiments.montecarlo as mc
import trackkit.scenario as S

GEOMETRIES = ["dbt-approaching", "dbt-receding", "dbt-observer-manoeuvre"]
FILTERS = ["EKF", "UKF", "AEKF", "MCEKF", "AMCEKF"]
Q_TRUE = 1e-4  # m^2/s^3: the filters' own q (a velocity random walk of 0.45 m/s in 2000 s)
T_99 = {9: 2.821, 5: 3.365}  # one-sided 99% quantiles of Student's t (9 and 5 dof)
GA_RUNS = 30

pytestmark = pytest.mark.slow


def _scenario(name: str, runs: int, block: int, q_true: float = 0.0,
              initialiser: str = "draw") -> S.Scenario:
    d = S.load(name).model_dump()
    d["target"]["motion"]["q"] = q_true
    d["prior"]["initialiser"] = initialiser
    d["run"].update(runs=runs, block=block)
    return S.parse(d, name)


def _run(s: S.Scenario):
    # the blocks are the jackknife's batches; filtered together, they cost one pass
    parts = mc.run_blocks(s, list(range(s.run.runs // s.run.block)), together=True)
    return mc.combine(s, parts), parts


def _ratio(parts, a: tuple[str, str], b: tuple[str, str], span: tuple[int, int]):
    """sqrt(MSE_a / MSE_b) over the steps ``span`` of two results' blocks (``a``, ``b`` =
    (which, filter), which indexing ``parts``), and its jackknife standard error."""
    k0, k1 = span
    sse = np.array([[p[w].metrics[f].mse("position")[k0:k1].sum() for w, f in (a, b)]
                    for p in parts])  # (blocks, 2): equal blocks, so sums of means suffice
    total = sse.sum(0)
    loo = np.sqrt((total[0] - sse[:, 0]) / (total[1] - sse[:, 1]))
    n = len(sse)
    se = np.sqrt((n - 1) / n * np.sum((loo - loo.mean()) ** 2))
    return float(np.sqrt(total[0] / total[1])), float(se)


# --- a truth with process noise, the filters assuming the same q -----------------------------


@pytest.fixture(scope="module")
def noisy():
    out = {g: _run(_scenario(g, 100, 10, q_true=Q_TRUE)) for g in GEOMETRIES}
    print()
    for g, (r, _) in out.items():
        for w in r.windows:
            print(f"{g} q_true = {Q_TRUE:g}, {w}: PCRLB {r.pcrlb_windows[w]['position']:.1f} m; "
                  + ", ".join(f"{f} {r.filters[f].windows[w]['rmse']['position']:.1f} m "
                              f"({r.efficiency(f, 'position', w):.2f}, ANEES "
                              f"{r.filters[f].windows[w]['anees']:.1f})" for f in FILTERS))
    return out


def test_the_well_tuned_ekf_is_consistent_and_near_the_bound(noisy):
    # Measured (ANEES from 600 s; RMSE/PCRLB transient, steady): approaching 5.42, 1.17,
    # 1.30; receding 4.92, 1.02, 1.15; manoeuvring observer 4.84, 1.09, 1.03. With the
    # exact-CV truth the same EKF has ANEES 2.0-2.2 (its q is then too large) and 1.4-1.6
    # times the bound in the steady window: the truth's noise is what its q describes.
    for g, (r, _) in noisy.items():
        f = r.filters["EKF"]
        assert 4.0 < f.anees < 6.5, (g, f.anees)
        for w in r.windows:
            assert 1.0 <= r.efficiency("EKF", "position", w) < 1.4, (g, w)
        assert all(r.filters[n].diverged == 0 for n in FILTERS), g


@pytest.mark.parametrize("window", ["steady"])
def test_adaptation_gains_nothing_when_q_and_r_are_right(noisy, window):
    # Paired (the same truths and measurements): AMCEKF/EKF position RMSE in the steady window
    # measured 1.10, 1.14 and 1.23. At 99% one-sided (2.82 jackknife standard errors over
    # ten blocks) it is above 0.95 in every geometry (adaptation gains nothing, not even 5%)
    # and above 1 (it loses) in the approaching one; the ratios' spread over blocks (standard
    # errors up to about 0.09) leaves the other two above 0.95 only. And the AMCEKF's
    # covariance falls far below its errors (ANEES 28-34 against the EKF's 5), where with the
    # exact-CV truth it is 3.3.
    worse = 0
    for g, (r, parts) in noisy.items():
        span = r.window_steps[window]
        ratio, se = _ratio([{"x": p} for p in parts], ("x", "AMCEKF"), ("x", "EKF"), span)
        low = ratio - T_99[len(parts) - 1] * se
        assert low > 0.95, (g, ratio, se)
        worse += low > 1.0
        assert r.filters["AMCEKF"].windows[window]["anees"] > 3 * r.filters["EKF"].windows[
            window]["anees"], g
    assert worse >= 1


# --- the GA initialiser against the draw from the prior ------------------------------------


@pytest.fixture(scope="module")
def starts():
    found = {}
    original = mc._ga_start

    def keep(plan, data, runs):
        g = original(plan, data, runs)
        found.setdefault(plan.scenario.name, []).append(g.mean[:, :2] - data.truth[0][:, :2])
        return g

    mc._ga_start = keep
    try:
        out = {g: {init: _run(_scenario(g, GA_RUNS, 5, initialiser=init))
                   for init in ("draw", "ga")} for g in GEOMETRIES}
    finally:
        mc._ga_start = original
    errors = {g: np.linalg.norm(np.concatenate(e), axis=-1) for g, e in found.items()}
    print()
    for g, by in out.items():
        print(f"{g}: GA position error median {np.median(errors[g]):.0f} m, max "
              f"{errors[g].max():.0f} m; " + "; ".join(
                  f"{init} " + ", ".join(f"{f} {r.filters[f].windows[w]['rmse']['position']:.1f}"
                                         for f in FILTERS for w in r.windows)
                  for init, (r, _) in by.items()))
    return out, errors


def test_the_ga_finds_the_initial_position_within_1000_m(starts):
    # the paper's Fig. 17 claim, in every run (measured over 100 runs: medians 163-196 m,
    # max 547 m)
    _, errors = starts
    for g in GEOMETRIES:
        assert len(errors[g]) == GA_RUNS
        assert errors[g].max() < 1000.0, g


def test_the_ga_starts_covariance_is_honest(starts):
    # P0 = diag(1000 m, 10 m/s, 5 Hz)^2 covers the GA's errors (a few hundred metres, the
    # whole target speed for the velocity guess 0, the Doppler shift for f0): the average
    # NEES of the non-adaptive filters over the first 100 s stays below the state's 5
    # (measured 3.4-3.6; the draw gives 4.7-5.7), and no run diverges
    out, _ = starts
    for g in GEOMETRIES:
        r, _ = out[g]["ga"]
        for f in ("EKF", "UKF", "MCEKF"):
            assert np.mean(r.filters[f].nees[:100]) < 5.0, (g, f)
        assert all(r.filters[f].diverged == 0 for f in FILTERS), g


def test_the_start_is_forgotten_by_the_steady_window(starts):
    # Steady window (1000-2000 s), EKF, GA/draw paired: measured 0.975, 0.94 and 0.985 on
    # these 30 runs (0.99, 0.98 and 1.00 over 100), the jackknife error over six blocks of
    # five runs 1-2%. At 99% one-sided (t with 5 dof, 3.37 standard errors) the GA start does
    # not hurt by 10% or more, and it helps by less than 10% (point estimate): what the start
    # changed is gone 1000 s later
    out, _ = starts
    for g in GEOMETRIES:
        (rd, pd), (_, pg) = out[g]["draw"], out[g]["ga"]
        span = rd.window_steps["steady"]
        parts = [{"ga": a, "draw": b} for a, b in zip(pg, pd, strict=True)]
        ratio, se = _ratio(parts, ("ga", "EKF"), ("draw", "EKF"), span)
        assert ratio + T_99[len(parts) - 1] * se < 1.10, (g, ratio, se)
        assert ratio > 0.9, (g, ratio, se)
