"""Simulated GPS/INS (trackkit.sim.gnss): truth sampling, noise statistics at a stated
confidence with fixed seeds, batching, and clear errors for bad input."""

import numpy as np
import pytest
from scipy import stats

from trackkit.angles import wrap
from trackkit.io.frames import EnuFrame
from trackkit.io.records import one_run
from trackkit.sim.gnss import (
    KHOR_MUSA,
    GpsModel,
    InsModel,
    sample_truth,
    sensor_times,
    simulate_gnss,
    simulate_gps,
    simulate_ins,
)

CONF = 0.999  # two-sided confidence of every statistical check here


def straight(duration=600.0, rate=1.0, speed=9.0, course=np.pi / 4, runs=()):
    t = np.arange(int(duration * rate) + 1) / rate
    shape = runs + t.shape
    e = np.broadcast_to(speed * np.sin(course) * t, shape)
    n = np.broadcast_to(speed * np.cos(course) * t, shape)
    psi = np.full(shape, course)
    return t, e, n, psi, np.full(shape, speed), np.zeros(shape), np.zeros(shape)


def turn(duration=60.0, rate=1.0, speed=9.0, v=-0.8, r=10.0 * np.pi / 180, psi0=0.4):
    """A steady turn with drift, closed form."""
    t = np.arange(int(duration * rate) + 1) / rate
    psi = psi0 + r * t
    e = (speed * (np.cos(psi0) - np.cos(psi)) + v * (np.sin(psi) - np.sin(psi0))) / r
    n = (speed * (np.sin(psi) - np.sin(psi0)) - v * (np.cos(psi0) - np.cos(psi))) / r
    return t, e, n, psi, np.full_like(t, speed), np.full_like(t, v), np.full_like(t, r)


def var_bounds(n):
    """Bounds on s^2 / sigma^2 for n independent zero-mean normal samples (sum of squares)."""
    a = (1 - CONF) / 2
    return stats.chi2.ppf(a, n) / n, stats.chi2.ppf(1 - a, n) / n


def test_sample_truth_is_the_truth_on_samples_and_hermite_between():
    t, e, n, psi, u, v, r = turn(rate=1.0)
    on = sample_truth(t, e, n, psi, u, v, r, t[3:7])
    assert np.array_equal(on.east, e[3:7]) and np.array_equal(on.north, n[3:7])
    assert np.array_equal(on.psi, psi[3:7])
    # halfway between 1 Hz samples of a 10 deg/s turn (R = 52 m): a chord would cut 0.2 m
    # inside; Hermite with the kinematic derivatives is within 1 mm, psi exact (linear)
    tq = t[:-1] + 0.5
    mid = sample_truth(t, e, n, psi, u, v, r, tq)
    t2, e2, n2, psi2, *_ = turn(rate=2.0)
    assert np.allclose(t2[1::2], tq)
    assert np.max(np.hypot(mid.east - e2[1::2], mid.north - n2[1::2])) < 1e-3
    assert np.allclose(mid.psi, psi2[1::2], atol=1e-12)
    chord = 0.5 * (e[:-1] + e[1:]) - e2[1::2], 0.5 * (n[:-1] + n[1:]) - n2[1::2]
    assert np.max(np.hypot(*chord)) > 0.1


def test_sensor_times_cover_the_truth():
    t = np.arange(1801) / 10.0  # 0..180 s
    assert len(sensor_times(t, 2.0)) == 361 and sensor_times(t, 2.0)[-1] == 180.0
    ts = sensor_times(t, 10.0, offset=0.05)
    assert ts[0] == 0.05 and ts[-1] <= 180.0 and len(ts) == 1800
    assert np.allclose(np.diff(ts), 0.1)


def test_noise_free_sensors_equal_the_truth():
    t, e, n, psi, u, v, r = turn(rate=10.0)
    gps, ins = simulate_gnss(t, e, n, psi, u, v, r, rng=np.random.default_rng(0),
                             gps=GpsModel(sigma_position=0, sigma_velocity=0),
                             ins=InsModel(sigma_heading=0, sigma_rate=0))
    frame = EnuFrame(*KHOR_MUSA)
    x, y, _ = frame.to_enu(gps.lat, gps.lon)
    k = np.searchsorted(t, gps.t)
    # the sea-level point vs the tangent-plane point: well under a millimetre here
    assert np.max(np.hypot(x - e[k], y - n[k])) < 1e-6
    assert np.allclose(gps.sog, np.hypot(9.0, 0.8))
    # course = heading + drift angle atan2(v, u) (v to starboard)
    assert np.allclose(wrap(gps.cog - psi[k] - np.arctan2(-0.8, 9.0)), 0, atol=1e-12)
    j = np.searchsorted(t, ins.t)
    assert np.allclose(wrap(ins.heading - psi[j]), 0, atol=1e-12)
    assert np.all((ins.heading >= 0) & (ins.heading < 2 * np.pi))
    assert np.allclose(ins.rate, np.deg2rad(10.0))


def test_noise_statistics_match_the_model():
    runs = (100,)
    t, e, n, psi, u, v, r = straight(runs=runs)
    gm, im = GpsModel(), InsModel()
    gps, ins = simulate_gnss(t, e, n, psi, u, v, r, rng=np.random.default_rng(7))
    assert gps.lat.shape == (100, 1201) and ins.heading.shape == (100, 6001)
    frame = EnuFrame(*KHOR_MUSA)
    x, y, _ = frame.to_enu(gps.lat, gps.lon)
    tr = sample_truth(t, e, n, psi, u, v, r, gps.t)
    ex, ey = x - tr.east, y - tr.north
    lo, hi = var_bounds(ex.size)
    for err, sigma in ((ex, gm.sigma_position), (ey, gm.sigma_position)):
        assert lo < np.mean(err**2) / sigma**2 < hi
        assert abs(err.mean()) < stats.norm.ppf(1 - (1 - CONF) / 2) * sigma / np.sqrt(err.size)
    assert abs(np.corrcoef(ex.ravel(), ey.ravel())[0, 1]) < 4 / np.sqrt(ex.size)
    # velocity vector noise, from SOG/COG: along and across the track
    ve, vn = gps.sog * np.sin(gps.cog), gps.sog * np.cos(gps.cog)
    dv = np.stack([ve - 9 * np.sin(np.pi / 4), vn - 9 * np.cos(np.pi / 4)])
    assert lo < np.mean(dv[0] ** 2) / gm.sigma_velocity**2 < hi
    assert lo < np.mean(dv[1] ** 2) / gm.sigma_velocity**2 < hi
    lo, hi = var_bounds(ins.heading.size)
    dh = wrap(ins.heading - np.pi / 4)
    assert lo < np.mean(dh**2) / im.sigma_heading**2 < hi
    assert lo < np.mean(ins.rate**2) / im.sigma_rate**2 < hi
    # the defaults are the documented ones
    assert gm.sigma_position == 1.5 and gm.sigma_velocity == 0.05 and gm.rate == 2.0
    assert np.isclose(np.rad2deg(im.sigma_heading), 0.2) and im.rate == 10.0
    assert np.isclose(np.rad2deg(im.sigma_rate), 0.05)


@pytest.mark.parametrize("speed", [0.5, 9.0])
def test_cog_noise_grows_at_low_speed(speed):
    t, e, n, psi, u, v, r = straight(speed=speed, runs=(50,))
    gps = simulate_gps(t, e, n, psi, u, v, r, rng=np.random.default_rng(3))
    dc = wrap(gps.cog - np.pi / 4)
    # the angle of a normal vector of mean `speed` and std 0.05 per axis: ~ sigma / speed,
    # 1 % above at 0.5 m/s (the next term of the series)
    expect = 0.05 / speed * (1 + 0.5 * (0.05 / speed) ** 2)
    lo, hi = var_bounds(dc.size)
    assert lo - 0.01 < np.mean(dc**2) / expect**2 < hi + 0.01


def test_gauss_markov_position_noise():
    t, e, n, psi, u, v, r = straight(runs=(500,))
    tau = 30.0
    gps = simulate_gps(t, e, n, psi, u, v, r, rng=np.random.default_rng(11),
                       model=GpsModel(position_corr_time=tau, sigma_velocity=0.0))
    x, y, _ = EnuFrame(*KHOR_MUSA).to_enu(gps.lat, gps.lon)
    tr = sample_truth(t, e, n, psi, u, v, r, gps.t)
    ex = x - tr.east
    a = np.exp(-0.5 / tau)
    rho = np.sum(ex[:, 1:] * ex[:, :-1]) / np.sum(ex[:, :-1] ** 2)
    assert abs(rho - a) < 0.002
    # stationary std 1.5 m (effective samples ~ N (1 - a^2) / (1 + a^2) ~ 10 000: 5 % at 99.9 %)
    assert abs(np.mean(ex**2) / 1.5**2 - 1) < 0.06
    assert abs(np.mean(ex[:, 0] ** 2) / 1.5**2 - 1) < 0.25  # from the first fix on


def test_runs_are_independent_and_silencing_one_noise_keeps_the_others():
    t, e, n, psi, u, v, r = straight(duration=60, runs=(3,))
    g1, i1 = simulate_gnss(t, e, n, psi, u, v, r, rng=np.random.default_rng(5))
    g2, i2 = simulate_gnss(t, e, n, psi, u, v, r, rng=np.random.default_rng(5),
                           gps=GpsModel(sigma_position=0.0))
    assert not np.allclose(i1.heading[0], i1.heading[1])
    assert np.array_equal(i1.heading, i2.heading) and np.array_equal(g1.sog, g2.sog)
    one = one_run(g1, 1)
    assert one.lat.shape == (121,) and np.array_equal(one.lat, g1.lat[1])
    assert np.array_equal(one.t, g1.t)


def test_one_generator_per_run_gives_each_run_its_own_noise_bit_for_bit():
    # a batch sensed in one call with one generator per run equals the runs sensed one at a
    # time: a run's noise depends on its generator alone (the Monte Carlo's guarantee)
    t, e, n, psi, u, v, r = straight(duration=60, runs=(3,))
    e = e + np.arange(3)[:, None]  # three different truths
    batch = simulate_gnss(t, e, n, psi, u, v, r,
                          rng=[np.random.default_rng(s) for s in (4, 5, 6)])
    for j, s in enumerate((4, 5, 6)):
        one = simulate_gnss(t, e[j], n[j], psi[j], u[j], v[j], r[j],
                            rng=np.random.default_rng(s))
        for b, o in zip(batch, one, strict=True):
            for f in b._fields[1:]:
                np.testing.assert_array_equal(getattr(b, f)[j], getattr(o, f), err_msg=f)
    with pytest.raises(ValueError, match="2 generators for a truth of shape"):
        simulate_gps(t, e, n, psi, u, v, r, rng=[np.random.default_rng(0)] * 2)


def test_bad_inputs_name_the_field():
    t, e, n, psi, u, v, r = straight(duration=10)
    rng = np.random.default_rng(0)
    t_bad = t.copy()
    t_bad[5] = t_bad[4]
    with pytest.raises(ValueError, match=r"t is not strictly increasing.*t\[5\]"):
        simulate_gps(t_bad, e, n, psi, u, v, r, rng=rng)
    with pytest.raises(ValueError, match=r"GpsModel.rate = -1"):
        GpsModel(rate=-1)
    with pytest.raises(ValueError, match=r"InsModel.sigma_heading"):
        InsModel(sigma_heading=float("nan"))
    with pytest.raises(ValueError, match=r"GpsModel.sigma_position = -0.5"):
        GpsModel(sigma_position=-0.5)
    with pytest.raises(ValueError, match=r"psi has shape \(5,\); expected \(\.\.\., 11\)"):
        simulate_ins(t, e, n, psi[:5], u, v, r, rng=rng)
    with pytest.raises(ValueError, match=r"u holds non-finite"):
        simulate_ins(t, e, n, psi, np.full_like(u, np.nan), v, r, rng=rng)
    with pytest.raises(ValueError, match=r"rng = 3; expected a numpy.random.Generator"):
        simulate_gps(t, e, n, psi, u, v, r, rng=3)
    with pytest.raises(ValueError, match=r"offset = 20.0 s is past the truth's end"):
        simulate_ins(t, e, n, psi, u, v, r, rng=rng, model=InsModel(offset=20.0))
    with pytest.raises(ValueError, match=r"times span"):
        sample_truth(t, e, n, psi, u, v, r, np.array([11.0]))
