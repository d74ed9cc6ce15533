"""Oracle: trackkit's KF, EKF and RTS smoother against FilterPy, step by step.

FilterPy is given only hand-written inputs: F, its own ``Q_continuous_white_noise`` (ordered
[x, y, vx, vy] with ``order_by_dim=False``), and hand-written h(x), Jacobians and angle
residuals. Its ``KalmanFilter`` and ``ExtendedKalmanFilter`` use the Joseph form, like
trackkit. ``KalmanFilter.rts_smoother(Xs, Ps, Fs, Qs)`` takes ``Fs[k + 1]``, ``Qs[k + 1]``
as the transition from step k to k + 1 (its ``batch_filter`` convention), so the step lengths
vary in every problem to catch an off-by-one in trackkit's ``smooth(..., dt)``.

Every step's filtered and smoothed mean and covariance must agree to 1e-9 relative (with an
absolute floor of ``FLOOR`` standard deviations, see ``helpers.FLOOR``).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter

import trackkit as tk

from .helpers import (
    assert_gaussian_close,
    cv_F,
    nautical_to_math,
    problem,
    stack_problems,
    wrap,
)

# --------------------------------------------------------------------------------------------
# Hand-written models for FilterPy (independent of trackkit's sensor code)


def _fp_Q(dt: float, q: float, order: int = 2) -> np.ndarray:
    return Q_continuous_white_noise(order, dt, q, block_size=2, order_by_dim=False)


def _ca_F(dt: float) -> np.ndarray:
    """Constant acceleration, ordering [x, y, vx, vy, ax, ay]."""
    e = np.eye(2)
    z = np.zeros((2, 2))
    return np.block([[e, dt * e, dt**2 / 2 * e], [z, e, dt * e], [z, z, e]])


def _bearing(d: np.ndarray, convention: str) -> float:
    return np.arctan2(d[0], d[1]) if convention == "nautical" else np.arctan2(d[1], d[0])


def _bearing_grad(d: np.ndarray, convention: str) -> np.ndarray:
    """d bearing / d (x, y): nautical atan2(dx, dy) -> (dy, -dx)/r^2; math is its negative."""
    r2 = d @ d
    g = np.array([d[1] / r2, -d[0] / r2])
    return g if convention == "nautical" else -g


def _hx(kind: str, convention: str):
    def hx(x, origin):
        d = x[:2] - origin
        if kind == "range_bearing":
            return np.array([np.hypot(d[0], d[1]), _bearing(d, convention)])
        return np.array([_bearing(d, convention)])

    return hx


def _HJ(kind: str, convention: str):
    def HJ(x, origin):
        d = x[:2] - origin
        H = np.zeros((2 if kind == "range_bearing" else 1, 4))
        H[-1, :2] = _bearing_grad(d, convention)
        if kind == "range_bearing":
            H[0, :2] = d / np.hypot(d[0], d[1])
        return H

    return HJ


def _residual(z, zhat):
    """z - zhat with the bearing (always the last component here) wrapped."""
    y = np.asarray(z, dtype=float) - zhat
    y[-1] = wrap(y[-1])
    return y


def _measurements(p, convention: str) -> np.ndarray:
    """The problem's measurements in the requested bearing convention (last component)."""
    z = np.array(p.z, dtype=float)
    if p.kind != "linear" and convention == "math":
        z[:, -1] = nautical_to_math(z[:, -1])
    return z


def _tk_sensors(p, convention: str, origins=None):
    origins = p.observer if origins is None else origins
    if p.kind == "linear":
        return tk.models.Position(dim=2, sigma=p.sigma)
    if p.kind == "range_bearing":
        return [tk.models.RangeBearing(origin=o, sigma_range=p.sigma[0],
                                       sigma_bearing=p.sigma[1], convention=convention)
                for o in origins]
    return [tk.models.Bearing(origin=o, sigma=p.sigma[0], convention=convention)
            for o in origins]


# --------------------------------------------------------------------------------------------
# FilterPy runs (cached: each is shared by the filter and the smoother tests)


def _fp_smooth(Xs, Ps, Fs, Qs):
    xs, Pss, _, _ = KalmanFilter(dim_x=Xs.shape[1], dim_z=1).rts_smoother(Xs, Ps, Fs, Qs)
    return xs, Pss


@cache
def fp_run(kind: str, seed: int, observer: str | None, convention: str = "nautical"):
    """FilterPy KF (linear) or EKF on one problem: (filtered means, covs, smoothed means,
    covs), each with a leading time axis."""
    p = problem(kind, seed, observer)
    z = _measurements(p, convention)
    R = np.diag(np.square(p.sigma))
    if kind == "linear":
        f = KalmanFilter(dim_x=4, dim_z=2)
        f.H = np.eye(2, 4)
    else:
        f = ExtendedKalmanFilter(dim_x=4, dim_z=p.dim_z)
        hx, HJ = _hx(kind, convention), _HJ(kind, convention)
    f.R = R
    f.x, f.P = np.array(p.x0), np.array(p.P0)
    Fs = np.array([cv_F(dt) for dt in p.dts])
    Qs = np.array([_fp_Q(dt, p.q) for dt in p.dts])
    Xs, Ps = [], []
    for k in range(p.T):
        f.F, f.Q = Fs[k], Qs[k]
        f.predict()
        if kind == "linear":
            f.update(z[k])
        else:
            o = p.observer[k]
            f.update(z[k], HJ, hx, args=(o,), hx_args=(o,), residual=_residual)
        Xs.append(np.array(f.x, dtype=float))
        Ps.append(np.array(f.P, dtype=float))
    Xs, Ps = np.array(Xs), np.array(Ps)
    return (Xs, Ps) + _fp_smooth(Xs, Ps, Fs, Qs)


def tk_run(p, f, convention: str = "nautical"):
    """trackkit filter + RTS smoother on one problem (or a stacked batch via ``p`` dict)."""
    motion = tk.models.ConstantVelocity(dim=2, q=p.q)
    prior = tk.Gaussian(np.array(p.x0), np.array(p.P0))
    _, filt = tk.filters.run_filter(f, prior, motion, _tk_sensors(p, convention),
                                    _measurements(p, convention), np.array(p.dts),
                                    history=True)
    return filt, tk.filters.smooth(f, filt, motion, np.array(p.dts[1:]))


# --------------------------------------------------------------------------------------------
# Linear Kalman filter


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kf_and_rts_match_filterpy_on_linear_problem(seed):
    """KF with a 2-D position sensor (sigma 4 m and 6 m per axis), CV q = 0.3, dt in
    [0.6, 1.4] s, correlated prior: filtered and RTS-smoothed sequences."""
    p = problem("linear", seed)
    fx, fP, sx, sP = fp_run("linear", seed, None)
    filt, sm = tk_run(p, tk.filters.KF())
    assert_gaussian_close(filt.mean, filt.cov, fx, fP, "KF filtered vs FilterPy")
    assert_gaussian_close(sm.mean, sm.cov, sx, sP, "KF RTS smoothed vs FilterPy")


def test_kf_and_rts_match_filterpy_constant_acceleration():
    """A 6-state model: trackkit's ConstantAcceleration against FilterPy with its own
    third-order Q_continuous_white_noise, ordered [x, y, vx, vy, ax, ay]."""
    rng = np.random.default_rng(11)
    T, q = 120, 0.05
    dts = rng.uniform(0.5, 1.5, T)
    sd = np.array([20.0, 25.0, 3.0, 2.0, 0.3, 0.4])
    C = np.eye(6) + 0.1 * np.triu(rng.uniform(-1, 1, (6, 6)), 1)
    C = C + np.triu(C, 1).T
    P0 = sd[:, None] * C * sd[None, :]
    x = np.array([100.0, -50.0, 5.0, -3.0, 0.2, -0.1])
    x0 = x + np.linalg.cholesky(P0) @ rng.standard_normal(6)
    zs = []
    for dt in dts:
        x = _ca_F(dt) @ x + np.linalg.cholesky(_fp_Q(dt, q, 3)) @ rng.standard_normal(6)
        zs.append(x[:2] + np.array([5.0, 3.0]) * rng.standard_normal(2))
    zs = np.array(zs)

    kf = KalmanFilter(dim_x=6, dim_z=2)
    kf.x, kf.P, kf.H, kf.R = x0.copy(), P0.copy(), np.eye(2, 6), np.diag([25.0, 9.0])
    Fs = np.array([_ca_F(dt) for dt in dts])
    Qs = np.array([_fp_Q(dt, q, 3) for dt in dts])
    Xs, Ps = [], []
    for k in range(T):
        kf.F, kf.Q = Fs[k], Qs[k]
        kf.predict()
        kf.update(zs[k])
        Xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
    Xs, Ps = np.array(Xs), np.array(Ps)
    sx, sP = _fp_smooth(Xs, Ps, Fs, Qs)

    f = tk.filters.KF()
    motion = tk.models.ConstantAcceleration(dim=2, q=q)
    _, filt = tk.filters.run_filter(f, tk.Gaussian(x0, P0), motion,
                                    tk.models.Position(dim=2, sigma=(5.0, 3.0)), zs, dts,
                                    history=True)
    sm = tk.filters.smooth(f, filt, motion, dts[1:])
    assert_gaussian_close(filt.mean, filt.cov, Xs, Ps, "KF (CA) filtered vs FilterPy")
    assert_gaussian_close(sm.mean, sm.cov, sx, sP, "KF (CA) RTS smoothed vs FilterPy")


# --------------------------------------------------------------------------------------------
# Extended Kalman filter, moving observers

EKF_CASES = [
    ("range_bearing", 0, "circle"),
    ("range_bearing", 1, "circle"),
    ("bearings_only", 0, "zigzag"),
    ("bearings_only", 1, "zigzag"),
    ("bearings_only", 2, "circle"),
]


@pytest.mark.parametrize("convention", ["nautical", "math"])
@pytest.mark.parametrize(("kind", "seed", "observer"), EKF_CASES)
def test_ekf_and_rts_match_filterpy_moving_observer(kind, seed, observer, convention):
    """EKF with a new sensor object per step (moving observer) against FilterPy's
    ExtendedKalmanFilter with hand-written h, Jacobian and wrapped residual; then RTS.

    ``circle``: the observer circles the target area, so the bearing sweeps through every
    direction and crosses the +-pi cut of both conventions; ``zigzag``: classic TMA legs.
    """
    p = problem(kind, seed, observer)
    fx, fP, sx, sP = fp_run(kind, seed, observer, convention)
    filt, sm = tk_run(p, tk.filters.EKF(), convention)
    what = f"EKF {kind}/{observer}/{convention}"
    assert_gaussian_close(filt.mean, filt.cov, fx, fP, f"{what} filtered vs FilterPy")
    assert_gaussian_close(sm.mean, sm.cov, sx, sP, f"{what} RTS smoothed vs FilterPy")


def test_bearing_sweep_crosses_both_cuts():
    """The circling-observer problems really exercise angle wrapping in both conventions."""
    for kind, seed, observer in EKF_CASES:
        if observer != "circle":
            continue
        b = problem(kind, seed, observer).z[:, -1]
        for conv_b in (b, nautical_to_math(b)):
            jumps = np.abs(np.diff(conv_b)) > np.pi
            assert jumps.any(), (kind, seed)


# --------------------------------------------------------------------------------------------
# Batched path: one trackkit call on B problems, each row against its own FilterPy run


class _Batch:
    """Stacked problems with the attributes ``tk_run`` reads; dt differs per row and step."""

    def __init__(self, kind, seeds, observers):
        self.problems = [problem(kind, s, o) for s, o in zip(seeds, observers, strict=True)]
        b = stack_problems(self.problems)
        p0 = self.problems[0]
        self.kind, self.q, self.sigma, self.dim_z = kind, p0.q, p0.sigma, p0.dim_z
        self.x0, self.P0, self.dts, self.observer, self.z = (
            b["x0"], b["P0"], b["dts"], b["observer"], b["z"])


BATCH_CASES = {
    "linear": ([0, 1, 2, 3, 4], [None] * 5),
    "range_bearing": ([0, 1, 2, 3, 4], ["circle"] * 5),
    "bearings_only": ([0, 1, 2, 3, 4], ["zigzag", "zigzag", "circle", "zigzag", "circle"]),
}


@pytest.mark.parametrize("kind", list(BATCH_CASES))
def test_batched_filter_and_rts_match_filterpy_per_row(kind):
    """Five different problems (own prior, own step lengths, own observer track) in one
    batched trackkit run: KF for the linear problems, EKF otherwise; row b of the filtered
    and smoothed sequences against FilterPy run on problem b alone."""
    seeds, observers = BATCH_CASES[kind]
    batch = _Batch(kind, seeds, observers)
    f = tk.filters.KF() if kind == "linear" else tk.filters.EKF()
    filt, sm = tk_run(batch, f)
    B = len(seeds)
    assert filt.mean.shape == (batch.z.shape[0], B, 4)
    assert sm.cov.shape == (batch.z.shape[0], B, 4, 4)
    for b, (seed, observer) in enumerate(zip(seeds, observers, strict=True)):
        fx, fP, sx, sP = fp_run(kind, seed, observer)
        what = f"batched {f.name} {kind} row {b}"
        assert_gaussian_close(filt.mean[:, b], filt.cov[:, b], fx, fP, f"{what} filtered")
        assert_gaussian_close(sm.mean[:, b], sm.cov[:, b], sx, sP, f"{what} smoothed")
