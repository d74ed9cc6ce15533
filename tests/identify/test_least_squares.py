"""Batch least squares for the vessel coefficients (``trackkit.identify.least_squares``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trackkit.identify import (
    EQUATIONS,
    NoiseLevels,
    coefficient_nees,
    least_squares,
    programme,
    relative_error,
)
from trackkit.models.manoeuvring import reference_vessel

REF = reference_vessel()
NO_NOISE = NoiseLevels(0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def exact():
    """Noise-free states of the identifier's own discrete model (substeps=1)."""
    return programme(1, seed=0, substeps=1, noise=NO_NOISE)


def test_noise_free_discrete_data_give_all_16_coefficients_exactly(exact):
    fit = least_squares(exact.x, exact.s, exact.dt, starts=exact.starts)
    assert relative_error(fit.theta, REF.theta).max() < 1e-9
    assert np.all(fit.residual_std < 1e-10)
    assert fit.rows[0] == exact.t.size - len(exact.segments)
    # column scaling keeps the problems well conditioned (the surge columns move together)
    assert np.all(fit.condition < 1e3)


def test_joins_and_missing_samples_are_left_out(exact):
    # without the joins the jumps between trials enter the fit
    fit = least_squares(exact.x, exact.s, exact.dt)
    assert relative_error(fit.theta, REF.theta).max() > 1e-3
    # a missing sample removes the two pairs it belongs to, and nothing else changes
    x = exact.x.copy()
    x[0, 100] = np.nan
    fit = least_squares(x, exact.s, exact.dt, starts=exact.starts)
    assert fit.rows[0] == exact.t.size - len(exact.segments) - 2
    assert relative_error(fit.theta, REF.theta).max() < 1e-9


def test_batched_equals_runs_one_at_a_time():
    rec = programme(4, seed=5)
    batch = least_squares(rec.z, rec.s, rec.dt, starts=rec.starts)
    for i in range(4):
        one = least_squares(rec.z[i], rec.s[i], rec.dt, starts=rec.starts)
        np.testing.assert_array_equal(one.theta, batch.theta[i])
        np.testing.assert_array_equal(one.cov, batch.cov[i])
        np.testing.assert_array_equal(one.residual_std, batch.residual_std[i])


def test_the_equations_are_separate_problems(exact):
    fit = least_squares(exact.x, exact.s, exact.dt, starts=exact.starts)
    block = np.zeros((16, 16), bool)
    for cols in EQUATIONS:
        block[np.ix_(cols, cols)] = True
    np.testing.assert_array_equal(fit.cov[0][~block], 0.0)


def test_covariance_is_right_for_a_white_equation_error():
    # Exact states of the discrete model driven by process noise w ~ N(0, q T): the equation
    # error is white with variance q / T and the regressors are exact, so least squares is
    # unbiased and its stated covariance is the true one. Over 200 runs the 16-dimensional
    # NEES averages 16, with a standard error of sqrt(2 * 16 / 200) = 0.4 (its mean lies in
    # 16 +/- 1.6, i.e. 4 standard errors, with > 99.99% confidence); the residual sd
    # estimates sqrt(q / T) per equation.
    q = np.array([1e-4, 1e-4, 1e-6])
    rec = programme(200, seed=21, substeps=1, noise=NO_NOISE, q=q)
    fit = least_squares(rec.x, rec.s, rec.dt, starts=rec.starts)
    nees = coefficient_nees(fit.theta, fit.cov, REF.theta)
    assert abs(nees.mean() - 16.0) < 4 * math.sqrt(2 * 16 / 200)
    np.testing.assert_allclose(np.median(fit.residual_std, 0), np.sqrt(q / rec.dt), rtol=0.02)
    # and the spread over runs matches the stated standard deviations (sway and yaw; the
    # sample sd of 200 runs has a relative standard error of 5%: 0.2 is 4 of them)
    sd_stated = np.sqrt(np.diagonal(fit.cov, axis1=-2, axis2=-1)).mean(0)
    np.testing.assert_allclose(fit.theta.std(0)[9:], sd_stated[9:], rtol=0.2)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"x": np.zeros((5, 2))}, "x has shape"),
    ({"x": np.zeros((1, 3))}, "x has shape"),
    ({"s": np.zeros((4, 2))}, "s has shape"),
    ({"dt": -1.0}, "dt = "),
    ({"starts": np.zeros(3, bool)}, "starts"),
    ({"norm": 1.0}, "norm"),
])
def test_bad_input_names_the_field(kwargs, match):
    args = {"x": np.ones((5, 3)), "s": np.ones((5, 2)), "dt": 1.0} | kwargs
    with pytest.raises(ValueError, match=match):
        least_squares(**args)


def test_too_few_samples_and_absent_excitation_are_reported(exact):
    with pytest.raises(ValueError, match="usable sample pairs"):
        least_squares(exact.x[:, :8], exact.s[:, :8], 1.0)
    # the acceleration run alone has no nozzle: the sway and yaw nozzle columns are zero
    seg = exact.segment("acceleration")
    with pytest.raises(ValueError, match="identically zero"):
        least_squares(exact.x[:, seg], exact.s[:, seg], 1.0)
