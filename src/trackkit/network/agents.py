"""One agent of the decentralised tracker of Jalalipoor and Kardehi Moghaddam (2021): its program
per execution (Jalalipoor and Kardehi Moghaddam 2021, Fig. 2), its tracks batched (arrays over
tracks), and the versioned message it broadcasts.

Per execution at time t (the order of Fig. 2, with our choices where the paper
leaves one open):

1. **Neighbours.** Received messages live in a :class:`~trackkit.network.tracks.MessageMemory`
   (``memory_s`` seconds); the neighbours are its senders. The raw bearings of every received
   message are queued on receipt (``Agent.receive``), because the memory keeps only each
   sender's newest message and a neighbour may execute twice between two of our executions.
2. **Prediction** of every track to t, constant velocity with spectral density q::

       x- = F(dt) x,  P- = F(dt) P F(dt)^T + Q(|dt|),
       F = [[I, dt I], [0, I]],  Q = q [[|dt|^3/3 I, dt^2/2 sgn(dt) I], [.., |dt| I]]

   (the same F back to a bearing's earlier time t_k, dt = t_k - t < 0, with ``Q(|dt|)``: the
   uncertainty of the extrapolation grows whichever way it goes).
3. **Association**, one bearing source (one sensor's execution: unlabelled bearings, one per
   target in range) at a time: each track's bearing from that sensor position at that time,
   ``zhat_i = atan2(x_i(t_k) - x_s, y_i(t_k) - y_s)``, ``S_i = H P_i(t_k) H^T + sigma^2``,
   the ellipsoidal ``gate`` (P_G = ``p_gate``), the cost ``c_ij = K1 (1 - exp(-K2 d2_ij))``
   (``saturating_costs``) and the Munkres assignment (``gnn_assign``).
4. **Batches and composite measurements.** Each track accumulates its associated bearings. A
   batch of at least ``batch_min`` bearings is offered to ``composite_measurement`` (all such
   tracks in one call, nan-padded rows, t_f = t, x0 = the prediction). Its status decides:
   CONVERGED and a goodness of fit ``2 lambda <= chi2.ppf(fit_p, M - 4)`` make a measurement
   z_c = x_ML, R_c = J^-1, and the batch is cleared, so every bearing enters one composite
   only (composites that reused bearings would be correlated measurements, which a Kalman
   update must not be fed). SINGULAR or NOT_CONVERGED keep accumulating; a batch that
   converges but fails the fit mixes targets (or holds a wrong association) and is dropped.
   Bearings older than ``batch_age_s`` leave the batch.
5. **Diffusion update** (eqs. 46-48, ``diffusion.adapt`` with H = I):
   ``P+ = (P-^-1 + R_c^-1)^-1``, ``x+ = x- + P+ R_c^-1 (z_c - x-)``.
6. **Combination** with the neighbours' estimates of the same targets: each neighbour's tracks
   from its newest message, predicted to t, are matched to ours by ``match_tracks`` (S_ij in a
   chi-square gate), and ``diffusion.combine`` fuses each of our tracks with its matches,
   uniform weights ``a_l = 1 / (1 + m)`` over the track itself and its m matches (Metropolis
   weights would need the neighbours' degrees, which the message does not carry). The
   default rule is ``"information"`` (covariance intersection with those fixed weights,
   consistent whatever the correlation: our composites and a neighbour's share raw bearings);
   ``"paper"`` is eqs. 49-50 as printed. Only the neighbours' confirmed tracks are used.
7. **Initiation** (eqs. 7-8). Bearings no track claimed (own and neighbours') stay in a pool
   for ``init_window_s``. Each unclaimed bearing new at this execution (own or a
   neighbour's, so that a target only neighbours measure can be started; up to
   ``max_initiations`` per execution, in random order) seeds
   ``initiate_from_bearing`` over the pool.
   *Support rule* (the paper has none; ours): the best candidate is accepted only when at
   least ``min_support`` pool bearings lie within 2 sigma of it, from at least
   ``min_sources`` different sensors (two separated sensors observe a CV target without
   manoeuvres; one does not), and the composite measurement of those bearings at t from the
   candidate converges and passes the fit test.
   The track starts at that composite (x_ML, J^-1), and its bearings leave the pool.
8. **Pruning, timers, deletion.** ``duplicates`` deletes the more uncertain of two tracks
   within the similarity gate; ``TimerLogic`` steps with hit = "a bearing was associated at
   this execution"; DELETED tracks are dropped, and so are *ghosts*, confirmed tracks no
   neighbour able to see them has matched for ``corroborate_s`` (ours; ``AgentSettings``).
   A Lost track coasts: the paper feeds it its
   own predicted measurement, z = h(x-), whose innovation is zero, so the update returns the
   prediction (with the covariance shrunk by a fictitious measurement, which we refuse:
   coasting keeps P- honest).
9. **Broadcast** of a :class:`Payload` (version :data:`PAYLOAD_VERSION`): the new raw own
   bearings, the tracks (ids, states, covariances, status, lost) at t, and the agent's
   position, velocity and communication range (for the neighbours' course control).
10. **Steering** (optional): ``steer`` with the confirmed tracks as targets and the neighbours
    from the memory (their last reported position and velocity), then the run moves the
    agent with ``move``.

``step`` is the program; the pieces (:func:`predict_tracks`, :func:`associate`,
:func:`composites`, :func:`combine_with_neighbours`, ...) are pure functions over the batched
:class:`Tracks`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.belief import Gaussian
from trackkit.eval.metrics import chi2_ppf
from trackkit.models.sensors import Bearing
from trackkit.network.composite import CONVERGED, composite_measurement
from trackkit.network.diffusion import COMBINATIONS, adapt, combine
from trackkit.network.steering import Steering, steer
from trackkit.network.tracks import (
    DEFAULT_GATE,
    Message,
    MessageMemory,
    duplicates,
    match_tracks,
)
from trackkit.tracking import (
    IdCounter,
    TimerLogic,
    gate,
    gnn_assign,
    predict_measurement,
    saturating_costs,
)
from trackkit.tracking.bearings import BearingSet, concat_bearings, empty_bearings
from trackkit.tracking.initiate import initiate_from_bearing
from trackkit.tracking.logic import TimerState, TrackStatus

__all__ = [
    "PAYLOAD_VERSION",
    "AgentSettings",
    "Agent",
    "BearingSet",
    "Payload",
    "Tracks",
    "StepReport",
    "associate",
    "Call",
    "Program",
    "run_inline",
    "scan_source",
    "combine_with_neighbours",
    "combine_program",
    "combine_call",
    "steer_call",
    "composites",
    "composite_inputs",
    "composite_step",
    "CompositeStep",
    "cv_predict",
    "empty_bearings",
    "empty_tracks",
    "own_bearings",
    "predict_tracks",
    "plausible_speed",
    "update_tracks",
]

Array = NDArray[np.float64]

#: version of the :class:`Payload` schema (``Payload.from_dict`` refuses any other)
PAYLOAD_VERSION = 1

_CONF = np.int8(TrackStatus.CONFIRMED)
_DEL = np.int8(TrackStatus.DELETED)


# --------------------------------------------------------------------------------------------
# settings


@dataclass(frozen=True)
class AgentSettings:
    """An agent's parameters (the paper gives none of them; these are ours).

    Association: ``k1`` = 1, ``k2`` = 0.5 (the cost K1 (1 - exp(-K2 d2)), d2 the squared
    Mahalanobis bearing residual, so 1 - c/K1 is the Gaussian likelihood's shape);
    ``p_gate`` = 0.999 (bearing gate probability).
    Motion: ``q`` = 1e-4 m^2/s^3 (nearly constant velocity; the targets do not manoeuvre, a
    little q keeps the filter from locking up over 1 000 s).
    Batches: ``batch_min`` = 12 bearings before a composite is tried (measured on the
    baseline-like geometry of tests/network, 3 agents and 3 targets over 1 000 s, 24 runs:
    with 6, two bearings per agent over about 10 s, the composites are poorly conditioned
    in range and the agents' late position RMSE was 1.3-2.9x the centralised filter's;
    with 12 it is 1.2-1.3x for most (agent, target) pairs; 24 is no better on average and
    loses more tracks, 36 loses a quarter of them); ``batch_age_s`` = 120 s
    (older bearings leave the batch); ``fit_p`` = 0.999 (the composite's goodness of fit
    ``2 lambda <= chi2.ppf(fit_p, M - 4)``).
    Plausibility: ``speed_gate`` = 3 standard deviations (``plausible_speed``): a composite
    or a track faster than ``v_max`` by more than that is dropped or deleted (ours: with 12-
    bearing batches a track dragged off by a crossing target ran away at 160 m/s and held on
    as a fourth confirmed track; inf turns the test off).
    Timers (``TimerLogic``): ``confirm_after`` = 30 s, ``lost_after`` = 60 s,
    ``delete_after`` = 180 s.
    Initiation: ``n_candidates`` = 2 000; ``r_min`` = 100 m, ``r_max`` = 50 km (capped by the
    measurement range), ``v_max`` = 30 m/s (the paper's top speed); ``init_window_s`` = 60 s
    (the unclaimed-bearing pool); ``min_support`` = 8 bearings within 2 sigma from
    ``min_sources`` = 2 sensors; ``max_initiations`` = 1 track started per execution, from at
    most ``init_attempts`` = 3 seed bearings.
    Network: ``memory_s`` = 30 s (message expiry); ``match_gate`` and ``prune_gate``
    chi2.ppf(0.99, 4) (track-to-track matching and duplicate pruning); ``combination``
    "information" (or "paper", "convex", "ci"); ``combine_neighbours`` False turns the
    combination step off (a centralised node has no neighbours anyway).
    Corroboration (ours; the paper has none): ``corroborate_s`` = 60 s (inf turns it off)
    deletes a confirmed track of ours that no neighbour able to see it has matched for that
    long: a *ghost*, a track at the wrong range on a true line of sight (the initiation's
    ambiguity, docs/network-comparison.md), gathers our own bearings and keeps its timers
    alive while every neighbour's bearings and tracks miss it. A neighbour is able to see it
    when it holds confirmed tracks and the track lies within our ``meas_range`` of its
    position (the message does not carry the neighbour's range: the sensors are taken as
    alike). Adopting a neighbour's unmatched confirmed tracks instead was tried and spreads
    one agent's ghost to every agent (net-baseline run 20: five and six tracks each).
    Steering: ``steering`` None (straight courses) or a ``Steering``; ``comm_range``,
    ``meas_range`` (m, inf for unlimited) used by the constraints and the candidates.
    """

    k1: float = 1.0
    k2: float = 0.5
    p_gate: float = 0.999
    q: float = 1e-4
    batch_min: int = 12
    batch_age_s: float = 120.0
    fit_p: float = 0.999
    confirm_after: float = 30.0
    lost_after: float = 60.0
    delete_after: float = 180.0
    n_candidates: int = 2000
    r_min: float = 100.0
    r_max: float = 50_000.0
    v_max: float = 30.0
    speed_gate: float = 3.0
    init_window_s: float = 60.0
    min_support: int = 8
    min_sources: int = 2
    max_initiations: int = 1
    init_attempts: int = 3
    memory_s: float = 30.0
    match_gate: float = DEFAULT_GATE
    prune_gate: float = DEFAULT_GATE
    combination: str = "information"
    combine_neighbours: bool = True
    corroborate_s: float = 60.0
    steering: Steering | None = None
    comm_range: float = math.inf
    meas_range: float = math.inf

    def __post_init__(self) -> None:
        positive = ("k1", "k2", "batch_age_s", "lost_after", "delete_after", "r_max", "v_max",
                    "speed_gate", "corroborate_s",
                    "init_window_s", "memory_s", "match_gate", "prune_gate", "comm_range",
                    "meas_range")
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and v > 0 and not math.isnan(v)):
                raise ValueError(f"AgentSettings.{name} = {v!r}; expected a number > 0")
        for name in ("q", "confirm_after", "r_min"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"AgentSettings.{name} = {v!r}; expected a finite number >= 0")
        for name in ("p_gate", "fit_p"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise ValueError(f"AgentSettings.{name} = {v!r}; expected a probability in "
                                 "(0, 1)")
        for name, least in (("batch_min", 4), ("n_candidates", 1), ("min_support", 1),
                            ("min_sources", 1), ("max_initiations", 0),
                            ("init_attempts", 1)):
            v = getattr(self, name)
            if not (isinstance(v, int | np.integer) and v >= least):
                raise ValueError(f"AgentSettings.{name} = {v!r}; expected an integer >= "
                                 f"{least}")
        if self.combination not in COMBINATIONS:
            raise ValueError(f"AgentSettings.combination = {self.combination!r}; expected "
                             f"one of {COMBINATIONS}")
        if not self.r_min < min(self.r_max, self.meas_range):
            raise ValueError(f"AgentSettings.r_min = {self.r_min!r}; expected below r_max "
                             f"and meas_range (min {min(self.r_max, self.meas_range)!r} m)")
        TimerLogic(self.confirm_after, self.lost_after, self.delete_after)  # validates

    @property
    def logic(self) -> TimerLogic:
        return TimerLogic(self.confirm_after, self.lost_after, self.delete_after)


# --------------------------------------------------------------------------------------------
# data


class Tracks(NamedTuple):
    """An agent's tracks at one time, batched over T tracks.

    ``ids (T,)`` int64; ``mean (T, 4)``, ``cov (T, 4, 4)``: [x, y, vx, vy] at the agent's
    last execution; ``logic``: the ``TimerState`` (status, born, last_hit, lost); the
    pending batch of associated bearings, nan-padded ``(T, B)``: ``bz``, ``bt``,
    ``bsigma`` and ``bsensor (T, B, 2)`` (B grows and shrinks with the longest batch);
    ``seen (T,)``: the last time a neighbour able to see the track matched it, or none could
    (``AgentSettings.corroborate_s``).
    """

    ids: NDArray[np.int64]
    mean: Array
    cov: Array
    logic: TimerState
    bz: Array
    bt: Array
    bsensor: Array
    bsigma: Array
    seen: Array

    @property
    def size(self) -> int:
        return int(self.ids.shape[0])

    def take(self, idx: ArrayLike) -> Tracks:
        """The tracks at ``idx`` (indices, or a mask of T). A mask that keeps every track
        returns these tracks themselves: the agent never writes a track's arrays in place,
        and most executions delete nothing."""
        if (isinstance(idx, np.ndarray) and idx.dtype == bool and idx.shape == self.ids.shape
                and idx.all()):
            return self
        lg = TimerState(*(np.asarray(a)[idx] for a in self.logic))
        return Tracks(self.ids[idx], self.mean[idx], self.cov[idx], lg, self.bz[idx],
                      self.bt[idx], self.bsensor[idx], self.bsigma[idx], self.seen[idx])


def empty_tracks() -> Tracks:
    """An agent's track batch with no tracks (every array with 0 rows)."""
    lg = TimerState(np.zeros(0), np.zeros(0), np.zeros(0, np.int8), np.zeros(0, bool))
    return Tracks(np.zeros(0, np.int64), np.zeros((0, 4)), np.zeros((0, 4, 4)), lg,
                  np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0, 2)), np.zeros((0, 0)),
                  np.zeros(0))


def new_tracks(ids: NDArray[np.int64], mean: Array, cov: Array, logic: TimerState,
               t: float) -> Tracks:
    """Tracks started at t with empty batches."""
    n = ids.shape[0]
    return Tracks(ids, mean, cov, logic, np.zeros((n, 0)), np.zeros((n, 0)),
                  np.zeros((n, 0, 2)), np.zeros((n, 0)), np.full(n, float(t)))


def _concat_tracks(a: Tracks, b: Tracks) -> Tracks:
    B = max(a.bz.shape[1], b.bz.shape[1])

    def pad(x: Array, width: int) -> Array:
        extra = width - x.shape[1]
        if extra == 0:
            return x
        shape = (x.shape[0], extra) + x.shape[2:]
        return np.concatenate([x, np.full(shape, np.nan)], axis=1)

    lg = TimerState(*(np.concatenate([u, v]) for u, v in zip(a.logic, b.logic, strict=True)))
    return Tracks(np.concatenate([a.ids, b.ids]), np.concatenate([a.mean, b.mean]),
                  np.concatenate([a.cov, b.cov]), lg,
                  *(np.concatenate([pad(u, B), pad(v, B)])
                    for u, v in ((a.bz, b.bz), (a.bt, b.bt), (a.bsensor, b.bsensor),
                                 (a.bsigma, b.bsigma))),
                  np.concatenate([a.seen, b.seen]))


@dataclass(frozen=True)
class Payload:
    """What an agent broadcasts (schema version :data:`PAYLOAD_VERSION`), in SI units.

    ``sender``, ``time``; ``bearings``: its new raw bearings (``z``, ``t``, ``sensor``,
    ``sigma``, ``source``); ``tracks``: ``ids``, ``mean``, ``cov``, ``status``
    (``TrackStatus`` codes), ``lost``, all at ``time``; ``position``, ``velocity`` and
    ``comm_range`` of the sender (for course control). ``to_dict`` gives plain Python
    lists and numbers (JSON or msgpack), ``from_dict`` checks the version and shapes.
    """

    sender: int
    time: float
    bearings: BearingSet
    ids: NDArray[np.int64]
    mean: Array
    cov: Array
    status: NDArray[np.int8]
    lost: NDArray[np.bool_]
    position: Array
    velocity: Array
    comm_range: float
    version: int = PAYLOAD_VERSION

    def to_dict(self) -> dict[str, Any]:
        b = self.bearings
        return {
            "version": int(self.version), "sender": int(self.sender), "time": float(self.time),
            "bearings": {"z": b.z.tolist(), "t": b.t.tolist(), "sensor": b.sensor.tolist(),
                         "sigma": b.sigma.tolist(), "source": b.source.tolist()},
            "tracks": {"ids": self.ids.tolist(), "mean": self.mean.tolist(),
                       "cov": self.cov.tolist(), "status": self.status.tolist(),
                       "lost": self.lost.tolist()},
            "position": self.position.tolist(), "velocity": self.velocity.tolist(),
            "comm_range": float(self.comm_range),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Payload:
        v = d.get("version")
        if v != PAYLOAD_VERSION:
            raise ValueError(f"payload version = {v!r}; expected {PAYLOAD_VERSION}")
        try:
            b, tr = d["bearings"], d["tracks"]
            M = len(b["z"])
            bs = BearingSet(np.asarray(b["z"], float).reshape(M),
                            np.asarray(b["t"], float).reshape(M),
                            np.asarray(b["sensor"], float).reshape(M, 2),
                            np.asarray(b["sigma"], float).reshape(M),
                            np.asarray(b["source"], np.int64).reshape(M))
            T = len(tr["ids"])
            return cls(int(d["sender"]), float(d["time"]), bs,
                       np.asarray(tr["ids"], np.int64).reshape(T),
                       np.asarray(tr["mean"], float).reshape(T, 4),
                       np.asarray(tr["cov"], float).reshape(T, 4, 4),
                       np.asarray(tr["status"], np.int8).reshape(T),
                       np.asarray(tr["lost"], bool).reshape(T),
                       np.asarray(d["position"], float).reshape(2),
                       np.asarray(d["velocity"], float).reshape(2),
                       float(d["comm_range"]), int(v))
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"payload does not follow schema version {PAYLOAD_VERSION}: "
                             f"{err!r}; expected the fields of Payload.to_dict") from None


# --------------------------------------------------------------------------------------------
# pure kernels


def cv_predict(mean: ArrayLike, cov: ArrayLike, dt: ArrayLike, q: float) -> tuple[Array, Array]:
    """``x- = F(dt) x``, ``P- = F P F^T + Q(|dt|)`` (module docstring, step 2), batched:
    ``mean (..., 4)``, ``cov (..., 4, 4)``, ``dt`` broadcast to ``(...)`` (any sign)."""
    x = np.asarray(mean, dtype=float)
    P = np.asarray(cov, dtype=float)
    d = np.broadcast_to(np.asarray(dt, dtype=float), x.shape[:-1])
    F = np.broadcast_to(np.eye(4), d.shape + (4, 4)).copy()
    F[..., 0, 2] = d
    F[..., 1, 3] = d
    a = np.abs(d)
    Q = np.zeros(d.shape + (4, 4))
    for i in (0, 1):
        Q[..., i, i] = q * a**3 / 3.0
        Q[..., i, i + 2] = Q[..., i + 2, i] = q * d * a / 2.0
        Q[..., i + 2, i + 2] = q * a
    xn = np.einsum("...ij,...j->...i", F, x)
    Pn = F @ P @ np.swapaxes(F, -1, -2) + Q
    return xn, 0.5 * (Pn + np.swapaxes(Pn, -1, -2))


def predict_tracks(tracks: Tracks, dt: float, q: float) -> Tracks:
    """Every track predicted by dt (>= 0) seconds."""
    if tracks.size == 0 or dt == 0:
        return tracks
    x, P = cv_predict(tracks.mean, tracks.cov, dt, q)
    return tracks._replace(mean=x, cov=P)


def associate(mean: Array, cov: Array, t: float, bearings: BearingSet, settings: AgentSettings
              ) -> NDArray[np.intp]:
    """Assign each track (``mean (T, 4)``, ``cov (T, 4, 4)`` at time t) at most one bearing of
    one source's scan (``bearings``, all of one sensor at one time): gate, the cost of
    Jalalipoor and Kardehi Moghaddam (2021) and Munkres (module docstring, step 3).
    Returns ``det (T,)``, -1 for none."""
    T, D = mean.shape[0], bearings.size
    if T == 0 or D == 0:
        return np.full(T, -1, np.intp)
    tk, sk = scan_source(bearings)
    x, P = cv_predict(mean, cov, tk - t, settings.q)
    pred = predict_measurement(Gaussian(x, P), Bearing(origin=sk, sigma=float(bearings.sigma[0])))
    g = gate(pred.zhat, pred.S, bearings.z[:, None], settings.p_gate, angular=(True,))
    return gnn_assign(g, saturating_costs(g, settings.k1, settings.k2)).det


def scan_source(bearings: BearingSet) -> tuple[float, Array]:
    """The time and sensor position of one source's scan (a ValueError for several)."""
    tk, sk = float(bearings.t[0]), bearings.sensor[0]
    if not (np.all(bearings.t == tk) and np.all(bearings.sensor == sk)):
        raise ValueError("associate: bearings come from several times or positions; expected "
                         "one source's scan (one sensor at one time)")
    return tk, sk


def _append(tracks: Tracks, det: NDArray[np.intp], bearings: BearingSet) -> Tracks:
    """One new batch column: track i gets ``bearings[det[i]]`` (nan where det is -1)."""
    hit = det >= 0
    if not hit.any():
        return tracks
    j = np.where(hit, det, 0)
    col = lambda a: np.where(hit, a[j], np.nan)[:, None]  # noqa: E731
    sen = np.where(hit[:, None], bearings.sensor[j], np.nan)[:, None, :]
    return tracks._replace(bz=np.concatenate([tracks.bz, col(bearings.z)], 1),
                           bt=np.concatenate([tracks.bt, col(bearings.t)], 1),
                           bsensor=np.concatenate([tracks.bsensor, sen], 1),
                           bsigma=np.concatenate([tracks.bsigma, col(bearings.sigma)], 1))


def _compact(tracks: Tracks, t: float, max_age: float) -> Tracks:
    """Drop batch bearings older than ``t - max_age``, move the present ones to the front of
    each row (order kept) and trim the all-missing columns."""
    if tracks.bz.shape[1] == 0:
        return tracks
    keep = ~np.isnan(tracks.bz) & (tracks.bt >= t - max_age)
    width = int(keep.sum(1).max()) if keep.size else 0
    # each row's gather as a (row, column) index pair: take_along_axis's own index building
    # costs more than the gather on a few tracks
    rows = np.arange(keep.shape[0])[:, None]
    order = np.argsort(~keep, axis=1, kind="stable")[:, :width]
    k = keep[rows, order]

    def take(a: Array) -> Array:
        return np.where(k, a[rows, order], np.nan)

    return tracks._replace(bz=take(tracks.bz), bt=take(tracks.bt), bsigma=take(tracks.bsigma),
                           bsensor=np.where(k[..., None], tracks.bsensor[rows, order], np.nan))


class CompositeStep(NamedTuple):
    """Per track: ``z (T, 4)`` the composite measurement (nan where none), ``R (T, 4, 4)``
    (nan where none), ``made (T,)`` and ``dropped (T,)`` (a batch that failed the fit)."""

    z: Array
    R: Array
    made: NDArray[np.bool_]
    dropped: NDArray[np.bool_]


def composites(tracks: Tracks, t: float, settings: AgentSettings) -> CompositeStep:
    """The composite measurements at t of every track whose batch may fix the state (module
    docstring, step 4), in one batched ``composite_measurement`` call."""
    rows, args = composite_inputs(tracks, t, settings)
    if rows.size == 0:
        return composite_step(tracks.size, rows, None, args[0], settings)
    return composite_step(tracks.size, rows, composite_measurement(*args), args[0], settings)


def composite_inputs(tracks: Tracks, t: float, settings: AgentSettings
                     ) -> tuple[NDArray[np.intp], tuple]:
    """The tracks whose batch holds at least ``batch_min`` bearings, and the arguments of
    ``composite_measurement`` for them (the missing slots filled: the fit ignores them)."""
    T = tracks.size
    count = (~np.isnan(tracks.bz)).sum(1) if T else np.zeros(0, int)
    rows = np.flatnonzero(count >= settings.batch_min)
    bz = tracks.bz[rows]
    present = ~np.isnan(bz)
    bt = np.where(present, tracks.bt[rows], t)
    bs = np.where(present[..., None], tracks.bsensor[rows], 0.0)
    sg = np.where(present, tracks.bsigma[rows], 1.0)
    return rows, (bz, bt, bs, sg, t, tracks.mean[rows])


def composite_step(T: int, rows: NDArray[np.intp], c: Any, bz: Array,
                   settings: AgentSettings) -> CompositeStep:
    """The :class:`CompositeStep` of T tracks from the fits ``c`` of the ``rows`` (None for
    no rows) to the bearings ``bz``: a converged fit that passes ``2 lambda <= chi2.ppf(
    fit_p, M - 4)`` and the speed test is a measurement; one that fails them is dropped."""
    z = np.full((T, 4), np.nan)
    R = np.full((T, 4, 4), np.nan)
    made = np.zeros(T, bool)
    dropped = np.zeros(T, bool)
    if c is None:
        return CompositeStep(z, R, made, dropped)
    M = (~np.isnan(bz)).sum(1)
    limit = chi2_ppf(settings.fit_p, np.maximum(M - 4, 1))
    ok = c.status == CONVERGED
    # a composite faster than any target (beyond its own uncertainty) is a mixed or wrongly
    # associated batch as surely as one that fails the fit: dropped too
    fit = (2.0 * c.cost <= limit) & plausible_speed(c.mean, c.cov, settings)
    use = ok & fit
    z[rows[use]] = c.mean[use]
    R[rows[use]] = c.cov[use]
    made[rows[use]] = True
    dropped[rows[ok & ~fit]] = True
    return CompositeStep(z, R, made, dropped)


def plausible_speed(mean: Array, cov: Array, settings: AgentSettings) -> NDArray[np.bool_]:
    """``|v| <= v_max + speed_gate sqrt(lambda_max(P_vv))`` per row of ``mean (..., 4)``,
    ``cov (..., 4, 4)``: the speed is one a target can have, within ``speed_gate`` standard
    deviations of the estimate's velocity along its worst direction (nan: False)."""
    if math.isinf(settings.speed_gate):
        return np.ones(mean.shape[:-1], bool)
    Pv = cov[..., 2:, 2:]
    # the larger eigenvalue of a symmetric 2 x 2, in closed form (batched, no LAPACK call)
    half_tr = 0.5 * (Pv[..., 0, 0] + Pv[..., 1, 1])
    det = Pv[..., 0, 0] * Pv[..., 1, 1] - Pv[..., 0, 1] * Pv[..., 1, 0]
    with np.errstate(invalid="ignore"):
        lam = half_tr + np.sqrt(np.maximum(half_tr * half_tr - det, 0.0))
        speed = np.hypot(mean[..., 2], mean[..., 3])
        return speed <= settings.v_max + settings.speed_gate * np.sqrt(lam)


def _clear_batches(tracks: Tracks, rows: NDArray[np.bool_]) -> Tracks:
    if not rows.any():
        return tracks
    m = rows[:, None]
    return tracks._replace(bz=np.where(m, np.nan, tracks.bz), bt=np.where(m, np.nan, tracks.bt),
                           bsigma=np.where(m, np.nan, tracks.bsigma),
                           bsensor=np.where(m[..., None], np.nan, tracks.bsensor))


def update_tracks(tracks: Tracks, step: CompositeStep) -> Tracks:
    """The diffusion update with each track's composite measurement (H = I, R = J^-1), via
    ``diffusion.adapt`` with one agent per track row; tracks without one keep their prior."""
    if not step.made.any():
        return tracks
    b = Gaussian(tracks.mean[:, None, :], tracks.cov[:, None, :, :])
    R = np.where(step.made[:, None, None], step.R, np.eye(4))[:, None]
    out = adapt(b, step.z[:, None, :], R, np.ones((1, 1)))
    return tracks._replace(mean=out.mean[:, 0], cov=out.cov[:, 0])


def combine_with_neighbours(mean: Array, cov: Array,
                            neighbours: Sequence[tuple[Array, Array]],
                            settings: AgentSettings) -> tuple[Array, Array, NDArray[np.int64]]:
    """Fuse our tracks ``(T, 4)``, ``(T, 4, 4)`` with each neighbour's tracks (already
    predicted to the same time) matched to them by ``match_tracks``: ``combine`` over the
    slots (own, neighbour 1, ..., neighbour L) with uniform weights over the track and its
    matches (module docstring, step 6). Returns the fused means, covariances and the number
    of matches of each track."""
    return run_inline(combine_program(mean, cov, neighbours, settings))


def combine_program(mean: Array, cov: Array, neighbours: Sequence[tuple[Array, Array]],
                    settings: AgentSettings) -> Program:
    """:func:`combine_with_neighbours` as a program (:class:`Call`)."""
    T, L = mean.shape[0], len(neighbours)
    matches = np.zeros(T, np.int64)
    if T == 0 or L == 0:
        return mean, cov, matches
    X = np.repeat(mean[:, None], L + 1, 1)
    P = np.repeat(cov[:, None], L + 1, 1)
    have = np.zeros((T, L + 1), bool)
    have[:, 0] = True
    for l, (xn, Pn) in enumerate(neighbours):  # a loop over neighbours, not over tracks
        if xn.shape[0] == 0:
            continue
        m = yield Call(match_tracks, (mean, cov, xn, Pn, settings.match_gate))
        X[m.a, l + 1] = xn[m.b]
        P[m.a, l + 1] = Pn[m.b]
        have[m.a, l + 1] = True
    matches = have[:, 1:].sum(1)
    if not matches.any():
        return mean, cov, matches
    # row 0 (ours) weights its present slots uniformly; the other rows are placeholders
    # (identity rows) that combine needs for a square matrix
    W = np.broadcast_to(np.eye(L + 1), (T, L + 1, L + 1)).copy()
    W[:, 0] = have / have.sum(1, keepdims=True)
    out = yield Call(combine_call, (X, P, W, settings.combination))
    return out.mean[:, 0], out.cov[:, 0], matches


def combine_call(X: Array, P: Array, W: Array, rule: str) -> Gaussian:
    """``combine`` with positional arguments (a :class:`Call`)."""
    return combine(Gaussian(X, P), W, rule)


def _support(x: Array, t0: float, pool: BearingSet) -> NDArray[np.bool_]:
    """Pool bearings within 2 sigma of the state ``x`` given at ``t0``."""
    dt = pool.t - t0
    zeta = wrap(np.arctan2(x[0] + dt * x[2] - pool.sensor[:, 0],
                           x[1] + dt * x[3] - pool.sensor[:, 1]) - pool.z) / pool.sigma
    return np.abs(zeta) <= 2.0


# --------------------------------------------------------------------------------------------
# the program's kernel calls


class Call(NamedTuple):
    """One kernel call of the agent's program, ``fn(*args)``: the program yields it and is
    sent the result, so that a driver may run the same call of many runs' agents together
    (:mod:`trackkit.network.lockstep`) or run it at once (:func:`run_inline`)."""

    fn: Callable[..., Any]
    args: tuple


#: the agent's program (``Agent.program``): a generator that yields its kernel calls and is
#: sent their answers
Program = Generator[Call, Any, Any]


def run_inline(program: Program) -> Any:
    """Run a program's calls one by one as it yields them; its return value."""
    try:
        call = next(program)
        while True:
            call = program.send(call.fn(*call.args))
    except StopIteration as stop:
        return stop.value


# --------------------------------------------------------------------------------------------
# the agent


class StepReport(NamedTuple):
    """Counts of one execution: bearings associated, composites made and dropped, tracks
    started, pruned and deleted, neighbours heard from."""

    associated: int
    composites: int
    dropped: int
    started: int
    pruned: int
    deleted: int
    neighbours: int


@dataclass
class Agent:
    """One agent: its index, settings, tracks, memory and random stream (a thin holder; the
    work is in the module's pure functions). ``step`` runs the program of one execution and
    returns the :class:`Message` to broadcast."""

    index: int
    settings: AgentSettings
    rng: np.random.Generator
    tracks: Tracks = field(default_factory=empty_tracks)
    time: float = -math.inf
    memory: MessageMemory | None = None
    inbox: list[BearingSet] = field(default_factory=list)
    pool: BearingSet = field(default_factory=empty_bearings)
    counter: IdCounter = field(default_factory=IdCounter)

    def __post_init__(self) -> None:
        if self.memory is None:
            self.memory = MessageMemory(self.settings.memory_s)

    # ---- network side
    def receive(self, message: Message) -> None:
        """Store a neighbour's message and queue its raw bearings (module docstring, 1)."""
        p = message.payload
        if not isinstance(p, Payload):
            raise ValueError(f"Agent.receive: payload of type {type(p).__name__}; expected "
                             "a Payload")
        if p.sender == self.index:
            return
        assert self.memory is not None
        self.memory.receive(message)
        if p.bearings.size:
            self.inbox.append(p.bearings)

    def neighbour_tracks(self, t: float) -> list[tuple[Array, Array]]:
        """Each neighbour's confirmed tracks from its newest message, predicted to t."""
        return run_inline(self._neighbour_tracks(t))

    def _neighbour_tracks(self, t: float) -> Program:
        assert self.memory is not None
        self.memory.expire(t)
        out = []
        for m in self.memory:
            p: Payload = m.payload
            keep = p.status == _CONF
            x, P = yield Call(cv_predict, (p.mean[keep], p.cov[keep], t - p.time,
                                           self.settings.q))
            out.append((x, P))
        return out

    # ---- the program
    def step(self, t: float, own: BearingSet, position: ArrayLike = (0.0, 0.0),
             velocity: ArrayLike = (0.0, 0.0)) -> tuple[Message, StepReport]:
        """One execution at time t with the agent's own new bearings ``own`` (one scan)."""
        return run_inline(self.program(t, own, position, velocity))

    def program(self, t: float, own: BearingSet, position: ArrayLike = (0.0, 0.0),
                velocity: ArrayLike = (0.0, 0.0)) -> Program:
        """``step`` as a program that yields its kernel calls (:class:`Call`) and returns
        the message and the report."""
        s = self.settings
        if not t >= self.time:
            raise ValueError(f"Agent.step: t = {t!r}; expected a time >= the last execution "
                             f"({self.time!r} s)")
        tr = yield Call(predict_tracks, (self.tracks, 0.0 if self.tracks.size == 0
                                         else t - self.time, s.q))
        self.time = t

        # association, one source (one sensor's execution) at a time, newest bearings last
        new = [own] + self.inbox
        self.inbox = []
        hits = np.zeros(tr.size, bool)
        unclaimed: list[BearingSet] = []
        n_assoc = 0
        for b in _by_source(new):
            det = yield Call(associate, (tr.mean, tr.cov, t, b, s))
            tr = _append(tr, det, b)
            hits |= det >= 0
            n_assoc += int((det >= 0).sum())
            taken = np.zeros(b.size, bool)
            taken[det[det >= 0]] = True
            unclaimed.append(b.take(~taken))
        tr = _compact(tr, t, s.batch_age_s)

        # composite measurements from batches that fix the state, then the update
        cs = yield Call(composites, (tr, t, s))
        tr = yield Call(update_tracks, (tr, cs))
        tr = _clear_batches(tr, cs.made | cs.dropped)
        tr = _compact(tr, t, s.batch_age_s)

        # combination with the neighbours' estimates of the same targets
        nb = yield from self._neighbour_tracks(t)
        if s.combine_neighbours and nb and tr.size:
            x, P, _ = yield from combine_program(tr.mean, tr.cov, nb, s)
            tr = tr._replace(mean=x, cov=P)

        # the timers (before initiation: a new track's first hit is its birth)
        logic = s.logic
        if tr.size:
            tr = tr._replace(logic=logic.step(tr.logic, t, hits))
        ghosts = 0
        if nb and tr.size and math.isfinite(s.corroborate_s):
            tr, ghosts = yield from self._corroborate(tr, nb, t)

        # initiation from the unclaimed pool
        n_new = sum(b.size for b in unclaimed)
        pool = concat_bearings(self.pool, *unclaimed) if unclaimed else self.pool
        fresh = np.arange(pool.size) >= pool.size - n_new
        recent = pool.t >= t - s.init_window_s
        pool, fresh = pool.take(recent), fresh[recent]
        tr, pool, started = yield from self._initiate(tr, pool, np.flatnonzero(fresh), t)
        self.pool = pool

        # duplicates, then deletion
        pruned = np.zeros(tr.size, bool)
        if tr.size > 1:
            pruned = yield Call(duplicates, (tr.mean, tr.cov, s.prune_gate))
        # a track that has run off faster than any target is following nothing real (a
        # ghost, or a track dragged off by a crossing target's bearings): deleted
        dead = pruned | (tr.logic.status == _DEL) | ~plausible_speed(tr.mean, tr.cov, s)
        tr = tr.take(~dead)
        self.tracks = tr

        msg = Message(self.index, t, self.payload(own, position, velocity))
        rep = StepReport(n_assoc, int(cs.made.sum()), int(cs.dropped.sum()), started,
                         int(pruned.sum()), int(dead.sum() - pruned.sum()) + ghosts, len(nb))
        return msg, rep

    def _corroborate(self, tr: Tracks, nb: list[tuple[Array, Array]], t: float) -> Program:
        """``AgentSettings.corroborate_s`` against the neighbours' confirmed tracks ``nb``
        (``neighbour_tracks(t)``, in memory order): refresh ``seen`` and delete the ghosts.
        Returns the tracks and the number of ghosts deleted."""
        s = self.settings
        assert self.memory is not None
        matched = np.zeros(tr.size, bool)
        watched = np.zeros(tr.size, bool)  # some neighbour holding tracks could see it
        for (xn, Pn), m in zip(nb, self.memory, strict=True):
            if xn.shape[0] == 0:
                continue
            found = yield Call(match_tracks, (tr.mean, tr.cov, xn, Pn, s.match_gate))
            matched[found.a] = True
            where = m.payload.position + (t - m.time) * m.payload.velocity
            watched |= np.hypot(*(tr.mean[:, :2] - where).T) <= s.meas_range
        seen = np.where(matched | ~watched, t, tr.seen)
        ghost = (tr.logic.status == _CONF) & (t - seen > s.corroborate_s)
        return tr._replace(seen=seen).take(~ghost), int(ghost.sum())

    def _initiate(self, tr: Tracks, pool: BearingSet, fresh: NDArray[np.intp], t: float
                  ) -> Program:
        """Initiation seeded by the unclaimed bearings new at this execution (``fresh``
        indices into the pool; own or neighbours', so that a target only neighbours see can
        be started), at most ``max_initiations`` of them, in random order. Returns the
        tracks, the pool and the number of tracks started."""
        s = self.settings
        started = 0
        if s.max_initiations == 0 or pool.size < s.min_support or fresh.size == 0:
            return tr, pool, 0
        seeds = self.rng.permutation(fresh)
        r_max = min(s.r_max, s.meas_range)
        used = np.zeros(pool.size, bool)
        for k in seeds[: s.init_attempts].tolist():
            if used[k] or started >= s.max_initiations:
                continue
            sub = np.flatnonzero(~used)
            kk = int(np.searchsorted(sub, k))
            part = pool.take(sub)
            ini = initiate_from_bearing(kk, part, s.r_min, r_max,
                           s.v_max, self.rng, s.n_candidates, s.k1, s.k2)
            sup = _support(ini.mean, float(part.t[kk]), part)
            if sup.sum() < s.min_support or np.unique(part.source[sup]).size < s.min_sources:
                continue
            x0, _ = cv_predict(ini.mean, np.eye(4), t - float(part.t[kk]), 0.0)
            b = part.take(sup)
            c = yield Call(composite_measurement, (b.z, b.t, b.sensor, b.sigma, t, x0))
            if c.status != CONVERGED or 2.0 * c.cost > chi2_ppf(s.fit_p, max(b.size - 4, 1)):
                continue
            ids, self.counter = self.counter.issue(1)
            lg = s.logic.init(t, 1)
            tr = _concat_tracks(tr, new_tracks(ids, c.mean[None], c.cov[None], lg, t))
            used[sub[sup]] = True
            started += 1
        return tr, pool.take(~used), started

    def payload(self, own: BearingSet, position: ArrayLike, velocity: ArrayLike) -> Payload:
        tr = self.tracks
        return Payload(self.index, self.time, own, tr.ids.copy(), tr.mean.copy(), tr.cov.copy(),
                       tr.logic.status.copy(), tr.logic.lost.copy(),
                       np.asarray(position, float).reshape(2),
                       np.asarray(velocity, float).reshape(2), float(self.settings.comm_range))

    def confirmed(self) -> Tracks:
        """The confirmed tracks (the agent's output)."""
        return self.tracks.take(self.tracks.logic.status == _CONF)

    # ---- course control
    def steer(self, position: ArrayLike, course: float, speed: float, dt: float) -> float:
        """The commanded course for the next dt seconds (``steer`` with the confirmed
        tracks as targets and the neighbours in memory); the current course when the
        settings have no ``steering``."""
        return run_inline(self.steering_program(position, course, speed, dt))

    def steering_program(self, position: ArrayLike, course: float, speed: float, dt: float
                         ) -> Program:
        """``steer`` as a program (:class:`Call`)."""
        s = self.settings
        if s.steering is None:
            return float(course)
        c = self.confirmed()
        if c.size:
            targets, tv = c.mean[None, :, :2], c.mean[None, :, 2:]
        else:
            targets = tv = np.full((1, 1, 2), np.nan)
        assert self.memory is not None
        msgs = list(self.memory)
        if msgs:
            # a neighbour's last reported position, carried to now on its reported velocity
            npos = np.stack([m.payload.position + (self.time - m.time) * m.payload.velocity
                             for m in msgs])[None]
            nvel = np.stack([m.payload.velocity for m in msgs])[None]
            nr = np.array([m.payload.comm_range for m in msgs])[None]
        else:
            npos = nvel = np.full((1, 1, 2), np.nan)
            nr = np.full((1, 1), np.nan)
        cmd = yield Call(steer_call, (np.asarray(position, float)[None], np.array([course]),
                                  np.array([speed]), np.array([dt]), targets, tv, npos, nvel,
                                  nr, np.array([s.comm_range]), np.array([s.meas_range]),
                                  s.steering))
        return float(cmd.course[0])


def steer_call(position: Array, course: Array, speed: Array, dt: Array, targets: Array,
               tv: Array, npos: Array, nvel: Array, nr: Array, comm_range: Array,
               meas_range: Array, params: Steering) -> Any:
    """``steer`` with positional arguments (a :class:`Call`)."""
    return steer(position, course, speed, dt, targets=targets, target_velocity=tv,
                 neighbours=npos, neighbour_velocity=nvel, neighbour_range=nr,
                 comm_range=comm_range, meas_range=meas_range, params=params)


def _by_source(sets: Sequence[BearingSet]) -> list[BearingSet]:
    """Split bearing sets into single-source scans (one sensor at one time), in time order."""
    out = []
    for b in sets:
        if b.size == 0:
            continue
        if np.all(b.source == b.source[0]) and np.all(b.t == b.t[0]):
            out.append(b)  # a message's bearings: one source already
            continue
        key = np.stack([b.source.astype(float), b.t], -1)
        _, inv = np.unique(key, axis=0, return_inverse=True)
        for g in range(int(inv.max()) + 1):
            out.append(b.take(inv.ravel() == g))
    out.sort(key=lambda b: float(b.t[0]))
    return out


def own_bearings(z: ArrayLike, t: float, position: ArrayLike, sigma: float,
                 source: int) -> BearingSet:
    """One scan's bearings ``z (Nt,)`` as a :class:`BearingSet`, nan (out of range) dropped.
    The slots' target order survives in the set's order, but nothing in the agent reads it:
    association, batches and initiation see unlabelled bearings."""
    z = np.asarray(z, dtype=float).reshape(-1)
    z = z[~np.isnan(z)]
    M = z.size
    return BearingSet(z, np.full(M, float(t)), np.broadcast_to(np.asarray(position, float),
                                                               (M, 2)).copy(),
                      np.full(M, float(sigma)), np.full(M, int(source), np.int64))

