"""Sensor models (trackkit.models.sensors).

Every sensor's Jacobian and Hessian against central finite differences over random geometry
(kept away from singular configurations), bearing conventions, angle-only residual wrapping,
the multipath-delay model of Naseri Solhdar, chapter 4 (image method, closed-form inverse,
the corrected tau2 Jacobian), azimuth/elevation (Naseri Solhdar, chapter 5), the
Doppler-bearing Jacobian of Hashemi and Alfi (2019), the sine sensor of the
missing-measurements thesis and batched (moving) observers.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trackkit.angles import wrap
from trackkit.models import (
    AzimuthElevation,
    Bearing,
    BearingFrequency,
    MultipathDelay,
    Position,
    RangeBearing,
    Sine,
    Stack,
)

FAST = settings(max_examples=50, deadline=None, derandomize=True, database=None)
MANY = settings(max_examples=250, deadline=None, derandomize=True, database=None)
PI = np.pi

SENSORS = [
    "Position2",
    "Position3",
    "Bearing-nautical",
    "Bearing-math",
    "RangeBearing-nautical",
    "RangeBearing-math",
    "AzEl-nautical",
    "AzEl-math",
    "BearingFrequency",
    "MultipathDelay",
    "Sine-amplitude",
    "Sine-unit",
    "Stack",
]


def _build(name: str, u, coin) -> tuple[object, np.ndarray]:
    """A sensor and a state for it, away from singular geometry: the target is at least 10 m
    from the sensor and at most ~50 times farther than the coordinates' own size, so that
    relative finite-difference steps resolve the geometry. ``u(lo, hi)`` draws a float and
    ``coin()`` a bool (from hypothesis or from numpy)."""
    o = np.array([u(-500, 500) for _ in range(3)])
    r = u(10.0, 5000.0)
    phi = u(-PI, PI)
    el = u(-1.2, 1.2)
    v = np.array([u(-30, 30) for _ in range(3)])
    if name.startswith("Position"):
        d = int(name[-1])
        x = np.concatenate([o[:d] + r * np.cos(phi), v[:d], [u(-1, 1)]])
        return Position(dim=d, sigma=np.arange(1.0, d + 1)), x
    if name.startswith("Bearing-") or name.startswith("RangeBearing"):
        conv = name.split("-")[1]
        p = o[:2] + r * np.array([np.cos(phi), np.sin(phi)])
        x = np.concatenate([p, v[:2], [u(-0.5, 0.5)]])  # CT-like, n = 5
        if name.startswith("Bearing-"):
            return Bearing(origin=o[:2], sigma=0.02, convention=conv), x
        return RangeBearing(origin=o[:2], sigma_range=5.0, sigma_bearing=0.01,
                            convention=conv), x
    if name.startswith("AzEl"):
        conv = name.split("-")[1]
        rel = r * np.array([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)])
        x = np.concatenate([o + rel, v])
        return AzimuthElevation(origin=o, sigma_az=0.01, sigma_el=0.02, convention=conv), x
    if name == "BearingFrequency":
        p = o[:2] + r * np.array([np.cos(phi), np.sin(phi)])
        vo = np.array([u(-10, 10), u(-10, 10)])
        f0 = u(50.0, 1000.0)
        x = np.concatenate([p, v[:2], [f0]])
        return BearingFrequency(origin=o[:2], velocity=vo, sigma_bearing=0.01,
                                sigma_freq=0.1), x
    if name == "MultipathDelay":
        hs, hb = u(5.0, 200.0), u(5.0, 200.0)
        dz = u(-0.95, 0.95) * (hs if coin() else hb)
        dz = min(max(dz, -0.95 * hb), 0.95 * hs)  # target in the water column
        rho = u(10.0, 5000.0)
        rel = np.array([rho * np.cos(phi), rho * np.sin(phi), dz])
        x = np.concatenate([o + rel, v])
        return MultipathDelay(origin=o, h_surface=hs, h_bottom=hb, sigma=[1e-4, 2e-4]), x
    if name == "Sine-amplitude":
        x = np.array([u(-10, 10), u(-20, 20), u(-5, 5)])
        return Sine(sigma=1.0, amplitude=True), x
    if name == "Sine-unit":
        return Sine(sigma=1.0, amplitude=False), np.array([u(-10, 10), u(-20, 20)])
    if name == "Stack":
        p = o[:2] + r * np.array([np.cos(phi), np.sin(phi)])
        o2 = o[:2] + np.array([300.0, -700.0])
        if np.hypot(*(p - o2)) < 10:
            o2 = o2 + 50.0
        x = np.concatenate([p, v[:2]])
        return Stack((Bearing(origin=o[:2]), RangeBearing(origin=o2, convention="math"),
                      Position(dim=2))), x
    raise AssertionError(name)


def _hyp(data):
    return (lambda lo, hi: data.draw(st.floats(lo, hi)), lambda: data.draw(st.booleans()))


def _np(seed):
    rng = np.random.default_rng(seed)
    return (lambda lo, hi: float(rng.uniform(lo, hi)), lambda: bool(rng.integers(2)))


def _scale(x):
    """Finite-difference step scale: the size of the state's coordinates (at least 1)."""
    return max(1.0, float(np.abs(x).max()))


def _jac(sensor, x):
    J = np.asarray(sensor.jacobian(x))
    return np.broadcast_to(J, (sensor.dim_z, x.shape[-1]))


# --------------------------------------------------------------------------------------------
# Jacobians and Hessians against finite differences
# --------------------------------------------------------------------------------------------


@MANY
@given(st.sampled_from(SENSORS), st.data())
def test_sensor_jacobian_matches_finite_differences(num, name, data):
    sensor, x = _build(name, *_hyp(data))
    J = _jac(sensor, x)
    Jfd = num.jac(sensor.h, x, diff=sensor.residual, floor=_scale(x))
    # besides rtol per row: the differences' own rounding, ~ eps |h_i| / step (x 50)
    atol = 1e-8 * np.abs(sensor.h(x))[:, None] / _scale(x) + 1e-300
    num.close(J, Jfd, rtol=1e-6, atol=atol, per_row=True,
              what=f"{name} jacobian at x={x.tolist()}")


@MANY
@given(st.sampled_from(SENSORS), st.data())
def test_sensor_hessian_matches_finite_differences(num, name, data):
    sensor, x = _build(name, *_hyp(data))
    H = np.asarray(sensor.hessian(x))
    n = x.shape[-1]
    assert H.shape == (sensor.dim_z, n, n)
    Hfd = num.hess(lambda p: _jac(sensor, p), x, floor=_scale(x))
    # besides rtol per row: the differences' own rounding, ~ eps |J_i| / step (x 50)
    atol = 1e-8 * np.abs(_jac(sensor, x)).max(-1)[:, None, None] / _scale(x) + 1e-300
    num.close(H, Hfd, rtol=1e-5, atol=atol, per_row=True,
              what=f"{name} hessian at x={x.tolist()}")
    np.testing.assert_allclose(H, np.swapaxes(H, -1, -2), rtol=1e-12, atol=1e-300)


GEOMETRY = {
    # fixed, well-conditioned cases for a Jacobian-free second-difference check
    "Bearing-nautical": (Bearing(origin=(1.0, -2.0)), np.array([30.0, 40.0, 1.0, -1.0])),
    "RangeBearing-math": (RangeBearing(origin=(5.0, 5.0), convention="math"),
                          np.array([-20.0, 35.0, 2.0, 1.0])),
    "AzEl-nautical": (AzimuthElevation(origin=(0.0, 0.0, -10.0)),
                      np.array([30.0, -20.0, 15.0, 1.0, 2.0, 0.0])),
    "BearingFrequency": (BearingFrequency(origin=(0.0, 0.0), velocity=(3.0, -2.0)),
                         np.array([40.0, 25.0, -5.0, 4.0, 300.0])),
    "MultipathDelay": (MultipathDelay(origin=(0.0, 0.0, 0.0), h_surface=30.0, h_bottom=20.0),
                       np.array([40.0, 30.0, -5.0, 0.0, 0.0, 0.0])),
    "Sine-amplitude": (Sine(), np.array([0.7, 10.0, 1.3])),
}


@pytest.mark.parametrize("name", sorted(GEOMETRY))
def test_sensor_hessian_matches_second_differences_of_h(num, name):
    sensor, x = GEOMETRY[name]
    H = sensor.hessian(x)
    Hfd = num.hess2(sensor.h, x, h=1e-4, diff=sensor.residual, floor=_scale(x))
    num.close(H, Hfd, rtol=1e-5, atol=1e-300, per_row=True, what=name)


@pytest.mark.parametrize("name", SENSORS)
def test_sensor_batched_shapes_and_rows(name):
    # h, jacobian, hessian over a (2, 3) batch equal the per-row results
    sensor, x0 = _build(name, *_np(17))
    rng = np.random.default_rng(3)
    X = x0 * (1 + 0.01 * rng.uniform(-1, 1, (2, 3, x0.size)))
    Z, J, H = sensor.h(X), sensor.jacobian(X), sensor.hessian(X)
    m, n = sensor.dim_z, X.shape[-1]
    assert Z.shape == (2, 3, m)
    J = np.broadcast_to(J, (2, 3, m, n))
    assert H.shape == (2, 3, m, n, n)
    for idx in np.ndindex(2, 3):
        np.testing.assert_allclose(Z[idx], sensor.h(X[idx]), rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(J[idx], _jac(sensor, X[idx]), rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(H[idx], sensor.hessian(X[idx]), rtol=1e-12, atol=1e-300)


# --------------------------------------------------------------------------------------------
# Bearing conventions and residuals
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "target, nautical, math",
    [
        ((1.0, 0.0), PI / 2, 0.0),  # due east
        ((0.0, 1.0), 0.0, PI / 2),  # due north
        ((-1.0, 0.0), -PI / 2, PI),  # due west
        ((0.0, -1.0), PI, -PI / 2),  # due south
        ((1.0, 1.0), PI / 4, PI / 4),
        ((1.0, -1.0), 3 * PI / 4, -PI / 4),
    ],
)
def test_bearing_conventions(target, nautical, math):
    o = np.array([10.0, -20.0])
    x = np.concatenate([o + 100 * np.array(target), [0.0, 0.0]])
    assert Bearing(origin=o).h(x)[0] == pytest.approx(nautical, abs=1e-15)
    assert Bearing(origin=o, convention="math").h(x)[0] == pytest.approx(math, abs=1e-15)
    # nautical = atan2(dx, dy)
    assert Bearing(origin=o).h(x)[0] == pytest.approx(np.arctan2(*(x[:2] - o)), abs=1e-15)
    rb = RangeBearing(origin=o).h(x)
    assert rb[0] == pytest.approx(100 * np.hypot(*target), rel=1e-15)
    assert rb[1] == pytest.approx(nautical, abs=1e-15)


def test_bearing_jacobian_sign_nautical_east():
    # target due north: moving it east increases the nautical bearing (clockwise)
    J = Bearing().jacobian(np.array([0.0, 10.0, 0.0, 0.0]))
    np.testing.assert_allclose(J, [[0.1, 0.0, 0.0, 0.0]], atol=1e-15)
    Jm = Bearing(convention="math").jacobian(np.array([0.0, 10.0, 0.0, 0.0]))
    np.testing.assert_allclose(Jm, [[-0.1, 0.0, 0.0, 0.0]], atol=1e-15)


def test_residual_wraps_angle_components_only():
    rb = RangeBearing()
    r = rb.residual(np.array([10.0, PI - 0.1]), np.array([3.0, -PI + 0.1]))
    np.testing.assert_allclose(r, [7.0, -0.2], atol=1e-12)
    # a range difference larger than pi is not wrapped
    r = rb.residual(np.array([100.0, 0.0]), np.array([0.0, 0.0]))
    np.testing.assert_allclose(r, [100.0, 0.0], atol=0)
    ae = AzimuthElevation()
    r = ae.residual(np.array([PI - 0.05, 0.1]), np.array([-PI + 0.05, 0.1 + 2 * PI]))
    np.testing.assert_allclose(r, [-0.1, 0.0], atol=1e-12)
    bf = BearingFrequency()
    r = bf.residual(np.array([-PI + 0.01, 310.0]), np.array([PI - 0.01, 300.0]))
    np.testing.assert_allclose(r, [0.02, 10.0], atol=1e-12)
    pos = Position(dim=2)
    np.testing.assert_array_equal(pos.residual(np.array([7.0, -9.0]), np.zeros(2)), [7, -9])
    st_ = Stack((Position(dim=2), Bearing()))
    assert st_.angular == (False, False, True)
    r = st_.residual(np.array([10.0, 10.0, 3.1]), np.array([0.0, 0.0, -3.1]))
    np.testing.assert_allclose(r, [10.0, 10.0, 6.2 - 2 * PI], atol=1e-12)
    # residuals are in (-pi, pi] for angle components, batched
    z = np.random.default_rng(0).uniform(-PI, PI, (50, 2))
    zh = np.random.default_rng(1).uniform(-PI, PI, (50, 2))
    res = ae.residual(z, zh)
    assert np.all((res > -PI) & (res <= PI))
    np.testing.assert_allclose(res, wrap(z - zh), atol=0)


def test_stack_composes_h_jacobian_noise():
    b = Bearing(origin=(0.0, 0.0), sigma=0.02)
    rb = RangeBearing(origin=(100.0, 0.0), sigma_range=3.0, sigma_bearing=0.01)
    s = Stack((b, rb))
    x = np.array([30.0, 40.0, 1.0, 2.0])
    assert s.dim_z == 3
    assert s.angular == (True, False, True)
    assert s.linear is False
    assert Stack((Position(2), Position(2))).linear is True
    np.testing.assert_array_equal(s.h(x), np.concatenate([b.h(x), rb.h(x)]))
    np.testing.assert_array_equal(s.jacobian(x), np.concatenate([b.jacobian(x), rb.jacobian(x)]))
    np.testing.assert_array_equal(s.noise, np.diag([0.02**2, 9.0, 0.01**2]))


# --------------------------------------------------------------------------------------------
# Azimuth / elevation (Naseri Solhdar, chapter 5)
# --------------------------------------------------------------------------------------------


def test_azimuth_elevation_values_and_thesis_jacobian():
    o = np.array([1.0, 2.0, -3.0])
    rel = np.array([30.0, -40.0, 20.0])
    x = np.concatenate([o + rel, [1.0, 1.0, 1.0]])
    RX, RY, RZ = rel
    rho2 = RX**2 + RY**2
    rho, R2 = np.sqrt(rho2), rho2 + RZ**2
    ae_m = AzimuthElevation(origin=o, convention="math")
    ae_n = AzimuthElevation(origin=o)
    np.testing.assert_allclose(ae_m.h(x), [np.arctan2(RY, RX), np.arctan2(RZ, rho)], rtol=1e-15)
    np.testing.assert_allclose(ae_n.h(x), [np.arctan2(RX, RY), np.arctan2(RZ, rho)], rtol=1e-15)
    J = ae_m.jacobian(x)
    expected = np.zeros((2, 6))
    expected[0, :3] = [-RY / rho2, RX / rho2, 0.0]
    expected[1, :3] = [-RX * RZ / (R2 * rho), -RY * RZ / (R2 * rho), rho / R2]
    np.testing.assert_allclose(J, expected, rtol=1e-13, atol=1e-17)
    # nautical azimuth: the same elevation row, azimuth gradient (RY, -RX)/rho^2
    Jn = ae_n.jacobian(x)
    np.testing.assert_allclose(Jn[0, :3], [RY / rho2, -RX / rho2, 0.0], rtol=1e-13)
    np.testing.assert_allclose(Jn[1], expected[1], rtol=1e-13, atol=1e-17)


def test_azimuth_elevation_up_is_positive():
    ae = AzimuthElevation()
    assert ae.h(np.array([10.0, 0.0, 10.0, 0, 0, 0]))[1] == pytest.approx(PI / 4)
    assert ae.h(np.array([0.0, 10.0, -10.0, 0, 0, 0]))[1] == pytest.approx(-PI / 4)


# --------------------------------------------------------------------------------------------
# Multipath delays (Naseri Solhdar, chapter 4)
# --------------------------------------------------------------------------------------------


def _reflected_path(rho, z_sensor, z_target, z_plane):
    """Length of the ray sensor -> plane -> target by the reflection point on the plane
    (Snell: equal angles), computed without any image source."""
    a, b = abs(z_plane - z_sensor), abs(z_plane - z_target)
    xr = rho * a / (a + b)  # horizontal distance of the reflection point from the sensor
    return np.hypot(xr, a) + np.hypot(rho - xr, b)


@FAST
@given(
    st.floats(5.0, 300.0), st.floats(5.0, 300.0), st.floats(-0.95, 0.95),
    st.floats(20.0, 3000.0), st.floats(-PI, PI),
)
def test_multipath_delays_equal_reflected_path_differences(hs, hb, frac, rho, phi):
    o = np.array([100.0, -50.0, -1000.0])
    dz = frac * (hs if frac > 0 else hb)
    x = np.concatenate([o + [rho * np.cos(phi), rho * np.sin(phi), dz], np.zeros(3)])
    c = 1480.0
    sensor = MultipathDelay(origin=o, h_surface=hs, h_bottom=hb, c=c)
    R = np.sqrt(rho**2 + dz**2)
    z_surface, z_bottom = o[2] + hs, o[2] - hb
    surf = _reflected_path(rho, o[2], o[2] + dz, z_surface)
    bott = _reflected_path(rho, o[2], o[2] + dz, z_bottom)
    tau = sensor.h(x)
    np.testing.assert_allclose(tau, [(surf - R) / c, (bott - R) / c], rtol=1e-9, atol=1e-15)
    assert np.all(tau > 0)  # reflected paths are longer
    # Naseri Solhdar, eqs 4-1, 4-2 with R_Z = Z_T - Z_O
    t1 = (np.sqrt(R**2 + 4 * hs**2 - 4 * dz * hs) - R) / c
    t2 = (np.sqrt(R**2 + 4 * hb**2 + 4 * dz * hb) - R) / c
    np.testing.assert_allclose(tau, [t1, t2], rtol=1e-9, atol=1e-15)


@FAST
@given(
    st.floats(5.0, 300.0), st.floats(5.0, 300.0), st.floats(-0.95, 0.95),
    st.floats(20.0, 3000.0), st.floats(-PI, PI),
)
def test_multipath_inverse_round_trip(hs, hb, frac, rho, phi):
    o = np.array([0.0, 0.0, -200.0])
    dz = frac * (hs if frac > 0 else hb)
    x = np.concatenate([o + [rho * np.cos(phi), rho * np.sin(phi), dz], np.zeros(3)])
    sensor = MultipathDelay(origin=o, h_surface=hs, h_bottom=hb)
    R, RZ = sensor.inverse(sensor.h(x))
    assert float(R) == pytest.approx(np.hypot(rho, dz), rel=1e-7)
    assert float(RZ) == pytest.approx(x[2] - o[2], rel=1e-6, abs=1e-6 * (hs + hb))


def test_multipath_inverse_batched():
    sensor = MultipathDelay(origin=(0.0, 0.0, 0.0), h_surface=40.0, h_bottom=60.0)
    X = np.array([[100.0, 0.0, 10.0, 0, 0, 0], [0.0, 500.0, -30.0, 0, 0, 0],
                  [-50.0, -50.0, 0.0, 0, 0, 0]])
    R, RZ = sensor.inverse(sensor.h(X))
    np.testing.assert_allclose(R, np.linalg.norm(X[:, :3], axis=-1), rtol=1e-9)
    np.testing.assert_allclose(RZ, X[:, 2], rtol=1e-8, atol=1e-8)


def _tau2_dz_corrected(d, hb, c):
    R = np.linalg.norm(d)
    S2 = np.sqrt(R**2 + 4 * hb**2 + 4 * hb * d[2])
    return ((d[2] + 2 * hb) / S2 - d[2] / R) / c


def _tau2_dz_thesis_printed(d, hb, c):
    R = np.linalg.norm(d)
    S2 = np.sqrt(R**2 + 4 * hb**2 - 4 * hb * d[2])
    return ((d[2] - 2 * hb) / S2 - d[2] / R) / c


@pytest.mark.parametrize("dz", [-15.0, -5.0, 0.0, 8.0, 25.0])
@pytest.mark.parametrize("rho", [30.0, 200.0, 2000.0])
def test_multipath_tau2_jacobian_is_the_corrected_form(num, dz, rho):
    hs, hb, c = 30.0, 20.0, 1500.0
    o = np.array([5.0, 5.0, -100.0])
    d = np.array([rho * 0.6, rho * 0.8, dz])
    x = np.concatenate([o + d, [1.0, -1.0, 0.0]])
    sensor = MultipathDelay(origin=o, h_surface=hs, h_bottom=hb, c=c)
    J = sensor.jacobian(x)
    Jfd = num.jac(sensor.h, x)
    corrected = _tau2_dz_corrected(d, hb, c)
    printed = _tau2_dz_thesis_printed(d, hb, c)
    assert J[1, 2] == pytest.approx(corrected, rel=1e-10, abs=1e-18)
    assert Jfd[1, 2] == pytest.approx(corrected, rel=1e-5)
    # the thesis's printed h23 (minus sign, S2 with -4 h_b dz) disagrees with the derivative
    assert abs(printed - Jfd[1, 2]) > 0.1 * abs(Jfd[1, 2])
    # the other printed entries (eqs 4-15ff) hold: tau1 row and the x, y entries
    R = np.linalg.norm(d)
    S1 = np.sqrt(R**2 + 4 * hs**2 - 4 * hs * dz)
    S2 = np.sqrt(R**2 + 4 * hb**2 + 4 * hb * dz)
    expected = np.zeros((2, 6))
    expected[0, :3] = [d[0] / c * (1 / S1 - 1 / R), d[1] / c * (1 / S1 - 1 / R),
                       ((dz - 2 * hs) / S1 - dz / R) / c]
    expected[1, :3] = [d[0] / c * (1 / S2 - 1 / R), d[1] / c * (1 / S2 - 1 / R), corrected]
    num.close(J, expected, rtol=1e-10, per_row=True, what="multipath jacobian (eqs 4-15ff)")


# --------------------------------------------------------------------------------------------
# Doppler-bearing (Hashemi and Alfi 2019)
# --------------------------------------------------------------------------------------------


@FAST
@given(
    st.floats(-3000, 3000), st.floats(-3000, 3000), st.floats(-20, 20), st.floats(-20, 20),
    st.floats(50, 2000), st.floats(-10, 10), st.floats(-10, 10), st.floats(1400, 1550),
)
def test_bearing_frequency_matches_hashemi_alfi(num, dx, dy, vx, vy, f0, ovx, ovy, c):
    if np.hypot(dx, dy) < 10:
        dx += 20.0
    o = np.array([200.0, -100.0])
    vo = np.array([ovx, ovy])
    x = np.array([o[0] + dx, o[1] + dy, vx, vy, f0])
    s = BearingFrequency(origin=o, velocity=vo, c=c)
    r = np.hypot(dx, dy)
    beta = np.arctan2(dx, dy)
    dvx, dvy = vx - ovx, vy - ovy
    VD = dvx * np.sin(beta) + dvy * np.cos(beta)
    z = s.h(x)
    assert abs(float(wrap(z[0] - beta))) < 1e-12  # (+-pi are the same bearing)
    assert z[1] == pytest.approx(f0 * (1 - VD / c), rel=1e-12)
    cross = dvx * dy - dvy * dx
    expected = np.array(
        [
            [dy / r**2, -dx / r**2, 0, 0, 0],
            [-(f0 / c) * dy * cross / r**3, (f0 / c) * dx * cross / r**3,
             -(f0 / c) * np.sin(beta), -(f0 / c) * np.cos(beta), 1 - VD / c],
        ]
    )
    num.close(s.jacobian(x), expected, rtol=1e-11, atol=1e-300, per_row=True,
              what="DBT jacobian vs Hashemi and Alfi")


def test_bearing_frequency_doppler_sign():
    # closing target (range decreasing) -> received frequency above f0
    s = BearingFrequency()
    closing = np.array([0.0, 1000.0, 0.0, -10.0, 500.0])
    opening = np.array([0.0, 1000.0, 0.0, 10.0, 500.0])
    assert s.h(closing)[1] > 500.0 > s.h(opening)[1]
    assert s.h(closing)[1] == pytest.approx(500.0 * (1 + 10.0 / 1500.0))


def test_bearing_frequency_rejects_wrong_state_length():
    with pytest.raises(ValueError, match=r"\[x, y, vx, vy, f0\]"):
        BearingFrequency().h(np.zeros(4))


# --------------------------------------------------------------------------------------------
# Sine (the missing-measurements thesis, eqs 2-96 ... 2-100)
# --------------------------------------------------------------------------------------------


def test_sine_values_jacobian_hessian_thesis():
    th, w, a = 0.7, 10.0, 1.3
    s = Sine()
    x = np.array([th, w, a])
    assert s.h(x)[0] == pytest.approx(a * np.sin(th))
    np.testing.assert_allclose(s.jacobian(x), [[a * np.cos(th), 0, np.sin(th)]], rtol=1e-15)
    np.testing.assert_allclose(
        s.hessian(x)[0],
        [[-a * np.sin(th), 0, np.cos(th)], [0, 0, 0], [np.cos(th), 0, 0]], rtol=1e-15,
    )
    s6 = Sine(amplitude=False)
    x6 = np.array([th, w])
    assert s6.h(x6)[0] == pytest.approx(np.sin(th))
    np.testing.assert_allclose(s6.jacobian(x6), [[np.cos(th), 0]], rtol=1e-15)
    assert s.noise.shape == (1, 1)


# --------------------------------------------------------------------------------------------
# Moving observer: the pose carries the batch axes
# --------------------------------------------------------------------------------------------


def test_batched_origin_broadcasts_per_row():
    rng = np.random.default_rng(4)
    B = 5
    O2 = rng.uniform(-100, 100, (B, 2))
    O3 = rng.uniform(-100, 100, (B, 3))
    V2 = rng.uniform(-5, 5, (B, 2))
    X4 = np.concatenate([O2 + rng.uniform(50, 500, (B, 2)), rng.uniform(-5, 5, (B, 2))], -1)
    X5 = np.concatenate([X4, rng.uniform(100, 500, (B, 1))], -1)
    X6 = np.concatenate([O3 + rng.uniform(50, 500, (B, 3)) * [1, 1, 0.05],
                         rng.uniform(-5, 5, (B, 3))], -1)
    cases = [
        (lambda o, v: Bearing(origin=o), O2, None, X4),
        (lambda o, v: Bearing(origin=o, convention="math"), O2, None, X4),
        (lambda o, v: RangeBearing(origin=o), O2, None, X4),
        (lambda o, v: AzimuthElevation(origin=o), O3, None, X6),
        (lambda o, v: BearingFrequency(origin=o, velocity=v), O2, V2, X5),
        (lambda o, v: MultipathDelay(origin=o, h_surface=60.0, h_bottom=60.0), O3, None, X6),
    ]
    for make, O, V, X in cases:
        batched = make(O, V)
        Z, J, H = batched.h(X), batched.jacobian(X), batched.hessian(X)
        for i in range(B):
            single = make(O[i], None if V is None else V[i])
            np.testing.assert_allclose(Z[i], single.h(X[i]), rtol=1e-12)
            np.testing.assert_allclose(J[i], single.jacobian(X[i]), rtol=1e-12, atol=1e-300)
            np.testing.assert_allclose(H[i], single.hessian(X[i]), rtol=1e-12, atol=1e-300)


def test_noise_matrices_match_sigmas():
    np.testing.assert_array_equal(Position(dim=3, sigma=[1.0, 2.0, 3.0]).noise,
                                  np.diag([1.0, 4.0, 9.0]))
    np.testing.assert_array_equal(RangeBearing(sigma_range=2.0, sigma_bearing=0.5).noise,
                                  np.diag([4.0, 0.25]))
    np.testing.assert_array_equal(MultipathDelay(sigma=[1e-3, 2e-3]).noise,
                                  np.diag([1e-6, 4e-6]))
    np.testing.assert_array_equal(Bearing(sigma=0.1).noise, [[0.1**2]])
