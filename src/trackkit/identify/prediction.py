"""Open-loop prediction with an identified model, and tracks from filtered body states.

``predict`` runs the model ``x_{k+1} = F_T(x_k; s_k, s_{k+1}, theta)`` from a known initial
body state, given only the sampled inputs of a trial: ``F_T`` is the identifier's own
discretisation (``identify.augmented.SampledVessel``: ``substeps`` Euler steps per sample,
the input interpolated between samples; one step with the mean input is the paper's eq. 4).
The pose then follows ``trackkit.models.manoeuvring.integrate_pose``: over each sample interval
the body velocity is held at the mean of its end samples and the pose moves on the exact
arc, ``east' = u sin psi + v cos psi``, ``north' = u cos psi - v sin psi``, ``psi' = r``.

``dead_reckon`` builds a track from filtered ``[u, v]`` and the *measured* heading (so that a
yaw-rate error does not accumulate into heading drift): each interval is the arc from the
measured ``psi_k`` turning by the measured ``wrap(psi_{k+1} - psi_k)``, at the mean body
velocity of its ends.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from trackkit.angles import wrap
from trackkit.identify.augmented import SUBSTEPS_SAMPLED_INPUTS, SampledVessel
from trackkit.models.manoeuvring import N_THETA, Normalisation, advance_pose, integrate_pose
from trackkit.renamed import renamed_keywords

__all__ = ["Prediction", "predict", "dead_reckon", "position_error", "rmse"]

Array = NDArray[np.float64]


class Prediction(NamedTuple):
    """``body (..., K, 3)``: the predicted ``[u, v, r]``; ``pose (..., K, 3)``:
    ``[east, north, psi]``."""

    body: Array
    pose: Array


@renamed_keywords(T="dt")
def predict(theta: ArrayLike, s: ArrayLike, dt: float, x0: ArrayLike, *,
            norm: Normalisation, pose0: ArrayLike = (0.0, 0.0, 0.0),
            substeps: int = SUBSTEPS_SAMPLED_INPUTS) -> Prediction:
    """Predict body states and poses for inputs ``s (..., K, 2)`` (rad, rpm) sampled every
    ``dt`` seconds from ``x0 (..., 3)`` (SI) and ``pose0 (..., 3)``, with coefficients
    ``theta (..., 16)`` in the prime units of ``norm``. Batch axes lead and broadcast."""
    theta = np.asarray(theta, dtype=float)
    s, x0 = np.asarray(s, dtype=float), np.asarray(x0, dtype=float)
    if theta.ndim < 1 or theta.shape[-1] != N_THETA or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta has shape {theta.shape}; expected finite (..., 16)")
    if s.ndim < 2 or s.shape[-1] != 2 or s.shape[-2] < 2 or not np.all(np.isfinite(s)):
        raise ValueError(f"s has shape {s.shape}; expected finite (..., K, 2) with K >= 2")
    if x0.ndim < 1 or x0.shape[-1] != 3 or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 has shape {x0.shape}; expected finite (..., 3)")
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}; expected a sample period > 0 s")
    K = s.shape[-2]
    batch = np.broadcast_shapes(theta.shape[:-1], s.shape[:-2], x0.shape[:-1])
    xa = np.concatenate([np.broadcast_to(x0, batch + (3,)),
                         np.broadcast_to(theta, batch + (N_THETA,))], -1)
    out = [xa[..., :3]]
    for k in range(K - 1):
        xa = SampledVessel(s[..., k, :], s[..., k + 1, :], norm, substeps=substeps).f(xa, dt)
        out.append(xa[..., :3])
    body = np.stack(out, -2)
    return Prediction(body, integrate_pose(body, dt, pose0))


@renamed_keywords(T="dt")
def dead_reckon(body: ArrayLike, heading: ArrayLike, dt: float,
                pose0: ArrayLike) -> Array:
    """Track ``(..., K, 3)`` = ``[east, north, psi]`` from body states ``body (..., K, 3)``
    (only u and v are used) and measured heading ``(..., K)`` (rad) every ``dt`` seconds,
    starting at the known ``pose0 (..., 3)`` (its east and north; psi is the measured
    heading throughout)."""
    body, heading = np.asarray(body, dtype=float), np.asarray(heading, dtype=float)
    if body.ndim < 2 or body.shape[-1] != 3:
        raise ValueError(f"body has shape {body.shape}; expected (..., K, 3)")
    K = body.shape[-2]
    if heading.shape[-1:] != (K,):
        raise ValueError(f"heading has shape {heading.shape}; expected (..., {K})")
    pose0 = np.asarray(pose0, dtype=float)
    batch = np.broadcast_shapes(body.shape[:-2], heading.shape[:-1], pose0.shape[:-1])
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r}; expected a sample period > 0 s")
    east = np.broadcast_to(pose0[..., 0], batch)
    north = np.broadcast_to(pose0[..., 1], batch)
    out = [np.stack([east, north, np.broadcast_to(heading[..., 0], batch)], -1)]
    for k in range(K - 1):
        turn = wrap(heading[..., k + 1] - heading[..., k])
        mean_body = 0.5 * (body[..., k, :] + body[..., k + 1, :])
        x = np.stack(np.broadcast_arrays(mean_body[..., 0], mean_body[..., 1], turn / dt), -1)
        pose = np.stack(np.broadcast_arrays(out[-1][..., 0], out[-1][..., 1],
                                            heading[..., k]), -1)
        nxt = advance_pose(pose, x, dt)
        out.append(np.stack([nxt[..., 0], nxt[..., 1],
                             np.broadcast_to(heading[..., k + 1], batch)], -1))
    return np.stack(out, -2)


def position_error(pose: ArrayLike, east: ArrayLike, north: ArrayLike) -> Array:
    """Horizontal distance ``(..., K)`` between ``pose[..., :2]`` and the true
    ``east, north (..., K)``."""
    pose = np.asarray(pose, dtype=float)
    return np.hypot(pose[..., 0] - np.asarray(east), pose[..., 1] - np.asarray(north))


def rmse(error: ArrayLike, axis: int | tuple[int, ...] = -1) -> Array:
    """Root mean square of ``error`` over ``axis``."""
    e = np.asarray(error, dtype=float)
    return np.sqrt(np.mean(e * e, axis=axis))
