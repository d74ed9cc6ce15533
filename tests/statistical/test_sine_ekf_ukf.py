"""Table 2-1 of the missing-measurements thesis (S3, the bundled ``sine-ekf-ukf``): the MSE of
theta, omega and a of the EKF and the UKF on the random sine y = a sin(theta) + r.

Table 2-1 is ONE noisy run (no seed, no run count): EKF 0.64, 0.53, 0.40 and UKF 0.59, 0.53,
0.39. One run's MSE varies from run to run by more than a factor of ten (a run whose filter
slips to the mirror solution (-a, theta + pi), which gives the same signal, keeps a theta
error of about pi), so the table's numbers are compared with the distribution over runs, never
asserted as they are: the median over runs within a factor of 3 of the table, and the
thesis's one ordering claim, the UKF's mean theta-MSE no worse than the EKF's.

The runs are the bundled scenario's 1 000 (seed 2107), filtered as the Monte Carlo engine
filters them (``tests.test_scenario_radar.filtered``; that the engine's squared RMSE is the
mean of these per-run MSEs is checked there). Confidence: a median is asserted through its
distribution-free 95.4 % interval over 1 000 runs, the order statistics 469 and 532, which
must lie inside the band as a whole; the mean comparison gives the paired difference with its
standard error. Where the thesis does not hold here the test is a strict xfail with the
numbers. The second-order EKF and the RTS smoothers (EKF + RTS, UKF + URTS; Figs. 2-11,
2-12, 2-15) have no numbers in the thesis: they are printed (``pytest -s``), not asserted.
So is another reading of the table: the toolbox's demo prints a root mean square under the
label MSE, and read as RMSEs the table lies within a factor of 2.4 of our median RMSEs (the
square roots of the median MSEs, printed beside them).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

import trackkit as tk
import trackkit.scenario as S
from tests.test_scenario_radar import filtered
from trackkit.experiments.montecarlo import plan_of
from trackkit.scenario.simulate import simulate_block

pytestmark = pytest.mark.slow  # about 6 s: 1 000 runs of 500 steps, three filters, two smoothers

NAME = "sine-ekf-ukf"
COMPONENTS = ("theta", "omega", "a")
#: Table 2-1, one run: MSE of theta, omega, a
TABLE = {"EKF": (0.64, 0.53, 0.40), "UKF": (0.59, 0.53, 0.39)}
FACTOR = 3.0


def median_interval(v: np.ndarray, confidence: float = 0.95) -> tuple[float, float]:
    """Distribution-free interval of the median: the order statistics k and N + 1 - k
    (1-based) with k the largest such that P(Binomial(N, 1/2) < k) <= (1 - confidence)/2."""
    n = len(v)
    k = int(binom.ppf((1 - confidence) / 2, n, 0.5))  # 469 for N = 1 000: coverage 95.4 %
    s = np.sort(v)
    return float(s[k - 1]), float(s[n - k])


@pytest.fixture(scope="module")
def runs() -> dict:
    """Per filter (and smoother), each run's MSE of theta, omega and a ``(runs, 3)``, and of
    the signal a sin(theta) ``(runs,)`` (what the toolbox's demo prints)."""
    s = S.load(NAME)
    assert s.run.runs >= 100
    plan = plan_of(s)
    data = simulate_block(plan, 0, s.run.runs)
    truth = data.truth[1:]
    estimates = {}
    for i, name in enumerate(plan.filter_names):
        estimates[name] = filtered(plan, data, i)
        if name in ("EKF", "UKF"):  # the UKF's is the unscented RTS smoother
            estimates[f"{name} + RTS"] = tk.filters.smooth(
                plan.filters[i], estimates[name], plan.filter_motions[i], plan.dt)

    def signal(x: np.ndarray) -> np.ndarray:
        return x[..., 2] * np.sin(x[..., 0])

    return {name: (((g.mean - truth) ** 2).mean(axis=0),
                   ((signal(g.mean) - signal(truth)) ** 2).mean(axis=0))
            for name, g in estimates.items()}


def test_numbers_of_every_filter_and_smoother(runs):
    """Prints mean, median (with its 95 % interval) and quartiles of each MSE, for the
    comparison with Table 2-1 (EKF2 and the smoothers included); asserts only that every
    run's MSE is a finite number (no filter lost a run to nan or inf)."""
    n = len(next(iter(runs.values()))[1])
    print(f"\nsine-ekf-ukf, {n} runs: per-run MSE over the 500 steps")
    print(f"{'':12s} {'':5s} {'mean':>8s} {'median':>8s} {'95% CI of median':>18s} "
          f"{'quartiles':>16s} {'sqrt(median)':>12s} {'table':>6s}")
    for name, (mse, sig) in runs.items():
        for j, c in enumerate(COMPONENTS + ("signal",)):
            v = mse[:, j] if j < 3 else sig
            lo, hi = median_interval(v)
            q1, q3 = np.percentile(v, [25, 75])
            table = f"{TABLE[name][j]:6.2f}" if name in TABLE and j < 3 else ""
            print(f"{name:12s} {c:6s} {v.mean():8.3f} {np.median(v):8.3f} "
                  f"  [{lo:6.3f}, {hi:6.3f}]  [{q1:6.3f}, {q3:6.3f}] "
                  f"{np.sqrt(np.median(v)):12.3f} {table}")
        assert np.all(np.isfinite(mse)) and np.all(np.isfinite(sig)), name


@pytest.mark.xfail(strict=True, reason=(
    "Does not hold here: over the 1 000 runs the UKF's mean theta-MSE is 5.49 and the "
    "EKF's 1.41 (paired difference +4.09, standard error 2.00, so the UKF is worse at about "
    "two standard errors); the medians agree in direction (UKF 0.084, EKF 0.076) and the UKF "
    "has the lower theta-MSE in 39 % of the runs. Its mean is driven by runs that slip to "
    "the mirror solution or diverge (8 of the UKF's, 1 of the EKF's, by the engine's rule). "
    "The UKF here is the additive-noise one with the toolbox's kappa = 3 - n = 0, not the "
    "demo's augmented UKF (kappa = -4); see the scenario's notes."))
def test_ukf_mean_theta_mse_is_no_worse_than_the_ekfs(runs):
    """The thesis's claim (Table 2-1: theta-MSE 0.64 -> 0.59): the UKF's mean theta-MSE
    over the runs is no worse than the EKF's."""
    ekf, ukf = runs["EKF"][0][:, 0], runs["UKF"][0][:, 0]
    d = ukf - ekf
    print(f"\ntheta-MSE mean: UKF {ukf.mean():.3f}, EKF {ekf.mean():.3f}; paired difference "
          f"{d.mean():+.3f} (standard error {d.std(ddof=1) / np.sqrt(len(d)):.3f}); UKF "
          f"lower in {np.mean(d < 0):.1%} of runs")
    assert ukf.mean() <= ekf.mean()


def _case(name: str, j: int, reason: str | None = None):
    marks = () if reason is None else pytest.mark.xfail(strict=True, reason=reason)
    return pytest.param(name, j, marks=marks, id=f"{name}-{COMPONENTS[j]}")


def _below(median: str, lo: str, hi: str, table: str, pct: str) -> str:
    return (f"Does not hold here: the median over 1 000 runs is {median} (95 % interval "
            f"[{lo}, {hi}]), below a third of the table's {table} ({float(table) / 3:.3f}); "
            f"the table's value is the {pct} percentile of our runs. One run in Table 2-1 "
            "drew from the upper tail, or the thesis ran another setting (its q1, q2, dt, x0 "
            "and P0 are not printed; ours are the toolbox's [ext]).")


@pytest.mark.parametrize("name, j", [
    _case("EKF", 0, _below("0.076", "0.073", "0.083", "0.64", "87th")),
    _case("EKF", 1),
    _case("EKF", 2, _below("0.060", "0.058", "0.062", "0.40", "91st")),
    _case("UKF", 0, _below("0.084", "0.080", "0.089", "0.59", "92nd")),
    _case("UKF", 1),
    _case("UKF", 2, _below("0.119", "0.110", "0.125", "0.39", "96th")),
])
def test_median_mse_is_within_a_factor_3_of_table_2_1(runs, name, j):
    """Each filter's median MSE of theta, omega and a over the runs lies within a factor of
    3 of Table 2-1's single run, with its whole 95 % interval inside [table/3, 3 table]."""
    v = runs[name][0][:, j]
    lo, hi = median_interval(v)
    table = TABLE[name][j]
    print(f"\n{name} {COMPONENTS[j]}: median {np.median(v):.3f} [{lo:.3f}, {hi:.3f}], table "
          f"{table} (band [{table / FACTOR:.3f}, {table * FACTOR:.3f}]); the table's value is "
          f"the {np.mean(v < table):.0%} quantile of the runs")
    assert table / FACTOR <= lo and hi <= table * FACTOR
