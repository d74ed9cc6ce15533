"""Angle wrapping to (-pi, pi] and weighted circular means (trackkit.angles)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from trackkit.angles import circular_mean, math_to_nautical, nautical_to_math, wrap

FAST = settings(max_examples=100, deadline=None, derandomize=True, database=None)
PI = np.pi

finite_angles = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


# --------------------------------------------------------------------------------------------
# wrap
# --------------------------------------------------------------------------------------------


def test_wrap_half_open_interval_endpoints():
    # (-pi, pi]: -pi is mapped to +pi and +pi stays +pi.
    assert wrap(-PI) == PI
    assert wrap(PI) == PI
    assert wrap(3 * PI) == PI
    assert wrap(-3 * PI) == PI
    assert wrap(0.0) == 0.0
    assert wrap(2 * PI) == 0.0


def test_wrap_known_values_and_shape():
    a = np.array([[0.5, -0.5, PI / 2 + 2 * PI], [-PI / 2 - 4 * PI, 7.0, -7.0]])
    expected = np.array([[0.5, -0.5, PI / 2], [-PI / 2, 7.0 - 2 * PI, -7.0 + 2 * PI]])
    out = wrap(a)
    assert out.shape == a.shape
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-12)


def test_wrap_just_inside_and_outside_the_cut():
    eps = 1e-9
    assert wrap(PI - eps) == pytest.approx(PI - eps, abs=1e-15)
    assert wrap(PI + eps) == pytest.approx(-PI + eps, abs=1e-12)
    assert wrap(-PI + eps) == pytest.approx(-PI + eps, abs=1e-15)
    assert wrap(-PI - eps) == pytest.approx(PI - eps, abs=1e-12)


@FAST
@given(finite_angles)
@example(-3.1415926535897927)  # nextafter(-pi, 0): inside (-pi, pi], must stay there
def test_wrap_range_and_equivalence(a):
    w = float(wrap(a))
    assert -PI < w <= PI
    # w differs from a by a whole number of turns
    turns = (a - w) / (2 * PI)
    assert abs(turns - round(turns)) < 1e-9 * max(1.0, abs(a))
    # same point on the circle
    assert np.cos(w) == pytest.approx(np.cos(a), abs=1e-9)
    assert np.sin(w) == pytest.approx(np.sin(a), abs=1e-9)


def test_wrap_stays_in_range_near_odd_multiples_of_pi():
    # Rounding in a - 2 pi ceil((a - pi) / 2 pi) must never push a result past +pi (or onto
    # -pi): the interval is (-pi, pi] for every finite input, including those within a few
    # ulps of an odd multiple of pi.
    k = np.arange(-200, 201)
    base = (2 * k + 1) * PI
    a = np.concatenate([np.nextafter(base, np.inf), np.nextafter(base, -np.inf), base,
                        [np.nextafter(-PI, 0.0), np.nextafter(PI, 4.0)]])
    w = wrap(a)
    bad = ~((w > -PI) & (w <= PI))
    assert not bad.any(), (
        f"{int(bad.sum())} of {a.size} results outside (-pi, pi], e.g. wrap({a[bad][0]!r}) = "
        f"{w[bad][0]!r}"
    )


@FAST
@given(st.floats(min_value=-PI, max_value=PI, exclude_min=True), st.integers(-50, 50))
def test_wrap_periodicity(a, k):
    # inside (-pi, pi] wrap is the identity, and shifting by k turns comes back (to rounding)
    assert wrap(a) == a
    back = float(wrap(a + 2 * PI * k))
    # the cut: a value within rounding of -pi may come back as +pi; compare on the circle
    d = abs(back - a)
    assert min(d, abs(d - 2 * PI)) < 1e-12 * (1 + abs(k))


@FAST
@given(finite_angles)
def test_wrap_idempotent(a):
    w = wrap(a)
    assert wrap(w) == w


def test_nautical_math_conversion():
    # due north: nautical 0, math pi/2; due east: nautical pi/2, math 0
    assert nautical_to_math(0.0) == pytest.approx(PI / 2)
    assert nautical_to_math(PI / 2) == pytest.approx(0.0)
    assert math_to_nautical(PI) == pytest.approx(-PI / 2)  # due west
    a = np.linspace(-3, 3, 13)
    np.testing.assert_allclose(wrap(math_to_nautical(nautical_to_math(a)) - a), 0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# circular_mean
# --------------------------------------------------------------------------------------------


def _reference_mean(a, w):
    return np.arctan2(np.sum(w * np.sin(a)), np.sum(w * np.cos(a)))


def test_circular_mean_across_the_cut():
    # points symmetric about +-pi: the arithmetic mean is 0, the circular mean is pi
    a = np.array([PI - 0.1, -PI + 0.1])
    assert circular_mean(a) == pytest.approx(PI, abs=1e-12)
    # unequal weights pull towards the heavier side, across the cut
    m = float(circular_mean(a, weights=[3.0, 1.0]))
    assert m == pytest.approx(_reference_mean(a, np.array([3.0, 1.0])), abs=1e-12)
    assert PI - 0.1 < m < PI  # on the heavier point's side of pi, not near 0
    m2 = float(circular_mean(a, weights=[1.0, 3.0]))
    assert -PI < m2 < -PI + 0.1


def test_circular_mean_exact_weighted_value():
    # two points at -pi + 0.2 and pi - 0.4 with weights 1:1 -> mean at pi - 0.1 (wrapped)
    a = np.array([-PI + 0.2, PI - 0.4])
    assert float(circular_mean(a)) == pytest.approx(PI - 0.1, abs=1e-12)


def test_circular_mean_negative_weights_like_unscented():
    a = np.array([0.3, 0.5, 0.1])
    w = np.array([-0.5, 0.75, 0.75])
    assert float(circular_mean(a, w)) == pytest.approx(_reference_mean(a, w), abs=1e-12)


def test_circular_mean_result_in_half_open_interval():
    # a mean that lands exactly on -pi is reported as +pi
    a = np.array([-PI, -PI])
    assert float(circular_mean(a)) == PI


@FAST
@given(
    st.lists(st.floats(-20, 20), min_size=1, max_size=8),
    st.data(),
)
def test_circular_mean_matches_reference_and_is_shift_equivariant(angles, data):
    a = np.array(angles)
    w = np.array(data.draw(st.lists(st.floats(0.1, 5.0), min_size=a.size, max_size=a.size)))
    s, c = np.sum(w * np.sin(a)), np.sum(w * np.cos(a))
    if np.hypot(s, c) < 1e-3 * w.sum():
        return  # mean direction undefined (resultant ~ 0)
    m = float(circular_mean(a, w))
    assert -PI < m <= PI
    assert m == pytest.approx(np.arctan2(s, c), abs=1e-9) or abs(m - PI) < 1e-9
    # rotating every angle by delta rotates the mean by delta (mod 2 pi), also across the cut
    delta = data.draw(st.floats(-10, 10))
    m_shift = float(circular_mean(a + delta, w))
    diff = float(wrap(m_shift - (m + delta)))
    assert min(abs(diff), abs(abs(diff) - 2 * PI)) < 1e-8


def test_circular_mean_batched_last_axis_with_1d_weights():
    rng = np.random.default_rng(1)
    a = rng.uniform(-PI, PI, size=(6, 5))
    w = rng.uniform(0.1, 1.0, size=5)
    got = circular_mean(a, w)  # axis=-1
    want = np.array([_reference_mean(row, w) for row in a])
    assert got.shape == (6,)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_circular_mean_axis0_with_1d_weights_along_that_axis():
    # np.average semantics: 1-D weights have the length of the averaged axis and weight it.
    # A square input makes a wrong-axis weighting run silently instead of raising.
    rng = np.random.default_rng(2)
    a = rng.uniform(-PI, PI, size=(4, 4))
    w = np.array([1.0, 2.0, 3.0, 4.0])
    got = circular_mean(a, w, axis=0)
    want = np.array([_reference_mean(a[:, j], w) for j in range(4)])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_circular_mean_axis0_with_full_shape_weights():
    # weights with the same shape as the angles: sum w sin a along the requested axis
    rng = np.random.default_rng(3)
    a = rng.uniform(-PI, PI, size=(3, 4))
    w = rng.uniform(0.1, 1.0, size=(3, 4))
    got = circular_mean(a, w, axis=0)
    want = np.array([_reference_mean(a[:, j], w[:, j]) for j in range(4)])
    np.testing.assert_allclose(got, want, atol=1e-12)
