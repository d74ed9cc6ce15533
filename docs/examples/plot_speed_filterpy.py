"""
Speed against FilterPy: the batched EKF and UKF
===============================================

FilterPy filters one problem step by step; trackkit filters a whole batch of Monte Carlo runs
in one call per step. This example times both on the problem of the core benchmark
(``benchmarks/bench_core.py``: bearings-only tracking of a constant-velocity target from a
weaving observer), checks that the two compute the same estimate, and draws the time per
step. It imports the benchmark's problem and timers rather than copying them, at a reduced
number of steps.

.. budget: 12 s
"""

# %%
# The benchmark's problem and timers
# ----------------------------------
# ``problem(runs, steps)`` simulates the bearings of ``runs`` independent runs;
# ``time_trackkit`` runs one trackkit filter over all of them, batched, and the FilterPy
# timers run run 0 alone with FilterPy's ``ExtendedKalmanFilter`` (the analytic Jacobian)
# and ``UnscentedKalmanFilter`` (``MerweScaledSigmaPoints(alpha=0.5, beta=2, kappa=-1)``,
# the sigma points of trackkit's default :class:`trackkit.filters.UKF`). FilterPy's filters
# are built inside the timers, so a subclass that remembers each one lets us read the
# estimate a timed run ended with. FilterPy's EKF keeps its state as a column ``(4, 1)``
# and needs its measurement as a column too (given ``(1,)``, ``x + K y`` broadcasts to
# ``(4, 4)``), so its timer is handed the bearings with a trailing axis.
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

# this file's path: sphinx-gallery gives it as sys.argv[0], a plain run also as __file__
here = Path(globals().get("__file__", sys.argv[0])).resolve()
sys.path.insert(0, str(here.parents[2] / "benchmarks"))
import bench_core as bench  # noqa: E402

import trackkit as tk  # noqa: E402

built = {}


def remembered(cls, name):
    class Remembered(cls):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            built[name] = self

    return Remembered


originals = bench.ExtendedKalmanFilter, bench.UnscentedKalmanFilter
bench.ExtendedKalmanFilter = remembered(originals[0], "EKF")
bench.UnscentedKalmanFilter = remembered(originals[1], "UKF")

RUNS, STEPS, REPEAT = 1000, 150, 3  # the benchmark: 1 000 runs of 2 000 steps
motion, observer, zs, prior = bench.problem(RUNS, STEPS)
print(f"bearings {zs.shape}: (steps, runs, 1)")
fp_bearings = {"EKF": zs[..., None], "UKF": zs}

# %%
# Timing, interleaved
# -------------------
# Each round times FilterPy and then trackkit, so that a change of machine load hits both;
# the best of the rounds is kept. trackkit's time is divided by steps x runs: the cost of
# one run-step, the unit in which a Monte Carlo study pays.
timers = {"EKF": bench.time_filterpy_ekf, "UKF": bench.time_filterpy_ukf}
filters = {"EKF": tk.filters.EKF(), "UKF": tk.filters.UKF()}
per_step = {}
for name in timers:
    t_fp = t_tk = np.inf
    for _ in range(REPEAT):
        t_fp = min(t_fp, timers[name](motion, observer, fp_bearings[name], prior) / STEPS)
        t_tk = min(t_tk, bench.time_trackkit(filters[name], motion, observer, zs, prior)
                   / (STEPS * RUNS))
    per_step[name] = (t_fp, t_tk)
    print(f"{name}: FilterPy {t_fp * 1e6:7.2f} us/step, trackkit {t_tk * 1e6:6.3f} us/run-step,"
          f" ratio {t_fp / t_tk:5.0f}x")
bench.ExtendedKalmanFilter, bench.UnscentedKalmanFilter = originals  # the module as it was

# %%
# The same computation
# --------------------
# Run 0 of trackkit's batch, filtered once more through
# :func:`trackkit.filters.run_filter`, against the estimate FilterPy's last timed run ended
# with, in metres and m/s and in standard deviations of the estimate. The EKFs agree to
# rounding. The UKFs differ in one convention: trackkit averages the sigma points' bearings
# on the circle (the angle of the weighted sum of unit vectors), FilterPy by their weighted
# arithmetic mean; on this problem that moves the estimate by a few thousandths of its
# standard deviation.
sensors = [tk.models.Bearing(o, bench.SIGMA) for o in observer]
for name, f in filters.items():
    b, _ = tk.filters.run_filter(f, prior, motion, sensors, zs, bench.DT)
    ours, theirs = b.mean[0], np.ravel(built[name].x)
    diff = np.abs(ours - theirs)
    print(f"{name}: final [x, y, vx, vy] = {np.array2string(ours, precision=2)}; largest "
          f"difference from FilterPy {diff.max():.2e} (m, m/s), "
          f"{(diff / np.sqrt(np.diag(b.cov[0]))).max():.1e} standard deviations")

# %%
# Time per step
# -------------
# Full-size numbers (2 000 steps, and the measured history of the ratios) are in
# ``benchmarks/RESULTS.md``, from ``python benchmarks/bench_core.py``. The numbers here come
# from the reduced run above and from whatever else this machine is doing; expect a ratio of
# about a hundred or more.
fig, ax = plt.subplots(figsize=(6, 4))
names = list(per_step)
x = np.arange(len(names))
fp = [per_step[n][0] * 1e6 for n in names]
tkk = [per_step[n][1] * 1e6 for n in names]
ax.bar(x - 0.2, fp, 0.4, label="FilterPy, one problem (per step)")
ax.bar(x + 0.2, tkk, 0.4, label=f"trackkit, {RUNS} runs batched (per run-step)")
for i in range(len(names)):
    ax.text(x[i] + 0.2, tkk[i] * 1.15, f"{fp[i] / tkk[i]:.0f}x faster", ha="center")
ax.set_xticks(x, names)
ax.set_yscale("log")
ax.set_ylim(top=30 * max(fp))  # room for the legend
ax.set_ylabel("time per step (µs)")
ax.set_title(f"Bearings-only CV target, {STEPS} steps")
ax.legend(loc="upper left")
fig.tight_layout()
plt.show()
