"""The virtual radar over recorded reports (trackkit.sim.virtual_radar).

Statistical tests use fixed seeds (so they are deterministic) and each accepts at the 99%
level: a two-sided p-value above 0.01.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from trackkit.angles import wrap
from trackkit.io import EnuFrame, Reports
from trackkit.sim.virtual_radar import (
    VirtualRadar,
    interpolate_positions,
    scan_times,
    virtual_radar,
)

DEG = math.pi / 180
ALPHA = 0.01


def make_reports(objects: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> Reports:
    """Reports from per-object (times, x, y), ids "obj0", "obj1", ... (codes in that order)."""
    t = np.concatenate([o[0] for o in objects])
    x = np.concatenate([o[1] for o in objects])
    y = np.concatenate([o[2] for o in objects])
    code = np.concatenate([np.full(len(o[0]), k) for k, o in enumerate(objects)])
    order = np.argsort(t, kind="stable")
    n = len(t)
    nan = np.full(n, np.nan)
    return Reports(time=t[order], code=code[order], ids=[f"obj{k}" for k in range(len(objects))],
                   x=x[order], y=y[order], z=np.zeros(n), vx=nan, vy=nan, vz=nan,
                   line=np.arange(2, n + 2), frame=EnuFrame(50.0, -1.0), epoch=None,
                   source="synthetic")


def straight(p0, v, times) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    times = np.asarray(times, float)
    return times, p0[0] + v[0] * times, p0[1] + v[1] * times


def fleet(n: int = 30, duration: float = 600.0, seed: int = 5) -> Reports:
    """n straight-moving objects 2-18 km from the origin, reports every 2-9 s (irregular)."""
    rng = np.random.default_rng(seed)
    objects = []
    for _ in range(n):
        r, b = rng.uniform(2e3, 18e3), rng.uniform(-np.pi, np.pi)
        p0 = (r * math.sin(b), r * math.cos(b))
        v = rng.normal(0.0, 5.0, 2)
        t = np.cumsum(rng.uniform(2.0, 9.0, 200))
        objects.append(straight(p0, v, t[t < duration]))
    return make_reports(objects)


# --- the interpolation ------------------------------------------------------------------------


def test_interpolation_exact_on_straight_segments():
    rng = np.random.default_rng(1)
    objects = [straight((100.0 * k, -50.0 * k), rng.normal(0, 8, 2),
                        np.sort(rng.uniform(0, 300, 40))) for k in range(5)]
    reps = make_reports(objects)
    times = np.arange(0.0, 300.0, 2.5)
    scan, obj, p, v = interpolate_positions(reps.time, reps.code, reps.x, reps.y, times, 5,
                                            max_gap=1e9)
    assert scan.size > 0
    # sorted by scan, then object
    assert np.all(np.diff(scan * 10 + obj) > 0)
    for k, (t, x, y) in enumerate(objects):
        m = obj == k
        tq = times[scan[m]]
        assert tq.min() >= t.min() and tq.max() <= t.max()  # only inside its interval
        # every scan inside the interval is there
        assert m.sum() == np.sum((times >= t.min()) & (times <= t.max()))
        vel = (x[-1] - x[0]) / (t[-1] - t[0]), (y[-1] - y[0]) / (t[-1] - t[0])
        np.testing.assert_allclose(p[m, 0], x[0] + vel[0] * (tq - t[0]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(p[m, 1], y[0] + vel[1] * (tq - t[0]), rtol=0, atol=1e-9)
        np.testing.assert_allclose(v[m][tq < t.max()], np.tile(vel, (int((tq < t.max()).sum()),
                                                                    1)), rtol=1e-9)


def test_interpolation_at_a_report_is_the_report_and_linear_between():
    reps = make_reports([(np.array([0.0, 10.0, 30.0]), np.array([0.0, 100.0, 100.0]),
                          np.array([0.0, 0.0, 200.0]))])
    times = np.array([0.0, 5.0, 10.0, 20.0, 30.0, 31.0])
    scan, obj, p, _ = interpolate_positions(reps.time, reps.code, reps.x, reps.y, times, 1,
                                            max_gap=100.0)
    assert scan.tolist() == [0, 1, 2, 3, 4]  # 31 s is after the last report
    np.testing.assert_array_equal(p, [[0, 0], [50, 0], [100, 0], [100, 100], [100, 200]])


def test_gaps_are_not_bridged_unless_still():
    t_moving = np.r_[np.arange(0.0, 100.0, 5.0), np.arange(300.0, 400.0, 5.0)]  # 205 s gap
    moving = straight((0.0, 0.0), (5.0, 0.0), t_moving)
    t_still = np.array([0.0, 180.0, 360.0])  # at anchor: a report every 3 minutes
    still = (t_still, np.array([5000.0, 5010.0, 5005.0]), np.array([0.0, 3.0, -2.0]))
    reps = make_reports([moving, still])
    times = np.arange(0.0, 400.0, 3.0)
    scan, obj, p, _ = interpolate_positions(reps.time, reps.code, reps.x, reps.y, times, 2,
                                            max_gap=120.0, still_distance=50.0, still_gap=600.0)
    tm = times[scan[obj == 0]]
    assert not np.any((tm > 95.0) & (tm < 300.0))  # nothing inside the gap
    assert np.all(np.isin(np.round(times[(times <= 95) | ((times >= 300) & (times <= 395))], 6),
                          np.round(tm, 6)))
    ts = times[scan[obj == 1]]
    assert ts.size == np.sum(times <= 360.0)  # the still one is bridged across 180 s gaps
    # a still object is not bridged past still_gap, a moving one not past max_gap
    scan2, obj2, _, _ = interpolate_positions(reps.time, reps.code, reps.x, reps.y, times, 2,
                                              max_gap=120.0, still_distance=50.0,
                                              still_gap=100.0)
    assert set(times[scan2[obj2 == 1]].tolist()) <= {0.0, 180.0, 360.0}
    scan3, obj3, _, _ = interpolate_positions(reps.time, reps.code, reps.x, reps.y, times, 2,
                                              max_gap=300.0)
    assert np.sum(obj3 == 0) == np.sum(times <= 395.0)  # a longer max_gap bridges it


def test_single_report_object_and_scan_times():
    reps = make_reports([(np.array([12.0]), np.array([1000.0]), np.array([0.0])),
                         straight((2000.0, 0.0), (1.0, 0.0), [0.0, 50.0]),
                         (np.array([10.0]), np.array([3000.0]), np.array([0.0]))])
    run = virtual_radar(reps, VirtualRadar(period=5.0, clutter=0.0, pd=1.0), seed=0)
    ids = run.truth.ids.tolist()
    # one report: seen only by a scan at its very time
    assert ids.count(0) == 0 and ids.count(2) == 1
    assert run.objects_seen == 2
    np.testing.assert_array_equal(run.scans.times, np.arange(0.0, 51.0, 5.0))
    np.testing.assert_array_equal(scan_times(0.0, 10.0, 2.5), [0, 2.5, 5, 7.5, 10])
    np.testing.assert_array_equal(scan_times(0.0, 10.0, 2.5, until=6.0, start=1.0),
                                  [1.0, 3.5, 6.0])
    assert scan_times(0.0, 10.0, 2.5, max_scans=2).tolist() == [0.0, 2.5]
    assert scan_times(5.0, 4.0, 1.0).size == 0


def test_range_limits_decide_what_is_seen():
    reps = make_reports([straight((0.0, 30.0), (0.0, 0.0), [0.0, 60.0]),        # 30 m: blind
                         straight((0.0, 10e3), (0.0, 0.0), [0.0, 60.0]),        # 10 km
                         straight((30e3, 0.0), (100.0, 0.0), [0.0, 60.0])])     # leaves range
    vr = VirtualRadar(period=3.0, pd=1.0, clutter=0.0, max_range=33e3, min_range=50.0)
    run = virtual_radar(reps, vr, seed=0)
    ids = run.truth.ids
    assert 0 not in ids
    assert np.sum(ids == 1) == len(run.scans)
    d = np.hypot(*run.truth.x[ids == 2].T)
    assert d.max() <= 33e3 and np.sum(ids == 2) == 11  # 30 km + 100 m/s: out after 30 s
    # pd = 1: a plot of every object in range, none else
    assert np.bincount(run.origin, minlength=3).tolist() == np.bincount(ids, minlength=3
                                                                       ).tolist()


def test_site_moves_the_geometry():
    reps = make_reports([straight((5000.0, 5000.0), (0.0, 0.0), [0.0, 30.0])])
    run = virtual_radar(reps, VirtualRadar(site=(5000.0, 0.0), period=3.0, pd=1.0,
                                           clutter=0.0, sigma_range=1e-6,
                                           sigma_bearing=1e-9), seed=0)
    np.testing.assert_allclose(run.scans.z[:, 0], 5000.0, atol=1e-4)
    np.testing.assert_allclose(run.scans.z[:, 1], 0.0, atol=1e-7)   # due north
    assert run.sensor.origin.tolist() == [5000.0, 0.0]


# --- the plots: statistics --------------------------------------------------------------------


@pytest.fixture(scope="module")
def stats_run():
    reps = fleet()
    vr = VirtualRadar(period=3.0, sigma_range=25.0, sigma_bearing=0.4 * DEG, pd=0.8,
                      clutter=6.0, max_range=20e3, min_range=100.0)
    return reps, vr, virtual_radar(reps, vr, seed=11)


def test_plot_count_is_pd_times_objects_plus_clutter(stats_run):
    _, vr, run = stats_run
    pairs = run.truth.x.shape[0]  # object-scans in range
    det = int(np.sum(run.origin >= 0))
    # detections: binomial(pairs, pd)
    assert stats.binomtest(det, pairs, vr.pd).pvalue > ALPHA
    # clutter: Poisson(S lambda) in all
    S = len(run.scans)
    n_c = int(np.sum(run.origin < 0))
    p = 2 * min(stats.poisson.cdf(n_c, S * vr.clutter), stats.poisson.sf(n_c - 1, S * vr.clutter))
    assert p > ALPHA
    # plots per scan = detected objects + clutter, scan by scan
    per_scan = run.scans.counts
    scan_of = np.repeat(np.arange(S), per_scan)
    assert np.array_equal(np.bincount(scan_of[run.origin >= 0], minlength=S)
                          + np.bincount(scan_of[run.origin < 0], minlength=S), per_scan)
    assert np.all(np.bincount(scan_of[run.origin >= 0], minlength=S) <= run.truth.sizes)


def test_noise_matches_sigma_and_clutter_is_uniform(stats_run):
    _, vr, run = stats_run
    S = len(run.scans)
    scan_of = np.repeat(np.arange(S), run.scans.counts)
    obj = run.origin >= 0
    # the true position of each object plot: its truth row in the same scan
    tscan = np.repeat(np.arange(S), run.truth.sizes)
    key_truth = tscan * 1000 + run.truth.ids
    key_plot = scan_of[obj] * 1000 + run.origin[obj]
    idx = np.searchsorted(key_truth, key_plot)
    assert np.array_equal(key_truth[idx], key_plot)
    p = run.truth.x[idx] - np.asarray(vr.site)
    r_true = np.hypot(p[:, 0], p[:, 1])
    b_true = np.arctan2(p[:, 0], p[:, 1])
    e_r = (run.scans.z[obj, 0] - r_true) / vr.sigma_range
    e_b = wrap(run.scans.z[obj, 1] - b_true) / vr.sigma_bearing
    for e in (e_r, e_b):
        assert stats.kstest(e, "norm").pvalue > ALPHA
    assert abs(np.corrcoef(e_r, e_b)[0, 1]) < 4 / math.sqrt(e_r.size)
    zc = run.scans.z[~obj]
    u_r = (zc[:, 0] - vr.min_range) / (vr.max_range - vr.min_range)
    u_b = (zc[:, 1] + np.pi) / (2 * np.pi)
    assert stats.kstest(u_r, "uniform").pvalue > ALPHA
    assert stats.kstest(u_b, "uniform").pvalue > ALPHA
    assert np.all(np.abs(run.scans.z[:, 1]) <= np.pi)


def test_plots_come_in_bearing_order(stats_run):
    _, _, run = stats_run
    for scan in list(run.scans)[:50]:
        assert np.all(np.diff(scan.z[:, 1]) >= 0)


def test_seeded_and_deterministic(stats_run):
    reps, vr, run = stats_run
    again = virtual_radar(reps, vr, seed=11)
    assert again.scans.equals(run.scans)
    assert np.array_equal(again.origin, run.origin)
    assert np.array_equal(again.truth.x, run.truth.x)
    other = virtual_radar(reps, vr, seed=12)
    assert not np.array_equal(other.scans.z[:100], run.scans.z[:100])
    assert np.array_equal(other.truth.x, run.truth.x)  # the truth does not depend on the seed
    # the clutter density the tracker is told
    assert vr.clutter_density == pytest.approx(6.0 / ((20e3 - 100.0) * 2 * np.pi))


def test_first_scans_are_the_same_whatever_the_run_length(stats_run):
    """Scan k draws from its own stream: a run cut short by max_scans or until is the start
    of the full run, plot for plot (and so is the truth)."""
    reps, vr, run = stats_run
    t0 = float(run.scans.times[0])
    for kw in (dict(max_scans=3), dict(max_scans=60), dict(until=t0 + 100 * vr.period + 1.0)):
        short = virtual_radar(reps, vr, seed=11, **kw)
        n = len(short.scans)
        assert 3 <= n < len(run.scans)
        end = int(run.scans.offsets[n])
        assert np.array_equal(short.scans.offsets, run.scans.offsets[:n + 1])
        assert np.array_equal(short.scans.z, run.scans.z[:end])
        assert np.array_equal(short.origin, run.origin[:end])
        assert np.array_equal(short.truth.x, run.truth.x[:int(run.truth.offsets[n])])


# --- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize("kw, names", [
    (dict(pd=0.0), ["VirtualRadar.pd", "0.0"]),
    (dict(period=-3.0), ["VirtualRadar.period", "-3.0"]),
    (dict(clutter=float("nan")), ["VirtualRadar.clutter"]),
    (dict(min_range=5e3, max_range=1e3), ["min_range", "max_range"]),
    (dict(site=(0.0,)), ["VirtualRadar.site"]),
    (dict(max_gap=0.0), ["VirtualRadar.max_gap"]),
])
def test_bad_radar_names_the_field(kw, names):
    with pytest.raises(ValueError) as err:
        VirtualRadar(**kw)
    for name in names:
        assert name in str(err.value)


def test_bad_call():
    reps = fleet(2, 60.0)
    with pytest.raises(ValueError, match="max_scans"):
        virtual_radar(reps, VirtualRadar(), max_scans=0)
    with pytest.raises(ValueError, match="no scan"):
        virtual_radar(reps, VirtualRadar(), start=1e6)
    with pytest.raises(ValueError, match="expected a VirtualRadar"):
        virtual_radar(reps, object())  # type: ignore[arg-type]
