"""Scoring of one tracker's confirmed tracks against the true targets, execution by
execution (the agents of Jalalipoor and Kardehi Moghaddam (2021) and the centralised reference;
``network.inprocess.Trace``).

At execution e with truth positions X_e = {x_1..x_Nt} and confirmed track positions
Y_e = {y_1..y_m} (``eval.track_metrics``, d the Euclidean position distance, cut-off c,
order p):

* ``count[e] = m``;
* ``gospa[e]`` = GOSPA(X_e, Y_e; c, p, alpha = 2)
  = (L + c^p/2 (Nt - k) + c^p/2 (m - k))^(1/p), L the summed d^p of the k assigned pairs;
* ``error[e, j] = |y_g(j) - x_j|`` for target j assigned to track g(j) by that optimal
  assignment (only pairs with d < c are assigned), nan where target j has no track.

``position_rmse`` then gives, per target, ``sqrt(mean over e in the window of error^2)``
over the executions where the target is held.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.eval.track_metrics import Frames, assign, gospa_steps

__all__ = ["TraceScore", "score_trace", "position_rmse"]

Array = NDArray[np.float64]


class TraceScore(NamedTuple):
    """``time (E,)``; ``count (E,)`` confirmed tracks; ``gospa (E,)`` (m);
    ``error (E, Nt)`` position error of each target's assigned track (m, nan: none)."""

    time: Array
    count: NDArray[np.int64]
    gospa: Array
    error: Array


def score_trace(time: ArrayLike, offsets: ArrayLike, mean: ArrayLike, truth: ArrayLike,
                c: float = 2000.0, p: float = 2.0) -> TraceScore:
    """Score a tracker's executions (module docstring).

    ``time (E,)``; ``offsets (E + 1,)`` and ``mean (N, 4)``: execution e's confirmed tracks
    are ``mean[offsets[e]:offsets[e + 1]]``; ``truth (E, Nt, 4)`` the targets at each
    execution; ``c`` the GOSPA cut-off (m), ``p`` its order.
    """
    t = np.asarray(time, dtype=float)
    off = np.asarray(offsets, dtype=np.int64)
    x = np.asarray(mean, dtype=float)
    X = np.asarray(truth, dtype=float)
    E = t.shape[0]
    if off.shape != (E + 1,) or off[0] != 0 or np.any(np.diff(off) < 0):
        raise ValueError(f"offsets has shape {off.shape}; expected ({E + 1},) non-decreasing "
                         "from 0 (one slice of tracks per execution)")
    if x.ndim != 2 or x.shape[1] < 2 or x.shape[0] != off[-1]:
        raise ValueError(f"mean has shape {x.shape}; expected ({int(off[-1])}, 4)")
    if X.ndim != 3 or X.shape[0] != E or X.shape[2] < 2:
        raise ValueError(f"truth has shape {X.shape}; expected ({E}, Nt, 4)")
    Nt = X.shape[1]
    tru = Frames(np.arange(E + 1, dtype=np.int64) * Nt, X[:, :, :2].reshape(E * Nt, 2))
    est = Frames(off, np.ascontiguousarray(x[:, :2]))
    g = gospa_steps(tru, est, c, p)
    I, J = assign(tru, est, c, p)
    err = np.full(E * Nt, np.nan)
    err[I] = np.hypot(*(est.x[J] - tru.x[I]).T)
    return TraceScore(t, np.diff(off), np.asarray(g.distance, dtype=float), err.reshape(E, Nt))


def position_rmse(score: TraceScore, t_from: float = -np.inf, t_to: float = np.inf) -> Array:
    """Per target ``(Nt,)``: ``sqrt(mean error^2)`` over the executions in
    ``[t_from, t_to]`` where the target has a track (nan if it never has one there)."""
    w = (score.time >= t_from) & (score.time <= t_to)
    e = score.error[w]
    held = ~np.isnan(e)
    n = held.sum(0)
    with np.errstate(invalid="ignore"):
        return np.where(n > 0, np.sqrt(np.nansum(e**2, 0) / np.maximum(n, 1)), np.nan)
