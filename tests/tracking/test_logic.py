"""Track logic: M-of-N history logic against a scalar reference and MATLAB's documented
behaviour, the SPRT score logic, and the track ID counter."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackkit.tracking.logic import (
    HistoryLogic,
    HistoryState,
    IdCounter,
    ScoreLogic,
    ScoreState,
    TrackStatus,
    concatenate,
    confirmed,
    held,
    select,
    sprt_thresholds,
    tentative,
    to_delete,
)

T, C, D = TrackStatus.TENTATIVE, TrackStatus.CONFIRMED, TrackStatus.DELETED
L = TrackStatus.LOST


# ------------------------------------------------------------------------------------------
# A straightforward scalar M-of-N reference: a Python list, most recent update first.


def reference_history(confirm, delete, pad_as_miss, updates):
    """Statuses after birth and after each of ``updates`` (bools), for one track."""
    M, N = confirm
    P, R = delete
    hist = [True]  # the birth detection
    status = T
    out = []

    def decide(status):
        if status == D:
            return D
        if status == C or sum(hist[:N]) >= M:
            window = hist[:R]
            misses = (R if pad_as_miss else len(window)) - sum(window)
            return D if misses >= P else C
        # tentative: can it still reach M hits within its first N updates?
        hits_so_far = sum(hist[:N])
        updates_left = N - len(hist)
        return D if hits_so_far + updates_left < M else T

    status = decide(status)
    out.append((status, list(hist)))
    for h in updates:
        hist.insert(0, bool(h))
        status = decide(status)
        out.append((status, list(hist)))
    return out


def _bits(history: int, n: int) -> list[bool]:
    return [bool((int(history) >> k) & 1) for k in range(n)]


# small windows most of the time (where confirmations and deletions happen), up to 64 bits
thresholds = st.one_of(st.integers(1, 8), st.integers(1, 64)).flatmap(
    lambda n: st.tuples(st.integers(1, n), st.just(n))
)


@settings(max_examples=150, deadline=None)
@given(confirm=thresholds, delete=thresholds, pad=st.booleans(), data=st.data())
def test_history_batched_equals_scalar_reference(confirm, delete, pad, data):
    """Batched logic == the list-based reference, track by track, at every update, for
    random thresholds and hit/miss sequences (the reference's tentative rule is written as
    "hits so far + updates left in the first N < M", the logic's as a miss count)."""
    n_tracks = data.draw(st.integers(1, 6))
    n_steps = data.draw(st.integers(0, 80))
    p_hit = data.draw(st.sampled_from([0.1, 0.5, 0.9]))
    seed = data.draw(st.integers(0, 2**32 - 1))
    hits = np.random.default_rng(seed).random((n_steps, n_tracks)) < p_hit
    logic = HistoryLogic(confirm, delete, pad_as_miss=pad)
    s = logic.init(n_tracks)
    got = [s]
    for h in hits:
        s = logic.step(s, h)
        got.append(s)
    for t in range(n_tracks):
        ref = reference_history(confirm, delete, pad, hits[:, t])
        for k, (status, hist) in enumerate(ref):
            assert got[k].status[t] == status, (t, k, hist)
            assert got[k].age[t] == len(hist)
            w = logic.window
            assert _bits(got[k].history[t], w) == (hist + [False] * w)[:w]
    # a tentative track never outlives its confirmation window
    assert all(np.all(st_.age[tentative(st_)] <= confirm[1]) for st_ in got)


def test_history_first_update_is_a_hit_matlab_init_example():
    """MATLAB init: default thresholds [2 3] and [6 6]; init gives History [1 0 0 0 0 0],
    not confirmed; a miss gives [0 1 0 0 0 0]; a hit [1 1 0 0 0 0] (MATLAB's hit/miss
    examples)."""
    logic = HistoryLogic()
    assert logic.confirm == (2, 3) and logic.delete == (6, 6) and logic.window == 6
    s = logic.init(2)
    assert _bits(s.history[0], 6) == [True] + [False] * 5
    assert np.all(s.age == 1) and np.all(tentative(s))
    s = logic.step(s, np.array([False, True]))
    assert _bits(s.history[0], 6) == [False, True, False, False, False, False]
    assert _bits(s.history[1], 6) == [True, True, False, False, False, False]
    assert list(s.status) == [T, C]


def test_history_matlab_check_confirmation_example():
    """MATLAB checkConfirmation: [2 3], [3 3]; init -> [1 0 0] not confirmed; hit ->
    [1 1 0] confirmed."""
    logic = HistoryLogic((2, 3), (3, 3))
    s = logic.init(1)
    assert not confirmed(s)[0]
    s = logic.step(s, np.array([True]))
    assert _bits(s.history[0], 3) == [True, True, False] and confirmed(s)[0]


def test_history_matlab_check_deletion_example_and_padding():
    """MATLAB checkDeletion: [2 3], [4 5]; after init the plain deletion check counts the
    zero padding and flags [1 0 0 0 0] (4 misses of 5) -- ``pad_as_miss=True`` reproduces
    the count; by default only the track's own update counts. As a tentative track (the
    tentative form of checkDeletion) it is kept either way."""
    for pad, misses in [(True, 4), (False, 0)]:
        logic = HistoryLogic((2, 3), (4, 5), pad_as_miss=pad)
        s = logic.init(1)
        assert logic.misses_in_delete_window(s)[0] == misses
        assert tentative(s)[0]
        s = logic.step(s, np.array([True]))
        assert confirmed(s)[0]


def test_history_scalar_thresholds_and_confirm_at_birth():
    """A scalar threshold M means [M M] (MATLAB); M = 1 confirms at birth."""
    logic = HistoryLogic(confirm=1, delete=3)
    assert logic.confirm == (1, 1) and logic.delete == (3, 3)
    s = logic.init(3)
    assert np.all(confirmed(s))
    for _ in range(2):
        s = logic.step(s, np.array([False, True, False]))
    assert list(s.status) == [C, C, C]
    s = logic.step(s, np.array([False, False, True]))
    assert list(s.status) == [D, C, C]


@pytest.mark.parametrize(
    "confirm, updates, statuses",
    [
        # [2 3]: one miss is allowed (N - M = 1), a second kills the tentative track
        ((2, 3), [0, 0], [T, T, D]),
        ((2, 3), [0, 1], [T, T, C]),
        ((2, 3), [1], [T, C]),
        # [3 5]: two misses allowed; confirmed on the last possible update
        ((3, 5), [0, 0, 0], [T, T, T, D]),
        ((3, 5), [0, 0, 1, 1], [T, T, T, T, C]),
        ((3, 5), [0, 1, 0, 1], [T, T, T, T, C]),
        ((3, 5), [1, 0, 0, 0], [T, T, T, T, D]),
        # [3 3]: no miss allowed
        ((3, 3), [1, 0], [T, T, D]),
    ],
)
def test_history_tentative_deletion(confirm, updates, statuses):
    """A tentative track is deleted as soon as it can no longer reach M hits in its first N
    updates (MATLAB checkDeletion(logic, true, age))."""
    logic = HistoryLogic(confirm, (6, 6))
    s = logic.init(1)
    got = [s.status[0]]
    for u in updates:
        s = logic.step(s, np.array([bool(u)]))
        got.append(s.status[0])
    assert got == statuses


def test_history_confirmed_deletion_and_absorbing():
    """A confirmed track is deleted at P misses in the last R updates; deleted stays
    deleted (even after hits)."""
    logic = HistoryLogic((2, 3), (3, 5))
    s = logic.init(1)
    got = []
    for u in [1, 0, 0, 1, 0, 0, 1, 1]:
        s = logic.step(s, np.array([bool(u)]))
        got.append(s.status[0])
    # history after each: 11, 011, 0011, 10011, 010011 (3 misses in the last 5: deleted)
    assert got == [C, C, C, C, D, D, D, D]
    assert to_delete(s)[0]


def test_history_batch_shape_and_select_concatenate():
    logic = HistoryLogic((2, 3), (2, 2))
    s = logic.init((2, 3))
    s = logic.step(s, np.ones((2, 3), dtype=bool))
    assert s.status.shape == (2, 3) and np.all(confirmed(s))
    a, b = logic.init(2), logic.step(logic.init(3), np.array([True, False, True]))
    both = concatenate(a, b)
    assert isinstance(both, HistoryState) and both.age.tolist() == [1, 1, 2, 2, 2]
    kept = select(both, ~to_delete(both))
    assert kept.age.shape == (5,)
    assert select(both, np.array([4, 0])).age.tolist() == [2, 1]
    with pytest.raises(ValueError, match="one type"):
        concatenate(a, ScoreLogic(0.9, 1e-6, 1e-7).init(1))


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"confirm": (3, 2)}, "confirm"),
        ({"confirm": (0, 3)}, "confirm"),
        ({"confirm": (2, 65)}, "confirm"),
        ({"confirm": 2.5}, "confirm"),
        ({"delete": (1, 2, 3)}, "delete"),
        ({"pad_as_miss": 1}, "pad_as_miss"),
    ],
)
def test_history_bad_parameters(kwargs, name):
    with pytest.raises(ValueError, match=name):
        HistoryLogic(**kwargs)


def test_history_bad_hits():
    logic = HistoryLogic()
    s = logic.init(3)
    with pytest.raises(ValueError, match="dtype"):
        logic.step(s, np.array([1, 0, 1]))
    with pytest.raises(ValueError, match="shape"):
        logic.step(s, np.array([True, False]))


# ------------------------------------------------------------------------------------------
# Score logic


def test_sprt_thresholds():
    """T_confirm = ln((1-beta)/alpha), T_delete = ln(beta/(1-alpha)) (Wald)."""
    alpha, beta = 1e-6, 1e-3
    tc, td = sprt_thresholds(alpha, beta)
    assert tc == pytest.approx(np.log((1 - beta) / alpha), rel=1e-15)
    assert td == pytest.approx(np.log(beta / (1 - alpha)), rel=1e-15)
    assert tc == pytest.approx(13.8145, abs=1e-4) and td == pytest.approx(-6.9078, abs=1e-4)
    logic = ScoreLogic.from_sprt(alpha, beta, pd=0.9, clutter_density=1e-6,
                                 new_target_density=1e-7)
    assert (logic.confirm_threshold, logic.delete_threshold) == (tc, td)
    for a, b in [(0.0, 0.1), (0.1, 1.0), (0.6, 0.5), (np.nan, 0.1)]:
        with pytest.raises(ValueError, match="alpha|beta"):
            sprt_thresholds(a, b)


def test_score_matlab_initial_scores():
    """MATLAB trackScoreLogic init(logic, volume, beta) with pd 0.9, pfa 1e-6, volume 1.3:
    scores 11.6699 (beta 0.1), 12.7685 (0.3), 2.4596 (1e-5): L_1 = ln(P_D beta / lambda)
    with lambda = pfa / volume."""
    for beta, want in [(0.1, 11.6699), (0.3, 12.7685), (1e-5, 2.4596)]:
        logic = ScoreLogic(pd=0.9, clutter_density=1e-6 / 1.3, new_target_density=beta)
        s = logic.init(2)
        assert np.allclose(s.score, want, atol=5e-5) and np.array_equal(s.max_score, s.score)


def reference_score(logic, hits, log_liks):
    """Scalar loop: the textbook increments and MATLAB's tests, for one track."""
    score = np.log(logic.pd * logic.new_target_density / logic.clutter_density)
    best, status = score, T
    out = []

    def decide(status):
        if status == D or score - best < logic.delete_threshold:
            return D
        return C if status == C or score >= logic.confirm_threshold else T

    status = decide(status)
    out.append((score, best, status))
    for h, ll in zip(hits, log_liks, strict=True):
        if h:
            score += np.log(logic.pd) + ll - np.log(logic.clutter_density)
        else:
            score += np.log(1 - logic.pd * logic.pg)
        best = max(best, score)
        status = decide(status)
        out.append((score, best, status))
    return out


@pytest.mark.parametrize("seed", range(5))
def test_score_batched_equals_scalar_reference(seed):
    rng = np.random.default_rng(seed)
    logic = ScoreLogic.from_sprt(1e-5, 1e-2, pd=rng.uniform(0.5, 0.99),
                                 clutter_density=10 ** rng.uniform(-8, -4),
                                 new_target_density=10 ** rng.uniform(-9, -5),
                                 pg=rng.uniform(0.9, 1.0))
    n_tracks, n_steps = 8, 40
    hits = rng.random((n_steps, n_tracks)) < rng.uniform(0.3, 0.95, n_tracks)
    # log N(nu; 0, S) of a 2-D measurement: -ln(2 pi sqrt|S|) - d2/2, S ~ (30 m)^2 I
    lls = -np.log(2 * np.pi * 900.0) - 0.5 * rng.chisquare(2, (n_steps, n_tracks))
    lls[~hits] = np.nan  # ignored at misses
    s = logic.init(n_tracks)
    got = [s]
    for h, ll in zip(hits, lls, strict=True):
        s = logic.step(s, h, ll)
        got.append(s)
    for t in range(n_tracks):
        for k, (score, best, status) in enumerate(reference_score(logic, hits[:, t],
                                                                 lls[:, t])):
            assert got[k].score[t] == pytest.approx(score, rel=1e-12, abs=1e-12)
            assert got[k].max_score[t] == pytest.approx(best, rel=1e-12, abs=1e-12)
            assert got[k].status[t] == status


def test_score_confirm_sticky_and_delete_on_drop():
    """Confirmed at L >= T_c and stays confirmed while the score falls; deleted once
    L - max L < T_d; deleted is absorbing."""
    logic = ScoreLogic(pd=0.9, clutter_density=1e-4, new_target_density=1e-5,
                       confirm_threshold=8.0, delete_threshold=-5.0)
    ll = np.array([-5.0])  # a hit adds ln 0.9 - 5 + ln 1e4 = 4.105
    s = logic.init(1)  # L_1 = ln(0.09) = -2.408
    assert s.score[0] == pytest.approx(np.log(0.09))
    statuses = []
    for h in [1, 1, 1, 0, 0, 1]:
        s = logic.step(s, np.array([bool(h)]), ll)
        statuses.append(s.status[0])
    # scores: 1.697, 5.802, 9.907 (confirm), 7.605, 5.302 (drop 4.6: kept), then a hit
    assert statuses == [T, T, C, C, C, C]
    s = logic.step(s, np.array([False]))  # 7.105: 2.8 below the max 9.907
    assert confirmed(s)[0]
    s = logic.step(s, np.array([False]))  # 4.802: 5.1 below the max
    assert to_delete(s)[0]
    s = logic.step(s, np.array([True]), ll)
    assert to_delete(s)[0]
    assert isinstance(s, ScoreState)


def reference_held_score(logic, hits, log_liks):
    """Scalar loop of the hold rule: a confirmed track more than the delete threshold below
    its maximum score is LOST, CONFIRMED again once back within it, deleted beyond the hold
    threshold."""
    score = np.log(logic.pd * logic.new_target_density / logic.clutter_density)
    best, status = score, T

    def decide(status):
        drop = score - best
        if status == D or drop < logic.hold_threshold:
            return D
        if status == T and score >= logic.confirm_threshold:
            status = C
        if drop < logic.delete_threshold:
            return D if status == T else L
        return T if status == T else C

    status = decide(status)
    out = [(score, best, status)]
    for h, ll in zip(hits, log_liks, strict=True):
        score += (np.log(logic.pd) + ll - np.log(logic.clutter_density) if h
                  else np.log(1 - logic.pd * logic.pg))
        best = max(best, score)
        status = decide(status)
        out.append((score, best, status))
    return out


@pytest.mark.parametrize("seed", range(5))
def test_score_with_hold_equals_scalar_reference(seed):
    rng = np.random.default_rng(100 + seed)
    logic = ScoreLogic.from_sprt(1e-2, 1e-3, pd=0.9, clutter_density=1e-6,
                                 new_target_density=1e-8, hold_threshold=-30.0)
    n_tracks, n_steps = 12, 80
    # runs of hits and of misses, so tracks are confirmed, lost, taken up again and deleted
    p_hit = rng.uniform(0.2, 0.95, n_tracks)
    hits = np.zeros((n_steps, n_tracks), dtype=bool)
    hits[0] = True
    for k in range(1, n_steps):
        stay = rng.random(n_tracks) < 0.85
        hits[k] = np.where(stay, hits[k - 1], rng.random(n_tracks) < p_hit)
    lls = -np.log(2 * np.pi * 900.0) - 0.5 * rng.chisquare(2, (n_steps, n_tracks))
    s = logic.init(n_tracks)
    got = [s]
    for h, ll in zip(hits, lls, strict=True):
        s = logic.step(s, h, ll)
        got.append(s)
    seen = set()
    for t in range(n_tracks):
        for k, (score, best, status) in enumerate(reference_held_score(logic, hits[:, t],
                                                                       lls[:, t])):
            assert got[k].score[t] == pytest.approx(score, rel=1e-12, abs=1e-12)
            assert got[k].max_score[t] == pytest.approx(best, rel=1e-12, abs=1e-12)
            assert got[k].status[t] == status
            seen.add(int(status))
    assert seen == {T, C, D, L}  # the draws walk every status


def test_score_hold_loses_takes_up_and_deletes():
    """With a hold, the miss that would delete a confirmed track makes it LOST (not
    confirmed, held); hits bring it back once its score is again within the delete
    threshold of its maximum; enough misses delete it. A tentative track is deleted at the
    delete threshold as without a hold."""
    logic = ScoreLogic(pd=0.9, clutter_density=1e-4, new_target_density=1e-5,
                       confirm_threshold=8.0, delete_threshold=-5.0, hold_threshold=-12.0)
    ll = np.array([-5.0, -5.0])  # a hit adds 4.105, a miss ln 0.1 = -2.303
    s = logic.init(2)
    for h in ([1, 0], [1, 0], [1, 0]):  # track 0 confirmed at 9.907; track 1 deleted
        s = logic.step(s, np.array(h, bool), ll)
    assert list(s.status) == [C, D]
    for k in range(4):  # drops 2.3, 4.6, 6.9 (lost), 9.2
        s = logic.step(s, np.array([False, False]))
        assert s.status[0] == (C if k < 2 else L)
    assert held(s)[0] and not confirmed(s)[0]
    s = logic.step(s, np.array([True, False]), ll)  # drop 5.1: held still
    assert s.status[0] == L
    s = logic.step(s, np.array([True, False]), ll)  # 1.0 below the max: seen again
    assert s.status[0] == C
    for k in range(5):  # drops 3.3, 5.6 (lost), 7.9, 10.2, 12.5 (gone)
        s = logic.step(s, np.array([False, False]))
        assert s.status[0] == (C, L, L, L, D)[k]
    assert to_delete(s)[0]


def test_score_hit_increment_matches_matlab_form():
    """MATLAB's hit adds ln(V * likelihood * P_D / P_FA); with lambda = P_FA / V that is
    ln P_D + ln likelihood - ln lambda."""
    pd, pfa, V, like = 0.8, 1e-3, 1.3, 0.0734
    logic = ScoreLogic(pd=pd, clutter_density=pfa / V, new_target_density=1e-5)
    s0 = logic.init(1)
    s1 = logic.step(s0, np.array([True]), np.log([like]))
    assert s1.score[0] - s0.score[0] == pytest.approx(np.log(V * like * pd / pfa), rel=1e-13)
    s2 = logic.step(s0, np.array([False]))
    assert s2.score[0] - s0.score[0] == pytest.approx(np.log(1 - pd), rel=1e-13)


def test_score_bad_input():
    with pytest.raises(ValueError, match="pd"):
        ScoreLogic(pd=1.0, clutter_density=1e-6, new_target_density=1e-7)
    with pytest.raises(ValueError, match="clutter_density"):
        ScoreLogic(pd=0.9, clutter_density=0.0, new_target_density=1e-7)
    with pytest.raises(ValueError, match="delete_threshold"):
        ScoreLogic(pd=0.9, clutter_density=1e-6, new_target_density=1e-7, delete_threshold=1)
    with pytest.raises(ValueError, match="hold_threshold"):
        ScoreLogic(pd=0.9, clutter_density=1e-6, new_target_density=1e-7,
                   delete_threshold=-5.0, hold_threshold=-4.0)
    logic = ScoreLogic(pd=0.9, clutter_density=1e-6, new_target_density=1e-7)
    s = logic.init(2)
    with pytest.raises(ValueError, match="log_likelihood"):
        logic.step(s, np.array([True, False]))
    with pytest.raises(ValueError, match="log_likelihood"):
        logic.step(s, np.array([True, False]), np.array([np.nan, 0.0]))


# ------------------------------------------------------------------------------------------
# IDs


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 50), max_size=30), st.integers(0, 1000))
def test_ids_never_repeat(ks, start):
    counter = IdCounter(start)
    issued = []
    for k in ks:
        ids, counter = counter.issue(k)
        assert ids.dtype == np.int64 and ids.shape == (k,)
        issued.append(ids)
    allids = np.concatenate([np.zeros(0, np.int64), *issued])
    assert len(np.unique(allids)) == len(allids) == sum(ks)
    assert np.all(np.diff(allids) > 0)  # increasing in issue order
    assert counter.next_id == start + sum(ks)


def test_ids_default_start_and_bad_input():
    ids, c = IdCounter().issue(3)
    assert ids.tolist() == [1, 2, 3] and c.next_id == 4
    with pytest.raises(ValueError, match="k"):
        c.issue(-1)
    with pytest.raises(ValueError, match="next_id"):
        IdCounter(-5)
    with pytest.raises(ValueError, match="overflow"):
        IdCounter(np.iinfo(np.int64).max).issue(2)


# --------------------------------------------------------------------------------------------
# The timer logic of Jalalipoor and Kardehi Moghaddam (2021)


def test_timer_logic_walks_query_track_lost_deleted():
    """One track through every state: Query at birth, Track once confirm_after has passed
    with a recent measurement, Lost after lost_after without one (still confirmed), back to
    Track on a measurement, deleted after delete_after without one, and deleted stays."""
    from trackkit.tracking.logic import TimerLogic, lost

    logic = TimerLogic(confirm_after=30.0, lost_after=20.0, delete_after=100.0)
    s = logic.init(0.0, 1)
    seen = []
    for t, hit in [(10, True), (29, True), (30, False), (45, False), (50, False),
                   (60, True), (159, False), (160, False), (300, True)]:
        s = logic.step(s, float(t), np.array([hit]))
        seen.append((t, int(s.status[0]), bool(lost(s)[0])))
    T, C, D = TrackStatus.TENTATIVE, TrackStatus.CONFIRMED, TrackStatus.DELETED
    assert seen == [(10, T, False), (29, T, False), (30, C, False), (45, C, False),
                    (50, C, True), (60, C, False), (159, C, True), (160, D, False),
                    (300, D, False)]


def test_timer_logic_is_batched_and_a_quiet_query_is_not_confirmed():
    """Rows with their own birth times and hits step together (equal to one at a time); a
    Query track whose last measurement is older than lost_after is not confirmed when its
    confirmation time comes, and is deleted after delete_after like any track."""
    from trackkit.tracking.logic import TimerLogic

    logic = TimerLogic(confirm_after=30.0, lost_after=20.0, delete_after=50.0)
    s = logic.init(np.array([0.0, 5.0, 10.0]), 3)
    hits = [np.array([True, False, True]), np.array([False, False, True]),
            np.array([True, False, False])]
    rows = [logic.init(b, 1) for b in (0.0, 5.0, 10.0)]
    for t, h in zip((20.0, 40.0, 56.0), hits, strict=True):
        s = logic.step(s, t, h)
        rows = [logic.step(r, t, h[i:i + 1]) for i, r in enumerate(rows)]
    for i, r in enumerate(rows):
        for a, b in zip(s, r, strict=True):
            assert a[i] == b[0]
    assert s.status.tolist() == [TrackStatus.CONFIRMED, TrackStatus.DELETED,
                                 TrackStatus.CONFIRMED]


@pytest.mark.parametrize("kwargs, message", [
    ({"lost_after": 0.0}, "expected 0 < lost_after < delete_after"),
    ({"lost_after": 100.0, "delete_after": 50.0}, "expected 0 < lost_after < delete_after"),
    ({"confirm_after": -1.0}, "confirm_after = -1.0; expected seconds >= 0"),
    ({"delete_after": float("inf")}, "delete_after = inf"),
])
def test_timer_logic_refuses_bad_times(kwargs, message):
    from trackkit.tracking.logic import TimerLogic

    with pytest.raises(ValueError, match=message):
        TimerLogic(**kwargs)


def test_timer_logic_refuses_time_going_back():
    from trackkit.tracking.logic import TimerLogic

    logic = TimerLogic()
    s = logic.step(logic.init(0.0, 2), 10.0, np.array([True, True]))
    with pytest.raises(ValueError, match="not before each track's last measurement"):
        logic.step(s, 5.0, np.array([False, False]))
    with pytest.raises(ValueError, match="expected bool"):
        logic.step(s, 20.0, np.array([1, 0]))
