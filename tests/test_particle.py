"""The bootstrap particle filter and its belief (tk.Particles, trackkit.filters.particle).

Expected values are computed here independently of the code under test (numpy's Cholesky,
scipy's multivariate normal log-density, explicit loops over rows); tolerances are 1e-12
relative for deterministic maths. Oracle comparisons with Stone Soup are in
tests/oracles/test_pf_stonesoup.py, the convergence to the Kalman filter in
tests/statistical/test_pf_convergence.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

import trackkit as tk
from trackkit.angles import wrap
from trackkit.belief import Particles
from trackkit.filters import resample as rs
from trackkit.filters.particle import PF, log_likelihood
from trackkit.filters.run import run_filter

CV = tk.models.ConstantVelocity(dim=2, q=0.5)
POS = tk.models.Position(dim=2, sigma=[2.0, 3.0])


def prior(batch=(3,), mean=(0.0, 0.0, 1.0, -1.0), std=(5.0, 5.0, 1.0, 1.0)):
    m = np.broadcast_to(np.asarray(mean, dtype=float), batch + (4,)).copy()
    P = np.broadcast_to(np.diag(np.square(std)), batch + (4, 4)).copy()
    return tk.Gaussian(m, P)


def particles(batch=(3,), N=200, seed=0, n=4):
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 3.0, batch + (N, n))
    lw = np.log(rng.dirichlet(np.ones(N), size=batch))
    return Particles(X, lw, np.random.default_rng(seed + 1))


# --------------------------------------------------------------------------------------------
# The belief
# --------------------------------------------------------------------------------------------


def test_particles_properties_at_and_make():
    b = particles(batch=(2, 3), N=50)
    assert (b.dim, b.n_particles, b.batch_shape) == (4, 50, (2, 3))
    np.testing.assert_allclose(b.weights.sum(-1), 1.0, rtol=1e-12)
    row = b.at((1, 2))
    assert row.states.shape == (50, 4) and row.rng is b.rng and row.lost is None
    assert np.array_equal(row.log_weights, b.log_weights[1, 2])
    assert b.at(0).batch_shape == (3,)
    with pytest.raises(IndexError):
        b.at((0, 0, 0))  # would index the particles, not a batch axis
    short = Particles._make((b.states, b.log_weights))
    assert short.rng is None and short.lost is None
    assert b._replace(lost=np.zeros((2, 3), dtype=np.int64)).lost.shape == (2, 3)


def test_particles_construction_errors_name_the_field():
    X = np.zeros((2, 5, 4))
    lw = np.full((2, 5), -math.log(5))
    with pytest.raises(ValueError, match=r"Particles.states has shape \(5,\)"):
        Particles(np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match=r"Particles.log_weights has shape \(2, 4\)"):
        Particles(X, lw[:, :4])
    bad = X.copy()
    bad[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match=r"Particles.states has a non-finite entry \(nan at "
                                         r"index \(1, 2, 3\)\)"):
        Particles(bad, lw)
    with pytest.raises(ValueError, match="not normalised: logsumexp over the particles is "
                                         "0.693147 in row"):
        Particles(X, lw + math.log(2))
    with pytest.raises(ValueError, match="log_weights has an entry nan"):
        Particles(X, np.where(np.arange(5) == 1, np.nan, lw))
    with pytest.raises(ValueError, match="Particles.rng is a int"):
        Particles(X, lw, 3)
    with pytest.raises(ValueError, match=r"Particles.lost has shape \(3,\)"):
        Particles(X, lw, None, np.zeros(3, dtype=int))
    # a particle of weight 0 is fine; a row of them is not normalised
    ok = Particles(X, [[-math.log(2)] * 2 + [-np.inf] * 3, [-math.log(5)] * 5])
    assert ok.log_weights[0, 2] == -np.inf


# --------------------------------------------------------------------------------------------
# init and predict
# --------------------------------------------------------------------------------------------


def test_init_samples_the_prior_with_several_batch_axes():
    """Particles are drawn from N(m, P) per row: the sample moments over 4 000 particles x 6
    rows agree with the prior within 5 standard errors; a singular prior (a component with
    zero variance) is sampled without error, that component exactly at its mean."""
    g = prior(batch=(2, 3))
    b = PF(4000).init(g, rng=np.random.default_rng(1))
    assert b.states.shape == (2, 3, 4000, 4) and b.log_weights.shape == (2, 3, 4000)
    np.testing.assert_allclose(b.log_weights, -math.log(4000), rtol=1e-15)
    assert isinstance(b.rng, np.random.Generator)
    m = b.states.mean(-2)
    sd = np.sqrt(np.diag(g.cov[0, 0]))
    assert np.all(np.abs(m - g.mean) < 5 * sd / math.sqrt(4000))
    var = b.states.var(-2)
    assert np.all(np.abs(var / sd**2 - 1) < 5 * math.sqrt(2 / 4000))
    P = np.diag([4.0, 0.0, 1.0, 1.0])
    b = PF(100).init(tk.Gaussian([1.0, 2.0, 3.0, 4.0], P), rng=np.random.default_rng(2))
    assert b.states.shape == (100, 4) and np.all(b.states[:, 1] == 2.0)


def test_init_takes_particles_and_keeps_or_replaces_the_generator():
    b = particles()
    f = PF(10)
    same = f.init(b)
    assert same.rng is b.rng and same.states is b.states
    g = np.random.default_rng(9)
    assert f.init(b, rng=g).rng is g
    assert isinstance(f.init(Particles._make((b.states, b.log_weights))).rng,
                      np.random.Generator)


def test_predict_is_f_plus_a_square_root_of_q_times_the_generators_normals():
    """x' = F x + L e with L = chol(Q) and e the generator's next standard normals."""
    b = particles(batch=(2, 3), N=40)
    seed_state = np.random.default_rng(5)
    b = b._replace(rng=seed_state)
    e = np.random.default_rng(5).standard_normal(b.states.shape)
    out = PF().predict(b, CV, 2.0)
    F, Q = CV.jacobian(None, 2.0), CV.noise(None, 2.0)
    want = b.states @ F.T + e @ np.linalg.cholesky(Q).T
    np.testing.assert_allclose(out.states, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert out.log_weights is b.log_weights and out.rng is seed_state
    assert not np.shares_memory(out.states, b.states)


def test_predict_with_a_singular_q_and_per_row_steps():
    """A coordinated turn with no turn-rate noise has a singular Q: the turn rate is carried
    unchanged. With one step per batch row, each row moves by its own dt (checked with
    q = 0 against the model row by row)."""
    ct = tk.models.CoordinatedTurn(q=0.1, q_omega=0.0)
    rng = np.random.default_rng(3)
    X = np.concatenate([rng.normal(0, 50, (2, 30, 4)), rng.normal(0, 0.1, (2, 30, 1))], -1)
    b = Particles(X, np.full((2, 30), -math.log(30)), np.random.default_rng(4))
    out = PF().predict(b, ct, 1.0)
    assert np.array_equal(out.states[..., 4], X[..., 4])
    assert not np.allclose(out.states[..., :4], ct.f(X, 1.0)[..., :4])
    still = tk.models.ConstantVelocity(dim=2, q=0.0)
    b4 = particles(batch=(3,), N=20)
    dts = np.array([0.5, 1.0, 3.0])
    out = PF().predict(b4, still, dts)
    for r in range(3):
        want = still.f(b4.states[r], float(dts[r]))
        np.testing.assert_allclose(out.states[r], want, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match=r"dt has shape \(2,\); expected a float or one step "
                                         r"per batch row, shape \(3,\)"):
        PF().predict(b4, still, dts[:2])


# --------------------------------------------------------------------------------------------
# update
# --------------------------------------------------------------------------------------------


def test_update_weights_are_the_normalised_gaussian_likelihoods():
    """log w' = log w + log N(z - h(x_i); 0, R) - logsumexp(...), per row (scipy's density),
    no resampling (threshold 0); the innovation is the weighted mean of z - h(x_i) and S their
    weighted covariance plus R."""
    b = particles(batch=(3,), N=100)
    z = np.array([[1.0, -2.0], [0.5, 0.5], [-3.0, 4.0]])
    post, innov = PF(ess_threshold=0.0).update(b, z, POS)
    R = POS.noise
    w = b.weights
    for r in range(3):
        ll = multivariate_normal(mean=np.zeros(2), cov=R).logpdf(z[r] - b.states[r, :, :2])
        a = b.log_weights[r] + ll
        want = a - np.log(np.exp(a - a.max()).sum()) - a.max()
        np.testing.assert_allclose(post.log_weights[r], want, rtol=1e-12, atol=1e-12)
        zbar = w[r] @ b.states[r, :, :2]
        np.testing.assert_allclose(innov.nu[r], z[r] - zbar, rtol=1e-12)
        d = b.states[r, :, :2] - zbar
        np.testing.assert_allclose(innov.cov[r], (w[r, :, None] * d).T @ d + R, rtol=1e-12)
    assert np.array_equal(post.states, b.states)
    # log_likelihood is the same density
    ll = log_likelihood(b.states, z, POS)
    want = multivariate_normal(mean=np.zeros(2), cov=R).logpdf(z[1] - b.states[1, :, :2])
    np.testing.assert_allclose(ll[1], want, rtol=1e-12)


def test_one_noise_covariance_per_row():
    """A sensor whose R has one matrix per batch row (``with_noise``, as an adaptive filter
    uses): each row's log-likelihood is scipy's density with that row's R, and the
    innovation covariance adds that row's R."""
    from trackkit.models.noise import with_noise

    b = particles(batch=(3,), N=80)
    rng = np.random.default_rng(4)
    A = rng.normal(size=(3, 2, 2))
    R = A @ A.mT + np.eye(2)
    sensor = with_noise(POS, R)
    z = rng.normal(size=(3, 2))
    ll = log_likelihood(b.states, z, sensor)
    post, innov = PF(ess_threshold=0.0).update(b, z, sensor)
    _, innov0 = PF(ess_threshold=0.0).update(b, z, POS)
    for r in range(3):
        want = multivariate_normal(mean=np.zeros(2), cov=R[r]).logpdf(z[r] - b.states[r, :, :2])
        np.testing.assert_allclose(ll[r], want, rtol=1e-12)
        np.testing.assert_allclose(innov.cov[r] - R[r], innov0.cov[r] - POS.noise,
                                   rtol=1e-12, atol=1e-12 * np.abs(innov0.cov[r]).max())


def test_tiny_likelihoods_stay_finite_in_log_space():
    """A measurement 1e4 sigma from every particle: every likelihood underflows in linear
    space (exp(-5e7)), yet the log-weights are finite and normalised."""
    b = particles(batch=(2,), N=50)
    z = np.full((2, 2), 2e4)
    post, innov = PF(ess_threshold=0.0).update(b, z, POS)
    assert np.isfinite(post.log_weights).any(-1).all()
    np.testing.assert_allclose(np.exp(post.log_weights).sum(-1), 1.0, rtol=1e-12)
    assert post.lost is None and np.isfinite(innov.nis).all()


def test_missing_rows_keep_the_prediction_and_get_a_nan_residual():
    b = particles(batch=(3,), N=60)
    z = np.array([[1.0, 2.0], [np.nan, 1.0], [0.0, 0.0]])
    post, innov = PF(ess_threshold=1.0).update(b, z, POS)
    assert np.array_equal(post.states[1], b.states[1])
    assert np.array_equal(post.log_weights[1], b.log_weights[1])
    assert np.isnan(innov.nu[1]).all() and not np.isnan(innov.nu[[0, 2]]).any()
    assert np.isfinite(innov.cov).all()
    w = b.weights[1]
    d = b.states[1, :, :2] - w @ b.states[1, :, :2]
    np.testing.assert_allclose(innov.cov[1], (w[:, None] * d).T @ d + POS.noise, rtol=1e-12)
    assert np.all(post.log_weights[[0, 2]] == -math.log(60))  # those rows were resampled
    # a missing row is not resampled either, whatever its ESS (the prediction is kept)
    assert 1 / np.sum(b.weights[1] ** 2) < 60


class _Blind(tk.models.Position):
    """A position sensor that cannot see row 1: h is +inf there for every particle."""

    def h(self, x):
        z = np.array(x[..., :2], dtype=float)
        z[1] = np.inf
        return z


def test_a_row_no_particle_can_explain_is_rejected_and_counted():
    b = particles(batch=(3,), N=40)
    sensor = _Blind(dim=2, sigma=1.0)
    f = PF(ess_threshold=0.0)
    post, innov = f.update(b, np.zeros((3, 2)), sensor)
    assert post.lost.tolist() == [0, 1, 0]
    assert np.array_equal(post.log_weights[1], b.log_weights[1])
    assert not np.array_equal(post.log_weights[0], b.log_weights[0])
    assert np.isfinite(f.estimate(post).mean).all()
    post2, _ = f.update(post, np.zeros((3, 2)), sensor)
    assert post2.lost.tolist() == [0, 2, 0]
    # overflowing residuals are likelihoods of zero too
    post3, _ = f.update(b, np.full((3, 2), 1e200), POS)
    assert post3.lost.tolist() == [1, 1, 1]
    assert np.array_equal(post3.log_weights, b.log_weights)
    # a rejected row is not resampled either, whatever its ESS
    post4, _ = PF(ess_threshold=1.0).update(b, np.zeros((3, 2)), sensor)
    assert np.array_equal(post4.states[1], b.states[1])
    assert np.all(post4.log_weights[[0, 2]] == -math.log(40))


def test_rows_above_the_ess_threshold_are_not_resampled():
    """Row 0 gets an informative measurement (its ESS collapses), row 1 a measurement every
    particle explains equally (all particles at one position, so the ESS stays N): only row 0
    is resampled."""
    rng = np.random.default_rng(6)
    N = 500
    X = rng.normal(0.0, 10.0, (2, N, 4))
    X[1, :, :2] = 3.0
    lw = np.full((2, N), -math.log(N))
    b = Particles(X, lw, np.random.default_rng(7))
    post, _ = PF(ess_threshold=0.5).update(b, np.array([[0.0, 0.0], [1.0, 1.0]]), POS)
    assert np.array_equal(post.states[1], X[1])
    np.testing.assert_allclose(post.log_weights[1], lw[1], rtol=1e-12)
    assert np.all(post.log_weights[0] == -math.log(N))
    assert len(np.unique(post.states[0, :, 0])) < N / 2  # copies of the likely ones
    assert np.isin(post.states[0, :, 0], X[0, :, 0]).all()


@pytest.mark.parametrize("resampler", ["systematic", "stratified", "residual", "multinomial"])
def test_determinism_for_a_given_generator(resampler):
    def run(seed):
        f = PF(300, resampler=resampler, ess_threshold=0.9, roughening=0.1)
        b = f.init(prior(batch=(2, 2)), rng=np.random.default_rng(seed))
        for k in range(4):
            b = f.predict(b, CV, 1.0)
            b, _ = f.update(b, np.full((2, 2, 2), float(k)), POS)
        return b
    a, b, c = run(21), run(21), run(22)
    assert np.array_equal(a.states, b.states) and np.array_equal(a.log_weights, b.log_weights)
    assert not np.array_equal(a.states, c.states)


def test_regularised_pf_jitters_resampled_particles():
    """After resampling with regularise=True no two particles coincide (plain resampling
    leaves copies), and the covariance is larger than without (same draws up to the
    jitter: the ratio of traces exceeds 1 in every row)."""
    g = prior(batch=(4,))
    z = np.zeros((4, 2))
    plain = PF(1000, ess_threshold=1.0)
    reg = PF(1000, ess_threshold=1.0, regularise=True)
    b0 = plain.init(g, rng=np.random.default_rng(8))
    p1, _ = plain.update(b0, z, POS)
    b0 = reg.init(g, rng=np.random.default_rng(8))
    p2, _ = reg.update(b0, z, POS)
    assert all(len(np.unique(p1.states[r, :, 0])) < 1000 for r in range(4))
    assert all(len(np.unique(p2.states[r, :, 0])) == 1000 for r in range(4))
    t1 = np.trace(plain.estimate(p1).cov, axis1=-2, axis2=-1)
    t2 = np.trace(reg.estimate(p2).cov, axis1=-2, axis2=-1)
    assert np.all(t2 > t1)


def test_shrinkage_keeps_the_resampled_cloud_as_wide_as_before():
    """Resampling with the plain kernel widens the cloud by about 1 + h^2 in every row;
    with shrinkage (same particles, same resampling) it stays as wide as the weighted cloud
    before resampling: 400 rows of 2 000 particles, the trace ratio's mean within 4.5 of its
    standard errors of 1 + h^2 (plain) and of 1 (shrink), h = 0.37 here."""
    R, N = 400, 2000
    g = prior(batch=(R,))
    z = np.zeros((R, 2))
    h = rs.optimal_bandwidth(N, 4)
    ratios = {}
    for shrink in (False, True):
        f = PF(N, ess_threshold=1.0, regularise=True, shrink=shrink)
        b0 = f.init(g, rng=np.random.default_rng(31))
        # the weighted cloud before resampling: the update without its resampling
        lw = b0.log_weights + log_likelihood(b0.states, z, POS)
        w = np.exp(lw - rs.logsumexp(lw)[..., None])
        before = np.trace(rs.weighted_mean_cov(b0.states, w)[1], axis1=-2, axis2=-1)
        b1, _ = f.update(b0, z, POS)
        ratios[shrink] = np.trace(f.estimate(b1).cov, axis1=-2, axis2=-1) / before
    for shrink, expected in ((False, 1 + h**2), (True, 1.0)):
        r = ratios[shrink]
        assert abs(r.mean() - expected) < 4.5 * r.std() / math.sqrt(R), (shrink, r.mean())


def test_bearing_innovation_is_circular_across_the_cut():
    """Particles due south of the sensor have bearings on both sides of +-pi; the predicted
    bearing and the innovation are taken on the circle (reference: the bearings unwrapped
    about pi, averaged, and z minus that mean wrapped), and S is their spread plus R."""
    rng = np.random.default_rng(9)
    N = 400
    X = np.zeros((2, N, 4))
    X[..., 0] = rng.normal(0.0, 30.0, (2, N))
    X[..., 1] = -1000.0
    b = Particles(X, np.log(rng.dirichlet(np.ones(N), size=2)), np.random.default_rng(1))
    sensor = tk.models.Bearing(sigma=0.02)
    bearings = sensor.h(X)[..., 0]
    assert (bearings > 0).any() and (bearings < 0).any()
    z = np.array([[np.pi - 0.01], [-np.pi + 0.02]])
    _, innov = PF(ess_threshold=0.0).update(b, z, sensor)
    w = b.weights
    unwrapped = np.where(bearings < 0, bearings + 2 * np.pi, bearings)
    mean = (w * unwrapped).sum(-1)
    np.testing.assert_allclose(innov.nu[:, 0], wrap(z[:, 0] - mean), rtol=1e-10)
    var = (w * (unwrapped - mean[:, None]) ** 2).sum(-1)
    np.testing.assert_allclose(innov.cov[:, 0, 0], var + 0.02**2, rtol=1e-10)
    assert np.all(np.abs(innov.nu) < 0.1)


def test_equal_weights_after_init_and_resampling_give_the_same_numbers():
    """Beliefs whose weights are all 1/N (after init, after resampling every row) take a
    shortcut in estimate and in the innovation; the numbers equal the general path's."""
    f = PF(300, ess_threshold=1.0)
    b = f.init(prior(batch=(2,)), rng=np.random.default_rng(3))
    general = Particles._make((b.states, b.log_weights.copy()))  # same values, not marked
    one, other = f.estimate(b), f.estimate(general)
    np.testing.assert_allclose(one.mean, other.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(one.cov, other.cov, rtol=1e-12, atol=1e-12)
    sensor = tk.models.RangeBearing(sigma_range=1.0, sigma_bearing=0.05)
    z = np.array([[5.0, 0.3], [6.0, -0.2]])
    _, i1 = PF(ess_threshold=0.0).update(b, z, sensor)
    _, i2 = PF(ess_threshold=0.0).update(general, z, sensor)
    np.testing.assert_allclose(i1.nu, i2.nu, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(i1.cov, i2.cov, rtol=1e-12, atol=1e-14)


def test_estimate_is_circular_on_angle_states():
    rng = np.random.default_rng(10)
    N = 300
    X = rng.normal(0.0, 1.0, (2, N, 3))
    X[..., 2] = wrap(np.pi + 0.05 * rng.standard_normal((2, N)))
    w = rng.dirichlet(np.ones(N), size=2)
    b = Particles(X, np.log(w))
    g = PF(angles=(2,)).estimate(b)
    s, c = (w * np.sin(X[..., 2])).sum(-1), (w * np.cos(X[..., 2])).sum(-1)
    np.testing.assert_allclose(g.mean[:, 2], np.arctan2(s, c), rtol=1e-12)
    assert np.all(np.abs(np.abs(g.mean[:, 2]) - np.pi) < 0.02)
    assert np.all(g.cov[:, 2, 2] < 0.01)  # not the ~pi^2 of a linear average
    # (a mean near 0 of values near 1: agreement relative to the particles' magnitude)
    np.testing.assert_allclose(g.mean[:, :2], np.einsum("rn,rnj->rj", w, X[..., :2]),
                               rtol=1e-12, atol=1e-12 * np.abs(X).max())
    linear = PF().estimate(b)
    assert np.all(linear.cov[:, 2, 2] > 1.0)


def test_sensor_with_a_pose_per_batch_row():
    """A range-bearing sensor whose origin has one row per run (a moving observer per run):
    the likelihood equals the one of a separate sensor per row (row loop), even when the
    batch size equals the number of particles."""
    rng = np.random.default_rng(11)
    B = N = 5
    X = rng.normal(0.0, 100.0, (B, N, 4)) + [500.0, 800.0, 0.0, 0.0]
    origins = rng.normal(0.0, 50.0, (B, 2))
    sensor = tk.models.RangeBearing(origin=origins, sigma_range=5.0, sigma_bearing=0.01)
    z = np.stack([[900.0, 0.5]] * B)
    ll = log_likelihood(X, z, sensor)
    for r in range(B):
        one = tk.models.RangeBearing(origin=origins[r], sigma_range=5.0, sigma_bearing=0.01)
        np.testing.assert_allclose(ll[r], log_likelihood(X[r], z[r], one), rtol=1e-12)
    b = Particles(X, np.full((B, N), -math.log(N)), np.random.default_rng(0))
    post, innov = PF(ess_threshold=0.0).update(b, z, sensor)
    assert innov.nu.shape == (B, 2) and post.states.shape == (B, N, 4)


def test_filter_runs_with_several_batch_axes_and_run_filter_passes_the_generator():
    motion = CV
    zs = [np.full((2, 3, 2), float(k)) for k in range(3)]
    f = PF(100)
    b, hist = run_filter(f, prior(batch=(2, 3)), motion, POS, zs, 1.0, history=True,
                         rng=np.random.default_rng(12))
    assert b.states.shape == (2, 3, 100, 4) and hist.mean.shape == (3, 2, 3, 4)
    assert hist.cov.shape == (3, 2, 3, 4, 4)
    b2, _ = run_filter(f, prior(batch=(2, 3)), motion, POS, zs, 1.0,
                       rng=np.random.default_rng(12))
    assert np.array_equal(b.states, b2.states)
    # a belief already built keeps its generator
    start = f.init(prior(batch=(2, 3)), rng=np.random.default_rng(13))
    b3, _ = run_filter(f, start, motion, POS, zs, 1.0)
    assert b3.rng is start.rng
    # a Gaussian filter ignores rng
    g, _ = run_filter(tk.filters.KF(), prior(batch=(2, 3)), motion, POS, zs, 1.0,
                      rng=np.random.default_rng(0))
    assert isinstance(g, tk.Gaussian)


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, message", [
    ({"n_particles": 0}, "PF n_particles = 0; expected an integer >= 1"),
    ({"n_particles": 2.5}, "PF n_particles = 2.5"),
    ({"resampler": "bootstrap"}, "PF resampler = 'bootstrap'; expected one of 'systematic'"),
    ({"ess_threshold": 1.5}, r"PF ess_threshold = 1.5; expected a number in \[0, 1\]"),
    ({"regularise": "yes"}, "PF regularise = 'yes'; expected True or False"),
    ({"roughening": -0.1}, "PF roughening = -0.1; expected a number >= 0"),
    ({"regularise": True, "roughening": 0.2}, "expected at most one of the two jitters"),
    ({"shrink": True}, "PF shrink = True without regularise; expected regularise = True"),
    ({"shrink": 1}, "PF shrink = 1; expected True or False"),
    ({"n_particles": 1, "regularise": True, "shrink": True}, "expected at least 2 particles"),
    ({"angles": (-1,)}, r"PF: angles = \(-1,\); expected indices >= 0"),
])
def test_bad_options(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PF(**kwargs)


def test_bad_beliefs_and_measurements_are_refused_with_names():
    f = PF(50)
    with pytest.raises(TypeError, match="PF.predict belief is a Gaussian; the particle filter "
                                        r"carries Particles: build them with PF.init"):
        f.predict(prior(), CV, 1.0)
    b = particles(batch=(3,), N=20, n=5)
    with pytest.raises(ValueError, match=r"PF.predict belief.states has shape \(3, 20, 5\); the "
                                         r"model's state has 4 components"):
        f.predict(b, CV, 1.0)
    b = particles(batch=(3,), N=20)
    bad = Particles._make((np.where(np.arange(4) == 2, np.inf, b.states), b.log_weights))
    with pytest.raises(ValueError, match="PF.update belief.states has 60 non-finite entries"):
        f.update(bad, np.zeros((3, 2)), POS)
    bad = Particles._make((b.states, np.full((3, 20), np.nan)))
    with pytest.raises(ValueError, match="PF.predict belief.log_weights has nan or"):
        f.predict(bad, CV, 1.0)
    with pytest.raises(ValueError, match=r"PF.update: z has shape \(3, 3\); the sensor "
                                         r"measures 2 components"):
        f.update(b, np.zeros((3, 3)), POS)
    with pytest.raises(ValueError, match=r"PF.update: z has shape \(4, 2\) but the belief's "
                                         r"batch shape is \(3,\)"):
        f.update(b, np.zeros((4, 2)), POS)
    with pytest.raises(ValueError, match="PF.predict: dt = -1.0; expected a finite time step"):
        f.predict(b, CV, -1.0)
    with pytest.raises(ValueError, match=r"PF.init prior.cov is not positive semi-definite"):
        f.init(tk.Gaussian(np.zeros(4), np.diag([1.0, -1.0, 1.0, 1.0])))
    with pytest.raises(ValueError, match="PF.init: rng is a int"):
        f.init(prior(), rng=1)
    with pytest.raises(ValueError, match=r"PF angles = \(7,\); the state has 4 components"):
        PF(angles=(7,)).init(prior())
