"""Motion models (trackkit.models.motion, trackkit.models.discretize).

Jacobians against central finite differences, closed forms of Q (CV, CA, Singer, the
missing-measurements thesis's CWPA via Van Loan and its random-sine model, eqs 2-94/2-95), the
coordinated turn through omega = 0, batched dt and the shape/PSD of every noise matrix.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import trackkit as tk
from trackkit.models import (
    ConstantAcceleration,
    ConstantVelocity,
    ContinuousLinear,
    CoordinatedTurn,
    KnownTurnRate,
    LinearMotion,
    RandomSine,
    Singer,
    discretize,
)

FAST = settings(max_examples=60, deadline=None, derandomize=True, database=None)


def _cv_block(dt):
    return np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])


def _ca_block(dt):
    return np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )


def _interleave(block, per_axis):
    """Place a per-axis (k, k) block into the [pos..., vel..., acc...] ordering."""
    k = block.shape[0]
    d = len(per_axis)
    out = np.zeros((k * d, k * d))
    for a in range(d):
        idx = [i * d + a for i in range(k)]
        out[np.ix_(idx, idx)] = per_axis[a] * block
    return out


def _singer_closed_form(T, tau, sigma):
    """Singer (1970) per axis, alpha = 1/tau, white-noise density 2 alpha sigma^2."""
    a = 1.0 / tau
    x = a * T
    e1, e2 = np.exp(-x), np.exp(-2 * x)
    F = np.array([[1, T, (x - 1 + e1) / a**2], [0, 1, (1 - e1) / a], [0, 0, e1]])
    q11 = (1 - e2 + 2 * x + 2 * x**3 / 3 - 2 * x**2 - 4 * x * e1) / (2 * a**5)
    q12 = (e2 + 1 - 2 * e1 + 2 * x * e1 - 2 * x + x**2) / (2 * a**4)
    q13 = (1 - e2 - 2 * x * e1) / (2 * a**3)
    q22 = (4 * e1 - 3 - e2 + 2 * x) / (2 * a**3)
    q23 = (e2 + 1 - 2 * e1) / (2 * a**2)
    q33 = (1 - e2) / (2 * a)
    Q = 2 * a * sigma**2 * np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])
    return F, Q


def _cwpa_A_L():
    """The missing-measurements thesis, eq 2-61/2-62: X = (x, y, vx, vy, ax, ay), ones at
    (1,3),(2,4),(3,5),(4,6)."""
    A = np.zeros((6, 6))
    for i, j in [(0, 2), (1, 3), (2, 4), (3, 5)]:
        A[i, j] = 1.0
    L = np.vstack([np.zeros((4, 2)), np.eye(2)])
    return A, L


_rng = np.random.default_rng(7)
_Fm = np.eye(4) + 0.1 * _rng.standard_normal((4, 4))
_Qm = np.eye(4) * 0.3
_A_cont, _L_cont = _cwpa_A_L()

MODELS = {
    "CV1": ConstantVelocity(dim=1, q=0.5),
    "CV2": ConstantVelocity(dim=2, q=[0.1, 0.7]),
    "CV3": ConstantVelocity(dim=3, q=2.0),
    "CA1": ConstantAcceleration(dim=1, q=0.3),
    "CA2": ConstantAcceleration(dim=2, q=[0.2, 1.5]),
    "CA3": ConstantAcceleration(dim=3, q=1.0),
    "Singer2": Singer(dim=2, tau=5.0, sigma=[1.0, 2.0]),
    "Singer3": Singer(dim=3, tau=30.0, sigma=0.5),
    "KnownTurn": KnownTurnRate(omega=0.3, q=0.2),
    "KnownTurn0": KnownTurnRate(omega=0.0, q=0.2),
    "CT": CoordinatedTurn(q=0.5, q_omega=1e-3),
    "RandomSine": RandomSine(q1=0.2, q2=0.1),
    "Linear": LinearMotion(_Fm, _Qm),
    "ContinuousLinear": ContinuousLinear(_A_cont, _L_cont, np.diag([0.2, 0.3])),
}


def _state_for(model, values):
    x = np.asarray(values[: model.dim_x], dtype=float)
    if isinstance(model, CoordinatedTurn):
        x[4] = np.clip(x[4], -3.0, 3.0)  # a turn rate, rad/s
    return x


state_values = st.lists(st.floats(-100, 100), min_size=9, max_size=9)
dts = st.floats(0.01, 5.0)


# --------------------------------------------------------------------------------------------
# Jacobians against finite differences
# --------------------------------------------------------------------------------------------


@FAST
@given(st.sampled_from(sorted(MODELS)), state_values, dts)
def test_motion_jacobian_matches_finite_differences(num, name, values, dt):
    model = MODELS[name]
    x = _state_for(model, values)
    J = np.broadcast_to(np.asarray(model.jacobian(x, dt)), (model.dim_x, model.dim_x))
    Jfd = num.jac(lambda p: model.f(p, dt), x)
    num.close(J, Jfd, rtol=1e-6, what=f"{name} jacobian at x={x}, dt={dt}")


turn_rates = st.one_of(
    st.just(0.0),
    st.floats(-1e-6, 1e-6),
    st.floats(-2e-3, 2e-3),  # straddles the |omega dt| < 1e-3 series branch
    st.floats(-1.0, 1.0),
    st.floats(-20.0, 20.0),  # large: several turns per step
)


@FAST
@given(
    st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.floats(-50, 50), st.floats(-50, 50),
    turn_rates, st.floats(0.01, 5.0),
)
def test_ct_jacobian_including_domega(num, px, py, vx, vy, w, dt):
    ct = MODELS["CT"]
    x = np.array([px, py, vx, vy, w])
    J = ct.jacobian(x, dt)
    Jfd = num.jac(lambda p: ct.f(p, dt), x)
    num.close(J, Jfd, rtol=1e-6, what=f"CT jacobian at x={x}, dt={dt}")


def test_ct_jacobian_domega_column_at_zero_turn_rate():
    # d/domega at omega = 0: x' -> -dt^2/2 vy, y' -> dt^2/2 vx, vx' -> -dt vy, vy' -> dt vx
    ct = CoordinatedTurn()
    vx, vy, dt = 3.0, -2.0, 0.7
    J = ct.jacobian(np.array([1.0, 2.0, vx, vy, 0.0]), dt)
    np.testing.assert_allclose(
        J[:, 4], [-dt**2 / 2 * vy, dt**2 / 2 * vx, -dt * vy, dt * vx, 1.0], rtol=1e-14
    )
    assert np.all(np.isfinite(J))


def test_ct_matches_the_thesis_turn_matrix():
    # the missing-measurements thesis's coordinated turn: F(omega) with sin(w dt)/w,
    # (cos(w dt) - 1)/w, ...
    ct = CoordinatedTurn()
    rng = np.random.default_rng(3)
    for _ in range(10):
        x = rng.uniform(-10, 10, 5)
        x[4] = rng.uniform(-2, 2)
        dt = rng.uniform(0.05, 3)
        w = x[4]
        s, c = np.sin(w * dt), np.cos(w * dt)
        F = np.array(
            [
                [1, 0, s / w, (c - 1) / w, 0],
                [0, 1, (1 - c) / w, s / w, 0],
                [0, 0, c, -s, 0],
                [0, 0, s, c, 0],
                [0, 0, 0, 0, 1],
            ]
        )
        np.testing.assert_allclose(ct.f(x, dt), F @ x, rtol=1e-12, atol=1e-12)


def test_ct_positive_omega_turns_counter_clockwise():
    # heading east with omega > 0 turns left (north): vy becomes positive
    ct = CoordinatedTurn()
    x1 = ct.f(np.array([0.0, 0.0, 10.0, 0.0, 0.5]), 1.0)
    assert x1[3] > 0 and x1[1] > 0


# --------------------------------------------------------------------------------------------
# CT continuity through omega = 0
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dt", [0.01, 0.5, 3.0])
def test_ct_continuity_at_zero_turn_rate(dt):
    ct = CoordinatedTurn()
    cv = ConstantVelocity(dim=2, q=1.0)
    base = np.array([100.0, -50.0, 12.0, -7.0])
    x_cv = cv.f(base, dt)
    x0 = ct.f(np.append(base, 0.0), dt)
    x_tiny = ct.f(np.append(base, 1e-9), dt)
    # omega = 0 is exactly straight-line motion
    np.testing.assert_allclose(x0[:4], x_cv, rtol=1e-15, atol=1e-12)
    assert x0[4] == 0.0
    # omega = 1e-9 moves the state by first-order amounts only: positions by
    # ~ omega dt^2 |v| / 2, velocities by ~ omega dt |v|
    speed = np.hypot(12.0, 7.0)
    err = np.abs(x_tiny[:4] - x0[:4])
    assert np.all(err[:2] <= 1e-9 * dt**2 * speed)
    assert np.all(err[2:] <= 1e-9 * dt * speed * 1.01)
    assert np.all(err > 0) or dt < 0.1  # the turn rate does act
    assert np.all(np.isfinite(ct.jacobian(np.append(base, 0.0), dt)))
    # Jacobian continuous too (its omega column changes by ~ omega dt^3 |v|)
    np.testing.assert_allclose(
        ct.jacobian(np.append(base, 1e-9), dt), ct.jacobian(np.append(base, 0.0), dt),
        rtol=0, atol=1e-9 * (dt + dt**3) * speed,
    )


@pytest.mark.parametrize("dt", [0.1, 1.0])
def test_ct_continuous_across_series_threshold(dt):
    # the series branch is used for |omega dt| < 1e-3; both sides must agree
    ct = CoordinatedTurn()
    w_c = 1e-3 / dt
    base = np.array([5.0, 6.0, 30.0, -20.0])
    below = np.append(base, np.nextafter(w_c, 0.0))
    above = np.append(base, w_c * (1 + 1e-12))
    np.testing.assert_allclose(ct.f(below, dt), ct.f(above, dt), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        ct.jacobian(below, dt), ct.jacobian(above, dt), rtol=1e-7, atol=1e-10
    )


def test_ct_batch_mixed_zero_and_nonzero_turn_rates():
    ct = CoordinatedTurn()
    X = np.array([[0, 0, 1, 2, 0.0], [0, 0, 1, 2, 1e-8], [1, 2, 3, 4, 0.4], [1, 2, 3, 4, -5.0]])
    dt = 0.8
    Y = ct.f(X, dt)
    J = ct.jacobian(X, dt)
    for i in range(len(X)):
        np.testing.assert_allclose(Y[i], ct.f(X[i], dt), rtol=1e-15, atol=0)
        np.testing.assert_allclose(J[i], ct.jacobian(X[i], dt), rtol=1e-15, atol=0)


# --------------------------------------------------------------------------------------------
# Closed forms: CV, CA, KnownTurnRate, RandomSine
# --------------------------------------------------------------------------------------------


def test_ct_f_and_jacobian_is_f_and_jacobian_bitwise():
    """The fused evaluation (one set of turn coefficients, used by the EKF prediction)
    equals f and jacobian to the last bit, on turn rates either side of the series threshold;
    a subclass that overrides f gets its own f."""
    ct = CoordinatedTurn(q=0.5, q_omega=1e-3)
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.normal(0, 1e3, (60, 2)), rng.normal(0, 10, (60, 2)),
                         np.concatenate([rng.normal(0, 1e-4, 30), rng.normal(0, 0.05, 30)])])
    for dt in (3.0, np.float64(0.5)):
        fx, F = ct.f_and_jacobian(x, dt)
        assert np.array_equal(fx, ct.f(x, dt)) and np.array_equal(F, ct.jacobian(x, dt))

    class Shifted(CoordinatedTurn):
        def f(self, x, dt):
            return super().f(x, dt) + 1.0

    fx, F = Shifted().f_and_jacobian(x, 3.0)
    assert np.array_equal(fx, CoordinatedTurn().f(x, 3.0) + 1.0)
    assert np.array_equal(F, CoordinatedTurn().jacobian(x, 3.0))


def test_cv_state_ordering_and_transition():
    cv = ConstantVelocity(dim=2, q=1.0)
    dt = 0.5
    x = np.array([1.0, 2.0, 3.0, -4.0])  # [x, y, vx, vy]
    np.testing.assert_allclose(cv.f(x, dt), [1 + 1.5, 2 - 2.0, 3.0, -4.0], rtol=1e-15)
    F = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]])
    np.testing.assert_array_equal(cv.jacobian(x, dt), F)
    cv3 = ConstantVelocity(dim=3)
    x3 = np.arange(6.0)  # [x, y, z, vx, vy, vz]
    np.testing.assert_allclose(cv3.f(x3, 2.0), [6, 9, 12, 3, 4, 5], rtol=1e-15)


@pytest.mark.parametrize("dt", [0.01, 0.5, 1.0, 7.0])
def test_cv_noise_closed_form_per_axis(dt):
    q = [0.3, 2.0]
    Q = ConstantVelocity(dim=2, q=q).noise(None, dt)
    qx, qy = q
    b = _cv_block(dt)
    expected = np.array(
        [
            [qx * b[0, 0], 0, qx * b[0, 1], 0],
            [0, qy * b[0, 0], 0, qy * b[0, 1]],
            [qx * b[1, 0], 0, qx * b[1, 1], 0],
            [0, qy * b[1, 0], 0, qy * b[1, 1]],
        ]
    )
    np.testing.assert_allclose(Q, expected, rtol=1e-15, atol=0)
    Q3 = ConstantVelocity(dim=3, q=[1.0, 2.0, 3.0]).noise(None, dt)
    np.testing.assert_allclose(Q3, _interleave(b, [1.0, 2.0, 3.0]), rtol=1e-15, atol=0)
    Q1 = ConstantVelocity(dim=1, q=0.4).noise(None, dt)
    np.testing.assert_allclose(Q1, 0.4 * b, rtol=1e-15, atol=0)


@pytest.mark.parametrize("dt", [0.1, 1.0, 3.0])
def test_ca_closed_form(dt):
    ca = ConstantAcceleration(dim=2, q=[0.5, 1.5])
    F1 = np.array([[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
    np.testing.assert_allclose(ca.jacobian(None, dt), _interleave(F1, [1, 1]), rtol=1e-15)
    np.testing.assert_allclose(ca.noise(None, dt), _interleave(_ca_block(dt), [0.5, 1.5]),
                               rtol=1e-15)
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])  # [x, y, vx, vy, ax, ay]
    np.testing.assert_allclose(
        ca.f(x, dt),
        [1 + 3 * dt + 5 * dt**2 / 2, 2 + 4 * dt + 6 * dt**2 / 2, 3 + 5 * dt, 4 + 6 * dt, 5, 6],
        rtol=1e-14,
    )


@pytest.mark.parametrize("dt", [0.2, 1.0, 4.0])
def test_discretize_reproduces_cv_and_ca(dt):
    for d in (1, 2, 3):
        # CV: dx/dt = [[0, I], [0, 0]] x + [0; I] w
        A = np.zeros((2 * d, 2 * d))
        A[:d, d:] = np.eye(d)
        L = np.vstack([np.zeros((d, d)), np.eye(d)])
        q = np.linspace(0.5, 1.5, d)
        F, Q = discretize(A, L, np.diag(q), dt)
        cv = ConstantVelocity(dim=d, q=q)
        np.testing.assert_allclose(F, cv.jacobian(None, dt), rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(Q, cv.noise(None, dt), rtol=1e-11, atol=1e-14)
        # CA
        A = np.zeros((3 * d, 3 * d))
        A[: 2 * d, d:] = np.eye(2 * d)
        L = np.vstack([np.zeros((2 * d, d)), np.eye(d)])
        F, Q = discretize(A, L, np.diag(q), dt)
        ca = ConstantAcceleration(dim=d, q=q)
        np.testing.assert_allclose(F, ca.jacobian(None, dt), rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(Q, ca.noise(None, dt), rtol=1e-10, atol=1e-14 * dt**5)


@pytest.mark.parametrize("dt", [0.1, 0.5, 1.0, 2.5])
def test_discretize_thesis_cwpa_uses_dt3_over_3(dt):
    # the missing-measurements thesis: A (2-65) and Q (2-66) with the corrected dt^3/3, times
    # q = 0.2
    A, L = _cwpa_A_L()
    F, Q = discretize(A, L, np.diag([0.2, 0.2]), dt)
    F_expected = np.array(
        [
            [1, 0, dt, 0, dt**2 / 2, 0],
            [0, 1, 0, dt, 0, dt**2 / 2],
            [0, 0, 1, 0, dt, 0],
            [0, 0, 0, 1, 0, dt],
            [0, 0, 0, 0, 1, 0],
            [0, 0, 0, 0, 0, 1],
        ]
    )
    Q_expected = _interleave(_ca_block(dt), [0.2, 0.2])
    np.testing.assert_allclose(F, F_expected, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(Q, Q_expected, rtol=1e-10, atol=1e-15)
    # the velocity variance is 0.2 dt^3/3, not the misprinted 0.2 dt^3/6
    assert Q[2, 2] == pytest.approx(0.2 * dt**3 / 3, rel=1e-10)
    assert abs(Q[2, 2] - 0.2 * dt**3 / 6) > 0.2 * dt**3 / 12


def test_discretize_batched_dt():
    A, L = _cwpa_A_L()
    dts = np.array([0.1, 0.5, 2.0])
    F, Q = discretize(A, L, np.diag([0.2, 0.3]), dts)
    assert F.shape == (3, 6, 6) and Q.shape == (3, 6, 6)
    for i, dt in enumerate(dts):
        Fi, Qi = discretize(A, L, np.diag([0.2, 0.3]), dt)
        np.testing.assert_allclose(F[i], Fi, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(Q[i], Qi, rtol=1e-14, atol=1e-15)


def test_discretize_rejects_bad_shapes():
    with pytest.raises(ValueError, match="A has shape"):
        discretize(np.zeros((2, 3)), np.zeros((2, 1)), [[1.0]], 1.0)
    with pytest.raises(ValueError, match="L has shape"):
        discretize(np.zeros((2, 2)), np.zeros((3, 1)), [[1.0]], 1.0)
    with pytest.raises(ValueError, match="Qc"):
        discretize(np.zeros((2, 2)), np.zeros((2, 1)), np.eye(2), 1.0)


@pytest.mark.parametrize(
    "dt, tau, sigma", [(1.0, 20.0, 1.0), (0.5, 2.0, 3.0), (5.0, 1.0, 0.5), (0.2, 4.0, 2.0),
                       (2.0, 60.0, 0.1)]
)
def test_singer_against_textbook_closed_form(dt, tau, sigma):
    F1, Q1 = _singer_closed_form(dt, tau, sigma)
    sing = Singer(dim=2, tau=tau, sigma=[sigma, 2 * sigma])
    np.testing.assert_allclose(sing.jacobian(None, dt), _interleave(F1, [1, 1]),
                               rtol=1e-12, atol=1e-14)
    # (the closed form itself loses ~1e-8 relative on q11 by cancellation when dt/tau is small)
    Qs = sing.noise(None, dt)
    Qe = _interleave(Q1, [1.0, 4.0])
    np.testing.assert_allclose(Qs, Qe, rtol=1e-6, atol=1e-12 * np.abs(Qe).max())


@pytest.mark.parametrize("ratio", [5.0, 10.0, 20.0, 50.0])
def test_singer_step_long_compared_with_tau(ratio):
    # dt >> tau is ordinary for a sonar (tau = 2 s manoeuvres, dt = 40 s updates). The
    # acceleration decorrelates, so its variance over the step tends to the stationary
    # sigma^2, and Q must equal the closed form (which is well conditioned for large dt/tau)
    # and stay positive semi-definite.
    tau, sigma = 2.0, 1.5
    dt = ratio * tau
    F1, Q1 = _singer_closed_form(dt, tau, sigma)
    sing = Singer(dim=1, tau=tau, sigma=sigma)
    # F: the acceleration decays by exp(-dt/tau); f() must use it
    np.testing.assert_allclose(sing.jacobian(None, dt), F1, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sing.f(np.array([0.0, 1.0, 1.0]), dt), F1 @ [0.0, 1.0, 1.0],
                               rtol=1e-9, atol=1e-9)
    Q = sing.noise(None, dt)
    assert Q[2, 2] == pytest.approx(sigma**2 * (1 - np.exp(-2 * ratio)), rel=1e-6)
    np.testing.assert_allclose(Q, Q1, rtol=1e-6)
    assert np.linalg.eigvalsh(Q).min() >= 0.0


def test_singer_long_tau_approaches_ca():
    tau, sigma, dt = 1e4, 2.0, 1.0
    sing = Singer(dim=2, tau=tau, sigma=sigma)
    ca = ConstantAcceleration(dim=2, q=2 * sigma**2 / tau)
    np.testing.assert_allclose(sing.jacobian(None, dt), ca.jacobian(None, dt), atol=1e-4)
    np.testing.assert_allclose(sing.noise(None, dt), ca.noise(None, dt), rtol=1e-3)


@pytest.mark.parametrize("omega", [0.0, 1e-9, 0.05, -0.7, 3.0])
@pytest.mark.parametrize("dt", [0.1, 1.0, 2.5])
def test_known_turn_rate_equals_coordinated_turn_at_fixed_omega(omega, dt):
    ktr = KnownTurnRate(omega=omega, q=0.3)
    ct = CoordinatedTurn(q=0.3, q_omega=0.01)
    rng = np.random.default_rng(11)
    X = rng.uniform(-20, 20, (5, 4))
    Xc = np.concatenate([X, np.full((5, 1), omega)], -1)
    np.testing.assert_allclose(ktr.f(X, dt), ct.f(Xc, dt)[:, :4], rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(ktr.jacobian(X, dt), ct.jacobian(Xc, dt)[0, :4, :4],
                               rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(ktr.noise(X, dt), ct.noise(Xc, dt)[:4, :4], rtol=1e-15)
    assert ct.noise(Xc, dt)[4, 4] == pytest.approx(0.01 * dt)


@pytest.mark.parametrize("dt", [0.01, 0.1, 1.0])
def test_random_sine_matches_thesis_eq_2_94_2_95(dt):
    q1, q2 = 0.2, 0.1
    m = RandomSine(q1=q1, q2=q2)
    A = np.array([[1, dt, 0], [0, 1, 0], [0, 0, 1]])
    Q = np.array(
        [[dt**3 * q1 / 3, dt**2 * q1 / 2, 0], [dt**2 * q1 / 2, dt * q1, 0], [0, 0, dt * q2]]
    )
    x = np.array([0.3, 10.0, 1.2])
    np.testing.assert_allclose(m.jacobian(x, dt), A, rtol=1e-15)
    np.testing.assert_allclose(m.f(x, dt), A @ x, rtol=1e-15)
    np.testing.assert_allclose(m.noise(x, dt), Q, rtol=1e-15, atol=0)
    # the two-state S6 variant is CV in one dimension with q = q1
    np.testing.assert_allclose(ConstantVelocity(dim=1, q=q1).noise(None, dt), Q[:2, :2],
                               rtol=1e-15)
    # continuous model 2-93 discretised by Van Loan gives the same (A, Q)
    Ac = np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0.0]])
    Lc = np.array([[0, 0], [1, 0], [0, 1.0]])
    Fd, Qd = discretize(Ac, Lc, np.diag([q1, q2]), dt)
    np.testing.assert_allclose(Fd, A, atol=1e-14)
    np.testing.assert_allclose(Qd, Q, rtol=1e-10, atol=1e-16)


# --------------------------------------------------------------------------------------------
# Batched dt and noise matrices
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(MODELS))
def test_batched_dt_equals_per_row_scalar_calls(name):
    model = MODELS[name]
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    B = 6
    X = rng.uniform(-10, 10, (B, model.dim_x))
    if isinstance(model, CoordinatedTurn):
        X[:, 4] = [0.0, 1e-9, 0.1, -0.5, 2.0, -3.0]
    dts = rng.uniform(0.05, 3.0, B)
    Y = model.f(X, dts)
    J = np.broadcast_to(model.jacobian(X, dts), (B, model.dim_x, model.dim_x))
    Qb = np.broadcast_to(model.noise(X, dts), (B, model.dim_x, model.dim_x))
    assert Y.shape == X.shape
    for i in range(B):
        np.testing.assert_allclose(Y[i], model.f(X[i], dts[i]), rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(J[i], model.jacobian(X[i], dts[i]), rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(Qb[i], model.noise(X[i], dts[i]), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_batched_state_scalar_dt(name):
    model = MODELS[name]
    rng = np.random.default_rng(5)
    X = rng.uniform(-10, 10, (2, 3, model.dim_x))
    if isinstance(model, CoordinatedTurn):
        X[..., 4] = rng.uniform(-1, 1, (2, 3))
    Y = model.f(X, 0.7)
    assert Y.shape == X.shape
    for idx in np.ndindex(2, 3):
        np.testing.assert_allclose(Y[idx], model.f(X[idx], 0.7), rtol=1e-14, atol=1e-13)


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("dt", [0.01, 0.3, 1.0, 10.0])
def test_noise_symmetric_psd(name, dt):
    model = MODELS[name]
    x = np.linspace(-1, 1, model.dim_x)
    Q = np.asarray(model.noise(x, dt))
    assert Q.shape[-2:] == (model.dim_x, model.dim_x)
    np.testing.assert_array_equal(Q, np.swapaxes(Q, -1, -2))
    ev = np.linalg.eigvalsh(Q)
    assert ev.min() >= -1e-12 * max(1.0, np.abs(Q).max())
    assert np.all(np.isfinite(Q))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_returned_matrices_cannot_change_the_model(name):
    # F and Q may be cached per dt; a caller writing into a returned matrix must neither
    # succeed silently nor change what the model returns next time
    model = MODELS[name]
    x = np.linspace(-1, 1, model.dim_x)
    for get in (model.jacobian, model.noise):
        first = np.array(get(x, 0.5), copy=True)
        M = get(x, 0.5)
        try:
            M[..., 0, 0] += 1.0
        except ValueError:
            pass  # read-only: fine
        np.testing.assert_array_equal(get(x, 0.5), first)


def test_models_are_frozen():
    cv = ConstantVelocity(dim=2, q=1.0)
    with pytest.raises(AttributeError):
        cv.q = 2.0  # type: ignore[misc]


def test_public_namespace():
    assert tk.models.ConstantVelocity is ConstantVelocity
    assert tk.models.discretize is discretize
