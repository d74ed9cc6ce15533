"""Track initiation: one-point, two-point differencing (pairing against brute force, the
covariance against the linear map it comes from) and converted range-bearing measurements
(Monte Carlo: unbiased mean, covariance equal to the sample covariance)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

import trackkit as tk
from trackkit.tracking.initiate import (
    convert_range_bearing,
    converted_cov_given_truth,
    pair_plots,
    single_point,
    two_point,
)

# ------------------------------------------------------------------------------------------
# One-point


def test_single_point_structure():
    z = np.array([[100.0, 200.0], [-5.0, 7.0], [0.0, 0.0]])
    R = np.array([[25.0, 3.0], [3.0, 16.0]])
    b = single_point(z, R, v_max=30.0)
    assert b.mean.shape == (3, 4) and b.cov.shape == (3, 4, 4)
    assert np.array_equal(b.mean[:, :2], z) and np.all(b.mean[:, 2:] == 0)
    assert np.array_equal(b.cov[:, :2, :2], np.broadcast_to(R, (3, 2, 2)))
    assert np.allclose(b.cov[:, 2:, 2:], np.eye(2) * 30.0**2 / 3, rtol=1e-15)
    assert np.all(b.cov[:, :2, 2:] == 0) and np.all(b.cov[:, 2:, :2] == 0)
    tk.check_gaussian(*b)
    # per-plot R and per-axis velocity std, 3-D
    z3 = np.arange(6.0).reshape(2, 3)
    R3 = np.stack([np.eye(3), 2 * np.eye(3)])
    b3 = single_point(z3, R3, v_std=[1.0, 2.0, 3.0])
    assert b3.mean.shape == (2, 6)
    assert np.allclose(np.diagonal(b3.cov, axis1=1, axis2=2),
                       [[1, 1, 1, 1, 4, 9], [2, 2, 2, 1, 4, 9]])


def test_single_point_bad_input():
    z = np.zeros((2, 2))
    with pytest.raises(ValueError, match="v_max"):
        single_point(z, np.eye(2))
    with pytest.raises(ValueError, match="v_max"):
        single_point(z, np.eye(2), v_max=1.0, v_std=1.0)
    with pytest.raises(ValueError, match="v_max"):
        single_point(z, np.eye(2), v_max=-1.0)
    with pytest.raises(ValueError, match="v_std"):
        single_point(z, np.eye(2), v_std=[1.0, 0.0])
    with pytest.raises(ValueError, match="R"):
        single_point(z, np.eye(3), v_max=1.0)
    with pytest.raises(ValueError, match="z"):
        single_point(np.array([[np.nan, 0.0]]), np.eye(2), v_max=1.0)


# ------------------------------------------------------------------------------------------
# Two-point


def _brute_pairs(z1, z2, r):
    d = np.linalg.norm(z2[None, :, :] - z1[:, None, :], axis=-1)
    return np.argwhere(d <= r)


@pytest.mark.parametrize("seed", range(8))
def test_pair_plots_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    k1, k2, d = rng.integers(0, 60), rng.integers(0, 60), rng.integers(1, 4)
    z1 = rng.uniform(0, 1000, (k1, d))
    z2 = rng.uniform(0, 1000, (k2, d))
    if k1 and k2:  # a stationary target: the same plot twice (distance 0)
        z2[0] = z1[0]
    r = rng.uniform(50, 300)
    got = pair_plots(z1, z2, r)
    assert got.dtype == np.int64 and got.shape[1] == 2
    assert np.array_equal(got, _brute_pairs(z1, z2, r))  # argwhere: sorted by i, then j


def test_pair_plots_boundary_and_zero_distance():
    z1 = np.array([[0.0, 0.0], [10.0, 0.0]])
    z2 = np.array([[0.0, 0.0], [13.0, 4.0], [30.0, 0.0]])  # |(13,4)-(10,0)| = 5 exactly
    assert pair_plots(z1, z2, 5.0).tolist() == [[0, 0], [1, 1]]


@pytest.mark.parametrize("seed", range(5))
def test_two_point_pairs_with_per_plot_times_equal_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    k1, k2 = 40, 50
    z1, z2 = rng.uniform(0, 2000, (k1, 2)), rng.uniform(0, 2000, (k2, 2))
    t1 = rng.uniform(0.0, 1.0, k1)
    t2 = rng.uniform(3.0, 5.0, k2)
    v_max, margin = 60.0, 20.0
    pairs, b = two_point(z1, np.eye(2), t1, z2, np.eye(2), t2, v_max=v_max, margin=margin)
    dist = np.linalg.norm(z2[None] - z1[:, None], axis=-1)
    want = np.argwhere(dist <= v_max * (t2[None] - t1[:, None]) + margin)
    assert len(want) > 0 and np.array_equal(pairs, want)
    i, j = pairs.T
    dt = t2[j] - t1[i]
    assert np.allclose(b.mean, np.hstack([z2[j], (z2[j] - z1[i]) / dt[:, None]]), rtol=1e-14)


def test_two_point_covariance_is_the_linear_map():
    """x = A [z1; z2] with A = [[0, I], [-I/dt, I/dt]], so P = A blkdiag(R1, R2) A^T."""
    rng = np.random.default_rng(7)
    d, dt = 2, 2.5
    z1 = np.array([[0.0, 0.0], [500.0, 500.0]])
    z2 = z1 + [[20.0, -10.0], [5.0, 5.0]]
    R1 = np.stack([np.cov(rng.normal(size=(d, 10))) for _ in range(2)])
    R2 = np.stack([np.cov(rng.normal(size=(d, 10))) for _ in range(2)])
    pairs, b = two_point(z1, R1, 10.0, z2, R2, 10.0 + dt, v_max=20.0)
    assert pairs.tolist() == [[0, 0], [1, 1]]
    I, O = np.eye(d), np.zeros((d, d))
    A = np.block([[O, I], [-I / dt, I / dt]])
    for p, (i, j) in enumerate(pairs):
        Z = np.block([[R1[i], O], [O, R2[j]]])
        assert np.allclose(b.cov[p], A @ Z @ A.T, rtol=1e-13, atol=1e-15)
        assert np.allclose(b.mean[p], A @ np.concatenate([z1[i], z2[j]]), rtol=1e-14)
    tk.check_gaussian(*b)


def test_two_point_empty_and_bad_input():
    z = np.zeros((3, 2))
    pairs, b = two_point(np.zeros((0, 2)), np.eye(2), 0.0, z, np.eye(2), 1.0, v_max=1.0)
    assert pairs.shape == (0, 2) and b.mean.shape == (0, 4) and b.cov.shape == (0, 4, 4)
    pairs, b = two_point(z, np.eye(2), 0.0, z + 100, np.eye(2), 1.0, v_max=1.0)
    assert pairs.shape == (0, 2) and b.mean.shape == (0, 4)
    with pytest.raises(ValueError, match="t2"):
        two_point(z, np.eye(2), 1.0, z, np.eye(2), 1.0, v_max=1.0)
    with pytest.raises(ValueError, match="v_max"):
        two_point(z, np.eye(2), 0.0, z, np.eye(2), 1.0, v_max=0.0)
    with pytest.raises(ValueError, match="t1"):
        two_point(z, np.eye(2), [0.0, 1.0], z, np.eye(2), 2.0, v_max=1.0)
    with pytest.raises(ValueError, match="same d"):
        two_point(z, np.eye(2), 0.0, np.zeros((2, 3)), np.eye(3), 1.0, v_max=1.0)


# ------------------------------------------------------------------------------------------
# Converted measurements
#
# Statistics: N = 200 000 draws per case with fixed seeds. Each covariance element is
# compared with 5 standard errors of its sample mean (the standard error estimated from the
# draws themselves, so no Gaussian assumption on the converted error): a false failure has
# probability about 6e-7 per element. The mean is tested with N e_bar^T Sigma^-1 e_bar
# against the chi-square(2) quantile at 1 - 1e-6 (27.6).

N_MC = 200_000
Z_TOL = 5.0
CHI2_MEAN = chi2.ppf(1 - 1e-6, 2)

# (range, sigma_range, sigma_bearing, bearing): r s_t^2 / s_r = 2.4, 18 and 9 -- all far
# above Lerro & Bar-Shalom's 0.4, where the plain conversion is biased.
REGIMES = [
    (20e3, 10.0, np.deg2rad(2.0), 0.7),
    (10e3, 50.0, 0.3, -2.5),
    (50e3, 5.0, np.deg2rad(1.0), 3.0),
]


def _second_moment_matches(e, R, u):
    """Whether E[e e^T] (sample) equals R within Z_TOL standard errors, per element, in the
    down-range / cross-range frame of the unit vector ``u`` (there the small range variance
    is an element of its own, not a sliver of the large cross-range one)."""
    Q = np.array([[u[0], -u[1]], [u[1], u[0]]])
    e, R = e @ Q, Q.T @ R @ Q
    for i, j in [(0, 0), (1, 1), (0, 1)]:
        prod = e[:, i] * e[:, j]
        se = prod.std(ddof=1) / np.sqrt(len(e))
        if abs(prod.mean() - R[i, j]) > Z_TOL * se:
            return False
    return True


def _mean_stat(e):
    m = e.mean(0)
    return len(e) * m @ np.linalg.solve(np.cov(e.T), m)


@pytest.mark.parametrize("convention", ["nautical", "math"])
@pytest.mark.parametrize("r, sr, st, theta", REGIMES)
def test_converted_unbiased_given_truth(r, sr, st, theta, convention):
    """Fixed truth, noisy plots: the unbiased conversion has zero mean error and the sample
    covariance of its error is ``converted_cov_given_truth``; the plain (linearised)
    conversion is detectably biased and its covariance does not match."""
    sensor = tk.models.RangeBearing(origin=[300.0, -200.0], sigma_range=sr, sigma_bearing=st,
                                    convention=convention)
    rng = np.random.default_rng([int(r), len(convention)])
    a, b = (np.sin(theta), np.cos(theta)) if convention == "nautical" else (
        np.cos(theta), np.sin(theta))
    p = sensor.origin + r * np.array([a, b])
    assert np.allclose(sensor.h(p[None]), [[r, theta]])  # the truth is where we think
    z = np.column_stack([r + sr * rng.standard_normal(N_MC),
                         theta + st * rng.standard_normal(N_MC)])
    pu, _ = convert_range_bearing(z, sensor)
    e = pu - p
    assert _mean_stat(e) < CHI2_MEAN
    Rt = converted_cov_given_truth(r, theta, sensor)
    assert _second_moment_matches(e, Rt, [a, b])

    pl, _ = convert_range_bearing(z, sensor, method="linearized")
    assert _mean_stat(pl - p) > 10 * CHI2_MEAN
    _, Rlin = convert_range_bearing(np.array([r, theta]), sensor, method="linearized")
    assert not _second_moment_matches(pu - p, Rlin, [a, b])


@pytest.mark.parametrize("convention", ["nautical", "math"])
@pytest.mark.parametrize("r, sr, st, theta", REGIMES)
def test_converted_covariance_given_measurement(r, sr, st, theta, convention):
    """Fixed plot z = (r_m, theta_m), truth drawn from it (flat prior: r = r_m - v,
    theta = theta_m - w): the sample E[(p_u - p)(p_u - p)^T] is the R_u that
    ``convert_range_bearing`` returns (Mo et al. 1998, the covariance given the plot)."""
    sensor = tk.models.RangeBearing(sigma_range=sr, sigma_bearing=st, convention=convention)
    rng = np.random.default_rng([int(r), len(convention), 1])
    pu, Ru = convert_range_bearing(np.array([r, theta]), sensor)
    rt = r - sr * rng.standard_normal(N_MC)
    tt = theta - st * rng.standard_normal(N_MC)
    a, b = (np.sin(tt), np.cos(tt)) if convention == "nautical" else (np.cos(tt), np.sin(tt))
    e = pu - rt[:, None] * np.column_stack([a, b])
    assert _second_moment_matches(e, Ru, pu / np.linalg.norm(pu))


def test_converted_small_bearing_error_agrees_with_linearised():
    """At small sigma_theta (r s_t^2 / s_r = 1e-3) the unbiased conversion and covariance
    agree with the linearised ones (the difference is O(s_t^2) relative)."""
    sensor = tk.models.RangeBearing(origin=[10.0, 20.0], sigma_range=10.0, sigma_bearing=1e-3)
    rng = np.random.default_rng(0)
    z = np.column_stack([rng.uniform(1e3, 1e4, 50), rng.uniform(-np.pi, np.pi, 50)])
    pu, Ru = convert_range_bearing(z, sensor)
    pl, Rl = convert_range_bearing(z, sensor, method="linearized")
    assert np.max(np.linalg.norm(pu - pl, axis=-1) / z[:, 0]) < 1e-6
    rel = np.linalg.norm(Ru - Rl, axis=(-1, -2)) / np.linalg.norm(Rl, axis=(-1, -2))
    assert rel.max() < 1e-4
    Rt = converted_cov_given_truth(z[:, 0], z[:, 1], sensor)
    rel_t = np.linalg.norm(Rt - Rl, axis=(-1, -2)) / np.linalg.norm(Rl, axis=(-1, -2))
    assert rel_t.max() < 1e-4
    # the linearised conversion inverts the sensor model exactly
    assert np.allclose(sensor.h(pl), z, rtol=1e-12, atol=1e-12)


def test_converted_conventions_and_batch():
    """Nautical (r, theta) converts like math (r, pi/2 - theta); batch axes pass through,
    covariances are symmetric positive definite."""
    rng = np.random.default_rng(5)
    z = np.stack([rng.uniform(1e3, 5e4, (4, 3)), rng.uniform(-np.pi, np.pi, (4, 3))], -1)
    naut = tk.models.RangeBearing(sigma_range=20.0, sigma_bearing=0.05)
    math = tk.models.RangeBearing(sigma_range=20.0, sigma_bearing=0.05, convention="math")
    zm = z.copy()
    zm[..., 1] = np.pi / 2 - z[..., 1]
    for method in ("unbiased", "linearized"):
        pn, Rn = convert_range_bearing(z, naut, method)
        pm, Rm = convert_range_bearing(zm, math, method)
        assert pn.shape == (4, 3, 2) and Rn.shape == (4, 3, 2, 2)
        assert np.allclose(pn, pm, rtol=1e-12) and np.allclose(Rn, Rm, rtol=1e-9)
        tk.check_gaussian(pn, Rn)
        assert np.all(np.linalg.eigvalsh(Rn) > 0)


def test_converted_feeds_single_point():
    sensor = tk.models.RangeBearing(sigma_range=10.0, sigma_bearing=np.deg2rad(1.0))
    pos, R = convert_range_bearing(np.array([[5e3, 0.3], [8e3, 2.0]]), sensor)
    b = single_point(pos, R, v_max=15.0)
    assert b.mean.shape == (2, 4) and np.array_equal(b.cov[:, :2, :2], R)


def test_converted_bad_input():
    sensor = tk.models.RangeBearing()
    with pytest.raises(ValueError, match="method"):
        convert_range_bearing(np.array([1.0, 0.0]), sensor, method="debiased")
    with pytest.raises(ValueError, match="sensor"):
        convert_range_bearing(np.array([1.0, 0.0]), tk.models.Position(dim=2))
    with pytest.raises(ValueError, match="z"):
        convert_range_bearing(np.array([1.0, 0.0, 3.0]), sensor)
