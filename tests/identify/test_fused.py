"""The compiled augmented EKF (``trackkit.identify.fused``), pinned to the textbook form it
speeds up: ``trackkit.filters.EKF`` on ``SampledVessel``, one predict-update at a time.

Tolerances as in ``tests/test_fast_paths.py``: two computations of the same quantity in a
different order differ by a few ulps of the largest intermediate, so a mean is compared to
``1e-12`` of its standard deviation plus its size, and a covariance entry to ``1e-12`` of
``sd_i sd_j`` (the scale of the numbers subtracted in ``P- - W W^T``). A wrong index, sign or
term is wrong at the 1e-3 .. 1 level."""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.belief import Gaussian
from trackkit.identify import SampledVessel, fused
from trackkit.models.manoeuvring import reference_vessel, step

REF = reference_vessel()
N = 37  # not a multiple of any chunk tried below
R = np.diag([0.05, 0.05, 0.0017]) ** 2
Qd = np.r_[3e-4, 3e-4, 3e-6, np.full(16, 1e-7)]


def _problem(seed=0, n=N):
    """Runs in mid-identification: body states near a zig-zag's, coefficients 20% off the
    reference, a covariance with correlations everywhere, inputs that change over the step."""
    rng = np.random.default_rng(seed)
    body = np.array([8.0, -0.6, 0.08]) + [0.5, 0.2, 0.03] * rng.standard_normal((n, 3))
    theta = REF.theta * (1 + 0.2 * rng.standard_normal((n, 16)))
    x = np.concatenate([body, theta], -1)
    sd = np.r_[0.05, 0.05, 0.002, 0.05 * np.abs(REF.theta) + 0.01]
    C = rng.standard_normal((n, 19, 30))
    C = C @ C.mT / 30 + 0.5 * np.eye(19)
    d = 1 / np.sqrt(np.diagonal(C, axis1=-2, axis2=-1))
    P = C * d[:, :, None] * d[:, None, :] * sd[:, None] * sd[None, :]
    P = 0.5 * (P + P.mT)
    s0 = np.c_[rng.uniform(-0.35, 0.35, n), rng.uniform(1200, 2000, n)]
    s1 = s0 + np.c_[rng.uniform(-0.05, 0.05, n), rng.uniform(-50, 50, n)]
    z = body + [0.3, 0.1, 0.01] * rng.standard_normal((n, 3))
    return x, P, s0, s1, z


def _fused(x, P, s0, s1, z, m, chunk=None, monkeypatch=None):
    if chunk is not None:
        monkeypatch.setattr(fused, "CHUNK", chunk)
    xs, Ps = np.ascontiguousarray(x.T), fused.pack(P)
    nis = fused.predict_update(xs, Ps, np.ascontiguousarray(s0.T), np.ascontiguousarray(s1.T),
                               fused.plan(REF.norm, m, 1.0), Qd, np.ascontiguousarray(z.T), R)
    return xs.T, fused.unpack(Ps), nis


def _textbook(x, P, s0, s1, z, m):
    model = SampledVessel(s0, s1, REF.norm, q_body=Qd[:3], q_theta=Qd[3:], substeps=m)
    ekf = tk.filters.EKF()
    b = ekf.predict(Gaussian(x, P), model, 1.0)
    b, innov = ekf.update(b, z, tk.models.Position(dim=3, sigma=np.sqrt(np.diag(R))))
    return b.mean, b.cov, innov.nis


@pytest.mark.parametrize("m", [1, 4])
def test_one_predict_update_is_the_textbook_ekfs(m):
    x, P, s0, s1, z = _problem(seed=m)
    xf, Pf, nf = _fused(x, P, s0, s1, z, m)
    xt, Pt, nt = _textbook(x, P, s0, s1, z, m)
    sd = np.sqrt(np.diagonal(Pt, axis1=-2, axis2=-1))
    assert np.all(np.abs(xf - xt) <= 1e-12 * (np.abs(xt) + sd))
    assert np.all(np.abs(Pf - Pt) <= 1e-12 * sd[:, :, None] * sd[:, None, :])
    np.testing.assert_allclose(nf, nt, rtol=1e-11)
    # and the update did something: the check is not vacuous
    assert np.all(np.abs(xf - x) > 1e-9 * np.abs(x))


def test_with_inputs_at_the_substeps_the_update_is_the_textbook_ekfs():
    """The inputs measured at the sub-steps' ends (a nozzle that starts and stops between the
    samples): the kernel's sf path against ``SampledVessel(s_sub=...)``."""
    x, P, s0, s1, z = _problem(seed=7)
    m = 5
    rng = np.random.default_rng(8)
    sub = s0 + np.linspace(0.0, 1.0, m + 1)[:, None, None] * (s1 - s0)
    sub[1:-1, :, 0] += rng.uniform(-0.05, 0.05, (m - 1, N))  # not on the line
    xs, Ps = np.ascontiguousarray(x.T), fused.pack(P)
    nf = fused.predict_update(xs, Ps, np.ascontiguousarray(s0.T), np.ascontiguousarray(s1.T),
                              fused.plan(REF.norm, m, 1.0), Qd, np.ascontiguousarray(z.T), R,
                              np.ascontiguousarray(sub.transpose(0, 2, 1)))
    model = SampledVessel(s0, s1, REF.norm, q_body=Qd[:3], q_theta=Qd[3:], substeps=m,
                          s_sub=sub)
    ekf = tk.filters.EKF()
    b = ekf.predict(Gaussian(x, P), model, 1.0)
    b, innov = ekf.update(b, z, tk.models.Position(dim=3, sigma=np.sqrt(np.diag(R))))
    sd = np.sqrt(np.diagonal(b.cov, axis1=-2, axis2=-1))
    assert np.all(np.abs(xs.T - b.mean) <= 1e-12 * (np.abs(b.mean) + sd))
    assert np.all(np.abs(fused.unpack(Ps) - b.cov) <= 1e-12 * sd[:, :, None] * sd[:, None, :])
    np.testing.assert_allclose(nf, innov.nis, rtol=1e-11)
    # the measured inputs matter: the interpolated ones give another prediction
    xi, _, _ = _fused(x, P, s0, s1, z, m)
    assert np.abs(xi[:, :3] - xs.T[:, :3]).max() > 1e-4


def test_the_prediction_is_the_models_euler_step_bit_for_bit():
    # with no measurement the kernel's state is the prediction, and eq. 2 is written once
    # (trackkit.models.manoeuvring.prime_rates), so one Euler step is the same bits
    x, P, s0, s1, z = _problem(seed=3)
    xf, Pf, nf = _fused(x, P, s0, s1, np.full_like(z, np.nan), 1)
    np.testing.assert_array_equal(xf[:, :3], step(x[:, :3], 0.5 * (s0 + s1), x[:, 3:], 1.0,
                                                  REF.norm))
    np.testing.assert_array_equal(xf[:, 3:], x[:, 3:])
    assert np.all(np.isnan(nf))
    F = SampledVessel(s0, s1, REF.norm).jacobian(x, 1.0)
    Pt = F @ P @ F.mT + np.diag(Qd)
    sd = np.sqrt(np.diagonal(Pt, axis1=-2, axis2=-1))
    assert np.all(np.abs(Pf - Pt) <= 1e-12 * sd[:, :, None] * sd[:, None, :])


@pytest.mark.parametrize("m", [1, 3])
def test_the_bits_do_not_depend_on_the_batch_or_the_chunk(m, monkeypatch):
    x, P, s0, s1, z = _problem(seed=5)
    z[4] = np.nan
    ref = _fused(x, P, s0, s1, z, m, chunk=256, monkeypatch=monkeypatch)
    for chunk in (1, 8, 16):
        out = _fused(x, P, s0, s1, z, m, chunk=chunk, monkeypatch=monkeypatch)
        for a, b in zip(out, ref, strict=True):
            np.testing.assert_array_equal(a, b)
    for i in (0, 4, N - 1):
        one = _fused(x[i:i + 1], P[i:i + 1], s0[i:i + 1], s1[i:i + 1], z[i:i + 1], m)
        for a, b in zip(one, ref, strict=True):
            np.testing.assert_array_equal(a[0], b[i])


def test_a_missing_measurement_keeps_the_prediction():
    x, P, s0, s1, z = _problem(seed=6)
    z[[2, 9]] = np.nan
    z[11, 1] = np.nan  # one missing component: the whole sample is missing
    xf, Pf, nf = _fused(x, P, s0, s1, z, 1)
    xp, Pp, _ = _fused(x, P, s0, s1, np.full_like(z, np.nan), 1)
    for i in (2, 9, 11):
        np.testing.assert_array_equal(xf[i], xp[i])
        np.testing.assert_array_equal(Pf[i], Pp[i])
    assert np.isnan(nf[[2, 9, 11]]).all() and np.isfinite(np.delete(nf, [2, 9, 11])).all()


def test_an_indefinite_innovation_covariance_is_an_error_naming_the_count():
    x, P, s0, s1, z = _problem(seed=7)
    P[[3, 20], 0, 0] = -1.0  # S_00 < 0 after the prediction
    with pytest.raises(ValueError, match="not positive definite in 2 run"):
        _fused(x, P, s0, s1, z, 1)


def test_pack_and_unpack_are_inverse():
    _, P, *_ = _problem(seed=8)
    P2 = fused.pack(P)
    assert P2.shape == (190, N) and P2.flags.c_contiguous
    np.testing.assert_array_equal(fused.unpack(P2), P)


_CHILD = """
import sys, numpy as np
sys.path[:0] = [{tests!r}]
from identify.test_fused import _fused, _problem
x, P, s0, s1, z = _problem(seed=9)
z[3] = np.nan
out = {{m: _fused(x, P, s0, s1, z, m) for m in (1, 3)}}
np.savez({path!r}, **{{f"{{m}}_{{i}}": a for m, v in out.items() for i, a in enumerate(v)}})
"""


@pytest.mark.parametrize("cpu", ["generic", "haswell"])
def test_the_same_bits_when_compiled_for_another_cpu(cpu, tmp_path):
    # numba compiles for the host (AVX-512 here); compiled for plain x86-64 (no FMA, SSE2)
    # and for AVX2 the kernel must give the same bits: no contraction into FMA, no sum
    # reordered by the vector width (docs/architecture.md, Determinism, promises 1e-12 across CPUs;
    # this kernel promises bits)
    import os
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "out.npz"
    code = _CHILD.format(tests=str(Path(__file__).parents[1]), path=str(path))
    env = dict(os.environ, NUMBA_CPU_NAME=cpu, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    subprocess.run([sys.executable, "-c", code], env=env, check=True, timeout=300)
    theirs = np.load(path)
    x, P, s0, s1, z = _problem(seed=9)
    z[3] = np.nan
    for m in (1, 3):
        for i, a in enumerate(_fused(x, P, s0, s1, z, m)):
            np.testing.assert_array_equal(theirs[f"{m}_{i}"], a, err_msg=f"{cpu} m={m} {i}")
