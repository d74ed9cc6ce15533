"""Running a filter over a measurement sequence, streaming by default."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from trackkit.belief import Gaussian, Innovation
from trackkit.filters.base import Filter
from trackkit.models.protocols import MotionModel, SensorModel

__all__ = ["run_filter"]


def run_filter(
    f: Filter,
    prior: Any,
    motion: MotionModel,
    sensor: SensorModel | Sequence[SensorModel],
    measurements: Iterable[ArrayLike],
    dt: float | Iterable[float],
    history: bool = False,
    on_step: Callable[[int, Any, Innovation], None] | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[Any, Gaussian | None]:
    """Filter ``measurements`` (an iterable of ``(..., m)`` arrays, nan where missing).

    Each step is predict by ``dt`` then update; the first measurement is taken at the prior's
    time plus one step. ``sensor`` may be one model or an iterable of per-step models (a moving
    observer). Working memory is that of one belief (runs x n^2); with ``history=True`` the
    filtered means and covariances are stacked along a new leading time axis.
    ``on_step(k, belief, innovation)`` lets metrics be accumulated as the run streams.

    A stochastic filter (``f.stochastic``, e.g. the particle filter) is initialised here,
    ``f.init(prior, rng=rng)``, from a Gaussian prior or its own belief; it draws from
    ``rng`` (None: a fresh generator, or the one the belief already carries), so a seeded
    generator makes the run reproducible. Other filters ignore ``rng``.
    """
    b = f.init(prior, rng=rng) if getattr(f, "stochastic", False) else prior
    dts = iter(dt) if np.ndim(dt) else None
    sensors = iter(sensor) if isinstance(sensor, list | tuple) else None
    means, covs = [], []
    for k, z in enumerate(measurements):
        step = next(dts) if dts is not None else dt
        s = next(sensors) if sensors is not None else sensor
        b = f.predict(b, motion, step)
        b, innov = f.update(b, z, s)
        if on_step is not None:
            on_step(k, b, innov)
        if history:
            g = f.estimate(b)
            means.append(g.mean)
            covs.append(g.cov)
    hist = Gaussian._make((np.stack(means), np.stack(covs))) if history and means else None
    return b, hist
