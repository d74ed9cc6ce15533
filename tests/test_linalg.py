"""Batched covariance helpers (trackkit.linalg): cholesky, solve_psd, check_covariance."""

from __future__ import annotations

import numpy as np
import pytest

from trackkit.linalg import (
    check_covariance,
    cholesky,
    quadratic_form,
    solve_psd,
    symmetrize,
)


def test_symmetrize_is_exact_and_batched():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((3, 2, 4, 4))
    S = symmetrize(A)
    np.testing.assert_array_equal(S, np.swapaxes(S, -1, -2))
    np.testing.assert_allclose(S, 0.5 * (A + np.swapaxes(A, -1, -2)), rtol=0, atol=0)


# --------------------------------------------------------------------------------------------
# cholesky
# --------------------------------------------------------------------------------------------


def test_cholesky_factor_batched(num):
    rng = np.random.default_rng(1)
    P = num.spd(rng, (5, 3), 4)
    L = cholesky(P, "P")
    np.testing.assert_allclose(L @ np.swapaxes(L, -1, -2), P, rtol=1e-12, atol=1e-10)
    assert np.all(np.triu(L, 1) == 0)


def test_cholesky_error_names_quantity_and_row():
    P = np.broadcast_to(np.eye(3), (4, 3, 3)).copy()
    P[2] = np.diag([1.0, -2.0, 1.0])
    with pytest.raises(ValueError) as ei:
        cholesky(P, "predicted state covariance")
    msg = str(ei.value)
    assert "predicted state covariance" in msg
    assert "positive definite" in msg
    assert "(2,)" in msg  # first failing batch row
    assert "(4, 3, 3)" in msg  # shape


def test_cholesky_error_unbatched_names_quantity():
    with pytest.raises(ValueError, match="my covariance"):
        cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]), "my covariance")


def test_cholesky_does_not_repair_semidefinite():
    # a singular PSD matrix is not positive definite: reported, no jitter added
    P = np.array([[1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(ValueError, match="not positive definite"):
        cholesky(P, "P")


# --------------------------------------------------------------------------------------------
# solve_psd
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("m", [1, 2, 3, 5])
@pytest.mark.parametrize("k", [1, 4])
def test_solve_psd_matches_numpy(num, m, k):
    rng = np.random.default_rng(10 * m + k)
    S = num.spd(rng, (6, 2), m, cond=1e4)
    B = rng.standard_normal((6, 2, m, k))
    got = solve_psd(S, B)
    want = np.linalg.solve(S, B)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("m", [1, 2, 3, 5])
def test_solve_psd_broadcast_unbatched_S(num, m):
    rng = np.random.default_rng(m)
    S = num.spd(rng, (), m)
    B = rng.standard_normal((7, m, 1))
    got = solve_psd(S, B)
    want = np.stack([np.linalg.solve(S, b) for b in B])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("m", [1, 2, 3, 5])
def test_solve_psd_rejects_indefinite_with_name(m):
    S = np.broadcast_to(np.eye(m), (3, m, m)).copy()
    S[1, 0, 0] = -1.0
    with pytest.raises(ValueError) as ei:
        solve_psd(S, np.ones((3, m, 1)), name="innovation covariance S")
    assert "innovation covariance S" in str(ei.value)
    assert "positive definite" in str(ei.value)


def test_quadratic_form_matches_direct(num):
    rng = np.random.default_rng(5)
    for m in (1, 2, 3):
        S = num.spd(rng, (8,), m)
        r = rng.standard_normal((8, m))
        want = np.einsum("bi,bij,bj->b", r, np.linalg.inv(S), r)
        np.testing.assert_allclose(quadratic_form(S, r), want, rtol=1e-10)


# --------------------------------------------------------------------------------------------
# check_covariance
# --------------------------------------------------------------------------------------------


def test_check_covariance_accepts_valid_and_returns_float():
    P = np.eye(3, dtype=int) * 2
    out = check_covariance(P, "P", n=3)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, 2 * np.eye(3))
    # PSD but singular is accepted (semi-definite)
    check_covariance(np.zeros((2, 2)), "P", n=2)
    check_covariance(np.array([[1.0, 1.0], [1.0, 1.0]]), "P", n=2)


def test_check_covariance_does_not_modify_input():
    P = np.array([[2.0, 0.5], [0.5, 1.0]])
    before = P.copy()
    out = check_covariance(P, "P", n=2)
    np.testing.assert_array_equal(P, before)
    np.testing.assert_array_equal(out, before)


@pytest.mark.parametrize(
    "P, n, fragment",
    [
        (np.eye(3), 2, "(..., 2, 2)"),
        (np.ones((2, 3)), None, "(..., n, n)"),
        (np.ones(3), None, "(..., n, n)"),
        (np.ones((4, 3, 2)), 3, "(..., 3, 3)"),
    ],
)
def test_check_covariance_wrong_shape(P, n, fragment):
    with pytest.raises(ValueError) as ei:
        check_covariance(P, "prior.cov", n=n)
    msg = str(ei.value)
    assert "prior.cov" in msg
    assert str(np.shape(P)) in msg
    assert fragment in msg


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_check_covariance_non_finite(bad):
    P = np.broadcast_to(np.eye(2), (3, 2, 2)).copy()
    P[1, 0, 0] = bad
    with pytest.raises(ValueError) as ei:
        check_covariance(P, "prior.cov", n=2)
    assert "prior.cov" in str(ei.value)
    assert "non-finite" in str(ei.value)


def test_check_covariance_asymmetric_is_reported_not_repaired():
    P = np.array([[[1.0, 0.2], [0.2, 1.0]], [[1.0, 0.2], [0.2001, 1.0]]])
    with pytest.raises(ValueError) as ei:
        check_covariance(P, "prior.cov", n=2)
    msg = str(ei.value)
    assert "prior.cov" in msg
    assert "not symmetric" in msg
    assert "(1,)" in msg  # the offending batch row


def test_check_covariance_tiny_asymmetry_tolerated():
    P = np.array([[1.0, 0.2], [0.2 + 1e-13, 1.0]])
    check_covariance(P, "P", n=2)


def test_check_covariance_not_psd():
    P = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3, -1
    with pytest.raises(ValueError) as ei:
        check_covariance(P, "measurement noise R", n=2)
    msg = str(ei.value)
    assert "measurement noise R" in msg
    assert "positive semi-definite" in msg
    assert "-1" in msg  # smallest eigenvalue reported
    # psd=False skips only that check
    check_covariance(P, "R", n=2, psd=False)
