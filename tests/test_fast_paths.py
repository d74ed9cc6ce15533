"""The fast paths of the core-speed commit, pinned against the reference computations.

Each fast path switches on batch size or shape; every test here runs an input through the
fast path and through the plain computation it replaces (LAPACK, the textbook formula, the
same problem one row at a time, the sensor's own ``h`` and ``jacobian``) and compares.

Tolerances. Two float computations of the same quantity in a different order differ by a few
units in the last place of the *largest intermediate*, not of the result, so every tolerance
here is ``1e-12 * scale`` with ``scale`` the size of the inputs that are combined (for a
covariance update ``P+ = P- - correction``, ``max |P-|``; for a Cholesky factor,
``sqrt(max diag P)``, which bounds every entry of L). On these well-conditioned problems
(condition numbers <= 1e3) the observed differences are 1e-16 .. 4e-14 of that scale, so
1e-12 leaves a margin of 25x or more while still catching any wrong formula, index or sign
(which is wrong at the 1e-3 .. 1 level). Where both sides do exactly the same floating-point
operations (a fused ``linearize`` against ``h`` and ``jacobian``, the cheap angle wrap
against ``wrap``, exact symmetry) the comparison is exact.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest

import trackkit as tk
from trackkit import linalg
from trackkit.angles import wrap
from trackkit.filters import CKF, EKF, KF, UKF, kalman, kalman_fast
from trackkit.filters import sigma as sigma_mod
from trackkit.models import (
    AzimuthElevation,
    Bearing,
    BearingFrequency,
    ConstantAcceleration,
    ConstantVelocity,
    MultipathDelay,
    Position,
    RangeBearing,
    SensorBase,
    Sine,
    Stack,
)

PI = np.pi
EPS = np.finfo(float).eps
TOL = 1e-12  # relative to the scale of the combined inputs (see the module docstring)


def _spd(rng, shape, n, cond=1e3, scale=None):
    """Random SPD matrices, eigenvalues log-uniform in [1, cond], optionally scaled per
    matrix (``scale`` of shape ``shape``); exactly symmetric."""
    A = rng.standard_normal(shape + (n, n))
    Qm, _ = np.linalg.qr(A)
    ev = np.exp(rng.uniform(0.0, np.log(cond), size=shape + (n,)))
    P = (Qm * ev[..., None, :]) @ np.swapaxes(Qm, -1, -2)
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    if scale is not None:
        P = P * np.asarray(scale)[..., None, None]
    return P


def _close(actual, expected, scale, tol=TOL, what=""):
    """``|actual - expected| <= tol * scale`` elementwise (scale broadcasts), nan fails."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, f"{what}: {actual.shape} != {expected.shape}"
    err = np.abs(actual - expected)
    bound = tol * np.asarray(scale)
    bad = ~(err <= bound)
    assert not bad.any(), (
        f"{what}: {int(bad.sum())} entries off; max error/scale "
        f"{float(np.max(err / np.broadcast_to(scale, err.shape))):.3e}"
    )


def _cov_scale(P):
    """max |P| per matrix, shaped to broadcast against ``(..., n, n)``."""
    return np.abs(P).max(axis=(-1, -2), keepdims=True)


def _mean_scale(x, P):
    """Scale of a mean's rounding: its own size plus one standard deviation."""
    sd = np.sqrt(np.abs(np.diagonal(P, axis1=-2, axis2=-1)).max(-1))
    return (np.abs(x).max(-1) + sd)[..., None]


def _assert_symmetric(P, what=""):
    assert np.array_equal(P, np.swapaxes(P, -1, -2)), f"{what}: covariance not exactly symmetric"


# ============================================================================================
# 1. linalg: vectorised Cholesky for stacks of small matrices
# ============================================================================================

# batch sizes just below and at each threshold, and well above
BATCHES = sorted({199, 200, 299, 300, 1000, linalg.CHOL_MIN_BATCH - 1, linalg.CHOL_MIN_BATCH,
                  linalg.CHOL_MIN_BATCH_FULL - 1, linalg.CHOL_MIN_BATCH_FULL})


def test_thresholds_are_what_the_batches_straddle():
    # the batch sizes below were chosen around these values: keep them honest
    assert linalg.CHOL_MIN_BATCH == 200
    assert linalg.CHOL_MIN_BATCH_FULL == 300
    assert linalg.CHOL_MAX_N == 6


class _Spy:
    """Wraps a function, counting calls (to check which path a call took)."""

    def __init__(self, fun):
        self.fun, self.calls = fun, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        return self.fun(*args, **kwargs)


@pytest.mark.parametrize("n", range(1, 7))
@pytest.mark.parametrize("B", BATCHES)
def test_cholesky_fast_path_equals_lapack_row_by_row(n, B, monkeypatch):
    rng = np.random.default_rng(1000 * n + B)
    # magnitudes over six decades across rows: each row is held to its own scale
    P = _spd(rng, (B,), n, scale=10.0 ** rng.uniform(-3, 3, B))
    spy = _Spy(linalg.cholesky_t)
    monkeypatch.setattr(linalg, "cholesky_t", spy)
    L = linalg.cholesky(P, "P")
    assert spy.calls == (1 if B >= linalg.CHOL_MIN_BATCH_FULL else 0)
    assert L.shape == P.shape and L.flags.c_contiguous
    # every |L_ij| <= sqrt(P_ii): that is the scale of the factor's rounding
    scale = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1).max(-1))
    for i in range(B):
        Li = np.linalg.cholesky(P[i])
        _close(L[i], Li, scale[i], what=f"row {i}")
    assert np.all(np.triu(L, 1) == 0)  # exactly lower triangular
    # and a factor: L L^T = P (backward stable: a few eps of |P|)
    _close(L @ np.swapaxes(L, -1, -2), P, scale[:, None, None] ** 2, what="L L^T")


@pytest.mark.parametrize("n", range(1, 7))
@pytest.mark.parametrize("B", BATCHES)
def test_cholesky_t_columns_equal_lapack(n, B):
    # the sigma-point filters use cholesky_t directly (from CHOL_MIN_BATCH): batch axis
    # last, C[j, i] = L[:, i, j]
    rng = np.random.default_rng(7 + 100 * n + B)
    P = _spd(rng, (B,), n, scale=10.0 ** rng.uniform(-3, 3, B))
    C = linalg.cholesky_t(P)
    assert C is not None and C.shape == (n, n, B)
    Lref = np.linalg.cholesky(P)
    scale = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1).max(-1))[:, None, None]
    _close(C.transpose(2, 1, 0), Lref, scale, what="cholesky_t")


@pytest.mark.parametrize("n", [2, 4, 6])
def test_cholesky_fast_path_reads_only_the_lower_triangle_like_lapack(n):
    rng = np.random.default_rng(n)
    P = _spd(rng, (400,), n)
    junk = P.copy()
    iu = np.triu_indices(n, 1)
    junk[:, iu[0], iu[1]] = rng.uniform(-1e6, 1e6, (400, iu[0].size))
    L = linalg.cholesky(junk, "P")
    np.testing.assert_array_equal(L, linalg.cholesky(P, "P"))
    Lref = np.linalg.cholesky(junk)  # LAPACK ignores the upper triangle too
    _close(L, Lref, np.sqrt(np.diagonal(P, axis1=-2, axis2=-1).max(-1))[:, None, None])


def test_cholesky_fast_path_with_several_batch_axes():
    rng = np.random.default_rng(5)
    P = _spd(rng, (3, 150), 4)  # 450 matrices >= the threshold
    L = linalg.cholesky(P, "P")
    assert L.shape == (3, 150, 4, 4)
    scale = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1).max(-1))[..., None, None]
    _close(L, np.linalg.cholesky(P), scale)


def _bad_stack(B, n, bad, kind):
    P = np.broadcast_to(np.eye(n) * 4.0, (B, n, n)).copy()
    d = np.full(n, 4.0)
    d[min(2, n - 1)] = -1.0 if kind == "negative" else 0.0  # indefinite / singular PSD
    P[bad] = np.diag(d)
    return P


@pytest.mark.parametrize("kind", ["negative", "singular"])
@pytest.mark.parametrize("n", [1, 3, 6])
@pytest.mark.parametrize("B", [10, 199, 300, 1000])
def test_cholesky_non_positive_definite_row_same_error_in_small_and_big_stacks(B, n, kind):
    bad = 137 if B > 137 else 7
    P = _bad_stack(B, n, bad, kind)
    with pytest.raises(ValueError) as big:
        linalg.cholesky(P, "the track covariance")
    msg = str(big.value)
    assert msg.startswith("the track covariance is not positive definite")
    assert f"1 of {B} batch rows (first at index ({bad},))" in msg
    assert f"shape {P.shape}" in msg
    # the same message as the small-stack (LAPACK) path gives, up to the stack's size
    small = _bad_stack(10, n, 7, kind)
    with pytest.raises(ValueError) as ref:
        linalg.cholesky(small, "the track covariance")
    expect = (str(ref.value).replace("of 10 batch", f"of {B} batch")
              .replace("index (7,)", f"index ({bad},)").replace("(10, ", f"({B}, "))
    assert msg == expect


@pytest.mark.parametrize("B", [10, 300])
def test_cholesky_nan_row_behaves_the_same_in_small_and_big_stacks(B):
    # cholesky_t rejects a nan pivot and hands the stack to LAPACK: same result both ways
    P = np.broadcast_to(np.eye(3), (B, 3, 3)).copy()
    P[5] = np.nan
    np.testing.assert_array_equal(linalg.cholesky(P, "P"), np.linalg.cholesky(P))


# ============================================================================================
# 2. Sigma-point filters: a big batch equals each row alone
# ============================================================================================

SIGMA_FILTERS = {"UKF": UKF, "UKF-a1": lambda: UKF(alpha=1.0, kappa=0.0), "CKF": CKF}
B_SIGMA = 301  # above CHOL_MIN_BATCH (200): the vectorised Cholesky; one row: LAPACK


def _sigma_problem(B, seed):
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-3000, 3000, (B, 2)), rng.uniform(-30, 30, (B, 2))])
    P = _spd(rng, (B,), 4, scale=10.0 ** rng.uniform(-1, 2, B))
    return rng, x, P


def _spy_factor(monkeypatch):
    spy = _Spy(sigma_mod.cholesky_t)
    monkeypatch.setattr(sigma_mod, "cholesky_t", spy)
    return spy


@pytest.mark.parametrize("fname", SIGMA_FILTERS)
@pytest.mark.parametrize("dt_kind", ["scalar", "per-row array"])
@pytest.mark.parametrize("B", [linalg.CHOL_MIN_BATCH - 1, linalg.CHOL_MIN_BATCH, B_SIGMA])
def test_sigma_predict_batch_equals_rows_alone(fname, dt_kind, B, monkeypatch):
    filt = SIGMA_FILTERS[fname]()
    cv = ConstantVelocity(dim=2, q=[0.3, 2.0])
    rng, x, P = _sigma_problem(B, 11)
    dt = 0.8 if dt_kind == "scalar" else rng.uniform(0.1, 3.0, B)
    spy = _spy_factor(monkeypatch)
    pred, C = filt.predict_with_cross(tk.Gaussian(x, P), cv, dt)
    # the vectorised factor from CHOL_MIN_BATCH rows (LAPACK below)
    assert spy.calls == (1 if B >= linalg.CHOL_MIN_BATCH else 0)
    pred2 = filt.predict(tk.Gaussian(x, P), cv, dt)
    np.testing.assert_array_equal(pred2.mean, pred.mean)
    np.testing.assert_array_equal(pred2.cov, pred.cov)
    _assert_symmetric(pred.cov, "batched predict")
    spy.calls = 0
    for i in range(B):
        dti = dt if np.ndim(dt) == 0 else float(dt[i])
        one, Ci = filt.predict_with_cross(tk.Gaussian(x[i:i + 1], P[i:i + 1]), cv, dti)
        _assert_symmetric(one.cov, f"row {i} predict")
        _close(one.mean[0], pred.mean[i], _mean_scale(x[i], P[i]), what=f"row {i} mean")
        _close(one.cov[0], pred.cov[i], _cov_scale(one.cov[0]), what=f"row {i} cov")
        _close(Ci[0], C[i], _cov_scale(one.cov[0]), what=f"row {i} cross-covariance")
    assert spy.calls == 0  # a batch of one never takes the vectorised factor


@pytest.mark.parametrize("fname", SIGMA_FILTERS)
@pytest.mark.parametrize("sname", ["Bearing", "Bearing-math", "RangeBearing"])
def test_sigma_update_batch_equals_rows_alone(fname, sname, monkeypatch):
    filt = SIGMA_FILTERS[fname]()
    sensor = {
        "Bearing": Bearing(origin=(150.0, -80.0), sigma=0.01),
        "Bearing-math": Bearing(origin=(150.0, -80.0), sigma=0.02, convention="math"),
        "RangeBearing": RangeBearing(origin=(150.0, -80.0), sigma_range=5.0,
                                     sigma_bearing=0.01),
    }[sname]
    rng, x, P = _sigma_problem(B_SIGMA, 12)
    prior = filt.predict(tk.Gaussian(x, P), ConstantVelocity(dim=2, q=0.5), 1.0)
    xp, Pp = prior.mean, prior.cov
    sd = np.sqrt(np.diag(sensor.noise))
    z = sensor.h(xp) + sd * rng.standard_normal((B_SIGMA, sensor.dim_z))
    z[..., -1] = wrap(z[..., -1])
    z[:3, -1] = PI - 1e-3  # bearings across the +-pi cut: residuals need the wrap
    xp[:3, :2] = np.array([150.0, -80.0]) + [[-1.0, -1000.0], [-2.0, -800.0], [-0.5, -500.0]]
    prior = tk.Gaussian(xp, Pp)
    missing = [5, 17, 200, B_SIGMA - 1]
    z[5] = np.nan
    z[17, -1] = np.nan  # one component missing is a missing row too
    z[200, 0] = np.nan
    z[B_SIGMA - 1] = np.nan
    spy = _spy_factor(monkeypatch)
    post, innov = filt.update(prior, z, sensor)
    assert spy.calls == 1
    _assert_symmetric(post.cov, "batched update")
    assert post.mean.shape == (B_SIGMA, 4) and innov.cov.shape == (B_SIGMA,) + (sensor.dim_z,) * 2
    # rows without a measurement return the prediction, bit for bit, and a nan residual
    for i in missing:
        np.testing.assert_array_equal(post.mean[i], xp[i])
        np.testing.assert_array_equal(post.cov[i], Pp[i])
        assert np.isnan(innov.nu[i]).all()
    spy.calls = 0
    for i in range(B_SIGMA):
        one, inn1 = filt.update(tk.Gaussian(xp[i:i + 1], Pp[i:i + 1]), z[i:i + 1], sensor)
        _assert_symmetric(one.cov, f"row {i} update")
        _close(one.mean[0], post.mean[i], _mean_scale(xp[i], Pp[i]), what=f"row {i} mean")
        # P+ = P- - K S K^T: rounding at the scale of P-
        _close(one.cov[0], post.cov[i], _cov_scale(Pp[i]), what=f"row {i} cov")
        _close(inn1.cov[0], innov.cov[i], _cov_scale(innov.cov[i]), what=f"row {i} S")
        if i in missing:
            assert np.isnan(inn1.nu[0]).all()
        else:
            _close(inn1.nu[0], innov.nu[i], np.sqrt(np.diag(innov.cov[i])),
                   what=f"row {i} residual")
    assert spy.calls == 0


@pytest.mark.parametrize("fname", SIGMA_FILTERS)
def test_sigma_shared_covariance_big_batch_equals_rows_alone(fname):
    # one covariance (n, n) for 300 means: factored once (LAPACK) and broadcast
    filt = SIGMA_FILTERS[fname]()
    sensor = RangeBearing(origin=(0.0, 0.0))
    rng, x, P = _sigma_problem(300, 13)
    P0 = P[0]
    z = sensor.h(x) + rng.standard_normal((300, 2)) * [5.0, 0.01]
    post, _ = filt.update(tk.Gaussian(x, P0), z, sensor)
    pred = filt.predict(tk.Gaussian(x, P0), ConstantVelocity(dim=2, q=0.5), 1.0)
    _assert_symmetric(post.cov)
    _assert_symmetric(pred.cov)
    for i in range(0, 300, 7):
        one, _ = filt.update(tk.Gaussian(x[i], P0), z[i], sensor)
        _close(one.mean, post.mean[i], _mean_scale(x[i], P0)[..., 0])
        _close(one.cov, post.cov[i], _cov_scale(P0)[0])
        p1 = filt.predict(tk.Gaussian(x[i], P0), ConstantVelocity(dim=2, q=0.5), 1.0)
        _close(p1.mean, pred.mean[i], _mean_scale(x[i], P0)[..., 0])
        _close(p1.cov, pred.cov[i], _cov_scale(p1.cov)[0])


@pytest.mark.parametrize("fname", SIGMA_FILTERS)
@pytest.mark.parametrize("cov_batch", [(2, 150), (150,), (2, 1)], ids=str)
def test_sigma_two_batch_axes_and_broadcast_covariance_equal_rows_alone(fname, cov_batch):
    # means (2, 150, n) with covariances of batch shape (2, 150), (150,) (one per column,
    # broadcast over the first axis: the factor columns are broadcast) or (2, 1)
    filt = SIGMA_FILTERS[fname]()
    sensor = Bearing(origin=(150.0, -80.0), sigma=0.01)
    cv = ConstantVelocity(dim=2, q=0.5)
    rng, x, P = _sigma_problem(300, 14)
    x = x.reshape(2, 150, 4)
    P = P[: int(np.prod(cov_batch))].reshape(cov_batch + (4, 4))
    Pb = np.broadcast_to(P, (2, 150, 4, 4))
    pred = filt.predict(tk.Gaussian(x, P), cv, 1.0)
    z = sensor.h(pred.mean) + 0.01 * rng.standard_normal((2, 150, 1))
    post, _ = filt.update(pred, z, sensor)
    assert post.cov.shape == pred.cov.shape == (2, 150, 4, 4)
    _assert_symmetric(pred.cov)
    _assert_symmetric(post.cov)
    for idx in [(0, 0), (0, 149), (1, 0), (1, 77), (1, 149)]:
        p1 = filt.predict(tk.Gaussian(x[idx], Pb[idx]), cv, 1.0)
        _close(p1.mean, pred.mean[idx], _mean_scale(x[idx], Pb[idx])[0])
        _close(p1.cov, pred.cov[idx], _cov_scale(p1.cov))
        q1, _ = filt.update(tk.Gaussian(pred.mean[idx], pred.cov[idx]), z[idx], sensor)
        _close(q1.mean, post.mean[idx], _mean_scale(pred.mean[idx], pred.cov[idx])[0])
        _close(q1.cov, post.cov[idx], _cov_scale(pred.cov[idx]))


@pytest.mark.parametrize("fname", SIGMA_FILTERS)
@pytest.mark.parametrize("B", [10, 300])
def test_sigma_singular_covariance_names_quantity_and_row(fname, B):
    # a singular PSD covariance passes the belief check; the factor then fails and the
    # error names the belief and the first bad row, whether the stack is big or small
    filt = SIGMA_FILTERS[fname]()
    x = np.zeros((B, 4)) + [100.0, 200.0, 1.0, 1.0]
    P = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
    P[7] = np.diag([1.0, 1.0, 1.0, 0.0])
    with pytest.raises(ValueError) as ei:
        filt.predict(tk.Gaussian(x, P), ConstantVelocity(dim=2, q=0.5), 1.0)
    msg = str(ei.value)
    assert msg.startswith(f"{filt.name}.predict belief.cov is not positive definite")
    assert f"1 of {B} batch rows (first at index (7,))" in msg


# ============================================================================================
# 3. Kalman filters: the Joseph update paths against the textbook Joseph form
# ============================================================================================


def _textbook(x, P, z, sensor):
    """One unbatched update by the textbook Joseph form (``kalman.joseph_update``)."""
    H = np.broadcast_to(sensor.jacobian(x), (sensor.dim_z, x.size))
    r = sensor.residual(z, sensor.h(x))
    return kalman.joseph_update(x, P, r, H, np.asarray(sensor.noise, dtype=float))


def test_joseph_update_is_the_textbook_formula():
    # the src textbook form against the formula typed out once more (inverse and all), one
    # problem and a batch with H and R per row
    rng = np.random.default_rng(19)
    for shape, n, m in [((), 4, 1), ((), 5, 3), ((6,), 4, 2), ((2, 3), 6, 4)]:
        x = rng.uniform(-100, 100, shape + (n,))
        P = _spd(rng, shape, n)
        H = rng.standard_normal(shape + (m, n))
        R = _spd(rng, shape, m)
        r = rng.standard_normal(shape + (m,))
        xn, Pn, S = kalman.joseph_update(x, P, r, H, R)
        S_ref = H @ P @ np.swapaxes(H, -1, -2) + R
        K = P @ np.swapaxes(H, -1, -2) @ np.linalg.inv(S_ref)
        IKH = np.eye(n) - K @ H
        P_ref = (IKH @ P @ np.swapaxes(IKH, -1, -2)
                 + K @ R @ np.swapaxes(K, -1, -2))
        _assert_symmetric(Pn, f"{shape} P+")
        _close(S, S_ref, _cov_scale(S_ref), what=f"{shape} S")
        _close(Pn, P_ref, _cov_scale(P), what=f"{shape} P+")
        _close(xn, x + (K @ r[..., None])[..., 0], _mean_scale(x, P), what=f"{shape} x+")


def _kernel_problem(rng, shape, n, m):
    x = rng.uniform(-100, 100, shape + (n,))
    P = _spd(rng, shape, n)
    H = rng.standard_normal((m, n))
    return x, P, rng.standard_normal(shape + (m,)), H, _spd(rng, (), m)


@pytest.mark.parametrize("n, m", [(n, m) for n in (1, 2, 4, 6, 7)
                                  for m in range(1, kalman_fast.FAST_MAX_M + 1) if m <= n])
@pytest.mark.parametrize("shape", [(), (1,), (9,), (2, 3)], ids=str)
def test_fast_update_kernels_equal_the_textbook_form(shape, n, m):
    # random well-conditioned problems (condition numbers <= 1e3): the fast kernels
    # (update_one for one problem, update_batch for a batch) and the Joseph form as written
    # agree to 1e-12 of |P| (the module docstring's tolerance)
    rng = np.random.default_rng(100 * n + 10 * m + len(shape))
    x, P, r, H, R = _kernel_problem(rng, shape, n, m)
    fast = kalman_fast.update_one if shape == () else kalman_fast.update_batch
    xf, Pf, Sf = fast(x, P, r, H, R)
    xt, Pt, St = kalman.joseph_update(x, P, r, H, R)
    _assert_symmetric(Pf, "fast P+")
    _close(Sf, St, _cov_scale(St), what="S")
    _close(Pf, Pt, _cov_scale(P), what="P+")
    _close(xf, xt, _mean_scale(x, P), what="x+")


@pytest.mark.parametrize("shape", [(), (5,)], ids=str)
def test_condition_takes_the_fast_kernels_exactly_up_to_fast_max_m(shape, monkeypatch):
    calls = {}
    for name in ("update_one", "update_batch", "joseph_update"):
        spy = _Spy(getattr(kalman, name))
        calls[name] = spy
        monkeypatch.setattr(kalman, name, spy)
    fast = "update_one" if shape == () else "update_batch"
    rng = np.random.default_rng(17)
    for m in range(1, kalman_fast.FAST_MAX_M + 3):
        x, P, r, H, R = _kernel_problem(rng, shape, 6, m)
        for spy in calls.values():
            spy.calls = 0
        kalman.condition(x, P, r, H, R)
        took = {k for k, spy in calls.items() if spy.calls}
        assert took == ({fast} if m <= kalman_fast.FAST_MAX_M else {"joseph_update"}), m
        if m > 3:
            continue
        # and the KF's own update (its lean path for one problem included)
        for spy in calls.values():
            spy.calls = 0
        sensor = Position(dim=m, sigma=1.0 + np.arange(m))
        KF().update(tk.Gaussian(x, P), x[..., :m] + 0.5, sensor)
        took = {k for k, spy in calls.items() if spy.calls}
        assert took == ({fast} if m <= kalman_fast.FAST_MAX_M else {"joseph_update"}), m


@pytest.mark.parametrize("m", [1, 2])
@pytest.mark.parametrize("H_kind", ["position", "general"])
def test_column_kernel_equals_the_textbook_form(m, H_kind):
    # update_columns, the large-batch kernel (and the IMM's), against the Joseph form as
    # written, row by row: a sensor that picks state components (H P H^T read off P) and one
    # that does not
    rng = np.random.default_rng(20 + m)
    N, n = kalman_fast.COLUMNS_MIN_ROWS, 6
    x, P, r, H, R = _kernel_problem(rng, (N,), n, m)
    if H_kind == "position":
        H = np.eye(n)[[1, 0][:m]]
    xc, Pc, Sc = kalman_fast.update_columns(x, P, r, H, R)
    xt, Pt, St = kalman.joseph_update(x, P, r, H, R)
    _assert_symmetric(Pc, "columns P+")
    _close(Sc, St, _cov_scale(St), what="S")
    _close(Pc, Pt, _cov_scale(P), what="P+")
    _close(xc, xt, _mean_scale(x, P), what="x+")


@pytest.mark.parametrize("m", [1, 2, 3])
def test_update_batch_takes_the_column_kernel_exactly_from_columns_min_rows(m, monkeypatch):
    spy = _Spy(kalman_fast.update_columns)
    monkeypatch.setattr(kalman_fast, "update_columns", spy)
    rng = np.random.default_rng(30 + m)
    T = kalman_fast.COLUMNS_MIN_ROWS
    for shape, batched_R in [((T - 1,), False), ((T,), False), ((2, T // 2), False),
                             ((T,), True)]:
        x, P, r, H, R = _kernel_problem(rng, shape, 6, m)
        if batched_R:
            R = np.broadcast_to(R, shape + R.shape)
        spy.calls = 0
        xn, Pn, S = kalman_fast.update_batch(x, P, r, H, R)
        assert xn.shape == x.shape and Pn.shape == P.shape and S.shape == shape + (m, m)
        take = m <= 2 and np.prod(shape) >= T and not batched_R
        assert spy.calls == int(take), (shape, batched_R)


def test_update_one_refuses_a_measurement_above_fast_max_m():
    rng = np.random.default_rng(18)
    x, P, r, H, R = _kernel_problem(rng, (), 6, kalman_fast.FAST_MAX_M + 1)
    with pytest.raises(ValueError, match="update_one takes measurements of 1 to 4"):
        kalman_fast.update_one(x, P, r, H, R)


KALMAN_CASES = {
    # name: (filter, sensor, n)        measurement size m and the path it takes
    "KF-Position1": (KF, Position(dim=1, sigma=3.0), 4),  # m = 1
    "KF-Position2": (KF, Position(dim=2, sigma=[3.0, 0.5]), 4),  # m = 2
    "KF-Position3": (KF, Position(dim=3, sigma=[3.0, 0.5, 1.0]), 6),  # m = 3 (generic)
    "EKF-Bearing": (EKF, Bearing(origin=(40.0, -60.0), sigma=0.002), 4),  # m = 1
    "EKF-Bearing-math": (EKF, Bearing(origin=(40.0, -60.0), sigma=0.01, convention="math"),
                         4),
    "EKF-RangeBearing": (EKF, RangeBearing(origin=(40.0, -60.0), sigma_range=2.0,
                                           sigma_bearing=0.005), 4),  # m = 2
    "EKF-RangeBearing-n5": (EKF, RangeBearing(origin=(40.0, -60.0)), 5),
    "EKF-two-radars": (EKF, Stack((RangeBearing(origin=(40.0, -60.0)),  # m = 4 (generic)
                                   RangeBearing(origin=(-300.0, 90.0), sigma_range=5.0))), 4),
    "EKF-three-radars": (EKF, Stack((RangeBearing(origin=(40.0, -60.0)),  # m = 6 (textbook)
                                     RangeBearing(origin=(-300.0, 90.0), sigma_range=5.0),
                                     RangeBearing(origin=(900.0, 500.0)))), 4),
}


def _kalman_problem(name, B, seed):
    make, sensor, n = KALMAN_CASES[name]
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-2000, 2000, (B, min(n, 3))),
                         rng.uniform(-20, 20, (B, n - min(n, 3)))])
    P = _spd(rng, (B,), n, scale=10.0 ** rng.uniform(-1, 2, B))
    sd = np.sqrt(np.diag(sensor.noise))
    z = sensor.h(x) + sd * rng.standard_normal((B, sensor.dim_z))
    if sensor.angular[-1]:
        z[..., -1] = wrap(z[..., -1])
    return make(), sensor, x, P, z


@pytest.mark.parametrize("name", KALMAN_CASES)
def test_joseph_update_unbatched_and_batched_equal_textbook(name):
    B = 40
    filt, sensor, x, P, z = _kalman_problem(name, B, 21)
    post, innov = filt.update(tk.Gaussian(x, P), z, sensor)  # batched path
    _assert_symmetric(post.cov, "batched")
    for i in range(B):
        xr, Pr, Sr = _textbook(x[i], P[i], z[i], sensor)
        one, inn1 = filt.update(tk.Gaussian(x[i], P[i]), z[i], sensor)  # unbatched path
        _assert_symmetric(one.cov, f"row {i} unbatched")
        for what, (xn, Pn, S) in {"batched": (post.mean[i], post.cov[i], innov.cov[i]),
                                  "unbatched": (one.mean, one.cov, inn1.cov)}.items():
            _close(xn, xr, _mean_scale(x[i], P[i])[0], what=f"{what} row {i} mean")
            _close(Pn, Pr, _cov_scale(P[i]), what=f"{what} row {i} cov")
            _close(S, Sr, _cov_scale(Sr), what=f"{what} row {i} S")
        # an unbatched step equals the batched step's row
        _close(one.mean, post.mean[i], _mean_scale(x[i], P[i])[0], what=f"row {i} mean")
        _close(one.cov, post.cov[i], _cov_scale(P[i]), what=f"row {i} cov")
        _close(inn1.nu, innov.nu[i], np.sqrt(np.diag(Sr)), what=f"row {i} r")


@pytest.mark.parametrize("name", ["KF-Position1", "KF-Position2", "EKF-Bearing",
                                  "EKF-RangeBearing"])
def test_joseph_update_shared_covariance_and_missing_rows(name):
    # one covariance for the whole batch (broadcast in the batched path); nan rows keep
    # the prediction
    B = 30
    filt, sensor, x, P, z = _kalman_problem(name, B, 22)
    P0 = P[3]
    z[4] = np.nan
    post, innov = filt.update(tk.Gaussian(x, P0), z, sensor)
    _assert_symmetric(post.cov)
    np.testing.assert_array_equal(post.mean[4], x[4])
    np.testing.assert_array_equal(post.cov[4], P0)
    assert np.isnan(innov.nu[4]).all()
    for i in range(B):
        if i == 4:
            continue
        xr, Pr, _ = _textbook(x[i], P0, z[i], sensor)
        _close(post.mean[i], xr, _mean_scale(x[i], P0)[0], what=f"row {i} mean")
        _close(post.cov[i], Pr, _cov_scale(P0), what=f"row {i} cov")


@pytest.mark.parametrize("name", ["KF-Position1", "KF-Position2", "EKF-Bearing",
                                  "EKF-RangeBearing"])
def test_joseph_update_two_batch_axes_equal_textbook(name):
    filt, sensor, x, P, z = _kalman_problem(name, 12, 24)
    x, P, z = x.reshape(3, 4, -1), P.reshape(3, 4, *P.shape[-2:]), z.reshape(3, 4, -1)
    post, _ = filt.update(tk.Gaussian(x, P), z, sensor)
    assert post.cov.shape == P.shape
    _assert_symmetric(post.cov)
    for idx in np.ndindex(3, 4):
        xr, Pr, _ = _textbook(x[idx], P[idx], z[idx], sensor)
        _close(post.mean[idx], xr, _mean_scale(x[idx], P[idx])[0], what=f"{idx} mean")
        _close(post.cov[idx], Pr, _cov_scale(P[idx]), what=f"{idx} cov")


@pytest.mark.parametrize("name", ["KF-Position2", "EKF-Bearing", "EKF-RangeBearing"])
def test_joseph_update_with_a_suboptimal_gain_tolerance_is_meaningful(name):
    # guard on the tolerance: P - K S K^T (the non-Joseph short form) with a gain that is
    # off by 1e-6 differs from the Joseph result far beyond 1e-12 * |P|, so the tests above
    # would notice a path that dropped the Joseph form's gain-error insensitivity ...
    # and the optimal-gain forms agree to the tolerance, as the paths assume
    filt, sensor, x, P, z = _kalman_problem(name, 1, 23)
    x, P, z = x[0], P[0], z[0]
    xr, Pr, S = _textbook(x, P, z, sensor)
    H = np.broadcast_to(sensor.jacobian(x), (sensor.dim_z, x.size))
    K = np.linalg.solve(S, H @ P).T
    _close(P - K @ S @ K.T, Pr, _cov_scale(P))
    Kb = K * (1 + 1e-6)
    IKH = np.eye(x.size) - Kb @ H
    joseph_b = IKH @ P @ IKH.T + Kb @ sensor.noise @ Kb.T
    short_b = P - Kb @ S @ Kb.T
    assert np.abs(joseph_b - short_b).max() > 1e3 * TOL * _cov_scale(P).max()


def test_identity_cache_gives_a_value_only_to_the_same_read_only_arrays():
    cache = kalman_fast.IdentityCache(2)
    a = np.eye(2)
    a.flags.writeable = False
    b = a.copy()  # equal values, another object
    b.flags.writeable = False
    cache.put("A", a)
    assert cache.get(a) == "A" and cache.get(b) is None
    w = np.eye(2)  # writeable: could change after the value was computed, so not kept
    cache.put("W", w)
    cache.put("AW", a, w)
    assert cache.get(w) is None and cache.get(a, w) is None
    cache.put("A3", a, tag=3)
    assert cache.get(a, tag=3) == "A3" and cache.get(a) == "A" and cache.get(a, tag=4) is None
    cache.put("B", b)  # full: cleared first
    assert cache.get(a) is None and cache.get(a, tag=3) is None and cache.get(b) == "B"
    # an entry keeps its arrays alive, so no new array can come back with their ids
    cache.put("AB", a, b)
    assert cache.get(a, b) == "AB" and cache.get(b, a) is None
    del a
    assert all(cache.get(np.eye(2), b) is None for _ in range(100))


@pytest.mark.parametrize("model", [ConstantVelocity(dim=1, q=0.2), ConstantVelocity(dim=2, q=0.5),
                                   ConstantVelocity(dim=3, q=[0.1, 0.2, 0.3]),
                                   ConstantAcceleration(dim=3, q=0.1)],
                         ids=["CV1", "CV2", "CV3", "CA3"])
@pytest.mark.parametrize("B", [None, 1, 50, 400])
def test_kf_predict_paths_equal_textbook(model, B):
    # unbatched (cached Kronecker GEMV), batched (GEMM + tiled Q), n > 6 (sandwich)
    n = model.dim_x
    rng = np.random.default_rng(31 + n + (B or 0))
    shape = () if B is None else (B,)
    x = rng.uniform(-100, 100, shape + (n,))
    P = _spd(rng, shape, n)
    kf = KF()
    for _ in range(2):  # second call: the cached matrices
        pred = kf.predict(tk.Gaussian(x, P), model, 0.7)
        F, Q = model.jacobian(x, 0.7), model.noise(x, 0.7)
        _assert_symmetric(pred.cov)
        _close(pred.cov, F @ P @ F.T + Q, _cov_scale(F @ P @ F.T + Q))
        _close(pred.mean, x @ F.T, np.abs(x).max(-1, keepdims=True) * 4)
    if B:
        one = kf.predict(tk.Gaussian(x[0], P[0]), model, 0.7)
        _close(one.cov, pred.cov[0], _cov_scale(pred.cov[0]))
        # and a per-row dt (a batch of F: not cached)
        dts = rng.uniform(0.1, 2.0, B)
        pa = kf.predict(tk.Gaussian(x, P), model, dts)
        _assert_symmetric(pa.cov)
        for i in range(0, B, max(1, B // 10)):
            F, Q = model.jacobian(x[i], float(dts[i])), model.noise(x[i], float(dts[i]))
            ref = F @ P[i] @ F.T + Q
            _close(pa.cov[i], ref, _cov_scale(ref))


# ============================================================================================
# 4. Sensors: fused linearize, overridden h, the cheap angle wrap
# ============================================================================================


def _sensor_cases():
    """(name, sensor, x of shape (n,)) for every sensor model in trackkit.models."""
    o2, o3 = np.array([30.0, -45.0]), np.array([30.0, -45.0, -20.0])
    x4 = np.array([830.0, 1200.0, 3.0, -4.0])
    x5 = np.array([830.0, 1200.0, 3.0, -4.0, 0.02])
    x6 = np.array([830.0, 1200.0, 10.0, 3.0, -4.0, 0.5])
    return [
        ("Position1", Position(dim=1, sigma=2.0), x4),
        ("Position2", Position(dim=2), x4),
        ("Position3", Position(dim=3, sigma=[1.0, 2.0, 3.0]), x6),
        ("Bearing", Bearing(origin=o2), x4),
        ("Bearing-math", Bearing(origin=o2, convention="math"), x5),
        ("RangeBearing", RangeBearing(origin=o2), x4),
        ("RangeBearing-math", RangeBearing(origin=o2, convention="math"), x5),
        ("AzimuthElevation", AzimuthElevation(origin=o3), x6),
        ("AzimuthElevation-math", AzimuthElevation(origin=o3, convention="math"), x6),
        ("BearingFrequency", BearingFrequency(origin=o2, velocity=(1.0, -2.0)),
         np.array([830.0, 1200.0, 3.0, -4.0, 300.0])),
        ("MultipathDelay", MultipathDelay(origin=o3, h_surface=60.0, h_bottom=40.0), x6),
        ("Sine", Sine(), np.array([0.7, 1.3, 2.0])),
        ("Sine-unit", Sine(amplitude=False), np.array([0.7, 1.3])),
        ("Stack", Stack((Bearing(origin=o2), RangeBearing(origin=-o2, convention="math"),
                         Position(dim=2))), x4),
    ]


SENSOR_CASES = _sensor_cases()


def test_every_sensor_model_is_covered():
    models = {name for name, obj in vars(tk.models).items()
              if inspect.isclass(obj) and issubclass(obj, SensorBase) and obj is not SensorBase}
    covered = {type(s).__name__ for _, s, _ in SENSOR_CASES}
    assert models == covered


@pytest.mark.parametrize("name, sensor, x0", SENSOR_CASES, ids=[c[0] for c in SENSOR_CASES])
@pytest.mark.parametrize("batch", [(), (1,), (7,), (2, 3)], ids=str)
def test_linearize_equals_h_and_jacobian(name, sensor, x0, batch):
    rng = np.random.default_rng(41)
    x = x0 * (1 + 0.05 * rng.uniform(-1, 1, batch + x0.shape)) if batch else x0.copy()
    zhat, H = sensor.linearize(x)
    # both sides do the same floating-point operations: exact
    np.testing.assert_array_equal(zhat, sensor.h(x))
    np.testing.assert_array_equal(H, sensor.jacobian(x))
    assert np.shape(zhat) == np.shape(sensor.h(x))
    assert np.shape(H) == np.shape(sensor.jacobian(x))
    # a strided (non-contiguous) state gives the same
    xs = np.stack([x, x + 1.0], -2)[..., 0, :] if batch else x
    np.testing.assert_array_equal(sensor.linearize(xs)[0], sensor.h(x))
    np.testing.assert_array_equal(sensor.linearize(xs)[1], sensor.jacobian(x))


@pytest.mark.parametrize("cls", [Bearing, RangeBearing])
@pytest.mark.parametrize("convention", ["nautical", "math"])
@pytest.mark.parametrize("origin_batched", [False, True])
def test_bearing_h_and_jacobian_equal_reference_formulas(cls, convention, origin_batched):
    # the rewritten h/jacobian (contiguous offsets, gradient written into strided views)
    # against the textbook formulas, batched state and (moving observer) batched origin
    rng = np.random.default_rng(43)
    B = 9
    x = np.column_stack([rng.uniform(-500, 500, (B, 2)), rng.uniform(-5, 5, (B, 3))])
    origin = rng.uniform(-50, 50, (B, 2)) if origin_batched else np.array([12.0, -7.0])
    kw = ({"sigma": 0.01} if cls is Bearing else {})
    sensor = cls(origin=origin, convention=convention, **kw)
    u, v = x[:, 0] - origin[..., 0], x[:, 1] - origin[..., 1]
    r2 = u * u + v * v
    if convention == "nautical":
        b, gb = np.arctan2(u, v), np.stack([v / r2, -u / r2], -1)
    else:
        b, gb = np.arctan2(v, u), np.stack([-v / r2, u / r2], -1)
    Jb = np.zeros((B, 1, 5))
    Jb[:, 0, :2] = gb
    if cls is Bearing:
        h_ref, J_ref = b[:, None], Jb
    else:
        r = np.sqrt(r2)
        h_ref = np.stack([np.hypot(u, v), b], -1)
        J_ref = np.zeros((B, 2, 5))
        J_ref[:, 0, :2] = np.stack([u / r, v / r], -1)
        J_ref[:, 1] = Jb[:, 0]
    for zhat, H in [sensor.linearize(x), (sensor.h(x), sensor.jacobian(x))]:
        # the same formulas, maybe another evaluation order: a few ulps
        _close(zhat, h_ref, np.abs(h_ref), tol=4 * EPS)
        _close(H, J_ref, np.abs(J_ref).max(-1, keepdims=True), tol=4 * EPS)
    # unbatched state against a batched origin broadcasts
    if origin_batched:
        zhat, H = sensor.linearize(x[0])
        np.testing.assert_array_equal(zhat, sensor.h(x[0]))
        np.testing.assert_array_equal(H, sensor.jacobian(x[0]))
        assert H.shape == (B, sensor.dim_z, 5)


BIAS = 0.125


class BiasedBearing(Bearing):
    """A user's sensor: a constant bias on the bearing (h overridden, jacobian inherited)."""

    def h(self, x):
        return super().h(x) + BIAS


class ScaledJacobianBearing(Bearing):
    """Only the jacobian overridden."""

    def jacobian(self, x):
        return 2.0 * super().jacobian(x)


class BiasedRangeBearing(RangeBearing):
    def h(self, x):
        return super().h(x) + [10.0, BIAS]


class OffsetPosition(Position):
    def h(self, x):
        return super().h(x) + 5.0


class PlainBearing(Bearing):
    """A subclass that overrides neither: it keeps the fused linearize."""

    def describe(self):
        return "plain"


@pytest.mark.parametrize("batch", [(), (6,)], ids=str)
def test_linearize_uses_a_subclass_override(batch):
    rng = np.random.default_rng(47)
    x = np.array([830.0, 1200.0, 3.0, -4.0]) * (1 + 0.05 * rng.uniform(-1, 1, batch + (4,)))
    for sub, base in [(BiasedBearing(origin=(3.0, 4.0)), Bearing(origin=(3.0, 4.0))),
                      (ScaledJacobianBearing(origin=(3.0, 4.0)), Bearing(origin=(3.0, 4.0))),
                      (BiasedRangeBearing(origin=(3.0, 4.0)), RangeBearing(origin=(3.0, 4.0))),
                      (OffsetPosition(dim=2), Position(dim=2)),
                      (PlainBearing(origin=(3.0, 4.0)), Bearing(origin=(3.0, 4.0)))]:
        zhat, H = sub.linearize(x)
        np.testing.assert_array_equal(zhat, sub.h(x), err_msg=type(sub).__name__)
        np.testing.assert_array_equal(H, sub.jacobian(x), err_msg=type(sub).__name__)
        changed_h = type(sub).h is not type(base).h
        changed_j = type(sub).jacobian is not type(base).jacobian
        assert (not np.array_equal(zhat, base.h(x))) == changed_h, type(sub).__name__
        assert (not np.array_equal(H, base.jacobian(x))) == changed_j, type(sub).__name__


@pytest.mark.parametrize("batch", [(), (5,)], ids=str)
def test_ekf_and_kf_updates_use_the_overridden_h(batch):
    rng = np.random.default_rng(53)
    x = np.array([830.0, 1200.0, 3.0, -4.0]) * (1 + 0.05 * rng.uniform(-1, 1, batch + (4,)))
    P = np.diag([100.0, 100.0, 4.0, 4.0])
    biased, plain = BiasedBearing(origin=(3.0, 4.0)), Bearing(origin=(3.0, 4.0))
    z = plain.h(x) + 0.03
    _, inn = EKF().update(tk.Gaussian(x, P), z, biased)
    np.testing.assert_allclose(inn.nu, wrap(z - plain.h(x) - BIAS), rtol=0, atol=1e-15)
    # the biased sensor with z is the plain sensor with z - bias
    post_b, _ = EKF().update(tk.Gaussian(x, P), z, biased)
    post_p, _ = EKF().update(tk.Gaussian(x, P), z - BIAS, plain)
    _close(post_b.mean, post_p.mean, _mean_scale(x, P))
    _close(post_b.cov, post_p.cov, 100.0)
    off, pos = OffsetPosition(dim=2), Position(dim=2)
    zp = x[..., :2] + 1.0
    _, inn = KF().update(tk.Gaussian(x, P), zp, off)
    np.testing.assert_array_equal(inn.nu, zp - x[..., :2] - 5.0)
    post_o, _ = KF().update(tk.Gaussian(x, P), zp, off)
    post_q, _ = KF().update(tk.Gaussian(x, P), zp - 5.0, pos)
    _close(post_o.mean, post_q.mean, _mean_scale(x, P))


class DuckBearing:
    """A duck-typed sensor (no SensorModel base, no linearize): the filters fall back to
    h and jacobian."""

    dim_z, angular, linear = 1, (True,), False

    def __init__(self, origin):
        self._b = Bearing(origin=origin, sigma=0.01)
        self.noise = self._b.noise

    def h(self, x):
        return self._b.h(x)

    def jacobian(self, x):
        return self._b.jacobian(x)

    def residual(self, z, zhat):
        return wrap(z - zhat)


@pytest.mark.parametrize("batch", [(), (5,)], ids=str)
def test_ekf_update_without_linearize_equals_fused(batch):
    rng = np.random.default_rng(57)
    x = np.array([830.0, 1200.0, 3.0, -4.0]) * (1 + 0.05 * rng.uniform(-1, 1, batch + (4,)))
    P = np.diag([100.0, 100.0, 4.0, 4.0])
    duck, plain = DuckBearing((3.0, 4.0)), Bearing(origin=(3.0, 4.0), sigma=0.01)
    assert not hasattr(duck, "linearize")
    z = plain.h(x) + 0.02
    post_d, inn_d = EKF().update(tk.Gaussian(x, P), z, duck)
    post_p, inn_p = EKF().update(tk.Gaussian(x, P), z, plain)
    np.testing.assert_array_equal(post_d.mean, post_p.mean)
    np.testing.assert_array_equal(post_d.cov, post_p.cov)
    np.testing.assert_array_equal(inn_d.nu, inn_p.nu)


# differences: inside (-3, 3) (the cheap path: no wrap needed), the edges and beyond
_NEAR_PI = [np.nextafter(PI, 0), np.nextafter(PI, 4), np.nextafter(-PI, 0),
            np.nextafter(-PI, -4)]
WRAP_VALUES = np.array(
    [0.0, -0.0, 1e-300, 0.5, -0.5, 2.9, -2.9, np.nextafter(3.0, 0), np.nextafter(-3.0, 0),
     3.0, -3.0, 3.1, -3.1, PI, -PI, *_NEAR_PI, 3.2, -3.2, 2 * PI, -2 * PI, 3 * PI, -3 * PI,
     7.0, -7.0, 100.0, -100.0, 1e6 + 0.3, -1e6 - 0.3, 12345.678, -12345.678]
)


def _angle_sensors():
    # all-angle sensors take the cheap wrap; RangeBearing and BearingFrequency wrap by mask
    return [Bearing(), AzimuthElevation(), RangeBearing(), BearingFrequency(),
            Stack((Bearing(), Bearing(origin=(1.0, 1.0))))]


@pytest.mark.parametrize("sensor", _angle_sensors(), ids=lambda s: type(s).__name__)
def test_residual_wrap_equals_angles_wrap(sensor):
    rng = np.random.default_rng(59)
    m = sensor.dim_z
    ang = np.array(sensor.angular)
    small = WRAP_VALUES[np.abs(WRAP_VALUES) < 3.0]
    for d in [WRAP_VALUES, small]:
        for zhat0 in [0.0, 0.25]:
            # each difference alone (the wrap decision is per array) and all at once
            for rows in [d[:, None], d.reshape(1, -1)]:
                diff = np.repeat(rows[..., None], m, -1)
                zhat = np.full(diff.shape, zhat0) + rng.uniform(-0.1, 0.1, diff.shape)
                z = zhat + diff
                raw = z - zhat  # the raw difference (z, zhat chosen so it is ~ diff)
                res = sensor.residual(z, zhat)
                expect = np.where(ang, wrap(raw), raw)
                np.testing.assert_array_equal(res, expect)
                a = res[..., ang]
                assert np.all((a > -PI) & (a <= PI))
    # the (-pi, pi] convention: -pi and +pi both map to +pi
    for v in (PI, -PI, 3 * PI, -3 * PI):
        z = np.full(m, v)
        res = sensor.residual(z, np.zeros(m))
        assert np.all(res[ang] == PI), (v, res)
    # unbatched single residuals within +-3 are returned unchanged (exactly)
    for v in small:
        res = sensor.residual(np.full(m, v), np.zeros(m))
        np.testing.assert_array_equal(res[ang], v)


def test_cheap_wrap_helper_equals_wrap():
    from trackkit.models.sensors import wrap_small

    rng = np.random.default_rng(61)
    for a in [WRAP_VALUES, WRAP_VALUES[np.abs(WRAP_VALUES) < 3.0],
              rng.uniform(-2.999, 2.999, 1000), rng.uniform(-20, 20, 1000),
              np.array([0.1, np.nan, -0.2]), np.zeros(0)]:
        np.testing.assert_array_equal(wrap_small(a), wrap(a))
    for v in WRAP_VALUES:
        np.testing.assert_array_equal(wrap_small(np.array([v])), wrap(np.array([v])))


# ============================================================================================
# 5. Motion: one-state apply and the cached matrices
# ============================================================================================


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("dt", [0.1, 1.0, 7.3, 2])
def test_cv_f_one_state_equals_batched_row_and_F_x(dim, dt):
    cv = ConstantVelocity(dim=dim, q=0.4)
    rng = np.random.default_rng(67 + dim)
    X = rng.uniform(-1000, 1000, (50, 2 * dim))
    F = cv.jacobian(X, dt)
    Y = cv.f(X, dt)
    assert Y.shape == X.shape
    for i in (0, 1, 49):
        y = cv.f(X[i], dt)
        assert y.shape == (2 * dim,)
        # each entry is a sum of at most 2 products: GEMV and GEMM may round differently,
        # by at most a few eps of sum |F_ij x_j|
        bound = 4 * EPS * (np.abs(F) @ np.abs(X[i]))
        _close(y, Y[i], bound, tol=1.0, what="one state vs batched row")
        _close(y, F @ X[i], bound, tol=1.0, what="one state vs F @ x")
        _close(Y[i], F @ X[i], bound, tol=1.0, what="batched row vs F @ x")
    # batch axes beyond one
    X3 = X.reshape(5, 10, 2 * dim)
    np.testing.assert_array_equal(cv.f(X3, dt).reshape(50, 2 * dim), Y)


def test_cv_cached_matrices_are_read_only_and_shared():
    cv = ConstantVelocity(dim=2, q=[0.5, 1.5])
    x = np.zeros(4)
    F, Q = cv.jacobian(x, 0.5), cv.noise(x, 0.5)
    for M in (F, Q):
        assert not M.flags.writeable
        with pytest.raises(ValueError):
            M[0, 0] = 1.0
    # the same dt, however it is spelt, returns the same objects
    for dt in (0.5, np.float64(0.5), np.array(0.5)):
        assert cv.jacobian(x, dt) is F
        assert cv.noise(x, dt) is Q
    assert cv.jacobian(np.zeros((7, 4)), 0.5) is F  # batch of states: same matrix
    assert cv.jacobian(x, 1) is cv.jacobian(x, 1.0)
    # a different dt: a different matrix, with the right values
    F2, Q2 = cv.jacobian(x, 0.75), cv.noise(x, 0.75)
    assert F2 is not F and Q2 is not Q
    assert not np.array_equal(F2, F) and not np.array_equal(Q2, Q)
    assert F2[0, 2] == 0.75 and F[0, 2] == 0.5
    np.testing.assert_allclose(Q2[0, 0], 0.5 * 0.75**3 / 3, rtol=1e-15)
    np.testing.assert_allclose(Q2[1, 1], 1.5 * 0.75**3 / 3, rtol=1e-15)
    # the first matrices are unchanged by the later builds
    assert F[0, 2] == 0.5 and cv.jacobian(x, 0.5) is F


def test_cv_array_dt_with_batch_axes_works_and_is_not_cached():
    cv = ConstantVelocity(dim=2, q=0.5)
    rng = np.random.default_rng(71)
    X = rng.uniform(-100, 100, (3, 4, 4))
    dts = rng.uniform(0.1, 2.0, (3, 4))
    cache_before = dict(cv.__dict__.get("_cache", {}))
    F1, F2 = cv.jacobian(X, dts), cv.jacobian(X, dts)
    Q1 = cv.noise(X, dts)
    assert F1.shape == Q1.shape == (3, 4, 4, 4)
    assert F1 is not F2  # built per call
    assert dict(cv.__dict__.get("_cache", {})) == cache_before  # nothing cached
    Y = cv.f(X, dts)
    for idx in np.ndindex(3, 4):
        dt = float(dts[idx])
        np.testing.assert_array_equal(F1[idx], cv.jacobian(X[idx], dt))
        np.testing.assert_array_equal(Q1[idx], cv.noise(X[idx], dt))
        Fi = cv.jacobian(X[idx], dt)
        _close(Y[idx], Fi @ X[idx], 4 * EPS * (np.abs(Fi) @ np.abs(X[idx])), tol=1.0)
    # a dt array broadcast against the batch (one dt per first axis)
    Yb = cv.f(X, dts[:, :1])
    for idx in np.ndindex(3, 4):
        Fi = cv.jacobian(X[idx], float(dts[idx[0], 0]))
        _close(Yb[idx], Fi @ X[idx], 4 * EPS * (np.abs(Fi) @ np.abs(X[idx])), tol=1.0)


# --- the fixed-lag smoother's compiled walk (filters.smoothers_fast) ----------------------

def _lag_problem(rng, N, n):
    """N rows in chains of random lengths (links to a later row, -1 at each chain's end),
    filtered covariances with condition numbers <= 1e3 and gains near the identity (as a
    smoother's are: eigenvalues near 1)."""
    x = rng.normal(size=(N, n)) * 100.0
    U = np.linalg.qr(rng.normal(size=(N, n, n)))[0]
    P = linalg.symmetrize(U @ (rng.uniform(1.0, 1e3, (N, n))[..., None] * U.mT))
    pc = P + np.eye(n) * rng.uniform(0.1, 10.0, (N, 1, 1))
    pm = x + rng.normal(size=(N, n))
    G = np.eye(n) * 0.95 + rng.normal(size=(N, n, n)) * 0.02
    nxt = np.full(N, -1, np.int64)
    order = rng.permutation(N)
    ends = np.sort(rng.choice(N, N // 15, replace=False))
    follows = np.ones(N - 1, bool)
    follows[ends[ends < N - 1]] = False
    nxt[order[:-1][follows]] = order[1:][follows]
    return x, P, pm, pc, G, nxt


@pytest.mark.parametrize("n", [2, 4, 5, 6])
@pytest.mark.parametrize("lag", [1, 3, 20, 400])
def test_fixed_lag_kernel_equals_the_numpy_sweeps(n, lag, monkeypatch):
    # the compiled walk (one kernel per n) against lag numpy passes of rts_update over every
    # row; a lag past the longest chain (400) is the fixed-interval smoother
    from trackkit.belief import Gaussian
    from trackkit.filters import smoothers
    rng = np.random.default_rng(60 + n + lag)
    x, P, pm, pc, G, nxt = _lag_problem(rng, 600, n)
    pred = Gaussian(pm, pc)
    assert smoothers.SWEEP_KERNEL_MIN_ROWS <= 600  # the kernel's side
    xs, Ps = smoothers.fixed_lag_sweeps(x, P, pred, G, nxt, lag)
    monkeypatch.setattr(smoothers, "SWEEP_KERNEL_MIN_ROWS", 10**9)  # the textbook side
    xt, Pt = smoothers.fixed_lag_sweeps(x, P, pred, G, nxt, lag)
    assert np.array_equal(xs[nxt < 0], x[nxt < 0]) and not np.allclose(xs, x)
    np.testing.assert_allclose(xs, xt, rtol=0, atol=1e-12 * np.abs(xt).max())
    np.testing.assert_allclose(Ps, Pt, rtol=0, atol=1e-12 * np.abs(Pt).max())
    assert np.array_equal(Ps, Ps.mT)
