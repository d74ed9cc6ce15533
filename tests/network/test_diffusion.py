"""Diffusion Kalman filter (Jalalipoor and Kardehi Moghaddam 2021, eqs. 44-50): weight rules, the
incremental update, the combination rules, ATC/CTA, batching, missing measurements, bad input, and
the consistency of the covariance combinations (Monte Carlo, fixed seeds)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import block_diag
from scipy.optimize import minimize
from scipy.stats import chi2

import trackkit as tk
from trackkit.network.diffusion import (
    COMBINATIONS,
    DiffusionKF,
    adapt,
    check_weights,
    ci_weights,
    combine,
    metropolis_weights,
    neighbourhood,
    uniform_weights,
)

MOTION = tk.models.ConstantVelocity(dim=2, q=0.05)
PATH3 = np.array([[0, 1, 0], [1, 0, 1], [0, 1, 0]], bool)
RING5 = np.roll(np.eye(5, dtype=bool), 1, 1) | np.roll(np.eye(5, dtype=bool), -1, 1)


def _nees(x: np.ndarray, P: np.ndarray, truth: np.ndarray) -> np.ndarray:
    e = x - truth
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def _user_weights(adjacency: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random non-negative weights on the graph (self included), rows summing to 1."""
    W = rng.uniform(0.1, 1.0, adjacency.shape) * neighbourhood(adjacency)
    return W / W.sum(-1, keepdims=True)


# -- 1. identical inputs -----------------------------------------------------------------------


@pytest.mark.parametrize("method", COMBINATIONS)
@pytest.mark.parametrize("rule", ["uniform", "metropolis", "user"])
def test_combination_leaves_identical_inputs_unchanged(method, rule, num):
    """Every agent with the same estimate: every combination rule returns it bit for bit
    (the rules weight deviations from the agent's own estimate, which are exactly zero)."""
    rng = np.random.default_rng(1)
    W = {"uniform": uniform_weights(RING5), "metropolis": metropolis_weights(RING5),
         "user": _user_weights(RING5, rng)}[rule]
    x = 1e4 * rng.standard_normal((3, 2, 1, 4))  # runs, targets, (agents), state
    P = num.spd(rng, (3, 2, 1), 4, cond=1e4)
    b = tk.Gaussian(np.repeat(x, 5, -2), np.repeat(P, 5, -3))
    out = combine(b, W, method)
    np.testing.assert_array_equal(out.mean, b.mean)
    np.testing.assert_array_equal(out.cov, b.cov)


@pytest.mark.parametrize("method", ["paper", "information"])
def test_equal_covariances_give_the_average(method, num):
    """Jalalipoor and Kardehi Moghaddam (2021): uniform weights with equal P give the mean estimate,
    P unchanged."""
    rng = np.random.default_rng(2)
    x = rng.standard_normal((4, 3, 4)) * 100
    P = np.repeat(num.spd(rng, (4, 1), 4), 3, -3)
    out = combine(tk.Gaussian(x, P), uniform_weights(np.ones((3, 3), bool)), method)
    num.close(out.mean, np.repeat(x.mean(-2, keepdims=True), 3, -2), rtol=1e-13,
              what="mean")
    np.testing.assert_array_equal(out.cov, P)


def test_information_combination_matches_the_direct_formula(num):
    """``P_k = (sum_l a_lk P_l^-1)^-1``, ``x_k = P_k sum_l a_lk P_l^-1 x_l`` (and the paper's
    arithmetic mean), against the formulas evaluated directly."""
    rng = np.random.default_rng(3)
    W = _user_weights(RING5, rng)
    x = rng.standard_normal((6, 5, 4)) * 50
    P = num.spd(rng, (6, 5), 4, cond=1e3)
    Pinv = np.linalg.inv(P)
    Pc = np.linalg.inv(np.einsum("kl,rlij->rkij", W, Pinv))
    xc = np.einsum("rkij,kl,rljm,rlm->rki", Pc, W, Pinv, x)
    info = combine(tk.Gaussian(x, P), W, "information")
    paper = combine(tk.Gaussian(x, P), W, "paper")
    num.close(info.cov, Pc, rtol=1e-12, what="information cov")
    num.close(info.mean, xc, rtol=1e-12, what="information mean")
    num.close(paper.cov, Pc, rtol=1e-12, what="paper cov")
    num.close(paper.mean, np.einsum("kl,rli->rki", W, x), rtol=1e-13, what="paper mean")
    assert (info.cov == info.cov.swapaxes(-1, -2)).all()


# -- 2. oracle: the centralised KF -------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Linear:
    """A linear sensor ``z = H x + v``, ``v ~ N(0, R)`` (R may carry batch axes): the
    stacked sensor of the centralised KF."""

    H: np.ndarray
    R: np.ndarray
    linear: bool = True

    @property
    def dim_z(self) -> int:
        return self.H.shape[0]

    @property
    def noise(self) -> np.ndarray:
        return self.R

    def h(self, x):
        return x @ self.H.T

    def jacobian(self, x):
        return self.H

    def residual(self, z, zhat):
        return z - zhat


def _oracle_run(order: str, method: str, H_kind: str, steps: int = 25):
    """Complete graph, every agent receives every measurement: each agent against one KF
    that receives them all (stacked). Returns the largest relative differences."""
    rng = np.random.default_rng(7)
    runs, N = 6, 4
    if H_kind == "composite":  # the paper's: H = I_4, R = J^-1 per agent
        H = np.broadcast_to(np.eye(4), (N, 4, 4))
    else:  # a general linear sensor, a different 2 x 4 matrix per agent
        H = rng.standard_normal((N, 2, 4))
    m = H.shape[-2]
    A = rng.standard_normal((runs, N, m, m))
    # (runs, N, m, m): full SPD, different by run and by agent
    R = (A @ A.swapaxes(-1, -2) + np.eye(m)) * rng.uniform(1, 30, (runs, N, 1, 1))
    f = DiffusionKF(np.ones((N, N), bool), "metropolis", order=order, combination=method,
                    share=np.ones((N, N)))
    kf = tk.filters.KF()
    sensor = _Linear(H.reshape(N * m, 4), np.stack([block_diag(*r) for r in R]))
    x0 = np.array([1000.0, -500.0, 8.0, 3.0])
    P0 = np.diag([400.0, 400.0, 25.0, 25.0])
    truth = x0 + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    central = tk.Gaussian(np.broadcast_to(x0, (runs, 4)).copy(), P0)
    net = tk.Gaussian(np.broadcast_to(x0, (runs, N, 4)).copy(), P0)
    dx = dP = 0.0
    for _ in range(steps):
        truth = MOTION.f(truth, 1.0) + rng.multivariate_normal(np.zeros(4),
                                                               MOTION.noise(None, 1.0), runs)
        z = (np.einsum("lij,rj->rli", H, truth)
             + np.einsum("rlij,rlj->rli", np.linalg.cholesky(R), rng.standard_normal((runs, N, m))))
        central = kf.predict(central, MOTION, 1.0)
        central, _ = kf.update(central, z.reshape(runs, N * m), sensor)
        net = f.update(f.predict(net, MOTION, 1.0), z, R, H)
        dx = max(dx, np.abs(net.mean - central.mean[:, None]).max() / np.abs(central.mean).max())
        dP = max(dP, np.abs(net.cov - central.cov[:, None]).max() / np.abs(central.cov).max())
    return dx, dP


@pytest.mark.parametrize("H_kind", ["composite", "general"])
@pytest.mark.parametrize("method", COMBINATIONS)
@pytest.mark.parametrize("order", ["atc", "cta"])
def test_complete_graph_equals_the_centralised_kf(order, method, H_kind):
    """Every agent's estimate equals the centralised KF's to 1e-9 (relative), for ATC and
    CTA and every combination: with full sharing and one prior, every agent's update uses
    the same information, so the agents agree at every step and the combination of identical
    estimates is the identity (test 1)."""
    dx, dP = _oracle_run(order, method, H_kind)
    assert dx < 1e-9 and dP < 1e-9, (dx, dP)


def test_adapt_equals_the_papers_sequential_updates(num):
    """The information-form update equals eqs. 46-48 applied neighbour by neighbour (the core
    KF, one measurement at a time), with a general H and missing measurements."""
    rng = np.random.default_rng(11)
    N, runs = 3, 5
    H = rng.standard_normal((N, 2, 4))
    R = num.spd(rng, (runs, N), 2, cond=10) * 4
    x = rng.standard_normal((runs, N, 4)) * 10
    P = num.spd(rng, (runs, N), 4, cond=100) * 9
    z = rng.standard_normal((runs, N, 2)) * 5
    z[1, 2] = np.nan
    z[3, 0, 1] = np.nan  # one nan component: the whole measurement is missing
    C = neighbourhood(PATH3).astype(float)
    out = adapt(tk.Gaussian(x, P), z, R, C, H)
    kf = tk.filters.KF()
    for r in range(runs):
        for k in range(N):
            b = tk.Gaussian(x[r, k], P[r, k])
            for l in np.flatnonzero(C[k]):
                b, _ = kf.update(b, z[r, l], _Linear(H[l], R[r, l]))
            num.close(out.mean[r, k], b.mean, rtol=1e-11, what=f"mean {r, k}")
            num.close(out.cov[r, k], b.cov, rtol=1e-11, what=f"cov {r, k}")


# -- 3. weight rules and consensus -------------------------------------------------------------


@st.composite
def _graphs(draw, connected: bool = False):
    n = draw(st.integers(1, 7))
    bits = draw(st.lists(st.booleans(), min_size=n * n, max_size=n * n))
    A = np.array(bits, bool).reshape(n, n)
    A = A | A.T
    if connected:  # add a random spanning tree
        order = draw(st.permutations(range(n)))
        for i in range(1, n):
            j = draw(st.integers(0, i - 1))
            A[order[i], order[j]] = A[order[j], order[i]] = True
    return A


@settings(max_examples=60, deadline=None)
@given(_graphs())
def test_weight_rules(A):
    """Rows sum to 1, weights are non-negative and zero off the graph; Metropolis weights
    are symmetric and doubly stochastic with a positive diagonal."""
    Nk = neighbourhood(A)
    for W in (uniform_weights(A), metropolis_weights(A)):
        np.testing.assert_allclose(W.sum(-1), 1.0, rtol=0, atol=1e-14)
        assert (W >= 0).all() and (W[~Nk] == 0).all() and (W[Nk] > 0).all()
        check_weights(W, A)
    M = metropolis_weights(A)
    n = Nk.sum(-1)
    off = Nk & ~np.eye(len(A), dtype=bool)
    np.testing.assert_array_equal(M[off], (1.0 / np.maximum.outer(n, n))[off])
    np.testing.assert_array_equal(M, M.T)
    np.testing.assert_allclose(M.sum(0), 1.0, rtol=0, atol=1e-14)
    # batched graphs give the same as one at a time
    np.testing.assert_array_equal(metropolis_weights(np.stack([A, A]))[1], M)


def test_weight_values():
    """Hand-computed weights: the path 0 - 1 - 2 and the star with centre 0."""
    third = 1.0 / 3.0
    np.testing.assert_allclose(metropolis_weights(PATH3), [[2 * third, third, 0],
                                                           [third, third, third],
                                                           [0, third, 2 * third]], rtol=1e-15)
    np.testing.assert_allclose(uniform_weights(PATH3), [[0.5, 0.5, 0], [third, third, third],
                                                        [0, 0.5, 0.5]], rtol=1e-15)
    star = np.zeros((4, 4), bool)
    star[0, 1:] = star[1:, 0] = True
    np.testing.assert_allclose(metropolis_weights(star),
                               [[0.25, 0.25, 0.25, 0.25], [0.25, 0.75, 0, 0],
                                [0.25, 0, 0.75, 0], [0.25, 0, 0, 0.75]], rtol=1e-15)


@settings(max_examples=25, deadline=None)
@given(_graphs(connected=True), st.sampled_from(["uniform", "metropolis"]),
       st.sampled_from(["convex", "information"]), st.integers(0, 2**32 - 1))
def test_repeated_combination_reaches_consensus(A, rule, method, seed):
    """On a connected graph, combining without measurements drives every agent's mean to the
    same value; Metropolis weights with the arithmetic mean reach the network average."""
    rng = np.random.default_rng(seed)
    N = A.shape[0]
    W = uniform_weights(A) if rule == "uniform" else metropolis_weights(A)
    x0 = rng.standard_normal((N, 4)) * 100
    L = rng.standard_normal((N, 4, 4))
    b = tk.Gaussian(x0, L @ L.swapaxes(-1, -2) + np.eye(4))
    for _ in range(600):  # second eigenvalue <= 0.934 for N <= 7: 0.934^600 ~ 1e-18
        b = combine(b, W, method)
    spread = np.abs(b.mean - b.mean[:1]).max()
    assert spread < 1e-8 * np.abs(x0).max(), spread
    if rule == "metropolis" and method == "convex":
        np.testing.assert_allclose(b.mean, np.broadcast_to(x0.mean(0), (N, 4)), atol=1e-9)


# -- covariance intersection -------------------------------------------------------------------


@pytest.mark.parametrize("criterion", ["det", "trace"])
def test_ci_weights_minimise_the_criterion(criterion, num):
    """The multiplicative algorithm decreases det P (trace P) at every step and reaches the
    minimum over the simplex that scipy's SLSQP finds (to 1e-8 relative); it keeps the
    support of the given weights."""
    rng = np.random.default_rng(5)
    N = 4
    P = num.spd(rng, (N,), 4, cond=100) * rng.uniform(0.3, 10, (N, 1, 1))
    Pinv = np.linalg.inv(P)

    def J(w):
        Pc = np.linalg.inv(np.einsum("l,lij->ij", w, Pinv))
        return np.linalg.det(Pc) if criterion == "det" else np.trace(Pc)

    W = np.full((N, N), 1.0 / N)
    path = [J(ci_weights(P, W, criterion, i)[0]) for i in range(30)]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(path, path[1:], strict=False)), path
    best = min((minimize(J, w0, method="SLSQP", bounds=[(0, 1)] * N,
                         constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1}],
                         options={"ftol": 1e-15, "maxiter": 1000})
                for w0 in [np.full(N, 1 / N), *rng.dirichlet(np.ones(N), 5)]),
               key=lambda r: r.fun)
    omega = ci_weights(P, W, criterion, 2000)
    assert J(omega[0]) <= best.fun * (1 + 1e-8), (J(omega[0]), best.fun)
    # combine(..., "ci") fuses with these weights, and beats the fixed weights a_lk
    x = rng.standard_normal((N, 4))
    ci = combine(tk.Gaussian(x, P), W, "ci", criterion, 2000)
    fixed = combine(tk.Gaussian(x, P), W, "information")
    Pc = np.linalg.inv(np.einsum("kl,lij->kij", omega, Pinv))
    num.close(ci.cov, Pc, rtol=1e-12, what="ci cov")
    num.close(ci.mean, np.einsum("kij,kl,ljm,lm->ki", Pc, omega, Pinv, x), rtol=1e-12,
              what="ci mean")
    size = np.linalg.det if criterion == "det" else lambda A: np.trace(A, axis1=-2, axis2=-1)
    assert (size(ci.cov) < 0.99 * size(fixed.cov)).all()
    # zero weights stay zero: the optimum over agents {0, 1} only
    W2 = np.tile([0.5, 0.5, 0.0, 0.0], (N, 1))
    assert (ci_weights(P, W2, criterion, 50)[:, 2:] == 0).all()


# -- 4. consistency ----------------------------------------------------------------------------


def _correlated_estimates(rng, M: int, U_scales):
    """Agents' estimates of one state whose errors share a common part: e_l = c + u_l,
    c ~ N(0, C) (the measurements they shared), u_l ~ N(0, s_l U) (their own). Each P_l =
    C + s_l U is the exact marginal covariance: every input is consistent on its own."""
    C = np.diag([4.0, 4.0, 0.2, 0.2])
    U = np.array([[3.0, 1.0, 0.2, 0.0], [1.0, 2.0, 0.0, 0.1],
                  [0.2, 0.0, 0.5, 0.1], [0.0, 0.1, 0.1, 0.4]])
    s = np.asarray(U_scales)
    c = rng.standard_normal((M, 1, 4)) @ np.linalg.cholesky(C).T
    u = rng.standard_normal((M, s.size, 4)) @ np.linalg.cholesky(U).T * np.sqrt(s)[:, None]
    P = C + s[:, None, None] * U
    truth = rng.standard_normal((M, 1, 4)) * 100
    return tk.Gaussian(truth + c + u, np.broadcast_to(P, (M,) + P.shape)), truth


M_ONE_SHOT = 4000
#: the mean NEES of M runs of a consistent 4-state estimator is below this with 99.5 %
#: confidence (chi-square with 4 M degrees of freedom)
UPPER_ONE_SHOT = chi2.ppf(0.995, 4 * M_ONE_SHOT) / M_ONE_SHOT


def test_paper_combination_is_overconfident_where_ci_is_not():
    """Correlated errors and unequal covariances (one agent far better than the others): the
    paper's pair (arithmetic mean, harmonic covariance) is overconfident, mean NEES far above
    the chi-square bound; covariance intersection, with the weights a_lk or optimised, is
    below it."""
    b, truth = _correlated_estimates(np.random.default_rng(21), M_ONE_SHOT, [0.05, 2.0, 40.0])
    W = uniform_weights(np.ones((3, 3), bool))
    nees = {}
    for method, crit in [("paper", "det"), ("information", "det"), ("ci", "det"),
                         ("ci", "trace")]:
        out = combine(b, W, method, crit)
        nees[method, crit] = _nees(out.mean, out.cov, truth).mean(0)  # per agent
    assert (nees["paper", "det"] > 2 * UPPER_ONE_SHOT).all(), nees
    for key in [("information", "det"), ("ci", "det"), ("ci", "trace")]:
        assert (nees[key] < UPPER_ONE_SHOT).all(), (key, nees[key], UPPER_ONE_SHOT)


def test_paper_combination_with_equal_covariances_is_conservative():
    """What the paper's combination gets right: with equal covariances, errors correlated
    through shared measurements (or not) leave it consistent, even conservative: the mean of
    the errors has covariance C + U / N <= P."""
    b, truth = _correlated_estimates(np.random.default_rng(22), M_ONE_SHOT, [1.0, 1.0, 1.0])
    out = combine(b, uniform_weights(np.ones((3, 3), bool)), "paper")
    nees = _nees(out.mean, out.cov, truth).mean(0)
    assert (nees < UPPER_ONE_SHOT).all() and (nees < 4.0).all(), nees


M_NET, T_NET = 1000, 25
#: per (step, agent) bound with a Bonferroni correction over the 25 x 3 checks: a consistent
#: filter passes all of them with 99 % confidence
UPPER_NET = chi2.ppf(1 - 0.01 / (T_NET * 3), 4 * M_NET) / M_NET


def _network_nees(method: str, order: str = "atc", iterations: int = 20) -> np.ndarray:
    """Path graph 0 - 1 - 2 with Metropolis weights; agent 0 measures well, agent 1 poorly,
    agent 2 (out of range) not at all (but uses agent 1's measurement). Mean NEES over M_NET
    runs, per step and agent."""
    rng = np.random.default_rng(31)
    f = DiffusionKF(PATH3, "metropolis", order=order, combination=method,
                    iterations=iterations)
    R = np.stack([np.diag([25.0, 25.0, 1.0, 1.0]), np.diag([400.0, 400.0, 16.0, 16.0]),
                  np.full((4, 4), np.nan)])
    x0, P0 = np.array([1000.0, 2000.0, 5.0, -3.0]), np.diag([1e4, 1e4, 100.0, 100.0])
    truth = x0 + rng.standard_normal((M_NET, 4)) @ np.linalg.cholesky(P0).T
    b = tk.Gaussian(np.broadcast_to(x0, (M_NET, 3, 4)).copy(), P0)
    Lr = np.linalg.cholesky(R[:2])
    Lq = np.linalg.cholesky(MOTION.noise(None, 1.0))
    out = []
    for _ in range(T_NET):
        truth = MOTION.f(truth, 1.0) + rng.standard_normal((M_NET, 4)) @ Lq.T
        z = np.full((M_NET, 3, 4), np.nan)
        v = np.einsum("lij,mlj->mli", Lr, rng.standard_normal((M_NET, 2, 4)))
        z[:, :2] = truth[:, None] + v
        b = f.update(f.predict(b, MOTION, 1.0), z, R)
        out.append(_nees(b.mean, b.cov, truth[:, None]).mean(0))
    return np.array(out)


@pytest.mark.parametrize("order", ["atc", "cta"])
def test_network_nees_paper_against_ci(order):
    """The whole filter, Monte Carlo: with the paper's combination the agent without a
    sensor is overconfident (NEES far above the bound while its covariance is much larger
    than its neighbour's); covariance intersection (a_lk weights or optimised) stays under
    the bound at every step and agent. Cattivelli and Sayed's own rule (the agent's covariance
    kept) is overconfident too."""
    paper = _network_nees("paper", order)
    assert paper[:, 2].max() > 2 * UPPER_NET, paper.max(0)
    assert _network_nees("convex", order).max() > UPPER_NET
    for method in ("information", "ci"):
        nees = _network_nees(method, order)
        assert nees.max() < UPPER_NET, (method, nees.max(0), UPPER_NET)


# -- 5. batching, missing measurements, bad input ----------------------------------------------


@pytest.mark.parametrize("method", COMBINATIONS)
@pytest.mark.parametrize("order", ["atc", "cta"])
def test_batched_equals_row_by_row(order, method, num):
    """(runs, targets, agents) at once against one (run, target) at a time."""
    rng = np.random.default_rng(41)
    runs, targets, N = 3, 2, 5
    f = DiffusionKF(RING5, "uniform", order=order, combination=method)
    b = tk.Gaussian(rng.standard_normal((runs, targets, N, 4)) * 30,
                    num.spd(rng, (runs, targets, N), 4, cond=100) * 10)
    z = rng.standard_normal((runs, targets, N, 4)) * 30
    z[0, 1, [1, 2]] = np.nan
    z[2, 0, 4] = np.nan
    R = num.spd(rng, (runs, targets, N), 4, cond=10) * 5
    out = f.update(f.predict(b, MOTION, 2.0), z, R)
    for r in range(runs):
        for t in range(targets):
            one = f.update(f.predict(b.at((r, t)), MOTION, 2.0), z[r, t], R[r, t])
            num.close(out.mean[r, t], one.mean, rtol=1e-12, what="mean")
            num.close(out.cov[r, t], one.cov, rtol=1e-12, what="cov")


def test_atc_and_cta_orders(num):
    """ATC is combine(adapt(.)) and CTA adapt(combine(.)); on a ring they differ."""
    rng = np.random.default_rng(44)
    b = tk.Gaussian(rng.standard_normal((2, 5, 4)) * 10, num.spd(rng, (2, 5), 4) * 4)
    z = rng.standard_normal((2, 5, 4)) * 10
    R = num.spd(rng, (2, 5), 4) + np.eye(4)
    W = metropolis_weights(RING5)
    C = neighbourhood(RING5).astype(float)
    atc = DiffusionKF(RING5, order="atc").update(b, z, R)
    cta = DiffusionKF(RING5, order="cta").update(b, z, R)
    num.close(atc.mean, combine(adapt(b, z, R, C), W).mean, rtol=1e-14, what="ATC")
    num.close(cta.mean, adapt(combine(b, W), z, R, C).mean, rtol=1e-14, what="CTA")
    assert np.abs(atc.mean - cta.mean).max() > 1e-3


def test_weights_with_batch_axes(num):
    """A weight matrix per run (a proximity graph that differs by run) equals each run's
    combination with its own matrix."""
    rng = np.random.default_rng(42)
    W = np.stack([_user_weights(RING5, rng), metropolis_weights(PATH3.repeat(2, 0)
                  .repeat(2, 1)[:5, :5] | np.eye(5, dtype=bool))])
    b = tk.Gaussian(rng.standard_normal((2, 5, 4)), num.spd(rng, (2, 5), 4))
    for method in COMBINATIONS:
        out = combine(b, W, method)
        for r in range(2):
            one = combine(b.at(r), W[r], method)
            num.close(out.mean[r], one.mean, rtol=1e-12, what=f"{method} mean")
            num.close(out.cov[r], one.cov, rtol=1e-12, what=f"{method} cov")


def test_missing_measurements_keep_the_prediction(num):
    """An agent none of whose neighbours measured keeps its prediction exactly; a missing
    measurement counts as if its agent shared nothing (nan R allowed there)."""
    rng = np.random.default_rng(43)
    b = tk.Gaussian(rng.standard_normal((2, 5, 4)) * 10, num.spd(rng, (2, 5), 4) * 4)
    z = rng.standard_normal((2, 5, 4)) * 10
    R = np.broadcast_to(np.eye(4) * 3, (2, 5, 4, 4)).copy()
    z[0, [0, 1, 4]] = np.nan  # agent 0's neighbourhood {4, 0, 1}: nothing to update with
    R[0, 1] = np.nan
    C = neighbourhood(RING5).astype(float)
    out = adapt(b, z, R, C)
    np.testing.assert_array_equal(out.mean[0, 0], b.mean[0, 0])
    np.testing.assert_array_equal(out.cov[0, 0], b.cov[0, 0])
    assert not np.allclose(out.mean[0, 2], b.mean[0, 2])
    C0 = C.copy()
    C0[:, [0, 1, 4]] = 0.0
    ref = adapt(b.at(0), np.nan_to_num(z[0]), np.eye(4) * 3, C0)
    num.close(out.mean[0], ref.mean, rtol=1e-13, what="mean")
    num.close(out.cov[0], ref.cov, rtol=1e-13, what="cov")
    # and nothing at all: the whole filter returns the prediction (combination of ATC aside)
    f = DiffusionKF(RING5, combination="convex")
    none = f.adapt(b, np.full((2, 5, 4), np.nan), R)
    np.testing.assert_array_equal(none.mean, b.mean)
    np.testing.assert_array_equal(none.cov, b.cov)


def _b(N=3):
    return tk.Gaussian(np.zeros((N, 4)), np.broadcast_to(np.eye(4), (N, 4, 4)))


@pytest.mark.parametrize("call, match", [
    (lambda: neighbourhood(np.ones((3, 2))), r"adjacency has shape \(3, 2\); expected"),
    (lambda: neighbourhood([[0, 2], [2, 0]]), r"adjacency\[0, 1\] = 2; expected booleans"),
    (lambda: neighbourhood([[0, 1], [0, 0]]), r"adjacency is not symmetric: \[0, 1\]"),
    (lambda: check_weights([[0.5, 0.6], [0.5, 0.5]]), r"weights: row \[0\] sums to 1.1"),
    (lambda: check_weights([[1.5, -0.5], [0.5, 0.5]]), r"weights\[0, 1\] = -0.5; expected"),
    (lambda: check_weights([[0.5, 0.5], [0.5, 0.5]], np.zeros((2, 2))),
     r"weights\[0, 1\] = 0.5 but agents 0 and 1 are not linked"),
    (lambda: check_weights(np.ones(3)), r"weights has shape \(3,\); expected \(\.\.\., N, N\)"),
    (lambda: DiffusionKF(PATH3, weights="max"), r"DiffusionKF.weights = 'max'"),
    (lambda: DiffusionKF(PATH3, weights=np.full((3, 3), 1 / 3)),
     r"DiffusionKF.weights\[0, 2\] = 0.33.* not linked"),
    (lambda: DiffusionKF(PATH3, order="ctc"), r"DiffusionKF.order = 'ctc'; expected"),
    (lambda: DiffusionKF(PATH3, combination="avg"), r"DiffusionKF.combination = 'avg'"),
    (lambda: DiffusionKF(PATH3, share=np.ones((3, 3))), r"DiffusionKF.share .* zero off"),
    (lambda: DiffusionKF(PATH3, iterations=-1), r"DiffusionKF.iterations = -1"),
    (lambda: combine(_b(), uniform_weights(PATH3), "mean"), r"method = 'mean'; expected"),
    (lambda: combine(_b(4), uniform_weights(PATH3)),
     r"combine belief.mean has shape \(4, 4\); weights is \(3, 3\), so expected \(\.\.\., 3"),
    (lambda: combine(tk.Gaussian(np.zeros((3, 4)), np.zeros((3, 4, 4))),
                     uniform_weights(PATH3), "information"),
     r"combine belief.cov is not positive definite"),
    (lambda: ci_weights(np.eye(4)[None].repeat(3, 0), uniform_weights(PATH3), "max"),
     r"criterion = 'max'; expected"),
    (lambda: adapt(_b(), np.zeros((3, 3)), np.eye(3), np.ones((3, 3))),
     r"the measurements give information of shape .* for the state of shape \(3, 4\)"),
    (lambda: adapt(_b(), np.zeros((3, 4)), np.eye(3), np.ones((3, 3))),
     r"R has shape \(3, 3\); z has 4 components"),
    (lambda: adapt(_b(), np.zeros((3, 4)), -np.eye(4), np.ones((3, 3))),
     r"R is not positive definite"),
    (lambda: adapt(_b(), np.zeros((3, 4)), [[1, 1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0],
                                            [0, 0, 0, 1]], np.ones((3, 3))),
     r"R is not symmetric"),
    (lambda: adapt(_b(), np.full((3, 4), np.inf), np.eye(4), np.ones((3, 3))),
     r"z has an infinite entry"),
    (lambda: adapt(_b(), np.zeros((3, 2)), np.eye(2), np.ones((3, 3)), np.ones((3, 4))),
     r"H has shape \(3, 4\); z has 2 components"),
    (lambda: adapt(_b(), np.zeros((3, 4)), np.eye(4), -np.ones((3, 3))),
     r"share has shape \(3, 3\) \(finite, >= 0: False\)"),
    (lambda: adapt(_b(), np.zeros((2, 4)), np.eye(4)[None].repeat(3, 0), np.ones((3, 3))),
     r"z \(2, 4\), R \(3, 4, 4\) and H \(4, 4\) do not broadcast"),
    (lambda: DiffusionKF(PATH3).predict(_b(2), MOTION, 1.0),
     r"DiffusionKF.predict belief.mean has shape \(2, 4\)"),
    (lambda: DiffusionKF(PATH3).predict(_b(), MOTION, -1.0), r"dt = -1.0; expected"),
])
def test_bad_inputs_name_the_field(call, match):
    with pytest.raises(ValueError, match=match):
        call()
