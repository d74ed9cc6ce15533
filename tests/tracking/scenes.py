"""Random multi-target scenes for the gating and association tests.

A scene is T tracks with a predicted 2-D CV belief ``[x, y, vx, vy]`` spread over a square,
position measurements (``tk.models.Position``), each target detected with probability P_D
near its predicted measurement, and uniform clutter of density lambda over the square.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

import trackkit as tk


class Scene(NamedTuple):
    prior: tk.Gaussian  # the tracks' states before prediction
    motion: object
    predicted: tk.Gaussian
    sensor: object
    z: np.ndarray  # (D, 2)
    clutter_density: float
    pd: float


def scene(rng: np.random.Generator, T: int, side: float = 2000.0, clutter: float = 20.0,
          pd: float = 0.9, sigma: float = 10.0, pos_std: tuple[float, float] = (5.0, 40.0),
          q: float = 0.5) -> Scene:
    """A random scene: ``T`` tracks in a ``side`` x ``side`` square, ``clutter`` false
    plots on average."""
    motion = tk.models.ConstantVelocity(dim=2, q=q)
    sensor = tk.models.Position(dim=2, sigma=sigma)
    x = np.column_stack([rng.uniform(0, side, (T, 2)), rng.normal(0, 5, (T, 2))])
    sp_ = rng.uniform(*pos_std, (T, 2))
    sv = rng.uniform(0.5, 3.0, (T, 2))
    rho = rng.uniform(-0.5, 0.5, T)
    P = np.zeros((T, 4, 4))
    P[:, 0, 0], P[:, 1, 1] = sp_[:, 0] ** 2, sp_[:, 1] ** 2
    P[:, 0, 1] = P[:, 1, 0] = rho * sp_[:, 0] * sp_[:, 1]
    P[:, 2, 2], P[:, 3, 3] = sv[:, 0] ** 2, sv[:, 1] ** 2
    P[:, 0, 2] = P[:, 2, 0] = 0.3 * sp_[:, 0] * sv[:, 0]
    P[:, 1, 3] = P[:, 3, 1] = 0.3 * sp_[:, 1] * sv[:, 1]
    prior = tk.Gaussian(x, P)
    pred = tk.filters.KF().predict(prior, motion, 1.0)
    S = pred.cov[:, :2, :2] + sigma**2 * np.eye(2)
    L = np.linalg.cholesky(S)
    detected = rng.uniform(size=T) < pd
    n = int(detected.sum())
    zt = pred.mean[detected, :2] + (L[detected] @ rng.standard_normal((n, 2, 1)))[..., 0]
    n_clutter = rng.poisson(clutter)
    zc = rng.uniform(0, side, (n_clutter, 2))
    z = np.concatenate([zt, zc])
    z = z[rng.permutation(z.shape[0])]
    return Scene(prior, motion, pred, sensor, z, clutter / side**2, pd)


def scene_range_bearing(rng: np.random.Generator, T: int, clutter: float = 20.0,
                        pd: float = 0.9, sigma_range: float = 10.0,
                        sigma_bearing: float = 0.01, span: float = 0.3,
                        r_lim: tuple[float, float] = (1000.0, 3000.0)) -> Scene:
    """A radar at the origin (``RangeBearing``, mathematical bearings) looking west, so that
    the targets' bearings straddle the +-pi cut: T targets within ``span`` rad of west
    and ``r_lim`` in range; clutter uniform in (range, bearing) over that window."""
    motion = tk.models.ConstantVelocity(dim=2, q=0.5)
    sensor = tk.models.RangeBearing(sigma_range=sigma_range, sigma_bearing=sigma_bearing,
                                    convention="math")
    r = rng.uniform(*r_lim, T)
    b = np.pi + rng.uniform(-span, span, T)
    b[:4] = np.pi + rng.uniform(-0.005, 0.005, b[:4].shape)  # a few right on the cut
    x = np.column_stack([r * np.cos(b), r * np.sin(b), rng.normal(0, 5, (T, 2))])
    sp_ = rng.uniform(5.0, 20.0, (T, 2))
    P = np.zeros((T, 4, 4))
    P[:, 0, 0], P[:, 1, 1] = sp_[:, 0] ** 2, sp_[:, 1] ** 2
    P[:, 2, 2] = P[:, 3, 3] = 4.0
    P[:, 0, 2] = P[:, 2, 0] = 0.3 * sp_[:, 0] * 2.0
    P[:, 1, 3] = P[:, 3, 1] = 0.3 * sp_[:, 1] * 2.0
    prior = tk.Gaussian(x, P)
    pred = tk.filters.KF().predict(prior, motion, 1.0)
    zhat, H = sensor.linearize(pred.mean)
    S = H @ pred.cov @ H.mT + sensor.noise
    L = np.linalg.cholesky(S)
    detected = rng.uniform(size=T) < pd
    n = int(detected.sum())
    zt = zhat[detected] + (L[detected] @ rng.standard_normal((n, 2, 1)))[..., 0]
    n_clutter = rng.poisson(clutter)
    zc = np.column_stack([rng.uniform(*r_lim, n_clutter),
                          np.pi + rng.uniform(-span, span, n_clutter)])
    z = np.concatenate([zt, zc])
    z[:, 1] = tk.angles.wrap(z[:, 1])
    z = z[rng.permutation(z.shape[0])]
    density = clutter / ((r_lim[1] - r_lim[0]) * 2 * span)
    return Scene(prior, motion, pred, sensor, z, density, pd)
