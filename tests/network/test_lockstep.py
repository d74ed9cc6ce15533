"""Runs of the agent network stepped together (``run_network_block``, ``lockstep.drive``)
against the same runs one at a time: bit for bit, and every batched kernel's answer equal
to its single call's."""

from __future__ import annotations

import hashlib
from collections import Counter

import numpy as np
import pytest

from trackkit.experiments import network_mc
from trackkit.linalg import CHOL_MIN_BATCH_FULL
from trackkit.network import lockstep
from trackkit.network.agents import Call, cv_predict, run_inline
from trackkit.network.inprocess import run_network, run_network_block
from trackkit.network.tracks import duplicates
from trackkit.scenario.network import load_network

RUNS = 4
DURATION = 300.0  # s: tracks confirmed, composites, combination and steering all in play


def _fingerprint(res) -> str:
    h = hashlib.sha256()
    for tr in res.agents + ([res.central] if res.central else []):
        for a in (tr.time, tr.offsets, tr.ids, tr.mean, tr.cov, tr.truth, tr.position):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(repr([tuple(r) for r in tr.reports]).encode())
    h.update(repr((res.sent, res.delivered, res.lost, res.spacing)).encode())
    if res.fusion is not None:
        for a in res.fusion:
            if isinstance(a, np.ndarray):
                h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _options(name: str, loss: float) -> dict:
    sc = load_network(name)
    net = sc.network
    return dict(duration=DURATION, period=net.period_s, sigma=sc.sigma_rad(),
                mr=sc.meas_range(), cr=sc.comm_range(), max_delay=net.max_delay_s, q=net.q,
                settings=network_mc._agent_settings(sc), steering=sc.settings.steering,
                central=sc.run.central, loss=loss)


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.fixture
def checked_kernels(monkeypatch):
    """Every batched kernel's answers compared with the single calls' as the block runs."""
    seen, differ = Counter(), Counter()
    for fn, many in list(lockstep.BATCHED.items()):
        def check(calls, fn=fn, many=many):
            got = many(calls)
            for args, answer in zip(calls, got, strict=True):
                seen[fn.__name__] += 1
                differ[fn.__name__] += not _same(answer, fn(*args))
            return got
        monkeypatch.setitem(lockstep.BATCHED, fn, check)
    return seen, differ


@pytest.mark.parametrize("name, loss", [("net-baseline", 0.0), ("net-limited", 0.1)])
def test_a_block_of_runs_equals_the_runs_one_at_a_time(name, loss, checked_kernels):
    sc = load_network(name)
    opts = _options(name, loss)
    targets = [sc.target_states(2026, r) for r in range(RUNS)]
    block = run_network_block(2026, list(range(RUNS)), targets, sc.agent_states(), **opts)
    one = [run_network(2026, r, targets[r], sc.agent_states(), **opts) for r in range(RUNS)]
    assert [_fingerprint(b) for b in block] == [_fingerprint(o) for o in one]
    seen, differ = checked_kernels
    print(dict(seen))
    # the steered network exercises every batched kernel except the one-row composites
    assert set(seen) >= {"associate", "predict_tracks", "cv_predict", "match_tracks",
                         "update_tracks", "combine_call", "steer_call", "duplicates",
                         "composites", "move", "bearings_at"}
    bad = {k: v for k, v in differ.items() if v}
    assert not bad, f"batched kernels that differ from their single calls: {bad}"
    # the runs really do differ from each other (no run's answer handed to another)
    assert len({_fingerprint(b) for b in block}) == RUNS


def test_the_monte_carlo_gives_the_same_numbers_in_blocks_of_any_size():
    sc = load_network("net-baseline")
    d = sc.model_dump()
    d["network"]["duration_s"] = DURATION
    short = type(sc).model_validate(d)
    a = network_mc.run_network_mc(short, runs=3, block=1, keep_example=False)
    b = network_mc.run_network_mc(short, runs=3, block=2, keep_example=False)
    for field in ("count", "gospa", "central_count", "central_gospa", "bound_pos", "bound_vel",
                  "bound_rng", "held_final", "final_range", "spacing", "sent", "delivered",
                  "lost"):
        assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=True), field
    for kind in a.err:
        assert np.array_equal(a.err[kind], b.err[kind], equal_nan=True), kind


def test_a_batched_kernel_one_ulp_off_is_caught(monkeypatch):
    sc = load_network("net-baseline")
    opts = _options("net-baseline", 0.0)
    targets = [sc.target_states(2026, r) for r in range(2)]
    one = [_fingerprint(run_network(2026, r, targets[r], sc.agent_states(), **opts))
           for r in range(2)]
    real = lockstep.BATCHED[cv_predict]

    def off(calls):
        return [(np.nextafter(x, np.inf), P) for x, P in real(calls)]
    monkeypatch.setitem(lockstep.BATCHED, cv_predict, off)
    block = run_network_block(2026, [0, 1], targets, sc.agent_states(), **opts)
    assert [_fingerprint(b) for b in block] != one


def test_batched_duplicates_equal_the_single_calls_on_both_sides_of_the_threshold():
    rng = np.random.default_rng(7)
    big = int(np.ceil(np.sqrt(CHOL_MIN_BATCH_FULL)))  # T * T pairs at the threshold: alone

    def tracks(T: int):
        # clustered tracks, so that some pairs fall inside the gate and some do not
        x = rng.normal(scale=[30, 30, 1, 1], size=(T, 4))
        A = rng.normal(size=(T, 4, 4))
        return x, A @ A.mT + 4 * np.eye(4) * [100, 100, 1, 1]

    calls = [(*tracks(T), 9.0) for T in (1, 3, 5, big, 2, 0, 4)]
    got = lockstep.BATCHED[duplicates](calls)
    want = [duplicates(*c) for c in calls]
    assert all(_same(g, w) for g, w in zip(got, want, strict=True))
    assert any(w.any() for w in want) and not all(w.all() for w in want if w.size)


def test_drive_answers_programs_that_branch_differently():
    def program(k: int):
        total = 0
        for i in range(k):  # k calls: the programs leave the rounds at different times
            total += yield Call(np.add, (i, k))
        if k % 2:
            total += (yield Call(np.multiply, (k, 10)))
        return total

    progs = [program(k) for k in range(6)]
    assert lockstep.drive(progs) == [run_inline(program(k)) for k in range(6)]


def test_a_block_refuses_a_target_set_per_run_missing():
    sc = load_network("net-baseline")
    with pytest.raises(ValueError, match="2 target sets for 3 runs"):
        run_network_block(2026, [0, 1, 2], [sc.target_states(2026, r) for r in range(2)],
                          sc.agent_states(), **_options("net-baseline", 0.0))


def test_run_network_mc_refuses_a_bad_block():
    with pytest.raises(ValueError, match="block = 0"):
        network_mc.run_network_mc(load_network("net-baseline"), runs=1, block=0)
