"""A model with its noise covariance replaced: what a filter believes R or Q to be.

A filter reads R only as ``sensor.noise`` and Q only as ``motion.noise(x, dt)`` (a caller
reads both alike, ``sensor.noise_cov(x)`` and ``motion.noise_cov(x, dt)``), so a model
whose noise is swapped is all an adaptive filter (or a filter with a deliberately wrong R0)
needs; everything else (h, Jacobians, residual wrapping) is the wrapped model's. The noise may
carry batch axes, ``(..., m, m)`` or ``(..., n, n)``, one matrix per batch row.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["with_noise", "SensorWithNoise", "MotionWithNoise"]

Array = NDArray[np.float64]


def _square(M: ArrayLike, size: int, what: str) -> Array:
    M = np.asarray(M, dtype=float)
    if M.ndim < 2 or M.shape[-2:] != (size, size):
        raise ValueError(f"{what} has shape {M.shape}; expected (..., {size}, {size})")
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{what} has non-finite entries; expected finite values")
    return M


class SensorWithNoise:
    """``sensor`` with ``noise`` = R (``(m, m)`` or batched ``(..., m, m)``)."""

    def __init__(self, sensor: Any, R: ArrayLike) -> None:
        self.sensor = sensor
        self.noise = _square(R, sensor.dim_z, "R")

    def noise_cov(self, x: Array | None = None) -> Array:
        return self.noise

    def __getattr__(self, name: str) -> Any:  # everything but the noise is the sensor's
        return getattr(self.sensor, name)

    def __repr__(self) -> str:
        return f"SensorWithNoise({self.sensor!r}, R shape {self.noise.shape})"


class MotionWithNoise:
    """``motion`` with ``noise(x, dt)`` = Q (``(n, n)`` or batched ``(..., n, n)``) for every
    x and dt."""

    def __init__(self, motion: Any, Q: ArrayLike) -> None:
        self.motion = motion
        self.Q = _square(Q, motion.dim_x, "Q")

    def noise(self, x: Array, dt: ArrayLike = 0.0) -> Array:
        return self.Q

    def noise_cov(self, x: Array, dt: ArrayLike = 0.0) -> Array:
        return self.Q

    def __getattr__(self, name: str) -> Any:
        return getattr(self.motion, name)

    def __repr__(self) -> str:
        return f"MotionWithNoise({self.motion!r}, Q shape {self.Q.shape})"


def with_noise(model: Any, noise: ArrayLike) -> SensorWithNoise | MotionWithNoise:
    """The sensor (``noise`` is R) or motion model (``noise`` is Q) with its noise replaced."""
    if hasattr(model, "dim_z"):
        return SensorWithNoise(model, noise)
    if hasattr(model, "dim_x"):
        return MotionWithNoise(model, noise)
    raise TypeError(f"with_noise: {type(model).__name__} is neither a sensor (dim_z) nor a "
                    "motion model (dim_x)")
