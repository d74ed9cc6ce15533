"""Smoothed tracks: a fixed-interval Rauch-Tung-Striebel smoother over every track's life.

Each track of a :class:`~trackkit.tracking.history.TrackHistory` is a run of rows, one per
scan from its start to its last scan alive (coasted scans included; held scans, and the
pieces of a track held and then continued by another, stand apart), with the filtered
``x_k = mean``, ``P_k = cov``. Backwards from its last row (where the smoothed estimate is the
filtered one), with the one-step prediction ``x-_{k+1}, P-_{k+1}`` of ``(x_k, P_k)`` over the
time between the two scans and the cross-covariance ``C_k = Cov(x_k, x_{k+1})`` (``P_k F^T``
for the KF and EKF; Rauch, Tung and Striebel 1965; Sarkka 2013, section 8.2):

    G_k  = C_k (P-_{k+1})^{-1}
    xs_k = x_k + G_k (xs_{k+1} - x-_{k+1})
    Ps_k = P_k + G_k (Ps_{k+1} - P-_{k+1}) G_k^T

(:func:`trackkit.filters.smoothers.rts_step`). The backward pass takes one batched step per
scan, over all the tracks that live on to the next scan together.

With a linear motion model and every update that of one plot (GNN) the backward pass is
exact given the filtered Gaussians (a range-bearing EKF's are themselves approximate);
after a JPDA update (a moment-matched mixture of hypotheses) or an IMM's (a moment-matched
mixture of models) it is the usual approximation that treats the filtered Gaussian as the
posterior. For an IMM tracker (:func:`smoothing_model`) the moment-matched estimates are
smoothed with one of the mixture's models, the one with the largest process noise in
position and velocity (the CV model of CV with a near-constant-position model, or of CV
with CT when the CT model's noise is no larger): a model with less noise than the mixture
allows for would pull the smoothed track straight through turns and starts (on the Solent
sample, CV + near-constant position smoothed with the latter is 68-85 m from the reported
positions, with CV 11-18 m); the largest trusts the filtered estimates most. This is not
the IMM smoother of Helmick, Blair and Hoffman (1995), which would need every model's
estimate at every scan. Smoothed that way the backward recursion need not contract: the
IMM's filtered covariance is wider than the smoothing model's prediction of it (the mixture
adds the spread of its models' means every scan), so the gains ``G_k`` have eigenvalues
just above 1, and over the thousand scans of a moored vessel the fixed-interval pass drifts
by hundreds of kilometres; ``smooth_tracks(..., lag=L)`` smooths each estimate with the next
L scans only (:func:`fixed_lag`), which ``trackkit track`` does.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from trackkit.belief import Gaussian
from trackkit.filters.smoothers import fixed_lag_sweeps, rts_gain, rts_step
from trackkit.tracking.history import TrackHistory
from trackkit.tracking.logic import TrackStatus

Array = NDArray[np.float64]

__all__ = ["SmoothedTracks", "fixed_lag", "smooth_tracks", "smoothing_model"]


class SmoothedTracks(NamedTuple):
    """Smoothed ``mean (N, m)`` and ``cov (N, m, m)``, row for row with the history, of the
    state components ``dims (m,)`` (indices into the history's state; all of them unless an
    IMM's smoothing model carries fewer)."""

    mean: Array
    cov: Array
    dims: NDArray[np.intp]


def next_rows(history: TrackHistory) -> NDArray[np.int64]:
    """Per row, the row of the same track at the next scan, or -1 at a track's last scan and
    wherever either row is held (LOST): held rows are predictions, never shown, over which
    a smoothing model other than the filter's would drift, and a held track is continued by
    another filter's track (``Tracker._rejoin``); the shown pieces are smoothed apart."""
    h = history
    scan = np.repeat(np.arange(h.times.size), np.diff(h.offsets))
    o = np.lexsort((scan, h.ids))
    follows = (h.ids[o][1:] == h.ids[o][:-1]) & (scan[o][1:] == scan[o][:-1] + 1)
    lost = np.asarray(h.status)[o] == TrackStatus.LOST
    follows &= ~(lost[:-1] | lost[1:])
    nxt = np.full(h.ids.size, -1, np.int64)
    nxt[o[:-1][follows]] = o[1:][follows]
    return nxt


def smooth_tracks(history: TrackHistory, motion: Any, filt: Any,
                  dims: NDArray[np.intp] | None = None,
                  lag: int | None = None) -> SmoothedTracks:
    """RTS-smooth every track of ``history`` (module docstring) with ``motion`` predicted by
    ``filt`` (a KF, EKF, UKF or CKF), over the state components ``dims`` (default all):
    over each track's whole life, or with a fixed ``lag`` (scans), each estimate from the
    plots up to ``lag`` scans after it (:func:`fixed_lag`)."""
    h = history
    if h.cov is None:
        raise ValueError("smooth_tracks: the history has no covariances (cov is None); "
                         "make it with run_tracker")
    n = h.mean.shape[1]
    d = np.arange(n) if dims is None else np.asarray(dims, np.intp)
    x, P = h.mean[:, d], h.cov[:, d[:, None], d]
    nxt = next_rows(h)
    if lag is not None:
        return SmoothedTracks(*fixed_lag(h, x, P, nxt, motion, filt, lag), d)
    xs, Ps = x.copy(), P.copy()
    for s in range(h.times.size - 2, -1, -1):
        rows = np.arange(h.offsets[s], h.offsets[s + 1])
        rows = rows[nxt[rows] >= 0]
        if rows.size:
            after = nxt[rows]
            xs[rows], Ps[rows] = rts_step(filt, x[rows], P[rows], xs[after], Ps[after],
                                          motion, float(h.times[s + 1] - h.times[s]))
    return SmoothedTracks(xs, Ps, d)


def fixed_lag(h: TrackHistory, x: Array, P: Array, nxt: NDArray[np.int64], motion: Any,
              filt: Any, lag: int) -> tuple[Array, Array]:
    """Fixed-lag RTS: each row smoothed back from the filtered estimate ``lag`` rows later
    (or its piece's last row), with the gains ``G_k`` of one batched pass over every row
    (:func:`trackkit.filters.smoothers.fixed_lag_sweeps`). When the smoothing model is not
    the filter's (an IMM's mixture, smoothed with one of its models) the backward recursion
    need not contract (``G_k`` with eigenvalues just above 1 over thousands of scans of a
    moored vessel), and a fixed lag bounds what the mismatch can accumulate."""
    if lag < 1:
        raise ValueError(f"lag = {lag!r}; expected a number of scans >= 1")
    scan = np.repeat(np.arange(h.times.size), np.diff(h.offsets))
    rows = np.flatnonzero(nxt >= 0)
    dt = np.diff(np.asarray(h.times, float))[scan[rows]]
    pred, G_r = rts_gain(filt, x[rows], P[rows], motion, dt)
    pm, pc, G = np.zeros_like(x), np.zeros_like(P), np.zeros_like(P)
    pm[rows], pc[rows], G[rows] = pred.mean, pred.cov, G_r
    return fixed_lag_sweeps(x, P, Gaussian._make((pm, pc)), G, nxt, lag)


def smoothing_model(tracker: Any, dt: float) -> tuple[Any, Any, NDArray[np.intp] | None]:
    """``(motion, filter, dims)`` for :func:`smooth_tracks` of ``tracker``'s tracks: its own
    model and filter over the whole state (dims None); for an IMM, the model with the
    largest process noise over ``dt`` s in position and velocity (trace of Q over the
    state's first four components; a linear model first on a tie), its inner filter and its
    components."""
    f = tracker.filter
    if not hasattr(f, "state_maps"):
        return tracker.motion, f, None
    models = f.models if tracker.motion is None else tuple(tracker.motion)

    def rank(j: int) -> tuple[float, bool]:
        m, a = models[j], f.state_maps[j]
        Q = np.asarray(m.noise(np.zeros(a.size), dt), float)
        kin = np.flatnonzero(a < 4)
        return float(np.trace(Q[np.ix_(kin, kin)])), bool(getattr(m, "linear", False))

    j = max(range(len(models)), key=rank)
    return models[j], f.filters[j], np.asarray(f.state_maps[j], np.intp)
