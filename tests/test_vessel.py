"""The vessel model of Zolfagharnasab and Seif (2025) (trackkit.models.manoeuvring): the data
tables, a hand-computed Euler step, Jacobians against central finite differences, the
instability of the printed coefficients, kinematics, the reference vessel's stability and the
augmented model in the EKF, UKF and CKF."""

from __future__ import annotations

import tomllib
from importlib.resources import files

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import trackkit as tk
from trackkit.models.manoeuvring import (
    COEFFICIENT_NAMES,
    IDENTITY,
    KNOT,
    AugmentedVessel,
    Normalisation,
    advance_pose,
    augmented_jacobian,
    augmented_step,
    integrate_pose,
    mean_input,
    naji7,
    paper_coefficients,
    pose_rate,
    reference_vessel,
    regressors,
    rhs,
    rhs_jacobian,
    step,
    step_jacobian_state,
    step_jacobian_theta,
    straight_line_speed,
    sway_yaw_block,
)

FAST = settings(max_examples=40, deadline=None, derandomize=True, database=None)
PAPER = {"a1": 0.6856, "a2": 0.2568, "a3": 0.2456, "a4": 0.5862, "a5": 0.2123, "a6": 0.1778,
         "a7": 0.4111, "a8": 0.2569, "a9": 0.1212, "b1": 0.1578, "b2": 0.2356, "b3": 0.0457,
         "b4": -0.1234, "c1": 0.1356, "c2": -0.1111, "c3": -0.3478}
REF = reference_vessel()


def _random_points(rng: np.random.Generator, m: int):
    x = np.column_stack([rng.uniform(0.5, 15, m), rng.uniform(-3, 3, m), rng.uniform(-.3, .3, m)])
    s = np.column_stack([rng.uniform(-0.5, 0.5, m), rng.uniform(500, 2500, m)])
    theta = REF.theta + rng.normal(0, 0.3, (m, 16))
    return x, s, theta


def _central(fun, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Central differences of fun (n,) -> (m,) at x with per-component steps h: (m, n)."""
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h[j]
        cols.append((fun(x + e) - fun(x - e)) / (2 * h[j]))
    return np.stack(cols, -1)


# --- data -----------------------------------------------------------------------------------


def test_tables_3_to_5_are_stored_exactly_with_the_reconstructed_signs():
    raw = tomllib.loads((files("trackkit.models") / "vessel_data.toml").read_text())
    assert raw["paper"]["coefficients"] == PAPER
    p = paper_coefficients()
    assert p.as_dict() == PAPER
    assert p.norm == IDENTITY and COEFFICIENT_NAMES[12] == "b4" and p.theta[12] == -0.1234
    assert (p.theta[14], p.theta[15]) == (-0.1111, -0.3478)


def test_table_2_is_stored_exactly_and_converted_to_si_once():
    raw = tomllib.loads((files("trackkit.models") / "vessel_data.toml").read_text())["naji7"]
    assert raw == {"length_overall_m": 19.6, "beam_m": 4.6, "draft_m": 1.01,
                   "net_weight_t": 35.0, "engines": 2, "engine_power_kw": 1006.695,
                   "max_speed_kn": 44.0, "gross_tonnage": 27.0}
    n = naji7()
    assert (n.length_overall, n.beam, n.draft, n.engines, n.gross_tonnage) == (
        19.6, 4.6, 1.01, 2, 27.0)
    assert n.mass == 35000.0
    assert n.engine_power == pytest.approx(1006695.0, rel=1e-15)
    assert n.max_speed == pytest.approx(44 * 1852 / 3600, rel=1e-15)


def test_reference_vessel_is_complete_stable_and_balanced_at_18_knots():
    assert np.all(REF.theta != 0) and REF.theta.size == 16
    assert REF.norm == Normalisation(19.6, 18 * KNOT, 2000.0)
    assert straight_line_speed(REF.theta, 2000.0, REF.norm) == pytest.approx(18 * KNOT, 1e-12)
    speeds = np.linspace(0, 44 * KNOT, 221)
    eig = np.linalg.eigvals(sway_yaw_block(speeds, REF.theta, REF.norm))
    assert eig.real.max() < -0.05  # sway-yaw stable at every speed 0-44 kn
    u, n = np.meshgrid(speeds[1:], np.linspace(0, 2500, 26))
    x = np.stack([u, 0 * u, 0 * u], -1)
    s = np.stack([0 * u, n], -1)
    assert np.all(rhs_jacobian(x, s, REF.theta, REF.norm)[..., 0, 0] < 0)  # surge stable
    # the paper's signs where they are physical: b2 > 0, b4 < 0, c2 < 0
    d = REF.as_dict()
    assert d["b2"] > 0 and d["b4"] < 0 and d["c2"] < 0 and d["a1"] < 0 < d["a9"]


def test_straight_line_speed_is_nan_for_the_printed_coefficients():
    assert np.isnan(straight_line_speed(paper_coefficients().theta, 2000.0))


# --- the model ------------------------------------------------------------------------------


def test_one_euler_step_with_the_mean_input_by_hand_in_si():
    theta = [-0.5, -0.2, -0.3, -0.1, 0.4, 0.2, -0.1, -0.001, 0.00001,
             -0.7, 0.3, -0.15, -0.9, -0.25, -1.0, 0.7]
    s_m = mean_input([0.2, 100.0], [0.4, 300.0])  # [0.3, 200]
    x1 = step([2.0, 0.5, 0.1], s_m, theta, 0.5)
    # f1 = -0.5*4 - 0.2*0.25 - 0.3*0.01 - 0.1*0.09 + 0.4*0.05 + 0.2*0.15 - 0.1*0.03
    #      - 0.001*2*200 + 1e-5*200^2 = -2.015
    # f2 = -0.7*0.5 + 0.3*0.1 - 0.15*0.3 - 0.9*2*0.1 = -0.545
    # f3 = -0.25*0.5 - 1.0*0.1 + 0.7*0.3 = -0.015
    np.testing.assert_allclose(x1, [2 - 0.5 * 2.015, 0.5 - 0.5 * 0.545, 0.1 - 0.5 * 0.015],
                               rtol=1e-13)


def test_one_euler_step_by_hand_in_prime_units():
    norm = Normalisation(length=20.0, speed=10.0, rpm=2000.0)  # U0^2/L = 5, U0^2/L^2 = 0.25
    theta = [-0.2, -0.4, -0.2, -0.15, 0.8, 0.2, -0.15, -0.12, 0.32,
             -0.7, 0.3, -0.15, -0.9, -0.25, -1.0, 0.7]
    s_m = mean_input([0.1, 1900.0], [0.3, 2100.0])  # [0.2, 2000]: n' = 1
    # u' = 1, v' = 0.1, r' = 0.05 * 20 / 10 = 0.1, d = 0.2
    # f1' = -0.2 - 0.004 - 0.002 - 0.006 + 0.008 + 0.004 - 0.003 - 0.12 + 0.32 = -0.003
    # f2' = -0.07 + 0.03 - 0.03 - 0.09 = -0.16;  f3' = -0.025 - 0.1 + 0.14 = 0.015
    x1 = step([10.0, 1.0, 0.05], s_m, theta, 1.0, norm)
    np.testing.assert_allclose(x1, [10 - 5 * 0.003, 1 - 5 * 0.16, 0.05 + 0.25 * 0.015],
                               rtol=1e-12)


@pytest.mark.parametrize("norm", [IDENTITY, REF.norm])
def test_rhs_is_the_regressor_matrix_times_theta(norm):
    x, s, theta = _random_points(np.random.default_rng(1), 30)
    P = regressors(x, s, norm)
    assert P.shape == (30, 3, 16)
    assert np.all(P[:, 0, 9:] == 0) and np.all(P[:, 1, :9] == 0) and np.all(P[:, 1, 13:] == 0)
    assert np.all(P[:, 2, :13] == 0)
    np.testing.assert_allclose(rhs(x, s, theta, norm), np.einsum("kij,kj->ki", P, theta),
                               rtol=1e-12, atol=1e-12)


def test_normalisation_maps_prime_dynamics_to_si():
    x, s, theta = _random_points(np.random.default_rng(2), 10)
    n = REF.norm
    prime = rhs(n.to_prime(x), n.inputs_to_prime(s), theta)  # theta applied to x', s'
    np.testing.assert_allclose(rhs(x, s, theta, n), n.rate_scale * prime, rtol=1e-12)
    np.testing.assert_allclose(n.from_prime(n.to_prime(x)), x, rtol=1e-15)
    assert n.time == pytest.approx(19.6 / (18 * KNOT))


def test_model_is_port_starboard_symmetric():
    x, s, theta = _random_points(np.random.default_rng(3), 10)
    m = np.array([1.0, -1.0, -1.0])
    f = rhs(x, s, theta, REF.norm)
    fm = rhs(x * m, s * np.array([-1.0, 1.0]), theta, REF.norm)
    np.testing.assert_array_equal(fm, f * m)


@pytest.mark.parametrize("norm", [IDENTITY, REF.norm])
def test_jacobians_match_central_differences(norm):
    x, s, theta = _random_points(np.random.default_rng(4), 8)
    dt = 0.7
    # the step is quadratic in each state and linear in each coefficient, so central
    # differences have no truncation error: large steps keep the rounding error small
    for k in range(8):
        hx = 1e-2 * np.maximum(1.0, np.abs(x[k]))
        Jx = step_jacobian_state(x[k], s[k], theta[k], dt, norm)
        Jfd = _central(lambda z, k=k: step(z, s[k], theta[k], dt, norm), x[k], hx)
        np.testing.assert_allclose(Jx, Jfd, rtol=1e-6, atol=1e-9 * np.abs(Jx).max())
        Jc = rhs_jacobian(x[k], s[k], theta[k], norm)
        np.testing.assert_allclose(Jx, np.eye(3) + dt * Jc, rtol=1e-15)
        ht = 1e-2 * np.maximum(1.0, np.abs(theta[k]))
        Jt = step_jacobian_theta(x[k], s[k], dt, norm)
        Jtfd = _central(lambda th, k=k: step(x[k], s[k], th, dt, norm), theta[k], ht)
        np.testing.assert_allclose(Jt, Jtfd, rtol=1e-6, atol=1e-9 * np.abs(Jt).max())


@FAST
@given(st.integers(0, 2**32 - 1))
def test_augmented_jacobian_matches_central_differences(seed):
    x, s, theta = _random_points(np.random.default_rng(seed), 1)
    xa = np.concatenate([x[0], theta[0]])
    dt = 1.0
    F = augmented_jacobian(xa, s[0], dt, REF.norm)
    h = 1e-2 * np.maximum(1.0, np.abs(xa))
    Ffd = _central(lambda z: augmented_step(z, s[0], dt, REF.norm), xa, h)
    np.testing.assert_allclose(F, Ffd, rtol=1e-6, atol=1e-9 * np.abs(F).max())
    np.testing.assert_array_equal(F[3:, 3:], np.eye(16))
    np.testing.assert_array_equal(F[3:, :3], 0.0)


def test_batched_jacobians_have_the_batch_axes():
    x, s, theta = _random_points(np.random.default_rng(5), 6)
    xa = np.concatenate([x, theta], -1).reshape(2, 3, 19)
    F = augmented_jacobian(xa, s.reshape(2, 3, 2), 1.0, REF.norm)
    assert F.shape == (2, 3, 19, 19)
    one = augmented_jacobian(xa[1, 2], s.reshape(2, 3, 2)[1, 2], 1.0, REF.norm)
    np.testing.assert_array_equal(F[1, 2], one)


# --- the printed coefficients (Tables 3-5) are unstable ---------------------------------------


def test_printed_sway_yaw_eigenvalues_in_si():
    th = paper_coefficients().theta
    for u in (5.0, 8.74, 9.26):
        eig = np.linalg.eigvals(sway_yaw_block(u, th))
        np.testing.assert_allclose(eig.real, [0.02335, 0.02335], rtol=1e-12)
        assert abs(eig.imag[0]) > 0  # a growing oscillation
    # u = 0: 0.02335 +/- sqrt(0.02335^2 - (b1 c2 - c1 b2)), b1 c2 - c1 b2 = -0.04947894
    eig = np.sort(np.linalg.eigvals(sway_yaw_block(0.0, th)).real)
    root = np.sqrt(0.02335**2 + 0.04947894)
    np.testing.assert_allclose(eig, [0.02335 - root, 0.02335 + root], rtol=1e-12)
    np.testing.assert_allclose(eig, [-0.200, 0.247], atol=5e-4)


@FAST
@given(st.floats(0.01, 500.0), st.floats(0.01, 100.0), st.floats(0.01, 1e4),
       st.floats(0.0, 30.0))
def test_no_positive_rescaling_makes_the_printed_coefficients_stable(L, U0, n0, u):
    th = paper_coefficients().theta
    norm = Normalisation(L, U0, n0)
    A = sway_yaw_block(u, th, norm)
    assert np.trace(A) > 0  # (U0 / L) (b1 + c2): one eigenvalue has a positive real part
    assert np.linalg.eigvals(A).real.max() > 0
    # straight line: every surge term is >= 0 for u, n > 0, so there is no equilibrium
    f = rhs([u + 0.1, 0.0, 0.0], [0.0, 0.5 * n0], th, norm)
    assert f[0] > 0


def test_simulating_the_printed_coefficients_in_si_diverges():
    th = paper_coefficients().theta
    x = np.array([18 * KNOT, 0.0, 0.0])
    with np.errstate(all="ignore"):
        for _ in range(10):
            x = step(x, [np.deg2rad(20), 2000.0], th, 1.0)
            if not np.all(np.isfinite(x)):
                break
    assert not np.all(np.isfinite(x)) or abs(x[0]) > 1e9
    # without the engine and nozzle the sway-yaw block alone grows too (surge frozen)
    x = np.array([0.0, 0.1, 0.01])
    for _ in range(200):
        x = np.array([0.0, *x[1:]])
        x = step(x, [0.0, 0.0], th, 0.5)
    assert np.hypot(x[1], x[2]) > 10


# --- kinematics -----------------------------------------------------------------------------


def test_pose_rate_directions():
    np.testing.assert_allclose(pose_rate([0, 0, 0], [2.0, 1.0, 0.1]), [1.0, 2.0, 0.1])
    np.testing.assert_allclose(pose_rate([0, 0, np.pi / 2], [2.0, 1.0, 0.0]), [2.0, -1.0, 0.0],
                               atol=1e-15)


@pytest.mark.parametrize("body", [[5.0, -1.0, 0.1], [7.0, 1.5, -0.05], [3.0, 0.0, 1e-7]])
def test_a_constant_turn_is_a_circle_of_radius_speed_over_rate(body):
    body = np.array(body)
    x = np.broadcast_to(body, (400, 3))
    pose0 = np.array([100.0, -50.0, 0.3])
    P = integrate_pose(x, 0.5, pose0)
    w = pose_rate(pose0, body)[:2]  # earth velocity at the start
    centre = pose0[:2] + np.array([w[1], -w[0]]) / body[2]  # 90 deg toward the turn
    R = np.hypot(P[:, 0] - centre[0], P[:, 1] - centre[1])
    np.testing.assert_allclose(R, np.hypot(body[0], body[1]) / abs(body[2]), rtol=1e-9)
    np.testing.assert_allclose(P[:, 2], pose0[2] + body[2] * 0.5 * np.arange(400), atol=1e-12)


def test_advance_pose_agrees_with_the_rate_for_a_short_step():
    pose, body, dt = np.array([1.0, 2.0, 0.4]), np.array([6.0, -1.0, 0.2]), 1e-4
    np.testing.assert_allclose((advance_pose(pose, body, dt) - pose) / dt,
                               pose_rate(pose, body), rtol=1e-4)


# --- the augmented model in the filters -------------------------------------------------------


@pytest.mark.parametrize("make", [tk.filters.EKF, tk.filters.UKF, tk.filters.CKF])
def test_augmented_vessel_runs_in_the_filters(make):
    xa = np.concatenate([[18 * KNOT, 0.0, 0.0], REF.theta])
    xa = np.stack([xa, xa + 0.01])
    P = np.broadcast_to(np.diag(np.r_[1e-2, 1e-2, 1e-4, 1e-3 * np.ones(16)]), (2, 19, 19))
    belief = tk.Gaussian(xa, P.copy())
    s_m = np.array([[0.1, 2000.0], [-0.2, 1900.0]])
    model = AugmentedVessel(s_m, REF.norm, q_body=[1e-4, 1e-4, 1e-6], q_theta=1e-7)
    sensor = tk.models.Position(dim=3, sigma=[0.05, 0.05, 0.002])  # H = [I3 0]
    f = make()
    pred = f.predict(belief, model, 1.0)
    np.testing.assert_allclose(pred.mean, augmented_step(xa, s_m, 1.0, REF.norm), rtol=1e-4,
                               atol=1e-6)
    post, innov = f.update(pred, np.array([[9.2, 0.1, 0.01], [9.3, -0.1, 0.0]]), sensor)
    assert post.mean.shape == (2, 19) and post.cov.shape == (2, 19, 19)
    assert np.all(np.isfinite(post.cov)) and innov.nu.shape == (2, 3)
    assert np.all(np.diagonal(post.cov, axis1=-2, axis2=-1) <= np.diagonal(pred.cov, 0, -2, -1)
                  + 1e-15)


def test_augmented_vessel_noise_is_the_random_walk():
    m = AugmentedVessel([0.0, 2000.0], REF.norm, q_body=[1.0, 2.0, 3.0], q_theta=0.5)
    Q = m.noise(None, 2.0)
    np.testing.assert_array_equal(np.diag(Q), 2.0 * np.r_[1.0, 2.0, 3.0, 0.5 * np.ones(16)])
    assert np.count_nonzero(Q - np.diag(np.diag(Q))) == 0


# --- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(("call", "field"), [
    (lambda: rhs([1.0, 2.0], [0, 0], REF.theta), "x"),
    (lambda: rhs([1.0, 2.0, 3.0], [0, 0, 0], REF.theta), "s"),
    (lambda: rhs([1.0, 2.0, 3.0], [0, 0], REF.theta[:15]), "theta"),
    (lambda: rhs([np.nan, 2.0, 3.0], [0, 0], REF.theta), "x"),
    (lambda: step([1.0, 2.0, 3.0], [0, 0], REF.theta, np.nan), "dt"),
    (lambda: step([1.0, 2.0, 3.0], [0, 0], REF.theta, np.inf), "dt"),
    (lambda: step([1.0, 2.0, 3.0], [0, 0], REF.theta, -1.0), "dt"),
    (lambda: augmented_step(np.zeros(18), [0, 0], 1.0), "xa"),
    (lambda: Normalisation(length=-1.0), "length"),
    (lambda: Normalisation(speed=np.inf), "speed"),
    (lambda: AugmentedVessel([0.1], REF.norm), "s_m"),
    (lambda: AugmentedVessel([0.1, 2000], REF.norm, q_theta=-1.0), "q_theta"),
    (lambda: AugmentedVessel([0.1, 2000], REF.norm, q_body=[1.0, 1.0]), "q_body"),
    (lambda: AugmentedVessel([0.1, 2000], "prime"), "norm"),
    (lambda: integrate_pose(np.zeros(3), 1.0), "x"),
])
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


@pytest.mark.parametrize("call", [
    lambda: step([1.0, 2.0, 3.0], [0, 0], REF.theta, T=1.0),
    lambda: augmented_step(np.zeros(19), [0, 0], T=1.0),
    lambda: augmented_jacobian(np.zeros(19), [0, 0], T=1.0),
])
def test_old_time_step_keyword_is_refused_naming_dt(call):
    with pytest.raises(TypeError, match="'T' is now spelled 'dt'"):
        call()
