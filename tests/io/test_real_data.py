"""The two recorded files in shared/data, read end to end (skipped when they are absent)."""

from pathlib import Path

import numpy as np
import pyarrow.csv as pacsv
import pytest

from trackkit.io import read_ais_csv, read_opensky_csv

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
SOLENT = DATA / "SolentAIS_20160112_130211.csv"
OPENSKY = DATA / "OpenSky_Plane_States.csv"

pytestmark = pytest.mark.skipif(not SOLENT.exists() or not OPENSKY.exists(),
                                reason="shared/data not beside the repository")


def _raw(path):
    """The file's own columns, read independently of trackkit (line i+2 is row i)."""
    return pacsv.read_csv(path)


def test_solent_end_to_end():
    calls = []
    r, rep = read_ais_csv(SOLENT, progress=lambda done, total: calls.append((done, total)))
    assert rep.rows_read == 18623
    assert rep.rows_read == rep.rows_kept + rep.n_skipped + rep.duplicates
    assert rep.n_skipped == 0 and rep.duplicates == 3 and rep.out_of_order == 0
    assert rep.rows_kept == len(r) == 18620
    assert dict(rep.not_given) == {"course": 1027}       # COG 360: "not available"
    assert len(r.ids) == 91 and set(r.id) == set(r.ids)
    assert str(rep.epoch) == "2016-01-12T13:02:11.000000000"
    assert r.time[0] == pytest.approx(0.218) and r.time[-1] - r.time[0] == pytest.approx(5070.706)
    assert np.all(np.diff(r.time) >= 0)
    # a vessel at rest with no course has velocity 0; moving with no course, nan
    assert np.isnan(r.vx).sum() == 345
    assert calls[-1] == (SOLENT.stat().st_size,) * 2

    # one report (line 8209) has longitude 54.8 E: valid, so kept, but 3000 km away
    d = np.hypot(r.x, r.y)
    assert r.line[d > 100e3].tolist() == [8209]
    near = d < 100e3
    assert 20e3 < np.ptp(r.x[near]) < 60e3 and 20e3 < np.ptp(r.y[near]) < 60e3

    # a box drops it, counted and named
    r2, rep2 = read_ais_csv(SOLENT, bounds=(49.0, 52.0, -3.0, 1.0))
    assert dict(rep2.skipped) == {"outside bounds": 1}
    assert str(rep2.bad[0]).startswith(f"{SOLENT}:8209:Latitude_degrees: outside bounds")
    assert rep2.skipped_lines.tolist() == [8209]
    assert np.hypot(r2.x, r2.y).max() < 50e3

    # back to latitude and longitude: the file's own values, to 1e-9 deg
    raw = _raw(SOLENT)
    lat, lon, _ = r.geodetic()
    i = r.line - 2
    assert np.max(np.abs(lat - raw["Latitude_degrees"].to_numpy()[i])) < 1e-9
    assert np.max(np.abs(lon - raw["Longitude_degrees"].to_numpy()[i])) < 1e-9
    sog = raw["SOG_knots"].to_numpy()[i] * 1852 / 3600
    np.testing.assert_allclose(np.hypot(r.vx, r.vy)[~np.isnan(r.vx)], sog[~np.isnan(r.vx)],
                               rtol=1e-12, atol=1e-12)


def test_opensky_end_to_end():
    r, rep = read_opensky_csv(OPENSKY)
    assert rep.rows_read == 6052
    assert rep.rows_read == rep.rows_kept + rep.n_skipped + rep.duplicates
    assert rep.n_skipped == 0
    # positions repeat over samples (lastposupdate unchanged): dropped as exact duplicates
    assert rep.duplicates == 642 and rep.rows_kept == len(r) == 5410
    assert rep.out_of_order > 0                            # position times lag the samples
    assert len(r.ids) == 84
    assert np.all(np.diff(r.time) >= 0)
    assert 1190 < r.time[-1] - r.time[0] < 1210
    # UK-wide: hundreds of km each way; altitudes up to 13 km
    assert 300e3 < np.ptp(r.x) < 1000e3 and 300e3 < np.ptp(r.y) < 1000e3
    assert -15e3 < r.z.min() and r.z.max() < 14e3
    assert not r.extra["onground"].any() and r.extra["callsign"].shape == (len(r),)

    raw = _raw(OPENSKY)
    i = r.line - 2
    t_abs = r.epoch.astype("datetime64[ns]").astype(np.int64) / 1e9 + r.time
    np.testing.assert_allclose(t_abs, raw["lastposupdate"].to_numpy()[i], rtol=0, atol=1e-6)
    lat, lon, alt = r.geodetic()
    assert np.max(np.abs(lat - raw["lat"].to_numpy()[i])) < 1e-9
    assert np.max(np.abs(lon - raw["lon"].to_numpy()[i])) < 1e-9
    np.testing.assert_allclose(alt, raw["geoaltitude"].to_numpy()[i], atol=1e-6)
    # the file's own east/north speeds agree with velocity and heading
    np.testing.assert_allclose(r.vx, raw["x_speed"].to_numpy()[i], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(r.vy, raw["y_speed"].to_numpy()[i], rtol=1e-6, atol=1e-6)


def test_readers_share_an_epoch_and_a_reference():
    # two sources in one frame and one clock, as a fused tracker needs
    r1, _ = read_ais_csv(SOLENT, reference=(50.8, -1.1), epoch="2016-01-12T13:00:00")
    assert (r1.frame.lat0, r1.frame.lon0) == (50.8, -1.1)
    assert r1.time[0] == pytest.approx(131.218)
    assert r1.for_object(r1.ids[0]).ids.tolist() == r1.ids.tolist()
