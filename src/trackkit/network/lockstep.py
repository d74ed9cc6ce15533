"""Many runs of the agents' program stepped together: a round of every program's kernel
call (:class:`~trackkit.network.agents.Call`) runs as one batched call per kernel.

The agent's program (``Agent.program``) yields each array computation it needs as a
``Call(fn, args)`` and is sent ``fn(*args)``. One run drives its programs one call at a time
(``run_inline``); a block of runs at one execution index (``run_network_block``) drives them
together with :func:`drive`: each round gathers the calls every waiting program has made,
groups them by kernel, and answers each group with one call of the kernel's batched form,
where it has one (:data:`BATCHED`), else one call per program. The programs branch as they
will (a run with no tracks skips the association its neighbour makes): a round holds
whatever calls are waiting.

A batched form computes each program's answer with the same floating-point operations, in
the same order, as the single call: the rows of every program are stacked and go through
the same elementwise and per-matrix operations, and where a kernel would change its method
with the size of the stack (``linalg.CHOL_MIN_BATCH_FULL``) the batched form keeps the
method the single call uses. A block's runs are therefore the one-at-a-time runs bit for bit
(``tests/network/test_lockstep.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import accumulate
from typing import Any

import numpy as np

from trackkit.belief import Gaussian
from trackkit.linalg import CHOL_MIN_BATCH_FULL
from trackkit.models.sensors import Bearing
from trackkit.network.agents import (
    Call,
    Program,
    associate,
    combine_call,
    composite_inputs,
    composite_step,
    composites,
    cv_predict,
    predict_tracks,
    scan_source,
    steer_call,
    update_tracks,
)
from trackkit.network.composite import Composite, composite_measurement
from trackkit.network.steering import CourseCommand, move
from trackkit.network.tracks import (
    Matches,
    dominated,
    duplicates,
    match_tracks,
    matches_within,
    uncertainty,
)
from trackkit.sim.sensor_network import bearings_at
from trackkit.tracking import (
    gate_pairs,
    gate_threshold,
    gnn_assign,
    predict_measurement,
    saturating_costs,
)

__all__ = ["BATCHED", "drive"]

#: a kernel's batched form: the list of argument tuples of one round's calls to the list
#: of their answers, each equal bit for bit to ``fn(*args)``
BATCHED: dict[Callable[..., Any], Callable[[list[tuple]], list[Any]]] = {}


def drive(programs: Sequence[Program]) -> list[Any]:
    """Run ``programs`` to their ends together (module docstring); their return values."""
    out: list[Any] = [None] * len(programs)
    waiting: dict[int, Call] = {}
    for i in range(len(programs)):
        _advance(programs, i, None, waiting, out, first=True)
    while waiting:
        groups: dict[Callable[..., Any], list[int]] = {}
        for i, call in waiting.items():
            groups.setdefault(call.fn, []).append(i)
        calls, waiting = waiting, {}
        for fn, idx in groups.items():
            many = BATCHED.get(fn)
            args = [calls[i].args for i in idx]
            answers = many(args) if many is not None and len(idx) > 1 else [fn(*a)
                                                                             for a in args]
            for i, answer in zip(idx, answers, strict=True):
                _advance(programs, i, answer, waiting, out)
    return out


def _advance(programs: Sequence[Program], i: int, answer: Any, waiting: dict[int, Call],
             out: list[Any], first: bool = False) -> None:
    try:
        waiting[i] = next(programs[i]) if first else programs[i].send(answer)
    except StopIteration as stop:
        out[i] = stop.value


def _grouped(calls: list[tuple], key: Callable[[tuple], Any],
             many: Callable[[list[tuple]], list[Any]]) -> list[Any]:
    """``many`` over each group of calls with one ``key`` (the parameters a stacked call
    must share), the answers back in the calls' order."""
    groups: dict[Any, list[int]] = {}
    for i, c in enumerate(calls):
        groups.setdefault(key(c), []).append(i)
    out: list[Any] = [None] * len(calls)
    for idx in groups.values():
        for i, answer in zip(idx, many([calls[i] for i in idx]), strict=True):
            out[i] = answer
    return out


def _associate_many(calls: list[tuple]) -> list[Any]:
    """``associate`` of several (tracks, scan) problems as one stacked scan: every track's
    prediction to its own scan's time and position, the gate on the pairs within each
    problem, the saturating costs and one assignment (each problem's tracks and bearings
    are their own clusters). Problems with no track or no bearing are answered alone."""
    def key(c: tuple) -> tuple:
        mean, _, _, b, s = c
        if mean.shape[0] == 0 or b.size == 0:
            return (None,)
        return s.q, s.p_gate, s.k1, s.k2, float(b.sigma[0])

    def many(group: list[tuple]) -> list[Any]:
        k = key(group[0])
        if k == (None,):
            return [associate(*c) for c in group]
        return _associate_stacked(group, *k)
    return _grouped(calls, key, many)


def _associate_stacked(calls: list[tuple], q: float, p_gate: float, k1: float, k2: float,
                       sigma: float) -> list[np.ndarray]:
    T = np.array([c[0].shape[0] for c in calls])
    D = np.array([c[3].size for c in calls])
    src = [scan_source(c[3]) for c in calls]
    dt = np.repeat([tk - c[2] for c, (tk, _) in zip(calls, src, strict=True)], T)
    origin = np.repeat(np.stack([sk for _, sk in src]), T, axis=0)
    x, P = cv_predict(np.concatenate([c[0] for c in calls]),
                      np.concatenate([c[1] for c in calls]), dt, q)
    pred = predict_measurement(Gaussian(x, P), Bearing(origin=origin, sigma=sigma))
    z = np.concatenate([c[3].z for c in calls])[:, None]
    t0 = np.concatenate([[0], np.cumsum(T)[:-1]])
    d0 = np.concatenate([[0], np.cumsum(D)[:-1]])
    # each problem's pairs in (track, bearing) order, as gate forms them
    pairs = [np.divmod(np.arange(n * m), m) for n, m in zip(T, D, strict=True)]
    track = np.concatenate([a + o for (a, _), o in zip(pairs, t0, strict=True)])
    det = np.concatenate([b + o for (_, b), o in zip(pairs, d0, strict=True)])
    L = np.linalg.cholesky(pred.S)  # gate's factor for stacks below CHOL_MIN_BATCH_FULL
    g = gate_pairs(pred.zhat, pred.S, L, z, track, det, gate_threshold(p_gate, 1),
                   angular=(True,))
    a = gnn_assign(g, saturating_costs(g, k1, k2)).det
    return [np.where(seg >= 0, seg - o, -1) for seg, o in
            zip(_split(a, T), d0, strict=True)]


BATCHED[associate] = _associate_many


def _split(a: np.ndarray, counts: Sequence[int]) -> list[np.ndarray]:
    """``a``'s leading axis cut into consecutive views of ``counts`` rows: ``np.split``'s
    views, without its per-call overhead (some 25 us, at tens of thousands of calls a run)."""
    ends = list(accumulate(int(k) for k in counts))
    return [a[start:end] for start, end in zip([0, *ends[:-1]], ends, strict=True)]


def _composite_measurement_many(calls: list[tuple]) -> list[Composite]:
    """``composite_measurement(z, t, sensor_pos, sigma, t_f, x0)`` of several problems as
    one: the rows stacked, each with its own t_f, and padded with missing bearings to the
    most slots (a row's fit skips its missing bearings, so its bits do not change)."""
    if not calls:
        return []
    rows = [np.atleast_2d(np.asarray(c[0], float)) for c in calls]
    n = [r.shape[0] for r in rows]
    M = max(r.shape[1] for r in rows)

    def stacked(i: int, fill: float, tail: tuple[int, ...] = ()) -> np.ndarray:
        out = np.full((sum(n), M) + tail, fill)
        at = 0
        for c, k in zip(calls, n, strict=True):
            m = np.shape(c[0])[-1]
            out[at:at + k, :m] = np.broadcast_to(c[i], (k, m) + tail)
            at += k
        return out
    z, t, S, sig = stacked(0, np.nan), stacked(1, 0.0), stacked(2, 0.0, (2,)), stacked(3, 1.0)
    tf = np.repeat([float(c[4]) for c in calls], n)
    x0 = np.concatenate([np.reshape(c[5], (k, 4)) for c, k in zip(calls, n, strict=True)])
    out = composite_measurement(z, t, S, sig, tf, x0)
    parts = [Composite(*f) for f in zip(*(_split(a, n) for a in out), strict=True)]
    return [p if np.ndim(c[0]) > 1 else Composite(*(a[0] for a in p))
            for p, c in zip(parts, calls, strict=True)]


def _composites_many(calls: list[tuple]) -> list[Any]:
    """``composites`` of several agents' tracks: their fits in one stacked call."""
    inputs = [composite_inputs(*c) for c in calls]
    fit = [i for i, (rows, _) in enumerate(inputs) if rows.size]
    fits = dict(zip(fit, _composite_measurement_many([inputs[i][1] for i in fit]),
                    strict=True))
    return [composite_step(c[0].size, rows, fits.get(i), args[0], c[2])
            for i, (c, (rows, args)) in enumerate(zip(calls, inputs, strict=True))]


def _cv_predict_many(calls: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``cv_predict(mean (T, 4), cov, dt, q)`` of several track sets: the rows stacked, each
    with its set's dt (other shapes answered alone)."""
    def stackable(c: tuple) -> bool:
        return np.ndim(c[0]) == 2 and np.ndim(c[2]) == 0

    def stack(group: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
        if not stackable(group[0]):
            return [cv_predict(*c) for c in group]
        n = [c[0].shape[0] for c in group]
        x, P = cv_predict(np.concatenate([c[0] for c in group]),
                          np.concatenate([c[1] for c in group]),
                          np.repeat([float(c[2]) for c in group], n), group[0][3])
        return list(zip(_split(x, n), _split(P, n), strict=True))
    return _grouped(calls, lambda c: (stackable(c), c[3]), stack)


def _predict_tracks_many(calls: list[tuple]) -> list[Any]:
    """``predict_tracks`` of several agents' tracks (a stacked ``cv_predict``)."""
    out: list[Any] = [c[0] for c in calls]
    move = [i for i, (tr, dt, _) in enumerate(calls) if tr.size and dt != 0]
    pred = _cv_predict_many([(calls[i][0].mean, calls[i][0].cov, calls[i][1], calls[i][2])
                             for i in move])
    for i, (x, P) in zip(move, pred, strict=True):
        out[i] = calls[i][0]._replace(mean=x, cov=P)
    return out


def _steer_many(calls: list[tuple]) -> list[CourseCommand]:
    """``steer`` of several agents (each a batch of one) as one batch: grouped by the
    number of targets and neighbours, so that every sum over them has the one call's
    length and order."""
    def key(c: tuple) -> tuple:
        return c[4].shape, c[6].shape, c[11]

    def stack(group: list[tuple]) -> list[CourseCommand]:
        args = [np.concatenate([c[k] for c in group]) for k in range(11)]
        cmd = steer_call(*args, group[0][11])
        return [CourseCommand(*(a[i:i + 1] for a in cmd)) for i in range(len(group))]
    return _grouped(calls, key, stack)


def _match_tracks_many(calls: list[tuple]) -> list[Matches]:
    """``match_tracks`` of several pairs of track sets: every pair's similarity in one
    stacked solve (LAPACK's per-matrix Cholesky, as each small call uses), then each
    assignment."""
    d, C, shapes = [], [], []
    for xa, Pa, xb, Pb, _ in calls:
        d.append((xa[:, None, :] - xb[None, :, :]).reshape(-1, 4))
        C.append((Pa[:, None] + Pb[None, :]).reshape(-1, 4, 4))
        shapes.append((xa.shape[0], xb.shape[0]))
    dd, CC = np.concatenate(d), np.concatenate(C)
    L = np.linalg.cholesky(CC)
    y = np.linalg.solve(L.mT, np.linalg.solve(L, dd[..., None]))[..., 0]
    S_all = np.einsum("...i,...i->...", dd, y)
    out = []
    for S, shape, c in zip(_split(S_all, [a * b for a, b in shapes]), shapes, calls,
                           strict=True):
        out.append(matches_within(S.reshape(shape), c[4]))
    return out


def _duplicates_many(calls: list[tuple]) -> list[np.ndarray]:
    """``duplicates`` of several agents' tracks: every agent's pair similarities in one
    stacked solve (LAPACK's per-matrix Cholesky, as a call of fewer than
    ``CHOL_MIN_BATCH_FULL`` pairs uses); a call with more pairs, none, leading axes, or a
    non-finite track (``duplicates`` names it) is answered alone."""
    alone = [len(c) != 3 or np.ndim(c[0]) != 2 or not 0 < len(c[0]) ** 2 < CHOL_MIN_BATCH_FULL
             or not (np.isfinite(c[0]).all() and np.isfinite(c[1]).all()) for c in calls]
    out: list[Any] = [duplicates(*c) if a else None for c, a in zip(calls, alone, strict=True)]
    mine = [i for i, a in enumerate(alone) if not a]
    if not mine:
        return out
    d = np.concatenate([(calls[i][0][:, None] - calls[i][0][None]).reshape(-1, 4)
                        for i in mine])
    C = np.concatenate([(calls[i][1][:, None] + calls[i][1][None]).reshape(-1, 4, 4)
                        for i in mine])
    L = np.linalg.cholesky(C)
    y = np.linalg.solve(L.mT, np.linalg.solve(L, d[..., None]))[..., 0]
    S_all = np.einsum("...i,...i->...", d, y)
    sizes = [len(calls[i][0]) for i in mine]
    for i, T, S in zip(mine, sizes, _split(S_all, [T * T for T in sizes]), strict=True):
        _, P, gate = calls[i]
        out[i] = dominated(S.reshape(T, T), uncertainty(P), gate)
    return out


BATCHED[composites] = _composites_many
BATCHED[composite_measurement] = _composite_measurement_many
BATCHED[cv_predict] = _cv_predict_many
BATCHED[predict_tracks] = _predict_tracks_many
BATCHED[steer_call] = _steer_many
BATCHED[match_tracks] = _match_tracks_many
BATCHED[duplicates] = _duplicates_many


def _combine_many(calls: list[tuple]) -> list[Any]:
    """``combine`` of several agents' tracks with their matches, stacked over the tracks of
    calls with the same number of slots and rule."""
    def stack(group: list[tuple]) -> list[Any]:
        n = [c[0].shape[0] for c in group]
        out = combine_call(*(np.concatenate([c[k] for c in group]) for k in range(3)),
                       group[0][3])
        return [type(out)(*parts) for parts in zip(_split(out.mean, n), _split(out.cov, n),
                                                    strict=True)]
    return _grouped(calls, lambda c: (c[0].shape[1:], c[3]), stack)


def _update_tracks_many(calls: list[tuple]) -> list[Any]:
    """``update_tracks`` of several agents' tracks: the updates of the tracks that have a
    composite, stacked."""
    out: list[Any] = [c[0] for c in calls]
    live = [i for i, (_, step) in enumerate(calls) if step.made.any()]
    if not live:
        return out
    n = [calls[i][0].size for i in live]
    tr = calls[live[0]][0]._replace(
        mean=np.concatenate([calls[i][0].mean for i in live]),
        cov=np.concatenate([calls[i][0].cov for i in live]))
    step = type(calls[live[0]][1])(*(np.concatenate([getattr(calls[i][1], f) for i in live])
                                     for f in calls[live[0]][1]._fields))
    new = update_tracks(tr, step)
    for i, x, P in zip(live, _split(new.mean, n), _split(new.cov, n), strict=True):
        out[i] = calls[i][0]._replace(mean=x, cov=P)
    return out


def _move_many(calls: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``move(position, course, speed, commanded, dt, turn_rate, check)`` of several
    programs (an agent moved to its execution, or all agents to a delivery), those of one
    shape stacked on a new leading axis: one move (elementwise: each agent's numbers are its
    own)."""
    def stack(group: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
        pos, course = move(*(np.stack([np.asarray(c[k], float) for c in group])
                             for k in range(5)), group[0][5], group[0][6])
        return list(zip(pos, course, strict=True))
    return _grouped(calls, lambda c: tuple(map(np.shape, c[:5])) + c[5:], stack)


def _bearings_many(calls: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``bearings_at(sensor_pos, targets, noise, sigma, mr)`` of several executions (one
    agent each) as one batch of executions."""
    def stack(group: list[tuple]) -> list[tuple[np.ndarray, np.ndarray]]:
        if len(group[0]) != 5 or group[0][2] is None:  # a convention, or noise-free
            return [bearings_at(*c) for c in group]
        z, seen = bearings_at(*(np.stack([np.asarray(c[k], float) for c in group])
                                for k in range(5)))
        return list(zip(z, seen, strict=True))
    return _grouped(calls, lambda c: (np.shape(c[0]), np.shape(c[1]), np.shape(c[2]),
                                      np.shape(c[3]), np.shape(c[4]), len(c)), stack)


BATCHED[move] = _move_many
BATCHED[bearings_at] = _bearings_many
BATCHED[combine_call] = _combine_many
BATCHED[update_tracks] = _update_tracks_many
