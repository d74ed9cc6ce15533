"""Tracks across agents (trackkit.network.tracks, Jalalipoor and Kardehi Moghaddam
2021, eqs. 39 and 51): similarity S_ij, track-to-track matching, duplicate pruning by
(P11 + P22)(P33 + P44), the message memory."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from trackkit.network.tracks import (
    DEFAULT_GATE,
    Message,
    MessageMemory,
    duplicates,
    match_tracks,
    matches_within,
    similarity,
    uncertainty,
)


def _random_tracks(rng, n_tracks, batch=()):
    x = rng.normal(0.0, 1000.0, batch + (n_tracks, 4))
    A = rng.normal(size=batch + (n_tracks, 4, 4))
    P = A @ A.swapaxes(-1, -2) + np.diag([100.0, 100.0, 1.0, 1.0])
    return x, P


def test_similarity_is_the_mahalanobis_distance_of_the_difference():
    rng = np.random.default_rng(1)
    xa, Pa = _random_tracks(rng, 3)
    xb, Pb = _random_tracks(rng, 2)
    S = similarity(xa, Pa, xb, Pb)
    assert S.shape == (3, 2)
    for i, j in itertools.product(range(3), range(2)):
        d = xa[i] - xb[j]
        np.testing.assert_allclose(S[i, j], d @ np.linalg.solve(Pa[i] + Pb[j], d), rtol=1e-12)


def test_the_default_gate_keeps_99_percent_of_a_targets_twin_tracks():
    """Two independent consistent estimates of one target: S ~ chi2(4), so the gate
    chi2.ppf(0.99, 4) keeps 99% of them; 40 000 pairs, the fraction within 4 standard errors
    (0.002) of 0.99."""
    assert DEFAULT_GATE == pytest.approx(chi2.ppf(0.99, 4), rel=1e-14)
    rng = np.random.default_rng(2)
    n = 40_000
    _, Pa = _random_tracks(rng, n)
    _, Pb = _random_tracks(rng, n)
    truth = rng.normal(0.0, 1e4, (n, 4))
    xa = truth + np.einsum("nij,nj->ni", np.linalg.cholesky(Pa), rng.standard_normal((n, 4)))
    xb = truth + np.einsum("nij,nj->ni", np.linalg.cholesky(Pb), rng.standard_normal((n, 4)))
    S = similarity(xa[:, None], Pa[:, None], xb[:, None], Pb[:, None])[:, 0, 0]
    inside = np.mean(S <= DEFAULT_GATE)
    assert abs(inside - 0.99) < 4 * np.sqrt(0.99 * 0.01 / n)


def _brute_force(S, gate):
    """The most pairs inside the gate, then the least summed S: over every one-to-one
    partial assignment."""
    A, B = S.shape
    best = (0, 0.0, ())
    for k in range(min(A, B), 0, -1):
        for rows in itertools.combinations(range(A), k):
            for cols in itertools.permutations(range(B), k):
                s = S[list(rows), list(cols)]
                if (s <= gate).all() and (k > best[0] or (k == best[0] and s.sum() < best[1])):
                    best = (k, s.sum(), tuple(zip(rows, cols, strict=True)))
        if best[0]:
            break
    return best


def test_matching_takes_the_most_gated_pairs_at_the_least_cost():
    """Against brute force over every partial one-to-one assignment of 200 random problems
    (up to 4 x 4 tracks, neighbours' tracks near some of ours)."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        A, B = rng.integers(1, 5, size=2)
        xa, Pa = _random_tracks(rng, A)
        xb, Pb = _random_tracks(rng, B)
        near = rng.random(B) < 0.6
        src = rng.integers(0, A, B)
        xb[near] = xa[src[near]] + rng.normal(0, 20.0, (near.sum(), 4))
        m = match_tracks(xa, Pa, xb, Pb)
        S = similarity(xa, Pa, xb, Pb)
        k, total, _ = _brute_force(S, DEFAULT_GATE)
        assert len(m.a) == k
        assert len(set(m.a)) == k and len(set(m.b)) == k
        np.testing.assert_allclose(m.s.sum(), total, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(m.s, S[m.a, m.b])


def test_pairs_sharing_no_track_skip_the_assignment_with_its_answer():
    """``matches_within``'s shortcut (the pairs inside the gate share no track, so the optimum
    holds them all) gives the assignment's pairs, order and similarities bit for bit, on 5 000
    random problems of up to 5 x 5 tracks that take either path."""
    rng = np.random.default_rng(11)
    paths = {True: 0, False: 0}
    for _ in range(5000):
        S = rng.exponential(2.0 * DEFAULT_GATE, size=tuple(rng.integers(1, 6, size=2)))
        inside = S <= DEFAULT_GATE
        if not inside.any():
            continue
        big = 1.0 + DEFAULT_GATE * min(S.shape)
        rows, cols = linear_sum_assignment(np.where(inside, S, big))
        keep = inside[rows, cols]
        m = matches_within(S, DEFAULT_GATE)
        for got, want in ((m.a, rows[keep]), (m.b, cols[keep]), (m.s, S[rows[keep], cols[keep]])):
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
        paths[bool(inside.sum(0).max() == 1 and inside.sum(1).max() == 1)] += 1
    assert min(paths.values()) > 1000, paths


def test_nothing_inside_the_gate_matches_nothing():
    x = np.zeros((1, 4))
    P = np.eye(4)[None]
    m = match_tracks(x, P, x + 1e3, P)
    assert m.a.size == m.b.size == m.s.size == 0


def test_uncertainty_is_position_sum_times_velocity_sum():
    P = np.diag([4.0, 9.0, 0.25, 1.0])
    assert uncertainty(P) == (4.0 + 9.0) * (0.25 + 1.0)


def test_duplicates_drop_the_more_uncertain_of_each_similar_pair():
    """a ~ b ~ c in a chain (a and c apart), U_a < U_b < U_c: b and c go; d is alone and
    stays; two identical tracks: the lower index stays."""
    P = np.diag([100.0, 100.0, 1.0, 1.0])
    x = np.array([[0.0, 0, 0, 0], [30.0, 0, 0, 0], [60.0, 0, 0, 0], [5000.0, 0, 0, 0]])
    Ps = np.stack([P, 1.1 * P, 1.2 * P, 5 * P])
    S = similarity(x, Ps, x, Ps)
    assert S[0, 1] < DEFAULT_GATE and S[1, 2] < DEFAULT_GATE and S[0, 2] > DEFAULT_GATE
    assert duplicates(x, Ps).tolist() == [False, True, True, False]
    assert duplicates(np.stack([x[0], x[0]]), np.stack([P, P])).tolist() == [False, True]


def test_duplicates_are_batched():
    rng = np.random.default_rng(4)
    x, P = _random_tracks(rng, 5, batch=(3,))
    x[:, 1] = x[:, 0] + 1.0
    d = duplicates(x, P)
    for r in range(3):
        np.testing.assert_array_equal(d[r], duplicates(x[r], P[r]))
    assert d[:, :2].any(axis=1).all()


def test_message_memory_keeps_the_newest_and_forgets_the_old():
    mem = MessageMemory(keep_s=30.0)
    mem.receive(Message(1, 10.0, "a"))
    mem.receive(Message(2, 20.0, "b"))
    mem.receive(Message(1, 5.0, "late"))  # older than what is held: stale
    assert mem.stale == 1 and [m.payload for m in mem] == ["a", "b"]
    assert mem.neighbours(35.0) == [1, 2]
    assert mem.neighbours(45.0) == [2] and mem.expired == 1
    mem.receive(Message(1, 44.0, "c"))
    assert [m.payload for m in mem] == ["c", "b"] and len(mem) == 2


@pytest.mark.parametrize("call, message", [
    (lambda: similarity(np.zeros((2, 4)), np.zeros((2, 4, 3)), np.zeros((1, 4)),
                        np.eye(4)[None]), r"means \(2, 4\) and covariances \(2, 4, 3\)"),
    (lambda: similarity(np.zeros((1, 4)), np.eye(4)[None], np.zeros((1, 2)),
                        np.eye(2)[None]), "tracks of 4 and 2 states"),
    (lambda: similarity(np.full((1, 4), np.nan), np.eye(4)[None], np.zeros((1, 4)),
                        np.eye(4)[None]), "non-finite"),
    (lambda: match_tracks(np.zeros((1, 4)), np.eye(4)[None], np.zeros((1, 4)),
                          np.eye(4)[None], gate=0.0), "gate = 0.0; expected a number > 0"),
    (lambda: uncertainty(np.eye(3)), r"shape \(3, 3\); expected \(\.\.\., 4, 4\)"),
    (lambda: MessageMemory(keep_s=0), "keep_s = 0; expected seconds > 0"),
    (lambda: MessageMemory(5.0).receive(Message(1, float("nan"), None)), "finite time"),
])
def test_bad_input_is_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()
