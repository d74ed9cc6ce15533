"""
The core from Python
====================

What ``trackkit run`` does underneath, by hand: a batched extended Kalman filter over 1 000
Monte Carlo runs of a radar track, the Rauch-Tung-Striebel smoother on the same runs, and a
motion model of your own that the filters take as they take the bundled ones. The setting,
an extended Kalman filter on a radar's range and bearing, is that of the missing-measurements
thesis; the equations are the textbook ones of Bar-Shalom, Li and Kirubarajan (2001) and the
smoother is that of Rauch, Tung and Striebel (1965). You will learn the shapes everything
takes (leading axes are runs), how to judge a filter by its RMSE and its NEES, and what a
motion model must provide.

.. budget: 10 s
"""

# %%
# One radar, one target, 1 000 runs
# ---------------------------------
#
# The state is ``[x, y, vx, vy]`` (SI units, positions first). The target follows
# :class:`trackkit.models.ConstantVelocity` with a small white-noise acceleration, and a radar
# at the origin measures range and bearing (:class:`trackkit.models.RangeBearing`, bearing
# clockwise from north). Every array carries the runs on its leading axis, so the truths of
# all 1 000 runs step forward together: the only Python loop is over time.

import matplotlib.pyplot as plt
import numpy as np

import trackkit as tk
from trackkit.eval import chi2_bounds

rng = np.random.default_rng(2026)
runs, steps, dt = 1000, 120, 1.0

motion = tk.models.ConstantVelocity(dim=2, q=0.05)            # q in m^2/s^3
radar = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=20.0,
                               sigma_bearing=np.deg2rad(0.5))

m0 = np.array([2000.0, 6000.0, 15.0, -5.0])                   # the prior's mean
P0 = np.diag([200.0, 200.0, 5.0, 5.0]) ** 2                   # and covariance


def simulate(motion, x0, sensor):
    """Truths (steps + 1, runs, n) from x0 and the sensor's measurements (steps, runs, m)."""
    xs = [x0]
    for _ in range(steps):
        Lq = np.linalg.cholesky(np.broadcast_to(motion.noise(xs[-1], dt), x0.shape + (4,)))
        w = np.einsum("...ij,...j->...i", Lq, rng.standard_normal(x0.shape))
        xs.append(motion.f(xs[-1], dt) + w)
    truth = np.stack(xs)
    Lr = np.linalg.cholesky(sensor.noise)
    z = sensor.h(truth[1:]) + rng.standard_normal((steps, runs, sensor.dim_z)) @ Lr.T
    z[..., 1] = np.angle(np.exp(1j * z[..., 1]))                # bearings in (-pi, pi]
    return truth, z


x0 = m0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T   # truth ~ N(m0, P0)
truth, z = simulate(motion, x0, radar)
print("truth", truth.shape, " measurements", z.shape)

# %%
# One step by hand, then the whole track
# --------------------------------------
#
# A belief is a :class:`trackkit.belief.Gaussian` whose mean is ``(runs, n)`` and covariance
# ``(runs, n, n)`` (or one shared ``(n, n)``). :class:`trackkit.filters.EKF` predicts it with
# the motion model and updates it with a measurement ``(runs, m)``; the update also returns
# the innovation and its covariance, the ingredients of the NIS.

ekf = tk.filters.EKF()
prior = tk.Gaussian(np.tile(m0, (runs, 1)), np.tile(P0, (runs, 1, 1)))
b = ekf.predict(prior, motion, dt)
b, innov = ekf.update(b, z[0], radar)
print("belief", b.mean.shape, b.cov.shape, " innovation", innov.nu.shape, innov.cov.shape)

# %%
# :func:`trackkit.filters.run_filter` streams the same predict-update pair over the whole
# measurement sequence; with ``history=True`` it stacks the filtered means and covariances
# along a new leading time axis, ``(steps, runs, n)``, which is what the smoother reads.
# :func:`trackkit.filters.smooth` runs the RTS recursion backwards over that history.

_, filtered = tk.filters.run_filter(ekf, prior, motion, radar, z, dt, history=True)
smoothed = tk.filters.smooth(ekf, filtered, motion, dt)
print("filtered", filtered.mean.shape, " smoothed", smoothed.mean.shape)

# %%
# RMSE and NEES, over the runs
# ----------------------------
#
# The position RMSE at step ``k`` pools the runs, :math:`\sqrt{\frac{1}{R}\sum_r
# \lVert \hat p_{r,k} - p_{r,k}\rVert^2}`. The NEES, :math:`\epsilon = e^\top P^{-1} e` with
# :math:`e` the state error, averaged over :math:`R` runs, is :math:`\chi^2` with :math:`Rn`
# degrees of freedom divided by :math:`R` when the filter's covariance is honest: its mean is
# :math:`n = 4`, and :func:`trackkit.eval.chi2_bounds` gives the two-sided 95% band. A NEES
# above the band means an overconfident filter, below it a pessimistic one.


def rmse_and_nees(est, truth):
    e = est.mean - truth[1:]
    rmse = np.sqrt(np.mean(np.sum(e[..., :2] ** 2, -1), axis=1))
    nees = np.mean(np.einsum("...i,...i->...", e, np.linalg.solve(est.cov, e[..., None])[..., 0]),
                   axis=1)
    return rmse, nees


lo, hi = chi2_bounds(runs, runs * 4)
cv = {name: rmse_and_nees(est, truth) for name, est in
      (("filtered", filtered), ("smoothed", smoothed))}
for name, (rmse, nees) in cv.items():
    inside = np.mean((nees >= lo) & (nees <= hi))
    print(f"{name:9s} position RMSE over the last 60 s {np.sqrt(np.mean(rmse[-60:] ** 2)):6.1f} m,"
          f" mean NEES {nees.mean():.2f} (band {lo:.2f}-{hi:.2f}, inside at {inside:.0%} of steps)")

# %%
# Your own motion model
# ---------------------
#
# A filter asks a motion model for four things only, the
# :class:`trackkit.models.protocols.MotionModel` protocol: ``dim_x``, the transition
# ``f(x, dt)``, its Jacobian ``jacobian(x, dt)`` and the process noise ``noise(x, dt)``, all
# batched over leading axes. No base class is needed. Here is a target that coasts to a stop,
# its velocity damped by quadratic drag, :math:`\dot v = -c\,\lVert v\rVert\,v` (one Euler
# step per ``dt``), with the white-noise acceleration of the constant-velocity model. Its
# Jacobian is :math:`\partial v'/\partial v = I - c\,\Delta t\,(\lVert v\rVert I +
# v v^\top/\lVert v\rVert)`.


class QuadraticDrag:
    """Velocity damped by quadratic drag ``c`` (1/m); white acceleration noise ``q``."""

    def __init__(self, c: float, q: float) -> None:
        self.c, self.q = c, q

    @property
    def dim_x(self) -> int:
        return 4

    def f(self, x, dt):
        p, v = x[..., :2], x[..., 2:]
        speed = np.linalg.norm(v, axis=-1, keepdims=True)
        return np.concatenate([p + v * dt, v - self.c * dt * speed * v], axis=-1)

    def jacobian(self, x, dt):
        v = x[..., 2:]
        speed = np.maximum(np.linalg.norm(v, axis=-1), 1e-12)[..., None, None]
        outer = v[..., :, None] * v[..., None, :]
        F = np.broadcast_to(np.eye(4), x.shape[:-1] + (4, 4)).copy()
        F[..., :2, 2:] = dt * np.eye(2)
        F[..., 2:, 2:] -= self.c * dt * (speed * np.eye(2) + outer / speed)
        return F

    def noise(self, x, dt):
        I2 = np.eye(2)
        return self.q * np.block([[dt**3 / 3 * I2, dt**2 / 2 * I2], [dt**2 / 2 * I2, dt * I2]])


drag = QuadraticDrag(c=2e-3, q=0.05)
print("satisfies MotionModel:", isinstance(drag, tk.models.protocols.MotionModel))

# %%
# An analytic Jacobian is worth checking before a filter depends on it: central differences,
# batched over a few hundred random states, should agree to about the square of the step.

xs = np.column_stack([rng.uniform(-5e3, 5e3, (300, 2)), rng.uniform(-30.0, 30.0, (300, 2))])
h = 1e-4 * np.maximum(np.abs(xs), 1.0)                       # a step per component
E = np.eye(4)
numeric = np.stack([(drag.f(xs + h[:, [j]] * E[j], dt) - drag.f(xs - h[:, [j]] * E[j], dt))
                    / (2 * h[:, [j]]) for j in range(4)], axis=-1)
gap = np.max(np.abs(drag.jacobian(xs, dt) - numeric))
print(f"largest |analytic - finite difference| = {gap:.1e}")

# %%
# The EKF and the smoother take the new model unchanged. Truths from the drag model start at
# the same prior; the target now slows down to a few metres per second.

x0 = m0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
truth_d, z_d = simulate(drag, x0, radar)
_, filtered_d = tk.filters.run_filter(ekf, prior, drag, radar, z_d, dt, history=True)
smoothed_d = tk.filters.smooth(ekf, filtered_d, drag, dt)
dr = {name: rmse_and_nees(est, truth_d) for name, est in
      (("filtered", filtered_d), ("smoothed", smoothed_d))}
speed = np.linalg.norm(truth_d[:, :, 2:], axis=-1).mean(1)
print(f"mean speed {speed[0]:.1f} m/s at the start, {speed[-1]:.1f} m/s at {steps * dt:g} s")
for name, (_, nees) in dr.items():
    print(f"{name:9s} mean NEES {nees.mean():.2f} (band {lo:.2f}-{hi:.2f})")

# %%
# Filtered against smoothed
# -------------------------
#
# The smoother uses every measurement, past and future, so its RMSE lies below the filter's
# everywhere except at the last step, where the two coincide. Both NEES curves wander about
# :math:`n = 4`, inside the band at most steps, as they should when the models are right (the
# 95% band leaves about one step in twenty outside). Left: the constant-velocity target;
# right: the drag model.

t = dt * np.arange(1, steps + 1)
fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), sharex=True, sharey="row")
for col, (title, res) in enumerate((("constant velocity", cv), ("quadratic drag (own model)", dr))):
    for name, (rmse, nees) in res.items():
        axes[0, col].plot(t, rmse, label=name)
        axes[1, col].plot(t, nees, label=name)
    axes[1, col].axhspan(lo, hi, color="0.85", label="95% band")
    axes[1, col].axhline(4, color="k", lw=0.8, ls=":")
    axes[0, col].set_title(f"{title}, {runs} runs")
    axes[1, col].set_xlabel("time [s]")
axes[0, 0].set_ylabel("position RMSE [m]")
axes[1, 0].set_ylabel("average NEES [-]")
handles, labels = axes[1, 0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncols=3)
fig.tight_layout(rect=(0, 0.05, 1, 1))
plt.show()
