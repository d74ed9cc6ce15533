"""The multi-target tracker: each stage of a scan against the kernels it strings together,
every core filter, stable IDs, one batched filter call per stage, bad input."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import trackkit as tk
import trackkit.tracking as tt
from trackkit.io.scans import Scan
from trackkit.tracking import (
    HistoryLogic,
    IdCounter,
    ScoreLogic,
    gate,
    gnn_assign,
    jpda_probabilities,
    loglik_costs,
    predict_measurement,
)
from trackkit.tracking.logic import held
from trackkit.tracking.tracker import GNN, JPDA, SinglePoint, Tracker, Tracks, TwoPoint

from .pdaf import jpda_update

CV = tk.models.ConstantVelocity(dim=2, q=0.05)
POS = tk.models.Position(dim=2, sigma=20.0)
RADAR = tk.models.RangeBearing(origin=[0.0, 0.0], sigma_range=30.0,
                               sigma_bearing=np.deg2rad(0.5))
FILTERS = {"KF": tk.filters.KF, "EKF": tk.filters.EKF, "UKF": tk.filters.UKF,
           "CKF": tk.filters.CKF}


def scene(n: int, scans: int, seed: int, sensor=RADAR, pd: float = 0.9,
          clutter: float = 10.0, dt: float = 2.0, spread: float = 15000.0):
    """Constant-velocity targets seen by ``sensor``; clutter uniform in measurement space
    (range 0-40 km and any bearing, or a square for a position sensor). Yields (truth, scan)."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, 4))
    x[:, :2] = rng.uniform(-spread, spread, (n, 2))
    x[:, 2:] = rng.normal(0.0, 10.0, (n, 2))
    sd = np.sqrt(np.diag(sensor.noise))
    for k in range(1, scans + 1):
        x[:, :2] += x[:, 2:] * dt
        zt = sensor.h(x) + rng.normal(size=(n, 2)) * sd
        zt = zt[rng.random(n) < pd]
        nc = rng.poisson(clutter)
        if isinstance(sensor, tk.models.RangeBearing):
            zc = np.stack([rng.uniform(0, 40000.0, nc), rng.uniform(-np.pi, np.pi, nc)], 1)
        else:
            zc = rng.uniform(-40000.0, 40000.0, (nc, 2))
        z = np.concatenate([zt, zc])
        yield x.copy(), Scan(k * dt, 0, z[rng.permutation(len(z))])


def density(sensor=RADAR, clutter: float = 10.0) -> float:
    volume = 40000.0 * 2 * np.pi if isinstance(sensor, tk.models.RangeBearing) else 80000.0**2
    return clutter / volume


def tracker(f="EKF", sensor=RADAR, **kw) -> Tracker:
    kw.setdefault("logic", HistoryLogic(confirm=(3, 4), delete=(3, 3)))
    kw.setdefault("initiator", SinglePoint(v_std=15.0))
    return Tracker(FILTERS[f](), CV, sensor, pd=0.9, clutter_density=density(sensor), **kw)


def some_tracks(trk: Tracker, seed: int = 3, n: int = 6) -> Tracks:
    """``n`` live tracks with varied beliefs at t = 0 (the filter's own covariances)."""
    rng = np.random.default_rng(seed)
    mean = np.zeros((n, 4))
    mean[:, :2] = rng.uniform(-3000, 3000, (n, 2))
    mean[:, 2:] = rng.normal(0, 10, (n, 2))
    cov = np.tile(np.diag([400.0, 400.0, 25.0, 25.0]), (n, 1, 1))
    b = trk.filter.predict(tk.Gaussian(mean, cov), CV, 0.0)
    return Tracks(b, np.arange(10, 10 + n), trk.logic.init(n), np.zeros(n), 0.0,
                  IdCounter(100), (np.zeros((0, 2)), np.zeros((0, 2, 2)), 0.0))


def plots_near(tracks: Tracks, sensor, seed: int, extra: int = 4) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = tracks.belief.mean.copy()
    x[:, :2] += x[:, 2:] * 2.0
    z = sensor.h(x) + rng.normal(size=(len(x), 2)) * np.sqrt(np.diag(sensor.noise)) * 2
    extra = min(extra, len(x))
    zc = sensor.h(x[:extra]) + rng.normal(size=(extra, 2)) * np.sqrt(np.diag(sensor.noise)) * 3
    return np.concatenate([z, zc])


# --- each stage against its kernel ----------------------------------------------------------


@pytest.mark.parametrize("f", ["KF", "EKF"])
def test_measurement_prediction_of_a_linearised_filter_is_h_and_hph_plus_r(f):
    sensor = POS if f == "KF" else RADAR
    trk = tracker(f, sensor)
    b = some_tracks(trk).belief
    zhat, S = trk.measurement_prediction(b, sensor)
    ref = predict_measurement(b, sensor)
    np.testing.assert_allclose(zhat, ref.zhat, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(S, ref.S, rtol=1e-12)


@pytest.mark.parametrize("f", ["UKF", "CKF"])
def test_measurement_prediction_of_a_sigma_point_filter_is_its_own(f):
    # the gate and the likelihood use the filter's own zhat and S: for the UKF the unscented
    # ones, checked against the innovation of an update with a real plot
    trk = tracker(f)
    b = some_tracks(trk).belief
    zhat, S = trk.measurement_prediction(b, RADAR)
    z = plots_near(some_tracks(trk), RADAR, seed=5, extra=0)
    _, innov = trk.filter.update(b, z, RADAR)
    np.testing.assert_allclose(innov.cov, S, rtol=1e-12)
    np.testing.assert_allclose(tk.angles.wrap(z - innov.nu - zhat), 0.0, atol=1e-9)
    # and it differs from the first-order prediction (the test would not see a mix-up)
    assert np.abs(S - predict_measurement(b, RADAR).S).max() > 1e-9 * np.abs(S).max()


def test_gnn_scan_equals_the_kernels_by_hand():
    trk = tracker("EKF", RADAR, associator=GNN())
    tracks = some_tracks(trk)
    z = plots_near(tracks, RADAR, seed=7)
    out = trk.step(tracks, Scan(2.0, 0, z))
    b = trk.filter.predict(tracks.belief, CV, 2.0)
    mp = predict_measurement(b, RADAR)
    g = gate(mp.zhat, mp.S, z, trk.p_gate, angular=RADAR.angular)
    a = gnn_assign(g, loglik_costs(g, trk.pd, trk.clutter_density, trk.p_gate))
    za = np.full((len(tracks), 2), np.nan)
    za[a.det >= 0] = z[a.det[a.det >= 0]]
    want, _ = trk.filter.update(b, za, RADAR)
    n = len(tracks)
    np.testing.assert_array_equal(out.ids[:n], tracks.ids)  # nobody deleted yet
    np.testing.assert_allclose(out.belief.mean[:n], want.mean, rtol=1e-12)
    np.testing.assert_allclose(out.belief.cov[:n], want.cov, rtol=1e-12)
    np.testing.assert_array_equal(out.info.hit, a.det >= 0)
    # the plots no track took start tentative tracks with new IDs, from 100 on
    assert len(out) == n + a.unassigned.size
    np.testing.assert_array_equal(out.ids[n:], 100 + np.arange(a.unassigned.size))


def test_jpda_scan_is_the_pdaf_update_of_the_kernel():
    # the tracker's JPDA moment-matches the filter's per-hypothesis updates; for a KF that is
    # exactly the PDAF/JPDA update (jpda_update, checked against Stone Soup's JPDA)
    trk = tracker("KF", POS, associator=JPDA())
    tracks = some_tracks(trk, n=8)
    tracks = tracks._replace(belief=tk.Gaussian(tracks.belief.mean * 0.2, tracks.belief.cov))
    z = plots_near(tracks, POS, seed=11, extra=6)
    out = trk.step(tracks, Scan(2.0, 0, z))
    b = trk.filter.predict(tracks.belief, CV, 2.0)
    mp = predict_measurement(b, POS)
    g = gate(mp.zhat, mp.S, z, trk.p_gate)
    r = jpda_probabilities(g, trk.pd, trk.clutter_density, trk.p_gate)
    assert np.any((r.beta > 0.05) & (r.beta < 0.95)), "the scene must have real ambiguity"
    want = jpda_update(b, mp.K, mp.S, g.track, g.nu, r.beta, r.beta0)
    n = len(tracks)
    np.testing.assert_allclose(out.belief.mean[:n], want.mean, rtol=1e-10)
    np.testing.assert_allclose(out.belief.cov[:n], want.cov, rtol=1e-9)


def test_one_batched_filter_call_per_stage_whatever_the_number_of_tracks():
    calls = {"predict": 0, "update": 0}

    class Counting(tk.filters.EKF):
        def predict(self, *a, **k):
            calls["predict"] += 1
            return super().predict(*a, **k)

        def update(self, *a, **k):
            calls["update"] += 1
            return super().update(*a, **k)

    for n in (3, 300):
        trk = Tracker(Counting(), CV, RADAR, pd=0.9, clutter_density=density())
        tracks = some_tracks(trk, n=n)
        calls.update(predict=0, update=0)
        trk.step(tracks, Scan(2.0, 0, plots_near(tracks, RADAR, seed=1)))
        assert calls == {"predict": 1, "update": 2}, (n, calls)


# --- whole runs -----------------------------------------------------------------------------


@pytest.mark.parametrize("f", list(FILTERS))
# M-of-N counts every hit alike, so for JPDA a hit here means "detected more likely than
# not"; the default (0.2, trackerJPDA's) suits the score logic, which weighs a hit by its
# likelihood (tests/statistical/test_tracking.py measures its false tracks)
@pytest.mark.parametrize("assoc", [GNN(), JPDA(hit=0.5)], ids=["GNN", "JPDA"])
def test_every_core_filter_tracks_spread_targets_in_clutter(f, assoc):
    sensor = POS if f == "KF" else RADAR
    trk = tracker(f, sensor, associator=assoc)
    tracks = trk.init()
    for x, scan in scene(8, 30, seed=4, sensor=sensor):
        tracks, truth = trk.step(tracks, scan), x
    est = tracks.belief.mean[tracks.confirmed]
    # every target has one confirmed track within 300 m, and there is no other
    d = np.linalg.norm(truth[:, None, :2] - est[None, :, :2], axis=-1)
    assert (d.min(1) < 300).all(), d.min(1)
    assert tracks.confirmed.sum() == 8


@pytest.mark.parametrize("init", [SinglePoint(v_std=15.0), TwoPoint(v_max=40.0, margin=300.0)],
                         ids=["single", "two-point"])
def test_ids_are_stable_and_never_reused(init):
    trk = tracker("EKF", RADAR, initiator=init)
    tracks = trk.init()
    seen, gone, owner = set(), set(), {}
    for truth, scan in scene(5, 40, seed=9, clutter=15.0):
        tracks = trk.step(tracks, scan)
        ids = set(tracks.ids.tolist())
        assert not ids & gone, "a deleted ID came back"
        assert len(ids) == len(tracks.ids)
        gone |= set(tracks.info.deleted.tolist())
        assert not set(tracks.info.started.tolist()) & seen
        seen |= ids
        for i, x in zip(tracks.ids[tracks.confirmed], tracks.belief.mean[tracks.confirmed],
                        strict=True):
            target = int(np.argmin(np.linalg.norm(truth[:, :2] - x[:2], axis=1)))
            owner.setdefault(int(i), target)
            assert owner[int(i)] == target, "a confirmed ID moved to another target"
    assert len({t for t in owner.values()}) == 5


def test_two_point_initiation_starts_with_the_velocity():
    trk = tracker("EKF", POS, initiator=TwoPoint(v_max=60.0, margin=100.0))
    tracks = trk.init()
    for x, scan in scene(3, 2, seed=2, sensor=POS, pd=1.0, clutter=0.0, spread=20000):
        tracks, truth = trk.step(tracks, scan), x
    assert len(tracks) == 3
    order = np.argsort(tracks.belief.mean[:, 0])
    v = tracks.belief.mean[order, 2:]
    vt = truth[np.argsort(truth[:, 0]), 2:]
    np.testing.assert_allclose(v, vt, atol=40.0)  # two 20 m plots, 2 s apart


def _two_scans(trk: Tracker, first, second):
    tracks = trk.step(trk.init(), Scan(0.0, 0, np.array(first, float)))
    return trk.step(tracks, Scan(2.0, 0, np.array(second, float)))


def test_two_point_sigmas_allow_for_each_pairs_plot_errors():
    """Range-bearing plots 5 km out (cross-range std 44 m) and 30 km out (262 m): a 400 m
    step in 2 s is beyond v_max dt = 40 m, within 3 sqrt(tr(R1 + R2)) only far out."""
    far, near = 30e3, 5e3
    first = [[near, 0.0], [far, 1.0]]
    second = [[near, 400.0 / near], [far, 1.0 + 400.0 / far]]
    plain = tracker("EKF", RADAR, initiator=TwoPoint(v_max=20.0))
    assert len(_two_scans(plain, first, second)) == 0
    wide = tracker("EKF", RADAR, initiator=TwoPoint(v_max=20.0, sigmas=3.0))
    tracks = _two_scans(wide, first, second)
    assert len(tracks) == 1
    assert np.hypot(*tracks.belief.mean[0, :2]) > 20e3  # the far pair, not the near one
    with pytest.raises(ValueError, match="TwoPoint sigmas = -1.0"):
        TwoPoint(sigmas=-1.0)


def test_two_point_both_plots_scores_the_second_plot():
    """Born from two plots, a track's score is L_1 plus the second plot's hit, its
    likelihood that of a plot uniform over the pair's disc (1 / (pi rho^2) per m^2); the
    M-of-N history has two hits."""
    lam = density(POS)
    logic = ScoreLogic(pd=0.9, clutter_density=lam, new_target_density=lam / 100)
    init = TwoPoint(v_max=30.0, margin=40.0, both_plots=True)
    tracks = _two_scans(tracker("EKF", POS, logic=logic, initiator=init),
                        [[0.0, 0.0]], [[50.0, 0.0]])
    rho = 30.0 * 2.0 + 40.0
    want = (logic.initial_score + np.log(0.9) - np.log(lam) - np.log(np.pi * rho**2))
    np.testing.assert_allclose(tracks.state.score, [want], rtol=1e-12)
    history = _two_scans(tracker("EKF", POS, initiator=init), [[0.0, 0.0]], [[50.0, 0.0]])
    assert history.state.age.tolist() == [2] and history.state.history.tolist() == [3]
    one = _two_scans(tracker("EKF", POS, initiator=replace(init, both_plots=False)),
                     [[0.0, 0.0]], [[50.0, 0.0]])
    assert one.state.age.tolist() == [1]


def test_score_logic_confirms_and_deletes():
    logic = ScoreLogic.from_sprt(alpha=1e-5, beta=1e-3, pd=0.9, clutter_density=density(),
                                 new_target_density=1e-9)
    trk = tracker("EKF", RADAR, logic=logic)
    tracks = trk.init()
    for _, scan in scene(4, 20, seed=6):
        tracks = trk.step(tracks, scan)
    assert tracks.confirmed.sum() == 4
    # the targets vanish: their tracks are deleted within a few scans
    for k in range(10):
        tracks = trk.step(tracks, Scan(42.0 + 2 * k, 0, np.zeros((0, 2))))
    assert len(tracks) == 0


# --- bad input ------------------------------------------------------------------------------


def test_bad_input_is_named():
    trk = tracker()
    tracks = trk.step(trk.init(), Scan(5.0, 0, np.array([[1000.0, 0.1]])))
    with pytest.raises(ValueError, match=r"t = 4\.0 is earlier than the tracks"):
        trk.step(tracks, Scan(4.0, 0, np.zeros((0, 2))))
    multi = Tracker(tk.filters.EKF(), CV, {0: RADAR}, clutter_density=1e-6)
    with pytest.raises(ValueError, match="sensor 3"):
        multi.step(multi.init(), Scan(1.0, 3, np.zeros((0, 2))))
    bearing = Tracker(tk.filters.EKF(), CV, tk.models.Bearing(sigma=0.01), clutter_density=1.0)
    with pytest.raises(ValueError, match="RangeBearing or 2-D Position"):
        bearing.step(bearing.init(), Scan(1.0, 0, np.array([[0.3]])))
    for kw, word in [({"pd": 0.0}, "pd"), ({"clutter_density": 0.0}, "clutter_density"),
                     ({"p_gate": 1.0}, "p_gate"), ({"extra_mean": (0.0,)}, "extra")]:
        with pytest.raises(ValueError, match=word):
            Tracker(tk.filters.EKF(), CV, RADAR, **kw)
    with pytest.raises(ValueError, match="cost"):
        GNN(cost="nearest")
    with pytest.raises(ValueError, match="GNN cost = 'seed004' is now spelled 'saturating'"):
        GNN(cost="seed004")
    assert GNN(cost="saturating").cost == "saturating"
    for old, new in [("gnn", "gnn_assign"), ("jpda", "jpda_probabilities"),
                     ("seed004_costs", "saturating_costs")]:
        with pytest.raises(AttributeError, match=f"tracking.{old} is now spelled {new}"):
            getattr(tt, old)
    for md in (0.0, -1.0, float("inf"), float("nan"), "10", True):
        with pytest.raises(ValueError, match=r"GNN missed_distance = .*expected a finite"):
            GNN(cost="distance", missed_distance=md)
    with pytest.raises(ValueError, match="missed_distance = 10.0 applies to cost 'distance' "
                       "only; got cost 'loglik'"):
        GNN(missed_distance=10.0)
    with pytest.raises(ValueError, match="v_max"):
        TwoPoint(v_max=-1.0)


# --- held tracks and track segment association -----------------------------------------------


def _gap_scene(seed: int, jump: float = 0.0, gap: int = 15):
    """Four constant-velocity targets seen for 30 scans, unseen for ``gap`` (no plot of them:
    a reporting gap), then seen again to scan 80; the last target comes back ``jump`` metres
    off its course. Plots at pd 0.9 among 10 false plots a scan. Yields scans."""
    rng = np.random.default_rng(seed)
    x = np.zeros((4, 4))
    x[:, :2] = rng.uniform(-5000, 5000, (4, 2))
    x[:, 2:] = rng.normal(0.0, 5.0, (4, 2))
    sd = np.sqrt(np.diag(RADAR.noise))
    for k in range(1, 81):
        x[:, :2] += x[:, 2:] * 2.0
        if k == 31 + gap:
            x[3, 0] += jump
        seen = (k <= 30) | (k > 30 + gap)
        zt = RADAR.h(x) + rng.normal(size=(4, 2)) * sd
        zt = zt[(rng.random(4) < 0.9) & seen]
        nc = rng.poisson(10.0)
        zc = np.stack([rng.uniform(0, 40000.0, nc), rng.uniform(-np.pi, np.pi, nc)], 1)
        yield Scan(k * 2.0, 0, np.concatenate([zt, zc]))


def _held_tracker(hold_scans: int | None, rejoin: float = 1000.0,
                  regain: float = 0.0) -> Tracker:
    logic = ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=0.9, clutter_density=density(),
                                 new_target_density=density() / 100)
    if hold_scans is not None:
        logic = replace(logic, hold_threshold=logic.delete_threshold
                        + hold_scans * np.log(0.1))
    return tracker("EKF", RADAR, logic=logic, initiator=TwoPoint(v_max=20.0),
                   rejoin_within=rejoin, regain_within=regain)


def _confirmed_ids(trk: Tracker, scans) -> list[set[int]]:
    tracks, out = trk.init(), []
    for scan in scans:
        tracks = trk.step(tracks, scan)
        out.append(set(tracks.ids[tracks.confirmed].tolist()))
    return out


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_held_track_gives_its_id_to_the_new_track_that_continues_it(seed):
    """Lost in a 30 s gap, each target's track is held (not confirmed, not deleted); the
    new track started when it is seen again takes the held track's ID, so the same four IDs
    are confirmed before and after the gap. Without the hold, four new IDs."""
    ids = _confirmed_ids(_held_tracker(40), _gap_scene(seed))
    before, after = ids[20], ids[-1]
    assert len(before) == 4 and after == before
    assert not set().union(*ids[34:46])  # lost in the gap: not shown
    plain = _confirmed_ids(_held_tracker(None), _gap_scene(seed))
    assert len(plain[-1]) == 4 and not plain[-1] & plain[20]


def test_a_new_track_far_from_a_held_one_keeps_its_own_id():
    """The fourth target comes back 3 km off its course: farther than rejoin_within (1 km),
    so its new track keeps the new ID while the other three continue their held tracks."""
    ids = _confirmed_ids(_held_tracker(40), _gap_scene(1, jump=3000.0))
    before, after = ids[20], ids[-1]
    assert len(before) == 4 and len(after) == 4 and len(after & before) == 3


def test_a_held_track_is_deleted_after_its_hold_and_never_confirmed_by_plots():
    """Held tracks take no plot (their gate has grown): the plots of a target seen again
    start a new track; a held track no new track continues is deleted after its hold."""
    trk = _held_tracker(10)
    tracks = trk.init()
    for scan in list(_gap_scene(2))[:21]:
        tracks = trk.step(tracks, scan)
    ids = set(tracks.ids[tracks.confirmed].tolist())
    assert len(ids) == 4
    for k in range(16):
        tracks = trk.step(tracks, Scan(44.0 + 2 * k, 0, np.zeros((0, 2))))
        if k == 8:  # 9 misses: lost, held
            assert ids <= set(tracks.ids.tolist())
            assert held(tracks.state)[np.isin(tracks.ids, list(ids))].all()
    assert not ids & set(tracks.ids.tolist())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_narrow_held_track_takes_up_its_object_again(seed):
    """A four-scan gap: the tracks are lost (more than two misses) and held. With a regain
    bound wider than their position std they take the next plots themselves and are shown
    again a scan or two later; with none, new tracks start and must be confirmed before they
    rejoin them, later."""
    logic = ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=0.9, clutter_density=density(),
                                 new_target_density=density() / 100)
    logic = replace(logic, delete_threshold=2.5 * np.log(0.1),
                    hold_threshold=(2.5 + 40) * np.log(0.1))

    def run(regain: float) -> list[set[int]]:
        trk = tracker("EKF", RADAR, logic=logic, initiator=TwoPoint(v_max=20.0),
                      rejoin_within=1000.0, regain_within=regain)
        tracks, out = trk.init(), []
        for scan in _gap_scene(seed, gap=4):
            tracks = trk.step(tracks, scan)
            out.append(set(tracks.ids[tracks.confirmed].tolist()))
        return out

    def back(ids: list[set[int]]) -> int:  # the first scan with the four IDs shown again
        return next((k for k in range(34, 80) if ids[k] == ids[29]), 80)

    ids = run(1000.0)
    assert len(ids[29]) == 4 and not ids[33]  # all lost in the gap
    assert back(ids) <= 36 and back(ids) < back(run(0.0))
