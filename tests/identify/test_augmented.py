"""The augmented-state identification (``trackkit.identify.augmented``): the sub-stepped
model, batching, trial joins, missing samples, the helpers and bad input. The filter itself
is checked against FilterPy in ``tests/oracles/test_vessel_filterpy.py`` and statistically
in ``tests/statistical/test_vessel_identification.py``."""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.identify import (
    DEFAULT_Q_BODY,
    DEFAULT_SUBSTEPS,
    Q_BODY_SAMPLED_INPUTS,
    SUBSTEPS_SAMPLED_INPUTS,
    SampledVessel,
    coefficient_nees,
    identify,
    initial_guess,
    programme,
    relative_error,
    settling_step,
)
from trackkit.models.manoeuvring import (
    AugmentedVessel,
    augmented_jacobian,
    augmented_step,
    reference_vessel,
    step,
)

REF = reference_vessel()
K = 150  # the acceleration run and most of the 20/20 zig-zag: one join (sample 61)


@pytest.fixture(scope="module")
def rec():
    return programme(4, seed=11)


def _xa(batch=()):
    rng = np.random.default_rng(5)
    body = np.array([8.0, -0.6, 0.08]) + 0.1 * rng.standard_normal(batch + (3,))
    theta = REF.theta * (1 + 0.2 * rng.standard_normal(batch + (16,)))
    return np.concatenate([body, theta], -1)


# --- the sub-stepped model ------------------------------------------------------------------


def test_one_substep_is_the_papers_model_bit_for_bit():
    xa = _xa((3,))
    s0, s1 = np.array([[0.1, 1500.0]] * 3), np.array([[0.3, 1700.0]] * 3)
    m = SampledVessel(s0, s1, REF.norm, q_body=[1.0, 2.0, 3.0], q_theta=0.5, substeps=1)
    s_m = 0.5 * (s0 + s1)
    a = AugmentedVessel(s_m, REF.norm, q_body=[1.0, 2.0, 3.0], q_theta=0.5)
    np.testing.assert_array_equal(m.f(xa, 1.0), augmented_step(xa, s_m, 1.0, REF.norm))
    np.testing.assert_array_equal(m.jacobian(xa, 1.0), augmented_jacobian(xa, s_m, 1.0,
                                                                          REF.norm))
    np.testing.assert_array_equal(m.noise(xa, 2.0), a.noise(xa, 2.0))


def test_substeps_are_euler_steps_with_the_interpolated_input():
    xa = _xa()
    s0, s1 = np.array([0.0, 1200.0]), np.array([0.35, 2000.0])
    m = 4
    body = xa[:3]
    for j in range(m):  # sub-step j: the mean of the linear input at its ends
        lo, hi = s0 + j / m * (s1 - s0), s0 + (j + 1) / m * (s1 - s0)
        body = step(body, 0.5 * (lo + hi), xa[3:], 0.25, REF.norm)
    out = SampledVessel(s0, s1, REF.norm, substeps=m).f(xa, 1.0)
    np.testing.assert_allclose(out[:3], body, rtol=1e-14)
    np.testing.assert_array_equal(out[3:], xa[3:])
    assert np.abs(out[:3] - augmented_step(xa, 0.5 * (s0 + s1), 1.0, REF.norm)[:3]).max() > 1e-3


def test_substeps_take_the_mean_of_the_inputs_measured_at_their_ends():
    xa = _xa()
    s_sub = np.array([[0.0, 1200.0], [0.1, 1300.0], [0.3, 1500.0], [0.3, 1900.0],
                      [0.35, 2000.0]])
    body = xa[:3]
    for j in range(4):
        body = step(body, 0.5 * (s_sub[j] + s_sub[j + 1]), xa[3:], 0.25, REF.norm)
    out = SampledVessel(s_sub[0], s_sub[-1], REF.norm, substeps=4, s_sub=s_sub).f(xa, 1.0)
    np.testing.assert_array_equal(out[:3], body)
    with pytest.raises(ValueError, match=r"s_sub has shape \(4, 2\); expected \(5, \.\.\., 2\)"):
        SampledVessel(s_sub[0], s_sub[-1], REF.norm, substeps=4, s_sub=s_sub[:4])


def test_the_default_discretisation_follows_the_inputs_given(rec):
    """Inputs at the samples: ten sub-steps and the larger Q; inputs every T / 50: fifty
    sub-steps, each with its measured inputs, and the smaller Q."""
    K = 40
    z, s, starts = rec.z[:2, :K], rec.s[:2, :K], rec.starts[:K]
    a = identify(z, s, rec.dt, starts=starts)
    b = identify(z, s, rec.dt, starts=starts, substeps=SUBSTEPS_SAMPLED_INPUTS,
                 q_body=Q_BODY_SAMPLED_INPUTS)
    np.testing.assert_array_equal(a.theta_history, b.theta_history)
    t = np.linspace(0.0, K - 1.0, (K - 1) * DEFAULT_SUBSTEPS + 1)
    s_sub = np.stack([np.stack([np.interp(t, np.arange(K), s[r, :, j]) for j in range(2)], -1)
                      for r in range(2)])
    c = identify(z, s_sub, rec.dt, starts=starts)
    d = identify(z, s, rec.dt, starts=starts, substeps=DEFAULT_SUBSTEPS, q_body=DEFAULT_Q_BODY)
    # the interpolated inputs at the sub-steps are the interpolation between the samples
    np.testing.assert_allclose(c.theta_history, d.theta_history, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match=r"s has shape \(2, 41, 2\); expected \(\.\.\., 40, 2\) "
                       r"inputs \[delta, n\] at the samples of z, or \(\.\.\., 1951, 2\)"):
        identify(z, s_sub[:, :41], rec.dt, starts=starts)


def test_substepped_jacobian_matches_finite_differences():
    xa = _xa()
    model = SampledVessel([0.0, 1200.0], [0.35, 2000.0], REF.norm, substeps=5)
    F = model.jacobian(xa, 1.0)
    eps = 1e-6 * np.maximum(np.abs(xa), 1e-2)
    fd = np.empty((19, 19))
    for i in range(19):
        d = np.zeros(19)
        d[i] = eps[i]
        fd[:, i] = (model.f(xa + d, 1.0) - model.f(xa - d, 1.0)) / (2 * eps[i])
    np.testing.assert_allclose(F, fd, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(F[3:, 3:], np.eye(16))
    np.testing.assert_array_equal(F[3:, :3], 0.0)


def test_substepped_model_is_batched_row_by_row():
    xa = _xa((5,))
    rng = np.random.default_rng(1)
    s0 = np.stack([rng.uniform(-0.3, 0.3, 5), rng.uniform(1000, 2000, 5)], -1)
    s1 = s0 + [0.1, 100.0]
    batch = SampledVessel(s0, s1, REF.norm, substeps=3)
    for i in range(5):
        one = SampledVessel(s0[i], s1[i], REF.norm, substeps=3)
        np.testing.assert_array_equal(batch.f(xa, 1.0)[i], one.f(xa[i], 1.0))
        np.testing.assert_allclose(batch.jacobian(xa, 1.0)[i], one.jacobian(xa[i], 1.0),
                                   rtol=1e-15, atol=0)


# --- the identification run -----------------------------------------------------------------


@pytest.mark.parametrize("m", [1, 10])
@pytest.mark.parametrize("filter", ["ekf", "generic"])
def test_ekf_batched_equals_runs_one_at_a_time_bit_for_bit(rec, m, filter):
    theta0 = initial_guess(REF.theta, 4, seed=3)
    f = "ekf" if filter == "ekf" else tk.filters.EKF()
    kw = dict(starts=rec.starts[:K], filter=f, substeps=m, keep_cov=True)
    batch = identify(rec.z[:, :K], rec.s[:, :K], rec.dt, theta0=theta0, **kw)
    for i in range(4):
        one = identify(rec.z[i:i + 1, :K], rec.s[i:i + 1, :K], rec.dt, theta0=theta0[i:i + 1],
                       **kw)
        for name in ("theta", "cov", "theta_history", "theta_std", "body", "body_std", "nis",
                     "cov_history"):
            np.testing.assert_array_equal(getattr(one, name)[0], getattr(batch, name)[i],
                                          err_msg=name)


@pytest.mark.parametrize("name", ["ukf", "ckf"])
def test_sigma_point_batched_equals_runs_one_at_a_time(rec, name):
    # not bit for bit: the sigma-point kernels fold the runs into one product (wm . Y over all
    # runs' columns), whose rounding depends on how many columns there are. The agreement is
    # checked relative to each value and, for a coefficient passing near zero, to its sd.
    kw = dict(starts=rec.starts[:K], filter=name, substeps=10)
    batch = identify(rec.z[:, :K], rec.s[:, :K], rec.dt, **kw)
    for i in range(4):
        one = identify(rec.z[i:i + 1, :K], rec.s[i:i + 1, :K], rec.dt, **kw)
        a, b, sd = one.theta_history[0], batch.theta_history[i], batch.theta_std[i]
        assert np.all(np.abs(a - b) <= 1e-9 * np.abs(b) + 1e-10 * sd)
        np.testing.assert_allclose(one.theta_std[0], sd, rtol=1e-9)
        np.testing.assert_allclose(one.body[0], batch.body[i], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("m", [1, 4])
def test_structured_ekf_equals_the_generic_filter(rec, m):
    # identify(filter="ekf") runs the EKF by blocks (F = [[A, B], [0, I]], H = [I3 0]); the
    # generic trackkit.filters.EKF on the same model must give the same numbers up to
    # rounding, here with joins and missing samples, over 300 samples of 4 runs
    z = rec.z[:, :300].copy()
    z[1, 100] = np.nan
    z[2, 200:203] = np.nan
    kw = dict(starts=rec.starts[:300], substeps=m, keep_cov=True)
    a = identify(z, rec.s[:, :300], rec.dt, filter="ekf", **kw)
    b = identify(z, rec.s[:, :300], rec.dt, filter=tk.filters.EKF(), **kw)
    sd = np.sqrt(np.diagonal(b.cov_history, axis1=-2, axis2=-1))
    mean_a = np.concatenate([a.body, a.theta_history], -1)
    mean_b = np.concatenate([b.body, b.theta_history], -1)
    assert np.all(np.abs(mean_a - mean_b) <= 1e-9 * np.abs(mean_b) + 1e-9 * sd)
    outer = sd[..., :, None] * sd[..., None, :]
    assert np.all(np.abs(a.cov_history - b.cov_history) <= 1e-9 * outer)
    np.testing.assert_allclose(a.nis, b.nis, rtol=1e-8)
    assert np.isnan(a.nis[1, 100]) and np.all(np.isnan(a.nis[2, 200:203]))
    # the structured update keeps the covariance exactly symmetric
    np.testing.assert_array_equal(a.cov_history, np.swapaxes(a.cov_history, -1, -2))


def test_one_run_without_batch_axes(rec):
    one = identify(rec.z[2, :K], rec.s[2, :K], rec.dt, starts=rec.starts[:K])
    batch = identify(rec.z[:, :K], rec.s[:, :K], rec.dt, starts=rec.starts[:K])
    assert one.theta.shape == (16,) and one.theta_history.shape == (K, 16)
    np.testing.assert_allclose(one.theta_history, batch.theta_history[2], rtol=1e-12,
                               atol=1e-12)


def test_result_fields_agree_with_the_final_covariance(rec):
    r = identify(rec.z[:, :K], rec.s[:, :K], rec.dt, starts=rec.starts[:K], keep_cov=True)
    assert r.theta.shape == (4, 16) and r.cov.shape == (4, 19, 19)
    assert r.theta_history.shape == r.theta_std.shape == (4, K, 16)
    assert r.body.shape == r.body_std.shape == (4, K, 3) and r.nis.shape == (4, K)
    np.testing.assert_array_equal(r.theta_history[:, -1], r.theta)
    np.testing.assert_array_equal(r.cov_history[:, -1], r.cov)
    np.testing.assert_array_equal(r.theta_std, np.sqrt(np.diagonal(
        r.cov_history, axis1=-2, axis2=-1))[..., 3:])
    assert r.filter == "EKF"
    # the standard deviations shrink as the data come in
    assert np.all(r.theta_std[:, -1, 9:] < 0.2 * r.theta_std[:, 0, 9:])


def test_a_join_reinitialises_the_body_and_keeps_theta(rec):
    j = rec.segments[1].start  # first sample of the 20/20 zig-zag
    r = identify(rec.z[:, :K], rec.s[:, :K], rec.dt, starts=rec.starts[:K], keep_cov=True)
    P = r.cov_history[:, j]
    np.testing.assert_array_equal(r.body[:, j], rec.z[:, j])
    np.testing.assert_array_equal(P[:, :3, :3], np.broadcast_to(np.diag(
        rec.noise.body**2), (4, 3, 3)))
    np.testing.assert_array_equal(P[:, :3, 3:], 0.0)
    np.testing.assert_array_equal(P[:, 3:, 3:], r.cov_history[:, j - 1, 3:, 3:])
    np.testing.assert_array_equal(r.theta_history[:, j], r.theta_history[:, j - 1])
    assert np.all(np.isnan(r.nis[:, [0, j]]))
    assert np.all(np.isfinite(r.nis[:, j + 1]))
    # without the join the filter would fit the jump: the results differ
    r2 = identify(rec.z[:, :K], rec.s[:, :K], rec.dt)
    assert np.abs(r2.theta - r.theta).max() > 1e-3


def test_missing_samples_keep_the_prediction(rec):
    z = rec.z[:, :K].copy()
    z[:, 40] = np.nan
    r = identify(z, rec.s[:, :K], rec.dt, starts=rec.starts[:K], keep_cov=True)
    assert np.all(np.isnan(r.nis[:, 40])) and np.all(np.isfinite(r.theta))
    # the coefficients are not updated at the missing sample (the prediction leaves them)
    np.testing.assert_array_equal(r.theta_history[:, 40], r.theta_history[:, 39])
    assert np.all(r.theta_std[:, 40] >= r.theta_std[:, 39])


def test_noise_free_discrete_data_give_the_coefficients():
    # the identifier's own model (substeps=1 truth), exact states, a small R: all 16 come out
    rec = programme(1, seed=3, substeps=1)
    r = identify(rec.x, rec.s, rec.dt, starts=rec.starts, substeps=1,
                 sigma_z=[1e-4, 1e-4, 5e-6], q_body=0.0)
    assert relative_error(r.theta, REF.theta).max() < 1e-5


def test_the_default_initial_guess_is_zero_with_unit_sd(rec):
    r = identify(rec.z[:, :2], rec.s[:, :2], rec.dt, keep_cov=True)
    np.testing.assert_array_equal(r.cov_history[:, 0, 3:, 3:], np.broadcast_to(np.eye(16),
                                                                                (4, 16, 16)))
    np.testing.assert_array_equal(r.theta_history[:, 0], 0.0)


# --- helpers --------------------------------------------------------------------------------


def test_initial_guess_depends_on_seed_and_run_only():
    a = initial_guess(REF.theta, 5, seed=9, spread=0.3)
    b = initial_guess(REF.theta, [3, 4], seed=9, spread=0.3)
    np.testing.assert_array_equal(a[3:], b)
    assert np.all(relative_error(a, REF.theta) <= 0.3)
    assert np.all(relative_error(a, REF.theta) > 0)
    assert not np.array_equal(a[0], a[1])


def test_settling_step():
    theta = np.ones(16)
    h = np.ones((2, 6, 16))
    h[0, :3, 0] = 2.0  # outside until sample 3
    h[1, 4, 1] = 1.5  # leaves at 4, back at 5
    h[1, 5, 2] = 0.5  # outside at the end
    k = settling_step(h, theta, tol=0.2)
    assert k[0, 0] == 3 and k[1, 1] == 5 and k[1, 2] == 6
    assert k[0, 1] == 0 and k[1, 0] == 0


def test_coefficient_nees_is_the_quadratic_form():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((19, 19))
    cov = A @ A.T + np.eye(19)
    theta, e = np.zeros(16), rng.standard_normal(16)
    np.testing.assert_allclose(coefficient_nees(e, cov, theta),
                               e @ np.linalg.solve(cov[3:, 3:], e), rtol=1e-12)
    idx = [9, 10, 11]
    np.testing.assert_allclose(coefficient_nees(e, cov, theta, idx),
                               e[idx] @ np.linalg.solve(cov[12:15, 12:15], e[idx]), rtol=1e-12)


# --- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"filter": "pf"}, "filter"),
    ({"filter": object()}, "filter"),
    ({"theta0": np.zeros(15)}, "theta0"),
    ({"theta_sd0": 0.0}, "theta_sd0"),
    ({"sigma_z": [0.1, 0.1]}, "sigma_z"),
    ({"q_body": -1.0}, "q_body"),
    ({"q_theta": np.nan}, "q_theta"),
    ({"substeps": 0}, "substeps"),
    ({"starts": np.zeros(5)}, "starts"),
    ({"norm": "prime"}, "norm"),
])
def test_bad_arguments_name_the_field(rec, kwargs, field):
    with pytest.raises(ValueError, match=field):
        identify(rec.z[:, :5], rec.s[:, :5], 1.0, **kwargs)


def test_bad_data_name_the_field(rec):
    with pytest.raises(ValueError, match="z has shape"):
        identify(rec.z[:, :5, :2], rec.s[:, :5], 1.0)
    with pytest.raises(ValueError, match="s has shape"):
        identify(rec.z[:, :5], rec.s[:, :4], 1.0)
    with pytest.raises(ValueError, match="dt = "):
        identify(rec.z[:, :5], rec.s[:, :5], 0.0)
    z = rec.z[:, :5].copy()
    z[1, 0, 2] = np.nan
    with pytest.raises(ValueError, match="trial start"):
        identify(z, rec.s[:, :5], 1.0)
    with pytest.raises(ValueError, match="run axes"):
        identify(rec.z[:, :5], rec.s[:3, :5], 1.0)
    with pytest.raises(ValueError, match="substeps"):
        SampledVessel([0.0, 1.0], [0.0, 1.0], REF.norm, substeps=0)
