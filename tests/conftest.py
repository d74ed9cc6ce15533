"""Shared helpers for the core tests: finite differences, random SPD matrices, tolerances.

The helpers are handed to tests through the session fixture ``num`` (not imported by module
name, so that another ``conftest.py`` under ``tests/`` can never shadow them); session scope
keeps them usable inside hypothesis tests.
"""

from __future__ import annotations

from collections.abc import Callable
from types import SimpleNamespace

import numpy as np
import pytest


def fd_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-6,
                diff: Callable | None = None, floor: float = 1.0):
    """Central finite-difference Jacobian of ``fun`` at the single point ``x`` (shape (n,)).

    The step is relative, ``h * max(floor, |x_i|)``; all 2n perturbed points are evaluated in one
    vectorised call, shape ``(2n, n)``. ``diff(a, b)`` forms ``a - b`` (pass a sensor's
    ``residual`` so that an angle crossing the +-pi cut is differenced on the circle).
    ``floor`` sets the smallest step scale (a sensor's geometry scale, so that a small
    component such as a depth offset is not differenced with a step far below rounding).
    Returns ``(m, n)``.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    E = np.eye(n) * step
    pts = np.concatenate([x + E, x - E], axis=0)
    vals = np.asarray(fun(pts))
    d = (vals[:n] - vals[n:]) if diff is None else np.asarray(diff(vals[:n], vals[n:]))
    return (d / (2 * step[:, None])).T


def fd_hessian_from_jacobian(jac: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                             h: float = 1e-6, floor: float = 1.0):
    """Central differences of an analytic Jacobian ``jac`` (``(n,) -> (m, n)``) at ``x``:
    returns ``(m, n, n)`` with ``out[i, j, k] = d^2 h_i / dx_j dx_k``."""
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    cols = []
    for k in range(n):
        e = np.zeros(n)
        e[k] = step[k]
        Jp = np.asarray(jac(x + e))
        Jm = np.asarray(jac(x - e))
        Jp = np.broadcast_to(Jp, Jp.shape[-2:])
        Jm = np.broadcast_to(Jm, Jm.shape[-2:])
        cols.append((Jp - Jm) / (2 * step[k]))
    return np.stack(cols, axis=-1)  # (m, n, n) with last index k


def fd_hessian_direct(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-4,
                      diff: Callable | None = None, floor: float = 1.0):
    """Second-order central differences of ``fun`` itself (no Jacobian used): ``(m, n, n)``;
    ``diff`` as for :func:`fd_jacobian`."""
    diff = (lambda a, b: a - b) if diff is None else diff
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    step = h * np.maximum(floor, np.abs(x))
    m = np.asarray(fun(x[None]))[0].shape[-1]
    H = np.zeros((m, n, n))
    for j in range(n):
        for k in range(n):
            ej = np.zeros(n)
            ek = np.zeros(n)
            ej[j] = step[j]
            ek[k] = step[k]
            pts = np.stack([x + ej + ek, x + ej - ek, x - ej + ek, x - ej - ek])
            v = np.asarray(fun(pts))
            H[:, j, k] = (diff(v[0], v[1]) - diff(v[2], v[3])) / (4 * step[j] * step[k])
    return H


def assert_close_scaled(actual, expected, rtol: float, atol: float = 0.0, what: str = "",
                        per_row: bool = False):
    """``|actual - expected| <= atol + rtol * scale`` elementwise, with a readable message.

    ``scale`` is ``max|expected|`` over the whole array, or, with ``per_row``, over each slice
    along the first axis (one measurement component of a Jacobian ``(m, n)`` or Hessian
    ``(m, n, n)``), so that a row of small entries (a bearing at long range next to a range)
    is held to its own magnitude. Zero entries of a Jacobian are compared against the scale.
    """
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    if per_row and expected.ndim >= 2:
        axes = tuple(range(1, expected.ndim))
        scale = np.max(np.abs(expected), axis=axes, keepdims=True)
    else:
        scale = np.max(np.abs(expected)) if expected.size else 0.0
    err = np.abs(actual - expected)
    tol = atol + rtol * scale
    bad = ~(err <= tol)  # nan anywhere is a failure too
    assert not np.any(bad), (
        f"{what}: {int(bad.sum())} entries off, max abs error {float(np.max(err)):.3e}"
        f"\nactual=\n{actual}\nexpected=\n{expected}"
    )


def random_spd(rng: np.random.Generator, shape: tuple[int, ...], n: int, cond: float = 1e3):
    """Random symmetric positive-definite matrices of shape ``shape + (n, n)``.

    Eigenvalues log-uniform in [1, cond] times a random orthogonal basis; exactly symmetric.
    """
    A = rng.standard_normal(shape + (n, n))
    Qm, _ = np.linalg.qr(A)
    ev = np.exp(rng.uniform(0.0, np.log(cond), size=shape + (n,)))
    P = (Qm * ev[..., None, :]) @ np.swapaxes(Qm, -1, -2)
    return 0.5 * (P + np.swapaxes(P, -1, -2))


@pytest.fixture(scope="session")
def num() -> SimpleNamespace:
    """Numerical helpers: ``num.jac``, ``num.hess``, ``num.hess2``, ``num.close``, ``num.spd``."""
    return SimpleNamespace(
        jac=fd_jacobian,
        hess=fd_hessian_from_jacobian,
        hess2=fd_hessian_direct,
        close=assert_close_scaled,
        spd=random_spd,
    )
