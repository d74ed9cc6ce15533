"""Association: clusters, GNN and its costs, JPDA marginals and the JPDA update, on
hand-computed cases and against brute-force enumeration (hypothesis)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

import trackkit as tk
from trackkit.tracking.association import (
    Costs,
    clusters,
    distance_costs,
    gnn_assign,
    jpda_probabilities,
    loglik_costs,
    pda_costs,
    saturating_costs,
)
from trackkit.tracking.gating import Gate, gate, predict_measurement

from .pdaf import jpda_update
from .scenes import scene


def make_gate(pairs, T, D, d2=None, loglik=None, m=2, threshold=9.21):
    """A Gate from a list of (track, det) pairs (sorted as ``gate`` sorts them)."""
    pairs = sorted(pairs)
    t = np.array([p[0] for p in pairs], dtype=np.intp)
    d = np.array([p[1] for p in pairs], dtype=np.intp)
    P = t.size
    d2 = np.ones(P) if d2 is None else np.asarray(d2, dtype=float)
    loglik = -0.5 * d2 if loglik is None else np.asarray(loglik, dtype=float)
    return Gate(t, d, d2, loglik, np.zeros((P, m)), T, D, threshold)


@st.composite
def random_gates(draw, max_t=6, max_d=7):
    T = draw(st.integers(1, max_t))
    D = draw(st.integers(0, max_d))
    cells = [(i, j) for i in range(T) for j in range(D)]
    keep = draw(st.lists(st.booleans(), min_size=len(cells), max_size=len(cells)))
    pairs = [c for c, k in zip(cells, keep, strict=True) if k]
    P = len(pairs)
    d2 = draw(st.lists(st.floats(0.0, 9.0), min_size=P, max_size=P))
    ll = draw(st.lists(st.floats(-12.0, 3.0), min_size=P, max_size=P))
    return make_gate(pairs, T, D, d2, ll)


# -- clusters ---------------------------------------------------------------------------------


def test_clusters_hand_computed():
    # tracks 0, 1 share det 0; track 2 has det 2; track 3 nothing; det 1 in no gate;
    # track 4 joins 0 and 1 through det 3
    g = make_gate([(0, 0), (1, 0), (2, 2), (1, 3), (4, 3)], T=5, D=4)
    c = clusters(g)
    assert c.count == 3
    np.testing.assert_array_equal(c.track, [0, 0, 1, 2, 0])
    np.testing.assert_array_equal(c.det, [0, -1, 1, 0])


def test_clusters_empty():
    c = clusters(make_gate([], T=3, D=2))
    assert c.count == 3
    np.testing.assert_array_equal(c.track, [0, 1, 2])
    np.testing.assert_array_equal(c.det, [-1, -1])
    c = clusters(make_gate([], T=0, D=2))
    assert c.count == 0 and c.det.tolist() == [-1, -1]


@settings(max_examples=150, deadline=None)
@given(random_gates(max_t=10, max_d=10))
def test_clusters_partition_tracks(g):
    c = clusters(g)
    assert sorted(set(c.track.tolist())) == list(range(c.count))
    # numbered in order of first track
    firsts = [int(np.flatnonzero(c.track == k)[0]) for k in range(c.count)]
    assert firsts == sorted(firsts)
    # every pair inside one cluster; a gated detection's cluster is its tracks'
    np.testing.assert_array_equal(c.track[g.track], c.det[g.det])
    ungated = np.setdiff1d(np.arange(g.n_dets), g.det)
    assert np.all(c.det[ungated] == -1)
    # the finest such partition: union-find over shared detections
    parent = list(range(g.n_tracks))

    def find(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for j in range(g.n_dets):
        ts = g.track[g.det == j]
        for a in ts[1:]:
            parent[find(int(a))] = find(int(ts[0]))
    roots = [find(i) for i in range(g.n_tracks)]
    for a in range(g.n_tracks):
        for b in range(g.n_tracks):
            assert (roots[a] == roots[b]) == (c.track[a] == c.track[b])


# -- GNN --------------------------------------------------------------------------------------


def test_gnn_global_beats_greedy():
    # greedy would give t0 -> d0 (cost 1) and leave t1 with d1 (10): 11; global: 2 + 2 = 4
    g = make_gate([(0, 0), (0, 1), (1, 0), (1, 1)], T=2, D=3)
    costs = Costs(np.array([1.0, 2.0, 2.0, 10.0]), np.array([20.0, 20.0]))
    for method in ("sparse", "clusters", "dense", "auto"):
        a = gnn_assign(g, costs, method=method)
        np.testing.assert_array_equal(a.det, [1, 0])
        np.testing.assert_array_equal(a.unassigned, [2])
        assert a.cost == 4.0
    # a cheap miss for track 1: t0 -> d0, t1 misses (1 + 2.5 < 4)
    costs = Costs(np.array([1.0, 2.0, 2.0, 10.0]), np.array([20.0, 2.5]))
    for method in ("sparse", "clusters", "dense", "auto"):
        a = gnn_assign(g, costs, method=method)
        np.testing.assert_array_equal(a.det, [0, -1])
        np.testing.assert_array_equal(a.unassigned, [1, 2])
        assert a.cost == 3.5


def test_gnn_negative_and_forbidden_costs():
    g = make_gate([(0, 0), (1, 0), (2, 1)], T=3, D=2)
    costs = Costs(np.array([-5.0, np.inf, -1.0]), np.array([0.0, -3.0, -2.0]))
    a = gnn_assign(g, costs)
    np.testing.assert_array_equal(a.det, [0, -1, -1])
    assert a.cost == -10.0
    with pytest.raises(ValueError, match="miss"):
        gnn_assign(g, Costs(np.zeros(3), np.array([0.0, np.inf, 0.0])))
    with pytest.raises(ValueError, match="shapes"):
        gnn_assign(g, Costs(np.zeros(2), np.zeros(3)))


def _brute_gnn(g, costs):
    """Least total cost over every feasible assignment (enumerated)."""
    options = [[-1] + [int(j) for j in g.det[g.track == i]] for i in range(g.n_tracks)]
    cost = {(int(t), int(d)): c for t, d, c in zip(g.track, g.det, costs.pair, strict=True)}
    best = np.inf
    for ev in itertools.product(*options):
        dets = [j for j in ev if j >= 0]
        if len(dets) != len(set(dets)):
            continue
        c = sum(costs.miss[i] if j < 0 else cost[(i, j)] for i, j in enumerate(ev))
        best = min(best, c)
    return best


@settings(max_examples=150, deadline=None)
@given(g=random_gates(), miss=st.floats(-2.0, 8.0))
def test_gnn_is_optimal(g, miss):
    rng = np.random.default_rng(g.size)
    costs = Costs(g.d2 - 3.0, np.full(g.n_tracks, miss) + rng.uniform(0, 1, g.n_tracks))
    a = gnn_assign(g, costs, method="sparse")
    b = gnn_assign(g, costs, method="clusters")
    c = gnn_assign(g, costs, method="dense")
    best = _brute_gnn(g, costs)
    assert a.cost == pytest.approx(best, abs=1e-9)
    assert b.cost == pytest.approx(best, abs=1e-9)
    assert c.cost == pytest.approx(best, abs=1e-9)
    # feasible: every detection at most once, only gated pairs
    assigned = a.det[a.det >= 0]
    assert len(set(assigned.tolist())) == assigned.size
    gated = set(zip(g.track.tolist(), g.det.tolist(), strict=True))
    assert all((i, int(j)) in gated for i, j in enumerate(a.det) if j >= 0)
    np.testing.assert_array_equal(np.sort(np.concatenate([assigned, a.unassigned])),
                                  np.arange(g.n_dets))


@pytest.mark.parametrize("T", [3, 60, 400])
def test_gnn_auto_takes_dense_below_the_threshold_and_clusters_above(T, monkeypatch):
    """Both sides of GNN_DENSE_MAX_CELLS give the same assignment as the other two methods,
    and "auto" takes the side the threshold says (spread-out tracks: many clusters)."""
    from trackkit.tracking import association

    rng = np.random.default_rng(T)
    pos = rng.uniform(0, 50.0 * T, (T, 2))
    z = np.concatenate([pos + rng.normal(0, 1.0, (T, 2)), rng.uniform(0, 50.0 * T, (T, 2))])
    g = gate(pos, np.broadcast_to(np.eye(2) * 4.0, (T, 2, 2)), z, 0.99)
    costs = Costs(g.d2 - 3.0, np.full(T, 2.0))
    ref = gnn_assign(g, costs, method="sparse")
    for method in ("clusters", "dense"):
        a = gnn_assign(g, costs, method=method)
        np.testing.assert_array_equal(a.det, ref.det)
        assert a.cost == pytest.approx(ref.cost, rel=1e-12)
    taken = []
    for name in ("_gnn_dense", "_gnn_clusters"):
        real = getattr(association, name)
        monkeypatch.setattr(association, name,
                            lambda *a, _r=real, _n=name: taken.append(_n) or _r(*a))
    np.testing.assert_array_equal(gnn_assign(g, costs).det, ref.det)
    dense = T * (g.n_dets + T) <= association.GNN_DENSE_MAX_CELLS
    assert taken == ["_gnn_dense" if dense else "_gnn_clusters"]
    assert (T == 400) != dense


@settings(max_examples=60, deadline=None)
@given(g=random_gates(max_t=5, max_d=5), pd=st.floats(0.3, 0.99),
       lam=st.floats(1e-4, 1.0))
def test_gnn_loglik_is_the_most_probable_event(g, pd, lam):
    """With loglik costs the GNN picks the joint event of largest JPDA weight."""
    a = gnn_assign(g, loglik_costs(g, pd, lam))
    w = _brute_events(g, pd, lam)
    best = max(w, key=w.get)
    assert w[tuple(a.det.tolist())] == pytest.approx(w[best], rel=1e-9)


def test_cost_functions_hand_computed():
    g = make_gate([(0, 0), (0, 1), (1, 1)], T=2, D=2, d2=[1.0, 4.0, 16.0],
                  loglik=[-2.0, -3.5, -9.5], threshold=chi2.ppf(0.99, 2))
    c = loglik_costs(g, 0.9, 1e-3)
    np.testing.assert_allclose(c.pair, -(np.log(0.9) + g.loglik - np.log(1e-3)), rtol=1e-15)
    np.testing.assert_allclose(c.miss, -np.log(1 - 0.9 * 0.99), rtol=1e-12)
    c = distance_costs(g, 3.0)
    np.testing.assert_array_equal(c.pair, [1.0, 2.0, np.inf])  # d = 4 >= 3 is forbidden
    np.testing.assert_array_equal(c.miss, [3.0, 3.0])
    assert distance_costs(g).miss[0] == np.sqrt(g.threshold)
    c = saturating_costs(g, k1=2.0, k2=0.25)
    np.testing.assert_allclose(c.pair, 2.0 * (1 - np.exp(-0.25 * g.d2)), rtol=1e-15)
    np.testing.assert_array_equal(c.miss, [2.0, 2.0])
    assert saturating_costs(g, miss_cost=0.5).miss.tolist() == [0.5, 0.5]
    # PDA probabilities: per track, beta_ij = L_ij / (1 - P_D P_G + sum_j L_ij)
    c = pda_costs(g, 0.9, 1e-3, 0.99)
    L = 0.9 * np.exp(g.loglik) / 1e-3
    b = 1 - 0.9 * 0.99
    np.testing.assert_allclose(-c.pair, [L[0] / (b + L[0] + L[1]), L[1] / (b + L[0] + L[1]),
                                         L[2] / (b + L[2])], rtol=1e-12)
    np.testing.assert_allclose(-c.miss, [b / (b + L[0] + L[1]), b / (b + L[2])], rtol=1e-12)
    with pytest.raises(ValueError, match="pd"):
        loglik_costs(g, 0.0, 1.0)
    for costs in (loglik_costs, pda_costs, jpda_probabilities):
        with pytest.raises(TypeError, match="'p_d' is now spelled 'pd'"):
            costs(g, p_d=0.9, clutter_density=1.0)
    with pytest.raises(ValueError, match="clutter_density"):
        pda_costs(g, 0.5, 0.0)
    with pytest.raises(ValueError, match="distance"):
        saturating_costs(g, distance="euclid")


def test_saturating_residual_distance_wraps_bearings():
    """The saturating cost (Jalalipoor and Kardehi Moghaddam 2021) of the bearing difference
    gamma = alpha_hat - alpha_z is wrapped."""
    zhat = np.array([[np.pi - 0.01]])
    z = np.array([[-np.pi + 0.01], [np.pi - 0.05]])
    g = gate(zhat, np.full((1, 1, 1), 0.02**2), z, threshold=100.0, angular=[True])
    c = saturating_costs(g, k1=1.0, k2=100.0, distance="residual")
    np.testing.assert_allclose(c.pair, 1 - np.exp(-100.0 * np.array([0.02, 0.04]) ** 2),
                               rtol=1e-9)
    assert gnn_assign(g, c).det.tolist() == [0]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), T=st.integers(1, 8), D=st.integers(1, 8))
def test_saturating_without_gate_is_rectangular_munkres(seed, T, D):
    """With every pair gated and a miss costing K1, the GNN makes min(T, D) assignments, the
    same as Munkres on the T x D matrix of K1 (1 - exp(-K2 d2)) (the paper's method)."""
    rng = np.random.default_rng(seed)
    zhat = rng.uniform(0, 10, (T, 2))
    z = rng.uniform(0, 10, (D, 2))
    S = np.tile(np.eye(2) * 4.0, (T, 1, 1))
    g = gate(zhat, S, z, threshold=1e9)
    assert g.size == T * D
    c = saturating_costs(g, k1=3.0, k2=0.2)
    a = gnn_assign(g, c)
    r, col = linear_sum_assignment(c.pair.reshape(T, D))
    assert (a.det >= 0).sum() == min(T, D)
    assert a.cost == pytest.approx(c.pair.reshape(T, D)[r, col].sum() + 3.0 * (T - len(r)),
                                   rel=1e-12)


def test_gnn_methods_agree_on_scenes():
    for seed in range(5):
        sc = scene(np.random.default_rng(seed), 300, side=3000.0, clutter=40.0)
        mp = predict_measurement(sc.predicted, sc.sensor)
        g = gate(mp.zhat, mp.S, sc.z)
        c = loglik_costs(g, sc.pd, sc.clutter_density)
        a, b = gnn_assign(g, c, "sparse"), gnn_assign(g, c, "clusters")
        np.testing.assert_array_equal(a.det, b.det)
        np.testing.assert_array_equal(a.unassigned, b.unassigned)
        assert a.cost == pytest.approx(b.cost, rel=1e-12)


# -- JPDA -------------------------------------------------------------------------------------


def _brute_events(g, pd, lam, p_g=None):
    """Weight of every feasible joint event, keyed by each track's detection (-1 = miss)."""
    p_g = chi2.cdf(g.threshold, g.nu.shape[1]) if p_g is None else p_g
    options = [[-1] + [int(j) for j in g.det[g.track == i]] for i in range(g.n_tracks)]
    ll = {(int(t), int(d)): v for t, d, v in zip(g.track, g.det, g.loglik, strict=True)}
    w = {}
    for ev in itertools.product(*options):
        dets = [j for j in ev if j >= 0]
        if len(dets) != len(set(dets)):
            continue
        w[ev] = np.prod([1 - pd * p_g if j < 0 else pd * np.exp(ll[(i, j)]) / lam
                         for i, j in enumerate(ev)])
    return w


def _brute_marginals(g, pd, lam):
    w = _brute_events(g, pd, lam)
    total = sum(w.values())
    beta = np.array([sum(v for ev, v in w.items() if ev[t] == d)
                     for t, d in zip(g.track, g.det, strict=True)]) / total
    beta0 = np.array([sum(v for ev, v in w.items() if ev[i] == -1)
                      for i in range(g.n_tracks)]) / total
    return beta, beta0


def test_jpda_hand_computed():
    """Two tracks sharing one detection: events {-, -}, {d, -}, {-, d}, weights b^2, r0 b,
    r1 b, with r_i = P_D N_i / lambda and b = 1 - P_D P_G."""
    pd, lam, p_g = 0.8, 0.01, 0.99
    g = make_gate([(0, 0), (1, 0)], T=2, D=1, loglik=[np.log(0.05), np.log(0.02)])
    r0, r1, b = pd * 0.05 / lam, pd * 0.02 / lam, 1 - pd * p_g
    Z = b * b + r0 * b + r1 * b
    res = jpda_probabilities(g, pd, lam, p_g)
    np.testing.assert_allclose(res.beta, [r0 * b / Z, r1 * b / Z], rtol=1e-14)
    np.testing.assert_allclose(res.beta0, [(b * b + r1 * b) / Z, (b * b + r0 * b) / Z],
                               rtol=1e-14)
    assert not res.approximated.any()
    # a single track: the PDA, beta_j = r_j / (b + sum r)
    g = make_gate([(0, 0), (0, 1)], T=2, D=3, loglik=[np.log(0.05), np.log(0.02)])
    res = jpda_probabilities(g, pd, lam, p_g)
    np.testing.assert_allclose(res.beta, np.array([r0, r1]) / (b + r0 + r1), rtol=1e-14)
    np.testing.assert_allclose(res.beta0, [b / (b + r0 + r1), 1.0], rtol=1e-14)


@settings(max_examples=150, deadline=None)
@given(g=random_gates(), pd=st.floats(0.2, 1.0), lam=st.floats(1e-4, 10.0))
def test_jpda_exact_equals_brute_force(g, pd, lam):
    res = jpda_probabilities(g, pd, lam)
    assert not res.approximated.any()
    beta, beta0 = _brute_marginals(g, pd, lam)
    np.testing.assert_allclose(res.beta, beta, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(res.beta0, beta0, rtol=1e-10, atol=1e-300)
    # per track the marginals sum to one; per detection at most one
    np.testing.assert_allclose(np.bincount(g.track, res.beta, g.n_tracks) + res.beta0, 1.0,
                               rtol=1e-12)
    assert np.all(np.bincount(g.det, res.beta, g.n_dets) <= 1.0 + 1e-12)


@settings(max_examples=80, deadline=None)
@given(g=random_gates(max_t=7, max_d=7), pd=st.floats(0.2, 1.0), lam=st.floats(1e-3, 10.0))
def test_jpda_approximation_is_flagged_and_consistent(g, pd, lam):
    """With max_events = 1 every multi-track cluster is approximated (LBP); its marginals still
    sum to one per track and at most one per detection. (How close they are to the exact
    ones depends on the cluster: loopy belief propagation has no error bound on a loopy
    graph; tests/tracking/test_stonesoup_association.py checks it against Stone Soup's.)"""
    res = jpda_probabilities(g, pd, lam, max_events=1)
    ntr = np.bincount(res.clusters.track, minlength=res.clusters.count)
    has_pairs = np.bincount(res.clusters.track[g.track], minlength=res.clusters.count) > 0
    np.testing.assert_array_equal(res.approximated, (ntr > 1) & has_pairs)
    np.testing.assert_allclose(np.bincount(g.track, res.beta, g.n_tracks) + res.beta0, 1.0,
                               rtol=1e-12)
    assert np.all(np.bincount(g.det, res.beta, g.n_dets) <= 1.0 + 1e-9)


def test_lbp_is_exact_on_a_cluster_without_cycles():
    """A chain t0 - d0 - t1 - d1 - t2 - d2 (a tree): belief propagation gives the exact
    marginals (up to its tolerance)."""
    g = make_gate([(0, 0), (1, 0), (1, 1), (2, 1), (2, 2), (0, 3)], T=3, D=4,
                  loglik=[-1.0, -2.0, -0.5, -3.0, -1.5, -2.5])
    exact = jpda_probabilities(g, 0.9, 0.05)
    approx = jpda_probabilities(g, 0.9, 0.05, max_events=2)
    assert approx.approximated.tolist() == [True] and not exact.approximated.any()
    np.testing.assert_allclose(approx.beta, exact.beta, rtol=1e-10)
    np.testing.assert_allclose(approx.beta0, exact.beta0, rtol=1e-10)


def test_lbp_with_dominant_weights():
    """A pair 1e26 times likelier than the miss: the messages must not divide by a sum that
    rounded to zero (1 + total - r_ij), and the marginals stay finite and exact-like."""
    g = make_gate([(0, 0), (0, 1), (1, 0), (1, 1)], T=2, D=2, loglik=[60.0, 0.0, 0.0, 60.0])
    res = jpda_probabilities(g, 0.9, 1e-3, max_events=1)
    exact = jpda_probabilities(g, 0.9, 1e-3)
    assert res.approximated.all() and np.all(np.isfinite(res.beta))
    np.testing.assert_allclose(res.beta, exact.beta, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(res.beta0, exact.beta0, rtol=1e-6, atol=1e-30)


def test_gnn_rejects_unknown_method():
    g = make_gate([(0, 0)], T=1, D=1)
    with pytest.raises(ValueError, match="method"):
        gnn_assign(g, Costs(np.zeros(1), np.zeros(1)), method="hungarian")


def test_jpda_large_cluster_falls_back():
    """A dense scene whose big cluster exceeds the event limit is approximated, reported, and
    its small clusters stay exact."""
    sc = scene(np.random.default_rng(7), 60, side=500.0, clutter=30.0)
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z)
    res = jpda_probabilities(g, sc.pd, sc.clutter_density, max_events=2000)
    assert res.approximated.any()
    np.testing.assert_allclose(np.bincount(g.track, res.beta, g.n_tracks) + res.beta0, 1.0,
                               rtol=1e-12)
    exact_clusters = ~res.approximated[res.clusters.track[g.track]]
    ref = jpda_probabilities(g, sc.pd, sc.clutter_density)
    np.testing.assert_allclose(res.beta[exact_clusters], ref.beta[exact_clusters], rtol=1e-12)


# -- the JPDA update --------------------------------------------------------------------------


def test_jpda_update_limits():
    """beta0 = 1 keeps the prediction; one certain detection is the Kalman update."""
    sc = scene(np.random.default_rng(1), 4)
    mp = predict_measurement(sc.predicted, sc.sensor)
    z = mp.zhat + np.array([3.0, -2.0])
    track = np.arange(4)
    nu = z - mp.zhat
    post = jpda_update(sc.predicted, mp.K, mp.S, track, nu, np.ones(4), np.zeros(4))
    kf, _ = tk.filters.KF().update(sc.predicted, z, sc.sensor)
    np.testing.assert_allclose(post.mean, kf.mean, rtol=1e-12)
    np.testing.assert_allclose(post.cov, kf.cov, rtol=1e-9, atol=1e-9 * np.abs(kf.cov).max())
    same = jpda_update(sc.predicted, mp.K, mp.S, track[:0], nu[:0], np.zeros(0), np.ones(4))
    np.testing.assert_array_equal(same.mean, sc.predicted.mean)
    np.testing.assert_allclose(same.cov, sc.predicted.cov, rtol=1e-15)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_jpda_update_is_the_moment_matched_mixture(seed):
    """The PDAF update equals moment matching of the mixture beta_0 N(x, P) +
    sum_j beta_j N(x + K nu_j, P^c) (Bar-Shalom), per track."""
    rng = np.random.default_rng(seed)
    sc = scene(rng, 6, side=300.0, clutter=15.0)
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z)
    res = jpda_probabilities(g, sc.pd, sc.clutter_density)
    P_upd = sc.predicted.cov - mp.K @ mp.S @ mp.K.mT
    post = jpda_update(sc.predicted, mp.K, mp.S, g.track, g.nu, res.beta, res.beta0,
                       P_upd=P_upd)
    for i in range(6):
        sel = g.track == i
        means = [sc.predicted.mean[i]] + [sc.predicted.mean[i] + mp.K[i] @ nu
                                          for nu in g.nu[sel]]
        covs = [sc.predicted.cov[i]] + [P_upd[i]] * int(sel.sum())
        w = np.concatenate([[res.beta0[i]], res.beta[sel]])
        m = sum(wk * mk for wk, mk in zip(w, means, strict=True))
        C = sum(wk * (Ck + np.outer(mk - m, mk - m))
                for wk, mk, Ck in zip(w, means, covs, strict=True))
        np.testing.assert_allclose(post.mean[i], m, rtol=1e-12)
        np.testing.assert_allclose(post.cov[i], C, rtol=1e-9, atol=1e-9 * np.abs(C).max())
        assert np.array_equal(post.cov[i], post.cov[i].T)
