"""
Kalman filters on a bearings-only problem, against the PCRLB
=============================================================

The EKF, UKF and CKF on one bearings-only problem, 500 Monte Carlo runs filtered as one batch
per filter, and their position RMSE against the square root of the posterior Cramer-Rao
lower bound (Tichavský, Muravchik and Nehorai 1998), which bounds the error of every
estimator. The geometry is that of ``bo-cv``, the default scenario of ``trackkit run``: the
classic two-leg geometry, an observer that turns once so that the range becomes observable.

.. budget: 10 s
"""

# %%
# The problem
# -----------
# The bundled ``bo-cv`` scenario, as ``trackkit run`` simulates it:
# :func:`trackkit.scenario.build.compile_scenario` turns it into models, sensors and times,
# :func:`trackkit.scenario.simulate.simulate_block` draws each run's truth and bearings from
# that run's own random stream. A constant-velocity target 12 km north of an observer that
# sails at 8 kn and turns 90 deg between 600 s and 690 s; a bearing (1 deg) every 5 s.
# Leading axes are runs: the truth is ``(T + 1, runs, 4)``, the bearings ``(T, runs, 1)``;
# each run's prior mean is its truth plus a draw from N(0, P0), as the scenario says.
import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.eval import pcrlb, rmse_bound
from trackkit.scenario import load
from trackkit.scenario.build import compile_scenario
from trackkit.scenario.simulate import simulate_block

runs = 500

scenario = load("bo-cv")
plan = compile_scenario(scenario)
data = simulate_block(plan, 0, runs)
truth, z, t = data.truth, data.z, plan.times
T, dt = t.size - 1, float(t[1] - t[0])
motion, sensors, P0 = plan.truth_motion, plan.sensors, plan.prior_cov
observer = plan.observer_states[0]  # (T + 1, 4): the observer's position and velocity
prior = data.prior(P0)  # each run's truth plus a draw from N(0, P0)

print(f"truth {truth.shape}, bearings {z.shape}")

# %%
# Filters and bound
# -----------------
# :func:`trackkit.filters.run_filter` streams a filter over the bearings (one sensor per step:
# the observer moves); ``history=True`` keeps every step's estimate. The plain
# :class:`trackkit.filters.KF` refuses a nonlinear sensor such as
# :class:`trackkit.models.Bearing`, so the comparison starts at the
# :class:`trackkit.filters.EKF`. :func:`trackkit.eval.pcrlb` runs the bound's recursion on
# the same truths, and :func:`trackkit.eval.rmse_bound` turns it into a position RMSE.
filters = {"EKF": tk.filters.EKF(), "UKF": tk.filters.UKF(), "CKF": tk.filters.CKF()}
rmse = {}
for name, f in filters.items():
    _, hist = tk.filters.run_filter(f, prior, motion, sensors, z, dt, history=True)
    err = hist.mean[..., :2] - truth[1:, :, :2]
    rmse[name] = np.sqrt((err**2).sum(-1).mean(-1))  # (T,) over the runs

bound = rmse_bound(pcrlb(P0, motion, sensors, truth, dt), [0, 1])
late = t[1:] >= 900.0
for name, r in rmse.items():
    print(f"{name}: RMSE after 900 s {r[late].mean():6.1f} m, "
          f"{(r[late] / bound[late]).mean():.2f} x sqrt(PCRLB)")
print(f"sqrt(PCRLB) after 900 s: {bound[late].mean():.1f} m")

# %%
# RMSE against the bound
# ----------------------
# Before the turn the bearings fix the line of sight but not the range, whose error grows
# with the uncertain velocity; the turn makes the range observable and the errors fall
# towards the bound. Along the second leg the filters drift away from it again: the bound
# takes every bearing's information at the true state, and a posterior stretched along the
# line of sight is not the Gaussian it assumes.
fig, ax = plt.subplots(figsize=(7, 4))
for name, r in rmse.items():
    ax.plot(t[1:], r, label=name)
ax.plot(t[1:], bound, "k--", label=r"$\sqrt{\mathrm{PCRLB}}$")
ax.axvspan(600.0, 690.0, color="0.9", label="observer turns")
ax.set_yscale("log")
ax.set_xlabel("time (s)")
ax.set_ylabel("position RMSE (m)")
ax.set_title(f"Bearings-only, {runs} runs")
ax.legend()
fig.tight_layout()
plt.show()
