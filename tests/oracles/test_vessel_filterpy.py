"""Oracle: the augmented-state identification EKF (``trackkit.identify.identify``) against
FilterPy's ``ExtendedKalmanFilter``, step by step.

FilterPy gets only what is written here, independently of ``trackkit.models.manoeuvring``: the
16-coefficient model of Zolfagharnasab and Seif (2025, eq. 2) in the prime system (L = 19.6 m, U0 =
18 kn, n0 = 2000 rpm), its forward-Euler step with the mean input (eq. 4) or m Euler sub-steps
with the input interpolated linearly between samples, the analytic Jacobians written out
here (chained over the sub-steps), Q = T diag(q_body, q_theta), H = [I3 0] and
R = diag(sigma^2). ``ExtendedKalmanFilter.predict`` propagates ``x = F x``; its
``predict_x`` is overridden with the nonlinear step (the usual FilterPy idiom), and its
update is the Joseph form, like trackkit's. At a trial join both re-initialise the body
states from the measurement (mean z, covariance R, no correlation with theta).

Both of trackkit's paths are compared: ``identify(filter="ekf")``, which runs the EKF
equations by blocks of ``F = [[A, B], [0, I]]`` and ``H = [I3 0]``, and
``identify(filter=trackkit.filters.EKF())``, the generic filter on the model. Every sample's
mean and covariance must agree to 1e-9 relative (with the absolute floor of
``helpers.FLOOR`` standard deviations).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

import trackkit as tk
from trackkit.identify import identify, initial_guess, programme

from .helpers import assert_gaussian_close

L, U0, N0 = 19.6, 18.0 * 1852.0 / 3600.0, 2000.0
SIGMA = np.array([0.05, 0.05, np.deg2rad(0.1)])
Q_BODY = np.array([3e-4, 3e-4, 3e-6])
Q_THETA = 1e-8  # a small random walk, so that the coefficients' Q is exercised too
K = 200  # samples: the acceleration run, the 20/20 zig-zag and part of the next zig-zag


def _f_and_jacobians(x, s, th):
    """SI ``f`` (3), ``df/dx`` (3 x 3) and ``df/dtheta`` (3 x 16) of eq. 2 in prime units:
    ``u' = u/U0``, ``v' = v/U0``, ``r' = r L/U0``, ``n' = n/n0``; ``f_SI = D f'`` with
    ``D = (U0^2/L, U0^2/L, U0^2/L^2)``."""
    u, v, r = x[0] / U0, x[1] / U0, x[2] * L / U0
    d, n = s[0], s[1] / N0
    a1, a2, a3, a4, a5, a6, a7, a8, a9, b1, b2, b3, b4, c1, c2, c3 = th
    D = np.array([U0**2 / L, U0**2 / L, U0**2 / L**2])
    f = np.array([
        a1 * u**2 + a2 * v**2 + a3 * r**2 + a4 * d**2 + a5 * v * r + a6 * v * d + a7 * r * d
        + a8 * u * n + a9 * n**2,
        b1 * v + b2 * r + b3 * d + b4 * u * r,
        c1 * v + c2 * r + c3 * d,
    ])
    Jp = np.array([
        [2 * a1 * u + a8 * n, 2 * a2 * v + a5 * r + a6 * d, 2 * a3 * r + a5 * v + a7 * d],
        [b4 * r, b1, b2 + b4 * u],
        [0.0, c1, c2],
    ])
    Gp = np.zeros((3, 16))
    Gp[0, :9] = [u * u, v * v, r * r, d * d, v * r, v * d, r * d, u * n, n * n]
    Gp[1, 9:13] = [v, r, d, u * r]
    Gp[2, 13:] = [v, r, d]
    dprime_dx = np.array([1 / U0, 1 / U0, L / U0])  # d(prime state)/d(SI state)
    return D * f, D[:, None] * Jp * dprime_dx[None, :], D[:, None] * Gp


def _substep_inputs(s0, s1, m):
    if m == 1:
        return [0.5 * (s0 + s1)]
    return [s0 + ((j + 0.5) / m) * (s1 - s0) for j in range(m)]


def _propagate(xa, s0, s1, T, m):
    """m Euler sub-steps of h = T/m and the chained 19 x 19 Jacobian."""
    h = T / m
    body, th = xa[:3].copy(), xa[3:]
    F = np.eye(19)
    for s in _substep_inputs(s0, s1, m):
        f, J, G = _f_and_jacobians(body, s, th)
        Fj = np.eye(19)
        Fj[:3, :3] += h * J
        Fj[:3, 3:] = h * G
        F = Fj @ F
        body = body + h * f
    return np.concatenate([body, th]), F


class _VesselEKF(ExtendedKalmanFilter):
    """FilterPy's EKF with the nonlinear prediction of the mean (``predict_x``)."""

    def predict_x(self, u=0):
        self.x = self.next_x


def _filterpy_run(z, s, starts, theta0, sd0, T, m):
    ekf = _VesselEKF(dim_x=19, dim_z=3)
    ekf.R = np.diag(SIGMA**2)
    ekf.Q = T * np.diag(np.concatenate([Q_BODY, np.full(16, Q_THETA)]))
    H = np.hstack([np.eye(3), np.zeros((3, 16))])
    means, covs = [], []
    for k in range(len(z)):
        if k == 0 or starts[k]:
            x = np.concatenate([z[k], theta0]) if k == 0 else ekf.x.copy()
            P = np.diag(np.concatenate([SIGMA**2, sd0**2])) if k == 0 else ekf.P.copy()
            x[:3] = z[k]
            P[:3, :] = 0.0
            P[:, :3] = 0.0
            P[:3, :3] = ekf.R
            ekf.x, ekf.P = x, P
        else:
            ekf.next_x, ekf.F = _propagate(ekf.x, s[k - 1], s[k], T, m)
            ekf.predict()
            ekf.update(z[k], lambda x: H, lambda x: H @ x)
        means.append(ekf.x.copy())
        covs.append(ekf.P.copy())
    return np.array(means), np.array(covs)


@pytest.fixture(scope="module")
def record():
    rec = programme([7], seed=2024)  # near-continuous truth, one run (run index 7)
    theta0 = initial_guess(rec.truth.theta, [7], seed=2024, spread=0.5)[0]
    return rec, theta0


@pytest.mark.parametrize("m", [1, 3])
@pytest.mark.parametrize("filter", ["ekf", "generic"])
def test_augmented_ekf_matches_filterpy(record, m, filter):
    # "ekf": identify's structured kernels; "generic": trackkit.filters.EKF on the model
    rec, theta0 = record
    z, s, starts = rec.z[0, :K], rec.s[0, :K], rec.starts[:K]
    assert starts[1:].sum() >= 2  # the comparison crosses trial joins
    sd0 = np.full(16, 0.5)
    f = "ekf" if filter == "ekf" else tk.filters.EKF()
    ours = identify(z, s, rec.dt, starts=starts, filter=f, theta0=theta0, theta_sd0=sd0,
                    sigma_z=SIGMA, q_body=Q_BODY, q_theta=Q_THETA, substeps=m, keep_cov=True)
    mean = np.concatenate([ours.body, ours.theta_history], -1)
    ref_mean, ref_cov = _filterpy_run(z, s, starts, theta0, sd0, rec.dt, m)
    assert_gaussian_close(mean, ours.cov_history, ref_mean, ref_cov,
                          f"augmented EKF ({filter}), {m} sub-step(s)")
    # the data moved the estimate: the comparison is not of two priors
    assert np.abs(ref_mean[-1, 3:] - theta0).max() > 0.05
