"""
Doppler-bearing tracking: the adaptive modified-covariance EKF
==============================================================

A passive sonar measures the bearing of a target's tone and its received, Doppler-shifted
frequency. Hashemi and Alfi (2019) track such a target with an adaptive modified-covariance
EKF (:class:`trackkit.filters.AMCEKF`) that rescales its measurement noise R and process
noise Q from a window of innovations, and claim it beats the EKF because it corrects poor
initial Q and R. This tutorial builds the paper's receding geometry from the library's
models and runs the EKF, the modified-covariance EKF (:class:`trackkit.filters.MCEKF`), a
Sage-Husa adaptive EKF (:class:`trackkit.filters.AEKF`) and the AMCEKF twice: on the
paper's premise (every filter starts from a Q ten times too large and an R at half the
truth) and with well-specified noise. All of them are scored against the posterior
Cramer-Rao bound (:func:`trackkit.eval.pcrlb`) and their own covariance (NEES).

.. budget: 25 s
"""

# %%
# The scenario and its command
# ----------------------------
#
# The bundled scenarios ``dbt-approaching``, ``dbt-receding`` and ``dbt-observer-manoeuvre``
# are the paper's three geometries with well-specified filters; each has a
# ``-misspecified`` twin with the same truths and measurements and the poor Q0 and R0. The
# full comparison (five filters, 100 runs) is one command:
#
# .. code-block:: bash
#
#    trackkit run dbt-receding-misspecified
#    trackkit run dbt-receding
#
# :doc:`/dbt-comparison` sets its numbers against the paper's. Here the same receding
# geometry is built by hand with 40 runs instead of 100, so the numbers below are noisier
# than the page's.
#
# The target starts at (6 km, 6 km) and opens the range at 15 kn on course 280; the
# observer leaves the origin at 5 kn on course 020. The state is ``[x, y, vx, vy, f0]``, the
# last component the emitted tone (500 Hz), which the filters estimate too. Neither vessel
# manoeuvres and the truth has no process noise.

import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.eval import chi2_bounds, pcrlb, rmse_bound

KNOT = 1852.0 / 3600.0  # m/s
runs, steps, dt = 40, 2000, 1.0
t = dt * np.arange(1, steps + 1)  # measurement times, s


def velocity(course_deg, speed_kn):
    c = np.deg2rad(course_deg)
    return speed_kn * KNOT * np.array([np.sin(c), np.cos(c)])  # nautical: clockwise from north


x0 = np.r_[6000.0, 6000.0, velocity(280.0, 15.0), 500.0]
truth_motion = tk.models.Augmented(tk.models.ConstantVelocity(dim=2, q=0.0), 1, 0.0)
truth = np.empty((steps + 1, runs, 5))  # (time, runs, state): runs are a batch axis
truth[0] = x0
for k in range(steps):
    truth[k + 1] = truth_motion.f(truth[k], dt)

v_obs = velocity(20.0, 5.0)
sensors = [tk.models.BearingFrequency(origin=v_obs * tk_s, velocity=v_obs,
                                      sigma_bearing=np.deg2rad(2.0), sigma_freq=0.3)
           for tk_s in t]  # one sensor per step: the observer moves

rng = np.random.default_rng(2019)
z = np.stack([s.h(x) for s, x in zip(sensors, truth[1:], strict=True)])  # (steps, runs, 2)
z += rng.standard_normal(z.shape) * np.sqrt(np.diagonal(sensors[0].noise))
z[..., 0] = tk.angles.wrap(z[..., 0])

# %%
# The premise: poor Q0 and R0
# ---------------------------
#
# Every filter starts from the same prior, the truth plus a draw from
# :math:`N(0, P_0)` with :math:`P_0 = \mathrm{diag}(1000\,\mathrm{m}, 1000\,\mathrm{m},
# 5\,\mathrm{m/s}, 5\,\mathrm{m/s}, 2\,\mathrm{Hz})^2`. On the premise, the filters
# believe a constant-velocity target with :math:`q = 10^{-3}\,\mathrm{m^2/s^3}` (ten times
# a well-tuned :math:`10^{-4}`) and half the true measurement variances, an optimistic
# sensor model; the paper gives neither its Q0 nor its R0, and the comparison page says why
# it chose this pair. The two settings run as one batch: a leading axis of two settings
# before the runs, each with its own Q and R (:func:`trackkit.models.with_noise` replaces a
# model's noise, with batch axes of its own), so every filter makes one pass for both.

P0 = np.diag([1000.0, 1000.0, 5.0, 5.0, 2.0]) ** 2
start = truth[0] + rng.standard_normal((runs, 5)) @ np.linalg.cholesky(P0).T
settings = ["poor Q0 and R0", "well specified"]
q = np.array([1e-3, 1e-4])[:, None, None, None]  # (setting, 1, 1, 1): over runs and state
r_factor = np.array([0.5, 1.0])[:, None, None, None]
prior = tk.Gaussian(np.broadcast_to(start, (2, runs, 5)).copy(),
                    np.broadcast_to(P0, (2, runs, 5, 5)).copy())
unit = tk.models.Augmented(tk.models.ConstantVelocity(dim=2, q=1.0), 1, 0.0)  # q = 1
motion = tk.models.with_noise(unit, q * unit.noise(x0, dt))  # Q (2, 1, 5, 5)
seen = [tk.models.with_noise(s, r_factor * s.noise) for s in sensors]  # R (2, 1, 2, 2)

filters = {"EKF": tk.filters.EKF(),
           "MCEKF": tk.filters.MCEKF(),
           "AEKF": tk.filters.AEKF(forgetting=0.99),
           "AMCEKF": tk.filters.AMCEKF(window=25, second_order=True, warmup="wait")}
results = {}
for name, f in filters.items():
    _, hist = tk.filters.run_filter(f, f.init(prior), motion, seen, z, dt, history=True)
    e = truth[1:, None] - hist.mean  # (steps, setting, runs, 5)
    nees = np.einsum("tsri,tsri->tsr", e, np.linalg.solve(hist.cov, e[..., None])[..., 0])
    results[name] = np.sqrt((e[..., :2] ** 2).sum(-1).mean(-1)), nees.mean(-1)

# %%
# The AEKF stands for the paper's reference [16], an adaptive EKF it does not specify:
# Sage-Husa R adaptation with a forgetting factor of 0.99. The AMCEKF adapts R after its
# 25-innovation window is full, with the second-order term of the paper's eqs. 12-13.
#
# The bound
# ---------
#
# The posterior Cramer-Rao bound follows the truth's own model (no process noise) and the
# true R, from the prior :math:`P_0`; :func:`trackkit.eval.rmse_bound` turns the bound on
# the covariance into a bound on the position RMSE. No estimator beats it on average.

bound = rmse_bound(pcrlb(P0, truth_motion, sensors, truth, dt), [0, 1])

# %%
# The numbers
# -----------
#
# As the comparison page does, the errors are averaged from 600 s (the root of the mean
# squared error over the runs and the steps), once the filters have settled. A consistent
# filter has an average NEES of 5, the state's dimension.

late = t >= 600.0


def window_rmse(r):
    return np.sqrt(np.mean(r[late] ** 2, axis=0))


pcrlb_late = window_rmse(bound)
ekf = window_rmse(results["EKF"][0])
print(f"PCRLB from 600 s: {pcrlb_late:.1f} m")
for i, setting in enumerate(settings):
    print(f"{setting}:\n  {'filter':8s} {'RMSE [m]':>9s} {'/ PCRLB':>8s} {'/ EKF':>6s} "
          f"{'ANEES':>6s}")
    for name, (rmse, nees) in results.items():
        r = window_rmse(rmse)[i]
        print(f"  {name:8s} {r:9.1f} {r / pcrlb_late:8.2f} {r / ekf[i]:6.2f} "
              f"{nees[late, i].mean():6.2f}")
print(f"an efficient filter, well specified: {pcrlb_late / ekf[1]:.2f} of the EKF's RMSE "
      "(Hashemi and Alfi's AMCEKF/EKF: 0.47)")

# %%
# With the poor Q0 and R0 the non-adaptive filters (EKF, MC-EKF) stay several times above
# the bound: nothing in them can repair a wrong Q or R. The Sage-Husa AEKF, which adapts R
# alone, recovers part of the loss. The AMCEKF rescales R by the trace ratio of its
# innovations' window (the paper's eq. 18) and Q by its own factor, and ends at a fraction
# of the EKF's error; the paper's Table 2 gives 41.3 m against the EKF's 87.36 m for this
# geometry, a ratio of 0.47. With well-specified noise the EKF is already close to the
# bound: the AMCEKF has little left to gain, the paper's margin is out of reach there even
# for an efficient filter (the last line), and the Sage-Husa AEKF loses ground. The NEES
# says more: with well-specified noise every filter's average is below 5, because
# q = 1e-4 is more process noise than this truth has (none); on the premise the EKF's
# too-small R and too-large Q pull its NEES in opposite directions, so a NEES near 5 does
# not make it a good filter.
#
# The premise has limits. Where the truth itself has process noise and the filters know
# it, adaptation loses, and the paper's GA start
# (:func:`trackkit.filters.ga_initial_position`) mostly helps the transient:
# :doc:`/dbt-truth-and-initialisation` measures both. The bundled variants scale both
# channels of R by the same factor, which the AMCEKF's single scale factor corrects
# exactly; :doc:`/dbt-comparison` shows it failing when the bearing and frequency channels
# are wrong in opposite directions, and maps the whole Q0 x R0 plane with
# ``trackkit sweep``:
#
# .. code-block:: bash
#
#    trackkit sweep dbt-receding --param 'filters.*.motion.q=x0.1,x1,x10,x100' \
#        --param 'filters.*.r0_diag_si=x0.1,x0.5,x1,x2,x10,x100' --runs 100 --workers 2

lo, hi = chi2_bounds(runs, 5 * runs)
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7.5), sharex=True)
for i, style in enumerate(["-", "--"]):
    for name, colour in zip(filters, ["C0", "C1", "C2", "C3"], strict=True):
        rmse, nees = results[name]
        label = name if i == 0 else None
        ax1.semilogy(t, rmse[:, i], style, color=colour, lw=1, label=label)
        ax2.plot(t, nees[:, i], style, color=colour, lw=1, label=label)
ax1.semilogy(t, bound, "k", lw=2, label="PCRLB")
for setting, style in zip(settings, ["-", "--"], strict=True):
    ax1.plot([], [], style, color="0.4", label=setting)
ax1.set_ylabel("position RMSE [m]")
ax1.set_title(f"Receding target, {runs} runs")
ax1.legend(fontsize=8, ncol=2)
ax2.axhspan(lo, hi, color="0.85", label="95% band of a consistent filter")
ax2.set_ylim(0, 12)
ax2.set_ylabel("average NEES (5 states)")
ax2.set_xlabel("time [s]")
ax2.legend(fontsize=8, ncol=3)
fig.tight_layout()
plt.show()
