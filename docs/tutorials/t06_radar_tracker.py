"""
A radar tracker: constant gains, manoeuvres, the IMM and missing plots
======================================================================

The missing-measurements thesis (see :doc:`/references`) builds a radar tracker from the
bottom up: the alpha-beta tracker and its gain designs, manoeuvre detection from the
innovations, the interacting multiple model filter (IMM), and, its own contribution, ways of
keeping a track while the plots stop for a while. This tutorial follows it on the thesis's
turning target: design alpha-beta gains (:class:`trackkit.filters.AlphaBeta`) and check
their variance reduction, watch two detectors (:class:`trackkit.filters.NISDetector`,
:class:`trackkit.filters.WindowDetector`) find the turns, and run the alpha-beta tracker and
an IMM (:class:`trackkit.filters.IMM`) through two gaps in the plots with
:func:`trackkit.filters.run_with_gaps`, coasting or fed with a fitted line.

.. budget: 12 s
"""

# %%
# The target
# ----------
#
# The bundled scenario ``imm-turn`` is the thesis's section 4-5 (with the numbers of the
# EKF/UKF toolbox demo it follows): a target at 1 m/s, straight for 3.9 s, a turn at
# 1 rad/s for 5 s, straight for 2 s, a turn back for 5 s, straight again; a position plot
# every 0.1 s with 0.22 m of noise per axis. ``trackkit run imm-turn`` compares the IMM with
# its two models alone (100 runs); :doc:`/radar-comparison` has the numbers. Here we take
# the scenario's truths and plots for 200 runs and build the trackers ourselves.

import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.filters import alphabeta as ab
from trackkit.scenario import load
from trackkit.scenario.build import compile_scenario
from trackkit.scenario.simulate import simulate_block

plan = compile_scenario(load("imm-turn"))
runs = 200
data = simulate_block(plan, 0, runs)  # truth (201, runs, 4) [x, y, vx, vy]; z (200, runs, 2)
radar, dt, t = plan.sensors[0], plan.dt, plan.times[1:]
sigma = np.sqrt(radar.noise[0, 0])
P0 = plan.prior_cov
prior = tk.Gaussian(data.truth[0] + data.prior_offset @ np.linalg.cholesky(P0).T,
                    np.broadcast_to(P0, (runs, 4, 4)).copy())
turns = [(leg.start, leg.end) for leg in plan.target_legs]  # s


def position_rmse(mean):
    """Position RMSE over the runs at each step, ``mean (steps, runs, >= 2)``."""
    return np.sqrt(((mean[..., :2] - data.truth[1:, :, :2]) ** 2).sum(-1).mean(1))


# %%
# Alpha-beta gains
# ----------------
#
# An alpha-beta tracker filters each coordinate with two constant gains. Its steady-state
# noise reduction has a closed form, the variance reduction ratio
# (:func:`trackkit.filters.alphabeta.vrr`): on a straight line the position error variance
# per axis is :math:`\mathrm{VRR}_x \sigma^2`. The thesis's gain designs: Kohn's pair, the
# Benedict-Bordner curve (best trade-off between noise and a velocity step) and the
# critically damped fading-memory gains; larger gains follow a manoeuvre faster and smooth
# less.

designs = {"Kohn": ab.kohn(),
           "Benedict-Bordner, alpha 0.3": (0.3, ab.benedict_bordner(0.3)),
           "fading memory, xi 0.5": ab.fading_memory(0.5)}
for name, (a, b) in designs.items():
    v = ab.vrr(a, b, dt)
    print(f"{name:28s} alpha {a:.3f} beta {b:.4f}  VRR(x) {v.x:.3f}  stable "
          f"{ab.is_stable(a, b)}  predicted position RMSE {np.sqrt(2 * v.x) * sigma:.3f} m")

# %%
# Kohn's gains on the first straight leg: once the start-up has died out (the roots of the
# characteristic polynomial, :func:`trackkit.filters.alphabeta.roots`, say how fast), the
# measured error should match the VRR's prediction, because the truth has no process noise,
# the case the VRR describes. (The tracker also carries the exact covariance of a
# constant-gain estimator, so its NEES means something.) We pass the IMM's
# constant-velocity model: the tracker predicts with its transition, and its Q enters only
# the covariance it carries; the gains stay constant.

cv = tk.models.ConstantVelocity(dim=2, q=0.01)
kohn = tk.filters.AlphaBeta(*ab.kohn())
_, hist = tk.filters.run_filter(kohn, kohn.init(prior), cv, radar, data.z, dt, history=True)
print(f"largest root of Kohn's gains: {np.abs(ab.roots(*ab.kohn())).max():.3f}")
leg = (t >= 1.5) & (t < 3.9)
print(f"Kohn, straight leg: {np.sqrt(np.mean(position_rmse(hist.mean)[leg] ** 2)):.3f} m "
      f"measured, {np.sqrt(2 * ab.vrr(*ab.kohn(), dt).x) * sigma:.3f} m from the VRR")

# %%
# Manoeuvre detection
# -------------------
#
# A filter whose model is right has white innovations with covariance S; a turn makes them
# large and correlated. :class:`~trackkit.filters.NISDetector` tests each step's normalised
# innovation squared against its chi-square quantile,
# :class:`~trackkit.filters.WindowDetector` the sum of the last L residuals; both thresholds
# come from a false-alarm probability per step. :func:`trackkit.filters.run_with_detector`
# runs a filter with a detector on its innovations (and, if asked, a response such as
# :class:`trackkit.filters.QInflation`); here it only watches a constant-velocity KF.

detectors = {"NIS": tk.filters.NISDetector(pfa=0.01, dim_z=2),
             "window, L = 5": tk.filters.WindowDetector(L=5, pfa=0.01, dim_z=2)}
watched = {name: tk.filters.run_with_detector(tk.filters.KF(), prior, cv, radar, data.z, dt,
                                              det)
           for name, det in detectors.items()}
before = t < turns[0][0]
for name, res in watched.items():
    above = res.statistic[before] > detectors[name].threshold
    found = res.fired & (t >= turns[0][0])[:, None]
    onset = np.where(found.any(0), t[np.argmax(found, axis=0)] - turns[0][0], np.nan)
    print(f"{name:14s} above its threshold at {100 * above.mean():.2f}% of the run-steps "
          f"before the first turn (designed: 1%); turn found after a median "
          f"{np.nanmedian(onset):.1f} s")

# %%
# A detector stays on until its statistic has been below an off threshold for a few steps
# (``n_off``), so the fraction of runs in which it is on (the figure) is larger than its
# false-alarm rate. The window detector pools five residuals: one large residual moves it
# less than the NIS, a run of moderate ones (a turn) more, and it stays on through the turns
# more steadily.
#
# The IMM
# -------
#
# The IMM runs a constant-velocity KF and a coordinated-turn EKF side by side and mixes them
# by their mode probabilities. Its state is the larger model's, ``[x, y, vx, vy, omega]``;
# the turn rate gets a prior of its own.

ct = tk.models.CoordinatedTurn(q=0.0, q_omega=0.15)
imm = tk.filters.IMM([cv, ct], [tk.filters.KF(), tk.filters.EKF()],
                     [[0.9, 0.1], [0.1, 0.9]], mu0=[0.95, 0.05])
prior5 = tk.Gaussian(np.concatenate([prior.mean, np.zeros((runs, 1))], -1),
                     np.pad(prior.cov, ((0, 0), (0, 1), (0, 1))))
prior5.cov[:, 4, 4] = 1.0  # (rad/s)^2
p_turn = []
tk.filters.run_filter(imm, imm.init(prior5), None, radar, data.z, dt,
                      on_step=lambda k, b, innov: p_turn.append(b.mu[:, 1].mean()))

# %%
# Missing plots
# -------------
#
# Two gaps of 1 s: one on the first straight leg, one in the middle of the first turn.
# :func:`trackkit.filters.mask_by_time` marks the steps
# (:func:`~trackkit.filters.mask_by_samples` and :func:`~trackkit.filters.mask_by_count` do
# the same by index), :func:`trackkit.filters.union` joins them. A gap
# handler decides what the filter is fed: :class:`trackkit.filters.Coast` (the thesis's
# B0) nothing, so the filter predicts through; :class:`trackkit.filters.PolynomialFit`
# (its P) a least-squares line through the last 15 plots, extrapolated;
# :class:`trackkit.filters.HoldLast` (B1) and :class:`trackkit.filters.MeanOfLast` (B2)
# repeat the last plot or the mean of the last few.

gaps = [(2.4, 3.4), (6.0, 7.0)]
mask = tk.filters.union(*(tk.filters.mask_by_time(t, a, b) for a, b in gaps))
fit = tk.filters.PolynomialFit(degree=1, window=15)
runs_with_gaps = {
    "alpha-beta (Kohn), coast": (kohn, prior, cv, tk.filters.Coast()),
    "IMM, coast": (imm, prior5, None, tk.filters.Coast()),
    "IMM, fitted line": (imm, prior5, None, fit),
}
errors = {}
for name, (f, pr, motion, handler) in runs_with_gaps.items():
    res = tk.filters.run_with_gaps(f, pr, motion, radar, data.z, dt, mask, handler)
    errors[name] = position_rmse(res.estimate.mean)

windows = {"whole track": np.ones(len(t), bool),
           "straight gap": tk.filters.mask_by_time(t, *gaps[0]),
           "turning gap": tk.filters.mask_by_time(t, *gaps[1]),
           "second turn": tk.filters.mask_by_time(t, *turns[1])}
print(f"{'position RMSE [m]':26s}" + "".join(f"{w:>14s}" for w in windows))
for name, e in errors.items():
    print(f"{name:26s}" + "".join(f"{np.sqrt(np.mean(e[w] ** 2)):14.3f}"
                                  for w in windows.values()))

# %%
# Through the turning gap the alpha-beta tracker coasts on a straight line while the target
# turns; the IMM's turn model, weighted up by the turn before the gap, predicts the arc. A
# line fitted to the last plots cannot follow an arc either, and fed to the IMM as if it
# were plots (with the radar's R) it does worse than letting the IMM coast: the comparison
# page finds the same in every turn it tried, while on a straight leg the fit can help. The
# damage outlasts the gap here: the pseudo-plots bend the turn model's turn rate, which the
# IMM learns back only slowly, so the second turn, seconds later, is tracked worse too. The
# thesis's claim for the fitted curve holds where its premise does, a filter whose model
# misses the target's motion (:doc:`/radar-comparison`, the ``gaps-*`` scenarios).

fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
for ax in (ax1, ax2):
    for a, b in turns:
        ax.axvspan(a, b, color="0.92")
    for a, b in gaps:
        ax.axvspan(a, b, color="tab:red", alpha=0.15)
for name, e in errors.items():
    ax1.plot(t, e, lw=1.2, label=name)
ax1.axhline(sigma * np.sqrt(2), color="k", lw=0.8, ls=":", label="error of a raw plot")
ax1.set_ylabel("position RMSE [m]")
ax1.set_title(f"imm-turn, {runs} runs: turns grey, gaps red")
ax1.legend(fontsize=8)
for name, res in watched.items():
    ax2.plot(t, res.on.mean(1), lw=1.2, label=f"{name} detector on (KF, CV)")
ax2.plot(t, p_turn, lw=1.2, label="IMM: probability of the turn model")
ax2.set_ylabel("fraction of runs / probability")
ax2.set_xlabel("time [s]")
ax2.legend(fontsize=8)
fig.tight_layout()
plt.show()
