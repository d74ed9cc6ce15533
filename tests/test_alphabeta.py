"""Constant-gain trackers of the missing-measurements thesis (sections 2-1 to 2-4 and its
printed examples).

References are computed here, independently of trackkit.filters.alphabeta: the closed-loop
matrix ``A = (I - K G) Phi`` is written out by hand and its steady state solved with
``scipy.linalg.solve_discrete_lyapunov``; the thesis's printed numbers are checked
to their printed digits and to exact rational arithmetic (``fractions.Fraction``) of the
thesis's formulas; least-squares fits use ``numpy.linalg.lstsq``.

Tolerances: the printed table values carry six decimals, so they are held to half a unit of
the last digit (5e-7 absolute); exact formulas to 1e-12 relative (a few roundings of O(1)
numbers); comparisons with a Lyapunov solve or a least-squares fit to 1e-9 relative (both go
through a linear solve of condition up to ~1e3); covariance entries are compared relative to
``sqrt(C_ii C_jj)`` (a cross term can pass through zero).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from scipy.linalg import solve_discrete_lyapunov
from scipy.stats import chi2

import trackkit as tk
from trackkit.filters.alphabeta import (
    AlphaBeta,
    AlphaBetaBelief,
    AlphaBetaGamma,
    alpha_beta_gamma_track,
    alpha_beta_track,
    benedict_bordner,
    benedict_bordner_gamma,
    benedict_bordner_vrr,
    characteristic_polynomial,
    fading_memory,
    fading_memory_abg,
    fading_memory_vrr,
    in_stability_region,
    in_stability_region_abg,
    is_stable,
    kohn,
    roots,
    simpson,
    simpson_abg,
    steady_state_cov,
    vrr,
    vrr_abg,
)

# --------------------------------------------------------------------------------------------
# Independent references


def closed_loop(alpha, beta, gamma=None, dt=1.0, accel_gain=2.0):
    """``(A, K)`` of one coordinate: ``Phi`` the polynomial transition, ``G = [1 0 (0)]``,
    ``K = [alpha, beta/dt(, accel_gain gamma/dt^2)]``, ``A = (I - K G) Phi``."""
    if gamma is None:
        Phi = np.array([[1.0, dt], [0.0, 1.0]])
        K = np.array([[alpha], [beta / dt]])
    else:
        Phi = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        K = np.array([[alpha], [beta / dt], [accel_gain * gamma / dt**2]])
    G = np.zeros((1, Phi.shape[0]))
    G[0, 0] = 1.0
    return (np.eye(Phi.shape[0]) - K @ G) @ Phi, K


def lyapunov_cov(alpha, beta, gamma=None, dt=1.0, sigma2=1.0, accel_gain=2.0):
    """Steady state of ``C = A C A^T + K sigma^2 K^T`` (noise-only input)."""
    A, K = closed_loop(alpha, beta, gamma, dt, accel_gain)
    return solve_discrete_lyapunov(A, sigma2 * K @ K.T)


def assert_cov_close(actual, expected, rtol, what=""):
    """Entrywise ``|a_ij - e_ij| <= rtol sqrt(e_ii e_jj)``."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    d = np.sqrt(np.abs(np.diagonal(expected, axis1=-2, axis2=-1)))
    scale = d[..., :, None] * d[..., None, :]
    err = np.abs(actual - expected)
    assert np.all(err <= rtol * scale), f"{what}: max scaled error {np.max(err / scale):.3e}"


def assert_scaled(actual, expected, rtol, what=""):
    """``|a - e| <= rtol max|e|`` (a trajectory passes through zero)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.max(np.abs(expected))
    err = np.max(np.abs(actual - expected))
    assert err <= rtol * scale, f"{what}: max error {err:.3e} vs scale {scale:.3e}"


def ls_fit(z, times, degree):
    """Least-squares polynomial through ``z[:k]`` for each k, evaluated at ``times[k-1]``:
    returns ``(K, degree + 1, runs)`` of (position, velocity[, acceleration]); rows with too
    few points for the degree are nan."""
    K, runs = z.shape
    out = np.full((K, degree + 1, runs), np.nan)
    for k in range(degree + 1, K + 1):
        s = times[:k] - times[k - 1]
        # columns 1, s, s^2/2: the coefficients are position, velocity, acceleration at t_k
        M = np.stack([s**j / [1.0, 1.0, 2.0][j] for j in range(degree + 1)], -1)
        out[k - 1] = np.linalg.lstsq(M, z[:k], rcond=None)[0]
    return out


def run(f, prior, zs, dt, sensor, motion=None):
    """Run a filter; stack the smoothed means, covariances and predicted means."""
    b = f.init(prior)
    means, covs, preds = [], [], []
    for z in zs:
        b = f.predict(b, motion, dt)
        preds.append(b.mean)
        b, _ = f.update(b, z, sensor)
        means.append(b.mean)
        covs.append(b.cov)
    return np.stack(means), np.stack(covs), np.stack(preds), b


def prior(n, batch=(), std=10.0, mean=None):
    m = np.zeros(batch + (n,)) if mean is None else np.broadcast_to(mean, batch + (n,))
    return tk.Gaussian(m, np.broadcast_to(std**2 * np.eye(n), batch + (n, n)))


# --------------------------------------------------------------------------------------------
# Gain designers


def test_designers_give_the_thesis_gains():
    assert kohn() == (0.5, 0.167)
    assert benedict_bordner(0.5) == pytest.approx(1 / 6, rel=1e-15, abs=0)
    assert abs(benedict_bordner(0.5) - 0.166667) <= 5e-7  # section 5's printed value
    assert fading_memory(0.5) == (0.75, 0.25)
    # gamma = 0 recovers 2-24; otherwise 2 beta - alpha (alpha + beta + gamma/2) = 0
    a = np.linspace(0.1, 1.9, 7)
    assert np.allclose(benedict_bordner_gamma(a, benedict_bordner(a)), 0.0, atol=1e-14)
    b = np.full(7, 0.3)
    g = benedict_bordner_gamma(a, b)
    assert np.allclose(2 * b - a * (a + b + g / 2), 0.0, atol=1e-13)


def test_simpson_gains_k_1_to_5():
    """The thesis prints (1, 3), (1, 1), (0.8333, 0.5), (0.7, 0.3), (0.6, 0.2) for k = 1..5."""
    table = [(Fraction(1), Fraction(3)), (Fraction(1), Fraction(1)),
             (Fraction(5, 6), Fraction(1, 2)), (Fraction(7, 10), Fraction(3, 10)),
             (Fraction(3, 5), Fraction(1, 5))]
    a, b = simpson(np.arange(1, 6))
    for k, (ea, eb) in enumerate(table, start=1):
        assert a[k - 1] == pytest.approx(float(ea), rel=1e-15, abs=0), k
        assert b[k - 1] == pytest.approx(float(eb), rel=1e-15, abs=0), k
        assert simpson(k) == (a[k - 1], b[k - 1])
    assert abs(a[2] - 0.8333) < 5e-5  # printed to four digits
    # the growing-memory quadratic: k = 3 is the parabola through three points
    assert simpson_abg(3) == pytest.approx((1.0, 1.5, 0.5), rel=1e-15, abs=0)


def test_fading_memory_puts_every_root_at_xi():
    """Double root for alpha-beta, triple for alpha-beta-gamma, both from the hand-built
    A = (I - K G) Phi. Coefficients to 1e-12; the roots of a triple root are only determined
    to about eps^(1/3) ~ 6e-6 by any root finder, so they are checked to 1e-4."""
    for xi in (0.0, 0.3, 0.5, 0.9):
        A, _ = closed_loop(*fading_memory(xi), dt=0.8)
        assert np.allclose(np.poly(A), np.poly([xi, xi]), rtol=0, atol=1e-12)
        assert np.allclose(characteristic_polynomial(*fading_memory(xi)),
                           np.poly([xi, xi]), rtol=0, atol=1e-12)
        assert np.allclose(roots(*fading_memory(xi)), xi, atol=1e-7)
        A, _ = closed_loop(*fading_memory_abg(xi), dt=0.8)
        assert np.allclose(np.poly(A), np.poly([xi] * 3), rtol=0, atol=1e-12)
        assert np.allclose(roots(*fading_memory_abg(xi)), xi, atol=1e-4)
    # gamma' = 2 gamma (the gamma/dt^2 convention) is FilterPy's / Brookner's (1 - xi)^3
    assert fading_memory_abg(0.4)[2] == pytest.approx(0.6**3 / 2, rel=1e-15, abs=0)


# --------------------------------------------------------------------------------------------
# The numbers the missing-measurements thesis prints


def _vrr_exact(a: Fraction, b: Fraction):
    """Eqs. 2-17..2-19 in exact rational arithmetic (dt = 1)."""
    den = a * (4 - 2 * a - b)
    return (2 * a * a - 3 * a * b + 2 * b) / den, b * (2 * a - b) / den, 2 * b * b / den


@pytest.mark.parametrize(
    "name, gains, exact, printed",
    [
        # Kohn: VRR(x) = 0.411931, C_xv dt / s^2 = 0.098208, VRR(v) dt^2 = 0.039377
        ("kohn", kohn(), (Fraction(1, 2), Fraction(167, 1000)),
         (0.411931, 0.098208, 0.039377)),
        # Benedict-Bordner alpha = 0.5: VRR(x) = 0.411765, VRR(v) dt^2 = 0.039216
        ("benedict-bordner", (0.5, benedict_bordner(0.5)), (Fraction(1, 2), Fraction(1, 6)),
         (0.411765, None, 0.039216)),
        # fading memory xi = 0.5: 0.629630, 0.185185 (corrected 2-30), 0.074074
        ("fading-memory", fading_memory(0.5), (Fraction(3, 4), Fraction(1, 4)),
         (0.629630, 0.185185, 0.074074)),
    ],
)
def test_section5_table(name, gains, exact, printed):
    """Every number of the table, to its printed digits; the formulas to exact rational
    arithmetic; and both against the Lyapunov solve of A = (I - K G) Phi, to 1e-9, at dt = 1
    and at dt = 0.37 (velocity terms scale as 1/dt and 1/dt^2)."""
    r = vrr(*gains)
    ours = (r.x, r.xv, r.v)
    for got, want in zip(ours, printed, strict=True):
        if want is not None:
            assert abs(got - want) <= 5e-7, (name, got, want)
    for got, want in zip(ours, _vrr_exact(*exact), strict=True):
        assert got == pytest.approx(float(want), rel=1e-12, abs=0), name
    for dt in (1.0, 0.37):
        C = lyapunov_cov(*gains, dt=dt)
        r = vrr(*gains, dt=dt)
        for got, want in ((r.x, C[0, 0]), (r.xv, C[0, 1]), (r.v, C[1, 1])):
            assert got == pytest.approx(want, rel=1e-9, abs=0), (name, dt)
        assert_cov_close(steady_state_cov(*gains, dt=dt, sigma=3.0), 9.0 * C, 1e-9, name)


def test_closed_forms_of_benedict_bordner_and_fading_memory():
    """2-25, 2-26 (and the derived cross term) equal 2-17 on the Benedict-Bordner curve;
    2-29, the corrected 2-30 and 2-31 equal 2-17 at the fading-memory gains; the thesis's
    printed 2-30, (1-xi)^2 (1 + 2 xi + 3 xi^2) / (dt (1+xi)^3), does not."""
    a = np.linspace(0.05, 1.15, 39)
    bb, gen = benedict_bordner_vrr(a, dt=0.6), vrr(a, benedict_bordner(a), dt=0.6)
    for f in ("x", "v", "xv"):
        np.testing.assert_allclose(getattr(bb, f), getattr(gen, f), rtol=1e-12, err_msg=f)
    # beyond alpha = 4 - 2 sqrt(2) the Benedict-Bordner pair is unstable: no steady state
    assert np.isnan(benedict_bordner_vrr(1.2).x) and not is_stable(1.2, benedict_bordner(1.2))
    assert is_stable(1.17, benedict_bordner(1.17))
    xi = np.linspace(0.0, 0.98, 50)
    fm, gen = fading_memory_vrr(xi, dt=0.6), vrr(*fading_memory(xi), dt=0.6)
    for f in ("x", "v", "xv"):
        np.testing.assert_allclose(getattr(fm, f), getattr(gen, f), rtol=1e-12, err_msg=f)
    printed_230 = (1 - 0.5) ** 2 * (1 + 2 * 0.5 + 3 * 0.25) / 1.5**3
    assert abs(printed_230 / vrr(*fading_memory(0.5)).xv - 1) > 0.05  # 10% off


def test_vrr_matches_lyapunov_on_random_gains():
    rng = np.random.default_rng(12)
    a = rng.uniform(0.02, 1.98, 300)
    b = rng.uniform(0.0, 1.0, 300) * (4 - 2 * a)
    keep = (b > 1e-3) & (b < 4 - 2 * a - 1e-3)
    a, b = a[keep], b[keep]
    dt = rng.uniform(0.1, 5.0, a.size)
    C = steady_state_cov(a, b, dt=dt)  # batched over gains and dt
    for i in range(a.size):
        assert_cov_close(C[i], lyapunov_cov(a[i], b[i], dt=dt[i]), 1e-9, f"row {i}")


def test_alpha_beta_gamma_characteristic_polynomial_and_vrr():
    """np.poly of (I - K G) Phi with K3 = 2 gamma / dt^2 is eq. 2-49; the VRR formulas
    2-45..2-47 at gamma' = 2 gamma (and our cross terms) equal the Lyapunov solve; and the
    thesis's formulas at gamma itself are the filter with K3 = gamma / dt^2 (the warning on
    the thesis's section 2-4)."""
    rng = np.random.default_rng(3)
    n_ok = 0
    for _ in range(400):
        a, b, g = rng.uniform(0, 2), rng.uniform(0, 4), rng.uniform(0, 1)
        dt = rng.uniform(0.05, 3.0)
        A, _ = closed_loop(a, b, g, dt)
        np.testing.assert_allclose(characteristic_polynomial(a, b, g), np.poly(A),
                                   rtol=0, atol=1e-12 * max(1.0, abs(a + b + g)))
        assert np.allclose(characteristic_polynomial(a, b, g),
                           [1, a + b + g - 3, 3 - 2 * a - b + g, -(1 - a)], rtol=0, atol=1e-15)
        if np.max(np.abs(np.linalg.eigvals(A))) > 0.999:
            continue
        n_ok += 1
        r = vrr_abg(a, b, g, dt)
        C = np.array([[r.x, r.xv, r.xa], [r.xv, r.v, r.va], [r.xa, r.va, r.a]])
        assert_cov_close(C, lyapunov_cov(a, b, g, dt), 1e-9, f"{(a, b, g, dt)}")
        assert_cov_close(steady_state_cov(a, b, g, dt=dt), C, 1e-15)
        # the thesis's formula as printed (gamma') is the gamma/dt^2 filter
        r1 = vrr_abg(a, b, g / 2, dt)
        C1 = lyapunov_cov(a, b, g, dt, accel_gain=1.0)
        assert r1.x == pytest.approx(C1[0, 0], rel=1e-9, abs=0)
        assert r1.v == pytest.approx(C1[1, 1], rel=1e-9, abs=0)
        assert r1.a == pytest.approx(C1[2, 2], rel=1e-9, abs=0)
    assert n_ok > 50


# --------------------------------------------------------------------------------------------
# Stability


def test_kohn_roots_have_modulus_sqrt_half():
    z = roots(*kohn())
    np.testing.assert_allclose(np.abs(z), np.sqrt(0.5), rtol=1e-12)
    np.testing.assert_allclose(np.sort_complex(z), np.sort_complex(
        np.roots([1, -(2 - 0.5 - 0.167), 1 - 0.5])), rtol=1e-12)
    assert is_stable(*kohn()) and in_stability_region(*kohn())


def test_root_test_and_region_agree_on_a_grid():
    """alpha-beta: the root test against 0 < alpha < 2, 0 < beta < 4 - 2 alpha on a
    121 x 121 grid over [-0.5, 2.5] x [-0.5, 4.5], excluding a band of 1e-6 about the
    boundary lines (where rounding decides)."""
    a, b = np.meshgrid(np.linspace(-0.5, 2.5, 121), np.linspace(-0.5, 4.5, 121))
    band = np.minimum.reduce([np.abs(a), np.abs(a - 2), np.abs(b), np.abs(b - (4 - 2 * a))])
    keep = band > 1e-6
    stable, region = is_stable(a, b), in_stability_region(a, b)
    assert np.array_equal(stable[keep], region[keep])
    assert 0.2 < region[keep].mean() < 0.8  # both classes well represented


def test_root_test_and_region_agree_for_alpha_beta_gamma():
    """Random (alpha, beta, gamma), excluding the band where numpy's own roots have
    modulus within 1e-6 of 1."""
    rng = np.random.default_rng(5)
    a = rng.uniform(-0.2, 2.2, 4000)
    b = rng.uniform(-0.2, 4.5, 4000)
    g = rng.uniform(-0.2, 2.0, 4000)
    ref = np.array([np.max(np.abs(np.roots([1, ai + bi + gi - 3, 3 - 2 * ai - bi + gi,
                                            ai - 1]))) for ai, bi, gi in zip(a, b, g, strict=True)])
    keep = np.abs(ref - 1) > 1e-6
    assert np.array_equal(is_stable(a, b, g)[keep], (ref < 1)[keep])
    assert np.array_equal(in_stability_region_abg(a, b, g)[keep], (ref < 1)[keep])
    assert 0.05 < (ref < 1).mean() < 0.95


def test_vrr_is_nan_outside_the_region():
    r = vrr(np.array([0.5, 2.5]), np.array([0.1, 0.1]))
    assert np.isfinite(r.x[0]) and np.isnan(r.x[1]) and np.isnan(r.v[1])
    assert np.isnan(vrr_abg(0.5, 0.1, 0.5).x)


# --------------------------------------------------------------------------------------------
# Growing memory: Simpson's gains are the least-squares fit


@pytest.mark.parametrize("order", [2, 3])
def test_simpson_gains_give_the_least_squares_fit(order):
    """The class with startup="simpson" (and, for alpha-beta, the plain recursion with
    Simpson's per-scan gains) equals the least-squares line (quadratic) through all data so
    far, position, velocity (and acceleration), at every scan from k = 2 (3), to 1e-9; 30
    runs of 15 scans of random data."""
    rng = np.random.default_rng(7 + order)
    K, runs, dt = 15, 30, 0.4
    z = rng.normal(50.0, 20.0, (K, runs))
    times = dt * np.arange(K)
    ref = ls_fit(z, times, order - 1)
    f = AlphaBeta(startup="simpson") if order == 2 else AlphaBetaGamma(startup="simpson")
    sensor = tk.models.Position(dim=1, sigma=1.0)
    means, _, _, _ = run(f, prior(order, (runs,)), z[..., None], dt, sensor)
    assert np.allclose(means[0, :, 0], z[0], rtol=1e-15, atol=0)
    for j in range(order):
        assert_scaled(means[order - 1:, :, j], ref[order - 1:, j], 1e-9, f"component {j}")
    if order == 2:
        a, b = simpson(np.arange(1, K + 1))
        tr = alpha_beta_track(z, dt, a[:, None], b[:, None])
        assert_scaled(tr.x_s[1:], ref[1:, 0], 1e-9, "plain x_s")
        assert_scaled(tr.v_s[1:], ref[1:, 1], 1e-9, "plain v_s")


def test_reset_restarts_the_growing_memory():
    """Rows reset before scan 7 equal the least-squares line of the data from scan 7 on;
    the others still fit all the data."""
    rng = np.random.default_rng(8)
    K, runs, dt = 14, 6, 1.0
    z = rng.normal(0.0, 5.0, (K, runs)) + 2.0 * np.arange(K)[:, None]
    f = AlphaBeta(startup="simpson")
    sensor = tk.models.Position(dim=1, sigma=1.0)
    rows = np.arange(runs) % 2 == 0
    b = f.init(prior(2, (runs,)))
    for n in range(K):
        if n == 6:
            b = f.reset(b, rows)
            assert np.array_equal(b.k, np.where(rows, 0, 6))
        b = f.predict(b, None, dt)
        b, _ = f.update(b, z[n, :, None], sensor)
    times = dt * np.arange(K)
    full = ls_fit(z, times, 1)[-1]
    late = ls_fit(z[6:], times[6:], 1)[-1]
    want = np.where(rows, late, full)
    assert_scaled(b.mean, want.T, 1e-9)
    assert np.array_equal(b.k, np.where(rows, K - 6, K))


def test_switch_from_growing_memory_to_constant_gains():
    f = AlphaBeta(0.3, benedict_bordner(0.3), startup="simpson", switch_after=5)
    k = np.arange(1, 10)
    a, b = f.scheduled_gains(k)
    sa, sb = simpson(k)
    assert np.array_equal(a, np.where(k <= 5, sa, 0.3))
    assert np.array_equal(b, np.where(k <= 5, sb, benedict_bordner(0.3)))
    for alpha in (0.3, 0.05, 0.9):
        s = AlphaBeta(alpha, 0.01, startup="simpson").switch_after
        assert simpson(s)[0] > alpha >= simpson(s + 1)[0]
        s = AlphaBetaGamma(alpha, 0.01, 1e-5, startup="simpson").switch_after
        assert simpson_abg(s)[0] > alpha >= simpson_abg(s + 1)[0]


# --------------------------------------------------------------------------------------------
# The filter class against the thesis's recursion


@pytest.mark.parametrize("order", [2, 3])
def test_filter_equals_the_plain_recursion(order):
    """d = 2, 20 runs, thesis start-up, prior velocity (acceleration) zero as in the thesis:
    the class's smoothed and predicted means equal alpha_beta(_gamma)_track to 1e-12."""
    rng = np.random.default_rng(order)
    K, runs, d, dt = 40, 20, 2, 0.3
    t = dt * np.arange(K)
    truth = 100.0 + 30.0 * t + (5.0 * t**2 if order == 3 else 0.0)
    z = truth[:, None, None] + rng.normal(0, 2.0, (K, runs, d))
    if order == 2:
        gains = kohn()
        f, tr = AlphaBeta(*gains), alpha_beta_track(z, dt, *gains)
        parts = [(tr.x_s, tr.x_p), (tr.v_s, tr.v_p)]
    else:
        gains = fading_memory_abg(0.7)
        f, tr = AlphaBetaGamma(*gains), alpha_beta_gamma_track(z, dt, *gains)
        parts = [(tr.x_s, tr.x_p), (tr.v_s, tr.v_p), (tr.a_s, tr.a_p)]
    sensor = tk.models.Position(dim=2, sigma=[2.0, 3.0])
    means, _, preds, b = run(f, prior(order * d, (runs,), mean=np.r_[5.0, 7.0, [0.0] *
                                                                     (order * d - 2)]),
                             z, dt, sensor)
    for j, (smoothed, predicted) in enumerate(parts):
        assert_scaled(means[..., j * d:(j + 1) * d], smoothed, 1e-12, f"smoothed {j}")
        assert_scaled(preds[1:, ..., j * d:(j + 1) * d], predicted[1:], 1e-12, f"pred {j}")
    assert np.array_equal(b.k, np.full(runs, K))


@pytest.mark.parametrize("order", [2, 3])
def test_thesis_startup_forgets_the_prior(order):
    """Scan 1 takes the position from z and keeps the prior's predicted velocity (0 in the
    thesis); from scan 2 (alpha-beta) or 3 (alpha-beta-gamma)
    the estimate no longer depends on the prior's velocity or acceleration."""
    rng = np.random.default_rng(11)
    K, dt = 8, 0.5
    z = rng.normal(0, 3.0, (K, 1))
    f = AlphaBeta(*kohn()) if order == 2 else AlphaBetaGamma(*fading_memory_abg(0.5))
    sensor = tk.models.Position(dim=1, sigma=1.0)
    m0, _, _, _ = run(f, prior(order), z, dt, sensor)
    m1, _, _, _ = run(f, prior(order, mean=[40.0, -9.0, 3.0][:order]), z, dt, sensor)
    # x_p + 1 (z - x_p) = z up to the rounding of the residual (x_p ~ 40)
    assert abs(m1[0, 0] - z[0, 0]) <= 1e-14 * 40
    assert m1[0, 1] == (-9.0 if order == 2 else -9.0 + 3.0 * dt)  # the predicted velocity
    assert_scaled(m1[order - 1:], m0[order - 1:], 1e-12)


def test_batched_rows_equal_rows_alone_bitwise():
    """A (3, 4) batch with per-row gains, per-row measurement gaps, a reset of some rows,
    process noise and per-axis sigma equals each row run alone, bit for bit (means,
    covariances, residuals, innovation covariances, k, tau)."""
    rng = np.random.default_rng(21)
    batch, d, K, dt = (3, 4), 2, 12, 0.7
    alpha = rng.uniform(0.2, 0.9, batch)
    beta = benedict_bordner(alpha)
    z = rng.normal(0, 10.0, (K,) + batch + (d,))
    z[3, 0, 1] = np.nan
    z[4:6, 2, :] = np.nan
    reset_rows = rng.random(batch) < 0.5
    motion = tk.models.ConstantVelocity(dim=d, q=0.3)
    sensor = tk.models.Position(dim=d, sigma=[1.0, 2.5])
    P0 = np.diag([50.0, 60.0, 5.0, 6.0])

    def go(f, mean, z_seq, rows):
        b = f.init(tk.Gaussian(mean, np.broadcast_to(P0, mean.shape[:-1] + (4, 4))))
        out = []
        for n, zn in enumerate(z_seq):
            if n == 7:
                b = f.reset(b, rows)
            b = f.predict(b, motion, dt)
            b, inn = f.update(b, zn, sensor)
            out.append((b.mean, b.cov, inn.nu, inn.cov, b.k, b.tau))
        return out

    mean0 = rng.normal(0, 5.0, batch + (4,))
    together = go(AlphaBeta(alpha, beta), mean0, z, reset_rows)
    for idx in np.ndindex(batch):
        alone = go(AlphaBeta(alpha[idx], beta[idx]), mean0[idx], z[(slice(None),) + idx],
                   np.asarray(reset_rows[idx]))
        for step, (t_all, t_one) in enumerate(zip(together, alone, strict=True)):
            for name, a_all, a_one in zip(("mean", "cov", "r", "S", "k", "tau"), t_all,
                                          t_one, strict=True):
                row = np.broadcast_to(a_all, batch + np.shape(a_one)[np.ndim(a_one) -
                                                                    (np.ndim(a_all) - 2):])
                assert np.array_equal(row[idx], a_one, equal_nan=True), (idx, step, name)


def test_per_row_gains_with_a_shared_prior():
    """Gains given per row (a gain study as one batch) with one unbatched prior: the rows
    equal separate filters, bitwise."""
    alpha = np.array([0.3, 0.5, 0.7])
    f = AlphaBetaGamma(alpha, 0.1, 0.002)
    sensor = tk.models.Position(dim=1, sigma=2.0)
    z = np.array([[1.0], [2.5], [np.nan], [6.0], [8.5]])
    means, covs, _, _ = run(f, prior(3), z, 0.5, sensor)
    for i, a in enumerate(alpha):
        m1, c1, _, _ = run(AlphaBetaGamma(a, 0.1, 0.002), prior(3), z, 0.5, sensor)
        assert np.array_equal(means[:, i], m1) and np.array_equal(covs[:, i], c1)


def test_nan_coasts_and_the_gap_is_spanned():
    """A missing scan keeps the prediction, k, and accumulates tau; the next update's gains
    span the gap, so the start-up line is exact through the two measurements."""
    f = AlphaBeta(*kohn())
    sensor = tk.models.Position(dim=1, sigma=1.0)
    b = f.init(prior(2))
    b = f.predict(b, None, 1.0)
    b, _ = f.update(b, [10.0], sensor)
    b = f.predict(b, None, 1.0)
    pred = b
    b, inn = f.update(b, [np.nan], sensor)
    assert np.array_equal(b.mean, pred.mean) and np.array_equal(b.cov, pred.cov)
    assert np.isnan(inn.nu).all() and b.k == 1 and b.tau == 1.0
    b = f.predict(b, None, 1.5)
    assert b.tau == 2.5
    b, _ = f.update(b, [15.0], sensor)
    assert b.mean[0] == pytest.approx(15.0, rel=1e-15, abs=0)
    assert b.mean[1] == pytest.approx(5.0 / 2.5, rel=1e-15, abs=0)
    assert b.k == 2 and b.tau == 0.0


# --------------------------------------------------------------------------------------------
# The propagated covariance


@pytest.mark.parametrize("order", [2, 3])
def test_covariance_converges_to_the_analytic_steady_state(order):
    """Q = 0, 200 scans: each axis's block of P equals steady_state_cov(sigma_axis) and the
    cross-axis blocks vanish, to 1e-9."""
    dt, sig = 0.25, np.array([2.0, 5.0])
    gains = kohn() if order == 2 else fading_memory_abg(0.6)
    f = AlphaBeta(*gains) if order == 2 else AlphaBetaGamma(*gains)
    sensor = tk.models.Position(dim=2, sigma=sig)
    z = np.zeros((200, 2))
    _, covs, _, _ = run(f, prior(2 * order, std=30.0), z, dt, sensor)
    P = covs[-1].reshape(order, 2, order, 2)
    for ax in range(2):
        want = steady_state_cov(*gains, dt=dt, sigma=sig[ax])
        assert_cov_close(P[:, ax, :, ax], want, 1e-9, f"axis {ax}")
    assert np.all(np.abs(P[:, 0, :, 1]) <= 1e-12 * sig.prod())


def test_covariance_with_process_noise_is_the_lyapunov_fixed_point():
    """With Q from ConstantVelocity(q) the recursion P+ = A P+ A^T + (I - K G) Q (I - K G)^T
    + K R K^T is what the filter propagates: its limit equals the Lyapunov solve, 1e-9."""
    dt, q, sigma = 0.5, 0.8, 3.0
    gains = (0.6, benedict_bordner(0.6))
    A, K = closed_loop(*gains, dt=dt)
    Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    IKG = np.eye(2) - K @ np.array([[1.0, 0.0]])
    want = solve_discrete_lyapunov(A, IKG @ Q @ IKG.T + sigma**2 * K @ K.T)
    f = AlphaBeta(*gains)
    _, covs, _, _ = run(f, prior(2), np.zeros((150, 1)), dt, tk.models.Position(1, sigma),
                        motion=tk.models.ConstantVelocity(dim=1, q=q))
    assert_cov_close(covs[-1], want, 1e-9)


@pytest.mark.parametrize("order", [2, 3])
def test_monte_carlo_variance_matches_the_vrr_and_nees_is_consistent(order):
    """4000 runs, d = 2, 100 scans of a straight-line (constant-acceleration) target with
    white position noise (sigma 2 and 5 m), Q = 0. At the last scan the errors are Gaussian
    with the steady-state covariance, so sum(e_x^2 / (sigma^2 VRR(x))) over runs and axes is
    chi-square with 8000 degrees of freedom (likewise velocity), and the summed NEES with the
    propagated P is chi-square with 4000 n. Each is held to its two-sided 99.9% interval
    (three statistics; with the fixed seed the test is deterministic)."""
    rng = np.random.default_rng(2024 + order)
    runs, K, dt, d = 4000, 100, 0.5, 2
    sig = np.array([2.0, 5.0])
    t = dt * np.arange(1, K + 1)
    acc = np.array([0.3, -0.2]) if order == 3 else np.zeros(2)
    pos = np.array([100.0, -50.0]) + np.array([12.0, 4.0]) * t[:, None] + acc * t[:, None] ** 2 / 2
    z = pos[:, None, :] + rng.standard_normal((K, runs, d)) * sig
    gains = kohn() if order == 2 else fading_memory_abg(0.5)
    f = AlphaBeta(*gains) if order == 2 else AlphaBetaGamma(*gains)
    b = f.init(prior(order * d, (runs,), std=100.0))
    sensor = tk.models.Position(dim=d, sigma=sig)
    for n in range(K):
        b = f.predict(b, None, dt)
        b, _ = f.update(b, z[n], sensor)
    vel = np.array([12.0, 4.0]) + acc * t[-1]
    err = b.mean - np.concatenate([pos[-1], vel] + ([acc] if order == 3 else []))
    r = vrr(*gains, dt=dt) if order == 2 else vrr_abg(*gains, dt=dt)
    lo, hi = chi2.ppf([0.0005, 0.9995], runs * d)
    stat_x = np.sum(err[:, :d] ** 2 / (sig**2 * r.x))
    stat_v = np.sum(err[:, d:2 * d] ** 2 / (sig**2 * r.v))
    assert lo < stat_x < hi, (stat_x, lo, hi)
    assert lo < stat_v < hi, (stat_v, lo, hi)
    nees = np.einsum("ri,rij,rj->r", err, np.linalg.inv(b.cov), err)
    lo, hi = chi2.ppf([0.0005, 0.9995], runs * order * d)
    assert lo < nees.sum() < hi, (nees.sum(), lo, hi)


def test_monte_carlo_nees_with_process_noise():
    """4000 runs of a ConstantVelocity(q = 2) target tracked by Benedict-Bordner gains with
    the same motion model for Q: the summed NEES at scan 60 is inside its two-sided 99.9%
    chi-square interval (4000 x 4 degrees of freedom)."""
    rng = np.random.default_rng(99)
    runs, K, dt, q, sigma = 4000, 60, 1.0, 2.0, 4.0
    motion = tk.models.ConstantVelocity(dim=2, q=q)
    L = np.linalg.cholesky(motion.noise(None, dt))
    F = motion.jacobian(None, dt)
    x = np.tile([0.0, 0.0, 10.0, 5.0], (runs, 1))
    f = AlphaBeta(0.5, benedict_bordner(0.5))
    b = f.init(prior(4, (runs,), std=100.0))
    sensor = tk.models.Position(dim=2, sigma=sigma)
    for _ in range(K):
        x = x @ F.T + rng.standard_normal((runs, 4)) @ L.T
        b = f.predict(b, motion, dt)
        b, _ = f.update(b, x[:, :2] + sigma * rng.standard_normal((runs, 2)), sensor)
    err = b.mean - x
    nees = np.einsum("ri,rij,rj->r", err, np.linalg.inv(b.cov), err)
    lo, hi = chi2.ppf([0.0005, 0.9995], runs * 4)
    assert lo < nees.sum() < hi, (nees.sum(), lo, hi)


# --------------------------------------------------------------------------------------------
# Bad input


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: AlphaBeta(2.5, 0.1), "alpha = 2.5"),
        (lambda: AlphaBeta(0.5, -0.1), "beta = -0.1"),
        (lambda: AlphaBeta(0.5, 3.5), "beta = 3.5"),
        (lambda: AlphaBeta(0.5, np.nan), "beta = nan"),
        (lambda: AlphaBeta(0.5), "beta not given"),
        (lambda: AlphaBeta(0.5, 0.1, startup="fast"), "startup = 'fast'"),
        (lambda: AlphaBeta(0.5, 0.1, switch_after=3), "switch_after = 3"),
        (lambda: AlphaBeta(0.5, 0.1, startup="simpson", switch_after=-1), "switch_after = -1"),
        (lambda: AlphaBetaGamma(0.5, 0.1, 0.5), "gamma = 0.5"),
        (lambda: AlphaBeta(np.array([0.5, 2.1]), 0.1), "alpha = 2.1"),
        (lambda: fading_memory(1.5), "xi = 1.5"),
        (lambda: fading_memory_vrr(1.0), "xi = 1.0"),
        (lambda: simpson(0), "k = 0"),
        (lambda: simpson_abg(1.5), "k = 1.5"),
        (lambda: vrr(0.5, 0.1, dt=0.0), "dt = 0.0"),
        (lambda: benedict_bordner(2.0), "alpha = 2.0"),
        (lambda: characteristic_polynomial(np.inf, 0.1), "alpha = inf"),
        (lambda: alpha_beta_track([1.0, np.nan, 3.0], 1.0, 0.5, 0.1), r"z\[1\] = nan"),
        (lambda: alpha_beta_track([1.0, 2.0], -1.0, 0.5, 0.1), "dt = -1.0"),
        (lambda: alpha_beta_gamma_track(np.zeros((4, 2)), 1.0, np.zeros(3), 0.1, 0.01),
         "alpha has shape"),
    ],
)
def test_bad_parameters_raise(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.parametrize("call", [
    lambda: vrr(0.5, 0.1, T=1.0),
    lambda: vrr_abg(0.5, 0.1, 0.01, T=1.0),
    lambda: steady_state_cov(0.5, 0.1, T=1.0),
    lambda: alpha_beta_track([1.0, 2.0], T=1.0, alpha=0.5, beta=0.1),
])
def test_old_time_step_keyword_is_refused_naming_dt(call):
    with pytest.raises(TypeError, match="'T' is now spelled 'dt'"):
        call()


def test_bad_filter_inputs_raise():
    f = AlphaBeta(*kohn())
    pos = tk.models.Position(dim=2, sigma=1.0)
    with pytest.raises(ValueError, match="5 components"):
        f.init(prior(5))
    b = f.init(prior(4))
    with pytest.raises(ValueError, match="ConstantAcceleration has 6 states"):
        f.predict(b, tk.models.ConstantAcceleration(dim=2, q=1.0), 1.0)
    with pytest.raises(ValueError, match="another transition"):
        f.predict(b, tk.models.LinearMotion(2 * np.eye(4), np.eye(4)), 1.0)
    with pytest.raises(ValueError, match="dt"):
        f.predict(b, None, -1.0)
    with pytest.raises(ValueError, match="sensor Bearing"):
        f.update(f.predict(b, None, 1.0), [0.1], tk.models.Bearing(sigma=0.01))
    with pytest.raises(ValueError, match="z has shape"):
        f.update(f.predict(b, None, 1.0), [1.0, 2.0, 3.0], pos)
    with pytest.raises(ValueError, match="tau = 0"):
        AlphaBeta(*kohn(), startup="prior").update(b, [1.0, 2.0], pos)
    with pytest.raises(ValueError, match="dtype"):
        f.reset(f.init(prior(4, (3,))), np.array([1, 0, 1]))
    assert isinstance(f.init(b), AlphaBetaBelief)
