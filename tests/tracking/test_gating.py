"""Gating: hand-computed cases, angles across the +-pi cut, and the KD-tree pre-gate against
the brute-force gate (bit-for-bit, on both sides of the switch-over threshold)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

import trackkit as tk
from trackkit.tracking import gating
from trackkit.tracking.gating import (
    KDTREE_MIN_PAIRS,
    gate,
    gate_threshold,
    predict_measurement,
)


def _same(a, b):
    for name in ("track", "det", "d2", "loglik", "nu"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert (a.n_tracks, a.n_dets, a.threshold) == (b.n_tracks, b.n_dets, b.threshold)


def test_hand_computed():
    S = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    z = np.array([[2.0, 0.0], [0.0, 1.0], [4.0, 0.0], [3.0, 3.0], [-1.0, -2.0]])
    g = gate(np.zeros((1, 2)), S, z, 0.99)
    assert g.threshold == chi2.ppf(0.99, 2)  # 9.21
    np.testing.assert_array_equal(g.det, [0, 1, 2, 4])  # d2 = 1, 1, 4, 11.25 (out), 4.25
    np.testing.assert_array_equal(g.track, [0, 0, 0, 0])
    np.testing.assert_allclose(g.d2, [1.0, 1.0, 4.0, 4.25], rtol=1e-15)
    logdet = np.log(np.linalg.det(2 * np.pi * S[0]))  # log det(2 pi S) = log(4 (2 pi)^2)
    np.testing.assert_allclose(g.loglik, -0.5 * (g.d2 + logdet), rtol=1e-14)
    np.testing.assert_array_equal(g.nu, z[[0, 1, 2, 4]])
    # the likelihood is the Gaussian density
    from scipy.stats import multivariate_normal
    np.testing.assert_allclose(np.exp(g.loglik),
                               multivariate_normal(np.zeros(2), S[0]).pdf(z[[0, 1, 2, 4]]),
                               rtol=1e-13)
    with pytest.raises(AttributeError, match="Gate.residual is now spelled Gate.nu"):
        _ = g.residual
    with pytest.raises(AttributeError, match="Innovation.residual is now spelled Innovation.nu"):
        _ = tk.Innovation(g.nu, S).residual


def test_take_keeps_the_pairs_asked_for():
    S = np.array([[[4.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]]])
    z = np.array([[2.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    g = gate(np.zeros((2, 2)), S, z, 0.99)
    keep = np.array([k % 2 == 0 for k in range(g.size)])
    sub = g.take(keep)
    for name in ("track", "det", "d2", "loglik", "nu"):
        np.testing.assert_array_equal(getattr(sub, name), getattr(g, name)[keep])
    assert (sub.n_tracks, sub.n_dets, sub.threshold) == (g.n_tracks, g.n_dets, g.threshold)
    _same(g.take(np.arange(g.size)), g)


def test_correlated_S_and_threshold():
    S = np.array([[[2.0, 1.0], [1.0, 2.0]]])
    z = np.array([[1.0, 1.0], [1.0, -1.0]])  # d2 = 2/3 and 2
    g = gate(np.zeros((1, 2)), S, z, threshold=1.0)
    np.testing.assert_array_equal(g.det, [0])
    np.testing.assert_allclose(g.d2, [2.0 / 3.0], rtol=1e-15)
    assert gate(np.zeros((1, 2)), S, z, threshold=2.0).size == 2  # boundary included


@pytest.mark.parametrize("method", ["brute", "kdtree"])
def test_bearing_across_the_cut(method):
    """A bearing of pi - 0.01 and a detection at -pi + 0.01 are 0.02 apart, not 2 pi - 0.02."""
    zhat = np.array([[np.pi - 0.01], [0.0], [-np.pi + 0.005]])
    S = np.full((3, 1, 1), 0.01**2)
    z = np.array([[-np.pi + 0.01], [0.01], [np.pi - 0.005], [1.0]])
    g = gate(zhat, S, z, 0.99, angular=[True], method=method)
    np.testing.assert_array_equal(g.track, [0, 0, 1, 2, 2])
    np.testing.assert_array_equal(g.det, [0, 2, 1, 0, 2])
    np.testing.assert_allclose(g.nu[:, 0], [0.02, 0.005, 0.01, 0.005, -0.01], atol=1e-12)
    np.testing.assert_allclose(g.d2, (g.nu[:, 0] / 0.01) ** 2, rtol=1e-9)


def test_unwrapped_angles_in_input():
    """zhat and z given outside (-pi, pi] (e.g. 3 pi) gate as their wrapped values."""
    zhat = np.array([[3 * np.pi - 0.01, 100.0]])
    S = np.array([np.diag([0.01**2, 1.0])])
    z = np.array([[-np.pi + 0.01, 100.5], [np.pi - 0.02, 101.0], [0.0, 100.0]])
    for method in ("brute", "kdtree"):
        g = gate(zhat, S, z, 0.99, angular=[True, False], method=method)
        np.testing.assert_array_equal(g.det, [0, 1])


def test_empty_inputs():
    g = gate(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.ones((3, 2)))
    assert g.size == 0 and g.n_tracks == 0 and g.n_dets == 3 and g.nu.shape == (0, 2)
    g = gate(np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1)), np.zeros((0, 2)))
    assert g.size == 0 and g.n_dets == 0
    g = gate(np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1)), [], method="kdtree")
    assert g.size == 0


@pytest.mark.parametrize("args,match", [
    ((np.zeros(2), np.eye(2)[None], np.zeros((1, 2))), "zhat"),
    ((np.zeros((1, 2)), np.eye(2), np.zeros((1, 2))), "S has shape"),
    ((np.zeros((1, 2)), np.eye(2)[None], np.zeros((1, 3))), "z has shape"),
    ((np.zeros((1, 2)), np.eye(2)[None], np.full((1, 2), np.nan)), "z has non-finite"),
    ((np.zeros((1, 2)), -np.eye(2)[None], np.zeros((1, 2))), "innovation covariance S"),
])
def test_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        gate(*args)


def test_bad_options():
    args = (np.zeros((1, 2)), np.eye(2)[None], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="p_gate"):
        gate(*args, p_gate=1.0)
    with pytest.raises(ValueError, match="angular"):
        gate(*args, angular=[True])
    with pytest.raises(ValueError, match="method"):
        gate(*args, method="fast")
    with pytest.raises(ValueError, match="threshold"):
        gate(*args, threshold=-1.0)


def test_gate_threshold():
    assert gate_threshold(0.95, 1) == pytest.approx(3.841458820694124, rel=1e-12)
    assert gate_threshold(0.99, 2) == pytest.approx(9.210340371976182, rel=1e-12)


def test_predict_measurement_matches_the_filter():
    rng = np.random.default_rng(0)
    b = tk.Gaussian(np.column_stack([rng.uniform(1e3, 5e3, (6, 2)), rng.normal(0, 5, (6, 2))]),
                    np.tile(np.diag([100.0, 200.0, 4.0, 4.0]), (6, 1, 1)))
    sensor = tk.models.RangeBearing(sigma_range=10.0, sigma_bearing=0.01)
    mp = predict_measurement(b, sensor)
    z = sensor.h(b.mean) + 1.0
    post, innov = tk.filters.EKF().update(b, z, sensor)
    np.testing.assert_allclose(mp.S, innov.cov, rtol=1e-12)
    np.testing.assert_allclose(mp.zhat, sensor.h(b.mean), rtol=1e-15)
    # the gain maps the innovation to the filter's update
    np.testing.assert_allclose(b.mean + (mp.K @ innov.nu[..., None])[..., 0], post.mean,
                               rtol=1e-12)


# -- brute force against the KD-tree ------------------------------------------------------------


def _random_problem(rng, T, D, m, angular, spread, cond):
    zhat = rng.uniform(-spread, spread, (T, m))
    A = rng.standard_normal((T, m, m))
    S = A @ A.mT + np.eye(m) / cond
    S *= rng.uniform(0.1, 10.0, (T, 1, 1))
    z = rng.uniform(-spread, spread, (D, m))
    # some detections near tracks, so that gates are not empty
    k = min(D, T)
    z[:k] = zhat[rng.integers(0, T, k)] + rng.standard_normal((k, m)) * 1.5
    ang = np.asarray(angular, dtype=bool)
    if ang.any():
        # angles on the circle, scaled so that gates are a fraction of it, some near the cut
        zhat[:, ang] = rng.uniform(-np.pi, np.pi, (T, int(ang.sum())))
        z[:, ang] = rng.uniform(-np.pi, np.pi, (D, int(ang.sum())))
        z[:k, ang] = zhat[rng.integers(0, T, k)][:, ang] + 2 * np.pi * rng.integers(-1, 2, (k, 1))
        z[:k, ang] += rng.normal(0, 0.05, (k, int(ang.sum())))
        near = rng.uniform(size=T) < 0.3
        zhat[np.ix_(near, ang)] = np.pi - rng.uniform(0, 0.05, (int(near.sum()), int(ang.sum())))
        sc = np.ones(m)
        sc[ang] = rng.choice([0.001, 0.05, 1.0])  # tight, medium, whole-circle gates
        S = S * sc[:, None] * sc[None, :]
    return zhat, S, z, ang


@settings(max_examples=120, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), T=st.integers(1, 40), D=st.integers(0, 60),
       angular=st.sampled_from([(False,), (True,), (False, False), (False, True),
                                (True, False, True), (False, False, False), (True, True)]),
       spread=st.sampled_from([3.0, 30.0, 300.0]), p_gate=st.sampled_from([0.5, 0.99, 0.9999]))
def test_kdtree_equals_brute_force(seed, T, D, angular, spread, p_gate):
    rng = np.random.default_rng(seed)
    zhat, S, z, ang = _random_problem(rng, T, D, len(angular), angular, spread, 1e3)
    a = gate(zhat, S, z, p_gate, angular=ang, method="brute")
    b = gate(zhat, S, z, p_gate, angular=ang, method="kdtree")
    _same(a, b)
    # and against a direct evaluation of every pair
    nu = z[None, :, :] - zhat[:, None, :]
    nu[..., ang] = tk.angles.wrap(nu[..., ang])
    d2 = np.einsum("tdi,tij,tdj->td", nu, np.linalg.inv(S), nu)
    inside = d2 <= a.threshold
    # pairs within rounding of the boundary may go either way; all others must agree
    clear = np.abs(d2 - a.threshold) > 1e-9 * a.threshold
    got = np.zeros((T, D), dtype=bool)
    got[a.track, a.det] = True
    assert np.array_equal(got[clear], inside[clear])
    np.testing.assert_allclose(a.d2, d2[a.track, a.det], rtol=1e-8)


def test_kdtree_finds_pairs_across_the_cut_in_a_big_scene():
    """Many tracks on the cut, bearing with range: the tree path must see both sides."""
    rng = np.random.default_rng(3)
    T, D = 400, 500
    zhat = np.column_stack([rng.uniform(0, 5e4, T), np.pi - rng.uniform(0, 0.01, T)])
    zhat[::2, 1] *= -1
    S = np.tile(np.diag([50.0**2, 0.005**2]), (T, 1, 1))
    z = np.column_stack([zhat[:, 0] + rng.normal(0, 50, T), zhat[:, 1] + rng.normal(0, 0.005, T)])
    z = np.concatenate([z, np.column_stack([rng.uniform(0, 5e4, D - T),
                                            rng.uniform(-np.pi, np.pi, D - T)])])
    z[:, 1] = tk.angles.wrap(z[:, 1])
    a = gate(zhat, S, z, 0.999, angular=[False, True], method="brute")
    b = gate(zhat, S, z, 0.999, angular=[False, True], method="kdtree")
    _same(a, b)
    crossing = np.abs(z[a.det, 1] - zhat[a.track, 1]) > np.pi
    assert crossing.sum() > 20


@pytest.mark.parametrize("extra", [-1, 0, 1, 500])
def test_auto_switches_at_the_threshold(monkeypatch, extra):
    """``auto`` uses brute force up to KDTREE_MIN_PAIRS pairs and the tree above; both sides
    give the same gate, bit for bit."""
    rng = np.random.default_rng(extra + 10)
    T = 100
    D = KDTREE_MIN_PAIRS // T + (extra if extra != 500 else 5)
    if extra == 0:
        assert T * D == KDTREE_MIN_PAIRS
    zhat, S, z, ang = _random_problem(rng, T, D, 2, (False, True), 300.0, 1e3)
    calls = []
    real = gating._candidates_kdtree
    monkeypatch.setattr(gating, "_candidates_kdtree",
                        lambda *a: calls.append(1) or real(*a))
    auto = gate(zhat, S, z, angular=ang)
    assert bool(calls) == (T * D > KDTREE_MIN_PAIRS)
    _same(auto, gate(zhat, S, z, angular=ang, method="brute"))
    _same(auto, gate(zhat, S, z, angular=ang, method="kdtree"))
