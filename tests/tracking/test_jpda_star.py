"""JPDA* (Blom and Bloem 2000): ``jpda_probabilities(..., star=True)`` against a literal brute-force
enumeration, its invariants, equality with plain JPDA when no swap is more likely, and the
coalescence it removes on swapped-symmetric geometry."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import trackkit as tk
from trackkit.tracking.association import _log_ratio, jpda_probabilities
from trackkit.tracking.gating import Gate, gate, predict_measurement
from trackkit.tracking.tracker import JPDA

from .pdaf import jpda_update

PD, LAM = 0.9, 1e-3


def make_gate(pairs, T, D, loglik, m=2, threshold=9.21):
    order = sorted(range(len(pairs)), key=lambda p: pairs[p])
    t = np.array([pairs[p][0] for p in order], dtype=np.intp)
    d = np.array([pairs[p][1] for p in order], dtype=np.intp)
    ll = np.asarray(loglik, dtype=float)[order]
    return Gate(t, d, -2.0 * ll, ll, np.zeros((t.size, m)), T, D, threshold)


def brute(g: Gate, star: bool):
    """Every feasible joint event of the whole scan, pruned literally (JPDA*: drop an event
    if some two detected tracks have a gated swap of higher weight), then normalised."""
    lr = _log_ratio(g, PD, LAM, None)
    r = {(int(i), int(j)): float(v) for i, j, v in zip(g.track, g.det, lr, strict=True)}
    opts = [[-1] + [j for (i, j) in r if i == t] for t in range(g.n_tracks)]
    events, logw = [], []
    for ev in itertools.product(*opts):
        dets = [j for j in ev if j >= 0]
        if len(dets) != len(set(dets)):
            continue
        if star:
            pruned = False
            for i, k in itertools.combinations(range(g.n_tracks), 2):
                j, m = ev[i], ev[k]
                if j < 0 or m < 0 or (i, m) not in r or (k, j) not in r:
                    continue
                if r[i, m] + r[k, j] > r[i, j] + r[k, m]:
                    pruned = True
            if pruned:
                continue
        events.append(ev)
        logw.append(sum(r[i, j] for i, j in enumerate(ev) if j >= 0))
    w = np.exp(np.array(logw) - max(logw))
    w /= w.sum()
    beta = np.zeros(g.size)
    beta0 = np.zeros(g.n_tracks)
    key = {(int(i), int(j)): p for p, (i, j) in enumerate(zip(g.track, g.det, strict=True))}
    for ev, p in zip(events, w, strict=True):
        for i, j in enumerate(ev):
            if j < 0:
                beta0[i] += p
            else:
                beta[key[i, j]] += p
    return beta, beta0


def random_gate(rng: np.random.Generator) -> Gate:
    T, D = int(rng.integers(1, 5)), int(rng.integers(1, 5))
    mask = rng.random((T, D)) < 0.6
    pairs = [(int(i), int(j)) for i, j in zip(*np.nonzero(mask), strict=True)]
    # log-likelihoods on a coarse grid too, so that exact ties occur
    ll = np.where(rng.random(len(pairs)) < 0.3, -1.0, rng.normal(-3.0, 2.0, len(pairs)))
    return make_gate(pairs, T, D, ll)


@pytest.mark.parametrize("seed", range(300))
def test_star_matches_brute_force(seed):
    g = random_gate(np.random.default_rng(seed))
    for star in (False, True):
        r = jpda_probabilities(g, PD, LAM, star=star)
        beta, beta0 = brute(g, star)
        np.testing.assert_allclose(r.beta, beta, atol=1e-12)
        np.testing.assert_allclose(r.beta0, beta0, atol=1e-12)
        assert not r.approximated.any()
        # per track the marginals sum to 1, per detection to at most 1
        tot = r.beta0 + np.bincount(g.track, r.beta, minlength=g.n_tracks)
        np.testing.assert_allclose(tot, 1.0, atol=1e-12)
        assert np.all(np.bincount(g.det, r.beta, minlength=g.n_dets) <= 1.0 + 1e-12)


def test_star_equals_plain_without_swaps():
    # a chain: no two tracks gate the same two detections, so no event has a swap
    g = make_gate([(0, 0), (0, 1), (1, 1), (1, 2), (2, 2), (2, 3)], T=3, D=4,
                  loglik=[-1.0, -0.5, -4.0, -0.2, -3.0, -2.0])
    a, b = jpda_probabilities(g, PD, LAM), jpda_probabilities(g, PD, LAM, star=True)
    np.testing.assert_array_equal(a.beta, b.beta)
    np.testing.assert_array_equal(a.beta0, b.beta0)
    # all four pairs gated but swaps exactly as likely: nothing is pruned
    g = make_gate([(0, 0), (0, 1), (1, 0), (1, 1)], T=2, D=2, loglik=[-1.0, -2.0, -3.0, -4.0])
    a, b = jpda_probabilities(g, PD, LAM), jpda_probabilities(g, PD, LAM, star=True)
    np.testing.assert_allclose(a.beta, b.beta, rtol=1e-14)


def test_star_equals_plain_well_separated():
    rng = np.random.default_rng(1)
    sensor = tk.models.Position(dim=2, sigma=10.0)
    x = np.array([[0.0, 0.0], [5e3, 0.0], [0.0, 5e3]])
    prior = tk.Gaussian(x, np.tile(np.eye(2) * 100.0, (3, 1, 1)))
    z = np.concatenate([x + rng.normal(0, 10.0, x.shape), rng.uniform(-50, 50, (4, 2))])
    mp = predict_measurement(prior, sensor)
    g = gate(mp.zhat, mp.S, z)
    a, b = jpda_probabilities(g, PD, LAM), jpda_probabilities(g, PD, LAM, star=True)
    np.testing.assert_array_equal(a.beta, b.beta)
    np.testing.assert_array_equal(a.beta0, b.beta0)


def test_star_removes_coalescence():
    """Two tracks 1 apart, their detections 3 apart, mirror-symmetric (P = 4 I, R = I, so
    K = 0.8 I): plain JPDA gives the swapped event about a third of the weight and pulls the
    updated means together; JPDA* prunes it and keeps them apart."""
    sensor = tk.models.Position(dim=2, sigma=1.0)
    prior = tk.Gaussian(np.array([[0.0, -0.5], [0.0, 0.5]]), np.tile(4.0 * np.eye(2), (2, 1, 1)))
    z = np.array([[0.0, -1.5], [0.0, 1.5]])
    mp = predict_measurement(prior, sensor)
    g = gate(mp.zhat, mp.S, z)
    assert g.size == 4
    sep = {}
    for star in (False, True):
        r = jpda_probabilities(g, 0.99, 1e-4, star=star)
        post = jpda_update(prior, mp.K, mp.S, g.track, g.nu, r.beta, r.beta0)
        sep[star] = post.mean[1, 1] - post.mean[0, 1]
    # with certain association each mean moves 0.8 of the way to its detection: 2.6 apart
    assert sep[False] < 1.5
    assert sep[True] == pytest.approx(2.6, abs=0.01)


def test_jpda_associator_flag():
    assert JPDA().star is False
    assert JPDA(star=True).star is True
