"""The multi-target tracker: the radar loop of the missing-measurements thesis (its chapter 1) on
the batched core.

One scan, for every live track at once (axis 0 of one batched belief is the track axis):

    predict      x-, P- = f.predict(x, P, dt)                      one filter call
    measure      zhat, S from the filter's own innovation            one filter call
    gate         d2_ij = nu_ij^T S_i^-1 nu_ij <= gamma(P_G)         KD-tree pre-gate
                 (a held track: only plots no other track gates, while narrow)
    associate    GNN (least cost, per cluster) or JPDA (marginals beta_ij, beta_i0)
    update       GNN: f.update(x-, z_assigned)  (nan: a missed track keeps x-)
                 JPDA: every gated hypothesis updated as one batch, then the mixture
                 x = beta_0 x- + sum_j beta_j x_j, P = sum (beta (P + d d^T)) moment-matched
                 (a filter with ``merge_hypotheses``, the IMM, combines its own beliefs)
    logic        hit/miss -> M-of-N or SPRT score -> confirm, delete
    rejoin       a newly confirmed track takes the ID of the held track it continues
    initiate     unassigned plots -> new tentative tracks, new IDs

``zhat`` and ``S`` come from the filter itself: an update at ``z0 = h(x-)`` returns the
residual ``z0 - zhat`` and the innovation covariance ``S`` of that filter (exactly
``h(x-)`` and ``H P H^T + R`` for the KF and EKF, the unscented ones for the UKF and CKF,
the mixture's for an IMM), so the gate and the association use the filter's likelihood. A
filter with a ``measurement_prediction`` (the IMM of first-order EKFs) gives the same two
without the update.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from trackkit.angles import wrap
from trackkit.belief import Gaussian, moment_match
from trackkit.filters.base import register
from trackkit.filters.kalman import EKF, KF
from trackkit.io.scans import Scan
from trackkit.models.sensors import Position, RangeBearing
from trackkit.tracking.association import (
    JPDA_MAX_EVENTS,
    distance_costs,
    gnn_assign,
    jpda_probabilities,
    loglik_costs,
    saturating_costs,
)
from trackkit.tracking.gating import (
    GATE_PROBABILITY,
    Gate,
    gate,
    gate_threshold,
    predict_measurement,
)
from trackkit.tracking.initiate import convert_range_bearing, single_point, two_point
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
    to_delete,
)

Array = NDArray[np.float64]
Index = NDArray[np.intp]

__all__ = ["GNN", "JPDA", "SinglePoint", "TwoPoint", "Tracks", "StepInfo", "Tracker"]

_NO_PAIR = 1e300  # the cost of a pair of plots too far apart to be one target
_FIRST_ORDER = (KF, EKF)  # filters whose zhat and S are h(x-) and H P H^T + R


# --- the strategies -----------------------------------------------------------------------


@dataclass(frozen=True)
class GNN:
    """Global nearest neighbour: the least-cost assignment, per cluster of tracks that share
    gated detections. ``cost``: "loglik" (negative log-likelihood ratio against clutter and
    a miss: the most probable joint event), "distance" (the Mahalanobis distance d, a miss
    costing ``missed_distance`` M, as Stone Soup's ``DistanceHypothesiser``) or
    "saturating" (``K1 (1 - exp(-K2 d^2))``, Jalalipoor and Kardehi Moghaddam 2021).

    With the distance cost and no ``missed_distance`` the miss costs the gate's edge
    sqrt(gamma), gamma = chi2.ppf(P_G, m). With ``missed_distance`` M the gate is M instead
    (``d^2 <= M^2``; the tracker's ``p_gate`` then plays no part): a pair at d < M costs
    less than a miss. M = 10 in two dimensions would need P_G = 1 - 2e-22, which is 1.0 in
    floating point."""

    cost: Literal["loglik", "distance", "saturating"] = "loglik"
    k1: float = 1.0
    k2: float = 0.5
    missed_distance: float | None = None

    def __post_init__(self) -> None:
        if self.cost == "seed004":
            raise ValueError("GNN cost = 'seed004' is now spelled 'saturating'")
        if self.cost not in ("loglik", "distance", "saturating"):
            raise ValueError(f"GNN cost = {self.cost!r}; expected 'loglik', 'distance' or "
                             "'saturating'")
        md = self.missed_distance
        if md is None:
            return
        if self.cost != "distance":
            raise ValueError(f"GNN missed_distance = {md!r} applies to cost 'distance' only; "
                             f"got cost {self.cost!r}")
        if (isinstance(md, bool) or not isinstance(md, (int, float, np.floating, np.integer))
                or not (np.isfinite(md) and md > 0)):
            raise ValueError(f"GNN missed_distance = {md!r}; expected a finite Mahalanobis "
                             "distance > 0")


@dataclass(frozen=True)
class JPDA:
    """Joint probabilistic data association: exact joint events per cluster, loopy belief
    propagation past ``max_events`` (reported in ``StepInfo.approximated``). A track counts
    as hit when its detection probability ``1 - beta_0`` is at least ``hit`` (MATLAB's
    ``trackerJPDA`` HitMissThreshold, default 0.2); a detection with total association
    probability of at least ``claim`` does not start a new track. ``star=True`` is JPDA*
    (Blom and Bloem 2000): the exact enumeration drops the events less likely than a swap of
    two tracks' detections, against track coalescence (see :func:`jpda_probabilities`)."""

    max_events: int = JPDA_MAX_EVENTS
    hit: float = 0.2
    claim: float = 0.5
    star: bool = False

    def __post_init__(self) -> None:
        if not (isinstance(self.max_events, int) and self.max_events >= 1):
            raise ValueError(f"JPDA max_events = {self.max_events!r}; expected an int >= 1")
        if not 0.0 < self.claim <= 1.0:
            raise ValueError(f"JPDA claim = {self.claim!r}; expected 0 < claim <= 1")
        if not 0.0 < self.hit <= 1.0:
            raise ValueError(f"JPDA hit = {self.hit!r}; expected 0 < hit <= 1")


@dataclass(frozen=True)
class SinglePoint:
    """A tentative track at every unassigned plot: position from the plot (range-bearing
    plots by the unbiased conversion), velocity zero with ``v_std`` per axis."""

    v_std: float = 50.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.v_std) and self.v_std > 0):
            raise ValueError(f"SinglePoint v_std = {self.v_std!r}; expected a positive number")


@dataclass(frozen=True)
class TwoPoint:
    """A tentative track from two unassigned plots of consecutive scans within
    ``v_max * dt + margin + sigmas sqrt(tr(R_1 + R_2))`` of each other (two-point
    differencing; ``R_1``, ``R_2`` the plots' Cartesian covariances, so that the allowance
    for plot errors grows with range for range-bearing plots); a plot that pairs with none
    waits one scan for a partner."""

    v_max: float = 300.0
    margin: float = 0.0
    sigmas: float = 0.0
    #: the new track's logic counts both plots (else only the second): a second hit whose
    #: likelihood is that of a plot uniform over the pair's disc of reach rho, ``1 / (pi
    #: rho^2)`` per m^2 (times the range for range-bearing plots, per m rad)
    both_plots: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.v_max) and self.v_max > 0):
            raise ValueError(f"TwoPoint v_max = {self.v_max!r}; expected a positive number")
        if not (np.isfinite(self.margin) and self.margin >= 0):
            raise ValueError(f"TwoPoint margin = {self.margin!r}; expected a number >= 0")
        if not (np.isfinite(self.sigmas) and self.sigmas >= 0):
            raise ValueError(f"TwoPoint sigmas = {self.sigmas!r}; expected a number >= 0")


# --- what the tracker carries -------------------------------------------------------------


class StepInfo(NamedTuple):
    """What happened in the last scan: the gated pairs, which tracks were hit, JPDA's
    clusters and those whose marginals were approximated (0 for GNN), tracks started and
    deleted (their IDs)."""

    pairs: int
    hit: NDArray[np.bool_]
    clusters: int
    approximated: int
    started: NDArray[np.int64]
    deleted: NDArray[np.int64]


class Tracks(NamedTuple):
    """Every live track, batched: ``belief`` (the filter's belief, axis 0 = track), stable
    ``ids``, the logic's ``state``, ``born`` (time of the first plot), the ``time`` of the
    beliefs, the ID ``counter``, the plots waiting for a partner (two-point initiation) and
    the last scan's ``info``."""

    belief: Any
    ids: NDArray[np.int64]
    state: HistoryState | ScoreState
    born: Array
    time: float
    counter: IdCounter
    waiting: tuple[Array, Array, float]  # (z (K, d), R (K, d, d), time) Cartesian plots
    info: StepInfo | None = None

    @property
    def confirmed(self) -> NDArray[np.bool_]:
        return confirmed(self.state)

    def __len__(self) -> int:  # the number of tracks, not of fields
        return int(self.ids.shape[0])


def _take(belief: Any, index: Index) -> Any:
    """Rows ``index`` of a batched belief (any NamedTuple of arrays with axis 0 = track)."""
    return type(belief)._make(np.asarray(a)[index] for a in belief)


def _join(a: Any, b: Any) -> Any:
    return type(a)._make(np.concatenate([x, y]) for x, y in zip(a, b, strict=True))


def _held_pairs(g: Gate, held_: NDArray[np.bool_], wide: NDArray[np.bool_]) -> Gate:
    """The gate with a held (lost, unseen) track's pairs only where no other track gates the
    plot, and none at all for a ``wide`` held track: a plot a seen track could explain is
    never given to one unseen for a while, and a held track whose position is no longer
    known to within ``Tracker.regain_within`` takes no plot (one in its grown gate is as
    likely another object's; the object found again starts a new track, which
    ``Tracker._rejoin`` tests against the held ones)."""
    if not held_.any():
        return g
    by_held = held_[g.track]
    near_seen = np.zeros(g.n_dets, dtype=bool)
    near_seen[g.det[~by_held]] = True
    keep = ~(by_held & (near_seen[g.det] | wide[g.track]))
    return g.take(keep)


# --- the tracker ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Tracker:
    """``Tracker(filter, motion, sensor, ...)``; ``tracks = tracker.step(tracks, scan)``.

    ``sensor`` is the sensor model of every scan, or a mapping from a scan's sensor id to its
    model. ``pd`` and ``clutter_density`` (false plots per unit of measurement space per
    scan) set the association's likelihood ratios and the score logic; ``p_gate`` the gate.
    The state is ``[x, y, vx, vy]`` with any extras after (e.g. a turn rate), which new tracks
    get with ``extra_mean`` and ``extra_std``. With a score logic that holds lost tracks
    (``ScoreLogic.hold_threshold``), a newly confirmed track within ``rejoin_within`` (m) of
    a held one continues it under its ID (``_rejoin``), and a held track whose position std
    is still within ``regain_within`` (m; 0: never) takes plots no other track gates, shown
    again once its score is back within the logic's deletion threshold of its maximum.
    """

    filter: Any
    motion: Any
    sensor: Any
    pd: float = 0.9
    clutter_density: float = 1e-6
    p_gate: float = GATE_PROBABILITY
    associator: GNN | JPDA = field(default_factory=GNN)
    logic: HistoryLogic | ScoreLogic = field(default_factory=HistoryLogic)
    initiator: SinglePoint | TwoPoint = field(default_factory=SinglePoint)
    extra_mean: tuple[float, ...] = ()
    extra_std: tuple[float, ...] = ()
    rejoin_within: float = np.inf
    regain_within: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 < self.pd <= 1.0:
            raise ValueError(f"Tracker pd = {self.pd!r}; expected 0 < pd <= 1")
        if not (np.isfinite(self.clutter_density) and self.clutter_density > 0):
            raise ValueError(f"Tracker clutter_density = {self.clutter_density!r}; expected a "
                             "positive density (false plots per unit volume per scan)")
        if not 0.0 < self.p_gate < 1.0:
            raise ValueError(f"Tracker p_gate = {self.p_gate!r}; expected 0 < P_G < 1")
        if len(self.extra_mean) != len(self.extra_std):
            raise ValueError(f"Tracker extra_mean has {len(self.extra_mean)} values and "
                             f"extra_std {len(self.extra_std)}; expected one each per extra")

    # -- the pieces ------------------------------------------------------------------------

    def sensor_for(self, scan: Scan) -> Any:
        if isinstance(self.sensor, dict):
            if scan.sensor not in self.sensor:
                raise ValueError(f"scan at t = {scan.time} is from sensor {scan.sensor}; the "
                                 f"tracker knows sensors {sorted(self.sensor)}")
            return self.sensor[scan.sensor]
        return self.sensor

    @property
    def extra_names(self) -> tuple[str, ...]:
        """The names of the state's extras: those the motion model (or the IMM's models, by
        their state maps) gives its state, else ``state_4, state_5 ...``."""
        n = 4 + len(self.extra_mean)
        names = {k: f"state_{k}" for k in range(4, n)}
        if self.motion is not None:
            models, maps = [self.motion], [np.arange(getattr(self.motion, "dim_x", n))]
        else:
            models = list(getattr(self.filter, "models", ()))
            maps = list(getattr(self.filter, "state_maps", ()))
        for model, where in zip(models, maps, strict=False):
            own = getattr(model, "state_names", None) or ()
            names.update({int(k): name for k, name in zip(where, own, strict=False) if 4 <= k < n})
        return tuple(names[k] for k in range(4, n))

    def init(self, time: float = 0.0) -> Tracks:
        """No tracks yet, at ``time``."""
        n = 4 + len(self.extra_mean)
        empty = Gaussian._make((np.zeros((0, n)), np.zeros((0, n, n))))
        belief = self.filter.init(empty) if hasattr(self.filter, "init") else empty
        return Tracks(belief, np.zeros(0, np.int64), self.logic.init(0), np.zeros(0),
                      float(time), IdCounter(), (np.zeros((0, 2)), np.zeros((0, 2, 2)),
                                                 float(time)))

    def estimate(self, belief: Any) -> Gaussian:
        """The Gaussian of a belief (the filter's estimate for filters with memory)."""
        return self.filter.estimate(belief) if hasattr(self.filter, "estimate") else belief

    def measurement_prediction(self, belief: Any, sensor: Any) -> tuple[Array, Array]:
        """``zhat (T, m)`` and ``S (T, m, m)`` of the filter: its update at ``z0 = h(x-)``
        gives the residual ``z0 - zhat`` and S. For the first-order KF and EKF that is
        ``h(x-)`` and ``H P H^T + R``, computed directly (no update)."""
        if type(self.filter) in _FIRST_ORDER and getattr(self.filter, "order", 1) == 1:
            mp = predict_measurement(belief, sensor)
            return mp.zhat, mp.S
        fast = getattr(self.filter, "measurement_prediction", None)
        out = None if fast is None else fast(belief, sensor)
        if out is not None:  # the filter's own, without an update (the IMM's)
            return out
        z0 = np.asarray(sensor.h(self.estimate(belief).mean), dtype=float)
        _, innov = self.filter.update(belief, z0, sensor)
        zhat = z0 - innov.nu
        ang = np.asarray(getattr(sensor, "angular", (False,) * z0.shape[-1]))
        if ang.any():
            zhat[:, ang] = wrap(zhat[:, ang])
        return zhat, np.asarray(innov.cov, dtype=float)

    def _plots(self, z: Array, sensor: Any) -> tuple[Array, Array]:
        """Cartesian positions and covariances of plots, for initiation."""
        if isinstance(sensor, RangeBearing):
            return convert_range_bearing(z, sensor)
        if isinstance(sensor, Position) and sensor.dim_z == 2:
            return z, np.broadcast_to(np.asarray(sensor.noise), (len(z), 2, 2))
        raise ValueError(f"tracks start from plots of a RangeBearing or 2-D Position sensor; "
                         f"got {type(sensor).__name__}")

    def _new_beliefs(self, g: Gaussian) -> Any:
        """The initiator's [x, y, vx, vy] Gaussians with the extras appended."""
        k = g.mean.shape[0]
        e = len(self.extra_mean)
        if e:
            mean = np.concatenate([g.mean, np.tile(self.extra_mean, (k, 1))], axis=1)
            cov = np.zeros((k, 4 + e, 4 + e))
            cov[:, :4, :4] = g.cov
            cov[:, 4:, 4:] = np.diag(np.square(self.extra_std))
            g = Gaussian._make((mean, cov))
        return self.filter.init(g) if hasattr(self.filter, "init") else g

    # -- one scan --------------------------------------------------------------------------

    def step(self, tracks: Tracks, scan: Scan) -> Tracks:
        """Predict, gate, associate, update, run the logic and start tracks, for one scan."""
        sensor = self.sensor_for(scan)
        z = np.asarray(scan.z, dtype=float).reshape(-1, sensor.dim_z)
        dt = float(scan.time) - tracks.time
        if dt < 0:
            raise ValueError(f"scan at t = {scan.time} is earlier than the tracks (t = "
                             f"{tracks.time}); expected scans in time order")
        T, D = len(tracks), z.shape[0]
        claimed = np.zeros(D, dtype=bool)
        info = dict(pairs=0, clusters=0, approximated=0)
        belief, state = tracks.belief, tracks.state
        hit = np.zeros(T, dtype=bool)
        if T:
            belief = self.filter.predict(belief, self.motion, dt)
            zhat, S = self.measurement_prediction(belief, sensor)
            g = gate(zhat, S, z, self.p_gate, angular=getattr(sensor, "angular", None),
                     threshold=self._gate_threshold())
            held_ = held(state)
            g = _held_pairs(g, held_, self._wide(belief, held_))
            info["pairs"] = g.size
            if isinstance(self.associator, JPDA):
                belief, hit, ll, claimed = self._jpda(belief, g, z, sensor, info)
            else:
                belief, hit, ll, claimed = self._gnn(belief, g, z, sensor, info)
            state = (self.logic.step(state, hit, ll) if isinstance(self.logic, ScoreLogic)
                     else self.logic.step(state, hit))
        ids, born = tracks.ids.copy(), tracks.born.copy()
        if T:
            state, rejoined = self._rejoin(belief, tracks.state, state, ids, born)
        # delete, then start tracks from the plots no track claimed
        keep = ~to_delete(state)
        deleted = np.setdiff1d(tracks.ids[~keep], rejoined) if T else tracks.ids[~keep]
        belief, state = _take(belief, np.flatnonzero(keep)), select(state, keep)
        ids, born = ids[keep], born[keep]
        new, waiting, second = self._initiate(z[~claimed], sensor, float(scan.time),
                                              tracks.waiting)
        counter = tracks.counter
        started = np.zeros(0, np.int64)
        if new is not None:
            k = new.mean.shape[0]
            started, counter = counter.issue(k)
            belief = _join(belief, self._new_beliefs(new))
            state = concatenate(state, self._born(k, second))
            ids = np.concatenate([ids, started])
            born = np.concatenate([born, np.full(k, float(scan.time))])
        step_info = StepInfo(info["pairs"], hit, info["clusters"], info["approximated"],
                             started, deleted)
        if isinstance(getattr(belief, "cov", None), np.ndarray):
            # gathered, mixed and initiated rows are covariances of the filter's making (or
            # PSD by construction): spare the next predict its full check of a user's input
            register(belief.cov)
        return Tracks(belief, ids, state, born, float(scan.time), counter, waiting, step_info)

    def _wide(self, belief: Any, held_: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The held tracks whose position std ``sqrt(P_xx + P_yy)`` exceeds
        ``regain_within`` (all of them when it is 0)."""
        wide = held_.copy()
        if held_.any() and self.regain_within > 0:
            P = np.asarray(self.estimate(_take(belief, np.flatnonzero(held_))).cov)
            wide[held_] = np.sqrt(P[:, 0, 0] + P[:, 1, 1]) > self.regain_within
        return wide

    def _rejoin(self, belief: Any, before: Any, state: Any, ids: NDArray[np.int64],
                born: Array) -> tuple[Any, NDArray[np.int64]]:
        """Track segment association: each track confirmed at this scan is tested against
        the held tracks, both at the scan's time, on ``[x, y, vx, vy]``:

            d2 = (x_new - x_held)^T (P_new + P_held)^-1 (x_new - x_held) <= chi2(P_G, 4)

        with the positions no farther apart than ``rejoin_within`` (a held track's covariance
        grows without bound while it is unseen, so the test alone would join it to any new
        track in a wide area); the pairs of least ``d2 + ln det(P_new + P_held)`` (twice
        the negative log likelihood of one object) are joined: the new track takes the held
        track's ID and birth (``ids``, ``born`` in place), the held track is deleted. An
        object lost and found again keeps its identity."""
        fresh = np.flatnonzero(confirmed(state) & ~confirmed(before) & ~held(before))
        lost = np.flatnonzero(held(state))
        if fresh.size == 0 or lost.size == 0:
            return state, np.zeros(0, np.int64)
        g = self.estimate(_take(belief, np.concatenate([fresh, lost])))
        x, P = np.asarray(g.mean)[:, :4], np.asarray(g.cov)[:, :4, :4]
        f = fresh.size
        dx = x[:f, None] - x[None, f:]
        C = P[:f, None] + P[None, f:]
        d2 = np.einsum("abi,abi->ab", dx, np.linalg.solve(C, dx[..., None])[..., 0])
        near = np.hypot(dx[..., 0], dx[..., 1]) <= self.rejoin_within
        cost = np.where(near & (d2 <= gate_threshold(self.p_gate, 4)),
                        d2 + np.linalg.slogdet(C)[1], np.inf)
        i, j = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e300))
        ok = np.isfinite(cost[i, j])
        a, b = fresh[i[ok]], lost[j[ok]]
        ids[a], born[a] = ids[b], born[b]
        status = np.asarray(state.status).copy()
        status[b] = TrackStatus.DELETED
        return state._replace(status=status), ids[a].copy()

    def _gate_threshold(self) -> float | None:
        """gamma of the gate: the GNN's missed distance squared, or None (from p_gate)."""
        md = getattr(self.associator, "missed_distance", None)
        return None if md is None else float(md) ** 2

    def _gnn(self, belief: Any, g: Gate, z: Array, sensor: Any, info: dict):
        a = self.associator
        if a.cost == "loglik":
            costs = loglik_costs(g, self.pd, self.clutter_density, self.p_gate)
        elif a.cost == "distance":
            costs = distance_costs(g, a.missed_distance)
        else:
            costs = saturating_costs(g, a.k1, a.k2)
        assignment = gnn_assign(g, costs)
        hit = assignment.det >= 0
        z_assigned = np.full((g.n_tracks, z.shape[1]), np.nan)
        z_assigned[hit] = z[assignment.det[hit]]
        belief, _ = self.filter.update(belief, z_assigned, sensor)
        claimed = np.zeros(z.shape[0], dtype=bool)
        claimed[assignment.det[hit]] = True
        # the score logic's hit term: ln N(z_j; zhat_i, S_i) of the assigned pair
        ll = np.zeros(g.n_tracks)
        key = g.track * z.shape[0] + g.det
        rows = np.flatnonzero(hit)
        ll[rows] = g.loglik[np.searchsorted(key, rows * z.shape[0] + assignment.det[rows])]
        return belief, hit, ll, claimed

    def _jpda(self, belief: Any, g: Gate, z: Array, sensor: Any, info: dict):
        a = self.associator
        r = jpda_probabilities(g, self.pd, self.clutter_density, self.p_gate,
                               max_events=a.max_events, star=a.star)
        info["clusters"], info["approximated"] = r.clusters.count, int(r.approximated.sum())
        merge = getattr(self.filter, "merge_hypotheses", None)
        if merge is not None:
            # a filter with its own combination of hypotheses (the IMM: per model, weights
            # beta_h mu_{j|h}), given the predicted belief and each gated pair's update
            if g.size:
                post, _ = self.filter.update(_take(belief, g.track), z[g.det], sensor)
                belief = merge(belief, post, g.track, r.beta0, r.beta)
            return belief, *self._jpda_outcome(g, r, z.shape[0])
        prior = self.estimate(belief)
        n = prior.mean.shape[1]
        if g.size:
            # every gated hypothesis (track i, detection j) updated as one batch
            post, _ = self.filter.update(_take(belief, g.track), z[g.det], sensor)
            xj, Pj = self.estimate(post)
        else:
            xj, Pj = np.zeros((0, n)), np.zeros((0, n, n))
        # the mixture beta_0 N(x-, P-) + sum_j beta_j N(x_j, P_j), moment-matched
        T = prior.mean.shape[0]
        x, P = moment_match(np.concatenate([r.beta0, r.beta]),
                            np.concatenate([prior.mean, xj]), np.concatenate([prior.cov, Pj]),
                            np.concatenate([np.arange(T), g.track]), T)
        mixed = Gaussian._make((x, P))
        belief = self.filter.init(mixed) if hasattr(self.filter, "init") else mixed
        return belief, *self._jpda_outcome(g, r, z.shape[0])

    def _jpda_outcome(self, g: Gate, r: Any, D: int):
        """Hits, the score logic's hit term and the plots claimed, from JPDA's marginals."""
        T = g.n_tracks
        hit = 1.0 - r.beta0 >= self.associator.hit
        claim = np.bincount(g.det, r.beta, minlength=D)
        # the score logic's hit term: ln N of the most probable gated detection
        best = np.full(T, -np.inf)
        np.maximum.at(best, g.track, r.beta)
        ll = np.zeros(T)
        top = r.beta == best[g.track]
        ll[g.track[top]] = g.loglik[top]
        return hit, ll, claim >= self.associator.claim

    def _born(self, k: int, second: Array | None) -> HistoryState | ScoreState:
        """The logic of ``k`` new tracks: born from one plot, or from two (``second``, the
        second plot's log-likelihood, ``TwoPoint.both_plots``)."""
        state = self.logic.init(k)
        if second is None:
            return state
        hit = np.ones(k, dtype=bool)
        if isinstance(self.logic, ScoreLogic):
            return self.logic.step(state, hit, second)
        return self.logic.step(state, hit)

    def _pairs(self, zw: Array, Rw: Array, tw: float, p: Array, R: Array, t: float):
        """``two_point`` on the waiting and the new plots, each pair within its own
        allowance for plot errors, ``sigmas sqrt(tr(R_1 + R_2))`` (``TwoPoint``)."""
        init = self.initiator
        if init.sigmas == 0:
            pairs, g = two_point(zw, Rw, tw, p, R, t, v_max=init.v_max, margin=init.margin)
            return pairs, g, np.full(pairs.shape[0], init.v_max * (t - tw) + init.margin)
        spread = (np.sqrt(np.trace(Rw, axis1=-2, axis2=-1)),
                  np.sqrt(np.trace(R, axis1=-2, axis2=-1)))
        widest = init.sigmas * np.hypot(spread[0].max(), spread[1].max())
        pairs, g = two_point(zw, Rw, tw, p, R, t, v_max=init.v_max,
                             margin=init.margin + widest)
        i, j = pairs[:, 0], pairs[:, 1]
        reach = (init.v_max * (t - tw) + init.margin
                 + init.sigmas * np.hypot(spread[0][i], spread[1][j]))
        keep = np.linalg.norm(p[j] - zw[i], axis=-1) <= reach
        return pairs[keep], Gaussian._make((g.mean[keep], g.cov[keep])), reach[keep]

    def _initiate(self, z: Array, sensor: Any, t: float, waiting):
        """New track beliefs ([x, y, vx, vy]) from the unclaimed plots, the plots left
        waiting for a partner (two-point) and, with ``TwoPoint.both_plots``, the second
        plot's log-likelihood per new track (else None)."""
        if z.shape[0] == 0 and not isinstance(self.initiator, TwoPoint):
            return None, waiting, None
        p, R = self._plots(z, sensor) if z.shape[0] else (np.zeros((0, 2)),
                                                            np.zeros((0, 2, 2)))
        if isinstance(self.initiator, SinglePoint):
            if p.shape[0] == 0:
                return None, waiting, None
            return single_point(p, R, v_std=self.initiator.v_std), waiting, None
        zw, Rw, tw = waiting
        left = (p, R, t)
        if zw.shape[0] == 0 or p.shape[0] == 0 or t <= tw:
            return None, left, None
        pairs, g, reach = self._pairs(zw, Rw, tw, p, R, t)
        if pairs.shape[0] == 0:
            return None, left, None
        # each plot starts at most one track: the pairing of least total speed
        cost = np.full((zw.shape[0], p.shape[0]), _NO_PAIR)
        cost[pairs[:, 0], pairs[:, 1]] = np.linalg.norm(g.mean[:, 2:4], axis=1)
        i, j = linear_sum_assignment(cost)
        ok = cost[i, j] < _NO_PAIR
        lookup = np.full(cost.shape, -1, np.intp)
        lookup[pairs[:, 0], pairs[:, 1]] = np.arange(pairs.shape[0])
        chosen = lookup[i[ok], j[ok]]
        rest = np.ones(p.shape[0], bool)
        rest[j[ok]] = False
        second = None
        if self.initiator.both_plots:
            # uniform over the disc: 1 / (pi rho^2) per m^2; per m rad, times the range
            ll = -np.log(np.pi * np.maximum(reach[chosen], 1e-9) ** 2)
            if isinstance(sensor, RangeBearing):
                ll = ll + np.log(np.maximum(z[j[ok]][:, 0], 1e-9))
            second = ll
        return (Gaussian._make((g.mean[chosen], g.cov[chosen])),
                (p[rest], R[rest], t), second)
