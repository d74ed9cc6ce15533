"""Multi-target radar scene simulation (trackkit.sim.scene).

Statistical tests use fixed seeds (so they are deterministic) and each accepts at the 99%
level: a two-sided p-value above 0.01.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

import trackkit.sim.scene as mt
from trackkit.models.motion import ConstantVelocity
from trackkit.models.sensors import Bearing, Position, RangeBearing
from trackkit.sim.kinematics import LegPlan, propagate
from trackkit.sim.scene import (
    Radar,
    Scene,
    Target,
    propagate_targets,
    radar_clutter,
    radar_crossing,
    radar_dense,
    simulate_scene,
)

DEG = math.pi / 180
ALPHA = 0.01  # two-sided, 99% confidence


def rb_radar(**kw) -> Radar:
    base = dict(sensor=RangeBearing((0.0, 0.0), 30.0, 0.5 * DEG),
                fov=((1000.0, 30000.0), (-math.pi, math.pi)), pd=0.9, clutter=0.0, period=2.0)
    return Radar(**{**base, **kw})


def plot_truth(run: mt.SceneRun, n_targets: int) -> tuple[np.ndarray, np.ndarray]:
    """For the target plots of a run: (z, true state at the plot's scan)."""
    s = run.scans.scan_index
    tgt = run.origin >= 0
    truth_scan = np.repeat(np.arange(run.truth.n_steps), run.truth.sizes)
    tkey = truth_scan * n_targets + run.truth.ids
    pkey = s[tgt] * n_targets + run.origin[tgt]
    rows = np.searchsorted(tkey, pkey)
    assert np.array_equal(tkey[rows], pkey)  # every plot's target is alive in that scan
    return run.scans.z[tgt], run.truth.x[rows]


def two_sided_chi2(stat: float, dof: int) -> float:
    c = stats.chi2.cdf(stat, dof)
    return 2 * min(c, 1 - c)


# --- determinism ---------------------------------------------------------------------------


def mixed_scene() -> Scene:
    """Two radars (range-bearing every 2 s, position every 3 s), births, deaths, legs."""
    targets = (
        Target((5000.0, 8000.0, 30.0, -10.0), q=0.5),
        Target((-4000.0, 6000.0, 0.0, 80.0), birth=7.0, death=41.0, q=0.1,
               legs=(LegPlan("turn", 20.0, 30.0, rate=3 * DEG),)),
        Target((2000.0, -9000.0, -50.0, 20.0), birth=-3.0, q=0.0,
               legs=(LegPlan("set", 12.0, course=45 * DEG, speed=70.0),)),
    )
    radars = (rb_radar(clutter=8.0),
              Radar(Position(2, (20.0, 25.0)), fov=((-10e3, 10e3), (-10e3, 12e3)), pd=0.8,
                    clutter=5.0, period=3.0, start=1.0))
    return Scene(targets, radars, end=60.0)


def same_run(a: mt.SceneRun, b: mt.SceneRun) -> bool:
    return (a.run == b.run and a.scans.equals(b.scans) and np.array_equal(a.origin, b.origin)
            and all(np.array_equal(x, y) for x, y in zip(a.truth, b.truth, strict=True)))


def test_run_alone_equals_run_in_batch_bitwise(monkeypatch):
    scene = mixed_scene()
    batch = simulate_scene(scene, range(10), seed=123)
    alone = simulate_scene(scene, [5], seed=123)[0]
    assert same_run(batch[5], alone)
    assert not batch[4].scans.equals(batch[5].scans)
    # chunking of the runs (memory bound) changes nothing
    monkeypatch.setattr(mt, "_CHUNK_ELEMENTS", 1)
    chunked = simulate_scene(scene, range(10), seed=123)
    assert all(same_run(x, y) for x, y in zip(batch, chunked, strict=True))
    assert same_run(simulate_scene(radar_crossing(), range(3, 6), seed=9)[1],
                    simulate_scene(radar_crossing(), [4], seed=9)[0])


def test_output_layout_and_merged_radars():
    scene = mixed_scene()
    run = simulate_scene(scene, 1, seed=1)[0]
    times, radar = scene.scan_times()
    assert np.array_equal(run.scans.times, times) and np.array_equal(run.scans.sensor, radar)
    assert np.all(np.diff(times) >= 0) and set(radar.tolist()) == {0, 1}
    assert len(run.scans) == run.truth.n_steps == 31 + 20
    assert run.origin.shape == (run.scans.z.shape[0],)
    assert run.truth.x.shape[1] == 4 and run.truth_positions.x.shape[1] == 2
    # each target gives at most one plot per scan
    s = run.scans.scan_index[run.origin >= 0]
    pairs = s * 3 + run.origin[run.origin >= 0]
    assert len(np.unique(pairs)) == len(pairs)
    # plots are in random order within a scan: target plots are not always first
    ranks = []
    for k in range(len(run.scans)):
        o = run.origin[run.scans.offsets[k]:run.scans.offsets[k + 1]]
        if len(o) > 1 and (o >= 0).any() and (o < 0).any():
            ranks.append(np.flatnonzero(o >= 0).mean() / (len(o) - 1))
    assert len(ranks) > 20 and 0.3 < np.mean(ranks) < 0.7
    assert np.allclose(scene.clutter_density, [8.0 / (29000 * 2 * math.pi), 5.0 / (20e3 * 22e3)])


# --- clutter -------------------------------------------------------------------------------


def clutter_run(radar: Radar, scans: int, seed: int) -> mt.SceneRun:
    scene = Scene((), (radar,), end=(scans - 1) * radar.period)
    return simulate_scene(scene, 1, seed=seed)[0]


def test_clutter_counts_are_poisson():
    lam, S = 12.0, 3000
    run = clutter_run(rb_radar(clutter=lam, period=1.0), S, seed=7)
    assert np.all(run.origin == -1)
    c = run.scans.counts
    assert len(c) == S
    # mean: the total is Poisson(S lam)
    tot = int(c.sum())
    p_mean = 2 * min(stats.poisson.cdf(tot, S * lam), stats.poisson.sf(tot - 1, S * lam))
    assert p_mean > ALPHA
    # dispersion: sum (c - cbar)^2 / cbar ~ chi2(S - 1) for Poisson counts (variance = mean)
    D = float(np.sum((c - c.mean()) ** 2) / c.mean())
    assert two_sided_chi2(D, S - 1) > ALPHA
    # no clutter at all for clutter = 0
    assert clutter_run(rb_radar(clutter=0.0), 50, seed=1).scans.z.shape[0] == 0


def test_clutter_uniform_in_range_and_bearing():
    # a sector across the +-pi cut (150 to 250 deg clockwise from north)
    lo_b, hi_b = 150 * DEG, 250 * DEG
    radar = rb_radar(clutter=30.0, fov=((2000.0, 25000.0), (lo_b, hi_b)))
    z = clutter_run(radar, 200, seed=3).scans.z
    assert len(z) > 5000 and np.all(radar.in_view(z))
    assert np.all((z[:, 1] > -math.pi) & (z[:, 1] <= math.pi))
    ur = (z[:, 0] - 2000.0) / 23000.0
    ub = np.mod(z[:, 1] - lo_b, 2 * math.pi) / (hi_b - lo_b)
    assert stats.kstest(ur, "uniform").pvalue > ALPHA
    assert stats.kstest(ub, "uniform").pvalue > ALPHA
    assert radar.volume == pytest.approx(23000.0 * 100 * DEG)
    assert radar.clutter_density == pytest.approx(30.0 / radar.volume)
    # a position radar: uniform over its rectangle
    pos = Radar(Position(2, 10.0), fov=((-5e3, 15e3), (0.0, 4e3)), clutter=30.0, period=1.0)
    zp = clutter_run(pos, 200, seed=4).scans.z
    assert stats.kstest((zp[:, 0] + 5e3) / 20e3, "uniform").pvalue > ALPHA
    assert stats.kstest(zp[:, 1] / 4e3, "uniform").pvalue > ALPHA


# --- detections ----------------------------------------------------------------------------


def test_detection_rate_matches_pd():
    pd = 0.7
    targets = tuple(Target.moving(10e3 * math.sin(a), 10e3 * math.cos(a), a + 1.0, 20.0)
                    for a in np.linspace(-3, 3, 8))
    scene = Scene(targets, (rb_radar(pd=pd),), end=200.0)
    runs = simulate_scene(scene, 5, seed=11)
    hits = sum(int((r.origin >= 0).sum()) for r in runs)
    trials = sum(r.truth.x.shape[0] for r in runs)  # every alive target is in view here
    assert trials == 5 * 8 * 101
    assert stats.binomtest(hits, trials, pd).pvalue > ALPHA
    # pd = 1: every alive in-view target is detected at every scan
    run = simulate_scene(Scene(targets, (rb_radar(pd=1.0),), end=20.0), 1, seed=2)[0]
    assert len(run.origin) == run.truth.x.shape[0]


def test_targets_out_of_view_are_not_detected():
    targets = (
        Target((0.0, 35e3, 0.0, 0.0)),  # beyond the 30 km range
        Target((500.0, 0.0, 0.0, 0.0)),  # inside the 1 km blind range
        Target((-10e3, -10e3, 0.0, 0.0)),  # bearing 225 deg, outside the sector
        Target((10e3, 10e3, 0.0, 0.0)),  # bearing 45 deg: seen
        Target((2000.0, 0.0, 200.0, 0.0)),  # leaves the 30 km range at t = 140 s
    )
    radar = rb_radar(pd=1.0, fov=((1000.0, 30000.0), (0.0, 180 * DEG)))
    run = simulate_scene(Scene(targets, (radar,), end=200.0), 1, seed=5)[0]
    seen = np.bincount(run.origin, minlength=5)
    assert seen.tolist() == [0, 0, 0, 101, 71]  # t = 0, 2, ..., 140
    assert run.truth.x.shape[0] == 5 * 101  # absent from view is not absent from the truth
    # position radar: the rectangle
    pos = Radar(Position(2, 10.0), fov=((1000.0, 12e3), (-100.0, 12e3)), pd=1.0, period=2.0)
    run = simulate_scene(Scene(targets, (pos,), end=10.0), 1, seed=5)[0]
    assert sorted(set(run.origin.tolist())) == [3, 4]


@pytest.mark.parametrize("kind", ["range-bearing", "position"])
def test_measurement_noise_matches_R(kind):
    if kind == "range-bearing":
        # targets all round, some near due south (bearing +-pi), to exercise the wrap
        sensor = RangeBearing((1000.0, -2000.0), 40.0, 1.0 * DEG)
        radar = Radar(sensor, ((100.0, 50e3), (-math.pi, math.pi)), pd=0.9, period=2.0)
    else:
        sensor = Position(2, (15.0, 40.0))
        radar = Radar(sensor, ((-50e3, 50e3), (-50e3, 50e3)), pd=0.9, period=2.0)
    ang = np.concatenate([np.linspace(-3.1, 3.1, 9), [math.pi, -math.pi + 1e-3, math.pi - 1e-3]])
    targets = tuple(Target((1000.0 + 8e3 * math.sin(a), -2000.0 + 8e3 * math.cos(a), 0.0, 0.0))
                    for a in ang)
    scene = Scene(targets, (radar,), end=100.0)
    runs = simulate_scene(scene, 10, seed=17)
    z = np.concatenate([plot_truth(r, len(targets))[0] for r in runs])
    x = np.concatenate([plot_truth(r, len(targets))[1] for r in runs])
    if kind == "range-bearing":
        assert np.all((z[:, 1] > -math.pi) & (z[:, 1] <= math.pi))
    nu = sensor.residual(z, sensor.h(x))
    Rinv = np.linalg.inv(sensor.noise)
    nis = np.einsum("ni,ij,nj->n", nu, Rinv, nu)
    N = len(nis)
    assert N > 4000
    assert two_sided_chi2(float(nis.sum()), 2 * N) > ALPHA
    # unbiased: the mean whitened residual is N(0, I / N)
    white = nu @ np.linalg.cholesky(Rinv)
    assert np.all(np.abs(white.mean(0)) * math.sqrt(N) < stats.norm.ppf(1 - ALPHA / 4))


# --- truth ---------------------------------------------------------------------------------


def test_targets_absent_outside_birth_death():
    targets = (
        Target((1e4, 1e4, 10.0, 0.0), birth=5.0, death=15.0),  # born between scans
        Target((1e4, -1e4, 0.0, 10.0), birth=4.0, death=12.0),  # born and dies on a scan
        Target((-1e4, 1e4, 0.0, 0.0)),
    )
    scene = Scene(targets, (rb_radar(pd=1.0, clutter=3.0),), end=20.0)
    run = simulate_scene(scene, 1, seed=3)[0]
    times = run.scans.times
    tscan = times[np.repeat(np.arange(len(times)), run.truth.sizes)]
    for i, t in enumerate(targets):
        present = tscan[run.truth.ids == i]
        expect = times[(t.birth <= times) & (times < t.death)]
        assert np.array_equal(present, expect)
        plots_t = times[run.scans.scan_index[run.origin == i]]
        assert np.array_equal(plots_t, expect)  # pd = 1
    assert np.array_equal(tscan[run.truth.ids == 1], [4.0, 6.0, 8.0, 10.0])


def test_truth_zero_noise_is_exact():
    # constant velocity, born off the scan grid: x(t) = x0 + v (t - birth)
    t0 = Target((100.0, -200.0, 12.5, -7.0), birth=3.3)
    times = np.arange(0.0, 61.0, 3.0)
    X = propagate_targets([t0], times)[0, :, 0]
    born = times >= 3.3
    expect = np.array(t0.state) + np.outer(times - 3.3, [12.5, -7.0, 0.0, 0.0])
    np.testing.assert_allclose(X[born], expect[born], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(X[~born], np.broadcast_to(t0.state, (int((~born).sum()), 4)))
    # scripted legs: the same path as sim.kinematics.propagate on the grid
    legs = (LegPlan("turn", 9.0, 30.0, rate=2 * DEG), LegPlan("set", 33.0, speed=50.0),
            LegPlan("accel", 39.0, 48.0, accel=1.5), LegPlan("turn", 42.0, 51.0, rate=-4 * DEG),
            LegPlan("velocity", 54.0, velocity=(-10.0, 3.0)))
    t1 = Target((0.0, 0.0, 30.0, 40.0), legs=legs)
    X1 = propagate_targets([t0, t1, t0], times)[0, :, 1]  # batched with other targets
    ref = propagate(np.array(t1.state), times, legs, dim=2)
    np.testing.assert_allclose(X1, ref, rtol=1e-12, atol=1e-9)
    # a coordinated turn: speed kept, course turned by rate * duration (21 s at 2 deg/s)
    k0, k1 = 3, 10  # t = 9 and t = 30
    crs = np.arctan2(X1[:, 2], X1[:, 3])
    assert math.degrees(crs[k1] - crs[k0]) == pytest.approx(42.0, abs=1e-9)
    assert np.hypot(*X1[k1, 2:]) == pytest.approx(50.0, abs=1e-9)


def test_process_noise_covariance():
    q, dt, R = 2.0, 5.0, 4000
    t = Target((0.0, 0.0, 10.0, 5.0), birth=1.0, q=q)
    noise = np.random.default_rng(0).standard_normal((R, 2, 1, 4))
    X = propagate_targets([t], [1.0, 1.0 + dt], noise)[:, :, 0]
    np.testing.assert_array_equal(X[:, 0], np.broadcast_to(t.state, (R, 4)))  # at birth
    Q = ConstantVelocity(2, q).noise(None, dt)
    d = X[:, 1] - ConstantVelocity(2, q).f(np.array(t.state), dt)
    nees = np.einsum("ni,ij,nj->n", d, np.linalg.inv(Q), d)
    assert two_sided_chi2(float(nees.sum()), 4 * R) > ALPHA


# --- scene builders ------------------------------------------------------------------------


def zero_noise_truth(scene: Scene):
    times = np.unique(scene.scan_times()[0])
    X = propagate_targets(scene.targets, times)[0]
    b = np.array([t.birth for t in scene.targets])
    d = np.array([t.death for t in scene.targets])
    return times, X, (b <= times[:, None]) & (times[:, None] < d)


def test_radar_crossing_geometry():
    scene = radar_crossing()
    (radar,) = scene.radars
    assert len(scene.targets) == 3 and radar.pd == 0.9 and radar.kind == "range-bearing"
    assert radar.clutter == 20.0 and len(scene.scan_times()[0]) == 101
    times, X, alive = zero_noise_truth(radar_crossing(q=0.0))
    assert alive.all()
    z = radar.sensor.h(X)
    assert radar.in_view(z).all()

    def dist(a, b):
        return np.hypot(*(X[:, a, :2] - X[:, b, :2]).T)

    ab, ac, bc = dist(0, 1), dist(0, 2), dist(1, 2)
    assert ab.min() == pytest.approx(100.0, abs=1) and times[np.argmin(ab)] == 99.0
    assert ac.min() == pytest.approx(99.0, abs=1) and bc.min() == pytest.approx(85.0, abs=1)
    par = (times >= 126) & (times <= 210)
    lateral = X[par, 0, 1] - X[par, 1, 1]
    assert np.all((lateral > 100) & (lateral < 200)) and np.all(ab[par] < 200)
    assert ab[0] > 600 and ab[-1] > 1500  # converging at the start, apart at the end


def test_radar_clutter_counts():
    scene = radar_clutter()
    (radar,) = scene.radars
    assert len(scene.targets) == 10 and radar.pd == 0.9 and radar.clutter == 20.0
    assert isinstance(radar.sensor, RangeBearing)
    births = [t.birth for t in scene.targets]
    assert len(set(births)) == 10
    deaths = [t.death for t in scene.targets if t.death < scene.end]
    assert len(deaths) == 3
    times, X, alive = zero_noise_truth(radar_clutter(q=0.0))
    assert radar.in_view(radar.sensor.h(X))[alive].all()
    runs = simulate_scene(scene, 2, seed=0)
    clutter = np.mean([(r.origin == -1).sum() / len(r.scans) for r in runs])
    assert 18 < clutter < 22


def test_radar_dense_counts_and_scale():
    scene = radar_dense()
    assert len(scene.targets) == 200 and len(scene.scan_times()[0]) == 301
    assert len(radar_dense(50).targets) == 50
    times, X, alive = zero_noise_truth(radar_dense(q=0.0))
    (radar,) = scene.radars
    assert radar.in_view(radar.sensor.h(X))[alive].mean() > 0.99
    runs = simulate_scene(scene, 2, seed=1)
    assert all(r.truth.x.shape[0] == alive.sum() for r in runs)
    assert all(len(r.scans) == 301 for r in runs)


# --- bad input -----------------------------------------------------------------------------


@pytest.mark.parametrize("make, field", [
    (lambda: rb_radar(pd=0.0), "Radar.pd"),
    (lambda: rb_radar(pd=1.2), "Radar.pd"),
    (lambda: rb_radar(pd=float("nan")), "Radar.pd"),
    (lambda: rb_radar(clutter=-1.0), "Radar.clutter"),
    (lambda: rb_radar(fov=((1000.0, 1000.0), (0.0, 1.0))), "Radar.fov"),
    (lambda: rb_radar(fov=((0.0, 1e4), (1.0, 0.5))), "Radar.fov"),
    (lambda: rb_radar(fov=((0.0, 1e4), (-4.0, 4.0))), "Radar.fov"),
    (lambda: rb_radar(fov=((-10.0, 1e4), (0.0, 1.0))), "Radar.fov"),
    (lambda: rb_radar(period=0.0), "Radar.period"),
    (lambda: rb_radar(times=(3.0, 1.0)), "Radar.times"),
    (lambda: rb_radar(sensor=Bearing((0.0, 0.0), 0.01)), "Radar.sensor"),
    (lambda: Target((0.0, 0.0, 1.0, 1.0), birth=10.0, death=10.0), "Target.birth"),
    (lambda: Target((0.0, 0.0, 1.0, 1.0), birth=10.0, death=5.0), "Target.death"),
    (lambda: Target((0.0, 0.0, 1.0)), "Target.state"),
    (lambda: Target((0.0, 0.0, 1.0, 1.0), q=-1.0), "Target.q"),
    (lambda: Target((0.0, 0.0, 1.0, 1.0), legs=(LegPlan("jump", 1.0),)), "Target.legs"),
    (lambda: Scene((), (), end=10.0), "Scene.radars"),
    (lambda: radar_dense(-1), "n = -1"),
    (lambda: simulate_scene(radar_crossing(), [-1], seed=0), "runs"),
])
def test_bad_input_names_the_field(make, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        make()
