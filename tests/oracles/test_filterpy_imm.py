"""Oracle: trackkit's IMM against FilterPy's ``IMMEstimator``, step by step.

FilterPy's IMM (``filterpy.kalman.IMM``) is Bar-Shalom's cycle with equal state sizes:
``predict()`` mixes with ``omega[i, j] = M[i, j] mu_i / cbar_j`` (``cbar = mu M``) and runs
each filter's predict; ``update(z)`` runs each filter's update, sets
``mu = cbar * likelihood`` normalised, recomputes ``cbar`` and ``omega`` for the next step
and combines the estimate with the new mu. Its ``x_prior``/``P_prior`` (the combination after
``predict``) uses the *previous posterior* mu, not c_j = cbar as Bar-Shalom's predicted
estimate (and our ``estimate`` of a predicted belief) does; the test checks that quantity with
our ``combine`` kernel and those weights, and checks our predicted mu against ``cbar``.

FilterPy's filters are ``KalmanFilter`` objects (Joseph form, like ours) given hand-written
F and Q for each step (the steps vary in length), so nothing of trackkit's models reaches
the oracle. Several problems run as one batch on our side, each against its own FilterPy
IMM, through both of our paths (the fast one for sets of KFs and the general one). Means
and covariances (per model and combined) must agree to 1e-9 relative, with the
absolute floor of ``helpers.FLOOR`` standard deviations; mode probabilities to 1e-9 relative
(absolute 1e-15).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import IMMEstimator, KalmanFilter

import trackkit as tk
from trackkit.filters.imm import IMM, combine

from .helpers import assert_gaussian_close

STEPS = 60


class TextbookKF(tk.filters.KF):
    """The KF under another type, so that the IMM takes its general path (each model through
    its filter object) rather than its fast path for sets of KFs: both are checked."""


def _F(dt: float, order: int) -> np.ndarray:
    """Nearly-constant velocity (order 2) or acceleration (order 3), [x, y, vx, vy(, ax, ay)]."""
    e, z = np.eye(2), np.zeros((2, 2))
    if order == 2:
        return np.block([[e, dt * e], [z, e]])
    return np.block([[e, dt * e, dt**2 / 2 * e], [z, e, dt * e], [z, z, e]])


def _Q(dt: float, q: float, order: int) -> np.ndarray:
    return Q_continuous_white_noise(order, dt, q, block_size=2, order_by_dim=False)


def _truth_and_z(seed: int, sigma: float):
    """A target that goes straight, accelerates, turns and goes straight again (hand-written
    kinematics), measured in position with noise sigma; variable steps."""
    rng = np.random.default_rng(seed)
    dts = rng.uniform(0.5, 1.5, STEPS)
    x = np.array([rng.normal(0, 100), rng.normal(0, 100), 10.0, -5.0])
    z = np.empty((STEPS, 2))
    for k, dt in enumerate(dts):
        a = np.zeros(2)
        if 15 <= k < 25:
            a = np.array([3.0, 1.0])
        elif 35 <= k < 45:
            a = np.array([-x[3], x[2]]) * 0.2  # a turn
        x = np.concatenate([x[:2] + dt * x[2:] + dt**2 / 2 * a, x[2:] + dt * a])
        z[k] = x[:2] + sigma * rng.standard_normal(2)
    return dts, z


CASES = {
    # name: (order, q per model, transition, mu0, sigma)
    "two CV": (2, (0.05, 20.0), [[0.95, 0.05], [0.2, 0.8]], (0.6, 0.4), 3.0),
    "two CA (6 states)": (3, (0.01, 2.0), [[0.97, 0.03], [0.1, 0.9]], (0.5, 0.5), 5.0),
    "three CV": (2, (0.01, 1.0, 40.0), [[0.9, 0.05, 0.05], [0.1, 0.8, 0.1], [0.05, 0.15, 0.8]],
                 (0.7, 0.2, 0.1), 2.0),
}


@pytest.mark.parametrize("path", ["fast", "general"])
@pytest.mark.parametrize("case", list(CASES))
def test_imm_equals_filterpy_step_by_step(case, path):
    order, qs, M, mu0, sigma = CASES[case]
    M = np.asarray(M)
    r, n = len(qs), 2 * order
    seeds = [11, 12, 13]
    problems = [_truth_and_z(s, sigma) for s in seeds]
    B = len(seeds)
    rng = np.random.default_rng(99)
    x0 = np.zeros((B, n))
    x0[:, :2] = [p[1][0] for p in problems]  # start at the first plot...
    x0[:, :2] += rng.normal(0, sigma, (B, 2))
    P0 = np.diag([sigma**2 * 4, sigma**2 * 4] + [100.0, 100.0] + [10.0, 10.0] * (order == 3))

    # FilterPy: one IMMEstimator per problem
    imms = []
    for b in range(B):
        kfs = []
        for _ in range(r):
            kf = KalmanFilter(dim_x=n, dim_z=2)
            kf.x = x0[b].reshape(n, 1).copy()
            kf.P = P0.copy()
            kf.H = np.eye(2, n)
            kf.R = sigma**2 * np.eye(2)
            kfs.append(kf)
        imms.append(IMMEstimator(kfs, np.array(mu0), M))

    # trackkit: one IMM over the batch of problems
    Model = tk.models.ConstantVelocity if order == 2 else tk.models.ConstantAcceleration
    inner = tk.filters.KF() if path == "fast" else TextbookKF()
    f = IMM([Model(dim=2, q=q) for q in qs], inner, M, mu0=mu0)
    sensor = tk.models.Position(dim=2, sigma=sigma)
    b = f.init(tk.Gaussian(x0, np.tile(P0, (B, 1, 1))))

    rec = {k: [] for k in ("mu_p", "mu_p_ref", "mu", "mu_ref", "xj_p", "Pj_p", "xj_p_ref",
                           "Pj_p_ref", "xj", "Pj", "xj_ref", "Pj_ref", "x", "P", "x_ref",
                           "P_ref", "xpri", "Ppri", "xpri_ref", "Ppri_ref")}
    for k in range(STEPS):
        dts = np.array([p[0][k] for p in problems])
        z = np.array([p[1][k] for p in problems])
        mu_before = b.mu
        b = f.predict(b, None, dts)
        for i, imm in enumerate(imms):
            for kf, q in zip(imm.filters, qs, strict=True):
                kf.F, kf.Q = _F(dts[i], order), _Q(dts[i], q, order)
            cbar = imm.cbar.copy()  # the c_j this predict mixes with
            imm.predict()
            rec["mu_p_ref"].append(cbar)
            rec["xj_p_ref"].append(np.stack([kf.x[:, 0] for kf in imm.filters]))
            rec["Pj_p_ref"].append(np.stack([kf.P for kf in imm.filters]))
            rec["xpri_ref"].append(imm.x_prior[:, 0])
            rec["Ppri_ref"].append(imm.P_prior)
        rec["mu_p"].extend(b.mu)
        rec["xj_p"].extend(b.mean)
        rec["Pj_p"].extend(b.cov)
        xp, Pp = combine(mu_before, b.mean, b.cov)  # FilterPy's x_prior: the previous mu
        rec["xpri"].extend(xp)
        rec["Ppri"].extend(Pp)

        b, _ = f.update(b, z, sensor)
        g = f.estimate(b)
        for i, imm in enumerate(imms):
            imm.update(z[i].reshape(2, 1))
            rec["mu_ref"].append(imm.mu.copy())
            rec["xj_ref"].append(np.stack([kf.x[:, 0] for kf in imm.filters]))
            rec["Pj_ref"].append(np.stack([kf.P for kf in imm.filters]))
            rec["x_ref"].append(imm.x_post[:, 0])
            rec["P_ref"].append(imm.P_post)
        rec["mu"].extend(b.mu)
        rec["xj"].extend(b.mean)
        rec["Pj"].extend(b.cov)
        rec["x"].extend(g.mean)
        rec["P"].extend(g.cov)

    a = {k: np.array(v) for k, v in rec.items()}
    for which in ("mu_p", "mu"):
        np.testing.assert_allclose(a[which], a[which + "_ref"], rtol=1e-9, atol=1e-15,
                                   err_msg=f"{case}: mode probabilities ({which})")
    # the mode probabilities really move (the test would not see a frozen mu)
    assert np.ptp(a["mu"][:, 0]) > 0.3
    for j in range(r):
        assert_gaussian_close(a["xj_p"][:, j], a["Pj_p"][:, j], a["xj_p_ref"][:, j],
                              a["Pj_p_ref"][:, j], f"{case}: model {j} predicted")
        assert_gaussian_close(a["xj"][:, j], a["Pj"][:, j], a["xj_ref"][:, j],
                              a["Pj_ref"][:, j], f"{case}: model {j} updated")
    assert_gaussian_close(a["x"], a["P"], a["x_ref"], a["P_ref"], f"{case}: combined")
    assert_gaussian_close(a["xpri"], a["Ppri"], a["xpri_ref"], a["Ppri_ref"],
                          f"{case}: FilterPy's x_prior")
