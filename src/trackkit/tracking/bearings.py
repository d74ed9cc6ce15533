"""Timestamped bearings as the network's agents hold and exchange them (Jalalipoor and Kardehi
Moghaddam 2021): one record for an agent's scans, its unclaimed pool, the bearings in a message and
the initiation's input. (``trackkit.sim.sensor_network.Bearings`` is the simulation's padded
record of every bearing slot of a run batch, a different thing.)"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["BearingSet", "concat_bearings", "empty_bearings"]

Array = NDArray[np.float64]


class BearingSet(NamedTuple):
    """Timestamped bearings: ``z (M,)`` (rad, nautical), ``t (M,)`` (s), ``sensor (M, 2)``
    (the sensor's position, m), ``sigma (M,)`` (rad), ``source (M,)`` int64 (the measuring
    agent's index; -1 unknown)."""

    z: Array
    t: Array
    sensor: Array
    sigma: Array
    source: NDArray[np.int64]

    def take(self, idx: ArrayLike) -> BearingSet:
        return BearingSet(*(np.asarray(a)[idx] for a in self))

    @property
    def size(self) -> int:
        return int(self.z.shape[0])


def empty_bearings() -> BearingSet:
    """A bearing set with no bearings (every field with 0 rows)."""
    return BearingSet(np.zeros(0), np.zeros(0), np.zeros((0, 2)), np.zeros(0),
                      np.zeros(0, np.int64))


def concat_bearings(*sets: BearingSet) -> BearingSet:
    """The bearings of ``sets`` one after another, in order, as one bearing set."""
    return BearingSet(*(np.concatenate(parts, axis=0) for parts in zip(*sets, strict=True)))
