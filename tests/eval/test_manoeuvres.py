"""Manoeuvring metrics and IMO criteria (trackkit.eval.manoeuvres) on synthetic records whose
answers are known in closed form, and on the reference vessel's trials."""

from __future__ import annotations

import numpy as np
import pytest

from trackkit.angles import wrap
from trackkit.eval.manoeuvres import imo_criteria, turning_metrics, zigzag_metrics
from trackkit.models.manoeuvring import naji7, reference_vessel
from trackkit.sim.seatrials import turning_circle, zigzag

DEG = np.pi / 180


def _zigzag_trace(t, A, w):
    """Heading A_j sin(w t) on the j-th half period: three half-waves of amplitudes A."""
    half = np.minimum((w * t // np.pi).astype(int), 2)
    return np.asarray(A)[half] * np.sin(w * t)


def test_zigzag_metrics_on_a_known_heading_trace():
    w, a = 2 * np.pi / 30.0, 10 * DEG  # 30 s period
    A = np.array([16.0, 19.0, 14.0]) * DEG
    t = np.arange(0, 60.0, 0.05)
    psi = _zigzag_trace(t, A, w)
    speed = 5.0
    east, north = np.zeros_like(t), speed * t  # distance sailed = 5 t
    m = zigzag_metrics(t, psi, a, east, north)
    t1 = np.arcsin(a / A[0]) / w
    t3 = (2 * np.pi + np.arcsin(a / A[2])) / w
    assert m.initial_turning_time == pytest.approx(t1, abs=1e-3)
    assert m.initial_turning_distance == pytest.approx(speed * t1, abs=5e-3)
    assert m.time_to_check_yaw == pytest.approx(np.pi / (2 * w) - t1, abs=1e-3)
    assert m.first_overshoot == pytest.approx(A[0] - a, abs=1e-6)
    assert m.second_overshoot == pytest.approx(A[1] - a, abs=1e-6)
    assert m.period == pytest.approx(t3 - t1, abs=1e-3)


def test_zigzag_metrics_are_batched_mirror_and_wrap_safe():
    w, a = 2 * np.pi / 24.0, 20 * DEG
    t = np.arange(0, 50.0, 0.5)
    psi = _zigzag_trace(t, np.array([30.0, 35.0, 28.0]) * DEG, w)
    port = wrap(np.pi - psi + 1e-3)  # port first, starting near south: wraps through +/- pi
    batch = zigzag_metrics(t, np.stack([psi, port]), a, side=np.array([1.0, -1.0]))
    one = zigzag_metrics(t, psi, a)
    for name in one._fields[:1] + one._fields[2:]:
        np.testing.assert_allclose(getattr(batch, name), getattr(one, name), rtol=1e-9,
                                   err_msg=name)
    assert np.all(np.isnan(batch.initial_turning_distance))


def test_zigzag_metrics_are_nan_for_events_that_never_happen():
    t = np.arange(0, 20.0, 1.0)
    m = zigzag_metrics(t, 0.005 * t, 10 * DEG)  # a slow swing that never reaches 10 deg
    assert np.isnan(m.initial_turning_time) and np.isnan(m.first_overshoot)
    assert np.isnan(m.period)


@pytest.mark.parametrize("psi0", [0.0, 0.5, -2.0])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_turning_metrics_on_a_circle(psi0, side):
    R, w = 40.0, 1 * DEG  # one degree per second
    t = np.arange(0, 600.0)
    th = w * t
    # starboard circle from the origin heading north, centre (R, 0): advance R, transfer R
    x, y = R - R * np.cos(th), R * np.sin(th)
    x = side * x  # a port turn is the mirror image
    c, s = np.cos(psi0), np.sin(psi0)  # rotate the track to initial heading psi0 (clockwise)
    east, north = 3.0 + c * x + s * y, -7.0 - s * x + c * y
    m = turning_metrics(t, east, north, psi0 + side * th, length=10.0)
    assert m.advance == pytest.approx(R, rel=1e-9)
    assert m.transfer == pytest.approx(R, rel=1e-9)
    assert m.tactical_diameter == pytest.approx(2 * R, rel=1e-9)
    assert m.steady_diameter == pytest.approx(2 * R, rel=1e-9)
    assert m.diameter_to_length == pytest.approx(8.0, rel=1e-9)


def test_imo_limits_depend_on_length_over_speed():
    from trackkit.eval.manoeuvres import ZigZagMetrics

    z = ZigZagMetrics(*(np.array([5.0]),) * 2, np.array([3.0]), np.array([14.0 * DEG]),
                      np.array([30.0 * DEG]), np.array([20.0]))
    L = 100.0
    cases = {5.0: (10.0, 25.0), 20.0: (15.0, 32.5), 40.0: (20.0, 40.0)}  # L/V -> limits
    for LV, (first, second) in cases.items():
        c = imo_criteria(L, L / LV, zigzag10=z)
        assert c["first_overshoot_10"].upper == pytest.approx(first * DEG)
        assert c["second_overshoot_10"].upper == pytest.approx(second * DEG)
        assert bool(c["first_overshoot_10"].passed[0]) == (14.0 <= first)
        assert bool(c["second_overshoot_10"].passed[0]) == (30.0 <= second)
        assert c["initial_turning"].upper == 250.0
    c = imo_criteria(L, np.array([2.0, 10.0]), zigzag10=z)  # batched: L/V = 50 s and 10 s
    assert c["first_overshoot_10"].passed.tolist() == [True, False]  # 20 deg, 10 deg


def test_imo_turning_checks_and_the_papers_band():
    from trackkit.eval.manoeuvres import TurningMetrics

    L = 20.0
    tm = TurningMetrics(np.array([80.0, 95.0]), np.array([40.0, 40.0]),
                        np.array([99.0, 101.0]), np.array([30.0, 150.0]),
                        np.array([1.5, 7.5]))
    c = imo_criteria(L, 9.0, turning=tm)
    assert c["advance"].passed.tolist() == [True, False]  # 4.5 L = 90 m
    assert c["tactical_diameter"].passed.tolist() == [True, False]  # 5 L = 100 m
    assert c["paper_band"].passed.tolist() == [False, False]
    assert (c["paper_band"].lower, c["paper_band"].upper) == (2.0, 7.0)


def test_reference_vessel_trials_against_imo():
    """Reference vessel: turning at the maximum nozzle (30 deg) and 10/10, 20/20 at 18 kn."""
    ref = reference_vessel()
    L, V = naji7().length_overall, ref.design["speed"]
    tr = turning_circle(ref.theta, ref.norm, delta=ref.design["max_delta"], rpm=2000.0)
    tm = turning_metrics(tr.t, tr.east, tr.north, tr.psi, L)
    z10 = zigzag(ref.theta, ref.norm, delta=10 * DEG, alpha=10 * DEG, rpm=2000.0)
    m10 = zigzag_metrics(z10.t, z10.psi, 10 * DEG, z10.east, z10.north)
    z20 = zigzag(ref.theta, ref.norm, delta=20 * DEG, alpha=20 * DEG, rpm=2000.0)
    m20 = zigzag_metrics(z20.t, z20.psi, 20 * DEG)
    c = imo_criteria(L, V, turning=tm, zigzag10=m10, zigzag20=m20)
    assert set(c) == {"advance", "tactical_diameter", "paper_band", "initial_turning",
                      "first_overshoot_10", "second_overshoot_10", "first_overshoot_20"}
    assert all(bool(v.passed) for v in c.values())
    assert 0 < m10.first_overshoot < m20.first_overshoot < 25 * DEG
    assert 0 < m10.time_to_check_yaw < m10.period


@pytest.mark.parametrize(("call", "field"), [
    (lambda: zigzag_metrics([0, 1, 1], [0, 0, 0], 0.1), "t"),
    (lambda: zigzag_metrics([0, 1, 2], [0, 0], 0.1), "psi"),
    (lambda: zigzag_metrics([0, 1, 2], [0, 0, 0], -0.1), "alpha"),
    (lambda: zigzag_metrics([0, 1, 2], [0, 0, 0], 0.1, side=0.0), "side"),
    (lambda: turning_metrics([0, 1, 2], [0, 0, 0], [0, 0], [0, 0, 0], 10.0), "north"),
    (lambda: turning_metrics([0, 1, 2], [0, 0, 0], [0, 0, 0], [0, 0, 0], 0.0), "length"),
    (lambda: imo_criteria(20.0, 0.0), "speed"),
    (lambda: imo_criteria(np.nan, 5.0), "length"),
])
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()
