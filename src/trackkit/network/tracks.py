"""Tracks across agents (Jalalipoor and Kardehi Moghaddam 2021, eqs. 39 and 51): similarity,
track-to-track matching, duplicate pruning, and the memory of neighbours' messages.

Similarity of track i (``x_i``, ``P_i``) and track j (eq. 39)::

    S_ij = (x_i - x_j)^T (P_i + P_j)^-1 (x_i - x_j)

For two independent, consistent estimates of one target, ``x_i - x_j ~ N(0, P_i + P_j)`` and
``S_ij`` is chi-square with n degrees of freedom, so a gate ``chi2.ppf(p, n)`` keeps the same
target's pair with probability p (estimates that share information are closer still). The
seed gives no threshold; :data:`DEFAULT_GATE` is the 99% point for n = 4.

Uncertainty of a track (eq. 51), the position variances' sum times the velocity variances'::

    U = (P_11 + P_22)(P_33 + P_44)

Duplicate pruning (2.7): of two similar tracks, the one with the larger uncertainty is
deleted. Applied to every pair at once: track j goes when some track i with ``S_ij <= gate``
is less uncertain (ties: the lower index stays). In a chain a ~ b ~ c with
``U_a < U_b < U_c`` and a, c apart, both b and c go: each has a more certain twin.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from trackkit.linalg import solve_psd

__all__ = ["DEFAULT_GATE", "similarity", "uncertainty", "Matches", "match_tracks",
           "matches_within", "duplicates", "dominated", "Message", "MessageMemory"]

Array = NDArray[np.float64]

#: chi2.ppf(0.99, 4): a 4-state track's twin passes with probability 0.99
DEFAULT_GATE = 13.276704135987622


def _tracks(x: ArrayLike, P: ArrayLike, name: str) -> tuple[Array, Array]:
    x = np.asarray(x, dtype=float)
    P = np.asarray(P, dtype=float)
    if x.ndim < 2 or P.shape != x.shape + x.shape[-1:]:
        raise ValueError(f"{name}: means {x.shape} and covariances {P.shape}; expected "
                         "(..., T, n) and (..., T, n, n)")
    if not (np.isfinite(x).all() and np.isfinite(P).all()):
        raise ValueError(f"{name}: non-finite means or covariances; expected finite tracks")
    return x, P


def similarity(xa: ArrayLike, Pa: ArrayLike, xb: ArrayLike, Pb: ArrayLike) -> Array:
    """``S_ij = (x_i - x_j)^T (P_i + P_j)^-1 (x_i - x_j)`` for every track i of set a
    ``(..., A, n)`` and j of set b ``(..., B, n)``: ``(..., A, B)``."""
    xa, Pa = _tracks(xa, Pa, "similarity: set a")
    xb, Pb = _tracks(xb, Pb, "similarity: set b")
    if xa.shape[-1] != xb.shape[-1]:
        raise ValueError(f"similarity: tracks of {xa.shape[-1]} and {xb.shape[-1]} states; "
                         "expected the same state")
    d = xa[..., :, None, :] - xb[..., None, :, :]
    C = Pa[..., :, None, :, :] + Pb[..., None, :, :, :]
    if d.size == 0:
        return np.zeros(d.shape[:-1])
    y = solve_psd(C, d[..., None], "similarity: P_i + P_j")[..., 0]
    return np.einsum("...i,...i->...", d, y)


def uncertainty(P: ArrayLike) -> Array:
    """``U = (P_11 + P_22)(P_33 + P_44)`` of 2-D constant-velocity tracks ``(..., 4, 4)``."""
    P = np.asarray(P, dtype=float)
    if P.shape[-2:] != (4, 4):
        raise ValueError(f"uncertainty: covariances have shape {P.shape}; expected "
                         "(..., 4, 4) ([x, y, vx, vy])")
    return (P[..., 0, 0] + P[..., 1, 1]) * (P[..., 2, 2] + P[..., 3, 3])


class Matches(NamedTuple):
    """Pairs of matched tracks: ``a[k]`` of set a with ``b[k]`` of set b, and their
    similarity ``s[k]``."""

    a: NDArray[np.intp]
    b: NDArray[np.intp]
    s: Array


def match_tracks(xa: ArrayLike, Pa: ArrayLike, xb: ArrayLike, Pb: ArrayLike,
                 gate: float = DEFAULT_GATE) -> Matches:
    """One-to-one matching of an agent's tracks (set a, ``(A, n)``) with a neighbour's (set
    b, ``(B, n)``): the assignment minimising the summed ``S_ij`` (Munkres) over the pairs
    inside the gate, ``S_ij <= gate``; a track with no partner inside it stays unmatched."""
    if not (isinstance(gate, int | float) and math.isfinite(gate) and gate > 0):
        raise ValueError(f"match_tracks: gate = {gate!r}; expected a number > 0 (a chi-square "
                         "quantile, e.g. 13.28 for 99% with 4 states)")
    S = similarity(xa, Pa, xb, Pb)
    if S.ndim != 2:
        raise ValueError(f"match_tracks: tracks {np.shape(xa)} and {np.shape(xb)}; expected "
                         "one agent's (A, n) and one neighbour's (B, n)")
    return matches_within(S, gate)


def matches_within(S: Array, gate: float) -> Matches:
    """:func:`match_tracks`'s assignment given the similarities ``S (A, B)``."""
    inside = S <= gate
    empty = Matches(np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0))
    if not inside.any():
        return empty
    # a pair outside the gate costs more than any set of pairs inside it, so the optimum
    # takes the most pairs inside first; the outside ones are dropped afterwards
    big = 1.0 + gate * min(S.shape)
    if inside.sum(0).max() == 1 and inside.sum(1).max() == 1:
        # the usual case, no two pairs inside share a track: the optimum holds them all
        # (leaving one out costs big, more than all of them together), in rows' order
        rows, cols = np.nonzero(inside)
        return Matches(rows, cols, S[rows, cols])
    rows, cols = linear_sum_assignment(np.where(inside, S, big))
    keep = inside[rows, cols]
    return Matches(rows[keep].astype(np.intp), cols[keep].astype(np.intp), S[rows[keep],
                                                                              cols[keep]])


def duplicates(x: ArrayLike, P: ArrayLike, gate: float = DEFAULT_GATE) -> NDArray[np.bool_]:
    """The tracks ``(..., T, 4)`` to delete as duplicates: track j when some track i with
    ``S_ij <= gate`` has a smaller uncertainty ``U`` (or the same and a lower index)."""
    if not (isinstance(gate, int | float) and math.isfinite(gate) and gate > 0):
        raise ValueError(f"duplicates: gate = {gate!r}; expected a number > 0")
    x, P = _tracks(x, P, "duplicates")
    return dominated(similarity(x, P, x, P), uncertainty(P), gate)


def dominated(S: Array, U: Array, gate: float) -> NDArray[np.bool_]:
    """The pruning rule of ``duplicates`` on given similarities ``S`` ``(..., T, T)`` and
    uncertainties ``U`` ``(..., T)``: track j when some i has ``S_ij <= gate`` and
    ``U_i < U_j``, or ``U_i = U_j`` and i < j."""
    idx = np.arange(U.shape[-1])
    better = (U[..., :, None] < U[..., None, :]) | (
        (U[..., :, None] == U[..., None, :]) & (idx[:, None] < idx[None, :]))
    return ((S <= gate) & better).any(axis=-2)


# --------------------------------------------------------------------------------------------
# The memory of neighbours' messages (2.10; Fig. 2 step 1)


@dataclass(frozen=True)
class Message:
    """What an agent broadcasts: its index, the (simulated) time it was sent, and a
    payload (its measurements and tracks)."""

    sender: Hashable
    time: float
    payload: Any


@dataclass
class MessageMemory:
    """Messages received from neighbours, kept for ``keep_s`` seconds of simulated time
    and then forgotten (the paper: data are held for a fixed period, and the neighbours are
    the agents whose data are in memory). The newest message of each sender is kept; an
    older one arriving late is counted in ``stale`` and not stored."""

    keep_s: float
    _last: dict[Hashable, Message] = field(default_factory=dict)
    stale: int = 0
    expired: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.keep_s, int | float) and math.isfinite(self.keep_s)
                and self.keep_s > 0):
            raise ValueError(f"MessageMemory keep_s = {self.keep_s!r}; expected seconds > 0")

    def receive(self, message: Message) -> None:
        """Store ``message`` unless the memory holds a newer one from its sender."""
        if not math.isfinite(message.time):
            raise ValueError(f"MessageMemory.receive: message time {message.time!r} from "
                             f"{message.sender!r}; expected a finite time in seconds")
        old = self._last.get(message.sender)
        if old is not None and old.time > message.time:
            self.stale += 1
            return
        self._last[message.sender] = message

    def expire(self, now: float) -> None:
        """Forget every message older than ``keep_s`` at time ``now``."""
        gone = [s for s, m in self._last.items() if now - m.time > self.keep_s]
        for s in gone:
            del self._last[s]
        self.expired += len(gone)

    def neighbours(self, now: float) -> list[Hashable]:
        """The senders heard from within ``keep_s`` of ``now`` (after expiring the rest)."""
        self.expire(now)
        return sorted(self._last, key=repr)

    def __iter__(self) -> Iterator[Message]:
        return iter(sorted(self._last.values(), key=lambda m: repr(m.sender)))

    def __len__(self) -> int:
        return len(self._last)
