"""Resamplers, weights and kernel moves (trackkit.filters.resample).

Statistical tests use fixed seeds, so they are deterministic; each states the confidence it
would have with a fresh seed. Expected offspring moments are computed here from the weights
by the textbook formulas (independently of the code under test): E o_i = n w_i and

* multinomial: Var o_i = n w_i (1 - w_i);
* residual: Var o_i = n_r p_i (1 - p_i), p_i = frac(n w_i) / n_r, n_r = n - sum floor(n w_i);
* systematic: Var o_i = f (1 - f), f = frac(n w_i);
* stratified: Var o_i = sum_k p_ik (1 - p_ik), p_ik = n |I_i cap [k/n, (k+1)/n)|.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackkit.angles import wrap
from trackkit.filters import resample as rs
from trackkit.linalg import psd_factor

NAMES = ["systematic", "stratified", "residual", "multinomial"]


def counts_of(idx: np.ndarray, N: int) -> np.ndarray:
    """Offspring counts ``(..., N)`` from ancestor indices ``(..., n)`` (bincount per row)."""
    flat = idx.reshape(-1, idx.shape[-1])
    rows = flat.shape[0]
    c = np.bincount((flat + N * np.arange(rows)[:, None]).ravel(), minlength=rows * N)
    return c.reshape(idx.shape[:-1] + (N,))


def stratum_probabilities(w: np.ndarray, n: int) -> np.ndarray:
    """``p[i, k]``: the chance that stratum k's point falls in particle i's interval."""
    c = np.concatenate([[0.0], np.cumsum(w)])
    c /= c[-1]
    k = np.arange(n)
    lo = np.maximum(c[:-1, None], k / n)
    hi = np.minimum(c[1:, None], (k + 1) / n)
    return n * np.clip(hi - lo, 0.0, None)


def expected_moments(name: str, w: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    nw = n * w
    if name == "multinomial":
        return nw, n * w * (1 - w)
    if name == "residual":
        f = nw - np.floor(nw)
        n_r = n - np.floor(nw).sum()
        p = f / f.sum()
        return nw, n_r * p * (1 - p)
    if name == "systematic":
        f = nw - np.floor(nw)
        return nw, f * (1 - f)
    p = stratum_probabilities(w, n)
    return nw, (p * (1 - p)).sum(1)


# weights with large, moderate, tiny and zero entries; n w has assorted fractional parts
W8 = np.array([0.31, 0.02, 0.17, 0.0, 0.005, 0.145, 0.23, 0.12])


@pytest.mark.parametrize("n", [8, 13])
@pytest.mark.parametrize("name", NAMES)
def test_offspring_counts_have_the_expected_mean_and_variance(name, n):
    """Mean and variance of every particle's offspring count over R = 40 000 independent
    resamplings (rows of one batched call), against the formulas of the module docstring.

    z-scores use the sample's own standard errors (for the variance, sqrt((m4 - s^4) / R));
    with |z| < 4.5 per check, a fresh seed would fail one of the 128 checks of this test
    with probability below 1e-3.
    """
    R = 40_000
    w = W8 / W8.sum()
    idx = rs.RESAMPLERS[name](np.tile(w, (R, 1)), np.random.default_rng(11), n)
    assert idx.shape == (R, n)
    o = counts_of(idx, w.size).astype(float)
    assert (o.sum(1) == n).all()
    mean_exp, var_exp = expected_moments(name, w, n)
    mean = o.mean(0)
    dev = o - mean
    var = (dev**2).mean(0)
    m4 = (dev**4).mean(0)
    se_mean = np.sqrt(var / R)
    se_var = np.sqrt(np.maximum(m4 - var**2, 0) / R)
    live = var_exp > 0
    assert np.all(np.abs(mean - mean_exp)[live] <= 4.5 * se_mean[live]), (mean, mean_exp)
    assert np.all(np.abs(var - var_exp)[live] <= 4.5 * se_var[live]), (var, var_exp)
    # a deterministic count (variance 0) must be exactly its mean in every row
    for i in np.flatnonzero(~live):
        assert np.all(o[:, i] == mean_exp[i])


@pytest.mark.parametrize("name", NAMES)
def test_indices_sorted_sum_and_batch_axes(name):
    rng = np.random.default_rng(2)
    w = rng.dirichlet(np.ones(7), size=(2, 3))
    idx = rs.RESAMPLERS[name](w, np.random.default_rng(0), 5)
    assert idx.shape == (2, 3, 5) and idx.dtype == np.intp
    assert np.all(np.diff(idx, axis=-1) >= 0)
    assert idx.min() >= 0 and idx.max() < 7
    # a zero-weight particle never has offspring
    w0 = w.copy()
    w0[..., 2] = 0.0
    w0 /= w0.sum(-1, keepdims=True)
    assert not np.any(rs.RESAMPLERS[name](w0, np.random.default_rng(0)) == 2)
    # one row: no batch axes
    assert rs.RESAMPLERS[name](w[0, 0], np.random.default_rng(0)).shape == (7,)


def test_systematic_counts_are_floor_or_ceil_of_n_w():
    """The defining property of systematic resampling, on 20 000 random weight rows."""
    rng = np.random.default_rng(3)
    for n in (50, 37):
        w = rng.dirichlet(np.full(50, 0.3), size=20_000)
        o = counts_of(rs.systematic(w, np.random.default_rng(4), n), 50)
        nw = n * w
        assert np.all((o == np.floor(nw)) | (o == np.ceil(nw)))


def test_keep_guarantees_systematic_residual_and_stratified():
    """Systematic and residual keep every particle with w > 1/N (residual: w >= 1/N);
    stratified every particle with w >= 2/N. Checked on 20 000 random rows whose weights
    cluster around 1/N and 2/N (a margin of 1e-12 keeps rounding of the cumulative sums out
    of the claim)."""
    rng = np.random.default_rng(5)
    N = 20
    w = rng.dirichlet(np.full(N, 3.0), size=20_000)
    above1 = w > (1 + 1e-12) / N
    above2 = w >= (2 + 1e-12) / N
    assert above1.sum() > 100_000 and above2.sum() > 1_000  # the claims are exercised
    o_sys = counts_of(rs.systematic(w, np.random.default_rng(6)), N)
    o_res = counts_of(rs.residual(w, np.random.default_rng(6)), N)
    o_str = counts_of(rs.stratified(w, np.random.default_rng(6)), N)
    assert np.all(o_sys[above1] >= 1)
    assert np.all(o_res[above1] >= 1)
    assert np.all(o_str[above2] >= 1)
    # ... while stratified does lose particles with 1/N < w < 2/N now and then
    between = above1 & ~above2
    lost = (o_str == 0) & between
    assert lost.sum() > 0


@pytest.mark.parametrize("weights, i, p_exact", [
    # particle 1 owns [1/8, 7/16): half of stratum 0 and three quarters of stratum 1
    ([0.125, 0.3125, 0.5625], 1, 0.5 * 0.25),
    # a weight just above 1/4 centred on the boundary 1/4: the worst case, ~(1 - 1/2)^2
    ([0.124875, 0.25025, 0.624875], 1, (1 - 0.5005) ** 2),
])
def test_stratified_loses_a_particle_above_one_over_n(weights, i, p_exact):
    """The claim that stratified resampling keeps every particle with w > 1/N is false: an
    interval of length in (1/N, 2/N) straddling a stratum boundary is missed when neither
    stratum's point falls in it, with probability (1 - a)(1 - b) (a, b its shares of the two
    strata, in units of 1/N). N = n = 4; 200 000 resamplings; the empirical frequency must
    be within 4.5 standard errors of the exact probability (fails with a fresh seed with
    probability ~7e-6). Systematic resampling never loses it."""
    w = np.asarray(weights)
    n, R = 4, 200_000  # n offspring from these 3 particles: strata of width 1/4
    assert w[i] > 1 / n
    p = stratum_probabilities(w, n)[i]
    assert math.isclose(np.prod(1 - p), p_exact, rel_tol=1e-12)
    o = counts_of(rs.stratified(np.tile(w, (R, 1)), np.random.default_rng(7), n), w.size)
    freq = np.mean(o[:, i] == 0)
    se = math.sqrt(p_exact * (1 - p_exact) / R)
    assert abs(freq - p_exact) <= 4.5 * se, (freq, p_exact)
    o_sys = counts_of(rs.systematic(np.tile(w, (R, 1)), np.random.default_rng(7), n), w.size)
    assert np.all(o_sys[:, i] >= 1)


def test_systematic_and_stratified_points_follow_the_draws():
    """Given the uniforms, the ancestors are those of an explicit search of the points
    u_k = (k + U) / n (systematic) or (k + U_k) / n (stratified) in the cumulative weights."""
    rng = np.random.default_rng(8)
    w = rng.dirichlet(np.ones(9), size=50)
    c = np.cumsum(w, -1)
    c /= c[:, -1:]
    n = 12
    U = np.random.default_rng(9).random(50)
    points = (np.arange(n) + U[:, None]) / n
    want = np.stack([np.searchsorted(c[r], points[r], side="right") for r in range(50)])
    assert np.array_equal(rs.systematic(w, np.random.default_rng(9), n), want)
    U = np.random.default_rng(10).random((50, n))
    points = (np.arange(n) + U) / n
    want = np.stack([np.searchsorted(c[r], points[r], side="right") for r in range(50)])
    assert np.array_equal(rs.stratified(w, np.random.default_rng(10), n), want)


def test_log_weights_and_ess():
    lw = np.array([[-1e4, -1e4 - 1.0, -1e4 - 2.0], [0.0, -np.inf, 0.0],
                   [-np.inf, -np.inf, -np.inf]])
    out, L = rs.normalise_log_weights(lw)
    p = np.exp([0.0, -1.0, -2.0])
    # log-weights near -1e4 carry an absolute rounding error of ~1e4 eps = 2e-12, which is
    # the relative error of the weights: 1e-11 here
    np.testing.assert_allclose(np.exp(out[0]), p / p.sum(), rtol=1e-11)
    assert math.isclose(L[0], -1e4 + math.log(p.sum()), rel_tol=1e-15)
    np.testing.assert_array_equal(np.exp(out[1]), [0.5, 0.0, 0.5])
    assert L[2] == -np.inf and np.all(out[2] == -np.inf)  # reported, not nan
    ess = rs.effective_sample_size(out[:2])
    np.testing.assert_allclose(ess, [1 / np.sum((p / p.sum()) ** 2), 2.0], rtol=1e-11)
    N = 1000
    assert math.isclose(rs.effective_sample_size(np.full(N, -math.log(N))), N, rel_tol=1e-12)
    assert math.isclose(rs.effective_sample_size(np.r_[0.0, np.full(9, -np.inf)]), 1.0)
    with pytest.raises(ValueError, match="nan"):
        rs.normalise_log_weights([0.0, np.nan])


def test_weighted_mean_cov_matches_numpy_and_is_circular_on_angles():
    rng = np.random.default_rng(12)
    X = rng.normal([1e3, -2.0, 5.0], [3.0, 0.1, 2.0], size=(4, 300, 3))
    w = rng.dirichlet(np.ones(300), size=4)
    m, P = rs.weighted_mean_cov(X, w)
    for r in range(4):
        np.testing.assert_allclose(m[r], np.average(X[r], axis=0, weights=w[r]), rtol=1e-12)
        np.testing.assert_allclose(P[r], np.cov(X[r].T, aweights=w[r], bias=True),
                                   rtol=1e-10, atol=1e-12 * np.abs(P[r]).max())
        assert np.array_equal(P[r], P[r].T)
    # an angle cloud straddling +-pi: centre pi - 0.05, spread 0.1
    a = np.pi - 0.05 + 0.1 * rng.standard_normal((4, 300))
    Xa = X.copy()
    Xa[..., 2] = (a + np.pi) % (2 * np.pi) - np.pi  # stored wrapped: both signs occur
    assert (Xa[..., 2] > 0).any() and (Xa[..., 2] < 0).any()
    m, P = rs.weighted_mean_cov(Xa, w, angles=(2,))
    s = (w * np.sin(Xa[..., 2])).sum(-1)
    c = (w * np.cos(Xa[..., 2])).sum(-1)
    np.testing.assert_allclose(m[:, 2], np.arctan2(s, c), rtol=1e-12)
    unwrapped = Xa[..., 2] % (2 * np.pi)  # the cloud is contiguous on [0, 2 pi)
    dev = unwrapped - (m[:, 2:] % (2 * np.pi))
    np.testing.assert_allclose(P[:, 2, 2], (w * dev**2).sum(-1), rtol=1e-10)
    np.testing.assert_allclose(m[:, :2], np.einsum("rn,rnj->rj", w, X[..., :2]), rtol=1e-12)


def test_weighted_mean_cov_with_equal_weights():
    """weights=None (equal weights, the fast path after resampling) equals 1/N weights."""
    rng = np.random.default_rng(19)
    X = rng.normal(0.0, 1.0, (3, 40, 3))
    X[..., 2] = wrap(np.pi + 0.1 * X[..., 2])
    for ang in ((), (2,)):
        m0, P0 = rs.weighted_mean_cov(X, np.full((3, 40), 1 / 40), ang)
        m1, P1 = rs.weighted_mean_cov(X, None, ang)
        np.testing.assert_allclose(m1, m0, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(P1, P0, rtol=1e-12, atol=1e-14)


def test_psd_factor_handles_singular_and_refuses_indefinite():
    Q = np.diag([1.0, 0.0, 4.0])
    Q[0, 2] = Q[2, 0] = 1.0
    L = psd_factor(Q, "Q")
    np.testing.assert_allclose(L @ L.T, Q, rtol=0, atol=1e-14)
    stack = np.stack([Q, 2 * Q])
    L = psd_factor(stack, "Q")
    np.testing.assert_allclose(L @ L.mT, stack, rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="Q is not positive semi-definite"):
        psd_factor(np.diag([1.0, -1.0]), "Q")


def test_a_sample_covariance_collapsed_to_a_point_is_factored():
    """A cloud collapsed to within a millimetre has a weighted covariance at the rounding
    level of the offsets its sums are taken about, so a negative eigenvalue of -4e-16 can be
    far more than 1e-10 of its size (1e-6 here). As a user's covariance that is refused; as a
    sample covariance (``sample=True``, which regularisation uses) the negative part is
    rounding and is taken as 0."""
    c, s_ = math.cos(0.3), math.sin(0.3)
    V = np.array([[c, -s_], [s_, c]])
    S = V @ np.diag([-4e-16, 1e-6]) @ V.T
    S = 0.5 * (S + S.T)[None]  # a stack: the eigen-decomposition path
    with pytest.raises(ValueError, match="S is not positive semi-definite"):
        psd_factor(S, "S")
    L = psd_factor(S, "S", sample=True)
    np.testing.assert_allclose(L[0] @ L[0].T, V @ np.diag([0.0, 1e-6]) @ V.T, rtol=0, atol=1e-20)


def test_optimal_bandwidth_value():
    # Musso, Oudjane and Le Gland: A = (4 / (n + 2))^(1 / (n + 4)), h = A N^(-1 / (n + 4))
    assert math.isclose(rs.optimal_bandwidth(1000, 4), (4 / 6) ** 0.125 * 1000 ** -0.125,
                        rel_tol=1e-15)
    assert math.isclose(rs.optimal_bandwidth(1, 1), (4 / 3) ** 0.2, rel_tol=1e-15)


@pytest.mark.parametrize("bandwidth", [None, 0.5])
def test_regularise_keeps_the_mean_and_inflates_the_covariance(bandwidth):
    """E[mean'] = mean and E[cov'] = (1 + h^2 (1 - sum w^2)) cov (-> 1 + h^2 for many equal
    weights), over R = 4 000 rows of N = 50 weighted particles in 3-D.

    The mean shift, whitened by the covariance, averages to 0 with per-component standard
    error sqrt(h^2 sum w^2 / R); the covariance's ratio is checked on its trace (averaged
    over rows, standard error from the sample). |z| < 4.5: a fresh seed fails with
    probability below 3e-5.
    """
    rng = np.random.default_rng(13)
    R, N, n = 4000, 50, 3
    X = rng.normal(0.0, [1.0, 5.0, 0.2], size=(R, N, n))
    X[..., 1] += 0.8 * X[..., 0]
    w = rng.dirichlet(np.full(N, 2.0), size=R)
    m, P = rs.weighted_mean_cov(X, w)
    Y = rs.regularise(X, w, np.random.default_rng(14), bandwidth=bandwidth)
    h = rs.optimal_bandwidth(N, n) if bandwidth is None else bandwidth
    m2, P2 = rs.weighted_mean_cov(Y, w)
    L = np.linalg.cholesky(P)
    u = np.linalg.solve(L, (m2 - m)[..., None])[..., 0]  # ~ N(0, h^2 sum w^2 I)
    sw2 = (w**2).sum(-1)
    z_mean = u.mean(0) / np.sqrt((h**2 * sw2).mean() / R)
    assert np.all(np.abs(z_mean) < 4.5), z_mean
    ratio = np.trace(np.linalg.solve(P, P2), axis1=-2, axis2=-1) / n  # E = 1 + h^2 (1 - sw2)
    expected = 1 + h**2 * (1 - sw2)
    dev = ratio - expected
    assert abs(dev.mean()) < 4.5 * dev.std() / math.sqrt(R), (ratio.mean(), expected.mean())
    # the move is a Gaussian kernel scaled by each row's covariance: whitened jitter ~ N(0, I)
    e = np.linalg.solve(L[:, None], (Y - X)[..., None])[..., 0] / h
    assert abs(e.mean()) < 4.5 / math.sqrt(e.size)
    assert abs(e.var() - 1) < 4.5 * math.sqrt(2 / e.size)


def test_regularise_wraps_angles_and_takes_a_given_covariance():
    rng = np.random.default_rng(15)
    X = np.zeros((2, 1000, 2))
    X[..., 1] = np.pi - 1e-3
    cov = np.diag([4.0, 0.01])
    Y = rs.regularise(X, np.full((2, 1000), 1e-3), rng, bandwidth=1.0, cov=cov, angles=(1,))
    assert np.all(np.abs(Y[..., 1]) <= np.pi) and (Y[..., 1] < 0).any()
    assert abs(Y[..., 0].std() - 2.0) < 0.15


@pytest.mark.parametrize("bandwidth", [None, 0.6])
def test_shrinkage_keeps_the_mean_and_the_covariance(bandwidth):
    """Liu and West: ``m + a (x_i - m) + h D e_i`` with ``a = sqrt(1 - h^2)``. Exactly: with
    the same draws, the shrunk cloud is the plain jittered cloud moved by
    ``(a - 1)(x_i - m)``. In expectation: the weighted mean is kept and the covariance stays
    ``(a^2 + h^2 (1 - sum w^2)) S`` (-> S), where the plain kernel gives
    ``(1 + h^2 (1 - sum w^2)) S``: over R = 4 000 rows of N = 50 weighted particles in 3-D,
    |z| < 4.5 on the trace ratio's mean (a fresh seed fails with probability below 3e-5),
    and the plain kernel's expectation is more than 20 standard errors away at h = 0.6."""
    rng = np.random.default_rng(23)
    R, N, n = 4000, 50, 3
    X = rng.normal(0.0, [1.0, 5.0, 0.2], size=(R, N, n))
    X[..., 1] += 0.8 * X[..., 0]
    w = rng.dirichlet(np.full(N, 2.0), size=R)
    m, P = rs.weighted_mean_cov(X, w)
    h = rs.optimal_bandwidth(N, n) if bandwidth is None else bandwidth
    a = math.sqrt(1 - h**2)
    Y = rs.regularise(X, w, np.random.default_rng(24), bandwidth=bandwidth, shrink=True)
    Yplain = rs.regularise(X, w, np.random.default_rng(24), bandwidth=bandwidth)
    np.testing.assert_allclose(Y, Yplain + (a - 1) * (X - m[:, None, :]), rtol=0, atol=1e-12)
    m2, P2 = rs.weighted_mean_cov(Y, w)
    u = np.linalg.solve(np.linalg.cholesky(P), (m2 - m)[..., None])[..., 0]
    sw2 = (w**2).sum(-1)
    assert np.all(np.abs(u.mean(0) / np.sqrt((h**2 * sw2).mean() / R)) < 4.5)
    ratio = np.trace(np.linalg.solve(P, P2), axis1=-2, axis2=-1) / n
    se = ratio.std() / math.sqrt(R)
    kept = a**2 + h**2 * (1 - sw2)
    assert abs((ratio - kept).mean()) < 4.5 * se, (ratio.mean(), kept.mean())
    if bandwidth is not None:
        assert ((1 + h**2 * (1 - sw2)) - ratio).mean() > 20 * se


def test_shrinkage_pulls_angles_towards_the_circular_mean():
    """A cloud straddling +-pi shrinks towards pi (its circular mean), not towards 0 (its
    arithmetic mean): with a zero covariance (no jitter) every deviation is scaled by
    ``a = sqrt(1 - h^2)`` exactly, on the circle."""
    rng = np.random.default_rng(25)
    A = wrap(np.pi + 0.05 * rng.standard_normal((3, 400, 1)))
    assert (A > 0).any() and (A < 0).any()
    h = 0.6
    Y = rs.regularise(A, np.full((3, 400), 1 / 400), rng, bandwidth=h, cov=np.zeros((3, 1, 1)),
                      angles=(0,), shrink=True)
    m = rs.weighted_mean_cov(A, None, angles=(0,))[0]
    np.testing.assert_allclose(wrap(Y - m[:, None]), 0.8 * wrap(A - m[:, None]), atol=1e-14)
    assert np.all(np.abs(Y) <= np.pi)


def test_roughen_jitter_is_k_range_n_to_minus_one_over_n():
    """sigma_j = K E_j N^(-1/n): the whitened jitter has unit variance per component (R x N
    = 400 000 draws: |z| < 4.5); a component with no spread is not moved."""
    rng = np.random.default_rng(16)
    R, N, n, K = 400, 1000, 3, 0.2
    X = rng.uniform(-1, 1, size=(R, N, n)) * [1.0, 30.0, 0.0]
    Y = rs.roughen(X, np.random.default_rng(17), K)
    E = X.max(-2) - X.min(-2)
    sigma = K * E * N ** (-1 / n)
    e = (Y - X)[..., :2] / sigma[:, None, :2]
    assert np.all(np.abs(e.mean((0, 1))) < 4.5 / math.sqrt(R * N))
    assert np.all(np.abs(e.var((0, 1)) - 1) < 4.5 * math.sqrt(2 / (R * N)))
    assert np.array_equal(Y[..., 2], X[..., 2])
    # an angle cloud straddling +-pi has a small range on the circle (~0.03 here), not ~2 pi
    A = wrap(np.pi + 0.01 * rng.standard_normal((200, 10, 1)))
    assert (A > 0).any() and (A < 0).any()
    moved = rs.roughen(A, np.random.default_rng(18), K, angles=(0,))
    assert np.abs(wrap(moved - A)).max() < 0.01
    assert np.all(np.abs(moved) <= np.pi)


@pytest.mark.parametrize("name", NAMES)
def test_bad_weights_are_refused_with_the_field_named(name):
    f = rs.RESAMPLERS[name]
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="weights sum to 0.9"):
        f([0.5, 0.4], rng)
    with pytest.raises(ValueError, match="negative or not finite"):
        f([1.5, -0.5], rng)
    with pytest.raises(ValueError, match="negative or not finite"):
        f([np.nan, 1.0], rng)
    with pytest.raises(ValueError, match=r"n = 0; expected an integer >= 1"):
        f([0.5, 0.5], rng, 0)
    with pytest.raises(ValueError, match=r"weights has shape \(\)"):
        f(1.0, rng)


def test_bad_moves_are_refused():
    X = np.zeros((10, 2))
    w = np.full(10, 0.1)
    with pytest.raises(ValueError, match="bandwidth = -1"):
        rs.regularise(X, w, None, bandwidth=-1.0)
    with pytest.raises(ValueError, match="bandwidth = 1.0 with shrink; expected a value below 1"):
        rs.regularise(X, w, None, bandwidth=1.0, shrink=True)
    with pytest.raises(ValueError, match="K = nan"):
        rs.roughen(X, None, float("nan"))
    with pytest.raises(ValueError, match=r"angles = \(2,\)"):
        rs.weighted_mean_cov(X, w, angles=(2,))
    with pytest.raises(ValueError, match=r"states \(10, 2\) and weights \(9,\)"):
        rs.weighted_mean_cov(X, w[:9])
