"""Sea-trial simulators of Zolfagharnasab and Seif (2025) (trackkit.sim.seatrials): the reference
vessel's turning circle against the paper's D/L, port/starboard mirror images, per-run zig-zag
switching, batches equal to single runs bit for bit, the discrete model at one sub-step, the rate
limit and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from trackkit.eval.manoeuvres import turning_metrics
from trackkit.models.manoeuvring import (
    IDENTITY,
    KNOT,
    integrate_pose,
    naji7,
    paper_coefficients,
    reference_vessel,
    step,
)
from trackkit.sim.seatrials import acceleration_run, turning_circle, zigzag

REF = reference_vessel()
TH, NORM = REF.theta, REF.norm
L = naji7().length_overall
DEG = np.pi / 180


def test_reference_turning_circle_matches_the_paper():
    """18 kn, 20 deg nozzle, 2000 rpm: diameter about 100 m, D/L about 5 (paper: 100 m / 20 m),
    inside the paper's 2-7 band; both sides; at least 540 deg."""
    tr = turning_circle(TH, NORM, delta=20 * DEG, rpm=2000.0, side=np.array([1.0, -1.0]))
    assert tr.u[:, 0] == pytest.approx(18 * KNOT)
    assert np.all(np.abs(tr.psi[:, -1]) >= 3 * np.pi)
    assert np.abs(tr.psi[:, -2]).min() < 3 * np.pi  # stopped at the first sample past 540
    m = turning_metrics(tr.t, tr.east, tr.north, tr.psi, L)
    assert np.all((m.diameter_to_length >= 4.5) & (m.diameter_to_length <= 5.5))
    assert np.all((m.diameter_to_length >= 2) & (m.diameter_to_length <= 7))
    assert np.all((m.tactical_diameter / L >= 4.5) & (m.tactical_diameter / L <= 5.5))
    speed = np.hypot(tr.u[:, -1], tr.v[:, -1])
    assert np.all((speed / tr.u[:, 0] > 0.6) & (speed / tr.u[:, 0] < 0.85))  # speed loss
    assert tr.v[0, -1] < 0 < tr.r[0, -1]  # starboard turn: drift to port, bow inside


def test_port_and_starboard_turns_mirror_each_other():
    tr = turning_circle(TH, NORM, delta=20 * DEG, rpm=2000.0, side=np.array([1.0, -1.0]),
                        duration=90.0)
    for name, sign in (("u", 1), ("v", -1), ("r", -1), ("delta", -1), ("n", 1), ("east", -1),
                       ("north", 1), ("psi", -1)):
        a = getattr(tr, name)
        np.testing.assert_allclose(a[1], sign * a[0], rtol=1e-12, atol=1e-9, err_msg=name)


def test_batched_runs_equal_single_runs_bit_for_bit():
    theta = np.stack([TH, TH * 1.05, TH * 0.95])
    side = np.array([1.0, -1.0, 1.0])
    delta = np.array([20.0, 10.0, 30.0]) * DEG
    alpha = np.array([20.0, 10.0, 15.0]) * DEG
    tb = turning_circle(theta, NORM, delta=delta, rpm=2000.0, speed=9.0, side=side,
                        duration=60.0)
    zb = zigzag(theta, NORM, delta=delta, alpha=alpha, rpm=2000.0, speed=9.0, side=side,
                duration=80.0)
    for i in range(3):
        t1 = turning_circle(theta[i], NORM, delta=delta[i], rpm=2000.0, speed=9.0,
                            side=side[i], duration=60.0)
        z1 = zigzag(theta[i], NORM, delta=delta[i], alpha=alpha[i], rpm=2000.0, speed=9.0,
                    side=side[i], duration=80.0)
        for batch, one in ((tb, t1), (zb, z1)):
            for name in one._fields[1:]:
                np.testing.assert_array_equal(getattr(batch, name)[i], getattr(one, name),
                                              err_msg=name)


def test_batched_noisy_runs_with_a_generator_per_run_equal_single_runs():
    seeds = [11, 12]
    gens = [np.random.default_rng(s) for s in seeds]
    q = [1e-3, 1e-3, 1e-5]
    zb = zigzag(TH, NORM, delta=np.array([10.0, 20.0]) * DEG, alpha=np.array([10, 20]) * DEG,
                rpm=2000.0, duration=300.0, q=q, rng=gens)
    for i, s in enumerate(seeds):
        z1 = zigzag(TH, NORM, delta=[10.0, 20.0][i] * DEG, alpha=[10, 20][i] * DEG,
                    rpm=2000.0, duration=300.0, q=q, rng=[np.random.default_rng(s)])
        np.testing.assert_array_equal(zb.psi[i], z1.psi)
    clean = zigzag(TH, NORM, delta=10 * DEG, alpha=10 * DEG, rpm=2000.0, duration=300.0)
    assert 0 < np.abs(zb.u[0] - clean.u).max() < 1.0


def test_one_generator_for_the_batch_is_reproducible():
    a = turning_circle(TH, NORM, delta=20 * DEG, rpm=2000.0, side=np.array([1.0, -1.0]),
                       duration=30.0, q=1e-4, rng=np.random.default_rng(5))
    b = turning_circle(TH, NORM, delta=20 * DEG, rpm=2000.0, side=np.array([1.0, -1.0]),
                       duration=30.0, q=1e-4, rng=np.random.default_rng(5))
    np.testing.assert_array_equal(a.east, b.east)


def test_zigzag_switches_per_run_on_its_own_heading():
    alpha = np.array([10.0, 20.0]) * DEG
    h = 0.02
    z = zigzag(TH, NORM, delta=alpha, alpha=alpha, rpm=2000.0, substeps=50)
    for i in range(2):
        d, e = z.delta[i], z.psi[i]
        # five commands: four reversals, each leaving the hard-over angle in the sample
        # interval in which the heading reached +/- alpha (detected within one sub-step)
        rev = np.flatnonzero((np.abs(d[:-1]) >= alpha[i] * (1 - 1e-12))
                             & (np.abs(d[1:]) < np.abs(d[:-1])))
        assert rev.size == 4 and d[1] > 0
        for k in rev:
            y = np.sign(d[k]) * e
            assert y[k + 1] >= alpha[i]
            assert y[k] <= alpha[i] + np.abs(z.r[i, k]) * h
        assert np.sign(d[rev]).tolist() == [1, -1, 1, -1]
        # after the fifth command the heading swings back to +alpha before the record ends
        assert e[rev[-1] + 1:].max() >= alpha[i]
    assert np.all(z.psi[:, -1] < np.pi)  # ...and the record stops soon after


def test_one_substep_is_the_papers_discrete_model():
    z = zigzag(TH, NORM, delta=20 * DEG, alpha=20 * DEG, rpm=2000.0, substeps=1,
               duration=60.0)
    x = np.stack([z.u, z.v, z.r], -1)
    s = np.stack([z.delta, z.n], -1)
    s_m = 0.5 * (s[:-1] + s[1:])
    np.testing.assert_array_equal(x[1:], step(x[:-1], s_m, TH, 1.0, NORM))
    pose = integrate_pose(x, 1.0)
    np.testing.assert_array_equal(pose[:, 0], z.east)
    np.testing.assert_array_equal(pose[:, 2], z.psi)


def test_nozzle_rate_limit_is_respected():
    rate = 5 * DEG
    z = zigzag(TH, NORM, delta=20 * DEG, alpha=10 * DEG, rpm=2000.0, rate_limit=rate,
               duration=60.0)
    assert np.abs(np.diff(z.delta)).max() <= rate * 1.0 + 1e-12
    assert np.abs(np.diff(z.delta)).max() == pytest.approx(rate)


def test_acceleration_run_reaches_the_new_straight_line_speed():
    a = acceleration_run(TH, NORM, rpm_start=1000.0, rpm_end=2000.0, t_step=10.0,
                         duration=120.0)
    assert a.u[0] == pytest.approx(9 * KNOT)  # equilibrium speed is proportional to rpm
    assert a.u[10] == pytest.approx(9 * KNOT)
    assert a.n[10] == 1000.0 and a.n[15] == 2000.0 and a.n[12] == pytest.approx(1400.0)
    assert a.u[-1] == pytest.approx(18 * KNOT, rel=1e-3)
    assert np.all(np.diff(a.u[10:]) >= 0)
    assert np.all(a.v == 0) and np.all(a.r == 0) and np.all(a.delta == 0)


def test_the_printed_coefficients_diverge_in_a_simulated_trial():
    with np.errstate(all="ignore"):
        tr = turning_circle(paper_coefficients().theta, IDENTITY, delta=20 * DEG, rpm=2000.0,
                            speed=18 * KNOT, duration=20.0)
    assert not np.all(np.isfinite(tr.u)) or np.abs(tr.u).max() > 1e9


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"rate_limit": -1.0}, "rate_limit"),
    ({"rate_limit": 0.0}, "rate_limit"),
    ({"dt": np.nan}, "dt"),
    ({"dt": np.inf}, "dt"),
    ({"substeps": 0}, "substeps"),
    ({"duration": -5.0}, "duration"),
    ({"side": 0.0}, "side"),
    ({"rpm": -100.0}, "rpm"),
    ({"q": [-1.0, 0, 0], "rng": np.random.default_rng(0)}, "q"),
    ({"q": [1.0, 0, 0]}, "rng"),
    ({"q": 1e-3, "rng": [np.random.default_rng(0)] * 3}, "rng"),
    ({"delta": [0.1, 0.2, 0.3], "side": [1.0, -1.0]}, "run axes"),
    ({"theta": np.zeros(15)}, "theta"),
    ({"norm": "prime"}, "norm"),
])
def test_bad_input_names_the_field(kwargs, field):
    args = {"theta": TH, "norm": NORM, "delta": 20 * DEG, "rpm": 2000.0, "duration": 10.0}
    args.update(kwargs)
    theta, norm = args.pop("theta"), args.pop("norm")
    with pytest.raises(ValueError, match=field):
        turning_circle(theta, norm, **args)


def test_no_straight_line_speed_needs_an_explicit_speed():
    with pytest.raises(ValueError, match="speed"):
        turning_circle(paper_coefficients().theta, IDENTITY, delta=0.3, rpm=2000.0)
    with pytest.raises(ValueError, match="alpha"):
        zigzag(TH, NORM, delta=0.1, alpha=0.0, rpm=2000.0)


def test_the_old_time_step_keyword_is_refused_naming_dt():
    with pytest.raises(TypeError, match="'T' is now spelled 'dt'"):
        turning_circle(TH, NORM, delta=20 * DEG, rpm=2000.0, duration=10.0, T=1.0)
