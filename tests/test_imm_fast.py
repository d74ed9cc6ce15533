"""The compiled IMM kernels (trackkit.filters.imm_fast) against the numpy IMM they replace,
on random beliefs: mode probabilities of exactly 0 and 1, bearings near +-pi, missed rows."""

import numpy as np
import pytest

import trackkit as tk
from trackkit.filters import IMM
from trackkit.models import ConstantVelocity, CoordinatedTurn
from trackkit.models.sensors import RangeBearing

RTOL = 1e-12


def cv_ct() -> IMM:
    return IMM([ConstantVelocity(dim=2, q=0.5), CoordinatedTurn(q=0.5, q_omega=1e-4)],
               tk.filters.EKF(), [[0.95, 0.05], [0.05, 0.95]], mu0=[0.8, 0.2])


def numpy_path(f: IMM) -> IMM:
    """The same IMM with the compiled path turned off."""
    g = cv_ct()
    g._compiled = False
    assert f._compiled
    return g


def beliefs(T: int, seed: int):
    """Random IMM beliefs: targets around the origin (some due south of it, bearing near
    +-pi), random SPD covariances, mu with rows of exactly (1, 0) and (0, 1)."""
    rng = np.random.default_rng(seed)
    X = np.zeros((T, 2, 5))
    pos = rng.normal(0, 5e3, (T, 2))
    pos[:4, 0] = [-1e-3, 1e-3, -1e-9, 0.0]  # south of the radar: bearings near +-pi
    pos[:4, 1] = -3e3
    for j in range(2):
        X[:, j, :2] = pos + rng.normal(0, 30, (T, 2))
        X[:, j, 2:4] = rng.normal(0, 10, (T, 2))
    X[:, 1, 4] = rng.normal(0, 0.02, T)
    X[::7, 1, 4] = 1e-5  # the turn's Taylor branch
    P = np.zeros((T, 2, 5, 5))
    for j, n in enumerate((4, 5)):
        A = rng.normal(0, 1, (T, n, n)) * np.array([30, 30, 3, 3, 0.01][:n])
        P[:, j, :n, :n] = A @ A.mT + np.diag([100.0, 100.0, 1.0, 1.0, 1e-6][:n])
    mu = rng.uniform(0, 1, T)
    mu[4], mu[5] = 0.0, 1.0
    return tk.filters.IMMBelief(np.stack([mu, 1 - mu], -1), X, P)


def close(a, b):
    """Equal to RTOL relative to each component's largest magnitude over the rows (an
    updated velocity near 0 is a difference of terms of the scale of the others)."""
    a, b = np.asarray(a), np.asarray(b)
    assert (np.isnan(a) == np.isnan(b)).all()
    scale = np.nanmax(np.abs(b), axis=0) if b.ndim > 1 else np.abs(b)
    err = np.nan_to_num(np.abs(a - b))
    np.testing.assert_array_less(err, np.broadcast_to(RTOL * scale + 1e-300, err.shape))


@pytest.mark.parametrize("convention", ["nautical", "math"])
def test_kernels_equal_the_numpy_imm(convention):
    f = cv_ct()
    g = numpy_path(f)
    radar = RangeBearing(origin=(0.0, 0.0), sigma_range=20.0, sigma_bearing=0.01,
                         convention=convention)
    b = beliefs(40, 1)
    pf, pg = f.predict(b, None, 3.0), g.predict(b, None, 3.0)
    for a, c in zip(pf, pg, strict=True):
        close(a, c)
    for a, c in zip(f.measurement_prediction(pf, radar), g.measurement_prediction(pf, radar),
                    strict=True):
        close(a, c)
    rng = np.random.default_rng(2)
    z = radar.h(f.estimate(pf).mean) + rng.normal(0, 1, (40, 2)) * [20.0, 0.01]
    z[:, 1] = tk.angles.wrap(z[:, 1])
    z[[3, 9, 5]] = np.nan  # missed rows (one with mu = 1)
    (uf, inf), (ug, ing) = f.update(pf, z, radar), g.update(pf, z, radar)
    for a, c in zip((*uf, *inf), (*ug, *ing), strict=True):
        close(a, c)
    for a, c in zip(f.estimate(uf), g.estimate(uf), strict=True):
        close(a, c)


def test_estimate_in_the_limit_of_a_vanishing_turn_model():
    """CT weights of 0 and below the smallest normal products take combine's limit."""
    f = cv_ct()
    g = numpy_path(f)
    b = beliefs(6, 3)
    mu = np.array([[1.0, 0.0], [1.0, 1e-300], [1.0, 5e-324], [0.0, 1.0], [0.5, 0.5],
                   [1.0, 1e-200]])
    b = tk.filters.IMMBelief(mu, b.mean, b.cov)
    for a, c in zip(f.estimate(b), g.estimate(b), strict=True):
        close(a, c)


def test_other_configurations_keep_the_numpy_path():
    assert cv_ct()._compiled
    assert not IMM([ConstantVelocity(dim=2, q=0.5), CoordinatedTurn(q=0.5)], tk.filters.UKF(),
                   [[0.9, 0.1], [0.1, 0.9]])._compiled
    assert not IMM([ConstantVelocity(dim=2, q=0.5), CoordinatedTurn(q=0.5)],
                   tk.filters.EKF(order=2), [[0.9, 0.1], [0.1, 0.9]])._compiled
    assert not IMM([ConstantVelocity(dim=2, q=0.5), CoordinatedTurn(q=0.5)], tk.filters.EKF(),
                   [[0.9, 0.1], [0.1, 0.9]], fill="zero")._compiled
