"""
RTS smoothing of a batch of runs
================================

A filter's estimate at step k uses the measurements up to k; the Rauch-Tung-Striebel
smoother (Rauch, Tung and Striebel 1965) runs backwards over a filtered batch and gives each
step the information of the whole record. :func:`trackkit.filters.smooth` smooths every run
of a batch at once, for any of trackkit's Gaussian filters (the unscented RTS smoother of
Särkkä (2008) for the UKF and CKF). Here: a radar's EKF tracks of 300 runs, filtered and
smoothed, their errors against the spread each claims.

.. budget: 7 s
"""

# %%
# A batch of radar tracks
# -----------------------
# A target wandering about a constant velocity (q = 0.5 m^2/s^3), a range-bearing radar at
# the origin (25 m, 0.5 deg), a plot every 2 s for 200 s; every run its own truth and plots.
import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.sim.kinematics import propagate

rng = np.random.default_rng(7)
runs, dt, T = 300, 2.0, 100
t = dt * np.arange(T + 1)
motion = tk.models.ConstantVelocity(dim=2, q=0.5)
radar = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=25.0,
                               sigma_bearing=np.deg2rad(0.5))

x0 = np.array([-4000.0, 9000.0, 40.0, -15.0])
L = np.linalg.cholesky(motion.noise(x0, dt))
truth = propagate(np.tile(x0, (runs, 1)), t, [], 2,
                  noise=rng.standard_normal((T, runs, 4)) @ L.T)
R = np.linalg.cholesky(radar.noise)
z = radar.h(truth[1:]) + rng.standard_normal((T, runs, 2)) @ R.T

P0 = np.diag([200.0**2, 200.0**2, 20.0**2, 20.0**2])
prior = tk.Gaussian(x0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T,
                    np.broadcast_to(P0, (runs, 4, 4)))

# %%
# Filter, then smooth
# -------------------
# ``history=True`` stacks the filtered means ``(T, runs, 4)`` and covariances; the smoother
# takes them, the motion model and the step, and returns the smoothed sequence in the same
# shapes.
f = tk.filters.EKF()
_, filtered = tk.filters.run_filter(f, prior, motion, radar, z, dt, history=True)
smoothed = tk.filters.smooth(f, filtered, motion, dt)
print(f"filtered {filtered.mean.shape}, smoothed {smoothed.mean.shape}")


def position_rmse(estimate):
    """RMSE over the runs, and the RMSE the estimate's own covariance claims."""
    e2 = ((estimate.mean[..., :2] - truth[1:, :, :2]) ** 2).sum(-1)
    claimed = np.trace(estimate.cov[..., :2, :2], axis1=-2, axis2=-1)
    return np.sqrt(e2.mean(-1)), np.sqrt(claimed.mean(-1))


curves = {"filtered": position_rmse(filtered), "smoothed": position_rmse(smoothed)}
for name, (actual, claimed) in curves.items():
    print(f"{name}: mean position RMSE {actual.mean():5.1f} m (its covariance claims "
          f"{claimed.mean():5.1f} m)")

# %%
# Errors over the record
# ----------------------
# The smoothed error is lowest in the middle of the record, where measurements on both sides
# count, and equals the filter's at the last step, where there is no future to use. In both
# the covariance's claim follows the actual error.
fig, ax = plt.subplots(figsize=(7, 4))
for (name, (actual, claimed)), colour in zip(curves.items(), ("C0", "C1"), strict=True):
    ax.plot(t[1:], actual, colour, label=f"{name}: RMSE over {runs} runs")
    ax.plot(t[1:], claimed, colour, ls="--", label=f"{name}: claimed by its covariance")
ax.set_xlabel("time (s)")
ax.set_ylabel("position error (m)")
ax.set_title("EKF and RTS smoother, range-bearing radar")
ax.legend()
fig.tight_layout()
plt.show()
