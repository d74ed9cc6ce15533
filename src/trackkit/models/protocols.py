"""What the filters rely on in a motion or a sensor model, as typed Protocols.

A model need not inherit from anything: any object with these members works (the bundled ones
share ``MotionBase`` and ``SensorBase``). Members a filter only looks for, with a fallback, are
left out: ``linear`` and ``angular`` of a motion model (False and None when absent), and a
sensor's ``linear``, ``linearize(x) -> (h(x), jacobian(x))`` (the Tracker's gate calls it) and
``hessian(x) (..., m, n, n)`` (the second-order filters call it).

Arrays carry leading batch axes: ``x (..., n)``, ``z (..., m)``; ``dt`` (s) is a float or an
array broadcasting against the batch axes.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = ["MotionModel", "SensorModel"]


@runtime_checkable
class MotionModel(Protocol):
    """``x_{k+1} = f(x_k, dt) + w``, ``w ~ N(0, Q(x_k, dt))``."""

    @property
    def dim_x(self) -> int:
        """n, the length of the state."""
        ...

    def f(self, x: Array, dt: ArrayLike) -> Array:
        """The transition, ``(..., n)``."""
        ...

    def jacobian(self, x: Array, dt: ArrayLike) -> Array:
        """``F = df/dx``, broadcastable to ``(..., n, n)``."""
        ...

    def noise(self, x: Array, dt: ArrayLike) -> Array:
        """Q, broadcastable to ``(..., n, n)``."""
        ...


@runtime_checkable
class SensorModel(Protocol):
    """``z = h(x) + v``, ``v ~ N(0, R)``."""

    @property
    def dim_z(self) -> int:
        """m, the length of a measurement."""
        ...

    @property
    def angular(self) -> tuple[bool, ...]:
        """Which measurement components are angles (wrapped, averaged circularly)."""
        ...

    @property
    def noise(self) -> Array:
        """R, ``(m, m)`` or batched ``(..., m, m)``."""
        ...

    def h(self, x: Array) -> Array:
        """The predicted measurement, ``(..., m)``."""
        ...

    def jacobian(self, x: Array) -> Array:
        """``H = dh/dx``, ``(..., m, n)``."""
        ...

    def residual(self, z: Array, zhat: Array) -> Array:
        """``z - zhat`` with the angle components wrapped to (-pi, pi]: the innovation nu."""
        ...
