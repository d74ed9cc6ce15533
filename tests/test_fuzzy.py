"""Fuzzy-adaptive Kalman filtering of Naseri Solhdar (trackkit.filters.fuzzy): the Mamdani system,
the windowed matching covariance, the DOM cost and the OFKF / OFEKF / OFUKF wrapper.

Expectations are computed by hand in the tests (explicit formulas, ``np.linalg.inv``, Python
loops over lists of innovations), never with the library's kernels, so every test could fail.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackkit.belief import Gaussian
from trackkit.filters import EKF, KF, UKF, FuzzyAdaptive, FuzzyBelief
from trackkit.filters.adaptive import push_innovation
from trackkit.filters.fuzzy import (
    DEFAULT_PARAMS,
    N_PARAMS,
    PARAM_BOUNDS,
    dom_cost,
    fis,
    matching_covariance,
)
from trackkit.models import (
    AzimuthElevation,
    Bearing,
    ConstantVelocity,
    LinearMotion,
    Position,
    with_noise,
)

FAST = settings(max_examples=60, deadline=None, derandomize=True, database=None)

# Naseri Solhdar's chapter-3 benchmark: 3 states, z = [x1, x2] + v.
F3 = np.array([[0.77, 0.20, 0.0], [0.22, 0.72, 0.22], [0.02, 0.0, 0.72]])
Q3 = 0.02 * np.eye(3)
R_TRUE = np.diag([0.8, 9.0])
H3 = np.eye(2, 3)


def params_of(c, s, y) -> np.ndarray:
    return np.concatenate([np.asarray(c, float), np.asarray(s, float), np.asarray(y, float)])


def fis_ref(p, x: float) -> float:
    """The centre-average Mamdani output written out term by term (moderate x only), the
    input first saturated to [c_1, c_5]."""
    c, s, y = p[0:5], p[5:10], p[10:15]
    x = min(max(x, c[0]), c[4])
    mu = [math.exp(-(((x - c[k]) / s[k]) ** 2)) for k in range(5)]
    return sum(y[k] * mu[k] for k in range(5)) / sum(mu)


def simulate_linear(T: int, B: int, seed: int, R=R_TRUE) -> np.ndarray:
    """Measurements (T, B, 2) of the chapter-3 system from x0 = 0."""
    rng = np.random.default_rng(seed)
    x = np.zeros((B, 3))
    sd = np.sqrt(np.diag(R))
    zs = []
    for _ in range(T):
        x = x @ F3.T + rng.standard_normal((B, 3)) * np.sqrt(np.diag(Q3))
        zs.append(x[:, :2] + rng.standard_normal((B, 2)) * sd)
    return np.array(zs)


def prior(B: int | None = None) -> Gaussian:
    if B is None:
        return Gaussian(np.zeros(3), 0.01 * np.eye(3))
    return Gaussian(np.zeros((B, 3)), np.broadcast_to(0.01 * np.eye(3), (B, 3, 3)).copy())


def run(f, z, sensor, motion, b0, dt: float = 1.0):
    """Filter the sequence; returns the beliefs after each update and the innovations."""
    b = f.init(b0)
    beliefs, innovs = [], []
    for k in range(len(z)):
        b = f.predict(b, motion, dt)
        b, innov = f.update(b, z[k], sensor)
        beliefs.append(b)
        innovs.append(innov)
    return beliefs, innovs


def diag(M):
    return np.diagonal(M, axis1=-2, axis2=-1)


# --------------------------------------------------------------------------------------------
# The Mamdani system
# --------------------------------------------------------------------------------------------


def test_fis_at_each_centre_of_narrow_well_separated_sets_is_that_rules_output():
    # Centres 2 apart, widths 0.1: at a centre the own membership is 1 and every other one is
    # at most exp(-(2 / 0.1)^2) = exp(-400) ~ 1e-174, so y equals the rule's output centre to
    # within 1e-174 * max|ybar| (far below the 1e-12 asserted).
    p = params_of([-4, -2, 0, 2, 4], [0.1] * 5, [3.0, 1.0, 0.25, -1.0, -3.0])
    out = fis(p, p[0:5])
    np.testing.assert_allclose(out, p[10:15], rtol=0, atol=1e-12)
    # and halfway between two sets the two rules share equally
    np.testing.assert_allclose(fis(p, [-3.0, 1.0]), [(3.0 + 1.0) / 2, (0.25 - 1.0) / 2],
                               rtol=0, atol=1e-12)


def test_fis_hand_computed_value():
    # c = (-2, -1, 0, 1, 2), s = (1, 0.5, 1, 2, 1), ybar = (1, 0.5, 0, -0.5, -1), x = 0.5:
    # ((x - c) / s)^2 = (6.25, 9, 0.25, 0.0625, 2.25), so
    # y = (e^-6.25 + 0.5 e^-9 + 0 e^-0.25 - 0.5 e^-0.0625 - e^-2.25)
    #     / (e^-6.25 + e^-9 + e^-0.25 + e^-0.0625 + e^-2.25) = -0.3139201275629969
    p = params_of([-2, -1, 0, 1, 2], [1, 0.5, 1, 2, 1], [1, 0.5, 0, -0.5, -1])
    e = math.exp
    num = e(-6.25) + 0.5 * e(-9) + 0.0 * e(-0.25) - 0.5 * e(-0.0625) - e(-2.25)
    den = e(-6.25) + e(-9) + e(-0.25) + e(-0.0625) + e(-2.25)
    assert float(fis(p, 0.5)) == pytest.approx(num / den, rel=1e-14)
    assert float(fis(p, 0.5)) == pytest.approx(-0.3139201275629969, rel=1e-14)
    assert np.shape(fis(p, 0.5)) == ()


@FAST
@given(
    a1=st.floats(0.1, 3.0), gap=st.floats(0.1, 3.0), s=st.floats(0.1, 3.0),
    b1=st.floats(0.0, 2.0), bgap=st.floats(0.0, 2.0),
)
def test_fis_symmetric_system_is_monotone_odd_and_zero_at_zero(a1, gap, s, b1, bgap):
    # centres symmetric about 0, equal widths, outputs antisymmetric and decreasing: then
    # dy/dx = (2 / s^2) Cov_w(ybar, c) <= 0 (w the normalised memberships, an exponential
    # family in x with statistic c) and y(-x) = -y(x).
    a2, b2 = a1 + gap, b1 + bgap
    p = params_of([-a2, -a1, 0, a1, a2], [s] * 5, [b2, b1, 0, -b1, -b2])
    x = np.linspace(-3 * a2 - 3 * s, 3 * a2 + 3 * s, 2001)
    y = fis(p, x)
    scale = max(b2, 1e-300)
    assert np.all(np.diff(y) <= 1e-12 * scale), np.diff(y).max()
    assert abs(float(fis(p, 0.0))) <= 1e-15 * scale
    np.testing.assert_allclose(y, -y[::-1], rtol=0, atol=1e-13 * scale)
    assert np.all(np.abs(y) <= b2 * (1 + 1e-12))


def test_default_params_are_symmetric_monotone_and_zero_at_zero():
    p = DEFAULT_PARAMS
    x = np.linspace(-10, 10, 4001)
    y = fis(p, x)
    assert np.all(np.diff(y) <= 1e-15)
    assert abs(float(fis(p, 0.0))) < 1e-17
    assert float(fis(p, -2.0)) > 0.19 and float(fis(p, 2.0)) < -0.19  # close to IL / DL
    assert np.all((PARAM_BOUNDS[:, 0] <= p) & (p <= PARAM_BOUNDS[:, 1]))


def test_fis_saturates_far_inputs_to_the_outer_centres_and_never_gives_nan():
    p = params_of([-2, -1, 0, 1, 2], [0.6] * 5, [0.2, 0.05, 0.0, -0.05, -0.2])
    # the naive ratio would be 0/0 there: every membership underflows to exactly 0
    for x in (-1e6, 1e6):
        assert np.all(np.exp(-(((x - p[0:5]) / p[5:10]) ** 2)) == 0.0)
    out = fis(p, [-1e6, 1e6, -1e3, 1e3, -2.5, np.inf, -np.inf])
    assert np.all(np.isfinite(out))
    np.testing.assert_array_equal(out, fis(p, [-2.0, 2.0, -2.0, 2.0, -2.0, 2.0, -2.0]))
    assert out[0] == pytest.approx(fis_ref(p, -2.0), rel=1e-14) and out[0] > 0.19
    # narrow sets: the far output is the outer rule's output centre (the neighbours weigh
    # exp(-(2 / 0.1)^2) ~ 1e-174 relative)
    q = params_of([-4, -2, 0, 2, 4], [0.1] * 5, [3.0, 1.0, 0.0, -1.0, -3.0])
    np.testing.assert_allclose(fis(q, [-1e6, 1e6]), [3.0, -3.0], rtol=0, atol=1e-12)
    # with a wide PS set (width 5) a far negative input is not claimed by PS: it still
    # increases (without saturation the widest set would win far out on either side, and
    # the output would be PS's -0.05)
    w = params_of([-2, -1, 0, 1, 2], [0.6, 0.6, 0.6, 5.0, 0.6], [0.2, 0.05, 0.0, -0.05, -0.2])
    assert float(fis(w, -1e6)) == float(fis(w, -2.0)) > 0.0
    assert float(fis(w, -1e6)) == pytest.approx(fis_ref(w, -2.0), rel=1e-14)


def test_fis_batched_params_broadcast_like_row_by_row():
    rng = np.random.default_rng(11)
    P, m = 6, 4
    params = rng.uniform(PARAM_BOUNDS[:, 0], PARAM_BOUNDS[:, 1], (P, N_PARAMS))
    x = rng.normal(0, 2, (P, m))
    out = fis(params[:, None, :], x)  # (P, 1, 15) against (P, m): one system per row
    assert out.shape == (P, m)
    for i in range(P):
        for j in range(m):
            assert out[i, j] == pytest.approx(fis_ref(params[i], x[i, j]), rel=1e-12, abs=1e-15)
            assert out[i, j] == float(fis(params[i], x[i, j]))
    # (P, 15) against x (P,): one input per system
    out1 = fis(params, x[:, 0])
    assert out1.shape == (P,)
    np.testing.assert_array_equal(out1, out[:, 0])
    # one system against many inputs
    np.testing.assert_array_equal(fis(params[2], x), [[float(fis(params[2], v)) for v in r]
                                                      for r in x])


@pytest.mark.parametrize("shape", [(14,), (16,), (3, 10)])
def test_fis_bad_parameter_shape_raises_naming_the_parameters(shape):
    with pytest.raises(ValueError, match=r"fuzzy parameters.*15"):
        fis(np.ones(shape), 0.0)


def test_fis_scalar_parameters_raise_value_error():
    with pytest.raises(ValueError, match="fuzzy parameters"):
        fis(1.0, 0.0)


@pytest.mark.parametrize("width", [0.0, -0.6])
def test_fis_non_positive_width_raises(width):
    p = np.array(DEFAULT_PARAMS)
    p[7] = width
    with pytest.raises(ValueError, match="width"):
        fis(p, 0.3)


# --------------------------------------------------------------------------------------------
# Matching covariance and the DOM cost
# --------------------------------------------------------------------------------------------


def _push_all(rs, N):
    buf, count = np.zeros((N, 0)), np.zeros((), np.int64)
    states = []
    for r in rs:
        buf, count = push_innovation(buf, count, np.asarray(r), np.ones((), bool), N, (),
                                     "test")
        states.append((buf, count))
    return states


def _hand_C(rs, k, N):
    """(1/N) sum of the outer products of the last N of rs[:k + 1], or 0 before N."""
    if k + 1 < N:
        return np.zeros((len(rs[0]), len(rs[0])))
    C = np.zeros((len(rs[0]), len(rs[0])))
    for r in rs[k + 1 - N:k + 1]:
        C += np.outer(r, r)
    return C / N


def test_matching_covariance_zero_until_full_then_mean_of_last_N_outer_products():
    N = 5
    rng = np.random.default_rng(2)
    rs = [rng.normal(0, [1.0, 3.0]) for _ in range(2 * N + 3)]  # wraps the ring twice
    for k, (buf, count) in enumerate(_push_all(rs, N)):
        assert int(count) == k + 1
        C = matching_covariance(buf, count)
        if k + 1 < N:
            np.testing.assert_array_equal(C, 0.0)
        else:
            np.testing.assert_allclose(C, _hand_C(rs, k, N), rtol=1e-13, atol=1e-15)
    # after 2N + 3 pushes slot (2N + 2) mod N holds the last innovation
    buf, _ = _push_all(rs, N)[-1]
    np.testing.assert_array_equal(buf[(2 * N + 2) % N], rs[-1])


def test_matching_covariance_batched_rows_with_different_counts():
    N = 3
    rng = np.random.default_rng(4)
    rs = rng.normal(size=(7, 2, 2))  # (steps, rows, m)
    keep = np.array([[True, True]] * 7)
    keep[[1, 4], 1] = False  # row 1 misses two innovations
    buf, count = np.zeros((2, N, 0)), np.zeros(2, np.int64)
    kept = [[], []]
    for k in range(7):
        buf, count = push_innovation(buf, count, rs[k], keep[k], N, (2,), "test")
        for i in range(2):
            if keep[k, i]:
                kept[i].append(rs[k, i])
        C = matching_covariance(buf, count)
        for i in range(2):
            assert count[i] == len(kept[i])
            np.testing.assert_allclose(C[i], _hand_C(kept[i], len(kept[i]) - 1, N),
                                       rtol=1e-13, atol=1e-15)


def test_dom_cost_is_alpha_sum_of_rms_of_the_diagonal_on_a_synthetic_sequence():
    rng = np.random.default_rng(5)
    K, m, alpha = 37, 3, 1000.0
    doms = [rng.normal(0, [0.5, 2.0, 0.1]) for _ in range(K)]  # DOM_k(i,i), k = 1..K
    expected = alpha * sum(math.sqrt(sum(d[i] ** 2 for d in doms) / K) for i in range(m))
    sq = np.sum(np.square(doms), axis=0)
    assert float(dom_cost(sq, K, alpha)) == pytest.approx(expected, rel=1e-13)
    assert float(dom_cost(sq, K)) == pytest.approx(expected, rel=1e-13)  # default alpha 1000
    assert float(dom_cost(sq, K, 5000.0)) == pytest.approx(5 * expected, rel=1e-13)
    # batched running sums (..., m)
    sq2 = np.stack([sq, 4 * sq])
    np.testing.assert_allclose(dom_cost(sq2, K, alpha), [expected, 2 * expected], rtol=1e-13)


# --------------------------------------------------------------------------------------------
# FuzzyAdaptive: reductions and adaptation
# --------------------------------------------------------------------------------------------


def zero_output(p=DEFAULT_PARAMS):
    q = np.array(p)
    q[10:15] = 0.0
    return q


@pytest.mark.parametrize("adapt", ["R", "Q"])
@pytest.mark.parametrize("normalise", ["current", "initial", "none"])
def test_zero_output_centres_give_the_plain_kf_step_by_step(adapt, normalise):
    T, B = 60, 3
    z = simulate_linear(T, B, seed=7)
    sensor = Position(dim=2, sigma=[1.0, 2.0])  # R0 = diag(1, 4), wrong on purpose
    motion = LinearMotion(F3, np.diag([0.5, 0.01, 0.3]))
    f = FuzzyAdaptive(KF(), zero_output(), adapt=adapt, normalise=normalise,
                      q_inputs=((0, 0), (1, 1), (0, 1)) if adapt == "Q" else None)
    fb, fi = run(f, z, sensor, motion, prior(B))
    kb, ki = run(KF(), z, sensor, motion, prior(B))
    for k in range(T):
        np.testing.assert_allclose(fb[k].mean, kb[k].mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(fb[k].cov, kb[k].cov, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(fi[k].cov, ki[k].cov, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(fb[k].R, np.broadcast_to(sensor.noise, (B, 2, 2)),
                                   rtol=1e-15, atol=0)
    assert np.all(fb[-1].count == T)


@pytest.mark.parametrize("factor", [0.1, 10.0])
def test_r_moves_from_a_tenfold_wrong_r0_to_the_truth(factor):
    # 20 runs of 400 steps of the chapter-3 system, R0 = factor * R_true, untuned default
    # system. After the window fills R is multiplied by at most 1.2 (or 0.8) per step, so it
    # needs ~20 steps to cover a factor 10; over steps 200..399 the geometric mean of
    # R / R_true over runs and steps must be within 25 % of 1. The windowed estimate C has a
    # relative sd of sqrt(2/25) = 0.28 per window, and the 20 x 200 steps hold ~160
    # independent windows, so the sd of the log mean is ~0.02: 25 % is > 10 sd, while a
    # filter that does not adapt sits at a factor 10.
    T, B = 400, 20
    z = simulate_linear(T, B, seed=1)
    R0 = factor * R_TRUE
    sensor = Position(dim=2, sigma=np.sqrt(np.diag(R0)))
    beliefs, _ = run(FuzzyAdaptive(KF()), z, sensor, LinearMotion(F3, Q3), prior(B))
    R = np.array([diag(b.R) for b in beliefs])  # (T, B, 2)
    R0 = sensor.noise  # = factor R_true up to the rounding of sigma^2
    np.testing.assert_array_equal(R[:24], np.broadcast_to(np.diag(R0), (24, B, 2)))
    # the first adaptation moves every run in the right direction
    if factor < 1:
        assert np.all(R[24] > np.diag(R0)) and np.all(R[60:].mean(0) > 4 * np.diag(R0))
    else:
        assert np.all(R[24] < np.diag(R0)) and np.all(R[60:].mean(0) < 0.25 * np.diag(R0))
    ratio = np.exp(np.log(R[200:] / np.diag(R_TRUE)).mean((0, 1)))
    assert np.all(np.abs(ratio - 1) < 0.25), ratio


def test_warmup_wait_keeps_r_and_c_zero_until_the_window_is_full():
    N, T, B = 25, 30, 2
    z = simulate_linear(T, B, seed=3)
    sensor = Position(dim=2, sigma=[0.3, 1.0])
    beliefs, innovs = run(FuzzyAdaptive(KF(), window=N), z, sensor, LinearMotion(F3, Q3),
                          prior(B))
    for k in range(N - 1):
        np.testing.assert_array_equal(beliefs[k].R, np.broadcast_to(sensor.noise, (B, 2, 2)))
        np.testing.assert_array_equal(beliefs[k].C, 0.0)
        np.testing.assert_array_equal(beliefs[k].count, k + 1)
        np.testing.assert_array_equal(beliefs[k].dom, beliefs[k].S)
    # the N-th update has a full window: C is the mean of the N outer products and R moves
    k = N - 1
    for i in range(B):
        C = sum(np.outer(innovs[j].nu[i], innovs[j].nu[i]) for j in range(N)) / N
        np.testing.assert_allclose(beliefs[k].C[i], C, rtol=1e-12)
        S = innovs[k].cov[i]
        np.testing.assert_allclose(beliefs[k].S[i], S, rtol=1e-15)
        R0 = np.diag(sensor.noise)
        expected = [R0[j] + R0[j] * fis_ref(DEFAULT_PARAMS, (S[j, j] - C[j, j]) / S[j, j])
                    for j in range(2)]
        np.testing.assert_allclose(diag(beliefs[k].R[i]), expected, rtol=1e-12)
    assert not np.allclose(diag(beliefs[k].R), np.diag(sensor.noise), rtol=1e-3)


def test_warmup_adapt_starts_at_the_first_update_with_partial_window():
    # with warmup="adapt" the first update adapts with C = 0 (window not full), so
    # DOM = S and the normalised input is 1: R1 = R0 (1 + FIS(1))
    z = simulate_linear(1, 1, seed=3)[:, 0]
    sensor = Position(dim=2, sigma=[0.3, 1.0])
    f = FuzzyAdaptive(KF(), warmup="adapt")
    b, _ = f.update(f.predict(f.init(prior()), LinearMotion(F3, Q3), 1.0), z[0], sensor)
    np.testing.assert_array_equal(b.C, 0.0)
    np.testing.assert_allclose(diag(b.R), np.diag(sensor.noise) * (1 + fis_ref(DEFAULT_PARAMS,
                                                                                 1.0)),
                               rtol=1e-13)
    assert fis_ref(DEFAULT_PARAMS, 1.0) < -0.04  # so this really decreased R


def _one_step_by_hand(m0, P0, z, F, Q, R):
    x = F @ m0
    P = F @ P0 @ F.T + Q
    S = H3 @ P @ H3.T + R
    K = P @ H3.T @ np.linalg.inv(S)
    r = z - H3 @ x
    return x + K @ r, (np.eye(3) - K @ H3) @ P, r, S


@pytest.mark.parametrize("normalise", ["current", "initial", "none"])
def test_r_adaptation_one_step_by_hand_and_used_at_the_next_update(normalise):
    # window 1 so that C = r r^T after the first innovation; warmup "adapt"
    R0 = np.array([[2.0, 0.3], [0.3, 5.0]])  # the off-diagonal entry must stay as it is
    sensor = with_noise(Position(dim=2, sigma=1.0), R0)
    motion = LinearMotion(F3, Q3)
    p = params_of([-2, -1, 0, 1, 2], [1.0, 0.7, 0.5, 0.8, 1.2], [0.4, 0.1, 0.0, -0.1, -0.3])
    f = FuzzyAdaptive(KF(), p, window=1, normalise=normalise, warmup="adapt")
    m0, P0 = np.array([0.5, -1.0, 0.2]), np.diag([0.3, 0.2, 0.1])
    z = np.array([[1.7, -4.0], [0.2, 3.0]])
    b, innov = f.update(f.predict(f.init(Gaussian(m0, P0)), motion, 1.0), z[0], sensor)
    x1, P1, r, S = _one_step_by_hand(m0, P0, z[0], F3, Q3, R0)
    np.testing.assert_allclose(b.mean, x1, rtol=1e-12)
    np.testing.assert_allclose(b.C, np.outer(r, r), rtol=1e-13)
    dom = S - np.outer(r, r)
    R1 = R0.copy()
    for i in range(2):
        if normalise == "current":
            adj = R0[i, i] * fis_ref(p, dom[i, i] / S[i, i])
        elif normalise == "initial":
            adj = R0[i, i] * fis_ref(p, dom[i, i] / R0[i, i])
        else:
            adj = fis_ref(p, dom[i, i])
        R1[i, i] = R0[i, i] + adj
    assert np.all(np.abs(np.diag(R1) - np.diag(R0)) > 5e-4)  # a real adjustment
    np.testing.assert_allclose(b.R, R1, rtol=1e-12)
    np.testing.assert_allclose(b.dom, dom, rtol=1e-12, atol=1e-12)
    # the next update uses R1
    b2, innov2 = f.update(f.predict(b, motion, 1.0), z[1], sensor)
    x2, P2, r2, S2 = _one_step_by_hand(x1, P1, z[1], F3, Q3, R1)
    np.testing.assert_allclose(innov2.cov, S2, rtol=1e-12)
    np.testing.assert_allclose(b2.mean, x2, rtol=1e-11)
    np.testing.assert_allclose(b2.cov, P2, rtol=1e-11)


@pytest.mark.parametrize("normalise", ["none", "current", "initial"])
def test_q_adaptation_one_step_by_hand_with_the_off_diagonal_input_squared(normalise):
    # Q(j,j) += ref_out FIS(d_j / ref_in) with d = (DOM(0,0), DOM(1,1), DOM(0,1)^2)
    # (thesis eq 3-21); for "none" ref_in = ref_out = 1.
    Q0 = np.array([[0.5, 0.05, 0.0], [0.05, 0.3, 0.02], [0.0, 0.02, 0.4]])
    motion = LinearMotion(F3, Q0)
    R = np.diag([0.8, 9.0])
    sensor = Position(dim=2, sigma=np.sqrt(np.diag(R)))
    p = params_of([-2, -1, 0, 1, 2], [1.5, 1.0, 0.8, 1.0, 1.5], [0.3, 0.1, 0.0, -0.1, -0.2])
    pairs = ((0, 0), (1, 1), (0, 1))
    f = FuzzyAdaptive(KF(), p, adapt="Q", window=1, normalise=normalise, warmup="adapt",
                      q_inputs=pairs)
    m0, P0 = np.array([0.5, -1.0, 0.2]), np.diag([0.3, 0.2, 0.1])
    z = np.array([[1.1, -2.5], [0.4, 1.0]])
    b = f.predict(f.init(Gaussian(m0, P0)), motion, 1.0)
    np.testing.assert_array_equal(b.Q, Q0)
    np.testing.assert_array_equal(b.Q0, np.diag(Q0))
    b, _ = f.update(b, z[0], sensor)
    x1, P1, r, S = _one_step_by_hand(m0, P0, z[0], F3, Q0, R)
    dom = S - np.outer(r, r)
    d = [dom[0, 0], dom[1, 1], dom[0, 1] ** 2]
    if normalise == "none":
        ref_in, ref_out = [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]
    elif normalise == "current":
        ref_in = [S[0, 0], S[1, 1], S[0, 0] * S[1, 1]]
        ref_out = list(np.diag(Q0))
    else:
        ref_in = [R[0, 0], R[1, 1], R[0, 0] * R[1, 1]]
        ref_out = list(np.diag(Q0))
    Q1 = Q0.copy()
    for j in range(3):
        Q1[j, j] = Q0[j, j] + ref_out[j] * fis_ref(p, d[j] / ref_in[j])
    assert np.all(np.abs(np.diag(Q1) - np.diag(Q0)) > 1e-4)
    np.testing.assert_allclose(b.Q, Q1, rtol=1e-12)
    np.testing.assert_array_equal(b.R, sensor.noise)  # R is known and stays
    # the next prediction uses Q1
    b2 = f.predict(b, motion, 1.0)
    np.testing.assert_allclose(b2.cov, F3 @ P1 @ F3.T + Q1, rtol=1e-12)
    np.testing.assert_array_equal(b2.Q0, np.diag(Q0))


@pytest.mark.parametrize("adapt", ["R", "Q"])
def test_floor_and_ceiling_hold_against_a_system_that_pushes_hard(adapt):
    T, B = 40, 2
    z = simulate_linear(T, B, seed=9)
    sensor = Position(dim=2, sigma=[1.0, 2.0])
    motion = LinearMotion(F3, np.diag([0.1, 0.2, 0.3]))
    for y, bound in ((50.0, "ceiling"), (-50.0, "floor")):
        p = zero_output()
        p[10:15] = y
        f = FuzzyAdaptive(KF(), p, adapt=adapt, floor=0.05, ceiling=20.0, warmup="adapt",
                          normalise="none", q_inputs=((0, 0), (1, 1), (0, 1)))
        beliefs, _ = run(f, z, sensor, motion, prior(B))
        ref = np.diag(sensor.noise) if adapt == "R" else np.array([0.1, 0.2, 0.3])
        for b in beliefs:
            v = diag(b.R if adapt == "R" else b.Q)
            assert np.all(v >= 0.05 * ref * (1 - 1e-15)) and np.all(v <= 20.0 * ref * (1 + 1e-15))
            assert np.all(np.isfinite(b.mean)) and np.all(np.isfinite(b.cov))
        # two pushes of +-50 take every entry (at most 4 = R0(1,1)) to its bound
        final = diag(beliefs[1].R if adapt == "R" else beliefs[1].Q)
        np.testing.assert_allclose(final, np.broadcast_to((20.0 if bound == "ceiling" else 0.05)
                                                          * ref, final.shape), rtol=1e-15)


def test_missing_measurement_row_keeps_the_prediction_and_the_adaptation_memory():
    T, B, k_miss = 32, 3, 28
    z = simulate_linear(T, B, seed=12)
    zm = z.copy()
    zm[k_miss, 1] = np.nan
    sensor = Position(dim=2, sigma=[0.3, 1.0])
    motion = LinearMotion(F3, Q3)
    f = FuzzyAdaptive(KF())
    b = f.init(prior(B))
    ref, _ = run(f, z, sensor, motion, prior(B))
    for k in range(T):
        pred = f.predict(b, motion, 1.0)
        b, innov = f.update(pred, zm[k], sensor)
        if k == k_miss:
            np.testing.assert_array_equal(b.mean[1], pred.mean[1])
            np.testing.assert_array_equal(b.cov[1], pred.cov[1])
            np.testing.assert_array_equal(b.R[1], pred.R[1])
            np.testing.assert_array_equal(b.residuals[1], pred.residuals[1])
            assert b.count[1] == pred.count[1] == k
            assert np.all(np.isnan(innov.nu[1]))
            # R of row 1 would have moved with the measurement: the test can fail
            assert not np.array_equal(ref[k].R[1], pred.R[1])
        if k <= k_miss:  # the other rows are unaffected
            for i in (0, 2):
                np.testing.assert_array_equal(b.mean[i], ref[k].mean[i])
                np.testing.assert_array_equal(b.R[i], ref[k].R[i])
    assert b.count.tolist() == [T, T - 1, T]
    assert np.all(np.isfinite(b.mean)) and np.all(np.isfinite(b.R))


@pytest.mark.parametrize("adapt", ["R", "Q"])
def test_a_population_of_params_in_one_batch_equals_each_alone(adapt):
    rng = np.random.default_rng(21)
    P, T = 5, 50
    params = rng.uniform(PARAM_BOUNDS[:, 0], PARAM_BOUNDS[:, 1], (P, N_PARAMS))
    z = simulate_linear(T, 1, seed=5)[:, 0]
    sensor = Position(dim=2, sigma=[0.5, 1.5])
    motion = LinearMotion(F3, np.diag([0.5, 0.05, 0.3]))
    kw = dict(adapt=adapt, q_inputs=((0, 0), (1, 1), (0, 1)) if adapt == "Q" else None)
    batch, _ = run(FuzzyAdaptive(KF(), params, **kw), np.broadcast_to(z[:, None], (T, P, 2)),
                   sensor, motion, prior(P))
    moved = False
    for i in range(P):
        alone, _ = run(FuzzyAdaptive(KF(), **kw).with_params(params[i]), z, sensor, motion,
                       prior())
        for k in (0, 24, 25, T - 1):
            np.testing.assert_allclose(batch[k].mean[i], alone[k].mean, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(batch[k].cov[i], alone[k].cov, rtol=1e-12, atol=1e-15)
            np.testing.assert_allclose(batch[k].R[i], alone[k].R, rtol=1e-12)
            np.testing.assert_allclose(batch[k].Q[i], alone[k].Q, rtol=1e-12)
            np.testing.assert_allclose(batch[k].C[i], alone[k].C, rtol=1e-12, atol=1e-15)
        moved |= not np.allclose(alone[-1].R if adapt == "R" else alone[-1].Q,
                                 sensor.noise if adapt == "R" else motion.Q)
    assert moved  # the candidates really adapted
    # the rows differ from each other (the population is not one system)
    assert not np.allclose(batch[-1].mean[0], batch[-1].mean[1])


# --------------------------------------------------------------------------------------------
# Names, settings and errors
# --------------------------------------------------------------------------------------------


def test_names_follow_the_base_filter_and_with_params_keeps_the_settings():
    assert FuzzyAdaptive(KF()).name == "OFKF"
    assert FuzzyAdaptive(EKF()).name == "OFEKF"
    assert FuzzyAdaptive(UKF()).name == "OFUKF"
    assert FuzzyAdaptive().name == "OFEKF"  # default base
    f = FuzzyAdaptive(UKF(), adapt="Q", window=7, normalise="none", floor=0.1, ceiling=9.0,
                      warmup="adapt", q_inputs=[(0, 0), (1, 1)])
    g = f.with_params(np.ones((4, N_PARAMS)))
    assert g.base is f.base and g.name == "OFUKF"
    assert (g.adapt, g.window, g.normalise, g.floor, g.ceiling, g.warmup, g.q_inputs) == (
        "Q", 7, "none", 0.1, 9.0, "adapt", ((0, 0), (1, 1)))
    assert g.params.shape == (4, N_PARAMS)
    np.testing.assert_array_equal(f.params, DEFAULT_PARAMS)
    with pytest.raises(ValueError):
        f.params[0] = 1.0  # read-only


@pytest.mark.parametrize("kwargs, field", [
    (dict(base=FuzzyAdaptive(KF())), "base"),
    (dict(base=object()), "base"),
    (dict(params=np.ones(14)), "params"),
    (dict(params=np.ones((3, 16))), "params"),
    (dict(params=np.full(15, np.nan)), "params"),
    (dict(params=np.where(np.arange(15) == 6, 0.0, DEFAULT_PARAMS)), "widths"),
    (dict(params=np.where(np.arange(15) == 9, -1.0, DEFAULT_PARAMS)), "widths"),
    (dict(params=np.r_[[2.0, 1.0, 0.0, -1.0, -2.0], DEFAULT_PARAMS[5:]]), "increasing order"),
    (dict(params=np.where(np.arange(15) == 1, -3.0, DEFAULT_PARAMS)), "input centres"),
    (dict(adapt="P"), "adapt"),
    (dict(window=0), "window"),
    (dict(window=2.5), "window"),
    (dict(normalise="true"), "normalise"),
    (dict(floor=0.0), "floor"),
    (dict(floor=np.inf), "floor"),
    (dict(ceiling=1e-4), "ceiling"),
    (dict(ceiling=np.inf), "ceiling"),
    (dict(warmup="later"), "warmup"),
])
def test_constructor_errors_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        FuzzyAdaptive(**({"base": KF()} | kwargs))


@pytest.mark.parametrize("pairs", [((0, 0), (1, 1)), ((0, 0), (1, 1), (0, 2)),
                                   ((0, 0), (1, 1), (-1, 0))])
def test_bad_q_inputs_raise_naming_q_inputs(pairs):
    # negative indices are refused by the constructor, the others once n and m are known
    with pytest.raises(ValueError, match="q_inputs"):
        f = FuzzyAdaptive(KF(), adapt="Q", q_inputs=pairs)
        b = f.predict(f.init(prior()), LinearMotion(F3, Q3), 1.0)
        f.update(b, np.array([0.1, 0.2]), Position(dim=2, sigma=1.0))


def test_init_builds_an_empty_memory_and_passes_a_fuzzy_belief_through():
    f = FuzzyAdaptive(KF(), window=4)
    b = f.init(prior(3))
    assert isinstance(b, FuzzyBelief)
    assert b.R.shape == (3, 0, 0) and b.Q.shape == (3, 0, 0) and b.residuals.shape == (3, 4, 0)
    np.testing.assert_array_equal(b.count, 0)
    assert f.init(b) is b
    g = f.estimate(b)
    assert isinstance(g, Gaussian) and not isinstance(g, FuzzyBelief)
    np.testing.assert_array_equal(g.mean, b.mean)


# --------------------------------------------------------------------------------------------
# Around the EKF and the UKF with nonlinear sensors
# --------------------------------------------------------------------------------------------


def _angles_problem(T: int, B: int, seed: int):
    """A 3-D constant-velocity target seen in azimuth and elevation from the origin."""
    rng = np.random.default_rng(seed)
    motion = ConstantVelocity(dim=3, q=1e-3)
    true = AzimuthElevation((0.0, 0.0, 0.0), sigma_az=0.02, sigma_el=0.01)
    x0 = np.array([800.0, 600.0, -100.0, -2.0, 1.0, 0.1])
    P0 = np.diag([30.0, 30.0, 10.0, 1.0, 1.0, 0.3]) ** 2
    L = np.linalg.cholesky(motion.noise(x0, 1.0))
    x = np.broadcast_to(x0, (B, 6)).copy()
    zs = []
    for _ in range(T):
        x = motion.f(x, 1.0) + rng.standard_normal((B, 6)) @ L.T
        zs.append(true.h(x) + rng.standard_normal((B, 2)) * [0.02, 0.01])
    m0 = x0 + rng.standard_normal((B, 6)) @ np.linalg.cholesky(P0).T
    return motion, true, np.array(zs), Gaussian(m0, np.broadcast_to(P0, (B, 6, 6)).copy())


@pytest.mark.parametrize("base", [EKF(), UKF()], ids=["EKF", "UKF"])
def test_around_ekf_and_ukf_zero_outputs_are_the_base_and_r_grows_from_too_small(base):
    T, B = 150, 10
    motion, true, z, b0 = _angles_problem(T, B, seed=31)
    small = with_noise(true, true.noise / 10)  # R0 ten times too small
    fb, fi = run(FuzzyAdaptive(base, zero_output()), z, small, motion, b0)
    bb, bi = run(base, z, small, motion, b0)
    for k in (0, 30, T - 1):
        np.testing.assert_allclose(fb[k].mean, bb[k].mean, rtol=1e-12)
        np.testing.assert_allclose(fb[k].cov, bb[k].cov, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(fi[k].nu, bi[k].nu, rtol=1e-10, atol=1e-15)
    beliefs, _ = run(FuzzyAdaptive(base), z, small, motion, b0)
    R = np.array([diag(b.R) for b in beliefs])  # (T, B, 2)
    np.testing.assert_array_equal(R[:24], np.broadcast_to(np.diag(small.noise), (24, B, 2)))
    # geometric mean over runs and the last 50 steps: from 0.1 to within a factor 1.5 of the
    # truth (the same statistical margin as the linear case; S carries the linearisation)
    ratio = np.exp(np.log(R[-50:] / np.diag(true.noise)).mean((0, 1)))
    assert np.all((ratio > 1 / 1.5) & (ratio < 1.5)), ratio


def test_ofekf_on_a_scalar_bearing_sensor():
    # m = 1: a bearing from the origin to a 2-D constant-velocity target
    rng = np.random.default_rng(8)
    T, B = 200, 8
    motion = ConstantVelocity(dim=2, q=1e-3)
    true = Bearing((0.0, 0.0), sigma=0.01)
    x = np.broadcast_to([3000.0, 4000.0, -5.0, 2.0], (B, 4)).copy()
    zs = []
    for _ in range(T):
        x = motion.f(x, 1.0) + rng.standard_normal((B, 4)) @ np.linalg.cholesky(
            motion.noise(x[0], 1.0)).T
        zs.append(true.h(x) + 0.01 * rng.standard_normal((B, 1)))
    # start from the true state with a tight prior so the filter is consistent
    b0 = Gaussian(np.broadcast_to([3000.0, 4000.0, -5.0, 2.0], (B, 4)).copy(),
                  np.broadcast_to(np.diag([1.0, 1.0, 0.1, 0.1]), (B, 4, 4)).copy())
    big = with_noise(true, true.noise * 10)
    beliefs, innovs = run(FuzzyAdaptive(EKF()), np.array(zs), big, motion, b0)
    assert beliefs[-1].R.shape == (B, 1, 1)
    assert np.all(beliefs[-1].R[:, 0, 0] < big.noise[0, 0])  # shrinks from 10x
    ratio = np.exp(np.log(np.array([b.R[:, 0, 0] for b in beliefs[-60:]])
                          / true.noise[0, 0]).mean())
    assert 1 / 1.5 < ratio < 1.5, ratio
