"""The identification trial programme (``trackkit.identify.programme``): structure, the
two truths, the noise and per-run seeding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackkit.identify import DEFAULT_PROGRAMME, NoiseLevels, TrialSpec, programme
from trackkit.models.manoeuvring import mean_input, reference_vessel, step, straight_line_speed
from trackkit.sim import seatrials

REF = reference_vessel()


@pytest.fixture(scope="module")
def rec():
    return programme(100, seed=42)


def test_structure(rec):
    names = [s.name for s in rec.segments]
    assert names == [t.name for t in DEFAULT_PROGRAMME]
    K = rec.t.size
    assert K == 657 and rec.segments[-1].stop == K
    assert rec.z.shape == rec.x.shape == rec.pose.shape == (100, K, 3)
    assert rec.s.shape == (100, K, 2) and rec.gps.shape == (100, K, 2)
    assert rec.heading.shape == (100, K)
    np.testing.assert_array_equal(np.flatnonzero(rec.starts), [s.start for s in rec.segments])
    for a, b in zip(rec.segments[:-1], rec.segments[1:], strict=True):
        assert a.stop == b.start
    np.testing.assert_array_equal(rec.t, np.arange(K) * 1.0)
    # every trial starts at its origin, heading north, at the steady speed of its rpm
    for seg in rec.segments:
        k = seg.start
        np.testing.assert_array_equal(rec.pose[:, k], 0.0)
        np.testing.assert_allclose(rec.x[:, k, 0], straight_line_speed(REF.theta, rec.s[0, k, 1],
                                                                       REF.norm), rtol=1e-12)
        np.testing.assert_array_equal(rec.x[:, k, 1:], 0.0)


def test_inputs_excite_what_the_identification_needs(rec):
    s = rec.s[0]
    zz20, zz10 = rec.segment("zigzag_20"), rec.segment("zigzag_10")
    np.testing.assert_allclose(np.abs(s[zz20, 0]).max(), math.radians(20), rtol=1e-12)
    np.testing.assert_allclose(np.abs(s[zz10, 0]).max(), math.radians(10), rtol=1e-12)
    # the zig-zags reverse the nozzle; the turns go both ways
    assert np.sum(np.diff(np.sign(s[zz20, 0][s[zz20, 0] != 0])) != 0) >= 8
    assert s[rec.segment("turn_port"), 0].min() < 0 < s[rec.segment("turn_starboard"), 0].max()
    # engine speed changes (the surge terms need them) and a second steady speed
    acc, dec = s[rec.segment("acceleration"), 1], s[rec.segment("deceleration"), 1]
    assert acc[0] == 1000.0 and acc[-1] == 2000.0 and dec[-1] == 1200.0
    np.testing.assert_array_equal(s[rec.segment("zigzag_20_1500"), 1], 1500.0)


def test_the_same_truth_as_seatrials(rec):
    seg = rec.segment("zigzag_20")
    z = seatrials.zigzag(REF.theta, REF.norm, delta=math.radians(20), alpha=math.radians(20),
                         rpm=2000.0, commands=9, duration=120.0)
    np.testing.assert_array_equal(rec.x[3, seg, 2], z.r)
    np.testing.assert_array_equal(rec.s[3, seg, 0], z.delta)
    np.testing.assert_array_equal(rec.pose[3, seg, 0], z.east)


def test_substeps_one_is_the_identifiers_discrete_model():
    rec = programme(1, seed=0, substeps=1)
    x, s = rec.x[0], rec.s[0]
    pred = step(x[:-1], mean_input(s[:-1], s[1:]), REF.theta, rec.dt, REF.norm)
    inside = ~rec.starts[1:]
    np.testing.assert_allclose(pred[inside], x[1:][inside], rtol=1e-13, atol=1e-15)
    # and the near-continuous default is not (an Euler step of 1 s misses by cm/s)
    rec10 = programme(1, seed=0)
    x10, s10 = rec10.x[0], rec10.s[0]
    pred10 = step(x10[:-1], mean_input(s10[:-1], s10[1:]), REF.theta, 1.0, REF.norm)
    assert np.abs(pred10[inside] - x10[1:][inside])[:, 0].max() > 0.02


def test_measurement_noise_has_the_stated_levels(rec):
    # 100 x 657 draws per component: the sample sd is within 1.5% of the truth at > 99.99%
    # (its relative standard error is 1/sqrt(2 N) = 0.28%)
    e = (rec.z - rec.x).reshape(-1, 3)
    np.testing.assert_allclose(e.std(0), rec.noise.body, rtol=0.015)
    assert np.all(np.abs(e.mean(0)) < 5 * rec.noise.body / math.sqrt(e.shape[0]))
    g = (rec.gps - rec.pose[..., :2]).reshape(-1, 2)
    np.testing.assert_allclose(g.std(0), 2.5, rtol=0.015)
    np.testing.assert_allclose((rec.heading - rec.pose[..., 2]).std(), math.radians(0.2),
                               rtol=0.015)
    np.testing.assert_allclose(rec.noise.body, [0.05, 0.05, math.radians(0.1)])
    # uncorrelated between u and v, and between runs
    assert abs(np.corrcoef(e[:, 0], e[:, 1])[0, 1]) < 5 / math.sqrt(e.shape[0])
    runs = (rec.z - rec.x)[:, :, 0]
    assert abs(np.corrcoef(runs[0], runs[1])[0, 1]) < 5 / math.sqrt(rec.t.size)


def test_a_run_depends_on_seed_and_run_only():
    q = [1e-4, 1e-4, 1e-7]
    full = programme(5, seed=8, q=q)
    block = programme([3, 4], seed=8, q=q)
    for name in ("x", "z", "gps", "heading", "s", "pose"):
        np.testing.assert_array_equal(getattr(block, name), getattr(full, name)[3:], name)
    # process noise makes the runs' truths differ, and a new seed changes the draws
    assert not np.array_equal(full.x[0], full.x[1])
    other = programme([3], seed=9, q=q)
    assert not np.array_equal(other.z[0], full.z[3])


def test_zero_noise_gives_the_truth():
    rec = programme(2, seed=1, noise=NoiseLevels(0.0, 0.0, 0.0))
    np.testing.assert_array_equal(rec.z, rec.x)
    np.testing.assert_array_equal(rec.gps, rec.pose[..., :2])


def test_a_custom_programme():
    trials = (TrialSpec("turn", "turn", {"delta": 0.3, "rpm": 1800.0, "duration": 30.0}),
              TrialSpec("acc", "acceleration", {"rpm_start": 1800.0, "rpm_end": 2000.0,
                                                "duration": 20.0}))
    rec = programme(3, seed=1, trials=trials, dt=0.5)
    assert rec.t.size == 61 + 41 and rec.dt == 0.5
    assert rec.segment("acc") == slice(61, 102)
    with pytest.raises(KeyError, match="nope"):
        rec.segment("nope")


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"runs": 0}, "runs"),
    ({"runs": []}, "runs"),
    ({"trials": (TrialSpec("x", "spiral", {}),)}, "kind"),
    ({"trials": ()}, "trials"),
    ({"noise": NoiseLevels([0.1, -0.1, 0.1], 1.0, 0.1)}, "noise.body"),
    ({"noise": NoiseLevels(0.1, np.nan, 0.1)}, "noise.gps"),
    ({"truth": "reference"}, "truth"),
    ({"substeps": 0}, "substeps"),
])
def test_bad_input_names_the_field(kwargs, field):
    args = {"runs": 2, "seed": 1} | kwargs
    with pytest.raises(ValueError, match=field):
        programme(**args)


def test_the_old_time_step_keyword_is_refused_naming_dt():
    from trackkit.identify import least_squares, programme

    with pytest.raises(TypeError, match="'T' is now spelled 'dt'"):
        programme(1, 0, T=1.0)
    with pytest.raises(TypeError, match="'T' is now spelled 'dt'"):
        least_squares(np.zeros((5, 3)), np.zeros((5, 2)), T=1.0)
