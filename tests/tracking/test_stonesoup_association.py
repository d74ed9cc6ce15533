"""Oracle: GNN and JPDA against Stone Soup on random scenes of 5-50 tracks with clutter.

Stone Soup gets trackkit's state ordering: tracks whose last state is the prior belief one
second before the scan, a ``LinearGaussianTimeInvariantTransitionModel`` built from
trackkit's CV F and Q, a ``KalmanPredictor``, ``LinearGaussian`` position measurements with
``mapping=(0, 1)`` and an ``ExtendedKalmanUpdater`` (``PDAUpdater`` for JPDA). trackkit
predicts the same beliefs with ``tk.filters.KF`` and gates with the same chi-square
threshold (Stone Soup's ``PDAHypothesiser`` keeps ``d2 <= chi2.ppf(P_G, m)``).

* GNN with a ``PDAHypothesiser``: Stone Soup's ``GNNWith2DAssignment`` maximises the sum of
  the per-track normalised PDA probabilities, so trackkit runs ``gnn_assign`` with ``pda_costs``.
* GNN with a ``DistanceHypothesiser`` (``Mahalanobis`` measure, ``missed_distance`` md):
  trackkit gates at md^2 and runs ``gnn_assign`` with ``distance_costs(g, md)``.
* JPDA: Stone Soup's ``JPDA`` enumerates the joint events of all the tracks it is given, so
  it is given one cluster at a time (clusters small enough for it); the posterior means and
  covariances of ``PDAUpdater`` are compared with ``jpda_probabilities`` + ``jpda_update`` to 1e-9.
"""

from __future__ import annotations

from datetime import datetime, timedelta

import numpy as np
import pytest
from stonesoup.dataassociator.neighbour import GlobalNearestNeighbour, GNNWith2DAssignment
from stonesoup.dataassociator.probability import JPDA, JPDAwithLBP
from stonesoup.hypothesiser.distance import DistanceHypothesiser
from stonesoup.hypothesiser.probability import PDAHypothesiser
from stonesoup.measures import Mahalanobis
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
from stonesoup.models.transition.linear import LinearGaussianTimeInvariantTransitionModel
from stonesoup.predictor.kalman import KalmanPredictor
from stonesoup.types.angle import Bearing
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track
from stonesoup.updater.kalman import ExtendedKalmanUpdater
from stonesoup.updater.probability import PDAUpdater

import trackkit as tk
from trackkit.tracking import GNN
from trackkit.tracking.association import (
    clusters,
    distance_costs,
    gnn_assign,
    jpda_probabilities,
    pda_costs,
)
from trackkit.tracking.gating import gate, gate_threshold, predict_measurement

from .pdaf import jpda_update
from .scenes import scene, scene_range_bearing

T0 = datetime(2025, 1, 1)
P_G = 0.99
RTOL = 1e-9


def _stonesoup(sc, updater_cls=ExtendedKalmanUpdater):
    """Tracks, detections, predictor and updater for a scene."""
    x0 = np.zeros(4)
    F = sc.motion.jacobian(x0, 1.0)
    Q = sc.motion.noise(x0, 1.0)
    tm = LinearGaussianTimeInvariantTransitionModel(transition_matrix=F, covariance_matrix=Q)
    if isinstance(sc.sensor, tk.models.RangeBearing):
        # Stone Soup measures [bearing, range], bearings as its Bearing type (wrapped)
        R = np.asarray(sc.sensor.noise)[::-1, ::-1]
        mm = CartesianToBearingRange(ndim_state=4, mapping=(0, 1), noise_covar=R)
        zs = [StateVector([Bearing(z[1]), z[0]]) for z in sc.z]
    else:
        mm = LinearGaussian(ndim_state=4, mapping=(0, 1), noise_covar=np.asarray(sc.sensor.noise))
        zs = [StateVector(z) for z in sc.z]
    tracks = [
        Track([GaussianState(StateVector(m), CovarianceMatrix(P), timestamp=T0)])
        for m, P in zip(sc.prior.mean, sc.prior.cov, strict=True)
    ]
    t1 = T0 + timedelta(seconds=1)
    dets = [Detection(z, timestamp=t1, measurement_model=mm) for z in zs]
    return tracks, dets, KalmanPredictor(tm), updater_cls(mm), t1


def _assignment_ss(assoc, tracks, dets, t1):
    index = {id(d): j for j, d in enumerate(dets)}
    hyps = assoc.associate(set(tracks), set(dets), t1)
    return np.array([index[id(hyps[t].measurement)] if hyps[t] else -1 for t in tracks])


SCENES = [(seed, T) for seed, T in zip(range(10), (5, 8, 12, 16, 20, 25, 30, 35, 40, 50),
                                         strict=True)]


@pytest.mark.parametrize("seed,T", SCENES)
def test_gnn_pda_hypothesiser(seed, T):
    rng = np.random.default_rng(100 + seed)
    # dense enough that clusters of several tracks compete for detections
    sc = scene(rng, T, side=120.0 * np.sqrt(T), clutter=10.0 + T / 2)
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z, P_G)
    assert clusters(g).count < T  # the scene has shared detections
    ours = gnn_assign(g, pda_costs(g, sc.pd, sc.clutter_density, P_G)).det
    tracks, dets, pred, upd, t1 = _stonesoup(sc)
    hyp = PDAHypothesiser(pred, upd, clutter_spatial_density=sc.clutter_density,
                          prob_detect=sc.pd, prob_gate=P_G)
    theirs = _assignment_ss(GNNWith2DAssignment(hyp), tracks, dets, t1)
    np.testing.assert_array_equal(ours, theirs)


@pytest.mark.parametrize("seed,T", SCENES[::2])
def test_gnn_distance_hypothesiser(seed, T):
    rng = np.random.default_rng(200 + seed)
    sc = scene(rng, T, side=120.0 * np.sqrt(T), clutter=10.0 + T / 2)
    md = 3.5
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z, threshold=md**2)
    ours = gnn_assign(g, distance_costs(g, md)).det
    tracks, dets, pred, upd, t1 = _stonesoup(sc)
    hyp = DistanceHypothesiser(pred, upd, Mahalanobis(), missed_distance=md)
    theirs = _assignment_ss(GNNWith2DAssignment(hyp), tracks, dets, t1)
    np.testing.assert_array_equal(ours, theirs)


def _close(actual, expected, what):
    scale = np.max(np.abs(expected))
    err = np.max(np.abs(actual - expected))
    assert err <= RTOL * scale, f"{what}: max abs error {err:.3e} vs scale {scale:.3e}"


def _far_plots(sc, rng, lo: float, hi: float) -> np.ndarray:
    """The scene's plots and one more per track at a Mahalanobis distance in (lo, hi) of
    its predicted measurement (inside Stone Soup's missed distance, outside a 0.99 gate)."""
    mp = predict_measurement(sc.predicted, sc.sensor)
    u = rng.standard_normal((len(mp.zhat), 2))
    u *= rng.uniform(lo, hi, (len(u), 1)) / np.linalg.norm(u, axis=1, keepdims=True)
    far = mp.zhat + (np.linalg.cholesky(mp.S) @ u[..., None])[..., 0]
    return np.concatenate([sc.z, far])


@pytest.mark.parametrize("seed", range(3))
def test_tracker_distance_cost_with_missed_distance_10_is_stonesoups_gnn(seed):
    """``Tracker`` with ``GNN(cost="distance", missed_distance=10)`` takes the pairs of Stone
    Soup's ``GlobalNearestNeighbour`` (exhaustive joint hypotheses) with a
    ``DistanceHypothesiser(Mahalanobis(), missed_distance=10)``: the same tracks hit and the
    same posteriors. The scene has a pair chosen at 5 < d < 10, which the gate's edge
    (sqrt(chi2.ppf(0.99, 2)) = 3.03, the miss cost without missed_distance) refuses."""
    md = 10.0
    rng = np.random.default_rng(600 + seed)
    sc = scene(rng, 6, side=600.0, clutter=3.0, pos_std=(5.0, 15.0), pd=0.5)
    sc = sc._replace(z=_far_plots(sc, rng, 5.0, 9.5))
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z, threshold=md**2)
    assert np.bincount(g.det).max() >= 2  # tracks compete for a plot
    tracks, dets, pred, upd, t1 = _stonesoup(sc)
    hyp = DistanceHypothesiser(pred, upd, Mahalanobis(), missed_distance=md)
    chosen = GlobalNearestNeighbour(hyp).associate(set(tracks), set(dets), t1)

    def step(associator):
        trk = tk.tracking.Tracker(tk.filters.KF(), sc.motion, sc.sensor, p_gate=P_G,
                                  associator=associator,
                                  logic=tk.tracking.HistoryLogic(confirm=(1, 1)))
        T = len(tracks)
        live = tk.tracking.Tracks(sc.prior, np.arange(T), trk.logic.init(T), np.zeros(T),
                                  0.0, tk.tracking.IdCounter(T),
                                  (np.zeros((0, 2)), np.zeros((0, 2, 2)), 0.0))
        return trk.step(live, tk.io.Scan(1.0, 0, sc.z))

    out = step(GNN(cost="distance", missed_distance=md))
    hit = np.array([bool(chosen[t]) for t in tracks])
    np.testing.assert_array_equal(out.info.hit, hit)
    assert (out.ids[:len(tracks)] == np.arange(len(tracks))).all()  # none deleted
    far = []
    for i, t in enumerate(tracks):
        h = chosen[t]
        ref = upd.update(h) if h else h.prediction
        _close(out.belief.mean[i], np.asarray(ref.state_vector, dtype=float)[:, 0], f"mean {i}")
        _close(out.belief.cov[i], np.asarray(ref.covar, dtype=float), f"cov {i}")
        if h:
            far.append(h.distance)
    assert 5.0 < max(far) < md
    # the gate's edge as the miss cost refuses that pair: another outcome
    old = step(GNN(cost="distance"))
    assert not np.array_equal(old.info.hit, hit) or not np.allclose(
        old.belief.mean[:len(tracks)], out.belief.mean[:len(tracks)])


@pytest.mark.parametrize("seed,T", [(0, 10), (1, 25), (2, 50)])
def test_jpda_pda_updater(seed, T):
    rng = np.random.default_rng(300 + seed)
    sc = scene(rng, T, side=150.0 * np.sqrt(T), clutter=10.0 + T / 2, pos_std=(5.0, 25.0))
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z, P_G)
    res = jpda_probabilities(g, sc.pd, sc.clutter_density, P_G)
    assert not res.approximated.any()
    post = jpda_update(sc.predicted, mp.K, mp.S, g.track, g.nu, res.beta, res.beta0)

    tracks, dets, pred, upd, t1 = _stonesoup(sc, PDAUpdater)
    hyp = PDAHypothesiser(pred, upd, clutter_spatial_density=sc.clutter_density,
                          prob_detect=sc.pd, prob_gate=P_G)
    assoc = JPDA(hyp)
    cl = res.clusters
    ntr = np.bincount(cl.track, minlength=cl.count)
    compared = multi = 0
    for k in range(cl.count):
        members = np.flatnonzero(cl.track == k)
        cdets = [dets[j] for j in np.flatnonzero(cl.det == k)]
        # Stone Soup enumerates the product of every member's options, filtered afterwards
        options = np.bincount(g.track, minlength=T)[members] + 1
        if np.prod(options) > 5000:
            continue
        hyps = assoc.associate({tracks[i] for i in members}, set(cdets), t1)
        for i in members:
            u = upd.update(hyps[tracks[i]])
            _close(post.mean[i], np.asarray(u.state_vector, dtype=float)[:, 0], f"mean {i}")
            _close(post.cov[i], np.asarray(u.covar, dtype=float), f"cov {i}")
            compared += 1
        multi += ntr[k] > 1
    assert compared >= T // 2 and multi >= 1


def _ss_measurement_prediction(tracks, pred, upd, t1):
    """Stone Soup's own zhat, S and K per track, in trackkit's [range, bearing] order.

    Stone Soup's ``CartesianToBearingRange`` has no analytic Jacobian: its EKF differentiates
    numerically, which moves H by ~1e-8 relative. The range-bearing oracle therefore feeds
    Stone Soup's linearisation to trackkit, so that it compares the association and the
    update, not two Jacobians.
    """
    zhat, S, K = [], [], []
    for tr in tracks:
        mp = upd.predict_measurement(pred.predict(tr, timestamp=t1))
        Sv = np.asarray(mp.covar, dtype=float)
        C = np.asarray(mp.cross_covar, dtype=float)
        zv = np.asarray(mp.state_vector, dtype=float)[:, 0]
        zhat.append(zv[::-1])
        S.append(Sv[::-1, ::-1])
        K.append((C @ np.linalg.inv(Sv))[:, ::-1])
    return np.array(zhat), np.array(S), np.array(K)


@pytest.mark.parametrize("seed", range(3))
def test_range_bearing_across_the_cut(seed):
    """Bearings straddling +-pi (Stone Soup wraps them in its Bearing type): GNN assignment
    and JPDA posteriors agree, and some gated pairs do cross the cut."""
    rng = np.random.default_rng(400 + seed)
    T = 20
    sc = scene_range_bearing(rng, T)
    tracks, dets, pred, upd, t1 = _stonesoup(sc, PDAUpdater)
    zhat, S, K = _ss_measurement_prediction(tracks, pred, upd, t1)
    # the linearisations differ only by Stone Soup's numerical Jacobian (~1e-4 here)
    S_tk = predict_measurement(sc.predicted, sc.sensor).S
    sd = np.sqrt(np.diagonal(S_tk, axis1=1, axis2=2))
    assert np.all(np.abs(S - S_tk) <= 1e-3 * sd[:, :, None] * sd[:, None, :])
    g = gate(zhat, S, sc.z, P_G, angular=sc.sensor.angular)
    assert np.any(np.abs(sc.z[g.det, 1] - zhat[g.track, 1]) > np.pi)
    hyp = PDAHypothesiser(pred, upd, clutter_spatial_density=sc.clutter_density,
                          prob_detect=sc.pd, prob_gate=P_G)
    ours = gnn_assign(g, pda_costs(g, sc.pd, sc.clutter_density, P_G)).det
    np.testing.assert_array_equal(ours, _assignment_ss(GNNWith2DAssignment(hyp), tracks, dets, t1))

    res = jpda_probabilities(g, sc.pd, sc.clutter_density, P_G)
    post = jpda_update(sc.predicted, K, S, g.track, g.nu, res.beta, res.beta0)
    cl = res.clusters
    assoc = JPDA(hyp)
    for k in range(cl.count):
        members = np.flatnonzero(cl.track == k)
        if np.prod(np.bincount(g.track, minlength=T)[members] + 1) > 5000:
            continue
        cdets = {dets[j] for j in np.flatnonzero(cl.det == k)}
        hyps = assoc.associate({tracks[i] for i in members}, cdets, t1)
        for i in members:
            u = upd.update(hyps[tracks[i]])
            _close(post.mean[i], np.asarray(u.state_vector, dtype=float)[:, 0], f"mean {i}")
            _close(post.cov[i], np.asarray(u.covar, dtype=float), f"cov {i}")


@pytest.mark.parametrize("seed", range(4))
def test_lbp_matches_stonesoup(seed):
    """The fallback marginals (loopy belief propagation) against Stone Soup's
    ``JPDAwithLBP._loopy_belief_propagation`` run to a tight tolerance, on a dense scene's
    big cluster."""
    rng = np.random.default_rng(500 + seed)
    sc = scene(rng, 40, side=400.0, clutter=20.0)
    mp = predict_measurement(sc.predicted, sc.sensor)
    g = gate(mp.zhat, mp.S, sc.z, P_G)
    res = jpda_probabilities(g, sc.pd, sc.clutter_density, P_G, max_events=50)
    assert res.approximated.any()
    lr = np.log(sc.pd) + g.loglik - np.log(sc.clutter_density) - np.log1p(-sc.pd * P_G)
    W = np.zeros((g.n_tracks, g.n_dets + 1))
    W[:, 0] = 1.0
    W[g.track, g.det + 1] = np.exp(lr)
    approx = res.approximated[res.clusters.track]
    ss = JPDAwithLBP._loopy_belief_propagation(W[approx], 1, 1e-12)
    sel = approx[g.track]
    rows = np.cumsum(approx) - 1
    np.testing.assert_allclose(res.beta[sel], ss[rows[g.track[sel]], g.det[sel] + 1],
                               rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(res.beta0[approx], ss[:, 0], rtol=1e-9, atol=1e-12)


def test_gate_threshold_matches_stonesoup():
    assert gate_threshold(P_G, 2) == PDAHypothesiser._gate_threshold(P_G, 2)


def test_scene_prediction_matches_stonesoup():
    """The two sides predict the same beliefs (the premise of the tests above)."""
    sc = scene(np.random.default_rng(5), 5)
    tracks, dets, pred, upd, t1 = _stonesoup(sc)
    for i, tr in enumerate(tracks):
        p = pred.predict(tr, timestamp=t1)
        _close(sc.predicted.mean[i], np.asarray(p.state_vector, dtype=float)[:, 0], "mean")
        _close(sc.predicted.cov[i], np.asarray(p.covar, dtype=float), "cov")
    assert isinstance(sc.predicted, tk.Gaussian)
