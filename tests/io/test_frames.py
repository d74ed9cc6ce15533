"""The local frame and the velocity conversions."""

import numpy as np
import pytest

from trackkit.io import KNOT, EnuFrame, course_from_velocity, velocity_from_course


def test_enu_round_trip_to_1e_9_deg():
    rng = np.random.default_rng(0)
    f = EnuFrame(51.8, -1.3, 0.0)
    lat = f.lat0 + rng.uniform(-4, 4, 10_000)
    lon = f.lon0 + rng.uniform(-6, 6, 10_000)
    alt = rng.uniform(-50, 13_000, 10_000)
    x, y, z = f.to_enu(lat, lon, alt)
    lat2, lon2, alt2 = f.to_geodetic(x, y, z)
    assert np.max(np.abs(lat2 - lat)) < 1e-9
    assert np.max(np.abs(lon2 - lon)) < 1e-9
    assert np.max(np.abs(alt2 - alt)) < 1e-6


def test_enu_axes_point_east_north_up():
    f = EnuFrame(50.0, -1.0)
    x, y, z = f.to_enu([50.0, 50.01, 50.0], [-0.99, -1.0, -1.0], [0.0, 0.0, 100.0])
    assert x[0] > 700 and abs(y[0]) < 1           # a point east: +x
    assert y[1] > 1100 and abs(x[1]) < 1e-6      # a point north: +y
    assert z[2] == pytest.approx(100.0)          # a point above: +z
    # one minute of latitude is about one nautical mile (1852 m; 1855 m at 50 deg)
    assert f.to_enu(50.0 + 1 / 60, -1.0)[1] == pytest.approx(1852.0, rel=3e-3)


def test_frame_at_median_and_validation():
    f = EnuFrame.at_median([50.0, 51.0, 90.0], [-1.0, 0.0, 1.0])
    assert (f.lat0, f.lon0, f.alt0) == (51.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="lat0 = 91.0"):
        EnuFrame(91.0, 0.0)
    with pytest.raises(ValueError, match="no positions"):
        EnuFrame.at_median([], [])


def test_velocity_from_course_is_nautical_and_inverts():
    vx, vy = velocity_from_course([10.0, 10.0, 10.0], [0.0, 90.0, 225.0])
    np.testing.assert_allclose(vx, [0.0, 10 * KNOT, -10 * KNOT / np.sqrt(2)], atol=1e-12)
    np.testing.assert_allclose(vy, [10 * KNOT, 0.0, -10 * KNOT / np.sqrt(2)], atol=1e-12)
    s, c = course_from_velocity(vx, vy)
    np.testing.assert_allclose(s, 10.0)
    np.testing.assert_allclose(c, [0.0, 90.0, 225.0], atol=1e-9)
    vx, vy = velocity_from_course(3.0, np.pi / 2, speed_unit="m/s", course_unit="rad")
    assert (vx, vy) == pytest.approx((3.0, 0.0))
    assert np.isnan(velocity_from_course(np.nan, 10.0)[0])
    with pytest.raises(ValueError, match="speed unit 'mph'"):
        velocity_from_course(1.0, 1.0, speed_unit="mph")
