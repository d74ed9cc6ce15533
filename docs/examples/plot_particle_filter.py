"""
The particle filter and its effective sample size
=================================================

Before a bearings-only observer manoeuvres, the bearings fix the line of sight and nothing
along it: the posterior is a long, curved ridge, not the ellipse a Kalman filter carries. The
bootstrap particle filter (Gordon, Salmond and Smith 1993), :class:`trackkit.filters.PF`,
represents it by weighted samples and resamples a run when its effective sample size
``1 / sum w_i^2`` (Kish 1965) falls below half the particles. Here: its cloud at three times
of one run, and how the effective sample size and the resampling go over 20 runs.

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
from trackkit.filters.resample import effective_sample_size
from trackkit.scenario import load
from trackkit.scenario.build import compile_scenario
from trackkit.scenario.simulate import simulate_block

runs, N = 20, 1000

scenario = load("bo-cv")
plan = compile_scenario(scenario)
data = simulate_block(plan, 0, runs)
truth, z, t = data.truth, data.z, plan.times
T, dt = t.size - 1, float(t[1] - t[0])
motion, sensors, P0 = plan.truth_motion, plan.sensors, plan.prior_cov
observer = plan.observer_states[0]  # (T + 1, 4): the observer's position and velocity
prior = data.prior(P0)  # each run's truth plus a draw from N(0, P0)

# %%
# The filter, step by step
# ------------------------
# The particle filter of ``bo-cv``: :class:`trackkit.filters.RangePF` draws the particles at
# the first bearing from the Gaussian prior conditioned on it (drawn from the prior itself, a
# run whose prior lies three sigmas off keeps only a few draws near that bearing), and
# ``regularise=True, shrink=True``: after resampling, a Gaussian-kernel jitter keeps the
# copies of one particle apart, with Liu and West's shrinkage so that the jitter does not
# widen the cloud. The scenario runs 2 000 particles; this example 1 000. The belief is
# :class:`trackkit.belief.Particles`, ``states (runs, N, 4)``
# and ``log_weights (runs, N)``; after each update the effective sample size of every run
# is read from its weights. A run just resampled has equal weights, an ESS of exactly N.
# For scale, an EKF filters the same runs.
pf = tk.filters.RangePF(n_particles=N, ess_threshold=0.5, regularise=True, shrink=True,
                        prior="bearing")
b = pf.init(prior, rng=np.random.default_rng(1))
ess = np.empty((T, runs))
means = np.empty((T, runs, 4))
clouds = {}
for k in range(T):
    b = pf.predict(b, motion, dt)
    b, _ = pf.update(b, z[k], sensors[k])
    ess[k] = effective_sample_size(b.log_weights)
    means[k] = pf.estimate(b).mean
    if t[k + 1] in (300.0, 900.0, 1500.0):
        clouds[t[k + 1]] = b.states[0, :, :2].copy()
resampled = np.isclose(ess, N, rtol=1e-9)

_, ekf = tk.filters.run_filter(tk.filters.EKF(), prior, motion, sensors, z, dt, history=True)
late = t[1:] >= 900.0
for name, m in (("PF", means), ("EKF", ekf.mean)):
    e2 = ((m[late, :, :2] - truth[1:][late, :, :2]) ** 2).sum(-1)
    print(f"{name}: position RMSE after 900 s over {runs} runs {np.sqrt(e2.mean()):6.1f} m")
print(f"share of runs resampled: {resampled[0].mean():.0%} at the first bearing, "
      f"{resampled[1:].mean():.0%} of the later steps; mean ESS after the first bearing "
      f"{ess[1:].mean() / N:.2f} N")

# %%
# Cloud and effective sample size
# -------------------------------
# On the first leg the cloud stretches kilometres along the line of sight; after the turn it
# closes in around the target. The particles are drawn along the first bearing's rays,
# already weighted by the prior, so no run needs to resample there; after that each bearing
# reweights a cloud that already agrees with it, and a run resamples only now and then (the
# shares printed above).
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4.5), width_ratios=(1, 1.2))
ax0.plot(truth[:, 0, 0] / 1e3, truth[:, 0, 1] / 1e3, "k", lw=1, label="target")
ax0.plot(observer[:, 0] / 1e3, observer[:, 1] / 1e3, "k--", lw=1, label="observer")
for (when, X), colour in zip(clouds.items(), ("C0", "C1", "C2"), strict=True):
    ax0.plot(X[:, 0] / 1e3, X[:, 1] / 1e3, ".", ms=1, color=colour, alpha=0.5)
    ax0.plot([], [], "o", color=colour, label=f"particles, {when:.0f} s")
ax0.set_xlabel("east (km)")
ax0.set_ylabel("north (km)")
ax0.set_aspect("equal")
ax0.set_title("run 0")
ax0.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.0, 1.0))

ax1.plot(t[1:], ess.mean(1) / N, label="mean ESS / N after the update")
ax1.plot(t[1:], ess[:, 0] / N, lw=0.8, alpha=0.7, label="ESS / N, run 0")
ax1.step(t[1:], resampled.mean(1), where="mid", lw=0.8, label="share of runs resampled")
ax1.axhline(pf.pf.ess_threshold, color="k", ls=":", lw=1, label="threshold")
ax1.axvspan(600.0, 690.0, color="0.9", label="observer turns")
ax1.set_xlabel("time (s)")
ax1.set_ylabel("fraction")
ax1.set_ylim(0, 1.3)
ax1.legend(fontsize="small", loc="upper center", ncol=2)
fig.tight_layout()
plt.show()
