"""Angles: wrapping to (-pi, pi] and circular means.

Bearings in trackkit are nautical by default (clockwise from north, ``atan2(dx, dy)``);
these helpers do not care which convention an angle uses.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["wrap", "circular_mean", "nautical_to_math", "math_to_nautical"]


def wrap(angle: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles to the half-open interval (-pi, pi].

    ``wrap(a) = a - 2 pi ceil((a - pi) / (2 pi))``, so ``wrap(-pi) == pi``.
    """
    a = np.asarray(angle, dtype=float)
    w = a - 2.0 * np.pi * np.ceil((a - np.pi) / (2.0 * np.pi))
    # the product above rounds; put the few results that land just outside back inside
    w = np.where(w > np.pi, w - 2.0 * np.pi, w)
    return np.where(w <= -np.pi, w + 2.0 * np.pi, w)


def circular_mean(
    angle: ArrayLike, weights: ArrayLike | None = None, axis: int = -1
) -> NDArray[np.float64]:
    """Weighted circular mean ``atan2(sum w sin a, sum w cos a)`` along ``axis``.

    Weights may be negative (unscented weights are); the result is in (-pi, pi].
    """
    a = np.asarray(angle, dtype=float)
    if weights is None:
        s, c = np.sin(a).sum(axis=axis), np.cos(a).sum(axis=axis)
    else:
        w = np.asarray(weights, dtype=float)
        if w.ndim == 1 and a.ndim > 1:  # np.average semantics: weights along ``axis``
            shape = [1] * a.ndim
            shape[axis] = -1
            w = w.reshape(shape)
        s, c = (w * np.sin(a)).sum(axis=axis), (w * np.cos(a)).sum(axis=axis)
    return wrap(np.arctan2(s, c))


def nautical_to_math(bearing: ArrayLike) -> NDArray[np.float64]:
    """Clockwise-from-north bearing to counter-clockwise-from-east angle: ``pi/2 - b``."""
    return wrap(np.pi / 2 - np.asarray(bearing, dtype=float))


def math_to_nautical(angle: ArrayLike) -> NDArray[np.float64]:
    """Counter-clockwise-from-east angle to clockwise-from-north bearing (self-inverse)."""
    return nautical_to_math(angle)
