"""
Gating and JPDA association probabilities
=========================================

One radar scan against three tracks: which plots can belong to which track (the gate), and
how likely each pairing is once every joint assignment of plots to tracks is weighed (the
joint probabilistic data association of Bar-Shalom, Willett and Tian (2011)). These are the
two kernels under :class:`trackkit.tracking.Tracker`'s association, called here on their own:
:func:`trackkit.tracking.gate` and :func:`trackkit.tracking.jpda_probabilities`.

.. budget: 8 s
"""

# %%
# Three predicted tracks and a scan
# ---------------------------------
# The tracks' predicted beliefs (one batched :class:`trackkit.Gaussian`, axis 0 = track)
# through a position sensor give each track its predicted plot ``zhat`` and innovation
# covariance ``S`` (:func:`trackkit.tracking.predict_measurement`). Tracks 0 and 1 are close
# enough that their gates overlap.
import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit import tracking as tt

tracks = tk.Gaussian(
    np.array([[0.0, 0.0, 10.0, 0.0], [130.0, 40.0, -10.0, 0.0], [420.0, -60.0, 0.0, 5.0]]),
    np.array([np.diag([900.0, 400.0, 25.0, 25.0]),
              [[1600.0, 600.0, 0.0, 0.0], [600.0, 900.0, 0.0, 0.0],
               [0.0, 0.0, 25.0, 0.0], [0.0, 0.0, 0.0, 25.0]],
              np.diag([500.0, 2500.0, 25.0, 25.0])]))
sensor = tk.models.Position(dim=2, sigma=20.0)
pred = tt.predict_measurement(tracks, sensor)
z = np.array([[25.0, -15.0], [70.0, 25.0], [150.0, 70.0], [400.0, -20.0], [440.0, -120.0],
              [250.0, 140.0], [-120.0, 90.0], [300.0, -160.0]])  # plots (m)

# %%
# Gate and marginals
# ------------------
# The gate keeps the pairs whose squared Mahalanobis distance ``d2 = nu^T S^-1 nu`` is below
# the chi-square quantile that holds 99% of a track's own plots. The JPDA marginals
# ``beta_ij`` weigh every feasible joint event (each plot to at most one track, each track at
# most one plot) by its likelihood, with the detection probability and the clutter density;
# ``beta_i0`` is the probability that track i was not detected.
pd, clutter_density = 0.9, 1e-5  # false plots per m^2 per scan
g = tt.gate(pred.zhat, pred.S, z, p_gate=0.99)
jp = tt.jpda_probabilities(g, pd, clutter_density, p_gate=0.99)
print(f"gate threshold gamma = {g.threshold:.2f}; {g.track.size} gated pairs in "
      f"{jp.clusters.count} clusters")
for i, j, d2, beta in zip(g.track, g.det, g.d2, jp.beta, strict=True):
    print(f"track {i}, plot {j}: d2 = {d2:5.2f}, beta = {beta:.3f}")
for i, b0 in enumerate(jp.beta0):
    print(f"track {i}: beta_0 (not detected) = {b0:.3f}")

# %%
# The picture
# -----------
# Gates as ellipses, gated pairs as lines whose width is ``beta_ij``. Plots 0 and 1 both lie
# in the two overlapping gates: weighing the joint events gives plot 0 almost wholly to
# track 0, and plot 1 more to track 1 than to track 0, though track 1's likeliest plot is
# its nearest, plot 2. Track 2's two plots have similar likelihoods, and its probability is
# split between them (the numbers printed above).
fig, ax = plt.subplots(figsize=(8, 5.5))
u = np.linspace(0, 2 * np.pi, 200)
circle = np.stack([np.cos(u), np.sin(u)])
for i, (zh, S) in enumerate(zip(pred.zhat, pred.S, strict=True)):
    ring = zh[:, None] + np.sqrt(g.threshold) * np.linalg.cholesky(S) @ circle
    ax.plot(*ring, color=f"C{i}")
    ax.plot(*zh, "+", color=f"C{i}", ms=10, mew=2, label=f"track {i}: gate, predicted plot")
for i, j, beta in zip(g.track, g.det, jp.beta, strict=True):
    ax.plot(*np.stack([pred.zhat[i], z[j]]).T, color=f"C{i}", lw=0.5 + 5 * beta, alpha=0.7)
    d = z[j] - pred.zhat[i]
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)  # label beside the line, not on it
    ax.annotate(f"{beta:.2f}", pred.zhat[i] + 0.5 * d, xytext=9 * normal,
                textcoords="offset points", color=f"C{i}", fontsize="small", ha="center",
                va="center")
ax.plot(*z.T, "ko", ms=4, label="plots")
for j, zj in enumerate(z):
    ax.annotate(f"plot {j}", zj, xytext=(4, -10), textcoords="offset points",
                fontsize="x-small")
ax.set_xlabel("x (m)")
ax.set_ylabel("y (m)")
ax.set_aspect("equal")
ax.legend(fontsize="small", loc="lower left")
ax.set_title("Gates (P_G = 0.99) and JPDA probabilities")
fig.tight_layout()
plt.show()
