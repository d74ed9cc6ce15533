"""
Your first comparison: ``trackkit run``
=======================================

``trackkit run`` with no argument runs the default scenario, ``bo-cv``: a Monte Carlo
comparison of seven filters on the classic two-leg bearings-only problem of passive sonar
(the field of Naseri Solhdar's thesis), the bearings-only specialists of Arulampalam and
Ristic (2000) among them. Here you run the same comparison through the library, read the
report it writes, and learn the two questions every trackkit report answers: how close a
filter's error comes to the posterior Cramér-Rao lower bound (PCRLB) of Tichavský, Muravchik
and Nehorai (1998), and whether the filter's own covariance is honest about its error (the
NEES against its chi-square band).

.. budget: 25 s
"""

# %%
# The command
# -----------
#
# .. code-block:: bash
#
#     trackkit run                              # bo-cv, its 200 runs, into trackkit-out/bo-cv/
#     trackkit run bo-cv --runs 50 --out my-run/
#
# It prints a summary table and writes its report into the output directory (the options are
# on :doc:`/cli`). The command loads the scenario with :func:`trackkit.scenario.load`, runs it
# with :func:`trackkit.experiments.compare.compare` (which tunes any fuzzy filter first, then
# runs the Monte Carlo comparison) and writes the files with
# :func:`trackkit.report.files.write_report`. The same three calls from Python, on 50 runs
# instead of the scenario's 200, so every number below comes from the reduced run:

import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from trackkit.experiments.compare import compare
from trackkit.report.files import write_report
from trackkit.scenario import load

scenario = load("bo-cv")
print(scenario.description)
print(f"{scenario.run.runs} runs by default, seed {scenario.run.seed}; "
      f"{scenario.time.duration_s:g} s in steps of {scenario.time.step_s:g} s")
for f in scenario.filters:
    print(f"  {f.name:6s} {f.type:6s} {f.options}")

result = compare(scenario, runs=50)
out = Path(tempfile.mkdtemp())
paths = write_report(result, out)

# %%
# What it writes
# --------------
#
# ``results.json`` holds the numbers of the summary (time averages, SI units, each quantity's
# unit under ``units``): equal seeds give a byte-identical file. ``metrics.parquet`` holds the
# same quantities per step, ``timings.json`` the wall-clock times, the PNG figures and
# ``report.html`` the pictures and the table on one self-contained page. The command adds
# ``manifest.json``, the list of what it wrote, with each file's size and checksum.

for p in sorted(paths.values(), key=lambda p: p.name):
    print(f"{p.name:16s} {p.stat().st_size:>9,d} bytes")
doc = json.loads(paths["results"].read_text(encoding="utf-8"))
print("results.json, EKF:", json.dumps(doc["filters"]["EKF"]))
print("results.json, PCRLB:", json.dumps(doc["pcrlb"]))
print("results.json, units:", json.dumps(doc["units"]))

# %%
# The summary table
# -----------------
#
# The returned :class:`trackkit.experiments.results.MonteCarloResult` holds everything the
# table and the files are made of. Each filter's RMSE is averaged over the steps after
# convergence (from ``report.average_from_s``, here after the observer's turn has made range
# observable). The command's table has the same rows for velocity, speed and course, the
# average NIS and the time per step as well.

start_s = result.times[result.start]
print(f"{result.runs} runs, averages over t >= {start_s:g} s")
print(f"{'filter':7s} {'RMSE pos [m]':>12s} {'RMSE/PCRLB':>10s} {'ANEES':>8s} "
      f"{'NEES in band':>12s} {'diverged':>8s}")
for name, f in result.filters.items():
    print(f"{name:7s} {f.rmse_mean['position']:12.1f} {result.efficiency(name, 'position'):10.2f}"
          f" {f.anees:8.3g} {f.nees_in_bounds:12.0%} {f.diverged:>5d}/{result.runs}")
print(f"{'PCRLB':7s} {result.pcrlb_mean['position']:12.1f} {1.0:10.2f}")

# %%
# RMSE against the PCRLB
# ----------------------
#
# For any estimator :math:`\hat x_k` of the state, the PCRLB bounds the mean square error from
# below, :math:`\mathrm{E}[(\hat x_k - x_k)(\hat x_k - x_k)^\top] \succeq J_k^{-1}`, where
# :math:`J_k` is the Fisher information that the prior, the motion model and every
# measurement up to step :math:`k` carry about the state, propagated by the recursion of
# Tichavský, Muravchik and Nehorai (1998) at the true states of the runs
# (:class:`trackkit.eval.PCRLB`). The square root of the trace of its position block,
# :math:`\sqrt{\mathrm{PCRLB}}`, is a floor under the position RMSE of any filter (not always
# one a filter can reach: the scenario's notes say when it is not tight). A ratio
# :math:`\mathrm{RMSE}/\sqrt{\mathrm{PCRLB}}` near 1 means an *efficient* filter: it extracts
# from the bearings nearly all the information they hold. A ratio of 1.3 means 30% more error
# than the bound; a ratio far above 1 means the filter has lost the target in some runs.
#
# NEES against its chi-square band
# --------------------------------
#
# A filter also reports its covariance :math:`P_k`. The normalised estimation error squared,
# :math:`\epsilon_k = (\hat x_k - x_k)^\top P_k^{-1} (\hat x_k - x_k)`, averaged over :math:`R`
# runs, is :math:`\chi^2_{Rn}/R` for a *consistent* filter (one whose covariance is its real
# error spread): its mean is the state dimension :math:`n = 4`, and 95% of the steps should
# fall inside the two-sided band from :func:`trackkit.eval.chi2_bounds`. Above the band the
# filter is overconfident (its covariance is too small, so it will weigh new bearings too
# little), below it pessimistic. ANEES is the average over the steps after convergence.

lo, hi = result.filters["EKF"].nees_bounds
print(f"with {result.runs} runs the band at each step is {lo[-1]:.2f} to {hi[-1]:.2f} "
      f"around n = 4")
best = min(result.filters, key=lambda n: result.efficiency(n, "position"))
print(f"closest to the bound: {best}, RMSE/PCRLB = {result.efficiency(best, 'position'):.2f}, "
      f"ANEES = {result.filters[best].anees:.2f}")
iekf = [note for note in result.notes if note.startswith("Expect the IEKF")]
print("\n".join(iekf))

# %%
# The two figures of the report
# -----------------------------
#
# ``rmse.png`` and ``nees.png`` of the report, drawn here from the result. Range is
# unobservable on the first leg (the bound itself is large there); the observer's turn
# (shaded) makes it observable, and the errors fall towards the bound. Both axes are
# logarithmic because a diverging filter sits orders of magnitude above the others; the NEES
# panel is cut at 30 so that the band stays readable.

print(f"largest average NEES: {max(f.nees.max() for f in result.filters.values()):.3g}")

t = result.times
turn = scenario.observers[0].legs[0]
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7.5), sharex=True)
for name, f in result.filters.items():
    ax1.plot(t, f.rmse["position"], lw=1.2, label=name)
    ax2.plot(t, f.nees, lw=1.0, label=name)
ax1.plot(t, result.pcrlb["position"], "k--", lw=2, label=r"$\sqrt{\mathrm{PCRLB}}$")
ax2.fill_between(t, lo, hi, color="0.8", label="95% band")
for ax in (ax1, ax2):
    ax.axvspan(turn.start_s, turn.end_s, color="0.5", alpha=0.15)
    ax.axvline(start_s, color="0.4", lw=0.8, ls=":")
    ax.set_yscale("log")
ax1.set_ylabel("position RMSE [m]")
ax1.set_title(f"bo-cv, {result.runs} runs (observer turn shaded; averages right of the "
              "dotted line)")
ax1.legend(ncols=4, fontsize="small")
ax2.axhline(4, color="k", lw=0.8)
ax2.set_ylim(1.0, 30.0)
ax2.set_ylabel("average NEES [-]")
ax2.set_xlabel("time [s]")
ax2.legend(ncols=4, fontsize="small")
fig.tight_layout()
plt.show()
