"""Pre-processing GPS/INS to the identifier's [u, v, r] (trackkit.io.navigation): exact to
the printed precision without noise (through an NMEA log), within the noise's statistics
with it (fixed seed, stated confidence), gaps named, measured inputs validated."""

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from trackkit.io.frames import KNOT, EnuFrame
from trackkit.io.navigation import (
    inputs_on_grid,
    interpolate,
    preprocess,
    preprocess_sim,
    read_inputs_csv,
    to_body,
)
from trackkit.io.nmea import NavLog, read_nmea, write_nmea
from trackkit.sim.gnss import KHOR_MUSA, GpsModel, InsModel, sample_truth, simulate_gnss

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
DEG = np.pi / 180
CONF = 0.999
SPEED, SWAY, RATE = 9.0, -0.8, np.deg2rad(6.0)  # a steady starboard turn, stern sliding out


def steady_turn(duration=120.0, rate=10.0, psi0=5.9):
    t = np.arange(int(duration * rate) + 1) / rate
    psi = psi0 + RATE * t
    e = (SPEED * (np.cos(psi0) - np.cos(psi)) + SWAY * (np.sin(psi) - np.sin(psi0))) / RATE
    n = (SPEED * (np.sin(psi) - np.sin(psi0)) - SWAY * (np.cos(psi0) - np.cos(psi))) / RATE
    return (t, e, n, psi, np.full_like(t, SPEED), np.full_like(t, SWAY),
            np.full_like(t, RATE))


QUIET = dict(gps=GpsModel(sigma_position=0, sigma_velocity=0),
             ins=InsModel(sigma_heading=0, sigma_rate=0))


def test_to_body_inverts_the_kinematics():
    rng = np.random.default_rng(0)
    u, v, psi = rng.normal(size=(3, 1000)) * [[5], [1], [3]]
    ve, vn = u * np.sin(psi) + v * np.cos(psi), u * np.cos(psi) - v * np.sin(psi)
    uu, vv = to_body(ve, vn, psi)
    assert np.allclose(uu, u, atol=1e-12) and np.allclose(vv, v, atol=1e-12)
    # heading north, moving east: all sway, to starboard
    assert np.allclose(to_body(1.0, 0.0, 0.0), (0.0, 1.0))


def test_interpolate_batched_with_gaps_and_exact_samples():
    t = np.array([0.0, 1.0, 2.0, 10.0, 11.0])
    y = np.stack([t * 2, t * 3 + np.array([0, 0, np.nan, 0, 0])])
    val, miss = interpolate([0.5, 2.0, 5.0, 10.0, 11.0, 12.0], t, y, max_gap=2.0)
    assert miss.tolist() == [False, False, True, False, False, True]
    assert np.allclose(val[0], [1.0, 4.0, np.nan, 20.0, 22.0, np.nan], equal_nan=True)
    assert np.isnan(val[1, 1]) and val[1, 3] == 30.0  # a sample beside a nan is itself


def test_exact_without_noise_through_an_nmea_log(tmp_path):
    truth = steady_turn()
    gps, ins = simulate_gnss(*truth, rng=np.random.default_rng(0), **QUIET)
    path = tmp_path / "turn.nmea"
    write_nmea(path, gps, ins, "2024-06-01T23:59:00")
    log, rep = read_nmea(path)
    m = preprocess(log, reference=KHOR_MUSA, dt=1.0)
    assert m.t[0] == 0.0 and m.t[-1] == 120.0 and np.all(np.diff(m.t) == 1.0)
    assert not m.gap.any() and m.gaps == ()
    tr = sample_truth(*truth, m.t)
    # from the printed digits: SOG within 0.0005 kn, COG and heading within 0.005 deg each,
    # so |du|, |dv| <= 0.0005 kn + |V| (0.005 + 0.005) deg; ROT within 0.005 deg/min
    speed = np.hypot(SPEED, SWAY)
    tol_uv = 0.0005 * KNOT + speed * 0.01 * DEG + 1e-9
    assert np.max(np.abs(m.u - tr.u)) <= tol_uv and np.max(np.abs(m.v - tr.v)) <= tol_uv
    assert np.max(np.abs(m.r - tr.r)) <= 0.005 * DEG / 60 + 1e-12
    assert np.max(np.abs(m.psi - tr.psi)) <= 0.005 * DEG + 1e-12
    # positions: 1e-5 minute of latitude or longitude is within 9.3 mm
    assert np.max(np.hypot(m.east - tr.east, m.north - tr.north)) <= 0.0093 * np.sqrt(2)
    # the same steps without the log are exact to rounding
    ms = preprocess_sim(gps, ins, reference=KHOR_MUSA)
    assert np.allclose(ms.u, tr.u, atol=1e-12) and np.allclose(ms.v, tr.v, atol=1e-12)
    assert np.allclose(ms.r, tr.r, atol=1e-15) and np.allclose(ms.east, tr.east, atol=1e-6)


def test_recovers_u_v_r_within_the_noise():
    runs = 60
    truth = [np.broadcast_to(x, (runs,) + x.shape) if k else x
             for k, x in enumerate(steady_turn(duration=600.0))]
    gps, ins = simulate_gnss(*truth, rng=np.random.default_rng(42))
    m = preprocess_sim(gps, ins, reference=KHOR_MUSA, dt=1.0)
    assert m.u.shape == (runs, 601) and not m.gap.any()
    tr = sample_truth(truth[0], *(x[0] for x in truth[1:]), m.t)
    du, dv, dr = m.u - tr.u, m.v - tr.v, m.r - tr.r
    g, i = GpsModel(), InsModel()
    # the grid falls on fixes and INS samples: u is the noisy velocity (isotropic, sigma_v)
    # projected on the noisy heading, so du = sigma_v noise + v dpsi, dv = ... - u dpsi to
    # first order in dpsi (the second order, u dpsi^2 / 2 ~ 2e-5 m/s, is negligible)
    expect = {"u": g.sigma_velocity**2 + SWAY**2 * i.sigma_heading**2,
              "v": g.sigma_velocity**2 + SPEED**2 * i.sigma_heading**2,
              "r": i.sigma_rate**2}
    n = du.size
    lo, hi = (stats.chi2.ppf(p, n) / n for p in ((1 - CONF) / 2, (1 + CONF) / 2))
    z = stats.norm.ppf((1 + CONF) / 2)
    for name, err in (("u", du), ("v", dv), ("r", dr)):
        ratio = np.mean(err**2) / expect[name]
        assert lo < ratio < hi, (name, ratio)
        assert abs(err.mean()) < z * np.sqrt(expect[name] / n), name
    # the identifier's R: sigma_u ~ 0.05 m/s, sigma_v ~ 0.06 m/s, sigma_r ~ 0.05 deg/s
    assert np.sqrt(expect["v"]) < 0.07


def test_fixture_preprocesses_to_its_truth():
    mod = _fixture()
    log, _ = read_nmea(FIXTURES / "sar_trial.nmea")
    m = preprocess(log, reference=mod.ORIGIN)
    tr = mod.truth()
    k = np.searchsorted(tr["t"], m.t)
    assert np.array_equal(tr["t"][k], m.t) and len(m.t) == 167
    # default noise: u, v within 5 sigma of their noise, r within 5 sigma of the gyro's
    assert np.max(np.abs(m.u - tr["u"][k])) < 5 * 0.07
    assert np.max(np.abs(m.v - tr["v"][k])) < 5 * 0.07
    assert np.max(np.abs(m.r - tr["r"][k])) < 5 * 0.05 * DEG
    assert np.sqrt(np.mean((m.east - tr["east"][k]) ** 2)) < 2.5


def _fixture():
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_sar_fixture",
                                                  FIXTURES / "make_sar_fixture.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _drop(log: NavLog, stream: str, t0: float, t1: float) -> NavLog:
    f = {k: getattr(log, k) for k in log.__dataclass_fields__}
    names = {"heading": ("t_heading", "heading", "line_heading"),
             "position": ("t_pos", "lat", "lon", "line_pos")}[stream]
    keep = ~((f[names[0]] > t0) & (f[names[0]] < t1))
    for k in names:
        f[k] = f[k][keep]
    return NavLog(**f)


def test_gaps_are_named_and_nan(tmp_path):
    gps, ins = simulate_gnss(*steady_turn(), rng=np.random.default_rng(0), **QUIET)
    path = tmp_path / "turn.nmea"
    write_nmea(path, gps, ins, "2024-06-01T12:00:00")
    log, _ = read_nmea(path)
    m = preprocess(_drop(log, "heading", 20.0, 25.0), reference=KHOR_MUSA)
    assert [(g.stream, g.start, g.end) for g in m.gaps] == [("heading", 20.0, 25.0)]
    # u, v, psi, r at the velocity times 20.5..24.5 are nan: grid 21..24 and (20, 25 are on
    # good fixes) kept
    bad = np.flatnonzero(m.gap).tolist()
    assert bad == [21, 22, 23, 24]
    assert np.all(np.isnan(m.u[bad])) and not np.isnan(m.east[bad]).any()
    assert not np.isnan(np.delete(m.u, bad)).any()
    m2 = preprocess(_drop(log, "position", 50.0, 60.0), reference=KHOR_MUSA, max_gap=30.0)
    assert m2.gaps == () and not m2.gap.any()


def test_rate_from_the_differenced_heading():
    gps, ins = simulate_gnss(*steady_turn(), rng=np.random.default_rng(0), **QUIET)
    m = preprocess_sim(gps, ins._replace(rate=np.zeros(0), t=ins.t), rate_source="heading")
    assert np.allclose(m.r, RATE, atol=1e-9)


def test_bad_arguments_name_the_field():
    gps, ins = simulate_gnss(*steady_turn(duration=10), rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"dt = 0.0; expected a positive grid period"):
        preprocess_sim(gps, ins, dt=0.0)
    log, _ = read_nmea(FIXTURES / "sar_trial.nmea")
    f = {k: getattr(log, k) for k in log.__dataclass_fields__}
    no_rot = NavLog(**{**f, "t_rate": [], "rate": [], "line_rate": []})
    with pytest.raises(ValueError, match=r"the rate stream has 0 samples.*rate_source"):
        preprocess(no_rot)
    assert preprocess(no_rot, rate_source="heading").r.shape == (167,)
    with pytest.raises(ValueError, match=r"rate_source = 'gps'"):
        preprocess_sim(gps, ins, rate_source="gps")
    with pytest.raises(ValueError, match=r"max_gap = -1"):
        preprocess_sim(gps, ins, max_gap=-1)
    late = ins._replace(t=ins.t + 100.0)
    with pytest.raises(ValueError, match=r"expected the position, velocity, heading and rate "
                                         r"streams to overlap"):
        preprocess_sim(gps, late)
    with pytest.raises(ValueError, match=r"heading times are not finite and strictly"):
        preprocess_sim(gps, ins._replace(t=ins.t[::-1].copy()))
    m = preprocess_sim(gps, ins, reference=EnuFrame(*KHOR_MUSA), start=2.0, end=5.0, dt=0.5)
    assert m.t.tolist() == [2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0]


# -- measured inputs -----------------------------------------------------------------------------


def test_fixture_inputs_align_with_the_log():
    log, _ = read_nmea(FIXTURES / "sar_trial.nmea")
    inputs, rep = read_inputs_csv(FIXTURES / "sar_trial_inputs.csv", epoch=log.epoch)
    assert rep.rows_read == rep.rows_kept == 167 and rep.n_skipped == 0
    assert inputs.t[0] == 0.0 and inputs.t[-1] == 166.0 and inputs.epoch == log.epoch
    assert set(np.round(np.rad2deg(inputs.nozzle), 6)) == {-20.0, 0.0, 20.0}
    assert np.all(np.abs(inputs.engine_speed * 60 - 2000) < 60)
    m = preprocess(log)
    nozzle, n = inputs_on_grid(inputs, m.t)
    assert np.array_equal(nozzle, inputs.nozzle) and np.array_equal(n, inputs.engine_speed)
    # the nozzle leads the turn by a second: it is +20 deg when the boat turns to starboard
    turning = m.r > np.deg2rad(2.0)
    assert turning.sum() > 60 and not turning[0]
    assert np.all(nozzle[np.flatnonzero(turning) - 1] > 0)


def test_inputs_csv_bad_rows_and_columns(tmp_path):
    p = tmp_path / "inputs.csv"
    p.write_text("time,nozzle_deg,rpm\n"
                 "0.0,5,2000\n"        # 2
                 "1.0,50,2000\n"       # 3 nozzle out of range
                 "2.0,5,-10\n"         # 4 negative rpm
                 "3.0,,2000\n"         # 5 missing nozzle
                 "2.5,6,2100\n"        # 6 out of order: kept, sorted
                 "2.5,7,2100\n"        # 7 repeated time: the first kept
                 "4.0,x,2000\n")       # 8 not a number
    inputs, rep = read_inputs_csv(p, time_format="seconds")
    got = {b.line: (b.column, b.reason) for b in rep.bad}
    assert got == {3: ("nozzle_deg", "nozzle angle outside [-45, 45]"),
                   4: ("rpm", "engine speed outside [0, 10000]"),
                   5: ("nozzle_deg", "missing value"), 8: ("nozzle_deg", "not a number")}
    assert inputs.t.tolist() == [0.0, 2.5] and inputs.line.tolist() == [2, 6]
    assert rep.duplicates == 1 and rep.out_of_order == 0 and inputs.epoch is None
    assert np.allclose(inputs.engine_speed, [2000 / 60, 2100 / 60])
    assert np.allclose(np.rad2deg(inputs.nozzle), [5, 6])
    with pytest.raises(ValueError, match=rf"{p}:3:nozzle_deg: nozzle angle outside"):
        read_inputs_csv(p, on_bad="stop", time_format="seconds")
    p.write_text("time,nozzle_deg,rpm,rudder\n0,1,2,3\n")
    with pytest.raises(ValueError, match=r"column 'rudder' is not known"):
        read_inputs_csv(p, time_format="seconds")
    p.write_text("time,nozzle_deg\n0,1\n")
    with pytest.raises(ValueError, match=r"no column 'rpm'"):
        read_inputs_csv(p, time_format="seconds")
    with pytest.raises(ValueError, match=r"max_rpm = -5"):
        read_inputs_csv(p, max_rpm=-5)
