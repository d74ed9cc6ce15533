"""
Alpha-beta gains: the design rules and the tracking index
=========================================================

An alpha-beta tracker is a constant-gain filter: a pair ``(alpha, beta)`` fixes how much of
each residual goes into position and velocity. The missing-measurements thesis (sections 2-1
to 2-4) gives the classical ways to choose the pair, which
:mod:`trackkit.filters.alphabeta` implements: Benedict and Bordner's (1962) curve, the
critically damped (fading-memory) pairs, Kohn's values and Simpson's growing-memory gains,
with the stability region and the variance-reduction ratios. This example draws them in the
gain plane, beside the gains the steady-state Kalman filter reaches for a given *tracking
index* ``Lambda = sqrt(q T^3) / sigma`` (process noise against measurement noise), computed
with :class:`trackkit.filters.KF` over a batch of indices.

.. budget: 8 s
"""

# %%
# The design rules
# ----------------
# Every designer takes arrays: one call gives a whole curve.
import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.filters import alphabeta as ab

alpha = np.linspace(0.01, 4 - 2 * np.sqrt(2), 200)  # the curve is stable below 4 - 2 sqrt(2)
bb = ab.benedict_bordner(alpha)                  # beta = alpha^2 / (2 - alpha)
xi = np.linspace(0.0, 0.99, 200)
fm_alpha, fm_beta = ab.fading_memory(xi)         # alpha = 1 - xi^2, beta = (1 - xi)^2
kohn = ab.kohn()
k = np.arange(2, 11)
simpson_alpha, simpson_beta = ab.simpson(k)      # the least-squares line through k plots

vr = ab.vrr(*kohn)
print(f"Kohn's pair {kohn}: stable {ab.is_stable(*kohn)}, root radius "
      f"{np.abs(ab.roots(*kohn)).max():.4f}, VRR position {vr.x:.4f}, velocity "
      f"{vr.v:.4f} / T^2")
print(f"Benedict-Bordner beta at alpha = 0.5: {ab.benedict_bordner(0.5):.4f}")

# %%
# Gains from the tracking index
# -----------------------------
# The Kalman filter of a constant-velocity target (white-noise acceleration of density q)
# with position plots every T seconds settles to constant gains; with q = T = 1 only the
# plots' noise varies, one row of the batch per tracking index (a batched R through
# :func:`trackkit.models.with_noise`). The steady-state gain is ``K = P- H^T / S``:
# ``alpha = K_x`` and ``beta = T K_v``.
index = np.logspace(-2, 1, 40)
T = 1.0
motion = tk.models.ConstantVelocity(dim=1, q=1.0)
sensor = tk.models.with_noise(tk.models.Position(dim=1), (1.0 / index**2)[:, None, None])
kf = tk.filters.KF()
b = tk.Gaussian(np.zeros((index.size, 2)), np.broadcast_to(1e6 * np.eye(2), (index.size, 2, 2)))
for _ in range(300):
    pred = kf.predict(b, motion, T)
    b, innov = kf.update(pred, np.zeros((index.size, 1)), sensor)
S = innov.cov[:, 0, 0]
kf_alpha, kf_beta = pred.cov[:, 0, 0] / S, T * pred.cov[:, 1, 0] / S
for lam in (0.1, 1.0):
    i = np.argmin(np.abs(index - lam))
    print(f"tracking index {index[i]:.2f}: alpha {kf_alpha[i]:.3f}, beta {kf_beta[i]:.3f} "
          f"(Benedict-Bordner beta at that alpha {ab.benedict_bordner(kf_alpha[i]):.3f})")
print(f"all steady-state pairs stable: {bool(ab.is_stable(kf_alpha, kf_beta).all())}")

# %%
# The gain plane
# --------------
# For small indices the Kalman filter's pairs lie on the Benedict-Bordner curve, and Kohn's
# pair among them; as the process noise grows they rise above it, alpha approaching 1 (a
# filter that believes each plot), still inside the stability triangle
# ``0 < alpha < 2, 0 < beta < 4 - 2 alpha``.
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4.2))
ga, gb = np.meshgrid(np.linspace(0, 2, 300), np.linspace(0, 2.2, 300))
ax0.contourf(ga, gb, ab.in_stability_region(ga, gb), levels=[0.5, 1.5], colors=["0.92"])
ax0.plot(alpha, bb, label="Benedict-Bordner")
ax0.plot(fm_alpha, fm_beta, label="fading memory (xi from 1 to 0)")
ax0.plot(kf_alpha, kf_beta, "k.", ms=4, label="steady-state KF")
ax0.plot(simpson_alpha, simpson_beta, "s", ms=4, mfc="none", label="Simpson, k = 2..10")
ax0.plot(*kohn, "r*", ms=10, label="Kohn")
ax0.set_xlabel("alpha")
ax0.set_ylabel("beta")
ax0.set_xlim(0, 2)
ax0.set_ylim(0, 2.2)
ax0.legend(fontsize="small", title="grey: stable", title_fontsize="small")

ax1.semilogx(index, kf_alpha, "C0", label="alpha")
ax1.semilogx(index, kf_beta, "C1", label="beta")
ax1.axhline(kohn[0], color="C0", ls=":", lw=1)
ax1.axhline(kohn[1], color="C1", ls=":", lw=1, label="Kohn's pair")
ax1.set_xlabel(r"tracking index $\sqrt{q T^3} / \sigma$")
ax1.set_ylabel("steady-state gain")
ax1.legend(fontsize="small")
fig.tight_layout()
plt.show()
