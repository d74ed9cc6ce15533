"""Track life cycle: M-of-N history logic, SPRT score logic, the timer logic of Jalalipoor and
Kardehi Moghaddam (2021) and stable track IDs.

Every live track is a row of one batched state (axis 0 = track, any leading axes allowed).
The logics are small frozen dataclasses holding parameters; their methods are pure kernels
over the whole batch, called once per scan:

    logic = HistoryLogic(confirm=(2, 3), delete=(6, 6))     # MATLAB trackHistoryLogic defaults
    s = logic.init(k)                  # k new tracks, born from a detection (first update: hit)
    s = logic.step(s, hit)             # hit: bool (T,), one update per scan
    confirmed(s), to_delete(s)         # bool (T,)

    logic = ScoreLogic.from_sprt(alpha=1e-6, beta=1e-3, pd=0.9, clutter_density=1e-8,
                                 new_target_density=1e-9)
    s = logic.step(logic.init(k), hit, log_lik)   # log_lik: ln N(nu; 0, S), a Gate's loglik

The statuses are ``TrackStatus`` codes; ``confirmed`` is sticky (a confirmed track stays
confirmed until deleted) and ``DELETED`` is absorbing. ``select`` and ``concatenate`` keep
rows of any of these states; ``IdCounter`` issues track IDs that are never reused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "TrackStatus",
    "HistoryState",
    "HistoryLogic",
    "ScoreState",
    "ScoreLogic",
    "sprt_thresholds",
    "confirmed",
    "tentative",
    "to_delete",
    "select",
    "concatenate",
    "IdCounter",
    "TimerState",
    "TimerLogic",
    "lost",
    "held",
]

Array = NDArray[np.float64]
Bool = NDArray[np.bool_]

MAX_WINDOW = 64  # one uint64 holds the history

# _MASK[k] keeps the k most recent updates (bits 0 .. k-1); a table because a shift by 64 is
# undefined in C and numpy's uint64 shift inherits that.
_MASK = np.array([(1 << k) - 1 for k in range(MAX_WINDOW + 1)], dtype=np.uint64)


class TrackStatus(IntEnum):
    """Status codes of a track (stored as int8 in the logic states)."""

    TENTATIVE = 0
    CONFIRMED = 1
    DELETED = 2
    LOST = 3  #: confirmed, then missed too long to be shown; held for re-acquisition


_TENT = np.int8(TrackStatus.TENTATIVE)
_CONF = np.int8(TrackStatus.CONFIRMED)
_DEL = np.int8(TrackStatus.DELETED)
_LOST = np.int8(TrackStatus.LOST)


# ------------------------------------------------------------------------------------------
# Queries shared by both logics (any state with a ``status`` field)


def confirmed(state: HistoryState | ScoreState) -> Bool:
    """Tracks whose status is CONFIRMED."""
    return np.asarray(state.status) == _CONF


def tentative(state: HistoryState | ScoreState) -> Bool:
    """Tracks whose status is TENTATIVE."""
    return np.asarray(state.status) == _TENT


def held(state: HistoryState | ScoreState) -> Bool:
    """Tracks whose status is LOST: kept, unseen, for a plot to take them up again."""
    return np.asarray(state.status) == _LOST


def to_delete(state: HistoryState | ScoreState) -> Bool:
    """Tracks whose status is DELETED (the tracker drops these rows)."""
    return np.asarray(state.status) == _DEL


S = TypeVar("S", bound=tuple)


def select(state: S, index: ArrayLike) -> S:
    """Rows ``index`` (mask or integer indices on the leading axis) of a logic state."""
    return type(state)(*(np.asarray(f)[index] for f in state))


def concatenate(*states: S) -> S:
    """Logic states of the same type stacked along the track axis (axis 0)."""
    if not states:
        raise ValueError("concatenate() got no states; expected at least one")
    kind = type(states[0])
    if any(type(s) is not kind for s in states):
        raise ValueError(
            f"concatenate() got states of types {[type(s).__name__ for s in states]}; "
            "expected one type"
        )
    return kind(*(np.concatenate(fs, axis=0) for fs in zip(*states, strict=True)))


# ------------------------------------------------------------------------------------------
# M-of-N history logic


class HistoryState(NamedTuple):
    """Batched history of the M-of-N logic.

    ``history`` (uint64): bit k is the update k scans ago (1 = hit), bit 0 the latest;
    ``age`` (int64): updates since birth, the birth detection included (1 after ``init``);
    ``status`` (int8): ``TrackStatus`` code.
    """

    history: NDArray[np.uint64]
    age: NDArray[np.int64]
    status: NDArray[np.int8]


def _threshold(value: int | Sequence[int], name: str) -> tuple[int, int]:
    """[M N] from a scalar M (meaning [M M], as MATLAB) or a pair, with 1 <= M <= N <= 64."""
    v = np.atleast_1d(np.asarray(value))
    ok = (
        v.ndim == 1
        and v.size in (1, 2)
        and np.issubdtype(v.dtype, np.integer)
        and 1 <= v[0] <= v[-1] <= MAX_WINDOW
    )
    if not ok:
        raise ValueError(
            f"{name} = {np.asarray(value).tolist()!r}; expected an integer M or a pair [M, N] "
            f"of integers with 1 <= M <= N <= {MAX_WINDOW}"
        )
    return int(v[0]), int(v[-1])


def _popcount(x: NDArray[np.uint64]) -> NDArray[np.int64]:
    return np.bitwise_count(x).astype(np.int64)


@dataclass(frozen=True)
class HistoryLogic:
    """M-of-N (history) confirmation and deletion, with the semantics of MATLAB's
    ``trackHistoryLogic`` as its tracker uses it (Blackman & Popoli 1999, ch. 6).

    - ``confirm = (M, N)``: a track is confirmed when at least M of its last N updates are
      hits.
    - ``delete = (P, R)``: a confirmed track is deleted when at least P of its last R updates
      are misses.
    - A tentative track is deleted as soon as it can no longer be confirmed within its first
      N updates: when the misses among its last ``min(age, N)`` updates exceed ``N - M``
      (MATLAB ``checkDeletion(logic, true, age)``). A tentative track thus lives at most N
      updates.
    - The first update is the detection that started the track: ``init`` records a hit
      (history ``[1 0 0 ...]``, age 1), and a track with M = 1 is confirmed at birth.

    Confirmation is tested before deletion in each update; confirmed is sticky.

    ``pad_as_miss``: MATLAB's history is a zero-filled vector, so its plain
    ``checkDeletion`` counts the slots before the track's birth as misses (its documented
    example flags ``[1 0 0 0 0]`` for deletion with ``DeletionThreshold = [4 5]``). With
    the default ``False`` only updates the track has had count, so a freshly confirmed track
    is never deleted for scans before it existed; ``True`` reproduces MATLAB exactly.
    """

    confirm: int | tuple[int, int] = (2, 3)
    delete: int | tuple[int, int] = (6, 6)
    pad_as_miss: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "confirm", _threshold(self.confirm, "confirm"))
        object.__setattr__(self, "delete", _threshold(self.delete, "delete"))
        if not isinstance(self.pad_as_miss, bool | np.bool_):
            raise ValueError(f"pad_as_miss = {self.pad_as_miss!r}; expected True or False")

    @property
    def window(self) -> int:
        """Length of the kept history, ``max(N, R)`` (MATLAB's History vector)."""
        return max(self.confirm[1], self.delete[1])

    def init(self, n: int | tuple[int, ...]) -> HistoryState:
        """``n`` new tracks (an int or a batch shape), each born from one detection (a hit)."""
        shape = (n,) if isinstance(n, int | np.integer) else tuple(n)
        if any(int(k) < 0 for k in shape):
            raise ValueError(f"n = {n!r}; expected a non-negative count or batch shape")
        history = np.ones(shape, dtype=np.uint64)
        age = np.ones(shape, dtype=np.int64)
        status = np.full(shape, _TENT, dtype=np.int8)
        return HistoryState(history, age, self._decide(history, age, status))

    def step(self, state: HistoryState, hit: ArrayLike) -> HistoryState:
        """One update of every track: ``hit`` (bool, the track's batch shape) is True where a
        detection was assigned. ``h <- (h << 1 | hit) & mask_window``, ``age <- age + 1``,
        then the confirmation and deletion tests."""
        hit = _hits(hit, state.age.shape)
        history = ((state.history << np.uint64(1)) | hit.astype(np.uint64)) & _MASK[self.window]
        age = state.age + 1
        return HistoryState(history, age, self._decide(history, age, state.status))

    # -- the tests, as pure kernels -------------------------------------------------------

    def hits_in_confirm_window(self, state: HistoryState) -> NDArray[np.int64]:
        """Hits among the last N updates."""
        return _popcount(state.history & _MASK[self.confirm[1]])

    def misses_in_delete_window(self, state: HistoryState) -> NDArray[np.int64]:
        """Misses among the last R updates (only the track's own updates unless
        ``pad_as_miss``)."""
        return self._misses(state.history, state.age, self.delete[1], self.pad_as_miss)

    @staticmethod
    def _misses(history: NDArray[np.uint64], age: NDArray[np.int64], n: int,
                pad: bool) -> NDArray[np.int64]:
        k = np.full(age.shape, n, dtype=np.int64) if pad else np.minimum(age, n)
        return k - _popcount(history & _MASK[k])

    def _decide(self, history: NDArray[np.uint64], age: NDArray[np.int64],
                status: NDArray[np.int8]) -> NDArray[np.int8]:
        M, N = self.confirm
        P, R = self.delete
        hits_c = _popcount(history & _MASK[N])
        conf = (status == _CONF) | (hits_c >= M)
        del_conf = self._misses(history, age, R, self.pad_as_miss) >= P
        # A tentative track that has already missed more than N - M of its first N updates
        # cannot reach M hits before its N-th update.
        del_tent = self._misses(history, age, N, False) > N - M
        out = np.where(conf, np.where(del_conf, _DEL, _CONF), np.where(del_tent, _DEL, _TENT))
        return np.where(status == _DEL, _DEL, out).astype(np.int8)


def _hits(hit: ArrayLike, shape: tuple[int, ...]) -> Bool:
    h = np.asarray(hit)
    if h.dtype != np.bool_:
        raise ValueError(f"hit has dtype {h.dtype}; expected bool (True where a track was hit)")
    if h.shape != shape:
        raise ValueError(f"hit has shape {h.shape}; expected the tracks' shape {shape}")
    return h


# ------------------------------------------------------------------------------------------
# SPRT (log-likelihood-ratio) score logic


def sprt_thresholds(alpha: float, beta: float) -> tuple[float, float]:
    """Wald's SPRT thresholds for the track score (Wald 1947; Blackman & Popoli 1999, ch. 6):

        T_confirm = ln((1 - beta) / alpha),    T_delete = ln(beta / (1 - alpha)),

    with ``alpha`` the probability of confirming a false track and ``beta`` the probability
    of deleting a true one."""
    for name, p in (("alpha", alpha), ("beta", beta)):
        if not (np.isfinite(p) and 0.0 < p < 1.0):
            raise ValueError(f"{name} = {p!r}; expected a probability in (0, 1)")
    if alpha + beta >= 1.0:
        raise ValueError(
            f"alpha + beta = {alpha + beta!r}; expected alpha + beta < 1 (else T_confirm <= "
            "T_delete and the test decides nothing)"
        )
    return float(np.log((1.0 - beta) / alpha)), float(np.log(beta / (1.0 - alpha)))


class ScoreState(NamedTuple):
    """Batched track score: ``score`` (the LLR), its running maximum ``max_score``, ``age``
    (updates since birth, 1 after ``init``) and ``status`` (``TrackStatus`` code)."""

    score: Array
    max_score: Array
    age: NDArray[np.int64]
    status: NDArray[np.int8]


def _probability(p: float, name: str, closed: bool = False) -> float:
    ok = np.isfinite(p) and (0.0 < p <= 1.0 if closed else 0.0 < p < 1.0)
    if not ok:
        want = "(0, 1]" if closed else "(0, 1)"
        raise ValueError(f"{name} = {p!r}; expected a probability in {want}")
    return float(p)


@dataclass(frozen=True)
class ScoreLogic:
    """Track-score (sequential probability ratio) logic of Blackman & Popoli (1999, ch. 6)
    with the deletion rule of MATLAB's ``trackScoreLogic``.

    The score is the log likelihood ratio of "true target" against "false alarms":

        birth:  L_1 = ln(P_D beta_NT / lambda_FA)
        hit:    L_k = L_{k-1} + ln P_D + ln N(nu; 0, S) - ln lambda_FA
        miss:   L_k = L_{k-1} + ln(1 - P_D P_G)

    with ``beta_NT`` (``new_target_density``) and ``lambda_FA`` (``clutter_density``) the
    densities of new targets and false alarms per unit measurement volume per scan (MATLAB's
    ``beta`` and ``pfa / volume``), ``P_G`` the gate probability. A track is confirmed when
    ``L >= confirm_threshold`` and deleted when ``L - max_j L_j < delete_threshold`` (a
    negative number: the drop from the running maximum). ``from_sprt`` sets both thresholds
    from Wald's SPRT error probabilities. Defaults follow MATLAB: 20 and -5.

    ``hold_threshold`` (None: off, a number below ``delete_threshold``) holds a confirmed
    track rather than deleting it: while ``hold_threshold <= L - max_j L_j <
    delete_threshold`` it is LOST (kept and updated, not shown), CONFIRMED again once hits
    bring its score back within ``delete_threshold`` of the maximum, deleted below
    ``hold_threshold``. An object unseen for a while (a reporting gap, a long fade) keeps its
    track and ID instead of getting a new one, and a stray plot in a lost track's wide gate
    cannot show it again: it takes the score's gain of several good hits. A tentative track
    is deleted at ``delete_threshold`` as without a hold.
    """

    pd: float
    clutter_density: float
    new_target_density: float
    pg: float = 1.0
    confirm_threshold: float = 20.0
    delete_threshold: float = -5.0
    hold_threshold: float | None = None

    def __post_init__(self) -> None:
        _probability(self.pd, "pd")
        _probability(self.pg, "pg", closed=True)
        for name in ("clutter_density", "new_target_density"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r}; expected a positive density (per unit volume)")
        if not np.isfinite(self.confirm_threshold):
            raise ValueError(f"confirm_threshold = {self.confirm_threshold!r}; expected finite")
        if not (np.isfinite(self.delete_threshold) and self.delete_threshold < 0):
            raise ValueError(
                f"delete_threshold = {self.delete_threshold!r}; expected a negative number "
                "(the allowed drop of the score below its maximum)"
            )
        h = self.hold_threshold
        if h is not None and not (np.isfinite(h) and h < self.delete_threshold):
            raise ValueError(f"hold_threshold = {h!r}; expected None or a number below "
                             f"delete_threshold ({self.delete_threshold!r})")

    @classmethod
    def from_sprt(cls, alpha: float, beta: float, **params) -> ScoreLogic:
        """Thresholds from ``sprt_thresholds(alpha, beta)``; other fields from ``params``."""
        t_confirm, t_delete = sprt_thresholds(alpha, beta)
        return cls(confirm_threshold=t_confirm, delete_threshold=t_delete, **params)

    @property
    def initial_score(self) -> float:
        """``L_1 = ln(P_D beta_NT / lambda_FA)``."""
        return float(np.log(self.pd * self.new_target_density / self.clutter_density))

    @property
    def miss_increment(self) -> float:
        """``ln(1 - P_D P_G)``."""
        return float(np.log1p(-self.pd * self.pg))

    def init(self, n: int | tuple[int, ...]) -> ScoreState:
        """``n`` new tracks (an int or a batch shape), each scored ``L_1``."""
        shape = (n,) if isinstance(n, int | np.integer) else tuple(n)
        if any(int(k) < 0 for k in shape):
            raise ValueError(f"n = {n!r}; expected a non-negative count or batch shape")
        score = np.full(shape, self.initial_score)
        age = np.ones(shape, dtype=np.int64)
        return ScoreState(score, score.copy(), age,
                          self._decide(score, score, np.full(shape, _TENT, dtype=np.int8)))

    def step(self, state: ScoreState, hit: ArrayLike,
             log_likelihood: ArrayLike | None = None) -> ScoreState:
        """One update: ``hit`` (bool, the tracks' shape) and, for the hits, ``log_likelihood``
        ``ln N(nu; 0, S)`` of the assigned measurement (ignored, may be nan, at misses)."""
        hit = _hits(hit, state.age.shape)
        if log_likelihood is None:
            if np.any(hit):
                raise ValueError("log_likelihood is None; expected ln N(nu; 0, S) for the hits")
            ll = np.zeros(hit.shape)
        else:
            ll = np.broadcast_to(np.asarray(log_likelihood, dtype=float), hit.shape)
            if not np.all(np.isfinite(ll[hit])):
                raise ValueError("log_likelihood has non-finite entries at hits; expected finite")
        gain = np.log(self.pd) - np.log(self.clutter_density) + np.where(hit, ll, 0.0)
        score = state.score + np.where(hit, gain, self.miss_increment)
        max_score = np.maximum(state.max_score, score)
        return ScoreState(score, max_score, state.age + 1,
                          self._decide(score, max_score, state.status))

    def _decide(self, score: Array, max_score: Array,
                status: NDArray[np.int8]) -> NDArray[np.int8]:
        drop = score - max_score < self.delete_threshold
        if self.hold_threshold is None:
            conf = (status == _CONF) | (score >= self.confirm_threshold)
            out = np.where(drop, _DEL, np.where(conf, _CONF, _TENT))
        else:
            seen = (status != _TENT) | (score >= self.confirm_threshold)
            gone = score - max_score < self.hold_threshold
            out = np.where(gone | (drop & ~seen), _DEL,
                           np.where(drop, _LOST, np.where(seen, _CONF, _TENT)))
        return np.where(status == _DEL, _DEL, out).astype(np.int8)


# ------------------------------------------------------------------------------------------
# Timer logic (Jalalipoor and Kardehi Moghaddam 2021, track status logic)


class TimerState(NamedTuple):
    """Batched clocks of the timer logic: ``born`` and ``last_hit``, the times (s) the track
    started and last had a measurement assigned; ``status`` the ``TrackStatus`` code;
    ``lost`` True for a confirmed track without a measurement for ``lost_after`` seconds."""

    born: Array
    last_hit: Array
    status: NDArray[np.int8]
    lost: Bool


def lost(state: TimerState) -> Bool:
    """Confirmed tracks that are Lost (coasting on pseudo-measurements)."""
    return np.asarray(state.lost) & (np.asarray(state.status) == _CONF)


@dataclass(frozen=True)
class TimerLogic:
    """The track states of Jalalipoor and Kardehi Moghaddam (2021) on elapsed times (the paper gives
    no values):

    - Query (``TENTATIVE``) from birth; Track (``CONFIRMED``) once ``t - born >=
      confirm_after`` with a measurement within the last ``lost_after`` seconds;
    - Lost: a confirmed track whose ``t - last_hit >= lost_after`` (it stays confirmed; the
      agent feeds it its own predicted measurement);
    - deleted, whatever the state, once ``t - last_hit >= delete_after``.

    Times are absolute simulated seconds, so agents that run at random instants need no
    common scan. ``confirm_after >= 0``, ``0 < lost_after < delete_after``.
    """

    confirm_after: float = 60.0
    lost_after: float = 60.0
    delete_after: float = 300.0

    def __post_init__(self) -> None:
        for name in ("confirm_after", "lost_after", "delete_after"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"TimerLogic {name} = {v!r}; expected seconds >= 0")
        if not 0 < self.lost_after < self.delete_after:
            raise ValueError(f"TimerLogic lost_after = {self.lost_after!r}, delete_after = "
                             f"{self.delete_after!r}; expected 0 < lost_after < delete_after")

    def init(self, t: float | ArrayLike, n: int | tuple[int, ...]) -> TimerState:
        """``n`` new tracks (a count or a batch shape) started at time ``t`` by a
        measurement (their first hit)."""
        shape = (n,) if isinstance(n, int | np.integer) else tuple(n)
        if any(int(k) < 0 for k in shape):
            raise ValueError(f"n = {n!r}; expected a non-negative count or batch shape")
        born = np.broadcast_to(np.asarray(t, dtype=float), shape).copy()
        if not np.isfinite(born).all():
            raise ValueError(f"TimerLogic.init: t = {t!r}; expected finite times")
        return self._decide(born, born.copy(), np.full(shape, _TENT, dtype=np.int8), born)

    def step(self, state: TimerState, t: float | ArrayLike, hit: ArrayLike) -> TimerState:
        """The tracks' states at time ``t`` (not before their last update), ``hit`` True
        where a measurement was assigned at t."""
        h = _hits(hit, state.born.shape)
        now = np.broadcast_to(np.asarray(t, dtype=float), state.born.shape)
        if not (np.isfinite(now).all() and (now >= state.last_hit).all()):
            raise ValueError(f"TimerLogic.step: t = {t!r}; expected finite times not before "
                             "each track's last measurement")
        last = np.where(h, now, state.last_hit)
        return self._decide(state.born, last, state.status, now)

    def _decide(self, born: Array, last: Array, status: NDArray[np.int8],
                now: Array) -> TimerState:
        quiet = now - last
        conf = (status == _CONF) | ((now - born >= self.confirm_after)
                                    & (quiet < self.lost_after))
        out = np.where(quiet >= self.delete_after, _DEL, np.where(conf, _CONF, _TENT))
        out = np.where(status == _DEL, _DEL, out).astype(np.int8)
        return TimerState(born, last, out, (out == _CONF) & (quiet >= self.lost_after))


# ------------------------------------------------------------------------------------------
# Track IDs


@dataclass(frozen=True)
class IdCounter:
    """Issues track IDs ``next_id, next_id + 1, ...``; never reuses one within a tracker's
    life (IDs start at 1, as MATLAB's TrackID). Pure: ``issue`` returns the new counter.

        ids, counter = counter.issue(k)     # k new IDs at once, int64 (k,)
    """

    next_id: int = 1

    def __post_init__(self) -> None:
        if not isinstance(self.next_id, int | np.integer) or self.next_id < 0:
            raise ValueError(f"next_id = {self.next_id!r}; expected a non-negative integer")

    def issue(self, k: int) -> tuple[NDArray[np.int64], IdCounter]:
        if not isinstance(k, int | np.integer) or k < 0:
            raise ValueError(f"k = {k!r}; expected a non-negative integer")
        if self.next_id + k - 1 > np.iinfo(np.int64).max:
            raise ValueError(f"k = {k}; issuing it would overflow int64 track IDs")
        ids = np.arange(self.next_id, self.next_id + k, dtype=np.int64)
        return ids, IdCounter(int(self.next_id) + int(k))
