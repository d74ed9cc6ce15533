"""Oracle: trackkit's AlphaBeta / AlphaBetaGamma against FilterPy's g-h filters.

FilterPy's ``GHFilter(x, dx, dt, g, h)`` and ``GHKFilter(x, dx, ddx, dt, g, h, k)`` run, per
``update(z)``::

    x_pred  = x + dx dt (+ ddx dt^2 / 2),   dx_pred = dx (+ ddx dt),   y = z - x_pred
    ddx     = ddx_pred + 2 k y / dt^2
    dx      = dx_pred + h y / dt
    x       = x_pred + g y

which is the thesis's recursion (eqs. 2-4..2-6, 2-33..2-36) with (g, h, k) = (alpha, beta,
gamma): FilterPy's acceleration gain 2 k / dt^2 is trackkit's convention 2 gamma / dt^2, so no
mapping is needed. Where the definitions differ:

- Start-up: FilterPy starts from the x, dx (ddx) it is given and applies the constant gains
  from the first measurement; the thesis's rules (2-7..2-9, 2-37..2-40, trackkit's default
  ``startup="thesis"``) replace the first measurements' gains. The comparison uses
  ``startup="prior"``, whose prior mean is FilterPy's initial state.
- Time-varying gains: FilterPy's ``update(z, g, h)`` with ``least_squares_parameters(n)``
  (n from 0) is trackkit's ``startup="simpson"`` at scan k = n + 1.
- FilterPy keeps no covariance; trackkit's is compared elsewhere (tests/test_alphabeta.py).
- ``GHKFilter.VRF()`` is not compared: it disagrees with the discrete Lyapunov solution (at
  g, h, k = 0.5, 0.2, 0.02 and dt = 0.7 it gives VRF(x) = -0.687, VRF(dx) = 0.0388 where the
  steady state is 0.469 and 0.158; its VRF(ddx) agrees). ``GHFilter.VRF()`` (g-h) agrees and is
  compared below.

Every estimate must agree step by step to 1e-12 relative to the trajectory's scale (the two
implementations round the same operations in a different order).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.gh import (
    GHFilter,
    GHKFilter,
    benedict_bornder_constants,
    critical_damping_parameters,
    least_squares_parameters,
)

import trackkit as tk
from trackkit.filters.alphabeta import (
    AlphaBeta,
    AlphaBetaGamma,
    benedict_bordner,
    fading_memory,
    fading_memory_abg,
    kohn,
    simpson,
    vrr,
)

RTOL = 1e-12


def assert_scaled(actual, expected, what):
    actual, expected = np.asarray(actual, float), np.asarray(expected, float)
    scale = np.max(np.abs(expected), axis=0)
    err = np.max(np.abs(actual - expected), axis=0)
    assert np.all(err <= RTOL * scale), f"{what}: errors {err} vs scale {scale}"


def _measurements(rng, K, d, dt, accel=0.0):
    t = dt * np.arange(1, K + 1)[:, None]
    truth = np.array([120.0, -40.0][:d]) + np.array([15.0, 6.0][:d]) * t + accel * t**2 / 2
    return truth + rng.normal(0.0, 3.0, (K, d))


def _ours(f, mean, z, dt, gains_per_step=None):
    """Our filter over z (K, d) from the prior mean: smoothed and predicted means per step."""
    d = z.shape[1]
    n = mean.size
    b = f.init(tk.Gaussian(mean, 25.0 * np.eye(n)))
    sensor = tk.models.Position(dim=d, sigma=3.0)
    smoothed, predicted = [], []
    for zk in z:
        b = f.predict(b, None, dt)
        predicted.append(b.mean.copy())
        b, _ = f.update(b, zk, sensor)
        smoothed.append(b.mean.copy())
    return np.array(smoothed), np.array(predicted)


@pytest.mark.parametrize("d", [1, 2])
@pytest.mark.parametrize("gains", [kohn(), (0.8, benedict_bordner(0.8)), fading_memory(0.3)])
def test_gh_filter_step_by_step(d, gains):
    rng = np.random.default_rng(10 * d)
    dt, K = 0.4, 60
    z = _measurements(rng, K, d, dt)
    x0, dx0 = np.array([100.0, -30.0][:d]), np.array([10.0, 2.0][:d])
    fp = GHFilter(x0.copy() if d > 1 else float(x0[0]), dx0.copy() if d > 1 else float(dx0[0]),
                  dt, *gains)
    ref_x, ref_dx, ref_pred = [], [], []
    for zk in z:
        fp.update(zk if d > 1 else float(zk[0]))
        ref_x.append(np.atleast_1d(fp.x).copy())
        ref_dx.append(np.atleast_1d(fp.dx).copy())
        ref_pred.append(np.atleast_1d(fp.x_prediction).copy())
    smoothed, predicted = _ours(AlphaBeta(*gains, startup="prior"), np.r_[x0, dx0], z, dt)
    assert_scaled(smoothed[:, :d], ref_x, "x")
    assert_scaled(smoothed[:, d:], ref_dx, "dx")
    assert_scaled(predicted[:, :d], ref_pred, "x_prediction")


@pytest.mark.parametrize("d", [1, 2])
@pytest.mark.parametrize("xi", [0.2, 0.5, 0.8])
def test_ghk_filter_step_by_step(d, xi):
    rng = np.random.default_rng(int(100 * xi) + d)
    dt, K = 0.25, 80
    z = _measurements(rng, K, d, dt, accel=np.array([2.0, -1.0][:d]))
    gains = fading_memory_abg(xi)
    x0, dx0, ddx0 = (np.array(v[:d]) for v in ([110.0, -35.0], [12.0, 5.0], [1.0, 0.0]))
    scalar = d == 1
    fp = GHKFilter(*(float(v[0]) if scalar else v.copy() for v in (x0, dx0, ddx0)), dt, *gains)
    ref = []
    for zk in z:
        fp.update(float(zk[0]) if scalar else zk)
        ref.append(np.concatenate([np.atleast_1d(fp.x), np.atleast_1d(fp.dx),
                                   np.atleast_1d(fp.ddx)]))
    smoothed, _ = _ours(AlphaBetaGamma(*gains, startup="prior"), np.r_[x0, dx0, ddx0], z, dt)
    ref = np.array(ref)
    for j, name in enumerate(("x", "dx", "ddx")):
        assert_scaled(smoothed[:, j * d:(j + 1) * d], ref[:, j * d:(j + 1) * d], name)


def test_least_squares_gains_step_by_step():
    """FilterPy's growing-memory (least-squares) g-h filter, gains least_squares_parameters(n)
    at its n-th update, against startup="simpson"."""
    rng = np.random.default_rng(4)
    dt, K = 0.5, 40
    z = _measurements(rng, K, 1, dt)
    fp = GHFilter(0.0, 0.0, dt, 1.0, 1.0)
    ref = []
    for n, zk in enumerate(z):
        fp.update(float(zk[0]), *least_squares_parameters(n))
        ref.append([fp.x, fp.dx])
    smoothed, _ = _ours(AlphaBeta(startup="simpson"), np.zeros(2), z, dt)
    ref = np.array(ref)
    assert_scaled(smoothed, ref, "x, dx")  # both start from x = dx = 0


def test_gain_designers_and_gh_vrf_agree():
    for g in np.linspace(0.05, 1.15, 12):
        assert benedict_bornder_constants(g) == pytest.approx((g, benedict_bordner(g)),
                                                              rel=1e-15, abs=0)
    for theta in np.linspace(0.0, 0.95, 12):
        assert critical_damping_parameters(theta) == pytest.approx(fading_memory(theta),
                                                                   rel=1e-15, abs=0)
        assert critical_damping_parameters(theta, order=3) == pytest.approx(
            fading_memory_abg(theta), rel=1e-14, abs=0)
    for n in range(30):
        assert least_squares_parameters(n) == pytest.approx(simpson(n + 1), rel=1e-15, abs=0)
    for g, h, dt in [(0.5, 0.167, 1.0), (0.75, 0.25, 0.3), (0.2, 0.02, 2.0)]:
        vx, vdx = GHFilter(0.0, 0.0, dt, g, h).VRF()
        r = vrr(g, h, dt=dt)
        assert (r.x, r.v) == pytest.approx((vx, vdx), rel=1e-12, abs=0)
